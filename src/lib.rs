//! cloudgi: physically based cloud rendering after Max et al., "Diffusion and Multiple
//! Anisotropic Scattering for Global Illumination in Clouds" (WSCG 2004).
//!
//! The library's API is what this page lists: a [`Scene`] (from a file with
//! [`Scene::from_file`], TOML text with [`Scene::from_toml`], or a [`SceneDesc`] built in code
//! with [`Scene::from_desc`]), optionally a [`Density`] grid from memory
//! ([`Scene::build_with`]), and [`render`] with [`Options`] (progress, cancellation) giving a
//! [`Render`] (image, AOVs, stats); every failure is an [`Error`].
//!
//! ```
//! use cloudgi::{render, Method, Options, Scene};
//! let scene = Scene::from_toml("[camera]\nwidth = 8\nheight = 6\n[medium]\nresolution = [10, 8, 6]")?;
//! let out = render(&scene, Method::Single, &Options::default())?;
//! assert_eq!(out.image.pixels.len(), 48);
//! # Ok::<(), cloudgi::Error>(())
//! ```
//!
//! Everything else is crate-private: the renderer's stages (one module each), the command line
//! (`src/cli/`, whose only public item is the binary's entry point) and the tools over the
//! renderer (`src/tools/`). The `internals` feature makes the stage modules public (hidden,
//! unstable) for the stage benches, the measurement examples and the fuzz targets.

// Some crate-private items serve only the tests (brute-force references such as
// `render_cube_brute`, accessors the checks read): dead code is what neither the renderer nor a
// test uses, so the lint runs on the test build (`cargo clippy --all-targets`).
#![cfg_attr(not(test), allow(dead_code, unused_imports))]

/// Declares the renderer's stage modules: crate-private, or public (hidden from the docs, no
/// API) with the `internals` feature.
macro_rules! stages {
    ($($name:ident),* $(,)?) => {$(
        #[cfg(feature = "internals")]
        #[doc(hidden)]
        pub mod $name;
        #[cfg(not(feature = "internals"))]
        pub(crate) mod $name;
    )*};
}

stages!(
    camera, cube, diffusion, edges, exposure, half, image, incident, io, lighting, limits, lit, math, medium, optics, peak, pipeline,
    reference, render, scene, sequence, tools, transport,
);

mod api;
#[doc(hidden)]
pub mod cli;
mod error;
mod par;

#[cfg(test)]
mod tests;

pub use crate::api::{
    check_output_file, ignored_settings, render, scene_warnings, Density, Event, FnProgress, Options, Render, Stats, DENSITY_SOURCE,
    TOML_SOURCE,
};
pub use crate::camera::CameraDesc;
pub use crate::error::{Error, Result};
pub use crate::image::Image;
pub use crate::lighting::{GroundDesc, SkyDesc, SkyModel, SunDesc};
pub use crate::math::Rgb;
pub use crate::medium::{MediumDesc, UpAxis, VoxelSize};
pub use crate::pipeline::{NoProgress, Progress, Timings};
pub use crate::scene::{
    AnimationDesc, CameraKey, KeyDesc, MediumKey, Method, RenderDesc, Scene, SceneDesc, SunKey, BUILTIN as BUILTIN_SOURCE,
};
