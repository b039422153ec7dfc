//! Empty dual cells of a pyramid level: a bit per cell of the lattice between the level's voxel
//! centres, set when any of its eight corner voxels holds density. A cube sample whose dual cell
//! is empty interpolates ρ = 0 exactly, so [`crate::lit::pyramid::Level::sample`] would return
//! None; the cube renderer tests the bit first and skips the trilinear blend (near the cloud's
//! surface most samples of the border cubes fall in such cells: 64 % on the default scene).

use crate::lit::pyramid::Level;
use crate::math::{fast_floor, Vec3};

/// Occupied dual cells of one level (bit set: some corner has ρ > 0).
#[derive(Clone, Debug)]
pub struct DualMask {
    /// Dual cells per axis: the level's dims + 1 (half a voxel beyond each face, where the
    /// trilinear rule clamps to the edge voxels).
    dims: [usize; 3],
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
                    if level.cells[i + n[0] * (j + n[1] * k)][0] <= 0.0 {
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
        DualMask { dims, bits }
    }

    /// Does the trilinear field at level-voxel coordinates `v` (inside the level's box, so each
    /// component in [0, dims]) blend any full voxel? False means ρ(v) = 0 exactly.
    #[inline]
    pub fn occupied(&self, v: Vec3) -> bool {
        // The same floor of v − ½ as the trilinear rule, shifted by one so −1 maps to cell 0.
        let cell = |x: f32, n: usize| ((fast_floor(x - 0.5) as isize + 1).clamp(0, n as isize - 1)) as usize;
        let q = cell(v.x, self.dims[0]) + self.dims[0] * (cell(v.y, self.dims[1]) + self.dims[1] * cell(v.z, self.dims[2]));
        (self.bits[q / 64] >> (q % 64)) & 1 == 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::{Sky, Sun};
    use crate::lit::LitVolume;
    use crate::math::Rgb;
    use crate::medium::{Grid3, Medium};

    /// Wherever the mask says empty, every level's sample is None; and it says occupied at a
    /// sample with density (checked on a sparse random cloud at random points, edges included).
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
                match lev.sample(v) {
                    Some(_) => {
                        full += 1;
                        assert!(mask.occupied(v), "level {:?} at {v}: density but marked empty", lev.dims);
                    }
                    None if !mask.occupied(v) => empty += 1,
                    None => {}
                }
            }
        }
        assert!(empty > 1000 && full > 1000, "empty {empty}, full {full}");
    }
}
