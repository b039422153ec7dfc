//! The first moment I1 of the diffuse field (eq. 3: I_d(ω) = I0 + I1·ω, ω the direction the light
//! travels) and the anisotropic part of the diffuse in-scattering it gives the final gather
//! (`render.diffuse_anisotropy`).
//!
//! **In-scattering.** With the HG phase function normalised to 1 and ∫p(ω′·ω) ω′ dω′ = g ω, the
//! diffuse radiance scattered towards the eye (ω = direction to the eye) per unit extinction is
//!
//! ```text
//!   J_d(ω) = a ∫ p(ω′·ω) (I0 + I1·ω′) dω′ = a (I0 + g I1·ω)
//! ```
//!
//! clamped at 0 per band (the P1 field can exceed its isotropic part where I0 is small).
//!
//! **I1 from the solver's own fluxes.** The scheme of [`super`] computes the outward flux
//! φ_f = I1·n/3 through every face of a full voxel: −D_f (I_N − I_P)/h + F_f·n on an interior face
//! (with the τ_min floor in D_f), the Marshak flux (β (I_P − L_face) + f)/(1 + 2β) on a boundary face
//! (L_face the incoming light of [`super::boundary`], zero in the paper's eq. 7). The
//! voxel-centre I1 on axis a is the mean of its two faces: I1_a = 3 (φ_+ − φ_−)/2. Away from
//! boundaries and the floor this is the central difference of Fick's law,
//! I1 = (−∇I0 + 3 Q1)/(ρσtr), with ∇I0 ≈ (I_{+1} − I_{−1})/(2h) and Q1 the mean of the
//! neighbours' F = Q1/(ρσtr); at a boundary face it uses the same ghost value as the solve. I1 is
//! zero where ρ = 0, and is interpolated density-weighted like I0: trilinear(ρ I1)/trilinear(ρ).
//!
//! **I0 in 16 bits.** The solution keeps I0 rounded to ≤ 2⁻¹² relative
//! ([`crate::medium::field16::Field16`]), and I1 is made of its differences: an interior face's
//! −D_f (I_N − I_P)/h moves by at most D_f/h·2⁻¹²(|I_N| + |I_P|), i.e. I1 by about
//! 2⁻¹¹·I0/τ_tr with τ_tr = ρσtr·h (floored at τ_min) the voxel's transport depth. That is small
//! against I1 where the gradient is resolved, and can be a large part of it only where I0 is
//! nearly flat over optically thin voxels, whose ρ-weighted contribution is small. Measured on the
//! default cloud at 200×160×120 with everything else equal: the images of `full` moved by a block
//! mean relative error of 3·10⁻⁶ (I0's rounding, its warm start and the solver's 16-bit residual
//! together).
//!
//! **Storage.** The lit volume keeps ρ·I1 in bf16 ([`CodedFlux`], 18 B per full voxel instead of
//! 36: it lives through the final gather of `full`): f32's range, so any irradiance scale fits,
//! and rounding ≤ 2⁻⁸ per component, unbiased, which moves the images by ≤ 2e-6 block mean
//! relative error on the evaluation scenes. The `diffusion` gather's records take I1 in f32.

use super::boundary::face_index;
use super::{boundary_terms, interior_coupling, DiffusionSolution};
use crate::half::Bf16;
use crate::incident::IncidentLight;
use crate::math::{Rgb, Trilinear, Vec3};
use crate::medium::sparse::VoxelField;
use crate::medium::Medium;
use std::sync::Arc;

/// I1 per band (`[band]` a vector, W·m⁻²·sr⁻¹) at full voxel `idx` (grid index), from the
/// solver's fluxes (module docs): a function, not a stored field, so each consumer keeps only
/// what it stores (the lit volume's ρ·I1 in 16 bits, the `diffusion` gather's records) and no
/// 36 B-per-voxel array of I1 is ever alive.
pub fn diffuse_flux<'a>(
    m: &'a Medium,
    inc: &'a IncidentLight,
    sol: &'a DiffusionSolution,
    tau_min: f64,
) -> impl Fn(usize) -> [Vec3; 3] + Sync + 'a {
    let d = m.dims();
    let rho = &*m.density;
    let h = [m.voxel_size.x as f64, m.voxel_size.y as f64, m.voxel_size.z as f64];
    let stride = [1usize, d[0], d[0] * d[1]];
    let sigma_tr: [f64; 3] = std::array::from_fn(|c| m.optics.sigma_tr(c));
    let index = m.density.full_index();
    let scattering = &inc.scattering;
    assert!(
        Arc::ptr_eq(scattering.index(), &index) && sol.i0.iter().all(|f| Arc::ptr_eq(f.index(), &index)),
        "stage 1's and the diffusion's fields are on the density's full voxels"
    );
    move |idx| {
        let cell = [idx % d[0], (idx / d[0]) % d[1], idx / (d[0] * d[1])];
        // The slots of the voxel and its six neighbours (0: empty or beyond the grid, which reads
        // ρ = 0), looked up once for ρ, Q1 and I0 of every band.
        let sp = index.slot(idx);
        let rp = rho.at_slot(sp) as f64;
        let nbr: [[(Option<usize>, usize); 2]; 3] = std::array::from_fn(|ax| {
            [-1i64, 1].map(|side| {
                let nc = cell[ax] as i64 + side;
                let nidx = (nc >= 0 && nc < d[ax] as i64).then(|| (idx as i64 + side * stride[ax] as i64) as usize);
                (nidx, nidx.map_or(0, |q| index.slot(q)))
            })
        });
        let mut out = [Vec3::ZERO; 3];
        for (c, o) in out.iter_mut().enumerate() {
            let s = sigma_tr[c];
            let i0 = &sol.i0[c];
            let ip = f64::from(i0.at_slot(sp));
            let f_at = |q: usize, ax: usize| scattering.q1_at_slot(ax, q, c) as f64 / (rho.at_slot(q) as f64 * s);
            let mut v = [0f64; 3];
            for ax in 0..3 {
                let fp = f_at(sp, ax);
                let mut phi = [0f64; 2];
                for (t, side) in [-1i64, 1].into_iter().enumerate() {
                    let (nidx, sq) = nbr[ax][t];
                    let rn = rho.at_slot(sq) as f64;
                    phi[t] = if rn > 0.0 {
                        let cf = interior_coupling(rp, rn, s, h[ax], tau_min);
                        let ff = 0.5 * (fp + f_at(sq, ax));
                        -cf * h[ax] * (f64::from(i0.at_slot(sq)) - ip) + ff * side as f64
                    } else {
                        let (dt, ft) = boundary_terms(rp, s, h[ax], tau_min);
                        let l_in = sol.boundary.at(nidx, face_index(ax, side), c);
                        h[ax] * (dt * (ip - l_in) + ft * fp * side as f64)
                    };
                }
                // φ_+ = I1_a/3 through the + face, φ_− = −I1_a/3 through the − face.
                v[ax] = 1.5 * (phi[1] - phi[0]);
            }
            *o = Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32);
        }
        out
    }
}

/// ρ·I1 of one voxel in bf16, `[band][axis]` (18 B; [`crate::half`]: relative rounding ≤ 2⁻⁸
/// per component, any irradiance scale).
pub type CodedFlux = [[Bf16; 3]; 3];

/// The zero of [`CodedFlux`] (the empty voxels' value).
pub const CODED_ZERO: CodedFlux = [[Bf16::ZERO; 3]; 3];

/// `v` (`[band]`) in bf16.
#[inline]
pub fn encode_flux(v: [Vec3; 3]) -> CodedFlux {
    v.map(|b| [Bf16::from_f32(b.x), Bf16::from_f32(b.y), Bf16::from_f32(b.z)])
}

/// One band's vector of a [`CodedFlux`].
#[inline(always)]
pub fn decode_band(c: &[Bf16; 3]) -> Vec3 {
    Vec3::new(c[0].to_f32(), c[1].to_f32(), c[2].to_f32())
}

/// ρ·I1 per full voxel, interpolated density-weighted; answers g·I1·ω at any point.
#[derive(Clone, Debug)]
pub struct FluxField {
    dims: [usize; 3],
    /// ρ·I1 per voxel, `[band]`, in bf16 (zero, and not stored, where ρ = 0).
    rho_i1: VoxelField<CodedFlux>,
    /// HG mean cosine of the medium.
    g: f32,
}

impl FluxField {
    /// From I1 at each full voxel (`i1(grid index)`, [`diffuse_flux`]) and the medium it was
    /// computed on: ρ·I1 rounded once to bf16 as it is made (no f32 copy: 36 B per full voxel at
    /// `full`'s last peak; the bf16 field is 18 B).
    pub fn new(m: &Medium, i1: impl Fn(usize) -> [Vec3; 3] + Sync) -> FluxField {
        let rho = &*m.density;
        let rho_i1 = VoxelField::from_fn(m.density.full_index(), CODED_ZERO, |g| {
            let r = rho.at(g);
            encode_flux(i1(g).map(|v| v * r))
        });
        FluxField {
            dims: m.dims(),
            rho_i1,
            g: m.optics.phase.mean_cosine() as f32,
        }
    }

    /// ρ·I1 per full voxel (`[band]`, bf16), for coarser copies (the viewing cubes' pyramid
    /// levels).
    pub fn rho_i1(&self) -> &VoxelField<CodedFlux> {
        &self.rho_i1
    }

    /// The HG mean cosine g the in-scattering g·I1·ω uses.
    pub fn g(&self) -> f32 {
        self.g
    }

    /// I1 per band at continuous voxel coordinates `v` where the trilinear density is `rho`.
    #[inline]
    pub fn i1_at_voxel(&self, v: Vec3, rho: f32) -> [Vec3; 3] {
        if rho <= 0.0 {
            return [Vec3::ZERO; 3];
        }
        let f = &self.rho_i1;
        let t = f.slots(&Trilinear::new(self.dims, v.to_array()));
        let s: [Vec3; 3] = std::array::from_fn(|c| t.blend(|q| decode_band(&f.at_slot(q)[c])));
        [s[0] / rho, s[1] / rho, s[2] / rho]
    }

    /// [`Self::anisotropic_at_voxel`] from the slots of the corners (density `rho` > 0 there):
    /// the same bits, without locating them again.
    #[inline]
    pub fn anisotropic_at_slots(&self, slots: &Trilinear, rho: f32, to_eye: Vec3) -> Rgb {
        let f = &self.rho_i1;
        let s: [Vec3; 3] = std::array::from_fn(|c| slots.blend(|q| decode_band(&f.at_slot(q)[c])));
        let i1 = [s[0] / rho, s[1] / rho, s[2] / rho];
        Rgb::new(i1[0].dot(to_eye), i1[1].dot(to_eye), i1[2].dot(to_eye)) * self.g
    }

    /// The anisotropic in-scattering g·I1·ω (per band, may be negative) at voxel coordinates `v`
    /// with trilinear density `rho`, towards the eye along `to_eye` (unit, the direction the
    /// scattered light travels).
    #[inline]
    pub fn anisotropic_at_voxel(&self, v: Vec3, rho: f32, to_eye: Vec3) -> Rgb {
        let i1 = self.i1_at_voxel(v, rho);
        Rgb::new(i1[0].dot(to_eye), i1[1].dot(to_eye), i1[2].dot(to_eye)) * self.g
    }
}
