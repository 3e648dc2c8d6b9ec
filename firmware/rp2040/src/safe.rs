//! Panic and hard-fault handling: release every output first, then report.
//!
//! The panic handler does what `panic-probe` (with `print-defmt`) does, with one step before it:
//! mask interrupts, **release the shutter, focus and flash lines** ([`release_all_raw`]), log the
//! message over defmt-RTT, then `udf` into the HardFault handler (which `probe-rs run` reports
//! with a backtrace). `panic-probe` itself cannot be used: it offers no hook to run before its
//! `udf`, and `probe-rs` halts the core on the HardFault vector catch, so a line held at the
//! moment of the panic would stay held on the bench.
//!
//! The HardFault handler (reached by that `udf`, or by a real fault) releases the lines again and
//! resets the chip by forcing a watchdog reset (`WATCHDOG.CTRL.TRIGGER`, which resets the
//! peripherals and the GPIOs as a watchdog timeout does; the core's `SYSRESETREQ` would reset
//! only the processors). After reset every GPIO is a released input until the firmware drives
//! them released again in `main`.

use core::panic::PanicInfo;
use core::sync::atomic::{AtomicBool, Ordering};

use cortex_m_rt::{exception, ExceptionFrame};

use crate::outputs::release_all_raw;

#[panic_handler]
fn panic(info: &PanicInfo<'_>) -> ! {
    static PANICKED: AtomicBool = AtomicBool::new(false);
    cortex_m::interrupt::disable();
    release_all_raw();
    // Guard against a panic inside the logger.
    if !PANICKED.load(Ordering::Relaxed) {
        PANICKED.store(true, Ordering::Relaxed);
        defmt::error!("panic: {}", defmt::Display2Format(info));
    }
    cortex_m::asm::udf()
}

#[exception]
unsafe fn HardFault(_frame: &ExceptionFrame) -> ! {
    release_all_raw();
    // A clean restart is the safe state: the host sees the device re-enumerate and re-handshakes.
    // What the watchdog resets: everything but the oscillators (as `Watchdog::start` sets it;
    // repeated here because a fault may come before the controller started the watchdog).
    embassy_rp::pac::PSM
        .wdsel()
        .write_value(embassy_rp::pac::psm::regs::Wdsel(0x0001_fffc));
    embassy_rp::pac::WATCHDOG
        .ctrl()
        .write(|w| w.set_trigger(true));
    // The reset takes a few cycles; should it not come, the core's own reset still does.
    cortex_m::peripheral::SCB::sys_reset()
}
