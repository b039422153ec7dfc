//! The lit volume: everything a viewing cube needs to render the cloud as a self-luminous,
//! absorbing medium (paper section 3): the medium (ρ, σt, albedo, g), the diffusion solution I0
//! per voxel, the reduced sun transmittance per voxel, the sun, the sky and the (lit) ground.
//!
//! **Source term.** Along a ray, radiance is ∫ T(s) κ(s) J(s) ds + T·background with κ = ρσt and
//! J the in-scattered radiance per unit extinction, J(X, ω) = a ∫ p(ω, ω′) I(X, ω′) dω′. With the
//! paper's split I = I_ri,sun + I0 + I1·ω (eq. 3), the sun's reduced radiance is a delta of
//! irradiance E_sun·T_sun(X) in the direction −ω_sun, and the HG phase integrates the isotropic
//! I0 to I0 (∫p = 1), so
//!
//!   J(X, ω) = a · ( I0(X) + p_HG(cosθ) · E_sun · T_sun(X) ),  cosθ = (−ω_sun)·ω,
//!
//! where ω is the direction the scattered light travels (towards the eye) and −ω_sun the
//! direction the sunlight travels. The g·I1·ω term and the first scattering of the reduced sky
//! are dropped, as the paper renders its cubes with colour I0 and opacity ρσt.

use super::ground::LitGround;
use crate::lighting::{Sky, Sun};
use crate::math::{Rgb, Vec3};
use crate::medium::{Grid3, Medium};
use crate::sunlight::SunTransmittance;
use std::sync::Arc;

/// The lit scene a viewing cube renders.
#[derive(Clone, Debug)]
pub struct LitVolume {
    /// The medium (cheap to clone: the grids are shared).
    pub medium: Medium,
    /// Diffuse radiance I0 (W·m⁻²·sr⁻¹ per band) at each voxel centre, index i + nx(j + ny k),
    /// clamped at 0 (see [`LitVolume::new`]).
    pub i0: Arc<Vec<Rgb>>,
    /// ρ·I0 per band at voxel centres, for the density-weighted interpolation.
    rho_i0: Arc<[Grid3; 3]>,
    /// Transmittance towards the sun (unitless) at each voxel centre, same dims as the density.
    pub sun_t: Arc<Grid3>,
    /// The sun (its light enters only through `sun_t` and the phase function, never as a disc).
    pub sun: Sun,
    /// The sky behind everything.
    pub sky: Sky,
    /// The ground with its irradiance, if the scene has a ground.
    pub ground: Option<LitGround>,
    /// The diffuse field's first moment I1 (`render.diffuse_anisotropy`), used by the final
    /// gather's dense source (not by the viewing cubes).
    pub flux: Option<Arc<crate::diffusion::flux::FluxField>>,
}

impl LitVolume {
    /// Assemble a lit volume. `i0` and `sun_t` must have the density grid's dimensions (an
    /// internal invariant: the caller builds them from the same medium).
    pub fn new(medium: Medium, i0: Vec<Rgb>, sun_t: Grid3, sun: Sun, sky: Sky, ground: Option<LitGround>) -> LitVolume {
        let n = medium.density.len();
        assert_eq!(i0.len(), n, "I0 must have one value per voxel");
        assert_eq!(sun_t.dims(), medium.dims(), "sun transmittance must have the density grid's dims");
        // One rule with the `diffusion` gather (crate::lit): I0 is clamped at 0 — the P1 solution
        // goes negative in thin voxels on sunlit tops (the −∇·(Q1/ρσtr) source is a dipole) and
        // a radiance cannot — and interpolated density-weighted, so the cubes' pyramid (which
        // stores ρ·I0) and the gather's dense source see the same field.
        let i0: Vec<Rgb> = i0.into_iter().map(|v| v.max(Rgb::ZERO)).collect();
        let d = medium.dims();
        let rho = medium.density.data();
        let band = |c: usize| {
            let data: Vec<f32> = i0.iter().zip(rho).map(|(v, r)| v[c] * r).collect();
            Grid3::from_vec(d, data, "lit volume").expect("I0 has one value per voxel")
        };
        let rho_i0 = Arc::new([band(0), band(1), band(2)]);
        LitVolume {
            medium,
            i0: Arc::new(i0),
            rho_i0,
            sun_t: Arc::new(sun_t),
            sun,
            sky,
            ground,
            flux: None,
        }
    }

    /// A lit volume from a scene: I0 given, the sun transmittance computed exactly at voxel
    /// centres near the cloud ([`SunTransmittance`]), the ground unshadowed until
    /// [`super::ground::render_ground`] replaces it.
    pub fn from_scene(scene: &crate::scene::Scene, i0: Vec<Rgb>) -> LitVolume {
        let sun_t = SunTransmittance::compute(&scene.medium, scene.sun.dir).grid;
        let ground = scene
            .ground
            .as_ref()
            .map(|g| LitGround::unoccluded(g.clone(), &scene.sun, &scene.sky));
        LitVolume::new(scene.medium.clone(), i0, sun_t, scene.sun.clone(), scene.sky.clone(), ground)
    }

    /// The same scene with another ground (e.g. the one [`super::ground::render_ground`] made).
    pub fn with_ground(mut self, ground: Option<LitGround>) -> LitVolume {
        self.ground = ground;
        self
    }

    /// Grid resolution.
    #[inline]
    pub fn dims(&self) -> [usize; 3] {
        self.medium.dims()
    }

    /// I0 (≥ 0) at continuous voxel coordinates `v`, density-weighted:
    /// trilinear(ρ·I0)/`rho`, with `rho` the trilinear density there (zero where `rho` ≤ 0).
    #[inline]
    pub fn i0_at_voxel(&self, v: Vec3, rho: f32) -> Rgb {
        if rho <= 0.0 {
            return Rgb::ZERO;
        }
        let a = v.to_array();
        Rgb::new(
            self.rho_i0[0].trilinear(a),
            self.rho_i0[1].trilinear(a),
            self.rho_i0[2].trilinear(a),
        ) / rho
    }

    /// In-scattered radiance per unit extinction J (W·m⁻²·sr⁻¹) at continuous voxel coordinates
    /// `v` with trilinear density `rho`, for light leaving towards the eye along `dir_to_eye`
    /// (unit). See the module docs.
    #[inline]
    pub fn source_at_voxel(&self, v: Vec3, rho: f32, dir_to_eye: Vec3) -> Rgb {
        let phase = self.medium.optics.phase.eval(self.sun.dir, dir_to_eye);
        let t = self.sun_t.trilinear(v.to_array());
        self.medium.optics.albedo * (self.i0_at_voxel(v, rho) + self.sun.irradiance * (phase * t))
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
