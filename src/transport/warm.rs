//! Warm starts of the transport solve across a sequence's frames. The previous frame's converged
//! moments (per full voxel, band and spherical harmonic, in the solver's order) are carried to
//! the next frame's grid by world position ([`FullVoxelPlacement::values_at`]: trilinear over the
//! old full voxels, so grids may grow, move or change size); a voxel with no old full voxel
//! around its centre starts from the cold start's zero. The iteration then runs to the same
//! tolerance as a cold solve, so only the number of iterations changes (docs/sequences.md, "Warm
//! starts").

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
}

impl TransportState {
    /// The state of a solve of `m` at SH `order`: its moments, `stride` per full voxel.
    pub(crate) fn new(m: &Medium, order: usize, moments: Vec<f32>, stride: usize) -> TransportState {
        TransportState {
            order,
            placement: FullVoxelPlacement::of(m),
            moments,
            stride,
        }
    }

    /// The start of a solve of `m` at `order` over the full voxels `voxels` (grid indices, in the
    /// solver's order), `stride` values each; None when the order differs (nothing to map).
    pub(crate) fn start(&self, m: &Medium, order: usize, voxels: &[usize], stride: usize) -> Option<Vec<f32>> {
        (order == self.order && stride == self.stride).then(|| self.placement.values_at(&self.moments, stride, m, voxels))
    }

    /// Bytes held: the moments and the old grid's occupancy.
    pub fn bytes(&self) -> usize {
        4 * self.moments.len() + self.placement.bytes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Rgb, Vec3};
    use crate::medium::Grid3;

    fn medium(dims: [usize; 3], origin: Vec3, full: impl Fn(usize, usize, usize) -> bool) -> Medium {
        let mut g = Grid3::filled(dims, 0.0);
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    g.set(i, j, k, if full(i, j, k) { 1.0 } else { 0.0 });
                }
            }
        }
        Medium::new(g, origin, Vec3::splat(10.0), 0.1, Rgb::splat(0.9), 0.5)
    }

    #[test]
    fn moments_follow_world_position_and_new_voxels_start_cold() {
        // Old: 2×1×1 voxels at x = 0..20 m, both full, moments 1 and 2.
        let old = medium([2, 1, 1], Vec3::ZERO, |_, _, _| true);
        let state = TransportState::new(&old, 1, vec![1.0, 1.0, 2.0, 2.0], 2);
        // New: 3×1×1 voxels from x = 10 m: the first is the old second voxel, the others are new.
        let new = medium([3, 1, 1], Vec3::new(10.0, 0.0, 0.0), |_, _, _| true);
        assert_eq!(state.start(&new, 1, &[0, 1, 2], 2).unwrap(), [2.0, 2.0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(state.start(&new, 2, &[0, 1, 2], 2), None, "another order starts cold");
    }
}
