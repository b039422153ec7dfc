//! A minimal OpenVDB file writer for tests: format 224, no compression, `Tree_<type>_5_4_3`
//! trees of leaves only, a `ScaleTranslateMap`, as OpenVDB lays them out (the layout
//! [`super::header`], [`super::tree`] and [`super::codec`] read). It writes what the test data
//! written by OpenVDB itself (tests/data/vdb) does not hold: empty grids, grids of any name and
//! class, several scalar grids, extreme voxel sizes.
//!
//! Self-contained (std only): the end-to-end tests include this file by path.

/// One grid to write.
#[derive(Clone, Debug)]
pub struct TestGrid {
    /// Grid name.
    pub name: String,
    /// Value type token: `float`, `double` or `int32` (a value is written as that type).
    pub value_type: &'static str,
    /// Stored as 16-bit halves (`_HalfFloat`; `float` only).
    pub half: bool,
    /// `class` metadata (`fog volume`, `level set`), if any.
    pub class: Option<&'static str>,
    /// World units per index step.
    pub voxel_size: [f64; 3],
    /// World position of index (0, 0, 0).
    pub translation: [f64; 3],
    /// Active voxels: index and value (none: an empty tree).
    pub voxels: Vec<([i32; 3], f32)>,
}

impl TestGrid {
    /// A fog-volume `float` grid named `name` with unit voxels holding `voxels`.
    pub fn float(name: &str, voxels: Vec<([i32; 3], f32)>) -> TestGrid {
        TestGrid {
            name: name.to_string(),
            value_type: "float",
            half: false,
            class: Some("fog volume"),
            voxel_size: [1.0; 3],
            translation: [0.0; 3],
            voxels,
        }
    }

    /// A solid `n`³ block of `value` from index (0, 0, 0).
    pub fn block(name: &str, n: i32, value: f32) -> TestGrid {
        let voxels = (0..n)
            .flat_map(|x| (0..n).flat_map(move |y| (0..n).map(move |z| ([x, y, z], value))))
            .collect();
        TestGrid::float(name, voxels)
    }
}

/// log2 of the node edges below the root (OpenVDB's standard 5-4-3 tree).
const LOG2: [u32; 3] = [5, 4, 3];

fn put_str(out: &mut Vec<u8>, s: &str) {
    out.extend((s.len() as u32).to_le_bytes());
    out.extend(s.as_bytes());
}

/// f32 → binary16, rounding to nearest (normal and zero values only: what tests write).
fn f32_to_half(v: f32) -> u16 {
    if v == 0.0 {
        return 0;
    }
    let b = v.to_bits();
    let sign = ((b >> 16) & 0x8000) as u16;
    let exp = ((b >> 23) & 0xff) as i32 - 127 + 15;
    assert!((1..31).contains(&exp), "{v} is not a normal half");
    let man = (b & 0x7f_ffff) + 0x1000; // round to nearest on the 13 dropped bits
    let (exp, man) = if man & 0x80_0000 != 0 { (exp + 1, 0) } else { (exp, man >> 13) };
    sign | ((exp as u16) << 10) | man as u16
}

fn put_value(out: &mut Vec<u8>, g: &TestGrid, v: f32, stored: bool) {
    match g.value_type {
        "float" if stored && g.half => out.extend(f32_to_half(v).to_le_bytes()),
        "float" => out.extend(v.to_le_bytes()),
        "double" => out.extend((v as f64).to_le_bytes()),
        "int32" => out.extend((v as i32).to_le_bytes()),
        t => panic!("test writer: value type {t}"),
    }
}

/// Offset of local coordinates `p` in a node of edge 2^`l` (z fastest, as OpenVDB).
fn offset(p: [i64; 3], l: u32) -> usize {
    ((p[0] << (2 * l)) | (p[1] << l) | p[2]) as usize
}

fn mask_bytes(bits: &[usize], n: usize) -> Vec<u8> {
    let mut m = vec![0u8; n / 8];
    for &b in bits {
        m[b / 8] |= 1 << (b % 8);
    }
    m
}

/// Origin of the node of edge `dim` holding `p`.
fn node_origin(p: [i64; 3], dim: i64) -> [i64; 3] {
    p.map(|c| c.div_euclid(dim) * dim)
}

/// An internal node's leaves (by offset), each its active values (by offset).
type Leaves = std::collections::BTreeMap<usize, std::collections::BTreeMap<usize, f32>>;

/// The tree of `g`: root (no tiles), internal nodes and leaves, topology then leaf buffers.
fn tree(g: &TestGrid) -> Vec<u8> {
    use std::collections::BTreeMap;
    let dims = [1i64 << 12, 1 << 7, 1 << 3];
    // root child → internal child → leaf → (offset → value).
    let mut nodes: BTreeMap<[i64; 3], BTreeMap<usize, Leaves>> = BTreeMap::new();
    for &(ijk, v) in &g.voxels {
        let p = ijk.map(i64::from);
        let (r, i, l) = (node_origin(p, dims[0]), node_origin(p, dims[1]), node_origin(p, dims[2]));
        let local = |o: [i64; 3], child: [i64; 3], step: i64, lg: u32| offset([0, 1, 2].map(|a| (child[a] - o[a]) / step), lg);
        nodes
            .entry(r)
            .or_default()
            .entry(local(r, i, dims[1], LOG2[0]))
            .or_default()
            .entry(local(i, l, dims[2], LOG2[1]))
            .or_default()
            .insert(local(l, p, 1, LOG2[2]), v);
    }
    let mut t = Vec::new();
    t.extend(1i32.to_le_bytes()); // buffer count
    put_value(&mut t, g, 0.0, false); // background
    t.extend(0u32.to_le_bytes()); // root tiles
    t.extend((nodes.len() as u32).to_le_bytes());
    let mut leaf_buffers = Vec::new();
    // An internal node's topology: child mask, an empty value mask (no tiles), its values
    // uncompressed (metadata byte 6: no inactive values to restore).
    let internal = |t: &mut Vec<u8>, children: Vec<usize>, level: usize| {
        let n = 1usize << (3 * LOG2[level]);
        t.extend(mask_bytes(&children, n));
        t.extend(mask_bytes(&[], n));
        t.push(6);
        for _ in 0..n {
            put_value(t, g, 0.0, true);
        }
    };
    for (origin, internals) in &nodes {
        for c in origin {
            t.extend((*c as i32).to_le_bytes());
        }
        internal(&mut t, internals.keys().copied().collect(), 0);
        for leaves in internals.values() {
            internal(&mut t, leaves.keys().copied().collect(), 1);
            for values in leaves.values() {
                let n = 1usize << (3 * LOG2[2]);
                let active: Vec<usize> = values.keys().copied().collect();
                let mask = mask_bytes(&active, n);
                t.extend(&mask);
                leaf_buffers.extend(&mask);
                leaf_buffers.push(6);
                for k in 0..n {
                    put_value(&mut leaf_buffers, g, values.get(&k).copied().unwrap_or(0.0), true);
                }
            }
        }
    }
    t.extend(leaf_buffers);
    t
}

/// The data of one grid: compression flags, metadata, transform, tree.
fn grid_data(g: &TestGrid) -> Vec<u8> {
    let mut d = Vec::new();
    d.extend(0u32.to_le_bytes()); // no compression
    match g.class {
        Some(c) => {
            d.extend(1u32.to_le_bytes());
            put_str(&mut d, "class");
            put_str(&mut d, "string");
            put_str(&mut d, c);
        }
        None => d.extend(0u32.to_le_bytes()),
    }
    put_str(&mut d, "ScaleTranslateMap");
    let s = g.voxel_size;
    for v in g.translation.iter().chain(&s) {
        d.extend(v.to_le_bytes());
    }
    // The derived values OpenVDB stores: voxel size, 1/scale, 1/scale², 1/(2 scale).
    for f in [|x: f64| x, |x: f64| 1.0 / x, |x: f64| 1.0 / (x * x), |x: f64| 0.5 / x] {
        for v in s {
            d.extend(f(v).to_le_bytes());
        }
    }
    d.extend(tree(g));
    d
}

/// A `.vdb` file holding `grids`.
pub fn vdb_file(grids: &[TestGrid]) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend(0x5644_4220i64.to_le_bytes());
    out.extend(224u32.to_le_bytes());
    out.extend(10u32.to_le_bytes());
    out.extend(0u32.to_le_bytes());
    out.push(1); // grid offsets
    out.extend(b"00000000-0000-0000-0000-000000000000");
    out.extend(0u32.to_le_bytes()); // file metadata
    out.extend((grids.len() as i32).to_le_bytes());
    for g in grids {
        put_str(&mut out, &g.name);
        let half = if g.half { "_HalfFloat" } else { "" };
        put_str(&mut out, &format!("Tree_{}_5_4_3{half}", g.value_type));
        put_str(&mut out, ""); // instance parent
        let data = grid_data(g);
        let start = out.len() as i64 + 24;
        let end = start + data.len() as i64;
        for v in [start, start, end] {
            out.extend(v.to_le_bytes());
        }
        out.extend(data);
    }
    out
}
