'use strict';
// The emulated board: rp2040js running the firmware image, with the few patches the image needs.
//
// Patches (all inside this harness, none in rp2040js):
//  * Boot without the bootrom: the image's flash segments are copied to 0x10000000, VTOR is set
//    to the vector table after boot2 (0x10000100) and SP/PC are taken from it. (Running boot2
//    from 0x10000000 works too; skipping it saves time and needs no SSI model.)
//  * The USB OUT endpoint keeps AVAILABLE set until the host has data. rp2040js answers an armed
//    OUT buffer at once, with zero bytes when the host has sent nothing, and clears AVAILABLE;
//    embassy-rp then reads a bogus packet. Here the read is parked (AVAILABLE stays set) and
//    completed when bytes arrive.
//  * The PIO runs in lockstep with the core: rp2040js steps it from a setTimeout loop, i.e. in
//    wall-clock time, which would make edge timestamps meaningless. `pio.run` is disabled and
//    both PIO blocks are stepped once per core cycle.
//  * SEV sets the event register (rp2040js ignores it), so WFE returns after a task woke
//    another one from thread mode, as on the chip.
//  * When the core sleeps (WFI/WFE) the clock jumps to the next alarm (timer, USB, or a model
//    event), or to the pacing target when none is pending.
//
// Device time = simulated time: the RP2040 timer reads `clock.nanos / 1000`, so an event
// scheduled at simulated nanosecond T is seen by the firmware at (T + capture latency) / 1000 us.

const { RP2040, USBCDC, ConsoleLogger, LogLevel } = require('rp2040js');
const { loadIntoFlash, FLASH_BASE } = require('./elf');

const CYCLE_NS = 8; // 125 MHz
const EP0_OUT_BUFFER_CONTROL = 0x84;
const USB_BUF_CTRL_AVAILABLE = 1 << 10;
const VECTOR_TABLE = FLASH_BASE + 0x100;
/** Value the firmware looks for in watchdog scratch 0 to know it runs in the emulator. */
const EMULATOR_MAGIC = 0x454d5521;

class Board {
  /**
   * @param {string} elfPath firmware ELF
   * @param {object} opts { logLevel: 'error'|'warn'|'info'|'debug' }
   */
  constructor(elfPath, opts = {}) {
    const mcu = new RP2040();
    const levels = { error: LogLevel.Error, warn: LogLevel.Warn, info: LogLevel.Info, debug: LogLevel.Debug };
    const inner = new ConsoleLogger(levels[opts.logLevel || 'error'] ?? LogLevel.Error, true);
    // SEV is a no-op in rp2040js (it only logs 'SEV'); embassy's executor relies on it to wake
    // from WFE after a task wakes another one. Set the event register when it is logged.
    mcu.logger = {
      debug: (c, m) => inner.debug(c, m),
      warn: (c, m) => inner.warn(c, m),
      error: (c, m) => inner.error(c, m),
      info: (c, m) => {
        if (m === 'SEV') mcu.core.eventRegistered = true;
        else inner.info(c, m);
      },
    };
    this.mcu = mcu;
    this.clock = mcu.clock;
    loadIntoFlash(elfPath, mcu.flash);
    mcu.peripherals[0x40058].scratchData[0] = EMULATOR_MAGIC;
    // Boot: vector table after boot2.
    mcu.core.VTOR = VECTOR_TABLE;
    mcu.core.SP = mcu.readUint32(VECTOR_TABLE);
    mcu.core.PC = mcu.readUint32(VECTOR_TABLE + 4) & ~1;

    // PIO in lockstep.
    for (const pio of mcu.pio) pio.run = () => {};

    this._setupUsb();
    this.outputListeners = [];
    for (const pin of mcu.gpio) {
      pin.addListener(() => {
        for (const l of this.outputListeners) l(pin.index, pin.outputEnable ? pin.outputValue : null);
      });
    }
    this.instructions = 0;
  }

  // ---------------------------------------------------------------- time

  /** Simulated time in nanoseconds since reset (the firmware's clock is this / 1000). */
  get nanos() {
    return this.clock.nanos;
  }

  /** Runs a callback at simulated time `atNanos` (absolute). Returns a cancel function. */
  at(atNanos, callback) {
    const alarm = this.clock.createAlarm(callback);
    alarm.schedule(Math.max(0, atNanos - this.clock.nanos));
    return () => alarm.cancel();
  }

  _stepPio(cycles) {
    const [pio0, pio1] = this.mcu.pio;
    for (let c = 0; c < cycles; c++) {
      if (!pio0.stopped) pio0.step();
      if (!pio1.stopped) pio1.step();
    }
  }

  /**
   * Runs the core until simulated time reaches `targetNanos` or `maxInstructions` ran.
   * Returns true if the target was reached.
   */
  runUntil(targetNanos, maxInstructions = 2_000_000) {
    const { core } = this.mcu;
    const clock = this.clock;
    let n = 0;
    while (clock.nanos < targetNanos) {
      if (core.waiting) {
        const toAlarm = clock.nanosToNextAlarm;
        const toTarget = targetNanos - clock.nanos;
        const jump = toAlarm > 0 ? Math.min(toAlarm, toTarget) : toTarget;
        clock.tick(jump);
        // Let the PIO react to inputs changed by alarm callbacks (2-4 cycles).
        for (let i = 0; i < 4 && core.waiting; i++) {
          this._stepPio(1);
          clock.tick(CYCLE_NS);
        }
      } else {
        const cycles = core.executeInstruction();
        this._stepPio(cycles);
        clock.tick(cycles * CYCLE_NS);
        if (++n >= maxInstructions) break;
      }
    }
    this.instructions += n;
    return clock.nanos >= targetNanos;
  }

  // ---------------------------------------------------------------- GPIO

  /** Drives an input pin from outside (true = high). */
  setInput(gpio, high) {
    this.mcu.gpio[gpio].setInputValue(!!high);
  }

  /** Level the firmware drives on `gpio`, or null if it is not an output. */
  output(gpio) {
    const pin = this.mcu.gpio[gpio];
    return pin.outputEnable ? pin.outputValue : null;
  }

  /** Calls `listener(gpio, levelOrNull)` whenever a pin's driven state changes. */
  onPinChange(listener) {
    this.outputListeners.push(listener);
  }

  // ---------------------------------------------------------------- USB CDC

  _setupUsb() {
    const usb = this.mcu.usbCtrl;
    const cdc = new USBCDC(usb);
    this.cdc = cdc;
    this.connected = false;
    this.hostToDevice = [];
    this.pendingOutRead = null; // { endpoint, size }
    this.serialListeners = [];
    cdc.onDeviceConnected = () => {
      this.connected = true;
      if (this.onConnected) this.onConnected();
    };
    cdc.onSerialData = (buf) => {
      for (const l of this.serialListeners) l(Buffer.from(buf));
    };
    const original = usb.onEndpointRead;
    usb.onEndpointRead = (endpoint, size) => {
      if (endpoint !== cdc.outEndpoint || endpoint <= 0) {
        original(endpoint, size);
        return;
      }
      if (this.hostToDevice.length > 0) {
        this._completeOut(endpoint, size);
      } else {
        // Park the read: keep AVAILABLE set so the firmware keeps waiting.
        this.pendingOutRead = { endpoint, size };
        this._setOutAvailable(endpoint, true);
      }
    };
  }

  _setOutAvailable(endpoint, available) {
    const view = this.mcu.usbDPRAMView;
    const reg = EP0_OUT_BUFFER_CONTROL + endpoint * 8;
    let v = view.getUint32(reg, true);
    v = available ? v | USB_BUF_CTRL_AVAILABLE : v & ~USB_BUF_CTRL_AVAILABLE;
    view.setUint32(reg, v, true);
  }

  _completeOut(endpoint, size) {
    const n = Math.min(size, this.hostToDevice.length);
    const chunk = Uint8Array.from(this.hostToDevice.splice(0, n));
    this._setOutAvailable(endpoint, false);
    this.mcu.usbCtrl.finishRead(endpoint, chunk);
  }

  /** Queues bytes from the host to the firmware. */
  sendToDevice(bytes) {
    for (const b of bytes) this.hostToDevice.push(b);
    if (this.pendingOutRead && this.hostToDevice.length > 0) {
      const { endpoint, size } = this.pendingOutRead;
      this.pendingOutRead = null;
      this._completeOut(endpoint, size);
    }
  }

  /**
   * Simulates unplugging and replugging the USB cable: a bus reset (the firmware's USB device
   * drops to its default state, its link goes down), then the emulated host enumerates and
   * configures it again (link up). Bytes in flight either way are lost, as on a real cable.
   */
  reconnectUsb() {
    const cdc = this.cdc;
    cdc.initialized = false;
    cdc.descriptorsSize = null;
    cdc.descriptors = [];
    cdc.inEndpoint = -1;
    cdc.outEndpoint = -1;
    this.connected = false;
    this.pendingOutRead = null;
    this.hostToDevice = [];
    this.mcu.usbCtrl.resetDevice();
  }

  /** Calls `listener(Buffer)` with every packet the firmware sends to the host. */
  onSerialData(listener) {
    this.serialListeners.push(listener);
  }

  /** USB descriptors as seen by the emulated host (for VID/PID checks). */
  get usbDescriptors() {
    return this.cdc.descriptors;
  }
}

module.exports = { Board, EMULATOR_MAGIC, CYCLE_NS };
