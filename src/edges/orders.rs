//! Orders of scattering along a low-density segment (paper section 4, eqs. 8–9).
//!
//! Along a segment of optical depth D, the number of scattering events is taken as Poisson:
//! q_i = e^{−D} D^i / i! (eq. 8). The phase function of i successive Henyey–Greenstein events is
//! the i-fold spherical self-convolution of HG(g), which is again HG with g^i (HG's Legendre
//! coefficients are g^l, and convolution on the sphere multiplies them): [`crate::optics::Hg::order`].

/// Poisson weights q_0, q_1, …, q_n for optical depth `d` (unitless), with n the smallest order
/// such that the omitted tail 1 − Σ q_i is below `tail` (e.g. 1e-4).
pub fn poisson_weights(d: f64, tail: f64) -> Vec<f64> {
    let d = d.max(0.0);
    let mut q = Vec::with_capacity(16);
    let mut term = (-d).exp();
    let mut sum = 0.0;
    let mut i = 0u32;
    loop {
        q.push(term);
        sum += term;
        // Stop once the remainder is small; the remainder is computed as 1 − sum, which is
        // accurate while sum is far from 1 − ε_machine (tails ≥ 1e-12).
        if 1.0 - sum < tail || i > 10_000 {
            break;
        }
        i += 1;
        term *= d / i as f64;
    }
    q
}

/// The mean optical depth, from a segment's near end, of the light it scatters towards the eye:
/// τ̄ = ∫₀ᴰ τ e^{−τ} dτ / ∫₀ᴰ e^{−τ} dτ = 1 − D/(e^D − 1). A cube read there gives the exact
/// ∫₀ᴰ e^{−τ} S(τ) dτ = (1 − e^{−D}) S(τ̄) for a source linear in depth, where the optical midpoint
/// D/2 does not. D/2 − D²/12 + D⁴/720 for thin segments (the paper's midpoint as D → 0); 0.925
/// for the surface layer's D = 4, where the eye sees the field at depth ~1 (Eddington–Barbier), not
/// at 2.
pub fn eye_weighted_depth(d: f64) -> f64 {
    let d = d.max(0.0);
    if d < 1e-3 {
        // The closed form cancels here; the series' next term is below 10⁻¹⁶·D.
        let d2 = d * d;
        return d * (0.5 - d / 12.0 + d2 * d / 720.0);
    }
    1.0 - d / d.exp_m1()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::Hg;

    fn hg_f64(mu: f64, g: f64) -> f64 {
        let g = g as f32;
        Hg::new(g).eval_cos_f64(mu)
    }
    use std::f64::consts::PI;

    #[test]
    fn poisson_weights_sum_to_one_minus_tail() {
        for &d in &[0.0, 1e-3, 0.1, 0.5, 1.0, 3.0, 10.0, 40.0] {
            for &tail in &[1e-4, 1e-8] {
                let q = poisson_weights(d, tail);
                let s: f64 = q.iter().sum();
                assert!(1.0 - s < tail && 1.0 - s >= -1e-12, "d={d} sum={s}");
                // The last order is needed: without it the tail would exceed the bound.
                if q.len() > 1 {
                    assert!(1.0 - (s - q[q.len() - 1]) >= tail, "d={d}: one order too many");
                }
                // Exact values against the closed form.
                let mut fact = 1.0;
                for (i, qi) in q.iter().enumerate() {
                    if i > 0 {
                        fact *= i as f64;
                    }
                    let exact = (-d).exp() * d.powi(i as i32) / fact;
                    assert!((qi - exact).abs() <= 1e-12 * exact.max(1e-300) + 1e-300, "q_{i}({d})");
                }
            }
        }
    }

    #[test]
    fn eye_weighted_depth_is_the_mean_depth_under_the_eyes_attenuation() {
        for &d in &[1e-6, 1e-4, 9.99e-4, 1.001e-3, 0.01, 0.3, 1.0, 4.0, 20.0] {
            // Midpoint rule for ∫ τ e^{−τ} / ∫ e^{−τ} over [0, D].
            let n = 20_000;
            let (mut num, mut den) = (0.0, 0.0);
            for k in 0..n {
                let t = d * (k as f64 + 0.5) / n as f64;
                num += t * (-t).exp();
                den += (-t).exp();
            }
            let want = num / den;
            assert!((eye_weighted_depth(d) - want).abs() < 1e-6 * want, "D = {d}: {} vs {want}", eye_weighted_depth(d));
        }
        // Thin: the paper's midpoint less D²/12; the layer's D = 4: 0.925, well short of 2.
        assert!((eye_weighted_depth(1e-5) - (0.5e-5 - 1e-10 / 12.0)).abs() < 1e-18);
        assert!((eye_weighted_depth(4.0) - 0.92537).abs() < 1e-5);
        assert_eq!(eye_weighted_depth(0.0), 0.0);
    }

    /// (p ∗ p)(cos θ) = ∫ p(ω·ω′) p(ω′·ẑ) dω′ by quadrature on the sphere.
    fn self_convolution(g: f64, theta: f64, n_theta: usize, n_phi: usize) -> f64 {
        let omega = [theta.sin(), 0.0, theta.cos()];
        let mut sum = 0.0;
        // Gauss-like midpoint rule in μ′ = cos θ′, refined where the integrand peaks (μ′ near 1
        // and near ω): a smooth substitution μ′ = 1 − 2s² concentrates points at μ′ = 1.
        for i in 0..n_theta {
            let s = (i as f64 + 0.5) / n_theta as f64;
            let mu = 1.0 - 2.0 * s * s;
            let dmu = 4.0 * s / n_theta as f64;
            let st = (1.0 - mu * mu).max(0.0).sqrt();
            let p2 = hg_f64(mu, g);
            for j in 0..n_phi {
                let phi = (j as f64 + 0.5) / n_phi as f64 * 2.0 * PI;
                let w = [st * phi.cos(), st * phi.sin(), mu];
                let c = w[0] * omega[0] + w[1] * omega[1] + w[2] * omega[2];
                sum += hg_f64(c, g) * p2 * dmu * (2.0 * PI / n_phi as f64);
            }
        }
        sum
    }

    #[test]
    fn hg_convolved_with_itself_is_hg_of_g_squared() {
        for &g in &[0.3, 0.6, 0.8] {
            for &theta in &[0.0f64, 0.2, 0.6, 1.5, 3.0] {
                let conv = self_convolution(g, theta, 1200, 720);
                let exact = hg_f64(theta.cos(), g * g);
                // Quadrature error of the peaked integrand: 0.5 % at g = 0.8 with this grid.
                assert!((conv - exact).abs() < 5e-3 * exact, "g={g} θ={theta}: {conv} vs {exact}");
            }
        }
    }
}
