//! The command line of the reference tools: `render --method reference`, `compare`, `export mitsuba`.

use crate::common::{cloudgi, npy_grid, ok};

const SCENE: &str = r#"
[medium]
resolution = [20, 16, 12]
voxel_size = 40.0
origin = [-400.0, 0.0, -240.0]
[camera]
width = 24
height = 18
[render]
method = "reference"
spp = 4
"#;

#[test]
fn render_compare_and_export() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("s.toml"), SCENE).unwrap();
    let out = cloudgi(d, &["render", "s.toml", "-o", "ref.exr", "--stderr", "--max-depth", "50", "-q"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let img = cloudgi::Image::read_exr(&d.join("ref.exr")).unwrap();
    assert!(img.layer("stderr").is_some() && img.layer("transmittance").is_some());
    assert!(d.join("ref.png").exists());
    let out = cloudgi(d, &["render", "s.toml", "-o", "single.exr", "--method", "single", "-q"]);
    assert!(out.status.success());

    // Against itself: zero error. Against `single`: darker (no multiple scattering).
    let out = cloudgi(d, &["compare", "ref.exr", "ref.exr"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["rmse"].as_f64(), Some(0.0));
    assert!(v["psnr"].is_null(), "infinite PSNR is written as null");
    assert_eq!(v["mask"], "transmittance < 0.99");
    let out = cloudgi(d, &["compare", "single.exr", "ref.exr", "--diff", "diff.png", "--mask", "ref.exr"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).unwrap();
    assert_eq!(text.lines().count(), 1);
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    for k in ["rmse", "psnr", "mean_relative_error", "luminance_bias"] {
        assert!(v[k].is_f64(), "{k} in {text}");
    }
    assert!(v["luminance_bias"].as_f64().unwrap() < -0.2, "{text}");
    assert!(v["pixels"].as_u64().unwrap() > 0);
    assert!(
        v["block_mean_relative_error"].is_f64() && v["block_bias"].as_f64().unwrap() < -0.2,
        "{text}"
    );
    assert!(d.join("diff.png").exists());
    // A mask image without a `transmittance` layer masks by its luminance, and says so.
    let out = cloudgi(d, &["compare", "single.exr", "ref.exr", "--mask", "single.exr"]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["mask"], "mask luminance < 0.99");
    // --budget: by region, with the reference's order shares; `single` has no AOVs, so only the total.
    let out = cloudgi(d, &["compare", "single.exr", "ref.exr", "--budget"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let all = &v["budget"][0];
    assert_eq!(all["region"], "all");
    assert_eq!(all["parts"][0]["part"], "total");
    assert_eq!(all["parts"][0]["bias"], v["block_bias"]);
    let out = cloudgi(d, &["compare", "single.exr", "ref.exr", "--ref-layer", "order1_sun"]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(
        v["block_bias"].as_f64().unwrap() > 0.5,
        "single adds the background to the sun's single scattering"
    );
    let out = cloudgi(d, &["compare", "single.exr", "ref.exr", "--ref-layer", "order1_sun", "--budget"]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // The same quantity summed in two orders: equal to the last bits.
    let (budget_bias, block_bias) = (
        v["budget"][0]["parts"][0]["bias"].as_f64().unwrap(),
        v["block_bias"].as_f64().unwrap(),
    );
    assert!(
        (budget_bias - block_bias).abs() < 1e-12,
        "the budget judges against the layer too: {budget_bias} vs {block_bias}"
    );
    let out = cloudgi(d, &["compare", "single.exr", "ref.exr", "--ref-layer", "nope"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("order0"), "lists the layers");
    let out = cloudgi(d, &["compare", "ref.exr", "single.exr", "--ref-layer", "order1_sun"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("single.exr") && err.contains("no layers beyond its RGB image"),
        "{err}"
    );
    let out = cloudgi(d, &["compare", "ref.exr", "single.exr", "--budget"]);
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("REF.exr"),
        "a reference without layers"
    );

    // Bad input: clear messages, no panic.
    let out = cloudgi(d, &["compare", "single.exr", "missing.exr"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("missing.exr"));
    let out = cloudgi(d, &["compare", "single.exr", "ref.exr", "--diff", "diff.jpg"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("--diff"));
    let out = cloudgi(d, &["render", "s.toml", "-o", "x.exr", "--time-limit", "0", "-q"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("command line: field `--time-limit`"));

    let out = cloudgi(d, &["export", "mitsuba", "s.toml", "-o", "mi", "-q"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(d.join("mi/scene.xml").exists() && d.join("mi/density.vol").exists());
}

#[test]
fn export_writes_one_frame_of_a_sequence_as_the_frame_file_alone() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Frame 3 of a pattern, keyed `sigma_t`: the same export as a scene naming that file and value.
    std::fs::write(d.join("c.0003.npy"), npy_grid([4, 3, 5], |i, j, k| (i + 2 * j + k) as f32 / 8.0)).unwrap();
    let medium = "[medium]\nvoxel_size = 50.0\n";
    std::fs::write(
        d.join("seq.toml"),
        format!(
            "{medium}grid = \"c.####.npy\"\n[[animation.key]]\nframe = 1\nmedium.sigma_t = 0.02\n\
             [[animation.key]]\nframe = 5\nmedium.sigma_t = 0.06\n"
        ),
    )
    .unwrap();
    std::fs::write(d.join("one.toml"), format!("{medium}grid = \"c.0003.npy\"\nsigma_t = 0.04\n")).unwrap();
    ok(d, &["export", "mitsuba", "seq.toml", "--frame", "3", "-o", "a", "-q"]);
    ok(d, &["export", "mitsuba", "one.toml", "-o", "b", "-q"]);
    let read = |f: &str| std::fs::read(d.join(f)).unwrap();
    assert_eq!(read("a/density.vol"), read("b/density.vol"));
    // The same XML but for the comment naming the scene file exported.
    let xml = |f: &str| String::from_utf8(read(f)).unwrap();
    assert_eq!(xml("a/scene.xml").replace("seq.toml", "one.toml"), xml("b/scene.xml"));
}
