//! Exact density profile along a ray, cut into pieces at chosen density levels, and the paper's
//! low-density segments S_j (0 < ρ < T) with their optical depth D_j and centre c_j.
//!
//! Inside one *dual* cell (between adjacent voxel centres) the trilinear density is a cubic in the
//! ray distance, so Simpson's rule gives its integral exactly over any sub-interval (as in
//! [`Medium::density_integral`]). The profile walks the dual lattice (skipping empty majorant
//! blocks), drops cells where ρ ≡ 0 (a cubic that vanishes at five points vanishes everywhere),
//! and splits the others where ρ crosses a level. Crossings are located by bisection between five
//! samples per cell; a level crossed twice between two samples (a dip shorter than a quarter
//! cell) is missed, which only moves a piece boundary, never the optical depth.

use crate::math::{Trilinear, Vec3};
use crate::medium::dda::ray_box;
use crate::medium::Medium;
use glam::DVec3;

/// Samples per dual cell used to detect level crossings (cell quarters).
const CELL_SAMPLES: usize = 4;

/// A stretch of ray inside one dual cell with ρ on one side of every level.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Piece {
    /// Start (m along the ray).
    pub t0: f64,
    /// End (m).
    pub t1: f64,
    /// Optical depth σt∫ρ ds over the piece (exact).
    pub tau: f64,
    /// ρ at start, middle, end.
    pub rho: [f32; 3],
}

/// The non-empty pieces of a ray through the medium, front to back.
#[derive(Clone, Debug)]
pub struct RayProfile {
    /// Pieces in order of t; consecutive pieces touch unless empty space lies between them.
    pub pieces: Vec<Piece>,
    o: DVec3,
    d: DVec3,
}

/// A maximal run of contiguous pieces whose mid-density is below a level (paper's S_j).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LowSegment {
    /// Entry (m along the ray).
    pub t0: f64,
    /// Exit (m).
    pub t1: f64,
    /// Optical depth D_j (unitless).
    pub depth: f64,
    /// Distance (m) of the cube centre c_j: where the optical depth from t0 reaches D_j/2 (a
    /// surface-layer segment: `orders::eye_weighted_depth`, set by `EdgeGather::top_segments`).
    pub t_center: f64,
    /// Pieces `first..end` of the profile.
    pub first: usize,
    /// One past the last piece.
    pub end: usize,
}

impl LowSegment {
    /// c_j in world space.
    pub fn center(&self, o: Vec3, d: Vec3) -> Vec3 {
        (o.as_dvec3() + d.as_dvec3() * self.t_center).as_vec3()
    }
}

/// Width (m) at which a bisection in t stops: 10⁻⁹ of the distance (and at least 1 nm), 60×
/// finer than an f32 position resolves there (the cube centres and the gather's points are f32).
#[inline]
pub(crate) fn bisection_tolerance(t: f64) -> f64 {
    1e-9 * (1.0 + t.abs())
}

/// Where a bracketed function changes side: `f(t)` = (t on a's side?, a signed value, ≤ 0 on a's
/// side and ≥ 0 on b's), with `fa` ≤ 0 ≤ `fb` its values at the ends. Illinois false position, each
/// point kept at least a quarter of [`bisection_tolerance`] inside the bracket so the bracket
/// closes to that width; plain bisection after [`FALSE_POSITION_STEPS`] steps bounds the count.
/// On the smooth cubics here it takes ~6 look-ups where bisection took ~25.
pub(crate) fn find_crossing(mut a: f64, mut fa: f64, mut b: f64, mut fb: f64, f: impl Fn(f64) -> (bool, f64)) -> f64 {
    // Which end the last step kept: the Illinois rule halves an end's value when it is kept twice,
    // so the other end moves too and the bracket closes from both sides.
    let mut kept_b = None;
    let mut steps = 0;
    while b - a > bisection_tolerance(b) {
        let eps = 0.25 * bisection_tolerance(b);
        let c = if steps < FALSE_POSITION_STEPS && fb > fa {
            a + (b - a) * (-fa / (fb - fa))
        } else {
            0.5 * (a + b)
        };
        let c = c.clamp(a + eps, b - eps);
        let (left, fc) = f(c);
        if left {
            a = c;
            fa = fc.min(0.0);
            if kept_b == Some(true) {
                fb *= 0.5;
            }
            kept_b = Some(true);
        } else {
            b = c;
            fb = fc.max(0.0);
            if kept_b == Some(false) {
                fa *= 0.5;
            }
            kept_b = Some(false);
        }
        steps += 1;
    }
    0.5 * (a + b)
}

/// Steps of false position before [`find_crossing`] falls back to bisection.
const FALSE_POSITION_STEPS: usize = 16;

/// ρ at distance t along the ray (inside the box).
#[inline]
fn rho_at(m: &Medium, o: DVec3, d: DVec3, t: f64) -> f32 {
    let v = ((o + d * t) - m.origin.as_dvec3()) / m.voxel_size.as_dvec3();
    m.density.trilinear([v.x as f32, v.y as f32, v.z as f32])
}

/// The trilinear ρ inside one dual cell: its 8 corner voxels read once, then expanded along a
/// ray into a cubic ([`CellCubic`]) that the cell's samples and crossings evaluate.
struct CellDensity {
    corners: [f32; 8],
    /// The cell's lower corner in the voxel-centre lattice (voxel coordinates − ½).
    lo: [f32; 3],
}

impl CellDensity {
    /// Dual cell `cell` (between voxel centres `cell − 1` and `cell`, clamped to the grid).
    fn new(m: &Medium, cell: [usize; 3]) -> CellDensity {
        let dims = m.density.dims();
        let lo: [usize; 3] = std::array::from_fn(|a| cell[a].saturating_sub(1).min(dims[a] - 1));
        let hi: [usize; 3] = std::array::from_fn(|a| cell[a].min(dims[a] - 1));
        // The same voxels as eight `get`s (a stride is 0 where the cell is clamped at the side).
        let corners = m.density.corners(&Trilinear::corner_indices(dims, lo, hi));
        CellDensity {
            corners,
            lo: std::array::from_fn(|a| cell[a] as f32 - 1.0),
        }
    }

    /// The dual cell holding the point at distance `t` along the ray.
    fn containing(m: &Medium, o: DVec3, d: DVec3, t: f64) -> CellDensity {
        let v = ((o + d * t) - m.origin.as_dvec3()) / m.voxel_size.as_dvec3();
        let dims = m.density.dims();
        // Dual cell c spans voxel coordinates [c − ½, c + ½]; the grid has dims + 1 of them.
        let cell = std::array::from_fn(|a| ((v[a] + 0.5).floor().max(0.0) as usize).min(dims[a]));
        CellDensity::new(m, cell)
    }

    /// No density anywhere in the cell (a trilinear blend of zeros).
    fn is_empty(&self) -> bool {
        self.corners.iter().all(|c| *c == 0.0)
    }

    /// Whether ρ > 0 everywhere in the cell and no level (the positive ones) lies between its
    /// smallest and largest corner, with a relative margin of 10⁻⁵ so that the expanded cubic's
    /// rounding (~10⁻¹⁴ relative) cannot put a sample across: the trilinear blend lies between its
    /// corners, so the samples would find no crossing either.
    fn clear_of(&self, levels: &[f32]) -> bool {
        let lo = self.corners.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = self.corners.iter().copied().fold(0.0, f32::max);
        lo > 0.0 && levels.iter().all(|&l| l <= 0.0 || hi < l * (1.0 - 1e-5) || lo > l * (1.0 + 1e-5))
    }

    /// The trilinear ρ along the ray inside the cell as a cubic in τ = t − `t0` (the blend's three
    /// lerps with fractions linear in τ, expanded in f64), so that each look-up is three
    /// multiply-adds instead of a position and a blend; within rounding of [`rho_at`].
    fn cubic(&self, m: &Medium, o: DVec3, d: DVec3, t0: f64) -> CellCubic {
        let h = m.voxel_size.as_dvec3();
        let v = ((o + d * t0) - m.origin.as_dvec3()) / h;
        let g = d / h;
        // Fraction on axis a: f[a] + g[a]·τ (from the cell's lower corner).
        let f = [
            v.x - 0.5 - self.lo[0] as f64,
            v.y - 0.5 - self.lo[1] as f64,
            v.z - 0.5 - self.lo[2] as f64,
        ];
        let c = |n: usize| self.corners[n] as f64;
        // Along x: lines a + b·τ for the four (y, z) edges.
        let line = |n: usize| {
            let dx = c(n + 1) - c(n);
            [c(n) + f[0] * dx, g[0] * dx]
        };
        // Along y: quadratics for z = 0, 1 (lerp of two lines by a linear fraction).
        let quad = |n: usize| {
            let (p, q) = (line(n), line(n + 2));
            let (d0, d1) = (q[0] - p[0], q[1] - p[1]);
            [p[0] + f[1] * d0, p[1] + f[1] * d1 + g[1] * d0, g[1] * d1]
        };
        let (p, q) = (quad(0), quad(4));
        let dq = [q[0] - p[0], q[1] - p[1], q[2] - p[2]];
        CellCubic {
            t0,
            c: [
                p[0] + f[2] * dq[0],
                p[1] + f[2] * dq[1] + g[2] * dq[0],
                p[2] + f[2] * dq[2] + g[2] * dq[1],
                g[2] * dq[2],
            ],
        }
    }
}

/// ρ along a ray inside one dual cell: a cubic in τ = t − t0 ([`CellDensity::cubic`]).
struct CellCubic {
    t0: f64,
    c: [f64; 4],
}

impl CellCubic {
    /// ρ at distance t (clamped at 0: the blend of non-negative corners never goes below it,
    /// the expanded cubic may by rounding).
    #[inline]
    fn at(&self, t: f64) -> f32 {
        let x = t - self.t0;
        let c = &self.c;
        ((((c[3] * x + c[2]) * x + c[1]) * x + c[0]) as f32).max(0.0)
    }
}

/// The world box (m) outside which ρ ≡ 0: the non-empty voxels' index box grown by one voxel
/// (the trilinear field reaches the neighbouring centres, and the grid's side where it is
/// clamped), or None for an empty medium.
pub fn density_bounds(m: &Medium) -> Option<(Vec3, Vec3)> {
    let (lo, hi) = m.active_box(1)?;
    let at = |c: [usize; 3]| m.origin + m.voxel_size * Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32);
    Some((at(lo), at(hi)))
}

impl RayProfile {
    /// Profile `o + t·d` (`d` unit), t ∈ [t_min, t_max], split wherever ρ crosses one of `levels`
    /// (density units; non-positive levels are ignored).
    pub fn trace(m: &Medium, o: Vec3, d: Vec3, t_min: f32, t_max: f32, levels: &[f32]) -> RayProfile {
        Self::trace_in(m, m.bbox(), o, d, t_min, t_max, levels)
    }

    /// [`Self::trace`] over the part of the ray inside `bounds` (world box, m), which must hold
    /// every point where ρ > 0 (e.g. [`density_bounds`]): the block walk then starts at the cloud,
    /// not at the grid's side.
    pub fn trace_in(m: &Medium, bounds: (Vec3, Vec3), o: Vec3, d: Vec3, t_min: f32, t_max: f32, levels: &[f32]) -> RayProfile {
        let (od, dd) = (o.as_dvec3(), d.as_dvec3());
        let mut prof = RayProfile {
            pieces: Vec::new(),
            o: od,
            d: dd,
        };
        let (lo, hi) = bounds;
        let Some((t0, t1)) = ray_box(lo.as_dvec3(), hi.as_dvec3(), od, dd, t_min as f64, t_max as f64) else {
            return prof;
        };
        let (t0, t1) = (t0 as f32, t1 as f32);
        let sigma_t = m.optics.sigma_t as f64;
        // Allocated only on a ray's first level crossing (most rays have none).
        let mut cuts: Vec<f64> = Vec::new();
        // Rays into the cloud have tens of pieces; the surface cut inserts one more.
        prof.pieces.reserve(64);
        m.for_each_dual_run(o, d, t0, t1, |cells| {
            for s in cells {
                let cell = CellDensity::new(m, s.cell);
                if cell.is_empty() {
                    continue;
                }
                let cubic = cell.cubic(m, od, dd, s.t0);
                let rho = |t: f64| cubic.at(t);
                let sample_t = |k: usize| s.t0 + (s.t1 - s.t0) * k as f64 / CELL_SAMPLES as f64;
                let piece = |r: [f32; 3]| Piece {
                    t0: s.t0,
                    t1: s.t1,
                    tau: sigma_t * (s.t1 - s.t0) / 6.0 * (r[0] as f64 + 4.0 * r[1] as f64 + r[2] as f64),
                    rho: r,
                };
                if cell.clear_of(levels) {
                    // ρ inside the cell lies between its corners, all on one side of every level
                    // and positive: no crossing, one piece from the samples at 0, ½, 1.
                    prof.pieces.push(piece([
                        rho(sample_t(0)),
                        rho(sample_t(CELL_SAMPLES / 2)),
                        rho(sample_t(CELL_SAMPLES)),
                    ]));
                    continue;
                }
                let simpson = |a: f64, b: f64| -> (f64, [f32; 3]) {
                    let r = [rho(a), rho(0.5 * (a + b)), rho(b)];
                    (sigma_t * (b - a) / 6.0 * (r[0] as f64 + 4.0 * r[1] as f64 + r[2] as f64), r)
                };
                let mut samples = [(0f64, 0f32); CELL_SAMPLES + 1];
                for (k, sm) in samples.iter_mut().enumerate() {
                    let t = sample_t(k);
                    *sm = (t, rho(t));
                }
                if samples.iter().all(|x| x.1 <= 0.0) {
                    continue;
                }
                cuts.clear();
                cuts.push(s.t0);
                for w in samples.windows(2) {
                    let (ta, ra) = w[0];
                    let (tb, rb) = w[1];
                    for &l in levels {
                        if l > 0.0 && (ra < l) != (rb < l) {
                            // ρ − l, signed so that ra's side is ≤ 0.
                            let sign = if ra < l { 1.0 } else { -1.0 };
                            let side = |t: f64| {
                                let r = rho(t);
                                ((r < l) == (ra < l), sign * (r - l) as f64)
                            };
                            cuts.push(find_crossing(ta, sign * (ra - l) as f64, tb, sign * (rb - l) as f64, side));
                        }
                    }
                }
                if cuts.len() == 1 {
                    // No crossing (the common case): the samples at 0, ½, 1 give Simpson's rule.
                    prof.pieces
                        .push(piece([samples[0].1, samples[CELL_SAMPLES / 2].1, samples[CELL_SAMPLES].1]));
                    continue;
                }
                cuts.push(s.t1);
                cuts.sort_by(f64::total_cmp);
                for w in cuts.windows(2) {
                    if w[1] > w[0] {
                        let (tau, r) = simpson(w[0], w[1]);
                        prof.pieces.push(Piece {
                            t0: w[0],
                            t1: w[1],
                            tau,
                            rho: r,
                        });
                    }
                }
            }
        });
        prof
    }

    /// Total optical depth.
    pub fn depth(&self) -> f64 {
        self.pieces.iter().map(|p| p.tau).sum()
    }

    /// Maximal runs of contiguous pieces with mid-density below `level` (the paper's segments
    /// for level = T), with D_j and c_j.
    pub fn segments(&self, m: &Medium, level: f32) -> Vec<LowSegment> {
        self.segments_where(m, |_, p| p.rho[1] < level)
    }

    /// Maximal runs of contiguous pieces for which `inside(k, piece)` holds, with D_j and c_j.
    pub fn segments_where(&self, m: &Medium, inside: impl Fn(usize, &Piece) -> bool) -> Vec<LowSegment> {
        let mut out = Vec::new();
        let mut k = 0;
        let n = self.pieces.len();
        while k < n {
            if !inside(k, &self.pieces[k]) {
                k += 1;
                continue;
            }
            let first = k;
            k += 1;
            while k < n && inside(k, &self.pieces[k]) && self.pieces[k].t0 == self.pieces[k - 1].t1 {
                k += 1;
            }
            out.push(self.segment(m, first, k));
        }
        out
    }

    /// Split the piece in which the optical depth accumulated from the ray's start reaches
    /// `target` (unitless) there, so that a piece boundary lies at exactly that depth; returns the
    /// number of pieces before it (all of them when the whole ray is shallower).
    pub fn cut_at_depth(&mut self, m: &Medium, target: f64) -> usize {
        let mut acc = 0.0;
        for k in 0..self.pieces.len() {
            let p = self.pieces[k];
            if acc + p.tau <= target {
                acc += p.tau;
                continue;
            }
            if acc >= target {
                return k;
            }
            let tc = self.t_at_depth(m, k, k + 1, target - acc);
            if tc <= p.t0 || tc >= p.t1 {
                return if tc <= p.t0 { k } else { k + 1 };
            }
            self.split_piece(m, k, tc);
            return k + 1;
        }
        self.pieces.len()
    }

    /// Split piece `k` at distance `tc` (strictly inside it) into two, with exact depths.
    pub fn split_piece(&mut self, m: &Medium, k: usize, tc: f64) {
        let p = self.pieces[k];
        let mid = |a: f64, b: f64| self.rho(m, 0.5 * (a + b));
        let rc = self.rho(m, tc);
        let left = Piece {
            t0: p.t0,
            t1: tc,
            tau: self.depth_within(m, p.t0, tc),
            rho: [p.rho[0], mid(p.t0, tc), rc],
        };
        let right = Piece {
            t0: tc,
            t1: p.t1,
            tau: self.depth_within(m, tc, p.t1),
            rho: [rc, mid(tc, p.t1), p.rho[2]],
        };
        self.pieces[k] = left;
        self.pieces.insert(k + 1, right);
    }

    /// The segment made of pieces `first..end` (contiguous), with its depth and centre.
    pub fn segment(&self, m: &Medium, first: usize, end: usize) -> LowSegment {
        let ps = &self.pieces[first..end];
        let depth: f64 = ps.iter().map(|p| p.tau).sum();
        LowSegment {
            t0: ps[0].t0,
            t1: ps[ps.len() - 1].t1,
            depth,
            t_center: self.t_at_depth(m, first, end, 0.5 * depth),
            first,
            end,
        }
    }

    /// The distance where the optical depth accumulated from the start of piece `first` reaches
    /// `target` (clamped to pieces `first..end`); exact up to bisection tolerance.
    pub fn t_at_depth(&self, m: &Medium, first: usize, end: usize, target: f64) -> f64 {
        let mut acc = 0.0;
        for p in &self.pieces[first..end] {
            if acc + p.tau >= target && p.tau > 0.0 {
                let want = target - acc;
                let sigma_t = m.optics.sigma_t as f64;
                let r0 = p.rho[0] as f64;
                let cubic = CellDensity::containing(m, self.o, self.d, 0.5 * (p.t0 + p.t1)).cubic(m, self.o, self.d, p.t0);
                let below = |t: f64| {
                    // Simpson on [t0, t] is exact: the piece lies in one dual cell.
                    let rm = cubic.at(0.5 * (p.t0 + t)) as f64;
                    let r1 = cubic.at(t) as f64;
                    let tau = sigma_t * (t - p.t0) / 6.0 * (r0 + 4.0 * rm + r1);
                    (tau < want, tau - want)
                };
                return find_crossing(p.t0, -want, p.t1, p.tau - want, below);
            }
            acc += p.tau;
        }
        self.pieces[end - 1].t1
    }

    /// Optical depth between `t_a` and `t_b` (both inside one piece), exact.
    pub fn depth_within(&self, m: &Medium, t_a: f64, t_b: f64) -> f64 {
        let r = |t| self.rho(m, t);
        depth_from_samples(m, t_a, t_b, [r(t_a), r(0.5 * (t_a + t_b)), r(t_b)])
    }

    /// ρ at distance t.
    pub fn rho(&self, m: &Medium, t: f64) -> f32 {
        rho_at(m, self.o, self.d, t)
    }
}

/// [`RayProfile::depth_within`] from ρ at `t_a`, the midpoint and `t_b` already looked up (the
/// same operations, so the same bits).
#[inline]
pub fn depth_from_samples(m: &Medium, t_a: f64, t_b: f64, r: [f32; 3]) -> f64 {
    m.optics.sigma_t as f64 * (t_b - t_a) / 6.0 * (r[0] as f64 + 4.0 * r[1] as f64 + r[2] as f64)
}

/// The paper's low-density segments along `o + t·d` (`d` unit), t ∈ [t_min, t_max]: maximal
/// stretches with 0 < ρ < `threshold`, with optical depth D_j and centre c_j.
pub fn low_density_segments(m: &Medium, o: Vec3, d: Vec3, t_min: f32, t_max: f32, threshold: f32) -> Vec<LowSegment> {
    RayProfile::trace(m, o, d, t_min, t_max, &[threshold]).segments(m, threshold)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Rgb;
    use crate::medium::Grid3;

    /// A medium whose density varies along x only: ρ(x) given at voxel centres.
    fn ramp_medium(values: &[f32], sigma_t: f32) -> Medium {
        let n = values.len();
        let mut g = Grid3::filled([n, 3, 3], 0.0);
        for k in 0..3 {
            for j in 0..3 {
                for (i, v) in values.iter().enumerate() {
                    g.set(i, j, k, *v);
                }
            }
        }
        Medium::new(g, Vec3::ZERO, Vec3::ONE, sigma_t, Rgb::ONE, 0.0)
    }

    /// A procedural cumulus on an offset grid with unequal voxel sides (the walks' general case).
    fn skewed_cumulus(dims: [usize; 3], seed: u64) -> Medium {
        let grid = crate::medium::procedural::cumulus(dims, seed);
        Medium::new(grid, Vec3::new(-1.0, 2.0, 0.5), Vec3::new(0.7, 1.1, 0.9), 1.0, Rgb::ONE, 0.8)
    }

    #[test]
    fn find_crossing_closes_on_the_exact_root_in_few_steps() {
        use std::cell::Cell;
        // f(t) = (t − r)³ + (t − r)/10 has its one root at r; brackets of either orientation.
        for (r, a, b) in [(1.3f64, 0.0, 3.0), (250.0 + 1.0 / 3.0, 249.0, 250.5), (7.0, 6.99, 9.0)] {
            for sign in [1.0, -1.0] {
                let f = |t: f64| sign * ((t - r).powi(3) + 0.1 * (t - r));
                let calls = Cell::new(0);
                let side = |t: f64| {
                    calls.set(calls.get() + 1);
                    let v = f(t);
                    ((v < 0.0) == (f(a) < 0.0), if f(a) < 0.0 { v } else { -v })
                };
                let s = if f(a) < 0.0 { 1.0 } else { -1.0 };
                let t = find_crossing(a, s * f(a), b, s * f(b), side);
                assert!((t - r).abs() <= bisection_tolerance(r), "{t} vs {r}");
                // Bisection needs ~log2(width / tolerance) ≈ 30 look-ups here.
                assert!(calls.get() <= 16, "{} look-ups", calls.get());
            }
        }
    }

    #[test]
    fn cell_cubic_matches_the_trilinear_look_up() {
        let m = skewed_cumulus([12, 10, 8], 5);
        let mut rng = crate::math::Rng::new(4, 2);
        let mut checked = 0;
        for _ in 0..200 {
            let o = Vec3::new(-4.0, 2.0 + rng.uniform() * 11.0, 0.5 + rng.uniform() * 7.2);
            let d = Vec3::new(1.0, rng.uniform() - 0.5, rng.uniform() - 0.5).normalize();
            let (od, dd) = (o.as_dvec3(), d.as_dvec3());
            let Some((t0, t1)) = m.intersect(o, d, 0.0, 100.0) else { continue };
            m.for_each_dual_block(o, d, t0, t1, |_, cells| {
                for s in cells {
                    let cubic = CellDensity::new(&m, s.cell).cubic(&m, od, dd, s.t0);
                    for k in 0..=4 {
                        let t = s.t0 + (s.t1 - s.t0) * k as f64 / 4.0;
                        let (a, b) = (cubic.at(t), rho_at(&m, od, dd, t));
                        assert!((a - b).abs() <= 1e-5 * (1.0 + b), "{a} vs {b}");
                        checked += 1;
                    }
                }
            });
        }
        assert!(checked > 1000, "{checked}");
    }

    #[test]
    fn dual_runs_cover_the_block_walks_cells_without_splitting_them() {
        let m = skewed_cumulus([24, 20, 16], 3);
        let mut rng = crate::math::Rng::new(7, 3);
        let mut merged = 0;
        for _ in 0..200 {
            let o = Vec3::new(-6.0, 2.0 + rng.uniform() * 22.0, 0.5 + rng.uniform() * 14.4);
            let d = Vec3::new(1.0, rng.uniform() - 0.5, rng.uniform() - 0.5).normalize();
            let Some((t0, t1)) = m.intersect(o, d, 0.0, 100.0) else { continue };
            let (mut blocks, mut runs) = (Vec::new(), Vec::new());
            m.for_each_dual_block(o, d, t0, t1, |_, cells| blocks.extend(cells.map(|s| (s.cell, s.t0, s.t1))));
            m.for_each_dual_run(o, d, t0, t1, |cells| runs.extend(cells.map(|s| (s.cell, s.t0, s.t1))));
            // The same stretches of ray (lengths summed) in the same cells, each cell's midpoint inside it.
            let len = |v: &[([usize; 3], f64, f64)]| v.iter().map(|c| c.2 - c.1).sum::<f64>();
            assert!((len(&blocks) - len(&runs)).abs() <= 1e-9 * (1.0 + len(&blocks)));
            let cells = |v: &[([usize; 3], f64, f64)]| {
                let mut c: Vec<[usize; 3]> = v.iter().map(|c| c.0).collect();
                c.dedup();
                c
            };
            assert_eq!(cells(&blocks), cells(&runs));
            for &(c, a, b) in &runs {
                let v = (o.as_dvec3() + d.as_dvec3() * (0.5 * (a + b)) - m.origin.as_dvec3()) / m.voxel_size.as_dvec3();
                assert!((0..3).all(|k| (v[k] + 0.5).floor() as usize == c[k]), "{c:?} at {v:?}");
            }
            // No cell twice in a row: a block face does not cut a cell in two.
            assert!(runs.windows(2).all(|w| w[0].0 != w[1].0));
            merged += blocks.len() - runs.len();
        }
        assert!(merged > 0, "no ray crossed a face between two non-empty blocks");
    }

    #[test]
    fn profiles_within_the_density_bounds_equal_the_whole_box() {
        // A small cloud in the middle of a larger grid: ρ = 0 outside the bounds, and the profile
        // walked only inside them has the same pieces' depth and segments as over the whole box.
        let mut g = Grid3::filled([20, 16, 12], 0.0);
        let mut rng = crate::math::Rng::new(5, 8);
        for k in 4..8 {
            for j in 5..10 {
                for i in 6..13 {
                    g.set(i, j, k, rng.uniform());
                }
            }
        }
        let m = Medium::new(g, Vec3::new(-2.0, 1.0, 0.0), Vec3::new(0.8, 1.2, 1.0), 1.5, Rgb::ONE, 0.8);
        let (lo, hi) = density_bounds(&m).expect("a non-empty medium");
        let (blo, bhi) = m.bbox();
        for _ in 0..2000 {
            let p = blo + (bhi - blo) * Vec3::new(rng.uniform(), rng.uniform(), rng.uniform());
            let inside = (0..3).all(|a| p[a] >= lo[a] && p[a] <= hi[a]);
            let rho = m.density.trilinear(m.to_voxel(p).to_array());
            assert!(inside || rho == 0.0, "ρ = {rho} at {p:?} outside {lo:?}..{hi:?}");
        }
        for _ in 0..300 {
            let o = Vec3::new(-8.0, rng.uniform() * 22.0, rng.uniform() * 14.0);
            let d = Vec3::new(1.0, rng.uniform() - 0.5, rng.uniform() - 0.5).normalize();
            let whole = RayProfile::trace(&m, o, d, 0.0, 100.0, &[0.3]);
            let within = RayProfile::trace_in(&m, (lo, hi), o, d, 0.0, 100.0, &[0.3]);
            assert!((whole.depth() - within.depth()).abs() <= 1e-9 * (1.0 + whole.depth()));
            assert_eq!(whole.segments(&m, 0.3).len(), within.segments(&m, 0.3).len());
        }
    }

    #[test]
    fn linear_ramp_segment_depth_and_centre_are_exact() {
        // ρ at centres x = i + 0.5: 0, 0.1, 0.2, …, 0.9 → ρ(x) = 0.1(x − 0.5) on [0.5, 9.5].
        let vals: Vec<f32> = (0..10).map(|i| 0.1 * i as f32).collect();
        let m = ramp_medium(&vals, 2.0);
        let o = Vec3::new(-1.0, 1.5, 1.5);
        let segs = low_density_segments(&m, o, Vec3::X, 0.0, 100.0, 0.45);
        assert_eq!(segs.len(), 1, "{segs:?}");
        let s = segs[0];
        // Starts where ρ leaves 0 (x = 0.5, t = 1.5), ends where ρ = 0.45 (x = 5, t = 6).
        assert!((s.t0 - 1.5).abs() < 1e-6 && (s.t1 - 6.0).abs() < 1e-5, "{s:?}");
        // D = σt ∫_{0.5}^{5} 0.1(x − 0.5) dx = 2 · 0.05 · 4.5² = 2.025.
        assert!((s.depth - 2.025).abs() < 1e-5, "{}", s.depth);
        // Half depth at 0.1 (x − 0.5)² = D/2 / 2 ⇒ x − 0.5 = 4.5/√2.
        let xc = 0.5 + 4.5 / 2f64.sqrt();
        assert!((s.t_center - (xc + 1.0)).abs() < 1e-5, "{} vs {}", s.t_center, xc + 1.0);
    }

    #[test]
    fn dense_core_splits_two_segments_and_gaps_split_too() {
        // 0 … low … dense … low … 0 … low … 0
        let vals = [0.0, 0.2, 0.2, 1.0, 1.0, 0.2, 0.2, 0.0, 0.0, 0.0, 0.3, 0.0];
        let m = ramp_medium(&vals, 1.0);
        let o = Vec3::new(-1.0, 1.5, 1.5);
        let segs = low_density_segments(&m, o, Vec3::X, 0.0, 100.0, 0.5);
        assert_eq!(segs.len(), 3, "{segs:?}");
        // Total depth of the pieces equals the exact integral.
        let prof = RayProfile::trace(&m, o, Vec3::X, 0.0, 100.0, &[0.5]);
        let exact = m.optical_depth(o, Vec3::X, 0.0, 100.0) as f64;
        assert!((prof.depth() - exact).abs() < 1e-5 * exact);
        // The third segment is a tent 0 → 0.3 → 0 over x ∈ [9.5, 11.5]: D = 0.3, centred at x = 10.5.
        let s = segs[2];
        assert!((s.depth - 0.3).abs() < 1e-6 && (s.t_center - 11.5).abs() < 1e-5, "{s:?}");
        // Threshold 0 gives no segments.
        assert!(low_density_segments(&m, o, Vec3::X, 0.0, 100.0, 0.0).is_empty());
    }

    #[test]
    fn oblique_rays_segment_depths_sum_to_low_part_of_the_integral() {
        let m = Medium::new(
            crate::medium::procedural::cumulus([24, 20, 16], 3),
            Vec3::ZERO,
            Vec3::ONE,
            1.0,
            Rgb::ONE,
            0.8,
        );
        let mut rng = crate::math::Rng::new(9, 1);
        for _ in 0..50 {
            let o = Vec3::new(-5.0, rng.uniform() * 20.0, rng.uniform() * 16.0);
            let d = Vec3::new(1.0, rng.uniform() - 0.5, rng.uniform() - 0.5).normalize();
            let prof = RayProfile::trace(&m, o, d, 0.0, 100.0, &[0.3]);
            let exact = m.optical_depth(o, d, 0.0, 100.0) as f64;
            assert!((prof.depth() - exact).abs() < 1e-4 * exact.max(1.0), "{} vs {exact}", prof.depth());
            for s in prof.segments(&m, 0.3) {
                for p in &prof.pieces[s.first..s.end] {
                    assert!(p.rho[1] < 0.3 && p.rho[0] <= 0.3 + 1e-4 && p.rho[2] <= 0.3 + 1e-4);
                }
                assert!(s.t_center > s.t0 && s.t_center < s.t1);
                let half = m.optical_depth(o, d, s.t0 as f32, s.t_center as f32) as f64;
                assert!((half - 0.5 * s.depth).abs() < 1e-4, "{half} vs {}", 0.5 * s.depth);
            }
        }
    }
}
