//! Stage 1's first scattering per full voxel, Q0 (eq. 5) and Q1 (eq. 6), kept in the smallest form
//! its sources allow and read through [`FirstScattering::q0`] and [`FirstScattering::q1`].
//!
//! **The sun alone** (`render.sky_boundary`, the default: sky and ground enter through the
//! diffusion's boundary condition, stage 1 propagates the sun only): with one source of irradiance
//! E, Σ0_c = E_c·T̄_c and Σ1 = Σ0·(−sun dir), T̄ the sun's voxel-mean transmittance, so
//!
//! ```text
//!   Q0_c = ρT̄ · σs_c E_c/(4π),   Q1 = g · Q0 · (−sun dir)
//! ```
//!
//! and, when every band decays with the same extinction (the medium's optics have one σt for all
//! bands), T̄ is one number per voxel: ρT̄ in 2 B per full voxel instead of 48, in 16
//! bits ([`Field16`]: relative rounding ≤ 2⁻¹² down to 2⁻¹³ of the largest ρT̄, absolute
//! ≤ 2⁻²⁵ of it below, where the sun's light is spent; it lives from stage 1 to the final lit
//! volume of `full`, through both solves).
//! **Otherwise** (sky bins, the clear-air hook, or per-band extinction) Q0 and Q1 are stored per
//! band.

use super::Acc;
use crate::math::{Rgb, Vec3};
use crate::medium::field16::Field16;
use crate::medium::sparse::{FullIndex, VoxelField};
use crate::optics::Optics;
use crate::par;
use std::f64::consts::PI;
use std::sync::Arc;

/// Q0 and Q1 per full voxel (zero where ρ = 0); see the module docs.
#[derive(Clone, Debug)]
pub enum FirstScattering {
    /// Any sources: Q0 per band (W·m⁻³·sr⁻¹), and Q1 as `q1[axis]` per band.
    General { q0: VoxelField<Rgb>, q1: [VoxelField<Rgb>; 3] },
    /// The sun alone, one extinction for all bands: ρ times the sun's voxel-mean transmittance.
    Sun {
        /// ρT̄ per full voxel (density units), in 16 bits; 0 where ρ = 0.
        rho_t: Field16,
        /// Q0 per unit ρT̄, σs_c E_c/(4π) per band (W·m⁻²·sr⁻¹ per unit density, × m⁻¹).
        q0_per_rho_t: [f64; 3],
        /// Q1 per unit Q0: g·(−sun dir), per axis.
        q1_per_q0: [f64; 3],
    },
}

impl FirstScattering {
    /// Q0 of grid voxel `g` in `band` (W·m⁻³·sr⁻¹). One band at a time: the diffusion reads
    /// one band per pass, and the sun's form computes only what is read.
    #[inline(always)]
    pub fn q0(&self, g: usize, band: usize) -> f32 {
        self.q0_at_slot(self.index().slot(g), band)
    }

    /// The `axis` component of Q1 of grid voxel `g` in `band` (W·m⁻³·sr⁻¹).
    #[inline(always)]
    pub fn q1(&self, axis: usize, g: usize, band: usize) -> f32 {
        self.q1_at_slot(axis, self.index().slot(g), band)
    }

    /// [`FirstScattering::q0`] of the voxel in slot `s` of [`FirstScattering::index`] (the
    /// density's: a caller that has the slot for ρ reads Q0 without a second look-up).
    #[inline(always)]
    pub fn q0_at_slot(&self, s: usize, band: usize) -> f32 {
        match self {
            FirstScattering::General { q0, .. } => q0.at_slot(s)[band],
            FirstScattering::Sun { rho_t, q0_per_rho_t, .. } => (f64::from(rho_t.at_slot(s)) * q0_per_rho_t[band]) as f32,
        }
    }

    /// [`FirstScattering::q1`] of the voxel in slot `s`.
    #[inline(always)]
    pub fn q1_at_slot(&self, axis: usize, s: usize, band: usize) -> f32 {
        match self {
            FirstScattering::General { q1, .. } => q1[axis].at_slot(s)[band],
            FirstScattering::Sun {
                rho_t,
                q0_per_rho_t,
                q1_per_q0,
            } => (f64::from(rho_t.at_slot(s)) * q1_per_q0[axis] * q0_per_rho_t[band]) as f32,
        }
    }

    /// The full-voxel index the values are stored on (the density's).
    pub fn index(&self) -> &Arc<FullIndex> {
        match self {
            FirstScattering::General { q0, .. } => q0.index(),
            FirstScattering::Sun { rho_t, .. } => rho_t.index(),
        }
    }

    /// Bytes held by the values (the shared index not counted).
    pub fn bytes(&self) -> usize {
        match self {
            FirstScattering::General { q0, q1 } => q0.bytes() + q1.iter().map(|f| f.bytes()).sum::<usize>(),
            FirstScattering::Sun { rho_t, .. } => rho_t.bytes(),
        }
    }

    /// Zero everywhere (nothing propagated), in the sun's form.
    pub fn zero(index: Arc<FullIndex>) -> FirstScattering {
        FirstScattering::Sun {
            rho_t: Field16::zero(index),
            q0_per_rho_t: [0.0; 3],
            q1_per_q0: [0.0; 3],
        }
    }

    /// From the accumulators `acc` of the full voxels (in `index` order) of density `rho`:
    /// Σ0, Σ1 scattered with ρσs/(4π) and ρσs·g/(4π). One parallel pass, ρσs/(4π) once per voxel
    /// and band. With δ-scaling (f = g) the scattering that changes direction is σs(1 − g),
    /// isotropic (g' = 0).
    pub fn general(index: Arc<FullIndex>, optics: &Optics, acc: &[Acc], rho: &[f32]) -> FirstScattering {
        let (sigma_s, g) = (optics.sigma_s(), optics.phase.mean_cosine());
        let n = acc.len() + 1;
        let mut q0 = vec![Rgb::ZERO; n];
        let mut q1: [Vec<Rgb>; 3] = std::array::from_fn(|_| vec![Rgb::ZERO; n]);
        let [q1x, q1y, q1z] = &mut q1;
        let mut parts: Vec<[&mut [Rgb]; 4]> = (q0[1..].chunks_mut(CHUNK).zip(q1x[1..].chunks_mut(CHUNK)))
            .zip(q1y[1..].chunks_mut(CHUNK).zip(q1z[1..].chunks_mut(CHUNK)))
            .map(|((q0, qx), (qy, qz))| [q0, qx, qy, qz])
            .collect();
        par::for_chunks(&mut parts, 1, &|ci, part| {
            let [q0, qx, qy, qz] = &mut part[0];
            let (acc, rho) = (&acc[ci * CHUNK..ci * CHUNK + q0.len()], &rho[ci * CHUNK..]);
            for (i, v) in acc.iter().enumerate() {
                let s: [f64; 3] = std::array::from_fn(|c| rho[i] as f64 * sigma_s[c] as f64 / (4.0 * PI));
                let term =
                    |t: usize, k: f64| Rgb::new((s[0] * k * v[t]) as f32, (s[1] * k * v[t + 1]) as f32, (s[2] * k * v[t + 2]) as f32);
                q0[i] = term(0, 1.0);
                qx[i] = term(3, g);
                qy[i] = term(6, g);
                qz[i] = term(9, g);
            }
            });
        let field = |slots| VoxelField::from_slots(index.clone(), slots);
        let [q1x, q1y, q1z] = q1;
        FirstScattering::General {
            q0: field(q0),
            q1: [field(q1x), field(q1y), field(q1z)],
        }
    }

    /// From a sweep whose only source was the sun, towards unit `sun_dir` with irradiance
    /// `sun_e` (W/m² per band), every band decaying alike: Σ0_c = E_c·T̄, so ρT̄ = ρΣ0_c/E_c;
    /// `sums` holds Σ0 of the band [`Self::sun_band`] only (Σ1 is the same light along the flow).
    pub fn sun(index: Arc<FullIndex>, optics: &Optics, sums: &[[f64; 1]], rho: &[f32], sun_dir: Vec3, sun_e: Rgb) -> FirstScattering {
        let band = Self::sun_band(sun_e);
        let inv_e = if sun_e[band] > 0.0 { 1.0 / sun_e[band] as f64 } else { 0.0 };
        let acc = sums;
        let mut rho_t = vec![0f32; acc.len()];
        par::for_chunks(&mut rho_t, CHUNK, &|ci, out| {
            for ((v, r), o) in acc[ci * CHUNK..].iter().zip(&rho[ci * CHUNK..]).zip(out) {
                *o = (*r as f64 * v[0] * inv_e) as f32;
            }
            });
        let g = optics.phase.mean_cosine();
        FirstScattering::Sun {
            rho_t: Field16::new(index, &rho_t),
            q0_per_rho_t: std::array::from_fn(|c| optics.sigma_s()[c] as f64 * sun_e[c] as f64 / (4.0 * PI)),
            q1_per_q0: std::array::from_fn(|a| -g * sun_dir[a] as f64),
        }
    }

    /// The band whose Σ0 a sun-only stage 1 accumulates ([`FirstScattering::sun`]'s `sums`):
    /// the sun's brightest (any would do, the bands differing only by the sun's colour).
    pub fn sun_band(sun_e: Rgb) -> usize {
        (0..3).fold(0, |b, c| if sun_e[c] > sun_e[b] { c } else { b })
    }
}

/// Voxels per task of the parallel passes.
const CHUNK: usize = 4096;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Rng;
    use crate::medium::Grid3;
    use crate::optics::Optics;

    /// A sun-only sweep's accumulators (Σ0_c = E_c·T̄, Σ1 = Σ0·flow) on a random cloud: the sun's
    /// form gives the general form's Q0 and Q1 to f32 rounding, in 4 B per full voxel.
    #[test]
    fn sun_form_matches_the_general_form_on_sun_only_sums() {
        let dims = [9, 7, 5];
        let mut rng = Rng::new(3, 0);
        let mut g = Grid3::filled(dims, 0.0);
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    if rng.uniform() < 0.6 {
                        g.set(i, j, k, 0.1 + 2.0 * rng.uniform());
                    }
                }
            }
        }
        let index = g.full_index();
        let rho: Vec<f32> = g.data().iter().copied().filter(|r| *r > 0.0).collect();
        let optics = Optics::new(0.8, Rgb::new(0.9, 0.7, 0.99), 0.6);
        let (dir, e) = (Vec3::new(0.3, 0.8, -0.5).normalize(), Rgb::new(2.0, 3.0, 1.5));
        let acc: Vec<Acc> = rho
            .iter()
            .map(|_| {
                let t = rng.uniform_f64();
                let mut a = [0.0; 12];
                for c in 0..3 {
                    a[c] = e[c] as f64 * t;
                    for ax in 0..3 {
                        a[3 + 3 * ax + c] = a[c] * -dir[ax] as f64;
                    }
                }
                a
            })
            .collect();
        let general = FirstScattering::general(index.clone(), &optics, &acc, &rho);
        let band = FirstScattering::sun_band(e);
        let sums: Vec<[f64; 1]> = acc.iter().map(|a| [a[band]]).collect();
        let sun = FirstScattering::sun(index.clone(), &optics, &sums, &rho, dir, e);
        assert_eq!(sun.bytes(), 2 * (rho.len() + 1));
        assert_eq!(general.bytes(), 48 * (rho.len() + 1));
        // ρT̄ in 16 bits: within 2⁻¹² relative above 2⁻¹³ of the largest, 2⁻²⁵ of it below.
        // (Q1 is Q0 times g·|sun dir| ≤ 1 per axis, so Q0's floor bounds it too.)
        let floor: [f32; 3] = std::array::from_fn(|c| (0..index.len()).map(|v| general.q0(v, c)).fold(0.0, f32::max) / 33_554_432.0);
        let close = |a: f32, b: f32, c: usize| (a - b).abs() <= b.abs() * (1.0 / 4096.0 + 4.0 * f32::EPSILON) + floor[c];
        let mut lit = 0;
        for v in 0..index.len() {
            for c in 0..3 {
                let (a, b) = (sun.q0(v, c), general.q0(v, c));
                assert!(close(a, b, c), "voxel {v} band {c}: Q0 {a} vs {b}");
                for ax in 0..3 {
                    let (a, b) = (sun.q1(ax, v, c), general.q1(ax, v, c));
                    assert!(close(a, b, c), "voxel {v} band {c}: Q1[{ax}] {a} vs {b}");
                }
            }
            lit += usize::from(general.q0(v, 0) > 0.0);
        }
        assert!(lit > 100, "{lit} lit voxels");
    }

    /// Nothing propagated: zero everywhere.
    #[test]
    fn zero_reads_zero() {
        let g = Grid3::filled([3, 2, 2], 1.0);
        let z = FirstScattering::zero(g.full_index());
        assert!((0..12).all(|v| (0..3).all(|c| z.q0(v, c) == 0.0 && (0..3).all(|a| z.q1(a, v, c) == 0.0))));
    }
}
