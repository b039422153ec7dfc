//! Subcommands of the `cloudgi` binary.

mod compare;
mod export;
mod figures;
mod info;
mod progress;
mod sky;
mod slab;

use clap::{Args, Parser, Subcommand};
use cloudgi::error::{Error, Result};
use cloudgi::scene::{Method, Scene};
use std::path::{Path, PathBuf};

/// Physically based cloud renderer (Max et al. 2004: diffusion and multiple anisotropic scattering).
#[derive(Parser, Debug)]
#[command(name = "cloudgi", version, about)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Worker threads (default: all cores). The image is identical for any count.
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
    /// Reflectance and transmittance of a plane-parallel slab (reference transport), one JSON line.
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
}

#[derive(Args, Debug)]
struct RenderArgs {
    /// Scene file (TOML). Without it, the built-in default scene.
    scene: Option<PathBuf>,
    /// Output EXR; the PNG preview is written beside it.
    #[arg(short, long, default_value = "cloud.exr")]
    output: PathBuf,
    /// Override render.method.
    #[arg(long, value_enum)]
    method: Option<Method>,
    /// Override camera.width (pixels).
    #[arg(long)]
    width: Option<u32>,
    /// Override camera.height (pixels).
    #[arg(long)]
    height: Option<u32>,
    /// Override render.spp.
    #[arg(long)]
    spp: Option<u32>,
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
    /// Set render.aov (full: write diffusion, low_density, sun_single, background as EXR layers).
    #[arg(long)]
    aov: bool,
}

/// Run the parsed command.
pub fn run(cli: Cli) -> Result<()> {
    if let Some(n) = cli.threads {
        if n == 0 {
            return Err(Error::invalid("command line", "--threads", "must be at least 1"));
        }
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
    }
}

/// The PNG written beside an EXR.
fn png_beside(exr: &Path) -> PathBuf {
    exr.with_extension("png")
}

fn check_exr_path(p: &Path, flag: &str) -> Result<()> {
    match p.extension().and_then(|e| e.to_str()) {
        Some(e) if e.eq_ignore_ascii_case("exr") => Ok(()),
        _ => Err(Error::invalid(
            "command line",
            flag,
            format!("`{}` must end in .exr (the PNG preview is written beside it)", p.display()),
        )),
    }
}

fn render(a: RenderArgs, quiet: bool) -> Result<()> {
    check_exr_path(&a.output, "--output")?;
    let scene = Scene::load(a.scene.as_deref(), |d| {
        if let Some(m) = a.method {
            d.render.method = m;
        }
        if let Some(w) = a.width {
            d.camera.width = w;
        }
        if let Some(h) = a.height {
            d.camera.height = h;
        }
        if let Some(s) = a.spp {
            d.render.spp = s;
        }
        if let Some(s) = a.seed {
            d.render.seed = s;
        }
        if let Some(m) = a.max_depth {
            d.render.max_depth = Some(m);
        }
        if let Some(t) = a.time_limit {
            d.render.time_limit = Some(t);
        }
        if a.stderr {
            d.render.stderr = true;
        }
        if let Some(n) = a.iterations {
            d.render.iterations = n;
        }
        if a.aov {
            d.render.aov = true;
        }
    })?;
    let progress = progress::Bars::new(quiet);
    let out = cloudgi::render(&scene, &progress)?;
    out.image.write_exr(&a.output)?;
    let png = png_beside(&a.output);
    out.image.write_png(&png, scene.render.exposure)?;
    if !quiet {
        eprintln!(
            "{} {}×{} → {} + {}",
            scene.render.method.name(),
            scene.camera.width,
            scene.camera.height,
            a.output.display(),
            png.display()
        );
        eprintln!("timings: {}", out.timings.summary());
    }
    Ok(())
}
