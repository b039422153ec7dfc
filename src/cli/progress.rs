//! Progress on stderr: a bar per stage on a terminal; without a terminal (a log file, a pipe) a
//! plain line every [`LINE_INTERVAL`] while a stage runs, so long renders show they are alive.
//! Nothing with --quiet.

use cloudgi::Progress;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Time between two progress lines when stderr is not a terminal.
pub const LINE_INTERVAL: Duration = Duration::from_secs(10);

/// One bar (or line printer) per stage.
pub struct Bars {
    quiet: bool,
    terminal: bool,
    bar: Mutex<Option<ProgressBar>>,
    lines: Mutex<Option<Lines>>,
}

/// The line printer of one stage: a thread that wakes every [`LINE_INTERVAL`] (or when the
/// stage ends) and prints the count.
struct Lines {
    pos: Arc<AtomicU64>,
    done: Arc<(Mutex<bool>, Condvar)>,
    thread: JoinHandle<()>,
}

impl Lines {
    fn start(stage: String, total: u64, interval: Duration) -> Lines {
        let pos = Arc::new(AtomicU64::new(0));
        let done = Arc::new((Mutex::new(false), Condvar::new()));
        let (p, d) = (pos.clone(), done.clone());
        let thread = std::thread::spawn(move || {
            let start = Instant::now();
            let (lock, cv) = &*d;
            let Ok(mut finished) = lock.lock() else { return };
            let mut next = start + interval;
            // The flag is checked before every wait: `finish` may have run before this thread
            // took the lock, and a wakeup may be spurious.
            while !*finished {
                let now = Instant::now();
                if now >= next {
                    note!("{}", line(&stage, p.load(Ordering::Relaxed), total, start.elapsed()));
                    next += interval;
                    continue;
                }
                let Ok((g, _)) = cv.wait_timeout(finished, next - now) else {
                    return;
                };
                finished = g;
            }
        });
        Lines { pos, done, thread }
    }

    fn finish(self) {
        if let Ok(mut f) = self.done.0.lock() {
            *f = true;
        }
        self.done.1.notify_all();
        let _ = self.thread.join();
    }
}

/// `stage: 1200/19200 (6.2 %), 10 s, eta 150 s`.
fn line(stage: &str, pos: u64, total: u64, elapsed: Duration) -> String {
    let t = elapsed.as_secs_f64();
    let frac = if total > 0 { pos as f64 / total as f64 } else { 0.0 };
    let eta = if pos > 0 {
        format!("eta {:.0} s", t * (1.0 - frac) / frac)
    } else {
        "eta unknown".into()
    };
    format!("{stage}: {pos}/{total} ({:.1} %), {t:.0} s, {eta}", 100.0 * frac)
}

impl Bars {
    pub fn new(quiet: bool) -> Self {
        Bars {
            quiet,
            terminal: std::io::stderr().is_terminal(),
            bar: Mutex::new(None),
            lines: Mutex::new(None),
        }
    }

    /// One line on stderr, above the bar if one is drawn.
    fn println(&self, msg: &str) {
        match self.bar.lock().ok().and_then(|b| b.clone()) {
            Some(pb) if !pb.is_hidden() => pb.println(msg),
            _ => note!("{msg}"),
        }
    }
}

impl Progress for Bars {
    fn begin(&self, stage: &str, total: u64) {
        if self.quiet {
            return;
        }
        if !self.terminal {
            if let Ok(mut l) = self.lines.lock() {
                if let Some(old) = l.replace(Lines::start(stage.to_string(), total, LINE_INTERVAL)) {
                    old.finish();
                }
            }
            return;
        }
        let pb = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr());
        pb.set_style(
            ProgressStyle::with_template("{msg:>20} [{bar:40}] {pos}/{len} {elapsed_precise} eta {eta}")
                .expect("valid template")
                .progress_chars("=> "),
        );
        pb.set_message(stage.to_string());
        if let Ok(mut b) = self.bar.lock() {
            *b = Some(pb);
        }
    }

    fn advance(&self, n: u64) {
        if let Ok(l) = self.lines.lock() {
            if let Some(l) = l.as_ref() {
                l.pos.fetch_add(n, Ordering::Relaxed);
                return;
            }
        }
        if let Ok(b) = self.bar.lock() {
            if let Some(pb) = b.as_ref() {
                pb.inc(n);
            }
        }
    }

    fn end(&self) {
        if let Some(l) = self.lines.lock().ok().and_then(|mut l| l.take()) {
            l.finish();
        }
        if let Ok(mut b) = self.bar.lock() {
            if let Some(pb) = b.take() {
                pb.finish_and_clear();
            }
        }
    }

    fn log(&self, msg: &str) {
        if self.quiet {
            return;
        }
        self.println(msg);
    }

    /// Printed with `--quiet` too, like the scene's warnings.
    fn warn(&self, msg: &str) {
        self.println(&format!("warning: {msg}"));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_say_where_a_stage_is() {
        assert_eq!(
            line("reference", 1200, 19200, Duration::from_secs(10)),
            "reference: 1200/19200 (6.2 %), 10 s, eta 150 s"
        );
        assert_eq!(line("x", 0, 0, Duration::ZERO), "x: 0/0 (0.0 %), 0 s, eta unknown");
        // The printer stops at once when the stage ends, without waiting out its interval,
        // whether it ends before or after the thread first waits.
        for pause in [0, 50] {
            let l = Lines::start("x".into(), 10, Duration::from_secs(3600));
            std::thread::sleep(Duration::from_millis(pause));
            let t = Instant::now();
            l.finish();
            assert!(t.elapsed() < Duration::from_secs(5));
        }
    }
}
