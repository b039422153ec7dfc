//! The participating medium: density grids, their sources, and ray queries.

pub mod grid;

pub use grid::Grid3;
