//! `cloudgi bench`: every stage's time (the `Timings` the renderer collects) and each run's peak
//! memory for the chosen methods on three sizes of the procedural cloud and on any scene files
//! named with `--clouds` (e.g. the Disney cloud), as a markdown table (the tables in
//! docs/performance.md, "Time per stage", are this command's output).

use super::scene_file::SceneFile;
use super::MethodArg;
use crate::error::{Error, Result};
use crate::scene::{Method, Scene};
use crate::Progress;
use clap::Args;
use std::path::PathBuf;
use std::sync::Mutex;

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Scene file (TOML) with a procedural grid. Without it, the built-in default scene.
    scene: Option<PathBuf>,
    /// Methods to time, in order; the first is the baseline of the `× first` column.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "single,diffusion,full,transport")]
    methods: Vec<MethodArg>,
    /// Procedural resolutions NXxNYxNZ; the voxel size is scaled so the cloud keeps its extent.
    #[arg(long, value_delimiter = ',', default_value = "50x40x30,100x80x60,200x160x120")]
    sizes: Vec<String>,
    /// Skip a method on a cloud when its time there, predicted from its previous cloud's time
    /// scaled by the voxel count, exceeds this many seconds; a note names the skipped runs.
    #[arg(long, default_value_t = 120.0)]
    max_seconds: f64,
    /// Scene files timed as they stand after the procedural sizes (their own grid, e.g.
    /// examples/disney16.toml: the Disney cloud at 1/16), one row per method each.
    #[arg(long, value_delimiter = ',')]
    clouds: Vec<PathBuf>,
    /// Override camera.width (pixels).
    #[arg(long)]
    width: Option<u32>,
    /// Override camera.height (pixels).
    #[arg(long)]
    height: Option<u32>,
}

impl BenchArgs {
    /// The scene keys the command line sets, with their flags (for the messages).
    fn flags(&self) -> Vec<(&'static str, &'static str)> {
        let given = [
            (self.width.is_some(), "camera.width", "--width"),
            (self.height.is_some(), "camera.height", "--height"),
        ];
        given.into_iter().filter(|g| g.0).map(|(_, k, f)| (k, f)).collect()
    }
}

/// Keeps the solver's one-line summaries (iterations per band), drops the progress bars and the
/// transport solver's line per iteration (its summary has the count).
struct Log(Mutex<Vec<String>>);

/// The start of the transport solver's per-iteration lines.
const PER_ITERATION: &str = "transport: iteration ";

impl Progress for Log {
    fn begin(&self, _: &str, _: u64) {}
    fn advance(&self, _: u64) {}
    fn end(&self) {}
    fn log(&self, msg: &str) {
        if msg.starts_with(PER_ITERATION) {
            return;
        }
        if let Ok(mut v) = self.0.lock() {
            v.push(msg.to_string());
        }
    }
    fn warn(&self, msg: &str) {
        self.log(&format!("warning: {msg}"));
    }
}

/// `NXxNYxNZ` as three positive counts.
fn parse_size(s: &str) -> Result<[usize; 3]> {
    let v: Vec<usize> = s.split('x').filter_map(|p| p.trim().parse().ok()).collect();
    match v[..] {
        [x, y, z] if x > 0 && y > 0 && z > 0 => Ok([x, y, z]),
        _ => Err(Error::invalid(
            "command line",
            "--sizes",
            format!("`{s}` is not NXxNYxNZ with positive counts, e.g. 100x80x60"),
        )),
    }
}

/// Seconds a run on a grid of `voxels` is predicted to take from the same method's run on a grid
/// of `prev` voxels that took `seconds`: proportional to the voxels (the methods' work is per
/// voxel).
fn predicted(prev: usize, seconds: f64, voxels: usize) -> f64 {
    seconds * voxels as f64 / prev.max(1) as f64
}

/// One table row: the cloud, the method, seconds per stage (in `stages`' order), the total and
/// the run's peak memory.
struct Row {
    cloud: String,
    /// Grid voxels (what the next cloud's time is predicted from).
    voxels: usize,
    method: Method,
    stages: Vec<(String, f64)>,
    total: f64,
    memory: Option<Peak>,
}

/// A run's peak resident memory above the process's resident memory at its start (bytes), and
/// the cloud's full voxels.
#[derive(Clone, Copy)]
struct Peak {
    bytes: u64,
    full_voxels: usize,
}

/// The process's resident memory, from /proc/self/status (Linux; None elsewhere).
mod resident {
    /// A `/proc/self/status` entry (`VmRSS:`, `VmHWM:`) in bytes.
    fn status(key: &str) -> Option<u64> {
        let text = std::fs::read_to_string("/proc/self/status").ok()?;
        let line = text.lines().find(|l| l.starts_with(key))?;
        let kb: u64 = line[key.len()..].trim().trim_end_matches("kB").trim().parse().ok()?;
        Some(kb * 1024)
    }

    /// Restart the peak (writing 5 to /proc/self/clear_refs sets it to the resident memory
    /// now) and return the resident memory now, the heap's free memory handed back first: a
    /// run that reused a larger run's freed pages would otherwise raise no peak at all.
    pub(super) fn restart_peak() -> Option<u64> {
        super::super::allocator::release_free_memory();
        std::fs::write("/proc/self/clear_refs", "5").ok()?;
        status("VmRSS:")
    }

    /// The peak since [`restart_peak`].
    pub(super) fn peak() -> Option<u64> {
        status("VmHWM:")
    }
}

/// One cloud of the table: its name and scene.
struct Cloud {
    name: String,
    desc: crate::scene::SceneDesc,
    source: String,
    base: PathBuf,
}

/// The markdown table: one column per stage any method ran (in order of first appearance),
/// the total, the total over that of the first method on the same cloud, and the run's peak
/// memory in all and per full voxel.
fn table(rows: &[Row]) -> String {
    let mut names: Vec<&str> = Vec::new();
    for r in rows {
        for (n, _) in &r.stages {
            if !names.contains(&n.as_str()) {
                names.push(n);
            }
        }
    }
    let first = rows.first().map(|r| r.method);
    let mut out = format!(
        "| cloud | method | {} | total | × {} | peak | B per full voxel |\n",
        names.join(" | "),
        first.map_or("", |m| m.name())
    );
    out += &format!("|---|---|{}---|---|---|---|\n", "---|".repeat(names.len()));
    for r in rows {
        let base = rows.iter().find(|b| b.cloud == r.cloud && Some(b.method) == first).map(|b| b.total);
        let cells: Vec<String> = names
            .iter()
            .map(|n| r.stages.iter().find(|s| s.0 == *n).map_or("–".into(), |s| format!("{:.2} s", s.1)))
            .collect();
        let ratio = base.filter(|b| *b > 0.0).map_or("–".into(), |b| format!("{:.1}", r.total / b));
        let (peak, per_voxel) = r.memory.map_or(("–".into(), "–".into()), |p| {
            (megabytes(p.bytes), format!("{:.0}", p.bytes as f64 / p.full_voxels.max(1) as f64))
        });
        out += &format!(
            "| {} | {} | {} | {:.2} s | {ratio} | {peak} | {per_voxel} |\n",
            r.cloud,
            r.method.name(),
            cells.join(" | "),
            r.total
        );
    }
    out
}

/// `bytes` in MB to 0.1 MB, or in kB below 0.1 MB (a small run's peak never reads 0.0 MB).
fn megabytes(bytes: u64) -> String {
    if bytes >= 100_000 {
        format!("{:.1} MB", bytes as f64 / 1e6)
    } else {
        format!("{:.0} kB", bytes as f64 / 1e3)
    }
}

pub fn run(a: BenchArgs) -> Result<()> {
    let sizes = a.sizes.iter().map(|s| parse_size(s)).collect::<Result<Vec<_>>>()?;
    if !(a.max_seconds > 0.0 && a.max_seconds <= crate::limits::MAX_SECONDS) {
        return Err(Error::invalid(
            "command line",
            "--max-seconds",
            format!(
                "{:?} is not allowed: it is a positive number of seconds, at most 1e9 (about 32 years), e.g. 60",
                a.max_seconds
            ),
        ));
    }
    let file = SceneFile::read(a.scene.as_deref())?;
    if file.desc.medium.grid != "procedural" {
        return Err(Error::invalid(
            &file.source,
            "medium.grid",
            "`cloudgi bench` scales the procedural cloud's resolution; set medium.grid = \"procedural\"",
        ));
    }
    let base = &file.desc.medium;
    let base_x = base.resolution[0] as f32;
    let mut clouds: Vec<Cloud> = sizes
        .iter()
        .map(|size| {
            let mut desc = file.desc.clone();
            desc.medium.resolution = *size;
            // The cloud's extent along x kept: every edge scaled alike.
            desc.medium.voxel_size = base.voxel_size.scaled(base_x / size[0] as f32);
            Cloud {
                name: format!("{}×{}×{}", size[0], size[1], size[2]),
                desc,
                source: file.source.clone(),
                base: file.base.clone(),
            }
        })
        .collect();
    for path in &a.clouds {
        let f = SceneFile::read(Some(path))?;
        clouds.push(Cloud {
            name: path
                .file_stem()
                .map_or_else(|| f.source.clone(), |s| s.to_string_lossy().into_owned()),
            desc: f.desc,
            source: f.source,
            base: f.base,
        });
    }
    let mut rows = Vec::new();
    let mut notes = Vec::new();
    for cloud in &clouds {
        for m in &a.methods {
            let method: Method = (*m).into();
            let mut desc = cloud.desc.clone();
            desc.render.method = method;
            if let Some(w) = a.width {
                desc.camera.width = w;
            }
            if let Some(h) = a.height {
                desc.camera.height = h;
            }
            super::memory::check_image(&desc, &cloud.source)?;
            let resident = resident::restart_peak();
            let scene = Scene::build(desc, &cloud.source, &cloud.base).map_err(|e| super::blamed_on_flags(e, &a.flags()))?;
            let voxels = scene.medium.density.len();
            let last = rows.iter().rev().find(|r: &&Row| r.method == method);
            if let Some(t) = last.map(|r| predicted(r.voxels, r.total, voxels)).filter(|t| *t > a.max_seconds) {
                notes.push(format!(
                    "{} {}: skipped, ≈ {t:.0} s predicted from {} (raise --max-seconds {} to run it)",
                    cloud.name,
                    method.name(),
                    last.map_or("", |r| &r.cloud),
                    a.max_seconds
                ));
                continue;
            }
            super::memory::check_solver(&scene, 0)?;
            let log = Log(Mutex::new(Vec::new()));
            let out = crate::render::render(&scene, &log)?;
            let memory = resident.zip(resident::peak()).map(|(start, peak)| Peak {
                bytes: peak.saturating_sub(start),
                full_voxels: scene.medium.density.count(),
            });
            for l in log.0.into_inner().unwrap_or_default() {
                notes.push(format!("{} {}: {l}", cloud.name, method.name()));
            }
            rows.push(Row {
                cloud: cloud.name.clone(),
                voxels,
                method,
                total: out.timings.total(),
                stages: out.timings.stages,
                memory,
            });
        }
    }
    let cam = &file.desc.camera;
    let mut text = format!(
        "{}×{} pixels, {} threads\n\n",
        a.width.unwrap_or(cam.width),
        a.height.unwrap_or(cam.height),
        rayon::current_num_threads()
    );
    text += &table(&rows);
    if !notes.is_empty() {
        text.push('\n');
    }
    for n in notes {
        text += &format!("- {n}\n");
    }
    super::console::print(&text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_or_name_the_flag() {
        assert_eq!(parse_size("100x80x60").unwrap(), [100, 80, 60]);
        for bad in ["100x80", "0x1x1", "axbxc"] {
            let e = parse_size(bad).unwrap_err().to_string();
            assert!(e.contains("--sizes"), "{e}");
        }
    }

    #[test]
    fn runs_are_predicted_by_voxels_and_per_iteration_lines_dropped() {
        assert_eq!(predicted(50 * 40 * 30, 4.0, 100 * 80 * 60), 32.0);
        let log = Log(Mutex::new(Vec::new()));
        log.log("transport: iteration 3, relative change of I0 2.09e-1");
        log.log("transport: 128 ordinates, order 7, 14 iterations");
        assert_eq!(log.0.into_inner().unwrap(), ["transport: 128 ordinates, order 7, 14 iterations"]);
    }

    #[test]
    fn table_has_a_column_per_stage_and_the_ratio_to_the_first_method() {
        let row = |method, stages: &[(&str, f64)]| Row {
            cloud: "2×2×2".into(),
            voxels: 8,
            memory: (method == Method::Diffusion).then_some(Peak {
                bytes: 2_500_000,
                full_voxels: 5,
            }),
            method,
            total: stages.iter().map(|s| s.1).sum(),
            stages: stages.iter().map(|(n, t)| (n.to_string(), *t)).collect(),
        };
        let t = table(&[
            row(Method::Single, &[("gather", 0.5)]),
            row(Method::Diffusion, &[("incident light", 1.0), ("gather", 1.0)]),
        ]);
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(
            lines[0],
            "| cloud | method | gather | incident light | total | × single | peak | B per full voxel |"
        );
        assert_eq!(lines[2], "| 2×2×2 | single | 0.50 s | – | 0.50 s | 1.0 | – | – |");
        assert_eq!(lines[3], "| 2×2×2 | diffusion | 1.00 s | 1.00 s | 2.00 s | 4.0 | 2.5 MB | 500000 |");
        assert_eq!(megabytes(56_000), "56 kB");
    }
}
