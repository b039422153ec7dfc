//! Image comparison against a reference render: error metrics over the pixels where the reference
//! shows cloud, and a false-colour difference image.
//!
//! **The mask.** A pixel counts when the transmittance of its camera ray through the cloud is
//! below [`CLOUD_T`] = 0.99, i.e. the cloud removes at least 1 % of the background there. The
//! transmittance comes from the `transmittance` layer that `render --method reference` writes into
//! its EXR (the exact transmittance of the pixel-centre ray, up to the ground). With
//! `--mask MASK.exr` it is read from that file instead (its `transmittance` layer, or else its
//! main channels' luminance). Without any, every pixel counts (the JSON then says `"mask": "all"`).
//! Pure sky and ground pixels are left out because every method gets them (nearly) right and
//! they would dilute the numbers.
//!
//! **The metrics** (over masked pixels; luminance is Rec. 709 of linear RGB):
//! * `rmse`: root mean square of the per-band differences (W·m⁻²·sr⁻¹);
//! * `psnr`: 20·log10(peak / rmse) in dB, peak = largest reference band value in the mask;
//! * `mean_relative_error`: mean of |Y_test − Y_ref| / Y_ref over masked pixels with Y_ref > 0;
//! * `luminance_bias`: (mean Y_test − mean Y_ref) / mean Y_ref, the relative bias of the mean luminance.
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
    /// Mean relative luminance error (unitless).
    pub mean_relative_error: f64,
    /// Relative bias of the mean luminance (unitless, signed).
    pub luminance_bias: f64,
    /// Number of pixels compared.
    pub pixels: usize,
    /// Where the mask came from: `transmittance < 0.99` or `all`.
    pub mask: String,
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
    let sel = |i: usize| mask.map_or(true, |m| m[i]);
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
    Ok(Metrics {
        rmse,
        psnr,
        mean_relative_error: if nrel > 0 { rel / nrel as f64 } else { 0.0 },
        luminance_bias: if yr > 0.0 { (yt - yr) / yr } else { 0.0 },
        pixels: n,
        mask: if mask.is_some() {
            "transmittance < 0.99".into()
        } else {
            "all".into()
        },
    })
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
        if !mask.map_or(true, |m| m[i]) {
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
    fn identical_images_have_zero_error() {
        let a = img(&[1.0, 2.0, 0.5]);
        let m = compare(&a, &a, None).unwrap();
        assert_eq!(m.rmse, 0.0);
        assert!(m.psnr.is_infinite());
        assert_eq!(m.mean_relative_error, 0.0);
        assert_eq!(m.luminance_bias, 0.0);
        assert_eq!(m.mask, "all");
    }

    #[test]
    fn scaled_image_has_known_errors() {
        let r = img(&[1.0, 2.0, 4.0, 100.0]);
        let t = img(&[1.1, 2.2, 4.4, 0.0]);
        // The last pixel is outside the mask and must not count.
        let mask = [true, true, true, false];
        let m = compare(&t, &r, Some(&mask)).unwrap();
        assert!((m.mean_relative_error - 0.1).abs() < 1e-6, "{m:?}");
        assert!((m.luminance_bias - 0.1).abs() < 1e-6, "{m:?}");
        let rmse = ((0.01f64 + 0.04 + 0.16) / 3.0).sqrt();
        assert!((m.rmse - rmse).abs() < 1e-6, "{m:?}");
        assert!((m.psnr - 20.0 * (4.0 / rmse).log10()).abs() < 1e-4);
        assert_eq!(m.pixels, 3);
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
