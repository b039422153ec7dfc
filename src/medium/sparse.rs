//! Storage per full voxel (ρ > 0), addressed by grid index: what the stages after the density
//! keep per voxel (stage 1's Q0/Q1 and sky harmonics, I0, I1, the lit volume and its pyramid)
//! lives only where the cloud is, so memory follows the cloud, not its box (a procedural cumulus
//! fills ~9 % of its box).
//!
//! [`FullIndex`] maps each grid voxel to its slot: 0 for an empty voxel, 1 + its rank among the
//! full voxels in grid order (x fastest) otherwise; stored per grid row over the span of its full
//! voxels (about 4 bytes per voxel of the cloud's box), built once per density grid and shared
//! ([`crate::medium::Grid3::full_index`]). A [`VoxelField`] stores slot 0 (the value every empty
//! voxel reads, e.g. zero) and one value per full voxel; reading it by grid index costs the row
//! (one multiplication), its span and slot (two loads) and the value.

use crate::math::Trilinear;
use rayon::prelude::*;
use std::sync::Arc;

/// Slot of every grid voxel: 0 where ρ = 0, 1 + rank in grid order where ρ > 0. Stored per row
/// (j, k) of the grid, over the span from the row's first to its last full voxel only: 12 B per
/// row and 4 B per voxel of the spans (about the cloud's box), instead of 4 B per grid voxel.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FullIndex {
    dims: [usize; 3],
    /// Per row: its span's first x, length, and where its slots start in `slot`.
    rows: Vec<Span>,
    /// The spans' slots, row after row.
    slot: Vec<u32>,
    count: usize,
    /// Grid index → row, without a division.
    row_of: Divider,
}

/// One row's span of the index.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Span {
    lo: u32,
    len: u32,
    start: u32,
}

/// Exact n / d for n < 2³² by one multiplication (Lemire, Kaser & Kurz 2019, "Faster remainder
/// by direct computation": with M = ⌊(2⁶⁴ − 1)/d⌋ + 1, n/d = ⌊M·n / 2⁶⁴⌋ for all 32-bit n and d);
/// larger n (grids beyond 2³² voxels) divide.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Divider {
    d: u64,
    m: u64,
    /// Whether every index to divide is below 2³² (and d > 1).
    fast: bool,
}

impl Divider {
    fn new(d: usize, n_max: usize) -> Divider {
        let d = d.max(1) as u64;
        let fast = d > 1 && d < 1 << 32 && (n_max as u64) < 1 << 32;
        Divider {
            d,
            m: if d > 1 { u64::MAX / d + 1 } else { 0 },
            fast,
        }
    }

    #[inline]
    fn div(&self, n: usize) -> usize {
        if self.fast {
            ((self.m as u128 * n as u128) >> 64) as usize
        } else {
            n / self.d as usize
        }
    }
}

impl FullIndex {
    /// The index of the voxels where `full(value)` holds, over a grid of `dims` with `values`
    /// (x fastest). Panics beyond 2³² − 1 full voxels (the medium's voxel limit is far below).
    pub fn build(dims: [usize; 3], values: &[f32], full: impl Fn(f32) -> bool) -> FullIndex {
        assert_eq!(values.len(), dims[0] * dims[1] * dims[2], "one value per voxel");
        let nx = dims[0].max(1);
        let mut count = 0usize;
        let mut rows = Vec::with_capacity(values.len() / nx);
        let mut slot = Vec::new();
        for row in values.chunks_exact(nx) {
            let first = row.iter().position(|v| full(*v));
            let span = match first {
                None => Span { lo: 0, len: 0, start: 0 },
                Some(lo) => {
                    let hi = row.iter().rposition(|v| full(*v)).expect("a first implies a last") + 1;
                    let start = u32::try_from(slot.len()).expect("fewer than 2^32 span voxels");
                    for v in &row[lo..hi] {
                        slot.push(if full(*v) {
                            count += 1;
                            u32::try_from(count).expect("fewer than 2^32 full voxels")
                        } else {
                            0
                        });
                    }
                    Span {
                        lo: lo as u32,
                        len: (hi - lo) as u32,
                        start,
                    }
                }
            };
            rows.push(span);
        }
        FullIndex {
            dims,
            rows,
            slot,
            count,
            row_of: Divider::new(nx, values.len()),
        }
    }

    /// Grid resolution.
    #[inline]
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Grid voxels.
    #[inline]
    pub fn len(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    /// True for a grid without voxels.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Full voxels.
    #[inline]
    pub fn count(&self) -> usize {
        self.count
    }

    /// Slot of grid voxel `g` (0: empty).
    #[inline]
    pub fn slot(&self, g: usize) -> usize {
        let r = self.row_of.div(g);
        let span = self.rows[r];
        let dx = ((g - r * self.dims[0]) as u32).wrapping_sub(span.lo);
        if dx < span.len {
            self.slot[(span.start + dx) as usize] as usize
        } else {
            0
        }
    }

    /// Grid indices of the full voxels, in grid order (the order of a field's packed values).
    pub fn full_voxels(&self) -> impl Iterator<Item = usize> + '_ {
        let nx = self.dims[0];
        self.rows.iter().enumerate().flat_map(move |(r, span)| {
            let slots = &self.slot[span.start as usize..(span.start + span.len) as usize];
            let g0 = r * nx + span.lo as usize;
            slots.iter().enumerate().filter(|(_, s)| **s != 0).map(move |(dx, _)| g0 + dx)
        })
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        std::mem::size_of::<Span>() * self.rows.len() + 4 * self.slot.len()
    }
}

/// Values per full voxel of a [`FullIndex`], read by grid index; every empty voxel reads the
/// field's `empty` value.
#[derive(Clone, Debug, PartialEq)]
pub struct VoxelField<T> {
    index: Arc<FullIndex>,
    /// Slot 0: the empty value; slot s ≥ 1: full voxel of rank s − 1.
    data: Vec<T>,
}

impl<T: Copy + Send + Sync> VoxelField<T> {
    /// From the values of the full voxels in grid order (`packed.len()` = `index.count()`).
    pub fn new(index: Arc<FullIndex>, empty: T, packed: impl IntoIterator<Item = T>) -> VoxelField<T> {
        let mut data = Vec::with_capacity(index.count() + 1);
        data.push(empty);
        data.extend(packed);
        assert_eq!(data.len(), index.count() + 1, "one value per full voxel");
        VoxelField { index, data }
    }

    /// From its slots: `slots[0]` the empty value, then the full voxels' values in grid order
    /// (`slots.len()` = `index.count() + 1`); takes the vector without a copy.
    pub fn from_slots(index: Arc<FullIndex>, slots: Vec<T>) -> VoxelField<T> {
        assert_eq!(slots.len(), index.count() + 1, "the empty value and one value per full voxel");
        VoxelField { index, data: slots }
    }

    /// Every voxel, full or empty, reads `empty`.
    pub fn filled(index: Arc<FullIndex>, empty: T) -> VoxelField<T> {
        let n = index.count();
        VoxelField::new(index, empty, std::iter::repeat(empty).take(n))
    }

    /// `at(grid index)` for every full voxel, in parallel; `empty` elsewhere.
    pub fn from_fn(index: Arc<FullIndex>, empty: T, at: impl Fn(usize) -> T + Sync) -> VoxelField<T> {
        let full: Vec<usize> = index.full_voxels().collect();
        let mut data = Vec::with_capacity(full.len() + 1);
        data.push(empty);
        data.par_extend(full.par_iter().map(|&g| at(g)));
        VoxelField { index, data }
    }

    /// The value of grid voxel `g`.
    #[inline]
    pub fn get(&self, g: usize) -> T {
        self.data[self.index.slot(g)]
    }

    /// `t` over this field's slots: blend it with [`Self::at_slot`] to read 8 corners with one
    /// look-up each (several channels blended from one [`Trilinear`] share them).
    #[inline]
    pub fn slots(&self, t: &Trilinear) -> Trilinear {
        Trilinear {
            idx: t.idx.map(|g| self.index.slot(g)),
            f: t.f,
        }
    }

    /// The value in slot `s` (from [`Self::slots`]).
    #[inline]
    pub fn at_slot(&self, s: usize) -> &T {
        &self.data[s]
    }

    /// The value of grid voxel `g` if it is full.
    #[inline]
    pub fn get_full(&self, g: usize) -> Option<&T> {
        match self.index.slot(g) {
            0 => None,
            s => Some(&self.data[s]),
        }
    }

    /// The values of the full voxels in grid order.
    #[inline]
    pub fn packed(&self) -> &[T] {
        &self.data[1..]
    }

    /// The index the field is addressed by.
    #[inline]
    pub fn index(&self) -> &Arc<FullIndex> {
        &self.index
    }

    /// Grid voxels (full and empty).
    #[inline]
    pub fn len(&self) -> usize {
        self.index.len()
    }

    /// True for a grid without voxels.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.index.is_empty()
    }

    /// Every grid voxel's value in grid order (empty voxels read the empty value).
    pub fn iter(&self) -> Iter<'_, T> {
        Iter {
            index: &self.index,
            g: 0,
            data: &self.data,
        }
    }

    /// A field of the same voxels with `f` of each value (the empty value too).
    pub fn map<U: Copy + Send + Sync>(&self, f: impl Fn(&T) -> U + Sync + Send) -> VoxelField<U> {
        VoxelField {
            index: self.index.clone(),
            data: self.data.par_iter().map(f).collect(),
        }
    }

    /// Bytes held by the values (the index is shared and counted apart).
    pub fn bytes(&self) -> usize {
        std::mem::size_of::<T>() * self.data.len()
    }
}

/// Every grid voxel's value of a [`VoxelField`], in grid order.
pub struct Iter<'a, T> {
    index: &'a FullIndex,
    g: usize,
    data: &'a [T],
}

impl<'a, T> Iterator for Iter<'a, T> {
    type Item = &'a T;
    #[inline]
    fn next(&mut self) -> Option<&'a T> {
        (self.g < self.index.len()).then(|| {
            self.g += 1;
            &self.data[self.index.slot(self.g - 1)]
        })
    }
    #[inline]
    fn size_hint(&self) -> (usize, Option<usize>) {
        let n = self.index.len() - self.g;
        (n, Some(n))
    }
}

impl<'a, T: Copy + Send + Sync> IntoIterator for &'a VoxelField<T> {
    type Item = &'a T;
    type IntoIter = Iter<'a, T>;
    fn into_iter(self) -> Iter<'a, T> {
        self.iter()
    }
}

impl<T: Copy + Send + Sync> std::ops::Index<usize> for VoxelField<T> {
    type Output = T;
    /// The value of grid voxel `g`.
    #[inline]
    fn index(&self, g: usize) -> &T {
        &self.data[self.index.slot(g)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn full_voxels_are_stored_and_empty_ones_read_the_empty_value() {
        let rho = [0.0, 2.0, 0.0, 0.5, 1.0, 0.0];
        let idx = Arc::new(FullIndex::build([3, 2, 1], &rho, |r| r > 0.0));
        assert_eq!((idx.count(), idx.len()), (3, 6));
        assert_eq!(idx.full_voxels().collect::<Vec<_>>(), vec![1, 3, 4]);
        let f = VoxelField::from_fn(idx.clone(), -1.0f32, |g| 10.0 * g as f32);
        assert_eq!(f.iter().copied().collect::<Vec<_>>(), vec![-1.0, 10.0, -1.0, 30.0, 40.0, -1.0]);
        assert_eq!((f[3], f.get(2), f.get_full(0), f.get_full(4)), (30.0, -1.0, None, Some(&40.0)));
        assert_eq!(f.packed(), &[10.0, 30.0, 40.0]);
        assert_eq!(f, VoxelField::new(idx.clone(), -1.0, [10.0, 30.0, 40.0]));
        assert_eq!(f, VoxelField::from_slots(idx.clone(), vec![-1.0, 10.0, 30.0, 40.0]));
        assert_eq!(f.map(|v| *v as i32 + 1).get(0), 0);
        assert_eq!(VoxelField::filled(idx, 7u8).iter().filter(|v| **v == 7).count(), 6);
    }

    /// The row-span index against the dense slot array it replaces, on a random grid with empty
    /// rows, gaps inside spans and full rows.
    #[test]
    fn the_index_equals_the_dense_slots() {
        let dims = [13, 7, 5];
        let mut rng = crate::math::Rng::new(9, 4);
        let values: Vec<f32> = (0..13 * 7 * 5)
            .map(|g| match (g / 13) % 4 {
                0 => 0.0,
                1 => 1.0,
                _ if rng.uniform() < 0.4 => rng.uniform() + 0.1,
                _ => 0.0,
            })
            .collect();
        let idx = FullIndex::build(dims, &values, |v| v > 0.0);
        let mut rank = 0;
        for (g, v) in values.iter().enumerate() {
            let want = if *v > 0.0 {
                rank += 1;
                rank
            } else {
                0
            };
            assert_eq!(idx.slot(g), want, "voxel {g}");
        }
        assert_eq!(idx.count(), rank);
        let want: Vec<usize> = (0..values.len()).filter(|g| values[*g] > 0.0).collect();
        assert_eq!(idx.full_voxels().collect::<Vec<_>>(), want);
        assert!(idx.bytes() < 4 * values.len());
    }

    /// The multiplication gives the quotient at the edges of the 32-bit range.
    #[test]
    fn the_divider_is_exact() {
        for d in [1usize, 2, 3, 7, 100, 400, 641, 65_537, (1 << 31) + 11] {
            let div = Divider::new(d, u32::MAX as usize);
            for n in [
                0usize,
                1,
                d - 1,
                d,
                d + 1,
                12_345_677,
                (1 << 31) - 1,
                1 << 31,
                u32::MAX as usize - 1,
                u32::MAX as usize,
            ] {
                assert_eq!(div.div(n), n / d, "{n} / {d}");
            }
        }
        assert_eq!(Divider::new(400, 1 << 40).div((1 << 40) - 1), ((1usize << 40) - 1) / 400);
    }
}
