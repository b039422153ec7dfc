//! Warm starts of the transport solve across a sequence's frames. The previous frame's converged
//! moments (per full voxel, band and spherical harmonic, in the solver's order) are carried to
//! the next frame's grid by world position: each new full voxel takes the moments of the old
//! voxel that contains its centre, when that voxel was full; a voxel new to the cloud starts from
//! the cold start's zero. The iteration then runs to the same tolerance as a cold solve, so only
//! the number of iterations changes (docs/sequences.md, "Warm starts").

use crate::math::Vec3;
use crate::medium::Medium;
use rayon::prelude::*;

/// Fewest source iterations of a warm-started solve, so that the dominant-mode extrapolation
/// (three iterations' changes) can remove the slow error a warm start leaves.
pub const WARM_MIN_ITERATIONS: usize = 3;

/// A converged transport solution, kept for the next frame's start.
#[derive(Clone, Debug)]
pub struct TransportState {
    order: usize,
    origin: Vec3,
    voxel_size: Vec3,
    dims: [usize; 3],
    /// Per voxel: index into `moments` (in units of `stride`), or `u32::MAX` where ρ = 0.
    full: Vec<u32>,
    /// Moments per full voxel, `stride` values each (W·m⁻²·sr⁻¹).
    moments: Vec<f32>,
    stride: usize,
}

impl TransportState {
    /// The state of a solve of `m` at SH `order`: its full-voxel index and moments.
    pub(crate) fn new(m: &Medium, order: usize, full: Vec<u32>, moments: Vec<f32>, stride: usize) -> TransportState {
        TransportState {
            order,
            origin: m.origin,
            voxel_size: m.voxel_size,
            dims: m.dims(),
            full,
            moments,
            stride,
        }
    }

    /// The start of a solve of `m` at `order` over the full voxels `voxels` (grid indices, in the
    /// solver's order), `stride` values each; None when the order differs (nothing to map).
    pub(crate) fn start(&self, m: &Medium, order: usize, voxels: &[usize], stride: usize) -> Option<Vec<f32>> {
        if order != self.order || stride != self.stride {
            return None;
        }
        let [nx, ny, _] = m.dims();
        let [ox, oy, oz] = self.dims;
        let mut out = vec![0f32; voxels.len() * stride];
        out.par_chunks_mut(stride).zip(voxels.par_iter()).for_each(|(o, &g)| {
            let c = m.voxel_center(g % nx, (g / nx) % ny, g / (nx * ny));
            let p = (c - self.origin) / self.voxel_size;
            if p.x < 0.0 || p.y < 0.0 || p.z < 0.0 {
                return;
            }
            let (i, j, k) = (p.x as usize, p.y as usize, p.z as usize);
            if i >= ox || j >= oy || k >= oz {
                return;
            }
            let old = self.full[i + ox * (j + oy * k)];
            if old != u32::MAX {
                let at = old as usize * stride;
                o.copy_from_slice(&self.moments[at..at + stride]);
            }
        });
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Rgb;
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
        let state = TransportState::new(&old, 1, vec![0, 1], vec![1.0, 1.0, 2.0, 2.0], 2);
        // New: 3×1×1 voxels from x = 10 m: the first is the old second voxel, the others are new.
        let new = medium([3, 1, 1], Vec3::new(10.0, 0.0, 0.0), |_, _, _| true);
        assert_eq!(state.start(&new, 1, &[0, 1, 2], 2).unwrap(), [2.0, 2.0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(state.start(&new, 2, &[0, 1, 2], 2), None, "another order starts cold");
    }
}
