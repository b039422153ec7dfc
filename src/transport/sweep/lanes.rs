//! The lane arithmetic a sweep's row step ([`super::step`]) is written in: eight f32 lanes in
//! one AVX register ([`Avx`]), in two SSE2 registers ([`Sse2`], every x86-64 processor), or one
//! lane as a plain `f32`. Each operation is the one IEEE f32 operation per lane (no fused
//! multiply-add, no approximate reciprocal), so the three give the same bits.

/// A vector of [`Vector::N`] f32 lanes. A mask is a vector whose lanes are all ones (true) or all
/// zeros (false).
pub(super) trait Vector: Copy {
    /// Lanes per vector.
    const N: usize;
    fn splat(x: f32) -> Self;
    /// The first [`Vector::N`] values of `a`.
    fn from_array(a: &[f32; 8]) -> Self;
    /// The lanes into the first [`Vector::N`] values of `out`.
    fn to_array(self, out: &mut [f32; 8]);
    /// Lanes `p` .. `p` + [`Vector::N`].
    ///
    /// # Safety
    ///
    /// They must be readable.
    unsafe fn load(p: *const f32) -> Self;
    /// The lanes into `p` .. `p` + [`Vector::N`].
    ///
    /// # Safety
    ///
    /// They must be writable.
    unsafe fn store(self, p: *mut f32);
    fn add(self, o: Self) -> Self;
    fn sub(self, o: Self) -> Self;
    fn mul(self, o: Self) -> Self;
    fn div(self, o: Self) -> Self;
    /// The mask of self > o.
    fn gt(self, o: Self) -> Self;
    /// Per lane, `a` where `mask` is true, else `b`.
    fn select(mask: Self, a: Self, b: Self) -> Self;
    /// 2ⁿ per lane from t = n + 1.5·2²³ (n an integer in −126..=127): its exponent field n + 127
    /// built from t's low mantissa bits.
    fn pow2_of_rounded(t: Self) -> Self;
}

/// 1.5·2²³: adding it rounds an f32 of magnitude below 2²² to an integer, held in the sum's low
/// mantissa bits (two's complement).
pub(super) const ROUND: f32 = 12_582_912.0;

/// The exponent field's bits of 2ⁿ from the bits of n + [`ROUND`].
#[inline(always)]
fn pow2_bits(t: u32) -> u32 {
    t.wrapping_sub(ROUND.to_bits()).wrapping_add(127) << 23
}

impl Vector for f32 {
    const N: usize = 1;
    #[inline(always)]
    fn splat(x: f32) -> f32 {
        x
    }
    #[inline(always)]
    fn from_array(a: &[f32; 8]) -> f32 {
        a[0]
    }
    #[inline(always)]
    fn to_array(self, out: &mut [f32; 8]) {
        out[0] = self;
    }
    #[inline(always)]
    unsafe fn load(p: *const f32) -> f32 {
        // SAFETY: the caller's contract.
        unsafe { *p }
    }
    #[inline(always)]
    unsafe fn store(self, p: *mut f32) {
        // SAFETY: the caller's contract.
        unsafe { *p = self };
    }
    #[inline(always)]
    fn add(self, o: f32) -> f32 {
        self + o
    }
    #[inline(always)]
    fn sub(self, o: f32) -> f32 {
        self - o
    }
    #[inline(always)]
    fn mul(self, o: f32) -> f32 {
        self * o
    }
    #[inline(always)]
    fn div(self, o: f32) -> f32 {
        self / o
    }
    #[inline(always)]
    fn gt(self, o: f32) -> f32 {
        f32::from_bits(if self > o { u32::MAX } else { 0 })
    }
    #[inline(always)]
    fn select(mask: f32, a: f32, b: f32) -> f32 {
        if mask.to_bits() != 0 {
            a
        } else {
            b
        }
    }
    #[inline(always)]
    fn pow2_of_rounded(t: f32) -> f32 {
        f32::from_bits(pow2_bits(t.to_bits()))
    }
}

#[cfg(target_arch = "x86_64")]
pub(super) use x86::{Avx, Sse2};

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::{Vector, ROUND};
    use std::arch::x86_64::*;

    /// Eight lanes in two SSE2 registers (x86-64's baseline).
    #[derive(Clone, Copy)]
    pub(in crate::transport::sweep) struct Sse2(__m128, __m128);

    impl Sse2 {
        #[inline(always)]
        fn map2(self, o: Sse2, f: impl Fn(__m128, __m128) -> __m128) -> Sse2 {
            Sse2(f(self.0, o.0), f(self.1, o.1))
        }
    }

    /// 2ⁿ's bits from n + [`ROUND`]'s, per lane of four.
    #[inline(always)]
    fn pow2_sse2(t: __m128) -> __m128 {
        // SAFETY: x86-64 always has SSE2.
        unsafe {
            let bias = _mm_set1_epi32(127i32.wrapping_sub(ROUND.to_bits() as i32));
            _mm_castsi128_ps(_mm_slli_epi32::<23>(_mm_add_epi32(_mm_castps_si128(t), bias)))
        }
    }

    impl Vector for Sse2 {
        const N: usize = 8;
        #[inline(always)]
        fn splat(x: f32) -> Sse2 {
            // SAFETY: x86-64 always has SSE2.
            unsafe { Sse2(_mm_set1_ps(x), _mm_set1_ps(x)) }
        }
        #[inline(always)]
        fn from_array(a: &[f32; 8]) -> Sse2 {
            // SAFETY: eight readable lanes.
            unsafe { Sse2::load(a.as_ptr()) }
        }
        #[inline(always)]
        fn to_array(self, out: &mut [f32; 8]) {
            // SAFETY: eight writable lanes (and x86-64 always has SSE2).
            unsafe {
                _mm_storeu_ps(out.as_mut_ptr(), self.0);
                _mm_storeu_ps(out.as_mut_ptr().add(4), self.1);
            }
        }
        #[inline(always)]
        unsafe fn load(p: *const f32) -> Sse2 {
            // SAFETY: the caller's contract (and x86-64 always has SSE2).
            unsafe { Sse2(_mm_loadu_ps(p), _mm_loadu_ps(p.add(4))) }
        }
        #[inline(always)]
        unsafe fn store(self, p: *mut f32) {
            // SAFETY: the caller's contract (and x86-64 always has SSE2).
            unsafe {
                _mm_storeu_ps(p, self.0);
                _mm_storeu_ps(p.add(4), self.1);
            }
        }
        #[inline(always)]
        fn add(self, o: Sse2) -> Sse2 {
            // SAFETY (here and below): x86-64 always has SSE2.
            self.map2(o, |a, b| unsafe { _mm_add_ps(a, b) })
        }
        #[inline(always)]
        fn sub(self, o: Sse2) -> Sse2 {
            self.map2(o, |a, b| unsafe { _mm_sub_ps(a, b) })
        }
        #[inline(always)]
        fn mul(self, o: Sse2) -> Sse2 {
            self.map2(o, |a, b| unsafe { _mm_mul_ps(a, b) })
        }
        #[inline(always)]
        fn div(self, o: Sse2) -> Sse2 {
            self.map2(o, |a, b| unsafe { _mm_div_ps(a, b) })
        }
        #[inline(always)]
        fn gt(self, o: Sse2) -> Sse2 {
            self.map2(o, |a, b| unsafe { _mm_cmpgt_ps(a, b) })
        }
        #[inline(always)]
        fn select(mask: Sse2, a: Sse2, b: Sse2) -> Sse2 {
            let pick = |m, a, b| unsafe { _mm_or_ps(_mm_and_ps(m, a), _mm_andnot_ps(m, b)) };
            Sse2(pick(mask.0, a.0, b.0), pick(mask.1, a.1, b.1))
        }
        #[inline(always)]
        fn pow2_of_rounded(t: Sse2) -> Sse2 {
            Sse2(pow2_sse2(t.0), pow2_sse2(t.1))
        }
    }

    /// Eight lanes in one AVX register. Made only inside the sweep's AVX copy
    /// (`sweep_ordinate_avx`), which runs where the processor has AVX.
    #[derive(Clone, Copy)]
    pub(in crate::transport::sweep) struct Avx(__m256);

    // SAFETY (every `unsafe` block below): an `Avx` exists only where the processor has AVX
    // (above); the loads' and stores' pointers as stated.
    impl Vector for Avx {
        const N: usize = 8;
        #[inline(always)]
        fn splat(x: f32) -> Avx {
            Avx(unsafe { _mm256_set1_ps(x) })
        }
        #[inline(always)]
        fn from_array(a: &[f32; 8]) -> Avx {
            // Eight readable lanes.
            unsafe { Avx::load(a.as_ptr()) }
        }
        #[inline(always)]
        fn to_array(self, out: &mut [f32; 8]) {
            // Eight writable lanes.
            unsafe { _mm256_storeu_ps(out.as_mut_ptr(), self.0) }
        }
        #[inline(always)]
        unsafe fn load(p: *const f32) -> Avx {
            // The caller's contract.
            Avx(unsafe { _mm256_loadu_ps(p) })
        }
        #[inline(always)]
        unsafe fn store(self, p: *mut f32) {
            // The caller's contract.
            unsafe { _mm256_storeu_ps(p, self.0) }
        }
        #[inline(always)]
        fn add(self, o: Avx) -> Avx {
            Avx(unsafe { _mm256_add_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn sub(self, o: Avx) -> Avx {
            Avx(unsafe { _mm256_sub_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn mul(self, o: Avx) -> Avx {
            Avx(unsafe { _mm256_mul_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn div(self, o: Avx) -> Avx {
            Avx(unsafe { _mm256_div_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn gt(self, o: Avx) -> Avx {
            Avx(unsafe { _mm256_cmp_ps::<_CMP_GT_OQ>(self.0, o.0) })
        }
        #[inline(always)]
        fn select(mask: Avx, a: Avx, b: Avx) -> Avx {
            Avx(unsafe { _mm256_blendv_ps(b.0, a.0, mask.0) })
        }
        #[inline(always)]
        fn pow2_of_rounded(t: Avx) -> Avx {
            // AVX has no eight-lane integer arithmetic: the two halves in SSE2.
            unsafe {
                let (lo, hi) = (_mm256_castps256_ps128(t.0), _mm256_extractf128_ps::<1>(t.0));
                Avx(_mm256_set_m128(pow2_sse2(hi), pow2_sse2(lo)))
            }
        }
    }
}
