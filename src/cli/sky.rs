//! `cloudgi sky [SCENE] -o sky.exr [--width W] [--frame N]`: export the scene's sky as an
//! equirectangular EXR (row 0 = +y, u = atan2(z, x)/2π; see docs/sky.md) plus a tone-mapped PNG
//! beside it. The sun is not in the map (it is carried separately); its direction and irradiance
//! are printed. A sequence whose keys move the sun needs `--frame`, as `export` does.

use super::export::frame_desc;
use crate::error::{Error, Result};
use crate::lighting::sun_and_sky;
use crate::sequence::Sequence;
use clap::Args;
use std::path::PathBuf;

/// Arguments of `cloudgi sky`.
#[derive(Args, Debug)]
pub struct SkyArgs {
    /// Scene file (TOML). Without it, the built-in default scene.
    scene: Option<PathBuf>,
    /// Output EXR; the PNG preview is written beside it.
    #[arg(short, long, default_value = "sky.exr")]
    output: PathBuf,
    /// Width of the map in pixels (height = width / 2). Default: the sky's own map width
    /// (`sky.map_width` for the atmosphere, the file's for an envmap, 512 for a constant sky).
    #[arg(long)]
    width: Option<u32>,
    /// The frame of a sequence whose sun and sky to export (needed when `[animation]` keys the sun).
    #[arg(long, value_name = "N")]
    frame: Option<u32>,
}

/// Run `cloudgi sky`.
pub fn run(a: SkyArgs, quiet: bool) -> Result<()> {
    super::check_exr_path(&a.output, "--output")?;
    if let Some(w) = a.width {
        if !(2..=16384).contains(&w) {
            return Err(Error::invalid(
                "command line",
                "--width",
                format!("{w} is not allowed: use 2 to 16384 pixels"),
            ));
        }
    }
    let file = super::SceneFile::read(a.scene.as_deref())?;
    // Without keys on the sun every frame has the scene's sky.
    let keyed = Sequence::new(&file.desc, &file.source)?.keys_sun();
    let desc = &if a.frame.is_some() || keyed {
        let one = "[animation] keys the sun, so `sky` exports one frame's sun and sky";
        frame_desc(&file.desc, &file.source, &file.base, a.frame, one)?
    } else {
        file.desc.clone()
    };
    let png = super::png_beside(&a.output);
    super::output::check_files(&[&a.output, &png], "--output", &file.inputs(desc))?;
    let t = std::time::Instant::now();
    let (sun, sky) = sun_and_sky(&desc.sun, &desc.sky, &file.source, &file.base)?;
    let img = sky.to_image(a.width.map(|w| w as usize));
    super::write_exr_and_png(&img, &a.output, &png, desc.render.exposure)?;
    if !quiet {
        note!(
            "sky {}×{} → {} + {} ({:.3} s)",
            img.width,
            img.height,
            a.output.display(),
            png.display(),
            t.elapsed().as_secs_f64()
        );
        let clipped = match sky.extracted_sun_clip {
            Some(_) => " (a lower bound: the map's sun is clipped)",
            None => "",
        };
        note!(
            "sun (not in the map): direction {:?}, irradiance {:?} W/m²{clipped}; sky irradiance on the ground {:?} W/m²",
            sun.dir.to_array(),
            sun.irradiance.to_array(),
            sky.irradiance_up.to_array()
        );
    }
    Ok(())
}
