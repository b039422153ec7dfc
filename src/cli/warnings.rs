//! Warnings for settings that do not apply to this scene or method (they would be silently
//! ignored) and for a cloud the camera cannot see. Printed on stderr; the render still runs.

use super::scene_file::SceneFile;
use crate::math::Vec3;
use crate::scene::{Method, Scene, SkyModel, RENDER_KEYS};
use crate::sequence::FrameList;

/// What kind of grid the medium is: the one `medium.grid` names, or an array given in memory.
#[derive(Clone, Copy, PartialEq, Eq)]
enum GridKind {
    Procedural,
    Vol,
    Npy,
    Raw,
    Vdb,
    Array,
}

fn grid_kind(grid: &str) -> GridKind {
    if grid == "procedural" {
        return GridKind::Procedural;
    }
    let ext = std::path::Path::new(grid)
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    match ext.as_str() {
        "vol" => GridKind::Vol,
        "npy" => GridKind::Npy,
        "raw" => GridKind::Raw,
        // The loader refuses other extensions before this runs.
        _ => GridKind::Vdb,
    }
}

/// Every warning for `scene`, read from `file`; `flags` are the command-line options given,
/// as (the key they set, the flag).
pub fn warnings(file: &SceneFile, flags: &[(&str, &str)], scene: &Scene) -> Vec<String> {
    let given_by = |key: &str| match flags.iter().find(|(k, _)| *k == key) {
        Some((_, flag)) => Some(format!("command line: `{flag}`")),
        None if file.sets(key) => Some(format!("{}: `{key}`", file.source)),
        None => None,
    };
    let mut out = scene.notes.clone();
    out.extend(ignored_settings(scene, false, &given_by));
    out.extend(scene_warnings(scene));
    out
}

/// The warnings for keys that do not apply to `scene`'s grid, sun, sky, ground or method (they
/// would be silently ignored). `given_by(key)` says who set `table.key` (`command line:
/// `--spp 4``), or None where nobody did (a default never warns); `array` is whether the density
/// came as an array in memory, which replaces `medium.grid`.
pub fn ignored_settings(scene: &Scene, array: bool, given_by: &dyn Fn(&str) -> Option<String>) -> Vec<String> {
    let d = &scene.desc;
    let mut out = Vec::new();
    let mut rule = |key: &str, applies: bool, why: &str| {
        if applies {
            return;
        }
        if let Some(given) = given_by(key) {
            out.push(format!("{given} does not apply {why}; it is ignored"));
        }
    };

    let kind = if array { GridKind::Array } else { grid_kind(&d.medium.grid) };
    let file_grid = match kind {
        GridKind::Array => "to a density array (it replaces medium.grid)".to_string(),
        _ => format!("to a grid read from a file (`{}` gives it)", d.medium.grid),
    };
    rule("medium.grid", kind != GridKind::Array, &file_grid);
    rule("medium.seed", kind == GridKind::Procedural, &file_grid);
    rule("medium.resolution", kind == GridKind::Procedural, &file_grid);
    let placement = match kind {
        GridKind::Vol => "to a .vol grid (the file carries its own bounding box)",
        _ => "to a .vdb grid (the file carries its own transform; medium.scale scales it)",
    };
    let placed_by_desc = matches!(kind, GridKind::Procedural | GridKind::Npy | GridKind::Raw | GridKind::Array);
    rule("medium.voxel_size", placed_by_desc, placement);
    rule("medium.origin", placed_by_desc, placement);
    let not_vdb = "unless medium.grid is a .vdb file";
    rule("medium.grid_name", kind == GridKind::Vdb, not_vdb);
    rule("medium.scale", kind == GridKind::Vdb, not_vdb);

    rule(
        "sun.irradiance",
        !d.sun.from_atmosphere,
        "with sun.from_atmosphere = true (the atmosphere gives the irradiance)",
    );
    rule(
        "sun.angular_diameter_deg",
        d.sun.angular_diameter_deg == 0.0,
        "to any method (each lights the scene with a point sun: sharp shadows, no disc drawn)",
    );
    let sky = d.sky.model;
    rule("sky.radiance", sky == SkyModel::Constant, "unless sky.model = \"constant\"");
    let atmosphere = "unless sky.model = \"atmosphere\"";
    rule(
        "sky.altitude_m",
        sky == SkyModel::Atmosphere || d.sun.from_atmosphere,
        "unless sky.model = \"atmosphere\" or sun.from_atmosphere = true",
    );
    rule("sky.map_width", sky == SkyModel::Atmosphere, atmosphere);
    rule("sky.planet_albedo", sky == SkyModel::Atmosphere, atmosphere);
    rule("sky.path", sky == SkyModel::Envmap, "unless sky.model = \"envmap\"");
    rule("sky.scale", sky == SkyModel::Envmap, "unless sky.model = \"envmap\"");
    let ground = d.ground.as_ref().is_some_and(|g| g.enabled);
    rule("ground.height", ground, "with ground.enabled = false");
    rule("ground.albedo", ground, "with ground.enabled = false");

    let m = scene.render.method;
    let name = m.name();
    for k in RENDER_KEYS {
        let why = match k.hint {
            Some(hint) => format!("to method {name} ({hint})"),
            None => format!("to method {name} (only {} it)", readers(k.methods)),
        };
        rule(&format!("render.{}", k.key), k.applies_to(m), &why);
    }
    // The sky's single scattering is the reduced sky of stage 1, which carries no sky when the
    // sky enters through the boundary condition (its light is then in I0 itself).
    let sky_single = RENDER_KEYS.iter().find(|k| k.key == "sky_single_scattering");
    if sky_single.is_some_and(|k| k.applies_to(m)) && scene.render.solver.sky_boundary {
        rule(
            "render.sky_single_scattering",
            false,
            "with render.sky_boundary = true (the sky enters through the diffusion's boundary and is in I0 itself; \
             set render.sky_boundary = false for the paper's stage-1 sky)",
        );
    }
    out
}

/// The warnings about the scene itself, whatever its keys were given by (a file, flags, the
/// Python package's keywords): a sun under the ground, a grid of zeros, a cloud of an odd size,
/// thick voxels, a low albedo, a back-scattering phase function, a sun in the sky map or a
/// clipped one, a cloud the camera does not see.
pub fn scene_warnings(scene: &Scene) -> Vec<String> {
    let mut out = Vec::new();
    out.extend(hidden_sun_warning(scene));
    // A medium with no density (an empty .vdb frame, which its note reports) has no cloud to
    // size or frame.
    let cloud = scene.medium.active_box(0).is_some();
    out.extend(no_density_warning(scene).filter(|_| !cloud));
    out.extend(super::cloud_size::warning(scene).filter(|_| cloud));
    out.extend(super::thick_voxels::warning(scene));
    out.extend(super::low_albedo::warning(scene));
    out.extend(super::back_scattering::warning(scene));
    out.extend(super::map_sun::found_note(scene));
    out.extend(super::map_sun::warning(scene));
    out.extend(super::map_sun::clip_warning(scene));
    out.extend(frame_warning(scene).filter(|_| cloud));
    out
}

/// The warnings of a sequence's frames that did not hold unchanged on every one of them, each
/// once, naming its frames (`frames 3-7: …`): `per_frame` holds each frame's number and
/// warnings, in frame order. Warnings of one [`kind`] (differing only in their numbers: a keyed
/// sun's elevation, a keyed extinction's optical depths) are one, shown with its first frame's
/// numbers.
pub fn over_some_frames(per_frame: &[(u32, Vec<String>)]) -> Vec<String> {
    struct Seen<'a> {
        shape: String,
        first: &'a str,
        frames: Vec<u32>,
        varies: bool,
    }
    let mut seen: Vec<Seen> = Vec::new();
    for (frame, warnings) in per_frame {
        for w in warnings {
            let shape = kind(w);
            // Two warnings of one frame stay two, whatever their shape.
            match seen.iter_mut().find(|s| s.shape == shape && s.frames.last() != Some(frame)) {
                Some(s) => {
                    s.frames.push(*frame);
                    s.varies |= s.first != w;
                }
                None => seen.push(Seen {
                    shape,
                    first: w,
                    frames: vec![*frame],
                    varies: false,
                }),
            }
        }
    }
    seen.into_iter()
        .filter(|s| s.frames.len() < per_frame.len() || s.varies)
        .map(|s| {
            let at = if s.varies {
                format!(" (the numbers are frame {}'s)", s.frames[0])
            } else {
                String::new()
            };
            let frames = FrameList::of(s.frames);
            let which = if frames.frames().len() == 1 { "frame" } else { "frames" };
            format!("{which} {frames}{at}: {}", s.first)
        })
        .collect()
}

/// A warning's kind: its text with each number (`-2.86`, `19`) written `#`.
pub fn kind(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut chars = text.chars().peekable();
    let mut in_number = false;
    while let Some(c) = chars.next() {
        let starts = c.is_ascii_digit() || (c == '-' && chars.peek().is_some_and(char::is_ascii_digit));
        let digit = starts || (in_number && c == '.');
        if !digit {
            out.push(c);
        } else if !in_number {
            out.push('#');
        }
        in_number = digit;
    }
    out
}

/// A warning when the ground hides a sun given an irradiance of its own (a sun from the
/// atmosphere is dark below the horizon anyway): the scene is lit by the sky alone
/// ([`crate::lighting::sun_over_ground`]).
fn hidden_sun_warning(scene: &Scene) -> Option<String> {
    let d = &scene.desc.sun;
    let extracted = scene.sky.sun_from_map.is_some();
    let given = extracted || (!d.from_atmosphere && d.irradiance.iter().any(|&e| e > 0.0));
    let hidden = scene.ground.is_some() && scene.sun.irradiance == crate::math::Rgb::ZERO;
    let raise = match extracted {
        true => {
            "the sun taken out of the map (sky.extract_sun) lies there; set ground.enabled = false to light the cloud \
                 from below"
        }
        false => {
            "raise sun.direction's y (or sun.elevation_deg) above 0, or set ground.enabled = false to light the \
             cloud from below"
        }
    };
    (given && hidden).then(|| {
        format!(
            "{}: the sun is {:.2}° below the horizon and the ground hides it: it lights nothing directly, \
             only the sky lights the scene; {raise}",
            scene.source,
            -scene.sun.dir.y.asin().to_degrees()
        )
    })
}

/// A warning when the grid's densities are all 0, so the image shows no cloud: an array of
/// zeros, or of values float32 cannot tell from 0 (1e-300 in a float64 `.npy`). A `.vdb` read
/// with no active voxels has its own note (an array given in its place has none).
fn no_density_warning(scene: &Scene) -> Option<String> {
    let noted = grid_kind(&scene.desc.medium.grid) == GridKind::Vdb && !scene.notes.is_empty();
    (!noted).then(|| {
        format!(
            "{}: every density of the grid is 0 (or below float32's smallest, 1.4e-45, which reads as 0): the image \
             shows sky and ground only; check the grid (or scale its densities up and medium.sigma_t down)",
            scene.source
        )
    })
}

/// "diffusion and full uses"-style list of the methods that read a key: "full uses",
/// "diffusion and full use", "single, diffusion, full and transport use".
fn readers(methods: &[Method]) -> String {
    let names: Vec<&str> = methods.iter().map(|m| m.name()).collect();
    match names.as_slice() {
        [one] => format!("{one} uses"),
        [rest @ .., last] => format!("{} and {last} use", rest.join(", ")),
        [] => "no method uses".into(),
    }
}

/// A warning when the camera cannot see the cloud: its box is outside the view or smaller than a
/// pixel (e.g. a .vdb in centimetres without `medium.scale`).
fn frame_warning(scene: &Scene) -> Option<String> {
    let (lo, hi) = scene.medium.bbox();
    let cam = &scene.camera;
    let p = cam.position;
    if p.cmpge(lo).all() && p.cmple(hi).all() {
        return None;
    }
    let corners: Vec<Vec3> = (0..8)
        .map(|c| {
            Vec3::new(
                if c & 1 == 0 { lo.x } else { hi.x },
                if c & 2 == 0 { lo.y } else { hi.y },
                if c & 4 == 0 { lo.z } else { hi.z },
            )
        })
        .collect();
    let (w, h) = (cam.width as f32, cam.height as f32);
    let aspect = w / h;
    // Image-plane position in pixels of a point in front of the camera.
    let project = |q: Vec3| -> Option<(f32, f32)> {
        let v = q - p;
        let z = v.dot(cam.forward);
        (z > 0.0).then(|| {
            let sx = v.dot(cam.right) / (z * cam.tan_half_fov * aspect);
            let sy = v.dot(cam.up) / (z * cam.tan_half_fov);
            ((sx + 1.0) * 0.5 * w, (1.0 - sy) * 0.5 * h)
        })
    };
    let projected: Vec<Option<(f32, f32)>> = corners.iter().map(|&c| project(c)).collect();
    let inside = |&(x, y): &(f32, f32)| (0.0..=w).contains(&x) && (0.0..=h).contains(&y);
    let corner_inside = projected.iter().flatten().any(inside);
    // Rays through a grid over the image catch a box that spans the frame without a corner in it.
    let n = 64;
    let ray_hits = (0..=n).any(|j| {
        (0..=n).any(|i| {
            let r = cam.ray(w * i as f32 / n as f32, h * j as f32 / n as f32);
            scene.medium.intersect(r.origin, r.dir, 0.0, f32::INFINITY).is_some()
        })
    });
    let bbox = format!("{:?} .. {:?} m", lo.to_array(), hi.to_array());
    let fix = "check camera.position and camera.look_at, or medium.voxel_size / medium.scale \
               (a .vdb in centimetres needs medium.scale = 0.01)";
    if !corner_inside && !ray_hits {
        return Some(format!(
            "{}: the cloud's bounding box {bbox} is not in the camera's view, the image will show no cloud; {fix}",
            scene.source
        ));
    }
    if projected.iter().all(Option::is_some) {
        let xs = projected.iter().flatten().map(|q| q.0);
        let ys = projected.iter().flatten().map(|q| q.1);
        let span = |v: &mut dyn Iterator<Item = f32>| {
            let (a, b) = v.fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), x| (a.min(x), b.max(x)));
            b - a
        };
        let (sx, sy) = (span(&mut xs.into_iter()), span(&mut ys.into_iter()));
        if sx < 1.0 && sy < 1.0 {
            return Some(format!(
                "{}: the cloud's bounding box {bbox} covers less than one pixel of the image; {fix}",
                scene.source
            ));
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn warnings_of(path: &Path) -> Vec<String> {
        let file = SceneFile::read(Some(path)).unwrap();
        let scene = Scene::build(file.desc.clone(), &file.source, &file.base).unwrap();
        warnings(&file, &[], &scene)
    }

    /// The warnings for a scene file holding `contents`.
    fn warnings_for(contents: &str) -> Vec<String> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.toml");
        std::fs::write(&p, contents).unwrap();
        warnings_of(&p)
    }

    #[test]
    fn the_examples_warn_about_nothing() {
        let mut n = 0;
        for folder in ["examples", "examples/eval", "examples/eval/glare", "examples/eval/spread"] {
            for e in std::fs::read_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join(folder)).unwrap() {
                let p = e.unwrap().path();
                if p.extension().is_some_and(|x| x == "toml") {
                    assert_eq!(warnings_of(&p), Vec::<String>::new(), "{}", p.display());
                    n += 1;
                }
            }
        }
        assert!(n >= 39, "{n} example scenes");
    }

    #[test]
    fn each_render_key_warns_exactly_for_the_methods_that_do_not_read_it() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.toml");
        // Every [render] key at its default (the two without one given a value).
        let toml::Value::Table(mut keys) = toml::Value::try_from(crate::scene::RenderDesc::default()).unwrap() else {
            panic!("[render] serialises as a table");
        };
        keys.insert("max_depth".into(), 10.into());
        keys.insert("time_limit".into(), 100.0.into());
        let declared: Vec<&str> = RENDER_KEYS.iter().map(|k| k.key).collect();
        let mut written: Vec<&str> = keys.keys().map(String::as_str).collect();
        written.sort_unstable();
        let mut sorted = declared.clone();
        sorted.sort_unstable();
        assert_eq!(written, sorted, "RENDER_KEYS declares every [render] key once");
        for m in Method::ALL {
            keys.insert("method".into(), m.name().into());
            let render = toml::to_string(&keys).unwrap();
            std::fs::write(
                &p,
                format!("[medium]\nresolution = [4, 4, 4]\nvoxel_size = 100.0\n\n[render]\n{render}"),
            )
            .unwrap();
            let w = warnings_of(&p);
            for k in RENDER_KEYS {
                let warned = w
                    .iter()
                    .any(|s| s.contains(&format!("`render.{}` does not apply to method {}", k.key, m.name())));
                assert_eq!(warned, !k.applies_to(m), "render.{} with method {}: {w:?}", k.key, m.name());
            }
        }
        assert_eq!(readers(&[Method::Full]), "full uses");
        assert_eq!(readers(&[Method::Diffusion, Method::Full]), "diffusion and full use");
    }

    #[test]
    fn a_sun_below_the_horizon_is_reported_only_where_the_ground_hides_it() {
        let grid = "[medium]\nresolution = [4, 4, 4]\nvoxel_size = 100.0\n";
        for (rest, warned) in [
            ("[sun]\ndirection = [1.0, -0.05, 0.0]\n[ground]\n", true),
            ("[sun]\ndirection = [1.0, 0.05, 0.0]\n[ground]\n", false),
            // No `[ground]` table: no ground.
            ("[sun]\ndirection = [1.0, -0.05, 0.0]\n", false),
            (
                "[sun]\ndirection = [1.0, -0.05, 0.0]\nirradiance = [0.0, 0.0, 0.0]\n[ground]\n",
                false,
            ),
        ] {
            let w = warnings_for(&format!("{grid}{rest}"));
            assert_eq!(w.iter().any(|m| m.contains("2.86° below the horizon")), warned, "{rest}: {w:?}");
        }
    }

    #[test]
    fn a_sequence_names_each_warning_once_with_its_frames() {
        let w = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let per_frame = vec![
            (1, w(&["a", "the sun is 0.50° below"])),
            (2, w(&["a", "the sun is 10.00° below", "c 3"])),
            (3, w(&["a", "the sun is 20.00° below"])),
            (5, w(&["a", "c 3", "c 4"])),
        ];
        assert_eq!(
            over_some_frames(&per_frame),
            [
                "frames 1-3 (the numbers are frame 1's): the sun is 0.50° below",
                "frames 2,5: c 3",
                "frame 5: c 4"
            ]
        );
        assert_eq!(kind("at -2.86° and [1.0, -3]; x-ray"), "at #° and [#, #]; x-ray");
    }

    #[test]
    fn an_array_of_zeros_given_for_a_vdb_grid_is_reported() {
        let mut desc = crate::scene::SceneDesc::default();
        desc.medium.grid = "cloud.vdb".into();
        let zeros = crate::Density::new([2, 2, 2], vec![0.0; 8], 100.0, [0.0; 3]).unwrap();
        let scene = Scene::build_with(desc, "s.toml", Path::new("."), Some(zeros)).unwrap();
        assert!(scene_warnings(&scene).iter().any(|m| m.contains("every density of the grid is 0")));
    }

    #[test]
    fn a_grid_of_zeros_is_reported_and_one_with_a_density_is_not() {
        let dir = tempfile::tempdir().unwrap();
        for (value, warned) in [(0.0f64, true), (1e-300, true), (1e-3, false)] {
            // A float64 .npy of 2×2×2.
            let header = "{'descr': '<f8', 'fortran_order': False, 'shape': (2, 2, 2), }";
            let mut npy = b"\x93NUMPY\x01\x00".to_vec();
            let pad = 64 - (10 + header.len() + 1) % 64;
            npy.extend_from_slice(&((header.len() + pad + 1) as u16).to_le_bytes());
            npy.extend_from_slice(header.as_bytes());
            npy.extend(std::iter::repeat_n(b' ', pad));
            npy.push(b'\n');
            npy.extend((0..8).flat_map(|_| value.to_le_bytes()));
            std::fs::write(dir.path().join("g.npy"), npy).unwrap();
            let p = dir.path().join("s.toml");
            std::fs::write(&p, "[medium]\ngrid = \"g.npy\"\nvoxel_size = 100.0\n").unwrap();
            let w = warnings_of(&p);
            assert_eq!(
                w.iter().any(|m| m.contains("every density of the grid is 0")),
                warned,
                "{value}: {w:?}"
            );
        }
    }

    #[test]
    fn a_sun_disc_is_reported_as_ignored_and_a_point_sun_is_not() {
        for (diameter, warned) in [(0.53, true), (0.0, false)] {
            let w = warnings_for(&format!("[sun]\nangular_diameter_deg = {diameter:?}\n"));
            assert_eq!(
                w.iter().any(|m| m.contains("`sun.angular_diameter_deg` does not apply")),
                warned,
                "{w:?}"
            );
        }
    }

    #[test]
    fn a_cloud_behind_the_camera_or_beside_the_frame_is_reported() {
        let grid = "[medium]\nresolution = [4, 4, 4]\nvoxel_size = 100.0\n";
        for (camera, warned) in [
            ("", false),
            ("[camera]\nlook_at = [0.0, 330.0, 3000.0]\n", true),
            ("[camera]\nlook_at = [3000.0, 330.0, 1500.0]\n", true),
            // Inside the cloud's box: it surrounds the camera.
            (
                "[camera]\nposition = [-300.0, 200.0, -200.0]\nlook_at = [0.0, 200.0, 3000.0]\n",
                false,
            ),
        ] {
            let w = warnings_for(&format!("{grid}{camera}"));
            assert_eq!(w.iter().any(|m| m.contains("not in the camera's view")), warned, "{camera}: {w:?}");
        }
    }
}
