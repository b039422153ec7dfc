//! `cloudgi figures`: the paper's figure series at a tiny size, checking every file, the table and
//! that the numbers are finite. About 10 s in release on 2 cores (a coarse 40×32×24 cloud, 48×36
//! pixels, 4 reference spp).

use crate::common::cloudgi;

// The default cloud on a coarser grid (same extent), so the test stays fast.
const SCENE: &str = r#"
[medium]
grid = "procedural"
seed = 1
resolution = [40, 32, 24]
voxel_size = 25.0
origin = [-500.0, 0.0, -300.0]
"#;

const IDS: [&str; 6] = [
    "fig4-single",
    "fig5-diffusion",
    "fig6-diffusion-low-density",
    "fig7-full",
    "fig8-sunset-full",
    "fig7-full-fixed",
];

/// Write `scene` to `d/scene.toml` and run `cloudgi -q figures scene.toml -o figs` with `args`.
fn figures(d: &std::path::Path, scene: &str, args: &[&str]) -> std::process::Output {
    std::fs::write(d.join("scene.toml"), scene).unwrap();
    cloudgi(d, &[&["-q", "figures", "scene.toml", "-o", "figs"], args].concat())
}

#[test]
fn figure_series_writes_everything() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = figures(
        d,
        SCENE,
        &["--threads", "2", "--width", "48", "--height", "36", "--reference-spp", "4"],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let f = d.join("figs");
    for id in IDS.iter().chain(&["reference", "fig8-reference"]) {
        for ext in ["exr", "png"] {
            let p = f.join(format!("{id}.{ext}"));
            assert!(p.metadata().map(|m| m.len() > 0).unwrap_or(false), "missing {}", p.display());
        }
    }
    for id in IDS {
        assert!(f.join(format!("diff-{id}.png")).exists(), "missing diff of {id}");
    }
    // The reference EXR carries the transmittance layer the masks come from.
    let r = cloudgi::Image::read_exr(&f.join("reference.exr")).unwrap();
    assert_eq!((r.width, r.height), (48, 36));
    assert!(r.layer("transmittance").is_some());

    let index = std::fs::read_to_string(f.join("index.md")).unwrap();
    assert!(index.contains("| Fig. | method | time (s) | MRE cloud | MRE edge |"), "{index}");
    for (fig, id) in (4..=8).zip(IDS) {
        assert!(index.contains(&format!("\n| {fig} | ")), "no table row for Fig. {fig}");
        assert!(index.contains(&format!("({id}.png)")) && index.contains(&format!("(diff-{id}.png)")));
    }

    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(f.join("results.json")).unwrap()).unwrap();
    let figs = json["figures"].as_array().unwrap();
    assert_eq!(figs.len(), IDS.len());
    // The fixed `full` (the scene's default settings) is not the paper's Fig. 7.
    let mre = |id: &str| figs.iter().find(|f| f["id"] == id).unwrap()["cloud"]["mean_relative_error"].as_f64();
    assert_ne!(mre("fig7-full"), mre("fig7-full-fixed"));
    let num = |v: &serde_json::Value| v.as_f64().filter(|x| x.is_finite());
    for fig in figs {
        assert!(num(&fig["seconds"]).is_some_and(|s| s >= 0.0));
        for mask in ["cloud", "edge"] {
            let m = &fig[mask];
            assert!(m.is_object(), "{} has no {mask} metrics: {fig}", fig["id"]);
            for key in ["rmse", "mean_relative_error", "luminance_bias"] {
                assert!(num(&m[key]).is_some(), "{}.{mask}.{key} not finite: {m}", fig["id"]);
            }
            assert!(m["pixels"].as_u64().unwrap() > 0);
        }
    }
    for r in json["references"].as_array().unwrap() {
        assert_eq!(r["spp"].as_u64(), Some(4));
        // 4 spp: the reference's own relative noise is finite and clearly above zero.
        assert!(
            num(&r["cloud_noise"]).is_some_and(|x| x > 0.001) && num(&r["edge_noise"]).is_some_and(|x| x > 0.001),
            "{r}"
        );
        assert!(r["edge_pixels"].as_u64().unwrap() > 0 && r["cloud_pixels"].as_u64().unwrap() > r["edge_pixels"].as_u64().unwrap());
    }
    // Physics sanity, robust even at 4 spp: single scattering alone misses most of the light of
    // an albedo-0.999 cloud (its mean luminance is far below the reference's), diffusion restores
    // most of it.
    let bias = |i: usize| figs[i]["cloud"]["luminance_bias"].as_f64().unwrap();
    assert!(bias(0) < -0.5, "single scattering bias {}", bias(0));
    assert!(
        bias(1).abs() < bias(0).abs() / 2.0,
        "diffusion bias {} vs single {}",
        bias(1),
        bias(0)
    );
}

#[test]
fn bad_arguments_are_reported() {
    let dir = tempfile::tempdir().unwrap();
    let out = cloudgi(dir.path(), &["figures", "-o", "x", "--width", "0"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--width"));
    let out = cloudgi(dir.path(), &["figures", "-o", "x", "--reference-spp", "0"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--reference-spp"));
    // A time limit that ends the reference before its first sample leaves nothing to measure.
    let out = cloudgi(
        dir.path(),
        &[
            "figures",
            "-o",
            "x",
            "--width",
            "8",
            "--height",
            "6",
            "--reference-time",
            "1e-9",
            "-q",
        ],
    );
    assert!(!out.status.success() && !dir.path().join("x").exists());
    assert!(String::from_utf8_lossy(&out.stderr).contains("1e-9 s ended the reference"));
    assert!(String::from_utf8_lossy(&out.stderr).contains("raise --reference-time"));
}

#[test]
fn a_run_that_fails_leaves_no_output_folder() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // The grid file is read only when the scene is built, after the folder would be made.
    std::fs::write(d.join("s.toml"), "[medium]\ngrid = \"bad.vol\"\n").unwrap();
    std::fs::write(d.join("bad.vol"), b"not a volume").unwrap();
    let out = cloudgi(d, &["figures", "s.toml", "-o", "out/figs", "-q"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("bad.vol"));
    assert!(!d.join("out").exists(), "no folder left behind");
}

#[test]
fn a_view_without_cloud_pixels_fails_before_writing_anything() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // The camera looks away from the cloud: no reference pixel has transmittance < 0.99.
    let away = format!("{SCENE}[camera]\nposition = [0.0, 350.0, 1500.0]\nlook_at = [0.0, 350.0, 3000.0]\n");
    let out = figures(d, &away, &["--width", "8", "--height", "6", "--reference-spp", "1"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("--width/--height") && err.contains("no pixel") && !err.contains("--mask"),
        "{err}"
    );
    assert!(!d.join("figs").exists(), "the output folder is left behind");
}

#[test]
fn a_grid_file_takes_the_scene_files_place_as_for_render() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("g.npy"), crate::common::npy_grid([4, 4, 4], |_, _, _| 1.0)).unwrap();
    let out = cloudgi(
        d,
        &[
            "-q",
            "figures",
            "g.npy",
            "-o",
            "figs",
            "--width",
            "8",
            "--height",
            "6",
            "--reference-spp",
            "1",
        ],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(d.join("figs/index.md").exists() && d.join("figs/fig7-full.exr").exists());
}
