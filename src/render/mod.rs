//! The methods (`single`, `diffusion`, `full`; `reference` in [`crate::reference`]) and their
//! dispatch. Progress, timings and the row loop live below the stages, in [`crate::pipeline`].

pub mod beam_check;
pub mod diffusion;
pub mod edge_pixels;
pub mod empty;
pub mod full;
pub mod full_beam;
pub mod single;
pub mod transport;
pub mod transport_ground;
pub mod warm;

use crate::error::{Error, Result};
use crate::image::Image;
pub use crate::pipeline::{render_rows, Progress, Timings};
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
    check_finite(scene.render.method.name(), &image)?;
    Ok(RenderOutput { image, timings })
}

/// Refuse an image holding a non-finite value (any layer but `stderr`, whose standard error of a
/// single sample is undefined and written as inf): an error naming the method and the layer, so
/// a numerical failure never reaches a file as a black, white or NaN pixel.
pub fn check_finite(method: &str, image: &Image) -> Result<()> {
    let layers = std::iter::once(("rgb", image.pixels.as_slice())).chain(
        image
            .layers
            .iter()
            .filter(|(n, _)| n != "stderr")
            .map(|(n, p)| (n.as_str(), p.as_slice())),
    );
    for (name, px) in layers {
        let bad = px.iter().filter(|p| !p.is_finite()).count();
        if let Some(k) = px.iter().position(|p| !p.is_finite()) {
            return Err(Error::Numerical {
                stage: format!("{method} render"),
                message: format!(
                    "{bad} pixels of layer `{name}` are not finite (the first at ({}, {}): {:?}); no image was \
                     written. Please report the scene; another --method may render it meanwhile",
                    k as u32 % image.width,
                    k as u32 / image.width,
                    px[k].to_array()
                ),
            });
        }
    }
    Ok(())
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Rgb;

    #[test]
    fn a_non_finite_pixel_is_an_error_naming_the_method_and_layer() {
        let mut img = Image::new(4, 3);
        assert!(check_finite("full", &img).is_ok());
        img.add_layer("stderr", vec![Rgb::splat(f32::INFINITY); 12]);
        assert!(
            check_finite("reference", &img).is_ok(),
            "one sample's standard error is inf by definition"
        );
        img.add_layer("light_sky", vec![Rgb::ZERO; 12]);
        img.layers[1].1[5] = Rgb::new(0.0, f32::NAN, 0.0);
        let e = check_finite("reference", &img).unwrap_err().to_string();
        assert!(
            e.starts_with("reference render:") && e.contains("`light_sky`") && e.contains("(1, 1)"),
            "{e}"
        );
    }
}
