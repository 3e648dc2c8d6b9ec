//! The smoothing stages (incidence plane and hemisphere): one local quadratic regression of the
//! samples' grey level over `(theta_i, theta_e, phi_d)`.
//!
//! * Input ([`smoother_input`], the only place the smoother's design and floor are made): an
//!   evenly strided subset of at most [`SmoothConfig::max_samples`] samples (plenty for a curve
//!   and its band; the smoother's cost grows with `n x neighbours`), as radians
//!   `(theta_i, theta_e, phi_d)` and `ln(grey + floor)`, `grey = (r + g + b) / 3` (a partial
//!   sample's channel scaled to a grey level by [`GreyScale`]). BRDF noise is
//!   multiplicative and a specular peak would otherwise set one residual scale for the whole
//!   domain, hence the log. The floor is [`log_floor_rho`]: the fit's own rule
//!   ([`crate::fit::auto_floor`], 1% of the median grey level by default), so the smoother and
//!   the fit resolve the same dynamic range.
//! * Span: chosen by generalized cross-validation among [`SPAN_CANDIDATES`] (or fixed).
//! * Output ([`Smoothed`]): the smoother, mapped back to 1/sr by `exp(v) - floor` (monotone, so
//!   bands map to bands), with its span, residual standard error (log units, i.e. relative) and
//!   run time.

use std::time::Instant;

use serde::{Deserialize, Serialize};
use skinbrdf_core::BrdfSample;

use crate::fit::{auto_floor, LOG_FLOOR_REL_MEDIAN};
use crate::loess::{choose_span_gcv, Bandwidth, Loess, LoessConfig, LoessError};
use crate::plot::{self, PlaneCurve};

/// Samples the smoother uses at most.
pub const SMOOTH_MAX_SAMPLES: usize = 20_000;
/// Spans tried by GCV.
pub const SPAN_CANDIDATES: [f64; 4] = [0.02, 0.05, 0.1, 0.2];
/// Samples at which each GCV candidate's residual scale is computed.
pub const GCV_SIGMA_POINTS: usize = 2_000;
/// Samples at which the chosen smoother's residual scale (and so its bands) is computed.
pub const FIT_SIGMA_POINTS: usize = 5_000;

/// How the span is chosen.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SpanChoice {
    /// Smallest GCV score among these spans.
    Gcv(Vec<f64>),
    /// This span.
    Fixed(f64),
}

/// Smoother settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SmoothConfig {
    /// Samples used at most (an evenly strided subset).
    pub max_samples: usize,
    /// The span.
    pub span: SpanChoice,
    /// Log floor relative to the median grey level.
    pub floor_rel_median: f64,
}

impl Default for SmoothConfig {
    fn default() -> Self {
        Self {
            max_samples: SMOOTH_MAX_SAMPLES,
            span: SpanChoice::Gcv(SPAN_CANDIDATES.to_vec()),
            floor_rel_median: LOG_FLOOR_REL_MEDIAN,
        }
    }
}

/// The smoother's design: predictors, log responses and the floor used.
#[derive(Debug, Clone, PartialEq)]
pub struct SmootherInput {
    /// `(theta_i, theta_e, phi_d)` in radians per used sample.
    pub x: Vec<Vec<f64>>,
    /// `ln(grey + floor_rho)` per used sample.
    pub y_log: Vec<f64>,
    /// The floor, 1/sr.
    pub floor_rho: f64,
}

/// Grey level `(r + g + b) / 3` of a sample, 1/sr (the mean of the channels it measured for
/// a partial sample; [`GreyScale`] makes partial samples of different channels comparable).
pub fn grey_rho(s: &BrdfSample) -> f64 {
    f64::from(s.mean_measured_rho())
}

/// The grey level of samples that may be partial (one channel each, from camera raw
/// photosites): a sample measuring channel `c` only stands for the grey level
/// `rho_c · mean_k(m_k) / m_c`, with `m_k` the median of channel `k` over the samples that
/// measured it. Exact for a sample of the set's median colour; skin's colour changes little
/// with angle next to the scatter the smoother shows, and no grey level of a set mixes the
/// channels' levels. A complete sample's grey is `(r + g + b) / 3` as it is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GreyScale {
    /// `mean_k(m_k) / m_c` per channel (1 where a channel has no partial sample to scale).
    pub factors: [f64; 3],
}

impl GreyScale {
    /// The scale of a sample set (identity when no sample is partial).
    pub fn of(samples: &[BrdfSample]) -> Self {
        if !samples.iter().any(BrdfSample::is_partial) {
            return Self { factors: [1.0; 3] };
        }
        let medians: [Option<f64>; 3] = std::array::from_fn(|c| {
            let v: Vec<f64> = samples
                .iter()
                .filter(|s| s.measures(c))
                .map(|s| f64::from(s.rho[c]))
                .collect();
            (!v.is_empty()).then(|| crate::fit::quantile(&v, 0.5))
        });
        let known: Vec<f64> = medians.iter().flatten().copied().collect();
        let mean = known.iter().sum::<f64>() / known.len().max(1) as f64;
        Self {
            factors: medians.map(|m| match m {
                Some(m) if m > 0.0 && mean > 0.0 => mean / m,
                _ => 1.0,
            }),
        }
    }

    /// A sample's grey level, 1/sr.
    pub fn grey(&self, s: &BrdfSample) -> f64 {
        if !s.is_partial() {
            return grey_rho(s);
        }
        let (sum, n) = (0..3)
            .filter(|&c| s.measures(c))
            .fold((0.0, 0u32), |(sum, n), c| {
                (sum + f64::from(s.rho[c]) * self.factors[c], n + 1)
            });
        if n == 0 {
            f64::NAN
        } else {
            sum / f64::from(n)
        }
    }
}

/// The log floor of a set of grey levels: `floor_rel_median` times their median (at least
/// 1e-9), the same rule the fit's log residual uses.
pub fn log_floor_rho(grey: &[f64], floor_rel_median: f64) -> f64 {
    auto_floor(grey, floor_rel_median)
}

/// Indices of an evenly strided subset of at most `k_max` of `n` items.
fn strided(n: usize, k_max: usize) -> impl Iterator<Item = usize> {
    let k = n.min(k_max);
    (0..k).map(move |i| ((i as u128 * n as u128) / k as u128) as usize)
}

/// The design of an evenly strided subset of at most `k_max` samples with a given floor (for
/// comparisons, where two sessions must share one floor).
pub fn log_design(
    samples: &[BrdfSample],
    k_max: usize,
    floor_rho: f64,
) -> (Vec<Vec<f64>>, Vec<f64>) {
    let scale = GreyScale::of(samples);
    strided(samples.len(), k_max)
        .map(|i| {
            let s = &samples[i];
            let x = vec![
                f64::from(s.theta_i_rad),
                f64::from(s.theta_e_rad),
                f64::from(s.phi_d_rad),
            ];
            (x, (scale.grey(s).max(0.0) + floor_rho).ln())
        })
        .unzip()
}

/// The smoother's design of at most `max_samples` samples, its floor computed from the same
/// subset by [`log_floor_rho`].
pub fn smoother_input(
    samples: &[BrdfSample],
    max_samples: usize,
    floor_rel_median: f64,
) -> SmootherInput {
    let scale = GreyScale::of(samples);
    let grey: Vec<f64> = strided(samples.len(), max_samples)
        .map(|i| scale.grey(&samples[i]))
        .collect();
    let floor_rho = log_floor_rho(&grey, floor_rel_median);
    let (x, y_log) = log_design(samples, max_samples, floor_rho);
    SmootherInput {
        x,
        y_log,
        floor_rho,
    }
}

/// What the smoother reports about itself.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SmoothMetrics {
    /// The span used (GCV-chosen unless fixed).
    pub span: f64,
    /// Residual standard error (natural-log units: a relative error).
    pub residual_sigma_log: f64,
    /// The log floor, 1/sr.
    pub floor_rho: f64,
    /// Samples the smoother ran on.
    pub samples_used: usize,
    /// Wall time, seconds (design, span choice and the final smooth).
    pub run_time_s: f64,
    /// The image whose samples sit furthest off the smoother: see [`ImageOffset`]. `None`
    /// when no image has [`IMAGE_OFFSET_MIN_RESIDUALS`] residuals.
    #[serde(default)]
    pub worst_image_offset: Option<ImageOffset>,
}

/// Residuals an image needs among the smoother's residual subset for its offset to be told
/// (the median of fewer is itself uncertain by a large part of the residual scale).
pub const IMAGE_OFFSET_MIN_RESIDUALS: usize = 30;

/// How far one image's samples sit off the smoother of all images: the median of its samples'
/// log residuals `ln(grey + floor) - smooth(theta_i, theta_e, phi_d)`.
///
/// The smoother describes the BRDF every image agrees on; an image whose exposure, flash,
/// pose or standard is wrong has its samples offset together (a relative error of its own),
/// while noise and the smoother's bias scatter about zero.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ImageOffset {
    /// The image's index in the session (`BrdfSample::image_index`).
    pub image_index: u16,
    /// The median log residual (a relative offset: 0.05 is 5 % bright).
    pub offset_log: f64,
    /// Residuals of the image the median is taken over.
    pub residuals: usize,
}

/// The image whose median residual is largest in magnitude, from `(sample index, residual)`
/// pairs of `samples`.
pub fn worst_image_offset(
    samples: &[BrdfSample],
    residuals: impl IntoIterator<Item = (usize, f64)>,
) -> Option<ImageOffset> {
    let mut by_image: std::collections::BTreeMap<u16, Vec<f64>> = Default::default();
    for (i, r) in residuals {
        let Some(s) = samples.get(i) else { continue };
        if s.image_index != u16::MAX && r.is_finite() {
            by_image.entry(s.image_index).or_default().push(r);
        }
    }
    by_image
        .into_iter()
        .filter(|(_, r)| r.len() >= IMAGE_OFFSET_MIN_RESIDUALS)
        .map(|(image_index, r)| ImageOffset {
            image_index,
            offset_log: crate::fit::quantile(&r, 0.5),
            residuals: r.len(),
        })
        .max_by(|a, b| a.offset_log.abs().total_cmp(&b.offset_log.abs()))
}

/// A smoother of `ln(grey + floor)` and its metrics.
#[derive(Debug)]
pub struct Smoothed {
    /// The smoother (log scale).
    pub loess: Loess,
    /// Span, residual scale, floor, samples, time.
    pub metrics: SmoothMetrics,
}

impl Smoothed {
    /// Maps a value (or band edge) of the smoother's log scale back to 1/sr.
    pub fn to_rho(&self, v_log: f64) -> f64 {
        v_log.exp() - self.metrics.floor_rho
    }

    /// The smoothed incidence-plane curve at `theta_i_deg` in 1/sr, with its band, where the
    /// smoother's standard error allows ([`plot::loess_curve`]).
    pub fn plane_curve(&self, label: &str, theta_i_deg: f64) -> PlaneCurve {
        plot::loess_curve(label, &self.loess, theta_i_deg, |v| self.to_rho(v))
    }
}

/// Smooths the samples' grey level over `(theta_i, theta_e, phi_d)`.
pub fn smooth(samples: &[BrdfSample], cfg: &SmoothConfig) -> Result<Smoothed, LoessError> {
    let t = Instant::now();
    let input = smoother_input(samples, cfg.max_samples, cfg.floor_rel_median);
    let base = LoessConfig {
        max_sigma_points: GCV_SIGMA_POINTS,
        ..LoessConfig::default()
    };
    let span = match &cfg.span {
        SpanChoice::Gcv(candidates) => choose_span_gcv(&input.x, &input.y_log, candidates, base)?.0,
        SpanChoice::Fixed(s) => *s,
    };
    let loess = Loess::fit(
        &input.x,
        &input.y_log,
        LoessConfig {
            bandwidth: Bandwidth::Span(span),
            max_sigma_points: FIT_SIGMA_POINTS,
            ..base
        },
    )?;
    let used: Vec<usize> = strided(samples.len(), cfg.max_samples).collect();
    let worst = worst_image_offset(
        samples,
        loess
            .sigma_residuals
            .iter()
            .filter_map(|&(j, r)| Some((*used.get(j)?, r))),
    );
    let metrics = SmoothMetrics {
        span,
        residual_sigma_log: loess.sigma,
        floor_rho: input.floor_rho,
        samples_used: input.y_log.len(),
        run_time_s: t.elapsed().as_secs_f64(),
        worst_image_offset: worst,
    };
    Ok(Smoothed { loess, metrics })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_floor_is_the_fits_rule_on_the_smoothed_subset() {
        let (_, samples) = crate::synthetic::lafortune2_samples(2_000, 0.05, 5);
        let input = smoother_input(&samples, 500, 0.01);
        assert_eq!(input.x.len(), 500);
        let grey: Vec<f64> = (0..500).map(|i| grey_rho(&samples[i * 4])).collect();
        assert_eq!(input.floor_rho, auto_floor(&grey, 0.01));
        let s = &samples[4];
        assert_eq!(
            input.y_log[1],
            (grey_rho(s).max(0.0) + input.floor_rho).ln()
        );
    }

    #[test]
    fn smooth_reports_its_span_scale_and_time() {
        let (_, samples) = crate::synthetic::lafortune2_samples(3_000, 0.1, 2);
        let sm = smooth(&samples, &SmoothConfig::default()).expect("smooth");
        assert!(SPAN_CANDIDATES.contains(&sm.metrics.span));
        // 10% multiplicative noise per channel: the grey level's log residual is 0.1 / sqrt(3)
        // or more (plus smoothing bias).
        assert!(
            (0.03..0.2).contains(&sm.metrics.residual_sigma_log),
            "{:?}",
            sm.metrics
        );
        assert_eq!(sm.metrics.samples_used, 3_000);
        assert!(sm.metrics.run_time_s > 0.0);
        let fixed = smooth(
            &samples,
            &SmoothConfig {
                span: SpanChoice::Fixed(0.1),
                max_samples: 1_000,
                ..SmoothConfig::default()
            },
        )
        .expect("fixed");
        assert_eq!(
            (fixed.metrics.span, fixed.metrics.samples_used),
            (0.1, 1_000)
        );
    }

    /// Gives `samples` to images `0..images` in turn, and scales image `dim`'s by `factor`.
    fn with_images(samples: &mut [BrdfSample], images: u16, dim: u16, factor: f32) {
        for (k, s) in samples.iter_mut().enumerate() {
            s.image_index = (k % usize::from(images)) as u16;
            if s.image_index == dim {
                s.rho = s.rho.map(|v| v * factor);
            }
        }
    }

    #[test]
    fn an_image_whose_samples_sit_off_the_others_is_the_worst_offset() {
        // 5 % noise: each image's median residual is within a percent or two of zero.
        let (_, mut samples) = crate::synthetic::lafortune2_samples(6_000, 0.05, 3);
        with_images(&mut samples, 20, 7, 0.8);
        let sm = smooth(&samples, &SmoothConfig::default()).expect("smooth");
        let worst = sm.metrics.worst_image_offset.expect("an offset");
        assert_eq!(worst.image_index, 7, "{worst:?}");
        // A fifth of the images' residuals: the smoother follows the dim image a little.
        assert!(
            (-0.26..-0.12).contains(&worst.offset_log),
            "{worst:?} against ln 0.8 = -0.223"
        );
        assert!(worst.residuals >= IMAGE_OFFSET_MIN_RESIDUALS);
    }

    #[test]
    fn images_that_agree_have_offsets_inside_the_scatter() {
        let (_, mut samples) = crate::synthetic::lafortune2_samples(6_000, 0.05, 4);
        with_images(&mut samples, 20, u16::MAX, 1.0);
        let sm = smooth(&samples, &SmoothConfig::default()).expect("smooth");
        let worst = sm.metrics.worst_image_offset.expect("an offset");
        assert!(
            worst.offset_log.abs() < sm.metrics.residual_sigma_log,
            "{worst:?} against the scatter {}",
            sm.metrics.residual_sigma_log
        );
    }

    #[test]
    fn images_with_few_residuals_or_none_are_not_told() {
        let (_, samples) = crate::synthetic::lafortune2_samples(200, 0.05, 5);
        // `lafortune2_samples` gives no image (u16::MAX).
        assert_eq!(
            worst_image_offset(&samples, (0..200).map(|i| (i, 0.5))),
            None
        );
        // 20 residuals per image, fewer than a median is told from.
        let mut few = samples.clone();
        with_images(&mut few, 10, u16::MAX, 1.0);
        assert_eq!(worst_image_offset(&few, (0..200).map(|i| (i, 0.5))), None);
        // 40 per image: told.
        with_images(&mut few, 5, u16::MAX, 1.0);
        let told = worst_image_offset(&few, (0..200).map(|i| (i, 0.5))).expect("told");
        assert_eq!((told.offset_log, told.residuals), (0.5, 40));
    }
}
