//! `[targets]` and every placed target of every group: the family, each target's geometry,
//! and ids unique across all layouts (placed and unplaced).

use std::collections::HashMap;
use std::path::Path;

use crate::checks::{check_id_and_size, check_target};
use crate::error::SessionErrors;
use crate::format::{SessionFile, Target, TAG_FAMILY};

/// Checks the family and every target, placed or not.
pub(super) fn check(s: &SessionFile, file: &Path, errs: &mut SessionErrors) {
    if s.targets.family != TAG_FAMILY {
        errs.push(
            file,
            "targets.family",
            format!(
                "`{}` is not supported (only {TAG_FAMILY})",
                s.targets.family
            ),
        );
    }
    let mut ids: HashMap<u32, String> = HashMap::new();
    for (field, t) in &placed(s) {
        check_target(t, file, field, errs);
        unique_id(t.id, field, &mut ids, file, errs);
    }
    unplaced(s, &mut ids, file, errs);
}

/// Every placed target with its field: the reference, headdress, flash and standard lists.
fn placed(s: &SessionFile) -> Vec<(String, &Target)> {
    let mut all_targets: Vec<(String, &Target)> = Vec::new();
    for (name, list) in [
        ("targets.reference", &s.targets.reference),
        ("targets.headdress", &s.targets.headdress),
        ("flash.targets", &s.flash.targets),
    ] {
        for (i, t) in list.iter().enumerate() {
            all_targets.push((format!("{name}[{i}]"), t));
        }
    }
    if let Some(st) = &s.standard {
        for (i, t) in st.targets.iter().enumerate() {
            all_targets.push((format!("standard.targets[{i}]"), t));
        }
    }
    all_targets
}

/// `[[targets.unplaced]]`: id and size, corners in a sheet's frame (a square, with the sheet
/// named), ids unique.
fn unplaced(
    s: &SessionFile,
    ids: &mut HashMap<u32, String>,
    file: &Path,
    errs: &mut SessionErrors,
) {
    for (i, t) in s.targets.unplaced.iter().enumerate() {
        let field = format!("targets.unplaced[{i}]");
        check_id_and_size(t.id, t.size_m, file, &field, errs);
        if let Some(corners_m) = t.sheet_corners_m {
            let as_target = Target {
                id: t.id,
                size_m: t.size_m,
                corners_m,
                centre_m: None,
            };
            check_target(&as_target, file, &format!("{field}.sheet"), errs);
            if t.sheet.is_none() {
                errs.push(
                    file,
                    format!("{field}.sheet_corners_m"),
                    "corners in a sheet's frame need the sheet's name (`sheet`)",
                );
            }
        }
        unique_id(t.id, &field, ids, file, errs);
    }
}

/// Records `id` as used by `field`; reports it when another target used it first.
fn unique_id(
    id: u32,
    field: &str,
    ids: &mut HashMap<u32, String>,
    file: &Path,
    errs: &mut SessionErrors,
) {
    if let Some(prev) = ids.insert(id, field.to_string()) {
        errs.push(
            file,
            format!("{field}.id"),
            format!("id {id} is also used by {prev}"),
        );
    }
}
