//! Exact-in-angle single scattering of the reduced sky and ground light (`render.sky_single_scattering`).
//!
//! The paper's gather scatters the reduced *sun* exactly but leaves out the single scattering of
//! the reduced sky and ground radiance I_ri,sky (eq. 2 for the 96 bins): its source is a·I0, and
//! I0 is the diffuse field, whose own source Q0/Q1 (eqs. 5, 6) is already the *first* scattering
//! of I_ri. The missing term of J (see [`super`]) is
//!
//! ```text
//!   J_ss(X, ω) = a ∫ p(ω′·ω) I_ri,sky(X, ω′) dω′,   ω′ the direction the light travels.
//! ```
//!
//! Nothing is counted twice: the diffuse field I0 + I1·ω holds light scattered at least once
//! (its source is Q0/Q1), so the gather's a·∫p·I_d is orders ≥ 2 towards the eye, and J_ss is
//! order 1; stage 1's Q0/Q1 are unchanged.
//!
//! **Storage.** Stage 1 knows the bin-mean reduced radiance Ī_b per voxel; it projects
//! Σ_b Δω_b Ī_b δ(ω′ − ω_b) onto the 9 real spherical harmonics of degree ≤ 2 (ω_b the bin's mean
//! flow direction), L_lm = Σ_b Δω_b Ī_b Y_lm(ω_b). Funk–Hecke with HG's Legendre coefficients g^l
//! gives J_ss(ω)/a = Σ_l g^l Σ_m L_lm Y_lm(ω): 27 floats per full voxel (9 per band, 108 bytes;
//! empty voxels hold nothing, [`crate::medium::sparse`]).
//! The truncation at l = 2 is exact for g = 0 and smooths the forward lobe of a strongly
//! forward-scattering phase function to degree 2; the sum is clamped at 0 per band. The field is
//! interpolated density-weighted like I0 (trilinear(ρ·L)/trilinear(ρ)).

use crate::math::{sh9, Rgb, Vec3, SH_COEFFS};
use crate::medium::sparse::VoxelField;
use crate::medium::Medium;

/// Degree of each coefficient of [`sh9`].
const DEGREE: [i32; SH_COEFFS] = [0, 1, 1, 1, 2, 2, 2, 2, 2];

/// ρ·g^l·L_lm per voxel and band, interpolated density-weighted; answers J_ss/a at any point.
#[derive(Clone, Debug)]
pub struct SkySingle {
    dims: [usize; 3],
    /// `[voxel][band * 9 + lm]`: ρ·g^l·L_lm (W·m⁻²·sr⁻¹ per unit density), per full voxel.
    rho_coef: VoxelField<[f32; 3 * SH_COEFFS]>,
}

impl SkySingle {
    /// From L_lm per voxel (`[band * 9 + lm]`, W·m⁻²·sr⁻¹, the projection of the reduced sky and
    /// ground radiance; stage 1's [`crate::incident::IncidentLight::sky_sh`]) and the medium
    /// (density and HG g); only the full voxels' values are read.
    pub fn new(m: &Medium, sh: &VoxelField<[f32; 3 * SH_COEFFS]>) -> SkySingle {
        let g = m.optics.phase.mean_cosine() as f32;
        let gl: [f32; SH_COEFFS] = std::array::from_fn(|k| g.powi(DEGREE[k]));
        let rho = &*m.density;
        let rho_coef = VoxelField::from_fn(m.density.full_index(), [0.0; 3 * SH_COEFFS], |n| {
            let c = &sh[n];
            std::array::from_fn(|k| c[k] * gl[k % SH_COEFFS] * rho.at(n))
        });
        SkySingle { dims: m.dims(), rho_coef }
    }

    /// J_ss/a (≥ 0 per band, W·m⁻²·sr⁻¹) at continuous voxel coordinates `v` with trilinear
    /// density `rho`, scattered towards the eye along `to_eye` (unit, the direction it travels).
    #[inline]
    pub fn at_voxel(&self, v: Vec3, rho: f32, to_eye: Vec3) -> Rgb {
        if rho <= 0.0 {
            return Rgb::ZERO;
        }
        let t = crate::math::Trilinear::new(self.dims, v.to_array());
        let [fx, fy, fz] = t.f;
        let y = sh9(to_eye);
        let mut out = [0f32; 3];
        for (corner, &idx) in t.idx.iter().enumerate() {
            let w = (if corner & 1 == 1 { fx } else { 1.0 - fx })
                * (if corner & 2 == 2 { fy } else { 1.0 - fy })
                * (if corner & 4 == 4 { fz } else { 1.0 - fz });
            // An empty corner holds ρ·L = 0.
            let Some(c) = self.rho_coef.get_full(idx).filter(|_| w != 0.0) else {
                continue;
            };
            for (b, o) in out.iter_mut().enumerate() {
                let s: f32 = (0..SH_COEFFS).map(|k| c[b * SH_COEFFS + k] * y[k]).sum();
                *o += w * s;
            }
        }
        Rgb::from_array(out).max(Rgb::ZERO) / rho
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::bins::DirectionBins;

    /// Projecting the 96 bins of a radiance L(ω′) = 1 + ω′·x̂ and convolving with HG reproduces
    /// ∫p L = 1 + g ω·x̂ (degree ≤ 1 is held exactly up to the bins' quadrature).
    #[test]
    fn bins_projected_and_convolved_give_the_hg_integral() {
        let bins = DirectionBins::new();
        let mut c = [0f32; SH_COEFFS];
        for b in &bins.bins {
            let d = b.mean_dir.normalize();
            let l = 1.0 + d.x;
            let y = sh9(d);
            for k in 0..SH_COEFFS {
                c[k] += (b.solid_angle as f32) * l * y[k];
            }
        }
        let g = 0.6f32;
        for w in [Vec3::X, -Vec3::X, Vec3::Y, Vec3::new(0.6, 0.0, 0.8)] {
            let y = sh9(w);
            let j: f32 = (0..SH_COEFFS).map(|k| g.powi(DEGREE[k]) * c[k] * y[k]).sum();
            let want = 1.0 + g * w.x;
            assert!((j - want).abs() < 0.02, "{w:?}: {j} vs {want}");
        }
    }
}
