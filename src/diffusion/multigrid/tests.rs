//! The assembled operator (eq. 4 with eq. 7) and the solver, against dense linear algebra
//! (inside the crate, so the solver's internals need not be public).

use super::coarse::{cholesky_in_place, envelope};
use super::codec::{pow2, Mg, Rows};
use super::cycle::Work;
use super::level::{less_couplings, with_rows, Coded, Level};
use super::operator::{coarsen, Node, Operator, Stencils};
use super::{Hierarchy, CHUNK, NONE, PAD};
use crate::diffusion::{assemble, BoundaryLight, Domain};
use crate::incident::{compute, IncidentLight, IncidentSettings, IncidentSources};
use crate::lighting::DirectionBins;
use crate::math::{Rgb, Rng, Vec3};
use crate::medium::{Grid3, Medium};
use std::collections::HashMap;

/// A random cloud: each voxel of the inner region full with probability 0.8, with optical depth
/// per voxel log-uniform in [1e-3, 10] (σt = 1 m⁻¹, 1 m voxels).
fn random_cloud(d: [usize; 3], seed: u64, albedo: f32, g: f32) -> Medium {
    let mut grid = Grid3::filled(d, 0.0);
    let mut rng = Rng::new(seed, 7);
    for k in 1..d[2] - 1 {
        for j in 1..d[1] - 1 {
            for i in 1..d[0] - 1 {
                if rng.uniform() < 0.8 {
                    grid.set(i, j, k, 10f32.powf(rng.uniform() * 4.0 - 3.0));
                }
            }
        }
    }
    Medium::new(grid, Vec3::ZERO, Vec3::ONE, 1.0, Rgb::splat(albedo), g)
}

fn sky_and_sun(l: f32, sun: Option<(Vec3, f32)>) -> IncidentSources {
    IncidentSources {
        bin_radiance: vec![Rgb::splat(l); 96],
        sun: sun.map(|(d, e)| (d.normalize(), Rgb::splat(e))),
    }
}

/// Stage 1 on `m` under a uniform sky of radiance `l` and an optional sun (direction, irradiance).
fn lit(m: &Medium, l: f32, sun: Option<(Vec3, f32)>) -> IncidentLight {
    compute(m, &DirectionBins::new(), &sky_and_sun(l, sun), &IncidentSettings::default(), None)
}

/// Band `band`'s operator and right-hand side on a random cloud under a unit sky and a sun
/// of irradiance 2 from `sun`.
fn sun_lit_system(d: [usize; 3], seed: u64, albedo: f32, g: f32, sun: Vec3, band: usize) -> (Operator, Vec<f64>) {
    let m = random_cloud(d, seed, albedo, g);
    let inc = lit(&m, 1.0, Some((sun, 2.0)));
    let dom = Domain::of(&m).unwrap();
    assemble(&m, &inc, &BoundaryLight::none(), band, 1e-3, &dom)
}

/// The operator as a dense matrix (row-major, one row per unknown).
fn dense(s: &Operator) -> Vec<f64> {
    let n = s.nodes.len();
    let mut a = vec![0.0; n * n];
    for (q, nd) in s.nodes.iter().enumerate() {
        a[q * n + q] = nd.diag;
        for ax in 0..3 {
            if nd.up_nbr[ax] != NONE {
                let r = nd.up_nbr[ax] as usize;
                let [c, d] = [nd.cell, s.nodes[r].cell].map(|c| c as usize);
                assert_eq!(d - c, [1, s.dims[0], s.dims[0] * s.dims[1]][ax], "+a neighbour's cell");
                a[q * n + r] = nd.up[ax];
                a[r * n + q] = nd.up[ax];
            }
        }
    }
    a
}

/// The operator CG solves with `h`, densely (row-major, in the order of the `n` unknowns):
/// the finest level's coded couplings, each diagonal the row's coded sum less them
/// (`Coded::apply_row`), times the power of two the levels are divided by.
fn as_solved(h: &Hierarchy, n: usize) -> Vec<f64> {
    let fine = &h.levels[0];
    let unit = pow2(fine.unit);
    let mut a = vec![0.0; n * n];
    for e in (0..fine.len()).filter(|e| fine.unknown(*e) != PAD) {
        let u = fine.unknown(e) as usize;
        let (nbr, c, d) = with_rows!(fine, |rows| rows.finest_row(e, &rows.row(e)));
        a[u * n + u] = d * unit;
        for q in (0..6).filter(|q| c[*q] != 0.0) {
            a[u * n + fine.unknown(nbr[q] as usize) as usize] = c[q] * unit;
        }
    }
    a
}

/// Gaussian elimination with partial pivoting.
fn dense_solve(mut a: Vec<f64>, mut b: Vec<f64>) -> Vec<f64> {
    let n = b.len();
    for c in 0..n {
        let p = (c..n).max_by(|x, y| a[x * n + c].abs().total_cmp(&a[y * n + c].abs())).unwrap();
        for k in 0..n {
            a.swap(c * n + k, p * n + k);
        }
        b.swap(c, p);
        for r in c + 1..n {
            let f = a[r * n + c] / a[c * n + c];
            for k in c..n {
                a[r * n + k] -= f * a[c * n + k];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = vec![0.0; n];
    for r in (0..n).rev() {
        let s: f64 = (r + 1..n).map(|k| a[r * n + k] * x[k]).sum();
        x[r] = (b[r] - s) / a[r * n + r];
    }
    x
}

#[test]
fn operator_is_symmetric_positive_definite() {
    let m = random_cloud([9, 8, 7], 3, 0.95, 0.8);
    let inc = lit(&m, 0.5, Some((Vec3::new(0.3, 1.0, 0.2), 3.0)));
    let dom = Domain::of(&m).unwrap();
    for tau_min in [0.0, 1e-3] {
        let (s, _) = assemble(&m, &inc, &BoundaryLight::none(), 0, tau_min, &dom);
        let a = dense(&s);
        let n = s.nodes.len();
        assert!(n > 100);
        for q in 0..n {
            for r in 0..n {
                assert_eq!(a[q * n + r], a[r * n + q]);
            }
        }
        // Cholesky must succeed with positive pivots.
        let mut l = a.clone();
        let first = envelope(&a, n);
        let smallest = cholesky_in_place(&mut l, n, &first);
        assert!(smallest > 0.0, "smallest pivot {smallest}: not positive definite");
        // Within the envelope: the same factor as the dense form, which reads every column; on
        // this small cloud the envelope is under half the triangle.
        let mut dense_l = a.clone();
        assert_eq!(cholesky_in_place(&mut dense_l, n, &vec![0; n]), smallest);
        for i in 0..n {
            for k in 0..=i {
                assert_eq!(l[i * n + k], dense_l[i * n + k], "L[{i}][{k}]");
            }
        }
        let profile: usize = (0..n).map(|i| i - first[i]).sum();
        assert!(2 * profile < n * (n - 1) / 2, "envelope {profile} of {} entries", n * (n - 1) / 2);
    }
}

#[test]
fn multigrid_matches_dense_solve() {
    // Coarsened down to 16 unknowns, so several multigrid levels sit above the direct one.
    for (d, seed) in [([14, 12, 10], 1u64), ([18, 14, 12], 2)] {
        let m = random_cloud(d, seed, 0.99, 0.85);
        let inc = lit(&m, 1.0, Some((Vec3::new(-0.2, 1.0, 0.4), 2.0)));
        let dom = Domain::of(&m).unwrap();
        let (s, b) = assemble(&m, &inc, &BoundaryLight::none(), 1, 0.0, &dom);
        let h = Hierarchy::build_with(&s.rows(), 16);
        assert!(h.levels() >= 4, "levels {}", h.levels());
        let (x, st) = h.solve(&b, None, 1e-12, 500);
        assert!(st.relative_residual <= 1e-12, "{st:?}");
        let xd = dense_solve(as_solved(&h, b.len()), b.clone());
        let num: f64 = x.iter().zip(&xd).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt();
        let den: f64 = xd.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!(num / den < 1e-8, "relative difference {}", num / den);
    }
}

#[test]
fn a_start_no_nearer_than_zero_is_dropped_and_a_near_one_kept() {
    let (s, b) = sun_lit_system([12, 10, 9], 5, 0.97, 0.8, Vec3::new(0.3, 1.0, -0.2), 0);
    let h = Hierarchy::build_with(&s.rows(), 16);
    let (cold, cold_stats) = h.solve(&b, None, 1e-9, 200);
    // Ten times the solution: its residual is nine times b's. The solve is the cold one.
    let far: Vec<f64> = cold.iter().map(|v| 10.0 * v).collect();
    let (x, st) = h.solve(&b, Some(&far), 1e-9, 200);
    assert_eq!(x, cold);
    assert_eq!(st.history, cold_stats.history);
    // The solution itself, slightly off: kept, and fewer iterations than from zero.
    let near: Vec<f64> = cold.iter().map(|v| 1.01 * v).collect();
    let (_, st) = h.solve(&b, Some(&near), 1e-9, 200);
    assert!(st.history[0] < 0.1 && st.iterations < cold_stats.iterations, "{:?}", st.history);
}

#[test]
fn systems_solved_together_match_their_own_solves_exactly() {
    let (s, b) = sun_lit_system([12, 10, 9], 5, 0.97, 0.8, Vec3::new(0.3, 1.0, -0.2), 0);
    let h = Hierarchy::build_with(&s.rows(), 16);
    // A second right-hand side that converges at another iteration, and a zero one.
    let b2: Vec<f64> = b.iter().enumerate().map(|(c, v)| if c % 3 == 0 { -2.0 * v } else { *v }).collect();
    let zero = vec![0.0; b.len()];
    let together = h.solve_many([&b, &b2, &zero], None, 1e-9, 200);
    for (one, rhs) in together.iter().zip([&b, &b2, &zero]) {
        let alone = h.solve(rhs, None, 1e-9, 200);
        assert_eq!(one.0, alone.0);
        assert_eq!(one.1.history, alone.1.history);
        assert_eq!(one.1.relative_residual, alone.1.relative_residual);
    }
    assert!(together[0].1.iterations > 5 && together[0].1.relative_residual <= 1e-9);
    assert_eq!(together[2].0, zero);
}

#[test]
fn cg_operator_keeps_every_row_sum() {
    // Couplings coded to 16 bits, each diagonal the row's coded sum less them: each coupling
    // and A·1 are the assembled operator's to ≤ 2⁻¹² of themselves (rounding the diagonal on
    // its own would move A·1 by 2⁻¹² of the diagonal, up to ~4 times the sum here), no row
    // sum lost below the code's range.
    let (s, _) = sun_lit_system([12, 10, 9], 4, 0.999, 0.85, Vec3::new(0.3, 1.0, 0.1), 0);
    let h = Hierarchy::build_with(&s.rows(), 16);
    let (a, n) = (dense(&s), s.nodes.len());
    let solved = as_solved(&h, n);
    for (x, y) in a.iter().zip(&solved) {
        assert!((x - y).abs() <= x.abs() / 4096.0 + 1e-12 * a[0], "coupling {x} coded {y}");
    }
    let fine = &h.levels[0];
    let unit = pow2(fine.unit);
    let ones: Vec<[f64; 1]> = (0..fine.len()).map(|e| [if fine.unknown(e) == PAD { 0.0 } else { 1.0 }]).collect();
    let mut smallest = f64::INFINITY;
    for e in (0..fine.len()).filter(|e| fine.unknown(*e) != PAD) {
        let u = fine.unknown(e) as usize;
        let want: f64 = a[u * n..(u + 1) * n].iter().sum();
        let got = with_rows!(fine, |c| c.apply_row(e, &c.row(e), &ones).0[0]) * unit;
        assert!(
            (got - want).abs() <= 1e-12 * a[u * n + u] + want.abs() / 4096.0,
            "row {u}: {got} vs {want}"
        );
        smallest = smallest.min(want / a[u * n + u]);
    }
    // Rows whose sum is far below their diagonal, where the difference shows.
    assert!(smallest < 1e-2, "{smallest}");
    // The pads' products are 0.
    assert_eq!(with_rows!(fine, |c| c.apply_row(fine.red, &c.row(fine.red), &ones)), ([0.0], 0.0));
}

#[test]
fn stops_on_the_true_residual_in_f64() {
    // Far below what the f32 recursion can follow: the stop must come from the true residual
    // (CG restarted from it), checked here densely on the scaled system D^-1/2 (b − A x), A
    // the operator CG solves (couplings and row sums rounded to f32) and D its diagonal.
    let (s, b) = sun_lit_system([12, 10, 9], 6, 0.98, 0.8, Vec3::new(0.2, 1.0, -0.3), 2);
    let h = Hierarchy::build_with(&s.rows(), 16);
    let tol = 1e-10;
    let (x, st) = h.solve(&b, None, tol, 500);
    let (a, n) = (as_solved(&h, b.len()), b.len());
    let d: Vec<f64> = (0..n).map(|q| a[q * n + q].sqrt()).collect();
    let res: f64 = (0..n)
        .map(|q| {
            let ax: f64 = (0..n).map(|r| a[q * n + r] * x[r]).sum();
            ((b[q] - ax) / d[q]).powi(2)
        })
        .sum::<f64>()
        .sqrt();
    let bn: f64 = (0..n).map(|q| (b[q] / d[q]).powi(2)).sum::<f64>().sqrt();
    assert!(res / bn <= tol, "true residual {} ({st:?})", res / bn);
    assert!(
        (st.relative_residual - res / bn).abs() <= 1e-3 * res / bn,
        "reported {} vs {}",
        st.relative_residual,
        res / bn
    );
    // f32 right-hand sides are accepted too (the callers' copies): the same solve to rounding.
    let b32: Vec<f32> = b.iter().map(|v| *v as f32).collect();
    let (x32, _) = h.solve(&b32, None, 1e-6, 500);
    let diff = x.iter().zip(&x32).map(|(p, q)| (p - q).powi(2)).sum::<f64>().sqrt();
    let norm = x.iter().map(|p| p * p).sum::<f64>().sqrt();
    assert!(diff / norm < 1e-4, "{}", diff / norm);
}

#[test]
fn coarse_operator_is_the_galerkin_product() {
    // Odd box sides: the last aggregates of each axis are one cell thick.
    let (s, _) = sun_lit_system([11, 9, 8], 4, 0.9, 0.8, Vec3::new(0.2, 1.0, 0.3), 0);
    let (c, parent, maxima) = coarsen(&s.rows());
    // The fine rows' largest values, found on the way.
    assert_eq!(maxima, super::Maxima::all(&s.rows()));
    assert!(maxima.cpl > 0.0 && maxima.sum > 0.0 && maxima.diag > maxima.sum);
    let (n, nc) = (s.nodes.len(), c.nodes.len());
    assert!(nc > 10 && nc < n, "{nc} of {n}");
    assert_eq!(c.dims, [s.dims[0].div_ceil(2), s.dims[1].div_ceil(2), s.dims[2].div_ceil(2)]);
    // PᵀAP with P[u][parent u] = 1, densely.
    let a = dense(&s);
    let mut g = vec![0.0; nc * nc];
    for u in 0..n {
        for v in 0..n {
            g[parent[u] as usize * nc + parent[v] as usize] += a[u * n + v];
        }
    }
    for (x, y) in g.iter().zip(&dense(&c)) {
        assert!((x - y).abs() <= 1e-12 * x.abs().max(1.0), "{x} vs {y}");
    }
    for (u, p) in parent.iter().enumerate() {
        let [i, j, k] = s.rows().ijk(u);
        let cell = i / 2 + c.dims[0] * (j / 2 + c.dims[1] * (k / 2));
        assert_eq!(c.nodes[*p as usize].cell as usize, cell);
    }
    assert!(c.nodes.windows(2).all(|w| w[0].cell < w[1].cell), "coarse unknowns in box order");
}

/// The preconditioner (one cycle from zero) of `h` applied to `b` (one value per entry of the
/// finest level, 0 on the pads).
fn precondition(h: &Hierarchy, b: &[f64]) -> Vec<f64> {
    let b: Vec<[Mg; 1]> = b.iter().map(|v| [*v as Mg]).collect();
    let mut x = vec![[0.0; 1]; b.len()];
    let mut work: Vec<Work<1>> = Work::all(h);
    h.w_cycle(0, &b, &mut x, &mut work);
    x.iter().map(|v| v[0] as f64).collect()
}

#[test]
fn restriction_sums_each_coarse_entrys_red_children() {
    // Each coarse entry gets the sum of its red children's residuals (whatever it held), the
    // pads 0: checked on every level against residuals made densely from the decoded rows.
    let (s, _) = sun_lit_system([14, 12, 10], 8, 0.99, 0.85, Vec3::new(0.1, 1.0, 0.3), 0);
    let h = Hierarchy::build_with(&s.rows(), 16);
    assert!(h.levels() >= 4);
    let mut rng = Rng::new(3, 2);
    for l in 0..h.levels() - 1 {
        let (fine, coarse) = (&h.levels[l], &h.levels[l + 1]);
        let mut random = || -> Vec<[Mg; 1]> {
            (0..fine.len())
                .map(|e| [if fine.unknown(e) == PAD { 0.0 } else { rng.uniform() - 0.5 }])
                .collect()
        };
        let (x, b) = (random(), random());
        let mut got = vec![[7.0; 1]; coarse.len()];
        coarse.restrict_residual(fine, &x, &b, &mut got);
        let (mut want, mut size) = (vec![0.0; coarse.len()], vec![0.0; coarse.len()]);
        for f in 0..fine.red {
            let nbr = fine.neighbours(f);
            let c = fine.couplings(f, &nbr).0.map(f64::from);
            let own = f64::from(with_rows!(fine, |rows| rows.row(f).codes.own.decode(rows.mine[3])));
            let d = match fine.row_sums {
                true => less_couplings(own, c),
                false => own,
            };
            let terms = (0..6)
                .map(|q| c[q] * f64::from(x[nbr[q] as usize][0]))
                .chain([d * f64::from(x[f][0])]);
            let p = fine.parent[f] as usize;
            want[p] += f64::from(b[f][0]) - terms.clone().sum::<f64>();
            size[p] += f64::from(b[f][0]).abs() + terms.map(f64::abs).sum::<f64>();
        }
        for e in 0..coarse.len() {
            if coarse.unknown(e) == PAD {
                assert_eq!(got[e], [0.0], "level {l} pad {e}");
            }
            let g = f64::from(got[e][0]);
            assert!((g - want[e]).abs() <= 1e-5 * size[e], "level {l} entry {e}: {g} vs {}", want[e]);
        }
        assert!(size.iter().filter(|v| **v > 0.0).count() > coarse.unknowns() / 2);
    }
}

#[test]
fn preconditioner_is_symmetric() {
    // zᵀ M⁻¹ y = yᵀ M⁻¹ z (to the cycle's f32 rounding), so CG's theory holds.
    let (s, _) = sun_lit_system([14, 12, 10], 8, 0.99, 0.85, Vec3::new(0.1, 1.0, 0.3), 0);
    let h = Hierarchy::build_with(&s.rows(), 16);
    assert!(h.levels() >= 4);
    let fine = &h.levels[0];
    let mut rng = Rng::new(9, 1);
    let mut random = || -> Vec<f64> {
        (0..fine.len())
            .map(|e| if fine.unknown(e) == PAD { 0.0 } else { rng.uniform() as f64 - 0.5 })
            .collect()
    };
    let (y, z) = (random(), random());
    let (my, mz) = (precondition(&h, &y), precondition(&h, &z));
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(p, q)| p * q).sum::<f64>();
    let (zmy, ymz) = (dot(&z, &my), dot(&y, &mz));
    assert!((zmy - ymz).abs() <= 1e-5 * (dot(&y, &my) * dot(&z, &mz)).sqrt(), "{zmy} vs {ymz}");
    assert!(dot(&y, &my) > 0.0 && dot(&z, &mz) > 0.0);
}

#[test]
fn first_coarse_operator_aggregates_the_unscaled_operator() {
    // Two levels: the finest one and the direct one, whose matrix (L Lᵀ) must be P₀ᵀ A P₀ for
    // the piecewise-constant prolongation P₀ of the operator as assembled (not scaled).
    let (s, _) = sun_lit_system([11, 9, 8], 4, 0.9, 0.8, Vec3::new(0.2, 1.0, 0.3), 0);
    let n = s.nodes.len();
    let h = Hierarchy::build_with(&s.rows(), n - 1);
    assert_eq!(h.levels(), 2);
    let (_, parent, _) = coarsen(&s.rows());
    let nc = parent.iter().max().unwrap() + 1;
    let nc = nc as usize;
    let a = dense(&s);
    let mut g = vec![0.0; nc * nc];
    for u in 0..n {
        for v in 0..n {
            g[parent[u] as usize * nc + parent[v] as usize] += a[u * n + v];
        }
    }
    let c = &h.coarse;
    assert_eq!(c.cells.len(), nc);
    // The coarse level's unknowns in its entries' order: map them to the aggregates (box order).
    let coarse_unk: Vec<usize> = c.cells.iter().map(|e| h.levels[1].unknown(*e) as usize).collect();
    for (q, cq) in coarse_unk.iter().enumerate() {
        for (r, cr) in coarse_unk.iter().enumerate() {
            let llt: f64 = (0..=q.min(r)).map(|k| c.l[q * nc + k] * c.l[r * nc + k]).sum();
            let want = g[cq * nc + cr] * pow2(-h.levels[0].unit);
            assert!((llt - want).abs() <= 1e-9 * want.abs().max(1e-3), "{llt} vs {want}");
        }
    }
    // The finest level holds its rows' sums; the coarse ones their diagonals.
    assert!(h.levels[0].row_sums && !h.levels[1].row_sums);
}

#[test]
fn coded_neighbours_and_couplings_are_the_plain_ones() {
    // A random sparse cloud, some couplings 0, and its coarse operator: each row's decoded
    // neighbours are those found from the cells, its couplings (the −a ones read from the −a
    // neighbours' rows) the operator's, and a missing neighbour (or one coupled by 0) has
    // coupling 0 and reads an entry of the other colour (its pad for a −a one).
    let (mut fine, _) = sun_lit_system([13, 11, 9], 3, 0.95, 0.8, Vec3::new(0.2, 1.0, 0.3), 0);
    for (u, nd) in fine.nodes.iter_mut().enumerate() {
        if u % 7 == 0 {
            nd.up[u % 3] = 0.0;
        }
    }
    let coarse = coarsen(&fine.rows()).0;
    for s in [fine, coarse] {
        for narrow in [true, false] {
            assert!(matches!(coded_rows_match(&s, narrow).rows, Rows::Narrow(_)) == narrow);
        }
    }
}

#[test]
fn planes_too_wide_for_u16_distances_keep_u32_ones() {
    // A full 370×370×2 box: a red cell's +z neighbour lies 68 450 black entries after its
    // `base` (2^16 = 65 536), so the level keeps u32 ±z distances, and they decode right.
    let dims = [370, 370, 2];
    let n = dims.iter().product::<usize>();
    let nodes = (0..n)
        .map(|c| {
            let (i, j, k) = (c % dims[0], (c / dims[0]) % dims[1], c / (dims[0] * dims[1]));
            let mut nd = Node::at(c as u32);
            nd.diag = 7.0;
            for (ax, (at, stride)) in [(i, 1), (j, dims[0]), (k, dims[0] * dims[1])].into_iter().enumerate() {
                if at + 1 < dims[ax] {
                    (nd.up_nbr[ax], nd.up[ax]) = ((c + stride) as u32, -1.0 - (c % 5) as f64 / 8.0);
                }
            }
            nd
        })
        .collect();
    let s = Operator { dims, nodes };
    assert!(matches!(coded_rows_match(&s, true).rows, Rows::Wide(_)));
}

#[test]
fn runs_rebuild_every_row() {
    // A box with a shaft through it and scattered holes, over three chunks of entries: each
    // entry's row rebuilt from its run decodes to the operator's neighbours and couplings
    // (u16 and u32 ±z distances); walking the runs from any entry (chunk boundaries
    // included) rebuilds the rows a lookup does; the runs are maximal, and few.
    let dims = [40, 30, 12];
    let mut rng = Rng::new(5, 3);
    let full: Vec<bool> = (0..dims.iter().product::<usize>())
        .map(|c| {
            let (i, j) = ((c % dims[0]) as i32, ((c / dims[0]) % dims[1]) as i32);
            let shaft = (i - 20).pow(2) + (j - 15).pow(2) < 16;
            !shaft && rng.uniform() > 0.01
        })
        .collect();
    let cells: Vec<usize> = (0..full.len()).filter(|c| full[*c]).collect();
    let mut unknown = vec![NONE; full.len()];
    for (u, c) in cells.iter().enumerate() {
        unknown[*c] = u as u32;
    }
    let nodes = cells
        .iter()
        .map(|&c| {
            let ijk = [c % dims[0], (c / dims[0]) % dims[1], c / (dims[0] * dims[1])];
            let mut nd = Node::at(c as u32);
            nd.diag = 7.0;
            for (ax, stride) in [1, dims[0], dims[0] * dims[1]].into_iter().enumerate() {
                if ijk[ax] + 1 < dims[ax] && full[c + stride] {
                    (nd.up_nbr[ax], nd.up[ax]) = (unknown[c + stride], -1.0 - (c % 5) as f64 / 8.0);
                }
            }
            nd
        })
        .collect();
    let s = Operator { dims, nodes };
    assert!(s.nodes.len() > 3 * CHUNK);
    for narrow in [true, false] {
        let level = coded_rows_match(&s, narrow);
        assert!(matches!(level.rows, Rows::Narrow(_)) == narrow);
        with_rows!(&level, |c| {
            assert_eq!(c.runs[0].start, 0);
            for w in c.runs.windows(2) {
                assert!(w[0].start < w[1].start && w[0].link_at(w[1].start as usize) != w[1].link);
            }
            let rows: Vec<_> = (0..c.len()).map(|e| c.row(e)).collect();
            let n = c.len();
            for start in [0, 1, CHUNK - 1, CHUNK, CHUNK + 1, 2 * CHUNK, c.red, c.red + 1, n - 1, n] {
                let end = n.min(start + CHUNK + 3);
                let mut walked = Vec::new();
                c.each_row(start..end, |e, row| walked.push((e, row)));
                let looked_up: Vec<_> = (start..end).zip(rows[start..end].iter().copied()).collect();
                assert_eq!(walked, looked_up, "from {start}");
            }
            // u32 rows with no −z neighbour end their runs (the bottom plane, the holes).
            let most = if narrow { n / 4 } else { n / 2 };
            assert!(c.runs.len() < most, "{} runs for {n} entries", c.runs.len());
        });
    }
}

#[test]
fn u16_and_u32_rows_solve_alike() {
    // The same hierarchy with every level's ±z distances in u32: the same iterates, bit for
    // bit.
    let (s, b) = sun_lit_system([15, 13, 11], 5, 0.99, 0.85, Vec3::new(0.3, 1.0, 0.2), 1);
    let [narrow, wide] = [true, false].map(|n| Hierarchy::build_coded(&s.rows(), 16, n));
    assert!(narrow.levels.iter().all(|l| matches!(l.rows, Rows::Narrow(_))));
    assert!(wide.levels.iter().all(|l| matches!(l.rows, Rows::Wide(_))));
    let [(xn, sn), (xw, sw)] = [narrow, wide].map(|h| h.solve(&b, None, 1e-10, 100));
    assert!(sn.iterations > 2 && sn.relative_residual <= 1e-10, "{sn:?}");
    assert_eq!((sn.iterations, sn.history), (sw.iterations, sw.history));
    assert!(xn.iter().zip(&xw).all(|(a, b)| a.to_bits() == b.to_bits()));
}

#[test]
fn operator_scale_does_not_change_the_solve() {
    // An operator and right-hand side times 2^±100 (couplings of µm or Gm voxels, far outside
    // the codes' scales' range, 2⁻²²³ … 2³¹, unless divided by the hierarchy's unit): the
    // same solution, bit for bit, and the same iterations.
    let (s, b) = sun_lit_system([13, 11, 9], 7, 0.99, 0.85, Vec3::new(0.3, 1.0, 0.2), 0);
    let base = Hierarchy::build_with(&s.rows(), 16).solve(&b, None, 1e-9, 100);
    assert!(base.1.iterations > 2 && base.1.relative_residual <= 1e-9, "{:?}", base.1);
    for k in [100, -100] {
        let f = pow2(k);
        let mut t = s.clone();
        for nd in &mut t.nodes {
            nd.diag *= f;
            nd.up = nd.up.map(|v| v * f);
        }
        let h = Hierarchy::build_with(&t.rows(), 16);
        assert_eq!(h.levels[0].unit, Hierarchy::build_with(&s.rows(), 16).levels[0].unit + k);
        let bt: Vec<f64> = b.iter().map(|v| v * f).collect();
        let (x, st) = h.solve(&bt, None, 1e-9, 100);
        assert_eq!(st.history, base.1.history, "2^{k}");
        assert!(x.iter().zip(&base.0).all(|(p, q)| p.to_bits() == q.to_bits()), "2^{k}");
    }
}

/// Checks the decoded rows of the level of `s` (u16 ±z distances allowed with `narrow`);
/// returns the level.
fn coded_rows_match(s: &Operator, narrow: bool) -> Level {
    let rows = s.rows();
    let (level, entry) = Level::from_stencils(&rows, false, narrow, Some(0), super::Maxima::all(&rows));
    let by_cell: HashMap<usize, usize> = s.nodes.iter().enumerate().map(|(u, n)| (n.cell as usize, u)).collect();
    let [nx, ny, _] = s.dims;
    let (mut seen, mut coupled) = (0, 0);
    for e in 0..level.len() {
        let u = level.unknown(e);
        // The other colour's entries, its pad last.
        let other = if e <= level.red {
            level.red + 1..level.len()
        } else {
            0..level.red + 1
        };
        let pad = other.end - 1;
        let got = level.neighbours(e);
        let cpl = level.couplings(e, &got).0;
        if u == PAD {
            assert!(e == level.red || e + 1 == level.len());
            assert_eq!((cpl, got), ([0.0; 6], [pad as u32; 6]));
            continue;
        }
        assert_eq!(entry[u as usize] as usize, e, "entry {e}'s unknown");
        seen += 1;
        let (nd, cell) = (&s.nodes[u as usize], s.nodes[u as usize].cell as usize);
        for (q, stride) in [1, 1, nx, nx, nx * ny, nx * ny].into_iter().enumerate() {
            let ax = q / 2;
            let at = if q % 2 == 0 {
                cell.checked_sub(stride)
            } else {
                Some(cell + stride)
            };
            let v = at
                .and_then(|c| by_cell.get(&c))
                .copied()
                .filter(|v| rows.ijk(*v)[(ax + 1) % 3] == rows.ijk(u as usize)[(ax + 1) % 3]);
            let coupling = v.map_or(0.0, |v| if q % 2 == 0 { s.nodes[v].up[ax] } else { nd.up[ax] });
            match v {
                Some(v) if coupling != 0.0 => {
                    assert_eq!(got[q], entry[v], "entry {e} neighbour {q}");
                    let coded = f64::from(cpl[q]);
                    assert!((coded - coupling).abs() <= coupling.abs() / 4096.0, "entry {e} coupling {q}");
                    coupled += 1;
                }
                _ if q % 2 == 0 => assert!(cpl[q] == 0.0 && got[q] as usize == pad, "entry {e} neighbour {q}"),
                _ => assert!(cpl[q] == 0.0 && other.contains(&(got[q] as usize)), "entry {e} neighbour {q}"),
            }
        }
    }
    assert_eq!(seen, s.nodes.len());
    assert!(coupled > 3 * seen, "{coupled} couplings for {seen} unknowns");
    level
}

#[test]
fn iterations_stay_few() {
    // The coarse space piecewise constant in the unscaled unknowns: a random cloud with optical
    // depths over four decades per voxel converges in 17 iterations to 1e-6 (piecewise constant
    // in the unknowns scaled to unit diagonal it needed 32 here).
    let m = random_cloud([26, 22, 18], 11, 0.999, 0.85);
    let inc = lit(&m, 1.0, Some((Vec3::new(0.3, 1.0, 0.2), 3.0)));
    let dom = Domain::of(&m).unwrap();
    let (s, b) = assemble(&m, &inc, &BoundaryLight::none(), 0, 1e-3, &dom);
    let h = Hierarchy::build_with(&s.rows(), 64);
    let (_, st) = h.solve(&b, None, 1e-6, 200);
    assert!(st.relative_residual <= 1e-6 && st.iterations <= 20, "{st:?}");
}
