//! `cloudgi sky`: the sky exported as an EXR with its PNG, at the scene's width or `--width`, and a
//! bad width refused without writing anything (the map's content is checked in `src/tests/sky.rs`).

use crate::common::{cloudgi, ok};

#[test]
fn sky_writes_the_map_and_its_png_and_refuses_a_bad_width() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene =
        "[sun]\nelevation_deg = 4.0\nazimuth_deg = 30.0\nfrom_atmosphere = true\n\n[sky]\nmodel = \"atmosphere\"\nmap_width = 128\n";
    std::fs::write(d.join("sunset.toml"), scene).unwrap();
    ok(d, &["sky", "sunset.toml", "-o", "sky.exr", "--quiet"]);
    assert!(d.join("sky.png").is_file());
    assert_eq!(cloudgi::Image::read_exr(&d.join("sky.exr")).unwrap().width, 128);
    ok(d, &["sky", "sunset.toml", "-o", "wide.exr", "--width", "256", "--quiet"]);
    assert_eq!(cloudgi::Image::read_exr(&d.join("wide.exr")).unwrap().width, 256);
    // A bad width is refused without writing anything.
    let out = cloudgi(d, &["sky", "-o", "x.exr", "--width", "1", "--quiet"]);
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("--width"));
    assert!(!d.join("x.exr").exists());
}
