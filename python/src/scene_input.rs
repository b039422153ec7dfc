//! A scene as Python gives it — a file path, TOML text or a dict (as JSON) — with the
//! overrides of `render()`'s keyword arguments (a JSON object of tables), turned into a
//! [`SceneDesc`] through the scene file's own parser, so every message is the command line's.

use cloudgi::SceneDesc;
use cloudgi::BUILTIN_SOURCE as BUILTIN;
use cloudgi::{Error, Result};
use std::path::{Path, PathBuf};

/// Name of a scene given as a dict, in messages.
const DICT_SOURCE: &str = "scene dict";

/// Where the scene comes from.
enum Source {
    Builtin,
    Path(PathBuf),
    Toml(String),
    Dict(String),
}

/// A scene as given, not yet parsed.
pub struct SceneInput {
    source: Source,
    overrides: toml::Table,
    /// The overrides given as `render()`'s own keywords (`spp=`), as dotted keys
    /// (`render.spp`); the others came in its `overrides` dict.
    keywords: Vec<String>,
}

impl SceneInput {
    /// `kind` is `builtin`, `path`, `toml` or `dict` (then `payload` is JSON); `overrides` a JSON object
    /// `{table: {key: value}}`, of which `keywords` (dotted keys) came as `render()`'s own keywords.
    pub fn new(kind: &str, payload: &str, overrides: &str, keywords: Vec<String>) -> Result<SceneInput> {
        let source = match kind {
            "builtin" => Source::Builtin,
            "path" => Source::Path(PathBuf::from(payload)),
            "toml" => Source::Toml(payload.to_string()),
            "dict" => Source::Dict(payload.to_string()),
            other => return Err(Error::invalid("cloudgi.render", "scene", format!("unknown scene kind `{other}`"))),
        };
        let mut overrides: toml::Table =
            serde_json::from_str(overrides).map_err(|e| Error::invalid("cloudgi.render", "keyword arguments", e.to_string()))?;
        unmark_non_finite(&mut overrides);
        Ok(SceneInput {
            source,
            overrides,
            keywords,
        })
    }

    /// The description, the name of its source for messages, and the folder its relative paths
    /// resolve against.
    pub fn desc(&self) -> Result<(SceneDesc, String, PathBuf)> {
        let (text, name, base) = match &self.source {
            Source::Builtin => {
                let desc = SceneDesc::default();
                if self.overrides.is_empty() {
                    return Ok((desc, BUILTIN.to_string(), PathBuf::from(".")));
                }
                (desc.to_toml(), BUILTIN.to_string(), PathBuf::from("."))
            }
            Source::Path(p) => {
                refuse_pipe(p)?;
                refuse_grid_file(p)?;
                // The file alone first: its errors read exactly as the command line's.
                let desc = SceneDesc::from_file(p)?;
                let name = p.display().to_string();
                let base = p
                    .parent()
                    .filter(|b| !b.as_os_str().is_empty())
                    .unwrap_or(Path::new("."))
                    .to_path_buf();
                if self.overrides.is_empty() {
                    return Ok((desc, name, base));
                }
                (std::fs::read_to_string(p).map_err(|e| Error::io(p, e))?, name, base)
            }
            Source::Toml(t) => (t.clone(), cloudgi::TOML_SOURCE.to_string(), PathBuf::from(".")),
            Source::Dict(json) => {
                let mut value: toml::Table = serde_json::from_str(json).map_err(|e| Error::Parse {
                    file: DICT_SOURCE.to_string(),
                    message: format!("{e} (values must be strings, numbers, booleans, lists or dicts; no None)"),
                })?;
                unmark_non_finite(&mut value);
                let text = toml::to_string(&value).map_err(|e| Error::Parse {
                    file: DICT_SOURCE.to_string(),
                    message: e.to_string(),
                })?;
                (text, DICT_SOURCE.to_string(), PathBuf::from("."))
            }
        };
        let desc = SceneDesc::from_toml(&text, &name)?;
        if self.overrides.is_empty() {
            return Ok((desc, name, base));
        }
        let mut table: toml::Table = text.parse().map_err(|e: toml::de::Error| Error::Parse {
            file: name.clone(),
            message: e.to_string(),
        })?;
        merge(&mut table, &self.overrides);
        // The scene alone parsed: an error now is the keyword arguments', and its line is in the
        // merged text, not the scene's.
        let merged_name = format!("keyword arguments on {name}");
        let merged = toml::to_string(&table).map_err(|e| Error::Parse {
            file: merged_name.clone(),
            message: e.to_string(),
        })?;
        let mut merged_desc = SceneDesc::from_toml(&merged, &merged_name).map_err(|e| self.blame(&text, &merged_name).unwrap_or(e))?;
        // A scene without a `[camera]` table frames its cloud (camera.fit); a keyword argument
        // that creates the table (`width=`) keeps that, as `--width` does on the command line.
        let sets_fit = self
            .overrides
            .get("camera")
            .and_then(toml::Value::as_table)
            .is_some_and(|c| c.contains_key("fit"));
        if !sets_fit {
            merged_desc.camera.fit = desc.camera.fit;
        }
        Ok((merged_desc, name, base))
    }
}

impl SceneInput {
    /// The error of the first override (in key order) that the scene `text` does not take,
    /// naming it and its value: the message of the merged scene would show a line of TOML the
    /// caller never wrote. `None` if each parses (then the merged scene's own error stands).
    fn blame(&self, text: &str, merged_name: &str) -> Option<Error> {
        let mut table: toml::Table = text.parse().ok()?;
        for (path, value) in leaves(&self.overrides) {
            merge(&mut table, &one_leaf(&path, value));
            let merged = toml::to_string(&table).ok()?;
            let message = match toml::from_str::<SceneDesc>(&merged) {
                Err(e) => e.message().trim_end().to_string(),
                Ok(_) => match SceneDesc::from_toml(&merged, merged_name) {
                    Err(Error::Invalid { message, .. }) => message,
                    _ => continue,
                },
            };
            let key = path.join(".");
            let written = match self.keyword(&key) {
                Some(name) => format!("{name}={value} (the scene's {key})"),
                None => format!("{key} = {value}"),
            };
            return Some(Error::Parse {
                file: merged_name.to_string(),
                message: format!("{written}: {message}"),
            });
        }
        None
    }

    /// Who set `table.key` (a keyword argument, the `overrides` dict, or the scene named `name`),
    /// to start a warning that it does not apply ([`cloudgi::ignored_settings`]); None where
    /// nobody did (a default, or the built-in scene's own keys).
    pub fn given_by(&self, name: &str) -> impl Fn(&str) -> Option<String> {
        let first_two = |table: &toml::Table| -> Vec<String> {
            leaves(table)
                .into_iter()
                .map(|(p, _)| p.iter().take(2).cloned().collect::<Vec<_>>().join("."))
                .collect()
        };
        let overridden = first_two(&self.overrides);
        let in_scene = first_two(&self.scene_table());
        let keywords = self.keywords.clone();
        let name = name.to_string();
        move |key: &str| {
            if keywords.iter().any(|k| k == key) {
                Some(format!("keyword argument `{}=`", key.rsplit('.').next().unwrap_or(key)))
            } else if overridden.iter().any(|k| k == key) {
                Some(format!("overrides: `{key}`"))
            } else if in_scene.iter().any(|k| k == key) {
                Some(format!("{name}: `{key}`"))
            } else {
                None
            }
        }
    }

    /// The scene's own keys as a table (empty for the built-in scene); called after the scene
    /// parsed, so a failure here reads as no keys.
    fn scene_table(&self) -> toml::Table {
        let text = match &self.source {
            Source::Builtin => return toml::Table::new(),
            Source::Path(p) => std::fs::read_to_string(p).unwrap_or_default(),
            Source::Toml(t) => t.clone(),
            Source::Dict(json) => return serde_json::from_str(json).unwrap_or_default(),
        };
        text.parse().unwrap_or_default()
    }

    /// `render()`'s keyword that set the dotted `key`, if one did (`spp` for `render.spp`).
    fn keyword<'k>(&self, key: &'k str) -> Option<&'k str> {
        let name = key.rsplit('.').next()?;
        self.keywords.iter().any(|k| k == key).then_some(name)
    }

    /// `e`, from building the merged scene, blamed on the keyword arguments when its field is
    /// one of them: the scene itself was valid before they were applied.
    pub fn blame_field(&self, e: Error, name: &str) -> Error {
        match e {
            Error::Invalid { file, field, message }
                if file == name && leaves(&self.overrides).iter().any(|(p, _)| p.join(".") == field) =>
            {
                let file = match self.keyword(&field) {
                    Some(k) => format!("keyword argument {k}= on {file}"),
                    None => format!("keyword arguments on {file}"),
                };
                Error::Invalid { file, field, message }
            }
            e => e,
        }
    }
}

/// Refuse a scene path that is a named pipe: its read waits for a writer, on the render's own
/// thread, which Ctrl-C cannot end (the command line's signal handler ends the process instead).
fn refuse_pipe(path: &Path) -> Result<()> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if std::fs::metadata(path).is_ok_and(|m| m.file_type().is_fifo()) {
            return Err(Error::format(
                path.display().to_string(),
                "a named pipe, which cloudgi.render would wait on for a writer, uninterruptibly; give the scene's text \
                 (render(open(path).read())) or a scene file",
            ));
        }
    }
    let _ = path;
    Ok(())
}

/// Refuse a grid file given as the scene (`cloudgi render cloud.vdb` renders one, framed): read
/// as TOML its message was "not UTF-8 text", which does not say what to pass instead.
fn refuse_grid_file(path: &Path) -> Result<()> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if !["vdb", "npy", "vol", "raw"].contains(&ext.as_str()) {
        return Ok(());
    }
    Err(Error::format(
        path.display().to_string(),
        format!(
            "a .{ext} grid file, not a scene file; give it as the scene's grid, scene={{\"medium\": {{\"grid\": path}}}} \
             (relative paths from the working folder; without a \"camera\" table the camera frames it), or its array as \
             density= (cloudgi.load_grid(path) returns it with its voxel_size and origin)"
        ),
    ))
}

/// Every non-table value of `table` with its path of keys, in key order.
fn leaves(table: &toml::Table) -> Vec<(Vec<String>, &toml::Value)> {
    let mut out = Vec::new();
    for (k, v) in table {
        match v {
            toml::Value::Table(t) if !t.is_empty() => out.extend(leaves(t).into_iter().map(|(mut p, v)| {
                p.insert(0, k.clone());
                (p, v)
            })),
            v => out.push((vec![k.clone()], v)),
        }
    }
    out
}

/// The table that sets the key at `path` to `value` alone.
fn one_leaf(path: &[String], value: &toml::Value) -> toml::Table {
    let mut value = value.clone();
    for part in path.iter().rev() {
        value = toml::Value::Table(toml::Table::from_iter([(part.clone(), value)]));
    }
    match value {
        toml::Value::Table(t) => t,
        _ => toml::Table::new(),
    }
}

/// Prefix of a non-finite float that Python sent as a string (JSON has no NaN or infinity);
/// `python/cloudgi/__init__.py` writes it.
const NON_FINITE: &str = "\0float:";

/// Turn Python's marked non-finite floats back into floats (`nan`, `inf`, `-inf`), so the scene
/// parser refuses them naming the key, as it does in a scene file.
fn unmark_non_finite(table: &mut toml::Table) {
    fn unmark(v: &mut toml::Value) {
        match v {
            toml::Value::String(s) => {
                if let Some(x) = s.strip_prefix(NON_FINITE).and_then(|r| r.parse::<f64>().ok()) {
                    *v = toml::Value::Float(x);
                }
            }
            toml::Value::Array(a) => a.iter_mut().for_each(unmark),
            toml::Value::Table(t) => t.iter_mut().for_each(|(_, v)| unmark(v)),
            _ => {}
        }
    }
    table.iter_mut().for_each(|(_, v)| unmark(v));
}

/// Set every `table.key` of `over` in `base`, keeping the table's other keys.
fn merge(base: &mut toml::Table, over: &toml::Table) {
    for (k, v) in over {
        match (base.get_mut(k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge(b, o),
            _ => {
                base.insert(k.clone(), v.clone());
            }
        }
    }
}
