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
//  * A watchdog reset (the timer expiring after a hang, or the firmware forcing one) reboots the
//    image as the chip does: a fresh chip (RAM, peripherals, GPIOs back to inputs, USB detached
//    and enumerated again), the same flash image, the models' input levels re-applied. One
//    difference: rp2040js's timer reads the simulated clock, so device time goes on counting
//    across the reboot instead of restarting at 0 (the host handshakes again anyway).
//
// Device time = simulated time: the RP2040 timer reads `clock.nanos / 1000`, so an event
// scheduled at simulated nanosecond T is seen by the firmware at (T + capture latency) / 1000 us.

const {
  RP2040, USBCDC, ConsoleLogger, LogLevel, createSetupPacket, DataDirection, SetupType, SetupRecipient,
} = require('rp2040js');
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
    this.elfPath = elfPath;
    this.opts = opts;
    this.outputListeners = [];
    this.serialListeners = [];
    this.resetListeners = [];
    this.inputLevels = new Map();
    this.resets = 0;
    this.instructions = 0;
    this._boot(new RP2040());
  }

  /** Loads the image into a fresh chip `mcu` and starts it (power-up, or after a reset). */
  _boot(mcu) {
    const opts = this.opts;
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
    loadIntoFlash(this.elfPath, mcu.flash);
    mcu.peripherals[0x40058].scratchData[0] = EMULATOR_MAGIC;
    // Boot: vector table after boot2.
    mcu.core.VTOR = VECTOR_TABLE;
    mcu.core.SP = mcu.readUint32(VECTOR_TABLE);
    mcu.core.PC = mcu.readUint32(VECTOR_TABLE + 4) & ~1;

    // PIO in lockstep.
    for (const pio of mcu.pio) pio.run = () => {};

    this._setupUsb();
    for (const pin of mcu.gpio) {
      pin.addListener(() => {
        if (this.mcu !== mcu) return;
        for (const l of this.outputListeners) l(pin.index, pin.outputEnable ? pin.outputValue : null);
      });
    }
    for (const [gpio, high] of this.inputLevels) mcu.gpio[gpio].setInputValue(high);
    const watchdog = mcu.peripherals[0x40058];
    watchdog.onWatchdogTrigger = () => {
      // Stop this chip's watchdog at once (its periodic alarm would fire again and again at
      // count 0), and reset from the run loop: the trigger fires inside an alarm or a store.
      watchdog.alarm.enable = false;
      watchdog.timer.enable = false;
      this.resetPending = watchdog.reason === 1 ? 'timeout' : 'forced';
    };
    this.resetPending = null;
    this.hung = false;
  }

  /**
   * The watchdog reset: every GPIO becomes an input at once (the outputs' external pull-downs
   * then hold the drivers off), the chip restarts from the same flash image.
   */
  _watchdogReset() {
    const cause = this.resetPending;
    this.resetPending = null;
    const old = this.mcu;
    old.peripherals[0x40058].alarm.enable = false;
    old.peripherals[0x40058].timer.enable = false;
    this.resets += 1;
    this.connected = false;
    const { RP2040: Chip } = require('rp2040js');
    this._boot(new Chip(this.clock));
    // The new chip's pins start as inputs: report that to the models (released outputs).
    for (let gpio = 0; gpio < this.mcu.gpio.length; gpio++) {
      for (const l of this.outputListeners) l(gpio, null);
    }
    for (const l of this.resetListeners) l(cause);
  }

  /** Calls `listener(cause)` after a watchdog reset ('timeout' or 'forced') rebooted the image. */
  onReset(listener) {
    this.resetListeners.push(listener);
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
      if (this.resetPending) {
        this._watchdogReset();
        this.instructions += n;
        return this.runUntil(targetNanos, Math.max(1, maxInstructions - n));
      }
      if (core.waiting || this.hung) {
        const toAlarm = clock.nanosToNextAlarm;
        const toTarget = targetNanos - clock.nanos;
        const jump = toAlarm > 0 ? Math.min(toAlarm, toTarget) : toTarget;
        clock.tick(jump);
        // Let the PIO react to inputs changed by alarm callbacks (2-4 cycles).
        for (let i = 0; i < 4 && core.waiting && !this.hung; i++) {
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
    this.inputLevels.set(gpio, !!high);
    this.mcu.gpio[gpio].setInputValue(!!high);
  }

  /**
   * Makes the firmware hang: the core stops making progress (as in a runaway loop with
   * interrupts masked) and runs no more code, so nothing feeds the watchdog; its reset is the
   * only way out. (The core is not stepped while hung: a spinning branch would only cost
   * emulation time.)
   */
  hang() {
    this.hung = true;
  }

  /**
   * Enters the firmware's panic handler as a panic would (`rust_begin_unwind`, at `address`,
   * from the ELF's symbols), with interrupts masked: it must release every output first.
   */
  enterPanicHandler(address, infoPtr) {
    const { core } = this.mcu;
    core.PM = true;
    core.registers[0] = infoPtr;
    core.PC = address & ~1;
    core.waiting = false;
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
    cdc.onDeviceConnected = () => {
      // A host's serial driver raises DTR when a program opens the port.
      this.setDtr(true);
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

  /**
   * The host opens (true) or closes (false) the port: USB CDC SET_CONTROL_LINE_STATE with DTR
   * and RTS set or cleared, as a host's serial driver sends it.
   */
  setDtr(asserted) {
    // Addressed to the CDC communication interface (0), as hosts send it. (rp2040js's own
    // cdcSetControlLineState addresses the device, which embassy-usb's CDC class ignores.)
    this.mcu.usbCtrl.sendSetupPacket(
      createSetupPacket({
        dataDirection: DataDirection.HostToDevice,
        type: SetupType.Class,
        recipient: SetupRecipient.Interface,
        bRequest: 0x22, // SET_CONTROL_LINE_STATE
        wValue: asserted ? 0x3 : 0x0, // DTR | RTS
        wIndex: 0,
        wLength: 0,
      }),
    );
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
