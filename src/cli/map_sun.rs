//! A warning when an environment map holds a sun of its own (a compact source carrying much of
//! its light): `transport` takes the sky's light as its mean over each ordinate's cell, about 20°
//! wide, so a source a few map pixels wide keeps its power but loses its direction; `full` and
//! `diffusion` take it as their bins' means (cells about 20° wide too) and let the sky in at the
//! cloud's surface as diffuse light, so a sun's light keeps its power but not the depth a
//! collimated beam reaches; `reference` samples the map exactly. The warning points to
//! `sky.extract_sun`, which takes it out of the map as the scene's sun, carried exactly.

use crate::lighting::{SkyModel, SunFromMap};
use crate::math::{luminance, Rgb};
use crate::scene::{Method, Scene};

/// Angular radius (°) around the sun sky.extract_sun took out within which what is left is
/// its aureole: the extracted region is at most 0.01 sr, a cap about 3.2° in radius.
const AUREOLE_RADIUS_DEG: f32 = 5.0;

/// How each method takes a map's sun, and what it measured (docs/sky.md, "A sun in the map").
fn measured(method: Method) -> Option<(&'static str, &'static str)> {
    match method {
        Method::Transport => Some((
            "averages over cells about 20° wide, keeping its light but blurring its direction",
            "transport 11 % block error and −7 % on the cloud",
        )),
        Method::Full => Some((
            "averages over bins about 20° wide and lets in at the cloud's surface as diffuse light, keeping its \
             power but not the depth a beam reaches",
            "full 15 % block error and +16 % on the cloud",
        )),
        Method::Diffusion => Some((
            "averages over bins about 20° wide and lets in at the cloud's surface as diffuse light, keeping its \
             power but not the depth a beam reaches",
            "diffusion 23 % block error on the cloud",
        )),
        Method::Single | Method::Reference => None,
    }
}

/// The warning for `scene`, if its sky is an environment map whose compact source carries more
/// than [`SHARE`] of its light and its method takes the map as its means over wide cells.
pub fn warning(scene: &Scene) -> Option<String> {
    let (takes, measured) = measured(scene.render.method)?;
    if scene.desc.sky.model != SkyModel::Envmap {
        return None;
    }
    let c = scene.sky.map()?.compact_source()?;
    if !c.is_sun() {
        return None;
    }
    // What sky.extract_sun leaves around the sun it took out (a bright sun's flanks under its
    // threshold: a Gaussian sun's tail holds about 0.5 % of its light, yet much of a dim sky's)
    // is the sun's own aureole, not another sun.
    let aureole = scene.sky.sun_from_map.is_some() && c.direction.angle_between(scene.sun.dir) < AUREOLE_RADIUS_DEG.to_radians();
    if aureole {
        return None;
    }
    let fix = match scene.sky.sun_from_map {
        None => "set [sky] extract_sun = true, which makes it the scene's sun (docs/sky.md)",
        Some(_) => "it is another than the sun taken out of the map; paint it out of the map",
    };
    Some(format!(
        "{}: the sky map holds a sun ({:.0} % of its light in {:.1e} sr towards [{:.3}, {:.3}, {:.3}]), which method {} \
         {takes} (a 3×3-pixel sun in a 512×256 map: {measured}; \
         docs/sky.md, \"A sun in the map\"); {fix}, or render with --method reference",
        scene.source,
        100.0 * c.share,
        c.solid_angle,
        c.direction.x,
        c.direction.y,
        c.direction.z,
        scene.render.method.name(),
    ))
}

/// Under a clear sky, the sun's irradiance on a plane facing it over the sky's on a level plane
/// (direct normal over diffuse horizontal irradiance): about 850 over 100 W/m² with the sun 45°
/// high, 550 over 60 with it 15° high; a hazy sky's is lower (600 over 200).
const CLEAR_SKY_SUN_OVER_SKY: (f32, f32) = (5.0, 10.0);

/// The note for `scene` when its sun was taken out of its map with `sky.extract_sun` left out
/// ([`SunFromMap::Found`]): the scene's light is the map's, but where it comes from has changed.
pub fn found_note(scene: &Scene) -> Option<String> {
    if scene.sky.sun_from_map != Some(SunFromMap::Found) {
        return None;
    }
    let (d, e) = (scene.sun.dir, scene.sun.irradiance);
    Some(format!(
        "{}: the sky map `{}` holds a sun: it is taken out of the map as the scene's sun, towards [{:.3}, {:.3}, \
         {:.3}] with {}, which every method carries exactly (they would blur it over cells about 20° wide; \
         docs/sky.md, \"A sun in the map\"); set sky.extract_sun = false to keep it in the map",
        scene.source,
        scene.desc.sky.path.as_deref().unwrap_or_default(),
        d.x,
        d.y,
        d.z,
        rgb_text(e, "W/m²"),
    ))
}

/// The warning for `scene` when the sun `sky.extract_sun` took out of its map was clipped
/// ([`crate::lighting::sun_clip`]): its irradiance is a lower bound.
pub fn clip_warning(scene: &Scene) -> Option<String> {
    let clip = scene.sky.extracted_sun_clip?;
    let d = &scene.desc.sky;
    let path = d.path.as_deref().unwrap_or_default();
    // The ceiling as the file holds it (the map is the file times sky.scale).
    let in_file = clip.ceiling / d.scale;
    let ceiling = match in_file.max_element() == in_file.min_element() {
        true => format!("{}", in_file.x),
        false => ["R", "G", "B"]
            .iter()
            .zip(in_file.to_array())
            .filter(|(_, c)| *c > 0.0)
            .map(|(band, c)| format!("{c} in {band}"))
            .collect::<Vec<_>>()
            .join(", "),
    };
    // A sun under the ground lights nothing (another warning says so).
    let e = scene.sun.irradiance;
    if e == Rgb::ZERO {
        return None;
    }
    let sky = luminance(scene.sky.irradiance_up);
    let ratio = luminance(e) / sky;
    let (low, high) = CLEAR_SKY_SUN_OVER_SKY;
    let against_sky = match (sky > 0.0, ratio < low) {
        (false, _) => String::new(),
        (true, false) => format!("; it is {ratio:.2} times the sky's on a level plane"),
        (true, true) => format!(
            "; it is {ratio:.2} times the sky's on a level plane, where under a clear sky the sun's is {low:.0} to \
             {high:.0} times it, so it may hold as little as 1/{:.0} to 1/{:.0} of the sun's light",
            low / ratio,
            high / ratio
        ),
    };
    Some(format!(
        "{}: the sun sky.extract_sun took out of `{path}` is clipped: {} of its pixels ({:.1e} sr) hold its brightest \
         value, {ceiling} in the file, so its irradiance, {}, is a lower bound (docs/sky.md, \"A clipped sun\"){against_sky}; use an \
         HDRI whose sun is not clipped",
        scene.source,
        clip.pixels,
        clip.solid_angle,
        rgb_text(e, "W/m²"),
    ))
}

/// `(r, g, b) unit`, each to 3 significant digits.
fn rgb_text(c: Rgb, unit: &str) -> String {
    let digits = |x: f32| format!("{x:.2e}").parse::<f64>().unwrap_or(x as f64);
    format!("({}, {}, {}) {unit}", digits(c.x), digits(c.y), digits(c.z))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Image;
    use crate::scene::SceneDesc;

    #[test]
    fn a_sun_kept_in_the_map_warns_the_methods_that_blur_it_and_one_taken_out_is_noted() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (128, 64);
        let mut img = Image::new(w, h);
        img.pixels = vec![Rgb::splat(0.5); (w * h) as usize];
        let uniform = dir.path().join("uniform.exr");
        img.write_exr(&uniform).unwrap();
        img.pixels[20 * w as usize + 30] = Rgb::splat(1e6);
        let sunny = dir.path().join("sun.exr");
        img.write_exr(&sunny).unwrap();
        let scene = |map: &std::path::Path, method: Method, extract_sun: Option<bool>| {
            let mut d = SceneDesc::default();
            d.medium.resolution = [20, 16, 12];
            d.sky.model = SkyModel::Envmap;
            d.sky.path = Some(map.to_string_lossy().into_owned());
            d.sky.extract_sun = extract_sun;
            d.render.method = method;
            Scene::build(d, "s.toml", dir.path()).unwrap()
        };
        for m in [Method::Transport, Method::Full, Method::Diffusion] {
            let w = warning(&scene(&sunny, m, Some(false))).expect("a sun in the map");
            assert!(
                w.contains("s.toml") && w.contains("extract_sun = true") && w.contains("--method reference"),
                "{w}"
            );
            assert_eq!(warning(&scene(&uniform, m, Some(false))), None);
            // Left out, sky.extract_sun takes the sun out (the default [sun] has none of its own
            // light): no warning, a note that says so and how to keep it.
            let taken = scene(&sunny, m, None);
            assert_eq!(warning(&taken), None);
            let note = found_note(&taken).expect("a note");
            assert!(
                note.contains("s.toml") && note.contains("sun.exr") && note.contains("extract_sun = false"),
                "{note}"
            );
            assert_eq!(found_note(&scene(&sunny, m, Some(true))), None);
            assert_eq!(found_note(&scene(&uniform, m, None)), None);
        }
        assert_eq!(warning(&scene(&sunny, Method::Reference, Some(false))), None);
    }

    /// A 1024×512 map of 0.5 with a Gaussian sun (σ = 2 pixels, peak 10⁶) cut at `ceiling`.
    fn clipped_sun_map(ceiling: f32) -> Image {
        let (w, h) = (1024u32, 512u32);
        let mut img = Image::new(w, h);
        img.pixels = (0..w * h)
            .map(|k| {
                let (di, dj) = ((k % w) as f32 - 200.3, (k / w) as f32 - 120.6);
                Rgb::splat((0.5 + 1e6 * (-(di * di + dj * dj) / 8.0).exp()).min(ceiling))
            })
            .collect();
        img
    }

    #[test]
    fn a_clipped_sun_taken_out_of_the_map_is_warned_about_with_its_ceiling() {
        let dir = tempfile::tempdir().unwrap();
        let warning_for = |ceiling: f32, scale: f32| {
            let map = dir.path().join(format!("sun{ceiling}.exr"));
            clipped_sun_map(ceiling).write_exr(&map).unwrap();
            let mut d = SceneDesc::default();
            d.medium.resolution = [20, 16, 12];
            d.sun.irradiance = [0.0; 3];
            d.sky.model = SkyModel::Envmap;
            d.sky.path = Some(map.to_string_lossy().into_owned());
            d.sky.scale = scale;
            d.sky.extract_sun = Some(true);
            clip_warning(&Scene::build(d, "s.toml", dir.path()).unwrap())
        };
        assert_eq!(warning_for(f32::MAX, 1.0), None);
        let w = warning_for(65504.0, 1.0).expect("clipped");
        assert!(
            w.starts_with("s.toml: ") && w.contains("sun65504.exr") && w.contains("65504 in the file"),
            "{w}"
        );
        assert!(w.contains("is a lower bound") && w.contains("not clipped"), "{w}");
        // The ceiling as the file holds it, whatever sky.scale makes of it.
        let w = warning_for(1e3, 4.0).expect("clipped");
        assert!(w.contains("1000 in the file") && w.contains("of its pixels"), "{w}");
        // The sun clipped at 10³ gives under the clear-sky 5 to 10 times the sky's: named.
        assert!(w.contains("may hold as little as 1/"), "{w}");
    }

    #[test]
    fn the_aureole_extract_sun_leaves_around_its_sun_is_not_another_sun() {
        // A Gaussian sun (σ = 2 pixels, peak 1e6) on a sky of 0.5: after extract_sun its flanks
        // under the threshold hold about a third of the map's light left, next to the sun.
        let dir = tempfile::tempdir().unwrap();
        let img = clipped_sun_map(f32::INFINITY);
        // A second sun, far from the first, is still warned about.
        let mut two = img.clone();
        two.pixels[300 * img.width as usize + 700] = Rgb::splat(3e6);
        for (name, map, warned) in [("aureole.exr", &img, false), ("two.exr", &two, true)] {
            let path = dir.path().join(name);
            map.write_exr(&path).unwrap();
            let mut d = SceneDesc::default();
            d.sky.model = SkyModel::Envmap;
            d.sky.path = Some(path.to_string_lossy().into_owned());
            d.sky.extract_sun = Some(true);
            d.sun.irradiance = [0.0; 3];
            d.medium.resolution = [20, 16, 12];
            let scene = Scene::build(d, "s.toml", dir.path()).unwrap();
            assert_eq!(warning(&scene).is_some(), warned, "{name}: {:?}", warning(&scene));
        }
    }
}
