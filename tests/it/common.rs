//! Helpers shared by the end-to-end tests: the binary, the test data and small grid files.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The `cloudgi` binary under test.
pub const BIN: &str = env!("CARGO_BIN_EXE_cloudgi");

/// Run the binary with `args` in `dir`; no run may panic.
pub fn cloudgi(dir: &Path, args: &[&str]) -> Output {
    let out = Command::new(BIN).current_dir(dir).args(args).output().unwrap();
    assert!(
        !String::from_utf8_lossy(&out.stderr).contains("panicked"),
        "cloudgi {args:?} panicked"
    );
    out
}

/// Run the binary in `dir`, which must succeed; its stderr.
pub fn ok(dir: &Path, args: &[&str]) -> String {
    let out = cloudgi(dir, args);
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(out.status.success(), "cloudgi {args:?} failed: {err}");
    err
}

/// A file under tests/data.
pub fn data(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(path)
}

/// A `.npy` file (version 1.0) with `header` (the dictionary, padded here) and raw `data`.
pub fn npy(header: &str, data: &[u8]) -> Vec<u8> {
    let mut h = header.to_string();
    while (10 + h.len() + 1) % 64 != 0 {
        h.push(' ');
    }
    h.push('\n');
    let mut v = b"\x93NUMPY\x01\x00".to_vec();
    v.extend((h.len() as u16).to_le_bytes());
    v.extend(h.as_bytes());
    v.extend(data);
    v
}

/// Little-endian bytes of `v`.
pub fn f32s(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// A float32 `.npy` grid of `dims = [nx, ny, nz]` voxels, `density(i, j, k)` each, stored
/// `[z][y][x]` as the grid loader reads it.
pub fn npy_grid(dims: [usize; 3], density: impl Fn(usize, usize, usize) -> f32) -> Vec<u8> {
    let [nx, ny, nz] = dims;
    let mut v = Vec::with_capacity(nx * ny * nz);
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                v.push(density(i, j, k));
            }
        }
    }
    npy(
        &format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({nz}, {ny}, {nx}), }}"),
        &f32s(&v),
    )
}

/// `cloudgi compare`'s block mean relative error of `test` against `reference`.
pub fn block_error(dir: &Path, test: &str, reference: &str) -> f64 {
    let out = Command::new(BIN)
        .current_dir(dir)
        .args(["compare", test, reference])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let m: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    m["block_mean_relative_error"].as_f64().unwrap()
}
