//! Dense 3-D scalar grid: the storage every density source is converted to.

use super::sparse::FullIndex;
use crate::error::{Error, Result};
use std::sync::{Arc, OnceLock};

/// A dense grid of `f32` values, index (i, j, k) = (x, y, z), x fastest in memory.
#[derive(Clone, Debug)]
pub struct Grid3 {
    dims: [usize; 3],
    data: Vec<f32>,
    /// The index of its voxels > 0, built on first use and dropped by every write.
    full: OnceLock<Arc<FullIndex>>,
}

impl PartialEq for Grid3 {
    fn eq(&self, other: &Grid3) -> bool {
        self.dims == other.dims && self.data == other.data
    }
}

impl Grid3 {
    /// A grid of `dims` filled with `value`.
    pub fn filled(dims: [usize; 3], value: f32) -> Self {
        Grid3 {
            dims,
            data: vec![value; dims[0] * dims[1] * dims[2]],
            full: OnceLock::new(),
        }
    }

    /// Wrap existing data (x fastest). `what` names the source for the error message.
    pub fn from_vec(dims: [usize; 3], data: Vec<f32>, what: &str) -> Result<Self> {
        let n = dims[0].checked_mul(dims[1]).and_then(|v| v.checked_mul(dims[2]));
        match n {
            Some(n) if n == data.len() && n > 0 => Ok(Grid3 {
                dims,
                data,
                full: OnceLock::new(),
            }),
            Some(0) => Err(Error::format(
                what,
                format!("grid has zero size (nx, ny, nz) = {dims:?}: every dimension must be at least 1"),
            )),
            _ => Err(Error::format(
                what,
                format!(
                    "grid resolution {dims:?} needs {} values but {} were given",
                    n.map_or("too many".to_string(), |n| n.to_string()),
                    data.len()
                ),
            )),
        }
    }

    /// Resolution (nx, ny, nz).
    #[inline]
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Number of voxels.
    #[inline]
    pub fn len(&self) -> usize {
        self.data.len()
    }

    /// True when the grid holds no voxel (never, for a validated grid).
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// Linear index of (i, j, k).
    #[inline]
    pub fn index(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }

    /// Value at (i, j, k); the caller guarantees the index is inside.
    #[inline]
    pub fn get(&self, i: usize, j: usize, k: usize) -> f32 {
        self.data[self.index(i, j, k)]
    }

    /// Value at signed (i, j, k), zero outside the grid.
    #[inline]
    pub fn get_or_zero(&self, i: isize, j: isize, k: isize) -> f32 {
        if i < 0 || j < 0 || k < 0 || i as usize >= self.dims[0] || j as usize >= self.dims[1] || k as usize >= self.dims[2] {
            0.0
        } else {
            self.get(i as usize, j as usize, k as usize)
        }
    }

    /// Set the value at (i, j, k).
    #[inline]
    pub fn set(&mut self, i: usize, j: usize, k: usize, v: f32) {
        let idx = self.index(i, j, k);
        self.full.take();
        self.data[idx] = v;
    }

    /// The raw values, x fastest.
    #[inline]
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// Mutable raw values, x fastest.
    #[inline]
    pub fn data_mut(&mut self) -> &mut [f32] {
        self.full.take();
        &mut self.data
    }

    /// The index of the voxels with a value > 0 (of a density grid: the full voxels), built on
    /// first use and shared by every field stored per full voxel ([`super::sparse`]).
    pub fn full_index(&self) -> Arc<FullIndex> {
        self.full
            .get_or_init(|| Arc::new(FullIndex::build(self.dims, &self.data)))
            .clone()
    }

    /// Trilinear interpolation at continuous voxel coordinates `p`, where voxel (i, j, k) has its
    /// centre at (i + 0.5, j + 0.5, k + 0.5). Indices are clamped to the grid (clamp-to-edge), so
    /// the field is defined on the whole box [0, n]³; the caller decides what lies outside it.
    #[inline]
    pub fn trilinear(&self, p: [f32; 3]) -> f32 {
        crate::math::Trilinear::new(self.dims, p).blend(|n| self.data[n])
    }

    /// Largest value (0 for an all-zero grid).
    pub fn max_value(&self) -> f32 {
        self.data.iter().copied().fold(0.0, f32::max)
    }

    /// The grid refined `k` times per axis (k odd): each voxel split into k³, each new voxel
    /// holding the trilinear field (ρ between voxel centres, clamped beyond the outermost ones)
    /// at its centre. With k odd the new centres include the old ones, and the trilinear field of
    /// the new grid is the old one (a trilinear function is trilinear on each sub-cell): the same
    /// cloud, resolved k times finer.
    pub fn refine(&self, k: usize) -> Grid3 {
        if k <= 1 {
            return self.clone();
        }
        let [nx, ny, nz] = self.dims;
        // A fine centre in coarse voxel coordinates: (m + ½)/k, i + ½ (a coarse centre) at m = k i + (k − 1)/2.
        let at = |m: usize| ((m as f64 + 0.5) / k as f64) as f32;
        let dims = [nx * k, ny * k, nz * k];
        let mut data = vec![0f32; dims[0] * dims[1] * dims[2]];
        // One z slice of the new grid per task.
        crate::par::for_chunks(&mut data, dims[0] * dims[1], &|kk, slice| {
            for (n, v) in slice.iter_mut().enumerate() {
                *v = self.trilinear([at(n % dims[0]), at(n / dims[0]), at(kk)]);
            }
        });
        Grid3 {
            dims,
            data,
            full: OnceLock::new(),
        }
    }

    /// Average `n`×`n`×`n` blocks into one voxel (the paper averaged 200×160×120 down to
    /// 100×80×60). Partial blocks at the far edges average the voxels they hold.
    pub fn downsample(&self, n: usize) -> Grid3 {
        if n <= 1 {
            return self.clone();
        }
        let nd = [self.dims[0].div_ceil(n), self.dims[1].div_ceil(n), self.dims[2].div_ceil(n)];
        let mut out = Grid3::filled(nd, 0.0);
        for k in 0..nd[2] {
            for j in 0..nd[1] {
                for i in 0..nd[0] {
                    let mut sum = 0.0f64;
                    let mut cnt = 0usize;
                    for kk in k * n..((k + 1) * n).min(self.dims[2]) {
                        for jj in j * n..((j + 1) * n).min(self.dims[1]) {
                            for ii in i * n..((i + 1) * n).min(self.dims[0]) {
                                sum += self.get(ii, jj, kk) as f64;
                                cnt += 1;
                            }
                        }
                    }
                    out.set(i, j, k, (sum / cnt as f64) as f32);
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Rng;

    #[test]
    fn refining_keeps_the_trilinear_field_and_the_centres() {
        let dims = [5, 4, 3];
        let mut rng = Rng::new(3, 1);
        let data: Vec<f32> = (0..60).map(|n| if n % 7 == 0 { 0.0 } else { rng.uniform() * 2.0 }).collect();
        let coarse = Grid3::from_vec(dims, data, "test").unwrap();
        for k in [3, 5] {
            let fine = coarse.refine(k);
            assert_eq!(fine.dims(), [5 * k, 4 * k, 3 * k]);
            // The old centres are new centres, with their values exactly.
            for (i, j, l) in [(0, 0, 0), (4, 3, 2), (2, 1, 1)] {
                assert_eq!(fine.get(k * i + k / 2, k * j + k / 2, k * l + k / 2), coarse.get(i, j, l));
            }
            // Anywhere in the box, clamped sides included, the same field.
            for _ in 0..2000 {
                let p: [f32; 3] = std::array::from_fn(|a| rng.uniform() * dims[a] as f32);
                let (want, got) = (coarse.trilinear(p), fine.trilinear(p.map(|x| x * k as f32)));
                assert!((got - want).abs() <= 2e-6 * (1.0 + want), "k = {k} at {p:?}: {got} vs {want}");
            }
        }
        assert_eq!(coarse.refine(1), coarse);
    }
}
