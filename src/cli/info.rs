//! `cloudgi info FILE [--json]`: what a `.vdb` file holds and what a dense render of it needs.

use super::console::print;
use crate::error::{Error, Result};
use crate::io::format_bytes;
use crate::medium::vdb::{read_vdb_info, VdbGridInfo};
use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct InfoArgs {
    /// An OpenVDB (.vdb) file.
    file: PathBuf,
    /// Print one JSON object on one line: {"grids": [{"name", "type", "active_voxels", "sum", "bbox_min",
    /// "bbox_max", "voxel_size", "translation", "dense_bytes"}]}.
    #[arg(long)]
    json: bool,
}

/// Thousands separators for counts.
fn grouped(n: u64) -> String {
    let s = n.to_string();
    let mut out = String::new();
    for (i, ch) in s.chars().enumerate() {
        if i > 0 && (s.len() - i) % 3 == 0 {
            out.push(',');
        }
        out.push(ch);
    }
    out
}

fn describe(g: &VdbGridInfo) -> String {
    let mut s = format!("  {}: {}", g.name, g.value_type);
    if g.half {
        s += " (stored as half)";
    }
    if let Some(c) = &g.class {
        s += &format!(", {c}");
    }
    s.push('\n');
    match g.active_voxels {
        Some(0) => s += "    active voxels  0: empty (a render reads it as a scene without a cloud)\n",
        Some(n) => s += &format!("    active voxels  {} (tiles expanded)\n", grouped(n)),
        None => s += "    active voxels  unknown (value type not read)\n",
    }
    if let Some(sum) = g.sum {
        s += &format!("    sum of values  {sum}\n");
    }
    if let (Some(lo), Some(hi)) = (g.bbox_min, g.bbox_max) {
        let d = [0, 1, 2].map(|a| hi[a] - lo[a] + 1);
        s += &format!("    index bbox     {lo:?} .. {hi:?} ({}×{}×{} voxels)\n", d[0], d[1], d[2]);
        s += &format!("    dense render   {} as float32\n", format_bytes(g.dense_bytes as u128));
    }
    s += &format!(
        "    transform      {}: voxel size {:?}, translation {:?}\n",
        g.map, g.voxel_size, g.translation
    );
    s
}

/// Run `info`.
pub fn run(a: InfoArgs) -> Result<()> {
    let grids = read_vdb_info(&a.file)?;
    if a.json {
        // A struct, not json!, so the keys keep the documented order.
        #[derive(serde::Serialize)]
        struct Out<'a> {
            grids: &'a [VdbGridInfo],
        }
        let json = serde_json::to_string(&Out { grids: &grids }).map_err(|e| Error::format("<json>", e.to_string()))?;
        print(&format!("{json}\n"))
    } else {
        let mut text = format!(
            "{}: {} grid{}\n",
            a.file.display(),
            grids.len(),
            if grids.len() == 1 { "" } else { "s" }
        );
        for g in &grids {
            text += &describe(g);
        }
        print(&text)
    }
}
