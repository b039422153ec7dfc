//! Method `reference`: an unbiased volumetric path tracer over exactly the same [`Scene`] as the
//! other methods — the ground truth they are measured against.
//!
//! * [`tracking`]: delta tracking (free paths) and ratio tracking (shadow rays) against the
//!   medium's majorant grid.
//! * [`sky`]: importance sampling of the sky for next-event estimation.
//! * [`integrator`]: the path estimator (NEE of sun and sky with MIS, Lambertian ground,
//!   Russian roulette, no depth cap by default).
//! * [`slab`]: the same transport in a plane-parallel slab, checked against adding-doubling.
//! * [`mitsuba`]: export of the scene to Mitsuba 3 for an independent cross-check.
//!
//! Rendering is progressive: pass after pass of one sample per pixel, each pixel sample drawing
//! from its own stream [`Rng::for_pixel`]`(seed, x, y, sample)`, summed per pixel in sample order,
//! so the image is bit-identical at any thread count. `render.time_limit` stops after the pass in
//! progress once the budget is spent (the image then depends on the machine's speed).
//!
//! Extra EXR layers: `transmittance` (the exact transmittance of the pixel-centre camera ray
//! through the cloud, up to the ground; R = G = B; `cloudgi compare` masks with it) and, with
//! `render.stderr`, `stderr` (the standard error of each pixel's mean, per band).

pub mod integrator;
pub mod mitsuba;
pub mod sky;
pub mod slab;
pub mod tracking;

pub use integrator::{radiance, PathOptions};
pub use sky::SkySampler;

use crate::error::Result;
use crate::image::Image;
use crate::math::{Rgb, Rng};
use crate::pipeline::{Progress, Timings};
use crate::scene::Scene;
use rayon::prelude::*;
use std::time::Instant;

/// Name of the camera-ray transmittance layer.
pub const TRANSMITTANCE_LAYER: &str = "transmittance";
/// Name of the standard-error layer.
pub const STDERR_LAYER: &str = "stderr";

/// What a reference render did besides the image.
#[derive(Clone, Debug)]
pub struct ReferenceStats {
    /// Samples per pixel actually taken (fewer than asked when the time limit hit).
    pub spp: u32,
    /// Wall-clock seconds of the path tracing.
    pub seconds: f64,
}

/// Render `scene` with the reference method (settings from `scene.render`: spp, seed, max_depth,
/// time_limit, stderr).
pub fn render(scene: &Scene, progress: &dyn Progress, timings: &mut Timings) -> Result<Image> {
    let (img, stats) = render_with_stats(scene, progress, timings);
    progress.log(&format!("reference: {} spp in {:.2} s", stats.spp, stats.seconds));
    Ok(img)
}

/// [`render`], also returning how many samples were taken.
pub fn render_with_stats(scene: &Scene, progress: &dyn Progress, timings: &mut Timings) -> (Image, ReferenceStats) {
    let cam = &scene.camera;
    let (w, h) = (cam.width as usize, cam.height as usize);
    let rs = &scene.render;
    let opts = PathOptions {
        max_depth: rs.max_depth.unwrap_or(u32::MAX),
    };
    let transmittance = timings.time("camera transmittance", || camera_transmittance(scene));
    // Per pixel: Σx and Σx² per band, in f64, summed in sample order.
    let mut sum = vec![[0f64; 6]; w * h];
    let start = Instant::now();
    let mut done = 0u32;
    timings.time("path tracing", || {
        progress.begin("reference", rs.spp as u64 * h as u64);
        while done < rs.spp {
            let s = done;
            sum.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
                for (x, acc) in row.iter_mut().enumerate() {
                    let v = sample_pixel(scene, &opts, x as u32, y as u32, s);
                    for c in 0..3 {
                        let v = v[c] as f64;
                        acc[c] += v;
                        acc[c + 3] += v * v;
                    }
                }
                progress.advance(1);
            });
            done += 1;
            if let Some(limit) = rs.time_limit {
                if start.elapsed().as_secs_f64() >= limit {
                    break;
                }
            }
        }
        progress.end();
    });
    let n = done.max(1) as f64;
    let mut img = Image::new(cam.width, cam.height);
    img.pixels = sum
        .iter()
        .map(|a| Rgb::new((a[0] / n) as f32, (a[1] / n) as f32, (a[2] / n) as f32))
        .collect();
    img.add_layer(TRANSMITTANCE_LAYER, transmittance.iter().map(|&t| Rgb::splat(t)).collect());
    if rs.stderr {
        let se = |s: f64, s2: f64| -> f32 {
            if done < 2 {
                return f32::INFINITY;
            }
            let mean = s / n;
            let var = ((s2 - n * mean * mean) / (n - 1.0)).max(0.0);
            (var / n).sqrt() as f32
        };
        img.add_layer(
            STDERR_LAYER,
            sum.iter()
                .map(|a| Rgb::new(se(a[0], a[3]), se(a[1], a[4]), se(a[2], a[5])))
                .collect(),
        );
    }
    let stats = ReferenceStats {
        spp: done,
        seconds: start.elapsed().as_secs_f64(),
    };
    (img, stats)
}

/// Convenience for tests and other methods' comparisons: the reference image of `scene` at `spp`
/// samples per pixel (no time limit, no progress), with the `transmittance` layer and, if
/// `scene.render.stderr`, the `stderr` layer. All other settings come from `scene.render`.
pub fn render_image(scene: &Scene, spp: u32) -> Image {
    let mut s = scene.clone();
    s.render.spp = spp.max(1);
    s.render.time_limit = None;
    render_with_stats(&s, &crate::pipeline::NoProgress, &mut Timings::default()).0
}

/// One sample of pixel (x, y): a jittered camera ray through the pixel, traced with stream
/// `Rng::for_pixel(seed, x, y, s)`.
#[inline]
pub fn sample_pixel(scene: &Scene, opts: &PathOptions, x: u32, y: u32, s: u32) -> Rgb {
    let mut rng = Rng::for_pixel(scene.render.seed, x, y, s);
    let (px, py) = (x as f32 + rng.uniform(), y as f32 + rng.uniform());
    let ray = scene.camera.ray(px, py);
    radiance(scene, ray.origin, ray.dir, opts, &mut rng)
}

/// Exact transmittance of each pixel-centre camera ray through the medium, up to the ground.
pub fn camera_transmittance(scene: &Scene) -> Vec<f32> {
    let cam = &scene.camera;
    let (w, h) = (cam.width as usize, cam.height as usize);
    let mut t = vec![1f32; w * h];
    t.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, v) in row.iter_mut().enumerate() {
            let ray = cam.ray(x as f32 + 0.5, y as f32 + 0.5);
            let t_max = scene
                .ground
                .as_ref()
                .and_then(|g| g.intersect(ray.origin, ray.dir))
                .unwrap_or(f32::INFINITY);
            *v = scene.medium.transmittance(ray.origin, ray.dir, 0.0, t_max);
        }
    });
    t
}
