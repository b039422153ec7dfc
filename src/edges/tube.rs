//! Where a segment's orders of scattering happen: inside its exclusion tube or in the cube's light.
//!
//! A segment's cube leaves out a tube of radius r around the segment (the cells the orders count,
//! paper section 6), so the cube's light K is the field that arrives at the tube's wall, and that
//! field already holds every collision it took outside the tube — with its absorption (the
//! diffusion's I0 is solved with the albedo). Eq. 9's a^i charges the albedo for all i collisions
//! of order i as if each lay on the segment. Only the collisions inside the tube are the segment's
//! own: going back from the last collision (on the eye ray, the tube's axis), the photon's previous
//! collision lies inside the tube with chance p = 1 − ⟨e^{−ℓ(ω′)}⟩, ℓ the optical chord back from
//! the axis to the tube's wall or end along the incoming direction ω′, averaged over the phase
//! function's ω′. Each earlier collision is the segment's with chance p again, and once the path
//! reaches the wall the rest is the cube's. Order i's albedo factor is then
//! a·[(1 − p)·Σ_{j=0}^{i−2} (p a)^j + (p a)^{i−1}]: a^i when p = 1 (eq. 9), a when p = 0, and 1 for
//! every order at a = 1 (the albedo-1 images do not move).

use crate::edges::orders::eye_weighted_depth;
use crate::optics::Hg;

/// Phase-function quantiles the chord average takes (the mean over them is the phase's average).
const QUANTILES: usize = 256;

/// The chance p that the light a segment scatters towards the eye took its previous collision
/// inside the segment's exclusion tube. `radius` is the tube's radius in optical depth (its radius
/// in m times the segment's mean extinction), `depth` the segment's optical depth D, `at` the
/// optical depth of the last collision from the segment's near end (the cube's place,
/// [`crate::edges::orders::eye_weighted_depth`]), `phase` the gather's (δ-M) phase function.
pub fn previous_collision_inside(radius: f64, depth: f64, at: f64, phase: Hg) -> f64 {
    if !(radius > 0.0 && depth > 0.0) {
        return 0.0;
    }
    let g = phase.mean_cosine();
    let (behind, front) = ((depth - at).max(0.0), at.clamp(0.0, depth));
    let mut escape = 0.0;
    for k in 0..QUANTILES {
        // μ = cos of the angle between the incoming direction and the way to the eye, at HG's
        // quantile (k + ½)/N: the mean over them is the phase-weighted mean over the sphere.
        let mu = hg_quantile(g, (k as f64 + 0.5) / QUANTILES as f64);
        let sin = (1.0 - mu * mu).max(0.0).sqrt();
        // μ > 0: the photon came from deeper in the segment (along the eye ray, away from the eye).
        let axial = if mu > 0.0 { behind / mu } else if mu < 0.0 { front / -mu } else { f64::INFINITY };
        let lateral = if sin > 0.0 { radius / sin } else { f64::INFINITY };
        escape += (-axial.min(lateral)).exp();
    }
    1.0 - escape / QUANTILES as f64
}

/// Order i's albedo factor, i = 1, 2, … in turn, for the chance `inside` that each earlier
/// collision lies inside the tube, with albedo `a`: a·[(1 − p)·Σ_{j<i−1} (p a)^j + (p a)^{i−1}].
pub fn order_albedo(a: f64, inside: f64) -> impl Iterator<Item = f64> {
    // `chain`: (p a)^{i−1}, every earlier collision in the tube; `left`: (1 − p)·Σ_{j<i−1} (p a)^j,
    // the paths that reached the wall after j collisions in it.
    let (mut chain, mut left, mut first) = (1.0, 0.0, true);
    std::iter::from_fn(move || {
        if !first {
            left += (1.0 - inside) * chain;
            chain *= inside * a;
        }
        first = false;
        Some(a * (left + chain))
    })
}

/// [`previous_collision_inside`] tabulated for one phase function over the tube's optical radius
/// and the segment's optical depth (the last collision at [`eye_weighted_depth`]), bilinear in
/// their logarithms: the gather asks once per segment and K's agreement test, and 256 exponentials
/// each time cost 16 % of `full` at 64×48.
pub struct TubeTable {
    values: Vec<f64>,
}

/// The table's range: radius and depth from 10⁻³ to 10² (beyond it, its edge: p ≈ 0 for thin
/// tubes and segments, and it no longer moves beyond).
const LN_LO: f64 = -6.907_755_278_982_137; // ln 1e-3
const LN_HI: f64 = 4.605_170_185_988_092; // ln 1e2
const NODES: usize = 64;

impl TubeTable {
    /// Tabulate for the gather's (δ-M) phase function.
    pub fn new(phase: Hg) -> TubeTable {
        let mut values = Vec::with_capacity(NODES * NODES);
        for i in 0..NODES {
            let radius = Self::node(i);
            for j in 0..NODES {
                let depth = Self::node(j);
                values.push(previous_collision_inside(radius, depth, eye_weighted_depth(depth), phase));
            }
        }
        TubeTable { values }
    }

    fn node(i: usize) -> f64 {
        (LN_LO + (LN_HI - LN_LO) * i as f64 / (NODES - 1) as f64).exp()
    }

    /// p for a tube of optical radius `radius` around a segment of optical depth `depth`.
    pub fn inside(&self, radius: f64, depth: f64) -> f64 {
        if !(radius > 0.0 && depth > 0.0) {
            return 0.0;
        }
        let at = |x: f64| {
            let u = ((x.ln() - LN_LO) / (LN_HI - LN_LO) * (NODES - 1) as f64).clamp(0.0, (NODES - 1) as f64);
            let i = (u as usize).min(NODES - 2);
            (i, u - i as f64)
        };
        let ((i, fi), (j, fj)) = (at(radius), at(depth));
        let v = |i: usize, j: usize| self.values[i * NODES + j];
        let lo = v(i, j) * (1.0 - fj) + v(i, j + 1) * fj;
        let hi = v(i + 1, j) * (1.0 - fj) + v(i + 1, j + 1) * fj;
        lo * (1.0 - fi) + hi * fi
    }
}

/// HG's inverse cumulative distribution in μ = cos θ at `xi` ∈ (0, 1).
fn hg_quantile(g: f64, xi: f64) -> f64 {
    if g.abs() < 1e-4 {
        return 2.0 * xi - 1.0;
    }
    let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * xi);
    ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_albedo_spans_eq9_and_a_single_collision() {
        let a = 0.8;
        // Every earlier collision in the tube: eq. 9's a^i.
        for (i, w) in order_albedo(a, 1.0).take(6).enumerate() {
            assert!((w - a.powi(i as i32 + 1)).abs() < 1e-12, "order {}: {w}", i + 1);
        }
        // None: only the last collision is the segment's.
        assert!(order_albedo(a, 0.0).take(6).all(|w| (w - a).abs() < 1e-12));
        // Albedo 1: every order keeps its whole weight, whatever p.
        assert!(order_albedo(1.0, 0.4).take(6).all(|w| (w - 1.0).abs() < 1e-12));
        // In between, order 2: the previous collision is the tube's (a²) with chance p, else a.
        let p = 0.3;
        let w: Vec<f64> = order_albedo(a, p).take(2).collect();
        assert!((w[1] - (p * a * a + (1.0 - p) * a)).abs() < 1e-12);
    }

    #[test]
    fn the_table_follows_the_quadrature() {
        for g in [0.0, 0.714] {
            let phase = Hg::new(g);
            let table = TubeTable::new(phase);
            for radius in [0.004, 0.05, 0.21, 0.5, 1.7, 20.0] {
                for depth in [0.002, 0.1, 0.6, 2.5, 4.0, 13.0] {
                    let exact = previous_collision_inside(radius, depth, eye_weighted_depth(depth), phase);
                    let got = table.inside(radius, depth);
                    assert!((got - exact).abs() < 0.01, "g {g} r {radius} D {depth}: {got} vs {exact}");
                }
            }
        }
    }

    #[test]
    fn hg_quantiles_have_the_mean_cosine_g() {
        for g in [0.0, 0.3, 0.714, -0.5] {
            let n = 20_000;
            let mean: f64 = (0..n).map(|k| hg_quantile(g, (k as f64 + 0.5) / n as f64)).sum::<f64>() / n as f64;
            assert!((mean - g).abs() < 1e-3, "g = {g}: mean cosine {mean}");
        }
    }

    #[test]
    fn isotropic_chance_matches_the_closed_form() {
        // Isotropic, a long tube (no axial cap): p = 1 − ½∫_{−1}^{1} e^{−r/√(1−μ²)} dμ.
        let r = 0.5;
        let n = 200_000;
        let exact = 1.0
            - (0..n)
                .map(|k| {
                    let mu = -1.0 + 2.0 * (k as f64 + 0.5) / n as f64;
                    (-r / (1.0 - mu * mu).sqrt()).exp()
                })
                .sum::<f64>()
                / n as f64;
        let p = previous_collision_inside(r, 1e6, 5e5, Hg::new(0.0));
        assert!((p - exact).abs() < 2e-3, "{p} vs {exact}");
    }

    #[test]
    fn chance_grows_with_the_tube_and_the_forward_peak() {
        let iso = |r| previous_collision_inside(r, 4.0, 0.925, Hg::new(0.0));
        assert!(iso(0.1) < iso(0.3) && iso(0.3) < iso(1.0) && iso(1.0) < 1.0);
        assert_eq!(previous_collision_inside(0.0, 4.0, 0.925, Hg::new(0.5)), 0.0);
        // A forward peak sends the incoming light along the axis, where the tube is deep.
        let fwd = previous_collision_inside(0.2, 4.0, 0.925, Hg::new(0.7));
        assert!(fwd > iso(0.2), "{fwd} vs {}", iso(0.2));
        // No depth behind or in front: only the lateral chord is left, and it is capped by both.
        assert!(previous_collision_inside(0.2, 0.01, 0.005, Hg::new(0.7)) < 0.02);
    }
}
