//! Diffusion benchmarks on the default 100×80×60 cloud: stage 1 (incident light), the three-band
//! MGPCG solve to 1e-6, and the whole `diffusion` render at 480×360. Prints the convergence
//! history of the solve first.

use cloudgi::diffusion::{solve_diffusion, DiffusionSettings};
use cloudgi::render::diffusion::compute_incident;
use cloudgi::{Method, NoProgress, Scene};
use criterion::{criterion_group, criterion_main, Criterion};

fn diffusion(c: &mut Criterion) {
    let mut scene = Scene::default_scene().unwrap();
    let inc = compute_incident(&scene, None);
    let sol = solve_diffusion(&scene.medium, &inc, None, &DiffusionSettings::default()).unwrap();
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
    g.bench_function("solve 3 bands to 1e-6, default cloud", |b| {
        b.iter(|| solve_diffusion(&scene.medium, &inc, None, &DiffusionSettings::default()).unwrap())
    });
    scene.render.method = Method::Diffusion;
    g.bench_function("render default scene 480x360", |b| {
        b.iter(|| cloudgi::render(&scene, &NoProgress).unwrap())
    });
    g.finish();
}

criterion_group!(benches, diffusion);
criterion_main!(benches);
