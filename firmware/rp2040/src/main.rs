//! skinbrdf trigger controller: RP2040 firmware (Raspberry Pi Pico).
//!
//! A thin embassy-rp driver of the sans-IO sequencer (`skinbrdf-sequencer`): it feeds the
//! sequencer timestamped pin edges, timer expiries and decoded host requests, and applies the
//! pin actions and sends the messages the sequencer returns.
//!
//! # Wiring
//!
//! The pin map lives in `hardware/pinmap.toml`; `build.rs` generates [`pins`] from it and fails
//! the build if this table or `hardware/wiring.md` disagree. Circuits: `hardware/circuits.md`.
//!
//! | signal | GPIO | dir | active | connects to |
//! |---|---|---|---|---|
//! | shutter | GP2 | out | high | optocoupler U1 LED; its transistor closes the 2.5 mm jack tip to sleeve |
//! | focus | GP3 | out | high | optocoupler U2 LED; its transistor closes the 2.5 mm jack ring to sleeve |
//! | flash_trigger | GP4 | out | high | optocoupler U3 LED; its transistor closes the flash's PC-sync contact |
//! | xsync | GP6 | in | low | optocoupler U4 output (pull-up); the hot-shoe X contact lights its LED |
//! | photodiode | GP7 | in | low | comparator U6 output (pull-up); low while the flash is seen |
//! | flash_ready | GP8 | in | low | optocoupler U5 output (pull-up); low while the flash is ready |
//! | status_led | GP25 | out | high | the Pico's on-board LED |
//!
//! USB: the Pico's micro-USB socket (CDC-ACM, see [`usb`]). Debug probe: SWD pads (defmt logs
//! over RTT).
//!
//! # Structure
//!
//! `main` sets every output released, starts the hardware watchdog, the edge capture
//! ([`capture`], PIO + highest-priority interrupt) and the USB tasks ([`usb`]), then hands
//! everything to the one orchestrating task, [`controller::run`].
#![no_std]
#![no_main]
#![deny(unsafe_op_in_unsafe_fn)]

mod capture;
mod controller;
mod outputs;
mod pins;
mod safe;
mod usb;

use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_rp::bind_interrupts;
use embassy_rp::peripherals::{PIO0, USB};
use embassy_rp::pio::{self, Pio};
use embassy_rp::usb::Driver;
use embassy_rp::watchdog::Watchdog;
use static_cell::StaticCell;

bind_interrupts!(struct Irqs {
    USBCTRL_IRQ => embassy_rp::usb::InterruptHandler<USB>;
    PIO0_IRQ_0 => pio::InterruptHandler<PIO0>;
});

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = embassy_rp::init(Default::default());
    let pins = pins::take_board_pins!(p);

    // Outputs first: released before anything else can run.
    let mut outputs = outputs::Outputs::new(
        pins.shutter,
        pins.focus,
        pins.flash_trigger,
        pins.status_led,
    );
    outputs.led(true);
    defmt::info!(
        "skinbrdf trigger controller {} on {}",
        env!("CARGO_PKG_VERSION"),
        pins::BOARD
    );
    for pin in pins::ALL {
        defmt::info!(
            "pin {} GP{} {} active-{}",
            pin.name,
            pin.gpio,
            if pin.output { "out" } else { "in" },
            if pin.active_high { "high" } else { "low" }
        );
    }

    let watchdog = Watchdog::new(p.WATCHDOG);
    let identity = controller::Identity::detect(&watchdog, p.FLASH);

    static SERIAL: StaticCell<heapless::String<24>> = StaticCell::new();
    let serial: &'static str = SERIAL.init(identity.serial.clone()).as_str();
    let (device, class) = usb::build(Driver::new(p.USB, Irqs), serial);
    let (tx, rx, control) = class.split_with_control();
    spawner.spawn(usb::usb_task(device).expect("usb task spawned once"));
    spawner.spawn(usb::dtr_task(control).expect("dtr task spawned once"));
    spawner.spawn(usb::rx_task(rx).expect("rx task spawned once"));
    spawner.spawn(usb::tx_task(tx).expect("tx task spawned once"));

    let capture = capture::Capture::start(
        Pio::new(p.PIO0, Irqs),
        pins.xsync,
        pins.photodiode,
        pins.flash_ready,
    );
    spawner.spawn(
        controller::run(controller::Hardware {
            outputs,
            _capture: capture,
            watchdog,
            identity,
        })
        .expect("controller task spawned once"),
    );
}
