//! `[known]`: the quantities a session states instead of measuring them.

use std::path::Path;

use crate::checks::{check_pose, positive};
use crate::error::SessionErrors;
use crate::format::KnownQuantities;

/// A finite light position, a positive calibration constant, valid poses.
pub(super) fn check(k: &KnownQuantities, file: &Path, errs: &mut SessionErrors) {
    if let Some(p) = k.light_position_m {
        if !p.is_finite() {
            errs.push(file, "known.light_position_m", "non-finite coordinate");
        }
    }
    if let Some(c) = k.calibration_c {
        if !c.iter().all(|&v| positive(v)) {
            errs.push(
                file,
                "known.calibration_c",
                format!(
                    "must be positive and finite, got [{}, {}, {}]",
                    c[0], c[1], c[2]
                ),
            );
        }
    }
    if let Some(p) = &k.world_from_flash {
        check_pose(p, file, "known.world_from_flash", errs);
    }
    if let Some(p) = &k.world_from_standard {
        check_pose(p, file, "known.world_from_standard", errs);
    }
}
