//! The `cloudgi` command line: argument parsing, progress bars, files and the subcommands. The
//! binary (`src/main.rs`) only calls [`main`]; all rendering is the library's.

/// `eprintln!` that never panics (see [`console::note`]).
macro_rules! note {
    ($($t:tt)*) => {
        $crate::cli::console::note(format_args!($($t)*))
    };
}

mod allocator;
mod back_scattering;
mod bench;
mod cloud_size;
mod compare;
mod console;
mod display;
mod export;
mod figures;
mod frames;
mod grid_scene;
mod info;
mod low_albedo;
mod map_sun;
pub(crate) mod memory;
mod output;
mod progress;
mod scene_file;
mod sky;
mod slab;
mod thick_voxels;
mod tonemap;
pub(crate) mod warnings;

use crate::error::{Error, Result};
use crate::scene::{Method, Scene};
use clap::{Args, Parser, Subcommand};
use scene_file::SceneFile;
use std::path::{Path, PathBuf};

/// `--method`: clap's view of [`Method`] (clap stays in the CLI).
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
enum MethodArg {
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

impl From<MethodArg> for Method {
    fn from(m: MethodArg) -> Method {
        match m {
            MethodArg::Single => Method::Single,
            MethodArg::Reference => Method::Reference,
            MethodArg::Diffusion => Method::Diffusion,
            MethodArg::Full => Method::Full,
            MethodArg::Transport => Method::Transport,
        }
    }
}

/// Physically based cloud renderer (Max et al. 2004: diffusion and multiple anisotropic scattering).
#[derive(Parser, Debug)]
#[command(name = "cloudgi", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Worker threads (default: all cores). Every output is identical for any count.
    #[arg(long, global = true)]
    threads: Option<usize>,
    /// No progress bars or summaries.
    #[arg(long, short, global = true)]
    quiet: bool,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Render a scene (default: the built-in cloud) to OUT.exr plus a tone-mapped OUT.png.
    Render(RenderArgs),
    /// Reflectance and transmittance of a plane-parallel slab (Monte Carlo, diffusion or discrete ordinates), one JSON line.
    Slab(slab::SlabArgs),
    /// Compare TEST.exr against REF.exr over the cloud pixels: one JSON line, optional difference PNG.
    Compare(compare::CompareArgs),
    /// Describe the grids of an OpenVDB file: types, active voxels, bounding boxes, transforms, dense memory.
    Info(info::InfoArgs),
    /// Export the scene's sky as an equirectangular EXR (row 0 = +y) plus a PNG preview.
    Sky(sky::SkyArgs),
    /// Export the scene for another renderer (Mitsuba 3) to cross-check the reference.
    Export(export::ExportArgs),
    /// Render the paper's figure series (Figs. 4–8) and the reference, with errors, into a folder with index.md.
    Figures(figures::FiguresArgs),
    /// Time every stage of the chosen methods on sizes of the procedural cloud (--sizes) and on scene files (--clouds): a markdown table.
    Bench(bench::BenchArgs),
    /// Re-make a render's PNG preview from its EXR (the same automatic exposure, or --exposure).
    Tonemap(tonemap::TonemapArgs),
}

#[derive(Args, Debug)]
struct RenderArgs {
    /// Scene file (TOML), or a grid file (.vdb, .npy, .vol, .raw) to render framed under the
    /// default sun and sky. Without it, the built-in default scene.
    scene: Option<PathBuf>,
    /// Output EXR or PNG; both are written: OUT.exr and its preview OUT.png.
    #[arg(short, long, default_value = "cloud.exr")]
    output: PathBuf,
    /// PNG exposure in stops (default: render.exposure if the scene file sets it, else automatic;
    /// docs/first_use.md). The EXR is never scaled.
    #[arg(long, allow_hyphen_values = true)]
    exposure: Option<f32>,
    /// Stream the image to the tev HDR viewer at HOST:PORT while rendering (reference: every
    /// pass; every method: the final image). No viewer there: a warning, the render goes on.
    #[arg(long, value_name = "HOST:PORT")]
    display_server: Option<String>,
    /// Override render.method (default: transport).
    #[arg(long, value_enum)]
    method: Option<MethodArg>,
    /// Override camera.width (pixels).
    #[arg(long)]
    width: Option<u32>,
    /// Override camera.height (pixels).
    #[arg(long)]
    height: Option<u32>,
    /// Override render.spp (reference: paths per pixel).
    #[arg(long)]
    spp: Option<u32>,
    /// Override render.aa_samples (single, diffusion, full, transport: anti-aliasing samples per pixel).
    #[arg(long)]
    aa_samples: Option<u32>,
    /// Override render.seed.
    #[arg(long)]
    seed: Option<u64>,
    /// Override render.max_depth (reference: most scattering events per path).
    #[arg(long)]
    max_depth: Option<u32>,
    /// Override render.time_limit (reference: seconds; checked inside a pass and a path).
    #[arg(long)]
    time_limit: Option<f64>,
    /// Set render.stderr (reference: write the per-pixel standard error as EXR layer `stderr`).
    #[arg(long)]
    stderr: bool,
    /// Override render.iterations (full: clear-air propagation iterations, 0 = paper Fig. 6).
    #[arg(long)]
    iterations: Option<usize>,
    /// Set render.aov: write the method's components as EXR layers (full: diffusion, low_density,
    /// sun_single, background; transport: diffuse, sun_single, background; reference: orders,
    /// light sources, transmittance; docs/reference.md and docs/transport.md).
    #[arg(long)]
    aov: bool,
    /// Override medium.grid_name: the .vdb grid read as the density (for `render cloud.vdb`
    /// whose file holds several float grids and none named `density`).
    #[arg(long, value_name = "NAME")]
    grid_name: Option<String>,
    #[command(flatten)]
    frames: frames::FrameArgs,
}

/// Most characters of a message shown; a longer one (a 50 MB path pasted into a key) keeps its
/// start and end around a count of what was left out.
const MESSAGE_CHARS: usize = 1000;

/// `message`, shortened to [`MESSAGE_CHARS`].
fn shortened(message: &str) -> String {
    let n = message.chars().count();
    if n <= MESSAGE_CHARS {
        return message.to_string();
    }
    let keep = MESSAGE_CHARS / 2;
    let head: String = message.chars().take(keep).collect();
    let tail: String = message.chars().skip(n - keep).collect();
    format!("{head} … ({} characters left out) … {tail}", n - 2 * keep)
}

/// The `cloudgi` program: parse the process's arguments, run the subcommand, and give the exit
/// status (0; 1 after an error, printed shortened to stderr; 141 when stdout's reader has gone).
/// Public only for `src/main.rs`; not part of the library's API.
#[doc(hidden)]
pub fn main() {
    allocator::large_arrays_mapped();
    let result = match Cli::try_parse() {
        Ok(cli) => run(cli),
        // `--help` and `--version` are results on stdout: a full disk is an error there too.
        Err(e) if !e.use_stderr() => console::print(&e.render().to_string()),
        Err(e) => e.exit(),
    };
    match result {
        Ok(()) => {}
        Err(e) if console::is_broken_pipe(&e) => std::process::exit(console::EXIT_BROKEN_PIPE),
        Err(e) => {
            console::note(format_args!("error: {}", shortened(&e.to_string())));
            std::process::exit(1);
        }
    }
}

/// Most worker threads: 4 per core. More only adds scheduling and memory (each thread holds its
/// own buffers), never speed, and tens of thousands make every method crawl.
const THREADS_PER_CORE: usize = 4;

/// Check `--threads` against the cores of this machine.
fn check_threads(n: usize) -> Result<()> {
    let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
    let max = THREADS_PER_CORE * cores;
    if n == 0 || n > max {
        return Err(Error::invalid(
            "command line",
            "--threads",
            format!("{n} is not allowed: give 1 to {max} ({THREADS_PER_CORE} per core on this machine's {cores} cores), or leave it out for one per core"),
        ));
    }
    Ok(())
}

/// Run the parsed command.
fn run(cli: Cli) -> Result<()> {
    console::clean_up_on_interrupt()?;
    if let Some(n) = cli.threads {
        check_threads(n)?;
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .map_err(|e| Error::invalid("command line", "--threads", e.to_string()))?;
    }
    match cli.command {
        Command::Render(a) => render(a, cli.quiet),
        Command::Slab(a) => slab::run(a),
        Command::Compare(a) => compare::run(a),
        Command::Info(a) => info::run(a),
        Command::Sky(a) => sky::run(a, cli.quiet),
        Command::Export(a) => export::run(a, cli.quiet),
        Command::Figures(a) => figures::run(a, cli.quiet),
        Command::Bench(a) => bench::run(a),
        Command::Tonemap(a) => tonemap::run(a, cli.quiet),
    }
}

/// Write an image's EXR and PNG preview together: both or neither.
fn write_exr_and_png(img: &crate::Image, exr: &Path, png: &Path, exposure: f32) -> Result<()> {
    let (e, p) = (img.to_exr_bytes()?, img.to_png_bytes(exposure)?);
    crate::io::write_atomic_all(&[(exr, &e), (png, &p)])
}

/// The PNG written beside an EXR.
fn png_beside(exr: &Path) -> PathBuf {
    exr.with_extension("png")
}

fn check_exr_path(p: &Path, flag: &str) -> Result<()> {
    check_output_name(p, flag)?;
    match p.extension().and_then(|e| e.to_str()) {
        Some(e) if e.eq_ignore_ascii_case("exr") => Ok(()),
        _ => Err(Error::invalid(
            "command line",
            flag,
            format!("`{}` must end in .exr (the PNG preview is written beside it)", p.display()),
        )),
    }
}

/// An output's file name: one the file system takes, and a name before `.exr` / `.png`.
fn check_output_name(p: &Path, flag: &str) -> Result<()> {
    crate::io::check_file_name(p, "command line", flag)?;
    let bare = p
        .file_name()
        .and_then(|n| n.to_str())
        .filter(|n| n.eq_ignore_ascii_case(".exr") || n.eq_ignore_ascii_case(".png"));
    match bare {
        Some(n) => Err(Error::invalid(
            "command line",
            flag,
            format!("`{}` has no name before {n}; give one, e.g. cloud{n}", p.display()),
        )),
        None => Ok(()),
    }
}

/// `e` as the command line's when the key it names was set by one of `flags` (key, flag): the
/// value of `--width 0` is the user's flag, not the scene file's `camera.width`.
fn blamed_on_flags(e: Error, flags: &[(&str, &str)]) -> Error {
    match e {
        Error::Invalid { file, field, message } => match flags.iter().find(|(key, _)| *key == field) {
            Some((_, flag)) => Error::invalid("command line", *flag, message),
            None => Error::Invalid { file, field, message },
        },
        e => e,
    }
}

impl RenderArgs {
    /// The scene keys the command line sets, with their flags (for the warnings).
    fn flags(&self) -> Vec<(&'static str, &'static str)> {
        let given = [
            (self.width.is_some(), "camera.width", "--width"),
            (self.height.is_some(), "camera.height", "--height"),
            (self.spp.is_some(), "render.spp", "--spp"),
            (self.aa_samples.is_some(), "render.aa_samples", "--aa-samples"),
            (self.max_depth.is_some(), "render.max_depth", "--max-depth"),
            (self.time_limit.is_some(), "render.time_limit", "--time-limit"),
            (self.stderr, "render.stderr", "--stderr"),
            (self.iterations.is_some(), "render.iterations", "--iterations"),
            (self.aov, "render.aov", "--aov"),
            (self.grid_name.is_some(), "medium.grid_name", "--grid-name"),
        ];
        given.into_iter().filter(|g| g.0).map(|(_, k, f)| (k, f)).collect()
    }

    /// Apply the overrides to a scene description.
    fn apply(&self, d: &mut crate::SceneDesc) {
        if let Some(m) = self.method {
            d.render.method = m.into();
        }
        if let Some(w) = self.width {
            d.camera.width = w;
        }
        if let Some(h) = self.height {
            d.camera.height = h;
        }
        if let Some(s) = self.spp {
            d.render.spp = s;
        }
        if let Some(s) = self.aa_samples {
            d.render.aa_samples = s;
        }
        if let Some(s) = self.seed {
            d.render.seed = s;
        }
        if let Some(m) = self.max_depth {
            d.render.max_depth = Some(m);
        }
        if let Some(t) = self.time_limit {
            d.render.time_limit = Some(t);
        }
        if self.stderr {
            d.render.stderr = true;
        }
        if let Some(n) = self.iterations {
            d.render.iterations = n;
        }
        if self.aov {
            d.render.aov = true;
        }
        if let Some(g) = &self.grid_name {
            d.medium.grid_name = g.clone();
        }
    }
}

fn render(a: RenderArgs, quiet: bool) -> Result<()> {
    check_output_name(&a.output, "--output")?;
    let (exr, png) = tonemap::outputs(&a.output)?;
    tonemap::check_flag(a.exposure)?;
    let viewer = a.display_server.as_deref().map(display::parse).transpose()?;
    let file = SceneFile::read(a.scene.as_deref())?;
    if frames::is_sequence(&a, &file) {
        if viewer.is_some() {
            return Err(Error::invalid(
                "command line",
                "--display-server",
                "shows a still render live, and this is a sequence: leave it out (open the frames' EXRs in tev \
                 afterwards) or render one frame as a still",
            ));
        }
        return frames::render(&a, &file, quiet);
    }
    let mut desc = file.desc.clone();
    a.apply(&mut desc);
    output::check_files(&[&exr, &png], "--output", &file.inputs(&desc))?;
    memory::check_image(&desc, &file.source)?;
    let scene = Scene::build(desc, &file.source, &file.base).map_err(|e| blamed_on_flags(e, &a.flags()))?;
    memory::check_solver(&scene, 0)?;
    for w in warnings::warnings(&file, &a.flags(), &scene) {
        note!("warning: {w}");
    }
    let live = viewer.and_then(|v| display::Display::connect(v, &exr.display().to_string()));
    let progress = progress::Bars::new(quiet).with_display(live);
    let options = crate::Options {
        progress: Some(&progress),
        cancel: None,
    };
    let out = crate::render(&scene, scene.render.method, &options)?;
    let timings = out.stats.timings.summary();
    let image = out.into_image();
    crate::Progress::image(&progress, &image);
    let (stops, why) = tonemap::stops(a.exposure, Some(&file), &image);
    write_exr_and_png(&image, &exr, &png, stops)?;
    if !quiet {
        note!(
            "{} {}×{} → {} + {} (exposure {stops:+.2} stops, {why})",
            scene.render.method.name(),
            scene.camera.width,
            scene.camera.height,
            exr.display(),
            png.display()
        );
        note!("timings: {timings}");
    }
    Ok(())
}
