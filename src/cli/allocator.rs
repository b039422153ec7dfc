//! The allocator setting of the `cloudgi` process.

/// Every allocation of 1 MiB or more gets its own mapping, returned to the system when freed.
/// By default glibc raises its mapping threshold to the size of each freed mapping (up to
/// 32 MiB), after which the stages' large arrays come from the heap, whose freed ranges stay
/// resident. The per-band and per-stage arrays (1–4 MiB at 200×160×120) are what `full`'s peak
/// holds, so a fixed 1 MiB threshold keeps that peak near its live heap for a little more system
/// time (docs/performance.md, "The solver on its unknowns"). Below that size freed memory stays with its
/// heap up to 64 MiB (the default, once the mapping threshold is fixed, is 128 KiB): `transport`'s
/// sweeps free and take again their plane buffers (about 0.5 MiB each) every ordinate, and a trim
/// hands them back to the system to be faulted in afresh (docs/performance.md, "`transport`
/// against `single`").
#[cfg(all(target_os = "linux", target_env = "gnu"))]
pub(super) fn large_arrays_mapped() {
    unsafe extern "C" {
        fn mallopt(param: i32, value: i32) -> i32;
    }
    const M_TRIM_THRESHOLD: i32 = -1;
    const M_MMAP_THRESHOLD: i32 = -3;
    // SAFETY: sets two allocator parameters (a fixed threshold also stops their adjustment),
    // before any other thread exists; a failure (0) leaves the default, which is only less frugal
    // or slower.
    unsafe {
        mallopt(M_MMAP_THRESHOLD, 1 << 20);
        mallopt(M_TRIM_THRESHOLD, 64 << 20);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
pub(super) fn large_arrays_mapped() {}

/// Hand the heap's free memory back to the system (glibc's `malloc_trim`, every arena), so that
/// the resident memory holds only what is live: `bench` measures each run's peak above it, which
/// memory freed by a larger run before, resident and reused, would hide.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
pub(super) fn release_free_memory() {
    unsafe extern "C" {
        fn malloc_trim(pad: usize) -> i32;
    }
    // SAFETY: returns free pages of the allocator's heaps to the system; it takes the heaps'
    // locks and leaves every allocation in place.
    unsafe {
        malloc_trim(0);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
pub(super) fn release_free_memory() {}
