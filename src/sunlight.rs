//! Transmittance of the direct sun through the cloud, precomputed at voxel centres.
//!
//! The paper keeps the reduced sun radiance I_risun per voxel; here each voxel centre near the
//! cloud gets the exact optical depth towards the sun (Simpson on the trilinear field), and the
//! gather interpolates it trilinearly. Voxels whose 3×3×3 neighbourhood is empty are never
//! sampled by a scattering point and are skipped (they read 1); they include every voxel beyond
//! one voxel of the full voxels' box, so only that box is stored ([`SubGrid`]).

use crate::incident::active_box;
use crate::math::Vec3;
use crate::medium::{Medium, SubGrid};
use rayon::prelude::*;
use std::sync::Arc;

/// exp(−τ_sun) at voxel centres.
#[derive(Clone, Debug)]
pub struct SunTransmittance {
    /// Transmittance towards the sun at each voxel centre (unitless), stored on the full voxels'
    /// box grown by one voxel; 1 elsewhere.
    pub grid: Arc<SubGrid>,
    /// Unit direction towards the sun.
    pub dir: Vec3,
}

impl SunTransmittance {
    /// Compute for every voxel within one voxel of non-zero density.
    pub fn compute(m: &Medium, sun_dir: Vec3) -> Self {
        let d = m.dims();
        let rho = &m.density;
        let (lo, hi) = active_box(m, 1).unwrap_or(([0; 3], [0; 3]));
        let mut grid = SubGrid::filled(d, lo, hi, 1.0, 1.0);
        let (_, [nx, ny, _]) = grid.bounds();
        if nx * ny > 0 {
            grid.box_values_mut().par_chunks_mut(nx * ny).enumerate().for_each(|(k, slab)| {
                let k = k + lo[2];
                for j in 0..ny {
                    for i in 0..nx {
                        let (i, j) = (i + lo[0], j + lo[1]);
                        let mut near = false;
                        'n: for dk in -1..=1isize {
                            for dj in -1..=1isize {
                                for di in -1..=1isize {
                                    if rho.get_or_zero(i as isize + di, j as isize + dj, k as isize + dk) > 0.0 {
                                        near = true;
                                        break 'n;
                                    }
                                }
                            }
                        }
                        if near {
                            let p = m.voxel_center(i, j, k);
                            slab[i - lo[0] + nx * (j - lo[1])] = m.transmittance(p, sun_dir, 0.0, f32::INFINITY);
                        }
                    }
                }
            });
        }
        SunTransmittance {
            grid: Arc::new(grid),
            dir: sun_dir,
        }
    }

    /// Interpolated transmittance at a point inside the medium's box.
    #[inline]
    pub fn at_voxel(&self, v: Vec3) -> f32 {
        self.grid.trilinear(v.to_array())
    }
}
