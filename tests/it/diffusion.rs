//! `cloudgi bench` on the diffusion method: a row per cloud and method, the solver's summary.

use crate::common::BIN;

#[test]
fn bench_prints_a_row_per_cloud_and_method_with_the_solver_summary() {
    let out = std::process::Command::new(BIN)
        .args(["bench", "--methods", "single,diffusion", "--sizes", "10x8x6,20x16x12"])
        .args(["--width", "16", "--height", "12"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    let rows: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with("| 10×8×6") || l.starts_with("| 20×16×12"))
        .collect();
    assert_eq!(rows.len(), 4, "{text}");
    assert!(rows[1].contains("| diffusion |") && text.contains("| diffusion solve |"), "{text}");
    assert!(
        text.contains("20×16×12 diffusion: diffusion:") && text.contains("iterations"),
        "{text}"
    );
    let bad = std::process::Command::new(BIN).args(["bench", "--sizes", "10x8"]).output().unwrap();
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("--sizes"));
}
