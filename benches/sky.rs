//! Sky benchmarks: atmosphere precompute (LUTs + 512×256 map), bin powers, importance sampling.

use cloudgi::lighting::{Atmosphere, AtmosphereParams, DirectionBins, Sky};
use cloudgi::math::Vec3;
use criterion::{criterion_group, criterion_main, Criterion};
use std::sync::Arc;

fn sky(c: &mut Criterion) {
    let sun = Vec3::new(0.3, 0.5, 0.4).normalize();
    let mut g = c.benchmark_group("sky");
    g.sample_size(10);
    g.bench_function("atmosphere LUTs", |b| b.iter(|| Atmosphere::new(AtmosphereParams::default())));
    let atm = Arc::new(Atmosphere::new(AtmosphereParams::default()));
    g.bench_function("atmosphere map 512x256", |b| b.iter(|| Sky::atmosphere(atm.clone(), 0.0, sun, 512)));
    let sky = Sky::atmosphere(atm, 0.0, sun, 512);
    let bins = DirectionBins::new();
    g.bench_function("bin powers 96", |b| b.iter(|| sky.bin_powers(&bins)));
    g.bench_function("sample x1000", |b| {
        b.iter(|| {
            let mut acc = 0.0;
            for k in 0..1000 {
                let u = glam::Vec2::new((k as f32 + 0.5) / 1000.0, ((k * 7919) % 1000) as f32 / 1000.0);
                acc += sky.sample(u).2;
            }
            acc
        })
    });
    g.finish();
}

criterion_group!(benches, sky);
criterion_main!(benches);
