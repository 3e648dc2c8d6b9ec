//! Joint bundle adjustment over a whole session.
//!
//! # Model
//!
//! Unknowns: per image, the camera pose (`world_from_camera`) and, for images whose head was
//! posed, the head pose (`world_from_head`); for the session, the flash pose
//! (`world_from_flash`), the standard's pose (`world_from_standard`) and optionally the camera
//! intrinsics (`fx, fy, cx, cy, k1, k2, k3, p1, p2`). Poses given in `session.toml` stay fixed.
//! For the placement survey ([`crate::survey()`]) the problem also has **bodies**: a target or a
//! printed sheet whose placement in its group's frame (world or head) is unknown, with its pose
//! `group_from_body` (6 parameters) and optionally a print-scale factor `k` (1 parameter); a
//! corner given in the body's frame as `p` is at `group_from_body · (k p)`.
//! Every detected corner of every target of a known layout is one observation: its layout
//! point, moved to the world by the layout's pose (identity for the reference structure),
//! projected through the image's camera. Residuals are whitened by the corner's standard
//! deviation (floored at [`BundleConfig::sigma_floor_px`]).
//!
//! # Robust loss
//!
//! On the norm `s` of a corner's whitened residual pair: Huber (`s²` within `k`, `2ks − k²`
//! beyond) or Cauchy (`k² ln(1 + s²/k²)`), minimised by iteratively reweighted least squares.
//! A target that is wrong (misidentified, moved, or half occluded) thereby pulls with bounded
//! (Huber) or vanishing (Cauchy) force.
//!
//! # Solver
//!
//! Levenberg-Marquardt with Marquardt scaling. The normal matrix is block-sparse: each image's
//! own parameters (camera and head, at most 12) couple only to the session parameters (flash,
//! standard, intrinsics and the `7 b` parameters of `b` bodies: `g ≤ 21 + 7 b`), never to another
//! image's. The session parameters are solved on the Schur complement
//! `S = H_gg − Σ H_gl H_ll⁻¹ H_lg` and the image blocks back-substituted, so an iteration costs
//! `O(images · (12³ + 12 g²) + g³)` plus the Jacobian: per corner, central differences over the
//! at most 28 parameters it depends on (camera, head, one body, intrinsics). With the default
//! scene's 75 bodies `g ≈ 470`: the `g³/3 ≈ 35 M` flops of the Cholesky and the
//! `images · 12 g²` of the Schur products stay far below the Jacobian's cost. A step is accepted
//! only when the robust cost decreases, so the result is never worse than its input (in that
//! cost); the report gives both costs.
//!
//! # Covariance
//!
//! The inverse of the normal matrix at the solution (with the final IRLS weights) times the
//! a-posteriori variance factor `σ̂² = Σ w r² / (m − n)`: the session block is `S⁻¹`, each image
//! block `H_ll⁻¹ + H_ll⁻¹ H_lg S⁻¹ H_gl H_ll⁻¹` (exact marginals of the full inverse).

use crate::pnp::{exp_so3, PointObs};
use glam::{DVec2, DVec3};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use skinbrdf_core::{CameraModel, Pose};

/// The robust loss on a corner's whitened residual norm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RobustLoss {
    /// Quadratic within `k`, linear beyond.
    Huber,
    /// `k² ln(1 + s²/k²)`: redescending, for gross outliers.
    Cauchy,
}

impl RobustLoss {
    /// `(ρ(s), IRLS weight)` for a residual norm `s` and threshold `k`.
    pub fn eval(self, s: f64, k: f64) -> (f64, f64) {
        match self {
            Self::Huber if s > k => (2.0 * k * s - k * k, k / s),
            Self::Huber => (s * s, 1.0),
            Self::Cauchy => {
                let q = s * s / (k * k);
                (k * k * q.ln_1p(), 1.0 / (1.0 + q))
            }
        }
    }
}

/// Settings of [`bundle_adjust`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BundleConfig {
    /// Run the adjustment at the end of [`crate::estimate_session`].
    pub enabled: bool,
    /// The loss.
    pub loss: RobustLoss,
    /// Loss threshold, whitened units (standard deviations).
    pub loss_k: f64,
    /// Floor of a corner's standard deviation, pixels.
    pub sigma_floor_px: f64,
    /// Maximum LM iterations.
    pub max_iterations: usize,
    /// Refine the intrinsics too (always done when the camera was calibrated from the
    /// session's own images).
    pub refine_intrinsics: bool,
    /// Hold `k3` at its start when refining the intrinsics, as the calibration does by default
    /// (`CalibConfig::k3`): a sixth-order term no narrow field observes, which otherwise
    /// wanders with `k2` into large, nearly cancelling values.
    pub hold_k3: bool,
    /// A target of an image whose worst corner is off by more than this many sigmas (and
    /// [`GATE_MIN_PX`]) at the input is left out (the per-image estimates' outlier rule: those
    /// targets were not used there either).
    pub gate_sigma: f64,
}

/// Floor of the input gate, pixels.
pub const GATE_MIN_PX: f64 = 1.0;

impl BundleConfig {
    /// Defaults: Huber at 3 sigma, intrinsics fixed when given.
    pub const DEFAULT: Self = Self {
        enabled: true,
        loss: RobustLoss::Huber,
        loss_k: 3.0,
        sigma_floor_px: 0.05,
        max_iterations: 30,
        refine_intrinsics: false,
        hold_k3: true,
        gate_sigma: 6.0,
    };
}

impl Default for BundleConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Which frame a layout point lives in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Frame {
    /// World (reference structure).
    World,
    /// The image's head.
    Head,
    /// The flash.
    Flash,
    /// The standard.
    Standard,
    /// A body (index into [`BundleProblem::bodies`]) placed in the world.
    WorldBody(usize),
    /// A body placed in the image's head frame.
    HeadBody(usize),
}

impl Frame {
    /// The body the point belongs to, if any.
    pub const fn body(self) -> Option<usize> {
        match self {
            Self::WorldBody(b) | Self::HeadBody(b) => Some(b),
            _ => None,
        }
    }

    /// Whether the point moves with the image's head.
    pub const fn on_head(self) -> bool {
        matches!(self, Self::Head | Self::HeadBody(_))
    }
}

/// A body of the survey: a target or a printed sheet whose placement is a parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BundleBody {
    /// Starting `group_from_body`.
    pub group_from_body: Pose,
    /// Starting print-scale factor (1: as printed at nominal size).
    pub scale: f64,
    /// Whether the pose is a parameter (false: it fixes the group's gauge).
    pub free: bool,
    /// Whether the scale is a parameter.
    pub scale_free: bool,
}

/// The observations and the starting poses of one image.
#[derive(Debug, Clone)]
pub struct BundleImage {
    /// Starting `world_from_camera`.
    pub world_from_camera: Pose,
    /// Whether the camera pose is a parameter (false: given).
    pub camera_free: bool,
    /// Starting `world_from_head` (None: head targets of this image are not used).
    pub world_from_head: Option<Pose>,
    /// Whether the head pose is a parameter.
    pub head_free: bool,
    /// Observed points with their frame.
    pub points: Vec<(Frame, PointObs)>,
}

/// The session-level inputs.
#[derive(Debug, Clone)]
pub struct BundleProblem {
    /// The camera (starting intrinsics).
    pub camera: CameraModel,
    /// Per image.
    pub images: Vec<BundleImage>,
    /// Starting `world_from_flash` and whether it is a parameter.
    pub world_from_flash: Option<(Pose, bool)>,
    /// Starting `world_from_standard` and whether it is a parameter.
    pub world_from_standard: Option<(Pose, bool)>,
    /// Bodies whose placement is adjusted (the survey's targets and sheets).
    pub bodies: Vec<BundleBody>,
}

/// What the adjustment did and what it cost.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct BundleReport {
    /// Robust cost at the input.
    pub initial_cost: f64,
    /// Robust cost at the result (never above `initial_cost`).
    pub final_cost: f64,
    /// `1 − final/initial`.
    pub relative_improvement: f64,
    /// RMS reprojection error over all corners at the input, pixels.
    pub initial_rms_px: f64,
    /// The same at the result.
    pub final_rms_px: f64,
    /// Corners used.
    pub observations: usize,
    /// Corners beyond the loss threshold at the result (down-weighted).
    pub downweighted: usize,
    /// Targets (per image) left out by the input gate.
    pub gated_targets: usize,
    /// Parameters adjusted.
    pub parameters: usize,
    /// Accepted LM iterations.
    pub iterations: usize,
    /// A-posteriori variance factor.
    pub variance_factor: f64,
    /// Whether the intrinsics were adjusted.
    pub intrinsics_refined: bool,
    /// Wall time, milliseconds.
    pub time_ms: f64,
}

/// A pose with its row-major 6 x 6 covariance (empty when the pose was held fixed).
pub type PoseCov = (Pose, Vec<f64>);

/// The adjusted quantities with their covariances (row-major; poses: orientation increment
/// rad then position m, world frame).
#[derive(Debug, Clone)]
pub struct BundleResult {
    /// The camera (adjusted intrinsics when refined).
    pub camera: CameraModel,
    /// 9 x 9 covariance of `fx, fy, cx, cy, k1, k2, k3, p1, p2` (empty when fixed).
    pub intrinsics_covariance: Vec<f64>,
    /// Per image: `(world_from_camera, cov)` and `(world_from_head, cov)`; empty covariance
    /// when the pose was fixed.
    pub images: Vec<(PoseCov, Option<PoseCov>)>,
    /// Flash pose and covariance.
    pub world_from_flash: Option<PoseCov>,
    /// Standard pose and covariance.
    pub world_from_standard: Option<PoseCov>,
    /// Per body: `group_from_body` with its covariance, and the scale with its variance
    /// (0 when fixed).
    pub bodies: Vec<(PoseCov, f64, f64)>,
    /// The report.
    pub report: BundleReport,
}

const N_INTR: usize = 9;
/// `k3`'s index in the intrinsics block (`fx, fy, cx, cy, k1, k2, k3, p1, p2`).
const K3_INDEX: usize = 6;

/// Current state: all poses and the intrinsics.
#[derive(Debug, Clone)]
struct State {
    camera: CameraModel,
    cams: Vec<Pose>,
    heads: Vec<Option<Pose>>,
    flash: Option<Pose>,
    standard: Option<Pose>,
    bodies: Vec<(Pose, f64)>,
}

fn intr_get(c: &CameraModel) -> [f64; N_INTR] {
    let d = &c.distortion;
    [
        c.fx_px, c.fy_px, c.cx_px, c.cy_px, d.k1, d.k2, d.k3, d.p1, d.p2,
    ]
}

fn intr_set(c: &CameraModel, v: &[f64]) -> CameraModel {
    let mut o = *c;
    o.fx_px = v[0];
    o.fy_px = v[1];
    o.cx_px = v[2];
    o.cy_px = v[3];
    o.distortion.k1 = v[4];
    o.distortion.k2 = v[5];
    o.distortion.k3 = v[6];
    o.distortion.p1 = v[7];
    o.distortion.p2 = v[8];
    o
}

/// Applies a 6-vector increment (world-frame rotation increment, translation) to a pose.
fn apply(p: &Pose, d: &[f64]) -> Pose {
    Pose::new(
        (exp_so3(DVec3::new(d[0], d[1], d[2])) * p.rotation).normalize(),
        p.translation_m + DVec3::new(d[3], d[4], d[5]),
    )
}

/// Layout of the parameter vector.
#[derive(Debug, Clone)]
struct Layout {
    /// Per image: offset of the camera block and of the head block within the image's local
    /// vector, and the local size.
    local: Vec<(Option<usize>, Option<usize>, usize)>,
    /// Global offsets: flash, standard, intrinsics, per body (pose, scale); and the global size.
    flash: Option<usize>,
    standard: Option<usize>,
    intr: Option<usize>,
    bodies: Vec<(Option<usize>, Option<usize>)>,
    n_global: usize,
}

fn layout(p: &BundleProblem, refine_intr: bool) -> Layout {
    let local = p
        .images
        .iter()
        .map(|im| {
            let mut n = 0;
            let c = im.camera_free.then(|| {
                n += 6;
                0
            });
            let h = (im.head_free && im.world_from_head.is_some()).then(|| {
                let o = n;
                n += 6;
                o
            });
            (c, h, n)
        })
        .collect();
    let mut g = 0;
    let mut take = |on: bool, k: usize| {
        on.then(|| {
            let o = g;
            g += k;
            o
        })
    };
    let flash = take(matches!(p.world_from_flash, Some((_, true))), 6);
    let standard = take(matches!(p.world_from_standard, Some((_, true))), 6);
    let intr = take(refine_intr, N_INTR);
    let bodies = p
        .bodies
        .iter()
        .map(|b| (take(b.free, 6), take(b.scale_free, 1)))
        .collect();
    Layout {
        local,
        flash,
        standard,
        intr,
        bodies,
        n_global: g,
    }
}

/// Projects one observation under the state; `None` when behind the camera or off the model.
fn project(st: &State, i: usize, frame: Frame, obj: DVec3) -> Option<DVec2> {
    let world = match frame {
        Frame::World => obj,
        Frame::Head => st.heads[i]?.transform_point(obj),
        Frame::Flash => st.flash?.transform_point(obj),
        Frame::Standard => st.standard?.transform_point(obj),
        Frame::WorldBody(b) => {
            let (p, k) = st.bodies.get(b)?;
            p.transform_point(obj * *k)
        }
        Frame::HeadBody(b) => {
            let (p, k) = st.bodies.get(b)?;
            st.heads[i]?.transform_point(p.transform_point(obj * *k))
        }
    };
    let c = &st.cams[i];
    st.camera
        .project(c.rotation.inverse() * (world - c.translation_m))
}

/// The parameters one observation depends on: `(local offset or global offset, is_global,
/// size, which)` where `which` selects how to perturb.
#[derive(Debug, Clone, Copy)]
enum Block {
    Camera,
    Head,
    Flash,
    Standard,
    Intrinsics,
    Body(usize),
    Scale(usize),
}

impl Block {
    const fn size(self) -> usize {
        match self {
            Self::Intrinsics => N_INTR,
            Self::Scale(_) => 1,
            _ => 6,
        }
    }
}

fn perturbed(st: &State, i: usize, b: Block, k: usize, h: f64) -> State {
    let mut s = st.clone();
    let mut d = [0.0; 6];
    match b {
        Block::Camera => {
            d[k] = h;
            s.cams[i] = apply(&st.cams[i], &d);
        }
        Block::Head => {
            d[k] = h;
            s.heads[i] = st.heads[i].map(|p| apply(&p, &d));
        }
        Block::Flash => {
            d[k] = h;
            s.flash = st.flash.map(|p| apply(&p, &d));
        }
        Block::Standard => {
            d[k] = h;
            s.standard = st.standard.map(|p| apply(&p, &d));
        }
        Block::Intrinsics => {
            let mut v = intr_get(&st.camera);
            v[k] += h;
            s.camera = intr_set(&st.camera, &v);
        }
        Block::Body(b) => {
            d[k] = h;
            s.bodies[b].0 = apply(&st.bodies[b].0, &d);
        }
        Block::Scale(b) => s.bodies[b].1 += h,
    }
    s
}

/// Finite-difference steps: rotations and translations 1e-6 (rad, m); focal lengths and
/// principal point 1e-3 px; distortion coefficients 1e-6.
fn step(b: Block, k: usize) -> f64 {
    match b {
        Block::Intrinsics if k < 4 => 1e-3,
        _ => 1e-6,
    }
}

/// Per-image normal-equation pieces.
struct ImageNormal {
    h_ll: DMatrix<f64>,
    h_lg: DMatrix<f64>,
    b_l: DVector<f64>,
    h_gg: DMatrix<f64>,
    b_g: DVector<f64>,
}

struct Eval {
    cost: f64,
    sum_sq_px: f64,
    count: usize,
    weighted_sq: f64,
    downweighted: usize,
}

fn evaluate(p: &BundleProblem, st: &State, cfg: &BundleConfig) -> Option<Eval> {
    let mut e = Eval {
        cost: 0.0,
        sum_sq_px: 0.0,
        count: 0,
        weighted_sq: 0.0,
        downweighted: 0,
    };
    for (i, im) in p.images.iter().enumerate() {
        for (f, o) in &im.points {
            if f.on_head() && st.heads[i].is_none() {
                continue;
            }
            let q = project(st, i, *f, o.object_m)?;
            let r = q - o.image_px;
            let s = r.length() / o.sigma_px.max(cfg.sigma_floor_px);
            let (rho, w) = cfg.loss.eval(s, cfg.loss_k);
            e.cost += rho;
            e.weighted_sq += w * s * s;
            e.sum_sq_px += r.length_squared();
            e.count += 1;
            if s > cfg.loss_k {
                e.downweighted += 1;
            }
        }
    }
    Some(e)
}

fn blocks_of(lay: &Layout, i: usize, f: Frame) -> Vec<(Block, Option<usize>, Option<usize>)> {
    // (block, local offset, global offset)
    let (c, h, _) = lay.local[i];
    let mut v = Vec::new();
    if let Some(o) = c {
        v.push((Block::Camera, Some(o), None));
    }
    match f {
        Frame::Head => {
            if let Some(o) = h {
                v.push((Block::Head, Some(o), None));
            }
        }
        Frame::Flash => {
            if let Some(o) = lay.flash {
                v.push((Block::Flash, None, Some(o)));
            }
        }
        Frame::Standard => {
            if let Some(o) = lay.standard {
                v.push((Block::Standard, None, Some(o)));
            }
        }
        Frame::World => {}
        Frame::WorldBody(b) | Frame::HeadBody(b) => {
            if f.on_head() {
                if let Some(o) = h {
                    v.push((Block::Head, Some(o), None));
                }
            }
            if let Some((po, so)) = lay.bodies.get(b) {
                if let Some(o) = po {
                    v.push((Block::Body(b), None, Some(*o)));
                }
                if let Some(o) = so {
                    v.push((Block::Scale(b), None, Some(*o)));
                }
            }
        }
    }
    if let Some(o) = lay.intr {
        v.push((Block::Intrinsics, None, Some(o)));
    }
    v
}

fn image_normal(
    p: &BundleProblem,
    st: &State,
    lay: &Layout,
    cfg: &BundleConfig,
    i: usize,
) -> Option<ImageNormal> {
    let nl = lay.local[i].2;
    let ng = lay.n_global;
    let mut out = ImageNormal {
        h_ll: DMatrix::zeros(nl, nl),
        h_lg: DMatrix::zeros(nl, ng),
        b_l: DVector::zeros(nl),
        h_gg: DMatrix::zeros(ng, ng),
        b_g: DVector::zeros(ng),
    };
    for (f, o) in &p.images[i].points {
        if f.on_head() && st.heads[i].is_none() {
            continue;
        }
        let q0 = project(st, i, *f, o.object_m)?;
        let sigma = o.sigma_px.max(cfg.sigma_floor_px);
        let r = (q0 - o.image_px) / sigma;
        let (_, w) = cfg.loss.eval(r.length(), cfg.loss_k);
        // Jacobian columns: (local index or global index, d r / d param).
        let mut cols: Vec<(bool, usize, DVec2)> = Vec::new();
        for (b, lo, go) in blocks_of(lay, i, *f) {
            for k in 0..b.size() {
                if matches!(b, Block::Intrinsics) && cfg.hold_k3 && k == K3_INDEX {
                    continue;
                }
                let hstep = step(b, k);
                let qp = project(&perturbed(st, i, b, k, hstep), i, *f, o.object_m)?;
                let qm = project(&perturbed(st, i, b, k, -hstep), i, *f, o.object_m)?;
                let d = (qp - qm) / (2.0 * hstep * sigma);
                match (lo, go) {
                    (Some(l), _) => cols.push((false, l + k, d)),
                    (_, Some(g)) => cols.push((true, g + k, d)),
                    _ => {}
                }
            }
        }
        for (ga, a, da) in &cols {
            let ba = -w * (da.x * r.x + da.y * r.y);
            if *ga {
                out.b_g[*a] += ba;
            } else {
                out.b_l[*a] += ba;
            }
            for (gb, b, db) in &cols {
                let v = w * (da.x * db.x + da.y * db.y);
                match (*ga, *gb) {
                    (false, false) => out.h_ll[(*a, *b)] += v,
                    (false, true) => out.h_lg[(*a, *b)] += v,
                    (true, true) => out.h_gg[(*a, *b)] += v,
                    (true, false) => {}
                }
            }
        }
    }
    Some(out)
}

fn apply_step(st: &State, lay: &Layout, dl: &[DVector<f64>], dg: &DVector<f64>) -> State {
    let mut s = st.clone();
    for (i, (c, h, _)) in lay.local.iter().enumerate() {
        if let Some(o) = c {
            s.cams[i] = apply(&st.cams[i], &dl[i].as_slice()[*o..*o + 6]);
        }
        if let Some(o) = h {
            s.heads[i] = st.heads[i].map(|p| apply(&p, &dl[i].as_slice()[*o..*o + 6]));
        }
    }
    if let Some(o) = lay.flash {
        s.flash = st.flash.map(|p| apply(&p, &dg.as_slice()[o..o + 6]));
    }
    if let Some(o) = lay.standard {
        s.standard = st.standard.map(|p| apply(&p, &dg.as_slice()[o..o + 6]));
    }
    if let Some(o) = lay.intr {
        let mut v = intr_get(&st.camera);
        for (k, x) in v.iter_mut().enumerate() {
            *x += dg[o + k];
        }
        s.camera = intr_set(&st.camera, &v);
    }
    for (b, (po, so)) in lay.bodies.iter().enumerate() {
        if let Some(o) = po {
            s.bodies[b].0 = apply(&st.bodies[b].0, &dg.as_slice()[*o..*o + 6]);
        }
        if let Some(o) = so {
            s.bodies[b].1 += dg[*o];
        }
    }
    s
}

/// Marquardt damping of a symmetric block: `H + λ diag(H)` (with a tiny floor).
fn damp(h: &DMatrix<f64>, lambda: f64) -> DMatrix<f64> {
    let mut d = h.clone();
    for k in 0..h.nrows() {
        d[(k, k)] += lambda * h[(k, k)].max(1e-12);
    }
    d
}

/// Solves the block system; returns the local steps, the global step, and (when `want_cov`)
/// the marginal covariances (local blocks, global block) of the undamped system.
#[allow(clippy::type_complexity)]
fn solve(
    normals: &[ImageNormal],
    lay: &Layout,
    held: &[usize],
    lambda: f64,
) -> Option<(
    Vec<DVector<f64>>,
    DVector<f64>,
    Vec<DMatrix<f64>>,
    DMatrix<f64>,
)> {
    let ng = lay.n_global;
    let mut s = DMatrix::<f64>::zeros(ng, ng);
    let mut rhs = DVector::<f64>::zeros(ng);
    let mut inv_ll = Vec::with_capacity(normals.len());
    for n in normals {
        s += &n.h_gg;
        rhs += &n.b_g;
    }
    let s = damp(&s, lambda);
    let mut s = s;
    for n in normals {
        let nl = n.h_ll.nrows();
        let inv = if nl == 0 {
            DMatrix::zeros(0, 0)
        } else {
            damp(&n.h_ll, lambda).cholesky()?.inverse()
        };
        if ng > 0 && nl > 0 {
            let t = n.h_lg.transpose() * &inv; // ng x nl
            s -= &t * &n.h_lg;
            rhs -= &t * &n.b_l;
        }
        inv_ll.push(inv);
    }
    // A held global parameter has no Jacobian column: its row and column are zero; a unit
    // diagonal keeps the system regular and its step zero.
    for &h in held {
        s[(h, h)] = 1.0;
    }
    let (dg, s_inv) = if ng > 0 {
        let ch = s.clone().cholesky()?;
        (ch.solve(&rhs), ch.inverse())
    } else {
        (DVector::zeros(0), DMatrix::zeros(0, 0))
    };
    let mut dl = Vec::with_capacity(normals.len());
    let mut cov_l = Vec::with_capacity(normals.len());
    for (n, inv) in normals.iter().zip(&inv_ll) {
        if n.h_ll.nrows() == 0 {
            dl.push(DVector::zeros(0));
            cov_l.push(DMatrix::zeros(0, 0));
            continue;
        }
        let b = if ng > 0 {
            &n.b_l - &n.h_lg * &dg
        } else {
            n.b_l.clone()
        };
        dl.push(inv * b);
        let c = if ng > 0 {
            let a = inv * &n.h_lg; // nl x ng
            inv + &a * &s_inv * a.transpose()
        } else {
            inv.clone()
        };
        cov_l.push(c);
    }
    Some((dl, dg, cov_l, s_inv))
}

fn row_major(m: &DMatrix<f64>, off: usize, n: usize, scale: f64) -> Vec<f64> {
    let mut v = Vec::with_capacity(n * n);
    for r in 0..n {
        for c in 0..n {
            v.push(m[(off + r, off + c)] * scale);
        }
    }
    v
}

/// Adjusts every pose of the session (and optionally the intrinsics) jointly. Returns `None`
/// when the problem is empty or its normal matrix is singular at the input (the caller keeps
/// its per-image estimates).
pub fn bundle_adjust(p: &BundleProblem, cfg: &BundleConfig) -> Option<BundleResult> {
    let t0 = std::time::Instant::now();
    // Input gate: drop per-image targets the per-image estimates would call outliers.
    let mut gated_targets = 0;
    let mut gated = p.clone();
    {
        let st0 = State {
            camera: p.camera,
            cams: p.images.iter().map(|im| im.world_from_camera).collect(),
            heads: p.images.iter().map(|im| im.world_from_head).collect(),
            flash: p.world_from_flash.map(|f| f.0),
            standard: p.world_from_standard.map(|f| f.0),
            bodies: p
                .bodies
                .iter()
                .map(|b| (b.group_from_body, b.scale))
                .collect(),
        };
        for (i, im) in gated.images.iter_mut().enumerate() {
            let mut bad: Vec<(Frame, u32)> = Vec::new();
            for (f, o) in &im.points {
                let off = project(&st0, i, *f, o.object_m)
                    .map_or(f64::INFINITY, |q| q.distance(o.image_px));
                let limit = (cfg.gate_sigma * o.sigma_px.max(cfg.sigma_floor_px)).max(GATE_MIN_PX);
                if off > limit && !bad.contains(&(*f, o.target)) {
                    bad.push((*f, o.target));
                }
            }
            gated_targets += bad.len();
            im.points.retain(|(f, o)| !bad.contains(&(*f, o.target)));
            // A pose whose every observation was gated is held at its input (it would make
            // the normal matrix singular).
            if !im.points.iter().any(|(f, _)| f.on_head()) {
                im.head_free = false;
            }
            if im.points.is_empty() {
                im.camera_free = false;
            }
        }
    }
    let p = &gated;
    let lay = layout(p, cfg.refine_intrinsics);
    let held: Vec<usize> = lay
        .intr
        .filter(|_| cfg.hold_k3)
        .map(|o| o + K3_INDEX)
        .into_iter()
        .collect();
    let n_params = lay.local.iter().map(|l| l.2).sum::<usize>() + lay.n_global;
    if n_params == 0 {
        return None;
    }
    let mut st = State {
        camera: p.camera,
        cams: p.images.iter().map(|im| im.world_from_camera).collect(),
        heads: p.images.iter().map(|im| im.world_from_head).collect(),
        flash: p.world_from_flash.map(|f| f.0),
        standard: p.world_from_standard.map(|f| f.0),
        bodies: p
            .bodies
            .iter()
            .map(|b| (b.group_from_body, b.scale))
            .collect(),
    };
    let e0 = evaluate(p, &st, cfg)?;
    if e0.count == 0 {
        return None;
    }
    let mut cur = e0.cost;
    let mut lambda = 1e-4;
    let mut iterations = 0;
    let normals_at = |st: &State| -> Option<Vec<ImageNormal>> {
        (0..p.images.len())
            .into_par_iter()
            .map(|i| image_normal(p, st, &lay, cfg, i))
            .collect()
    };
    let mut normals = normals_at(&st)?;
    for _ in 0..cfg.max_iterations {
        let mut accepted = false;
        for _ in 0..10 {
            let Some((dl, dg, _, _)) = solve(&normals, &lay, &held, lambda) else {
                lambda *= 10.0;
                continue;
            };
            let cand = apply_step(&st, &lay, &dl, &dg);
            match evaluate(p, &cand, cfg) {
                Some(e) if e.cost < cur => {
                    let rel = (cur - e.cost) / cur.max(1e-300);
                    st = cand;
                    cur = e.cost;
                    lambda = (lambda * 0.3).max(1e-9);
                    accepted = true;
                    iterations += 1;
                    if rel < 1e-10 {
                        accepted = false; // converged
                    }
                    break;
                }
                _ => lambda *= 10.0,
            }
        }
        if !accepted {
            break;
        }
        normals = normals_at(&st)?;
    }
    let e1 = evaluate(p, &st, cfg)?;
    // Covariance at the solution (undamped).
    let (_, _, cov_l, cov_g) = solve(&normals, &lay, &held, 0.0)?;
    let dof = (2 * e1.count).saturating_sub(n_params).max(1);
    let vf = e1.weighted_sq / dof as f64;
    let images = p
        .images
        .iter()
        .enumerate()
        .map(|(i, _)| {
            let (c, h, _) = lay.local[i];
            let cam_cov = c.map_or_else(Vec::new, |o| row_major(&cov_l[i], o, 6, vf));
            let head = st.heads[i].map(|hp| {
                (
                    hp,
                    h.map_or_else(Vec::new, |o| row_major(&cov_l[i], o, 6, vf)),
                )
            });
            ((st.cams[i], cam_cov), head)
        })
        .collect();
    let global = |o: Option<usize>, pose: Option<Pose>| {
        pose.map(|pp| (pp, o.map_or_else(Vec::new, |o| row_major(&cov_g, o, 6, vf))))
    };
    let report = BundleReport {
        initial_cost: e0.cost,
        final_cost: e1.cost,
        relative_improvement: 1.0 - e1.cost / e0.cost.max(1e-300),
        initial_rms_px: (e0.sum_sq_px / e0.count as f64).sqrt(),
        final_rms_px: (e1.sum_sq_px / e1.count as f64).sqrt(),
        observations: e1.count,
        downweighted: e1.downweighted,
        gated_targets,
        parameters: n_params,
        iterations,
        variance_factor: vf,
        intrinsics_refined: lay.intr.is_some(),
        time_ms: t0.elapsed().as_secs_f64() * 1e3,
    };
    Some(BundleResult {
        camera: st.camera,
        intrinsics_covariance: lay.intr.map_or_else(Vec::new, |o| {
            let mut c = row_major(&cov_g, o, N_INTR, vf);
            if cfg.hold_k3 {
                c[K3_INDEX * N_INTR + K3_INDEX] = 0.0;
            }
            c
        }),
        images,
        world_from_flash: global(lay.flash, st.flash),
        world_from_standard: global(lay.standard, st.standard),
        bodies: st
            .bodies
            .iter()
            .zip(&lay.bodies)
            .map(|((pose, k), (po, so))| {
                let cov = po.map_or_else(Vec::new, |o| row_major(&cov_g, o, 6, vf));
                let var = so.map_or(0.0, |o| cov_g[(o, o)] * vf);
                ((*pose, cov), *k, var)
            })
            .collect(),
        report,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn camera() -> CameraModel {
        let mut c = CameraModel::from_fov(1524, 1012, 16f64.to_radians());
        c.distortion.k1 = -0.06;
        c
    }

    /// Reference targets on a cylinder around the origin and head targets on a small cap.
    fn square(c: DVec3, n: DVec3, s: f64) -> [DVec3; 4] {
        let x = DVec3::Z.cross(n).normalize();
        let y = n.cross(x);
        [
            c + (-x + y) * s / 2.0,
            c + (x + y) * s / 2.0,
            c + (x - y) * s / 2.0,
            c + (-x - y) * s / 2.0,
        ]
    }

    fn problem(
        noise_px: f64,
        wrong_target: bool,
        seed: u64,
    ) -> (BundleProblem, Vec<Pose>, Vec<Pose>) {
        let cam = camera();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut refs = Vec::new();
        for (k, z) in [-0.12, 0.0, 0.12].iter().enumerate() {
            for j in 0..12 {
                let a = (j as f64 * 30.0 + k as f64 * 10.0).to_radians();
                let c = DVec3::new(0.22 * a.sin(), 0.22 * a.cos(), *z);
                refs.push(square(c, DVec3::new(0.3, 1.0, 0.0).normalize(), 0.035));
            }
        }
        let mut heads_t = Vec::new();
        for j in -2..=2 {
            let a = (j as f64 * 25.0).to_radians();
            let c = DVec3::new(0.08 * a.sin(), 0.08 * a.cos(), 0.06);
            heads_t.push(square(
                c,
                DVec3::new(a.sin(), a.cos(), 0.4).normalize(),
                0.025,
            ));
        }
        let mut images = Vec::new();
        let mut cams = Vec::new();
        let mut heads = Vec::new();
        for i in 0..8 {
            let az = (-20.0 + 10.0 * i as f64).to_radians();
            let eye = DVec3::new(2.0 * az.sin(), 2.0 * az.cos(), 0.1);
            let wc = Pose::look_at(eye, DVec3::new(0.0, 0.09, 0.02), DVec3::Z).expect("look-at");
            let wh = Pose::from_rotation_vector(
                DVec3::new(0.002 * i as f64, -0.003, 0.001),
                DVec3::new(0.001, -0.0005 * i as f64, 0.0008),
            );
            let mut pts = Vec::new();
            let mut obs = |frame: Frame,
                           id: u32,
                           corners: &[DVec3; 4],
                           to_world: Pose,
                           pts: &mut Vec<(Frame, PointObs)>| {
                for c in corners {
                    let w = to_world.transform_point(*c);
                    let Some(px) = cam.project(wc.inverse().transform_point(w)) else {
                        continue;
                    };
                    if !cam.contains(px) {
                        continue;
                    }
                    let n = DVec2::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))
                        * noise_px
                        * 1.7;
                    let mut obj = *c;
                    if wrong_target && id == 3 {
                        obj.x += 0.01;
                    }
                    pts.push((
                        frame,
                        PointObs {
                            object_m: obj,
                            image_px: px + n,
                            sigma_px: noise_px,
                            target: id,
                            normal: DVec3::ZERO,
                        },
                    ));
                }
            };
            for (id, r) in refs.iter().enumerate() {
                // Only targets on the far side, beside the head (as in the layout).
                let c = (r[0] + r[2]) * 0.5;
                if c.dot(eye) > 0.0 && c.truncate().length() > 0.0 {
                    continue;
                }
                obs(Frame::World, id as u32, r, Pose::IDENTITY, &mut pts);
            }
            for (id, h) in heads_t.iter().enumerate() {
                obs(Frame::Head, 100 + id as u32, h, wh, &mut pts);
            }
            // Start from perturbed poses.
            let d = |s: f64, rng: &mut rand_chacha::ChaCha8Rng| {
                DVec3::new(
                    rng.random_range(-s..s),
                    rng.random_range(-s..s),
                    rng.random_range(-s..s),
                )
            };
            let wc0 = Pose::new(
                exp_so3(d(1e-4, &mut rng)) * wc.rotation,
                wc.translation_m + d(1e-3, &mut rng),
            );
            let wh0 = Pose::new(
                exp_so3(d(1e-3, &mut rng)) * wh.rotation,
                wh.translation_m + d(1e-3, &mut rng),
            );
            images.push(BundleImage {
                world_from_camera: wc0,
                camera_free: true,
                world_from_head: Some(wh0),
                head_free: true,
                points: pts,
            });
            cams.push(wc);
            heads.push(wh);
        }
        (
            BundleProblem {
                camera: cam,
                images,
                world_from_flash: None,
                world_from_standard: None,
                bodies: Vec::new(),
            },
            cams,
            heads,
        )
    }

    /// These problems start 1 mm / 0.06° off: no input gate.
    const UNGATED: BundleConfig = BundleConfig {
        gate_sigma: f64::INFINITY,
        ..BundleConfig::DEFAULT
    };

    fn max_head_error(r: &BundleResult, heads: &[Pose]) -> f64 {
        r.images
            .iter()
            .zip(heads)
            .map(|(im, t)| {
                im.1.as_ref()
                    .map_or(f64::INFINITY, |h| h.0.distance_to_m(t))
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn converges_from_perturbed_poses_and_lowers_the_cost() {
        let (p, cams, heads) = problem(0.05, false, 1);
        let r = bundle_adjust(&p, &UNGATED).expect("adjusted");
        assert!(r.report.final_cost < r.report.initial_cost);
        assert!(r.report.final_rms_px < 0.2, "{:?}", r.report);
        for (im, t) in r.images.iter().zip(&cams) {
            assert!(
                im.0 .0.distance_to_m(t) < 5e-4,
                "camera {}",
                im.0 .0.distance_to_m(t)
            );
        }
        assert!(max_head_error(&r, &heads) < 5e-4);
        // Covariances: 6 x 6, positive diagonal, and they cover the actual error.
        for ((im, t), h) in r.images.iter().zip(&cams).zip(&heads) {
            assert_eq!(im.0 .1.len(), 36);
            let sig = (im.0 .1[21] + im.0 .1[28] + im.0 .1[35]).sqrt();
            assert!(sig > 0.0 && im.0 .0.distance_to_m(t) < 5.0 * sig + 1e-6);
            let hh = im.1.as_ref().expect("head");
            let hs = (hh.1[21] + hh.1[28] + hh.1[35]).sqrt();
            assert!(hh.0.distance_to_m(h) < 5.0 * hs + 1e-6);
        }
    }

    #[test]
    fn never_returns_a_worse_result_than_a_perfect_input() {
        let (mut p, cams, heads) = problem(0.0, false, 2);
        for (im, (c, h)) in p.images.iter_mut().zip(cams.iter().zip(&heads)) {
            im.world_from_camera = *c;
            im.world_from_head = Some(*h);
        }
        let r = bundle_adjust(&p, &BundleConfig::DEFAULT).expect("adjusted");
        assert!(r.report.final_cost <= r.report.initial_cost);
        assert!(max_head_error(&r, &heads) < 1e-8);
    }

    #[test]
    fn robust_losses_resist_a_wrong_target() {
        for loss in [RobustLoss::Huber, RobustLoss::Cauchy] {
            let (p, _cams, heads) = problem(0.05, true, 3);
            let cfg = BundleConfig {
                loss,
                gate_sigma: f64::INFINITY,
                ..BundleConfig::DEFAULT
            };
            let r = bundle_adjust(&p, &cfg).expect("adjusted");
            assert!(
                r.report.downweighted >= 4 || r.report.gated_targets >= 1,
                "{loss:?}: {:?}",
                r.report
            );
            assert!(max_head_error(&r, &heads) < 1e-3, "{loss:?}");
        }
    }

    #[test]
    fn the_input_gate_leaves_out_a_wrong_target() {
        let (mut p, cams, heads) = problem(0.05, true, 3);
        // From the per-image estimates' accuracy (here: the truth), as in a session.
        for (im, (c, h)) in p.images.iter_mut().zip(cams.iter().zip(&heads)) {
            im.world_from_camera = *c;
            im.world_from_head = Some(*h);
        }
        let r = bundle_adjust(&p, &BundleConfig::DEFAULT).expect("adjusted");
        assert!(r.report.gated_targets >= 1, "{:?}", r.report);
        assert!(max_head_error(&r, &heads) < 1e-3);
    }

    #[test]
    fn refines_wrong_intrinsics_from_the_reference_field() {
        let (mut p, _cams, heads) = problem(0.05, false, 4);
        let truth_fx = p.camera.fx_px;
        p.camera.fx_px *= 1.01;
        p.camera.fy_px *= 1.01;
        let cfg = BundleConfig {
            refine_intrinsics: true,
            ..UNGATED
        };
        let r = bundle_adjust(&p, &cfg).expect("adjusted");
        assert!(r.report.intrinsics_refined);
        assert_eq!(r.intrinsics_covariance.len(), 81);
        let err = (r.camera.fx_px - truth_fx).abs();
        assert!(err < 0.2 * 0.01 * truth_fx, "fx error {err}");
        // k3 is held at its start, with no variance.
        assert_eq!(r.camera.distortion.k3, p.camera.distortion.k3);
        assert_eq!(r.intrinsics_covariance[K3_INDEX * N_INTR + K3_INDEX], 0.0);
        assert!(r.intrinsics_covariance[0] > 0.0);
        assert!(max_head_error(&r, &heads) < 2e-3);
    }
}
