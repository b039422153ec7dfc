//! The library's front door: a [`Scene`] from a file, a TOML string or a [`SceneDesc`] built in
//! code, an optional in-memory [`Density`], and [`render`] with [`Options`] (progress,
//! cancellation) giving a [`Render`]. The command line and the Python package both use it.

use crate::error::{Error, Result};
use crate::image::Image;
use crate::math::{Rgb, Vec3};
use crate::medium::loaders::Loaded;
use crate::medium::{Grid3, VoxelSize};
use crate::pipeline::{NoProgress, Progress, Timings};
use crate::scene::{Method, Scene, SceneDesc};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// Name of a scene given as TOML text, in messages.
pub const TOML_SOURCE: &str = "TOML string";

/// Name of an in-memory density grid, in messages.
pub const DENSITY_SOURCE: &str = "in-memory density";

impl Scene {
    /// Read, validate and load a scene file; relative paths in it resolve against its folder.
    ///
    /// ```
    /// let dir = tempfile::tempdir().unwrap();
    /// let path = dir.path().join("tiny.toml");
    /// std::fs::write(&path, "[camera]\nwidth = 8\nheight = 6\n").unwrap();
    /// let scene = cloudgi::Scene::from_file(&path).unwrap();
    /// assert_eq!(scene.desc.camera.width, 8);
    /// ```
    pub fn from_file(path: impl AsRef<Path>) -> Result<Scene> {
        Scene::load(Some(path.as_ref()), |_| {})
    }

    /// Parse and validate a scene given as TOML text (named [`TOML_SOURCE`] in messages);
    /// relative paths resolve against the current folder. Missing keys take the default scene's.
    ///
    /// ```
    /// let scene = cloudgi::Scene::from_toml("[render]\nmethod = \"single\"").unwrap();
    /// assert_eq!(scene.desc.render.method, cloudgi::Method::Single);
    /// let err = cloudgi::Scene::from_toml("[camera]\nwdith = 8").unwrap_err();
    /// assert!(err.to_string().contains("unknown field `wdith`"));
    /// ```
    pub fn from_toml(text: &str) -> Result<Scene> {
        Scene::build(SceneDesc::from_toml(text, TOML_SOURCE)?, TOML_SOURCE, Path::new("."))
    }

    /// Validate a description built in code (named "built-in scene" in messages); relative
    /// paths resolve against the current folder.
    ///
    /// ```
    /// let mut desc = cloudgi::SceneDesc::default();
    /// desc.camera.width = 8;
    /// desc.camera.height = 6;
    /// let scene = cloudgi::Scene::from_desc(desc).unwrap();
    /// assert_eq!(scene.desc.camera.height, 6);
    /// ```
    pub fn from_desc(desc: SceneDesc) -> Result<Scene> {
        Scene::build(desc, crate::scene::BUILTIN, Path::new("."))
    }

    /// What reading the scene's inputs found that the user should be told, e.g. a `.vdb` grid
    /// with no active voxels (the scene renders without a cloud) or the grid read from a file
    /// without a `density` grid. `cloudgi render` prints them as warnings; Python issues them as
    /// `RuntimeWarning`s.
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// Resolution `[nx, ny, nz]` of the density grid as loaded (after `medium.downsample` or
    /// `medium.refine`).
    ///
    /// ```
    /// let scene = cloudgi::Scene::from_toml("[medium]\nresolution = [10, 8, 6]").unwrap();
    /// assert_eq!(scene.grid_dims(), [10, 8, 6]);
    /// ```
    pub fn grid_dims(&self) -> [usize; 3] {
        self.medium.dims()
    }
}

impl Image {
    /// The exposure (stops) the command line gives a PNG preview when neither `--exposure` nor
    /// `render.exposure` sets one: −log2 L, L the 99th percentile of the finite luminances (it maps
    /// to 1, which the filmic curve takes to 0.80);
    /// 0 for an image without a positive one. Use it with [`Image::to_png_bytes`].
    ///
    /// ```
    /// let mut img = cloudgi::Image::new(2, 1);
    /// img.pixels.fill(cloudgi::Rgb::splat(3.2));
    /// assert!((img.auto_exposure() + 3.2f32.log2()).abs() < 1e-5);
    /// ```
    pub fn auto_exposure(&self) -> f32 {
        crate::exposure::auto_stops(self)
    }
}

/// Check, before any work, that `path` can be written as an output file, as the command line
/// checks its outputs: a file name (not empty, not ending in a separator, within the file
/// systems' 255 bytes), not a folder, in an existing folder this process can create files in.
/// `source` and `field` name where the path came from, in the message ([`Error::Invalid`]).
///
/// ```
/// let e = cloudgi::check_output_file(".", "my tool", "--out").unwrap_err();
/// assert_eq!(e.to_string(), "my tool: field `--out`: `.` is a folder; the output must be a file name");
/// ```
pub fn check_output_file(path: impl AsRef<Path>, source: &str, field: &str) -> Result<()> {
    crate::io::check_output_file(path.as_ref(), source, field)
}

/// A density grid in memory: it replaces `medium.grid` (see [`Scene::build_with`]); the scene's
/// `medium.downsample`, `medium.refine`, `max_voxels` and optical properties still apply.
#[derive(Clone, Debug)]
pub struct Density {
    grid: Grid3,
    voxel_size: [f32; 3],
    origin: [f32; 3],
    notes: Vec<String>,
}

impl Density {
    /// `values` indexed `[z][y][x]` (x fastest, the order of a C-ordered `.npy` file) for a grid
    /// of `dims = [nx, ny, nz]` voxels of `voxel_size` metres (one edge, or `[x, y, z]`), its
    /// minimum corner at `origin` (m). Sizes are checked here; values (finite, ≥ 0), voxel size and origin when the scene
    /// is built.
    ///
    /// ```
    /// use cloudgi::{Density, Scene, SceneDesc};
    /// let mut desc = SceneDesc::default();
    /// desc.camera.width = 8;
    /// desc.camera.height = 6;
    /// let density = Density::new([4, 3, 2], vec![0.5; 24], 100.0, [-200.0, 0.0, -100.0]).unwrap();
    /// let scene = Scene::build_with(desc, "example", ".".as_ref(), Some(density)).unwrap();
    /// assert_eq!(scene.grid_dims(), [4, 3, 2]);
    /// assert!(Density::new([4, 3, 2], vec![0.5; 23], 100.0, [0.0; 3]).is_err());
    /// // Cells that are not cubes: 100 m wide, 25 m tall.
    /// let layers = Density::new([4, 3, 2], vec![0.5; 24], [100.0, 25.0, 100.0], [0.0; 3]).unwrap();
    /// assert_eq!(layers.voxel_size(), [100.0, 25.0, 100.0]);
    /// ```
    pub fn new(dims: [usize; 3], values: Vec<f32>, voxel_size: impl Into<VoxelSize>, origin: [f32; 3]) -> Result<Density> {
        Ok(Density {
            grid: Grid3::from_vec(dims, values, DENSITY_SOURCE)?,
            voxel_size: voxel_size.into().to_vec3().to_array(),
            origin,
            notes: Vec::new(),
        })
    }

    /// Refuse, from its shape alone, a density a caller is about to copy that would not fit in
    /// this machine's available memory: `shape` (any number of dimensions) holds values of which
    /// the caller's copies take `caller_bytes_per_value` bytes each, and the grid 4 more (f32).
    /// A virtual array (numpy's `broadcast_to`) is then refused before it is materialised.
    ///
    /// ```
    /// assert!(cloudgi::Density::check_fits(&[4, 3, 2], 8).is_ok());
    /// // Linux tells the available memory (elsewhere nothing is refused).
    /// # #[cfg(target_os = "linux")]
    /// # {
    /// let err = cloudgi::Density::check_fits(&[1 << 30, 1 << 30, 1 << 30], 4).unwrap_err();
    /// assert!(err.to_string().contains("field `density`: 1073741824×1073741824×1073741824 values need about"));
    /// # }
    /// ```
    pub fn check_fits(shape: &[u64], caller_bytes_per_value: u64) -> Result<()> {
        let values = shape.iter().fold(1u128, |n, &d| n.saturating_mul(d as u128));
        let dims = shape.iter().map(u64::to_string).collect::<Vec<_>>().join("×");
        crate::io::check_memory(
            DENSITY_SOURCE,
            "density",
            &format!("{dims} values need"),
            values.saturating_mul(caller_bytes_per_value as u128 + 4),
            "downsample the array (e.g. density[::2, ::2, ::2])",
        )
    }

    /// A density from the bytes of a `.npy` file (float32 or float64, C order, shape
    /// `(nz, ny, nx)`), checked like a `.npy` grid file named [`DENSITY_SOURCE`].
    ///
    /// ```
    /// let mut npy = b"\x93NUMPY\x01\x00".to_vec();
    /// let header = "{'descr': '<f4', 'fortran_order': False, 'shape': (1, 1, 2), }";
    /// npy.extend((header.len() as u16).to_le_bytes());
    /// npy.extend(header.as_bytes());
    /// npy.extend([0.5f32, 1.0].iter().flat_map(|v| v.to_le_bytes()));
    /// let d = cloudgi::Density::from_npy(&npy, 10.0, [0.0; 3]).unwrap();
    /// assert_eq!(d.dims(), [2, 1, 1]);
    /// ```
    pub fn from_npy(bytes: &[u8], voxel_size: impl Into<VoxelSize>, origin: [f32; 3]) -> Result<Density> {
        Ok(Density {
            grid: crate::medium::loaders::parse_npy(bytes, DENSITY_SOURCE)?,
            voxel_size: voxel_size.into().to_vec3().to_array(),
            origin,
            notes: Vec::new(),
        })
    }

    /// Read grid `grid_name` of a grid file as a scene's `medium.grid` would be read (`.vdb`
    /// placed by its own transform; `.npy`, `.raw`, `.vol` as their formats say), without
    /// `medium.downsample` or `medium.refine`. `path` is a file (relative: to the current folder),
    /// never the scene's `procedural`.
    ///
    /// ```
    /// let dir = tempfile::tempdir().unwrap();
    /// let path = dir.path().join("missing.vdb");
    /// let err = cloudgi::Density::load(&path, "density").unwrap_err();
    /// assert!(matches!(err, cloudgi::Error::Io { .. }) && err.to_string().contains("missing.vdb"));
    /// let err = cloudgi::Density::load(dir.path(), "density").unwrap_err();
    /// assert!(err.to_string().contains("not a regular file"));
    /// ```
    pub fn load(path: impl AsRef<Path>, grid_name: &str) -> Result<Density> {
        let path = path.as_ref();
        // The scene's messages would name `medium.grid`, paths relative to a scene file, and
        // take `procedural` for the built-in cloud: none of which a caller with a path meant.
        if !std::fs::metadata(path).map_err(|e| Error::io(path, e))?.is_file() {
            return Err(Error::format(
                path.display().to_string(),
                "not a regular file (a folder, device or pipe); give the path of a grid file (.vdb, .npy, .raw or .vol)",
            ));
        }
        let desc = crate::medium::MediumDesc {
            grid: path.display().to_string(),
            grid_name: grid_name.to_string(),
            ..Default::default()
        };
        let loaded = crate::medium::loaders::load(&desc, &desc.grid, Path::new("."))?;
        Ok(Density {
            grid: loaded.grid,
            voxel_size: loaded.voxel_size.to_array(),
            origin: loaded.origin.to_array(),
            notes: loaded.notes,
        })
    }

    /// What reading the file found that the user should be told: a `.vdb` grid with no active
    /// voxels (read as one voxel of density 0 at the grid's index origin, a scene without a cloud)
    /// or the grid read from a file without a `density` grid ([`Scene::notes`] carries them on).
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// The values, `[z][y][x]` (x fastest).
    pub fn values(&self) -> &[f32] {
        self.grid.data()
    }

    /// Voxel edge lengths (m) along x, y, z.
    pub fn voxel_size(&self) -> [f32; 3] {
        self.voxel_size
    }

    /// Minimum corner (m).
    pub fn origin(&self) -> [f32; 3] {
        self.origin
    }

    /// Resolution `[nx, ny, nz]`.
    pub fn dims(&self) -> [usize; 3] {
        self.grid.dims()
    }

    /// The grid as the medium's loader gives it.
    pub(crate) fn into_loaded(self) -> Loaded {
        Loaded {
            grid: self.grid,
            origin: Vec3::from(self.origin),
            voxel_size: Vec3::from(self.voxel_size),
            name: DENSITY_SOURCE.to_string(),
            downsampled: false,
            notes: self.notes,
        }
    }
}

/// How [`render`] reports and stops: both optional.
#[derive(Clone, Copy, Default)]
pub struct Options<'a> {
    /// Receives stage begins, progress, log lines and warnings (e.g. [`FnProgress`] around a
    /// closure); none: silent.
    pub progress: Option<&'a dyn Progress>,
    /// Set it (from any thread) to stop the render: it is polled between stages, rows, passes
    /// and solver iterations, and the render then returns [`Error::Cancelled`].
    pub cancel: Option<&'a AtomicBool>,
}

/// A finished render.
#[derive(Clone, Debug)]
pub struct Render {
    /// The radiance image (linear HDR, W·m⁻²·sr⁻¹ per band, row 0 at the top), without layers.
    pub image: Image,
    /// The method's extra layers (`render.aov`, `render.stderr`), by name, in the image's size.
    pub aovs: Vec<(String, Vec<Rgb>)>,
    /// What the render did and how long it took.
    pub stats: Stats,
}

impl Render {
    /// One image with the AOVs as its layers: what the command line writes to EXR.
    ///
    /// ```
    /// let scene = cloudgi::Scene::from_toml("[camera]\nwidth = 4\nheight = 3\n[medium]\nresolution = [8, 6, 4]").unwrap();
    /// let out = cloudgi::render(&scene, cloudgi::Method::Single, &Default::default()).unwrap();
    /// assert_eq!(out.into_image().pixels.len(), 12);
    /// ```
    pub fn into_image(self) -> Image {
        let mut image = self.image;
        image.layers = self.aovs;
        image
    }
}

/// What a render did.
#[derive(Clone, Debug)]
pub struct Stats {
    /// The method used.
    pub method: Method,
    /// Wall-clock seconds of each stage.
    pub timings: Timings,
    /// Wall-clock seconds of the whole render.
    pub seconds: f64,
}

/// Render `scene` with `method` (instead of its `render.method`). Before any work it refuses
/// ([`Error::Invalid`]), as the command line does, an image or a solver too large for this
/// machine's available memory and a cloud wider than the diffusion solver takes, which would
/// otherwise abort or panic midway.
///
/// ```
/// use cloudgi::{render, Method, Options, Scene};
/// let scene = Scene::from_toml("[camera]\nwidth = 8\nheight = 6\n[medium]\nresolution = [10, 8, 6]").unwrap();
/// let out = render(&scene, Method::Transport, &Options::default()).unwrap();
/// assert_eq!((out.image.width, out.image.height), (8, 6));
/// assert!(out.image.pixels.iter().all(|p| p.is_finite() && p.min_element() >= 0.0));
/// println!("{}", out.stats.timings.summary());
/// ```
pub fn render(scene: &Scene, method: Method, options: &Options) -> Result<Render> {
    let start = Instant::now();
    let cancelled = || options.cancel.is_some_and(|c| c.load(Ordering::Relaxed));
    if cancelled() {
        return Err(Error::Cancelled);
    }
    let progress = Watched {
        inner: options.progress.unwrap_or(&NoProgress),
        cancel: options.cancel,
    };
    let chosen;
    let scene = if scene.render.method == method {
        scene
    } else {
        let mut s = scene.clone();
        s.render.method = method;
        chosen = s;
        &chosen
    };
    crate::cli::memory::check_scene(scene)?;
    let out = crate::render::render(scene, &progress)?;
    if cancelled() {
        return Err(Error::Cancelled);
    }
    let mut image = out.image;
    let aovs = std::mem::take(&mut image.layers);
    Ok(Render {
        image,
        aovs,
        stats: Stats {
            method,
            timings: out.timings,
            seconds: start.elapsed().as_secs_f64(),
        },
    })
}

/// The warnings about `scene` itself that the command line prints before it renders: a sun
/// under the ground, a grid of zeros, a cloud of an odd size, voxels too thick for the fast
/// methods, a low albedo, a back-scattering phase function, a sun in the sky map or a clipped one
/// (docs/sky.md), a cloud the camera does not see. (Warnings about keys that do not apply are [`ignored_settings`], and
/// the grid's notes are in [`Scene::notes`].) The Python package issues them as `RuntimeWarning`s.
pub fn scene_warnings(scene: &Scene) -> Vec<String> {
    crate::cli::warnings::scene_warnings(scene)
}

/// The command line's warnings for keys given that do not apply to `scene`'s grid, sun, sky,
/// ground or method, so would be ignored (`render.spp` with a deterministic method, `sky.path`
/// with a constant sky). `given_by("table.key")` names who set the key (it starts the warning:
/// `"scene.toml: `render.spp`"`), None where nobody did: a default never warns. `array`: the
/// density came as a [`Density`], which replaces `medium.grid`. The Python package issues them
/// as `RuntimeWarning`s.
pub fn ignored_settings(scene: &Scene, array: bool, given_by: &dyn Fn(&str) -> Option<String>) -> Vec<String> {
    crate::cli::warnings::ignored_settings(scene, array, given_by)
}

/// The caller's progress sink with the cancel flag as its [`Progress::cancelled`].
struct Watched<'a> {
    inner: &'a dyn Progress,
    cancel: Option<&'a AtomicBool>,
}

impl Progress for Watched<'_> {
    fn begin(&self, stage: &str, total: u64) {
        self.inner.begin(stage, total)
    }
    fn advance(&self, n: u64) {
        self.inner.advance(n)
    }
    fn end(&self) {
        self.inner.end()
    }
    fn log(&self, msg: &str) {
        self.inner.log(msg)
    }
    fn converge(&self, change: f64, tolerance: f64) {
        self.inner.converge(change, tolerance)
    }
    fn wants_images(&self) -> bool {
        self.inner.wants_images()
    }
    fn image(&self, img: &crate::image::Image) {
        self.inner.image(img)
    }
    fn warn(&self, msg: &str) {
        self.inner.warn(msg)
    }
    fn cancelled(&self) -> bool {
        self.cancel.is_some_and(|c| c.load(Ordering::Relaxed)) || self.inner.cancelled()
    }
}

/// One thing a render reports to an [`FnProgress`] closure.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Event<'a> {
    /// Stage `stage` has done `done` of `total` units of work (`done == 0`: it begins;
    /// `done == total`: it ended).
    Stage {
        /// The stage, e.g. `transport iterations`.
        stage: &'a str,
        /// Units done.
        done: u64,
        /// Units in all.
        total: u64,
    },
    /// A line of information (e.g. solver convergence).
    Log(&'a str),
    /// A warning the user must see (e.g. a solver stopped at its iteration cap).
    Warning(&'a str),
}

/// A [`Progress`] that calls a closure with each [`Event`]; the closure is called from the
/// render's worker threads, one call at a time.
///
/// ```
/// use cloudgi::{render, Event, FnProgress, Method, Options, Scene};
/// use std::sync::atomic::{AtomicU64, Ordering};
/// let scene = Scene::from_toml("[camera]\nwidth = 4\nheight = 3\n[medium]\nresolution = [8, 6, 4]").unwrap();
/// let rows = AtomicU64::new(0);
/// let progress = FnProgress::new(|e| {
///     if let Event::Stage { stage: "single scattering", done, .. } = e {
///         rows.fetch_max(done, Ordering::Relaxed);
///     }
/// });
/// render(&scene, Method::Single, &Options { progress: Some(&progress), ..Default::default() }).unwrap();
/// assert_eq!(rows.load(Ordering::Relaxed), 3);
/// ```
pub struct FnProgress<F> {
    f: F,
    state: std::sync::Mutex<(String, u64, u64)>,
}

impl<F: Fn(Event) + Sync> FnProgress<F> {
    /// Wrap `f`.
    pub fn new(f: F) -> Self {
        FnProgress {
            f,
            state: std::sync::Mutex::new((String::new(), 0, 0)),
        }
    }

    fn update(&self, change: impl FnOnce(&mut (String, u64, u64))) {
        if let Ok(mut s) = self.state.lock() {
            change(&mut s);
            (self.f)(Event::Stage {
                stage: &s.0,
                done: s.1,
                total: s.2,
            });
        }
    }
}

impl<F: Fn(Event) + Sync> Progress for FnProgress<F> {
    fn begin(&self, stage: &str, total: u64) {
        self.update(|s| *s = (stage.to_string(), 0, total));
    }
    fn advance(&self, n: u64) {
        self.update(|s| s.1 = (s.1 + n).min(s.2));
    }
    fn end(&self) {
        self.update(|s| s.1 = s.2);
    }
    fn log(&self, msg: &str) {
        (self.f)(Event::Log(msg))
    }
    fn warn(&self, msg: &str) {
        (self.f)(Event::Warning(msg))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tiny() -> Scene {
        Scene::from_toml("[camera]\nwidth = 6\nheight = 4\n[medium]\nresolution = [10, 8, 6]").unwrap()
    }

    #[test]
    fn a_set_flag_cancels_every_method() {
        let flag = AtomicBool::new(true);
        let opts = Options {
            cancel: Some(&flag),
            ..Default::default()
        };
        for m in [Method::Single, Method::Transport, Method::Reference] {
            assert!(matches!(render(&tiny(), m, &opts), Err(Error::Cancelled)));
        }
    }

    #[test]
    fn a_flag_set_during_the_render_cancels_it() {
        let flag = AtomicBool::new(false);
        let progress = FnProgress::new(|e| {
            if matches!(e, Event::Stage { done: 1, .. }) {
                flag.store(true, Ordering::Relaxed);
            }
        });
        let opts = Options {
            progress: Some(&progress),
            cancel: Some(&flag),
        };
        assert!(matches!(render(&tiny(), Method::Transport, &opts), Err(Error::Cancelled)));
    }

    #[test]
    fn the_method_argument_wins_and_output_matches_the_plain_dispatch() {
        let s = tiny();
        let api = render(&s, Method::Transport, &Options::default()).unwrap();
        let plain = crate::render::render(&s, &NoProgress).unwrap();
        assert_eq!(api.into_image(), plain.image);
        assert_eq!(
            render(&s, Method::Single, &Options::default()).unwrap().stats.method,
            Method::Single
        );
    }

    #[test]
    fn a_cloud_wider_than_the_diffusion_solver_takes_is_an_error_not_a_panic() {
        // Two rows of 131 071 voxels: the solver's u16 row distances overflowed and it panicked.
        let n = crate::diffusion::MAX_BOX_ROW_CELLS + 1;
        let d = Density::new([n, 2, 1], vec![1.0; 2 * n], 0.01, [0.0; 3]).unwrap();
        let scene = Scene::build_with(tiny().desc, "x", Path::new("."), Some(d)).unwrap();
        let e = render(&scene, Method::Diffusion, &Options::default()).unwrap_err().to_string();
        assert!(e.contains("diffusion solver takes at most 131070"), "{e}");
    }

    #[test]
    fn an_in_memory_density_is_checked_like_a_file() {
        let mut v = vec![0.5; 24];
        v[5] = f32::NAN;
        let d = Density::new([4, 3, 2], v, 10.0, [0.0; 3]).unwrap();
        let e = Scene::build_with(SceneDesc::default(), "x", Path::new("."), Some(d)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "in-memory density: density at voxel (x, y, z) = (1, 1, 0), array index [0, 1, 1], is NaN: \
             densities must be finite and non-negative"
        );
    }
}
