//! Measures the sparse (interpolated) edge gather against one cube per segment on the default
//! scene, and prints the default cloud's density statistics behind `render.low_density_threshold`.
//!
//! `cargo run --release --features internals --example edges_sparse [WIDTH] [CUBE_RES] [REFERENCE_CUBE_RES]`
//!
//! With a reference resolution, errors are measured against one cube per segment at that finer
//! resolution, and the per-segment gather at CUBE_RES is listed too (time against error).
//!
//! The cubes here are rendered by single-scattering ray marching (the `single` method per cube
//! pixel), a stand-in for the full cube renderer with a realistic cost per cube.

use cloudgi::cube::CubeImage;
use cloudgi::edges::gather::EdgeAov;
use cloudgi::edges::{gather_image, CubeRequest, CubeSource, EdgeGather, EdgeSettings, PixelRay, SparseSettings, SunInput};
use cloudgi::lit::sunlight::SunTransmittance;
use cloudgi::math::{luminance, Rgb, Vec3};
use cloudgi::render::single;
use cloudgi::scene::{Scene, SceneDesc};
use std::time::Instant;

struct MarchCubes<'a> {
    scene: &'a Scene,
    sun_t: &'a SunTransmittance,
}

impl CubeSource for MarchCubes<'_> {
    fn render_cube(&self, req: &CubeRequest) -> CubeImage {
        let mut c = CubeImage::along(req.res, req.x_axis);
        for face in 0..6 {
            for j in 0..req.res {
                for i in 0..req.res {
                    let k = c.index(face, i, j);
                    let d = c.direction(face, i, j);
                    c.pixels[k] = single::radiance(self.scene, self.sun_t, req.center, d, 0.5);
                }
            }
        }
        c
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let width: u32 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(96);
    let res: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(8);
    let ref_res: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(res);
    let scene = Scene::from_desc({
        let mut d = SceneDesc::default();
        d.camera.height = d.camera.height * width / d.camera.width;
        d.camera.width = width;
        d
    })
    .expect("default scene");
    let m = &scene.medium;

    // Density statistics of the default cloud.
    let nz: Vec<f32> = m.density.packed().to_vec();
    let max = nz.iter().copied().fold(0.0, f32::max);
    println!("default cloud: {} non-zero voxels, max density {max:.3}", nz.len());
    for t in [0.05, 0.1, 0.2, 0.3, 0.5, 0.75] {
        let below = nz.iter().filter(|v| **v < t).count();
        println!(
            "  T = {t:.2}: {:.1} % of non-zero voxels below T; optical depth of one voxel at T: {:.3}",
            100.0 * below as f64 / nz.len() as f64,
            t * m.optics.sigma_t * m.min_voxel()
        );
    }

    let sun_t = SunTransmittance::compute(m, scene.sun.dir);
    let cubes = MarchCubes {
        scene: &scene,
        sun_t: &sun_t,
    };
    let sun_irr = |p: Vec3| scene.sun.irradiance * sun_t.at_voxel(m.to_voxel(p));
    let dense = |_: Vec3, _: Vec3| m.optics.albedo * Rgb::splat(1.0);
    let settings = EdgeSettings {
        cube_res: res,
        step_m: scene.render.step_voxels * m.min_voxel(),
        // The paper's edges only (the measurements of docs/edges.md).
        surface_depth: 0.0,
        ..Default::default()
    };
    let t = Instant::now();
    let gather = EdgeGather::new(
        m,
        settings,
        &cubes,
        SunInput {
            dir: scene.sun.dir,
            irradiance_at: &sun_irr,
        },
        &dense,
    );
    println!(
        "order table (res {res}, {} orders): {:.2} s",
        gather.kernel().max_order,
        t.elapsed().as_secs_f64()
    );
    let ref_settings = EdgeSettings {
        cube_res: ref_res,
        ..settings
    };
    let ref_gather = EdgeGather::new(
        m,
        ref_settings,
        &cubes,
        SunInput {
            dir: scene.sun.dir,
            irradiance_at: &sun_irr,
        },
        &dense,
    );
    let cam = &scene.camera;
    let ray = |x: u32, y: u32| {
        let r = cam.ray(x as f32 + 0.5, y as f32 + 0.5);
        let t_max = scene
            .ground
            .as_ref()
            .and_then(|g| g.intersect(r.origin, r.dir))
            .unwrap_or(f32::INFINITY);
        PixelRay {
            o: r.origin,
            d: r.dir,
            t_max,
            background: single::background(&scene, r.origin, r.dir),
        }
    };
    let (w, h) = (cam.width, cam.height);
    {
        use rayon::prelude::*;
        let t = Instant::now();
        let (segs, jobs): (usize, usize) = (0..w * h)
            .into_par_iter()
            .map(|i| {
                let r = ray(i % w, i / w);
                let p = gather.plan(r.o, r.d, r.t_max);
                (p.jobs.iter().filter(|j| j.top.is_some()).count(), p.jobs.len())
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        println!(
            "{w}×{h}: planning every ray (profile, segments, bridges; no cube): {:.2} s; {segs} unbridged segments, {jobs} edge jobs",
            t.elapsed().as_secs_f64()
        );
    }
    if args.get(4).map(String::as_str) == Some("plan-only") {
        return;
    }
    let t = Instant::now();
    let (reference, st) = gather_image(&ref_gather, w, h, &ray, None);
    let t_ref = t.elapsed().as_secs_f64();
    println!(
        "{w}×{h}, reference cube res {ref_res}: one cube per segment: {t_ref:.2} s, {} cubes",
        st.cubes
    );
    let err = |a: &[EdgeAov]| {
        let (mut se, mut sn, mut te, mut n) = (0.0, 0.0, 0.0, 0usize);
        for (x, r) in a.iter().zip(&reference) {
            let (le, lr) = (luminance(x.edge) as f64, luminance(r.edge) as f64);
            if lr > 1e-4 {
                se += (le - lr).abs();
                sn += lr;
                te += ((luminance(x.total()) - luminance(r.total())) as f64).abs() / luminance(r.total()).max(1e-6) as f64;
                n += 1;
            }
        }
        (se / sn.max(1e-12), te / n.max(1) as f64)
    };
    if ref_res != res {
        let t = Instant::now();
        let (img, st) = gather_image(&gather, w, h, &ray, None);
        let secs = t.elapsed().as_secs_f64();
        let (e_edge, e_total) = err(&img);
        println!(
            "one cube per segment at res {res}: {secs:.2} s, {} cubes; edge-part L1 error {:.2} %, mean relative error of the pixel {:.3} %",
            st.cubes,
            100.0 * e_edge,
            100.0 * e_total
        );
    }
    for (block, tol) in [(8, 10.0), (8, 30.0), (4, 10.0), (4, 30.0)] {
        let sp = SparseSettings {
            block,
            depth_tolerance: tol,
            ..SparseSettings::default()
        };
        let t = Instant::now();
        let (img, st) = gather_image(&gather, w, h, &ray, Some(sp));
        let secs = t.elapsed().as_secs_f64();
        let (e_edge, e_total) = err(&img);
        println!(
            "sparse block {block}, tolerance {tol} m: {secs:.2} s ({:.1}× faster), {} cubes, {} interpolated, {} direct; \
             edge-part L1 error {:.2} %, mean relative error of the pixel {:.3} %",
            t_ref / secs,
            st.cubes,
            st.interpolated,
            st.direct,
            100.0 * e_edge,
            100.0 * e_total
        );
    }
}
