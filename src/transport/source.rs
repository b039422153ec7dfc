//! The per-voxel steps of a sweep batch, in the solver's spherical-harmonic order
//! ([`parity_order`]): (1) the source J(Ω) = Σ_lm a′χ′_l (I_lm + E T′_sun Y_lm(Ω_sun)) Y_lm(Ω) in
//! both ordinates of each opposite pair from one pass over a voxel's moments ([`source_block`]),
//! and (3) the moments I_lm += w I(Ω) Y_lm(Ω) of the batch's radiances ([`moments_block`]).

use super::grid::Ctx;
use super::simd::has_avx;
use super::sphere::Quadrature;
use super::BandOptics;
use crate::math::real_sh;

/// The order of the harmonics inside the solver: every even-l one first, then the odd-l ones
/// (each l's block in `real_sh`'s order). Y_lm(−Ω) = (−1)^l Y_lm(Ω), so one pass over a voxel's
/// coefficients gives the even and odd sums E, O and with them the source in both ordinates of an
/// opposite pair (E ± O); likewise one pass accumulates both ordinates' moments. `perm[i]` is
/// the `real_sh` index of inner index i; the second value, the count of even ones.
pub(super) fn parity_order(order: usize) -> (Vec<usize>, usize) {
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

/// Ordinates swept side by side: their per-voxel sources, replaced by their radiances, are held
/// at once (12 B per full voxel each). Fixed, so the sums are the same for any thread count.
pub(crate) const ORDINATE_BATCH: usize = 16;

/// Opposite pairs per batch: the lanes of the source evaluation.
pub(super) const PAIRS: usize = ORDINATE_BATCH / 2;

/// A batch's pairs side by side, one AVX register: 32-byte aligned, so the AVX kernels load it
/// whole (an unaligned 256-bit load is split into two 128-bit ones).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C, align(32))]
pub(super) struct PairLanes(pub(super) [f32; PAIRS]);

/// Per ordinate pair, what the sweeps' per-voxel steps read (inner harmonic order, f32).
#[derive(Clone)]
pub(super) struct PairTables {
    /// The ordinates (d, d′ = opposite).
    pub(super) pairs: Vec<[usize; 2]>,
    /// Weights (sr) of d and d′.
    pub(super) weights: Vec<[f32; 2]>,
    /// Y_lm(Ω_d) for the moments, per batch in blocks of eight harmonics with the batch's pairs
    /// side by side ([`accumulate`]): the even ones' blocks, then the odd ones' (zero past each
    /// part's end).
    pub(super) y_acc: Vec<[PairLanes; PAIRS]>,
    /// a′χ′_l Y_lm(Ω_d) per batch of pairs, band and lm, the batch's pairs in lanes (0 past the
    /// last pair): the source in Ω_d is Σ I_lm times this.
    pub(super) y_src: Vec<PairLanes>,
    /// The reduced sun's first scattering per unit T′ in Ω_d and in −Ω_d per batch and band, in
    /// lanes: Σ_lm a′χ′_l E Y_lm(Ω_sun) Y_lm(±Ω_d) (W·m⁻²·sr⁻¹).
    pub(super) sun: Vec<[PairLanes; 2]>,
    /// The even and odd harmonics the source kernel reads and the moment kernel accumulates: a
    /// prefix of each parity part, all of them or those of a lower order
    /// ([`PairTables::truncated`]).
    pub(super) source_active: [usize; 2],
    pub(super) moment_active: [usize; 2],
}

impl PairTables {
    pub(super) fn new(q: &Quadrature, order: usize, perm: &[usize], bands: &[BandOptics], e_sun: [f64; 3], y_sun: &[f64]) -> PairTables {
        let nsh = perm.len();
        let pairs = opposite_pairs(q);
        let l_of = |k: usize| (k as f64).sqrt().floor() as usize;
        let batches = pairs.len().div_ceil(PAIRS);
        let ne = perm.iter().filter(|k| l_of(**k) % 2 == 0).count();
        let (nbe, nblk) = (ne.div_ceil(8), ne.div_ceil(8) + (nsh - ne).div_ceil(8));
        let mut y_acc = vec![[PairLanes::default(); PAIRS]; batches * nblk];
        let mut y_src = vec![PairLanes::default(); batches * 3 * nsh];
        let mut sun = vec![[PairLanes::default(); 2]; batches * 3];
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
                y_acc[bi * nblk + kb][lane].0[l] = yd[*k] as f32;
            }
            for (b, bo) in bands.iter().enumerate() {
                for (i, k) in perm.iter().enumerate() {
                    y_src[(bi * 3 + b) * nsh + i].0[lane] = (bo.albedo * bo.chi[l_of(*k)] * yd[*k]) as f32;
                }
                let term = |k: usize| bo.albedo * bo.chi[l_of(k)] * e_sun[b] * y_sun[k] * yd[k];
                let (e, o) = (0..nsh).fold(
                    (0.0, 0.0),
                    |(e, o), k| if l_of(k) % 2 == 0 { (e + term(k), o) } else { (e, o + term(k)) },
                );
                sun[bi * 3 + b][0].0[lane] = (e + o) as f32;
                sun[bi * 3 + b][1].0[lane] = (e - o) as f32;
            }
        }
        let weights = pairs.iter().map(|[d, o]| [q.weights[*d] as f32, q.weights[*o] as f32]).collect();
        PairTables {
            pairs,
            weights,
            y_acc,
            y_src,
            sun,
            source_active: [ne, nsh - ne],
            moment_active: [ne, nsh - ne],
        }
    }

    /// The same tables with the source read from the harmonics of order ≤ `source_order` and
    /// the moments accumulated to order `moment_order` (in the parity order each part's
    /// harmonics of an order ≤ l are a prefix); the sun's first scattering keeps every order.
    pub(super) fn truncated(&self, source_order: usize, moment_order: usize) -> PairTables {
        let active = |order: usize| {
            let count = |from: usize| (from..=order).step_by(2).map(|l| 2 * l + 1).sum::<usize>();
            [count(0).min(self.source_active[0]), count(1).min(self.source_active[1])]
        };
        PairTables {
            source_active: active(source_order),
            moment_active: active(moment_order),
            ..self.clone()
        }
    }
}

/// Σ_k m[k] y[k] for every lane (a batch's pairs), two k at a time in independent sums.
#[inline(always)]
fn lanes_dot(m: &[f32], y: &[PairLanes]) -> [f32; PAIRS] {
    let (mut a0, mut a1) = ([0f32; PAIRS], [0f32; PAIRS]);
    for (mk, yk) in m.chunks_exact(2).zip(y.chunks_exact(2)) {
        // Whole lanes copied out: an aligned load of each (indexed in place, each lane is a load
        // of unknown alignment, which the AVX copy splits).
        let (y0, y1) = (yk[0].0, yk[1].0);
        for p in 0..PAIRS {
            a0[p] += mk[0] * y0[p];
            a1[p] += mk[1] * y1[p];
        }
    }
    if m.len() % 2 == 1 {
        let (mk, yk) = (m[m.len() - 1], y[m.len() - 1].0);
        for (a, yp) in a0.iter_mut().zip(yk) {
            *a += mk * yp;
        }
    }
    // A loop, not `array::from_fn`: its closure would not be compiled for the AVX copy
    // (src/transport/sweep/step.rs).
    for p in 0..PAIRS {
        a0[p] += a1[p];
    }
    a0
}

/// acc[k] += Σ_p s[p] y_p[k] (pairs 0–3 and 4–7 each summed in order from 0, the two sums
/// added, then added to acc[k]), eight k at a time: `blocks[kb][p]` holds y_p[8kb..8kb + 8]; the
/// same order for any thread count.
/// Lanes past a short batch's last pair hold s = y = 0 and add +0 (a sum from +0 never is −0).
/// `FIRST`: acc[k] = the sum instead, the same bits as adding it to +0 (the sum is never −0).
#[inline(always)]
fn accumulate<const FIRST: bool>(acc: &mut [f32], s: &[f32; PAIRS], blocks: &[[PairLanes; PAIRS]]) {
    for (a, blk) in acc.chunks_mut(8).zip(blocks) {
        // Two sums of four pairs each, then added: two chains of dependent adds, not one of eight.
        let (mut r, mut r1) = ([0f32; 8], [0f32; 8]);
        let half = PAIRS / 2;
        for (sp, y) in s[..half].iter().zip(&blk[..half]) {
            let y = y.0;
            for (rl, yl) in r.iter_mut().zip(y) {
                *rl += sp * yl;
            }
        }
        for (sp, y) in s[half..].iter().zip(&blk[half..]) {
            let y = y.0;
            for (rl, yl) in r1.iter_mut().zip(y) {
                *rl += sp * yl;
            }
        }
        for (rl, r1l) in r.iter_mut().zip(r1) {
            *rl += r1l;
        }
        // A whole block as one vector (its length known), a part's short last block lane by lane.
        if a.len() == 8 {
            let whole: &mut [f32; 8] = a.try_into().expect("a block of eight");
            add_lanes::<FIRST>(whole, &r);
        } else {
            let n = a.len();
            add_lanes::<FIRST>(a, &r[..n]);
        }
    }
}

/// a = r (`FIRST`) or a += r, lane by lane.
#[inline(always)]
fn add_lanes<const FIRST: bool>(a: &mut [f32], r: &[f32]) {
    for (al, rl) in a.iter_mut().zip(r) {
        if FIRST {
            *al = *rl;
        } else {
            *al += *rl;
        }
    }
}
/// Step (1) of a sweep batch for the full voxels from `f0` whose moments are `block`: the
/// source in both ordinates of each of the batch's `pairs` pairs (batch `bi`), into `out[2p]` and
/// `out[2p + 1]` (each slot's entries for these voxels).
#[inline(always)]
pub(super) fn source_kernel(c: &Ctx, t: &PairTables, bi: usize, pairs: usize, block: &[f32], f0: usize, out: &mut [&mut [[f32; 3]]]) {
    let (nsh, ne) = (c.nsh, c.even);
    let [ae, ao] = t.source_active;
    for (k, mom) in block.chunks_exact(3 * nsh).enumerate() {
        let f = f0 + k;
        let tf = c.sun_t[f];
        // Per band, the pairs in lanes (computed as vectors), then per slot its three bands.
        let (mut plus, mut minus) = ([[0f32; PAIRS]; 3], [[0f32; PAIRS]; 3]);
        for b in 0..3 {
            let (m, y) = (&mom[b * nsh..(b + 1) * nsh], &t.y_src[(bi * 3 + b) * nsh..(bi * 3 + b + 1) * nsh]);
            let (e, o) = (lanes_dot(&m[..ae], &y[..ae]), lanes_dot(&m[ne..ne + ao], &y[ne..ne + ao]));
            let [sp_, sm_] = &t.sun[bi * 3 + b];
            for p in 0..PAIRS {
                plus[b][p] = (e[p] + o[p] + tf[b] * sp_.0[p]).max(0.0);
                minus[b][p] = (e[p] - o[p] + tf[b] * sm_.0[p]).max(0.0);
            }
        }
        for slot in 0..pairs {
            out[2 * slot][k] = [plus[0][slot], plus[1][slot], plus[2][slot]];
            out[2 * slot + 1][k] = [minus[0][slot], minus[1][slot], minus[2][slot]];
        }
    }
}

/// [`source_kernel`], compiled for AVX where the processor has it.
pub(super) fn source_block(c: &Ctx, t: &PairTables, bi: usize, pairs: usize, block: &[f32], f0: usize, out: &mut [&mut [[f32; 3]]]) {
    #[cfg(target_arch = "x86_64")]
    if has_avx() {
        // SAFETY: the processor has AVX.
        return unsafe { source_block_avx(c, t, bi, pairs, block, f0, out) };
    }
    source_kernel(c, t, bi, pairs, block, f0, out)
}

/// [`source_kernel`] compiled for AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn source_block_avx(c: &Ctx, t: &PairTables, bi: usize, pairs: usize, block: &[f32], f0: usize, out: &mut [&mut [[f32; 3]]]) {
    source_kernel(c, t, bi, pairs, block, f0, out)
}

/// What step (3) of a sweep batch reads: the batch's radiances per ordinate slot and full voxel, the
/// slots' weights (sr) and the pairs' Y_lm (the batch's blocks of [`PairTables::y_acc`]).
pub(super) struct Lanes<'a> {
    pub(super) nfull: usize,
    pub(super) wts: &'a [f32],
    pub(super) radiance: &'a [[f32; 3]],
    pub(super) y: &'a [[PairLanes; PAIRS]],
    /// The sweep's first batch: it writes the new moments instead of adding to them.
    pub(super) first: bool,
    /// The even and odd harmonics accumulated ([`PairTables::moment_active`]); the others are
    /// left as they are.
    pub(super) active: [usize; 2],
}

/// Step (3) of a sweep batch for the full voxels from `f0` whose new moments are `block`: I_lm +=
/// w I(Ω) Y_lm(Ω) + w′ I(−Ω) (−1)^l Y_lm(Ω) over the batch's pairs.
#[inline(always)]
pub(super) fn moments_kernel(c: &Ctx, l: &Lanes, block: &mut [f32], f0: usize) {
    let (nsh, ne, nfull) = (c.nsh, c.even, l.nfull);
    let [ae, ao] = l.active;
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
            let (even, odd) = a.split_at_mut(ne);
            if l.first {
                accumulate::<true>(&mut even[..ae], &se, &l.y[..nbe]);
                accumulate::<true>(&mut odd[..ao], &so, &l.y[nbe..]);
            } else {
                accumulate::<false>(&mut even[..ae], &se, &l.y[..nbe]);
                accumulate::<false>(&mut odd[..ao], &so, &l.y[nbe..]);
            }
        }
    }
}

/// [`moments_kernel`], compiled for AVX where the processor has it.
pub(super) fn moments_block(c: &Ctx, l: &Lanes, block: &mut [f32], f0: usize) {
    #[cfg(target_arch = "x86_64")]
    if has_avx() {
        // SAFETY: the processor has AVX.
        return unsafe { moments_block_avx(c, l, block, f0) };
    }
    moments_kernel(c, l, block, f0)
}

/// [`moments_kernel`] compiled for AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn moments_block_avx(c: &Ctx, l: &Lanes, block: &mut [f32], f0: usize) {
    moments_kernel(c, l, block, f0)
}
/// The diffuse source a′χ′_l I_lm in real_sh's order for the gather, from the solver's
/// moments (in `perm`'s parity order), per full voxel, band, lm, written over `out` (as long as
/// `moments`: the solve hands over its spent array, whose pages are already mapped).
pub(super) fn diffuse_source_of(moments: &[f32], bands: &[BandOptics], perm: &[usize], nsh: usize, mut out: Vec<f32>) -> Vec<f32> {
    // Per band and inner index: the real_sh index and a′χ′_l.
    let factors: Vec<Vec<(usize, f64)>> = bands
        .iter()
        .map(|bo| perm.iter().map(|&k| (k, bo.albedo * bo.chi[(k as f64).sqrt().floor() as usize])).collect())
        .collect();
    assert_eq!(out.len(), moments.len(), "the diffuse source's array as long as the moments");
    // Voxels per task: a few hundred.
    let per_task = 256 * 3 * nsh;
    crate::par::for_chunks(&mut out, per_task, &|ci, os| {
        for (o, mf) in os.chunks_mut(3 * nsh).zip(moments[ci * per_task..].chunks(3 * nsh)) {
            for (band, fb) in factors.iter().enumerate() {
                for (i, &(k, a_chi)) in fb.iter().enumerate() {
                    o[band * nsh + k] = (a_chi * mf[band * nsh + i] as f64) as f32;
                }
            }
        }
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::sh_count;
    use glam::DVec3;

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
    fn truncated_tables_cover_exactly_the_lower_orders() {
        // In the parity order the harmonics of order ≤ 3 are the first 6 even and 10 odd ones.
        let order = 7;
        let (perm, ne) = parity_order(order);
        let q = Quadrature::product(4, 8);
        let band = BandOptics {
            sigma_t: 1.0,
            albedo: 0.9,
            chi: (0..=order).map(|l| 0.8f64.powi(l as i32)).collect(),
            f: 0.0,
        };
        let bands = [band.clone(), band.clone(), band];
        let full = PairTables::new(&q, order, &perm, &bands, [1.0; 3], &vec![0.0; perm.len()]);
        assert_eq!((full.source_active, full.moment_active), ([28, 36], [28, 36]));
        let t = full.truncated(3, order);
        assert_eq!((t.source_active, t.moment_active), ([6, 10], [28, 36]));
        let l_of = |k: usize| (k as f64).sqrt().floor() as usize;
        let [e, o] = t.source_active;
        assert!(perm[..e].iter().chain(&perm[ne..ne + o]).all(|k| l_of(*k) <= 3));
        assert!(perm[e..ne].iter().chain(&perm[ne + o..]).all(|k| l_of(*k) > 3));
        assert_eq!(full.truncated(9, 9).source_active, [28, 36], "no more than the tables hold");
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
                    e + od + tf[b] * t.sun[bi * 3 + b][0].0[lane],
                    e - od + tf[b] * t.sun[bi * 3 + b][1].0[lane],
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
        accumulate::<false>(&mut acc[..ne], &se, &t.y_acc[..nbe]);
        accumulate::<false>(&mut acc[ne..], &so, &t.y_acc[nbe..nblk]);
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
