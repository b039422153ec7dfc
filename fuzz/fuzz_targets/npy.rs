//! Any bytes given to the NumPy .npy reader: an error or a grid, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = cloudgi::medium::loaders::parse_npy(data, "fuzz.npy");
});
