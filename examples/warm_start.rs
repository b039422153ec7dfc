//! Warm against cold solves over three sequences, as a markdown table (docs/sequences.md, "Warm
//! starts"):
//! - `growing`: the procedural cumulus on a grid that grows by one voxel per axis and moves 6 m
//!   per frame (every frame a different grid size and origin);
//! - `sun`: the same cloud with only the sun moving, 1° in elevation and azimuth per frame;
//! - `drift`: the same cloud carried by the wind a quarter voxel (4 m) per frame, its density
//!   evolving under a ±5 % wave that moves one voxel per frame through it (at most 1.6 % per
//!   voxel and frame).
//!
//! Per frame: the solve's iterations (`transport`: source iterations; `diffusion`, `full`: CG
//! iterations of the middle band, summed over `full`'s solves), the solve's and the frame's
//! seconds, cold and warm; the block mean relative error of the warm image against the cold one,
//! and of the cold and warm images against a tightly converged one (`transport` to 1e-5,
//! `diffusion` and `full` to a relative residual of 1e-7): the tolerance's own effect on the image.
//!
//! `cargo run --release --features internals --example warm_start [FRAMES] [WIDTH] [METHOD]
//! [SEQUENCES]` (defaults 8, 80, transport and growing,sun,drift; 4:3 images)

use cloudgi::math::Vec3;
use cloudgi::medium::procedural::cumulus;
use cloudgi::medium::Medium;
use cloudgi::render::warm::{render_warm, Warm};
use cloudgi::scene::{Method, Scene, SceneDesc};
use cloudgi::tools::compare::compare;
use cloudgi::{Image, NoProgress};
use std::path::Path;

/// Voxel edge (m) and the first frame's grid.
const VOXEL: f32 = 16.0;
const DIMS: [usize; 3] = [50, 40, 30];

/// How a sequence changes from frame to frame.
#[derive(Clone, Copy, PartialEq)]
enum Sequence {
    Growing,
    Sun,
    Drift,
}

impl Sequence {
    fn name(self) -> &'static str {
        match self {
            Sequence::Growing => "growing",
            Sequence::Sun => "sun",
            Sequence::Drift => "drift",
        }
    }
}

/// Wavelength of the drifting cloud's density wave, in voxels along x + z.
const WAVE_VOXELS: f32 = 20.0;

fn scene(width: u32, frame: usize, seq: Sequence, method: Method) -> Scene {
    let mut d = SceneDesc::default();
    (d.camera.width, d.camera.height) = (width, width * 3 / 4);
    d.render.method = method;
    let f = frame as f32;
    let sun = seq == Sequence::Sun;
    d.sun.direction = None;
    d.sun.elevation_deg = Some(if sun { 50.0 - f } else { 50.0 });
    d.sun.azimuth_deg = Some(if sun { 40.0 + f } else { 40.0 });
    let mut s = Scene::build(d, "warm_start", Path::new(".")).expect("the default scene builds");
    let grow = if seq == Sequence::Growing { frame } else { 0 };
    let dims = DIMS.map(|n| n + grow);
    let moved_m = match seq {
        Sequence::Growing => 6.0 * f,
        Sequence::Sun => 0.0,
        Sequence::Drift => 0.25 * VOXEL * f,
    };
    let origin = Vec3::new(-400.0 + moved_m, 0.0, -240.0);
    let mut density = cumulus(dims, 1);
    if seq == Sequence::Drift {
        for (k, j, i) in (0..dims[2]).flat_map(|k| (0..dims[1]).flat_map(move |j| (0..dims[0]).map(move |i| (k, j, i)))) {
            let phase = std::f32::consts::TAU * ((i + k) as f32 - f) / WAVE_VOXELS;
            density.set(i, j, k, density.get(i, j, k) * (1.0 + 0.05 * phase.sin()));
        }
    }
    let o = &s.medium.optics;
    s.medium = Medium::new(density, origin, Vec3::splat(VOXEL), o.sigma_t, o.albedo, s.desc.medium.g);
    s
}

/// The scene solved to a tight tolerance.
fn tight(s: &Scene) -> Scene {
    let mut t = s.clone();
    t.render.transport.tolerance = 1e-5;
    t.render.transport.max_iterations = 200;
    t.render.solver.tolerance = 1e-7;
    t.render.solver.max_iterations = 2000;
    t
}

/// Render, returning the image, the solve's iterations, the solve's and the frame's seconds.
fn render(s: &Scene, warm: &mut Warm) -> (Image, usize, f64, f64) {
    let out = render_warm(s, &NoProgress, warm).expect("renders");
    let t = &out.timings.stages;
    let solve = t.iter().filter(|t| t.0.ends_with(" solve")).map(|t| t.1).sum();
    (out.image, warm.iterations.unwrap_or(0), solve, out.timings.total())
}

fn block_error(test: &Image, reference: &Image) -> f64 {
    compare(test, reference, None)
        .expect("same size")
        .block_mean_relative_error
        .unwrap_or(0.0)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let frames = args.first().and_then(|a| a.parse().ok()).unwrap_or(8);
    let width = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(80);
    let method = match args.get(2).map_or("transport", String::as_str) {
        "diffusion" => Method::Diffusion,
        "full" => Method::Full,
        _ => Method::Transport,
    };
    println!(
        "| {} | frame | full voxels | iterations cold / warm | solve s cold / warm | frame s cold / warm | warm vs cold | cold vs tight | warm vs tight |",
        method.name()
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let chosen = args.get(3).map_or("growing,sun,drift", String::as_str);
    let sequences = [Sequence::Growing, Sequence::Sun, Sequence::Drift];
    for seq in sequences.into_iter().filter(|s| chosen.split(',').any(|c| c == s.name())) {
        let (mut warm, mut total) = (Warm::new(true), [0usize; 2]);
        let mut seconds = [0f64; 2];
        for frame in 0..frames {
            let s = scene(width, frame, seq, method);
            let (cold_img, cold_it, cold_s, cold_f) = render(&s, &mut Warm::new(false));
            let (warm_img, warm_it, warm_s, warm_f) = render(&s, &mut warm);
            let (tight_img, ..) = render(&tight(&s), &mut Warm::new(false));
            if frame > 0 {
                total[0] += cold_it;
                total[1] += warm_it;
                seconds[0] += cold_f;
                seconds[1] += warm_f;
            }
            println!(
                "| {} | {frame} | {} | {cold_it} / {warm_it} | {cold_s:.2} / {warm_s:.2} | {cold_f:.2} / {warm_f:.2} | {:.1e} | {:.1e} | {:.1e} |",
                seq.name(),
                s.medium.density.full_index().count(),
                block_error(&warm_img, &cold_img),
                block_error(&cold_img, &tight_img),
                block_error(&warm_img, &tight_img),
            );
        }
        eprintln!(
            "{}: after the first frame, iterations cold {} warm {} ({:.2}×), frame seconds cold {:.1} warm {:.1}",
            seq.name(),
            total[0],
            total[1],
            total[0] as f64 / total[1].max(1) as f64,
            seconds[0],
            seconds[1]
        );
    }
}
