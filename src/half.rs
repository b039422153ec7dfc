//! 16-bit storage codes for fields that live through a whole render (docs/performance.md):
//!
//! - [`Bf16`]: the upper half of an f32 (sign, 8-bit exponent, 7 stored mantissa bits), rounded
//!   to nearest, ties to even. f32's whole range, so robust to any irradiance scale (a scene in
//!   W/m² with a real sun); relative rounding ≤ 2⁻⁸ ≈ 0.4 % (half an ulp of 8 significant bits),
//!   unbiased; decoding is one shift. Used for the diffuse field's first moment ρ·I1
//!   ([`crate::diffusion::flux::FluxField`]).
//! - [`Unit16`]: an unsigned float for values in [0, 1] (5-bit exponent, 11-bit mantissa) covering
//!   [2⁻³¹, 1]; relative rounding ≤ 2⁻¹² ≈ 0.024 %, values below 2⁻³¹ ≈ 4.7e-10 read 2⁻³¹;
//!   decoding is a shift and an integer add. Used for the sun transmittance
//!   ([`crate::lit::sunlight::SunTransmittance`]).
//! - [`Signed16`]: a signed float for values relative to a power-of-two scale, |y| < 2 (sign,
//!   4-bit exponent, 11-bit mantissa, with subnormals): relative rounding ≤ 2⁻¹² for
//!   |y| ≥ 2⁻¹⁴, absolute ≤ 2⁻²⁶ below; decoding is a shift, an or of the sign and a multiply by
//!   2¹¹² (no branch). [`crate::medium::field16::Field16`] holds one per full voxel with the field's scale 2ᵏ chosen from
//!   its largest magnitude, so any irradiance scale fits: relative ≤ 2⁻¹² for every value above
//!   2⁻¹³ of the largest, absolute ≤ 2⁻²⁵ of the largest below. Used for the diffusion's I0
//!   ([`crate::diffusion::DiffusionSolution::i0`]), which is slightly negative on sunlit faces.
//! - [`Scaled16`]: an unsigned float (5-bit exponent, 11-bit mantissa) under a power-of-two scale
//!   2^k chosen per field from its largest value; code 0 is exactly 0. Relative rounding ≤ 2⁻¹²,
//!   values more than ~2³⁰ below the field's largest read 0; decoding is a shift and a multiply
//!   by the scale. Used for the multigrid's couplings and row sums
//!   ([`crate::diffusion::multigrid`]).
//!
//! [`Texel`] is what a [`crate::medium::SubGrid`] stores: f32 itself or a code.

use crate::par;

/// A value stored in a grid: encoded once from f32, decoded at every read.
pub trait Texel: Copy + Send + Sync + PartialEq + std::fmt::Debug + 'static {
    /// The stored form of `v` (rounded to the nearest representable value).
    fn encode(v: f32) -> Self;
    /// The value stored.
    fn decode(self) -> f32;
}

impl Texel for f32 {
    #[inline(always)]
    fn encode(v: f32) -> f32 {
        v
    }
    #[inline(always)]
    fn decode(self) -> f32 {
        self
    }
}

/// bfloat16: an f32 without its lower 16 mantissa bits (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Bf16(u16);

impl Bf16 {
    /// Zero.
    pub const ZERO: Bf16 = Bf16(0);

    /// `v` rounded to nearest, ties to even. Finite values stay finite: one that would round
    /// beyond f32::MAX saturates to the largest finite bf16 (the rounding carry would otherwise
    /// reach the infinity pattern). NaN stays NaN (quiet).
    #[inline]
    pub fn from_f32(v: f32) -> Bf16 {
        let b = v.to_bits();
        if v.is_nan() {
            return Bf16(((b >> 16) as u16) | 0x0040);
        }
        // Add 0x7fff plus the lowest kept bit: a half-way tail rounds to the even neighbour.
        let rounded = b.wrapping_add(0x7fff + ((b >> 16) & 1)) >> 16;
        let r = rounded as u16;
        if v.is_finite() && (r & 0x7f80) == 0x7f80 {
            // Rounded up into the infinity pattern: the largest finite bf16 of that sign.
            return Bf16((r & 0x8000) | 0x7f7f);
        }
        Bf16(r)
    }

    /// The f32 it stands for (exact: every bf16 is an f32).
    #[inline(always)]
    pub fn to_f32(self) -> f32 {
        f32::from_bits((self.0 as u32) << 16)
    }
}

/// The exponent offset of [`Unit16`] in f32 bits: the code's exponent 0 is 2⁻³¹, f32's 96.
const UNIT_BIAS: u32 = 96 << 23;
/// The smallest value [`Unit16`] holds, 2⁻³¹ (code 0).
pub const UNIT16_MIN: f32 = 1.0 / 2_147_483_648.0;

/// An unsigned float for transmittances (module docs): code = (f32 bits − 96·2²³) / 2¹², i.e. a
/// 5-bit exponent (2⁻³¹ … 2⁰) and the f32's upper 11 mantissa bits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Unit16(u16);

impl Unit16 {
    /// `v` clamped to [2⁻³¹, 1] (NaN reads 2⁻³¹), rounded to nearest, ties to even.
    #[inline]
    pub fn from_f32(v: f32) -> Unit16 {
        // NaN compares false and takes the lower end.
        let b = if v >= UNIT16_MIN { v.min(1.0) } else { UNIT16_MIN }.to_bits();
        let rounded = (b + 0x7ff + ((b >> 12) & 1)) >> 12;
        // 1.0 rounds to itself, so the code stays ≤ 31·2¹¹ (no overflow of the 5-bit exponent).
        Unit16((rounded - (UNIT_BIAS >> 12)) as u16)
    }

    /// The value it stands for: a shift and an add of the exponent offset.
    #[inline(always)]
    pub fn to_f32(self) -> f32 {
        f32::from_bits(((self.0 as u32) << 12) + UNIT_BIAS)
    }
}

impl Texel for Unit16 {
    #[inline(always)]
    fn encode(v: f32) -> Unit16 {
        Unit16::from_f32(v)
    }
    #[inline(always)]
    fn decode(self) -> f32 {
        self.to_f32()
    }
}

/// The exponent offset of [`Signed16`] in f32 bits: the code's exponent 1 is 2⁻¹⁴ (f32's 113).
const SIGNED_BIAS: u32 = 112 << 23;
/// The smallest normal magnitude of [`Signed16`], 2⁻¹⁴; below it the codes are subnormal.
const SIGNED_MIN_NORMAL: f32 = 1.0 / 16384.0;
/// The step of [`Signed16`]'s subnormal range (and of its lowest normal binade), 2⁻²⁵.
const SIGNED_TINY: f32 = 1.0 / 33_554_432.0;
/// 2¹¹², from f32's exponent bias (127) to the code's (15).
const SIGNED_UNBIAS: f32 = 5.192_297e33;
/// The largest magnitude code: (2 − 2⁻¹¹).
const SIGNED_MAX_MAG: u32 = 0x7fff;

/// A signed float for values relative to a scale (module docs): bit 15 the sign, then a 4-bit
/// exponent e and an 11-bit mantissa f; |y| = (1 + f/2¹¹)·2^(e−15) for e ≥ 1 (2⁻¹⁴ … 2 − 2⁻¹¹),
/// f·2⁻²⁵ for e = 0.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Signed16(u16);

impl Signed16 {
    /// `y` rounded to nearest, ties to even, the sign kept; magnitudes from 2 − 2⁻¹² up
    /// (infinity too) saturate to 2 − 2⁻¹¹; NaN reads 0.
    #[inline]
    pub fn from_f32(y: f32) -> Signed16 {
        if y.is_nan() {
            return Signed16(0);
        }
        let sign = ((y.to_bits() >> 16) & 0x8000) as u16;
        let a = y.abs();
        let mag = if a < SIGNED_MIN_NORMAL {
            // a / 2⁻²⁵ < 2¹¹ is exact in f32; rounding to the integer is the code's rounding.
            (a / SIGNED_TINY).round_ties_even() as u32
        } else {
            let b = a.to_bits();
            // Infinity's bits (0x7f80_0000) plus the carry stay far below u32::MAX.
            (((b + 0x7ff + ((b >> 12) & 1)) >> 12) - (SIGNED_BIAS >> 12)).min(SIGNED_MAX_MAG)
        };
        Signed16(sign | mag as u16)
    }

    /// The value it stands for, without a branch: the code's bits placed in an f32 read
    /// (1 + f/2¹¹)·2^(e−127) for e ≥ 1 and, as an f32 subnormal, f·2⁻¹¹·2⁻¹²⁶ for e = 0; times
    /// 2¹¹² (exact) both are the code's values.
    #[inline(always)]
    pub fn to_f32(self) -> f32 {
        let c = u32::from(self.0);
        f32::from_bits(((c & SIGNED_MAX_MAG) << 12) | ((c & 0x8000) << 16)) * SIGNED_UNBIAS
    }
}

/// k with 2ᵏ ≤ `max` < 2ᵏ⁺¹, raised by one where `max`·2⁻ᵏ would round to 2 (saturating), and
/// kept where f32 holds 2ᵏ and 2⁻ᵏ as normal numbers; 0 for a zero or non-finite `max`.
fn scale_exponent(max: f64) -> i32 {
    if !(max.is_finite() && max > 0.0) {
        return 0;
    }
    let k = max.log2().floor() as i32;
    // log2 may be off by one ulp at powers of two: correct with the exact powers.
    let k = if 2f64.powi(k) > max {
        k - 1
    } else if 2f64.powi(k + 1) <= max {
        k + 1
    } else {
        k
    };
    let k = if max * 2f64.powi(-k) >= 2.0 - 1.0 / 4096.0 { k + 1 } else { k };
    k.clamp(-125, 125)
}

impl Signed16 {
    /// `values` relative to the scale 2ᵏ of [`Field16`] (returned): each scaled exactly in f64,
    /// rounded to f32, then to the code (the bound stays 2⁻¹²: the f32 step, 2⁻²⁴, is within
    /// the slack of the code's half step).
    pub fn code_all<T: Copy + Into<f64> + Sync>(values: &[T]) -> (Vec<Signed16>, f32) {
        code_after(values, 0)
    }
}

/// The value relative to its scale (what the diffusion solver reads of a coded right-hand side).
impl From<Signed16> for f64 {
    #[inline(always)]
    fn from(c: Signed16) -> f64 {
        f64::from(c.to_f32())
    }
}

/// The scale 2ᵏ [`Field16`](crate::medium::field16::Field16) and [`Signed16::code_all`] choose for values of largest magnitude
/// `max` (1 for 0): codes of v·2⁻ᵏ are within 2⁻¹² relative of every value above 2⁻¹³·`max`.
pub fn power_of_two_scale(max: f64) -> f32 {
    2f32.powi(scale_exponent(max))
}

/// [`Signed16::code_all`] after `lead` zero codes.
pub(crate) fn code_after<T: Copy + Into<f64> + Sync>(values: &[T], lead: usize) -> (Vec<Signed16>, f32) {
    // The largest magnitude per chunk, then of the chunks' (a maximum is exact in any order).
    let chunk_max = par::map_range(values.len().div_ceil(par::CHUNK), &|ci| {
        values[ci * par::CHUNK..].iter().take(par::CHUNK).fold(0.0, |m: f64, v| m.max((*v).into().abs()))
    });
    let k = scale_exponent(chunk_max.into_iter().fold(0.0, f64::max));
    let inv = 2f64.powi(-k);
    let mut codes = vec![Signed16(0); values.len() + lead];
    par::for_chunks(&mut codes[lead..], par::CHUNK, &|ci, codes| {
        for (c, v) in codes.iter_mut().zip(&values[ci * par::CHUNK..]) {
            *c = Signed16::from_f32(((*v).into() * inv) as f32);
        }
    });
    (codes, 2f32.powi(k))
}

/// f32 bits of [`Scaled16`]'s codes: code c is the f32 whose bits are c·2¹², so its exponent
/// field is 0 … 31 (f32's lowest binades, 2⁻¹²⁶ … 2⁻⁹⁵) and its upper 11 mantissa bits are kept.
const SCALED_SHIFT: u32 = 12;

/// The largest scale exponent of [`Scaled16::wide_exponent_for`]: f32's largest values (below
/// 2¹²⁸) land in exponent field 30 under it.
const WIDE_TOP: i32 = 127 + 97;

/// An unsigned float for a field of values ≥ 0 under a power-of-two scale 2^k per field (the
/// multigrid's couplings and row sums, whose magnitudes depend on the voxel size and density):
/// the code of v is the f32 v·2⁻ᵏ shifted right by 12 bits, rounded to nearest (ties to even)
/// at its 11th mantissa bit, so decoding is one shift and one multiply by 2^k.
///
/// * **Scale:** [`Scaled16::exponent_for`] picks k so that the field's largest value lands in
///   f32's exponent field 30 (v·2⁻ᵏ in [2⁻⁹⁷, 2⁻⁹⁶): its rounding cannot carry out of the code).
/// * **Range:** codes with exponent fields 1 … 31, v·2⁻ᵏ in [2⁻¹²⁶, 2⁻⁹⁵): every value from
///   2⁻²⁹ of the field's largest up is kept to ≤ 2⁻¹² relative (half an ulp of 12 significant
///   bits); smaller ones (and negative ones, and NaN) read 0, an absolute error below 2⁻²⁹ of
///   the largest. Exponent field 0 (f32's subnormals, slow to multiply) is never coded but by 0.
/// * **Zero** is code 0, decoded exactly (0·2^k).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Scaled16(u16);

impl Scaled16 {
    /// Zero.
    pub const ZERO: Scaled16 = Scaled16(0);

    /// The scale exponent k for a field whose largest value is `max` (> 0): `max`·2⁻ᵏ in
    /// [2⁻⁹⁷, 2⁻⁹⁶). Clamped to −126 … 127, where 2^k is a normal f32 (`max` from ~2⁻²²³ to 2³¹:
    /// larger values then saturate, smaller ones read 0); 0 for a field of zeros (or NaN).
    pub fn exponent_for(max: f64) -> i32 {
        if !(max > 0.0 && max.is_finite()) {
            return 0;
        }
        // ⌊log2 max⌋ from the f64's exponent field (a subnormal counts as 2⁻¹⁰²³; clamped anyway).
        let e = ((max.to_bits() >> 52) & 0x7ff) as i32 - 1023;
        (e + 97).clamp(-126, 127)
    }

    /// [`Scaled16::exponent_for`] without its top: k up to 127 + 97, so the largest value of a
    /// field of any finite f32 values (up to 2¹²⁸) still lands in exponent field 30 instead of
    /// saturating above 2³¹. A k above 127 is beyond one f32 scale: decode under
    /// [`Scaled16::split_scale`]'s two factors.
    pub fn wide_exponent_for(max: f64) -> i32 {
        if !(max > 0.0 && max.is_finite()) {
            return 0;
        }
        let e = ((max.to_bits() >> 52) & 0x7ff) as i32 - 1023;
        (e + 97).clamp(-126, WIDE_TOP)
    }

    /// 2^k for k in −126 … 127 + 97 as two normal f32 factors, [2^min(k, 127), 2^max(k − 127, 0)]:
    /// a code's value is `decode(first) · second`, exact (a code's f32 under the first factor is
    /// a normal number, and both are powers of two). The second is 1 wherever
    /// [`Scaled16::exponent_for`] would have done.
    pub fn split_scale(k: i32) -> [f32; 2] {
        let k = k.clamp(-126, WIDE_TOP);
        [Scaled16::scale(k), Scaled16::scale(k - k.min(127))]
    }

    /// 2^k as an f32, for k in −126 … 127 (the decoding scale).
    pub fn scale(k: i32) -> f32 {
        let k = k.clamp(-126, 127);
        f32::from_bits(((k + 127) as u32) << 23)
    }

    /// `v` under scale 2^k, rounded to nearest, ties to even (type docs; k from
    /// [`Scaled16::exponent_for`] or [`Scaled16::wide_exponent_for`]). Values beyond the code's
    /// top, (2 − 2⁻¹¹)·2^(k−96) (only when k was not chosen from them), saturate there.
    pub fn encode(v: f64, k: i32) -> Scaled16 {
        // v·2⁻ᵏ is exact in f64; round it to 12 significant bits there (41 of f64's 52 stored
        // mantissa bits dropped), then the f32 is exact.
        let x = v * f64::from_bits(((1023 - k.clamp(-126, WIDE_TOP)) as u64) << 52);
        if x.is_nan() || x <= 0.0 {
            return Scaled16::ZERO;
        }
        let b = x.to_bits();
        let rounded = f64::from_bits((b + (1 << 40) - 1 + ((b >> 41) & 1)) & !((1u64 << 41) - 1));
        let f = rounded as f32;
        if f < f32::MIN_POSITIVE {
            return Scaled16::ZERO;
        }
        Scaled16(u16::try_from(f.to_bits() >> SCALED_SHIFT).unwrap_or(u16::MAX))
    }

    /// The value it stands for under the scale `scale` (2^k from [`Scaled16::scale`], or −2^k
    /// for a field stored negated): a shift and a multiply, exact (12 significant bits times a
    /// power of two).
    #[inline(always)]
    pub fn decode(self, scale: f32) -> f32 {
        f32::from_bits(u32::from(self.0) << SCALED_SHIFT) * scale
    }

    /// Four codes decoded at once, each under its scale ([`Scaled16::decode`]): on x86-64 one
    /// widening, one shift and one multiply of four SSE2 lanes (lane by lane, the compiler kept
    /// four scalar shifts and multiplies: +2 % of `full`'s instructions).
    #[inline(always)]
    pub fn decode4(c: [Scaled16; 4], scale: [f32; 4]) -> [f32; 4] {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{_mm_castsi128_ps, _mm_loadu_ps, _mm_mul_ps, _mm_set_epi32, _mm_slli_epi32, _mm_storeu_ps};
            let mut out = [0.0; 4];
            // SAFETY: SSE2 is part of x86-64; the loads and the store are of four f32.
            unsafe {
                let w = _mm_set_epi32(i32::from(c[3].0), i32::from(c[2].0), i32::from(c[1].0), i32::from(c[0].0));
                let f = _mm_castsi128_ps(_mm_slli_epi32::<{ SCALED_SHIFT as i32 }>(w));
                _mm_storeu_ps(out.as_mut_ptr(), _mm_mul_ps(f, _mm_loadu_ps(scale.as_ptr())));
            }
            out
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            std::array::from_fn(|i| c[i].decode(scale[i]))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Rng;

    #[test]
    fn bf16_round_trips_its_own_values_and_rounds_to_nearest_even() {
        for v in [0.0f32, -0.0, 1.0, -1.0, 0.5, 3.0, -96.0, 1.5 * f32::MIN_POSITIVE, f32::MIN_POSITIVE] {
            assert_eq!(Bf16::from_f32(v).to_f32().to_bits(), v.to_bits(), "{v}");
        }
        // 1 + 2⁻⁸ is half-way between 1 and 1 + 2⁻⁷: ties go to the even mantissa (1).
        assert_eq!(Bf16::from_f32(1.0 + 1.0 / 256.0).to_f32(), 1.0);
        // 1 + 3·2⁻⁸ is half-way between 1 + 2⁻⁷ and 1 + 2⁻⁶: ties go to 1 + 2⁻⁶.
        assert_eq!(Bf16::from_f32(1.0 + 3.0 / 256.0).to_f32(), 1.0 + 1.0 / 64.0);
        // Just above half-way rounds up, just below rounds down.
        let up = f32::from_bits((1.0f32 + 1.0 / 256.0).to_bits() + 1);
        assert_eq!(Bf16::from_f32(up).to_f32(), 1.0 + 1.0 / 128.0);
        let down = f32::from_bits((1.0f32 + 1.0 / 256.0).to_bits() - 1);
        assert_eq!(Bf16::from_f32(down).to_f32(), 1.0);
        assert_eq!(Bf16::from_f32(-down).to_f32(), -1.0, "symmetric in the sign");
    }

    #[test]
    fn bf16_error_is_within_half_an_ulp_and_finite_stays_finite() {
        let mut rng = Rng::new(5, 1);
        for _ in 0..100_000 {
            // Magnitudes from 1e-30 to 1e30, both signs.
            let v = (rng.uniform() * 138.0 - 69.0).exp() * if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
            let r = Bf16::from_f32(v).to_f32();
            assert!((r - v).abs() <= v.abs() / 256.0, "{v} → {r}");
            assert_eq!(r.is_sign_negative(), v.is_sign_negative());
        }
        // The range ends: f32::MAX would round up to infinity; it saturates instead.
        for v in [f32::MAX, -f32::MAX, 3.4e38, -3.39e38] {
            let r = Bf16::from_f32(v).to_f32();
            assert!(
                r.is_finite() && r.signum() == v.signum() && (r - v).abs() <= v.abs() / 128.0,
                "{v} → {r}"
            );
        }
        assert_eq!(Bf16::from_f32(f32::INFINITY).to_f32(), f32::INFINITY);
        assert!(Bf16::from_f32(f32::NAN).to_f32().is_nan());
        // Subnormals keep their upper bits (absolute error below f32's smallest normal).
        let tiny = f32::MIN_POSITIVE / 3.0;
        assert!((Bf16::from_f32(tiny).to_f32() - tiny).abs() < 1e-40);
        assert_eq!(Bf16::ZERO.to_f32(), 0.0);
    }

    #[test]
    fn unit16_covers_zero_to_one_within_its_rounding() {
        assert_eq!(Unit16::from_f32(1.0).to_f32(), 1.0);
        assert_eq!(Unit16::from_f32(0.5).to_f32(), 0.5);
        assert_eq!(Unit16::from_f32(UNIT16_MIN).to_f32(), UNIT16_MIN);
        // Below the range (0 included) and NaN read the smallest value; above, 1.
        for v in [0.0, -0.0, 1e-20, -3.0, f32::NAN, f32::NEG_INFINITY] {
            assert_eq!(Unit16::from_f32(v).to_f32(), UNIT16_MIN, "{v}");
        }
        for v in [1.0 + 1e-7, 2.0, f32::INFINITY] {
            assert_eq!(Unit16::from_f32(v).to_f32(), 1.0, "{v}");
        }
        // Ties to even: 1 − 2⁻¹³ is half-way between 1 − 2⁻¹² and 1 (even mantissa 0 → 1).
        assert_eq!(Unit16::from_f32(1.0 - 1.0 / 8192.0).to_f32(), 1.0);
        let mut rng = Rng::new(9, 4);
        let mut worst = 0f32;
        for _ in 0..100_000 {
            let v = (-21.0 * rng.uniform()).exp();
            let r = Unit16::from_f32(v).to_f32();
            worst = worst.max((r - v).abs() / v);
            assert!((0.0..=1.0).contains(&r));
        }
        assert!(worst <= 1.0 / 4096.0 && worst > 1.0 / 8192.0, "relative error {worst}");
        // Monotonic: a larger transmittance never reads smaller.
        let mut last = 0.0;
        for k in 0..=4000 {
            let r = Unit16::from_f32(k as f32 / 4000.0).to_f32();
            assert!(r >= last);
            last = r;
        }
    }

    #[test]
    fn signed16_round_trips_its_values_keeps_the_sign_and_rounds_to_nearest_even() {
        let tiny = SIGNED_TINY;
        for v in [
            0.0f32,
            1.0,
            -1.0,
            0.5,
            -1.5,
            2.0 - 1.0 / 2048.0,
            SIGNED_MIN_NORMAL,
            -SIGNED_MIN_NORMAL,
            tiny,
            -7.0 * tiny,
            2047.0 * tiny,
        ] {
            assert_eq!(Signed16::from_f32(v).to_f32(), v, "{v}");
        }
        // −0 keeps its sign bit and reads zero.
        assert_eq!(Signed16::from_f32(-0.0).to_f32(), 0.0);
        // 1 + 2⁻¹² is half-way between 1 and 1 + 2⁻¹¹: ties go to the even mantissa (1); 1 + 3·2⁻¹²
        // to 1 + 2⁻¹⁰.
        assert_eq!(Signed16::from_f32(1.0 + 1.0 / 4096.0).to_f32(), 1.0);
        assert_eq!(Signed16::from_f32(-(1.0 + 3.0 / 4096.0)).to_f32(), -(1.0 + 1.0 / 1024.0));
        // In the subnormal range: 2.5 steps round to 2, 3.5 to 4.
        assert_eq!(Signed16::from_f32(2.5 * tiny).to_f32(), 2.0 * tiny);
        assert_eq!(Signed16::from_f32(-3.5 * tiny).to_f32(), -4.0 * tiny);
        // The largest magnitude saturates, infinity too; NaN reads 0.
        let top = 2.0 - 1.0 / 2048.0;
        for (v, want) in [
            (1.9999, top),
            (2.0, top),
            (-5.0, -top),
            (f32::INFINITY, top),
            (f32::NEG_INFINITY, -top),
        ] {
            assert_eq!(Signed16::from_f32(v).to_f32(), want, "{v}");
        }
        assert_eq!(Signed16::from_f32(f32::NAN).to_f32(), 0.0);
    }

    #[test]
    fn signed16_decodes_every_code_as_its_definition() {
        assert_eq!(SIGNED_UNBIAS, 2f32.powi(112));
        for c in 0..=u16::MAX {
            let (m, neg) = (u32::from(c) & SIGNED_MAX_MAG, c & 0x8000 != 0);
            let (e, f) = ((m >> 11) as i32, (m & 0x7ff) as f64);
            let mag = if e == 0 {
                f * 2f64.powi(-25)
            } else {
                (1.0 + f / 2048.0) * 2f64.powi(e - 15)
            };
            let want = if neg { -mag } else { mag };
            let got = Signed16(c).to_f32();
            assert_eq!(f64::from(got), want, "code {c:#x}");
            assert_eq!(got.is_sign_negative(), neg, "code {c:#x}");
            // Every code encodes back to itself (−0 aside, which reads as 0 too).
            if m != 0 {
                assert_eq!(Signed16::from_f32(got), Signed16(c), "code {c:#x}");
            }
        }
    }

    #[test]
    fn signed16_error_is_within_its_bounds_and_monotonic() {
        let mut rng = Rng::new(3, 8);
        let mut worst = 0f32;
        for _ in 0..200_000 {
            // Magnitudes from 2⁻³⁰ to 2, both signs.
            let a = (-30.0 * rng.uniform() * std::f32::consts::LN_2).exp() * (2.0 - 1.0 / 4096.0);
            let v = if rng.uniform() < 0.5 { -a } else { a };
            let r = Signed16::from_f32(v).to_f32();
            assert_eq!(r.is_sign_negative(), v.is_sign_negative(), "{v} → {r}");
            if a >= SIGNED_MIN_NORMAL {
                worst = worst.max((r - v).abs() / a);
            } else {
                assert!((r - v).abs() <= SIGNED_TINY / 2.0, "{v} → {r}");
            }
        }
        assert!(worst <= 1.0 / 4096.0 && worst > 1.0 / 8192.0, "relative error {worst}");
        let mut last = -2.0;
        for k in -40_000..=40_000 {
            let r = Signed16::from_f32(k as f32 / 20_000.0).to_f32();
            assert!(r >= last, "{k}");
            last = r;
        }
    }

    #[test]
    fn scaled16_rounds_to_nearest_within_its_range_and_keeps_zero() {
        // Fields whose largest value spans f32's range and beyond (couplings of mm to km voxels).
        for max in [3.7e-30, 1.0, 0.5, 6.6, 1.0 - 1e-12, 2.0e9] {
            let k = Scaled16::exponent_for(max);
            let s = Scaled16::scale(k);
            // The largest value sits in exponent field 30: its code has room for the carry.
            let top = Scaled16::encode(max, k);
            assert!(top.0 >> 11 == 30 || top.0 == 31 << 11, "{max}: code {:#x}", top.0);
            assert_eq!(Scaled16::encode(0.0, k).decode(s), 0.0);
            assert_eq!(Scaled16::ZERO.decode(-s).abs(), 0.0);
            let mut rng = Rng::new(13, 2);
            let mut worst = 0f64;
            for _ in 0..50_000 {
                // From the largest value down to 2⁻²⁹ of it: kept to half an ulp of 12 bits.
                let v = max * (-29.0 * std::f64::consts::LN_2 * rng.uniform() as f64).exp();
                let r = f64::from(Scaled16::encode(v, k).decode(s));
                worst = worst.max((r - v).abs() / v);
                assert!(r > 0.0, "{v} of {max} lost");
            }
            assert!(worst <= 1.0 / 4096.0 && worst > 1.0 / 8192.0, "{max}: relative error {worst}");
            // Far below the range: 0 (an absolute error below 2⁻²⁹ of the largest).
            for v in [max * 2f64.powi(-31), max * 1e-12, -max, f64::NAN] {
                assert_eq!(Scaled16::encode(v, k).decode(s), 0.0, "{v} of {max}");
            }
            // Stored negated (couplings ≤ 0): the same magnitude, negative.
            assert_eq!(Scaled16::encode(max, k).decode(-s), -Scaled16::encode(max, k).decode(s));
        }
        // Four at once: the same values, bit for bit.
        let (codes, scales) = ([3u16, 0, 0xf7ff, 0x1234].map(Scaled16), [0.5f32, -2.0, 8.0, -1e30]);
        let one_by_one: [f32; 4] = std::array::from_fn(|i| codes[i].decode(scales[i]));
        assert_eq!(Scaled16::decode4(codes, scales).map(f32::to_bits), one_by_one.map(f32::to_bits));
        // Ties to even: 1 + 2⁻¹² lies half-way between 1 and 1 + 2⁻¹¹ (mantissa 0 is even).
        let k = Scaled16::exponent_for(1.5);
        assert_eq!(Scaled16::encode(1.0 + 1.0 / 4096.0, k).decode(Scaled16::scale(k)), 1.0);
        assert_eq!(
            Scaled16::encode(1.0 + 3.0 / 4096.0, k).decode(Scaled16::scale(k)),
            1.0 + 1.0 / 1024.0
        );
        // Powers of two and the field's own values round-trip exactly.
        for v in [1.0, 0.25, 1.0 + 1.0 / 2048.0, 2f64.powi(-29)] {
            assert_eq!(f64::from(Scaled16::encode(v, k).decode(Scaled16::scale(k))), v);
        }
        // Monotonic, and above the top it saturates (finite).
        let mut last = 0.0;
        for i in 0..=5000 {
            let r = Scaled16::encode(i as f64 / 2500.0, k).decode(Scaled16::scale(k));
            assert!(r >= last);
            last = r;
        }
        assert!(Scaled16::encode(1e30, k).decode(Scaled16::scale(k)).is_finite());
        // A field of zeros takes k = 0; the scale stays a normal f32 at the ends.
        assert_eq!(Scaled16::exponent_for(0.0), 0);
        assert_eq!(Scaled16::scale(Scaled16::exponent_for(1e300)), 2f32.powi(127));
        assert_eq!(Scaled16::scale(Scaled16::exponent_for(1e-300)), 2f32.powi(-126));
    }

    /// Fields whose largest value is above 2³² (ρ·I0 of light brighter than ~4e9 W·m⁻²·sr⁻¹):
    /// one f32 scale saturates them ([`Scaled16::exponent_for`] stops at 127); the wide exponent
    /// under its two factors keeps them to 2⁻¹² up to f32's largest, and below 2³¹ it is the same
    /// scale with a second factor of 1.
    #[test]
    fn scaled16_wide_scale_keeps_fields_up_to_f32s_largest() {
        for max in [1e10f64, 1e20, 1e30, 3e38] {
            let one = Scaled16::exponent_for(max);
            let saturated = Scaled16::encode(max, one).decode(Scaled16::scale(one));
            assert!(f64::from(saturated) < 0.5 * max, "{max}: one scale reads {saturated}");
            let k = Scaled16::wide_exponent_for(max);
            let [first, second] = Scaled16::split_scale(k);
            let mut rng = Rng::new(5, 1);
            for _ in 0..10_000 {
                let v = max * (-29.0 * std::f64::consts::LN_2 * rng.uniform() as f64).exp();
                let r = f64::from(Scaled16::encode(v, k).decode(first) * second);
                assert!((r - v).abs() <= v / 4096.0, "{v} of {max}: {r}");
            }
            assert_eq!(Scaled16::ZERO.decode(first) * second, 0.0);
        }
        for max in [1e-30, 1.0, 2.0e9] {
            let k = Scaled16::wide_exponent_for(max);
            assert_eq!(k, Scaled16::exponent_for(max));
            assert_eq!(Scaled16::split_scale(k), [Scaled16::scale(k), 1.0]);
        }
    }
}
