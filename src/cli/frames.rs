//! `render` over frames: `--frames`, a farm task's chunk (`--task-index`, `--task-count`),
//! `-o out.####.exr` and `--skip-existing`. Every frame's inputs and outputs are checked before
//! the first renders; each frame's EXR and PNG are written atomically, so an interrupted sequence
//! resumes with `--skip-existing`. The sequence itself (patterns, lists, keyframes) is
//! [`crate::sequence`].

use super::scene_file::SceneFile;
use super::{memory, output, progress, warnings, write_exr_and_png, RenderArgs};
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::render::warm::{render_warm, Warm};
use crate::scene::{Method, Scene, SceneDesc};
use crate::sequence::{FrameList, FramePattern, Sequence};
use clap::Args;
use std::path::PathBuf;
use std::time::Instant;

/// The frame flags of `render`.
#[derive(Args, Debug)]
pub struct FrameArgs {
    /// Frames to render: `1-240`, `1-240x2` (every 2nd), `1,5,9-12` (default: animation.frames).
    #[arg(long)]
    frames: Option<String>,
    /// A farm task: render the I-th (from 0) of --task-count contiguous chunks of the frames
    /// (`sbatch --array=0-15 … --task-index $SLURM_ARRAY_TASK_ID --task-count 16`).
    #[arg(long, value_name = "I", requires = "task_count")]
    task_index: Option<usize>,
    /// The number of chunks the frames are split into (see --task-index).
    #[arg(long, value_name = "N", requires = "task_index")]
    task_count: Option<usize>,
    /// Leave every frame whose EXR and PNG both exist (resumes an interrupted sequence).
    #[arg(long)]
    skip_existing: bool,
    /// Solve every frame from nothing. By default `transport` starts each frame from the
    /// previous frame's solution (a chunk's first frame is cold); warm and cold frames both lie
    /// within 0.4 × render.transport_tolerance of the converged image (docs/sequences.md), cold
    /// frames are the same bits however the range is split.
    #[arg(long)]
    cold: bool,
}

/// Whether `render` runs as a sequence: a frame flag, a frame pattern in `-o`, or an animated
/// scene (a grid pattern, `[animation]`).
pub fn is_sequence(a: &RenderArgs, file: &SceneFile) -> bool {
    let f = &a.frames;
    f.frames.is_some()
        || f.task_index.is_some()
        || f.skip_existing
        || file.desc.animation.is_some()
        || FramePattern::parse(&a.output.to_string_lossy(), "", "").map_or(true, |p| p.is_some())
        || FramePattern::parse(&file.desc.medium.grid, "", "").map_or(true, |p| p.is_some())
}

/// One frame to render: its number, description and output files.
struct Frame {
    number: u32,
    desc: SceneDesc,
    exr: PathBuf,
    png: PathBuf,
}

/// An error found for one frame names it.
fn at_frame(e: Error, frame: u32) -> Error {
    match e {
        Error::Invalid { file, field, message } => Error::Invalid {
            file,
            field,
            message: format!("{message} (frame {frame})"),
        },
        e => e,
    }
}

/// The frames the command line and the scene ask for, before the task split.
fn requested(f: &FrameArgs, seq: &Sequence, output_pattern: bool) -> Result<FrameList> {
    if let Some(t) = &f.frames {
        return FrameList::parse(t, "command line", "--frames");
    }
    if let Some(l) = seq.frames() {
        return Ok(l.clone());
    }
    let why = if seq.is_animated() {
        "the scene is animated (a frame pattern in medium.grid, or [animation] keys)"
    } else if output_pattern {
        "--output names a frame pattern"
    } else if f.task_index.is_some() {
        "--task-index splits the frames into chunks"
    } else {
        // A still with --skip-existing: one frame, its number unused.
        return Ok(FrameList::single(0));
    };
    Err(Error::invalid(
        "command line",
        "--frames",
        format!("{why} but no frames are given; pass --frames (e.g. --frames 1-240) or set animation.frames in the scene"),
    ))
}

/// This task's frames: the chunk `--task-index` of `--task-count`, or all of them.
fn chunk(f: &FrameArgs, all: &FrameList) -> Result<FrameList> {
    let (Some(i), Some(n)) = (f.task_index, f.task_count) else {
        return Ok(all.clone());
    };
    if n == 0 {
        return Err(Error::invalid("command line", "--task-count", "must be at least 1"));
    }
    if i >= n {
        return Err(Error::invalid(
            "command line",
            "--task-index",
            format!(
                "task {i} is out of range for --task-count {n}: tasks are numbered 0 to {} (sbatch --array=0-{})",
                n - 1,
                n - 1
            ),
        ));
    }
    Ok(all.chunk(i, n))
}

/// The first bytes of an OpenEXR file and of a PNG.
const EXR_MAGIC: &[u8] = &[0x76, 0x2f, 0x31, 0x01];
const PNG_MAGIC: &[u8] = &[0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];

/// Whether `path` is a file that begins with `magic`: `--skip-existing` takes an empty or foreign
/// file in a frame's place as not done (the frames themselves are renamed into place whole).
fn starts_with(path: &std::path::Path, magic: &[u8]) -> bool {
    use std::io::Read;
    let mut head = vec![0u8; magic.len()];
    std::fs::File::open(path).and_then(|mut f| f.read_exact(&mut head)).is_ok() && head == magic
}

/// Render the frames `a` asks for.
pub fn render(a: &RenderArgs, file: &SceneFile, quiet: bool) -> Result<()> {
    let seq = Sequence::new(&file.desc, &file.source)?;
    let out_pattern = FramePattern::parse(&a.output.to_string_lossy(), "command line", "--output")?;
    let all = requested(&a.frames, &seq, out_pattern.is_some())?;
    if out_pattern.is_none() && all.frames().len() > 1 {
        return Err(Error::invalid(
            "command line",
            "--output",
            format!(
                "`{}` has no frame pattern but {} frames ({all}) are asked for; name each frame's file with one, e.g. `-o out.####.exr`",
                a.output.display(),
                all.frames().len()
            ),
        ));
    }
    let frames = chunk(&a.frames, &all)?;
    let mut todo = Vec::new();
    let mut skipped = 0;
    for &n in frames.frames() {
        let name = out_pattern.as_ref().map_or_else(|| a.output.clone(), |p| PathBuf::from(p.name(n)));
        // `-o out.####.png` names the PNG: the EXR goes beside it, as for a still.
        let (exr, png) = super::tonemap::outputs(&name)?;
        if a.frames.skip_existing && starts_with(&exr, EXR_MAGIC) && starts_with(&png, PNG_MAGIC) {
            skipped += 1;
            continue;
        }
        let mut desc = seq.desc_at(n);
        a.apply(&mut desc);
        output::check_files(&[&exr, &png], "--output", &file.inputs(&desc))?;
        // Each frame's keyed values within the scene's limits before any frame renders.
        crate::scene::check_magnitudes(&desc, &file.source).map_err(|e| at_frame(e, n))?;
        memory::check_image(&desc, &file.source).map_err(|e| at_frame(e, n))?;
        Camera::from_desc(&desc.camera, &file.source).map_err(|e| at_frame(e, n))?;
        todo.push(Frame { number: n, desc, exr, png });
    }
    let numbers: Vec<u32> = todo.iter().map(|f| f.number).collect();
    seq.check_grid_files(&numbers, &file.base, &file.source)?;
    if !quiet {
        let task = match (a.frames.task_index, a.frames.task_count) {
            (Some(i), Some(n)) => format!("task {i} of {n}: "),
            _ => String::new(),
        };
        let skip = if skipped > 0 {
            format!(", {skipped} skipped (their EXR and PNG exist)")
        } else {
            String::new()
        };
        note!("{task}frames {frames} of {all}: {} to render{skip}", todo.len());
    }
    let start = Instant::now();
    let mut warm = Warm::new(!a.frames.cold);
    let (mut shown, mut per_frame) = (std::collections::HashSet::new(), Vec::with_capacity(todo.len()));
    for (i, frame) in todo.iter().enumerate() {
        let t = Instant::now();
        let scene = Scene::build(frame.desc.clone(), &file.source, &file.base)
            .map_err(|e| at_frame(super::blamed_on_flags(e, &a.flags()), frame.number))?;
        let kept = memory::warm_state_bytes(&scene, warm.bytes(), warm.enabled);
        memory::check_solver(&scene, kept).map_err(|e| at_frame(e, frame.number))?;
        // Each warning the first time its kind comes (its keyed sun, extinction and camera, its
        // grid file), before the frame renders; at the end, those that held on only some frames.
        let frame_warnings = warnings::warnings(file, &a.flags(), &scene);
        for w in frame_warnings.iter().filter(|w| shown.insert(warnings::kind(w))) {
            match i {
                0 => note!("warning: {w}"),
                _ => note!("warning: frame {}: {w}", frame.number),
            }
        }
        per_frame.push((frame.number, frame_warnings));
        let was_warm = warm.is_warm();
        let out = render_warm(&scene, &progress::Bars::new(quiet), &mut warm)?;
        // Each frame's preview as a still's: --exposure, render.exposure, or its own automatic one.
        let (stops, _) = super::tonemap::stops(a.exposure, Some(file), &out.image);
        write_exr_and_png(&out.image, &frame.exr, &frame.png, stops)?;
        if !quiet {
            let done = i + 1;
            let elapsed = start.elapsed().as_secs_f64();
            let eta = elapsed / done as f64 * (todo.len() - done) as f64;
            let kind = match scene.render.method {
                Method::Transport => "iterations",
                _ => "CG iterations",
            };
            let solve = match warm.iterations {
                Some(n) => format!(" · {n} {kind}{}", if was_warm { " (warm)" } else { " (cold)" }),
                None => String::new(),
            };
            note!(
                "frame {} ({done} of {}): {} {}×{} → {} + {} · {:.2} s{solve} · sequence {elapsed:.1} s, eta {eta:.0} s",
                frame.number,
                todo.len(),
                scene.render.method.name(),
                scene.camera.width,
                scene.camera.height,
                frame.exr.display(),
                frame.png.display(),
                t.elapsed().as_secs_f64()
            );
        }
    }
    for w in warnings::over_some_frames(&per_frame) {
        note!("warning: {w}");
    }
    Ok(())
}
