//! Warm starts of the transport solve across a sequence's frames. The previous frame's converged
//! moments (per full voxel, band and spherical harmonic, in the solver's order) are carried to
//! the next frame's grid by world position ([`FullVoxelPlacement::values_at`]: trilinear over the
//! old full voxels, so grids may grow, move or change size; a voxel new to the cloud from its
//! neighbours), and so is the cloud's diffuse light on the ground ([`GroundLight::e_down_from`]).
//! The iteration then runs to the same tolerance as a cold solve, with the stopping test of
//! [`warm_converged`] (docs/sequences.md, "Warm starts").

use super::ground::{GroundLight, GroundMap};
use crate::medium::remap::FullVoxelPlacement;
use crate::medium::Medium;

/// Fewest source iterations of a warm-started solve: two changes to read the slowest mode's
/// ratio from, and one more to confirm it.
pub const WARM_MIN_ITERATIONS: usize = 3;

/// A warm-started solve stops once the error it is estimated to leave is below this fraction of
/// `render.transport_tolerance` ([`warm_converged`]).
pub const WARM_ERROR_FRACTION: f64 = 0.1;

/// Whether a warm-started solve may stop, from its relative changes of I0 so far (`history`).
/// A warm start's error lies in the slow modes (the anisotropic orders DSA does not reach, which
/// fall by r ≈ 0.6–0.7 per iteration), spread over the whole cloud, where a cold solve's last
/// error lies in a few voxels: stopped at the cold test (last change below the tolerance) the warm
/// image is 2–5 times further from the converged one than the cold image. So the error left,
/// estimated as the last change Δ times max(1, r/(1 − r)) with r the last ratio of changes (the
/// geometric tail), must be below [`WARM_ERROR_FRACTION`] of the tolerance, after at least
/// [`WARM_MIN_ITERATIONS`] (docs/sequences.md: then the warm image is closer to the converged
/// one than the cold image).
pub(super) fn warm_converged(history: &[f64], tolerance: f64) -> bool {
    let [.., before, last] = history else {
        return false;
    };
    if history.len() < WARM_MIN_ITERATIONS {
        return false;
    }
    let r = last / before;
    let left = if r < 1.0 { last * (r / (1.0 - r)).max(1.0) } else { f64::INFINITY };
    left < WARM_ERROR_FRACTION * tolerance
}

/// A converged transport solution, kept for the next frame's start.
#[derive(Clone, Debug)]
pub struct TransportState {
    order: usize,
    placement: FullVoxelPlacement,
    /// Moments per full voxel in grid order, `stride` values each (W·m⁻²·sr⁻¹).
    moments: Vec<f32>,
    stride: usize,
    /// The ground's radiance the solve ended with.
    ground: GroundMap,
}

/// A solve's start from a previous frame: the moments on its full voxels and the cloud's change
/// to the ground's downward irradiance per column of its ground map (none without a ground).
pub(super) struct WarmStart {
    pub(super) moments: Vec<f32>,
    pub(super) e_down: Option<Vec<[f64; 3]>>,
}

impl TransportState {
    /// The state of a solve of `m` at SH `order`: its moments, `stride` per full voxel, and its
    /// last ground map.
    pub(crate) fn new(m: &Medium, order: usize, moments: Vec<f32>, stride: usize, ground: GroundMap) -> TransportState {
        TransportState {
            order,
            placement: FullVoxelPlacement::of(m),
            moments,
            stride,
            ground,
        }
    }

    /// The start of a solve of `m` at `order` with `stride` values per full voxel (in grid
    /// order) and the ground light `ground`; None when the order differs (nothing to map).
    pub(super) fn start(&self, m: &Medium, order: usize, stride: usize, ground: &GroundLight) -> Option<WarmStart> {
        (order == self.order && stride == self.stride).then(|| WarmStart {
            moments: self.placement.values_at(&self.moments, stride, m),
            e_down: ground.e_down_from(&self.ground),
        })
    }

    /// Bytes held: the moments, the old grid's occupancy and the ground map.
    pub fn bytes(&self) -> usize {
        4 * self.moments.len() + self.placement.bytes() + 24 * self.ground.radiance.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_warm_solve_stops_when_its_estimated_error_is_a_tenth_of_the_tolerance() {
        let tol = 5e-3;
        // The cold test would stop at 1.0e-3; the slow mode (r = 0.67) leaves about 2e-3.
        assert!(!warm_converged(&[6.9e-3, 1.5e-3, 1.0e-3], tol));
        assert!(!warm_converged(&[6.9e-3, 1.5e-3, 1.0e-3, 7.0e-4], tol));
        // After the extrapolation: 2.9e-4 at r = 0.41 leaves 2.9e-4 < 5e-4.
        assert!(warm_converged(&[6.9e-3, 1.5e-3, 1.0e-3, 7.0e-4, 2.9e-4], tol));
        // A fast fall stops as soon as the last change is small enough, but not before the
        // third iteration, nor on a rising change.
        assert!(!warm_converged(&[1e-3, 1e-4], tol));
        assert!(warm_converged(&[1e-3, 1e-4, 1e-5], tol));
        assert!(!warm_converged(&[1e-5, 1e-5, 2e-4], tol));
        assert!(!warm_converged(&[], tol));
    }
}
