//! Rendering: method dispatch, progress reporting and stage timings.

pub mod diffusion;
pub mod full;
pub mod march;
pub mod single;

use crate::error::Result;
use crate::image::Image;
use crate::scene::{Method, Scene};
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

/// A finished render.
#[derive(Clone, Debug)]
pub struct RenderOutput {
    /// The image (linear HDR).
    pub image: Image,
    /// Stage timings.
    pub timings: Timings,
}

/// Render `scene` with its configured method.
pub fn render(scene: &Scene, progress: &dyn Progress) -> Result<RenderOutput> {
    let mut timings = Timings::default();
    let image = match scene.render.method {
        Method::Single => single::render(scene, progress, &mut timings)?,
        Method::Reference => crate::reference::render(scene, progress, &mut timings)?,
        Method::Diffusion => diffusion::render(scene, progress, &mut timings)?,
        Method::Full => full::render(scene, progress, &mut timings)?,
        Method::Transport => crate::transport::render::render(scene, progress, &mut timings)?,
    };
    Ok(RenderOutput { image, timings })
}

/// Render rows in parallel: `shade(x, y)` gives a pixel; progress advances per row.
pub fn render_rows<T: Clone + Default + Send>(
    width: u32,
    height: u32,
    progress: &dyn Progress,
    stage: &str,
    shade: impl Fn(u32, u32) -> T + Sync,
) -> Vec<T> {
    use rayon::prelude::*;
    progress.begin(stage, height as u64);
    let mut px = vec![T::default(); width as usize * height as usize];
    px.par_chunks_mut(width as usize).enumerate().for_each(|(y, row)| {
        for (x, p) in row.iter_mut().enumerate() {
            *p = shade(x as u32, y as u32);
        }
        progress.advance(1);
    });
    progress.end();
    px
}
