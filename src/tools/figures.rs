//! The paper's figure series (Max et al. 2004, Figs. 4–8) rendered from one scene, each method
//! compared against the unbiased reference: `cloudgi figures [SCENE] -o DIR`.
//!
//! Renders, at one size:
//! * Fig. 4 `single`: exact single scattering of the sun plus the attenuated background;
//! * Fig. 5 `diffusion`: diffusion composited with single scattering;
//! * Fig. 6 `full` with `render.iterations = 0`: diffusion + the low-density edge gather;
//! * Fig. 7 `full`: also the clear-air cube iterations;
//! * Fig. 8 `full` of the same scene at sunset (sun 4° high at the scene sun's azimuth, reddened
//!   by the atmosphere, atmosphere sky), compared against its own reference;
//! * `fig7-full-fixed`: `full` with the scene's own settings, by default the measured fixes to
//!   the paper's method (sky and ground single scattering, δ-M, g·I1·ω; docs/budget.md), where
//!   Figs. 5–8 render the paper's scheme (those switches off);
//! * `reference` of the scene (and of the sunset scene), the unbiased path tracer.
//!
//! Writes `DIR/<id>.exr` + `.png` per render, `DIR/diff-<id>.png` (relative luminance difference
//! against the reference, see [`crate::tools::compare`]), `DIR/index.md` (images side by side with the
//! error table) and `DIR/results.json`.
//!
//! **Masks.** Each method is measured twice:
//! * *cloud*: reference transmittance < 0.99 ([`crate::tools::compare::CLOUD_T`]), every pixel that
//!   shows cloud;
//! * *edge*: reference transmittance in [[`EDGE_T_MIN`], [`EDGE_T_MAX`]] = [0.05, 0.9]: the thin
//!   rims where the camera ray's optical depth is between about 0.1 and 3. Below 0.05 the ray
//!   hits the dense core (the diffusion region); above 0.9 the cloud adds only a faint haze on
//!   the background and the relative error is dominated by the background, which every method
//!   gets right. This band is where the paper's low-density treatment (section 4) acts.

use crate::error::{Error, Result};
use crate::image::Image;
use crate::pipeline::{Progress, Timings};
use crate::reference::TRANSMITTANCE_LAYER;
use crate::scene::{Method, Scene, SceneDesc, SkyModel};
use crate::tools::compare::{compare, write_diff_png, Metrics};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

/// Lowest reference transmittance of the edge mask.
pub const EDGE_T_MIN: f32 = 0.05;
/// Highest reference transmittance of the edge mask.
pub const EDGE_T_MAX: f32 = 0.9;
/// Sun elevation of the sunset figure (degrees; the paper's Fig. 8 has the sun near the horizon).
pub const SUNSET_ELEVATION_DEG: f32 = 4.0;
/// PNG exposure of the sunset renders (stops): the atmosphere's sun is ~400× brighter than the
/// default scene's 3 W/m² (as in examples/sunset.toml).
pub const SUNSET_EXPOSURE: f32 = -2.5;

/// Settings of a figure run.
#[derive(Clone, Debug)]
pub struct FigureOptions {
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// Samples per pixel of each reference render.
    pub reference_spp: u32,
    /// Time limit of each reference render (seconds; stops after the pass in progress).
    pub reference_time: Option<f64>,
}

impl Default for FigureOptions {
    fn default() -> Self {
        FigureOptions {
            width: 120,
            height: 90,
            reference_spp: 256,
            reference_time: Some(15.0),
        }
    }
}

/// One rendered method and its errors.
#[derive(Clone, Debug, Serialize)]
pub struct FigureResult {
    /// File stem: `fig4-single` etc.
    pub id: String,
    /// The paper's figure number.
    pub figure: u32,
    /// What it shows.
    pub title: String,
    /// Method name.
    pub method: String,
    /// `render.iterations` used (full only).
    pub iterations: Option<usize>,
    /// Which reference it is compared against (file stem).
    pub reference: String,
    /// Wall-clock seconds of the render (scene set-up excluded).
    pub seconds: f64,
    /// Per-stage seconds.
    pub stages: Vec<(String, f64)>,
    /// Errors over the cloud mask.
    pub cloud: Metrics,
    /// Errors over the edge mask (`null` when no pixel falls in it).
    pub edge: Option<Metrics>,
}

/// One reference render.
#[derive(Clone, Debug, Serialize)]
pub struct ReferenceResult {
    /// File stem.
    pub id: String,
    /// Samples per pixel taken.
    pub spp: u32,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// Pixels in the cloud mask.
    pub cloud_pixels: usize,
    /// Pixels in the edge mask.
    pub edge_pixels: usize,
    /// Mean over the cloud mask of the reference's relative standard error (luminance of the
    /// per-band standard error / luminance): the reference's own noise, which the per-pixel
    /// mean relative error of every method includes (for Gaussian noise about 0.8× this).
    pub cloud_noise: f64,
    /// The same over the edge mask.
    pub edge_noise: f64,
}

/// Everything `results.json` holds.
#[derive(Clone, Debug, Serialize)]
pub struct FigureReport {
    /// Scene file (or `<built-in>`).
    pub scene: String,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Worker threads used.
    pub threads: usize,
    /// The cloud mask's definition.
    pub cloud_mask: String,
    /// The edge mask's definition.
    pub edge_mask: String,
    /// The reference renders (scene, sunset).
    pub references: Vec<ReferenceResult>,
    /// The methods.
    pub figures: Vec<FigureResult>,
}

/// The edge mask from a transmittance layer: [`EDGE_T_MIN`] ≤ T ≤ [`EDGE_T_MAX`].
pub fn edge_mask(t: &[crate::math::Rgb]) -> Vec<bool> {
    t.iter().map(|v| (EDGE_T_MIN..=EDGE_T_MAX).contains(&v.x)).collect()
}

/// Turn `desc` into the same scene at sunset: the sun [`SUNSET_ELEVATION_DEG`] above the horizon
/// at the azimuth of the scene's sun, its irradiance from the atmosphere, an atmosphere sky.
pub fn sunset_desc(desc: &SceneDesc) -> SceneDesc {
    let mut d = desc.clone();
    let az = match (desc.sun.direction, desc.sun.azimuth_deg) {
        (_, Some(a)) => a,
        (Some(v), None) => v[2].atan2(v[0]).to_degrees(),
        (None, None) => 0.0,
    };
    d.sun.direction = None;
    d.sun.elevation_deg = Some(SUNSET_ELEVATION_DEG);
    d.sun.azimuth_deg = Some(az);
    d.sun.from_atmosphere = true;
    d.sky.model = SkyModel::Atmosphere;
    d.sky.altitude_m = 0.0;
    d.sky.map_width = 256;
    d.render.exposure = SUNSET_EXPOSURE;
    d
}

struct Masks {
    cloud: Vec<bool>,
    edge: Vec<bool>,
}

fn masks(reference: &Image) -> Result<Masks> {
    let t = reference
        .layer(TRANSMITTANCE_LAYER)
        .ok_or_else(|| Error::format("<reference render>", "no transmittance layer"))?;
    Ok(Masks {
        cloud: crate::tools::compare::mask_from_transmittance(t),
        edge: edge_mask(t),
    })
}

fn write_pair(dir: &Path, id: &str, img: &Image, exposure: f32) -> Result<()> {
    img.write_exr(&dir.join(format!("{id}.exr")))?;
    img.write_png(&dir.join(format!("{id}.png")), exposure)
}

/// Render the figure series of the scene `desc` (named `source` in messages, its relative paths
/// resolved against `folder`) into `dir` (created if missing) and return what was measured. The
/// scene's own camera size and method are replaced by `opts` and each figure's method.
pub fn run(desc: &SceneDesc, source: &str, folder: &Path, dir: &Path, opts: &FigureOptions, progress: &dyn Progress) -> Result<FigureReport> {
    if opts.width == 0 || opts.height == 0 {
        return Err(Error::invalid(
            "command line",
            "--width/--height",
            "the image needs at least 1×1 pixels",
        ));
    }
    if opts.reference_spp == 0 {
        return Err(Error::invalid(
            "command line",
            "--reference-spp",
            "the reference needs at least 1 sample per pixel",
        ));
    }
    crate::io::create_output_dir(dir)?;
    let mut d = desc.clone();
    (d.camera.width, d.camera.height, d.render.aov) = (opts.width, opts.height, false);
    let base = Scene::build(d, source, folder)?;
    let sunset_base = Scene::build(sunset_desc(&base.desc), &format!("{source} (sunset)"), folder)?;

    // `paper`: the paper's scheme (the measured fixes of docs/budget.md off); else the scene's own settings.
    let with = |s: &Scene, method: Method, iterations: Option<usize>, paper: bool| -> Result<Scene> {
        let mut d = s.desc.clone();
        d.render.method = method;
        if paper {
            d.render.sky_single_scattering = false;
            d.render.sky_boundary = false;
            d.render.forward_fraction = 0.0;
            d.render.diffuse_anisotropy = false;
            d.render.surface_depth = 0.0;
        }
        if let Some(n) = iterations {
            d.render.iterations = n;
        }
        if method == Method::Reference {
            d.render.spp = opts.reference_spp;
            d.render.time_limit = opts.reference_time;
            // One sample has no standard error; the report's noise is then unknown.
            d.render.stderr = opts.reference_spp >= 2;
        }
        Scene::build(d, &s.source, folder)
    };

    // References first: the masks come from them.
    let mut references = Vec::new();
    let mut refs = Vec::new();
    for (id, s) in [("reference", &base), ("fig8-reference", &sunset_base)] {
        let scene = with(s, Method::Reference, None, false)?;
        let mut timings = Timings::default();
        let t0 = Instant::now();
        let (img, stats) = crate::reference::render_with_stats(&scene, progress, &mut timings);
        if stats.spp == 0 && !progress.cancelled() {
            return Err(Error::invalid(
                "command line",
                "--reference-time",
                format!(
                    "{} ended the reference before any pixel completed a sample, so there is nothing to \
                     measure against; raise --reference-time (0: no limit)",
                    crate::limits::seconds_text(opts.reference_time.unwrap_or(0.0))
                ),
            ));
        }
        let seconds = t0.elapsed().as_secs_f64();
        progress.log(&format!("{id}: {} spp in {seconds:.1} s", stats.spp));
        let m = masks(&img)?;
        if !m.cloud.contains(&true) {
            return Err(Error::invalid(
                "command line",
                "--width/--height",
                format!(
                    "no pixel of the {}×{} {id} shows the cloud (transmittance < {}), so there is nothing to \
                     measure the figures on; raise --width and --height, or point the scene's camera at the cloud",
                    opts.width,
                    opts.height,
                    crate::tools::compare::CLOUD_T
                ),
            ));
        }
        references.push(ReferenceResult {
            id: id.into(),
            spp: stats.spp,
            seconds,
            cloud_pixels: m.cloud.iter().filter(|&&b| b).count(),
            edge_pixels: m.edge.iter().filter(|&&b| b).count(),
            cloud_noise: relative_noise(&img, &m.cloud),
            edge_noise: relative_noise(&img, &m.edge),
        });
        refs.push((img, m, scene.render.exposure));
    }
    // Written once both have a cloud to measure: a failed check leaves no output.
    for (r, (img, _, exposure)) in references.iter().zip(&refs) {
        write_pair(dir, &r.id, img, *exposure)?;
    }

    let plan = [
        ("fig4-single", 4, "single scattering", Method::Single, None, 0, true),
        ("fig5-diffusion", 5, "diffusion", Method::Diffusion, None, 0, true),
        (
            "fig6-diffusion-low-density",
            6,
            "diffusion + low-density",
            Method::Full,
            Some(0),
            0,
            true,
        ),
        ("fig7-full", 7, "full (+ clear-air iterations)", Method::Full, None, 0, true),
        ("fig8-sunset-full", 8, "full, at sunset", Method::Full, None, 1, true),
        (
            "fig7-full-fixed",
            7,
            "full with the measured fixes (scene settings)",
            Method::Full,
            None,
            0,
            false,
        ),
    ];
    let mut figures = Vec::new();
    for (id, figure, title, method, iterations, which, paper) in plan {
        let src = if which == 0 { &base } else { &sunset_base };
        let scene = with(src, method, iterations, paper)?;
        let t0 = Instant::now();
        let out = crate::render::render(&scene, progress)?;
        let seconds = t0.elapsed().as_secs_f64();
        progress.log(&format!("{id}: {seconds:.1} s"));
        write_pair(dir, id, &out.image, scene.render.exposure)?;
        let (rimg, m, _) = &refs[which];
        write_diff_png(&dir.join(format!("diff-{id}.png")), &out.image, rimg, Some(&m.cloud))?;
        let cloud = compare(&out.image, rimg, Some(&m.cloud))?;
        let edge = if m.edge.iter().any(|&b| b) {
            let mut e = compare(&out.image, rimg, Some(&m.edge))?;
            e.mask = edge_mask_name();
            Some(e)
        } else {
            None
        };
        figures.push(FigureResult {
            id: id.into(),
            figure,
            title: title.into(),
            method: method.name().into(),
            iterations: (method == Method::Full).then_some(scene.render.clear_air.iterations),
            reference: references[which].id.clone(),
            seconds,
            stages: out.timings.stages.clone(),
            cloud,
            edge,
        });
    }

    let report = FigureReport {
        scene: base.source.clone(),
        width: opts.width,
        height: opts.height,
        threads: rayon::current_num_threads(),
        cloud_mask: format!("reference transmittance < {}", crate::tools::compare::CLOUD_T),
        edge_mask: edge_mask_name(),
        references,
        figures,
    };
    let json = serde_json::to_string_pretty(&report).map_err(|e| Error::format("results.json", e.to_string()))?;
    crate::io::write_atomic(&dir.join("results.json"), json.as_bytes())?;
    crate::io::write_atomic(&dir.join("index.md"), index_markdown(&report).as_bytes())?;
    Ok(report)
}

/// Mean of luminance(stderr) / luminance(image) over the masked pixels with positive luminance.
fn relative_noise(img: &Image, mask: &[bool]) -> f64 {
    let Some(se) = img.layer(crate::reference::STDERR_LAYER) else {
        return f64::NAN;
    };
    let (mut sum, mut n) = (0f64, 0usize);
    for ((p, e), &m) in img.pixels.iter().zip(se).zip(mask) {
        let y = crate::math::luminance(*p) as f64;
        if m && y > 0.0 {
            sum += crate::math::luminance(*e) as f64 / y;
            n += 1;
        }
    }
    if n > 0 {
        sum / n as f64
    } else {
        0.0
    }
}

fn edge_mask_name() -> String {
    format!("{EDGE_T_MIN} ≤ reference transmittance ≤ {EDGE_T_MAX}")
}

fn pct(x: Option<f64>) -> String {
    x.map_or("n/a".into(), |x| format!("{:.1} %", 100.0 * x))
}

fn signed_pct(x: Option<f64>) -> String {
    x.map_or("n/a".into(), |x| format!("{:+.1} %", 100.0 * x))
}

/// The error table of `report` as Markdown (one row per method).
pub fn table_markdown(report: &FigureReport) -> String {
    let mut s = String::new();
    s.push_str("| Fig. | method | time (s) | MRE cloud | MRE edge | RMSE cloud | RMSE edge | bias cloud | bias edge |\n");
    s.push_str("|---|---|---:|---:|---:|---:|---:|---:|---:|\n");
    for f in &report.figures {
        let (me, re, be) = match &f.edge {
            Some(e) => (
                pct(e.mean_relative_error),
                format!("{:.4}", e.rmse),
                signed_pct(e.luminance_bias),
            ),
            None => ("n/a".into(), "n/a".into(), "n/a".into()),
        };
        let _ = writeln!(
            s,
            "| {} | {} | {:.1} | {} | {} | {:.4} | {} | {} | {} |",
            f.figure,
            f.title,
            f.seconds,
            pct(f.cloud.mean_relative_error),
            me,
            f.cloud.rmse,
            re,
            signed_pct(f.cloud.luminance_bias),
            be
        );
    }
    s
}

fn index_markdown(r: &FigureReport) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Figure series: {}\n", r.scene);
    let _ = writeln!(
        s,
        "{}×{} pixels, {} threads. Errors against the reference (unbiased path tracer): MRE = mean \
         relative luminance error, RMSE per band (W·m⁻²·sr⁻¹), bias = relative bias of the mean \
         luminance. *cloud*: {}; *edge*: {} (thin cloud edges, where the low-density treatment acts).\n",
        r.width, r.height, r.threads, r.cloud_mask, r.edge_mask
    );
    for rf in &r.references {
        let _ = writeln!(
            s,
            "- `{}`: {} spp in {:.1} s; {} cloud pixels, {} edge pixels; its own noise (mean relative \
             standard error) {} over the cloud, {} over the edges.",
            rf.id,
            rf.spp,
            rf.seconds,
            rf.cloud_pixels,
            rf.edge_pixels,
            pct(Some(rf.cloud_noise)),
            pct(Some(rf.edge_noise))
        );
    }
    s.push('\n');
    s.push_str(&table_markdown(r));
    s.push_str("\nDifference images: relative luminance difference to the reference, white = equal, red = brighter, blue = darker, saturating at ±25 %; grey = outside the cloud mask.\n\n");
    s.push_str("| Fig. | render | reference | difference |\n|---|---|---|---|\n");
    for f in &r.figures {
        let _ = writeln!(
            s,
            "| {} {} | ![{}]({}.png) | ![{}]({}.png) | ![diff]({}) |",
            f.figure,
            f.title,
            f.id,
            f.id,
            f.reference,
            f.reference,
            format_args!("diff-{}.png", f.id)
        );
    }
    s
}
