//! Whether the sun's scattered light stays in the cloud: a non-local factor on the surface layer's
//! sun orders i ≥ 2 (docs/edges.md, "The sun's orders ≥ 2 on a thin cloud").
//!
//! The layer renders its segment's orders with eq. 8's one-dimensional Poisson weights: a photon
//! of the sun's beam that has collided once in a path of optical depth D collides again before
//! leaving it with probability
//!
//!   P(D) = (1 − e^{−D} − D e^{−D}) / (1 − e^{−D})
//!
//! (the first collision's density ∝ e^{−s} on [0, D], the next one within the D − s left). The
//! layer's orders take that path to be the cloud's D_s of depth. The sun's δ-M scattered light is
//! forward-peaked and runs along the sun's line, so the depth it actually has is the δ-M optical
//! chord through the point along the sun, τ′_c = τ′_⊙ (to the sun) + τ′ (onwards to the cloud's
//! far side). Where the chord is shorter than the layer (a cloud thin along the sun) each further
//! order is weighted by P(τ′_c)/P(D_s); where it is at least as deep, by 1 (light that stays
//! beyond the layer is the cubes' and the diffusion's).

use crate::lit::sunlight::{SunGrid, SunTransmittance};
use crate::math::Vec3;
use crate::medium::Medium;
use std::sync::Arc;

/// P(D) above: the chance that a photon whose first collision lies on a path of optical depth
/// `depth` (unitless) collides again on it, moving along it.
pub fn chord_stay(depth: f64) -> f64 {
    if depth < 1e-4 {
        // The series: D/2 − D²/12 (the closed form loses its digits to cancellation).
        return (0.5 * depth - depth * depth / 12.0).max(0.0);
    }
    let e = (-depth).exp();
    (1.0 - e - depth * e) / (1.0 - e)
}

/// The δ-M chord along the sun at every voxel centre, as the factor on the sun's further orders.
pub struct SunChord {
    /// exp(−τ′) towards the sun (the lit volume's grid).
    to_sun: Arc<SunGrid>,
    /// exp(−τ′) away from the sun, to the cloud's far side.
    onwards: SunGrid,
    /// P(D_s) of the layer's depth.
    layer_stay: f64,
}

impl SunChord {
    /// For medium `m` (the δ-M medium the gather sees), the unit direction `sun_dir` towards the
    /// sun, its transmittance grid `to_sun` (of that medium) and the layer's depth D_s (> 0).
    pub fn new(m: &Medium, sun_dir: Vec3, to_sun: Arc<SunGrid>, layer_depth: f32) -> Self {
        let onwards = Arc::unwrap_or_clone(SunTransmittance::compute(m, -sun_dir).grid);
        SunChord {
            to_sun,
            onwards,
            layer_stay: chord_stay(layer_depth as f64),
        }
    }

    /// The chord's optical depth τ′_c at voxel coordinates `v` (trilinear transmittances).
    pub fn depth_at(&self, v: Vec3) -> f64 {
        let t = |g: &SunGrid| -(g.trilinear(v.to_array()).max(f32::MIN_POSITIVE) as f64).ln();
        t(&self.to_sun) + t(&self.onwards)
    }

    /// The factor on each further order at voxel coordinates `v`: min(1, P(τ′_c)/P(D_s)), in [0, 1].
    pub fn stay_at(&self, v: Vec3) -> f64 {
        if self.layer_stay <= 0.0 {
            return 1.0;
        }
        (chord_stay(self.depth_at(v)) / self.layer_stay).min(1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Rgb;
    use crate::medium::Grid3;

    /// P(D) against its definition integrated numerically, and its limits.
    #[test]
    fn chord_stay_is_the_integral() {
        for &d in &[1e-5, 0.01, 0.3, 1.5, 4.0, 20.0] {
            let n = 20_000;
            let (mut num, mut den) = (0.0, 0.0);
            for k in 0..n {
                let s = d * (k as f64 + 0.5) / n as f64;
                num += (-s).exp() * (1.0 - (-(d - s)).exp());
                den += (-s).exp();
            }
            let want = num / den;
            assert!((chord_stay(d) - want).abs() < 1e-6 * want.max(1e-3), "D = {d}: {} vs {want}", chord_stay(d));
        }
        assert_eq!(chord_stay(0.0), 0.0);
        assert!((chord_stay(60.0) - 1.0).abs() < 1e-12);
    }

    /// A uniform medium of `dims` voxels of 1 m, extinction `sigma_t` (m⁻¹).
    fn uniform(density: Grid3, sigma_t: f32) -> Medium {
        Medium::new(density, Vec3::ZERO, Vec3::ONE, sigma_t, Rgb::ONE, 0.0)
    }

    fn chord(m: &Medium, sun: Vec3, depth: f32) -> SunChord {
        let to_sun = SunTransmittance::compute(m, sun).grid;
        SunChord::new(m, sun, to_sun, depth)
    }

    /// A thick slab lit from above: the chord through every voxel is deep, the factor 1.
    #[test]
    fn thick_slab_keeps_every_order() {
        let m = uniform(Grid3::filled([6, 6, 40], 1.0), 0.5);
        let c = chord(&m, Vec3::Z, 3.0);
        for k in [0, 5, 20, 39] {
            let v = m.to_voxel(m.voxel_center(3, 3, k));
            assert!(c.depth_at(v) > 19.0, "k = {k}: {}", c.depth_at(v));
            assert_eq!(c.stay_at(v), 1.0, "k = {k}");
        }
    }

    /// A thin sphere: at its centre the chord along the sun is its optical diameter, and the factor
    /// is P(diameter)/P(D_s) < 1.
    #[test]
    fn thin_sphere_loses_its_further_orders() {
        let n = 33;
        let r = 12.0;
        let mut g = Grid3::filled([n, n, n], 0.0);
        let c0 = (n / 2) as f32;
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let p = Vec3::new(i as f32, j as f32, k as f32) - Vec3::splat(c0);
                    if p.length() <= r {
                        g.set(i, j, k, 1.0);
                    }
                }
            }
        }
        let sigma_t = 0.05;
        let m = uniform(g, sigma_t);
        let sun = Vec3::new(0.3, 0.4, 0.866).normalize();
        let c = chord(&m, sun, 3.0);
        let v = m.to_voxel(m.voxel_center(n / 2, n / 2, n / 2));
        // The trilinear field's chord through the centre: the sphere's diameter within a voxel.
        let diameter = (2.0 * r * sigma_t) as f64;
        assert!((c.depth_at(v) - diameter).abs() < 1.5 * sigma_t as f64, "{} vs {diameter}", c.depth_at(v));
        let want = chord_stay(c.depth_at(v)) / chord_stay(3.0);
        assert!((c.stay_at(v) - want).abs() < 1e-12);
        assert!(c.stay_at(v) < 0.8, "{}", c.stay_at(v));
        // Nearer the rim the chord shortens and the factor with it.
        let rim = m.to_voxel(m.voxel_center(n / 2 + 10, n / 2, n / 2));
        assert!(c.stay_at(rim) < c.stay_at(v));
    }
}
