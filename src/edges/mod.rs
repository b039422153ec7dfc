//! Multiple anisotropic scattering at the cloud's edges (paper section 4, with the fixes its
//! section 6 asks for): low-density segments along each viewing ray, Poisson-weighted orders of
//! Henyey–Greenstein scattering over a view-aligned cube, and a front-to-back gather that blends
//! them with the dense (diffusion) solution. See `docs/edges.md`.

pub mod escape;
pub mod gather;
pub(crate) mod orders;
pub mod orders_kernel;
pub mod segments;
pub mod sparse;
pub mod tube;

pub use gather::{CubeRequest, CubeSource, EdgeGather, EdgeSettings, SunInput};
pub use orders_kernel::segment_orders;
pub use sparse::{gather_image, PixelRay, SparseSettings};
