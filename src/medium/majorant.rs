//! Majorant grid: the maximum of the trilinear density field over each block of B³ voxels.
//! It lets ray marchers skip empty space and gives delta/ratio tracking a tight local bound,
//! so dense clouds do not crawl.

use super::{Dda, Grid3, Medium};
use crate::math::Vec3;
use glam::DVec3;

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
    /// Build with blocks of `block`³ voxels. The bound of a block covers every voxel the trilinear
    /// field can blend inside it (one voxel of apron on every side).
    pub fn build(g: &Grid3, block: usize) -> MajorantGrid {
        let d = g.dims();
        let dims = [d[0].div_ceil(block), d[1].div_ceil(block), d[2].div_ceil(block)];
        let mut max_density = vec![0f32; dims[0] * dims[1] * dims[2]];
        for bk in 0..dims[2] {
            for bj in 0..dims[1] {
                for bi in 0..dims[0] {
                    let range = |b: usize, n: usize| (b * block).saturating_sub(1)..((b + 1) * block + 1).min(n);
                    let mut m = 0f32;
                    for k in range(bk, d[2]) {
                        for j in range(bj, d[1]) {
                            for i in range(bi, d[0]) {
                                m = m.max(g.get(i, j, k));
                            }
                        }
                    }
                    max_density[bi + dims[0] * (bj + dims[1] * bk)] = m;
                }
            }
        }
        MajorantGrid { block, dims, max_density }
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

    /// Origin-independent helper: lattice cell size (m) for a medium.
    pub fn cell_size(&self, m: &Medium) -> DVec3 {
        m.voxel_size.as_dvec3() * self.block as f64
    }
}
