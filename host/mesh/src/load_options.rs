//! Units of a scan file's coordinates ([`LengthUnit`], guessed from the bounding box when the
//! file does not say; see [`crate::load`]) and the options of the loaders ([`LoadOptions`]).

use glam::Vec3;
use skinbrdf_core::TriMesh;

use crate::report::RepairPolicy;

/// Length unit of the coordinates in a scan file.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub enum LengthUnit {
    /// Metres.
    Metres,
    /// Centimetres.
    Centimetres,
    /// Millimetres.
    Millimetres,
    /// Inches.
    Inches,
    /// Any unit, by its size in metres.
    Custom(f64),
    /// Guess from the bounding box (see [`crate::load`]).
    Auto,
}

impl LengthUnit {
    /// Metres per file unit (`None` for `Auto`).
    pub fn metres_per_unit(self) -> Option<f64> {
        Some(match self {
            Self::Metres => 1.0,
            Self::Centimetres => 0.01,
            Self::Millimetres => 0.001,
            Self::Inches => 0.0254,
            Self::Custom(m) => m,
            Self::Auto => return None,
        })
    }

    /// Parses `m`, `cm`, `mm`, `in`, `auto` or a number of metres per unit.
    pub fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "m" => Self::Metres,
            "cm" => Self::Centimetres,
            "mm" => Self::Millimetres,
            "in" | "inch" => Self::Inches,
            "auto" => Self::Auto,
            other => {
                let v: f64 = other.parse().ok()?;
                if !(v.is_finite() && v > 0.0) {
                    return None;
                }
                Self::Custom(v)
            }
        })
    }
}

/// Options for [`crate::load_mesh`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoadOptions {
    /// Unit of the file's coordinates.
    pub unit: LengthUnit,
    /// What to do about defects.
    pub policy: RepairPolicy,
}

impl Default for LoadOptions {
    fn default() -> Self {
        Self {
            unit: LengthUnit::Auto,
            policy: RepairPolicy::repair(),
        }
    }
}

/// Guesses the unit from the largest bounding-box extent (see [`crate::load`]).
pub fn guess_unit(mesh: &TriMesh) -> LengthUnit {
    let finite = mesh.positions.iter().filter(|p| p.is_finite());
    let (lo, hi) = finite.fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let extent = (hi - lo).max_element();
    if !(extent.is_finite()) || extent < 2.0 {
        LengthUnit::Metres
    } else if extent < 50.0 {
        LengthUnit::Centimetres
    } else {
        LengthUnit::Millimetres
    }
}

/// The unit of a glTF file: metres by specification when the caller leaves it to the loader.
pub(crate) fn gltf_unit(unit: LengthUnit) -> LengthUnit {
    match unit {
        LengthUnit::Auto => LengthUnit::Metres,
        u => u,
    }
}

/// Scales a mesh read in `unit` (guessed when `Auto`) to metres; returns the unit used.
pub(crate) fn scale_to_metres(mesh: &mut TriMesh, unit: LengthUnit) -> LengthUnit {
    let unit = match unit {
        LengthUnit::Auto => guess_unit(mesh),
        u => u,
    };
    let scale = unit.metres_per_unit().unwrap_or(1.0) as f32;
    if scale != 1.0 {
        for p in &mut mesh.positions {
            *p *= scale;
        }
    }
    unit
}
