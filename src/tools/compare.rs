//! Image comparison against a reference render: error metrics over the pixels where the reference
//! shows cloud, and a false-colour difference image.
//!
//! **The mask.** A pixel counts when the transmittance of its camera ray through the cloud is
//! below [`CLOUD_T`] = 0.99, i.e. the cloud removes at least 1 % of the background there. The
//! transmittance comes from the `transmittance` layer that `render --method reference` writes into
//! its EXR (the exact transmittance of the pixel-centre ray, up to the ground). With
//! `--mask MASK.exr` it is read from that file instead (its `transmittance` layer, or else its
//! main channels' luminance). Without any, every pixel counts (the JSON then says `"mask": "all"`).
//! `--where LAYER<VALUE` (or `>`, repeatable; [`PixelCondition`]) narrows the mask to the pixels
//! where a layer's luminance (REF's, or `--where-from`'s) meets every threshold, e.g. the ground
//! in a shadow; the JSON's `mask` then lists the conditions after the mask they narrow.
//! Pure sky and ground pixels are left out because every method gets them (nearly) right and
//! they would dilute the numbers.
//!
//! **The metrics** (over masked pixels; luminance is Rec. 709 of linear RGB):
//! * `rmse`: root mean square of the per-band differences (W·m⁻²·sr⁻¹);
//! * `psnr`: 20·log10(peak / rmse) in dB, peak = largest reference band value in the mask;
//! * `mean_relative_error`: mean of |Y_test − Y_ref| / Y_ref over masked pixels with Y_ref > 0;
//! * `luminance_bias`: (mean Y_test − mean Y_ref) / mean Y_ref, the relative bias of the mean luminance.
//!
//! A relative metric has no value against a reference that is black where it is taken (no pixel,
//! or no block, with Y_ref > 0): it is `null` then, not 0, which would read as a perfect match.
//!
//! **Block means** (the scores every change of physics is judged by; per-pixel noise of a Monte
//! Carlo reference averages down 4× in a block): the image is tiled into [`BLOCK`]×[`BLOCK`]-pixel
//! blocks from its top-left corner (a partial block at the right or bottom edge is dropped); a
//! block counts when at least [`BLOCK_MIN_CLOUD`] = 12 of its 16 pixels are in the mask; its
//! value is the mean luminance of all 16 pixels.
//! * `block_mean_relative_error`: mean over counted blocks of |B_test − B_ref| / B_ref;
//! * `block_bias`: (Σ B_test − Σ B_ref) / Σ B_ref over counted blocks;
//! * `blocks`: how many blocks count (`null` metrics when none does);
//! * `reference_block_noise`: when REF has a `stderr` layer, the mean over counted blocks of
//!   σ(B_ref) / B_ref, σ(B_ref) = √(Σ σ_Y²) / 16 with σ_Y the luminance of the pixel's per-band
//!   standard errors (exact when the bands' noise is fully correlated, as with a grey albedo; an
//!   upper bound otherwise). It is the floor that the reference's own noise puts under
//!   `block_mean_relative_error` (roughly: a perfect method scores about 0.8× this).
//!
//! **The difference image** shows the relative luminance difference (Y_test − Y_ref)/Y_ref:
//! white where equal, towards red where the test is brighter and blue where it is darker,
//! saturating at ±[`DIFF_SCALE`] (25 %); pixels outside the mask are dark grey.

use crate::error::{Error, Result};
use crate::image::Image;
use crate::math::{luminance, Rgb};
use serde::Serialize;

/// Transmittance below which a pixel shows cloud.
pub const CLOUD_T: f32 = 0.99;
/// Relative difference at which the false colours saturate.
pub const DIFF_SCALE: f32 = 0.25;

/// The numbers `cloudgi compare` prints.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Metrics {
    /// Root mean square difference per band (W·m⁻²·sr⁻¹).
    pub rmse: f64,
    /// Peak signal-to-noise ratio (dB); `null` in JSON when the images are identical.
    pub psnr: f64,
    /// Mean relative luminance error (unitless); `None` when no reference pixel has luminance.
    pub mean_relative_error: Option<f64>,
    /// Relative bias of the mean luminance (unitless, signed); `None` when the reference is black.
    pub luminance_bias: Option<f64>,
    /// Number of pixels compared.
    pub pixels: usize,
    /// Where the mask came from: `transmittance < 0.99` or `all` (the CLI names a `--mask` image's
    /// luminance, `mask luminance < 0.99`, and appends its `--where` conditions, joined by ` and `).
    pub mask: String,
    /// Mean relative luminance error of 4×4 block means (unitless); `None` when no block counts
    /// or every counted block is black in the reference.
    pub block_mean_relative_error: Option<f64>,
    /// Relative bias of the summed 4×4 block means (unitless, signed); `None` when no block counts
    /// or the reference's blocks sum to 0.
    pub block_bias: Option<f64>,
    /// Number of 4×4 blocks compared.
    pub blocks: usize,
    /// The reference's own relative noise on its block means (unitless), from its `stderr` layer.
    pub reference_block_noise: Option<f64>,
}

/// Edge of a scoring block (pixels).
pub const BLOCK: usize = 4;
/// Pixels of a block (of [`BLOCK`]²) that must be in the mask for the block to count.
pub const BLOCK_MIN_CLOUD: usize = 12;

/// The pixel indices of each counted block (see the module notes), in row-major block order.
pub fn cloud_blocks(width: u32, height: u32, mask: Option<&[bool]>) -> Vec<[usize; BLOCK * BLOCK]> {
    let (w, h) = (width as usize, height as usize);
    let mut out = Vec::new();
    for by in 0..h / BLOCK {
        for bx in 0..w / BLOCK {
            let mut px = [0usize; BLOCK * BLOCK];
            for (k, p) in px.iter_mut().enumerate() {
                *p = (by * BLOCK + k / BLOCK) * w + bx * BLOCK + k % BLOCK;
            }
            if px.iter().filter(|&&i| mask.is_none_or(|m| m[i])).count() >= BLOCK_MIN_CLOUD {
                out.push(px);
            }
        }
    }
    out
}

/// Mean of `values` over each block.
pub fn block_means(values: &[f64], blocks: &[[usize; BLOCK * BLOCK]]) -> Vec<f64> {
    blocks
        .iter()
        .map(|b| b.iter().map(|&i| values[i]).sum::<f64>() / b.len() as f64)
        .collect()
}

/// (mean relative error over blocks with B_ref > 0, relative bias of the sums) of block means;
/// each `None` when no block has B_ref > 0 (a black reference has no error relative to it).
pub fn block_scores(test: &[f64], reference: &[f64]) -> (Option<f64>, Option<f64>) {
    let (mut rel, mut n) = (0f64, 0usize);
    for (t, r) in test.iter().zip(reference) {
        if *r > 0.0 {
            rel += (t - r).abs() / r;
            n += 1;
        }
    }
    let (st, sr) = (test.iter().sum::<f64>(), reference.iter().sum::<f64>());
    ((n > 0).then(|| rel / n as f64), (sr > 0.0).then(|| (st - sr) / sr))
}

/// Luminance of every pixel, in f64.
pub fn luminances(px: &[Rgb]) -> Vec<f64> {
    px.iter().map(|p| luminance(*p) as f64).collect()
}

/// Mean over `blocks` of σ(B) / B from a per-band standard-error layer (see the module notes).
pub fn block_noise(reference: &[Rgb], stderr: &[Rgb], blocks: &[[usize; BLOCK * BLOCK]]) -> Option<f64> {
    let y = luminances(reference);
    let (mut sum, mut n) = (0f64, 0usize);
    for b in blocks {
        let mean = b.iter().map(|&i| y[i]).sum::<f64>() / b.len() as f64;
        let var = b.iter().map(|&i| (luminance(stderr[i]) as f64).powi(2)).sum::<f64>();
        if mean > 0.0 {
            sum += var.sqrt() / b.len() as f64 / mean;
            n += 1;
        }
    }
    (n > 0).then(|| sum / n as f64)
}

/// The cloud mask from a transmittance layer: true where T < [`CLOUD_T`].
pub fn mask_from_transmittance(t: &[Rgb]) -> Vec<bool> {
    t.iter().map(|v| v.x < CLOUD_T).collect()
}

/// The mask to use for `reference` (its transmittance layer) or, when given, `mask_img`
/// (its transmittance layer, else its luminance). `None` means every pixel.
pub fn choose_mask(reference: &Image, mask_img: Option<&Image>) -> Option<Vec<bool>> {
    match mask_img {
        Some(m) => Some(match m.layer(crate::reference::TRANSMITTANCE_LAYER) {
            Some(t) => mask_from_transmittance(t),
            None => m.pixels.iter().map(|p| luminance(*p) < CLOUD_T).collect(),
        }),
        None => reference.layer(crate::reference::TRANSMITTANCE_LAYER).map(mask_from_transmittance),
    }
}

/// The name `--where` gives an image's main channels (its other names are its layers').
pub const IMAGE_LAYER: &str = "image";

/// The error for a layer `name` that `img` (read from `source`) lacks, asked for by `flag`: it
/// lists the layers the image has, or says it has none beyond its RGB image.
pub fn missing_layer(img: &Image, name: &str, source: &str, flag: &str) -> Error {
    let have = if img.layers.is_empty() {
        "it has no layers beyond its RGB image (`render --aov` writes the method's layers)".to_string()
    } else {
        let names: Vec<&str> = img.layers.iter().map(|l| l.0.as_str()).collect();
        format!("it has: {}", names.join(", "))
    };
    let image = if flag == "--where" {
        format!("; `{IMAGE_LAYER}` names its RGB image")
    } else {
        String::new()
    };
    Error::invalid(source, flag, format!("no layer `{name}`; {have}{image}"))
}

/// A condition on each pixel's luminance in one layer of an image: `LAYER<VALUE` or
/// `LAYER>VALUE` (`cloudgi compare --where`), LAYER one of the image's layers or [`IMAGE_LAYER`].
#[derive(Clone, Debug, PartialEq)]
pub struct PixelCondition {
    /// A layer name, or [`IMAGE_LAYER`].
    pub layer: String,
    /// True for `<`, false for `>`.
    pub below: bool,
    /// The threshold, in the layer's units (W·m⁻²·sr⁻¹ for light, unitless for transmittance).
    pub value: f64,
}

impl PixelCondition {
    /// Parse `LAYER<VALUE` or `LAYER>VALUE`; the error says what is wrong and the form expected.
    pub fn parse(text: &str) -> std::result::Result<Self, String> {
        let form = "write LAYER<VALUE or LAYER>VALUE, e.g. `image<0.15` or `light_ground>0`";
        let (at, below) = match (text.find('<'), text.find('>')) {
            (Some(i), None) => (i, true),
            (None, Some(i)) => (i, false),
            _ => return Err(format!("`{text}` needs exactly one `<` or `>`: {form}")),
        };
        let layer = text[..at].trim();
        if layer.is_empty() {
            return Err(format!("`{text}` names no layer: {form}"));
        }
        let value = text[at + 1..].trim();
        match value.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(PixelCondition {
                layer: layer.to_string(),
                below,
                value: v,
            }),
            _ => Err(format!("`{value}` in `{text}` is not a finite number: {form}")),
        }
    }

    /// Whether each pixel of `img` meets the condition; an error naming `source` and the layers
    /// it has when it lacks this one.
    pub fn select(&self, img: &Image, source: &str) -> Result<Vec<bool>> {
        let px = if self.layer == IMAGE_LAYER {
            &img.pixels[..]
        } else {
            img.layer(&self.layer)
                .ok_or_else(|| missing_layer(img, &self.layer, source, "--where"))?
        };
        Ok(px
            .iter()
            .map(|p| {
                let y = luminance(*p) as f64;
                if self.below {
                    y < self.value
                } else {
                    y > self.value
                }
            })
            .collect())
    }
}

impl std::fmt::Display for PixelCondition {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}{}{}", self.layer, if self.below { "<" } else { ">" }, self.value)
    }
}

/// `mask` (`None`: every pixel) narrowed to the pixels of `img` (read from `source`) that meet
/// every condition. Errors when a layer is missing or no pixel is left.
pub fn narrow_mask(mask: Option<Vec<bool>>, img: &Image, source: &str, conditions: &[PixelCondition]) -> Result<Option<Vec<bool>>> {
    if conditions.is_empty() {
        return Ok(mask);
    }
    let mut keep = mask.unwrap_or_else(|| vec![true; img.pixels.len()]);
    if keep.len() != img.pixels.len() {
        return Err(Error::invalid(source, "--where", "its size differs from the images; use a render of the same view and size"));
    }
    for c in conditions {
        for (k, ok) in keep.iter_mut().zip(c.select(img, source)?) {
            *k &= ok;
        }
    }
    if !keep.contains(&true) {
        let all: Vec<String> = conditions.iter().map(|c| c.to_string()).collect();
        return Err(Error::invalid(
            source,
            "--where",
            format!("no pixel meets {} inside the mask; loosen a threshold", all.join(" and ")),
        ));
    }
    Ok(Some(keep))
}

fn check_size(a: &Image, b: &Image, what: &str) -> Result<()> {
    if a.width != b.width || a.height != b.height {
        return Err(Error::invalid(
            "command line",
            what,
            format!(
                "image sizes differ: {}×{} vs {}×{}; render both at the same size",
                a.width, a.height, b.width, b.height
            ),
        ));
    }
    Ok(())
}

/// Compare `test` against `reference` over `mask` (None: all pixels). Errors if sizes differ or
/// the mask selects no pixel.
pub fn compare(test: &Image, reference: &Image, mask: Option<&[bool]>) -> Result<Metrics> {
    check_size(test, reference, "TEST.exr")?;
    if let Some(m) = mask {
        if m.len() != reference.pixels.len() {
            return Err(Error::invalid("command line", "--mask", "mask size differs from the images"));
        }
    }
    let sel = |i: usize| mask.is_none_or(|m| m[i]);
    let (mut se, mut peak, mut rel, mut nrel, mut yt, mut yr, mut n) = (0f64, 0f64, 0f64, 0usize, 0f64, 0f64, 0usize);
    for (i, (t, r)) in test.pixels.iter().zip(&reference.pixels).enumerate() {
        if !sel(i) {
            continue;
        }
        n += 1;
        let dd = (*t - *r).as_dvec3();
        se += dd.length_squared();
        peak = peak.max(r.max_element() as f64);
        let (lt, lr) = (luminance(*t) as f64, luminance(*r) as f64);
        yt += lt;
        yr += lr;
        if lr > 0.0 {
            rel += (lt - lr).abs() / lr;
            nrel += 1;
        }
    }
    if n == 0 {
        return Err(Error::invalid(
            "command line",
            "--mask",
            "no pixel shows cloud (transmittance < 0.99) in the mask; check the reference image or pass --mask",
        ));
    }
    let rmse = (se / (3 * n) as f64).sqrt();
    let psnr = if rmse > 0.0 { 20.0 * (peak / rmse).log10() } else { f64::INFINITY };
    let blocks = cloud_blocks(reference.width, reference.height, mask);
    let (block_mre, block_bias) = block_scores(
        &block_means(&luminances(&test.pixels), &blocks),
        &block_means(&luminances(&reference.pixels), &blocks),
    );
    let noise = reference
        .layer(crate::reference::STDERR_LAYER)
        .and_then(|se| block_noise(&reference.pixels, se, &blocks));
    Ok(Metrics {
        rmse,
        psnr,
        mean_relative_error: (nrel > 0).then(|| rel / nrel as f64),
        luminance_bias: (yr > 0.0).then(|| (yt - yr) / yr),
        pixels: n,
        mask: if mask.is_some() {
            "transmittance < 0.99".into()
        } else {
            "all".into()
        },
        block_mean_relative_error: block_mre,
        block_bias,
        blocks: blocks.len(),
        reference_block_noise: noise,
    })
}

/// How a fast method's `--aov` layers map to the reference's order/light layers: (part name, test
/// layers summed, reference layers summed). A part is scored when the test has all its layers.
/// `full`'s `background` is the sky and ground seen through the cloud (the reference's order 0);
/// `sun_single` the sun's single scattering (`order1_sun`); its `diffusion` and `low_density`
/// (the edge treatment, blended with the diffusion by density) together carry everything else:
/// the single scattering of sky and ground light and every order ≥ 2.
pub const PARTS: [(&str, &[&str], &[&str]); 3] = [
    ("background", &["background"], &["order0"]),
    ("sun_single", &["sun_single"], &["order1_sun"]),
    (
        "multiple",
        &["diffusion", "low_density"],
        &["order1_sky", "order1_ground", "order2", "order3_4", "order5_8", "order9plus"],
    ),
];

/// Reference layers whose share of the light [`budget`] reports per region.
pub const SHARE_LAYERS: [&str; 12] = [
    "order0",
    "order1",
    "order2",
    "order3_4",
    "order5_8",
    "order9plus",
    "light_sun",
    "light_sky",
    "light_ground",
    "order1_sun",
    "order1_sky",
    "order1_ground",
];

/// Block transmittance bounds of the `edges` region.
pub const EDGE_T: (f64, f64) = (0.05, 0.9);

/// The error of one part of the image over one region, in units of the reference's total.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct PartScore {
    /// `total` or a name from [`PARTS`].
    pub part: String,
    /// Σ B_ref,part / Σ B_ref over the region's blocks.
    pub reference_share: f64,
    /// Σ B_test,part / Σ B_ref.
    pub test_share: f64,
    /// Mean over blocks of |B_test,part − B_ref,part| / B_ref (B_ref: the block's total).
    pub error: f64,
    /// Σ (B_test,part − B_ref,part) / Σ B_ref: the parts' biases add up to the total's.
    pub bias: f64,
}

/// The budget of one region.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct RegionBudget {
    /// `all`, `lit`, `base`, `core`, `edges` or `haze` (see [`budget`]).
    pub region: String,
    /// Blocks in the region.
    pub blocks: usize,
    /// Share of the reference's light per layer of [`SHARE_LAYERS`] (present in REF), in order.
    pub reference: Vec<(String, f64)>,
    /// `total` first, then every scored part.
    pub parts: Vec<PartScore>,
}

/// Luminance of the sum of `names` (`None` if any is missing).
fn layers_luminance(img: &Image, names: &[&str]) -> Option<Vec<f64>> {
    let mut out = vec![0f64; img.pixels.len()];
    for n in names {
        for (o, p) in out.iter_mut().zip(img.layer(n)?) {
            *o += luminance(*p) as f64;
        }
    }
    Some(out)
}

/// The error budget of `test` against `reference` over the cloud blocks of `mask`, by part and by
/// region. Regions, from the reference's own layers on each counted block (B = block mean):
/// * `edges`: block transmittance (REF's `transmittance` layer) in [0.05, 0.9];
/// * `haze`: transmittance above 0.9 (thin wisps; the mask stops at 0.99);
/// * the opaque blocks (transmittance below 0.05) split three ways: `lit` where the sun's
///   single scattering is positive and at least its cloud-wide share (B(order1_sun)/B ≥
///   Σ order1_sun / Σ total over all counted blocks: the sunlit surface the camera sees), else
///   `base` where the ground-reflected light is positive and at least its cloud-wide share
///   (B(light_ground)/B ≥ Σ light_ground / Σ total: the underside the ground lights), else `core`.
///
/// With `ref_layer` (e.g. `light_sun`, for a test rendered with only the sun on and a black
/// ground) the test's image is judged against that layer of REF instead of REF's image, shares and
/// errors are in units of that layer, and no AOV part is scored; the regions stay REF's.
///
/// Errors when REF lacks the order/light layers or the transmittance layer (render it with
/// `--method reference`), or when no block counts.
pub fn budget(test: &Image, reference: &Image, mask: Option<&[bool]>, ref_layer: Option<&str>) -> Result<Vec<RegionBudget>> {
    check_size(test, reference, "TEST.exr")?;
    let missing = |what: &str| {
        Error::invalid(
            "command line",
            "REF.exr",
            format!("has no `{what}` layer; --budget needs a reference rendered by this version of `--method reference`"),
        )
    };
    let blocks = cloud_blocks(reference.width, reference.height, mask);
    if blocks.is_empty() {
        return Err(Error::invalid("command line", "--budget", "no 4×4 block shows cloud"));
    }
    let bm = |v: &[f64]| block_means(v, &blocks);
    let ref_total = bm(&luminances(&reference.pixels));
    let test_total = bm(&luminances(&test.pixels));
    let t_layer = reference
        .layer(crate::reference::TRANSMITTANCE_LAYER)
        .ok_or_else(|| missing(crate::reference::TRANSMITTANCE_LAYER))?;
    let t_block = bm(&t_layer.iter().map(|p| p.x as f64).collect::<Vec<_>>());
    let ref_blocks = |n: &str| layers_luminance(reference, &[n]).map(|v| bm(&v)).ok_or_else(|| missing(n));
    let (sun1, ground) = (ref_blocks("order1_sun")?, ref_blocks("light_ground")?);
    let sum = |v: &[f64]| v.iter().sum::<f64>();
    let (f_sun1, f_ground) = (sum(&sun1) / sum(&ref_total), sum(&ground) / sum(&ref_total));
    let region_of = |b: usize| -> &'static str {
        let (t, y) = (t_block[b], ref_total[b]);
        if t > EDGE_T.1 {
            "haze"
        } else if t >= EDGE_T.0 {
            "edges"
        } else if sun1[b] > 0.0 && y > 0.0 && sun1[b] / y >= f_sun1 {
            "lit"
        } else if ground[b] > 0.0 && y > 0.0 && ground[b] / y >= f_ground {
            "base"
        } else {
            "core"
        }
    };
    let shares: Vec<(&str, Vec<f64>)> = SHARE_LAYERS.iter().filter_map(|n| ref_blocks(n).ok().map(|v| (*n, v))).collect();
    // (part, test block means, reference block means) for the total and every scored part.
    // What the test is judged against: REF's image, or one of its layers.
    let ref_judged = match ref_layer {
        Some(n) => ref_blocks(n)?,
        None => ref_total.clone(),
    };
    let mut parts = vec![("total", test_total.clone(), ref_judged.clone())];
    for (name, tl, rl) in PARTS.iter().filter(|_| ref_layer.is_none()) {
        if let Some(t) = layers_luminance(test, tl) {
            let r = layers_luminance(reference, rl).ok_or_else(|| missing(rl[0]))?;
            parts.push((name, bm(&t), bm(&r)));
        }
    }
    let mut out = Vec::new();
    for region in ["all", "lit", "base", "core", "edges", "haze"] {
        let sel: Vec<usize> = (0..blocks.len()).filter(|&b| region == "all" || region_of(b) == region).collect();
        if sel.is_empty() {
            continue;
        }
        let total: f64 = sel.iter().map(|&b| ref_judged[b]).sum();
        let share = |v: &[f64]| {
            if total > 0.0 {
                sel.iter().map(|&b| v[b]).sum::<f64>() / total
            } else {
                0.0
            }
        };
        let score = |(name, t, r): &(&str, Vec<f64>, Vec<f64>)| {
            let err: f64 = sel
                .iter()
                .filter(|&&b| ref_judged[b] > 0.0)
                .map(|&b| (t[b] - r[b]).abs() / ref_judged[b])
                .sum::<f64>()
                / sel.len() as f64;
            PartScore {
                part: name.to_string(),
                reference_share: share(r),
                test_share: share(t),
                error: err,
                bias: share(t) - share(r),
            }
        };
        out.push(RegionBudget {
            region: region.into(),
            blocks: sel.len(),
            reference: shares.iter().map(|(n, v)| (n.to_string(), share(v))).collect(),
            parts: parts.iter().map(score).collect(),
        });
    }
    Ok(out)
}

/// False-colour map of a relative difference: white at 0, red for positive, blue for negative.
#[inline]
pub fn diverging(rel: f32) -> [u8; 3] {
    let x = (rel / DIFF_SCALE).clamp(-1.0, 1.0);
    let fade = ((1.0 - x.abs()) * 255.0 + 0.5) as u8;
    if x >= 0.0 {
        [255, fade, fade]
    } else {
        [fade, fade, 255]
    }
}

/// The difference image as 8-bit RGB (row-major, top row first).
pub fn diff_rgb8(test: &Image, reference: &Image, mask: Option<&[bool]>) -> Result<Vec<u8>> {
    check_size(test, reference, "TEST.exr")?;
    let mut out = Vec::with_capacity(test.pixels.len() * 3);
    for (i, (t, r)) in test.pixels.iter().zip(&reference.pixels).enumerate() {
        if !mask.is_none_or(|m| m[i]) {
            out.extend_from_slice(&[40, 40, 40]);
            continue;
        }
        let (lt, lr) = (luminance(*t), luminance(*r));
        let rel = if lr > 0.0 {
            (lt - lr) / lr
        } else if lt > 0.0 {
            1.0
        } else {
            0.0
        };
        out.extend_from_slice(&diverging(rel));
    }
    Ok(out)
}

/// Write the difference image as a PNG.
pub fn write_diff_png(path: &std::path::Path, test: &Image, reference: &Image, mask: Option<&[bool]>) -> Result<()> {
    let px = diff_rgb8(test, reference, mask)?;
    let mut buf = std::io::Cursor::new(Vec::new());
    image::write_buffer_with_format(
        &mut buf,
        &px,
        test.width,
        test.height,
        image::ExtendedColorType::Rgb8,
        image::ImageFormat::Png,
    )
    .map_err(|e| Error::format("<png encoder>", e.to_string()))?;
    crate::io::write_atomic(path, &buf.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn img(vals: &[f32]) -> Image {
        let mut i = Image::new(vals.len() as u32, 1);
        i.pixels = vals.iter().map(|&v| Rgb::splat(v)).collect();
        i
    }

    #[test]
    fn pixel_conditions_parse_and_refuse_bad_text() {
        let c = PixelCondition::parse("image<0.15").unwrap();
        assert_eq!((c.layer.as_str(), c.below, c.value), ("image", true, 0.15));
        let c = PixelCondition::parse(" light_ground > 0 ").unwrap();
        assert_eq!((c.layer.as_str(), c.below, c.value), ("light_ground", false, 0.0));
        assert_eq!(c.to_string(), "light_ground>0");
        for bad in ["image", "<0.1", "image<", "image<x", "a<1>2", "image<inf", "image<NaN"] {
            let e = PixelCondition::parse(bad).unwrap_err();
            assert!(e.contains("LAYER<VALUE"), "{bad}: {e}");
        }
    }

    #[test]
    fn conditions_narrow_the_mask_to_the_pixels_meeting_all_of_them() {
        // Four pixels: the ground's transmittance 1, one cloud pixel (0.5); their luminances.
        let mut i = img(&[0.1, 0.3, 0.1, 0.05]);
        i.add_layer("transmittance", [1.0, 1.0, 0.5, 1.0].map(Rgb::splat).to_vec());
        let ground = PixelCondition::parse("transmittance>0.99").unwrap();
        let dark = PixelCondition::parse("image<0.15").unwrap();
        let got = narrow_mask(None, &i, "r.exr", &[ground.clone(), dark.clone()]).unwrap();
        assert_eq!(got, Some(vec![true, false, false, true]));
        let got = narrow_mask(Some(vec![false, true, true, true]), &i, "r.exr", std::slice::from_ref(&dark)).unwrap();
        assert_eq!(got, Some(vec![false, false, true, true]));
        assert_eq!(narrow_mask(None, &i, "r.exr", &[]).unwrap(), None);
        // The scores follow the narrowed mask: only its two pixels count.
        let t = img(&[0.2, 0.3, 0.1, 0.1]);
        let m = compare(&t, &i, got.as_deref()).unwrap();
        assert_eq!(m.pixels, 2);
        assert!((m.luminance_bias.unwrap() - (0.2 / 0.15 - 1.0)).abs() < 1e-6, "{m:?}");
        // Nothing left, or a layer the image lacks: an error naming --where and the fix.
        let e = narrow_mask(Some(vec![false, true, false, false]), &i, "r.exr", &[dark]).unwrap_err().to_string();
        assert!(e.contains("--where") && e.contains("image<0.15") && e.contains("loosen"), "{e}");
        let e = narrow_mask(None, &i, "r.exr", &[PixelCondition::parse("light_sun<1").unwrap()]).unwrap_err().to_string();
        assert!(e.contains("r.exr") && e.contains("light_sun") && e.contains("transmittance"), "{e}");
    }

    #[test]
    fn identical_images_have_zero_error() {
        let a = img(&[1.0, 2.0, 0.5]);
        let m = compare(&a, &a, None).unwrap();
        assert_eq!(m.rmse, 0.0);
        assert!(m.psnr.is_infinite());
        assert_eq!(m.mean_relative_error, Some(0.0));
        assert_eq!(m.luminance_bias, Some(0.0));
        assert_eq!(m.mask, "all");
    }

    #[test]
    fn a_black_reference_has_no_relative_error() {
        // Nothing to be relative to: the relative metrics are unknown (null), never a perfect 0;
        // the absolute ones still say how far the test is.
        let black = flat(8, 4, 0.0);
        let lit = flat(8, 4, 0.5);
        let m = compare(&lit, &black, None).unwrap();
        assert_eq!((m.mean_relative_error, m.luminance_bias), (None, None), "{m:?}");
        assert_eq!((m.block_mean_relative_error, m.block_bias, m.blocks), (None, None, 2), "{m:?}");
        assert!((m.rmse - 0.5).abs() < 1e-9, "{m:?}");
        let json = serde_json::to_string(&m).unwrap();
        assert!(json.contains("\"mean_relative_error\":null") && json.contains("\"block_bias\":null"), "{json}");
        // Against a lit reference the same call scores.
        let m = compare(&black, &lit, None).unwrap();
        assert_eq!((m.mean_relative_error, m.luminance_bias, m.block_bias), (Some(1.0), Some(-1.0), Some(-1.0)));
    }

    #[test]
    fn scaled_image_has_known_errors() {
        let r = img(&[1.0, 2.0, 4.0, 100.0]);
        let t = img(&[1.1, 2.2, 4.4, 0.0]);
        // The last pixel is outside the mask and must not count.
        let mask = [true, true, true, false];
        let m = compare(&t, &r, Some(&mask)).unwrap();
        assert!((m.mean_relative_error.unwrap() - 0.1).abs() < 1e-6, "{m:?}");
        assert!((m.luminance_bias.unwrap() - 0.1).abs() < 1e-6, "{m:?}");
        let rmse = ((0.01f64 + 0.04 + 0.16) / 3.0).sqrt();
        assert!((m.rmse - rmse).abs() < 1e-6, "{m:?}");
        assert!((m.psnr - 20.0 * (4.0 / rmse).log10()).abs() < 1e-4);
        assert_eq!(m.pixels, 3);
    }

    /// A w×h image of constant value `v`.
    fn flat(w: u32, h: u32, v: f32) -> Image {
        let mut i = Image::new(w, h);
        i.pixels = vec![Rgb::splat(v); (w * h) as usize];
        i
    }

    #[test]
    fn block_means_with_known_answers() {
        // 8×4: two blocks. Reference 1 everywhere; the test is 2 on the left block's pixels in
        // a checkerboard (block mean 1.5) and alternates 0 / 2 on the right (block mean 1: the
        // per-pixel error is 100 %, the block error 0).
        let r = flat(8, 4, 1.0);
        let mut t = flat(8, 4, 1.0);
        for y in 0..4 {
            for x in 0..8 {
                let odd = (x + y) % 2 == 1;
                t.pixels[y * 8 + x] = Rgb::splat(match (x < 4, odd) {
                    (true, true) => 2.0,
                    (true, false) => 1.0,
                    (false, true) => 2.0,
                    (false, false) => 0.0,
                });
            }
        }
        let m = compare(&t, &r, None).unwrap();
        assert_eq!(m.blocks, 2);
        assert!((m.block_mean_relative_error.unwrap() - 0.25).abs() < 1e-12, "{m:?}");
        assert!((m.block_bias.unwrap() - 0.25).abs() < 1e-12, "{m:?}");
        assert!((m.mean_relative_error.unwrap() - 0.75).abs() < 1e-6, "{m:?}");
        // A block counts with 12 of 16 pixels in the mask, not with 11; partial blocks never.
        let mut mask = vec![true; 32];
        for i in [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11].map(|k| 4 + (k / 4) * 8 + k % 4) {
            mask[i] = false; // right block: 12 of 16 out
        }
        assert_eq!(cloud_blocks(8, 4, Some(&mask)).len(), 1);
        mask[4] = true; // left block untouched, right block 5 in
        mask[12] = true;
        mask[20] = true;
        mask[21] = true;
        mask[22] = true;
        mask[23] = true;
        mask[13] = true;
        assert_eq!(cloud_blocks(8, 4, Some(&mask)).len(), 1, "11 of 16 is not enough");
        mask[14] = true;
        assert_eq!(cloud_blocks(8, 4, Some(&mask)).len(), 2, "12 of 16 is enough");
        assert_eq!(cloud_blocks(9, 5, None).len(), 2);
        // Reference noise: σ = 0.4 per pixel on B = 1 gives σ(B) = √16·0.4/16 = 0.1.
        let mut rn = r.clone();
        rn.add_layer(crate::reference::STDERR_LAYER, vec![Rgb::splat(0.4); 32]);
        let m = compare(&t, &rn, None).unwrap();
        assert!((m.reference_block_noise.unwrap() - 0.1).abs() < 1e-6, "{m:?}");
        assert!(m.block_mean_relative_error.is_some() && compare(&t, &r, None).unwrap().reference_block_noise.is_none());
    }

    #[test]
    fn budget_splits_the_error_by_part_and_region() {
        // Two blocks of the same light: the left opaque (T = 0), the right an edge (T = 0.5).
        let mut r = flat(8, 4, 1.0);
        let t_layer = (0..32).map(|i| Rgb::splat(if i % 8 < 4 { 0.0 } else { 0.5 })).collect();
        r.add_layer(crate::reference::TRANSMITTANCE_LAYER, t_layer);
        for (n, v) in [
            ("order0", 0.2),
            ("order1_sun", 0.1),
            ("order1_sky", 0.1),
            ("order1_ground", 0.0),
            ("order2", 0.6),
            ("order3_4", 0.0),
            ("order5_8", 0.0),
            ("order9plus", 0.0),
            ("light_ground", 0.0),
        ] {
            r.add_layer(n, vec![Rgb::splat(v); 32]);
        }
        // The test gets background and sun exactly and 0.4 of the 0.7 of the rest.
        let mut t = flat(8, 4, 0.7);
        for (n, v) in [("background", 0.2), ("sun_single", 0.1), ("diffusion", 0.3), ("low_density", 0.1)] {
            t.add_layer(n, vec![Rgb::splat(v); 32]);
        }
        let b = budget(&t, &r, None, None).unwrap();
        let names: Vec<&str> = b.iter().map(|x| x.region.as_str()).collect();
        // The left block's sun share equals the cloud-wide one (≥ counts): lit.
        assert_eq!(names, ["all", "lit", "edges"]);
        for region in &b {
            let p = |n: &str| region.parts.iter().find(|x| x.part == n).unwrap().clone();
            let close = |a: f64, b: f64| (a - b).abs() < 1e-6;
            assert!(close(p("total").bias, -0.3) && close(p("total").error, 0.3), "{region:?}");
            assert!(close(p("multiple").bias, -0.3) && close(p("multiple").reference_share, 0.7));
            assert!(close(p("background").error, 0.0) && close(p("sun_single").bias, 0.0));
            let order2 = region.reference.iter().find(|x| x.0 == "order2").unwrap().1;
            assert!(close(order2, 0.6));
        }
        // Against one layer: shares and errors in units of that layer, no parts.
        let b = budget(&t, &r, None, Some("order2")).unwrap();
        let total = &b[0].parts[0];
        assert_eq!(b[0].parts.len(), 1);
        assert!((total.bias - 1.0 / 6.0).abs() < 1e-6 && (total.reference_share - 1.0).abs() < 1e-9);
        let order2 = b[0].reference.iter().find(|x| x.0 == "order2").unwrap().1;
        assert!((order2 - 1.0).abs() < 1e-6, "order2 is the whole of itself");
        // A reference without the order layers is refused with a fix.
        let e = budget(&t, &flat(8, 4, 1.0), None, None).unwrap_err().to_string();
        assert!(e.contains("REF.exr") && e.contains("--method reference"), "{e}");
    }

    #[test]
    fn mask_and_colours() {
        let mut r = img(&[1.0, 1.0, 1.0]);
        r.add_layer("transmittance", vec![Rgb::splat(0.5), Rgb::splat(0.995), Rgb::splat(0.0)]);
        let mask = choose_mask(&r, None).unwrap();
        assert_eq!(mask, vec![true, false, true]);
        let t = img(&[2.0, 1.0, 0.5]);
        let px = diff_rgb8(&t, &r, Some(&mask)).unwrap();
        assert_eq!(&px[0..3], &[255, 0, 0]); // +100 % saturates red
        assert_eq!(&px[3..6], &[40, 40, 40]); // outside the mask
        assert_eq!(&px[6..9], &[0, 0, 255]); // −50 % saturates blue
        assert_eq!(diverging(0.0), [255, 255, 255]);
        let empty = vec![false; 3];
        assert!(compare(&t, &r, Some(&empty)).is_err());
        assert!(compare(&img(&[1.0]), &r, None).is_err());
    }
}
