//! Anderson mixing (Walker & Ni 2011) of the accelerated iteration x → G(x) = DSA(sweep(x)) of a
//! cold solve, on the low orders of the moments. After DSA the error left is anisotropic: per
//! order l the change of the plain iteration falls by ~0.75 (l = 1) and ~0.6 (l = 2, 3) per
//! iteration on the noon scene, and orders 1–2 carry most of it. The new iterate is the
//! combination x_{k+1} = Σ_j α_j G(x_j) of the last [`DEPTH`] + 1 maps (Σ α_j = 1) whose I_00
//! residuals f_j = G(x_j)_00 − (x_j)_00 combine to the least |Σ α_j f_j|: the coefficients are
//! fitted on I_00 (what the stopping test reads) and applied to every harmonic of order
//! l ≤ [`MIXED_ORDER`]; the higher orders take G(x_k) as it is. Measured on the 19 evaluation
//! scenes (docs/transport.md, "Iteration and acceleration"): 159 → 132 iterations, every image
//! within 0.24·tolerance of a solve to 10⁻⁵.

use crate::par;
use std::collections::VecDeque;

/// Earlier maps combined with the newest: 1 took 8 iterations where 2 and 3 took 7.
pub(super) const DEPTH: usize = 2;

/// Highest order mixed: with l ≤ 1 the image's error, carried by the lagging l = 2 (its change
/// 4× that of I_00 at the stop), reached 0.87·tolerance on sun060; l ≤ 2 leaves ≤ 0.24.
pub(super) const MIXED_ORDER: usize = 2;

/// Values summed per chunk of the inner products; the chunks' sums are added in order, so the
/// coefficients are the same for any thread count.
const CHUNK: usize = 4096;

/// Rows (a voxel's band) per task of the mixing's update.
const ROWS: usize = 1024;

/// Bytes per full voxel the mixing holds: per earlier map, its harmonics of order ≤
/// [`MIXED_ORDER`] and its I_00 residual, for 3 bands in f32 (240 B at depth 2).
pub(super) fn bytes_per_full_voxel() -> u64 {
    (DEPTH * ((MIXED_ORDER + 1) * (MIXED_ORDER + 1) + 1) * 3 * 4) as u64
}

/// The history of the mixing: the earlier maps on the mixed harmonics and their I_00 residuals.
pub(super) struct Mixing {
    /// Solver indices of the mixed harmonics (order ≤ [`MIXED_ORDER`]); the first is I_00.
    mixed: Vec<usize>,
    nsh: usize,
    /// G(x_j) on the mixed harmonics per full voxel and band, oldest first.
    maps: VecDeque<Vec<f32>>,
    /// f_j, the I_00 residual per full voxel and band, oldest first.
    residuals: VecDeque<Vec<f32>>,
}

impl Mixing {
    /// An empty history for moments with `nsh` harmonics per band, in the solver's order, `perm`
    /// giving each one's `real_sh` index (whose order l is ⌊√index⌋).
    pub(super) fn new(perm: &[usize], nsh: usize) -> Mixing {
        let order_of = |i: usize| (perm[i] as f64).sqrt() as usize;
        Mixing {
            mixed: (0..nsh).filter(|&i| order_of(i) <= MIXED_ORDER).collect(),
            nsh,
            maps: VecDeque::new(),
            residuals: VecDeque::new(),
        }
    }

    /// Replace the mixed harmonics of `next` = G(x), x = `moments`, by the Anderson iterate and
    /// remember G(x) and its residual.
    pub(super) fn mix(&mut self, moments: &[f32], next: &mut [f32]) {
        let nsh = self.nsh;
        let residual: Vec<f32> = par::map_items(next.len().div_ceil(nsh), CHUNK, &|i| next[i * nsh] - moments[i * nsh]);
        let alpha = self.coefficients(&residual);
        let k = self.mixed.len();
        // The newest map goes into a fresh slot while the history fills, then into the oldest
        // map's, which each row reads before it is overwritten.
        let recycled = self.maps.len() == DEPTH;
        if recycled {
            let oldest = self.maps.pop_front().expect("DEPTH maps");
            self.maps.push_back(oldest);
            self.residuals.pop_front();
        } else {
            self.maps.push_back(vec![0f32; residual.len() * k]);
        }
        let n = self.maps.len();
        let (earlier, newest) = self.maps.make_contiguous().split_at_mut(n - 1);
        let slot = &mut newest[0];
        let mixed = &self.mixed;
        let tasks: Vec<(&mut [f32], &mut [f32])> = next.chunks_mut(ROWS * nsh).zip(slot.chunks_mut(ROWS * k)).collect();
        par::map_each(tasks, &|task, (rows, keeps)| {
            for (rr, (row, keep)) in rows.chunks_mut(nsh).zip(keeps.chunks_mut(k)).enumerate() {
                let r = task * ROWS + rr;
                for (j, &i) in mixed.iter().enumerate() {
                    let g = row[i];
                    if !alpha.is_empty() {
                        let mut v = alpha[alpha.len() - 1] * g as f64;
                        let mut a = 0;
                        if recycled {
                            v += alpha[0] * keep[j] as f64;
                            a = 1;
                        }
                        for (e, c) in earlier.iter().zip(&alpha[a..alpha.len() - 1]) {
                            v += c * e[r * k + j] as f64;
                        }
                        row[i] = v as f32;
                    }
                    keep[j] = g;
                }
            }
        });
        self.residuals.push_back(residual);
    }

    /// α over the remembered maps (oldest first) and the newest: the least-squares combination
    /// of the residuals with Σ α = 1, as min |f_k − Σ γ_i (f_{i+1} − f_i)| (Walker & Ni's
    /// form, lightly regularised); empty with no history, or when the residuals do not change.
    fn coefficients(&self, newest: &[f32]) -> Vec<f64> {
        let f: Vec<&[f32]> = self.residuals.iter().map(Vec::as_slice).chain([newest]).collect();
        let m = f.len() - 1;
        if m == 0 {
            return Vec::new();
        }
        // Column i: f_{i+1} − f_i.
        let mut gram = vec![vec![0.0f64; m]; m];
        let mut rhs = vec![0.0f64; m];
        for i in 0..m {
            rhs[i] = diff_dot(f[i + 1], f[i], newest, None);
            for j in 0..=i {
                gram[i][j] = diff_dot(f[i + 1], f[i], f[j + 1], Some(f[j]));
                gram[j][i] = gram[i][j];
            }
        }
        let trace: f64 = (0..m).map(|i| gram[i][i]).sum();
        if !(trace > 0.0 && trace.is_finite()) {
            return Vec::new();
        }
        for (i, row) in gram.iter_mut().enumerate() {
            row[i] += 1e-10 * trace;
        }
        let gamma = solve_small(gram, rhs);
        // G_k − Σ γ_i (G_{i+1} − G_i) as weights on G_0..G_k.
        let mut alpha = vec![0.0; m + 1];
        alpha[m] = 1.0;
        for (i, g) in gamma.iter().enumerate() {
            alpha[i + 1] -= g;
            alpha[i] += g;
        }
        alpha
    }
}

/// (a − b)·(c − d) (d = 0 when None), summed in fixed chunks.
fn diff_dot(a: &[f32], b: &[f32], c: &[f32], d: Option<&[f32]>) -> f64 {
    let parts: Vec<f64> = par::map_range(a.len().div_ceil(CHUNK), &|ci| {
        let r = ci * CHUNK..((ci + 1) * CHUNK).min(a.len());
        r.map(|e| (a[e] - b[e]) as f64 * (c[e] - d.map_or(0.0, |d| d[e])) as f64).sum::<f64>()
    });
    parts.iter().sum()
}

/// Gaussian elimination with partial pivoting of a small dense system (zeros if singular).
fn solve_small(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Vec<f64> {
    let n = b.len();
    for c in 0..n {
        let p = (c..n).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs())).unwrap_or(c);
        a.swap(c, p);
        b.swap(c, p);
        if a[c][c] == 0.0 {
            return vec![0.0; n];
        }
        let (pivot, below) = a.split_at_mut(c + 1);
        let pivot = &pivot[c];
        for (r, row) in below.iter_mut().enumerate() {
            let k = row[c] / pivot[c];
            row.iter_mut().zip(pivot).skip(c).for_each(|(x, p)| *x -= k * p);
            b[c + 1 + r] -= k * b[c];
        }
    }
    let mut x = vec![0.0; n];
    for r in (0..n).rev() {
        let s: f64 = (r + 1..n).map(|j| a[r][j] * x[j]).sum();
        x[r] = (b[r] - s) / a[r][r];
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transport::source::parity_order;

    /// A linear map per voxel and band on order-3 moments (16 harmonics): the first moments'
    /// error decays by 0.8 per iteration (the slow mode) and feeds I_00, every other harmonic's
    /// by 0.3; its fixed point x* = (1 − A)⁻¹ b is known.
    fn map(x: &[f32], b: &[f32], even: usize) -> Vec<f32> {
        let mut g = vec![0f32; x.len()];
        for ((gr, xr), br) in g.chunks_mut(16).zip(x.chunks(16)).zip(b.chunks(16)) {
            for i in 0..16 {
                let slow = (even..even + 3).contains(&i);
                gr[i] = if slow { 0.8 } else { 0.3 } * xr[i] + br[i];
            }
            gr[0] += 0.5 * (xr[even] + xr[even + 1] - xr[even + 2]);
        }
        g
    }

    /// Iterations until no harmonic changes by 1e-6, and the iterate, with or without mixing.
    fn iterate(b: &[f32], even: usize, perm: &[usize], mixed: bool) -> (usize, Vec<f32>) {
        let mut mixing = Mixing::new(perm, 16);
        let mut x = vec![0f32; b.len()];
        for n in 1..200 {
            let mut g = map(&x, b, even);
            let change = g.iter().zip(&x).fold(0f32, |c, (p, q)| c.max((p - q).abs()));
            if mixed {
                mixing.mix(&x, &mut g);
            }
            x = g;
            if change < 1e-6 {
                return (n, x);
            }
        }
        (200, x)
    }

    #[test]
    fn mixing_removes_a_slow_first_moment_mode_and_keeps_the_fixed_point() {
        let (perm, even) = parity_order(3);
        let rows = 3 * 5000;
        let b: Vec<f32> = (0..rows * 16).map(|i| ((i * 7919 % 1000) as f32 / 1000.0) * if i % 16 == 0 { 1.0 } else { 0.1 }).collect();
        // The fixed point: the other harmonics first, then the first moments, then I_00.
        let exact: Vec<f64> = b
            .chunks(16)
            .flat_map(|br| {
                let mut x: Vec<f64> = (0..16).map(|i| br[i] as f64 / if (even..even + 3).contains(&i) { 0.2 } else { 0.7 }).collect();
                x[0] = (br[0] as f64 + 0.5 * (x[even] + x[even + 1] - x[even + 2])) / 0.7;
                x
            })
            .collect();
        let (plain, _) = iterate(&b, even, &perm, false);
        let (mixed, x) = iterate(&b, even, &perm, true);
        let err = x.iter().zip(&exact).fold(0f64, |e, (p, q)| e.max((*p as f64 - q).abs()));
        eprintln!("iterations: plain {plain}, mixed {mixed}; largest error of the mixed iterate {err:.1e}");
        assert!(mixed * 2 < plain, "mixed {mixed}, plain {plain}");
        assert!(err < 1e-4, "{err}");
        // The same bits on one thread and four.
        let run = |n| rayon::ThreadPoolBuilder::new().num_threads(n).build().unwrap().install(|| iterate(&b, even, &perm, true));
        let (one, four) = (run(1), run(4));
        assert_eq!(one.0, four.0);
        assert!(one.1.iter().zip(&four.1).all(|(p, q)| p.to_bits() == q.to_bits()));
    }

    #[test]
    fn the_history_holds_depth_maps_of_the_mixed_orders() {
        let (perm, _) = parity_order(7);
        let mut mixing = Mixing::new(&perm, 64);
        assert_eq!(mixing.mixed.len(), 9);
        let x = vec![0f32; 2 * 3 * 64];
        for k in 1..5 {
            let mut g = vec![k as f32; x.len()];
            mixing.mix(&x, &mut g);
            assert_eq!(mixing.maps.len(), k.min(DEPTH));
            assert_eq!(mixing.residuals.len(), k.min(DEPTH));
        }
        assert_eq!(bytes_per_full_voxel(), 240);
    }
}
