//! Density grids that unit tests of several stages share (cubes, the incident sweep, the sun
//! march): made here, below those stages, so that their tests need nothing above them.

use super::Grid3;
use crate::math::{Rng, Vec3};

/// Two smooth lobes of density (peak 1) centred in a `dims` grid with a gap of clear air between
/// them, so that some viewing cubes look across clear air at cloud.
pub(crate) fn two_lobes(dims: [usize; 3], radius: f32) -> Grid3 {
    let mut g = Grid3::filled(dims, 0.0);
    let c = Vec3::new(dims[0] as f32, dims[1] as f32, dims[2] as f32) * 0.5;
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let p = Vec3::new(i as f32 + 0.5, j as f32 + 0.5, k as f32 + 0.5);
                let a = (p - c - Vec3::new(radius, 0.0, 0.0)).length() / radius;
                let b = (p - c + Vec3::new(radius * 1.2, 0.0, 0.0)).length() / (0.8 * radius);
                g.set(i, j, k, (1.0 - a * a).max(0.0) + (1.0 - b * b).max(0.0));
            }
        }
    }
    g
}

/// An irregular cloud: each voxel of a `dims` grid full with probability `fill`, its density
/// `lo + span·u` (u uniform in [0, 1)), drawn from `rng` in grid order.
pub(crate) fn random_cloud(dims: [usize; 3], rng: &mut Rng, fill: f32, lo: f32, span: f32) -> Grid3 {
    let mut g = Grid3::filled(dims, 0.0);
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                if rng.uniform() < fill {
                    g.set(i, j, k, lo + span * rng.uniform());
                }
            }
        }
    }
    g
}
