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
//! iteration more). The first iteration, from zero (its source the sun's first scattering
//! alone), sweeps [`first_quadrature`]'s 32 ordinates instead of the solve's 96: the same
//! iteration counts on 19 scenes, images within 5·10⁻⁴ (docs/transport.md, "The first
//! iteration on 32 ordinates"); on the later low iterations a coarse quadrature cost an iteration
//! on 4 of them.

use super::source::PairTables;
use super::sphere::Quadrature;

/// The order of a cold solve's first iterations.
const START_ORDER: usize = 3;

/// The change of I0 (relative) below which the start ends. 0.05, four iterations at order 3
/// on the Disney cloud, took 8 iterations instead of 7 (the last change 5.2·10⁻³ against
/// 4.0·10⁻³).
const SWITCH_CHANGE: f64 = 0.2;

/// Which tables an iteration of a cold solve sweeps with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Phase {
    /// [`Phase::Low`] on [`first_quadrature`]: the first iteration, from zero.
    First,
    /// The source and the moments of order ≤ [`START_ORDER`].
    Low,
    /// The source of order ≤ [`START_ORDER`], every moment.
    Handover,
    /// Every order.
    Full,
}

/// The first iteration's ordinates: the fewest whose products of harmonics of order ≤
/// [`START_ORDER`] the quadrature integrates ([`Quadrature::reduced`]: n_mu ≥ L + 1, n_phi ≥
/// 2L + 1), 32.
fn first_quadrature() -> Quadrature {
    Quadrature::reduced(START_ORDER + 1, 2 * START_ORDER + 2)
}

/// The ordinates and tables of the start's phases.
pub(super) struct StartTables {
    /// [`first_quadrature`] and its tables of order ≤ [`START_ORDER`], where it has fewer
    /// ordinates than the solve's quadrature.
    first: Option<(Quadrature, PairTables)>,
    low: PairTables,
    handover: PairTables,
}

impl StartTables {
    /// The start's tables from the solve's (`full`, of order `order`, on `q`); `tables_on`
    /// makes the solve's tables on another quadrature, and with `coarse_first` false the first
    /// iteration keeps the solve's ordinates. None when the order is not above [`START_ORDER`].
    pub(super) fn new(
        q: &Quadrature,
        full: &PairTables,
        order: usize,
        coarse_first: bool,
        tables_on: impl Fn(&Quadrature) -> PairTables,
    ) -> Option<StartTables> {
        (order > START_ORDER).then(|| StartTables {
            first: Some(first_quadrature()).filter(|f| coarse_first && f.dirs.len() < q.dirs.len()).map(|f| {
                let tables = tables_on(&f).truncated(START_ORDER, START_ORDER);
                (f, tables)
            }),
            low: full.truncated(START_ORDER, START_ORDER),
            handover: full.truncated(START_ORDER, order),
        })
    }

    /// The first iteration's ordinates where they are not the solve's.
    pub(super) fn first_quadrature(&self) -> Option<&Quadrature> {
        self.first.as_ref().map(|(q, _)| q)
    }

    /// The ordinates and tables of `phase`: the solve's, `q` and `full`, for [`Phase::Full`].
    pub(super) fn tables<'a>(&'a self, phase: Phase, q: &'a Quadrature, full: &'a PairTables) -> (&'a Quadrature, &'a PairTables) {
        match (phase, &self.first) {
            (Phase::First, Some((first, tables))) => (first, tables),
            (Phase::First | Phase::Low, _) => (q, &self.low),
            (Phase::Handover, _) => (q, &self.handover),
            (Phase::Full, _) => (q, full),
        }
    }
}

/// The phase of the next iteration of a solve still in its start, from the relative changes of
/// I0 so far: the handover when the last change times the last ratio is below
/// [`SWITCH_CHANGE`].
pub(super) fn next_phase(history: &[f64]) -> Phase {
    match history {
        [] => Phase::First,
        [.., before, last] if last * (last / before) < SWITCH_CHANGE => Phase::Handover,
        _ => Phase::Low,
    }
}

/// Whether the start is over after an iteration in `phase` whose relative change of I0 was
/// `change` (a low iteration whose change fell below [`SWITCH_CHANGE`] sooner than predicted
/// ends it too: the next iteration reads zeros for orders above [`START_ORDER`]).
pub(super) fn start_over(phase: Phase, change: f64) -> bool {
    !matches!(phase, Phase::First | Phase::Low) || change < SWITCH_CHANGE
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The first iteration sweeps the 32 ordinates at order ≤ 3; the other low iterations and
    /// the handover the solve's own; a solve whose quadrature is no larger keeps its own.
    #[test]
    fn only_the_first_iteration_sweeps_the_coarse_ordinates() {
        let order = 7;
        let (perm, _) = super::super::source::parity_order(order);
        let band = crate::transport::BandOptics {
            sigma_t: 1.0,
            albedo: 0.9,
            chi: (0..=order).map(|l| 0.8f64.powi(l as i32)).collect(),
            f: 0.0,
        };
        let bands = [band.clone(), band.clone(), band];
        let tables_on = |q: &Quadrature| PairTables::new(q, order, &perm, &bands, [1.0; 3], &vec![0.0; perm.len()]);
        let q = Quadrature::reduced(8, 16);
        let full = tables_on(&q);
        let start = StartTables::new(&q, &full, order, true, tables_on).unwrap();
        let (first, tables) = start.tables(Phase::First, &q, &full);
        assert_eq!((first.dirs.len(), q.dirs.len()), (32, 96));
        assert_eq!((tables.pairs.len(), tables.source_active, tables.moment_active), (16, [6, 10], [6, 10]));
        for phase in [Phase::Low, Phase::Handover, Phase::Full] {
            assert_eq!(start.tables(phase, &q, &full).0.dirs.len(), 96, "{phase:?}");
        }
        let small = first_quadrature();
        let own = tables_on(&small);
        let start = StartTables::new(&small, &own, order, true, tables_on).unwrap();
        assert!(std::ptr::eq(start.tables(Phase::First, &small, &own).0, &small));
        let start = StartTables::new(&q, &full, order, false, tables_on).unwrap();
        assert!(start.first_quadrature().is_none() && std::ptr::eq(start.tables(Phase::First, &q, &full).0, &q));
    }

    #[test]
    fn the_start_hands_over_when_the_next_change_is_predicted_below_the_switch() {
        // The Disney cloud's changes: 1, 0.375 (predicted 0.14 next), 0.106.
        assert_eq!(next_phase(&[]), Phase::First);
        assert_eq!(next_phase(&[1.0]), Phase::Low);
        assert_eq!(next_phase(&[1.0, 0.6]), Phase::Low);
        assert_eq!(next_phase(&[1.0, 0.375]), Phase::Handover);
        assert!(!start_over(Phase::First, 1.0));
        assert!(!start_over(Phase::Low, 0.375));
        assert!(start_over(Phase::Low, 0.1));
        assert!(start_over(Phase::Handover, 0.3));
        assert!(start_over(Phase::Full, 0.3));
    }
}
