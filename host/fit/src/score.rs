//! Scoring a fitted model against a known true BRDF (synthetic sessions' `truth.json`).
//!
//! Both models are evaluated at the samples' own angles, so the score weighs the domain the
//! way the measurement covered it. Per channel: [`ErrorMetrics`] of the fitted value against
//! the true one with the log floor at 0.1% of the true channel's mean (the truth is noise-free,
//! so the floor only guards against zeros).

use std::time::Instant;

use serde::{Deserialize, Serialize};
use skinbrdf_brdf::BrdfModel;
use skinbrdf_core::BrdfSample;

use crate::fit::{error_metrics, ErrorMetrics, Fitted};

/// Log floor of the truth score relative to the true channel's mean.
pub const TRUTH_FLOOR_REL_MEAN: f64 = 1e-3;

/// Accuracy of the fitted model against a true model at the samples' angles.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TruthScore {
    /// Per channel.
    pub channels: [ErrorMetrics; 3],
    /// Wall time of the scoring, seconds.
    #[serde(default)]
    pub run_time_s: f64,
}

impl TruthScore {
    /// RMS over the channels of their log-RMSE.
    pub fn log_rmse(&self) -> f64 {
        (self
            .channels
            .iter()
            .map(|m| m.log_rmse.powi(2))
            .sum::<f64>()
            / 3.0)
            .sqrt()
    }
}

fn eval(model: &BrdfModel, s: &BrdfSample) -> [f64; 3] {
    model.eval_angles(
        f64::from(s.theta_i_rad),
        f64::from(s.theta_e_rad),
        f64::from(s.phi_d_rad),
    )
}

/// Scores the fitted model against `truth` at the angles of `samples`.
pub fn score_against_truth(
    fitted: &Fitted,
    truth: &BrdfModel,
    samples: &[BrdfSample],
) -> TruthScore {
    let t = Instant::now();
    let model = &fitted.fit.model;
    let channel = |c: usize| {
        let y: Vec<f64> = samples.iter().map(|s| eval(truth, s)[c]).collect();
        let floor = TRUTH_FLOOR_REL_MEAN * y.iter().sum::<f64>() / y.len().max(1) as f64;
        error_metrics(|i| eval(model, &samples[i])[c], &y, floor)
    };
    let channels = [channel(0), channel(1), channel(2)];
    TruthScore {
        channels,
        run_time_s: t.elapsed().as_secs_f64(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::{fit_model, FitConfig};
    use skinbrdf_brdf::ModelSpec;

    #[test]
    fn a_fit_of_noise_free_samples_scores_near_zero_and_a_wrong_truth_does_not() {
        let (truth, samples) = crate::synthetic::lafortune2_samples(3_000, 0.0, 4);
        let fitted = fit_model(
            &samples,
            &FitConfig::default(),
            ModelSpec::Lafortune { lobes: 2 },
        )
        .expect("fit");
        let s = score_against_truth(&fitted, &truth, &samples);
        // Noise-free samples of a 2-lobe model: the fit recovers it to solver precision.
        const RECOVERED_LOG_RMSE: f64 = 1e-3;
        assert!(s.log_rmse() < RECOVERED_LOG_RMSE, "{s:?}");
        assert_eq!(s.channels[0].count, 3_000);
        // A Lambertian "truth" with the true diffuse albedo misses the lobes: a clear error.
        let lambertian = BrdfModel::Lambertian {
            albedo: [0.45, 0.3, 0.25],
        };
        let wrong = score_against_truth(&fitted, &lambertian, &samples);
        assert!(wrong.log_rmse() > 0.05, "{wrong:?}");
    }

    /// Each sample keeps one channel, as a Bayer mosaic's photosites do: R, G, G, B in turn.
    fn partial(samples: &[BrdfSample]) -> Vec<BrdfSample> {
        samples
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let own = [0, 1, 1, 2][i % 4];
                let mut p = *s;
                p.rho = std::array::from_fn(|k| if k == own { s.rho[k] } else { f32::NAN });
                p
            })
            .collect()
    }

    #[test]
    fn partial_samples_fit_each_channel_from_the_samples_that_measured_it() {
        let (truth, samples) = crate::synthetic::lafortune2_samples(6_000, 0.0, 5);
        let samples = partial(&samples);
        let fitted = fit_model(
            &samples,
            &FitConfig::default(),
            ModelSpec::Lafortune { lobes: 2 },
        )
        .expect("fit");
        let s = score_against_truth(&fitted, &truth, &samples);
        // As for complete samples: the fit recovers the model to solver precision.
        const RECOVERED_LOG_RMSE: f64 = 1e-3;
        assert!(s.log_rmse() < RECOVERED_LOG_RMSE, "{s:?}");
        assert_eq!(fitted.fit.n_samples, 6_000);
        // A sample that measured nothing is refused.
        let mut bad = samples.clone();
        bad[7].rho = [f32::NAN; 3];
        let err = fit_model(
            &bad,
            &FitConfig::default(),
            ModelSpec::Lafortune { lobes: 2 },
        )
        .expect_err("refused");
        assert!(
            matches!(
                err,
                crate::FitError::BadSample {
                    index: 7,
                    field: "rho"
                }
            ),
            "{err}"
        );
    }

    #[test]
    fn partial_samples_have_grey_levels_on_the_complete_samples_scale() {
        let (_, samples) = crate::synthetic::lafortune2_samples(4_000, 0.0, 6);
        let scale = crate::smooth::GreyScale::of(&partial(&samples));
        let grey = |s: &[BrdfSample]| {
            let mut v: Vec<f64> = s.iter().map(|x| scale.grey(x)).collect();
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let (a, b) = (grey(&samples), grey(&partial(&samples)));
        // The channels' medians rescale each partial sample to the set's grey level.
        const SAME_MEDIAN_REL: f64 = 0.1;
        assert!(
            (a - b).abs() / a < SAME_MEDIAN_REL,
            "complete {a}, partial {b}"
        );
    }
}
