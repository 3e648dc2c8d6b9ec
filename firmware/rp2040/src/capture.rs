//! Edge timestamps for the three inputs (X-sync, photodiode, flash ready).
//!
//! Each input is watched by its own PIO0 state machine running the same 6-instruction program:
//! wait for the line to go high, push `0xFFFF_FFFF`; wait for it to go low, push `0`. The RX
//! FIFO becoming non-empty raises `PIO0_IRQ_1` (embassy's PIO driver only uses `PIO0_IRQ_0`),
//! whose handler runs at the highest NVIC priority and reads the 64-bit 1 MHz system timer
//! *first*, then drains the FIFOs into [`EDGES`]. Nothing polls in a task.
//!
//! Timing (125 MHz system clock, see `docs/firmware.md`):
//! * the PIO sees the pin 2 cycles after it changes (input synchroniser) and pushes 2 cycles
//!   later: 32 ns;
//! * exception entry is 16 cycles on the Cortex-M0+ and the handler's timer read ~10 more:
//!   ~0.2 us in total, added to the 1 us quantisation of the timer (the value read is the floor
//!   of the true time in microseconds);
//! * the only extra delay is a critical section (interrupts masked) running when the edge comes;
//!   embassy's are a few microseconds at most. Edges that arrive while the handler is pending
//!   share its timestamp; the FIFO (8 deep per input with the join) loses none.
//!
//! The reported level is the raw pin level; [`crate::pins::PinInfo::active_high`] maps it to
//! "asserted". A report equal to the last known level (e.g. the first one after start-up, or
//! a glitch shorter than the handler latency) carries no edge and is dropped by the driver.

use portable_atomic::{AtomicU32, Ordering};

use embassy_rp::interrupt::{self as irq, InterruptExt, Priority};
use embassy_rp::pac::interrupt;
use embassy_rp::pac;
use embassy_rp::peripherals::PIO0;
use embassy_rp::pio::{
    Common, Config, Direction, FifoJoin, LoadedProgram, Pio, PioPin, StateMachine,
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
    /// System timer (microseconds since boot) read at the start of the interrupt handler.
    pub at_us: u64,
}

/// Captured edges, oldest first. Big enough for a burst of bounces on all three inputs.
pub static EDGES: Channel<CriticalSectionRawMutex, Edge, 32> = Channel::new();

/// Edges lost because [`EDGES`] was full (reported in logs; should stay 0).
pub static EDGES_DROPPED: AtomicU32 = AtomicU32::new(0);

/// Mask of the state machines in use (SM0..SM2).
const SM_MASK: u8 = 0b0111;

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
    cfg.fifo_join = FifoJoin::RxOnly;
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
        let prg = pio::pio_asm!(
            ".wrap_target",
            "wait 1 pin 0",
            "mov isr, ~null",
            "push noblock",
            "wait 0 pin 0",
            "mov isr, null",
            "push noblock",
            ".wrap",
        );
        let program = common.load_program(&prg.program);
        configure(&mut common, &mut sm0, &program, xsync, crate::pins::XSYNC);
        configure(&mut common, &mut sm1, &program, photodiode, crate::pins::PHOTODIODE);
        configure(&mut common, &mut sm2, &program, flash_ready, crate::pins::FLASH_READY);

        // Route "RX FIFO not empty" of SM0..SM2 to PIO0's second interrupt line.
        pac::PIO0.irqs(1).inte().write(|w| {
            w.set_sm0_rxnempty(true);
            w.set_sm1_rxnempty(true);
            w.set_sm2_rxnempty(true);
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
    // Read the clock before anything else: this is the timestamp of every edge drained here.
    let at_us = embassy_time::Instant::now().as_micros();
    let pio = pac::PIO0;
    loop {
        let nonempty = !pio.fstat().read().rxempty() & SM_MASK;
        if nonempty == 0 {
            break;
        }
        for input in Input::ALL {
            let sm = input as usize;
            if nonempty & (1 << sm) != 0 {
                let word = pio.rxf(sm).read();
                let edge = Edge {
                    input,
                    level_high: word != 0,
                    at_us,
                };
                if EDGES.try_send(edge).is_err() {
                    EDGES_DROPPED.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    }
}
