//! `cloudgi slab` (the path-traced slab): one JSON line near the adding-doubling row, a bad
//! albedo named, a flag the method does not read named as ignored.

use crate::common::BIN;

/// `cloudgi slab` on the slab τ = 1, albedo 0.8, g = 0 lit by `incidence`, with `extra`.
fn slab(incidence: &str, extra: &[&str]) -> std::process::Output {
    std::process::Command::new(BIN)
        .args(["slab", "--thickness", "1", "--albedo", "0.8", "--g", "0", "--incidence", incidence])
        .args(extra)
        .output()
        .unwrap()
}

#[test]
fn cli_prints_one_json_line() {
    let out = slab("collimated", &["--samples", "20000", "--seed", "5"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).unwrap();
    assert_eq!(text.lines().count(), 1);
    let v: serde_json::Value = serde_json::from_str(text.trim()).unwrap();
    for k in ["R", "T", "R_stderr", "T_stderr"] {
        assert!(v[k].is_f64(), "{k} missing in {text}");
    }
    // Row τ=1, a=0.8, g=0: UR1 = 0.210847, UT1 = 0.541400.
    assert!((v["R"].as_f64().unwrap() - 0.210847).abs() < 3.0 * v["R_stderr"].as_f64().unwrap() + 0.002);
    assert!((v["T"].as_f64().unwrap() - 0.541400).abs() < 3.0 * v["T_stderr"].as_f64().unwrap() + 0.002);
    // A flag the method does not read is named as ignored; the one it reads is not.
    let warned = |method: &str, extra: &[&str]| {
        let out = slab("diffuse", &[&["--method", method], extra].concat());
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let said = warned("diffusion", &["--samples", "100", "--seed", "3", "--forward-fraction", "0.5"]);
    assert!(
        said.contains("`--samples` does not apply to --method diffusion") && said.contains("`--seed`"),
        "{said}"
    );
    assert!(!said.contains("--forward-fraction"), "{said}");
    let said = warned("transport", &["--forward-fraction", "0.5"]);
    assert!(
        said.contains("`--forward-fraction` does not apply to --method transport, only to --method diffusion"),
        "{said}"
    );
    assert!(!warned("reference", &["--samples", "2000"]).contains("warning"));
    let bad = std::process::Command::new(BIN)
        .args(["slab", "--thickness", "1", "--albedo", "2", "--g", "0", "--incidence", "diffuse"])
        .output()
        .unwrap();
    assert!(!bad.status.success());
    let msg = String::from_utf8_lossy(&bad.stderr);
    assert!(msg.contains("--albedo") && msg.contains("[0, 1]"), "{msg}");
}
