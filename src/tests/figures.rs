//! The figure series' masks and its sunset scene (the series itself, through the binary, is
//! `tests/it/figures.rs`).

use crate::math::Rgb;
use crate::scene::SkyModel;
use crate::tools::figures::{edge_mask, sunset_desc, SUNSET_ELEVATION_DEG};
use crate::{Scene, SceneDesc};
use std::path::Path;

#[test]
fn masks_and_sunset() {
    let t: Vec<Rgb> = [0.0, 0.04, 0.05, 0.5, 0.9, 0.95, 1.0].iter().map(|&v| Rgb::splat(v)).collect();
    assert_eq!(edge_mask(&t), vec![false, false, true, true, true, false, false]);
    // The default sun (0.3, 0.8, 0.5) keeps its azimuth atan2(0.5, 0.3) and drops to 4°.
    let d = sunset_desc(&SceneDesc::default());
    assert_eq!(d.sun.elevation_deg, Some(SUNSET_ELEVATION_DEG));
    assert!((d.sun.azimuth_deg.unwrap() - 0.5f32.atan2(0.3).to_degrees()).abs() < 1e-4);
    assert!(d.sun.direction.is_none() && d.sun.from_atmosphere);
    assert_eq!(d.sky.model, SkyModel::Atmosphere);
    Scene::build(d, "sunset", Path::new(".")).unwrap();
}
