//! File header, metadata maps and grid descriptors of an OpenVDB file (format versions 222–224,
//! written by OpenVDB 3 and later).

use super::bytes::Cursor;
use crate::error::Result;

/// `"VDB "` as the little-endian int64 every OpenVDB file starts with.
const MAGIC: i64 = 0x5644_4220;
/// Oldest supported format: per-grid compression flags and active-mask compression (OpenVDB 3).
pub(crate) const MIN_VERSION: u32 = 222;
/// Newest format known when this reader was written (OpenVDB 6 to 12).
pub(crate) const MAX_VERSION: u32 = 224;

/// What the file header says.
/// `text` from a file with its control characters written as escapes (`\u{1b}`): grid names and
/// types are printed by `info` and in errors, and a file's bytes must not drive the terminal.
pub(super) fn printable(text: &str) -> String {
    text.chars()
        .map(|c| match c.is_control() {
            true => c.escape_unicode().to_string(),
            false => c.to_string(),
        })
        .collect()
}

#[derive(Debug)]
pub(crate) struct FileHeader {
    #[allow(dead_code)]
    pub version: u32,
    pub descriptors: Vec<GridDescriptor>,
}

/// One entry of the grid table.
#[derive(Debug, Clone)]
pub(crate) struct GridDescriptor {
    /// Grid name (the unique-name suffix OpenVDB adds to duplicates stripped).
    pub name: String,
    /// Name as stored, unique within the file (instances refer to their parent by it).
    pub unique_name: String,
    /// Tree type, e.g. `Tree_float_5_4_3` (the `_HalfFloat` suffix removed).
    pub tree_type: String,
    /// True if floating-point values are stored as 16-bit halves.
    pub half: bool,
    /// Name of the grid whose tree this one shares (instancing), empty if none.
    pub instance_parent: String,
    /// Offset of the grid's data (compression flags, metadata, transform, tree).
    pub grid_pos: u64,
    /// Offset just past the grid's data.
    pub end_pos: u64,
}

/// A metadata value the reader understands (the rest are skipped by their declared size).
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Meta {
    Str(String),
    Int(i64),
    Float(f64),
    Bool(bool),
    Vec3i([i32; 3]),
    Other,
}

/// Read a metadata map: count, then (name, type name, byte size, value) records.
pub(crate) fn read_meta(c: &mut Cursor) -> Result<Vec<(String, Meta)>> {
    let count = c.u32("metadata count")?;
    // Each record is at least 12 bytes (three u32 sizes): refuse counts the file cannot hold.
    if count as usize > c.remaining() / 12 {
        return Err(c.err(format!("corrupt metadata: {count} entries declared, the file cannot hold them")));
    }
    let mut out = Vec::new();
    for _ in 0..count {
        let name = c.string("metadata name")?;
        let ty = c.string("metadata type")?;
        let size = c.u32("metadata size")? as usize;
        let b = c.take(size, "metadata value")?;
        let arr4 = |o: usize| [b[o], b[o + 1], b[o + 2], b[o + 3]];
        let v = match (ty.as_str(), size) {
            ("string", _) => Meta::Str(String::from_utf8_lossy(b).into_owned()),
            ("bool", 1) => Meta::Bool(b[0] != 0),
            ("int32", 4) => Meta::Int(i32::from_le_bytes(arr4(0)) as i64),
            ("int64", 8) => Meta::Int(i64::from_le_bytes(b.try_into().expect("8 bytes"))),
            ("float", 4) => Meta::Float(f32::from_le_bytes(arr4(0)) as f64),
            ("double", 8) => Meta::Float(f64::from_le_bytes(b.try_into().expect("8 bytes"))),
            ("vec3i", 12) => Meta::Vec3i([
                i32::from_le_bytes(arr4(0)),
                i32::from_le_bytes(arr4(4)),
                i32::from_le_bytes(arr4(8)),
            ]),
            _ => Meta::Other,
        };
        out.push((name, v));
    }
    Ok(out)
}

/// Read the file header, file metadata and grid descriptors.
pub(crate) fn read_header(c: &mut Cursor) -> Result<FileHeader> {
    let magic = c
        .i64("file magic")
        .map_err(|_| c.err("not an OpenVDB file: shorter than its 8-byte magic number"))?;
    if magic != MAGIC {
        return Err(c.err("not an OpenVDB file (it must start with the magic bytes `VDB` 20 42 44 56 00 00 00 00)"));
    }
    let version = c.u32("file format version")?;
    if !(MIN_VERSION..=MAX_VERSION).contains(&version) {
        return Err(c.err(format!(
            "OpenVDB file format version {version} is not supported (this reader handles {MIN_VERSION} to {MAX_VERSION}, \
             OpenVDB 3 and later); re-save the file with a current OpenVDB"
        )));
    }
    let _lib_major = c.u32("library version")?;
    let _lib_minor = c.u32("library version")?;
    let has_offsets = c.u8("grid-offsets flag")?;
    if has_offsets == 0 {
        return Err(c.err("the file has no grid offsets (streamed .vdb); re-save it as a regular file"));
    }
    c.skip(36, "file UUID")?;
    read_meta(c)?;
    let count = c.i32("grid count")?;
    if count < 0 || count as usize > c.remaining() / 36 {
        return Err(c.err(format!("corrupt header: {count} grids declared, the file cannot hold them")));
    }
    let mut descriptors = Vec::new();
    for _ in 0..count {
        let unique = c.string("grid name")?;
        let name = printable(unique.split('\u{1e}').next().unwrap_or(""));
        let mut tree_type = printable(&c.string("grid type")?);
        let half = tree_type.ends_with("_HalfFloat");
        if half {
            tree_type.truncate(tree_type.len() - "_HalfFloat".len());
        }
        let instance_parent = c.string("instance parent name")?;
        let grid_pos = c.i64("grid offset")?;
        let _block_pos = c.i64("grid block offset")?;
        let end_pos = c.i64("grid end offset")?;
        let file_len = c.pos() + c.remaining();
        if grid_pos < 0 || end_pos < grid_pos {
            return Err(c.err(format!(
                "corrupt grid table: grid `{name}` spans bytes {grid_pos}..{end_pos}, outside the {file_len}-byte file"
            )));
        }
        // A table that names bytes past the end is what a copy or download cut short leaves.
        if end_pos as u64 > file_len as u64 {
            return Err(c.err(format!(
                "truncated: grid `{name}` ends at byte {end_pos}, but the file has {file_len} bytes: it was cut \
                 short (a copy or download that stopped); copy or export it again"
            )));
        }
        descriptors.push(GridDescriptor {
            name,
            unique_name: unique.clone(),
            tree_type,
            half,
            instance_parent,
            grid_pos: grid_pos as u64,
            end_pos: end_pos as u64,
        });
        c.seek(end_pos as u64, "the grid end offset")?;
    }
    Ok(FileHeader { version, descriptors })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn control_characters_in_a_files_text_are_written_as_escapes() {
        assert_eq!(printable("density"), "density");
        assert_eq!(printable("smoke\u{1b}[2J\nx"), "smoke\\u{1b}[2J\\u{a}x");
        assert_eq!(printable("dichte→ü"), "dichte→ü");
    }
}
