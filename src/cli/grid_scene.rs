//! A grid file given where a scene file goes (`cloudgi render cloud.vdb`): the default scene's sun
//! and sky, no ground, and the camera framing the cloud (`camera.fit`).

use crate::scene::SceneDesc;
use std::path::Path;

/// The grid file types a scene's `medium.grid` reads.
const GRID_EXTENSIONS: [&str; 4] = ["vdb", "npy", "vol", "raw"];

/// Whether `path` names a grid file rather than a scene file (by its extension).
pub fn is_grid_file(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| GRID_EXTENSIONS.iter().any(|g| e.eq_ignore_ascii_case(g)))
}

/// The scene that renders the grid file `name` (relative to the folder it lies in): what a scene
/// file with only `[medium] grid = "name"` describes.
pub fn scene_of(name: &str) -> SceneDesc {
    let mut d = SceneDesc::default();
    d.medium.grid = name.to_string();
    d.ground = None;
    d.camera.fit = true;
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_grid_file_is_the_scene_with_only_its_medium_grid() {
        assert!(is_grid_file(Path::new("a/cloud.VDB")) && is_grid_file(Path::new("x.npy")));
        assert!(!is_grid_file(Path::new("scene.toml")) && !is_grid_file(Path::new("vdb")));
        let text = "[medium]\ngrid = \"cloud.vdb\"\n";
        assert_eq!(scene_of("cloud.vdb"), SceneDesc::from_toml(text, "s.toml").unwrap());
    }
}
