//! Processor features the solver's kernels dispatch on. Each kernel is a plain `fn` compiled
//! as built and a copy compiled for AVX (`#[target_feature(enable = "avx")]`): their lanes and
//! sums are explicit and Rust never fuses a multiply with an add, so both give the same bits;
//! AVX does eight lanes per instruction instead of four.

/// Whether the processor runs AVX instructions (the AVX copies may be called).
#[inline]
pub(super) fn has_avx() -> bool {
    #[cfg(target_arch = "x86_64")]
    return std::arch::is_x86_feature_detected!("avx");
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// Bring the cache line at `p` towards L1 ahead of use (a hint: no effect on results).
#[inline(always)]
pub(super) fn prefetch<T>(p: *const T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: x86_64 always has SSE, and a prefetch never faults (any address may be named).
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p as *const i8)
    };
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}
