//! Warm starts of the transport solve across a sequence's frames. The previous frame's converged
//! moments (per full voxel, band and spherical harmonic, in the solver's order) are carried to
//! the next frame's grid by world position ([`FullVoxelPlacement::values_at`]: trilinear over the
//! old full voxels, so grids may grow, move or change size; a voxel new to the cloud from its
//! neighbours), and so is the cloud's diffuse light on the ground ([`GroundLight::e_down_from`]).
//! The iteration then runs to the same tolerance in image terms as a cold solve
//! ([`IMAGE_ERROR_FRACTION`]), stopped by [`WarmStop`] (docs/sequences.md, "Warm starts").

use super::convergence::SlowMode;
use super::ground::{GroundLight, GroundMap};
use crate::medium::remap::FullVoxelPlacement;
use crate::medium::Medium;

/// The tolerance in image terms: every frame, warm or cold, lies within this fraction of
/// `render.transport_tolerance` of the converged image (4×4 block mean relative error against a
/// solve to 1e-5), so a warm frame and a cold one within twice it of each other. Cold frames
/// measured 0.04–0.35 of the tolerance on the glare sweep's 12 scenes and 0.03–0.12 on the
/// sequences of examples/warm_start.rs and the tests (docs/sequences.md, "Warm starts").
pub const IMAGE_ERROR_FRACTION: f64 = 0.4;

/// Fewest source iterations of a warm-started solve: two changes to read the slowest mode's
/// ratio from, and one more to confirm it.
pub const WARM_MIN_ITERATIONS: usize = 3;

/// A warm-started solve stops once the relative error of I0 it is estimated to leave
/// ([`warm_error_left`]) is below this fraction of `render.transport_tolerance`. On the cumulus
/// sequences the image's error was at most 0.55 times the estimate wherever it was above 1e-5
/// (warm frames within 0.02 of the tolerance, closer than their cold frames); on the small cloud
/// of tests/it/sequences.rs, the sun 4° a frame, up to 0.17 (docs/sequences.md): inside
/// [`IMAGE_ERROR_FRACTION`] with room for a scene that is worse.
pub const WARM_ERROR_FRACTION: f64 = 0.15;

/// A warm start whose first iteration changes I0 by at least this many times
/// `render.transport_tolerance` is far from the frame's light: the solve mixes on from its
/// iterate as a cold one. Measured (docs/sequences.md, "A far warm start"): a cloud whose every
/// voxel changes 2 % a frame starts 20 tolerances away and takes 4–5 iterations instead of 7; at
/// 3 tolerances the cold test stopped after 2 iterations at 0.17 tolerances from converged.
pub const FAR_START_TOLERANCES: f64 = 10.0;

/// Least uncertainty of an extrapolated mode's ratio: two ratios that agree do not make it exact.
const MIN_RATIO_SPREAD: f64 = 0.05;

/// The stopping test of a warm-started solve and what it has seen.
#[derive(Clone, Debug, Default)]
pub(super) struct WarmStop {
    /// Σ|ΔI0| / Σ|I0| after each iteration.
    mean_changes: Vec<f64>,
    /// The slowest mode's ratio: the previous frame's, or larger, this frame's.
    slow_ratio: f64,
}

impl WarmStop {
    /// A warm solve's test, starting from the previous frame's slowest ratio.
    pub(super) fn new(slow_ratio: f64) -> WarmStop {
        WarmStop {
            mean_changes: Vec::new(),
            slow_ratio,
        }
    }

    /// Whether the solve may stop after an iteration whose mean relative change of I0 was
    /// `mean_change`, the iterate extrapolated along `extrapolated` if at all.
    pub(super) fn converged(&mut self, mean_change: f64, extrapolated: Option<SlowMode>, tolerance: f64) -> bool {
        self.mean_changes.push(mean_change);
        let left = warm_error_left(&self.mean_changes, extrapolated, self.slow_ratio);
        if let Some(mode) = extrapolated {
            self.slow_ratio = self.slow_ratio.max(mode.ratio);
        }
        self.mean_changes.len() >= WARM_MIN_ITERATIONS && left < WARM_ERROR_FRACTION * tolerance
    }
}

/// The relative error of I0 (a mean over the cloud, as the image sees it) that a warm-started
/// solve is estimated to leave after its last iteration. A warm start's error lies in the slow
/// modes (the anisotropic orders DSA does not reach, r ≈ 0.6–0.8 per iteration) and is spread over
/// the whole cloud, so the largest voxel's change does not measure it and the last ratio of
/// changes may still be a faster mode's. From the mean changes Δ:
/// - after an extrapolation along a mode of ratio r, known to ±δr (its `spread`): it added
///   r/(1 − r) times the step, and δr leaves δr/(1 − r)² times Δ;
/// - otherwise the geometric tail Δ·max(1, r/(1 − r)), r the larger of the last ratio of changes
///   and `slow_ratio` (the slowest ratio seen before, this frame's or the previous frame's).
pub(super) fn warm_error_left(mean_changes: &[f64], extrapolated: Option<SlowMode>, slow_ratio: f64) -> f64 {
    let Some(&last) = mean_changes.last() else {
        return f64::INFINITY;
    };
    if let Some(mode) = extrapolated {
        return last * mode.spread.max(MIN_RATIO_SPREAD) / (1.0 - mode.ratio).powi(2);
    }
    let r = match mean_changes {
        [.., before, _] => (last / before).max(slow_ratio),
        _ => slow_ratio,
    };
    if r < 1.0 {
        last * (r / (1.0 - r)).max(1.0)
    } else {
        f64::INFINITY
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
    /// The slowest mode's ratio the solve saw (0: none), for the next frame's [`WarmStop`].
    slow_ratio: f64,
}

/// A solve's start from a previous frame: the moments on its full voxels and the cloud's change
/// to the ground's downward irradiance per column of its ground map (none without a ground).
pub(super) struct WarmStart {
    pub(super) moments: Vec<f32>,
    pub(super) e_down: Option<Vec<[f64; 3]>>,
    /// The previous solve's slowest ratio.
    pub(super) slow_ratio: f64,
}

impl TransportState {
    /// The state of a solve of `m` at SH `order`: its moments, `stride` per full voxel, its last
    /// ground map and the slowest mode's ratio it saw.
    pub(crate) fn new(m: &Medium, order: usize, moments: Vec<f32>, stride: usize, ground: GroundMap, slow_ratio: f64) -> TransportState {
        TransportState {
            order,
            placement: FullVoxelPlacement::of(m),
            moments,
            stride,
            ground,
            slow_ratio,
        }
    }

    /// The start of a solve of `m` at `order` with `stride` values per full voxel (in grid
    /// order) and the ground light `ground`; None when the order differs (nothing to map).
    pub(super) fn start(&self, m: &Medium, order: usize, stride: usize, ground: &GroundLight) -> Option<WarmStart> {
        (order == self.order && stride == self.stride).then(|| WarmStart {
            moments: self.placement.values_at(&self.moments, stride, m),
            e_down: ground.e_down_from(&self.ground),
            slow_ratio: self.slow_ratio,
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
    fn the_error_left_is_the_slowest_modes_geometric_tail() {
        // The sun sequence's second frame: mean changes 2.5e-3, 7.1e-4, 5.1e-4 (ratio 0.72).
        let changes = [2.5e-3, 7.1e-4, 5.1e-4];
        let tail = 5.1e-4 * 0.72 / 0.28;
        assert!((warm_error_left(&changes, None, 0.0) / tail - 1.0).abs() < 0.02);
        // A faster last ratio is not trusted below the slowest seen before.
        let fast = [2.5e-3, 7.1e-4, 2.0e-4];
        assert!((warm_error_left(&fast, None, 0.75) / (2.0e-4 * 3.0) - 1.0).abs() < 1e-9);
        assert!((warm_error_left(&fast, None, 0.0) / 2.0e-4 - 1.0).abs() < 1e-9, "at least the change");
        // After an extrapolation along r = 0.7 ± 0.05: 0.05/0.09 of the step.
        let mode = SlowMode { ratio: 0.7, spread: 0.02 };
        assert!((warm_error_left(&changes, Some(mode), 0.0) / (5.1e-4 * 0.05 / 0.09) - 1.0).abs() < 1e-9);
        assert_eq!(warm_error_left(&[1e-3, 2e-3], None, 0.0), f64::INFINITY, "a rising change");
        assert_eq!(warm_error_left(&[], None, 0.7), f64::INFINITY);
    }

    #[test]
    fn a_warm_solve_stops_when_its_estimated_error_is_below_the_fraction_and_not_before_three_iterations() {
        let tol = 5e-3;
        let mut stop = WarmStop::new(0.75);
        // 1e-4 at r = 0.75 leaves 3e-4 < 7.5e-4, but only the third iteration may stop.
        assert!(!stop.converged(1e-3, None, tol));
        assert!(!stop.converged(1e-4, None, tol));
        assert!(stop.converged(1e-4 * 0.75, None, tol));
        // 2e-4 at the slow ratio 0.8 leaves 8e-4: not yet.
        let mut slow = WarmStop::new(0.8);
        for d in [1e-3, 5e-4] {
            assert!(!slow.converged(d, None, tol));
        }
        assert!(!slow.converged(2e-4, None, tol));
        // An extrapolation's ratio is remembered: 0.85 from then on.
        let mut seen = WarmStop::new(0.0);
        assert!(!seen.converged(1e-3, Some(SlowMode { ratio: 0.85, spread: 0.01 }), tol));
        assert!((seen.slow_ratio - 0.85).abs() < 1e-12);
    }
}
