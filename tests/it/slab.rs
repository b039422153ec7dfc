//! `cloudgi slab` (the path-traced slab): one JSON line near the adding-doubling row, a bad
//! albedo named.

use crate::common::BIN;

#[test]
fn cli_prints_one_json_line() {
    let out = std::process::Command::new(BIN)
        .args([
            "slab",
            "--thickness",
            "1",
            "--albedo",
            "0.8",
            "--g",
            "0",
            "--incidence",
            "collimated",
        ])
        .args(["--samples", "20000", "--seed", "5"])
        .output()
        .unwrap();
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
    let slab = |method: &str, extra: &[&str]| {
        let out = std::process::Command::new(BIN)
            .args([
                "slab",
                "--thickness",
                "1",
                "--albedo",
                "0.8",
                "--g",
                "0",
                "--incidence",
                "diffuse",
                "--method",
                method,
            ])
            .args(extra)
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let said = slab("diffusion", &["--samples", "100", "--seed", "3", "--forward-fraction", "0.5"]);
    assert!(
        said.contains("`--samples` does not apply to --method diffusion") && said.contains("`--seed`"),
        "{said}"
    );
    assert!(!said.contains("--forward-fraction"), "{said}");
    let said = slab("transport", &["--forward-fraction", "0.5"]);
    assert!(
        said.contains("`--forward-fraction` does not apply to --method transport, only to --method diffusion"),
        "{said}"
    );
    assert!(!slab("reference", &["--samples", "2000"]).contains("warning"));
    let bad = std::process::Command::new(BIN)
        .args(["slab", "--thickness", "1", "--albedo", "2", "--g", "0", "--incidence", "diffuse"])
        .output()
        .unwrap();
    assert!(!bad.status.success());
    let msg = String::from_utf8_lossy(&bad.stderr);
    assert!(msg.contains("--albedo") && msg.contains("[0, 1]"), "{msg}");
}
