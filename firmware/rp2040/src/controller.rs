//! The one orchestrating task.
//!
//! It waits for whichever comes first: bytes from the host, a captured edge, or the next
//! deadline, and turns each into an input of the sequencer; the sequencer's outputs become pin
//! levels and frames for the host. It also feeds the hardware watchdog and drives the status LED.

use embassy_futures::select::{select3, Either3};
use embassy_rp::peripherals::FLASH;
use embassy_rp::watchdog::Watchdog;
use embassy_rp::Peri;
use embassy_time::{Duration, Instant, Timer};

use crate::capture::{self, Capture, Edge, Input};
use crate::outputs::Outputs;
use crate::pins;
use crate::usb;

/// Value the emulator harness writes to watchdog scratch register 0 before boot. On a board the
/// register is 0 after power-on (the bootrom only uses scratch 4..7).
pub const EMULATOR_MAGIC: u32 = 0x454D_5521; // "EMU!"

/// Hardware watchdog timeout: a hang longer than this resets the chip (outputs released).
const WATCHDOG_TIMEOUT: Duration = Duration::from_millis(500);
/// The controller wakes at least this often to feed the watchdog.
const HOUSEKEEPING_PERIOD: Duration = Duration::from_millis(100);

/// Who this device is.
pub struct Identity {
    /// USB serial string and handshake serial.
    pub serial: heapless::String<24>,
    /// True when running in the rp2040js emulator harness.
    pub emulated: bool,
}

impl Identity {
    /// Board: serial from the flash's unique ID. Emulator (magic in watchdog scratch 0): a fixed
    /// serial, because the emulator cannot run the flash commands that read the ID.
    pub fn detect(watchdog: &Watchdog, flash: Peri<'static, FLASH>) -> Self {
        let mut serial = heapless::String::new();
        let _ = serial.push_str(usb::SERIAL_PREFIX);
        let emulated = scratch0(watchdog) == EMULATOR_MAGIC;
        if emulated {
            let _ = serial.push_str("EMULATOR");
        } else {
            let mut flash =
                embassy_rp::flash::Flash::<_, embassy_rp::flash::Blocking, { 2 * 1024 * 1024 }>::new_blocking(flash);
            let mut uid = [0u8; 8];
            if flash.blocking_unique_id(&mut uid).is_ok() {
                for b in uid {
                    let _ = serial.push(hex(b >> 4));
                    let _ = serial.push(hex(b & 0xf));
                }
            } else {
                let _ = serial.push_str("UNKNOWN");
            }
        }
        Self { serial, emulated }
    }
}

fn scratch0(_watchdog: &Watchdog) -> u32 {
    embassy_rp::pac::WATCHDOG.scratch0().read()
}

const fn hex(nibble: u8) -> char {
    (if nibble < 10 { b'0' + nibble } else { b'a' + nibble - 10 }) as char
}

/// Everything the controller owns.
pub struct Hardware {
    /// Shutter, focus, flash trigger and LED.
    pub outputs: Outputs,
    /// Keeps the edge capture running.
    pub capture: Capture,
    /// Hardware watchdog (started by the controller).
    pub watchdog: Watchdog,
    /// Serial and emulator flag.
    pub identity: Identity,
}

/// The orchestrating task.
#[embassy_executor::task]
pub async fn run(mut hw: Hardware) -> ! {
    hw.watchdog.start(WATCHDOG_TIMEOUT);
    let mut levels = capture::levels();
    defmt::info!(
        "controller: serial {}, emulated {}, inputs xsync={} photodiode={} flash_ready={}",
        hw.identity.serial.as_str(),
        hw.identity.emulated,
        levels[0],
        levels[1],
        levels[2]
    );
    let mut rx = [0u8; usb::PACKET];
    let mut next_housekeeping = Instant::now() + HOUSEKEEPING_PERIOD;
    let mut led = true;
    loop {
        match select3(
            usb::RX.read(&mut rx),
            capture::EDGES.receive(),
            Timer::at(next_housekeeping),
        )
        .await
        {
            Either3::First(n) => {
                // Echo (replaced by the sequencer).
                let _ = usb::TX.try_write(&rx[..n]);
            }
            Either3::Second(edge) => {
                if let Some(asserted) = take_edge(&mut levels, edge) {
                    defmt::debug!("edge {} asserted={} at {} us", edge.input, asserted, edge.at_us);
                    let mut line: heapless::String<64> = heapless::String::new();
                    let _ = core::fmt::write(
                        &mut line,
                        format_args!("EDGE {} {} {}\n", edge.input as u8, asserted, edge.at_us),
                    );
                    let _ = usb::TX.try_write(line.as_bytes());
                }
            }
            Either3::Third(()) => {
                hw.watchdog.feed(WATCHDOG_TIMEOUT);
                led = !led;
                hw.outputs.led(led);
                next_housekeeping += HOUSEKEEPING_PERIOD;
                let now = Instant::now();
                if next_housekeeping < now {
                    next_housekeeping = now + HOUSEKEEPING_PERIOD;
                }
            }
        }
    }
}

/// Turns a level report into an edge: `Some(asserted)` if the level changed, `None` if it
/// repeats the known level (start-up report, or a glitch shorter than the handler latency).
fn take_edge(levels: &mut [bool; 3], edge: Edge) -> Option<bool> {
    let slot = &mut levels[edge.input as usize];
    if *slot == edge.level_high {
        return None;
    }
    *slot = edge.level_high;
    let info = match edge.input {
        Input::Xsync => pins::XSYNC,
        Input::Photodiode => pins::PHOTODIODE,
        Input::FlashReady => pins::FLASH_READY,
    };
    Some(info.asserted(edge.level_high))
}
