//! No method may write a negative or non-finite radiance: every method and every EXR layer is
//! finite and ≥ 0 on scenes that drive the paper's I0 negative or overflow f32 — the noon example
//! (sunlit tops: navy rims), an optically very thick conservative cloud (albedo 1, σt = 100 m⁻¹)
//! and an absurdly bright sun (1e30 W/m²). Tiny images on a coarse grid keep it fast.

use super::common::{assert_finite_nonnegative, METHODS};
use crate::{Method, NoProgress, Scene, SceneDesc};
use std::path::Path;

/// The scene file `name` in examples/ (or the built-in scene) on a coarse grid and a tiny image.
fn scene(example: Option<&str>, method: Method, edit: impl Fn(&mut SceneDesc)) -> Scene {
    let path = example.map(|e| Path::new(env!("CARGO_MANIFEST_DIR")).join("examples").join(e));
    Scene::load(path.as_deref(), |d| {
        d.medium.resolution = [25, 20, 15];
        d.medium.voxel_size = 40.0.into();
        d.sky.map_width = 64;
        d.camera.width = 24;
        d.camera.height = 18;
        d.render.method = method;
        d.render.aov = true;
        d.render.stderr = true;
        // The dense scene's paths would scatter ~10⁸ times; a cap keeps it short
        // and the estimate (then biased low) must still be non-negative.
        d.render.max_depth = Some(16);
        // Two samples: the reference's standard error of one sample is undefined (written as inf).
        d.render.spp = if method == Method::Reference { 2 } else { 1 };
        edit(d);
    })
    .unwrap()
}

fn assert_nonnegative(label: &str, s: &Scene) {
    let out = match crate::render::render(s, &NoProgress) {
        Ok(out) => out,
        // Transport on voxels thousands of optical depths thick: its acceleration diverges and
        // plain source iteration cannot converge; it refuses, naming the stage (docs/transport.md,
        // "Robustness"), rather than writing an unconverged image.
        Err(crate::Error::Numerical { stage, message }) if s.render.method == Method::Transport && s.medium.optics.sigma_t >= 100.0 => {
            assert!(
                stage == "transport solve" && message.contains("--method reference"),
                "{label}: {message}"
            );
            return;
        }
        Err(e) => panic!("{label}: {e}"),
    };
    let img = out.image;
    if s.render.method == Method::Full {
        assert_eq!(img.layers.len() + 1, 5, "{label}: full with aov writes four layers");
    }
    assert_finite_nonnegative(label, &img, &[]);
}

fn every_method(label: &str, example: Option<&str>, edit: impl Fn(&mut SceneDesc)) {
    for m in METHODS {
        let s = scene(example, m, &edit);
        assert_nonnegative(&format!("{label} {}", m.name()), &s);
    }
}

#[test]
fn noon_example_is_nonnegative() {
    every_method("noon", Some("noon.toml"), |_| {});
    let s = scene(Some("noon.toml"), Method::Full, |d| d.render.diffuse_anisotropy = true);
    assert_nonnegative("noon full diffuse_anisotropy", &s);
}

#[test]
fn thick_conservative_cloud_is_nonnegative() {
    every_method("albedo 1, sigma_t 100", None, |d| {
        d.medium.albedo = [1.0; 3];
        d.medium.sigma_t = 100.0;
    });
}

#[test]
fn huge_sun_is_nonnegative() {
    every_method("sun 1e30", None, |d| d.sun.irradiance = [1e30; 3]);
}
