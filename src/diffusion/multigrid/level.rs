//! One level of the hierarchy ([`Level`]): its coded rows read through [`Coded`], and the
//! cycle's kernels on it: red-black Gauss–Seidel ([`Level::smooth`]), the restriction of the
//! residual and the prolongation of the correction.

use super::codec::{code_rows, pow2, unit_of, Codes, Dz, Mg, Plain, Real, RowAt, Rows, Run, Runs};
use super::operator::{row_sum, Maxima, Operator, Stencils};
use crate::par::{for_chunks, map_each};
use super::{CHUNK, NONE, PAD};
use crate::half::Scaled16;

/// A [`Level`]'s rows with their type known ([`with_rows`]), their scales and its number of red
/// entries: what the passes read.
pub(super) struct Coded<'a, Z> {
    pub(super) red: usize,
    pub(super) codes: &'a [Codes],
    pub(super) runs: &'a [Run<Z>],
    /// The scales of a row's own codes (+x, +y, +z couplings and [`Row::own`](super::codec::Row::own):
    /// [`Level::cpl_scale`] ×3, [`Level::own_scale`]) and of its −a neighbours' couplings (and
    /// a zero lane), as [`Scaled16::decode4`] takes them.
    pub(super) mine: [f32; 4],
    pub(super) theirs: [f32; 4],
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
pub(super) use with_rows;

/// One level's operator on its unknowns only.
///
/// Entries `0..red` are the unknowns of colour 0 ((i + j + k) even) in box order, entry `red` a
/// pad, then the unknowns of colour 1 and a last pad. A level's vectors have one value per entry
/// and right-hand side (`[T; K]`, the K systems that share the operator solved together, so the
/// rows are read once for all of them); the pads hold 0 and stand in for missing neighbours (a
/// coupling of 0 to the other colour's pad), so the rows need no branches and a colour's pass
/// reads only the other colour.
///
/// No level is scaled to unit diagonal (that would take, on the finest level, a scale D^-½, a fix of
/// its rounding and the prolongation weights D^½: 10 B per unknown). Gauss–Seidel does not depend
/// on a diagonal scaling S, and PCG on S A S with the preconditioner S M S has the iterates of PCG
/// on A with M, so the cycle works on the unknowns as assembled; its coarse space, piecewise
/// constant in them, holds the errors the smoother leaves, which are smooth in them. (Piecewise
/// constant in the scaled unknowns it needed 22/26/29 iterations at 50×40×30/100×80×60/
/// 200×160×120 instead of 9/8/6.)
#[derive(Clone, Debug)]
pub(super) struct Level {
    pub(super) red: usize,
    /// Each row's [`Row::own`](super::codec::Row::own) holds its sum, its diagonal plus its six couplings, computed in
    /// f64 from the assembled row and rounded once (the finest level), not its diagonal; the
    /// diagonal is that sum less the row's stored couplings ([`less_couplings`]). CG's operator
    /// ([`Coded::apply_row`]) so keeps every assembled row sum to its own rounding: the
    /// absorption and the boundary's leakage (A·1 for a uniform fluence), tiny against the
    /// couplings in a thick cloud, which a rounded diagonal would move by far more (in f32 by up
    /// to ~10⁻⁴ of themselves: the 100×80×60 cloud's `diffusion` image moved by 2.9·10⁻⁶, block
    /// mean relative error, against 2·10⁻⁹ with f32 sums).
    pub(super) row_sums: bool,
    pub(super) rows: Rows,
    /// The scales of the rows' codes ([`Scaled16`]): −2^k for the couplings (stored negated:
    /// they are ≤ 0), 2^k for the sums or diagonals, each k from the level's largest value
    /// ([`Scaled16::exponent_for`]). Values below ~2⁻²⁹ of the largest read 0.
    pub(super) cpl_scale: f32,
    pub(super) own_scale: f32,
    /// The power of two 2^-unit that the whole hierarchy's operator is stored scaled by (the
    /// finest level's, [`unit_of`]): the solve scales the right-hand sides alike.
    pub(super) unit: i32,
    /// Entry of the next coarser level holding each red entry (only the red ones are
    /// prolonged: [`Level::prolong_red`]); empty on the coarsest level.
    pub(super) parent: Vec<u32>,
    /// Per z plane of the level's box, and one past the last: the first red entry of the finer
    /// level aggregated into it (those of two finer planes, contiguous, as the red entries are
    /// in box order) and its first red and black entries (each colour in box order). A plane's
    /// entries have their red children in its range and no others, so the restriction is one
    /// task per plane, each adding its children in their order ([`Level::restrict_residual`]).
    /// Empty on the finest level.
    pub(super) planes: Vec<[u32; 3]>,
}

/// A row's diagonal from its sum `sum` and its couplings `c` (−x, +x, −y, +y, −z, +z):
/// sum − Σ c (in the precision of `T`).
#[inline(always)]
pub(super) fn less_couplings<T: Copy + std::ops::Add<Output = T> + std::ops::Sub<Output = T>>(sum: T, c: [T; 6]) -> T {
    sum - ((c[0] + c[1]) + (c[2] + c[3]) + (c[4] + c[5]))
}

/// The other colour's entries `off..off + x.len()` (its pad last) as the rows of one colour read
/// them: their values and codes (for their +x, +y, +z couplings), and the couplings' scale.
pub(super) struct OtherColour<'a, const K: usize> {
    pub(super) x: &'a [[Mg; K]],
    pub(super) codes: &'a [Codes],
    /// [`Coded::mine`], [`Coded::theirs`].
    pub(super) mine: [f32; 4],
    pub(super) theirs: [f32; 4],
}

impl<'a, const K: usize> OtherColour<'a, K> {
    /// The other colour of the level of rows `level` whose values, from entry `off` on, are `x`.
    pub(super) fn of<Z>(level: &Coded<'a, Z>, x: &'a [[Mg; K]], off: usize) -> Self {
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
    pub(super) fn couple<Z: Dz>(&self, row: &RowAt<Z>) -> ([Mg; K], [Mg; 6], Mg) {
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
/// [`Row::own`](super::codec::Row::own) and its couplings: one copy of the pass per rule, so its
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

impl<'a, Z: Dz> Coded<'a, Z> {
    /// `level`'s passes' view of its `runs` (the level's own [`Rows`] variant).
    #[inline(always)]
    pub(super) fn of(level: &'a Level, runs: &'a Runs<Z>) -> Coded<'a, Z> {
        Coded {
            red: level.red,
            codes: &runs.codes,
            runs: &runs.runs,
            mine: level.scales(),
            theirs: [level.cpl_scale; 4],
        }
    }

    /// Entries, pads included.
    pub(super) fn len(&self) -> usize {
        self.codes.len()
    }

    /// The run holding entry `e`.
    pub(super) fn run_of(&self, e: usize) -> usize {
        self.runs.partition_point(|r| r.start as usize <= e) - 1
    }

    /// Entry e's row, rebuilt from its run (found by a binary search: the passes walk the runs,
    /// [`Coded::each_row`]).
    pub(super) fn row(&self, e: usize) -> RowAt<'a, Z> {
        self.runs[self.run_of(e)].at(e, &self.codes[e])
    }

    /// `f(e, row, o)` for each entry e from `first` on in order, its row rebuilt from its run
    /// and its codes, and `o` its value of `out` (one per entry, from `first`): the first run
    /// found by a binary search, then each in turn.
    #[inline(always)]
    pub(super) fn each_row_into<T>(&self, first: usize, out: &mut [T], mut f: impl FnMut(usize, RowAt<'a, Z>, &mut T)) {
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
    pub(super) fn each_row(&self, range: std::ops::Range<usize>, mut f: impl FnMut(usize, RowAt<'a, Z>)) {
        let mut none = vec![(); range.len()];
        self.each_row_into(range.start, &mut none, |e, row, _| f(e, row));
    }

    /// The [`Operator`]'s unknown at entry `e` ([`PAD`] on the pads), whose row is `row`: the
    /// unknowns of its colour before it plus those of the other colour (its row's `base`).
    #[inline(always)]
    pub(super) fn unknown_of(&self, e: usize, row: &RowAt<Z>) -> u32 {
        let black = self.red + 1;
        match e {
            _ if e == self.red || e + 1 == self.len() => PAD,
            _ if e < self.red => (e + row.base() as usize) as u32,
            _ => (e - black + row.base() as usize) as u32,
        }
    }

    /// The [`Operator`]'s unknown at entry `e`: [`Coded::unknown_of`].
    pub(super) fn unknown(&self, e: usize) -> u32 {
        self.unknown_of(e, &self.row(e))
    }

    /// Entry e's neighbours' entries (−x, +x, −y, +y, −z, +z; [`Row::neighbours`] of its row
    /// `row`, counted from the level's first entry).
    #[inline(always)]
    pub(super) fn neighbours(&self, e: usize, row: &RowAt<Z>) -> [u32; 6] {
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
    pub(super) fn couplings(&self, row: &RowAt<Z>, nbr: &[u32; 6]) -> ([Mg; 6], Mg) {
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
    pub(super) fn residual_red<const K: usize>(
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
    pub(super) fn finest_row(&self, e: usize, row: &RowAt<Z>) -> ([u32; 6], [f64; 6], f64) {
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
    pub(super) fn apply_row<X: Real, const K: usize>(&self, e: usize, row: &RowAt<Z>, x: &[[X; K]]) -> ([f64; K], f64) {
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
    pub(super) fn from_stencils(a: &impl Stencils, row_sums: bool, narrow: bool, unit: Option<i32>, m: Maxima) -> (Level, Vec<u32>) {
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
    pub(super) fn scales(&self) -> [f32; 4] {
        let c = self.cpl_scale;
        [c, c, c, self.own_scale]
    }

    /// The [`Operator`]'s unknown at entry `e` ([`PAD`] on the pads): [`Coded::unknown`] (a
    /// binary search over the runs: a pass over the entries takes [`Level::unknowns_in_order`]).
    pub(super) fn unknown(&self, e: usize) -> u32 {
        with_rows!(self, |c| c.unknown(e))
    }

    /// Each entry's unknown ([`PAD`] on the pads), in order of the entries.
    pub(super) fn unknowns_in_order(&self) -> Vec<u32> {
        let mut u = Vec::with_capacity(self.len());
        with_rows!(self, |c| c.each_row(0..c.len(), |e, row| u.push(c.unknown_of(e, &row))));
        u
    }

    /// Entry e's neighbours' entries: [`Coded::neighbours`].
    #[cfg(test)]
    pub(super) fn neighbours(&self, e: usize) -> [u32; 6] {
        with_rows!(self, |c| c.neighbours(e, &c.row(e)))
    }

    /// Entry e's couplings to its neighbours `nbr` and its decoded [`Row::own`]:
    /// [`Coded::couplings`].
    #[cfg(test)]
    pub(super) fn couplings(&self, e: usize, nbr: &[u32; 6]) -> ([Mg; 6], Mg) {
        with_rows!(self, |c| c.couplings(&c.row(e), nbr))
    }

    /// Entries, pads included (the length of the level's vectors).
    pub(super) fn len(&self) -> usize {
        self.rows.len()
    }

    pub(super) fn unknowns(&self) -> usize {
        self.len() - 2
    }

    /// Record that `coarse`, of operator `op`, aggregates this level: each red entry's parent
    /// (from each unknown's aggregate `parent` and the coarse unknowns' entries `coarse_entry`)
    /// and the ranges of the coarse level's planes ([`Level::planes`]). Only the red entries
    /// are linked: a black pass before every restriction of the cycle leaves the black
    /// residuals at zero, and one after every prolongation overwrites the black values.
    pub(super) fn link(&mut self, parent: &[u32], coarse: &mut Level, coarse_entry: &[u32], op: &Operator) {
        let plane_cells = (op.dims[0] * op.dims[1]) as u32;
        let plane = |cu: u32| (op.nodes[cu as usize].cell / plane_cells) as usize;
        let mut parents = vec![0; self.red];
        for_chunks(&mut parents, CHUNK, &|ci, ps| {
            for (p, e) in ps.iter_mut().zip(ci * CHUNK..) {
                *p = coarse_entry[parent[self.unknown(e) as usize] as usize];
            }
        });
        self.parent = parents;
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
    pub(super) fn restrict_residual<const K: usize>(&self, fine: &Level, xf: &[[Mg; K]], bf: &[[Mg; K]], b: &mut [[Mg; K]]) {
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
        with_rows!(fine, |rows| with_diagonal!(fine, |diag| map_each(
            tasks,
            &|_, (start, end, red, black)| {
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
        )));
    }

    /// The first red pass from x = 0: x = b / diag on the red unknowns, 0 elsewhere (the finest
    /// level's diagonals from its rows' sums and couplings: this pass reads its rows).
    pub(super) fn smooth_red_from_zero<const K: usize>(&self, x: &mut [[Mg; K]], b: &[[Mg; K]]) {
        let red = self.red;
        for_chunks(&mut x[red..], CHUNK, &|_, xs| xs.fill([0.0; K]));
        with_rows!(self, |rows| for_chunks(&mut x[..red], CHUNK, &|ci, xs| {
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
    pub(super) fn smooth<const K: usize>(&self, x: &mut [[Mg; K]], b: &[[Mg; K]], colour: usize) {
        let red = self.red;
        let (xr, xb) = x.split_at_mut(red + 1);
        let black = xb.len() - 1;
        let (mine, other, first, off) = if colour == 0 {
            (&mut xr[..red], &*xb, 0, red + 1)
        } else {
            (&mut xb[..black], &*xr, red + 1, 0)
        };
        with_rows!(self, |coded| with_diagonal!(self, |diag| for_chunks(mine, CHUNK, &|ci, xs| {
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
    pub(super) fn prolong_red<const K: usize>(&self, x: &mut [[Mg; K]], xc: &[[Mg; K]], w: Mg) {
        for_chunks(&mut x[..self.red], CHUNK, &|ci, xs| {
            for (v, p) in xs.iter_mut().zip(&self.parent[ci * CHUNK..]) {
                let c = &xc[*p as usize];
                for k in 0..K {
                    v[k] += w * c[k];
                }
            }
        });
    }
}
