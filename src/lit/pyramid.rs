//! Mip pyramid of the lit volume for cone-matched volume rendering (the modern stand-in for the
//! paper's octree of least-squares approximations, Schussman and Max 2001).
//!
//! Level 0 holds, per voxel, the pre-multiplied quantities (ρ, ρ·I0 (RGB), ρ·T_sun): it is the lit
//! volume's own cells ([`LitVolume::cells`], the same allocation, not a copy); level l+1
//! averages 2×2×2 blocks of level l, counting cells beyond the grid as empty, so every level keeps
//! the cloud's total mass and the mass-weighted mean colour. A sample at level l interpolates
//! trilinearly and divides by ρ to recover the colour, so empty space never darkens the colour.
//! Each level has a block occupancy grid for empty-space skipping. Every level stores its cells
//! only where ρ > 0 ([`crate::medium::sparse`]; level 0 shares the density grid's index).

use super::LitVolume;
use crate::math::{Trilinear, Vec3};
use crate::medium::sparse::{FullIndex, VoxelField};
use crate::medium::MajorantGrid;
use glam::Vec4;
use std::sync::Arc;

/// Block edge (in the level's voxels) of each level's occupancy grid.
pub const BLOCK: usize = 4;

/// Values stored per voxel: ρ, ρ·I0.r, ρ·I0.g, ρ·I0.b, ρ·T_sun.
pub type Cell = [f32; 5];

/// One level of the pyramid.
#[derive(Clone, Debug)]
pub struct Level {
    /// Cells per axis.
    pub dims: [usize; 3],
    /// Voxel edge lengths at this level (m).
    pub voxel_size: Vec3,
    /// Pre-multiplied cells, x fastest, stored where ρ > 0 (zero elsewhere); level 0's are the
    /// lit volume's cells (shared).
    pub cells: Arc<VoxelField<Cell>>,
    /// Upper bounds of ρ per block of [`BLOCK`]³ cells (with a one-cell apron).
    pub occupancy: MajorantGrid,
}

impl Level {
    /// Trilinear sample at continuous level-voxel coordinates `v` (inside the level's box);
    /// None where the interpolated density is zero (the colour channels are then not gathered).
    #[inline]
    pub fn sample(&self, v: Vec3) -> Option<Cell> {
        let t = self.cells.slots(&Trilinear::new(self.dims, v.to_array()));
        let rho = t.blend(|s| self.cells.at_slot(s)[0]);
        if rho <= 1e-12 {
            return None;
        }
        let c = t.blend(|s| {
            let c = self.cells.at_slot(s);
            Vec4::new(c[1], c[2], c[3], c[4])
        });
        Some([rho, c.x, c.y, c.z, c.w])
    }
}

/// The pyramid, finest level first.
#[derive(Clone, Debug)]
pub struct LitPyramid {
    /// Levels 0 (the voxel grid) to the coarsest.
    pub levels: Vec<Level>,
    /// Minimum corner shared by every level (m).
    pub origin: Vec3,
}

impl LitPyramid {
    /// Build from a lit volume, down to a level whose largest axis has at most [`BLOCK`] cells or
    /// `max_levels` levels in all (at least 1).
    pub fn build(lit: &LitVolume, max_levels: usize) -> LitPyramid {
        let m = &lit.medium;
        // Level 0's occupancy is the medium's majorant grid where its blocks are the same.
        let occupancy = match m.majorant.block {
            BLOCK => (*m.majorant).clone(),
            _ => MajorantGrid::of_density(&m.density, BLOCK),
        };
        let level0 = Level {
            dims: m.dims(),
            voxel_size: m.voxel_size,
            cells: lit.cells().clone(),
            occupancy,
        };
        let mut levels = vec![level0];
        while levels.len() < max_levels.max(1) {
            let last = levels.last().expect("at least one level");
            if last.dims.iter().all(|&d| d <= BLOCK) {
                break;
            }
            let next = downsample(last);
            levels.push(next);
        }
        LitPyramid { levels, origin: m.origin }
    }
}

/// Grid indices (x fastest, in that order) of the cells of a `d` grid that the coarser cell `c`
/// averages: its 2×2×2 block, less the cells beyond the grid (they count as empty, so the mean
/// still divides by 8).
pub fn children(d: [usize; 3], c: [usize; 3]) -> impl Iterator<Item = usize> {
    let span = move |a: usize| 2 * c[a]..(2 * c[a] + 2).min(d[a]);
    span(2).flat_map(move |kk| span(1).flat_map(move |jj| span(0).map(move |ii| ii + d[0] * (jj + d[1] * kk))))
}

/// Average 2×2×2 blocks; cells beyond the grid count as empty (mass-preserving). Walks the
/// finer level's full cells only, in grid order, so each coarse cell adds its full children in
/// the order of [`children`] (its empty ones add nothing): the coarse level is never held for
/// every cell of its grid (20 B per coarse cell, the 200×160×120 cloud's `full` peak), only its
/// ρ (4 B per coarse cell, for its index) while it is built.
fn downsample(l: &Level) -> Level {
    let d = l.dims;
    let nd = [d[0].div_ceil(2), d[1].div_ceil(2), d[2].div_ceil(2)];
    let coarse = |n: usize| {
        let (i, j, k) = (n % d[0], (n / d[0]) % d[1], n / (d[0] * d[1]));
        i / 2 + nd[0] * (j / 2 + nd[1] * (k / 2))
    };
    let fine = || l.cells.index().full_voxels().zip(l.cells.packed());
    let mut rho = vec![0f32; nd[0] * nd[1] * nd[2]];
    for (n, c) in fine() {
        rho[coarse(n)] += c[0];
    }
    rho.iter_mut().for_each(|r| *r *= 0.125);
    let index = Arc::new(FullIndex::build(nd, &rho, |r| r > 0.0));
    let occupancy = MajorantGrid::build(nd, index.full_voxels().map(|n| (n, rho[n])), BLOCK);
    drop(rho);
    let mut cells = vec![[0f32; 5]; index.count() + 1];
    for (n, c) in fine() {
        // Slot 0: a coarse cell whose mean ρ rounds to 0 is empty.
        let s = index.slot(coarse(n));
        if s != 0 {
            for (a, v) in cells[s].iter_mut().zip(c) {
                *a += v;
            }
        }
    }
    cells[1..].iter_mut().for_each(|c| *c = c.map(|x| x * 0.125));
    Level {
        dims: nd,
        voxel_size: l.voxel_size * 2.0,
        cells: Arc::new(VoxelField::from_slots(index, cells)),
        occupancy,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::{Sky, Sun};
    use crate::math::Rgb;
    use crate::medium::{Grid3, Medium};

    #[test]
    fn every_level_keeps_mass_and_mean_colour() {
        let dims = [7, 5, 6];
        let mut g = Grid3::filled(dims, 0.0);
        let mut i0 = vec![Rgb::ZERO; 7 * 5 * 6];
        for (n, x) in g.data_mut().iter_mut().enumerate() {
            *x = ((n * 13) % 5) as f32 * 0.5;
            i0[n] = Rgb::new(n as f32 % 3.0, 1.0, 2.0);
        }
        let m = Medium::new(g, Vec3::ZERO, Vec3::ONE, 1.0, Rgb::ONE, 0.5);
        let sun = Sun {
            dir: Vec3::Y,
            irradiance: Rgb::ONE,
        };
        let lit = LitVolume::new(m, i0, Grid3::filled(dims, 0.5), sun, Sky::constant(Rgb::ONE), None);
        let p = LitPyramid::build(&lit, 10);
        assert!(p.levels.len() >= 2);
        let total = |l: &Level| {
            let vol = l.voxel_size.x * l.voxel_size.y * l.voxel_size.z;
            let mut s = [0f64; 5];
            for c in l.cells.packed() {
                for a in 0..5 {
                    s[a] += (c[a] * vol) as f64;
                }
            }
            s
        };
        let t0 = total(&p.levels[0]);
        for l in &p.levels[1..] {
            let t = total(l);
            for a in 0..5 {
                assert!((t[a] - t0[a]).abs() < 1e-4 * t0[a].max(1.0), "level {:?}: {t:?} vs {t0:?}", l.dims);
            }
        }
    }
}
