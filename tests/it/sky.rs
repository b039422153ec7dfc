//! `cloudgi sky`: the sky exported as an EXR with its PNG, at the scene's width or `--width`, and a
//! bad width refused without writing anything (the map's content is checked in `src/tests/sky.rs`);
//! a sequence's sky by frame; a map's sun taken out as the scene's (`sky.extract_sun`) or warned about.

use crate::common::{cloudgi, ok};

#[test]
fn sky_writes_the_map_and_its_png_and_refuses_a_bad_width() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene =
        "[sun]\nelevation_deg = 4.0\nazimuth_deg = 30.0\nfrom_atmosphere = true\n\n[sky]\nmodel = \"atmosphere\"\nmap_width = 128\n";
    std::fs::write(d.join("sunset.toml"), scene).unwrap();
    ok(d, &["sky", "sunset.toml", "-o", "sky.exr", "--quiet"]);
    assert!(d.join("sky.png").is_file());
    assert_eq!(cloudgi::Image::read_exr(&d.join("sky.exr")).unwrap().width, 128);
    ok(d, &["sky", "sunset.toml", "-o", "wide.exr", "--width", "256", "--quiet"]);
    assert_eq!(cloudgi::Image::read_exr(&d.join("wide.exr")).unwrap().width, 256);
    // A bad width is refused without writing anything.
    let out = cloudgi(d, &["sky", "-o", "x.exr", "--width", "1", "--quiet"]);
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("--width"));
    assert!(!d.join("x.exr").exists());
}

#[test]
fn sky_of_a_sequence_shows_the_sun_of_the_frame_asked_for() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sky = "[sky]\nmodel = \"atmosphere\"\nmap_width = 32\n";
    let keys = "[animation]\nframes = \"1-5\"\n[[animation.key]]\nframe = 1\nsun.elevation_deg = 60.0\n\
        [[animation.key]]\nframe = 5\nsun.elevation_deg = 10.0\n";
    let sun = |elevation: &str| format!("[sun]\nelevation_deg = {elevation}\nazimuth_deg = 30.0\nfrom_atmosphere = true\n{sky}");
    std::fs::write(d.join("seq.toml"), format!("{}{keys}", sun("60.0"))).unwrap();
    std::fs::write(d.join("still.toml"), sun("35.0")).unwrap();
    // The keyed sun differs by frame: which one is asked for.
    let out = cloudgi(d, &["sky", "seq.toml", "-o", "a.exr", "--quiet"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("--frame") && err.contains("keys the sun"),
        "{err}"
    );
    assert!(!d.join("a.exr").exists());
    // Frame 3, halfway between the keys: the still scene's sun at 35°.
    ok(d, &["sky", "seq.toml", "--frame", "3", "-o", "f3.exr", "--quiet"]);
    ok(d, &["sky", "still.toml", "-o", "still.exr", "--quiet"]);
    assert!(std::fs::read(d.join("f3.exr")).unwrap() == std::fs::read(d.join("still.exr")).unwrap());
    let out = cloudgi(d, &["sky", "still.toml", "--frame", "3", "-o", "b.exr", "--quiet"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("not a sequence"), "{err}");
}

#[test]
fn a_maps_sun_is_taken_out_unless_extract_sun_is_false() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A 256×128 map of 0.5 with a 2×2-pixel sun of 10⁵ about 35° up, towards +z.
    let (w, h) = (256u32, 128u32);
    let mut map = cloudgi::Image::new(w, h);
    map.pixels = vec![cloudgi::Rgb::splat(0.5); (w * h) as usize];
    for j in 38..40 {
        for i in 60..62 {
            map.pixels[(j * w + i) as usize] = cloudgi::Rgb::splat(1e5);
        }
    }
    map.write_exr(&d.join("sunny.exr")).unwrap();
    let scene = |extract: &str| {
        format!(
            "[medium]\nresolution = [8, 8, 8]\nvoxel_size = 100.0\n[sun]\nirradiance = [0.0, 0.0, 0.0]\n\
             [sky]\nmodel = \"envmap\"\npath = \"sunny.exr\"\n{extract}\n[camera]\nwidth = 8\nheight = 6\n"
        )
    };
    std::fs::write(d.join("kept.toml"), scene("extract_sun = false")).unwrap();
    std::fs::write(d.join("taken.toml"), scene("extract_sun = true")).unwrap();
    std::fs::write(d.join("found.toml"), scene("")).unwrap();
    let render = |file: &str| {
        let out = cloudgi(d, &["render", file, "--method", "transport", "-o", "x.exr"]);
        assert!(out.status.success(), "{out:?}");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    assert!(render("kept.toml").contains("extract_sun = true"));
    assert!(!render("taken.toml").contains("holds a sun"));
    // Left out, the sun is taken out too, and a note says so and how to keep it in the map.
    let found = render("found.toml");
    assert!(
        found.contains("holds a sun: it is taken out") && found.contains("extract_sun = false"),
        "{found}"
    );
    let (a, b) = (d.join("a.exr"), d.join("b.exr"));
    for (file, out) in [("taken.toml", &a), ("found.toml", &b)] {
        let out = out.to_string_lossy().into_owned();
        assert!(cloudgi(d, &["render", file, "--method", "transport", "-q", "-o", &out])
            .status
            .success());
    }
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap(), "the same scene either way");
    // `cloudgi sky` shows the map without it and the sun it became.
    let shown = ok(d, &["sky", "taken.toml", "-o", "painted.exr"]);
    assert!(shown.contains("sun (not in the map): direction [0.060"), "{shown}");
    let painted = cloudgi::Image::read_exr(&d.join("painted.exr")).unwrap();
    assert!(painted.pixels.iter().all(|p| *p == cloudgi::Rgb::splat(0.5)));
}

#[test]
fn a_clipped_sun_taken_out_with_extract_sun_is_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A 1024×512 map of 0.5 with a Gaussian sun (σ = 2 pixels, peak 10⁶), as it is and cut at
    // half float's largest value.
    let (w, h) = (1024u32, 512u32);
    for (name, ceiling) in [("whole.exr", f32::MAX), ("clipped.exr", 65504.0)] {
        let mut map = cloudgi::Image::new(w, h);
        map.pixels = (0..w * h)
            .map(|k| {
                let (di, dj) = ((k % w) as f32 - 200.3, (k / w) as f32 - 120.6);
                cloudgi::Rgb::splat((0.5 + 1e6 * (-(di * di + dj * dj) / 8.0).exp()).min(ceiling))
            })
            .collect();
        map.write_exr(&d.join(name)).unwrap();
        let scene = format!(
            "[medium]\nresolution = [8, 8, 8]\nvoxel_size = 100.0\n[sky]\nmodel = \"envmap\"\npath = \"{name}\"\n\
             extract_sun = true\n[camera]\nwidth = 8\nheight = 6\n"
        );
        std::fs::write(d.join("s.toml"), scene).unwrap();
        let out = cloudgi(d, &["render", "s.toml", "--method", "transport", "-o", "x.exr"]);
        assert!(out.status.success(), "{out:?}");
        let said = String::from_utf8_lossy(&out.stderr);
        let warned = said.contains("warning: s.toml: the sun sky.extract_sun took out of `clipped.exr` is clipped");
        assert_eq!(warned, name == "clipped.exr", "{said}");
        let shown = ok(d, &["sky", "s.toml", "-o", "painted.exr"]);
        assert_eq!(shown.contains("a lower bound"), name == "clipped.exr", "{shown}");
    }
}
