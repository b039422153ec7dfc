//! Viewing cubes (paper sections 3 and 4): radiance images on the six faces of a cube around a
//! point. [`image`] holds the image type shared by the clear-air propagation and the final
//! gather's low-density edges; [`render`] the cone-matched cube renderer over the lit volume's
//! pyramid ([`crate::lit`]) (and a brute-force reference); [`border`] the cubes
//! at the cloud's border voxels for stage 1; [`ground`] the ground's hemicubes. See docs/cubes.md.

pub mod border;
pub mod ground;
pub mod ground_peak;
pub mod image;
pub mod refine;
pub mod render;
pub mod skip;

pub use border::BorderCubes;
pub use image::CubeImage;
pub use render::{opposite_bin, CubeOptions, CubeRenderer, LevelTables};

use crate::error::{check, Result};
use crate::lighting::Ground;
use crate::lit::LitVolume;
use crate::math::Rgb;
use crate::pipeline::Progress;

/// The clear-air loop of `full` (paper section 3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClearAirSettings {
    /// Most propagation iterations (`render.iterations`; 0: diffusion plus edges only, paper
    /// Fig. 6). Default 1: on the default scene the first changes I0 by 2.5 %, the second by
    /// 0.03 % (images within 4·10⁻⁴ mean relative difference), as the paper found.
    pub iterations: usize,
    /// Stop once I0 changes by less than this fraction (`render.propagation_tolerance`, unitless).
    pub propagation_tolerance: f64,
}

impl Default for ClearAirSettings {
    fn default() -> Self {
        ClearAirSettings {
            iterations: 1,
            propagation_tolerance: 0.01,
        }
    }
}

impl ClearAirSettings {
    /// Check the settings; `file` names the scene file for messages.
    pub fn validate(&self, file: &str) -> Result<()> {
        check(
            file,
            "render.iterations",
            self.iterations <= 20,
            self.iterations,
            "the clear-air iterations are a count from 0 to 20 (the paper found 1 enough)",
        )?;
        check(
            file,
            "render.propagation_tolerance",
            self.propagation_tolerance.is_finite() && self.propagation_tolerance >= 0.0,
            self.propagation_tolerance,
            "the propagation tolerance is a relative change ≥ 0, e.g. 0.01",
        )
    }
}

/// What one propagation iteration gets from the cubes.
#[derive(Clone, Debug)]
pub struct ClearAir {
    /// The lit volume, with the ground from its hemicubes (if the scene has a ground).
    pub lit: LitVolume,
    /// What the border cubes, rendered over that ground, keep.
    pub border: BorderLight,
}

/// What is kept of the border cubes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BorderKeep {
    /// Every cube's needed bins: stage 1's hook ([`BorderCubes::hook`]).
    Bins,
    /// Only the light each cube sends through its faces into the cloud
    /// ([`border::render_border_face_light_with`]): the boundary condition's.
    FaceLight,
}

/// The border cubes' light, as [`BorderKeep`] asked.
#[derive(Clone, Debug)]
pub enum BorderLight {
    Bins(BorderCubes),
    /// The number of cubes, and (border voxel's grid index, the full voxel's face, L_face) per
    /// face between them and the cloud.
    FaceLight(usize, Vec<(usize, usize, Rgb)>),
}

impl BorderLight {
    /// Number of border cubes rendered.
    pub fn cubes(&self) -> usize {
        match self {
            BorderLight::Bins(c) => c.len(),
            BorderLight::FaceLight(n, _) => *n,
        }
    }
}

/// One iteration's cubes over `lit` (the current I0, its ground unoccluded): the ground's
/// hemicubes first (they look up only), then every border cube with that lit ground behind it,
/// of which `keep` is kept. Both render through the lit volume's one pyramid. `opts`:
/// `render.cube_resolution`, `render.ground_samples`.
pub fn clear_air(lit: LitVolume, ground: Option<&Ground>, opts: &CubeOptions, keep: BorderKeep, progress: &dyn Progress) -> ClearAir {
    let mut lit = lit;
    // The lit ground keeps the pyramid: one set of level tables for both renderers.
    let tables = LevelTables::new(&lit, opts);
    if let Some(g) = ground {
        let renderer = ground::ground_renderer(&lit, opts, tables.clone());
        let lg = ground::render_ground_with(&renderer, g, progress);
        lit = lit.with_ground(Some(lg));
    }
    let renderer = border::border_renderer(&lit, opts, tables);
    let border = match keep {
        BorderKeep::Bins => BorderLight::Bins(border::render_border_cubes_with(&renderer, progress)),
        BorderKeep::FaceLight => {
            let (n, light) = border::render_border_face_light_with(&renderer, progress);
            BorderLight::FaceLight(n, light)
        }
    };
    drop(renderer);
    ClearAir { lit, border }
}
