//! `--method transport`: a converged discrete-ordinates solution of the radiative transfer
//! equation, with δ-M scaled optics, the sun exact and apart, and the iteration accelerated by a
//! diffusion solve (diffusion synthetic acceleration, DSA). See docs/transport.md.
//!
//! - [`TransportOptics`]: the medium's optics after the δ-M similarity transform (Wiscombe 1977)
//!   truncated at the solver's Legendre order, the one place the transport solver reads σt,
//!   albedo and g (the medium's own are [`crate::optics::Optics`]).
//! - [`slab`]: the solver on a plane-parallel column (checked against adding-doubling).
//! - [`solve`]: the 3-D solver (SH source per full voxel, sweeps, DSA); its stages are the private
//!   modules `sweep`, `source`, `dsa` (its operator in `accel`), `mixing`, `start` (the first iterations at a lower order), `ground`, `grid` and `convergence`. The gather is
//!   `crate::render::transport`.

mod accel;
mod convergence;
mod dsa;
mod grid;
mod ground;
mod mixing;
mod simd;
pub mod slab;
pub mod solve;
mod source;
mod sky_cells;
pub mod sphere;
mod start;
mod sweep;
pub mod warm;

use crate::error::{check, Error, Result};
use crate::medium::Medium;
use solve::TransportSettings;

/// Most Legendre order `render.transport_order` accepts (memory grows as (L + 1)², the sweeps'
/// work as (L + 1)² times the ordinates).
pub const MAX_ORDER: usize = 15;

/// Most Gauss–Legendre nodes `render.transport_polar_ordinates` accepts (2·32² = 2048 ordinates).
pub const MAX_POLAR_ORDINATES: usize = 32;

impl TransportSettings {
    /// Check the `render.transport_*` keys that set these settings (`file` names the scene).
    pub fn validate(&self, file: &str) -> Result<()> {
        check(
            file,
            "render.transport_order",
            (1..=MAX_ORDER).contains(&self.order),
            self.order,
            &format!("the Legendre order is 1 to {MAX_ORDER} (default 7; 5 is faster, 9 resolves backlit glow better)"),
        )?;
        // An odd count puts a ring of ordinates on the horizon (μ = 0), which the plane sweeps
        // handle worse (docs/transport.md).
        check(
            file,
            "render.transport_polar_ordinates",
            (2..=MAX_POLAR_ORDINATES).contains(&self.n_mu) && self.n_mu % 2 == 0,
            self.n_mu,
            &format!(
                "the ordinates in cos θ are an even count from 2 to {MAX_POLAR_ORDINATES} (default 8; \
                 at least render.transport_order + 1 integrates the source exactly)"
            ),
        )?;
        // Fewer rings than L + 1 do not integrate the source's products Y_lm Y_l′m′, and the
        // iteration can diverge (order 11 on 8 rings, order 7 on 2).
        if self.n_mu < self.order + 1 {
            return Err(Error::invalid(
                file,
                "render.transport_polar_ordinates",
                format!(
                    "{} is less than render.transport_order + 1 = {}: the ordinates do not integrate the \
                     order-{} source and the iteration can diverge; set render.transport_polar_ordinates = {} \
                     or lower render.transport_order",
                    self.n_mu,
                    self.order + 1,
                    self.order,
                    (self.order + 1).next_multiple_of(2)
                ),
            ));
        }
        check(
            file,
            "render.transport_tolerance",
            self.tolerance.is_finite() && self.tolerance > 0.0 && self.tolerance < 1.0,
            self.tolerance,
            "the relative change of I0 that stops the iteration is in (0, 1), e.g. 5e-3",
        )?;
        check(
            file,
            "render.transport_max_iterations",
            self.max_iterations >= 1,
            self.max_iterations,
            "the solver needs at least 1 iteration (default 60)",
        )
    }
}

/// Peak memory of a transport render (solve, eye source and gather; not the image), estimated
/// from the medium before anything is allocated. Peak resident memory measured on the
/// development sandbox (`/usr/bin/time -f %M`, two threads, 8×6 images unless named;
/// docs/performance.md, "Peaks"): the default cloud at 50×40×30 20.7 MB, 100×80×60 99.2 MB and
/// 200×160×120 709 MB, the Disney cloud at 1/16 (363 k full voxels, 320×240) 749 MB; the model
/// below is 1.03–1.24 times each (the most on the smallest cloud, where the fixed part is most of
/// it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TransportMemory {
    /// Voxels with ρ > 0.
    pub full_voxels: u64,
    /// The SH order it was estimated for.
    pub order: usize,
    /// The estimate (bytes).
    pub bytes: u64,
}

impl TransportMemory {
    /// Bytes of a render whatever the cloud: the program, its libraries and threads.
    pub const FIXED_BYTES: u64 = 14 << 20;
    /// Bytes per voxel of the whole grid at the solve's peak: the medium's occupancy index
    /// (0.25 B), through which the full voxels are found, rounded up to the fit of the
    /// measurements (the gather's dense density copy, 4 B per box voxel, comes after the solve
    /// has freed its sweep arrays).
    pub const GRID_BYTES: u64 = 8;
    /// Bytes per voxel of the tight box of full voxels: the sweeps' cells in three orders
    /// (3 × 8 B per voxel of the swept box), the acceleration's box-sized arrays, and a margin
    /// that keeps the estimate at or above the measured peaks.
    pub const DOMAIN_BYTES: u64 = 56;

    /// Bytes per full voxel beside the harmonic arrays and the batch array: the δ-M sun
    /// transmittance per band (12 B) and the acceleration's per-unknown arrays (its right-hand
    /// sides, corrections and CG vectors; 55–68 B measured), which live beside the batch array.
    pub const FULL_EXTRA_BYTES: u64 = 84;

    /// Bytes per full voxel: at the solve's peak two spherical-harmonic arrays (the moments and
    /// the sweep's new moments; the source is evaluated from the moments, not stored) of 3 bands
    /// × (L + 1)² f32, the batch array of ordinates' sources, in place of which the sweeps write
    /// their radiances (12 B each), the mixing's history (240 B) and [`Self::FULL_EXTRA_BYTES`]:
    /// 2,052 B at order 7 (a stored source array would add 768 B).
    pub fn bytes_per_full_voxel(order: usize) -> u64 {
        2 * 3 * 4 * crate::math::sh_count(order) as u64
            + 12 * source::ORDINATE_BATCH as u64
            + mixing::bytes_per_full_voxel()
            + Self::FULL_EXTRA_BYTES
    }

    /// The estimate for medium `m` solved with `s`.
    pub fn of(m: &Medium, s: &TransportSettings) -> TransportMemory {
        let full = m.density.count() as u64;
        let domain = crate::diffusion::Domain::of(m).map_or(0, |d| d.dims.iter().product::<usize>()) as u64;
        TransportMemory {
            full_voxels: full,
            order: s.order,
            bytes: Self::FIXED_BYTES
                + full * Self::bytes_per_full_voxel(s.order)
                + m.density.len() as u64 * Self::GRID_BYTES
                + domain * Self::DOMAIN_BYTES,
        }
    }

    /// Refuse, naming the fixes, an estimate over `limit` bytes (`what` says what the limit is,
    /// e.g. "the memory available"; `coarser` leads the ways to coarsen the cloud,
    /// [`crate::medium::MediumDesc::coarser_refine`]); `file` names the scene.
    pub fn check(&self, file: &str, limit: u64, what: &str, coarser: &str) -> Result<()> {
        if self.bytes <= limit {
            return Ok(());
        }
        let gib = |b: u64| b as f64 / (1u64 << 30) as f64;
        Err(Error::invalid(
            file,
            "medium",
            format!(
                "method transport needs about {:.1} GiB ({} full voxels × {} B at render.transport_order = {}, \
                 plus the grid and the acceleration's box) but {what} is {:.1} GiB; coarsen the cloud \
                 ({coarser}medium.downsample, medium.resolution or medium.max_voxels), lower \
                 render.transport_order, or use --method full",
                gib(self.bytes),
                self.full_voxels,
                Self::bytes_per_full_voxel(self.order),
                self.order,
                gib(limit)
            ),
        ))
    }
}

/// One band's optics after the δ-M transform of a Henyey–Greenstein phase function truncated
/// after Legendre order `L`: the forward fraction f = g^{L+1} moves into the unscattered beam,
/// σt′ = σt(1 − a f), a′ = a(1 − f)/(1 − a f), χ′_l = (g^l − f)/(1 − f) for l ≤ L. A
/// back-scattering phase function (g < 0) has no forward peak to truncate: f = 0 there (g^{L+1}
/// of a negative g is ±|g|^{L+1}, and with f = 0.43 for g = −0.9 at L = 7 the scaled moment
/// χ′_1 = −2.3 would make the scattering operator amplify the first moment: source iteration diverges).
/// So |χ′_l| ≤ 1 for every g.
#[derive(Clone, Debug, PartialEq)]
pub struct BandOptics {
    /// Scaled extinction σt′ per unit density (m⁻¹, or per unit optical depth on a slab).
    pub sigma_t: f64,
    /// Scaled single-scattering albedo a′.
    pub albedo: f64,
    /// Truncated fraction f.
    pub f: f64,
    /// Scaled Legendre moments χ′_0..χ′_L of the phase function (χ′_0 = 1).
    pub chi: Vec<f64>,
}

impl BandOptics {
    /// δ-M transform of (σt, a, HG g) truncated after order `order`.
    pub fn delta_m(sigma_t: f64, albedo: f64, g: f64, order: usize) -> BandOptics {
        let f = g.max(0.0).powi(order as i32 + 1);
        let scaled = crate::optics::delta_m(sigma_t, albedo, g, f);
        let chi = (0..=order).map(|l| (g.powi(l as i32) - f) / (1.0 - f)).collect();
        BandOptics {
            sigma_t: scaled.sigma_t,
            albedo: scaled.albedo,
            f,
            chi,
        }
    }

    /// Scaled transport extinction σtr′ = σt′(1 − a′χ′_1) per unit density (m⁻¹): the
    /// diffusion coefficient's 1/(3σtr′) and Fick's law of the acceleration.
    pub fn sigma_tr(&self) -> f64 {
        self.sigma_t * (1.0 - self.albedo * self.chi.get(1).copied().unwrap_or(0.0))
    }

    /// The truncated phase function p′(cos Θ) = Σ (2l+1) χ′_l P_l(cos Θ) (normalised to 4π over
    /// the sphere; it may be slightly negative far from the peak, which the sweeps tolerate).
    pub fn phase(&self, cos_theta: f64) -> f64 {
        let p = legendre(self.chi.len() - 1, cos_theta);
        self.chi
            .iter()
            .zip(&p)
            .enumerate()
            .map(|(l, (c, p))| (2 * l + 1) as f64 * c * p)
            .sum()
    }
}

/// The medium's optics for the transport solver: the exact HG g and, per RGB band, the δ-M
/// scaled extinction, albedo and phase moments.
#[derive(Clone, Debug, PartialEq)]
pub struct TransportOptics {
    /// Exact HG mean cosine (for the exact single scattering).
    pub g: f64,
    /// Exact extinction per unit density (m⁻¹).
    pub sigma_t: f64,
    /// Exact albedo per band.
    pub albedo: [f64; 3],
    /// δ-M scaled optics per band.
    pub bands: [BandOptics; 3],
}

impl TransportOptics {
    /// The medium's optics truncated after Legendre order `order`. The only reader of the
    /// medium's σt, albedo and g in this module.
    pub fn from_medium(m: &Medium, order: usize) -> TransportOptics {
        let o = &m.optics;
        let a = [o.albedo.x as f64, o.albedo.y as f64, o.albedo.z as f64];
        let (st, g) = (o.sigma_t as f64, o.phase.mean_cosine());
        TransportOptics {
            g,
            sigma_t: st,
            albedo: a,
            bands: a.map(|a| BandOptics::delta_m(st, a, g, order)),
        }
    }
}

/// Legendre polynomials P_0(x)..P_n(x) by the three-term recurrence.
pub fn legendre(n: usize, x: f64) -> Vec<f64> {
    let mut p = vec![1.0; n + 1];
    if n >= 1 {
        p[1] = x;
    }
    for l in 2..=n {
        p[l] = ((2 * l - 1) as f64 * x * p[l - 1] - (l - 1) as f64 * p[l - 2]) / l as f64;
    }
    p
}

/// `n`-point Gauss–Legendre nodes and weights on [−1, 1] (Newton on P_n; weights sum to 2).
pub fn gauss_legendre(n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut x = vec![0.0; n];
    let mut w = vec![0.0; n];
    for i in 0..n {
        let mut z = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            let p = legendre(n, z);
            // P_n′(z) = n (z P_n − P_{n−1}) / (z² − 1).
            dp = n as f64 * (z * p[n] - p[n - 1]) / (z * z - 1.0);
            let dz = p[n] / dp;
            z -= dz;
            if dz.abs() < 1e-15 {
                break;
            }
        }
        x[i] = -z;
        w[i] = 2.0 / ((1.0 - z * z) * dp * dp);
    }
    (x, w)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_legendre_integrates_polynomials_exactly() {
        let (x, w) = gauss_legendre(8);
        assert!((w.iter().sum::<f64>() - 2.0).abs() < 1e-13);
        // ∫ x^14 dx over [−1, 1] = 2/15 (degree 2n − 2 is exact).
        let s: f64 = x.iter().zip(&w).map(|(x, w)| w * x.powi(14)).sum();
        assert!((s - 2.0 / 15.0).abs() < 1e-13, "{s}");
        assert!(x.windows(2).all(|p| p[0] < p[1]));
    }

    #[test]
    fn delta_m_keeps_the_scaled_moments_and_normalisation() {
        let b = BandOptics::delta_m(2.0, 0.9, 0.8, 7);
        let f = 0.8f64.powi(8);
        assert!((b.f - f).abs() < 1e-15);
        assert!((b.sigma_t - 2.0 * (1.0 - 0.9 * f)).abs() < 1e-15);
        // Scattering optical depth of the non-truncated part is preserved: σt′a′ = σt a (1 − f).
        assert!((b.sigma_t * b.albedo - 2.0 * 0.9 * (1.0 - f)).abs() < 1e-14);
        assert_eq!(b.chi[0], 1.0);
        // (1/2)∫ p′ dμ = 1 and (1/2)∫ μ p′ dμ = χ′_1.
        let (x, w) = gauss_legendre(16);
        let n: f64 = x.iter().zip(&w).map(|(x, w)| 0.5 * w * b.phase(*x)).sum();
        let m1: f64 = x.iter().zip(&w).map(|(x, w)| 0.5 * w * x * b.phase(*x)).sum();
        assert!((n - 1.0).abs() < 1e-12, "{n}");
        assert!((m1 - b.chi[1]).abs() < 1e-12 && (b.chi[1] - (0.8 - f) / (1.0 - f)).abs() < 1e-14);
    }
}
