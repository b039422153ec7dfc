//! Method `diffusion` (the paper's Figure 5): stage 1 (incident light), stage 2 (diffusion solve)
//! and a final gather that composites, front to back, the diffusion radiance I0 as the volume's
//! colour with opacity from ρσt plus the exact single scattering of the reduced sun, over the sky
//! or ground. See [`crate::lit::LitVolume`] for the source term; the gather evaluates it from
//! [`source_field`], one packed record per voxel.

pub mod source_field;

use super::single::{background, pixel_sample};
use super::{render_rows, Progress, Timings};
use crate::diffusion::flux::{diffuse_flux, FluxField};
use crate::diffusion::surface::visible_i0;
use crate::diffusion::warm::{DiffusionState, WarmSolve};
use crate::diffusion::{solve_diffusion_from, BoundaryLight, DiffusionSolution};
use crate::error::check_finite_field;
use crate::error::Result;
use crate::image::Image;
use crate::incident::FirstScattering;
use crate::incident::{compute, EntryRadiance, IncidentLight, IncidentSources};
use crate::lighting::bins::DirectionBins;
use crate::lit::ground::LitGround;
use crate::lit::sky_single::SkySingle;
use crate::lit::sunlight::SunTransmittance;
use crate::lit::LitVolume;
use crate::math::Rgb;
use crate::medium::march::march_with;
use crate::medium::sparse::VoxelField;
use crate::scene::Scene;
use source_field::SourceField;

/// Stage 1 for a scene with default sampling (seed from `render.seed`), the clear-air hook
/// `entry` if any. With `render.sky_boundary` stage 1 propagates the sun only: the sky and
/// ground enter through the diffusion's boundary condition instead ([`boundary_light`]).
pub fn compute_incident(scene: &Scene, entry: Option<&EntryRadiance<'_>>) -> IncidentLight {
    let mut settings = scene.render.incident.clone();
    let bins = DirectionBins::new();
    let mut sources = scene_sources(scene, &bins);
    if scene.render.solver.sky_boundary {
        sources.bin_radiance.fill(Rgb::ZERO);
        settings.sky_single = false;
    }
    compute(&scene.medium, &bins, &sources, &settings, entry)
}

/// Refuse stage 1's output holding a non-finite value (Q0, Q1, the propagated bins, the sky's
/// projection): an error naming `incident light`. One pass over the stored values.
pub fn check_incident(inc: &IncidentLight) -> Result<()> {
    let stage = "incident light";
    match &inc.scattering {
        FirstScattering::General { q0, q1 } => {
            check_finite_field(stage, "Q0 (eq. 5)", q0.packed().iter().flat_map(|c| c.to_array()))?;
            for f in q1 {
                check_finite_field(stage, "Q1 (eq. 6)", f.packed().iter().flat_map(|c| c.to_array()))?;
            }
        }
        FirstScattering::Sun {
            rho_t,
            q0_per_rho_t,
            q1_per_q0,
        } => {
            let scales = q0_per_rho_t.iter().chain(q1_per_q0).map(|&v| v as f32);
            check_finite_field(stage, "the sun's Q0 and Q1 (eqs. 5, 6)", scales.chain([rho_t.scale()]))?;
        }
    }
    check_finite_field(
        stage,
        "the propagated bin radiance",
        inc.bin_radiance.iter().flat_map(|c| c.to_array()),
    )?;
    if let Some(sh) = &inc.sky_sh {
        check_finite_field(stage, "the sky's projection", sh.packed().iter().flatten().copied())?;
    }
    Ok(())
}

/// The light entering the diffusion through its boundary faces: with `render.sky_boundary`, the
/// unoccluded sky and ground over each face's outer hemisphere; else none (the paper's eq. 7).
pub fn boundary_light(scene: &Scene) -> BoundaryLight {
    if !scene.render.solver.sky_boundary {
        return BoundaryLight::none();
    }
    let bins = DirectionBins::new();
    BoundaryLight::uniform(&bins.bins, &scene_sources(scene, &bins).bin_radiance)
}

/// The scene's sun, and its sky and unshadowed ground averaged over each of `bins`.
fn scene_sources(scene: &Scene, bins: &DirectionBins) -> IncidentSources {
    IncidentSources::from_lighting(&scene.sun, &scene.sky, scene.ground.as_ref(), bins)
}

/// The lit volume of a scene from I0 per voxel and the sun transmittance at voxel centres, the
/// ground (if any) lit by the unoccluded sun and sky.
pub fn scene_lit_volume(scene: &Scene, i0: impl std::ops::Index<usize, Output = Rgb> + Sync, sun_t: &SunTransmittance) -> LitVolume {
    let ground = scene
        .ground
        .as_ref()
        .map(|g| LitGround::unoccluded(g.clone(), &scene.sun, &scene.sky));
    LitVolume::new(
        scene.medium.clone(),
        i0,
        sun_t.grid.clone(),
        scene.sun.clone(),
        scene.sky.clone(),
        ground,
    )
}

/// I0 per voxel as RGB (stored per full voxel, like the solution).
pub fn i0_rgb(sol: &DiffusionSolution) -> VoxelField<Rgb> {
    let i0 = &sol.i0;
    VoxelField::from_fn(i0[0].index().clone(), Rgb::ZERO, |k| {
        Rgb::new(i0[0].get(k), i0[1].get(k), i0[2].get(k))
    })
}

/// I0 per voxel as RGB as the eye sees it: thick boundary voxels show their value one optical
/// depth inside the surface, not their centre's ([`visible_i0`]).
pub fn visible_i0_rgb(scene: &Scene, inc: &IncidentLight, sol: &DiffusionSolution) -> VoxelField<Rgb> {
    let i0 = visible_i0(&scene.medium, inc, sol, scene.render.solver.min_optical_depth);
    VoxelField::from_fn(i0[0].index().clone(), Rgb::ZERO, |k| {
        Rgb::new(i0[0].get(k), i0[1].get(k), i0[2].get(k))
    })
}

/// The lit volume of a solved scene (`sun_t` its medium's sun transmittance), I0 as the eye sees
/// it ([`visible_i0_rgb`]), with the first moment attached when `render.diffuse_anisotropy` is on
/// and the sky and ground single scattering when stage 1 projected it
/// (`render.sky_single_scattering`).
pub fn solved_lit_volume(scene: &Scene, inc: &IncidentLight, sol: &DiffusionSolution, sun_t: &SunTransmittance) -> LitVolume {
    let mut lit = scene_lit_volume(scene, visible_i0_rgb(scene, inc, sol), sun_t);
    if scene.render.diffuse_anisotropy {
        let i1 = diffuse_flux(&scene.medium, inc, sol, scene.render.solver.min_optical_depth);
        lit = lit.with_flux(FluxField::new(&scene.medium, i1));
    }
    if let Some(sh) = &inc.sky_sh {
        lit = lit.with_sky_single(SkySingle::new(&scene.medium, sh));
    }
    lit
}

/// The gather's source of a solved scene: [`solved_lit_volume`]'s terms packed per voxel.
fn source_field(scene: &Scene, inc: &IncidentLight, sol: &DiffusionSolution, sun_t: &SunTransmittance) -> SourceField {
    let i1 = diffuse_flux(&scene.medium, inc, sol, scene.render.solver.min_optical_depth);
    SourceField::new(
        &scene.medium,
        &visible_i0(&scene.medium, inc, sol, scene.render.solver.min_optical_depth),
        scene.render.diffuse_anisotropy.then_some(&i1),
        inc.sky_sh.as_ref(),
        &sun_t.grid,
        &scene.sun,
    )
}

/// Render the image.
pub fn render(scene: &Scene, progress: &dyn Progress, timings: &mut Timings) -> Result<Image> {
    Ok(render_warm(scene, progress, timings, WarmSolve::default())?.0)
}

/// [`render`] as a frame of a sequence: the solve starts from `warm.start` (a previous frame's
/// solution, src/diffusion/warm.rs) and, with `warm.keep`, hands its own on; also the solve's
/// CG iterations (the middle band's).
pub fn render_warm(scene: &Scene, progress: &dyn Progress, timings: &mut Timings, warm: WarmSolve) -> Result<(Image, Option<DiffusionState>, usize)> {
    let inc = timings.time("incident light", || compute_incident(scene, None));
    check_incident(&inc)?;
    let sol = timings.time("diffusion solve", || {
        let start = warm.start.map(|st| st.start(&scene.medium));
        solve_diffusion_from(&scene.medium, &inc, &boundary_light(scene), start, &scene.render.solver)
    })?;
    progress.log(&sol.summary());
    let state = warm.keep.then(|| DiffusionState::new(&scene.medium, &sol));
    let iterations = sol.stats[1].iterations;
    // Only the source field reads the sun transmittance: computed after the solve, not held
    // through it.
    let sun_t = timings.time("sun transmittance", || SunTransmittance::compute(&scene.medium, scene.sun.dir));
    sun_t.check_finite()?;
    let field = timings.time("source field", || source_field(scene, &inc, &sol, &sun_t));
    drop((inc, sun_t));
    let cam = &scene.camera;
    let spp = scene.render.aa_samples;
    let step = scene.render.step_voxels * scene.medium.min_voxel();
    // ρ from the dense copy on the cloud's box (built here, after the solve's peak): the same
    // bits as the packed density's, without its slot look-ups.
    let px = timings.time("gather", || {
        let dense = scene.medium.dense_density();
        render_rows(cam.width, cam.height, progress, "diffusion gather", |x, y| {
            let mut sum = Rgb::ZERO;
            for s in 0..spp {
                let (px, py, xi) = pixel_sample(scene, x, y, s, spp);
                let ray = cam.ray(px, py);
                let t_max = scene
                    .ground
                    .as_ref()
                    .and_then(|g| g.intersect(ray.origin, ray.dir))
                    .unwrap_or(f32::INFINITY);
                let src = field.along(-ray.dir);
                let r = march_with(
                    &scene.medium,
                    |v| dense.trilinear(v),
                    ray.origin,
                    ray.dir,
                    0.0,
                    t_max,
                    step,
                    xi,
                    |v, rho, _| src.at(v, rho),
                );
                sum += r.radiance;
                if r.transmittance > 0.0 {
                    sum += r.transmittance * background(scene, ray.origin, ray.dir);
                }
            }
            sum / spp as f32
        })
    });
    let mut img = Image::new(cam.width, cam.height);
    img.pixels = px;
    Ok((img, state, iterations))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::medium::sparse::FullIndex;
    use crate::pipeline::NoProgress;
    use crate::scene::{Method, SceneDesc};
    use std::sync::Arc;

    /// Stage 1's light on a 2×1×1 grid of full voxels, in the sun's form with Q0 per unit ρT̄ `q0`.
    fn sun_only(q0: f64) -> IncidentLight {
        let index = Arc::new(FullIndex::build([2, 1, 1], &[1.0, 1.0]));
        let mut inc = IncidentLight {
            dims: [2, 1, 1],
            scattering: FirstScattering::zero(index),
            sun_irradiance: Rgb::splat(3.0),
            bin_radiance: vec![Rgb::splat(0.1); 4],
            sky_sh: None,
        };
        if let FirstScattering::Sun { q0_per_rho_t, .. } = &mut inc.scattering {
            q0_per_rho_t[1] = q0;
        }
        inc
    }

    #[test]
    fn a_non_finite_stage_1_value_is_an_error_naming_the_stage() {
        assert!(check_incident(&sun_only(0.25)).is_ok());
        let e = check_incident(&sun_only(f64::NAN)).unwrap_err().to_string();
        assert!(e.starts_with("incident light:") && e.contains("Q0"), "{e}");
        let mut inc = sun_only(0.25);
        inc.bin_radiance[2] = Rgb::new(0.0, 0.0, f32::INFINITY);
        let e = check_incident(&inc).unwrap_err().to_string();
        assert!(e.starts_with("incident light:") && e.contains("bin radiance"), "{e}");
    }

    /// The procedural cloud in 40-m voxels of 10⁶ m⁻¹ (some 10⁷ optical depths each), albedo 1,
    /// g = 0, under a sun of 3 W/m² and a sky of at most 0.8 W·m⁻²·sr⁻¹.
    fn thick_scene(method: Method) -> Scene {
        let text = "[medium]\ngrid = \"procedural\"\nresolution = [12, 10, 8]\nvoxel_size = 40.0\n\
                    origin = [-240.0, 100.0, -160.0]\nsigma_t = 1e6\nalbedo = [1.0, 1.0, 1.0]\ng = 0.0\n\
                    [sun]\ndirection = [0.3, 0.8, 0.5]\nirradiance = [3.0, 3.0, 3.0]\n\
                    [sky]\nmodel = \"constant\"\nradiance = [0.3, 0.45, 0.8]\n\
                    [camera]\nposition = [0.0, 350.0, 1500.0]\nlook_at = [0.0, 300.0, 0.0]\nfov_deg = 30.0\nwidth = 24\nheight = 18\n";
        let desc = SceneDesc::from_toml(text, "thick.toml").unwrap();
        let mut scene = Scene::build(desc, "thick.toml", std::path::Path::new(".")).unwrap();
        scene.render.method = method;
        scene
    }

    #[test]
    fn a_cloud_of_very_thick_voxels_is_no_brighter_than_its_light_allows() {
        // A conservative surface sends back what it receives: its exitance is at most
        // E + π L_sky, and no direction of a diffuse surface is more than ~2.5 times brighter than
        // the mean (the Eddington profile's 1 + (3/2)μ). The centres' I0 ((3/2)τ times the
        // surface's) gave 10⁷ here.
        let bound = 2.5 * (3.0 / std::f32::consts::PI + 0.8);
        for method in [Method::Diffusion, Method::Full] {
            let out = crate::render::render(&thick_scene(method), &NoProgress).unwrap();
            let max = out.image.pixels.iter().map(|p| p.max_element()).fold(0f32, f32::max);
            let cloud = out.image.pixels.iter().filter(|p| p.max_element() > 0.9).count();
            assert!(
                max <= bound && cloud > 0,
                "{method:?}: max pixel {max} (bound {bound}), {cloud} bright pixels"
            );
        }
    }
}
