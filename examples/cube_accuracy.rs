//! Measure the border cubes on the default scene: how many, how long at each cube resolution,
//! and their bin error against brute-force cubes (res 32, steps of 0.25 voxel) on a sample.
//!
//! `cargo run --release --features internals --example cube_accuracy [sample_every]`
//!
//! I0 is a stand-in (this measures the renderer, not the diffusion solution): the sky radiance
//! plus the sun's irradiance scaled by the transmittance towards it, which gives the lit/shadowed
//! contrast of a real solution.

use cloudgi::cube::border::{find_border_voxels, render_border_cubes};
use cloudgi::cube::ground::render_ground;
use cloudgi::cube::render::{render_cube_brute, BinMask, CubeOptions, CubeRenderer};
use cloudgi::lit::sunlight::SunTransmittance;
use cloudgi::math::Rgb;
use cloudgi::render::diffusion::scene_lit_volume;
use cloudgi::{NoProgress, Scene, SceneDesc};
use std::time::Instant;

fn main() {
    let every: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(200);
    let scene = Scene::from_desc(SceneDesc::default()).expect("default scene");
    let t = Instant::now();
    let sun_t = SunTransmittance::compute(&scene.medium, scene.sun.dir);
    let l_sky = scene.sky.radiance(cloudgi::math::Vec3::Y);
    let i0: Vec<Rgb> = sun_t
        .grid
        .values()
        .map(|t| l_sky * 0.8 + scene.sun.irradiance * (t * 0.5 / std::f32::consts::PI))
        .collect();
    let lit = scene_lit_volume(&scene, i0, &sun_t);
    println!("lit volume {:.2} s", t.elapsed().as_secs_f64());
    let found = find_border_voxels(&scene.medium.density);
    let bins: u64 = found.iter().map(|(_, f)| BinMask::for_faces(*f).count() as u64).sum();
    println!(
        "grid {:?}: {} border voxels, {} needed bins of {} ({:.0} %)",
        scene.medium.dims(),
        found.len(),
        bins,
        found.len() * 96,
        100.0 * bins as f64 / (found.len() * 96) as f64
    );
    let threads = rayon::current_num_threads();
    // Ground first, so cubes see the shadowed ground.
    let t = Instant::now();
    let g = render_ground(&lit, scene.ground.as_ref().unwrap(), &CubeOptions::default(), &NoProgress);
    println!(
        "ground hemicubes 32x32 at res 16: {:.2} s on {threads} threads",
        t.elapsed().as_secs_f64()
    );
    let lit = lit.with_ground(Some(g));
    // Reference on a sample of cubes.
    let sample: Vec<usize> = (0..found.len()).step_by(every).collect();
    let t = Instant::now();
    let refs: Vec<Vec<Rgb>> = sample
        .iter()
        .map(|&n| {
            let ([i, j, k], f) = found[n];
            render_cube_brute(&lit, scene.medium.voxel_center(i, j, k), 32, BinMask::for_faces(f), 0.25).bin_averages()
        })
        .collect();
    println!("brute reference for {} cubes: {:.1} s", sample.len(), t.elapsed().as_secs_f64());
    let configs: Vec<(usize, f32, f32)> = match std::env::var("CUBE_CONFIGS") {
        Ok(s) => s
            .split(';')
            .map(|c| {
                let v: Vec<&str> = c.split(',').collect();
                (v[0].parse().unwrap(), v[1].parse().unwrap(), v[2].parse().unwrap())
            })
            .collect(),
        Err(_) => vec![
            (4, 1.0, 0.0),
            (8, 1.0, 0.0),
            (8, 1.0, 1.0),
            (16, 1.0, 0.0),
            (16, 1.0, 1.0),
            (32, 1.0, 0.0),
        ],
    };
    for (res, step, lod_bias) in configs {
        let opts = CubeOptions {
            res,
            step_level_voxels: step,
            lod_bias,
            ..Default::default()
        };
        let r = CubeRenderer::new(&lit, &opts);
        let (mut sum, mut cnt, mut max) = (0f64, 0usize, 0f64);
        let (mut wsum, mut wref) = (0f64, 0f64);
        for (q, &n) in sample.iter().enumerate() {
            let ([i, j, k], f) = found[n];
            let m = BinMask::for_faces(f);
            let got = r.bin_radiance(scene.medium.voxel_center(i, j, k), m);
            for b in m.iter() {
                let (a, e) = (got[b], refs[q][b]);
                let d = ((a - e).abs() / e.max(Rgb::splat(1e-6))).max_element() as f64;
                sum += d;
                cnt += 1;
                max = max.max(d);
                wsum += (a - e).abs().element_sum() as f64;
                wref += e.element_sum() as f64;
            }
        }
        let t = Instant::now();
        let cpu = cpu_seconds();
        let all = if res <= 16 {
            let c = render_border_cubes(&lit, &opts, &NoProgress);
            Some((t.elapsed().as_secs_f64(), cpu_seconds() - cpu, c.len()))
        } else {
            None
        };
        println!(
            "res {res:2} step {step} bias {lod_bias}: bin error mean {:.4} max {:.4} (flux-weighted {:.4}); all cubes {}",
            sum / cnt as f64,
            max,
            wsum / wref,
            all.map_or("skipped".to_string(), |(s, c, n)| format!(
                "{s:.2} s wall, {c:.2} s CPU ({n} cubes, {threads} threads)"
            ))
        );
    }
}

/// User + system CPU seconds of this process (Linux /proc; 0 elsewhere): a load-independent
/// measure on a shared machine.
fn cpu_seconds() -> f64 {
    let s = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let f: Vec<&str> = s.rsplit(')').next().unwrap_or("").split_whitespace().collect();
    let tick = |i: usize| f.get(i).and_then(|x| x.parse::<f64>().ok()).unwrap_or(0.0);
    (tick(11) + tick(12)) / 100.0
}
