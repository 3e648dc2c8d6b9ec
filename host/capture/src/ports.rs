//! Listing serial ports and recognising our trigger controllers by USB identity.
//!
//! A port is a *candidate* controller when its USB vendor/product IDs match
//! [`CONTROLLER_USB_ID`]; `skinbrdf ports` then confirms candidates with a handshake (a board with
//! our VID/PID but other firmware would fail it). On Linux the listing reads sysfs (no libudev
//! needed); pseudo-terminals (the simulator) are not listed, only ever named with `--port`.

use serialport::{SerialPortInfo, SerialPortType};

/// USB vendor and product ID of the controller firmware.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UsbId {
    /// Vendor ID.
    pub vid: u16,
    /// Product ID.
    pub pid: u16,
}

/// The controller's USB identity as the RP2040 firmware announces it (`firmware/rp2040/src/usb.rs`:
/// pid.codes VID with its test PID; a test checks the two agree).
pub const CONTROLLER_USB_ID: UsbId = UsbId {
    vid: 0x1209,
    pid: 0x0001,
};

/// Prefix of the controller's USB serial string (`SKB-` + the flash chip's unique ID).
pub const CONTROLLER_SERIAL_PREFIX: &str = "SKB-";

/// The controller's USB product string.
pub const CONTROLLER_PRODUCT: &str = "skinbrdf trigger controller";

/// One serial port as seen on this machine.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PortListing {
    /// Device path (`/dev/ttyACM0`, `COM3`).
    pub path: String,
    /// USB identity, if it is a USB port.
    pub usb: Option<UsbId>,
    /// USB serial string, if any.
    pub serial_number: Option<String>,
    /// USB manufacturer string, if any.
    pub manufacturer: Option<String>,
    /// USB product string, if any.
    pub product: Option<String>,
    /// True when the USB identity matches our controller.
    pub is_candidate: bool,
}

/// Why ports could not be listed.
#[derive(Debug, thiserror::Error)]
#[error("cannot list serial ports: {message}")]
pub struct ListPortsError {
    /// The OS's message.
    pub message: String,
}

/// Lists the machine's serial ports, sorted by path, marking controller candidates.
pub fn list_ports() -> Result<Vec<PortListing>, ListPortsError> {
    let ports = serialport::available_ports().map_err(|e| ListPortsError {
        message: e.description,
    })?;
    let mut out: Vec<PortListing> = ports.into_iter().map(classify).collect();
    out.sort_by(|a, b| a.path.cmp(&b.path));
    Ok(out)
}

/// Turns serialport's description into a [`PortListing`].
pub fn classify(info: SerialPortInfo) -> PortListing {
    match info.port_type {
        SerialPortType::UsbPort(usb) => {
            let id = UsbId {
                vid: usb.vid,
                pid: usb.pid,
            };
            PortListing {
                path: info.port_name,
                is_candidate: is_controller_id(id),
                usb: Some(id),
                serial_number: usb.serial_number,
                manufacturer: usb.manufacturer,
                product: usb.product,
            }
        }
        _ => PortListing {
            path: info.port_name,
            usb: None,
            serial_number: None,
            manufacturer: None,
            product: None,
            is_candidate: false,
        },
    }
}

/// True for our controller's VID/PID.
pub fn is_controller_id(id: UsbId) -> bool {
    id == CONTROLLER_USB_ID
}

#[cfg(test)]
mod tests {
    use super::*;
    use serialport::UsbPortInfo;

    fn usb(vid: u16, pid: u16) -> SerialPortInfo {
        SerialPortInfo {
            port_name: "/dev/ttyACM0".into(),
            port_type: SerialPortType::UsbPort(UsbPortInfo {
                vid,
                pid,
                serial_number: Some("SKB-0001".into()),
                manufacturer: None,
                product: None,
            }),
        }
    }

    #[test]
    fn matches_controller_ids_only() {
        let ours = classify(usb(CONTROLLER_USB_ID.vid, CONTROLLER_USB_ID.pid));
        assert!(ours.is_candidate);
        assert_eq!(ours.serial_number.as_deref(), Some("SKB-0001"));
        let other = classify(usb(0x0403, 0x6001));
        assert!(!other.is_candidate);
        let pci = classify(SerialPortInfo {
            port_name: "/dev/ttyS0".into(),
            port_type: SerialPortType::PciPort,
        });
        assert!(!pci.is_candidate && pci.usb.is_none());
    }

    #[test]
    fn agrees_with_the_firmware_descriptor() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../firmware/rp2040/src/usb.rs");
        let Ok(src) = std::fs::read_to_string(&path) else {
            eprintln!("skipped: {} not present", path.display());
            return;
        };
        let vid = format!("pub const VID: u16 = {:#06x};", CONTROLLER_USB_ID.vid);
        let pid = format!("pub const PID: u16 = {:#06x};", CONTROLLER_USB_ID.pid);
        let product = format!("pub const PRODUCT: &str = {CONTROLLER_PRODUCT:?};");
        for needle in [vid, pid, product] {
            assert!(src.contains(&needle), "{} lacks `{needle}`", path.display());
        }
        assert!(
            src.contains(&format!("{CONTROLLER_SERIAL_PREFIX:?}")),
            "serial prefix differs"
        );
    }

    #[test]
    fn listing_does_not_fail_here() {
        // Machines without serial hardware list nothing, but the call must succeed.
        list_ports().expect("list ports");
    }
}
