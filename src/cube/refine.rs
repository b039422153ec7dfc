//! Adaptive sampling of a smooth field on an n×n grid: the ground's hemicube light.
//!
//! The grid is filled coarse to fine. The coarsest nodes (every `coarse`-th index per axis, and
//! the last) are evaluated; each finer pass halves the spacing, and a new node is interpolated
//! (bilinearly, from the nodes of the pass before that bracket it) when those nodes agree to a
//! relative tolerance in every channel, else evaluated. A field that is linear between the
//! coarse nodes costs only the coarse nodes; near an edge every node is evaluated.

use crate::math::Rgb;
use crate::par;

/// Is index `i` (of `n`) a node of the pass with spacing `s`?
#[inline]
fn on(i: usize, s: usize, n: usize) -> bool {
    i % s == 0 || i == n - 1
}

/// The nodes of the pass with spacing 2s that bracket index `i` (a node of spacing s), and
/// `i`'s fraction between them.
#[inline]
fn bracket(i: usize, s: usize, n: usize) -> (usize, usize, f32) {
    if on(i, 2 * s, n) {
        return (i, i, 0.0);
    }
    // i is an odd multiple of s and not the last index: i − s is a node, the next is i + s or n − 1.
    let (lo, hi) = (i - s, (i + s).min(n - 1));
    (lo, hi, (i - lo) as f32 / (hi - lo) as f32)
}

/// `f(a, b)` on every node (a, b) of an n×n grid (index a + n·b), evaluating it on the nodes
/// of spacing `coarse` (a power of two; 1: everywhere) and, pass by pass, on the finer nodes whose
/// bracketing nodes differ by more than `tol` × (their largest value + `base` at the node) in some
/// channel; the others are interpolated. `base` (≥ 0, per node): for a field that is added to
/// it, the tolerance is relative to the sum; zero: relative to the field. Returns the values and
/// how many nodes were evaluated. Each pass evaluates in parallel; the result does not depend on
/// the thread count. `f` is a trait object: each call traces a ray, and one copy of this
/// function (with its parallel loop) serves every caller.
pub fn refine(n: usize, coarse: usize, tol: f32, base: &[Rgb], f: &(dyn Fn(usize, usize) -> Rgb + Sync)) -> (Vec<Rgb>, usize) {
    assert_eq!(base.len(), n * n, "one base value per node");
    assert!(coarse.is_power_of_two(), "coarse spacing {coarse} is not a power of two");
    let mut out = vec![Rgb::ZERO; n * n];
    let mut evaluated = 0;
    let mut s = coarse;
    loop {
        // The new nodes of this pass: on the spacing-s grid, not on the previous pass's.
        let first = s == coarse;
        let new: Vec<(usize, usize)> = (0..n)
            .filter(|&b| on(b, s, n))
            .flat_map(|b| (0..n).filter(move |&a| on(a, s, n)).map(move |a| (a, b)))
            .filter(|&(a, b)| first || !(on(a, 2 * s, n) && on(b, 2 * s, n)))
            .collect();
        let values = par::map_range(new.len(), &|i| {
            let (a, b) = new[i];
            if !first {
                let ((a0, a1, u), (b0, b1, v)) = (bracket(a, s, n), bracket(b, s, n));
                let c = [out[a0 + n * b0], out[a1 + n * b0], out[a0 + n * b1], out[a1 + n * b1]];
                let (lo, hi) = c.iter().fold((c[0], c[0]), |(lo, hi), x| (lo.min(*x), hi.max(*x)));
                if (hi - lo).cmple((hi + base[a + n * b]) * tol).all() {
                    let l = (c[0] * (1.0 - u) + c[1] * u) * (1.0 - v) + (c[2] * (1.0 - u) + c[3] * u) * v;
                    return (l, false);
                }
            }
            (f(a, b), true)
        });
        for (&(a, b), (l, e)) in new.iter().zip(values) {
            out[a + n * b] = l;
            evaluated += e as usize;
        }
        if s == 1 {
            return (out, evaluated);
        }
        s /= 2;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A linear field whose brackets agree to the tolerance costs only the coarse nodes, and
    /// bilinear interpolation reproduces it exactly; with a tolerance below its spread, every
    /// node is evaluated.
    #[test]
    fn a_gently_linear_field_costs_only_the_coarse_nodes() {
        let f = |a: usize, b: usize| Rgb::new(10.0 + 0.01 * a as f32, 20.0 + 0.02 * b as f32, 30.0 + 0.01 * (a + b) as f32);
        for (n, coarse, nodes) in [(32, 2, 17), (32, 4, 9), (7, 4, 3), (2, 2, 2)] {
            assert_eq!(
                refine(n, coarse, 1e-6, &vec![Rgb::ZERO; n * n], &f).1,
                n * n,
                "n {n} coarse {coarse}"
            );
            let (got, evaluated) = refine(n, coarse, 0.01, &vec![Rgb::ZERO; n * n], &f);
            assert_eq!(evaluated, nodes * nodes, "n {n} coarse {coarse}");
            for b in 0..n {
                for a in 0..n {
                    let (x, y) = (got[a + n * b], f(a, b));
                    assert!((x - y).abs().max_element() <= 1e-5 * y.max_element(), "({a}, {b}): {x} vs {y}");
                }
            }
        }
    }

    /// With tolerance 0 every node whose brackets differ is evaluated; a step is reproduced
    /// exactly (on both sides of it the brackets agree), and a constant field at no extra cost.
    #[test]
    fn a_step_is_evaluated_where_it_is() {
        let n = 32;
        let f = |a: usize, b: usize| Rgb::splat(if a + b < 19 { 1.0 } else { 5.0 });
        let zero = vec![Rgb::ZERO; n * n];
        let (got, evaluated) = refine(n, 4, 0.0, &zero, &f);
        for b in 0..n {
            for a in 0..n {
                assert_eq!(got[a + n * b], f(a, b), "({a}, {b})");
            }
        }
        assert!(evaluated < n * n / 2, "{evaluated} evaluated");
        let (_, evaluated) = refine(n, 4, 0.0, &zero, &|_, _| Rgb::ONE);
        assert_eq!(evaluated, 9 * 9);
        let (all, evaluated) = refine(n, 1, 0.0, &zero, &f);
        assert_eq!(evaluated, n * n);
        assert_eq!(all, got);
    }

    /// Over a large base the same step is within the tolerance: only the coarse nodes are
    /// evaluated, and every node is within tol × (value + base) of the field.
    #[test]
    fn a_base_widens_the_tolerance() {
        let n = 32;
        let f = |a: usize, b: usize| Rgb::splat(if a + b < 19 { 1.0 } else { 2.0 });
        let base = vec![Rgb::splat(100.0); n * n];
        let (got, evaluated) = refine(n, 4, 0.02, &base, &f);
        assert_eq!(evaluated, 9 * 9);
        for b in 0..n {
            for a in 0..n {
                assert!((got[a + n * b] - f(a, b)).abs().max_element() <= 0.02 * 102.0, "({a}, {b})");
            }
        }
        assert!(refine(n, 4, 0.02, &vec![Rgb::ZERO; n * n], &f).1 > 9 * 9);
    }
}
