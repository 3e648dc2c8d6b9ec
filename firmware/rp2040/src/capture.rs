//! Edge timestamps for the three inputs (X-sync, photodiode, flash ready).
//!
//! Each input is watched by its own PIO0 state machine. On an edge the state machine raises its
//! IRQ flag (routed to `PIO0_IRQ_1`, which embassy's PIO driver leaves alone) and then **counts
//! its own clock cycles until the CPU acknowledges**. The interrupt handler runs at the highest
//! NVIC priority; it reads the 1 MHz system timer first, acknowledges at once (one word into the
//! state machine's TX FIFO), and gets back the count and the new level. The edge time is the
//! timer reading minus the counted latency. So the timestamp does not depend on how late the
//! handler runs: a critical section or another interrupt delaying it changes the count, not the
//! result. Nothing polls in a task.
//!
//! Accuracy (see `docs/firmware.md`): the handler waits for the next 1 MHz timer tick (at
//! most 1 us) before acknowledging, so the time of its reference point is known exactly, not
//! just to within the timer step. The edge time is that tick minus the counted latency (3 PIO
//! cycles = 24 ns per count), rounded to the nearest microsecond: error within +-0.5 us plus a
//! few cycles (measured in the emulator: -0.51..+0.52 us over 2000 edges). Pulses on the same
//! input shorter than the handler latency (~1-2 us, longer while a defmt log statement holds
//! interrupts masked) can be merged or their second edge reported late: the state machine looks
//! at the pin again only after the acknowledgement. Camera X-sync and flash pulses last
//! milliseconds.
//!
//! The reported level is the raw pin level; [`crate::pins::PinInfo::active_high`] maps it to
//! "asserted". A report equal to the last known level (e.g. the first one after start-up) carries
//! no edge and is dropped by the driver.

use portable_atomic::{AtomicU32, Ordering};

use embassy_rp::interrupt::{self as irq, InterruptExt, Priority};
use embassy_rp::pac;
use embassy_rp::pac::interrupt;
use embassy_rp::peripherals::PIO0;
use embassy_rp::pio::{
    Common, Config, Direction, FifoJoin, LoadedProgram, Pio, PioPin, ShiftConfig, ShiftDirection,
    StateMachine, StatusSource,
};
use embassy_rp::Peri;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;

use crate::pins::PinInfo;

/// Which input an edge came from (= its PIO0 state machine number).
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum Input {
    /// Camera hot-shoe X-sync.
    Xsync = 0,
    /// Flash photodiode.
    Photodiode = 1,
    /// Flash ready.
    FlashReady = 2,
}

impl Input {
    const ALL: [Input; 3] = [Input::Xsync, Input::Photodiode, Input::FlashReady];
}

/// One captured level change.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub struct Edge {
    /// Which input.
    pub input: Input,
    /// Raw pin level after the change.
    pub level_high: bool,
    /// Edge time: system timer microseconds since boot, latency-corrected (see module docs).
    pub at_us: u64,
}

/// Captured edges, oldest first. Big enough for a burst of bounces on all three inputs.
pub static EDGES: Channel<CriticalSectionRawMutex, Edge, 32> = Channel::new();

/// Edges lost because [`EDGES`] was full (logged by the controller; should stay 0).
pub static EDGES_DROPPED: AtomicU32 = AtomicU32::new(0);

/// Mask of the state machines in use (SM0..SM2).
const SM_MASK: u8 = 0b0111;

/// PIO cycles per count of the latency loop (`mov y, status`; `jmp !y`; `jmp x--`).
const CYCLES_PER_COUNT: u64 = 3;
/// Cycles between the timer tick the handler waits for and the moment the state machine sees
/// the acknowledgement, which the count includes but the edge-to-tick latency does not: the
/// tick-detecting read, the TX FIFO writes and the status test, minus the cycles before the
/// count starts (input synchroniser, `irq`, `mov x`). Calibrated in the emulator (mean error
/// 0); on the chip the bus timing of the same few instructions differs by a few cycles
/// (< 0.05 us).
const ACK_DELAY_CYCLES: u64 = 15;

/// Microseconds per system clock cycle in Q24 fixed point (2^24 / MHz), set by
/// [`Capture::start`]; keeps divisions (slow software routines on the M0+) out of the handler.
/// Rounding it to an integer costs < 1e-5 relative error: < 0.01 us for a 1 ms latency.
static US_PER_CYCLE_Q24: AtomicU32 = AtomicU32::new((1 << 24) / 125);

/// Handler could not read back a state machine's count (should stay 0).
pub static CAPTURE_ERRORS: AtomicU32 = AtomicU32::new(0);

/// Owns the PIO block and its state machines; dropping it would stop the capture, so it lives
/// in the controller task for the whole run.
pub struct Capture {
    _common: Common<'static, PIO0>,
    _sm0: StateMachine<'static, PIO0, 0>,
    _sm1: StateMachine<'static, PIO0, 1>,
    _sm2: StateMachine<'static, PIO0, 2>,
}

fn configure<const SM: usize>(
    common: &mut Common<'static, PIO0>,
    sm: &mut StateMachine<'static, PIO0, SM>,
    program: &LoadedProgram<'static, PIO0>,
    pin: Peri<'static, impl PioPin>,
    info: PinInfo,
) {
    let mut pin = common.make_pio_pin(pin);
    pin.set_pull(info.pull.unwrap_or(embassy_rp::gpio::Pull::None));
    pin.set_schmitt(true);
    sm.set_pin_dirs(Direction::In, &[&pin]);
    let mut cfg = Config::default();
    cfg.set_in_pins(&[&pin]);
    // `mov y, status` is all-ones while the TX FIFO is empty (no acknowledgement yet).
    cfg.status_sel = StatusSource::TxFifoLevel;
    cfg.status_n = 1;
    cfg.fifo_join = FifoJoin::Duplex;
    cfg.shift_in = ShiftConfig {
        auto_fill: false,
        threshold: 32,
        direction: ShiftDirection::Left,
    };
    cfg.use_program(program, &[]);
    sm.set_config(&cfg);
}

impl Capture {
    /// Loads the program, starts one state machine per input and enables `PIO0_IRQ_1` at the
    /// highest priority.
    pub fn start(
        pio: Pio<'static, PIO0>,
        xsync: Peri<'static, impl PioPin>,
        photodiode: Peri<'static, impl PioPin>,
        flash_ready: Peri<'static, impl PioPin>,
    ) -> Self {
        let Pio {
            mut common,
            mut sm0,
            mut sm1,
            mut sm2,
            ..
        } = pio;
        // Per edge direction: wait for it, raise the flag, count 3-cycle steps down from
        // 0xFFFF_FFFF until the CPU writes the TX FIFO, take that word, clear the flag, push
        // (count << 1 | level).
        let prg = pio::pio_asm!(
            ".wrap_target",
            "wait 1 pin 0",
            "irq nowait 0 rel",
            "mov x, ~null",
            "count_high:",
            "mov y, status",
            "jmp !y acked_high",
            "jmp x-- count_high",
            "acked_high:",
            "pull block",
            "irq clear 0 rel",
            "set y, 1",
            "in x, 31",
            "in y, 1",
            "push block",
            "wait 0 pin 0",
            "irq nowait 0 rel",
            "mov x, ~null",
            "count_low:",
            "mov y, status",
            "jmp !y acked_low",
            "jmp x-- count_low",
            "acked_low:",
            "pull block",
            "irq clear 0 rel",
            "set y, 0",
            "in x, 31",
            "in y, 1",
            "push block",
            ".wrap",
        );
        let program = common.load_program(&prg.program);
        configure(&mut common, &mut sm0, &program, xsync, crate::pins::XSYNC);
        configure(
            &mut common,
            &mut sm1,
            &program,
            photodiode,
            crate::pins::PHOTODIODE,
        );
        configure(
            &mut common,
            &mut sm2,
            &program,
            flash_ready,
            crate::pins::FLASH_READY,
        );

        let mhz = (embassy_rp::clocks::clk_sys_freq() / 1_000_000).max(1);
        US_PER_CYCLE_Q24.store((1 << 24) / mhz, Ordering::Relaxed);
        // Route the IRQ flags 0..2 (raised by SM0..SM2) to PIO0's second interrupt line.
        pac::PIO0.irqs(1).inte().write(|w| {
            w.set_sm0(true);
            w.set_sm1(true);
            w.set_sm2(true);
        });
        irq::PIO0_IRQ_1.set_priority(Priority::P0);
        irq::PIO0_IRQ_1.unpend();
        // SAFETY: the handler below only touches PIO0's FIFOs, the timer and a
        // critical-section channel; enabling it cannot break a critical section's assumptions.
        unsafe { irq::PIO0_IRQ_1.enable() };

        sm0.set_enable(true);
        sm1.set_enable(true);
        sm2.set_enable(true);
        Self {
            _common: common,
            _sm0: sm0,
            _sm1: sm1,
            _sm2: sm2,
        }
    }
}

/// Current raw level of every input (`[xsync, photodiode, flash_ready]`), read from SIO.
pub fn levels() -> [bool; 3] {
    let inputs = pac::SIO.gpio_in(0).read();
    let bit = |info: PinInfo| inputs & (1 << info.gpio) != 0;
    [
        bit(crate::pins::XSYNC),
        bit(crate::pins::PHOTODIODE),
        bit(crate::pins::FLASH_READY),
    ]
}

#[interrupt]
fn PIO0_IRQ_1() {
    let pio = pac::PIO0;
    let timer = pac::TIMER;
    // Which state machines to serve; then wait for the next tick of the 1 MHz timer (at most
    // 1 us) so the read time is known exactly (the tick boundary), not just to within 1 us; then
    // acknowledge at once: from the tick to the acknowledgement is a fixed handful of cycles
    // ([`ACK_DELAY_CYCLES`]).
    let flags = pio.irq().read().irq() & SM_MASK;
    let hi_before = timer.timerawh().read();
    let first = timer.timerawl().read();
    let mut lo = first;
    while lo == first {
        lo = timer.timerawl().read();
    }
    if flags & 0b001 != 0 {
        pio.txf(0).write_value(0);
    }
    if flags & 0b010 != 0 {
        pio.txf(1).write_value(0);
    }
    if flags & 0b100 != 0 {
        pio.txf(2).write_value(0);
    }
    let hi_after = timer.timerawh().read();
    // If the high word ticked between the reads, `lo` tells on which side of it we read.
    let hi = if hi_before == hi_after || lo >= 0x8000_0000 {
        hi_before
    } else {
        hi_after
    };
    let tick_us = (u64::from(hi) << 32) | u64::from(lo);
    let us_per_cycle_q24 = u64::from(US_PER_CYCLE_Q24.load(Ordering::Relaxed));

    for input in Input::ALL {
        let sm = input as usize;
        if flags & (1 << sm) == 0 {
            continue;
        }
        // The state machine pushes 6 cycles after it sees the acknowledgement.
        let mut spins = 0u32;
        while pio.fstat().read().rxempty() & (1 << sm) != 0 {
            spins += 1;
            if spins > 1_000 {
                break;
            }
        }
        if spins > 1_000 {
            CAPTURE_ERRORS.fetch_add(1, Ordering::Relaxed);
            continue;
        }
        let word = pio.rxf(sm).read();
        let count = u64::from(0x7FFF_FFFF - (word >> 1));
        let latency_cycles = (count * CYCLES_PER_COUNT).saturating_sub(ACK_DELAY_CYCLES);
        let latency_q24 = latency_cycles * us_per_cycle_q24;
        // Edge = tick - latency, rounded to the nearest microsecond.
        let latency_rounded_us = (latency_q24 + (1 << 23)) >> 24;
        let at_us = tick_us.saturating_sub(latency_rounded_us);
        let edge = Edge {
            input,
            level_high: word & 1 != 0,
            at_us,
        };
        if EDGES.try_send(edge).is_err() {
            EDGES_DROPPED.fetch_add(1, Ordering::Relaxed);
        }
    }
}
