//! The sun's light that the δ-M forward peak scatters onto the ground.
//!
//! `full`'s medium is δ-M scaled (`render.forward_fraction` f): its transmittance towards the sun
//! T′ = T^{σt/σt′} holds, beside the unscattered sun T, the light peak-scattered one or more times
//! on the way, as if it went on straight. Counted as direct sun it lands exactly in the cloud's
//! shadow; it really leaves the cloud turned by the peak's angles and lands spread around it, over
//! the peak's width × its distance from the ground. So the ground's direct sun is T (exact) and the
//! peak's light is gathered over the directions ω of the sky around the sun, from the last peak
//! scattering on each ray x + tω:
//!
//!   E_peak(x) = E_⊙ ∫_{ω·y>0} (ω·y) dω ∫ dt a σt ρ(y) T′_⊙(y) [f P]_λ(y)(ω·ω_⊙)/(4π) T(x, y),
//!
//! T′_⊙(y) the δ-M transmittance from y to the sun (the lit volume's grid: every peak scattering on
//! the sun's leg counted in the beam), [f P]_λ the peak with the λ = af τ_⊙(y) peak scatterings on
//! that leg spreading it ([`PeakSpread::peak_with`], as the final gather spreads the eye's sun
//! term), and T(x, y) the exact transmittance back to the ground (no scattering after the last).
//! Integrated over the ground it gives the light T′ − T that the δ-M beam holds beyond the
//! unscattered sun (for a slab and small angles: ∫ af σ e^{−(1−af)τ(t,∞)} e^{−τ(0,t)} dτ = T′ − T).
//!
//! The smooth part of the scattering, (1 − f) HG(g′), is the hemicubes' (their sun single
//! scattering with the δ-M medium's own a′ and g′, `CubeRenderer::sun_transformed`), and the light
//! scattered more than once the diffusion's I0 of the same δ-M medium: every stage sees one
//! transform, and no peak-scattered path is counted twice.

use crate::lit::LitVolume;
use crate::math::{Rgb, Vec3};
use crate::peak::PeakSpread;
use std::f64::consts::PI;

/// Panel edges (degrees from the sun) of the angular quadrature: fine where the peak is (half
/// its weight within 6.5° for g = 0.9, f = 0.65), coarser out to the antisolar point, where the
/// spread peak of many scatterings (orders 0 and 1 only) still reaches.
const PANELS_DEG: [f64; 12] = [0.0, 1.5, 4.0, 8.0, 14.0, 22.0, 32.0, 45.0, 62.0, 85.0, 120.0, 180.0];

/// Azimuths around the sun per polar node.
const AZIMUTHS: usize = 8;

/// The peak's spread is tabulated in λ up to this (the beam is then T′ ≤ e^{−λ σt′/(σt − σt′)},
/// below 10⁻³ for f ≤ 0.8), in steps of [`LAMBDA_STEP`].
const LAMBDA_MAX: f64 = 16.0;
const LAMBDA_STEP: f64 = 0.25;

/// A ray's march stops when its exact transmittance back to the ground falls below this.
const T_CUTOFF: f64 = 1e-4;

/// One direction of the quadrature.
struct Node {
    /// Unit direction towards the sky.
    dir: Vec3,
    /// Solid angle × ω·y (sr).
    weight: f64,
    /// Index of its polar angle in [`GroundPeak::tables`].
    polar: usize,
}

/// The peak's light on the ground for one lit volume: its quadrature and tables.
pub struct GroundPeak {
    nodes: Vec<Node>,
    /// Per polar angle, [f P]_λ(cos Θ)/(4π) at λ = 0, LAMBDA_STEP, .., LAMBDA_MAX.
    tables: Vec<Vec<f64>>,
    /// af/(1 − af): λ = this × τ′_⊙.
    lambda_per_tau: f64,
    /// The true albedo a per band.
    albedo: Rgb,
    /// The true extinction σt at density 1 (m⁻¹).
    sigma_t: f64,
}

impl GroundPeak {
    /// The peak of `lit`'s δ-M medium; None without a transform (f = 0: T′ = T, nothing to
    /// spread) or with the sun below the horizon.
    pub fn new(lit: &LitVolume) -> Option<GroundPeak> {
        let optics = &lit.medium.optics;
        let f = optics.forward_fraction();
        let sun = lit.sun.dir;
        if f <= 0.0 || sun.y <= 0.0 {
            return None;
        }
        let spread = PeakSpread::similarity(optics.sun_single.1.mean_cosine(), f);
        let ratio = optics.extinction_ratio();
        // Two unit vectors across the sun's direction.
        let e1 = if sun.x.abs() < 0.9 { Vec3::X } else { Vec3::Z };
        let e1 = (e1 - sun * sun.dot(e1)).normalize();
        let e2 = sun.cross(e1);
        let half = 1.0 / 3f64.sqrt();
        let steps = (LAMBDA_MAX / LAMBDA_STEP).round() as usize;
        let (mut nodes, mut tables) = (Vec::new(), Vec::new());
        for pair in PANELS_DEG.windows(2) {
            let (a, b) = (pair[0].to_radians(), pair[1].to_radians());
            // Gauss–Legendre, two nodes per panel.
            for x in [-half, half] {
                let theta = 0.5 * (a + b) + 0.5 * (b - a) * x;
                let d_theta = 0.5 * (b - a);
                let legendre = spread.legendre_all(theta.cos());
                let polar = tables.len();
                tables.push(
                    (0..=steps)
                        .map(|i| spread.peak_with(i as f64 * LAMBDA_STEP, &legendre) / (4.0 * PI))
                        .collect(),
                );
                for j in 0..AZIMUTHS {
                    let phi = 2.0 * PI * (j as f64 + 0.5) / AZIMUTHS as f64;
                    let (s, c) = (theta.sin() as f32, theta.cos() as f32);
                    let dir = (sun * c + (e1 * phi.cos() as f32 + e2 * phi.sin() as f32) * s).normalize();
                    if dir.y <= 0.0 {
                        continue;
                    }
                    let weight = theta.sin() * d_theta * (2.0 * PI / AZIMUTHS as f64) * dir.y as f64;
                    nodes.push(Node { dir, weight, polar });
                }
            }
        }
        Some(GroundPeak {
            nodes,
            tables,
            lambda_per_tau: (ratio - 1.0).max(0.0) as f64,
            albedo: optics.sun_single.0 / ratio,
            sigma_t: optics.sigma_t as f64 * ratio as f64,
        })
    }

    /// [f P]_λ/(4π) along polar node `polar` (linear in λ between the table's entries).
    #[inline]
    fn peak(&self, polar: usize, lambda: f64) -> f64 {
        let table = &self.tables[polar];
        let x = (lambda / LAMBDA_STEP).clamp(0.0, (table.len() - 1) as f64);
        let i = (x as usize).min(table.len() - 2);
        let u = x - i as f64;
        table[i] * (1.0 - u) + table[i + 1] * u
    }

    /// E_peak (W/m²) at ground point `p` (see the module docs): one march per direction of the
    /// quadrature over the lit volume's dual cells (empty blocks skipped), the sun's δ-M
    /// transmittance read at each cell's middle.
    pub fn irradiance(&self, lit: &LitVolume, p: Vec3) -> Rgb {
        let m = &lit.medium;
        let sun_t = lit.sun_t();
        let mut sum = 0.0;
        for node in &self.nodes {
            let Some((t0, t1)) = m.intersect(p, node.dir, 0.0, f32::INFINITY) else {
                continue;
            };
            let (mut tr, mut ray) = (1.0f64, 0.0f64);
            m.for_each_dual_run(p, node.dir, t0, t1, |cells| {
                for c in cells {
                    if tr < T_CUTOFF {
                        return;
                    }
                    let v = m.to_voxel(p + node.dir * (0.5 * (c.t0 + c.t1)) as f32).to_array();
                    let rho = m.density.trilinear(v) as f64;
                    if rho <= 0.0 {
                        continue;
                    }
                    let t_sun = sun_t.trilinear(v) as f64;
                    let e = (-self.sigma_t * rho * (c.t1 - c.t0)).exp();
                    if t_sun > 0.0 {
                        let lambda = -self.lambda_per_tau * t_sun.ln();
                        ray += tr * (1.0 - e) * t_sun * self.peak(node.polar, lambda);
                    }
                    tr *= e;
                }
            });
            sum += node.weight * ray;
        }
        lit.sun.irradiance * self.albedo * sum as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::{Sky, Sun};
    use crate::lit::sunlight::SunTransmittance;
    use crate::medium::{Grid3, Medium};

    /// g = 0.9 at 1 m voxels, true σt `sigma_t` (m⁻¹), albedo 1, δ-M at `full`'s f = 0.65, lit by
    /// a sun of unit irradiance from `sun_dir`.
    fn lit(grid: Grid3, origin: Vec3, sigma_t: f32, sun_dir: Vec3) -> LitVolume {
        let mut m = Medium::new(grid, origin, Vec3::ONE, sigma_t, Rgb::ONE, 0.9);
        m.optics = m.optics.delta_m(0.65);
        let n = m.density.len();
        let sun = Sun {
            dir: sun_dir.normalize(),
            irradiance: Rgb::ONE,
        };
        let sun_t = SunTransmittance::compute(&m, sun.dir).grid;
        LitVolume::new(m, vec![Rgb::ZERO; n], sun_t, sun, Sky::constant(Rgb::ZERO), None)
    }

    /// The δ-M and the exact transmittance towards the sun from `p`.
    fn t_pair(lit: &LitVolume, p: Vec3) -> (f64, f64) {
        let tau = lit.medium.optical_depth(p, lit.sun.dir, 0.0, f32::INFINITY) as f64;
        ((-tau).exp(), (-tau * lit.medium.optics.extinction_ratio() as f64).exp())
    }

    /// The peak's light moves but is not lost: under a uniform sphere (true optical diameter
    /// 1.5) 30 m above the ground, the ground's E_peak summed over a wide area is the sun's
    /// E μ_⊙ (T′ − T) summed over the shadow (the light δ-M's T′ would have put into it), within
    /// 3 %, for a high and a low sun; and under the sphere it is less than that (spread out).
    #[test]
    fn the_spread_peak_keeps_its_energy_over_the_ground() {
        let (n, r) = (24usize, 10.0f32);
        let mut g = Grid3::filled([n; 3], 0.0);
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let c = Vec3::new(i as f32, j as f32, k as f32) + 0.5 - n as f32 / 2.0;
                    g.set(i, j, k, if c.length() < r { 1.0 } else { 0.0 });
                }
            }
        }
        let centre_height = 30.0;
        let origin = Vec3::new(-(n as f32) / 2.0, centre_height - n as f32 / 2.0, -(n as f32) / 2.0);
        for sun_dir in [Vec3::Y, Vec3::new(0.5, 1.0, 0.2)] {
            let lit = lit(g.clone(), origin, 1.5 / (2.0 * r), sun_dir);
            let peak = GroundPeak::new(&lit).expect("a δ-M medium has a peak");
            let s = lit.sun.dir;
            // The shadow's centre on the ground.
            let c = Vec3::new(0.0, centre_height, 0.0) - s * (centre_height / s.y);
            let sum = |half: f32, cells: usize, f: &dyn Fn(Vec3) -> f64| {
                let h = 2.0 * half / cells as f32;
                let mut acc = 0.0;
                for b in 0..cells {
                    for a in 0..cells {
                        let p = Vec3::new(c.x - half + (a as f32 + 0.5) * h, 0.0, c.z - half + (b as f32 + 0.5) * h);
                        acc += f(p) * (h * h) as f64;
                    }
                }
                acc
            };
            let spread = sum(90.0, 60, &|p| peak.irradiance(&lit, p).y as f64);
            let straight = sum(25.0, 200, &|p| {
                let (tp, t) = t_pair(&lit, p);
                s.y as f64 * (tp - t)
            });
            assert!(straight > 50.0, "the sphere casts a peak: {straight}");
            assert!((spread / straight - 1.0).abs() < 0.03, "sun {s}: spread {spread} vs straight {straight}");
            let (tp, t) = t_pair(&lit, c);
            let under = peak.irradiance(&lit, c).y as f64;
            assert!(under > 0.0 && under < 0.9 * s.y as f64 * (tp - t), "{under} vs {}", s.y as f64 * (tp - t));
        }
    }

    /// A thin half-plane (x < 0, true vertical depth 0.01) 40 m above the ground, the sun
    /// overhead: across the edge's shadow the peak's light rises from 0 to its value under the
    /// layer over the distance the peak's angles reach at 40 m, as the peak's own phase function
    /// (HG(g) − (1 − f) HG(g′))/f, integrated over the directions that meet the layer, says
    /// (single peak scattering: λ ≈ 0.006), within 0.05 of the value under the layer.
    #[test]
    fn a_shadow_edge_is_blurred_by_the_peaks_width() {
        let (nx, nz, height) = (160usize, 160usize, 40.0f32);
        let mut g = Grid3::filled([nx, 3, nz], 0.0);
        for k in 0..nz {
            for i in 0..150 {
                g.set(i, 1, k, 1.0);
            }
        }
        // Voxel centres x = −149.5 .. 9.5: the density falls from 1 to 0 across x = 0.
        let lit = lit(g, Vec3::new(-150.0, height - 1.5, -80.0), 0.01, Vec3::Y);
        let peak = GroundPeak::new(&lit).expect("a δ-M medium has a peak");
        let (gf, f) = (0.9f64, 0.65f64);
        let gp = (gf - f) / (1.0 - f);
        let hg = |g: f64, c: f64| (1.0 - g * g) / (1.0 + g * g - 2.0 * g * c).powf(1.5);
        let p_hat = |c: f64| (hg(gf, c) - (1.0 - f) * hg(gp, c)) / f;
        // ∫ P(Θ) dω over the directions from (x, 0, 0) that meet the layer's mid-plane inside it.
        let expected = |x: f64| {
            let (ns, nphi) = (1500, 360);
            let mut acc = 0.0;
            for a in 0..ns {
                let s = (a as f64 + 0.5) / ns as f64;
                let theta = 0.5 * PI * s * s;
                let d_theta = PI * s / ns as f64;
                let reach = height as f64 * theta.tan();
                for b in 0..nphi {
                    let phi = 2.0 * PI * (b as f64 + 0.5) / nphi as f64;
                    let (hx, hz) = (x + reach * phi.cos(), reach * phi.sin());
                    if hx > -150.0 && hx < 0.0 && hz.abs() < 80.0 {
                        acc += p_hat(theta.cos()) * theta.sin() * d_theta * 2.0 * PI / nphi as f64;
                    }
                }
            }
            acc
        };
        let at = |x: f32| peak.irradiance(&lit, Vec3::new(x, 0.0, 0.0)).y as f64;
        let (deep, deep_expected) = (at(-40.0), expected(-40.0));
        assert!(deep > 0.0);
        for x in [-12.0, -5.0, -2.0, 0.0, 2.0, 5.0, 12.0] {
            let (got, want) = (at(x) / deep, expected(x as f64) / deep_expected);
            assert!((got - want).abs() < 0.05, "x {x} m: {got:.3} of the value under the layer, expected {want:.3}");
        }
        // The blur is the peak's: a quarter of the light still lands 2 m beyond the edge.
        assert!(expected(2.0) / deep_expected > 0.2);
    }
}
