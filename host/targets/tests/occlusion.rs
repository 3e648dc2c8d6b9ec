//! Honest corners on partly hidden tags: synthetic tags with known corners, some partly covered
//! by an occluder painted over the border (a dark blob, a skin-coloured disc, a piece of white
//! paper such as another tag's), blurred and noisy. For whole and occluded tags alike, the
//! corners' errors over their stated sigmas must have a median near 1 and none beyond 5; the
//! corners the detector marks occluded are where the large errors are.
//!
//! Run with `--nocapture` for the statistics (docs/benchmarks-poses.md, "Partly hidden tags").

// Corner loops index the detection and the truth together.
#![allow(clippy::needless_range_loop)]

use glam::{DMat3, DVec2, DVec3};
use rand::{Rng, SeedableRng};
use skinbrdf_targets::homography::apply_h;
use skinbrdf_targets::render::paint_tag;
use skinbrdf_targets::{detect, DetectorConfig, GrayF32};

/// Largest error over stated sigma allowed for any corner (the bound).
const MAX_ERROR_OVER_SIGMA: f64 = 5.0;

/// Range of the median error over sigma: honest sigmas give about 1.18 (the Rayleigh median of a
/// per-axis sigma; the sigma stated is the worst direction's, which lowers it), above 1.6 they
/// are optimistic. On these clean 32..70 px tags the corner errors (median 0.03 px) are below
/// the sigma floor (`SIGMA_FLOOR_PX`, 0.04 px, set on the rendered sessions where the median
/// is 1.1), so whole tags sit at about 0.6, and the occluded corners' added term, the samples
/// hidden by the contrast tests and the border displacements under the marking floor that go
/// into the covariance (`BORDER_COVARIANCE_SIGMAS`) and the allowance for correlated edge
/// residuals (`MAX_RESIDUAL_CORRELATION`) lower the partly hidden tags' median further, to
/// about 0.34: 0.3 is the pessimistic end still useful (the rendered sessions, whose errors are
/// above the floor, sit at 0.62..0.88, docs/benchmarks-poses.md).
const MEDIAN_RANGE: (f64, f64) = (0.3, 1.6);

/// Corner error beyond which a corner must be marked occluded, pixels (about ten times the
/// whole tags' largest error here).
const MUST_FLAG_PX: f64 = 0.5;

/// Homography of a tag with black-square half-side `s` px centred at `c`, turned by `angle`,
/// with perspective terms `(g, h)`.
fn tag_h(c: DVec2, s: f64, angle: f64, g: f64, h: f64) -> DMat3 {
    let (sn, cs) = angle.sin_cos();
    DMat3::from_cols(
        DVec3::new(s * cs + c.x * g, s * sn + c.y * g, g),
        DVec3::new(-s * sn + c.x * h, s * cs + c.y * h, h),
        DVec3::new(c.x, c.y, 1.0),
    )
}

fn corners(h: &DMat3) -> [DVec2; 4] {
    [(-1.0, 1.0), (1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)].map(|(x, y)| apply_h(h, DVec2::new(x, y)))
}

/// Paints an anti-aliased disc of level `v`.
fn disc(img: &mut GrayF32, c: DVec2, r: f64, v: f32) {
    let (w, h) = (img.width as i64, img.height as i64);
    for y in ((c.y - r).floor() as i64 - 1).max(0)..=((c.y + r).ceil() as i64 + 1).min(h - 1) {
        for x in ((c.x - r).floor() as i64 - 1).max(0)..=((c.x + r).ceil() as i64 + 1).min(w - 1) {
            let mut inside = 0;
            for sy in 0..4 {
                for sx in 0..4 {
                    let p = DVec2::new(
                        x as f64 - 0.375 + 0.25 * sx as f64,
                        y as f64 - 0.375 + 0.25 * sy as f64,
                    );
                    inside += usize::from(p.distance(c) <= r);
                }
            }
            let f = inside as f32 / 16.0;
            let i = (y * w + x) as usize;
            img.data[i] = img.data[i] * (1.0 - f) + v * f;
        }
    }
}

/// Paints an anti-aliased straight-edged sheet of level `v` covering the half-plane beyond the
/// line through `p` with outward normal `n` (another tag's paper laid over this one).
fn sheet(img: &mut GrayF32, p: DVec2, n: DVec2, reach: f64, v: f32) {
    let (w, h) = (img.width as i64, img.height as i64);
    for y in ((p.y - reach) as i64).max(0)..((p.y + reach) as i64).min(h) {
        for x in ((p.x - reach) as i64).max(0)..((p.x + reach) as i64).min(w) {
            let d = (DVec2::new(x as f64, y as f64) - p).dot(n);
            let f = (d + 0.5).clamp(0.0, 1.0) as f32;
            let i = (y * w + x) as usize;
            img.data[i] = img.data[i] * (1.0 - f) + v * f;
        }
    }
}

struct Case {
    id: u32,
    truth: [DVec2; 4],
    occluded: bool,
}

/// One image of 8 x 5 tags (32..70 px); every second one partly hidden.
fn image(seed: u64) -> (GrayF32, Vec<Case>) {
    let (w, h) = (1280usize, 800usize);
    let mut img = GrayF32::new(w, h, vec![0.5; w * h]).expect("size matches");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut cases = Vec::new();
    for j in 0..5 {
        for i in 0..8 {
            let id = (seed as usize * 40 + j * 8 + i) % 587;
            let c = DVec2::new(80.0 + 160.0 * i as f64, 80.0 + 160.0 * j as f64);
            let s = rng.random_range(16.0..35.0);
            let hm = tag_h(
                c,
                s,
                rng.random_range(0.0..std::f64::consts::TAU),
                rng.random_range(-4e-4..4e-4),
                rng.random_range(-4e-4..4e-4),
            );
            assert!(paint_tag(&mut img, &hm, id, 0.06, 0.92, 4));
            let truth = corners(&hm);
            let occluded = (i + j) % 2 == 1;
            if occluded {
                // Where: a corner or a point on a side; what: dark blob, skin, paper.
                let k = rng.random_range(0..4usize);
                let along = if rng.random_bool(0.5) {
                    0.0
                } else {
                    rng.random_range(0.2..0.8)
                };
                let at = truth[k] + (truth[(k + 1) % 4] - truth[k]) * along;
                let side = 2.0 * s;
                match rng.random_range(0..3u32) {
                    0 => disc(&mut img, at, rng.random_range(0.15..0.4) * side, 0.08),
                    1 => disc(&mut img, at, rng.random_range(0.15..0.4) * side, 0.55),
                    _ => {
                        let n = (at - c).normalize();
                        let p = at - n * rng.random_range(0.05..0.25) * side;
                        sheet(&mut img, p, n, 0.9 * side, 0.92);
                    }
                }
            }
            cases.push(Case {
                id: id as u32,
                truth,
                occluded,
            });
        }
    }
    // Blur (3 x 3 binomial, sigma ~0.7 px) and noise.
    let src = img.data.clone();
    let k = [0.25f32, 0.5, 0.25];
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let mut acc = 0.0;
            for (dy, ky) in k.iter().enumerate() {
                for (dx, kx) in k.iter().enumerate() {
                    acc += ky * kx * src[(y + dy - 1) * w + x + dx - 1];
                }
            }
            img.data[y * w + x] = acc;
        }
    }
    for v in img.data.iter_mut() {
        *v += rng.random_range(-0.04..0.04);
    }
    (img, cases)
}

#[derive(Default)]
struct Stats {
    ratios: Vec<f64>,
    errors: Vec<f64>,
    flagged: usize,
    flagged_big: usize,
    big: usize,
    tags: usize,
    found: usize,
}

impl Stats {
    fn summary(&mut self, what: &str) -> (f64, f64) {
        self.ratios.sort_by(f64::total_cmp);
        self.errors.sort_by(f64::total_cmp);
        let med = self.ratios[self.ratios.len() / 2];
        let max = *self.ratios.last().expect("corners");
        eprintln!(
            "{what}: {}/{} tags found, {} corners, error median {:.3} px, max {:.3} px; \
             error/sigma median {med:.2}, p95 {:.2}, max {max:.2}; flagged occluded {} \
             (of the {} corners off by > {MUST_FLAG_PX} px: {} flagged)",
            self.found,
            self.tags,
            self.ratios.len(),
            self.errors[self.errors.len() / 2],
            self.errors.last().expect("corners"),
            self.ratios[self.ratios.len() * 95 / 100],
            self.flagged,
            self.big,
            self.flagged_big,
        );
        (med, max)
    }
}

#[test]
fn stated_sigmas_cover_the_corner_errors_of_whole_and_partly_hidden_tags() {
    let (mut whole, mut hidden) = (Stats::default(), Stats::default());
    for seed in 1..=3 {
        let (img, cases) = image(seed);
        let dets = detect(&img, &DetectorConfig::default());
        for c in &cases {
            let st = if c.occluded { &mut hidden } else { &mut whole };
            st.tags += 1;
            let centre = 0.25 * c.truth.iter().copied().sum::<DVec2>();
            let Some(d) = dets
                .iter()
                .find(|d| d.id == c.id && d.center_px.distance(centre) < 10.0)
            else {
                continue;
            };
            st.found += 1;
            let sig = d.corner_sigma_px();
            for k in 0..4 {
                let e = d.corners_px[k].distance(c.truth[k]);
                st.ratios.push(e / sig[k]);
                st.errors.push(e);
                st.flagged += usize::from(d.occluded_corners[k]);
                if e > MUST_FLAG_PX {
                    st.big += 1;
                    st.flagged_big += usize::from(d.occluded_corners[k]);
                }
            }
        }
        // No false positives.
        for d in &dets {
            assert!(
                cases.iter().any(|c| c.id == d.id),
                "false positive {} at {}",
                d.id,
                d.center_px
            );
        }
    }
    let (wm, wx) = whole.summary("whole tags");
    let (hm, hx) = hidden.summary("partly hidden tags");
    assert_eq!(whole.found, whole.tags, "every whole tag is found");
    assert_eq!(
        whole.flagged, 0,
        "no corner of a whole tag is marked occluded"
    );
    assert_eq!(
        hidden.flagged_big, hidden.big,
        "every corner off by more than {MUST_FLAG_PX} px is marked occluded"
    );
    for (what, med, max) in [("whole", wm, wx), ("partly hidden", hm, hx)] {
        assert!(
            (MEDIAN_RANGE.0..=MEDIAN_RANGE.1).contains(&med),
            "{what}: error/sigma median {med}"
        );
        assert!(
            max <= MAX_ERROR_OVER_SIGMA,
            "{what}: a corner at {max} sigma"
        );
    }
}

/// A surface brighter than the white ring standing over it a pixel from the border: a crop of a
/// rendered studio image (`synth`, default scene, 1524 x 1012, image `m06`), where the
/// reflectance standard hides the reference target 52's ring under the right two thirds of its
/// bottom side and leaves a sliver of ring about a pixel wide. The tag itself is whole, so its
/// corners are `fully_visible` in the truth, but the double step (black, the sliver, the
/// brighter standard) pulls the bottom side's line out at one end unless the contrast ceiling
/// (`CONTRAST_CEILING_MADS`) hides it. Every corner must be within 3 of its sigmas or marked
/// occluded.
#[test]
fn a_brighter_surface_over_the_ring_next_to_the_border() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/studio_bright_surface.png");
    let img = GrayF32::load(&path).expect("fixture loads");
    // The truth's corners (`truth.json`, less the crop's origin 720, 140), in the detector's
    // order (bottom-left, bottom-right, top-right, top-left of the printed tag).
    let truth = [
        DVec2::new(37.0723, 119.1742),
        DVec2::new(104.9649, 117.5935),
        DVec2::new(103.5298, 30.6834),
        DVec2::new(35.6187, 33.122),
    ];
    let dets = detect(&img, &DetectorConfig::default());
    let d = dets.iter().find(|d| d.id == 52).expect("tag 52 found");
    let sig = d.corner_sigma_px();
    for j in 0..4 {
        let e = d.corners_px[j].distance(truth[j]);
        println!(
            "corner {j}: error {e:.3} px, sigma {:.3} px, marked {}",
            sig[j], d.occluded_corners[j]
        );
        assert!(
            d.occluded_corners[j] || e <= 3.0 * sig[j],
            "corner {j}: error {e:.2} px at sigma {:.2} px, not marked",
            sig[j]
        );
    }
    // The corners away from the surface keep their accuracy and are not marked.
    for j in [2, 3] {
        assert!(!d.occluded_corners[j], "corner {j} marked");
        assert!(d.corners_px[j].distance(truth[j]) < 0.15, "corner {j}");
    }
}
