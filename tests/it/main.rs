//! End-to-end tests through the `cloudgi` binary, one integration-test binary (one link of the
//! crate): one module per subject, shared helpers in [`common`]. Tests of the stages themselves
//! are unit tests in `src/` (`src/tests/` for the end-to-end ones).

mod bad_input;
mod common;
mod diffusion;
mod figures;
mod first_use;
mod reference_cli;
mod sequences;
mod sky;
mod slab;
mod transport;
mod transport_slab;
mod vdb_input;
mod vdb_scene;
/// The test writer of `.vdb` files (empty grids, grids of any name), shared with the unit tests.
#[path = "../../src/medium/vdb/test_file.rs"]
mod vdb_writer;
