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
    /// The rings of ordinates, in `dirs` order.
    pub rings: Vec<Ring>,
}

/// One ring of ordinates (one Gauss node in cos θ) and the cells of the sphere it stands for: the
/// band of cos θ whose width is its node's weight (the bands tile [−1, 1] in the nodes' order, and
/// each holds its node), cut into `count` equal azimuth sectors, each centred on an ordinate. A
/// cell's solid angle is its ordinate's weight.
#[derive(Clone, Debug, PartialEq)]
pub struct Ring {
    /// The band of cos θ, low to high.
    pub mu: [f64; 2],
    /// Its first ordinate in `dirs` and how many it has.
    pub first: usize,
    pub count: usize,
}

impl Quadrature {
    /// `n_mu` Gauss nodes in cos θ times `n_phi` azimuths (offset by half a step, so no ordinate
    /// is axis-aligned). Exact for spherical polynomials of degree < 2·n_mu in θ and < n_phi in φ:
    /// products Y_lm Y_l′m′ with l, l′ ≤ L need n_mu ≥ L + 1 and n_phi ≥ 2L + 1.
    pub fn product(n_mu: usize, n_phi: usize) -> Quadrature {
        Self::rings(n_mu, |_| n_phi)
    }

    /// `n_mu` Gauss nodes in cos θ, each ring with fewer azimuths towards the poles, where the
    /// rings are shorter (SHDOM's reduced grid, Evans 1998): ring j gets the even count
    /// ⌊1.9 + (n_phi − 1) sin θ_j⌋, at least 8 (or `n_phi` when fewer), so its ordinates are
    /// about as far apart along the ring as on the horizon's. Exact for the products Y_lm Y_l′m′
    /// with |m| + |m′| below every ring's count: every harmonic of order ≤ L with |m| ≤ 3 for
    /// n_mu ≥ L + 1 (the higher |m| at the poles, where those harmonics are ∝ sin^|m| θ, carry
    /// little of a cloud's light: docs/transport.md, "Ordinates"). Even counts keep every
    /// ordinate's opposite.
    pub fn reduced(n_mu: usize, n_phi: usize) -> Quadrature {
        Self::rings(n_mu, |sin_theta| (((1.9 + (n_phi as f64 - 1.0) * sin_theta) as usize) & !1).clamp(8.min(n_phi), n_phi))
    }

    /// `n_mu` Gauss nodes in cos θ, the ring at sin θ with `azimuths(sin θ)` azimuths offset by
    /// half a step (so no ordinate is axis-aligned), each weighted by its node's share of 4π.
    fn rings(n_mu: usize, azimuths: impl Fn(f64) -> usize) -> Quadrature {
        let (x, w) = gauss_legendre(n_mu);
        let bands = mu_bands(&x, &w);
        let mut dirs = Vec::new();
        let mut weights = Vec::new();
        let mut rings = Vec::new();
        for ((mu, wm), band) in x.iter().zip(&w).zip(bands) {
            let s = (1.0 - mu * mu).max(0.0).sqrt();
            let n = azimuths(s);
            rings.push(Ring {
                mu: band,
                first: dirs.len(),
                count: n,
            });
            for k in 0..n {
                let phi = 2.0 * PI * (k as f64 + 0.5) / n as f64;
                dirs.push(DVec3::new(s * phi.cos(), *mu, s * phi.sin()));
                weights.push(wm * 2.0 * PI / n as f64);
            }
        }
        Quadrature { dirs, weights, rings }
    }

    /// The ordinate whose cell ([`Ring`]) holds the unit direction `dir`.
    pub fn cell_of(&self, dir: DVec3) -> usize {
        // The band holding cos θ, whatever the rings' order; cos θ = 1 (or above, rounded) in the
        // top band.
        let ring = self
            .rings
            .iter()
            .find(|r| (r.mu[0]..r.mu[1]).contains(&dir.y))
            .or_else(|| self.rings.iter().max_by(|a, b| a.mu[1].total_cmp(&b.mu[1])))
            .expect("a quadrature has rings");
        let phi = dir.z.atan2(dir.x).rem_euclid(2.0 * PI);
        let k = ((phi / (2.0 * PI) * ring.count as f64) as usize).min(ring.count - 1);
        ring.first + k
    }
}

/// The bands of cos θ the Gauss nodes `x` with weights `w` (summing to 2) stand for: in the
/// nodes' ascending order, each as wide as its weight, from −1 to 1. Each band holds its node
/// (the Chebyshev–Markov–Stieltjes separation of Gauss quadrature).
fn mu_bands(x: &[f64], w: &[f64]) -> Vec<[f64; 2]> {
    let mut order: Vec<usize> = (0..x.len()).collect();
    order.sort_by(|a, b| x[*a].total_cmp(&x[*b]));
    let mut bands = vec![[0.0; 2]; x.len()];
    let mut lo = -1.0;
    for (n, &i) in order.iter().enumerate() {
        // The last band ends at 1 exactly, whatever the weights' rounding.
        let hi = if n + 1 == order.len() { 1.0 } else { lo + w[i] };
        bands[i] = [lo, hi];
        lo = hi;
    }
    bands
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{real_sh, sh_count};
    use crate::transport::legendre;

    #[test]
    fn every_ordinate_lies_in_its_own_cell_and_the_cells_tile_the_sphere_by_the_weights() {
        for q in [Quadrature::reduced(8, 16), Quadrature::product(4, 8), Quadrature::reduced(2, 4)] {
            for (o, d) in q.dirs.iter().enumerate() {
                assert_eq!(q.cell_of(*d), o, "ordinate {o} at {d}");
            }
            // The cells' solid angles, counted on a fine grid of directions, are the weights.
            let (n_theta, n_phi) = (720, 1440);
            let mut area = vec![0.0; q.dirs.len()];
            for i in 0..n_theta {
                let theta = PI * (i as f64 + 0.5) / n_theta as f64;
                let d_omega = theta.sin() * (PI / n_theta as f64) * (2.0 * PI / n_phi as f64);
                for j in 0..n_phi {
                    let phi = 2.0 * PI * (j as f64 + 0.5) / n_phi as f64;
                    let dir = DVec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin());
                    area[q.cell_of(dir)] += d_omega;
                }
            }
            for (o, (a, w)) in area.iter().zip(&q.weights).enumerate() {
                assert!((a / w - 1.0).abs() < 0.02, "ordinate {o}: cell {a:.4} sr, weight {w:.4} sr");
            }
            assert_eq!(q.cell_of(DVec3::Y), q.cell_of(DVec3::new(1e-9, 1.0, 0.0)), "the pole");
            let mut bands: Vec<[f64; 2]> = q.rings.iter().map(|r| r.mu).collect();
            bands.sort_by(|a, b| a[0].total_cmp(&b[0]));
            assert_eq!((bands[0][0], bands[bands.len() - 1][1]), (-1.0, 1.0));
            assert!(bands.windows(2).all(|p| p[0][1] == p[1][0]), "contiguous: {bands:?}");
        }
    }

    #[test]
    fn quadrature_weights_sum_to_four_pi_and_sh_are_orthonormal() {
        let l = 5;
        let q = Quadrature::product(l + 1, 2 * l + 2);
        assert!((q.weights.iter().sum::<f64>() - 4.0 * PI).abs() < 1e-12);
        assert!(orthonormality_error(&q, l, l) < 1e-10);
    }

    /// max |Σ_d w_d Y_a(d) Y_b(d) − δ_ab| over the harmonics a, b of order ≤ `l` with |m| ≤ `m_max`.
    fn orthonormality_error(q: &Quadrature, l: usize, m_max: usize) -> f64 {
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
        // real_sh's index of (l, m) is l² + l + m.
        let m_of = |k: usize| (k as i64 - ((k as f64).sqrt() as i64).pow(2) - (k as f64).sqrt() as i64).unsigned_abs() as usize;
        let mut worst: f64 = 0.0;
        for a in (0..n).filter(|a| m_of(*a) <= m_max) {
            for b in (0..n).filter(|b| m_of(*b) <= m_max) {
                let s: f64 = ys.iter().zip(&q.weights).map(|(y, w)| w * y[a] * y[b]).sum();
                worst = worst.max((s - if a == b { 1.0 } else { 0.0 }).abs());
            }
        }
        worst
    }

    #[test]
    fn the_reduced_grid_is_symmetric_and_exact_up_to_m_3() {
        for (n_mu, ordinates) in [(2, 8), (4, 32), (6, 60), (8, 96), (16, 348)] {
            let q = Quadrature::reduced(n_mu, 2 * n_mu);
            assert_eq!(q.dirs.len(), ordinates, "n_mu {n_mu}");
            assert!((q.weights.iter().sum::<f64>() - 4.0 * PI).abs() < 1e-12);
            // Every ordinate's opposite is in the set, with its weight.
            for (d, w) in q.dirs.iter().zip(&q.weights) {
                let o = q.dirs.iter().position(|e| (*e + *d).length() < 1e-12).expect("opposite");
                assert_eq!(q.weights[o], *w);
            }
            let l = n_mu - 1;
            assert!(orthonormality_error(&q, l, 3) < 1e-12, "n_mu {n_mu}");
        }
        // The higher |m| are not integrated exactly: the product rule is.
        let l = 7;
        assert!(orthonormality_error(&Quadrature::reduced(8, 16), l, l) > 1e-2);
        assert!(orthonormality_error(&Quadrature::product(8, 16), l, l) < 1e-12);
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
