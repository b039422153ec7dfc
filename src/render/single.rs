//! Method `single` (the paper's Figure 4): exact single scattering of the attenuated sun through
//! the Henyey–Greenstein phase function, plus the attenuated sky or ground behind the cloud.
//! No multiple scattering: the cloud is dark, as the paper shows.

use super::{render_rows, Progress, Timings};
use crate::error::Result;
use crate::image::Image;
use crate::lit::sunlight::SunTransmittance;
use crate::math::{Rgb, Rng, Vec3};
use crate::medium::march::march_with;
use crate::scene::Scene;

/// Image-plane sample position for sample `s` of `spp` (pixel centre for one sample, else
/// stratified jitter on a √spp grid), and a march offset in [0, 1).
#[inline]
pub fn pixel_sample(scene: &Scene, x: u32, y: u32, s: u32, spp: u32) -> (f32, f32, f32) {
    let mut rng = Rng::for_pixel(scene.render.seed, x, y, s);
    let xi = rng.uniform();
    if spp == 1 {
        return (x as f32 + 0.5, y as f32 + 0.5, xi);
    }
    let n = (spp as f32).sqrt().ceil() as u32;
    let (sx, sy) = (s % n, (s / n) % n);
    (
        x as f32 + (sx as f32 + rng.uniform()) / n as f32,
        y as f32 + (sy as f32 + rng.uniform()) / n as f32,
        xi,
    )
}

/// Radiance of the background seen along a ray from `o` in direction `d` beyond `t_max`:
/// the ground (sun shadowed exactly by the cloud, marched on the dense copy of the density as
/// the eye rays are: the same bits) or the sky.
pub fn background(scene: &Scene, o: Vec3, d: Vec3) -> Rgb {
    scene.background(o, d, |p| scene.medium.dense_transmittance(p, scene.sun.dir, 0.0, f32::INFINITY))
}

/// Single-scattering radiance along one camera ray.
pub fn radiance(scene: &Scene, sun_t: &SunTransmittance, o: Vec3, d: Vec3, xi: f32) -> Rgb {
    let m = &scene.medium;
    let t_max = scene.ground.as_ref().and_then(|g| g.intersect(o, d)).unwrap_or(f32::INFINITY);
    let step = scene.render.step_voxels * m.min_voxel();
    // Light travels from the sun (direction −sun.dir) towards the eye (direction −d).
    let phase = m.optics.phase.eval(scene.sun.dir, -d);
    let sun_term = m.optics.albedo * scene.sun.irradiance * phase;
    // ρ from the dense copy on the cloud's box: the same bits, without the packed density's slot look-ups.
    let dense = m.dense_density();
    let r = march_with(
        m,
        |v| dense.trilinear(v),
        o,
        d,
        0.0,
        t_max,
        step,
        xi,
        |v, _, _| sun_term * sun_t.at_voxel(v),
    );
    if r.transmittance <= 0.0 {
        return r.radiance;
    }
    r.radiance + r.transmittance * background(scene, o, d)
}

/// Render the image.
pub fn render(scene: &Scene, progress: &dyn Progress, timings: &mut Timings) -> Result<Image> {
    let sun_t = timings.time("sun transmittance", || SunTransmittance::compute(&scene.medium, scene.sun.dir));
    sun_t.check_finite()?;
    let cam = &scene.camera;
    let spp = scene.render.aa_samples;
    let px = timings.time("gather", || {
        render_rows(cam.width, cam.height, progress, "single scattering", |x, y| {
            let mut sum = Rgb::ZERO;
            for s in 0..spp {
                let (px, py, xi) = pixel_sample(scene, x, y, s, spp);
                let ray = cam.ray(px, py);
                sum += radiance(scene, &sun_t, ray.origin, ray.dir, xi);
            }
            sum / spp as f32
        })
    });
    let mut img = Image::new(cam.width, cam.height);
    img.pixels = px;
    Ok(img)
}
