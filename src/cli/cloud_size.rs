//! A warning when the cloud's box is smaller or larger than any real cloud: the grid's unit is
//! probably not the metre (a .vdb in centimetres, a Blender object of a few metres), and the
//! warning names the key that rescales it.

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
    let factor = if across < SMALLEST_M {
        10f32.powf((100.0 / across).log10().ceil())
    } else {
        10f32.powf((10_000.0 / across).log10().floor())
    };
    let grid = &scene.desc.medium.grid;
    let ext = std::path::Path::new(grid).extension().and_then(|e| e.to_str()).unwrap_or("");
    let key = match ext.to_ascii_lowercase().as_str() {
        "vdb" => format!("medium.scale = {factor}"),
        "vol" => "a .vol file's own bounding box in metres (re-export it)".to_string(),
        _ => format!("medium.voxel_size = {}", scene.desc.medium.voxel_size.scaled(factor)),
    };
    let hint = if across < SMALLEST_M {
        "real clouds are 100 m to 10 km across; a file modelled in other units needs rescaling"
    } else {
        "a VDB in centimetres? set medium.scale = 0.01"
    };
    Some(format!(
        "{}: the cloud is {across:.3} m across ({hint}); set {key} to make it {:.0} m",
        scene.source,
        across * factor
    ))
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
        assert!(w.contains("centimetres") && w.contains("medium.voxel_size = 50"), "{w}");
    }
}
