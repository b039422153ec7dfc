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

/// Whether a warm-started solve may stop, from its relative changes of I0 so far (EXPERIMENT).
pub(super) fn warm_converged(history: &[f64], tolerance: f64) -> bool {
    let env = |k: &str, d: f64| std::env::var(k).ok().and_then(|v| v.parse().ok()).unwrap_or(d);
    let (min, k) = (env("CLOUDGI_WARM_MIN", 3.0) as usize, env("CLOUDGI_WARM_K", 0.0));
    let n = history.len();
    if n < min.max(1) || history[n - 1] >= tolerance {
        return false;
    }
    if k <= 0.0 || n < 2 {
        return true;
    }
    let r = history[n - 1] / history[n - 2];
    let err = if r < 1.0 { history[n - 1] * (r / (1.0 - r)).max(1.0) } else { f64::INFINITY };
    err < k * tolerance
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
