//! Empty dual cells of a pyramid level: a bit per cell of the lattice between the level's voxel
//! centres, set when any of its eight corner voxels holds density. A cube sample whose dual cell
//! is empty interpolates ρ = 0 exactly, so [`crate::lit::pyramid::Level::sample`] would return
//! None; the cube renderer tests the bit first and skips the trilinear blend (near the cloud's
//! surface most samples of the border cubes fall in such cells: 64 % on the default scene).

use crate::lit::pyramid::{Cell, Level};
use crate::math::{fast_floor, small_int, Trilinear, Vec3};

/// Occupied dual cells of one level (bit set: some corner has ρ > 0).
#[derive(Clone, Debug)]
pub struct DualMask {
    /// Dual cells per axis: the level's dims + 1 (half a voxel beyond each face, where the
    /// trilinear rule clamps to the edge voxels).
    dims: [usize; 3],
    /// The level's box in its voxel coordinates: (n_x, n_y, n_z).
    size: Vec3,
    bits: Vec<u64>,
}

impl DualMask {
    /// The mask of `level`.
    pub fn new(level: &Level) -> DualMask {
        let n = level.dims;
        let dims = [n[0] + 1, n[1] + 1, n[2] + 1];
        let len = dims[0] * dims[1] * dims[2];
        let mut bits = vec![0u64; len.div_ceil(64)];
        // Dual cell a (per axis) has the voxel corners clamp(a − 1) and clamp(a), as in
        // [`crate::math::Trilinear::new`]: a full voxel i marks the cells i and i + 1.
        for k in 0..n[2] {
            for j in 0..n[1] {
                for i in 0..n[0] {
                    if level.cells.get(i + n[0] * (j + n[1] * k))[0] <= 0.0 {
                        continue;
                    }
                    for c in k..=k + 1 {
                        for b in j..=j + 1 {
                            for a in i..=i + 1 {
                                let q = a + dims[0] * (b + dims[1] * c);
                                bits[q / 64] |= 1 << (q % 64);
                            }
                        }
                    }
                }
            }
        }
        assert!(
            n.iter().all(|&a| a < 1 << 22),
            "level {n:?} too large for the float index arithmetic"
        );
        let size = Vec3::new(n[0] as f32, n[1] as f32, n[2] as f32);
        DualMask { dims, size, bits }
    }

    /// Does the dual cell whose lower corner voxel is `fl` (floor of v − ½ per axis, v inside the
    /// level's box, so fl ∈ [−1, n − 1]) blend any full voxel? False means ρ = 0 exactly there.
    #[inline]
    fn bit(&self, fl: [i32; 3]) -> bool {
        // Shifted by one so the half voxel below the first centre (−1) is cell 0; a cell
        // outside (never, for v inside the box) fails the slice's bound check.
        let cell = |a: usize| (fl[a] + 1) as usize;
        let q = cell(0) + self.dims[0] * (cell(1) + self.dims[1] * cell(2));
        (self.bits[q / 64] >> (q % 64)) & 1 == 1
    }

    /// [`Level::sample`] of `level` (the level this mask was made from) at `v`, None outside its
    /// box [0, n]³ (or at NaN), with the floors taken once for the mask and the blend: None at
    /// once in an empty dual cell, else the very same operations as [`crate::math::Trilinear`],
    /// so the same bits.
    #[inline]
    pub fn sample(&self, level: &Level, v: Vec3) -> Option<Cell> {
        self.sample_slots(level, v).map(|(c, _)| c)
    }

    /// [`Self::sample`] with the trilinear corners as slots of the level's cells, so fields
    /// stored on the same index (the gather source's ρ·I1 levels) blend at the same point.
    #[inline]
    pub fn sample_slots(&self, level: &Level, v: Vec3) -> Option<(Cell, Trilinear)> {
        if !(v.cmpge(Vec3::ZERO).all() && v.cmple(self.size).all()) {
            return None;
        }
        // Inside the box x = v − ½ ∈ [−½, n − ½]: the floors are in [−1, n − 1] (far below 2²²),
        // so they convert without saturating casts and the clamps below need one side each.
        let p = v.to_array();
        let mut fl = [0i32; 3];
        let mut f = [0f32; 3];
        for a in 0..3 {
            let x = p[a] - 0.5;
            // One SSE4.1 round on the x86-64-v2 build.
            let x0 = fast_floor(x);
            fl[a] = small_int(x0);
            f[a] = x - x0;
        }
        if !self.bit(fl) {
            return None;
        }
        let n = level.dims;
        let lo = |a: usize| fl[a].max(0) as usize;
        let hi = |a: usize| (fl[a] + 1).min(n[a] as i32 - 1) as usize;
        let (x, y, z) = ([lo(0), hi(0)], [lo(1), hi(1)], [lo(2), hi(2)]);
        let ix = |c: usize| x[c & 1] + n[0] * (y[(c >> 1) & 1] + n[1] * z[c >> 2]);
        let t = level.cells.slots(&Trilinear {
            idx: std::array::from_fn(ix),
            f,
        });
        let rho = level.cells.rho_blend(&t);
        if rho <= 1e-12 {
            return None;
        }
        let c = level.cells.rest_blend(&t);
        Some(([rho, c.x, c.y, c.z, c.w], t))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::{Sky, Sun};
    use crate::lit::LitVolume;
    use crate::math::Rgb;
    use crate::medium::{Grid3, Medium};

    /// Wherever the mask says empty, every level's sample is None; it says occupied at a sample
    /// with density; and its own sample is the level's, bit for bit (a sparse random cloud at
    /// random points, the box's faces included).
    #[test]
    fn empty_cells_sample_to_none_and_full_ones_are_marked() {
        let dims = [9, 7, 8];
        let mut g = Grid3::filled(dims, 0.0);
        let mut rng = crate::math::Rng::new(3, 0);
        for x in g.data_mut().iter_mut() {
            if rng.uniform() < 0.08 {
                *x = 0.5 + rng.uniform();
            }
        }
        let m = Medium::new(g, Vec3::ZERO, Vec3::ONE, 1.0, Rgb::ONE, 0.5);
        let sun = Sun {
            dir: Vec3::Y,
            irradiance: Rgb::ONE,
        };
        let n = m.density.len();
        let lit = LitVolume::new(m, vec![Rgb::ONE; n], Grid3::filled(dims, 0.5), sun, Sky::constant(Rgb::ONE), None);
        let p = lit.pyramid();
        let (mut empty, mut full) = (0, 0);
        for lev in &p.levels {
            let mask = DualMask::new(lev);
            let d = Vec3::new(lev.dims[0] as f32, lev.dims[1] as f32, lev.dims[2] as f32);
            for s in 0..4000 {
                // Every 10th point on a face or corner of the box.
                let mut v = Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * d;
                if s % 10 == 0 {
                    v = Vec3::select(v.cmplt(d * 0.5), Vec3::ZERO, d);
                }
                assert_eq!(mask.sample(lev, v), lev.sample(v), "level {:?} at {v}", lev.dims);
                let occupied = mask.bit(v.to_array().map(|x| (x - 0.5).floor() as i32));
                match lev.sample(v) {
                    Some(_) => {
                        full += 1;
                        assert!(occupied, "level {:?} at {v}: density but marked empty", lev.dims);
                    }
                    None if !occupied => empty += 1,
                    None => {}
                }
            }
        }
        assert!(empty > 1000 && full > 1000, "empty {empty}, full {full}");
    }
}
