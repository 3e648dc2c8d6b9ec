//! Plane-to-image homographies of a tag: the map from the tag's square `[-1, 1]^2` to its
//! detected quad, and applying one to a point. Shared by detection, the small-tag edge-profile
//! fit, the reference quad stage and the renderer of synthetic tags.

use glam::{DMat3, DVec2, DVec3};

/// Homography mapping the tag square `(-1,-1), (1,-1), (1,1), (-1,1)` to `q`.
pub fn square_to_quad(q: &[DVec2; 4]) -> Option<DMat3> {
    // Closed form (Heckbert): unit square to quad, composed with the scaling from [-1,1]^2.
    let (p0, p1, p2, p3) = (q[0], q[1], q[2], q[3]);
    let s = p0 - p1 + p2 - p3;
    let d1 = p1 - p2;
    let d2 = p3 - p2;
    let den = d1.perp_dot(d2);
    if den.abs() < 1e-12 {
        return None;
    }
    let g = s.perp_dot(d2) / den;
    let h = d1.perp_dot(s) / den;
    // Maps unit-square (u, v) in [0,1]^2 with (0,0)->p0, (1,0)->p1, (1,1)->p2, (0,1)->p3.
    let m = DMat3::from_cols(
        DVec3::new(p1.x - p0.x + g * p1.x, p1.y - p0.y + g * p1.y, g),
        DVec3::new(p3.x - p0.x + h * p3.x, p3.y - p0.y + h * p3.y, h),
        DVec3::new(p0.x, p0.y, 1.0),
    );
    // [-1,1] -> [0,1]: u = (x + 1) / 2.
    let sq = DMat3::from_cols(
        DVec3::new(0.5, 0.0, 0.0),
        DVec3::new(0.0, 0.5, 0.0),
        DVec3::new(0.5, 0.5, 1.0),
    );
    Some(m * sq)
}

/// Applies a homography to a point.
pub fn apply_h(h: &DMat3, p: DVec2) -> DVec2 {
    let r = *h * DVec3::new(p.x, p.y, 1.0);
    DVec2::new(r.x / r.z, r.y / r.z)
}
