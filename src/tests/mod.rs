//! End-to-end tests of the renderer's stages and methods (one module per subject), beside the
//! unit tests in each module; those through the binary are `tests/it/`.

mod anisotropy;
mod bad_input;
pub(crate) mod common;
mod cubes;
mod diffusion;
mod edges;
mod extreme_media;
mod figures;
mod foundation;
mod full;
mod fuzz_stress;
mod methods;
mod nonnegative;
mod phase_sampling;
mod reference;
mod sky;
mod slab;
mod transport;
mod transport_slab;
mod vdb;
mod vdb_scene;
mod warm;
