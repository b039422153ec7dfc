//! The 3-D solver (after SHDOM, Evans 1998): the diffuse radiance's source function stored in real
//! spherical harmonics per full voxel, swept through the grid along discrete ordinates, iterated
//! with diffusion synthetic acceleration.
//!
//! **Sweep.** For an ordinate Ω, the axis a with the largest |Ω_a|/h_a orders the voxel planes
//! upwind. A voxel's centre looks back along −Ω to the plane of the previous centres, a distance
//! s = h_a/|Ω_a|; there, the radiance, source and density are bilinear in the four upwind centres
//! (the offsets are ≤ 1 voxel because a is the major axis). Across the step the source is linear
//! in optical path and integrated exactly: I = I_b e^{−τ} + w_in S_b + w_out S (τ = σt′ s (ρ_b + ρ)/2).
//! Empty voxels carry the radiance unchanged. Outside the swept box the ordinate sees the sky,
//! or, going up, the Lambertian ground at the point straight back along −Ω ([`GroundMap`]: the
//! δ-M shadowed sun plus the sky's and the cloud's downward diffuse light of the last sweep, so
//! every ground bounce is iterated; the map reaches as far as the cloud's shadow).
//!
//! **Source.** J(Ω) = Σ_lm a′χ′_l (I_lm + E T′_sun Y_lm(Ω_sun)) Y_lm(Ω), I_lm the diffuse
//! radiance's moments; the δ-M reduced sun E T′_sun = E T^{1 − a f} is exact and apart.
//!
//! **Acceleration.** After a sweep the isotropic change ΔI0 drives the diffusion equation
//! −∇·(D∇δ) + ρσa′ δ = ρσs′ ΔI0 with D = 1/(3ρσtr′) plus the sweeps' own numerical diffusion
//! (δ-M coefficients, Marshak boundary; [`super::accel`]: consistent with the sweeps on thick
//! voxels), solved by multigrid-preconditioned CG; I_00 += √(4π) δ, and the
//! correction's P1 current (Fick's law) goes into the first moments ([`accelerate`]).

use super::accel::{DsaOperator, SweepDiffusion};
use super::sphere::Quadrature;
use super::warm::{TransportState, WARM_MIN_ITERATIONS};
use super::{BandOptics, Optics};
use crate::diffusion::multigrid::Hierarchy;
use crate::diffusion::{interior_coupling, Domain, DEFAULT_MIN_OPTICAL_DEPTH};
use crate::error::{Error, Result};
use crate::lighting::{Ground, Sky, Sun};
use crate::math::{real_sh, sh_count};
use crate::math::{Rgb, Vec3};
use crate::medium::{Density, Medium};
use crate::pipeline::Progress;
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::PI;

/// Settings of the 3-D solver.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TransportSettings {
    /// Legendre/SH truncation order L of the δ-M phase function and of the source.
    pub order: usize,
    /// Ordinates in cos θ (the azimuths are 2× this).
    pub n_mu: usize,
    /// Convergence: max over full voxels of |ΔI0| / max I0 between iterations.
    pub tolerance: f64,
    /// Iteration cap.
    pub max_iterations: usize,
    /// Diffusion synthetic acceleration on.
    pub acceleration: bool,
}

impl Default for TransportSettings {
    fn default() -> Self {
        TransportSettings {
            order: 7,
            n_mu: 8,
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
    pub optics: Optics,
    /// SH order.
    pub order: usize,
    /// Per voxel: index into the full-voxel arrays, or `u32::MAX` where ρ = 0.
    pub full: Vec<u32>,
    /// Diffuse source coefficients a′χ′_l I_lm per full voxel, band, lm (W·m⁻²·sr⁻¹); the sun's
    /// first scattering is not in it (the gather adds it exactly).
    pub diffuse_source: Vec<f32>,
    /// δ-M sun transmittance T′ per voxel centre and band (1 where no cloud is near).
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

/// Radiance of the Lambertian ground (W·m⁻²·sr⁻¹) on columns of the grid's horizontal spacing,
/// over the grid's footprint grown by `margin` columns (as far as the cloud's shadow reaches);
/// `clear`, the unshadowed ground, beyond.
#[derive(Clone, Debug)]
pub struct GroundMap {
    /// Columns added on every side of the footprint.
    pub margin: usize,
    /// Columns per axis (x, z).
    pub dims: [usize; 2],
    /// Per column, x fastest.
    pub radiance: Vec<Rgb>,
    /// Per column, the part of `radiance` from the sky's and the cloud's diffuse light
    /// (ρ_g/π E_down; the rest is the shadowed sun), for the gather to filter.
    pub diffuse: Vec<Rgb>,
    /// Beyond the map.
    pub clear: Rgb,
    /// World x, z of the grid's minimum corner (m) and the column size (m).
    pub origin: [f64; 2],
    /// Column size (m).
    pub h: [f64; 2],
}

impl GroundMap {
    /// Column index (x, z) of world (x, z), if on the map.
    #[inline]
    fn column(&self, x: f64, z: f64) -> Option<usize> {
        let gi = ((x - self.origin[0]) / self.h[0]).floor() + self.margin as f64;
        let gk = ((z - self.origin[1]) / self.h[1]).floor() + self.margin as f64;
        (gi >= 0.0 && gk >= 0.0 && (gi as usize) < self.dims[0] && (gk as usize) < self.dims[1])
            .then(|| gi as usize + self.dims[0] * gk as usize)
    }

    /// Radiance at world (x, z).
    #[inline]
    pub fn at(&self, x: f64, z: f64) -> Rgb {
        self.column(x, z).map_or(self.clear, |c| self.radiance[c])
    }
}

/// Raw pointer for disjoint parallel writes: within one plane of a sweep every voxel is written by
/// exactly one cell.
#[derive(Clone, Copy)]
struct Shared<T>(*mut T);
unsafe impl<T> Send for Shared<T> {}
unsafe impl<T> Sync for Shared<T> {}
impl<T> Shared<T> {
    /// SAFETY: the caller writes index `i` from one thread only while the pointer is shared.
    #[inline]
    unsafe fn at(self, i: usize) -> *mut T {
        self.0.add(i)
    }
}

/// (e^{−x}, w_in, w_out) of a step of optical length x with a source linear in optical path
/// (as the slab solver's, whose f64 form the test checks it against), in f32 with a series below x = 0.2 (the closed form cancels there).
#[inline]
fn step_weights(x: f32) -> (f32, f32, f32) {
    if x < 0.2 {
        let (x2, x3, x4, x5) = (x * x, x * x * x, x * x * x * x, x * x * x * x * x);
        return (
            1.0 - x + 0.5 * x2 - x3 / 6.0 + x4 / 24.0 - x5 / 120.0,
            0.5 * x - x2 / 3.0 + x3 / 8.0 - x4 / 30.0 + x5 / 144.0,
            0.5 * x - x2 / 6.0 + x3 / 24.0 - x4 / 120.0 + x5 / 720.0,
        );
    }
    let e = (-x).exp();
    let w_out = 1.0 - (1.0 - e) / x;
    (e, 1.0 - e - w_out, w_out)
}

/// Everything the sweeps read.
struct Ctx<'a> {
    dims: [usize; 3],
    /// The swept box: minimum corner and cells per axis (the full voxels plus one voxel).
    lo: [usize; 3],
    n: [usize; 3],
    h: [f64; 3],
    rho: &'a Density,
    full: &'a [u32],
    nsh: usize,
    /// Even-l harmonics (the first of the inner order, [`parity_order`]).
    even: usize,
    /// Grid index of every full voxel, in grid order.
    voxels: &'a [usize],
    /// δ-M sun transmittance T′ per grid voxel and band.
    sun_t: &'a [[f32; 3]],
    /// The box's cells in each major axis' sweep order ([`box_cells`]).
    cells: [Vec<(f32, u32)>; 3],
    sigma_t: [f32; 3],
    /// All bands share σt′ (one set of step weights serves them).
    grey: bool,
    sky: &'a Sky,
    /// Grid origin (m) and the ground's height (m), if any.
    origin: DVec3,
    ground_height: Option<f64>,
}

impl Ctx<'_> {
    /// Radiance entering the swept box along `om` at the outside grid position (i, j, k): clear
    /// air outside the box carries it unchanged from the sky or, going up, from the ground point
    /// straight back along −om.
    #[inline]
    fn boundary(&self, om: DVec3, i: isize, j: isize, k: isize, ground: &GroundMap, sky: Rgb) -> [f32; 3] {
        let c = match self.ground_height {
            Some(gh) if om.y > 0.0 => {
                let p = self.origin
                    + DVec3::new(
                        (i as f64 + 0.5) * self.h[0],
                        (j as f64 + 0.5) * self.h[1],
                        (k as f64 + 0.5) * self.h[2],
                    );
                let q = p - om * ((p.y - gh).max(0.0) / om.y);
                ground.at(q.x, q.z)
            }
            _ => sky,
        };
        [c.x, c.y, c.z]
    }
}

/// One ordinate's ground splats (map column, change of the downward irradiance in W/m² per band).
type Splats = Vec<(usize, [f64; 3])>;

/// Ordinates swept side by side: their per-voxel sources and radiances are held at once
/// (2 × 12 B per full voxel each). Fixed, so the sums are the same for any thread count.
pub(crate) const ORDINATE_BATCH: usize = 16;

/// The order of the harmonics inside the solver: every even-l one first, then the odd-l ones
/// (each l's block in `real_sh`'s order). Y_lm(−Ω) = (−1)^l Y_lm(Ω), so one pass over a voxel's
/// coefficients gives the even and odd sums E, O and with them the source in both ordinates of an
/// opposite pair (E ± O); likewise one pass accumulates both ordinates' moments. `perm[i]` is
/// the `real_sh` index of inner index i; the second value, the count of even ones.
fn parity_order(order: usize) -> (Vec<usize>, usize) {
    let block = |l: usize| l * l..(l + 1) * (l + 1);
    let even: Vec<usize> = (0..=order).step_by(2).flat_map(block).collect();
    let ne = even.len();
    (even.into_iter().chain((1..=order).step_by(2).flat_map(block)).collect(), ne)
}

/// The ordinates in opposite pairs (d, d′) with Ω_d′ = −Ω_d (the product quadrature is symmetric).
fn opposite_pairs(q: &Quadrature) -> Vec<[usize; 2]> {
    let pairs: Vec<[usize; 2]> = (0..q.dirs.len())
        .filter_map(|d| {
            let o = (0..q.dirs.len()).min_by(|a, b| (q.dirs[*a] + q.dirs[d]).length().total_cmp(&(q.dirs[*b] + q.dirs[d]).length()))?;
            (d < o).then_some([d, o])
        })
        .collect();
    assert!(
        2 * pairs.len() == q.dirs.len() && pairs.iter().all(|[d, o]| (q.dirs[*d] + q.dirs[*o]).length() < 1e-9),
        "the quadrature is symmetric"
    );
    pairs
}

/// Opposite pairs per batch: the lanes of the source evaluation.
const PAIRS: usize = ORDINATE_BATCH / 2;

/// Per ordinate pair, what the sweeps' per-voxel steps read (inner harmonic order, f32).
struct PairTables {
    /// The ordinates (d, d′ = opposite).
    pairs: Vec<[usize; 2]>,
    /// Weights (sr) of d and d′.
    weights: Vec<[f32; 2]>,
    /// Y_lm(Ω_d) for the moments, per batch in blocks of eight harmonics with the batch's pairs
    /// side by side ([`accumulate`]): the even ones' blocks, then the odd ones' (zero past each
    /// part's end).
    y_acc: Vec<[[f32; 8]; PAIRS]>,
    /// a′χ′_l Y_lm(Ω_d) per batch of pairs, band and lm, the batch's pairs in lanes (0 past the
    /// last pair): the source in Ω_d is Σ I_lm times this.
    y_src: Vec<[f32; PAIRS]>,
    /// The reduced sun's first scattering per unit T′ in Ω_d and in −Ω_d per batch and band, in
    /// lanes: Σ_lm a′χ′_l E Y_lm(Ω_sun) Y_lm(±Ω_d) (W·m⁻²·sr⁻¹).
    sun: Vec<[[f32; PAIRS]; 2]>,
}

impl PairTables {
    fn new(q: &Quadrature, order: usize, perm: &[usize], bands: &[BandOptics], e_sun: [f64; 3], y_sun: &[f64]) -> PairTables {
        let nsh = perm.len();
        let pairs = opposite_pairs(q);
        let l_of = |k: usize| (k as f64).sqrt().floor() as usize;
        let batches = pairs.len().div_ceil(PAIRS);
        let ne = perm.iter().filter(|k| l_of(**k) % 2 == 0).count();
        let (nbe, nblk) = (ne.div_ceil(8), ne.div_ceil(8) + (nsh - ne).div_ceil(8));
        let mut y_acc = vec![[[0f32; 8]; PAIRS]; batches * nblk];
        let mut y_src = vec![[0f32; PAIRS]; batches * 3 * nsh];
        let mut sun = vec![[[0f32; PAIRS]; 2]; batches * 3];
        let mut yd = vec![0.0; nsh];
        for (p, [d, _]) in pairs.iter().enumerate() {
            real_sh(order, q.dirs[*d], &mut yd);
            let (bi, lane) = (p / PAIRS, p % PAIRS);
            for (i, k) in perm.iter().enumerate() {
                let (kb, l) = if i < ne {
                    (i / 8, i % 8)
                } else {
                    (nbe + (i - ne) / 8, (i - ne) % 8)
                };
                y_acc[bi * nblk + kb][lane][l] = yd[*k] as f32;
            }
            for (b, bo) in bands.iter().enumerate() {
                for (i, k) in perm.iter().enumerate() {
                    y_src[(bi * 3 + b) * nsh + i][lane] = (bo.albedo * bo.chi[l_of(*k)] * yd[*k]) as f32;
                }
                let term = |k: usize| bo.albedo * bo.chi[l_of(k)] * e_sun[b] * y_sun[k] * yd[k];
                let (e, o) = (0..nsh).fold(
                    (0.0, 0.0),
                    |(e, o), k| if l_of(k) % 2 == 0 { (e + term(k), o) } else { (e, o + term(k)) },
                );
                sun[bi * 3 + b][0][lane] = (e + o) as f32;
                sun[bi * 3 + b][1][lane] = (e - o) as f32;
            }
        }
        let weights = pairs.iter().map(|[d, o]| [q.weights[*d] as f32, q.weights[*o] as f32]).collect();
        PairTables {
            pairs,
            weights,
            y_acc,
            y_src,
            sun,
        }
    }
}

/// Σ_k m[k] y[k] for every lane (a batch's pairs), two k at a time in independent sums.
#[inline(always)]
fn lanes_dot(m: &[f32], y: &[[f32; PAIRS]]) -> [f32; PAIRS] {
    let (mut a0, mut a1) = ([0f32; PAIRS], [0f32; PAIRS]);
    for (mk, yk) in m.chunks_exact(2).zip(y.chunks_exact(2)) {
        for p in 0..PAIRS {
            a0[p] += mk[0] * yk[0][p];
            a1[p] += mk[1] * yk[1][p];
        }
    }
    if m.len() % 2 == 1 {
        let (mk, yk) = (m[m.len() - 1], y[m.len() - 1]);
        for p in 0..PAIRS {
            a0[p] += mk * yk[p];
        }
    }
    std::array::from_fn(|p| a0[p] + a1[p])
}

/// acc[k] += Σ_p s[p] y_p[k] (the pairs in order, in a sum from 0 per k, then added), eight k
/// at a time: `blocks[kb][p]` holds y_p[8kb..8kb + 8]; the same order for any thread count.
/// Lanes past a short batch's last pair hold s = y = 0 and add +0 (a sum from +0 never is −0).
#[inline(always)]
fn accumulate(acc: &mut [f32], s: &[f32; PAIRS], blocks: &[[[f32; 8]; PAIRS]]) {
    for (a, blk) in acc.chunks_mut(8).zip(blocks) {
        let mut r = [0f32; 8];
        for (sp, y) in s.iter().zip(blk) {
            for (rl, yl) in r.iter_mut().zip(y) {
                *rl += sp * yl;
            }
        }
        for (al, rl) in a.iter_mut().zip(r) {
            *al += rl;
        }
    }
}

/// Define `$name`, which runs `$body` compiled for AVX where the processor has it, else as
/// built. The kernels' lanes and sums are explicit and Rust never fuses a multiply with an add,
/// so both give the same bits; AVX does eight lanes per instruction instead of four.
/// With `@ name, avx_name, plain, fast`, the AVX copy runs `fast` (a body with explicit AVX
/// arithmetic that must give `plain`'s bits).
macro_rules! with_avx {
    (@ $name:ident, $avx:ident, $plain:expr, $fast:expr, ($($a:ident: $t:ty),*) $(-> $r:ty)?) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx")]
        unsafe fn $avx($($a: $t),*) $(-> $r)? {
            $fast($($a),*)
        }
        fn $name($($a: $t),*) $(-> $r)? {
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx") {
                // SAFETY: the processor has AVX.
                return unsafe { $avx($($a),*) };
            }
            $plain($($a),*)
        }
    };
    ($name:ident, $avx:ident, $body:ident, $($sig:tt)*) => {
        with_avx!(@ $name, $avx, $body, $body, $($sig)*);
    };
}

/// Step (1) of [`sweep`] for the full voxels from `f0` whose moments are `block`: the source in
/// both ordinates of each of the batch's `pairs` pairs (batch `bi`), into slots 2p and 2p + 1.
#[inline(always)]
fn source_kernel(c: &Ctx, t: &PairTables, bi: usize, pairs: usize, block: &[f32], f0: usize, sp: Shared<[f32; 3]>) {
    let (nsh, ne) = (c.nsh, c.even);
    let nfull = c.voxels.len();
    for (k, mom) in block.chunks_exact(3 * nsh).enumerate() {
        let f = f0 + k;
        let tf = c.sun_t[c.voxels[f]];
        let (mut plus, mut minus) = ([[0f32; 3]; PAIRS], [[0f32; 3]; PAIRS]);
        for b in 0..3 {
            let (m, y) = (&mom[b * nsh..(b + 1) * nsh], &t.y_src[(bi * 3 + b) * nsh..(bi * 3 + b + 1) * nsh]);
            let (e, o) = (lanes_dot(&m[..ne], &y[..ne]), lanes_dot(&m[ne..], &y[ne..]));
            let [sp_, sm_] = t.sun[bi * 3 + b];
            for p in 0..PAIRS {
                plus[p][b] = (e[p] + o[p] + tf[b] * sp_[p]).max(0.0);
                minus[p][b] = (e[p] - o[p] + tf[b] * sm_[p]).max(0.0);
            }
        }
        for slot in 0..pairs {
            // SAFETY: entries (slot, f) are written by the task owning voxel f only.
            unsafe {
                *sp.at(2 * slot * nfull + f) = plus[slot];
                *sp.at((2 * slot + 1) * nfull + f) = minus[slot];
            }
        }
    }
}
with_avx!(source_block, source_block_avx, source_kernel, (c: &Ctx, t: &PairTables, bi: usize, pairs: usize, block: &[f32], f0: usize, sp: Shared<[f32; 3]>));

/// What step (3) of [`sweep`] reads: the batch's radiances per ordinate slot and full voxel, the
/// slots' weights (sr) and the pairs' Y_lm (the batch's blocks of [`PairTables::y_acc`]).
struct Lanes<'a> {
    nfull: usize,
    wts: &'a [f32],
    radiance: &'a [[f32; 3]],
    y: &'a [[[f32; 8]; PAIRS]],
}

/// Step (3) of [`sweep`] for the full voxels from `f0` whose new moments are `block`: I_lm +=
/// w I(Ω) Y_lm(Ω) + w′ I(−Ω) (−1)^l Y_lm(Ω) over the batch's pairs.
#[inline(always)]
fn moments_kernel(c: &Ctx, l: &Lanes, block: &mut [f32], f0: usize) {
    let (nsh, ne, nfull) = (c.nsh, c.even, l.nfull);
    let pairs = l.wts.len() / 2;
    let (mut se, mut so) = ([0f32; PAIRS], [0f32; PAIRS]);
    for (k, acc) in block.chunks_exact_mut(3 * nsh).enumerate() {
        let f = f0 + k;
        for band in 0..3 {
            for (slot, (e, o)) in se[..pairs].iter_mut().zip(&mut so[..pairs]).enumerate() {
                let (ip, im) = (
                    l.wts[2 * slot] * l.radiance[2 * slot * nfull + f][band],
                    l.wts[2 * slot + 1] * l.radiance[(2 * slot + 1) * nfull + f][band],
                );
                (*e, *o) = (ip + im, ip - im);
            }
            let a = &mut acc[band * nsh..(band + 1) * nsh];
            let nbe = ne.div_ceil(8);
            accumulate(&mut a[..ne], &se, &l.y[..nbe]);
            accumulate(&mut a[ne..], &so, &l.y[nbe..]);
        }
    }
}
with_avx!(moments_block, moments_block_avx, moments_kernel, (c: &Ctx, l: &Lanes, block: &mut [f32], f0: usize));

/// One sweep of every ordinate: the diffuse radiance moments I_lm per full voxel (inner harmonic
/// order), and how much the cloud changes the ground's downward irradiance, per ground map column.
///
/// `moments` are the last iterate's; the source J(Ω) = Σ a′χ′_l (I_lm + E T′ Y_lm(Ω_sun)) Y_lm(Ω)
/// is evaluated from them directly (no array of source coefficients is stored). Ordinates go in
/// batches of opposite pairs: (1) per full voxel, the source in both ordinates of each pair of the
/// batch from one pass over its coefficients; (2) the batch's sweeps, one ordinate per task;
/// (3) per full voxel, the moments of both ordinates of each pair in one pass, the pairs in
/// their fixed order.
fn sweep(c: &Ctx, q: &Quadrature, t: &PairTables, moments: &[f32], next: &mut [f32], ground: &GroundMap) -> Vec<[f64; 3]> {
    let nsh = c.nsh;
    let nfull = moments.len() / (3 * nsh);
    // `next` is the last iteration's array, kept (reused, no new pages); the batch's sources
    // and radiances are freed before the acceleration's solve.
    next.fill(0.0);
    let mut src = vec![[0f32; 3]; ORDINATE_BATCH * nfull];
    let mut radiance = vec![[0f32; 3]; ORDINATE_BATCH * nfull];
    // Change of the ground's downward irradiance by the cloud, per ground map column (W/m²).
    let mut e_down = vec![[0f64; 3]; ground.radiance.len()];
    // Full voxels per task in the per-voxel steps (1) and (3).
    let chunk = 256;
    for (bi, first) in (0..t.pairs.len()).step_by(PAIRS).enumerate() {
        let batch = first..(first + PAIRS).min(t.pairs.len());
        // (1) Source in each ordinate, clamped at 0 (the truncated expansion may dip); slot 2p
        // holds pair p's ordinate d, 2p + 1 its opposite.
        let sp = Shared(src.as_mut_ptr());
        moments
            .par_chunks(chunk * 3 * nsh)
            .enumerate()
            .for_each(|(ci, block)| source_block(c, t, bi, batch.len(), block, ci * chunk, sp));
        // (2) The sweeps.
        let dirs: Vec<usize> = batch.clone().flat_map(|p| t.pairs[p]).collect();
        let wts: Vec<f32> = batch.clone().flat_map(|p| t.weights[p]).collect();
        let splats: Vec<Splats> = dirs
            .par_iter()
            .zip(src.par_chunks(nfull.max(1)))
            .zip(radiance.par_chunks_mut(nfull.max(1)))
            .map(|((d, sd), rd)| sweep_ordinate(c, q.dirs[*d], q.weights[*d], sd, ground, rd))
            .collect();
        let radiance = &radiance;
        for splats in &splats {
            for (col, e) in splats {
                for band in 0..3 {
                    e_down[*col][band] += e[band];
                }
            }
        }
        // (3) Moments: I_lm += w I(Ω) Y_lm(Ω) + w′ I(−Ω) (−1)^l Y_lm(Ω).
        let nblk = t.y_acc.len() / t.pairs.len().div_ceil(PAIRS);
        let yb = &t.y_acc[bi * nblk..(bi + 1) * nblk];
        let lanes = Lanes {
            nfull,
            wts: &wts,
            radiance,
            y: yb,
        };
        next.par_chunks_mut(chunk * 3 * nsh)
            .enumerate()
            .for_each(|(ci, block)| moments_block(c, &lanes, block, ci * chunk));
    }
    e_down
}

/// The two axes across major axis `a`, the faster-varying first.
fn cross_axes(a: usize) -> (usize, usize) {
    match a {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    }
}

/// The swept box's cells (density, full-voxel index or `u32::MAX`) in the order a sweep along
/// major axis `a` visits them: planes of a, rows of the second cross axis, cells of the first;
/// so the sweeps read them contiguously whichever axis they run along. [`PREFETCH_AHEAD`] empty
/// cells follow the last, so that the sweep's look-ahead never runs off the end. Every index is
/// checked below `voxels` (the number of full voxels) here, once per solve: the sweeps index the
/// sources and radiances by it unchecked.
fn box_cells(dims: [usize; 3], lo: [usize; 3], n: [usize; 3], rho: &Density, full: &[u32], voxels: usize, a: usize) -> Vec<(f32, u32)> {
    let (b, cc) = cross_axes(a);
    let mut out = Vec::with_capacity(n[0] * n[1] * n[2] + PREFETCH_AHEAD);
    for pa in 0..n[a] {
        for ic in 0..n[cc] {
            for ib in 0..n[b] {
                let mut v = lo;
                v[a] += pa;
                v[b] += ib;
                v[cc] += ic;
                let vi = v[0] + dims[0] * (v[1] + dims[1] * v[2]);
                assert!(
                    full[vi] == u32::MAX || (full[vi] as usize) < voxels,
                    "full-voxel index out of range"
                );
                out.push((rho.at(vi), full[vi]));
            }
        }
    }
    out.extend([(0.0, u32::MAX); PREFETCH_AHEAD]);
    out
}

/// A cell of a sweep's plane buffer: radiance per band, density, density × source per band
/// (lanes [`I`], [`RHO`], [`RS`]) and a spare lane, so that the upwind interpolation is eight-lane
/// arithmetic on one 32-byte record per neighbour.
#[derive(Clone, Copy, Default)]
#[repr(C, align(32))]
struct PlaneCell([f32; 8]);

/// Lanes of a [`PlaneCell`].
const I: usize = 0;
const RHO: usize = 3;
const RS: usize = 4;

impl PlaneCell {
    fn new(i: [f32; 3], rho: f32, rs: [f32; 3]) -> PlaneCell {
        PlaneCell([i[0], i[1], i[2], rho, rs[0], rs[1], rs[2], 0.0])
    }
}

/// Σ_k w_k n_k per lane of four plane records, from 0 in the neighbours' order.
#[inline(always)]
fn bilinear(w: &[f32; 4], n: [&[f32; 8]; 4]) -> [f32; 8] {
    std::array::from_fn(|k| 0.0 + w[0] * n[0][k] + w[1] * n[1][k] + w[2] * n[2][k] + w[3] * n[3][k])
}

/// [`bilinear`] in eight-lane AVX arithmetic (the compiler keeps it in four-lane halves): the
/// same multiplies and adds in the same order, so the same bits.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[inline]
unsafe fn bilinear_avx(w: &[f32; 4], n: [&[f32; 8]; 4]) -> [f32; 8] {
    use std::arch::x86_64::*;
    let mut acc = _mm256_setzero_ps();
    for (wk, nk) in w.iter().zip(n) {
        acc = _mm256_add_ps(acc, _mm256_mul_ps(_mm256_set1_ps(*wk), _mm256_loadu_ps(nk.as_ptr())));
    }
    let mut out = [0f32; 8];
    _mm256_storeu_ps(out.as_mut_ptr(), acc);
    out
}

/// Upwind density below which a cell's back source is its own instead of the density-weighted
/// mean of its upwind neighbours. The mean ρ·J/ρ loses its bits where ρ·J is subnormal (f32 has
/// 24 bits down to 1.2e-38; the Disney cloud holds densities of 1.7e-37, and the bilinear
/// weights make them smaller still) and 1/ρ overflows to inf below 2.9e-39, so it would be
/// NaN or inf; a density of 1e-30 puts an optical depth below 1e-30·σt·h into the step, which no
/// image can show.
const RHO_WEIGHT_MIN: f32 = 1e-30;

/// One cell's step along a sweep (module docs) from its upwind record `acc` ([`bilinear`]),
/// its density, its source `sc` (0 where empty; `full`: ρ > 0) and the step length `s` (m): its
/// radiance and its record for the next plane.
#[inline(always)]
fn cell(c: &Ctx, acc: [f32; 8], rho: f32, sc: [f32; 3], full: bool, s: f32) -> ([f32; 3], PlaneCell) {
    let ib_ = [acc[I], acc[I + 1], acc[I + 2]];
    let (rb, sbw) = (acc[RHO], [acc[RS], acc[RS + 1], acc[RS + 2]]);
    let mut out = ib_;
    let rm = 0.5 * (rb + rho) * s;
    if rm > 0.0 {
        let sb = if rb > RHO_WEIGHT_MIN { sbw.map(|x| x * (1.0 / rb)) } else { sc };
        let se = if full { sc } else { sb };
        let mut wgt = step_weights(c.sigma_t[0] * rm);
        for band in 0..3 {
            if band > 0 && !c.grey {
                wgt = step_weights(c.sigma_t[band] * rm);
            }
            let (e, wi, wo) = wgt;
            out[band] = ib_[band] * e + wi * sb[band] + wo * se[band];
        }
    }
    (out, PlaneCell::new(out, rho, sc.map(|x| rho * x)))
}

/// [`bilinear`] and [`cell`] for grey optics (one σt′) in AVX registers: the three bands in the
/// lanes of one four-lane operation, the same multiplies and adds in the same order, so the
/// same bits.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[inline]
unsafe fn cell_grey_avx(
    w: &[f32; 4],
    n: [&[f32; 8]; 4],
    rho: f32,
    sc: [f32; 3],
    full: bool,
    s: f32,
    sigma_t: f32,
) -> ([f32; 3], PlaneCell) {
    use std::arch::x86_64::*;
    let mut acc = _mm256_setzero_ps();
    for (wk, nk) in w.iter().zip(n) {
        acc = _mm256_add_ps(acc, _mm256_mul_ps(_mm256_set1_ps(*wk), _mm256_loadu_ps(nk.as_ptr())));
    }
    // Lanes I, I + 1, I + 2, RHO and RS, RS + 1, RS + 2, spare.
    let (lo, hi) = (_mm256_castps256_ps128(acc), _mm256_extractf128_ps::<1>(acc));
    let sc4 = _mm_setr_ps(sc[0], sc[1], sc[2], 0.0);
    let rb = _mm_cvtss_f32(_mm_shuffle_ps::<0xff>(lo, lo));
    let rm = 0.5 * (rb + rho) * s;
    let out = if rm > 0.0 {
        let sb = if rb > RHO_WEIGHT_MIN {
            _mm_mul_ps(hi, _mm_set1_ps(1.0 / rb))
        } else {
            sc4
        };
        let se = if full { sc4 } else { sb };
        let (e, wi, wo) = step_weights(sigma_t * rm);
        let ie = _mm_mul_ps(lo, _mm_set1_ps(e));
        _mm_add_ps(_mm_add_ps(ie, _mm_mul_ps(_mm_set1_ps(wi), sb)), _mm_mul_ps(_mm_set1_ps(wo), se))
    } else {
        lo
    };
    // The record: the radiance, ρ, ρ × source, and ρ × 0 = +0 in the spare lane.
    let rec_lo = _mm_blend_ps::<0b1000>(out, _mm_set1_ps(rho));
    let rec_hi = _mm_mul_ps(_mm_set1_ps(rho), sc4);
    let mut rec = PlaneCell::default();
    _mm256_storeu_ps(rec.0.as_mut_ptr(), _mm256_set_m128(rec_hi, rec_lo));
    let mut o = [0f32; 4];
    _mm_storeu_ps(o.as_mut_ptr(), out);
    ([o[0], o[1], o[2]], rec)
}

/// Cells ahead of the current one in a sweep's plane whose source and radiance are prefetched.
const PREFETCH_AHEAD: usize = 16;

/// Bring the cache line at `p` towards L1 ahead of use (a hint: no effect on results).
#[inline(always)]
fn prefetch<T>(p: *const T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: x86_64 always has SSE, and a prefetch never faults (any address may be named).
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p as *const i8)
    };
}

/// Sweep one ordinate `om` (weight `w`, sr) through the box upwind plane by plane: the radiance at
/// every full voxel's centre, and the ground splats (column, change of downward irradiance, W/m²)
/// of the light leaving the box downwards. `src` is the source in this ordinate per full voxel;
/// `radiance` receives the radiance at every full voxel (all lie in the box).
#[inline(always)]
fn sweep_kernel<const AVX: bool>(c: &Ctx, om: DVec3, w: f64, src: &[[f32; 3]], ground: &GroundMap, radiance: &mut [[f32; 3]]) -> Splats {
    let mut splats = Vec::new();
    let skyr = c.sky.radiance(Vec3::new(-om.x as f32, -om.y as f32, -om.z as f32));
    let splat = om.y < 0.0 && c.ground_height.is_some();
    // Major axis and the two others.
    let r = [om.x.abs() / c.h[0], om.y.abs() / c.h[1], om.z.abs() / c.h[2]];
    let a = (0..3).max_by(|p, q| r[*p].total_cmp(&r[*q])).unwrap_or(0);
    let (b, cc) = cross_axes(a);
    let (na, nb, nc) = (c.n[a], c.n[b], c.n[cc]);
    let cells = &c.cells[a];
    let oa = om[a];
    let s = (c.h[a] / oa.abs()) as f32;
    // Back point offsets in the previous plane (voxels), split into floor and fraction.
    // |offset| ≤ 1 as a is the major axis; clamp rounding and keep the floor in {−1, 0}, so
    // ties (|Ω_b|/h_b = |Ω_a|/h_a) stay inside the 2×2 upwind neighbourhood.
    let ob = (-(s as f64) * om[b] / c.h[b]).clamp(-1.0, 1.0);
    let oc = (-(s as f64) * om[cc] / c.h[cc]).clamp(-1.0, 1.0);
    let (fb, fc) = (ob.floor().min(0.0), oc.floor().min(0.0));
    let (tb, tc) = ((ob - fb) as f32, (oc - fc) as f32);
    let (fb, fc) = (fb as isize, fc as isize);
    let wts = [(1.0 - tb) * (1.0 - tc), tb * (1.0 - tc), (1.0 - tb) * tc, tb * tc];
    let stride = nb + 2;
    // Plane buffers with a one-cell ghost ring.
    let mut prev = vec![PlaneCell::default(); stride * (nc + 2)];
    let mut cur = prev.clone();
    // Grid coordinates of box cell (pa, pb, pc) in the (a, b, c) frame.
    let coord = |pa: isize, pb: isize, pc: isize| {
        let mut v = [0isize; 3];
        v[a] = pa + c.lo[a] as isize;
        v[b] = pb + c.lo[b] as isize;
        v[cc] = pc + c.lo[cc] as isize;
        v
    };
    // The ghost cells of plane pa (all of it when `whole`; otherwise the ring's row and column on
    // the upwind side, the only ones the cells read: the upwind floor is −1 or 0 per cross
    // axis): what enters the box there.
    let (ring_b, ring_c) = (if fb < 0 { -1 } else { nb as isize }, if fc < 0 { -1 } else { nc as isize });
    let fill_ghosts = |pa: isize, whole: bool, buf: &mut [PlaneCell]| {
        for ic in -1..=nc as isize {
            let ibs = if whole || ic == ring_c { -1..=nb as isize } else { ring_b..=ring_b };
            for ib in ibs {
                let v = coord(pa, ib, ic);
                buf[(ib + 1) as usize + stride * (ic + 1) as usize] =
                    PlaneCell::new(c.boundary(om, v[0], v[1], v[2], ground, skyr), 0.0, [0.0; 3]);
            }
        }
    };
    let first = if oa > 0.0 { -1 } else { na as isize };
    let sky_only = !(c.ground_height.is_some() && om.y > 0.0);
    if sky_only {
        // Without a ground seen upwards every ghost cell holds the sky ([`Ctx::boundary`]): fill
        // both buffers once (the cells write only the interior).
        let ghost = PlaneCell::new([skyr.x, skyr.y, skyr.z], 0.0, [0.0; 3]);
        prev.fill(ghost);
        cur.fill(ghost);
    } else {
        fill_ghosts(first, true, &mut prev);
    }
    // Offset of the upwind (0, 0) neighbour from a cell in the plane buffer.
    let up = fb + fc * stride as isize;
    // The unchecked indexing below relies on these: a cell's four upwind records lie in the
    // plane buffer (its size and the upwind floors asserted here), and the box's full voxels
    // index `src` and `radiance` ([`box_cells`] checked each below `voxels.len()`).
    assert!(src.len() == c.voxels.len() && radiance.len() == c.voxels.len() && cells.len() == na * nb * nc + PREFETCH_AHEAD);
    assert!(prev.len() == stride * (nc + 2) && cur.len() == prev.len() && (-1..=0).contains(&fb) && (-1..=0).contains(&fc));
    for step in 0..na {
        let pa = if oa > 0.0 { step } else { na - 1 - step };
        let plane = &cells[pa * nb * nc..(pa + 1) * nb * nc];
        // The cells PREFETCH_AHEAD further on (past the plane's end: the next plane's, or the
        // padding).
        let ahead = &cells[pa * nb * nc + PREFETCH_AHEAD..][..nb * nc];
        for (ic, (row, row_ahead)) in plane.chunks_exact(nb).zip(ahead.chunks_exact(nb)).enumerate() {
            let l0 = stride * (ic + 1) + 1;
            for (ib, (&(rho, fi), &(_, fa))) in row.iter().zip(row_ahead).enumerate() {
                // The full voxels' sources and radiances lie a grid row apart in x-major sweeps
                // (past the L2 cache on large boxes): ask for the lines a few cells ahead.
                if fa != u32::MAX {
                    prefetch(src.as_ptr().wrapping_add(fa as usize));
                    prefetch(radiance.as_ptr().wrapping_add(fa as usize));
                }
                let l = l0 + ib;
                // l = stride (ic + 1) + ib + 1 with ib < nb, ic < nc and up = fb + fc stride with
                // fb, fc in {−1, 0}: u ≥ stride ic + ib ≥ 0 and u + stride + 1 < stride (nc + 2).
                let u = (l as isize + up) as usize;
                // SAFETY: the bounds above (asserted before the planes).
                let (n0, n1, n2, n3) = unsafe {
                    (
                        &prev.get_unchecked(u).0,
                        &prev.get_unchecked(u + 1).0,
                        &prev.get_unchecked(u + stride).0,
                        &prev.get_unchecked(u + stride + 1).0,
                    )
                };
                // Radiance and density bilinear; the source (per unit extinction, defined only
                // where ρ > 0) density-weighted, so that empty neighbours do not pull it
                // towards 0 (a uniform source stays uniform: the furnace holds). One expression
                // per lane (from 0, the neighbours in order) so it compiles to whole-record
                // arithmetic without copies of the records.
                let (n, full) = ([n0, n1, n2, n3], fi != u32::MAX);
                // SAFETY: a full cell's index is below voxels.len() = src.len() (asserted in box_cells and above).
                let sc = if full {
                    unsafe { *src.get_unchecked(fi as usize) }
                } else {
                    [0f32; 3]
                };
                #[cfg(not(target_arch = "x86_64"))]
                let (out, rec) = cell(c, bilinear(&wts, n), rho, sc, full, s);
                // SAFETY (both): `AVX` is true only in the copy compiled for (and run on) AVX.
                #[cfg(target_arch = "x86_64")]
                let (out, rec) = if AVX && c.grey {
                    unsafe { cell_grey_avx(&wts, n, rho, sc, full, s, c.sigma_t[0]) }
                } else if AVX {
                    cell(c, unsafe { bilinear_avx(&wts, n) }, rho, sc, full, s)
                } else {
                    cell(c, bilinear(&wts, n), rho, sc, full, s)
                };
                // SAFETY: l ≤ u + stride + 1 and radiance.len() == src.len() (asserted above).
                unsafe {
                    *cur.get_unchecked_mut(l) = rec;
                    if full {
                        *radiance.get_unchecked_mut(fi as usize) = out;
                    }
                }
            }
        }
        let pa = pa as isize;
        if splat {
            // Light leaving the box downwards lands on the ground along Ω: splat its flux
            // change against the sky it hides, (I − L_sky) w |Ω·n| A_face, per column area.
            let exit_b = if om[b] > 0.0 { nb - 1 } else { 0 };
            let exit_c = if om[cc] > 0.0 { nc - 1 } else { 0 };
            let mut faces: Vec<(usize, usize, usize)> = (0..nc).map(|ic| (exit_b, ic, b)).collect();
            faces.extend((0..nb).map(|ib| (ib, exit_c, cc)));
            if step + 1 == na {
                faces.extend((0..nc).flat_map(|ic| (0..nb).map(move |ib| (ib, ic, a))));
            }
            for (ib, ic, ax) in faces {
                let v = coord(pa, ib as isize, ic as isize);
                let mut face = c.origin
                    + DVec3::new(
                        (v[0] as f64 + 0.5) * c.h[0],
                        (v[1] as f64 + 0.5) * c.h[1],
                        (v[2] as f64 + 0.5) * c.h[2],
                    );
                face[ax] += 0.5 * c.h[ax] * om[ax].signum();
                let gh = c.ground_height.unwrap_or(0.0);
                let q = face + om * ((gh - face.y).min(0.0) / om.y);
                if let Some(col) = ground.column(q.x, q.z) {
                    let area = c.h[0] * c.h[1] * c.h[2] / c.h[ax];
                    let f = w as f32 as f64 * om[ax].abs() * area / (c.h[0] * c.h[2]);
                    let i = &cur[ib + 1 + stride * (ic + 1)].0[I..I + 3];
                    splats.push((col, [0, 1, 2].map(|band| f * (i[band] as f64 - skyr[band] as f64))));
                }
            }
        }
        std::mem::swap(&mut prev, &mut cur);
        if !sky_only {
            fill_ghosts(pa, false, &mut prev);
        }
    }
    splats
}
with_avx!(@ sweep_ordinate, sweep_ordinate_avx, sweep_kernel::<false>, sweep_kernel::<true>, (c: &Ctx, om: DVec3, w: f64, src: &[[f32; 3]], ground: &GroundMap, radiance: &mut [[f32; 3]]) -> Splats);

/// Diffusion synthetic acceleration of band `b` after a sweep (module docs): the isotropic change
/// ΔI0 of the sweep drives the diffusion equation for the error δ of the mean radiance (W·m⁻²·sr⁻¹);
/// I_00 += √(4π) δ, and the P1 radiance of the correction, δI(Ω) = δ − Ω·∇δ/(ρσtr′) (Fick's law
/// with the operator's own face couplings), adds its first moments I_1m += −√(4π/3) ∂_m δ/(ρσtr′).
/// Without the first moments the current's error decays only by a′χ′_1 ≈ 0.8 per sweep: the
/// noon cloud at σt × 4 took 18 iterations with δ alone, 13 with both.
///
/// `hier` holds one hierarchy per band, or one for all three when the bands' optics are the same
/// (then the three systems are solved together, the operator's rows read once per pass).
/// `voxels`: the grid index of every full voxel (the unknowns), in grid order.
fn accelerate(c: &Ctx, voxels: &[usize], hier: &[Hierarchy], bands: &[BandOptics], moments: &[f32], next: &mut [f32]) {
    let rhs: Vec<Vec<f64>> = (0..3).map(|b| dsa_rhs(c, voxels, &bands[b], b, moments, next)).collect();
    // The correction need only be as good as the iteration's tolerance: 1e-2 instead of 1e-4
    // changed the dense cloud's image by 3e-6 and halved the time of the solve.
    let (tol, cap) = (1e-2, 100);
    let mut deltas: Vec<Vec<f64>> = if let [h] = hier {
        h.solve_many([&rhs[0][..], &rhs[1][..], &rhs[2][..]], None, tol, cap)
            .map(|(d, _)| d)
            .into()
    } else {
        hier.iter().zip(&rhs).map(|(h, r)| h.solve(r, None, tol, cap).0).collect()
    };
    for (b, delta) in deltas.iter_mut().enumerate() {
        // With back-scattering (χ′_1 < 0) the error's current alternates from sweep to sweep and
        // the full correction overshoots it (g = −0.9 diverged, with or without the first
        // moments); half of it converges (the default cloud at g = −0.9: 14 iterations).
        if bands[b].chi.get(1).is_some_and(|&c| c < 0.0) {
            delta.iter_mut().for_each(|d| *d *= 0.5);
        }
        dsa_apply(c, voxels, &bands[b], b, delta, next);
    }
}

/// Band `b`'s DSA right-hand side per full voxel: ρσs′ ΔI0 of the last sweep.
fn dsa_rhs(c: &Ctx, voxels: &[usize], bo: &BandOptics, b: usize, moments: &[f32], next: &[f32]) -> Vec<f64> {
    let nsh = c.nsh;
    let y00 = 1.0 / (4.0 * PI).sqrt();
    voxels
        .par_iter()
        .enumerate()
        .map(|(f, &v)| {
            let d0 = (next[(f * 3 + b) * nsh] - moments[(f * 3 + b) * nsh]) as f64 * y00;
            c.rho.at(v) as f64 * bo.sigma_t * bo.albedo * d0
        })
        .collect()
}

/// Add band `b`'s correction δ (per full voxel) as its P1 radiance (see [`accelerate`]).
fn dsa_apply(c: &Ctx, voxels: &[usize], bo: &BandOptics, b: usize, delta: &[f64], next: &mut [f32]) {
    let (dims, nsh) = (c.dims, c.nsh);
    let y00 = 1.0 / (4.0 * PI).sqrt();
    let sigma_tr = bo.sigma_t * (1.0 - bo.albedo * bo.chi.get(1).copied().unwrap_or(0.0));
    let gstride = [1, dims[0], dims[0] * dims[1]];
    for (f, &v) in voxels.iter().enumerate() {
        let cell = [v % dims[0], (v / dims[0]) % dims[1], v / (dims[0] * dims[1])];
        let fo = (f * 3 + b) * nsh;
        next[fo] += (delta[f] / y00) as f32;
        if nsh < 4 {
            continue;
        }
        for ax in 0..3 {
            // ∂δ/∂x_ax / (ρσtr′): the mean over this voxel's faces to full neighbours of
            // 3 D_f (δ_n − δ_p)/h, D_f/h² being the operator's face coupling.
            let (mut sum, mut faces) = (0.0, 0.0);
            for side in [-1i64, 1] {
                let nc = cell[ax] as i64 + side;
                if nc < 0 || nc >= dims[ax] as i64 {
                    continue;
                }
                let nv = (v as i64 + side * gstride[ax] as i64) as usize;
                let nf = match c.full[nv] {
                    u32::MAX => continue,
                    nf => nf as usize,
                };
                let cf = interior_coupling(
                    c.rho.at(v) as f64,
                    c.rho.at(nv) as f64,
                    sigma_tr,
                    c.h[ax],
                    DEFAULT_MIN_OPTICAL_DEPTH,
                );
                sum += 3.0 * cf * c.h[ax] * (delta[nf] - delta[f]) * side as f64;
                faces += 1.0;
            }
            if faces > 0.0 {
                // real_sh's l = 1 functions are √(3/4π) (z, y, x), the first odd ones.
                next[fo + c.even + [2, 1, 0][ax]] -= ((4.0 * PI / 3.0).sqrt() * sum / faces) as f32;
            }
        }
    }
}

/// Extrapolation of the slowest error mode (Lyusternik's): once DSA has removed the diffusive
/// modes, the change shrinks geometrically, by r per iteration (≈ 0.6–0.75 measured: the
/// anisotropic orders DSA does not reach), so the remaining error is r/(1 − r) times the last step.
/// When the last two ratios agree within 0.1 and r ∈ (0.3, 0.9), the factor to add the last step
/// with; None otherwise (an erratic history is left alone). Both ratios must be of changes made
/// after the last extrapolation (at iteration `last`, 0 for none), so at most every third
/// iteration. Measured on the five evaluation scenes: 13/13/6/13/13 → 8/9/5/9/8 iterations,
/// the same images within the tolerance.
fn dominant_mode_step(history: &[f64], last: usize) -> Option<f32> {
    let n = history.len();
    if n < 4 || n < last + 3 {
        return None;
    }
    let (r0, r1) = (history[n - 2] / history[n - 3], history[n - 1] / history[n - 2]);
    (r1 > 0.3 && r1 < 0.9 && (r1 - r0).abs() < 0.1).then(|| (r1 / (1.0 - r1)) as f32)
}

/// Most optical depth per voxel (ρσt′ h, thinnest axis) the solve accepts. The acceleration
/// multiplies a sweep's change of I0 by about the voxels' optical depth τ, and with it the sweeps'
/// f32 rounding (relative 6·10⁻⁸): beyond ~10⁵ that exceeds the tolerance. Measured (albedo 1,
/// g = 0, 40-m voxels): τ = 60 converges in 12 iterations, 6·10³ in 43, 6·10⁵ diverges.
pub const MAX_VOXEL_OPTICAL_DEPTH: f64 = 1e4;

/// A change of I_00 this many times the smallest since the iteration (re)started means the
/// acceleration amplifies: a converging iteration's change falls (erratically by at most ~2 on the
/// evaluation scenes), a diverging one's grows by orders of magnitude within a few iterations.
const DIVERGENCE_FACTOR: f64 = 4.0;

/// (max |ΔI_00|, max |I_00|) over the full voxels and bands (W·m⁻²·sr⁻¹): inf for the first
/// when either iterate holds a non-finite value (so a NaN is never read as "no change").
fn i00_change(next: &[f32], moments: &[f32], nsh: usize) -> (f64, f64) {
    next.iter()
        .step_by(nsh)
        .zip(moments.iter().step_by(nsh))
        .fold((0.0f64, 1e-30f64), |(c, m), (x, y)| {
            let d = (x - y).abs() as f64;
            (if d.is_finite() { c.max(d) } else { f64::INFINITY }, m.max(x.abs() as f64))
        })
}

/// Whether plain source iteration (after the acceleration was given up) has converged: its
/// change falls by r per iteration with r → 1 on thick media, so the error left is about
/// r/(1 − r) times the last change, not the change itself (a change of 4.9·10⁻³ at r = 0.957
/// left 22 times that). `changes`: the relative changes since the restart.
fn plain_converged(changes: &[f64], tolerance: f64) -> bool {
    match changes {
        [.., a, b] if b < a => b * (b / (a - b)).max(1.0) < tolerance,
        _ => false,
    }
}

/// The largest scaled optical depth of a full voxel along its thinnest axis, max ρ σt′ h.
fn max_voxel_optical_depth(c: &Ctx, voxels: &[usize], bands: &[BandOptics]) -> f64 {
    let rho = voxels.iter().fold(0.0f64, |a, &v| a.max(c.rho.at(v) as f64));
    let st = bands.iter().fold(0.0f64, |a, b| a.max(b.sigma_t));
    rho * st * c.h.iter().copied().fold(f64::INFINITY, f64::min)
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
    Ok(solve_warm(m, sun, sky, ground, s, progress, None, false, None)?.0)
}

/// [`solve`] from `start` (a previous frame's converged state, mapped onto this grid; None: the
/// cold start), iterated to the same tolerance; with `keep`, also the converged state for the
/// next frame (src/transport/warm.rs). With `live`, each iteration's iterate is also handed to
/// it as a field (for a live view; built only then, so the solve without it is unchanged).
#[allow(clippy::too_many_arguments)]
pub fn solve_warm(
    m: &Medium,
    sun: &Sun,
    sky: &Sky,
    ground: Option<&Ground>,
    s: &TransportSettings,
    progress: &dyn Progress,
    start: Option<&TransportState>,
    keep: bool,
    live: Option<&dyn Fn(&TransportField)>,
) -> Result<(TransportField, Option<TransportState>)> {
    let optics = Optics::from_medium(m, s.order);
    let h_min = m.voxel_size.x.min(m.voxel_size.y).min(m.voxel_size.z) as f64;
    let tau_max = m.density.max_value() as f64 * optics.bands.iter().fold(0.0f64, |a, b| a.max(b.sigma_t)) * h_min;
    if tau_max > MAX_VOXEL_OPTICAL_DEPTH {
        return Err(Error::Numerical {
            stage: "transport solve".into(),
            message: format!(
                "voxels up to {tau_max:.1e} optical depths thick (medium.sigma_t × density × medium.voxel_size, δ-M \
                 scaled), above the {MAX_VOXEL_OPTICAL_DEPTH:.0e} to which the solve converges (the sweeps' f32 \
                 rounding, amplified about τ times by the acceleration, exceeds render.transport_tolerance beyond); \
                 render it with --method diffusion, or give it thinner voxels (a smaller medium.voxel_size or \
                 medium.sigma_t)"
            ),
        });
    }
    let dims = m.dims();
    let [nx, _, nz] = dims;
    let rho = &*m.density;
    let mut full = vec![u32::MAX; rho.len()];
    let mut nfull = 0usize;
    for (g, _) in rho.full_voxels() {
        full[g] = nfull as u32;
        nfull += 1;
    }
    let nsh = sh_count(s.order);
    let (perm, even) = parity_order(s.order);
    let q = Quadrature::product(s.n_mu, 2 * s.n_mu);
    let bands = &optics.bands;
    // δ-M sun transmittance T′ = T^{1 − a f} at the voxel centres.
    let exact_t = crate::sunlight::SunTransmittance::compute(m, sun.dir);
    let sun_t: Vec<[f32; 3]> = exact_t
        .grid
        .values()
        .map(|t| [0, 1, 2].map(|b| t.powf((bands[b].sigma_t / optics.sigma_t) as f32)))
        .collect();
    drop(exact_t);
    let e_sun = [sun.irradiance.x as f64, sun.irradiance.y as f64, sun.irradiance.z as f64];
    let mut y_sun = vec![0.0; nsh];
    let beam = -DVec3::new(sun.dir.x as f64, sun.dir.y as f64, sun.dir.z as f64);
    real_sh(s.order, beam, &mut y_sun);
    let tables = PairTables::new(&q, s.order, &perm, bands, e_sun, &y_sun);
    let full_vox: Vec<usize> = m.density.full_index().full_voxels().collect();
    debug_assert_eq!(full_vox.len(), nfull);
    let (lo, hi) = m.active_box(1).unwrap_or(([0; 3], dims));
    // Ground: ρ_g/π (E_sun μ_s T′ + E_down) per column, over the footprint grown as far as the
    // cloud's shadow reaches; E_down is the clear sky's plus the cloud's change to it in the last
    // sweep (light leaving the box downwards minus the sky it hides).
    let (hx, hz) = (m.voxel_size.x as f64, m.voxel_size.z as f64);
    let margin = match ground {
        Some(g) => {
            let top = (m.origin.y + m.voxel_size.y * dims[1] as f32 - g.height).max(0.0) as f64;
            let tan = (1.0 - (sun.dir.y as f64).powi(2)).max(0.0).sqrt() / (sun.dir.y as f64).max(1e-3);
            ((top * tan / hx.min(hz)).ceil() as usize).min(2 * nx.max(nz))
        }
        None => 0,
    };
    let gdims = [nx + 2 * margin, nz + 2 * margin];
    let col_xz = |c: usize| {
        let (i, k) = ((c % gdims[0]) as f64 - margin as f64, (c / gdims[0]) as f64 - margin as f64);
        (m.origin.x as f64 + (i + 0.5) * hx, m.origin.z as f64 + (k + 0.5) * hz)
    };
    let ground_t: Vec<[f64; 3]> = (0..gdims[0] * gdims[1])
        .into_par_iter()
        .map(|c| match ground {
            Some(g) => {
                let (x, z) = col_xz(c);
                let t = m.transmittance(Vec3::new(x as f32, g.height, z as f32), sun.dir, 0.0, f32::INFINITY) as f64;
                [0, 1, 2].map(|b| t.powf(bands[b].sigma_t / optics.sigma_t))
            }
            None => [0.0; 3],
        })
        .collect();
    let sky_down = [sky.irradiance_up.x as f64, sky.irradiance_up.y as f64, sky.irradiance_up.z as f64];
    let ground_of = |e_down: Option<&[[f64; 3]]>| -> GroundMap {
        let (radiance, diffuse) = match ground {
            Some(g) => {
                let mu_s = sun.dir.y.max(0.0) as f64;
                (0..gdims[0] * gdims[1])
                    .map(|c| {
                        let de = e_down.map_or([0.0; 3], |e| e[c]);
                        let e = [0, 1, 2].map(|b| (sky_down[b] + de[b]).max(0.0));
                        let total = [0, 1, 2].map(|b| (g.albedo[b] as f64 / PI * (e_sun[b] * mu_s * ground_t[c][b] + e[b])) as f32);
                        let diffuse = [0, 1, 2].map(|b| (g.albedo[b] as f64 / PI * e[b]) as f32);
                        (Rgb::from(total), Rgb::from(diffuse))
                    })
                    .unzip()
            }
            None => (vec![Rgb::ZERO; gdims[0] * gdims[1]], vec![Rgb::ZERO; gdims[0] * gdims[1]]),
        };
        GroundMap {
            margin,
            dims: gdims,
            radiance,
            diffuse,
            clear: ground.map_or(Rgb::ZERO, |g| g.radiance(Vec3::ZERO, sun, sky, 1.0)),
            origin: [m.origin.x as f64, m.origin.z as f64],
            h: [hx, hz],
        }
    };
    let mut ground_map = ground_of(None);
    let n = [0, 1, 2].map(|a| hi[a] - lo[a]);
    let ctx = Ctx {
        dims,
        lo,
        n,
        h: [m.voxel_size.x as f64, m.voxel_size.y as f64, m.voxel_size.z as f64],
        rho,
        full: &full,
        nsh,
        even,
        voxels: &full_vox,
        sun_t: &sun_t,
        cells: [0, 1, 2].map(|a| box_cells(dims, lo, n, rho, &full, full_vox.len(), a)),
        sigma_t: [0, 1, 2].map(|b| bands[b].sigma_t as f32),
        grey: bands[0].sigma_t == bands[1].sigma_t && bands[1].sigma_t == bands[2].sigma_t,
        sky,
        origin: DVec3::new(m.origin.x as f64, m.origin.y as f64, m.origin.z as f64),
        ground_height: ground.map(|g| g.height as f64),
    };
    let dom = Domain::of(m);
    // One DSA hierarchy per distinct band optics (one for grey optics, as in every example).
    let distinct = if bands[1..].iter().all(|b| *b == bands[0]) { 1 } else { 3 };
    let hier: Vec<Hierarchy> = match (&dom, s.acceleration) {
        (Some(dom), true) => (0..distinct)
            .map(|b| {
                let bo = &bands[b];
                // The DSA operator: the diffusion operator with the δ-M coefficients and the
                // sweeps' own diffusion (src/transport/accel.rs).
                let chi1 = bo.chi.get(1).copied().unwrap_or(0.0);
                let (sigma_a, sigma_tr) = (bo.sigma_t * (1.0 - bo.albedo), bo.sigma_t * (1.0 - bo.albedo * chi1));
                Hierarchy::build(&DsaOperator {
                    grid: dims,
                    rho,
                    full: &full,
                    voxels: &full_vox,
                    dom: *dom,
                    h: ctx.h,
                    sigma_a,
                    sigma_tr,
                    tau_min: DEFAULT_MIN_OPTICAL_DEPTH,
                    sweep: SweepDiffusion::new(bo.sigma_t, &q, ctx.h),
                })
            })
            .collect(),
        _ => Vec::new(),
    };
    let warm = start.and_then(|st| st.start(m, s.order, &full_vox, 3 * nsh));
    // A warm start's error is mostly the slow modes the dominant-mode step removes, which needs
    // three iterations to see (src/transport/warm.rs).
    let min_iterations = if warm.is_some() { WARM_MIN_ITERATIONS } else { 1 };
    let mut moments = warm.unwrap_or_else(|| vec![0f32; nfull * 3 * nsh]);
    let mut next = vec![0f32; moments.len()];
    let mut history = Vec::new();
    let mut extrapolated = 0;
    // The acceleration's guard (module docs, "When the acceleration diverges"): the largest
    // change of I_00 since the iteration (re)started, its smallest value so far, and the
    // iteration at which the acceleration was given up.
    let (mut accelerated, mut smallest, mut since_start, mut given_up) = (s.acceleration, f64::INFINITY, 0usize, None);
    // The extrapolation assumes the slowest error mode keeps its sign (a ratio r > 0). With a
    // back-scattering phase function the odd moments' scattering eigenvalues a′χ′_l are negative:
    // their error alternates, and adding the last step r/(1 − r) times amplified it (g = −0.9
    // diverged). Not done there.
    let extrapolate = bands.iter().all(|b| b.chi.iter().all(|&c| c >= 0.0));
    progress.begin("transport iterations", s.max_iterations as u64);
    // An empty medium has nothing to iterate: the sky and ground pass unchanged.
    for _ in 0..if nfull == 0 { 0 } else { s.max_iterations } {
        if progress.cancelled() {
            break;
        }
        let e_down = sweep(&ctx, &q, &tables, &moments, &mut next, &ground_map);
        if accelerated && !hier.is_empty() {
            accelerate(&ctx, &full_vox, &hier, bands, &moments, &mut next);
        }
        let (change_abs, scale) = i00_change(&next, &moments, nsh);
        since_start += 1;
        let diverging = !change_abs.is_finite() || (since_start >= 2 && change_abs > DIVERGENCE_FACTOR * smallest);
        if diverging && accelerated {
            // DSA's diffusion operator is not the sweeps' own diffusion limit, and on voxels many
            // mean free paths thick the mismatch amplifies: start again from zero with plain
            // source iteration (positive, and a contraction for a′ ≤ 1).
            accelerated = false;
            given_up = Some(history.len() + 1);
            moments.fill(0.0);
            next.fill(0.0);
            (smallest, since_start) = (f64::INFINITY, 0);
            ground_map = ground_of(None);
            history.push(1.0);
            progress.advance(1);
            progress.log(&format!(
                "transport: iteration {}, the acceleration diverged (change of I0 {change_abs:.2e} W·m⁻²·sr⁻¹, smallest before {:.2e}); plain source iteration from zero",
                history.len(),
                smallest
            ));
            continue;
        }
        if diverging {
            return Err(Error::Numerical {
                stage: "transport solve".into(),
                message: format!(
                    "plain source iteration diverged at iteration {} (change of I0 {change_abs:.2e}); this is a bug: please report the scene, and render it with --method full or reference meanwhile",
                    history.len() + 1
                ),
            });
        }
        smallest = smallest.min(change_abs);
        let change = change_abs / scale;
        history.push(change);
        if let Some(k) = (accelerated && extrapolate)
            .then(|| dominant_mode_step(&history, extrapolated))
            .flatten()
        {
            next.par_iter_mut().zip(moments.par_iter()).for_each(|(x, o)| *x += k * (*x - o));
            extrapolated = history.len();
        }
        std::mem::swap(&mut moments, &mut next);
        ground_map = ground_of(Some(&e_down));
        progress.converge(change, s.tolerance);
        progress.advance(1);
        progress.log(&format!(
            "transport: iteration {}, relative change of I0 {change:.2e} (stops below {:.1e})",
            history.len(),
            s.tolerance
        ));
        if let Some(show) = live {
            show(&TransportField {
                optics: optics.clone(),
                order: s.order,
                full: full.clone(),
                diffuse_source: diffuse_source_of(&moments, bands, &perm, nsh),
                sun_t: sun_t.clone(),
                ground: ground_map.clone(),
                history: history.clone(),
                full_voxels: nfull,
                ordinates: q.dirs.len(),
            });
        }
        if change < s.tolerance
            && history.len() >= min_iterations
            && (accelerated || plain_converged(&history[history.len() - since_start..], s.tolerance))
        {
            break;
        }
    }
    let last = history.last().copied().unwrap_or(0.0);
    if let Some(at) = given_up.filter(|_| !plain_converged(&history[history.len() - since_start..], s.tolerance)) {
        let tau = max_voxel_optical_depth(&ctx, &full_vox, bands);
        return Err(Error::Numerical {
            stage: "transport solve".into(),
            message: format!(
                "the diffusion acceleration diverged at iteration {at} (voxels up to {tau:.3e} optical depths \
                 thick), and plain source iteration, which needs of the order of (optical depth)² sweeps, had not \
                 converged after render.transport_max_iterations = {} (last change of I0 {last:.1e}, error left \
                 estimated above render.transport_tolerance = {:.1e}); render this medium with --method full or \
                 reference, or give it voxels of at most a few optical depths (a smaller medium.voxel_size or \
                 medium.sigma_t)",
                s.max_iterations, s.tolerance
            ),
        });
    }
    progress.end();
    drop(next);
    let diffuse_source = diffuse_source_of(&moments, bands, &perm, nsh);
    let state = keep.then(|| TransportState::new(m, s.order, full.clone(), moments, 3 * nsh));
    let field = TransportField {
        optics: optics.clone(),
        order: s.order,
        full,
        diffuse_source,
        sun_t,
        ground: ground_map,
        history,
        full_voxels: nfull,
        ordinates: q.dirs.len(),
    };
    Ok((field, state))
}

/// The diffuse source a′χ′_l I_lm in real_sh's order for the gather, from the solver's
/// moments (in `perm`'s parity order), per full voxel, band, lm.
fn diffuse_source_of(moments: &[f32], bands: &[BandOptics], perm: &[usize], nsh: usize) -> Vec<f32> {
    let mut diffuse_source = vec![0f32; moments.len()];
    diffuse_source
        .par_chunks_mut(3 * nsh)
        .zip(moments.par_chunks(3 * nsh))
        .for_each(|(o, mf)| {
            for (band, bo) in bands.iter().enumerate() {
                for (i, k) in perm.iter().enumerate() {
                    let l = (*k as f64).sqrt().floor() as usize;
                    o[band * nsh + k] = (bo.albedo * bo.chi[l] * mf[band * nsh + i] as f64) as f32;
                }
            }
        });
    diffuse_source
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_weights_integrate_constants_and_ramps() {
        for x in [1e-4f32, 5e-3, 0.02, 0.199, 0.201, 0.5, 3.0, 40.0] {
            let (e, wi, wo) = step_weights(x);
            let xd = x as f64;
            let ed = (-xd).exp();
            // ∫₀ˣ e^{−(x−t)} dt = 1 − e^{−x}; ∫₀ˣ (t/x) e^{−(x−t)} dt = 1 − (1 − e^{−x})/x.
            let wod = 1.0 - (1.0 - ed) / xd;
            assert!(((e as f64) - ed).abs() < 1e-6, "x={x}");
            assert!(((wi + wo) as f64 - (1.0 - ed)).abs() < 1e-6 * (1.0 - ed).max(1e-2), "x={x}");
            assert!(((wo as f64) - wod).abs() < 1e-5 * wod, "x={x}: {wo} vs {wod}");
            assert!(wi >= 0.0 && wo >= 0.0);
        }
    }

    #[test]
    fn dominant_mode_step_extrapolates_only_a_steady_geometric_decay() {
        let geometric: Vec<f64> = (0..7).map(|i| 0.75f64.powi(i)).collect();
        // r = 0.75: the remaining error is 3 steps.
        assert!((dominant_mode_step(&geometric[..4], 0).unwrap() - 3.0).abs() < 1e-5);
        assert_eq!(dominant_mode_step(&geometric[..5], 4), None, "two ratios since the last one");
        assert_eq!(dominant_mode_step(&geometric[..6], 4), None);
        assert!((dominant_mode_step(&geometric[..7], 4).unwrap() - 3.0).abs() < 1e-5);
        assert!((dominant_mode_step(&geometric[..5], 0).unwrap() - 3.0).abs() < 1e-5);
        assert_eq!(dominant_mode_step(&[1.0, 0.5, 0.6, 0.3], 0), None, "erratic");
        assert_eq!(dominant_mode_step(&[1.0, 0.95, 0.9025, 0.857], 0), None, "too slow to trust");
        assert_eq!(dominant_mode_step(&[1.0, 0.1, 0.01, 0.001], 0), None, "fast already");
    }

    #[test]
    fn the_avx_kernels_give_the_same_bits_as_the_plain_ones() {
        // A 7×5×4 box with empty voxels inside, random moments: each kernel as built and through
        // its dispatcher (AVX where the processor has it) must agree bit for bit.
        let dims = [7, 5, 4];
        let nv = dims[0] * dims[1] * dims[2];
        let rho: Vec<f32> = (0..nv).map(|v| ((v as f32 * 0.618).fract() - 0.2).max(0.0) * 3.0).collect();
        let mut full = vec![u32::MAX; nv];
        let mut voxels = Vec::new();
        for v in 0..nv {
            if rho[v] > 0.0 {
                full[v] = voxels.len() as u32;
                voxels.push(v);
            }
        }
        let density = Density::from_grid(&crate::medium::Grid3::from_vec(dims, rho, "test").unwrap());
        let nfull = voxels.len();
        let order = 7;
        let (perm, even) = parity_order(order);
        let nsh = perm.len();
        let sun_t: Vec<[f32; 3]> = (0..nv).map(|v| [0.3, 0.5, 0.7].map(|t| t + 0.01 * (v % 7) as f32)).collect();
        let sky = Sky::constant(Rgb::new(0.2, 0.3, 0.5));
        let c = Ctx {
            dims,
            lo: [0; 3],
            n: dims,
            h: [10.0, 8.0, 12.0],
            rho: &density,
            full: &full,
            nsh,
            even,
            voxels: &voxels,
            sun_t: &sun_t,
            cells: [0, 1, 2].map(|a| box_cells(dims, [0; 3], dims, &density, &full, voxels.len(), a)),
            sigma_t: [0.05, 0.06, 0.07],
            grey: false,
            sky: &sky,
            origin: DVec3::ZERO,
            ground_height: None,
        };
        let ground = GroundMap {
            margin: 0,
            dims: [dims[0], dims[2]],
            radiance: vec![Rgb::ZERO; dims[0] * dims[2]],
            diffuse: vec![Rgb::ZERO; dims[0] * dims[2]],
            clear: Rgb::ZERO,
            origin: [0.0; 2],
            h: [10.0, 12.0],
        };
        let bands: Vec<BandOptics> = (0..3)
            .map(|b| BandOptics::delta_m(0.05, 0.9 + 0.03 * b as f64, 0.85, order))
            .collect();
        let q = Quadrature::product(8, 16);
        let mut y_sun = vec![0.0; nsh];
        real_sh(order, DVec3::new(0.2, -0.9, 0.3).normalize(), &mut y_sun);
        let t = PairTables::new(&q, order, &perm, &bands, [2.0, 1.8, 1.5], &y_sun);
        let moments: Vec<f32> = (0..nfull * 3 * nsh)
            .map(|i| ((i as f32 * 0.37).sin() * 0.5 + 0.6) / (1 + i % nsh) as f32)
            .collect();
        let bits = |v: &[[f32; 3]]| v.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
        // Step (1).
        let (mut plain, mut disp) = (vec![[0f32; 3]; ORDINATE_BATCH * nfull], vec![[0f32; 3]; ORDINATE_BATCH * nfull]);
        source_kernel(&c, &t, 1, PAIRS, &moments, 0, Shared(plain.as_mut_ptr()));
        source_block(&c, &t, 1, PAIRS, &moments, 0, Shared(disp.as_mut_ptr()));
        assert_eq!(bits(&plain), bits(&disp));
        assert!(plain.iter().flatten().any(|x| *x > 0.0));
        // Step (2), one ordinate per major axis and sign, with coloured and with grey optics
        // (the AVX copy's own cell step).
        let grey = Ctx {
            sigma_t: [0.05; 3],
            grey: true,
            cells: c.cells.clone(),
            ..c
        };
        for c in [&c, &grey] {
            for d in [0, 5, 37, 64, 90, 127] {
                let (mut ra, mut rb) = (vec![[0f32; 3]; nfull], vec![[0f32; 3]; nfull]);
                sweep_kernel::<false>(c, q.dirs[d], q.weights[d], &plain[..nfull], &ground, &mut ra);
                sweep_ordinate(c, q.dirs[d], q.weights[d], &plain[..nfull], &ground, &mut rb);
                assert_eq!(bits(&ra), bits(&rb), "ordinate {d}, grey {}", c.grey);
                assert!(ra.iter().flatten().any(|x| *x > 0.0));
            }
        }
        // Step (3).
        let wts: Vec<f32> = t.weights[PAIRS..2 * PAIRS].iter().flatten().copied().collect();
        let nblk = t.y_acc.len() / t.pairs.len().div_ceil(PAIRS);
        let l = Lanes {
            nfull,
            wts: &wts,
            radiance: &plain,
            y: &t.y_acc[nblk..2 * nblk],
        };
        let (mut ma, mut mb) = (moments.clone(), moments.clone());
        moments_kernel(&c, &l, &mut ma, 0);
        moments_block(&c, &l, &mut mb, 0);
        assert_eq!(
            ma.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
            mb.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
        );
    }

    #[test]
    fn parity_order_puts_even_l_first_and_pairs_are_opposite() {
        let (perm, ne) = parity_order(7);
        assert_eq!((perm.len(), ne), (64, 28));
        let l_of = |k: usize| (k as f64).sqrt().floor() as usize;
        assert!(perm[..ne].iter().all(|k| l_of(*k) % 2 == 0) && perm[ne..].iter().all(|k| l_of(*k) % 2 == 1));
        assert_eq!(&perm[ne..ne + 3], &[1, 2, 3], "the l = 1 block leads the odd ones (DSA's current)");
        let mut sorted = perm.clone();
        sorted.sort();
        assert_eq!(sorted, (0..64).collect::<Vec<_>>());
        let q = Quadrature::product(8, 16);
        let pairs = opposite_pairs(&q);
        assert_eq!(pairs.len(), 64);
        for [d, o] in pairs {
            assert!((q.dirs[d] + q.dirs[o]).length() < 1e-12 && q.weights[d] == q.weights[o]);
        }
    }

    #[test]
    fn pair_source_and_moments_match_the_direct_sums() {
        // Random coefficients I_lm: the source from the pair tables (E ± O plus the sun) against
        // Σ a′χ′_l (I_lm + E T′ Y_lm(Ω_sun)) Y_lm(Ω) in each ordinate, and the moments
        // accumulated per pair against Σ_Ω w I(Ω) Y_lm(Ω) in f64.
        let order = 5;
        let nsh = sh_count(order);
        let (perm, ne) = parity_order(order);
        let q = Quadrature::product(6, 12);
        let bands: Vec<BandOptics> = [0.99, 0.9, 0.6]
            .iter()
            .map(|a| BandOptics {
                sigma_t: 1.0,
                albedo: *a,
                chi: (0..=order).map(|l| 0.8f64.powi(l as i32)).collect(),
                f: 0.0,
            })
            .collect();
        let e_sun = [2.0, 1.5, 1.0];
        let beam = DVec3::new(0.3, -0.8, 0.2).normalize();
        let mut y_sun = vec![0.0; nsh];
        real_sh(order, beam, &mut y_sun);
        let t = PairTables::new(&q, order, &perm, &bands, e_sun, &y_sun);
        let mom: Vec<f64> = (0..3 * nsh).map(|i| ((i as f64) * 0.731).sin() / (1.0 + i as f64 * 0.1)).collect();
        let mom_inner: Vec<f32> = (0..3)
            .flat_map(|b| perm.iter().map(move |k| (b, *k)))
            .map(|(b, k)| mom[b * nsh + k] as f32)
            .collect();
        let tf = [0.7f32, 0.5, 0.3];
        let l_of = |k: usize| (k as f64).sqrt().floor() as usize;
        let mut y = vec![0.0; nsh];
        for (p, [d, o]) in t.pairs.iter().enumerate() {
            let (bi, lane) = (p / PAIRS, p % PAIRS);
            for (b, bo) in bands.iter().enumerate() {
                let m = &mom_inner[b * nsh..(b + 1) * nsh];
                let ys = &t.y_src[(bi * 3 + b) * nsh..(bi * 3 + b + 1) * nsh];
                let (e, od) = (lanes_dot(&m[..ne], &ys[..ne])[lane], lanes_dot(&m[ne..], &ys[ne..])[lane]);
                let got = [
                    e + od + tf[b] * t.sun[bi * 3 + b][0][lane],
                    e - od + tf[b] * t.sun[bi * 3 + b][1][lane],
                ];
                for (dir, g) in [*d, *o].iter().zip(got) {
                    real_sh(order, q.dirs[*dir], &mut y);
                    let want: f64 = (0..nsh)
                        .map(|k| bo.albedo * bo.chi[l_of(k)] * (mom[b * nsh + k] + e_sun[b] * tf[b] as f64 * y_sun[k]) * y[k])
                        .sum();
                    assert!((g as f64 - want).abs() < 1e-5, "pair {p} band {b}: {g} vs {want}");
                }
            }
        }
        // Moments of a radiance field I(Ω) = 1 + Ω_x + Ω_y Ω_z over the pairs of batch 0.
        let radiance = |v: DVec3| 1.0 + v.x + v.y * v.z;
        let np = PAIRS.min(t.pairs.len());
        let (mut se, mut so) = ([0f32; PAIRS], [0f32; PAIRS]);
        for p in 0..np {
            let [d, o] = t.pairs[p];
            let (ip, im) = (
                t.weights[p][0] * radiance(q.dirs[d]) as f32,
                t.weights[p][1] * radiance(q.dirs[o]) as f32,
            );
            (se[p], so[p]) = (ip + im, ip - im);
        }
        let mut acc = vec![0f32; nsh];
        let nbe = ne.div_ceil(8);
        let nblk = t.y_acc.len() / t.pairs.len().div_ceil(PAIRS);
        accumulate(&mut acc[..ne], &se, &t.y_acc[..nbe]);
        accumulate(&mut acc[ne..], &so, &t.y_acc[nbe..nblk]);
        for (i, k) in perm.iter().enumerate() {
            let want: f64 = t.pairs[..np]
                .iter()
                .flatten()
                .map(|dir| {
                    real_sh(order, q.dirs[*dir], &mut y);
                    q.weights[*dir] * radiance(q.dirs[*dir]) * y[*k]
                })
                .sum();
            assert!((acc[i] as f64 - want).abs() < 1e-5, "lm {k}: {} vs {want}", acc[i]);
        }
    }
}
