//! Foundation checks: analytic transport cases, loaders, determinism and the procedural cloud.

use super::common::npy_bytes;
use crate::lighting::{Sky, Sun};
use crate::lit::sunlight::SunTransmittance;
use crate::math::{Rgb, Vec3};
use crate::medium::{loaders, Grid3, Medium};
use crate::optics::Hg;
use crate::render::single;
use crate::scene::{Scene, SceneDesc};
use std::path::Path;

/// A scene around a homogeneous 10 m cube of density 1 at the origin, no ground.
fn box_scene(sigma_t: f32, albedo: f32, g: f32, sun_dir: Vec3) -> Scene {
    let mut desc = SceneDesc {
        ground: None,
        ..Default::default()
    };
    desc.sky.radiance = [0.2, 0.3, 0.5];
    desc.medium.sigma_t = sigma_t;
    desc.medium.albedo = [albedo; 3];
    desc.medium.g = g;
    desc.medium.resolution = [10, 10, 10];
    let mut scene = Scene::build(desc, "test", Path::new(".")).unwrap();
    scene.medium = Medium::new(
        Grid3::filled([10, 10, 10], 1.0),
        Vec3::ZERO,
        Vec3::ONE,
        sigma_t,
        Rgb::splat(albedo),
        g,
    );
    scene.sun = Sun {
        dir: sun_dir.normalize(),
        irradiance: Rgb::new(3.0, 2.0, 1.0),
    };
    scene.sky = Sky::constant(Rgb::new(0.2, 0.3, 0.5));
    scene
}

#[test]
fn transmittance_through_absorbing_box_is_exp_sigma_l() {
    // Albedo 0: the pixel is the sky attenuated by exp(−σt·L) for chord L.
    let scene = box_scene(0.15, 0.0, 0.0, Vec3::Y);
    let sun_t = SunTransmittance::compute(&scene.medium, scene.sun.dir);
    for (o, d) in [
        (Vec3::new(5.0, 5.0, 30.0), Vec3::NEG_Z),
        (Vec3::new(-20.0, 3.0, 2.0), Vec3::new(1.0, 0.1, 0.2).normalize()),
        (Vec3::new(5.5, 20.0, 4.5), Vec3::new(-0.05, -1.0, 0.03).normalize()),
    ] {
        let chord = scene.medium.intersect(o, d, 0.0, f32::INFINITY).map(|(a, b)| b - a).unwrap();
        let l = single::radiance(&scene, &sun_t, o, d, 0.5);
        let expect = Rgb::new(0.2, 0.3, 0.5) * (-0.15 * chord).exp();
        // Piecewise-constant march of a constant density is exact: only f32 rounding remains.
        assert!(((l - expect) / expect).abs().max_element() < 1e-4, "{l} vs {expect}");
    }
}

#[test]
fn single_scattering_in_thin_box_matches_analytic() {
    // Sun straight down; camera ray along −z through y = 5: every point is 5 m below the top,
    // so L = a·p(θ)·E·e^{−σ·5}·(1 − e^{−σ·D}) + L_sky·e^{−σ·D}, D = 10 m, θ = 90°.
    let (sigma, a, g) = (0.02f32, 0.9f32, 0.6f32);
    let scene = box_scene(sigma, a, g, Vec3::Y);
    let sun_t = SunTransmittance::compute(&scene.medium, scene.sun.dir);
    let (o, d) = (Vec3::new(5.0, 5.0, 40.0), Vec3::NEG_Z);
    let p = Hg::new(g).eval(Vec3::Y, -d);
    let ss = Rgb::new(3.0, 2.0, 1.0) * (a * p * (-sigma * 5.0).exp() * (1.0 - (-sigma * 10.0).exp()));
    let expect = ss + Rgb::new(0.2, 0.3, 0.5) * (-sigma * 10.0f32).exp();
    let mut mean = Rgb::ZERO;
    for k in 0..8 {
        let l = single::radiance(&scene, &sun_t, o, d, (k as f32 + 0.5) / 8.0);
        // Error sources: trilinear interpolation of e^{−σ·h} between voxel centres (relative
        // (σ·1 m)²/8 = 5e-5) and f32 rounding: 1e-3 relative is a safe bound.
        let ss_got = l - Rgb::new(0.2, 0.3, 0.5) * (-sigma * 10.0f32).exp();
        assert!(
            ((ss_got - ss) / ss).abs().max_element() < 1e-3,
            "single scattering {ss_got} vs {ss}"
        );
        mean += l / 8.0;
    }
    assert!(((mean - expect) / expect).abs().max_element() < 1e-3);
}

fn scene_with_grid(dir: &Path, grid_file: &str) -> crate::Result<Scene> {
    let text = format!("[medium]\ngrid = \"{grid_file}\"\nvoxel_size = 2.0\norigin = [1.0, 2.0, 3.0]\n");
    let path = dir.join("scene.toml");
    std::fs::write(&path, text).unwrap();
    Scene::load(Some(&path), |_| {})
}

fn test_grid() -> Grid3 {
    let dims = [7, 5, 3];
    let data = (0..105).map(|i| (i as f32 * 0.37).sin().abs() * 2.0).collect();
    Grid3::from_vec(dims, data, "test").unwrap()
}

#[test]
fn loaders_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let g = test_grid();
    loaders::write_npy(&dir.path().join("a.npy"), &g).unwrap();
    loaders::write_raw(&dir.path().join("a.raw"), &g).unwrap();
    loaders::write_vol(&dir.path().join("a.vol"), &g, Vec3::new(1.0, 2.0, 3.0), Vec3::new(15.0, 12.0, 9.0)).unwrap();
    // The same `.raw` whose sidecar a Windows editor saved with a UTF-8 byte-order mark.
    std::fs::copy(dir.path().join("a.raw"), dir.path().join("b.raw")).unwrap();
    let sidecar = std::fs::read(dir.path().join("a.json")).unwrap();
    std::fs::write(dir.path().join("b.json"), [&b"\xef\xbb\xbf"[..], &sidecar].concat()).unwrap();
    for f in ["a.npy", "a.raw", "a.vol", "b.raw"] {
        let s = scene_with_grid(dir.path(), f).unwrap();
        assert_eq!(s.medium.density.to_grid(), g, "{f}");
        assert_eq!(s.medium.origin, Vec3::new(1.0, 2.0, 3.0), "{f}");
        assert_eq!(s.medium.voxel_size, Vec3::splat(2.0), "{f}");
    }
}

/// `medium.voxel_size = [x, y, z]` (a simulation's cells that are not cubes) places an `.npy` or
/// `.raw` grid as a `.vdb` ScaleMap would; with `up_axis = "z"` the edges turn with the grid.
#[test]
fn voxels_that_are_not_cubes_are_placed_per_axis() {
    let dir = tempfile::tempdir().unwrap();
    let g = test_grid();
    loaders::write_npy(&dir.path().join("a.npy"), &g).unwrap();
    loaders::write_raw(&dir.path().join("a.raw"), &g).unwrap();
    for f in ["a.npy", "a.raw"] {
        // The file's grid is 7 × 5 × 3; z-up, its third axis becomes the world's y.
        for (up, edges, world, dims) in [
            ("y", [50.0, 12.5, 40.0], [50.0, 12.5, 40.0], [7, 5, 3]),
            ("z", [50.0, 40.0, 12.5], [50.0, 12.5, 40.0], [7, 3, 5]),
        ] {
            let text = format!(
                "[medium]\ngrid = \"{f}\"\nvoxel_size = [{}, {}, {}]\nup_axis = \"{up}\"\n",
                edges[0], edges[1], edges[2]
            );
            let path = dir.path().join("scene.toml");
            std::fs::write(&path, text).unwrap();
            let s = Scene::load(Some(&path), |_| {}).unwrap();
            assert_eq!(s.medium.voxel_size, Vec3::from(world), "{f} {up}");
            assert_eq!(s.medium.dims(), dims, "{f} {up}");
        }
    }
}

#[test]
fn npy_float64_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let header = "{'descr': '<f8', 'fortran_order': False, 'shape': (2, 1, 3), }";
    let body: Vec<u8> = [0.0f64, 0.5, 1.0, 1.5, 2.0, 2.5].iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(dir.path().join("b.npy"), npy_bytes(header, &body)).unwrap();
    let s = scene_with_grid(dir.path(), "b.npy").unwrap();
    assert_eq!(s.medium.dims(), [3, 1, 2]);
    assert_eq!(s.medium.density.get(2, 0, 1), 2.5);
}

/// NumPy's other numeric types (a uint8 CT stack, a float16 export, a boolean mask) are read by
/// value, and a Fortran-order array (first index fastest) lands where a C-order one does.
#[test]
fn npy_of_integers_bools_halves_and_fortran_order_is_read() {
    let dir = tempfile::tempdir().unwrap();
    // Shape (nz, ny, nx) = (2, 1, 3): C order holds [z][y][x] = z·3 + x.
    let c: Vec<u8> = (0..6).collect();
    let fortran: Vec<u8> = [0, 3, 1, 4, 2, 5].to_vec(); // z fastest
    let header = |descr: &str, fortran: bool| {
        let f = if fortran { "True" } else { "False" };
        format!("{{'descr': '{descr}', 'fortran_order': {f}, 'shape': (2, 1, 3), }}")
    };
    // 0 to 5 in binary16.
    let halves: Vec<u8> = [0x0000u16, 0x3c00, 0x4000, 0x4200, 0x4400, 0x4500]
        .iter()
        .flat_map(|h| h.to_le_bytes())
        .collect();
    let files: [(&str, Vec<u8>); 5] = [
        ("u1.npy", npy_bytes(&header("|u1", false), &c)),
        (
            "i2.npy",
            npy_bytes(
                &header(">i2", false),
                &c.iter().flat_map(|&v| (v as i16).to_be_bytes()).collect::<Vec<_>>(),
            ),
        ),
        ("f2.npy", npy_bytes(&header("<f2", false), &halves)),
        ("fortran_u1.npy", npy_bytes(&header("|u1", true), &fortran)),
        (
            "fortran_f4.npy",
            npy_bytes(
                &header("<f4", true),
                &fortran.iter().flat_map(|&v| (v as f32).to_le_bytes()).collect::<Vec<_>>(),
            ),
        ),
    ];
    for (name, bytes) in files {
        std::fs::write(dir.path().join(name), bytes).unwrap();
        let s = scene_with_grid(dir.path(), name).unwrap();
        assert_eq!(s.medium.dims(), [3, 1, 2], "{name}");
        for (x, z) in [(0, 0), (2, 0), (1, 1), (2, 1)] {
            assert_eq!(s.medium.density.get(x, 0, z), (z * 3 + x) as f32, "{name} ({x}, 0, {z})");
        }
    }
    // A boolean mask: 0 and 1.
    std::fs::write(dir.path().join("b1.npy"), npy_bytes(&header("|b1", false), &[0, 1, 0, 1, 1, 0])).unwrap();
    let s = scene_with_grid(dir.path(), "b1.npy").unwrap();
    assert_eq!((s.medium.density.get(1, 0, 0), s.medium.density.get(2, 0, 1)), (1.0, 0.0));
}

#[test]
fn procedural_cloud_is_deterministic_with_paper_proportions() {
    let a = Scene::default_scene().unwrap();
    let b = Scene::default_scene().unwrap();
    assert_eq!(a.medium.density, b.medium.density);
    let g = &a.medium.density;
    let d = g.dims();
    let (mut lo, mut hi) = ([usize::MAX; 3], [0usize; 3]);
    for k in 0..d[2] {
        for j in 0..d[1] {
            for i in 0..d[0] {
                if g.get(i, j, k) > 0.0 {
                    for (a, v) in [i, j, k].into_iter().enumerate() {
                        lo[a] = lo[a].min(v);
                        hi[a] = hi[a].max(v);
                    }
                }
            }
        }
    }
    let ext: Vec<usize> = (0..3).map(|a| hi[a] - lo[a] + 1).collect();
    // The paper's non-zero region is 91×51×25 in a 100×80×60 box; allow a few voxels of noise erosion.
    for (e, want) in ext.iter().zip([91, 51, 25]) {
        assert!((*e as i64 - want).abs() <= 6, "extent {ext:?} vs 91×51×25");
    }
    // A dense core and tenuous edges: densities span at least two orders of magnitude.
    let nz: Vec<f32> = g.packed().to_vec();
    let max = nz.iter().copied().fold(0.0, f32::max);
    let small = nz.iter().filter(|&&v| v < 0.01 * max).count();
    assert!(max > 1.0 && small > nz.len() / 50, "max {max}, {small} of {} below 1 %", nz.len());
}

#[test]
fn single_render_is_identical_with_any_thread_count() {
    let scene = Scene::load(None, |d| {
        d.camera.width = 64;
        d.camera.height = 48;
        d.render.method = crate::Method::Single;
        d.render.aa_samples = 2;
    })
    .unwrap();
    let run = |n: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(n).build().unwrap();
        pool.install(|| crate::render::render(&scene, &crate::NoProgress).unwrap().image)
    };
    let (a, b) = (run(1), run(2));
    assert_eq!(a.pixels, b.pixels);
    assert!(a.pixels.iter().all(|p| p.is_finite() && p.min_element() >= 0.0));
}

/// A ground that cuts through the grid: the scene holds no density a voxel or more under the
/// plane (the opaque ground hides it from every path; transport and full would light it and let
/// it shine into the cloud), and the same density as the file from the plane up.
#[test]
fn the_scene_empties_the_density_under_its_ground() {
    let mut desc = SceneDesc::default();
    desc.medium.resolution = [20, 16, 12];
    desc.medium.voxel_size = 50.0.into();
    desc.medium.origin = [-500.0, -300.0, -300.0];
    desc.ground.as_mut().expect("the default scene has a ground").height = 0.0;
    let (loaded, _) = Medium::from_desc_with(&desc.medium, "cut.toml", Path::new("."), None).unwrap();
    let s = Scene::build(desc, "cut.toml", Path::new(".")).unwrap();
    let m = &s.medium;
    let (mut under, mut above) = (0.0f64, 0.0f64);
    for k in 0..12 {
        for j in 0..16 {
            for i in 0..20 {
                let (a, b) = (loaded.density.get(i, j, k), m.density.get(i, j, k));
                // Row j's centre is at −275 + 50 j m; rows 0–4 end a voxel further, at or under 0.
                if j < 5 {
                    under += a as f64;
                    assert_eq!(b, 0.0, "voxel ({i}, {j}, {k})");
                } else {
                    above += a as f64;
                    assert_eq!(a, b, "voxel ({i}, {j}, {k})");
                }
            }
        }
    }
    assert!(under > 0.0 && above > 0.0, "the cloud must straddle the ground: {under} {above}");
}
