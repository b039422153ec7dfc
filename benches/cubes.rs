//! Viewing-cube benchmarks on the default scene (100×80×60, 8100 border voxels): one border
//! cube (its needed bins) and one full cube at the default resolution, all border cubes, and the
//! 32×32 ground hemicubes. I0 is a stand-in (sky + sun-lit term), which does not change the cost.

use cloudgi::cube::border::{find_border_voxels, render_border_cubes_with};
use cloudgi::cube::ground::render_ground;
use cloudgi::cube::render::{BinMask, CubeRenderer};
use cloudgi::lit::sunlight::SunTransmittance;
use cloudgi::math::{Rgb, Vec3};
use cloudgi::render::diffusion::scene_lit_volume;
use cloudgi::{NoProgress, Scene, SceneDesc};
use criterion::{criterion_group, criterion_main, Criterion};

fn cubes(c: &mut Criterion) {
    let scene = Scene::from_desc(SceneDesc::default()).unwrap();
    let sun_t = SunTransmittance::compute(&scene.medium, scene.sun.dir);
    let l_sky = scene.sky.radiance(Vec3::Y);
    let i0: Vec<Rgb> = sun_t
        .grid
        .values()
        .map(|t| l_sky * 0.8 + scene.sun.irradiance * (t * 0.5 / std::f32::consts::PI))
        .collect();
    let lit = scene_lit_volume(&scene, i0, &sun_t);
    let opts = scene.render.cubes.clone();
    let renderer = CubeRenderer::new(&lit, &opts);
    let border = find_border_voxels(&scene.medium.density);
    let ([i, j, k], faces) = border[border.len() / 2];
    let p = scene.medium.voxel_center(i, j, k);
    let mut g = c.benchmark_group("cubes");
    g.sample_size(10);
    g.bench_function(format!("one border cube res {} (needed bins)", opts.res), |b| {
        b.iter(|| renderer.bin_radiance(p, BinMask::for_faces(faces)))
    });
    g.bench_function(format!("one full cube res {}", opts.res), |b| {
        b.iter(|| renderer.render_cube(p, BinMask::ALL))
    });
    g.bench_function("pyramid build", |b| b.iter(|| CubeRenderer::new(&lit, &opts)));
    g.bench_function(format!("all {} border cubes res {}", border.len(), opts.res), |b| {
        b.iter(|| render_border_cubes_with(&renderer, &NoProgress))
    });
    let ground = scene.ground.clone().unwrap();
    g.bench_function(
        format!("ground {0}x{0} hemicubes res {1}", opts.ground_samples, opts.ground_res),
        |b| b.iter(|| render_ground(&lit, &ground, &opts, &NoProgress)),
    );
    g.finish();
}

criterion_group!(benches, cubes);
criterion_main!(benches);
