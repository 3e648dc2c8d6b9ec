//! BRDF models.
//!
//! Every model evaluates `rho(w_i, w_e)` per RGB channel (1/sr) from local unit directions
//! (+z = normal, both pointing away from the surface; see [`skinbrdf_core::angles`]).
//! [`BrdfModel`] is the serialisable sum of the models, used by scene files, `truth.json` and
//! fit results.
//!
//! For fitting, each model also exists as a [`ChannelModel`]: one RGB channel as a function of a
//! well-conditioned parameter vector, with bounds, analytic derivatives (checked against finite
//! differences in the tests) and starting points: [`LambertianFit`], [`LafortuneFit`] (1-3
//! lobes, log exponent and log lobe albedo separated from the lobe shape), [`CookTorranceFit`]
//! (GGX, Smith, dielectric Fresnel). [`Geom`] holds the per-sample dot products they need.

mod error;
pub mod geom;
pub mod lafortune;
pub mod lambertian;
pub mod microfacet;
pub mod param;

pub use error::BrdfError;
pub use geom::Geom;
pub use lafortune::{Lafortune, LafortuneFit, LafortuneLobe, LobeSpec};
pub use lambertian::LambertianFit;
pub use microfacet::{CookTorrance, CookTorranceFit};
pub use param::{ChannelModel, ModelSpec, ParamBound, StartHint};

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// Any BRDF the project knows, serialised with a `model` tag.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "snake_case")]
pub enum BrdfModel {
    /// Ideal diffuse reflector: `rho = albedo / pi`.
    Lambertian {
        /// Diffuse albedo per channel, in `[0, 1]`.
        albedo: [f64; 3],
    },
    /// Lambertian plus generalized cosine lobes (Lafortune et al. 1997).
    Lafortune(Lafortune),
    /// Lambertian plus a GGX Cook-Torrance specular term (see [`microfacet`]).
    CookTorrance(CookTorrance),
}

impl BrdfModel {
    /// Evaluates the BRDF per channel (1/sr) for local directions. Directions below the surface
    /// give zero.
    pub fn eval(&self, wi: DVec3, we: DVec3) -> [f64; 3] {
        if wi.z <= 0.0 || we.z <= 0.0 {
            return [0.0; 3];
        }
        match self {
            Self::Lambertian { albedo } => albedo.map(|a| a * std::f64::consts::FRAC_1_PI),
            Self::Lafortune(l) => l.eval(wi, we),
            Self::CookTorrance(m) => m.eval_geom(&Geom::from_dirs(wi, we)),
        }
    }

    /// Evaluates from the isotropic angles (see [`skinbrdf_core::BrdfAngles`]).
    pub fn eval_angles(&self, theta_i_rad: f64, theta_e_rad: f64, phi_d_rad: f64) -> [f64; 3] {
        let (wi, we) =
            skinbrdf_core::BrdfAngles::canonical_directions(theta_i_rad, theta_e_rad, phi_d_rad);
        self.eval(wi, we)
    }

    /// The diffuse (Lambertian) albedo per channel of any model.
    pub fn diffuse_albedo(&self) -> [f64; 3] {
        match self {
            Self::Lambertian { albedo } => *albedo,
            Self::Lafortune(l) => l.diffuse_albedo,
            Self::CookTorrance(m) => m.diffuse_albedo,
        }
    }

    /// Checks every parameter: finite, albedos in `[0, 1.5]` (1 plus calibration slack),
    /// exponents and roughness positive, index of refraction above 1.
    pub fn validate(&self) -> Result<(), BrdfError> {
        let bad = |field: String, reason: &str| {
            Err(BrdfError::InvalidParameter {
                field,
                reason: reason.to_owned(),
            })
        };
        let albedo = self.diffuse_albedo();
        if !albedo
            .iter()
            .all(|a| a.is_finite() && (0.0..=lambertian::MAX_ALBEDO).contains(a))
        {
            return bad("diffuse_albedo".into(), "must be finite and in [0, 1.5]");
        }
        match self {
            Self::Lambertian { .. } => {}
            Self::Lafortune(l) => {
                for (k, lobe) in l.lobes.iter().enumerate() {
                    if !lobe.cxy.iter().chain(&lobe.cz).all(|v| v.is_finite()) {
                        return bad(format!("lobes[{k}].cxy/cz"), "must be finite");
                    }
                    if !lobe.exponent.iter().all(|n| n.is_finite() && *n > 0.0) {
                        return bad(
                            format!("lobes[{k}].exponent"),
                            "must be finite and positive",
                        );
                    }
                }
            }
            Self::CookTorrance(m) => {
                if !m.specular_scale.iter().all(|v| v.is_finite() && *v >= 0.0) {
                    return bad("specular_scale".into(), "must be finite and non-negative");
                }
                if !m.roughness_alpha.iter().all(|v| v.is_finite() && *v > 0.0) {
                    return bad("roughness_alpha".into(), "must be finite and positive");
                }
                if !(m.ior.is_finite() && m.ior > 1.0) {
                    return bad("ior".into(), "must be finite and above 1");
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn serde_tags_are_stable() {
        let m = BrdfModel::Lambertian { albedo: [0.5; 3] };
        let j = serde_json::to_string(&m).expect("json");
        assert!(j.contains("\"model\":\"lambertian\""), "{j}");
        let ct = BrdfModel::CookTorrance(CookTorrance {
            diffuse_albedo: [0.4; 3],
            specular_scale: [0.5; 3],
            roughness_alpha: [0.3; 3],
            ior: 1.4,
        });
        let j = serde_json::to_string(&ct).expect("json");
        assert!(j.contains("\"model\":\"cook_torrance\""), "{j}");
        assert_eq!(serde_json::from_str::<BrdfModel>(&j).expect("back"), ct);
        let lf = LafortuneFit::standard(2)
            .to_model(&std::array::from_fn(|_| {
                vec![0.3, -1.0, -1.0, 3.0, -2.0, 1.0, 1.0]
            }))
            .expect("model");
        let j = serde_json::to_string(&lf).expect("json");
        assert!(j.contains("\"model\":\"lafortune\""), "{j}");
        let back = serde_json::from_str::<BrdfModel>(&j).expect("back");
        for (ti, te, pd) in [(0.3, 0.3, 3.1), (1.0, 0.2, 0.0)] {
            let (a, b) = (
                lf.eval_angles(ti, te, pd)[0],
                back.eval_angles(ti, te, pd)[0],
            );
            assert!((a - b).abs() < 1e-12 * a, "{a} {b}");
        }
    }

    #[test]
    fn validate_rejects_bad_parameters() {
        assert!(BrdfModel::Lambertian {
            albedo: [0.5, f64::NAN, 0.1]
        }
        .validate()
        .is_err());
        let ct = BrdfModel::CookTorrance(CookTorrance {
            diffuse_albedo: [0.4; 3],
            specular_scale: [0.5; 3],
            roughness_alpha: [0.0; 3],
            ior: 1.4,
        });
        let e = ct.validate().expect_err("alpha 0");
        assert!(e.to_string().contains("roughness_alpha"));
    }

    #[test]
    fn model_spec_parses_cli_names() {
        for (s, n) in [
            ("lambertian", 1),
            ("lafortune1", 4),
            ("lafortune2", 7),
            ("lafortune3", 10),
            ("cook-torrance", 3),
        ] {
            let spec: ModelSpec = s.parse().expect("spec");
            assert_eq!(spec.channel_model().n_params(), n);
            assert_eq!(spec.to_string(), s);
        }
        assert!("phong".parse::<ModelSpec>().is_err());
    }

    #[test]
    fn channel_models_match_brdf_model_eval() {
        let ct = CookTorranceFit::default();
        let p = vec![0.3, 0.8, 0.2f64.ln()];
        let m = ct
            .to_model(&[p.clone(), p.clone(), p.clone()])
            .expect("model");
        for (ti, te, pd) in [(0.2, 0.3, 3.0), (1.2, 1.4, 0.1), (0.0, 0.7, 1.0)] {
            let a = m.eval_angles(ti, te, pd)[2];
            let b = ct.eval(&p, &Geom::from_angles(ti, te, pd));
            assert!((a - b).abs() < 1e-12 * a.abs().max(1.0));
        }
    }
}
