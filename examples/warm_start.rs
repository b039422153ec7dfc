//! Warm against cold transport solves over two sequences, as a markdown table
//! (docs/sequences.md, "Warm starts"):
//! - `growing`: the procedural cumulus on a grid that grows by one voxel per axis and moves 6 m
//!   per frame (every frame a different grid size and origin);
//! - `sun`: the same cloud with only the sun moving, 1° in elevation and azimuth per frame.
//!
//! Per frame: transport iterations and solve seconds cold and warm, the block mean relative error
//! of the warm image against the cold one, and of the cold image against a solve to 1e-5 (the
//! tolerance's own effect on the image).
//!
//! `cargo run --release --features internals --example warm_start [FRAMES] [WIDTH]` (defaults 8 and 80; 4:3 images)

use cloudgi::math::Vec3;
use cloudgi::medium::procedural::cumulus;
use cloudgi::medium::Medium;
use cloudgi::render::warm::{render_warm, Warm};
use cloudgi::scene::{Scene, SceneDesc};
use cloudgi::tools::compare::compare;
use cloudgi::{Image, NoProgress};
use std::path::Path;

/// Voxel edge (m) and the first frame's grid.
const VOXEL: f32 = 16.0;
const DIMS: [usize; 3] = [50, 40, 30];

fn scene(width: u32, frame: usize, growing: bool) -> Scene {
    let mut d = SceneDesc::default();
    (d.camera.width, d.camera.height) = (width, width * 3 / 4);
    let f = frame as f32;
    d.sun.direction = None;
    d.sun.elevation_deg = Some(if growing { 50.0 } else { 50.0 - f });
    d.sun.azimuth_deg = Some(if growing { 40.0 } else { 40.0 + f });
    let mut s = Scene::build(d, "warm_start", Path::new(".")).expect("the default scene builds");
    let grow = if growing { frame } else { 0 };
    let dims = DIMS.map(|n| n + grow);
    let origin = Vec3::new(-400.0 + if growing { 6.0 * f } else { 0.0 }, 0.0, -240.0);
    let o = &s.medium.optics;
    s.medium = Medium::new(cumulus(dims, 1), origin, Vec3::splat(VOXEL), o.sigma_t, o.albedo, s.desc.medium.g);
    s
}

/// Render, returning the image, the solve's iterations and seconds.
fn render(s: &Scene, warm: &mut Warm) -> (Image, usize, f64) {
    let out = render_warm(s, &NoProgress, warm).expect("renders");
    let solve = out.timings.stages.iter().find(|t| t.0 == "transport solve").map_or(0.0, |t| t.1);
    (out.image, warm.iterations.unwrap_or(0), solve)
}

fn block_error(test: &Image, reference: &Image) -> f64 {
    compare(test, reference, None)
        .expect("same size")
        .block_mean_relative_error
        .unwrap_or(0.0)
}

fn main() {
    let args: Vec<usize> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let frames = args.first().copied().unwrap_or(8);
    let width = args.get(1).copied().unwrap_or(80) as u32;
    println!("| sequence | frame | full voxels | iterations cold / warm | solve s cold / warm | warm vs cold | cold vs 1e-5 |");
    println!("|---|---|---|---|---|---|---|");
    for growing in [true, false] {
        let (mut warm, mut total) = (Warm::new(true), [0usize; 2]);
        for frame in 0..frames {
            let s = scene(width, frame, growing);
            let (cold_img, cold_it, cold_s) = render(&s, &mut Warm::new(false));
            let (warm_img, warm_it, warm_s) = render(&s, &mut warm);
            let mut tight = s.clone();
            tight.render.transport.tolerance = 1e-5;
            tight.render.transport.max_iterations = 200;
            let (tight_img, _, _) = render(&tight, &mut Warm::new(false));
            total[0] += cold_it;
            total[1] += warm_it;
            println!(
                "| {} | {frame} | {} | {cold_it} / {warm_it} | {cold_s:.2} / {warm_s:.2} | {:.2e} | {:.2e} |",
                if growing { "growing, moving cloud" } else { "sun moving 1°/frame" },
                s.medium.density.full_index().full_voxels().count(),
                block_error(&warm_img, &cold_img),
                block_error(&cold_img, &tight_img),
            );
        }
        eprintln!("iterations over the sequence: cold {}, warm {}", total[0], total[1]);
    }
}
