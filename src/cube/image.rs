//! A cube map of radiance around a point: six square faces of `res`×`res` pixels, laid out like
//! the 96 direction bins ([`CUBE_FACES`]: face order +x, −x, +y, −y, +z, −z in the cube's local
//! frame; pixel (i, j) spans u ∈ [−1 + 2i/res, −1 + 2(i+1)/res], v likewise with j). A cube may be
//! rotated: `axes` maps local directions to world directions (the identity for world-aligned
//! cubes, whose pixels then nest exactly inside the 96 bins when `res` is a multiple of 4).

use crate::lighting::bins::{rect_solid_angle, BINS_PER_EDGE, CUBE_FACES, NUM_BINS};
use crate::math::{Rgb, Vec3};
use glam::Mat3;

/// Radiance (W m⁻² sr⁻¹ per band) arriving at a point, one value per cube pixel.
#[derive(Clone, Debug)]
pub struct CubeImage {
    /// Pixels per face edge.
    pub res: usize,
    /// Local → world rotation (columns are the local x, y, z axes in world space).
    pub axes: Mat3,
    /// Radiance per pixel, index = (face·res + j)·res + i.
    pub pixels: Vec<Rgb>,
}

impl CubeImage {
    /// A black world-aligned cube.
    pub fn new(res: usize) -> Self {
        Self::with_axes(res, Mat3::IDENTITY)
    }

    /// A black cube whose local frame is `axes`.
    pub fn with_axes(res: usize, axes: Mat3) -> Self {
        assert!(res > 0, "cube resolution must be positive");
        CubeImage {
            res,
            axes,
            pixels: vec![Rgb::ZERO; 6 * res * res],
        }
    }

    /// A cube whose local +x axis is `x_axis` (unit), as the paper orients the final gather's
    /// cubes along the viewing ray.
    pub fn along(res: usize, x_axis: Vec3) -> Self {
        let f = crate::math::Frame::from_normal(x_axis);
        // Columns: local x → x_axis, local y → f.t, local z → f.b; right-handed since
        // (t, b, n) is right-handed and (n, t, b) is a cyclic permutation of it.
        Self::with_axes(res, Mat3::from_cols(x_axis, f.t, f.b))
    }

    /// Index of pixel (i, j) on `face`.
    #[inline]
    pub fn index(&self, face: usize, i: usize, j: usize) -> usize {
        (face * self.res + j) * self.res + i
    }

    /// (u0, u1) range of column i (or row j) at resolution `res`.
    #[inline]
    pub fn pixel_range(res: usize, i: usize) -> (f64, f64) {
        let s = 2.0 / res as f64;
        (-1.0 + i as f64 * s, -1.0 + (i + 1) as f64 * s)
    }

    /// Unit local direction through the centre of pixel (i, j) on `face`.
    #[inline]
    pub fn local_direction(res: usize, face: usize, i: usize, j: usize) -> Vec3 {
        let f = &CUBE_FACES[face];
        let u = -1.0 + (2 * i + 1) as f32 / res as f32;
        let v = -1.0 + (2 * j + 1) as f32 / res as f32;
        (f.n + f.tu * u + f.tv * v).normalize()
    }

    /// Unit world direction through the centre of pixel (i, j) on `face`.
    #[inline]
    pub fn direction(&self, face: usize, i: usize, j: usize) -> Vec3 {
        (self.axes * Self::local_direction(self.res, face, i, j)).normalize()
    }

    /// Exact solid angle (sr) of pixel (i, j) (the same on every face).
    #[inline]
    pub fn pixel_solid_angle(res: usize, i: usize, j: usize) -> f64 {
        let (u0, u1) = Self::pixel_range(res, i);
        let (v0, v1) = Self::pixel_range(res, j);
        rect_solid_angle(u0, u1, v0, v1)
    }

    /// Solid angle of every pixel of one face, index j·res + i.
    pub fn face_solid_angles(res: usize) -> Vec<f64> {
        let mut out = Vec::with_capacity(res * res);
        for j in 0..res {
            for i in 0..res {
                out.push(Self::pixel_solid_angle(res, i, j));
            }
        }
        out
    }

    /// ∫ L(ω) w(ω) dω over the sphere, with the world direction of each pixel centre passed to `w`.
    pub fn integrate(&self, w: impl Fn(Vec3) -> f64) -> [f64; 3] {
        let sa = Self::face_solid_angles(self.res);
        let mut acc = [0f64; 3];
        for face in 0..6 {
            for j in 0..self.res {
                for i in 0..self.res {
                    let k = w(self.direction(face, i, j)) * sa[j * self.res + i];
                    let l = self.pixels[self.index(face, i, j)];
                    acc[0] += l.x as f64 * k;
                    acc[1] += l.y as f64 * k;
                    acc[2] += l.z as f64 * k;
                }
            }
        }
        acc
    }

    /// Mean radiance in each of the 96 direction bins (solid-angle weighted). Requires a
    /// world-aligned cube whose `res` is a multiple of 4, so pixels nest inside bins.
    pub fn bin_averages(&self) -> Vec<Rgb> {
        assert!(
            self.res % BINS_PER_EDGE == 0,
            "cube res {} is not a multiple of {BINS_PER_EDGE}",
            self.res
        );
        assert!(self.axes == Mat3::IDENTITY, "bin averages need a world-aligned cube");
        let per = self.res / BINS_PER_EDGE;
        let sa = Self::face_solid_angles(self.res);
        let mut sum = vec![[0f64; 3]; NUM_BINS];
        let mut area = vec![0f64; NUM_BINS];
        for face in 0..6 {
            for j in 0..self.res {
                for i in 0..self.res {
                    let b = face * BINS_PER_EDGE * BINS_PER_EDGE + (j / per) * BINS_PER_EDGE + i / per;
                    let w = sa[j * self.res + i];
                    let l = self.pixels[self.index(face, i, j)];
                    sum[b][0] += l.x as f64 * w;
                    sum[b][1] += l.y as f64 * w;
                    sum[b][2] += l.z as f64 * w;
                    area[b] += w;
                }
            }
        }
        sum.iter()
            .zip(&area)
            .map(|(s, a)| Rgb::new((s[0] / a) as f32, (s[1] / a) as f32, (s[2] / a) as f32))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::bins::DirectionBins;

    #[test]
    fn pixel_solid_angles_sum_to_4pi() {
        for res in [1, 4, 7, 16] {
            let s: f64 = CubeImage::face_solid_angles(res).iter().sum::<f64>() * 6.0;
            assert!((s - 4.0 * std::f64::consts::PI).abs() < 1e-10, "res {res}: {s}");
        }
    }

    #[test]
    fn pixels_nest_in_bins() {
        let bins = DirectionBins::new();
        let cube = CubeImage::new(8);
        for face in 0..6 {
            for j in 0..8 {
                for i in 0..8 {
                    let b = bins.bin_of(cube.direction(face, i, j));
                    assert_eq!(b, face * 16 + (j / 2) * 4 + i / 2);
                }
            }
        }
    }

    #[test]
    fn bin_averages_of_a_direction_function_match_bin_integrals() {
        let bins = DirectionBins::new();
        let f = |d: Vec3| Rgb::new(1.0 + d.x, 2.0 + d.y * d.z, 1.5 - d.z);
        let mut cube = CubeImage::new(64);
        for face in 0..6 {
            for j in 0..64 {
                for i in 0..64 {
                    let k = cube.index(face, i, j);
                    cube.pixels[k] = f(cube.direction(face, i, j));
                }
            }
        }
        let avg = cube.bin_averages();
        let exact = bins.integrate(32, &f);
        for (b, bin) in bins.bins.iter().enumerate() {
            let e = exact[b] / bin.solid_angle as f32;
            assert!((avg[b] - e).abs().max_element() < 2e-3, "bin {b}: {} vs {}", avg[b], e);
        }
    }

    #[test]
    fn rotated_cube_points_x_along_axis_and_is_orthonormal() {
        let x = Vec3::new(0.3, -0.5, 0.8).normalize();
        let cube = CubeImage::along(4, x);
        assert!((cube.axes.x_axis - x).length() < 1e-6);
        assert!((cube.axes.determinant() - 1.0).abs() < 1e-5);
        // Cosine-weighted integral of a constant over the sphere is zero; of 1 is 4π.
        let mut c = cube.clone();
        c.pixels.iter_mut().for_each(|p| *p = Rgb::ONE);
        let s = c.integrate(|_| 1.0);
        assert!((s[0] - 4.0 * std::f64::consts::PI).abs() < 1e-4);
        let m = c.integrate(|d| d.dot(x) as f64);
        assert!(m[0].abs() < 1e-4);
    }
}
