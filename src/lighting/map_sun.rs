//! A sun painted into an environment map: found ([`EnvMap::compact_source`], for the warning that
//! the fast methods blur it) and taken out of the map as a directional sun
//! ([`EnvMap::extract_sun`], for `sky.extract_sun`). The methods but `reference` take a map sky as
//! its means over cells about 20° wide, and carry a directional sun exactly (docs/sky.md, "A sun
//! in the map").

use super::envmap::{direction, neighbourhood, row_solid_angle, EnvMap};
use super::sun_clip::SunClip;
use crate::math::{luminance, Rgb, Vec3};
use glam::DVec3;

/// How many times the map's mean radiance (luminance, over the sphere) a pixel of a sun is.
pub const BRIGHT_OVER_MEAN: f64 = 100.0;

/// The largest solid angle (sr) a sun taken out of a map may cover: a cap about 3° in radius
/// (the real sun's is 6.8·10⁻⁵ sr; an HDRI's sun with its glare covers a few pixels).
pub const MAX_SUN_SOLID_ANGLE: f64 = 0.01;

/// The share of a map's light (luminance) a compact source carries at least to be the map's sun:
/// warned about, and taken out as the scene's sun where `sky.extract_sun` is left out.
pub const SUN_SHARE: f64 = 0.2;

/// A compact bright source in a map: the pixels brighter than [`BRIGHT_OVER_MEAN`] times the
/// map's mean radiance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CompactSource {
    /// Their share of the map's whole ∫ L dω (luminance).
    pub share: f64,
    /// Their solid angle (sr).
    pub solid_angle: f64,
    /// Their light's mean direction (unit; towards the source).
    pub direction: Vec3,
    /// Their ∫ L dω per band: the irradiance they give a surface facing them (W/m²).
    pub irradiance: Rgb,
}

impl CompactSource {
    /// Whether it is a sun: at least [`SUN_SHARE`] of the map's light within
    /// [`MAX_SUN_SOLID_ANGLE`].
    pub fn is_sun(&self) -> bool {
        self.share >= SUN_SHARE && self.solid_angle <= MAX_SUN_SOLID_ANGLE
    }
}

/// A sun taken out of a map by [`EnvMap::extract_sun`].
#[derive(Clone, Debug)]
pub struct ExtractedSun {
    /// The map with the sun's pixels painted over by the sky around them.
    pub map: EnvMap,
    /// Towards the sun (unit).
    pub direction: Vec3,
    /// Its irradiance on a plane facing it (W/m² per band): the light the painted pixels lost.
    pub irradiance: Rgb,
    /// The solid angle of the pixels painted over (sr).
    pub solid_angle: f64,
    /// The sun's clipped top, if it has one: then its irradiance is a lower bound.
    pub clip: Option<SunClip>,
}

/// Why a map has no sun to take out.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum NoSun {
    /// The map is black.
    Black,
    /// Its brightest pixel is this many times its mean radiance, not over [`BRIGHT_OVER_MEAN`].
    NotBright(f64),
    /// The bright pixels joined to the brightest one cover this solid angle (sr), over
    /// [`MAX_SUN_SOLID_ANGLE`]: a bright region, not a sun.
    TooWide(f64),
}

impl EnvMap {
    /// The map's mean luminance over the sphere (∫ Y dω / 4π); `None` for a black map.
    fn mean_luminance(&self) -> Option<f64> {
        Some(self.luminance_integral()? / (4.0 * std::f64::consts::PI))
    }

    /// The map's pixels brighter than [`BRIGHT_OVER_MEAN`] times its mean: their share of its
    /// light and their solid angle; `None` for a black map.
    pub fn compact_source(&self) -> Option<CompactSource> {
        let (w, h) = (self.width, self.height);
        let mean = self.mean_luminance()?;
        let threshold = BRIGHT_OVER_MEAN * mean;
        let (mut power, mut solid_angle, mut toward, mut irradiance) = (0.0, 0.0, DVec3::ZERO, DVec3::ZERO);
        for j in 0..h {
            let dw = row_solid_angle(j, h, w);
            for (i, p) in self.pixels[j * w..(j + 1) * w].iter().enumerate() {
                let y = luminance(*p) as f64;
                if y > threshold {
                    power += y * dw;
                    solid_angle += dw;
                    irradiance += p.as_dvec3() * dw;
                    toward += self.pixel_direction(i, j).as_dvec3() * (y * dw);
                }
            }
        }
        Some(CompactSource {
            share: power / (4.0 * std::f64::consts::PI * mean),
            solid_angle,
            direction: toward.normalize_or_zero().as_vec3(),
            irradiance: irradiance.as_vec3(),
        })
    }

    /// The sun around the map's brightest pixel taken out of it: the pixels over
    /// [`BRIGHT_OVER_MEAN`] times the map's mean joined to that pixel (8-connected, wrapping in
    /// azimuth) are painted with the mean radiance of the pixels bordering them (per band, no more
    /// than their own mean), and the light they lose, Σ (L − fill) dω per band, becomes a
    /// directional sun towards its centroid. The map's ∫ L dω plus the sun's irradiance is the
    /// original map's ∫ L dω in every band.
    pub fn extract_sun(&self) -> Result<ExtractedSun, NoSun> {
        let (w, h) = (self.width, self.height);
        let mean = self.mean_luminance().ok_or(NoSun::Black)?;
        let lum = |k: usize| luminance(self.pixels[k]) as f64;
        // The first brightest pixel in row-major order: the same sun for the same map.
        let seed = (0..w * h).fold(0, |best, k| if lum(k) > lum(best) { k } else { best });
        let threshold = BRIGHT_OVER_MEAN * mean;
        if lum(seed) <= threshold {
            return Err(NoSun::NotBright(lum(seed) / mean));
        }
        let mut inside = vec![false; w * h];
        inside[seed] = true;
        let (mut stack, mut sun_pixels) = (vec![seed], Vec::new());
        while let Some(k) = stack.pop() {
            sun_pixels.push(k);
            for n in neighbourhood(k, w, h) {
                if !inside[n] && lum(n) > threshold {
                    inside[n] = true;
                    stack.push(n);
                }
            }
        }
        let solid_angle_of = |k: usize| row_solid_angle(k / w, h, w);
        let solid_angle: f64 = sun_pixels.iter().map(|&k| solid_angle_of(k)).sum();
        if solid_angle > MAX_SUN_SOLID_ANGLE {
            return Err(NoSun::TooWide(solid_angle));
        }
        let sun_light: DVec3 = sun_pixels.iter().map(|&k| self.pixels[k].as_dvec3() * solid_angle_of(k)).sum();
        // The sky around the sun: the solid-angle mean of the pixels bordering it.
        let mut bordering = vec![false; w * h];
        let (mut border_light, mut border_solid_angle) = (DVec3::ZERO, 0.0);
        for &k in &sun_pixels {
            for n in neighbourhood(k, w, h) {
                if !inside[n] && !bordering[n] {
                    bordering[n] = true;
                    border_light += self.pixels[n].as_dvec3() * solid_angle_of(n);
                    border_solid_angle += solid_angle_of(n);
                }
            }
        }
        // No band of the sun negative: the fill is at most the sun pixels' own mean.
        let sun_mean = sun_light / solid_angle;
        let fill = match border_solid_angle > 0.0 {
            true => (border_light / border_solid_angle).min(sun_mean),
            false => DVec3::ZERO,
        };
        let fill_luminance = luminance(fill.as_vec3()) as f64;
        let mut toward = DVec3::ZERO;
        let mut pixels = self.pixels.clone();
        for &k in &sun_pixels {
            let excess = (lum(k) - fill_luminance).max(0.0) * solid_angle_of(k);
            toward += self.pixel_direction(k % w, k / w).as_dvec3() * excess;
            pixels[k] = fill.as_vec3();
        }
        Ok(ExtractedSun {
            map: EnvMap::new(w, h, pixels),
            direction: toward.try_normalize().unwrap_or(self.pixel_direction(seed % w, seed / w).as_dvec3()).as_vec3(),
            irradiance: ((sun_mean - fill) * solid_angle).as_vec3(),
            solid_angle,
            clip: self.sun_clip(&sun_pixels),
        })
    }

    /// The direction through the centre of pixel (column `i`, row `j`).
    fn pixel_direction(&self, i: usize, j: usize) -> Vec3 {
        direction((i as f32 + 0.5) / self.width as f32, (j as f32 + 0.5) / self.height as f32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 512×256 map of 0.5 with a 3×3-pixel sun of 2·10⁵ at columns and rows 100–102 and 60–62.
    fn sunny_map() -> (EnvMap, Vec<Rgb>) {
        let (w, h) = (512, 256);
        let mut px = vec![Rgb::splat(0.5); w * h];
        for j in 60..63 {
            for i in 100..103 {
                px[j * w + i] = Rgb::splat(2e5);
            }
        }
        (EnvMap::new(w, h, px.clone()), px)
    }

    #[test]
    fn a_sun_in_the_map_is_found_with_its_share_and_solid_angle() {
        let (w, h) = (512, 256);
        assert_eq!(EnvMap::new(w, h, vec![Rgb::splat(0.5); w * h]).compact_source().map(|c| c.share), Some(0.0));
        let c = sunny_map().0.compact_source().unwrap();
        // Nine pixels of about 1.2e-4 sr each hold nearly all the light.
        assert!(c.share > 0.9 && (5e-4..2e-3).contains(&c.solid_angle), "{c:?}");
        // Towards pixel (101, 61)'s centre, with the nine pixels' power.
        assert!((c.direction - direction(101.5 / w as f32, 61.5 / h as f32)).length() < 1e-3, "{c:?}");
        assert!((c.irradiance.x as f64 / (2e5 * c.solid_angle) - 1.0).abs() < 1e-6, "{c:?}");
        assert_eq!(EnvMap::new(2, 1, vec![Rgb::ZERO; 2]).compact_source(), None);
    }

    /// ∫ L dω per band over the whole map, in f64.
    fn map_light(m: &EnvMap) -> DVec3 {
        (0..m.height)
            .map(|j| {
                let dw = row_solid_angle(j, m.height, m.width);
                m.pixels[j * m.width..(j + 1) * m.width].iter().map(|p| p.as_dvec3() * dw).sum::<DVec3>()
            })
            .sum()
    }

    #[test]
    fn an_extracted_sun_keeps_the_maps_light_and_leaves_the_sky_around_it() {
        let (map, _) = sunny_map();
        let (w, h) = (map.width, map.height);
        let sun = map.extract_sun().unwrap();
        // The nine pixels, painted with the sky around them; every other pixel as it was.
        assert!(sun.map.pixels.iter().all(|p| *p == Rgb::splat(0.5)));
        assert!((sun.solid_angle / (9.0 * row_solid_angle(61, h, w)) - 1.0).abs() < 1e-3, "{}", sun.solid_angle);
        assert!((sun.direction - direction(101.5 / w as f32, 61.5 / h as f32)).length() < 1e-3);
        // What the map lost is the sun's irradiance, in every band.
        let lost = map_light(&map) - map_light(&sun.map);
        assert!((sun.irradiance.as_dvec3() - lost).abs().max_element() < 1e-6 * lost.x, "{sun:?} {lost}");
        assert!((sun.irradiance.x as f64 - (2e5 - 0.5) * sun.solid_angle).abs() < 1e-6 * sun.irradiance.x as f64);
    }

    #[test]
    fn a_sun_across_the_maps_seam_is_one_sun_and_a_coloured_one_stays_non_negative() {
        let (w, h) = (512, 256);
        // Two pixels each side of the u = 0 seam; a red sun on a blue sky.
        let mut px = vec![Rgb::new(0.1, 0.2, 0.9); w * h];
        for i in [w - 2, w - 1, 0, 1] {
            px[100 * w + i] = Rgb::new(5e5, 0.0, 0.0);
        }
        let sun = EnvMap::new(w, h, px).extract_sun().unwrap();
        assert!((sun.solid_angle / (4.0 * row_solid_angle(100, h, w)) - 1.0).abs() < 1e-6);
        // Towards the seam (u = 0: +x, tilted up).
        assert!(sun.direction.x > 0.5 && sun.direction.z.abs() < 1e-4, "{:?}", sun.direction);
        assert!(sun.irradiance.min_element() >= 0.0 && sun.irradiance.y == 0.0, "{:?}", sun.irradiance);
        assert!(sun.map.pixels.iter().all(|p| p.min_element() >= 0.0 && p.is_finite()));
    }

    #[test]
    fn a_map_with_no_sun_says_why() {
        let (w, h) = (64, 32);
        assert_eq!(EnvMap::new(w, h, vec![Rgb::ZERO; w * h]).extract_sun().err(), Some(NoSun::Black));
        let mut px = vec![Rgb::ONE; w * h];
        px[5] = Rgb::splat(50.0);
        assert!(matches!(EnvMap::new(w, h, px.clone()).extract_sun(), Err(NoSun::NotBright(r)) if (40.0..60.0).contains(&r)));
        // A bright patch 20 pixels square in a 512×256 map (0.06 sr): a region, not a sun.
        let (w, h) = (512, 256);
        let mut px = vec![Rgb::ONE; w * h];
        for j in 118..138 {
            for i in 300..320 {
                px[j * w + i] = Rgb::splat(1e5);
            }
        }
        assert!(matches!(EnvMap::new(w, h, px).extract_sun(), Err(NoSun::TooWide(sr)) if sr > MAX_SUN_SOLID_ANGLE));
    }
}
