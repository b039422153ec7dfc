//! I0 as the eye sees it at the cloud's surface.
//!
//! The discretised Marshak condition (eq. 7, [`super::boundary_terms`]) ties a boundary voxel's
//! centre value I_P to its face through half a voxel of the diffusion profile: the outward flux
//! is φ = (β(I_P − L) + f)/(1 + 2β), β = 2/(3ρσtr h), and the face value is I_face = L + 2φ.
//! In a voxel many optical depths thick, β → 0 and I_P ≈ L + (3/2)ρσtr h φ: the centre lies
//! τ/2 optical depths below a surface the eye cannot see past one. Shown as the surface (the
//! gathers and the clear-air cubes blend I0 from voxel centres), it made a thick cloud as bright
//! as (3/2)τ times its outgoing flux (albedo 1, 40-m voxels: max pixel 1.0·10³ at σt = 100 m⁻¹,
//! 1.0·10⁷ at 10⁶, under a sun giving ≲ 1).
//!
//! [`visible_i0`] gives every boundary voxel the value of its half-cell profile (linear from
//! I_face to I_P) one optical depth ρσt inside each boundary face, averaged over its boundary
//! faces: I_face + (I_P − I_face)·2/(ρσt h). Where a face is at most 2 optical depths thick that
//! depth reaches the centre and the value is I_P unchanged; a band none of whose boundary voxels
//! is thicker keeps its I0 bit for bit.

use super::boundary::face_index;
use super::DiffusionSolution;
use crate::incident::IncidentLight;
use crate::medium::field16::Field16;
use crate::medium::Medium;
use rayon::prelude::*;

/// Optical depth ρσt h of a voxel across a face up to which the eye's mean free path reaches its
/// centre from that face (half the voxel's depth: one optical depth).
const CENTRE_VISIBLE_DEPTH: f64 = 2.0;

/// I0 per band as the eye sees it (module docs): the solution's I0, each boundary voxel more
/// than 2 optical depths thick across a boundary face replaced by its value one optical depth
/// inside that face. `tau_min` is the solve's floor on the transport depth.
pub fn visible_i0(m: &Medium, inc: &IncidentLight, sol: &DiffusionSolution, tau_min: f64) -> [Field16; 3] {
    let rho = &*m.density;
    let sigma_t = m.optics.sigma_t as f64;
    let h = [m.voxel_size.x as f64, m.voxel_size.y as f64, m.voxel_size.z as f64];
    let h_min = h.iter().copied().fold(f64::INFINITY, f64::min);
    if rho.max_value() as f64 * sigma_t * h_min <= CENTRE_VISIBLE_DEPTH {
        return sol.i0.clone();
    }
    let index = m.density.full_index();
    let gd = m.dims();
    let gstride = [1, gd[0], gd[0] * gd[1]];
    let full: Vec<usize> = index.full_voxels().collect();
    std::array::from_fn(|c| {
        let sigma_tr = m.optics.sigma_tr(c);
        let packed: Vec<f32> = full
            .par_iter()
            .enumerate()
            .map(|(r, &idx)| {
                let ip = sol.i0[c].packed_at(r) as f64;
                let sp = index.slot(idx);
                let rp = rho.at_slot(sp) as f64;
                let cell = [idx % gd[0], (idx / gd[0]) % gd[1], idx / (gd[0] * gd[1])];
                let (mut sum, mut faces) = (0.0, 0usize);
                for a in 0..3 {
                    // F = Q1/(ρσtr), the first scattering's part of the flux (eq. 7's f).
                    let fp = inc.scattering.q1_at_slot(a, sp, c) as f64 / (rp * sigma_tr);
                    for side in [-1i64, 1] {
                        let nc = cell[a] as i64 + side;
                        let nidx = (nc >= 0 && nc < gd[a] as i64).then(|| (idx as i64 + side * gstride[a] as i64) as usize);
                        if nidx.is_some_and(|g| index.slot(g) != 0) {
                            continue;
                        }
                        faces += 1;
                        let tau = rp * sigma_t * h[a];
                        if tau <= CENTRE_VISIBLE_DEPTH {
                            sum += ip;
                            continue;
                        }
                        let l = sol.boundary.at(nidx, face_index(a, side), c);
                        let beta = 2.0 / (3.0 * (rp * sigma_tr * h[a]).max(tau_min));
                        let flux = (beta * (ip - l) + fp * side as f64) / (1.0 + 2.0 * beta);
                        let face = l + 2.0 * flux;
                        sum += face + (ip - face) * CENTRE_VISIBLE_DEPTH / tau;
                    }
                }
                if faces == 0 {
                    ip as f32
                } else {
                    (sum / faces as f64) as f32
                }
            })
            .collect();
        let same = packed.iter().enumerate().all(|(r, v)| v.to_bits() == sol.i0[c].packed_at(r).to_bits());
        if same {
            sol.i0[c].clone()
        } else {
            Field16::new(index.clone(), &packed)
        }
    })
}
