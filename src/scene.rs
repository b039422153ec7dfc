//! The scene file (TOML): its keys, their defaults (the built-in default scene), validation with
//! messages that name the file and field, and the runtime [`Scene`] built from it.
//!
//! Every table and key is optional; a missing one takes the default scene's value. Unknown keys
//! are an error that names the key.

use crate::camera::Camera;
pub use crate::camera::CameraDesc;
use crate::cube::{ClearAirSettings, CubeOptions};
use crate::diffusion::DiffusionSettings;
use crate::edges::gather::EdgeSettings;
use crate::error::{check, Error, Result};
use crate::incident::IncidentSettings;
use crate::lighting::{Ground, Sky, Sun};
pub use crate::lighting::{GroundDesc, SkyDesc, SkyModel, SunDesc};
use crate::math::{Rgb, Vec3};
use crate::medium::Medium;
pub use crate::medium::MediumDesc;
use crate::transport::solve::TransportSettings;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Finest `render.step` (voxels): 100 samples per voxel edge; the march time grows as 1/step.
const MIN_STEP_VOXELS: f32 = 0.01;

/// Rendering method.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
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
    /// Every method.
    pub const ALL: [Method; 5] = [
        Method::Single,
        Method::Reference,
        Method::Diffusion,
        Method::Full,
        Method::Transport,
    ];

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

/// Declares the `[render]` table once: each row is a scene-file key with its doc and type, the
/// field of [`RenderSettings`] (usually a stage's settings struct) it sets, and, after `for`, the
/// methods that read it (none named: every method) with an optional hint for the others
/// ([`RENDER_KEYS`]: the CLI warns when a key is set for a method that does not read it). The
/// key's default is that field's default, so a new setting is one row here plus its field in the
/// stage that owns it. (serde's `flatten` would let the stage structs deserialise directly, but it loses the
/// key and line in type errors and cannot be combined with `deny_unknown_fields`.)
macro_rules! render_table {
    ($( $(#[$doc:meta])* $key:ident : $ty:ty => $($path:ident).+ $(, for [$($method:ident),+] $(($hint:literal))?)? ; )*) => {
        /// Every `[render]` key with the methods that read it.
        pub const RENDER_KEYS: &[RenderKey] = &[
            $( RenderKey {
                key: stringify!($key),
                methods: render_key_methods!($($($method),+)?),
                hint: render_key_hint!($($($hint)?)?),
            }, )*
        ];

        /// `[render]`: the flat table of the scene file (see `RenderSettings` for where each
        /// key goes).
        #[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
        #[serde(deny_unknown_fields, default)]
        pub struct RenderDesc {
            $( $(#[$doc])* pub $key: $ty, )*
        }

        impl Default for RenderDesc {
            fn default() -> Self {
                let s = RenderSettings::default();
                RenderDesc { $( $key: s.$($path).+.clone(), )* }
            }
        }

        impl RenderDesc {
            /// Set the fields the keys map to (validation is the owners' and [`Scene::build`]'s).
            fn apply(&self, s: &mut RenderSettings) {
                $( s.$($path).+ = self.$key.clone(); )*
            }
        }
    };
}

/// The methods of a [`render_table!`] row: those named, or every method.
macro_rules! render_key_methods {
    () => {
        &Method::ALL
    };
    ($($method:ident),+) => {
        &[$(Method::$method),+]
    };
}

/// The hint of a [`render_table!`] row, if it gives one.
macro_rules! render_key_hint {
    () => {
        None
    };
    ($hint:literal) => {
        Some($hint)
    };
}

/// A `[render]` key and the methods that read it.
#[derive(Clone, Copy, Debug)]
pub struct RenderKey {
    /// The key (without `render.`).
    pub key: &'static str,
    /// The methods that read it.
    pub methods: &'static [Method],
    /// Why it does not apply to the other methods, or what they read instead.
    pub hint: Option<&'static str>,
}

impl RenderKey {
    /// Whether method `m` reads the key.
    pub fn applies_to(&self, m: Method) -> bool {
        self.methods.contains(&m)
    }
}

render_table! {
    /// The method.
    method: Method => method;
    /// Seed of every random stream.
    seed: u64 => seed;
    /// `reference`: samples (paths) per pixel.
    spp: u32 => spp, for [Reference] ("it is the path tracer's samples per pixel; the deterministic methods' anti-aliasing is render.aa_samples");
    /// `single`, `diffusion`, `full`, `transport`: anti-aliasing samples per pixel (stratified
    /// positions, one whole gather each); independent of the path tracer's `spp`.
    aa_samples: u32 => aa_samples, for [Single, Diffusion, Full, Transport] ("its samples per pixel are render.spp");
    /// Exposure of the PNG preview, in stops (the EXR is never scaled).
    exposure: f32 => exposure;
    /// Ray-march step of the gather, as a fraction of the smallest voxel edge (unitless).
    step: f32 => step_voxels, for [Single, Diffusion, Full, Transport] ("it tracks collisions exactly, without a march step");
    /// `reference`: most scattering events (medium or ground) per path; absent = no cap.
    max_depth: Option<u32> => max_depth, for [Reference];
    /// `reference`: stop after the pass in progress once this many seconds have passed.
    time_limit: Option<f64> => time_limit, for [Reference];
    /// `reference`: add the per-pixel standard error of the mean as EXR layer `stderr`.
    stderr: bool => stderr, for [Reference];
    /// Pixels per face edge of the viewing cubes (a multiple of 4; docs/cubes.md).
    cube_resolution: usize => cubes.res, for [Full];
    /// Ground irradiance samples per edge (N×N hemicubes; docs/cubes.md).
    ground_samples: usize => cubes.ground_samples, for [Full];
    /// Density T below which the final gather uses the edge treatment (paper section 4); 0 turns it off.
    low_density_threshold: f32 => edges.threshold, for [Full];
    /// `full`: optical depth D_s (after the δ-M transform) of every eye ray's surface layer that
    /// the final gather renders with the Poisson orders of eqs. 8–9, like a low-density segment,
    /// instead of the diffusion source (docs/edges.md, "The surface layer"); 0: the paper's scheme.
    surface_depth: f32 => edges.surface_depth, for [Full];
    /// `full`: fraction of `surface_depth` over which the surface layer blends into the diffusion
    /// source (smoothstep in optical depth), in [0, 1].
    surface_band: f32 => edges.surface_band, for [Full];
    /// Relative residual the diffusion solver must reach (unitless).
    solver_tolerance: f64 => solver.tolerance, for [Diffusion, Full];
    /// Most conjugate-gradient iterations of the diffusion solver per band.
    solver_max_iterations: usize => solver.max_iterations, for [Diffusion, Full];
    /// `full`: most clear-air propagation iterations (0: diffusion plus edges only, paper Fig. 6).
    iterations: usize => clear_air.iterations, for [Full];
    /// `full`: stop iterating once I0 changes by less than this fraction (unitless).
    propagation_tolerance: f64 => clear_air.propagation_tolerance, for [Full];
    /// `full`, `transport`: write the method's components as EXR layers (docs/scene.md, "AOVs").
    aov: bool => aov, for [Full, Transport] ("only full and transport write AOV layers");
    /// `diffusion`, `full`: the gather's diffuse source is a·max(0, I0 + g·I1·ω) instead of a·I0
    /// (src/diffusion/flux.rs, docs/diffusion.md); default on (measured with the δ-M transform,
    /// docs/budget.md "Fixes"), false: the paper's gather.
    diffuse_anisotropy: bool => diffuse_anisotropy, for [Diffusion, Full];
    /// `diffusion`, `full`: add the single scattering of the reduced sky and ground light to the
    /// gather's source, a·∫p·I_ri,sky (src/lit/sky_single.rs); default on (docs/budget.md
    /// "Fixes"), false: the paper's gather.
    sky_single_scattering: bool => incident.sky_single, for [Diffusion, Full];
    /// `diffusion`, `full`: the sky and ground light enter through the diffusion's boundary
    /// condition (eq. 7 with each boundary face's incoming radiance; `full`'s clear-air cubes give
    /// it per face) instead of as stage 1's reduced sky bins (src/diffusion/boundary.rs); default
    /// on (docs/budget.md "The sky through the boundary"), false: the paper's scheme.
    sky_boundary: bool => solver.sky_boundary, for [Diffusion, Full];
    /// `diffusion`, `full`: forward fraction f of the δ-M transform every stage runs on
    /// (0 ≤ f < 1, capped at g; src/optics.rs); default 0.65, measured in docs/budget.md ("The sky through the boundary");
    /// 0 is the paper's scheme exactly.
    forward_fraction: f32 => forward_fraction, for [Diffusion, Full];
    /// `transport`: Legendre order L of the δ-M phase function and of the spherical-harmonic
    /// source, 1 to 15 (memory 24·(L + 1)² bytes per full voxel; docs/transport.md).
    transport_order: usize => transport.order, for [Transport];
    /// `transport`: Gauss–Legendre ordinates in cos θ, even, 2 to 32; up to twice as many
    /// azimuths per ring (`transport_reduced_azimuths`: 96 ordinates at 8, else 8 × 16 = 128).
    /// At least L + 1 for order L.
    transport_polar_ordinates: usize => transport.n_mu, for [Transport];
    /// `transport`: fewer azimuths on the rings of ordinates towards the poles, about 2·n·sin θ
    /// and at least 8 (SHDOM's reduced grid: 96 ordinates at the default 8; exact for harmonics
    /// with |m| ≤ 3); false: 2·n on every ring (128), exact for every harmonic of order ≤ n − 1.
    transport_reduced_azimuths: bool => transport.reduced_azimuths, for [Transport];
    /// `transport`: stop iterating once I0 changes by less than this fraction of its largest
    /// value between iterations (unitless, 0 < t < 1).
    transport_tolerance: f64 => transport.tolerance, for [Transport];
    /// `transport`: most source iterations (sweeps of every ordinate), at least 1.
    transport_max_iterations: usize => transport.max_iterations, for [Transport];
    /// `transport`: accelerate the iteration with a diffusion solve (DSA); false: plain source
    /// iteration (many more sweeps in thick clouds).
    transport_acceleration: bool => transport.acceleration, for [Transport];
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
    /// `[ground]`, absent for no ground (so a scene file without the table has none, unlike the
    /// other tables, which take the default scene's values).
    #[serde(default)]
    pub ground: Option<GroundDesc>,
    /// `[camera]`.
    pub camera: CameraDesc,
    /// `[render]`.
    pub render: RenderDesc,
    /// `[animation]`: frames and keyframes (src/sequence); absent for a still.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub animation: Option<AnimationDesc>,
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
            animation: None,
        }
    }
}

/// Name used in messages for the scene without a file.
pub const BUILTIN: &str = "built-in scene";

impl SceneDesc {
    /// Parse TOML text; `file` names the source in error messages.
    pub fn from_toml(text: &str, file: &str) -> Result<Self> {
        let mut desc: SceneDesc = toml::from_str(text).map_err(|e| Error::Parse {
            file: file.to_string(),
            message: e.to_string().trim_end().to_string(),
        })?;
        // serde reads a `[T; 3]` from the first three items and ignores the rest.
        if let Ok(table) = text.parse::<toml::Table>() {
            check_array_lengths(&table, "", file)?;
            check_f32_overflow(&table, &desc, file)?;
            // A file without a `[camera]` table frames its cloud (camera.fit).
            if !table.contains_key("camera") {
                desc.camera.fit = true;
            }
        }
        Ok(desc)
    }

    /// Read and parse a scene file.
    pub fn from_file(path: &Path) -> Result<Self> {
        let bytes = crate::io::read_capped(path, crate::io::MAX_TEXT_BYTES, "a scene file")?;
        let text = String::from_utf8(bytes).map_err(|e| {
            Error::format(
                path.display().to_string(),
                format!(
                    "not UTF-8 text (invalid byte at offset {}): a scene file is TOML text, see examples/default.toml",
                    e.utf8_error().valid_up_to()
                ),
            )
        })?;
        Self::from_toml(&text, &path.display().to_string())
    }

    /// Serialise back to TOML (used by `export` and the tests).
    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).unwrap_or_default()
    }
}

pub use crate::limits::{MAX_COORDINATE, MAX_EXPOSURE, MAX_LIGHT, MAX_SIGMA_T};

/// Refuse finite magnitudes no f32 render can hold (the owners refuse NaN, inf and negatives).
pub(crate) fn check_magnitudes(d: &SceneDesc, f: &str) -> Result<()> {
    let light = format!("at most {MAX_LIGHT:e}; the sun gives 1361 W/m² (default 3), larger values overflow f32 in the methods");
    let place = format!("each coordinate within ±{MAX_COORDINATE:e} m; move the scene near the origin");
    let rows: [(&str, Vec<f32>, &str); 7] = [
        ("sun.irradiance", d.sun.irradiance.to_vec(), &light),
        ("sky.radiance", d.sky.radiance.to_vec(), &light),
        ("sky.scale", vec![d.sky.scale], &light),
        (
            "medium.sigma_t",
            vec![d.medium.sigma_t],
            "at most 1e9 m⁻¹ (an optical depth of 1 per nanometre); clouds have 0.01–1 m⁻¹",
        ),
        ("medium.origin", d.medium.origin.to_vec(), &place),
        ("camera.position", d.camera.position.to_vec(), &place),
        ("camera.look_at", d.camera.look_at.to_vec(), &place),
    ];
    for (key, values, what) in rows {
        let max = largest_magnitude(key);
        check(f, key, values.iter().all(|v| !v.is_finite() || v.abs() <= max), &values, what)?;
    }
    check(
        f,
        "render.exposure",
        d.render.exposure.abs() <= largest_magnitude("render.exposure") || !d.render.exposure.is_finite(),
        d.render.exposure,
        "at most ±64 stops; past 127 the preview's scale factor overflows f32",
    )
}

/// The largest magnitude scene field `key` takes: its own bound where [`check_magnitudes`] has
/// one, else f32's largest (every other float field is an f32 or an f64).
fn largest_magnitude(key: &str) -> f32 {
    match key {
        "sun.irradiance" | "sky.radiance" | "sky.scale" => MAX_LIGHT,
        "medium.sigma_t" => MAX_SIGMA_T,
        "medium.origin" | "camera.position" | "camera.look_at" => MAX_COORDINATE,
        "render.exposure" => MAX_EXPOSURE,
        _ => f32::MAX,
    }
}

/// Refuse a number of the file that its f32 field cannot hold (`1e39` reads as infinity, whose
/// message would be "inf is not allowed"), naming the field, the value as written and the
/// largest allowed. `desc` is `table` parsed: a field infinite in `desc` where `table` holds a
/// finite number overflowed. One walk covers every field; f64 fields hold such numbers and pass.
fn check_f32_overflow(table: &toml::Table, desc: &SceneDesc, file: &str) -> Result<()> {
    fn walk(written: &toml::Value, parsed: &toml::Value, key: &str, file: &str) -> Result<()> {
        use toml::Value::{Array, Float, Table};
        match (written, parsed) {
            (Table(w), Table(p)) => {
                for (k, v) in w {
                    let name = if key.is_empty() { k.clone() } else { format!("{key}.{k}") };
                    if let Some(pv) = p.get(k) {
                        walk(v, pv, &name, file)?;
                    }
                }
            }
            // An array of tables names each (`animation.key[0].sun`); a list of numbers is one field.
            (Array(w), Array(p)) => {
                for (i, (v, pv)) in w.iter().zip(p).enumerate() {
                    let name = if v.is_table() { format!("{key}[{i}]") } else { key.to_string() };
                    walk(v, pv, &name, file)?;
                }
            }
            (Float(x), Float(y)) if x.is_finite() && y.is_infinite() => {
                let largest = largest_magnitude(key);
                let kind = if largest == f32::MAX { " (a 32-bit float's largest)" } else { "" };
                return Err(Error::invalid(
                    file,
                    key,
                    format!("{x:?} is beyond the range of this field: the largest magnitude allowed is {largest:?}{kind}"),
                ));
            }
            _ => {}
        }
        Ok(())
    }
    match toml::Value::try_from(desc) {
        Ok(parsed) => walk(&toml::Value::Table(table.clone()), &parsed, "", file),
        // The description always serialises; if it did not, the owners' checks still refuse the infinity.
        Err(_) => Ok(()),
    }
}

/// The grid's largest density times the brightest light within
/// [`crate::limits::MAX_DENSITY_TIMES_LIGHT`] (each alone may be within its own bound).
fn check_density_times_light(medium: &Medium, sun: &Sun, sky: &Sky, f: &str) -> Result<()> {
    let densest = f64::from(medium.density.max_value());
    let light = f64::from(sun.irradiance.max_element().max(sky.brightest()));
    let product = densest * light;
    let max = crate::limits::MAX_DENSITY_TIMES_LIGHT;
    check(
        f,
        "medium.grid",
        product <= max,
        densest as f32,
        &format!(
            "the grid's largest density {densest:e} times the brightest light {light:e} (sun.irradiance or the sky's \
             radiance) is {product:e}, above {max:e}: the methods weight light by density in f32, which would overflow; \
             scale the grid's densities down and medium.sigma_t up by the same factor (only their product, the \
             extinction, is physical)"
        ),
    )
}

/// Every array of a scene file holds three numbers (a colour, a position, a direction, a
/// resolution): a longer one is refused, naming its key.
fn check_array_lengths(table: &toml::Table, prefix: &str, file: &str) -> Result<()> {
    for (key, value) in table {
        let name = format!("{prefix}{key}");
        match value {
            toml::Value::Table(t) => check_array_lengths(t, &format!("{name}."), file)?,
            // An array of tables (`[[animation.key]]`) holds any number of them.
            toml::Value::Array(a) if a.iter().all(toml::Value::is_table) => {
                for (i, item) in a.iter().enumerate() {
                    if let toml::Value::Table(t) = item {
                        check_array_lengths(t, &format!("{name}[{i}]."), file)?;
                    }
                }
            }
            toml::Value::Array(a) if a.len() > 3 => {
                return Err(Error::invalid(
                    file,
                    name,
                    format!("has {} items; give exactly 3, e.g. [1.0, 1.0, 1.0]", a.len()),
                ))
            }
            _ => {}
        }
    }
    Ok(())
}

/// Settings of the render itself (from `[render]` after validation): the output's own, and each
/// stage's settings struct, owned and validated by that stage.
#[derive(Clone, Debug)]
pub struct RenderSettings {
    /// The method.
    pub method: Method,
    /// Seed of every random stream.
    pub seed: u64,
    /// `reference`: samples per pixel (≥ 1).
    pub spp: u32,
    /// Deterministic methods: anti-aliasing samples per pixel (≥ 1).
    pub aa_samples: u32,
    /// PNG exposure (stops).
    pub exposure: f32,
    /// The gathers' march step in voxels: a fraction of the smallest voxel edge (`render.step`).
    pub step_voxels: f32,
    /// `reference`: most scattering events per path (None = unlimited).
    pub max_depth: Option<u32>,
    /// `reference`: wall-clock budget in seconds (None = render all spp).
    pub time_limit: Option<f64>,
    /// `reference`: write the standard-error layer.
    pub stderr: bool,
    /// Stage 1 (`render.seed`, `render.sky_single_scattering`).
    pub incident: IncidentSettings,
    /// Stage 2's solver (`render.solver_tolerance`, `render.solver_max_iterations`).
    pub solver: DiffusionSettings,
    /// Viewing cubes and hemicubes (`render.cube_resolution`, `render.ground_samples`).
    pub cubes: CubeOptions,
    /// `full`: the clear-air loop (`render.iterations`, `render.propagation_tolerance`).
    pub clear_air: ClearAirSettings,
    /// `full`: the final gather's edge treatment (`render.low_density_threshold`, `render.step`
    /// in metres, `render.cube_resolution`).
    pub edges: EdgeSettings,
    /// `full`, `transport`: write the method's components as EXR layers (docs/scene.md, "AOVs").
    pub aov: bool,
    /// `diffusion`, `full`: the gather's diffuse source is a·max(0, I0 + g·I1·ω) instead of a·I0
    /// (src/diffusion/flux.rs, docs/diffusion.md).
    pub diffuse_anisotropy: bool,
    /// `diffusion`, `full`: δ-M forward fraction f (unitless, 0 ≤ f < 1) of the medium every
    /// stage sees ([`crate::optics::Optics::delta_m`], with TMS sun single scattering); 0 = off.
    pub forward_fraction: f32,
    /// `transport`: the solver (`render.transport_order`, `render.transport_polar_ordinates`,
    /// `render.transport_tolerance`, `render.transport_max_iterations`,
    /// `render.transport_acceleration`).
    pub transport: TransportSettings,
}

impl Default for RenderSettings {
    /// The render's own defaults; each stage's struct brings its own.
    fn default() -> Self {
        RenderSettings {
            method: Method::Transport,
            seed: 0,
            spp: 1,
            aa_samples: 1,
            exposure: 0.0,
            step_voxels: 0.5,
            max_depth: None,
            time_limit: None,
            stderr: false,
            incident: IncidentSettings::default(),
            solver: DiffusionSettings::default(),
            cubes: CubeOptions::default(),
            clear_air: ClearAirSettings::default(),
            edges: EdgeSettings::default(),
            aov: false,
            diffuse_anisotropy: true,
            forward_fraction: 0.65,
            transport: TransportSettings::default(),
        }
    }
}

/// A validated scene, ready to render: its [`SceneDesc`] and what that loads (the medium, the
/// lights, the camera; crate-private, public with the `internals` feature).
#[derive(Clone, Debug)]
pub struct Scene {
    /// Where it came from (file path or [`BUILTIN`]), for messages.
    pub source: String,
    /// The description it was built from.
    pub desc: SceneDesc,
    /// The medium, loaded.
    #[cfg(feature = "internals")]
    pub medium: Medium,
    #[cfg(not(feature = "internals"))]
    pub(crate) medium: Medium,
    /// The sun.
    #[cfg(feature = "internals")]
    pub sun: Sun,
    #[cfg(not(feature = "internals"))]
    pub(crate) sun: Sun,
    /// The sky.
    #[cfg(feature = "internals")]
    pub sky: Sky,
    #[cfg(not(feature = "internals"))]
    pub(crate) sky: Sky,
    /// The ground, if any.
    #[cfg(feature = "internals")]
    pub ground: Option<Ground>,
    #[cfg(not(feature = "internals"))]
    pub(crate) ground: Option<Ground>,
    /// The camera.
    #[cfg(feature = "internals")]
    pub camera: Camera,
    #[cfg(not(feature = "internals"))]
    pub(crate) camera: Camera,
    /// Render settings.
    #[cfg(feature = "internals")]
    pub render: RenderSettings,
    #[cfg(not(feature = "internals"))]
    pub(crate) render: RenderSettings,
    /// What reading the inputs found that the user should be told ([`Scene::notes`]).
    pub(crate) notes: Vec<String>,
}

impl Scene {
    /// Validate a description and load what it refers to. `source` names it in messages;
    /// relative grid paths resolve against `base_dir`.
    pub fn build(desc: SceneDesc, source: &str, base_dir: &Path) -> Result<Scene> {
        Scene::build_with(desc, source, base_dir, None)
    }

    /// [`Scene::build`] with the density grid given in memory instead of `medium.grid`'s.
    pub fn build_with(desc: SceneDesc, source: &str, base_dir: &Path, density: Option<crate::Density>) -> Result<Scene> {
        let f = source;
        let r = &desc.render;
        check(f, "render.spp", r.spp >= 1, r.spp, "samples per pixel must be at least 1")?;
        check(
            f,
            "render.stderr",
            !(r.stderr && r.method == Method::Reference && r.spp < 2),
            r.stderr,
            &format!(
                "the standard error needs at least 2 samples per pixel, and render.spp is {}; raise render.spp \
                 (--spp 2 or more) or leave render.stderr (--stderr) out",
                r.spp
            ),
        )?;
        check(
            f,
            "render.aa_samples",
            (1..=1024).contains(&r.aa_samples),
            r.aa_samples,
            "anti-aliasing samples per pixel must be 1 to 1024",
        )?;
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
            (MIN_STEP_VOXELS..=4.0).contains(&r.step),
            r.step,
            "the march step is a fraction of a voxel in [0.01, 4]; the march's time grows as 1/step \
             (1e-30 would never end)",
        )?;
        if let Some(t) = r.time_limit {
            check(
                f,
                "render.time_limit",
                t.is_finite() && t > 0.0 && t <= crate::limits::MAX_SECONDS,
                t,
                "the time limit is a positive number of seconds, at most 1e9 (about 32 years)",
            )?;
        }
        check(
            f,
            "render.forward_fraction",
            (0.0..1.0).contains(&r.forward_fraction),
            r.forward_fraction,
            "the δ-M forward fraction is in [0, 1), e.g. 0.43 (g⁸ for g = 0.9); 0 turns it off",
        )?;
        check_magnitudes(&desc, f)?;
        // Each stage's settings from its keys, validated by the stage that owns them.
        let mut render = RenderSettings::default();
        r.apply(&mut render);
        render.incident.seed = render.seed;
        render.edges.cube_res = render.cubes.res;
        render.cubes.validate(f)?;
        render.edges.validate(f)?;
        render.clear_air.validate(f)?;
        render.solver.validate(f)?;
        render.transport.validate(f)?;
        let camera = Camera::from_desc(&desc.camera, f)?;
        let (sun, sky) = crate::lighting::sun_and_sky(&desc.sun, &desc.sky, f, base_dir)?;
        let ground = match &desc.ground {
            Some(g) if g.enabled => Some(Ground::from_desc(g, f)?),
            Some(_) => None,
            None => None,
        };
        let sun = crate::lighting::sun_over_ground(sun, ground.as_ref());
        let (medium, notes) = Medium::from_desc_with(&desc.medium, f, base_dir, density.map(crate::Density::into_loaded))?;
        check_density_times_light(&medium, &sun, &sky, f)?;
        // The ground is opaque: density under it is neither lit nor seen (every method alike).
        let medium = match &ground {
            Some(g) => medium.emptied_below(g.height).unwrap_or(medium),
            None => medium,
        };
        // camera.fit: the camera moved to frame the cloud's box (src/camera/fit.rs). A medium with
        // no density (an empty frame of a simulation) has no box to frame: the camera stays where
        // the scene puts it, looking the same way as a framed one (camera.fit keeps the direction),
        // and the sky and a cloud-less ground look the same from any point above the ground.
        let (desc, camera) = match desc.camera.fit && medium.active_box(0).is_some() {
            true => {
                let (lo, hi) = medium.cloud_box();
                let mut desc = desc;
                desc.camera = crate::camera::fit::framed(&desc.camera, lo, hi);
                let camera = Camera::from_desc(&desc.camera, f)?;
                (desc, camera)
            }
            false => (desc, camera),
        };
        render.edges.step_m = render.step_voxels * medium.min_voxel();
        Ok(Scene {
            source: source.to_string(),
            desc,
            medium,
            sun,
            sky,
            ground,
            camera,
            render,
            notes,
        })
    }

    /// The built-in default scene.
    pub(crate) fn default_scene() -> Result<Scene> {
        Scene::build(SceneDesc::default(), BUILTIN, Path::new("."))
    }

    /// Load a scene file (None: the built-in default scene), applying `edit` to the description first.
    pub(crate) fn load(path: Option<&Path>, edit: impl FnOnce(&mut SceneDesc)) -> Result<Scene> {
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
    pub(crate) fn background(&self, origin: Vec3, dir: Vec3, sun_visibility: impl Fn(Vec3) -> f32) -> Rgb {
        if let Some(g) = &self.ground {
            if let Some(t) = g.intersect(origin, dir) {
                let p = origin + dir * t;
                return g.radiance(p, &self.sun, &self.sky, sun_visibility(p));
            }
        }
        self.sky.radiance(dir)
    }
}

/// The `[animation]` table's description (src/sequence/animation.rs interpolates it).
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct AnimationDesc {
    /// The scene's frames (`1-240`, `1-240x2`, `1,5,9-12`); `--frames` overrides it.
    #[serde(default)]
    pub frames: Option<String>,
    /// The keyframes (`[[animation.key]]`), in any order.
    #[serde(default)]
    pub key: Vec<KeyDesc>,
}

/// One keyframe: its frame and the channels it sets.
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct KeyDesc {
    /// The frame number.
    pub frame: u32,
    /// `sun.elevation_deg`, `sun.azimuth_deg` (degrees), `sun.irradiance` (W/m² per band).
    #[serde(default)]
    pub sun: SunKey,
    /// `camera.position`, `camera.look_at` (m), `camera.fov_deg` (degrees, vertical).
    #[serde(default)]
    pub camera: CameraKey,
    /// `medium.sigma_t` (m⁻¹ at density 1).
    #[serde(default)]
    pub medium: MediumKey,
}

/// The sun's keyable values.
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SunKey {
    /// Degrees above the horizon.
    pub elevation_deg: Option<f32>,
    /// Degrees from +x towards +z (interpolated as numbers: 350 → 10 turns the long way round).
    pub azimuth_deg: Option<f32>,
    /// W/m² per band.
    pub irradiance: Option<[f32; 3]>,
}

/// The camera's keyable values.
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CameraKey {
    /// Eye position (m).
    pub position: Option<[f32; 3]>,
    /// Point looked at (m).
    pub look_at: Option<[f32; 3]>,
    /// Vertical field of view (degrees).
    pub fov_deg: Option<f32>,
}

/// The medium's keyable values.
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MediumKey {
    /// Extinction at density 1 (m⁻¹).
    pub sigma_t: Option<f32>,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The message of the scene file `text`, which must be refused.
    fn refusal(text: &str) -> String {
        SceneDesc::from_toml(text, "s.toml").unwrap_err().to_string()
    }

    #[test]
    fn a_number_past_f32_names_its_field_its_value_and_the_largest_allowed_whatever_the_field() {
        let f32_max = "the largest magnitude allowed is 3.4028235e38 (a 32-bit float's largest)";
        for (text, message) in [
            ("[medium]\nvoxel_size = 1e39", format!("field `medium.voxel_size`: 1e39 is beyond the range of this field: {f32_max}")),
            ("[medium]\nvoxel_size = [1.0, -2e39, 1.0]", format!("field `medium.voxel_size`: -2e39 is beyond the range of this field: {f32_max}")),
            ("[medium]\ng = -1e39", format!("field `medium.g`: -1e39 is beyond the range of this field: {f32_max}")),
            ("[camera]\nfov_deg = 1e300", format!("field `camera.fov_deg`: 1e300 is beyond the range of this field: {f32_max}")),
            // Fields with a bound of their own name it.
            ("[medium]\norigin = [0.0, 1e39, 0.0]", "field `medium.origin`: 1e39 is beyond the range of this field: the largest magnitude allowed is 10000000.0".into()),
            ("[sun]\nirradiance = [1e40, 1.0, 1.0]", "field `sun.irradiance`: 1e40 is beyond the range of this field: the largest magnitude allowed is 1e30".into()),
            ("[sky]\nradiance = [1.0, 1.0, 3.5e38]", "field `sky.radiance`: 3.5e38 is beyond the range of this field: the largest magnitude allowed is 1e30".into()),
            // A keyframe of a sequence is named by its index.
            (
                "[[animation.key]]\nframe = 1\nsun.irradiance = [1.0, 1e39, 1.0]",
                format!("field `animation.key[0].sun.irradiance`: 1e39 is beyond the range of this field: {f32_max}"),
            ),
        ] {
            assert!(refusal(text).ends_with(&message), "{text}: {}", refusal(text));
        }
        // An f64 field holds 1e39: its own check (at build) refuses it, naming its range.
        assert!(SceneDesc::from_toml("[render]\nsolver_tolerance = 1e39", "s.toml").is_ok());
        // Within f32's range, a number is not this check's to refuse.
        assert!(SceneDesc::from_toml("[camera]\nfov_deg = 3.4e38", "s.toml").is_ok());
    }
}
