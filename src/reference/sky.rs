//! Importance sampling of the sky for next-event estimation.
//!
//! [`SkySampler`] has the same shape as `Sky::sample(u) -> (dir, radiance, pdf)` and
//! `Sky::pdf(dir)` (planned for environment maps and the atmosphere): when those land, the tracer
//! switches by changing the one line in `integrator.rs` that builds its sampler. It samples the
//! uniform sphere, which is valid for any sky model and ideal for the constant sky (every direction
//! equally bright); MIS with the phase function (or the ground's cosine lobe) takes care of the rest.

use crate::lighting::Sky;
use crate::math::{uniform_sphere, Rgb, Vec3};
use std::f32::consts::PI;

/// Samples directions towards the sky.
#[derive(Clone, Debug)]
pub struct SkySampler<'a> {
    sky: &'a Sky,
}

impl<'a> SkySampler<'a> {
    /// A sampler for `sky`.
    pub fn new(sky: &'a Sky) -> Self {
        SkySampler { sky }
    }

    /// A direction towards the sky from two uniforms, its radiance (W·m⁻²·sr⁻¹) and its density (sr⁻¹).
    #[inline]
    pub fn sample(&self, u: [f32; 2]) -> (Vec3, Rgb, f32) {
        let dir = uniform_sphere(u[0], u[1]);
        (dir, self.sky.radiance(dir), 1.0 / (4.0 * PI))
    }

    /// Density (sr⁻¹) with which [`SkySampler::sample`] picks `dir`.
    #[inline]
    pub fn pdf(&self, dir: Vec3) -> f32 {
        let _ = dir;
        1.0 / (4.0 * PI)
    }
}
