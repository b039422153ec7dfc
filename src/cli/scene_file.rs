//! The scene file as the command line reads it: the description, where it came from, and which
//! keys the file really sets (for the "does not apply" warnings, which must not fire on defaults).

use crate::error::{Error, Result};
use crate::scene::{SceneDesc, SkyModel, BUILTIN};
use std::path::{Path, PathBuf};

/// A scene file read but not yet built.
pub struct SceneFile {
    /// The description (defaults filled in).
    pub desc: SceneDesc,
    /// The file name for messages, or [`BUILTIN`].
    pub source: String,
    /// The folder relative paths resolve against.
    pub base: PathBuf,
    /// The scene file itself (None: the built-in scene).
    pub path: Option<PathBuf>,
    /// `table.key` of every key the file sets.
    pub keys: Vec<String>,
}

impl SceneFile {
    /// Read `path` (None: the built-in default scene; a grid file: [`super::grid_scene::scene_of`] it).
    pub fn read(path: Option<&Path>) -> Result<SceneFile> {
        let Some(p) = path else {
            return Ok(SceneFile {
                desc: SceneDesc::default(),
                source: BUILTIN.to_string(),
                base: PathBuf::from("."),
                path: None,
                keys: Vec::new(),
            });
        };
        let base = p.parent().map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("."));
        if super::grid_scene::is_grid_file(p) {
            return Ok(SceneFile {
                desc: super::grid_scene::scene_of(&p.file_name().unwrap_or_default().to_string_lossy()),
                source: p.display().to_string(),
                base,
                path: None,
                keys: vec!["medium.grid".to_string()],
            });
        }
        let desc = SceneDesc::from_file(p).map_err(|e| with_extension_hint(p, e))?;
        // The file parsed as a scene, so it is readable TOML text.
        let table: toml::Table = crate::io::read_capped(p, crate::io::MAX_TEXT_BYTES, "a scene file")
            .ok()
            .and_then(|b| String::from_utf8(b).ok())
            .and_then(|t| t.parse().ok())
            .unwrap_or_default();
        let mut keys = Vec::new();
        for (name, value) in &table {
            match value.as_table() {
                Some(t) => keys.extend(t.keys().map(|k| format!("{name}.{k}"))),
                None => keys.push(name.clone()),
            }
        }
        Ok(SceneFile {
            desc,
            source: p.display().to_string(),
            base,
            path: Some(p.to_path_buf()),
            keys,
        })
    }

    /// Whether the file sets `key` (`table.key`).
    pub fn sets(&self, key: &str) -> bool {
        self.keys.iter().any(|k| k == key)
    }

    /// The files the scene reads, each with the key that names it: the scene file, the grid
    /// (and a `.raw` grid's `.json` sidecar) and the environment map.
    pub fn inputs(&self, desc: &SceneDesc) -> Vec<(PathBuf, String)> {
        let mut v = Vec::new();
        if let Some(p) = &self.path {
            v.push((p.clone(), "the scene file".to_string()));
        }
        if desc.medium.grid != "procedural" {
            let g = self.base.join(&desc.medium.grid);
            if g.extension().is_some_and(|e| e.eq_ignore_ascii_case("raw")) {
                v.push((g.with_extension("json"), "the .json sidecar of medium.grid".to_string()));
            }
            v.push((g, "medium.grid".to_string()));
        }
        if desc.sky.model == SkyModel::Envmap {
            if let Some(p) = &desc.sky.path {
                v.push((self.base.join(p), "sky.path".to_string()));
            }
        }
        v
    }
}

/// A file that does not parse as a scene and whose name ends neither in `.toml` nor in a grid
/// type was read as a scene by default: say so, and which endings make a grid file.
fn with_extension_hint(p: &Path, e: Error) -> Error {
    if p.extension().is_some_and(|x| x.eq_ignore_ascii_case("toml")) {
        return e;
    }
    let hint = "(read as a scene file, TOML, because the name does not end in a grid type: .vdb, .npy, .vol or .raw)";
    match e {
        Error::Parse { file, message } => Error::Parse {
            file,
            message: format!("{message}\n{hint}"),
        },
        Error::Format { file, message } => Error::Format {
            file,
            message: format!("{message} {hint}"),
        },
        other => other,
    }
}
