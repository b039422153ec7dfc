//! Importance sampling of the sky for next-event estimation.
//!
//! [`SkySampler`] forwards to `Sky::sample` / `Sky::pdf`: the uniform sphere for the constant sky
//! (every direction equally bright), and a piecewise-constant distribution over the
//! equirectangular map for the atmosphere and environment maps, each pixel's weight bounding its
//! bilinear radiance (src/lighting/envmap.rs). MIS with
//! the phase function (or the ground's cosine lobe) takes care of the rest.

use crate::lighting::Sky;
use crate::math::{Rgb, Vec3};

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
        self.sky.sample(glam::Vec2::new(u[0], u[1]))
    }

    /// Density (sr⁻¹) with which [`SkySampler::sample`] picks `dir`.
    #[inline]
    pub fn pdf(&self, dir: Vec3) -> f32 {
        self.sky.pdf(dir)
    }
}
