//! The OpenVDB reader against files written by OpenVDB itself (tests/data/vdb, values in
//! reference.json read back by OpenVDB), plus robustness against truncated, corrupted and
//! hostile files.

use crate::medium::vdb::{read_vdb_dense_bytes, read_vdb_grids_bytes, read_vdb_info, read_vdb_info_bytes};
use crate::Error;
use serde_json::Value;
use std::path::PathBuf;

fn data(name: &str) -> PathBuf {
    super::common::data("vdb").join(name)
}

fn reference() -> Value {
    serde_json::from_str(&std::fs::read_to_string(data("reference.json")).unwrap()).unwrap()
}

fn arr3(v: &Value) -> [f64; 3] {
    [0, 1, 2].map(|i| v[i].as_f64().unwrap())
}

/// Parse a probe key "(x, y, z)".
fn probe_key(k: &str) -> [i64; 3] {
    let v: Vec<i64> = k
        .trim_matches(|c| c == '(' || c == ')')
        .split(',')
        .map(|s| s.trim().parse().unwrap())
        .collect();
    [v[0], v[1], v[2]]
}

#[test]
fn every_file_matches_openvdb_reference() {
    let r = reference();
    let files = r.as_object().unwrap();
    assert_eq!(files.len(), 10, "all ten reference files are checked");
    for (file, fr) in files {
        let bytes = std::fs::read(data(file)).unwrap();
        let grids = read_vdb_grids_bytes(&bytes, file).unwrap_or_else(|e| panic!("{file}: {e}"));
        let infos = read_vdb_info_bytes(&bytes, file).unwrap();
        let refs = fr["grids"].as_object().unwrap();
        assert_eq!(grids.len(), refs.len(), "{file}: grid count");
        for (gname, gr) in refs {
            let g = grids
                .iter()
                .find(|g| &g.name == gname)
                .unwrap_or_else(|| panic!("{file}: no grid {gname}"));
            let info = infos.iter().find(|g| &g.name == gname).unwrap();
            let ctx = format!("{file}:{gname}");
            assert_eq!(info.value_type, gr["type"].as_str().unwrap(), "{ctx} type");
            assert_eq!(g.half, gr["meta_half"].as_bool().unwrap(), "{ctx} half");
            // Transform: voxel size and index→world of two points, to f64 rounding.
            let vs = arr3(&gr["voxel_size"]);
            for a in 0..3 {
                assert!(
                    (info.voxel_size[a] - vs[a]).abs() <= 1e-12 * vs[a],
                    "{ctx} voxel size {:?} vs {vs:?}",
                    info.voxel_size
                );
            }
            for (key, p) in [("index_to_world_000", [0.0, 0.0, 0.0]), ("index_to_world_123", [1.0, 2.0, 3.0])] {
                let want = arr3(&gr[key]);
                let got = g.transform.index_to_world(p);
                for a in 0..3 {
                    assert!((got[a] - want[a]).abs() <= 1e-12, "{ctx} {key}: {got:?} vs {want:?}");
                }
            }
            assert_eq!(info.translation, g.transform.index_to_world([0.0; 3]), "{ctx} translation");
            let Some(count) = gr["active_voxel_count"].as_u64() else {
                // The vec3s grid: listed with its topology, no sum.
                assert!(info.sum.is_none(), "{ctx}: vector grids have no sum");
                continue;
            };
            assert_eq!(info.active_voxels, Some(count), "{ctx} active voxels");
            let bmin = gr["bbox_min"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_i64().unwrap())
                .collect::<Vec<_>>();
            let bmax = gr["bbox_max"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_i64().unwrap())
                .collect::<Vec<_>>();
            assert_eq!(info.bbox_min.unwrap().to_vec(), bmin, "{ctx} bbox min");
            assert_eq!(info.bbox_max.unwrap().to_vec(), bmax, "{ctx} bbox max");
            let dims: u64 = (0..3).map(|a| (bmax[a] - bmin[a] + 1) as u64).product();
            assert_eq!(info.dense_bytes, 4 * dims, "{ctx} dense bytes");
            // The same f32 (or half) values summed in f64 in another order than OpenVDB's
            // reference script: agreement to 1e-11 relative (order-only rounding).
            let want = gr["sum"].as_f64().unwrap();
            let got = info.sum.unwrap();
            assert!((got - want).abs() <= 1e-11 * want.abs(), "{ctx} sum {got} vs {want}");
            // Probes: values read by OpenVDB's getValue. Exact: the half grids' reference values
            // are the halves themselves, widened.
            let tree = g.tree.as_ref().unwrap();
            for (k, v) in gr["probes"].as_object().unwrap() {
                let want = v.as_f64().unwrap();
                let got = tree.active_value(probe_key(k)).unwrap_or(tree.background);
                // Reference values are f32 (or half) values widened to f64 and printed; compare
                // as f32, which is exact (serde_json's f64 parse may be off in the last bit).
                assert_eq!(got as f32, want as f32, "{ctx} probe {k}");
            }
            // min/max over the active values (tiles included).
            let mm = arr3(&Value::Array(vec![gr["min_max"][0].clone(), gr["min_max"][1].clone(), 0.into()]));
            let mut lo = f64::INFINITY;
            let mut hi = f64::NEG_INFINITY;
            for l in &tree.leaves {
                for &v in &l.values {
                    lo = lo.min(v as f64);
                    hi = hi.max(v as f64);
                }
            }
            for t in &tree.tiles {
                lo = lo.min(t.value);
                hi = hi.max(t.value);
            }
            assert_eq!([lo as f32, hi as f32], [mm[0] as f32, mm[1] as f32], "{ctx} min/max");
        }
    }
}

#[test]
fn dense_grid_holds_the_tree_values() {
    let r = reference();
    for file in [
        "sphere64_blosc.vdb",
        "sphere64_half_blosc.vdb",
        "tiles_blosc.vdb",
        "aniso_scale_blosc.vdb",
    ] {
        let gr = &r[file]["grids"]["density"];
        let bytes = std::fs::read(data(file)).unwrap();
        let d = read_vdb_dense_bytes(&bytes, file, Some("density"), 50_000_000, 1).unwrap();
        let bmin = d.index_min;
        assert_eq!(
            bmin.to_vec(),
            gr["bbox_min"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_i64().unwrap())
                .collect::<Vec<_>>()
        );
        // Dense sum = reference sum (inactive voxels are 0), to f32-accumulation-free rounding.
        let sum: f64 = d.grid.data().iter().map(|&v| v as f64).sum();
        let want = gr["sum"].as_f64().unwrap();
        assert!((sum - want).abs() <= 1e-11 * want, "{file}: dense sum {sum} vs {want}");
        for (k, v) in gr["probes"].as_object().unwrap() {
            let p = probe_key(k);
            let dims = d.grid.dims();
            let q = [0, 1, 2].map(|a| p[a] - bmin[a]);
            let got = if (0..3).all(|a| q[a] >= 0 && (q[a] as usize) < dims[a]) {
                d.grid.get(q[0] as usize, q[1] as usize, q[2] as usize) as f64
            } else {
                0.0
            };
            assert_eq!(got as f32, v.as_f64().unwrap() as f32, "{file} probe {k}");
        }
        // Placement: voxel (0,0,0) of the dense grid is centred at index_to_world(bbox_min).
        let vs = arr3(&gr["voxel_size"]);
        let w0 = arr3(&gr["index_to_world_000"]);
        for a in 0..3 {
            let centre = d.origin[a] + 0.5 * d.voxel_size[a];
            assert!((centre - (w0[a] + bmin[a] as f64 * vs[a])).abs() < 1e-9, "{file} origin");
        }
    }
}

#[test]
fn downsampling_while_reading_equals_downsampling_the_dense_grid() {
    for file in ["tiles_blosc.vdb", "sphere64_half_blosc.vdb"] {
        let bytes = std::fs::read(data(file)).unwrap();
        let full = read_vdb_dense_bytes(&bytes, file, None, 50_000_000, 1).unwrap();
        for n in [2, 3, 8] {
            let d = read_vdb_dense_bytes(&bytes, file, None, u64::MAX, n).unwrap();
            let want = full.grid.downsample(n);
            assert_eq!(d.grid.dims(), want.dims(), "{file} n={n}");
            for (a, b) in d.grid.data().iter().zip(want.data()) {
                assert!((a - b).abs() <= 1e-6 * b.abs().max(1e-3), "{file} n={n}: {a} vs {b}");
            }
            assert_eq!(d.voxel_size, full.voxel_size.map(|v| v * n as f64));
            assert_eq!(d.origin, full.origin);
        }
    }
}

#[test]
fn root_tile_is_refused_by_the_memory_guard_then_read_downsampled() {
    let file = "root_tile_blosc.vdb";
    let bytes = std::fs::read(data(file)).unwrap();
    let e = read_vdb_dense_bytes(&bytes, file, Some("density"), 200_000_000, 1).unwrap_err();
    let msg = e.to_string();
    assert!(
        matches!(e, Error::Invalid { ref field, .. } if field == "medium.max_voxels"),
        "{msg}"
    );
    // 4128×4096×4096 voxels; the smallest downsample under 2e8 voxels is 8 (516×512×512).
    for part in [
        "4128×4096×4096",
        "69256347648 voxels",
        "258.0 GiB",
        "medium.downsample = 8",
        "516×512×512",
    ] {
        assert!(msg.contains(part), "missing `{part}` in: {msg}");
    }
    // Downsampled by 64: 65×64×64 blocks. Each full block of the 4096³ tile averages 0.125;
    // the block holding the extra voxels averages their sum over 64³ voxels.
    let d = read_vdb_dense_bytes(&bytes, file, Some("density"), 200_000_000, 64).unwrap();
    assert_eq!(d.grid.dims(), [65, 64, 64]);
    assert_eq!(d.voxel_size, [64.0; 3]);
    assert_eq!(d.origin, [-32.5, -0.5, -0.5]);
    let r = reference();
    let want_sum = r[file]["grids"]["density"]["sum"].as_f64().unwrap();
    // Sum of block means × voxels per block = total sum (blocks are clipped to the box).
    let dims = [4128u64, 4096, 4096];
    let mut total = 0.0;
    for k in 0..64 {
        for j in 0..64 {
            for i in 0..65 {
                let held = |a: usize, b: u64| ((b + 1) * 64).min(dims[a]) - b * 64;
                total += d.grid.get(i, j, k) as f64 * (held(0, i as u64) * held(1, j as u64) * held(2, k as u64)) as f64;
            }
        }
    }
    assert!((total - want_sum).abs() < 1e-6 * want_sum, "{total} vs {want_sum}");
    // A block entirely inside the tile and away from the extra voxels: exactly 0.125.
    assert_eq!(d.grid.get(40, 40, 40), 0.125);
}

#[test]
fn grid_selection_and_non_scalar_grids() {
    let file = "multi_grid_blosc.vdb";
    let bytes = std::fs::read(data(file)).unwrap();
    let t = read_vdb_dense_bytes(&bytes, file, Some("temperature"), 1 << 30, 1).unwrap();
    assert_eq!(t.grid.dims(), [28, 28, 28]);
    let e = read_vdb_dense_bytes(&bytes, file, Some("vel"), 1 << 30, 1).unwrap_err().to_string();
    assert!(e.contains("vec3s") && e.contains("scalar"), "{e}");
    let e = read_vdb_dense_bytes(&bytes, file, Some("smoke"), 1 << 30, 1)
        .unwrap_err()
        .to_string();
    assert!(e.contains("no grid named `smoke`") && e.contains("`temperature` (float)"), "{e}");
    // Default: `density`.
    let d = read_vdb_dense_bytes(&bytes, file, None, 1 << 30, 1).unwrap();
    assert_eq!(d.grid.dims(), [58, 58, 58]);
    assert!(read_vdb_info(&data("missing.vdb")).is_err());
}

// ------------------------------------------------------------------ robustness

/// Parse must return (never panic) for every input.
fn parse_all(bytes: &[u8]) -> bool {
    let a = read_vdb_info_bytes(bytes, "t.vdb").is_ok();
    let b = read_vdb_dense_bytes(bytes, "t.vdb", None, 4_000_000, 1).is_ok();
    a || b
}

#[test]
fn truncation_at_every_structure_gives_an_error() {
    for file in ["sphere64_half_blosc.vdb", "blobs_zip.vdb", "tiles_blosc.vdb", "root_tile_blosc.vdb"] {
        let bytes = std::fs::read(data(file)).unwrap();
        // Every offset in the header region, then a stride through the tree.
        let offsets: Vec<usize> = (0..600.min(bytes.len())).chain((600..bytes.len()).step_by(997)).collect();
        for &n in &offsets {
            let e = read_vdb_info_bytes(&bytes[..n], file);
            let Err(e) = e else {
                panic!("{file} truncated to {n} bytes was accepted")
            };
            assert!(e.to_string().starts_with(file), "{e}");
        }
    }
}

#[test]
fn corrupted_bytes_never_panic() {
    // Flip bytes at a deterministic spread of positions of each file; any result but a panic
    // (or abort) is fine: corrupt values can still parse.
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    for file in [
        "sphere64_half_blosc.vdb",
        "blobs_half_zip.vdb",
        "tiles_blosc.vdb",
        "sphere64_none.vdb",
    ] {
        let bytes = std::fs::read(data(file)).unwrap();
        for _ in 0..60 {
            let mut b = bytes.clone();
            for _ in 0..1 + next() % 4 {
                let i = (next() % b.len() as u64) as usize;
                b[i] ^= 1 << (next() % 8);
            }
            parse_all(&b);
        }
    }
}

/// Offset of the first occurrence of `needle`.
fn find(hay: &[u8], needle: &[u8]) -> usize {
    hay.windows(needle.len()).position(|w| w == needle).unwrap()
}

#[test]
fn hostile_sizes_give_clear_errors() {
    let file = "sphere64_blosc.vdb";
    let bytes = std::fs::read(data(file)).unwrap();
    // Grid count: at the end of the (empty) file metadata, right after the 36-byte UUID.
    let mut b = bytes.clone();
    let at = 8 + 4 + 8 + 1 + 36 + 4;
    b[at..at + 4].copy_from_slice(&i32::MAX.to_le_bytes());
    let e = read_vdb_info_bytes(&b, file).unwrap_err().to_string();
    assert!(e.contains("grids declared"), "{e}");
    // Root tile/child counts: right after the background value, after "Tree buffer count" = 1.
    // Find the transform type name, then the tree follows it.
    let t = find(&bytes, b"UniformScaleMap") + "UniformScaleMap".len() + 5 * 24;
    assert_eq!(&bytes[t..t + 4], &1i32.to_le_bytes(), "buffer count");
    let mut b = bytes.clone();
    b[t + 8..t + 12].copy_from_slice(&u32::MAX.to_le_bytes());
    let e = read_vdb_info_bytes(&b, file).unwrap_err().to_string();
    assert!(e.contains("more than the file can hold"), "{e}");
    // A blosc chunk size of 2^62: refused as past the end, no allocation.
    let mut b = bytes.clone();
    let chunk = t + 4 + 4 + 4 + 4 + 12; // after the root child origin: upper node masks follow
    let masks = 2 * 4096;
    let size_at = chunk + masks + 1; // compression byte, then the chunk size
    b[size_at..size_at + 8].copy_from_slice(&(1i64 << 62).to_le_bytes());
    let e = read_vdb_info_bytes(&b, file).unwrap_err().to_string();
    assert!(e.contains("truncated") || e.contains("corrupt"), "{e}");
    // Negative (uncompressed) size that disagrees with the node.
    b[size_at..size_at + 8].copy_from_slice(&(-7i64).to_le_bytes());
    let e = read_vdb_info_bytes(&b, file).unwrap_err().to_string();
    assert!(e.contains("uncompressed chunk of 7 bytes"), "{e}");
    // Not a VDB at all.
    let e = read_vdb_info_bytes(b"VOL\x03 hello", file).unwrap_err().to_string();
    assert!(e.contains("not an OpenVDB file"), "{e}");
    // A grid offset past the end of the file.
    let mut b = bytes.clone();
    let gd = find(&bytes, b"Tree_float_5_4_3") + "Tree_float_5_4_3".len() + 4; // after empty parent name
    b[gd..gd + 8].copy_from_slice(&(1i64 << 40).to_le_bytes());
    let e = read_vdb_info_bytes(&b, file).unwrap_err().to_string();
    assert!(e.contains("outside the"), "{e}");
}
