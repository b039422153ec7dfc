//! `cloudgi export mitsuba [SCENE] -o DIR [--frame N]`: write the scene (one frame of a sequence) for
//! an independent renderer.

use crate::error::{Error, Result};
use crate::scene::{Scene, SceneDesc};
use crate::sequence::Sequence;
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ExportArgs {
    #[command(subcommand)]
    target: Target,
}

#[derive(Subcommand, Debug)]
enum Target {
    /// Mitsuba 3: DIR/scene.xml (volpath, heterogeneous medium, sun, sky, ground, camera) + DIR/density.vol
    /// (+ DIR/sky.exr for an atmosphere or envmap sky).
    Mitsuba(MitsubaArgs),
}

#[derive(Args, Debug)]
struct MitsubaArgs {
    /// Scene file (TOML). Without it, the built-in default scene.
    scene: Option<PathBuf>,
    /// Output folder (created if missing).
    #[arg(short, long)]
    output: PathBuf,
    /// The frame to export of a sequence (a frame pattern in `medium.grid`, or `[animation]`).
    #[arg(long, value_name = "N")]
    frame: Option<u32>,
}

/// The description of the one frame a command writes: the scene's own, or `frame`'s of a
/// sequence; `one` says why the command needs one frame (`export writes one frame`).
pub(super) fn frame_desc(desc: &SceneDesc, source: &str, base: &std::path::Path, frame: Option<u32>, one: &str) -> Result<SceneDesc> {
    let seq = Sequence::new(desc, source)?;
    match (seq.is_animated(), frame) {
        (false, None) => Ok(desc.clone()),
        (true, Some(f)) => {
            seq.check_grid_files(&[f], base, source)?;
            Ok(seq.desc_at(f))
        }
        (true, None) => Err(Error::invalid(
            source,
            "--frame",
            format!("is missing: the scene is a sequence (a frame pattern in medium.grid, or [animation]) and {one}; pass --frame N"),
        )),
        (false, Some(f)) => Err(Error::invalid(
            "command line",
            "--frame",
            format!("{f} is not allowed: {source} is not a sequence (no frame pattern in medium.grid, no [animation]); leave --frame out"),
        )),
    }
}

pub fn run(a: ExportArgs, quiet: bool) -> Result<()> {
    match a.target {
        Target::Mitsuba(m) => {
            let file = super::SceneFile::read(m.scene.as_deref())?;
            let desc = frame_desc(&file.desc, &file.source, &file.base, m.frame, "export writes one frame")?;
            let ours = |p: &std::path::Path| {
                p.file_name()
                    .is_some_and(|n| n == "scene.xml" || n == "density.vol" || n == crate::reference::mitsuba::SKY_FILE)
            };
            super::output::check_folder(&m.output, "--output", &file.inputs(&desc), ours)?;
            let scene = Scene::build(desc, &file.source, &file.base)?;
            // What reading the grid found (an empty .vdb, the grid chosen), as render prints it.
            for n in scene.notes() {
                note!("warning: {n}");
            }
            let files = crate::reference::mitsuba::export(&scene, &m.output)?;
            if !quiet {
                for f in files {
                    note!("wrote {}", f.display());
                }
            }
            Ok(())
        }
    }
}
