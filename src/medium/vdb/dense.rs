//! Sparse tree → dense grid over the active bounding box, optionally averaging N×N×N blocks
//! on the fly (so a grid too large to densify can still be read downsampled), behind a
//! memory guard that is checked before anything is allocated.

use super::tree::{set_bits, SparseTree};
use crate::error::{Error, Result};
use crate::medium::Grid3;

/// Dense voxel count of `dims` downsampled by `n` (u128: never overflows).
fn count(dims: [u64; 3], n: u64) -> u128 {
    dims.iter().map(|&d| d.div_ceil(n) as u128).product()
}

/// Densify `tree` over its active bbox, averaging `n`³ blocks. Returns the grid (x fastest).
/// Refuses (before allocating) when the result would exceed `max_voxels`.
pub(crate) fn densify(tree: &SparseTree, file: &str, grid: &str, max_voxels: u64, n: usize) -> Result<Grid3> {
    let Some((lo, hi)) = tree.bbox else {
        return Err(Error::format(
            file,
            format!("grid `{grid}` has no active voxels: there is nothing to render"),
        ));
    };
    let full = [0, 1, 2].map(|a| (hi[a] - lo[a] + 1) as u64);
    let n64 = n.max(1) as u64;
    let want = count(full, n64);
    if want > max_voxels as u128 {
        let suggestion = (n.max(1) + 1..=64)
            .find(|&k| count(full, k as u64) <= max_voxels as u128)
            .map(|k| {
                let d = full.map(|v| v.div_ceil(k as u64));
                format!(
                    "set medium.downsample = {k} (→ {}×{}×{} voxels) or raise medium.max_voxels",
                    d[0], d[1], d[2]
                )
            })
            .unwrap_or_else(|| {
                format!(
                    "even medium.downsample = 64 gives {} voxels; raise medium.max_voxels",
                    count(full, 64)
                )
            });
        let d = full.map(|v| v.div_ceil(n64));
        return Err(Error::invalid(
            file,
            "medium.max_voxels",
            format!(
                "grid `{grid}`: its active bounding box {lo:?}..{hi:?} is {}×{}×{} voxels{}, so the dense grid would have \
                 {}×{}×{} = {want} voxels ({} as float32), more than max_voxels = {max_voxels}; {suggestion}",
                full[0],
                full[1],
                full[2],
                if n > 1 { format!(" (downsampled by {n})") } else { String::new() },
                d[0],
                d[1],
                d[2],
                crate::io::format_bytes(want * 4),
            ),
        ));
    }
    let dims = full.map(|v| v.div_ceil(n64) as usize);
    let total = dims[0] * dims[1] * dims[2];
    let idx = |p: [i64; 3]| -> usize {
        let q = [0, 1, 2].map(|a| ((p[a] - lo[a]) as u64 / n64) as usize);
        q[0] + dims[0] * (q[1] + dims[1] * q[2])
    };
    let ll = *tree.log2.last().expect("levels");
    let m = (1usize << ll) - 1;
    let leaf_local = |i: usize| [(i >> (2 * ll)) as i64, ((i >> ll) & m) as i64, (i & m) as i64];
    if n <= 1 {
        let mut data = vec![0f32; total];
        for t in &tree.tiles {
            let v = t.value as f32;
            for z in t.origin[2]..t.origin[2] + t.dim {
                for y in t.origin[1]..t.origin[1] + t.dim {
                    let row = idx([t.origin[0], y, z]);
                    data[row..row + t.dim as usize].fill(v);
                }
            }
        }
        for leaf in &tree.leaves {
            for (k, i) in set_bits(&leaf.mask).enumerate() {
                let p = leaf_local(i);
                data[idx([leaf.origin[0] + p[0], leaf.origin[1] + p[1], leaf.origin[2] + p[2]])] =
                    leaf.values.get(k).copied().unwrap_or(0.0);
            }
        }
        return Grid3::from_vec(dims, data, file);
    }
    // Block sums in f64, then divide by the voxels each block holds (partial blocks at the far
    // edges average what they hold, as Grid3::downsample does).
    let mut sums = vec![0f64; total];
    for t in &tree.tiles {
        // Per axis: the output cells the tile overlaps and by how many voxels.
        let spans = [0, 1, 2].map(|a| {
            let (a0, a1) = ((t.origin[a] - lo[a]) as u64, (t.origin[a] + t.dim - lo[a]) as u64);
            (a0 / n64..a1.div_ceil(n64))
                .map(|b| (b as usize, ((b + 1) * n64).min(a1) - (b * n64).max(a0)))
                .collect::<Vec<_>>()
        });
        for &(bz, wz) in &spans[2] {
            for &(by, wy) in &spans[1] {
                for &(bx, wx) in &spans[0] {
                    sums[bx + dims[0] * (by + dims[1] * bz)] += t.value * (wx * wy * wz) as f64;
                }
            }
        }
    }
    for leaf in &tree.leaves {
        for (k, i) in set_bits(&leaf.mask).enumerate() {
            let p = leaf_local(i);
            sums[idx([leaf.origin[0] + p[0], leaf.origin[1] + p[1], leaf.origin[2] + p[2]])] +=
                leaf.values.get(k).copied().unwrap_or(0.0) as f64;
        }
    }
    let held = |a: usize, b: usize| -> f64 { (((b as u64 + 1) * n64).min(full[a]) - b as u64 * n64) as f64 };
    let mut data = vec![0f32; total];
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            let cyz = held(1, y) * held(2, z);
            for x in 0..dims[0] {
                let i = x + dims[0] * (y + dims[1] * z);
                data[i] = (sums[i] / (held(0, x) * cyz)) as f32;
            }
        }
    }
    Grid3::from_vec(dims, data, file)
}
