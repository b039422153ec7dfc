//! The terminal side of the command line: results on stdout as fallible writes (a full disk is
//! an error, a closed pipe ends the command quietly), notes on stderr that never panic, and
//! SIGINT/SIGTERM/SIGHUP, which remove the temporary output files before the process exits.

use crate::error::{Error, Result};
use std::io::Write;

/// Exit status of a command whose reader closed stdout (the shell's 128 + SIGPIPE).
pub const EXIT_BROKEN_PIPE: i32 = 141;

/// Write `text` to stdout and flush it. A reader that closed the pipe is [`Error::Io`] of kind
/// `BrokenPipe` (see [`is_broken_pipe`]); any other failure (a full disk) is an error naming
/// standard output.
pub fn print(text: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())
        .and_then(|()| out.flush())
        .map_err(|e| Error::io("standard output", e))
}

/// Whether `e` is stdout's reader having gone away: the command ends quietly.
pub fn is_broken_pipe(e: &Error) -> bool {
    matches!(e, Error::Io { source, .. } if source.kind() == std::io::ErrorKind::BrokenPipe)
}

/// Write one line to stderr. A stderr that cannot be written (a full disk) drops the line: there
/// is nowhere left to say so, and the command's own result does not depend on it.
pub fn note(args: std::fmt::Arguments) {
    let mut err = std::io::stderr().lock();
    let _ = err.write_fmt(args).and_then(|()| err.write_all(b"\n"));
}

/// On SIGINT, SIGTERM or SIGHUP (the terminal closed; not where it is ignored, as under
/// `nohup`): remove the output temporaries being written (waiting for renames in progress) and
/// the output folders created that are still empty, say in one line whether anything was
/// written, and exit with 128 + the signal.
pub fn clean_up_on_interrupt() -> Result<()> {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    let mut caught = vec![SIGINT, SIGTERM];
    if !ignored(SIGHUP) {
        caught.push(SIGHUP);
    }
    let mut signals = signal_hook::iterator::Signals::new(caught).map_err(|e| Error::io("signal handlers", e))?;
    std::thread::spawn(move || {
        if let Some(sig) = signals.forever().next() {
            let removed = crate::io::remove_temporaries();
            crate::io::remove_created_empty_dirs();
            let name = match sig {
                SIGINT => "SIGINT",
                SIGTERM => "SIGTERM",
                _ => "SIGHUP",
            };
            let written = crate::io::written();
            let what = match (written.is_empty(), removed) {
                (true, _) => "no output written".to_string(),
                (false, removed) => format!(
                    "wrote {}{}",
                    written.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "),
                    if removed { "; the files in progress were removed" } else { "" }
                ),
            };
            note(format_args!("interrupted ({name}): {what}"));
            std::process::exit(128 + sig);
        }
    });
    Ok(())
}

/// Whether signal `sig` is ignored (SIG_IGN), as `nohup` leaves SIGHUP for the command it starts:
/// a handler would undo what the user asked for.
fn ignored(sig: i32) -> bool {
    let mut old = std::mem::MaybeUninit::<libc::sigaction>::zeroed();
    // SAFETY: a null new action only reads the current one into `old`, which is valid for writes.
    let read = unsafe { libc::sigaction(sig, std::ptr::null(), old.as_mut_ptr()) } == 0;
    // SAFETY: sigaction succeeded, so it wrote `old` (and zeroed memory is a valid sigaction anyway).
    read && unsafe { old.assume_init() }.sa_sigaction == libc::SIG_IGN
}
