//! `cloudgi info` on `.vdb` files: the JSON summary and the errors for files that are not one.

use crate::common::{data, BIN};

#[test]
fn info_cli_prints_the_issue_json() {
    let out = std::process::Command::new(BIN)
        .args(["info", data("vdb/tiles_blosc.vdb").to_str().unwrap(), "--json"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let g = &v["grids"][0];
    assert_eq!(g["name"], "density");
    assert_eq!(g["type"], "float");
    assert_eq!(g["active_voxels"], 2_102_816);
    assert_eq!(g["bbox_min"], serde_json::json!([-63, -63, -63]));
    assert_eq!(g["bbox_max"], serde_json::json!([271, 127, 127]));
    assert_eq!(g["voxel_size"], serde_json::json!([1.0, 1.0, 1.0]));
    assert_eq!(g["translation"], serde_json::json!([0.0, 0.0, 0.0]));
    assert_eq!(g["dense_bytes"], 4 * 335 * 191 * 191);
    assert!((g["sum"].as_f64().unwrap() - 1_050_174.267_848_443_2).abs() < 1e-5);
    // Keys in the documented order, and nothing else.
    let keys: Vec<&str> = [
        "name",
        "type",
        "active_voxels",
        "sum",
        "bbox_min",
        "bbox_max",
        "voxel_size",
        "translation",
        "dense_bytes",
    ]
    .to_vec();
    let pos: Vec<usize> = keys.iter().map(|k| text.find(&format!("\"{k}\"")).unwrap()).collect();
    assert!(pos.windows(2).all(|w| w[0] < w[1]), "key order {pos:?}");
    assert_eq!(g.as_object().unwrap().len(), keys.len());
    // Text form and a clean failure on a non-VDB file.
    let out = std::process::Command::new(BIN)
        .args(["info", data("vdb/README.md").to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("not an OpenVDB file") && !err.contains("panicked"), "{err}");
    let out = std::process::Command::new(BIN)
        .args(["info", data("vdb/multi_grid_blosc.vdb").to_str().unwrap()])
        .output()
        .unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("3 grids") && text.contains("vel: vec3s") && text.contains("100,024"),
        "{text}"
    );
}
