//! The ground as the lit volume carries it: the Lambertian plane with its irradiance, unoccluded
//! or sampled on a grid by the ground's hemicubes ([`crate::cube::ground`], paper section 3).

use crate::lighting::{Ground, Sky, Sun};
use crate::math::{Rgb, Vec3};
use std::f32::consts::PI;

/// Irradiance samples on a regular grid over a ground rectangle.
#[derive(Clone, Debug)]
pub struct GroundGrid {
    /// Minimum (x, z) corner of the rectangle (m).
    pub min: [f32; 2],
    /// Maximum (x, z) corner (m).
    pub max: [f32; 2],
    /// Samples per edge; sample (a, b) sits at the centre of cell (a, b) of an n×n split.
    pub n: usize,
    /// Irradiance (W/m² per band) per sample, index a + n·b (a along x, b along z).
    pub irradiance: Vec<Rgb>,
}

impl GroundGrid {
    /// World position (x, z) of sample (a, b).
    #[inline]
    pub fn sample_xz(&self, a: usize, b: usize) -> [f32; 2] {
        [
            self.min[0] + (a as f32 + 0.5) / self.n as f32 * (self.max[0] - self.min[0]),
            self.min[1] + (b as f32 + 0.5) / self.n as f32 * (self.max[1] - self.min[1]),
        ]
    }
}

/// The ground with its irradiance.
#[derive(Clone, Debug)]
pub struct LitGround {
    /// The plane and its albedo.
    pub ground: Ground,
    /// Irradiance with no cloud: sun (if above the horizon) plus the whole sky (W/m²).
    pub unoccluded: Rgb,
    /// Rendered samples, if any.
    pub grid: Option<GroundGrid>,
}

impl LitGround {
    /// A ground lit by the unoccluded sun and sky everywhere (no cloud shadow).
    pub fn unoccluded(ground: Ground, sun: &Sun, sky: &Sky) -> LitGround {
        let unoccluded = ground.irradiance(sun, sky, 1.0);
        LitGround {
            ground,
            unoccluded,
            grid: None,
        }
    }

    /// Irradiance (W/m²) at ground point `p` (its y is ignored): bilinear between the samples
    /// inside the grid's rectangle (clamped to the outermost samples), unoccluded outside.
    pub fn irradiance(&self, p: Vec3) -> Rgb {
        let Some(g) = &self.grid else {
            return self.unoccluded;
        };
        if p.x < g.min[0] || p.x > g.max[0] || p.z < g.min[1] || p.z > g.max[1] {
            return self.unoccluded;
        }
        let n = g.n;
        let fx = ((p.x - g.min[0]) / (g.max[0] - g.min[0]) * n as f32 - 0.5).clamp(0.0, (n - 1) as f32);
        let fz = ((p.z - g.min[1]) / (g.max[1] - g.min[1]) * n as f32 - 0.5).clamp(0.0, (n - 1) as f32);
        let (a0, b0) = (fx.floor() as usize, fz.floor() as usize);
        let (a1, b1) = ((a0 + 1).min(n - 1), (b0 + 1).min(n - 1));
        let (u, v) = (fx - a0 as f32, fz - b0 as f32);
        let e = |a: usize, b: usize| g.irradiance[a + n * b];
        (e(a0, b0) * (1.0 - u) + e(a1, b0) * u) * (1.0 - v) + (e(a0, b1) * (1.0 - u) + e(a1, b1) * u) * v
    }

    /// Outgoing radiance (W·m⁻²·sr⁻¹) of the Lambertian ground at `p`: albedo·E/π.
    #[inline]
    pub fn radiance(&self, p: Vec3) -> Rgb {
        self.ground.albedo * self.irradiance(p) / PI
    }
}
