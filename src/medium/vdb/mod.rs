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
#[cfg(test)]
pub(crate) mod test_file;

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
    /// The grid has no active voxels (`grid` is then one voxel of density 0).
    pub empty: bool,
    /// The name of the grid read (empty for a file with no grids).
    pub grid_name: String,
    /// What the user should be told: the grid read when the file has no `density`, an empty grid.
    pub notes: Vec<String>,
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

/// The grid a density is read from when the scene names none (`medium.grid_name`'s default).
pub const DEFAULT_GRID: &str = "density";

/// A grid's class as OpenVDB writes it for signed distance fields.
const LEVEL_SET: &str = "level set";

/// Read one grid of a `.vdb` held in memory for a density: `grid_name` (None: [`DEFAULT_GRID`]).
/// A file without a grid of the default name gives its only float, double or half grid (not a
/// level set), with a note naming it; with several such grids it is an error listing them. A
/// grid of another type, or a level set, is refused. Returns the grid and the note, if any.
pub fn read_vdb_grid_bytes(bytes: &[u8], file: &str, grid_name: Option<&str>) -> Result<(VdbGrid, Option<String>)> {
    let mut c = Cursor::new(bytes, file);
    let h = read_header(&mut c)?;
    let type_of = |d: &GridDescriptor| {
        tree::parse_tree_type(&d.tree_type)
            .map(|(t, _)| t)
            .unwrap_or_else(|| d.tree_type.clone())
    };
    let list = |ds: &[&GridDescriptor]| ds.iter().map(|d| format!("`{}` ({})", d.name, type_of(d))).collect::<Vec<_>>().join(", ");
    let all: Vec<&GridDescriptor> = h.descriptors.iter().collect();
    let held = if all.is_empty() { "no grids".to_string() } else { list(&all) };
    let refuse = |why: String| Err(Error::invalid(file, "medium.grid_name", why));
    let wanted = grid_name.unwrap_or(DEFAULT_GRID);
    let mut note = None;
    let d = match all.iter().find(|d| d.name == wanted) {
        Some(d) => *d,
        None if wanted != DEFAULT_GRID => return refuse(format!("the file has no grid named `{wanted}`; it has: {held}")),
        None => {
            // Candidates: scalar real grids that are not level sets (their class is in the grid's
            // own metadata, read without the tree).
            let mut fog: Vec<&GridDescriptor> = Vec::new();
            for d in &all {
                let density = ValueType::from_token(&type_of(d)).is_some_and(|v| v.is_density());
                if density && read_grid(bytes, file, d, &h.descriptors, false)?.class.as_deref() != Some(LEVEL_SET) {
                    fog.push(*d);
                }
            }
            let fix = format!(
                "choose one with medium.grid_name (`cloudgi render {} --grid-name NAME`, or in a scene file `[medium]` `grid = \"{}\"` `grid_name = \"NAME\"`)",
                file_name(file),
                file_name(file)
            );
            match fog.as_slice() {
                [only] => {
                    note = Some(format!(
                        "{file}: the file has no grid named `{DEFAULT_GRID}`; reading its only float grid, `{}` ({}: to read another grid, {fix})",
                        only.name,
                        if all.len() == 1 { "the file's only grid".to_string() } else { format!("the file has {held}") },
                    ));
                    *only
                }
                [] => {
                    return refuse(format!(
                        "the file has no grid named `{DEFAULT_GRID}` and no float, double or half grid that is not a level set to read a density from; it has: {held}"
                    ))
                }
                several => {
                    return refuse(format!(
                        "the file has no grid named `{DEFAULT_GRID}` and {} float grids, {}: {fix}",
                        several.len(),
                        list(several)
                    ))
                }
            }
        }
    };
    let g = read_grid(bytes, file, d, &h.descriptors, true)?;
    if !ValueType::from_token(&g.value_type).is_some_and(|v| v.is_density()) {
        return refuse(format!(
            "grid `{}` holds `{}` values; a density must be a scalar grid (float, double or half). The file has: {held}",
            g.name, g.value_type
        ));
    }
    if g.class.as_deref() == Some(LEVEL_SET) {
        return refuse(format!(
            "grid `{}` is a level set (signed distances to a surface, negative inside), not a density; convert it \
             to a fog volume first (Houdini: Convert VDB to Fog Volume; OpenVDB: tools::sdfToFogVolume). The file has: {held}",
            g.name
        ));
    }
    Ok((g, note))
}

/// The last component of `file`, for messages that show a scene line.
fn file_name(file: &str) -> String {
    Path::new(file)
        .file_name()
        .map_or_else(|| file.to_string(), |n| n.to_string_lossy().into_owned())
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

/// Densify one grid of a `.vdb` held in memory (the grid [`read_vdb_grid_bytes`] chooses),
/// averaging `downsample`³ blocks, behind the `max_voxels` guard. A grid with no active voxels (a
/// simulation's frame before its cloud forms or after it is gone) gives one voxel of density 0 at
/// index (0, 0, 0), with a note: the scene renders without a cloud.
pub fn read_vdb_dense_bytes(bytes: &[u8], file: &str, grid_name: Option<&str>, max_voxels: u64, downsample: usize) -> Result<VdbDense> {
    // A file with no grids at all is what a cache writes for a frame with no volume (Houdini's
    // File Cache when nothing was emitted yet): an empty frame, when no grid was asked for by name.
    if grid_name.is_none_or(|n| n == DEFAULT_GRID) && read_header(&mut Cursor::new(bytes, file))?.descriptors.is_empty() {
        return Ok(VdbDense {
            grid: Grid3::filled([1, 1, 1], 0.0),
            voxel_size: [1.0; 3],
            origin: [-0.5; 3],
            index_min: [0; 3],
            empty: true,
            grid_name: String::new(),
            notes: vec![format!(
                "{file}: the file holds no grids (an empty frame, as a cache writes before a volume is emitted or \
                 after it is gone): rendering the scene without a cloud, sky and ground only"
            )],
        });
    }
    let (g, note) = read_vdb_grid_bytes(bytes, file, grid_name)?;
    let tree = g.tree.as_ref().expect("scalar grids are read");
    let n = downsample.max(1);
    let mut notes: Vec<String> = note.into_iter().collect();
    let (grid, lo) = match tree.bbox {
        Some((lo, _)) => (dense::densify(tree, file, &g.name, max_voxels, n)?, lo),
        None => {
            notes.push(format!(
                "{file}: grid `{}` has no active voxels (an empty frame, as a simulation writes before its cloud forms \
                 or after it is gone): rendering the scene without a cloud, sky and ground only",
                g.name
            ));
            (Grid3::filled([1, 1, 1], 0.0), [0; 3])
        }
    };
    let corner = g
        .transform
        .index_to_world([lo[0] as f64 - 0.5, lo[1] as f64 - 0.5, lo[2] as f64 - 0.5]);
    Ok(VdbDense {
        grid,
        voxel_size: g.transform.scale.map(|s| s * n as f64),
        origin: corner,
        index_min: lo,
        empty: tree.bbox.is_none(),
        grid_name: g.name.clone(),
        notes,
    })
}

#[cfg(test)]
mod tests {
    use super::test_file::{vdb_file, TestGrid};
    use super::*;

    fn dense(grids: &[TestGrid], name: Option<&str>) -> Result<VdbDense> {
        read_vdb_dense_bytes(&vdb_file(grids), "sim/cloud.0007.vdb", name, 1 << 20, 1)
    }

    #[test]
    fn the_test_writer_writes_what_the_reader_reads() {
        let mut g = TestGrid::float("density", vec![([-3, 0, 5], 0.5), ([130, 7, -4100], 2.0), ([0, 0, 0], 1.0)]);
        g.voxel_size = [0.5, 0.25, 2.0];
        g.translation = [10.0, -1.0, 3.0];
        let info = read_vdb_info_bytes(&vdb_file(&[g.clone()]), "t.vdb").unwrap();
        assert_eq!(info[0].active_voxels, Some(3));
        assert_eq!(info[0].sum, Some(3.5));
        assert_eq!((info[0].bbox_min, info[0].bbox_max), (Some([-3, 0, -4100]), Some([130, 7, 5])));
        assert_eq!((info[0].voxel_size, info[0].translation), (g.voxel_size, g.translation));
        let (read, note) = read_vdb_grid_bytes(&vdb_file(&[g.clone()]), "t.vdb", None).unwrap();
        assert_eq!(read.tree.unwrap().active_value([130, 7, -4100]), Some(2.0));
        assert!(note.is_none());
        for (value_type, half) in [("double", false), ("float", true)] {
            let h = TestGrid { value_type, half, ..g.clone() };
            let info = read_vdb_info_bytes(&vdb_file(&[h]), "t.vdb").unwrap();
            assert_eq!((info[0].sum, info[0].half), (Some(3.5), half), "{value_type}");
        }
    }

    #[test]
    fn an_empty_grid_reads_as_one_voxel_of_nothing_with_a_note() {
        let mut g = TestGrid::float("density", Vec::new());
        g.voxel_size = [0.5; 3];
        g.translation = [100.0, 20.0, -4.0];
        let d = dense(&[g.clone()], None).unwrap();
        assert!(d.empty);
        assert_eq!((d.grid.dims(), d.grid.data()), ([1, 1, 1], &[0.0][..]));
        assert_eq!((d.origin, d.voxel_size), ([99.75, 19.75, -4.25], [0.5; 3]));
        assert_eq!(d.notes.len(), 1);
        let n = &d.notes[0];
        assert!(n.contains("sim/cloud.0007.vdb") && n.contains("`density` has no active voxels") && n.contains("without a cloud"), "{n}");
        // info says so too: no bbox, no voxels, and a reader that does not fail.
        let info = read_vdb_info_bytes(&vdb_file(&[g]), "t.vdb").unwrap();
        assert_eq!((info[0].active_voxels, info[0].bbox_min, info[0].dense_bytes), (Some(0), None, 0));
        // A file with no grids at all is an empty frame too, unless a grid is asked for by name.
        let none = dense(&[], None).unwrap();
        assert!(none.empty && none.notes[0].contains("holds no grids"), "{:?}", none.notes);
        let e = dense(&[], Some("smoke")).unwrap_err().to_string();
        assert!(e.contains("no grid named `smoke`") && e.contains("no grids"), "{e}");
        // A non-empty grid is not marked.
        assert!(!dense(&[TestGrid::block("density", 2, 1.0)], None).unwrap().empty);
    }

    #[test]
    fn a_file_without_density_gives_its_only_float_grid_or_names_the_choice() {
        // One float grid of another name: read, with a note naming it and the key that picks.
        let d = dense(&[TestGrid::block("smoke", 2, 1.0)], None).unwrap();
        assert_eq!(d.grid.dims(), [2, 2, 2]);
        let n = d.notes.join("\n");
        assert!(n.contains("no grid named `density`") && n.contains("`smoke`") && n.contains("medium.grid_name"), "{n}");
        // `density` named explicitly is the same rule (it is the default).
        assert_eq!(dense(&[TestGrid::block("smoke", 2, 1.0)], Some("density")).unwrap().notes.len(), 1);
        // Beside grids that cannot be a density (an int32 mask, a level set), still the only one.
        let mut mask = TestGrid::block("mask", 2, 1.0);
        mask.value_type = "int32";
        let mut surface = TestGrid::block("surface", 2, -0.5);
        surface.class = Some("level set");
        let d = dense(&[mask.clone(), surface.clone(), TestGrid::block("smoke", 3, 1.0)], None).unwrap();
        assert_eq!(d.grid.dims(), [3, 3, 3]);
        // Several: an error listing them with the fix, naming the file.
        let e = dense(&[TestGrid::block("smoke", 2, 1.0), TestGrid::block("heat", 2, 1.0), mask.clone()], None)
            .unwrap_err()
            .to_string();
        for part in ["sim/cloud.0007.vdb", "medium.grid_name", "2 float grids", "`smoke` (float)", "`heat` (float)", "grid_name = \"NAME\""] {
            assert!(e.contains(part), "{part}: {e}");
        }
        assert!(!e.contains("`mask`"), "{e}");
        // None: the error lists what the file holds.
        let e = dense(&[mask, surface.clone()], None).unwrap_err().to_string();
        assert!(e.contains("no float, double or half grid") && e.contains("`mask` (int32)"), "{e}");
        // A level set named explicitly: refused, saying how to convert it.
        let e = dense(&[surface], Some("surface")).unwrap_err().to_string();
        assert!(e.contains("level set") && e.contains("fog volume"), "{e}");
    }
}
