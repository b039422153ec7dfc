//! Storage per full voxel (ρ > 0), addressed by grid index: what the stages after the density
//! keep per voxel (stage 1's Q0/Q1 and sky harmonics, I0, I1, the lit volume and its pyramid)
//! lives only where the cloud is, so memory follows the cloud, not its box (a procedural cumulus
//! fills ~9 % of its box).
//!
//! [`FullIndex`] maps each grid voxel to its slot: 0 for an empty voxel, 1 + its rank among the
//! full voxels in grid order (x fastest) otherwise; 4 bytes per grid voxel, built once per density
//! grid and shared ([`crate::medium::Grid3::full_index`]). A [`VoxelField`] stores slot 0 (the
//! value every empty voxel reads, e.g. zero) and one value per full voxel; reading it by grid
//! index is one extra load and no branch.

use crate::math::Trilinear;
use rayon::prelude::*;
use std::sync::Arc;

/// Slot of every grid voxel: 0 where ρ = 0, 1 + rank in grid order where ρ > 0.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FullIndex {
    dims: [usize; 3],
    slot: Vec<u32>,
    count: usize,
}

impl FullIndex {
    /// The index of the voxels where `full(value)` holds, over a grid of `dims` with `values`
    /// (x fastest). Panics beyond 2³² − 1 full voxels (the medium's voxel limit is far below).
    pub fn build(dims: [usize; 3], values: &[f32], full: impl Fn(f32) -> bool) -> FullIndex {
        assert_eq!(values.len(), dims[0] * dims[1] * dims[2], "one value per voxel");
        let mut count = 0usize;
        let slot = values
            .iter()
            .map(|&v| {
                if full(v) {
                    count += 1;
                    u32::try_from(count).expect("fewer than 2^32 full voxels")
                } else {
                    0
                }
            })
            .collect();
        FullIndex { dims, slot, count }
    }

    /// Grid resolution.
    #[inline]
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Grid voxels.
    #[inline]
    pub fn len(&self) -> usize {
        self.slot.len()
    }

    /// True for a grid without voxels.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.slot.is_empty()
    }

    /// Full voxels.
    #[inline]
    pub fn count(&self) -> usize {
        self.count
    }

    /// Slot of grid voxel `g` (0: empty).
    #[inline]
    pub fn slot(&self, g: usize) -> usize {
        self.slot[g] as usize
    }

    /// Grid indices of the full voxels, in grid order (the order of a field's packed values).
    pub fn full_voxels(&self) -> impl Iterator<Item = usize> + '_ {
        self.slot.iter().enumerate().filter(|(_, s)| **s != 0).map(|(g, _)| g)
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        4 * self.slot.len()
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
            slots: self.index.slot.iter(),
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
    slots: std::slice::Iter<'a, u32>,
    data: &'a [T],
}

impl<'a, T> Iterator for Iter<'a, T> {
    type Item = &'a T;
    #[inline]
    fn next(&mut self) -> Option<&'a T> {
        self.slots.next().map(|&s| &self.data[s as usize])
    }
    #[inline]
    fn size_hint(&self) -> (usize, Option<usize>) {
        self.slots.size_hint()
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
}
