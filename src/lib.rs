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
//! The modules below the API (hidden from these docs) are the renderer's stages, public only so
//! that the command line (`src/cli/`) and the integration tests in `tests/` can reach them; they
//! are not a stable API.

mod api;
#[doc(hidden)]
pub mod camera;
#[doc(hidden)]
pub mod compare;
#[doc(hidden)]
pub mod cube;
#[doc(hidden)]
pub mod diffusion;
#[doc(hidden)]
pub mod edges;
pub mod error;
#[doc(hidden)]
pub mod exposure;
#[doc(hidden)]
pub mod figures;
pub(crate) mod half;
#[doc(hidden)]
pub mod image;
#[doc(hidden)]
pub mod incident;
#[doc(hidden)]
pub mod io;
#[doc(hidden)]
pub mod lighting;
#[doc(hidden)]
pub mod limits;
#[doc(hidden)]
pub mod lit;
#[doc(hidden)]
pub mod math;
#[doc(hidden)]
pub mod medium;
#[doc(hidden)]
pub mod optics;
pub(crate) mod orders;
pub(crate) mod peak;
pub(crate) mod pipeline;
#[doc(hidden)]
pub mod reference;
#[doc(hidden)]
pub mod render;
#[doc(hidden)]
pub mod scene;
#[doc(hidden)]
pub mod sequence;
#[doc(hidden)]
pub mod sunlight;
#[doc(hidden)]
pub mod transport;

pub use api::{render, Density, Event, FnProgress, Options, Render, Stats, DENSITY_SOURCE, TOML_SOURCE};
pub use error::{Error, Result};
pub use image::Image;
pub use pipeline::{NoProgress, Progress, Timings};
pub use scene::{Method, Scene, SceneDesc};
