//! Equirectangular environment maps: storage, lookup, file input/output and importance sampling.
//!
//! Convention (the same for `sky.model = "envmap"` input and `cloudgi sky` output), with +y up:
//!
//! - pixel (column i, row j) of a W × H map covers u ∈ [i/W, (i+1)/W], v ∈ [j/H, (j+1)/H];
//! - polar angle θ = π·v from +y: **row 0 is the top (+y, zenith)**, the last row is −y;
//! - azimuth φ = 2π·u measured from +x towards +z: direction = (sin θ cos φ, cos θ, sin θ sin φ).
//!   So the left edge (u = 0) looks along +x, u = 1/4 along +z, u = 1/2 along −x, u = 3/4 along −z;
//!   φ is the scene file's `sun.azimuth_deg`, and u = atan2(z, x)/2π (wrapped to [0, 1)).
//!
//! Radiance between pixel centres is bilinear (wrapping in u, clamped in v). Sampling draws
//! directions from a piecewise-constant density proportional to (Y_max + ε)·sin θ per pixel, Y_max
//! the largest luminance of the pixel and its eight neighbours: the bilinear radiance anywhere in
//! a pixel blends those nine centres, so radiance over density stays bounded even where a sun's
//! light bleeds into the pixels around it (ε = 10⁻³ × the mean luminance keeps the density
//! positive wherever radiance can be).

use super::bins::cube_pixel;
use crate::error::{Error, Result};
use crate::image::Image;
use crate::math::{luminance, Rgb, Vec3};
use glam::Vec2;
use std::f32::consts::PI;

/// Fewest map samples along the narrowest cell's edge in [`EnvMap::cell_means`]: a map coarser
/// than that is read at several bilinear points per pixel, a finer one at its pixels.
pub const SAMPLES_PER_CELL_EDGE: f64 = 64.0;

/// Map rows summed per parallel task in [`EnvMap::cell_means`].
const ROWS_PER_BLOCK: usize = 16;

/// An equirectangular radiance map with its sampling distribution.
#[derive(Clone)]
pub struct EnvMap {
    /// Width (pixels).
    pub width: usize,
    /// Height (pixels).
    pub height: usize,
    /// Radiance (W·m⁻²·sr⁻¹ per band), row-major, row 0 = +y.
    pub pixels: Vec<Rgb>,
    /// Sampling weight f_ij = (Y_max + ε)·sin θ_j per pixel, Y_max over the pixel and its neighbours.
    weight: Vec<f64>,
    /// Per row: cumulative weights over columns (length W + 1), unnormalised.
    row_cdf: Vec<f64>,
    /// Cumulative row sums (length H + 1), unnormalised.
    marginal_cdf: Vec<f64>,
}

impl std::fmt::Debug for EnvMap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "EnvMap({}×{})", self.width, self.height)
    }
}

/// Direction of map coordinates (u, v) ∈ [0, 1]².
#[inline]
pub fn direction(u: f32, v: f32) -> Vec3 {
    let (st, ct) = (PI * v).sin_cos();
    let (sp, cp) = (2.0 * PI * u).sin_cos();
    Vec3::new(st * cp, ct, st * sp)
}

/// Map coordinates (u, v) ∈ [0, 1)×[0, 1] of a unit direction.
#[inline]
pub fn uv(dir: Vec3) -> (f32, f32) {
    let mut u = dir.z.atan2(dir.x) / (2.0 * PI);
    if u < 0.0 {
        u += 1.0;
    }
    if u >= 1.0 {
        u = 0.0;
    }
    (u, dir.y.clamp(-1.0, 1.0).acos() / PI)
}

impl EnvMap {
    /// A map from `width` × `height` radiance pixels (row 0 = +y). `pixels.len()` must be
    /// width·height and every value finite and non-negative (checked by the loaders).
    pub fn new(width: usize, height: usize, pixels: Vec<Rgb>) -> EnvMap {
        assert!(width >= 1 && height >= 1 && pixels.len() == width * height, "EnvMap::new: bad size");
        let mean = pixels.iter().map(|p| luminance(*p).max(0.0) as f64).sum::<f64>() / pixels.len() as f64;
        let eps = if mean > 0.0 { 1e-3 * mean } else { 1.0 };
        let mut weight = Vec::with_capacity(width * height);
        let mut row_cdf = Vec::with_capacity((width + 1) * height);
        let mut marginal_cdf = Vec::with_capacity(height + 1);
        marginal_cdf.push(0.0);
        let lum: Vec<f32> = pixels.iter().map(|p| luminance(*p).max(0.0)).collect();
        // The largest luminance of each pixel's row neighbours (wrapping), then of its column's.
        let row_max: Vec<f32> = (0..width * height)
            .map(|k| {
                let (i, j) = (k % width, k / width);
                let at = |di: usize| lum[j * width + (i + width + di - 1) % width];
                at(0).max(at(1)).max(at(2))
            })
            .collect();
        for j in 0..height {
            let sin_t = (std::f64::consts::PI * (j as f64 + 0.5) / height as f64).sin();
            let mut acc = 0.0;
            row_cdf.push(0.0);
            let rows = j.saturating_sub(1)..(j + 2).min(height);
            for i in 0..width {
                let y_max = rows.clone().map(|r| row_max[r * width + i]).fold(0.0_f32, f32::max);
                let f = (y_max as f64 + eps) * sin_t;
                weight.push(f);
                acc += f;
                row_cdf.push(acc);
            }
            let last = *marginal_cdf.last().unwrap_or(&0.0);
            marginal_cdf.push(last + acc);
        }
        EnvMap {
            width,
            height,
            pixels,
            weight,
            row_cdf,
            marginal_cdf,
        }
    }

    /// A map from an image, radiance multiplied by `scale`; `file` names it in errors.
    pub fn from_image(img: &Image, scale: f32, file: &str) -> Result<EnvMap> {
        if img.width < 2 || img.height < 1 {
            return Err(Error::format(
                file,
                format!(
                    "an environment map needs at least 2×1 pixels, this one is {}×{}",
                    img.width, img.height
                ),
            ));
        }
        if let Some(k) = img.pixels.iter().position(|p| !p.is_finite() || p.min_element() < 0.0) {
            let (x, y) = (k as u32 % img.width, k as u32 / img.width);
            return Err(Error::format(
                file,
                format!(
                    "pixel ({x}, {y}) is {}: an environment map must hold finite, non-negative radiance",
                    img.pixels[k]
                ),
            ));
        }
        Ok(EnvMap::new(
            img.width as usize,
            img.height as usize,
            img.pixels.iter().map(|p| *p * scale).collect(),
        ))
    }

    /// The map as an image (same pixels, same convention).
    pub fn to_image(&self) -> Image {
        let mut img = Image::new(self.width as u32, self.height as u32);
        img.pixels.clone_from(&self.pixels);
        img
    }

    /// Resample to `width` × `height`: each new pixel is the mean of 4 × 4 bilinear lookups.
    pub fn resample(&self, width: usize, height: usize) -> EnvMap {
        let mut px = vec![Rgb::ZERO; width * height];
        for (k, p) in px.iter_mut().enumerate() {
            let (i, j) = (k % width, k / width);
            let mut acc = Rgb::ZERO;
            for a in 0..4 {
                for b in 0..4 {
                    let u = (i as f32 + (a as f32 + 0.5) / 4.0) / width as f32;
                    let v = (j as f32 + (b as f32 + 0.5) / 4.0) / height as f32;
                    acc += self.lookup(u, v);
                }
            }
            *p = acc / 16.0;
        }
        EnvMap::new(width, height, px)
    }

    /// Bilinear radiance at map coordinates (u, v).
    #[inline]
    pub fn lookup(&self, u: f32, v: f32) -> Rgb {
        self.bilinear(u, v, |k| self.pixels[k])
    }

    /// Bilinear interpolation at (u, v) of the values `at(pixel index)` on the map's grid.
    #[inline]
    fn bilinear(&self, u: f32, v: f32, at: impl Fn(usize) -> Rgb) -> Rgb {
        let (w, h) = (self.width as f32, self.height as f32);
        let x = u * w - 0.5;
        let y = (v * h - 0.5).clamp(0.0, h - 1.0);
        let x0f = x.floor();
        let fx = x - x0f;
        let x0 = (x0f as i64).rem_euclid(self.width as i64) as usize;
        let x1 = (x0 + 1) % self.width;
        let y0 = y.floor() as usize;
        let y1 = (y0 + 1).min(self.height - 1);
        let fy = y - y0 as f32;
        let at = |i: usize, j: usize| at(j * self.width + i);
        (at(x0, y0) * (1.0 - fx) + at(x1, y0) * fx) * (1.0 - fy) + (at(x0, y1) * (1.0 - fx) + at(x1, y1) * fx) * fy
    }

    /// Radiance arriving from unit direction `dir`.
    #[inline]
    pub fn radiance(&self, dir: Vec3) -> Rgb {
        let (u, v) = uv(dir);
        self.lookup(u, v)
    }

    /// Total sampling weight Σ f_ij.
    #[inline]
    fn total(&self) -> f64 {
        self.marginal_cdf[self.height]
    }

    /// Solid-angle density (sr⁻¹) of [`EnvMap::sample`] at pixel (i, j) and polar sine `sin_t`.
    #[inline]
    fn pdf_pixel(&self, i: usize, j: usize, sin_t: f32) -> f32 {
        if sin_t <= 0.0 {
            return 0.0;
        }
        // Density in (u, v) is f_ij / mean f; dω = 2π² sin θ du dv.
        let pdf_uv = self.weight[j * self.width + i] * (self.width * self.height) as f64 / self.total();
        (pdf_uv / (2.0 * std::f64::consts::PI * std::f64::consts::PI * sin_t as f64)) as f32
    }

    /// Draw a direction with density ∝ (luminance + ε)·sin θ per pixel, from two uniforms in
    /// [0, 1): (direction, its radiance, its solid-angle density in sr⁻¹). The density is 0 only
    /// exactly at a pole (probability zero); callers should skip such a sample.
    pub fn sample(&self, u: Vec2) -> (Vec3, Rgb, f32) {
        let total = self.total();
        // Row from the marginal, then column from the row's conditional; reuse the remainder.
        let target = u.y as f64 * total;
        let j = search(&self.marginal_cdf, target).min(self.height - 1);
        let row_sum = self.marginal_cdf[j + 1] - self.marginal_cdf[j];
        let fv = ((target - self.marginal_cdf[j]) / row_sum).clamp(0.0, 1.0);
        let row = &self.row_cdf[j * (self.width + 1)..(j + 1) * (self.width + 1)];
        let target_u = u.x as f64 * row[self.width];
        let i = search(row, target_u).min(self.width - 1);
        let fu = ((target_u - row[i]) / (row[i + 1] - row[i])).clamp(0.0, 1.0);
        let uu = ((i as f64 + fu) / self.width as f64) as f32;
        let vv = ((j as f64 + fv) / self.height as f64) as f32;
        let dir = direction(uu.min(1.0 - f32::EPSILON), vv);
        // The density of the pixel the direction lies in as `pdf` finds it (f32 rounding can put
        // a draw at its pixel's edge on the neighbour's side), so MIS weighs both alike.
        (dir, self.radiance(dir), self.pdf(dir))
    }

    /// Solid-angle density (sr⁻¹) with which [`EnvMap::sample`] draws unit direction `dir`.
    pub fn pdf(&self, dir: Vec3) -> f32 {
        let (u, v) = uv(dir);
        let i = ((u * self.width as f32) as usize).min(self.width - 1);
        let j = ((v * self.height as f32) as usize).min(self.height - 1);
        // sin θ from x and z: accurate near the poles, and the same formula as `sample`.
        self.pdf_pixel(i, j, dir.x.hypot(dir.z))
    }

    /// Sub-pixels per pixel edge for [`EnvMap::for_each_subpixel`] no wider than `max_rad` (in θ,
    /// and in φ on the equator): an even number, so that the bilinear radiance bends (at pixel
    /// centres) only at sub-pixel edges and their midpoints integrate it to second order.
    pub fn subpixels_within(&self, max_rad: f64) -> usize {
        let pi = std::f64::consts::PI;
        let pixel_rad = (pi / self.height as f64).max(2.0 * pi / self.width as f64);
        ((pixel_rad / max_rad / 2.0).ceil() as usize).max(1) * 2
    }

    /// `visit(direction, radiance, solid angle in sr)` at the centre of every one of `k` × `k`
    /// sub-pixels per pixel of the map's rows `rows`: bilinear radiance, exact solid angles (the
    /// whole map's sum to 4π). Integrals over regions of the sky that hold few map pixels, or a
    /// part of one, take the map's power where it is instead of point samples.
    pub fn for_each_subpixel(&self, rows: std::ops::Range<usize>, k: usize, visit: &mut dyn FnMut(Vec3, Rgb, f64)) {
        let (w, h) = (self.width * k, self.height * k);
        let columns: Vec<SubColumn> = (0..w).map(|a| SubColumn::new(a, w)).collect();
        for b in rows.start * k..rows.end.min(self.height) * k {
            let row = SubRow::new(b, h, w);
            for c in &columns {
                visit(row.direction(c), self.lookup(c.u, row.v), row.solid_angle);
            }
        }
    }

    /// The map's mean radiance (W·m⁻²·sr⁻¹) over each of `cells` cells of the sphere, `cell_of`
    /// naming the cell a unit direction lies in: every sub-pixel's radiance times its solid angle
    /// summed into its cell, over the solid angle summed there. A sun one map pixel wide enters
    /// its cell with its power, where samples at fixed directions degrees apart would miss it or
    /// count it over a whole cell. The map is read at enough sub-pixels per pixel that at least
    /// [`SAMPLES_PER_CELL_EDGE`] lie across the narrowest cell edge, `narrowest` (rad).
    /// `below_horizon`: the radiance taken instead of the map's from directions below the horizon
    /// (y < 0), a ground's. Summed per block of rows in parallel and the blocks in order: the same
    /// bits for any number of threads.
    pub fn cell_means(
        &self,
        cells: usize,
        narrowest: f64,
        cell_of: &(dyn Fn(Vec3) -> usize + Sync),
        below_horizon: Option<Rgb>,
    ) -> Vec<Rgb> {
        let pixel_rad = (std::f64::consts::PI / self.height as f64).max(2.0 * std::f64::consts::PI / self.width as f64);
        let k = (pixel_rad * SAMPLES_PER_CELL_EDGE / narrowest).ceil().max(1.0) as usize;
        let blocks = self.height.div_ceil(ROWS_PER_BLOCK);
        // Per cell: the power in each band and the solid angle (sr).
        let sums = crate::par::map_range(blocks, &|b| {
            let mut sum = vec![[0.0f64; 4]; cells];
            let rows = b * ROWS_PER_BLOCK..((b + 1) * ROWS_PER_BLOCK).min(self.height);
            self.for_each_subpixel(rows, k, &mut |dir, l, d_omega| {
                let l = match below_horizon {
                    Some(ground) if dir.y < 0.0 => ground,
                    _ => l,
                };
                let cell = &mut sum[cell_of(dir)];
                for (c, v) in cell.iter_mut().zip([l.x as f64, l.y as f64, l.z as f64, 1.0]) {
                    *c += v * d_omega;
                }
            });
            sum
        });
        let mut total = vec![[0.0f64; 4]; cells];
        for block in &sums {
            for (t, s) in total.iter_mut().zip(block) {
                (0..4).for_each(|i| t[i] += s[i]);
            }
        }
        total.iter().map(|[r, g, b, a]| Rgb::new((r / a) as f32, (g / a) as f32, (b / a) as f32)).collect()
    }

    /// Irradiance (W/m² per band) on an upward-facing plane from the upper hemisphere of the map,
    /// each pixel's radiance over its whole cell: Σ L_ij ∫ cos θ dω, where a cell of row j (θ from
    /// πj/h to π(j + 1)/h, cut at the horizon) has ∫ cos θ dω = (π/w)(sin²θ₁ − sin²θ₀). Exact
    /// for a sun one pixel wide, which samples on a fixed grid would miss or count too often.
    pub fn irradiance_up(&self) -> Rgb {
        let (w, h) = (self.width, self.height);
        let horizon = std::f64::consts::FRAC_PI_2;
        let theta = |j: usize| (std::f64::consts::PI * j as f64 / h as f64).min(horizon);
        let mut e = [0f64; 3];
        for j in (0..h).take_while(|&j| theta(j) < horizon) {
            let weight = std::f64::consts::PI / w as f64 * (theta(j + 1).sin().powi(2) - theta(j).sin().powi(2));
            for p in &self.pixels[j * w..(j + 1) * w] {
                for c in 0..3 {
                    e[c] += p[c] as f64 * weight;
                }
            }
        }
        Rgb::new(e[0] as f32, e[1] as f32, e[2] as f32)
    }
}

/// The solid angle (sr) of one cell of row `j` of an equirectangular grid of `rows` × `columns`
/// cells: (2π/columns)(cos θ_j − cos θ_{j+1}), θ_j = πj/rows (the whole grid's sum to 4π).
pub(super) fn row_solid_angle(j: usize, rows: usize, columns: usize) -> f64 {
    let theta = |j: usize| std::f64::consts::PI * j as f64 / rows as f64;
    2.0 * std::f64::consts::PI / columns as f64 * (theta(j).cos() - theta(j + 1).cos())
}

/// Pixel `k` of a `w` × `h` map and its 8-connected neighbours: wrapping in azimuth (columns),
/// not across the poles (rows).
pub(super) fn neighbourhood(k: usize, w: usize, h: usize) -> impl Iterator<Item = usize> {
    let (i, j) = (k % w, k / w);
    let rows = j.saturating_sub(1)..(j + 2).min(h);
    rows.flat_map(move |r| [w - 1, 0, 1].map(|di| r * w + (i + di) % w))
}

/// Column `a` of `w` sub-pixel columns: its centre's u and (sin φ, cos φ).
struct SubColumn {
    u: f32,
    sin_phi: f32,
    cos_phi: f32,
}

impl SubColumn {
    fn new(a: usize, w: usize) -> SubColumn {
        let u = (a as f64 + 0.5) / w as f64;
        let (sp, cp) = (2.0 * std::f64::consts::PI * u).sin_cos();
        SubColumn {
            u: u as f32,
            sin_phi: sp as f32,
            cos_phi: cp as f32,
        }
    }
}

/// Row `b` of an `h` × `w` sub-pixel grid: its centre's v, (sin θ, cos θ) and a cell's solid angle.
struct SubRow {
    v: f32,
    sin_theta: f64,
    cos_theta: f64,
    solid_angle: f64,
}

impl SubRow {
    fn new(b: usize, h: usize, w: usize) -> SubRow {
        let v = (b as f64 + 0.5) / h as f64;
        let (st, ct) = (std::f64::consts::PI * v).sin_cos();
        SubRow {
            v: v as f32,
            sin_theta: st,
            cos_theta: ct,
            solid_angle: row_solid_angle(b, h, w),
        }
    }

    /// The direction of the sub-pixel at column `c` of this row.
    #[inline]
    fn direction(&self, c: &SubColumn) -> Vec3 {
        let st = self.sin_theta as f32;
        Vec3::new(st * c.cos_phi, self.cos_theta as f32, st * c.sin_phi)
    }
}

impl EnvMap {
    /// ∫ luminance dω over the sphere, each pixel's over its cell; `None` for a black map.
    pub(super) fn luminance_integral(&self) -> Option<f64> {
        let (w, h) = (self.width, self.height);
        let total: f64 = (0..h)
            .map(|j| row_solid_angle(j, h, w) * self.pixels[j * w..(j + 1) * w].iter().map(|p| luminance(*p) as f64).sum::<f64>())
            .sum();
        (total > 0.0).then_some(total)
    }

    /// The map split into a base, the map less its pixels brighter than `over_mean` times its
    /// mean luminance, and those pixels as points: their bilinear radiance integrated in
    /// sub-pixels no wider than `max_rad` (an even number per pixel edge,
    /// [`EnvMap::subpixels_within`]), merged per cell of a cube map whose narrowest cell is no
    /// wider than `max_rad`. A renderer that takes the sky at fixed directions can take
    /// the base there and add the points' power where they fall: a sun one map pixel wide is then
    /// neither missed nor counted over a whole sample's solid angle. `None`: no pixel is brighter.
    pub fn split_bright(&self, over_mean: f64, max_rad: f64) -> Option<BrightSplit<'_>> {
        let threshold = over_mean * self.luminance_integral()? / (4.0 * std::f64::consts::PI);
        let bright: Vec<usize> = (0..self.pixels.len()).filter(|&n| luminance(self.pixels[n]) as f64 > threshold).collect();
        if bright.is_empty() {
            return None;
        }
        let (w, h) = (self.width, self.height);
        // The cells a bright pixel's bilinear radiance reaches: its own and its eight neighbours.
        let mut cells: Vec<usize> = bright
            .iter()
            .flat_map(|&n| neighbourhood(n, w, h))
            .collect();
        cells.sort_unstable();
        cells.dedup();
        let excess = |n: usize| if bright.binary_search(&n).is_ok() { self.pixels[n] } else { Rgb::ZERO };
        let k = self.subpixels_within(max_rad);
        let grid = (2.0 / (3.0 * max_rad)).ceil() as usize;
        // Per merge cell: Σ direction·weight and Σ power per band (ordered: the same points for any threads).
        let mut merged: std::collections::BTreeMap<usize, (glam::DVec3, [f64; 3])> = Default::default();
        let (sw, sh) = (w * k, h * k);
        for n in cells {
            let (i, j) = (n % w, n / w);
            for b in j * k..(j + 1) * k {
                let row = SubRow::new(b, sh, sw);
                for a in i * k..(i + 1) * k {
                    let c = SubColumn::new(a, sw);
                    let e = self.bilinear(c.u, row.v, excess);
                    if e == Rgb::ZERO {
                        continue;
                    }
                    let dir = row.direction(&c);
                    let power = e.as_dvec3() * row.solid_angle;
                    let m = merged.entry(cube_pixel(grid, dir)).or_default();
                    m.0 += dir.as_dvec3() * power.element_sum();
                    for (s, x) in m.1.iter_mut().zip(power.to_array()) {
                        *s += x;
                    }
                }
            }
        }
        let points = merged.into_values().map(|(d, p)| (d.normalize().as_vec3(), p)).collect();
        Some(BrightSplit { map: self, bright, points })
    }
}

/// An [`EnvMap`] as a base and the power of its brightest pixels as points
/// ([`EnvMap::split_bright`]).
#[derive(Clone, Debug)]
pub struct BrightSplit<'a> {
    map: &'a EnvMap,
    /// The indices of the pixels brighter than the threshold, in order.
    bright: Vec<usize>,
    /// (unit direction, ∫ L dω per band in W/m²) of those pixels' bilinear radiance; the points'
    /// powers add up to its integral over the sphere.
    pub points: Vec<(Vec3, [f64; 3])>,
}

impl BrightSplit<'_> {
    /// The base's bilinear radiance from unit direction `dir` (the bright pixels black): the
    /// map's less the points'.
    pub fn base_radiance(&self, dir: Vec3) -> Rgb {
        let (u, v) = uv(dir);
        let map = self.map;
        map.bilinear(u, v, |n| if self.bright.binary_search(&n).is_ok() { Rgb::ZERO } else { map.pixels[n] })
    }
}

/// Largest index k with cdf[k] <= target (cdf ascending, cdf[0] = 0), skipping empty cells.
#[inline]
fn search(cdf: &[f64], target: f64) -> usize {
    let n = cdf.len() - 1;
    // partition_point: first k with cdf[k] > target.
    let k = cdf.partition_point(|&c| c <= target);
    let mut i = k.saturating_sub(1).min(n - 1);
    // Never land on a zero-width cell (cannot happen with ε > 0, but stay safe).
    while i + 1 < n && cdf[i + 1] <= cdf[i] {
        i += 1;
    }
    i
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uv_direction_round_trip_and_axes() {
        for (u, v) in [(0.1, 0.2), (0.6, 0.7), (0.9, 0.5), (0.25, 0.5)] {
            let d = direction(u, v);
            let (a, b) = uv(d);
            assert!((a - u).abs() < 1e-5 && (b - v).abs() < 1e-5, "{u} {v} -> {a} {b}");
        }
        assert!((direction(0.0, 0.5) - Vec3::X).length() < 1e-6);
        assert!((direction(0.25, 0.5) - Vec3::Z).length() < 1e-6);
        assert!((direction(0.5, 0.0) - Vec3::Y).length() < 1e-6);
    }

    #[test]
    fn irradiance_up_holds_a_uniform_sky_and_a_sun_one_pixel_wide() {
        // Odd height: the middle row straddles the horizon.
        let (w, h) = (64, 33);
        assert!(((EnvMap::new(w, h, vec![Rgb::ONE; w * h]).irradiance_up().x as f64 - PI as f64).abs()) < 1e-5);
        // A bright pixel between the axis samples of a fixed grid: its power, the radiance times its
        // cell's ∫ cos θ dω.
        let (w, h) = (2048, 1024);
        let mut px = vec![Rgb::ZERO; w * h];
        px[300 * w + 700] = Rgb::splat(1e6);
        let (t0, t1) = (std::f64::consts::PI * 300.0 / h as f64, std::f64::consts::PI * 301.0 / h as f64);
        let exact = 1e6 * std::f64::consts::PI / w as f64 * (t1.sin().powi(2) - t0.sin().powi(2));
        let e = EnvMap::new(w, h, px).irradiance_up().x as f64;
        assert!((e - exact).abs() < 1e-5 * exact, "{e} vs {exact}");
    }

    #[test]
    fn a_neighbourhood_wraps_in_azimuth_and_stops_at_the_poles() {
        let mut n: Vec<usize> = neighbourhood(0, 4, 3).collect();
        n.sort_unstable();
        assert_eq!(n, vec![0, 1, 3, 4, 5, 7]);
        assert_eq!(neighbourhood(5, 4, 3).count(), 9);
    }

    #[test]
    fn sample_pdf_agree() {
        let px: Vec<Rgb> = (0..32 * 16).map(|k| Rgb::splat(((k * 7919) % 13) as f32)).collect();
        let m = EnvMap::new(32, 16, px);
        let mut rng = crate::math::Rng::new(3, 4);
        for _ in 0..2000 {
            let (d, _, pdf) = m.sample(Vec2::new(rng.uniform(), rng.uniform()));
            let q = m.pdf(d);
            assert!((pdf - q).abs() <= 1e-3 * pdf.max(q), "{pdf} vs {q}");
        }
    }
}
