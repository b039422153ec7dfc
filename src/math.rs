//! Small math helpers shared by every stage: colour type, rays, orthonormal frames, and a
//! counter-based random stream that makes renders independent of the thread count.

pub use glam::Vec3;

/// Linear RGB triple (radiance in W·m⁻²·sr⁻¹ per band, irradiance in W·m⁻², or a unitless factor).
pub type Rgb = Vec3;

/// A ray `origin + t·dir`, `dir` unit length, `t` in metres.
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    /// Start point (m).
    pub origin: Vec3,
    /// Unit direction.
    pub dir: Vec3,
}

impl Ray {
    /// A ray from `origin` along `dir` (normalised here).
    #[inline]
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Ray {
            origin,
            dir: dir.normalize(),
        }
    }
}

/// `v` scaled to unit length, computed in f64: f32's squared length overflows past 1.8e19 and
/// underflows below 1e-19, so a valid direction such as `[1e30, 1e30, 0]` or `[1e-30, 0, 1e-30]`
/// would otherwise become NaN or zero. `None` for a zero or non-finite `v`.
pub fn unit_vector(v: [f32; 3]) -> Option<Vec3> {
    let d = glam::DVec3::new(v[0].into(), v[1].into(), v[2].into());
    let len = d.length();
    (len.is_finite() && len > 0.0).then(|| (d / len).as_vec3())
}

/// An orthonormal frame (t, b, n) with `n` given; used to turn local directions into world ones.
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    /// First tangent.
    pub t: Vec3,
    /// Second tangent.
    pub b: Vec3,
    /// The given axis.
    pub n: Vec3,
}

impl Frame {
    /// Frame around unit `n` (Duff et al. 2017, branchless and continuous).
    #[inline]
    pub fn from_normal(n: Vec3) -> Self {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let t = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let bb = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        Frame { t, b: bb, n }
    }

    /// Local (x, y, z) → world, z along `n`.
    #[inline]
    pub fn to_world(self, v: Vec3) -> Vec3 {
        self.t * v.x + self.b * v.y + self.n * v.z
    }
}

/// Luminance of linear Rec.709 RGB.
#[inline]
pub fn luminance(c: Rgb) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// SplitMix64 finaliser: a strong 64-bit mixer used to derive independent stream seeds.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// PCG32 random stream. Seed it from (scene seed, pixel, sample) with [`Rng::for_pixel`] so each
/// pixel sample draws the same numbers whichever thread runs it.
#[derive(Clone, Debug)]
pub struct Rng {
    state: u64,
    inc: u64,
}

impl Rng {
    /// A stream from a seed and a stream id.
    pub fn new(seed: u64, stream: u64) -> Self {
        let mut r = Rng {
            state: 0,
            inc: (mix64(stream) << 1) | 1,
        };
        r.next_u32();
        r.state = r.state.wrapping_add(mix64(seed));
        r.next_u32();
        r
    }

    /// The stream for one sample of one pixel of one render.
    pub fn for_pixel(seed: u64, x: u32, y: u32, sample: u32) -> Self {
        let key = ((y as u64) << 32) | x as u64;
        Rng::new(mix64(seed ^ mix64(key)), sample as u64)
    }

    /// Next 32 random bits.
    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }

    /// Uniform in [0, 1).
    #[inline]
    pub fn uniform(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / 16_777_216.0)
    }

    /// Uniform in [0, 1) with 53 bits.
    #[inline]
    pub fn uniform_f64(&mut self) -> f64 {
        let hi = (self.next_u32() as u64) << 21;
        let lo = (self.next_u32() >> 11) as u64;
        (hi | lo) as f64 * (1.0 / 9_007_199_254_740_992.0)
    }
}

/// Uniformly distributed direction on the unit sphere from two uniforms.
#[inline]
pub fn uniform_sphere(u1: f32, u2: f32) -> Vec3 {
    let z = 1.0 - 2.0 * u1;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * std::f32::consts::PI * u2;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Cosine-weighted direction on the hemisphere around +z.
#[inline]
pub fn cosine_hemisphere(u1: f32, u2: f32) -> Vec3 {
    let r = u1.sqrt();
    let phi = 2.0 * std::f32::consts::PI * u2;
    Vec3::new(r * phi.cos(), r * phi.sin(), (1.0 - u1).max(0.0).sqrt())
}

/// floor for |x| < 2³¹ without a libm call: `f32::floor` where it is one instruction (SSE4.1
/// round on the x86-64-v2 build, aarch64's frintm), else by a truncating cast (the plain x86-64
/// target has no SSE4.1 round; there `floor` is a libm call). The same value either way.
#[inline(always)]
pub fn fast_floor(x: f32) -> f32 {
    if cfg!(any(target_feature = "sse4.1", target_arch = "aarch64")) {
        x.floor()
    } else {
        let t = x as i32 as f32;
        if t > x {
            t - 1.0
        } else {
            t
        }
    }
}

/// The value of an integral `x` with |x| < 2²² as an i32: the low mantissa bits of x + 1.5·2²³,
/// which holds it exactly (one add and a move, where `as` also tests for saturation and NaN,
/// ~7 % of the cube tracer's instructions). Outside that range the result is wrong, never
/// undefined: callers keep `x` in range.
#[inline(always)]
pub fn small_int(x: f32) -> i32 {
    const SHIFT: f32 = 12_582_912.0; // 1.5·2²³: [2²³, 2²⁴) for x in [−2²², 2²²), unit spacing
    (x + SHIFT).to_bits() as i32 - SHIFT.to_bits() as i32
}

/// The one trilinear interpolation of the crate: the 8 corner indices and the fractions at
/// continuous voxel coordinates `p` of a lattice of `dims` cells with centres at half-integers,
/// indices clamped to the lattice (clamp-to-edge, so the field is defined on the whole box
/// [0, n]³; the caller decides what lies outside it). Memory order x fastest.
#[derive(Clone, Copy, Debug)]
pub struct Trilinear {
    /// Corner indices: (lo/hi x, lo/hi y, lo/hi z) with x fastest, i.e. corner c = x + 2y + 4z.
    pub idx: [usize; 8],
    /// Fractions along x, y, z, in [0, 1).
    pub f: [f32; 3],
}

impl Trilinear {
    /// Corners and fractions at `p`. Always inlined: called per sample in every march and gather
    /// loop, where LLVM otherwise keeps it out of line (a call per look-up, 10 % of `full`).
    #[inline(always)]
    pub fn new(dims: [usize; 3], p: [f32; 3]) -> Trilinear {
        let (lo, hi, f) = Self::corners(dims, p);
        let nx = dims[0];
        let nxy = nx * dims[1];
        let ix = |i: usize, j: usize, k: usize| i + nx * j + nxy * k;
        Trilinear {
            idx: [
                ix(lo[0], lo[1], lo[2]),
                ix(hi[0], lo[1], lo[2]),
                ix(lo[0], hi[1], lo[2]),
                ix(hi[0], hi[1], lo[2]),
                ix(lo[0], lo[1], hi[2]),
                ix(hi[0], lo[1], hi[2]),
                ix(lo[0], hi[1], hi[2]),
                ix(hi[0], hi[1], hi[2]),
            ],
            f,
        }
    }

    /// The eight corner indices (c = x + 2y + 4z, as [`Trilinear::idx`]) of the cell from `lo` to
    /// `hi` (per axis equal or one apart) in a grid of `dims`: one index and a stride per axis.
    #[inline(always)]
    pub fn corner_indices(dims: [usize; 3], lo: [usize; 3], hi: [usize; 3]) -> [usize; 8] {
        let (nx, nxy) = (dims[0], dims[0] * dims[1]);
        let base = lo[0] + nx * lo[1] + nxy * lo[2];
        let step = [hi[0] - lo[0], nx * (hi[1] - lo[1]), nxy * (hi[2] - lo[2])];
        std::array::from_fn(|c| base + (c & 1) * step[0] + (c >> 1 & 1) * step[1] + (c >> 2 & 1) * step[2])
    }

    /// The lower and upper corner per axis (clamped to the grid) and the fractions of `p`
    /// (continuous voxel coordinates, centres at +0.5) between them.
    #[inline(always)]
    pub fn corners(dims: [usize; 3], p: [f32; 3]) -> ([usize; 3], [usize; 3], [f32; 3]) {
        let mut lo = [0usize; 3];
        let mut hi = [0usize; 3];
        let mut f = [0f32; 3];
        for a in 0..3 {
            let n = dims[a] as isize;
            let x = p[a] - 0.5;
            let fl = fast_floor(x);
            let fi = fl as isize;
            f[a] = x - fl;
            lo[a] = fi.clamp(0, n - 1) as usize;
            hi[a] = (fi + 1).clamp(0, n - 1) as usize;
        }
        (lo, hi, f)
    }

    /// Blend the corner values `at(index)` by successive linear interpolation along x, y, z.
    /// Always inlined, like [`Trilinear::new`].
    #[inline(always)]
    pub fn blend<T>(&self, at: impl Fn(usize) -> T) -> T
    where
        T: Copy + std::ops::Add<Output = T> + std::ops::Mul<f32, Output = T>,
    {
        let [fx, fy, fz] = self.f;
        let i = &self.idx;
        let c00 = at(i[0]) * (1.0 - fx) + at(i[1]) * fx;
        let c10 = at(i[2]) * (1.0 - fx) + at(i[3]) * fx;
        let c01 = at(i[4]) * (1.0 - fx) + at(i[5]) * fx;
        let c11 = at(i[6]) * (1.0 - fx) + at(i[7]) * fx;
        let c0 = c00 * (1.0 - fy) + c10 * fy;
        let c1 = c01 * (1.0 - fy) + c11 * fy;
        c0 * (1.0 - fz) + c1 * fz
    }
}

/// Number of real spherical harmonics of degree ≤ 2 (the sky single-scattering field per band).
pub const SH_COEFFS: usize = 9;

/// The 9 real orthonormal spherical harmonics of degree ≤ 2 at unit `d`: [`real_sh`] at order 2
/// in closed form and f32 (the same functions, order and signs; tested equal), for the per-voxel
/// and per-pixel sky single scattering.
#[inline]
pub fn sh9(d: Vec3) -> [f32; SH_COEFFS] {
    let (x, y, z) = (d.x, d.y, d.z);
    [
        0.282_094_8,
        0.488_602_5 * z,
        0.488_602_5 * y,
        0.488_602_5 * x,
        1.092_548_4 * x * z,
        1.092_548_4 * y * z,
        0.315_391_6 * (3.0 * y * y - 1.0),
        1.092_548_4 * x * y,
        0.546_274_2 * (x * x - z * z),
    ]
}

/// Number of real spherical harmonics up to order `l_max`: (L + 1)².
pub fn sh_count(l_max: usize) -> usize {
    (l_max + 1) * (l_max + 1)
}

/// Real orthonormal spherical harmonics Y_lm(dir) for l ≤ `l_max` into `out` (length (L+1)²),
/// θ measured from +y and φ = atan2(z, x).
pub fn real_sh(l_max: usize, dir: glam::DVec3, out: &mut [f64]) {
    let x = dir.y.clamp(-1.0, 1.0);
    let s = (1.0 - x * x).max(0.0).sqrt();
    let phi = dir.z.atan2(dir.x);
    // Associated Legendre P_l^m(x) (no Condon–Shortley phase; the sign cancels in products).
    let n = l_max + 1;
    let mut p = vec![0.0; n * n];
    let at = |l: usize, m: usize| l * n + m;
    let mut pmm = 1.0;
    for m in 0..n {
        if m > 0 {
            pmm *= (2 * m - 1) as f64 * s;
        }
        p[at(m, m)] = pmm;
        if m + 1 < n {
            p[at(m + 1, m)] = x * (2 * m + 1) as f64 * pmm;
        }
        for l in m + 2..n {
            p[at(l, m)] = ((2 * l - 1) as f64 * x * p[at(l - 1, m)] - (l + m - 1) as f64 * p[at(l - 2, m)]) / (l - m) as f64;
        }
    }
    // cos mφ and sin mφ once per m (each l reads them).
    let trig: Vec<(f64, f64)> = (0..n).map(|m| ((m as f64 * phi).cos(), (m as f64 * phi).sin())).collect();
    for l in 0..n {
        let mut fact = 1.0; // (l − m)!/(l + m)!, built up as m grows
        for m in 0..=l {
            if m > 0 {
                fact /= ((l + m) * (l - m + 1)) as f64;
            }
            let k = ((2 * l + 1) as f64 / (4.0 * std::f64::consts::PI) * fact).sqrt();
            if m == 0 {
                out[l * l + l] = k * p[at(l, 0)];
            } else {
                let c = std::f64::consts::SQRT_2 * k * p[at(l, m)];
                let (cos, sin) = trig[m];
                out[l * l + l + m] = c * cos;
                out[l * l + l - m] = c * sin;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_int_is_the_cast_over_its_whole_range() {
        for i in -(1i32 << 22)..(1 << 22) {
            assert_eq!(small_int(i as f32), i);
        }
        for x in [-3.7f32, -1.0, -0.5, 0.0, 0.2, 1.0, 17.99, 4_194_303.0] {
            assert_eq!(small_int(x.floor()), x.floor() as i32, "{x}");
            assert_eq!(fast_floor(x), x.floor(), "{x}");
        }
    }

    #[test]
    fn sh9_is_real_sh_of_order_two() {
        for d in [
            Vec3::X,
            Vec3::Y,
            -Vec3::Z,
            Vec3::new(0.3, -0.8, 0.5).normalize(),
            Vec3::new(-0.6, 0.2, -0.77).normalize(),
        ] {
            let mut want = [0f64; SH_COEFFS];
            real_sh(2, glam::DVec3::new(d.x as f64, d.y as f64, d.z as f64), &mut want);
            for (k, (a, b)) in sh9(d).iter().zip(want).enumerate() {
                assert!((*a as f64 - b).abs() < 1e-6, "{d:?} coefficient {k}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn unit_vector_keeps_huge_and_tiny_directions() {
        let s = std::f32::consts::FRAC_1_SQRT_2;
        for v in [[1e30, 1e30, 0.0], [1e-30, 1e-30, 0.0], [3e38, 3e38, 0.0], [1e-45, 1e-45, 0.0]] {
            let u = unit_vector(v).unwrap();
            assert!((u - Vec3::new(s, s, 0.0)).length() < 1e-6, "{v:?} -> {u}");
        }
        assert_eq!(unit_vector([0.0, -2.0, 0.0]), Some(Vec3::NEG_Y));
        for v in [[0.0; 3], [f32::NAN, 1.0, 0.0], [f32::INFINITY, 0.0, 0.0]] {
            assert_eq!(unit_vector(v), None, "{v:?}");
        }
    }

    #[test]
    fn frame_is_orthonormal() {
        for n in [Vec3::X, Vec3::Y, Vec3::Z, -Vec3::Z, Vec3::new(0.3, -0.8, 0.5).normalize()] {
            let f = Frame::from_normal(n);
            assert!(f.t.dot(f.b).abs() < 1e-6 && f.t.dot(n).abs() < 1e-6 && f.b.dot(n).abs() < 1e-6);
            assert!((f.t.length() - 1.0).abs() < 1e-6 && (f.b.length() - 1.0).abs() < 1e-6);
        }
    }

    #[test]
    fn rng_streams_differ_and_repeat() {
        let a: Vec<u32> = (0..4)
            .map(|_| 0)
            .scan(Rng::for_pixel(1, 2, 3, 0), |r, _| Some(r.next_u32()))
            .collect();
        let b: Vec<u32> = (0..4)
            .map(|_| 0)
            .scan(Rng::for_pixel(1, 2, 3, 0), |r, _| Some(r.next_u32()))
            .collect();
        let c: Vec<u32> = (0..4)
            .map(|_| 0)
            .scan(Rng::for_pixel(1, 2, 3, 1), |r, _| Some(r.next_u32()))
            .collect();
        assert_eq!(a, b);
        assert_ne!(a, c);
        let mut r = Rng::new(7, 7);
        let mean: f64 = (0..100_000).map(|_| r.uniform() as f64).sum::<f64>() / 100_000.0;
        assert!((mean - 0.5).abs() < 0.01);
    }

    #[test]
    fn trilinear_is_exact_on_affine_fields_and_clamps_to_edge() {
        let dims = [5, 4, 3];
        let f = |i: usize, j: usize, k: usize| 1.0 + 2.0 * i as f32 - 0.5 * j as f32 + 0.25 * k as f32;
        let vals: Vec<f32> = (0..60).map(|n| f(n % 5, (n / 5) % 4, n / 20)).collect();
        let mut rng = Rng::new(3, 4);
        for _ in 0..200 {
            let p = [0.5 + 4.0 * rng.uniform(), 0.5 + 3.0 * rng.uniform(), 0.5 + 2.0 * rng.uniform()];
            let v = Trilinear::new(dims, p).blend(|n| vals[n]);
            let exact = 1.0 + 2.0 * (p[0] - 0.5) - 0.5 * (p[1] - 0.5) + 0.25 * (p[2] - 0.5);
            assert!((v - exact).abs() < 1e-4, "{p:?}: {v} vs {exact}");
        }
        // Outside the centres the edge value holds.
        assert_eq!(Trilinear::new(dims, [0.0, 0.1, 0.2]).blend(|n| vals[n]), vals[0]);
    }
}
