//! Bad input: every case gives a message naming the file and field, a non-zero exit, no output
//! file, and no panic.

use std::path::Path;
use std::process::Command;

fn cloudgi(dir: &Path, args: &[&str]) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_cloudgi"))
        .current_dir(dir)
        .args(args)
        .arg("--quiet")
        .output()
        .unwrap();
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stderr).to_string())
}

/// Write `scene` as s.toml and render it small; assert a clean failure mentioning `expect`.
fn assert_fails(scene: &str, expect: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("s.toml"), scene).unwrap();
    let (code, err) = cloudgi(
        dir.path(),
        &["render", "s.toml", "-o", "out.exr", "--width", "16", "--height", "12"],
    );
    assert_ne!(code, 0, "must fail: {scene}");
    assert_ne!(code, 101, "panicked: {err}");
    assert!(!err.contains("panicked"), "panicked: {err}");
    for e in expect {
        assert!(err.contains(e), "message `{err}` should mention `{e}`");
    }
    assert!(
        !dir.path().join("out.exr").exists() && !dir.path().join("out.png").exists(),
        "no output on failure"
    );
    let leftovers: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(leftovers.len(), 1, "only the scene file may remain: {leftovers:?}");
}

#[test]
fn bad_optical_properties() {
    assert_fails("[medium]\nsigma_t = -0.1\n", &["s.toml", "medium.sigma_t", "non-negative"]);
    assert_fails("[medium]\nalbedo = [0.5, 1.2, 0.5]\n", &["s.toml", "medium.albedo", "[0, 1]"]);
    assert_fails("[medium]\ng = 1.0\n", &["s.toml", "medium.g", "|g| < 1"]);
    assert_fails("[medium]\ng = -1.5\n", &["medium.g"]);
}

#[test]
fn bad_camera_and_image() {
    assert_fails(
        "[camera]\nposition = [0.0, 100.0, 0.0]\nlook_at = [0.0, 0.0, 0.0]\nup = [0.0, 1.0, 0.0]\n",
        &["s.toml", "camera.up", "parallel"],
    );
    let dir = tempfile::tempdir().unwrap();
    let (code, err) = cloudgi(dir.path(), &["render", "-o", "x.exr", "--width", "0"]);
    assert!(code != 0 && err.contains("camera.width"), "{err}");
    assert!(!dir.path().join("x.exr").exists());
}

#[test]
fn unknown_key_is_named() {
    assert_fails("[medium]\nsigmat = 0.1\n", &["s.toml", "sigmat"]);
    assert_fails("[render]\nmethod = \"magic\"\n", &["s.toml", "magic"]);
}

#[test]
fn missing_grid_file() {
    assert_fails("[medium]\ngrid = \"nope.vol\"\n", &["nope.vol"]);
}

fn write_vol(dir: &Path, dims: [i32; 3], values: &[f32], truncate: usize) {
    let mut b = b"VOL\x03".to_vec();
    for v in [1, dims[0], dims[1], dims[2], 1] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    for v in [0.0f32, 0.0, 0.0, 1.0, 1.0, 1.0] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    for v in values {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b.truncate(b.len() - truncate);
    std::fs::write(dir.join("g.vol"), b).unwrap();
}

fn assert_grid_fails(dims: [i32; 3], values: &[f32], truncate: usize, expect: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    write_vol(dir.path(), dims, values, truncate);
    std::fs::write(dir.path().join("s.toml"), "[medium]\ngrid = \"g.vol\"\n").unwrap();
    let (code, err) = cloudgi(dir.path(), &["render", "s.toml", "-o", "out.exr", "--width", "8", "--height", "8"]);
    assert!(code != 0 && code != 101 && !err.contains("panicked"), "{err}");
    for e in expect {
        assert!(err.contains(e), "`{err}` should mention `{e}`");
    }
    assert!(!dir.path().join("out.exr").exists());
}

#[test]
fn bad_grids() {
    assert_grid_fails([0, 2, 2], &[], 0, &["g.vol", "zero size"]);
    assert_grid_fails([2, 2, 2], &[1.0; 8], 5, &["g.vol", "truncated"]);
    assert_grid_fails(
        [2, 2, 2],
        &[1.0, f32::NAN, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0],
        0,
        &["g.vol", "voxel (1, 0, 0)", "finite"],
    );
    assert_grid_fails([2, 2, 2], &[1.0, 1.0, 1.0, -0.5, 1.0, 1.0, 1.0, 1.0], 0, &["g.vol", "non-negative"]);
    // Hostile header: a huge declared size must not allocate.
    assert_grid_fails([1 << 20, 1 << 20, 1 << 20], &[1.0; 4], 0, &["g.vol"]);
}

#[test]
fn default_render_writes_exr_and_png() {
    let dir = tempfile::tempdir().unwrap();
    let (code, err) = cloudgi(dir.path(), &["render", "--width", "32", "--height", "24"]);
    assert_eq!(code, 0, "{err}");
    let img = cloudgi::Image::read_exr(&dir.path().join("cloud.exr")).unwrap();
    assert_eq!((img.width, img.height), (32, 24));
    assert!(dir.path().join("cloud.png").exists());
}
