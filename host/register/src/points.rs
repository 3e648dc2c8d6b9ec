//! Hand-picked target corners on an untextured scan.
//!
//! When the scan has no usable texture, an operator picks target corners on the scan in a mesh
//! viewer and lists them, in metres in the scan's frame, in a TOML file:
//!
//! ```toml
//! [[points]]
//! target = 104        # tag36h11 id of a headdress target
//! corner = 0          # 0..3: bottom-left, bottom-right, top-right, top-left of the printed tag
//! scan_m = [0.0123, -0.0456, 0.0789]
//! ```
//!
//! At least three points that are not collinear are needed (three corners of one target
//! suffice; corners of several targets spread over the band constrain the rotation better).
//! [`align_points`] fits the survey's corners to them as [`crate::align()`] does, rejecting a
//! target whose points do not fit.

use std::path::Path;

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::align::{fit_correspondences, AlignConfig, AlignKind, Alignment, Correspondence};
use crate::RegisterError;

/// One picked corner.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ScanPoint {
    /// tag36h11 id.
    pub target: u32,
    /// Corner (0..4, session order).
    pub corner: u8,
    /// The corner on the scan, scan frame, metres.
    pub scan_m: DVec3,
}

/// Reads a points file (see the module docs).
pub fn load_point_pairs(path: &Path) -> Result<Vec<ScanPoint>, RegisterError> {
    let text =
        skinbrdf_core::untrusted::read_text_io(path, skinbrdf_core::untrusted::SETTINGS_FILE)
            .map_err(|source| RegisterError::Io {
                path: path.to_path_buf(),
                source,
            })?;
    parse_point_pairs(&text, path)
}

/// Parses the text of a points file; `path` names it in errors.
pub fn parse_point_pairs(text: &str, path: &Path) -> Result<Vec<ScanPoint>, RegisterError> {
    let err = |field: String, reason: String| RegisterError::PointsFile {
        path: path.to_path_buf(),
        field,
        reason,
    };
    let table: toml::Table = text
        .parse()
        .map_err(|e: toml::de::Error| err("(file)".into(), e.message().to_string()))?;
    if let Some(k) = table.keys().find(|k| k.as_str() != "points") {
        return Err(err(
            k.clone(),
            "unknown key (the file holds `[[points]]` entries only)".into(),
        ));
    }
    let Some(list) = table.get("points") else {
        return Err(err(
            "points".into(),
            "missing: no `[[points]]` entry".into(),
        ));
    };
    let Some(list) = list.as_array() else {
        return Err(err(
            "points".into(),
            "must be an array of tables `[[points]]`".into(),
        ));
    };
    let mut out: Vec<ScanPoint> = Vec::with_capacity(list.len());
    for (i, item) in list.iter().enumerate() {
        let name = |f: &str| format!("points[{i}].{f}");
        let Some(t) = item.as_table() else {
            return Err(err(format!("points[{i}]"), "must be a table".into()));
        };
        if let Some(k) = t
            .keys()
            .find(|k| !matches!(k.as_str(), "target" | "corner" | "scan_m"))
        {
            return Err(err(
                name(k),
                "unknown field (expected target, corner, scan_m)".into(),
            ));
        }
        let int = |f: &str, max: i64| -> Result<i64, RegisterError> {
            let v = t
                .get(f)
                .ok_or_else(|| err(name(f), "missing".into()))?
                .as_integer()
                .ok_or_else(|| err(name(f), "must be an integer".into()))?;
            if !(0..=max).contains(&v) {
                return Err(err(name(f), format!("{v} is outside 0..={max}")));
            }
            Ok(v)
        };
        let target = int("target", i64::from(u32::MAX))? as u32;
        let corner = int("corner", 3)? as u8;
        let arr = t
            .get("scan_m")
            .ok_or_else(|| err(name("scan_m"), "missing".into()))?
            .as_array()
            .ok_or_else(|| {
                err(
                    name("scan_m"),
                    "must be an array [x, y, z] of metres".into(),
                )
            })?;
        if arr.len() != 3 {
            return Err(err(
                name("scan_m"),
                format!("has {} values, expected 3 ([x, y, z] metres)", arr.len()),
            ));
        }
        let mut xyz = [0.0; 3];
        for (k, v) in arr.iter().enumerate() {
            let x = v
                .as_float()
                .or_else(|| v.as_integer().map(|i| i as f64))
                .ok_or_else(|| err(name("scan_m"), format!("value {k} is not a number")))?;
            if !x.is_finite() {
                return Err(err(name("scan_m"), format!("value {k} is not finite")));
            }
            xyz[k] = x;
        }
        if let Some(j) = out
            .iter()
            .position(|p| p.target == target && p.corner == corner)
        {
            return Err(err(
                format!("points[{i}]"),
                format!("target {target} corner {corner} is listed twice (also points[{j}])"),
            ));
        }
        out.push(ScanPoint {
            target,
            corner,
            scan_m: DVec3::from_array(xyz),
        });
    }
    if out.len() < 3 {
        return Err(err(
            "points".into(),
            format!(
                "{} point(s): at least 3 non-collinear points are needed",
                out.len()
            ),
        ));
    }
    if let Some(problem) = collinear(&out) {
        return Err(err("points".into(), problem));
    }
    Ok(out)
}

/// Points closer to a line than this fraction of their spread count as collinear: a rotation
/// about that line is then not fixed (a picked corner is good to a millimetre over a spread of
/// centimetres, so real picks are far above it).
pub const COLLINEAR_REL_TOL: f64 = 1e-3;

/// Why the points cannot fix a rotation (all on one spot or on one line), or `None`.
fn collinear(points: &[ScanPoint]) -> Option<String> {
    let a = points.first()?.scan_m;
    let b = points
        .iter()
        .map(|p| p.scan_m)
        .max_by(|p, q| p.distance(a).total_cmp(&q.distance(a)))?;
    let spread_m = b.distance(a);
    if spread_m <= 0.0 {
        return Some(
            "every point is at the same place: at least 3 non-collinear points are needed".into(),
        );
    }
    let axis = (b - a) / spread_m;
    let off_line_m = points
        .iter()
        .map(|p| (p.scan_m - a).cross(axis).length())
        .fold(0.0, f64::max);
    (off_line_m <= COLLINEAR_REL_TOL * spread_m).then(|| {
        format!(
            "the points lie on one line (at most {off_line_m:.2e} m from it over a spread of \
             {spread_m:.3} m): at least 3 non-collinear points are needed"
        )
    })
}

/// Aligns the survey's corners to picked scan points (matched by target and corner), with the
/// rejection of [`crate::align()`]. Points of targets the survey does not have are listed in
/// [`Alignment::unmatched`].
pub fn align_points(
    survey: &[(u32, [DVec3; 4])],
    points: &[ScanPoint],
    kind: AlignKind,
    cfg: &AlignConfig,
) -> Result<Alignment, RegisterError> {
    let mut pairs = Vec::new();
    let mut unmatched = Vec::new();
    for p in points {
        match survey.iter().find(|(id, _)| *id == p.target) {
            Some((_, c)) => pairs.push(Correspondence {
                id: p.target,
                corner: p.corner,
                survey_m: c[usize::from(p.corner.min(3))],
                scan_m: p.scan_m,
            }),
            None => unmatched.push(p.target),
        }
    }
    unmatched.sort_unstable();
    unmatched.dedup();
    let mut a = fit_correspondences(&pairs, kind, cfg)?;
    a.unmatched = unmatched;
    Ok(a)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_name_the_file_and_field() {
        let p = Path::new("picked.toml");
        let cases = [
            ("[[points]]\ntarget = 1\ncorner = 0\n", "points[0].scan_m"),
            (
                "[[points]]\ntarget = 1\ncorner = 5\nscan_m = [0, 0, 0]\n",
                "points[0].corner",
            ),
            (
                "[[points]]\ntarget = 1\ncorner = 0\nscan_m = [0, 0]\n",
                "points[0].scan_m",
            ),
            (
                "[[points]]\ntarget = 1\ncorner = 0\nscan_m = [0, 0, 0]\ncolour = 1\n",
                "points[0].colour",
            ),
            (
                "[[points]]\ntarget = 1\ncorner = 0\nscan_m = [0, 0, 0]\n",
                "`points`",
            ),
            ("[[points]]\ntarget = -3\n", "points[0].target"),
            ("pts = 1\n", "`pts`"),
            ("[[points]\n", "(file)"),
        ];
        for (text, field) in cases {
            let e = parse_point_pairs(text, p).expect_err(text);
            let s = e.to_string();
            assert!(s.starts_with("picked.toml: "), "{s}");
            assert!(s.contains(field), "{text:?}: {s}");
        }
        let dup = "[[points]]\ntarget = 1\ncorner = 0\nscan_m = [0, 0, 0]\n".repeat(2);
        let s = parse_point_pairs(&dup, p).expect_err("dup").to_string();
        assert!(s.contains("points[1]") && s.contains("twice"), "{s}");
    }
}
