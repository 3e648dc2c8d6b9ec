//! The four outputs and their safe (released) state.
//!
//! Released means "optocoupler LED off": the camera's shutter and focus contacts and the flash
//! sync contact are open. Every path that stops normal operation releases them: boot (the pins
//! are configured released before anything else runs), an abort, a fault (the sequencer says
//! so), a panic and a hard fault ([`release_all_raw`] writes SIO directly, without the HAL),
//! and a hang (the hardware watchdog resets the chip, which turns every GPIO back into a
//! high-impedance input; the external pull-downs on the optocoupler drivers keep them off).

use embassy_rp::gpio::{Drive, Level, Output, Pin};
use embassy_rp::pac;
use embassy_rp::Peri;

use crate::pins::{self, PinInfo};

/// A line the sequencer can drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum Line {
    /// Camera shutter (remote-jack tip).
    Shutter,
    /// Camera focus (remote-jack ring).
    Focus,
    /// Flash sync output.
    FlashTrigger,
}

/// The driven outputs; created released.
pub struct Outputs {
    shutter: Output<'static>,
    focus: Output<'static>,
    flash_trigger: Output<'static>,
    led: Output<'static>,
}

const fn released(info: PinInfo) -> Level {
    if info.active_high {
        Level::Low
    } else {
        Level::High
    }
}

const fn level(info: PinInfo, asserted: bool) -> Level {
    if asserted == info.active_high {
        Level::High
    } else {
        Level::Low
    }
}

impl Outputs {
    /// Takes the output pins of the pin map and drives them released (and the LED off).
    pub fn new(
        shutter: Peri<'static, impl Pin>,
        focus: Peri<'static, impl Pin>,
        flash_trigger: Peri<'static, impl Pin>,
        status_led: Peri<'static, impl Pin>,
    ) -> Self {
        let mut shutter = Output::new(shutter, released(pins::SHUTTER));
        let mut focus = Output::new(focus, released(pins::FOCUS));
        // The shutter and focus pins drive optocoupler LEDs directly (up to ~5 mA through
        // 470 R, `hardware/circuits.md`): more than the pads' default 4 mA class, so the
        // 8 mA class. The flash trigger drives only a MOSFET gate.
        shutter.set_drive_strength(Drive::_8mA);
        focus.set_drive_strength(Drive::_8mA);
        Self {
            shutter,
            focus,
            flash_trigger: Output::new(flash_trigger, released(pins::FLASH_TRIGGER)),
            led: Output::new(status_led, released(pins::STATUS_LED)),
        }
    }

    /// Asserts or releases one line.
    pub fn set(&mut self, line: Line, asserted: bool) {
        match line {
            Line::Shutter => self.shutter.set_level(level(pins::SHUTTER, asserted)),
            Line::Focus => self.focus.set_level(level(pins::FOCUS, asserted)),
            Line::FlashTrigger => self
                .flash_trigger
                .set_level(level(pins::FLASH_TRIGGER, asserted)),
        }
    }

    /// Status LED on or off.
    pub fn led(&mut self, on: bool) {
        self.led.set_level(level(pins::STATUS_LED, on));
    }
}

/// Drives every output of the pin map to its released level by writing SIO directly.
///
/// For the panic and hard-fault paths: no HAL object, no lock, no allocation; safe to call with
/// interrupts masked and from any state. Pins not yet switched to SIO are unaffected (they are
/// still inputs, i.e. released).
pub fn release_all_raw() {
    let mut set_mask = 0u32;
    let mut clr_mask = 0u32;
    for info in pins::ALL {
        if info.output {
            if info.active_high {
                clr_mask |= 1 << info.gpio;
            } else {
                set_mask |= 1 << info.gpio;
            }
        }
    }
    pac::SIO.gpio_out(0).value_clr().write_value(clr_mask);
    pac::SIO.gpio_out(0).value_set().write_value(set_mask);
}
