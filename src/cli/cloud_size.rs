//! A warning when the cloud's box is smaller or larger than any real cloud: the grid's unit is
//! probably not the metre (a .vdb in centimetres, a Blender object of a few metres), and the
//! warning names the key that rescales it.

use crate::medium::VoxelSize;
use crate::scene::Scene;

/// Clouds smaller than this across (m) are reported.
pub const SMALLEST_M: f32 = 10.0;
/// Clouds larger than this across (m) are reported.
pub const LARGEST_M: f32 = 100_000.0;

/// The warning for `scene`'s cloud, if its largest extent is outside [`SMALLEST_M`, `LARGEST_M`].
pub fn warning(scene: &Scene) -> Option<String> {
    let (lo, hi) = scene.medium.cloud_box();
    let across = (hi - lo).max_element();
    if (SMALLEST_M..=LARGEST_M).contains(&across) {
        return None;
    }
    // The power of ten that brings the cloud to between 100 m and 10 km.
    let exponent = if across < SMALLEST_M {
        (100.0 / across as f64).log10().ceil()
    } else {
        (10_000.0 / across as f64).log10().floor()
    } as i32;
    let times = |x: f32| decimal(x as f64 * 10f64.powi(exponent));
    let m = &scene.desc.medium;
    let ext = std::path::Path::new(&m.grid).extension().and_then(|e| e.to_str()).unwrap_or("");
    let vdb = ext.eq_ignore_ascii_case("vdb");
    let key = if vdb {
        format!("medium.scale = {}", times(m.scale))
    } else if ext.eq_ignore_ascii_case("vol") {
        "a .vol file's own bounding box in metres (re-export it)".to_string()
    } else {
        let size = match m.voxel_size {
            VoxelSize::Cube(h) => times(h).to_string(),
            VoxelSize::Box(h) => format!("[{}, {}, {}]", times(h[0]), times(h[1]), times(h[2])),
        };
        format!("medium.voxel_size = {size}")
    };
    let hint = match (across < SMALLEST_M, vdb) {
        (true, _) => "real clouds are 100 m to 10 km across; a file modelled in other units needs rescaling",
        (false, true) => "real clouds are 100 m to 10 km across; a VDB in centimetres?",
        (false, false) => "real clouds are 100 m to 10 km across",
    };
    Some(format!(
        "{}: the cloud is {across:.3} m across ({hint}); set {key} to make it {} m",
        scene.source,
        decimal(across as f64 * 10f64.powi(exponent)).round()
    ))
}

/// `x` to six significant digits, so a suggested value reads as the user would write it
/// (100, not the 100.00001 of an f32 product).
fn decimal(x: f64) -> f64 {
    format!("{x:.5e}").parse().unwrap_or(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::SceneDesc;
    use std::path::Path;

    fn warning_for(voxel_size: f32) -> Option<String> {
        let mut d = SceneDesc::default();
        d.medium.resolution = [8, 6, 4];
        d.medium.voxel_size = voxel_size.into();
        warning(&Scene::build(d, "s.toml", Path::new(".")).unwrap())
    }

    #[test]
    fn small_and_large_clouds_name_the_factor() {
        assert_eq!(warning_for(100.0), None);
        let w = warning_for(0.375).unwrap();
        assert!(w.contains("medium.voxel_size = 37.5"), "{w}");
        let w = warning_for(50_000.0).unwrap();
        assert!(!w.contains("centimetres") && w.contains("medium.voxel_size = 500 to"), "{w}");
        // Six significant digits: no f32 product digits (such as 100.00001).
        let w = warning_for(100_000.0).unwrap();
        assert!(w.contains("medium.voxel_size = 1000 to"), "{w}");
    }

    #[test]
    fn a_vdbs_suggested_scale_is_the_scale_that_fixes_it() {
        let vdb = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/vdb/sphere64_blosc.vdb");
        let for_scale = |scale: f32| {
            let mut d = SceneDesc::default();
            d.medium.grid = vdb.to_string_lossy().into_owned();
            d.medium.scale = scale;
            warning(&Scene::build(d, "s.toml", Path::new(".")).unwrap())
        };
        assert_eq!(for_scale(100.0), None);
        let w = for_scale(1e6).unwrap();
        assert!(w.contains("centimetres") && w.contains("medium.scale = 1000 to"), "{w}");
        let w = for_scale(0.01).unwrap();
        assert!(w.contains("medium.scale = 100 to"), "{w}");
    }
}
