//! The levels' rows in 16-bit codes: a [`Row`]'s 8 B of codes per entry, its neighbours'
//! coding once per run of entries that share it ([`Runs`]), narrow (u16) or wide (u32) ±z
//! distances ([`Rows`]), and the hierarchy's power-of-two scale ([`unit_of`]).

use crate::par::map_chunks;
use super::CHUNK;
use crate::half::Scaled16;
use std::sync::atomic::{AtomicBool, Ordering};

/// The scalar of the multigrid levels ([`Level`](super::level::Level)) and of the CG vectors.
pub(super) trait Real: Copy + Send + Sync {
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
pub(super) type Mg = f32;

/// One row of a [`Level`](super::level::Level): its couplings to its +x, +y, +z neighbours, its sum (or diagonal)
/// and where the entries of the six neighbours (−x, +x, −y, +y, −z, +z) lie (20 B with `Z` =
/// u16, 24 B with u32; stored as [`Runs`]: its codes per entry, the rest per run). The couplings and the sum are 16-bit codes ([`Scaled16`],
/// ≤ 2⁻¹² relative, under a power-of-two scale per level and field); in f32 beside 24 B rows
/// they would take 28 B per unknown. The −a couplings are read from the −a neighbours' rows (a
/// separate array of couplings, 16 + 12 B, takes as many instructions as 40 B rows with all six,
/// but puts `full`'s peak at 200×160×120 4 MB above the rows', through the allocator).
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
pub(super) struct Row<Z> {
    /// The other colour's first entry after this unknown (its unknowns before this one), and
    /// the [`NO_MINUS_X`] flag.
    pub(super) base: u32,
    /// Couplings to the +x, +y, +z neighbours, negated (they are ≤ 0) and coded at the level's
    /// [`Level::cpl_scale`](super::level::Level::cpl_scale) (0 to a missing one, and on the pads): each face's coupling is
    /// stored once, and a row's −a coupling is its −a neighbour's +a one.
    pub(super) up: [Scaled16; 3],
    /// The row's sum (the finest level: [`Level::row_sums`](super::level::Level::row_sums)) or its diagonal, coded at the
    /// level's [`Level::own_scale`](super::level::Level::own_scale) (0 on the pads).
    pub(super) own: Scaled16,
    /// Entries from `base` back to the −y neighbour and on to the +y one.
    pub(super) dy: [u16; 2],
    /// Entries from `base` back to the −z neighbour and on to the +z one.
    pub(super) dz: [Z; 2],
}

/// The type of a [`Row`]'s ±z distances: u16 where they all fit (fewer than 2^16 of the other
/// colour's entries between any cell and its ±z neighbours: every level of the clouds measured,
/// up to 400×320×240), else u32. Each level picks once ([`Rows`]); the passes are compiled per
/// type ([`with_rows`](super::level::with_rows)).
pub(super) trait Dz: Copy + Default + PartialEq + Send + Sync + std::fmt::Debug + Into<u32> {
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
pub(super) const NO_MINUS_X: u32 = 1 << 31;

/// Widest box (cells along x) the solver takes: a row's ±y distances, at most half a box row of
/// the other colour's entries, are stored in a u16. The command line and the library's `render`
/// refuse a wider cloud before any work (`medium.downsample` is the fix); a build past them panics.
pub const MAX_BOX_ROW_CELLS: usize = 2 * u16::MAX as usize;

impl<Z: Dz> Row<Z> {
    /// The row of coded couplings `up` and sum (or diagonal) `own` and of the neighbours' entries
    /// `nbr` (`pad`, the other colour's
    /// pad, for a missing neighbour), `base` the other colour's first entry after the unknown
    /// (all counted from the other colour's first entry); `None` if a ±z distance does not fit
    /// in `Z`.
    pub(super) fn encode(up: [Scaled16; 3], own: Scaled16, nbr: [u32; 6], base: u32, pad: u32) -> Option<Row<Z>> {
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
    pub(super) fn codes(&self) -> Codes {
        Codes {
            up: self.up,
            own: self.own,
        }
    }

    /// Its neighbours' coding, stored per run ([`Runs`]).
    pub(super) fn link(&self) -> Link<Z> {
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
pub(super) struct Codes {
    pub(super) up: [Scaled16; 3],
    pub(super) own: Scaled16,
}

/// A [`Row`]'s neighbours' coding: [`Row::base`] with the [`NO_MINUS_X`] flag, ±y and ±z
/// distances.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Link<Z> {
    pub(super) base: u32,
    pub(super) dy: [u16; 2],
    pub(super) dz: [Z; 2],
}

/// A maximal range of a level's consecutive entries whose rows' [`Link`]s are one: `link` at
/// its first entry `start`, its `base` one more at each entry after (same distances and flag).
/// Along a box row inside the cloud a colour's unknowns are every second cell, and the other
/// colour's unknown between two of them advances `base` by one: the procedural cloud's finest
/// level has ~12 unknowns per run (200×160×120: 30 387 runs for 356 296 unknowns). (A u32 row
/// with no −z neighbour codes that distance from `base`, [`Dz::missing_minus`], so it ends a
/// run: such rows are wide only where a plane is too large for u16 distances.)
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Run<Z> {
    pub(super) start: u32,
    pub(super) link: Link<Z>,
}

impl<Z: Dz> Run<Z> {
    /// The link of entry `e` of the run (at or after `start`).
    #[inline(always)]
    pub(super) fn link_at(&self, e: usize) -> Link<Z> {
        // `base` < 2^31 at every entry (Row::encode): no carry into the flag.
        Link {
            base: self.link.base + (e as u32 - self.start),
            ..self.link
        }
    }

    /// The row of entry `e` of the run, whose codes are `c`.
    #[inline(always)]
    pub(super) fn at<'a>(&'a self, e: usize, c: &'a Codes) -> RowAt<'a, Z> {
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
pub(super) struct RowAt<'a, Z> {
    pub(super) base: u32,
    pub(super) link: &'a Link<Z>,
    pub(super) codes: &'a Codes,
}

impl<Z: Dz> RowAt<'_, Z> {
    /// The neighbours' entries (−x, +x, −y, +y, −z, +z), `pad` the other colour's pad: a missing
    /// −a one's is `pad`, a missing +a one's `base`.
    #[inline(always)]
    pub(super) fn neighbours(&self, pad: u32) -> [u32; 6] {
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
    pub(super) fn base(&self) -> u32 {
        self.base & !NO_MINUS_X
    }
}

/// A level's rows: their codes per entry (8 B) and their links per [`Run`] (16 B with u16 ±z
/// distances, 20 B with u32 ones), ~9.4 B per unknown on the procedural cloud's finest level
/// against 20 B for whole rows per entry (−3.8 MB at 200×160×120). The passes rebuild each row
/// from its run and its codes, walking the runs in order ([`Coded::each_row`](super::level::Coded::each_row)), so their inner
/// loops read whole rows, as from rows stored per entry; the other colour's couplings are read from the codes by entry.
#[derive(Clone, Debug)]
pub(super) struct Runs<Z> {
    pub(super) codes: Vec<Codes>,
    /// In order of `start`, the first at entry 0.
    pub(super) runs: Vec<Run<Z>>,
}

impl<Z: Dz> Runs<Z> {
    /// Appends entry `e`'s `link` (entries in order): to the last run if it continues it, else
    /// as a new run.
    pub(super) fn push(runs: &mut Vec<Run<Z>>, e: usize, link: Link<Z>) {
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
pub(super) enum Rows {
    Narrow(Runs<u16>),
    Wide(Runs<u32>),
}

const _: () = assert!(std::mem::size_of::<Codes>() == 8 && std::mem::size_of::<Run<u16>>() == 16 && std::mem::size_of::<Run<u32>>() == 20);

impl Rows {
    pub(super) fn len(&self) -> usize {
        match self {
            Rows::Narrow(r) => r.codes.len(),
            Rows::Wide(r) => r.codes.len(),
        }
    }

    /// Bytes held.
    pub(super) fn bytes(&self) -> usize {
        let codes = self.len() * std::mem::size_of::<Codes>();
        codes
            + match self {
                Rows::Narrow(r) => r.runs.len() * std::mem::size_of::<Run<u16>>(),
                Rows::Wide(r) => r.runs.len() * std::mem::size_of::<Run<u32>>(),
            }
    }
}

/// 2^k in f64 (k in −1022 … 1023).
pub(super) fn pow2(k: i32) -> f64 {
    f64::from_bits(((1023 + k) as u64) << 52)
}

/// The power of two 2^unit a hierarchy's operator is divided by, from the largest coupling
/// magnitude or row sum `max` of its finest level (0 for an empty one). Its values are then below
/// 2⁻³ and its diagonals below 1 (each at most 7 of them: the sum plus six coupling magnitudes),
/// and a coarse level's values below the finest level's unknowns (< 2³¹: a Galerkin diagonal is
/// at most the sum of its aggregate's finer diagonals, a coupling at most a diagonal), so every
/// level's scale 2^k is a normal f32 ([`Scaled16::exponent_for`]) for any voxel size or density.
pub(super) fn unit_of(max: f64) -> i32 {
    if !(max > 0.0 && max.is_finite()) {
        return 0;
    }
    (((max.to_bits() >> 52) & 0x7ff) as i32 - 1023 + 4).clamp(-1000, 1000)
}

/// One row as [`Level::from_stencils`](super::level::Level::from_stencils) makes it, before it is coded ([`Row::encode`]): its +a
/// couplings (≤ 0) and its sum (or diagonal), in f64 as assembled, its neighbours' entries, its
/// `base` and the other colour's pad.
pub(super) type Plain = ([f64; 3], f64, [u32; 6], u32, u32);

/// The row `plain(e, unk[e])` of entry e with ±z distances in `Z`, its values divided by
/// 2^`unit` and coded at scale exponents `k` (couplings, sums or diagonals); `None` if a
/// distance does not fit.
pub(super) fn code_row<Z: Dz>(e: usize, unk: &[u32], plain: &impl Fn(usize, u32) -> Plain, unit: i32, k: [i32; 2]) -> Option<Row<Z>> {
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
pub(super) fn code_rows<Z: Dz>(unk: &[u32], plain: &(impl Fn(usize, u32) -> Plain + Sync), unit: i32, k: [i32; 2]) -> Option<Runs<Z>> {
    let fits = AtomicBool::new(true);
    let mut codes = vec![Codes::default(); unk.len()];
    let parts: Vec<Vec<Run<Z>>> = map_chunks(&mut codes, CHUNK, &|ci, cs| {
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
        });
    let mut runs = Vec::with_capacity(parts.iter().map(Vec::len).sum());
    for r in parts.into_iter().flatten() {
        Runs::push(&mut runs, r.start as usize, r.link);
    }
    runs.shrink_to_fit();
    fits.into_inner().then_some(Runs { codes, runs })
}
