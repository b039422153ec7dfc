//! The 96 direction bins of the paper's Figure 1b: the six faces of a unit cube, 4×4 bins per
//! face. Each bin has its exact solid angle and the exact first moment ∫ω dω; a sky's power in a
//! bin is integrated over the bin, never sampled at its centre. The sun is never binned.

use crate::math::{Rgb, Vec3};

/// Bins per face edge.
pub const BINS_PER_EDGE: usize = 4;
/// Number of bins.
pub const NUM_BINS: usize = 6 * BINS_PER_EDGE * BINS_PER_EDGE;

/// A cube face: outward normal `n` and tangents `tu`, `tv`; a point (u, v) ∈ [-1, 1]² on it is the
/// direction n + u·tu + v·tv.
#[derive(Clone, Copy, Debug)]
pub struct CubeFace {
    /// Outward normal (a world axis).
    pub n: Vec3,
    /// Direction of increasing u.
    pub tu: Vec3,
    /// Direction of increasing v.
    pub tv: Vec3,
}

/// The faces in order +x, −x, +y, −y, +z, −z. Each (tu, tv, n) is right-handed.
pub const CUBE_FACES: [CubeFace; 6] = [
    CubeFace {
        n: Vec3::X,
        tu: Vec3::NEG_Z,
        tv: Vec3::Y,
    },
    CubeFace {
        n: Vec3::NEG_X,
        tu: Vec3::Z,
        tv: Vec3::Y,
    },
    CubeFace {
        n: Vec3::Y,
        tu: Vec3::X,
        tv: Vec3::NEG_Z,
    },
    CubeFace {
        n: Vec3::NEG_Y,
        tu: Vec3::X,
        tv: Vec3::Z,
    },
    CubeFace {
        n: Vec3::Z,
        tu: Vec3::X,
        tv: Vec3::Y,
    },
    CubeFace {
        n: Vec3::NEG_Z,
        tu: Vec3::NEG_X,
        tv: Vec3::Y,
    },
];

/// Face and (u, v) ∈ [-1, 1]² of the cube point in direction `dir` (any length > 0).
#[inline]
pub fn face_uv(dir: Vec3) -> (usize, f32, f32) {
    let a = dir.abs();
    let face = if a.x >= a.y && a.x >= a.z {
        if dir.x > 0.0 {
            0
        } else {
            1
        }
    } else if a.y >= a.z {
        if dir.y > 0.0 {
            2
        } else {
            3
        }
    } else if dir.z > 0.0 {
        4
    } else {
        5
    };
    let f = &CUBE_FACES[face];
    let d = dir / dir.dot(f.n);
    (face, d.dot(f.tu).clamp(-1.0, 1.0), d.dot(f.tv).clamp(-1.0, 1.0))
}

/// Index ([`crate::cube::CubeImage::index`]) of the pixel of a `res` cube that direction `dir`
/// falls in (in the cube's own frame).
pub fn cube_pixel(res: usize, dir: Vec3) -> usize {
    let (face, u, v) = face_uv(dir);
    let at = |x: f32| (((x + 1.0) * 0.5 * res as f32) as usize).min(res - 1);
    (face * res + at(v)) * res + at(u)
}

/// The narrowest angle (rad) across a pixel of a `res` cube: a corner pixel's, along its edge on
/// the cube's edge, where the face is seen most obliquely.
pub fn narrowest_pixel_edge(res: usize) -> f64 {
    let inner = glam::DVec3::new(1.0 - 2.0 / res as f64, 1.0, 1.0).normalize();
    inner.angle_between(glam::DVec3::ONE.normalize())
}

/// Exact solid angle (sr) subtended by the rectangle [u0, u1]×[v0, v1] on a cube face at unit distance.
#[inline]
pub fn rect_solid_angle(u0: f64, u1: f64, v0: f64, v1: f64) -> f64 {
    let f = |u: f64, v: f64| (u * v / (1.0 + u * u + v * v).sqrt()).atan();
    f(u1, v1) - f(u0, v1) - f(u1, v0) + f(u0, v0)
}

/// 8-point Gauss–Legendre nodes and weights on [−1, 1] (exact to ~1e-12 for the smooth
/// integrands of solid angles and moments over cube-face rectangles).
pub(crate) const GL8_X: [f64; 8] = [
    -0.960_289_856_497_536_3,
    -0.796_666_477_413_626_7,
    -0.525_532_409_916_329,
    -0.183_434_642_495_649_8,
    0.183_434_642_495_649_8,
    0.525_532_409_916_329,
    0.796_666_477_413_626_7,
    0.960_289_856_497_536_3,
];
pub(crate) const GL8_W: [f64; 8] = [
    0.101_228_536_290_376_3,
    0.222_381_034_453_374_5,
    0.313_706_645_877_887_3,
    0.362_683_783_378_362,
    0.362_683_783_378_362,
    0.313_706_645_877_887_3,
    0.222_381_034_453_374_5,
    0.101_228_536_290_376_3,
];

/// Exact first moment ∫ω dω (a vector, sr) of the rectangle [u0, u1]×[v0, v1] on a face, in the
/// face's (u, v, n) frame, by Gauss–Legendre quadrature (the integrand is smooth).
fn rect_first_moment(u0: f64, u1: f64, v0: f64, v1: f64) -> [f64; 3] {
    // 8-point Gauss–Legendre on each axis is exact to ~1e-12 for these smooth integrands.
    let mut m = [0.0; 3];
    for (xi, wi) in GL8_X.iter().zip(GL8_W) {
        let u = 0.5 * (u0 + u1) + 0.5 * (u1 - u0) * xi;
        for (xj, wj) in GL8_X.iter().zip(GL8_W) {
            let v = 0.5 * (v0 + v1) + 0.5 * (v1 - v0) * xj;
            let r2 = 1.0 + u * u + v * v;
            // dω = du dv / r³; ω = (u, v, 1)/r.
            let w = wi * wj * 0.25 * (u1 - u0) * (v1 - v0) / (r2 * r2);
            m[0] += w * u;
            m[1] += w * v;
            m[2] += w;
        }
    }
    m
}

/// One direction bin.
#[derive(Clone, Copy, Debug)]
pub struct Bin {
    /// Face index into [`CUBE_FACES`].
    pub face: usize,
    /// Unit direction through the bin's centre on the cube.
    pub center: Vec3,
    /// Mean direction ∫ω dω / Δω (length < 1: it carries the bin's spread).
    pub mean_dir: Vec3,
    /// Exact solid angle Δω (sr).
    pub solid_angle: f64,
    /// u range on the face.
    pub u: [f64; 2],
    /// v range on the face.
    pub v: [f64; 2],
}

impl Bin {
    /// A direction inside the bin at fractional position (a, b) ∈ [0, 1]² of its (u, v) square.
    #[inline]
    pub fn direction_at(&self, a: f32, b: f32) -> Vec3 {
        let f = &CUBE_FACES[self.face];
        let u = self.u[0] as f32 + (self.u[1] - self.u[0]) as f32 * a;
        let v = self.v[0] as f32 + (self.v[1] - self.v[0]) as f32 * b;
        (f.n + f.tu * u + f.tv * v).normalize()
    }
}

/// The 96 bins with their geometry.
#[derive(Clone, Debug)]
pub struct DirectionBins {
    /// The bins, index = face·16 + bv·4 + bu.
    pub bins: Vec<Bin>,
}

impl Default for DirectionBins {
    fn default() -> Self {
        Self::new()
    }
}

impl DirectionBins {
    /// Build the 96 bins.
    pub fn new() -> Self {
        let mut bins = Vec::with_capacity(NUM_BINS);
        let step = 2.0 / BINS_PER_EDGE as f64;
        for (face, f) in CUBE_FACES.iter().enumerate() {
            for bv in 0..BINS_PER_EDGE {
                for bu in 0..BINS_PER_EDGE {
                    let (u0, u1) = (-1.0 + bu as f64 * step, -1.0 + (bu + 1) as f64 * step);
                    let (v0, v1) = (-1.0 + bv as f64 * step, -1.0 + (bv + 1) as f64 * step);
                    let sa = rect_solid_angle(u0, u1, v0, v1);
                    let m = rect_first_moment(u0, u1, v0, v1);
                    let mean = (f.tu * m[0] as f32 + f.tv * m[1] as f32 + f.n * m[2] as f32) / sa as f32;
                    let (uc, vc) = (0.5 * (u0 + u1) as f32, 0.5 * (v0 + v1) as f32);
                    let center = (f.n + f.tu * uc + f.tv * vc).normalize();
                    bins.push(Bin {
                        face,
                        center,
                        mean_dir: mean,
                        solid_angle: sa,
                        u: [u0, u1],
                        v: [v0, v1],
                    });
                }
            }
        }
        DirectionBins { bins }
    }

    /// Index of the bin containing direction `dir`.
    #[inline]
    pub fn bin_of(&self, dir: Vec3) -> usize {
        let (face, u, v) = face_uv(dir);
        let bu = (((u + 1.0) * 0.5 * BINS_PER_EDGE as f32) as usize).min(BINS_PER_EDGE - 1);
        let bv = (((v + 1.0) * 0.5 * BINS_PER_EDGE as f32) as usize).min(BINS_PER_EDGE - 1);
        face * BINS_PER_EDGE * BINS_PER_EDGE + bv * BINS_PER_EDGE + bu
    }

    /// Power ∫_bin L(ω) dω (W/m² per band) of a radiance function in every bin, integrated with
    /// `sub`×`sub` sub-rectangles per bin, each weighted by its exact solid angle. Runs once per
    /// scene: `radiance` is a trait object, one copy of this loop for every sky.
    pub fn integrate(&self, sub: usize, radiance: &(dyn Fn(Vec3) -> Rgb + Sync)) -> Vec<Rgb> {
        crate::par::map_range(self.bins.len(), &|bi| {
            let b = &self.bins[bi];
            let f = &CUBE_FACES[b.face];
            let du = (b.u[1] - b.u[0]) / sub as f64;
            let dv = (b.v[1] - b.v[0]) / sub as f64;
            let mut acc = [0f64; 3];
            for j in 0..sub {
                for i in 0..sub {
                    let (u0, v0) = (b.u[0] + i as f64 * du, b.v[0] + j as f64 * dv);
                    let sa = rect_solid_angle(u0, u0 + du, v0, v0 + dv);
                    let dir = (f.n + f.tu * (u0 + 0.5 * du) as f32 + f.tv * (v0 + 0.5 * dv) as f32).normalize();
                    let l = radiance(dir);
                    acc[0] += l.x as f64 * sa;
                    acc[1] += l.y as f64 * sa;
                    acc[2] += l.z as f64 * sa;
                }
            }
            Rgb::new(acc[0] as f32, acc[1] as f32, acc[2] as f32)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solid_angles_sum_to_4pi_and_match_quadrature() {
        let bins = DirectionBins::new();
        let total: f64 = bins.bins.iter().map(|b| b.solid_angle).sum();
        assert!((total - 4.0 * std::f64::consts::PI).abs() < 1e-12, "total {total}");
        for b in &bins.bins {
            // Brute-force: 400×400 midpoint rule of du dv / r³.
            let n = 400;
            let mut s = 0.0;
            for i in 0..n {
                for j in 0..n {
                    let u = b.u[0] + (i as f64 + 0.5) * (b.u[1] - b.u[0]) / n as f64;
                    let v = b.v[0] + (j as f64 + 0.5) * (b.v[1] - b.v[0]) / n as f64;
                    s += (1.0 + u * u + v * v).powf(-1.5);
                }
            }
            s *= (b.u[1] - b.u[0]) * (b.v[1] - b.v[0]) / (n * n) as f64;
            assert!((s - b.solid_angle).abs() < 1e-6 * b.solid_angle, "{s} vs {}", b.solid_angle);
        }
    }

    #[test]
    fn the_narrowest_pixel_edge_is_a_corner_pixels() {
        // Against the angle across every pixel of a res-8 cube, along u and along v.
        let res = 8;
        let step = 2.0 / res as f32;
        let mut least = f64::INFINITY;
        for a in 0..res {
            for b in 0..res {
                let (u, v) = (-1.0 + a as f32 * step, -1.0 + b as f32 * step);
                let at = |u: f32, v: f32| Vec3::new(u, v, 1.0).normalize().as_dvec3();
                least = least.min(at(u, v).angle_between(at(u + step, v)));
                least = least.min(at(u, v).angle_between(at(u, v + step)));
            }
        }
        assert!((narrowest_pixel_edge(res) - least).abs() < 1e-6, "{} against {least}", narrowest_pixel_edge(res));
    }

    #[test]
    fn bin_of_centre_round_trips() {
        let bins = DirectionBins::new();
        for (i, b) in bins.bins.iter().enumerate() {
            assert_eq!(bins.bin_of(b.center), i);
            assert_eq!(bins.bin_of(b.direction_at(0.1, 0.9)), i);
        }
    }

    #[test]
    fn first_moments_cancel() {
        let bins = DirectionBins::new();
        let s: Vec3 = bins.bins.iter().map(|b| b.mean_dir * b.solid_angle as f32).sum();
        assert!(s.length() < 1e-5);
    }

    #[test]
    fn constant_sky_power_is_4pi_l() {
        let bins = DirectionBins::new();
        let l = Rgb::new(0.3, 0.45, 0.8);
        let p = bins.integrate(8, &|_| l);
        let total: Rgb = p.iter().copied().sum();
        assert!((total - l * 4.0 * std::f32::consts::PI).abs().max_element() < 1e-5);
    }
}
