//! Any bytes given to the OpenVDB reader: an error or a result, never a panic, abort or
//! unbounded allocation.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = cloudgi::medium::vdb::read_vdb_info_bytes(data, "fuzz.vdb");
    // A small memory guard: the dense grid is bounded by it, whatever the file declares.
    let _ = cloudgi::medium::vdb::read_vdb_dense_bytes(data, "fuzz.vdb", None, 1 << 20, 1);
    let _ = cloudgi::medium::vdb::read_vdb_dense_bytes(data, "fuzz.vdb", None, 1 << 20, 4);
});
