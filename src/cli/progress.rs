//! Progress on stderr: a bar per stage on a terminal; without a terminal (a log file, a pipe) a
//! plain line every [`LINE_INTERVAL`] while a stage runs, so long renders show they are alive.
//! Nothing with --quiet.

use crate::Progress;
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
    convergence: Mutex<Option<Convergence>>,
    display: Option<super::display::Display>,
}

/// The line printer of one stage: a thread that wakes every [`LINE_INTERVAL`] (or when the
/// stage ends) and prints the count, or for an iteration towards a tolerance the convergence
/// ([`Convergence::text`], as the terminal bar shows it).
struct Lines {
    pos: Arc<AtomicU64>,
    convergence: Arc<Mutex<Option<String>>>,
    done: Arc<(Mutex<bool>, Condvar)>,
    thread: JoinHandle<()>,
}

impl Lines {
    fn start(stage: String, total: u64, interval: Duration) -> Lines {
        let pos = Arc::new(AtomicU64::new(0));
        let convergence = Arc::new(Mutex::new(None::<String>));
        let done = Arc::new((Mutex::new(false), Condvar::new()));
        let (p, c, d) = (pos.clone(), convergence.clone(), done.clone());
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
                    match c.lock().ok().and_then(|c| c.clone()) {
                        Some(text) => note!("{stage}: {text}"),
                        None => note!("{}", line(&stage, p.load(Ordering::Relaxed), total, start.elapsed())),
                    }
                    next += interval;
                    continue;
                }
                let Ok((g, _)) = cv.wait_timeout(finished, next - now) else {
                    return;
                };
                finished = g;
            }
        });
        Lines {
            pos,
            convergence,
            done,
            thread,
        }
    }

    fn finish(self) {
        if let Ok(mut f) = self.done.0.lock() {
            *f = true;
        }
        self.done.1.notify_all();
        let _ = self.thread.join();
    }
}

/// No estimate before this share of the work is done *and* this much time has passed: the first
/// units of a stage (threads starting, caches filling) are not its pace.
const ETA_AFTER: (f64, Duration) = (0.01, Duration::from_secs(2));

/// Seconds left at the average pace so far, once [`ETA_AFTER`] allows an estimate.
fn eta_s(pos: u64, total: u64, elapsed: Duration) -> Option<f64> {
    let frac = if total > 0 { pos as f64 / total as f64 } else { 0.0 };
    (pos > 0 && (frac >= ETA_AFTER.0 || elapsed >= ETA_AFTER.1)).then(|| elapsed.as_secs_f64() * (1.0 - frac) / frac)
}

/// `12 s`, `4.5 min`, `2.1 h`.
fn duration_text(s: f64) -> String {
    match s {
        s if s < 90.0 => format!("{s:.0} s"),
        s if s < 5400.0 => format!("{:.1} min", s / 60.0),
        s => format!("{:.1} h", s / 3600.0),
    }
}

/// `stage: 1200/19200 (6.2 %), 10 s, eta 2.5 min`.
fn line(stage: &str, pos: u64, total: u64, elapsed: Duration) -> String {
    let t = elapsed.as_secs_f64();
    let frac = if total > 0 { pos as f64 / total as f64 } else { 0.0 };
    let eta = match eta_s(pos, total, elapsed) {
        Some(e) => format!("eta {}", duration_text(e)),
        None => "eta unknown".into(),
    };
    format!("{stage}: {pos}/{total} ({:.1} %), {t:.0} s, {eta}", 100.0 * frac)
}

/// An iteration towards a tolerance: the first change seen, the last, how many iterations.
struct Convergence {
    first: f64,
    last: f64,
    iterations: u32,
    start: Instant,
}

/// Steps of the convergence bar (log-scale progress from the first change to the tolerance).
const CONVERGENCE_STEPS: u64 = 1000;

impl Convergence {
    /// Share of the way, on a log scale, from the first change down to `tol` (0 to 1).
    fn fraction(&self, tol: f64) -> f64 {
        if self.first <= tol || self.last <= tol {
            return 1.0;
        }
        ((self.first / self.last).ln() / (self.first / tol).ln()).clamp(0.0, 1.0)
    }

    /// Seconds left if the change keeps falling at its mean rate per iteration so far (None
    /// after one iteration, or while it does not fall).
    fn eta_s(&self, tol: f64, elapsed: Duration) -> Option<f64> {
        if self.last <= tol {
            return Some(0.0);
        }
        let rate = (self.first / self.last).ln() / self.iterations.saturating_sub(1) as f64;
        (self.iterations >= 2 && rate > 0.0).then(|| {
            let left = (self.last / tol).ln() / rate;
            left * elapsed.as_secs_f64() / self.iterations as f64
        })
    }

    /// `change 1.4e-2 → 5.0e-3, iteration 3, eta 4 s`.
    fn text(&self, tol: f64) -> String {
        let eta = match self.eta_s(tol, self.start.elapsed()) {
            Some(e) => format!("eta {}", duration_text(e)),
            None => "eta unknown".into(),
        };
        format!("change {:.1e} → {tol:.1e}, iteration {}, {eta}", self.last, self.iterations)
    }
}

impl Bars {
    pub fn new(quiet: bool) -> Self {
        Bars {
            quiet,
            terminal: std::io::stderr().is_terminal(),
            bar: Mutex::new(None),
            lines: Mutex::new(None),
            convergence: Mutex::new(None),
            display: None,
        }
    }

    /// Also stream the images to a live view (`--display-server`).
    pub fn with_display(mut self, display: Option<super::display::Display>) -> Self {
        self.display = display;
        self
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
        if let Ok(mut c) = self.convergence.lock() {
            *c = None;
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
            ProgressStyle::with_template("{msg:>20} [{bar:40}] {human_pos}/{human_len} {elapsed_precise} {honest_eta}")
                .expect("valid template")
                .with_key("honest_eta", |s: &indicatif::ProgressState, w: &mut dyn std::fmt::Write| {
                    let _ = match eta_s(s.pos(), s.len().unwrap_or(0), s.elapsed()) {
                        Some(e) => write!(w, "eta {}", duration_text(e)),
                        None => write!(w, "eta unknown"),
                    };
                })
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

    /// The bar becomes log-scale progress from the first change to the tolerance, with the
    /// change, the iteration and an ETA from the mean rate of fall (the iteration cap is only a cap).
    fn converge(&self, change: f64, tolerance: f64) {
        let Ok(mut c) = self.convergence.lock() else { return };
        let state = c.get_or_insert(Convergence {
            first: change,
            last: change,
            iterations: 0,
            start: Instant::now(),
        });
        state.last = change;
        state.iterations += 1;
        if let Some(l) = self.lines.lock().ok().as_ref().and_then(|l| l.as_ref()) {
            if let Ok(mut text) = l.convergence.lock() {
                *text = Some(state.text(tolerance));
            }
        }
        if let Some(pb) = self.bar.lock().ok().and_then(|b| b.clone()) {
            if state.iterations == 1 {
                pb.set_style(
                    ProgressStyle::with_template("{prefix:>20} [{bar:40}] {msg}")
                        .expect("valid template")
                        .progress_chars("=> "),
                );
                pb.set_prefix("transport");
                pb.set_length(CONVERGENCE_STEPS);
            }
            pb.set_position((state.fraction(tolerance) * CONVERGENCE_STEPS as f64) as u64);
            pb.set_message(state.text(tolerance));
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

    fn wants_images(&self) -> bool {
        self.display.is_some()
    }

    fn image(&self, img: &crate::Image) {
        if let Some(d) = &self.display {
            d.show(img);
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
            "reference: 1200/19200 (6.2 %), 10 s, eta 2.5 min"
        );
        assert_eq!(line("x", 0, 0, Duration::ZERO), "x: 0/0 (0.0 %), 0 s, eta unknown");
        // No estimate from the first 1 % in the first 2 s; hours and minutes in their units.
        assert_eq!(
            line("reference paths", 50, 19200, Duration::from_secs(1)),
            "reference paths: 50/19200 (0.3 %), 1 s, eta unknown"
        );
        assert_eq!(
            line("reference paths", 50, 19200, Duration::from_secs(60)),
            "reference paths: 50/19200 (0.3 %), 60 s, eta 6.4 h"
        );
        // The printer stops at once when the stage ends, without waiting out its interval,
        // whether it ends before or after the thread first waits (600 s: far from the hour a
        // missed wake-up waits, far above any load's scheduling delay).
        for pause in [0, 50] {
            let l = Lines::start("x".into(), 10, Duration::from_secs(3600));
            std::thread::sleep(Duration::from_millis(pause));
            let t = Instant::now();
            l.finish();
            assert!(t.elapsed() < Duration::from_secs(600), "waited out the 3600 s interval");
        }
    }

    #[test]
    fn the_line_printer_shows_the_convergence_not_the_cap() {
        let mut bars = Bars::new(false);
        bars.terminal = false;
        bars.begin("transport iterations", 60);
        bars.converge(1e-1, 1e-4);
        bars.converge(1e-2, 1e-4);
        let text = bars
            .lines
            .lock()
            .unwrap()
            .as_ref()
            .and_then(|l| l.convergence.lock().unwrap().clone());
        let text = text.expect("the line printer holds the convergence");
        assert!(text.starts_with("change 1.0e-2 → 1.0e-4, iteration 2, eta "), "{text}");
        bars.end();
    }

    #[test]
    fn convergence_counts_towards_the_tolerance_not_the_cap() {
        // 1e-1, 1e-2, 1e-3 in 3 iterations of 1 s: a decade per iteration, one more to 1e-4.
        let c = Convergence {
            first: 1e-1,
            last: 1e-3,
            iterations: 3,
            start: Instant::now(),
        };
        assert!((c.fraction(1e-4) - 2.0 / 3.0).abs() < 1e-12);
        let eta = c.eta_s(1e-4, Duration::from_secs(3)).unwrap();
        assert!((eta - 1.0).abs() < 1e-9, "{eta}");
        let one = Convergence {
            iterations: 1,
            last: 1e-1,
            ..c
        };
        assert_eq!((one.fraction(1e-4), one.eta_s(1e-4, Duration::from_secs(1))), (0.0, None));
    }
}
