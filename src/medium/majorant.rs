//! Majorant grid: the maximum of the trilinear density field over each block of B³ voxels.
//! It lets ray marchers skip empty space and gives delta/ratio tracking a tight local bound,
//! so dense clouds do not crawl.

use super::{Dda, Density, Medium};
use crate::math::Vec3;

/// Per-block upper bounds of ρ.
#[derive(Clone, Debug)]
pub struct MajorantGrid {
    /// Block edge in voxels.
    pub block: usize,
    /// Number of blocks per axis.
    pub dims: [usize; 3],
    /// max ρ over each block's region, block x fastest.
    pub max_density: Vec<f32>,
}

impl MajorantGrid {
    /// Build with blocks of `block`³ voxels over a grid of `dims` from its full voxels (grid
    /// index, ρ > 0). The bound of a block covers every voxel the trilinear field can blend
    /// inside it (one voxel of apron on every side), so a voxel raises the blocks whose region
    /// it lies in: up to two per axis.
    pub fn build(dims: [usize; 3], full: impl IntoIterator<Item = (usize, f32)>, block: usize) -> MajorantGrid {
        let nb = [dims[0].div_ceil(block), dims[1].div_ceil(block), dims[2].div_ceil(block)];
        let mut max_density = vec![0f32; nb[0] * nb[1] * nb[2]];
        // Blocks b with b·B − 1 ≤ i < (b + 1)·B + 1.
        let blocks = |i: usize, a: usize| i.saturating_sub(1) / block..=((i + 1) / block).min(nb[a] - 1);
        for (n, rho) in full {
            let c = [n % dims[0], (n / dims[0]) % dims[1], n / (dims[0] * dims[1])];
            for bk in blocks(c[2], 2) {
                for bj in blocks(c[1], 1) {
                    for bi in blocks(c[0], 0) {
                        let m = &mut max_density[bi + nb[0] * (bj + nb[1] * bk)];
                        *m = m.max(rho);
                    }
                }
            }
        }
        MajorantGrid {
            block,
            dims: nb,
            max_density,
        }
    }

    /// [`Self::build`] for the medium's density.
    pub fn of_density(rho: &Density, block: usize) -> MajorantGrid {
        MajorantGrid::build(rho.dims(), rho.full_voxels(), block)
    }

    /// Bound of block (i, j, k).
    #[inline]
    pub fn get(&self, c: [usize; 3]) -> f32 {
        self.max_density[c[0] + self.dims[0] * (c[1] + self.dims[1] * c[2])]
    }

    /// Walk the blocks along `o + t·d` for t ∈ [t0, t1] (already clipped to the medium's box),
    /// calling `f(t_enter, t_exit, max_density)`; `f` returns false to stop.
    #[inline]
    pub fn for_each_block(&self, m: &Medium, o: Vec3, d: Vec3, t0: f32, t1: f32, mut f: impl FnMut(f32, f32, f32) -> bool) {
        let cell = m.voxel_size.as_dvec3() * self.block as f64;
        for s in Dda::new(
            m.origin.as_dvec3(),
            cell,
            self.dims,
            o.as_dvec3(),
            d.as_dvec3(),
            t0 as f64,
            t1 as f64,
        ) {
            if !f(s.t0 as f32, s.t1 as f32, self.get(s.cell)) {
                break;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Rng;
    use crate::medium::Grid3;

    /// The bound as defined: the max over each block's region and its one-voxel apron.
    fn dense_oracle(g: &Grid3, block: usize) -> Vec<f32> {
        let d = g.dims();
        let nb = [d[0].div_ceil(block), d[1].div_ceil(block), d[2].div_ceil(block)];
        let range = |b: usize, n: usize| (b * block).saturating_sub(1)..((b + 1) * block + 1).min(n);
        let mut out = Vec::new();
        for bk in 0..nb[2] {
            for bj in 0..nb[1] {
                for bi in 0..nb[0] {
                    let mut m = 0f32;
                    for k in range(bk, d[2]) {
                        for j in range(bj, d[1]) {
                            for i in range(bi, d[0]) {
                                m = m.max(g.get(i, j, k));
                            }
                        }
                    }
                    out.push(m);
                }
            }
        }
        out
    }

    #[test]
    fn bounds_from_the_full_voxels_equal_the_max_over_each_blocks_apron() {
        let mut rng = Rng::new(4, 4);
        for (dims, block, fill) in [
            ([11, 9, 7], 4, 0.1),
            ([8, 8, 8], 4, 0.5),
            ([5, 13, 3], 2, 0.3),
            ([6, 2, 9], 3, 0.05),
        ] {
            let mut g = Grid3::filled(dims, 0.0);
            for v in g.data_mut() {
                if rng.uniform() < fill {
                    *v = rng.uniform() * 2.0;
                }
            }
            let m = MajorantGrid::of_density(&Density::from_grid(&g), block);
            assert_eq!(m.dims, [dims[0].div_ceil(block), dims[1].div_ceil(block), dims[2].div_ceil(block)]);
            assert_eq!(m.max_density, dense_oracle(&g, block), "{dims:?}, block {block}");
        }
    }
}
