//! The trilinear interpolation of `--method transport`'s gather over the cloud's edge: over the
//! full voxels and the shell of empty voxels beside them (src/transport/shell.rs), whose source
//! the solve gives too. The quantity interpolated is the source per unit (scaled) optical depth,
//! J: the radiance is continuous across the edge, so J is; ρ·J is not (it falls to 0 with ρ).

use crate::math::{Rgb, Vec3};
use crate::medium::sparse::FullIndex;
use crate::transport::shell::Shell;

/// A corner of the gather's trilinear cell: a full voxel (its index in the [`FullIndex`]) or a
/// shell voxel (its index in [`Shell`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Corner {
    Full(usize),
    Shell(usize),
}

/// The trilinear mean of `value(corner)` over the full and shell voxels among the eight around
/// continuous voxel coordinates `v` (grid `dims`), their weights renormalised (zero where none
/// is either: the grid's faces).
#[inline]
pub fn edge_weighted(dims: [usize; 3], full: &FullIndex, shell: &Shell, v: Vec3, mut value: impl FnMut(Corner) -> Rgb) -> Rgb {
    let u = v - Vec3::splat(0.5);
    let b = u.floor();
    let t = u - b;
    let (mut sum, mut wsum) = (Rgb::ZERO, 0.0f32);
    for dz in 0..2 {
        for dy in 0..2 {
            for dx in 0..2 {
                let c = [b.x as i64 + dx, b.y as i64 + dy, b.z as i64 + dz];
                if (0..3).any(|a| c[a] < 0 || c[a] >= dims[a] as i64) {
                    continue;
                }
                let idx = c[0] as usize + dims[0] * (c[1] as usize + dims[1] * c[2] as usize);
                let corner = match full.slot(idx).checked_sub(1) {
                    Some(fi) => Corner::Full(fi),
                    None => match shell.slot(idx).checked_sub(1) {
                        Some(si) => Corner::Shell(si),
                        None => continue,
                    },
                };
                let w = (if dx == 1 { t.x } else { 1.0 - t.x })
                    * (if dy == 1 { t.y } else { 1.0 - t.y })
                    * (if dz == 1 { t.z } else { 1.0 - t.z });
                sum += value(corner) * w;
                wsum += w;
            }
        }
    }
    if wsum > 0.0 {
        sum / wsum
    } else {
        Rgb::ZERO
    }
}
