//! Sequences end to end: a grid sequence frame by frame (mixed grid sizes allowed), farm chunks
//! that write the same bits as one render of the whole range, `--skip-existing`, the keyframed
//! time-lapse, and a real Slurm array job (ci/slurm/start.sh; skipped with a message where Slurm
//! cannot start, a failure under CI=true).

use crate::common::{block_error, npy_grid, ok as cloudgi, BIN};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// A small procedural cloud whose sun sets over the frames (one scene file, one command).
const SUNSET: &str = "[medium]\nresolution = [20, 16, 12]\nvoxel_size = 50.0\n\
    [camera]\nwidth = 24\nheight = 18\n\
    [animation]\nframes = \"1-8\"\n\
    [[animation.key]]\nframe = 1\nsun.elevation_deg = 60.0\nsun.azimuth_deg = 40.0\n\
    [[animation.key]]\nframe = 8\nsun.elevation_deg = 5.0\nsun.azimuth_deg = 80.0\nmedium.sigma_t = 0.03\n";

fn bytes(p: &Path) -> Vec<u8> {
    std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// The EXR and PNG of each frame in `dir` equal those in `other`.
fn same_frames(dir: &Path, other: &Path, frames: impl IntoIterator<Item = u32>) {
    for f in frames {
        for ext in ["exr", "png"] {
            let name = format!("sun.{f:04}.{ext}");
            assert!(bytes(&dir.join(&name)) == bytes(&other.join(&name)), "{name} differs");
        }
    }
}

/// A float32 `.npy` of a ball of density falling from 1 at `centre` to 0 at `radius` (voxels).
fn blob(dims: [usize; 3], centre: [f32; 3], radius: f32) -> Vec<u8> {
    npy_grid(dims, |i, j, k| {
        let d = [i as f32 - centre[0], j as f32 - centre[1], k as f32 - centre[2]];
        let r = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        (1.0 - r / radius).max(0.0)
    })
}

#[test]
fn a_grid_sequence_renders_each_frame_and_frames_may_change_size() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A growing cloud: the second frame's grid is larger (simulations grow their box).
    std::fs::write(d.join("c.0001.npy"), blob([8, 8, 8], [3.5, 3.5, 3.5], 3.0)).unwrap();
    std::fs::write(d.join("c.0002.npy"), blob([12, 10, 9], [5.5, 4.5, 4.0], 4.5)).unwrap();
    let scene = "[medium]\ngrid = \"c.$F4.npy\"\nvoxel_size = 60.0\norigin = [-300.0, 100.0, -300.0]\n\
        [camera]\nwidth = 20\nheight = 16\n";
    std::fs::write(d.join("s.toml"), scene).unwrap();
    let err = cloudgi(d, &["render", "s.toml", "--frames", "1-2", "-o", "sun.%04d.exr", "--cold"]);
    assert!(err.contains("frame 2 (2 of 2)"), "a line per frame: {err}");
    // Each cold frame is the still render of its grid file.
    std::fs::write(d.join("still.toml"), scene.replace("c.$F4.npy", "c.0002.npy")).unwrap();
    cloudgi(d, &["render", "still.toml", "-o", "still.exr", "-q"]);
    assert!(bytes(&d.join("still.exr")) == bytes(&d.join("sun.0002.exr")));
    assert!(bytes(&d.join("sun.0001.exr")) != bytes(&d.join("sun.0002.exr")));
    // The warm start maps the first frame's solution onto the larger grid.
    let err = cloudgi(d, &["render", "s.toml", "--frames", "1-2", "-o", "warm.####.exr"]);
    assert!(err.contains("iterations (warm)"), "{err}");
    assert!(block_error(d, "warm.0002.exr", "sun.0002.exr") < 5e-3);
}

#[test]
fn chunks_write_the_bits_of_the_whole_range_and_skip_existing_resumes() {
    let (whole, chunks) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    for d in [whole.path(), chunks.path()] {
        std::fs::write(d.join("s.toml"), SUNSET).unwrap();
    }
    // Cold frames: the same bits however the range is split.
    let cold = ["render", "s.toml", "-o", "sun.####.exr", "--cold", "-q"];
    cloudgi(whole.path(), &cold);
    for i in ["0", "1", "2"] {
        cloudgi(chunks.path(), &[&cold[..], &["--task-index", i, "--task-count", "3"]].concat());
    }
    same_frames(whole.path(), chunks.path(), 1..=8);
    // The sun sets: the last frame differs from the first.
    assert!(bytes(&whole.path().join("sun.0001.exr")) != bytes(&whole.path().join("sun.0008.exr")));
    // An interrupted sequence: two frames lost; --skip-existing renders exactly those again.
    for f in ["sun.0003.exr", "sun.0006.png"] {
        std::fs::remove_file(chunks.path().join(f)).unwrap();
    }
    // An empty file in a frame's place is not a frame.
    std::fs::write(chunks.path().join("sun.0004.exr"), b"").unwrap();
    let err = cloudgi(
        chunks.path(),
        &["render", "s.toml", "-o", "sun.####.exr", "--cold", "--skip-existing"],
    );
    assert!(err.contains("3 to render, 5 skipped"), "{err}");
    same_frames(whole.path(), chunks.path(), 1..=8);
    // A PNG pattern names the previews: each frame's EXR goes beside its PNG, as for a still.
    let png = tempfile::tempdir().unwrap();
    std::fs::write(png.path().join("s.toml"), SUNSET).unwrap();
    cloudgi(
        png.path(),
        &["render", "s.toml", "-o", "sun.####.png", "--cold", "--frames", "7-8", "-q"],
    );
    same_frames(whole.path(), png.path(), 7..=8);
}

/// The iterations of each frame's solve, from the per-frame lines.
fn iterations(err: &str) -> Vec<usize> {
    err.lines()
        .filter(|l| l.starts_with("frame "))
        .filter_map(|l| {
            l.split(" · ")
                .find_map(|p| p.strip_suffix(" iterations (warm)").or(p.strip_suffix(" iterations (cold)")))
        })
        .map(|n| n.parse().unwrap())
        .collect()
}

/// The farm contract for warm starts (docs/sequences.md, "Warm starts"): warm and cold frames
/// both lie within the stated tolerance of the converged image (a solve to 1e-5), 0.4 of
/// `render.transport_tolerance` (`transport::warm::IMAGE_ERROR_FRACTION` × the default 5e-3), so
/// within twice it of each other, and each warm frame takes fewer iterations.
const IMAGE_BOUND: f64 = 0.4 * 5e-3;

#[test]
fn warm_frames_lie_within_the_stated_tolerance_of_converged_in_fewer_iterations() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A slowly changing sequence: the sun 2° lower and further round per frame.
    let scene = SUNSET.replace("frames = \"1-8\"", "frames = \"1-8x2\"").replace(
        "sun.elevation_deg = 5.0\nsun.azimuth_deg = 80.0\nmedium.sigma_t = 0.03\n",
        "sun.elevation_deg = 46.0\nsun.azimuth_deg = 54.0\n",
    );
    assert!(scene.contains("= 46.0"));
    std::fs::write(d.join("s.toml"), &scene).unwrap();
    let tight = "[render]\ntransport_tolerance = 1e-5\ntransport_max_iterations = 200\n";
    std::fs::write(d.join("tight.toml"), format!("{tight}{scene}")).unwrap();
    let warm = iterations(&cloudgi(d, &["render", "s.toml", "-o", "warm.####.exr"]));
    let cold = iterations(&cloudgi(d, &["render", "s.toml", "-o", "cold.####.exr", "--cold"]));
    cloudgi(d, &["render", "tight.toml", "-o", "tight.####.exr", "--cold", "-q"]);
    assert_eq!((warm.len(), cold.len()), (4, 4));
    assert_eq!(warm[0], cold[0], "the first frame is cold");
    assert!(warm.iter().zip(&cold).skip(1).all(|(w, c)| w < c), "warm {warm:?}, cold {cold:?}");
    for f in [3, 5, 7] {
        let cold_error = block_error(d, &format!("cold.{f:04}.exr"), &format!("tight.{f:04}.exr"));
        let warm_error = block_error(d, &format!("warm.{f:04}.exr"), &format!("tight.{f:04}.exr"));
        assert!(
            warm_error < IMAGE_BOUND && cold_error < IMAGE_BOUND,
            "frame {f}: warm {warm_error:.2e} and cold {cold_error:.2e} from converged (bound {IMAGE_BOUND:.0e})"
        );
    }
}

/// Why Slurm cannot run here, or None once ci/slurm/start.sh has it up.
fn start_slurm() -> Option<String> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("ci/slurm/start.sh");
    match Command::new("bash").arg(&script).output() {
        Ok(o) if o.status.success() => None,
        Ok(o) => Some(String::from_utf8_lossy(&o.stderr).trim().to_string()),
        Err(e) => Some(format!("cannot run {}: {e}", script.display())),
    }
}

/// Run a Slurm command; its stdout.
fn slurm(cmd: &str, args: &[&str]) -> String {
    let o = Command::new(cmd).args(args).output().unwrap();
    assert!(o.status.success(), "{cmd} {args:?}: {}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).trim().to_string()
}

/// Wait until job `id` has left the queue.
fn wait_for(id: &str) {
    let start = Instant::now();
    while !slurm("squeue", &["-h", "-j", id, "-o", "%i"]).is_empty() {
        assert!(start.elapsed() < Duration::from_secs(300), "job {id} still queued after 300 s");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Submit render.sbatch as an array over `array` with `tasks` chunks; the job id.
fn submit(dir: &Path, array: &str, tasks: &str, extra: &[&str]) -> String {
    let sbatch: PathBuf = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/farm/render.sbatch");
    let array = format!("--array={array}");
    let mut args = vec!["--parsable", "--hold", &array, "--chdir"];
    let d = dir.to_str().unwrap();
    args.extend([d, "--output", "slurm-%A_%a.log"]);
    let sbatch = sbatch.to_str().unwrap();
    args.extend([sbatch, "s.toml", "sun.####.exr", "-q"]);
    args.extend(extra);
    let o = Command::new("sbatch")
        .args(&args)
        .env("CLOUDGI", BIN)
        .env("CLOUDGI_TASKS", tasks)
        .output()
        .unwrap();
    assert!(o.status.success(), "sbatch: {}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).trim().split(';').next().unwrap().to_string()
}

#[test]
fn a_slurm_array_job_renders_the_frames_of_a_local_render() {
    if let Some(why) = start_slurm() {
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "CI must run the Slurm test, but Slurm cannot start: {why}"
        );
        eprintln!("SKIPPED a_slurm_array_job_renders_the_frames_of_a_local_render: Slurm cannot start here: {why}");
        return;
    }
    let (local, farm) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    for d in [local.path(), farm.path()] {
        std::fs::write(d.join("s.toml"), SUNSET).unwrap();
    }
    // 8 frames in 4 array elements (2 each); element 2 (frames 5-6) is cancelled before it runs.
    let job = submit(farm.path(), "0-3", "4", &[]);
    slurm("scancel", &[&format!("{job}_2")]);
    slurm("scontrol", &["release", &job]);
    // The local renders while Slurm schedules the farm's. Warm starts (the default) restart cold
    // at each chunk's first frame: the local render of each task's range is the farm's bits.
    for range in ["1-2", "3-4", "5-6", "7-8"] {
        cloudgi(local.path(), &["render", "s.toml", "--frames", range, "-o", "sun.####.exr", "-q"]);
    }
    wait_for(&job);
    let exists = |f: u32| farm.path().join(format!("sun.{f:04}.exr")).is_file();
    assert!(
        (1..=8).all(|f| exists(f) != (5..=6).contains(&f)),
        "the cancelled element's frames are missing, the rest are there"
    );
    // The whole array again with --skip-existing: only the missing chunk renders.
    let again = submit(farm.path(), "0-3", "4", &["--skip-existing"]);
    slurm("scontrol", &["release", &again]);
    wait_for(&again);
    same_frames(local.path(), farm.path(), 1..=8);
}

#[test]
fn a_warning_of_some_frames_is_printed_as_it_comes_and_at_the_end_naming_them() {
    let dir = tempfile::tempdir().unwrap();
    // The sun sets behind the ground from frame 3 on (-5°, -15°, -25°).
    let scene = "[medium]\nresolution = [8, 8, 8]\nvoxel_size = 100.0\n[camera]\nwidth = 8\nheight = 6\n[ground]\n\
        [animation]\nframes = \"1-5\"\n\
        [[animation.key]]\nframe = 1\nsun.elevation_deg = 15.0\nsun.azimuth_deg = 40.0\n\
        [[animation.key]]\nframe = 5\nsun.elevation_deg = -25.0\nsun.azimuth_deg = 40.0\n";
    std::fs::write(dir.path().join("s.toml"), scene).unwrap();
    let err = cloudgi(dir.path(), &["render", "s.toml", "--method", "single", "-o", "f.####.exr"]);
    // Printed as frame 3 comes, and at the end with every frame it held on.
    let hidden: Vec<&str> = err.lines().filter(|l| l.contains("below the horizon")).collect();
    assert_eq!(hidden.len(), 2, "{err}");
    assert!(
        hidden[0].starts_with("warning: frame 3: ") && hidden[0].contains("5.00° below"),
        "{err}"
    );
    assert!(
        hidden[1].starts_with("warning: frames 3-5 (the numbers are frame 3's): ") && hidden[1].contains("5.00° below"),
        "{err}"
    );
    let frame_3 = err.find("warning: frame 3: ").unwrap();
    assert!(
        err[..frame_3].contains("frame 2 (2 of 5)") && !err[..frame_3].contains("frame 3 (3 of 5)"),
        "{err}"
    );
}
