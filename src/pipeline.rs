//! What every stage and method shares and nothing depends on: progress reporting, stage
//! timings and the parallel row loop. Below the stages in the module order (medium/lighting →
//! stage 1 → diffusion → lit → clear air → edges → methods → CLI), so any of them may use it.

use std::time::Instant;

/// Receives progress of long stages (the CLI draws bars; tests pass [`NoProgress`]).
pub trait Progress: Sync {
    /// A stage with `total` units of work begins.
    fn begin(&self, stage: &str, total: u64);
    /// `n` more units are done.
    fn advance(&self, n: u64);
    /// The current stage is finished.
    fn end(&self);
    /// A one-line message (e.g. solver convergence).
    fn log(&self, _msg: &str) {}
    /// An iterative stage's measure of change after an iteration, against the `tolerance` that
    /// ends it (both unitless): progress is how far the change has come down, on a log scale.
    fn converge(&self, _change: f64, _tolerance: f64) {}
    /// Whether [`Progress::image`] shows anything (a stage builds its image so far only then).
    fn wants_images(&self) -> bool {
        false
    }
    /// The image so far (`reference`: after each pass), for a live view.
    fn image(&self, _img: &crate::image::Image) {}
    /// A one-line warning the user must see even when progress is quiet (e.g. a solver stopped
    /// at its iteration cap); by default a [`Progress::log`] line.
    fn warn(&self, msg: &str) {
        self.log(msg)
    }
    /// Whether the caller asked the render to stop ([`crate::Options::cancel`]); polled between
    /// rows, passes and solver iterations, which then skip their remaining work. False by default.
    fn cancelled(&self) -> bool {
        false
    }
}

/// Progress sink that ignores everything.
pub struct NoProgress;

impl Progress for NoProgress {
    fn begin(&self, _: &str, _: u64) {}
    fn advance(&self, _: u64) {}
    fn end(&self) {}
}

/// Wall-clock time per stage, in order.
#[derive(Clone, Debug, Default)]
pub struct Timings {
    /// (stage, seconds).
    pub stages: Vec<(String, f64)>,
}

impl Timings {
    /// Run `f` as stage `name`, recording its time (added to the stage's earlier runs, so an
    /// iterated stage shows its total).
    pub fn time<T>(&mut self, name: &str, f: impl FnOnce() -> T) -> T {
        let t = Instant::now();
        let r = f();
        let dt = t.elapsed().as_secs_f64();
        match self.stages.iter_mut().find(|s| s.0 == name) {
            Some(s) => s.1 += dt,
            None => self.stages.push((name.to_string(), dt)),
        }
        r
    }

    /// Total seconds.
    pub fn total(&self) -> f64 {
        self.stages.iter().map(|s| s.1).sum()
    }

    /// One line: `stage 0.12 s · stage 0.50 s · total 0.62 s`.
    pub fn summary(&self) -> String {
        let mut parts: Vec<String> = self.stages.iter().map(|(n, s)| format!("{n} {s:.3} s")).collect();
        parts.push(format!("total {:.3} s", self.total()));
        parts.join(" · ")
    }
}

/// Render rows in parallel: `shade(x, y)` gives a pixel; progress advances per row.
pub fn render_rows<T: Clone + Default + Send>(
    width: u32,
    height: u32,
    progress: &dyn Progress,
    stage: &str,
    shade: impl Fn(u32, u32) -> T + Sync,
) -> Vec<T> {
    progress.begin(stage, height as u64);
    let mut px = vec![T::default(); width as usize * height as usize];
    crate::par::for_chunks(&mut px, width as usize, &|y, row| {
        if progress.cancelled() {
            return;
        }
        for (x, p) in row.iter_mut().enumerate() {
            *p = shade(x as u32, y as u32);
        }
        progress.advance(1);
    });
    progress.end();
    px
}
