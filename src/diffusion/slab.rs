//! The diffusion method on a plane-parallel slab: the same stage-1 definitions (voxel-mean reduced
//! radiance, Q0 and Q1 as eqs. 5 and 6) and the same finite-difference rows (interior faces and
//! the ghost-eliminated Robin boundary of [`super`]) on a column of cells across the slab's
//! thickness. Sideways the slab is infinite (periodic lateral faces carry no net flux), so the 3-D
//! stencil reduces exactly to a tridiagonal system, solved directly.
//!
//! R and T are hemispherical flux ratios: the diffuse outflow through a boundary face is 4π φ
//! (= 2π I0 at the face), divided by the incident flux; T adds the unscattered transmission
//! (e^{−τ} for a normal beam, 2E₃(τ) for diffuse light), as the adding-doubling table does.

use super::{boundary_terms, interior_coupling};
use serde::Serialize;

/// How the slab is lit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Incidence {
    /// A beam at normal incidence (the adding-doubling table's UR1/UT1).
    Collimated,
    /// Uniform radiance from the whole upper hemisphere (cosine-weighted incident directions;
    /// the table's URU/UTU).
    Diffuse,
}

/// Reflected and transmitted fractions with their standard errors (0 from the deterministic
/// solvers, `diffusion::slab` and `transport::slab`).
#[derive(Clone, Copy, Debug, Serialize, PartialEq)]
pub struct SlabResult {
    /// Total reflectance (fraction of the incident flux leaving through the top).
    #[serde(rename = "R")]
    pub r: f64,
    /// Total transmittance (fraction leaving through the bottom, unscattered beam included).
    #[serde(rename = "T")]
    pub t: f64,
    /// Standard error of R.
    #[serde(rename = "R_stderr")]
    pub r_stderr: f64,
    /// Standard error of T.
    #[serde(rename = "T_stderr")]
    pub t_stderr: f64,
}

/// Exponential integral E_n(x) = ∫₀¹ μ^{n−2} e^{−x/μ} dμ (n ≥ 2, x ≥ 0), composite Gauss–Legendre.
pub fn expint(n: i32, x: f64) -> f64 {
    const X: [f64; 4] = [
        -0.861_136_311_594_052_6,
        -0.339_981_043_584_856_3,
        0.339_981_043_584_856_3,
        0.861_136_311_594_052_6,
    ];
    const W: [f64; 4] = [
        0.347_854_845_137_453_9,
        0.652_145_154_862_546_1,
        0.652_145_154_862_546_1,
        0.347_854_845_137_453_9,
    ];
    let m = 256;
    let mut s = 0.0;
    for k in 0..m {
        let (a, b) = (k as f64 / m as f64, (k + 1) as f64 / m as f64);
        for (xi, wi) in X.iter().zip(W) {
            let mu = 0.5 * (a + b) + 0.5 * (b - a) * xi;
            s += wi * 0.5 * (b - a) * mu.powi(n - 2) * (-x / mu).exp();
        }
    }
    s
}

/// R and T of a slab of optical thickness `tau`, albedo `a`, HG `g`, discretised with `cells` cells.
pub fn solve_slab(tau: f64, a: f64, g: f64, incidence: Incidence, cells: usize) -> SlabResult {
    if tau * (1.0 - a * g) < EMPTY_SLAB_DEPTH {
        return SlabResult { r: 0.0, t: 1.0, r_stderr: 0.0, t_stderr: 0.0 };
    }
    let n = cells.max(1);
    let h = 1.0;
    let sigma_t = tau / n as f64; // ρ = 1, h = 1 m
    let sigma_s = a * sigma_t;
    let sigma_a = sigma_t - sigma_s;
    let sigma_tr = sigma_t * (1.0 - a * g);
    let dtau = sigma_t * h;
    let four_pi = 4.0 * std::f64::consts::PI;
    // Voxel-mean Q0 and Q1 (z component, z = depth, light flows +z); incident flux E_in.
    let mut q0 = vec![0.0; n];
    let mut q1 = vec![0.0; n];
    let e_in = match incidence {
        Incidence::Collimated => {
            for k in 0..n {
                let t0 = k as f64 * dtau;
                let mean = (-t0).exp() * (-(-dtau).exp_m1()) / dtau;
                q0[k] = sigma_s / four_pi * mean;
                q1[k] = sigma_s * g / four_pi * mean;
            }
            1.0
        }
        Incidence::Diffuse => {
            // ∫_hemisphere e^{−t/μ} dω = 2π E2(t), ∫ μ e^{−t/μ} dω = 2π E3(t); cell means from E3, E4.
            let e3: Vec<f64> = (0..=n).map(|k| expint(3, k as f64 * dtau)).collect();
            let e4: Vec<f64> = (0..=n).map(|k| expint(4, k as f64 * dtau)).collect();
            for k in 0..n {
                let m2 = (e3[k] - e3[k + 1]) / dtau;
                let m3 = (e4[k] - e4[k + 1]) / dtau;
                let two_pi = 2.0 * std::f64::consts::PI;
                q0[k] = sigma_s / four_pi * two_pi * m2;
                q1[k] = sigma_s * g / four_pi * two_pi * m3;
            }
            std::f64::consts::PI
        }
    };
    let (x, f) = solve_column(&q0, &q1, sigma_a, sigma_tr);
    let (bd, bf) = boundary_terms(1.0, sigma_tr, h, 0.0);
    // Outgoing fluxes 4π φ / h·h (per unit area: φ/h·h).
    let phi_top = (bd * x[0] + bf * (-f[0])) * h;
    let phi_bot = (bd * x[n - 1] + bf * f[n - 1]) * h;
    let unscattered = match incidence {
        Incidence::Collimated => (-tau).exp(),
        Incidence::Diffuse => 2.0 * expint(3, tau),
    };
    SlabResult {
        r: four_pi * phi_top / e_in,
        t: four_pi * phi_bot / e_in + unscattered,
        r_stderr: 0.0,
        t_stderr: 0.0,
    }
}

/// I0 per cell (ρ = 1, h = 1, so σ per unit optical depth) of the column with sources `q0`, `q1`
/// (z components, z the depth), by the rows of [`super`]: interior faces and the ghost-eliminated
/// Marshak boundary (eq. 7) at both faces. Returns (I0, F = Q1/σtr) per cell.
fn solve_column(q0: &[f64], q1: &[f64], sigma_a: f64, sigma_tr: f64) -> (Vec<f64>, Vec<f64>) {
    let n = q0.len();
    let h = 1.0;
    // Tridiagonal system: lower l, diagonal d, upper u, rhs b.
    let f: Vec<f64> = q1.iter().map(|q| q / sigma_tr).collect();
    let mut d = vec![sigma_a; n];
    let mut l = vec![0.0; n];
    let mut u = vec![0.0; n];
    let mut b = q0.to_vec();
    let (bd, bf) = boundary_terms(1.0, sigma_tr, h, 0.0);
    let c = interior_coupling(1.0, 1.0, sigma_tr, h, 0.0);
    for k in 0..n {
        // Top face (outward normal −z).
        if k == 0 {
            d[k] += bd;
            b[k] -= bf * (-f[k]);
        } else {
            d[k] += c;
            l[k] = -c;
            b[k] += 0.5 * (f[k] + f[k - 1]) / h;
        }
        // Bottom face (outward +z).
        if k + 1 == n {
            d[k] += bd;
            b[k] -= bf * f[k];
        } else {
            d[k] += c;
            u[k] = -c;
            b[k] -= 0.5 * (f[k] + f[k + 1]) / h;
        }
    }
    // Thomas algorithm.
    let mut cp = vec![0.0; n];
    let mut dp = vec![0.0; n];
    for k in 0..n {
        let den = d[k] - if k > 0 { l[k] * cp[k - 1] } else { 0.0 };
        cp[k] = u[k] / den;
        dp[k] = (b[k] - if k > 0 { l[k] * dp[k - 1] } else { 0.0 }) / den;
    }
    let mut x = vec![0.0; n];
    for k in (0..n).rev() {
        x[k] = dp[k] - if k + 1 < n { cp[k] * x[k + 1] } else { 0.0 };
    }
    (x, f)
}

/// The diffusion's I0 per cell (W·m⁻²·sr⁻¹ per W·m⁻² of sun irradiance across its rays) in a
/// slab of optical thickness `tau` (`cells` cells of τ/cells each), albedo `a`, HG `g`, lit by
/// the sun at μ0 = cos of its angle from the inward normal: stage 1's voxel-mean Q0, Q1 (eqs. 5,
/// 6, the sun's direction's z component μ0 in Q1) and the 3-D solver's rows.
pub fn collimated_profile(tau: f64, a: f64, g: f64, mu0: f64, cells: usize) -> Vec<f64> {
    let n = cells.max(1);
    let dtau = tau / n as f64;
    let (sigma_s, sigma_a, sigma_tr) = (a * dtau, (1.0 - a) * dtau, dtau * (1.0 - a * g));
    let four_pi = 4.0 * std::f64::consts::PI;
    // Cell mean of e^{−t/μ0} over the cell's optical depths [t0, t0 + Δτ].
    let mean = |k: usize| (-(k as f64) * dtau / mu0).exp() * (-(-dtau / mu0).exp_m1()) * mu0 / dtau;
    let q0: Vec<f64> = (0..n).map(|k| sigma_s / four_pi * mean(k)).collect();
    let q1: Vec<f64> = q0.iter().map(|q| q * g * mu0).collect();
    solve_column(&q0, &q1, sigma_a, sigma_tr).0
}

/// [`solve_slab`] after the δ-M similarity transform with forward fraction `f` (0 ≤ f < 1;
/// [`crate::optics::delta_m`]): τ′ = τ(1 − a f), a′ = a(1 − f)/(1 − a f), g′ = (g − f)/(1 − f).
/// The forward-peaked fraction f of the scattering is treated as unscattered, so the transformed
/// slab's unscattered transmission e^{−τ′} (or 2E₃(τ′)) holds it and R, T stay hemispherical
/// totals. f = 0 is [`solve_slab`] exactly; f = g² ([`slab_forward_fraction`]) is the measured
/// choice.
pub fn solve_slab_similar(tau: f64, a: f64, g: f64, f: f64, incidence: Incidence) -> SlabResult {
    let scaled = crate::optics::delta_m(tau, a, g, f);
    solve_slab(scaled.sigma_t, scaled.albedo, scaled.g, incidence, default_cells(scaled.sigma_t))
}

/// The slab's forward fraction f = g² for g > 0 (0 otherwise): measured against the
/// adding-doubling table, it brings every row with (1 − g)τ ≥ 1 within 0.03 (docs/budget.md).
pub fn slab_forward_fraction(g: f64) -> f64 {
    if g > 0.0 {
        g * g
    } else {
        0.0
    }
}

/// Cells used for a slab of optical thickness `tau`: at most 0.05 optical depth per cell, at
/// least 40, but none thinner than [`MIN_CELL_DEPTH`].
pub fn default_cells(tau: f64) -> usize {
    let cells = ((tau / 0.05).ceil() as usize).clamp(40, 4000);
    cells.min(((tau / MIN_CELL_DEPTH) as usize).max(1))
}

/// The thinnest cell (optical depth): the face coupling 1/(3Δτ) of thinner cells is so much larger
/// than the absorption on the diagonal that the tridiagonal elimination cancels to 0/0 (at
/// Δτ ≈ 1e-16); a slab this thin is one cell, whose R and T are the thin limit's.
const MIN_CELL_DEPTH: f64 = 1e-9;

/// Below this optical depth (with the transport extinction σt(1 − a g)) R is under 1e-300 and
/// T rounds to 1: the slab is returned as empty (R = 0, T = 1, exact at τ = 0), where the
/// boundary's β = 2/(3τ) would overflow.
const EMPTY_SLAB_DEPTH: f64 = 1e-300;

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn thin_and_empty_slabs_reflect_nothing_and_transmit_everything() {
        for incidence in [Incidence::Collimated, Incidence::Diffuse] {
            assert_eq!(solve_slab_similar(0.0, 0.5, 0.0, 0.0, incidence), SlabResult { r: 0.0, t: 1.0, r_stderr: 0.0, t_stderr: 0.0 });
            // R ≈ a τ/2 (collimated) or a τ (diffuse), T ≈ 1 − 2τ at most; 2E₃'s quadrature rounds
            // within 1e-15 of 1.
            for tau in [1e-12, 1e-15, 1e-20, 1e-45, 1e-300] {
                let s = solve_slab_similar(tau, 0.5, 0.0, 0.0, incidence);
                assert!(s.r.is_finite() && s.t.is_finite(), "τ {tau}: {s:?}");
                assert!((0.0..=2.0 * tau).contains(&s.r) && (s.t - 1.0).abs() <= 4.0 * tau + 1e-15, "τ {tau}: {s:?}");
            }
        }
    }

    /// The diffuse outflow 4π φ through the top and bottom faces of the column `i0` (τ in
    /// `cells` cells, albedo `a`, HG `g`, sun at `mu0`): eq. 7's flux (β I_P + f)/(1 + 2β) with
    /// f = Q1·n/σtr of the face's cell, Q0 of a face cell a μ0(1 − e^{−Δτ/μ0})e^{−t0/μ0}/(4πΔτ)·Δτ.
    fn outflow(i0: &[f64], tau: f64, a: f64, g: f64, mu0: f64) -> (f64, f64) {
        let n = i0.len();
        let dtau = tau / n as f64;
        let sigma_tr = dtau * (1.0 - a * g);
        let (bd, bf) = boundary_terms(1.0, sigma_tr, 1.0, 0.0);
        let q0 = |t0: f64| a * mu0 * (-t0 / mu0).exp() * (-(-dtau / mu0).exp_m1()) / (4.0 * PI);
        let f = |t0: f64| q0(t0) * g * mu0 / sigma_tr;
        let top = bd * i0[0] - bf * f(0.0);
        let bottom = bd * i0[n - 1] + bf * f(tau - dtau);
        (4.0 * PI * top, 4.0 * PI * bottom)
    }

    #[test]
    fn an_oblique_sun_s_scattered_power_is_absorbed_or_leaves() {
        // Σ 4π σa I0 Δτ + the outflows = the power the beam loses to scattering, a μ0 (1 − e^{−τ/μ0}).
        let (tau, a, g) = (6.0, 0.9, 0.7);
        for mu0 in [1.0, 0.69, 0.4, 0.2] {
            let i0 = collimated_profile(tau, a, g, mu0, 120);
            let absorbed: f64 = i0.iter().map(|v| 4.0 * PI * (1.0 - a) * v * tau / 120.0).sum();
            let (up, down) = outflow(&i0, tau, a, g, mu0);
            let scattered = a * mu0 * -(-tau / mu0).exp_m1();
            assert!((absorbed + up + down - scattered).abs() < 1e-12, "μ0 {mu0}: {} vs {scattered}", absorbed + up + down);
            assert!(i0.iter().all(|v| v.is_finite() && *v > 0.0), "μ0 {mu0}");
        }
    }

    #[test]
    fn a_normal_sun_s_profile_gives_the_slab_s_reflectance_and_transmittance() {
        let (tau, a, g, cells) = (4.0, 0.95, 0.8, 80);
        let i0 = collimated_profile(tau, a, g, 1.0, cells);
        let (up, down) = outflow(&i0, tau, a, g, 1.0);
        let slab = solve_slab(tau, a, g, Incidence::Collimated, cells);
        assert!((up - slab.r).abs() < 1e-12 && (down + (-tau).exp() - slab.t).abs() < 1e-12, "{up} {down} {slab:?}");
    }
}
