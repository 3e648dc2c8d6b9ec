//! The one orchestrating task.
//!
//! It waits for whichever comes first: bytes from the host, a captured edge, the sequencer's
//! next deadline, or a USB connect/disconnect, and turns each into an input of the sequencer
//! (`skinbrdf-sequencer`, which makes every decision); after each input it drives the pins to
//! the sequencer's output levels and queues its messages as frames for the host. It also feeds
//! the hardware watchdog and drives the status LED (lit while a session runs, otherwise a
//! flash of one housekeeping period, ~100 ms, once a second).

use embassy_futures::select::{select4, Either4};
use embassy_rp::peripherals::FLASH;
use embassy_rp::watchdog::Watchdog;
use embassy_rp::Peri;
use embassy_time::{Duration, Instant, Timer};

use portable_atomic::Ordering;
use skinbrdf_protocol::{DeviceKind, FrameDecoder, Request, MAX_FRAME_LEN};
use skinbrdf_sequencer::{Config, Input as SeqInput, Sequencer};

use crate::capture::{self, Capture, Edge, Input};
use crate::outputs::{Line, Outputs};
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
            let mut flash = embassy_rp::flash::Flash::<
                _,
                embassy_rp::flash::Blocking,
                { 2 * 1024 * 1024 },
            >::new_blocking(flash);
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
    (if nibble < 10 {
        b'0' + nibble
    } else {
        b'a' + nibble - 10
    }) as char
}

/// Everything the controller owns.
pub struct Hardware {
    /// Shutter, focus, flash trigger and LED.
    pub outputs: Outputs,
    /// Keeps the edge capture running (never read: owning it is the point).
    pub _capture: Capture,
    /// Hardware watchdog (started by the controller).
    pub watchdog: Watchdog,
    /// Serial and emulator flag.
    pub identity: Identity,
}

/// The orchestrating task: feeds the sequencer, applies its outputs, sends its messages.
#[embassy_executor::task]
pub async fn run(mut hw: Hardware) -> ! {
    hw.watchdog.start(WATCHDOG_TIMEOUT);
    let kind = if hw.identity.emulated {
        DeviceKind::Emulator
    } else {
        DeviceKind::Board
    };
    let now = now_us();
    let mut seq: Sequencer<RING> = Sequencer::new(
        Config::new(env!("CARGO_PKG_VERSION"), hw.identity.serial.as_str(), kind),
        now,
    );
    let mut levels = capture::levels();
    let ready = pins::FLASH_READY.asserted(levels[Input::FlashReady as usize]);
    seq.handle(now, SeqInput::FlashReady { at_us: now, ready });
    defmt::info!(
        "controller: serial {}, {}, flash ready {}",
        hw.identity.serial.as_str(),
        if hw.identity.emulated {
            "emulated"
        } else {
            "board"
        },
        ready
    );

    let mut decoder: FrameDecoder<MAX_FRAME_LEN> = FrameDecoder::new();
    let mut rx = [0u8; usb::PACKET];
    let mut frame = [0u8; MAX_FRAME_LEN];
    let mut next_housekeeping = Instant::now() + HOUSEKEEPING_PERIOD;
    let mut heartbeat = false;
    let mut reported_drops = 0u32;
    loop {
        // Outputs and messages after every input.
        apply(&seq, &mut hw.outputs, heartbeat);
        let backlog = flush(&mut seq, &mut frame);

        // Wake for the sequencer's next deadline, housekeeping, or a message backlog.
        let mut wake = next_housekeeping;
        if let Some(deadline_us) = seq.next_deadline() {
            wake = wake.min(Instant::from_micros(deadline_us));
        }
        if backlog {
            wake = wake.min(Instant::now() + TX_RETRY);
        }
        let event = select4(
            usb::RX.read(&mut rx),
            capture::EDGES.receive(),
            Timer::at(wake),
            usb::LINK.wait(),
        )
        .await;
        match event {
            Either4::First(n) => {
                let now = now_us();
                for &byte in &rx[..n] {
                    match decoder.push_byte::<Request>(byte) {
                        Some(Ok(request)) => seq.handle(now, SeqInput::Request(request)),
                        Some(Err(err)) => seq.handle(now, SeqInput::BadFrame(err)),
                        None => {}
                    }
                    // A request can change the outputs (Abort): apply at once.
                    apply(&seq, &mut hw.outputs, heartbeat);
                }
            }
            Either4::Second(first) => {
                // Hand over every queued edge, oldest first, then tick.
                let now = now_us();
                let mut next = Some(first);
                while let Some(edge) = next {
                    if let Some(input) = to_input(&mut levels, edge) {
                        seq.handle(now, input);
                        apply(&seq, &mut hw.outputs, heartbeat);
                    }
                    next = capture::EDGES.try_receive().ok();
                }
                seq.tick(now);
            }
            Either4::Third(()) => {
                seq.tick(now_us());
                if Instant::now() >= next_housekeeping {
                    hw.watchdog.feed(WATCHDOG_TIMEOUT);
                    heartbeat = heartbeat_phase(Instant::now());
                    next_housekeeping += HOUSEKEEPING_PERIOD;
                    let now = Instant::now();
                    if next_housekeeping < now {
                        next_housekeeping = now + HOUSEKEEPING_PERIOD;
                    }
                    let drops = capture::EDGES_DROPPED.load(Ordering::Relaxed)
                        + capture::CAPTURE_ERRORS.load(Ordering::Relaxed);
                    if drops != reported_drops {
                        reported_drops = drops;
                        defmt::warn!("edge capture: {} edges lost", drops);
                    }
                }
            }
            Either4::Fourth(up) => {
                let now = now_us();
                decoder.reset();
                if up {
                    seq.handle(now, SeqInput::LinkUp);
                    // A lone delimiter makes the host's decoder drop any partial frame.
                    let _ = usb::TX.try_write(&[0]);
                } else {
                    seq.handle(now, SeqInput::LinkDown);
                }
                defmt::info!("link {}", if up { "up" } else { "down" });
            }
        }
    }
}

/// Records held until acknowledged (~100 bytes each).
const RING: usize = skinbrdf_sequencer::DEFAULT_RING;
/// Retry sending queued messages this soon when the USB pipe was full.
const TX_RETRY: Duration = Duration::from_millis(2);

fn now_us() -> u64 {
    Instant::now().as_micros()
}

/// Heartbeat phase: lit during the first housekeeping period (~100 ms) of every second.
fn heartbeat_phase(now: Instant) -> bool {
    now.as_millis() % 1000 < HOUSEKEEPING_PERIOD.as_millis()
}

/// Drives every pin to the sequencer's levels (the authoritative state, so applying is
/// idempotent). The LED shows the session (lit while running) or the idle heartbeat.
fn apply<const N: usize>(seq: &Sequencer<N>, outputs: &mut Outputs, heartbeat: bool) {
    let levels = seq.outputs();
    outputs.set(Line::Shutter, levels.shutter);
    outputs.set(Line::Focus, levels.focus);
    outputs.set(Line::FlashTrigger, levels.flash_trigger);
    outputs.led(levels.status_led || heartbeat);
}

/// Encodes and queues the sequencer's messages while the USB pipe has room for a full frame.
/// Returns true if messages are left (the pipe was full).
fn flush<const N: usize>(seq: &mut Sequencer<N>, frame: &mut [u8; MAX_FRAME_LEN]) -> bool {
    while seq.has_message() {
        if usb::TX.free_capacity() < MAX_FRAME_LEN {
            return true;
        }
        let Some(msg) = seq.pop_message() else {
            break;
        };
        match skinbrdf_protocol::encode(&msg, frame) {
            Ok(bytes) => {
                // `try_write` stops at the end of the ring buffer: write in up to two pieces.
                // It fits: the free capacity was checked above.
                let mut rest: &[u8] = bytes;
                while !rest.is_empty() {
                    match usb::TX.try_write(rest) {
                        Ok(n) => rest = &rest[n..],
                        Err(_) => break,
                    }
                }
            }
            Err(_) => defmt::error!("message does not fit a frame (protocol limits violated)"),
        }
    }
    false
}

/// Turns a level report into a sequencer input: asserted X-sync and photodiode edges, and
/// every flash-ready change. Reports that repeat the known level (start-up, or a glitch that
/// the capture merged) and released X-sync/photodiode edges yield `None`.
fn to_input(levels: &mut [bool; 3], edge: Edge) -> Option<SeqInput> {
    let slot = &mut levels[edge.input as usize];
    if *slot == edge.level_high {
        return None;
    }
    *slot = edge.level_high;
    let at_us = edge.at_us;
    match edge.input {
        Input::Xsync => pins::XSYNC
            .asserted(edge.level_high)
            .then_some(SeqInput::XsyncEdge { at_us }),
        Input::Photodiode => pins::PHOTODIODE
            .asserted(edge.level_high)
            .then_some(SeqInput::PhotodiodeEdge { at_us }),
        Input::FlashReady => Some(SeqInput::FlashReady {
            at_us,
            ready: pins::FLASH_READY.asserted(edge.level_high),
        }),
    }
}
