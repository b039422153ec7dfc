//! The reference path tracer against exact answers: furnace (thin and thick clouds), Beer–Lambert
//! transmittance, single scattering against the `single` method, determinism across thread counts,
//! the time limit and the extra EXR layers.

use crate::lighting::{Sky, Sun};
use crate::math::{Rgb, Vec3};
use crate::medium::{Grid3, Medium};
use crate::reference::{render_with_stats, LIGHT_LAYERS, ORDER_LAYERS, SAMPLES_LAYER, SINGLE_LAYERS, STDERR_LAYER, TRANSMITTANCE_LAYER};
use crate::render::Timings;
use crate::scene::{Method, Scene, SceneDesc};
use crate::{Image, NoProgress};
use std::path::Path;

/// A small scene: no ground, sun and sky as given, camera at (0, 0, `dist`) looking at the origin.
fn scene(medium: Medium, sun: Rgb, sky: Rgb, dist: f32, fov: f32, size: (u32, u32), spp: u32) -> Scene {
    let mut desc = SceneDesc {
        ground: None,
        ..Default::default()
    };
    desc.medium.resolution = [4, 4, 4];
    desc.camera.position = [0.0, 0.0, dist];
    desc.camera.look_at = [0.0, 0.0, 0.0];
    desc.camera.fov_deg = fov;
    desc.camera.width = size.0;
    desc.camera.height = size.1;
    desc.render.method = Method::Reference;
    desc.render.spp = spp;
    // One sample has no standard error (the scene refuses render.stderr then).
    desc.render.stderr = spp >= 2;
    desc.render.seed = 7;
    let mut s = Scene::build(desc, "test", Path::new(".")).unwrap();
    s.medium = medium;
    s.sun = Sun {
        dir: Vec3::new(0.3, 0.9, 0.2).normalize(),
        irradiance: sun,
    };
    s.sky = Sky::constant(sky);
    s
}

/// A ball of density 1 (smooth edge) of radius 7 m in a 16³ grid of 1 m voxels centred on the origin.
fn ball(sigma_t: f32, albedo: f32, g: f32) -> Medium {
    let mut grid = Grid3::filled([16, 16, 16], 0.0);
    for k in 0..16 {
        for j in 0..16 {
            for i in 0..16 {
                let p = Vec3::new(i as f32 - 7.5, j as f32 - 7.5, k as f32 - 7.5);
                grid.set(i, j, k, (7.0 - p.length()).clamp(0.0, 1.0));
            }
        }
    }
    Medium::new(grid, Vec3::splat(-8.0), Vec3::ONE, sigma_t, Rgb::splat(albedo), g)
}

/// A homogeneous 10 m cube of density 1 centred on the origin.
fn cube(sigma_t: f32, albedo: f32, g: f32) -> Medium {
    Medium::new(
        Grid3::filled([10, 10, 10], 1.0),
        Vec3::splat(-5.0),
        Vec3::ONE,
        sigma_t,
        Rgb::splat(albedo),
        g,
    )
}

fn render(s: &Scene) -> (Image, u32) {
    let (img, stats) = render_with_stats(s, &NoProgress, &mut Timings::default());
    (img, stats.spp)
}

/// Furnace: albedo 1, constant sky L, no sun, no ground ⇒ every pixel reads L.
fn furnace(sigma_t: f32, g: f32, spp: u32) {
    furnace_with(sigma_t, g, spp, false);
}

/// `envmap`: the constant sky as an equirectangular map, so next-event estimation samples the
/// map's sin θ-weighted distribution (not the uniform sphere) and MIS must still add up to L.
fn furnace_with(sigma_t: f32, g: f32, spp: u32, envmap: bool) {
    let l = Rgb::new(0.5, 1.0, 2.0);
    let mut s = scene(ball(sigma_t, 1.0, g), Rgb::ZERO, l, 40.0, 30.0, (8, 6), spp);
    if envmap {
        s.sky = Sky::from_envmap(crate::lighting::envmap::EnvMap::new(32, 16, vec![l; 32 * 16]));
    }
    let (img, _) = render(&s);
    let se = img.layer(STDERR_LAYER).unwrap();
    let t = img.layer(TRANSMITTANCE_LAYER).unwrap();
    let mut cloud = 0;
    let (mut sum, mut var) = (Rgb::ZERO, Rgb::ZERO);
    for (i, (p, e)) in img.pixels.iter().zip(se).enumerate() {
        // 5 standard errors per band and pixel (144 checks; a fixed seed makes it reproducible),
        // plus float rounding.
        let tol = *e * 5.0 + l * 1e-4;
        assert!(((*p - l).abs() - tol).max_element() <= 0.0, "pixel {i}: {p} ± {e} vs {l}");
        if t[i].x < 0.99 {
            cloud += 1;
            sum += *p;
            var += *e * *e;
        }
    }
    assert!(cloud >= 12, "the ball must cover part of the image ({cloud} pixels)");
    // The mean over cloud pixels is tighter: 4 standard errors of the mean.
    let n = cloud as f32;
    let (mean, se_mean) = (sum / n, Rgb::new(var.x.sqrt(), var.y.sqrt(), var.z.sqrt()) / n);
    assert!(
        ((mean - l).abs() - se_mean * 4.0 - l * 1e-4).max_element() <= 0.0,
        "mean {mean} ± {se_mean}"
    );
}

#[test]
fn furnace_thin_cloud() {
    // Optical diameter 0.5: most camera rays pass; the scattered ones must add back exactly.
    furnace(0.5 / 14.0, 0.5, 128);
}

#[test]
fn furnace_with_an_importance_sampled_environment_map() {
    furnace_with(8.0 / 14.0, 0.85, 128, true);
}

#[test]
fn furnace_thick_cloud() {
    // Optical diameter 60, strongly forward scattering: tens to hundreds of bounces per path.
    furnace(60.0 / 14.0, 0.85, 128);
}

#[test]
fn absorbing_cube_transmits_exp_minus_tau() {
    // Albedo 0: each sample reads L or 0, with probability e^{−τ}. A 1° field of view keeps the
    // rays within 0.3° of the axis, so every chord is 10 m to 2e-5.
    let l = Rgb::new(0.2, 0.4, 0.8);
    let sigma_t = 0.12;
    let s = scene(cube(sigma_t, 0.0, 0.0), Rgb::ZERO, l, 60.0, 1.0, (4, 4), 256);
    let (img, _) = render(&s);
    let expect = (-sigma_t * 10.0f32).exp();
    let t = img.layer(TRANSMITTANCE_LAYER).unwrap();
    let mut mean = 0.0;
    for (p, tl) in img.pixels.iter().zip(t) {
        assert!((tl.x - expect).abs() < 1e-4 * expect, "layer {} vs {expect}", tl.x);
        mean += p.x / l.x;
    }
    mean /= img.pixels.len() as f32;
    // Bernoulli mean over 16·256 samples: standard error √(p(1−p)/4096) ≈ 0.0077; allow 4 of them.
    let se = (expect * (1.0 - expect) / 4096.0).sqrt();
    assert!((mean - expect).abs() < 4.0 * se, "{mean} vs {expect}");
}

#[test]
fn single_scattering_matches_the_single_method() {
    // Sun only (sky black, no ground), max_depth 1: the reference computes exactly what `single`
    // computes, by a different estimator. The camera sees only the cube's interior.
    let mut s = scene(cube(0.15, 0.8, 0.5), Rgb::new(3.0, 2.0, 1.0), Rgb::ZERO, 12.0, 30.0, (6, 6), 128);
    s.render.max_depth = Some(1);
    let (rf, _) = render(&s);
    let mut ss = s.clone();
    ss.render.method = Method::Single;
    ss.render.spp = 16;
    let single = crate::render::render(&ss, &NoProgress).unwrap().image;
    let se = rf.layer(STDERR_LAYER).unwrap();
    for (i, ((&a, &b), &e)) in rf.pixels.iter().zip(&single.pixels).zip(se).enumerate() {
        assert!(b.min_element() > 0.0);
        // 4.5 standard errors of the reference + 2 % for the single method's march (half-voxel
        // steps, sun transmittance interpolated from voxel centres).
        let tol = e * 4.5 + b * 0.02;
        assert!(
            ((a - b).abs() - tol).max_element() <= 0.0,
            "pixel {i}: reference {a} ± {e}, single {b}"
        );
    }
    // With every bounce allowed the image must be brighter (multiple scattering adds light).
    s.render.max_depth = None;
    let full = crate::reference::render_image(&s, 32);
    let sum = |im: &Image| im.pixels.iter().map(|p| p.x).sum::<f32>();
    assert!(sum(&full) > 1.05 * sum(&rf));
}

#[test]
fn identical_with_any_thread_count() {
    let mut s = scene(
        ball(1.5, 0.95, 0.7),
        Rgb::new(3.0, 3.0, 3.0),
        Rgb::new(0.3, 0.4, 0.8),
        40.0,
        30.0,
        (7, 5),
        4,
    );
    s.ground = Some(crate::lighting::Ground {
        height: -9.0,
        albedo: Rgb::splat(0.4),
    });
    let imgs: Vec<Image> = [1, 3]
        .iter()
        .map(|&n| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(n).build().unwrap();
            pool.install(|| render(&s).0)
        })
        .collect();
    assert_eq!(imgs[0], imgs[1]);
    assert!(imgs[0].pixels.iter().all(|p| p.is_finite() && p.min_element() >= 0.0));
}

#[test]
fn time_limit_stops_early_and_layers_round_trip() {
    let mut s = scene(
        ball(1.0, 0.99, 0.8),
        Rgb::splat(2.0),
        Rgb::splat(0.3),
        40.0,
        30.0,
        (6, 4),
        1_000_000,
    );
    s.render.time_limit = Some(0.3);
    let (img, spp) = render(&s);
    // A million passes of 24 pixels cannot finish in 0.3 s on any machine; how many do is the
    // machine's load (on a busy one none may), so only the early stop is asserted, and a pixel
    // left without a sample reads a finite 0.
    assert!(spp < 1_000_000, "{spp}");
    assert!(img.pixels.iter().all(|p| p.is_finite() && p.min_element() >= 0.0));
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("r.exr");
    img.write_exr(&p).unwrap();
    let back = Image::read_exr(&p).unwrap();
    assert!(back.layer(TRANSMITTANCE_LAYER).is_some() && back.layer(STDERR_LAYER).is_some());
}

/// Sum of the named layers of `img`.
fn layer_sum(img: &Image, names: &[&str]) -> Vec<Rgb> {
    let mut out = vec![Rgb::ZERO; img.pixels.len()];
    for n in names {
        for (o, v) in out.iter_mut().zip(img.layer(n).unwrap_or_else(|| panic!("layer {n}"))) {
            *o += *v;
        }
    }
    out
}

#[test]
fn order_and_light_layers_sum_to_the_image() {
    // Sun, sky and a ground below a ball: every kind of path. The layers split the same f32
    // terms the image sums, so they add up to it to rounding.
    let mut s = scene(
        ball(0.8, 0.95, 0.7),
        Rgb::new(3.0, 3.0, 3.0),
        Rgb::new(0.3, 0.4, 0.8),
        30.0,
        40.0,
        (8, 6),
        8,
    );
    s.ground = Some(crate::lighting::Ground {
        height: -7.5,
        albedo: Rgb::splat(0.4),
    });
    let (img, _) = render(&s);
    let orders: Vec<&str> = ORDER_LAYERS.iter().map(|l| l.0).collect();
    for (what, sum) in [("orders", layer_sum(&img, &orders)), ("lights", layer_sum(&img, &LIGHT_LAYERS))] {
        for (i, (a, b)) in sum.iter().zip(&img.pixels).enumerate() {
            assert!(
                ((*a - *b).abs() - *b * 1e-5 - Rgb::splat(1e-6)).max_element() <= 0.0,
                "{what}, pixel {i}: {a} vs {b}"
            );
        }
    }
    let single = layer_sum(&img, &SINGLE_LAYERS);
    for (a, b) in single.iter().zip(img.layer("order1").unwrap()) {
        assert!(((*a - *b).abs() - *b * 1e-5).max_element() <= 1e-6);
    }
    // Every layer has light somewhere (orders 9+ too: albedo 0.95, optical diameter 11).
    for n in orders.iter().chain(&LIGHT_LAYERS) {
        assert!(layer_sum(&img, &[n]).iter().any(|p| p.x > 0.0), "layer {n} is black");
    }
    // Single scattering only: no order ≥ 2; order 0 and 1 still sum to the image.
    s.render.max_depth = Some(1);
    let (one, _) = render(&s);
    assert!(layer_sum(&one, &orders[2..]).iter().all(|p| *p == Rgb::ZERO));
    // No ground: no ground light, and the sky seen past the ball is order 0 and the whole pixel.
    s.ground = None;
    s.render.max_depth = None;
    let (ng, _) = render(&s);
    assert!(ng.layer("light_ground").unwrap().iter().all(|p| *p == Rgb::ZERO));
    assert_eq!(ng.layer("order0").unwrap()[0], ng.pixels[0]);
    assert_eq!(ng.pixels[0], Rgb::new(0.3, 0.4, 0.8));
    // Order 0 is the unscattered sky: its mean over the image is the sky times the camera rays'
    // mean transmittance (binomial noise of 384 samples; 2 % for the pixel-centre transmittance
    // against jittered rays). Counting the escape of a camera ray as order 1 would fail this.
    let t = ng.layer(TRANSMITTANCE_LAYER).unwrap();
    let mean_t = t.iter().map(|p| p.x as f64).sum::<f64>() / t.len() as f64;
    let o0 = ng.layer("order0").unwrap().iter().map(|p| p.y as f64).sum::<f64>() / t.len() as f64 / 0.4;
    let se = (mean_t * (1.0 - mean_t) / 384.0).sqrt();
    assert!(
        (o0 - mean_t).abs() < 4.0 * se + 0.02 * mean_t,
        "order 0 {o0} vs transmittance {mean_t} ± {se}"
    );
    assert!(mean_t < 0.9, "the ball must cover part of the image: {mean_t}");
}

#[test]
fn a_time_limit_ended_before_any_sample_is_an_error_naming_it() {
    let mut s = scene(ball(1e4, 1.0, 0.9), Rgb::splat(2.0), Rgb::splat(0.3), 0.5, 30.0, (6, 4), 1);
    s.source = "t.toml".into();
    s.render.time_limit = Some(1e-9);
    let e = crate::reference::render(&s, &NoProgress, &mut Timings::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("t.toml") && e.contains("render.time_limit") && e.contains("raise"),
        "{e}"
    );
}

#[test]
fn time_limit_holds_inside_a_pass_on_a_dense_medium() {
    // The camera inside a ball of albedo 1 and optical radius 7e4: each path random-walks for
    // ~1e8 vertices before it escapes, so only a clock inside the path can stop it. Before that
    // check this test ran for hours.
    let mut s = scene(ball(1e4, 1.0, 0.9), Rgb::splat(2.0), Rgb::splat(0.3), 0.5, 30.0, (6, 4), 1);
    s.render.time_limit = Some(0.2);
    // No pixel finished its first path: only the clock inside the path can have ended the render
    // (without it, it runs for hours); no wall-clock bound, which a loaded machine would break.
    let (img, stats) = render_with_stats(&s, &NoProgress, &mut Timings::default());
    assert!(stats.min_spp == 0 && stats.spp <= 1, "{stats:?}");
    assert!(img.pixels.iter().all(|p| p.is_finite() && p.min_element() >= 0.0));
    assert!(img.layer(SAMPLES_LAYER).is_some());
    // σt = 1e6 at albedo 0.999, and --max-depth bounding a path without a limit.
    let mut d = scene(ball(1e6, 0.999, 0.9), Rgb::splat(2.0), Rgb::splat(0.3), 40.0, 30.0, (6, 4), 1);
    d.render.time_limit = Some(0.2);
    let (dense_img, dense) = render_with_stats(&d, &NoProgress, &mut Timings::default());
    assert!(dense.spp <= 1, "{dense:?}");
    assert!(dense_img.pixels.iter().all(|p| p.is_finite() && p.min_element() >= 0.0));
    s.render.time_limit = None;
    s.render.max_depth = Some(200);
    let (_, spp) = render(&s);
    assert_eq!(spp, 1);
}

#[test]
fn scene_keys_and_bad_input() {
    let text = "[render]\nmethod = \"reference\"\nmax_depth = 3\ntime_limit = 2.5\nstderr = true\n";
    let d = SceneDesc::from_toml(text, "t.toml").unwrap();
    assert_eq!(d.render.method, Method::Reference);
    assert_eq!(d.render.max_depth, Some(3));
    let bad = SceneDesc::from_toml("[render]\ntime_limit = -1.0\n", "t.toml").unwrap();
    let e = Scene::build(bad, "t.toml", Path::new(".")).unwrap_err().to_string();
    assert!(e.contains("t.toml") && e.contains("render.time_limit"), "{e}");
}
