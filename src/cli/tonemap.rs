//! The PNG preview's exposure and `cloudgi tonemap IN.exr -o OUT.png [--exposure S]`, which
//! re-makes a render's PNG from its EXR (byte for byte, with the same exposure rule).
//!
//! Precedence: `--exposure S` on the command line, then `render.exposure` when the scene file sets
//! it, then the automatic exposure of [`crate::exposure`] (a function of the pixels alone).

use super::scene_file::SceneFile;
use crate::error::{Error, Result};
use crate::limits::MAX_EXPOSURE;
use crate::Image;
use clap::Args;
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
pub struct TonemapArgs {
    /// The render's EXR.
    input: PathBuf,
    /// The PNG to write.
    #[arg(short, long)]
    output: PathBuf,
    /// Exposure in stops (default: automatic, the rule `render` uses).
    #[arg(long, allow_hyphen_values = true)]
    exposure: Option<f32>,
}

/// `--exposure` must be a finite number of stops within the scene key's ±64 (`limits.rs`).
pub fn check_flag(exposure: Option<f32>) -> Result<()> {
    match exposure {
        Some(s) if !s.is_finite() => Err(Error::invalid(
            "command line",
            "--exposure",
            format!("{s} is not a finite number of stops (e.g. --exposure -2.5)"),
        )),
        Some(s) if s.abs() > MAX_EXPOSURE => Err(Error::invalid(
            "command line",
            "--exposure",
            format!("{s} stops is beyond ±{MAX_EXPOSURE}: past 127 the preview's scale factor overflows f32"),
        )),
        _ => Ok(()),
    }
}

/// The PNG's exposure in stops and where it came from, by the precedence above (`file`: None for
/// `tonemap`, which has no scene).
pub fn stops(flag: Option<f32>, file: Option<&SceneFile>, img: &Image) -> (f32, &'static str) {
    if let Some(s) = flag {
        return (s, "--exposure");
    }
    if let Some(f) = file.filter(|f| f.sets("render.exposure")) {
        return (f.desc.render.exposure, "render.exposure");
    }
    (crate::exposure::auto_stops(img), "automatic")
}

/// The EXR and PNG a render writes for `-o PATH`: `OUT.exr` gives `OUT.png` beside it; `OUT.png`
/// gives `OUT.exr` beside it (the EXR is the render; the PNG only its preview).
pub fn outputs(output: &Path) -> Result<(PathBuf, PathBuf)> {
    let ext = output.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("exr") => Ok((output.to_path_buf(), output.with_extension("png"))),
        Some("png") => Ok((output.with_extension("exr"), output.to_path_buf())),
        _ => Err(Error::invalid(
            "command line",
            "--output",
            format!(
                "`{}` must end in .exr or .png (both are written: OUT.exr and the preview OUT.png)",
                output.display()
            ),
        )),
    }
}

/// `path`, given with `flag`, names a PNG: a file name ending in `.png` (`.png` alone is a
/// hidden file's name with no extension).
pub(super) fn check_png_name(path: &Path, flag: &str) -> Result<()> {
    match path.extension().and_then(|e| e.to_str()) {
        Some(e) if e.eq_ignore_ascii_case("png") => Ok(()),
        _ => Err(Error::invalid(
            "command line",
            flag,
            format!("`{}` must be a file name ending in .png, e.g. preview.png", path.display()),
        )),
    }
}

pub fn run(a: TonemapArgs, quiet: bool) -> Result<()> {
    check_flag(a.exposure)?;
    check_png_name(&a.output, "--output")?;
    super::output::check_files(&[&a.output], "--output", &[(a.input.clone(), "IN".to_string())])?;
    let img = Image::read_exr(&a.input)?;
    if let Some(w) = invalid_pixels_warning(&img, &a.input) {
        note!("{w}");
    }
    let (s, why) = stops(a.exposure, None, &img);
    img.write_png(&a.output, s)?;
    if !quiet {
        note!("{} → {} (exposure {s:+.2} stops, {why})", a.input.display(), a.output.display());
    }
    Ok(())
}

/// A warning when `img` holds pixels no render writes (NaN, infinite or negative): the preview
/// still shows them, black or white, so the warning is what tells that the EXR is not sound.
fn invalid_pixels_warning(img: &Image, path: &Path) -> Option<String> {
    let bad = |p: &crate::math::Rgb| !p.is_finite() || p.min_element() < 0.0;
    let (first, p) = img.pixels.iter().enumerate().find(|(_, p)| bad(p))?;
    let count = img.pixels.iter().filter(|p| bad(p)).count();
    Some(format!(
        "warning: {}: {count} pixel(s) hold a NaN, infinite or negative value (the first at ({}, {}): {p}); \
         the preview draws NaN and negative values black and infinite ones white. cloudgi render writes \
         none: check what wrote this EXR",
        path.display(),
        first % img.width as usize,
        first / img.width as usize
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixels_no_render_writes_are_warned_about() {
        let img = |v: f32| {
            let mut i = Image::new(3, 2);
            i.pixels.fill(crate::math::Rgb::new(0.5, v, 0.5));
            i
        };
        assert_eq!(invalid_pixels_warning(&img(0.0), Path::new("a.exr")), None);
        for v in [f32::NAN, f32::INFINITY, -1e-3] {
            let w = invalid_pixels_warning(&img(v), Path::new("a.exr")).expect("a warning");
            assert!(w.contains("a.exr") && w.contains("6 pixel(s)") && w.contains("(0, 0)"), "{w}");
        }
    }

    #[test]
    fn either_output_names_both_files() {
        let both = (PathBuf::from("a/b.exr"), PathBuf::from("a/b.png"));
        assert_eq!(outputs(Path::new("a/b.exr")).unwrap(), both);
        assert_eq!(outputs(Path::new("a/b.png")).unwrap(), both);
        assert!(outputs(Path::new("b.jpg")).is_err() && outputs(Path::new("b")).is_err());
    }
}
