//! The lit volume: what the diffusion stages leave for every later renderer (the final gather,
//! and the viewing cubes of the clear-air and ground stages). It holds the density, the diffusion
//! radiance I0 per band, the sun's transmittance at voxel centres, and the medium's parameters,
//! and answers "how much light does the cloud send towards the eye from here".
//!
//! The source per unit extinction at a point is S = a·(I0 + E_sun·T_sun·p(θ)): the in-scattered
//! diffuse radiance (the paper volume-renders the colour I0 with opacity ρσt; the albedo a makes
//! that exact for the isotropic part of I_d) plus the exact single scattering of the reduced sun
//! through the HG phase function. The g·I1·ω part of the diffuse field and the sky's own single
//! scattering are not included (the paper's approximation) unless `render.diffuse_anisotropy`
//! attaches the first moment ([`LitVolume::with_diffuse_anisotropy`], [`crate::diffusion::flux`]):
//! then the diffuse part is a·max(0, I0 + g·I1·ω), ω the direction to the eye.
//!
//! I0 is defined only where ρ > 0. Between voxel centres it is interpolated density-weighted,
//! I0(p) = trilinear(ρ·I0)/trilinear(ρ), so that empty voxels (I0 = 0) do not darken the cloud's
//! edge; where the trilinear ρ is zero there is no emission anyway.

use crate::diffusion::flux::{diffuse_flux, FluxField};
use crate::diffusion::DiffusionSolution;
use crate::incident::IncidentLight;
use crate::math::{Rgb, Vec3};
use crate::medium::{Grid3, Medium};
use crate::render::march::{march, March};
use crate::sunlight::SunTransmittance;

/// A medium with its diffusion solution and direct sun, ready to be rendered from any viewpoint.
#[derive(Clone, Debug)]
pub struct LitVolume {
    /// The medium (density, σt, albedo, g, box).
    pub medium: Medium,
    /// I0 per band at voxel centres (W·m⁻²·sr⁻¹), clamped at 0; zero where ρ = 0.
    pub i0: [Grid3; 3],
    /// ρ·I0 per band at voxel centres, for the density-weighted interpolation.
    rho_i0: [Grid3; 3],
    /// Sun transmittance at voxel centres.
    pub sun_transmittance: SunTransmittance,
    /// Sun irradiance (W/m² per band).
    pub sun_irradiance: Rgb,
    /// The diffuse field's first moment I1, when `render.diffuse_anisotropy` is on.
    pub flux: Option<FluxField>,
}

impl LitVolume {
    /// Combine stage 1 (sun) and stage 2 (I0).
    pub fn new(medium: &Medium, incident: &IncidentLight, solution: &DiffusionSolution) -> LitVolume {
        let d = medium.dims();
        let rho = medium.density.data();
        // I0 is clamped at 0: the P1 approximation can go negative in thin voxels at a strongly
        // forward-lit edge (the −∇·(Q1/ρσtr) source is a dipole), and a radiance cannot.
        let mk = |c: usize, weighted: bool| {
            let data: Vec<f32> = solution.i0[c]
                .iter()
                .zip(rho)
                .map(|(v, r)| if weighted { v.max(0.0) * r } else { v.max(0.0) })
                .collect();
            Grid3::from_vec(d, data, "diffusion solution").unwrap_or_else(|_| Grid3::filled(d, 0.0))
        };
        LitVolume {
            medium: medium.clone(),
            i0: [mk(0, false), mk(1, false), mk(2, false)],
            rho_i0: [mk(0, true), mk(1, true), mk(2, true)],
            sun_transmittance: incident.sun_transmittance.clone(),
            sun_irradiance: incident.sun_irradiance,
            flux: None,
        }
    }

    /// Add the anisotropic diffuse in-scattering g·I1·ω (I1 from the solver's fluxes with floor
    /// `tau_min`, see [`crate::diffusion::flux`]).
    pub fn with_diffuse_anisotropy(mut self, incident: &IncidentLight, solution: &DiffusionSolution, tau_min: f64) -> LitVolume {
        let i1 = diffuse_flux(&self.medium, incident, solution, tau_min);
        self.flux = Some(FluxField::new(&self.medium, &i1));
        self
    }

    /// I0 at continuous voxel coordinates `v` (density-weighted trilinear), given the trilinear ρ there.
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

    /// Source per unit extinction S (W·m⁻²·sr⁻¹) at voxel coordinates `v` with trilinear density
    /// `rho`, seen along `view_dir` (the direction the viewing ray travels, unit).
    #[inline]
    pub fn source_at_voxel(&self, v: Vec3, rho: f32, view_dir: Vec3) -> Rgb {
        let m = &self.medium;
        // Sunlight travels along −sun_dir and leaves towards the eye along −view_dir.
        let phase = m.optics.phase.eval(self.sun_transmittance.dir, -view_dir);
        let sun = self.sun_irradiance * (phase * self.sun_transmittance.at_voxel(v));
        let mut diffuse = self.i0_at_voxel(v, rho);
        if let Some(f) = &self.flux {
            diffuse = (diffuse + f.anisotropic_at_voxel(v, rho, -view_dir)).max(Rgb::ZERO);
        }
        m.optics.albedo * (diffuse + sun)
    }

    /// Extinction ρσt (m⁻¹) at a world point.
    #[inline]
    pub fn extinction(&self, p: Vec3) -> f32 {
        self.medium.density_at(p) * self.medium.optics.sigma_t
    }

    /// Emission ρσt·S (W·m⁻³·sr⁻¹) at a world point towards an eye looking along `view_dir`:
    /// the albedo·σt·ρ-weighted source a march integrates as ∫ T(s) emission ds.
    #[inline]
    pub fn emission(&self, p: Vec3, view_dir: Vec3) -> Rgb {
        let rho = self.medium.density_at(p);
        if rho <= 0.0 {
            return Rgb::ZERO;
        }
        self.source_at_voxel(self.medium.to_voxel(p), rho, view_dir) * (rho * self.medium.optics.sigma_t)
    }

    /// Front-to-back march of `o + t·d`, t ∈ [t_min, t_max], steps of at most `step` m, sample
    /// offset `xi` ∈ [0, 1): radiance from the cloud and the transmittance through it.
    #[inline]
    pub fn march(&self, o: Vec3, d: Vec3, t_min: f32, t_max: f32, step: f32, xi: f32) -> March {
        march(&self.medium, o, d, t_min, t_max, step, xi, |v, rho| self.source_at_voxel(v, rho, d))
    }
}
