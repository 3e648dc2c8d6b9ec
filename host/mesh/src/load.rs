//! Loading a head scan: PLY, OBJ or glTF (`.glb`, `.gltf`) by extension, scanner units to
//! metres, validation and repair.
//!
//! Units: scanners write millimetres (most structured-light and laser scanners), centimetres,
//! inches or metres, and rarely say which. [`LengthUnit::Auto`] decides from the bounding box:
//! a head (or a forehead patch) is 0.05 to 0.5 m across, so the largest extent `E` in file units
//! picks metres for `E < 2`, centimetres for `2 <= E < 50` (a head is 5-50 cm), millimetres
//! above. The chosen unit is reported; pass the unit explicitly when the scan is not a head.
//! glTF is metres by specification: for `.glb` and `.gltf`, `Auto` means metres, no guess
//! ([`crate::gltf_scan`]).

use std::path::Path;

use skinbrdf_core::TriMesh;

use crate::error::{unknown_format, MeshError};
use crate::load_options::{gltf_unit, scale_to_metres};
pub use crate::load_options::{guess_unit, LengthUnit, LoadOptions};
use crate::validate::{repair, MeshReport};

/// A loaded, validated mesh in metres with what was done to it.
#[derive(Debug, Clone)]
pub struct LoadedMesh {
    /// The mesh, metres.
    pub mesh: TriMesh,
    /// The unit the file was read in (resolved when `Auto`).
    pub unit: LengthUnit,
    /// Validation and repair.
    pub report: MeshReport,
}

/// Loads `.ply`, `.obj`, `.glb` or `.gltf`, converts to metres and validates/repairs per
/// `opts`. A glTF's images are not decoded here (a texture that does not decode is no error
/// for the geometry, as a missing MTL file is none for an OBJ).
pub fn load_mesh(path: &Path, opts: &LoadOptions) -> Result<LoadedMesh, MeshError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let mut unit = opts.unit;
    let mut mesh = match ext.as_deref() {
        Some("ply") => crate::ply::read_ply(path)?.0,
        Some("obj") => read_obj(path)?,
        Some("glb" | "gltf") => {
            unit = gltf_unit(unit);
            crate::gltf_scan::read_gltf(path, crate::gltf_scan::Detail::Geometry)?.mesh
        }
        _ => return Err(unknown_format(path)),
    };
    let unit = scale_to_metres(&mut mesh, unit);
    let (mesh, report) = repair(&mesh, opts.policy, &path.display().to_string())?;
    Ok(LoadedMesh { mesh, unit, report })
}

/// Reads an OBJ file (all objects merged, polygons triangulated, normals dropped: OBJ normals
/// are indexed separately from positions and the scan's normals are refitted anyway). Texture
/// coordinates and materials are ignored here (see [`crate::textured::load_textured`]), and a
/// missing MTL file is no error for the geometry.
pub fn read_obj(path: &Path) -> Result<TriMesh, MeshError> {
    Ok(crate::obj::read_obj_data(path)?.mesh)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn millimetre_ply_becomes_metres() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("scan.ply");
        let m = TriMesh {
            positions: vec![
                Vec3::ZERO,
                Vec3::new(150.0, 0.0, 0.0),
                Vec3::new(0.0, 200.0, 0.0),
            ],
            indices: vec![[0, 1, 2]],
            normals: None,
        };
        crate::ply::write_ply_binary(&p, &m).unwrap();
        let l = load_mesh(&p, &LoadOptions::default()).unwrap();
        assert_eq!(l.unit, LengthUnit::Millimetres);
        assert!((l.mesh.positions[2].y - 0.2).abs() < 1e-7);
        let l = load_mesh(
            &p,
            &LoadOptions {
                unit: LengthUnit::Custom(1e-4),
                ..Default::default()
            },
        )
        .unwrap();
        assert!((l.mesh.positions[1].x - 0.015).abs() < 1e-7);
    }

    #[test]
    fn obj_quads_are_triangulated() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("scan.obj");
        std::fs::write(
            &p,
            "# quad in cm\nv 0 0 0\nv 10 0 0\nv 10 10 0\nv 0 10 0\nf 1 2 3 4\n",
        )
        .unwrap();
        let l = load_mesh(&p, &LoadOptions::default()).unwrap();
        assert_eq!(l.unit, LengthUnit::Centimetres);
        assert_eq!(l.mesh.indices.len(), 2);
        assert!((l.mesh.positions[2].x - 0.1).abs() < 1e-7);
    }

    #[test]
    fn bad_files_give_precise_errors() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("scan.stl");
        std::fs::write(&p, "solid").unwrap();
        let e = load_mesh(&p, &LoadOptions::default()).unwrap_err();
        assert!(
            e.to_string().contains("scan.stl: unknown mesh format"),
            "{e}"
        );
        let p = dir.path().join("empty.obj");
        std::fs::write(&p, "v 0 0 0\n").unwrap();
        let e = load_mesh(&p, &LoadOptions::default()).unwrap_err();
        assert!(e.to_string().contains("empty.obj: OBJ has no faces"), "{e}");
        assert_eq!(LengthUnit::parse("mm"), Some(LengthUnit::Millimetres));
        assert_eq!(LengthUnit::parse("-1"), None);
    }
}
