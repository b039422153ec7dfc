//! Flux-limited diffusion (Levermore & Pomraning 1981): the solve's flux is Fick's law scaled by
//! κ = 3λ(R), so that I1 never exceeds free streaming, |I1| ≤ 3 I0 (|F| ≤ cE with F = 4π I1/3 and
//! E = 4π I0/c).
//!
//! With G = ∇I0 − 3Q1 (eq. 4's flux is I1 = −G/(ρσtr)), the limited flux is
//!
//! ```text
//!   I1 = −3λ(R) G/(ρσtr),   R = |G|/(ρσtr I0),   λ(R) = (coth R − 1/R)/R      (LP, eq. 28)
//! ```
//!
//! λ → 1/3 as R → 0 (thick, smooth fields keep eq. 4) and λ → 1/R as R → ∞ (|I1| → 3 I0). Both
//! the coupling D and the source flux F = Q1/(ρσtr) of every face (and the Marshak boundary's β and
//! f) are scaled by κ: the limiter is a factor on the whole flux of eq. 4's scheme. κ is lagged: it
//! is computed per full voxel from the previous solve's I0 ([`Limiter::of`]), a face takes the mean
//! of its two voxels' κ (the operator stays symmetric), and the solve is repeated from the current
//! I0 until I0 moves by less than [`OUTER_TOLERANCE`] ([`super::solve_bands`]).
//!
//! Bands with the same albedo share one κ (from their summed I0 and G: the same σtr, and one
//! hierarchy for all of them).

use super::flux::flux_of;
use super::BoundaryLight;
use crate::incident::IncidentLight;
use crate::medium::field16::Field16;
use crate::medium::sparse::VoxelField;
use crate::medium::Medium;

/// Relative change of I0 (L2 over every band, clamped at 0) at which the lagged iteration stops.
pub const OUTER_TOLERANCE: f64 = 1e-2;

/// Most re-solves with a new κ after the first solve.
pub const MAX_OUTER: usize = 6;

/// R where I0 ≤ 0 (the P1 solution's negative dipoles on sunlit faces) or R exceeds it: κ ≈ 0.03,
/// well above 0, so that the operator stays well conditioned.
const R_MAX: f64 = 100.0;

/// LP's λ(R) = (coth R − 1/R)/R; its series 1/3 − R²/45 + 2R⁴/945 below R = 10⁻², where the
/// difference of coth R and 1/R loses its digits.
pub fn lp_lambda(r: f64) -> f64 {
    if r < 1e-2 {
        let r2 = r * r;
        1.0 / 3.0 - r2 / 45.0 + 2.0 * r2 * r2 / 945.0
    } else {
        (1.0 / r.tanh() - 1.0 / r) / r
    }
}

/// κ = 3λ(R) per band of every full voxel (1 in empty ones).
#[derive(Clone, Debug)]
pub struct Limiter {
    kappa: VoxelField<[f32; 3]>,
}

impl Limiter {
    /// κ from `i0` (I0 per band) and its unlimited (Fick) flux, with the light `boundary` entering
    /// through the boundary faces and `tau_min` the solve's floor.
    pub fn of(m: &Medium, inc: &IncidentLight, i0: &[Field16; 3], boundary: &BoundaryLight, tau_min: f64) -> Limiter {
        let fick = flux_of(m, inc, i0, boundary, tau_min, None);
        let albedo = m.optics.albedo;
        let kappa = VoxelField::from_fn(m.density.full_index(), [1.0; 3], |g| {
            let i1 = fick(g);
            let s = m.density.full_index().slot(g);
            std::array::from_fn(|c| {
                let (mut flux, mut mean) = (crate::math::Vec3::ZERO, 0f64);
                for b in (0..3).filter(|b| albedo[*b] == albedo[c]) {
                    flux += i1[b];
                    mean += f64::from(i0[b].at_slot(s));
                }
                let r = if mean > 0.0 {
                    (f64::from(flux.length()) / mean).min(R_MAX)
                } else {
                    R_MAX
                };
                (3.0 * lp_lambda(r)) as f32
            })
        });
        Limiter { kappa }
    }

    /// κ of band `c` at slot `s` (1 at slot 0: empty).
    #[inline]
    pub fn at_slot(&self, s: usize, c: usize) -> f64 {
        f64::from(self.kappa.at_slot(s)[c])
    }

    /// κ of band `c` on the face between the full voxels in slots `sp` and `sn`.
    #[inline]
    pub fn face(&self, sp: usize, sn: usize, c: usize) -> f64 {
        0.5 * (self.at_slot(sp, c) + self.at_slot(sn, c))
    }
}

/// κ of band `c` at slot `s` under `limiter` (1 without).
#[inline]
pub fn kappa_at(limiter: Option<&Limiter>, s: usize, c: usize) -> f64 {
    limiter.map_or(1.0, |l| l.at_slot(s, c))
}

/// κ of band `c` on the face between slots `sp` and `sn` under `limiter` (1 without).
#[inline]
pub fn kappa_face(limiter: Option<&Limiter>, sp: usize, sn: usize, c: usize) -> f64 {
    limiter.map_or(1.0, |l| l.face(sp, sn, c))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lambda_is_a_third_for_smooth_fields_and_free_streaming_for_steep_ones() {
        assert!((lp_lambda(0.0) - 1.0 / 3.0).abs() < 1e-15);
        // The series and the closed form meet at R = 10⁻².
        let closed = |r: f64| (1.0 / r.tanh() - 1.0 / r) / r;
        assert!((lp_lambda(0.0099) - closed(0.0099)).abs() < 1e-9);
        assert!((lp_lambda(1e-3) - 1.0 / 3.0).abs() < 1e-7);
        // Monotone, and the flux λR stays below free streaming (1) and approaches it.
        let mut last = lp_lambda(0.0);
        for k in 1..400 {
            let r = 0.05 * k as f64;
            let l = lp_lambda(r);
            assert!(l < last && l * r < 1.0, "R = {r}: λ = {l}");
            last = l;
        }
        assert!(lp_lambda(1e3) * 1e3 > 0.998);
    }
}
