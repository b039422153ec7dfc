//! A physically based clear-sky atmosphere after Hillaire, "A Scalable and Production Ready Sky
//! and Atmosphere Rendering Technique" (EGSR 2020), with the planet and constants of Bruneton's
//! "Precomputed Atmospheric Scattering" reference implementation (2017).
//!
//! A spherical planet (centre at the origin, +y up at the observer) carries three constituents
//! with exponential or tent density profiles: Rayleigh (air molecules), Mie (aerosols, own phase
//! function) and ozone (absorption only). Precomputed here, all in f64:
//!
//! - the transmittance LUT T(r, μ) to the top of the atmosphere, with Bruneton's (r, μ) mapping;
//! - Hillaire's multiple-scattering LUT Ψ_ms(r, μ_s) (eq. 5–10 of the paper: second-order
//!   isotropic luminance L_2nd times the geometric series 1/(1 − f_ms));
//! - the sky radiance for any view direction at the observer's altitude: single scattering of
//!   the sun through the Rayleigh and Mie phase functions, shadowed by the planet, plus σ_s·Ψ_ms,
//!   plus the sun-lit planet ground below the horizon (direct sun only, as Hillaire's sky view).
//!
//! Three RGB "bands" stand for wavelengths 680, 550 and 440 nm, each 100 nm wide.

use crate::math::{Rgb, Vec3};
use crate::par;
use glam::DVec3;
use std::f64::consts::PI;

/// Planet radius (m). Source: Bruneton 2017 demo and Hillaire 2020, Earth preset.
pub const BOTTOM_RADIUS_M: f64 = 6_360_000.0;
/// Radius of the top of the atmosphere (m), 100 km above the ground. Same source.
pub const TOP_RADIUS_M: f64 = 6_460_000.0;
/// Rayleigh scattering coefficient at sea level (m⁻¹) at 680, 550, 440 nm. Source: Bruneton 2017
/// demo (λ⁻⁴ law, 1.24062e-6 m⁻¹ µm⁴), values as listed in Hillaire 2020's Earth preset.
pub const RAYLEIGH_SCATTERING: [f64; 3] = [5.802e-6, 13.558e-6, 33.100e-6];
/// Rayleigh density scale height (m). Source: Bruneton 2017, Hillaire 2020.
pub const RAYLEIGH_SCALE_HEIGHT_M: f64 = 8_000.0;
/// Mie scattering coefficient at sea level (m⁻¹), grey. Source: Hillaire 2020 Earth preset
/// (Bruneton 2017: Ångström turbidity β = 0.04, α = 0, single-scattering albedo 0.9).
pub const MIE_SCATTERING: f64 = 3.996e-6;
/// Mie absorption coefficient at sea level (m⁻¹), grey. Same source.
pub const MIE_ABSORPTION: f64 = 0.444e-6;
/// Mie density scale height (m). Source: Bruneton 2017, Hillaire 2020.
pub const MIE_SCALE_HEIGHT_M: f64 = 1_200.0;
/// Mie asymmetry parameter of the Cornette–Shanks phase function (unitless). Source: Hillaire 2020
/// and Bruneton 2017 (g = 0.8).
pub const MIE_G: f64 = 0.8;
/// Ozone absorption coefficient at the layer's peak density (m⁻¹) at 680, 550, 440 nm. Source:
/// Hillaire 2020 Earth preset, i.e. Bruneton 2017's 300 Dobson units spread over the tent layer
/// times the ozone cross-sections of Serdyuchenko et al. (IUP Bremen, 233 K).
pub const OZONE_ABSORPTION: [f64; 3] = [0.650e-6, 1.881e-6, 0.085e-6];
/// Altitude of the ozone tent's peak (m): density rises linearly from 10 km, peaks at 25 km and
/// falls to zero at 40 km. Source: Bruneton 2017 demo (two linear layers).
pub const OZONE_CENTER_M: f64 = 25_000.0;
/// Half width of the ozone tent (m). Same source.
pub const OZONE_HALF_WIDTH_M: f64 = 15_000.0;
/// Extraterrestrial solar irradiance per band (W/m²): the ASTM G-173 extraterrestrial (ETR)
/// spectral irradiance averaged over 680–690, 550–560 and 440–450 nm (1.474, 1.8504, 1.91198
/// W·m⁻²·nm⁻¹, as tabulated in Bruneton 2017's demo) times a 100 nm band width. Their sum,
/// 523.6 W/m², is close to the ASTM value of the whole 400–700 nm range (≈ 530 W/m²).
pub const SOLAR_IRRADIANCE: [f64; 3] = [147.40, 185.04, 191.198];

/// Transmittance LUT size: μ (Bruneton's x_μ) × r (x_r). Same as Hillaire 2020 (256 × 64).
const TRANS_W: usize = 256;
const TRANS_H: usize = 64;
/// Multiple-scattering LUT size: μ_s × altitude (Hillaire 2020: 32 × 32).
const MS_W: usize = 32;
const MS_H: usize = 32;
/// Directions per multiple-scattering texel: a 12 × 12 stratified sphere (Hillaire 2020 uses 64;
/// 144 halves the error against a Monte Carlo reference, see src/tests/sky.rs).
const MS_DIRS: usize = 12;
/// Ray-march segments per multiple-scattering direction (Hillaire 2020: 20).
const MS_STEPS: usize = 20;
/// Ray-march segments per sky view ray.
const VIEW_STEPS: usize = 48;
/// Simpson intervals per piece of the optical-depth integrals (a ray has at most 8 pieces).
const DEPTH_INTERVALS: usize = 32;

/// The atmosphere's physical parameters (SI units). `Default` is the Earth preset above.
#[derive(Clone, Debug, PartialEq)]
pub struct AtmosphereParams {
    /// Planet radius (m).
    pub bottom_radius: f64,
    /// Radius of the top of the atmosphere (m).
    pub top_radius: f64,
    /// Rayleigh scattering at density 1 (m⁻¹ per band).
    pub rayleigh_scattering: DVec3,
    /// Rayleigh scale height (m).
    pub rayleigh_scale_height: f64,
    /// Mie scattering at density 1 (m⁻¹ per band).
    pub mie_scattering: DVec3,
    /// Mie absorption at density 1 (m⁻¹ per band).
    pub mie_absorption: DVec3,
    /// Mie scale height (m).
    pub mie_scale_height: f64,
    /// Cornette–Shanks asymmetry (unitless, |g| < 1).
    pub mie_g: f64,
    /// Ozone absorption at the tent's peak (m⁻¹ per band).
    pub ozone_absorption: DVec3,
    /// Ozone tent peak altitude (m).
    pub ozone_center: f64,
    /// Ozone tent half width (m).
    pub ozone_half_width: f64,
    /// Lambertian albedo of the planet's ground (unitless per band): lights the sky from below
    /// (in Ψ_ms) and is what the sky shows below the horizon.
    pub ground_albedo: DVec3,
    /// Extraterrestrial solar irradiance (W/m² per band).
    pub solar_irradiance: DVec3,
    /// Include multiple scattering (Ψ_ms); false gives single scattering only (for tests).
    pub multiple_scattering: bool,
}

impl Default for AtmosphereParams {
    fn default() -> Self {
        AtmosphereParams {
            bottom_radius: BOTTOM_RADIUS_M,
            top_radius: TOP_RADIUS_M,
            rayleigh_scattering: DVec3::from(RAYLEIGH_SCATTERING),
            rayleigh_scale_height: RAYLEIGH_SCALE_HEIGHT_M,
            mie_scattering: DVec3::splat(MIE_SCATTERING),
            mie_absorption: DVec3::splat(MIE_ABSORPTION),
            mie_scale_height: MIE_SCALE_HEIGHT_M,
            mie_g: MIE_G,
            ozone_absorption: DVec3::from(OZONE_ABSORPTION),
            ozone_center: OZONE_CENTER_M,
            ozone_half_width: OZONE_HALF_WIDTH_M,
            ground_albedo: DVec3::splat(0.3),
            solar_irradiance: DVec3::from(SOLAR_IRRADIANCE),
            multiple_scattering: true,
        }
    }
}

/// Rayleigh phase function (sr⁻¹) of the cosine ν between the light's and the view's directions.
#[inline]
pub fn rayleigh_phase(nu: f64) -> f64 {
    3.0 / (16.0 * PI) * (1.0 + nu * nu)
}

/// Cornette–Shanks phase function (sr⁻¹), as in Bruneton 2017 and Hillaire 2020.
#[inline]
pub fn cornette_shanks_phase(nu: f64, g: f64) -> f64 {
    let k = 3.0 / (8.0 * PI) * (1.0 - g * g) / (2.0 + g * g);
    k * (1.0 + nu * nu) / (1.0 + g * g - 2.0 * g * nu).max(1e-12).powf(1.5)
}

/// Densities (unitless, 1 at the reference level) of Rayleigh, Mie and ozone at altitude `h` (m).
#[inline]
fn densities(p: &AtmosphereParams, h: f64) -> [f64; 3] {
    let h = h.max(0.0);
    [
        (-h / p.rayleigh_scale_height).exp(),
        (-h / p.mie_scale_height).exp(),
        (1.0 - (h - p.ozone_center).abs() / p.ozone_half_width).max(0.0),
    ]
}

impl AtmosphereParams {
    /// Extinction coefficient (m⁻¹ per band) for integrated densities `d` = [Rayleigh, Mie, ozone].
    #[inline]
    pub fn extinction(&self, d: [f64; 3]) -> DVec3 {
        self.rayleigh_scattering * d[0] + (self.mie_scattering + self.mie_absorption) * d[1] + self.ozone_absorption * d[2]
    }

    /// Densities [Rayleigh, Mie, ozone] at altitude `h` (m) above the ground.
    #[inline]
    pub fn densities(&self, h: f64) -> [f64; 3] {
        densities(self, h)
    }

    /// Distance from radius `r` along a ray of zenith cosine `mu` to the top of the atmosphere (m).
    #[inline]
    pub fn distance_to_top(&self, r: f64, mu: f64) -> f64 {
        let disc = r * r * (mu * mu - 1.0) + self.top_radius * self.top_radius;
        (-r * mu + disc.max(0.0).sqrt()).max(0.0)
    }

    /// Distance to the ground if the ray from radius `r` with zenith cosine `mu` hits it.
    #[inline]
    pub fn distance_to_ground(&self, r: f64, mu: f64) -> Option<f64> {
        let disc = r * r * (mu * mu - 1.0) + self.bottom_radius * self.bottom_radius;
        if mu < 0.0 && disc >= 0.0 {
            Some((-r * mu - disc.sqrt()).max(0.0))
        } else {
            None
        }
    }

    /// Integrated densities [Rayleigh, Mie, ozone] (m) along the ray from radius `r`, zenith
    /// cosine `mu`, over distance `dist`. The ray is cut at its lowest point and where it crosses
    /// the ozone tent's kinks, so every piece has monotone altitude and a smooth integrand; each
    /// piece gets Simpson's rule in s with t = a + (b − a)·s², which crowds samples at its lower
    /// (denser) end.
    pub fn integrated_densities(&self, r: f64, mu: f64, dist: f64) -> [f64; 3] {
        let t_low = (-r * mu).clamp(0.0, dist);
        let mut cuts = vec![0.0, dist, t_low];
        for hk in [
            self.ozone_center - self.ozone_half_width,
            self.ozone_center,
            self.ozone_center + self.ozone_half_width,
        ] {
            // |x0 + t·d| = R + hk:  t² + 2 r μ t + r² − (R + hk)² = 0.
            let rk = self.bottom_radius + hk;
            let b = r * mu;
            let disc = b * b - (r * r - rk * rk);
            if disc >= 0.0 {
                let sq = disc.sqrt();
                for t in [-b - sq, -b + sq] {
                    if t > 0.0 && t < dist {
                        cuts.push(t);
                    }
                }
            }
        }
        cuts.sort_by(f64::total_cmp);
        let mut acc = [0.0; 3];
        for w in cuts.windows(2) {
            let (lo, hi) = (w[0], w[1]);
            if hi - lo <= 1e-9 * dist.max(1.0) {
                continue;
            }
            // Dense end: the one nearer the ray's lowest point.
            let (a, len) = if (lo - t_low).abs() <= (hi - t_low).abs() {
                (lo, hi - lo)
            } else {
                (hi, lo - hi)
            };
            let n = DEPTH_INTERVALS;
            for k in 0..=n {
                let s = k as f64 / n as f64;
                let wk = if k == 0 || k == n {
                    1.0
                } else if k % 2 == 1 {
                    4.0
                } else {
                    2.0
                };
                let t = a + len * s * s;
                let rt = (r * r + t * t + 2.0 * r * mu * t).max(0.0).sqrt();
                let d = densities(self, rt - self.bottom_radius);
                let jac = 2.0 * len.abs() * s * wk / (3.0 * n as f64);
                for c in 0..3 {
                    acc[c] += d[c] * jac;
                }
            }
        }
        acc
    }

    /// Transmittance (per band) from radius `r` along zenith cosine `mu` to the top of the
    /// atmosphere, by direct integration; zero if the ray hits the ground.
    pub fn transmittance_to_top(&self, r: f64, mu: f64) -> DVec3 {
        if self.distance_to_ground(r, mu).is_some() {
            return DVec3::ZERO;
        }
        let d = self.integrated_densities(r, mu, self.distance_to_top(r, mu));
        (-self.extinction(d)).exp()
    }
}

/// A bilinear table over fractional texel indices.
#[derive(Clone)]
struct Lut {
    w: usize,
    h: usize,
    data: Vec<DVec3>,
}

impl Lut {
    /// Bilinear value at fractional texel index (x, y), clamped to the table.
    #[inline]
    fn get(&self, x: f64, y: f64) -> DVec3 {
        let x = x.clamp(0.0, (self.w - 1) as f64);
        let y = y.clamp(0.0, (self.h - 1) as f64);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.w - 1), (y0 + 1).min(self.h - 1));
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let at = |i: usize, j: usize| self.data[j * self.w + i];
        (at(x0, y0) * (1.0 - fx) + at(x1, y0) * fx) * (1.0 - fy) + (at(x0, y1) * (1.0 - fx) + at(x1, y1) * fx) * fy
    }
}

/// One march segment of a view ray: where it is and what it contributes, independent of azimuth.
#[derive(Clone, Copy)]
struct ViewSample {
    /// Distance along the ray (m).
    t: f64,
    /// Radius (m) and what the LUT lookups need at it.
    rc: Radial,
    /// Rayleigh scattering × ∫ transmittance over the segment (per band, unitless·m⁻¹·m).
    w_rayleigh: DVec3,
    /// Mie scattering × ∫ transmittance.
    w_mie: DVec3,
}

/// A marched ray: its segments and, if it hits the ground, (distance, transmittance to it).
type Marched = (Vec<ViewSample>, Option<(f64, DVec3)>);

/// What the LUT lookups at a fixed radius need, computed once per radius.
#[derive(Clone, Copy)]
struct Radial {
    /// Radius (m), clamped to the atmosphere.
    r: f64,
    /// Fractional row of the transmittance LUT.
    trans_y: f64,
    /// Fractional row of the multiple-scattering LUT.
    ms_y: f64,
    /// Bruneton's d_min and d_max − d_min.
    d_min: f64,
    d_span: f64,
    /// Rays with zenith cosine ≤ this (and < 0) hit the ground.
    mu_horizon: f64,
}

/// The precomputed atmosphere.
#[derive(Clone)]
pub struct Atmosphere {
    /// Its parameters.
    pub params: AtmosphereParams,
    trans: Lut,
    ms: Lut,
}

impl std::fmt::Debug for Atmosphere {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Atmosphere").field("params", &self.params).finish_non_exhaustive()
    }
}

impl Atmosphere {
    /// Precompute the transmittance and multiple-scattering LUTs (parallel, deterministic).
    pub fn new(params: AtmosphereParams) -> Atmosphere {
        let p = &params;
        let hh = (p.top_radius * p.top_radius - p.bottom_radius * p.bottom_radius).sqrt();
        let mut trans_data = vec![DVec3::ZERO; TRANS_W * TRANS_H];
        par::for_chunks(&mut trans_data, TRANS_W, &|j, row| {
            for (i, out) in row.iter_mut().enumerate() {
                let (x_mu, x_r) = (i as f64 / (TRANS_W - 1) as f64, j as f64 / (TRANS_H - 1) as f64);
                let rho = hh * x_r;
                let r = (rho * rho + p.bottom_radius * p.bottom_radius).sqrt();
                let (d_min, d_max) = (p.top_radius - r, rho + hh);
                let d = d_min + x_mu * (d_max - d_min);
                let mu = if d <= 0.0 {
                    1.0
                } else {
                    ((hh * hh - rho * rho - d * d) / (2.0 * r * d)).clamp(-1.0, 1.0)
                };
                let dens = p.integrated_densities(r, mu, d);
                *out = (-p.extinction(dens)).exp();
            }
        });
        let mut atm = Atmosphere {
            trans: Lut {
                w: TRANS_W,
                h: TRANS_H,
                data: trans_data,
            },
            ms: Lut {
                w: MS_W,
                h: MS_H,
                data: vec![DVec3::ZERO; MS_W * MS_H],
            },
            params,
        };
        if atm.params.multiple_scattering {
            let rows = par::map_range(MS_H, &|j| atm.ms_row(j));
            atm.ms.data = rows.concat();
        }
        atm
    }

    /// Transmittance (per band) from radius `r` to the top of the atmosphere along zenith cosine
    /// `mu`, from the LUT, including the planet's shadow (zero when the ray hits the ground).
    #[inline]
    pub fn transmittance(&self, r: f64, mu: f64) -> DVec3 {
        self.trans_at(&self.radial(r), mu)
    }

    /// LUT coordinates at radius `r`.
    #[inline]
    fn radial(&self, r: f64) -> Radial {
        let p = &self.params;
        let r = r.clamp(p.bottom_radius, p.top_radius);
        let (r2, b2, t2) = (r * r, p.bottom_radius * p.bottom_radius, p.top_radius * p.top_radius);
        let hh = (t2 - b2).sqrt();
        let rho = (r2 - b2).max(0.0).sqrt();
        let d_min = p.top_radius - r;
        Radial {
            r,
            trans_y: rho / hh * (TRANS_H - 1) as f64,
            ms_y: ((r - p.bottom_radius) / (p.top_radius - p.bottom_radius)).clamp(0.0, 1.0) * (MS_H - 1) as f64,
            d_min,
            d_span: rho + hh - d_min,
            mu_horizon: -(1.0 - b2 / r2).max(0.0).sqrt(),
        }
    }

    /// Transmittance LUT lookup at a prepared radius (same as [`Atmosphere::transmittance`]).
    #[inline]
    fn trans_at(&self, c: &Radial, mu: f64) -> DVec3 {
        if mu < 0.0 && mu <= c.mu_horizon {
            return DVec3::ZERO;
        }
        let r = c.r;
        let top = self.params.top_radius;
        let d = -r * mu + (r * r * (mu * mu - 1.0) + top * top).max(0.0).sqrt();
        let x_mu = ((d - c.d_min) / c.d_span).clamp(0.0, 1.0);
        self.trans.get(x_mu * (TRANS_W - 1) as f64, c.trans_y)
    }

    /// Multiple-scattering LUT lookup at a prepared radius.
    #[inline]
    fn ms_at(&self, c: &Radial, mu_s: f64) -> DVec3 {
        self.ms.get((mu_s.clamp(-1.0, 1.0) + 1.0) * 0.5 * (MS_W - 1) as f64, c.ms_y)
    }

    /// One altitude row of the multiple-scattering LUT (Hillaire 2020, eq. 5–10, isotropic
    /// phase). The march along each direction does not depend on the sun, so it is done once per
    /// direction zenith angle and reused for every sun angle and azimuth; azimuths φ and −φ give
    /// the same result (the sun lies in the x–y plane), so only half are walked.
    fn ms_row(&self, j: usize) -> Vec<DVec3> {
        let p = &self.params;
        let h = (p.top_radius - p.bottom_radius) * j as f64 / (MS_H - 1) as f64;
        let r0 = (p.bottom_radius + h).min(p.top_radius - 1.0);
        let iso = 1.0 / (4.0 * PI);
        let n_dirs = (MS_DIRS * MS_DIRS) as f64;
        let rays: Vec<(f64, f64, Marched)> = (0..MS_DIRS)
            .map(|a| {
                let cos_t = 1.0 - 2.0 * (a as f64 + 0.5) / MS_DIRS as f64;
                (cos_t, (1.0 - cos_t * cos_t).max(0.0).sqrt(), self.march(r0, cos_t, MS_STEPS))
            })
            .collect();
        // f_ms = mean over directions of ∫ σ_s T dt (independent of the sun).
        let fms: DVec3 = rays
            .iter()
            .flat_map(|ray| ray.2 .0.iter().map(|s| s.w_rayleigh + s.w_mie))
            .sum::<DVec3>()
            * (MS_DIRS as f64 / n_dirs);
        let half = MS_DIRS / 2;
        (0..MS_W)
            .map(|i| {
                let mu_s = -1.0 + 2.0 * i as f64 / (MS_W - 1) as f64;
                let sun_x = (1.0 - mu_s * mu_s).max(0.0).sqrt();
                let mut l2 = DVec3::ZERO;
                for (cos_t, sin_t, (samples, ground)) in &rays {
                    for b in 0..MS_DIRS.div_ceil(2) {
                        let phi = 2.0 * PI * (b as f64 + 0.5) / MS_DIRS as f64;
                        // Pairs (φ, 2π − φ) are equal; an odd middle one counts once.
                        let weight = if MS_DIRS % 2 == 1 && b == half { 1.0 } else { 2.0 };
                        let nu = sin_t * phi.cos() * sun_x + cos_t * mu_s;
                        let mut l = DVec3::ZERO;
                        for s in samples {
                            let mu_at = ((r0 * mu_s + s.t * nu) / s.rc.r).clamp(-1.0, 1.0);
                            l += (s.w_rayleigh + s.w_mie) * self.trans_at(&s.rc, mu_at);
                        }
                        l *= iso;
                        if let Some((tg, tr)) = ground {
                            let mu_g = ((r0 * mu_s + tg * nu) / p.bottom_radius).clamp(-1.0, 1.0);
                            if mu_g > 0.0 {
                                l += *tr * self.transmittance(p.bottom_radius, mu_g) * mu_g * p.ground_albedo / PI;
                            }
                        }
                        l2 += l * weight;
                    }
                }
                // ∫_Ω (·) p_u dω with uniform directions = mean over directions.
                (l2 / n_dirs) / (DVec3::ONE - fms)
            })
            .collect()
    }

    /// The azimuth-independent part of a ray from radius `r0` with zenith cosine `mu`, marched
    /// in `steps` segments: per segment its position, LUT coordinates and scattering weights;
    /// and, if the ray hits the ground, (distance, transmittance to it).
    fn march(&self, r0: f64, mu: f64, steps: usize) -> Marched {
        let p = &self.params;
        let ground = p.distance_to_ground(r0, mu);
        let t_end = ground.unwrap_or_else(|| p.distance_to_top(r0, mu));
        let mut tr = DVec3::ONE;
        let mut out = Vec::with_capacity(steps);
        for (t, dt) in segments(r0, mu, t_end, steps) {
            let rt = (r0 * r0 + t * t + 2.0 * r0 * mu * t).max(0.0).sqrt();
            let d = densities(p, rt - p.bottom_radius);
            let sig_t = p.extinction(d);
            let seg_t = (-sig_t * dt).exp();
            // ∫_segment T dt / T_start = (1 − e^{−σ_t dt}) / σ_t (Hillaire's energy-conserving step).
            let integ = DVec3::select(sig_t.cmpgt(DVec3::splat(1e-30)), (DVec3::ONE - seg_t) / sig_t, DVec3::splat(dt));
            let w = tr * integ;
            out.push(ViewSample {
                t,
                rc: self.radial(rt),
                w_rayleigh: w * p.rayleigh_scattering * d[0],
                w_mie: w * p.mie_scattering * d[1],
            });
            tr *= seg_t;
        }
        (out, ground.map(|g| (g, tr)))
    }

    /// Radiance (per band, per unit solar irradiance) along a prepared view ray from radius `r0`,
    /// for a sun whose zenith cosine at the observer is `sun_y` and whose cosine with the view
    /// direction is `nu`.
    fn shade(&self, r0: f64, ray: &Marched, sun_y: f64, nu: f64) -> DVec3 {
        let p = &self.params;
        let (mut single_r, mut single_m, mut multi) = (DVec3::ZERO, DVec3::ZERO, DVec3::ZERO);
        for s in &ray.0 {
            // Sun zenith cosine at the sample: (x0 + t·d)·s / r with x0 = (0, r0, 0).
            let mu_s = ((r0 * sun_y + s.t * nu) / s.rc.r).clamp(-1.0, 1.0);
            let sun_t = self.trans_at(&s.rc, mu_s);
            single_r += s.w_rayleigh * sun_t;
            single_m += s.w_mie * sun_t;
            if p.multiple_scattering {
                multi += (s.w_rayleigh + s.w_mie) * self.ms_at(&s.rc, mu_s);
            }
        }
        let mut l = single_r * rayleigh_phase(nu) + single_m * cornette_shanks_phase(nu, p.mie_g) + multi;
        if let Some((tg, tr)) = ray.1 {
            let mu_g = ((r0 * sun_y + tg * nu) / p.bottom_radius).clamp(-1.0, 1.0);
            if mu_g > 0.0 {
                l += tr * self.transmittance(p.bottom_radius, mu_g) * mu_g * p.ground_albedo / PI;
            }
        }
        l
    }

    /// Sky radiance (W·m⁻²·sr⁻¹ per band) seen from altitude `altitude_m` (m) in unit direction
    /// `dir` (+y up), with the sun in unit direction `sun_dir`. The sun's disc is not included.
    pub fn sky_radiance(&self, altitude_m: f64, dir: DVec3, sun_dir: DVec3) -> DVec3 {
        let r0 = self.params.bottom_radius + altitude_m;
        let ray = self.march(r0, dir.y.clamp(-1.0, 1.0), VIEW_STEPS);
        self.shade(r0, &ray, sun_dir.y, dir.dot(sun_dir).clamp(-1.0, 1.0)) * self.params.solar_irradiance
    }

    /// The sun's irradiance (W/m² per band, on a plane facing it) at altitude `altitude_m` for a
    /// sun in unit direction `sun_dir`: solar irradiance × transmittance (direct integration).
    pub fn sun_irradiance(&self, altitude_m: f64, sun_dir: DVec3) -> DVec3 {
        let r0 = self.params.bottom_radius + altitude_m;
        self.params.solar_irradiance * self.params.transmittance_to_top(r0, sun_dir.y.clamp(-1.0, 1.0))
    }

    /// The whole sky as an equirectangular map of `width` × `height` pixels, in the convention of
    /// [`crate::lighting::envmap`] (row 0 = +y, u = atan2(z, x)/2π), rows in parallel.
    pub fn render_map(&self, altitude_m: f64, sun_dir: Vec3, width: usize, height: usize) -> Vec<Rgb> {
        let r0 = self.params.bottom_radius + altitude_m;
        let s = sun_dir.as_dvec3().normalize();
        let e = self.params.solar_irradiance;
        let mut px = vec![Rgb::ZERO; width * height];
        par::for_chunks(&mut px, width, &|j, row| {
            let theta = PI * (j as f64 + 0.5) / height as f64;
            let (sin_t, cos_t) = theta.sin_cos();
            let ray = self.march(r0, cos_t, VIEW_STEPS);
            for (i, out) in row.iter_mut().enumerate() {
                let phi = 2.0 * PI * (i as f64 + 0.5) / width as f64;
                let d = DVec3::new(sin_t * phi.cos(), cos_t, sin_t * phi.sin());
                let l = self.shade(r0, &ray, s.y, d.dot(s).clamp(-1.0, 1.0)) * e;
                *out = l.as_vec3();
            }
        });
        px
    }
}

/// March segments (midpoint t, length dt) over [0, t_end] along a ray from radius `r` with zenith
/// cosine `mu`: n segments, spaced quadratically away from the densest point (the start, or the
/// ray's lowest point, which gets n/2 on each side).
fn segments(r: f64, mu: f64, t_end: f64, n: usize) -> Vec<(f64, f64)> {
    // Segments from the dense end `a` towards `b`, in the order walked.
    fn side(a: f64, b: f64, k: usize) -> Vec<(f64, f64)> {
        let mut out = Vec::with_capacity(k);
        for i in 0..k {
            let (s0, s1) = (i as f64 / k as f64, (i + 1) as f64 / k as f64);
            let (t0, t1) = (a + (b - a) * s0 * s0, a + (b - a) * s1 * s1);
            let (lo, hi) = if t0 < t1 { (t0, t1) } else { (t1, t0) };
            if hi > lo {
                out.push((0.5 * (lo + hi), hi - lo));
            }
        }
        out
    }
    let t_low = (-r * mu).clamp(0.0, t_end);
    if t_low <= 0.0 {
        // Density falls from the start.
        side(0.0, t_end, n)
    } else if t_low >= t_end {
        // Density rises to the end (a ray hitting the ground): walk back from it, then reverse.
        let mut s = side(t_end, 0.0, n);
        s.reverse();
        s
    } else {
        let k = n / 2;
        let mut s = side(t_low, 0.0, k);
        s.reverse();
        s.extend(side(t_low, t_end, n - k));
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segments_tile_the_ray_in_order() {
        let p = AtmosphereParams::default();
        for (r, mu) in [
            (p.bottom_radius, 0.3),
            (p.bottom_radius + 20_000.0, -0.05),
            (p.bottom_radius + 5000.0, -0.9),
        ] {
            let t_end = p.distance_to_ground(r, mu).unwrap_or_else(|| p.distance_to_top(r, mu));
            let s = segments(r, mu, t_end, 40);
            let total: f64 = s.iter().map(|x| x.1).sum();
            assert!((total - t_end).abs() < 1e-6 * t_end);
            assert!(s.windows(2).all(|w| w[0].0 < w[1].0));
        }
    }

    #[test]
    fn lut_matches_direct_transmittance() {
        let atm = Atmosphere::new(AtmosphereParams {
            multiple_scattering: false,
            ..Default::default()
        });
        let p = &atm.params;
        for (h, mu) in [(0.0, 1.0), (0.0, 0.1), (3000.0, 0.02), (30_000.0, -0.1), (1000.0, 0.5)] {
            let r = p.bottom_radius + h;
            let a = atm.transmittance(r, mu);
            let b = p.transmittance_to_top(r, mu);
            // Bilinear interpolation of a 256×64 table: a few 1e-3 relative (where T is not tiny).
            assert!(
                (a - b).abs().max_element() < 5e-3 * b.max_element().max(1e-3),
                "{h} {mu}: {a} vs {b}"
            );
        }
    }
}
