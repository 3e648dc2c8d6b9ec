'use strict';
// Models of the hardware around the controller, driving the firmware's input pins and watching
// its outputs, on the simulated clock.
//
// Camera: when the shutter line is asserted, after a shutter lag drawn uniformly from
// [lagMinUs, lagMaxUs] (seeded, so runs repeat), the hot-shoe X contact closes for xsyncWidthUs.
// Fault: `enabled = false` (camera does not fire: no X-sync).
//
// Flash: fires on the hot-shoe contact (`firesOn` 'hotshoe'), on the controller's flash-trigger
// output ('trigger') or on either ('both'), but only when ready. Firing makes the photodiode see
// light photodiodeDelayUs later for flashDurationUs, drops the ready line, and raises it again
// after recycleUs. Faults: `misfire` (fires, so it recycles, but no light), `neverReady`.
//
// Every change is reported through `emit({event, ..., sim_ns})`.

/** Small deterministic PRNG (mulberry32). */
function prng(seed) {
  let a = seed >>> 0;
  return () => {
    a = (a + 0x6d2b79f5) >>> 0;
    let t = a;
    t = Math.imul(t ^ (t >>> 15), t | 1);
    t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
}

const CAMERA_DEFAULTS = { enabled: true, lagMinUs: 60_000, lagMaxUs: 120_000, xsyncWidthUs: 5_000, seed: 1 };
const FLASH_DEFAULTS = {
  firesOn: 'both',
  recycleUs: 1_000_000,
  photodiodeDelayUs: 50,
  flashDurationUs: 1_000,
  misfire: false,
  neverReady: false,
};

class Rig {
  /**
   * @param {Board} board
   * @param {object} pins pin map (lib/pinmap.js)
   * @param {(ev: object) => void} emit
   */
  constructor(board, pins, emit, opts = {}) {
    this.board = board;
    this.pins = pins;
    this.emit = emit;
    this.camera = { ...CAMERA_DEFAULTS, ...(opts.camera || {}) };
    this.flash = { ...FLASH_DEFAULTS, ...(opts.flash || {}) };
    this.random = prng(this.camera.seed);
    this.asserted = { xsync: false, photodiode: false, flash_ready: false };
    this.outputs = { shutter: false, focus: false, flash_trigger: false, status_led: false };
    this.shots = 0;
    // Inputs start released; the flash starts ready unless told otherwise.
    for (const name of ['xsync', 'photodiode', 'flash_ready']) this.drive(name, false, true);
    this.flashReady = false;
    this.setFlashReady(!this.flash.neverReady);

    board.onPinChange((gpio, level) => {
      for (const name of Object.keys(this.outputs)) {
        const p = pins[name];
        if (p.gpio !== gpio) continue;
        const asserted = level === null ? false : level === p.activeHigh;
        if (asserted === this.outputs[name]) return;
        this.outputs[name] = asserted;
        if (name !== 'status_led') this.emit({ event: name, asserted, sim_ns: board.nanos });
        this.onOutput(name, asserted);
      }
    });
  }

  /** Drives input `name` (asserted = its active level). */
  drive(name, asserted, quiet = false) {
    const p = this.pins[name];
    this.asserted[name] = asserted;
    this.board.setInput(p.gpio, asserted === p.activeHigh);
    if (!quiet) this.emit({ event: name, asserted, sim_ns: this.board.nanos });
  }

  /** Asserts input `name` at absolute simulated time `atNs` for `widthNs`. */
  pulse(name, atNs, widthNs) {
    this.board.at(atNs, () => {
      this.drive(name, true);
      if (name === 'xsync') this.onHotShoe();
    });
    this.board.at(atNs + widthNs, () => this.drive(name, false));
  }

  setFlashReady(ready) {
    if (this.flash.neverReady) ready = false;
    this.flashReady = ready;
    this.drive('flash_ready', ready);
  }

  onOutput(name, asserted) {
    if (name === 'shutter' && asserted) {
      this.shots += 1;
      if (!this.camera.enabled) {
        this.emit({ event: 'camera_did_not_fire', sim_ns: this.board.nanos });
        return;
      }
      const { lagMinUs, lagMaxUs, xsyncWidthUs } = this.camera;
      const lagUs = lagMinUs + (lagMaxUs - lagMinUs) * this.random();
      const at = this.board.nanos + Math.round(lagUs * 1000);
      this.pulse('xsync', at, xsyncWidthUs * 1000);
    }
    if (name === 'flash_trigger' && asserted && this.flash.firesOn !== 'hotshoe') this.fire('trigger');
  }

  onHotShoe() {
    if (this.flash.firesOn !== 'trigger') this.fire('hotshoe');
  }

  fire(source) {
    const now = this.board.nanos;
    if (!this.flashReady) {
      this.emit({ event: 'flash_ignored_not_ready', source, sim_ns: now });
      return;
    }
    const f = this.flash;
    this.emit({ event: 'flash_fired', source, misfire: f.misfire, sim_ns: now });
    this.setFlashReady(false);
    if (!f.misfire) this.pulse('photodiode', now + f.photodiodeDelayUs * 1000, f.flashDurationUs * 1000);
    this.board.at(now + f.recycleUs * 1000, () => this.setFlashReady(true));
  }

  /** Updates model options (fault injection). */
  configure({ camera, flash } = {}) {
    Object.assign(this.camera, camera || {});
    Object.assign(this.flash, flash || {});
    if (flash && 'neverReady' in flash) this.setFlashReady(!flash.neverReady);
  }
}

module.exports = { Rig, CAMERA_DEFAULTS, FLASH_DEFAULTS, prng };
