//! The bad-input catalogue: one row per kind of bad input (scene text, grid file or command-line
//! arguments) with the fragments its message must contain. Each row runs the binary in a fresh
//! folder and asserts a non-zero exit that is not a panic, every fragment, and that no file was
//! written. Most rows fail before any rendering, in milliseconds. The warnings for settings that
//! do not apply (the render still runs) and the first-use defaults are checked at the end.

use crate::common::{data, f32s, npy, BIN};
use std::path::{Path, PathBuf};
use std::process::Command;

/// Little-endian bytes of `v`.
fn f64s(v: &[f64]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// A file a row writes into its folder first: name and bytes.
type File = (&'static str, Vec<u8>);

/// Run the binary in `dir`: (exit code, stdout, stderr).
fn run_in(dir: &Path, args: &[&str]) -> (i32, String, String) {
    let out = Command::new(BIN).current_dir(dir).args(args).output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).to_string(),
        String::from_utf8_lossy(&out.stderr).to_string(),
    )
}

/// Every path under `dir`, relative, sorted.
fn listing(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p.clone());
            }
            out.push(p.strip_prefix(dir).unwrap().to_path_buf());
        }
    }
    out.sort();
    out
}

fn write_files(dir: &Path, files: &[File]) {
    for (name, bytes) in files {
        let p = dir.join(name);
        if name.ends_with('/') {
            std::fs::create_dir_all(&p).unwrap();
        } else {
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, bytes).unwrap();
        }
    }
}

/// Run `args` in a fresh folder holding `files`: a clean failure that mentions every fragment of
/// `expect` and leaves the folder as it was.
fn fails(files: &[File], args: &[&str], expect: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    write_files(dir.path(), files);
    let before = listing(dir.path());
    let (code, _, err) = run_in(dir.path(), args);
    let row = format!("{args:?} with {:?}", files.iter().map(|f| f.0).collect::<Vec<_>>());
    assert_ne!(code, 0, "must fail: {row}");
    assert_ne!(code, 101, "panicked: {row}: {err}");
    assert!(!err.contains("panicked"), "panicked: {row}: {err}");
    for e in expect {
        assert!(err.contains(e), "{row}: message `{}` should mention `{e}`", err.trim_end());
    }
    assert_eq!(listing(dir.path()), before, "{row} wrote files");
}

/// `scene` as s.toml (plus `files`), rendered at 8×8.
fn render_fails(scene: &str, files: &[File], expect: &[&str]) {
    let mut all = vec![("s.toml", scene.as_bytes().to_vec())];
    all.extend(files.iter().cloned());
    fails(
        &all,
        &["render", "s.toml", "-o", "out.exr", "--width", "8", "--height", "8", "--quiet"],
        expect,
    );
}

fn scene_rows(rows: &[(&str, &[&str])]) {
    for (scene, expect) in rows {
        render_fails(scene, &[], expect);
    }
}

#[test]
fn scene_text_that_is_not_a_scene() {
    scene_rows(&[
        ("this is not toml", &["s.toml"]),
        ("[medium]\nsigma_t = 0.1\nsigma_t = 0.2\n", &["s.toml", "duplicate"]),
        ("[foo]\nx = 1\n", &["s.toml", "foo"]),
        ("[medium]\nsigmat = 0.1\n", &["s.toml", "sigmat"]),
        ("[medium]\nsigma_t = \"thick\"\n", &["s.toml", "sigma_t"]),
        ("[medium]\norigin = [1.0, 2.0]\n", &["s.toml", "origin"]),
        ("[camera]\nwidth = -5\n", &["s.toml", "width"]),
        ("[render]\nmethod = \"magic\"\n", &["s.toml", "magic"]),
        ("[sky]\nmodel = \"preetham\"\n", &["s.toml", "preetham"]),
        ("[ground]\nenabled = \"no\"\n", &["s.toml", "enabled"]),
        ("medium = 3\n", &["s.toml", "medium"]),
    ]);
    // Not UTF-8: say that a TOML scene file is expected.
    fails(
        &[("s.toml", vec![0xff, 0xfe, b'[', 0x00])],
        &["render", "s.toml", "-q"],
        &["s.toml", "not UTF-8", "TOML"],
    );
    fails(&[], &["render", "nope.toml", "-q"], &["nope.toml"]);
    // A folder where the scene file should be: said so, not the OS's "Is a directory".
    fails(
        &[("d.toml/", vec![])],
        &["render", "d.toml", "-q"],
        &["d.toml", "a folder, not a scene file"],
    );
    // Neither .toml nor a grid type: read as a scene, and the message says so.
    fails(
        &[("g.xyz", b"abc".to_vec())],
        &["render", "g.xyz", "-q"],
        &["g.xyz", "TOML", ".vdb, .npy, .vol or .raw"],
    );
    fails(
        &[("g.vdb.gz", vec![0x1f, 0x8b, 0x08, 0xff])],
        &["render", "g.vdb.gz", "-q"],
        &["g.vdb.gz", "not UTF-8", ".vdb, .npy, .vol or .raw"],
    );
}

#[test]
fn bad_medium_values() {
    scene_rows(&[
        ("[medium]\nsigma_t = -0.1\n", &["s.toml", "medium.sigma_t", "non-negative"]),
        ("[medium]\nsigma_t = nan\n", &["s.toml", "medium.sigma_t"]),
        ("[medium]\nsigma_t = inf\n", &["s.toml", "medium.sigma_t"]),
        ("[medium]\nalbedo = [0.5, 1.2, 0.5]\n", &["s.toml", "medium.albedo", "[0, 1]"]),
        ("[medium]\nalbedo = [nan, 0.5, 0.5]\n", &["s.toml", "medium.albedo"]),
        ("[medium]\ng = 1.0\n", &["s.toml", "medium.g", "within ±0.999"]),
        ("[medium]\ng = -0.9999\n", &["s.toml", "medium.g", "within ±0.999", "too bright"]),
        ("[medium]\ng = -1.5\n", &["s.toml", "medium.g"]),
        ("[medium]\ng = nan\n", &["s.toml", "medium.g"]),
        ("[medium]\ndownsample = 0\n", &["s.toml", "medium.downsample"]),
        ("[medium]\ndownsample = 65\n", &["s.toml", "medium.downsample"]),
        ("[medium]\nrefine = 0\n", &["s.toml", "medium.refine", "odd"]),
        ("[medium]\nrefine = 2\n", &["s.toml", "medium.refine", "odd"]),
        ("[medium]\nrefine = 9\n", &["s.toml", "medium.refine", "7"]),
        (
            "[medium]\nrefine = 3\ndownsample = 2\n",
            &["s.toml", "medium.refine", "medium.downsample"],
        ),
        (
            "[medium]\nrefine = 7\nmax_voxels = 1000000\n",
            &["medium.refine (= 7", "medium.max_voxels"],
        ),
        ("[medium]\nmax_voxels = 0\n", &["s.toml", "medium.max_voxels"]),
        ("[medium]\nresolution = [0, 10, 10]\n", &["s.toml", "medium.resolution"]),
        ("[medium]\nresolution = [5000, 10, 10]\n", &["s.toml", "medium.resolution"]),
        // The memory guard names the key to change.
        (
            "[medium]\nresolution = [1000, 1000, 1000]\n",
            &["s.toml", "field `medium.resolution`", "medium.max_voxels = 200000000"],
        ),
        ("[medium]\nvoxel_size = 0.0\n", &["s.toml", "medium.voxel_size"]),
        // Too small for f32 positions 500 m out: said so, not blamed on the framed camera.
        ("[medium]\nvoxel_size = 1e-30\n", &["s.toml", "medium.voxel_size", "units"]),
        ("[medium]\nvoxel_size = -1.0\n", &["s.toml", "medium.voxel_size"]),
        (
            "[medium]\nvoxel_size = [10.0, 0.0, 10.0]\n",
            &["s.toml", "medium.voxel_size", "[x, y, z]"],
        ),
        (
            "[medium]\nvoxel_size = [10.0, 10.0]\n",
            &["s.toml", "voxel_size", "one per axis [x, y, z]"],
        ),
        (
            "[medium]\nresolution = [4, 4, 4]\nvoxel_size = [10.0, 1e20, 10.0]\n",
            &["s.toml", "medium.voxel_size", "1e6 m"],
        ),
        (
            "[medium]\nresolution = [4, 4, 4]\nvoxel_size = 1e20\n",
            // The value as the file writes it, not glam's `Vec3(…)`.
            &["s.toml", "medium.voxel_size", "[1e20, 1e20, 1e20] is not allowed", "1e6 m"],
        ),
        (
            "[medium]\nresolution = [8, 8, 8]\norigin = [nan, 0.0, 0.0]\n",
            &["s.toml", "medium.origin"],
        ),
        // A missing grid file names the key.
        ("[medium]\ngrid = \"nope.vol\"\n", &["s.toml", "medium.grid", "nope.vol"]),
        ("[medium]\ngrid = \"\"\n", &["s.toml", "medium.grid"]),
    ]);
    render_fails(
        "[medium]\ngrid = \"g.txt\"\n",
        &[("g.txt", b"1 2 3".to_vec())],
        &["s.toml", "medium.grid", "unsupported grid file type"],
    );
}

#[test]
fn bad_lights_ground_camera_and_render_keys() {
    scene_rows(&[
        ("[sun]\ndirection = [0.0, 0.0, 0.0]\n", &["s.toml", "sun.direction"]),
        ("[sun]\ndirection = [nan, 1.0, 0.0]\n", &["s.toml", "sun.direction"]),
        ("[sun]\ndirection = [0.0, 1.0, 0.0]\nelevation_deg = 30.0\n", &["s.toml", "sun."]),
        ("[sun]\nelevation_deg = 100.0\nazimuth_deg = 0.0\n", &["s.toml", "sun."]),
        ("[sun]\nazimuth_deg = 30.0\n", &["s.toml", "sun.azimuth_deg", "sun.elevation_deg"]),
        ("[sun]\nelevation_deg = nan\n", &["s.toml", "sun.elevation_deg"]),
        ("[sun]\nirradiance = [-1.0, 3.0, 3.0]\n", &["s.toml", "sun.irradiance"]),
        ("[sun]\nangular_diameter_deg = -1.0\n", &["s.toml", "sun.angular_diameter_deg"]),
        ("[sun]\nangular_diameter_deg = 50.0\n", &["s.toml", "sun.angular_diameter_deg"]),
        ("[sky]\nradiance = [-0.1, 0.4, 0.8]\n", &["s.toml", "sky.radiance"]),
        ("[sky]\nradiance = [nan, 0.4, 0.8]\n", &["s.toml", "sky.radiance"]),
        ("[sky]\nmodel = \"envmap\"\n", &["s.toml", "sky.path"]),
        (
            "[sky]\nmodel = \"envmap\"\npath = \"nope.exr\"\n",
            &["s.toml", "sky.path", "nope.exr"],
        ),
        ("[sky]\nmodel = \"atmosphere\"\naltitude_m = -1.0\n", &["s.toml", "sky.altitude_m"]),
        ("[sky]\nmodel = \"atmosphere\"\nmap_width = 0\n", &["s.toml", "sky.map_width"]),
        (
            "[sky]\nmodel = \"atmosphere\"\nplanet_albedo = [2.0, 0.3, 0.3]\n",
            &["s.toml", "sky.planet_albedo"],
        ),
        ("[ground]\nalbedo = [1.5, 0.3, 0.3]\n", &["s.toml", "ground.albedo"]),
        ("[ground]\nheight = nan\n", &["s.toml", "ground.height"]),
        (
            "[camera]\nposition = [0.0, 100.0, 0.0]\nlook_at = [0.0, 0.0, 0.0]\nup = [0.0, 1.0, 0.0]\n",
            &[
                "s.toml",
                "camera.up",
                "parallel",
                "[0.0, -100.0, 0.0]",
                "[0.0, 0.0, -1.0] or [0.0, 0.0, 1.0]",
            ],
        ),
        ("[camera]\nup = [0.0, 0.0, 0.0]\n", &["s.toml", "camera.up"]),
        (
            "[camera]\nposition = [0.0, 330.0, 0.0]\nlook_at = [0.0, 330.0, 0.0]\n",
            &["s.toml", "camera.look_at"],
        ),
        ("[camera]\nposition = [nan, 0.0, 0.0]\n", &["s.toml", "camera.position"]),
        ("[camera]\nfov_deg = 0.0\n", &["s.toml", "camera.fov_deg"]),
        ("[camera]\nfov_deg = 180.0\n", &["s.toml", "camera.fov_deg"]),
        ("[render]\nspp = 0\n", &["s.toml", "render.spp"]),
        // One sample has no standard error: the whole layer would be infinite.
        (
            "[render]\nmethod = \"reference\"\nstderr = true\n",
            &["s.toml", "render.stderr", "--spp 2"],
        ),
        ("[render]\naa_samples = 0\n", &["s.toml", "render.aa_samples"]),
        ("[render]\nexposure = nan\n", &["s.toml", "render.exposure"]),
        ("[render]\nstep = 0.0\n", &["s.toml", "render.step"]),
        ("[render]\nstep = 5.0\n", &["s.toml", "render.step"]),
        // A step too fine to end: the march would take 5e31 samples per voxel.
        ("[render]\nstep = 1e-30\n", &["s.toml", "render.step", "0.01"]),
        ("[render]\ntime_limit = -1.0\n", &["s.toml", "render.time_limit"]),
        ("[render]\ntime_limit = 1e300\n", &["s.toml", "render.time_limit", "1e300", "1e9"]),
        ("[render]\ncube_resolution = 6\n", &["s.toml", "render.cube_resolution"]),
        ("[render]\nground_samples = 0\n", &["s.toml", "render.ground_samples"]),
        (
            "[render]\nlow_density_threshold = -1.0\n",
            &["s.toml", "render.low_density_threshold"],
        ),
        ("[render]\niterations = 21\n", &["s.toml", "render.iterations"]),
        (
            "[render]\npropagation_tolerance = -1.0\n",
            &["s.toml", "render.propagation_tolerance"],
        ),
        ("[render]\nsolver_tolerance = 2.0\n", &["s.toml", "render.solver_tolerance"]),
        ("[render]\nsolver_max_iterations = 0\n", &["s.toml", "render.solver_max_iterations"]),
        ("[render]\ntransport_order = 0\n", &["s.toml", "render.transport_order", "1 to 15"]),
        ("[render]\ntransport_order = 16\n", &["s.toml", "render.transport_order", "1 to 15"]),
        (
            "[render]\ntransport_order = 9\n",
            &[
                "s.toml",
                "render.transport_polar_ordinates",
                "8 is less than render.transport_order + 1 = 10",
                "= 10",
            ],
        ),
        (
            "[render]\ntransport_polar_ordinates = 7\n",
            &["s.toml", "render.transport_polar_ordinates", "even"],
        ),
        (
            "[render]\ntransport_polar_ordinates = 0\n",
            &["s.toml", "render.transport_polar_ordinates"],
        ),
        (
            "[render]\ntransport_polar_ordinates = 34\n",
            &["s.toml", "render.transport_polar_ordinates"],
        ),
        (
            "[render]\ntransport_tolerance = 0.0\n",
            &["s.toml", "render.transport_tolerance", "(0, 1)"],
        ),
        ("[render]\ntransport_tolerance = 1.0\n", &["s.toml", "render.transport_tolerance"]),
        ("[render]\ntransport_tolerance = nan\n", &["s.toml", "render.transport_tolerance"]),
        (
            "[render]\ntransport_max_iterations = 0\n",
            &["s.toml", "render.transport_max_iterations"],
        ),
        (
            "[render]\ntransport_acceleration = \"yes\"\n",
            &["s.toml", "transport_acceleration"],
        ),
    ]);
    render_fails(
        "[sky]\nmodel = \"envmap\"\npath = \"env.exr\"\n",
        &[("env.exr", b"not an image".to_vec())],
        &["env.exr"],
    );
    // Each factor within the light bound, their product past it: named with the file and the fix.
    let mut bright = cloudgi::Image::new(4, 2);
    bright.pixels.fill(cloudgi::Rgb::splat(1e20));
    render_fails(
        "[sky]\nmodel = \"envmap\"\npath = \"env.exr\"\nscale = 1e20\n",
        &[("env.exr", bright.to_exr_bytes().unwrap())],
        &["s.toml", "sky.scale", "env.exr", "1e30"],
    );
    // A NaN in the map: named by pixel, in the same words as the light it stands for.
    let mut holed = cloudgi::Image::new(4, 2);
    holed.pixels[5] = cloudgi::Rgb::new(0.1, f32::NAN, 0.1);
    render_fails(
        "[sky]\nmodel = \"envmap\"\npath = \"env.exr\"\n",
        &[("env.exr", holed.to_exr_bytes().unwrap())],
        &["env.exr", "pixel (1, 1) is [0.1, NaN, 0.1]", "finite, non-negative"],
    );
}

// ------------------------------------------------------------------------------- grid files

/// A Mitsuba .vol: version, encoding, dims, channels, bbox, values, then `truncate` bytes cut.
fn vol_full(version: u8, enc: i32, dims: [i32; 3], ch: i32, bbox: [f32; 6], values: &[f32], truncate: usize) -> Vec<u8> {
    let mut b = b"VOL".to_vec();
    b.push(version);
    for v in [enc, dims[0], dims[1], dims[2], ch] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    for v in bbox.iter().chain(values) {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b.truncate(b.len() - truncate);
    b
}

fn vol(dims: [i32; 3], values: &[f32], truncate: usize) -> Vec<u8> {
    vol_full(3, 1, dims, 1, [0.0, 0.0, 0.0, 1.0, 1.0, 1.0], values, truncate)
}

fn grid_fails(grid: &str, files: &[File], expect: &[&str]) {
    render_fails(&format!("[medium]\ngrid = \"{grid}\"\n"), files, expect);
}

fn vdb_data(name: &str) -> Vec<u8> {
    std::fs::read(data("vdb").join(name)).unwrap()
}

#[test]
fn corrupt_vol_files() {
    let ones = [1.0f32; 8];
    let rows: Vec<(Vec<u8>, &[&str])> = vec![
        (vol([0, 2, 2], &[], 0), &["g.vol", "zero size"]),
        (vol([2, 2, 2], &ones, 5), &["g.vol", "truncated"]),
        (vol([2, 2, 2], &ones, 0)[..20].to_vec(), &["g.vol", "truncated"]),
        (
            vol([2, 2, 2], &[1.0, f32::NAN, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0], 0),
            &["g.vol", "voxel (x, y, z) = (1, 0, 0), array index [0, 0, 1]", "finite"],
        ),
        (
            vol([2, 2, 2], &[1.0, 1.0, 1.0, -0.5, 1.0, 1.0, 1.0, 1.0], 0),
            &["g.vol", "non-negative"],
        ),
        // Hostile header: a huge declared size must not allocate.
        (vol([1 << 20, 1 << 20, 1 << 20], &[1.0; 4], 0), &["g.vol"]),
        (vol([-2, 2, 2], &ones, 0), &["g.vol", "negative resolution"]),
        (
            b"XYZ\x03and more bytes than a header needs, forty-eight at least......".to_vec(),
            &["g.vol", "VOL"],
        ),
        (
            vol_full(2, 1, [2, 2, 2], 1, [0.0, 0.0, 0.0, 1.0, 1.0, 1.0], &ones, 0),
            &["g.vol", "version 2"],
        ),
        (
            vol_full(3, 2, [2, 2, 2], 1, [0.0, 0.0, 0.0, 1.0, 1.0, 1.0], &ones, 0),
            &["g.vol", "encoding 2"],
        ),
        (
            vol_full(3, 1, [2, 2, 2], 3, [0.0, 0.0, 0.0, 1.0, 1.0, 1.0], &[1.0; 24], 0),
            &["g.vol", "3 channels"],
        ),
        (
            vol_full(3, 1, [2, 2, 2], 1, [0.0, 0.0, 0.0, 1.0, 0.0, 1.0], &ones, 0),
            &["g.vol", "bounding box"],
        ),
        (
            vol_full(3, 1, [2, 2, 2], 1, [0.0, 0.0, 0.0, 1.0, f32::NAN, 1.0], &ones, 0),
            &["g.vol", "bounding box"],
        ),
    ];
    for (bytes, expect) in rows {
        grid_fails("g.vol", &[("g.vol", bytes)], expect);
    }
    // A grid over medium.max_voxels names both ways out.
    render_fails(
        "[medium]\ngrid = \"g.vol\"\nmax_voxels = 4\n",
        &[("g.vol", vol([2, 2, 2], &ones, 0))],
        &["medium.max_voxels", "medium.downsample"],
    );
    // Transport's memory is estimated from the loaded grid (8 M full voxels × 6.5 kB at order 15
    // is 52 GB, twice the CI machine's memory) and refused, for that method, before the solve
    // allocates it.
    let n = 200;
    let cube = vol([n; 3], &vec![1.0; (n * n * n) as usize], 0);
    render_fails(
        "[medium]\ngrid = \"g.vol\"\n[render]\ntransport_order = 15\ntransport_polar_ordinates = 16\n",
        &[("g.vol", cube)],
        &[
            "s.toml",
            "method transport",
            "GiB",
            "render.transport_order = 15",
            "medium.downsample",
        ],
    );
}

#[test]
fn corrupt_npy_raw_and_vdb_files() {
    let four = f32s(&[1.0; 4]);
    let npy_rows: Vec<(Vec<u8>, &[&str])> = vec![
        (b"NUMPY not really".to_vec(), &["g.npy", "magic"]),
        (b"\x93NUMPY\x01\x00\xff\x00{".to_vec(), &["g.npy", "truncated"]),
        (
            npy("{'descr': '<f4', 'fortran_order': False, 'shape': (2, 2, 2), }", &four),
            &["g.npy", "truncated"],
        ),
        (
            npy("{'descr': '<c8', 'fortran_order': False, 'shape': (1, 2, 2), }", &four),
            &["g.npy", "'<c8'", "float16/32/64", "bool"],
        ),
        // An integer array read by value: a negative one is not a density.
        (
            npy("{'descr': '|i1', 'fortran_order': False, 'shape': (1, 2, 2), }", &[1, 0xfe, 3, 4]),
            &["g.npy", "is -2", "non-negative"],
        ),
        (
            npy("{'descr': '<f4', 'fortran_order': False, 'shape': (2, 2), }", &four),
            &["g.npy", "2 dimensions"],
        ),
        (npy("{'fortran_order': False, 'shape': (1, 2, 2), }", &four), &["g.npy", "descr"]),
        // Named by the array's shape, not (nx, ny, nz) reversed.
        (
            npy("{'descr': '<f4', 'fortran_order': False, 'shape': (0, 2, 3), }", &[]),
            &["g.npy", "array of shape (0, 2, 3) holds no voxel", "[z][y][x]"],
        ),
        (
            npy("{'descr': '<f4', 'fortran_order': False, 'shape': (4,), }", &four),
            &["g.npy", "has 1 dimension;"],
        ),
        (
            npy(
                "{'descr': '<f4', 'fortran_order': False, 'shape': (1, 2, 2), }",
                &f32s(&[1.0, 1.0, f32::INFINITY, 1.0]),
            ),
            &["g.npy", "finite"],
        ),
        // A finite float64 past f32's range: named as what the file holds, not as an infinity.
        (
            npy(
                "{'descr': '<f8', 'fortran_order': False, 'shape': (1, 2, 2), }",
                &f64s(&[1.0, 1e300, 1.0, 1.0]),
            ),
            &["g.npy", "value 1 is 1e300", "float32", "medium.sigma_t"],
        ),
    ];
    for (bytes, expect) in npy_rows {
        grid_fails("g.npy", &[("g.npy", bytes)], expect);
    }
    let raw = |json: &str, data: Vec<u8>| vec![("g.raw", data), ("g.json", json.as_bytes().to_vec())];
    // A missing sidecar, or a folder in its place: what the .raw needs, not an OS error.
    grid_fails(
        "g.raw",
        &[("g.raw", four.clone())],
        &["g.raw", "needs its sidecar", "g.json", "resolution"],
    );
    grid_fails(
        "g.raw",
        &[("g.raw", four.clone()), ("g.json/", vec![])],
        &["g.raw", "needs its sidecar", "g.json"],
    );
    grid_fails("g.raw", &raw("{\"resolution\": [2, 2", four.clone()), &["g.json", "resolution"]);
    grid_fails(
        "g.raw",
        &raw("{\"resolution\": [2, 2, 2], \"dtype\": \"float32\"}", four.clone()),
        &["g.raw", "needs 32 bytes"],
    );
    grid_fails(
        "g.raw",
        &raw("{\"resolution\": [1, 1, 2], \"dtype\": \"float64\", \"endian\": \"big\"}", {
            [1.0f64, -1e300].iter().flat_map(|v| v.to_be_bytes()).collect()
        }),
        &["g.raw", "value 1 is -1e300", "float32"],
    );
    grid_fails(
        "g.raw",
        &raw("{\"resolution\": [1, 2, 2], \"dtype\": \"int7\"}", four.clone()),
        &["g.raw", "sidecar field `dtype`", "int7"],
    );
    grid_fails(
        "g.raw",
        &raw(
            "{\"resolution\": [1, 2, 2], \"dtype\": \"float32\", \"endian\": \"middle\"}",
            four.clone(),
        ),
        &["g.raw", "sidecar field `endian`"],
    );
    grid_fails(
        "g.raw",
        &raw("{\"resolution\": [0, 2, 2], \"dtype\": \"float32\"}", four.clone()),
        &["g.raw", "zero size"],
    );
    let sphere = vdb_data("sphere64_blosc.vdb");
    grid_fails("g.vdb", &[("g.vdb", b"definitely not a vdb".to_vec())], &["g.vdb", "OpenVDB"]);
    // Cut short (a copy or download that stopped): said so, with how much of it is there.
    grid_fails(
        "g.vdb",
        &[("g.vdb", sphere[..sphere.len() / 2].to_vec())],
        &["g.vdb", "truncated", "cut short"],
    );
    grid_fails(
        "g.vdb",
        &[("g.vdb", sphere[..sphere.len() - 1].to_vec())],
        &["g.vdb", "truncated", "ends at byte", "cut short"],
    );
    grid_fails("g.vdb", &[("g.vdb", sphere[..40].to_vec())], &["g.vdb"]);
    // An integer grid is not a density (docs/vdb.md), whatever its values.
    let mut int32 = sphere.clone();
    let at = int32.windows(16).position(|w| w == b"Tree_float_5_4_3").unwrap();
    int32[at..at + 16].copy_from_slice(b"Tree_int32_5_4_3");
    grid_fails("g.vdb", &[("g.vdb", int32)], &["g.vdb", "`int32` values", "float, double or half"]);
    render_fails(
        "[medium]\ngrid = \"g.vdb\"\ngrid_name = \"smoke\"\n",
        &[("g.vdb", sphere.clone())],
        &["medium.grid_name", "smoke"],
    );
    render_fails(
        "[medium]\ngrid = \"g.vdb\"\nscale = 0.0\n",
        &[("g.vdb", sphere.clone())],
        &["s.toml", "medium.scale"],
    );
    render_fails(
        "[medium]\ngrid = \"g.vdb\"\nmax_voxels = 1000\n",
        &[("g.vdb", sphere)],
        &["g.vdb", "medium.max_voxels", "medium.downsample"],
    );
}

#[test]
fn arrays_longer_than_three_and_magnitudes_no_f32_render_holds() {
    scene_rows(&[
        // serde would read the first three items and drop the rest.
        (
            "[medium]\nalbedo = [0.5, 0.5, 0.5, \"junk\"]\n",
            &["s.toml", "medium.albedo", "4 items", "exactly 3"],
        ),
        (
            "[medium]\nresolution = [40, 32, 24, 7]\n",
            &["s.toml", "medium.resolution", "4 items"],
        ),
        ("[sun]\ndirection = [0.0, 1.0, 0.0, 1.0]\n", &["s.toml", "sun.direction", "4 items"]),
        (
            "[camera]\nposition = [0.0, 1.0, 0.0, 1.0, 2.0]\n",
            &["s.toml", "camera.position", "5 items"],
        ),
        ("[sky]\nradiance = [0.1, 0.1, 0.1, 0.1]\n", &["s.toml", "sky.radiance", "4 items"]),
        // Finite but past what f32 sums hold: named with the bound and its reason.
        (
            "[sun]\nirradiance = [1e38, 1e38, 1e38]\n",
            &["s.toml", "sun.irradiance", "1e30", "1361"],
        ),
        ("[sun]\nirradiance = [3.0, inf, 3.0]\n", &["s.toml", "sun.irradiance"]),
        ("[sun]\nirradiance = [nan, 3.0, 3.0]\n", &["s.toml", "sun.irradiance"]),
        ("[sky]\nradiance = [1e35, 0.4, 0.8]\n", &["s.toml", "sky.radiance", "1e30"]),
        ("[sky]\nradiance = [inf, 0.4, 0.8]\n", &["s.toml", "sky.radiance"]),
        (
            "[sky]\nmodel = \"envmap\"\npath = \"env.exr\"\nscale = 1e38\n",
            &["s.toml", "sky.scale", "1e30"],
        ),
        ("[medium]\nsigma_t = 1e12\n", &["s.toml", "medium.sigma_t", "1e9"]),
        ("[medium]\norigin = [1e12, 0.0, 0.0]\n", &["s.toml", "medium.origin", "1e7"]),
        ("[camera]\nposition = [0.0, 1e11, 0.0]\n", &["s.toml", "camera.position", "1e7"]),
        ("[camera]\nlook_at = [0.0, 0.0, -1e9]\n", &["s.toml", "camera.look_at", "1e7"]),
        ("[render]\nexposure = 1e30\n", &["s.toml", "render.exposure", "64"]),
        ("[render]\nexposure = inf\n", &["s.toml", "render.exposure"]),
        // NaN, inf, negative and zero of the numeric keys not covered above.
        ("[medium]\nvoxel_size = nan\n", &["s.toml", "medium.voxel_size"]),
        ("[medium]\nvoxel_size = inf\n", &["s.toml", "medium.voxel_size"]),
        ("[medium]\norigin = [0.0, inf, 0.0]\n", &["s.toml", "medium.origin"]),
        ("[medium]\ng = inf\n", &["s.toml", "medium.g"]),
        ("[medium]\nalbedo = [-0.1, 0.5, 0.5]\n", &["s.toml", "medium.albedo"]),
        ("[sun]\nangular_diameter_deg = nan\n", &["s.toml", "sun.angular_diameter_deg"]),
        ("[sky]\nmodel = \"atmosphere\"\naltitude_m = inf\n", &["s.toml", "sky.altitude_m"]),
        ("[ground]\nheight = inf\n", &["s.toml", "ground.height"]),
        ("[ground]\nalbedo = [nan, 0.3, 0.3]\n", &["s.toml", "ground.albedo"]),
        ("[camera]\nfov_deg = nan\n", &["s.toml", "camera.fov_deg"]),
        ("[camera]\nfov_deg = -10.0\n", &["s.toml", "camera.fov_deg"]),
        ("[camera]\nlook_at = [nan, 0.0, 0.0]\n", &["s.toml", "camera.look_at"]),
        ("[render]\nstep = nan\n", &["s.toml", "render.step"]),
        ("[render]\ntime_limit = nan\n", &["s.toml", "render.time_limit"]),
        ("[render]\ntime_limit = inf\n", &["s.toml", "render.time_limit"]),
        ("[render]\nforward_fraction = nan\n", &["s.toml", "render.forward_fraction"]),
        ("[render]\nforward_fraction = 1.0\n", &["s.toml", "render.forward_fraction"]),
        ("[render]\nsolver_tolerance = nan\n", &["s.toml", "render.solver_tolerance"]),
        (
            "[render]\npropagation_tolerance = nan\n",
            &["s.toml", "render.propagation_tolerance"],
        ),
        (
            "[render]\nlow_density_threshold = nan\n",
            &["s.toml", "render.low_density_threshold"],
        ),
        (
            "[render]\nlow_density_threshold = inf\n",
            &["s.toml", "render.low_density_threshold"],
        ),
        ("[render]\nsurface_depth = nan\n", &["s.toml", "render.surface_depth"]),
        ("[render]\nsurface_depth = -1.0\n", &["s.toml", "render.surface_depth"]),
        ("[render]\nsurface_band = 2.0\n", &["s.toml", "render.surface_band"]),
    ]);
    // σt times the grid's densest voxel is the extinction the methods use.
    let dense = npy(
        "{'descr': '<f4', 'fortran_order': False, 'shape': (1, 2, 2), }",
        &f32s(&[1.0, 1.0, 1e30, 1.0]),
    );
    grid_fails("g.npy", &[("g.npy", dense)], &["s.toml", "medium.sigma_t", "largest density"]);
    // Density and light each within its bound, their product past what f32 holds (1e20 under a
    // sun of 3e20 gives inf in three methods unrefused): named, with the fix.
    let dense = npy(
        "{'descr': '<f4', 'fortran_order': False, 'shape': (1, 2, 2), }",
        &f32s(&[1e20, 1e20, 1e20, 1e20]),
    );
    render_fails(
        "[medium]\ngrid = \"g.npy\"\nsigma_t = 1e-21\n[sun]\nirradiance = [3e20, 3e20, 3e20]\n",
        &[("g.npy", dense)],
        &["s.toml", "medium.grid", "brightest light", "1e33", "medium.sigma_t up"],
    );
    // A grid file larger than any grid medium.max_voxels allows is refused before it is read.
    render_fails(
        "[medium]\ngrid = \"g.npy\"\nmax_voxels = 8\n",
        &[(
            "g.npy",
            npy("{'descr': '<f4', 'fortran_order': False, 'shape': (1, 2, 2), }", &vec![0; 2 << 20]),
        )],
        &["s.toml", "medium.max_voxels", "g.npy", "bytes"],
    );
}

#[test]
fn grid_files_that_mislead_or_say_two_things() {
    let four = f32s(&[1.0; 4]);
    let header = "{'descr': '<f4', 'fortran_order': False, 'shape': (1, 2, 2), }";
    // NumPy takes the last of two keys: refuse rather than guess.
    grid_fails(
        "g.npy",
        &[(
            "g.npy",
            npy(
                "{'descr': '<f4', 'descr': '<f8', 'fortran_order': False, 'shape': (1, 2, 2), }",
                &four,
            ),
        )],
        &["g.npy", "'descr' more than once"],
    );
    let mut longer = four.clone();
    longer.extend_from_slice(&[0, 0, 0]);
    grid_fails("g.npy", &[("g.npy", npy(header, &longer))], &["g.npy", "3 bytes follow"]);
    // The sidecar's scale is named, not the voxel it spoils.
    let raw = |json: &str| vec![("g.raw", four.clone()), ("g.json", json.as_bytes().to_vec())];
    for scale in ["-1.0", "0.0", "1e300"] {
        grid_fails(
            "g.raw",
            &raw(&format!(
                "{{\"resolution\": [1, 2, 2], \"dtype\": \"float32\", \"scale\": {scale}}}"
            )),
            &["g.raw", "sidecar field `scale`", "positive and finite"],
        );
    }
    let big = f32s(&[1e30; 4]);
    grid_fails(
        "g.raw",
        &[
            ("g.raw", big),
            (
                "g.json",
                b"{\"resolution\": [1, 2, 2], \"dtype\": \"float32\", \"scale\": 1e20}".to_vec(),
            ),
        ],
        &["g.raw", "sidecar field `scale`", "overflows"],
    );
    // A .vdb's own transform times medium.scale: the key the user set is named.
    let sphere = vdb_data("sphere64_blosc.vdb");
    for scale in ["1e30", "3e38"] {
        render_fails(
            &format!("[medium]\ngrid = \"g.vdb\"\nscale = {scale}\n"),
            &[("g.vdb", sphere.clone())],
            &["s.toml", "field `medium.scale`", "metres per unit"],
        );
    }
    // A 2 MB grid path is shown shortened.
    let long = format!("[medium]\ngrid = \"{}.vol\"\n", "g".repeat(2 << 20));
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("s.toml"), long).unwrap();
    let (code, _, err) = run_in(dir.path(), &["render", "s.toml", "-q"]);
    assert_eq!(code, 1, "{}", &err[..200.min(err.len())]);
    assert!(
        err.len() < 3000 && err.contains("characters left out") && err.contains("medium.grid"),
        "{} bytes",
        err.len()
    );
}

#[cfg(unix)]
#[test]
fn endless_inputs_are_cut_off() {
    // A path to an endless device is refused at once, wherever a file is read.
    let cases: [(&str, &[&str], &[&str]); 4] = [
        ("s.toml", &["render", "s.toml", "-q"], &["s.toml", "16 MiB", "scene file"]),
        ("g.json", &["render", "r.toml", "-q"], &["g.json", "16 MiB", "sidecar"]),
        ("env.exr", &["render", "e.toml", "-q"], &["sky.path", "env.exr", "not a file"]),
        ("a.exr", &["compare", "a.exr", "a.exr"], &["a.exr", "regular file"]),
    ];
    for (link, args, expect) in cases {
        let dir = tempfile::tempdir().unwrap();
        write_files(
            dir.path(),
            &[
                ("r.toml", b"[medium]\ngrid = \"g.raw\"\n".to_vec()),
                ("g.raw", f32s(&[1.0; 4])),
                ("e.toml", b"[sky]\nmodel = \"envmap\"\npath = \"env.exr\"\n".to_vec()),
            ],
        );
        std::os::unix::fs::symlink("/dev/zero", dir.path().join(link)).unwrap();
        let before = listing(dir.path());
        let (code, _, err) = run_in(dir.path(), args);
        assert_eq!(code, 1, "{args:?}: {err}");
        for e in expect {
            assert!(err.contains(e), "{args:?}: `{}` should mention `{e}`", err.trim_end());
        }
        assert_eq!(listing(dir.path()), before);
    }
    grid_fails("g.vdb", &[], &["s.toml", "medium.grid", "g.vdb"]);
}

/// Run the binary in `dir` with its stdout and stderr sent to `/dev/full`.
#[cfg(target_os = "linux")]
fn run_full(dir: &Path, args: &[&str], stdout_full: bool) -> (i32, String) {
    use std::process::Stdio;
    let full = || std::fs::OpenOptions::new().write(true).open("/dev/full").unwrap();
    let mut cmd = Command::new(BIN);
    cmd.current_dir(dir).args(args);
    if stdout_full {
        cmd.stdout(full());
    } else {
        cmd.stdout(Stdio::null()).stderr(full());
    }
    let out = cmd.output().unwrap();
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stderr).to_string())
}

#[cfg(target_os = "linux")]
#[test]
fn a_full_disk_or_a_closed_pipe_is_no_panic() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("g.vdb"), vdb_data("sphere64_blosc.vdb")).unwrap();
    std::fs::write(dir.path().join("s.toml"), SCENE).unwrap();
    let (code, err) = run_full(
        dir.path(),
        &[
            "render", "s.toml", "--method", "single", "-o", "a.exr", "--width", "8", "--height", "8",
        ],
        false,
    );
    assert_eq!(code, 0, "a full stderr loses only the notes: {err}");
    assert!(dir.path().join("a.exr").is_file() && dir.path().join("a.png").is_file());
    let commands: [&[&str]; 7] = [
        // Help and version are results on stdout too.
        &["--help"],
        &["--version"],
        &["info", "g.vdb", "--json"],
        &["info", "g.vdb"],
        &[
            "slab",
            "--thickness",
            "1",
            "--albedo",
            "0.9",
            "--g",
            "0",
            "--incidence",
            "diffuse",
            "--method",
            "diffusion",
        ],
        &["compare", "a.exr", "a.exr"],
        &["bench", "--methods", "single", "--sizes", "8x8x8", "--width", "8", "--height", "8"],
    ];
    for args in commands {
        let (code, err) = run_full(dir.path(), args, true);
        assert_eq!(code, 1, "{args:?}: {err}");
        assert!(err.contains("standard output") && err.contains("No space left"), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
    // A reader that closed the pipe before the command wrote: quiet, the shell's 128 + SIGPIPE.
    // The read end is closed before the command starts, so its first write always fails.
    // (std::io::pipe is newer than the library's MSRV; the tests run on the current toolchain.)
    #[allow(clippy::incompatible_msrv)]
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let out = Command::new(BIN)
        .current_dir(dir.path())
        .args(["info", "g.vdb"])
        .stdout(writer)
        .stderr(std::process::Stdio::piped())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(141), "{err}");
    assert!(err.is_empty(), "{err}");
}

#[cfg(unix)]
#[test]
fn an_interrupt_leaves_no_file_and_says_so() {
    // Both renders at once, a thread each, each signalled as soon as it catches the signals (a
    // render of 100,000 samples per pixel is still running then).
    // SIGHUP too, unless this process ignores it (started under nohup): the render inherits that
    // and rightly keeps it ignored (the next test).
    let hup = [("HUP", 129)].into_iter().filter(|_| !ignores_hangups());
    let runs: Vec<_> = [("INT", 130), ("TERM", 143)]
        .into_iter()
        .chain(hup)
        .map(|(signal, code)| {
            let dir = tempfile::tempdir().unwrap();
            let child = long_render(dir.path(), Command::new(BIN)).spawn().unwrap();
            (signal, code, dir, child)
        })
        .collect();
    let ready: Vec<bool> = runs.iter().map(|(_, _, _, child)| catches_interrupts(child.id())).collect();
    // Both signalled before any assertion, so a failure leaves no render running.
    let killed: Vec<bool> = runs
        .iter()
        .map(|(signal, _, _, child)| {
            let kill = Command::new("kill").args([&format!("-{signal}"), &child.id().to_string()]).status();
            kill.is_ok_and(|status| status.success())
        })
        .collect();
    for (((signal, code, dir, child), killed), ready) in runs.into_iter().zip(killed).zip(ready) {
        assert!(
            ready,
            "SIG{signal}: the render exited or caught no SIGINT/SIGTERM/SIGHUP within 60 s"
        );
        assert!(killed);
        let out = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(code), "{err}");
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(err.contains(&format!("interrupted (SIG{signal}): no output written")), "{err}");
        assert_eq!(listing(dir.path()), [PathBuf::from("s.toml")]);
    }
}

/// A render started under `nohup` (SIGHUP ignored) keeps it ignored: a closed terminal does not
/// end it, and SIGTERM still does.
#[cfg(unix)]
#[test]
fn a_render_under_nohup_goes_on_through_a_hangup() {
    let dir = tempfile::tempdir().unwrap();
    let mut nohup = Command::new("nohup");
    nohup.arg(BIN);
    let Ok(child) = long_render(dir.path(), nohup).stdout(std::process::Stdio::null()).spawn() else {
        return; // no nohup on this machine
    };
    let pid = child.id().to_string();
    let ready = catches_interrupts(child.id());
    let hup = Command::new("kill").args(["-HUP", &pid]).status().is_ok_and(|s| s.success());
    std::thread::sleep(std::time::Duration::from_millis(300));
    let still = std::fs::read_to_string(format!("/proc/{pid}/status")).is_ok_and(|s| !s.contains("State:\tZ"));
    let term = Command::new("kill").args(["-TERM", &pid]).status().is_ok_and(|s| s.success());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(ready && hup && term, "{err}");
    assert!(
        still || !Path::new("/proc/self/status").exists(),
        "SIGHUP ended a render under nohup: {err}"
    );
    assert_eq!(out.status.code(), Some(143), "{err}");
    assert!(err.contains("interrupted (SIGTERM): no output written"), "{err}");
}

/// `command` (the binary, or a wrapper with the binary as its first argument) set to render
/// [`SCENE`] in `dir` with `reference` at 100,000 samples per pixel on one thread (still running
/// when it is signalled), its stderr piped.
#[cfg(unix)]
fn long_render(dir: &Path, mut command: Command) -> Command {
    std::fs::write(dir.join("s.toml"), SCENE).unwrap();
    command
        .current_dir(dir)
        .args([
            "render",
            "s.toml",
            "--method",
            "reference",
            "--spp",
            "100000",
            "-q",
            "--threads",
            "1",
        ])
        .stderr(std::process::Stdio::piped());
    command
}

/// Whether this process ignores SIGHUP (bit 1 of its `SigIgn` mask in /proc; false without /proc).
#[cfg(unix)]
fn ignores_hangups() -> bool {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let ignored = status.lines().find_map(|l| l.strip_prefix("SigIgn:")).map(str::trim);
    ignored
        .and_then(|mask| u64::from_str_radix(mask, 16).ok())
        .is_some_and(|mask| mask & 1 == 1)
}

/// Whether process `pid` catches SIGINT and SIGTERM (bits 2 and 15, counted from 1, of its
/// `SigCgt` mask in /proc) within 60 s; false as soon as it has exited. Where there is no /proc,
/// true after a wait long enough on a loaded machine.
#[cfg(unix)]
fn catches_interrupts(pid: u32) -> bool {
    use std::time::{Duration, Instant};
    if !Path::new("/proc/self/status").exists() {
        std::thread::sleep(Duration::from_secs(2));
        return true;
    }
    let wanted = (1u64 << (2 - 1)) | (1u64 << (15 - 1));
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(60) {
        let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
        let field = |name: &str| status.lines().find_map(|l| l.strip_prefix(name)).map(str::trim);
        if field("State:").is_none_or(|state| state.starts_with('Z')) {
            return false;
        }
        let caught = field("SigCgt:").and_then(|mask| u64::from_str_radix(mask, 16).ok()).unwrap_or(0);
        if caught & wanted == wanted {
            return true;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    false
}

// --------------------------------------------------------------------- command-line arguments

/// The built-in cloud on 8³ voxels of 100 m, each one optical depth thick at density 1 (no
/// thick-voxel warning).
const SCENE: &str = "[medium]\nresolution = [8, 8, 8]\nvoxel_size = 100.0\nsigma_t = 0.01\n";

#[test]
fn bad_render_arguments_and_outputs() {
    let s = || ("s.toml", SCENE.as_bytes().to_vec());
    let small = ["--width", "8", "--height", "8", "-q"];
    let render = |extra: &[&'static str]| -> Vec<&'static str> {
        let mut v = vec!["render", "s.toml"];
        v.extend_from_slice(extra);
        v.extend_from_slice(&small);
        v
    };
    fails(&[s()], &render(&["-o", "out.jpg"]), &["--output", ".exr or .png"]);
    // The output folder is checked before any work.
    fails(
        &[s()],
        &render(&["-o", "missing/x.exr"]),
        &["--output", "missing", "does not exist"],
    );
    fails(
        &[s(), ("out.exr/", vec![])],
        &render(&["-o", "out.exr"]),
        &["--output", "out.exr", "folder"],
    );
    // A .png sibling that is a folder fails up front: no .exr left behind.
    fails(
        &[s(), ("out.png/", vec![])],
        &render(&["-o", "out.exr"]),
        &["--output", "out.png", "folder"],
    );
    // An output that is one of the scene's own inputs.
    fails(
        &[("s.exr", SCENE.as_bytes().to_vec())],
        &["render", "s.exr", "-o", "s.exr", "-q"],
        &["--output", "the scene file"],
    );
    let env = cloudgi::Image::new(4, 2).to_exr_bytes().unwrap();
    let envmap = "[sky]\nmodel = \"envmap\"\npath = \"env.exr\"\n";
    fails(
        &[("s.toml", envmap.as_bytes().to_vec()), ("env.exr", env.clone())],
        &render(&["-o", "env.exr"]),
        &["--output", "sky.path"],
    );
    fails(
        &[("s.toml", envmap.as_bytes().to_vec()), ("env.exr", env.clone()), ("sub/", vec![])],
        &render(&["-o", "./sub/../env.exr", "--method", "single"]),
        &["--output", "sky.path"],
    );
    fails(
        &[("s.toml", envmap.as_bytes().to_vec()), ("env.exr", env)],
        &["sky", "s.toml", "-o", "env.exr", "-q"],
        &["--output", "sky.path"],
    );
    fails(&[s()], &render(&["--threads", "0"]), &["--threads"]);
    // --exposure holds render.exposure's bound: 2^1e30 is no scale factor.
    fails(&[s()], &render(&["--exposure", "1e30"]), &["--exposure", "±64"]);
    let exr = cloudgi::Image::new(4, 2).to_exr_bytes().unwrap();
    fails(
        &[("a.exr", exr)],
        &["tonemap", "a.exr", "-o", "a.png", "--exposure", "-65"],
        &["--exposure", "±64"],
    );
    fails(&[s()], &render(&["--threads", "10000"]), &["--threads", "10000", "per core"]);
    // Names that are no file, or that no file system accepts, fail before the render.
    fails(&[s()], &render(&["-o", ".exr"]), &["--output", "no name before .exr"]);
    fails(&[s()], &render(&["-o", "out.exr/"]), &["--output", "names a folder"]);
    let long: &'static str = format!("{}.exr", "n".repeat(296)).leak();
    fails(&[s()], &render(&["-o", long]), &["--output", "300 bytes", "at most 255"]);
    fails(&[s()], &render(&["--method", "magic"]), &["magic"]);
    fails(&[s()], &["render", "s.toml", "--width", "abc"], &["abc"]);
    // A flag's bad value is the command line's, not the scene file's key it sets.
    fails(
        &[s()],
        &["render", "s.toml", "--width", "0", "-q"],
        &["command line", "--width", "1 to 32768"],
    );
    fails(
        &[s()],
        &["render", "s.toml", "--height", "40000", "-q"],
        &["command line", "--height"],
    );
    fails(
        &[s()],
        &["bench", "s.toml", "--width", "0", "-q"],
        &["command line", "--width", "1 to 32768"],
    );
    fails(
        &[s()],
        &["bench", "s.toml", "--height", "0", "-q"],
        &["command line", "--height", "1 to 32768"],
    );
    // Durations past 1e9 s (about 32 years) are refused, written as the user wrote them.
    fails(
        &[s()],
        &render(&["--time-limit", "1e300"]),
        &["command line", "--time-limit", "1e300", "1e9"],
    );
    fails(
        &[s()],
        &["bench", "s.toml", "--max-seconds", "1e300", "-q"],
        &["--max-seconds", "1e300", "1e9"],
    );
    fails(
        &[s()],
        &["render", "s.toml", "--width", "4294967295", "--height", "4294967295", "-q"],
        &["camera.width"],
    );
    fails(&[s()], &render(&["--time-limit", "0"]), &["command line", "--time-limit"]);
    fails(&[s()], &render(&["--spp", "0"]), &["command line", "--spp"]);
    fails(&[s()], &render(&["--aa-samples", "0"]), &["command line", "--aa-samples"]);
    // An image too large for memory is refused before anything is allocated, with what it needs.
    fails(
        &[s()],
        &["render", "s.toml", "--width", "32768", "--height", "32768", "--aov", "-q"],
        &["camera.width", "GiB", "--width/--height"],
    );
}

/// A valid 2×2×2 `.npy` grid (one sequence frame).
fn npy_frame() -> Vec<u8> {
    npy("{'descr': '<f4', 'fortran_order': False, 'shape': (2, 2, 2), }", &f32s(&[1.0; 8]))
}

#[test]
fn bad_frames_patterns_keys_and_tasks() {
    let render = |extra: &[&'static str]| -> Vec<&'static str> {
        let mut a = vec!["render", "s.toml", "-o", "out.####.exr", "--width", "8", "--height", "8", "-q"];
        a.extend_from_slice(extra);
        a
    };
    let seq = "[medium]\ngrid = \"c.####.npy\"\n";
    let frames: Vec<File> = vec![("s.toml", seq.into()), ("c.0001.npy", npy_frame()), ("c.0002.npy", npy_frame())];
    let rows: &[(&[&str], &[&str])] = &[
        // A missing frame fails before any frame renders (frames 1 and 2 exist).
        (&["--frames", "1-3"], &["s.toml", "medium.grid", "frame 3", "c.0003.npy"]),
        (&["--frames", ""], &["--frames", "empty"]),
        (&["--frames", "2-1"], &["--frames", "backwards", "1-2"]),
        (&["--frames", "1-2x0"], &["--frames", "step"]),
        (&["--frames", "1-two"], &["--frames", "two", "1-240"]),
        (&["--frames", "1,1-2"], &["--frames", "twice"]),
        (&[], &["--frames", "animated", "animation.frames"]),
        (
            &["--frames", "1-2", "--task-index", "2", "--task-count", "2"],
            &["--task-index", "0 to 1"],
        ),
        (
            &["--frames", "1-2", "--task-index", "0", "--task-count", "0"],
            &["--task-count", "at least 1"],
        ),
        (&["--frames", "1-2", "--task-index", "0"], &["--task-count"]),
        (
            &["--frames", "1-2", "--display-server", "127.0.0.1:14158"],
            &["--display-server", "sequence"],
        ),
    ];
    for (extra, expect) in rows {
        fails(&frames, &render(extra), expect);
    }
    // A keyed value past the scene's limits on a later frame is refused before frame 1 renders.
    let late = "[medium]\nresolution = [8, 6, 4]\nvoxel_size = 100.0\n[animation]\nframes = \"1-3\"\n\
        [[animation.key]]\nframe = 1\nmedium.sigma_t = 0.05\n[[animation.key]]\nframe = 3\nmedium.sigma_t = 1e12\n";
    fails(&[("s.toml", late.into())], &render(&[]), &["s.toml", "medium.sigma_t", "frame 2"]);
    // Several frames need a frame pattern in --output; a bad one is named.
    fails(
        &frames,
        &["render", "s.toml", "--frames", "1-2", "-o", "out.exr", "-q"],
        &["--output", "no frame pattern", "out.####.exr"],
    );
    fails(
        &frames,
        &["render", "s.toml", "--frames", "1-2", "-o", "out.%4d.exr", "-q"],
        &["--output", "not a frame pattern"],
    );
    // Bad grid patterns, animation tables and keys.
    scene_rows(&[
        ("[medium]\ngrid = \"c.%s.npy\"\n", &["s.toml", "medium.grid", "not a frame pattern"]),
        ("[medium]\ngrid = \"c.####.$F4.npy\"\n", &["s.toml", "medium.grid", "more than one"]),
        ("[medium]\ngrid = \"c.#@.npy\"\n", &["s.toml", "medium.grid", "mixes"]),
        ("[animation]\nframes = \"9-3\"\n", &["s.toml", "animation.frames", "backwards"]),
        ("[animation]\nframes = \"\"\n", &["s.toml", "animation.frames", "empty"]),
        ("[animation]\nfps = 24\n", &["s.toml", "fps"]),
        ("[[animation.key]]\nframe = -1\n", &["s.toml", "frame"]),
        ("[[animation.key]]\nsun.elevation_deg = 5.0\n", &["s.toml", "frame"]),
        ("[[animation.key]]\nframe = 1\nsun.height = 5.0\n", &["s.toml", "height"]),
        ("[[animation.key]]\nframe = 1\nmedium.g = 0.5\n", &["s.toml", "`g`"]),
        (
            "[animation]\nframes = \"1\"\n[[animation.key]]\nframe = 1\nmedium.sigma_t = -0.1\n",
            &["s.toml", "animation.key[0].medium.sigma_t", "non-negative"],
        ),
        (
            "[[animation.key]]\nframe = 1\nsun.irradiance = [nan, 1.0, 1.0]\n",
            &["s.toml", "animation.key[0].sun.irradiance"],
        ),
        (
            "[[animation.key]]\nframe = 1\ncamera.fov_deg = 200.0\n",
            &["s.toml", "animation.key[0].camera.fov_deg"],
        ),
        (
            "[[animation.key]]\nframe = 1\nsun.elevation_deg = 95.0\n",
            &["s.toml", "sun.elevation_deg", "[-90, 90]"],
        ),
        (
            "[[animation.key]]\nframe = 1\ncamera.position = [inf, 0.0, 0.0]\n",
            &["s.toml", "animation.key[0].camera.position"],
        ),
        (
            "[[animation.key]]\nframe = 1\ncamera.look_at = [0.0, nan, 0.0]\n",
            &["s.toml", "animation.key[0].camera.look_at"],
        ),
        (
            "[[animation.key]]\nframe = 2\n[[animation.key]]\nframe = 2\n",
            &["s.toml", "animation.key", "two keys for frame 2"],
        ),
        (
            "[animation]\nframes = \"1-3\"\n[[animation.key]]\nframe = 1\nsun.elevation_deg = 10.0\n",
            &["s.toml", "animation.key.sun.elevation_deg", "sun.azimuth_deg"],
        ),
        (
            "[animation]\nframes = \"1-3\"\n[[animation.key]]\nframe = 1\nsun.azimuth_deg = 10.0\n",
            &["s.toml", "animation.key.sun.azimuth_deg", "sun.elevation_deg"],
        ),
        (
            "[sun]\nfrom_atmosphere = true\n[[animation.key]]\nframe = 1\nsun.irradiance = [1.0, 1.0, 1.0]\n",
            &["s.toml", "animation.key.sun.irradiance", "from_atmosphere"],
        ),
    ]);
    // A keyed camera that passes through its look-at point mid-sequence names the frame.
    let through = "[camera]\nlook_at = [0.0, 330.0, 0.0]\n[animation]\nframes = \"1-3\"\n\
        [[animation.key]]\nframe = 1\ncamera.position = [0.0, 330.0, 100.0]\n\
        [[animation.key]]\nframe = 3\ncamera.position = [0.0, 330.0, -100.0]\n";
    fails(
        &[("s.toml", through.into())],
        &render(&[]),
        &["s.toml", "camera.look_at", "frame 2"],
    );
}

#[test]
fn bad_arguments_of_the_other_commands() {
    let s = || ("s.toml", SCENE.as_bytes().to_vec());
    fails(&[s()], &["sky", "s.toml", "-o", "sky.png"], &["--output", ".exr"]);
    fails(&[s()], &["sky", "s.toml", "-o", "no/sky.exr"], &["--output", "does not exist"]);
    fails(&[s(), ("sky.png/", vec![])], &["sky", "s.toml"], &["--output", "sky.png", "folder"]);
    fails(&[s()], &["sky", "s.toml", "--width", "1"], &["--width"]);
    let img = cloudgi::Image::new(4, 4).to_exr_bytes().unwrap();
    let small = cloudgi::Image::new(2, 2).to_exr_bytes().unwrap();
    fails(&[("a.exr", img.clone())], &["compare", "a.exr", "nope.exr"], &["nope.exr"]);
    // A NaN or an infinity would score as `null`, or as a clean 0 in the relative metrics.
    let mut bad = cloudgi::Image::new(4, 4);
    bad.pixels[6] = cloudgi::Rgb::new(0.5, f32::NAN, 0.5);
    let bad = bad.to_exr_bytes().unwrap();
    for args in [["compare", "a.exr", "n.exr"], ["compare", "n.exr", "a.exr"]] {
        fails(
            &[("a.exr", img.clone()), ("n.exr", bad.clone())],
            &args,
            &["n.exr", "pixel (2, 1)", "NaN", "finite"],
        );
    }
    fails(
        &[("a.exr", img.clone()), ("b.exr", b"junk".to_vec())],
        &["compare", "a.exr", "b.exr"],
        &["b.exr", "OpenEXR"],
    );
    fails(
        &[("a.exr", img.clone())],
        &["compare", "a.exr", "a.exr", "--diff", "d.jpg"],
        &["--diff", ".png"],
    );
    fails(
        &[("a.exr", img.clone()), ("m.exr", small.clone())],
        &["compare", "a.exr", "a.exr", "--mask", "m.exr"],
        &["--mask", "2×2"],
    );
    fails(
        &[("a.exr", img.clone())],
        &["compare", "a.exr", "a.exr", "--where", "image"],
        &["--where", "LAYER<VALUE"],
    );
    fails(
        &[("a.exr", img.clone())],
        &["compare", "a.exr", "a.exr", "--where", "light_sun<1"],
        &[
            "a.exr",
            "--where",
            "no layer `light_sun`",
            "no layers beyond its RGB image",
            "`image` names its RGB image",
        ],
    );
    fails(
        &[("a.exr", img.clone())],
        &["compare", "a.exr", "a.exr", "--all-pixels", "--where", "image<0"],
        &["--where", "image<0", "loosen"],
    );
    fails(
        &[("a.exr", img.clone()), ("m.exr", small.clone())],
        &["compare", "a.exr", "a.exr", "--where-from", "m.exr", "--where", "image<1"],
        &["m.exr", "--where-from", "2×2"],
    );
    fails(&[("a.exr", img), ("b.exr", small)], &["compare", "a.exr", "b.exr"], &["4×4", "2×2"]);
    fails(&[], &["info", "nope.vdb"], &["nope.vdb"]);
    fails(
        &[("x.vdb", b"not a vdb at all".to_vec())],
        &["info", "x.vdb"],
        &["x.vdb", "OpenVDB"],
    );
    let slab = |extra: &[&'static str]| {
        let mut v = vec![
            "slab",
            "--thickness",
            "1",
            "--albedo",
            "0.9",
            "--g",
            "0.5",
            "--incidence",
            "diffuse",
        ];
        v.extend_from_slice(extra);
        v
    };
    fails(
        &[],
        &["slab", "--thickness", "1", "--albedo", "2", "--g", "0", "--incidence", "diffuse"],
        &["albedo"],
    );
    fails(
        &[],
        &["slab", "--thickness", "1", "--albedo", "0.5", "--g", "1", "--incidence", "diffuse"],
        &["g"],
    );
    fails(
        &[],
        &["slab", "--thickness", "-1", "--albedo", "0.5", "--g", "0", "--incidence", "diffuse"],
        &["thickness"],
    );
    fails(&[], &slab(&["--samples", "1"]), &["--samples"]);
    // A phase function this strongly backwards makes the slab's transport iteration diverge: an
    // error, not a number.
    fails(
        &[],
        &[
            "slab",
            "--thickness",
            "10",
            "--albedo",
            "1",
            "--g",
            "-0.98",
            "--incidence",
            "collimated",
            "--method",
            "transport",
        ],
        &["slab --method transport", "no physical result", "--g -0.98", "--method reference"],
    );
    // The transport mesh's layer count grows with τ: 1e30 would never end.
    fails(
        &[],
        &[
            "slab",
            "--thickness",
            "1e30",
            "--albedo",
            "0.5",
            "--g",
            "0",
            "--incidence",
            "diffuse",
            "--method",
            "transport",
        ],
        &["--thickness", "--method reference"],
    );
    fails(
        &[],
        &["slab", "--thickness", "1", "--albedo", "0.5", "--g", "0", "--incidence", "sideways"],
        &["sideways"],
    );
    fails(
        &[s()],
        &["figures", "s.toml", "-o", "f", "--reference-spp", "0", "-q"],
        &["--reference-spp"],
    );
    fails(&[s()], &["figures", "s.toml", "-o", "f", "--width", "0", "-q"], &["--width"]);
    fails(
        &[s()],
        &["figures", "s.toml", "-o", "f", "--reference-time=-1", "-q"],
        &["--reference-time"],
    );
    fails(
        &[s()],
        &["figures", "s.toml", "-o", "f", "--reference-time", "1e300", "-q"],
        &["--reference-time", "1e300 is not allowed", "1e9"],
    );
    fails(
        &[s(), ("f", b"a file".to_vec())],
        &["figures", "s.toml", "-o", "f", "-q"],
        &["--output", "is a file"],
    );
    fails(
        &[
            ("s.toml", b"[sky]\nmodel = \"envmap\"\npath = \"reference.exr\"\n".to_vec()),
            ("reference.exr", vec![]),
        ],
        &["figures", "s.toml", "-o", ".", "-q"],
        &["--output", "sky.path"],
    );
    fails(
        &[s(), ("d", b"a file".to_vec())],
        &["export", "mitsuba", "s.toml", "-o", "d", "-q"],
        &["--output", "is a file"],
    );
    fails(
        &[
            ("s.toml", b"[medium]\ngrid = \"density.vol\"\n".to_vec()),
            ("density.vol", vol([2, 2, 2], &[1.0; 8], 0)),
        ],
        &["export", "mitsuba", "s.toml", "-o", ".", "-q"],
        &["--output", "medium.grid"],
    );
    // A sequence exports one frame, named by --frame; a still scene takes none.
    let frames = || ("c.0001.vol", vol([2, 2, 2], &[1.0; 8], 0));
    let pattern = || ("p.toml", b"[medium]\ngrid = \"c.####.vol\"\n".to_vec());
    fails(
        &[pattern(), frames()],
        &["export", "mitsuba", "p.toml", "-o", "d", "-q"],
        &["--frame", "sequence"],
    );
    fails(
        &[pattern(), frames()],
        &["export", "mitsuba", "p.toml", "-o", "d", "--frame", "2", "-q"],
        &["frame 2", "c.0002.vol"],
    );
    fails(
        &[s()],
        &["export", "mitsuba", "s.toml", "-o", "d", "--frame", "1", "-q"],
        &["--frame", "not a sequence"],
    );
}

// ------------------------------------------------------------------------- warnings and help

/// Render `scene` (single, 8×8 unless `args` say otherwise): success, and stderr holds every
/// fragment of `expect` on `warning:` lines (none at all when `expect` is empty).
fn warns(files: &[File], args: &[&str], expect: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    write_files(dir.path(), files);
    let mut all = vec!["render", "s.toml", "-o", "out.exr", "--width", "8", "--height", "8", "-q"];
    all.extend_from_slice(args);
    let (code, _, err) = run_in(dir.path(), &all);
    assert_eq!(code, 0, "{all:?}: {err}");
    let warnings: Vec<&str> = err.lines().filter(|l| l.starts_with("warning: ")).collect();
    if expect.is_empty() {
        assert!(warnings.is_empty(), "{all:?}: unexpected {warnings:?}");
    }
    for e in expect {
        assert!(
            warnings.iter().any(|w| w.contains(e)),
            "{all:?}: no warning mentions `{e}` in {err}"
        );
    }
    assert!(dir.path().join("out.exr").exists(), "the render still runs");
}

/// Voxels five optical depths thick where the light enters: every deterministic method is warned
/// (with the refinement that resolves them), `reference` is not, and refined the cloud is quiet.
#[test]
fn thick_entry_voxels_are_warned_about() {
    let thick = |extra: &str| {
        vec![(
            "s.toml",
            format!("{SCENE}sigma_t = 0.05\n{extra}")
                .replace("sigma_t = 0.01\n", "")
                .into_bytes(),
        )]
    };
    let warning = ["optical depths thick", "--method reference", "medium.refine = 3"];
    warns(&thick(""), &["--method", "transport"], &warning);
    warns(&thick(""), &["--method", "single"], &warning);
    warns(&thick(""), &["--method", "reference", "--spp", "1"], &[]);
    warns(&thick("refine = 3\n"), &["--method", "single"], &[]);
}

#[test]
fn settings_that_do_not_apply_are_named() {
    let scene = |text: &str| vec![("s.toml", format!("{SCENE}{text}").into_bytes())];
    let medium = |lines: &str| vec![("s.toml", format!("{SCENE}{lines}").into_bytes())];
    let single = ["--method", "single"];
    warns(&scene(""), &single, &[]);
    warns(
        &scene("[render]\nspp = 64\n"),
        &["--method", "single"],
        &["s.toml: `render.spp`", "render.aa_samples"],
    );
    warns(
        &scene("[render]\nspp = 64\nmethod = \"full\"\n"),
        &["--iterations", "0"],
        &["`render.spp`", "method full"],
    );
    warns(&scene(""), &["--method", "single", "--aov", "--stderr"], &["`--aov`", "`--stderr`"]);
    warns(
        &scene(""),
        &["--method", "single", "--spp", "4", "--max-depth", "3"],
        &["`--spp`", "`--max-depth`"],
    );
    warns(
        &scene("[render]\nmax_depth = 3\niterations = 2\n"),
        &single,
        &["`render.max_depth`", "`render.iterations`"],
    );
    warns(
        &scene("[render]\naa_samples = 2\nstep = 0.25\n"),
        &["--method", "reference"],
        &["`render.aa_samples`", "`render.step`"],
    );
    warns(
        &scene("[render]\nsolver_tolerance = 1e-4\n"),
        &single,
        &["`render.solver_tolerance`"],
    );
    warns(
        &scene("[render]\ntransport_order = 5\ntransport_acceleration = false\n"),
        &single,
        &["`render.transport_order`", "`render.transport_acceleration`", "only transport"],
    );
    // Transport converges on this cloud without a warning; stopped by its cap, it says so and
    // names the key to raise; too few ordinates for the order are named too.
    warns(&scene(""), &[], &[]);
    warns(
        &scene("[render]\ntransport_max_iterations = 1\n"),
        &[],
        &[
            "s.toml: the transport iteration stopped at render.transport_max_iterations = 1",
            "relative change of I0 of 1.0e0",
            "raise render.transport_max_iterations",
        ],
    );
    warns(
        &scene("[sky]\nscale = 2.0\naltitude_m = 10.0\n"),
        &single,
        &["`sky.scale`", "`sky.altitude_m`"],
    );
    warns(
        &scene("[ground]\nenabled = false\nalbedo = [0.5, 0.5, 0.5]\n"),
        &single,
        &["`ground.albedo`"],
    );
    warns(
        &medium("grid_name = \"density\"\nscale = 2.0\n"),
        &single,
        &["`medium.grid_name`", "`medium.scale`"],
    );
    let mut vdb = vec![("g.vdb", vdb_data("sphere64_blosc.vdb"))];
    vdb.push((
        "s.toml",
        b"[medium]\ngrid = \"g.vdb\"\nvoxel_size = 7.0\norigin = [0.0, 0.0, 0.0]\nresolution = [4, 4, 4]\n[camera]\nfov_deg = 40.0\n"
            .to_vec(),
    ));
    // The sphere is about 3 m across, 1500 m from the default camera (a [camera] table, so not
    // fitted): less than a pixel, and too small for a cloud.
    warns(
        &vdb,
        &single,
        &[
            "`medium.voxel_size`",
            "`medium.origin`",
            "`medium.resolution`",
            ".vdb",
            "less than one pixel",
            "medium.scale = 100",
        ],
    );
    let mut vol_scene = vec![("g.vol", vol([2, 2, 2], &[1.0; 8], 0))];
    vol_scene.push((
        "s.toml",
        b"[medium]\ngrid = \"g.vol\"\nscale = 2.0\ngrid_name = \"d\"\n[camera]\nfov_deg = 40.0\n".to_vec(),
    ));
    warns(
        &vol_scene,
        &single,
        &["`medium.scale`", "`medium.grid_name`", "less than one pixel"],
    );
    warns(
        &scene("[camera]\nposition = [0.0, 350.0, 1500.0]\nlook_at = [0.0, 330.0, 3000.0]\n"),
        &single,
        &["not in the camera's view", "medium.scale"],
    );
}

#[test]
fn help_texts_and_info_json() {
    for cmd in ["info", "compare", "slab"] {
        let (code, out, _) = run_in(Path::new("."), &[cmd, "--help"]);
        assert_eq!(code, 0);
        assert!(!out.contains("The image is identical"), "{cmd} --help: {out}");
    }
    let vdb = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/vdb/tiles_blosc.vdb");
    let (code, out, err) = run_in(Path::new("."), &["info", vdb.to_str().unwrap(), "--json"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(out.lines().count(), 1, "one line of JSON: {out}");
    assert!(serde_json::from_str::<serde_json::Value>(&out).is_ok());
}

// ----------------------------------------------------------------------------- first use

#[test]
fn default_render_writes_exr_and_png() {
    let dir = tempfile::tempdir().unwrap();
    let (code, _, err) = run_in(
        dir.path(),
        &["render", "--width", "32", "--height", "24", "--method", "single", "-q"],
    );
    assert_eq!(code, 0, "{err}");
    let img = cloudgi::Image::read_exr(&dir.path().join("cloud.exr")).unwrap();
    assert_eq!((img.width, img.height), (32, 24));
    assert!(dir.path().join("cloud.png").exists());
    // A 250-byte name is valid: the temporaries' own short names fit beside it.
    let name = format!("{}.exr", "n".repeat(246));
    let (code, _, err) = run_in(
        dir.path(),
        &["render", "--width", "8", "--height", "8", "--method", "single", "-q", "-o", &name],
    );
    assert_eq!(code, 0, "{err}");
    let mut names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().len())
        .collect();
    names.sort();
    assert_eq!(names, [9, 9, 250, 250], "cloud.exr, cloud.png and the long pair; no temporary left");
}

#[test]
fn the_default_method_is_transport_and_default_toml_is_the_default_scene() {
    let d = cloudgi::SceneDesc::default();
    assert_eq!(d.render.method, cloudgi::Method::Transport);
    let text = include_str!("../../examples/default.toml");
    assert_eq!(cloudgi::SceneDesc::from_toml(text, "default.toml").unwrap(), d);
}
