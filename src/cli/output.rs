//! Checks on where a command will write, made before any work: the folder exists and is
//! writable, no output is a folder or an existing read-only file, and no output is one of the
//! scene's own input files (the atomic rename would replace either).

use crate::error::{Error, Result};
use crate::io::{check_output_file, check_writable_folder, folder_of, NAME_MAX};
use std::path::{Path, PathBuf};

/// The source named in the messages.
const CLI: &str = "command line";

/// `path` with its folder resolved (symbolic links, `..`), the file itself need not exist.
fn resolved(path: &Path) -> Option<PathBuf> {
    if let Ok(p) = path.canonicalize() {
        return Some(p);
    }
    Some(folder_of(path).canonicalize().ok()?.join(path.file_name()?))
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

/// Every file in `files` can be written ([`check_output_file`]: a file name, not a folder nor an
/// existing read-only file, in a writable folder) and is none of the scene's `inputs`. `flag`
/// names the option the paths come from.
pub fn check_files(files: &[&Path], flag: &str, inputs: &[(PathBuf, String)]) -> Result<()> {
    for f in files {
        check_output_file(f, CLI, flag)?;
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
        return check_writable_folder(above, CLI, flag);
    }
    check_writable_folder(dir, CLI, flag)?;
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
    fn a_folder_name_no_file_system_accepts_is_refused() {
        // A folder the command would create: refused before any work, naming the flag.
        let dir = tempfile::tempdir().unwrap();
        let long = dir.path().join("figs").join("n".repeat(300));
        let e = check_folder(&long, "--output", &[], |_| true).unwrap_err().to_string();
        assert!(e.contains("--output") && e.contains("300 bytes"), "{e}");
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
