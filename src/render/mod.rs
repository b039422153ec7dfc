//! The methods (`single`, `diffusion`, `full`; `reference` in [`crate::reference`]) and their
//! dispatch. Progress, timings and the row loop live below the stages, in [`crate::pipeline`].

pub mod diffusion;
pub mod empty;
pub mod full;
pub mod single;
pub mod transport;
pub mod transport_ground;
pub mod warm;

use crate::error::Result;
use crate::image::Image;
pub use crate::pipeline::{render_rows, NoProgress, Progress, Timings};
use crate::scene::{Method, Scene};

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
    if matches!(scene.render.method, Method::Diffusion | Method::Full) && empty::is_transparent(&scene.medium) {
        let image = empty::render(scene, progress, &mut timings)?;
        return Ok(RenderOutput { image, timings });
    }
    let image = match scene.render.method {
        Method::Single => single::render(scene, progress, &mut timings)?,
        Method::Reference => crate::reference::render(scene, progress, &mut timings)?,
        Method::Diffusion => diffusion::render(&delta_m(scene), progress, &mut timings)?,
        Method::Full => full::render(&delta_m(scene), progress, &mut timings)?,
        Method::Transport => transport::render(scene, progress, &mut timings)?,
    };
    Ok(RenderOutput { image, timings })
}

/// The scene every stage of `diffusion` and `full` runs on: its medium after the δ-M transform
/// with `render.forward_fraction` (the same scene when it is 0, the paper's scheme).
pub fn delta_m(scene: &Scene) -> std::borrow::Cow<'_, Scene> {
    let f = scene.render.forward_fraction;
    if f == 0.0 {
        return std::borrow::Cow::Borrowed(scene);
    }
    let mut s = scene.clone();
    s.medium.optics = s.medium.optics.delta_m(f);
    std::borrow::Cow::Owned(s)
}
