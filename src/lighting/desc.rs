//! The scene-file tables of the lighting: `[sun]`, `[sky]` and `[ground]`, with their defaults
//! (the built-in default scene's).

use serde::{Deserialize, Serialize};

/// `[sun]`: a directional light.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SunDesc {
    /// Direction towards the sun (normalised by the program). Exclusive with elevation/azimuth.
    /// Absent from a `[sun]` table (and no elevation given): the default scene's direction.
    #[serde(default)]
    pub direction: Option<[f32; 3]>,
    /// Elevation above the horizon (degrees); direction = (cos el cos az, sin el, cos el sin az).
    pub elevation_deg: Option<f32>,
    /// Azimuth (degrees), measured from +x towards +z.
    pub azimuth_deg: Option<f32>,
    /// Irradiance on a plane perpendicular to the rays (W/m² per band). Ignored when
    /// `from_atmosphere` is true.
    pub irradiance: [f32; 3],
    /// Derive the irradiance from the atmosphere: extraterrestrial solar irradiance × the
    /// transmittance along the sun's path from the observer (`sky.altitude_m`).
    pub from_atmosphere: bool,
    /// Angular diameter of the sun's disc (degrees; 0 = a point, the real sun is 0.53).
    pub angular_diameter_deg: f32,
}

impl Default for SunDesc {
    fn default() -> Self {
        SunDesc {
            direction: Some([0.3, 0.8, 0.5]),
            elevation_deg: None,
            azimuth_deg: None,
            irradiance: [3.0, 3.0, 3.0],
            from_atmosphere: false,
            angular_diameter_deg: 0.0,
        }
    }
}

/// Which sky model lights the scene.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum SkyModel {
    /// The same radiance from every direction.
    Constant,
    /// A physically based atmosphere (Rayleigh, Mie, ozone; single + multiple scattering).
    Atmosphere,
    /// An equirectangular HDR environment map (`sky.path`).
    Envmap,
}

/// `[sky]`.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SkyDesc {
    /// The model.
    pub model: SkyModel,
    /// Radiance of the constant sky (W·m⁻²·sr⁻¹ per band).
    pub radiance: [f32; 3],
    /// Atmosphere: the observer's altitude above the planet's ground (m).
    pub altitude_m: f32,
    /// Atmosphere: width of the precomputed equirectangular sky map (pixels, height = width/2).
    pub map_width: u32,
    /// Atmosphere: albedo of the planet's ground (unitless per band, in [0, 1]).
    pub planet_albedo: [f32; 3],
    /// Envmap: equirectangular OpenEXR file, relative to the scene file.
    pub path: Option<String>,
    /// Envmap: factor on the file's radiance (unitless).
    pub scale: f32,
    /// Envmap: take the map's sun out of it and make it the scene's sun (docs/sky.md, "A sun in
    /// the map"): true asks for it (an error where the map holds none), false keeps the map as it
    /// is, and left out it is done where the map holds a sun and the scene's `[sun]` no light of
    /// its own.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub extract_sun: Option<bool>,
}

impl Default for SkyDesc {
    fn default() -> Self {
        SkyDesc {
            model: SkyModel::Constant,
            radiance: [0.3, 0.45, 0.8],
            altitude_m: 0.0,
            map_width: super::DEFAULT_MAP_WIDTH,
            planet_albedo: [0.3, 0.3, 0.3],
            path: None,
            scale: 1.0,
            extract_sun: None,
        }
    }
}

/// `[ground]`: an infinite Lambertian plane y = height.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct GroundDesc {
    /// False: no ground, as if the table were absent.
    pub enabled: bool,
    /// Height of the plane (m).
    pub height: f32,
    /// Lambertian albedo per band (unitless, in [0, 1]).
    pub albedo: [f32; 3],
}

impl Default for GroundDesc {
    fn default() -> Self {
        GroundDesc {
            enabled: true,
            height: 0.0,
            albedo: [0.3, 0.3, 0.3],
        }
    }
}
