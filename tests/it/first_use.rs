//! First use, end to end through the binary: a grid file as the scene, framed and lit; z-up
//! files; the PNG's automatic exposure and `tonemap`; the live view to a tev listener.

use crate::common::{cloudgi, npy_grid, ok};
use cloudgi::Image;
use std::path::{Path, PathBuf};

fn data(name: &str) -> PathBuf {
    crate::common::data("vdb").join(name)
}

/// The reference's transmittance layer.
const TRANSMITTANCE: &str = "transmittance";

/// Rec. 709 luminance, the automatic exposure's.
fn luminance(p: cloudgi::Rgb) -> f32 {
    0.2126 * p.x + 0.7152 * p.y + 0.0722 * p.z
}

/// Share of the pixels whose camera ray crosses some cloud (the reference's transmittance layer
/// below 1).
fn cloud_share(img: &Image) -> f32 {
    let t = img.layer(TRANSMITTANCE).unwrap();
    t.iter().filter(|p| p.x < 1.0).count() as f32 / t.len() as f32
}

/// The quick render every test here makes: the path tracer at one path per pixel, 64×48.
const QUICK: [&str; 8] = ["--method", "reference", "--spp", "1", "--width", "64", "--height", "48"];

#[test]
fn a_vdb_alone_renders_framed_with_a_warning_about_its_size() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(data("sphere64_blosc.vdb"), dir.path().join("cloud.vdb")).unwrap();
    let mut args = vec!["render", "cloud.vdb", "-o", "out.exr"];
    args.extend(QUICK);
    let err = ok(dir.path(), &args);
    // The sphere is 2.9 m across: the warning names the factor that makes it a cloud.
    assert!(err.contains("2.900 m across") && err.contains("medium.scale = 100"), "{err}");
    let img = Image::read_exr(&dir.path().join("out.exr")).unwrap();
    // The box fills 90 % of the frame's height; the noisy sphere inside it covers 30 % of the
    // image (measured: 0.305); without the fit it covered one pixel.
    let share = cloud_share(&img);
    assert!((0.2..0.6).contains(&share), "the cloud covers {share} of the image");
    // A scene file without [camera] frames it the same way.
    std::fs::write(dir.path().join("s.toml"), "[medium]\ngrid = \"cloud.vdb\"\n").unwrap();
    let mut args = vec!["render", "s.toml", "-o", "file.exr"];
    args.extend(QUICK);
    ok(dir.path(), &args);
    let from_file = Image::read_exr(&dir.path().join("file.exr")).unwrap();
    assert_eq!(from_file.pixels, img.pixels);
}

/// Bad input for the keys and flags this file's features add: an error naming the file, the key
/// or flag and the fix, a non-zero exit and no output.
#[test]
fn bad_first_use_input_is_refused_before_any_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("bad.vdb"), b"not a vdb").unwrap();
    std::fs::write(d.join("fit.toml"), "[camera]\nfit = \"yes\"\n").unwrap();
    for (args, want) in [
        (
            vec!["render", "missing.vdb"],
            "missing.vdb: field `medium.grid`: `missing.vdb` is not a file",
        ),
        (vec!["render", "bad.vdb"], "bad.vdb"),
        (vec!["render", "fit.toml"], "expected a boolean"),
        (vec!["render", "--exposure", "nan"], "--exposure"),
        (vec!["render", "-o", "out.jpg"], "must end in .exr or .png"),
        (vec!["tonemap", "missing.exr", "-o", "t.png"], "missing.exr"),
        (vec!["tonemap", "fit.toml", "-o", "t.png"], "fit.toml"),
        (vec!["tonemap", "missing.exr", "-o", "t.exr"], "must be a file name ending in .png"),
        (vec!["tonemap", "missing.exr", "-o", ".png"], "must be a file name ending in .png"),
        (vec!["tonemap", "missing.exr", "-o", "t.png", "--exposure", "inf"], "--exposure"),
    ] {
        let out = cloudgi(d, &args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains(want), "{args:?}: {err}");
        let left: Vec<_> = std::fs::read_dir(d).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(left.len(), 2, "{args:?} wrote nothing: {left:?}");
    }
}

/// The exposed luminance (radiance × 2^stops) of the median cloud pixel (transmittance < 0.99).
fn cloud_median(img: &Image, stops: f32) -> f32 {
    let t = img.layer(TRANSMITTANCE).unwrap();
    let mut lum: Vec<f32> = img
        .pixels
        .iter()
        .zip(t)
        .filter(|(_, t)| t.x < 0.99)
        .map(|(p, _)| luminance(*p) * stops.exp2())
        .collect();
    lum.sort_by(f32::total_cmp);
    lum[lum.len() / 2]
}

#[test]
fn automatic_exposure_and_tonemap_remake_the_png() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::copy(data("sphere64_blosc.vdb"), d.join("cloud.vdb")).unwrap();
    // The sphere made 290 m across: an optically thick cloud under the default sun and sky.
    std::fs::write(d.join("s.toml"), "[medium]\ngrid = \"cloud.vdb\"\nscale = 100.0\n").unwrap();
    // `-o out.png` writes out.exr beside it.
    let mut args = vec!["render", "s.toml", "-o", "out.png", "--spp", "4"];
    args.extend(&QUICK[..2]);
    args.extend(&QUICK[4..]);
    let err = ok(d, &args);
    assert!(err.contains("automatic"), "{err}");
    let img = Image::read_exr(&d.join("out.exr")).unwrap();
    let stops = img.auto_exposure();
    // The rule maps the 99th percentile of luminance to 1; the cloud's median lands at 0.74
    // (+0.68 stops): a bright cloud below white.
    let median = cloud_median(&img, stops);
    assert!((0.4..0.9).contains(&median), "cloud median {median} at {stops} stops");
    // `tonemap` re-makes the PNG byte for byte; --exposure overrides both.
    ok(d, &["tonemap", "out.exr", "-o", "again.png"]);
    let png = std::fs::read(d.join("out.png")).unwrap();
    assert_eq!(std::fs::read(d.join("again.png")).unwrap(), png);
    ok(d, &["tonemap", "out.exr", "-o", "dark.png", "--exposure", "-3"]);
    assert_eq!(std::fs::read(d.join("dark.png")).unwrap(), img.to_png_bytes(-3.0).unwrap());
    // render.exposure in the scene file wins over the automatic rule; --exposure over both.
    std::fs::write(
        d.join("fixed.toml"),
        "[medium]\ngrid = \"cloud.vdb\"\nscale = 100.0\n[render]\nexposure = -1.0\n",
    )
    .unwrap();
    for (extra, want) in [(None, -1.0), (Some("2"), 2.0)] {
        let mut args = vec!["render", "fixed.toml", "-o", "fixed.exr", "--spp", "4"];
        args.extend(&QUICK[..2]);
        args.extend(&QUICK[4..]);
        if let Some(e) = extra {
            args.extend(["--exposure", e]);
        }
        ok(d, &args);
        let fixed = Image::read_exr(&d.join("fixed.exr")).unwrap();
        assert_eq!(std::fs::read(d.join("fixed.png")).unwrap(), fixed.to_png_bytes(want).unwrap());
    }
}

#[test]
fn a_z_up_file_renders_as_the_same_file_turned_y_up() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A lopsided blob, 12 × 8 × 6 voxels of 20 m (z-up: 6 voxels tall), and the same voxels
    // turned y-up by hand: (x, y, z) → (x, z, −y).
    let [nx, ny, nz] = [12, 8, 6];
    let rho = |i: usize, j: usize, k: usize| ((i * 7 + j * 3 + k * 5) % 11) as f32 * 0.1 * (i as f32 / nx as f32);
    std::fs::write(d.join("z.npy"), npy_grid([nx, ny, nz], rho)).unwrap();
    std::fs::write(d.join("y.npy"), npy_grid([nx, nz, ny], |i, k, j| rho(i, ny - 1 - j, k))).unwrap();
    let origin = [-120.0f32, -80.0, 10.0];
    let turned = [origin[0], origin[2], -(origin[1] + 20.0 * ny as f32)];
    let camera = "[camera]\nposition = [50.0, 300.0, 600.0]\nlook_at = [0.0, 60.0, 0.0]\nwidth = 32\nheight = 24\n";
    let medium = "[medium]\nvoxel_size = 20.0\nsigma_t = 0.02\n";
    std::fs::write(
        d.join("z.toml"),
        format!("{medium}grid = \"z.npy\"\nup_axis = \"z\"\norigin = {:?}\n{camera}", origin),
    )
    .unwrap();
    std::fs::write(
        d.join("y.toml"),
        format!("{medium}grid = \"y.npy\"\norigin = {:?}\n{camera}", turned),
    )
    .unwrap();
    for s in ["z", "y"] {
        ok(
            d,
            &["render", &format!("{s}.toml"), "-o", &format!("{s}.exr"), "--method", "single"],
        );
    }
    let (z, y) = (
        Image::read_exr(&d.join("z.exr")).unwrap(),
        Image::read_exr(&d.join("y.exr")).unwrap(),
    );
    assert_eq!(z.pixels, y.pixels);
    assert!(
        z.pixels.iter().any(|p| (*p - z.pixels[0]).abs().max_element() > 1e-3),
        "the cloud is in view"
    );
    // A bad value names the key and the choices.
    std::fs::write(d.join("bad.toml"), "[medium]\nup_axis = \"x\"\n").unwrap();
    let out = cloudgi(d, &["render", "bad.toml", "-o", "bad.exr"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("up_axis") && err.contains("expected `y` or `z`"),
        "{err}"
    );
}

#[test]
fn compare_says_when_it_compares_every_pixel() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::copy(data("sphere64_blosc.vdb"), d.join("cloud.vdb")).unwrap();
    ok(
        d,
        &[
            "render",
            "cloud.vdb",
            "-o",
            "a.exr",
            "--method",
            "single",
            "--width",
            "16",
            "--height",
            "12",
        ],
    );
    let err = ok(d, &["compare", "a.exr", "a.exr"]);
    assert!(err.contains("no `transmittance` layer, so every pixel is compared"), "{err}");
}

/// Packets (type, payload) of tev's protocol: a little-endian u32 length (itself included), a
/// type byte, the payload.
fn tev_packets(bytes: &[u8]) -> Vec<(u8, &[u8])> {
    let mut out = Vec::new();
    let mut i = 0;
    while i + 5 <= bytes.len() {
        let len = u32::from_le_bytes(bytes[i..i + 4].try_into().unwrap()) as usize;
        assert!(len >= 5 && i + len <= bytes.len(), "packet at {i} of length {len}");
        out.push((bytes[i + 4], &bytes[i + 5..i + len]));
        i += len;
    }
    assert_eq!(i, bytes.len(), "whole packets");
    out
}

/// A loopback listener standing in for tev: its address, and the bytes of its one connection.
fn tev_listener() -> (String, std::thread::JoinHandle<Vec<u8>>) {
    use std::io::Read;
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let reader = std::thread::spawn(move || {
        let (mut s, _) = listener.accept().unwrap();
        let mut bytes = Vec::new();
        s.read_to_end(&mut bytes).unwrap();
        bytes
    });
    (addr, reader)
}

/// The f32 RGB pixels at the end of an UpdateImageV3 payload of a `w`×`h` image.
fn update_pixels(payload: &[u8], w: usize, h: usize) -> Vec<f32> {
    payload[payload.len() - w * h * 12..]
        .chunks(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

/// A temporary folder holding the test sphere as `cloud.vdb`.
fn sphere_dir() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(data("sphere64_blosc.vdb"), dir.path().join("cloud.vdb")).unwrap();
    dir
}

/// Render `scene` in `d` to `out` at 16×12 with `extra` flags; with `live`, streamed to a
/// loopback tev listener, whose received bytes are returned.
fn render_small(d: &Path, scene: &str, out: &str, extra: &[&str], live: bool) -> Vec<u8> {
    let mut args = vec!["render", scene, "-o", out, "--width", "16", "--height", "12"];
    args.extend(extra);
    if !live {
        ok(d, &args);
        return Vec::new();
    }
    let (addr, reader) = tev_listener();
    args.extend(["--display-server", &addr]);
    ok(d, &args);
    reader.join().unwrap()
}

#[test]
fn display_server_streams_each_transport_iteration_and_full_sample() {
    let dir = sphere_dir();
    let d = dir.path();
    // The sphere at half resolution (29³ voxels, 3 iterations): the checks are on the stream.
    std::fs::write(d.join("half.toml"), "[medium]\ngrid = \"cloud.vdb\"\ndownsample = 2\n").unwrap();
    // The three renders at once: each is too small to keep both cores busy alone.
    let (bytes, full_bytes) = std::thread::scope(|s| {
        let live = s.spawn(|| render_small(d, "half.toml", "t.exr", &["--method", "transport"], true));
        let plain = s.spawn(|| render_small(d, "half.toml", "plain.exr", &["--method", "transport"], false));
        let full = render_small(d, "half.toml", "f.exr", &["--method", "full", "--aa-samples", "3"], true);
        plain.join().unwrap();
        (live.join().unwrap(), full)
    });
    let packets = tev_packets(&bytes);
    // CreateImage once, then an update per iteration (at least 2) and the final image.
    let updates: Vec<&[u8]> = packets.iter().filter(|p| p.0 == 6).map(|p| p.1).collect();
    assert_eq!(packets[0].0, 4);
    assert!(updates.len() >= 3, "{} updates", updates.len());
    let img = Image::read_exr(&d.join("t.exr")).unwrap();
    let want: Vec<f32> = img.pixels.iter().flat_map(|p| p.to_array()).collect();
    // The last iteration's live image is the gather of the converged field: the final image.
    assert_eq!(update_pixels(updates[updates.len() - 2], 16, 12), want);
    assert_eq!(update_pixels(updates[updates.len() - 1], 16, 12), want);
    // Without a viewer the image is the same, bit for bit.
    let plain = Image::read_exr(&d.join("plain.exr")).unwrap();
    assert_eq!(plain.pixels, img.pixels);
    // `full`: an update after each antialiasing sample but the last, then the final image.
    let types: Vec<u8> = tev_packets(&full_bytes).iter().map(|p| p.0).collect();
    assert_eq!(types, [4, 6, 6, 6]);
}

#[test]
fn display_server_streams_every_pass_to_a_tev_listener() {
    let dir = sphere_dir();
    let d = dir.path();
    let bytes = render_small(d, "cloud.vdb", "live.exr", &["--method", "reference", "--spp", "3"], true);
    let packets = tev_packets(&bytes);
    // CreateImage (4) once, then UpdateImageV3 (6) after each of the 3 passes and the final image.
    let types: Vec<u8> = packets.iter().map(|p| p.0).collect();
    assert_eq!(types, [4, 6, 6, 6, 6]);
    let create = packets[0].1;
    let name_end = 1 + create[1..].iter().position(|&b| b == 0).unwrap();
    assert_eq!(&create[1..name_end], b"live.exr");
    let size = &create[name_end + 1..name_end + 9];
    assert_eq!(
        (
            u32::from_le_bytes(size[..4].try_into().unwrap()),
            u32::from_le_bytes(size[4..].try_into().unwrap())
        ),
        (16, 12)
    );
    // The last update carries the final image's pixels, as f32 RGB at its end.
    let img = Image::read_exr(&d.join("live.exr")).unwrap();
    let floats = update_pixels(packets[4].1, 16, 12);
    let want: Vec<f32> = img.pixels.iter().flat_map(|p| p.to_array()).collect();
    assert_eq!(floats, want);
    // No viewer listening: a warning, and the render still succeeds.
    let args = [
        "render",
        "cloud.vdb",
        "-o",
        "live.exr",
        "--method",
        "reference",
        "--spp",
        "3",
        "--width",
        "16",
        "--height",
        "12",
    ];
    let closed = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .to_string();
    let mut no_view = args.to_vec();
    no_view.extend(["--display-server", &closed]);
    let err = ok(d, &no_view);
    assert!(err.contains("cannot reach a tev viewer"), "{err}");
    // A malformed address is refused before any work.
    let mut bad = args.to_vec();
    bad[3] = "bad.exr";
    bad.extend(["--display-server", "nowhere"]);
    let out = cloudgi(d, &bad);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("--display-server") && !d.join("bad.exr").exists(),
        "{err}"
    );
}
