//! `transport` benchmarks on the default scene's 100×80×60 cloud (44 k full voxels): the solve
//! to the default tolerance, the solve cut at 3 iterations (with the one above, the cost of an
//! iteration apart from the set-up), and the whole render at 160×120. The iterations and the last
//! change of I0 are printed first. Run with `cargo bench --features internals --bench transport`
//! (docs/performance.md, "`transport` against `single`").

use cloudgi::transport::solve::{solve, TransportSettings};
use cloudgi::{Method, NoProgress, Scene, SceneDesc};
use criterion::{criterion_group, criterion_main, Criterion};
use std::time::Duration;

fn transport(c: &mut Criterion) {
    let mut desc = SceneDesc::default();
    (desc.camera.width, desc.camera.height) = (160, 120);
    let mut scene = Scene::from_desc(desc).unwrap();
    scene.render.method = Method::Transport;
    let cut = TransportSettings {
        max_iterations: 3,
        ..TransportSettings::default()
    };
    let run = |s: &TransportSettings| solve(&scene.medium, &scene.sun, &scene.sky, scene.ground.as_ref(), s, &NoProgress).unwrap();
    for (name, s) in [("to the tolerance", TransportSettings::default()), ("cut at 3 iterations", cut)] {
        let f = run(&s);
        println!(
            "solve {name}: {} iterations, last change of I0 {:.2e}",
            f.iterations(),
            f.history.last().copied().unwrap_or(0.0)
        );
    }
    let mut g = c.benchmark_group("transport");
    g.sample_size(10).measurement_time(Duration::from_secs(15));
    g.bench_function("solve, default cloud, to the tolerance", |b| {
        b.iter(|| run(&TransportSettings::default()))
    });
    g.bench_function("solve, default cloud, 3 iterations", |b| b.iter(|| run(&cut)));
    g.bench_function("render default scene 160x120", |b| {
        b.iter(|| cloudgi::render::render(&scene, &NoProgress).unwrap())
    });
    g.finish();
}

criterion_group!(benches, transport);
criterion_main!(benches);
