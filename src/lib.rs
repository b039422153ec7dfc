//! cloudgi: physically based cloud rendering after Max et al., "Diffusion and Multiple
//! Anisotropic Scattering for Global Illumination in Clouds" (WSCG 2004).
//!
//! Pipeline: [`scene::Scene`] → [`medium::Medium`] and [`lighting`] → a method in [`render`] →
//! [`image::Image`] (linear HDR) → EXR + tone-mapped PNG.

pub mod camera;
pub mod compare;
pub mod cube;
pub mod diffusion;
pub mod edges;
pub mod error;
pub mod exposure;
pub mod figures;
pub mod half;
pub mod image;
pub mod incident;
pub mod io;
pub mod lighting;
pub mod lit;
pub mod math;
pub mod medium;
pub mod optics;
pub mod orders;
pub mod pipeline;
pub mod reference;
pub mod render;
pub mod scene;
pub mod sunlight;
pub mod transport;

pub use error::{Error, Result};
pub use image::Image;
pub use pipeline::{NoProgress, Progress};
pub use render::{render, RenderOutput};
pub use scene::{Method, Scene, SceneDesc};
