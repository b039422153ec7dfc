//! A transparent medium (`medium.sigma_t = 0`, or every density zero) is a valid scene: nothing
//! scatters, so every method's image is the background (sky and ground), which the single-
//! scattering march gives exactly. The diffusion solve would divide by the zero extinction.

use super::{single, Progress, Timings};
use crate::error::Result;
use crate::image::Image;
use crate::medium::Medium;
use crate::scene::Scene;

/// True when the medium neither absorbs nor scatters anywhere.
pub fn is_transparent(m: &Medium) -> bool {
    m.optics.sigma_t == 0.0 || m.density.max_value() == 0.0
}

/// The background-only image, with `full`'s AOV layers (all light is background) when asked.
pub fn render(scene: &Scene, progress: &dyn Progress, timings: &mut Timings) -> Result<Image> {
    progress.log("the medium is transparent (sigma_t = 0 or no density): sky and ground only, no solve");
    let mut img = single::render(scene, progress, timings)?;
    if scene.render.aov && scene.render.method == crate::scene::Method::Full {
        let zero = vec![crate::math::Rgb::ZERO; img.pixels.len()];
        for name in ["diffusion", "low_density", "sun_single"] {
            img.add_layer(name, zero.clone());
        }
        let background = img.pixels.clone();
        img.add_layer("background", background);
    }
    Ok(img)
}
