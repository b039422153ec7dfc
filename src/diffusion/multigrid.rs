//! Matrix-free geometric multigrid on the voxel lattice, used as the preconditioner of conjugate
//! gradients (MGPCG, McAdams et al. 2010).
//!
//! * **Operator.** A symmetric 7-point stencil on its unknowns, read row by row ([`Stencils`]):
//!   assembled as an [`Operator`] (each unknown's box cell, diagonal and +x, +y, +z couplings and
//!   neighbours), or made on demand from what it is assembled from (the diffusion bands' rows, from
//!   the density: the build then never holds the finest operator beside its level);
//!   [`Hierarchy::build`] turns every level into a [`Level`] that stores its unknowns with their
//!   six neighbours' coded entries, their +x, +y, +z couplings and their row sum (or diagonal),
//!   the values in 16-bit codes ([`Row`]: its 8 B of codes per entry, its neighbours' coding once
//!   per run of entries that share it, [`Runs`], 16 B, or 20 B on a level whose z planes are too
//!   large for u16 ±z distances: [`Rows`]; each −a coupling is read from the −a neighbour's
//!   codes, so each face's is stored once). Nothing is stored per cell of the box (the cloud fills about
//!   half of its tight box), so the memory and the work scale with the unknowns. The whole
//!   hierarchy is divided by one power of two ([`unit_of`], the right-hand sides alike), which
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
//! * **Coarsest level** (≤ [`COARSE_CELLS`] unknowns): dense Cholesky, exact.
//! * **Krylov:** CG with the iterate in f64 and its other vectors in f32, stopped on the true
//!   residual in f64 ([`Hierarchy::solve_many`]); its operator is the finest level's rows (16-bit
//!   couplings and row sums, ≤ 2⁻¹² relative, products summed in f64). It stops on the relative
//!   residual of the diagonally scaled system, ‖D^-½ r‖/‖D^-½ b‖, D taken from the rows where
//!   the norms are summed.
//! * **Determinism:** updates within a colour are independent; reductions sum fixed-size chunks'
//!   partial sums in order. Bit-identical at any thread count.

use super::SolveStats;
use crate::half::Scaled16;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

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

/// One unknown of an [`Operator`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Node {
    /// Its cell in the operator's box (x fastest).
    pub cell: u32,
    /// The unknowns of its +x, +y, +z neighbours ([`NONE`]: not an unknown).
    pub up_nbr: [u32; 3],
    /// Diagonal (> 0).
    pub diag: f64,
    /// Matrix entries to its +x, +y, +z neighbours (0 where there is none).
    pub up: [f64; 3],
}

impl Node {
    /// An unknown at `cell` with no couplings yet.
    pub fn at(cell: u32) -> Node {
        Node {
            cell,
            up_nbr: [NONE; 3],
            diag: 0.0,
            up: [0.0; 3],
        }
    }
}

/// A symmetric 7-point operator stored on its unknowns only: the form the callers assemble
/// (48 B per unknown, nothing per cell of the box). The unknowns are in box order (increasing
/// `cell`); each −a coupling is its −a neighbour's +a one.
#[derive(Clone, Debug)]
pub struct Operator {
    /// Cells per axis of the box the unknowns' cells index.
    pub dims: [usize; 3],
    pub nodes: Vec<Node>,
}

/// One unknown's full row of a symmetric 7-point operator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stencil {
    /// Diagonal (> 0).
    pub diag: f64,
    /// Matrix entries to the −x, +x, −y, +y, −z, +z neighbours (0 where there is none).
    pub off: [f64; 6],
    /// Those neighbours' unknowns ([`NONE`]: not an unknown).
    pub nbr: [u32; 6],
}

/// A symmetric 7-point operator read one unknown at a time, its unknowns in box order: an
/// [`Operator`] ([`Operator::rows`]) or rows made on demand from what they are assembled from,
/// so that the finest level's build need not hold them all (the diffusion bands' assembly).
pub trait Stencils: Sync {
    /// Cells per axis of the box the unknowns' cells index.
    fn dims(&self) -> [usize; 3];
    /// Unknowns.
    fn len(&self) -> usize;
    /// Box cell (x fastest) of unknown `u`.
    fn cell(&self, u: usize) -> u32;
    /// Unknown `u`'s row.
    fn stencil(&self, u: usize) -> Stencil;

    /// Unknown `u` in [`Operator`] form (its +a half of the row).
    fn node(&self, u: usize) -> Node {
        let st = self.stencil(u);
        Node {
            cell: self.cell(u),
            up_nbr: [st.nbr[1], st.nbr[3], st.nbr[5]],
            diag: st.diag,
            up: [st.off[1], st.off[3], st.off[5]],
        }
    }

    /// Cell (i, j, k) of unknown `u`.
    fn ijk(&self, u: usize) -> [usize; 3] {
        let [nx, ny, _] = self.dims();
        let c = self.cell(u) as usize;
        [c % nx, (c / nx) % ny, c / (nx * ny)]
    }
}

impl Operator {
    /// The operator's full rows (each unknown's −a neighbours found once, 8 B per unknown).
    pub fn rows(&self) -> OperatorRows<'_> {
        let mut down = vec![[NONE; 2]; self.nodes.len()];
        for (u, nd) in self.nodes.iter().enumerate() {
            for ax in 1..3 {
                if nd.up_nbr[ax] != NONE {
                    down[nd.up_nbr[ax] as usize][ax - 1] = u as u32;
                }
            }
        }
        OperatorRows { a: self, down }
    }
}

/// An [`Operator`] read as [`Stencils`]: each −a entry is the −a neighbour's +a one.
pub struct OperatorRows<'a> {
    a: &'a Operator,
    /// Each unknown's −y and −z neighbours (the −x one is the unknown before it, if that is
    /// coupled to it).
    down: Vec<[u32; 2]>,
}

impl Stencils for OperatorRows<'_> {
    fn dims(&self) -> [usize; 3] {
        self.a.dims
    }

    fn len(&self) -> usize {
        self.a.nodes.len()
    }

    fn cell(&self, u: usize) -> u32 {
        self.a.nodes[u].cell
    }

    fn stencil(&self, u: usize) -> Stencil {
        let nodes = &self.a.nodes;
        let nd = &nodes[u];
        let mut st = Stencil {
            diag: nd.diag,
            off: [0.0; 6],
            nbr: [NONE; 6],
        };
        for ax in 0..3 {
            let d = match ax {
                0 => match u.checked_sub(1) {
                    Some(d) if nodes[d].up_nbr[0] == u as u32 => d as u32,
                    _ => NONE,
                },
                _ => self.down[u][ax - 1],
            };
            if d != NONE {
                (st.off[2 * ax], st.nbr[2 * ax]) = (nodes[d as usize].up[ax], d);
            }
            (st.off[2 * ax + 1], st.nbr[2 * ax + 1]) = (nd.up[ax], nd.up_nbr[ax]);
        }
        st
    }

    fn node(&self, u: usize) -> Node {
        self.a.nodes[u]
    }
}

/// The first unknown of `a` whose cell is at least `cell` (the unknowns are in box order).
fn first_at(a: &impl Stencils, cell: usize) -> usize {
    let (mut lo, mut hi) = (0, a.len());
    while lo < hi {
        let mid = (lo + hi) / 2;
        if (a.cell(mid) as usize) < cell {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    lo
}

/// Galerkin coarse operator PᵀAP of `a` for 2×2×2 piecewise-constant aggregation, and each
/// unknown's aggregate. A coarse unknown exists where any child is one; its diagonal sums its
/// children's diagonals and the couplings inside it (twice: both directions), a coarse coupling
/// the fine ones across the shared face. Children add in box order, as the box-array form did.
/// Also `a`'s [`Maxima`], from the same reading of its rows (the finest level's rows are made
/// on demand: a pass of their own cost ~1 % of `full`'s instructions).
fn coarsen(a: &impl Stencils) -> (Operator, Vec<u32>, Maxima) {
    let [nx, ny, nz] = a.dims();
    let cd = [nx.div_ceil(2), ny.div_ceil(2), nz.div_ceil(2)];
    let key = |ijk: [usize; 3]| (ijk[0] / 2 + cd[0] * (ijk[1] / 2 + cd[1] * (ijk[2] / 2))) as u32;
    // One task per coarse z plane: its aggregates' children are the fine unknowns of two
    // fine planes (contiguous, as the unknowns are in box order). Aggregates are numbered
    // in box order through a rank per coarse cell (NONE: no child), and each adds its
    // children in the fine order a serial pass would, so nothing depends on the thread count.
    let plane = cd[0] * cd[1];
    let fine_planes: Vec<std::ops::Range<usize>> = (0..cd[2])
        .map(|k| first_at(a, 2 * k * nx * ny)..first_at(a, (2 * k + 2) * nx * ny))
        .collect();
    let mut rank = vec![NONE; plane * cd[2]];
    let counts: Vec<u32> = rank
        .par_chunks_mut(plane)
        .zip(&fine_planes)
        .enumerate()
        .map(|(k, (r, fine))| {
            for u in fine.clone() {
                r[key(a.ijk(u)) as usize - k * plane] = 0;
            }
            let mut c = 0;
            for v in r.iter_mut().filter(|v| **v == 0) {
                *v = c;
                c += 1;
            }
            c
        })
        .collect();
    let offsets: Vec<u32> = counts
        .iter()
        .scan(0, |s, c| {
            *s += c;
            Some(*s - c)
        })
        .collect();
    rank.par_chunks_mut(plane).zip(&offsets).for_each(|(r, o)| {
        r.iter_mut().filter(|v| **v != NONE).for_each(|v| *v += o);
    });
    let parent: Vec<u32> = (0..a.len()).into_par_iter().map(|u| rank[key(a.ijk(u)) as usize]).collect();
    let mut nodes: Vec<Node> = (0..rank.len() as u32)
        .into_par_iter()
        .filter(|c| rank[*c as usize] != NONE)
        .map(Node::at)
        .collect();
    drop(rank);
    let mut planes = Vec::with_capacity(cd[2]);
    let (mut rest, mut base) = (&mut nodes[..], 0);
    for (fine, here) in fine_planes.into_iter().zip(counts) {
        let (mine, more) = rest.split_at_mut(here as usize);
        planes.push((fine, base, mine));
        (rest, base) = (more, base + here as usize);
    }
    let maxima = planes
        .into_par_iter()
        .map(|(fine, base, mine)| {
            let mut m = Maxima::default();
            for u in fine {
                let st = a.stencil(u);
                m = m.max(Maxima::of(&st));
                let ijk = a.ijk(u);
                let p = &mut mine[parent[u] as usize - base];
                p.diag += st.diag;
                for (ax, at) in ijk.iter().enumerate() {
                    let (v, up) = (st.nbr[2 * ax + 1], st.off[2 * ax + 1]);
                    if v == NONE {
                        continue;
                    }
                    if at % 2 == 0 {
                        p.diag += 2.0 * up;
                    } else {
                        p.up[ax] += up;
                        p.up_nbr[ax] = parent[v as usize];
                    }
                }
            }
            m
        })
        .reduce(Maxima::default, Maxima::max);
    (Operator { dims: cd, nodes }, parent, maxima)
}

/// The largest values of an operator's rows, from which a level's codes take their scales
/// ([`Scaled16::exponent_for`]): coupling magnitude, diagonal, row sum.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Maxima {
    cpl: f64,
    diag: f64,
    sum: f64,
}

impl Maxima {
    /// Those of one row.
    fn of(st: &Stencil) -> Maxima {
        let cpl = st
            .off
            .iter()
            .zip(st.nbr)
            .filter(|(_, v)| *v != NONE)
            .fold(0f64, |m, (c, _)| m.max(-c));
        Maxima {
            cpl,
            diag: st.diag,
            sum: row_sum(st),
        }
    }

    /// Each the larger of the two (the same in any order: thread-count independent).
    fn max(self, o: Maxima) -> Maxima {
        Maxima {
            cpl: self.cpl.max(o.cpl),
            diag: self.diag.max(o.diag),
            sum: self.sum.max(o.sum),
        }
    }

    /// Those of all of `a`'s rows (a pass over them: for a level not read by [`coarsen`]).
    fn all(a: &impl Stencils) -> Maxima {
        (0..a.len())
            .into_par_iter()
            .map(|u| Maxima::of(&a.stencil(u)))
            .reduce(Maxima::default, Maxima::max)
    }
}

/// The scalar of the multigrid levels ([`Level`]) and of the CG vectors.
trait Real: Copy + Send + Sync {
    fn of(v: f64) -> Self;
    fn get(self) -> f64;
}

impl Real for f32 {
    #[inline]
    fn of(v: f64) -> f32 {
        v as f32
    }
    #[inline]
    fn get(self) -> f64 {
        self as f64
    }
}

impl Real for f64 {
    #[inline]
    fn of(v: f64) -> f64 {
        v
    }
    #[inline]
    fn get(self) -> f64 {
        self
    }
}

/// The multigrid's scalar: the cycle is only a preconditioner, and single precision halves its
/// memory traffic (iterations unchanged at tolerance 1e-6). Also CG's residual, A p and search
/// direction: the iterate stays f64, and a true residual in f64 decides the stop (restarting CG
/// when the recursion's rounding left it above the tolerance; 1e-12 is still reached).
type Mg = f32;

/// One row of a [`Level`]: its couplings to its +x, +y, +z neighbours, its sum (or diagonal)
/// and where the entries of the six neighbours (−x, +x, −y, +y, −z, +z) lie (20 B with `Z` =
/// u16, 24 B with u32; stored as [`Runs`]: its codes per entry, the rest per run). The couplings and the sum are 16-bit codes ([`Scaled16`],
/// ≤ 2⁻¹² relative, under a power-of-two scale per level and field); in f32 beside 24 B rows
/// they took 28 B per unknown. The −a couplings are read from the −a neighbours' rows (a
/// separate array of couplings, 16 + 12 B, took as many instructions as 40 B rows with all six,
/// but `full`'s peak at 200×160×120 came out 4 MB above the rows', through the allocator).
///
/// The entries are the other colour's, counted from its first (a colour's pass indexes the
/// other's values and rows with them as they are: subtracting an offset cost ~7 % more of the
/// solve's instructions), and coded from `base`, the other colour's first entry after this
/// unknown in box order: the ±x neighbours (cells c ± 1) are the entries just before and at
/// `base`, the ±y and ±z ones lie `dy` and `dz` entries before or after it (the other colour's
/// unknowns between the cells, fewer than half a box row or plane). A missing neighbour (or one
/// coupled by 0) has coupling 0: a missing +a one reads `base` (distance 0), its own coupling
/// being 0 (any entry of the other colour would do, its value finite); a missing −a one reads
/// the other colour's pad, whose value and couplings are 0, as its coupling is the neighbour's
/// (the [`NO_MINUS_X`] flag, distance 0 for −y, and for −z [`Dz::missing_minus`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Row<Z> {
    /// The other colour's first entry after this unknown (its unknowns before this one), and
    /// the [`NO_MINUS_X`] flag.
    base: u32,
    /// Couplings to the +x, +y, +z neighbours, negated (they are ≤ 0) and coded at the level's
    /// [`Level::cpl_scale`] (0 to a missing one, and on the pads): each face's coupling is
    /// stored once, and a row's −a coupling is its −a neighbour's +a one.
    up: [Scaled16; 3],
    /// The row's sum (the finest level: [`Level::row_sums`]) or its diagonal, coded at the
    /// level's [`Level::own_scale`] (0 on the pads).
    own: Scaled16,
    /// Entries from `base` back to the −y neighbour and on to the +y one.
    dy: [u16; 2],
    /// Entries from `base` back to the −z neighbour and on to the +z one.
    dz: [Z; 2],
}

/// The type of a [`Row`]'s ±z distances: u16 where they all fit (fewer than 2^16 of the other
/// colour's entries between any cell and its ±z neighbours: every level of the clouds measured,
/// up to 400×320×240), else u32. Each level picks once ([`Rows`]); the passes are compiled per
/// type ([`with_rows`]).
trait Dz: Copy + Default + PartialEq + Send + Sync + std::fmt::Debug + Into<u32> {
    /// How a missing −z neighbour is coded, `base.wrapping_sub(pad)` in u32 (read back by the
    /// same subtraction as a present one: no select), 0 in u16 (the pad is too far, and a
    /// present −z neighbour lies at least 1 entry before `base`).
    fn missing_minus(base: u32, pad: u32) -> Self;

    /// Distance `d` in this type, if it fits.
    fn of(d: u32) -> Option<Self>;

    /// The −z neighbour's entry, `d` entries before `base` (`pad` when missing).
    fn minus(base: u32, d: Self, pad: u32) -> u32;
}

impl Dz for u32 {
    fn missing_minus(base: u32, pad: u32) -> u32 {
        base.wrapping_sub(pad)
    }

    fn of(d: u32) -> Option<u32> {
        Some(d)
    }

    #[inline(always)]
    fn minus(base: u32, d: u32, _: u32) -> u32 {
        base.wrapping_sub(d)
    }
}

impl Dz for u16 {
    fn missing_minus(_: u32, _: u32) -> u16 {
        0
    }

    fn of(d: u32) -> Option<u16> {
        u16::try_from(d).ok()
    }

    #[inline(always)]
    fn minus(base: u32, d: u16, pad: u32) -> u32 {
        if d == 0 {
            pad
        } else {
            base.wrapping_sub(u32::from(d))
        }
    }
}

/// [`Row::base`] flag: no −x neighbour (it reads the other colour's pad, not the entry before
/// `base`).
const NO_MINUS_X: u32 = 1 << 31;

/// Widest box (cells along x) the solver takes: a row's ±y distances, at most half a box row of
/// the other colour's entries, are stored in a u16. The command line refuses a wider cloud
/// before any work (`medium.downsample` is the fix); a library caller's build panics.
pub const MAX_BOX_ROW_CELLS: usize = 2 * u16::MAX as usize;

impl<Z: Dz> Row<Z> {
    /// The row of coded couplings `up` and sum (or diagonal) `own` and of the neighbours' entries
    /// `nbr` (`pad`, the other colour's
    /// pad, for a missing neighbour), `base` the other colour's first entry after the unknown
    /// (all counted from the other colour's first entry); `None` if a ±z distance does not fit
    /// in `Z`.
    fn encode(up: [Scaled16; 3], own: Scaled16, nbr: [u32; 6], base: u32, pad: u32) -> Option<Row<Z>> {
        assert!(base < NO_MINUS_X, "more than 2^31 entries on one level");
        let missing = |q: usize| nbr[q] == pad;
        debug_assert!(missing(0) || nbr[0] + 1 == base, "−x neighbour just before base");
        debug_assert!(missing(1) || nbr[1] == base, "+x neighbour at base");
        // Entries between base and neighbour q (before base for the − ones, at least 1); 0:
        // base itself, or the pad for −y (−z: [`Dz::missing_minus`]).
        let dist = |q: usize| match (missing(q), q) {
            (true, _) => 0,
            (false, 0 | 2 | 4) => base - nbr[q],
            (false, _) => nbr[q] - base,
        };
        let dy = |q: usize| u16::try_from(dist(q)).expect("a box row of at most MAX_BOX_ROW_CELLS cells");
        let minus_z = if missing(4) { Z::missing_minus(base, pad) } else { Z::of(dist(4))? };
        Some(Row {
            base: base | if missing(0) { NO_MINUS_X } else { 0 },
            up,
            own,
            dy: [dy(2), dy(3)],
            dz: [minus_z, Z::of(dist(5))?],
        })
    }

    /// Its codes, stored per entry ([`Runs`]).
    fn codes(&self) -> Codes {
        Codes {
            up: self.up,
            own: self.own,
        }
    }

    /// Its neighbours' coding, stored per run ([`Runs`]).
    fn link(&self) -> Link<Z> {
        Link {
            base: self.base,
            dy: self.dy,
            dz: self.dz,
        }
    }
}

/// A [`Row`]'s codes: its +x, +y, +z couplings and its sum or diagonal (8 B, stored per entry:
/// the other colour's rows read the −a couplings from them by entry).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Codes {
    up: [Scaled16; 3],
    own: Scaled16,
}

/// A [`Row`]'s neighbours' coding: [`Row::base`] with the [`NO_MINUS_X`] flag, ±y and ±z
/// distances.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Link<Z> {
    base: u32,
    dy: [u16; 2],
    dz: [Z; 2],
}

/// A maximal range of a level's consecutive entries whose rows' [`Link`]s are one: `link` at
/// its first entry `start`, its `base` one more at each entry after (same distances and flag).
/// Along a box row inside the cloud a colour's unknowns are every second cell, and the other
/// colour's unknown between two of them advances `base` by one: the procedural cloud's finest
/// level has ~12 unknowns per run (200×160×120: 30 387 runs for 356 296 unknowns). (A u32 row
/// with no −z neighbour codes that distance from `base`, [`Dz::missing_minus`], so it ends a
/// run: such rows are wide only where a plane is too large for u16 distances.)
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Run<Z> {
    start: u32,
    link: Link<Z>,
}

impl<Z: Dz> Run<Z> {
    /// The link of entry `e` of the run (at or after `start`).
    #[inline(always)]
    fn link_at(&self, e: usize) -> Link<Z> {
        // `base` < 2^31 at every entry (Row::encode): no carry into the flag.
        Link {
            base: self.link.base + (e as u32 - self.start),
            ..self.link
        }
    }

    /// The row of entry `e` of the run, whose codes are `c`.
    #[inline(always)]
    fn at<'a>(&'a self, e: usize, c: &'a Codes) -> RowAt<'a, Z> {
        RowAt {
            base: self.link_at(e).base,
            link: &self.link,
            codes: c,
        }
    }
}

/// Entry e's row as the passes read it ([`Run::at`]): its `base` with the [`NO_MINUS_X`] flag,
/// its run's link (for the distances) and its codes, read where they are stored. Instructions of
/// `full`'s diffusion solve at 100×80×60 (one thread): whole rows per entry 195 M, this 224 M,
/// a [`Row`] rebuilt by value 228 M, the neighbours decoded once per run and advanced per
/// entry 252 M (the coarse levels' runs are short).
#[derive(Clone, Copy, Debug, PartialEq)]
struct RowAt<'a, Z> {
    base: u32,
    link: &'a Link<Z>,
    codes: &'a Codes,
}

impl<Z: Dz> RowAt<'_, Z> {
    /// The neighbours' entries (−x, +x, −y, +y, −z, +z), `pad` the other colour's pad: a missing
    /// −a one's is `pad`, a missing +a one's `base`.
    #[inline(always)]
    fn neighbours(&self, pad: u32) -> [u32; 6] {
        let base = self.base();
        let minus_y = base.wrapping_sub(u32::from(self.link.dy[0]));
        [
            if self.base & NO_MINUS_X == 0 { base.wrapping_sub(1) } else { pad },
            base,
            if self.link.dy[0] == 0 { pad } else { minus_y },
            base + u32::from(self.link.dy[1]),
            Z::minus(base, self.link.dz[0], pad),
            base + self.link.dz[1].into(),
        ]
    }

    /// The other colour's first entry after the unknown.
    #[inline(always)]
    fn base(&self) -> u32 {
        self.base & !NO_MINUS_X
    }
}

/// A level's rows: their codes per entry (8 B) and their links per [`Run`] (16 B with u16 ±z
/// distances, 20 B with u32 ones), ~9.4 B per unknown on the procedural cloud's finest level
/// against 20 B for whole rows per entry (−3.8 MB at 200×160×120). The passes rebuild each row
/// from its run and its codes, walking the runs in order ([`Coded::each_row`]), so their inner
/// loops read rows as before; the other colour's couplings are read from the codes by entry.
#[derive(Clone, Debug)]
struct Runs<Z> {
    codes: Vec<Codes>,
    /// In order of `start`, the first at entry 0.
    runs: Vec<Run<Z>>,
}

impl<Z: Dz> Runs<Z> {
    /// Appends entry `e`'s `link` (entries in order): to the last run if it continues it, else
    /// as a new run.
    fn push(runs: &mut Vec<Run<Z>>, e: usize, link: Link<Z>) {
        match runs.last() {
            Some(r) if r.link_at(e) == link => {}
            _ => runs.push(Run { start: e as u32, link }),
        }
    }
}

/// A level's rows, their ±z distances in u16 where all fit, else in u32 ([`Dz`]). The narrow
/// rows (when stored whole per entry, 24 B against 28 B) lowered `full`'s peak heap at 200×160×120 by 1.6 MB (the
/// solves', one thread) at the solve's instructions and speed (a −z select in u16, within 0.3 %
/// of the wide rows').
#[derive(Clone, Debug)]
enum Rows {
    Narrow(Runs<u16>),
    Wide(Runs<u32>),
}

const _: () = assert!(std::mem::size_of::<Codes>() == 8 && std::mem::size_of::<Run<u16>>() == 16 && std::mem::size_of::<Run<u32>>() == 20);

impl Rows {
    fn len(&self) -> usize {
        match self {
            Rows::Narrow(r) => r.codes.len(),
            Rows::Wide(r) => r.codes.len(),
        }
    }

    /// Bytes held.
    fn bytes(&self) -> usize {
        let codes = self.len() * std::mem::size_of::<Codes>();
        codes
            + match self {
                Rows::Narrow(r) => r.runs.len() * std::mem::size_of::<Run<u16>>(),
                Rows::Wide(r) => r.runs.len() * std::mem::size_of::<Run<u32>>(),
            }
    }
}

/// A [`Level`]'s rows with their type known ([`with_rows`]), their scales and its number of red
/// entries: what the passes read.
struct Coded<'a, Z> {
    red: usize,
    codes: &'a [Codes],
    runs: &'a [Run<Z>],
    /// The scales of a row's own codes (+x, +y, +z couplings and [`Row::own`]:
    /// [`Level::cpl_scale`] ×3, [`Level::own_scale`]) and of its −a neighbours' couplings (and
    /// a zero lane), as [`Scaled16::decode4`] takes them.
    mine: [f32; 4],
    theirs: [f32; 4],
}

/// Runs `$pass` with `$c`, the [`Coded`] rows of `$level`: one copy of the pass per row type,
/// so its inner loops do not branch on it.
macro_rules! with_rows {
    ($level:expr, |$c:ident| $pass:expr) => {{
        let level: &Level = $level;
        match &level.rows {
            Rows::Narrow(rows) => {
                let $c = Coded::of(level, rows);
                $pass
            }
            Rows::Wide(rows) => {
                let $c = Coded::of(level, rows);
                $pass
            }
        }
    }};
}

/// One level's operator on its unknowns only.
///
/// Entries `0..red` are the unknowns of colour 0 ((i + j + k) even) in box order, entry `red` a
/// pad, then the unknowns of colour 1 and a last pad. A level's vectors have one value per entry
/// and right-hand side (`[T; K]`, the K systems that share the operator solved together, so the
/// rows are read once for all of them); the pads hold 0 and stand in for missing neighbours (a
/// coupling of 0 to the other colour's pad), so the rows need no branches and a colour's pass
/// reads only the other colour.
///
/// No level is scaled to unit diagonal (that took, on the finest level, a scale D^-½, a fix of
/// its rounding and the prolongation weights D^½: 10 B per unknown). Gauss–Seidel does not depend
/// on a diagonal scaling S, and PCG on S A S with the preconditioner S M S has the iterates of PCG
/// on A with M, so the cycle works on the unknowns as assembled; its coarse space, piecewise
/// constant in them, holds the errors the smoother leaves, which are smooth in them. (Piecewise
/// constant in the scaled unknowns it needed 22/26/29 iterations at 50×40×30/100×80×60/
/// 200×160×120 instead of 9/8/6.)
#[derive(Clone, Debug)]
struct Level {
    red: usize,
    /// Each row's [`Row::own`] holds its sum, its diagonal plus its six couplings, computed in
    /// f64 from the assembled row and rounded once (the finest level), not its diagonal; the
    /// diagonal is that sum less the row's stored couplings ([`less_couplings`]). CG's operator
    /// ([`Coded::apply_row`]) so keeps every assembled row sum to its own rounding: the
    /// absorption and the boundary's leakage (A·1 for a uniform fluence), tiny against the
    /// couplings in a thick cloud, which a rounded diagonal would move by far more (in f32 by up
    /// to ~10⁻⁴ of themselves: the 100×80×60 cloud's `diffusion` image moved by 2.9·10⁻⁶, block
    /// mean relative error, against 2·10⁻⁹ with f32 sums).
    row_sums: bool,
    rows: Rows,
    /// The scales of the rows' codes ([`Scaled16`]): −2^k for the couplings (stored negated:
    /// they are ≤ 0), 2^k for the sums or diagonals, each k from the level's largest value
    /// ([`Scaled16::exponent_for`]). Values below ~2⁻²⁹ of the largest read 0.
    cpl_scale: f32,
    own_scale: f32,
    /// The power of two 2^-unit that the whole hierarchy's operator is stored scaled by (the
    /// finest level's, [`unit_of`]): the solve scales the right-hand sides alike.
    unit: i32,
    /// Entry of the next coarser level holding each red entry (only the red ones are
    /// prolonged: [`Level::prolong_red`]); empty on the coarsest level.
    parent: Vec<u32>,
    /// Per z plane of the level's box, and one past the last: the first red entry of the finer
    /// level aggregated into it (those of two finer planes, contiguous, as the red entries are
    /// in box order) and its first red and black entries (each colour in box order). A plane's
    /// entries have their red children in its range and no others, so the restriction is one
    /// task per plane, each adding its children in their order ([`Level::restrict_residual`]).
    /// Empty on the finest level.
    planes: Vec<[u32; 3]>,
}

/// A row's diagonal from its sum `sum` and its couplings `c` (−x, +x, −y, +y, −z, +z):
/// sum − Σ c (in the precision of `T`).
#[inline(always)]
fn less_couplings<T: Copy + std::ops::Add<Output = T> + std::ops::Sub<Output = T>>(sum: T, c: [T; 6]) -> T {
    sum - ((c[0] + c[1]) + (c[2] + c[3]) + (c[4] + c[5]))
}

/// The row's sum: its diagonal plus its couplings to its neighbours, in f64 as assembled.
fn row_sum(st: &Stencil) -> f64 {
    st.off
        .iter()
        .zip(st.nbr)
        .filter(|(_, v)| *v != NONE)
        .fold(st.diag, |s, (o, _)| s + o)
}

/// The other colour's entries `off..off + x.len()` (its pad last) as the rows of one colour read
/// them: their values and codes (for their +x, +y, +z couplings), and the couplings' scale.
struct OtherColour<'a, const K: usize> {
    x: &'a [[Mg; K]],
    codes: &'a [Codes],
    /// [`Coded::mine`], [`Coded::theirs`].
    mine: [f32; 4],
    theirs: [f32; 4],
}

impl<'a, const K: usize> OtherColour<'a, K> {
    /// The other colour of the level of rows `level` whose values, from entry `off` on, are `x`.
    fn of<Z>(level: &Coded<'a, Z>, x: &'a [[Mg; K]], off: usize) -> Self {
        // Sliced to the length of `x`: one bounds check serves both reads of a neighbour.
        OtherColour {
            x,
            codes: &level.codes[off..off + x.len()],
            mine: level.mine,
            theirs: level.theirs,
        }
    }

    /// Σ_q cpl_q · x\[nbr_q\] per system, the off-diagonal part of `row` (of the other colour),
    /// the couplings cpl_q (−x, +x, −y, +y, −z, +z; they give the finest level's diagonal) and
    /// the row's decoded [`Row::own`].
    /// (Always inlined: it is the smoother's inner loop, and an outlined call costs ~10 % of the
    /// solve's instructions.)
    #[inline(always)]
    fn couple<Z: Dz>(&self, row: &RowAt<Z>) -> ([Mg; K], [Mg; 6], Mg) {
        let [i0, i1, i2, i3, i4, i5] = row.neighbours((self.x.len() - 1) as u32).map(|v| v as usize);
        let (up, codes) = (&row.codes.up, self.codes);
        // Four codes at a time (one vector shift and multiply where the target has them).
        let mine = Scaled16::decode4([up[0], up[1], up[2], row.codes.own], self.mine);
        let theirs = Scaled16::decode4([codes[i0].up[0], codes[i2].up[1], codes[i4].up[2], Scaled16::ZERO], self.theirs);
        let c = [theirs[0], mine[0], theirs[1], mine[1], theirs[2], mine[2]];
        let (n0, n1, n2, n3, n4, n5) = (&self.x[i0], &self.x[i1], &self.x[i2], &self.x[i3], &self.x[i4], &self.x[i5]);
        let mut s = [0.0; K];
        for k in 0..K {
            s[k] = (c[0] * n0[k] + c[1] * n1[k]) + (c[2] * n2[k] + c[3] * n3[k]) + (c[4] * n4[k] + c[5] * n5[k]);
        }
        (s, c, mine[3])
    }
}

/// Runs `$pass` with `$d`, the rule giving a row's diagonal on `$level` from the row's decoded
/// [`Row::own`] and its couplings: one copy of the pass per rule, so its
/// inner loop does not branch on it.
macro_rules! with_diagonal {
    ($level:expr, |$d:ident| $pass:expr) => {{
        if $level.row_sums {
            let $d = |own: Mg, c: &[Mg; 6]| less_couplings(own, *c);
            $pass
        } else {
            let $d = |own: Mg, _: &[Mg; 6]| own;
            $pass
        }
    }};
}

/// 2^k in f64 (k in −1022 … 1023).
fn pow2(k: i32) -> f64 {
    f64::from_bits(((1023 + k) as u64) << 52)
}

/// The power of two 2^unit a hierarchy's operator is divided by, from the largest coupling
/// magnitude or row sum `max` of its finest level (0 for an empty one). Its values are then below
/// 2⁻³ and its diagonals below 1 (each at most 7 of them: the sum plus six coupling magnitudes),
/// and a coarse level's values below the finest level's unknowns (< 2³¹: a Galerkin diagonal is
/// at most the sum of its aggregate's finer diagonals, a coupling at most a diagonal), so every
/// level's scale 2^k is a normal f32 ([`Scaled16::exponent_for`]) for any voxel size or density.
fn unit_of(max: f64) -> i32 {
    if !(max > 0.0 && max.is_finite()) {
        return 0;
    }
    (((max.to_bits() >> 52) & 0x7ff) as i32 - 1023 + 4).clamp(-1000, 1000)
}

/// One row as [`Level::from_stencils`] makes it, before it is coded ([`Row::encode`]): its +a
/// couplings (≤ 0) and its sum (or diagonal), in f64 as assembled, its neighbours' entries, its
/// `base` and the other colour's pad.
type Plain = ([f64; 3], f64, [u32; 6], u32, u32);

/// The row `plain(e, unk[e])` of entry e with ±z distances in `Z`, its values divided by
/// 2^`unit` and coded at scale exponents `k` (couplings, sums or diagonals); `None` if a
/// distance does not fit.
fn code_row<Z: Dz>(e: usize, unk: &[u32], plain: &impl Fn(usize, u32) -> Plain, unit: i32, k: [i32; 2]) -> Option<Row<Z>> {
    let to_unit = pow2(-unit);
    let (up, own, nbr, base, pad) = plain(e, unk[e]);
    debug_assert!(up.iter().all(|c| *c <= 0.0), "an M-matrix's couplings are ≤ 0");
    let up = up.map(|c| Scaled16::encode(-c * to_unit, k[0]));
    let own = Scaled16::encode(own * to_unit, k[1]);
    Row::encode(up, own, nbr, base, pad)
}

/// The rows of every entry ([`code_row`]) as [`Runs`]; `None` if a distance does not fit. The
/// codes are written in place and each chunk's runs found by one task, joined in order (a
/// chunk's first run merged into the one before when it continues it): the same runs at any
/// thread count, and the whole rows never held.
fn code_rows<Z: Dz>(unk: &[u32], plain: &(impl Fn(usize, u32) -> Plain + Sync), unit: i32, k: [i32; 2]) -> Option<Runs<Z>> {
    let fits = AtomicBool::new(true);
    let mut codes = vec![Codes::default(); unk.len()];
    let parts: Vec<Vec<Run<Z>>> = codes
        .par_chunks_mut(CHUNK)
        .enumerate()
        .map(|(ci, cs)| {
            let mut runs = Vec::new();
            for (t, c) in cs.iter_mut().enumerate() {
                let e = ci * CHUNK + t;
                let row = code_row(e, unk, plain, unit, k).unwrap_or_else(|| {
                    fits.store(false, Ordering::Relaxed);
                    Row::default()
                });
                *c = row.codes();
                Runs::push(&mut runs, e, row.link());
            }
            runs
        })
        .collect();
    let mut runs = Vec::with_capacity(parts.iter().map(Vec::len).sum());
    for r in parts.into_iter().flatten() {
        Runs::push(&mut runs, r.start as usize, r.link);
    }
    runs.shrink_to_fit();
    fits.into_inner().then_some(Runs { codes, runs })
}

impl<'a, Z: Dz> Coded<'a, Z> {
    /// `level`'s passes' view of its `runs` (the level's own [`Rows`] variant).
    #[inline(always)]
    fn of(level: &'a Level, runs: &'a Runs<Z>) -> Coded<'a, Z> {
        Coded {
            red: level.red,
            codes: &runs.codes,
            runs: &runs.runs,
            mine: level.scales(),
            theirs: [level.cpl_scale; 4],
        }
    }

    /// Entries, pads included.
    fn len(&self) -> usize {
        self.codes.len()
    }

    /// The run holding entry `e`.
    fn run_of(&self, e: usize) -> usize {
        self.runs.partition_point(|r| r.start as usize <= e) - 1
    }

    /// Entry e's row, rebuilt from its run (found by a binary search: the passes walk the runs,
    /// [`Coded::each_row`]).
    fn row(&self, e: usize) -> RowAt<'a, Z> {
        self.runs[self.run_of(e)].at(e, &self.codes[e])
    }

    /// `f(e, row, o)` for each entry e from `first` on in order, its row rebuilt from its run
    /// and its codes, and `o` its value of `out` (one per entry, from `first`): the first run
    /// found by a binary search, then each in turn.
    #[inline(always)]
    fn each_row_into<T>(&self, first: usize, out: &mut [T], mut f: impl FnMut(usize, RowAt<'a, Z>, &mut T)) {
        if out.is_empty() {
            return;
        }
        let (runs, codes) = (self.runs, &self.codes[first..first + out.len()]);
        let mut i = self.run_of(first);
        let mut t = 0;
        while t < out.len() {
            let run = &runs[i];
            let end = runs.get(i + 1).map_or(out.len(), |r| (r.start as usize - first).min(out.len()));
            for ((c, o), e) in codes[t..end].iter().zip(&mut out[t..end]).zip(first + t..) {
                f(e, run.at(e, c), o);
            }
            (t, i) = (end, i + 1);
        }
    }

    /// `f(e, row)` for each entry e of `range` in order: [`Coded::each_row_into`].
    #[inline(always)]
    fn each_row(&self, range: std::ops::Range<usize>, mut f: impl FnMut(usize, RowAt<'a, Z>)) {
        let mut none = vec![(); range.len()];
        self.each_row_into(range.start, &mut none, |e, row, _| f(e, row));
    }

    /// The [`Operator`]'s unknown at entry `e` ([`PAD`] on the pads), whose row is `row`: the
    /// unknowns of its colour before it plus those of the other colour (its row's `base`).
    #[inline(always)]
    fn unknown_of(&self, e: usize, row: &RowAt<Z>) -> u32 {
        let black = self.red + 1;
        match e {
            _ if e == self.red || e + 1 == self.len() => PAD,
            _ if e < self.red => (e + row.base() as usize) as u32,
            _ => (e - black + row.base() as usize) as u32,
        }
    }

    /// The [`Operator`]'s unknown at entry `e`: [`Coded::unknown_of`].
    fn unknown(&self, e: usize) -> u32 {
        self.unknown_of(e, &self.row(e))
    }

    /// Entry e's neighbours' entries (−x, +x, −y, +y, −z, +z; [`Row::neighbours`] of its row
    /// `row`, counted from the level's first entry).
    #[inline(always)]
    fn neighbours(&self, e: usize, row: &RowAt<Z>) -> [u32; 6] {
        // The other colour's first entry and its pad, counted from it.
        let (other, pad) = if e <= self.red {
            (self.red + 1, self.len() - self.red - 2)
        } else {
            (0, self.red)
        };
        row.neighbours(pad as u32).map(|v| v + other as u32)
    }

    /// The couplings of row `row` to its neighbours `nbr` (its [`Coded::neighbours`]; −x, +x,
    /// −y, +y, −z, +z; the −a ones are the −a neighbours' +a ones) and its decoded [`Row::own`].
    #[inline(always)]
    fn couplings(&self, row: &RowAt<Z>, nbr: &[u32; 6]) -> ([Mg; 6], Mg) {
        let codes = self.codes;
        let mine = Scaled16::decode4([row.codes.up[0], row.codes.up[1], row.codes.up[2], row.codes.own], self.mine);
        let theirs = Scaled16::decode4(
            [
                codes[nbr[0] as usize].up[0],
                codes[nbr[2] as usize].up[1],
                codes[nbr[4] as usize].up[2],
                Scaled16::ZERO,
            ],
            self.theirs,
        );
        ([theirs[0], mine[0], theirs[1], mine[1], theirs[2], mine[2]], mine[3])
    }

    /// The residual b − A x at red entry e of row `row` (of `x` split at the black entries into
    /// `xr` and the black colour `xb`), `diag` the level's diagonal rule ([`with_diagonal`]).
    #[inline(always)]
    fn residual_red<const K: usize>(
        e: usize,
        row: &RowAt<Z>,
        xr: &[[Mg; K]],
        xb: &OtherColour<K>,
        b: &[[Mg; K]],
        diag: &impl Fn(Mg, &[Mg; 6]) -> Mg,
    ) -> [Mg; K] {
        let (s, c, own) = xb.couple(row);
        let d = diag(own, &c);
        std::array::from_fn(|k| b[e][k] - (d * xr[e][k] + s[k]))
    }

    /// Entry e of the finest level (which holds its rows' sums), of row `row`: its neighbours'
    /// entries, its couplings to them (widened to f64) and its diagonal, the row's sum less
    /// those couplings in f64 (0 on the pads).
    #[inline(always)]
    fn finest_row(&self, e: usize, row: &RowAt<Z>) -> ([u32; 6], [f64; 6], f64) {
        let nbr = self.neighbours(e, row);
        let (c, own) = self.couplings(row, &nbr);
        let c = c.map(f64::from);
        (nbr, c, less_couplings(f64::from(own), c))
    }

    /// Entry e of A x per system with the finest level's operator, summed in f64, and the
    /// row's diagonal: the rows' coded couplings, and the diagonal that gives each row its
    /// assembled sum (to the rounding of the coded sum: [`Level::row_sums`]). So CG solves the
    /// assembled operator (divided by 2^unit) up to a ≤ 2⁻¹² relative change of each coupling,
    /// with every row sum kept to ≤ 2⁻¹² of itself (the absorption and the boundary's leakage;
    /// one below ~2⁻²⁹ of the level's largest reads 0); the f64 couplings took 24 B per unknown,
    /// f32 ones and an f32 sum 16 B. 0 on the pads.
    #[inline(always)]
    fn apply_row<X: Real, const K: usize>(&self, e: usize, row: &RowAt<Z>, x: &[[X; K]]) -> ([f64; K], f64) {
        let (nbr, c, d) = self.finest_row(e, row);
        let v = |q: usize, k: usize| c[q] * x[nbr[q] as usize][k].get();
        // A plain loop, not `array::from_fn`: the closure was not always inlined here (+0.35 G
        // instructions in the solve, depending on how the crate was split).
        let mut out = [0.0; K];
        for (k, o) in out.iter_mut().enumerate() {
            let s = (v(0, k) + v(1, k)) + (v(2, k) + v(3, k)) + (v(4, k) + v(5, k));
            *o = d * x[e][k].get() + s;
        }
        (out, d)
    }
}

impl Level {
    /// The level of operator `a` and each unknown's entry; with `row_sums` it holds the rows'
    /// sums, not their diagonals (the finest level: [`Level::row_sums`]). Its values are divided
    /// by 2^`unit` (by default [`unit_of`] its own largest value: the finest level's), and
    /// coded at scales from `a`'s [`Maxima`] `m`. Its rows' ±z distances are u16 where every one
    /// fits, else u32 ([`Rows`]; always u32 with `narrow` false, for the tests).
    fn from_stencils(a: &impl Stencils, row_sums: bool, narrow: bool, unit: Option<i32>, m: Maxima) -> (Level, Vec<u32>) {
        let n = a.len();
        let colour = |u: usize| a.ijk(u).iter().sum::<usize>() % 2;
        let red = (0..n).filter(|u| colour(*u) == 0).count();
        // Each unknown's entry, and (while the rows are built) each entry's unknown.
        let mut entry = vec![0u32; n];
        let mut unk = vec![PAD; n + 2];
        let mut next = [0, red + 1];
        for (u, e) in entry.iter_mut().enumerate() {
            let c = colour(u);
            *e = next[c] as u32;
            unk[next[c]] = u as u32;
            next[c] += 1;
        }
        // The other colour's unknowns before unknown u (its row's `base`): u − e for a red one,
        // u − (e − red − 1) for a black one.
        let base = |u: usize| match entry[u] as usize {
            e if e < red => (u - e) as u32,
            e => (u + red + 1 - e) as u32,
        };
        let pads = [(n + 1) as u32, red as u32];
        // The rows, and their diagonals or sums, from one stencil each.
        let plain = |e: usize, u: u32| -> Plain {
            // The other colour's first entry, from which the row counts its entries.
            let other = [red + 1, 0][usize::from(e > red)] as u32;
            let pad = pads[usize::from(e > red)] - other;
            if u == PAD {
                return ([0.0; 3], 0.0, [pad; 6], pad, pad);
            }
            let st = a.stencil(u as usize);
            // The +a couplings (each −a one is read from the −a neighbour's row).
            let up = std::array::from_fn(|ax| if st.nbr[2 * ax + 1] != NONE { st.off[2 * ax + 1] } else { 0.0 });
            let mut nbr = [pad; 6];
            for q in 0..6 {
                if st.nbr[q] != NONE && st.off[q] != 0.0 {
                    nbr[q] = entry[st.nbr[q] as usize] - other;
                }
            }
            let own = if row_sums { row_sum(&st) } else { st.diag };
            (up, own, nbr, base(u as usize), pad)
        };
        // The codes' scales from the largest values.
        let max_own = if row_sums { m.sum } else { m.diag };
        let unit = unit.unwrap_or_else(|| unit_of(m.cpl.max(max_own)));
        let k = [m.cpl, max_own].map(|v| Scaled16::exponent_for(v * pow2(-unit)));
        // The rows in u16 first; only where a distance does not fit, all again in u32 (the
        // stencils made again, but no wide rows held meanwhile).
        let rows = match narrow.then(|| code_rows(&unk, &plain, unit, k)).flatten() {
            Some(rows) => Rows::Narrow(rows),
            None => Rows::Wide(code_rows(&unk, &plain, unit, k).expect("u32 distances always fit")),
        };
        let level = Level {
            red,
            row_sums,
            rows,
            cpl_scale: -Scaled16::scale(k[0]),
            own_scale: Scaled16::scale(k[1]),
            unit,
            parent: Vec::new(),
            planes: Vec::new(),
        };
        (level, entry)
    }

    /// The scales of a row's own codes: [`Coded::mine`].
    fn scales(&self) -> [f32; 4] {
        let c = self.cpl_scale;
        [c, c, c, self.own_scale]
    }

    /// The [`Operator`]'s unknown at entry `e` ([`PAD`] on the pads): [`Coded::unknown`] (a
    /// binary search over the runs: a pass over the entries takes [`Level::unknowns_in_order`]).
    fn unknown(&self, e: usize) -> u32 {
        with_rows!(self, |c| c.unknown(e))
    }

    /// Each entry's unknown ([`PAD`] on the pads), in order of the entries.
    fn unknowns_in_order(&self) -> Vec<u32> {
        let mut u = Vec::with_capacity(self.len());
        with_rows!(self, |c| c.each_row(0..c.len(), |e, row| u.push(c.unknown_of(e, &row))));
        u
    }

    /// Entry e's neighbours' entries: [`Coded::neighbours`].
    #[cfg(test)]
    fn neighbours(&self, e: usize) -> [u32; 6] {
        with_rows!(self, |c| c.neighbours(e, &c.row(e)))
    }

    /// Entry e's couplings to its neighbours `nbr` and its decoded [`Row::own`]:
    /// [`Coded::couplings`].
    #[cfg(test)]
    fn couplings(&self, e: usize, nbr: &[u32; 6]) -> ([Mg; 6], Mg) {
        with_rows!(self, |c| c.couplings(&c.row(e), nbr))
    }

    /// Entries, pads included (the length of the level's vectors).
    fn len(&self) -> usize {
        self.rows.len()
    }

    fn unknowns(&self) -> usize {
        self.len() - 2
    }

    /// Record that `coarse`, of operator `op`, aggregates this level: each red entry's parent
    /// (from each unknown's aggregate `parent` and the coarse unknowns' entries `coarse_entry`)
    /// and the ranges of the coarse level's planes ([`Level::planes`]). Only the red entries
    /// are linked: a black pass before every restriction of the cycle leaves the black
    /// residuals at zero, and one after every prolongation overwrites the black values.
    fn link(&mut self, parent: &[u32], coarse: &mut Level, coarse_entry: &[u32], op: &Operator) {
        let plane_cells = (op.dims[0] * op.dims[1]) as u32;
        let plane = |cu: u32| (op.nodes[cu as usize].cell / plane_cells) as usize;
        self.parent = (0..self.red)
            .into_par_iter()
            .map(|e| coarse_entry[parent[self.unknown(e) as usize] as usize])
            .collect();
        // Counts per plane (shifted by one), then their running sums from each range's start.
        let mut planes = vec![[0u32; 3]; op.dims[2] + 1];
        with_rows!(self, |c| c.each_row(0..self.red, |e, row| {
            planes[plane(parent[c.unknown_of(e, &row) as usize]) + 1][0] += 1;
        }));
        for (cu, e) in coarse_entry.iter().enumerate() {
            planes[plane(cu as u32) + 1][1 + usize::from(*e as usize > coarse.red)] += 1;
        }
        planes[0] = [0, 0, coarse.red as u32 + 1];
        for k in 0..op.dims[2] {
            let before = planes[k];
            for (v, b) in planes[k + 1].iter_mut().zip(before) {
                *v += b;
            }
        }
        coarse.planes = planes;
    }

    /// b = Pᵀ r, r = bf − Af xf the residual of the finer level `fine`: each entry sums its red
    /// children's residuals as they are made (not stored), in their order, one task per plane
    /// ([`Level::planes`]). Called right after a black pass, which leaves the black residuals at
    /// zero.
    fn restrict_residual<const K: usize>(&self, fine: &Level, xf: &[[Mg; K]], bf: &[[Mg; K]], b: &mut [[Mg; K]]) {
        let (xr, xb) = xf.split_at(fine.red + 1);
        // Each plane's red and black entries (the pads, which have no children, hold 0).
        let (mut red, mut black) = b.split_at_mut(self.red + 1);
        let mut tasks = Vec::with_capacity(self.planes.len());
        for w in self.planes.windows(2) {
            let (here, rest) = std::mem::take(&mut red).split_at_mut((w[1][1] - w[0][1]) as usize);
            let (here_black, rest_black) = std::mem::take(&mut black).split_at_mut((w[1][2] - w[0][2]) as usize);
            tasks.push((w[0], w[1][0] as usize, here, here_black));
            (red, black) = (rest, rest_black);
        }
        red.fill([0.0; K]);
        black.fill([0.0; K]);
        let split = self.red as u32;
        with_rows!(fine, |rows| with_diagonal!(fine, |diag| tasks.into_par_iter().for_each(
            |(start, end, red, black)| {
                red.fill([0.0; K]);
                black.fill([0.0; K]);
                let xb = OtherColour::of(&rows, xb, fine.red + 1);
                rows.each_row(start[0] as usize..end, |f, row| {
                    let rf = Coded::residual_red(f, &row, xr, &xb, bf, &diag);
                    let p = fine.parent[f];
                    let v = if p < split {
                        &mut red[(p - start[1]) as usize]
                    } else {
                        &mut black[(p - start[2]) as usize]
                    };
                    for k in 0..K {
                        v[k] += rf[k];
                    }
                })
            }
        )))
    }

    /// The first red pass from x = 0: x = b / diag on the red unknowns, 0 elsewhere (the finest
    /// level's diagonals from its rows' sums and couplings: this pass reads its rows).
    fn smooth_red_from_zero<const K: usize>(&self, x: &mut [[Mg; K]], b: &[[Mg; K]]) {
        let red = self.red;
        x[red..].par_chunks_mut(CHUNK).for_each(|xs| xs.fill([0.0; K]));
        with_rows!(self, |rows| x[..red].par_chunks_mut(CHUNK).enumerate().for_each(|(ci, xs)| {
            let first = ci * CHUNK;
            rows.each_row_into(first, xs, |e, row, xv| {
                let d = if self.row_sums {
                    let (c, own) = rows.couplings(&row, &rows.neighbours(e, &row));
                    less_couplings(own, c)
                } else {
                    row.codes.own.decode(rows.mine[3])
                };
                *xv = b[e].map(|v| v / d);
            })
        }))
    }

    /// One Gauss–Seidel pass over the unknowns of `colour`: each reads only the other colour.
    fn smooth<const K: usize>(&self, x: &mut [[Mg; K]], b: &[[Mg; K]], colour: usize) {
        let red = self.red;
        let (xr, xb) = x.split_at_mut(red + 1);
        let black = xb.len() - 1;
        let (mine, other, first, off) = if colour == 0 {
            (&mut xr[..red], &*xb, 0, red + 1)
        } else {
            (&mut xb[..black], &*xr, red + 1, 0)
        };
        with_rows!(self, |coded| with_diagonal!(self, |diag| mine
            .par_chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(ci, xs)| {
                let start = first + ci * CHUNK;
                let other = OtherColour::of(&coded, other, off);
                coded.each_row_into(start, xs, |e, row, xv| {
                    let (s, c, own) = other.couple(&row);
                    let d = diag(own, &c);
                    *xv = std::array::from_fn(|k| (b[e][k] - s[k]) / d);
                })
            })))
    }

    /// x += w P xc on the red unknowns, each adding its parent's correction: a black pass
    /// follows, which overwrites the black ones whatever they hold.
    fn prolong_red<const K: usize>(&self, x: &mut [[Mg; K]], xc: &[[Mg; K]], w: Mg) {
        x[..self.red]
            .par_chunks_mut(CHUNK)
            .zip(self.parent.par_chunks(CHUNK))
            .for_each(|(xs, ps)| {
                for (v, p) in xs.iter_mut().zip(ps) {
                    let c = &xc[*p as usize];
                    for k in 0..K {
                        v[k] += w * c[k];
                    }
                }
            });
    }
}

/// Deterministic dot products per system: per-chunk partial sums added in order.
fn dot<A: Real, B: Real, const K: usize>(a: &[[A; K]], b: &[[B; K]]) -> [f64; K] {
    let parts: Vec<[f64; K]> = a
        .par_chunks(CHUNK)
        .zip(b.par_chunks(CHUNK))
        .map(|(x, y)| {
            let mut s = [0.0; K];
            for (p, q) in x.iter().zip(y) {
                for k in 0..K {
                    s[k] += p[k].get() * q[k].get();
                }
            }
            s
        })
        .collect();
    sum_parts(&parts)
}

fn sum_parts<const K: usize>(parts: &[[f64; K]]) -> [f64; K] {
    let mut s = [0.0; K];
    for p in parts {
        for k in 0..K {
            s[k] += p[k];
        }
    }
    s
}

/// The CG step y += α p (in f64), r −= α q per system.
fn cg_step<const K: usize>(y: &mut [[f64; K]], r: &mut [[Mg; K]], p: &[[Mg; K]], q: &[[Mg; K]], alpha: [f64; K]) {
    y.par_chunks_mut(CHUNK)
        .zip(r.par_chunks_mut(CHUNK))
        .zip(p.par_chunks(CHUNK).zip(q.par_chunks(CHUNK)))
        .for_each(|((ys, rs), (ps, qs))| {
            for (((yv, rv), pv), qv) in ys.iter_mut().zip(rs.iter_mut()).zip(ps).zip(qs) {
                for k in 0..K {
                    yv[k] += alpha[k] * pv[k].get();
                    rv[k] = Mg::of(rv[k].get() - alpha[k] * qv[k].get());
                }
            }
        });
}

/// v² / d: one entry's term of a squared norm scaled by the diagonal, ‖D^-½ v‖², given
/// `inv_d` = 1/d ([`inverse`]).
#[inline(always)]
fn scaled_square(v: f64, inv_d: f64) -> f64 {
    v * v * inv_d
}

/// 1/d for a diagonal d > 0, 0 for a pad's (d = 0: its values are 0 and count nothing).
#[inline(always)]
fn inverse(d: f64) -> f64 {
    if d > 0.0 {
        1.0 / d
    } else {
        0.0
    }
}

/// Dense Cholesky factor of the coarsest level.
#[derive(Clone, Debug)]
struct Dense {
    /// The level's entries that are unknowns.
    cells: Vec<usize>,
    /// The factor L (row-major) below the diagonal and on it, Lᵀ above it.
    l: Vec<f64>,
}

/// In-place lower Cholesky factor of the dense n×n SPD matrix `a` (row-major). Pivots are clamped
/// at 1e-300 so a singular coarse grid still factors; returns the smallest pivot before the clamp
/// (> 0 exactly when `a` is positive definite).
fn cholesky_in_place(a: &mut [f64], n: usize) -> f64 {
    let mut smallest = f64::INFINITY;
    for j in 0..n {
        let mut d = a[j * n + j];
        for k in 0..j {
            d -= a[j * n + k] * a[j * n + k];
        }
        smallest = smallest.min(d);
        let d = d.max(1e-300).sqrt();
        a[j * n + j] = d;
        for i in j + 1..n {
            let mut v = a[i * n + j];
            for k in 0..j {
                v -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = v / d;
        }
    }
    smallest
}

impl Dense {
    /// The factor of operator `s` divided by 2^unit (the level's [`Level::unit`]), whose
    /// unknowns are the entries `entry` of `level`.
    fn build(s: &impl Stencils, level: &Level, entry: &[u32]) -> Dense {
        let to_unit = pow2(-level.unit);
        let cells: Vec<usize> = (0..level.len()).filter(|e| level.unknown(*e) != PAD).collect();
        let n = cells.len();
        let mut q_of = vec![usize::MAX; level.len()];
        for (q, e) in cells.iter().enumerate() {
            q_of[*e] = q;
        }
        let mut a = vec![0f64; n * n];
        for (q, &e) in cells.iter().enumerate() {
            let nd = s.node(level.unknown(e) as usize);
            a[q * n + q] = nd.diag * to_unit;
            for ax in 0..3 {
                let v = nd.up[ax] * to_unit;
                if v != 0.0 && nd.up_nbr[ax] != NONE {
                    let r = q_of[entry[nd.up_nbr[ax] as usize] as usize];
                    a[q * n + r] += v;
                    a[r * n + q] += v;
                }
            }
        }
        cholesky_in_place(&mut a, n);
        // Lᵀ into the upper triangle: the backward substitution then reads rows too.
        for i in 0..n {
            for j in 0..i {
                a[j * n + i] = a[i * n + j];
            }
        }
        Dense { cells, l: a }
    }

    /// x = A⁻¹ b on the level's unknowns, all systems in one pass over the factor (each row read
    /// once per substitution, forward along L's rows, backward along Lᵀ's).
    fn solve<const K: usize>(&self, b: &[[Mg; K]], x: &mut [[Mg; K]]) {
        let n = self.cells.len();
        x.fill([0.0; K]);
        let mut y: Vec<[f64; K]> = self.cells.iter().map(|c| b[*c].map(Real::get)).collect();
        for i in 0..n {
            let (done, rest) = y.split_at_mut(i);
            let row = &self.l[i * n..i * n + i];
            let v = &mut rest[0];
            for (lk, yk) in row.iter().zip(done.iter()) {
                for k in 0..K {
                    v[k] -= lk * yk[k];
                }
            }
            *v = v.map(|v| v / self.l[i * n + i]);
        }
        for i in (0..n).rev() {
            let (head, done) = y.split_at_mut(i + 1);
            let row = &self.l[i * n + i + 1..(i + 1) * n];
            let v = &mut head[i];
            for (lk, yk) in row.iter().zip(done.iter()) {
                for k in 0..K {
                    v[k] -= lk * yk[k];
                }
            }
            *v = v.map(|v| v / self.l[i * n + i]);
        }
        for (c, v) in self.cells.iter().zip(&y) {
            x[*c] = v.map(Mg::of);
        }
    }
}

/// Vectors of one multigrid level's cycle: the next level's right-hand side and correction
/// (the level's residual is restricted as it is made: [`Level::restrict_residual`]).
struct Work<const K: usize> {
    bc: Vec<[Mg; K]>,
    xc: Vec<[Mg; K]>,
}

impl<const K: usize> Work<K> {
    /// The vectors for the cycle on a level with `coarse` below it.
    fn new(coarse: &Level) -> Work<K> {
        Work {
            bc: vec![[0.0; K]; coarse.len()],
            xc: vec![[0.0; K]; coarse.len()],
        }
    }

    /// The vectors for every level of `h` above its coarsest.
    fn all(h: &Hierarchy) -> Vec<Work<K>> {
        h.levels[1..].iter().map(Work::new).collect()
    }
}

/// The multigrid hierarchy of one operator.
#[derive(Clone, Debug)]
pub struct Hierarchy {
    /// Levels, finest first (the finest holding its rows' sums: [`Level::row_sums`]).
    levels: Vec<Level>,
    coarse: Dense,
    /// Coarse-grid visits per level (1: V-cycle, 2: W-cycle).
    pub cycle: usize,
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
            cycle: 2,
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

    /// One cycle on level `l` for A_l x = b, x starting at zero; `work` holds the vectors of
    /// levels l and below.
    fn cycle<const K: usize>(&self, l: usize, b: &[[Mg; K]], x: &mut [[Mg; K]], work: &mut [Work<K>]) {
        if l + 1 == self.levels.len() {
            self.coarse.solve(b, x);
            return;
        }
        let s = &self.levels[l];
        // Red, black before the corrections; black, red after; a symmetric black-red-black
        // between the two corrections of a W-cycle (its red-red pair in the middle is one pass:
        // a second red pass recomputes the same values).
        s.smooth_red_from_zero(x, b);
        s.smooth(x, b, 1);
        for _ in 1..self.sweeps {
            s.smooth(x, b, 0);
            s.smooth(x, b, 1);
        }
        let (w, rest) = work.split_first_mut().expect("a work entry per level above the coarsest");
        let coarse_is_direct = l + 2 == self.levels.len();
        let visits = if coarse_is_direct { 1 } else { self.cycle.max(1) };
        for visit in 0..visits {
            self.levels[l + 1].restrict_residual(s, x, b, &mut w.bc);
            self.cycle(l + 1, &w.bc, &mut w.xc, rest);
            s.prolong_red(x, &w.xc, Mg::of(self.over_correction));
            if visit + 1 < visits {
                s.smooth(x, b, 1);
                s.smooth(x, b, 0);
                s.smooth(x, b, 1);
            }
        }
        for _ in 0..self.sweeps {
            s.smooth(x, b, 1);
            s.smooth(x, b, 0);
        }
    }

    /// q = A p per system (computed in f64, stored in the multigrid's precision). Returns, in
    /// f64 and summed as [`dot`] does, pᵀA p and, for the scaled norm ‖D^-½ (r − α q)‖ of the
    /// step's residual (made before α is known), rᵀD⁻¹r, rᵀD⁻¹q and qᵀD⁻¹q (q as stored): D is
    /// not stored, so the norm is taken where the rows are read.
    fn apply<const K: usize>(&self, p: &[[Mg; K]], q: &mut [[Mg; K]], r: &[[Mg; K]]) -> [[f64; K]; 4] {
        let parts: Vec<[[f64; K]; 4]> = with_rows!(&self.levels[0], |fine| q
            .par_chunks_mut(CHUNK)
            .enumerate()
            .map(|(ci, qs)| {
                let first = ci * CHUNK;
                let mut sums = [[0.0; K]; 4];
                fine.each_row_into(first, qs, |e, row, qv| {
                    let (ap, d) = fine.apply_row(e, &row, p);
                    let w = inverse(d);
                    for k in 0..K {
                        qv[k] = Mg::of(ap[k]);
                        let (rk, qk) = (r[e][k].get(), qv[k].get());
                        sums[0][k] += p[e][k].get() * ap[k];
                        sums[1][k] += scaled_square(rk, w);
                        sums[2][k] += rk * qk * w;
                        sums[3][k] += scaled_square(qk, w);
                    }
                });
                sums
            })
            .collect());
        std::array::from_fn(|i| sum_parts(&parts.iter().map(|s| s[i]).collect::<Vec<_>>()))
    }

    /// The true residual b − A x in f64 (`be(u)` the right-hand sides of the unknown u at an
    /// entry, 0 for [`PAD`]), stored into r for the systems in `which`; returns its scaled
    /// ‖D^-½ r‖² per system (summed as [`dot`] does; 0 for the others).
    fn true_residual<const K: usize>(
        &self,
        be: &(impl Fn(u32) -> [f64; K] + Sync),
        x: &[[f64; K]],
        r: &mut [[Mg; K]],
        which: [bool; K],
    ) -> [f64; K] {
        let parts: Vec<[f64; K]> = with_rows!(&self.levels[0], |fine| r
            .par_chunks_mut(CHUNK)
            .enumerate()
            .map(|(ci, rs)| {
                let first = ci * CHUNK;
                let mut rr = [0.0; K];
                fine.each_row_into(first, rs, |e, row, rv| {
                    let (b, (ax, d)) = (be(fine.unknown_of(e, &row)), fine.apply_row(e, &row, x));
                    let w = inverse(d);
                    for k in 0..K {
                        if which[k] {
                            let v = b[k] - ax[k];
                            rv[k] = Mg::of(v);
                            rr[k] += scaled_square(v, w);
                        }
                    }
                });
                rr
            })
            .collect());
        sum_parts(&parts)
    }

    /// Solve A x = b (A as assembled; `b`, `x0` and the result per unknown) by MGPCG from `x0`
    /// (or zero) to relative residual `tol` of the diagonally scaled system,
    /// ‖D^-½ (b − A x)‖ / ‖D^-½ b‖ (thin voxels, large D, then do not drown out thick ones), at
    /// most `max_iter` iterations.
    pub fn solve<B: Copy + Into<f64> + Sync>(&self, b: &[B], x0: Option<&[B]>, tol: f64, max_iter: usize) -> (Vec<f64>, SolveStats) {
        let [out] = self.solve_many([b], x0.map(|x| [x]), tol, max_iter);
        out
    }

    /// [`Hierarchy::solve`] for K right-hand sides at once (the bands that share the operator):
    /// each system's iterates are exactly those of its own solve, and the rows are read once per
    /// pass for all of them. `b` and `x0` in f64 or f32 (f32 halves the caller's copies).
    pub fn solve_many<B: Copy + Into<f64> + Sync, const K: usize>(
        &self,
        b: [&[B]; K],
        x0: Option<[&[B]; K]>,
        tol: f64,
        max_iter: usize,
    ) -> [(Vec<f64>, SolveStats); K] {
        let a = &self.levels[0];
        assert!(b.iter().all(|v| v.len() == a.unknowns()), "one value per unknown");
        let mut x: Vec<[f64; K]> = match x0 {
            Some(x) => {
                assert!(x.iter().all(|v| v.len() == a.unknowns()), "one value per unknown");
                let unk = a.unknowns_in_order();
                unk.par_iter()
                    .map(|u| match *u {
                        PAD => [0.0; K],
                        u => x.map(|v| v[u as usize].into()),
                    })
                    .collect()
            }
            None => vec![[0.0; K]; a.len()],
        };
        // The right-hand sides per entry, made where they are read (not held), divided by the
        // power of two that the operator is (exactly: the solution is the caller's).
        let to_unit = pow2(-a.unit);
        let be = |u: u32| match u {
            PAD => [0.0; K],
            u => b.map(|v| v[u as usize].into() * to_unit),
        };
        let stats = self.solve_entries(&be, &mut x, x0.is_none(), tol, max_iter);
        let unk = a.unknowns_in_order();
        let mut lane = 0;
        stats.map(|st| {
            let mut out = vec![0.0; a.unknowns()];
            for (u, v) in unk.iter().zip(&x) {
                if *u != PAD {
                    out[*u as usize] = v[lane];
                }
            }
            lane += 1;
            (out, st)
        })
    }

    /// MGPCG on A x = b (vectors on the finest level's entries, `be(u)` the right-hand sides of
    /// the unknown u at an entry, 0 for [`PAD`]), each system stopping on its own when ‖D^-½ r‖ ≤ `tol` ‖D^-½ b‖. Mixed
    /// precision: the iterate x is f64, the residual, A p and the search direction are in the
    /// multigrid's precision (their dots summed in f64). When a system's recursive residual
    /// meets `tol`, its true residual is computed in f64; if that does not meet `tol` (the
    /// rounding of the recursion), CG restarts from it.
    fn solve_entries<const K: usize>(
        &self,
        be: &(impl Fn(u32) -> [f64; K] + Sync),
        x: &mut [[f64; K]],
        cold: bool,
        tol: f64,
        max_iter: usize,
    ) -> [SolveStats; K] {
        let a = &self.levels[0];
        let n = a.len();
        let parts: Vec<[f64; K]> = with_rows!(a, |fine| (0..n.div_ceil(CHUNK))
            .into_par_iter()
            .map(|ci| {
                let mut s = [0.0; K];
                fine.each_row(ci * CHUNK..n.min((ci + 1) * CHUNK), |e, row| {
                    let (v, w) = (be(fine.unknown_of(e, &row)), inverse(fine.finest_row(e, &row).2));
                    for k in 0..K {
                        s[k] += scaled_square(v[k], w);
                    }
                });
                s
            })
            .collect());
        let bb = sum_parts(&parts);
        let bnorm = bb.map(f64::sqrt);
        let mut stats: [SolveStats; K] = std::array::from_fn(|_| SolveStats {
            iterations: 0,
            relative_residual: 0.0,
            history: Vec::new(),
            unknowns: a.unknowns(),
            levels: self.levels.len(),
            bytes_per_unknown: 0.0,
        });
        // The hierarchy; x in f64; r, p and q (A p, then z) in the multigrid's precision, and
        // per level in `work` the next level's b and x (the caller's b and x, per unknown, not
        // counted).
        let lanes = |v: usize, bytes: usize| v * bytes * K;
        let held = self.bytes()
            + lanes(n, 8)
            + lanes(3 * n, std::mem::size_of::<Mg>())
            + self.levels[1..]
                .iter()
                .map(|l| lanes(2 * l.len(), std::mem::size_of::<Mg>()))
                .sum::<usize>();
        for st in &mut stats {
            st.bytes_per_unknown = held as f64 / (K * a.unknowns().max(1)) as f64;
        }
        // From x = 0 (`cold`) the true residual is b, and its scaled r·r the b·b above (bit for
        // bit: A 0 = 0 exactly, and the same chunks add in the same order).
        let mut r = vec![[0.0; K]; n];
        let rr = if cold {
            with_rows!(a, |fine| r.par_chunks_mut(CHUNK).enumerate().for_each(|(ci, rs)| {
                let first = ci * CHUNK;
                fine.each_row_into(first, rs, |e, row, rv| *rv = be(fine.unknown_of(e, &row)).map(Mg::of));
            }));
            bb
        } else {
            self.true_residual(be, x, &mut r, [true; K])
        };
        // Each system's final true r·r, kept from the check that stopped it.
        let mut last: [Option<f64>; K] = [None; K];
        // `q` holds A p from the product to the step, then the preconditioned residual z = M r
        // (each is dead when the other is written: one vector for both).
        let (mut p, mut q) = (vec![[0.0; K]; n], vec![[0.0; K]; n]);
        let mut work: Vec<Work<K>> = Work::all(self);
        let mut active = [false; K];
        for k in 0..K {
            if bnorm[k] == 0.0 {
                x.iter_mut().for_each(|v| v[k] = 0.0);
                stats[k].history.push(0.0);
            } else {
                let rel = rr[k].sqrt() / bnorm[k];
                stats[k].history.push(rel);
                active[k] = rel > tol;
                if !active[k] {
                    last[k] = Some(rr[k]);
                }
            }
        }
        if active.iter().any(|a| *a) {
            self.cycle(0, &r, &mut q, &mut work);
            p.copy_from_slice(&q);
            let mut rz = dot(&r, &q);
            let mut iterations = 0;
            while iterations < max_iter {
                let [pap, rdr, rdq, qdq] = self.apply(&p, &mut q, &r);
                let mut alpha = [0.0; K];
                for k in 0..K {
                    if pap[k].is_nan() || pap[k] <= 0.0 {
                        active[k] = false;
                    }
                    if active[k] {
                        alpha[k] = rz[k] / pap[k];
                    }
                }
                if !active.iter().any(|a| *a) {
                    break;
                }
                cg_step(x, &mut r, &p, &q, alpha);
                iterations += 1;
                let mut check = [false; K];
                for k in 0..K {
                    if !active[k] {
                        continue;
                    }
                    stats[k].iterations += 1;
                    // ‖D^-½ (r − α q)‖², expanded (clamped at 0: it cancels to rounding when
                    // the step leaves almost nothing).
                    let rr = (rdr[k] - 2.0 * alpha[k] * rdq[k] + alpha[k] * alpha[k] * qdq[k]).max(0.0);
                    let rel = rr.sqrt() / bnorm[k];
                    stats[k].history.push(rel);
                    check[k] = rel <= tol;
                }
                // Systems whose recursive residual meets the tolerance: stop on the true one,
                // or restart CG from it (its direction dropped: β = 0).
                let mut restart = [false; K];
                if check.iter().any(|c| *c) {
                    let rt = self.true_residual(be, x, &mut r, check);
                    for k in 0..K {
                        if check[k] {
                            restart[k] = rt[k].sqrt() / bnorm[k] > tol;
                            active[k] = restart[k];
                            if !restart[k] {
                                last[k] = Some(rt[k]);
                            }
                        }
                    }
                }
                if !active.iter().any(|a| *a) {
                    break;
                }
                self.cycle(0, &r, &mut q, &mut work);
                let rz_new = dot(&r, &q);
                let beta: [f64; K] = std::array::from_fn(|k| if active[k] && !restart[k] { rz_new[k] / rz[k] } else { 0.0 });
                rz = rz_new;
                p.par_iter_mut()
                    .zip(&q)
                    .for_each(|(pv, zz)| *pv = std::array::from_fn(|k| Mg::of(zz[k].get() + beta[k] * pv[k].get())));
            }
        }
        // Report the true residuals (those not known from the stop: a breakdown or the
        // iteration cap).
        drop((p, q, work));
        let need: [bool; K] = std::array::from_fn(|k| bnorm[k] > 0.0 && last[k].is_none());
        let rr = if need.iter().any(|v| *v) {
            self.true_residual(be, x, &mut r, need)
        } else {
            [0.0; K]
        };
        for k in 0..K {
            if bnorm[k] > 0.0 {
                stats[k].relative_residual = last[k].unwrap_or(rr[k]).sqrt() / bnorm[k];
            }
        }
        stats
    }
}

/// The assembled operator (eq. 4 with eq. 7) and the solver, against dense linear algebra
/// (moved here from tests/ so the solver's internals need not be public).
#[cfg(test)]
mod operator_tests {
    use super::{coarsen, Coded, Hierarchy, Level, Mg, Node, Operator, Rows, Stencils, Work, CHUNK, NONE, PAD};
    use crate::diffusion::{assemble, BoundaryLight, Domain};
    use crate::incident::{compute, IncidentLight, IncidentSettings, IncidentSources};
    use crate::lighting::DirectionBins;
    use crate::math::{Rgb, Rng, Vec3};
    use crate::medium::{Grid3, Medium};
    use std::collections::HashMap;

    /// A random cloud: each voxel of the inner region full with probability 0.8, with optical depth
    /// per voxel log-uniform in [1e-3, 10] (σt = 1 m⁻¹, 1 m voxels).
    fn random_cloud(d: [usize; 3], seed: u64, albedo: f32, g: f32) -> Medium {
        let mut grid = Grid3::filled(d, 0.0);
        let mut rng = Rng::new(seed, 7);
        for k in 1..d[2] - 1 {
            for j in 1..d[1] - 1 {
                for i in 1..d[0] - 1 {
                    if rng.uniform() < 0.8 {
                        grid.set(i, j, k, 10f32.powf(rng.uniform() * 4.0 - 3.0));
                    }
                }
            }
        }
        Medium::new(grid, Vec3::ZERO, Vec3::ONE, 1.0, Rgb::splat(albedo), g)
    }

    fn sky_and_sun(l: f32, sun: Option<(Vec3, f32)>) -> IncidentSources {
        IncidentSources {
            bin_radiance: vec![Rgb::splat(l); 96],
            sun: sun.map(|(d, e)| (d.normalize(), Rgb::splat(e))),
        }
    }

    /// Stage 1 on `m` under a uniform sky of radiance `l` and an optional sun (direction, irradiance).
    fn lit(m: &Medium, l: f32, sun: Option<(Vec3, f32)>) -> IncidentLight {
        compute(m, &DirectionBins::new(), &sky_and_sun(l, sun), &IncidentSettings::default(), None)
    }

    /// Band `band`'s operator and right-hand side on a random cloud under a unit sky and a sun
    /// of irradiance 2 from `sun`.
    fn sun_lit_system(d: [usize; 3], seed: u64, albedo: f32, g: f32, sun: Vec3, band: usize) -> (Operator, Vec<f64>) {
        let m = random_cloud(d, seed, albedo, g);
        let inc = lit(&m, 1.0, Some((sun, 2.0)));
        let dom = Domain::of(&m).unwrap();
        assemble(&m, &inc, &BoundaryLight::none(), band, 1e-3, &dom)
    }

    /// The operator as a dense matrix (row-major, one row per unknown).
    fn dense(s: &Operator) -> Vec<f64> {
        let n = s.nodes.len();
        let mut a = vec![0.0; n * n];
        for (q, nd) in s.nodes.iter().enumerate() {
            a[q * n + q] = nd.diag;
            for ax in 0..3 {
                if nd.up_nbr[ax] != NONE {
                    let r = nd.up_nbr[ax] as usize;
                    let [c, d] = [nd.cell, s.nodes[r].cell].map(|c| c as usize);
                    assert_eq!(d - c, [1, s.dims[0], s.dims[0] * s.dims[1]][ax], "+a neighbour's cell");
                    a[q * n + r] = nd.up[ax];
                    a[r * n + q] = nd.up[ax];
                }
            }
        }
        a
    }

    /// The operator CG solves with `h`, densely (row-major, in the order of the `n` unknowns):
    /// the finest level's coded couplings, each diagonal the row's coded sum less them
    /// (`Coded::apply_row`), times the power of two the levels are divided by.
    fn as_solved(h: &Hierarchy, n: usize) -> Vec<f64> {
        let fine = &h.levels[0];
        let unit = super::pow2(fine.unit);
        let mut a = vec![0.0; n * n];
        for e in (0..fine.len()).filter(|e| fine.unknown(*e) != PAD) {
            let u = fine.unknown(e) as usize;
            let (nbr, c, d) = with_rows!(fine, |rows| rows.finest_row(e, &rows.row(e)));
            a[u * n + u] = d * unit;
            for q in (0..6).filter(|q| c[*q] != 0.0) {
                a[u * n + fine.unknown(nbr[q] as usize) as usize] = c[q] * unit;
            }
        }
        a
    }

    /// Gaussian elimination with partial pivoting.
    fn dense_solve(mut a: Vec<f64>, mut b: Vec<f64>) -> Vec<f64> {
        let n = b.len();
        for c in 0..n {
            let p = (c..n).max_by(|x, y| a[x * n + c].abs().total_cmp(&a[y * n + c].abs())).unwrap();
            for k in 0..n {
                a.swap(c * n + k, p * n + k);
            }
            b.swap(c, p);
            for r in c + 1..n {
                let f = a[r * n + c] / a[c * n + c];
                for k in c..n {
                    a[r * n + k] -= f * a[c * n + k];
                }
                b[r] -= f * b[c];
            }
        }
        let mut x = vec![0.0; n];
        for r in (0..n).rev() {
            let s: f64 = (r + 1..n).map(|k| a[r * n + k] * x[k]).sum();
            x[r] = (b[r] - s) / a[r * n + r];
        }
        x
    }

    #[test]
    fn operator_is_symmetric_positive_definite() {
        let m = random_cloud([9, 8, 7], 3, 0.95, 0.8);
        let inc = lit(&m, 0.5, Some((Vec3::new(0.3, 1.0, 0.2), 3.0)));
        let dom = Domain::of(&m).unwrap();
        for tau_min in [0.0, 1e-3] {
            let (s, _) = assemble(&m, &inc, &BoundaryLight::none(), 0, tau_min, &dom);
            let a = dense(&s);
            let n = s.nodes.len();
            assert!(n > 100);
            for q in 0..n {
                for r in 0..n {
                    assert_eq!(a[q * n + r], a[r * n + q]);
                }
            }
            // Cholesky must succeed with positive pivots.
            let mut l = a.clone();
            let smallest = super::cholesky_in_place(&mut l, n);
            assert!(smallest > 0.0, "smallest pivot {smallest}: not positive definite");
        }
    }

    #[test]
    fn multigrid_matches_dense_solve() {
        // Coarsened down to 16 unknowns, so several multigrid levels sit above the direct one.
        for (d, seed) in [([14, 12, 10], 1u64), ([18, 14, 12], 2)] {
            let m = random_cloud(d, seed, 0.99, 0.85);
            let inc = lit(&m, 1.0, Some((Vec3::new(-0.2, 1.0, 0.4), 2.0)));
            let dom = Domain::of(&m).unwrap();
            let (s, b) = assemble(&m, &inc, &BoundaryLight::none(), 1, 0.0, &dom);
            let h = Hierarchy::build_with(&s.rows(), 16);
            assert!(h.levels() >= 4, "levels {}", h.levels());
            let (x, st) = h.solve(&b, None, 1e-12, 500);
            assert!(st.relative_residual <= 1e-12, "{st:?}");
            let xd = dense_solve(as_solved(&h, b.len()), b.clone());
            let num: f64 = x.iter().zip(&xd).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt();
            let den: f64 = xd.iter().map(|v| v * v).sum::<f64>().sqrt();
            assert!(num / den < 1e-8, "relative difference {}", num / den);
        }
    }

    #[test]
    fn systems_solved_together_match_their_own_solves_exactly() {
        let (s, b) = sun_lit_system([12, 10, 9], 5, 0.97, 0.8, Vec3::new(0.3, 1.0, -0.2), 0);
        let h = Hierarchy::build_with(&s.rows(), 16);
        // A second right-hand side that converges at another iteration, and a zero one.
        let b2: Vec<f64> = b.iter().enumerate().map(|(c, v)| if c % 3 == 0 { -2.0 * v } else { *v }).collect();
        let zero = vec![0.0; b.len()];
        let together = h.solve_many([&b, &b2, &zero], None, 1e-9, 200);
        for (one, rhs) in together.iter().zip([&b, &b2, &zero]) {
            let alone = h.solve(rhs, None, 1e-9, 200);
            assert_eq!(one.0, alone.0);
            assert_eq!(one.1.history, alone.1.history);
            assert_eq!(one.1.relative_residual, alone.1.relative_residual);
        }
        assert!(together[0].1.iterations > 5 && together[0].1.relative_residual <= 1e-9);
        assert_eq!(together[2].0, zero);
    }

    #[test]
    fn cg_operator_keeps_every_row_sum() {
        // Couplings coded to 16 bits, each diagonal the row's coded sum less them: each coupling
        // and A·1 are the assembled operator's to ≤ 2⁻¹² of themselves (rounding the diagonal on
        // its own would move A·1 by 2⁻¹² of the diagonal, up to ~4 times the sum here), no row
        // sum lost below the code's range.
        let (s, _) = sun_lit_system([12, 10, 9], 4, 0.999, 0.85, Vec3::new(0.3, 1.0, 0.1), 0);
        let h = Hierarchy::build_with(&s.rows(), 16);
        let (a, n) = (dense(&s), s.nodes.len());
        let solved = as_solved(&h, n);
        for (x, y) in a.iter().zip(&solved) {
            assert!((x - y).abs() <= x.abs() / 4096.0 + 1e-12 * a[0], "coupling {x} coded {y}");
        }
        let fine = &h.levels[0];
        let unit = super::pow2(fine.unit);
        let ones: Vec<[f64; 1]> = (0..fine.len()).map(|e| [if fine.unknown(e) == PAD { 0.0 } else { 1.0 }]).collect();
        let mut smallest = f64::INFINITY;
        for e in (0..fine.len()).filter(|e| fine.unknown(*e) != PAD) {
            let u = fine.unknown(e) as usize;
            let want: f64 = a[u * n..(u + 1) * n].iter().sum();
            let got = with_rows!(fine, |c| c.apply_row(e, &c.row(e), &ones).0[0]) * unit;
            assert!(
                (got - want).abs() <= 1e-12 * a[u * n + u] + want.abs() / 4096.0,
                "row {u}: {got} vs {want}"
            );
            smallest = smallest.min(want / a[u * n + u]);
        }
        // Rows whose sum is far below their diagonal, where the difference shows.
        assert!(smallest < 1e-2, "{smallest}");
        // The pads' products are 0.
        assert_eq!(with_rows!(fine, |c| c.apply_row(fine.red, &c.row(fine.red), &ones)), ([0.0], 0.0));
    }

    #[test]
    fn stops_on_the_true_residual_in_f64() {
        // Far below what the f32 recursion can follow: the stop must come from the true residual
        // (CG restarted from it), checked here densely on the scaled system D^-1/2 (b − A x), A
        // the operator CG solves (couplings and row sums rounded to f32) and D its diagonal.
        let (s, b) = sun_lit_system([12, 10, 9], 6, 0.98, 0.8, Vec3::new(0.2, 1.0, -0.3), 2);
        let h = Hierarchy::build_with(&s.rows(), 16);
        let tol = 1e-10;
        let (x, st) = h.solve(&b, None, tol, 500);
        let (a, n) = (as_solved(&h, b.len()), b.len());
        let d: Vec<f64> = (0..n).map(|q| a[q * n + q].sqrt()).collect();
        let res: f64 = (0..n)
            .map(|q| {
                let ax: f64 = (0..n).map(|r| a[q * n + r] * x[r]).sum();
                ((b[q] - ax) / d[q]).powi(2)
            })
            .sum::<f64>()
            .sqrt();
        let bn: f64 = (0..n).map(|q| (b[q] / d[q]).powi(2)).sum::<f64>().sqrt();
        assert!(res / bn <= tol, "true residual {} ({st:?})", res / bn);
        assert!(
            (st.relative_residual - res / bn).abs() <= 1e-3 * res / bn,
            "reported {} vs {}",
            st.relative_residual,
            res / bn
        );
        // f32 right-hand sides are accepted too (the callers' copies): the same solve to rounding.
        let b32: Vec<f32> = b.iter().map(|v| *v as f32).collect();
        let (x32, _) = h.solve(&b32, None, 1e-6, 500);
        let diff = x.iter().zip(&x32).map(|(p, q)| (p - q).powi(2)).sum::<f64>().sqrt();
        let norm = x.iter().map(|p| p * p).sum::<f64>().sqrt();
        assert!(diff / norm < 1e-4, "{}", diff / norm);
    }

    #[test]
    fn coarse_operator_is_the_galerkin_product() {
        // Odd box sides: the last aggregates of each axis are one cell thick.
        let (s, _) = sun_lit_system([11, 9, 8], 4, 0.9, 0.8, Vec3::new(0.2, 1.0, 0.3), 0);
        let (c, parent, maxima) = coarsen(&s.rows());
        // The fine rows' largest values, found on the way.
        assert_eq!(maxima, super::Maxima::all(&s.rows()));
        assert!(maxima.cpl > 0.0 && maxima.sum > 0.0 && maxima.diag > maxima.sum);
        let (n, nc) = (s.nodes.len(), c.nodes.len());
        assert!(nc > 10 && nc < n, "{nc} of {n}");
        assert_eq!(c.dims, [s.dims[0].div_ceil(2), s.dims[1].div_ceil(2), s.dims[2].div_ceil(2)]);
        // PᵀAP with P[u][parent u] = 1, densely.
        let a = dense(&s);
        let mut g = vec![0.0; nc * nc];
        for u in 0..n {
            for v in 0..n {
                g[parent[u] as usize * nc + parent[v] as usize] += a[u * n + v];
            }
        }
        for (x, y) in g.iter().zip(&dense(&c)) {
            assert!((x - y).abs() <= 1e-12 * x.abs().max(1.0), "{x} vs {y}");
        }
        for (u, p) in parent.iter().enumerate() {
            let [i, j, k] = s.rows().ijk(u);
            let cell = i / 2 + c.dims[0] * (j / 2 + c.dims[1] * (k / 2));
            assert_eq!(c.nodes[*p as usize].cell as usize, cell);
        }
        assert!(c.nodes.windows(2).all(|w| w[0].cell < w[1].cell), "coarse unknowns in box order");
    }

    /// The preconditioner (one cycle from zero) of `h` applied to `b` (one value per entry of the
    /// finest level, 0 on the pads).
    fn precondition(h: &Hierarchy, b: &[f64]) -> Vec<f64> {
        let b: Vec<[Mg; 1]> = b.iter().map(|v| [*v as Mg]).collect();
        let mut x = vec![[0.0; 1]; b.len()];
        let mut work: Vec<Work<1>> = Work::all(h);
        h.cycle(0, &b, &mut x, &mut work);
        x.iter().map(|v| v[0] as f64).collect()
    }

    #[test]
    fn restriction_sums_each_coarse_entrys_red_children() {
        // Each coarse entry gets the sum of its red children's residuals (whatever it held), the
        // pads 0: checked on every level against residuals made densely from the decoded rows.
        let (s, _) = sun_lit_system([14, 12, 10], 8, 0.99, 0.85, Vec3::new(0.1, 1.0, 0.3), 0);
        let h = Hierarchy::build_with(&s.rows(), 16);
        assert!(h.levels() >= 4);
        let mut rng = Rng::new(3, 2);
        for l in 0..h.levels() - 1 {
            let (fine, coarse) = (&h.levels[l], &h.levels[l + 1]);
            let mut random = || -> Vec<[Mg; 1]> {
                (0..fine.len())
                    .map(|e| [if fine.unknown(e) == PAD { 0.0 } else { rng.uniform() - 0.5 }])
                    .collect()
            };
            let (x, b) = (random(), random());
            let mut got = vec![[7.0; 1]; coarse.len()];
            coarse.restrict_residual(fine, &x, &b, &mut got);
            let (mut want, mut size) = (vec![0.0; coarse.len()], vec![0.0; coarse.len()]);
            for f in 0..fine.red {
                let nbr = fine.neighbours(f);
                let c = fine.couplings(f, &nbr).0.map(f64::from);
                let own = f64::from(with_rows!(fine, |rows| rows.row(f).codes.own.decode(rows.mine[3])));
                let d = match fine.row_sums {
                    true => super::less_couplings(own, c),
                    false => own,
                };
                let terms = (0..6)
                    .map(|q| c[q] * f64::from(x[nbr[q] as usize][0]))
                    .chain([d * f64::from(x[f][0])]);
                let p = fine.parent[f] as usize;
                want[p] += f64::from(b[f][0]) - terms.clone().sum::<f64>();
                size[p] += f64::from(b[f][0]).abs() + terms.map(f64::abs).sum::<f64>();
            }
            for e in 0..coarse.len() {
                if coarse.unknown(e) == PAD {
                    assert_eq!(got[e], [0.0], "level {l} pad {e}");
                }
                let g = f64::from(got[e][0]);
                assert!((g - want[e]).abs() <= 1e-5 * size[e], "level {l} entry {e}: {g} vs {}", want[e]);
            }
            assert!(size.iter().filter(|v| **v > 0.0).count() > coarse.unknowns() / 2);
        }
    }

    #[test]
    fn preconditioner_is_symmetric() {
        // zᵀ M⁻¹ y = yᵀ M⁻¹ z (to the cycle's f32 rounding), so CG's theory holds.
        let (s, _) = sun_lit_system([14, 12, 10], 8, 0.99, 0.85, Vec3::new(0.1, 1.0, 0.3), 0);
        let h = Hierarchy::build_with(&s.rows(), 16);
        assert!(h.levels() >= 4);
        let fine = &h.levels[0];
        let mut rng = Rng::new(9, 1);
        let mut random = || -> Vec<f64> {
            (0..fine.len())
                .map(|e| if fine.unknown(e) == PAD { 0.0 } else { rng.uniform() as f64 - 0.5 })
                .collect()
        };
        let (y, z) = (random(), random());
        let (my, mz) = (precondition(&h, &y), precondition(&h, &z));
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(p, q)| p * q).sum::<f64>();
        let (zmy, ymz) = (dot(&z, &my), dot(&y, &mz));
        assert!((zmy - ymz).abs() <= 1e-5 * (dot(&y, &my) * dot(&z, &mz)).sqrt(), "{zmy} vs {ymz}");
        assert!(dot(&y, &my) > 0.0 && dot(&z, &mz) > 0.0);
    }

    #[test]
    fn first_coarse_operator_aggregates_the_unscaled_operator() {
        // Two levels: the finest one and the direct one, whose matrix (L Lᵀ) must be P₀ᵀ A P₀ for
        // the piecewise-constant prolongation P₀ of the operator as assembled (not scaled).
        let (s, _) = sun_lit_system([11, 9, 8], 4, 0.9, 0.8, Vec3::new(0.2, 1.0, 0.3), 0);
        let n = s.nodes.len();
        let h = Hierarchy::build_with(&s.rows(), n - 1);
        assert_eq!(h.levels(), 2);
        let (_, parent, _) = coarsen(&s.rows());
        let nc = parent.iter().max().unwrap() + 1;
        let nc = nc as usize;
        let a = dense(&s);
        let mut g = vec![0.0; nc * nc];
        for u in 0..n {
            for v in 0..n {
                g[parent[u] as usize * nc + parent[v] as usize] += a[u * n + v];
            }
        }
        let c = &h.coarse;
        assert_eq!(c.cells.len(), nc);
        // The coarse level's unknowns in its entries' order: map them to the aggregates (box order).
        let coarse_unk: Vec<usize> = c.cells.iter().map(|e| h.levels[1].unknown(*e) as usize).collect();
        for (q, cq) in coarse_unk.iter().enumerate() {
            for (r, cr) in coarse_unk.iter().enumerate() {
                let llt: f64 = (0..=q.min(r)).map(|k| c.l[q * nc + k] * c.l[r * nc + k]).sum();
                let want = g[cq * nc + cr] * super::pow2(-h.levels[0].unit);
                assert!((llt - want).abs() <= 1e-9 * want.abs().max(1e-3), "{llt} vs {want}");
            }
        }
        // The finest level holds its rows' sums; the coarse ones their diagonals.
        assert!(h.levels[0].row_sums && !h.levels[1].row_sums);
    }

    #[test]
    fn coded_neighbours_and_couplings_are_the_plain_ones() {
        // A random sparse cloud, some couplings 0, and its coarse operator: each row's decoded
        // neighbours are those found from the cells, its couplings (the −a ones read from the −a
        // neighbours' rows) the operator's, and a missing neighbour (or one coupled by 0) has
        // coupling 0 and reads an entry of the other colour (its pad for a −a one).
        let (mut fine, _) = sun_lit_system([13, 11, 9], 3, 0.95, 0.8, Vec3::new(0.2, 1.0, 0.3), 0);
        for (u, nd) in fine.nodes.iter_mut().enumerate() {
            if u % 7 == 0 {
                nd.up[u % 3] = 0.0;
            }
        }
        let coarse = coarsen(&fine.rows()).0;
        for s in [fine, coarse] {
            for narrow in [true, false] {
                assert!(matches!(coded_rows_match(&s, narrow).rows, Rows::Narrow(_)) == narrow);
            }
        }
    }

    #[test]
    fn planes_too_wide_for_u16_distances_keep_u32_ones() {
        // A full 370×370×2 box: a red cell's +z neighbour lies 68 450 black entries after its
        // `base` (2^16 = 65 536), so the level keeps u32 ±z distances, and they decode right.
        let dims = [370, 370, 2];
        let n = dims.iter().product::<usize>();
        let nodes = (0..n)
            .map(|c| {
                let (i, j, k) = (c % dims[0], (c / dims[0]) % dims[1], c / (dims[0] * dims[1]));
                let mut nd = Node::at(c as u32);
                nd.diag = 7.0;
                for (ax, (at, stride)) in [(i, 1), (j, dims[0]), (k, dims[0] * dims[1])].into_iter().enumerate() {
                    if at + 1 < dims[ax] {
                        (nd.up_nbr[ax], nd.up[ax]) = ((c + stride) as u32, -1.0 - (c % 5) as f64 / 8.0);
                    }
                }
                nd
            })
            .collect();
        let s = Operator { dims, nodes };
        assert!(matches!(coded_rows_match(&s, true).rows, Rows::Wide(_)));
    }

    #[test]
    fn runs_rebuild_every_row() {
        // A box with a shaft through it and scattered holes, over three chunks of entries: each
        // entry's row rebuilt from its run decodes to the operator's neighbours and couplings
        // (u16 and u32 ±z distances); walking the runs from any entry (chunk boundaries
        // included) rebuilds the rows a lookup does; the runs are maximal, and few.
        let dims = [40, 30, 12];
        let mut rng = Rng::new(5, 3);
        let full: Vec<bool> = (0..dims.iter().product::<usize>())
            .map(|c| {
                let (i, j) = ((c % dims[0]) as i32, ((c / dims[0]) % dims[1]) as i32);
                let shaft = (i - 20).pow(2) + (j - 15).pow(2) < 16;
                !shaft && rng.uniform() > 0.01
            })
            .collect();
        let cells: Vec<usize> = (0..full.len()).filter(|c| full[*c]).collect();
        let mut unknown = vec![NONE; full.len()];
        for (u, c) in cells.iter().enumerate() {
            unknown[*c] = u as u32;
        }
        let nodes = cells
            .iter()
            .map(|&c| {
                let ijk = [c % dims[0], (c / dims[0]) % dims[1], c / (dims[0] * dims[1])];
                let mut nd = Node::at(c as u32);
                nd.diag = 7.0;
                for (ax, stride) in [1, dims[0], dims[0] * dims[1]].into_iter().enumerate() {
                    if ijk[ax] + 1 < dims[ax] && full[c + stride] {
                        (nd.up_nbr[ax], nd.up[ax]) = (unknown[c + stride], -1.0 - (c % 5) as f64 / 8.0);
                    }
                }
                nd
            })
            .collect();
        let s = Operator { dims, nodes };
        assert!(s.nodes.len() > 3 * CHUNK);
        for narrow in [true, false] {
            let level = coded_rows_match(&s, narrow);
            assert!(matches!(level.rows, Rows::Narrow(_)) == narrow);
            with_rows!(&level, |c| {
                assert_eq!(c.runs[0].start, 0);
                for w in c.runs.windows(2) {
                    assert!(w[0].start < w[1].start && w[0].link_at(w[1].start as usize) != w[1].link);
                }
                let rows: Vec<_> = (0..c.len()).map(|e| c.row(e)).collect();
                let n = c.len();
                for start in [0, 1, CHUNK - 1, CHUNK, CHUNK + 1, 2 * CHUNK, c.red, c.red + 1, n - 1, n] {
                    let end = n.min(start + CHUNK + 3);
                    let mut walked = Vec::new();
                    c.each_row(start..end, |e, row| walked.push((e, row)));
                    let looked_up: Vec<_> = (start..end).zip(rows[start..end].iter().copied()).collect();
                    assert_eq!(walked, looked_up, "from {start}");
                }
                // u32 rows with no −z neighbour end their runs (the bottom plane, the holes).
                let most = if narrow { n / 4 } else { n / 2 };
                assert!(c.runs.len() < most, "{} runs for {n} entries", c.runs.len());
            });
        }
    }

    #[test]
    fn u16_and_u32_rows_solve_alike() {
        // The same hierarchy with every level's ±z distances in u32: the same iterates, bit for
        // bit.
        let (s, b) = sun_lit_system([15, 13, 11], 5, 0.99, 0.85, Vec3::new(0.3, 1.0, 0.2), 1);
        let [narrow, wide] = [true, false].map(|n| Hierarchy::build_coded(&s.rows(), 16, n));
        assert!(narrow.levels.iter().all(|l| matches!(l.rows, Rows::Narrow(_))));
        assert!(wide.levels.iter().all(|l| matches!(l.rows, Rows::Wide(_))));
        let [(xn, sn), (xw, sw)] = [narrow, wide].map(|h| h.solve(&b, None, 1e-10, 100));
        assert!(sn.iterations > 2 && sn.relative_residual <= 1e-10, "{sn:?}");
        assert_eq!((sn.iterations, sn.history), (sw.iterations, sw.history));
        assert!(xn.iter().zip(&xw).all(|(a, b)| a.to_bits() == b.to_bits()));
    }

    #[test]
    fn operator_scale_does_not_change_the_solve() {
        // An operator and right-hand side times 2^±100 (couplings of µm or Gm voxels, far outside
        // the codes' scales' range, 2⁻²²³ … 2³¹, unless divided by the hierarchy's unit): the
        // same solution, bit for bit, and the same iterations.
        let (s, b) = sun_lit_system([13, 11, 9], 7, 0.99, 0.85, Vec3::new(0.3, 1.0, 0.2), 0);
        let base = Hierarchy::build_with(&s.rows(), 16).solve(&b, None, 1e-9, 100);
        assert!(base.1.iterations > 2 && base.1.relative_residual <= 1e-9, "{:?}", base.1);
        for k in [100, -100] {
            let f = super::pow2(k);
            let mut t = s.clone();
            for nd in &mut t.nodes {
                nd.diag *= f;
                nd.up = nd.up.map(|v| v * f);
            }
            let h = Hierarchy::build_with(&t.rows(), 16);
            assert_eq!(h.levels[0].unit, Hierarchy::build_with(&s.rows(), 16).levels[0].unit + k);
            let bt: Vec<f64> = b.iter().map(|v| v * f).collect();
            let (x, st) = h.solve(&bt, None, 1e-9, 100);
            assert_eq!(st.history, base.1.history, "2^{k}");
            assert!(x.iter().zip(&base.0).all(|(p, q)| p.to_bits() == q.to_bits()), "2^{k}");
        }
    }

    /// Checks the decoded rows of the level of `s` (u16 ±z distances allowed with `narrow`);
    /// returns the level.
    fn coded_rows_match(s: &Operator, narrow: bool) -> Level {
        let rows = s.rows();
        let (level, entry) = Level::from_stencils(&rows, false, narrow, Some(0), super::Maxima::all(&rows));
        let by_cell: HashMap<usize, usize> = s.nodes.iter().enumerate().map(|(u, n)| (n.cell as usize, u)).collect();
        let [nx, ny, _] = s.dims;
        let (mut seen, mut coupled) = (0, 0);
        for e in 0..level.len() {
            let u = level.unknown(e);
            // The other colour's entries, its pad last.
            let other = if e <= level.red {
                level.red + 1..level.len()
            } else {
                0..level.red + 1
            };
            let pad = other.end - 1;
            let got = level.neighbours(e);
            let cpl = level.couplings(e, &got).0;
            if u == PAD {
                assert!(e == level.red || e + 1 == level.len());
                assert_eq!((cpl, got), ([0.0; 6], [pad as u32; 6]));
                continue;
            }
            assert_eq!(entry[u as usize] as usize, e, "entry {e}'s unknown");
            seen += 1;
            let (nd, cell) = (&s.nodes[u as usize], s.nodes[u as usize].cell as usize);
            for (q, stride) in [1, 1, nx, nx, nx * ny, nx * ny].into_iter().enumerate() {
                let ax = q / 2;
                let at = if q % 2 == 0 {
                    cell.checked_sub(stride)
                } else {
                    Some(cell + stride)
                };
                let v = at
                    .and_then(|c| by_cell.get(&c))
                    .copied()
                    .filter(|v| rows.ijk(*v)[(ax + 1) % 3] == rows.ijk(u as usize)[(ax + 1) % 3]);
                let coupling = v.map_or(0.0, |v| if q % 2 == 0 { s.nodes[v].up[ax] } else { nd.up[ax] });
                match v {
                    Some(v) if coupling != 0.0 => {
                        assert_eq!(got[q], entry[v], "entry {e} neighbour {q}");
                        let coded = f64::from(cpl[q]);
                        assert!((coded - coupling).abs() <= coupling.abs() / 4096.0, "entry {e} coupling {q}");
                        coupled += 1;
                    }
                    _ if q % 2 == 0 => assert!(cpl[q] == 0.0 && got[q] as usize == pad, "entry {e} neighbour {q}"),
                    _ => assert!(cpl[q] == 0.0 && other.contains(&(got[q] as usize)), "entry {e} neighbour {q}"),
                }
            }
        }
        assert_eq!(seen, s.nodes.len());
        assert!(coupled > 3 * seen, "{coupled} couplings for {seen} unknowns");
        level
    }

    #[test]
    fn iterations_stay_few() {
        // The coarse space piecewise constant in the unscaled unknowns: a random cloud with optical
        // depths over four decades per voxel converges in 17 iterations to 1e-6 (piecewise constant
        // in the unknowns scaled to unit diagonal it needed 32 here).
        let m = random_cloud([26, 22, 18], 11, 0.999, 0.85);
        let inc = lit(&m, 1.0, Some((Vec3::new(0.3, 1.0, 0.2), 3.0)));
        let dom = Domain::of(&m).unwrap();
        let (s, b) = assemble(&m, &inc, &BoundaryLight::none(), 0, 1e-3, &dom);
        let h = Hierarchy::build_with(&s.rows(), 64);
        let (_, st) = h.solve(&b, None, 1e-6, 200);
        assert!(st.relative_residual <= 1e-6 && st.iterations <= 20, "{st:?}");
    }
}
