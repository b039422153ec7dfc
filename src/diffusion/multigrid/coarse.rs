//! The coarsest level, solved exactly by dense Cholesky.

use super::codec::{pow2, Mg, Real};
use super::level::Level;
use super::operator::Stencils;
use super::{NONE, PAD};

/// Dense Cholesky factor of the coarsest level.
#[derive(Clone, Debug)]
pub(super) struct Dense {
    /// The level's entries that are unknowns.
    pub(super) cells: Vec<usize>,
    /// The factor L (row-major) below the diagonal and on it, Lᵀ above it.
    pub(super) l: Vec<f64>,
    /// Per row of L, its first nonzero column (the matrix's envelope, which Cholesky keeps).
    first: Vec<usize>,
    /// Per column of L, one past its last nonzero row.
    end: Vec<usize>,
}

/// Per row of the symmetric n×n matrix `a` (row-major), its first nonzero column: the envelope.
/// A lexicographically numbered grid's rows reach back one plane, so the envelope holds about
/// n·(cells per plane) entries against the n²/2 of the triangle.
pub(super) fn envelope(a: &[f64], n: usize) -> Vec<usize> {
    (0..n)
        .map(|i| (0..i).find(|&k| a[i * n + k] != 0.0).unwrap_or(i))
        .collect()
}

/// In-place lower Cholesky factor of the dense n×n SPD matrix `a` (row-major) whose row i has no
/// nonzero before column `first[i]` ([`envelope`]). Cholesky fills only inside the envelope, so
/// each dot product starts where both rows do and the rows that start after column j are left at
/// zero: n·b² work for an envelope of b columns rather than n³/3. Pivots are clamped at 1e-300 so
/// a singular coarse grid still factors; returns the smallest pivot before the clamp (> 0 exactly
/// when `a` is positive definite).
pub(super) fn cholesky_in_place(a: &mut [f64], n: usize, first: &[usize]) -> f64 {
    let mut smallest = f64::INFINITY;
    for j in 0..n {
        let mut d = a[j * n + j];
        for k in first[j]..j {
            d -= a[j * n + k] * a[j * n + k];
        }
        smallest = smallest.min(d);
        let d = d.max(1e-300).sqrt();
        a[j * n + j] = d;
        for i in j + 1..n {
            if first[i] > j {
                continue;
            }
            let mut v = a[i * n + j];
            for k in first[i].max(first[j])..j {
                v -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = v / d;
        }
    }
    smallest
}

impl Dense {
    /// The factor of operator `s` divided by 2^unit (the level's [`Level::unit`]), whose
    /// unknowns are the entries `entry` of `level`.
    pub(super) fn build(s: &impl Stencils, level: &Level, entry: &[u32]) -> Dense {
        let to_unit = pow2(-level.unit);
        let cells: Vec<usize> = (0..level.len()).filter(|e| level.unknown(*e) != PAD).collect();
        let n = cells.len();
        let mut q_of = vec![usize::MAX; level.len()];
        for (q, e) in cells.iter().enumerate() {
            q_of[*e] = q;
        }
        let mut a = vec![0f64; n * n];
        for (q, &e) in cells.iter().enumerate() {
            let nd = s.node(level.unknown(e) as usize);
            a[q * n + q] = nd.diag * to_unit;
            for ax in 0..3 {
                let v = nd.up[ax] * to_unit;
                if v != 0.0 && nd.up_nbr[ax] != NONE {
                    let r = q_of[entry[nd.up_nbr[ax] as usize] as usize];
                    a[q * n + r] += v;
                    a[r * n + q] += v;
                }
            }
        }
        let first = envelope(&a, n);
        cholesky_in_place(&mut a, n, &first);
        // Lᵀ into the upper triangle: the backward substitution then reads rows too.
        let mut end: Vec<usize> = (1..=n).collect();
        for i in 0..n {
            for j in first[i]..i {
                a[j * n + i] = a[i * n + j];
                end[j] = end[j].max(i + 1);
            }
        }
        Dense { cells, l: a, first, end }
    }

    /// x = A⁻¹ b on the level's unknowns, all systems in one pass over the factor (each row read
    /// once per substitution, forward along L's rows, backward along Lᵀ's).
    pub(super) fn solve<const K: usize>(&self, b: &[[Mg; K]], x: &mut [[Mg; K]]) {
        let n = self.cells.len();
        x.fill([0.0; K]);
        let mut y: Vec<[f64; K]> = self.cells.iter().map(|c| b[*c].map(Real::get)).collect();
        for i in 0..n {
            let (done, rest) = y.split_at_mut(i);
            let row = &self.l[i * n + self.first[i]..i * n + i];
            let v = &mut rest[0];
            for (lk, yk) in row.iter().zip(&done[self.first[i]..]) {
                for k in 0..K {
                    v[k] -= lk * yk[k];
                }
            }
            *v = v.map(|v| v / self.l[i * n + i]);
        }
        for i in (0..n).rev() {
            let (head, done) = y.split_at_mut(i + 1);
            let row = &self.l[i * n + i + 1..i * n + self.end[i]];
            let v = &mut head[i];
            for (lk, yk) in row.iter().zip(done.iter()) {
                for k in 0..K {
                    v[k] -= lk * yk[k];
                }
            }
            *v = v.map(|v| v / self.l[i * n + i]);
        }
        for (c, v) in self.cells.iter().zip(&y) {
            x[*c] = v.map(Mg::of);
        }
    }
}
