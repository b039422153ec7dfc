//! OpenVDB (`.vdb`) input, written from the file format rather than with the vdb-rs crate (see
//! docs/vdb.md for why): header and metadata ([`header`]), transforms ([`transform`]), value
//! storage and compression ([`codec`]), the sparse tree ([`tree`]) and densification ([`dense`]).
//!
//! Supported: format versions 222–224 (OpenVDB 3 to 12); float, double and half-stored grids
//! (`_HalfFloat`); no compression, zip, blosc (LZ4, byte shuffle) and active-mask compression;
//! active tiles at every level including the root; several grids per file; instanced grids;
//! scale, non-uniform scale, translation and diagonal affine maps. Vector and integer grids
//! are listed by [`read_vdb_info`] but cannot be read as a density.

mod bytes;
pub mod codec;
mod dense;
mod header;
pub mod transform;
pub mod tree;

use crate::error::{Error, Result};
use crate::medium::Grid3;
use bytes::Cursor;
use codec::ValueType;
use header::{read_header, read_meta, GridDescriptor, Meta};
use serde::Serialize;
use std::path::Path;
pub use transform::Transform;
pub use tree::SparseTree;

/// What `cloudgi info` reports about one grid.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct VdbGridInfo {
    /// Grid name.
    pub name: String,
    /// Value type as OpenVDB names it (`float`, `double`, `vec3s`, …); half-stored floats are `float`.
    #[serde(rename = "type")]
    pub value_type: String,
    /// Active voxels, tiles expanded (null for value types this reader cannot parse).
    pub active_voxels: Option<u64>,
    /// Sum of active values, each tile counted once per voxel it covers (null for non-scalar grids).
    pub sum: Option<f64>,
    /// Inclusive index-space bounding box of the active voxels (null when empty or unknown).
    pub bbox_min: Option<[i64; 3]>,
    /// See `bbox_min`.
    pub bbox_max: Option<[i64; 3]>,
    /// Voxel size (world units per index step, per axis).
    pub voxel_size: [f64; 3],
    /// World position of index (0, 0, 0).
    pub translation: [f64; 3],
    /// Bytes a dense float32 grid over the bounding box would need (no downsampling).
    pub dense_bytes: u64,
    /// Values stored as 16-bit halves.
    #[serde(skip)]
    pub half: bool,
    /// OpenVDB map type of the transform.
    #[serde(skip)]
    pub map: &'static str,
    /// Grid class from the metadata (`fog volume`, `level set`, …), if any.
    #[serde(skip)]
    pub class: Option<String>,
}

/// One grid, read: its transform and its sparse tree.
#[derive(Clone, Debug)]
pub struct VdbGrid {
    /// Grid name.
    pub name: String,
    /// Value type token.
    pub value_type: String,
    /// Values stored as halves.
    pub half: bool,
    /// Index-to-world map.
    pub transform: Transform,
    /// The tree (None for value types this reader cannot parse).
    pub tree: Option<SparseTree>,
    /// Grid class, if the metadata names one.
    pub class: Option<String>,
}

/// A grid densified over its active bounding box.
#[derive(Clone, Debug)]
pub struct VdbDense {
    /// Values (x fastest); voxel (0, 0, 0) covers index `index_min` (a block of `downsample`³).
    pub grid: Grid3,
    /// World size of a dense voxel (file voxel size × downsample).
    pub voxel_size: [f64; 3],
    /// World position of the dense grid's minimum corner.
    pub origin: [f64; 3],
    /// Index of the first voxel of the active bounding box.
    pub index_min: [i64; 3],
}

/// A descriptor's data, bounded to its grid's byte range.
fn read_grid(bytes: &[u8], file: &str, d: &GridDescriptor, all: &[GridDescriptor], want_tree: bool) -> Result<VdbGrid> {
    let mut c = Cursor::new(&bytes[..d.end_pos as usize], file);
    c.seek(d.grid_pos, "the grid offset")?;
    let mut compression = if want_tree { c.u32("grid compression flags")? } else { 0 };
    if !want_tree {
        c.skip(4, "grid compression flags")?;
    }
    let meta = read_meta(&mut c)?;
    let class = meta.iter().find_map(|(k, v)| match (k.as_str(), v) {
        ("class", Meta::Str(s)) => Some(header::printable(s)),
        _ => None,
    });
    let transform = transform::read_transform(&mut c, &d.name)?;
    let Some((token, log2)) = tree::parse_tree_type(&d.tree_type) else {
        return Err(c.err(format!(
            "grid `{}`: grid type `{}` is not an OpenVDB tree type",
            d.name, d.tree_type
        )));
    };
    let vt = ValueType::from_token(&token);
    let mut grid = VdbGrid {
        name: d.name.clone(),
        value_type: token.clone(),
        half: d.half,
        transform,
        tree: None,
        class,
    };
    let Some(vt) = vt.filter(|_| want_tree) else {
        return Ok(grid);
    };
    // An instance shares its parent's tree: read the tree where the parent stores it.
    let mut pc;
    let cur = if d.instance_parent.is_empty() {
        &mut c
    } else {
        let parent = all
            .iter()
            .find(|p| p.unique_name == d.instance_parent && p.instance_parent.is_empty())
            .ok_or_else(|| {
                Error::format(
                    file,
                    format!(
                        "grid `{}` is an instance of `{}`, which is not in the file",
                        d.name, d.instance_parent
                    ),
                )
            })?;
        pc = Cursor::new(&bytes[..parent.end_pos as usize], file);
        pc.seek(parent.grid_pos, "the grid offset")?;
        compression = pc.u32("grid compression flags")?;
        read_meta(&mut pc)?;
        transform::read_transform(&mut pc, &parent.name)?;
        &mut pc
    };
    let t = tree::read_tree(cur, &vt, d.half, compression, &log2, &d.name).map_err(|e| with_grid(e, &d.name))?;
    grid.tree = Some(t);
    Ok(grid)
}

/// Prefix a format error with the grid name when it does not already say it.
fn with_grid(e: Error, grid: &str) -> Error {
    match e {
        Error::Format { file, message } if !message.contains('`') => Error::Format {
            file,
            message: format!("grid `{grid}`: {message}"),
        },
        e => e,
    }
}

/// Read every grid of a `.vdb` held in memory; `file` names it in errors.
pub fn read_vdb_grids_bytes(bytes: &[u8], file: &str) -> Result<Vec<VdbGrid>> {
    let mut c = Cursor::new(bytes, file);
    let h = read_header(&mut c)?;
    h.descriptors
        .iter()
        .map(|d| read_grid(bytes, file, d, &h.descriptors, true))
        .collect()
}

/// Read one grid of a `.vdb` held in memory: `grid_name`, or else `density`, or else the first
/// float, double or half grid; a grid of another type is refused.
pub fn read_vdb_grid_bytes(bytes: &[u8], file: &str, grid_name: Option<&str>) -> Result<VdbGrid> {
    let mut c = Cursor::new(bytes, file);
    let h = read_header(&mut c)?;
    let list = || {
        h.descriptors
            .iter()
            .map(|d| {
                let t = tree::parse_tree_type(&d.tree_type)
                    .map(|(t, _)| t)
                    .unwrap_or_else(|| d.tree_type.clone());
                format!("`{}` ({t})", d.name)
            })
            .collect::<Vec<_>>()
            .join(", ")
    };
    let scalar = |d: &&GridDescriptor| {
        tree::parse_tree_type(&d.tree_type)
            .and_then(|(t, _)| ValueType::from_token(&t))
            .is_some_and(|v| v.is_density())
    };
    let d = match grid_name {
        Some(n) => h.descriptors.iter().find(|d| d.name == n),
        None => h
            .descriptors
            .iter()
            .find(|d| d.name == "density")
            .or_else(|| h.descriptors.iter().find(scalar)),
    };
    let Some(d) = d else {
        return Err(Error::invalid(
            file,
            "medium.grid_name",
            match grid_name {
                Some(n) => format!(
                    "the file has no grid named `{n}`; it has: {}",
                    if h.descriptors.is_empty() { "no grids".into() } else { list() }
                ),
                None => format!("the file has no float, double or half grid; it has: {}", list()),
            },
        ));
    };
    let g = read_grid(bytes, file, d, &h.descriptors, true)?;
    match ValueType::from_token(&g.value_type) {
        Some(v) if v.is_density() => Ok(g),
        _ => Err(Error::invalid(
            file,
            "medium.grid_name",
            format!(
                "grid `{}` holds `{}` values; a density must be a scalar grid (float, double or half). The file has: {}",
                g.name,
                g.value_type,
                list()
            ),
        )),
    }
}

fn info_of(g: &VdbGrid) -> VdbGridInfo {
    let t = g.tree.as_ref();
    let bbox = t.and_then(|t| t.bbox);
    let dense = bbox.map_or(0u128, |(lo, hi)| (0..3).map(|a| (hi[a] - lo[a] + 1) as u128).product::<u128>() * 4);
    VdbGridInfo {
        name: g.name.clone(),
        value_type: g.value_type.clone(),
        active_voxels: t.map(|t| t.active_voxels),
        sum: t.and_then(|t| t.sum),
        bbox_min: bbox.map(|b| b.0),
        bbox_max: bbox.map(|b| b.1),
        voxel_size: g.transform.scale,
        translation: g.transform.translation,
        dense_bytes: u64::try_from(dense).unwrap_or(u64::MAX),
        half: g.half,
        map: g.transform.map,
        class: g.class.clone(),
    }
}

/// Describe every grid of a `.vdb` held in memory.
pub fn read_vdb_info_bytes(bytes: &[u8], file: &str) -> Result<Vec<VdbGridInfo>> {
    Ok(read_vdb_grids_bytes(bytes, file)?.iter().map(info_of).collect())
}

/// Describe every grid of a `.vdb` file.
pub fn read_vdb_info(path: &Path) -> Result<Vec<VdbGridInfo>> {
    let bytes = crate::io::read_regular(path, "an OpenVDB file")?;
    read_vdb_info_bytes(&bytes, &path.display().to_string())
}

/// Densify one grid of a `.vdb` held in memory (see [`read_vdb_dense`]).
pub fn read_vdb_dense_bytes(bytes: &[u8], file: &str, grid_name: Option<&str>, max_voxels: u64, downsample: usize) -> Result<VdbDense> {
    let g = read_vdb_grid_bytes(bytes, file, grid_name)?;
    let tree = g.tree.as_ref().expect("scalar grids are read");
    let n = downsample.max(1);
    let grid = dense::densify(tree, file, &g.name, max_voxels, n)?;
    let (lo, _) = tree.bbox.expect("densify refuses empty grids");
    let corner = g
        .transform
        .index_to_world([lo[0] as f64 - 0.5, lo[1] as f64 - 0.5, lo[2] as f64 - 0.5]);
    Ok(VdbDense {
        grid,
        voxel_size: g.transform.scale.map(|s| s * n as f64),
        origin: corner,
        index_min: lo,
    })
}
