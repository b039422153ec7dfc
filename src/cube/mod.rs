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

use crate::math::Rgb;
use crate::medium::Grid3;
use crate::render::Progress;
use crate::scene::Scene;

/// What one propagation iteration gets from the cubes.
#[derive(Clone, Debug)]
pub struct ClearAir {
    /// The lit volume, with the ground from its hemicubes (if the scene has a ground).
    pub lit: LitVolume,
    /// The border cubes, rendered over that ground; [`BorderCubes::hook`] is stage 1's hook.
    pub cubes: BorderCubes,
}

/// One iteration's cubes: the lit volume from `scene` with the current `i0` (W·m⁻²·sr⁻¹ per
/// voxel) and `sun_t` (transmittance towards the sun at voxel centres, e.g.
/// [`crate::sunlight::SunTransmittance`]`::compute(..).grid`); the ground's hemicubes first (they
/// look up only), then every border cube with that lit ground behind it. Settings from
/// `scene.render.cubes` (`render.cube_resolution`, `render.ground_samples`).
pub fn clear_air(scene: &Scene, i0: Vec<Rgb>, sun_t: Grid3, progress: &dyn Progress) -> ClearAir {
    let opts = &scene.render.cubes;
    let ground = scene
        .ground
        .as_ref()
        .map(|g| LitGround::unoccluded(g.clone(), &scene.sun, &scene.sky));
    let mut lit = LitVolume::new(scene.medium.clone(), i0, sun_t, scene.sun.clone(), scene.sky.clone(), ground);
    if let Some(g) = &scene.ground {
        let lg = render_ground(&lit, g, opts, progress);
        lit = lit.with_ground(Some(lg));
    }
    let cubes = render_border_cubes(&lit, opts, progress);
    ClearAir { lit, cubes }
}
