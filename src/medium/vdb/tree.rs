//! The sparse tree: root table (tiles and children), internal nodes (child mask, value mask,
//! tile values) and leaves (value mask, values), read in OpenVDB's two passes — topology, then
//! leaf buffers. Only what a density needs is kept: active tiles at every level (root included)
//! and, per leaf, its active mask and active values.

use super::bytes::Cursor;
use super::codec::{read_node_values, ValueType};
use crate::error::Result;
use std::collections::HashMap;

/// An active tile: a constant cube of `dim`³ voxels.
#[derive(Clone, Debug, PartialEq)]
pub struct Tile {
    /// Minimum index corner.
    pub origin: [i64; 3],
    /// Edge length in voxels.
    pub dim: i64,
    /// The value of every voxel it covers.
    pub value: f64,
}

/// A leaf node: `dim`³ voxels, of which those set in `mask` are active.
#[derive(Clone, Debug, PartialEq)]
pub struct Leaf {
    /// Minimum index corner.
    pub origin: [i64; 3],
    /// Active-voxel bits, offset n = (x·dim + y)·dim + z (z fastest, as OpenVDB).
    pub mask: Vec<u64>,
    /// Values of the active voxels in offset order (empty for vector grids).
    pub values: Vec<f32>,
}

/// A grid's tree, reduced to its active content.
#[derive(Clone, Debug)]
pub struct SparseTree {
    /// log2 of the node edge per level below the root, e.g. [5, 4, 3].
    pub log2: Vec<u32>,
    /// Background value.
    pub background: f64,
    /// Active tiles (root, internal).
    pub tiles: Vec<Tile>,
    /// Leaves in file order.
    pub leaves: Vec<Leaf>,
    /// Active voxels, tiles expanded (saturating).
    pub active_voxels: u64,
    /// Sum of active values, each tile counted once per voxel (None for vector grids).
    pub sum: Option<f64>,
    /// Inclusive index bounding box of the active voxels (None if there are none).
    pub bbox: Option<([i64; 3], [i64; 3])>,
    leaf_index: HashMap<[i64; 3], usize>,
}

impl SparseTree {
    /// Leaf edge in voxels.
    pub fn leaf_dim(&self) -> i64 {
        1 << self.log2.last().copied().unwrap_or(0)
    }

    /// The active value at index `ijk`, or None if that voxel is inactive.
    pub fn active_value(&self, ijk: [i64; 3]) -> Option<f64> {
        let d = self.leaf_dim();
        let o = [ijk[0].div_euclid(d) * d, ijk[1].div_euclid(d) * d, ijk[2].div_euclid(d) * d];
        if let Some(&li) = self.leaf_index.get(&o) {
            let leaf = &self.leaves[li];
            let n = (((ijk[0] - o[0]) * d + (ijk[1] - o[1])) * d + (ijk[2] - o[2])) as usize;
            if leaf.mask[n / 64] >> (n % 64) & 1 == 1 {
                let rank = leaf.mask[..n / 64].iter().map(|w| w.count_ones()).sum::<u32>()
                    + (leaf.mask[n / 64] & ((1u64 << (n % 64)) - 1)).count_ones();
                return leaf.values.get(rank as usize).map(|&v| v as f64);
            }
        }
        self.tiles
            .iter()
            .find(|t| (0..3).all(|a| ijk[a] >= t.origin[a] && ijk[a] < t.origin[a] + t.dim))
            .map(|t| t.value)
    }
}

/// Bits set in a mask.
pub(crate) fn set_bits(mask: &[u64]) -> impl Iterator<Item = usize> + '_ {
    mask.iter().enumerate().flat_map(|(w, &word)| {
        let mut bits = word;
        std::iter::from_fn(move || {
            if bits == 0 {
                return None;
            }
            let i = w * 64 + bits.trailing_zeros() as usize;
            bits &= bits - 1;
            Some(i)
        })
    })
}

fn read_mask(c: &mut Cursor, n_bits: usize, what: &str) -> Result<Vec<u64>> {
    let b = c.take(n_bits / 8, what)?;
    Ok(b.chunks_exact(8)
        .map(|w| u64::from_le_bytes(w.try_into().expect("8 bytes")))
        .collect())
}

/// Local coordinates of offset `n` in a node of edge 2^`l` (z fastest).
fn local(n: usize, l: u32) -> [i64; 3] {
    let m = (1usize << l) - 1;
    [(n >> (2 * l)) as i64, ((n >> l) & m) as i64, (n & m) as i64]
}

struct Reader<'r> {
    vt: &'r ValueType,
    half: bool,
    compression: u32,
    log2: &'r [u32],
    tiles: Vec<Tile>,
    leaves: Vec<Leaf>,
}

impl Reader<'_> {
    /// Edge (voxels) of a node at `level` (0 = the root's children).
    fn dim(&self, level: usize) -> i64 {
        1i64 << self.log2[level..].iter().sum::<u32>()
    }

    fn internal_topology(&mut self, c: &mut Cursor, level: usize, origin: [i64; 3]) -> Result<()> {
        let l = self.log2[level];
        let n = 1usize << (3 * l);
        let child_mask = read_mask(c, n, "internal node child mask")?;
        let value_mask = read_mask(c, n, "internal node value mask")?;
        let values = read_node_values(c, &value_mask, n, self.vt, self.half, self.compression, "internal node values")?;
        let child_dim = self.dim(level + 1);
        for (k, i) in set_bits(&value_mask).enumerate() {
            if child_mask[i / 64] >> (i % 64) & 1 == 1 {
                continue;
            }
            let p = local(i, l);
            self.tiles.push(Tile {
                origin: [
                    origin[0] + p[0] * child_dim,
                    origin[1] + p[1] * child_dim,
                    origin[2] + p[2] * child_dim,
                ],
                dim: child_dim,
                value: values.get(k).copied().unwrap_or(0.0),
            });
        }
        for i in set_bits(&child_mask) {
            let p = local(i, l);
            let o = [
                origin[0] + p[0] * child_dim,
                origin[1] + p[1] * child_dim,
                origin[2] + p[2] * child_dim,
            ];
            if level + 2 == self.log2.len() {
                let ln = 1usize << (3 * self.log2[level + 1]);
                let mask = read_mask(c, ln, "leaf value mask")?;
                self.leaves.push(Leaf {
                    origin: o,
                    mask,
                    values: Vec::new(),
                });
            } else {
                self.internal_topology(c, level + 1, o)?;
            }
        }
        Ok(())
    }
}

/// Parse a tree type name `Tree_<value>_<log2>_…`: the value token and the per-level log2 edges.
pub(crate) fn parse_tree_type(t: &str) -> Option<(String, Vec<u32>)> {
    let rest = t.strip_prefix("Tree_")?;
    let mut parts: Vec<&str> = rest.split('_').collect();
    let mut log2 = Vec::new();
    while let Some(last) = parts.last() {
        match last.parse::<u32>() {
            Ok(v) => {
                log2.push(v);
                parts.pop();
            }
            Err(_) => break,
        }
    }
    log2.reverse();
    if parts.is_empty() {
        return None;
    }
    Some((parts.join("_"), log2))
}

/// Read a tree's topology and buffers. `grid` names it in errors.
pub(crate) fn read_tree(c: &mut Cursor, vt: &ValueType, half: bool, compression: u32, log2: &[u32], grid: &str) -> Result<SparseTree> {
    if log2.len() < 2 || log2.len() > 4 || log2.iter().any(|&l| !(2..=6).contains(&l)) || log2.iter().sum::<u32>() > 24 {
        return Err(c.err(format!(
            "grid `{grid}`: tree configuration {log2:?} is not supported (2 to 4 node levels of 2² to 2⁶ per edge, as OpenVDB's 5-4-3)"
        )));
    }
    let buffers = c.i32("tree buffer count")?;
    if buffers != 1 {
        return Err(c.err(format!("grid `{grid}`: {buffers} buffers per leaf; only 1 is supported")));
    }
    let bg = c.take(vt.size, "background value")?;
    let background = vt.decode(bg, false);
    let num_tiles = c.u32("root tile count")? as usize;
    let num_children = c.u32("root child count")? as usize;
    let tile_bytes = 12 + vt.size + 1;
    if num_tiles.saturating_mul(tile_bytes).saturating_add(num_children.saturating_mul(12)) > c.remaining() {
        return Err(c.err(format!(
            "grid `{grid}`: the root declares {num_tiles} tiles and {num_children} children, more than the file can hold"
        )));
    }
    let mut r = Reader {
        vt,
        half,
        compression,
        log2,
        tiles: Vec::new(),
        leaves: Vec::new(),
    };
    let top = r.dim(0);
    for _ in 0..num_tiles {
        let o = c.vec3i("root tile origin")?;
        let v = vt.decode(c.take(vt.size, "root tile value")?, false);
        let active = c.u8("root tile active flag")? != 0;
        if active {
            r.tiles.push(Tile {
                origin: o.map(i64::from),
                dim: top,
                value: v,
            });
        }
    }
    let mut origins: Vec<[i64; 3]> = r.tiles.iter().map(|t| t.origin).collect();
    origins.sort_unstable();
    if origins.windows(2).any(|w| w[0] == w[1]) {
        return Err(c.err(format!("grid `{grid}`: two root tiles share an origin")));
    }
    // (root child origin, range of its leaves) in file order.
    let mut children: Vec<([i64; 3], std::ops::Range<usize>)> = Vec::new();
    for _ in 0..num_children {
        let o = c.vec3i("root child origin")?.map(i64::from);
        if o.iter().any(|v| v.rem_euclid(top) != 0) {
            return Err(c.err(format!(
                "grid `{grid}`: root child origin {o:?} is not a multiple of the node size {top}"
            )));
        }
        let start = r.leaves.len();
        r.internal_topology(c, 0, o)?;
        children.push((o, start..r.leaves.len()));
    }
    // Buffers are read in the root table's order (sorted by origin), as OpenVDB does.
    children.sort_by_key(|(o, _)| *o);
    if children.windows(2).any(|w| w[0].0 == w[1].0) {
        return Err(c.err(format!("grid `{grid}`: two root children share an origin")));
    }
    let leaf_bits = 1usize << (3 * log2[log2.len() - 1]);
    let mut leaves = std::mem::take(&mut r.leaves);
    let mut leaf_sum = 0.0f64;
    for (_, range) in &children {
        for leaf in &mut leaves[range.clone()] {
            c.skip(leaf_bits / 8, "leaf value mask")?;
            let v = read_node_values(c, &leaf.mask, leaf_bits, vt, half, compression, "leaf values")?;
            leaf.values = v.iter().map(|&x| x as f32).collect();
            // Sums use the full-precision values (exact for double grids too).
            leaf_sum += v.iter().sum::<f64>();
        }
    }
    let tiles = r.tiles;
    let mut active: u64 = 0;
    let mut sum = 0.0f64;
    let mut lo = [i64::MAX; 3];
    let mut hi = [i64::MIN; 3];
    for t in &tiles {
        let n = (t.dim as u64).saturating_pow(3);
        active = active.saturating_add(n);
        sum += t.value * n as f64;
        for a in 0..3 {
            lo[a] = lo[a].min(t.origin[a]);
            hi[a] = hi[a].max(t.origin[a] + t.dim - 1);
        }
    }
    let ll = log2[log2.len() - 1];
    for leaf in &leaves {
        for i in set_bits(&leaf.mask) {
            let p = local(i, ll);
            for a in 0..3 {
                lo[a] = lo[a].min(leaf.origin[a] + p[a]);
                hi[a] = hi[a].max(leaf.origin[a] + p[a]);
            }
        }
        active = active.saturating_add(leaf.mask.iter().map(|w| w.count_ones() as u64).sum());
    }
    sum += leaf_sum;
    let leaf_index = leaves.iter().enumerate().map(|(i, l)| (l.origin, i)).collect();
    Ok(SparseTree {
        log2: log2.to_vec(),
        background,
        tiles,
        leaves,
        active_voxels: active,
        sum: vt.is_scalar().then_some(sum),
        bbox: (active > 0).then_some((lo, hi)),
        leaf_index,
    })
}
