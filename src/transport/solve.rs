//! The 3-D solver (after SHDOM, Evans 1998): the diffuse radiance's source function stored in real
//! spherical harmonics per full voxel, swept through the grid along discrete ordinates, iterated
//! with diffusion synthetic acceleration. [`solve_warm`] sets up, iterates and hands back the field;
//! the stages live beside it:
//!
//! - **Sweep** (src/transport/sweep/mod.rs, [`sweep`](super::sweep::sweep)). For an ordinate Ω, the
//!   axis a with the largest |Ω_a|/h_a orders the voxel planes upwind. A voxel's centre looks back
//!   along −Ω to the plane of the previous centres, a distance s = h_a/|Ω_a|; there, the radiance,
//!   source and density are bilinear in the four upwind centres (the offsets are ≤ 1 voxel because
//!   a is the major axis). Across the step the source is linear in optical path and integrated
//!   exactly: I = I_b e^{−τ} + w_in S_b + w_out S (τ = σt′ s (ρ_b + ρ)/2). Empty voxels carry the
//!   radiance unchanged. Outside the swept box the ordinate sees the sky, or, going up, the
//!   Lambertian ground at the point straight back along −Ω.
//! - **Ground** (src/transport/ground.rs, [`GroundMap`]): the δ-M shadowed sun plus the sky's and
//!   the cloud's downward diffuse light of the last sweep, so every ground bounce is iterated; the
//!   map reaches as far as the cloud's shadow.
//! - **Source** (src/transport/source.rs). J(Ω) = Σ_lm a′χ′_l (I_lm + E T′_sun Y_lm(Ω_sun)) Y_lm(Ω),
//!   I_lm the diffuse radiance's moments; the δ-M reduced sun E T′_sun = E T^{1 − a f} is exact and
//!   apart.
//! - **Acceleration** (src/transport/dsa.rs). After a sweep the isotropic change ΔI0 drives the
//!   diffusion equation −∇·(D∇δ) + ρσa′ δ = ρσs′ ΔI0, D = 1/(3ρσtr′) plus the sweeps' own
//!   numerical diffusion (src/transport/accel.rs: consistent with the sweeps on thick voxels;
//!   δ-M coefficients, Marshak boundary), solved by multigrid-preconditioned CG;
//!   I_00 += √(4π) δ, and the correction's P1 current (Fick's law) goes into the first moments.
//! - **Mixing** (src/transport/mixing.rs): Anderson mixing of a cold solve's orders l ≤ 2 over
//!   the last three accelerated maps, fitted on I_00.
//! - **Start** (src/transport/start.rs): a cold solve's first iterations read the source of
//!   order ≤ 3 only, the very first on 32 ordinates.
//! - **Convergence** (src/transport/convergence.rs): the stopping test, the divergence guard and
//!   the dominant-mode extrapolation of warm solves.

use super::convergence::{dominant_mode_step, i00_change, i00_mean_change, max_voxel_optical_depth, plain_converged, DIVERGENCE_FACTOR};
use super::dsa::{accelerate, hierarchies};
use super::grid::{Ctx, FullVoxels};
use super::ground::GroundLight;
use super::mixing::Mixing;
pub use super::ground::GroundMap;
use super::source::{diffuse_source_of, parity_order, PairTables};
use super::sky_cells::SkyCells;
use super::sphere::Quadrature;
use super::start::{next_phase, start_over, Phase, StartTables};
use super::sweep::{sweep, BatchArrays};
use super::warm::{TransportState, WarmStart, WarmStop, FAR_START_TOLERANCES};
use super::TransportOptics;
use crate::diffusion::multigrid::Hierarchy;
use crate::error::{Error, Result};
use crate::lighting::{Ground, Sky, Sun};
use crate::math::{real_sh, sh_count};
use crate::medium::sparse::FullIndex;
use crate::medium::Medium;
use crate::pipeline::Progress;
use glam::DVec3;
use std::sync::Arc;

/// Settings of the 3-D solver.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TransportSettings {
    /// Legendre/SH truncation order L of the δ-M phase function and of the source.
    pub order: usize,
    /// Ordinates in cos θ (the azimuths are 2× this on the rings near the horizon).
    pub n_mu: usize,
    /// Fewer azimuths on the rings towards the poles ([`Quadrature::reduced`]); false: 2·`n_mu`
    /// on every ring ([`Quadrature::product`]).
    pub reduced_azimuths: bool,
    /// Convergence: max over full voxels of |ΔI0| / max I0 between iterations.
    pub tolerance: f64,
    /// Iteration cap.
    pub max_iterations: usize,
    /// Diffusion synthetic acceleration on.
    pub acceleration: bool,
}

impl TransportSettings {
    /// The sweeps' ordinates.
    pub(super) fn quadrature(&self) -> Quadrature {
        if self.reduced_azimuths {
            Quadrature::reduced(self.n_mu, 2 * self.n_mu)
        } else {
            Quadrature::product(self.n_mu, 2 * self.n_mu)
        }
    }
}

impl Default for TransportSettings {
    fn default() -> Self {
        TransportSettings {
            order: 7,
            n_mu: 8,
            reduced_azimuths: true,
            tolerance: 5e-3,
            max_iterations: 60,
            acceleration: true,
        }
    }
}

/// The converged solution.
#[derive(Clone, Debug)]
pub struct TransportField {
    /// The optics it was solved with.
    pub optics: TransportOptics,
    /// SH order.
    pub order: usize,
    /// The medium's occupancy index: a grid voxel's slot is 1 + its index into the full-voxel
    /// arrays, 0 where ρ = 0.
    pub full: Arc<FullIndex>,
    /// Diffuse source coefficients a′χ′_l I_lm per full voxel, band, lm (W·m⁻²·sr⁻¹); the sun's
    /// first scattering is not in it (the gather adds it exactly).
    pub diffuse_source: Vec<f32>,
    /// δ-M sun transmittance T′ per full voxel's centre and band.
    pub sun_t: Vec<[f32; 3]>,
    /// The ground's radiance.
    pub ground: GroundMap,
    /// Relative change of I0 after each iteration.
    pub history: Vec<f64>,
    /// Full voxels.
    pub full_voxels: usize,
    /// Ordinates.
    pub ordinates: usize,
}

impl TransportField {
    /// Iterations done.
    pub fn iterations(&self) -> usize {
        self.history.len()
    }
}

/// What [`solve_warm`] starts from and hands back beside the field.
#[derive(Clone, Copy, Default)]
pub struct SolveOptions<'a> {
    /// A previous frame's converged state, mapped onto this grid (None: the cold start, zero).
    pub start: Option<&'a TransportState>,
    /// Also hand back the converged state, for the next frame's start (src/transport/warm.rs).
    pub keep: bool,
    /// Called with each iteration's iterate as a field (a live view; built only then, so the
    /// solve without it is unchanged).
    pub live: Option<&'a dyn Fn(&TransportField)>,
}

/// Solve the transport problem for the scene's medium, sun, sky and ground.
pub fn solve(
    m: &Medium,
    sun: &Sun,
    sky: &Sky,
    ground: Option<&Ground>,
    s: &TransportSettings,
    progress: &dyn Progress,
) -> Result<TransportField> {
    Ok(solve_warm(m, sun, sky, ground, s, progress, SolveOptions::default())?.0)
}

/// Most optical depth per voxel (ρσt′ h, thinnest axis) the solve accepts. The acceleration
/// multiplies a sweep's change of I0 by about the voxels' optical depth τ, and with it the sweeps'
/// f32 rounding (relative 6·10⁻⁸): beyond ~10⁵ that exceeds the tolerance. Measured (albedo 1,
/// g = 0, 40-m voxels): τ = 60 converges in 12 iterations, 6·10³ in 43, 6·10⁵ diverges.
pub const MAX_VOXEL_OPTICAL_DEPTH: f64 = 1e4;

/// Most optical depth per voxel (ρσt′ h) at which a cold solve's first iteration sweeps the
/// start's coarser ordinates (src/transport/start.rs): the acceleration's numerical diffusion is
/// the solve's ordinates', and on thicker voxels the coarse sweep's differs enough to cost an
/// iteration (the default scene at σt = 5, 50 optical depths: 9 → 10; at 10 the same 9).
const COARSE_FIRST_MAX_OPTICAL_DEPTH: f64 = 10.0;

/// [`solve`] from `opts.start`, iterated to the same tolerance; with `opts.keep`, also the
/// converged state for the next frame.
pub fn solve_warm(
    m: &Medium,
    sun: &Sun,
    sky: &Sky,
    ground: Option<&Ground>,
    s: &TransportSettings,
    progress: &dyn Progress,
    opts: SolveOptions,
) -> Result<(TransportField, Option<TransportState>)> {
    let optics = TransportOptics::from_medium(m, s.order);
    let h_min = m.voxel_size.x.min(m.voxel_size.y).min(m.voxel_size.z) as f64;
    let tau_max = m.density.max_value() as f64 * optics.bands.iter().fold(0.0f64, |a, b| a.max(b.sigma_t)) * h_min;
    if tau_max > MAX_VOXEL_OPTICAL_DEPTH {
        return Err(Error::Numerical {
            stage: "transport solve".into(),
            message: format!(
                "voxels up to {tau_max:.1e} optical depths thick (medium.sigma_t × density × medium.voxel_size, δ-M \
                 scaled), above the {MAX_VOXEL_OPTICAL_DEPTH:.0e} to which the solve converges (the sweeps' f32 \
                 rounding, amplified about τ times by the acceleration, exceeds render.transport_tolerance beyond); \
                 render it with --method reference (exact; full and diffusion finish but are measured 15-23 % dark at \
                 50-125 optical depths per voxel, docs/accuracy.md), or give it thinner voxels (a smaller \
                 medium.voxel_size or medium.sigma_t)"
            ),
        });
    }
    let index = FullVoxels::of(&m.density);
    let sun_t = sun_transmittance(m, sun, &optics, &index.voxels, ground.map(|g| g.height));
    let q = s.quadrature();
    let sky_cells = SkyCells::new(sky, &q);
    let ctx = Ctx::new(m, &sky_cells, ground, &index, &sun_t, s.order, &optics.bands);
    let tables = pair_tables(&q, sun, s.order, &optics);
    let coarse_first = max_voxel_optical_depth(&ctx, ctx.voxels, &optics.bands) <= COARSE_FIRST_MAX_OPTICAL_DEPTH;
    let start = StartTables::new(&q, &tables, s.order, coarse_first, |q| pair_tables(q, sun, s.order, &optics));
    // The first iteration's own sky cells: its ordinates' cells are not the solve's.
    let first_sky = start.as_ref().and_then(StartTables::first_quadrature).map(|fq| SkyCells::new(sky, fq));
    let first_ctx = first_sky.as_ref().map(|fs| Ctx { sky: fs, ..ctx.clone() });
    let ground_light = GroundLight::new(m, sun, sky, ground, &optics);
    let hier = if s.acceleration {
        hierarchies(m, &optics.bands, &index, &q)
    } else {
        Vec::new()
    };
    let solver = Solver {
        ctx: &ctx,
        first_ctx: first_ctx.as_ref(),
        q: &q,
        tables: &tables,
        start: start.as_ref(),
        hier: &hier,
        optics: &optics,
        ground: &ground_light,
        s,
    };
    let warm = opts.start.and_then(|st| st.start(m, s.order, 3 * ctx.nsh, &ground_light));
    let mut it = Iterate::new(&solver, warm);
    solver.iterate(&mut it, progress, opts.live)?;
    solver.check_converged(&it)?;
    progress.end();
    let Iterate {
        moments,
        next,
        batch,
        history,
        ground_map,
        slowest,
        carried_ratio,
        ..
    } = it;
    drop(batch);
    let nsh = ctx.nsh;
    let kept_ground = opts.keep.then(|| ground_map.clone());
    // T′ moves into the field once `ctx`, which borrows it, is dropped (below). The diffuse
    // source takes the spent `next`: a fresh array of its size would be mapped page by page.
    let mut field = solver.field(&moments, history, ground_map, Arc::clone(&index.index), Vec::new(), next);
    drop(ctx);
    let state = kept_ground.map(|g| TransportState::new(m, s.order, moments, 3 * nsh, g, slowest.unwrap_or(carried_ratio)));
    field.sun_t = sun_t;
    Ok((field, state))
}

/// δ-M sun transmittance T′ = T^{1 − a f} = T^{σt′/σt} at the centres of the full voxels
/// (grid indices `voxels`), per band; a centre under the ground (height `floor`, m) is taken on
/// the plane above it, whose light its cell holds (`sweep::ground_cut`).
fn sun_transmittance(m: &Medium, sun: &Sun, optics: &TransportOptics, voxels: &[usize], floor: Option<f32>) -> Vec<[f32; 3]> {
    let exact = crate::lit::sunlight::SunTransmittance::at_voxels(m, sun.dir, voxels, floor);
    let ratio = [0, 1, 2].map(|b| (optics.bands[b].sigma_t / optics.sigma_t) as f32);
    // Grey optics (every example): one power serves the three bands.
    let grey = ratio[1..].iter().all(|r| *r == ratio[0]);
    crate::par::map_items(exact.len(), crate::par::CHUNK, &|i| {
        let t = exact[i];
        if grey {
            [t.powf(ratio[0]); 3]
        } else {
            ratio.map(|r| t.powf(r))
        }
    })
}

/// The per-pair tables of the sweeps for the sun's beam and the δ-M optics.
fn pair_tables(q: &Quadrature, sun: &Sun, order: usize, optics: &TransportOptics) -> PairTables {
    let (perm, _) = parity_order(order);
    let e_sun = [sun.irradiance.x as f64, sun.irradiance.y as f64, sun.irradiance.z as f64];
    let mut y_sun = vec![0.0; sh_count(order)];
    let beam = -DVec3::new(sun.dir.x as f64, sun.dir.y as f64, sun.dir.z as f64);
    real_sh(order, beam, &mut y_sun);
    PairTables::new(q, order, &perm, &optics.bands, e_sun, &y_sun)
}

/// What stays fixed through the iteration.
struct Solver<'a> {
    ctx: &'a Ctx<'a>,
    q: &'a Quadrature,
    tables: &'a PairTables,
    /// `ctx` with the sky of the first iteration's ordinates, where they are not the solve's.
    first_ctx: Option<&'a Ctx<'a>>,
    /// The tables of a cold solve's first iterations (src/transport/start.rs; none when the
    /// solve's order is not above its start order).
    start: Option<&'a StartTables>,
    /// The DSA hierarchies (none: no acceleration).
    hier: &'a [Hierarchy],
    optics: &'a TransportOptics,
    ground: &'a GroundLight<'a>,
    s: &'a TransportSettings,
}

/// The iterate and the record of the iteration.
struct Iterate {
    /// The moments I_lm per full voxel, band and harmonic (solver order), and the next sweep's.
    moments: Vec<f32>,
    next: Vec<f32>,
    /// The sweeps' per-voxel arrays of an ordinate batch.
    batch: BatchArrays,
    /// Relative change of I0 after each iteration.
    history: Vec<f64>,
    ground_map: GroundMap,
    /// Started from a previous frame's state: its stopping test.
    warm: Option<WarmStop>,
    /// Iteration of the last extrapolation (0: none).
    extrapolated: usize,
    /// The cold solve's Anderson mixing.
    mixing: Mixing,
    /// The slowest mode's ratio this solve's extrapolations saw, and the previous frame's: the
    /// next frame's start takes this solve's, else the previous one's.
    slowest: Option<f64>,
    carried_ratio: f64,
    /// The acceleration's guard (docs/transport.md, "Robustness", "Thick voxels"): whether
    /// it is still on, the smallest change of I_00 since the iteration (re)started, iterations
    /// since then, and the iteration at which the acceleration was given up.
    accelerated: bool,
    smallest: f64,
    since_start: usize,
    given_up: Option<usize>,
    /// Still in a cold solve's first iterations at the start order (src/transport/start.rs).
    starting: bool,
}

/// `n` zeros written, not left to the allocator's zero pages: the first iteration reads the cold
/// start's moments, and a page first read maps the shared zero page, so the second iteration's
/// writes into the same array would take a second fault per page.
fn written_zeros(n: usize) -> Vec<f32> {
    let mut v = Vec::with_capacity(n);
    v.resize(n, 0.0);
    v
}

impl Iterate {
    /// The cold start (zero) or the warm start's moments and ground.
    fn new(solver: &Solver, warm: Option<WarmStart>) -> Iterate {
        let carried_ratio = warm.as_ref().map_or(0.0, |w| w.slow_ratio);
        let stop = warm.as_ref().map(|w| WarmStop::new(w.slow_ratio));
        let cold = warm.is_none();
        let (moments, e_down) = match warm {
            Some(w) => (w.moments, w.e_down),
            None => (written_zeros(solver.ctx.voxels.len() * 3 * solver.ctx.nsh), None),
        };
        Iterate {
            next: vec![0f32; moments.len()],
            batch: BatchArrays::new(solver.ctx.voxels.len()),
            moments,
            history: Vec::new(),
            ground_map: solver.ground.map(e_down.as_deref()),
            warm: stop,
            extrapolated: 0,
            mixing: Mixing::new(&parity_order(solver.s.order).0, solver.ctx.nsh),
            slowest: None,
            carried_ratio,
            accelerated: solver.s.acceleration,
            smallest: f64::INFINITY,
            since_start: 0,
            given_up: None,
            starting: cold && solver.start.is_some() && solver.s.acceleration,
        }
    }

    /// The relative changes since the iteration (re)started.
    fn since_restart(&self) -> &[f64] {
        &self.history[self.history.len() - self.since_start..]
    }
}

impl Solver<'_> {
    /// Source iteration to the tolerance or the cap: a sweep, the acceleration, the divergence
    /// guard and the extrapolation per iteration.
    fn iterate(&self, it: &mut Iterate, progress: &dyn Progress, live: Option<&dyn Fn(&TransportField)>) -> Result<()> {
        let (s, nsh) = (self.s, self.ctx.nsh);
        // The extrapolation assumes the slowest error mode keeps its sign (a ratio r > 0). With a
        // back-scattering phase function the odd moments' scattering eigenvalues a′χ′_l are
        // negative: their error alternates, and adding the last step r/(1 − r) times amplified
        // it (g = −0.9 diverged). Neither it nor the mixing is done there.
        let extrapolate = self.optics.bands.iter().all(|b| b.chi.iter().all(|&c| c >= 0.0));
        let first_moment_ratio = self.optics.bands.iter().fold(0.0f64, |r, b| r.max(b.albedo * b.chi.get(1).copied().unwrap_or(0.0)));
        progress.begin("transport iterations", s.max_iterations as u64);
        // An empty medium has nothing to iterate: the sky and ground pass unchanged.
        let iterations = if self.ctx.voxels.is_empty() { 0 } else { s.max_iterations };
        for done in 0..iterations {
            if progress.cancelled() {
                break;
            }
            // The last two iterations allowed are full ones, so a solve cut off by
            // render.transport_max_iterations still ends on the whole map.
            let phase = if it.starting && iterations - done > 2 { next_phase(it.since_restart()) } else { Phase::Full };
            let (q, tables) = self.start.map_or((self.q, self.tables), |st| st.tables(phase, self.q, self.tables));
            let ctx = match phase {
                Phase::First => self.first_ctx.unwrap_or(self.ctx),
                _ => self.ctx,
            };
            let e_down = sweep(ctx, q, tables, &it.moments, &mut it.next, &it.ground_map, &mut it.batch);
            if it.accelerated && !self.hier.is_empty() {
                accelerate(self.ctx, self.ctx.voxels, self.hier, &self.optics.bands, &it.moments, &mut it.next);
            }
            let (change_abs, scale) = i00_change(&it.next, &it.moments, nsh);
            let mean_change = it.warm.is_some().then(|| i00_mean_change(&it.next, &it.moments, nsh));
            it.since_start += 1;
            let diverging = !change_abs.is_finite() || (it.since_start >= 2 && change_abs > DIVERGENCE_FACTOR * it.smallest);
            if diverging && it.accelerated {
                self.give_up_acceleration(it, change_abs, progress);
                continue;
            }
            if diverging {
                return Err(Error::Numerical {
                    stage: "transport solve".into(),
                    message: format!(
                        "plain source iteration diverged at iteration {} (change of I0 {change_abs:.2e}); this is a bug: please report the scene, and render it with --method full or reference meanwhile",
                        it.history.len() + 1
                    ),
                });
            }
            it.smallest = it.smallest.min(change_abs);
            let change = change_abs / scale;
            it.history.push(change);
            if it.warm.is_some() && it.since_start == 1 && change >= 1.0 {
                self.start_cold(it, change, progress);
                continue;
            }
            if it.warm.is_some() && it.since_start == 1 && change >= FAR_START_TOLERANCES * s.tolerance {
                self.mix_from_far_start(it, change, progress);
            }
            it.starting &= !start_over(phase, change);
            // Cold solves mix (src/transport/mixing.rs); warm ones extrapolate, as their
            // stopping rule reads the extrapolated mode.
            let mixed = it.accelerated && extrapolate && it.warm.is_none();
            if mixed {
                it.mixing.mix(&it.moments, &mut it.next);
                // Not measured here: the plain iteration's slowest mode, the first moment's
                // a′χ′_1, is what a following warm frame's stopping rule assumes.
                it.slowest.get_or_insert(first_moment_ratio);
            }
            let mode = (it.accelerated && extrapolate && !mixed)
                .then(|| dominant_mode_step(&it.history, it.extrapolated))
                .flatten();
            if let Some(mode) = mode {
                let k = mode.factor();
                let moments = &it.moments;
                crate::par::for_chunks(&mut it.next, crate::par::CHUNK, &|ci, xs| {
                    for (x, o) in xs.iter_mut().zip(&moments[ci * crate::par::CHUNK..]) {
                        *x += k * (*x - o);
                    }
                });
                it.extrapolated = it.history.len();
                it.slowest = Some(it.slowest.map_or(mode.ratio, |r| r.max(mode.ratio)));
            }
            std::mem::swap(&mut it.moments, &mut it.next);
            it.ground_map = self.ground.map(Some(&e_down));
            progress.converge(change, s.tolerance);
            progress.advance(1);
            progress.log(&format!(
                "transport: iteration {}, relative change of I0 {change:.2e} (stops below {:.1e})",
                it.history.len(),
                s.tolerance
            ));
            if let Some(show) = live {
                show(&self.field(
                    &it.moments,
                    it.history.clone(),
                    it.ground_map.clone(),
                    Arc::clone(self.ctx.full),
                    self.ctx.sun_t.to_vec(),
                    vec![0f32; it.moments.len()],
                ));
            }
            let stop = match (&mut it.warm, mean_change) {
                (Some(w), Some(mean)) => w.converged(mean, mode, s.tolerance),
                _ => change < s.tolerance,
            };
            // An iteration with the source at the start order is not the solve's map: no stop.
            if stop && phase == Phase::Full && (it.accelerated || plain_converged(it.since_restart(), s.tolerance))
            {
                break;
            }
        }
        Ok(())
    }

    /// A warm start no nearer the first iterate than zero is (a relative change of I0 of at least
    /// 1, a cold start's by definition: from zero every value changes by itself) is no start,
    /// e.g. a frame whose sun has just set carries light the scene no longer has, and the warm
    /// iteration's extrapolation overshoots while that light decays. Start again from zero as a
    /// cold solve (its start at order 3, the mixing, the cold stopping test).
    fn start_cold(&self, it: &mut Iterate, change: f64, progress: &dyn Progress) {
        self.restart_from_zero(it);
        it.starting = self.start.is_some() && it.accelerated;
        progress.advance(1);
        progress.log(&format!(
            "transport: iteration {}, relative change of I0 {change:.2e} from the previous frame's light, no nearer than \
             zero: solving from zero",
            it.history.len()
        ));
    }

    /// A warm start far from this frame's light (a first change of I0 of many tolerances: every
    /// voxel of a simulation's cloud changed, the extinction or the sun jumped) leaves an error
    /// the mixing takes faster than the warm solve's extrapolation, and large enough that the
    /// cold stopping test cannot stop early on it: go on from the iterate as a cold solve (the
    /// mixing, the cold test), keeping what the start got right.
    fn mix_from_far_start(&self, it: &mut Iterate, change: f64, progress: &dyn Progress) {
        it.warm = None;
        progress.log(&format!(
            "transport: iteration {}, relative change of I0 {change:.2e} from the previous frame's light, at least \
             {FAR_START_TOLERANCES} tolerances: mixing on from it as a cold solve",
            it.history.len()
        ));
    }

    /// The iterate back to zero (the moments and the cloud's light on the ground) and its counts
    /// restarted: from zero the solve is a cold one, stopped by the cold test.
    fn restart_from_zero(&self, it: &mut Iterate) {
        it.warm = None;
        it.moments.fill(0.0);
        it.next.fill(0.0);
        (it.smallest, it.since_start) = (f64::INFINITY, 0);
        it.ground_map = self.ground.map(None);
    }

    /// DSA's diffusion operator is not the sweeps' own diffusion limit, and on voxels many mean
    /// free paths thick the mismatch amplifies: start again from zero with plain source
    /// iteration (positive, and a contraction for a′ ≤ 1).
    fn give_up_acceleration(&self, it: &mut Iterate, change_abs: f64, progress: &dyn Progress) {
        it.accelerated = false;
        it.starting = false;
        it.given_up = Some(it.history.len() + 1);
        let smallest = it.smallest;
        self.restart_from_zero(it);
        it.history.push(1.0);
        progress.advance(1);
        progress.log(&format!(
            "transport: iteration {}, the acceleration diverged (change of I0 {change_abs:.2e} W·m⁻²·sr⁻¹, smallest before {:.2e}); plain source iteration from zero",
            it.history.len(),
            smallest
        ));
    }

    /// After the acceleration was given up, refuse a plain source iteration that had not
    /// converged by the cap, naming the fixes.
    fn check_converged(&self, it: &Iterate) -> Result<()> {
        let s = self.s;
        let last = it.history.last().copied().unwrap_or(0.0);
        let Some(at) = it.given_up.filter(|_| !plain_converged(it.since_restart(), s.tolerance)) else {
            return Ok(());
        };
        let tau = max_voxel_optical_depth(self.ctx, self.ctx.voxels, &self.optics.bands);
        // χ′_1 is g itself for a back-scattering phase function (no δ-M there).
        let g = self.optics.bands[0].chi.get(1).copied().unwrap_or(0.0);
        let backwards = if g < -0.9 {
            format!(" (a phase function this strongly backwards, g = {g:.4}, unsettles the iteration too: --method reference renders it)")
        } else {
            String::new()
        };
        Err(Error::Numerical {
            stage: "transport solve".into(),
            message: format!(
                "the diffusion acceleration diverged at iteration {at} (voxels up to {tau:.3e} optical depths \
                 thick){backwards}, and plain source iteration, which needs of the order of (optical depth)² sweeps, had not \
                 converged after render.transport_max_iterations = {} (last change of I0 {last:.1e}, error left \
                 estimated above render.transport_tolerance = {:.1e}); render this medium with --method full or \
                 reference, or give it voxels of at most a few optical depths (a smaller medium.voxel_size or \
                 medium.sigma_t)",
                s.max_iterations, s.tolerance
            ),
        })
    }

    /// The field of `moments`, for the gather; its diffuse source is written over `spare` (as
    /// long as `moments`).
    fn field(
        &self,
        moments: &[f32],
        history: Vec<f64>,
        ground: GroundMap,
        full: Arc<FullIndex>,
        sun_t: Vec<[f32; 3]>,
        spare: Vec<f32>,
    ) -> TransportField {
        let (perm, _) = parity_order(self.s.order);
        TransportField {
            optics: self.optics.clone(),
            order: self.s.order,
            full,
            diffuse_source: diffuse_source_of(moments, &self.optics.bands, &perm, self.ctx.nsh, spare),
            sun_t,
            ground,
            history,
            full_voxels: self.ctx.voxels.len(),
            ordinates: self.q.dirs.len(),
        }
    }
}
