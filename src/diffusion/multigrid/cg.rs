//! Conjugate gradients preconditioned by one multigrid cycle, with the iterate in f64 and its
//! other vectors in f32, stopped on the true residual in f64 ([`Hierarchy::solve_many`]).

use super::super::SolveStats;
use super::codec::Rows;
use super::codec::{pow2, Mg, Real};
use super::cycle::Work;
use super::level::{with_rows, Coded, Level};
use crate::par::{for_chunks, map_chunks, map_each, map_range};
use super::{Hierarchy, CHUNK, PAD};

/// Deterministic dot products per system: per-chunk partial sums added in order.
pub(super) fn dot<A: Real, B: Real, const K: usize>(a: &[[A; K]], b: &[[B; K]]) -> [f64; K] {
    let parts: Vec<[f64; K]> = map_range(a.len().div_ceil(CHUNK), &|ci| {
        let chunk = ci * CHUNK..a.len().min((ci + 1) * CHUNK);
        let mut s = [0.0; K];
        for (p, q) in a[chunk.clone()].iter().zip(&b[chunk]) {
            for k in 0..K {
                s[k] += p[k].get() * q[k].get();
            }
        }
        s
    });
    sum_parts(&parts)
}

pub(super) fn sum_parts<const K: usize>(parts: &[[f64; K]]) -> [f64; K] {
    let mut s = [0.0; K];
    for p in parts {
        for k in 0..K {
            s[k] += p[k];
        }
    }
    s
}

/// The CG step y += α p (in f64), r −= α q per system.
pub(super) fn cg_step<const K: usize>(y: &mut [[f64; K]], r: &mut [[Mg; K]], p: &[[Mg; K]], q: &[[Mg; K]], alpha: [f64; K]) {
    let chunks = y.chunks_mut(CHUNK).zip(r.chunks_mut(CHUNK)).collect();
    map_each(chunks, &|ci, (ys, rs)| {
        let first = ci * CHUNK;
        let (ps, qs) = (&p[first..first + ys.len()], &q[first..first + ys.len()]);
        for (((yv, rv), pv), qv) in ys.iter_mut().zip(rs.iter_mut()).zip(ps).zip(qs) {
            for k in 0..K {
                yv[k] += alpha[k] * pv[k].get();
                rv[k] = Mg::of(rv[k].get() - alpha[k] * qv[k].get());
            }
        }
    });
}

/// v² / d: one entry's term of a squared norm scaled by the diagonal, ‖D^-½ v‖², given
/// `inv_d` = 1/d ([`inverse`]).
#[inline(always)]
pub(super) fn scaled_square(v: f64, inv_d: f64) -> f64 {
    v * v * inv_d
}

/// 1/d for a diagonal d > 0, 0 for a pad's (d = 0: its values are 0 and count nothing).
#[inline(always)]
pub(super) fn inverse(d: f64) -> f64 {
    if d > 0.0 {
        1.0 / d
    } else {
        0.0
    }
}

impl Hierarchy {
    /// q = A p per system (computed in f64, stored in the multigrid's precision). Returns, in
    /// f64 and summed as [`dot`] does, pᵀA p and, for the scaled norm ‖D^-½ (r − α q)‖ of the
    /// step's residual (made before α is known), rᵀD⁻¹r, rᵀD⁻¹q and qᵀD⁻¹q (q as stored): D is
    /// not stored, so the norm is taken where the rows are read.
    pub(super) fn apply<const K: usize>(&self, p: &[[Mg; K]], q: &mut [[Mg; K]], r: &[[Mg; K]]) -> [[f64; K]; 4] {
        let parts: Vec<[[f64; K]; 4]> = with_rows!(&self.levels[0], |fine| map_chunks(q, CHUNK, &|ci, qs| {
                let first = ci * CHUNK;
                let mut sums = [[0.0; K]; 4];
                fine.each_row_into(first, qs, |e, row, qv| {
                    let (ap, d) = fine.apply_row(e, &row, p);
                    let w = inverse(d);
                    for k in 0..K {
                        qv[k] = Mg::of(ap[k]);
                        let (rk, qk) = (r[e][k].get(), qv[k].get());
                        sums[0][k] += p[e][k].get() * ap[k];
                        sums[1][k] += scaled_square(rk, w);
                        sums[2][k] += rk * qk * w;
                        sums[3][k] += scaled_square(qk, w);
                    }
                });
                sums
            }));
        std::array::from_fn(|i| sum_parts(&parts.iter().map(|s| s[i]).collect::<Vec<_>>()))
    }

    /// The true residual b − A x in f64 (`be(u)` the right-hand sides of the unknown u at an
    /// entry, 0 for [`PAD`]), stored into r for the systems in `which`; returns its scaled
    /// ‖D^-½ r‖² per system (summed as [`dot`] does; 0 for the others).
    pub(super) fn true_residual<const K: usize>(
        &self,
        be: &(impl Fn(u32) -> [f64; K] + Sync),
        x: &[[f64; K]],
        r: &mut [[Mg; K]],
        which: [bool; K],
    ) -> [f64; K] {
        let parts: Vec<[f64; K]> = with_rows!(&self.levels[0], |fine| map_chunks(r, CHUNK, &|ci, rs| {
                let first = ci * CHUNK;
                let mut rr = [0.0; K];
                fine.each_row_into(first, rs, |e, row, rv| {
                    let (b, (ax, d)) = (be(fine.unknown_of(e, &row)), fine.apply_row(e, &row, x));
                    let w = inverse(d);
                    for k in 0..K {
                        if which[k] {
                            let v = b[k] - ax[k];
                            rv[k] = Mg::of(v);
                            rr[k] += scaled_square(v, w);
                        }
                    }
                });
                rr
            }));
        sum_parts(&parts)
    }

    /// Solve A x = b (A as assembled; `b`, `x0` and the result per unknown) by MGPCG from `x0`
    /// (or zero) to relative residual `tol` of the diagonally scaled system,
    /// ‖D^-½ (b − A x)‖ / ‖D^-½ b‖ (thin voxels, large D, then do not drown out thick ones), at
    /// most `max_iter` iterations.
    pub fn solve<B: Copy + Into<f64> + Sync>(&self, b: &[B], x0: Option<&[B]>, tol: f64, max_iter: usize) -> (Vec<f64>, SolveStats) {
        let [out] = self.solve_many([b], x0.map(|x| [x]), tol, max_iter);
        out
    }

    /// [`Hierarchy::solve`] for K right-hand sides at once (the bands that share the operator):
    /// each system's iterates are exactly those of its own solve, and the rows are read once per
    /// pass for all of them. `b` and `x0` in f64 or f32 (f32 halves the caller's copies).
    pub fn solve_many<B: Copy + Into<f64> + Sync, const K: usize>(
        &self,
        b: [&[B]; K],
        x0: Option<[&[B]; K]>,
        tol: f64,
        max_iter: usize,
    ) -> [(Vec<f64>, SolveStats); K] {
        let a = &self.levels[0];
        assert!(b.iter().all(|v| v.len() == a.unknowns()), "one value per unknown");
        let mut x: Vec<[f64; K]> = match x0 {
            Some(x) => {
                assert!(x.iter().all(|v| v.len() == a.unknowns()), "one value per unknown");
                let unk = a.unknowns_in_order();
                let mut start = vec![[0.0; K]; unk.len()];
                for_chunks(&mut start, CHUNK, &|ci, xs| {
                    for (xv, u) in xs.iter_mut().zip(&unk[ci * CHUNK..]) {
                        if *u != PAD {
                            *xv = x.map(|v| v[*u as usize].into());
                        }
                    }
                });
                start
            }
            None => vec![[0.0; K]; a.len()],
        };
        // The right-hand sides per entry, made where they are read (not held), divided by the
        // power of two that the operator is (exactly: the solution is the caller's).
        let to_unit = pow2(-a.unit);
        let be = |u: u32| match u {
            PAD => [0.0; K],
            u => b.map(|v| v[u as usize].into() * to_unit),
        };
        let stats = self.solve_entries(&be, &mut x, x0.is_none(), tol, max_iter);
        let unk = a.unknowns_in_order();
        let mut lane = 0;
        stats.map(|st| {
            let mut out = vec![0.0; a.unknowns()];
            for (u, v) in unk.iter().zip(&x) {
                if *u != PAD {
                    out[*u as usize] = v[lane];
                }
            }
            lane += 1;
            (out, st)
        })
    }

    /// MGPCG on A x = b (vectors on the finest level's entries, `be(u)` the right-hand sides of
    /// the unknown u at an entry, 0 for [`PAD`]), each system stopping on its own when ‖D^-½ r‖ ≤ `tol` ‖D^-½ b‖. Mixed
    /// precision: the iterate x is f64, the residual, A p and the search direction are in the
    /// multigrid's precision (their dots summed in f64). When a system's recursive residual
    /// meets `tol`, its true residual is computed in f64; if that does not meet `tol` (the
    /// rounding of the recursion), CG restarts from it.
    pub(super) fn solve_entries<const K: usize>(
        &self,
        be: &(impl Fn(u32) -> [f64; K] + Sync),
        x: &mut [[f64; K]],
        cold: bool,
        tol: f64,
        max_iter: usize,
    ) -> [SolveStats; K] {
        let a = &self.levels[0];
        let n = a.len();
        let parts: Vec<[f64; K]> = with_rows!(a, |fine| map_range(n.div_ceil(CHUNK), &|ci| {
                let mut s = [0.0; K];
                fine.each_row(ci * CHUNK..n.min((ci + 1) * CHUNK), |e, row| {
                    let (v, w) = (be(fine.unknown_of(e, &row)), inverse(fine.finest_row(e, &row).2));
                    for k in 0..K {
                        s[k] += scaled_square(v[k], w);
                    }
                });
                s
            }));
        let bb = sum_parts(&parts);
        let bnorm = bb.map(f64::sqrt);
        let mut stats: [SolveStats; K] = std::array::from_fn(|_| SolveStats {
            iterations: 0,
            relative_residual: 0.0,
            history: Vec::new(),
            unknowns: a.unknowns(),
            levels: self.levels.len(),
            bytes_per_unknown: 0.0,
        });
        // The hierarchy; x in f64; r, p and q (A p, then z) in the multigrid's precision, and
        // per level in `work` the next level's b and x (the caller's b and x, per unknown, not
        // counted).
        let lanes = |v: usize, bytes: usize| v * bytes * K;
        let held = self.bytes()
            + lanes(n, 8)
            + lanes(3 * n, std::mem::size_of::<Mg>())
            + self.levels[1..]
                .iter()
                .map(|l| lanes(2 * l.len(), std::mem::size_of::<Mg>()))
                .sum::<usize>();
        for st in &mut stats {
            st.bytes_per_unknown = held as f64 / (K * a.unknowns().max(1)) as f64;
        }
        // From x = 0 (`cold`) the true residual is b, and its scaled r·r the b·b above (bit for
        // bit: A 0 = 0 exactly, and the same chunks add in the same order).
        let mut r = vec![[0.0; K]; n];
        let rr = if cold {
            with_rows!(a, |fine| for_chunks(&mut r, CHUNK, &|ci, rs| {
                let first = ci * CHUNK;
                fine.each_row_into(first, rs, |e, row, rv| *rv = be(fine.unknown_of(e, &row)).map(Mg::of));
            }));
            bb
        } else {
            let rr = self.true_residual(be, x, &mut r, [true; K]);
            // A start no nearer the solution than zero is (its scaled residual at least b's: a
            // warm start across an abrupt change of the light, a sun that has set) is dropped:
            // that system goes on from zero, as its cold solve does, bit for bit.
            let no_start: [bool; K] = std::array::from_fn(|k| rr[k] >= bb[k]);
            if no_start.contains(&true) {
                for v in x.iter_mut() {
                    (0..K).filter(|&k| no_start[k]).for_each(|k| v[k] = 0.0);
                }
                let from_zero = self.true_residual(be, x, &mut r, no_start);
                std::array::from_fn(|k| if no_start[k] { from_zero[k] } else { rr[k] })
            } else {
                rr
            }
        };
        // Each system's final true r·r, kept from the check that stopped it.
        let mut last: [Option<f64>; K] = [None; K];
        // `q` holds A p from the product to the step, then the preconditioned residual z = M r
        // (each is dead when the other is written: one vector for both).
        let (mut p, mut q) = (vec![[0.0; K]; n], vec![[0.0; K]; n]);
        let mut work: Vec<Work<K>> = Work::all(self);
        let mut active = [false; K];
        for k in 0..K {
            if bnorm[k] == 0.0 {
                x.iter_mut().for_each(|v| v[k] = 0.0);
                stats[k].history.push(0.0);
            } else {
                let rel = rr[k].sqrt() / bnorm[k];
                stats[k].history.push(rel);
                active[k] = rel > tol;
                if !active[k] {
                    last[k] = Some(rr[k]);
                }
            }
        }
        if active.iter().any(|a| *a) {
            self.w_cycle(0, &r, &mut q, &mut work);
            p.copy_from_slice(&q);
            let mut rz = dot(&r, &q);
            let mut iterations = 0;
            while iterations < max_iter {
                let [pap, rdr, rdq, qdq] = self.apply(&p, &mut q, &r);
                let mut alpha = [0.0; K];
                for k in 0..K {
                    if pap[k].is_nan() || pap[k] <= 0.0 {
                        active[k] = false;
                    }
                    if active[k] {
                        alpha[k] = rz[k] / pap[k];
                    }
                }
                if !active.iter().any(|a| *a) {
                    break;
                }
                cg_step(x, &mut r, &p, &q, alpha);
                iterations += 1;
                let mut check = [false; K];
                for k in 0..K {
                    if !active[k] {
                        continue;
                    }
                    stats[k].iterations += 1;
                    // ‖D^-½ (r − α q)‖², expanded (clamped at 0: it cancels to rounding when
                    // the step leaves almost nothing).
                    let rr = (rdr[k] - 2.0 * alpha[k] * rdq[k] + alpha[k] * alpha[k] * qdq[k]).max(0.0);
                    let rel = rr.sqrt() / bnorm[k];
                    stats[k].history.push(rel);
                    check[k] = rel <= tol;
                }
                // Systems whose recursive residual meets the tolerance: stop on the true one,
                // or restart CG from it (its direction dropped: β = 0).
                let mut restart = [false; K];
                if check.iter().any(|c| *c) {
                    let rt = self.true_residual(be, x, &mut r, check);
                    for k in 0..K {
                        if check[k] {
                            restart[k] = rt[k].sqrt() / bnorm[k] > tol;
                            active[k] = restart[k];
                            if !restart[k] {
                                last[k] = Some(rt[k]);
                            }
                        }
                    }
                }
                if !active.iter().any(|a| *a) {
                    break;
                }
                self.w_cycle(0, &r, &mut q, &mut work);
                let rz_new = dot(&r, &q);
                let beta: [f64; K] = std::array::from_fn(|k| if active[k] && !restart[k] { rz_new[k] / rz[k] } else { 0.0 });
                rz = rz_new;
                for_chunks(&mut p, CHUNK, &|ci, ps| {
                    for (pv, zz) in ps.iter_mut().zip(&q[ci * CHUNK..]) {
                        *pv = std::array::from_fn(|k| Mg::of(zz[k].get() + beta[k] * pv[k].get()));
                    }
                });
            }
        }
        // Report the true residuals (those not known from the stop: a breakdown or the
        // iteration cap).
        drop((p, q, work));
        let need: [bool; K] = std::array::from_fn(|k| bnorm[k] > 0.0 && last[k].is_none());
        let rr = if need.iter().any(|v| *v) {
            self.true_residual(be, x, &mut r, need)
        } else {
            [0.0; K]
        };
        for k in 0..K {
            if bnorm[k] > 0.0 {
                stats[k].relative_residual = last[k].unwrap_or(rr[k]).sqrt() / bnorm[k];
            }
        }
        stats
    }
}
