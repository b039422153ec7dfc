//! `render.diffuse_anisotropy`: the first moment I1 of the diffuse field (src/diffusion/flux.rs)
//! and the a·(I0 + g·I1·ω) gather source it gives.

use crate::diffusion::flux::{diffuse_flux, FluxField};
use crate::diffusion::{solve_diffusion, BoundaryLight, DiffusionSettings, DiffusionSolution};
use crate::incident::{compute, FirstScattering, IncidentLight, IncidentSettings, IncidentSources};
use crate::lighting::{DirectionBins, Sky, Sun};
use crate::lit::LitVolume;
use crate::math::{Rgb, Vec3};
use crate::medium::field16::Field16;
use crate::medium::sparse::VoxelField;
use crate::medium::{Grid3, Medium};
use crate::render::diffusion::i0_rgb;
use crate::{render::render, Method, NoProgress, Scene};

const TAU_MIN: f64 = crate::diffusion::DEFAULT_MIN_OPTICAL_DEPTH;

/// A uniform cube of n³ voxels, ρ = 1, σt = 1 m⁻¹, 1 m voxels.
fn cube(n: usize, albedo: f32, g: f32) -> Medium {
    Medium::new(Grid3::filled([n; 3], 1.0), Vec3::ZERO, Vec3::ONE, 1.0, Rgb::splat(albedo), g)
}

fn unlit(m: &Medium) -> IncidentLight {
    let src = IncidentSources {
        bin_radiance: vec![Rgb::ZERO; 96],
        sun: None,
    };
    compute(m, &DirectionBins::new(), &src, &IncidentSettings::default(), None)
}

fn solution_of(m: &Medium, f: impl Fn(usize, usize, usize) -> f32 + Sync) -> DiffusionSolution {
    let d = m.dims();
    let index = m.density.full_index();
    let packed: Vec<f32> = index
        .full_voxels()
        .map(|g| f(g % d[0], (g / d[0]) % d[1], g / (d[0] * d[1])))
        .collect();
    let v = Field16::new(index, &packed);
    DiffusionSolution {
        dims: d,
        i0: [v.clone(), v.clone(), v],
        stats: Default::default(),
        boundary: BoundaryLight::none(),
    }
}

#[test]
fn flux_is_ficks_law_in_the_interior() {
    // Central differences are exact for linear fields: in voxels whose six neighbours are full,
    // a constant I0 gives I1 = 0, a linear one −∇I0/(ρσtr), and a constant Q1 adds 3Q1/(ρσtr).
    let n = 8;
    let (a, g) = (0.9f32, 0.5f32);
    let m = cube(n, a, g);
    let sigma_tr = 1.0 - a * g;
    let mut inc = unlit(&m);
    // I1 at every voxel (all are full), evaluated before stage 1's light is replaced below.
    let all = |f: &dyn Fn(usize) -> [Vec3; 3]| (0..n * n * n).map(f).collect::<Vec<_>>();
    let constant = all(&diffuse_flux(&m, &inc, &solution_of(&m, |_, _, _| 2.0), TAU_MIN));
    // Multiples of 2⁻⁴ below 8: held exactly by the solution's 16-bit I0.
    let grad = Vec3::new(0.125, 0.25, -0.0625);
    let linear = solution_of(&m, |i, j, k| 3.0 + grad.dot(Vec3::new(i as f32, j as f32, k as f32)));
    let lin = all(&diffuse_flux(&m, &inc, &linear, TAU_MIN));
    let q1 = Vec3::new(0.02, -0.01, 0.03);
    let field = |v: f32| VoxelField::filled(m.density.full_index(), Rgb::splat(v));
    inc.scattering = FirstScattering::General {
        q0: field(0.0),
        q1: [field(q1[0]), field(q1[1]), field(q1[2])],
    };
    let with_q1 = all(&diffuse_flux(&m, &inc, &linear, TAU_MIN));
    let want_lin = -grad / sigma_tr;
    let want_q1 = want_lin + 3.0 * q1 / sigma_tr;
    let mut boundary_outward = 0;
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let idx = i + n * (j + n * k);
                let interior = [i, j, k].iter().all(|&c| c > 0 && c < n - 1);
                if interior {
                    for c in 0..3 {
                        assert!(constant[idx][c].length() < 1e-6, "constant I0: I1 = {:?}", constant[idx][c]);
                        assert!((lin[idx][c] - want_lin).length() < 1e-5, "{:?} vs {want_lin:?}", lin[idx][c]);
                        assert!((with_q1[idx][c] - want_q1).length() < 1e-5, "{:?} vs {want_q1:?}", with_q1[idx][c]);
                    }
                } else if i == 0 && j > 0 && j < n - 1 && k > 0 && k < n - 1 {
                    // On the −x face a constant I0 leaks out through the Marshak boundary: I1_x < 0.
                    assert!(constant[idx][0].x < 0.0);
                    boundary_outward += 1;
                }
            }
        }
    }
    assert!(boundary_outward > 0);
}

/// The built-in cloud's extent on 20×16×12 voxels, 16×12 pixels: the comparisons below are exact
/// per pixel, so any image of the cloud shows whether the term is wired in.
fn small_scene(g: f32, method: Method, aniso: bool) -> Scene {
    Scene::load(None, |d| {
        d.medium.resolution = [20, 16, 12];
        d.medium.voxel_size = 50.0.into();
        d.medium.g = g;
        d.camera.width = 16;
        d.camera.height = 12;
        d.render.method = method;
        d.render.diffuse_anisotropy = aniso;
    })
    .unwrap()
}

#[test]
fn zero_g_changes_nothing() {
    // With g = 0 the term g·I1·ω vanishes: both methods give bit-identical images.
    for method in [Method::Diffusion, Method::Full] {
        let off = render(&small_scene(0.0, method, false), &NoProgress).unwrap().image;
        let on = render(&small_scene(0.0, method, true), &NoProgress).unwrap().image;
        assert_eq!(off.pixels, on.pixels, "{method:?}");
        // And with g = 0.9 it does change the image (the option is wired in).
        let off9 = render(&small_scene(0.9, method, false), &NoProgress).unwrap().image;
        let on9 = render(&small_scene(0.9, method, true), &NoProgress).unwrap().image;
        assert_ne!(off9.pixels, on9.pixels, "{method:?}");
    }
}

#[test]
fn slab_lit_from_above_is_brighter_below_darker_above() {
    // A slab (optical depth 6, g = 0.8) under a vertical sun: the diffuse flux points down, so the
    // forward term brightens the slab seen from below (transmitted light) and darkens it from above.
    let d = [10, 10, 10];
    let mut grid = Grid3::filled(d, 0.0);
    for k in 0..d[2] {
        for j in 2..8 {
            for i in 0..d[0] {
                grid.set(i, j, k, 1.0);
            }
        }
    }
    let m = Medium::new(grid, Vec3::ZERO, Vec3::ONE, 1.0, Rgb::splat(0.99), 0.8);
    let src = IncidentSources {
        bin_radiance: vec![Rgb::ZERO; 96],
        sun: Some((Vec3::Y, Rgb::ONE)),
    };
    let inc = compute(&m, &DirectionBins::new(), &src, &IncidentSettings::default(), None);
    let settings = DiffusionSettings::default();
    let sol = solve_diffusion(&m, &inc, &BoundaryLight::none(), None, &settings).unwrap();
    let i1 = diffuse_flux(&m, &inc, &sol, settings.min_optical_depth);
    let sun = Sun {
        dir: Vec3::Y,
        irradiance: inc.sun_irradiance,
    };
    let sun_t = crate::lit::sunlight::SunTransmittance::compute(&m, Vec3::Y).grid;
    let off = LitVolume::new(m.clone(), i0_rgb(&sol), sun_t, sun, Sky::constant(Rgb::ZERO), None);
    let on = off.clone().with_flux(FluxField::new(&m, &i1));
    for j in 2..8 {
        let idx = 5 + d[0] * (j + d[1] * 5);
        assert!(i1(idx)[1].y < 0.0, "layer {j}: I1 = {:?}", i1(idx)[1]);
        let v = Vec3::new(5.5, j as f32 + 0.5, 5.5);
        // The source takes the direction to the eye: −Y is an eye below looking up.
        let below = (on.source(v, 1.0, -Vec3::Y) - off.source(v, 1.0, -Vec3::Y)).y;
        let above = (on.source(v, 1.0, Vec3::Y) - off.source(v, 1.0, Vec3::Y)).y;
        assert!(below > 0.0, "layer {j}: from below {below}");
        assert!(above < 0.0, "layer {j}: from above {above}");
        // The change is ±a·g·|I1_y| (clamped at zero radiance from above), I1 as the lit volume
        // holds it: ρ·I1 in bf16, within 2⁻⁸ of it (ρ = 1 at the voxel centre).
        let want = 0.99 * 0.8 * -i1(idx)[1].y;
        assert!((below - want).abs() <= want / 256.0 + 1e-4 * want.max(1e-3), "{below} vs {want}");
    }
}
