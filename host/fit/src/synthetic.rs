//! Deterministic synthetic sample sets for benchmarks and peer comparisons (no RNG crate: a
//! SplitMix64 stream, Box-Muller normals).

use skinbrdf_brdf::{BrdfModel, ChannelModel, LafortuneFit};
use skinbrdf_core::{BrdfAngles, BrdfSample};

struct SplitMix(u64);

impl SplitMix {
    fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }

    fn normal(&mut self) -> f64 {
        let u1 = self.next_f64().max(1e-300);
        let u2 = self.next_f64();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

/// The benchmark's true model: a skin-like 2-lobe Lafortune BRDF (diffuse albedo 0.45/0.3/0.25,
/// a forward lobe of exponent 25 tilted off-specular, a broad retro lobe), in the fitting
/// parametrisation of [`LafortuneFit`].
pub fn bench_truth_params() -> [Vec<f64>; 3] {
    std::array::from_fn(|c| {
        let albedo = [0.45, 0.3, 0.25][c];
        vec![
            albedo,
            (0.12f64).ln(),
            -0.9,
            25f64.ln(),
            (0.04f64).ln(),
            0.8,
            3f64.ln(),
        ]
    })
}

/// `n` samples of the benchmark model at random directions (uniform in projected solid angle,
/// grazing angles beyond 85 degrees excluded), with multiplicative log-normal noise of
/// `noise_rel` standard deviation.
pub fn lafortune2_samples(n: usize, noise_rel: f64, seed: u64) -> (BrdfModel, Vec<BrdfSample>) {
    let fit = LafortuneFit::standard(2);
    let params = bench_truth_params();
    let model = fit
        .to_model(&params)
        .expect("the benchmark parameters are valid");
    let mut rng = SplitMix(seed);
    let max_sin = 85f64.to_radians().sin();
    let mut out = Vec::with_capacity(n);
    let dir = |rng: &mut SplitMix| {
        let r = max_sin * rng.next_f64().sqrt();
        let phi = 2.0 * std::f64::consts::PI * rng.next_f64();
        glam::DVec3::new(r * phi.cos(), r * phi.sin(), (1.0 - r * r).sqrt())
    };
    while out.len() < n {
        let wi = dir(&mut rng);
        let we = dir(&mut rng);
        let a = BrdfAngles::from_local(wi, we);
        let g = skinbrdf_brdf::Geom::from_dirs(wi, we);
        let rho: [f32; 3] = std::array::from_fn(|c| {
            (fit.eval(&params[c], &g) * (noise_rel * rng.normal()).exp()) as f32
        });
        out.push(BrdfSample::from_angles(&a, rho));
    }
    (model, out)
}
