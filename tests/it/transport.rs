//! `--method transport` through the binary: the scene's keys reach the solver, its AOVs are
//! written, and `cloudgi bench` times it.

use crate::common::{ok, BIN};
use cloudgi::Image;

fn assert_valid(img: &Image) {
    assert!(img.pixels.iter().all(|p| p.is_finite() && p.min_element() >= 0.0));
}

#[test]
fn cli_renders_with_method_transport_and_reports_iterations() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("small.toml");
    let text = "[medium]\nresolution = [20, 16, 12]\norigin = [-100.0, 0.0, -60.0]\n\
         [camera]\nposition = [0.0, 80.0, 400.0]\nlook_at = [0.0, 80.0, 0.0]\nwidth = 16\nheight = 12\n\
         [render]\ntransport_order = 5\ntransport_polar_ordinates = 6\n";
    let out = dir.path().join("t.exr");
    let render = |text: &str| {
        std::fs::write(&scene, text).unwrap();
        let r = std::process::Command::new(BIN)
            .args([
                "render",
                scene.to_str().unwrap(),
                "--method",
                "transport",
                "--aov",
                "-o",
                out.to_str().unwrap(),
            ])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&r.stderr).into_owned();
        assert!(r.status.success(), "{err}");
        err
    };
    let err = render(text);
    assert!(err.contains("iterations") && err.contains("transport solve"), "{err}");
    // The scene's keys reach the solver: 6 rings of 8, 10 and 12 azimuths each way at order 5;
    // without the reduced grid 6 × 12.
    assert!(err.contains("60 ordinates, order 5") && !err.contains("warning"), "{err}");
    let img = Image::read_exr(&out).unwrap();
    assert_valid(&img);
    assert!(img.layer("sun_single").is_some());
    let err = render(&format!("{text}transport_reduced_azimuths = false\n"));
    assert!(err.contains("72 ordinates, order 5"), "{err}");
}

#[test]
fn bench_times_transport_with_its_iterations_and_memory_and_skips_what_would_take_too_long() {
    let bench = |extra: &[&str]| {
        std::process::Command::new(BIN)
            .args(["bench", "--methods", "transport", "--sizes", "10x8x6,20x16x12"])
            .args(["--width", "16", "--height", "12"])
            .args(extra)
            .output()
            .unwrap()
    };
    // A run that must succeed: its table.
    let table = |extra: &[&str]| {
        let out = bench(extra);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let text = table(&["--max-seconds", "1e-4"]);
    assert!(
        text.contains("| transport solve | eye source |") && text.contains("| 10×8×6 | transport |"),
        "{text}"
    );
    assert!(text.contains("| peak | B per full voxel |"), "{text}");
    assert!(
        text.contains("10×8×6 transport: transport:") && text.contains("iterations") && text.contains("B + grid"),
        "{text}"
    );
    assert!(!text.contains("iteration 1,"), "per-iteration lines are dropped: {text}");
    assert!(
        !text.contains("| 20×16×12 |") && text.contains("20×16×12 transport: skipped"),
        "{text}"
    );
    let bad = bench(&["--max-seconds", "0"]);
    assert!(!bad.status.success() && String::from_utf8_lossy(&bad.stderr).contains("--max-seconds"));
    // A scene file of its own grid (the Disney cloud at a quarter of 1/16) gets a row by its name.
    let text = table(&["--clouds", "tests/data/clouds/wdas.toml"]);
    assert!(
        text.contains("| wdas | transport |") && text.contains("wdas transport: transport:"),
        "{text}"
    );
    let missing = bench(&["--clouds", "no-such-scene.toml"]);
    let err = String::from_utf8_lossy(&missing.stderr);
    assert!(
        !missing.status.success() && err.contains("no-such-scene.toml") && missing.stdout.is_empty(),
        "{err}"
    );
}

/// The solver's AVX copies keep their intrinsics inlined. A closure (`array::from_fn`, an
/// iterator adaptor) or a helper left outlined inside a kernel is not compiled for the copy's
/// target feature, so its intrinsics become calls: the same bits, the solve 3× slower
/// (docs/transport.md, "AVX"). An outlined intrinsic is a function of its own in the binary's
/// symbol table (`nm`, binutils, which links the binary); a structural check, not a timing.
/// Debug builds inline nothing, so only optimised ones are read.
#[test]
#[cfg(all(target_arch = "x86_64", target_os = "linux"))]
#[cfg_attr(debug_assertions, ignore = "unoptimised builds keep every intrinsic outlined")]
fn the_avx_kernels_keep_their_intrinsics_inlined() {
    let out = std::process::Command::new("nm")
        .args(["--defined-only", BIN])
        .output()
        .unwrap_or_else(|e| panic!("this check reads the binary's symbols with `nm` (binutils): {e}"));
    assert!(out.status.success(), "nm {BIN}: {}", String::from_utf8_lossy(&out.stderr));
    let symbols = String::from_utf8_lossy(&out.stdout);
    // The symbols are there to be read (a stripped binary would pass without a look).
    assert!(
        symbols.contains("sweep_ordinate_avx"),
        "{BIN} has no symbol table: the check cannot see"
    );
    let outlined: Vec<&str> = symbols.lines().filter(|l| l.contains("core_arch3x863avx")).collect();
    assert!(
        outlined.is_empty(),
        "{BIN} holds outlined core::arch AVX intrinsics: part of a transport kernel runs outside its \
         #[target_feature] copy (`nm -C {BIN} | grep core_arch::x86::avx`): {outlined:?}"
    );
}

/// The sun 0.6° above the horizon straight behind a cloud of 40-m voxels: the gather's sunlight
/// between the voxel centres is far above the beam's exponential fall-off (the image +19 %
/// against `reference` with `transport`, +30 % with `full`), and the render says so, naming the
/// fix; the image is still written.
#[test]
fn a_low_sun_through_coarse_voxels_is_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("graze.toml");
    let base = "[medium]\nresolution = [24, 20, 16]\nvoxel_size = 40.0\norigin = [-480.0, 0.0, -320.0]\n\
                sigma_t = 0.05\ng = 0.9\n[camera]\nposition = [0.0, 350.0, 1800.0]\nlook_at = [0.0, 330.0, 0.0]\n\
                fov_deg = 40.0\nwidth = 32\nheight = 24\n";
    for method in ["transport", "full"] {
        let run = |sun: &str| {
            std::fs::write(&scene, format!("{base}[sun]\ndirection = {sun}\n")).unwrap();
            let err = ok(dir.path(), &["render", "graze.toml", "--method", method, "-o", "t.exr", "-q"]);
            assert!(dir.path().join("t.exr").exists());
            std::fs::remove_file(dir.path().join("t.exr")).unwrap();
            err
        };
        let err = run("[0.0, 0.011, -1.0]");
        assert!(
            err.contains("warning: ") && err.contains("between the voxel centres") && err.contains(&format!("the {method} gather")),
            "{method}: {err}"
        );
        assert!(err.contains("medium.refine = 3"), "{err}");
        // The default sun, high and to the side: no such warning.
        let err = run("[0.3, 0.8, 0.5]");
        assert!(!err.contains("between the voxel centres"), "{method}: {err}");
    }
}
