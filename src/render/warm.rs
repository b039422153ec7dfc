//! Frames of a sequence rendered one after another, each solve starting from the previous
//! frame's converged solution (a warm start) instead of from nothing: `transport`'s moments, the
//! diffusion solution of `diffusion` and `full`. `single` and `reference` have no solve.

use super::{check_finite, delta_m, diffusion, empty, full, render, transport, RenderOutput};
use crate::diffusion::warm::{DiffusionState, WarmSolve};
use crate::error::Result;
use crate::pipeline::{Progress, Timings};
use crate::scene::{Method, Scene};
use crate::transport::warm::TransportState;

/// What one frame hands the next.
#[derive(Clone, Debug, Default)]
pub struct Warm {
    /// Start each solve from the last frame's state and keep the new one (false: every frame cold).
    pub enabled: bool,
    /// The last `transport` solve's converged state.
    pub transport: Option<TransportState>,
    /// The last `diffusion` or `full` frame's diffusion solution.
    pub diffusion: Option<DiffusionState>,
    /// Iterations of the last frame's solve: `transport`'s source iterations, or the CG
    /// iterations of `diffusion`'s and `full`'s diffusion solves (the middle band's).
    pub iterations: Option<usize>,
}

impl Warm {
    /// Warm starts on or off; the first frame is always cold.
    pub fn new(enabled: bool) -> Warm {
        Warm {
            enabled,
            ..Warm::default()
        }
    }

    /// Whether the next frame starts from a carried state.
    pub fn is_warm(&self) -> bool {
        self.transport.is_some() || self.diffusion.is_some()
    }

    /// Bytes of the carried state: held beside the next frame's solve.
    pub fn bytes(&self) -> u64 {
        let t = self.transport.as_ref().map_or(0, TransportState::bytes);
        let d = self.diffusion.as_ref().map_or(0, DiffusionState::bytes);
        (t + d) as u64
    }
}

/// Render `scene` as the next frame of a sequence: [`render`], with `transport`, `diffusion` and
/// `full` started from `warm`'s state (when enabled), which is then replaced by this frame's.
pub fn render_warm(scene: &Scene, progress: &dyn Progress, warm: &mut Warm) -> Result<RenderOutput> {
    let method = scene.render.method;
    let solves = match method {
        Method::Transport => true,
        Method::Diffusion | Method::Full => !empty::is_transparent(&scene.medium),
        Method::Single | Method::Reference => false,
    };
    if !solves {
        *warm = Warm::new(warm.enabled);
        return render(scene, progress);
    }
    let mut timings = Timings::default();
    if method == Method::Transport {
        warm.diffusion = None;
        let image = transport::render_with(scene, progress, &mut timings, Some(warm))?;
        check_finite(method.name(), &image)?;
        return Ok(RenderOutput { image, timings });
    }
    warm.transport = None;
    let keep = warm.enabled;
    let opts = WarmSolve {
        start: warm.diffusion.as_ref().filter(|_| keep),
        keep,
    };
    let scene = delta_m(scene);
    let (image, state, iterations) = match method {
        Method::Diffusion => diffusion::render_warm(&scene, progress, &mut timings, opts)?,
        _ => full::render_warm(&scene, progress, &mut timings, opts)?,
    };
    check_finite(method.name(), &image)?;
    (warm.diffusion, warm.iterations) = (state, Some(iterations));
    Ok(RenderOutput { image, timings })
}
