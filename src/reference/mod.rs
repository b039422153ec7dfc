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
//! so the image is bit-identical at any thread count. `render.time_limit` is checked before each
//! pixel sample and inside paths; pixels then average the samples they completed (the image
//! then depends on the machine's speed; layer `samples` holds the counts).
//!
//! Extra EXR layers: `transmittance` (the exact transmittance of the pixel-centre camera ray
//! through the cloud, up to the ground; R = G = B; `cloudgi compare` masks with it); with
//! `render.stderr`, `stderr` (the standard error of each pixel's mean, per band); and the image
//! split by scattering order ([`ORDER_LAYERS`]) and by light ([`LIGHT_LAYERS`], [`SINGLE_LAYERS`]),
//! each set summing to the image (docs/reference.md).

pub mod integrator;
pub mod mitsuba;
pub mod sky;
pub mod slab;
pub mod tracking;

pub use integrator::{radiance, Light, PathOptions};

use crate::error::{Error, Result};
use crate::image::Image;
use crate::math::{Rgb, Rng};
use crate::pipeline::{Progress, Timings};
use crate::scene::Scene;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;

/// Name of the camera-ray transmittance layer.
pub const TRANSMITTANCE_LAYER: &str = "transmittance";
/// Name of the standard-error layer.
pub const STDERR_LAYER: &str = "stderr";
/// Name of the per-pixel sample-count layer (R = G = B = samples averaged), written when the time
/// limit ended the render (it may end a pass part-way, so pixels hold different counts).
pub const SAMPLES_LAYER: &str = "samples";

/// Scattering-order classes of the order layers: (layer name, lowest order, highest order).
/// Order = medium scattering events on the path; ground bounces do not count (they change the
/// light, see [`Light`]). Order 0 is the background: sky and ground seen through the cloud.
pub const ORDER_LAYERS: [(&str, u32, u32); 6] = [
    ("order0", 0, 0),
    ("order1", 1, 1),
    ("order2", 2, 2),
    ("order3_4", 3, 4),
    ("order5_8", 5, 8),
    ("order9plus", 9, u32::MAX),
];
/// Light layers, indexed by [`Light`] as usize: sun and sky on paths that never touch the
/// ground, and every path with a ground vertex.
pub const LIGHT_LAYERS: [&str; 3] = ["light_sun", "light_sky", "light_ground"];
/// Single scattering (order 1) split by light, indexed by [`Light`] as usize.
pub const SINGLE_LAYERS: [&str; 3] = ["order1_sun", "order1_sky", "order1_ground"];

/// Index of `order` in [`ORDER_LAYERS`].
#[inline]
pub fn order_class(order: u32) -> usize {
    match order {
        0..=2 => order as usize,
        3..=4 => 3,
        5..=8 => 4,
        _ => 5,
    }
}

/// Per-band sums of one pixel: Σx, Σx² of the sample values, and Σx per (order class, light) bin.
#[derive(Clone)]
struct PixelSums {
    n: u32,
    sum: [f64; 3],
    sum2: [f64; 3],
    bins: [[f64; 3]; 18],
}

impl Default for PixelSums {
    fn default() -> Self {
        PixelSums {
            n: 0,
            sum: [0.0; 3],
            sum2: [0.0; 3],
            bins: [[0.0; 3]; 18],
        }
    }
}

/// What a reference render did besides the image.
#[derive(Clone, Debug)]
pub struct ReferenceStats {
    /// Samples per pixel of the pixels with the most (fewer than asked when the time limit hit).
    pub spp: u32,
    /// Fewest samples any pixel holds (below `spp` when the time limit ended a pass part-way).
    pub min_spp: u32,
    /// Wall-clock seconds of the path tracing.
    pub seconds: f64,
}

/// Render `scene` with the reference method (settings from `scene.render`: spp, seed, max_depth,
/// time_limit, stderr).
pub fn render(scene: &Scene, progress: &dyn Progress, timings: &mut Timings) -> Result<Image> {
    let rs = &scene.render;
    let order = mean_scattering_order(&scene.medium);
    if rs.time_limit.is_none() && rs.max_depth.is_none() && order > LONG_PATH_ORDER {
        progress.warn(&format!(
            "{}: paths in this medium scatter about {order:.1e} times each (optical depth up to ~{:.1e}, no \
             depth cap), so the render may take hours or more: set render.time_limit (--time-limit S) to \
             stop it in time, or render.max_depth (biased low)",
            scene.source,
            order.sqrt()
        ));
    }
    let (img, stats) = render_with_stats(scene, progress, timings);
    check_samples(scene, &stats, progress)?;
    let spp = if stats.min_spp == stats.spp {
        format!("{} spp", stats.spp)
    } else {
        format!("{}–{} spp (time limit inside a pass; layer `samples`)", stats.min_spp, stats.spp)
    };
    progress.log(&format!("reference: {spp} in {:.2} s", stats.seconds));
    Ok(img)
}

/// A time limit that ended the render before any pixel completed a sample leaves nothing to
/// show: an error naming the limit (no image is written). One that ended the first pass part-way
/// leaves pixels that read 0: a warning (the `samples` layer marks them). A cancelled render
/// reports its cancellation instead.
fn check_samples(scene: &Scene, stats: &ReferenceStats, progress: &dyn Progress) -> Result<()> {
    if stats.min_spp > 0 || progress.cancelled() {
        return Ok(());
    }
    let limit = crate::limits::seconds_text(scene.render.time_limit.unwrap_or(f64::INFINITY));
    if stats.spp == 0 {
        return Err(Error::invalid(
            &scene.source,
            "render.time_limit",
            format!(
                "{limit} ended the reference before any pixel completed a sample, so there is no image: \
                 raise render.time_limit (--time-limit S)"
            ),
        ));
    }
    progress.warn(&format!(
        "{}: render.time_limit {limit} ended the reference inside its first pass: pixels without a \
         sample read 0 (layer `samples` counts each pixel's); raise render.time_limit (--time-limit S)",
        scene.source
    ));
    Ok(())
}

/// Estimated scatterings per path above which `render` warns that it may not finish without a
/// time limit (about 0.1 s of CPU per path).
const LONG_PATH_ORDER: f64 = 1e6;

/// A path's mean number of scatterings, estimated up front: about τ² for a thick medium of
/// optical thickness τ (a random walk's steps to cross it), capped by 1/(1 − a) where albedo a < 1
/// ends the walk first. τ is the densest voxel's extinction across the grid's thinnest extent.
fn mean_scattering_order(m: &crate::medium::Medium) -> f64 {
    let rho = m.density.full_voxels().fold(0.0f64, |a, (_, v)| a.max(v as f64));
    let d = m.dims();
    let extent = (0..3).map(|a| d[a] as f64 * m.voxel_size[a] as f64).fold(f64::INFINITY, f64::min);
    let tau = rho * m.optics.sigma_t as f64 * extent;
    let a = m.optics.albedo.max_element() as f64;
    (tau * tau).min(if a < 1.0 { 1.0 / (1.0 - a) } else { f64::INFINITY })
}

/// Seconds of path tracing after which the projected remaining time is trusted enough to warn.
const PACE_SETTLE_S: f64 = 30.0;

/// Projected remaining seconds above which a render without a time limit warns (the estimate of
/// [`mean_scattering_order`] does not see every cost, e.g. tentative collisions in a dense cloud's
/// thin fringe under a loose majorant).
const PACE_WARN_S: f64 = 3600.0;

/// Watches the samples' pace and warns once when, without a time limit, the render would run for
/// more than [`PACE_WARN_S`] more seconds.
struct Pace {
    start: Instant,
    total: u64,
    done: AtomicU64,
    warned: AtomicBool,
}

impl Pace {
    fn new(start: Instant, total: u64) -> Pace {
        Pace { start, total, done: AtomicU64::new(0), warned: AtomicBool::new(false) }
    }

    /// One more sample finished (a look at the clock: tens of nanoseconds against a path's
    /// microseconds).
    fn sample_done(&self, progress: &dyn Progress, source: &str) {
        let done = self.done.fetch_add(1, Ordering::Relaxed) + 1;
        if self.warned.load(Ordering::Relaxed) {
            return;
        }
        let elapsed = self.start.elapsed().as_secs_f64();
        if let Some(left) = remaining_if_long(done, self.total, elapsed) {
            if !self.warned.swap(true, Ordering::Relaxed) {
                progress.warn(&format!(
                    "{source}: at this pace the reference needs about {:.1} h more ({done} of {} samples in \
                     {elapsed:.0} s); set render.time_limit (--time-limit S) to stop it in time (each pixel \
                     averages the samples it completed), or lower render.spp",
                    left / 3600.0,
                    self.total
                ));
            }
        }
    }
}

/// The projected remaining seconds when `done` of `total` samples took `elapsed` seconds, where
/// the pace has settled ([`PACE_SETTLE_S`]) and the remainder exceeds [`PACE_WARN_S`].
fn remaining_if_long(done: u64, total: u64, elapsed: f64) -> Option<f64> {
    if done == 0 || elapsed < PACE_SETTLE_S {
        return None;
    }
    let left = elapsed / done as f64 * total.saturating_sub(done) as f64;
    (left > PACE_WARN_S).then_some(left)
}

/// [`render`], also returning how many samples were taken.
///
/// The time limit is checked before every pixel sample and every [`integrator::DEADLINE_CHECK`]
/// vertices inside a path, so it holds to well under a second; a path cut off by it is dropped,
/// and each pixel averages the samples it completed.
pub fn render_with_stats(scene: &Scene, progress: &dyn Progress, timings: &mut Timings) -> (Image, ReferenceStats) {
    let cam = &scene.camera;
    let (w, h) = (cam.width as usize, cam.height as usize);
    let rs = &scene.render;
    let start = Instant::now();
    let deadline = rs.time_limit.map(|s| start + std::time::Duration::from_secs_f64(s.clamp(0.0, crate::limits::MAX_SECONDS)));
    let opts = PathOptions {
        max_depth: rs.max_depth.unwrap_or(u32::MAX),
        deadline,
    };
    let transmittance = timings.time("camera transmittance", || camera_transmittance(scene));
    // Per pixel, in f64, summed in sample order (so any thread count gives the same image).
    let mut acc = vec![PixelSums::default(); w * h];
    let stop = AtomicBool::new(false);
    let mut passes = 0u32;
    timings.time("path tracing", || {
        if let Some(t) = rs.time_limit {
            // The progress counts towards `spp`; the limit usually ends the render first.
            progress.log(&format!("reference: time limit {}", crate::limits::seconds_text(t)));
        }
        progress.begin("reference paths", rs.spp as u64 * (w * h) as u64);
        let pace = rs.time_limit.is_none().then(|| Pace::new(start, rs.spp as u64 * (w * h) as u64));
        while passes < rs.spp && !stop.load(Ordering::Relaxed) {
            let s = passes;
            crate::par::for_chunks(&mut acc, w, &|y, row| {
                for (x, a) in row.iter_mut().enumerate() {
                    if stop.load(Ordering::Relaxed) || deadline.is_some_and(|t| Instant::now() >= t) || progress.cancelled() {
                        stop.store(true, Ordering::Relaxed);
                        return;
                    }
                    let mut bins = [Rgb::ZERO; 18];
                    let sink = |order: u32, light: Light, c: Rgb| bins[order_class(order) * 3 + light as usize] += c;
                    let Some(v) = sample_pixel(scene, &opts, x as u32, y as u32, s, sink) else {
                        stop.store(true, Ordering::Relaxed);
                        return;
                    };
                    a.n += 1;
                    for c in 0..3 {
                        let v = v[c] as f64;
                        a.sum[c] += v;
                        a.sum2[c] += v * v;
                        for (b, sb) in a.bins.iter_mut().zip(&bins) {
                            b[c] += sb[c] as f64;
                        }
                    }
                    progress.advance(1);
                    if let Some(p) = &pace {
                        p.sample_done(progress, &scene.source);
                    }
                }
            });
            passes += 1;
            if progress.wants_images() {
                let mut live = Image::new(cam.width, cam.height);
                live.pixels = acc.iter().map(|a| a.sum.map(|s| (s / a.n.max(1) as f64) as f32).into()).collect();
                progress.image(&live);
            }
        }
        progress.end();
    });
    let spp = acc.iter().map(|a| a.n).max().unwrap_or(0);
    let min_spp = acc.iter().map(|a| a.n).min().unwrap_or(0);
    // A pixel with no completed sample (time limit below one pass) reads 0.
    let mean = |a: &PixelSums, s: &[f64; 3]| -> Rgb {
        let n = a.n.max(1) as f64;
        Rgb::new((s[0] / n) as f32, (s[1] / n) as f32, (s[2] / n) as f32)
    };
    let mut img = Image::new(cam.width, cam.height);
    img.pixels = acc.iter().map(|a| mean(a, &a.sum)).collect();
    img.add_layer(TRANSMITTANCE_LAYER, transmittance.iter().map(|&t| Rgb::splat(t)).collect());
    let binsum = |a: &PixelSums, pick: &dyn Fn(usize, usize) -> bool| -> [f64; 3] {
        let mut s = [0f64; 3];
        for (i, b) in a.bins.iter().enumerate() {
            if pick(i / 3, i % 3) {
                for c in 0..3 {
                    s[c] += b[c];
                }
            }
        }
        s
    };
    for (k, (name, _, _)) in ORDER_LAYERS.iter().enumerate() {
        img.add_layer(name, acc.iter().map(|a| mean(a, &binsum(a, &|o, _| o == k))).collect());
    }
    for (k, name) in LIGHT_LAYERS.iter().enumerate() {
        img.add_layer(name, acc.iter().map(|a| mean(a, &binsum(a, &|_, l| l == k))).collect());
    }
    for (k, name) in SINGLE_LAYERS.iter().enumerate() {
        img.add_layer(name, acc.iter().map(|a| mean(a, &binsum(a, &|o, l| o == 1 && l == k))).collect());
    }
    if rs.stderr {
        let se = |a: &PixelSums, c: usize| -> f32 {
            if a.n < 2 {
                return f32::INFINITY;
            }
            let n = a.n as f64;
            let mean = a.sum[c] / n;
            let var = ((a.sum2[c] - n * mean * mean) / (n - 1.0)).max(0.0);
            (var / n).sqrt() as f32
        };
        img.add_layer(STDERR_LAYER, acc.iter().map(|a| Rgb::new(se(a, 0), se(a, 1), se(a, 2))).collect());
    }
    if min_spp < rs.spp {
        img.add_layer(SAMPLES_LAYER, acc.iter().map(|a| Rgb::splat(a.n as f32)).collect());
    }
    let stats = ReferenceStats {
        spp,
        min_spp,
        seconds: start.elapsed().as_secs_f64(),
    };
    (img, stats)
}

/// Convenience for tests and other methods' comparisons: the reference image of `scene` at `spp`
/// samples per pixel (no time limit, no progress), with the `transmittance` and order/light
/// layers and, if `scene.render.stderr`, the `stderr` layer. All other settings come from `scene.render`.
pub fn render_image(scene: &Scene, spp: u32) -> Image {
    let mut s = scene.clone();
    s.render.spp = spp.max(1);
    s.render.time_limit = None;
    render_with_stats(&s, &crate::pipeline::NoProgress, &mut Timings::default()).0
}

/// One sample of pixel (x, y): a jittered camera ray through the pixel, traced with stream
/// `Rng::for_pixel(seed, x, y, s)`; `None` when the path passed `opts.deadline`. The terms by
/// order and light go to `sink` (see [`integrator::radiance`]).
#[inline]
pub fn sample_pixel(scene: &Scene, opts: &PathOptions, x: u32, y: u32, s: u32, sink: impl FnMut(u32, Light, Rgb)) -> Option<Rgb> {
    let mut rng = Rng::for_pixel(scene.render.seed, x, y, s);
    let (px, py) = (x as f32 + rng.uniform(), y as f32 + rng.uniform());
    let ray = scene.camera.ray(px, py);
    radiance(scene, ray.origin, ray.dir, opts, &mut rng, sink)
}

/// Exact transmittance of each pixel-centre camera ray through the medium, up to the ground.
pub fn camera_transmittance(scene: &Scene) -> Vec<f32> {
    let cam = &scene.camera;
    let (w, h) = (cam.width as usize, cam.height as usize);
    let mut t = vec![1f32; w * h];
    crate::par::for_chunks(&mut t, w, &|y, row| {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_render_warns_only_when_its_settled_pace_leaves_more_than_an_hour() {
        // 10 of 1,000 samples in 60 s: 5,940 s left.
        assert_eq!(remaining_if_long(10, 1000, 60.0), Some(5940.0));
        // The same pace over fewer samples: 3,000 s left, under the hour.
        assert_eq!(remaining_if_long(10, 510, 60.0), None);
        // Before the pace settles, and with nothing done, no projection.
        assert_eq!(remaining_if_long(1, 1_000_000, PACE_SETTLE_S - 1.0), None);
        assert_eq!(remaining_if_long(0, 1000, 1e6), None);
        // All done: nothing left.
        assert_eq!(remaining_if_long(1000, 1000, 1e6), None);
    }
}
