//! `.vdb` in a scene: placement from the file's transform, `medium.scale`, `medium.downsample`
//! on every grid source, the memory guard, an end-to-end render, and `cloudgi info`.

use crate::math::Vec3;
use crate::medium::{loaders, Grid3};
use crate::{NoProgress, Scene};
use std::path::{Path, PathBuf};

fn data(name: &str) -> PathBuf {
    super::common::data("vdb").join(name)
}

/// A scene in `dir` whose `[medium]` is `medium` (TOML lines); the .vdb is copied beside it.
fn scene(dir: &Path, vdb: &str, medium: &str, rest: &str) -> crate::Result<Scene> {
    std::fs::copy(data(vdb), dir.join("cloud.vdb")).unwrap();
    scene_over(dir, "cloud.vdb", &format!("{medium}\n{rest}"))
}

/// The scene file `[medium] grid = "{grid}"` followed by `text`, in `dir`, loaded.
fn scene_over(dir: &Path, grid: &str, text: &str) -> crate::Result<Scene> {
    let path = dir.join("scene.toml");
    std::fs::write(&path, format!("[medium]\ngrid = \"{grid}\"\n{text}")).unwrap();
    Scene::load(Some(&path), |_| {})
}

#[test]
fn placement_comes_from_the_vdb_transform() {
    let dir = tempfile::tempdir().unwrap();
    // blobs: voxel 0.25, translation (1.5, -2, 0.75), active bbox from (-300, -40, -2500).
    // 5324×124×2549 voxels needs downsample 4 under 2e8 voxels.
    let s = scene(dir.path(), "blobs_zip.vdb", "downsample = 4", "").unwrap();
    assert_eq!(s.medium.dims(), [1331, 31, 638]);
    assert_eq!(s.medium.voxel_size, Vec3::splat(1.0));
    let want = Vec3::new(1.5 + (-300.5) * 0.25, -2.0 + (-40.5) * 0.25, 0.75 + (-2500.5) * 0.25);
    assert!((s.medium.origin - want).abs().max_element() < 1e-4, "{} vs {want}", s.medium.origin);
    // Non-uniform scale, and medium.scale multiplying the whole transform.
    let s = scene(dir.path(), "aniso_scale_blosc.vdb", "scale = 2.0", "").unwrap();
    assert_eq!(s.medium.dims(), [58, 58, 58]);
    assert!((s.medium.voxel_size - Vec3::new(0.2, 0.4, 0.2)).abs().max_element() < 1e-6);
    assert!(
        (s.medium.origin - Vec3::new(0.5, 1.0, 0.5)).abs().max_element() < 1e-6,
        "{}",
        s.medium.origin
    );
    // The scene's voxel_size and origin do not apply to .vdb files.
    let s = scene(dir.path(), "sphere64_blosc.vdb", "voxel_size = 7.0\norigin = [9.0, 9.0, 9.0]", "").unwrap();
    assert!((s.medium.origin - Vec3::splat(0.125)).abs().max_element() < 1e-6);
    assert!((s.medium.voxel_size - Vec3::splat(0.05)).abs().max_element() < 1e-7);
}

#[test]
fn memory_guard_and_grid_name_errors_name_the_fix() {
    let dir = tempfile::tempdir().unwrap();
    let e = scene(dir.path(), "root_tile_blosc.vdb", "", "").unwrap_err().to_string();
    assert!(
        e.contains("medium.max_voxels") && e.contains("medium.downsample = 8") && e.contains("4128×4096×4096"),
        "{e}"
    );
    let s = scene(dir.path(), "root_tile_blosc.vdb", "downsample = 64", "").unwrap();
    assert_eq!(s.medium.dims(), [65, 64, 64]);
    let e = scene(dir.path(), "multi_grid_blosc.vdb", "grid_name = \"smoke\"", "")
        .unwrap_err()
        .to_string();
    assert!(e.contains("medium.grid_name") && e.contains("`density` (float)"), "{e}");
    let e = scene(dir.path(), "sphere64_blosc.vdb", "scale = -1.0", "").unwrap_err().to_string();
    assert!(e.contains("medium.scale"), "{e}");
    let s = scene(
        dir.path(),
        "multi_grid_blosc.vdb",
        "grid_name = \"temperature\"\nsigma_t = 0.001",
        "",
    )
    .unwrap();
    assert_eq!(s.medium.dims(), [28, 28, 28]);
}

#[test]
fn downsample_applies_to_every_grid_source() {
    let dir = tempfile::tempdir().unwrap();
    let g = Grid3::from_vec([6, 4, 5], (0..120).map(|i| (i % 7) as f32 * 0.25).collect(), "t").unwrap();
    loaders::write_npy(&dir.path().join("a.npy"), &g).unwrap();
    loaders::write_raw(&dir.path().join("a.raw"), &g).unwrap();
    loaders::write_vol(&dir.path().join("a.vol"), &g, Vec3::ZERO, Vec3::new(6.0, 4.0, 5.0)).unwrap();
    let want = g.downsample(2);
    for f in ["a.npy", "a.raw", "a.vol"] {
        let path = dir.path().join("s.toml");
        std::fs::write(&path, format!("[medium]\ngrid = \"{f}\"\nvoxel_size = 1.0\ndownsample = 2\n")).unwrap();
        let s = Scene::load(Some(&path), |_| {}).unwrap();
        assert_eq!(s.medium.density.to_grid(), want, "{f}");
        assert_eq!(s.medium.voxel_size, Vec3::splat(2.0), "{f}");
    }
    let path = dir.path().join("p.toml");
    std::fs::write(&path, "[medium]\nresolution = [20, 16, 12]\ndownsample = 4\n").unwrap();
    assert_eq!(Scene::load(Some(&path), |_| {}).unwrap().medium.dims(), [5, 4, 3]);
    let s = scene(dir.path(), "sphere64_blosc.vdb", "downsample = 3", "").unwrap();
    assert_eq!(s.medium.dims(), [20, 20, 20]);
    assert!((s.medium.voxel_size - Vec3::splat(0.15)).abs().max_element() < 1e-6);
}

/// The sphere cloud (world box 0.125..3.025 m) seen from +z, sun from above-front, sky only.
pub const VIEW: &str = "sigma_t = 4.0\n\
    [sun]\ndirection = [0.3, 0.8, 0.5]\nirradiance = [3.0, 3.0, 3.0]\n\
    [sky]\nradiance = [0.3, 0.45, 0.8]\n\
    [camera]\nposition = [1.575, 1.575, 9.0]\nlook_at = [1.575, 1.575, 1.575]\nfov_deg = 30.0\nwidth = 24\nheight = 18\n\
    [render]\nmethod = \"single\"\nspp = 1\n";

#[test]
fn a_vdb_cloud_renders_end_to_end() {
    let dir = tempfile::tempdir().unwrap();
    // No [ground] table, so no ground; pixel (0, 0) sees the sky.
    let s = scene(dir.path(), "sphere64_half_blosc.vdb", VIEW, "").unwrap();
    let out = crate::render::render(&s, &NoProgress).unwrap();
    let img = out.image;
    assert!(
        img.pixels.iter().all(|p| p.is_finite() && p.min_element() >= 0.0),
        "finite, non-negative"
    );
    let sky = img.get(0, 0);
    let centre = img.get(12, 9);
    // The cloud covers the centre: it must differ from the background there, and cover a
    // plausible share of the frame (the sphere's ~2.9 m across at 7.4 m with a 30° fov: ~70% of
    // the height, so 25–60% of the pixels).
    assert!((centre - sky).abs().max_element() > 0.05, "centre {centre} vs background {sky}");
    let covered = img.pixels.iter().filter(|p| (**p - sky).abs().max_element() > 1e-3).count();
    let frac = covered as f32 / img.pixels.len() as f32;
    assert!((0.2..0.7).contains(&frac), "cloud covers {frac} of the image");
}

/// A scene in `dir` over the `.vdb` the test writer makes of `grids`.
fn written(dir: &Path, grids: &[crate::medium::vdb::test_file::TestGrid], rest: &str) -> crate::Result<Scene> {
    std::fs::write(dir.join("w.vdb"), crate::medium::vdb::test_file::vdb_file(grids)).unwrap();
    scene_over(dir, "w.vdb", rest)
}

#[test]
fn an_empty_grid_keeps_the_camera_and_its_note_reaches_the_scene_and_the_library() {
    use crate::medium::vdb::test_file::TestGrid;
    let dir = tempfile::tempdir().unwrap();
    let mut empty = TestGrid::float("density", Vec::new());
    empty.voxel_size = [50.0; 3];
    // camera.fit (no [camera] table) has no box to frame: the scene's camera stays.
    let s = written(dir.path(), &[empty.clone()], "").unwrap();
    assert!(s.desc.camera.fit && s.medium.active_box(0).is_none());
    assert_eq!(s.desc.camera.position, crate::camera::CameraDesc::default().position);
    assert!(s.notes().len() == 1 && s.notes()[0].contains("no active voxels"), "{:?}", s.notes());
    // A cloud is framed as before, with no note.
    let s = written(
        dir.path(),
        &[TestGrid {
            voxels: vec![([0, 0, 0], 1.0)],
            ..empty
        }],
        "",
    )
    .unwrap();
    assert!(s.notes().is_empty() && s.desc.camera.position != crate::camera::CameraDesc::default().position);
    // The library's Density::load carries the grid-choice note into a scene built with it.
    std::fs::write(
        dir.path().join("s.vdb"),
        crate::medium::vdb::test_file::vdb_file(&[TestGrid::block("smoke", 2, 1.0)]),
    )
    .unwrap();
    let d = crate::Density::load(dir.path().join("s.vdb"), "density").unwrap();
    assert!(d.notes().len() == 1 && d.notes()[0].contains("`smoke`"), "{:?}", d.notes());
    let s = Scene::build_with(crate::SceneDesc::default(), "t", dir.path(), Some(d)).unwrap();
    assert!(s.notes()[0].contains("`smoke`"), "{:?}", s.notes());
}

#[test]
fn a_negative_or_nan_vdb_density_is_named_by_its_index_in_the_file() {
    use crate::medium::vdb::test_file::TestGrid;
    let dir = tempfile::tempdir().unwrap();
    let mut g = TestGrid::block("density", 4, 1.0);
    g.voxels.push(([5, -3, 2], -1e-7));
    let e = written(dir.path(), &[g.clone()], "").unwrap_err().to_string();
    for part in ["w.vdb", "grid `density`", "index [5, -3, 2]", "-0.0000001", "max(@density, 0)"] {
        assert!(e.contains(part), "{part}: {e}");
    }
    g.voxels.pop();
    g.voxels.push(([-6, 1, 1], f32::NAN));
    let e = written(dir.path(), &[g], "downsample = 2").unwrap_err().to_string();
    assert!(
        e.contains("index [-6, 0, 0]") && e.contains("2³ block") && e.contains("finite"),
        "{e}"
    );
}
