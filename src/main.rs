//! The `cloudgi` command line: argument parsing, progress bars and files. All rendering lives in
//! the library.

mod cli;

use clap::Parser;

fn main() {
    large_arrays_mapped();
    let args = cli::Cli::parse();
    match cli::run(args) {
        Ok(()) => {}
        Err(e) if cli::console::is_broken_pipe(&e) => std::process::exit(cli::console::EXIT_BROKEN_PIPE),
        Err(e) => {
            cli::console::note(format_args!("error: {}", cli::shortened(&e.to_string())));
            std::process::exit(1);
        }
    }
}

/// Every allocation of 1 MiB or more gets its own mapping, returned to the system when freed.
/// By default glibc raises its mapping threshold to the size of each freed mapping (up to
/// 32 MiB), after which the stages' large arrays come from the heap, whose freed ranges stay
/// resident. 16 MiB (the seventh round) left the per-band arrays of 4–16 MiB on the heap; 4 MiB
/// (the eighth) took `full`'s peak from 81 to 73 MB at 200×160×120. Since the ninth round's
/// per-band and per-stage arrays (1–4 MiB at 200×160×120) are what the peak holds, 1 MiB takes it
/// from 71 to 55 MB there (its live heap is 42 MB), for ~0.06 s more system time in a 1.6 s run
/// (docs/performance.md, "Memory of `full`, ninth round").
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn large_arrays_mapped() {
    extern "C" {
        fn mallopt(param: i32, value: i32) -> i32;
    }
    const M_MMAP_THRESHOLD: i32 = -3;
    // SAFETY: sets one allocator parameter (a fixed threshold also stops its adjustment), before
    // any other thread exists; a failure (0) leaves the default, which is only less frugal.
    unsafe {
        mallopt(M_MMAP_THRESHOLD, 1 << 20);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn large_arrays_mapped() {}
