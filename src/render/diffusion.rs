//! Method `diffusion` (the paper's Figure 5): stage 1 (incident light), stage 2 (diffusion solve)
//! and a final gather that composites, front to back, the diffusion radiance I0 as the volume's
//! colour with opacity from ρσt plus the exact single scattering of the reduced sun, over the sky
//! or ground. See [`crate::lit::LitVolume`] for the source term.

use super::single::{background, pixel_sample};
use super::{render_rows, Progress, Timings};
use crate::diffusion::{solve_diffusion, DiffusionSettings};
use crate::error::Result;
use crate::image::Image;
use crate::incident::compute_incident;
use crate::lit::LitVolume;
use crate::math::Rgb;
use crate::scene::Scene;

/// Solver settings from `[render]`.
pub fn settings(scene: &Scene) -> DiffusionSettings {
    DiffusionSettings {
        tolerance: scene.render.solver_tolerance,
        max_iterations: scene.render.solver_max_iterations,
        ..DiffusionSettings::default()
    }
}

/// Stages 1 and 2: the lit volume of a scene (no clear-air iterations).
pub fn lit_volume(scene: &Scene, progress: &dyn Progress, timings: &mut Timings) -> Result<LitVolume> {
    let inc = timings.time("incident light", || compute_incident(scene, None));
    let sol = timings.time("diffusion solve", || solve_diffusion(&scene.medium, &inc, None, &settings(scene)))?;
    progress.log(&sol.summary());
    let lit = LitVolume::new(&scene.medium, &inc, &sol);
    if scene.render.diffuse_anisotropy {
        return Ok(lit.with_diffuse_anisotropy(&inc, &sol, settings(scene).min_optical_depth));
    }
    Ok(lit)
}

/// Render the image.
pub fn render(scene: &Scene, progress: &dyn Progress, timings: &mut Timings) -> Result<Image> {
    let lit = lit_volume(scene, progress, timings)?;
    let cam = &scene.camera;
    let spp = scene.render.aa_samples;
    let step = scene.render.step * scene.medium.min_voxel();
    let px = timings.time("gather", || {
        render_rows(cam.width, cam.height, progress, "diffusion gather", |x, y| {
            let mut sum = Rgb::ZERO;
            for s in 0..spp {
                let (px, py, xi) = pixel_sample(scene, x, y, s, spp);
                let ray = cam.ray(px, py);
                let t_max = scene
                    .ground
                    .as_ref()
                    .and_then(|g| g.intersect(ray.origin, ray.dir))
                    .unwrap_or(f32::INFINITY);
                let r = lit.march(ray.origin, ray.dir, 0.0, t_max, step, xi);
                sum += r.radiance;
                if r.transmittance > 0.0 {
                    sum += r.transmittance * background(scene, ray.origin, ray.dir);
                }
            }
            sum / spp as f32
        })
    });
    let mut img = Image::new(cam.width, cam.height);
    img.pixels = px;
    Ok(img)
}
