//! `cloudgi compare TEST.exr REF.exr`: error metrics over the cloud pixels as one JSON line, and
//! an optional false-colour difference PNG (see `crate::tools::compare` for the mask and metrics).

use crate::error::{Error, Result};
use crate::tools::compare::{budget, choose_mask, compare, missing_layer, narrow_mask, write_diff_png, PixelCondition};
use crate::Image;
use clap::Args;
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
pub struct CompareArgs {
    /// The image to judge (EXR).
    test: PathBuf,
    /// The reference image (EXR), e.g. from `render --method reference`.
    reference: PathBuf,
    /// Write a false-colour relative luminance difference here (PNG): red brighter, blue darker, ±25 % saturates.
    #[arg(long)]
    diff: Option<PathBuf>,
    /// Take the cloud mask (transmittance < 0.99) from this EXR's `transmittance` layer instead of REF's.
    #[arg(long)]
    mask: Option<PathBuf>,
    /// Score every pixel (sky and ground too) instead of the cloud: for views where the ground
    /// (a shadow, the light under a cloud) is what is judged.
    #[arg(long, conflicts_with = "mask")]
    all_pixels: bool,
    /// Add `budget` to the JSON: block-mean error and bias by part of TEST's AOVs (against REF's
    /// order/light layers) and by region of the cloud (lit, base, core, edges, haze), with REF's
    /// share of light per order and light (docs/budget.md).
    #[arg(long)]
    budget: bool,
    /// Judge TEST against this layer of REF instead of its image (e.g. `light_sun` for a render
    /// with only the sun on and a black ground); the mask (and --budget's regions) still come from REF.
    #[arg(long, value_name = "NAME")]
    ref_layer: Option<String>,
    /// Keep only the pixels where a layer's luminance meets a condition (repeatable; all must
    /// hold): `LAYER<VALUE` or `LAYER>VALUE`, LAYER a layer of REF (or of --where-from) or `image`
    /// for its main channels. E.g. the ground the eye sees where REF is darker than 0.15:
    /// `--all-pixels --where 'transmittance>0.99' --where 'light_ground>0' --where 'image<0.15'`.
    #[arg(long = "where", value_name = "LAYER<VALUE", value_parser = PixelCondition::parse)]
    conditions: Vec<PixelCondition>,
    /// Read --where's layers from this EXR instead of REF (e.g. the whole scene's reference when
    /// REF is a render with only the sun on).
    #[arg(long, value_name = "EXR", requires = "conditions")]
    where_from: Option<PathBuf>,
}

pub fn run(a: CompareArgs) -> Result<()> {
    if let Some(d) = &a.diff {
        super::tonemap::check_png_name(d, "--diff")?;
        let mut inputs = vec![(a.test.clone(), "TEST".to_string()), (a.reference.clone(), "REF".to_string())];
        inputs.extend(a.mask.iter().map(|m| (m.clone(), "--mask".to_string())));
        inputs.extend(a.where_from.iter().map(|m| (m.clone(), "--where-from".to_string())));
        super::output::check_files(&[d], "--diff", &inputs)?;
    }
    let test = Image::read_exr(&a.test)?;
    let full_reference = Image::read_exr(&a.reference)?;
    let mut reference = full_reference.clone();
    if let Some(name) = &a.ref_layer {
        let Some(px) = reference.layer(name) else {
            let source = a.reference.display().to_string();
            return Err(missing_layer(&reference, name, &source, "--ref-layer"));
        };
        reference.pixels = px.to_vec();
        // The standard errors are the image's, not the layer's.
        reference.layers.retain(|l| l.0 != crate::reference::STDERR_LAYER);
    }
    refuse_non_finite(&test, &a.test, None)?;
    refuse_non_finite(&reference, &a.reference, a.ref_layer.as_deref())?;
    let mask_img = match &a.mask {
        Some(p) => Some(Image::read_exr(p)?),
        None => None,
    };
    if let Some(m) = &mask_img {
        if (m.width, m.height) != (reference.width, reference.height) {
            return Err(Error::invalid(
                "command line",
                "--mask",
                format!(
                    "{} is {}×{} but the images are {}×{}",
                    a.mask.as_ref().map(|p| p.display().to_string()).unwrap_or_default(),
                    m.width,
                    m.height,
                    reference.width,
                    reference.height
                ),
            ));
        }
    }
    let mask = if a.all_pixels {
        None
    } else {
        let mask = choose_mask(&reference, mask_img.as_ref());
        if mask.is_none() {
            note!(
                "note: {} has no `transmittance` layer, so every pixel is compared (sky and ground too); \
                 pass --mask with a reference render's EXR to compare the cloud's pixels only, or --all-pixels",
                a.reference.display()
            );
        }
        mask
    };
    // A --mask image without a `transmittance` layer masks by its own luminance.
    let described = match (&mask, &mask_img) {
        (None, _) => "all",
        (Some(_), Some(m)) if m.layer(crate::reference::TRANSMITTANCE_LAYER).is_none() => "mask luminance < 0.99",
        (Some(_), _) => "transmittance < 0.99",
    };
    let mask = if a.conditions.is_empty() {
        mask
    } else {
        let from;
        let (img, source) = match &a.where_from {
            Some(p) => {
                from = Image::read_exr(p)?;
                (&from, p.display().to_string())
            }
            None => (&full_reference, a.reference.display().to_string()),
        };
        if (img.width, img.height) != (reference.width, reference.height) {
            return Err(Error::invalid(
                source,
                "--where-from",
                format!(
                    "is {}×{} but the images are {}×{}; use a render of the same view and size",
                    img.width, img.height, reference.width, reference.height
                ),
            ));
        }
        narrow_mask(mask, img, &source, &a.conditions)?
    };
    let mut metrics = compare(&test, &reference, mask.as_deref())?;
    metrics.mask = std::iter::once(described.to_string())
        .chain(a.conditions.iter().map(|c| c.to_string()))
        .collect::<Vec<_>>()
        .join(" and ");
    if let Some(d) = &a.diff {
        write_diff_png(d, &test, &reference, mask.as_deref())?;
    }
    let json = |e: serde_json::Error| Error::format("<json>", e.to_string());
    let mut line = serde_json::to_string(&metrics).map_err(json)?;
    if a.budget {
        // Regions come from REF's own layers, whatever the test is judged against.
        let b = budget(&test, &full_reference, mask.as_deref(), a.ref_layer.as_deref())?;
        // Appended to the metrics' object so their key order stays as it was.
        line.pop();
        line += &format!(",\"budget\":{}}}", serde_json::to_string(&b).map_err(json)?);
    }
    super::console::print(&format!("{line}\n"))?;
    Ok(())
}

/// Refuse an image whose compared pixels hold a NaN or an infinity: the error sums would be NaN
/// (written as `null`) or, in the relative ones, skip the pixel and report a clean score.
fn refuse_non_finite(img: &Image, path: &Path, layer: Option<&str>) -> Result<()> {
    let Some((i, p)) = img.pixels.iter().enumerate().find(|(_, p)| !p.is_finite()) else {
        return Ok(());
    };
    let which = layer.map_or("RGB".to_string(), |l| format!("layer `{l}`"));
    Err(Error::format(
        path.display().to_string(),
        format!(
            "{which} pixel ({}, {}) is {p}: every metric needs finite values; render the image again \
             (cloudgi writes none that are not) or compare another layer",
            i % img.width as usize,
            i / img.width as usize
        ),
    ))
}
