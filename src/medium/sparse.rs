//! Storage per full voxel (ρ > 0), addressed by grid index: what the stages after the density
//! keep per voxel (stage 1's Q0/Q1 and sky harmonics, I0, I1, the lit volume and its pyramid)
//! lives only where the cloud is, so memory follows the cloud, not its box (a procedural cumulus
//! fills ~9 % of its box).
//!
//! [`FullIndex`] maps each grid voxel to its slot: 0 for an empty voxel, 1 + its rank among the
//! full voxels in grid order (x fastest) otherwise. It stores one 32-bit occupancy mask and the
//! rank of its first voxel per 32 grid voxels (8 bytes per 32 voxels: 0.25 B per grid voxel, a
//! sixteenth of a u32 slot per voxel), built once per density grid and shared
//! ([`crate::medium::Grid3::full_index`]); a slot is one load, a shift and a population count. A
//! [`VoxelField`] stores slot 0 (the value every empty voxel reads, e.g. zero) and one value per
//! full voxel; reading it by grid index is the slot and one load, no branch.

use crate::math::Trilinear;
use crate::par;
use std::sync::Arc;

/// Grid voxels per occupancy word.
const WORD_VOXELS: usize = 32;

/// The occupancy of 32 consecutive grid voxels and the rank of the first full one among them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
struct Word {
    /// Bit b set: grid voxel 32·w + b is full.
    mask: u32,
    /// Full voxels before grid voxel 32·w.
    base: u32,
}

/// Slot of every grid voxel: 0 where ρ = 0, 1 + rank in grid order where ρ > 0.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FullIndex {
    dims: [usize; 3],
    words: Vec<Word>,
    len: usize,
    count: usize,
}

impl FullIndex {
    /// The index of the voxels whose value is > 0 (full), over a grid of `dims` with `values`
    /// (x fastest). Panics beyond 2³² − 2 full voxels (the medium's voxel limit is far below).
    pub fn build(dims: [usize; 3], values: &[f32]) -> FullIndex {
        assert_eq!(values.len(), dims[0] * dims[1] * dims[2], "one value per voxel");
        let mut words = vec![Word::default(); values.len().div_ceil(WORD_VOXELS)];
        par::for_chunks(&mut words, par::CHUNK, &|ci, words| {
            let first = ci * par::CHUNK * WORD_VOXELS;
            for (w, chunk) in words.iter_mut().zip(values[first..].chunks(WORD_VOXELS)) {
                w.mask = chunk.iter().enumerate().fold(0, |m, (b, &v)| m | (u32::from(v > 0.0) << b));
            }
        });
        let mut count = 0usize;
        for w in &mut words {
            w.base = u32::try_from(count).expect("fewer than 2^32 full voxels");
            count += w.mask.count_ones() as usize;
        }
        u32::try_from(count + 1).expect("fewer than 2^32 - 1 full voxels");
        FullIndex {
            dims,
            words,
            len: values.len(),
            count,
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
        self.len
    }

    /// True for a grid without voxels.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Full voxels.
    #[inline]
    pub fn count(&self) -> usize {
        self.count
    }

    /// Slot of grid voxel `g` (0: empty): 1 + the word's base + the full voxels below `g` in its
    /// word, masked to 0 when `g` itself is empty (no branch).
    #[inline(always)]
    pub fn slot(&self, g: usize) -> usize {
        let w = self.words[g / WORD_VOXELS];
        let bit = (g % WORD_VOXELS) as u32;
        let below = w.mask & ((1u32 << bit) - 1);
        let full = (w.mask >> bit) & 1;
        ((w.base + below.count_ones() + 1) & 0u32.wrapping_sub(full)) as usize
    }

    /// True when grid voxel `g` is full (its occupancy bit).
    #[inline(always)]
    pub fn is_full(&self, g: usize) -> bool {
        (self.words[g / WORD_VOXELS].mask >> (g % WORD_VOXELS)) & 1 != 0
    }

    /// Slots of grid voxels `g0` and `g1`: when `g1` is `g0`'s neighbour along x in the same word
    /// (a trilinear look-up's corner pairs, nearly always), one load and one population count
    /// serve both.
    #[inline(always)]
    pub fn slot_pair(&self, g0: usize, g1: usize) -> [usize; 2] {
        let bit = g0 % WORD_VOXELS;
        if g1 != g0 + 1 || bit + 1 == WORD_VOXELS {
            return [self.slot(g0), self.slot(g1)];
        }
        let w = self.words[g0 / WORD_VOXELS];
        let bit = bit as u32;
        let rank = w.base + (w.mask & ((1u32 << bit) - 1)).count_ones();
        let full0 = (w.mask >> bit) & 1;
        let full1 = (w.mask >> (bit + 1)) & 1;
        [
            ((rank + 1) & 0u32.wrapping_sub(full0)) as usize,
            ((rank + full0 + 1) & 0u32.wrapping_sub(full1)) as usize,
        ]
    }

    /// Grid indices of the full voxels, in grid order (the order of a field's packed values).
    pub fn full_voxels(&self) -> impl Iterator<Item = usize> + '_ {
        self.words.iter().enumerate().flat_map(|(w, word)| {
            let mut mask = word.mask;
            std::iter::from_fn(move || {
                (mask != 0).then(|| {
                    let b = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    w * WORD_VOXELS + b
                })
            })
        })
    }

    /// Every grid voxel's slot in grid order.
    fn slots(&self) -> Slots<'_> {
        Slots {
            index: self,
            g: 0,
            rank: 0,
        }
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        std::mem::size_of::<Word>() * self.words.len()
    }
}

/// Every grid voxel's slot in grid order, counting the rank as it goes.
struct Slots<'a> {
    index: &'a FullIndex,
    g: usize,
    rank: u32,
}

impl Iterator for Slots<'_> {
    type Item = usize;
    #[inline]
    fn next(&mut self) -> Option<usize> {
        if self.g == self.index.len {
            return None;
        }
        let word = self.index.words[self.g / WORD_VOXELS];
        let full = (word.mask >> (self.g % WORD_VOXELS)) & 1;
        self.rank += full;
        self.g += 1;
        Some((self.rank & 0u32.wrapping_sub(full)) as usize)
    }
    #[inline]
    fn size_hint(&self) -> (usize, Option<usize>) {
        let n = self.index.len - self.g;
        (n, Some(n))
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
        VoxelField::new(index, empty, std::iter::repeat_n(empty, n))
    }

    /// `at(grid index)` for every full voxel, in parallel; `empty` elsewhere.
    pub fn from_fn(index: Arc<FullIndex>, empty: T, at: impl Fn(usize) -> T + Sync) -> VoxelField<T> {
        VoxelField::fill(index, empty, &|out, voxels| {
            for (o, &g) in out.iter_mut().zip(voxels) {
                *o = at(g);
            }
        })
    }

    /// The field with `fill(values, voxels)` writing the values of the full voxels with grid
    /// indices `voxels`, called in parallel on chunks of them: one compiled copy of the loop per
    /// value type, not per caller's closure.
    fn fill(index: Arc<FullIndex>, empty: T, fill: &(dyn Fn(&mut [T], &[usize]) + Sync)) -> VoxelField<T> {
        let mut data = vec![empty; index.count() + 1];
        // The full voxels' grid indices a batch at a time: all of them (8 B per full voxel)
        // would be the largest transient at `full`'s last stage (2.85 MB at 200×160×120).
        const BATCH: usize = 1 << 15;
        let mut batch = Vec::with_capacity(BATCH.min(index.count()));
        let mut voxels = index.full_voxels();
        let mut done = 1;
        loop {
            batch.clear();
            batch.extend(voxels.by_ref().take(BATCH));
            if batch.is_empty() {
                break;
            }
            let out = &mut data[done..done + batch.len()];
            par::for_chunks(out, par::CHUNK, &|ci, out| fill(out, &batch[ci * par::CHUNK..]));
            done += batch.len();
        }
        drop(voxels);
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
        let i = &t.idx;
        let [a, b] = self.index.slot_pair(i[0], i[1]);
        let [c, d] = self.index.slot_pair(i[2], i[3]);
        let [e, f] = self.index.slot_pair(i[4], i[5]);
        let [g, h] = self.index.slot_pair(i[6], i[7]);
        Trilinear {
            idx: [a, b, c, d, e, f, g, h],
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

    /// The values of the full voxels in grid order, to overwrite in place.
    #[inline]
    pub fn packed_mut(&mut self) -> &mut [T] {
        &mut self.data[1..]
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
            slots: self.index.slots(),
            data: &self.data,
        }
    }

    /// A field of the same voxels with `f` of each value (the empty value too).
    pub fn map<U: Copy + Send + Sync>(&self, f: impl Fn(&T) -> U + Sync + Send) -> VoxelField<U> {
        let empty = f(&self.data[0]);
        let mut data = vec![empty; self.data.len()];
        par::for_chunks(&mut data[1..], par::CHUNK, &|ci, out| {
            for (o, v) in out.iter_mut().zip(&self.data[1 + ci * par::CHUNK..]) {
                *o = f(v);
            }
        });
        VoxelField {
            index: self.index.clone(),
            data,
        }
    }

    /// Bytes held by the values (the index is shared and counted apart).
    pub fn bytes(&self) -> usize {
        std::mem::size_of::<T>() * self.data.len()
    }
}

/// Every grid voxel's value of a [`VoxelField`], in grid order.
pub struct Iter<'a, T> {
    slots: Slots<'a>,
    data: &'a [T],
}

impl<'a, T> Iterator for Iter<'a, T> {
    type Item = &'a T;
    #[inline]
    fn next(&mut self) -> Option<&'a T> {
        self.slots.next().map(|s| &self.data[s])
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
        let idx = Arc::new(FullIndex::build([3, 2, 1], &rho));
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

    #[test]
    fn slots_match_a_running_count_across_word_boundaries() {
        // Occupancy patterns that cross the 32-voxel words: runs, isolated voxels, a full word,
        // an empty word, and a tail shorter than a word (7·5·3 = 105 voxels).
        let mut state = 12345u64;
        let rho: Vec<f32> = (0..105)
            .map(|g| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                match g {
                    32..=63 => 1.0,
                    64..=95 => 0.0,
                    _ => f32::from((state >> 33) % 3 == 0),
                }
            })
            .collect();
        let idx = FullIndex::build([7, 5, 3], &rho);
        let mut rank = 0;
        let naive: Vec<usize> = rho
            .iter()
            .map(|&r| {
                if r > 0.0 {
                    rank += 1;
                    rank
                } else {
                    0
                }
            })
            .collect();
        assert_eq!(idx.count(), rank);
        assert_eq!((0..105).map(|g| idx.slot(g)).collect::<Vec<_>>(), naive);
        assert_eq!(
            (0..105).map(|g| idx.is_full(g)).collect::<Vec<_>>(),
            naive.iter().map(|s| *s > 0).collect::<Vec<_>>()
        );
        assert_eq!(idx.slots().collect::<Vec<_>>(), naive);
        for g in 0..104 {
            assert_eq!(idx.slot_pair(g, g + 1), [naive[g], naive[g + 1]], "pair at {g}");
            assert_eq!(idx.slot_pair(g, g), [naive[g], naive[g]], "clamped pair at {g}");
        }
        let full: Vec<usize> = (0..105).filter(|&g| rho[g] > 0.0).collect();
        assert_eq!(idx.full_voxels().collect::<Vec<_>>(), full);
        assert_eq!(idx.bytes(), 8 * 4);
    }
}
