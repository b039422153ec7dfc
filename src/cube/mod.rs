//! Viewing cubes (paper sections 3 and 4): radiance images on the six faces of a cube around a
//! point. [`image`] holds the image type shared by the clear-air propagation and the final
//! gather's low-density edges.

pub mod image;

pub use image::CubeImage;
