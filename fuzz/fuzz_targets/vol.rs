//! Any bytes given to the Mitsuba .vol reader: an error or a grid, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = cloudgi::medium::loaders::parse_vol(data, "fuzz.vol");
});
