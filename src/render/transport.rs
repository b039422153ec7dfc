//! The gather of `--method transport`: each camera ray is marched through the δ-M medium
//! (extinction σt′), collecting the converged diffuse source evaluated from its spherical
//! harmonics in the eye's direction plus the sun's single scattering with the exact HG phase
//! function (TMS, Nakajima & Tanaka 1988: σs p(Θ) E T′_sun per unit length, i.e. a/(1 − a f)
//! p(Θ) E T′ per unit scaled optical depth). Behind the cloud: the sky, or the ground with the
//! solver's per-column irradiance (shadowed sun and the cloud's diffuse light).
//!
//! With `render.aov` the EXR has the layers `diffuse` (the converged diffuse source: orders ≥ 2 of the sun,
//! all orders of sky and ground light), `sun_single` (TMS) and `background`; they sum to the image.
//!
//! The eye-direction source is evaluated once per full voxel in the direction from the camera to
//! the voxel's centre (a voxel subtends a small angle from the eye), then interpolated
//! trilinearly over full voxels only, so empty neighbours do not darken the cloud's rim.

use crate::error::Result;
use crate::image::Image;
use crate::math::{real_sh, sh_count};
use crate::math::{Rgb, Vec3};
use crate::medium::march::march;
use crate::medium::Medium;
use crate::pipeline::{render_rows, Progress, Timings};
use crate::render::single::pixel_sample;
use crate::scene::Scene;
use crate::transport::solve::{solve, TransportField, TransportSettings};
use crate::transport::TransportMemory;
use glam::DVec3;
use rayon::prelude::*;

/// Source per unit scaled optical depth towards the eye, per voxel (zero where ρ = 0): the
/// diffuse (multiple-scattering) part and the sun's exact single scattering.
pub fn eye_source(scene: &Scene, f: &TransportField) -> (Vec<Rgb>, Vec<Rgb>) {
    let m = &scene.medium;
    let [nx, ny, _] = m.dims();
    let nsh = sh_count(f.order);
    let eye = scene.camera.position;
    let o = &f.optics;
    let (sun_dir, e_sun) = (scene.sun.dir, scene.sun.irradiance);
    (0..f.full.len())
        .into_par_iter()
        .map(|v| {
            let fi = f.full[v];
            if fi == u32::MAX {
                return (Rgb::ZERO, Rgb::ZERO);
            }
            let (i, j, k) = (v % nx, (v / nx) % ny, v / (nx * ny));
            let d = (m.voxel_center(i, j, k) - eye).normalize_or_zero();
            // Radiance towards the eye travels along −d.
            let mut y = vec![0.0; nsh];
            real_sh(f.order, -DVec3::new(d.x as f64, d.y as f64, d.z as f64), &mut y);
            let p = m.optics.phase.eval(sun_dir, -d);
            let (mut diffuse, mut sun) = ([0f32; 3], [0f32; 3]);
            for b in 0..3 {
                let base = (fi as usize * 3 + b) * nsh;
                let js = &f.diffuse_source[base..base + nsh];
                diffuse[b] = js.iter().zip(&y).map(|(j, y)| *j as f64 * y).sum::<f64>().max(0.0) as f32;
                let a = o.albedo[b];
                sun[b] = (a / (1.0 - a * o.bands[b].f) * (e_sun[b] * p * f.sun_t[v][b]) as f64) as f32;
            }
            (Rgb::from(diffuse), Rgb::from(sun))
        })
        .unzip()
}

/// Trilinear interpolation of `grid` at continuous voxel coordinates `v`, over full voxels only.
#[inline]
fn full_trilinear(m: &Medium, full: &[u32], grid: &[Rgb], v: Vec3) -> Rgb {
    let d = m.dims();
    let u = v - Vec3::splat(0.5);
    let b = u.floor();
    let t = u - b;
    let (mut sum, mut wsum) = (Rgb::ZERO, 0.0f32);
    for dz in 0..2 {
        for dy in 0..2 {
            for dx in 0..2 {
                let c = [b.x as i64 + dx, b.y as i64 + dy, b.z as i64 + dz];
                if (0..3).any(|a| c[a] < 0 || c[a] >= d[a] as i64) {
                    continue;
                }
                let idx = c[0] as usize + d[0] * (c[1] as usize + d[1] * c[2] as usize);
                if full[idx] == u32::MAX {
                    continue;
                }
                let w = (if dx == 1 { t.x } else { 1.0 - t.x })
                    * (if dy == 1 { t.y } else { 1.0 - t.y })
                    * (if dz == 1 { t.z } else { 1.0 - t.z });
                sum += grid[idx] * w;
                wsum += w;
            }
        }
    }
    if wsum > 0.0 {
        sum / wsum
    } else {
        Rgb::ZERO
    }
}

/// The background along a ray: the ground with the solver's irradiance (shadowed sun and the
/// cloud's diffuse light), or the sky.
fn background(scene: &Scene, f: &TransportField, o: Vec3, d: Vec3) -> Rgb {
    if let Some(t) = scene.ground.as_ref().and_then(|g| g.intersect(o, d)) {
        let p = o + d * t;
        return f.ground.at(p.x as f64, p.z as f64);
    }
    scene.sky.radiance(d)
}

/// Most memory a transport render may ask for (bytes), whatever the machine has; the CLI also
/// checks the estimate against the memory available before it starts.
const MAX_BYTES: u64 = 16 << 30;

/// The warning when the iteration stopped at `render.transport_max_iterations` with the last
/// relative change of I0 (`history`, one entry per iteration) still at or above the tolerance
/// (an empty medium does not iterate and is not warned about).
fn unconverged(source: &str, history: &[f64], s: &TransportSettings) -> Option<String> {
    let last = *history.last()?;
    (history.len() >= s.max_iterations && last >= s.tolerance).then(|| {
        format!(
            "{source}: the transport iteration stopped at render.transport_max_iterations = {} with a \
             relative change of I0 of {last:.1e}, above render.transport_tolerance = {:.1e}; raise \
             render.transport_max_iterations (the image is not converged)",
            s.max_iterations, s.tolerance
        )
    })
}

/// Render with `--method transport` and the scene's `render.transport_*` settings.
pub fn render(scene: &Scene, progress: &dyn Progress, timings: &mut Timings) -> Result<Image> {
    let m = &scene.medium;
    let s = &scene.render.transport;
    // Refuse, with the fix, a cloud whose arrays would not fit (rather than abort).
    let memory = TransportMemory::of(m, s);
    memory.check(&scene.source, MAX_BYTES, "the library's limit")?;
    let field = timings.time("transport solve", || {
        solve(m, &scene.sun, &scene.sky, scene.ground.as_ref(), s, progress)
    })?;
    let last = field.history.last().copied().unwrap_or(0.0);
    progress.log(&format!(
        "transport: {} ordinates, order {}, {} iterations (last change {last:.1e}); memory ≈ {:.0} MB: \
         {} full voxels × {} B + grid and DSA box (estimate)",
        field.ordinates,
        field.order,
        field.iterations(),
        memory.bytes as f64 / 1e6,
        field.full_voxels,
        TransportMemory::bytes_per_full_voxel(field.order),
    ));
    if let Some(w) = unconverged(&scene.source, &field.history, s) {
        progress.warn(&w);
    }
    let (diffuse, sun) = timings.time("eye source", || eye_source(scene, &field));
    // March with the δ-M extinction of the middle band (the bands differ only by σt f Δa).
    let mut scaled = m.clone();
    scaled.optics.sigma_t = field.optics.bands[1].sigma_t as f32;
    let cam = &scene.camera;
    let spp = scene.render.aa_samples;
    let step = scene.render.step_voxels * m.min_voxel();
    // Per pixel: [diffuse source, sun single scattering, background]; the image is their sum.
    let px = timings.time("gather", || {
        render_rows(cam.width, cam.height, progress, "transport gather", |x, y| {
            let mut sum = [Rgb::ZERO; 3];
            for smp in 0..spp {
                let (px, py, xi) = pixel_sample(scene, x, y, smp, spp);
                let ray = cam.ray(px, py);
                let (o, d) = (ray.origin, ray.dir);
                let t_max = scene.ground.as_ref().and_then(|g| g.intersect(o, d)).unwrap_or(f32::INFINITY);
                let ms = march(&scaled, o, d, 0.0, t_max, step, xi, |v, _| {
                    full_trilinear(m, &field.full, &diffuse, v)
                });
                let ss = march(&scaled, o, d, 0.0, t_max, step, xi, |v, _| full_trilinear(m, &field.full, &sun, v));
                let bg = if ms.transmittance > 0.0 {
                    background(scene, &field, o, d)
                } else {
                    Rgb::ZERO
                };
                sum[0] += ms.radiance;
                sum[1] += ss.radiance;
                sum[2] += bg * ms.transmittance;
            }
            sum.map(|c| (c / spp as f32).max(Rgb::ZERO))
        })
    });
    let mut img = Image::new(cam.width, cam.height);
    img.pixels = px.iter().map(|p| p[0] + p[1] + p[2]).collect();
    if scene.render.aov {
        for (c, name) in ["diffuse", "sun_single", "background"].iter().enumerate() {
            img.add_layer(name, px.iter().map(|p| p[c]).collect());
        }
    }
    Ok(img)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_an_iteration_stopped_by_its_cap_above_the_tolerance_is_warned_about() {
        let s = TransportSettings {
            max_iterations: 3,
            tolerance: 1e-2,
            ..TransportSettings::default()
        };
        let w = unconverged("s.toml", &[1.0, 0.3, 0.05], &s).expect("stopped at the cap");
        assert!(
            w.contains("s.toml") && w.contains("= 3") && w.contains("5.0e-2") && w.contains("raise render.transport_max_iterations"),
            "{w}"
        );
        // Converged on the last allowed iteration, converged early, or nothing to iterate.
        assert_eq!(unconverged("s.toml", &[1.0, 0.3, 0.005], &s), None);
        assert_eq!(unconverged("s.toml", &[1.0, 0.005], &s), None);
        assert_eq!(unconverged("s.toml", &[], &s), None);
    }
}
