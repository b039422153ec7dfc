//! Stage 1 (incident light), stage 2 (diffusion operator and MGPCG solver), the slab check, and
//! the diffusion render.

use crate::diffusion::slab::{default_cells, slab_forward_fraction, solve_slab, solve_slab_similar, Incidence};
use crate::diffusion::{boundary_outflow, solve_diffusion, solve_diffusion_lean, BoundaryLight, DiffusionSettings};
use crate::incident::{compute, IncidentLight, IncidentSettings, IncidentSources};
use crate::lighting::DirectionBins;
use crate::math::{Rgb, Vec3};
use crate::medium::{Grid3, Medium};
use crate::render::diffusion::{boundary_light, compute_incident};
use crate::{Error, Method, NoProgress, Scene};
use std::f64::consts::PI;

/// Analytic solution of the 1-D eq. 4 with eq. 7 for a slab under a normal beam (E = 1):
/// Q0 = σs/(4π) e^{−σt z}, Q1 = g Q0; returns (R, T) as 2π I0 at the faces (+ e^{−τ} for T).
fn analytic_slab(tau: f64, a: f64, g: f64) -> (f64, f64) {
    let (st, l) = (1.0, tau);
    let ss = a * st;
    let sa = st - ss;
    let str_ = st * (1.0 - a * g);
    let (qa, qb) = (ss / (4.0 * PI), ss * g / (4.0 * PI));
    // I0'' /(3σtr) − σa I0 = −Q0 + Q1'/σtr with Q0 = qa e^{−z}, Q1 = qb e^{−z}:
    let c = -(qa + st * qb / str_) / (st * st / (3.0 * str_) - sa);
    let k = (3.0 * sa * str_).sqrt();
    // I0 = c e^{−z} + p e^{kz} + q e^{−kz}; BCs:
    // z = 0: I0 − 2/(3σtr) I0' + 2/σtr Q1 = 0;  z = L: I0 + 2/(3σtr) I0' − 2/σtr Q1 = 0.
    let w = 2.0 / (3.0 * str_);
    let q1_0 = qb;
    let q1_l = qb * (-st * l).exp();
    // Row 0: p(1 − w k) + q(1 + w k) = −[c(1 + w st) + 2 q1_0/σtr]
    let (a11, a12, r1) = (1.0 - w * k, 1.0 + w * k, -(c * (1.0 + w * st) + 2.0 * q1_0 / str_));
    let el = (-st * l).exp();
    let (ekl, emkl) = ((k * l).exp(), (-k * l).exp());
    // Row L: p e^{kL}(1 + w k) + q e^{−kL}(1 − w k) = −[c e^{−L}(1 − w st) − 2 q1_L/σtr]
    let (a21, a22, r2) = (
        ekl * (1.0 + w * k),
        emkl * (1.0 - w * k),
        -(c * el * (1.0 - w * st) - 2.0 * q1_l / str_),
    );
    let det = a11 * a22 - a12 * a21;
    let p = (r1 * a22 - a12 * r2) / det;
    let q = (a11 * r2 - a21 * r1) / det;
    let i0 = |z: f64| c * (-st * z).exp() + p * (k * z).exp() + q * (-k * z).exp();
    (2.0 * PI * i0(0.0), 2.0 * PI * i0(l) + el)
}

#[test]
fn slab_matches_analytic_diffusion_solution() {
    // The discretisation converges to the continuous diffusion solution; at 0.01 optical depth per
    // cell the difference is well below 0.5 % (measured ~1e-4).
    for (tau, a, g) in [(2.0, 0.9, 0.0), (5.0, 0.99, 0.5), (10.0, 0.95, 0.9)] {
        let (r_exact, t_exact) = analytic_slab(tau, a, g);
        let s = solve_slab(tau, a, g, Incidence::Collimated, (tau / 0.01) as usize);
        assert!(
            (s.r - r_exact).abs() < 5e-3 * r_exact.max(0.01),
            "tau {tau} a {a} g {g}: R {} vs {r_exact}",
            s.r
        );
        assert!(
            (s.t - t_exact).abs() < 5e-3 * t_exact.max(0.01),
            "tau {tau} a {a} g {g}: T {} vs {t_exact}",
            s.t
        );
    }
}

#[test]
fn slab_against_adding_doubling() {
    // Diffusion is accurate for thick, highly scattering slabs. Rows with reduced optical depth
    // (1 − g)τ ≥ 5 and albedo ≥ 0.99: R and T within 0.04 absolute (measured worst ~0.03, see
    // docs/accuracy.md). Thin or absorbing slabs are not expected to agree and are not tested.
    let mut checked = 0;
    for v in super::common::slab_rows() {
        let (tau, a, g) = (v[0], v[1], v[2]);
        if (1.0 - g) * tau < 5.0 || a < 0.99 {
            continue;
        }
        let n = solve_slab(tau, a, g, Incidence::Collimated, default_cells(tau));
        let d = solve_slab(tau, a, g, Incidence::Diffuse, default_cells(tau));
        for (name, got, want) in [("UR1", n.r, v[3]), ("UT1", n.t, v[4]), ("URU", d.r, v[5]), ("UTU", d.t, v[6])] {
            assert!((got - want).abs() < 0.04, "tau {tau} a {a} g {g} {name}: {got:.4} vs {want:.4}");
        }
        checked += 1;
    }
    assert!(checked >= 10, "only {checked} rows");
}

#[test]
fn delta_m_slab_against_adding_doubling() {
    // With the δ-M transform (f = g²) every row of reduced optical depth (1 − g)τ ≥ 1, absorbing
    // rows included: R and T within 0.03 absolute, never negative (measured worst: docs/budget.md).
    let mut checked = 0;
    let mut worst: f64 = 0.0;
    for v in super::common::slab_rows() {
        let (tau, a, g) = (v[0], v[1], v[2]);
        let f = slab_forward_fraction(g);
        let n = solve_slab_similar(tau, a, g, f, Incidence::Collimated);
        let d = solve_slab_similar(tau, a, g, f, Incidence::Diffuse);
        for x in [n.r, n.t, d.r, d.t] {
            assert!(x >= 0.0 && x.is_finite(), "tau {tau} a {a} g {g}: {n:?} {d:?}");
        }
        if (1.0 - g) * tau < 1.0 {
            continue;
        }
        for (name, got, want) in [("UR1", n.r, v[3]), ("UT1", n.t, v[4]), ("URU", d.r, v[5]), ("UTU", d.t, v[6])] {
            worst = worst.max((got - want).abs());
            assert!((got - want).abs() < 0.03, "tau {tau} a {a} g {g} {name}: {got:.4} vs {want:.4}");
        }
        checked += 1;
    }
    assert!(checked >= 30, "only {checked} rows");
    eprintln!("δ-M slab: {checked} rows, worst |error| {worst:.4}");
}

#[test]
fn q0_q1_homogeneous_box_under_vertical_sun_and_one_bin() {
    // 4×6×3 box, ρ = 0.8, σt = 0.5 m⁻¹, voxels 2×1.5×1 m, sun straight down (E = 2). Layer j (from
    // the top) has voxel-mean transmittance e^{−κ h j}(1 − e^{−κh})/(κh). Stage 1 keeps ρT̄ in 16
    // bits (≤ 2⁻¹² relative) besides its sweep's ~1e-5.
    let (rho, st, a, g) = (0.8f32, 0.5f32, 0.9f32, 0.6f32);
    let m = Medium::new(
        Grid3::filled([4, 6, 3], rho),
        Vec3::ZERO,
        Vec3::new(2.0, 1.5, 1.0),
        st,
        Rgb::splat(a),
        g,
    );
    let src = IncidentSources {
        bin_radiance: vec![Rgb::ZERO; 96],
        sun: Some((Vec3::Y, Rgb::splat(2.0))),
    };
    let inc = compute(&m, &DirectionBins::new(), &src, &IncidentSettings::default(), None);
    let kh = (rho * st * 1.5) as f64;
    for j in 0..6 {
        let depth = 5 - j; // layers counted from the top
        let tbar = (-kh * depth as f64).exp() * (1.0 - (-kh).exp()) / kh;
        let q0 = (rho * a * st) as f64 / (4.0 * PI) * 2.0 * tbar;
        for (i, k) in [(0, 0), (3, 2), (1, 1)] {
            let idx = i + 4 * (j + 6 * k);
            assert!(
                (inc.q0(idx, 0) as f64 - q0).abs() < (1e-5 + 1.0 / 4096.0) * q0,
                "layer {j}: {} vs {q0}",
                inc.q0(idx, 0)
            );
            assert!((inc.q1(1, idx, 1) as f64 + g as f64 * q0).abs() < (1e-5 + 1.0 / 4096.0) * q0);
            assert!(inc.q1(0, idx, 2).abs() < 1e-9 && inc.q1(2, idx, 0).abs() < 1e-9);
        }
    }
    // One bin of radiance L and a nearly transparent box: Q0 = ρσs/(4π)·Δω·L in every voxel,
    // Q1 = g·Q0·(−mean direction of the bin).
    let bins = DirectionBins::new();
    let thin = Medium::new(
        Grid3::filled([5, 4, 6], 1e-7),
        Vec3::ZERO,
        Vec3::new(1.0, 2.0, 1.5),
        1.0,
        Rgb::ONE,
        0.5,
    );
    for b in [3usize, 40, 77] {
        let mut r = vec![Rgb::ZERO; 96];
        r[b] = Rgb::splat(1.5);
        let inc = compute(
            &thin,
            &bins,
            &IncidentSources {
                bin_radiance: r,
                sun: None,
            },
            &IncidentSettings::default(),
            None,
        );
        let q0 = 1e-7 / (4.0 * PI) * bins.bins[b].solid_angle * 1.5;
        let q1 = -bins.bins[b].mean_dir * (0.5 * q0) as f32;
        for idx in 0..inc.dims.iter().product() {
            assert!(
                (inc.q0(idx, 1) as f64 - q0).abs() < 1e-5 * q0,
                "bin {b} voxel {idx}: {} vs {q0}",
                inc.q0(idx, 1)
            );
            for ax in 0..3 {
                assert!((inc.q1(ax, idx, 1) - q1[ax]).abs() < 1e-5 * q0 as f32);
            }
        }
    }
}

#[test]
fn energy_balance_with_albedo_one() {
    // Albedo 1, box under a vertical sun: the diffuse power leaving through the cloud's boundary
    // must equal the power removed from the beam, E·A·(1 − e^{−τ}) (exact for the discrete scheme
    // up to the solver tolerance 1e-10 and the storage: the solver keeps each row's sum, here the
    // boundary's leakage, to its 16-bit rounding, and I0 is stored in 16 bits, each ≤ 2⁻¹² of
    // itself; the balance came out within 5.3·10⁻⁵ and 1.4·10⁻⁵ with each alone, within 10⁻⁶ in f32).
    let m = Medium::new(Grid3::filled([6, 8, 5], 1.0), Vec3::ZERO, Vec3::ONE, 0.4, Rgb::ONE, 0.7);
    let src = IncidentSources {
        bin_radiance: vec![Rgb::ZERO; 96],
        sun: Some((Vec3::Y, Rgb::splat(3.0))),
    };
    let inc = compute(&m, &DirectionBins::new(), &src, &IncidentSettings::default(), None);
    let settings = DiffusionSettings {
        tolerance: 1e-10,
        max_iterations: 500,
        min_optical_depth: 0.0,
        sky_boundary: false,
    };
    let sol = solve_diffusion(&m, &inc, &BoundaryLight::none(), None, &settings).unwrap();
    let out = boundary_outflow(&m, &inc, &sol, 0.0);
    let removed = 3.0 * 6.0 * 5.0 * (1.0 - (-0.4f64 * 8.0).exp());
    assert!(
        ((out.x as f64) - removed).abs() < removed / 4096.0,
        "out {} removed {removed}",
        out.x
    );
    // All I0 positive deep inside, and the solution is symmetric under x ↦ 5 − x (vertical sun).
    for k in 0..5 {
        for j in 0..8 {
            for i in 0..6 {
                let v = sol.at(i, j, k).x;
                let w = sol.at(5 - i, j, k).x;
                assert!((v - w).abs() <= 1e-5 * v.abs().max(1e-3), "asymmetric {v} {w}");
            }
        }
    }
}

fn default_small() -> Scene {
    Scene::load(None, |d| {
        d.medium.resolution = [50, 40, 30];
        d.medium.voxel_size = 20.0.into();
        d.camera.width = 64;
        d.camera.height = 48;
    })
    .unwrap()
}

#[test]
fn convergence_independent_of_resolution_warm_start_and_failure() {
    // The default cloud at full and half resolution: the mean residual reduction per PCG
    // iteration stays below 0.8 for both (measured ~0.66 and ~0.6).
    let full = Scene::default_scene().unwrap();
    let half = default_small();
    let mut iters = vec![];
    for scene in [&half, &full] {
        let inc = compute_incident(scene, None);
        let sol = solve_diffusion(&scene.medium, &inc, &boundary_light(scene), None, &DiffusionSettings::default()).unwrap();
        for s in &sol.stats {
            assert!(s.relative_residual <= DiffusionSettings::default().tolerance);
            assert!(
                s.convergence_factor() < 0.8,
                "factor {} ({} iterations)",
                s.convergence_factor(),
                s.iterations
            );
        }
        iters.push(sol.stats[0].iterations);
        if std::ptr::eq(scene, &half) {
            // Warm start from the solution of a slightly brighter sky converges in fewer iterations.
            let warm = solve_diffusion(
                &scene.medium,
                &inc,
                &boundary_light(scene),
                Some(&sol),
                &DiffusionSettings::default(),
            )
            .unwrap();
            assert!(
                warm.stats[0].iterations < sol.stats[0].iterations / 2,
                "{} vs {}",
                warm.stats[0].iterations,
                sol.stats[0].iterations
            );
            let inc2 = compute(
                &scene.medium,
                &DirectionBins::new(),
                &IncidentSources {
                    bin_radiance: inc.bin_radiance.iter().map(|r| *r * 1.1).collect(),
                    sun: Some((scene.sun.dir, scene.sun.irradiance)),
                },
                &IncidentSettings::default(),
                None,
            );
            let warm2 = solve_diffusion(
                &scene.medium,
                &inc2,
                &boundary_light(scene),
                Some(&sol),
                &DiffusionSettings::default(),
            )
            .unwrap();
            assert!(
                warm2.stats[0].iterations < sol.stats[0].iterations,
                "{} vs {}",
                warm2.stats[0].iterations,
                sol.stats[0].iterations
            );
            // The bands one by one, warm-started in place, and the change from the start is
            // ‖new⁺ − old⁺‖/‖new⁺‖ over all voxels and bands (⁺: clamped at 0).
            let inc3 = compute(
                &scene.medium,
                &DirectionBins::new(),
                &IncidentSources {
                    bin_radiance: inc.bin_radiance.clone(),
                    sun: Some((scene.sun.dir, scene.sun.irradiance * 1.1)),
                },
                &IncidentSettings::default(),
                None,
            );
            let settings = DiffusionSettings::default();
            let warm3 = solve_diffusion(&scene.medium, &inc3, &boundary_light(scene), Some(&sol), &settings).unwrap();
            let (lean, change) =
                solve_diffusion_lean(&scene.medium, &inc3, &boundary_light(scene), Some(sol.i0.clone()), &settings).unwrap();
            // Its solve finds the correction to the coded start from the start's coded residual:
            // the same solution to the solver's tolerance (measured 1.5e-5 relative, L2).
            let (mut dd, mut nn) = (0f64, 0f64);
            for c in 0..3 {
                for (a, b) in lean.i0[c].decoded().iter().zip(warm3.i0[c].decoded()) {
                    dd += f64::from(a - b).powi(2);
                    nn += f64::from(b).powi(2);
                }
            }
            let apart = (dd / nn).sqrt();
            assert!(apart < 1e-4, "one by one and together apart by {apart:e}");
            let (mut num, mut den) = (0f64, 0f64);
            for c in 0..3 {
                for (a, b) in sol.i0[c].decoded().iter().zip(lean.i0[c].decoded()) {
                    let (a, b) = (a.max(0.0) as f64, b.max(0.0) as f64);
                    num += (b - a).powi(2);
                    den += b * b;
                }
            }
            let want = (num / den).sqrt();
            assert!(want > 1e-3, "the brighter sun moves I0: {want}");
            assert!((change - want).abs() <= 1e-12 * want, "{change} vs {want}");
            // Too few iterations: a clear numerical error, never a silent result.
            let err = solve_diffusion(
                &scene.medium,
                &inc,
                &boundary_light(scene),
                None,
                &DiffusionSettings {
                    max_iterations: 2,
                    ..Default::default()
                },
            )
            .unwrap_err();
            assert!(matches!(err, Error::Numerical { .. }), "{err}");
            assert!(err.to_string().contains("solver_max_iterations"), "{err}");
        }
    }
    assert!(iters[1] <= iters[0] + 15, "iterations grow with resolution: {iters:?}");
}

/// Q0 of every grid voxel, in grid order.
fn q0_of(inc: &IncidentLight) -> Vec<Rgb> {
    (0..inc.dims.iter().product())
        .map(|g| Rgb::new(inc.q0(g, 0), inc.q0(g, 1), inc.q0(g, 2)))
        .collect()
}

#[test]
fn deterministic_at_any_thread_count_and_hook_replaces_radiance() {
    let scene = default_small();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let inc = compute_incident(&scene, None);
            let sol = solve_diffusion(&scene.medium, &inc, &boundary_light(&scene), None, &DiffusionSettings::default()).unwrap();
            (q0_of(&inc), sol.i0.clone())
        })
    };
    let (q1, s1) = run(1);
    let (q3, s3) = run(3);
    assert!(q1 == q3 && s1 == s3, "results depend on the thread count");
    // Hook: with no sky and no sun, Q0 is zero; a hook giving radiance L at every entry lights the
    // full voxels next to empty ones.
    let bins = DirectionBins::new();
    let dark = IncidentSources {
        bin_radiance: vec![Rgb::ZERO; 96],
        sun: None,
    };
    let none = compute(&scene.medium, &bins, &dark, &IncidentSettings::default(), Some(&|_, _| None));
    assert!(q0_of(&none).iter().all(|q| *q == Rgb::ZERO));
    let lit = compute(
        &scene.medium,
        &bins,
        &dark,
        &IncidentSettings::default(),
        Some(&|_, _| Some(Rgb::ONE)),
    );
    let rho = &scene.medium.density;
    let n_lit = q0_of(&lit).iter().zip(rho.iter()).filter(|(q, r)| *r > 0.0 && q.x > 0.0).count();
    let n_full = rho.count();
    assert!(n_lit * 10 > n_full * 9, "{n_lit} of {n_full} full voxels lit by the hook");
}

#[test]
fn diffusion_render_is_brighter_than_single_scattering() {
    let mut scene = default_small();
    scene.render.method = Method::Diffusion;
    let d = crate::render::render(&scene, &NoProgress).unwrap();
    scene.render.method = Method::Single;
    let s = crate::render::render(&scene, &NoProgress).unwrap();
    assert!(d.timings.stages.iter().any(|(n, _)| n == "diffusion solve"));
    // Pixels where the cloud is: compare the mean luminance over the image centre.
    let lum = |img: &crate::Image| -> f64 {
        let mut sum = 0.0;
        for y in 16..32 {
            for x in 20..44 {
                let p = img.pixels[(y * 64 + x) as usize];
                assert!(p.is_finite() && p.min_element() >= 0.0);
                sum += crate::math::luminance(p) as f64;
            }
        }
        sum
    };
    let (ld, ls) = (lum(&d.image), lum(&s.image));
    assert!(ld > 1.5 * ls, "diffusion {ld} vs single {ls}");
}

#[test]
fn bad_solver_settings_name_the_field() {
    for (field, edit) in [
        (
            "render.solver_tolerance",
            Box::new(|d: &mut crate::SceneDesc| d.render.solver_tolerance = 0.0) as Box<dyn Fn(&mut crate::SceneDesc)>,
        ),
        (
            "render.solver_tolerance",
            Box::new(|d: &mut crate::SceneDesc| d.render.solver_tolerance = f64::NAN),
        ),
        (
            "render.solver_tolerance",
            Box::new(|d: &mut crate::SceneDesc| d.render.solver_tolerance = 1e-30),
        ),
        (
            "render.solver_max_iterations",
            Box::new(|d: &mut crate::SceneDesc| d.render.solver_max_iterations = 0),
        ),
    ] {
        let err = Scene::load(None, |d| edit(d)).unwrap_err();
        match err {
            Error::Invalid { field: f, .. } => assert_eq!(f, field),
            e => panic!("{e}"),
        }
    }
}

#[test]
fn jittered_direction_strata_keep_the_bin_power() {
    // n² jittered families per bin, weighted by their exact solid angles: in a nearly transparent
    // box Q0 is still ρσs/(4π)·Δω·L (to 1e-5), and Q1 = g·Q0·(−mean direction) to 2 % (the strata's
    // jittered directions sample the bin's first moment).
    let bins = DirectionBins::new();
    let thin = Medium::new(Grid3::filled([6, 5, 4], 1e-7), Vec3::ZERO, Vec3::ONE, 1.0, Rgb::ONE, 0.5);
    let settings = IncidentSettings {
        rays_per_face_edge: 3,
        ..Default::default()
    };
    for b in [5usize, 60] {
        let mut r = vec![Rgb::ZERO; 96];
        r[b] = Rgb::ONE;
        let inc = compute(
            &thin,
            &bins,
            &IncidentSources {
                bin_radiance: r,
                sun: None,
            },
            &settings,
            None,
        );
        let q0 = 1e-7 / (4.0 * PI) * bins.bins[b].solid_angle;
        let q1 = -bins.bins[b].mean_dir * (0.5 * q0) as f32;
        for idx in 0..inc.dims.iter().product() {
            assert!((inc.q0(idx, 0) as f64 - q0).abs() < 1e-5 * q0, "{} vs {q0}", inc.q0(idx, 0));
            let got = Vec3::new(inc.q1(0, idx, 0), inc.q1(1, idx, 0), inc.q1(2, idx, 0));
            assert!((got - q1).length() < 0.02 * q1.length(), "{got} vs {q1}");
        }
    }
}
