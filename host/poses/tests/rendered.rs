//! End to end on rendered images: tags painted through the exact camera projection (pinhole),
//! blurred and noisy, detected, and the camera and head poses recovered.

use glam::{DMat3, DVec2, DVec3};
use rand::{Rng, SeedableRng};
use skinbrdf_core::{CameraModel, Pose};
use skinbrdf_poses::pnp::target_points;
use skinbrdf_poses::{estimate_pose, PnpConfig, PointObs};
use skinbrdf_targets::render::paint_tag;
use skinbrdf_targets::{detect, DetectorConfig, GrayF32};

/// Median camera position error, metres: the default scene's stated bound (1 mm).
const CAMERA_POSITION_MAX_M: f64 = 1e-3;
/// Median camera orientation error, degrees: the default scene's stated bound.
const CAMERA_ORIENTATION_MAX_DEG: f64 = 0.02;
/// Median head position error, metres: the default scene's stated bound (0.5 mm).
const HEAD_POSITION_MAX_M: f64 = 0.5e-3;

/// A square target: id, corners (bottom-left, bottom-right, top-right, top-left), normal.
type Tag = (u32, [DVec3; 4], DVec3);

fn square(id: u32, centre: DVec3, outward: DVec3, up: DVec3, size: f64) -> Tag {
    let z_in = -outward.normalize();
    let x = up.cross(z_in).normalize();
    let y = z_in.cross(x);
    let h = 0.5 * size;
    let c = |sx: f64, sy: f64| centre + x * (sx * h) + y * (sy * h);
    (
        id,
        [c(-1.0, 1.0), c(1.0, 1.0), c(1.0, -1.0), c(-1.0, -1.0)],
        outward.normalize(),
    )
}

/// Reference field: tags on three planes (world frame, z towards the camera is -z).
fn reference() -> Vec<Tag> {
    let mut v = Vec::new();
    let mut id = 0;
    for (plane, tilt) in [(-1.0f64, 0.5f64), (0.0, 0.0), (1.0, -0.5)] {
        let n = DVec3::new(tilt.sin(), 0.0, -tilt.cos());
        for j in -2..=2 {
            for k in 0..2 {
                let c = DVec3::new(
                    plane * 0.16 + (k as f64 - 0.5) * 0.05 * tilt.cos(),
                    j as f64 * 0.045,
                    (k as f64 - 0.5) * 0.05 * tilt.sin() + plane.abs() * 0.03,
                );
                v.push(square(id, c, n, DVec3::new(0.0, -1.0, 0.0), 0.028));
                id += 1;
            }
        }
    }
    v
}

/// Headdress: small tags on a band, head frame.
fn headdress() -> Vec<Tag> {
    (0..6)
        .map(|i| {
            let a = (i as f64 - 2.5) * 0.3;
            let n = DVec3::new(a.sin(), 0.0, -a.cos());
            square(100 + i, n * 0.07, n, DVec3::new(0.0, -1.0, 0.0), 0.018)
        })
        .collect()
}

fn image_from_tag(cam: &CameraModel, world_from_camera: &Pose, corners: &[DVec3; 4]) -> DMat3 {
    // Tag frame (-1,1) = corner 0 (bottom-left), (1,1) = corner 1, (1,-1) = corner 2.
    let c = corners.iter().copied().sum::<DVec3>() / 4.0;
    let ex = (corners[1] - corners[0]) * 0.5;
    let ey = (corners[0] - corners[3]) * 0.5;
    let inv = world_from_camera.inverse();
    let r = inv.rotation;
    let k = DMat3::from_cols(
        DVec3::new(cam.fx_px, 0.0, 0.0),
        DVec3::new(0.0, cam.fy_px, 0.0),
        DVec3::new(cam.cx_px, cam.cy_px, 1.0),
    );
    k * DMat3::from_cols(r * ex, r * ey, inv.transform_point(c))
}

fn render(cam: &CameraModel, wc: &Pose, tags: &[Tag], img: &mut GrayF32) {
    for (id, corners, n) in tags {
        let to_cam = (wc.translation_m - corners[0]).normalize();
        if n.dot(to_cam) < 0.2 {
            continue;
        }
        let h = image_from_tag(cam, wc, corners);
        paint_tag(img, &h, *id as usize, 0.06, 0.85, 4);
    }
}

fn obs(dets: &[skinbrdf_targets::Detection], tags: &[Tag]) -> Vec<PointObs> {
    let mut v = Vec::new();
    for d in dets {
        if let Some((id, c, n)) = tags.iter().find(|t| t.0 == d.id) {
            v.extend(target_points(
                *id,
                c,
                *n,
                &d.corners_px,
                &d.corner_sigma_px(),
            ));
        }
    }
    v
}

#[test]
fn camera_and_head_poses_from_rendered_images() {
    let cam = CameraModel::from_fov(1524, 1012, 40f64.to_radians());
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let refs = reference();
    let head = headdress();
    let mut cam_pos = Vec::new();
    let mut cam_ang = Vec::new();
    let mut head_pos = Vec::new();
    for k in 0..4 {
        let a = (k as f64 - 1.5) * 0.25;
        let eye = DVec3::new(0.55 * a.sin(), -0.05, -0.55 * a.cos());
        let wc = Pose::look_at(eye, DVec3::new(0.0, 0.0, 0.0), DVec3::new(0.0, -1.0, 0.0))
            .expect("valid");
        let world_from_head = Pose::from_rotation_vector(
            DVec3::new(0.02 * k as f64, 0.05, -0.01),
            DVec3::new(0.01, 0.0, -0.12 - 0.003 * k as f64),
        );
        let head_world: Vec<Tag> = head
            .iter()
            .map(|(id, c, n)| {
                (
                    *id,
                    c.map(|p| world_from_head.transform_point(p)),
                    world_from_head.transform_vector(*n),
                )
            })
            .collect();
        let mut img = GrayF32::new(1524, 1012, vec![0.35; 1524 * 1012]).expect("size");
        render(&cam, &wc, &refs, &mut img);
        render(&cam, &wc, &head_world, &mut img);
        for v in img.data.iter_mut() {
            *v += rng.random_range(-0.02..0.02);
        }
        let dets = detect(&img, &DetectorConfig::default());
        let est = estimate_pose(&cam, &obs(&dets, &refs), None, &PnpConfig::default())
            .expect("camera pose");
        cam_pos.push(est.frame_from_camera.distance_to_m(&wc));
        cam_ang.push(est.frame_from_camera.angle_to_rad(&wc).to_degrees());
        let hd = estimate_pose(&cam, &obs(&dets, &head), None, &PnpConfig::default())
            .expect("head pose");
        let wh = est.frame_from_camera * hd.frame_from_camera.inverse();
        head_pos.push(wh.distance_to_m(&world_from_head));
        let _ = DVec2::ZERO;
    }
    let med = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (p, a, h) = (med(&mut cam_pos), med(&mut cam_ang), med(&mut head_pos));
    eprintln!(
        "median camera position error {:.4} mm, orientation {:.5} deg, head {:.4} mm",
        p * 1e3,
        a,
        h * 1e3
    );
    assert!(p < CAMERA_POSITION_MAX_M, "camera position error {p}");
    assert!(
        a < CAMERA_ORIENTATION_MAX_DEG,
        "camera orientation error {a}"
    );
    assert!(h < HEAD_POSITION_MAX_M, "head position error {h}");
}
