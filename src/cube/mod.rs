//! Viewing cubes (paper sections 3 and 4): radiance images on the six faces of a cube around a
//! point. [`image`] holds the image type shared by the clear-air propagation and the final
//! gather's low-density edges; [`lit`] the lit volume cubes render; [`pyramid`] its mip pyramid;
//! [`render`] the cone-matched cube renderer (and a brute-force reference); [`border`] the cubes
//! at the cloud's border voxels for stage 1; [`ground`] the ground's hemicubes. See docs/cubes.md.

pub mod border;
pub mod ground;
pub mod image;
pub mod lit;
pub mod pyramid;
pub mod render;

pub use border::{find_border_voxels, render_border_cubes, BorderCubes};
pub use ground::{render_ground, LitGround};
pub use image::CubeImage;
pub use lit::LitVolume;
pub use render::{opposite_bin, render_cube_brute, BinMask, CubeOptions, CubeRenderer};
