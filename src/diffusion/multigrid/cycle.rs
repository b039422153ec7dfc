//! The multigrid cycle: red-black smoothing around the coarse-grid corrections, visiting each
//! coarser level [`W_CYCLE_VISITS`] times (a W-cycle), the correction scaled by
//! [`Hierarchy::over_correction`].

use super::codec::{Mg, Real};
use super::level::Level;
use super::{Hierarchy, W_CYCLE_VISITS};

/// Vectors of one multigrid level's cycle: the next level's right-hand side and correction
/// (the level's residual is restricted as it is made: [`Level::restrict_residual`]).
pub(super) struct Work<const K: usize> {
    pub(super) bc: Vec<[Mg; K]>,
    pub(super) xc: Vec<[Mg; K]>,
}

impl<const K: usize> Work<K> {
    /// The vectors for the cycle on a level with `coarse` below it.
    pub(super) fn new(coarse: &Level) -> Work<K> {
        Work {
            bc: vec![[0.0; K]; coarse.len()],
            xc: vec![[0.0; K]; coarse.len()],
        }
    }

    /// The vectors for every level of `h` above its coarsest.
    pub(super) fn all(h: &Hierarchy) -> Vec<Work<K>> {
        h.levels[1..].iter().map(Work::new).collect()
    }
}

impl Hierarchy {
    /// One cycle on level `l` for A_l x = b, x starting at zero; `work` holds the vectors of
    /// levels l and below.
    pub(super) fn w_cycle<const K: usize>(&self, l: usize, b: &[[Mg; K]], x: &mut [[Mg; K]], work: &mut [Work<K>]) {
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
        let visits = if coarse_is_direct { 1 } else { W_CYCLE_VISITS };
        for visit in 0..visits {
            self.levels[l + 1].restrict_residual(s, x, b, &mut w.bc);
            self.w_cycle(l + 1, &w.bc, &mut w.xc, rest);
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
}
