//! Grid sources: the procedural cumulus and files — Mitsuba `.vol`, NumPy `.npy`, `.raw`
//! with a `.json` sidecar, and OpenVDB `.vdb` (read by [`super::vdb`]) — plus writers for each (used by `export` and round-trip tests).
//!
//! Readers never trust a header: every size is checked against the bytes really present before
//! anything is allocated, so a hostile file cannot cause an unbounded allocation or a panic.

use super::MediumDesc;
use super::{procedural, Grid3};
use crate::error::check;
use crate::error::{Error, Result};
use crate::math::Vec3;
use std::path::{Path, PathBuf};

/// A loaded grid with its placement in the world.
#[derive(Debug)]
pub struct Loaded {
    /// Densities.
    pub grid: Grid3,
    /// Minimum corner (m).
    pub origin: Vec3,
    /// Voxel edge lengths (m).
    pub voxel_size: Vec3,
    /// Name for messages (the file path, or the scene file for procedural).
    pub name: String,
    /// True if `medium.downsample` was already applied while loading.
    pub downsampled: bool,
    /// What the user should be told about the file (a `.vdb`'s grid chosen for them, an empty grid).
    pub notes: Vec<String>,
}

/// The smallest `.raw` sidecar, for messages.
const RAW_SIDECAR_EXAMPLE: &str = r#"{"resolution": [nx, ny, nz], "dtype": "float32"}"#;

/// Load the grid `[medium]` describes.
pub fn load(d: &MediumDesc, file: &str, base_dir: &Path) -> Result<Loaded> {
    if d.grid == "procedural" {
        let r = d.resolution;
        check(
            file,
            "medium.resolution",
            r.iter().all(|&n| (1..=4096).contains(&n)),
            r,
            "each dimension must be 1 to 4096 voxels",
        )?;
        let n = r[0] as u64 * r[1] as u64 * r[2] as u64;
        check(
            file,
            "medium.resolution",
            n <= d.max_voxels,
            r,
            &format!(
                "asks for {n} voxels, more than medium.max_voxels = {}; lower medium.resolution (or raise medium.max_voxels)",
                d.max_voxels
            ),
        )?;
        return placed(d, file, file.to_string(), || Ok(procedural::cumulus(r, d.seed)));
    }
    let path: PathBuf = base_dir.join(&d.grid);
    let name = path.display().to_string();
    if !path.is_file() {
        return Err(Error::invalid(
            file,
            "medium.grid",
            format!("`{name}` is not a file (paths are relative to the scene file)"),
        ));
    }
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    match ext.as_str() {
        "vol" => {
            let bytes = read_dense(&path, d, file)?;
            let (grid, lo, hi) = parse_vol(&bytes, &name)?;
            let n = grid.dims();
            let size = (hi - lo) / Vec3::new(n[0] as f32, n[1] as f32, n[2] as f32);
            if !(size.min_element() > 0.0 && size.is_finite()) {
                return Err(Error::format(
                    &name,
                    format!("bounding box {lo} .. {hi} is empty or not finite: max must exceed min on every axis"),
                ));
            }
            Ok(Loaded {
                grid,
                origin: lo,
                voxel_size: size,
                name,
                downsampled: false,
                notes: Vec::new(),
            })
        }
        "npy" => placed(d, file, name.clone(), || parse_npy(&read_dense(&path, d, file)?, &name)),
        "vdb" => load_vdb(d, file, &read(&path)?, name),
        "raw" => {
            let sidecar = path.with_extension("json");
            // Missing or a folder; a device is cut off by the read's cap below.
            if !sidecar.exists() || sidecar.is_dir() {
                return Err(Error::format(
                    &name,
                    format!(
                        "a .raw grid needs its sidecar `{}` beside it, a file holding {RAW_SIDECAR_EXAMPLE} (docs/scene.md)",
                        sidecar.display()
                    ),
                ));
            }
            let text = crate::io::read_capped(&sidecar, crate::io::MAX_TEXT_BYTES, "a .json sidecar")?;
            // Windows editors start UTF-8 text with a byte-order mark, which JSON does not allow.
            let text = text.strip_prefix(b"\xef\xbb\xbf").unwrap_or(&text);
            let meta: RawMeta = serde_json::from_slice(text).map_err(|e| {
                Error::format(
                    sidecar.display().to_string(),
                    format!("{e}; expected {RAW_SIDECAR_EXAMPLE}"),
                )
            })?;
            placed(d, file, name.clone(), || parse_raw(&read_dense(&path, d, file)?, &meta, &name))
        }
        _ => Err(Error::invalid(
            file,
            "medium.grid",
            format!(
                "`{}`: unsupported grid file type; use \"procedural\" or a .vol, .npy, .raw (+ .json) or .vdb file",
                d.grid
            ),
        )),
    }
}

/// A grid placed by `medium.origin` and `medium.voxel_size` (the procedural cloud, `.npy` and
/// `.raw`): the voxel size is checked before `grid` reads or builds anything.
fn placed(d: &MediumDesc, file: &str, name: String, grid: impl FnOnce() -> Result<Grid3>) -> Result<Loaded> {
    check(
        file,
        "medium.voxel_size",
        d.voxel_size.is_valid(),
        d.voxel_size,
        "a voxel's edges must be finite and positive (m): one number, or [x, y, z]",
    )?;
    Ok(Loaded {
        grid: grid()?,
        origin: Vec3::from(d.origin),
        voxel_size: d.voxel_size.to_vec3(),
        name,
        downsampled: false,
        notes: Vec::new(),
    })
}

/// A `.vdb` grid: placed by the file's own transform (times `medium.scale`), densified over its
/// active bounding box with `medium.downsample` applied while reading, behind `medium.max_voxels`.
fn load_vdb(d: &MediumDesc, file: &str, bytes: &[u8], name: String) -> Result<Loaded> {
    check(
        file,
        "medium.scale",
        d.scale.is_finite() && d.scale > 0.0,
        d.scale,
        "the factor on the .vdb transform must be positive and finite",
    )?;
    let v = super::vdb::read_vdb_dense_bytes(bytes, &name, Some(&d.grid_name), d.max_voxels, d.downsample)?;
    check_vdb_densities(&v, d.downsample, &name)?;
    let s = d.scale as f64;
    let (origin, voxel_size) = (v.origin.map(|x| x * s), v.voxel_size.map(|x| x * s));
    let max = super::MAX_VOXEL_SIZE as f64;
    let far = crate::limits::MAX_COORDINATE as f64;
    let fault = if !voxel_size.iter().all(|&x| x > 0.0 && x <= max && (x as f32) > 0.0) {
        Some(format!(
            "the file's voxel size {:?} gives {voxel_size:?} m; a voxel must be positive and at most {max:e} m",
            v.voxel_size
        ))
    } else if !origin.iter().all(|x| x.abs() <= far) {
        Some(format!(
            "the file's grid corner {:?} goes to {origin:?} m, beyond ±{far:e} m",
            v.origin
        ))
    } else {
        None
    };
    if let Some(f) = fault {
        return Err(Error::invalid(
            file,
            "medium.scale",
            format!("{} times {f}: set medium.scale to the file's metres per unit", d.scale),
        ));
    }
    Ok(Loaded {
        grid: v.grid,
        origin: Vec3::from(origin.map(|x| x as f32)),
        voxel_size: Vec3::from(voxel_size.map(|x| x as f32)),
        name,
        downsampled: true,
        notes: v.notes,
    })
}

/// A `.vdb` density that is negative or not finite, named by its index in the file (what `cloudgi
/// info` and the DCC show), with the usual cause and fix: a simulation's advection leaves small
/// negative values in fog volumes.
fn check_vdb_densities(v: &super::vdb::VdbDense, downsample: usize, name: &str) -> Result<()> {
    let Some((i, &value)) = v.grid.data().iter().enumerate().find(|(_, x)| !x.is_finite() || **x < 0.0) else {
        return Ok(());
    };
    let n = v.grid.dims();
    let at = [i % n[0], (i / n[0]) % n[1], i / (n[0] * n[1])];
    let index = [0, 1, 2].map(|a| v.index_min[a] + (at[a] * downsample.max(1)) as i64);
    let block = match downsample {
        0 | 1 => String::new(),
        k => format!(" (the mean of the {k}³ block from there)"),
    };
    let fix = match value < 0.0 {
        true => {
            "a fog volume's densities must be non-negative: simulations leave small negative values where \
             advection overshoots; clamp them before export (Houdini: a Volume Wrangle with \
             `@density = max(@density, 0);`)"
        }
        false => "densities must be finite: the file holds NaN or infinite values; re-export it from a clean simulation",
    };
    Err(Error::format(
        name,
        format!("grid `{}`: the voxel at index {index:?}{block} holds {value}; {fix}", v.grid_name),
    ))
}

fn read(path: &Path) -> Result<Vec<u8>> {
    crate::io::read_regular(path, "a density grid")
}

/// Most bytes of a dense grid file (`.vol`, `.npy`, `.raw`): `medium.max_voxels` values (times
/// downsample³, which is applied after reading) of at most 8 bytes each, plus 1 MiB of header.
fn dense_file_limit(d: &MediumDesc) -> u64 {
    let factor = (d.downsample as u64).saturating_pow(3);
    d.max_voxels.saturating_mul(factor).saturating_mul(8).saturating_add(1 << 20)
}

/// Read a dense grid file, refusing one larger than any grid `medium.max_voxels` allows before
/// reading it.
fn read_dense(path: &Path, d: &MediumDesc, file: &str) -> Result<Vec<u8>> {
    let len = std::fs::metadata(path).map_err(|e| Error::io(path, e))?.len();
    let limit = dense_file_limit(d);
    if len > limit {
        return Err(Error::invalid(
            file,
            "medium.max_voxels",
            format!(
                "`{}` is {len} bytes, more than a grid of medium.max_voxels = {} voxels (at downsample {}) can fill ({limit} bytes); raise medium.max_voxels or medium.downsample",
                path.display(),
                d.max_voxels,
                d.downsample
            ),
        ));
    }
    read(path)
}

/// Number of voxels of `dims`, refusing overflow and zero.
fn voxel_count(dims: [u64; 3], name: &str) -> Result<usize> {
    if dims.contains(&0) {
        return Err(Error::format(
            name,
            format!("grid has zero size (nx, ny, nz) = {dims:?}: every dimension must be at least 1"),
        ));
    }
    dims[0]
        .checked_mul(dims[1])
        .and_then(|v| v.checked_mul(dims[2]))
        .and_then(|v| usize::try_from(v).ok())
        .ok_or_else(|| Error::format(name, format!("grid resolution {dims:?} is too large")))
}

/// Need `n` values of `size` bytes from `avail` bytes: a clear truncation error otherwise.
fn need(n: usize, size: usize, avail: usize, name: &str, what: &str) -> Result<()> {
    match n.checked_mul(size) {
        Some(b) if b <= avail => Ok(()),
        _ => Err(Error::format(
            name,
            format!(
                "truncated: the header declares {n} {what} values ({} bytes) but only {avail} bytes follow",
                n.saturating_mul(size)
            ),
        )),
    }
}

// ---------------------------------------------------------------- Mitsuba .vol

/// Parse a Mitsuba `.vol`: `VOL`, version 3, encoding 1 (float32), resolution, channels (1),
/// bbox min/max (float32), values x fastest. Returns the grid and its bbox.
pub fn parse_vol(b: &[u8], name: &str) -> Result<(Grid3, Vec3, Vec3)> {
    if b.len() < 48 {
        return Err(Error::format(
            name,
            format!("truncated: {} bytes, a .vol header alone is 48", b.len()),
        ));
    }
    if &b[0..3] != b"VOL" {
        return Err(Error::format(name, "not a Mitsuba .vol file (it must start with the bytes `VOL`)"));
    }
    if b[3] != 3 {
        return Err(Error::format(
            name,
            format!("unsupported .vol version {} (only version 3 is supported)", b[3]),
        ));
    }
    let i32_at = |o: usize| i32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]]);
    let f32_at = |o: usize| f32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]]);
    let enc = i32_at(4);
    if enc != 1 {
        return Err(Error::format(
            name,
            format!("unsupported .vol encoding {enc} (only 1 = float32 is supported)"),
        ));
    }
    let (nx, ny, nz, ch) = (i32_at(8), i32_at(12), i32_at(16), i32_at(20));
    if ch != 1 {
        return Err(Error::format(
            name,
            format!(".vol has {ch} channels; a density grid needs exactly 1"),
        ));
    }
    if nx < 0 || ny < 0 || nz < 0 {
        return Err(Error::format(name, format!("negative resolution {nx}×{ny}×{nz}")));
    }
    let n = voxel_count([nx as u64, ny as u64, nz as u64], name)?;
    let lo = Vec3::new(f32_at(24), f32_at(28), f32_at(32));
    let hi = Vec3::new(f32_at(36), f32_at(40), f32_at(44));
    need(n, 4, b.len() - 48, name, "float32")?;
    let data = b[48..48 + 4 * n]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    Ok((Grid3::from_vec([nx as usize, ny as usize, nz as usize], data, name)?, lo, hi))
}

/// Write a Mitsuba `.vol` (float32, one channel).
pub fn write_vol(path: &Path, g: &Grid3, lo: Vec3, hi: Vec3) -> Result<()> {
    let d = g.dims();
    let mut b = Vec::with_capacity(48 + 4 * g.len());
    b.extend_from_slice(b"VOL");
    b.push(3);
    for v in [1i32, d[0] as i32, d[1] as i32, d[2] as i32, 1] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    for v in [lo.x, lo.y, lo.z, hi.x, hi.y, hi.z] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    for v in g.data() {
        b.extend_from_slice(&v.to_le_bytes());
    }
    crate::io::write_atomic(path, &b)
}

// ---------------------------------------------------------------- NumPy .npy

/// Parse a `.npy` of shape (nz, ny, nx) in C or Fortran order, of any type
/// [`NpyDtype`](super::npy_dtype::NpyDtype) reads (floats, integers, booleans; either endianness).
pub fn parse_npy(b: &[u8], name: &str) -> Result<Grid3> {
    if b.len() < 10 || &b[0..6] != b"\x93NUMPY" {
        return Err(Error::format(name, "not a NumPy .npy file (missing the \\x93NUMPY magic)"));
    }
    let major = b[6];
    let (hlen, hstart) = match major {
        1 => (u16::from_le_bytes([b[8], b[9]]) as usize, 10usize),
        2 | 3 => {
            if b.len() < 12 {
                return Err(Error::format(name, "truncated .npy header"));
            }
            (u32::from_le_bytes([b[8], b[9], b[10], b[11]]) as usize, 12)
        }
        v => return Err(Error::format(name, format!("unsupported .npy format version {v}"))),
    };
    let hend = hstart
        .checked_add(hlen)
        .filter(|&e| e <= b.len())
        .ok_or_else(|| Error::format(name, "truncated .npy header"))?;
    let header = std::str::from_utf8(&b[hstart..hend]).map_err(|_| Error::format(name, ".npy header is not text"))?;
    for key in ["descr", "fortran_order", "shape"] {
        if header.matches(&format!("'{key}'")).count() > 1 {
            return Err(Error::format(
                name,
                format!(".npy header gives '{key}' more than once; NumPy would take the last, write the file again with numpy.save"),
            ));
        }
    }
    let field = |key: &str| -> Option<&str> {
        let at = header.find(&format!("'{key}'"))?;
        let rest = &header[at + key.len() + 2..];
        let colon = rest.find(':')?;
        Some(rest[colon + 1..].trim_start())
    };
    let descr = field("descr").ok_or_else(|| Error::format(name, ".npy header has no 'descr'"))?;
    let descr = descr.strip_prefix('\'').and_then(|s| s.split('\'').next()).ok_or_else(|| {
        Error::format(
            name,
            ".npy dtype is structured (named fields), not one number per voxel; save one field, e.g. numpy.save(path, array['density'])",
        )
    })?;
    let fortran = field("fortran_order").map(|s| s.starts_with("True")).unwrap_or(false);
    let dtype = super::npy_dtype::NpyDtype::parse(descr).ok_or_else(|| {
        Error::format(
            name,
            format!(
                ".npy dtype '{descr}' is not supported; save the array as {}",
                super::npy_dtype::SUPPORTED
            ),
        )
    })?;
    let shape_s = field("shape")
        .and_then(|s| s.strip_prefix('('))
        .and_then(|s| s.split(')').next())
        .ok_or_else(|| Error::format(name, ".npy header has no 'shape'"))?;
    let shape: Vec<u64> = shape_s
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<u64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| Error::format(name, format!(".npy shape ({shape_s}) is not a list of integers")))?;
    if shape.len() != 3 {
        return Err(Error::format(
            name,
            format!(
                ".npy array has {} dimension{}; a density grid needs 3, indexed [z][y][x]",
                shape.len(),
                if shape.len() == 1 { "" } else { "s" }
            ),
        ));
    }
    if shape.contains(&0) {
        // Named by the array's own shape: (nx, ny, nz) reversed reads as another array.
        return Err(Error::format(
            name,
            format!(
                ".npy array of shape ({}, {}, {}) holds no voxel: each axis of [z][y][x] must be at least 1 long",
                shape[0], shape[1], shape[2]
            ),
        ));
    }
    let n = voxel_count([shape[2], shape[1], shape[0]], name)?;
    let body = &b[hend..];
    let value_size = dtype.size;
    if n.checked_mul(value_size).is_some_and(|need| body.len() > need) {
        return Err(Error::format(
            name,
            format!(
                "{} bytes follow the {n} values of shape ({shape_s}): a .npy holds its array and nothing after it; write the file again with numpy.save",
                body.len() - n * value_size
            ),
        ));
    }
    need(n, value_size, body.len(), name, descr)?;
    let values = body[..value_size * n].chunks_exact(value_size).map(|c| dtype.value(c));
    let data = narrowed(values, name)?;
    let dims = [shape[2] as usize, shape[1] as usize, shape[0] as usize];
    let data = if fortran { c_order(&data, dims) } else { data };
    Grid3::from_vec(dims, data, name)
}

/// The values of a Fortran-order array of shape (nz, ny, nx) (its first index fastest) in the C
/// order [z][y][x] the grid holds (x fastest).
fn c_order(fortran: &[f32], [nx, ny, nz]: [usize; 3]) -> Vec<f32> {
    let mut out = Vec::with_capacity(fortran.len());
    for z in 0..nz {
        for y in 0..ny {
            out.extend((0..nx).map(|x| fortran[z + nz * (y + ny * x)]));
        }
    }
    out
}

/// Values read in f64 as the f32 densities are held in. A finite value past f32's range is named
/// as such: cast, it would be reported as an infinite density the file does not hold.
fn narrowed(values: impl Iterator<Item = f64>, name: &str) -> Result<Vec<f32>> {
    values
        .enumerate()
        .map(|(k, v)| {
            let narrow = v as f32;
            if v.is_finite() && !narrow.is_finite() {
                return Err(Error::format(
                    name,
                    format!(
                        "value {k} is {v:e}, beyond float32's ±3.4e38 that densities are held in; scale the \
                         densities down and medium.sigma_t (extinction at density 1) up"
                    ),
                ));
            }
            Ok(narrow)
        })
        .collect()
}

/// float64 values as the f32 densities are held in ([`narrowed`]).
fn float64_values(b: &[u8], big_endian: bool, name: &str) -> Result<Vec<f32>> {
    let values = b.chunks_exact(8).map(|c| {
        let a: [u8; 8] = c.try_into().expect("chunk of 8");
        if big_endian {
            f64::from_be_bytes(a)
        } else {
            f64::from_le_bytes(a)
        }
    });
    narrowed(values, name)
}

/// Write a float32 `.npy` of shape (nz, ny, nx).
pub fn write_npy(path: &Path, g: &Grid3) -> Result<()> {
    let d = g.dims();
    let mut header = format!(
        "{{'descr': '<f4', 'fortran_order': False, 'shape': ({}, {}, {}), }}",
        d[2], d[1], d[0]
    );
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut b = Vec::with_capacity(10 + header.len() + 4 * g.len());
    b.extend_from_slice(b"\x93NUMPY\x01\x00");
    b.extend_from_slice(&(header.len() as u16).to_le_bytes());
    b.extend_from_slice(header.as_bytes());
    for v in g.data() {
        b.extend_from_slice(&v.to_le_bytes());
    }
    crate::io::write_atomic(path, &b)
}

// ---------------------------------------------------------------- .raw + .json

/// The `.json` sidecar of a `.raw` grid.
#[derive(Debug, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct RawMeta {
    /// (nx, ny, nz); values are stored x fastest.
    pub resolution: [u64; 3],
    /// `float32`, `float64`, `uint8` or `uint16`.
    pub dtype: String,
    /// `little` (default) or `big`.
    #[serde(default = "little")]
    pub endian: String,
    /// Factor applied to every value (default 1; e.g. 1/255 for uint8 data).
    #[serde(default = "one")]
    pub scale: f32,
}

fn little() -> String {
    "little".into()
}
fn one() -> f32 {
    1.0
}

/// Parse raw values described by `meta`.
pub fn parse_raw(b: &[u8], meta: &RawMeta, name: &str) -> Result<Grid3> {
    let n = voxel_count(meta.resolution, name)?;
    let be = match meta.endian.as_str() {
        "little" => false,
        "big" => true,
        e => {
            return Err(Error::format(
                name,
                format!("sidecar field `endian` is \"{e}\"; use \"little\" or \"big\""),
            ))
        }
    };
    if !(meta.scale.is_finite() && meta.scale > 0.0) {
        return Err(Error::format(
            name,
            format!(
                "sidecar field `scale` is {}: it multiplies every value, so it must be positive and finite (1, or e.g. 1/255 for uint8 data)",
                meta.scale
            ),
        ));
    }
    let size = match meta.dtype.as_str() {
        "float32" => 4,
        "float64" => 8,
        "uint8" => 1,
        "uint16" => 2,
        t => {
            return Err(Error::format(
                name,
                format!("sidecar field `dtype` is \"{t}\"; use float32, float64, uint8 or uint16"),
            ))
        }
    };
    if n.checked_mul(size) != Some(b.len()) {
        return Err(Error::format(
            name,
            format!(
                "{} bytes, but resolution {:?} of {} needs {} bytes: fix the sidecar's resolution or dtype",
                b.len(),
                meta.resolution,
                meta.dtype,
                n.saturating_mul(size)
            ),
        ));
    }
    let mut data: Vec<f32> = match meta.dtype.as_str() {
        "float32" => {
            need(n, 4, b.len(), name, "float32")?;
            b[..4 * n]
                .chunks_exact(4)
                .map(|c| {
                    if be {
                        f32::from_be_bytes([c[0], c[1], c[2], c[3]])
                    } else {
                        f32::from_le_bytes([c[0], c[1], c[2], c[3]])
                    }
                })
                .collect()
        }
        "float64" => {
            need(n, 8, b.len(), name, "float64")?;
            float64_values(&b[..8 * n], be, name)?
        }
        "uint8" => {
            need(n, 1, b.len(), name, "uint8")?;
            b[..n].iter().map(|&v| v as f32).collect()
        }
        "uint16" => {
            need(n, 2, b.len(), name, "uint16")?;
            b[..2 * n]
                .chunks_exact(2)
                .map(|c| {
                    let v = if be {
                        u16::from_be_bytes([c[0], c[1]])
                    } else {
                        u16::from_le_bytes([c[0], c[1]])
                    };
                    v as f32
                })
                .collect()
        }
        t => {
            return Err(Error::format(
                name,
                format!("sidecar field `dtype` is \"{t}\"; use float32, float64, uint8 or uint16"),
            ))
        }
    };
    scale_values(&mut data, meta.scale, name)?;
    Grid3::from_vec(
        [
            meta.resolution[0] as usize,
            meta.resolution[1] as usize,
            meta.resolution[2] as usize,
        ],
        data,
        name,
    )
}

/// Multiply every value by the sidecar's `scale`; a finite value the product takes past f32's
/// range is the scale's fault and named so.
fn scale_values(data: &mut [f32], scale: f32, name: &str) -> Result<()> {
    if scale == 1.0 {
        return Ok(());
    }
    for v in data.iter_mut() {
        let p = *v * scale;
        if v.is_finite() && !p.is_finite() {
            return Err(Error::format(
                name,
                format!("sidecar field `scale` = {scale:e} times the value {v:e} overflows float32; lower `scale`"),
            ));
        }
        *v = p;
    }
    Ok(())
}

/// Write a float32 little-endian `.raw` and its `.json` sidecar.
pub fn write_raw(path: &Path, g: &Grid3) -> Result<()> {
    let d = g.dims();
    let mut b = Vec::with_capacity(4 * g.len());
    for v in g.data() {
        b.extend_from_slice(&v.to_le_bytes());
    }
    crate::io::write_atomic(path, &b)?;
    let meta = RawMeta {
        resolution: [d[0] as u64, d[1] as u64, d[2] as u64],
        dtype: "float32".into(),
        endian: "little".into(),
        scale: 1.0,
    };
    crate::io::write_atomic(
        &path.with_extension("json"),
        serde_json::to_string_pretty(&meta).expect("serialisable").as_bytes(),
    )
}
