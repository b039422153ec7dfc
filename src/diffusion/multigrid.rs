//! Matrix-free geometric multigrid on the voxel lattice, used as the preconditioner of conjugate
//! gradients (MGPCG, McAdams et al. 2010).
//!
//! * **Operator.** A symmetric 7-point stencil. Callers assemble it straight onto its unknowns as
//!   an [`Operator`] (each unknown's box cell, diagonal and +x, +y, +z couplings and neighbours);
//!   [`Hierarchy::build`] turns every level into a [`Level`] that stores its unknowns with their
//!   six neighbours' indices and couplings. Nothing is stored per cell of the box (the cloud fills
//!   about half of its tight box), so the memory and the work scale with the unknowns.
//! * **Coarsening** by 2×2×2 aggregation with Galerkin coarse operators Aᶜ = PᵀAP: the first
//!   with the smoothed prolongation P = (I − ω D⁻¹A) P₀ (P₀ piecewise constant), whose
//!   iterations barely grow with the size; the next ones piecewise constant, their correction
//!   scaled by [`OVER_CORRECTION`]. The coarse operators are general sparse rows ([`Coarse`]).
//!   A coarse cell exists where any child is full.
//! * **Smoother:** red-black Gauss–Seidel on the finest level (red then black before the coarse
//!   correction, black then red after it), multicolour Gauss–Seidel on the coarse ones (colours
//!   in order before, in reverse after), so the cycle is a symmetric preconditioner.
//! * **Cycle:** W on the finest level, V below it.
//! * **Coarsest level** (≤ [`COARSE_CELLS`] unknowns): dense Cholesky, exact.
//! * **Determinism:** updates within a colour are independent; reductions sum fixed-size chunks'
//!   partial sums in order. Bit-identical at any thread count.

use super::SolveStats;
use rayon::prelude::*;

/// Unknowns at or below which a level is solved directly.
pub const COARSE_CELLS: usize = 800;

/// Default [`Hierarchy::over_correction`]. Piecewise-constant prolongation under-corrects smooth
/// errors (the interpolant jumps at every aggregate face, so PᵀAP overestimates a smooth error's
/// energy and the correction comes out too small), so the correction is scaled up (Braess 1995). Measured on the procedural cloud at tolerance
/// 1e-6 (iterations per band at 50×40×30, 100×80×60, 200×160×120): 1.0 → 31/36/46, 1.3 → 29/33/40,
/// 1.5 → 28/32/38, 1.6 → 28/32/38, at no cost per iteration. A K-cycle (a Krylov step on every
/// level) and two smoothing sweeps were tried and did not do better per unit of work.
pub const OVER_CORRECTION: f64 = 1.5;

/// Rows per parallel task (and per partial sum of the reductions: fixed, so sums do not depend
/// on the thread count).
const CHUNK: usize = 4096;

/// Marks a pad entry in [`Level::unk`].
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

impl Operator {
    /// Cell (i, j, k) of unknown `u`.
    fn ijk(&self, u: usize) -> [usize; 3] {
        let [nx, ny, _] = self.dims;
        let c = self.nodes[u].cell as usize;
        [c % nx, (c / nx) % ny, c / (nx * ny)]
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

/// The multigrid's scalar: the cycle is only a preconditioner of the f64 CG, and single
/// precision halves its memory traffic (iterations unchanged at tolerance 1e-6, and 1e-12 is
/// still reached).
type Mg = f32;

/// One row of a [`Level`]: the couplings to the six neighbours (−x, +x, −y, +y, −z, +z), the
/// diagonal and the neighbours' entries.
#[derive(Clone, Copy, Debug)]
struct Row {
    cpl: [Mg; 6],
    diag: Mg,
    nbr: [u32; 6],
}

/// One level's operator on its unknowns only.
///
/// Entries `0..red` are the unknowns of colour 0 ((i + j + k) even) in box order, entry `red` a
/// pad, then the unknowns of colour 1 and a last pad. A level's vectors have one value per entry
/// and right-hand side (`[T; K]`, the K systems that share the operator solved together, so the
/// rows are read once for all of them); the pads hold 0 and stand in for missing neighbours (a
/// coupling of 0 to the other colour's pad), so the rows need no branches and a colour's pass
/// reads only the other colour.
#[derive(Clone, Debug)]
struct Level {
    red: usize,
    rows: Vec<Row>,
    /// The [`Operator`]'s unknown per entry; [`PAD`] on the pads.
    unk: Vec<u32>,
}

/// Σ_q cpl_q · x[nbr_q − off] per system: a row's off-diagonal part, `x` the slice of entries
/// from `off` on.
#[inline]
fn couple<const K: usize>(row: &Row, x: &[[Mg; K]], off: usize) -> [Mg; K] {
    let n = row.nbr.map(|q| &x[q as usize - off]);
    std::array::from_fn(|k| {
        let v = |q: usize| row.cpl[q] * n[q][k];
        (v(0) + v(1)) + (v(2) + v(3)) + (v(4) + v(5))
    })
}

impl Level {
    /// The level of operator `a` and each unknown's entry. `want_plus` also returns each entry's
    /// +x, +y, +z couplings in f64 (the finest level's operator for CG).
    fn from_operator(a: &Operator, want_plus: bool) -> (Level, Vec<u32>, Vec<[f64; 3]>) {
        let n = a.nodes.len();
        let colour = |u: usize| a.ijk(u).iter().sum::<usize>() % 2;
        let red = (0..n).filter(|u| colour(*u) == 0).count();
        let mut entry = vec![0u32; n];
        let mut unk = vec![PAD; n + 2];
        let mut next = [0, red + 1];
        for (u, e) in entry.iter_mut().enumerate() {
            let c = colour(u);
            *e = next[c] as u32;
            unk[next[c]] = u as u32;
            next[c] += 1;
        }
        // Each unknown's −x, −y, −z neighbours: the unknowns whose +a neighbour it is.
        let mut down = vec![[NONE; 3]; n];
        for (u, nd) in a.nodes.iter().enumerate() {
            for ax in 0..3 {
                if nd.up_nbr[ax] != NONE {
                    down[nd.up_nbr[ax] as usize][ax] = u as u32;
                }
            }
        }
        let pads = [(n + 1) as u32, red as u32];
        let mut plus = vec![[0.0; 3]; if want_plus { n + 2 } else { 0 }];
        let row = |e: usize, u: u32, up: &mut [f64; 3]| {
            if u == PAD {
                return Row {
                    cpl: [0.0; 6],
                    diag: 0.0,
                    nbr: [e as u32; 6],
                };
            }
            let nd = &a.nodes[u as usize];
            let mut row = Row {
                cpl: [0.0; 6],
                diag: Mg::of(nd.diag),
                nbr: [pads[usize::from(e > red)]; 6],
            };
            for ax in 0..3 {
                let d = down[u as usize][ax];
                if d != NONE && a.nodes[d as usize].up[ax] != 0.0 {
                    row.nbr[2 * ax] = entry[d as usize];
                    row.cpl[2 * ax] = Mg::of(a.nodes[d as usize].up[ax]);
                }
                if nd.up_nbr[ax] != NONE && nd.up[ax] != 0.0 {
                    row.nbr[2 * ax + 1] = entry[nd.up_nbr[ax] as usize];
                    row.cpl[2 * ax + 1] = Mg::of(nd.up[ax]);
                    up[ax] = nd.up[ax];
                }
            }
            row
        };
        // Written in place (an unzip would hold a second copy while it gathers its pieces).
        let rows: Vec<Row> = if want_plus {
            unk.par_iter()
                .zip(plus.par_iter_mut())
                .enumerate()
                .map(|(e, (u, p))| row(e, *u, p))
                .collect()
        } else {
            unk.par_iter().enumerate().map(|(e, u)| row(e, *u, &mut [0.0; 3])).collect()
        };
        let level = Level { red, rows, unk };
        (level, entry, plus)
    }

    /// Entries, pads included (the length of the level's vectors).
    fn len(&self) -> usize {
        self.rows.len()
    }

    fn unknowns(&self) -> usize {
        self.len() - 2
    }

    /// r = b − A x on the red unknowns. Called right after a black pass, which leaves the black
    /// residuals at zero, so r's black entries (and pads) keep the zeros they start with.
    fn residual_red<const K: usize>(&self, x: &[[Mg; K]], b: &[[Mg; K]], r: &mut [[Mg; K]]) {
        let (xr, xb) = x.split_at(self.red + 1);
        r[..self.red].par_chunks_mut(CHUNK).enumerate().for_each(|(ci, rs)| {
            let first = ci * CHUNK;
            for (t, rv) in rs.iter_mut().enumerate() {
                let e = first + t;
                let row = &self.rows[e];
                let s = couple(row, xb, self.red + 1);
                *rv = std::array::from_fn(|k| b[e][k] - (row.diag * xr[e][k] + s[k]));
            }
        });
    }

    /// The first red pass from x = 0: x = b / diag on the red unknowns, 0 elsewhere.
    fn smooth_red_from_zero<const K: usize>(&self, x: &mut [[Mg; K]], b: &[[Mg; K]]) {
        x.par_chunks_mut(CHUNK).enumerate().for_each(|(ci, xs)| {
            let first = ci * CHUNK;
            for (t, xv) in xs.iter_mut().enumerate() {
                let e = first + t;
                *xv = if e < self.red {
                    b[e].map(|v| v / self.rows[e].diag)
                } else {
                    [0.0; K]
                };
            }
        });
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
        mine.par_chunks_mut(CHUNK).enumerate().for_each(|(ci, xs)| {
            let start = first + ci * CHUNK;
            for (t, xv) in xs.iter_mut().enumerate() {
                let row = &self.rows[start + t];
                let s = couple(row, other, off);
                *xv = std::array::from_fn(|k| (b[start + t][k] - s[k]) / row.diag);
            }
        });
    }
}

/// A sparse matrix by rows in f64: the setup's form of the operators and the transfers.
#[derive(Clone, Debug)]
struct Csr {
    start: Vec<u32>,
    col: Vec<u32>,
    val: Vec<f64>,
}

impl Csr {
    fn from_rows<R: AsRef<[(u32, f64)]>>(rows: &[R]) -> Csr {
        let nnz = rows.iter().map(|r| r.as_ref().len()).sum();
        let (mut start, mut col, mut val) = (Vec::with_capacity(rows.len() + 1), Vec::with_capacity(nnz), Vec::with_capacity(nnz));
        start.push(0);
        for r in rows {
            for (c, v) in r.as_ref() {
                col.push(*c);
                val.push(*v);
            }
            start.push(col.len() as u32);
        }
        Csr { start, col, val }
    }

    /// The operator's matrix, one row per unknown (diagonal first, then the couplings).
    fn of_operator(a: &Operator) -> Csr {
        let n = a.nodes.len();
        // Each unknown's −x, −y, −z neighbours: the unknowns whose +a neighbour it is.
        let mut down = vec![[NONE; 3]; n];
        for (u, nd) in a.nodes.iter().enumerate() {
            for ax in 0..3 {
                if nd.up_nbr[ax] != NONE {
                    down[nd.up_nbr[ax] as usize][ax] = u as u32;
                }
            }
        }
        let rows: Vec<Small> = (0..n)
            .into_par_iter()
            .map(|u| {
                let nd = &a.nodes[u];
                let mut r = Small::default();
                r.push(u as u32, nd.diag);
                for (ax, &d) in down[u].iter().enumerate() {
                    if d != NONE && a.nodes[d as usize].up[ax] != 0.0 {
                        r.push(d, a.nodes[d as usize].up[ax]);
                    }
                    if nd.up_nbr[ax] != NONE && nd.up[ax] != 0.0 {
                        r.push(nd.up_nbr[ax], nd.up[ax]);
                    }
                }
                r
            })
            .collect();
        Csr::from_rows(&rows)
    }

    fn rows(&self) -> usize {
        self.start.len() - 1
    }

    fn row(&self, r: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let s = self.start[r] as usize..self.start[r + 1] as usize;
        self.col[s.clone()].iter().map(|c| *c as usize).zip(self.val[s].iter().copied())
    }

    /// The transpose (`cols` rows), each row's entries in increasing column.
    fn transpose(&self, cols: usize) -> Csr {
        let mut start = vec![0u32; cols + 1];
        for c in &self.col {
            start[*c as usize + 1] += 1;
        }
        for i in 0..cols {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        let (mut col, mut val) = (vec![0; self.col.len()], vec![0.0; self.col.len()]);
        for r in 0..self.rows() {
            for (c, v) in self.row(r) {
                let f = &mut fill[c];
                col[*f as usize] = r as u32;
                val[*f as usize] = v;
                *f += 1;
            }
        }
        Csr { start, col, val }
    }
}

/// Colours of the coarse levels' Gauss–Seidel: (i mod 3, j mod 3, k mod 3) of the cell. Their rows
/// reach at most 2 cells along an axis (smoothed aggregation's first coarse level; 1 below it),
/// so the unknowns of a colour never couple and update in parallel.
const COLOURS: usize = 27;

/// Colour of `cell` in a box of `dims`.
fn colour(cell: u32, dims: [usize; 3]) -> usize {
    let c = cell as usize;
    let [i, j, k] = [c % dims[0], (c / dims[0]) % dims[1], c / (dims[0] * dims[1])];
    i % 3 + 3 * (j % 3) + 9 * (k % 3)
}

/// 2×2×2 aggregation of the unknowns at `cells` of a box of `dims`: the coarse box, its
/// unknowns' cells (one where any child is an unknown; by colour, then in box order) and each
/// unknown's aggregate.
fn aggregate(cells: &[u32], dims: [usize; 3], f: usize) -> ([usize; 3], Vec<u32>, Vec<u32>) {
    let [nx, ny, _] = dims;
    let cd = dims.map(|d| d.div_ceil(f));
    let keys: Vec<u32> = cells
        .par_iter()
        .map(|c| {
            let c = *c as usize;
            let [i, j, k] = [c % nx, (c / nx) % ny, c / (nx * ny)];
            (i / f + cd[0] * (j / f + cd[1] * (k / f))) as u32
        })
        .collect();
    let mut sorted = keys.clone();
    sorted.par_sort_unstable();
    sorted.dedup();
    let mut coarse = sorted.clone();
    coarse.par_sort_unstable_by_key(|c| (colour(*c, cd), *c));
    let mut rank = vec![0u32; coarse.len()];
    for (r, c) in coarse.iter().enumerate() {
        rank[sorted.binary_search(c).expect("a coarse cell")] = r as u32;
    }
    let parent = keys
        .par_iter()
        .map(|k| rank[sorted.binary_search(k).expect("every aggregate is a coarse unknown")])
        .collect();
    (cd, coarse, parent)
}

/// The prolongation of aggregation `parent`: piecewise constant (`omega` 0), or smoothed,
/// P = (I − ω D⁻¹A) P₀. Smoothing makes the coarse functions overlap, so a smooth error is
/// interpolated without the jumps at the aggregates' faces that slow piecewise-constant
/// aggregation on finer (optically thinner) grids.
fn prolongation(a: &Csr, parent: &[u32], omega: f64) -> Csr {
    let rows: Vec<Small> = (0..a.rows())
        .into_par_iter()
        .map(|u| {
            let mut r = Small::default();
            r.push(parent[u], 1.0);
            if omega == 0.0 {
                return r;
            }
            let d = a.row(u).find(|(j, _)| *j == u).map_or(1.0, |(_, v)| v);
            for (j, v) in a.row(u) {
                // Equal columns add in the row's order, the same at any thread count.
                let (c, w) = (parent[j], -omega * v / d);
                match r.e[..r.n].iter_mut().find(|e| e.0 == c) {
                    Some(e) => e.1 += w,
                    None => r.push(c, w),
                }
            }
            r.e[..r.n].sort_unstable_by_key(|e| e.0);
            r
        })
        .collect();
    Csr::from_rows(&rows)
}

/// A row of at most 8 entries (the 7-point operator's, the smoothed prolongation's).
#[derive(Clone, Copy, Default)]
struct Small {
    n: usize,
    e: [(u32, f64); 8],
}

impl Small {
    fn push(&mut self, c: u32, v: f64) {
        self.e[self.n] = (c, v);
        self.n += 1;
    }
}

impl AsRef<[(u32, f64)]> for Small {
    fn as_ref(&self) -> &[(u32, f64)] {
        &self.e[..self.n]
    }
}

/// The product of `a` and `b` (`b.rows()` = `a`'s columns, `cols` its own), row by row; each
/// entry's terms add in a fixed order, the same at any thread count.
fn product(a: &Csr, b: &Csr, cols: usize) -> Csr {
    let n = a.rows();
    let chunks: Vec<Csr> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|ci| {
            let (mut acc, mut seen, mut cs) = (vec![0.0f64; cols], vec![false; cols], Vec::<u32>::new());
            let mut out = Csr {
                start: vec![0],
                col: Vec::new(),
                val: Vec::new(),
            };
            for i in ci * CHUNK..n.min((ci + 1) * CHUNK) {
                for (e, w) in a.row(i) {
                    for (c, q) in b.row(e) {
                        if !seen[c] {
                            seen[c] = true;
                            cs.push(c as u32);
                        }
                        acc[c] += w * q;
                    }
                }
                cs.sort_unstable();
                for c in &cs {
                    let c = *c as usize;
                    seen[c] = false;
                    out.col.push(c as u32);
                    out.val.push(std::mem::take(&mut acc[c]));
                }
                out.start.push(out.col.len() as u32);
                cs.clear();
            }
            out
        })
        .collect();
    let mut out = Csr {
        start: vec![0],
        col: Vec::new(),
        val: Vec::new(),
    };
    for c in chunks {
        let off = out.col.len() as u32;
        out.start.extend(c.start[1..].iter().map(|s| s + off));
        out.col.extend(c.col);
        out.val.extend(c.val);
    }
    out
}

/// The Galerkin product PᵀAP (`pt` = Pᵀ): Pᵀ(AP).
fn galerkin(a: &Csr, p: &Csr, pt: &Csr) -> Csr {
    let nc = pt.rows();
    product(pt, &product(a, p, nc), nc)
}

/// A sparse matrix by rows in the multigrid's precision.
#[derive(Clone, Debug)]
struct Rows {
    start: Vec<u32>,
    col: Vec<u32>,
    val: Vec<Mg>,
}

impl Rows {
    /// `a`'s entries, columns renumbered by `col_of`, rows placed by `row_at` (rows not placed
    /// are empty) in `n` rows; the diagonal apart when `diag` is given.
    fn of(a: &Csr, n: usize, row_at: &[u32], col_of: impl Fn(usize) -> u32, mut diag: Option<&mut Vec<Mg>>) -> Rows {
        let mut src = vec![usize::MAX; n];
        for (r, at) in row_at.iter().enumerate() {
            src[*at as usize] = r;
        }
        let (mut start, mut col, mut val) = (vec![0], Vec::new(), Vec::new());
        for (at, r) in src.iter().enumerate() {
            if *r != usize::MAX {
                for (c, v) in a.row(*r) {
                    match diag.as_deref_mut() {
                        Some(d) if c == *r => d[at] = Mg::of(v),
                        _ => {
                            col.push(col_of(c));
                            val.push(Mg::of(v));
                        }
                    }
                }
            }
            start.push(col.len() as u32);
        }
        Rows { start, col, val }
    }

    #[inline]
    fn row(&self, r: usize) -> (&[u32], &[Mg]) {
        let s = self.start[r] as usize..self.start[r + 1] as usize;
        (&self.col[s.clone()], &self.val[s])
    }

    /// Σ_c a_rc x_c per system.
    #[inline]
    fn dot_row<const K: usize>(&self, r: usize, x: &[[Mg; K]]) -> [Mg; K] {
        let (c, v) = self.row(r);
        let mut s = [0.0; K];
        for (c, v) in c.iter().zip(v) {
            let xc = &x[*c as usize];
            for k in 0..K {
                s[k] += v * xc[k];
            }
        }
        s
    }

    fn bytes(&self) -> usize {
        4 * (self.start.len() + self.col.len()) + std::mem::size_of::<Mg>() * self.val.len()
    }
}

/// The transfer between a level and the next coarser one: P by the finer level's vector entries,
/// Pᵀ by the coarser one's, and the scale of the coarse correction.
#[derive(Clone, Debug)]
struct Transfer {
    p: Rows,
    pt: Rows,
    weight: Mg,
}

impl Transfer {
    /// b = Pᵀ r.
    fn restrict<const K: usize>(&self, r: &[[Mg; K]], b: &mut [[Mg; K]]) {
        b.par_chunks_mut(CHUNK).enumerate().for_each(|(ci, bs)| {
            for (t, v) in bs.iter_mut().enumerate() {
                *v = self.pt.dot_row(ci * CHUNK + t, r);
            }
        });
    }

    /// x += w P xc on the entries `0..n`.
    fn prolong<const K: usize>(&self, x: &mut [[Mg; K]], xc: &[[Mg; K]], n: usize) {
        x[..n].par_chunks_mut(CHUNK).enumerate().for_each(|(ci, xs)| {
            for (t, v) in xs.iter_mut().enumerate() {
                let c = self.p.dot_row(ci * CHUNK + t, xc);
                for k in 0..K {
                    v[k] += self.weight * c[k];
                }
            }
        });
    }

    fn bytes(&self) -> usize {
        self.p.bytes() + self.pt.bytes()
    }
}

/// A coarse level: its Galerkin operator in general rows (smoothed aggregation couples an
/// aggregate to more than its six face neighbours), smoothed by multicolour Gauss–Seidel
/// ([`COLOURS`]), colours in order before the coarse correction and in reverse order after it
/// (a symmetric cycle). The unknowns are stored by colour.
#[derive(Clone, Debug)]
struct Coarse {
    diag: Vec<Mg>,
    off: Rows,
    /// The unknowns of colour c: `colour_start[c]..colour_start[c + 1]`.
    colour_start: Vec<usize>,
}

/// Rows per parallel task of a coarse level's colour pass (a colour of the first coarse level
/// has a few thousand).
const COARSE_CHUNK: usize = 256;

impl Coarse {
    /// The level of matrix `a`, whose unknowns are at `cells` (by colour) of a box of `dims`.
    fn of(a: &Csr, cells: &[u32], dims: [usize; 3]) -> Coarse {
        let n = a.rows();
        let col: Vec<usize> = cells.iter().map(|c| colour(*c, dims)).collect();
        let mut colour_start = vec![0; COLOURS + 1];
        for c in &col {
            colour_start[c + 1] += 1;
        }
        for c in 0..COLOURS {
            colour_start[c + 1] += colour_start[c];
        }
        assert!(col.windows(2).all(|w| w[0] <= w[1]), "unknowns stored by colour");
        for r in 0..n {
            assert!(
                a.row(r).all(|(c, _)| c == r || col[c] != col[r]),
                "a colour's unknowns do not couple"
            );
        }
        let mut diag = vec![0.0; n];
        let at: Vec<u32> = (0..n as u32).collect();
        let off = Rows::of(a, n, &at, |c| c as u32, Some(&mut diag));
        Coarse { diag, off, colour_start }
    }

    fn len(&self) -> usize {
        self.diag.len()
    }

    /// One Gauss–Seidel pass over the unknowns of colour `c`: each reads only the others.
    fn pass<const K: usize>(&self, x: &mut [[Mg; K]], b: &[[Mg; K]], c: usize) {
        let (s, e) = (self.colour_start[c], self.colour_start[c + 1]);
        let (head, rest) = x.split_at_mut(s);
        let (mine, tail) = rest.split_at_mut(e - s);
        let (head, tail) = (&*head, &*tail);
        mine.par_chunks_mut(COARSE_CHUNK).enumerate().for_each(|(ci, xs)| {
            for (t, xv) in xs.iter_mut().enumerate() {
                let i = s + ci * COARSE_CHUNK + t;
                let (cols, vals) = self.off.row(i);
                let mut sum = [0.0; K];
                for (j, v) in cols.iter().zip(vals) {
                    let j = *j as usize;
                    let xj = if j < s { &head[j] } else { &tail[j - e] };
                    for k in 0..K {
                        sum[k] += v * xj[k];
                    }
                }
                *xv = std::array::from_fn(|k| (b[i][k] - sum[k]) / self.diag[i]);
            }
        });
    }

    fn forward<const K: usize>(&self, x: &mut [[Mg; K]], b: &[[Mg; K]]) {
        for c in 0..COLOURS {
            self.pass(x, b, c);
        }
    }

    fn backward<const K: usize>(&self, x: &mut [[Mg; K]], b: &[[Mg; K]]) {
        for c in (0..COLOURS).rev() {
            self.pass(x, b, c);
        }
    }

    /// r = b − A x.
    fn residual<const K: usize>(&self, x: &[[Mg; K]], b: &[[Mg; K]], r: &mut [[Mg; K]]) {
        r.par_chunks_mut(CHUNK).enumerate().for_each(|(ci, rs)| {
            for (t, rv) in rs.iter_mut().enumerate() {
                let i = ci * CHUNK + t;
                let s = self.off.dot_row(i, x);
                *rv = std::array::from_fn(|k| b[i][k] - (self.diag[i] * x[i][k] + s[k]));
            }
        });
    }

    fn bytes(&self) -> usize {
        self.off.bytes() + std::mem::size_of::<Mg>() * self.diag.len()
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

/// The CG step y += α p, r −= α q per system, and r in the multigrid's precision into `rm`;
/// returns r·r (summed as [`dot`] does).
fn cg_step<const K: usize>(
    y: &mut [[f64; K]],
    r: &mut [[f64; K]],
    rm: &mut [[Mg; K]],
    p: &[[f64; K]],
    q: &[[f64; K]],
    alpha: [f64; K],
) -> [f64; K] {
    let parts: Vec<[f64; K]> = y
        .par_chunks_mut(CHUNK)
        .zip(r.par_chunks_mut(CHUNK))
        .zip(rm.par_chunks_mut(CHUNK))
        .zip(p.par_chunks(CHUNK).zip(q.par_chunks(CHUNK)))
        .map(|(((ys, rs), rms), (ps, qs))| {
            let mut s = [0.0; K];
            for ((((yv, rv), rmv), pv), qv) in ys.iter_mut().zip(rs.iter_mut()).zip(rms.iter_mut()).zip(ps).zip(qs) {
                for k in 0..K {
                    yv[k] += alpha[k] * pv[k];
                    rv[k] -= alpha[k] * qv[k];
                    rmv[k] = Mg::of(rv[k]);
                    s[k] += rv[k] * rv[k];
                }
            }
            s
        })
        .collect();
    sum_parts(&parts)
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
    /// The factor of matrix `a`, whose row q is the level's vector entry `cells[q]`.
    fn build(a: &Csr, cells: Vec<usize>) -> Dense {
        let n = cells.len();
        let mut l = vec![0f64; n * n];
        for q in 0..n {
            for (r, v) in a.row(q) {
                l[q * n + r] += v;
            }
        }
        cholesky_in_place(&mut l, n);
        // Lᵀ into the upper triangle: the backward substitution then reads rows too.
        for i in 0..n {
            for j in 0..i {
                l[j * n + i] = l[i * n + j];
            }
        }
        Dense { cells, l }
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

/// Vectors of one multigrid level's cycle: its residual and the next level's right-hand side
/// and correction.
struct Work<const K: usize> {
    r: Vec<[Mg; K]>,
    bc: Vec<[Mg; K]>,
    xc: Vec<[Mg; K]>,
}

/// The multigrid hierarchy of one (diagonally scaled) operator.
#[derive(Clone, Debug)]
pub struct Hierarchy {
    /// D^{-1/2} of the finest operator per entry of the finest level (0 on the pads).
    scale: Vec<f64>,
    /// The scaled finest operator's +x, +y, +z couplings per entry in f64 (its diagonal is 1):
    /// the operator CG solves.
    plus: Vec<[f64; 3]>,
    /// The finest level (scaled).
    fine: Level,
    /// Levels 1, 2, …; the last one (or the finest, if there is none) is solved directly.
    coarse_levels: Vec<Coarse>,
    /// The transfers between level l and l + 1.
    transfers: Vec<Transfer>,
    coarse: Dense,
    /// Coarse-grid visits from the finest level (1: V-cycle, 2: W-cycle).
    pub cycle: usize,
    /// Red-black sweeps before and after the coarse correction on the finest level.
    pub sweeps: usize,
}

/// Damping ω of the prolongation's smoothing. 4 / (3 ρ(D⁻¹A)) = 2/3 (ρ ≤ 2) gave 29/34/39
/// iterations per band at the three bench sizes, 0.8 24/27/29, 0.9 21/23/24 (with
/// [`SMOOTHED_OVER_CORRECTION`]); 1 makes an isolated cell's interpolation weight 1 − ω vanish.
const SMOOTHING: f64 = 0.9;

/// Scale of the correction from the smoothed-aggregation level.
const SMOOTHED_OVER_CORRECTION: f64 = 1.4;

impl Hierarchy {
    /// Scale `a` to unit diagonal and build the levels down to [`COARSE_CELLS`] unknowns.
    pub fn build(a: Operator) -> Hierarchy {
        Self::build_with(a, COARSE_CELLS)
    }

    /// As [`Hierarchy::build`], coarsening until a level has at most `coarse_cells` unknowns.
    /// The first coarsening is smoothed aggregation, the next ones piecewise-constant
    /// aggregation of the coarse levels (smoothing there too would widen their rows at every
    /// level: 125 neighbours, then 343).
    pub fn build_with(mut a: Operator, coarse_cells: usize) -> Hierarchy {
        let scale_of: Vec<f64> = a.nodes.iter().map(|n| 1.0 / n.diag.sqrt()).collect();
        a.nodes.par_iter_mut().enumerate().for_each(|(u, n)| {
            for ax in 0..3 {
                if n.up_nbr[ax] != NONE {
                    n.up[ax] *= scale_of[u] * scale_of[n.up_nbr[ax] as usize];
                }
            }
            n.diag = 1.0;
        });
        let (fine, entry, plus) = Level::from_operator(&a, true);
        let scale = fine
            .unk
            .iter()
            .map(|u| if *u == PAD { 0.0 } else { scale_of[*u as usize] })
            .collect();
        drop(scale_of);
        let mut dims = a.dims;
        let mut cells: Vec<u32> = a.nodes.iter().map(|n| n.cell).collect();
        let mut op = Csr::of_operator(&a);
        drop(a);
        let (mut coarse_levels, mut transfers) = (Vec::new(), Vec::new());
        while op.rows() > coarse_cells && dims.iter().any(|d| *d > 1) {
            let first = transfers.is_empty();
            let (cd, cc, parent) = aggregate(&cells, dims, 2);
            let p = prolongation(&op, &parent, if first { SMOOTHING } else { 0.0 });
            let pt = p.transpose(cc.len());
            let next = galerkin(&op, &p, &pt);
            // On the finest level P's rows and Pᵀ's columns are its vector entries.
            let (fine_len, at): (usize, Vec<u32>) = if first {
                (fine.len(), entry.clone())
            } else {
                (op.rows(), (0..op.rows() as u32).collect())
            };
            let all: Vec<u32> = (0..cc.len() as u32).collect();
            transfers.push(Transfer {
                p: Rows::of(&p, fine_len, &at, |c| c as u32, None),
                pt: Rows::of(&pt, cc.len(), &all, |f| at[f], None),
                weight: Mg::of(if first { SMOOTHED_OVER_CORRECTION } else { OVER_CORRECTION }),
            });
            coarse_levels.push(Coarse::of(&next, &cc, cd));
            (op, dims, cells) = (next, cd, cc);
        }
        let coarse = if coarse_levels.is_empty() {
            Dense::build(&op, entry.iter().map(|e| *e as usize).collect())
        } else {
            Dense::build(&op, (0..op.rows()).collect())
        };
        Hierarchy {
            scale,
            plus,
            fine,
            coarse_levels,
            transfers,
            coarse,
            cycle: 2,
            sweeps: 1,
        }
    }

    /// Number of levels (including the direct one).
    #[cfg(test)]
    pub fn levels(&self) -> usize {
        1 + self.coarse_levels.len()
    }

    /// Length of level l's vectors.
    fn len(&self, l: usize) -> usize {
        if l == 0 {
            self.fine.len()
        } else {
            self.coarse_levels[l - 1].len()
        }
    }

    /// Bytes the hierarchy holds.
    fn bytes(&self) -> usize {
        self.fine.rows.len() * std::mem::size_of::<Row>()
            + 4 * self.fine.unk.len()
            + self.coarse_levels.iter().map(Coarse::bytes).sum::<usize>()
            + self.transfers.iter().map(Transfer::bytes).sum::<usize>()
            + 8 * self.scale.len()
            + 24 * self.plus.len()
            + 8 * (self.coarse.l.len() + self.coarse.cells.len())
    }

    /// One cycle on level `l` for A_l x = b, x starting at zero; `work` holds the vectors of
    /// levels l and below.
    fn cycle<const K: usize>(&self, l: usize, b: &[[Mg; K]], x: &mut [[Mg; K]], work: &mut [Work<K>]) {
        if l == self.coarse_levels.len() {
            self.coarse.solve(b, x);
            return;
        }
        let (w, rest) = work.split_first_mut().expect("a work entry per level above the coarsest");
        let t = &self.transfers[l];
        // The finest level visits the next one `cycle` times (unless it is the direct one); the
        // coarse levels once (a V-cycle below the smoothed-aggregation level: more visits cost
        // more than they save).
        let visits = if l == 0 && self.coarse_levels.len() > 1 {
            self.cycle.max(1)
        } else {
            1
        };
        if l == 0 {
            // Red, black before the corrections; black, red after; a symmetric black-red-black
            // between the two corrections of a W-cycle (its red-red pair in the middle is one
            // pass: a second red pass recomputes the same values).
            let s = &self.fine;
            s.smooth_red_from_zero(x, b);
            s.smooth(x, b, 1);
            for _ in 1..self.sweeps {
                s.smooth(x, b, 0);
                s.smooth(x, b, 1);
            }
            for visit in 0..visits {
                s.residual_red(x, b, &mut w.r);
                t.restrict(&w.r, &mut w.bc);
                self.cycle(l + 1, &w.bc, &mut w.xc, rest);
                // The red entries only: the black pass that follows overwrites the black ones.
                t.prolong(x, &w.xc, s.red);
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
        } else {
            let s = &self.coarse_levels[l - 1];
            x.fill([0.0; K]);
            s.forward(x, b);
            s.residual(x, b, &mut w.r);
            t.restrict(&w.r, &mut w.bc);
            self.cycle(l + 1, &w.bc, &mut w.xc, rest);
            t.prolong(x, &w.xc, s.len());
            s.backward(x, b);
        }
    }

    /// y = A x with the scaled finest operator in f64 (unit diagonal, couplings `plus`, each
    /// −a coupling read from the −a neighbour's +a one); returns x·y (summed as [`dot`] does).
    fn apply<const K: usize>(&self, x: &[[f64; K]], y: &mut [[f64; K]]) -> [f64; K] {
        let rows = &self.fine.rows;
        let parts: Vec<[f64; K]> = y
            .par_chunks_mut(CHUNK)
            .enumerate()
            .map(|(ci, ys)| {
                let first = ci * CHUNK;
                let mut xy = [0.0; K];
                for (t, yv) in ys.iter_mut().enumerate() {
                    let e = first + t;
                    let (nb, up) = (&rows[e].nbr, &self.plus[e]);
                    let v = |q: usize, c: f64, k: usize| c * x[nb[q] as usize][k];
                    for k in 0..K {
                        let s = (v(0, self.plus[nb[0] as usize][0], k) + v(1, up[0], k))
                            + (v(2, self.plus[nb[2] as usize][1], k) + v(3, up[1], k))
                            + (v(4, self.plus[nb[4] as usize][2], k) + v(5, up[2], k));
                        yv[k] = x[e][k] + s;
                        xy[k] += x[e][k] * yv[k];
                    }
                }
                xy
            })
            .collect();
        sum_parts(&parts)
    }

    /// Solve A x = b (unscaled A, as assembled; `b`, `x0` and the result per unknown) by MGPCG
    /// from `x0` (or zero) to relative residual `tol` of the scaled system, at most `max_iter`
    /// iterations.
    pub fn solve(&self, b: &[f64], x0: Option<&[f64]>, tol: f64, max_iter: usize) -> (Vec<f64>, SolveStats) {
        let [out] = self.solve_many([b], x0.map(|x| [x]), tol, max_iter);
        out
    }

    /// [`Hierarchy::solve`] for K right-hand sides at once (the bands that share the operator):
    /// each system's iterates are exactly those of its own solve, and the rows are read once per
    /// pass for all of them.
    pub fn solve_many<const K: usize>(
        &self,
        b: [&[f64]; K],
        x0: Option<[&[f64]; K]>,
        tol: f64,
        max_iter: usize,
    ) -> [(Vec<f64>, SolveStats); K] {
        let a = &self.fine;
        let gather = |v: [&[f64]; K], f: fn(f64, f64) -> f64| -> Vec<[f64; K]> {
            assert!(v.iter().all(|v| v.len() == a.unknowns()), "one value per unknown");
            a.unk
                .par_iter()
                .zip(&self.scale)
                .map(|(u, s)| if *u == PAD { [0.0; K] } else { v.map(|v| f(v[*u as usize], *s)) })
                .collect()
        };
        let bs = gather(b, |v, s| v * s);
        let mut y = match x0 {
            Some(x) => gather(x, |v, s| v / s),
            None => vec![[0.0; K]; a.len()],
        };
        let stats = self.solve_scaled(&bs, &mut y, tol, max_iter);
        let mut lane = 0;
        stats.map(|st| {
            let mut out = vec![0.0; a.unknowns()];
            for ((u, v), s) in a.unk.iter().zip(&y).zip(&self.scale) {
                if *u != PAD {
                    out[*u as usize] = v[lane] * s;
                }
            }
            lane += 1;
            (out, st)
        })
    }

    /// MGPCG on the scaled systems A y = bs (vectors on the finest level's entries), each system
    /// stopping on its own.
    fn solve_scaled<const K: usize>(&self, bs: &[[f64; K]], y: &mut [[f64; K]], tol: f64, max_iter: usize) -> [SolveStats; K] {
        let a = &self.fine;
        let n = a.len();
        let bnorm = dot(bs, bs).map(f64::sqrt);
        let mut stats: [SolveStats; K] = std::array::from_fn(|_| SolveStats {
            iterations: 0,
            relative_residual: 0.0,
            history: Vec::new(),
            unknowns: a.unknowns(),
            levels: 1 + self.coarse_levels.len(),
            bytes_per_unknown: 0.0,
        });
        let mut work: Vec<Work<K>> = (0..self.coarse_levels.len())
            .map(|l| Work {
                r: vec![[0.0; K]; self.len(l)],
                bc: vec![[0.0; K]; self.len(l + 1)],
                xc: vec![[0.0; K]; self.len(l + 1)],
            })
            .collect();
        let (mut r, mut ap, mut p) = (vec![[0f64; K]; n], vec![[0f64; K]; n], vec![[0f64; K]; n]);
        let (mut rm, mut z) = (vec![[0.0; K]; n], vec![[0.0; K]; n]);
        // The hierarchy; bs, y, r, p and A p in f64; r and z in the multigrid's precision, and
        // three vectors per level in `work` (the caller's b and x, per unknown, not counted).
        let lanes = |v: usize, bytes: usize| v * bytes * K;
        let held = self.bytes()
            + lanes(5 * n, 8)
            + lanes(2 * n, std::mem::size_of::<Mg>())
            + (0..self.coarse_levels.len())
                .map(|l| lanes(self.len(l) + 2 * self.len(l + 1), std::mem::size_of::<Mg>()))
                .sum::<usize>();
        for st in &mut stats {
            st.bytes_per_unknown = held as f64 / (K * a.unknowns().max(1)) as f64;
        }
        // r = bs − A y.
        let residual = |y: &[[f64; K]], r: &mut Vec<[f64; K]>, ap: &mut Vec<[f64; K]>| {
            self.apply(y, ap);
            r.par_iter_mut()
                .zip(bs.par_iter().zip(&*ap))
                .for_each(|(r, (b, q))| *r = std::array::from_fn(|k| b[k] - q[k]));
        };
        residual(y, &mut r, &mut ap);
        rm.par_iter_mut().zip(&r).for_each(|(m, v)| *m = v.map(Mg::of));
        let rr = dot(&r, &r);
        let mut active = [false; K];
        for k in 0..K {
            if bnorm[k] == 0.0 {
                y.iter_mut().for_each(|v| v[k] = 0.0);
                stats[k].history.push(0.0);
            } else {
                let rel = rr[k].sqrt() / bnorm[k];
                stats[k].history.push(rel);
                active[k] = rel > tol;
            }
        }
        if active.iter().any(|a| *a) {
            self.cycle(0, &rm, &mut z, &mut work);
            p.par_iter_mut().zip(&z).for_each(|(p, z)| *p = z.map(Real::get));
            let mut rz = dot(&r, &z);
            let mut iterations = 0;
            while iterations < max_iter {
                let pap = self.apply(&p, &mut ap);
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
                let rr = cg_step(y, &mut r, &mut rm, &p, &ap, alpha);
                iterations += 1;
                for k in 0..K {
                    if !active[k] {
                        continue;
                    }
                    stats[k].iterations += 1;
                    let rel = rr[k].sqrt() / bnorm[k];
                    stats[k].history.push(rel);
                    active[k] = rel > tol;
                }
                if !active.iter().any(|a| *a) {
                    break;
                }
                self.cycle(0, &rm, &mut z, &mut work);
                let rz_new = dot(&r, &z);
                let beta: [f64; K] = std::array::from_fn(|k| if active[k] { rz_new[k] / rz[k] } else { 0.0 });
                rz = rz_new;
                p.par_iter_mut()
                    .zip(&z)
                    .for_each(|(q, zz)| *q = std::array::from_fn(|k| zz[k].get() + beta[k] * q[k]));
            }
        }
        // Report the true residuals.
        residual(y, &mut r, &mut ap);
        let rr = dot(&r, &r);
        for k in 0..K {
            if bnorm[k] > 0.0 {
                stats[k].relative_residual = rr[k].sqrt() / bnorm[k];
            }
        }
        stats
    }
}

/// The assembled operator (eq. 4 with eq. 7) and the solver, against dense linear algebra
/// (moved here from tests/ so the solver's internals need not be public).
#[cfg(test)]
mod operator_tests {
    use super::{aggregate, galerkin, prolongation, Coarse, Csr, Hierarchy, Operator, NONE};
    use crate::diffusion::{assemble, BoundaryLight, Domain};
    use crate::incident::{compute, IncidentLight, IncidentSettings, IncidentSources};
    use crate::lighting::DirectionBins;
    use crate::math::{Rgb, Rng, Vec3};
    use crate::medium::{Grid3, Medium};

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
            let h = Hierarchy::build_with(s.clone(), 16);
            assert!(h.levels() >= 4, "levels {}", h.levels());
            let (x, st) = h.solve(&b, None, 1e-12, 500);
            assert!(st.relative_residual <= 1e-12, "{st:?}");
            let xd = dense_solve(dense(&s), b.clone());
            let num: f64 = x.iter().zip(&xd).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt();
            let den: f64 = xd.iter().map(|v| v * v).sum::<f64>().sqrt();
            assert!(num / den < 1e-8, "relative difference {}", num / den);
        }
    }

    #[test]
    fn systems_solved_together_match_their_own_solves_exactly() {
        let m = random_cloud([12, 10, 9], 5, 0.97, 0.8);
        let inc = lit(&m, 1.0, Some((Vec3::new(0.3, 1.0, -0.2), 2.0)));
        let dom = Domain::of(&m).unwrap();
        let (s, b) = assemble(&m, &inc, &BoundaryLight::none(), 0, 1e-3, &dom);
        let h = Hierarchy::build_with(s, 16);
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
    fn coarse_operator_is_the_galerkin_product() {
        // Odd box sides: the last aggregates of each axis are one cell thick.
        let m = random_cloud([11, 9, 8], 4, 0.9, 0.8);
        let inc = lit(&m, 1.0, Some((Vec3::new(0.2, 1.0, 0.3), 2.0)));
        let dom = Domain::of(&m).unwrap();
        let (s, _) = assemble(&m, &inc, &BoundaryLight::none(), 0, 1e-3, &dom);
        let a = Csr::of_operator(&s);
        let cells: Vec<u32> = s.nodes.iter().map(|n| n.cell).collect();
        let (cd, cc, parent) = aggregate(&cells, s.dims, 2);
        let (n, nc) = (s.nodes.len(), cc.len());
        assert!(nc > 10 && nc < n, "{nc} of {n}");
        assert_eq!(cd, [s.dims[0].div_ceil(2), s.dims[1].div_ceil(2), s.dims[2].div_ceil(2)]);
        for (u, p) in parent.iter().enumerate() {
            let [i, j, k] = s.ijk(u);
            assert_eq!(cc[*p as usize] as usize, i / 2 + cd[0] * (j / 2 + cd[1] * (k / 2)));
        }
        let ad = dense(&s);
        for omega in [0.0, 2.0 / 3.0, 0.9] {
            let p = prolongation(&a, &parent, omega);
            // P = (I − ω D⁻¹A) P₀ densely, then PᵀAP.
            let mut pd = vec![0.0; n * nc];
            for u in 0..n {
                pd[u * nc + parent[u] as usize] += 1.0;
                for v in 0..n {
                    pd[u * nc + parent[v] as usize] -= omega * ad[u * n + v] / ad[u * n + u];
                }
            }
            for u in 0..n {
                let mut row = vec![0.0; nc];
                for (c, v) in p.row(u) {
                    row[c] += v;
                }
                for c in 0..nc {
                    assert!((row[c] - pd[u * nc + c]).abs() <= 1e-12, "P[{u}][{c}]");
                }
            }
            let mut ap = vec![0.0; n * nc];
            for u in 0..n {
                for v in 0..n {
                    if ad[u * n + v] != 0.0 {
                        for c in 0..nc {
                            ap[u * nc + c] += ad[u * n + v] * pd[v * nc + c];
                        }
                    }
                }
            }
            let g = galerkin(&a, &p, &p.transpose(nc));
            for i in 0..nc {
                let mut row = vec![0.0; nc];
                for (c, v) in g.row(i) {
                    row[c] += v;
                }
                for j in 0..nc {
                    let x: f64 = (0..n).map(|u| pd[u * nc + i] * ap[u * nc + j]).sum();
                    assert!((x - row[j]).abs() <= 1e-12 * x.abs().max(1.0), "ω {omega}: {x} vs {}", row[j]);
                    let t = g.row(j).find(|e| e.0 == i).map_or(0.0, |e| e.1);
                    assert!((t - row[j]).abs() <= 1e-12 * t.abs().max(1.0), "symmetric: {t} vs {}", row[j]);
                }
            }
            // The coarse level's colours never couple.
            let _ = Coarse::of(&g, &cc, cd);
        }
    }
}
