//! The scene file (TOML): its keys, their defaults (the built-in default scene), validation with
//! messages that name the file and field, and the runtime [`Scene`] built from it.
//!
//! Every table and key is optional; a missing one takes the default scene's value. Unknown keys
//! are an error that names the key.

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::lighting::{Ground, Sky, Sun};
use crate::math::{Rgb, Vec3};
use crate::medium::Medium;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// `[medium]`: the cloud's density grid and its optical properties.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct MediumDesc {
    /// `"procedural"` or a path relative to the scene file: `.vol`, `.npy`, `.raw` (+ `.json`), `.vdb`.
    pub grid: String,
    /// Seed of the procedural cumulus.
    pub seed: u64,
    /// Procedural resolution (nx, ny, nz).
    pub resolution: [usize; 3],
    /// Voxel edge length (m), for `.npy`, `.raw` and procedural grids.
    pub voxel_size: f32,
    /// Minimum corner of the grid (m), for `.npy`, `.raw` and procedural grids.
    pub origin: [f32; 3],
    /// Extinction coefficient at density 1 (m⁻¹).
    pub sigma_t: f32,
    /// Single-scattering albedo per RGB band (unitless, in [0, 1]).
    pub albedo: [f32; 3],
    /// Henyey–Greenstein mean cosine (unitless, |g| < 1).
    pub g: f32,
    /// Grid to read from a `.vdb` file.
    pub grid_name: String,
    /// Extra factor on a `.vdb` file's index-to-world transform (unitless).
    pub scale: f32,
    /// Largest dense grid accepted, in voxels (memory guard; 4 bytes each plus solver storage).
    pub max_voxels: u64,
    /// Average N×N×N blocks after loading (1 = off).
    pub downsample: usize,
}

impl Default for MediumDesc {
    fn default() -> Self {
        MediumDesc {
            grid: "procedural".into(),
            seed: 1,
            resolution: [100, 80, 60],
            voxel_size: 10.0,
            origin: [-500.0, 0.0, -300.0],
            sigma_t: 0.05,
            albedo: [0.999, 0.999, 0.999],
            g: 0.9,
            grid_name: "density".into(),
            scale: 1.0,
            max_voxels: 200_000_000,
            downsample: 1,
        }
    }
}

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
}

impl Default for SkyDesc {
    fn default() -> Self {
        SkyDesc {
            model: SkyModel::Constant,
            radiance: [0.3, 0.45, 0.8],
            altitude_m: 0.0,
            map_width: crate::lighting::DEFAULT_MAP_WIDTH,
            planet_albedo: [0.3, 0.3, 0.3],
            path: None,
            scale: 1.0,
        }
    }
}

/// `[ground]`: an infinite Lambertian plane y = height.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct GroundDesc {
    /// Height of the plane (m).
    pub height: f32,
    /// Lambertian albedo per band (unitless, in [0, 1]).
    pub albedo: [f32; 3],
}

impl Default for GroundDesc {
    fn default() -> Self {
        GroundDesc {
            height: 0.0,
            albedo: [0.3, 0.3, 0.3],
        }
    }
}

/// `[camera]`: a pinhole camera.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct CameraDesc {
    /// Eye position (m).
    pub position: [f32; 3],
    /// Point looked at (m).
    pub look_at: [f32; 3],
    /// Up hint; must not be parallel to the view direction.
    pub up: [f32; 3],
    /// Vertical field of view (degrees).
    pub fov_deg: f32,
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
}

impl Default for CameraDesc {
    fn default() -> Self {
        CameraDesc {
            position: [0.0, 350.0, 1500.0],
            look_at: [0.0, 330.0, 0.0],
            up: [0.0, 1.0, 0.0],
            fov_deg: 40.0,
            width: 480,
            height: 360,
        }
    }
}

/// Rendering method.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Exact single scattering of the sun plus the attenuated background (paper Fig. 4).
    Single,
    /// Unbiased volumetric path tracing (delta/ratio tracking, NEE + MIS): the ground truth.
    Reference,
    /// Diffusion (stage 1 + eq. 4 solved by multigrid) composited with exact sun single scattering (paper Fig. 5).
    Diffusion,
    /// Diffusion, clear-air propagation with viewing cubes and ground hemicubes, and the
    /// low-density edge treatment in the final gather (paper Fig. 7).
    Full,
    /// Converged discrete-ordinates transport (δ-M, SH source, DSA) with TMS single scattering.
    Transport,
}

impl Method {
    /// The name used in scene files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Method::Single => "single",
            Method::Reference => "reference",
            Method::Diffusion => "diffusion",
            Method::Full => "full",
            Method::Transport => "transport",
        }
    }
}

/// `[render]`.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct RenderDesc {
    /// The method.
    pub method: Method,
    /// Seed of every random stream.
    pub seed: u64,
    /// Samples per pixel.
    pub spp: u32,
    /// Exposure of the PNG preview, in stops (the EXR is never scaled).
    pub exposure: f32,
    /// Ray-march step of the gather, as a fraction of the smallest voxel edge (unitless).
    pub step: f32,
    /// `reference`: most scattering events (medium or ground) per path; absent = no cap.
    pub max_depth: Option<u32>,
    /// `reference`: stop after the pass in progress once this many seconds have passed.
    pub time_limit: Option<f64>,
    /// `reference`: add the per-pixel standard error of the mean as EXR layer `stderr`.
    pub stderr: bool,
    /// Pixels per face edge of the viewing cubes (a multiple of 4; docs/cubes.md).
    pub cube_resolution: usize,
    /// Ground irradiance samples per edge (N×N hemicubes; docs/cubes.md).
    pub ground_samples: usize,
    /// Density T below which the final gather uses the edge treatment (paper section 4); 0 turns it off.
    pub low_density_threshold: f32,
    /// Relative residual the diffusion solver must reach (unitless).
    pub solver_tolerance: f64,
    /// Most conjugate-gradient iterations of the diffusion solver per band.
    pub solver_max_iterations: usize,
    /// `full`: most clear-air propagation iterations (0: diffusion plus edges only, paper Fig. 6).
    pub iterations: usize,
    /// Stage 1 with similarity (δ-) scaling, forward fraction f = g (docs/diffusion.md): keeps I0
    /// positive on sunlit faces but, with the paper's gather, darkens the cloud (measured against
    /// `reference`: luminance bias −62 % vs −21 %), so off by default; false: the paper's
    /// first-moment Q1 scheme exactly.
    pub delta_scaling: bool,
    /// `full`: stop iterating once I0 changes by less than this fraction (unitless).
    pub propagation_tolerance: f64,
    /// `full`: write the components (diffusion, low_density, sun_single, background) as EXR layers.
    pub aov: bool,
    /// `diffusion`, `full`: the gather's diffuse source is a·max(0, I0 + g·I1·ω) instead of a·I0
    /// (src/diffusion/flux.rs, docs/diffusion.md).
    pub diffuse_anisotropy: bool,
}

impl Default for RenderDesc {
    fn default() -> Self {
        RenderDesc {
            method: Method::Single,
            seed: 0,
            spp: 1,
            exposure: 0.0,
            step: 0.5,
            max_depth: None,
            time_limit: None,
            stderr: false,
            cube_resolution: crate::cube::render::DEFAULT_CUBE_RESOLUTION,
            ground_samples: crate::cube::render::DEFAULT_GROUND_SAMPLES,
            low_density_threshold: crate::edges::gather::DEFAULT_THRESHOLD,
            iterations: crate::render::full::DEFAULT_ITERATIONS,
            propagation_tolerance: crate::render::full::DEFAULT_PROPAGATION_TOLERANCE,
            aov: false,
            delta_scaling: false,
            solver_tolerance: 1e-6,
            solver_max_iterations: 200,
            diffuse_anisotropy: false,
        }
    }
}

/// The whole scene file, as written.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SceneDesc {
    /// `[medium]`.
    pub medium: MediumDesc,
    /// `[sun]`.
    pub sun: SunDesc,
    /// `[sky]`.
    pub sky: SkyDesc,
    /// `[ground]`, absent for no ground.
    pub ground: Option<GroundDesc>,
    /// `[camera]`.
    pub camera: CameraDesc,
    /// `[render]`.
    pub render: RenderDesc,
}

impl Default for SceneDesc {
    /// The built-in default scene: the procedural cumulus over a grey ground, sun high behind the camera's right.
    fn default() -> Self {
        SceneDesc {
            medium: MediumDesc::default(),
            sun: SunDesc::default(),
            sky: SkyDesc::default(),
            ground: Some(GroundDesc::default()),
            camera: CameraDesc::default(),
            render: RenderDesc::default(),
        }
    }
}

/// Name used in messages for the scene without a file.
pub const BUILTIN: &str = "built-in scene";

impl SceneDesc {
    /// Parse TOML text; `file` names the source in error messages.
    pub fn from_toml(text: &str, file: &str) -> Result<Self> {
        toml::from_str(text).map_err(|e| Error::Parse {
            file: file.to_string(),
            message: e.to_string().trim_end().to_string(),
        })
    }

    /// Read and parse a scene file.
    pub fn from_file(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Self::from_toml(&text, &path.display().to_string())
    }

    /// Serialise back to TOML (used by `export` and the tests).
    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).unwrap_or_default()
    }
}

/// Settings of the render itself (from `[render]` after validation).
#[derive(Clone, Debug)]
pub struct RenderSettings {
    /// The method.
    pub method: Method,
    /// Seed of every random stream.
    pub seed: u64,
    /// Samples per pixel (≥ 1).
    pub spp: u32,
    /// PNG exposure (stops).
    pub exposure: f32,
    /// March step as a fraction of the smallest voxel edge.
    pub step: f32,
    /// `reference`: most scattering events per path (None = unlimited).
    pub max_depth: Option<u32>,
    /// `reference`: wall-clock budget in seconds (None = render all spp).
    pub time_limit: Option<f64>,
    /// `reference`: write the standard-error layer.
    pub stderr: bool,
    /// Viewing-cube and hemicube settings (`render.cube_resolution`, `render.ground_samples`).
    pub cubes: crate::cube::CubeOptions,
    /// Density below which the edge treatment applies (0: off).
    pub low_density_threshold: f32,
    /// Diffusion solver: relative residual to reach.
    pub solver_tolerance: f64,
    /// Diffusion solver: most iterations per band.
    pub solver_max_iterations: usize,
    /// `full`: most clear-air propagation iterations (0: diffusion plus edges only, paper Fig. 6).
    pub iterations: usize,
    /// Stage 1 with similarity (δ-) scaling, forward fraction f = g (docs/diffusion.md); false:
    /// the paper's first-moment Q1 scheme exactly.
    pub delta_scaling: bool,
    /// `full`: stop iterating once I0 changes by less than this fraction (unitless).
    pub propagation_tolerance: f64,
    /// `full`: write the components (diffusion, low_density, sun_single, background) as EXR layers.
    pub aov: bool,
    /// `diffusion`, `full`: the gather's diffuse source is a·max(0, I0 + g·I1·ω) instead of a·I0
    /// (src/diffusion/flux.rs, docs/diffusion.md).
    pub diffuse_anisotropy: bool,
}

/// A validated scene, ready to render.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Where it came from (file path or [`BUILTIN`]), for messages.
    pub source: String,
    /// The description it was built from.
    pub desc: SceneDesc,
    /// The medium, loaded.
    pub medium: Medium,
    /// The sun.
    pub sun: Sun,
    /// The sky.
    pub sky: Sky,
    /// The ground, if any.
    pub ground: Option<Ground>,
    /// The camera.
    pub camera: Camera,
    /// Render settings.
    pub render: RenderSettings,
}

/// Check a finite number; `what` describes the allowed range for the message.
pub(crate) fn check(file: &str, field: &str, ok: bool, value: impl std::fmt::Debug, what: &str) -> Result<()> {
    if ok {
        Ok(())
    } else {
        Err(Error::invalid(file, field, format!("{value:?} is not allowed: {what}")))
    }
}

pub(crate) fn finite3(v: [f32; 3]) -> bool {
    v.iter().all(|x| x.is_finite())
}

pub(crate) fn rgb_in_unit(v: [f32; 3]) -> bool {
    v.iter().all(|x| (0.0..=1.0).contains(x))
}

pub(crate) fn rgb_nonneg(v: [f32; 3]) -> bool {
    v.iter().all(|x| x.is_finite() && *x >= 0.0)
}

impl Scene {
    /// Validate a description and load what it refers to. `source` names it in messages;
    /// relative grid paths resolve against `base_dir`.
    pub fn build(desc: SceneDesc, source: &str, base_dir: &Path) -> Result<Scene> {
        let f = source;
        let r = &desc.render;
        check(f, "render.spp", r.spp >= 1, r.spp, "samples per pixel must be at least 1")?;
        check(
            f,
            "render.exposure",
            r.exposure.is_finite(),
            r.exposure,
            "exposure must be a finite number of stops",
        )?;
        check(
            f,
            "render.step",
            r.step.is_finite() && r.step > 0.0 && r.step <= 4.0,
            r.step,
            "the march step is a fraction of a voxel in (0, 4]",
        )?;
        if let Some(t) = r.time_limit {
            check(
                f,
                "render.time_limit",
                t.is_finite() && t > 0.0,
                t,
                "the time limit is a positive number of seconds",
            )?;
        }
        let cubes = crate::cube::CubeOptions {
            res: r.cube_resolution,
            ground_samples: r.ground_samples,
            ..Default::default()
        };
        cubes.validate(f)?;
        check(
            f,
            "render.low_density_threshold",
            r.low_density_threshold.is_finite() && r.low_density_threshold >= 0.0,
            r.low_density_threshold,
            "the edge threshold is a density ≥ 0 (0 turns the edge treatment off)",
        )?;
        check(
            f,
            "render.iterations",
            r.iterations <= 20,
            r.iterations,
            "the clear-air iterations are a count from 0 to 20 (the paper found 1 enough)",
        )?;
        check(
            f,
            "render.propagation_tolerance",
            r.propagation_tolerance.is_finite() && r.propagation_tolerance >= 0.0,
            r.propagation_tolerance,
            "the propagation tolerance is a relative change ≥ 0, e.g. 0.01",
        )?;
        check(
            f,
            "render.solver_tolerance",
            r.solver_tolerance.is_finite() && r.solver_tolerance > 0.0 && r.solver_tolerance < 1.0,
            r.solver_tolerance,
            "the solver's relative residual must be in (0, 1), e.g. 1e-6",
        )?;
        check(
            f,
            "render.solver_max_iterations",
            r.solver_max_iterations >= 1,
            r.solver_max_iterations,
            "the solver needs at least 1 iteration (default 200)",
        )?;
        let camera = Camera::from_desc(&desc.camera, f)?;
        let (sun, sky) = crate::lighting::sun_and_sky(&desc.sun, &desc.sky, f, base_dir)?;
        let ground = match &desc.ground {
            Some(g) => Some(Ground::from_desc(g, f)?),
            None => None,
        };
        let medium = Medium::from_desc(&desc.medium, f, base_dir)?;
        let render = RenderSettings {
            method: r.method,
            seed: r.seed,
            spp: r.spp,
            exposure: r.exposure,
            step: r.step,
            max_depth: r.max_depth,
            time_limit: r.time_limit,
            stderr: r.stderr,
            cubes,
            low_density_threshold: r.low_density_threshold,
            iterations: r.iterations,
            propagation_tolerance: r.propagation_tolerance,
            aov: r.aov,
            delta_scaling: r.delta_scaling,
            solver_tolerance: r.solver_tolerance,
            solver_max_iterations: r.solver_max_iterations,
            diffuse_anisotropy: r.diffuse_anisotropy,
        };
        Ok(Scene {
            source: source.to_string(),
            desc,
            medium,
            sun,
            sky,
            ground,
            camera,
            render,
        })
    }

    /// The built-in default scene.
    pub fn default_scene() -> Result<Scene> {
        Scene::build(SceneDesc::default(), BUILTIN, Path::new("."))
    }

    /// Load a scene file (None: the built-in default scene), applying `edit` to the description first.
    pub fn load(path: Option<&Path>, edit: impl FnOnce(&mut SceneDesc)) -> Result<Scene> {
        let (mut desc, source, base) = match path {
            Some(p) => (
                SceneDesc::from_file(p)?,
                p.display().to_string(),
                p.parent().map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from(".")),
            ),
            None => (SceneDesc::default(), BUILTIN.to_string(), PathBuf::from(".")),
        };
        edit(&mut desc);
        Scene::build(desc, &source, &base)
    }

    /// Radiance arriving along a ray that leaves the medium's box without further scattering:
    /// the ground (lit by sun and sky, sun shadowed by the cloud) or the sky. The sun's disc is
    /// not included (a point sun is never seen directly).
    pub fn background(&self, origin: Vec3, dir: Vec3, sun_visibility: impl Fn(Vec3) -> f32) -> Rgb {
        if let Some(g) = &self.ground {
            if let Some(t) = g.intersect(origin, dir) {
                let p = origin + dir * t;
                return g.radiance(p, &self.sun, &self.sky, sun_visibility(p));
            }
        }
        self.sky.radiance(dir)
    }
}
