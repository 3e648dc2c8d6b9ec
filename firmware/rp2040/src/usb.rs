//! USB CDC-ACM link to the host (embassy-usb).
//!
//! The host finds the controller by VID/PID and checks it with the protocol handshake:
//! * VID `0x1209` (pid.codes), PID `0x0001` (pid.codes test PID: fine for a lab instrument, to
//!   be replaced by an allocated PID before boards are given away);
//! * manufacturer `skinbrdf`, product `skinbrdf trigger controller`;
//! * serial `SKB-` + the 16 hex digits of the flash chip's unique ID (`SKB-EMULATOR` when the
//!   rp2040js harness runs the image, which cannot issue flash commands).
//!
//! Four tasks share the class: [`usb_task`] runs the device state machine (whose callbacks
//! report the link state in [`LINK`]), [`dtr_task`] reports the host opening and closing the
//! port (DTR) in [`LINK`] too, [`rx_task`] copies received bytes into [`RX`] for the
//! controller's frame decoder,
//! [`tx_task`] drains the controller's outgoing byte pipe into 64-byte packets (with a
//! zero-length packet after a full one, so the host's read returns at once).

use embassy_rp::peripherals::USB;
use embassy_rp::usb::Driver;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::pipe::Pipe;
use embassy_sync::signal::Signal;
use embassy_usb::class::cdc_acm::{CdcAcmClass, ControlChanged, Receiver, Sender, State};
use embassy_usb::{Builder, Config, UsbDevice};
use static_cell::StaticCell;

/// USB vendor ID (pid.codes).
pub const VID: u16 = 0x1209;
/// USB product ID (pid.codes test PID).
pub const PID: u16 = 0x0001;
/// USB manufacturer string.
pub const MANUFACTURER: &str = "skinbrdf";
/// USB product string.
pub const PRODUCT: &str = "skinbrdf trigger controller";
/// Prefix of the USB serial string.
pub const SERIAL_PREFIX: &str = "SKB-";

/// Full-speed bulk packet size.
pub const PACKET: usize = 64;

/// The USB driver type.
pub type UsbDriver = Driver<'static, USB>;

/// Bytes the controller wants sent (encoded frames). Big enough for a full-size frame plus a
/// few records; writers wait when it is full.
pub static TX: Pipe<CriticalSectionRawMutex, 2048> = Pipe::new();

/// Bytes received from the host, in USB packet sized chunks.
pub static RX: Pipe<CriticalSectionRawMutex, 512> = Pipe::new();

/// USB link state changes (true: configured by a host, false: unplugged, bus reset or
/// deconfigured), from [`LinkHandler`].
pub static LINK: Signal<CriticalSectionRawMutex, bool> = Signal::new();

/// Turns embassy-usb's device state callbacks into [`LINK`] changes.
struct LinkHandler;

impl embassy_usb::Handler for LinkHandler {
    fn enabled(&mut self, enabled: bool) {
        if !enabled {
            LINK.signal(false);
        }
    }

    fn reset(&mut self) {
        LINK.signal(false);
    }

    fn configured(&mut self, configured: bool) {
        LINK.signal(configured);
    }
}

/// Builds the device and the CDC-ACM class.
pub fn build(
    driver: UsbDriver,
    serial: &'static str,
) -> (
    UsbDevice<'static, UsbDriver>,
    CdcAcmClass<'static, UsbDriver>,
) {
    let mut config = Config::new(VID, PID);
    config.manufacturer = Some(MANUFACTURER);
    config.product = Some(PRODUCT);
    config.serial_number = Some(serial);
    config.max_power = 100;
    config.max_packet_size_0 = 64;

    static CONFIG_DESC: StaticCell<[u8; 256]> = StaticCell::new();
    static BOS_DESC: StaticCell<[u8; 256]> = StaticCell::new();
    static CONTROL_BUF: StaticCell<[u8; 64]> = StaticCell::new();
    static STATE: StaticCell<State<'static>> = StaticCell::new();

    let mut builder = Builder::new(
        driver,
        config,
        CONFIG_DESC.init([0; 256]),
        BOS_DESC.init([0; 256]),
        &mut [], // no Microsoft OS descriptors
        CONTROL_BUF.init([0; 64]),
    );
    let class = CdcAcmClass::new(&mut builder, STATE.init(State::new()), PACKET as u16);
    static HANDLER: StaticCell<LinkHandler> = StaticCell::new();
    builder.handler(HANDLER.init(LinkHandler));
    (builder.build(), class)
}

/// Runs the USB device state machine forever.
#[embassy_executor::task]
pub async fn usb_task(mut device: UsbDevice<'static, UsbDriver>) -> ! {
    device.run().await
}

/// Reports the host's DTR line as link changes: a host program that closes the port (or dies,
/// which closes it) drops DTR, and the sequencer pauses the session as for an unplugged cable;
/// opening the port raises DTR again (link up: the host handshakes). Only changes are
/// reported, so a host that never raises DTR still talks (configuration brings the link up).
#[embassy_executor::task]
pub async fn dtr_task(control: ControlChanged<'static>) -> ! {
    let mut dtr = control.dtr();
    loop {
        control.control_changed().await;
        let now = control.dtr();
        if now != dtr {
            dtr = now;
            LINK.signal(now);
        }
    }
}

/// Copies received packets into [`RX`].
#[embassy_executor::task]
pub async fn rx_task(mut rx: Receiver<'static, UsbDriver>) -> ! {
    let mut buf = [0u8; PACKET];
    loop {
        rx.wait_connection().await;
        while let Ok(n) = rx.read_packet(&mut buf).await {
            RX.write_all(&buf[..n]).await;
        }
    }
}

/// Sends [`TX`]'s bytes to the host. While no host is connected the bytes are discarded: the
/// records they carry stay in the sequencer's ring buffer and are fetched after reconnecting.
#[embassy_executor::task]
pub async fn tx_task(mut tx: Sender<'static, UsbDriver>) -> ! {
    let mut buf = [0u8; PACKET];
    loop {
        tx.wait_connection().await;
        TX.clear();
        loop {
            let n = TX.read(&mut buf).await;
            if tx.write_packet(&buf[..n]).await.is_err() {
                break;
            }
            if n == PACKET && TX.is_empty() && tx.write_packet(&[]).await.is_err() {
                break;
            }
        }
    }
}
