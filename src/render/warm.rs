//! Frames of a sequence rendered one after another, each solve starting from the previous
//! frame's converged solution (a warm start) instead of from nothing. Only `transport` carries
//! a state; the other methods render every frame cold.

use super::{render, transport, RenderOutput};
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
    /// Source iterations of the last `transport` solve.
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
}

/// Render `scene` as the next frame of a sequence: [`render`], with `transport` started from
/// `warm`'s state (when enabled), which is then replaced by this frame's.
pub fn render_warm(scene: &Scene, progress: &dyn Progress, warm: &mut Warm) -> Result<RenderOutput> {
    if scene.render.method != Method::Transport {
        *warm = Warm::new(warm.enabled);
        return render(scene, progress);
    }
    let mut timings = Timings::default();
    let image = transport::render_with(scene, progress, &mut timings, Some(warm))?;
    Ok(RenderOutput { image, timings })
}
