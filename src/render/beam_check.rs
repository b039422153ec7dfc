//! A check on how the gathers of `transport` and `full` carry the sun's beam between voxel
//! centres. Each takes the sun's light trilinear between the centres, where the beam falls off
//! exponentially: over a stretch τ optical depths long along the sun, the chord lies above it by
//! (τ/2)·coth(τ/2) (+8 % at τ = 1). Where the voxels are optically thick along the sun's path
//! (coarse voxels under a low sun), the image's sunlit light comes out too bright: +19 %
//! (`transport`) and +30 % (`full`) against `reference` with the sun 0.6° behind a cloud of 40-m
//! voxels (docs/accuracy.md, "The sun's beam between centres: a check"). So the sun single
//! scattering of every second pixel's centre ray, each way, is also marched with the beam's
//! optical depth −ln T trilinear (exact where τ is linear), and the two are compared over the
//! cloud's pixels ([`share_over_pixels`]): the difference estimates the chord's excess in the
//! image, and above [`BEAM_EXCESS`] of the cloud's light a warning names the fix ([`report`]).
//! Here: the shared sums and report, and [`BeamCheck`], `transport`'s per-voxel source for it;
//! `full`'s is [`super::full_beam`].
//! (Not used for `transport`'s image itself: with the chord's excess taken out there, a deficit
//! of the solve's diffuse light on other scenes comes to light; docs/accuracy.md.)

use super::transport::{full_weighted, SunSource};
use crate::math::{Rgb, Vec3};
use crate::medium::sparse::FullIndex;
use crate::medium::Medium;
use crate::pipeline::{render_rows, NoProgress, Progress};
use crate::scene::Scene;

/// The share of the cloud's light by which the gather's sun single scattering may exceed the one
/// with the beam interpolated exponentially before a warning: above every scene of the evaluation
/// sets (at most 2.4 %, docs/accuracy.md), below the 40-m, low-sun case (7–29 % by image size).
pub const BEAM_EXCESS: f64 = 0.05;

/// Per full voxel (in [`FullIndex`] order) the middle band's sun single scattering towards the eye
/// per unit T′, its smooth and peak parts ([`SunSource`]), and ln T′.
pub struct BeamCheck {
    per_beam_and_ln: Vec<Rgb>,
}

impl BeamCheck {
    /// From the eye source's sun part `sun` and the δ-M beam `sun_t` at the full voxels.
    pub fn new(sun: &[SunSource], sun_t: &[[f32; 3]]) -> BeamCheck {
        let per_beam_and_ln = sun
            .iter()
            .zip(sun_t)
            .map(|(s, t)| {
                let t = t[1];
                // A voxel the beam does not reach adds nothing whatever its log.
                let per_beam = |part: f32| if t > 0.0 { part / t } else { 0.0 };
                Rgb::new(per_beam(s.smooth.y), per_beam(s.peak.y), t.max(f32::MIN_POSITIVE).ln())
            })
            .collect();
        BeamCheck { per_beam_and_ln }
    }

    /// The middle band's sun single scattering at continuous voxel coordinates `v`, seen through
    /// `t_eye_af` ([`SunSource::seen`]), with the beam's optical depth trilinear over the full
    /// voxels (as the gather's own source is).
    pub fn source(&self, m: &Medium, full: &FullIndex, v: Vec3, t_eye_af: f32) -> f32 {
        let c = full_weighted(m, full, v, |fi| self.per_beam_and_ln[fi]);
        (c.x + c.y * t_eye_af).max(0.0) * c.z.exp()
    }
}

/// The estimate's sums over the cloud's pixels (those `cloudgi compare` scores: the exact
/// transmittance through the cloud below 0.99): the gather's sun single scattering less the one
/// with the beam interpolated exponentially, and the whole image, both of the middle band.
#[derive(Clone, Copy, Debug, Default)]
pub struct BeamSums {
    /// Σ (the gather's sun single scattering − the check's), W·m⁻²·sr⁻¹ summed over pixels.
    pub excess: f64,
    /// Σ the image, the same units.
    pub light: f64,
}

impl BeamSums {
    /// The sums of one pixel: its sun single scattering (the gather's and the check's), its total,
    /// and whether the cloud covers it.
    pub fn pixel(sun: f32, sun_exponential: f32, total: f32, in_cloud: bool) -> BeamSums {
        if !in_cloud {
            return BeamSums::default();
        }
        BeamSums {
            excess: (sun - sun_exponential) as f64,
            light: total as f64,
        }
    }

    /// The excess as a share of the cloud's light (0 for an image without cloud).
    pub fn share(&self) -> f64 {
        if self.light > 0.0 {
            self.excess / self.light
        } else {
            0.0
        }
    }
}

/// The share ([`BeamSums::share`]) over every second pixel's centre ray each way (an estimate
/// over the cloud, not an image): `pixel(x, y, origin, direction, t_max)` gives a pixel's sums,
/// t_max (m) where its ray meets the ground. Summed in pixel order: the same for any thread
/// count.
pub fn share_over_pixels(scene: &Scene, pixel: impl Fn(u32, u32, Vec3, Vec3, f32) -> BeamSums + Sync) -> f64 {
    let cam = &scene.camera;
    let (w, h) = (cam.width.div_ceil(2), cam.height.div_ceil(2));
    let sums = render_rows(w, h, &NoProgress, "beam check", |x, y| {
        let (x, y) = (2 * x, 2 * y);
        let ray = cam.ray(x as f32 + 0.5, y as f32 + 0.5);
        let t_max = scene.ground.as_ref().and_then(|g| g.intersect(ray.origin, ray.dir)).unwrap_or(f32::INFINITY);
        pixel(x, y, ray.origin, ray.dir, t_max)
    });
    sums.iter()
        .fold(BeamSums::default(), |a, s| BeamSums {
            excess: a.excess + s.excess,
            light: a.light + s.light,
        })
        .share()
}

/// Log `method`'s estimated `share` and warn above [`BEAM_EXCESS`].
pub fn report(scene: &Scene, method: &str, share: f64, progress: &dyn Progress) {
    // (A reading that rounds to zero is printed as 0.0, not −0.0.)
    let shown = if share.abs() < 5e-4 { 0.0 } else { share };
    progress.log(&format!(
        "{method}: the sun's beam between voxel centres adds an estimated {:.1} % to the cloud's light (above {:.0} % is warned about)",
        shown * 100.0,
        BEAM_EXCESS * 100.0
    ));
    if let Some(w) = warning(scene, method, share) {
        progress.warn(&w);
    }
}

/// The warning for `scene` rendered with `method` (`transport` or `full`) when the estimated
/// excess `share` passes [`BEAM_EXCESS`].
pub fn warning(scene: &Scene, method: &str, share: f64) -> Option<String> {
    (share > BEAM_EXCESS).then(|| {
        format!(
            "{}: the sun's light between the voxel centres comes out {:.0} % of the cloud's light above what the \
             sun's beam gives falling off exponentially between them (the {method} gather interpolates it \
             linearly): the voxels are optically thick along the sun's path (a low sun, coarse voxels), and the \
             cloud's sunlit parts may come out that much too bright or more (a cloud of 40-m voxels with the sun \
             0.6° behind it: transport +19 %, full +30 % against reference; docs/accuracy.md, \"The sun's beam \
             between centres: a check\"); refine the grid with medium.refine = 3, or check with --method reference",
            scene.source,
            share * 100.0
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_share_counts_the_cloud_s_pixels_only() {
        let mut s = BeamSums::default();
        for p in [BeamSums::pixel(2.0, 1.0, 10.0, true), BeamSums::pixel(5.0, 0.0, 50.0, false)] {
            s.excess += p.excess;
            s.light += p.light;
        }
        assert_eq!(s.share(), 0.1);
        assert_eq!(BeamSums::default().share(), 0.0);
    }

    #[test]
    fn the_check_source_is_the_gather_s_where_the_beam_is_uniform() {
        // One full voxel: the normalised weights give its own values, and ln T′ back exp'd.
        let sun = SunSource {
            smooth: Rgb::new(0.0, 0.3, 0.0),
            peak: Rgb::new(0.0, 0.2, 0.0),
        };
        let check = BeamCheck::new(&[sun], &[[0.5, 0.6, 0.7]]);
        let c = check.per_beam_and_ln[0];
        assert!(((c.x + 0.5 * c.y) * c.z.exp() - 0.4).abs() < 1e-6, "{c:?}");
        // A voxel the beam does not reach: no source, a finite log.
        let dark = BeamCheck::new(&[SunSource::default()], &[[0.0; 3]]).per_beam_and_ln[0];
        assert_eq!((dark.x, dark.y), (0.0, 0.0));
        assert!(dark.z.is_finite());
    }
}
