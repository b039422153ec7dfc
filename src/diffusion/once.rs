//! The sun's once-scattered light in a half-space lit at normal incidence, as a function of the
//! δ-M depth τ along the sun.
//!
//! At depth τ the light scattered once from the beam E e^{−τ} and travelling with direction
//! cosine μ to the sun's direction is (per unit a′E e^{−τ}, p the phase function per steradian)
//!
//! ```text
//!   I1s(μ, τ) = p(μ) G(μ, τ),  G = (1 − e^{−τ(1/μ − 1)})/(1 − μ) for μ > 0,  1/(1 − μ) for μ ≤ 0
//! ```
//!
//! (the integral of the source e^{−τ′} along the ray back to the surface, or to infinite depth for
//! light travelling up). Its mean radiance M0 = ½∫ p G dμ and first moment M1 = ½∫ p G μ dμ.

use crate::optics::Hg;

/// Per order n = 1..=K of the sun's light scattered n times in the half-space (albedo 1; order n
/// scales by a′ⁿ), its mean radiance M0ⁿ(τ) and first moment M1ⁿ(τ) per unit E e^{−τ}.
#[derive(Clone, Debug)]
pub struct OnceScattered {
    m0: Vec<Vec<f64>>,
    m1: Vec<Vec<f64>>,
}

/// Depth beyond which e^{−τ} < 10⁻¹³: the table ends there.
const TAU_MAX: f64 = 30.0;
/// Table nodes per unit depth.
const PER_UNIT: usize = 16;
/// Legendre orders of the phase function's azimuthal mean.
const L_MAX: usize = 64;

impl OnceScattered {
    /// For the phase function `phase`, orders 1..=`k`.
    pub fn new(phase: Hg, k: usize) -> OnceScattered {
        let (mu, wt) = crate::transport::gauss_legendre(64);
        let n = (TAU_MAX as usize) * PER_UNIT;
        let dt = 1.0 / PER_UNIT as f64;
        let tau = |i: usize| i as f64 * dt;
        let g = phase.mean_cosine();
        let pl: Vec<Vec<f64>> = mu.iter().map(|&x| crate::transport::legendre(L_MAX, x)).collect();
        // Order 1, exact: p(μ) e^{−τ} G(μ, τ).
        let mut field: Vec<Vec<f64>> = (0..=n)
            .map(|i| {
                let t = tau(i);
                mu.iter()
                    .map(|&x| {
                        let gg = if x > 0.0 { -(-t * (1.0 / x - 1.0)).exp_m1() / (1.0 - x) } else { 1.0 / (1.0 - x) };
                        phase.eval_cos_f64(x) * (-t).exp() * gg
                    })
                    .collect()
            })
            .collect();
        let (mut m0, mut m1) = (Vec::new(), Vec::new());
        for order in 1..=k {
            let (a, b): (Vec<f64>, Vec<f64>) = field
                .iter()
                .enumerate()
                .map(|(i, row)| {
                    let e = (tau(i)).exp();
                    let a: f64 = row.iter().zip(&wt).map(|(v, w)| 0.5 * w * v).sum();
                    let b: f64 = row.iter().zip(&wt).zip(&mu).map(|((v, w), x)| 0.5 * w * v * x).sum();
                    (a * e, b * e)
                })
                .unzip();
            m0.push(a);
            m1.push(b);
            if order == k {
                break;
            }
            // The next order's source S(τ, μ) = Σ_l (2l+1)/2 g^l P_l(μ) Σ_j w_j P_l(μ_j) I(τ, μ_j).
            let source: Vec<Vec<f64>> = field
                .iter()
                .map(|row| {
                    let c: Vec<f64> = (0..=L_MAX)
                        .map(|l| (2 * l + 1) as f64 / 2.0 * g.powi(l as i32) * row.iter().zip(&wt).zip(&pl).map(|((v, w), p)| w * p[l] * v).sum::<f64>())
                        .collect();
                    pl.iter().map(|p| c.iter().zip(p).map(|(c, p)| c * p).sum::<f64>()).collect()
                })
                .collect();
            // Transfer along each direction, the source linear across each cell.
            let mut next = vec![vec![0.0; mu.len()]; n + 1];
            for (j, &x) in mu.iter().enumerate() {
                let xx = dt / x.abs();
                let e = (-xx).exp();
                let e1 = -(-xx).exp_m1();
                let e2 = (e1 - xx * e) / xx;
                if x > 0.0 {
                    for i in 0..n {
                        next[i + 1][j] = next[i][j] * e + source[i + 1][j] * (e1 - e2) + source[i][j] * e2;
                    }
                } else {
                    for i in (0..n).rev() {
                        next[i][j] = next[i + 1][j] * e + source[i][j] * (e1 - e2) + source[i + 1][j] * e2;
                    }
                }
            }
            field = next;
        }
        OnceScattered { m0, m1 }
    }

    /// Orders tabulated.
    pub fn orders(&self) -> usize {
        self.m0.len()
    }

    /// (M0ⁿ, M1ⁿ) of order `n` (1-based) at depth `tau` (linear in between nodes; the last node
    /// beyond).
    pub fn moments(&self, n: usize, tau: f64) -> (f64, f64) {
        let (m0, m1) = (&self.m0[n - 1], &self.m1[n - 1]);
        let x = (tau.max(0.0) * PER_UNIT as f64).min((m0.len() - 1) as f64);
        let i = (x as usize).min(m0.len() - 2);
        let t = x - i as f64;
        (m0[i] + t * (m0[i + 1] - m0[i]), m1[i] + t * (m1[i + 1] - m1[i]))
    }
}

/// The switch of the experiment (CLOUDGI_HYBRID).
pub fn hybrid(phase: Hg) -> Option<&'static OnceScattered> {
    static T: std::sync::OnceLock<Option<OnceScattered>> = std::sync::OnceLock::new();
    T.get_or_init(|| {
        std::env::var("CLOUDGI_HYBRID")
            .ok()
            .map(|k| OnceScattered::new(phase, k.parse().unwrap_or(1)))
    })
        .as_ref()
}

/// (Q0, Q1) second-collision over first-collision source of the full voxel in `slot`, band `c`:
/// (4π a′ M0(τ), 4π a′ M1(τ)), τ = −ln T̄; (1, 1) without the hybrid.
pub fn source_scale(inc: &crate::incident::IncidentLight, m: &crate::medium::Medium, slot: usize, c: usize) -> (f64, f64) {
    use crate::incident::FirstScattering;
    let Some(t) = hybrid(m.optics.phase) else {
        return (1.0, 1.0);
    };
    let FirstScattering::Sun { rho_t, .. } = &inc.scattering else {
        return (1.0, 1.0);
    };
    let rho = m.density.at_slot(slot) as f64;
    if rho <= 0.0 {
        return (1.0, 1.0);
    }
    let tbar = (f64::from(rho_t.at_slot(slot)) / rho).clamp(1e-30, 1.0);
    let n = t.orders();
    let (m0, m1) = t.moments(n, -tbar.ln());
    let k = 4.0 * std::f64::consts::PI * (m.optics.albedo[c] as f64).powi(n as i32);
    (k * m0, k * m1)
}

/// The once-scattered light's (I0, I1) at full voxel `slot`: (a′E T̄ M0, 3a′E T̄ M1 ŝ) per band,
/// ŝ the sun's travel direction; None without the hybrid.
pub fn once_moments(inc: &crate::incident::IncidentLight, m: &crate::medium::Medium, sun: &crate::lighting::Sun, slot: usize) -> Option<(crate::math::Rgb, [crate::math::Vec3; 3])> {
    use crate::incident::FirstScattering;
    let t = hybrid(m.optics.phase)?;
    let FirstScattering::Sun { rho_t, .. } = &inc.scattering else {
        return None;
    };
    let rho = m.density.at_slot(slot) as f64;
    if rho <= 0.0 {
        return None;
    }
    let tbar = (f64::from(rho_t.at_slot(slot)) / rho).clamp(0.0, 1.0);
    if tbar <= 0.0 {
        return None;
    }
    let tau = -tbar.ln();
    let sum = |c: usize| -> (f64, f64) {
        let a = m.optics.albedo[c] as f64;
        (1..=t.orders()).fold((0.0, 0.0), |(s0, s1), n| {
            let (m0, m1) = t.moments(n, tau);
            (s0 + a.powi(n as i32) * m0, s1 + a.powi(n as i32) * m1)
        })
    };
    let s: [(f64, f64); 3] = std::array::from_fn(sum);
    let i0: [f32; 3] = std::array::from_fn(|c| (sun.irradiance[c] as f64 * tbar * s[c].0) as f32);
    let i1 = std::array::from_fn(|c| -sun.dir * (3.0 * sun.irradiance[c] as f64 * tbar * s[c].1) as f32);
    Some((crate::math::Rgb::new(i0[0], i0[1], i0[2]), i1))
}
