//! Transmittance of the direct sun through the cloud, precomputed at voxel centres.
//!
//! The paper keeps the reduced sun radiance I_risun per voxel; here each voxel centre near the
//! cloud gets the exact optical depth towards the sun (Simpson on the trilinear field), and the
//! gather interpolates it trilinearly. Voxels whose 3×3×3 neighbourhood is empty are never
//! sampled by a scattering point and are skipped.

use crate::math::Vec3;
use crate::medium::{Grid3, Medium};
use rayon::prelude::*;
use std::sync::Arc;

/// exp(−τ_sun) at voxel centres.
#[derive(Clone, Debug)]
pub struct SunTransmittance {
    /// Transmittance towards the sun at each voxel centre (unitless).
    pub grid: Arc<Grid3>,
    /// Unit direction towards the sun.
    pub dir: Vec3,
}

impl SunTransmittance {
    /// Compute for every voxel within one voxel of non-zero density.
    pub fn compute(m: &Medium, sun_dir: Vec3) -> Self {
        let d = m.dims();
        let rho = &m.density;
        let mut grid = Grid3::filled(d, 1.0);
        let (nx, ny) = (d[0], d[1]);
        grid.data_mut().par_chunks_mut(nx * ny).enumerate().for_each(|(k, slab)| {
            for j in 0..ny {
                for i in 0..nx {
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
                        slab[i + nx * j] = m.transmittance(p, sun_dir, 0.0, f32::INFINITY);
                    }
                }
            }
        });
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
