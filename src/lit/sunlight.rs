//! Transmittance of the direct sun through the cloud, precomputed at voxel centres.
//!
//! The paper keeps the reduced sun radiance I_risun per voxel; here each voxel centre near the
//! cloud gets the exact optical depth towards the sun (Simpson on the trilinear field), and the
//! gather interpolates it trilinearly. Voxels whose 3×3×3 neighbourhood is empty are never
//! sampled by a scattering point and are skipped (they read 1); they include every voxel beyond
//! one voxel of the full voxels' box, so only that box is stored ([`SubGrid`]).
//!
//! **The march** is [`Medium::density_integral`]'s (Simpson per dual cell, exact for the
//! trilinear field) with the cell's 8 corner densities loaded once for its midpoint and exit
//! point, the entry value carried over from the previous cell, and positions kept in f64: the
//! same integral up to rounding (~1e-7 relative), at about half the loads. It stops once
//! exp(−τ) is 0 in f32.
//!
//! **Storage.** T ∈ [0, 1] is kept in 16 bits ([`Unit16`]: relative rounding ≤ 2⁻¹² ≈ 0.024 %,
//! values below 2⁻³¹ ≈ 4.7e-10 read 2⁻³¹), decoded by a shift and an add at each corner of the
//! trilinear look-up: the grid lives from stage 1 to the final gather of `full`, through its
//! memory peak, at 2 B per voxel of the grown box instead of 4.

use crate::half::Unit16;
use crate::math::Vec3;
use crate::medium::{Medium, SubGrid};
use glam::DVec3;
use crate::par;
use std::sync::atomic::Ordering;
use std::sync::Arc;

/// The sun transmittance's grid: 16-bit codes (module docs).
pub type SunGrid = SubGrid<Unit16>;

/// exp(−τ_sun) at voxel centres.
#[derive(Clone, Debug)]
pub struct SunTransmittance {
    /// Transmittance towards the sun at each voxel centre (unitless), stored on the full voxels'
    /// box grown by one voxel; 1 elsewhere.
    pub grid: Arc<SunGrid>,
    /// The bits of a non-finite transmittance met while computing (stored values are clamped to
    /// [0, 1] by their 16-bit code, so it is kept here for [`SunTransmittance::check_finite`]).
    non_finite: Option<u32>,
}

impl SunTransmittance {
    /// Compute for every voxel within one voxel of non-zero density.
    pub fn compute(m: &Medium, sun_dir: Vec3) -> Self {
        let d = m.dims();
        let (lo, hi) = m.active_box(1).unwrap_or(([0; 3], [0; 3]));
        // A dense copy of ρ on the same box, dropped on return: the march reads 8 corners per
        // dual cell, one load each here (a slot look-up each on the packed density).
        let rho = m.density.box_copy(lo, hi);
        let mut grid = SunGrid::filled(d, lo, hi, 1.0, 1.0);
        let (_, [nx, ny, _]) = grid.bounds();
        // The first non-finite value's bits (u32::MAX: none seen; a NaN's bits are never that).
        let bad = std::sync::atomic::AtomicU32::new(u32::MAX);
        if nx * ny > 0 {
            par::for_chunks(grid.box_values_mut(), nx * ny, &|k, slab| {
                let k = k + lo[2];
                for j in 0..ny {
                    for i in 0..nx {
                        let (i, j) = (i + lo[0], j + lo[1]);
                        let mut near = false;
                        'n: for dk in -1..=1isize {
                            for dj in -1..=1isize {
                                for di in -1..=1isize {
                                    // Beyond the grid's side the index wraps: outside the box, 0.
                                    let at = |c: usize, dc: isize| c.wrapping_add_signed(dc);
                                    if rho.get(at(i, di), at(j, dj), at(k, dk)) > 0.0 {
                                        near = true;
                                        break 'n;
                                    }
                                }
                            }
                        }
                        if near {
                            let p = m.voxel_center(i, j, k);
                            let t = transmittance(m, &rho, p, sun_dir, TAU_UNIT16);
                            if !t.is_finite() {
                                let _ = bad.compare_exchange(u32::MAX, t.to_bits(), Ordering::Relaxed, Ordering::Relaxed);
                            }
                            slab[i - lo[0] + nx * (j - lo[1])] = Unit16::from_f32(t);
                        }
                    }
                }
            });
        }
        SunTransmittance {
            grid: Arc::new(grid),
            non_finite: Some(bad.into_inner()).filter(|b| *b != u32::MAX),
        }
    }

    /// The transmittance at the centres of the grid voxels `voxels` (grid indices of full voxels
    /// or their neighbours), rounded as [`Self::compute`]'s grid stores it: the same values as
    /// that grid's there, marching only these voxels (the transport solve reads T at its full
    /// voxels alone, a fifth of the Disney cloud's box). A centre under `floor` (m: the ground's
    /// height, under which the transport solve's cells hold the light at the plane) is taken at
    /// that height.
    pub fn at_voxels(m: &Medium, sun_dir: Vec3, voxels: &[usize], floor: Option<f32>) -> Vec<f32> {
        let (lo, hi) = m.active_box(1).unwrap_or(([0; 3], [0; 3]));
        let rho = m.density.box_copy(lo, hi);
        let [nx, ny, _] = m.dims();
        // A march per voxel: a few hundred voxels per task.
        par::map_items(voxels.len(), 256, &|n| {
            let v = voxels[n];
            let mut p = m.voxel_center(v % nx, (v / nx) % ny, v / (nx * ny));
            p.y = floor.map_or(p.y, |f| p.y.max(f));
            Unit16::from_f32(transmittance(m, &rho, p, sun_dir, TAU_UNIT16)).to_f32()
        })
    }

    /// Refuse a transmittance that was non-finite at some voxel centre (before its 16-bit code
    /// clamped it): an error naming the stage `sun transmittance`.
    pub fn check_finite(&self) -> crate::error::Result<()> {
        let bad = self.non_finite.map(f32::from_bits);
        crate::error::check_finite_field("sun transmittance", "T_sun at the voxel centres", bad)
    }

    /// Interpolated transmittance at a point inside the medium's box.
    #[inline]
    pub fn at_voxel(&self, v: Vec3) -> f32 {
        self.grid.trilinear(v.to_array())
    }
}

/// Optical depth beyond which exp(−τ) is below [`crate::half::UNIT16_MIN`] = 2⁻³¹ = e^{−21.49}, which a
/// [`Unit16`] holds as 2⁻³¹ whatever the value: a march that only stores it stops there.
const TAU_UNIT16: f64 = 22.0;

/// exp(−τ) from `o` along unit `d` to the medium's box (all of it), as [`Medium::transmittance`],
/// the march stopped once τ ≥ `tau_cut` (then exp(−τ) ≤ e^{−tau_cut}); `rho` holds the medium's
/// density on a box around all of its full voxels.
fn transmittance(m: &Medium, rho: &SubGrid, o: Vec3, d: Vec3, tau_cut: f64) -> f32 {
    let sigma_t = m.optics.sigma_t as f64;
    let Some((t0, t1)) = m.intersect(o, d, 0.0, f32::INFINITY) else {
        return 1.0;
    };
    let (od, dd) = (o.as_dvec3(), d.as_dvec3());
    let h = m.voxel_size.as_dvec3();
    let orig = m.origin.as_dvec3();
    let dims = m.dims();
    let limit = tau_cut / sigma_t;
    let mut sum = 0.0;
    // Simpson over the dual cells crossed in [ta, tb]; false once exp(−τ) is 0.
    let mut walk = |ta: f64, tb: f64| {
        let mut r0 = None;
        // Dual cell c spans the voxel centres c − 1 and c (clamped to the grid, as the trilinear
        // field is), voxel coordinates [c − ½, c + ½].
        for s in m.dual_dda(o, d, ta, tb) {
            let c = s.cell;
            let lo: [usize; 3] = std::array::from_fn(|a| c[a].saturating_sub(1).min(dims[a] - 1));
            let hi: [usize; 3] = std::array::from_fn(|a| c[a].min(dims[a] - 1));
            let c8 = rho.corner_values(lo, hi);
            let v: [f64; 8] = std::array::from_fn(|n| c8[n] as f64);
            let corner = DVec3::new(c[0] as f64 - 0.5, c[1] as f64 - 0.5, c[2] as f64 - 0.5);
            let rho_at = |t: f64| {
                let f = (((od + dd * t) - orig) / h - corner).clamp(DVec3::ZERO, DVec3::ONE);
                let x0 = v[0] + (v[1] - v[0]) * f.x;
                let x1 = v[2] + (v[3] - v[2]) * f.x;
                let x2 = v[4] + (v[5] - v[4]) * f.x;
                let x3 = v[6] + (v[7] - v[6]) * f.x;
                let y0 = x0 + (x1 - x0) * f.y;
                let y1 = x2 + (x3 - x2) * f.y;
                y0 + (y1 - y0) * f.z
            };
            let ra = r0.unwrap_or_else(|| rho_at(s.t0));
            let rm = rho_at(0.5 * (s.t0 + s.t1));
            let rb = rho_at(s.t1);
            sum += (s.t1 - s.t0) / 6.0 * (ra + 4.0 * rm + rb);
            if sum >= limit {
                return false;
            }
            r0 = Some(rb);
        }
        true
    };
    // Runs of consecutive non-empty majorant blocks, each walked with one DDA.
    let mut run: Option<(f64, f64)> = None;
    let mut going = true;
    m.majorant.for_each_block(m, o, d, t0, t1, |ta, tb, maj| {
        let (ta, tb) = (ta as f64, tb as f64);
        if maj > 0.0 {
            run = Some(run.map_or((ta, tb), |r| (r.0, tb)));
            return true;
        }
        if let Some((a, b)) = run.take() {
            going = walk(a, b);
        }
        going
    });
    if let (true, Some((a, b))) = (going, run) {
        walk(a, b);
    }
    (-((sigma_t * sum) as f32)).exp()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Rgb, Rng};
    use crate::medium::{Grid3, TAU_ZERO};

    /// ρ on the medium's grown active box, as `compute` marches it.
    fn box_of(m: &Medium) -> SubGrid {
        let (lo, hi) = m.active_box(1).unwrap_or(([0; 3], [0; 3]));
        m.density.box_copy(lo, hi)
    }

    /// The march against the medium's exact transmittance, on an irregular cloud of non-cubic
    /// voxels with empty gaps, from points inside, on the faces and outside, in many directions.
    #[test]
    fn transmittance_matches_the_medium_s() {
        let dims = [9, 7, 8];
        let mut rng = Rng::new(7, 2);
        let g = crate::medium::test_grids::random_cloud(dims, &mut rng, 0.6, 0.0, 3.0);
        let m = Medium::new(g, Vec3::new(-2.0, 1.0, 0.5), Vec3::new(1.0, 0.7, 1.3), 0.4, Rgb::ONE, 0.0);
        for n in 0..3000 {
            let p = m.origin + m.voxel_size * Vec3::new(rng.uniform() * 11.0 - 1.0, rng.uniform() * 9.0 - 1.0, rng.uniform() * 10.0 - 1.0);
            let d = crate::math::uniform_sphere(rng.uniform(), rng.uniform());
            let (got, want) = (transmittance(&m, &box_of(&m), p, d, TAU_ZERO), m.transmittance(p, d, 0.0, f32::INFINITY));
            assert!((got - want).abs() <= 2e-6 * want + 1e-30, "{n}: {got} vs {want}");
        }
    }

    /// At the full voxels, the values the whole grid stores there.
    #[test]
    fn at_voxels_reads_what_the_grid_stores() {
        let mut rng = Rng::new(11, 3);
        let g = crate::medium::test_grids::random_cloud([9, 7, 8], &mut rng, 0.6, 0.0, 3.0);
        let m = Medium::new(g, Vec3::new(-2.0, 1.0, 0.5), Vec3::new(1.0, 0.7, 1.3), 0.4, Rgb::ONE, 0.0);
        let dir = Vec3::new(0.3, 0.8, -0.5).normalize();
        let grid = SunTransmittance::compute(&m, dir).grid;
        let voxels: Vec<usize> = (0..m.density.len()).filter(|v| m.density.at(*v) > 0.0).collect();
        let at = SunTransmittance::at_voxels(&m, dir, &voxels, None);
        assert!(at.iter().any(|t| *t < 0.9), "some voxel in shadow");
        for (v, t) in voxels.iter().zip(&at) {
            assert_eq!(t.to_bits(), grid.at_index(*v).to_bits(), "voxel {v}");
        }
    }

    /// Optically deep rays stop early and read 0, as exp(−τ) does in f32.
    #[test]
    fn deep_rays_read_zero() {
        let m = Medium::new(Grid3::filled([4, 4, 40], 1.0), Vec3::ZERO, Vec3::ONE, 5.0, Rgb::ONE, 0.0);
        let p = Vec3::new(2.0, 2.0, 0.5);
        assert_eq!(transmittance(&m, &box_of(&m), p, Vec3::Z, TAU_ZERO), 0.0);
        assert_eq!(m.transmittance(p, Vec3::Z, 0.0, f32::INFINITY), 0.0);
        let q = Vec3::new(2.0, 2.0, 39.0);
        let exact = (-5.0f32).exp();
        assert!((transmittance(&m, &box_of(&m), q, Vec3::Z, TAU_ZERO) - exact).abs() < 1e-6 * exact);
    }
}
