//! [`super::beam_check`] for `full`: its gather takes the sun's transmittance
//! trilinear between the voxel centres of the sun grid ([`LitVolume::sun_t`]), whose chord lies
//! above the beam's exponential fall-off where the voxels are optically thick along the sun's
//! path (a cloud of 40-m voxels with the sun 0.6° behind it: `full` +30 % against `reference`).
//! Every second pixel's centre ray marches the middle band's sun single scattering (the exact HG
//! phase, `Optics::sun_single`) with T_sun trilinear and with ln T_sun trilinear (exact where τ
//! is linear), both in one march; the difference over the cloud's pixels, as a share of their light, is
//! logged and warned about as `transport`'s is.

use super::beam_check::{self, BeamSums};
use crate::image::Image;
use crate::lit::LitVolume;
use crate::math::Rgb;
use crate::medium::march::march_with;
use crate::scene::Scene;

/// The estimated share of the cloud's light in `image` (rendered from `lit`) by which the sun's
/// transmittance interpolated linearly between the voxel centres exceeds it interpolated
/// exponentially; `step_m` the gather's march step (m).
pub fn share(scene: &Scene, lit: &LitVolume, image: &Image, step_m: f32) -> f64 {
    let m = &lit.medium;
    let cam = &scene.camera;
    let sun_t = lit.sun_t();
    let dense = m.dense_density();
    // The exact single scattering's albedo (per unit of the marched extinction) and phase
    // (`Optics::sun_single`); the middle band's a·E, the phase per ray.
    let (albedo, phase) = m.optics.sun_single;
    let k = albedo.y * lit.sun.irradiance.y;
    beam_check::share_over_pixels(scene, |x, y, o, d, t_max| {
        let rho = |v: [f32; 3]| dense.trilinear(v);
        // One march, the two interpolations side by side (x: linear, y: exponential).
        let both = march_with(m, rho, o, d, 0.0, t_max, step_m, 0.5, |v, _, _| {
            let v = v.to_array();
            Rgb::new(sun_t.trilinear(v), sun_t.trilinear_log(v), 0.0)
        });
        // Light from the sun scattered back along the ray (sr⁻¹).
        let p = phase.eval(lit.sun.dir, -d);
        let total = image.pixels[(x + y * cam.width) as usize].y;
        BeamSums::pixel(k * p * both.radiance.x, k * p * both.radiance.y, total, both.transmittance < 0.99)
    })
}
