//! The sun's δ-M beam T′ as the sweeps and the gather read it: sampled at the full voxels'
//! centres and interpolated linearly between them (the sweeps' steps take the source linear in
//! optical path, the gather's source is trilinear). Within a cloud the beam falls off
//! exponentially, and the chord of an exponential lies above it: over a segment of optical length
//! τ the linear interpolation's mean is (τ/2)·coth(τ/2) times the exact mean, +2 % at τ = 0.5 and
//! +8 % at τ = 1 (one 20-m voxel of density 1 at σt′ = 0.05 m⁻¹). Each centre's T′ is scaled by the
//! inverse, tanh(τ/2)/(τ/2), per axis (trilinear interpolation of a separable exponential is the
//! product of three linear ones), with τ the beam's optical length across the voxel along that
//! axis from the voxel's own density. Towards an empty neighbour the sweeps and the gather hold
//! the centre's source over the fade of the density instead (src/transport/sweep/step.rs,
//! src/render/transport.rs), where the beam grows towards the sun and falls away from it: on
//! that side the factor is the beam's density-weighted mean over the fade against the centre's
//! value ([`side_factor`]). Each axis takes the mean of its two sides'. The first scattering of
//! the sun's light then holds its amount inside a uniform cloud and at its faces.

/// The factor tanh(τ/2)/(τ/2) ∈ (0, 1] that makes linear interpolation between samples of
/// e^{−x} spaced τ apart integrate it exactly (its Taylor series below τ = 10⁻³).
pub fn trapezoid_factor(tau: f64) -> f64 {
    let half = 0.5 * tau.max(0.0);
    if half < 5e-4 {
        1.0 - half * half / 3.0
    } else {
        half.tanh() / half
    }
}

/// What lies beside a voxel along an axis, on one side.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// A full voxel: the source is interpolated linearly towards its centre.
    Full,
    /// An empty voxel (or the grid's face) towards the sun: the density fades to 0 there, and
    /// the source, held at the centre's, stands for a beam that grows towards the sun.
    EmptySunward,
    /// An empty voxel away from the sun: the held source stands for a beam that falls off.
    EmptyAway,
}

/// The factor on one side of a centre over which the beam's optical depth across a voxel is
/// `tau`: on a segment to a full neighbour [`trapezoid_factor`]; on a fade to an empty one, the
/// density-weighted mean of the beam over the fade (ρ falls linearly to 0 across the voxel, so the
/// beam's optical depth from the centre is τ(u − u²/2) at u voxels out) against the held value,
/// 2(e^{τ/2} − 1)/τ towards the sun and 2(1 − e^{−τ/2})/τ away from it.
pub fn side_factor(tau: f64, side: Side) -> f64 {
    let half = 0.5 * tau.max(0.0);
    if half < 5e-4 {
        // Series to τ²: the exact factors' error is below 1e-10 here.
        return match side {
            Side::Full => 1.0 - half * half / 3.0,
            Side::EmptySunward => 1.0 + half / 2.0 + half * half / 6.0,
            Side::EmptyAway => 1.0 - half / 2.0 + half * half / 6.0,
        };
    }
    match side {
        Side::Full => trapezoid_factor(tau),
        Side::EmptySunward => half.exp_m1() / half,
        Side::EmptyAway => -(-half).exp_m1() / half,
    }
}

/// The factor on the δ-M sun transmittance at a voxel's centre: per axis, the mean of its two
/// sides' [`side_factor`]s (`sides[a]`: towards −a and +a), with extinction `sigma_t` (1/m per
/// unit density, δ-M scaled) at density `rho`, voxel edges `h` (m) and the direction towards the
/// sun `dir` (unit); the product over the axes.
pub fn beam_factor(sigma_t: f64, rho: f64, h: [f64; 3], dir: [f64; 3], sides: [[Side; 2]; 3]) -> f64 {
    (0..3)
        .map(|a| {
            let tau = sigma_t * rho * h[a] * dir[a].abs();
            0.5 * (side_factor(tau, sides[a][0]) + side_factor(tau, sides[a][1]))
        })
        .product()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scaled_samples_of_an_exponential_integrate_it_exactly_when_interpolated_linearly() {
        for tau in [1e-5, 1e-3, 0.1, 0.5, 1.0, 3.0] {
            // Samples e^{−kτ}, k = 0..n, the chords' integral over the n segments against ∫ e^{−x}.
            let n = 6;
            let k = trapezoid_factor(tau);
            let chords: f64 = (0..n).map(|i| 0.5 * tau * k * ((-(i as f64) * tau).exp() + (-((i + 1) as f64) * tau).exp())).sum();
            let exact = 1.0 - (-(n as f64) * tau).exp();
            assert!((chords - exact).abs() < 1e-9 * exact.max(1e-12) + 1e-15, "τ {tau}: {chords} vs {exact}");
            // Unscaled, the chords overestimate (by τ²/12 to leading order).
            assert!(k < 1.0 && chords / k > exact, "τ {tau}");
        }
        assert_eq!(trapezoid_factor(0.0), 1.0);
        assert!((trapezoid_factor(1.0) - 0.924_234).abs() < 1e-6);
    }

    #[test]
    fn the_beam_factor_is_the_product_over_the_axes_of_its_sides_means() {
        let h = [10.0, 20.0, 10.0];
        let full = [[Side::Full; 2]; 3];
        // Straight down: only the y axis; no density, no beam fall-off: 1.
        assert_eq!(beam_factor(0.05, 1.0, h, [0.0, 1.0, 0.0], full), trapezoid_factor(1.0));
        assert_eq!(beam_factor(0.05, 0.0, h, [0.6, 0.8, 0.0], full), 1.0);
        let d = [0.6, 0.8, 0.0];
        let want = trapezoid_factor(0.05 * 10.0 * 0.6) * trapezoid_factor(0.05 * 20.0 * 0.8);
        assert!((beam_factor(0.05, 1.0, h, d, full) - want).abs() < 1e-15);
        // A lone voxel's held source stands for the beam's mean over it: sinh(τ/2)/(τ/2) > 1.
        let lone = [[Side::EmptyAway, Side::EmptySunward]; 3];
        let f = beam_factor(0.05, 1.0, h, [0.0, 1.0, 0.0], lone);
        assert!((f - 0.5f64.sinh() / 0.5).abs() < 1e-12, "{f}");
    }

    #[test]
    fn a_fades_factor_is_the_density_weighted_mean_of_the_beam_over_it() {
        for tau in [1e-5, 0.3, 1.0, 2.0] {
            // ∫₀¹ (1 − u) e^{±τ(u − u²/2)} du / ∫₀¹ (1 − u) du by the midpoint rule.
            let n = 20000;
            let mean = |sign: f64| {
                (0..n)
                    .map(|i| {
                        let u = (i as f64 + 0.5) / n as f64;
                        2.0 * (1.0 - u) * (sign * tau * (u - u * u / 2.0)).exp() / n as f64
                    })
                    .sum::<f64>()
            };
            for (side, sign) in [(Side::EmptySunward, 1.0), (Side::EmptyAway, -1.0)] {
                let (f, m) = (side_factor(tau, side), mean(sign));
                assert!((f - m).abs() < 1e-6, "τ {tau}, {side:?}: {f} vs {m}");
            }
            assert!(side_factor(tau, Side::EmptySunward) > 1.0 && side_factor(tau, Side::EmptyAway) < 1.0);
        }
    }
}
