//! Matrix-free geometric multigrid on the voxel lattice, used as the preconditioner of conjugate
//! gradients (MGPCG, McAdams et al. 2010).
//!
//! * **Operator.** A symmetric 7-point stencil on its unknowns, read row by row ([`Stencils`]):
//!   assembled as an [`Operator`] (each unknown's box cell, diagonal and +x, +y, +z couplings and
//!   neighbours), or made on demand from what it is assembled from (the diffusion bands' rows, from
//!   the density: the build then never holds the finest operator beside its level);
//!   [`Hierarchy::build`] turns every level into a [`Level`] that stores its unknowns with their
//!   six neighbours' coded entries, their +x, +y, +z couplings and their row sum (or diagonal),
//!   the values in 16-bit codes ([`Row`](codec::Row): its 8 B of codes per entry, its neighbours' coding once
//!   per run of entries that share it, [`Runs`](codec::Runs), 16 B, or 20 B on a level whose z planes are too
//!   large for u16 ±z distances: [`Rows`](codec::Rows); each −a coupling is read from the −a neighbour's
//!   codes, so each face's is stored once). Nothing is stored per cell of the box (the cloud fills about
//!   half of its tight box), so the memory and the work scale with the unknowns. The whole
//!   hierarchy is divided by one power of two ([`unit_of`](codec::unit_of), the right-hand sides alike), which
//!   keeps every level's code scale a normal f32 whatever the voxel size.
//! * **Coarsening** by 2×2×2 aggregation with the Galerkin product Aᶜ = PᵀAP, P the piecewise-
//!   constant prolongation: the coarse operator is again a 7-point stencil (an aggregate's diagonal
//!   sums its children's diagonals and the couplings inside it; a coarse coupling sums the fine
//!   couplings across the aggregates' shared face). Galerkin coarse operators follow coefficient
//!   jumps and the domain's shape exactly, keep symmetry and definiteness, and need no
//!   re-discretisation. A coarse cell exists where any child is full. No level is scaled
//!   diagonally (the hierarchy's power of two divides all alike): the coarse space is piecewise
//!   constant in the unknowns as assembled, whose smooth errors are locally constant (see
//!   [`Level`]).
//! * **Smoother:** red-black Gauss–Seidel, red then black before the coarse correction and black
//!   then red after it, so the cycle is a symmetric preconditioner. A level stores its red
//!   unknowns first, then its black ones, so a colour's pass streams through its own rows.
//! * **Cycle:** a W-cycle whose coarse correction is scaled by [`OVER_CORRECTION`].
//! * **Coarsest level** (≤ [`COARSE_CELLS`] unknowns): Cholesky within the envelope, exact.
//! * **Krylov:** CG with the iterate in f64 and its other vectors in f32, stopped on the true
//!   residual in f64 ([`Hierarchy::solve_many`]); its operator is the finest level's rows (16-bit
//!   couplings and row sums, ≤ 2⁻¹² relative, products summed in f64). It stops on the relative
//!   residual of the diagonally scaled system, ‖D^-½ r‖/‖D^-½ b‖, D taken from the rows where
//!   the norms are summed.
//! * **Determinism:** updates within a colour are independent; reductions sum fixed-size chunks'
//!   partial sums in order. Bit-identical at any thread count.

mod cg;
mod coarse;
mod codec;
mod cycle;
mod level;
mod operator;

#[cfg(test)]
mod tests;

use coarse::Dense;
pub use codec::MAX_BOX_ROW_CELLS;
use level::Level;
use operator::{coarsen, Maxima};
pub use operator::{Node, Operator, Stencil, Stencils};

/// The cycle is a W-cycle: each level above the coarsest direct one visits the next coarser
/// level twice (a V-cycle, once, needs about twice the CG iterations: docs/diffusion.md).
const W_CYCLE_VISITS: usize = 2;

/// Unknowns at or below which a level is solved directly.
pub const COARSE_CELLS: usize = 800;

/// Default [`Hierarchy::over_correction`]. Piecewise-constant prolongation under-corrects smooth
/// errors (the interpolant jumps at every aggregate face, so PᵀAP overestimates a smooth error's
/// energy and the correction comes out too small), so the correction is scaled up (Braess 1995).
/// Measured on the procedural cloud (iterations per band at 50×40×30, 100×80×60, 200×160×120, to
/// 1e-6): 1.0 → 14–15/12/10–11, 1.2 → 13–14/11/8–9, 1.3 → 12–13/11/8, 1.5 → 16–18/13–14/10–11;
/// to 1e-4, 1.1–1.4 all give 9/8/6 ±1.
pub const OVER_CORRECTION: f64 = 1.3;

/// Rows per parallel task (and per partial sum of the reductions: fixed, so sums do not depend
/// on the thread count).
const CHUNK: usize = 4096;

/// Marks a pad entry ([`Level::unknown`]).
const PAD: u32 = u32::MAX;

/// Marks a missing neighbour in [`Node::up_nbr`].
pub const NONE: u32 = u32::MAX;

/// The multigrid hierarchy of one operator.
#[derive(Clone, Debug)]
pub struct Hierarchy {
    /// Levels, finest first (the finest holding its rows' sums: [`Level::row_sums`]).
    levels: Vec<Level>,
    coarse: Dense,
    /// Scale of the coarse-grid correction (over-correction of piecewise-constant aggregation).
    pub over_correction: f64,
    /// Red-black sweeps before and after the coarse correction.
    pub sweeps: usize,
}

impl Hierarchy {
    /// Build the levels of `a` down to [`COARSE_CELLS`] unknowns.
    pub fn build(a: &impl Stencils) -> Hierarchy {
        Self::build_with(a, COARSE_CELLS)
    }

    /// As [`Hierarchy::build`], coarsening until a level has at most `coarse_cells` unknowns.
    ///
    /// `a` is read row by row (twice: for the first coarse operator and for the finest level's
    /// rows), never held as a whole here; each coarser operator is held only until its level
    /// and the next operator exist.
    pub fn build_with(a: &impl Stencils, coarse_cells: usize) -> Hierarchy {
        Self::build_coded(a, coarse_cells, true)
    }

    /// [`Hierarchy::build_with`], every level's ±z distances u32 unless `narrow` ([`Rows`]).
    fn build_coded(a: &impl Stencils, coarse_cells: usize, narrow: bool) -> Hierarchy {
        let mut first = (a.len() > coarse_cells && a.dims().iter().any(|d| *d > 1)).then(|| coarsen(a));
        let maxima = first.as_ref().map_or_else(|| Maxima::all(a), |c| c.2);
        let (mut level, mut entry) = Level::from_stencils(a, true, narrow, None, maxima);
        let unit = Some(level.unit);
        let mut levels = Vec::new();
        // The operator of `level` when it is a coarse one.
        let mut coarsest: Option<Operator> = None;
        loop {
            let (c, parent) = match (first.take(), &coarsest) {
                (Some((c, parent, _)), _) => (c, parent),
                (None, Some(f)) if level.unknowns() > coarse_cells && f.dims.iter().any(|d| *d > 1) => {
                    let (c, parent, _) = coarsen(&f.rows());
                    (c, parent)
                }
                _ => break,
            };
            let rows = c.rows();
            let (mut next, next_entry) = Level::from_stencils(&rows, false, narrow, unit, Maxima::all(&rows));
            level.link(&parent, &mut next, &next_entry, &c);
            levels.push(std::mem::replace(&mut level, next));
            (coarsest, entry) = (Some(c), next_entry);
        }
        let coarse = match &coarsest {
            Some(c) => Dense::build(&c.rows(), &level, &entry),
            None => Dense::build(a, &level, &entry),
        };
        levels.push(level);
        Hierarchy {
            levels,
            coarse,
            over_correction: OVER_CORRECTION,
            sweeps: 1,
        }
    }

    /// Number of levels (including the direct one).
    #[cfg(test)]
    pub fn levels(&self) -> usize {
        self.levels.len()
    }

    /// Bytes the hierarchy holds.
    fn bytes(&self) -> usize {
        let level = |l: &Level| l.rows.bytes() + 4 * (l.parent.len() + 3 * l.planes.len());
        self.levels.iter().map(level).sum::<usize>() + 8 * (self.coarse.l.len() + self.coarse.cells.len())
    }
}
