//! `cloudgi export mitsuba [SCENE] -o DIR`: write the scene for an independent renderer.

use crate::error::Result;
use crate::scene::Scene;
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
}

pub fn run(a: ExportArgs, quiet: bool) -> Result<()> {
    match a.target {
        Target::Mitsuba(m) => {
            let file = super::SceneFile::read(m.scene.as_deref())?;
            let ours = |p: &std::path::Path| {
                p.file_name()
                    .is_some_and(|n| n == "scene.xml" || n == "density.vol" || n == crate::reference::mitsuba::SKY_FILE)
            };
            super::output::check_folder(&m.output, "--output", &file.inputs(&file.desc), ours)?;
            let scene = Scene::build(file.desc, &file.source, &file.base)?;
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
