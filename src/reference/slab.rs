//! The plane-parallel slab validator: the reference transport in a homogeneous slab of optical
//! thickness τ, infinite sideways, with no refraction at its faces, lit from above by a collimated
//! beam at normal incidence or by uniform diffuse light. Estimates the total reflected (R) and
//! transmitted (T, including the unscattered beam) fractions of the incident flux, to be checked
//! against adding-doubling (`tests/data/slab_adding_doubling.csv`).
//!
//! The transport is the tracer's: exponential free paths (delta tracking in a homogeneous medium
//! with a tight majorant is exactly this), Henyey–Greenstein directions from [`Hg::sample_cos`], and
//! the throughput multiplied by the albedo at each collision followed by Russian roulette with
//! survival probability min(1, throughput) — which for a single band is the same as absorbing the
//! photon with probability 1 − albedo, so every photon scores 0 or 1.
//!
//! Photon i draws from its own stream `Rng::new(seed, i)`, so the result is identical at any thread count.

pub use crate::diffusion::slab::{Incidence, SlabResult};
use crate::error::{Error, Result};
use crate::math::Rng;
use crate::optics::Hg;

/// A slab case.
#[derive(Clone, Copy, Debug)]
pub struct SlabParams {
    /// Optical thickness τ (unitless, ≥ 0).
    pub thickness: f64,
    /// Single-scattering albedo in [0, 1].
    pub albedo: f64,
    /// HG mean cosine, |g| < 1.
    pub g: f64,
    /// Illumination.
    pub incidence: Incidence,
}

/// Where a photon ends.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Fate {
    Reflected,
    Transmitted,
    Absorbed,
}

/// Photons per parallel work item.
const CHUNK: u64 = 2048;

/// Work items traced at a time: the per-item counts held at once stay bounded whatever the
/// photon count.
const BATCH: u64 = 1 << 16;

/// Most photons: 1e12, a standard error of 5e-7 and about 12 core-days at a million photons
/// per core-second.
pub const MAX_SAMPLES: u64 = 1_000_000_000_000;

impl SlabParams {
    /// Check the parameters; `file` names the source for messages (e.g. "command line").
    pub fn validate(&self, file: &str) -> Result<()> {
        if !(self.thickness.is_finite() && self.thickness >= 0.0) {
            return Err(Error::invalid(
                file,
                "--thickness",
                format!("{} is not allowed: the optical thickness must be finite and ≥ 0", self.thickness),
            ));
        }
        if !(0.0..=1.0).contains(&self.albedo) {
            return Err(Error::invalid(
                file,
                "--albedo",
                format!("{} is not allowed: the albedo must be in [0, 1]", self.albedo),
            ));
        }
        if !(self.g.is_finite() && self.g.abs() < 1.0) {
            return Err(Error::invalid(
                file,
                "--g",
                format!("{} is not allowed: the Henyey-Greenstein g must satisfy |g| < 1", self.g),
            ));
        }
        Ok(())
    }
}

/// Trace one photon.
fn photon(p: &SlabParams, rng: &mut Rng) -> Fate {
    // μ: cosine between the direction and the downward normal; z: optical depth below the top.
    let mut mu = match p.incidence {
        Incidence::Collimated => 1.0f64,
        Incidence::Diffuse => rng.uniform_f64().sqrt().max(1e-12),
    };
    let mut z = 0.0f64;
    let phase = Hg::new(p.g as f32);
    loop {
        z += -(1.0 - rng.uniform_f64()).ln() * mu;
        if z <= 0.0 {
            return Fate::Reflected;
        }
        if z >= p.thickness {
            return Fate::Transmitted;
        }
        // Throughput × albedo, then roulette with q = throughput: survive with probability albedo.
        if rng.uniform_f64() >= p.albedo {
            return Fate::Absorbed;
        }
        let c = phase.sample_cos(rng.uniform()) as f64;
        let s = ((1.0 - c * c) * (1.0 - mu * mu)).max(0.0).sqrt();
        let phi = 2.0 * std::f64::consts::PI * rng.uniform_f64();
        mu = (mu * c + s * phi.cos()).clamp(-1.0, 1.0);
    }
}

/// Estimate R and T with `samples` photons (≥ 2).
pub fn slab(p: &SlabParams, samples: u64, seed: u64) -> Result<SlabResult> {
    p.validate("slab")?;
    if !(2..=MAX_SAMPLES).contains(&samples) {
        return Err(Error::invalid(
            "slab",
            "--samples",
            format!(
                "{samples} is not allowed: give 2 photons (the fewest with a standard error) to {MAX_SAMPLES:e} \
                 (a standard error of 5e-7, about 12 core-days)"
            ),
        ));
    }
    let chunks = samples.div_ceil(CHUNK);
    let (mut r, mut t) = (0u64, 0u64);
    for first in (0..chunks).step_by(BATCH as usize) {
        let counts: Vec<(u64, u64)> = crate::par::map_range((chunks - first).min(BATCH) as usize, &|k| {
            let c = first + k as u64;
            let (mut r, mut t) = (0u64, 0u64);
            for i in c * CHUNK..((c + 1) * CHUNK).min(samples) {
                let mut rng = Rng::new(seed, i);
                match photon(p, &mut rng) {
                    Fate::Reflected => r += 1,
                    Fate::Transmitted => t += 1,
                    Fate::Absorbed => {}
                }
            }
            (r, t)
        });
        for (a, b) in counts {
            (r, t) = (r + a, t + b);
        }
    }
    let n = samples as f64;
    // Each photon scores 0 or 1: the sample variance of a Bernoulli mean is p(1 − p)/(n − 1).
    let est = |k: u64| {
        let m = k as f64 / n;
        (m, (m * (1.0 - m) / (n - 1.0)).sqrt())
    };
    let ((r, r_stderr), (t, t_stderr)) = (est(r), est(t));
    Ok(SlabResult { r, t, r_stderr, t_stderr })
}
