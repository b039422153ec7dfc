//! Orders of scattering over a view-aligned cube (paper section 4, eqs. 8–9).
//!
//! **Direction convention.** The cube at a segment's centre c_j has its local +x axis along the
//! viewing ray `d` (from the eye into the scene). A cube pixel in local direction ω shows the
//! radiance that arrives at c_j *from* ω, i.e. light travelling along −ω. To reach the eye it must
//! leave travelling along −d, so the scattering angle satisfies cos θ = (−ω)·(−d) = ω·d = ω_x.
//! The forward peak of the phase function therefore sits on the +x face: the part of the scene
//! behind the segment (seen through it) — the silver lining when the sun is behind the cloud.
//!
//! **Weights.** For order i the i-fold phase function is HG(g^i) (see [`crate::edges::orders`]). The
//! table holds w_i(pixel) = ∫_pixel HG(g^i, ω_x) dω, integrated adaptively (the forward peak of
//! g = 0.9 is narrower than a pixel) and then normalised so Σ_pixels w_i = 1 exactly (so a uniform
//! cube gives K_i = L exactly: the furnace property; the raw sum is within 1e-4 of 1).
//! K_i = Σ_pixels w_i · L (eq. 9's convolution sample).
//!
//! **Albedo.** The Poisson weights q_i (eq. 8) count *collisions*; each collision scatters with
//! probability a (per band) and absorbs otherwise, so the radiance that survives exactly i
//! scatterings carries a^i: E = Σ_{i≥1} q_i a^i K_i. The paper writes eq. 9 for a ≈ 1; with
//! absorption, Σ_{i≥0} q_i a^i = e^{−D(1−a)} is the correct transmittance of light that is only
//! absorbed, not scattered, which checks the factor. The i = 0 term (unscattered light from behind)
//! is not part of E: the gather composites what lies behind the segment attenuated by e^{−D}.

use crate::cube::CubeImage;
use crate::edges::orders::poisson_weights;
use crate::lighting::bins::{rect_solid_angle, CUBE_FACES};
use crate::math::Rgb;
use crate::optics::Hg;
use crate::par;

/// Sub-pixels per rectangle edge in one step of the adaptive pixel integration.
const SUB: usize = 3;
/// Relative tolerance of the adaptive pixel integration (per pixel).
const PIXEL_TOL: f64 = 1e-4;
/// Deepest subdivision of a pixel (each level splits it 2×2).
const MAX_LEVEL: usize = 7;

/// The k² midpoints of a cube-face rectangle split k×k: (cos θ from local +x, solid angle).
fn rect_points(face: usize, u0: f64, u1: f64, v0: f64, v1: f64, k: usize, out: &mut [(f64, f64)]) {
    let f = &CUBE_FACES[face];
    for b in 0..k {
        let (va, vb) = (v0 + (v1 - v0) * b as f64 / k as f64, v0 + (v1 - v0) * (b + 1) as f64 / k as f64);
        for a in 0..k {
            let (ua, ub) = (u0 + (u1 - u0) * a as f64 / k as f64, u0 + (u1 - u0) * (a + 1) as f64 / k as f64);
            let dir = f.n.as_dvec3() + f.tu.as_dvec3() * (0.5 * (ua + ub)) + f.tv.as_dvec3() * (0.5 * (va + vb));
            out[b * k + a] = (dir.x / dir.length(), rect_solid_angle(ua, ub, va, vb));
        }
    }
}

/// One rectangle of a pixel's adaptive rule: its SUB² midpoints (cos θ, dΩ) and, once a rule
/// has needed them, its four quadrants'. The geometry (four atans per point) is what the rule
/// costs; the tree keeps it for every order of the same pixel, which then only re-weights it.
struct RectNode {
    pts: [(f64, f64); SUB * SUB],
    kids: Option<Box<[RectNode; 4]>>,
}

impl RectNode {
    fn new(face: usize, r: Rect) -> RectNode {
        let mut pts = [(0.0, 0.0); SUB * SUB];
        rect_points(face, r.0, r.1, r.2, r.3, SUB, &mut pts);
        RectNode { pts, kids: None }
    }

    /// Midpoint rule: Σ HG(g, ω_x)·dΩ over the SUB² points.
    fn midpoint(&self, g: Hg) -> f64 {
        let mut s = 0.0;
        for (c, w) in &self.pts {
            s += g.eval_cos_f64(*c) * w;
        }
        s
    }

    /// ∫ HG(g, ω_x) dΩ over the rectangle `r` of `face`, adaptively: a rectangle whose SUB²
    /// midpoint estimate disagrees with the sum over its four quadrants by more than PIXEL_TOL
    /// (relative) is split. The forward peak of g = 0.9 needs a few levels; the rest of the
    /// sphere none.
    fn integrate(&mut self, face: usize, r: Rect, g: Hg, level: usize) -> f64 {
        let coarse = self.midpoint(g);
        let quads = quadrants(r);
        let kids = self.kids.get_or_insert_with(|| Box::new(quads.map(|q| RectNode::new(face, q))));
        let fine: f64 = kids.iter().map(|k| k.midpoint(g)).sum();
        if level >= MAX_LEVEL || (fine - coarse).abs() <= PIXEL_TOL * fine + 1e-12 {
            return fine;
        }
        kids.iter_mut().zip(quads).map(|(k, q)| k.integrate(face, q, g, level + 1)).sum()
    }
}

/// A cube-face rectangle (u0, u1, v0, v1).
type Rect = (f64, f64, f64, f64);

/// The four quadrants of `r`, (u, v) = (lo, lo), (hi, lo), (lo, hi), (hi, hi).
fn quadrants(r: Rect) -> [Rect; 4] {
    let (u0, u1, v0, v1) = r;
    let (um, vm) = (0.5 * (u0 + u1), 0.5 * (v0 + v1));
    [(u0, um, v0, vm), (um, u1, v0, vm), (u0, um, vm, v1), (um, u1, vm, v1)]
}

/// Largest optical depth the Poisson weights are evaluated at (see [`segment_orders`]).
pub const MAX_DEPTH: f64 = 500.0;

/// Default bound on the omitted Poisson tail Σ q_i beyond the last order kept (eq. 8).
pub const DEFAULT_TAIL: f64 = 1e-4;

/// Precomputed per-pixel weights w_i for orders i = 1..=`max_order` at one cube resolution and g.
#[derive(Clone, Debug)]
pub struct OrderKernel {
    /// Pixels per face edge.
    pub res: usize,
    /// Highest order tabulated.
    pub max_order: usize,
    /// w[(i − 1)·6res² + pixel], f32, each order sums to 1.
    weights: Vec<f32>,
}

impl OrderKernel {
    /// Tabulate orders 1..=`max_order` (at least 1) for cubes of `res` pixels per edge.
    pub fn new(res: usize, phase: Hg, max_order: usize) -> Self {
        assert!(res > 0, "cube resolution must be positive");
        let max_order = max_order.max(1);
        let n = 6 * res * res;
        let orders: Vec<Hg> = (1..=max_order).map(|i| phase.order(i)).collect();
        // The weights depend on a pixel only through ω_x over it, the same on pixels that the
        // cube's symmetries about the x axis map onto each other (8 per ±x face, the four side
        // faces alike): each class is integrated once, at its first pixel.
        let (class, reps) = symmetry_classes(res);
        let unique: Vec<Vec<f64>> = par::map_range(reps.len(), &|c| pixel_integrals(res, reps[c], &orders));
        let raw: Vec<&Vec<f64>> = class.iter().map(|&c| &unique[c]).collect();
        let mut weights = Vec::with_capacity(max_order * n);
        for i in 0..max_order {
            let total: f64 = raw.iter().map(|r| r[i]).sum();
            weights.extend(raw.iter().map(|r| (r[i] / total) as f32));
        }
        OrderKernel {
            res,
            max_order,
            weights,
        }
    }

    /// Pixels per cube (6·res²).
    #[inline]
    pub fn pixels(&self) -> usize {
        6 * self.res * self.res
    }

    /// The weights of order `i` (1 ≤ i ≤ max_order), indexed like [`CubeImage::pixels`].
    #[inline]
    pub fn weights(&self, i: usize) -> &[f32] {
        assert!(i >= 1 && i <= self.max_order, "order {i} outside 1..={}", self.max_order);
        let n = self.pixels();
        &self.weights[(i - 1) * n..i * n]
    }

    /// K_i = Σ_pixels w_i·L for i = 1..=`orders` (index 0 holds K_1). Orders above `max_order`
    /// use the last tabulated one (g^i is then below g^max_order; see [`OrderKernel::orders_for_depth`]).
    pub fn convolve(&self, cube: &CubeImage, orders: usize) -> Vec<Rgb> {
        assert_eq!(cube.res, self.res, "cube resolution differs from the kernel's");
        let mut k: Vec<Rgb> = (1..=orders.min(self.max_order))
            .map(|i| {
                let w = self.weights(i);
                let mut s = [0f64; 3];
                for (wk, l) in w.iter().zip(&cube.pixels) {
                    let wk = *wk as f64;
                    s[0] += wk * l.x as f64;
                    s[1] += wk * l.y as f64;
                    s[2] += wk * l.z as f64;
                }
                Rgb::new(s[0] as f32, s[1] as f32, s[2] as f32)
            })
            .collect();
        if let Some(&last) = k.last() {
            k.resize(orders, last);
        }
        k
    }

    /// Σ_i w_i(pixel) summed over the pixels a predicate selects (for tests and diagnostics).
    pub fn mass(&self, i: usize, select: impl Fn(usize) -> bool) -> f64 {
        self.weights(i)
            .iter()
            .enumerate()
            .filter(|(k, _)| select(*k))
            .map(|(_, w)| *w as f64)
            .sum()
    }

    /// Orders worth tabulating for segments up to optical depth `d_max`: those eq. 8 needs, but no
    /// further than the first order with g^i < 0.02 (higher orders are within 2 % of isotropic
    /// in their first moment, and [`OrderKernel::convolve`] reuses the last tabulated one).
    pub fn orders_to_tabulate(phase: Hg, d_max: f64, tail: f64) -> usize {
        let need = Self::orders_for_depth(d_max, tail);
        let flat = (1..=need).find(|&i| phase.order(i).mean_cosine().abs() < 0.02).unwrap_or(need);
        need.min(flat).max(1)
    }

    /// Number of orders (≥ 1) that eq. 8 needs at optical depth `d` for an omitted tail below `tail`.
    pub fn orders_for_depth(d: f64, tail: f64) -> usize {
        (poisson_weights(d.min(MAX_DEPTH), tail).len() - 1).max(1)
    }
}

/// ∫ HG(g_i, ω_x) dΩ over pixel `p` (face-major, then rows) of a cube of `res` pixels per edge,
/// for each order's phase function: the first two levels of the adaptive rule are the SUB²
/// coarse and (2·SUB)² fine midpoints; where they disagree the pixel is integrated adaptively on
/// a tree of rectangles built once for all its orders.
fn pixel_integrals(res: usize, p: usize, orders: &[Hg]) -> Vec<f64> {
    let (face, j, i) = (p / (res * res), (p / res) % res, p % res);
    let (u0, u1) = CubeImage::pixel_range(res, i);
    let (v0, v1) = CubeImage::pixel_range(res, j);
    let mut coarse = [(0.0, 0.0); SUB * SUB];
    let mut fine = [(0.0, 0.0); 4 * SUB * SUB];
    rect_points(face, u0, u1, v0, v1, SUB, &mut coarse);
    rect_points(face, u0, u1, v0, v1, 2 * SUB, &mut fine);
    let mut tree: Option<RectNode> = None;
    orders
        .iter()
        .map(|gi| {
            let c: f64 = coarse.iter().map(|(x, w)| gi.eval_cos_f64(*x) * w).sum();
            let f: f64 = fine.iter().map(|(x, w)| gi.eval_cos_f64(*x) * w).sum();
            if (f - c).abs() <= PIXEL_TOL * f + 1e-12 {
                f
            } else {
                let r = (u0, u1, v0, v1);
                tree.get_or_insert_with(|| RectNode::new(face, r)).integrate(face, r, *gi, 0)
            }
        })
        .collect()
}

/// The pixels of a cube of `res` pixels per edge grouped by the symmetries that keep ω_x: per
/// pixel the index of its class, and each class's first pixel. On a ±x face ω_x = ±1/|dir| is
/// even in u and v and symmetric under their swap; on a side face it is ±(the x-aligned
/// coordinate)/|dir|, even in the other one, and the four side faces map onto each other by
/// quarter turns about x. Mirroring a pixel index i ↦ res − 1 − i mirrors its range exactly.
fn symmetry_classes(res: usize) -> (Vec<usize>, Vec<usize>) {
    let fold = |i: usize| i.min(res - 1 - i);
    let key = |p: usize| -> (u8, usize, usize) {
        let (face, j, i) = (p / (res * res), (p / res) % res, p % res);
        let f = &CUBE_FACES[face];
        if f.n.x != 0.0 {
            let (a, b) = (fold(i), fold(j));
            (if f.n.x > 0.0 { 0 } else { 1 }, a.min(b), a.max(b))
        } else {
            // The tangent along ±x carries ω_x's sign; the other coordinate enters squared.
            let (along, sign, other) = if f.tu.x != 0.0 { (i, f.tu.x, j) } else { (j, f.tv.x, i) };
            (2, if sign > 0.0 { along } else { res - 1 - along }, fold(other))
        }
    };
    let mut first = std::collections::HashMap::new();
    let mut reps = Vec::new();
    let class = (0..6 * res * res)
        .map(|p| {
            *first.entry(key(p)).or_insert_with(|| {
                reps.push(p);
                reps.len() - 1
            })
        })
        .collect();
    (class, reps)
}

/// The scattering weights of one segment: c_i = q_i (i ≥ 1) from eq. 8 with the omitted Poisson
/// tail (< `tail`) added to the highest order kept, so Σ_{i≥0} q_i = 1 exactly and the furnace
/// test holds to rounding. Index 0 of the result is order 1.
pub fn segment_orders(d: f64, tail: f64) -> Vec<f64> {
    // Beyond D = 500 (never reached by a low-density segment of a sensible scene) e^{−D} would
    // underflow; there every kept order is far past the tabulated ones, which are all equal.
    let mut q = poisson_weights(d.min(MAX_DEPTH), tail);
    let omitted = (1.0 - q.iter().sum::<f64>()).max(0.0);
    if q.len() == 1 {
        // D so small that q_0 alone passes the bound: keep order 1 with the whole remainder.
        q.push(0.0);
    }
    let last = q.len() - 1;
    q[last] += omitted;
    q.remove(0);
    q
}

/// E = Σ_{i≥1} q_i a^i K_i (eq. 9 with albedo), `q[0]` and `k[0]` being order 1; where `k` holds
/// fewer orders than `q`, its last serves the rest (high orders are nearly isotropic). Orders with
/// index ≥ `skip_below` only (1-based; pass 1 for all, 2 to leave out single scattering).
pub fn edge_radiance(q: &[f64], k: &[Rgb], albedo: Rgb, skip_below: usize) -> Rgb {
    let mut e = [0f64; 3];
    let a = [albedo.x as f64, albedo.y as f64, albedo.z as f64];
    let mut ai = [1f64; 3];
    let Some(last) = k.last() else {
        return Rgb::ZERO;
    };
    for (idx, (qi, ki)) in q.iter().zip(k.iter().chain(std::iter::repeat(last))).enumerate() {
        for b in 0..3 {
            ai[b] *= a[b];
        }
        if idx + 1 < skip_below {
            continue;
        }
        e[0] += qi * ai[0] * ki.x as f64;
        e[1] += qi * ai[1] * ki.y as f64;
        e[2] += qi * ai[2] * ki.z as f64;
    }
    Rgb::new(e[0] as f32, e[1] as f32, e[2] as f32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vec3;
    use std::f64::consts::PI;

    #[test]
    fn symmetric_pixels_have_the_integrals_of_their_class() {
        // Every pixel's own integrals against its class representative's, at an even and an odd
        // resolution; the classes are the 8-fold folds of the ±x faces and one side face's halves.
        let orders: Vec<Hg> = (1..=4).map(|i| Hg::new(0.85).order(i)).collect();
        for res in [4, 5] {
            let (class, reps) = symmetry_classes(res);
            let half = res.div_ceil(2);
            assert_eq!(reps.len(), 2 * half * (half + 1) / 2 + res * half, "res {res}");
            for p in 0..6 * res * res {
                let own = pixel_integrals(res, p, &orders);
                let rep = pixel_integrals(res, reps[class[p]], &orders);
                for (a, b) in own.iter().zip(&rep) {
                    assert!((a - b).abs() <= 1e-12 * b.abs().max(1e-300), "res {res} pixel {p}: {a} vs {b}");
                }
            }
        }
    }

    #[test]
    fn weights_sum_to_one_and_peak_forward() {
        let k = OrderKernel::new(8, Hg::new(0.9), 6);
        for i in 1..=6 {
            let s: f64 = k.weights(i).iter().map(|w| *w as f64).sum();
            assert!((s - 1.0).abs() < 1e-5, "order {i}: {s}");
        }
        // Order 1 at g = 0.9: the +x face lies between the cones θ < 45° (inscribed) and
        // θ < arccos(1/√3) (circumscribed), whose HG masses are 0.9116 and 0.9354 (closed-form CDF),
        // against 1/6 for an isotropic kernel.
        let n = 64;
        let front = k.mass(1, |p| p < n);
        assert!(front > 0.9116 && front < 0.9354, "front mass {front}");
        // High orders tend to isotropic: g^6 = 0.53 already spreads the mass out.
        assert!(k.mass(6, |p| p < n) < front);
        // −x face (backward) carries little at order 1.
        let back = k.mass(1, |p| (n..2 * n).contains(&p));
        assert!(back < 0.01, "back mass {back}");
    }

    #[test]
    fn bright_pixel_ahead_dominates_one_behind() {
        // One bright pixel straight ahead (+x face centre) versus straight behind (−x face centre).
        let res = 8;
        let k = OrderKernel::new(res, Hg::new(0.9), 1);
        let mut ahead = CubeImage::new(res);
        let mut behind = CubeImage::new(res);
        let ia = ahead.index(0, res / 2, res / 2);
        let ib = behind.index(1, res / 2, res / 2);
        ahead.pixels[ia] = Rgb::ONE;
        behind.pixels[ib] = Rgb::ONE;
        let ka = k.convolve(&ahead, 1)[0].x as f64;
        let kb = k.convolve(&behind, 1)[0].x as f64;
        // Single pixel: K = ∫_pixel HG dΩ; brute force with 400² points over the pixel.
        let brute = |face: usize| {
            let (u0, u1) = CubeImage::pixel_range(res, res / 2);
            let n = 400;
            let mut s = 0.0;
            for b in 0..n {
                for a in 0..n {
                    let ua = u0 + (u1 - u0) * a as f64 / n as f64;
                    let va = u0 + (u1 - u0) * b as f64 / n as f64;
                    let (du, dv) = ((u1 - u0) / n as f64, (u1 - u0) / n as f64);
                    let f = &CUBE_FACES[face];
                    let dir = f.n.as_dvec3() + f.tu.as_dvec3() * (ua + 0.5 * du) + f.tv.as_dvec3() * (va + 0.5 * dv);
                    s += Hg::new(0.9).eval_cos_f64(dir.x / dir.length()) * rect_solid_angle(ua, ua + du, va, va + dv);
                }
            }
            s
        };
        assert!(ka > 1000.0 * kb, "{ka} vs {kb}");
        assert!((ka / brute(0) - 1.0).abs() < 1e-3, "{ka} vs {}", brute(0));
        assert!((kb / brute(1) - 1.0).abs() < 1e-3, "{kb} vs {}", brute(1));
        // Mirror check: with the cube oriented along a world direction, the pixel whose world
        // direction is the ray direction is the forward one.
        let d = crate::math::Vec3::new(0.2, -0.4, 0.9).normalize();
        let c = CubeImage::along(res, d);
        assert!(c.direction(0, res / 2, res / 2).dot(d) > 0.95);
    }

    /// Brute-force order-i convolution: ∫ p_i(ω_x) L(ω) dω by quadrature in (μ, φ) about +x, for a
    /// smooth radiance L, against the kernel applied to the pixelised L.
    #[test]
    fn matches_brute_force_convolution_of_smooth_radiance() {
        let g = 0.8f32;
        let res = 24;
        let k = OrderKernel::new(res, Hg::new(g), 4);
        let l = |w: Vec3| 1.0 + 0.8 * w.x + 0.5 * w.y * w.z + 0.3 * (3.0 * w.x * w.x - 1.0);
        let mut cube = CubeImage::new(res);
        for face in 0..6 {
            for j in 0..res {
                for i in 0..res {
                    let idx = cube.index(face, i, j);
                    cube.pixels[idx] = Rgb::splat(l(CubeImage::local_direction(res, face, i, j)));
                }
            }
        }
        let kk = k.convolve(&cube, 4);
        for i in 1..=4 {
            let phase_i = Hg::new(g).order(i);
            let gi = phase_i.mean_cosine();
            // Quadrature with μ = 1 − 2s² (points crowd the forward peak).
            let (nt, np) = (800, 256);
            let mut sum = 0.0;
            for a in 0..nt {
                let s = (a as f64 + 0.5) / nt as f64;
                let mu = 1.0 - 2.0 * s * s;
                let dmu = 4.0 * s / nt as f64;
                let st = (1.0 - mu * mu).max(0.0).sqrt();
                for b in 0..np {
                    let phi = (b as f64 + 0.5) / np as f64 * 2.0 * PI;
                    let w = Vec3::new(mu as f32, (st * phi.cos()) as f32, (st * phi.sin()) as f32);
                    sum += phase_i.eval_cos_f64(mu) * l(w) as f64 * dmu * 2.0 * PI / np as f64;
                }
            }
            // Exact by Legendre: ∫ HG(g^i) L = L_0 + g^i·0.8 (the P1 term) + g^{2i}·0.3·2 (P2 = (3μ²−1)/2).
            let exact = 1.0 + gi * 0.8 + gi * gi * 0.6;
            assert!((sum - exact).abs() < 2e-3, "quadrature {sum} vs Legendre {exact}");
            // Pixelisation of L (24² per face) limits the kernel's accuracy to about 1 %.
            assert!(
                (kk[i - 1].x as f64 - exact).abs() < 0.01 * exact,
                "order {i}: {} vs {exact}",
                kk[i - 1].x
            );
        }
    }

    #[test]
    fn segment_orders_sum_with_q0_to_one_and_tail_bound() {
        for &d in &[0.0, 1e-6, 0.05, 0.7, 3.0, 12.0] {
            let q = segment_orders(d, DEFAULT_TAIL);
            let s: f64 = q.iter().sum::<f64>() + (-d).exp();
            assert!((s - 1.0).abs() < 1e-12, "d={d}: {s}");
            // Without the tail folding the bound holds: the raw weights leave < 1e-4 out.
            let raw = poisson_weights(d, DEFAULT_TAIL);
            assert!(1.0 - raw.iter().sum::<f64>() < DEFAULT_TAIL);
            assert_eq!(q.len(), (raw.len() - 1).max(1));
        }
        // Huge depths stay finite and normalised.
        let q = segment_orders(5000.0, DEFAULT_TAIL);
        assert!(q.iter().all(|x| x.is_finite()) && (q.iter().sum::<f64>() - 1.0).abs() < 1e-9 && q.len() < 700);
    }

    #[test]
    fn uniform_cube_gives_closed_form() {
        // K_i = L for all i; E = Σ_{i≥1} q_i a^i L = (e^{−D(1−a)} − e^{−D}) L (up to the tail).
        let k = OrderKernel::new(4, Hg::new(0.9), 40);
        let mut cube = CubeImage::new(4);
        cube.pixels.iter_mut().for_each(|p| *p = Rgb::new(2.0, 1.0, 0.5));
        let a = Rgb::new(1.0, 0.9, 0.5);
        for &d in &[0.1f64, 1.0, 4.0] {
            let q = segment_orders(d, 1e-10);
            let kk = k.convolve(&cube, q.len());
            let e = edge_radiance(&q, &kk, a, 1);
            for (b, (lb, ab)) in [(e.x, a.x), (e.y, a.y), (e.z, a.z)].iter().enumerate() {
                let lin = [2.0, 1.0, 0.5][b];
                let exact = ((-d * (1.0 - *ab as f64)).exp() - (-d).exp()) * lin;
                assert!((*lb as f64 - exact).abs() < 1e-5, "d={d} band {b}: {lb} vs {exact}");
            }
            // Leaving out order 1 removes exactly q_1 a L.
            let e2 = edge_radiance(&q, &kk, a, 2);
            assert!(((e - e2).x as f64 - q[0] * 2.0).abs() < 1e-5);
            // K's last order serves the orders beyond it: the same E from the first two alone.
            assert_eq!(edge_radiance(&q, &kk[..2], a, 1), e);
        }
    }
}
