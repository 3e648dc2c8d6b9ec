'use strict';
// In-process test driver: the emulated board, the camera/flash rig and a protocol client on the
// USB CDC bytes, all on the simulated clock (no pty, no wall-clock waits), for test/*.test.js.

const fs = require('fs');
const path = require('path');
const { Board } = require('./board');
const { Rig } = require('./models');
const { loadPinmap } = require('./pinmap');
const proto = require('./protocol');

function defaultElf() {
  const repo = path.join(__dirname, '..', '..', '..');
  const targetDir = process.env.CARGO_TARGET_DIR || path.join(repo, 'firmware', 'rp2040', 'target');
  return process.env.SKINBRDF_FIRMWARE_ELF || path.join(targetDir, 'thumbv6m-none-eabi', 'release', 'skinbrdf-rp2040');
}

class EmulatedDevice {
  constructor(opts = {}) {
    this.elf = opts.elf || defaultElf();
    this.board = new Board(this.elf);
    this.pins = loadPinmap();
    this.log = [];
    this.rig = new Rig(this.board, this.pins, (e) => this.log.push(e), { camera: opts.camera, flash: opts.flash });
    this.decoder = new proto.FrameDecoder();
    this.messages = [];
    this.board.onSerialData((d) => {
      for (const m of this.decoder.push(d)) this.messages.push(m);
    });
    this.seq = 0;
  }

  static elfExists(elf = defaultElf()) {
    return fs.existsSync(elf);
  }

  get nowUs() {
    return this.board.nanos / 1000;
  }

  /** Runs simulated time until `pred()` holds; throws after `maxUs` of simulated time. */
  runUntil(pred, maxUs, what = 'condition') {
    const limit = this.board.nanos + maxUs * 1000;
    while (!pred()) {
      if (this.board.nanos >= limit) throw new Error(`timed out after ${maxUs} us of simulated time waiting for ${what}`);
      this.board.runUntil(Math.min(limit, this.board.nanos + 200_000));
    }
  }

  /** Runs for `us` microseconds of simulated time. */
  runFor(us) {
    const target = this.board.nanos + us * 1000;
    while (!this.board.runUntil(target)) {
      /* instruction budget exhausted: keep going */
    }
  }

  boot() {
    this.runUntil(() => this.board.connected, 1_000_000, 'USB enumeration');
    this.runFor(5_000);
  }

  sendRaw(bytes) {
    this.board.sendToDevice(bytes);
  }

  /** Sends a request and returns its response ({seq, ok} or {seq, err}). */
  request(body, maxUs = 500_000) {
    const seq = ++this.seq;
    this.sendRaw(proto.encodeRequest(seq, body));
    let resp;
    this.runUntil(() => {
      const i = this.messages.findIndex((m) => m.kind === 'Response' && m.seq === seq);
      if (i < 0) return false;
      resp = this.messages.splice(i, 1)[0];
      return true;
    }, maxUs, `response to ${body.type}`);
    return resp;
  }

  /** Waits for an event of `type` and removes it (and returns it). */
  waitEvent(type, maxUs) {
    let ev;
    this.runUntil(() => {
      const i = this.messages.findIndex((m) => m.kind === 'Event' && m.event.type === type);
      if (i < 0) return false;
      ev = this.messages.splice(i, 1)[0].event;
      return true;
    }, maxUs, `event ${type}`);
    return ev;
  }

  /** Removes and returns every received event of `type`. */
  takeEvents(type) {
    const out = [];
    this.messages = this.messages.filter((m) => {
      if (m.kind === 'Event' && m.event.type === type) {
        out.push(m.event);
        return false;
      }
      return true;
    });
    return out;
  }

  hello() {
    return this.request({ type: 'Hello', protocol_version: proto.PROTOCOL_VERSION });
  }

  /** Simulated times (ns) at which the rig saw `name` become `asserted`. */
  times(name, asserted = true) {
    return this.log.filter((e) => e.event === name && e.asserted === asserted).map((e) => e.sim_ns);
  }

  /** Levels of the camera/flash outputs as the rig sees them. */
  outputsAsserted() {
    const { shutter, focus, flash_trigger } = this.rig.outputs;
    return { shutter, focus, flash_trigger };
  }
}

/** A one-group plan. */
function plan(overrides = {}, policy = { max_retries: 0, on_exhausted: 'AbortSession' }) {
  return {
    groups: [
      {
        label: 'measurement',
        role: 'Measurement',
        count: 3,
        min_interval_us: 100_000,
        pre_focus_us: 20_000,
        shutter_pulse_us: 50_000,
        xsync_timeout_us: 300_000,
        flash_ready_timeout_us: 2_000_000,
        flash_window_us: 20_000,
        flash_mode: 'CameraHotShoe',
        ...overrides,
      },
    ],
    policy,
    flash_trigger_pulse_us: 1_000,
  };
}

module.exports = { EmulatedDevice, plan, defaultElf };
