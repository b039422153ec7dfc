//! Method `full` (the paper's Figure 7): stages 1 and 2, the clear-air propagation of section 3,
//! and the final gather with the low-density edges of section 4.
//!
//! 1. Stage 1 (incident light from sky, ground and sun) and stage 2 (diffusion solve).
//! 2. Clear air, iterated (`render.iterations`, `--iterations`): the ground's hemicubes and a
//!    viewing cube at every empty border voxel are rendered from the current lit volume; stage 1 is
//!    re-run with rays entering the cloud from a border voxel carrying that cube's radiance from
//!    the opposite bin (light reflected by other cloud parts and the lit ground); the diffusion
//!    equation is re-solved warm-started from the previous I0. The relative change of I0 is logged
//!    per iteration and the loop stops early below `render.propagation_tolerance`.
//! 3. Final gather ([`crate::edges::gather::EdgeGather`]): exact sun single scattering everywhere,
//!    the diffusion radiance in the dense core, and for low-density segments the Poisson-weighted
//!    HG orders convolved with a view-aligned cube at the segment's optical midpoint, over the lit
//!    ground (the hemicubes' irradiance: cloud shadow and cloud light) or the sky.
//!
//! With `iterations = 0` this is the paper's Figure 6 (diffusion plus the low-density edges, the
//! ground still lit by its hemicubes).

use super::diffusion::{boundary_light, check_incident, compute_incident, scene_lit_volume, solved_lit_volume, visible_i0_rgb};
use super::edge_pixels::{edge_pixels, EDGE_GRID, EDGE_SAMPLES};
use super::single::pixel_sample;
use super::{Progress, Timings};
use crate::cube::{clear_air, BorderKeep, BorderLight, ClearAir, CubeImage, CubeOptions, CubeRenderer};
use crate::diffusion::warm::{DiffusionState, WarmSolve};
use crate::diffusion::{solve_diffusion_lean, BoundaryLight, DiffusionSettings, DiffusionSolution};
use crate::edges::escape::SunChord;
use crate::edges::gather::{CubeRequest, CubeSource, EdgeGather, SunInput};
use crate::edges::sparse::{gather_image, gather_pixels, PixelRay, SparseSettings};
use crate::error::check_finite_field;
use crate::error::Result;
use crate::image::Image;
use crate::incident::IncidentLight;
use crate::lighting::bins::cube_pixel;
use crate::lighting::envmap::BrightSplit;
use crate::lighting::SkyKind;
use crate::lit::ground::LitGround;
use crate::lit::sunlight::SunTransmittance;
use crate::render::{full_beam, beam_check};
use crate::lit::LitVolume;
use crate::math::{Rgb, Vec3};
use crate::scene::Scene;

/// The lit scene after the clear-air iterations.
pub struct Propagation {
    /// Lit volume (final I0, sun transmittance, lit ground) for cubes and the gather.
    pub lit: LitVolume,
    /// The final diffusion solution.
    pub solution: DiffusionSolution,
    /// The stage-1 light the final solution was solved with.
    pub incident: IncidentLight,
    /// Relative change ‖I0_new − I0_old‖/‖I0_new‖ of each clear-air iteration.
    pub changes: Vec<f64>,
    /// CG iterations of the diffusion solves (the middle band's, summed over the solves).
    pub cg_iterations: usize,
    /// The first solve's solution, kept for the next frame's first solve (with `keep`).
    pub first_state: Option<DiffusionState>,
}

/// Relative residual of the first diffusion solve when clear-air iterations follow it: its I0 only
/// lights the border cubes. Against a first solve to 1e-4 the images differ by a block-mean
/// relative error of at most 3.7·10⁻⁵ (default and evaluation scenes; docs/full.md), and the first
/// solve takes 4 iterations per band instead of 7–8 at 100×80×60.
const FIRST_SOLVE_TOLERANCE: f64 = 1e-2;

/// Stages 1–2 and the clear-air iterations.
pub fn propagate(scene: &Scene, progress: &dyn Progress, timings: &mut Timings) -> Result<Propagation> {
    propagate_from(scene, progress, timings, WarmSolve::default())
}

/// [`propagate`] with the first diffusion solve started from `warm.start` (a previous frame's
/// first solution, src/diffusion/warm.rs) instead of zero, to the same tolerance; with
/// `warm.keep` the first solution is kept for the next frame. The first solution, not the final
/// one: the final one holds the clear-air light, which the first solve, stopped at
/// FIRST_SOLVE_TOLERANCE, would keep part of (the warm image then up to 6 times further from the
/// converged one than the cold image; docs/sequences.md).
pub fn propagate_from(scene: &Scene, progress: &dyn Progress, timings: &mut Timings, warm: WarmSolve) -> Result<Propagation> {
    let settings = &scene.render.solver;
    let mut inc = timings.time("incident light", || compute_incident(scene, None));
    check_incident(&inc)?;
    let unoccluded = boundary_light(scene);
    // The first solution only lights the clear-air cubes when a clear-air iteration follows
    // (their light moves I0 by a few per cent, and the re-solve meets the full tolerance): it
    // stops at FIRST_SOLVE_TOLERANCE.
    let iterations = scene.render.clear_air.iterations;
    let first = DiffusionSettings {
        tolerance: if iterations > 0 {
            settings.tolerance.max(FIRST_SOLVE_TOLERANCE)
        } else {
            settings.tolerance
        },
        ..settings.clone()
    };
    let mut sol = timings.time("diffusion solve", || {
        let start = warm.start.map(|st| st.start(&scene.medium));
        solve_diffusion_lean(&scene.medium, &inc, &unoccluded, start, &first).map(|(sol, _)| sol)
    })?;
    progress.log(&sol.summary());
    let first_state = warm.keep.then(|| DiffusionState::new(&scene.medium, &sol));
    let mut cg_iterations = sol.stats[1].iterations;
    // The sun transmittance depends only on the medium and the sun: once per run, after the
    // first solve (only the lit volumes read it), so that solve does not hold it.
    let sun_t = timings.time("sun transmittance", || SunTransmittance::compute(&scene.medium, scene.sun.dir));
    sun_t.check_finite()?;
    let mut changes = Vec::new();
    let opts = &scene.render.cubes;
    // With `render.sky_boundary` the cubes' light enters through the boundary condition, and
    // only what each cube sends through its faces is kept; else stage 1 reads their bins.
    let keep = if settings.sky_boundary {
        BorderKeep::FaceLight
    } else {
        BorderKeep::Bins
    };
    let cubes = |sol: &DiffusionSolution, inc: &IncidentLight| {
        clear_air(
            scene_lit_volume(scene, visible_i0_rgb(scene, inc, sol), &sun_t),
            scene.ground.as_ref(),
            opts,
            keep,
            progress,
        )
    };
    // Memory: each iteration's cubes, and the old stage-1 light, are dropped once the new stage-1
    // light no longer needs them; only the cubes' lit ground is kept.
    let mut ca = Some(timings.time("clear-air cubes", || cubes(&sol, &inc)));
    let mut ground = ca.as_ref().and_then(|c| c.lit.ground.clone());
    check_ground(ground.as_ref())?;
    for it in 0..iterations {
        if progress.cancelled() {
            break;
        }
        let c = match ca.take() {
            Some(c) => c,
            None => timings.time("clear-air cubes", || cubes(&sol, &inc)),
        };
        // The lit volume (its I0 and pyramid) is dropped before the re-solve.
        let ClearAir { lit, border } = c;
        ground = lit.ground.clone();
        check_ground(ground.as_ref())?;
        drop(lit);
        let n_cubes = border.cubes();
        check_border(&border)?;
        // Stage 1 asks with bin b = the direction the light comes from (its rays flow along −ω_b),
        // which is the cube's own bin b ("radiance arriving from ω_b").
        // With `render.sky_boundary` the cubes' light enters through the boundary condition and
        // stage 1 (the sun only) does not change; else stage 1 is re-run with the cubes' light.
        let boundary = match border {
            BorderLight::FaceLight(_, light) => unoccluded.clone().with_ghosts(light),
            BorderLight::Bins(cubes) => {
                drop(inc);
                let hook = cubes.hook();
                inc = timings.time("incident light", || compute_incident(scene, Some(&hook)));
                check_incident(&inc)?;
                BoundaryLight::none()
            }
        };
        // The new I0 overwrites the old band by band; the change is measured as it does.
        let (new, change) = timings.time("diffusion solve", || {
            solve_diffusion_lean(&scene.medium, &inc, &boundary, Some(sol.i0), settings)
        })?;
        // A change near or above 100 % is not noise: on grids whose voxels are optically very
        // thick (τ ≫ 1 per voxel) stage 1 deposits all light in the first voxel, and the P1 dipole
        // source −∇·(Q1/ρσtr) is not resolved, so the cubes' anisotropic light moves I0 a lot.
        let tau_voxel = scene.medium.optics.sigma_t * scene.medium.density.max_value() * scene.medium.min_voxel();
        let hint = if change > 0.5 && tau_voxel > 10.0 {
            format!(
                "; large because voxels reach optical depth {tau_voxel:.0}: stage 1's P1 source is resolved \
                 only near 1 per voxel (raise medium.resolution or lower medium.sigma_t)"
            )
        } else {
            String::new()
        };
        progress.log(&format!(
            "clear-air iteration {}/{}: {} border cubes, I0 changed by {:.3} % ({} warm-start iterations){hint}",
            it + 1,
            iterations,
            n_cubes,
            100.0 * change,
            new.stats[1].iterations
        ));
        cg_iterations += new.stats[1].iterations;
        sol = new;
        changes.push(change);
        if change < scene.render.clear_air.propagation_tolerance {
            break;
        }
    }
    let lit = solved_lit_volume(scene, &inc, &sol, &sun_t).with_ground(ground);
    Ok(Propagation {
        lit,
        solution: sol,
        incident: inc,
        changes,
        cg_iterations,
        first_state,
    })
}

/// Refuse a lit ground whose hemicube irradiance is non-finite: an error naming `ground hemicubes`.
fn check_ground(ground: Option<&LitGround>) -> Result<()> {
    let grid = ground.and_then(|g| g.grid.as_ref());
    check_finite_field(
        "ground hemicubes",
        "the ground's irradiance",
        grid.into_iter().flat_map(|g| g.irradiance.iter().flat_map(|c| c.to_array())),
    )
}

/// Refuse clear-air cubes holding a non-finite radiance: an error naming `clear-air cubes`.
fn check_border(border: &BorderLight) -> Result<()> {
    let stage = "clear-air cubes";
    match border {
        BorderLight::Bins(cubes) => check_finite_field(stage, "the border cubes' bins", cubes.radiance.iter().flat_map(|c| c.to_array())),
        BorderLight::FaceLight(_, light) => check_finite_field(
            stage,
            "the light through the border faces",
            light.iter().flat_map(|(_, _, c)| c.to_array()),
        ),
    }
}

/// View-aligned cubes for the edge gather, rendered through the clear-air cube renderer.
pub struct GatherCubes<'a> {
    renderer: CubeRenderer<'a>,
    /// Radius (m) of the tube around a segment whose cells are left out of its own cube.
    exclude_radius: f32,
    /// Trace the five rear faces, and the front face's outer ring, at half resolution (see
    /// [`CubeSource::render_cube`] below); measured on the default scene: the rear faces made the
    /// gather 31 % faster, image within 1.1·10⁻⁵ mean relative difference of full-resolution
    /// cubes; the ring 25 % fewer traces per cube, images within 6.4·10⁻⁴ block MRE
    /// (docs/performance.md, "Approximations made for speed").
    pub rear_half_resolution: bool,
    /// Solid angle (sr) and cone width (rad, its square root) of each pixel of a face at
    /// `cone_res` pixels per edge (the scene's cube resolution): the same for every cube, so
    /// computed once (four `atan` per pixel).
    faces: FacePixels,
    cone_res: usize,
    /// A file map sky as its base and its brightest pixels' power as points
    /// ([`crate::lighting::EnvMap::split_bright`]): a cube pixel that sees the sky sees the base
    /// on its axis plus the points' power in it over its solid angle. None: the sky on the axis.
    sky: Option<BrightSplit<'a>>,
}

/// Pixels brighter than this many times a file map's mean luminance are taken as points by the
/// gather cubes. The base left is at most this bright, so a cube pixel's axis sample of it is off
/// by less than 10·mean·Ω: 1.3 % of the sky's ∫ L dω for a full-resolution pixel of a res-16 cube
/// (Ω ≤ 0.016 sr), 5 % for a 2×2 block that one trace fills. At most a tenth of the sphere is
/// this bright, so at most about a tenth of the merge grid's cells hold points.
const SKY_POINTS_OVER_MEAN: f64 = 10.0;

/// Per face pixel at one resolution, index j·res + i: solid angle (sr) and cone width (rad).
struct FacePixels {
    solid_angle: Vec<f64>,
    cone: Vec<f32>,
}

impl FacePixels {
    fn new(res: usize) -> FacePixels {
        let solid_angle = CubeImage::face_solid_angles(res);
        let cone = solid_angle.iter().map(|w| (*w as f32).sqrt()).collect();
        FacePixels { solid_angle, cone }
    }
}

impl<'a> GatherCubes<'a> {
    /// Cubes over `lit` with the scene's cube settings.
    pub fn new(lit: &'a LitVolume, scene: &Scene) -> Self {
        let opts = CubeOptions {
            step_level_voxels: scene.render.cubes.gather_step_level_voxels,
            ..scene.render.cubes.clone()
        };
        let mut renderer = CubeRenderer::new(lit, &opts);
        // With the surface layer (`render.surface_depth` > 0) the cubes see the dense cloud around
        // them, and what they see is scattered again by the orders: the cloud emits the gather's
        // own diffuse source, and the sun's single scattering uses the δ-M medium's (a′, g′) —
        // the TMS pair would count the forward peak twice, once in the δ-M transmittance
        // (docs/edges.md, "The surface layer"). Off: the paper's cubes.
        let surface = scene.render.edges.surface_depth > 0.0;
        renderer.gather_source = surface;
        renderer.sun_transformed = surface;
        let cone_res = scene.render.edges.cube_res;
        // Points no wider than an eighth of the narrowest cube pixel (a third of its edge 2/res, in
        // rad, at a face's corner), as the ground's hemicubes take the map.
        let sky = match &lit.sky.kind {
            SkyKind::EnvMap { map } => map.split_bright(SKY_POINTS_OVER_MEAN, 2.0 / (3.0 * cone_res as f64) / 8.0),
            _ => None,
        };
        GatherCubes {
            renderer,
            exclude_radius: lit.medium.min_voxel(),
            rear_half_resolution: true,
            faces: FacePixels::new(cone_res),
            cone_res,
            sky,
        }
    }

    /// Distance along `d` from the cube centre at which a ray leaves the segment's cells: the
    /// tube of radius `exclude_radius` around the segment (paper section 6: the cells S_j crosses
    /// are excluded, their scattering is what the orders count).
    fn exclusion_start(&self, req: &CubeRequest, d: Vec3) -> f32 {
        let (a, b) = req.exclude;
        let axis = b - a;
        let len = axis.length();
        if len <= 0.0 {
            return 0.0;
        }
        let x = axis / len;
        let s_c = (req.center - a).dot(x).clamp(0.0, len);
        let along = d.dot(x);
        let t_axial = if along > 1e-6 {
            (len - s_c) / along
        } else if along < -1e-6 {
            s_c / -along
        } else {
            f32::INFINITY
        };
        let perp = (d - x * along).length();
        let t_tube = if perp > 1e-6 { self.exclude_radius / perp } else { f32::INFINITY };
        let t = t_axial.min(t_tube);
        if t.is_finite() {
            t
        } else {
            0.0
        }
    }
}

impl CubeSource for GatherCubes<'_> {
    /// The front face (local +x, along the viewing ray, where the forward-peaked orders weigh
    /// most): its central half (a quarter of its pixels) at full resolution, its outer ring at
    /// half; the five rear faces, whose HG weights are small and smooth, at half resolution, each
    /// trace filling a 2×2 block (the paper's sampling patterns: rear faces at half the front's
    /// density, the front's centre densest).
    fn render_cube(&self, req: &CubeRequest) -> CubeImage {
        let mut cube = CubeImage::along(req.res, req.x_axis);
        let res = req.res;
        let own;
        let faces = if res == self.cone_res {
            &self.faces
        } else {
            own = FacePixels::new(res);
            &own
        };
        let cones = &faces.cone;
        // The sky points' power (W/m² per band) in each pixel of this cube.
        let points = self.sky.as_ref().map(|split| {
            let mut power = vec![[0f64; 3]; 6 * res * res];
            let to_local = cube.axes.transpose();
            for (d, p) in &split.points {
                for (s, x) in power[cube_pixel(res, to_local * *d)].iter_mut().zip(p) {
                    *s += x;
                }
            }
            (split, power)
        });
        // Radiance from `d` for pixels `ks` (one, or a block that one trace fills): with a split
        // map, the sky behind is its base on `d` plus the points' mean over the pixels.
        let trace = |d: Vec3, cone: f32, ks: &[usize]| {
            let t0 = self.exclusion_start(req, d);
            let o = req.center + d * t0;
            let Some((split, power)) = &points else {
                return self.renderer.trace(o, d, cone);
            };
            let (mut sum, mut area) = ([0f64; 3], 0f64);
            for &k in ks {
                for (s, x) in sum.iter_mut().zip(power[k]) {
                    *s += x;
                }
                area += faces.solid_angle[k % (res * res)];
            }
            let mean = Rgb::new((sum[0] / area) as f32, (sum[1] / area) as f32, (sum[2] / area) as f32);
            self.renderer.trace_to_sky(o, d, cone, split.base_radiance(d) + mean)
        };
        let pixel = |cube: &mut CubeImage, face: usize, i: usize, j: usize| {
            let k = cube.index(face, i, j);
            cube.pixels[k] = trace(cube.direction(face, i, j), cones[j * res + i], &[k]);
        };
        if res < 2 || res % 2 != 0 || !self.rear_half_resolution {
            for face in 0..6 {
                for j in 0..res {
                    for i in 0..res {
                        pixel(&mut cube, face, i, j);
                    }
                }
            }
            return cube;
        }
        let half = res / 2;
        // Blocks half/4..3·half/4 on both axes: the front face's central half (its pixels within
        // about 27° of the ray for res 8).
        let central = half / 4..half - half / 4;
        for face in 0..6 {
            for bj in 0..half {
                for bi in 0..half {
                    if face == 0 && central.contains(&bi) && central.contains(&bj) {
                        for (i, j) in block_pixels(bi, bj) {
                            pixel(&mut cube, face, i, j);
                        }
                        continue;
                    }
                    let local = CubeImage::local_direction(half, face, bi, bj);
                    let d = (cube.axes * local).normalize();
                    let ks = block_pixels(bi, bj).map(|(i, j)| cube.index(face, i, j));
                    let l = trace(d, 2.0 * cones[(2 * bj) * res + 2 * bi], &ks);
                    for k in ks {
                        cube.pixels[k] = l;
                    }
                }
            }
        }
        cube
    }
}

/// The four pixels of 2×2 block (bi, bj) of a face.
fn block_pixels(bi: usize, bj: usize) -> [(usize, usize); 4] {
    [
        (2 * bi, 2 * bj),
        (2 * bi + 1, 2 * bj),
        (2 * bi, 2 * bj + 1),
        (2 * bi + 1, 2 * bj + 1),
    ]
}

/// Shortest compositing step of the final gather (voxels): above a dual cell's diagonal (√3), so
/// each profile piece (at most one dual cell) is one step with its own Simpson depth and midpoint
/// density, no further look-ups. Measured against `render.step` (0.5): block MRE ≤ 5·10⁻⁶ on the
/// default scene, the composite's instructions ÷2.8 (docs/performance.md).
const GATHER_STEP_VOXELS: f32 = 2.0;

/// Final gather over a propagated scene: the image, with AOV layers when `render.aov` is set.
/// K is computed sparsely and interpolated across pixels where neighbouring cubes lie at similar
/// depths ([`crate::edges::sparse`], the paper's speed-up); `render.aa_samples` > 1 averages whole
/// gathers at jittered pixel positions, 1 shades pixel centres and re-shades the edge pixels
/// with [`EDGE_SAMPLES`] sub-pixels ([`crate::render::edge_pixels`]).
pub fn gather(scene: &Scene, lit: &LitVolume, progress: &dyn Progress) -> Image {
    let cubes = GatherCubes::new(lit, scene);
    let m = &lit.medium;
    let sun_e = lit.sun.irradiance;
    let sun_at = move |p: Vec3| sun_e * lit.sun_t().trilinear(m.to_voxel(p).to_array());
    let sun = SunInput {
        dir: lit.sun.dir,
        irradiance_at: &sun_at,
    };
    let albedo = m.optics.albedo;
    let dense = move |p: Vec3, to_eye: Vec3| {
        // a·I0, or a·max(0, I0 + g·I1·ω) with the first moment ([`LitVolume::diffuse`]).
        albedo * lit.diffuse_at(p, to_eye)
    };
    let mut settings = scene.render.edges;
    settings.step_m = gather_step(scene, lit);
    let edge = EdgeGather::new(m, settings, &cubes, sun, &dense).with_peak_spread(sun_e);
    // The sun's chord weights the surface layer's sun orders ≥ 2 (docs/edges.md); the paper's
    // scheme (no layer, D_s = 0) keeps eq. 8 alone.
    let chord = (settings.surface_depth > 0.0).then(|| SunChord::new(m, lit.sun.dir, lit.sun_t().clone(), settings.surface_depth));
    let edge = match &chord {
        Some(c) => edge.with_sun_chord(c),
        None => edge,
    };
    let cam = &scene.camera;
    let spp = scene.render.aa_samples;
    let n = cam.width as usize * cam.height as usize;
    let mut sum = vec![[Rgb::ZERO; 4]; n];
    // Sample `s` of `spp` in pixel (x, y).
    let pixel_ray = |x: u32, y: u32, s: u32, spp: u32| {
        let (px, py, _) = pixel_sample(scene, x, y, s, spp);
        let r = cam.ray(px, py);
        let t_ground = lit.ground_hit(r.origin, r.dir);
        PixelRay {
            o: r.origin,
            d: r.dir,
            t_max: t_ground.unwrap_or(f32::INFINITY),
            background: lit.background(r.origin, r.dir, t_ground),
        }
    };
    progress.begin("final gather", spp as u64);
    for s in 0..spp {
        if progress.cancelled() {
            break;
        }
        let ray = |x: u32, y: u32| pixel_ray(x, y, s, spp);
        let (aovs, stats) = gather_image(&edge, cam.width, cam.height, &ray, Some(SparseSettings::default()));
        progress.log(&format!(
            "final gather: {} cubes rendered, K interpolated for {} segments, own cube for {}",
            stats.cubes, stats.interpolated, stats.direct
        ));
        for (acc, a) in sum.iter_mut().zip(&aovs) {
            acc[0] += a.diffusion;
            acc[1] += a.edge;
            acc[2] += a.sun_single;
            acc[3] += a.background;
        }
        progress.advance(1);
        // A live view sees the mean of the samples so far (no extra work: the gather is the
        // pipeline's only image).
        if progress.wants_images() && s + 1 < spp {
            let mut live = Image::new(cam.width, cam.height);
            let k = 1.0 / (s + 1) as f32;
            live.pixels = sum.iter().map(|a| (a[0] + a[1] + a[2] + a[3]) * k).collect();
            progress.image(&live);
        }
    }
    if spp == 1 && !progress.cancelled() {
        let n_edges = refine_edge_pixels(&edge, cam.width, &mut sum, &pixel_ray);
        progress.log(&format!("final gather: {n_edges} edge pixels re-shaded with {EDGE_SAMPLES} samples"));
    }
    let k = 1.0 / spp as f32;
    let mut img = Image::new(cam.width, cam.height);
    img.pixels = sum.iter().map(|a| (a[0] + a[1] + a[2] + a[3]) * k).collect();
    if scene.render.aov {
        for (c, name) in ["diffusion", "low_density", "sun_single", "background"].iter().enumerate() {
            img.add_layer(name, sum.iter().map(|a| a[c] * k).collect());
        }
    }
    img
}

/// Image rows re-shaded by one sparse sub-pixel gather ([`refine_edge_pixels`]): 4 rows of
/// `EDGE_GRID` = 4 sub-pixels are 16 sub-pixel rows, the sparse gather's largest square, and a
/// band's memory stays that of 16 image rows at 4× the width.
const EDGE_BAND_ROWS: u32 = 4;

/// Re-shade the edge pixels ([`edge_pixels`]) of a one-sample image `px` (parts diffusion, edge,
/// sun single scattering, background) as their mean over `EDGE_GRID`² sub-pixels: per band of
/// [`EDGE_BAND_ROWS`] rows holding an edge, one sparse gather over the band at `EDGE_GRID`× the
/// resolution, only the sub-pixels of edge pixels (K interpolated between sub-pixels as between
/// pixels). `pixel_ray(x, y, s, n)` is sample s of n in pixel (x, y). Returns the number of
/// pixels re-shaded.
fn refine_edge_pixels(
    edge: &EdgeGather,
    width: u32,
    px: &mut [[Rgb; 4]],
    pixel_ray: &(dyn Fn(u32, u32, u32, u32) -> PixelRay + Sync),
) -> usize {
    let edges = edge_pixels(px, width);
    let (w, height) = (width as usize, (px.len() / width.max(1) as usize) as u32);
    let mut is_edge = vec![false; px.len()];
    for &i in &edges {
        is_edge[i] = true;
        px[i] = [Rgb::ZERO; 4];
    }
    let sub_w = w * EDGE_GRID as usize;
    for y0 in (0..height).step_by(EDGE_BAND_ROWS as usize) {
        let rows = EDGE_BAND_ROWS.min(height - y0);
        if !is_edge[y0 as usize * w..(y0 + rows) as usize * w].contains(&true) {
            continue;
        }
        // Band sub-pixel (x, y) → pixel and its sample (pixel_sample's strata).
        let parent = |x: u32, y: u32| {
            let y = y + y0 * EDGE_GRID;
            (x / EDGE_GRID, y / EDGE_GRID, (y % EDGE_GRID) * EDGE_GRID + x % EDGE_GRID)
        };
        let pixel_of = |k: usize| {
            let (x, y, _) = parent((k % sub_w) as u32, (k / sub_w) as u32);
            y as usize * w + x as usize
        };
        let sub_ray = |x: u32, y: u32| {
            let (x, y, s) = parent(x, y);
            pixel_ray(x, y, s, EDGE_SAMPLES)
        };
        let wanted = |k: usize| is_edge[pixel_of(k)];
        let sparse = Some(SparseSettings::default());
        let (sub, _) = gather_pixels(edge, width * EDGE_GRID, rows * EDGE_GRID, &sub_ray, sparse, &wanted);
        for (k, a) in sub.iter().enumerate() {
            let i = pixel_of(k);
            if is_edge[i] {
                for (c, v) in px[i].iter_mut().zip([a.diffusion, a.edge, a.sun_single, a.background]) {
                    *c += v * (1.0 / EDGE_SAMPLES as f32);
                }
            }
        }
    }
    edges.len()
}

/// Render the image.
pub fn render(scene: &Scene, progress: &dyn Progress, timings: &mut Timings) -> Result<Image> {
    Ok(render_warm(scene, progress, timings, WarmSolve::default())?.0)
}

/// [`render`] as a frame of a sequence: the first diffusion solve starts from `warm.start` and,
/// with `warm.keep`, its solution is handed on ([`propagate_from`]); also the solves' CG
/// iterations.
pub fn render_warm(scene: &Scene, progress: &dyn Progress, timings: &mut Timings, warm: WarmSolve) -> Result<(Image, Option<DiffusionState>, usize)> {
    let p = propagate_from(scene, progress, timings, warm)?;
    // The solution and stage-1 light are dead once the lit volume holds what the gather needs.
    let Propagation {
        lit,
        cg_iterations,
        first_state: state,
        ..
    } = p;
    let img = timings.time("final gather", || gather(scene, &lit, progress));
    let share = timings.time("final gather: beam check", || full_beam::share(scene, &lit, &img, gather_step(scene, &lit)));
    beam_check::report(scene, "full", share, progress);
    Ok((img, state, cg_iterations))
}

/// The final gather's march step (m): the edges' step, at least [`GATHER_STEP_VOXELS`] voxels.
fn gather_step(scene: &Scene, lit: &LitVolume) -> f32 {
    scene.render.edges.step_m.max(GATHER_STEP_VOXELS * lit.medium.min_voxel())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::{EnvMap, Sky, Sun};
    use crate::medium::{Grid3, Medium};

    /// An empty scene under a map sky of 0.5 W·m⁻²·sr⁻¹ with a sun one map pixel wide (10⁸ times
    /// brighter; a map pixel is 1/20 to 1/40 of a res-16 cube pixel's solid angle): a gather cube
    /// holds the map's ∫ L dω whatever pixel's axis the sun lies near, for any orientation. A
    /// sample on each pixel's axis misses the sun (2π against 20,505 for the first) or counts it
    /// over the pixel's whole solid angle.
    #[test]
    fn a_sun_one_map_pixel_wide_reaches_a_gather_cube_by_its_power() {
        let scene = Scene::from_toml("[medium]\nresolution = [4, 4, 4]").unwrap();
        let res = scene.render.edges.cube_res;
        let (w, h) = (256, 128);
        let centre = Vec3::new(3.0, -1.0, 2.0);
        for (i, j) in [(20, 30), (101, 61), (200, 90)] {
            let mut pixels = vec![Rgb::splat(0.5); w * h];
            pixels[j * w + i] = Rgb::splat(5e7);
            let map = EnvMap::new(w, h, pixels);
            // ∫ L dω of the bilinear map, in sub-pixels far finer than the cubes'.
            let mut exact = 0.0;
            map.for_each_subpixel(0..h, 16, &mut |_, l, dw| exact += l.x as f64 * dw);
            let sun = Sun {
                dir: Vec3::Y,
                irradiance: Rgb::ZERO,
            };
            let empty = Medium::new(Grid3::filled([2, 2, 2], 0.0), Vec3::ZERO, Vec3::ONE, 1.0, Rgb::ONE, 0.0);
            let lit = LitVolume::new(empty, vec![Rgb::ZERO; 8], Grid3::filled([2, 2, 2], 1.0), sun, Sky::from_envmap(map), None);
            let cubes = GatherCubes::new(&lit, &scene);
            for x_axis in [Vec3::X, Vec3::new(0.3, -0.5, 0.81), Vec3::new(-0.7, 0.2, -0.3)] {
                let cube = cubes.render_cube(&CubeRequest {
                    center: centre,
                    x_axis: x_axis.normalize(),
                    res,
                    exclude: (centre, centre),
                });
                assert!(cube.pixels.iter().all(|p| p.is_finite() && p.min_element() >= 0.0));
                let total = cube.integrate(|_| 1.0)[0];
                assert!((total / exact - 1.0).abs() < 2e-3, "sun at ({i}, {j}), x {x_axis}: {total} vs {exact}");
            }
        }
    }
}
