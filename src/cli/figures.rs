//! `cloudgi figures [SCENE] -o DIR`: the paper's figure series (Figs. 4–8) with the reference,
//! difference images, `index.md` and `results.json` (see `crate::tools::figures`).

use crate::error::Result;
use crate::scene::Method;
use crate::tools::figures::{run as run_figures, table_markdown, FigureOptions};
use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct FiguresArgs {
    /// Scene file (TOML), or a grid file (.vdb, .npy, .vol, .raw) framed under the default sun and
    /// sky, as for `render`. Without it, the built-in default scene.
    scene: Option<PathBuf>,
    /// Output folder (created if missing).
    #[arg(short, long, default_value = "figures")]
    output: PathBuf,
    /// Image width (pixels).
    #[arg(long, default_value_t = FigureOptions::default().width)]
    width: u32,
    /// Image height (pixels).
    #[arg(long, default_value_t = FigureOptions::default().height)]
    height: u32,
    /// Samples per pixel of each reference render (scene and sunset).
    #[arg(long, default_value_t = FigureOptions::default().reference_spp)]
    reference_spp: u32,
    /// Time limit of each reference render in seconds (0 = none; stops after the pass in progress).
    #[arg(long, default_value_t = FigureOptions::default().reference_time.unwrap_or(0.0))]
    reference_time: f64,
}

pub fn run(a: FiguresArgs, quiet: bool) -> Result<()> {
    let opts = FigureOptions {
        width: a.width,
        height: a.height,
        reference_spp: a.reference_spp,
        reference_time: (a.reference_time > 0.0).then_some(a.reference_time),
    };
    if !(0.0..=crate::limits::MAX_SECONDS).contains(&a.reference_time) {
        return Err(crate::Error::invalid(
            "command line",
            "--reference-time",
            format!(
                "{:?} is not allowed: the time limit is a number of seconds from 0 (none) to 1e9 (about 32 years)",
                a.reference_time
            ),
        ));
    }
    let file = super::SceneFile::read(a.scene.as_deref())?;
    // figures writes .exr, .png, .json and .md files under fixed names into the folder.
    let ours = |p: &std::path::Path| {
        p.extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| ["exr", "png", "json", "md"].contains(&e.to_ascii_lowercase().as_str()))
    };
    super::output::check_folder(&a.output, "--output", &file.inputs(&file.desc), ours)?;
    for method in [Method::Reference, Method::Full] {
        let mut d = file.desc.clone();
        (d.camera.width, d.camera.height, d.render.method, d.render.stderr) = (a.width, a.height, method, true);
        super::memory::check_image(&d, "command line")?;
    }
    let progress = super::progress::Bars::new(quiet);
    // A run that fails leaves no empty output folder (an interrupt: src/cli/console.rs).
    let report = run_figures(&file.desc, &file.source, &file.base, &a.output, &opts, &progress)
        .inspect_err(|_| crate::io::remove_created_empty_dirs())?;
    if !quiet {
        note!("{}", table_markdown(&report).trim_end());
        note!("→ {}", a.output.join("index.md").display());
    }
    Ok(())
}
