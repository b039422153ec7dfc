//! Valid scenes at the edges of the scene file: without a ground, with a transparent medium,
//! and `render.spp` on the deterministic methods (the bad ones are `tests/it/bad_input.rs`).

use crate::medium::{loaders, Grid3};
use crate::{Image, Method, NoProgress, Scene, SceneDesc};
use std::path::Path;

const SCENE: &str = "[medium]\nresolution = [8, 8, 8]\nvoxel_size = 100.0\n";

fn build(text: &str) -> Scene {
    let desc = SceneDesc::from_toml(text, "s.toml").unwrap();
    Scene::build(desc, "s.toml", Path::new(".")).unwrap()
}

/// `text` with a small camera looking down at the cloud's foot, so the ground fills the lower rows.
fn small(text: &str) -> String {
    format!("{text}[camera]\nwidth = 12\nheight = 9\nlook_at = [0.0, 0.0, 0.0]\n")
}

fn render_as(s: &Scene, m: Method) -> Image {
    let mut t = s.clone();
    t.render.method = m;
    crate::render::render(&t, &NoProgress).unwrap().image
}

#[test]
fn a_scene_without_ground_table_or_with_enabled_false_has_no_ground() {
    assert!(Scene::default_scene().unwrap().ground.is_some());
    assert!(build(SCENE).ground.is_none(), "no [ground] table: no ground");
    assert!(build(&format!("{SCENE}[ground]\nenabled = false\n")).ground.is_none());
    let g = build(&format!("{SCENE}[ground]\nheight = 5.0\n"))
        .ground
        .expect("a [ground] table: a ground");
    assert_eq!(g.height, 5.0);
    // And the image shows it: the bottom row sees the ground, or the sky without one.
    let none = render_as(&build(&small(SCENE)), Method::Single);
    let off = render_as(&build(&small(&format!("{SCENE}[ground]\nenabled = false\n"))), Method::Single);
    let on = render_as(&build(&small(&format!("{SCENE}[ground]\n"))), Method::Single);
    assert_eq!(none, off);
    assert_ne!(none.get(6, 8), on.get(6, 8));
}

#[test]
fn a_transparent_medium_renders_sky_and_ground_without_a_solve() {
    let dir = tempfile::tempdir().unwrap();
    loaders::write_npy(&dir.path().join("g.npy"), &Grid3::filled([2, 2, 2], 0.0)).unwrap();
    let zero_grid = format!(
        "[medium]\ngrid = \"{}\"\n[ground]\n[render]\naov = true\n",
        dir.path().join("g.npy").display().to_string().replace('\\', "/")
    );
    for text in [format!("{SCENE}sigma_t = 0.0\n[ground]\n[render]\naov = true\n"), zero_grid] {
        let s = build(&small(&text));
        let single = render_as(&s, Method::Single);
        // Every pixel is the background seen through nothing.
        for y in 0..9 {
            for x in 0..12 {
                let r = s.camera.ray(x as f32 + 0.5, y as f32 + 0.5);
                assert_eq!(single.get(x, y), s.background(r.origin, r.dir, |_| 1.0), "pixel ({x}, {y})");
            }
        }
        assert_eq!(render_as(&s, Method::Diffusion).pixels, single.pixels, "{text}");
        let full = render_as(&s, Method::Full);
        assert_eq!(full.pixels, single.pixels, "{text}");
        assert_eq!(full.layer("background").unwrap(), &single.pixels[..]);
        assert!(full.layer("diffusion").unwrap().iter().all(|p| *p == crate::math::Rgb::ZERO));
    }
}

#[test]
fn spp_does_not_multiply_the_deterministic_methods() {
    let s = build(&small(SCENE));
    for m in [Method::Single, Method::Full] {
        let img = |spp: u32, aa: u32| {
            let mut t = s.clone();
            (t.render.spp, t.render.aa_samples) = (spp, aa);
            render_as(&t, m)
        };
        let base = img(1, 1);
        assert_eq!(img(16, 1), base, "{m:?}: render.spp must not change a deterministic image");
        assert_ne!(img(1, 4), base, "{m:?}: render.aa_samples anti-aliases");
    }
}

#[test]
fn huge_and_tiny_direction_vectors_keep_their_direction() {
    // f32's squared length overflows at 1e30 and underflows at 1e-30: normalised in f32, such a
    // sun would march NaN (or be refused as a zero vector) although its direction is plain.
    let unit = build(&small(&format!("{SCENE}[sun]\ndirection = [1.0, 1.0, 0.0]\n")));
    let base = render_as(&unit, Method::Single);
    for v in ["1e30", "1e-30", "3e38"] {
        let s = build(&small(&format!("{SCENE}[sun]\ndirection = [{v}, {v}, 0.0]\n")));
        assert!(
            (s.sun.dir - unit.sun.dir).length() < 1e-6,
            "sun.direction [{v}, {v}, 0]: {}",
            s.sun.dir
        );
        let img = render_as(&s, Method::Single);
        for (a, b) in img.pixels.iter().zip(&base.pixels) {
            assert!((*a - *b).abs().max_element() <= 1e-5 * b.max_element(), "{v}: {a} vs {b}");
        }
        let up = |y: &str| build(&format!("{SCENE}[camera]\nup = [0.0, {y}, 0.0]\n")).camera.up;
        assert!((up(v) - up("1.0")).length() < 1e-6, "camera.up [0, {v}, 0]: {}", up(v));
    }
}
