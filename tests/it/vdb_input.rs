//! `.vdb` input as simulations write it: empty frames (before a cloud forms, after it is gone) in
//! a sequence and alone, files whose only float grid is not named `density`, and files with
//! several such grids (render, export, info). The files are written by the test writer (`src/medium/vdb/test_file.rs`).

use crate::common::{block_error, cloudgi, ok};
use crate::vdb_writer::{vdb_file, TestGrid};
use std::path::Path;

/// An 8³ block of 50-m voxels of `value`, 100 m above the origin (`density` when `name` is).
fn cloud(name: &str, value: f32) -> TestGrid {
    let mut g = TestGrid::block(name, 8, value);
    g.voxel_size = [50.0; 3];
    g.translation = [-200.0, 100.0, -200.0];
    g
}

/// The same grid with no active voxels (its transform kept, as a simulation writes it).
fn empty() -> TestGrid {
    TestGrid {
        voxels: Vec::new(),
        ..cloud("density", 0.0)
    }
}

fn write(dir: &Path, name: &str, grids: &[TestGrid]) {
    std::fs::write(dir.join(name), vdb_file(grids)).unwrap();
}

fn read(p: &Path) -> Vec<u8> {
    std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// A scene over the ground whose camera frames each frame's cloud (camera.fit).
const SCENE: &str = "[medium]\ngrid = \"c.####.vdb\"\nsigma_t = 0.02\n\
    [camera]\nwidth = 24\nheight = 18\nfit = true\n[ground]\n[animation]\nframes = \"1-3\"\n";

#[test]
fn an_empty_frame_of_a_sequence_renders_the_cloudless_scene_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "c.0001.vdb", &[cloud("density", 1.0)]);
    write(d, "c.0002.vdb", &[empty()]);
    write(d, "c.0003.vdb", &[cloud("density", 0.6)]);
    std::fs::write(d.join("s.toml"), SCENE).unwrap();
    let err = ok(d, &["render", "s.toml", "-o", "f.####.exr", "--cold"]);
    let warned: Vec<&str> = err.lines().filter(|l| l.contains("no active voxels")).collect();
    assert!(
        warned.len() == 2
            && warned[0].starts_with("warning: frame 2: ")
            && warned[0].contains("c.0002.vdb")
            && warned[0].contains("without a cloud")
            && warned[1].starts_with("warning: frame 2: "),
        "once as frame 2 comes, once at the end naming it: {err}"
    );
    assert!(err.contains("frame 3 (3 of 3)"), "the sequence goes on: {err}");
    // The empty frame is its neighbour's view without the cloud: frame 1's scene with no
    // extinction, framed on frame 1's cloud, gives the same sky and ground.
    std::fs::write(d.join("clear.toml"), SCENE.replace("0.02", "0.0")).unwrap();
    ok(d, &["render", "clear.toml", "--frames", "1", "-o", "clear.####.exr", "-q"]);
    let e = block_error(d, "f.0002.exr", "clear.0001.exr");
    assert!(e < 1e-5, "empty frame against the cloud-less frame 1: {e}");
    assert!(read(&d.join("f.0001.exr")) != read(&d.join("f.0002.exr")));
    // The frame after it is its own still render (cold), and a warm start across the empty
    // frame lands within the warm-start tolerance of it.
    std::fs::write(
        d.join("still.toml"),
        SCENE
            .replace("c.####.vdb", "c.0003.vdb")
            .replace("[animation]\nframes = \"1-3\"\n", ""),
    )
    .unwrap();
    ok(d, &["render", "still.toml", "-o", "still.exr", "-q"]);
    assert!(read(&d.join("still.exr")) == read(&d.join("f.0003.exr")));
    ok(d, &["render", "s.toml", "-o", "warm.####.exr", "-q"]);
    let e = block_error(d, "warm.0003.exr", "f.0003.exr");
    assert!(e < 5e-3, "warm frame 3 after the empty frame: {e}");
}

#[test]
fn an_empty_file_alone_renders_clear_sky_with_a_warning_and_info_says_empty() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "e.vdb", &[empty()]);
    write(d, "b.vdb", &[cloud("density", 1.0)]);
    let small = ["--width", "16", "--height", "12"];
    let err = ok(d, &[&["render", "e.vdb", "-o", "e.exr"][..], &small].concat());
    assert!(
        err.contains("warning: ") && err.contains("e.vdb") && err.contains("`density` has no active voxels"),
        "{err}"
    );
    assert!(
        !err.contains("not in the camera's view") && !err.contains("less than one pixel"),
        "{err}"
    );
    // The clear sky the grid-file scene shows (no ground) without a cloud.
    std::fs::write(
        d.join("clear.toml"),
        "[medium]\ngrid = \"b.vdb\"\nsigma_t = 0.0\n[ground]\nenabled = false\n",
    )
    .unwrap();
    ok(d, &[&["render", "clear.toml", "-o", "clear.exr", "-q"][..], &small].concat());
    let e = block_error(d, "e.exr", "clear.exr");
    assert!(e < 1e-5, "{e}");
    // Exported for Mitsuba with the same warning.
    let err = ok(d, &["export", "mitsuba", "e.vdb", "-o", "mitsuba"]);
    assert!(err.contains("warning: ") && err.contains("`density` has no active voxels"), "{err}");
    let out = cloudgi(d, &["info", "e.vdb"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success() && text.contains("active voxels  0: empty"), "{text}");
    let out = cloudgi(d, &["info", "e.vdb", "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        (v["grids"][0]["active_voxels"].as_u64(), v["grids"][0]["bbox_min"].is_null()),
        (Some(0), true)
    );
}

#[test]
fn the_only_float_grid_is_read_whatever_its_name_and_several_are_a_choice() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut vel = cloud("vel_mask", 1.0);
    vel.value_type = "int32";
    write(d, "smoke.vdb", &[vel.clone(), cloud("smoke", 1.0)]);
    write(d, "density.vdb", &[cloud("density", 1.0)]);
    let small = ["--width", "16", "--height", "12", "-o"];
    let err = ok(d, &[&["render", "smoke.vdb"][..], &small, &["smoke.exr"]].concat());
    assert!(
        err.contains("warning: ")
            && err.contains("smoke.vdb")
            && err.contains("only float grid, `smoke`")
            && err.contains("medium.grid_name"),
        "{err}"
    );
    ok(d, &[&["render", "density.vdb", "-q"][..], &small, &["density.exr"]].concat());
    assert!(read(&d.join("smoke.exr")) == read(&d.join("density.exr")), "the same grid, read");
    // Two float grids and no `density`: an error listing them and the key that picks, no output.
    write(d, "two.vdb", &[cloud("smoke", 1.0), cloud("heat", 0.5), vel]);
    let out = cloudgi(d, &[&["render", "two.vdb"][..], &small, &["two.exr"]].concat());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    for part in [
        "two.vdb",
        "medium.grid_name",
        "`smoke` (float)",
        "`heat` (float)",
        "grid_name = \"NAME\"",
        "cloudgi render two.vdb --grid-name NAME",
    ] {
        assert!(err.contains(part), "{part}: {err}");
    }
    assert!(!d.join("two.exr").exists() && !d.join("two.png").exists());
    // The scene key picks one, and so does --grid-name on the grid file itself.
    std::fs::write(d.join("heat.toml"), "[medium]\ngrid = \"two.vdb\"\ngrid_name = \"heat\"\n").unwrap();
    let err = ok(d, &[&["render", "heat.toml"][..], &small, &["heat.exr"]].concat());
    assert!(!err.contains("only float grid"), "{err}");
    ok(
        d,
        &[&["render", "two.vdb", "--grid-name", "heat", "-q"][..], &small, &["flag.exr"]].concat(),
    );
    assert!(
        read(&d.join("heat.exr")) == read(&d.join("flag.exr")),
        "the flag reads the grid the key does"
    );
}
