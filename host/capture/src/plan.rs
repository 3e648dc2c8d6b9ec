//! `plan.toml`: loading and validating a capture plan.
//!
//! A plan is a list of shot groups ([`CapturePlan`], defined in `skinbrdf-session`). Loading is
//! strict: unknown keys are errors (a typo such as `min_interval_ms` must not silently fall back
//! to a default), TOML syntax and type errors keep the parser's line and column, and every
//! semantic problem names the group (index and label), the field and what is wrong with it.
//!
//! Validation rejects plans the controller could not honour (zero counts, zero pulse widths or
//! timeouts, an interval shorter than focus + shutter pulse) and values that are almost certainly
//! a unit slip (any duration above [`MAX_DURATION_US`]).

use std::path::{Path, PathBuf};

use skinbrdf_protocol::MIN_SHUTTER_OFF_US;
use skinbrdf_session::capture::{CapturePlan, ShotGroup};

/// Longest duration accepted for any plan field: one hour. Every real interval or timeout is
/// seconds at most, so anything longer is a unit slip (seconds or milliseconds typed as us*1e6).
pub const MAX_DURATION_US: u64 = 3_600_000_000;

/// Most shots one group may hold; the method needs ~30, so this only catches typos.
pub const MAX_GROUP_COUNT: u32 = 10_000;

/// Most retries per shot; more would hide a broken camera or flash behind endless retries.
pub const MAX_RETRIES: u32 = 100;

const TOP_LEVEL_KEYS: &[&str] = &["groups", "max_retries"];
const GROUP_KEYS: &[&str] = &[
    "label",
    "role",
    "count",
    "min_interval_us",
    "pre_focus_us",
    "shutter_pulse_us",
    "xsync_timeout_us",
    "flash_ready_timeout_us",
    "flash_mode",
];

/// Why a plan could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// The file could not be read.
    #[error("{path}: cannot read the plan")]
    Read {
        /// The plan file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// TOML syntax or a type error (the message carries line and column).
    #[error("{path}: {message}")]
    Parse {
        /// The plan file.
        path: PathBuf,
        /// The parser's message.
        message: String,
    },
    /// A key the plan format does not know.
    #[error("{path}: unknown key `{key}` in {location} (known keys: {known})")]
    UnknownKey {
        /// The plan file.
        path: PathBuf,
        /// Where it was found (`the top level` or `groups[2] ("measurement")`).
        location: String,
        /// The unknown key.
        key: String,
        /// The keys that are allowed there.
        known: String,
    },
    /// The plan parsed but cannot be run.
    #[error("{path}: {location}: {problem}")]
    Invalid {
        /// The plan file.
        path: PathBuf,
        /// The group and field (groups[0] (`measurement`).count) or `max_retries`.
        location: String,
        /// What is wrong.
        problem: String,
    },
}

/// Reads, parses and validates a `plan.toml`.
pub fn load_plan(path: &Path) -> Result<CapturePlan, PlanError> {
    let text =
        skinbrdf_core::untrusted::read_text_io(path, skinbrdf_core::untrusted::SETTINGS_FILE)
            .map_err(|source| PlanError::Read {
                path: path.to_path_buf(),
                source,
            })?;
    parse_plan(&text, path)
}

/// Parses and validates plan text; `origin` names the source in errors.
pub fn parse_plan(text: &str, origin: &Path) -> Result<CapturePlan, PlanError> {
    let table: toml::Table = toml::from_str(text).map_err(|e| PlanError::Parse {
        path: origin.to_path_buf(),
        message: e.to_string().trim_end().to_string(),
    })?;
    check_keys(&table, origin)?;
    let plan: CapturePlan = toml::from_str(text).map_err(|e| PlanError::Parse {
        path: origin.to_path_buf(),
        message: e.to_string().trim_end().to_string(),
    })?;
    validate_plan(&plan, origin)?;
    Ok(plan)
}

fn group_location(index: usize, label: Option<&str>) -> String {
    match label {
        Some(l) => format!("groups[{index}] (`{l}`)"),
        None => format!("groups[{index}]"),
    }
}

fn check_keys(table: &toml::Table, origin: &Path) -> Result<(), PlanError> {
    let unknown = |location: String, key: &str, known: &[&str]| PlanError::UnknownKey {
        path: origin.to_path_buf(),
        location,
        key: key.to_string(),
        known: known.join(", "),
    };
    for key in table.keys() {
        if !TOP_LEVEL_KEYS.contains(&key.as_str()) {
            return Err(unknown("the top level".into(), key, TOP_LEVEL_KEYS));
        }
    }
    if let Some(toml::Value::Array(groups)) = table.get("groups") {
        for (i, g) in groups.iter().enumerate() {
            if let toml::Value::Table(t) = g {
                let label = t.get("label").and_then(toml::Value::as_str);
                for key in t.keys() {
                    if !GROUP_KEYS.contains(&key.as_str()) {
                        return Err(unknown(group_location(i, label), key, GROUP_KEYS));
                    }
                }
            }
        }
    }
    Ok(())
}

/// Checks that a plan can be run; errors name `origin`, the group and the field.
pub fn validate_plan(plan: &CapturePlan, origin: &Path) -> Result<(), PlanError> {
    let invalid = |location: String, problem: String| PlanError::Invalid {
        path: origin.to_path_buf(),
        location,
        problem,
    };
    if plan.groups.is_empty() {
        return Err(invalid(
            "groups".into(),
            "the plan has no shot groups (add at least one [[groups]] table)".into(),
        ));
    }
    if plan.groups.len() > skinbrdf_protocol::MAX_GROUPS {
        return Err(invalid(
            "groups".into(),
            format!(
                "{} groups exceed the controller's limit of {}",
                plan.groups.len(),
                skinbrdf_protocol::MAX_GROUPS
            ),
        ));
    }
    if plan.max_retries > MAX_RETRIES {
        return Err(invalid(
            "max_retries".into(),
            format!("{} exceeds the limit of {MAX_RETRIES}", plan.max_retries),
        ));
    }
    for (i, g) in plan.groups.iter().enumerate() {
        validate_group(i, g).map_err(|(field, problem)| {
            invalid(
                format!("{}.{field}", group_location(i, Some(&g.label))),
                problem,
            )
        })?;
    }
    // Across a group boundary the next group's interval counts from the previous group's last
    // shutter command, whose pulse may be longer.
    for (i, pair) in plan.groups.windows(2).enumerate() {
        let (prev, next) = (&pair[0], &pair[1]);
        let needed = prev.shutter_pulse_us.saturating_add(MIN_SHUTTER_OFF_US);
        if next.min_interval_us < needed {
            return Err(invalid(
                format!(
                    "{}.min_interval_us",
                    group_location(i + 1, Some(&next.label))
                ),
                format!(
                    "{} us after the last shot of {}, whose shutter pulse is {} us, leaves the \
                     shutter released for {} us before the next press; a camera needs {} us \
                     to see two presses (the controller would space them): set \
                     min_interval_us >= {needed}",
                    next.min_interval_us,
                    group_location(i, Some(&prev.label)),
                    prev.shutter_pulse_us,
                    next.min_interval_us.saturating_sub(prev.shutter_pulse_us),
                    MIN_SHUTTER_OFF_US,
                ),
            ));
        }
    }
    Ok(())
}

fn validate_group(_index: usize, g: &ShotGroup) -> Result<(), (&'static str, String)> {
    if g.label.trim().is_empty() {
        return Err(("label", "the label is empty".into()));
    }
    if g.label.len() > skinbrdf_protocol::LABEL_LEN {
        return Err((
            "label",
            format!(
                "{} bytes exceed the controller's limit of {} bytes",
                g.label.len(),
                skinbrdf_protocol::LABEL_LEN
            ),
        ));
    }
    if !g.role.fired_by_controller() {
        return Err((
            "role",
            "survey images are taken by hand before the subject sits (room light, no \
             flash), not fired by the controller: give them to `skinbrdf ingest --survey DIR`"
                .into(),
        ));
    }
    if g.count == 0 {
        return Err(("count", "a group must have at least one shot".into()));
    }
    if g.count > MAX_GROUP_COUNT {
        return Err((
            "count",
            format!("{} shots exceeds the limit of {MAX_GROUP_COUNT}", g.count),
        ));
    }
    let durations: [(&'static str, u64, bool); 5] = [
        ("min_interval_us", g.min_interval_us, false),
        ("pre_focus_us", g.pre_focus_us, false),
        ("shutter_pulse_us", g.shutter_pulse_us, true),
        ("xsync_timeout_us", g.xsync_timeout_us, true),
        ("flash_ready_timeout_us", g.flash_ready_timeout_us, true),
    ];
    for (field, value, must_be_positive) in durations {
        if must_be_positive && value == 0 {
            return Err((field, "must be greater than zero".into()));
        }
        if value > MAX_DURATION_US {
            return Err((
                field,
                format!(
                    "{value} us is longer than one hour ({MAX_DURATION_US} us): \
                     is the unit microseconds?"
                ),
            ));
        }
    }
    let needed = g.pre_focus_us.saturating_add(g.shutter_pulse_us);
    if g.count > 1 && g.min_interval_us < needed {
        return Err((
            "min_interval_us",
            format!(
                "{} us is shorter than pre_focus_us + shutter_pulse_us = {needed} us, \
                 so consecutive shots would overlap",
                g.min_interval_us
            ),
        ));
    }
    let needed = g.shutter_pulse_us.saturating_add(MIN_SHUTTER_OFF_US);
    if g.count > 1 && g.min_interval_us < needed {
        return Err((
            "min_interval_us",
            format!(
                "{} us leaves the shutter released for {} us between shots; a camera needs \
                 {} us to see two presses (the controller would space them): set \
                 min_interval_us >= shutter_pulse_us + {} = {needed}",
                g.min_interval_us,
                g.min_interval_us.saturating_sub(g.shutter_pulse_us),
                MIN_SHUTTER_OFF_US,
                MIN_SHUTTER_OFF_US,
            ),
        ));
    }
    Ok(())
}

/// Total number of planned shots (retries excluded).
pub fn planned_shots(plan: &CapturePlan) -> u64 {
    plan.groups.iter().map(|g| u64::from(g.count)).sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinbrdf_session::capture::{FlashMode, ImageRole};

    const GOOD: &str = r#"
max_retries = 1

[[groups]]
label = "measurement"
role = "measurement"
count = 30
min_interval_us = 4_000_000
pre_focus_us = 300_000
shutter_pulse_us = 100_000
xsync_timeout_us = 1_000_000
flash_ready_timeout_us = 10_000_000
flash_mode = "camera-hot-shoe"

[[groups]]
label = "reference standard"
role = "reference-standard"
count = 1
min_interval_us = 200_000
pre_focus_us = 300_000
shutter_pulse_us = 100_000
xsync_timeout_us = 1_000_000
flash_ready_timeout_us = 10_000_000
flash_mode = "controller-on-xsync"
"#;

    fn origin() -> &'static Path {
        Path::new("plan.toml")
    }

    #[test]
    fn parses_a_good_plan() {
        let plan = parse_plan(GOOD, origin()).expect("good plan");
        assert_eq!(plan.groups.len(), 2);
        assert_eq!(plan.max_retries, 1);
        assert_eq!(plan.groups[0].role, ImageRole::Measurement);
        assert_eq!(plan.groups[1].flash_mode, FlashMode::ControllerOnXsync);
        assert_eq!(planned_shots(&plan), 31);
    }

    #[test]
    fn repo_plans_load() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../plans");
        let mut n = 0;
        for entry in std::fs::read_dir(&dir).expect("plans/ exists") {
            let path = entry.expect("dir entry").path();
            if path.extension().is_some_and(|e| e == "toml") {
                load_plan(&path).unwrap_or_else(|e| panic!("{e}"));
                n += 1;
            }
        }
        assert!(n >= 1, "no plans found in {}", dir.display());
    }

    #[test]
    fn method_plan_has_the_method_shape() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../plans/method.toml");
        let plan = load_plan(&path).expect("method plan");
        let count = |role: ImageRole| -> u32 {
            plan.groups
                .iter()
                .filter(|g| g.role == role)
                .map(|g| g.count)
                .sum()
        };
        assert!((25..=40).contains(&count(ImageRole::Measurement)));
        assert_eq!(count(ImageRole::LightPosition), 3);
        assert_eq!(count(ImageRole::ReferenceStandard), 1);
        assert_eq!(count(ImageRole::StandardPosition), 2);
    }

    #[test]
    fn unknown_key_is_named() {
        let text = GOOD.replace("min_interval_us = 4_000_000", "min_interval_ms = 4000");
        let err = parse_plan(&text, origin()).expect_err("typo must fail");
        let msg = err.to_string();
        assert!(matches!(err, PlanError::UnknownKey { .. }), "{msg}");
        assert!(msg.contains("min_interval_ms"), "{msg}");
        assert!(msg.contains("groups[0] (`measurement`)"), "{msg}");
    }

    #[test]
    fn unknown_top_level_key_is_named() {
        let text = format!("retries = 3\n{GOOD}");
        let msg = parse_plan(&text, origin()).expect_err("fails").to_string();
        assert!(
            msg.contains("`retries`") && msg.contains("top level"),
            "{msg}"
        );
    }

    #[test]
    fn bad_enum_keeps_line() {
        let text = GOOD.replace("\"camera-hot-shoe\"", "\"hotshoe\"");
        let err = parse_plan(&text, origin()).expect_err("bad variant");
        let msg = err.to_string();
        assert!(matches!(err, PlanError::Parse { .. }), "{msg}");
        assert!(msg.contains("hotshoe"), "{msg}");
        assert!(msg.contains("line"), "{msg}");
    }

    #[test]
    fn zero_count_is_rejected_with_location() {
        let text = GOOD.replace("count = 30", "count = 0");
        let msg = parse_plan(&text, origin()).expect_err("zero").to_string();
        assert!(msg.contains("groups[0] (`measurement`).count"), "{msg}");
    }

    #[test]
    fn a_survey_group_is_refused_naming_the_group() {
        let text = GOOD.replace("role = \"measurement\"", "role = \"survey\"");
        let msg = parse_plan(&text, origin()).expect_err("survey").to_string();
        assert!(msg.contains("groups[0] (`measurement`).role"), "{msg}");
        assert!(msg.contains("--survey"), "{msg}");
    }

    #[test]
    fn overlapping_interval_is_rejected() {
        let text = GOOD.replace("min_interval_us = 4_000_000", "min_interval_us = 200_000");
        let msg = parse_plan(&text, origin())
            .expect_err("overlap")
            .to_string();
        assert!(
            msg.contains("min_interval_us") && msg.contains("400000"),
            "{msg}"
        );
    }

    #[test]
    fn interval_without_off_time_is_rejected() {
        let text = GOOD
            .replace("min_interval_us = 4_000_000", "min_interval_us = 140_000")
            .replace("pre_focus_us = 300_000", "pre_focus_us = 0");
        let msg = parse_plan(&text, origin()).expect_err("no off").to_string();
        assert!(
            msg.contains("min_interval_us") && msg.contains("150000"),
            "{msg}"
        );
    }

    #[test]
    fn interval_shorter_than_the_previous_groups_pulse_is_rejected() {
        // The plan that merged two presses on the firmware image: a second group with no
        // pre-focus whose 10 ms interval is shorter than the first group's 100 ms pulse.
        let text = r#"
max_retries = 0

[[groups]]
label = "a"
role = "measurement"
count = 1
min_interval_us = 10_000
pre_focus_us = 0
shutter_pulse_us = 100_000
xsync_timeout_us = 500_000
flash_ready_timeout_us = 5_000_000
flash_mode = "controller-on-xsync"

[[groups]]
label = "b"
role = "measurement"
count = 1
min_interval_us = 10_000
pre_focus_us = 0
shutter_pulse_us = 100_000
xsync_timeout_us = 500_000
flash_ready_timeout_us = 5_000_000
flash_mode = "controller-on-xsync"
"#;
        let msg = parse_plan(text, origin()).expect_err("merged").to_string();
        assert!(
            msg.contains("groups[1] (`b`).min_interval_us")
                && msg.contains("groups[0] (`a`)")
                && msg.contains("100000 us")
                && msg.contains(">= 150000"),
            "{msg}"
        );
    }

    #[test]
    fn unit_slip_is_rejected() {
        let text = GOOD.replace(
            "flash_ready_timeout_us = 10_000_000\nflash_mode = \"camera",
            "flash_ready_timeout_us = 10_000_000_000\nflash_mode = \"camera",
        );
        let msg = parse_plan(&text, origin()).expect_err("slip").to_string();
        assert!(
            msg.contains("flash_ready_timeout_us") && msg.contains("one hour"),
            "{msg}"
        );
    }

    #[test]
    fn long_label_is_rejected() {
        let text = GOOD.replace(
            "label = \"measurement\"",
            "label = \"measurement around the circle of the head\"",
        );
        let msg = parse_plan(&text, origin()).expect_err("long").to_string();
        assert!(msg.contains(".label") && msg.contains("24 bytes"), "{msg}");
    }

    #[test]
    fn empty_plan_is_rejected() {
        let msg = parse_plan("max_retries = 0\n", origin())
            .expect_err("empty")
            .to_string();
        assert!(msg.contains("groups"), "{msg}");
    }

    #[test]
    fn missing_file_names_path() {
        let msg = load_plan(Path::new("/nonexistent/plan.toml"))
            .expect_err("missing")
            .to_string();
        assert!(msg.contains("/nonexistent/plan.toml"), "{msg}");
    }
}
