//! Values held per full voxel, carried from one grid to another by world position: how a
//! sequence's frame starts its solves from the previous frame's solution when the grid moves,
//! grows or changes its voxels (docs/sequences.md, "Warm starts").

use super::sparse::FullIndex;
use super::Medium;
use crate::math::Vec3;
use crate::par;
use std::sync::Arc;

/// Where a grid's full voxels lie in the world: what [`Self::values_at`] needs of an old frame.
#[derive(Clone, Debug)]
pub struct FullVoxelPlacement {
    origin: Vec3,
    voxel_size: Vec3,
    index: Arc<FullIndex>,
}

impl FullVoxelPlacement {
    /// The placement of `m`'s full voxels.
    pub fn of(m: &Medium) -> FullVoxelPlacement {
        FullVoxelPlacement {
            origin: m.origin,
            voxel_size: m.voxel_size,
            index: m.density.full_index(),
        }
    }

    /// Full voxels.
    pub fn count(&self) -> usize {
        self.index.count()
    }

    /// Bytes held (the index's occupancy words).
    pub fn bytes(&self) -> usize {
        self.index.bytes()
    }

    /// `values` (`stride` per full voxel of this placement, in grid order) at the centres of
    /// `m`'s full voxels (in grid order), `stride` each: trilinear between this grid's voxel
    /// centres, over its full voxels only (their weights renormalised, so an empty neighbour does
    /// not pull the value to zero). A voxel with no full voxel among its eight neighbours here (new
    /// to the cloud, at its growing edge) takes the mean of its face neighbours' values, growing
    /// inwards from the mapped ones for up to [`FILL_STEPS`] voxels; beyond, zero.
    pub fn values_at(&self, values: &[f32], stride: usize, m: &Medium) -> Vec<f32> {
        debug_assert_eq!(values.len(), self.index.count() * stride);
        let new = m.density.full_index();
        let voxels: Vec<usize> = new.full_voxels().collect();
        let [nx, ny, _] = m.dims();
        let d = self.index.dims();
        let mut out = vec![0f32; voxels.len() * stride];
        let stride = stride.max(1);
        let mut known = vec![false; voxels.len()];
        // Each task a chunk of voxels: their values and whether they were mapped.
        let mut parts: Vec<(&mut [f32], &mut [bool])> = out.chunks_mut(par::CHUNK * stride).zip(known.chunks_mut(par::CHUNK)).collect();
        par::for_chunks(&mut parts, 1, &|ci, part| {
            let (out, known) = &mut part[0];
            for ((o, k), &g) in out.chunks_mut(stride).zip(known.iter_mut()).zip(&voxels[ci * par::CHUNK..]) {
                let centre = m.voxel_center(g % nx, (g / nx) % ny, g / (nx * ny));
                // Continuous coordinates in units of old voxels, from the first old centre.
                let u = (centre - self.origin) / self.voxel_size - Vec3::splat(0.5);
                let b = u.floor();
                let t = u - b;
                let mut weight = 0f32;
                for corner in 0..8 {
                    let at = [corner & 1, (corner >> 1) & 1, corner >> 2];
                    let c = [b.x as i64 + at[0], b.y as i64 + at[1], b.z as i64 + at[2]];
                    if (0..3).any(|a| c[a] < 0 || c[a] >= d[a] as i64) {
                        continue;
                    }
                    let slot = self.index.slot(c[0] as usize + d[0] * (c[1] as usize + d[1] * c[2] as usize));
                    let w = [t.x, t.y, t.z]
                        .iter()
                        .zip(at)
                        .map(|(t, a)| if a == 1 { *t } else { 1.0 - t })
                        .product::<f32>();
                    if slot == 0 || w <= 0.0 {
                        continue;
                    }
                    let from = (slot - 1) * stride;
                    o.iter_mut().zip(&values[from..from + stride]).for_each(|(s, v)| *s += w * v);
                    weight += w;
                }
                if weight > 0.0 {
                    o.iter_mut().for_each(|s| *s /= weight);
                }
                *k = weight > 0.0;
            }
        });
        // Each step reads only the values known before it: the same whatever the thread count.
        let dims = m.dims();
        for _ in 0..FILL_STEPS {
            let missing: Vec<usize> = (0..voxels.len()).filter(|&r| !known[r]).collect();
            if missing.is_empty() {
                break;
            }
            let filled: Vec<Option<Vec<f32>>> = par::map_range(missing.len(), &|m| {
                let r = missing[m];
                let g = voxels[r];
                let cell = [g % nx, (g / nx) % ny, g / (nx * ny)];
                let mut sum = vec![0f32; stride];
                let mut n = 0;
                for a in 0..3 {
                    let step = [1, nx, nx * ny][a];
                    for side in [-1i64, 1] {
                        let c = cell[a] as i64 + side;
                        if c < 0 || c >= dims[a] as i64 {
                            continue;
                        }
                        let slot = new.slot((g as i64 + side * step as i64) as usize);
                        if slot == 0 || !known[slot - 1] {
                            continue;
                        }
                        let from = (slot - 1) * stride;
                        sum.iter_mut().zip(&out[from..from + stride]).for_each(|(s, v)| *s += v);
                        n += 1;
                    }
                }
                (n > 0).then(|| sum.into_iter().map(|s| s / n as f32).collect())
                });
            for (&r, f) in missing.iter().zip(filled) {
                if let Some(f) = f {
                out[r * stride..(r + 1) * stride].copy_from_slice(&f);
                known[r] = true;
                }
            }
        }
        out
    }
}

/// Voxels inwards from the mapped ones that a voxel new to the cloud is filled across.
pub const FILL_STEPS: usize = 3;

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
    fn values_are_trilinear_in_world_position_over_full_voxels_only() {
        // Old: 3×1×1 voxels at x = 0..30 m; the first two full with values (1, 10) and (3, 30).
        let old = medium([3, 1, 1], Vec3::ZERO, |i, _, _| i < 2);
        let place = FullVoxelPlacement::of(&old);
        assert_eq!(place.count(), 2);
        let values = [1.0, 10.0, 3.0, 30.0];
        // New: 4×1×1 voxels from x = 7.5 m; centres at 12.5, 22.5, 32.5 and 42.5 m.
        let new = medium([4, 1, 1], Vec3::new(7.5, 0.0, 0.0), |_, _, _| true);
        let at = place.values_at(&values, 2, &new);
        // 12.5 m: three quarters of the way from the first centre (5 m) to the second (15 m).
        assert_eq!(at[..2], [2.5, 25.0]);
        // 22.5 m: between the second (full) and the third (empty) centre: the full one's value.
        assert_eq!(at[2..4], [3.0, 30.0]);
        // 32.5 and 42.5 m: only empty or outside voxels around: new to the cloud, filled from
        // the face neighbour (one step, then two).
        assert_eq!(at[4..], [3.0, 30.0, 3.0, 30.0]);
        // Beyond FILL_STEPS from any mapped voxel: zero.
        let far = medium([6, 1, 1], Vec3::new(17.5, 0.0, 0.0), |_, _, _| true);
        let at = place.values_at(&values, 2, &far);
        assert_eq!(at[..2], [3.0, 30.0]);
        assert_eq!(at[2 * FILL_STEPS..2 * FILL_STEPS + 2], [3.0, 30.0]);
        assert_eq!(at[2 * FILL_STEPS + 2..], [0.0; 4]);
    }
}
