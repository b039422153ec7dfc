//! A warning when an environment map holds a sun of its own (a compact source carrying much of
//! its light): `transport` takes the sky's light as its mean over each ordinate's cell, about 20°
//! wide, so a source a few map pixels wide keeps its power but loses its direction; `full` and
//! `diffusion` take it along their bins' samples, directions degrees apart, so it is missed or
//! smeared; `reference` samples the map exactly. The warning points to `sky.extract_sun`, which
//! takes it out of the map as the scene's sun, carried exactly.

use crate::lighting::map_sun::MAX_SUN_SOLID_ANGLE;
use crate::lighting::SkyModel;
use crate::scene::{Method, Scene};

/// Share of the map's light above which a compact source is warned about.
const SHARE: f64 = 0.2;

/// How each method takes a map's sun, and what it measured (docs/sky.md, "A sun in the map").
fn measured(method: Method) -> Option<(&'static str, &'static str)> {
    match method {
        Method::Transport => Some((
            "averages over cells about 20° wide, keeping its light but blurring its direction",
            "transport 11 % block error and −7 % on the cloud",
        )),
        Method::Full => Some((
            "takes at directions degrees apart, missing or smearing it",
            "full 14 % block error and −15 % on the cloud",
        )),
        Method::Diffusion => Some((
            "takes at directions degrees apart, missing or smearing it",
            "diffusion 19 % block error on the cloud",
        )),
        Method::Single | Method::Reference => None,
    }
}

/// The warning for `scene`, if its sky is an environment map whose compact source carries more
/// than [`SHARE`] of its light and its method takes the map at fixed directions.
pub fn warning(scene: &Scene) -> Option<String> {
    let (takes, measured) = measured(scene.render.method)?;
    if scene.desc.sky.model != SkyModel::Envmap {
        return None;
    }
    let c = scene.sky.map()?.compact_source()?;
    if c.share < SHARE || c.solid_angle > MAX_SUN_SOLID_ANGLE {
        return None;
    }
    let fix = match scene.desc.sky.extract_sun {
        false => "set [sky] extract_sun = true, which makes it the scene's sun (docs/sky.md)",
        true => "it is another than the sun sky.extract_sun took out; paint it out of the map",
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Image;
    use crate::math::Rgb;
    use crate::scene::SceneDesc;

    #[test]
    fn a_map_with_a_sun_warns_the_methods_that_sample_it_at_fixed_directions() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (128, 64);
        let mut img = Image::new(w, h);
        img.pixels = vec![Rgb::splat(0.5); (w * h) as usize];
        let uniform = dir.path().join("uniform.exr");
        img.write_exr(&uniform).unwrap();
        img.pixels[20 * w as usize + 30] = Rgb::splat(1e6);
        let sunny = dir.path().join("sun.exr");
        img.write_exr(&sunny).unwrap();
        let warning_for = |map: &std::path::Path, method: Method| {
            let mut d = SceneDesc::default();
            d.medium.resolution = [20, 16, 12];
            d.sky.model = SkyModel::Envmap;
            d.sky.path = Some(map.to_string_lossy().into_owned());
            d.render.method = method;
            warning(&Scene::build(d, "s.toml", dir.path()).unwrap())
        };
        for m in [Method::Transport, Method::Full, Method::Diffusion] {
            let w = warning_for(&sunny, m).expect("a sun in the map");
            assert!(
                w.contains("s.toml") && w.contains("extract_sun = true") && w.contains("--method reference"),
                "{w}"
            );
            assert_eq!(warning_for(&uniform, m), None);
        }
        assert_eq!(warning_for(&sunny, Method::Reference), None);
    }
}
