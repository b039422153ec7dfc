//! The diffusion's I0(τ) against the exact one in a slab lit by the sun at an angle (docs/accuracy.md,
//! "The diffusion's I0 where the sun enters: one dimension first"). In the medium `full` runs on
//! (the cumulus's g = 0.9 and albedo 0.999 after δ-M with f = g⁴), per depth bin along the normal
//! and per μ0: I0 of the diffusion's own rows ([`cloudgi::diffusion::slab::collimated_profile`],
//! cells as thick as one of the cumulus's 10-m voxels at density 1; and at cells ten times finer),
//! of P1 with the sun's l = 2 moment from its local balance, of P3, and of the first-collision
//! source (the once-scattered light exact, P1 or P3 for the orders ≥ 2; docs/accuracy.md, "The
//! first-collision source and the beam's first moment"), each over the exact mean diffuse
//! radiance by Monte Carlo (track-length estimator, the same δ-M medium, HG(g′)). Then the
//! 3-D solver (stage 1's sun and `solve_diffusion`) on a slab whose faces are axis-aligned and on
//! one tilted 45° to the grid (a staircase), against the same Monte Carlo.
//!
//! `cargo run --release --features internals --example slab_profile [PHOTONS]` (default 400,000)

use cloudgi::diffusion::slab::collimated_profile;
use cloudgi::diffusion::{solve_diffusion, BoundaryLight, DiffusionSettings};
use cloudgi::incident::{compute, IncidentSettings, IncidentSources};
use cloudgi::lighting::DirectionBins;
use cloudgi::math::{Rgb, Rng, Vec3};
use cloudgi::medium::{Grid3, Medium};
use cloudgi::optics::{delta_m, Hg};
use rayon::prelude::*;

/// The slab's δ-M optical thickness: a half-space for the first 20 optical depths.
const THICKNESS: f64 = 60.0;
/// δ-M optical depth of one cell (a 10-m voxel of the cumulus at density 1: σt′ = 0.0172 m⁻¹).
const CELL: f64 = 0.172;
/// Upper ends of the depth bins (δ-M optical depth along the normal).
const DEPTHS: [f64; 9] = [0.25, 0.5, 1.0, 1.5, 2.0, 3.0, 5.0, 10.0, 20.0];

fn main() {
    let photons: u64 = std::env::args().nth(1).map_or(400_000, |s| s.parse().expect("PHOTONS"));
    let (g, a) = (0.9f64, 0.999f64);
    let f = g.powi(4);
    let dm = delta_m(1.0, a, g, f);
    let cells = (THICKNESS / CELL).round() as usize;
    println!(
        "δ-M f = {f:.3}: a′ = {:.5}, g′ = {:.3}; {cells} cells of {CELL} optical depth, {photons} photons",
        dm.albedo, dm.g
    );
    for mu0 in [1.0, 0.69, 0.4, 0.2] {
        let diffusion = collimated_profile(THICKNESS, dm.albedo, dm.g, mu0, cells);
        let (exact, exact_once) = exact_profiles(THICKNESS, dm.albedo, dm.g, mu0, cells, photons);
        // The rows at ten times finer cells, averaged back over each cell.
        let fine = collimated_profile(THICKNESS, dm.albedo, dm.g, mu0, 10 * cells);
        let fine: Vec<f64> = fine.chunks(10).map(|c| c.iter().sum::<f64>() / 10.0).collect();
        let p1 = pn_profile(THICKNESS, dm.albedo, dm.g, mu0, cells, Closure::P1);
        let local = pn_profile(THICKNESS, dm.albedo, dm.g, mu0, cells, Closure::LocalSecondMoment);
        let p3 = pn_profile(THICKNESS, dm.albedo, dm.g, mu0, cells, Closure::P3);
        let worst = diffusion.iter().zip(&p1).map(|(d, p)| (d - p).abs() / p.abs()).fold(0.0, f64::max);
        let first = first_collision_profile(THICKNESS, dm.albedo, dm.g, mu0, cells, Closure::P1);
        let first_p3 = first_collision_profile(THICKNESS, dm.albedo, dm.g, mu0, cells, Closure::P3);
        println!("μ0 = {mu0}: I0 / exact by depth along the normal: the diffusion's rows, the same at cells 10× finer, P1 with φ2 = S2/σ2, P3, the first-collision source with P1, with P3 (exact I0 per unit sun irradiance); P1 = the rows within {worst:.1e}");
        let once: Vec<f64> = once_scattered_moments(THICKNESS, dm.albedo, dm.g, mu0, cells)
            .iter()
            .zip(&exact_once)
            .map(|(m, e)| m[0] / (4.0 * std::f64::consts::PI) / e)
            .collect();
        let worst_once = once.iter().take((1.0 / CELL) as usize).map(|r| (r - 1.0).abs()).fold(0.0, f64::max);
        println!("  the once-scattered I0 against its Monte Carlo share, first optical depth: within {worst_once:.3}");
        let columns = [&diffusion, &fine, &local, &p3, &first, &first_p3];
        let mut lo = 0.0;
        for hi in DEPTHS {
            let (mut sums, mut e, mut m) = ([0.0; 6], 0.0, 0);
            for k in 0..cells {
                let mid = (k as f64 + 0.5) * CELL;
                if mid >= lo && mid < hi {
                    for (s, c) in sums.iter_mut().zip(columns) {
                        *s += c[k];
                    }
                    e += exact[k];
                    m += 1;
                }
            }
            let ratios: Vec<String> = sums.iter().map(|s| format!("{:.3}", s / e)).collect();
            println!("  τ′ {lo:>5}–{hi:<5} {}  ({:.4})", ratios.join("  "), e / m as f64);
            lo = hi;
        }
    }
    // Albedo 0.9 (diffusion length 3 optical depths) keeps the box's sides out of the middle.
    let a3 = 0.9;
    println!(
        "3-D solver on a slab of {SLAB_3D} optical depths (a′ = {a3}, g′ = {:.3}), voxels of {VOXEL_3D}: I0 / exact by depth along the normal",
        dm.g
    );
    let fine = (SLAB_3D / 0.05) as usize;
    for mu0 in [1.0, 0.69, 0.4] {
        let exact = exact_profile(SLAB_3D, a3, dm.g, mu0, fine, photons);
        let rows = collimated_profile(SLAB_3D, a3, dm.g, mu0, (SLAB_3D / VOXEL_3D) as usize);
        let rows: Vec<f64> = rows.iter().flat_map(|v| std::iter::repeat_n(*v, fine / rows.len())).collect();
        let one_d = binned_ratio(&rows, &exact);
        let row: Vec<String> = one_d.iter().map(|(hi, r)| format!("<{hi}: {r:.3}")).collect();
        println!("  μ0 = {mu0}, the 1-D rows: {}", row.join(", "));
        for tilt in [0.0f64, 45.0] {
            let bins = staircase(a3, dm.g, mu0, tilt.to_radians(), &exact);
            let row: Vec<String> = bins.iter().map(|(hi, r)| format!("<{hi}: {r:.3}")).collect();
            println!("  μ0 = {mu0}, 3-D, faces tilted {tilt}°: {}", row.join(", "));
        }
    }
}

/// Mean diffuse radiance (1/4π)∫I dω per cell, per unit sun irradiance across its rays, by Monte
/// Carlo: photons enter at μ0, each carries the flux μ0/N, collide at exponential free paths,
/// keep a′ of their weight at each collision (Russian roulette below 10⁻³), and scatter by HG(g);
/// path length after the first collision is tallied per cell (φ = Σℓ/Δτ, I0 = φ/4π).
fn exact_profile(tau: f64, a: f64, g: f64, mu0: f64, cells: usize, photons: u64) -> Vec<f64> {
    exact_profiles(tau, a, g, mu0, cells, photons).0
}

/// [`exact_profile`], and beside it the once-scattered light's share alone (the flights between
/// the first and the second collision).
fn exact_profiles(tau: f64, a: f64, g: f64, mu0: f64, cells: usize, photons: u64) -> (Vec<f64>, Vec<f64>) {
    let dtau = tau / cells as f64;
    let hg = Hg::new(g as f32);
    const CHUNK: u64 = 4096;
    let sums: Vec<Vec<f64>> = (0..photons.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let mut tally = vec![0.0; 2 * cells];
            for i in c * CHUNK..((c + 1) * CHUNK).min(photons) {
                let mut rng = Rng::new(7, i);
                let (mut z, mut mu, mut w, mut collisions) = (0.0f64, mu0, 1.0f64, 0);
                loop {
                    let s = -(1.0 - rng.uniform_f64()).ln();
                    let z1 = (z + s * mu).clamp(0.0, tau);
                    if collisions > 0 {
                        deposit(&mut tally[..cells], z, z1, mu, w, dtau);
                    }
                    if collisions == 1 {
                        deposit(&mut tally[cells..], z, z1, mu, w, dtau);
                    }
                    if z + s * mu <= 0.0 || z + s * mu >= tau {
                        break;
                    }
                    z = z1;
                    collisions += 1;
                    w *= a;
                    if w < 1e-3 {
                        if rng.uniform_f64() < 0.1 {
                            w *= 10.0;
                        } else {
                            break;
                        }
                    }
                    let ct = hg.sample_cos(rng.uniform()) as f64;
                    let st = (1.0 - ct * ct).max(0.0).sqrt();
                    let phi = 2.0 * std::f64::consts::PI * rng.uniform_f64();
                    mu = (mu * ct + (1.0 - mu * mu).max(0.0).sqrt() * st * phi.cos()).clamp(-1.0, 1.0);
                }
            }
            tally
        })
        .collect();
    let scale = mu0 / (photons as f64 * dtau * 4.0 * std::f64::consts::PI);
    let total = |k: usize| sums.iter().map(|t| t[k]).sum::<f64>() * scale;
    ((0..cells).map(total).collect(), (cells..2 * cells).map(total).collect())
}

/// Adds weight × the path length of the segment z0 → z1 (direction cosine `mu`) inside each cell.
fn deposit(tally: &mut [f64], z0: f64, z1: f64, mu: f64, w: f64, dtau: f64) {
    let (lo, hi) = if z0 < z1 { (z0, z1) } else { (z1, z0) };
    let per_depth = w / mu.abs().max(1e-12);
    let (k0, k1) = ((lo / dtau) as usize, ((hi / dtau) as usize).min(tally.len() - 1));
    for (k, t) in tally.iter_mut().enumerate().take(k1 + 1).skip(k0) {
        let (a, b) = (k as f64 * dtau, (k + 1) as f64 * dtau);
        *t += per_depth * (hi.min(b) - lo.max(a)).max(0.0);
    }
}

/// How the P_N equations are closed.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Closure {
    /// φ2 = φ3 = 0: the diffusion.
    P1,
    /// φ2 = S2/σ2, the l = 2 balance without its transport terms; φ3 = 0.
    LocalSecondMoment,
    /// φ4 = 0.
    P3,
}

/// I0 per cell of the P1 (`p3` false) or P3 equations in the slab (φ_l = 2π∫I P_l dμ, HG(g)
/// moments χ_l = g^l, the sun's first scattering S_l = a E T̄ χ_l P_l(μ0) with T̄ the cell mean):
/// finite volumes with φ0, φ2 at cell centres and φ1, φ3 at faces, Marshak's conditions
/// ∫₀¹ I P_{1,3}(μ) dμ = 0 for the inward μ at both faces (P1: the diffusion's rows exactly).
fn pn_profile(tau: f64, a: f64, g: f64, mu0: f64, cells: usize, closure: Closure) -> Vec<f64> {
    let h = tau / cells as f64;
    let p_mu0 = [1.0, mu0, 0.5 * (3.0 * mu0 * mu0 - 1.0), 0.5 * (5.0 * mu0.powi(3) - 3.0 * mu0)];
    let t_mean = |k: usize| (-(k as f64) * h / mu0).exp() * (-(-h / mu0).exp_m1()) * mu0 / h;
    pn_solve(tau, a, g, cells, closure, &|l, k| a * t_mean(k) * g.powi(l as i32) * p_mu0[l])
}

/// The P_N equations of [`pn_profile`] with the source moments S_l of cell k given by `src(l, k)`
/// (l = 0…3, φ_l units: 2π∫S P_l dμ per unit optical depth); I0 per cell.
fn pn_solve(tau: f64, a: f64, g: f64, cells: usize, closure: Closure, src: &dyn Fn(usize, usize) -> f64) -> Vec<f64> {
    let p3 = closure == Closure::P3;
    let n = cells;
    let h = tau / n as f64;
    let sigma: Vec<f64> = (0..4).map(|l| 1.0 - a * g.powi(l)).collect();
    // Unknowns: top face (φ0, φ2), cells (φ0, φ2)…, bottom face (φ0, φ2).
    let size = 2 * n + 4;
    let (top, cell, bot) = (0usize, |k: usize| 2 + 2 * k, 2 * n + 2);
    let mut m = vec![vec![0.0; size + 1]; size];
    // φ1 and φ3 on the face from node L to node R (Δ apart) as (coefficients, constant).
    let face = |l: usize, r: usize, delta: f64, s1: f64, s3: f64| {
        let phi1 = (
            vec![
                (r, -1.0 / (3.0 * delta * sigma[1])),
                (l, 1.0 / (3.0 * delta * sigma[1])),
                (r + 1, -2.0 / (3.0 * delta * sigma[1])),
                (l + 1, 2.0 / (3.0 * delta * sigma[1])),
            ],
            s1 / sigma[1],
        );
        let phi3 = (
            vec![(r + 1, -3.0 / (7.0 * delta * sigma[3])), (l + 1, 3.0 / (7.0 * delta * sigma[3]))],
            s3 / sigma[3],
        );
        (phi1, phi3)
    };
    type Lin = (Vec<(usize, f64)>, f64);
    let add = |row: &mut Vec<f64>, e: &Lin, w: f64| {
        for (i, c) in &e.0 {
            row[*i] += w * c;
        }
        row[size] -= w * e.1;
    };
    let faces: Vec<(Lin, Lin)> = (0..=n)
        .map(|j| match j {
            0 => face(top, cell(0), 0.5 * h, src(1, 0), src(3, 0)),
            j if j == n => face(cell(n - 1), bot, 0.5 * h, src(1, n - 1), src(3, n - 1)),
            j => face(
                cell(j - 1),
                cell(j),
                h,
                0.5 * (src(1, j - 1) + src(1, j)),
                0.5 * (src(3, j - 1) + src(3, j)),
            ),
        })
        .collect();
    for k in 0..n {
        let (i0, i2) = (cell(k), cell(k) + 1);
        let (lo, hi) = (&faces[k], &faces[k + 1]);
        let row = &mut m[i0];
        row[i0] += sigma[0];
        row[size] += src(0, k);
        add(row, &hi.0, 1.0 / h);
        add(row, &lo.0, -1.0 / h);
        let row = &mut m[i2];
        if p3 {
            row[i2] += sigma[2];
            row[size] += src(2, k);
            add(row, &hi.1, 0.6 / h);
            add(row, &lo.1, -0.6 / h);
            add(row, &hi.0, 0.4 / h);
            add(row, &lo.0, -0.4 / h);
        } else {
            row[i2] = 1.0;
            if closure == Closure::LocalSecondMoment {
                row[size] = src(2, k) / sigma[2];
            }
        }
    }
    // Marshak: φ0/2 ± φ1 + 5φ2/8 = 0 and −φ0/8 + 5φ2/8 ± φ3 = 0 (+ at the top, − at the bottom).
    for (node, f, sign) in [(top, &faces[0], 1.0), (bot, &faces[n], -1.0)] {
        let row = &mut m[node];
        row[node] += 0.5;
        row[node + 1] += 0.625;
        add(row, &f.0, sign);
        let row = &mut m[node + 1];
        if p3 {
            row[node] -= 0.125;
            row[node + 1] += 0.625;
            add(row, &f.1, sign);
        } else {
            row[node + 1] = 1.0;
            if closure == Closure::LocalSecondMoment {
                row[size] = src(2, if node == top { 0 } else { n - 1 }) / sigma[2];
            }
        }
    }
    let x = gauss(m);
    (0..n).map(|k| x[cell(k)] / (4.0 * std::f64::consts::PI)).collect()
}

/// The sun's once-scattered light, exactly: cell means of its Legendre moments φ_l = 2π∫I P_l dμ
/// (l = 0…3, per unit sun irradiance across the rays) in the slab lit at μ0. Its source is
/// a e^{−t/μ0} p̄(μ, μ0) per unit optical depth, p̄ the azimuthal mean of HG(g) (its Legendre
/// series to l = 150); downwards I(τ, μ) = a p̄ μ0 (e^{−τ/μ} − e^{−τ/μ0})/(μ − μ0), upwards
/// a p̄ μ0/(μ0 + |μ|) (e^{−τ/μ0} − e^{−T/μ0} e^{−(T−τ)/|μ|}); 1024 Gauss–Legendre nodes in μ.
fn once_scattered_moments(tau: f64, a: f64, g: f64, mu0: f64, cells: usize) -> Vec<[f64; 4]> {
    use std::f64::consts::PI;
    let h = tau / cells as f64;
    let legendre = |x: f64, n: usize| cloudgi::transport::legendre(n, x);
    let pl0 = legendre(mu0, 150);
    let (xs, ws) = cloudgi::transport::gauss_legendre(1024);
    let nodes = xs.into_iter().zip(ws);
    // Cell mean of e^{−τ/m} over [t0, t0 + h].
    let mean = |m: f64, t0: f64| m * ((-t0 / m).exp() - (-(t0 + h) / m).exp()) / h;
    let mut out = vec![[0.0; 4]; cells];
    for (mu, w) in nodes {
        let pl = legendre(mu, 150);
        let p_bar: f64 = (0..=150)
            .map(|l| (2 * l + 1) as f64 * g.powi(l as i32) * pl[l] * pl0[l])
            .sum::<f64>()
            / (4.0 * PI);
        for (k, o) in out.iter_mut().enumerate() {
            let t0 = k as f64 * h;
            let i = if mu > 0.0 {
                if (mu - mu0).abs() < 1e-9 {
                    // τ e^{−τ/μ0}/μ0, its cell mean.
                    let s = 16;
                    (0..s)
                        .map(|j| {
                            let t = t0 + (j as f64 + 0.5) * h / s as f64;
                            t * (-t / mu0).exp() / mu0
                        })
                        .sum::<f64>()
                        / s as f64
                } else {
                    mu0 * (mean(mu, t0) - mean(mu0, t0)) / (mu - mu0)
                }
            } else {
                let m = -mu;
                let far = m * ((-(tau - t0 - h) / m).exp() - (-(tau - t0) / m).exp()) / h;
                mu0 / (mu0 + m) * (mean(mu0, t0) - (-tau / mu0).exp() * far)
            };
            let pm = [1.0, mu, 0.5 * (3.0 * mu * mu - 1.0), 0.5 * (5.0 * mu.powi(3) - 3.0 * mu)];
            for l in 0..4 {
                o[l] += 2.0 * PI * w * a * p_bar * i * pm[l];
            }
        }
    }
    out
}

/// The first-collision source: the sun's once-scattered light exactly ([`once_scattered_moments`])
/// plus the `closure`'s solution for the orders ≥ 2, whose source is the once-scattered light
/// scattered again, S_l = a g^l φ_l^(1). I0 per cell.
fn first_collision_profile(tau: f64, a: f64, g: f64, mu0: f64, cells: usize, closure: Closure) -> Vec<f64> {
    let once = once_scattered_moments(tau, a, g, mu0, cells);
    let rest = pn_solve(tau, a, g, cells, closure, &|l, k| a * g.powi(l as i32) * once[k][l]);
    rest.iter()
        .zip(&once)
        .map(|(r, o)| r + o[0] / (4.0 * std::f64::consts::PI))
        .collect()
}

/// Solves the augmented system (each row: coefficients, then the right-hand side) by Gaussian
/// elimination with partial pivoting.
fn gauss(mut m: Vec<Vec<f64>>) -> Vec<f64> {
    let n = m.len();
    for c in 0..n {
        let p = (c..n).max_by(|&i, &j| m[i][c].abs().total_cmp(&m[j][c].abs())).unwrap();
        m.swap(c, p);
        let (upper, lower) = m.split_at_mut(c + 1);
        let pivot = &upper[c];
        for row in lower {
            let k = row[c] / pivot[c];
            if k != 0.0 {
                for (v, q) in row[c..].iter_mut().zip(&pivot[c..]) {
                    *v -= k * q;
                }
            }
        }
    }
    let mut x = vec![0.0; n];
    for r in (0..n).rev() {
        let s: f64 = (r + 1..n).map(|j| m[r][j] * x[j]).sum();
        x[r] = (m[r][n] - s) / m[r][r];
    }
    x
}

/// Depth bins of the 3-D comparison (upper ends, optical depth along the normal).
const EDGES_3D: [f64; 6] = [0.5, 1.0, 2.0, 3.0, 5.0, 10.0];

/// Σ`profile` / Σ`exact` over the fine cells of each bin of [`EDGES_3D`] (cells across [`SLAB_3D`]).
fn binned_ratio(profile: &[f64], exact: &[f64]) -> Vec<(f64, f64)> {
    let cell = SLAB_3D / exact.len() as f64;
    let mut sums = [(0.0, 0.0); EDGES_3D.len()];
    for (k, (p, e)) in profile.iter().zip(exact).enumerate() {
        if let Some(b) = EDGES_3D.iter().position(|&hi| (k as f64 + 0.5) * cell < hi) {
            sums[b].0 += p;
            sums[b].1 += e;
        }
    }
    EDGES_3D.iter().zip(sums).map(|(hi, (p, e))| (*hi, p / e)).collect()
}

/// The 3-D slab's δ-M optical thickness and its voxels' δ-M optical depth.
const SLAB_3D: f64 = 20.0;
const VOXEL_3D: f64 = 0.5;

/// The 3-D solver's I0 over the exact one, binned by optical depth along the normal (bins ending
/// at 0.5, 1, 2, 3, 5, 10), on a slab of [`SLAB_3D`] whose normal is tilted by `tilt` from the grid's
/// y axis about x (45°: every surface voxel a stair), lit by the sun at μ0 from its normal, in the
/// normal's plane; voxels of [`VOXEL_3D`] optical depth (1 m, σt′ = 0.5 m⁻¹). Read in the middle
/// (8 voxels either side of the centre in x and along the slab) to stay clear of its edges.
fn staircase(a: f64, g: f64, mu0: f64, tilt: f64, exact: &[f64]) -> Vec<(f64, f64)> {
    let thick = SLAB_3D / VOXEL_3D;
    let (nx, nyz) = (40usize, if tilt == 0.0 { 60usize } else { 100 });
    let n = Vec3::new(0.0, tilt.cos() as f32, tilt.sin() as f32);
    let t = Vec3::new(0.0, -tilt.sin() as f32, tilt.cos() as f32);
    let sin0 = (1.0 - mu0 * mu0).sqrt() as f32;
    let to_sun = n * mu0 as f32 - t * sin0;
    let mut grid = Grid3::filled([nx, if tilt == 0.0 { thick as usize } else { nyz }, nyz], 0.0);
    let dims = grid.dims();
    // The slab's mid-plane passes through the box's centre.
    let centre = Vec3::new(dims[0] as f32, dims[1] as f32, dims[2] as f32) * 0.5;
    // Depth below the lit surface (voxels).
    let depth_at = |i: usize, j: usize, k: usize| {
        let p = Vec3::new(i as f32 + 0.5, j as f32 + 0.5, k as f32 + 0.5);
        (0.5 * thick as f32) - (p - centre).dot(n)
    };
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let d = depth_at(i, j, k);
                if d >= 0.0 && d <= thick as f32 {
                    grid.set(i, j, k, 1.0);
                }
            }
        }
    }
    let m = Medium::new(grid, Vec3::ZERO, Vec3::ONE, VOXEL_3D as f32, Rgb::splat(a as f32), g as f32);
    let src = IncidentSources {
        bin_radiance: vec![Rgb::ZERO; 96],
        sun: Some((to_sun, Rgb::ONE)),
    };
    let inc = compute(&m, &DirectionBins::new(), &src, &IncidentSettings::default(), None);
    let settings = DiffusionSettings {
        tolerance: 1e-8,
        max_iterations: 1000,
        min_optical_depth: 0.0,
        sky_boundary: false,
    };
    let sol = solve_diffusion(&m, &inc, &BoundaryLight::none(), None, &settings).expect("solve");
    let mut sums = [(0.0, 0.0); EDGES_3D.len()];
    let cell = SLAB_3D / exact.len() as f64;
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let p = Vec3::new(i as f32 + 0.5, j as f32 + 0.5, k as f32 + 0.5);
                if m.density.at(i + dims[0] * (j + dims[1] * k)) <= 0.0 || (p.x - centre.x).abs() > 8.0 || (p - centre).dot(t).abs() > 8.0 {
                    continue;
                }
                let tau = f64::from(depth_at(i, j, k)) * VOXEL_3D;
                if let Some(b) = EDGES_3D.iter().position(|&e| tau < e) {
                    let e = exact[((tau / cell) as usize).min(exact.len() - 1)];
                    sums[b].0 += f64::from(sol.at(i, j, k).x);
                    sums[b].1 += e;
                }
            }
        }
    }
    EDGES_3D.iter().zip(sums).map(|(e, (d, x))| (*e, d / x)).collect()
}
