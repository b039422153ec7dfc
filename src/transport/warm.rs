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

/// Fewest source iterations of a warm-started solve: its first two changes still carry the
/// start's faster modes (on the sun-only sequence, stopped at the third iteration the warm image
/// is 1.5–2.5 times further from the converged one than the cold image; docs/sequences.md).
pub const WARM_MIN_ITERATIONS: usize = 3;

/// A warm-started solve stops once the error it is estimated to leave is below this fraction of
/// `render.transport_tolerance` ([`warm_converged`]).
pub const WARM_ERROR_FRACTION: f64 = 0.4;

/// Whether a warm-started solve may stop, from its last relative change of I0 `last`, after
/// `iterations`, and the slowest mode's ratio `slow_ratio` (the larger of this solve's and the
/// previous frame's, [`SlowRatio`]). A warm start's error lies in the slow modes (the anisotropic
/// orders DSA does not reach, which fall by r ≈ 0.6–0.8 per iteration), spread over the whole
/// cloud, where a cold solve's last error lies in a few voxels: stopped at the cold test (last
/// change below the tolerance) the warm image is 2–5 times further from the converged one than
/// the cold image. So the error left, estimated as Δ·max(1, r/(1 − r)) (the geometric tail), must
/// be below [`WARM_ERROR_FRACTION`] of the tolerance. The ratio is the medium's, not the last
/// two changes': right after an extrapolation, or in the first iterations, their ratio is the
/// faster modes' and the estimate would stop a solve 1.5–2.5 times too early (docs/sequences.md).
pub(super) fn warm_converged(last: f64, iterations: usize, slow_ratio: f64, tolerance: f64) -> bool {
    let left = if slow_ratio < 1.0 {
        last * (slow_ratio / (1.0 - slow_ratio)).max(1.0)
    } else {
        f64::INFINITY
    };
    iterations >= WARM_MIN_ITERATIONS && left < WARM_ERROR_FRACTION * tolerance
}

/// The slowest error mode's ratio seen in a solve: the largest ratio of two consecutive changes
/// of I0 with no extrapolation between them (an extrapolation removes most of the mode, so the
/// ratio across it is not the medium's).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct SlowRatio(pub(super) f64);

impl SlowRatio {
    /// Takes the ratio of the last two changes of `history` when no extrapolation was applied
    /// after the first of them (`extrapolated`: the iteration of the last one, 0 for none).
    pub(super) fn observe(&mut self, history: &[f64], extrapolated: usize) {
        if let [.., before, last] = history {
            if extrapolated + 1 < history.len() && *before > 0.0 {
                self.0 = self.0.max(last / before);
            }
        }
    }
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
    /// The slowest mode's ratio ([`SlowRatio`]), the largest seen by this frame's solve and those
    /// before it since the last cold frame: the next frame's solve stops by it.
    slow_ratio: f64,
}

/// A solve's start from a previous frame: the moments on its full voxels and the cloud's change
/// to the ground's downward irradiance per column of its ground map (none without a ground).
pub(super) struct WarmStart {
    pub(super) moments: Vec<f32>,
    /// The previous solve's slowest-mode ratio.
    pub(super) slow_ratio: SlowRatio,
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
            slow_ratio: 0.0,
        }
    }

    /// The state with the slowest-mode ratio its solve saw.
    pub(super) fn with_slow_ratio(self, r: SlowRatio) -> TransportState {
        TransportState { slow_ratio: r.0, ..self }
    }

    /// The start of a solve of `m` at `order` with `stride` values per full voxel (in grid
    /// order) and the ground light `ground`; None when the order differs (nothing to map).
    pub(super) fn start(&self, m: &Medium, order: usize, stride: usize, ground: &GroundLight) -> Option<WarmStart> {
        (order == self.order && stride == self.stride).then(|| WarmStart {
            moments: self.placement.values_at(&self.moments, stride, m),
            slow_ratio: SlowRatio(self.slow_ratio),
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
    fn a_warm_solve_stops_when_its_estimated_error_is_below_the_fraction_of_the_tolerance() {
        let tol = 5e-3;
        // The sun-only sequence at r = 0.71: 9.7e-4 leaves 2.4e-3, 6.9e-4 leaves 1.7e-3 < 2e-3.
        assert!(!warm_converged(9.7e-4, 3, 0.71, tol));
        assert!(warm_converged(6.9e-4, 4, 0.71, tol));
        // A fast fall stops once the last change is small enough, but not before the third
        // iteration, nor at a ratio of 1 or more.
        assert!(!warm_converged(1e-5, 2, 0.1, tol));
        assert!(warm_converged(1e-5, 3, 0.1, tol));
        assert!(!warm_converged(1e-5, 5, 1.0, tol));
    }

    #[test]
    fn the_slow_ratio_skips_the_ratio_across_an_extrapolation() {
        let mut r = SlowRatio::default();
        let history = [1.0, 0.27, 0.137, 0.083, 0.022, 0.0135, 0.0101];
        for n in 1..=4 {
            r.observe(&history[..n], 0);
        }
        assert!((r.0 - 0.6).abs() < 0.01, "{r:?}");
        // Extrapolated after the fourth change: 0.022 / 0.083 is not the medium's ratio.
        r.observe(&history[..5], 4);
        assert!((r.0 - 0.6).abs() < 0.01, "{r:?}");
        r.observe(&history[..6], 4);
        r.observe(&history[..7], 4);
        assert!((r.0 - 0.75).abs() < 0.01, "{r:?}");
    }
}
