//! A grid's values stored on a sub-box only, with one constant everywhere outside it: for a
//! field that is constant away from the cloud (the sun transmittance is 1 beyond one voxel of it),
//! so memory follows the cloud's box, not the whole grid. Reads give the same bits as the dense
//! grid holding that constant outside the box (same corners, same weights, same blend).
//!
//! The values are stored as a [`Texel`]: f32 (the density's dense copies), or a 16-bit code (the
//! sun transmittance, [`crate::half::Unit16`]) decoded at each read, before the blend.

use super::Grid3;
use crate::half::Texel;
use crate::math::Trilinear;

/// Values on the box [lo, lo + box_dims) of a grid of `dims`, `outside` elsewhere, stored as `T`.
#[derive(Clone, Debug, PartialEq)]
pub struct SubGrid<T: Texel = f32> {
    dims: [usize; 3],
    lo: [usize; 3],
    box_dims: [usize; 3],
    /// The box's values (x fastest), then `outside` (the slot every corner outside the box reads).
    data: Vec<T>,
}

impl<T: Texel> SubGrid<T> {
    /// The box [lo, hi) of a grid of `dims`, every value `fill`, `outside` beyond the box (both
    /// encoded as `T`).
    pub fn filled(dims: [usize; 3], lo: [usize; 3], hi: [usize; 3], fill: f32, outside: f32) -> SubGrid<T> {
        assert!((0..3).all(|a| lo[a] <= hi[a] && hi[a] <= dims[a]), "the box lies in the grid");
        let box_dims = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
        let mut data = vec![T::encode(fill); box_dims.iter().product::<usize>() + 1];
        *data.last_mut().expect("the outside slot") = T::encode(outside);
        SubGrid { dims, lo, box_dims, data }
    }

    /// Resolution of the whole grid.
    #[inline]
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// The box's minimum corner and size (voxels).
    pub fn bounds(&self) -> ([usize; 3], [usize; 3]) {
        (self.lo, self.box_dims)
    }

    /// The box's values, x fastest (without the outside slot), to fill in place.
    pub fn box_values_mut(&mut self) -> &mut [T] {
        let n = self.data.len() - 1;
        &mut self.data[..n]
    }

    /// Slot of grid voxel (i, j, k): its box index, or the outside slot.
    #[inline]
    fn slot(&self, c: [usize; 3]) -> usize {
        let (x, y, z) = (
            c[0].wrapping_sub(self.lo[0]),
            c[1].wrapping_sub(self.lo[1]),
            c[2].wrapping_sub(self.lo[2]),
        );
        if x < self.box_dims[0] && y < self.box_dims[1] && z < self.box_dims[2] {
            x + self.box_dims[0] * (y + self.box_dims[1] * z)
        } else {
            self.data.len() - 1
        }
    }

    /// Value of grid voxel (i, j, k).
    #[inline]
    pub fn get(&self, i: usize, j: usize, k: usize) -> f32 {
        self.data[self.slot([i, j, k])].decode()
    }

    /// Value of the grid voxel with linear index `g` = i + nx(j + ny k).
    #[inline]
    pub fn at_index(&self, g: usize) -> f32 {
        let (nx, ny) = (self.dims[0], self.dims[1]);
        self.get(g % nx, (g / nx) % ny, g / (nx * ny))
    }

    /// Every grid voxel's value in grid order.
    pub fn values(&self) -> impl Iterator<Item = f32> + '_ {
        let [nx, ny, nz] = self.dims;
        (0..nz).flat_map(move |k| (0..ny).flat_map(move |j| (0..nx).map(move |i| self.get(i, j, k))))
    }

    /// Trilinear interpolation at continuous voxel coordinates `p`, as [`Grid3::trilinear`].
    /// (Always inlined: the marches' per-sample look-up; out of line it cost `single`'s gather
    /// 15 % more instructions.)
    #[inline(always)]
    pub fn trilinear(&self, p: [f32; 3]) -> f32 {
        // Trilinear::new's corners and fractions, as grid coordinates.
        let (lo, hi, f) = Trilinear::corners(self.dims, p);
        self.trilinear_at_corners(lo, hi, f)
    }

    /// [`Self::trilinear`] at the point whose [`Trilinear::corners`] are `lo`, `hi`, `f` (the same
    /// bits): for a caller that has them already. When the eight corners lie in the box (nearly
    /// every sample in a cloud, and the sun's look-ups per eye-ray piece) one bounds check serves
    /// them all: one slot and strides (hi − lo is 0 or 1 per axis), the same slots as eight `slot`
    /// calls.
    #[inline(always)]
    pub fn trilinear_at_corners(&self, lo: [usize; 3], hi: [usize; 3], f: [f32; 3]) -> f32 {
        Trilinear {
            idx: self.corner_slots(lo, hi),
            f,
        }
        .blend(|n| self.data[n].decode())
    }

    /// exp of the trilinear interpolation of ln of the values at continuous voxel coordinates `p`
    /// (exact for a field whose log is linear, as a transmittance through uniform medium is;
    /// values ≤ 0 read as the smallest positive f32).
    pub fn trilinear_log(&self, p: [f32; 3]) -> f32 {
        let (lo, hi, f) = Trilinear::corners(self.dims, p);
        Trilinear {
            idx: self.corner_slots(lo, hi),
            f,
        }
        .blend(|n| self.data[n].decode().max(f32::MIN_POSITIVE).ln())
        .exp()
    }

    /// The values of the eight grid voxels from `lo` to `hi` (per axis equal or one apart), in
    /// [`Trilinear::idx`] order (c = x + 2y + 4z).
    #[inline(always)]
    pub fn corner_values(&self, lo: [usize; 3], hi: [usize; 3]) -> [f32; 8] {
        let s = self.corner_slots(lo, hi);
        let d = &self.data;
        // Spelled out: an array `map` here stays out of line (a call per dual cell).
        [d[s[0]], d[s[1]], d[s[2]], d[s[3]], d[s[4]], d[s[5]], d[s[6]], d[s[7]]].map(T::decode)
    }

    /// The slots of the eight corners from `lo` to `hi`.
    #[inline(always)]
    fn corner_slots(&self, lo: [usize; 3], hi: [usize; 3]) -> [usize; 8] {
        let inside = (0..3).all(|a| lo[a] >= self.lo[a] && hi[a] < self.lo[a] + self.box_dims[a]);
        if inside {
            let rel = |c: [usize; 3]| [c[0] - self.lo[0], c[1] - self.lo[1], c[2] - self.lo[2]];
            Trilinear::corner_indices(self.box_dims, rel(lo), rel(hi))
        } else {
            self.corner_slots_at_the_edge(lo, hi)
        }
    }

    /// [`Self::corner_slots`] when a corner may lie outside the box (rare: kept out of line so
    /// the in-box path stays small enough to inline).
    #[cold]
    #[inline(never)]
    fn corner_slots_at_the_edge(&self, lo: [usize; 3], hi: [usize; 3]) -> [usize; 8] {
        let pick = |c: usize, a: usize| if (c >> a) & 1 == 0 { lo[a] } else { hi[a] };
        std::array::from_fn(|c| self.slot([pick(c, 0), pick(c, 1), pick(c, 2)]))
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        std::mem::size_of::<T>() * self.data.len()
    }
}

/// The whole grid as its own box (nothing outside), each value encoded as `T`.
impl<T: Texel> From<Grid3> for SubGrid<T> {
    fn from(g: Grid3) -> SubGrid<T> {
        let dims = g.dims();
        let mut s = SubGrid::filled(dims, [0; 3], dims, 0.0, 0.0);
        for (o, &v) in s.box_values_mut().iter_mut().zip(g.data()) {
            *o = T::encode(v);
        }
        s
    }
}

impl<T: Texel> From<Grid3> for std::sync::Arc<SubGrid<T>> {
    fn from(g: Grid3) -> std::sync::Arc<SubGrid<T>> {
        std::sync::Arc::new(g.into())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Rng;

    /// A beam falling off exponentially along x (e^{−τ}, 1.5 optical depths per voxel): the log
    /// interpolation is exact between the centres, the linear one above it (midway by
    /// cosh(τ/2) − 1 = 29 %).
    #[test]
    fn the_log_interpolation_is_exact_for_an_exponential_beam() {
        let dims = [6, 3, 3];
        let mut g = Grid3::filled(dims, 0.0);
        for (i, j, k) in (0..6).flat_map(|i| (0..3).flat_map(move |j| (0..3).map(move |k| (i, j, k)))) {
            g.set(i, j, k, (-1.5 * i as f32).exp());
        }
        let sub: SubGrid = g.into();
        for x in [1.0f32, 1.5, 2.25, 3.5, 4.9] {
            // Voxel i's centre is at x = i + 0.5.
            let want = (-1.5 * (x - 0.5)).exp();
            let p = [x, 1.5, 1.5];
            assert!((sub.trilinear_log(p) - want).abs() <= 1e-5 * want, "{x}");
            assert!(sub.trilinear(p) >= want * (1.0 - 1e-6), "{x}");
        }
        let mid = (-1.5f32 * 1.5).exp();
        assert!((sub.trilinear([2.0, 1.5, 1.5]) / mid - 0.75f32.cosh()).abs() < 1e-3);
    }

    /// Against the dense grid with the box's values inside and the constant outside: the same
    /// bits everywhere, corners clamped at the grid's faces included.
    #[test]
    fn reads_equal_the_dense_grid_with_the_constant_outside() {
        let dims = [7, 5, 6];
        let (lo, hi) = ([2, 1, 0], [6, 5, 3]);
        let mut rng = Rng::new(3, 1);
        let mut sub = SubGrid::filled(dims, lo, hi, 0.0, 0.75);
        let mut dense = Grid3::filled(dims, 0.75);
        let bd = [4, 4, 3];
        for (n, v) in sub.box_values_mut().iter_mut().enumerate() {
            *v = rng.uniform();
            let (i, j, k) = (n % bd[0], (n / bd[0]) % bd[1], n / (bd[0] * bd[1]));
            dense.set(i + lo[0], j + lo[1], k + lo[2], *v);
        }
        assert_eq!(sub.values().collect::<Vec<_>>(), dense.data());
        for g in 0..dense.len() {
            assert_eq!(sub.at_index(g), dense.data()[g]);
        }
        for _ in 0..2000 {
            let p = [0, 1, 2].map(|a| (rng.uniform() * 1.2 - 0.1) * dims[a] as f32);
            assert_eq!(sub.trilinear(p).to_bits(), dense.trilinear(p).to_bits(), "at {p:?}");
        }
        // From corners located by the caller: the same bits, inside the box, across its faces and
        // outside it.
        for _ in 0..2000 {
            let p = [0, 1, 2].map(|a| (rng.uniform() * 1.2 - 0.1) * dims[a] as f32);
            let (c0, c1, f) = Trilinear::corners(dims, p);
            assert_eq!(
                sub.trilinear_at_corners(c0, c1, f).to_bits(),
                dense.trilinear(p).to_bits(),
                "at {p:?}"
            );
        }
        let whole: SubGrid = dense.clone().into();
        assert_eq!(whole.values().collect::<Vec<_>>(), dense.data());
        assert_eq!(whole.bytes(), 4 * (dense.len() + 1));
    }

    /// Stored as 16-bit codes: every read is that of the f32 grid holding the decoded values
    /// (the codes are decoded before the blend), within the code's rounding of the originals.
    #[test]
    fn coded_reads_equal_the_grid_of_decoded_values() {
        use crate::half::Unit16;
        let dims = [6, 5, 4];
        let mut rng = Rng::new(8, 2);
        let exact = Grid3::from_vec(dims, (0..120).map(|_| rng.uniform()).collect(), "test").unwrap();
        let coded: SubGrid<Unit16> = exact.clone().into();
        let decoded = Grid3::from_vec(dims, coded.values().collect(), "test").unwrap();
        for (d, e) in decoded.data().iter().zip(exact.data()) {
            assert!((d - e).abs() <= e / 4096.0 + 1e-9, "{d} vs {e}");
        }
        for _ in 0..2000 {
            let p = [0, 1, 2].map(|a| rng.uniform() * dims[a] as f32);
            assert_eq!(coded.trilinear(p).to_bits(), decoded.trilinear(p).to_bits(), "at {p:?}");
        }
        assert_eq!(coded.bytes(), 2 * 121);
    }
}
