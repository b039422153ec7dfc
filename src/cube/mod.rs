//! Viewing cubes (paper sections 3 and 4): radiance images on the six faces of a cube around a
//! point. [`image`] holds the image type shared by the clear-air propagation and the final
//! gather's low-density edges; [`lit`] the lit volume cubes render; [`pyramid`] its mip pyramid;
//! [`render`] the cone-matched cube renderer (and a brute-force reference); [`border`] the cubes
//! at the cloud's border voxels for stage 1; [`ground`] the ground's hemicubes. See docs/cubes.md.

pub mod border;
pub mod ground;
pub mod image;
pub mod render;

pub use border::{find_border_voxels, render_border_cubes, BorderCubes};
pub use ground::{render_ground, LitGround};
pub use image::CubeImage;
pub use render::{opposite_bin, render_cube_brute, BinMask, CubeOptions, CubeRenderer};

use crate::lighting::Ground;
use crate::lit::LitVolume;
use crate::pipeline::Progress;

/// Default cap on clear-air iterations: on the default scene the first changes I0 by 2.5 %, the
/// second by 0.03 % (images within 4·10⁻⁴ mean relative difference), as the paper found.
pub const DEFAULT_ITERATIONS: usize = 1;
/// Default stopping threshold on the relative change of I0 between iterations.
pub const DEFAULT_PROPAGATION_TOLERANCE: f64 = 0.01;

/// What one propagation iteration gets from the cubes.
#[derive(Clone, Debug)]
pub struct ClearAir {
    /// The lit volume, with the ground from its hemicubes (if the scene has a ground).
    pub lit: LitVolume,
    /// The border cubes, rendered over that ground; [`BorderCubes::hook`] is stage 1's hook.
    pub cubes: BorderCubes,
}

/// One iteration's cubes over `lit` (the current I0, its ground unoccluded): the ground's
/// hemicubes first (they look up only), then every border cube with that lit ground behind it.
/// Both render through the lit volume's one pyramid. `opts`: `render.cube_resolution`,
/// `render.ground_samples`.
pub fn clear_air(lit: LitVolume, ground: Option<&Ground>, opts: &CubeOptions, progress: &dyn Progress) -> ClearAir {
    let mut lit = lit;
    if let Some(g) = ground {
        let lg = render_ground(&lit, g, opts, progress);
        lit = lit.with_ground(Some(lg));
    }
    let cubes = render_border_cubes(&lit, opts, progress);
    ClearAir { lit, cubes }
}
