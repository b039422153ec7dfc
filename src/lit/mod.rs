//! The lit volume: what the diffusion stages leave for every later renderer — the `diffusion`
//! gather, the viewing cubes of the clear-air stage (border cubes and the ground's hemicubes),
//! and the `full` gather's dense source and edge cubes. One type, one source term, one
//! interpolation rule; its mip pyramid ([`pyramid`]) beside it, built once per lit volume.
//!
//! **Source term.** Along a ray, radiance is ∫ T(s) κ(s) J(s) ds + T·background with κ = ρσt and
//! J the in-scattered radiance per unit extinction, J(X, ω) = a ∫ p(ω, ω′) I(X, ω′) dω′. With the
//! paper's split I = I_ri,sun + I0 + I1·ω (eq. 3), the sun's reduced radiance is a delta of
//! irradiance E_sun·T_sun(X) from the sun's direction, and HG integrates the isotropic I0 to I0
//! (∫p = 1), so
//!
//!   J(X, ω) = a · ( I0(X) + p(ω_sun → ω) · E_sun · T_sun(X) ),
//!
//! ω the direction the scattered light leaves in (towards the eye; [`crate::optics::Hg::eval`]).
//! The g·I1·ω part of the diffuse field and the sky's own single scattering are left out (the
//! paper's approximation: it volume-renders the colour I0 with opacity ρσt) unless
//! `render.diffuse_anisotropy` attaches the first moment ([`LitVolume::with_flux`],
//! [`crate::diffusion::flux`]): then the diffuse part is max(0, I0 + g·I1·ω).
//!
//! `render.sky_single_scattering` adds the missing single scattering of the reduced sky and
//! ground light, a·∫p(ω′·ω) I_ri,sky(X, ω′) dω′ ([`sky_single`], [`LitVolume::with_sky_single`]).
//!
//! **The one I0 rule.** I0 is clamped at 0 — the P1 solution goes negative in thin voxels on
//! sunlit tops (the −∇·(Q1/ρσtr) source of eq. 4 is a dipole) and a radiance cannot — and
//! interpolated density-weighted, I0(p) = trilinear(ρ·I0)/trilinear(ρ): empty voxels (I0 = 0)
//! do not darken the cloud's edge, and it is the rule a mip pyramid of pre-multiplied ρ·I0 obeys
//! at every level, so the gathers and the cubes see one field.
//!
//! **Storage.** Every per-voxel field here (the cells [ρ, ρ·I0, ρ·T_sun], ρ·I1, the sky
//! harmonics, the pyramid's coarser cells) is zero where ρ = 0 and is stored only at the full
//! voxels ([`crate::medium::sparse`]), so a lit volume costs bytes per voxel of the cloud, not of
//! its box; only the density and the sun transmittance (sampled beside the cloud too) are dense.
//! ρ·I0 is stored once, in the lit volume's cells ([`pyramid::Cells`], five 16-bit codes, 10 B per
//! full voxel, ≤ 2⁻¹² relative rounding), which are also the pyramid's level 0 (the same
//! allocation, not a copy): the gathers read ρ·I0 from their channels 1..4, decoded.

pub mod ground;
pub mod pyramid;
pub mod sky_single;
pub mod sunlight;

use crate::diffusion::flux::FluxField;
use crate::lighting::{Sky, Sun};
use crate::lit::sunlight::SunGrid;
use crate::math::{Rgb, Trilinear, Vec3};
use crate::medium::Medium;
use ground::LitGround;
use pyramid::{Cells, LitPyramid};
use sky_single::SkySingle;
use std::sync::{Arc, OnceLock};

/// A medium with its diffusion radiance and direct sun, ready to be rendered from any viewpoint.
/// Cheap to clone (the grids are shared).
#[derive(Clone, Debug)]
pub struct LitVolume {
    /// The medium (density, optics, box). The cells and the pyramid are built from it once: do
    /// not replace it.
    pub medium: Medium,
    /// Per full voxel at voxel centres, [ρ, ρ·max(I0, 0) (RGB, W·m⁻²·sr⁻¹), ρ·T_sun] in 16-bit
    /// codes: the density-weighted rule's ρ·I0 and the pyramid's level 0 (shared with it, one
    /// copy).
    cells: Arc<Cells>,
    /// Transmittance towards the sun at voxel centres (unitless), the density grid's dims. Private
    /// (read by [`Self::sun_t`]): the cells' ρ·T_sun is made from it once.
    sun_t: Arc<SunGrid>,
    /// The sun (its light enters only through `sun_t` and the phase function, never as a disc).
    pub sun: Sun,
    /// The sky behind everything.
    pub sky: Sky,
    /// The ground with its irradiance, if the scene has a ground.
    pub ground: Option<LitGround>,
    /// The diffuse field's first moment I1 (`render.diffuse_anisotropy`); the gathers' source
    /// uses it, the viewing cubes do not.
    pub flux: Option<Arc<FluxField>>,
    /// The single scattering of the reduced sky and ground light (`render.sky_single_scattering`),
    /// added to the diffuse part of the source; [`sky_single`].
    pub sky_single: Option<Arc<SkySingle>>,
    /// The mip pyramid, built on first use and shared by every clone (it does not depend on the
    /// ground or the flux).
    pyramid: Arc<OnceLock<Arc<LitPyramid>>>,
}

impl LitVolume {
    /// Assemble a lit volume from I0 per voxel (indexed by grid index i + nx(j + ny k): a dense
    /// `Vec<Rgb>` or a [`crate::medium::sparse::VoxelField`]; W·m⁻²·sr⁻¹ per band; clamped at 0
    /// here, read only at full voxels) and the sun transmittance at voxel centres. Both must have the density grid's
    /// dimensions (an internal invariant: the caller builds them from the same medium).
    pub fn new(
        medium: Medium,
        i0: impl std::ops::Index<usize, Output = Rgb> + Sync,
        sun_t: impl Into<Arc<SunGrid>>,
        sun: Sun,
        sky: Sky,
        ground: Option<LitGround>,
    ) -> LitVolume {
        let sun_t = sun_t.into();
        assert_eq!(sun_t.dims(), medium.dims(), "sun transmittance must have the density grid's dims");
        let rho = &*medium.density;
        let t = &*sun_t;
        let cells = Cells::from_fn(medium.density.full_index(), |n| {
            let r = rho.at(n);
            let c = i0[n].max(Rgb::ZERO) * r;
            [r, c.x, c.y, c.z, r * t.at_index(n)]
        });
        LitVolume {
            cells: Arc::new(cells),
            medium,
            sun_t,
            sun,
            sky,
            ground,
            flux: None,
            sky_single: None,
            pyramid: Arc::new(OnceLock::new()),
        }
    }

    /// The same scene with another ground (e.g. the one [`crate::cube::render_ground`] made).
    pub fn with_ground(mut self, ground: Option<LitGround>) -> LitVolume {
        self.ground = ground;
        self
    }

    /// Add the anisotropic diffuse in-scattering g·I1·ω ([`crate::diffusion::flux`]).
    pub fn with_flux(mut self, flux: FluxField) -> LitVolume {
        self.flux = Some(Arc::new(flux));
        self
    }

    /// Add the single scattering of the reduced sky and ground light ([`sky_single`]).
    pub fn with_sky_single(mut self, s: SkySingle) -> LitVolume {
        self.sky_single = Some(Arc::new(s));
        self
    }

    /// Grid resolution.
    #[inline]
    pub fn dims(&self) -> [usize; 3] {
        self.medium.dims()
    }

    /// The cells [ρ, ρ·I0 (RGB, W·m⁻²·sr⁻¹), ρ·T_sun] at voxel centres, stored per full voxel in
    /// 16-bit codes: the pyramid's level 0.
    #[inline]
    pub fn cells(&self) -> &Arc<Cells> {
        &self.cells
    }

    /// The transmittance towards the sun at voxel centres (unitless), the density grid's dims.
    #[inline]
    pub fn sun_t(&self) -> &Arc<SunGrid> {
        &self.sun_t
    }

    /// The mip pyramid (all levels down to [`pyramid::BLOCK`] cells), built on first use.
    pub fn pyramid(&self) -> Arc<LitPyramid> {
        self.pyramid.get_or_init(|| Arc::new(LitPyramid::build(self, usize::MAX))).clone()
    }

    /// I0 (≥ 0, W·m⁻²·sr⁻¹) at continuous voxel coordinates `v` with trilinear density `rho`
    /// there, by the module's rule; zero where `rho` ≤ 0.
    #[inline]
    pub fn i0(&self, v: Vec3, rho: f32) -> Rgb {
        if rho <= 0.0 {
            return Rgb::ZERO;
        }
        let f = &*self.cells;
        f.rho_i0_blend(&f.slots(&Trilinear::new(self.dims(), v.to_array()))) / rho
    }

    /// The diffuse radiance scattered towards `to_eye` per unit albedo (W·m⁻²·sr⁻¹): I0, or
    /// max(0, I0 + g·I1·ω) with the first moment attached; plus the reduced sky and ground
    /// light's single scattering ∫p·I_ri,sky when attached.
    #[inline]
    pub fn diffuse(&self, v: Vec3, rho: f32, to_eye: Vec3) -> Rgb {
        if rho <= 0.0 {
            return self.diffuse_parts(v, rho, self.i0(v, rho), None, to_eye);
        }
        self.diffuse_corners(v, rho, &Trilinear::new(self.dims(), v.to_array()), to_eye)
    }

    /// [`Self::diffuse`] at `p` (m) with the density there ([`Medium::density_at`]), the
    /// trilinear corners located once for ρ, ρ·I0 and ρ·I1 (the same bits as the separate
    /// look-ups): the final gather's dense source, one call per compositing step.
    #[inline]
    pub fn diffuse_at(&self, p: Vec3, to_eye: Vec3) -> Rgb {
        let m = &self.medium;
        let v = m.to_voxel(p);
        let d = m.dims();
        if v.x < 0.0 || v.y < 0.0 || v.z < 0.0 || v.x > d[0] as f32 || v.y > d[1] as f32 || v.z > d[2] as f32 {
            return self.diffuse(v, 0.0, to_eye);
        }
        let t = Trilinear::new(d, v.to_array());
        let rho = m.density.blend(&t);
        if rho <= 0.0 {
            return self.diffuse(v, rho, to_eye);
        }
        self.diffuse_corners(v, rho, &t, to_eye)
    }

    /// [`Self::diffuse`] for `rho` > 0 given the grid corners `t` of `v`: ρ·I0 and ρ·I1 share
    /// one slot look-up when they share the density's index.
    #[inline]
    fn diffuse_corners(&self, v: Vec3, rho: f32, t: &Trilinear, to_eye: Vec3) -> Rgb {
        let f = &*self.cells;
        let slots = f.slots(t);
        let i0 = f.rho_i0_blend(&slots) / rho;
        let shared = self.flux.as_ref().filter(|fl| Arc::ptr_eq(fl.rho_i1().index(), f.index()));
        self.diffuse_parts(v, rho, i0, shared.map(|_| &slots), to_eye)
    }

    /// max(0, I0 + g·I1·ω) (or I0) plus the sky's single scattering, given I0 and, when the flux
    /// shares the cells' index, the slots of `v`'s corners.
    #[inline(always)]
    fn diffuse_parts(&self, v: Vec3, rho: f32, i0: Rgb, slots: Option<&Trilinear>, to_eye: Vec3) -> Rgb {
        let d = match (&self.flux, slots) {
            (Some(f), Some(t)) => (i0 + f.anisotropic_at_slots(t, rho, to_eye)).max(Rgb::ZERO),
            (Some(f), None) => (i0 + f.anisotropic_at_voxel(v, rho, to_eye)).max(Rgb::ZERO),
            (None, _) => i0,
        };
        match &self.sky_single {
            Some(s) => d + s.at_voxel(v, rho, to_eye),
            None => d,
        }
    }

    /// The source J per unit extinction (W·m⁻²·sr⁻¹) at continuous voxel coordinates `v` with
    /// trilinear density `rho`, leaving towards the eye along `to_eye` (unit); module docs.
    #[inline]
    pub fn source(&self, v: Vec3, rho: f32, to_eye: Vec3) -> Rgb {
        let optics = &self.medium.optics;
        let sun = self.sun.irradiance * optics.sun_scatter(self.sun.dir, to_eye) * self.sun_t.trilinear(v.to_array());
        optics.albedo * self.diffuse(v, rho, to_eye) + sun
    }

    /// Radiance arriving at `o` from direction `d` beyond the medium: the lit ground where the
    /// ray meets it, else the sky. `t_ground` is the ground hit distance from [`Self::ground_hit`].
    #[inline]
    pub fn background(&self, o: Vec3, d: Vec3, t_ground: Option<f32>) -> Rgb {
        match (t_ground, &self.ground) {
            (Some(t), Some(g)) => g.radiance(o + d * t),
            _ => self.sky.radiance(d),
        }
    }

    /// Distance (m) along `o + t·d` to the ground, if the scene has one and the ray meets it.
    #[inline]
    pub fn ground_hit(&self, o: Vec3, d: Vec3) -> Option<f32> {
        self.ground.as_ref().and_then(|g| g.ground.intersect(o, d))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::medium::Grid3;

    /// The pyramid's level 0 is the lit volume's cells (one allocation), the cells are
    /// [ρ, ρ·max(I0, 0), ρ·T_sun] to their codes' rounding (≤ 2⁻¹² relative a channel), and `i0`
    /// is the density-weighted rule on the decoded ρ·I0: trilinear(ρ·I0)/trilinear(ρ), bit for
    /// bit.
    #[test]
    fn level0_is_the_cells_and_i0_is_the_rule() {
        let dims = [6, 5, 7];
        let n = dims[0] * dims[1] * dims[2];
        let mut g = Grid3::filled(dims, 0.0);
        for (k, x) in g.data_mut().iter_mut().enumerate() {
            *x = ((k * 7) % 4) as f32 * 0.3;
        }
        let i0: Vec<Rgb> = (0..n)
            .map(|k| Rgb::new((k % 5) as f32 - 1.0, 0.5 + (k % 3) as f32, 2.0 - (k % 7) as f32 * 0.4))
            .collect();
        let sun_t = Grid3::from_vec(dims, (0..n).map(|k| (k % 9) as f32 / 8.0).collect(), "test").unwrap();
        let m = Medium::new(g, Vec3::ZERO, Vec3::ONE, 1.0, Rgb::ONE, 0.5);
        let sun = Sun {
            dir: Vec3::Y,
            irradiance: Rgb::ONE,
        };
        let lit = LitVolume::new(m.clone(), i0.clone(), sun_t.clone(), sun, Sky::constant(Rgb::ONE), None);
        let p = lit.pyramid();
        assert!(Arc::ptr_eq(&p.levels[0].cells, lit.cells()));
        assert!(p.levels.len() >= 2);
        let rho = |k: usize| m.density.at(k);
        let st: Arc<SunGrid> = Arc::new(sun_t.into());
        let want = |k: usize| {
            let ri0 = i0[k].max(Rgb::ZERO) * rho(k);
            [rho(k), ri0.x, ri0.y, ri0.z, rho(k) * st.at_index(k)]
        };
        let max = (0..n).fold([0f32; 5], |m, k| std::array::from_fn(|a| m[a].max(want(k)[a])));
        let mut zeros = 0;
        for k in 0..n {
            let c = lit.cells().get(k);
            for (a, w) in want(k).into_iter().enumerate() {
                // Below 2⁻²⁹ of the channel's largest (T_sun's floor 2⁻³¹ here) it may read 0.
                let tol = w / 4096.0 + max[a] * 2f32.powi(-29);
                assert!((c[a] - w).abs() <= tol, "voxel {k} channel {a}: {} vs {w}", c[a]);
                assert!(w > 0.0 || c[a] == 0.0, "voxel {k} channel {a}: zero kept");
            }
            zeros += want(k).contains(&0.0) as usize;
        }
        assert!(zeros > 10 && zeros < n, "{zeros}");
        let dense: Vec<Rgb> = (0..n)
            .map(|k| {
                let c = lit.cells().get(k);
                Rgb::new(c[1], c[2], c[3])
            })
            .collect();
        let mut checked = 0;
        for s in 0..200 {
            let v = Vec3::new(s as f32 * 0.037 % 6.0, s as f32 * 0.061 % 5.0, s as f32 * 0.023 % 7.0);
            let t = Trilinear::new(dims, v.to_array());
            let r = m.density.blend(&t);
            let want = if r <= 0.0 { Rgb::ZERO } else { t.blend(|k| dense[k]) / r };
            assert_eq!(
                lit.i0(v, r).to_array().map(f32::to_bits),
                want.to_array().map(f32::to_bits),
                "at {v}"
            );
            checked += (r > 0.0) as usize;
        }
        assert!(checked > 100, "{checked}");
    }
}
