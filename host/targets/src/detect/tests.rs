//! The detector's unit tests: synthetic tags painted through known homographies.

use super::*;
use crate::detect::border_width::{displaced_sides, thinner_of_pair, InnerEdges};
use crate::detect::cells::SQUARE;
use crate::profile::refine_small_tag;
use crate::render::paint_tag;
use crate::test_scenes::scene;
use glam::{DMat3, DVec3};
use rand::{Rng, SeedableRng};

fn blank(w: usize, h: usize, v: f32) -> GrayF32 {
    GrayF32::new(w, h, vec![v; w * h]).expect("size matches")
}

/// Homography of a tag of half-size `s` px centred at `c`, turned by `angle` and with a
/// perspective term `(g, h)`.
fn tag_h(c: DVec2, s: f64, angle: f64, g: f64, h: f64) -> DMat3 {
    let (sn, cs) = angle.sin_cos();
    DMat3::from_cols(
        DVec3::new(s * cs + c.x * g, s * sn + c.y * g, g),
        DVec3::new(-s * sn + c.x * h, s * cs + c.y * h, h),
        DVec3::new(c.x, c.y, 1.0),
    )
}

fn truth_corners(h: &DMat3) -> [DVec2; 4] {
    [(-1.0, 1.0), (1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)].map(|(x, y)| apply_h(h, DVec2::new(x, y)))
}

#[test]
fn finds_rotated_and_foreshortened_tags_with_subpixel_corners() {
    let mut img = blank(640, 480, 0.5);
    let cases = [
        (3usize, DVec2::new(120.0, 120.0), 40.0, 0.0, 0.0, 0.0),
        (42, DVec2::new(320.0, 120.0), 50.0, 1.7, 0.0005, 0.0),
        (100, DVec2::new(510.0, 130.0), 45.0, 3.0, -0.0008, 0.0004),
        (586, DVec2::new(150.0, 350.0), 30.0, 4.4, 0.0, 0.0012),
        (7, DVec2::new(420.0, 340.0), 60.0, -0.3, 0.0007, 0.0007),
    ];
    let mut truth = Vec::new();
    for &(id, c, s, a, g, h) in &cases {
        let hm = tag_h(c, s, a, g, h);
        assert!(paint_tag(&mut img, &hm, id, 0.08, 0.9, 8));
        truth.push((id as u32, truth_corners(&hm)));
    }
    let dets = detect(&img, &DetectorConfig::default());
    assert_eq!(dets.len(), cases.len(), "{dets:?}");
    for (id, corners) in truth {
        let d = dets.iter().find(|d| d.id == id).expect("tag found");
        for k in 0..4 {
            let e = d.corners_px[k].distance(corners[k]);
            assert!(e < 0.1, "tag {id} corner {k}: error {e} px");
        }
        assert_eq!(d.hamming, 0);
    }
}

#[test]
fn binary_boundary_corners_are_coarser_than_edge_refined_ones() {
    let mut img = blank(640, 480, 0.5);
    let cases = [
        (3usize, DVec2::new(160.0, 140.0), 40.0, 0.3, 0.0004, 0.0),
        (42, DVec2::new(450.0, 300.0), 50.0, 1.7, 0.0, 0.0006),
    ];
    for &(id, c, s, a, g, h) in &cases {
        assert!(paint_tag(&mut img, &tag_h(c, s, a, g, h), id, 0.08, 0.9, 8));
    }
    let boundary = DetectorConfig {
        corner_model: CornerModel::BinaryBoundary,
        ..DetectorConfig::default()
    };
    let rms = |cfg: &DetectorConfig| {
        let dets = detect(&img, cfg);
        assert_eq!(dets.len(), cases.len(), "{dets:?}");
        let mut s2 = 0.0;
        for &(id, c, s, a, g, h) in &cases {
            let truth = truth_corners(&tag_h(c, s, a, g, h));
            let d = dets.iter().find(|d| d.id == id as u32).expect("tag found");
            for k in 0..4 {
                s2 += d.corners_px[k].distance_squared(truth[k]);
            }
        }
        (s2 / (4 * cases.len()) as f64).sqrt()
    };
    let (edge, binary) = (rms(&DetectorConfig::default()), rms(&boundary));
    // The boundary of the threshold sits on the half-pixel grid: a few tenths of a pixel,
    // not the edge refinement's few hundredths.
    assert!(binary < 0.3, "binary boundary RMS {binary}");
    assert!(
        edge < 0.5 * binary,
        "edge {edge} vs binary boundary {binary}"
    );
}

#[test]
fn survives_noise_blur_and_a_lighting_gradient_with_honest_sigma() {
    let (w, h) = (400usize, 300usize);
    let mut img = blank(w, h, 0.0);
    let hm = tag_h(DVec2::new(200.3, 150.7), 70.0, 0.4, 0.0003, -0.0002);
    // Paint into a white card, then apply a strong left-to-right flash falloff and noise.
    for v in img.data.iter_mut() {
        *v = 0.9;
    }
    assert!(paint_tag(&mut img, &hm, 11, 0.05, 0.9, 8));
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    // 3x3 box blur.
    let src = img.clone();
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let mut s = 0.0;
            for dy in 0..3 {
                for dx in 0..3 {
                    s += src.data[(y + dy - 1) * w + x + dx - 1];
                }
            }
            img.data[y * w + x] = s / 9.0;
        }
    }
    for y in 0..h {
        for x in 0..w {
            let gain = 0.35 + 0.65 * x as f32 / w as f32;
            let n: f32 = rng.random_range(-0.03..0.03);
            img.data[y * w + x] = img.data[y * w + x] * gain + n;
        }
    }
    let dets = detect(&img, &DetectorConfig::default());
    assert_eq!(dets.len(), 1, "{dets:?}");
    let truth = truth_corners(&hm);
    let d = &dets[0];
    assert_eq!(d.id, 11);
    let sig = d.corner_sigma_px();
    for k in 0..4 {
        let e = d.corners_px[k].distance(truth[k]);
        assert!(e < 0.15, "corner {k}: error {e}");
        // The stated uncertainty is within a factor of a few of the actual error scale.
        assert!(sig[k] > 0.005 && sig[k] < 0.3, "sigma {}", sig[k]);
    }
}

#[test]
fn rejects_plain_squares_and_noise() {
    let mut img = blank(300, 300, 0.8);
    // A black square with no code, and a square with a random (non-code) pattern.
    for y in 50..130 {
        for x in 50..130 {
            img.data[y * 300 + x] = 0.1;
        }
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    for v in img.data[160 * 300..].iter_mut() {
        if rng.random_bool(0.3) {
            *v = 0.1;
        }
    }
    assert!(detect(&img, &DetectorConfig::default()).is_empty());
}

/// Paints white paper (level `v`, anti-aliased) over the half-plane beyond the line through
/// `p` with outward normal `n`, within `reach` px of `p`.
fn paper_edge(img: &mut GrayF32, p: DVec2, n: DVec2, reach: f64, v: f32) {
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

/// 3 x 3 binomial blur (sigma about 0.7 px) and uniform noise of +-`noise`.
fn blur_and_noise(img: &mut GrayF32, noise: f32, seed: u64) {
    let (w, h) = (img.width, img.height);
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
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    for v in img.data.iter_mut() {
        *v += rng.random_range(-noise..noise);
    }
}

/// A neighbouring target's white paper laid over the outer 1..2 px of one side's black
/// border, parallel to it: the paper's edge is as straight and as contrasted as the border's
/// own, so only the border's width gives it away. Both corners of that side must be marked
/// occluded with a sigma that covers their displacement; the other two, and every corner of
/// the same tags uncovered, must not be marked.
#[test]
fn a_paper_edge_over_one_side_of_the_border_marks_both_its_corners() {
    // (id, centre, half side px, angle, perspective g, h, paper over the border px): cells
    // of 5 px (the studio's reference targets at half resolution) and of 8 px.
    let cases = [
        (21usize, DVec2::new(90.0, 90.0), 20.0, 0.3, 0.0, 0.0, 1.0),
        (52, DVec2::new(250.0, 90.0), 20.0, -0.5, 0.0008, 0.0, 1.6),
        (3, DVec2::new(90.0, 250.0), 32.0, 2.0, 0.0, -0.0006, 1.5),
        (44, DVec2::new(250.0, 250.0), 32.0, 4.0, 0.0005, 0.0005, 2.0),
    ];
    for covered in [false, true] {
        let mut img = blank(340, 340, 0.45);
        for (n, &(id, c, s, a, g, hh, over)) in cases.iter().enumerate() {
            let hm = tag_h(c, s, a, g, hh);
            assert!(paint_tag(&mut img, &hm, id, 0.06, 0.9, 8));
            if covered {
                // Side k of the tag frame, from corner k to k + 1 (BL, BR, TR, TL).
                let k = n % 4;
                let t = truth_corners(&hm);
                let (p, q) = (t[k], t[(k + 1) % 4]);
                let centre = apply_h(&hm, DVec2::ZERO);
                let dir = (q - p).normalize();
                let mut out = DVec2::new(-dir.y, dir.x);
                if out.dot(p - centre) < 0.0 {
                    out = -out;
                }
                paper_edge(&mut img, p - out * over, out, 2.0 * s, 0.9);
            }
        }
        blur_and_noise(&mut img, 0.03, 11);
        let dets = detect(&img, &DetectorConfig::default());
        assert_eq!(dets.len(), cases.len(), "covered {covered}: {dets:?}");
        for (n, &(id, c, s, a, g, hh, over)) in cases.iter().enumerate() {
            let truth = truth_corners(&tag_h(c, s, a, g, hh));
            let d = dets.iter().find(|d| d.id == id as u32).expect("tag found");
            let sig = d.corner_sigma_px();
            let k = n % 4;
            for j in 0..4 {
                let e = d.corners_px[j].distance(truth[j]);
                let on_side = covered && (j == k || j == (k + 1) % 4);
                assert_eq!(
                    d.occluded_corners[j], on_side,
                    "tag {id} (covered {covered}, {over} px over side {k}) corner {j}: \
                     error {e:.2} px, sigma {:.2}",
                    sig[j]
                );
                assert!(
                    e <= 3.0 * sig[j],
                    "tag {id} (covered {covered}) corner {j}: error {e:.2} px, sigma {:.2}",
                    sig[j]
                );
                if on_side {
                    // The paper moved the corner by about its overlap.
                    assert!(e > 0.5 * over, "tag {id} corner {j}: error {e:.2} px");
                }
            }
        }
    }
}

/// Foreshortened small tags (18..23 px wide, 40 px tall: cells of 2.2..2.9 px across the
/// long sides, too small for each side's border to be tested on its own) with a
/// neighbour's white paper laid obliquely over one long side's border, from 0.1 px over at
/// one corner to 0.9 px at the other: the side stays straight and as contrasted as a whole
/// one. Compared with the opposite side (`thinner_of_pair`), its border is thinner there,
/// so that corner is marked occluded with a sigma that covers its error; every other
/// corner, covered or not, stays within five sigmas.
#[test]
fn paper_over_a_small_cells_side_is_found_against_the_opposite_side() {
    // (id, centre, width px, turn, side covered: 1 or 3, the long ones)
    let cases = [
        (5usize, DVec2::new(70.0, 70.0), 18.0, 0.2, 1usize),
        (17, DVec2::new(190.0, 70.0), 20.0, 1.1, 3),
        (29, DVec2::new(310.0, 70.0), 23.0, -0.4, 1),
        (40, DVec2::new(70.0, 200.0), 21.0, 2.6, 3),
        (63, DVec2::new(190.0, 200.0), 19.0, -2.0, 1),
        (77, DVec2::new(310.0, 200.0), 22.0, 0.7, 3),
    ];
    let quad = |c: DVec2, w: f64, turn: f64| -> [DVec2; 4] {
        let (sn, cs) = turn.sin_cos();
        SQUARE.map(|(x, y)| {
            let (x, y) = (0.5 * w * x, 20.0 * y);
            c + DVec2::new(cs * x - sn * y, sn * x + cs * y)
        })
    };
    for covered in [false, true] {
        let mut img = blank(380, 270, 0.45);
        for &(id, c, w, turn, k) in &cases {
            let q = quad(c, w, turn);
            let hm = square_to_quad(&q).expect("homography");
            assert!(paint_tag(&mut img, &hm, id, 0.06, 0.9, 8));
            if covered {
                let (a, b) = (q[k], q[(k + 1) % 4]);
                let dir = (b - a).normalize();
                let mut out = DVec2::new(-dir.y, dir.x);
                if out.dot(a - c) < 0.0 {
                    out = -out;
                }
                // The paper's edge from 0.1 px inside the border at `a` to 0.9 px at `b`.
                let (pa, pb) = (a - out * 0.1, b - out * 0.9);
                let along = (pb - pa).normalize();
                let mut n = DVec2::new(-along.y, along.x);
                if n.dot(out) < 0.0 {
                    n = -n;
                }
                paper_edge(&mut img, (pa + pb) * 0.5, n, 26.0, 0.9);
            }
        }
        blur_and_noise(&mut img, 0.02, 5);
        let dets = detect(&img, &DetectorConfig::default());
        for &(id, c, w, turn, k) in &cases {
            let truth = truth_corners(&square_to_quad(&quad(c, w, turn)).expect("homography"));
            let d = dets
                .iter()
                .find(|d| d.id == id as u32)
                .unwrap_or_else(|| panic!("covered {covered}: tag {id} not found"));
            let sig = d.corner_sigma_px();
            for j in 0..4 {
                let e = d.corners_px[j].distance(truth[j]);
                let msg = format!(
                    "tag {id} (covered {covered}, side {k}) corner {j}: error {e:.2} px, \
                     sigma {:.2}, occluded {}",
                    sig[j], d.occluded_corners[j]
                );
                // Detections list the corners in the reverse of the quad's order.
                if covered && j == 3 - (k + 1) % 4 {
                    // Where the paper lies furthest over the border it moved the corner,
                    // and the corner is marked with a sigma that covers that.
                    assert!(e > 0.5 && d.occluded_corners[j], "{msg}");
                    assert!(e <= 3.0 * sig[j], "{msg}");
                } else {
                    assert!(e <= 5.0 * sig[j], "{msg}");
                }
            }
        }
    }
}

/// Inner edges measured along a side: mean offset and its standard deviation, the offset
/// line's values at the two corners and their standard deviation.
fn edges(offset_px: f64, sd: f64, end_offset_px: [f64; 2], end_sd: f64) -> InnerEdges {
    InnerEdges {
        offset_px,
        var_px2: sd * sd,
        end_offset_px,
        end_var_px2: [end_sd * end_sd; 2],
    }
}

#[test]
fn a_pair_of_small_sides_flags_the_thinner_one_where_it_is_thinner() {
    let whole = edges(0.1, 0.03, [0.1; 2], 0.06);
    // Both borders alike (whatever pull or ink spread they share): nothing.
    assert_eq!(thinner_of_pair(whole, whole), [None, None]);
    // A paper over the border, 0.1 px at the start corner, 0.9 px at the end: the border
    // thins by 7/8 of that (the mean by 7/8 of 0.5 px). The mean test finds the side, the
    // end test the larger displacement at its end corner; the opposite side is left alone.
    let slanted = edges(0.1 - 0.4375, 0.03, [0.1 - 0.0875, 0.1 - 0.7875], 0.06);
    let [s, o] = thinner_of_pair(slanted, whole);
    assert_eq!(o, None);
    let s = s.expect("the thinner side is displaced");
    assert!((s.d_px[0] - 0.4375).abs() < 1e-9, "{s:?}");
    assert!((s.d_px[1] - 0.7875).abs() < 1e-9, "{s:?}");
    assert_eq!(s.marked, [true; 2]);
    // The same with the sides swapped.
    let [s2, o2] = thinner_of_pair(whole, slanted);
    assert_eq!((s2, o2), (None, Some(s)));
    // Thicker is never displaced; within two standard deviations nothing, within four
    // or under MIN_BORDER_DISPLACEMENT_PX a displacement for the covariance only.
    assert_eq!(
        thinner_of_pair(edges(0.6, 0.03, [0.6; 2], 0.06), whole)[0],
        None
    );
    let faint = edges(0.1 - 0.08, 0.04, [0.02; 2], 0.2);
    assert_eq!(thinner_of_pair(faint, whole), [None, None]);
    let slight = edges(0.1 - 0.2, 0.03, [-0.1; 2], 0.2);
    let s = thinner_of_pair(slight, whole)[0].expect("beyond two sigmas");
    assert_eq!(s.marked, [false; 2]);
    assert!((s.d_px[0] - 0.2).abs() < 1e-9 && (s.d_px[1] - 0.2).abs() < 1e-9);
}

#[test]
fn border_width_flags_one_displaced_side_but_not_a_common_thickening() {
    let side = |offset_px: f64| Some(edges(offset_px, 0.03, [offset_px; 2], 0.03));
    // A side moved 1 px inward: its border is 7/8 px thinner than predicted, the opposite
    // side's 1/8 px thicker; only the moved side is displaced, by about 1 px.
    let one = displaced_sides(&[side(-0.875), side(0.0), side(0.125), side(0.0)]);
    assert!(
        one[0].is_some_and(|s| (s.d_px[0] - 1.0).abs() < 1e-9
            && s.d_px[0] == s.d_px[1]
            && s.marked == [true; 2]),
        "{one:?}"
    );
    assert_eq!(one[1..], [None, None, None]);
    // Every border 0.4 px thicker (ink spread): nothing is displaced.
    assert_eq!(displaced_sides(&[side(0.4); 4]), [None; 4]);
    // Under the floor, or beyond the floor but under four sigmas: a displacement for the
    // covariance, not an occluder; under two sigmas, nothing.
    let small = displaced_sides(&[side(-0.2), side(0.0), side(0.0), side(0.0)]);
    assert!(
        small[0]
            .is_some_and(|s| s.marked == [false; 2] && (s.d_px[0] - 0.2 * 8.0 / 7.0).abs() < 0.05),
        "{small:?}"
    );
    assert_eq!(small[1..], [None, None, None]);
    let noisy_side = |offset_px: f64| Some(edges(offset_px, 0.2, [offset_px; 2], 0.2));
    let noisy = displaced_sides(&[noisy_side(-0.6), side(0.0), side(0.0), side(0.0)]);
    assert!(
        noisy[0].is_some_and(|s| s.marked == [false; 2]),
        "{noisy:?}"
    );
    let quiet = [noisy_side(-0.3), side(0.0), side(0.0), side(0.0)];
    assert_eq!(displaced_sides(&quiet), [None; 4]);
    // Sides not measured are not tested.
    assert_eq!(displaced_sides(&[None; 4]), [None; 4]);
}

/// Small blurred tags (cells of 1.25..2.5 px, blur 0.7 px, white paper around): the border's
/// inner edge pulls the outer edge outward where the data cell behind it is white, so
/// uncorrected every quad is too large; and the gradient centroid's phase error is common
/// to a side's samples. With the pull taken off (`unbias_inner_edges`) the quads' mean
/// outward error stays under the bound (what remains is the weaker pull of edges two
/// cells in, which every sample shares), and with the narrow difference's floor the stated
/// sigmas cover the errors.
#[test]
fn small_blurred_tags_lose_the_inner_edge_bias_and_state_honest_sigmas() {
    let (mut outward, mut ratios) = (Vec::new(), Vec::new());
    for seed in 0..12 {
        let sc = scene(seed, (10.0, 20.0), 1.0, 1.0, 0.7);
        for d in detect(&sc.img, &DetectorConfig::default()) {
            let Some((_, q)) = sc.truth.iter().find(|t| t.0 == d.id) else {
                continue;
            };
            if d.occluded_corners.contains(&true) {
                continue;
            }
            let centre = (q[0] + q[1] + q[2] + q[3]) * 0.25;
            let sigma = d.corner_sigma_px();
            for (c, s) in d.corners_px.iter().zip(sigma) {
                let t = q
                    .iter()
                    .copied()
                    .min_by(|a, b| a.distance(*c).total_cmp(&b.distance(*c)))
                    .expect("four corners");
                outward.push((*c - t).dot((t - centre).normalize()));
                ratios.push(c.distance(t) / s);
            }
        }
    }
    assert!(outward.len() >= 150, "too few corners: {}", outward.len());
    let mean_outward = outward.iter().sum::<f64>() / outward.len() as f64;
    ratios.sort_by(f64::total_cmp);
    let (median, max) = (ratios[ratios.len() / 2], ratios[ratios.len() - 1]);
    eprintln!(
        "{} corners: mean outward error {mean_outward:+.3} px, error/sigma median {median:.2}, max {max:.2}",
        ratios.len()
    );
    assert!(mean_outward.abs() < 0.08, "{mean_outward}");
    assert!(median < 1.5 && max < 5.0, "median {median}, max {max}");
}

/// Small foreshortened tags (10..14 px wide, twice as tall, blur 0.7 px): the long sides,
/// with a cell of 1.25..1.75 px across them, take several times the pull of the short
/// ones, so each pair of opposite sides gets its own bias. A side's outward offset from the
/// true side is the mean of its two corners' errors along its outward normal. Left in, the
/// pull moves the long sides outward beyond the first bound; one bias for the whole tag
/// moves the short sides inward beyond the second. What stays on the long sides is the
/// weaker pull of edges two cells in, which every point shares.
#[test]
fn a_foreshortened_small_tag_has_each_pair_of_sides_unbiased() {
    let (mut long, mut short) = (Vec::new(), Vec::new());
    for seed in 0..10 {
        let sc = crate::test_scenes::stretched_scene(seed, (10.0, 14.0), 2.0, 1.0, 1.0, 0.7);
        let (img, truth) = (&sc.img, &sc.truth);
        for d in detect(img, &DetectorConfig::default()) {
            let Some((_, q)) = truth.iter().find(|t| t.0 == d.id) else {
                continue;
            };
            if d.occluded_corners.contains(&true) {
                continue;
            }
            // The detected corners matched to the true ones, in the true order.
            let found: Vec<DVec2> = q
                .iter()
                .map(|t| {
                    d.corners_px
                        .iter()
                        .copied()
                        .min_by(|a, b| a.distance(*t).total_cmp(&b.distance(*t)))
                        .expect("four corners")
                })
                .collect();
            let centre = (q[0] + q[1] + q[2] + q[3]) * 0.25;
            for k in 0..4 {
                let (a, b) = (q[k], q[(k + 1) % 4]);
                let along = (b - a).normalize();
                let mut n = DVec2::new(-along.y, along.x);
                if n.dot((a + b) * 0.5 - centre) < 0.0 {
                    n = -n;
                }
                let offset = 0.5 * ((found[k] - a).dot(n) + (found[(k + 1) % 4] - b).dot(n));
                if a.distance(b) > 15.0 {
                    long.push(offset);
                } else {
                    short.push(offset);
                }
            }
        }
    }
    assert!(
        long.len() >= 60 && short.len() >= 60,
        "{} long, {} short sides",
        long.len(),
        short.len()
    );
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let (ml, ms) = (mean(&long), mean(&short));
    eprintln!(
        "{} tags: mean outward offset, long sides {ml:+.3} px, short sides {ms:+.3} px",
        long.len() / 2
    );
    assert!(ml.abs() < 0.1, "long sides {ml}");
    assert!(ms.abs() < 0.04, "short sides {ms}");
}

#[test]
fn corrects_bit_errors_up_to_the_limit() {
    let mut img = blank(240, 240, 0.8);
    let hm = tag_h(DVec2::new(120.0, 120.0), 80.0, 0.0, 0.0, 0.0);
    assert!(paint_tag(&mut img, &hm, 9, 0.1, 0.9, 4));
    // Flip two data cells by painting over them (partial occlusion).
    let cell = 20.0;
    for (r, c) in [(3usize, 3usize), (5, 6)] {
        let x0 = 120.0 - 100.0 + c as f64 * cell;
        let y0 = 120.0 - 100.0 + r as f64 * cell;
        let v = img.bilinear(DVec2::new(x0 + 10.0, y0 + 10.0));
        let nv = if v > 0.5 { 0.1 } else { 0.9 };
        for y in y0 as usize + 2..(y0 + cell) as usize - 2 {
            for x in x0 as usize + 2..(x0 + cell) as usize - 2 {
                img.data[y * 240 + x] = nv;
            }
        }
    }
    let dets = detect(&img, &DetectorConfig::default());
    assert_eq!(dets.len(), 1);
    assert_eq!((dets[0].id, dets[0].hamming), (9, 2));
    let strict = DetectorConfig {
        max_hamming: 1,
        ..DetectorConfig::default()
    };
    assert!(detect(&img, &strict).is_empty());
}

// The edge-profile fit of small tags (`crate::profile`) through the detector.

/// Corner RMS of the default detector with and without the profile fit, over the tags
/// both find through their refined quads (a tag read through its contour's quad, every
/// corner marked occluded, has no profile-fitted corners to compare).
fn rms_pair(beyond: f32, white: f32, sigma: f64) -> (f64, f64, usize) {
    let (mut n, mut s2_plain, mut s2_prof) = (0, 0.0, 0.0);
    for seed in 0..6 {
        let sc = scene(seed, (12.0, 32.0), beyond, white, sigma);
        let with = detect(
            &sc.img,
            &DetectorConfig {
                profile_small_tags: true,
                ..DetectorConfig::default()
            },
        );
        let without = detect(&sc.img, &DetectorConfig::default());
        for d in &with {
            let (Some((_, q)), Some(p)) = (
                sc.truth.iter().find(|t| t.0 == d.id),
                without.iter().find(|p| p.id == d.id),
            ) else {
                continue;
            };
            if d.occluded_corners == [true; 4] || p.occluded_corners == [true; 4] {
                continue;
            }
            let err = |c: &[DVec2; 4]| -> f64 {
                c.iter()
                    .map(|p| {
                        q.iter()
                            .map(|t| t.distance_squared(*p))
                            .fold(f64::MAX, f64::min)
                    })
                    .sum()
            };
            s2_prof += err(&d.corners_px);
            s2_plain += err(&p.corners_px);
            n += 4;
        }
    }
    let rms = |s2: f64| (s2 / n.max(1) as f64).sqrt();
    (rms(s2_plain), rms(s2_prof), n)
}

#[test]
fn profile_fit_removes_the_neighbouring_edges_bias() {
    for (beyond, white) in [(0.2f32, 1.0f32), (0.55, 1.0), (1.0, 0.7)] {
        for sigma in [0.6, 1.0, 1.5] {
            let (plain, prof, n) = rms_pair(beyond, white, sigma);
            eprintln!(
                "surround {beyond}, white {white}, blur {sigma}: {n} corners, RMS {plain:.3} -> {prof:.3} px"
            );
            assert!(n >= 40, "too few tags found: {n} corners");
            // Never worse beyond noise, and clearly better wherever the surround differs
            // from the ring (the measured gains are 40..50 % there).
            assert!(prof < 1.05 * plain, "{prof} vs {plain}");
            if beyond != 0.55 {
                assert!(prof < 0.75 * plain, "{prof} vs {plain}");
            }
        }
    }
}

#[test]
fn large_tags_are_left_alone() {
    let sc = scene(1, (60.0, 80.0), 0.2, 1.0, 1.0);
    let det = detect(
        &sc.img,
        &DetectorConfig {
            profile_small_tags: true,
            ..DetectorConfig::default()
        },
    );
    assert_eq!(det.len(), 6);
    for d in &det {
        assert!(refine_small_tag(&sc.img, &d.corners_px).is_none());
    }
}
