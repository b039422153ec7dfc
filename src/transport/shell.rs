//! The shell: the empty voxels beside the full ones (every empty voxel among a full voxel's 26
//! neighbours), where the gather's trilinear interpolation meets the cloud's edge. The
//! iteration keeps moments at full voxels only; after it converges, one more sweep of every
//! ordinate records the radiance at the shell's centres too (the sweeps step those cells anyway:
//! a shell cell steps as an empty one, [`SHELL`](super::grid::SHELL), so the full voxels' radiance
//! is the iteration's) and takes its moments. The gather interpolates the source per unit
//! optical depth, J = a′χ′_l I_lm Y_lm, over full and shell corners: the radiance is continuous
//! across the edge, so J is, while ρ·J falls to 0 with ρ.

use super::grid::{box_cells, cross_axes, full_spans, Ctx};
use super::ground::GroundMap;
use super::source::PairTables;
use super::sphere::Quadrature;
use super::sweep::{sweep, BatchArrays};
use crate::medium::sparse::FullIndex;
use std::sync::Arc;

/// The shell voxels: their occupancy index (a grid voxel's slot is 1 + its index among the shell
/// voxels, 0 elsewhere) and their grid indices in grid order.
#[derive(Clone, Debug)]
pub struct Shell {
    pub index: Arc<FullIndex>,
    pub voxels: Vec<usize>,
}

impl Shell {
    /// No shell (a live view's iterate: the gather interpolates over full voxels only).
    pub fn none() -> Shell {
        Shell {
            index: Arc::new(FullIndex::build([0, 0, 0], &[])),
            voxels: Vec::new(),
        }
    }

    /// The shell of the full voxels of `full`.
    pub fn of(full: &FullIndex) -> Shell {
        let d = full.dims();
        let mut mark = vec![0f32; full.len()];
        for g in full.full_voxels() {
            let c = [g % d[0], (g / d[0]) % d[1], g / (d[0] * d[1])];
            for n in 0..27 {
                let e = [n % 3, (n / 3) % 3, n / 9];
                // c + e − 1 inside the grid.
                if (0..3).any(|a| c[a] + e[a] == 0 || c[a] + e[a] > d[a]) {
                    continue;
                }
                let v = (c[0] + e[0] - 1) + d[0] * ((c[1] + e[1] - 1) + d[1] * (c[2] + e[2] - 1));
                if !full.is_full(v) {
                    mark[v] = 1.0;
                }
            }
        }
        let index = FullIndex::build(d, &mark);
        let voxels = index.full_voxels().collect();
        Shell {
            index: Arc::new(index),
            voxels,
        }
    }

    /// Shell voxels.
    pub fn len(&self) -> usize {
        self.voxels.len()
    }

    /// True without shell voxels.
    pub fn is_empty(&self) -> bool {
        self.voxels.is_empty()
    }

    /// The shell slot of grid voxel `g` (0: not in the shell, or no shell; else 1 + its index).
    #[inline(always)]
    pub fn slot(&self, g: usize) -> usize {
        if self.voxels.is_empty() {
            0
        } else {
            self.index.slot(g)
        }
    }
}

/// What the gather reads at the shell's voxels: like [`super::solve::TransportField`]'s at the
/// full ones, the diffuse source a′χ′_l I_lm per shell voxel, band and lm (real_sh's order), and
/// the δ-M sun transmittance T′ per shell voxel's centre and band.
#[derive(Clone, Debug)]
pub struct ShellSource {
    pub shell: Shell,
    pub diffuse_source: Vec<f32>,
    pub sun_t: Vec<[f32; 3]>,
}

impl ShellSource {
    /// No shell ([`Shell::none`]).
    pub fn none() -> ShellSource {
        ShellSource {
            shell: Shell::none(),
            diffuse_source: Vec::new(),
            sun_t: Vec::new(),
        }
    }
}

/// The moments I_lm (solver order, per shell voxel and band) at the centres of `shell`'s voxels:
/// one sweep of every ordinate from the converged `moments` (per full voxel), with the sweeps'
/// context `c` and tables `t`. `moments` and `spare` (as long) are the iteration's arrays, grown
/// here by the shell's share; `moments` comes back as it went in.
pub(super) fn shell_moments(
    c: &Ctx,
    shell: &Shell,
    q: &Quadrature,
    t: &PairTables,
    moments: &mut Vec<f32>,
    mut spare: Vec<f32>,
    ground: &GroundMap,
) -> Vec<f32> {
    let nfull = c.voxels.len();
    let per = moments.len() / nfull.max(1);
    let total = nfull + shell.len();
    let voxels: Vec<usize> = c.voxels.iter().chain(&shell.voxels).copied().collect();
    // The shell cells' sources are never read (they step as empty cells).
    let sun_t: Vec<[f32; 3]> = c.sun_t.iter().copied().chain(std::iter::repeat_n([0f32; 3], shell.len())).collect();
    let cells = [0, 1, 2].map(|a| box_cells(c.dims, c.lo, c.n, c.rho, c.full, Some(&shell.index), total, a));
    let spans = [0, 1, 2].map(|a| full_spans(&cells[a], c.n[cross_axes(a).0]));
    let ext = Ctx {
        voxels: &voxels,
        sun_t: &sun_t,
        cells,
        spans,
        ..*c
    };
    moments.resize(total * per, 0.0);
    spare.resize(total * per, 0.0);
    let mut batch = BatchArrays::new(total);
    sweep(&ext, q, t, moments, &mut spare, ground, &mut batch);
    moments.truncate(nfull * per);
    spare.drain(..nfull * per);
    spare
}
