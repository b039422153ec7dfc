//! Light sources: the sun (a directional light, never binned), the sky, and the Lambertian ground.

pub mod bins;

use crate::error::Result;
use crate::math::{Rgb, Vec3};
use crate::scene::{check, finite3, rgb_in_unit, rgb_nonneg, GroundDesc, SkyDesc, SkyModel, SunDesc};
use std::f32::consts::PI;
use std::path::Path;

pub use bins::{DirectionBins, CUBE_FACES};

/// The sun: a directional light.
#[derive(Clone, Debug)]
pub struct Sun {
    /// Unit direction towards the sun.
    pub dir: Vec3,
    /// Irradiance on a plane perpendicular to the rays (W/m² per band).
    pub irradiance: Rgb,
}

impl Sun {
    /// Validate `[sun]`.
    pub fn from_desc(d: &SunDesc, file: &str) -> Result<Sun> {
        let dir = match (d.direction, d.elevation_deg, d.azimuth_deg) {
            (Some(v), None, None) => {
                check(
                    file,
                    "sun.direction",
                    finite3(v) && Vec3::from(v).length() > 1e-12,
                    v,
                    "must be a finite non-zero vector towards the sun",
                )?;
                Vec3::from(v).normalize()
            }
            (None, Some(el), az) => {
                let az = az.unwrap_or(0.0);
                check(
                    file,
                    "sun.elevation_deg",
                    el.is_finite() && (-90.0..=90.0).contains(&el),
                    el,
                    "elevation must be in [-90, 90] degrees",
                )?;
                check(
                    file,
                    "sun.azimuth_deg",
                    az.is_finite(),
                    az,
                    "azimuth must be a finite number of degrees",
                )?;
                let (el, az) = (el.to_radians(), az.to_radians());
                Vec3::new(el.cos() * az.cos(), el.sin(), el.cos() * az.sin()).normalize()
            }
            (None, None, Some(_)) => {
                return Err(crate::Error::invalid(
                    file,
                    "sun.azimuth_deg",
                    "given without sun.elevation_deg: give both, or sun.direction",
                ));
            }
            (None, None, None) => {
                return Err(crate::Error::invalid(
                    file,
                    "sun.direction",
                    "missing: give sun.direction or sun.elevation_deg (+ azimuth_deg)",
                ));
            }
            (Some(_), _, _) => {
                return Err(crate::Error::invalid(
                    file,
                    "sun.direction",
                    "given together with sun.elevation_deg/azimuth_deg: give one or the other",
                ));
            }
        };
        check(
            file,
            "sun.irradiance",
            rgb_nonneg(d.irradiance),
            d.irradiance,
            "irradiance must be finite and non-negative (W/m²)",
        )?;
        Ok(Sun {
            dir,
            irradiance: Rgb::from(d.irradiance),
        })
    }
}

/// The sky's radiance model.
#[derive(Clone, Debug)]
pub enum SkyKind {
    /// The same radiance (W·m⁻²·sr⁻¹ per band) from every direction.
    Constant(Rgb),
}

/// The sky: radiance arriving from each direction, plus cached integrals.
#[derive(Clone, Debug)]
pub struct Sky {
    /// The model.
    pub kind: SkyKind,
    /// Irradiance on an upward-facing horizontal plane from the whole unoccluded upper
    /// hemisphere (W/m² per band).
    pub irradiance_up: Rgb,
}

impl Sky {
    /// Validate `[sky]`.
    pub fn from_desc(d: &SkyDesc, file: &str, _base_dir: &Path) -> Result<Sky> {
        match d.model {
            SkyModel::Constant => {
                check(
                    file,
                    "sky.radiance",
                    rgb_nonneg(d.radiance),
                    d.radiance,
                    "radiance must be finite and non-negative (W/(m² sr))",
                )?;
                Ok(Sky::constant(Rgb::from(d.radiance)))
            }
        }
    }

    /// A constant sky.
    pub fn constant(l: Rgb) -> Sky {
        Sky {
            kind: SkyKind::Constant(l),
            irradiance_up: l * PI,
        }
    }

    /// Radiance arriving from direction `dir` (unit, pointing away from the observer towards the sky).
    #[inline]
    pub fn radiance(&self, dir: Vec3) -> Rgb {
        match &self.kind {
            SkyKind::Constant(l) => {
                let _ = dir;
                *l
            }
        }
    }

    /// Numerically integrate the cosine-weighted upper hemisphere (for models without a closed form).
    pub fn integrate_irradiance_up(&self) -> Rgb {
        let (nt, np) = (64, 128);
        let mut e = Rgb::ZERO;
        for i in 0..nt {
            // Integrate over μ = cosθ ∈ [0, 1]; dω = dμ dφ.
            let mu = (i as f32 + 0.5) / nt as f32;
            let s = (1.0 - mu * mu).sqrt();
            for j in 0..np {
                let phi = (j as f32 + 0.5) / np as f32 * 2.0 * PI;
                let dir = Vec3::new(s * phi.cos(), mu, s * phi.sin());
                e += self.radiance(dir) * mu;
            }
        }
        e * (2.0 * PI / (nt * np) as f32)
    }
}

/// The ground: the infinite Lambertian plane y = height.
#[derive(Clone, Debug)]
pub struct Ground {
    /// Height of the plane (m).
    pub height: f32,
    /// Lambertian albedo per band.
    pub albedo: Rgb,
}

impl Ground {
    /// Validate `[ground]`.
    pub fn from_desc(d: &GroundDesc, file: &str) -> Result<Ground> {
        check(file, "ground.height", d.height.is_finite(), d.height, "must be a finite height (m)")?;
        check(
            file,
            "ground.albedo",
            rgb_in_unit(d.albedo),
            d.albedo,
            "each band must be in [0, 1]",
        )?;
        Ok(Ground {
            height: d.height,
            albedo: Rgb::from(d.albedo),
        })
    }

    /// Distance along a ray to the plane, seen from above only.
    #[inline]
    pub fn intersect(&self, origin: Vec3, dir: Vec3) -> Option<f32> {
        if origin.y > self.height && dir.y < -1e-7 {
            Some((self.height - origin.y) / dir.y)
        } else {
            None
        }
    }

    /// Irradiance (W/m² per band) at a ground point from the sun with visibility `sun_visibility`
    /// (cloud transmittance towards the sun) and the unoccluded sky.
    #[inline]
    pub fn irradiance(&self, sun: &Sun, sky: &Sky, sun_visibility: f32) -> Rgb {
        sun.irradiance * (sun.dir.y.max(0.0) * sun_visibility) + sky.irradiance_up
    }

    /// Outgoing radiance (W·m⁻²·sr⁻¹) of the ground at `_p`.
    #[inline]
    pub fn radiance(&self, _p: Vec3, sun: &Sun, sky: &Sky, sun_visibility: f32) -> Rgb {
        self.albedo * self.irradiance(sun, sky, sun_visibility) / PI
    }
}
