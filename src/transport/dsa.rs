//! Diffusion synthetic acceleration (module docs of [`super::solve`]): after a sweep the
//! isotropic change ΔI0 drives the diffusion equation −∇·(D∇δ) + ρσa′ δ = ρσs′ ΔI0 with
//! D = 1/(3ρσtr′) plus the sweeps' own numerical diffusion ([`super::accel`]: consistent with the
//! sweeps on thick voxels; δ-M coefficients, Marshak boundary), solved by
//! multigrid-preconditioned CG; I_00 += √(4π) δ, and the correction's P1 current (Fick's law)
//! goes into the first moments.

use super::accel::{DsaOperator, SweepDiffusion};
use super::grid::Ctx;
use super::grid::{full_of, FullVoxels};
use super::sphere::Quadrature;
use super::BandOptics;
use crate::diffusion::multigrid::Hierarchy;
use crate::diffusion::{interior_coupling, Domain, DEFAULT_MIN_OPTICAL_DEPTH};
use crate::medium::Medium;
use crate::par;
use std::f64::consts::PI;

/// The DSA operators' multigrid hierarchies: the diffusion operator of medium `m` with each
/// band's δ-M coefficients σa′ and σtr′ and the sweeps' own diffusion on quadrature `q`
/// ([`DsaOperator`]), one per distinct band optics (one for grey optics, as in every example);
/// none for an empty medium. `index`: the medium's full voxels.
pub(super) fn hierarchies(m: &Medium, bands: &[BandOptics; 3], index: &FullVoxels, q: &Quadrature) -> Vec<Hierarchy> {
    let Some(dom) = Domain::of(m) else {
        return Vec::new();
    };
    let h = [m.voxel_size.x as f64, m.voxel_size.y as f64, m.voxel_size.z as f64];
    let distinct = if bands[1..].iter().all(|b| *b == bands[0]) { 1 } else { 3 };
    bands[..distinct]
        .iter()
        .map(|bo| {
            Hierarchy::build(&DsaOperator {
                grid: m.dims(),
                rho: &m.density,
                full: &index.index,
                voxels: &index.voxels,
                dom,
                h,
                sigma_a: bo.sigma_t * (1.0 - bo.albedo),
                sigma_tr: bo.sigma_tr(),
                tau_min: DEFAULT_MIN_OPTICAL_DEPTH,
                sweep: SweepDiffusion::new(bo.sigma_t, q, h),
            })
        })
        .collect()
}

/// Diffusion synthetic acceleration of band `b` after a sweep (module docs): the isotropic change
/// ΔI0 of the sweep drives the diffusion equation for the error δ of the mean radiance (W·m⁻²·sr⁻¹);
/// I_00 += √(4π) δ, and the P1 radiance of the correction, δI(Ω) = δ − Ω·∇δ/(ρσtr′) (Fick's law
/// with the operator's own face couplings), adds its first moments I_1m += −√(4π/3) ∂_m δ/(ρσtr′).
/// Without the first moments the current's error decays only by a′χ′_1 ≈ 0.8 per sweep: the
/// noon cloud at σt × 4 took 18 iterations with δ alone, 13 with both.
///
/// `hier` holds one hierarchy per band, or one for all three when the bands' optics are the same
/// (then the three systems are solved together, the operator's rows read once per pass).
/// `voxels`: the grid index of every full voxel (the unknowns), in grid order.
pub(super) fn accelerate(c: &Ctx, voxels: &[usize], hier: &[Hierarchy], bands: &[BandOptics], moments: &[f32], next: &mut [f32]) {
    let rhs: Vec<Vec<f64>> = (0..3).map(|b| dsa_rhs(c, voxels, &bands[b], b, moments, next)).collect();
    // The correction need only remove most of the slow error, not converge: looser than this,
    // thick clouds take more transport iterations (docs/transport.md, "The DSA's own tolerance").
    let (tol, cap) = (1e-1, 100);
    let mut deltas: Vec<Vec<f64>> = if let [h] = hier {
        h.solve_many([&rhs[0][..], &rhs[1][..], &rhs[2][..]], None, tol, cap)
            .map(|(d, _)| d)
            .into()
    } else {
        hier.iter().zip(&rhs).map(|(h, r)| h.solve(r, None, tol, cap).0).collect()
    };
    for (b, delta) in deltas.iter_mut().enumerate() {
        // With back-scattering (χ′_1 < 0) the error's current alternates from sweep to sweep and
        // the full correction overshoots it (g = −0.9 diverged, with or without the first
        // moments); half of it converges (the default cloud at g = −0.9: 14 iterations).
        if bands[b].chi.get(1).is_some_and(|&c| c < 0.0) {
            delta.iter_mut().for_each(|d| *d *= 0.5);
        }
    }
    // Each voxel's update writes only its own entries: voxels in parallel, the same bits.
    let chunk = 1024;
    par::for_chunks(next, chunk * 3 * c.nsh, &|ci, block| {
        let f0 = ci * chunk;
        dsa_apply(c, &voxels[f0..f0 + block.len() / (3 * c.nsh)], f0, bands, &deltas, block);
    });
}

/// Band `b`'s DSA right-hand side per full voxel: ρσs′ ΔI0 of the last sweep.
fn dsa_rhs(c: &Ctx, voxels: &[usize], bo: &BandOptics, b: usize, moments: &[f32], next: &[f32]) -> Vec<f64> {
    let nsh = c.nsh;
    let y00 = 1.0 / (4.0 * PI).sqrt();
    par::map_items(voxels.len(), par::CHUNK, &|f| {
        let d0 = (next[(f * 3 + b) * nsh] - moments[(f * 3 + b) * nsh]) as f64 * y00;
        c.rho.at(voxels[f]) as f64 * bo.sigma_t * bo.albedo * d0
    })
}

/// Add each band's correction δ (per full voxel, `deltas`) as its P1 radiance (see
/// [`accelerate`]) to the full voxels from `f0`, whose grid indices are `voxels` and whose entries
/// of the new moments are `next`. The neighbours and densities are found once per voxel for
/// the three bands.
fn dsa_apply(c: &Ctx, voxels: &[usize], f0: usize, bands: &[BandOptics], deltas: &[Vec<f64>], next: &mut [f32]) {
    let (dims, nsh) = (c.dims, c.nsh);
    let y00 = 1.0 / (4.0 * PI).sqrt();
    let sigma_tr: [f64; 3] = std::array::from_fn(|b| bands[b].sigma_tr());
    let gstride = [1, dims[0], dims[0] * dims[1]];
    for (k, &v) in voxels.iter().enumerate() {
        let f = f0 + k;
        for (b, delta) in deltas.iter().enumerate() {
            next[(k * 3 + b) * nsh] += (delta[f] / y00) as f32;
        }
        if nsh < 4 {
            continue;
        }
        let cell = [v % dims[0], (v / dims[0]) % dims[1], v / (dims[0] * dims[1])];
        let rho = c.rho.at(v) as f64;
        for ax in 0..3 {
            // This voxel's full neighbours along the axis: (side, full index, density).
            let mut faces = [(0.0, 0usize, 0.0); 2];
            let mut n = 0;
            for side in [-1i64, 1] {
                let nc = cell[ax] as i64 + side;
                if nc < 0 || nc >= dims[ax] as i64 {
                    continue;
                }
                let nv = (v as i64 + side * gstride[ax] as i64) as usize;
                match full_of(c.full, nv) {
                    u32::MAX => {}
                    nf => {
                        faces[n] = (side as f64, nf as usize, c.rho.at(nv) as f64);
                        n += 1;
                    }
                }
            }
            if n == 0 {
                continue;
            }
            for (b, delta) in deltas.iter().enumerate() {
                // ∂δ/∂x_ax / (ρσtr′): the mean over this voxel's faces to full neighbours of
                // 3 D_f (δ_n − δ_p)/h, D_f/h² being the operator's face coupling.
                let mut sum = 0.0;
                for &(side, nf, rho_n) in &faces[..n] {
                    let cf = interior_coupling(rho, rho_n, sigma_tr[b], c.h[ax], DEFAULT_MIN_OPTICAL_DEPTH);
                    sum += 3.0 * cf * c.h[ax] * (delta[nf] - delta[f]) * side;
                }
                // real_sh's l = 1 functions are √(3/4π) (z, y, x), the first odd ones.
                next[(k * 3 + b) * nsh + c.even + [2, 1, 0][ax]] -= ((4.0 * PI / 3.0).sqrt() * sum / n as f64) as f32;
            }
        }
    }
}
