//! Build script of the RP2040 firmware.
//!
//! 1. Puts `memory.x` on the linker search path (cortex-m-rt's `link.x` includes it).
//! 2. Generates `pins.rs` (pin numbers, polarities, pulls and the typed pin bundle) from
//!    `hardware/pinmap.toml`, the one source of truth of the pin map.
//! 3. Checks that the two human-readable copies of the pin map, the `//!` wiring header of
//!    `src/main.rs` and the pin table of `hardware/wiring.md`, agree with `pinmap.toml`; the build
//!    fails naming the file, the signal and both GPIO numbers if they do not.
//! 4. Checks the board's net list (`hardware/netlist.toml`): each pin-map signal's net holds
//!    that signal's GPIO and no other, no pin is on two nets, every net has two pins or more,
//!    and its parts are exactly the parts of `hardware/bom.md`'s table.

use std::collections::BTreeMap;
use std::env;
use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};

use serde::Deserialize;

/// Signals the firmware needs, in the order the generated bundle lists them.
const REQUIRED: [(&str, Direction); 7] = [
    ("shutter", Direction::Output),
    ("focus", Direction::Output),
    ("flash_trigger", Direction::Output),
    ("xsync", Direction::Input),
    ("photodiode", Direction::Input),
    ("flash_ready", Direction::Input),
    ("status_led", Direction::Output),
];

/// RP2040 user GPIOs are GP0..=GP29.
const MAX_GPIO: u8 = 29;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
enum Direction {
    Input,
    Output,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
enum Level {
    High,
    Low,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
enum PullKind {
    Up,
    Down,
    None,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PinSpec {
    gpio: u8,
    direction: Direction,
    active: Level,
    pull: Option<PullKind>,
    description: String,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PinMap {
    board: String,
    pins: BTreeMap<String, PinSpec>,
}

fn fail(msg: String) -> ! {
    // A panic in a build script fails the build and prints the message.
    panic!("pin map check failed: {msg}");
}

fn load_pinmap(path: &Path) -> PinMap {
    let text = fs::read_to_string(path)
        .unwrap_or_else(|e| fail(format!("cannot read {}: {e}", path.display())));
    let map: PinMap = toml::from_str(&text)
        .unwrap_or_else(|e| fail(format!("{} is not a valid pin map: {e}", path.display())));
    validate(&map, path);
    map
}

fn validate(map: &PinMap, path: &Path) {
    let p = path.display();
    for (name, dir) in REQUIRED {
        let Some(spec) = map.pins.get(name) else {
            fail(format!("{p}: signal `{name}` is missing"));
        };
        if spec.direction != dir {
            fail(format!("{p}: signal `{name}` must be an {dir:?}"));
        }
        if spec.gpio > MAX_GPIO {
            fail(format!(
                "{p}: signal `{name}`: GPIO {} does not exist (GP0..GP29)",
                spec.gpio
            ));
        }
        match (dir, spec.pull) {
            (Direction::Input, None) => fail(format!("{p}: input `{name}` needs `pull`")),
            (Direction::Output, Some(_)) => {
                fail(format!("{p}: output `{name}` must not have `pull`"))
            }
            _ => {}
        }
    }
    for name in map.pins.keys() {
        if !REQUIRED.iter().any(|(n, _)| n == name) {
            fail(format!(
                "{p}: unknown signal `{name}` (the firmware does not drive it)"
            ));
        }
    }
    let mut seen: BTreeMap<u8, &str> = BTreeMap::new();
    for (name, spec) in &map.pins {
        if let Some(other) = seen.insert(spec.gpio, name) {
            fail(format!(
                "{p}: GPIO {} is used by both `{other}` and `{name}`",
                spec.gpio
            ));
        }
    }
}

/// Extracts `| signal | GPn | ...` rows from a Markdown table (or a `//! |` doc table).
fn table_rows(text: &str) -> BTreeMap<String, u8> {
    let mut rows = BTreeMap::new();
    for line in text.lines() {
        let line = line.trim_start_matches("//!").trim();
        if !line.starts_with('|') {
            continue;
        }
        let cells: Vec<&str> = line
            .split('|')
            .map(|c| c.trim().trim_matches('`'))
            .collect();
        // cells[0] is empty (before the first '|').
        if cells.len() < 3 {
            continue;
        }
        let name = cells[1];
        if let Some(num) = cells[2].strip_prefix("GP") {
            if let Ok(gpio) = num.parse::<u8>() {
                rows.insert(name.to_string(), gpio);
            }
        }
    }
    rows
}

fn check_copy(map: &PinMap, path: &Path) {
    let text = fs::read_to_string(path)
        .unwrap_or_else(|e| fail(format!("cannot read {}: {e}", path.display())));
    let rows = table_rows(&text);
    for (name, spec) in &map.pins {
        match rows.get(name) {
            None => fail(format!(
                "{} has no `| {name} | GP{} |` row (hardware/pinmap.toml lists it)",
                path.display(),
                spec.gpio
            )),
            Some(&gpio) if gpio != spec.gpio => fail(format!(
                "{} says `{name}` is on GP{gpio}, hardware/pinmap.toml says GP{}",
                path.display(),
                spec.gpio
            )),
            Some(_) => {}
        }
    }
    for name in rows.keys() {
        if !map.pins.contains_key(name) {
            fail(format!(
                "{} lists signal `{name}` that hardware/pinmap.toml does not have",
                path.display()
            ));
        }
    }
}

fn generate(map: &PinMap) -> String {
    let mut out = String::new();
    let w = &mut out;
    let _ = writeln!(
        w,
        "// Generated by build.rs from hardware/pinmap.toml. Do not edit."
    );
    let _ = writeln!(w, "/// The board the pin map is for.");
    let _ = writeln!(w, "pub const BOARD: &str = {:?};", map.board);
    for (name, _) in REQUIRED {
        let spec = &map.pins[name];
        let upper = name.to_uppercase();
        let pull = match spec.pull {
            Some(PullKind::Up) => "Some(Pull::Up)",
            Some(PullKind::Down) => "Some(Pull::Down)",
            Some(PullKind::None) => "Some(Pull::None)",
            None => "None",
        };
        let _ = writeln!(w, "/// `{name}`: {}.", spec.description);
        let _ = writeln!(
            w,
            "pub const {upper}: PinInfo = PinInfo {{ name: {name:?}, gpio: {}, output: {}, active_high: {}, pull: {pull} }};",
            spec.gpio,
            spec.direction == Direction::Output,
            spec.active == Level::High,
        );
    }
    let _ = writeln!(w, "/// Every pin of the map, in a fixed order.");
    let _ = write!(w, "pub const ALL: [PinInfo; {}] = [", REQUIRED.len());
    for (name, _) in REQUIRED {
        let _ = write!(w, "{}, ", name.to_uppercase());
    }
    let _ = writeln!(w, "];");
    let _ = writeln!(
        w,
        "/// The board's pins, typed, as the pin map assigns them."
    );
    let _ = writeln!(w, "pub struct BoardPins {{");
    for (name, _) in REQUIRED {
        let _ = writeln!(
            w,
            "    /// {name} (GP{}).\n    pub {name}: Peri<'static, peripherals::PIN_{}>,",
            map.pins[name].gpio, map.pins[name].gpio
        );
    }
    let _ = writeln!(w, "}}");
    let _ = writeln!(
        w,
        "/// Moves the pin-map pins out of `embassy_rp::init`'s peripherals."
    );
    let _ = writeln!(
        w,
        "macro_rules! take_board_pins {{ ($p:ident) => {{ $crate::pins::BoardPins {{"
    );
    for (name, _) in REQUIRED {
        let _ = writeln!(w, "    {name}: $p.PIN_{},", map.pins[name].gpio);
    }
    let _ = writeln!(w, "}} }} }}");
    let _ = writeln!(w, "pub(crate) use take_board_pins;");
    out
}

fn main() {
    let manifest =
        PathBuf::from(env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let out = PathBuf::from(env::var("OUT_DIR").expect("cargo sets OUT_DIR"));

    // 1. memory.x
    fs::copy(manifest.join("memory.x"), out.join("memory.x")).expect("copy memory.x to OUT_DIR");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");

    // 2. pins.rs from the pin map
    let pinmap_path = manifest.join("../../hardware/pinmap.toml");
    let map = load_pinmap(&pinmap_path);
    fs::write(out.join("pins.rs"), generate(&map)).expect("write generated pins.rs");

    // 3. the human-readable copies agree with it
    let main_rs = manifest.join("src/main.rs");
    let wiring = manifest.join("../../hardware/wiring.md");
    check_copy(&map, &main_rs);
    check_copy(&map, &wiring);

    // 4. the net list
    let netlist = manifest.join("../../hardware/netlist.toml");
    let bom = manifest.join("../../hardware/bom.md");
    check_netlist(&map, &netlist, &bom);

    for p in [&pinmap_path, &main_rs, &wiring, &netlist, &bom] {
        println!("cargo:rerun-if-changed={}", p.display());
    }
    println!("cargo:rerun-if-changed=build.rs");
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct NetList {
    nets: BTreeMap<String, Vec<String>>,
}

/// Designators in the first column of `bom.md`'s table (`U1, U2` lists several).
fn bom_refs(path: &Path) -> Vec<String> {
    let text = fs::read_to_string(path)
        .unwrap_or_else(|e| fail(format!("cannot read {}: {e}", path.display())));
    let mut refs = Vec::new();
    for line in text.lines() {
        let Some(row) = line.trim().strip_prefix('|') else {
            continue;
        };
        let first = row.split('|').next().unwrap_or("").trim();
        if first.is_empty() || first == "ref" || first.starts_with("---") {
            continue;
        }
        refs.extend(first.split(',').map(|r| r.trim().to_string()));
    }
    refs
}

fn check_netlist(map: &PinMap, netlist_path: &Path, bom_path: &Path) {
    let name = netlist_path.display();
    let text = fs::read_to_string(netlist_path)
        .unwrap_or_else(|e| fail(format!("cannot read {name}: {e}")));
    let list: NetList = toml::from_str(&text)
        .unwrap_or_else(|e| fail(format!("{name} is not a valid net list: {e}")));
    let mut seen: BTreeMap<&str, &str> = BTreeMap::new();
    let mut parts: std::collections::BTreeSet<&str> = std::collections::BTreeSet::new();
    for (net, pins) in &list.nets {
        if pins.len() < 2 {
            fail(format!(
                "{name}: net {net} has fewer than two pins: {pins:?}"
            ));
        }
        for pin in pins {
            let Some((part, _)) = pin.split_once('.') else {
                fail(format!("{name}: net {net}: {pin:?} is not REF.PIN"));
            };
            parts.insert(part);
            if let Some(other) = seen.insert(pin, net) {
                fail(format!(
                    "{name}: pin {pin} is on two nets, {other} and {net}"
                ));
            }
        }
    }
    for (signal, spec) in &map.pins {
        let gpio = format!("A1.GP{}", spec.gpio);
        let Some(pins) = list.nets.get(signal) else {
            fail(format!(
                "{name}: no net {signal} (pin-map signal on GP{})",
                spec.gpio
            ));
        };
        if !pins.contains(&gpio) {
            fail(format!(
                "{name}: net {signal} does not hold {gpio} (pinmap.toml: GP{})",
                spec.gpio
            ));
        }
        if let Some(other) = pins.iter().find(|p| p.starts_with("A1.GP") && **p != gpio) {
            fail(format!("{name}: net {signal} also holds {other}"));
        }
    }
    let bom = bom_refs(bom_path);
    for r in &bom {
        if !parts.contains(r.as_str()) {
            fail(format!(
                "{}: part {r} is on no net of {name}",
                bom_path.display()
            ));
        }
    }
    for p in &parts {
        if !bom.iter().any(|r| r == p) {
            fail(format!("{name}: part {p} is not in {}", bom_path.display()));
        }
    }
}
