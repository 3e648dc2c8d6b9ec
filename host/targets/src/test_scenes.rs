//! Synthetic scenes of small blurred tags with known corners, shared by the unit tests of the
//! detector and of the edge-profile fit.

use crate::homography::square_to_quad;
use crate::image::GrayF32;
use crate::render::paint_tag;
use glam::DVec2;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Separable Gaussian blur (clamped borders).
fn blur(img: &GrayF32, sigma: f64) -> GrayF32 {
    let r = (3.0 * sigma).ceil() as isize;
    let k: Vec<f64> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let ks: f64 = k.iter().sum();
    let (w, h) = (img.width as isize, img.height as isize);
    let pass = |src: &[f32], horizontal: bool| -> Vec<f32> {
        let mut out = vec![0f32; src.len()];
        for y in 0..h {
            for x in 0..w {
                let mut acc = 0.0;
                for (j, kv) in k.iter().enumerate() {
                    let d = j as isize - r;
                    let (xx, yy) = if horizontal {
                        ((x + d).clamp(0, w - 1), y)
                    } else {
                        (x, (y + d).clamp(0, h - 1))
                    };
                    acc += kv * f64::from(src[(yy * w + xx) as usize]);
                }
                out[(y * w + x) as usize] = (acc / ks) as f32;
            }
        }
        out
    };
    let a = pass(&img.data, true);
    GrayF32::new(img.width, img.height, pass(&a, false)).expect("image")
}

/// Synthetic tags and their true corners.
pub(crate) struct Scene {
    pub(crate) img: GrayF32,
    pub(crate) truth: Vec<(u32, [DVec2; 4])>,
}

/// Small tags (black squares of `sides` px) on a surround of level `beyond`, white cells at
/// `white`, blurred and noisy.
pub(crate) fn scene(seed: u64, sides: (f64, f64), beyond: f32, white: f32, sigma: f64) -> Scene {
    stretched_scene(seed, sides, 1.0, beyond, white, sigma)
}

/// As [`scene`], each tag `aspect` times as tall as it is wide (`sides` its width): a
/// foreshortened tag.
pub(crate) fn stretched_scene(
    seed: u64,
    sides: (f64, f64),
    aspect: f64,
    beyond: f32,
    white: f32,
    sigma: f64,
) -> Scene {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (w, h) = (480, 360);
    let mut img = GrayF32::new(w, h, vec![beyond; w * h]).expect("image");
    let mut truth = Vec::new();
    for (i, (cx, cy)) in [
        (80.0, 80.0),
        (240.0, 80.0),
        (400.0, 80.0),
        (80.0, 260.0),
        (240.0, 260.0),
        (400.0, 260.0),
    ]
    .into_iter()
    .enumerate()
    {
        let side = rng.random_range(sides.0..sides.1);
        let ang: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        let (s, c) = ang.sin_cos();
        let half = 0.5 * side;
        let mut corner = |x: f64, y: f64| {
            let y = y * aspect;
            DVec2::new(cx + rng.random_range(-0.3..0.3), cy)
                + DVec2::new(c * x - s * y, s * x + c * y) * half
        };
        let q = [
            corner(-1.0, -1.0),
            corner(1.0, -1.0),
            corner(1.0, 1.0),
            corner(-1.0, 1.0),
        ];
        let hm = square_to_quad(&q).expect("homography");
        let id = 3 + 7 * i;
        assert!(paint_tag(&mut img, &hm, id, 0.05, white, 4));
        truth.push((id as u32, q));
    }
    let mut img = blur(&img, sigma);
    for v in &mut img.data {
        *v += rng.random_range(-0.01..0.01);
    }
    Scene { img, truth }
}
