//! The lit ground (paper section 3, last paragraph): upward hemicubes on a ground sample grid
//! over the area the cloud can shadow give the irradiance
//!
//!   E(x) = ∫_{ω·y>0} L(x, ω) (ω·y) dω + E_sun · max(ω_sun·y, 0) · T_sun(x) + E_peak(x),
//!
//! where L is the cloud-lit scene (cloud with colour I0 and the smooth part of the sun's single
//! scattering, sky behind) rendered on the hemicube, T_sun the exact (not δ-M) transmittance of
//! the cloud towards the sun, and E_peak the light the δ-M forward peak scatters, spread by the
//! peak's angles ([`super::ground_peak`]). Each hemicube pixel is weighted by its exact
//! cosine-weighted solid angle. The ground is Lambertian: radiance = albedo·E/π. Outside the grid
//! the unoccluded irradiance is used.
//!
//! **Area.** The rectangle (in x, z) covering the cloud's occupied voxels projected straight down,
//! widened on every side by the cloud top's height above the ground (beyond that the cloud is below
//! 45° elevation and blocks little sky), united with the occupied box projected along the sun
//! onto the ground (its shadow; for suns lower than ω_sun·y = 0.1 the shadow is projected as if
//! the sun were at that height, so a grazing sun cannot stretch the grid without bound).

use super::ground_peak::GroundPeak;
use super::render::{BinMask, CubeOptions, CubeRenderer, LevelTables, PixelTable};
use crate::lighting::bins::cube_pixel;
use crate::lighting::{EnvMap, Ground, Sky};
pub use crate::lit::ground::{GroundGrid, LitGround};
use crate::lit::LitVolume;
use crate::math::{Rgb, Vec3};
use crate::pipeline::Progress;
use crate::par;

/// The (x, z) rectangle the ground grid covers for this cloud and sun (see the module docs);
/// None for an empty cloud.
pub fn ground_area(lit: &LitVolume, ground: &Ground) -> Option<([f32; 2], [f32; 2])> {
    let m = &lit.medium;
    let d = m.dims();
    let (mut lo, mut hi) = ([usize::MAX; 3], [0usize; 3]);
    let mut any = false;
    for k in 0..d[2] {
        for j in 0..d[1] {
            for i in 0..d[0] {
                if m.density.get(i, j, k) > 0.0 {
                    any = true;
                    for (a, x) in [i, j, k].into_iter().enumerate() {
                        lo[a] = lo[a].min(x);
                        hi[a] = hi[a].max(x);
                    }
                }
            }
        }
    }
    if !any {
        return None;
    }
    // One voxel of apron: the trilinear field reaches half a voxel beyond the centres.
    let bmin = m.origin + m.voxel_size * Vec3::new(lo[0] as f32, lo[1] as f32, lo[2] as f32) - m.voxel_size;
    let bmax = m.origin + m.voxel_size * Vec3::new(hi[0] as f32 + 2.0, hi[1] as f32 + 2.0, hi[2] as f32 + 2.0);
    let height = (bmax.y - ground.height).max(0.0);
    let mut rmin = [bmin.x - height, bmin.z - height];
    let mut rmax = [bmax.x + height, bmax.z + height];
    let s = lit.sun.dir;
    if s.y > 0.0 {
        let sy = s.y.max(0.1);
        for c in 0..8 {
            let p = Vec3::new(
                if c & 1 == 0 { bmin.x } else { bmax.x },
                if c & 2 == 0 { bmin.y } else { bmax.y },
                if c & 4 == 0 { bmin.z } else { bmax.z },
            );
            let up = (p.y - ground.height).max(0.0);
            let q = [p.x - s.x / sy * up, p.z - s.z / sy * up];
            rmin = [rmin[0].min(q[0]), rmin[1].min(q[1])];
            rmax = [rmax[0].max(q[0]), rmax[1].max(q[1])];
        }
    }
    Some((rmin, rmax))
}

/// Exact cosine-weighted solid angle ∫ max(ω·y, 0) dω of every cube pixel at `res` (index as
/// [`super::CubeImage::index`]); they sum to π. Gauss–Legendre 8×8 per pixel (smooth integrand).
pub fn hemicube_weights(res: usize) -> Vec<f64> {
    use crate::lighting::bins::{GL8_W, GL8_X};
    let mut out = vec![0.0; 6 * res * res];
    for (face, f) in crate::lighting::CUBE_FACES.iter().enumerate() {
        for j in 0..res {
            for i in 0..res {
                let (u0, u1) = super::CubeImage::pixel_range(res, i);
                let (v0, v1) = super::CubeImage::pixel_range(res, j);
                let mut s = 0.0;
                for (xi, wi) in GL8_X.iter().zip(GL8_W) {
                    let u = 0.5 * (u0 + u1) + 0.5 * (u1 - u0) * xi;
                    for (xj, wj) in GL8_X.iter().zip(GL8_W) {
                        let v = 0.5 * (v0 + v1) + 0.5 * (v1 - v0) * xj;
                        let r2 = 1.0 + u * u + v * v;
                        // ω = (n + u tu + v tv)/r, dω = du dv / r³, so (ω·y) dω = (n + u tu + v tv)·y du dv / r⁴.
                        let y = f.n.y as f64 + u * f.tu.y as f64 + v * f.tv.y as f64;
                        s += wi * wj * y.max(0.0) / (r2 * r2);
                    }
                }
                out[(face * res + j) * res + i] = s * 0.25 * (u1 - u0) * (v1 - v0);
            }
        }
    }
    out
}

/// A hemicube's pixels at one resolution: each one's exact cosine-weighted solid angle
/// ([`hemicube_weights`]) and the sky's mean radiance over it, weighted likewise. The sky lies at
/// infinity, so every ground point sees it through the same pixels: built once per ground.
#[derive(Clone, Debug)]
pub struct Hemicube {
    /// Pixels per face edge.
    pub res: usize,
    /// ∫ max(ω·y, 0) dω per pixel (sr), index as [`super::CubeImage::index`].
    pub weights: Vec<f64>,
    /// The sky's cosine-weighted mean radiance per pixel (W·m⁻²·sr⁻¹), same index (unused below
    /// the horizon, where the weight is 0).
    pub sky: Vec<Rgb>,
}

impl Hemicube {
    /// The hemicube at `res` under `sky`.
    pub fn new(res: usize, sky: &Sky) -> Hemicube {
        let weights = hemicube_weights(res);
        let sky = match sky.map() {
            Some(map) => sky_cosine_means(map, res, &weights),
            // A constant sky is its value on every pixel's axis.
            None => PixelTable::new(res).dirs.iter().map(|d| sky.radiance(*d)).collect(),
        };
        Hemicube { res, weights, sky }
    }
}

/// Row bands of the map integrated in parallel (fixed, so the sums do not depend on the threads).
const SKY_BANDS: usize = 16;

/// The map's cosine-weighted mean radiance over each upper-hemisphere pixel of a `res` hemicube
/// (`weights` its [`hemicube_weights`]): the pixel's share of the map's irradiance over its exact
/// weight, so the pixels together hold the whole of it. A sample on the pixel's axis would miss a
/// sun one map pixel wide, or count it over the whole pixel's solid angle.
fn sky_cosine_means(map: &EnvMap, res: usize, weights: &[f64]) -> Vec<Rgb> {
    sky_cosine_power(map, res)
        .iter()
        .zip(weights)
        .map(|([r, g, b], w)| if *w > 0.0 { Rgb::new((r / w) as f32, (g / w) as f32, (b / w) as f32) } else { Rgb::ZERO })
        .collect()
}

/// ∫ L cosθ dω (W/m² per band) of the map over each pixel of a `res` cube: the map's sub-pixels,
/// each added to the pixel its centre falls in.
fn sky_cosine_power(map: &EnvMap, res: usize) -> Vec<[f64; 3]> {
    // Sub-pixels an eighth of the narrowest cube pixel (a third of its edge 2/res, in rad, at a
    // face's corner) wide: a pixel's edge misplaces at most an eighth of its width.
    let k = map.subpixels_within(2.0 / (3.0 * res as f64) / 8.0);
    let upper_rows = map.height.div_ceil(2);
    let bands = par::map_range(SKY_BANDS, &|band| {
        let mut power = vec![[0f64; 3]; 6 * res * res];
        let rows = band * upper_rows / SKY_BANDS..(band + 1) * upper_rows / SKY_BANDS;
        map.for_each_subpixel(rows, k, &mut |dir, l, solid_angle| {
            if dir.y > 0.0 {
                let c = solid_angle * dir.y as f64;
                for (s, x) in power[cube_pixel(res, dir)].iter_mut().zip([l.x, l.y, l.z]) {
                    *s += x as f64 * c;
                }
            }
        });
        power
    });
    let mut power = vec![[0f64; 3]; 6 * res * res];
    for band in &bands {
        for (sum, p) in power.iter_mut().zip(band) {
            for (s, x) in sum.iter_mut().zip(p) {
                *s += x;
            }
        }
    }
    power
}

/// Irradiance (W/m²) on an upward-facing ground point `p` from the hemicube plus the sun and its
/// peak. `hemicube` is at the renderer's `opts.res`.
pub fn hemicube_irradiance(renderer: &CubeRenderer<'_>, hemicube: &Hemicube, p: Vec3) -> Rgb {
    let lit = renderer.lit;
    let peak = GroundPeak::new(lit).map_or(Rgb::ZERO, |k| k.irradiance(lit, p));
    hemicube_sky(renderer, hemicube, p) + sun_irradiance(lit, p) + peak
}

/// The hemicube's part of [`hemicube_irradiance`]: Σ L·w over the upper hemisphere's pixels
/// (cloud and sky, W/m²).
fn hemicube_sky(renderer: &CubeRenderer<'_>, hemicube: &Hemicube, p: Vec3) -> Rgb {
    let res = renderer.opts.res;
    assert_eq!(hemicube.res, res, "the hemicube is for another resolution");
    let mut acc = [0f64; 3];
    for b in BinMask::upper_hemisphere().iter() {
        for (face, i, j) in renderer.pixels.bin_pixels(b) {
            let k = (face * res + j) * res + i;
            let w = hemicube.weights[k];
            if w <= 0.0 {
                continue;
            }
            let l = renderer.trace_to_sky(p, renderer.pixels.dirs[k], renderer.pixels.cone[j * res + i], hemicube.sky[k]);
            acc[0] += l.x as f64 * w;
            acc[1] += l.y as f64 * w;
            acc[2] += l.z as f64 * w;
        }
    }
    Rgb::new(acc[0] as f32, acc[1] as f32, acc[2] as f32)
}

/// The sun's unscattered part of [`hemicube_irradiance`]: E_sun·cosθ_sun·T_sun with the exact
/// transmittance T = T′^{σt/σt′} (the light δ-M's T′ holds beyond it is [`GroundPeak`]'s).
fn sun_irradiance(lit: &LitVolume, p: Vec3) -> Rgb {
    let sun = &lit.sun;
    if sun.dir.y > 0.0 {
        let t_scaled = lit.medium.transmittance(p, sun.dir, 0.0, f32::INFINITY);
        sun.irradiance * (sun.dir.y * t_scaled.powf(lit.medium.optics.extinction_ratio()))
    } else {
        Rgb::ZERO
    }
}

/// Spacing (samples) of the ground grid's first pass of hemicubes; the finer passes trace only
/// where the hemicube light of the pass before varies ([`super::refine`]).
pub const GROUND_COARSE: usize = 4;

/// Spread of the hemicube sums (with the peak's light, [`GroundPeak`]) around a ground sample,
/// relative to the largest plus the sample's own sunlight, below which the sample's hemicube and
/// peak are interpolated from them
/// ([`super::refine::refine`]); the sun's shadow, the sharp part, is exact at every sample.
/// Measured on the default and evaluation scenes: block MRE ≤ 2.7·10⁻⁴ against every hemicube
/// traced, 271 of the 1024 hemicubes traced on the default scene (docs/performance.md).
pub const GROUND_TOLERANCE: f32 = 0.02;

/// Render `opts.ground_samples`² hemicubes of `opts.ground_res` pixels per face edge over
/// [`ground_area`] and return the lit ground.
pub fn render_ground(lit: &LitVolume, ground: &Ground, opts: &CubeOptions, progress: &dyn Progress) -> LitGround {
    render_ground_with(&ground_renderer(lit, opts, LevelTables::new(lit, opts)), ground, progress)
}

/// The hemicubes' renderer over `lit` (`tables` made for its pyramid): [`ground_options`], and
/// the sun's single scattering with the δ-M medium's own (a′, HG(g′)), its smooth part: the peak's
/// part is [`GroundPeak`]'s.
pub fn ground_renderer<'a>(lit: &'a LitVolume, opts: &CubeOptions, tables: LevelTables) -> CubeRenderer<'a> {
    let mut renderer = CubeRenderer::with_tables(lit, &ground_options(opts), tables);
    renderer.sun_transformed = true;
    renderer
}

/// The hemicubes' renderer options: `opts` at the ground's resolution.
pub fn ground_options(opts: &CubeOptions) -> CubeOptions {
    CubeOptions {
        res: opts.ground_res,
        ..opts.clone()
    }
}

/// [`render_ground`] with a renderer already built ([`ground_renderer`]).
pub fn render_ground_with(renderer: &CubeRenderer<'_>, ground: &Ground, progress: &dyn Progress) -> LitGround {
    let lit = renderer.lit;
    let mut out = LitGround::unoccluded(ground.clone(), &lit.sun, &lit.sky);
    let Some((min, max)) = ground_area(lit, ground) else {
        return out;
    };
    let n = renderer.opts.ground_samples;
    let hemicube = Hemicube::new(renderer.opts.res, &lit.sky);
    let mut grid = GroundGrid {
        min,
        max,
        n,
        irradiance: vec![Rgb::ZERO; n * n],
    };
    // Just above the plane, so upward rays start on the visible side.
    let y = ground.height + 1e-3 * lit.medium.min_voxel();
    let at = |a: usize, b: usize| {
        let [x, z] = grid.sample_xz(a, b);
        Vec3::new(x, y, z)
    };
    progress.begin("ground hemicubes", (n * n) as u64);
    // The sun's shadow (the sharp part) at every sample, the hemicube light and the peak's
    // (smooth on the ground) adaptively, to a tolerance relative to the whole irradiance.
    let sun = par::map_range(n * n, &|k| sun_irradiance(lit, at(k % n, k / n)));
    // The peak's light is spread over tens of metres: smooth on the ground like the hemicubes'.
    let peak = GroundPeak::new(lit);
    let (sky, traced) = super::refine::refine(n, GROUND_COARSE, GROUND_TOLERANCE, &sun, &|a, b| {
        progress.advance(1);
        let p = at(a, b);
        hemicube_sky(renderer, &hemicube, p) + peak.as_ref().map_or(Rgb::ZERO, |g| g.irradiance(lit, p))
    });
    progress.advance((n * n - traced) as u64);
    progress.end();
    grid.irradiance = sky.iter().zip(&sun).map(|(d, s)| *d + *s).collect();
    out.grid = Some(grid);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::Sun;
    use crate::medium::{Grid3, Medium};

    /// An empty scene under a map sky of 0.5 W·m⁻²·sr⁻¹ with a sun one map pixel wide (10⁸ times
    /// brighter; a map pixel is a fifteenth of a cube pixel there): the hemicube gives the map's
    /// irradiance, the sun's power whatever cube pixel's axis it lies near.
    #[test]
    fn a_sun_one_map_pixel_wide_lights_the_hemicube_by_its_power() {
        let (w, h) = (256, 128);
        let mut pixels = vec![Rgb::splat(0.5); w * h];
        pixels[30 * w + 20] = Rgb::splat(5e7);
        let sky = Sky::from_envmap(EnvMap::new(w, h, pixels));
        let sun = Sun {
            dir: Vec3::Y,
            irradiance: Rgb::ZERO,
        };
        let empty = Medium::new(Grid3::filled([2, 2, 2], 0.0), Vec3::ZERO, Vec3::ONE, 1.0, Rgb::ONE, 0.0);
        let lit = LitVolume::new(empty, vec![Rgb::ZERO; 8], Grid3::filled([2, 2, 2], 1.0), sun, sky, None);
        let res = CubeOptions::default().ground_res;
        let renderer = CubeRenderer::new(&lit, &ground_options(&CubeOptions::default()));
        let e = hemicube_irradiance(&renderer, &Hemicube::new(res, &lit.sky), Vec3::new(3.0, -1.0, 2.0));
        // The sky's π·0.5 and the sun pixel's power: its radiance over the map pixel
        // (dω = 2π² sinθ du dv) times cosθ, at its centre θ (exact to 10⁻³ for one pixel).
        let theta = std::f64::consts::PI * 30.5 / h as f64;
        let sun_power = 5e7 * 2.0 * std::f64::consts::PI.powi(2) * theta.sin() * theta.cos() / (w * h) as f64;
        let exact = Rgb::splat((0.5 * std::f64::consts::PI + sun_power) as f32);
        assert!(((e - exact).abs() / exact).max_element() < 2e-3, "{e} vs {exact}");
    }
}
