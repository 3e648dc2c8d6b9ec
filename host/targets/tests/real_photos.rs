//! The real photographs of `shared/data/apriltag/`: every tag the reference library lists must
//! be found (right ID, right place, nothing extra), with sub-pixel agreement.
//!
//! Two references: the `.txt` files shipped with the photos, which the AprilTag C library
//! reproduces exactly with `refine_edges = 0` (unrefined quad corners, see
//! `scripts/peers/apriltag_reference_fixture.py`), and the same library with edge refinement
//! (`tests/data/apriltag_c_refined.json`), which is the like-for-like sub-pixel comparison.
//!
//! The issue's bound, every listed tag found with corners within 0.5 px of the reference
//! library's (median well below), is asserted for the reference library's own corner estimator,
//! which we reproduce ([`CornerModel::BinaryBoundary`], the library's quad stage reimplemented
//! in `skinbrdf_targets::reference_quad`): measured median 0.001 px, max 0.275 px against the
//! `.txt`. The remaining hundredths are JPEG decoding: our luma differs from the library's
//! decoder by a grey level here and there, which moves a threshold pixel.
//!
//! Our default corners (edge refinement) are held to the refined library like for like, and to
//! the `.txt` with wider named bounds, because the `.txt` corners are biased where the
//! reference's threshold is (docs/benchmarks-poses.md, "Real photos"): they are the dark/light
//! boundary of its adaptive threshold, whose threshold is the mid-level of the local minimum and
//! maximum. Above most of these tags the white ring (~180 of 255) is darker than the background
//! beyond it (~250), so the maximum is the background, the threshold sits above the black/ring
//! mid-level and the boundary moves outward: the top edges of the `.txt` are 0.26 px above our
//! edge-refined ones on average, the other three sides agree within 0.05 px. On synthetic tiny
//! JPEG tags with known truth the reference estimator is less accurate than the edge refinement
//! (RMS 0.25 / 0.35 / 0.57 px against 0.09 / 0.23 / 0.41 at blur 0.6 / 1.0 / 1.5 px; with a ring
//! darker than its surroundings 0.48 / 0.84 / 1.29 against 0.12 / 0.36 / 0.74), and even the true
//! corners of such tags are up to 0.6..1.5 px from it.

use glam::DVec2;
use skinbrdf_targets::{detect, CornerModel, Detection, DetectorConfig, GrayF32};
use std::path::{Path, PathBuf};

struct RefTag {
    id: u32,
    /// Corners converted to our convention (same order).
    corners: [DVec2; 4],
}

fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/apriltag")
}

const STEMS: [&str; 2] = ["33369213973_9d9bb4cc96_c", "34085369442_304b6bafd9_c"];

/// Parses `id, (x y), (x y), (x y), (x y)` and converts the reference library's corners
/// (its pixel centres are at half-integers: its coordinates are ours + 0.5; same corner order).
fn parse_txt(path: &Path) -> Vec<RefTag> {
    let text = std::fs::read_to_string(path).expect("reference file readable");
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let nums: Vec<f64> = l
                .replace(['(', ')', ','], " ")
                .split_whitespace()
                .map(|t| t.parse().expect("number"))
                .collect();
            assert_eq!(nums.len(), 9, "{l}");
            let c = |i: usize| DVec2::new(nums[1 + 2 * i], nums[2 + 2 * i]) - DVec2::splat(0.5);
            RefTag {
                id: nums[0] as u32,
                corners: [c(0), c(1), c(2), c(3)],
            }
        })
        .collect()
}

fn parse_fixture(stem: &str) -> Vec<RefTag> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/apriltag_c_refined.json");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).expect("fixture")).expect("json");
    v[stem]
        .as_array()
        .expect("stem present")
        .iter()
        .map(|d| {
            let c = |i: usize| {
                DVec2::new(
                    d["corners"][i][0].as_f64().expect("x"),
                    d["corners"][i][1].as_f64().expect("y"),
                )
            };
            RefTag {
                id: d["id"].as_u64().expect("id") as u32,
                corners: [c(0), c(1), c(2), c(3)],
            }
        })
        .collect()
}

fn centre(c: &[DVec2; 4]) -> DVec2 {
    c.iter().copied().sum::<DVec2>() / 4.0
}

fn find<'a>(dets: &'a [Detection], r: &RefTag) -> Option<&'a Detection> {
    dets.iter()
        .find(|d| d.id == r.id && d.center_px.distance(centre(&r.corners)) < 0.25 * d.side_px())
}

fn percentile(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

/// Like for like (both libraries refine edges), median: well below the issue's 0.5 px. Measured
/// 0.176 px; the JPEG tags of 10..33 px leave both libraries a tenth of a pixel of noise.
const MEDIAN_VS_REFINED_PX: f64 = 0.2;

/// Like for like, 90th percentile: set by 10..15 px tags where neither library is sure to 0.5 px
/// (the C library's ±3 px search reaches the next edge, our window stays within a cell; and
/// the library leaves in the pull of the border's inner edge, which we take off tags whose
/// smallest cell is under 3 px). Measured 0.573 px (0.554 px with the pull left in).
const P90_VS_REFINED_PX: f64 = 0.6;

/// Against the unrefined `.txt` corners, median (measured 0.359 px): the C library itself
/// differs from them by 0.27 / 0.39 px when it refines edges; see the module docs for the top
/// edges' 0.26 px threshold bias.
const MEDIAN_VS_TXT_PX: f64 = 0.42;

/// Against the `.txt`, worst corner (measured 1.392 px: the top-right corner of a 20 px tag at
/// (236, 393) in the second photo, where the `.txt`'s top edge carries the threshold bias
/// described above; next, 1.278 px, the top-right corner of a 19 px tag at (309, 400), whose
/// ring (~150) is much darker than the white above it (~255), so the reference's threshold
/// (~132 against a black/ring mid-level of ~85) puts its top edge about a pixel too high). Tags
/// whose smallest cell is under 3 px have their inner edges' pull taken off (the detector's
/// `INNER_EDGE_BIAS_MAX_CELL_PX`), which moves their sides inward by a few hundredths of a
/// pixel on average here, and the first corner by 0.13 px (1.261 px before).
const MAX_VS_TXT_PX: f64 = 1.45;

/// The issue's bound: every corner of the reference library's estimator (ours reimplementing
/// it) within 0.5 px of the `.txt` it wrote.
const ISSUE_BOUND_PX: f64 = 0.5;

/// "Median well below" the bound, for the reference estimator (measured 0.001 px: the same
/// integer threshold and line fits on the same pixels; a tenth of the bound leaves room for a
/// different JPEG decoder).
const MEDIAN_BOUNDARY_VS_TXT_PX: f64 = 0.05;

/// Mean outward offset of each side (the side whose outward normal is closest to up, left,
/// down, right in the image) of `d` from the reference `r`.
fn side_offsets(d: &[DVec2; 4], r: &[DVec2; 4]) -> [(usize, f64); 4] {
    let c = centre(r);
    std::array::from_fn(|k| {
        let (a, b) = (r[k], r[(k + 1) % 4]);
        let mid = 0.5 * (a + b);
        let mut n = (b - a).perp().normalize();
        if n.dot(mid - c) < 0.0 {
            n = -n;
        }
        let dir = (n.y.atan2(n.x) / std::f64::consts::FRAC_PI_2).round() as i64;
        // atan2 quarter turns: -1 up, 0 right, 1 down, 2 / -2 left.
        let slot = match dir {
            -1 => 0,
            1 => 2,
            0 => 3,
            _ => 1,
        };
        (slot, (0.5 * (d[k] + d[(k + 1) % 4]) - mid).dot(n))
    })
}

struct Errors {
    txt: Vec<f64>,
    refined: Vec<f64>,
    /// Sum and count of outward side offsets against the `.txt`: up, left, down, right.
    sides: [(f64, usize); 4],
}

fn run(cfg: &DetectorConfig) -> Errors {
    let mut e = Errors {
        txt: Vec::new(),
        refined: Vec::new(),
        sides: [(0.0, 0); 4],
    };
    let mut misses = Vec::new();
    for stem in STEMS {
        let img = GrayF32::load(&data_dir().join(format!("{stem}.jpg"))).expect("photo loads");
        let dets = detect(&img, cfg);
        let refs = parse_txt(&data_dir().join(format!("{stem}.txt")));
        for r in &refs {
            match find(&dets, r) {
                Some(d) => {
                    e.txt
                        .extend((0..4).map(|k| d.corners_px[k].distance(r.corners[k])));
                    for (slot, off) in side_offsets(&d.corners_px, &r.corners) {
                        e.sides[slot].0 += off;
                        e.sides[slot].1 += 1;
                    }
                }
                None => misses.push(format!("{stem}: tag {} at {}", r.id, centre(&r.corners))),
            }
        }
        // Detections the reference does not list. Two are known and genuine, checked by eye:
        // tag 0 on the faces of distant cubes in the second photo, at (610, 105) (11 px square,
        // Hamming 1) and at (655, 111) (10 x 13 px, Hamming 0, the near cube's left face); the
        // reference library misses both. Anything else would be a false positive.
        const KNOWN_EXTRA: [(&str, u32, f64, f64); 2] = [
            ("34085369442_304b6bafd9_c", 0, 610.0, 105.0),
            ("34085369442_304b6bafd9_c", 0, 655.0, 111.0),
        ];
        let extra: Vec<&Detection> = dets
            .iter()
            .filter(|d| {
                !refs
                    .iter()
                    .any(|r| find(std::slice::from_ref(*d), r).is_some())
            })
            .collect();
        for d in &extra {
            eprintln!(
                "{stem}: detection not in the reference: {} at {}",
                d.id, d.center_px
            );
            assert!(
                KNOWN_EXTRA.iter().any(|&(s, id, x, y)| s == stem
                    && id == d.id
                    && d.center_px.distance(DVec2::new(x, y)) < 3.0),
                "{stem}: unexpected detection {} at {}",
                d.id,
                d.center_px
            );
        }
        for r in &parse_fixture(stem) {
            let d = find(&dets, r).expect("every refined-reference tag is found");
            e.refined
                .extend((0..4).map(|k| d.corners_px[k].distance(r.corners[k])));
        }
    }
    assert!(misses.is_empty(), "not found: {misses:#?}");
    e
}

/// Median, 90th percentile and maximum, printed with the count over the issue's bound.
fn summary(label: &str, v: &mut [f64]) -> (f64, f64, f64) {
    let (m, p90, max) = (percentile(v, 0.5), percentile(v, 0.9), percentile(v, 1.0));
    let over = v.iter().filter(|&&x| x >= ISSUE_BOUND_PX).count();
    eprintln!(
        "{label}: {} corners, median {m:.3} px, p90 {p90:.3}, max {max:.3}, {over} at or over {ISSUE_BOUND_PX} px",
        v.len()
    );
    (m, p90, max)
}

fn print_sides(label: &str, sides: &[(f64, usize); 4]) {
    let mean = |i: usize| sides[i].0 / sides[i].1.max(1) as f64;
    eprintln!(
        "{label}: mean outward side offset vs .txt: up {:+.3} px, left {:+.3}, down {:+.3}, right {:+.3}",
        mean(0),
        mean(1),
        mean(2),
        mean(3)
    );
}

#[test]
fn real_photos_match_the_reference_library() {
    let mut e = run(&DetectorConfig::default());
    let (m_txt, _, max_txt) = summary("edge-refined vs .txt (unrefined)", &mut e.txt);
    let (m_ref, p90_ref, _) = summary(
        "edge-refined vs C library with refine_edges",
        &mut e.refined,
    );
    print_sides("edge-refined", &e.sides);
    assert!(
        m_ref < MEDIAN_VS_REFINED_PX,
        "median vs refined reference {m_ref}"
    );
    assert!(
        p90_ref < P90_VS_REFINED_PX,
        "p90 vs refined reference {p90_ref}"
    );
    assert!(m_txt < MEDIAN_VS_TXT_PX, "median vs .txt {m_txt}");
    assert!(max_txt < MAX_VS_TXT_PX, "max vs .txt {max_txt}");
}

#[test]
fn the_reference_estimator_reproduces_the_txt_corners() {
    let cfg = DetectorConfig {
        corner_model: CornerModel::BinaryBoundary,
        ..DetectorConfig::default()
    };
    let mut e = run(&cfg);
    let (m_txt, _, max_txt) = summary("reference estimator vs .txt (unrefined)", &mut e.txt);
    summary(
        "reference estimator vs C library with refine_edges",
        &mut e.refined,
    );
    print_sides("reference estimator", &e.sides);
    assert!(m_txt < MEDIAN_BOUNDARY_VS_TXT_PX, "median vs .txt {m_txt}");
    assert!(max_txt < ISSUE_BOUND_PX, "max vs .txt {max_txt}");
}
