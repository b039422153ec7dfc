//! A sweep's cell step ([`super`] module docs) for the cells of a plane row, [`LANES`] at a time:
//! the cells of a plane read only the previous plane, and every cell of a plane reads its four
//! upwind neighbours at the same offsets with the same bilinear weights, so a run of cells is
//! one lane-wise computation. The plane buffers hold each field of a cell in its own array
//! ([`Plane`]), so the eight cells' upwind values are one eight-lane load per field and
//! neighbour. The step is written once over a lane type ([`Vector`]: AVX, SSE2 or one `f32`),
//! every operation per lane in a fixed order, so each gives the same bits (a test steps every
//! ordinate one cell at a time, in SSE2 and in AVX lanes). The step has no closures
//! (`array::from_fn`, iterator adaptors): a closure is a function of its own, not compiled for
//! the AVX copy's target feature, and where LLVM leaves one outlined every intrinsic inside it
//! becomes a call (measured: the solve 3× slower). Plain loops and `#[inline(always)]` functions.

use super::lanes::{Vector, ROUND};
use crate::transport::simd::prefetch;

/// Cells of a row stepped together: one AVX register of f32.
const LANES: usize = 8;

/// Fields of a plane cell: the radiance per band ([`I`]..), the density ([`RHO`]) and the
/// density × source per band ([`RS`]..).
pub(super) const I: usize = 0;
pub(super) const RHO: usize = 3;
pub(super) const RS: usize = 4;
const FIELDS: usize = 7;

/// A plane cell's fields.
pub(in crate::transport) type Record = [f32; FIELDS];

/// The record of a cell holding radiance `i`, density `rho` and density × source `rs`.
pub(in crate::transport) fn record(i: [f32; 3], rho: f32, rs: [f32; 3]) -> Record {
    [i[0], i[1], i[2], rho, rs[0], rs[1], rs[2]]
}

/// A sweep's plane buffer: per field, one array over the plane's cells (with the ghost ring),
/// followed by [`LANES`] spare cells so that a run's last eight-lane load stays inside it.
pub(in crate::transport) struct Plane {
    /// Cells per field array, the spare ones included.
    len: usize,
    data: Vec<f32>,
}

impl Plane {
    /// A buffer of `cells` cells, each holding `rec`.
    pub(in crate::transport) fn new(cells: usize, rec: Record) -> Plane {
        let len = cells + LANES;
        let mut data = Vec::with_capacity(FIELDS * len);
        for value in rec {
            data.resize(data.len() + len, value);
        }
        Plane { len, data }
    }

    /// Cells in the buffer (without the spare ones).
    pub(in crate::transport) fn cells(&self) -> usize {
        self.len - LANES
    }

    /// Cell `i` set to `rec`.
    pub(in crate::transport) fn set(&mut self, i: usize, rec: Record) {
        assert!(i < self.cells(), "plane cell {i} of {}", self.cells());
        for (f, value) in rec.into_iter().enumerate() {
            self.data[f * self.len + i] = value;
        }
    }

    /// The record at the back point of the cell `l` of the next plane: its four upwind cells'
    /// ([`Step`]) bilinear mean, field by field, summed in [`step_row`]'s order.
    pub(super) fn upwind(&self, k: &Step, l: usize) -> Record {
        let u = usize::try_from(l as isize + k.up).expect("upwind cell inside the buffer");
        std::array::from_fn(|f| {
            let field = &self.data[f * self.len..(f + 1) * self.len];
            let mut sum = 0f32;
            for (wk, i) in k.weights.iter().zip([u, u + 1, u + k.stride, u + k.stride + 1]) {
                sum += wk * field[i];
            }
            sum
        })
    }

    /// Cell `i`'s record.
    #[cfg(test)]
    pub(in crate::transport) fn record(&self, i: usize) -> Record {
        std::array::from_fn(|f| self.data[f * self.len + i])
    }

    /// Cell `i`'s radiance per band.
    pub(in crate::transport) fn radiance(&self, i: usize) -> [f32; 3] {
        [0, 1, 2].map(|band| self.data[(I + band) * self.len + i])
    }
}

/// Upwind density below which a cell's back source is its own instead of the density-weighted
/// mean of its upwind neighbours. The mean ρ·J/ρ loses its bits where ρ·J is subnormal (f32 has
/// 24 bits down to 1.2e-38; the Disney cloud holds densities of 1.7e-37, and the bilinear
/// weights make them smaller still) and 1/ρ overflows to inf below 2.9e-39, so it would be
/// NaN or inf; a density of 1e-30 puts an optical depth below 1e-30·σt·h into the step, which no
/// image can show.
pub(super) const RHO_WEIGHT_MIN: f32 = 1e-30;

/// What a sweep's steps share along one ordinate: the bilinear weights of the four upwind
/// neighbours (offsets 0, 1, `stride`, `stride` + 1 from `up` cells off the cell), the step
/// length `s` (m) and the δ-M extinction σt′ per band (1/m per unit density).
pub(in crate::transport) struct Step {
    pub(in crate::transport) weights: [f32; 4],
    pub(in crate::transport) up: isize,
    pub(in crate::transport) stride: usize,
    pub(in crate::transport) s: f32,
    pub(in crate::transport) sigma_t: [f32; 3],
    /// All bands share σt′ (one set of step weights serves them).
    pub(in crate::transport) grey: bool,
}

/// Step a run of cells of one plane row, [`Vector::N`] at a time: `row` holds their (density,
/// full-voxel index or `u32::MAX`), `ahead` the cells
/// [`PREFETCH_AHEAD`](crate::transport::grid::PREFETCH_AHEAD) further on in the sweep (whose
/// sources are prefetched), and `l0` is the first one's index in the plane buffers. Each cell
/// reads its upwind record in `prev` and its source in `light`, writes its record in `cur` and,
/// if full, its radiance over its source in `light`.
///
/// Panics where the run's upwind records or records lie outside the buffers; a full-voxel
/// index must be below `light.len()` (the callers check it once per solve,
/// [`box_cells`](crate::transport::grid::box_cells)).
#[inline(always)]
pub(in crate::transport) fn step_row<V: Vector>(
    k: &Step,
    prev: &Plane,
    cur: &mut Plane,
    light: &mut [[f32; 3]],
    row: &[(f32, u32)],
    ahead: &[(f32, u32)],
    l0: usize,
) {
    // The loads below reach cells l0 + up .. l0 + n + stride + N of `prev`; the stores cells
    // l0 .. l0 + n of `cur`.
    let n = row.len();
    assert!(ahead.len() >= n && V::N <= LANES);
    assert!(l0 as isize + k.up >= 0 && l0 + n + k.stride < prev.cells() && prev.len == cur.len);
    let w = [V::splat(k.weights[0]), V::splat(k.weights[1]), V::splat(k.weights[2]), V::splat(k.weights[3])];
    let mut start = 0;
    while start < n {
        let m = (n - start).min(V::N);
        let mut rho = [0f32; 8];
        let mut full = [0f32; 8];
        let mut fi = [0usize; 8];
        let mut sc = [[0f32; 8]; 3];
        for j in 0..m {
            let (r, f) = row[start + j];
            // The full voxels' sources and radiances lie a grid row apart in x-major sweeps
            // (past the L2 cache on large boxes): ask for the lines a few cells ahead.
            let fa = ahead[start + j].1;
            if fa != u32::MAX {
                prefetch(light.as_ptr().wrapping_add(fa as usize));
            }
            rho[j] = r;
            if f != u32::MAX {
                full[j] = f32::from_bits(u32::MAX);
                fi[j] = f as usize;
                // SAFETY: a full cell's index is below light.len() (this function's contract).
                let s = unsafe { *light.get_unchecked(f as usize) };
                for band in 0..3 {
                    sc[band][j] = s[band];
                }
            }
        }
        let l = l0 + start;
        let u = (l as isize + k.up) as usize;
        // Radiance and density bilinear; the source (per unit extinction, defined only where
        // ρ > 0) density-weighted, so that empty neighbours do not pull it towards 0 (a uniform
        // source stays uniform: the furnace holds). From 0, the neighbours in order.
        // Loops, not `array::from_fn` or closures: a closure does not inherit the AVX copy's
        // target feature, and where LLVM leaves one outlined every intrinsic in it becomes a call
        // (the solve 3× slower; module docs).
        let mut acc = [V::splat(0.0); FIELDS];
        for (f, sum) in acc.iter_mut().enumerate() {
            let field = prev.data[f * prev.len..].as_ptr();
            for (wk, i) in w.iter().zip([u, u + 1, u + k.stride, u + k.stride + 1]) {
                // SAFETY: u ≥ 0 and u + stride + 1 + N ≤ l0 + n + stride + N ≤ the field's
                // length (the spare cells included), asserted above.
                *sum = sum.add(wk.mul(unsafe { V::load(field.add(i)) }));
            }
        }
        let (rho_v, full_v) = (V::from_array(&rho), V::from_array(&full));
        let sc_v = [V::from_array(&sc[0]), V::from_array(&sc[1]), V::from_array(&sc[2])];
        let out = cells(k, &acc, rho_v, full_v, &sc_v);
        let rs = [rho_v.mul(sc_v[0]), rho_v.mul(sc_v[1]), rho_v.mul(sc_v[2])];
        // A short run's last cells: its m lanes, the buffer's own values in the others.
        let part = m < V::N;
        let keep = V::splat(m as f32).gt(V::from_array(&[0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]));
        for (f, v) in [out[0], out[1], out[2], rho_v, rs[0], rs[1], rs[2]].into_iter().enumerate() {
            // SAFETY: l + N ≤ l0 + n + N ≤ the field's length (the spare cells included),
            // asserted above.
            unsafe {
                let p = cur.data.as_mut_ptr().add(f * cur.len + l);
                let v = if part { V::select(keep, v, V::load(p)) } else { v };
                v.store(p);
            }
        }
        let mut radiance = [[0f32; 8]; 3];
        for (v, lanes) in out.into_iter().zip(&mut radiance) {
            v.to_array(lanes);
        }
        for j in 0..m {
            if full[j].to_bits() != 0 {
                // SAFETY: as the source's load above.
                unsafe { *light.get_unchecked_mut(fi[j]) = [radiance[0][j], radiance[1][j], radiance[2][j]] };
            }
        }
        start += m;
    }
}

/// The cells' step (module docs of [`super`]) from their upwind records `acc`, densities `rho`,
/// whether full (a mask) and sources `sc` (0 where empty): their radiance per band.
#[inline(always)]
fn cells<V: Vector>(k: &Step, acc: &[V; FIELDS], rho: V, full: V, sc: &[V; 3]) -> [V; 3] {
    let rb = acc[RHO];
    let rm = V::splat(0.5).mul(rb.add(rho)).mul(V::splat(k.s));
    let stepping = rm.gt(V::splat(0.0));
    let weighted = rb.gt(V::splat(RHO_WEIGHT_MIN));
    let inv_rb = V::splat(1.0).div(rb);
    let grey = step_weights_lanes(V::splat(k.sigma_t[0]).mul(rm));
    // A loop, not `array::from_fn` (its closure may be left outside the AVX copy: step_row).
    let mut out = [V::splat(0.0); 3];
    for (band, o) in out.iter_mut().enumerate() {
        let (e, wi, wo) = if band == 0 || k.grey {
            grey
        } else {
            step_weights_lanes(V::splat(k.sigma_t[band]).mul(rm))
        };
        let ib = acc[I + band];
        let sb = V::select(weighted, acc[RS + band].mul(inv_rb), sc[band]);
        let se = V::select(full, sc[band], sb);
        let stepped = ib.mul(e).add(wi.mul(sb)).add(wo.mul(se));
        *o = V::select(stepping, stepped, ib);
    }
    out
}

/// Optical lengths below which the step weights are their series (the closed form cancels).
const SERIES_BELOW: f32 = 0.5;

/// (e^{−x}, w_in, w_out) of a step of optical length x ≥ 0 with a source linear in optical path
/// (as the slab solver's, whose f64 form the test checks it against): with m = (1 − e^{−x})/x,
/// w_in = m − e^{−x} and w_out = 1 − m; below [`SERIES_BELOW`] their Taylor series to x⁸,
/// w_out = Σ (−1)^{k+1} x^k/(k+1)!, w_in = Σ (−1)^{k+1} k x^k/(k+1)!.
#[inline(always)]
fn step_weights_lanes<V: Vector>(x: V) -> (V, V, V) {
    let e = exp_neg(x);
    let (series_in, series_out) = (horner(x, &SERIES_IN), horner(x, &SERIES_OUT));
    let mean = V::splat(1.0).sub(e).div(x);
    let (closed_in, closed_out) = (mean.sub(e), V::splat(1.0).sub(mean));
    let series = V::splat(SERIES_BELOW).gt(x);
    (e, V::select(series, series_in, closed_in), V::select(series, series_out, closed_out))
}

/// Σ_k c_k x^{k+1} by Horner's rule.
#[inline(always)]
fn horner<V: Vector>(x: V, c: &[f32; 8]) -> V {
    let mut acc = V::splat(0.0);
    for ck in c.iter().rev() {
        acc = acc.mul(x).add(V::splat(*ck));
    }
    acc.mul(x)
}

/// The coefficients of x, x², …, x⁸ in w_in's and w_out's series ([`step_weights_lanes`]):
/// (−1)^{k+1} k/(k+1)! and (−1)^{k+1}/(k+1)!.
const SERIES_IN: [f32; 8] = [
    1.0 / 2.0,
    -2.0 / 6.0,
    3.0 / 24.0,
    -4.0 / 120.0,
    5.0 / 720.0,
    -6.0 / 5040.0,
    7.0 / 40320.0,
    -8.0 / 362880.0,
];
const SERIES_OUT: [f32; 8] = [
    1.0 / 2.0,
    -1.0 / 6.0,
    1.0 / 24.0,
    -1.0 / 120.0,
    1.0 / 720.0,
    -1.0 / 5040.0,
    1.0 / 40320.0,
    -1.0 / 362880.0,
];

/// [`step_weights_lanes`] of one step.
pub(super) fn step_weights(x: f32) -> (f32, f32, f32) {
    step_weights_lanes(x)
}

/// Optical lengths above which e^{−x} is 0 in [`exp_neg`] (e^{−87} = 1.6e-38, the smallest
/// normal f32 is 1.2e-38).
const EXP_NEG_MAX: f32 = 87.0;

/// e^{−x} per lane for x ≥ 0, within an ulp (0 above [`EXP_NEG_MAX`]): −x = n ln 2 + r with n
/// the nearest integer to −x/ln 2 (by adding and subtracting [`ROUND`]) and ln 2 in two parts
/// (Cody and Waite), e^r by the Cephes `expf` polynomial on |r| ≤ ln 2/2, 2ⁿ from its exponent
/// bits.
#[inline(always)]
fn exp_neg<V: Vector>(x: V) -> V {
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    const P: [f32; 6] = [1.987_569_2e-4, 1.398_199_9e-3, 8.333_452e-3, 4.166_579_6e-2, 1.666_666_5e-1, 0.5];
    let max = V::splat(EXP_NEG_MAX);
    let beyond = x.gt(max);
    let y = V::splat(0.0).sub(V::select(beyond, max, x));
    let t = y.mul(V::splat(std::f32::consts::LOG2_E)).add(V::splat(ROUND));
    let n = t.sub(V::splat(ROUND));
    let r = y.sub(n.mul(V::splat(LN2_HI))).sub(n.mul(V::splat(LN2_LO)));
    let mut p = V::splat(P[0]);
    for c in &P[1..] {
        p = p.mul(r).add(V::splat(*c));
    }
    let er = p.mul(r.mul(r)).add(r).add(V::splat(1.0));
    V::select(beyond, V::splat(0.0), er.mul(V::pow2_of_rounded(t)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_neg_is_within_two_ulp() {
        let mut worst = 0f64;
        for i in 0..=200_000 {
            let x = i as f32 * (EXP_NEG_MAX / 200_000.0);
            let got = exp_neg(x) as f64;
            let want = (-(x as f64)).exp();
            // One ulp of the wanted value (normal f32 down to e^{−87}).
            let ulp = f32::EPSILON as f64 * 2f64.powi(want.log2().floor() as i32);
            worst = worst.max((got - want).abs() / ulp);
        }
        assert!(worst <= 2.0, "{worst} ulp");
        assert_eq!(exp_neg(0f32), 1.0);
        assert_eq!([87.5, 1e30, f32::INFINITY].map(exp_neg), [0.0; 3]);
    }

    #[test]
    fn step_weights_integrate_constants_and_ramps() {
        // Step lengths 10⁻⁶·1.01^i up to 100 and both sides of the series' end.
        let xs = (0..).map(|i| 1e-6f32 * 1.01f32.powi(i)).take_while(|x| *x < 100.0);
        // Largest relative error of e^{−x}, w_in and w_out.
        let mut worst = [0f64; 3];
        for x in xs.chain([SERIES_BELOW, SERIES_BELOW * (1.0 - f32::EPSILON)]) {
            let (e, wi, wo) = step_weights(x);
            assert!(wi > 0.0 && wo > 0.0, "x={x}");
            let xd = x as f64;
            let ed = (-xd).exp();
            // ∫₀ˣ e^{−(x−t)} dt = 1 − e^{−x}; ∫₀ˣ (t/x) e^{−(x−t)} dt = 1 − (1 − e^{−x})/x; below
            // 0.1 their series to x²⁰ (the closed form cancels in f64 too).
            let term = |k: i32, c: f64| (-1f64).powi(k + 1) * c * xd.powi(k) / (1..=k + 1).map(f64::from).product::<f64>();
            let (wid, wod) = if xd < 0.1 {
                ((1..=20).map(|k| term(k, k as f64)).sum(), (1..=20).map(|k| term(k, 1.0)).sum())
            } else {
                ((1.0 - ed) / xd - ed, 1.0 - (1.0 - ed) / xd)
            };
            // e^{−x} is 0 past EXP_NEG_MAX (below the smallest normal f32).
            let ed = if x > EXP_NEG_MAX { 0.0 } else { ed };
            for (w, (got, want)) in worst.iter_mut().zip([(e, ed), (wi, wid), (wo, wod)]) {
                *w = w.max(if want == 0.0 { got as f64 } else { (got as f64 - want).abs() / want });
            }
        }
        // e^{−x} within an ulp; the weights within 4.1e-7 and 2.5e-7 (w_in: m − e^{−x} cancels
        // a few bits where x ≈ SERIES_BELOW).
        assert!(worst[0] < 1.2e-7 && worst[1] < 5e-7 && worst[2] < 3e-7, "(e, w_in, w_out): {worst:?}");
    }
}
