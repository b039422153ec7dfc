//! Reference tracer benchmarks (small, so they can run on a laptop in seconds): the default cloud at
//! 96×72 with 1 sample per pixel, and one slab case.

use cloudgi::reference::slab::{slab, Incidence, SlabParams};
use cloudgi::scene::Method;
use cloudgi::{NoProgress, Scene, SceneDesc};
use criterion::{criterion_group, criterion_main, Criterion};

fn reference(c: &mut Criterion) {
    let scene = Scene::from_desc({
        let mut d = SceneDesc::default();
        d.render.method = Method::Reference;
        d.camera.width = 96;
        d.camera.height = 72;
        d.render.spp = 1;
        d
    })
    .unwrap();
    let mut g = c.benchmark_group("reference");
    g.sample_size(10);
    g.bench_function("default scene 96x72 1 spp", |b| {
        b.iter(|| cloudgi::render::render(&scene, &NoProgress).unwrap())
    });
    let p = SlabParams {
        thickness: 10.0,
        albedo: 0.999,
        g: 0.9,
        incidence: Incidence::Collimated,
    };
    g.bench_function("slab tau 10 g 0.9 10k photons", |b| b.iter(|| slab(&p, 10_000, 1).unwrap()));
    g.finish();
}

criterion_group!(benches, reference);
criterion_main!(benches);
