//! What the stages need when nothing known lets them skip ([`SectionNeeds`]): the targets
//! they locate things by (placed, or unplaced ones the survey can place), the standard and
//! its image.

use std::path::Path;

use crate::capture::ImageRole;
use crate::error::SessionErrors;
use crate::format::{SessionFile, TargetGroup};
use crate::needs::SectionNeeds;
use crate::parse::Stated;

/// Reports every section a planned stage needs that the session lacks.
pub(super) fn check(s: &SessionFile, stated: Stated, file: &Path, errs: &mut SessionErrors) {
    let needs = SectionNeeds::of(&s.images, &s.known, Some(&s.camera));
    let reference_unplaced = unplaced_needed(
        s,
        TargetGroup::Reference,
        &needs.reference_targets,
        file,
        errs,
    );
    let headdress_unplaced = unplaced_needed(
        s,
        TargetGroup::Headdress,
        &needs.headdress_targets,
        file,
        errs,
    );
    let flash_unplaced = unplaced_needed(s, TargetGroup::Flash, &needs.flash_targets, file, errs);
    unplaced_needed(s, TargetGroup::Standard, &needs.standard, file, errs);
    if stated.targets {
        if let (Some(why), true, false) = (
            &needs.reference_targets,
            s.targets.reference.is_empty(),
            reference_unplaced,
        ) {
            errs.push(file, "targets.reference", format!("empty, but {why}"));
        }
        if let (Some(why), true, false) = (
            &needs.headdress_targets,
            s.targets.headdress.is_empty(),
            headdress_unplaced,
        ) {
            errs.push(file, "targets.headdress", format!("empty, but {why}"));
        }
    }
    if let (Some(why), true, true, false) = (
        &needs.flash_targets,
        stated.flash,
        s.flash.targets.is_empty(),
        flash_unplaced,
    ) {
        errs.push(file, "flash.targets", format!("empty, and {why}"));
    }
    if let Some(why) = &needs.standard {
        if s.standard.is_none() {
            errs.push(file, "standard", format!("missing, and {why}"));
        }
        let count = |role| s.images.iter().filter(|i| i.role == role).count();
        if count(ImageRole::ReferenceStandard) == 0 {
            errs.push(
                file,
                "images",
                format!("no reference-standard image, and {why}"),
            );
        }
    }
}

/// Whether `group` has unplaced targets that a planned stage (`why`) needs; reports them
/// when nothing can place them.
///
/// Unplaced reference and headdress targets are the placement survey's to place; it needs the
/// world's origin (a placed reference target). Flash and standard targets are placed by their
/// printed layouts: unplaced ones are an error where a stage needs them.
fn unplaced_needed(
    s: &SessionFile,
    group: TargetGroup,
    why: &Option<String>,
    file: &Path,
    errs: &mut SessionErrors,
) -> bool {
    let ids = s.targets.unplaced_ids(group);
    if ids.is_empty() || why.is_none() {
        return false;
    }
    let problem = match group {
        TargetGroup::Reference if s.targets.reference.is_empty() => Some(unplaced_problem(
            group,
            &ids,
            "no reference target has a placement to fix the world's origin: the rig must \
             state the corners of at least one (or a reference sheet's placement)",
        )),
        TargetGroup::Reference | TargetGroup::Headdress => None,
        TargetGroup::Flash | TargetGroup::Standard => why.as_deref().map(|why| {
            unplaced_problem(
                group,
                &ids,
                &format!(
                    "{why}; the survey places reference and headdress targets only, flash \
                     and standard targets are placed by their printed layouts"
                ),
            )
        }),
    };
    if let Some(p) = problem {
        errs.push(file, "targets.unplaced", p);
    }
    true
}

/// The error of a group whose placements a planned stage needs but nobody measured.
fn unplaced_problem(group: TargetGroup, ids: &[u32], why: &str) -> String {
    let shown: Vec<String> = ids.iter().take(8).map(u32::to_string).collect();
    let more = if ids.len() > 8 { ", ..." } else { "" };
    format!(
        "{} {} target(s) have no placement in the {} frame (ids {}{more}), but {why}",
        ids.len(),
        group.name(),
        group.frame(),
        shown.join(", "),
    )
}
