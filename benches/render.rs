//! Foundation benchmarks: the default `single` render at 480×360, and the sun-transmittance precompute.

use cloudgi::lit::sunlight::SunTransmittance;
use cloudgi::{NoProgress, Scene, SceneDesc};
use criterion::{criterion_group, criterion_main, Criterion};

fn single(c: &mut Criterion) {
    let scene = Scene::from_desc(SceneDesc::default()).unwrap();
    let mut g = c.benchmark_group("single");
    g.sample_size(10);
    g.bench_function("default scene 480x360", |b| {
        b.iter(|| cloudgi::render::render(&scene, &NoProgress).unwrap())
    });
    g.bench_function("sun transmittance grid", |b| {
        b.iter(|| SunTransmittance::compute(&scene.medium, scene.sun.dir))
    });
    g.bench_function("procedural cloud 100x80x60", |b| {
        b.iter(|| cloudgi::medium::procedural::cumulus([100, 80, 60], 1))
    });
    g.finish();
}

criterion_group!(benches, single);
criterion_main!(benches);
