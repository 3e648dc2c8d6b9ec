//! Multi-start, bounded, per-channel model fits with uncertainties and accuracy metrics.
//!
//! [`fit_rgb`] fits one [`ChannelModel`] to each RGB channel of a sample set:
//!
//! 1. Geometry ([`Geom`]) is computed once per sample; the residual is log-space by default
//!    (`floor = 1%` of the channel's median value, stated in the result).
//! 2. Every starting point of the model ([`ChannelModel::starting_points`], derived from the
//!    data's diffuse level and peak) is solved on a deterministic subsample of at most
//!    [`FitConfig::subsample`] samples; the best is polished on all samples. With fewer samples
//!    than that, every start runs on all of them (no polish needed).
//! 3. Parameter standard errors come from `s^2 (J^T J)^-1`, `s^2 = 2 cost / (m - n)`, computed on
//!    the diagonally scaled matrix. Its condition number is reported; parameters the data do not
//!    determine (relative standard error above [`UNIDENTIFIED_REL_SE`] or a null direction) are
//!    listed as warnings, and are an error with [`FitConfig::strict`].
//! 4. A start whose cost is not finite is skipped; if all are, or the polish does not converge,
//!    the fit fails with a typed [`FitError`].

use std::time::Instant;

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use skinbrdf_brdf::{BrdfModel, ChannelModel, Geom, ModelSpec, StartHint};
use skinbrdf_core::BrdfSample;

use crate::lm::{self, ChannelData, LmConfig, LmStatus, ResidualKind};

/// A standard error above this multiple of `max(|p|, 1)` marks a parameter as not determined.
pub const UNIDENTIFIED_REL_SE: f64 = 10.0;
/// Ratio of sample counts between polishing stages: after the multi-start subsample the best
/// start is polished on `m / 10^k`, ..., `m / 10`, then all `m` samples (stages within 2x of the
/// subsample are skipped).
pub const POLISH_GROWTH: usize = 10;
/// Solver runs (each of [`LmConfig::max_iterations`]) the final stage may use before a fit is
/// reported as not converged. Data that barely constrain some parameters (samples only near
/// grazing, say) leave a long, flat, curved valley in the cost along which LM crawls: measured
/// on the `grazing` scene (7,770 samples), the best start lowers its cost by ~1e-5 relative per
/// iteration and converges after ~400 iterations. Each continuation restarts the damping from
/// the point reached; the cost never increases between runs.
pub const FINAL_SOLVE_RUNS: usize = 5;
/// Residual floor relative to the median grey level `(r + g + b) / 3` (log residuals; one floor
/// for all channels, so a channel that is nearly zero everywhere is not blown up).
pub const LOG_FLOOR_REL_MEDIAN: f64 = 0.01;

/// Errors of a fit. All are loud: a fit either converges or says why not.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    /// Fewer samples than parameters (plus one).
    #[error("{found} usable samples cannot determine {needed} parameters")]
    TooFewSamples {
        /// Samples needed.
        needed: usize,
        /// Samples present.
        found: usize,
    },
    /// A sample has a non-finite angle, value or weight.
    #[error("sample {index} has a non-finite or negative {field}")]
    BadSample {
        /// Sample index.
        index: usize,
        /// The field.
        field: &'static str,
    },
    /// A sample's angle is outside its domain (`theta` in `[0, pi/2]`, `phi_d` in `[-2 pi, 2 pi]`).
    #[error("sample {index}: {field} = {value_rad} rad is outside [{min_rad}, {max_rad}]")]
    AngleOutOfRange {
        /// Sample index.
        index: usize,
        /// The angle (`theta_i_rad`, `theta_e_rad`, `phi_d_rad`).
        field: &'static str,
        /// Its value.
        value_rad: f64,
        /// Lowest value accepted.
        min_rad: f64,
        /// Highest value accepted.
        max_rad: f64,
    },
    /// Fewer samples with a positive weight than the model has parameters (plus one); every
    /// weight zero is the extreme case.
    #[error("only {weighted} of {samples} samples have a positive weight; {needed} are needed to determine the parameters")]
    TooFewWeighted {
        /// Samples with a positive weight.
        weighted: usize,
        /// Samples in all.
        samples: usize,
        /// Samples needed.
        needed: usize,
    },
    /// No starting point gave a finite cost.
    #[error("channel {channel}: the cost is not finite at any of the {starts} starting points")]
    NoFiniteStart {
        /// RGB channel.
        channel: usize,
        /// Starts tried.
        starts: usize,
    },
    /// The solver hit its iteration limit.
    #[error("channel {channel}: no convergence after {iterations} iterations (cost {cost:.6e})")]
    NotConverged {
        /// RGB channel.
        channel: usize,
        /// Iterations used.
        iterations: usize,
        /// Cost reached.
        cost: f64,
    },
    /// With `strict`, the data do not determine some parameters.
    #[error("channel {channel}: the samples do not determine {} (condition number {condition_number:.3e})", .params.join(", "))]
    IllConditioned {
        /// RGB channel.
        channel: usize,
        /// The undetermined parameters.
        params: Vec<String>,
        /// Condition number of the scaled `J^T J`.
        condition_number: f64,
    },
    /// The model rejected the fitted parameters.
    #[error("fitted parameters rejected")]
    Model(#[from] skinbrdf_brdf::BrdfError),
}

/// How a fit runs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FitConfig {
    /// Residual form; `None` = log space with the automatic floor.
    pub residual: Option<ResidualKind>,
    /// Solver settings.
    pub lm: LmConfig,
    /// Samples used for the multi-start stage.
    pub subsample: usize,
    /// Fail on undetermined parameters instead of warning.
    pub strict: bool,
    /// Log-residual floor relative to each channel's median value (when `residual` is `None`).
    pub log_floor_rel_median: f64,
}

impl Default for FitConfig {
    fn default() -> Self {
        Self {
            residual: None,
            lm: LmConfig::default(),
            subsample: 20_000,
            strict: false,
            log_floor_rel_median: LOG_FLOOR_REL_MEDIAN,
        }
    }
}

/// The outcome of one starting point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StartOutcome {
    /// Starting parameters.
    pub start: Vec<f64>,
    /// Final cost on the subsample (`None` if not finite).
    pub cost: Option<f64>,
    /// Iterations.
    pub iterations: usize,
    /// Status.
    pub status: Option<LmStatus>,
}

/// What one stage of a channel fit does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FitStageKind {
    /// Residual targets, start hints and the multi-start subsample.
    Prepare,
    /// Every starting point solved on the subsample.
    Multistart,
    /// The best start solved again on a larger subsample, or on all samples.
    Polish,
    /// The fitted model's error against all samples.
    ErrorMetrics,
}

/// One stage of a channel fit: what it ran on, what it reached, what it cost.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageReport {
    /// What the stage does.
    pub kind: FitStageKind,
    /// Samples the stage ran on.
    pub samples: usize,
    /// Solver runs (starts) in the stage.
    pub solves: usize,
    /// Iterations summed over the solves.
    pub iterations: usize,
    /// Passes over the stage's samples summed over the solves.
    pub evaluations: usize,
    /// Best final cost of the stage (on its own samples; `None` for `prepare`).
    pub cost: Option<f64>,
    /// Wall time, seconds.
    pub seconds: f64,
}

/// One channel's fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelFit {
    /// Fitted parameters (model parametrisation).
    pub params: Vec<f64>,
    /// Standard errors (`None` where undetermined).
    pub std_errors: Vec<Option<f64>>,
    /// Final cost `0.5 sum r^2` on all samples.
    pub cost: f64,
    /// Root-mean-square residual.
    pub rms_residual: f64,
    /// Iterations of the final solve.
    pub iterations: usize,
    /// Why the final solve stopped.
    pub status: LmStatus,
    /// Condition number of the diagonally scaled `J^T J`; `None` when the matrix is singular
    /// (the condition number is infinite: see `unidentified`).
    pub condition_number: Option<f64>,
    /// Parameters the data do not determine.
    pub unidentified: Vec<String>,
    /// The multi-start outcomes.
    pub starts: Vec<StartOutcome>,
    /// The stages of the fit (multi-start on a subsample, then polishing on growing
    /// subsamples up to all samples), each with its cost and time.
    #[serde(default)]
    pub stages: Vec<StageReport>,
    /// Accuracy against the samples.
    pub error: ErrorMetrics,
}

/// Fit error against reference values.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct ErrorMetrics {
    /// RMS of `ln(f + floor) - ln(y + floor)`.
    pub log_rmse: f64,
    /// Median of `|f - y| / y` over samples with `y > floor`.
    pub median_rel_err: f64,
    /// Samples compared.
    pub count: usize,
}

/// A fitted RGB model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RgbFit {
    /// Model name (`lafortune2`, ...).
    pub model_name: String,
    /// Parameter names (per channel).
    pub param_names: Vec<String>,
    /// The fitted model.
    pub model: BrdfModel,
    /// Per channel results.
    pub channels: Vec<ChannelFit>,
    /// The residual used per channel.
    pub residuals: Vec<ResidualKind>,
    /// Samples fitted.
    pub n_samples: usize,
    /// Wall time of the fit, seconds.
    pub fit_time_s: f64,
    /// Things the user should know (undetermined parameters, iteration limits).
    pub warnings: Vec<String>,
}

/// Geometry, values and weights in f64, validated.
#[derive(Debug, Clone)]
pub struct FitData {
    /// Geometry per sample.
    pub geom: Vec<Geom>,
    /// Values per channel, 1/sr.
    pub y: [Vec<f64>; 3],
    /// `sqrt(weight)` per sample.
    pub sqrt_w: Vec<f64>,
}

impl FitData {
    /// Converts samples, rejecting non-finite fields, negative weights and angles outside their
    /// domain (see [`check_angles`]). A partial sample (a channel it did not measure is NaN,
    /// [`BrdfSample::measured`]) is kept; a sample measuring no channel, or with an infinite
    /// `rho`, is refused. Each channel is fitted to the samples that measured it
    /// ([`FitData::channel`]).
    pub fn from_samples(samples: &[BrdfSample]) -> Result<Self, FitError> {
        let mut geom = Vec::with_capacity(samples.len());
        let mut y: [Vec<f64>; 3] = std::array::from_fn(|_| Vec::with_capacity(samples.len()));
        let mut sqrt_w = Vec::with_capacity(samples.len());
        for (index, s) in samples.iter().enumerate() {
            if ![s.theta_i_rad, s.theta_e_rad, s.phi_d_rad]
                .iter()
                .all(|v| v.is_finite())
            {
                return Err(FitError::BadSample {
                    index,
                    field: "angle",
                });
            }
            check_angles(index, s)?;
            if s.rho.iter().any(|v| v.is_infinite()) || s.rho.iter().all(|v| v.is_nan()) {
                return Err(FitError::BadSample {
                    index,
                    field: "rho",
                });
            }
            if !(s.weight.is_finite() && s.weight >= 0.0) {
                return Err(FitError::BadSample {
                    index,
                    field: "weight",
                });
            }
            geom.push(Geom::from_angles(
                f64::from(s.theta_i_rad),
                f64::from(s.theta_e_rad),
                f64::from(s.phi_d_rad),
            ));
            for (c, yc) in y.iter_mut().enumerate() {
                yc.push(f64::from(s.rho[c]));
            }
            sqrt_w.push(f64::from(s.weight).sqrt());
        }
        Ok(Self { geom, y, sqrt_w })
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.geom.len()
    }

    /// True when some sample did not measure channel `c`.
    pub fn is_partial(&self, c: usize) -> bool {
        self.y.get(c).is_some_and(|y| y.iter().any(|v| v.is_nan()))
    }

    /// The samples that measured channel `c` (all of them, borrowed, when none is partial
    /// there); the other channels' values are carried along and may be NaN.
    pub fn channel(&self, c: usize) -> std::borrow::Cow<'_, Self> {
        if !self.is_partial(c) {
            return std::borrow::Cow::Borrowed(self);
        }
        let keep: Vec<usize> = (0..self.len())
            .filter(|&i| !self.y[c][i].is_nan())
            .collect();
        std::borrow::Cow::Owned(Self {
            geom: keep.iter().map(|&i| self.geom[i]).collect(),
            y: std::array::from_fn(|k| keep.iter().map(|&i| self.y[k][i]).collect()),
            sqrt_w: keep.iter().map(|&i| self.sqrt_w[i]).collect(),
        })
    }

    /// Per sample, the mean of the channels it measured (the grey level the log floor is
    /// taken from).
    fn grey(&self) -> Vec<f64> {
        (0..self.len())
            .map(|i| {
                let (sum, n) = (0..3)
                    .map(|c| self.y[c][i])
                    .filter(|v| !v.is_nan())
                    .fold((0.0, 0u32), |(s, n), v| (s + v, n + 1));
                sum / f64::from(n.max(1))
            })
            .collect()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.geom.is_empty()
    }
}

/// Slack on the angle domains: the samples store angles as `f32`, and a direction on the
/// horizon may round a little past `pi/2`.
pub const ANGLE_DOMAIN_SLACK_RAD: f64 = 1e-4;

/// Checks a sample's angles against their domains: `theta_i`, `theta_e` in `[0, pi/2]` (the
/// hemisphere above the surface) and `phi_d` in `[-2 pi, 2 pi]` (any azimuth convention), each
/// with [`ANGLE_DOMAIN_SLACK_RAD`]. An angle outside is a unit or column mix-up, not data.
pub fn check_angles(index: usize, s: &BrdfSample) -> Result<(), FitError> {
    use std::f64::consts::{FRAC_PI_2, TAU};
    let e = ANGLE_DOMAIN_SLACK_RAD;
    for (field, v, lo, hi) in [
        ("theta_i_rad", s.theta_i_rad, 0.0, FRAC_PI_2),
        ("theta_e_rad", s.theta_e_rad, 0.0, FRAC_PI_2),
        ("phi_d_rad", s.phi_d_rad, -TAU, TAU),
    ] {
        let v = f64::from(v);
        if !(lo - e..=hi + e).contains(&v) {
            return Err(FitError::AngleOutOfRange {
                index,
                field,
                value_rad: v,
                min_rad: lo,
                max_rad: hi,
            });
        }
    }
    Ok(())
}

pub(crate) fn quantile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mut s: Vec<f64> = v.to_vec();
    let k = ((s.len() - 1) as f64 * q).round() as usize;
    let (_, x, _) = s.select_nth_unstable_by(k, f64::total_cmp);
    *x
}

/// The automatic log-residual floor of a channel.
pub fn auto_floor(y: &[f64], rel_median: f64) -> f64 {
    (rel_median * quantile(y, 0.5)).max(1e-9)
}

/// Error metrics of `model` channel `c` against values `y` at `geom`.
pub fn error_metrics(f: impl Fn(usize) -> f64 + Sync, y: &[f64], floor: f64) -> ErrorMetrics {
    use rayon::prelude::*;
    let (sq, rels): (f64, Vec<f64>) = (0..y.len())
        .into_par_iter()
        .map(|i| {
            let fi = f(i);
            let d = (fi.max(0.0) + floor).ln() - (y[i].max(0.0) + floor).ln();
            let rel = if y[i] > floor {
                Some((fi - y[i]).abs() / y[i])
            } else {
                None
            };
            (d * d, rel)
        })
        .fold(
            || (0.0, Vec::new()),
            |mut acc, (d2, rel)| {
                acc.0 += d2;
                if let Some(r) = rel {
                    acc.1.push(r);
                }
                acc
            },
        )
        .reduce(
            || (0.0, Vec::new()),
            |mut a, mut b| {
                a.0 += b.0;
                a.1.append(&mut b.1);
                a
            },
        );
    ErrorMetrics {
        log_rmse: if y.is_empty() {
            0.0
        } else {
            (sq / y.len() as f64).sqrt()
        },
        median_rel_err: quantile(&rels, 0.5),
        count: y.len(),
    }
}

/// A [`ChannelFit::condition_number`] as text: `1.23e4`, or `infinite` for a singular matrix.
pub fn condition_text(condition_number: Option<f64>) -> String {
    condition_number.map_or_else(|| "infinite".to_string(), |c| format!("{c:.2e}"))
}

/// Standard errors and identifiability from `J^T J`.
fn uncertainties(
    jtj: &DMatrix<f64>,
    cost: f64,
    m: usize,
    names: &[String],
    params: &[f64],
) -> (Vec<Option<f64>>, f64, Vec<String>) {
    let n = jtj.nrows();
    let dof = m.saturating_sub(n).max(1) as f64;
    let s2 = 2.0 * cost / dof;
    let d: Vec<f64> = (0..n).map(|j| jtj[(j, j)].max(0.0).sqrt()).collect();
    let dmax = d.iter().cloned().fold(0.0, f64::max);
    let mut scaled = jtj.clone();
    for r in 0..n {
        for c in 0..n {
            let den = d[r] * d[c];
            scaled[(r, c)] = if den > 0.0 {
                jtj[(r, c)] / den
            } else if r == c {
                1.0
            } else {
                0.0
            };
        }
    }
    let eig = scaled.clone().symmetric_eigen();
    let lmax = eig.eigenvalues.iter().cloned().fold(0.0, f64::max);
    let lmin = eig
        .eigenvalues
        .iter()
        .cloned()
        .fold(f64::INFINITY, f64::min);
    let condition = if lmin > 0.0 {
        lmax / lmin
    } else {
        f64::INFINITY
    };
    // Pseudo-inverse of the scaled matrix, dropping null directions.
    let cut = lmax * 1e-14;
    let mut inv = DMatrix::zeros(n, n);
    let mut null_mass = vec![0.0; n];
    for k in 0..n {
        let l = eig.eigenvalues[k];
        let v = eig.eigenvectors.column(k);
        if l > cut {
            inv += (v * v.transpose()) / l;
        } else {
            for j in 0..n {
                null_mass[j] += v[j] * v[j];
            }
        }
    }
    let mut se = Vec::with_capacity(n);
    let mut unidentified = Vec::new();
    for j in 0..n {
        let val = if d[j] > 1e-12 * dmax.max(1e-300) && null_mass[j] < 0.5 {
            Some((s2 * inv[(j, j)]).max(0.0).sqrt() / d[j])
        } else {
            None
        };
        let bad = match val {
            None => true,
            Some(v) => !v.is_finite() || v > UNIDENTIFIED_REL_SE * params[j].abs().max(1.0),
        };
        if bad {
            unidentified.push(names[j].clone());
        }
        se.push(val.filter(|v| v.is_finite()));
    }
    (se, condition, unidentified)
}

/// Deterministic, evenly strided subsample indices.
fn stride_indices(m: usize, k: usize) -> Vec<usize> {
    if m <= k {
        return (0..m).collect();
    }
    (0..k)
        .map(|i| ((i as u128 * m as u128) / k as u128) as usize)
        .collect()
}

/// One or more solver runs continuing each other.
struct Runs {
    /// The last run's outcome.
    outcome: lm::LmOutcome,
    /// Runs made.
    solves: usize,
    /// Iterations summed over the runs.
    iterations: usize,
    /// Passes over the data summed over the runs.
    evaluations: usize,
}

impl Runs {
    fn single(outcome: lm::LmOutcome) -> Self {
        Self {
            solves: 1,
            iterations: outcome.iterations,
            evaluations: outcome.evaluations,
            outcome,
        }
    }
}

/// Relative cost difference below which two multistart results on the subsample count as tied:
/// the relative standard error of a sum of squares over the 20k-sample subsample is about
/// `sqrt(2 / 20000)` = 1 %, so costs 0.2 % apart say nothing about which basin is better.
pub const START_TIE_REL: f64 = 2e-3;

/// Whether multistart result `o` should replace the best so far `b`: a clearly lower cost, or a
/// tie ([`START_TIE_REL`]) reached in fewer iterations. Among tied starts the one that converged
/// fastest lies in the better-conditioned basin; one that crept along a flat valley (a
/// near-degenerate lobe) to a cost lower by less than the subsample's noise made the polish on
/// all samples walk the same valley: 384 iterations and 11 s on the demo session's samples
/// against 12 iterations, for the same median error to 1e-8.
fn better_start(o: &lm::LmOutcome, b: &lm::LmOutcome) -> bool {
    let tied = (o.cost - b.cost).abs() <= START_TIE_REL * b.cost.abs().max(1e-300);
    if tied {
        o.iterations < b.iterations
    } else {
        o.cost < b.cost
    }
}

/// Solves from `p0`, continuing from the point reached while a run stops at its iteration limit,
/// up to [`FINAL_SOLVE_RUNS`] runs.
fn solve_to_convergence(
    model: &dyn ChannelModel,
    p0: &[f64],
    data: &ChannelData<'_>,
    cfg: &LmConfig,
) -> Option<Runs> {
    let mut runs = Runs::single(lm::solve(model, p0, data, cfg)?);
    while !runs.outcome.status.converged() && runs.solves < FINAL_SOLVE_RUNS {
        let next = lm::solve(model, &runs.outcome.params, data, cfg)?;
        runs.solves += 1;
        runs.iterations += next.iterations;
        runs.evaluations += next.evaluations;
        runs.outcome = next;
    }
    Some(runs)
}

/// Fits one channel.
pub fn fit_channel(
    model: &dyn ChannelModel,
    data: &FitData,
    channel: usize,
    cfg: &FitConfig,
) -> Result<(ChannelFit, ResidualKind), FitError> {
    let floor = auto_floor(&data.grey(), cfg.log_floor_rel_median);
    fit_channel_with_floor(model, &data.channel(channel), channel, cfg, floor)
}

fn fit_channel_with_floor(
    model: &dyn ChannelModel,
    data: &FitData,
    channel: usize,
    cfg: &FitConfig,
    floor: f64,
) -> Result<(ChannelFit, ResidualKind), FitError> {
    let m = data.len();
    let n = model.n_params();
    if m < n + 1 {
        return Err(FitError::TooFewSamples {
            needed: n + 1,
            found: m,
        });
    }
    let weighted = data.sqrt_w.iter().filter(|&&w| w > 0.0).count();
    if weighted < n + 1 {
        return Err(FitError::TooFewWeighted {
            weighted,
            samples: m,
            needed: n + 1,
        });
    }
    let y = &data.y[channel];
    let residual = cfg
        .residual
        .unwrap_or(ResidualKind::Log { floor_rho: floor });
    let t_prep = Instant::now();
    let target = lm::transform_target(residual, &data.geom, y);
    let full = ChannelData {
        geom: &data.geom,
        target: &target,
        sqrt_w: &data.sqrt_w,
        residual,
    };
    let hint = StartHint {
        diffuse_rho: quantile(y, 0.25).max(0.0),
        peak_rho: quantile(y, 0.999).max(0.0),
    };
    let idx = stride_indices(m, cfg.subsample);
    let sub_owned = (idx.len() < m).then(|| {
        (
            idx.iter().map(|&i| data.geom[i]).collect::<Vec<_>>(),
            idx.iter().map(|&i| target[i]).collect::<Vec<_>>(),
            idx.iter().map(|&i| data.sqrt_w[i]).collect::<Vec<_>>(),
        )
    });
    let sub = match &sub_owned {
        Some((g, t, w)) => ChannelData {
            geom: g,
            target: t,
            sqrt_w: w,
            residual,
        },
        None => full,
    };
    let starts = model.starting_points(&hint);
    let mut stages = vec![StageReport {
        kind: FitStageKind::Prepare,
        samples: m,
        solves: 0,
        iterations: 0,
        evaluations: 0,
        cost: None,
        seconds: t_prep.elapsed().as_secs_f64(),
    }];
    let t_stage = Instant::now();
    let (mut iters, mut evals) = (0, 0);
    let mut outcomes = Vec::with_capacity(starts.len());
    let mut best: Option<lm::LmOutcome> = None;
    for s in &starts {
        let r = lm::solve(model, s, &sub, &cfg.lm);
        outcomes.push(StartOutcome {
            start: s.clone(),
            cost: r.as_ref().map(|o| o.cost),
            iterations: r.as_ref().map_or(0, |o| o.iterations),
            status: r.as_ref().map(|o| o.status),
        });
        if let Some(o) = r {
            iters += o.iterations;
            evals += o.evaluations;
            if best.as_ref().is_none_or(|b| better_start(&o, b)) {
                best = Some(o);
            }
        }
    }
    let mut best = best.ok_or(FitError::NoFiniteStart {
        channel,
        starts: starts.len(),
    })?;
    stages.push(StageReport {
        kind: FitStageKind::Multistart,
        samples: idx.len(),
        solves: starts.len(),
        iterations: iters,
        evaluations: evals,
        cost: Some(best.cost),
        seconds: t_stage.elapsed().as_secs_f64(),
    });
    // Polish through growing subsamples (x POLISH_GROWTH each) so that most iterations run on
    // few samples and the full set only confirms the last steps.
    let mut sizes = vec![m];
    while sizes[sizes.len() - 1] / POLISH_GROWTH > idx.len() * 2 {
        sizes.push(sizes[sizes.len() - 1] / POLISH_GROWTH);
    }
    if idx.len() == m {
        sizes.clear();
        if !best.status.converged() {
            // No polishing stage: the best start itself is continued on all samples.
            sizes.push(m);
        }
    }
    for size in sizes.into_iter().rev() {
        let t_stage = Instant::now();
        let stage = if size < m {
            let idx = stride_indices(m, size);
            let (g, t, w) = (
                idx.iter().map(|&i| data.geom[i]).collect::<Vec<_>>(),
                idx.iter().map(|&i| target[i]).collect::<Vec<_>>(),
                idx.iter().map(|&i| data.sqrt_w[i]).collect::<Vec<_>>(),
            );
            let cd = ChannelData {
                geom: &g,
                target: &t,
                sqrt_w: &w,
                residual,
            };
            lm::solve(model, &best.params, &cd, &cfg.lm).map(Runs::single)
        } else {
            solve_to_convergence(model, &best.params, &full, &cfg.lm)
        };
        let Runs {
            outcome,
            solves,
            iterations,
            evaluations,
        } = stage.ok_or(FitError::NoFiniteStart { channel, starts: 1 })?;
        best = outcome;
        stages.push(StageReport {
            kind: FitStageKind::Polish,
            samples: size,
            solves,
            iterations,
            evaluations,
            cost: Some(best.cost),
            seconds: t_stage.elapsed().as_secs_f64(),
        });
    }
    let fin = best;
    if !fin.status.converged() {
        return Err(FitError::NotConverged {
            channel,
            iterations: stages.last().map_or(fin.iterations, |s| s.iterations),
            cost: fin.cost,
        });
    }
    let names = model.param_names();
    let (std_errors, condition_number, unidentified) =
        uncertainties(&fin.jtj, fin.cost, m, &names, &fin.params);
    if cfg.strict && !unidentified.is_empty() {
        return Err(FitError::IllConditioned {
            channel,
            params: unidentified,
            condition_number,
        });
    }
    let t_stage = Instant::now();
    let fitted = lm::eval_all(model, &fin.params, &data.geom);
    let error = error_metrics(|i| fitted[i], y, floor);
    stages.push(StageReport {
        kind: FitStageKind::ErrorMetrics,
        samples: m,
        solves: 0,
        iterations: 0,
        evaluations: 1,
        cost: Some(fin.cost),
        seconds: t_stage.elapsed().as_secs_f64(),
    });
    Ok((
        ChannelFit {
            params: fin.params.clone(),
            std_errors,
            cost: fin.cost,
            rms_residual: (2.0 * fin.cost / m as f64).sqrt(),
            iterations: fin.iterations,
            status: fin.status,
            condition_number: Some(condition_number).filter(|c| c.is_finite()),
            unidentified,
            starts: outcomes,
            stages,
            error,
        },
        residual,
    ))
}

/// The fit stage's result: the fitted model with its per-channel metrics, and the stage's time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Fitted {
    /// The fit.
    pub fit: RgbFit,
    /// Wall time of the stage (sample validation and the fit), seconds.
    pub run_time_s: f64,
}

/// The fit stage: fits `model` to every RGB channel of `samples`.
pub fn fit_model(
    samples: &[BrdfSample],
    cfg: &FitConfig,
    model: ModelSpec,
) -> Result<Fitted, FitError> {
    let t = Instant::now();
    let fit = fit_rgb(model.channel_model().as_ref(), samples, cfg)?;
    Ok(Fitted {
        fit,
        run_time_s: t.elapsed().as_secs_f64(),
    })
}

/// Fits a model to every RGB channel of `samples`.
pub fn fit_rgb(
    model: &dyn ChannelModel,
    samples: &[BrdfSample],
    cfg: &FitConfig,
) -> Result<RgbFit, FitError> {
    let data = FitData::from_samples(samples)?;
    fit_data(model, &data, cfg)
}

/// Fits a model to every channel of prepared data.
pub fn fit_data(
    model: &dyn ChannelModel,
    data: &FitData,
    cfg: &FitConfig,
) -> Result<RgbFit, FitError> {
    let t0 = Instant::now();
    let mut channels = Vec::with_capacity(3);
    let mut residuals = Vec::with_capacity(3);
    let mut warnings = Vec::new();
    let floor = auto_floor(&data.grey(), cfg.log_floor_rel_median);
    // The three channels run in parallel (each solve is itself parallel over sample chunks;
    // on small subsamples the channel level is what keeps both cores busy).
    use rayon::prelude::*;
    let fits = (0..3)
        .into_par_iter()
        .map(|c| fit_channel_with_floor(model, &data.channel(c), c, cfg, floor))
        .collect::<Result<Vec<_>, _>>()?;
    for (c, (fit, res)) in fits.into_iter().enumerate() {
        if !fit.unidentified.is_empty() {
            warnings.push(format!(
                "channel {c}: the samples do not determine {} (condition number {}); their values are arbitrary within a valley of equal cost",
                fit.unidentified.join(", "),
                condition_text(fit.condition_number)
            ));
        }
        channels.push(fit);
        residuals.push(res);
    }
    let params: [Vec<f64>; 3] = std::array::from_fn(|c| channels[c].params.clone());
    let brdf = model.to_model(&params)?;
    Ok(RgbFit {
        model_name: model.name(),
        param_names: model.param_names(),
        model: brdf,
        channels,
        residuals,
        n_samples: data.len(),
        fit_time_s: t0.elapsed().as_secs_f64(),
        warnings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinbrdf_brdf::LafortuneFit;
    use skinbrdf_core::BrdfAngles;
    use skinbrdf_samples::{CornellBrdf, Illuminant};
    use std::path::{Path, PathBuf};

    fn cornell(name: &str) -> Vec<BrdfSample> {
        let p: PathBuf = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../../shared/data/cornell")
            .join(name);
        let b = CornellBrdf::read(&p).expect("read");
        let conv = b.rgb_converter(Illuminant::D65, &p).expect("conv");
        b.to_rgb_samples(&conv)
    }

    /// Samples of a known model on a regular grid of angles (plus a dense band around the mirror
    /// direction so that narrow lobes are resolved).
    pub(crate) fn synthetic(
        model: &BrdfModel,
        ti_range: (f64, f64),
        te_range: (f64, f64),
        n: usize,
    ) -> Vec<BrdfSample> {
        let mut out = Vec::new();
        for a in 0..n {
            let ti = ti_range.0 + (ti_range.1 - ti_range.0) * (a as f64 + 0.5) / n as f64;
            for b in 0..n {
                let te = te_range.0 + (te_range.1 - te_range.0) * (b as f64 + 0.5) / n as f64;
                for k in 0..n {
                    let pd = std::f64::consts::PI * k as f64 / (n - 1) as f64;
                    let (wi, we) = BrdfAngles::canonical_directions(ti, te, pd);
                    let rho = model.eval(wi, we).map(|v| v as f32);
                    out.push(BrdfSample::from_angles(
                        &BrdfAngles::from_local(wi, we),
                        rho,
                    ));
                }
                // Near-mirror band: te = ti +- small offsets on the mirror side.
                for d in [-0.02, -0.01, -0.005, 0.0, 0.005, 0.01, 0.02] {
                    let te2 = (ti + d).clamp(0.0, 1.55);
                    for pd in [
                        std::f64::consts::PI,
                        std::f64::consts::PI - 0.01,
                        std::f64::consts::PI - 0.03,
                    ] {
                        let (wi, we) = BrdfAngles::canonical_directions(ti, te2, pd);
                        let rho = model.eval(wi, we).map(|v| v as f32);
                        out.push(BrdfSample::from_angles(
                            &BrdfAngles::from_local(wi, we),
                            rho,
                        ));
                    }
                }
            }
        }
        out
    }

    #[test]
    fn unusable_data_is_an_error_not_a_fit() {
        let truth = BrdfModel::Lambertian { albedo: [0.5; 3] };
        let good = synthetic(&truth, (0.1, 1.2), (0.1, 1.2), 6);
        let model = ModelSpec::Lambertian.channel_model();
        let cfg = FitConfig::default();
        assert!(fit_rgb(model.as_ref(), &good, &cfg).is_ok());

        let mut zero = good.clone();
        for s in &mut zero {
            s.weight = 0.0;
        }
        let e = fit_rgb(model.as_ref(), &zero, &cfg).expect_err("all weights zero");
        assert!(
            matches!(e, FitError::TooFewWeighted { weighted: 0, .. }),
            "{e}"
        );

        let mut bad = good.clone();
        bad[5].theta_i_rad = 7.0;
        let e = fit_rgb(model.as_ref(), &bad, &cfg).expect_err("theta = 7 rad");
        assert!(
            matches!(
                e,
                FitError::AngleOutOfRange {
                    index: 5,
                    field: "theta_i_rad",
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("7 rad"), "{e}");
    }

    /// The stated error bound of one Cornell material's 2-lobe Lafortune fit.
    struct CornellBound {
        file: &'static str,
        /// The channel that carries the paint's colour (largest median).
        dominant: usize,
        /// Log-RMSE bound on the dominant channel.
        dominant_log_rmse: f64,
        /// Median relative error bound on the dominant channel.
        dominant_median_rel: f64,
        /// Log-RMSE bound on every channel.
        any_log_rmse: f64,
    }

    /// Per-material bounds on the Cornell fits of a 2-lobe Lafortune model: the measured values
    /// (docs/fitting.md) plus ~10% headroom. A paint is not exactly Lafortune and its diffuse
    /// level falls towards grazing, so these are model-error bounds; the weak channels of a
    /// saturated paint are near zero and partly gamut-mapped, hence the looser bound on them.
    const CORNELL_BOUNDS: [CornellBound; 2] = [
        CornellBound {
            file: "garnet_red.brdf",
            dominant: 0,
            dominant_log_rmse: 0.44,
            dominant_median_rel: 0.13,
            any_log_rmse: 0.95,
        },
        CornellBound {
            file: "krylon_blue.brdf",
            dominant: 2,
            dominant_log_rmse: 0.53,
            dominant_median_rel: 0.17,
            any_log_rmse: 0.81,
        },
    ];

    #[test]
    fn cornell_files_fit_within_the_stated_error() {
        // Every file of the data directory has a bound.
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/cornell");
        let mut files: Vec<String> = std::fs::read_dir(&dir)
            .expect("cornell dir")
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".brdf"))
            .collect();
        files.sort();
        let mut bounded: Vec<String> = CORNELL_BOUNDS.iter().map(|b| b.file.into()).collect();
        bounded.sort();
        assert_eq!(files, bounded, "a Cornell file without a stated bound");
        for b in &CORNELL_BOUNDS {
            let samples = cornell(b.file);
            let fit =
                fit_rgb(&LafortuneFit::standard(2), &samples, &FitConfig::default()).expect("fit");
            let d = fit.channels[b.dominant].error;
            assert!(
                d.log_rmse < b.dominant_log_rmse && d.median_rel_err < b.dominant_median_rel,
                "{}: {d:?}",
                b.file
            );
            for c in &fit.channels {
                assert!(
                    c.error.log_rmse < b.any_log_rmse,
                    "{}: {:?}",
                    b.file,
                    c.error
                );
                assert!(c.status.converged());
            }
            // The fitted model must beat the Lambertian one on the dominant channel.
            let lam = fit_rgb(
                &skinbrdf_brdf::LambertianFit,
                &samples,
                &FitConfig::default(),
            )
            .expect("fit");
            assert!(lam.channels[b.dominant].error.log_rmse > 1.3 * d.log_rmse);
        }
    }

    #[test]
    #[ignore = "prints the per-material table for docs/fitting.md; run with --ignored --nocapture"]
    fn cornell_table() {
        for name in ["garnet_red.brdf", "krylon_blue.brdf"] {
            let samples = cornell(name);
            for spec in [
                "lambertian",
                "lafortune1",
                "lafortune2",
                "lafortune3",
                "cook-torrance",
            ] {
                let model = spec.parse::<ModelSpec>().expect("spec").channel_model();
                let fit = fit_rgb(model.as_ref(), &samples, &FitConfig::default()).expect("fit");
                let e: Vec<String> = fit
                    .channels
                    .iter()
                    .map(|c| format!("{:.3} / {:.3}", c.error.log_rmse, c.error.median_rel_err))
                    .collect();
                println!(
                    "| {name} | {spec} | {} | {:.3} | {:?} |",
                    e.join(" | "),
                    fit.fit_time_s,
                    fit.warnings.len()
                );
            }
        }
    }

    #[test]
    fn staged_polishing_reaches_the_optimum_on_all_samples() {
        let (_, samples) = crate::synthetic::lafortune2_samples(100_000, 0.05, 11);
        let data = FitData::from_samples(&samples).expect("data");
        let model = LafortuneFit::standard(2);
        let cfg = FitConfig {
            subsample: 1_000,
            ..FitConfig::default()
        };
        let fit = fit_data(&model, &data, &cfg).expect("fit");
        for (c, ch) in fit.channels.iter().enumerate() {
            let sizes: Vec<usize> = ch.stages.iter().map(|s| s.samples).collect();
            assert_eq!(sizes, [100_000, 1_000, 10_000, 100_000, 100_000], "{c}");
            // A fresh solve on all samples from the result finds no lower cost.
            let target = lm::transform_target(fit.residuals[c], &data.geom, &data.y[c]);
            let cd = ChannelData {
                geom: &data.geom,
                target: &target,
                sqrt_w: &data.sqrt_w,
                residual: fit.residuals[c],
            };
            let again = lm::solve(&model, &ch.params, &cd, &LmConfig::default()).expect("solve");
            assert!(
                again.cost >= ch.cost * (1.0 - 1e-10),
                "channel {c}: {} then {}",
                ch.cost,
                again.cost
            );
            // And the truth is recovered (5% noise, 1e5 samples).
            let truth = &crate::synthetic::bench_truth_params()[c];
            assert!((ch.params[3] - truth[3]).abs() < 0.01, "{:?}", ch.params);
        }
    }

    #[test]
    fn a_fit_stopped_by_its_iteration_limit_is_continued_or_fails_loudly() {
        // 5,000 samples: below the multi-start subsample, so there is no polishing stage and the
        // best start is continued on all samples when it stopped at its limit.
        let (_, samples) = crate::synthetic::lafortune2_samples(5_000, 0.05, 3);
        let data = FitData::from_samples(&samples).expect("data");
        let model = LafortuneFit::standard(2);
        let free = fit_data(&model, &data, &FitConfig::default()).expect("fit");
        let needed = free.channels[0].stages[1].iterations;
        let best_iters = free.channels[0].iterations;
        assert!(
            best_iters >= 6,
            "the best start took {best_iters} iterations"
        );
        let capped = |max_iterations| FitConfig {
            lm: LmConfig {
                max_iterations,
                ..LmConfig::default()
            },
            ..FitConfig::default()
        };
        // A limit a third of what the best start needs: continued to the same optimum.
        let fit = fit_data(&model, &data, &capped(best_iters.div_ceil(3))).expect("continued");
        let ch = &fit.channels[0];
        let last = ch
            .stages
            .iter()
            .rev()
            .find(|s| s.kind == FitStageKind::Polish)
            .expect("polish");
        assert_eq!(last.samples, 5_000, "{last:?} ({needed})");
        assert!(ch.status.converged());
        let rel = (ch.cost - free.channels[0].cost).abs() / free.channels[0].cost;
        assert!(rel < 1e-6, "cost {} vs {}", ch.cost, free.channels[0].cost);
        // Tolerances of zero never count as converged: after FINAL_SOLVE_RUNS runs the fit
        // fails, and the error says how far it went.
        let never = FitConfig {
            lm: LmConfig {
                max_iterations: 3,
                ftol: 0.0,
                gtol: 0.0,
                xtol: 0.0,
            },
            ..FitConfig::default()
        };
        match fit_data(&model, &data, &never) {
            Err(FitError::NotConverged { iterations, .. }) => {
                assert_eq!(iterations, 3 * FINAL_SOLVE_RUNS);
            }
            other => panic!("expected NotConverged, got {other:?}"),
        }
    }

    #[test]
    fn recovers_a_near_mirror_lobe_with_a_huge_dynamic_range() {
        // Exponent 3000, peak/diffuse ratio ~1e5.
        let truth = LafortuneFit::standard(1)
            .to_model(&std::array::from_fn(|_| {
                vec![0.05, 0.0, -1.0, 3000f64.ln()]
            }))
            .expect("truth");
        let samples = synthetic(&truth, (0.1, 1.3), (0.05, 1.45), 12);
        let fit =
            fit_rgb(&LafortuneFit::standard(1), &samples, &FitConfig::default()).expect("fit");
        let p = &fit.channels[0].params;
        assert!(
            (p[3].exp() / 3000.0 - 1.0).abs() < 0.02,
            "exponent {}",
            p[3].exp()
        );
        assert!((p[2] + 1.0).abs() < 1e-3, "t {}", p[2]);
        assert!(
            fit.channels[0].error.log_rmse < 1e-3,
            "{:?}",
            fit.channels[0].error
        );
    }
}
