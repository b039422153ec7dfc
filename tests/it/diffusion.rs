//! `cloudgi bench` on the diffusion method: a row per cloud and method, the solver's summary;
//! each row's own peak memory.

use crate::common::BIN;

/// `cloudgi bench` of `methods` on the procedural cloud at `sizes`, `width` × `height` pixels.
fn bench(methods: &str, sizes: &str, width: &str, height: &str) -> std::process::Output {
    std::process::Command::new(BIN)
        .args([
            "bench",
            "--methods",
            methods,
            "--sizes",
            sizes,
            "--width",
            width,
            "--height",
            height,
        ])
        .output()
        .unwrap()
}

#[test]
fn bench_prints_a_row_per_cloud_and_method_with_the_solver_summary() {
    let out = bench("single,diffusion", "10x8x6,20x16x12", "16", "12");
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

#[test]
fn bench_reports_each_rows_own_peak_after_a_larger_run() {
    let out = bench("single,transport", "80x64x48,20x16x12", "32", "24");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    let header: Vec<&str> = text.lines().find(|l| l.starts_with("| cloud")).unwrap().split('|').collect();
    let peak = header.iter().position(|c| c.trim() == "peak").unwrap();
    let rows: Vec<&str> = text.lines().filter(|l| l.starts_with("| 80×") || l.starts_with("| 20×")).collect();
    assert_eq!(rows.len(), 4, "{text}");
    for r in rows {
        let cell = r.split('|').nth(peak).unwrap().trim();
        let value: f64 = cell.split(' ').next().unwrap().parse().unwrap();
        assert!(value > 0.0, "every run allocates: {r}\n{text}");
    }
}
