//! Henyey–Greenstein phase function: evaluation, importance sampling, and the i-fold
//! self-convolution (HG with g^i) used for the orders of scattering (paper section 4).
//!
//! Convention: `cos_theta` is the cosine between the propagation directions before and after
//! scattering, so g > 0 scatters forward. Values are per steradian and integrate to 1.

use crate::math::{Frame, Vec3};
use std::f32::consts::PI;

/// p(θ) = (1 − g²) / (4π (1 − 2g cosθ + g²)^{3/2}), in sr⁻¹.
#[inline]
pub fn hg(cos_theta: f32, g: f32) -> f32 {
    let denom = 1.0 + g * g - 2.0 * g * cos_theta;
    (1.0 - g * g) / (4.0 * PI * denom * denom.sqrt().max(1e-12))
}

/// f64 version of [`hg`] for reference integrations.
#[inline]
pub fn hg_f64(cos_theta: f64, g: f64) -> f64 {
    let denom = 1.0 + g * g - 2.0 * g * cos_theta;
    (1.0 - g * g) / (4.0 * std::f64::consts::PI * denom * denom.sqrt().max(1e-300))
}

/// Sample cosθ with density `hg` (inverse CDF; exact, also for g = 0).
#[inline]
pub fn sample_hg_cos(g: f32, u: f32) -> f32 {
    if g.abs() < 1e-3 {
        return 1.0 - 2.0 * u;
    }
    let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u);
    ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
}

/// Sample a new propagation direction after scattering from direction `dir` (unit), using two
/// uniforms. Returns the direction; its density is `hg(dir·new, g)`.
#[inline]
pub fn sample_hg(dir: Vec3, g: f32, u1: f32, u2: f32) -> Vec3 {
    let cos_t = sample_hg_cos(g, u1);
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let phi = 2.0 * PI * u2;
    Frame::from_normal(dir)
        .to_world(Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t))
        .normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hg_normalised_and_mean_cosine_is_g() {
        for &g in &[-0.5f64, 0.0, 0.3, 0.9, 0.95] {
            // Integrate over cosθ with a fine midpoint rule (2π from φ).
            let n = 200_000;
            let (mut total, mut mean) = (0.0, 0.0);
            for i in 0..n {
                let mu = -1.0 + (i as f64 + 0.5) * 2.0 / n as f64;
                let p = hg_f64(mu, g) * 2.0 * std::f64::consts::PI * (2.0 / n as f64);
                total += p;
                mean += p * mu;
            }
            assert!((total - 1.0).abs() < 1e-4, "g={g} total={total}");
            assert!((mean - g).abs() < 1e-4, "g={g} mean={mean}");
        }
    }
}
