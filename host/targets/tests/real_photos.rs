//! The real photographs of `shared/data/apriltag/`: every tag the reference library lists must
//! be found (right ID, right place, nothing extra), with sub-pixel agreement.
//!
//! Two references: the `.txt` files shipped with the photos, which the AprilTag C library
//! reproduces exactly with `refine_edges = 0` (unrefined quad corners, see
//! `scripts/peers/apriltag_reference_fixture.py`), and the same library with edge refinement
//! (`tests/data/apriltag_c_refined.json`), which is the like-for-like sub-pixel comparison.

use glam::DVec2;
use skinbrdf_targets::{detect, Detection, DetectorConfig, GrayF32};
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

#[test]
fn real_photos_match_the_reference_library() {
    let mut err_txt = Vec::new();
    let mut err_refined = Vec::new();
    let mut misses = Vec::new();
    for stem in STEMS {
        let img = GrayF32::load(&data_dir().join(format!("{stem}.jpg"))).expect("photo loads");
        let dets = detect(&img, &DetectorConfig::default());
        let refs = parse_txt(&data_dir().join(format!("{stem}.txt")));
        for r in &refs {
            match find(&dets, r) {
                Some(d) => err_txt.extend((0..4).map(|k| d.corners_px[k].distance(r.corners[k]))),
                None => misses.push(format!("{stem}: tag {} at {}", r.id, centre(&r.corners))),
            }
        }
        // Detections the reference does not list. One is known and genuine: a tag 0 on a distant
        // cube (11 px square, Hamming 1) in the second photo at (610, 105), checked by eye; the
        // reference library misses it. Anything more would be a false positive.
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
        }
        assert!(extra.len() <= 1, "{stem}: {} extra detections", extra.len());
        for r in &parse_fixture(stem) {
            let d = find(&dets, r).expect("every refined-reference tag is found");
            err_refined.extend((0..4).map(|k| d.corners_px[k].distance(r.corners[k])));
        }
    }
    assert!(misses.is_empty(), "not found: {misses:#?}");
    let (m_txt, p90_txt, max_txt) = (
        percentile(&mut err_txt, 0.5),
        percentile(&mut err_txt, 0.9),
        percentile(&mut err_txt, 1.0),
    );
    let (m_ref, p90_ref, max_ref) = (
        percentile(&mut err_refined, 0.5),
        percentile(&mut err_refined, 0.9),
        percentile(&mut err_refined, 1.0),
    );
    eprintln!(
        "vs .txt (unrefined): {} corners, median {m_txt:.3} px, p90 {p90_txt:.3}, max {max_txt:.3}",
        err_txt.len()
    );
    eprintln!(
        "vs C library with refine_edges: {} corners, median {m_ref:.3} px, p90 {p90_ref:.3}, max {max_ref:.3}",
        err_refined.len()
    );
    // Like for like (both refine edges): median well below 0.5 px.
    assert!(m_ref < 0.2, "median vs refined reference {m_ref}");
    // The 90th percentile is set by 10..15 px JPEG tags where neither library is sure to
    // 0.5 px; the narrow gradient we use for cells under 3 px (unbiased on synthetic images with
    // known truth) departs most from the C library's wider one there.
    assert!(p90_ref < 0.6, "p90 vs refined reference {p90_ref}");
    // Against the unrefined .txt corners (the C library itself differs from them by a median of
    // 0.27 / 0.39 px when it refines edges): median below 0.5 px.
    assert!(m_txt < 0.5, "median vs .txt {m_txt}");
    assert!(max_txt < 1.5, "max vs .txt {max_txt}");
}
