//! Diffusion benchmarks on the default 100×80×60 cloud: stage 1 (incident light) and the whole
//! `diffusion` render at 480×360, with the convergence history of the solve printed first; and
//! group `solver`: the three-band MGPCG solve to the default tolerance (1e-4) at three resolutions of the same cloud
//! (50×40×30, 100×80×60 and 200×160×120, voxels scaled to keep its extent), whose ratios are the
//! solver's scaling (the target: 200×160×120 in at most 9× the time of 100×80×60).

use cloudgi::diffusion::{solve_diffusion, DiffusionSettings};
use cloudgi::render::diffusion::{boundary_light, compute_incident};
use cloudgi::{Method, NoProgress, Scene, SceneDesc};
use criterion::{criterion_group, criterion_main, Criterion};

fn diffusion(c: &mut Criterion) {
    let mut scene = Scene::from_desc(SceneDesc::default()).unwrap();
    let inc = compute_incident(&scene, None);
    let sol = solve_diffusion(&scene.medium, &inc, &boundary_light(&scene), None, &DiffusionSettings::default()).unwrap();
    println!("{}", sol.summary());
    for (band, s) in sol.stats.iter().enumerate() {
        let h: Vec<String> = s.history.iter().map(|r| format!("{r:.2e}")).collect();
        println!(
            "band {band}: factor {:.3} per iteration; history {}",
            s.convergence_factor(),
            h.join(" ")
        );
    }
    let mut g = c.benchmark_group("diffusion");
    g.sample_size(10);
    g.bench_function("stage 1 incident light, default cloud", |b| {
        b.iter(|| compute_incident(&scene, None))
    });
    scene.render.method = Method::Diffusion;
    g.bench_function("render default scene 480x360", |b| {
        b.iter(|| cloudgi::render::render(&scene, &NoProgress).unwrap())
    });
    g.finish();
}

fn solver(c: &mut Criterion) {
    let mut g = c.benchmark_group("solver");
    g.sample_size(10);
    for (r, h) in [([50, 40, 30], 20.0), ([100, 80, 60], 10.0), ([200, 160, 120], 5.0)] {
        let scene = Scene::from_desc({
            let mut d = SceneDesc::default();
            d.medium.resolution = r;
            d.medium.voxel_size = h.into();
            d
        })
        .unwrap();
        let inc = compute_incident(&scene, None);
        let sol = solve_diffusion(&scene.medium, &inc, &boundary_light(&scene), None, &DiffusionSettings::default()).unwrap();
        println!("{}x{}x{}: {}", r[0], r[1], r[2], sol.summary());
        let name = format!("solve 3 bands to 1e-4, {}x{}x{}", r[0], r[1], r[2]);
        g.bench_function(name, |b| {
            b.iter(|| solve_diffusion(&scene.medium, &inc, &boundary_light(&scene), None, &DiffusionSettings::default()).unwrap())
        });
    }
    g.finish();
}

criterion_group!(benches, diffusion, solver);
criterion_main!(benches);
