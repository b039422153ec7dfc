//! The medium's optical properties, owned once: extinction, albedo and the Henyey–Greenstein
//! phase function, with everything derived from them (σs, σa, σtr, the i-fold phase functions of
//! the scattering orders, the similarity transform). No other module reads g or writes the HG
//! formula, so a change of optics (e.g. δ-scaling) is made here and every stage sees it.
//!
//! **Phase convention.** [`Hg::eval`]`(to_light, to_eye)` takes the unit direction *towards* the
//! light (the light travels along −to_light) and the unit direction the scattered light leaves in
//! (towards the eye); the scattering angle is cos θ = (−to_light)·to_eye, so g > 0 scatters
//! forward. [`Hg::eval_cos`] takes that cosine directly. Values are per steradian and integrate
//! to 1 over the sphere.

use crate::math::{Frame, Rgb, Vec3};
use std::f32::consts::PI;

/// Henyey–Greenstein phase function with mean cosine g (|g| < 1). g is kept in f64 so the
/// orders' HG(gⁱ) (paper section 4) are exact to f64 rounding.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hg {
    g: f64,
}

impl Hg {
    /// HG with mean cosine `g` (unitless, |g| < 1).
    #[inline]
    pub fn new(g: f32) -> Hg {
        Hg { g: g as f64 }
    }

    /// The mean cosine g (unitless).
    #[inline]
    pub fn mean_cosine(&self) -> f64 {
        self.g
    }

    /// p(θ) = (1 − g²) / (4π (1 − 2g cosθ + g²)^{3/2}) in sr⁻¹, from cos θ (see the module docs);
    /// evaluated in f64 ([`Self::eval_cos_f64`]): in f32, 1 + g² − 2g cancels to 0 or below for
    /// |g| ≥ 0.9999 and the peak came out as inf or NaN.
    #[inline]
    pub fn eval_cos(&self, cos_theta: f32) -> f32 {
        self.eval_cos_f64(cos_theta as f64) as f32
    }

    /// [`Self::eval_cos`] in f64, for quadratures and the order kernels. The denominator's
    /// 1 + g² − 2g cos θ is written as a sum of non-negative terms, (1 − g)² + 2g(1 − cos θ) for
    /// g ≥ 0 and (1 + g)² + 2|g|(1 + cos θ) for g < 0, so it is never below (1 − |g|)² > 0: finite
    /// and positive for every |g| < 1 (the peak (1 + |g|)/(4π(1 − |g|)²) is 4.4·10¹³ sr⁻¹ for the
    /// f32 closest to 1, inside f32).
    #[inline]
    pub fn eval_cos_f64(&self, cos_theta: f64) -> f64 {
        let (g, c) = (self.g, cos_theta.clamp(-1.0, 1.0));
        let denom = if g >= 0.0 {
            (1.0 - g) * (1.0 - g) + 2.0 * g * (1.0 - c)
        } else {
            (1.0 + g) * (1.0 + g) - 2.0 * g * (1.0 + c)
        };
        (1.0 - g) * (1.0 + g) / (4.0 * std::f64::consts::PI * denom * denom.sqrt())
    }

    /// p for light arriving from `to_light` (unit, towards the light) and leaving along `to_eye`
    /// (unit): cos θ = (−to_light)·to_eye (sr⁻¹).
    #[inline]
    pub fn eval(&self, to_light: Vec3, to_eye: Vec3) -> f32 {
        self.eval_cos((-to_light).dot(to_eye))
    }

    /// (1 − cos θ, 1 + cos θ) of a sample with density p (inverse CDF; exact, also for g = 0)
    /// from a uniform `u`, in f64 and each without cancellation: with s = (1 − g²)/(1 − g + 2gu),
    /// cos θ = (1 + g² − s²)/(2g), so 1 − cos θ = (s² − (1 − g)²)/(2g) and
    /// 1 + cos θ = ((1 + g)² − s²)/(2g). For |g| → 1 the lobe is narrower than f32 resolves near
    /// cos θ = ±1; these keep sin θ = √((1 − cos θ)(1 + cos θ)) exact there.
    #[inline]
    fn sample_one_minus_plus(&self, u: f32) -> (f64, f64) {
        let (g, u) = (self.g, u as f64);
        if g.abs() < 1e-3 {
            return (2.0 * u, 2.0 - 2.0 * u);
        }
        let s = (1.0 - g) * (1.0 + g) / (1.0 - g + 2.0 * g * u);
        let omc = ((s - (1.0 - g)) * (s + (1.0 - g)) / (2.0 * g)).clamp(0.0, 2.0);
        let opc = (((1.0 + g) - s) * ((1.0 + g) + s) / (2.0 * g)).clamp(0.0, 2.0);
        (omc, opc)
    }

    /// Sample cos θ with density p (inverse CDF; exact, also for g = 0) from a uniform `u`.
    #[inline]
    pub fn sample_cos(&self, u: f32) -> f32 {
        let (omc, opc) = self.sample_one_minus_plus(u);
        (if omc < opc { 1.0 - omc } else { opc - 1.0 }) as f32
    }

    /// Sample a new propagation direction after scattering from propagation direction `dir`
    /// (unit), using two uniforms; its density is `eval_cos(dir·new)`.
    #[inline]
    pub fn sample(&self, dir: Vec3, u1: f32, u2: f32) -> Vec3 {
        let (omc, opc) = self.sample_one_minus_plus(u1);
        let cos_t = (if omc < opc { 1.0 - omc } else { opc - 1.0 }) as f32;
        let sin_t = (omc * opc).sqrt() as f32;
        let phi = 2.0 * PI * u2;
        Frame::from_normal(dir)
            .to_world(Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t))
            .normalize()
    }

    /// The phase function of `i` successive scatterings: the i-fold spherical self-convolution
    /// of HG(g) is HG(gⁱ) (HG's Legendre coefficients are g^l; convolution multiplies them).
    #[inline]
    pub fn order(&self, i: usize) -> Hg {
        Hg { g: self.g.powi(i as i32) }
    }
}

/// Optical properties of the medium at density 1.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Optics {
    /// Extinction σt at density 1 (m⁻¹).
    pub sigma_t: f32,
    /// Single-scattering albedo a = σs/σt per band (unitless, in [0, 1]).
    pub albedo: Rgb,
    /// The phase function.
    pub phase: Hg,
    /// Albedo per band and phase function of the *exact* single scattering of the sun, per unit
    /// of this medium's extinction: (a, p) untransformed; after [`Optics::delta_m`] the true
    /// albedo and HG with the TMS factor, (a σt/σt′, p) (Nakajima & Tanaka 1988).
    pub sun_single: (Rgb, Hg),
}

/// One band's optics after the δ-M similarity transform (Wiscombe 1977) with forward fraction
/// f (0 ≤ f < 1): the fraction f of the scattering, taken as exactly forward, is treated as
/// unscattered. See [`delta_m`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeltaM {
    /// Scaled extinction σt′ = σt(1 − a f) (the unit of the σt given: m⁻¹, or optical depth).
    pub sigma_t: f64,
    /// Scaled single-scattering albedo a′ = a(1 − f)/(1 − a f) (unitless).
    pub albedo: f64,
    /// Scaled HG mean cosine g′ = (g − f)/(1 − f) (unitless).
    pub g: f64,
}

/// The δ-M transform of one band with extinction `sigma_t`, albedo `albedo` and HG mean cosine
/// `g`, truncating the forward fraction `f`: the one place the transform is written (the
/// diffusion and full media through [`Optics::delta_m`], the transport solver's bands with
/// f = g^{L+1}, the diffusion slab with f = g²). It keeps the absorption, σt′(1 − a′) = σt(1 − a),
/// and the transport extinction, σt′(1 − a′g′) = σt(1 − a g); f = 0 is exactly the identity.
pub fn delta_m(sigma_t: f64, albedo: f64, g: f64, f: f64) -> DeltaM {
    DeltaM {
        sigma_t: sigma_t * (1.0 - albedo * f),
        albedo: albedo * (1.0 - f) / (1.0 - albedo * f),
        g: (g - f) / (1.0 - f),
    }
}

impl Optics {
    /// σt (m⁻¹), albedo a (per band) and HG mean cosine g.
    pub fn new(sigma_t: f32, albedo: Rgb, g: f32) -> Optics {
        Optics {
            sigma_t,
            albedo,
            phase: Hg::new(g),
            sun_single: (albedo, Hg::new(g)),
        }
    }

    /// The δ-M medium (`render.forward_fraction`; Wiscombe 1977) every stage of `diffusion` and
    /// `full` runs on: the forward fraction `f` (0 ≤ f < 1) of the scattering is treated as
    /// unscattered, σt′ = σt(1 − ā f) with ā the bands' mean albedo (one extinction for all bands,
    /// exact for grey albedo), the absorption σa kept per band (a′ = 1 − σa/σt′), g′ = (g − f)/(1 − f);
    /// the sun's single scattering stays exact (TMS): true HG with albedo a·σt/σt′ per unit of
    /// the transformed extinction, seen through the transformed transmittance. f = 0 returns
    /// `self` unchanged; f is capped at g (a transform may not make g′ negative), so it is the
    /// identity for g ≤ 0.
    pub fn delta_m(&self, f: f32) -> Optics {
        let f = f.min(self.phase.g.max(0.0) as f32);
        if f == 0.0 {
            return *self;
        }
        let mean_a = (self.albedo.x + self.albedo.y + self.albedo.z) / 3.0;
        // One extinction for all bands: the mean albedo's; each band keeps its absorption.
        let scaled = delta_m(self.sigma_t as f64, mean_a as f64, self.phase.g, f as f64);
        let st = scaled.sigma_t as f32;
        let sigma_a = Rgb::ONE - self.albedo;
        let albedo = (Rgb::ONE - sigma_a * (self.sigma_t / st)).clamp(Rgb::ZERO, Rgb::ONE);
        Optics {
            sigma_t: st,
            albedo,
            phase: Hg::new(scaled.g as f32),
            sun_single: (self.albedo * (self.sigma_t / st), self.phase),
        }
    }

    /// The sun's exact single-scattering source per unit extinction and unit irradiance (sr⁻¹
    /// per band): albedo × p(sun → eye), with `to_sun` and `to_eye` unit ([`Self::sun_single`]).
    #[inline]
    pub fn sun_scatter(&self, to_sun: Vec3, to_eye: Vec3) -> Rgb {
        self.sun_single.0 * self.sun_single.1.eval(to_sun, to_eye)
    }

    /// [`Self::sun_scatter`] split for a gather that marches this (δ-M) medium: (the smooth part
    /// a p_{g′}(1 − f) σt/σt′, the truncated peak's part, k). δ-M carries every peak scattering on
    /// in the beam, so scattering the whole beam through the exact p counts a path of several peak
    /// scatterings once per scattering (the aureole too bright, docs/transport.md); the peak's
    /// part is counted once when no peak scattering follows on the eye's leg: weight it by
    /// T_eye^{af} = T′^k, T′ the marched δ-M transmittance from the eye, k = af/(1 − af) =
    /// σt/σt′ − 1 (0 without the transform: the split changes nothing).
    pub fn sun_scatter_split(&self, to_sun: Vec3, to_eye: Vec3) -> (Rgb, Rgb, f32) {
        let f = self.forward_fraction() as f32;
        let all = self.sun_scatter(to_sun, to_eye);
        let smooth = self.sun_single.0 * ((1.0 - f) * self.phase.eval(to_sun, to_eye));
        (smooth, all - smooth, (self.extinction_ratio() - 1.0).max(0.0))
    }

    /// The δ-M forward fraction f this medium was made with, from g′ = (g − f)/(1 − f) (0 without
    /// the transform).
    pub fn forward_fraction(&self) -> f64 {
        let (g, g_scaled) = (self.sun_single.1.mean_cosine(), self.phase.mean_cosine());
        if g_scaled < g {
            (g - g_scaled) / (1.0 - g_scaled)
        } else {
            0.0
        }
    }

    /// σt/σt′, the true extinction over this (δ-M) medium's: 1 − a′ + a σt/σt′ (σa is kept), per
    /// band; the middle band's (one scaled extinction serves all bands). 1 without the transform:
    /// the exact transmittance is T′ to this power.
    #[inline]
    pub fn extinction_ratio(&self) -> f32 {
        1.0 - self.albedo.y + self.sun_single.0.y
    }

    /// Scattering σs = a·σt per band at density 1 (m⁻¹).
    #[inline]
    pub fn sigma_s(&self) -> Rgb {
        self.albedo * self.sigma_t
    }

    /// Absorption σa = σt(1 − a) of band `c` at density 1 (m⁻¹), f64.
    #[inline]
    pub fn sigma_a(&self, c: usize) -> f64 {
        self.sigma_t as f64 * (1.0 - self.albedo[c] as f64)
    }

    /// Transport extinction σtr = σt(1 − a·g) of band `c` at density 1 (m⁻¹), f64: the
    /// diffusion coefficient is 1/(3ρσtr) (paper eq. 4).
    #[inline]
    pub fn sigma_tr(&self, c: usize) -> f64 {
        self.sigma_t as f64 * (1.0 - self.albedo[c] as f64 * self.phase.g)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hg_normalised_and_mean_cosine_is_g() {
        for &g in &[-0.5f32, 0.0, 0.3, 0.9, 0.95] {
            let p = Hg::new(g);
            // Integrate over cosθ with a fine midpoint rule (2π from φ).
            let n = 200_000;
            let (mut total, mut mean) = (0.0, 0.0);
            for i in 0..n {
                let mu = -1.0 + (i as f64 + 0.5) * 2.0 / n as f64;
                let w = p.eval_cos_f64(mu) * 2.0 * std::f64::consts::PI * (2.0 / n as f64);
                total += w;
                mean += w * mu;
            }
            assert!((total - 1.0).abs() < 1e-4, "g={g} total={total}");
            assert!((mean - g as f64).abs() < 1e-4, "g={g} mean={mean}");
        }
    }

    #[test]
    fn hg_near_one_is_finite_positive_and_samples_its_mean_cosine() {
        // The f32 closest to 1 and the |g| ≥ 0.9999 that gave NaN (f32 cancellation).
        let closest = f32::from_bits(1.0f32.to_bits() - 1);
        for &g in &[0.9999f32, 0.999999, -0.99999, closest, -closest] {
            let p = Hg::new(g);
            for &c in &[-1.0f32, -0.5, 0.0, 0.999, 1.0] {
                let v = p.eval_cos(c);
                assert!(v.is_finite() && v > 0.0, "g={g} cos={c}: p={v}");
            }
            // Normalised: ∫p dΩ = 2π ∫ p d(cos θ), in the variable t = ln(1 ∓ cos θ) that
            // resolves the narrow peak.
            let n = 200_000;
            let (lo, hi) = (1e-22f64.ln(), 2f64.ln());
            let total: f64 = (0..n)
                .map(|i| {
                    let t = lo + (i as f64 + 0.5) * (hi - lo) / n as f64;
                    let x = t.exp();
                    let c = if g > 0.0 { 1.0 - x } else { x - 1.0 };
                    p.eval_cos_f64(c) * x * (hi - lo) / n as f64
                })
                .sum::<f64>()
                * 2.0
                * std::f64::consts::PI;
            assert!((total - 1.0).abs() < 1e-3, "g={g}: ∫p = {total}");
            let m = 20_000;
            let mut mean = 0.0;
            for i in 0..m {
                let u = (i as f32 + 0.5) / m as f32;
                let d = p.sample(Vec3::Z, u, 0.3);
                assert!(d.is_finite() && (d.length() - 1.0).abs() < 1e-5, "g={g} u={u}: {d}");
                mean += d.z as f64 / m as f64;
            }
            assert!((mean - g as f64).abs() < 1e-3, "g={g}: sampled mean cosine {mean}");
        }
    }

    #[test]
    fn eval_convention_is_forward_for_positive_g() {
        let p = Hg::new(0.8);
        let sun = Vec3::new(0.0, 1.0, 0.0);
        // Light from above travelling down, leaving downwards: forward (cos θ = 1).
        assert_eq!(p.eval(sun, -sun), p.eval_cos(1.0));
        assert_eq!(p.eval(sun, sun), p.eval_cos(-1.0));
        assert!(p.eval(sun, -sun) > p.eval(sun, sun));
        assert_eq!(p.order(2).mean_cosine(), 0.8f32 as f64 * 0.8f32 as f64);
    }

    #[test]
    fn the_sun_scatter_split_sums_to_it_and_names_the_peaks_weight() {
        let o = Optics::new(0.05, Rgb::splat(0.99), 0.9);
        let (to_sun, to_eye) = (Vec3::Y, Vec3::new(0.1, -0.99, 0.0).normalize());
        let (smooth, peak, k) = o.sun_scatter_split(to_sun, to_eye);
        assert_eq!((peak, k), (Rgb::ZERO, 0.0));
        assert_eq!(smooth, o.sun_scatter(to_sun, to_eye));
        let t = o.delta_m(0.65);
        let (smooth, peak, k) = t.sun_scatter_split(to_sun, to_eye);
        let all = t.sun_scatter(to_sun, to_eye);
        assert!(((smooth + peak).y - all.y).abs() < 1e-5 * all.y && peak.y > smooth.y);
        // k = af/(1 − af).
        assert!((k - 0.99 * 0.65 / (1.0 - 0.99 * 0.65)).abs() < 1e-4, "{k}");
    }

    #[test]
    fn delta_m_keeps_absorption_and_sun_single_scattering() {
        let o = Optics::new(0.05, Rgb::new(0.9, 0.9, 0.9), 0.85);
        assert_eq!(o.delta_m(0.0), o);
        let t = o.delta_m(0.4);
        let (to_sun, to_eye) = (Vec3::Y, Vec3::new(0.6, -0.8, 0.0));
        for c in 0..3 {
            // σa′ = σa, and κ′·(sun source) = κ·a·p: the exact single scattering per unit length.
            assert!(((t.sigma_t * (1.0 - t.albedo[c])) - o.sigma_t * (1.0 - o.albedo[c])).abs() < 1e-7);
            let want = o.sigma_t * o.albedo[c] * o.phase.eval(to_sun, to_eye);
            assert!((t.sigma_t * t.sun_scatter(to_sun, to_eye)[c] - want).abs() < 1e-6 * want);
        }
        assert!((t.phase.mean_cosine() - (0.85f64 - 0.4) / 0.6).abs() < 1e-6);
    }

    #[test]
    fn delta_m_is_identity_at_zero_and_keeps_absorption_and_transport_extinction() {
        let (st, g) = (0.05f32 as f64, 0.85f32 as f64);
        for a in [0.9f32 as f64, 0.99f32 as f64, 1.0] {
            let s0 = delta_m(st, a, g, 0.0);
            assert_eq!((s0.sigma_t, s0.albedo, s0.g), (st, a, g));
            let s = delta_m(st, a, g, g);
            assert_eq!(s.g, 0.0);
            // σa′ = σt′ − σs′ = σa: the transform moves scattering, never absorption.
            let sa = s.sigma_t * (1.0 - s.albedo);
            assert!((sa - st * (1.0 - a)).abs() < 1e-8, "a = {a}: {sa} vs {}", st * (1.0 - a));
            // σtr = σt′(1 − a′g′) is invariant: the diffusion operator does not change.
            let tr = s.sigma_t * (1.0 - s.albedo * s.g);
            assert!((tr - st * (1.0 - a * g)).abs() < 1e-8);
        }
    }
}
