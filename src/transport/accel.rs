//! The acceleration's diffusion operator, made consistent with the sweeps' own diffusion limit.
//!
//! **Why.** A sweep step (`sweep::step::step_weights`: the source linear in optical path between the
//! upwind plane's bilinear back point and the voxel centre) is exact for a source linear along
//! the ray, but for one with curvature J″ along the ray it gives I = J − J′/σ + (1 + ε(τ)) J″/σ²
//! instead of J − J′/σ + J″/σ² (σ = ρσt′, τ = σs the step's optical length, s = h_a/|Ω_a|), with
//!
//! ```text
//! ε(τ) = (τ/2) coth(τ/2) − 1   (τ²/12 for thin steps, τ/2 − 1 for thick ones),
//! ```
//!
//! and the bilinear back point adds t(1 − t) h_b²/(2τ) ∂_b²J across each cross axis b (t = s|Ω_b|/h_b
//! the back point's offset; for any τ, since the radiance and the source carry the same error).
//! Summed over the ordinates this is a diffusion of its own,
//!
//! ```text
//! D_num,x(ρ) = Σ_Ω (w/4π) Ω_x² ε(ρσt′ s_Ω)/(ρσt′) + Σ_{Ω: x not major} (w/4π) t_x (1 − t_x) h_x²/(2 s_Ω)   (m),
//! ```
//!
//! O(h) in thick voxels against the physical 1/(3ρσtr′) (85 optical depths per voxel: ~60×). A
//! diffusion acceleration that underestimates the sweeps' diffusion by more than 2× amplifies the
//! error (Adams & Larsen 2002): the DSA with the physical coefficient alone diverged on voxels
//! more than a few optical depths thick. [`DsaOperator`] is the diffusion operator with
//! D = 1/(3ρσtr′) + D_num(ρ) on every face and in the Marshak boundary (β = 2D/h), so the
//! correction matches what the sweeps do at every thickness; in thin voxels D_num is negligible
//! and the operator is the physical one. The correction is still that of the error (its
//! right-hand side vanishes at convergence), so the converged solution is the sweeps' own.

use super::sphere::Quadrature;
use crate::diffusion::multigrid::{Stencil, Stencils, NONE};
use crate::diffusion::Domain;
use super::grid::full_of;
use crate::medium::sparse::FullIndex;
use crate::medium::Density;
use std::f64::consts::PI;

/// ε(τ) = (τ/2) coth(τ/2) − 1: the sweep step's extra curvature term along a ray of optical
/// length τ per step, in units of the exact 1/σ² (module docs).
pub(crate) fn step_curvature_excess(tau: f64) -> f64 {
    let x = 0.5 * tau;
    if x < 1e-2 {
        // x coth x − 1 = x²/3 − x⁴/45 + …; the closed form cancels here.
        return x * x / 3.0 - x.powi(4) / 45.0;
    }
    x / x.tanh() - 1.0
}

/// Table points per decade of ρσt′h and the decades it spans (10⁻⁶ to 10¹⁰ optical depths per
/// voxel); beyond them D_num is evaluated directly.
const PER_DECADE: f64 = 32.0;
const LOG_LO: f64 = -6.0;
const LOG_HI: f64 = 10.0;

/// The sweeps' numerical diffusion D_num per axis as a function of density (module docs), for
/// one band's σt′ on one quadrature and voxel size.
#[derive(Clone, Debug)]
pub(crate) struct SweepDiffusion {
    sigma_t: f64,
    /// Per ordinate: w/4π and its step length s (m).
    ords: Vec<(f64, f64)>,
    /// Per axis: Σ (w/4π) Ω_x² per ordinate (parallel to `ords`), and the bilinear part (m).
    along: [Vec<f64>; 3],
    cross: [f64; 3],
    /// ρσt′ h_min at table point 0 is 10^LOG_LO; per axis D_num (m) at the table points.
    h_min: f64,
    table: [Vec<f64>; 3],
}

impl SweepDiffusion {
    /// For extinction `sigma_t` (σt′ per unit density, m⁻¹), the sweeps' quadrature `q` and
    /// voxel size `h` (m).
    pub(crate) fn new(sigma_t: f64, q: &Quadrature, h: [f64; 3]) -> SweepDiffusion {
        let mut ords = Vec::with_capacity(q.dirs.len());
        let mut along: [Vec<f64>; 3] = Default::default();
        let mut cross = [0.0; 3];
        for (d, w) in q.dirs.iter().zip(&q.weights) {
            let om = [d.x, d.y, d.z];
            let r = [0, 1, 2].map(|a| om[a].abs() / h[a]);
            let a = (0..3).max_by(|p, q| r[*p].total_cmp(&r[*q])).unwrap_or(0);
            let s = h[a] / om[a].abs();
            let wn = w / (4.0 * PI);
            ords.push((wn, s));
            for ax in 0..3 {
                along[ax].push(wn * om[ax] * om[ax]);
                if ax != a {
                    let t = (s * om[ax].abs() / h[ax]).min(1.0);
                    cross[ax] += wn * t * (1.0 - t) * h[ax] * h[ax] / (2.0 * s);
                }
            }
        }
        let h_min = h.iter().copied().fold(f64::INFINITY, f64::min);
        let mut sd = SweepDiffusion {
            sigma_t,
            ords,
            along,
            cross,
            h_min,
            table: Default::default(),
        };
        let points = ((LOG_HI - LOG_LO) * PER_DECADE) as usize + 1;
        let table = [0, 1, 2].map(|ax| {
            (0..points)
                .map(|i| sd.direct(ax, 10f64.powf(LOG_LO + i as f64 / PER_DECADE) / (sigma_t * h_min)))
                .collect()
        });
        sd.table = table;
        sd
    }

    /// D_num on axis `ax` at density `rho` (m), summed over the ordinates.
    fn direct(&self, ax: usize, rho: f64) -> f64 {
        let st = rho * self.sigma_t;
        let along: f64 = self
            .ords
            .iter()
            .zip(&self.along[ax])
            .map(|((_, s), a)| a * step_curvature_excess(st * s) / st)
            .sum();
        along + self.cross[ax]
    }

    /// D_num on axis `ax` at density `rho` (m): linear in the table's log spacing (the function
    /// is smooth there), direct beyond it.
    pub(crate) fn at(&self, ax: usize, rho: f64) -> f64 {
        let x = ((rho * self.sigma_t * self.h_min).log10() - LOG_LO) * PER_DECADE;
        let t = &self.table[ax];
        if !(x >= 0.0 && x < (t.len() - 1) as f64) {
            return if rho > 0.0 && rho.is_finite() {
                self.direct(ax, rho)
            } else {
                self.cross[ax]
            };
        }
        let (i, f) = (x.floor() as usize, x.fract());
        t[i] + f * (t[i + 1] - t[i])
    }
}

/// The DSA's diffusion operator on the full voxels (module docs): −∇·(D∇δ) + ρσa′ δ with
/// D = 1/(3ρσtr′) + D_num(ρ) on each face (ρ the mean of the two voxels') and in the Marshak
/// boundary, the transport depth ρσtr′h floored at `tau_min` as in the diffusion module.
pub(crate) struct DsaOperator<'a> {
    /// Grid dimensions, the density and the full-voxel index of every grid voxel.
    pub grid: [usize; 3],
    pub rho: &'a Density,
    pub full: &'a FullIndex,
    /// Grid index of every full voxel (the unknowns), in grid order.
    pub voxels: &'a [usize],
    /// The box of the full voxels.
    pub dom: Domain,
    /// Voxel size (m).
    pub h: [f64; 3],
    /// Absorption and transport extinction per unit density (m⁻¹, δ-M scaled).
    pub sigma_a: f64,
    pub sigma_tr: f64,
    pub tau_min: f64,
    pub sweep: SweepDiffusion,
}

impl DsaOperator<'_> {
    /// D on axis `ax` at density `rho` (m).
    fn diffusivity(&self, ax: usize, rho: f64) -> f64 {
        self.h[ax] / (3.0 * (rho * self.sigma_tr * self.h[ax]).max(self.tau_min)) + self.sweep.at(ax, rho)
    }
}

impl Stencils for DsaOperator<'_> {
    fn dims(&self) -> [usize; 3] {
        self.dom.dims
    }

    fn len(&self) -> usize {
        self.voxels.len()
    }

    fn cell(&self, u: usize) -> u32 {
        let (v, g) = (self.voxels[u], self.grid);
        self.dom.cell([v % g[0], (v / g[0]) % g[1], v / (g[0] * g[1])])
    }

    fn stencil(&self, u: usize) -> Stencil {
        let (v, g) = (self.voxels[u], self.grid);
        let cell = [v % g[0], (v / g[0]) % g[1], v / (g[0] * g[1])];
        let gstride = [1, g[0], g[0] * g[1]];
        let rp = self.rho.at(v) as f64;
        let mut st = Stencil {
            diag: rp * self.sigma_a,
            off: [0.0; 6],
            nbr: [NONE; 6],
        };
        for ax in 0..3 {
            let h = self.h[ax];
            for (q, side) in [(2 * ax, -1i64), (2 * ax + 1, 1)] {
                let nc = cell[ax] as i64 + side;
                let nf = (nc >= 0 && nc < g[ax] as i64)
                    .then(|| full_of(self.full, (v as i64 + side * gstride[ax] as i64) as usize))
                    .filter(|f| *f != u32::MAX);
                match nf {
                    Some(nf) => {
                        let rho_f = 0.5 * (rp + self.rho.at(self.voxels[nf as usize]) as f64);
                        let cf = self.diffusivity(ax, rho_f) / (h * h);
                        st.diag += cf;
                        (st.off[q], st.nbr[q]) = (-cf, nf);
                    }
                    None => {
                        // Marshak: outward flux (β δ_P)/(h(1 + 2β)) per unit volume, β = 2D/h.
                        let beta = 2.0 * self.diffusivity(ax, rp) / h;
                        st.diag += beta / (h * (1.0 + 2.0 * beta));
                    }
                }
            }
        }
        st
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_curvature_excess_has_its_thin_and_thick_limits() {
        for tau in [1e-4, 1e-2, 0.019, 0.021, 0.3, 2.0, 30.0, 1e4] {
            let x: f64 = 0.5 * tau;
            let want = if tau < 0.02 {
                tau * tau / 12.0 - tau.powi(4) / 720.0
            } else if x < 5.0 {
                x * (1.0 + (-tau).exp()) / (1.0 - (-tau).exp()) - 1.0
            } else {
                x - 1.0
            };
            let got = step_curvature_excess(tau);
            assert!(
                (got - want).abs() <= 1e-9 * want.abs().max(1e-12) + 1e-15,
                "τ = {tau}: {got} vs {want}"
            );
        }
        assert!((step_curvature_excess(1e-3) / 1e-6 - 1.0 / 12.0).abs() < 1e-6);
    }

    #[test]
    fn the_sweeps_diffusion_is_negligible_in_thin_voxels_and_order_h_in_thick_ones() {
        let q = Quadrature::product(8, 16);
        let h = [10.0, 10.0, 10.0];
        let sd = SweepDiffusion::new(0.05, &q, h);
        for ax in 0..3 {
            // τ = 0.01 per voxel: the physical D = h/(3τ) is 333 h; the sweeps' own is below h/10.
            let thin = sd.at(ax, 0.01 / (0.05 * 10.0));
            assert!(thin > 0.0 && thin < 1.0, "axis {ax}: {thin}");
            // τ = 10⁴ per voxel: about <s Ω_x²>/2 + the bilinear part, a fraction of h.
            let thick = sd.at(ax, 1e4 / (0.05 * 10.0));
            assert!(thick > 1.0 && thick < 10.0, "axis {ax}: {thick}");
            // The table against the direct sum between its points, and beyond its end.
            for tau in [0.37, 5.3, 81.0, 2e11] {
                let rho = tau / (0.05 * 10.0);
                let (t, d) = (sd.at(ax, rho), sd.direct(ax, rho));
                assert!((t - d).abs() <= 1e-3 * d, "τ = {tau}: {t} vs {d}");
            }
        }
    }
}

#[cfg(test)]
mod solve_tests {
    use crate::lighting::{Sky, Sun};
    use crate::math::{Rgb, Vec3};
    use crate::medium::{Grid3, Medium};
    use crate::pipeline::NoProgress;
    use crate::transport::solve::{solve, TransportSettings};

    /// A filled 8³ cube of 1-m voxels at `sigma_t` m⁻¹, albedo 1, g = 0: density 1 inside, 0.02
    /// in its outer layer (a cloud's soft edge: through a sharp edge of τ ≫ 1 the sweeps couple
    /// the inside to the sky only by e^{−τ/2}, and every uniform field is nearly a solution).
    fn cube(sigma_t: f32) -> Medium {
        let mut g = Grid3::filled([8, 8, 8], 0.02);
        for k in 1..7 {
            for j in 1..7 {
                for i in 1..7 {
                    g.set(i, j, k, 1.0);
                }
            }
        }
        Medium::new(g, Vec3::ZERO, Vec3::ONE, sigma_t, Rgb::ONE, 0.0)
    }

    #[test]
    fn a_conservative_cube_of_thick_voxels_under_a_uniform_sky_converges_to_the_sky() {
        // 50 optical depths per voxel (1 in the edge layer) under a sky of radiance 1, no sun:
        // the radiance is 1 everywhere (the furnace; an exact discrete solution of the sweeps
        // too). With the
        // physical diffusion coefficient alone the acceleration diverged here, and plain
        // iteration (of the order of τ² sweeps) did not converge in 60.
        let sun = Sun {
            dir: Vec3::Y,
            irradiance: Rgb::ZERO,
        };
        let f = solve(
            &cube(50.0),
            &sun,
            &Sky::constant(Rgb::ONE),
            None,
            &TransportSettings::default(),
            &NoProgress,
        )
        .unwrap();
        assert!(f.iterations() <= 30, "{} iterations", f.iterations());
        let nsh = crate::math::sh_count(f.order);
        let y00 = 1.0 / (4.0 * std::f32::consts::PI).sqrt();
        for (v, s) in f.diffuse_source.chunks_exact(3 * nsh).enumerate() {
            for b in 0..3 {
                // a′χ′_0 I_00 Y_00 with a′ = χ′_0 = 1: the mean radiance.
                let i0 = s[b * nsh] * y00;
                assert!((i0 - 1.0).abs() < 0.03, "voxel {v} band {b}: I0 = {i0}");
            }
        }
    }

    #[test]
    fn voxels_too_thick_to_converge_are_refused_before_the_solve() {
        let sun = Sun {
            dir: Vec3::Y,
            irradiance: Rgb::splat(3.0),
        };
        let e = solve(
            &cube(1e6),
            &sun,
            &Sky::constant(Rgb::ONE),
            None,
            &TransportSettings::default(),
            &NoProgress,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.starts_with("transport solve:") && e.contains("--method reference") && e.contains("medium.voxel_size"),
            "{e}"
        );
    }
}
