//! The PNG preview's automatic exposure, a function of the image's pixels alone (so `cloudgi
//! tonemap` re-makes a render's PNG from its EXR): the [`PERCENTILE`] of the pixels' luminance is
//! mapped to [`TARGET`] (the filmic curve takes 1.0 to 0.80, sRGB 231 of 255), so the brightest
//! sunlit cloud sits just below white whatever the sun's irradiance, and the rest keeps its ratios.
//! The EXR is never scaled.

use crate::image::Image;
use crate::math::Rgb;

/// Share of the pixels at or below the luminance mapped to [`TARGET`] (unitless).
pub const PERCENTILE: f64 = 0.99;

/// Exposed luminance of the [`PERCENTILE`] pixel (unitless: radiance × 2^stops).
pub const TARGET: f32 = 1.0;

/// Rec. 709 luminance of a linear RGB radiance (W·m⁻²·sr⁻¹).
pub fn luminance(p: Rgb) -> f32 {
    0.2126 * p.x + 0.7152 * p.y + 0.0722 * p.z
}

/// The automatic exposure of `img` in stops: log2(TARGET / L), L the [`PERCENTILE`] of the finite
/// luminances (nearest rank); 0 for an image without a positive one (a black frame).
pub fn auto_stops(img: &Image) -> f32 {
    let mut lum: Vec<f32> = img.pixels.iter().map(|&p| luminance(p)).filter(|l| l.is_finite()).collect();
    if lum.is_empty() {
        return 0.0;
    }
    let rank = (PERCENTILE * (lum.len() - 1) as f64).round() as usize;
    let (_, l, _) = lum.select_nth_unstable_by(rank, f32::total_cmp);
    if *l > 0.0 {
        (TARGET / *l).log2()
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_percentile_pixel_lands_on_the_target() {
        let mut img = Image::new(100, 1);
        for (i, p) in img.pixels.iter_mut().enumerate() {
            *p = Rgb::splat(0.01 * (i + 1) as f32);
        }
        // Rank 98 of 0..=99 holds 0.99; a non-finite pixel is left out.
        img.pixels[0] = Rgb::splat(f32::NAN);
        let s = auto_stops(&img);
        let l = 0.01 * 99.0 * (s.exp2());
        assert!((l - TARGET).abs() < 1e-2, "{s} stops put the percentile at {l}");
        assert_eq!(auto_stops(&Image::new(4, 4)), 0.0, "a black frame keeps 0 stops");
        // Scaling the radiance by 2^k moves the exposure by −k stops.
        for p in img.pixels.iter_mut() {
            *p *= 8.0;
        }
        assert!((auto_stops(&img) - (s - 3.0)).abs() < 1e-5);
    }
}
