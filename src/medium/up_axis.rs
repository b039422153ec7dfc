//! `medium.up_axis`: grids written z-up (Blender) turned into this program's y-up world.
//!
//! A z-up file's point (x, y, z) is the world's (x, z, −y): a rotation by −90° about x, the one
//! Blender's own y-up exporters (glTF, FBX "Y up") apply, so the file's −y (Blender's front view
//! looks along +y) faces the world's +z, where the default camera stands.

use super::Grid3;
use crate::math::Vec3;
use serde::{Deserialize, Serialize};

/// Which axis of the grid file points up.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum UpAxis {
    /// y up, as this program, Houdini and Maya (no change).
    #[default]
    Y,
    /// z up, as Blender and 3ds Max.
    Z,
}

/// A grid with its minimum corner and voxel size (m).
pub type Placed = (Grid3, Vec3, Vec3);

/// The grid `(grid, origin, voxel_size)` of a file whose up axis is `up`, in the y-up world.
pub fn to_y_up(up: UpAxis, (grid, origin, voxel): Placed) -> Placed {
    if up == UpAxis::Y {
        return (grid, origin, voxel);
    }
    let [nx, ny, nz] = grid.dims();
    // World voxel (i, j, k) is the file's (i, ny − 1 − k, j).
    let mut out = Grid3::filled([nx, nz, ny], 0.0);
    for k in 0..ny {
        for j in 0..nz {
            for i in 0..nx {
                out.set(i, j, k, grid.get(i, ny - 1 - k, j));
            }
        }
    }
    let far_y = origin.y + voxel.y * ny as f32;
    (out, Vec3::new(origin.x, origin.z, -far_y), Vec3::new(voxel.x, voxel.z, voxel.y))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_z_up_voxel_lands_where_the_rotation_takes_its_centre() {
        let mut g = Grid3::filled([2, 3, 4], 0.0);
        g.set(1, 2, 0, 5.0);
        let (origin, voxel) = (Vec3::new(1.0, 2.0, 3.0), Vec3::new(0.5, 1.0, 2.0));
        let centre = origin + voxel * Vec3::new(1.5, 2.5, 0.5);
        let (w, wo, wv) = to_y_up(UpAxis::Z, (g, origin, voxel));
        assert_eq!(w.dims(), [2, 4, 3]);
        let (i, j, k) = (0..24)
            .map(|n| (n % 2, (n / 2) % 4, n / 8))
            .find(|&(i, j, k)| w.get(i, j, k) == 5.0)
            .unwrap();
        let world = wo + wv * Vec3::new(i as f32 + 0.5, j as f32 + 0.5, k as f32 + 0.5);
        assert_eq!(world, Vec3::new(centre.x, centre.z, -centre.y));
    }
}
