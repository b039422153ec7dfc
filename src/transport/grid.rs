//! The solver's view of the grid ([`Ctx`]): the swept box, the full-voxel index and the
//! optics the sweeps, the per-voxel source and moment steps and the acceleration read, and the
//! box's cells in each sweep order ([`box_cells`]).

use super::ground::GroundMap;
use super::sky_cells::SkyCells;
use super::source::parity_order;
use super::BandOptics;
use crate::lighting::Ground;
use crate::math::{sh_count, Rgb};
use crate::medium::sparse::FullIndex;
use crate::medium::{Density, Medium};
use std::sync::Arc;
use glam::DVec3;

/// The full voxels (ρ > 0): the unknowns of the solve, in grid order.
pub(super) struct FullVoxels {
    /// The medium's occupancy index: a grid voxel's slot is 1 + its index among the full voxels
    /// (0 where ρ = 0), 0.25 B per grid voxel.
    pub(super) index: Arc<FullIndex>,
    /// Grid index of every full voxel.
    pub(super) voxels: Vec<usize>,
}

impl FullVoxels {
    /// The full voxels of `rho`.
    pub(super) fn of(rho: &Density) -> FullVoxels {
        let index = rho.full_index();
        let voxels: Vec<usize> = index.full_voxels().collect();
        FullVoxels { index, voxels }
    }
}

/// Index among the full voxels of grid voxel `g`, or `u32::MAX` where ρ = 0.
#[inline(always)]
pub(crate) fn full_of(index: &FullIndex, g: usize) -> u32 {
    (index.slot(g) as u32).wrapping_sub(1)
}

/// Cells ahead of the current one in a sweep's plane whose source and radiance are prefetched.
pub(super) const PREFETCH_AHEAD: usize = 16;

/// Everything the sweeps read: the grid, the swept box, the full voxels and the δ-M optics. A
/// clone shares the cell lists (a sweep on other ordinates takes one with their sky).
#[derive(Clone)]
pub(super) struct Ctx<'a> {
    pub(super) dims: [usize; 3],
    /// The swept box: minimum corner and cells per axis (the full voxels plus one voxel).
    pub(super) lo: [usize; 3],
    pub(super) n: [usize; 3],
    pub(super) h: [f64; 3],
    pub(super) rho: &'a Density,
    pub(super) full: &'a Arc<FullIndex>,
    pub(super) nsh: usize,
    /// Even-l harmonics (the first of the inner order, [`parity_order`]).
    pub(super) even: usize,
    /// Grid index of every full voxel, in grid order.
    pub(super) voxels: &'a [usize],
    /// δ-M sun transmittance T′ per full voxel and band.
    pub(super) sun_t: &'a [[f32; 3]],
    /// The box's cells in each major axis' sweep order ([`box_cells`]).
    pub(super) cells: Arc<[Vec<(f32, u32)>; 3]>,
    /// Per major axis, each row of `cells`: its first full cell and one past its last
    /// ([`full_spans`]).
    pub(super) spans: Arc<[Vec<(u32, u32)>; 3]>,
    pub(super) sigma_t: [f32; 3],
    /// All bands share σt′ (one set of step weights serves them).
    pub(super) grey: bool,
    /// The sky along each ordinate (its mean over the ordinate's cell).
    pub(super) sky: &'a SkyCells,
    /// Grid origin (m) and the ground's height (m), if any.
    pub(super) origin: DVec3,
    pub(super) ground_height: Option<f64>,
}

impl<'a> Ctx<'a> {
    /// The sweeps' view of medium `m` under `sky` and `ground`: the box of the full voxels grown
    /// by one voxel, swept with SH `order` and the δ-M `bands`.
    pub(super) fn new(
        m: &'a Medium,
        sky: &'a SkyCells,
        ground: Option<&Ground>,
        index: &'a FullVoxels,
        sun_t: &'a [[f32; 3]],
        order: usize,
        bands: &[BandOptics; 3],
    ) -> Ctx<'a> {
        let dims = m.dims();
        let rho = &*m.density;
        let (lo, hi) = m.active_box(1).unwrap_or(([0; 3], dims));
        let n = [0, 1, 2].map(|a| hi[a] - lo[a]);
        let cells = [0, 1, 2].map(|a| box_cells(dims, lo, n, rho, &index.index, index.voxels.len(), a));
        let spans = [0, 1, 2].map(|a| full_spans(&cells[a], n[cross_axes(a).0]));
        Ctx {
            dims,
            lo,
            n,
            h: [m.voxel_size.x as f64, m.voxel_size.y as f64, m.voxel_size.z as f64],
            rho,
            full: &index.index,
            nsh: sh_count(order),
            even: parity_order(order).1,
            voxels: &index.voxels,
            sun_t,
            cells: Arc::new(cells),
            spans: Arc::new(spans),
            sigma_t: [0, 1, 2].map(|b| bands[b].sigma_t as f32),
            grey: bands[0].sigma_t == bands[1].sigma_t && bands[1].sigma_t == bands[2].sigma_t,
            sky,
            origin: DVec3::new(m.origin.x as f64, m.origin.y as f64, m.origin.z as f64),
            ground_height: ground.map(|g| g.height as f64),
        }
    }

    /// Radiance entering the swept box along `om` at the outside grid position (i, j, k): clear
    /// air outside the box carries it unchanged from the sky or, going up, from the ground point
    /// straight back along −om.
    #[inline]
    pub(super) fn boundary(&self, om: DVec3, i: isize, j: isize, k: isize, ground: &GroundMap, sky: Rgb) -> [f32; 3] {
        let c = match self.ground_height {
            Some(gh) if om.y > 0.0 => {
                let p = self.origin
                    + DVec3::new(
                        (i as f64 + 0.5) * self.h[0],
                        (j as f64 + 0.5) * self.h[1],
                        (k as f64 + 0.5) * self.h[2],
                    );
                let q = p - om * ((p.y - gh).max(0.0) / om.y);
                ground.at(q.x, q.z)
            }
            _ => sky,
        };
        [c.x, c.y, c.z]
    }
}
/// The two axes across major axis `a`, the faster-varying first.
pub(super) fn cross_axes(a: usize) -> (usize, usize) {
    match a {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    }
}

/// The swept box's cells (density, full-voxel index or `u32::MAX`) in the order a sweep along
/// major axis `a` visits them: planes of a, rows of the second cross axis, cells of the first;
/// so the sweeps read them contiguously whichever axis they run along. [`PREFETCH_AHEAD`] empty
/// cells follow the last, so that the sweep's look-ahead never runs off the end. Every index is
/// checked below `voxels` (the number of full voxels) here, once per solve: the sweeps index the
/// sources and radiances by it unchecked.
pub(super) fn box_cells(
    dims: [usize; 3],
    lo: [usize; 3],
    n: [usize; 3],
    rho: &Density,
    full: &FullIndex,
    voxels: usize,
    a: usize,
) -> Vec<(f32, u32)> {
    let (b, cc) = cross_axes(a);
    let mut out = Vec::with_capacity(n[0] * n[1] * n[2] + PREFETCH_AHEAD);
    for pa in 0..n[a] {
        for ic in 0..n[cc] {
            for ib in 0..n[b] {
                let mut v = lo;
                v[a] += pa;
                v[b] += ib;
                v[cc] += ic;
                let vi = v[0] + dims[0] * (v[1] + dims[1] * v[2]);
                let fi = full_of(full, vi);
                assert!(fi == u32::MAX || (fi as usize) < voxels, "full-voxel index out of range");
                out.push((rho.at(vi), fi));
            }
        }
    }
    out.extend([(0.0, u32::MAX); PREFETCH_AHEAD]);
    out
}

/// Per row of `cells` (rows of `row` cells, [`box_cells`]' order; the look-ahead padding after the
/// last row ignored): the index of its first full cell and one past its last, (0, 0) for a row
/// without one. The sweeps step only the cells of a row that a full cell or a non-clear upwind
/// cell can reach.
pub(super) fn full_spans(cells: &[(f32, u32)], row: usize) -> Vec<(u32, u32)> {
    let rows = (cells.len() - PREFETCH_AHEAD) / row.max(1);
    cells[..rows * row]
        .chunks_exact(row.max(1))
        .map(|r| match (r.iter().position(|c| c.1 != u32::MAX), r.iter().rposition(|c| c.1 != u32::MAX)) {
            (Some(first), Some(last)) => (first as u32, last as u32 + 1),
            _ => (0, 0),
        })
        .collect()
}
