//! 16-bit storage codes for fields that live through a whole render (memory of `full`, issue 16):
//!
//! - [`Bf16`]: the upper half of an f32 (sign, 8-bit exponent, 7 stored mantissa bits), rounded
//!   to nearest, ties to even. f32's whole range, so robust to any irradiance scale (a scene in
//!   W/m² with a real sun); relative rounding ≤ 2⁻⁸ ≈ 0.4 % (half an ulp of 8 significant bits),
//!   unbiased; decoding is one shift. Used for the diffuse field's first moment ρ·I1
//!   ([`crate::diffusion::flux::FluxField`]).
//! - [`Unit16`]: an unsigned float for values in [0, 1] (5-bit exponent, 11-bit mantissa) covering
//!   [2⁻³¹, 1]; relative rounding ≤ 2⁻¹² ≈ 0.024 %, values below 2⁻³¹ ≈ 4.7e-10 read 2⁻³¹;
//!   decoding is a shift and an integer add. Used for the sun transmittance
//!   ([`crate::sunlight::SunTransmittance`]).
//!
//! [`Texel`] is what a [`crate::medium::SubGrid`] stores: f32 itself or a code.

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
}
