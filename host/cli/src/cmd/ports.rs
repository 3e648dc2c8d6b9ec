//! `skinbrdf ports`: list serial ports and mark our trigger controllers.

use std::time::Duration;

use skinbrdf_capture::client::identity;
use skinbrdf_capture::{list_ports, Client, SerialTransport};

/// Flags of `skinbrdf ports`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Handshake with every listed port, not only those with our USB VID/PID.
    #[arg(long)]
    all: bool,
    /// Extra ports to probe (pseudo-terminals such as the simulator's are not listed).
    #[arg(long = "probe", value_name = "PATH")]
    probe: Vec<String>,
    /// Handshake timeout, milliseconds.
    #[arg(long, default_value_t = 500)]
    timeout_ms: u64,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let ports = list_ports()?;
    let timeout = Duration::from_millis(args.timeout_ms);
    if ports.is_empty() && args.probe.is_empty() {
        println!("no serial ports found (a simulator's pty can be checked with --probe PATH)");
        return Ok(());
    }
    let mut found = 0;
    for p in &ports {
        let usb = p.usb.map_or_else(
            || "-        ".to_string(),
            |u| format!("{:04x}:{:04x}", u.vid, u.pid),
        );
        let what = [
            p.manufacturer.as_deref(),
            p.product.as_deref(),
            p.serial_number.as_deref(),
        ]
        .into_iter()
        .flatten()
        .collect::<Vec<_>>()
        .join(" / ");
        let status = if p.is_candidate || args.all {
            let s = probe(&p.path, timeout);
            if s.starts_with("controller") {
                found += 1;
            }
            s
        } else {
            String::new()
        };
        let mark = if p.is_candidate { "*" } else { " " };
        println!("{mark} {:<20} {usb}  {what:<40} {status}", p.path);
    }
    for path in &args.probe {
        let s = probe(path, timeout);
        if s.starts_with("controller") {
            found += 1;
        }
        println!("  {path:<20} {:<9}  {:<40} {s}", "(probe)", "");
    }
    println!("{found} skinbrdf controller(s) answered (* = our USB VID/PID)");
    Ok(())
}

/// Handshakes with `path` and describes the outcome in one line.
fn probe(path: &str, timeout: Duration) -> String {
    let transport = match SerialTransport::open(path) {
        Ok(t) => t,
        Err(e) => return format!("cannot open: {e}"),
    };
    match Client::connect(transport, timeout) {
        Ok(c) => match c.info() {
            Some(info) => {
                let id = identity(info);
                format!(
                    "controller: {} firmware {} serial {} protocol {}",
                    id.kind, id.firmware_version, id.serial, id.protocol_version
                )
            }
            None => "controller (no identity)".into(),
        },
        Err(e) => format!("no: {e}"),
    }
}
