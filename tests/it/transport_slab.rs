//! `cloudgi slab --method transport`: the 1-D transport solution through the binary.

use crate::common::BIN;

#[test]
fn cli_method_transport_prints_the_solution() {
    let out = std::process::Command::new(BIN)
        .args(["slab", "--thickness", "10", "--albedo", "0.999", "--g", "0.9"])
        .args(["--incidence", "diffuse", "--method", "transport"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_str(String::from_utf8(out.stdout).unwrap().trim()).unwrap();
    // Row τ=10, a=0.999, g=0.9: URU = 0.442086, UTU = 0.538213.
    assert!((v["R"].as_f64().unwrap() - 0.442086).abs() < 0.005, "{v}");
    assert!((v["T"].as_f64().unwrap() - 0.538213).abs() < 0.005, "{v}");
    assert_eq!(v["R_stderr"].as_f64(), Some(0.0));
}
