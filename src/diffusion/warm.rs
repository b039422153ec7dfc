//! Warm starts of the diffusion solve across a sequence's frames (`diffusion` and `full`): the
//! previous frame's I0 (`diffusion`: the converged solution; `full`: its first solve's, without
//! the clear-air light) is carried to the next frame's full voxels by world position
//! ([`FullVoxelPlacement::values_at`]: trilinear over the old full voxels; a voxel new to the
//! cloud from its neighbours), and the solve runs from it to the same relative residual as a
//! cold solve (docs/sequences.md, "Warm starts").

use super::DiffusionSolution;
use crate::medium::field16::Field16;
use crate::medium::remap::FullVoxelPlacement;
use crate::medium::Medium;

/// What a frame's solve starts from and whether it keeps its own solution for the next frame.
#[derive(Clone, Copy, Debug, Default)]
pub struct WarmSolve<'a> {
    /// A previous frame's converged state (None: the cold start, zero).
    pub start: Option<&'a DiffusionState>,
    /// Hand back this frame's converged state.
    pub keep: bool,
}

/// A converged diffusion solution, kept for the next frame's start.
#[derive(Clone, Debug)]
pub struct DiffusionState {
    placement: FullVoxelPlacement,
    /// I0 per full voxel in grid order, three bands each (W·m⁻²·sr⁻¹).
    i0: Vec<f32>,
}

impl DiffusionState {
    /// The state of `sol`, solved on `m`.
    pub fn new(m: &Medium, sol: &DiffusionSolution) -> DiffusionState {
        let bands = sol.i0.each_ref().map(Field16::decoded);
        DiffusionState {
            placement: FullVoxelPlacement::of(m),
            i0: (0..bands[0].len()).flat_map(|v| bands.iter().map(move |b| b[v])).collect(),
        }
    }

    /// The start of a solve on `m`: I0 per band on its full voxels.
    pub fn start(&self, m: &Medium) -> [Field16; 3] {
        let index = m.density.full_index();
        let i0 = self.placement.values_at(&self.i0, 3, m);
        [0, 1, 2].map(|b| {
            let band: Vec<f32> = i0.iter().skip(b).step_by(3).copied().collect();
            Field16::new(index.clone(), &band)
        })
    }

    /// Bytes held: I0 and the old grid's occupancy.
    pub fn bytes(&self) -> usize {
        4 * self.i0.len() + self.placement.bytes()
    }

    /// Bytes a state of `full_voxels` full voxels on a grid of `grid_voxels` holds.
    pub fn bytes_for(full_voxels: u64, grid_voxels: u64) -> u64 {
        12 * full_voxels + grid_voxels.div_ceil(4)
    }
}
