//! Tessellated ideal shapes (sessions whose geometry is a sphere or a cylinder, tests).

use glam::{DQuat, DVec3, Vec3};
use skinbrdf_core::TriMesh;

/// A closed UV sphere: `n_lat` rings (≥ 2) of `n_lon` (≥ 3) vertices, outward winding.
pub fn uv_sphere(centre_m: DVec3, radius_m: f64, n_lat: u32, n_lon: u32) -> TriMesh {
    let (n_lat, n_lon) = (n_lat.max(2), n_lon.max(3));
    let at = |v: DVec3| (centre_m + v * radius_m).as_vec3();
    let mut positions = vec![at(DVec3::Z)];
    for i in 1..n_lat {
        let th = std::f64::consts::PI * i as f64 / n_lat as f64;
        for j in 0..n_lon {
            let ph = std::f64::consts::TAU * j as f64 / n_lon as f64;
            positions.push(at(DVec3::new(
                th.sin() * ph.cos(),
                th.sin() * ph.sin(),
                th.cos(),
            )));
        }
    }
    positions.push(at(-DVec3::Z));
    let last = positions.len() as u32 - 1;
    let ring = |i: u32, j: u32| 1 + (i - 1) * n_lon + (j % n_lon);
    let mut indices = Vec::new();
    for j in 0..n_lon {
        indices.push([0, ring(1, j), ring(1, j + 1)]);
        indices.push([last, ring(n_lat - 1, j + 1), ring(n_lat - 1, j)]);
    }
    for i in 1..n_lat - 1 {
        for j in 0..n_lon {
            let (a, b, c, d) = (
                ring(i, j),
                ring(i, j + 1),
                ring(i + 1, j),
                ring(i + 1, j + 1),
            );
            indices.push([a, c, d]);
            indices.push([a, d, b]);
        }
    }
    TriMesh {
        positions,
        indices,
        normals: None,
    }
}

/// A bumpy closed sphere, the ray-throughput benchmarks' head-sized mesh:
/// `r(θ, φ) = radius_m · (1 + bump · sin 5θ · cos 7φ)`, `n_lat` rings of `n_lon` vertices, same
/// topology and winding as [`uv_sphere`] (224 x 448 gives 199,808 triangles).
pub fn bumpy_sphere(radius_m: f64, bump: f64, n_lat: u32, n_lon: u32) -> TriMesh {
    let (n_lat, n_lon) = (n_lat.max(2), n_lon.max(3));
    let r = |th: f64, ph: f64| radius_m * (1.0 + bump * (5.0 * th).sin() * (7.0 * ph).cos());
    let at = |th: f64, ph: f64| {
        (DVec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()) * r(th, ph)).as_vec3()
    };
    let mut mesh = uv_sphere(DVec3::ZERO, 1.0, n_lat, n_lon);
    mesh.positions[0] = at(0.0, 0.0);
    for i in 1..n_lat {
        let th = std::f64::consts::PI * i as f64 / n_lat as f64;
        for j in 0..n_lon {
            let ph = std::f64::consts::TAU * j as f64 / n_lon as f64;
            mesh.positions[(1 + (i - 1) * n_lon + j) as usize] = at(th, ph);
        }
    }
    let last = mesh.positions.len() - 1;
    mesh.positions[last] = at(std::f64::consts::PI, 0.0);
    mesh
}

/// An open cylinder (no caps) around `axis` through `centre_m`, outward winding.
pub fn cylinder(
    centre_m: DVec3,
    axis: DVec3,
    radius_m: f64,
    length_m: f64,
    n_len: u32,
    n_around: u32,
) -> TriMesh {
    let (n_len, n_around) = (n_len.max(1), n_around.max(3));
    let rot = DQuat::from_rotation_arc(DVec3::Z, axis.try_normalize().unwrap_or(DVec3::Z));
    let mut positions: Vec<Vec3> = Vec::new();
    for i in 0..=n_len {
        let z = (i as f64 / n_len as f64 - 0.5) * length_m;
        for j in 0..n_around {
            let ph = std::f64::consts::TAU * j as f64 / n_around as f64;
            let p = DVec3::new(radius_m * ph.cos(), radius_m * ph.sin(), z);
            positions.push((centre_m + rot * p).as_vec3());
        }
    }
    let id = |i: u32, j: u32| i * n_around + (j % n_around);
    let mut indices = Vec::new();
    for i in 0..n_len {
        for j in 0..n_around {
            let (a, b, c, d) = (id(i, j), id(i, j + 1), id(i + 1, j), id(i + 1, j + 1));
            indices.push([a, b, d]);
            indices.push([a, d, c]);
        }
    }
    TriMesh {
        positions,
        indices,
        normals: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shapes_are_clean_and_wound_outward() {
        let c = DVec3::new(0.1, 0.2, 0.3);
        for m in [
            uv_sphere(c, 0.05, 12, 24),
            cylinder(c, DVec3::new(1.0, 1.0, 0.0), 0.05, 0.2, 4, 24),
        ] {
            let r = crate::inspect(&m);
            assert!(r.is_clean(), "{}", r.summary());
            for t in 0..m.indices.len() {
                let [a, b, cc] = m.triangle(t);
                let centroid = ((a + b + cc) / 3.0).as_dvec3();
                let n = m.face_normal_area2(t).as_dvec3();
                let out = centroid - c;
                // Outward: positive radial component (cylinder: remove the axial part).
                let radial = out
                    - DVec3::new(1.0, 1.0, 0.0).normalize()
                        * out.dot(DVec3::new(1.0, 1.0, 0.0).normalize());
                assert!(n.dot(out) > 0.0 || n.dot(radial) > 0.0, "triangle {t}");
            }
        }
    }
}
