//! Export a scene to Mitsuba 3 (`cloudgi export mitsuba`), so a user can cross-check the reference
//! tracer with an independent renderer: `scene.xml` plus the density grid as `density.vol`.
//!
//! Mapping (Mitsuba 3 plugin names):
//! * medium → a `cube` shape with a `null` BSDF bounding the grid, interior `heterogeneous` medium
//!   with `sigma_t` a `gridvolume` (trilinear, clamp — the same field as ours) scaled by
//!   `medium.sigma_t`, `albedo` as RGB and an `hg` phase function;
//! * sun → `directional` emitter (Mitsuba's `direction` is the direction the light travels, i.e.
//!   minus ours) with the same irradiance;
//! * constant sky → `constant` emitter with the same radiance; any other sky (atmosphere,
//!   envmap) → `envmap` emitter reading `sky.exr`, the map `cloudgi sky` writes, rotated from our
//!   u convention to Mitsuba's ([`ENVMAP_TO_WORLD`]);
//! * ground → a `rectangle` of half-size [`GROUND_HALF_SIZE`] facing up with a `diffuse` BSDF. When
//!   the ground lies within [`ground_offset`] of the grid's floor it is lowered to that distance
//!   below it: Mitsuba pushes new rays off a surface by about 5e-6 × the coordinates' magnitude
//!   (2.7 mm at 500 m), and a shadow ray leaving a ground that touches the box would start inside
//!   the box, which Mitsuba then treats as blocked (the box's footprint came out black);
//! * camera → `perspective` sensor, vertical field of view (`fov_axis = "y"`), `hdrfilm` of the
//!   same size, `box` filter, `independent` sampler with `render.spp` samples;
//! * integrator → `volpath` with no depth cap (`max_depth = -1`), as our reference.
//!
//! Colours are linear RGB; render Mitsuba in an RGB variant (e.g. `scalar_rgb` or `llvm_ad_rgb`).

use crate::error::{Error, Result};
use crate::lighting::SkyKind;
use crate::math::Vec3;
use crate::medium::loaders::write_vol;
use crate::scene::Scene;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The sky map written beside `scene.xml` for a sky that is not constant.
pub const SKY_FILE: &str = "sky.exr";

/// Mitsuba's `envmap` reads u = atan2(x, −z)/2π in its local frame, ours u = atan2(z, x)/2π
/// (both v = acos(y)/π, row 0 = +y): local = (z, y, −x) of world, so `to_world` (4×4, row
/// major) maps local (x, y, z) to world (−z, y, x).
const ENVMAP_TO_WORLD: &str = "0 0 -1 0  0 1 0 0  1 0 0 0  0 0 0 1";

/// Half-size (m) of the ground rectangle.
pub const GROUND_HALF_SIZE: f32 = 1.0e6;
/// How far (m) the ground must stay below the grid's floor in the export: 1e-4 × the largest
/// coordinate of the grid's box (+1 m), about 20 times Mitsuba's ray offset there.
pub fn ground_offset(lo: Vec3, hi: Vec3) -> f32 {
    1.0e-4 * (lo.abs().max(hi.abs()).max_element() + 1.0)
}

fn v3(v: Vec3) -> String {
    format!("{}, {}, {}", v.x, v.y, v.z)
}

/// The Mitsuba 3 XML for `scene`, referring to the grid as `vol_name`.
pub fn scene_xml(scene: &Scene, vol_name: &str) -> Result<String> {
    let m = &scene.medium;
    let cam = &scene.camera;
    let cd = &scene.desc.camera;
    let (lo, hi) = m.bbox();
    let mut x = String::new();
    let w = &mut x;
    let _ = writeln!(w, "<?xml version=\"1.0\" encoding=\"utf-8\"?>");
    let _ = writeln!(w, "<!-- Exported by cloudgi from {} -->", xml_escape(&scene.source));
    let _ = writeln!(w, "<scene version=\"3.0.0\">");
    let _ = writeln!(w, "    <integrator type=\"volpath\">");
    let _ = writeln!(w, "        <integer name=\"max_depth\" value=\"-1\"/>");
    let _ = writeln!(w, "    </integrator>");
    let _ = writeln!(w, "    <sensor type=\"perspective\">");
    let _ = writeln!(w, "        <string name=\"fov_axis\" value=\"y\"/>");
    let _ = writeln!(w, "        <float name=\"fov\" value=\"{}\"/>", cd.fov_deg);
    let _ = writeln!(w, "        <transform name=\"to_world\">");
    let _ = writeln!(
        w,
        "            <lookat origin=\"{}\" target=\"{}\" up=\"{}\"/>",
        v3(cam.position),
        v3(cam.position + cam.forward),
        v3(cam.up)
    );
    let _ = writeln!(w, "        </transform>");
    let _ = writeln!(w, "        <sampler type=\"independent\">");
    let _ = writeln!(w, "            <integer name=\"sample_count\" value=\"{}\"/>", scene.render.spp);
    let _ = writeln!(w, "            <integer name=\"seed\" value=\"{}\"/>", scene.render.seed as u32);
    let _ = writeln!(w, "        </sampler>");
    let _ = writeln!(w, "        <film type=\"hdrfilm\">");
    let _ = writeln!(w, "            <integer name=\"width\" value=\"{}\"/>", cam.width);
    let _ = writeln!(w, "            <integer name=\"height\" value=\"{}\"/>", cam.height);
    let _ = writeln!(w, "            <rfilter type=\"box\"/>");
    let _ = writeln!(w, "            <string name=\"pixel_format\" value=\"rgb\"/>");
    let _ = writeln!(w, "        </film>");
    let _ = writeln!(w, "    </sensor>");
    if scene.sun.irradiance.max_element() > 0.0 {
        let _ = writeln!(w, "    <emitter type=\"directional\">");
        let _ = writeln!(w, "        <vector name=\"direction\" value=\"{}\"/>", v3(-scene.sun.dir));
        let _ = writeln!(w, "        <rgb name=\"irradiance\" value=\"{}\"/>", v3(scene.sun.irradiance));
        let _ = writeln!(w, "    </emitter>");
    }
    match &scene.sky.kind {
        SkyKind::Constant(l) => {
            if l.max_element() > 0.0 {
                let _ = writeln!(w, "    <emitter type=\"constant\">");
                let _ = writeln!(w, "        <rgb name=\"radiance\" value=\"{}\"/>", v3(*l));
                let _ = writeln!(w, "    </emitter>");
            }
        }
        // The map holds the radiance already multiplied by `sky.scale`, so Mitsuba's scale is 1.
        _ => {
            let _ = writeln!(w, "    <emitter type=\"envmap\">");
            let _ = writeln!(w, "        <string name=\"filename\" value=\"{}\"/>", xml_escape(SKY_FILE));
            let _ = writeln!(w, "        <float name=\"scale\" value=\"1\"/>");
            let _ = writeln!(w, "        <transform name=\"to_world\">");
            let _ = writeln!(w, "            <matrix value=\"{ENVMAP_TO_WORLD}\"/>");
            let _ = writeln!(w, "        </transform>");
            let _ = writeln!(w, "    </emitter>");
        }
    }
    let centre = (lo + hi) * 0.5;
    let half = (hi - lo) * 0.5;
    let _ = writeln!(w, "    <shape type=\"cube\">");
    let _ = writeln!(w, "        <transform name=\"to_world\">");
    let _ = writeln!(w, "            <scale value=\"{}\"/>", v3(half));
    let _ = writeln!(w, "            <translate value=\"{}\"/>", v3(centre));
    let _ = writeln!(w, "        </transform>");
    let _ = writeln!(w, "        <bsdf type=\"null\"/>");
    let _ = writeln!(w, "        <medium type=\"heterogeneous\" name=\"interior\">");
    let _ = writeln!(w, "            <volume type=\"gridvolume\" name=\"sigma_t\">");
    let _ = writeln!(w, "                <string name=\"filename\" value=\"{}\"/>", xml_escape(vol_name));
    let _ = writeln!(w, "                <string name=\"filter_type\" value=\"trilinear\"/>");
    let _ = writeln!(w, "                <string name=\"wrap_mode\" value=\"clamp\"/>");
    let _ = writeln!(w, "                <transform name=\"to_world\">");
    let _ = writeln!(w, "                    <scale value=\"{}\"/>", v3(hi - lo));
    let _ = writeln!(w, "                    <translate value=\"{}\"/>", v3(lo));
    let _ = writeln!(w, "                </transform>");
    let _ = writeln!(w, "            </volume>");
    let _ = writeln!(w, "            <float name=\"scale\" value=\"{}\"/>", m.optics.sigma_t);
    let _ = writeln!(w, "            <rgb name=\"albedo\" value=\"{}\"/>", v3(m.optics.albedo));
    let _ = writeln!(w, "            <phase type=\"hg\">");
    let _ = writeln!(
        w,
        "                <float name=\"g\" value=\"{}\"/>",
        m.optics.phase.mean_cosine() as f32
    );
    let _ = writeln!(w, "            </phase>");
    let _ = writeln!(w, "        </medium>");
    let _ = writeln!(w, "    </shape>");
    if let Some(g) = &scene.ground {
        let off = ground_offset(lo, hi);
        let h = if (g.height - lo.y).abs() < off { lo.y - off } else { g.height };
        // Mitsuba's rectangle spans [−1, 1]² in the xy plane facing +z; rotate it to face +y.
        let _ = writeln!(w, "    <shape type=\"rectangle\">");
        let _ = writeln!(w, "        <transform name=\"to_world\">");
        let _ = writeln!(w, "            <scale value=\"{GROUND_HALF_SIZE}\"/>");
        let _ = writeln!(w, "            <rotate x=\"1\" angle=\"-90\"/>");
        let _ = writeln!(w, "            <translate value=\"0, {h}, 0\"/>");
        let _ = writeln!(w, "        </transform>");
        let _ = writeln!(w, "        <bsdf type=\"diffuse\">");
        let _ = writeln!(w, "            <rgb name=\"reflectance\" value=\"{}\"/>", v3(g.albedo));
        let _ = writeln!(w, "        </bsdf>");
        let _ = writeln!(w, "    </shape>");
    }
    let _ = writeln!(w, "</scene>");
    Ok(x)
}

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Write `scene.xml`, `density.vol` and, for a sky that is not constant, [`SKY_FILE`] (the
/// sky's own map, as `cloudgi sky` writes it) into `dir` (created if missing); returns the paths
/// written. A scene Mitsuba cannot take is refused before anything is created.
pub fn export(scene: &Scene, dir: &Path) -> Result<Vec<PathBuf>> {
    let text = scene_xml(scene, "density.vol")?;
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let vol = dir.join("density.vol");
    let xml = dir.join("scene.xml");
    let (lo, hi) = scene.medium.bbox();
    write_vol(&vol, &scene.medium.density.to_grid(), lo, hi)?;
    let mut files = vec![xml.clone(), vol];
    if !matches!(scene.sky.kind, SkyKind::Constant(_)) {
        let sky = dir.join(SKY_FILE);
        scene.sky.to_image(None).write_exr(&sky)?;
        files.push(sky);
    }
    crate::io::write_atomic(&xml, text.as_bytes())?;
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::medium::loaders::parse_vol;
    use crate::scene::SceneDesc;

    #[test]
    fn exports_every_part_and_the_same_grid() {
        let mut d = SceneDesc::default();
        d.medium.resolution = [12, 10, 8];
        d.medium.voxel_size = 50.0.into();
        let scene = Scene::build(d, "t.toml", Path::new(".")).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let files = export(&scene, dir.path()).unwrap();
        let xml = std::fs::read_to_string(&files[0]).unwrap();
        for needle in [
            "<integrator type=\"volpath\">",
            "<emitter type=\"directional\">",
            "<emitter type=\"constant\">",
            "<medium type=\"heterogeneous\" name=\"interior\">",
            "<phase type=\"hg\">",
            "<float name=\"g\" value=\"0.9\"/>",
            "<float name=\"scale\" value=\"0.05\"/>",
            "<bsdf type=\"diffuse\">",
            "<integer name=\"width\" value=\"480\"/>",
            "<string name=\"fov_axis\" value=\"y\"/>",
        ] {
            assert!(xml.contains(needle), "missing {needle} in\n{xml}");
        }
        // Mitsuba's direction is where the light goes: minus ours.
        let s = -scene.sun.dir;
        assert!(xml.contains(&format!("value=\"{}, {}, {}\"", s.x, s.y, s.z)));
        // The ground sits on the grid's floor in the default scene: lowered by 1e-4 × 500 m (+1).
        let (lo, hi) = scene.medium.bbox();
        assert!((ground_offset(lo, hi) - 0.0501).abs() < 1e-6);
        assert!(xml.contains("<translate value=\"0, -0.0501, 0\"/>"), "{xml}");
        let bytes = std::fs::read(&files[1]).unwrap();
        let (g, lo, hi) = parse_vol(&bytes, "density.vol").unwrap();
        assert_eq!(g, scene.medium.density.to_grid());
        assert_eq!((lo, hi), scene.medium.bbox());
        // Balanced tags.
        assert_eq!(xml.matches("<shape").count(), xml.matches("</shape>").count());
    }

    #[test]
    fn an_atmosphere_sky_is_an_envmap_emitter_with_the_sky_commands_map() {
        let mut d = SceneDesc::default();
        d.medium.resolution = [6, 5, 4];
        d.sky.model = crate::scene::SkyModel::Atmosphere;
        d.sky.map_width = 16;
        let scene = Scene::build(d, "t.toml", Path::new(".")).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let files = export(&scene, dir.path()).unwrap();
        let xml = std::fs::read_to_string(&files[0]).unwrap();
        for needle in [
            "<emitter type=\"envmap\">",
            "<string name=\"filename\" value=\"sky.exr\"/>",
            &format!("<matrix value=\"{ENVMAP_TO_WORLD}\"/>"),
        ] {
            assert!(xml.contains(needle), "missing {needle} in\n{xml}");
        }
        assert!(!xml.contains("type=\"constant\""));
        let map = crate::image::Image::read_exr(&dir.path().join(SKY_FILE)).unwrap();
        assert_eq!(map.pixels, scene.sky.to_image(None).pixels);
    }

    /// Mitsuba's envmap lookup of a world direction through `to_world` (its inverse, the
    /// transpose, takes world to local) reads the same u, v as ours.
    #[test]
    fn the_envmap_rotation_turns_our_u_into_mitsubas() {
        let m: Vec<f32> = ENVMAP_TO_WORLD.split_whitespace().map(|x| x.parse().unwrap()).collect();
        let to_world = |r: usize, c: usize| m[4 * r + c];
        for d in [
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(-1.0, 0.2, 0.0),
            Vec3::new(0.3, 0.5, -0.8),
            Vec3::new(-0.6, -0.3, 0.7),
        ] {
            let d = d.normalize();
            let local: Vec<f32> = (0..3).map(|c| (0..3).map(|r| to_world(r, c) * d[r]).sum()).collect();
            let mut u_mitsuba = local[0].atan2(-local[2]) / (2.0 * std::f32::consts::PI);
            u_mitsuba -= u_mitsuba.floor();
            let v_mitsuba = local[1].clamp(-1.0, 1.0).acos() / std::f32::consts::PI;
            let (u, v) = crate::lighting::envmap::uv(d);
            let du = (u - u_mitsuba).abs();
            assert!(du.min(1.0 - du) < 1e-6 && (v - v_mitsuba).abs() < 1e-6, "{d:?}: {u} {u_mitsuba}");
        }
    }
}
