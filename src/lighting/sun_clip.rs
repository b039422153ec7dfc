//! A clipped sun in an environment map: its brightest pixels cut at one value (a format's or a
//! camera's ceiling: 1.0, half float's 65504, a sensor's white), so the light
//! [`EnvMap::extract_sun`] takes from it is a lower bound. Found per band as a plateau on the
//! sun's top that its surroundings rise into (docs/sky.md, "A clipped sun").

use super::envmap::{neighbourhood, row_solid_angle, EnvMap};
use crate::math::Rgb;
use std::collections::BTreeSet;

/// The fewest pixels at a band's maximum that make a plateau: more than the ties of an unclipped
/// peak (one centred on a pixel corner ties four by symmetry).
pub const MIN_CLIPPED_PIXELS: usize = 5;

/// The least median, over the pixels two out from a plateau, of a band's value over the
/// plateau's, for the plateau to be a clip: the top of a profile that still rises into it.
/// A drawn disc (its edge anti-aliased or not) falls to its sky within two pixels (a sun is over
/// 100 times the map's mean); a clipped sun and its glare do not: a Gaussian of σ = 2 pixels
/// clipped at 6.5·10⁻² to 10⁻⁴ of its peak holds 0.018 to 0.08 there, σ = 4 pixels 0.12 to 0.29.
/// A sun clipped with no such rise (σ = 1 pixel: 0.001) is a drawn disc to this test.
pub const RISE_TWO_PIXELS_OUT: f32 = 0.01;

/// A sun's clipped top.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SunClip {
    /// The value its clipped pixels hold per band (W·m⁻²·sr⁻¹); 0 in a band not clipped.
    pub ceiling: Rgb,
    /// How many of the sun's pixels hold a ceiling in some band.
    pub pixels: usize,
    /// Their solid angle (sr).
    pub solid_angle: f64,
}

impl EnvMap {
    /// The clip on the sun made of pixels `sun` (indices, row-major), if its top is one.
    pub fn sun_clip(&self, sun: &[usize]) -> Option<SunClip> {
        let mut ceiling = [0.0f32; 3];
        let mut clipped = BTreeSet::new();
        for (band, c) in ceiling.iter_mut().enumerate() {
            let value = |k: usize| self.pixels[k][band];
            let top = sun.iter().map(|&k| value(k)).fold(0.0, f32::max);
            // A clip writes one value: equality, not nearness.
            let plateau: BTreeSet<usize> = sun.iter().copied().filter(|&k| value(k) == top).collect();
            if top > 0.0 && plateau.len() >= MIN_CLIPPED_PIXELS && self.rises_into(&plateau, band, top) {
                *c = top;
                clipped.extend(plateau);
            }
        }
        let solid_angle = clipped.iter().map(|&k| row_solid_angle(k / self.width, self.height, self.width)).sum();
        (!clipped.is_empty()).then_some(SunClip {
            ceiling: Rgb::from_array(ceiling),
            pixels: clipped.len(),
            solid_angle,
        })
    }

    /// The map's largest value in any band and how many pixels hold it exactly in that band, if
    /// at least [`MIN_CLIPPED_PIXELS`] do: the mark of a map cut at a ceiling, where a sun too
    /// dim to find (its pixels under 100 times the mean) may have been clipped.
    pub fn plateau_at_max(&self) -> Option<(f32, usize)> {
        let top = self.pixels.iter().map(|p| p.max_element()).fold(0.0, f32::max);
        let band = (0..3).find(|&b| self.pixels.iter().any(|p| p[b] == top))?;
        let count = self.pixels.iter().filter(|p| p[band] == top).count();
        (top > 0.0 && count >= MIN_CLIPPED_PIXELS).then_some((top, count))
    }

    /// Whether the pixels two out from `plateau` (8-connected) hold, in `band`, a median over
    /// [`RISE_TWO_PIXELS_OUT`] times `top`.
    fn rises_into(&self, plateau: &BTreeSet<usize>, band: usize, top: f32) -> bool {
        let (w, h) = (self.width, self.height);
        let around = |set: &BTreeSet<usize>| -> BTreeSet<usize> { set.iter().flat_map(|&k| neighbourhood(k, w, h)).collect() };
        let one_out = around(plateau);
        let mut two_out: Vec<f32> = around(&one_out).difference(&one_out).map(|&k| self.pixels[k][band]).collect();
        if two_out.is_empty() {
            return false;
        }
        two_out.sort_by(f32::total_cmp);
        two_out[two_out.len() / 2] >= RISE_TWO_PIXELS_OUT * top
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::map_sun::ExtractedSun;

    const W: usize = 2048;
    const H: usize = 1024;
    /// The sun's centre (pixel units; off the pixel grid so no two pixels tie by symmetry).
    const CENTRE: (f64, f64) = (600.3, 300.6);

    /// A 2048×1024 map of 0.5 with `sun(r)` added at each pixel, r in pixels from [`CENTRE`],
    /// each value cut at `ceiling`.
    fn map_with(sun: impl Fn(f64) -> f64, ceiling: f32) -> EnvMap {
        let px = (0..W * H)
            .map(|k| {
                let (di, dj) = ((k % W) as f64 + 0.5 - CENTRE.0, (k / W) as f64 + 0.5 - CENTRE.1);
                Rgb::splat((0.5 + sun((di * di + dj * dj).sqrt())) as f32).min(Rgb::splat(ceiling))
            })
            .collect();
        EnvMap::new(W, H, px)
    }

    fn gaussian(peak: f64, sigma_px: f64) -> impl Fn(f64) -> f64 {
        move |r| peak * (-r * r / (2.0 * sigma_px * sigma_px)).exp()
    }

    fn extracted(m: &EnvMap) -> ExtractedSun {
        m.extract_sun().expect("a sun")
    }

    #[test]
    fn an_unclipped_sun_is_not_called_clipped() {
        for sigma in [0.5, 1.0, 2.0, 4.0] {
            assert_eq!(extracted(&map_with(gaussian(1e6, sigma), f32::MAX)).clip, None, "σ {sigma} px");
        }
        // A drawn disc 3 pixels in radius: its top is flat, its edge hard or anti-aliased
        // (coverage by the distance to its rim).
        let hard = |r: f64| if r < 3.0 { 1e6 } else { 0.0 };
        let antialiased = |r: f64| 1e6 * (3.5 - r).clamp(0.0, 1.0);
        assert_eq!(extracted(&map_with(hard, f32::MAX)).clip, None);
        assert_eq!(extracted(&map_with(antialiased, f32::MAX)).clip, None);
        // On a glare of its own (a hundredth of it at the centre, falling over 5 pixels: 0.4 % of
        // the disc two pixels out).
        let glare = |r: f64| antialiased(r).max(1e4 * (-r / 5.0).exp());
        assert_eq!(extracted(&map_with(glare, f32::MAX)).clip, None);
    }

    #[test]
    fn a_clipped_sun_is_found_at_its_ceiling_with_its_pixels() {
        for sigma in [2.0, 4.0] {
            for ceiling in [65504.0f32, 1e4, 1e3, 100.0] {
                let m = map_with(gaussian(1e6, sigma), ceiling);
                let clip = extracted(&m).clip.unwrap_or_else(|| panic!("σ {sigma} px, clipped at {ceiling}"));
                assert_eq!(clip.ceiling, Rgb::splat(ceiling));
                assert_eq!(clip.pixels, m.pixels.iter().filter(|p| p.x == ceiling).count());
            }
        }
        // One band cut: only it is named.
        let mut m = map_with(gaussian(1e6, 3.0), f32::MAX);
        m.pixels.iter_mut().for_each(|p| p.x = p.x.min(5e3));
        let clip = extracted(&m).clip.expect("red clipped");
        assert_eq!((clip.ceiling.x, clip.ceiling.y, clip.ceiling.z), (5e3, 0.0, 0.0));
    }

    #[test]
    fn a_clipped_white_sky_with_no_sun_is_no_clipped_sun() {
        // A sky brightening towards its top, cut at 1: a plateau, but nothing over 100 times
        // the mean to be a sun.
        let px = (0..W * H).map(|k| Rgb::splat((3.0 * (1.0 - (k / W) as f32 / H as f32)).min(1.0))).collect();
        assert!(EnvMap::new(W, H, px).extract_sun().is_err());
        // A hard disc on it, unclipped: found, and not clipped (the sky's plateau is not the sun's).
        let mut m = map_with(|r| if r < 2.0 { 1e7 } else { 0.0 }, f32::MAX);
        m.pixels.iter_mut().enumerate().for_each(|(k, p)| *p = p.max(Rgb::splat((3.0 * (1.0 - (k / W) as f32 / H as f32)).min(1.0))));
        assert_eq!(extracted(&m).clip, None);
    }

    #[test]
    fn a_map_cut_at_a_ceiling_shows_a_plateau_at_its_maximum() {
        // A sky of 0.3 whose sun was clipped at 1.0 over 3×3 pixels; the same sky with the sun
        // one pixel of 1.0 (a peak, not a plateau).
        let (w, h) = (64, 32);
        let mut px = vec![Rgb::splat(0.3); w * h];
        for k in [0, 1, 2].iter().flat_map(|j| [0, 1, 2].map(|i| (10 + j) * w + 20 + i)) {
            px[k] = Rgb::splat(1.0);
        }
        assert_eq!(EnvMap::new(w, h, px).plateau_at_max(), Some((1.0, 9)));
        let mut one = vec![Rgb::splat(0.3); w * h];
        one[10 * w + 20] = Rgb::splat(1.0);
        assert_eq!(EnvMap::new(w, h, one).plateau_at_max(), None);
        assert_eq!(EnvMap::new(w, h, vec![Rgb::ZERO; w * h]).plateau_at_max(), None);
    }
}
