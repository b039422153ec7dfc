//! I0 as the eye sees it at the cloud's surface.
//!
//! The discretised Marshak condition (eq. 7, [`super::boundary_terms`]) ties a boundary voxel's
//! centre value I_P to its face through half a voxel of the diffusion profile: the outward flux
//! is φ = (β(I_P − L) + f)/(1 + 2β), β = 2/(3ρσtr h), and the face value is I_face = L + 2φ.
//! In a voxel many optical depths thick, β → 0 and I_P ≈ L + (3/2)ρσtr h φ: the centre lies
//! τ/2 optical depths below a surface the eye cannot see past one. Shown as the surface (the
//! gathers and the clear-air cubes blend I0 from voxel centres), it would make a thick cloud as bright
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
use crate::par::{self, CHUNK};

/// Optical depth ρσt h of a voxel across a face up to which the eye's mean free path reaches its
/// centre from that face (half the voxel's depth: one optical depth).
const CENTRE_VISIBLE_DEPTH: f64 = 2.0;

/// Optical depth ρσt h of a voxel past which the eye, having crossed it, sees nothing of the
/// voxels behind (transmittance e⁻²⁰ = 2·10⁻⁹).
const HIDDEN_DEPTH: f64 = 20.0;

/// `values` with every voxel for which `kept` is false replaced, layer by layer inwards from the
/// kept ones, by the mean of its face neighbours of the layer before: the voxels inside a cloud
/// of voxels more than [`HIDDEN_DEPTH`] thick show the surface's value. No gather can see them
/// through such voxels, but one whose sample falls deeper than the first voxel (the edge
/// gather's coarser step, a clear-air cube's trilinear blend) would show their I0, which grows
/// as (3/2)τ times the surface's. `slot(g)`: the 1-based full-voxel index of grid voxel g, 0 if
/// empty; `full`: the full voxels' grid indices.
fn fill_hidden(
    values: &[f32],
    full: &[usize],
    gd: [usize; 3],
    kept: impl Fn(usize) -> bool + Sync,
    slot: impl Fn(usize) -> usize,
) -> Vec<f32> {
    let mut out = values.to_vec();
    let mut done: Vec<bool> = par::map_items(full.len(), CHUNK, &kept);
    let neighbours = |r: usize| {
        let g = full[r];
        let c = [g % gd[0], (g / gd[0]) % gd[1], g / (gd[0] * gd[1])];
        let stride = [1, gd[0], gd[0] * gd[1]];
        (0..6).filter_map(move |q| {
            let (a, up) = (q / 2, q % 2 == 1);
            let ok = if up { c[a] + 1 < gd[a] } else { c[a] > 0 };
            ok.then(|| if up { g + stride[a] } else { g - stride[a] })
        })
    };
    let mut layer: Vec<usize> = (0..full.len()).filter(|r| done[*r]).collect();
    while !layer.is_empty() {
        let mut next: Vec<usize> = layer
            .iter()
            .flat_map(|r| neighbours(*r).map(&slot).filter(|s| *s != 0).map(|s| s - 1).collect::<Vec<_>>())
            .filter(|r| !done[*r])
            .collect();
        next.sort_unstable();
        next.dedup();
        let vals: Vec<f32> = next
            .iter()
            .map(|r| {
                let (sum, n) = neighbours(*r)
                    .map(&slot)
                    .filter(|s| *s != 0 && done[*s - 1])
                    .fold((0.0, 0usize), |(a, n), s| (a + out[s - 1] as f64, n + 1));
                (sum / n.max(1) as f64) as f32
            })
            .collect();
        for (r, v) in next.iter().zip(vals) {
            out[*r] = v;
            done[*r] = true;
        }
        layer = next;
    }
    out
}

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
        let packed: Vec<f32> = par::map_items(full.len(), CHUNK, &|r| {
            let idx = full[r];
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
        });
        // A thick voxel with no boundary face but an empty voxel among its 26 neighbours (in a
        // concave corner or along an edge of the surface) lies inside the trilinear blend the eye
        // samples there: it takes the mean of its boundary face-neighbours' visible values.
        let first = packed;
        let packed: Vec<f32> = par::map_items(full.len(), CHUNK, &|r| {
            let idx = full[r];
            let cell = [idx % gd[0], (idx / gd[0]) % gd[1], idx / (gd[0] * gd[1])];
            let neighbour = |d: [i64; 3]| -> Option<usize> {
                let c: Vec<i64> = (0..3).map(|a| cell[a] as i64 + d[a]).collect();
                (0..3)
                    .all(|a| c[a] >= 0 && c[a] < gd[a] as i64)
                    .then(|| (0..3).map(|a| c[a] as usize * gstride[a]).sum())
            };
            let is_full = |d: [i64; 3]| neighbour(d).is_some_and(|g| index.slot(g) != 0);
            let offsets = (-1..=1).flat_map(|z| (-1..=1).flat_map(move |y| (-1..=1).map(move |x| [x, y, z])));
            let axis = |a: usize, side: i64| std::array::from_fn(|k| if k == a { side } else { 0 });
            let faces: Vec<[i64; 3]> = (0..3).flat_map(|a| [axis(a, -1), axis(a, 1)]).collect();
            let thick = rho.at_slot(index.slot(idx)) as f64 * sigma_t * h_min > CENTRE_VISIBLE_DEPTH;
            if !thick || !faces.iter().all(|d| is_full(*d)) || offsets.clone().all(is_full) {
                return first[r];
            }
            // Face neighbours with a boundary face of their own.
            let (mut sum, mut n) = (0.0, 0usize);
            for d in &faces {
                let g = neighbour(*d).unwrap_or(idx);
                let on_surface = faces.iter().any(|e| {
                    let gc = [g % gd[0], (g / gd[0]) % gd[1], g / (gd[0] * gd[1])];
                    let c: Vec<i64> = (0..3).map(|a| gc[a] as i64 + e[a]).collect();
                    !(0..3).all(|a| c[a] >= 0 && c[a] < gd[a] as i64)
                        || index.slot((0..3).map(|a| c[a] as usize * gstride[a]).sum()) == 0
                });
                if on_surface {
                    sum += first[index.slot(g) - 1] as f64;
                    n += 1;
                }
            }
            if n == 0 {
                first[r]
            } else {
                (sum / n as f64) as f32
            }
        });
        let packed = fill_hidden(
            &packed,
            &full,
            gd,
            |r| {
                let idx = full[r];
                let boundary = (0..3).any(|a| {
                    let c = [idx % gd[0], (idx / gd[0]) % gd[1], idx / (gd[0] * gd[1])][a];
                    [-1i64, 1].iter().any(|side| {
                        let nc = c as i64 + side;
                        !(nc >= 0 && nc < gd[a] as i64) || index.slot((idx as i64 + side * gstride[a] as i64) as usize) == 0
                    })
                });
                boundary || packed[r] != first[r] || (rho.at_slot(r + 1) as f64) * sigma_t * h_min <= HIDDEN_DEPTH
            },
            |g| index.slot(g),
        );
        let same = packed
            .iter()
            .enumerate()
            .all(|(r, v)| v.to_bits() == sol.i0[c].packed_at(r).to_bits());
        if same {
            sol.i0[c].clone()
        } else {
            Field16::new(index.clone(), &packed)
        }
    })
}
