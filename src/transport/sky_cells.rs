//! The sky as the sweeps see it. Along each ordinate the sky enters with its mean radiance over
//! the ordinate's cell of the sphere ([`Ring`](super::sphere::Ring): a solid angle equal to the
//! ordinate's weight), not with a point sample at the ordinate: a map's sun, aureole or bright
//! patch then enters with its power (Σ_o w_o L̄_o = ∫ L dω, the quadrature's sum of the sky
//! exact), where samples degrees apart would miss it or count it over a whole cell. A constant
//! sky is its own mean.

use super::sphere::Quadrature;
use crate::lighting::Sky;
use crate::math::Rgb;
use glam::DVec3;

/// Fewest map samples along the narrowest cell's edge when the cells' means are summed: a map
/// coarser than that is read at several bilinear points per pixel, a finer one at its pixels.
const SAMPLES_PER_CELL_EDGE: f64 = 64.0;

/// Map rows summed per parallel task.
const ROWS_PER_BLOCK: usize = 16;

/// The sky radiance each ordinate's sweep starts from.
pub(super) enum SkyCells {
    /// The same radiance from every direction.
    Constant(Rgb),
    /// Per ordinate of the quadrature, the sky's mean over its cell (W·m⁻²·sr⁻¹).
    Means { q: Quadrature, means: Vec<Rgb> },
}

impl SkyCells {
    /// `sky` over the cells of `q`.
    pub(super) fn new(sky: &Sky, q: &Quadrature) -> SkyCells {
        let Some(map) = sky.map() else {
            return SkyCells::Constant(sky.radiance(glam::Vec3::Y));
        };
        // The narrowest cell edge, as the smaller of each band's width in θ and its sectors'
        // angle in azimuth.
        let narrowest = q
            .rings
            .iter()
            .map(|r| {
                let theta = r.mu[0].clamp(-1.0, 1.0).acos() - r.mu[1].clamp(-1.0, 1.0).acos();
                theta.min(2.0 * std::f64::consts::PI / r.count as f64)
            })
            .fold(f64::INFINITY, f64::min);
        let pixel_rad = (std::f64::consts::PI / map.height as f64).max(2.0 * std::f64::consts::PI / map.width as f64);
        let k = (pixel_rad * SAMPLES_PER_CELL_EDGE / narrowest).ceil().max(1.0) as usize;
        // Per block of map rows, in parallel, summed in the blocks' order: the same bits for any
        // number of threads.
        let blocks = map.height.div_ceil(ROWS_PER_BLOCK);
        // Per cell: the power in each band and the solid angle (sr).
        let sums = crate::par::map_range(blocks, &|b| {
            let mut sum = vec![[0.0f64; 4]; q.dirs.len()];
            let rows = b * ROWS_PER_BLOCK..((b + 1) * ROWS_PER_BLOCK).min(map.height);
            map.for_each_subpixel(rows, k, &mut |dir, l, d_omega| {
                let cell = &mut sum[q.cell_of(DVec3::new(dir.x as f64, dir.y as f64, dir.z as f64))];
                for (c, v) in cell.iter_mut().zip([l.x as f64, l.y as f64, l.z as f64, 1.0]) {
                    *c += v * d_omega;
                }
            });
            sum
        });
        let mut total = vec![[0.0f64; 4]; q.dirs.len()];
        for block in &sums {
            for (t, s) in total.iter_mut().zip(block) {
                (0..4).for_each(|i| t[i] += s[i]);
            }
        }
        let means = total.iter().map(|[r, g, b, a]| Rgb::new((r / a) as f32, (g / a) as f32, (b / a) as f32)).collect();
        SkyCells::Means { q: q.clone(), means }
    }

    /// The sky radiance arriving along the ordinate direction `om` (from −`om`).
    pub(super) fn arriving(&self, om: DVec3) -> Rgb {
        match self {
            SkyCells::Constant(l) => *l,
            SkyCells::Means { q, means } => means[q.cell_of(-om)],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::envmap::EnvMap;

    fn map_sky(width: usize, height: usize, radiance: impl Fn(usize, usize) -> Rgb) -> Sky {
        let pixels = (0..height).flat_map(|j| (0..width).map(move |i| (i, j))).map(|(i, j)| radiance(i, j)).collect();
        Sky::from_envmap(EnvMap::new(width, height, pixels))
    }

    #[test]
    fn a_constant_sky_and_a_uniform_map_enter_every_ordinate_unchanged() {
        let q = Quadrature::reduced(8, 16);
        let l = Rgb::new(0.2, 0.3, 0.5);
        let constant = SkyCells::new(&Sky::constant(l), &q);
        let uniform = SkyCells::new(&map_sky(64, 32, |_, _| l), &q);
        for d in &q.dirs {
            assert_eq!(constant.arriving(*d), l);
            let u = uniform.arriving(*d);
            assert!((u.x / l.x - 1.0).abs() < 1e-5 && (u.z / l.z - 1.0).abs() < 1e-5, "{u:?}");
        }
    }

    #[test]
    fn a_one_pixel_sun_enters_one_ordinate_with_its_power() {
        // A 512×256 map of 0.5 with one pixel of 1e6: the quadrature's sum of the sky, Σ w L̄,
        // is the map's integral (its sum over pixels times their solid angles), wherever the
        // sun's pixel lies. A point sample at the ordinates would miss it.
        let q = Quadrature::reduced(8, 16);
        let (w, h) = (512, 256);
        for (si, sj) in [(37, 61), (300, 128), (5, 3)] {
            let sky = map_sky(w, h, |i, j| if (i, j) == (si, sj) { Rgb::splat(1e6) } else { Rgb::splat(0.5) });
            let map = sky.map().unwrap();
            let mut exact = 0.0;
            map.for_each_subpixel(0..h, 1, &mut |_, l, d_omega| exact += l.x as f64 * d_omega);
            let cells = SkyCells::new(&sky, &q);
            let sum: f64 = q.dirs.iter().zip(&q.weights).map(|(d, wt)| cells.arriving(-*d).x as f64 * wt).sum();
            assert!((sum / exact - 1.0).abs() < 0.01, "sun at pixel ({si}, {sj}): {sum} against {exact}");
            let point: f64 = q.dirs.iter().zip(&q.weights).map(|(d, wt)| sky.radiance(d.as_vec3()).x as f64 * wt).sum();
            assert!(point < 0.5 * exact, "point samples miss it: {point} against {exact}");
        }
    }
}
