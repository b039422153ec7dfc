//! cloudgi: physically based cloud rendering after Max et al., "Diffusion and Multiple
//! Anisotropic Scattering for Global Illumination in Clouds" (WSCG 2004).

pub mod error;
pub mod medium;

pub use error::{Error, Result};
