//! The final gather with the edge treatment: one pixel ray, composited front to back.
//!
//! Along the ray the density profile is cut at the blend band [T_lo, T] (T_lo = (1 − band)·T):
//! * every piece emits the **exact sun single scattering**, a·E_sun(p)·HG(g, ω_sun·d) per unit
//!   optical depth (E_sun(p) is the attenuated sun irradiance the caller supplies);
//! * the caller's **dense source** (the diffusion solution, radiance per unit optical depth) is
//!   weighted by w(ρ) = smoothstep(T_lo, T, ρ): 0 below T_lo, 1 from T up;
//! * each **low-density segment** S_j (0 < ρ < T, the paper's definition) gets
//!   E_j = Σ_{i≥1} q_i a^i K_ij from a view-aligned cube at c_j (eq. 9, [`super::orders_kernel`]),
//!   spread uniformly in optical depth over the segment (source E_j/(1 − e^{−D_j}), so an
//!   unblended segment adds exactly E_j times the transmittance in front of it), weighted 1 − w(ρ);
//! * what lies behind is attenuated by the exact transmittance, the background last.
//!
//! **The surface layer** (`surface_depth` = D_s > 0; docs/edges.md): the first D_s of optical depth
//! of the ray, whatever its density, joins its first segment(s) — the segments are the runs of
//! pieces with ρ < T *or* in the layer — and there the edge weight is 1 (falling over the last
//! `surface_band` of D_s), so eqs. 8–9 render the layer the eye's light comes from, the diffusion
//! only what lies behind it. With D_s = 0 the gather is the paper's.
//!
//! **No double counting of the sun.** The cube must not contain the direct sun (a point light is
//! never in a cube image). Its multiple scattering inside the segment is added analytically as a
//! delta in the sun's direction for orders i ≥ 2: a^i q_i E_sun(c_j) HG(g^i, ω_sun·d). Order 1 of the
//! sun is left out because the exact single scattering above already covers it (exactly, rather than
//! with the Poisson estimate q_1 = D e^{−D}).
//!
//! **Section 6 fixes.** (1) The cube request carries the segment so the cube renderer leaves out the
//! cells the segment crosses (scattering along S_j is what the orders already count). (2) Where two
//! segments are joined by a *bridge* — an interior stretch with ρ in the blend band that does not
//! reach T — the segment's edge source is (1 − w_b)·(merged) + w_b·(split at the bridge's density
//! maximum), w_b = w(max ρ on the bridge). At max ρ → T this tends to the two separate segments the
//! paper would use just above T, and at max ρ → T_lo to the merged one: no seam where segments join.
//! Likewise for a *near-gap* (an interior stretch with ρ below `GAP_FRACTION`·T_lo): the split
//! weight is 1 − smoothstep(0, gap, min ρ), so two wisps that touch across clear air fade into one
//! segment instead of switching abruptly when the gap closes.

use super::escape::SunChord;
use super::orders::eye_weighted_depth;
use super::orders_kernel::{edge_radiance, segment_orders, OrderKernel, DEFAULT_TAIL};
use super::segments::{density_bounds, depth_from_samples, LowSegment, RayProfile};
use crate::cube::CubeImage;
use crate::math::{Rgb, Vec3};
use crate::medium::Medium;
use crate::peak::PeakSpread;

/// Bridges are resolved recursively at most this deep (2^depth sub-segments at worst).
pub const MAX_BRIDGE_DEPTH: usize = 3;

/// Near-gap level as a fraction of T_lo: interior stretches of a segment thinner than this fade
/// towards a split, so two wisps joining across clear air leave no seam.
pub const GAP_FRACTION: f32 = 0.25;

/// What a cube renderer is asked for.
#[derive(Clone, Copy, Debug)]
pub struct CubeRequest {
    /// Cube centre c_j (m).
    pub center: Vec3,
    /// Unit local +x axis: the viewing ray's direction (from the eye into the scene).
    pub x_axis: Vec3,
    /// Pixels per face edge.
    pub res: usize,
    /// The segment S_j (entry and exit points, m): cells it crosses must be left out of the cube
    /// (paper section 6) so its own scattering is not counted twice.
    pub exclude: (Vec3, Vec3),
}

/// Renders the radiance arriving at a point from every direction (the lit volume, sky, ground,
/// but **not** the direct sun) into a cube made with [`CubeImage::along`]`(res, x_axis)`.
pub trait CubeSource: Sync {
    /// Render one cube.
    fn render_cube(&self, req: &CubeRequest) -> CubeImage;
}

/// The attenuated sun, for exact single scattering and the sun's higher orders in segments.
#[derive(Clone, Copy)]
pub struct SunInput<'a> {
    /// Unit direction towards the sun.
    pub dir: Vec3,
    /// Sun irradiance reaching a point (W m⁻² per band), i.e. E_sun·exp(−τ_sun(p)).
    pub irradiance_at: &'a (dyn Fn(Vec3) -> Rgb + Sync),
}

/// Settings of the edge treatment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdgeSettings {
    /// T: densities below it use the edge treatment (`render.low_density_threshold`); 0 disables it.
    pub threshold: f32,
    /// Relative width of the blend band below T: T_lo = (1 − band)·T, in [0, 1].
    pub band: f32,
    /// Cube pixels per face edge.
    pub cube_res: usize,
    /// Bound on the omitted Poisson tail (eq. 8).
    pub tail: f64,
    /// Longest compositing step (m); pieces are cut to at most this length (the scene's
    /// `render.step` voxels times the smallest voxel edge).
    pub step_m: f32,
    /// Resolve bridges between segments smoothly (section 6 fix); false: the paper's hard switch.
    pub merge_transition: bool,
    /// D_s: optical depth (unitless, of the medium the gather sees, i.e. after the δ-M transform)
    /// of the **surface layer** — the first D_s of every eye ray, whatever its density — that is
    /// rendered with the Poisson orders of eqs. 8–9 like a low-density segment, not with the
    /// dense source (`render.surface_depth`); 0: only ρ < T, the paper's scheme.
    pub surface_depth: f32,
    /// Fraction of D_s over which the surface layer's edge weight falls from 1 to 0 (smoothstep in
    /// optical depth, ending at D_s), in [0, 1]; 0 switches abruptly at D_s.
    pub surface_band: f32,
}

impl Default for EdgeSettings {
    fn default() -> Self {
        EdgeSettings {
            threshold: DEFAULT_THRESHOLD,
            band: 0.5,
            cube_res: 16,
            tail: DEFAULT_TAIL,
            step_m: 5.0,
            merge_transition: true,
            surface_depth: DEFAULT_SURFACE_DEPTH,
            surface_band: 0.0,
        }
    }
}

impl EdgeSettings {
    /// Check the settings; `file` names the scene file for messages.
    pub fn validate(&self, file: &str) -> crate::error::Result<()> {
        crate::error::check(
            file,
            "render.low_density_threshold",
            self.threshold.is_finite() && self.threshold >= 0.0,
            self.threshold,
            "the edge threshold is a density ≥ 0 (0 turns the edge treatment off)",
        )?;
        crate::error::check(
            file,
            "render.surface_depth",
            self.surface_depth.is_finite() && self.surface_depth >= 0.0,
            self.surface_depth,
            "the surface layer's depth is an optical depth ≥ 0, e.g. 2 (0 turns it off)",
        )?;
        crate::error::check(
            file,
            "render.surface_band",
            (0.0..=1.0).contains(&self.surface_band),
            self.surface_band,
            "the surface layer's blend is a fraction of its depth in [0, 1]",
        )
    }
}

/// Default D_s for `render.surface_depth` (optical depth of the δ-M medium): the five scenes'
/// scores stop changing beyond 3 (docs/budget.md, "The surface layer"); with the sun's chord
/// on its orders ≥ 2, 4 lifts the glare sweep's ψ = 35°–60° views (docs/accuracy.md).
pub const DEFAULT_SURFACE_DEPTH: f32 = 4.0;

/// Default T for `render.low_density_threshold` (density units); see docs/edges.md.
pub const DEFAULT_THRESHOLD: f32 = 0.3;

/// One pixel's radiance split into its parts (W m⁻² sr⁻¹ per band); they add up to the pixel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EdgeAov {
    /// Dense-region (diffusion) emission, attenuated to the eye.
    pub diffusion: Rgb,
    /// Low-density multiple scattering E_j (orders ≥ 1 of the cube, ≥ 2 of the sun), attenuated.
    pub edge: Rgb,
    /// Exact single scattering of the sun, attenuated.
    pub sun_single: Rgb,
    /// Background (sky or ground) times the transmittance of the whole ray.
    pub background: Rgb,
    /// Transmittance of the whole ray.
    pub transmittance: f32,
    /// Number of cubes rendered for this pixel.
    pub cubes: u32,
}

impl EdgeAov {
    /// The pixel value.
    pub fn total(&self) -> Rgb {
        self.diffusion + self.edge + self.sun_single + self.background
    }
}

/// The final gather with the edge treatment over one medium.
pub struct EdgeGather<'a> {
    medium: &'a Medium,
    settings: EdgeSettings,
    kernel: OrderKernel,
    cubes: &'a dyn CubeSource,
    sun: SunInput<'a>,
    dense: &'a (dyn Fn(Vec3, Vec3) -> Rgb + Sync),
    /// Where ρ > 0 ([`density_bounds`]): the eye rays' profiles start there.
    bounds: (Vec3, Vec3),
    /// The δ-M peak's spread on the sun's leg and the sun's irradiance above the medium (W m⁻²
    /// per band), when set ([`EdgeGather::with_peak_spread`]).
    peak: Option<(PeakSpread, Rgb)>,
    /// The δ-M chord along the sun that weights the sun's orders ≥ 2 ([`EdgeGather::with_sun_chord`]).
    chord: Option<&'a SunChord>,
}

/// One low-density segment (or a bridge's merged/split variant) whose E is needed for a pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdgeJob {
    /// The segment (pieces of the plan's profile, D_j, c_j).
    pub seg: LowSegment,
    /// Weight of its edge source (1 without bridges).
    pub weight: f32,
    /// Index j among the ray's top-level segments when this job is one whole, unbridged segment
    /// (the only kind the sparse gather interpolates).
    pub top: Option<usize>,
}

/// A ray's profile and edge jobs, before any cube is rendered.
#[derive(Clone, Debug)]
pub struct PixelPlan {
    /// Ray origin (m).
    pub o: Vec3,
    /// Unit ray direction.
    pub d: Vec3,
    /// The density profile.
    pub profile: RayProfile,
    /// The segments whose E the composite needs.
    pub jobs: Vec<EdgeJob>,
    /// Pieces `0..surface_end` lie in the surface layer (the first D_s of optical depth).
    pub surface_end: usize,
    /// The sun irradiance at each piece's midpoint (where the composite takes a one-step piece's
    /// sources); the segments' sun for orders ≥ 2 is their depth-weighted mean.
    pub sun: Vec<Rgb>,
}

/// Sun samples per segment at least, for its orders ≥ 2 (with the surface layer): pieces longer
/// than 1/8 of their segment are subdivided ([`EdgeGather::segment_sun`]).
const SUN_SAMPLES: f64 = 8.0;

/// Largest segment optical depth whose orders are tabulated separately (deeper ones reuse the last).
const MAX_TABULATED_DEPTH: f64 = 40.0;

impl<'a> EdgeGather<'a> {
    /// Prepare the gather: tabulates the order weights for `settings.cube_res` and the medium's g.
    /// `dense(p, dir_to_eye)` is the dense-region source: radiance emitted per unit optical depth
    /// at p (already including the albedo), e.g. a·I0(p) from the diffusion solution.
    pub fn new(
        medium: &'a Medium,
        settings: EdgeSettings,
        cubes: &'a dyn CubeSource,
        sun: SunInput<'a>,
        dense: &'a (dyn Fn(Vec3, Vec3) -> Rgb + Sync),
    ) -> Self {
        let orders = OrderKernel::orders_to_tabulate(medium.optics.phase, MAX_TABULATED_DEPTH, settings.tail);
        let kernel = OrderKernel::new(settings.cube_res.max(1), medium.optics.phase, orders);
        EdgeGather {
            medium,
            settings,
            kernel,
            cubes,
            sun,
            dense,
            bounds: density_bounds(medium).unwrap_or((Vec3::ZERO, Vec3::ZERO)),
            peak: None,
            chord: None,
        }
    }

    /// Weight the segments' sun order i ≥ 2 by s^{i−1}, s the chance that the sun's scattered
    /// light stays in the cloud along the sun's chord relative to the surface layer's own
    /// ([`SunChord::stay_at`], docs/edges.md). Without it every order stays (eq. 8 alone).
    pub fn with_sun_chord(mut self, chord: &'a SunChord) -> Self {
        self.chord = Some(chord);
        self
    }

    /// Spread the sun's peak and smooth parts by the peak scatterings on the sun's leg
    /// ([`crate::peak::PeakSpread`]): λ = af τ_⊙ = k (−ln T′_⊙), T′_⊙ = E_⊙(p)/`sun_irradiance`
    /// (the unattenuated sun, W m⁻² per band). Without it the sun term keeps HG's sharp shape
    /// however deep the point lies.
    pub fn with_peak_spread(mut self, sun_irradiance: Rgb) -> Self {
        let o = &self.medium.optics;
        let f = o.forward_fraction();
        if f > 0.0 {
            self.peak = Some((PeakSpread::similarity(o.sun_single.1.mean_cosine(), f), sun_irradiance));
        }
        self
    }

    /// The tabulated kernel (read by examples/edges_sparse.rs).
    #[cfg_attr(not(feature = "internals"), allow(dead_code))]
    pub fn kernel(&self) -> &OrderKernel {
        &self.kernel
    }

    /// The profile of `o + t·d`, t ∈ [0, `t_max`], cut at `levels`, walked only where ρ > 0.
    pub fn profile(&self, o: Vec3, d: Vec3, t_max: f32, levels: &[f32]) -> RayProfile {
        RayProfile::trace_in(self.medium, self.bounds, o, d, 0.0, t_max, levels)
    }

    /// The settings.
    pub fn settings(&self) -> &EdgeSettings {
        &self.settings
    }

    /// Lower end of the blend band.
    fn t_lo(&self) -> f32 {
        self.settings.threshold * (1.0 - self.settings.band.clamp(0.0, 1.0))
    }

    /// Dense weight w(ρ).
    fn dense_weight(&self, rho: f32) -> f32 {
        let t = self.settings.threshold;
        if t <= 0.0 || rho >= t {
            return 1.0;
        }
        let lo = self.t_lo();
        if rho <= lo {
            return 0.0;
        }
        let x = (rho - lo) / (t - lo);
        x * x * (3.0 - 2.0 * x)
    }

    /// Render the cube of a segment and convolve it: K_i for orders 1..=`orders`.
    pub fn segment_k(&self, o: Vec3, d: Vec3, seg: &LowSegment, orders: usize) -> Vec<Rgb> {
        let req = CubeRequest {
            center: seg.center(o, d),
            x_axis: d,
            res: self.settings.cube_res,
            exclude: (
                (o.as_dvec3() + d.as_dvec3() * seg.t0).as_vec3(),
                (o.as_dvec3() + d.as_dvec3() * seg.t1).as_vec3(),
            ),
        };
        let cube = self.cubes.render_cube(&req);
        self.kernel.convolve(&cube, orders)
    }

    /// Orders eq. 8 needs for a segment.
    pub fn orders_for(&self, seg: &LowSegment) -> usize {
        OrderKernel::orders_for_depth(seg.depth, self.settings.tail)
    }

    /// E_j from the cube's K_i (eq. 9 with albedo) plus the sun's orders ≥ 2 as a delta. If `k`
    /// holds fewer orders than needed, the last one is reused (high orders are nearly isotropic).
    pub fn segment_radiance_from_k(&self, plan: &PixelPlan, seg: &LowSegment, k: &[Rgb]) -> Rgb {
        let m = self.medium;
        let d = plan.d;
        let q = self.orders(seg.depth);
        let mut e = self.cube_part(&q, k);
        let es = self.segment_sun(plan, seg);
        if es.max_element() > 0.0 && q.len() >= 2 {
            // cos θ = (−ω_sun)·(−d): sunlight leaving towards the eye.
            let c = self.sun.dir.dot(d) as f64;
            let phase = m.optics.phase;
            let stay = self.chord.map_or(1.0, |ch| self.segment_stay(plan, seg, ch));
            let ks: Vec<Rgb> = (1..=q.len())
                .map(|i| es * (phase.order(i).eval_cos_f64(c) * stay.powi(i as i32 - 1)) as f32)
                .collect();
            e += edge_radiance(&q, &ks, m.optics.albedo, 2);
        }
        e
    }

    /// Poisson weights q_i (i ≥ 1) of a segment of optical depth `depth` (eq. 8).
    pub fn orders(&self, depth: f64) -> Vec<f64> {
        segment_orders(depth, self.settings.tail)
    }

    /// The cube's part of E_j, Σ_{i≥1} q_i a^i K_i, with the segment's Poisson weights `q`
    /// ([`Self::orders`]); K's last order serves the orders beyond it.
    pub fn cube_part(&self, q: &[f64], k: &[Rgb]) -> Rgb {
        edge_radiance(q, k, self.medium.optics.albedo, 1)
    }

    /// The sun irradiance (W m⁻² per band) the segment's orders ≥ 2 start from. The paper's
    /// segments are thin and take it at c_j; with the surface layer (`surface_depth` > 0) a
    /// segment spans optical depths of 1–3, across which the sun decays convexly, so it is the mean
    /// over the segment per unit optical depth (given i collisions, Poisson's first one is uniform
    /// in optical depth): the pieces' midpoint irradiances (`plan.sun`, which the composite uses
    /// too) weighted by their exact optical depths.
    fn segment_sun(&self, plan: &PixelPlan, seg: &LowSegment) -> Rgb {
        let at_centre = || (self.sun.irradiance_at)(seg.center(plan.o, plan.d));
        if self.settings.surface_depth <= 0.0 {
            return at_centre();
        }
        let (od, dd) = (plan.o.as_dvec3(), plan.d.as_dvec3());
        let len = seg.t1 - seg.t0;
        let (mut acc, mut tau) = (Rgb::ZERO, 0f64);
        for (p, e) in plan.profile.pieces[seg.first..seg.end].iter().zip(&plan.sun[seg.first..seg.end]) {
            // A piece longer than 1/SUN_SAMPLES of the segment (a coarse grid) is sampled at
            // that spacing, its ρ taken as uniform: the sun decays convexly across it.
            let n = (SUN_SAMPLES * (p.t1 - p.t0) / len).ceil().max(1.0);
            if n <= 1.0 {
                acc += *e * p.tau as f32;
            } else {
                let mut sum = Rgb::ZERO;
                for s in 0..n as usize {
                    let t = p.t0 + (p.t1 - p.t0) * (s as f64 + 0.5) / n;
                    sum += (self.sun.irradiance_at)((od + dd * t).as_vec3());
                }
                acc += sum * (p.tau / n) as f32;
            }
            tau += p.tau;
        }
        if tau > 0.0 {
            acc / tau as f32
        } else {
            at_centre()
        }
    }

    /// The chord's factor ([`SunChord::stay_at`]) over the segment, at its pieces' midpoints
    /// weighted as its sun is ([`Self::segment_sun`]: where the first collisions lie).
    fn segment_stay(&self, plan: &PixelPlan, seg: &LowSegment, chord: &SunChord) -> f64 {
        let (od, dd) = (plan.o.as_dvec3(), plan.d.as_dvec3());
        let (mut num, mut den) = (0f64, 0f64);
        for (p, e) in plan.profile.pieces[seg.first..seg.end].iter().zip(&plan.sun[seg.first..seg.end]) {
            let w = e.max_element() as f64 * p.tau;
            let mid = (od + dd * (0.5 * (p.t0 + p.t1))).as_vec3();
            num += w * chord.stay_at(self.medium.to_voxel(mid));
            den += w;
        }
        if den > 0.0 {
            num / den
        } else {
            chord.stay_at(self.medium.to_voxel(seg.center(plan.o, plan.d)))
        }
    }

    /// E_j for a segment of `plan`, rendering its cube.
    pub fn segment_radiance(&self, plan: &PixelPlan, seg: &LowSegment) -> Rgb {
        let k = self.segment_k(plan.o, plan.d, seg, self.orders_for(seg));
        self.segment_radiance_from_k(plan, seg, &k)
    }

    /// Edge jobs of `seg` (pieces `seg.first..seg.end`, from [`RayProfile::segment`]) with weight
    /// `weight`, resolving bridges recursively.
    fn plan_edge(&self, prof: &RayProfile, seg: LowSegment, weight: f32, depth: usize, top: Option<usize>, jobs: &mut Vec<EdgeJob>) {
        let (first, end) = (seg.first, seg.end);
        if seg.depth <= 1e-12 {
            return;
        }
        let bridge = if self.settings.merge_transition && depth < MAX_BRIDGE_DEPTH {
            self.strongest_bridge(prof, first, end)
        } else {
            None
        };
        let wb = bridge.map_or(0.0, |b| b.1);
        jobs.push(EdgeJob {
            seg,
            weight: weight * (1.0 - wb),
            top: if bridge.is_none() { top } else { None },
        });
        if let Some((split, wb)) = bridge {
            let m = self.medium;
            self.plan_edge(prof, prof.segment(m, first, split), weight * wb, depth + 1, None, jobs);
            self.plan_edge(prof, prof.segment(m, split, end), weight * wb, depth + 1, None, jobs);
        }
    }

    /// The interior band run of pieces `first..end` with the largest dense weight: returns the
    /// piece index to split before (the boundary nearest the run's density maximum) and w_b.
    fn strongest_bridge(&self, prof: &RayProfile, first: usize, end: usize) -> Option<(usize, f32)> {
        let lo = self.t_lo();
        let gap = self.gap_level();
        let ps = &prof.pieces;
        let mut best: Option<(usize, f32)> = None;
        // Two kinds of interior runs: dense bridges (ρ ≥ T_lo, strength w(max ρ)) and near-gaps
        // (ρ < gap level, strength 1 − smoothstep(0, gap, min ρ)).
        for dense in [true, false] {
            let inside = |p: &super::segments::Piece| if dense { p.rho[1] >= lo } else { p.rho[1] < gap };
            let mut k = first;
            while k < end {
                if !inside(&ps[k]) {
                    k += 1;
                    continue;
                }
                let run0 = k;
                while k < end && inside(&ps[k]) {
                    k += 1;
                }
                // Interior only: other pieces on both sides within the segment.
                if run0 == first || k == end {
                    continue;
                }
                // The boundary inside the run with the most extreme density; a one-piece run
                // splits at its end nearer the extreme.
                let better = |a: f32, b: f32| if dense { a > b } else { a < b };
                let at = |b: usize| if b < k { ps[b].rho[0] } else { ps[k - 1].rho[2] };
                let (mut arg, mut ext) = (run0, at(run0));
                for b in run0 + 1..=k {
                    if better(at(b), ext) {
                        ext = at(b);
                        arg = b;
                    }
                }
                for p in &ps[run0..k] {
                    if better(p.rho[1], ext) {
                        ext = p.rho[1];
                    }
                }
                let w = if dense {
                    self.dense_weight(ext)
                } else {
                    let x = (ext / gap).clamp(0.0, 1.0);
                    1.0 - x * x * (3.0 - 2.0 * x)
                };
                if w > 0.0 && arg > first && arg < end && !matches!(best, Some(b) if b.1 >= w) {
                    best = Some((arg, w));
                }
            }
        }
        best
    }

    /// Density below which an interior stretch of a segment counts as a near-gap.
    fn gap_level(&self) -> f32 {
        GAP_FRACTION * self.t_lo()
    }

    /// Trace the ray's profile and list its edge jobs (no cube rendered yet).
    pub fn plan(&self, o: Vec3, d: Vec3, t_max: f32) -> PixelPlan {
        let m = self.medium;
        let t = self.settings.threshold;
        let levels = [self.gap_level(), self.t_lo(), t];
        let levels: &[f32] = if t > 0.0 { &levels } else { &[] };
        let mut profile = self.profile(o, d, t_max, levels);
        if self.settings.merge_transition && t > 0.0 {
            refine_extrema(&mut profile, m, self.gap_level(), self.t_lo(), t);
        }
        let surface_end = self.cut_surface(&mut profile);
        let mut jobs = Vec::new();
        for (j, seg) in self.top_segments(&profile, surface_end).into_iter().enumerate() {
            // A segment in the surface layer is one Poisson segment: no bridge splits it (its
            // dense stretches are what it is for).
            let depth = if seg.first < surface_end { MAX_BRIDGE_DEPTH } else { 0 };
            self.plan_edge(&profile, seg, 1.0, depth, Some(j), &mut jobs);
        }
        let (od, dd) = (o.as_dvec3(), d.as_dvec3());
        let sun = profile
            .pieces
            .iter()
            .map(|p| (self.sun.irradiance_at)((od + dd * piece_midpoint(p)).as_vec3()))
            .collect();
        PixelPlan {
            o,
            d,
            profile,
            jobs,
            surface_end,
            sun,
        }
    }

    /// Cut `profile` at the surface layer's depth D_s; the number of pieces in the layer.
    pub fn cut_surface(&self, profile: &mut RayProfile) -> usize {
        if self.settings.surface_depth > 0.0 {
            profile.cut_at_depth(self.medium, self.settings.surface_depth as f64)
        } else {
            0
        }
    }

    /// The ray's top-level edge segments: maximal contiguous runs of pieces with ρ < T (the
    /// paper's S_j) or in the surface layer (pieces `0..surface_end`). A segment that holds
    /// surface pieces (optical depth up to D_s) has its cube at the depth where the eye sees its
    /// light scattered, [`eye_weighted_depth`], not at its optical midpoint: where the sun enters
    /// steeply the diffuse field grows with depth across the layer, and the midpoint would read it
    /// too bright (docs/edges.md, "Where the layer's cube stands"). The paper's thin segments keep
    /// their midpoint (the two agree to D²/12).
    pub fn top_segments(&self, profile: &RayProfile, surface_end: usize) -> Vec<LowSegment> {
        let t = self.settings.threshold;
        if t <= 0.0 && surface_end == 0 {
            return Vec::new();
        }
        let mut segs = profile.segments_where(self.medium, |k, p| k < surface_end || p.rho[1] < t);
        for s in segs.iter_mut().filter(|s| s.first < surface_end) {
            s.t_center = profile.t_at_depth(self.medium, s.first, s.end, eye_weighted_depth(s.depth));
        }
        segs
    }

    /// Edge weight of the surface layer at optical depth `tau` from the ray's start: 1, falling
    /// by a smoothstep to 0 over the last `surface_band` of D_s.
    fn surface_weight(&self, tau: f64) -> f32 {
        let ds = self.settings.surface_depth as f64;
        if tau >= ds {
            return 0.0;
        }
        let lo = ds * (1.0 - self.settings.surface_band.clamp(0.0, 1.0) as f64);
        if tau <= lo {
            return 1.0;
        }
        let x = ((tau - lo) / (ds - lo)) as f32;
        1.0 - x * x * (3.0 - 2.0 * x)
    }

    /// Radiance along `o + t·d` (`d` unit) for t ∈ [0, t_max], with `background` the radiance
    /// arriving from beyond t_max (sky or ground), split into its parts. Renders one cube per
    /// edge job.
    pub fn radiance(&self, o: Vec3, d: Vec3, t_max: f32, background: Rgb) -> EdgeAov {
        let plan = self.plan(o, d, t_max);
        let e: Vec<Rgb> = plan.jobs.iter().map(|j| self.segment_radiance(&plan, &j.seg)).collect();
        let mut aov = self.composite(&plan, &e, background);
        aov.cubes = plan.jobs.len() as u32;
        aov
    }

    /// Composite a planned ray front to back, given E for each of its jobs.
    pub fn composite(&self, plan: &PixelPlan, e: &[Rgb], background: Rgb) -> EdgeAov {
        let m = self.medium;
        let (o, d, prof) = (plan.o, plan.d, &plan.profile);
        let mut aov = EdgeAov::default();
        // A ray without jobs has no edge source anywhere: nothing allocated.
        let mut edge_src = if plan.jobs.is_empty() {
            Vec::new()
        } else {
            vec![Rgb::ZERO; prof.pieces.len()]
        };
        for (job, ej) in plan.jobs.iter().zip(e) {
            let s = *ej / (-(-job.seg.depth).exp_m1()) as f32 * job.weight;
            for x in &mut edge_src[job.seg.first..job.seg.end] {
                *x += s;
            }
        }
        // The peak's part counted once: weighted by T_eye^{af} = T′^k (Optics::sun_scatter_split).
        let (sun_smooth, sun_peak, peak_k) = m.optics.sun_scatter_split(self.sun.dir, -d);
        // The peak scatterings' spread (4π-normalised series, per band's albedo factor).
        let spread = self.peak.as_ref().map(|(s, e)| {
            (
                s,
                s.legendre(self.sun.dir.dot(d) as f64),
                e.y,
                m.optics.sun_single.0 / (4.0 * std::f32::consts::PI),
            )
        });
        // (smooth, peak) parts at a point the sun reaches with E_⊙ and seen through the δ-M
        // transmittance `tr_eye`: both spread by the λ = k τ′_⊙ peak scatterings on the sun's leg,
        // the smooth part also by the k τ′_eye on the eye's leg (`PeakSpread::spread_split_with`).
        let sun_at = |sun: Rgb, tr_eye: f64| -> (Rgb, Rgb) {
            match &spread {
                Some((s, legendre, e, a)) if sun.y > 0.0 && *e > 0.0 => {
                    let lambda = peak_k as f64 * -(sun.y as f64 / *e as f64).min(1.0).ln();
                    let (smooth, peak) = s.spread_split_with(lambda, peak_k as f64 * -tr_eye.ln(), legendre);
                    (sun_smooth + *a * smooth as f32, sun_peak + *a * peak as f32)
                }
                _ => (sun_smooth, sun_peak),
            }
        };
        let to_eye = -d;
        let mut tr = 1.0f64;
        // Optical depth from the ray's start (the surface layer's coordinate).
        let mut tau = 0.0f64;
        let (od, dd) = (o.as_dvec3(), d.as_dvec3());
        'pieces: for (k, p) in prof.pieces.iter().enumerate() {
            let n = ((p.t1 - p.t0) / self.settings.step_m.max(1e-6) as f64).ceil().max(1.0) as usize;
            // ρ at the step's start: the previous step's end (the same t, so the same bits).
            let mut r_start = None;
            for s in 0..n {
                let ta = p.t0 + (p.t1 - p.t0) * s as f64 / n as f64;
                let tb = p.t0 + (p.t1 - p.t0) * (s + 1) as f64 / n as f64;
                let tm = if n == 1 { piece_midpoint(p) } else { 0.5 * (ta + tb) };
                // ρ at the midpoint serves both the step's depth and its weights; a one-step
                // piece's midpoint density is the profile's own.
                let rho = if n == 1 { p.rho[1] } else { prof.rho(m, tm) };
                let delta = if n == 1 {
                    p.tau
                } else {
                    let ra = r_start.unwrap_or_else(|| prof.rho(m, ta));
                    let rb = prof.rho(m, tb);
                    r_start = Some(rb);
                    depth_from_samples(m, ta, tb, [ra, rho, rb])
                };
                if delta <= 0.0 {
                    continue;
                }
                let pos = (od + dd * tm).as_vec3();
                let mut w = self.dense_weight(rho);
                if k < plan.surface_end {
                    w = w.min(1.0 - self.surface_weight(tau + 0.5 * delta));
                }
                tau += delta;
                // e^{−δ} − 1 once for the step's weight and the transmittance behind it.
                let em1 = (-delta).exp_m1();
                let f = (tr * -em1) as f32;
                if w > 0.0 {
                    aov.diffusion += f * w * (self.dense)(pos, to_eye);
                }
                if w < 1.0 {
                    aov.edge += f * (1.0 - w) * edge_src.get(k).copied().unwrap_or(Rgb::ZERO);
                }
                let sun = if n == 1 { plan.sun[k] } else { (self.sun.irradiance_at)(pos) };
                // The spread series dips below 0 in places (as transport's sun_phase): clamped there.
                let (smooth, peak) = sun_at(sun, tr);
                aov.sun_single += f * sun * (smooth + peak * (tr as f32).powf(peak_k)).max(Rgb::ZERO);
                tr *= 1.0 + em1;
                if tr < crate::medium::march::T_CUTOFF as f64 {
                    tr = 0.0;
                    break 'pieces;
                }
            }
        }
        aov.transmittance = tr as f32;
        aov.background = background * tr as f32;
        aov
    }
}

/// The midpoint of a piece as the composite's one-step rule computes it (the same bits).
#[inline]
fn piece_midpoint(p: &super::segments::Piece) -> f64 {
    0.5 * (p.t0 + (p.t0 + (p.t1 - p.t0)))
}

/// Cut pieces at interior density maxima in the blend band and interior minima below the gap
/// level (golden-section search on the cubic), so bridges split exactly where the two segments
/// would separate.
fn refine_extrema(prof: &mut RayProfile, m: &Medium, gap: f32, lo: f32, hi: f32) {
    let mut k = 0;
    while k < prof.pieces.len() {
        let p = prof.pieces[k];
        let max = p.rho[1] >= lo && p.rho[1] < hi && p.rho[1] > p.rho[0] && p.rho[1] > p.rho[2];
        let min = p.rho[1] < gap && p.rho[1] < p.rho[0] && p.rho[1] < p.rho[2];
        if !(max || min) {
            k += 1;
            continue;
        }
        let sign = if max { 1.0 } else { -1.0 };
        let (mut a, mut b) = (p.t0, p.t1);
        let gr = 0.5 * (5f64.sqrt() - 1.0);
        while b - a > super::segments::bisection_tolerance(b) {
            let c = b - gr * (b - a);
            let e = a + gr * (b - a);
            if sign * prof.rho(m, c) > sign * prof.rho(m, e) {
                b = e;
            } else {
                a = c;
            }
        }
        let tc = 0.5 * (a + b);
        if tc > p.t0 && tc < p.t1 {
            prof.split_piece(m, k, tc);
            k += 2;
        } else {
            k += 1;
        }
    }
}
