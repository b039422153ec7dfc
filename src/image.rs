//! Images: linear HDR RGB f32 with optional named extra layers (AOVs), OpenEXR input/output,
//! and the tone-mapped PNG preview (exposure, a filmic curve, sRGB encoding).

use crate::error::{Error, Result};
use crate::math::Rgb;
use exr::prelude::{
    AnyChannel, AnyChannels, Encoding, FlatSamples, Image as ExrImage, Layer, LayerAttributes, ReadChannels, ReadLayers, WritableImage,
};
use std::path::Path;

/// A linear RGB image, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width (pixels).
    pub width: u32,
    /// Height (pixels).
    pub height: u32,
    /// Pixels, row-major, top row first. Radiance in W·m⁻²·sr⁻¹ per band.
    pub pixels: Vec<Rgb>,
    /// Extra layers written as `NAME.R`, `NAME.G`, `NAME.B` channels.
    pub layers: Vec<(String, Vec<Rgb>)>,
}

impl Image {
    /// Refuse, from its size alone, writing a `width`×`height` image of `layers` RGB layers
    /// whose caller holds `caller_bytes_per_value` bytes per value (on top of the 12 a value
    /// the image, its EXR channels and the encoded file take here) when this machine's available
    /// memory is smaller: an [`Error::Invalid`] of `source`'s `field`.
    ///
    /// ```
    /// use cloudgi::Image;
    /// assert!(Image::check_fits(64, 48, 2, 8, "images.exr", "images").is_ok());
    /// # #[cfg(target_os = "linux")]
    /// # {
    /// let err = Image::check_fits(u32::MAX, u32::MAX, 1, 4, "images.exr", "images").unwrap_err();
    /// assert!(err.to_string().contains("field `images`: a 4294967295×4294967295 image of 1 layer needs about"));
    /// # }
    /// ```
    pub fn check_fits(width: u32, height: u32, layers: u32, caller_bytes_per_value: u64, source: &str, field: &str) -> Result<()> {
        let values = width as u128 * height as u128 * 3 * layers as u128;
        let plural = if layers == 1 { "" } else { "s" };
        crate::io::check_memory(
            source,
            field,
            &format!("a {width}×{height} image of {layers} layer{plural} needs"),
            values.saturating_mul(caller_bytes_per_value as u128 + 12),
            "write it in tiles or at a lower resolution",
        )
    }

    /// A black image.
    pub fn new(width: u32, height: u32) -> Self {
        Image {
            width,
            height,
            pixels: vec![Rgb::ZERO; width as usize * height as usize],
            layers: Vec::new(),
        }
    }

    /// Pixel (x, y).
    #[inline]
    pub fn get(&self, x: u32, y: u32) -> Rgb {
        self.pixels[(y * self.width + x) as usize]
    }

    /// Add an extra layer (must have width × height pixels).
    pub fn add_layer(&mut self, name: &str, pixels: Vec<Rgb>) {
        debug_assert_eq!(pixels.len(), self.pixels.len());
        self.layers.push((name.to_string(), pixels));
    }

    /// A named extra layer.
    pub fn layer(&self, name: &str) -> Option<&[Rgb]> {
        self.layers.iter().find(|(n, _)| n == name).map(|(_, p)| p.as_slice())
    }

    /// Encode as OpenEXR (f32, lossless ZIP) bytes.
    pub fn to_exr_bytes(&self) -> Result<Vec<u8>> {
        let mut chans: Vec<AnyChannel<FlatSamples>> = Vec::new();
        let mut push = |prefix: &str, px: &[Rgb]| {
            for (c, name) in ["R", "G", "B"].iter().enumerate() {
                let full = if prefix.is_empty() {
                    name.to_string()
                } else {
                    format!("{prefix}.{name}")
                };
                chans.push(AnyChannel::new(full.as_str(), FlatSamples::F32(px.iter().map(|p| p[c]).collect())));
            }
        };
        push("", &self.pixels);
        for (n, px) in &self.layers {
            push(n, px);
        }
        let channels = AnyChannels::sort(chans.into());
        let layer = Layer::new(
            (self.width as usize, self.height as usize),
            LayerAttributes::default(),
            Encoding::SMALL_LOSSLESS,
            channels,
        );
        let img = ExrImage::from_layer(layer);
        let mut buf = std::io::Cursor::new(Vec::new());
        img.write()
            .to_buffered(&mut buf)
            .map_err(|e| Error::format("<exr encoder>", e.to_string()))?;
        Ok(buf.into_inner())
    }

    /// Write an OpenEXR file atomically.
    pub fn write_exr(&self, path: &Path) -> Result<()> {
        crate::io::write_atomic(path, &self.to_exr_bytes()?)
    }

    /// Read an OpenEXR file: channels R, G, B (a missing one reads as 0; a Y-only file is grey)
    /// and every `NAME.R/G/B` triple as a layer.
    pub fn read_exr(path: &Path) -> Result<Image> {
        let name = path.display().to_string();
        let bytes = crate::io::read_regular(path, "an OpenEXR image")?;
        check_exr_fits(&bytes, &name, crate::io::available_memory())?;
        let img = exr::prelude::read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .first_valid_layer()
            .all_attributes()
            .from_buffered(std::io::Cursor::new(bytes))
            .map_err(|e| match e {
                exr::error::Error::Io(io) => Error::io(path, io),
                other => Error::format(&name, format!("not a readable OpenEXR image: {other}")),
            })?;
        let layer = img.layer_data;
        let (w, h) = (layer.size.width(), layer.size.height());
        if w == 0 || h == 0 {
            return Err(Error::format(&name, "image has zero size"));
        }
        let get = |ch: &str| -> Option<Vec<f32>> {
            layer
                .channel_data
                .list
                .iter()
                .find(|c| c.name.to_string() == ch)
                .map(|c| match &c.sample_data {
                    FlatSamples::F16(v) => v.iter().map(|x| x.to_f32()).collect(),
                    FlatSamples::F32(v) => v.clone(),
                    FlatSamples::U32(v) => v.iter().map(|&x| x as f32).collect(),
                })
        };
        let triple = |prefix: &str| -> Option<Vec<Rgb>> {
            let n = |c: &str| {
                if prefix.is_empty() {
                    c.to_string()
                } else {
                    format!("{prefix}.{c}")
                }
            };
            let (r, g, b) = (get(&n("R")), get(&n("G")), get(&n("B")));
            if r.is_none() && g.is_none() && b.is_none() {
                return None;
            }
            let zero = vec![0.0; w * h];
            let (r, g, b) = (
                r.unwrap_or_else(|| zero.clone()),
                g.unwrap_or_else(|| zero.clone()),
                b.unwrap_or(zero),
            );
            Some((0..w * h).map(|i| Rgb::new(r[i], g[i], b[i])).collect())
        };
        let pixels = triple("")
            .or_else(|| get("Y").map(|y| y.into_iter().map(Rgb::splat).collect()))
            .ok_or_else(|| Error::format(&name, "has no R, G, B (or Y) channels"))?;
        let mut out = Image {
            width: w as u32,
            height: h as u32,
            pixels,
            layers: Vec::new(),
        };
        let mut prefixes: Vec<String> = layer
            .channel_data
            .list
            .iter()
            .filter_map(|c| c.name.to_string().rsplit_once('.').map(|(p, _)| p.to_string()))
            .collect();
        prefixes.dedup();
        for p in prefixes {
            if out.layer(&p).is_none() {
                if let Some(px) = triple(&p) {
                    out.layers.push((p, px));
                }
            }
        }
        Ok(out)
    }

    /// Tone-map to 8-bit sRGB: multiply by 2^exposure, apply the filmic curve, encode sRGB.
    pub fn to_srgb8(&self, exposure_stops: f32) -> Vec<u8> {
        let k = exposure_stops.exp2();
        self.pixels
            .iter()
            .flat_map(|p| (0..3).map(move |c| (srgb_encode(filmic(p[c] * k)) * 255.0 + 0.5) as u8))
            .collect()
    }

    /// Encode the tone-mapped preview as PNG bytes.
    pub fn to_png_bytes(&self, exposure_stops: f32) -> Result<Vec<u8>> {
        let mut buf = std::io::Cursor::new(Vec::new());
        image::write_buffer_with_format(
            &mut buf,
            &self.to_srgb8(exposure_stops),
            self.width,
            self.height,
            image::ExtendedColorType::Rgb8,
            image::ImageFormat::Png,
        )
        .map_err(|e| Error::format("<png encoder>", e.to_string()))?;
        Ok(buf.into_inner())
    }

    /// Write the tone-mapped PNG preview atomically.
    pub fn write_png(&self, path: &Path, exposure_stops: f32) -> Result<()> {
        crate::io::write_atomic(path, &self.to_png_bytes(exposure_stops)?)
    }
}

/// The pixels an OpenEXR file's header declares must fit in `available` bytes once decoded (its
/// samples, then their f32 copies here): a damaged or hostile header can declare billions of
/// pixels in a few bytes, which the decoder would allocate before finding the data missing.
fn check_exr_fits(bytes: &[u8], name: &str, available: Option<u64>) -> Result<()> {
    let meta = exr::meta::MetaData::read_from_buffered(bytes, false)
        .map_err(|e| Error::format(name, format!("not a readable OpenEXR image: {e}")))?;
    let Some(avail) = available else { return Ok(()) };
    for h in &meta.headers {
        let (w, ht, n) = (h.layer_size.width(), h.layer_size.height(), h.channels.list.len());
        let need = (w as u128 * ht as u128) * (h.channels.bytes_per_pixel as u128 + 8 * n as u128);
        if need > u128::from(avail) {
            return Err(Error::format(
                name,
                format!(
                    "its header declares a {w}×{ht} image of {n} channels, which needs about {} of memory to \
                     read but {} is available; a damaged header declares such sizes: check or re-export the file",
                    crate::io::format_bytes(need),
                    crate::io::format_bytes(u128::from(avail))
                ),
            ));
        }
    }
    Ok(())
}

/// Filmic tone curve (Narkowicz's ACES fit): maps [0, ∞) to [0, 1), 1.0 → 0.80.
#[inline]
pub fn filmic(x: f32) -> f32 {
    let x = x.max(0.0);
    if !x.is_finite() {
        return 1.0;
    }
    ((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14)).clamp(0.0, 1.0)
}

/// Linear → sRGB transfer function.
#[inline]
pub fn srgb_encode(x: f32) -> f32 {
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exr_round_trip_with_layers() {
        let mut img = Image::new(5, 3);
        for (i, p) in img.pixels.iter_mut().enumerate() {
            *p = Rgb::new(i as f32 * 0.5, 1e4 + i as f32, 1e-6 * i as f32);
        }
        img.add_layer("sun", (0..15).map(|i| Rgb::splat(i as f32)).collect());
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.exr");
        img.write_exr(&p).unwrap();
        let back = Image::read_exr(&p).unwrap();
        assert_eq!(back, img);
    }

    #[test]
    fn a_header_declaring_more_pixels_than_memory_is_refused_before_decoding() {
        let mut bytes = Image::new(2, 2).to_exr_bytes().unwrap();
        // dataWindow (box2i: x min, y min, x max, y max) → 200000×200000 pixels, 480 GB of samples.
        let key = b"dataWindow\0box2i\0";
        let at = bytes.windows(key.len()).position(|w| w == key).unwrap() + key.len() + 4;
        for (k, v) in [0i32, 0, 199_999, 199_999].iter().enumerate() {
            bytes[at + 4 * k..at + 4 * k + 4].copy_from_slice(&v.to_le_bytes());
        }
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("huge.exr");
        std::fs::write(&p, &bytes).unwrap();
        let e = Image::read_exr(&p).unwrap_err().to_string();
        assert!(e.contains("huge.exr") && e.contains("200000×200000") && e.contains("available"), "{e}");
        // The same header where the memory is there passes the check.
        check_exr_fits(&bytes, "huge.exr", Some(u64::MAX)).unwrap();
        check_exr_fits(&bytes, "huge.exr", None).unwrap();
    }
}
