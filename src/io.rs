//! File input with a cap on what is read, and file output that never leaves a partial file:
//! write a hidden temporary beside the target, then rename.

use crate::error::{Error, Result};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard};

/// Most bytes read from a text input (a scene file, a `.json` sidecar): 16 MiB, a thousand times
/// the longest hand-written scene, so a path to an endless device (`/dev/zero`) or a huge file
/// fails at once instead of filling memory.
pub const MAX_TEXT_BYTES: u64 = 16 << 20;

/// Read at most `max` bytes of `path`; more is an error that names `what` the file should be.
pub fn read_capped(path: &Path, max: u64, what: &str) -> Result<Vec<u8>> {
    let f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    if f.metadata().is_ok_and(|m| m.is_dir()) {
        return Err(Error::format(
            path.display().to_string(),
            format!("a folder, not {what}; give the path of {what}"),
        ));
    }
    let mut bytes = Vec::new();
    f.take(max + 1).read_to_end(&mut bytes).map_err(|e| Error::io(path, e))?;
    if bytes.len() as u64 > max {
        return Err(Error::format(
            path.display().to_string(),
            format!("more than {}: {what} is far smaller; check the path", size_text(max)),
        ));
    }
    Ok(bytes)
}

/// Read a binary input (a grid, an image): it must be a regular file, and no more than the
/// size it had when opened is read, so a device or a file that grows cannot exhaust memory.
pub fn read_regular(path: &Path, what: &str) -> Result<Vec<u8>> {
    let f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let meta = f.metadata().map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        return Err(Error::format(
            path.display().to_string(),
            format!("not a regular file (a device, pipe or folder); give the path of {what}"),
        ));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    f.take(meta.len()).read_to_end(&mut bytes).map_err(|e| Error::io(path, e))?;
    Ok(bytes)
}

/// The folder a file path lives in (`.` for a bare name).
pub fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// `dir` must be an existing folder this process can create files in (tried with a probe file,
/// which is removed again). `source` and `field` say where the path came from, in the message
/// (`command line`, `--output`).
pub fn check_writable_folder(dir: &Path, source: &str, field: &str) -> Result<()> {
    if !dir.is_dir() {
        let message = if dir.exists() {
            format!("`{}` is a file, not a folder to write in", dir.display())
        } else {
            format!("the folder `{}` does not exist; create it first", dir.display())
        };
        return Err(Error::invalid(source, field, message));
    }
    let probe = dir.join(format!(".cloudgi-write-test-{}", std::process::id()));
    match std::fs::OpenOptions::new().write(true).create_new(true).open(&probe) {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) => Err(Error::invalid(
            source,
            field,
            format!("cannot write in the folder `{}`: {e}", dir.display()),
        )),
    }
}

/// Longest file name (bytes) Linux, macOS and Windows file systems accept.
pub(crate) const NAME_MAX: usize = 255;

/// `path` names a file a command can create: it is not empty, does not end in a `/` (a folder)
/// and its name fits the file system's limit of [`NAME_MAX`] bytes.
pub fn check_file_name(path: &Path, source: &str, field: &str) -> Result<()> {
    let text = path.as_os_str().as_encoded_bytes();
    if text.is_empty() {
        return Err(Error::invalid(source, field, "the path is empty; give a file name, e.g. cloud.exr"));
    }
    if text.ends_with(b"/") || text.ends_with(std::path::MAIN_SEPARATOR_STR.as_bytes()) {
        return Err(Error::invalid(
            source,
            field,
            format!(
                "`{}` ends in a path separator, so it names a folder; give a file name, e.g. cloud.exr",
                path.display()
            ),
        ));
    }
    if text.contains(&0) {
        return Err(Error::invalid(
            source,
            field,
            format!("{path:?} holds a NUL character, which no file name can; remove it"),
        ));
    }
    let len = path.file_name().map_or(0, |n| n.as_encoded_bytes().len());
    if len > NAME_MAX {
        return Err(Error::invalid(
            source,
            field,
            format!("the file name is {len} bytes long; file systems allow at most {NAME_MAX}: choose a shorter name"),
        ));
    }
    Ok(())
}

/// `path` can be written as an output file, checked before any work: a file name
/// ([`check_file_name`]), not a folder nor an existing read-only file, in an existing folder
/// this process can write in.
pub fn check_output_file(path: &Path, source: &str, field: &str) -> Result<()> {
    check_file_name(path, source, field)?;
    if path.is_dir() {
        return Err(Error::invalid(
            source,
            field,
            format!("`{}` is a folder; the output must be a file name", path.display()),
        ));
    }
    // The atomic write renames a new file over the old one: a device, pipe or socket there would
    // be replaced by a regular file (`/dev/full`, where root may rename), not written to.
    if std::fs::metadata(path).is_ok_and(|m| !m.is_file()) {
        return Err(Error::invalid(
            source,
            field,
            format!(
                "`{}` is a device, pipe or socket, not a file: the output is written as a new file renamed over \
                 the old one, which would replace it; give a file name",
                path.display()
            ),
        ));
    }
    // Nor would the old file's own permission stop it.
    if std::fs::metadata(path).is_ok_and(|m| m.permissions().readonly()) {
        return Err(Error::invalid(
            source,
            field,
            format!(
                "`{}` exists and is read-only; make it writable (chmod u+w) to replace it, or choose another output name",
                path.display()
            ),
        ));
    }
    check_writable_folder(folder_of(path), source, field)
}

/// `n` bytes in the largest whole unit.
fn size_text(n: u64) -> String {
    if n >= 1 << 20 && n % (1 << 20) == 0 {
        format!("{} MiB", n >> 20)
    } else {
        format!("{n} bytes")
    }
}

/// The temporaries being written now; removed by [`remove_temporaries`] on an interrupt.
static TEMPORARIES: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// The files this process has written (renamed into place), for the interrupt's message.
static WRITTEN: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// The output folders this process created (innermost first), for removal while still empty.
static CREATED_DIRS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn created_dirs() -> MutexGuard<'static, Vec<PathBuf>> {
    CREATED_DIRS.lock().unwrap_or_else(|e| e.into_inner())
}

/// Create the output folder `dir` and its missing parents, each registered for
/// [`remove_created_empty_dirs`], so an error or interrupt before anything is written in it
/// leaves no empty folder behind.
pub fn create_output_dir(dir: &Path) -> Result<()> {
    let missing: Vec<PathBuf> = dir
        .ancestors()
        .take_while(|d| !d.as_os_str().is_empty() && !d.exists())
        .map(Path::to_path_buf)
        .collect();
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    created_dirs().extend(missing);
    Ok(())
}

/// Remove the folders [`create_output_dir`] created that are still empty, innermost first (a
/// folder that holds written output stays).
pub fn remove_created_empty_dirs() {
    for d in created_dirs().drain(..) {
        let _ = std::fs::remove_dir(d);
    }
}

/// The files this process has written so far.
pub fn written() -> Vec<PathBuf> {
    WRITTEN.lock().unwrap_or_else(|e| e.into_inner()).clone()
}

fn temporaries() -> MutexGuard<'static, Vec<PathBuf>> {
    TEMPORARIES.lock().unwrap_or_else(|e| e.into_inner())
}

/// Remove every temporary file being written (called when the process is interrupted). It waits
/// for a set of renames in progress, so the outputs are either all in place or none. Returns
/// whether any was removed.
pub fn remove_temporaries() -> bool {
    let mut t = temporaries();
    let any = !t.is_empty();
    for p in t.drain(..) {
        let _ = std::fs::remove_file(p);
    }
    any
}

/// A short hidden temporary name in the folder of `path`: it fits every file system's 255-byte
/// name limit whatever the length of the target's name.
fn temp_name(path: &Path) -> PathBuf {
    static NEXT: AtomicUsize = AtomicUsize::new(0);
    let n = NEXT.fetch_add(1, Ordering::Relaxed);
    path.with_file_name(format!(".cloudgi-{}-{n}.tmp", std::process::id()))
}

/// Write `bytes` to a temporary beside `path` (registered for removal on an interrupt); on
/// failure remove it.
fn write_temp(path: &Path, bytes: &[u8]) -> Result<PathBuf> {
    let tmp = temp_name(path);
    temporaries().push(tmp.clone());
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()
    })();
    result.map(|()| tmp.clone()).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        temporaries().retain(|t| t != &tmp);
        Error::io(path, e)
    })
}

/// Write `bytes` to `path` atomically (temporary file in the same folder, then rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic_all(&[(path, bytes)])
}

/// Write several files as one: every file goes to its temporary name first, and only when all
/// of them are written are they renamed into place, so a failure on one (a full disk, a folder
/// in the way) leaves none of them behind; a rename that fails removes the files already
/// renamed.
pub fn write_atomic_all(files: &[(&Path, &[u8])]) -> Result<()> {
    let mut temps: Vec<PathBuf> = Vec::with_capacity(files.len());
    let forget = |temps: &[PathBuf]| {
        let mut t = temporaries();
        for p in temps {
            let _ = std::fs::remove_file(p);
            t.retain(|x| x != p);
        }
    };
    for (path, bytes) in files {
        match write_temp(path, bytes) {
            Ok(t) => temps.push(t),
            Err(e) => {
                forget(&temps);
                return Err(e);
            }
        }
    }
    // The lock keeps an interrupt from removing temporaries halfway through the renames.
    let mut pending = temporaries();
    let mut result = Ok(());
    for (i, ((path, _), tmp)) in files.iter().zip(&temps).enumerate() {
        if let Err(e) = std::fs::rename(tmp, path) {
            for (done, _) in &files[..i] {
                let _ = std::fs::remove_file(done);
            }
            for t in &temps[i..] {
                let _ = std::fs::remove_file(t);
            }
            result = Err(Error::io(*path, e));
            break;
        }
    }
    pending.retain(|x| !temps.contains(x));
    if result.is_ok() {
        WRITTEN
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .extend(files.iter().map(|(p, _)| p.to_path_buf()));
    }
    result
}

/// Bytes of memory available to new allocations (Linux `MemAvailable`), if known.
pub fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Refuse, before it is allocated, work that needs `need` bytes when less is available: an
/// [`Error::Invalid`] of `source`'s `field` saying "`what` need(s) about N of memory to `purpose`
/// but M is available; `fix`". Unknown available memory (not Linux) refuses nothing.
pub fn check_memory(source: &str, field: &str, what: &str, need: u128, fix: &str) -> Result<()> {
    match available_memory() {
        Some(avail) if need > avail as u128 => Err(Error::invalid(
            source,
            field,
            format!(
                "{what} about {} of memory but {} is available; {fix}",
                format_bytes(need),
                format_bytes(avail as u128)
            ),
        )),
        _ => Ok(()),
    }
}

/// A byte count for messages, in binary units with one decimal: `1536` → `1.5 KiB`.
pub fn format_bytes(b: u128) -> String {
    const UNITS: [&str; 7] = ["B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    let mut v = b as f64;
    let mut u = 0;
    while v >= 1024.0 && u + 1 < UNITS.len() {
        v /= 1024.0;
        u += 1;
    }
    format!("{v:.1} {}", UNITS[u])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failing_file_leaves_none_of_the_set_behind() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.exr"), dir.path().join("missing/b.png"));
        assert!(write_atomic_all(&[(&a, b"1"), (&b, b"2")]).is_err());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "no a.exr, no temporary file");
        let b = dir.path().join("b.png");
        write_atomic_all(&[(&a, b"1"), (&b, b"2")]).unwrap();
        assert_eq!(std::fs::read(&a).unwrap(), b"1");
        assert_eq!(std::fs::read(&b).unwrap(), b"2");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
    }

    #[test]
    fn a_failing_rename_removes_the_files_already_renamed() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a.exr");
        // A non-empty folder where the second file goes: its temporary is written, its rename fails.
        let b = dir.path().join("b.png");
        std::fs::create_dir_all(b.join("inside")).unwrap();
        assert!(write_atomic_all(&[(&a, b"1"), (&b, b"2")]).is_err());
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(left, ["b.png"], "no a.exr, no temporary file");
    }

    #[test]
    fn temporary_names_fit_any_file_system_and_long_targets_still_write() {
        let dir = tempfile::tempdir().unwrap();
        let long = dir.path().join(format!("{}.exr", "n".repeat(250)));
        assert!(temp_name(&long).file_name().unwrap().len() < 40);
        write_atomic(&long, b"x").unwrap();
        assert_eq!(std::fs::read(&long).unwrap(), b"x");
    }

    #[test]
    fn names_no_file_system_accepts_are_refused() {
        let e = check_file_name(Path::new("out.exr/"), "command line", "--output").unwrap_err().to_string();
        assert!(e.contains("names a folder"), "{e}");
        let long = format!("{}.exr", "n".repeat(300));
        let e = check_file_name(Path::new(&long), "command line", "--output").unwrap_err().to_string();
        assert!(e.contains("304 bytes") && e.contains("shorter"), "{e}");
        assert!(check_file_name(Path::new(&format!("{}.exr", "n".repeat(251))), "command line", "--output").is_ok());
        let e = check_file_name(Path::new(""), "cloudgi.write_exr", "path").unwrap_err().to_string();
        assert_eq!(e, "cloudgi.write_exr: field `path`: the path is empty; give a file name, e.g. cloud.exr");
    }

    #[test]
    fn an_output_that_is_a_folder_is_refused_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        for folder in [Path::new("."), dir.path()] {
            let e = check_output_file(folder, "cloudgi.write_exr", "path").unwrap_err().to_string();
            let want = format!("cloudgi.write_exr: field `path`: `{}` is a folder; the output must be a file name", folder.display());
            assert_eq!(e, want);
        }
        assert!(check_output_file(&dir.path().join("x.exr"), "cloudgi.write_exr", "path").is_ok());
        let file = dir.path().join("f.txt");
        std::fs::write(&file, b"x").unwrap();
        let e = check_output_file(&file.join("x.exr"), "cloudgi.write_exr", "path").unwrap_err().to_string();
        assert!(e.ends_with(&format!("`{}` is a file, not a folder to write in", file.display())), "{e}");
        std::fs::remove_file(&file).unwrap();
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "the probe file is removed");
    }

    #[test]
    #[cfg(unix)]
    fn an_output_that_is_a_socket_or_device_or_holds_a_nul_is_refused_not_replaced() {
        // Renamed over, a device (`/dev/full` as root) became a regular file holding an EXR.
        let dir = tempfile::tempdir().unwrap();
        let socket = dir.path().join("s.exr");
        let _listener = std::os::unix::net::UnixListener::bind(&socket).unwrap();
        for path in [socket.as_path(), Path::new("/dev/null")] {
            let e = check_output_file(path, "cloudgi.write_exr", "path").unwrap_err().to_string();
            assert!(e.contains("is a device, pipe or socket, not a file"), "{e}");
        }
        let e = check_output_file(Path::new("a\0b.exr"), "cloudgi.write_exr", "path").unwrap_err().to_string();
        assert_eq!(e, "cloudgi.write_exr: field `path`: \"a\\0b.exr\" holds a NUL character, which no file name can; remove it");
    }

    #[test]
    fn reading_is_capped() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.toml");
        std::fs::write(&p, vec![b'#'; 2048]).unwrap();
        assert_eq!(read_capped(&p, 2048, "a scene").unwrap().len(), 2048);
        let e = read_capped(&p, 1024, "a scene").unwrap_err().to_string();
        assert!(e.contains("s.toml") && e.contains("a scene"), "{e}");
    }

    #[test]
    fn byte_counts_read_in_binary_units() {
        assert_eq!(format_bytes(0), "0.0 B");
        assert_eq!(format_bytes(1536), "1.5 KiB");
        assert_eq!(format_bytes(3 << 30), "3.0 GiB");
    }
}
