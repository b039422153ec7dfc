//! Directions on the sphere: a product quadrature (Gauss–Legendre in cos θ about +y, uniform in
//! azimuth) for the real spherical harmonics of [`crate::math::real_sh`].

use super::gauss_legendre;
use glam::DVec3;
use std::f64::consts::PI;

/// Discrete ordinates: unit directions and solid-angle weights (summing to 4π sr).
#[derive(Clone, Debug)]
pub struct Quadrature {
    /// Unit directions.
    pub dirs: Vec<DVec3>,
    /// Weights (sr).
    pub weights: Vec<f64>,
}

impl Quadrature {
    /// `n_mu` Gauss nodes in cos θ times `n_phi` azimuths (offset by half a step, so no ordinate
    /// is axis-aligned). Exact for spherical polynomials of degree < 2·n_mu in θ and < n_phi in φ:
    /// products Y_lm Y_l′m′ with l, l′ ≤ L need n_mu ≥ L + 1 and n_phi ≥ 2L + 1.
    pub fn product(n_mu: usize, n_phi: usize) -> Quadrature {
        let (x, w) = gauss_legendre(n_mu);
        let mut dirs = Vec::with_capacity(n_mu * n_phi);
        let mut weights = Vec::with_capacity(n_mu * n_phi);
        for (mu, wm) in x.iter().zip(&w) {
            let s = (1.0 - mu * mu).max(0.0).sqrt();
            for k in 0..n_phi {
                let phi = 2.0 * PI * (k as f64 + 0.5) / n_phi as f64;
                dirs.push(DVec3::new(s * phi.cos(), *mu, s * phi.sin()));
                weights.push(wm * 2.0 * PI / n_phi as f64);
            }
        }
        Quadrature { dirs, weights }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{real_sh, sh_count};
    use crate::transport::legendre;

    #[test]
    fn quadrature_weights_sum_to_four_pi_and_sh_are_orthonormal() {
        let l = 5;
        let q = Quadrature::product(l + 1, 2 * l + 2);
        assert!((q.weights.iter().sum::<f64>() - 4.0 * PI).abs() < 1e-12);
        let n = sh_count(l);
        let ys: Vec<Vec<f64>> = q
            .dirs
            .iter()
            .map(|d| {
                let mut y = vec![0.0; n];
                real_sh(l, *d, &mut y);
                y
            })
            .collect();
        for a in 0..n {
            for b in 0..n {
                let s: f64 = ys.iter().zip(&q.weights).map(|(y, w)| w * y[a] * y[b]).sum();
                let want = if a == b { 1.0 } else { 0.0 };
                assert!((s - want).abs() < 1e-10, "({a}, {b}): {s}");
            }
        }
    }

    #[test]
    fn addition_theorem_holds() {
        // Σ_m Y_lm(a) Y_lm(b) = (2l+1)/(4π) P_l(a·b).
        let (a, b) = (DVec3::new(0.3, 0.8, -0.52).normalize(), DVec3::new(-0.7, 0.1, 0.7).normalize());
        let l = 7;
        let (mut ya, mut yb) = (vec![0.0; sh_count(l)], vec![0.0; sh_count(l)]);
        real_sh(l, a, &mut ya);
        real_sh(l, b, &mut yb);
        let p = legendre(l, a.dot(b));
        for (ll, pl) in p.iter().enumerate() {
            let s: f64 = (ll * ll..(ll + 1) * (ll + 1)).map(|i| ya[i] * yb[i]).sum();
            assert!((s - (2 * ll + 1) as f64 / (4.0 * PI) * pl).abs() < 1e-12, "l={ll}");
        }
    }
}
