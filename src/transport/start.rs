//! A cold solve's first iterations at a lower angular order (docs/transport.md, "The first
//! iterations at order 3"). From zero, the first sweeps' changes of I0 (1, 0.3–0.4, ~0.1) are
//! the diffusive, nearly isotropic modes', which the orders ≤ 3 carry: on the Disney cloud the
//! changes at order 3 are those at order 7 within 1 % (1, 0.375, 0.106 against 1, 0.375, 0.105).
//! So these iterations read the source from the 16 harmonics of order ≤ 3 and accumulate only
//! those moments (the sun's first scattering keeps every order, in the tables' sun term); the
//! kernels do a quarter of their work. The iteration whose change is predicted to fall below
//! [`SWITCH_CHANGE`] (the last ratio of the changes applied to the last change) hands over: its
//! source is still of order 3, but it accumulates every moment, so the first full iteration reads
//! orders 4–L made by a whole sweep rather than zeros (without it 5 of 19 scenes took one
//! iteration more).

use super::source::PairTables;

/// The order of a cold solve's first iterations.
const START_ORDER: usize = 3;

/// The change of I0 (relative) below which the start ends. 0.05, four iterations at order 3
/// on the Disney cloud, took 8 iterations instead of 7 (the last change 5.2·10⁻³ against
/// 4.0·10⁻³).
const SWITCH_CHANGE: f64 = 0.2;

/// Which tables an iteration of a cold solve sweeps with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Phase {
    /// The source and the moments of order ≤ [`START_ORDER`].
    Low,
    /// The source of order ≤ [`START_ORDER`], every moment.
    Handover,
    /// Every order.
    Full,
}

/// The tables of the start's two phases.
pub(super) struct StartTables {
    low: PairTables,
    handover: PairTables,
}

impl StartTables {
    /// The start's tables from the solve's (`full`, of order `order`); none when the order is
    /// not above [`START_ORDER`].
    pub(super) fn new(full: &PairTables, order: usize) -> Option<StartTables> {
        (order > START_ORDER).then(|| StartTables {
            low: full.truncated(START_ORDER, START_ORDER),
            handover: full.truncated(START_ORDER, order),
        })
    }

    /// The tables of `phase`, `full` for [`Phase::Full`].
    pub(super) fn tables<'a>(&'a self, phase: Phase, full: &'a PairTables) -> &'a PairTables {
        match phase {
            Phase::Low => &self.low,
            Phase::Handover => &self.handover,
            Phase::Full => full,
        }
    }
}

/// The phase of the next iteration of a solve still in its start, from the relative changes of
/// I0 so far: the handover when the last change times the last ratio is below
/// [`SWITCH_CHANGE`].
pub(super) fn next_phase(history: &[f64]) -> Phase {
    match history {
        [.., before, last] if last * (last / before) < SWITCH_CHANGE => Phase::Handover,
        _ => Phase::Low,
    }
}

/// Whether the start is over after an iteration in `phase` whose relative change of I0 was
/// `change` (a low iteration whose change fell below [`SWITCH_CHANGE`] sooner than predicted
/// ends it too: the next iteration reads zeros for orders above [`START_ORDER`]).
pub(super) fn start_over(phase: Phase, change: f64) -> bool {
    phase != Phase::Low || change < SWITCH_CHANGE
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_start_hands_over_when_the_next_change_is_predicted_below_the_switch() {
        // The Disney cloud's changes: 1, 0.375 (predicted 0.14 next), 0.106.
        assert_eq!(next_phase(&[]), Phase::Low);
        assert_eq!(next_phase(&[1.0]), Phase::Low);
        assert_eq!(next_phase(&[1.0, 0.6]), Phase::Low);
        assert_eq!(next_phase(&[1.0, 0.375]), Phase::Handover);
        assert!(!start_over(Phase::Low, 0.375));
        assert!(start_over(Phase::Low, 0.1));
        assert!(start_over(Phase::Handover, 0.3));
        assert!(start_over(Phase::Full, 0.3));
    }
}
