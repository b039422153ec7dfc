//! Checks on where a command will write, made before any work: the folder exists and is
//! writable, no output is a folder or an existing read-only file, and no output is one of the
//! scene's own input files (the atomic rename would replace either).

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// The folder a file path lives in (`.` for a bare name).
fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// `path` with its folder resolved (symbolic links, `..`), the file itself need not exist.
fn resolved(path: &Path) -> Option<PathBuf> {
    if let Ok(p) = path.canonicalize() {
        return Some(p);
    }
    Some(folder_of(path).canonicalize().ok()?.join(path.file_name()?))
}

/// `dir` must be an existing folder this process can create files in (tried with a probe file,
/// which is removed again).
pub fn check_writable_folder(dir: &Path, flag: &str) -> Result<()> {
    if !dir.is_dir() {
        return Err(Error::invalid(
            "command line",
            flag,
            format!("the folder `{}` does not exist; create it first", dir.display()),
        ));
    }
    let probe = dir.join(format!(".cloudgi-write-test-{}", std::process::id()));
    match std::fs::OpenOptions::new().write(true).create_new(true).open(&probe) {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) => Err(Error::invalid(
            "command line",
            flag,
            format!("cannot write in the folder `{}`: {e}", dir.display()),
        )),
    }
}

/// Longest file name (bytes) Linux, macOS and Windows file systems accept.
const NAME_MAX: usize = 255;

/// `path` names a file a command can create: it does not end in a `/` (a folder) and its name
/// fits the file system's limit of [`NAME_MAX`] bytes.
pub fn check_file_name(path: &Path, flag: &str) -> Result<()> {
    let text = path.as_os_str().as_encoded_bytes();
    if text.ends_with(b"/") || text.ends_with(std::path::MAIN_SEPARATOR_STR.as_bytes()) {
        return Err(Error::invalid(
            "command line",
            flag,
            format!(
                "`{}` ends in a path separator, so it names a folder; give a file name, e.g. cloud.exr",
                path.display()
            ),
        ));
    }
    let len = path.file_name().map_or(0, |n| n.as_encoded_bytes().len());
    if len > NAME_MAX {
        return Err(Error::invalid(
            "command line",
            flag,
            format!("the file name is {len} bytes long; file systems allow at most {NAME_MAX}: choose a shorter name"),
        ));
    }
    Ok(())
}

/// `path` must not be one of `inputs` (path, the key or role that names it).
fn check_not_input(path: &Path, flag: &str, inputs: &[(PathBuf, String)]) -> Result<()> {
    let Some(out) = resolved(path) else {
        return Ok(());
    };
    for (input, key) in inputs {
        if input.canonicalize().is_ok_and(|i| i == out) {
            return Err(Error::invalid(
                "command line",
                flag,
                format!(
                    "`{}` is {key}, an input of this command; writing it would overwrite it, choose another output name",
                    path.display()
                ),
            ));
        }
    }
    Ok(())
}

/// Every file in `files` can be written: its folder exists and is writable, it is not a folder
/// nor an existing read-only file, and it is none of the scene's `inputs`. `flag` names the option the paths come from.
pub fn check_files(files: &[&Path], flag: &str, inputs: &[(PathBuf, String)]) -> Result<()> {
    for f in files {
        check_file_name(f, flag)?;
        if f.is_dir() {
            return Err(Error::invalid(
                "command line",
                flag,
                format!("`{}` is a folder; the output must be a file name", f.display()),
            ));
        }
        // The atomic write renames a new file over the old one, which its own permission would
        // not stop.
        if std::fs::metadata(f).is_ok_and(|m| m.permissions().readonly()) {
            return Err(Error::invalid(
                "command line",
                flag,
                format!(
                    "`{}` exists and is read-only; make it writable (chmod u+w) to replace it, or choose another output name",
                    f.display()
                ),
            ));
        }
        check_writable_folder(folder_of(f), flag)?;
        check_not_input(f, flag, inputs)?;
    }
    Ok(())
}

/// An output folder (the command creates it if missing): it, or the nearest folder above it that
/// exists, is writable, and it holds none of the scene's `inputs` under a name `would_write` says
/// the command writes there.
pub fn check_folder(dir: &Path, flag: &str, inputs: &[(PathBuf, String)], would_write: impl Fn(&Path) -> bool) -> Result<()> {
    if let Some(len) = dir.iter().map(|c| c.as_encoded_bytes().len()).find(|&n| n > NAME_MAX) {
        return Err(Error::invalid(
            "command line",
            flag,
            format!(
                "a folder name in `{}` is {len} bytes long; file systems allow at most {NAME_MAX}: choose a shorter name",
                dir.display()
            ),
        ));
    }
    if dir.exists() && !dir.is_dir() {
        return Err(Error::invalid(
            "command line",
            flag,
            format!("`{}` is a file; the output must be a folder", dir.display()),
        ));
    }
    if !dir.exists() {
        let mut above = folder_of(dir);
        while !above.exists() {
            above = folder_of(above);
        }
        return check_writable_folder(above, flag);
    }
    check_writable_folder(dir, flag)?;
    let Ok(d) = dir.canonicalize() else {
        return Ok(());
    };
    for (input, key) in inputs {
        if let Ok(i) = input.canonicalize() {
            if i.parent() == Some(d.as_path()) && would_write(&i) {
                return Err(Error::invalid(
                    "command line",
                    flag,
                    format!(
                        "the folder `{}` holds {key} of the scene (`{}`), which this command may overwrite; choose another folder",
                        dir.display(),
                        input.display()
                    ),
                ));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_input_is_refused_under_another_spelling() {
        let dir = tempfile::tempdir().unwrap();
        let env = dir.path().join("env.exr");
        std::fs::write(&env, b"x").unwrap();
        let inputs = vec![(env.clone(), "sky.path".to_string())];
        let other = dir.path().join("sub/../env.exr");
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        let e = check_files(&[&other], "--output", &inputs).unwrap_err().to_string();
        assert!(e.contains("sky.path"), "{e}");
        assert!(check_files(&[&dir.path().join("out.exr")], "--output", &inputs).is_ok());
    }

    #[test]
    fn a_read_only_output_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out.exr");
        std::fs::write(&out, b"x").unwrap();
        assert!(check_files(&[&out], "--output", &[]).is_ok());
        let mut p = std::fs::metadata(&out).unwrap().permissions();
        p.set_readonly(true);
        std::fs::set_permissions(&out, p).unwrap();
        let e = check_files(&[&out], "--output", &[]).unwrap_err().to_string();
        assert!(e.contains("--output") && e.contains("out.exr") && e.contains("read-only"), "{e}");
    }

    #[test]
    fn names_no_file_system_accepts_are_refused() {
        // A folder the command would create, too: refused before any work, naming the flag.
        let dir = tempfile::tempdir().unwrap();
        let long = dir.path().join("figs").join("n".repeat(300));
        let e = check_folder(&long, "--output", &[], |_| true).unwrap_err().to_string();
        assert!(e.contains("--output") && e.contains("300 bytes"), "{e}");
        let e = check_file_name(Path::new("out.exr/"), "--output").unwrap_err().to_string();
        assert!(e.contains("names a folder"), "{e}");
        let long = format!("{}.exr", "n".repeat(300));
        let e = check_file_name(Path::new(&long), "--output").unwrap_err().to_string();
        assert!(e.contains("304 bytes") && e.contains("shorter"), "{e}");
        assert!(check_file_name(Path::new(&format!("{}.exr", "n".repeat(251))), "--output").is_ok());
    }

    #[test]
    fn missing_folder_and_folder_as_file_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let e = check_files(&[&dir.path().join("nope/x.exr")], "--output", &[])
            .unwrap_err()
            .to_string();
        assert!(e.contains("does not exist"), "{e}");
        std::fs::create_dir(dir.path().join("x.png")).unwrap();
        let e = check_files(&[&dir.path().join("x.png")], "--output", &[]).unwrap_err().to_string();
        assert!(e.contains("is a folder"), "{e}");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1, "the probe file is removed");
    }
}
