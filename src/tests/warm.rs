//! Warm starts across a sequence's frames, end to end through `render_warm`: every solving method
//! starts from the previous frame's state mapped onto a moved and grown grid, and ends where a
//! cold solve does (docs/sequences.md, "Warm starts").

use crate::math::Vec3;
use crate::medium::procedural::cumulus;
use crate::medium::Medium;
use crate::pipeline::NoProgress;
use crate::render::warm::{render_warm, Warm};
use crate::scene::{Method, Scene, SceneDesc};
use crate::tools::compare::compare;
use crate::transport::solve::{solve_warm, SolveOptions};
use crate::transport::warm::IMAGE_ERROR_FRACTION;

/// A small cumulus of 40-m voxels under a sun at `elevation_deg`, its grid grown by `grow`
/// voxels per axis (the cloud stretches with it) and moved `moved_m` metres, with a ground.
fn frame(method: Method, elevation_deg: f32, grow: usize, moved_m: f32) -> Scene {
    let mut d = SceneDesc::default();
    (d.camera.width, d.camera.height) = (32, 24);
    d.render.method = method;
    d.sun.direction = None;
    d.sun.elevation_deg = Some(elevation_deg);
    d.sun.azimuth_deg = Some(40.0);
    let mut s = Scene::build(d, "warm.toml", std::path::Path::new(".")).unwrap();
    let dims = [20 + grow, 16 + grow, 12 + grow];
    let origin = Vec3::new(-400.0 + moved_m, 0.0, -240.0);
    let o = &s.medium.optics;
    s.medium = Medium::new(cumulus(dims, 1), origin, Vec3::splat(40.0), o.sigma_t, o.albedo, s.desc.medium.g);
    s
}

fn block_error(a: &crate::image::Image, b: &crate::image::Image) -> f64 {
    compare(a, b, None).unwrap().block_mean_relative_error.unwrap_or(0.0)
}

#[test]
fn every_solving_method_starts_a_frame_from_the_last_one_and_ends_where_a_cold_solve_does() {
    for method in [Method::Transport, Method::Diffusion, Method::Full] {
        let mut warm = Warm::new(true);
        render_warm(&frame(method, 50.0, 0, 0.0), &NoProgress, &mut warm).unwrap();
        assert!(warm.is_warm() && warm.bytes() > 0, "{method:?} keeps a state");
        let next = frame(method, 49.0, 1, 10.0);
        let mut cold = Warm::new(false);
        let cold_image = render_warm(&next, &NoProgress, &mut cold).unwrap().image;
        assert!(!cold.is_warm(), "--cold keeps nothing");
        let warm_image = render_warm(&next, &NoProgress, &mut warm).unwrap().image;
        let (w, c) = (warm.iterations.unwrap(), cold.iterations.unwrap());
        let apart = block_error(&warm_image, &cold_image);
        if method == Method::Transport {
            // The grown grid stretches the cloud 5 %: the start is far (every voxel changed), so
            // the solve mixes on from it as a cold one (5 iterations against 7 here), the image
            // within the stated tolerance (below).
            assert!(w < c, "transport: iterations warm {w}, cold {c}");
            assert_within_stated_tolerance(&next, &warm_image, &cold_image);
            continue;
        }
        // The diffusion solves stop on the residual: the images agree to I0's 16-bit coding (this
        // small grid's CG takes 2 iterations either way).
        assert!(
            w <= c && apart < 1e-4,
            "{method:?}: iterations warm {w}, cold {c}; images {apart:.2e} apart"
        );
    }
}

/// Warm and cold frames of `s` both lie within the stated tolerance of a converged solve
/// (IMAGE_ERROR_FRACTION of render.transport_tolerance; docs/sequences.md).
fn assert_within_stated_tolerance(s: &Scene, warm_image: &crate::image::Image, cold_image: &crate::image::Image) {
    let mut tight = s.clone();
    (tight.render.transport.tolerance, tight.render.transport.max_iterations) = (1e-5, 200);
    let converged = render_warm(&tight, &NoProgress, &mut Warm::new(false)).unwrap().image;
    let (warm_error, cold_error) = (block_error(warm_image, &converged), block_error(cold_image, &converged));
    let bound = IMAGE_ERROR_FRACTION * s.render.transport.tolerance;
    assert!(
        warm_error < bound && cold_error < bound,
        "transport: warm {warm_error:.2e} and cold {cold_error:.2e} from converged (bound {bound:.1e})"
    );
}

/// `next` rendered from `warm`'s state takes fewer `transport` iterations than cold, and both
/// frames lie within the stated tolerance of a converged solve.
fn assert_warm_takes_fewer_iterations_within_the_stated_tolerance(next: &Scene, warm: &mut Warm) {
    let mut cold = Warm::new(false);
    let cold_image = render_warm(next, &NoProgress, &mut cold).unwrap().image;
    let warm_image = render_warm(next, &NoProgress, warm).unwrap().image;
    let (w, c) = (warm.iterations.unwrap(), cold.iterations.unwrap());
    assert!(w < c, "iterations warm {w}, cold {c}");
    assert_within_stated_tolerance(next, &warm_image, &cold_image);
}

#[test]
fn a_slowly_drifting_clouds_warm_transport_frames_take_fewer_iterations_within_the_stated_tolerance() {
    // Each frame carried a quarter voxel by the wind, the sun 1° lower.
    let mut warm = Warm::new(true);
    for f in 0..2 {
        render_warm(
            &frame(Method::Transport, 50.0 - f as f32, 0, 10.0 * f as f32),
            &NoProgress,
            &mut warm,
        )
        .unwrap();
    }
    let next = frame(Method::Transport, 48.0, 0, 20.0);
    assert_warm_takes_fewer_iterations_within_the_stated_tolerance(&next, &mut warm);
}

#[test]
fn a_far_warm_start_mixes_on_as_a_cold_solve_and_takes_fewer_iterations_within_the_stated_tolerance() {
    // The extinction tripled between frames (a simulation's cloud thickening everywhere): the
    // carried light is nearer than zero but many tolerances away. Extrapolated as a near start
    // the frame took more iterations than a cold solve; mixed on from the iterate it takes fewer.
    let mut warm = Warm::new(true);
    render_warm(&frame(Method::Transport, 50.0, 0, 0.0), &NoProgress, &mut warm).unwrap();
    let mut next = frame(Method::Transport, 50.0, 0, 0.0);
    let (m, g) = (&next.medium, next.desc.medium.g);
    next.medium = Medium::new(
        cumulus([20, 16, 12], 1),
        m.origin,
        m.voxel_size,
        3.0 * m.optics.sigma_t,
        m.optics.albedo,
        g,
    );
    assert_warm_takes_fewer_iterations_within_the_stated_tolerance(&next, &mut warm);
}

#[test]
fn a_warm_start_no_nearer_than_zero_is_dropped_for_a_cold_solve() {
    // The previous frame lit by the sun, this one by the sky alone (its sun set): the carried
    // light is farther from this frame's first iterate than zero is. The solve starts again from
    // zero and takes the cold solve's iterations plus the one that found it, ending where the cold
    // solve does.
    // A clear sky's irradiance is a tenth of the sun's or less; with no sun the scene is dim.
    let mut lit = frame(Method::Transport, 50.0, 0, 0.0);
    lit.sky = crate::lighting::Sky::constant(crate::math::Rgb::splat(0.02));
    let mut dark = lit.clone();
    dark.sun.irradiance = crate::math::Rgb::ZERO;
    let t = &lit.render.transport;
    let keep = SolveOptions {
        keep: true,
        ..SolveOptions::default()
    };
    let (_, state) = solve_warm(&lit.medium, &lit.sun, &lit.sky, lit.ground.as_ref(), t, &NoProgress, keep).unwrap();
    let solve = |start| {
        let opts = SolveOptions {
            start,
            ..SolveOptions::default()
        };
        solve_warm(&dark.medium, &dark.sun, &dark.sky, dark.ground.as_ref(), t, &NoProgress, opts)
            .unwrap()
            .0
    };
    let (cold, warm) = (solve(None), solve(state.as_ref()));
    assert!(warm.history[0] >= 1.0, "the lit frame's light is a start: {:?}", warm.history);
    assert_eq!(
        warm.history[1..],
        cold.history[..],
        "warm {:?}, cold {:?}",
        warm.history,
        cold.history
    );
    assert_eq!(warm.diffuse_source, cold.diffuse_source);
}

#[test]
fn a_transport_solve_started_from_its_own_solution_starts_converged() {
    // The moments and the cloud's light on the ground both carried: the first sweep changes I0
    // by less than the tolerance.
    let s = frame(Method::Transport, 50.0, 0, 0.0);
    assert!(s.ground.is_some(), "the scene has a ground to carry light to");
    let t = &s.render.transport;
    let keep = SolveOptions {
        keep: true,
        ..SolveOptions::default()
    };
    let (cold, state) = solve_warm(&s.medium, &s.sun, &s.sky, s.ground.as_ref(), t, &NoProgress, keep).unwrap();
    let start = SolveOptions {
        start: state.as_ref(),
        ..SolveOptions::default()
    };
    let (warm, _) = solve_warm(&s.medium, &s.sun, &s.sky, s.ground.as_ref(), t, &NoProgress, start).unwrap();
    assert!(
        warm.history[0] < t.tolerance && warm.iterations() < cold.iterations(),
        "warm {:?}, cold {:?}",
        warm.history,
        cold.history
    );
}
