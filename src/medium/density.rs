//! The medium's density ρ, stored per full voxel (ρ > 0): 4 B per full voxel plus the shared
//! [`FullIndex`] (0.25 B per grid voxel), instead of 4 B per grid voxel. A procedural cumulus
//! fills ~9 % of its box, so the dense grid cost ~43 B per full voxel for the whole run.
//!
//! The loaders and the procedural generator build a dense [`Grid3`]; [`Density::from_grid`]
//! packs it when the medium is built and the dense grid is dropped. Every read returns the very
//! same f32 the dense grid held (empty voxels read 0), so images do not change.

use super::sparse::{FullIndex, VoxelField};
use super::{Grid3, SubGrid};
use crate::math::Trilinear;
use std::sync::Arc;

/// ρ per voxel (unitless, ≥ 0), read by grid index (x fastest); stored only where ρ > 0.
#[derive(Clone, Debug, PartialEq)]
pub struct Density {
    /// Slot 0 is 0 (every empty voxel); then the full voxels' ρ in grid order.
    values: VoxelField<f32>,
    /// Largest ρ (0 for an empty grid).
    max: f32,
    /// Index box [lo, hi) of the full voxels (`None` without any).
    full_box: Option<([usize; 3], [usize; 3])>,
}

impl Density {
    /// Pack a dense grid (values must be finite and ≥ 0: the medium's validation).
    pub fn from_grid(grid: &Grid3) -> Density {
        let index = grid.full_index();
        let data = grid.data();
        let packed = index.full_voxels().map(|g| data[g]);
        let d = grid.dims();
        let (mut lo, mut hi) = (d, [0usize; 3]);
        for g in index.full_voxels() {
            let c = [g % d[0], (g / d[0]) % d[1], g / (d[0] * d[1])];
            for a in 0..3 {
                lo[a] = lo[a].min(c[a]);
                hi[a] = hi[a].max(c[a] + 1);
            }
        }
        Density {
            values: VoxelField::new(index.clone(), 0.0, packed),
            max: grid.max_value(),
            full_box: (index.count() > 0).then_some((lo, hi)),
        }
    }

    /// Index box [lo, hi) of the full voxels, `None` when there is none (computed once, when
    /// packed: the solver's domain, the dense box copies and the memory guard read it).
    #[inline]
    pub fn full_box(&self) -> Option<([usize; 3], [usize; 3])> {
        self.full_box
    }

    /// The dense grid (for exports and tests; 4 B per grid voxel while it lives).
    pub fn to_grid(&self) -> Grid3 {
        Grid3::from_vec(self.dims(), self.values.iter().copied().collect(), "density").expect("a validated grid")
    }

    /// Resolution (nx, ny, nz).
    #[inline]
    pub fn dims(&self) -> [usize; 3] {
        self.values.index().dims()
    }

    /// Grid voxels (full and empty); never 0 (a grid has at least one voxel).
    #[inline]
    #[cfg_attr(feature = "internals", allow(clippy::len_without_is_empty))]
    pub fn len(&self) -> usize {
        self.values.len()
    }

    /// Linear index of (i, j, k).
    #[inline]
    pub fn index(&self, i: usize, j: usize, k: usize) -> usize {
        let d = self.dims();
        i + d[0] * (j + d[1] * k)
    }

    /// ρ of grid voxel `n` (linear index).
    #[inline]
    pub fn at(&self, n: usize) -> f32 {
        self.values.get(n)
    }

    /// ρ in slot `s` of [`Self::full_index`] (0: every empty voxel): for a caller that reads
    /// several fields on that index at one voxel with one slot look-up.
    #[inline]
    pub fn at_slot(&self, s: usize) -> f32 {
        *self.values.at_slot(s)
    }

    /// True where ρ > 0 (the occupancy bit alone, no value load).
    #[inline]
    pub fn is_full(&self, n: usize) -> bool {
        self.values.index().is_full(n)
    }

    /// ρ at (i, j, k); the caller guarantees the index is inside.
    #[inline]
    pub fn get(&self, i: usize, j: usize, k: usize) -> f32 {
        self.at(self.index(i, j, k))
    }

    /// ρ at signed (i, j, k), zero outside the grid.
    #[inline]
    pub fn get_or_zero(&self, i: isize, j: isize, k: isize) -> f32 {
        let d = self.dims();
        if i < 0 || j < 0 || k < 0 || i as usize >= d[0] || j as usize >= d[1] || k as usize >= d[2] {
            0.0
        } else {
            self.get(i as usize, j as usize, k as usize)
        }
    }

    /// ρ of the eight voxels `idx` (a dual cell's corners, c = x + 2y + 4z as [`Trilinear::idx`]):
    /// the x-neighbour pairs share one slot look-up.
    #[inline(always)]
    pub fn corners(&self, idx: &[usize; 8]) -> [f32; 8] {
        let index = self.values.index();
        let mut out = [0.0; 8];
        for p in 0..4 {
            let [a, b] = index.slot_pair(idx[2 * p], idx[2 * p + 1]);
            out[2 * p] = *self.values.at_slot(a);
            out[2 * p + 1] = *self.values.at_slot(b);
        }
        out
    }

    /// Trilinear interpolation at continuous voxel coordinates `p`, where voxel (i, j, k) has its
    /// centre at (i + 0.5, j + 0.5, k + 0.5). Indices are clamped to the grid (clamp-to-edge), so
    /// the field is defined on the whole box [0, n]³; the caller decides what lies outside it.
    #[inline(always)]
    pub fn trilinear(&self, p: [f32; 3]) -> f32 {
        self.blend(&Trilinear::new(self.dims(), p))
    }

    /// ρ blended at the corners and fractions `t` (of this grid's dims), as
    /// `t.blend(|n| self.at(n))` with the corners' pair look-ups ([`Self::corners`]).
    #[inline(always)]
    pub fn blend(&self, t: &Trilinear) -> f32 {
        let v = self.corners(&t.idx);
        Trilinear {
            idx: [0, 1, 2, 3, 4, 5, 6, 7],
            f: t.f,
        }
        .blend(|c| v[c])
    }

    /// Largest ρ (0 for an all-zero grid).
    #[inline]
    pub fn max_value(&self) -> f32 {
        self.max
    }

    /// The index of the full voxels, shared by every field stored per full voxel.
    #[inline]
    pub fn full_index(&self) -> Arc<FullIndex> {
        self.values.index().clone()
    }

    /// Full voxels.
    #[inline]
    pub fn count(&self) -> usize {
        self.values.index().count()
    }

    /// The full voxels' ρ in grid order (a field's packed order).
    #[inline]
    pub fn packed(&self) -> &[f32] {
        self.values.packed()
    }

    /// (grid index, ρ) of every full voxel, in grid order.
    pub fn full_voxels(&self) -> impl Iterator<Item = (usize, f32)> + '_ {
        self.values.index().full_voxels().zip(self.packed().iter().copied())
    }

    /// ρ on the box [lo, hi) as a dense [`SubGrid`] (0 outside it): a transient copy for a stage
    /// that reads ρ many times per voxel of the cloud's box (the sun's march); 4 B per box voxel.
    /// Every full voxel must lie in the box.
    pub fn box_copy(&self, lo: [usize; 3], hi: [usize; 3]) -> SubGrid {
        let mut sub = SubGrid::filled(self.dims(), lo, hi, 0.0, 0.0);
        self.fill_box(lo, hi, sub.box_values_mut());
        sub
    }

    /// Write ρ on the box [lo, hi) into `out` (x fastest, zeroed by the caller) from the full
    /// voxels, all of which must lie in the box.
    pub fn fill_box(&self, lo: [usize; 3], hi: [usize; 3], out: &mut [f32]) {
        let d = self.dims();
        let bd = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
        assert_eq!(out.len(), bd[0] * bd[1] * bd[2], "one value per box voxel");
        for (n, rho) in self.full_voxels() {
            let c = [n % d[0], (n / d[0]) % d[1], n / (d[0] * d[1])];
            let r = [0, 1, 2].map(|a| c[a].wrapping_sub(lo[a]));
            assert!((0..3).all(|a| r[a] < bd[a]), "full voxel {c:?} outside the box");
            out[r[0] + bd[0] * (r[1] + bd[1] * r[2])] = rho;
        }
    }

    /// Every grid voxel's ρ in grid order (empty voxels read 0).
    pub fn iter(&self) -> impl Iterator<Item = f32> + '_ {
        self.values.iter().copied()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Rng;

    /// A random grid with ~40 % empty voxels, full runs and empty words.
    fn random_grid(dims: [usize; 3], seed: u64) -> Grid3 {
        let mut rng = Rng::new(seed, 0);
        let mut g = Grid3::filled(dims, 0.0);
        for v in g.data_mut() {
            if rng.uniform() < 0.6 {
                *v = 0.01 + 3.0 * rng.uniform();
            }
        }
        g
    }

    #[test]
    fn reads_equal_the_dense_grid_everywhere() {
        let dims = [13, 7, 5];
        let g = random_grid(dims, 3);
        let d = Density::from_grid(&g);
        assert_eq!((d.dims(), d.len(), d.max_value()), (dims, g.len(), g.max_value()));
        assert_eq!(d.count(), g.data().iter().filter(|v| **v > 0.0).count());
        assert_eq!(d.iter().collect::<Vec<_>>(), g.data());
        assert_eq!(d.to_grid(), g);
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let n = g.index(i, j, k);
                    assert_eq!((d.index(i, j, k), d.at(n), d.get(i, j, k)), (n, g.data()[n], g.get(i, j, k)));
                    assert_eq!((d.at_slot(d.full_index().slot(n)), d.is_full(n)), (g.data()[n], g.data()[n] > 0.0));
                }
            }
        }
        for (i, j, k) in [
            (-1, 0, 0),
            (0, -1, 3),
            (2, 2, -1),
            (13, 0, 0),
            (0, 7, 0),
            (0, 0, 5),
            (12, 6, 4),
            (3, 4, 2),
        ] {
            assert_eq!(d.get_or_zero(i, j, k), g.get_or_zero(i, j, k), "({i}, {j}, {k})");
        }
        let full: Vec<(usize, f32)> = g.data().iter().copied().enumerate().filter(|(_, v)| *v > 0.0).collect();
        assert_eq!(d.full_voxels().collect::<Vec<_>>(), full);
        assert_eq!(d.packed(), full.iter().map(|f| f.1).collect::<Vec<_>>());
    }

    #[test]
    fn trilinear_and_corners_equal_the_dense_grid_including_the_clamped_borders() {
        let dims = [9, 6, 4];
        let g = random_grid(dims, 8);
        let d = Density::from_grid(&g);
        let mut rng = Rng::new(2, 1);
        for _ in 0..5000 {
            // Beyond the box too: the clamped corners repeat a voxel (a pair with g1 = g0).
            let p = [rng.uniform() * 11.0 - 1.0, rng.uniform() * 8.0 - 1.0, rng.uniform() * 6.0 - 1.0];
            assert_eq!(d.trilinear(p).to_bits(), g.trilinear(p).to_bits(), "at {p:?}");
            let t = Trilinear::new(dims, p);
            assert_eq!(d.corners(&t.idx), t.idx.map(|n| g.data()[n]));
        }
    }

    #[test]
    fn a_box_copy_reads_the_density_inside_and_zero_outside() {
        let dims = [9, 7, 6];
        let mut g = Grid3::filled(dims, 0.0);
        for (i, j, k) in [(2, 1, 1), (6, 5, 4), (3, 3, 2), (6, 1, 1)] {
            g.set(i, j, k, 0.5 + i as f32);
        }
        let d = Density::from_grid(&g);
        let (lo, hi) = ([1, 1, 0], [8, 7, 5]);
        let sub = d.box_copy(lo, hi);
        assert_eq!(sub.bounds(), (lo, [7, 6, 5]));
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    assert_eq!(sub.get(i, j, k), g.get(i, j, k), "({i}, {j}, {k})");
                }
            }
        }
        assert_eq!(sub.corner_values([2, 1, 1], [3, 2, 1]), [2.5, 0.0, 0.0, 0.0, 2.5, 0.0, 0.0, 0.0]);
    }

    #[test]
    fn an_empty_grid_has_no_full_voxel_and_reads_zero() {
        let d = Density::from_grid(&Grid3::filled([4, 3, 2], 0.0));
        assert_eq!((d.count(), d.max_value(), d.trilinear([1.5, 1.0, 0.7])), (0, 0.0, 0.0));
        assert!(d.iter().all(|v| v == 0.0));
    }
}
