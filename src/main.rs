//! The `cloudgi` command line: argument parsing, progress bars and files. All rendering lives in
//! the library.

mod cli;

use clap::Parser;

fn main() {
    large_arrays_mapped();
    let args = cli::Cli::parse();
    match cli::run(args) {
        Ok(()) => {}
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    }
}

/// Every allocation of 4 MiB or more gets its own mapping, returned to the system when freed.
/// By default glibc raises its mapping threshold to the size of each freed mapping (up to
/// 32 MiB), after which the stages' large arrays come from the heap, whose freed ranges stay
/// resident: `full`'s peak resident memory at 200×160×120 was ~10 MB above what its live arrays
/// need. 16 MiB (the seventh round) still left the per-band arrays of 4–16 MiB on the heap:
/// 4 MiB takes `full`'s peak from 81 to 73 MB at 200×160×120 and from 539 to 490 MB at
/// 400×320×240, without measurable system time. (1 MiB saved no more but mapped the smaller
/// per-stage arrays afresh each time: +0.15 s of system time at 200×160×120; docs/performance.md,
/// "`full`'s peak, seventh round" and "Issue 16, eighth round".)
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn large_arrays_mapped() {
    extern "C" {
        fn mallopt(param: i32, value: i32) -> i32;
    }
    const M_MMAP_THRESHOLD: i32 = -3;
    // SAFETY: sets one allocator parameter (a fixed threshold also stops its adjustment), before
    // any other thread exists; a failure (0) leaves the default, which is only less frugal.
    unsafe {
        mallopt(M_MMAP_THRESHOLD, 4 << 20);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn large_arrays_mapped() {}
