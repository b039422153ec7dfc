//! The path-tracing estimator of the radiance arriving along one ray.
//!
//! Vertices are real collisions in the medium (delta tracking) and hits on the Lambertian ground.
//! At each vertex: next-event estimation of the sun (a directional light, shadowed by ratio
//! tracking) and of the sky (sampled by [`SkySampler`], shadowed by ratio tracking, weighted by the
//! power heuristic against the phase function or the ground's cosine lobe); then the path continues
//! in a direction sampled from the phase function or the cosine lobe. A continuation that escapes
//! to the sky picks up the sky's radiance with the complementary MIS weight. The throughput is
//! multiplied by the albedo at each vertex and Russian roulette with survival probability
//! min(1, max band of the throughput) ends paths without bias; there is no depth cap unless
//! `max_depth` is set.
//!
//! [`radiance`] also hands every contribution to a sink with its **scattering order** (the
//! number of medium scattering events on the path; a ground bounce does not count) and its
//! **light** ([`Light::Ground`] when the path has touched the ground anywhere, else the sun or the
//! sky it ends on). The sum the estimator returns is unchanged: same draws, same f32 additions.

use super::sky::SkySampler;
use super::tracking::{ratio_transmittance, sample_collision};
use crate::math::{cosine_hemisphere, Frame, Rgb, Rng, Vec3};
use crate::scene::Scene;
use std::f32::consts::FRAC_1_PI;
use std::time::Instant;

/// Offset (m) that lifts a ground hit above the plane before tracing on.
const GROUND_EPS: f32 = 1e-3;

/// Options of the estimator.
#[derive(Clone, Copy, Debug)]
pub struct PathOptions {
    /// Most scattering events (medium or ground) per path; `u32::MAX` for no cap.
    pub max_depth: u32,
    /// Wall-clock instant after which a path in progress is abandoned (checked every
    /// [`DEADLINE_CHECK`] vertices); `None` for no limit.
    pub deadline: Option<Instant>,
}

impl Default for PathOptions {
    fn default() -> Self {
        PathOptions {
            max_depth: u32::MAX,
            deadline: None,
        }
    }
}

/// Vertices between two looks at the clock: a path in a medium of albedo 1 and optical depth
/// 1e4 random-walks for ~1e8 vertices, so the time limit must be checked inside a path; a clock
/// read (~25 ns) every 256 vertices (~50 µs) costs nothing.
pub const DEADLINE_CHECK: u32 = 256;

/// Where a contribution's light came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Light {
    /// The sun, reached by next-event estimation, the path never touching the ground.
    Sun = 0,
    /// The sky (NEE or escape), the path never touching the ground.
    Sky = 1,
    /// Any path with at least one ground vertex: light reflected by the ground.
    Ground = 2,
}

/// Power heuristic weight of a strategy with density `a` against one with density `b`.
#[inline]
fn power(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2 + b2 > 0.0 {
        a2 / (a2 + b2)
    } else {
        0.0
    }
}

/// Radiance (W·m⁻²·sr⁻¹) arriving at `o` from direction `d` (the ray `o + t·d`), one sample;
/// `None` when the path passed `opts.deadline` (checked between vertices and inside long tracking
/// walks) and was abandoned. Every term of the sum is also handed to
/// `sink(order, light, contribution)` (order = medium scattering events before the light is
/// reached; see the module notes).
pub fn radiance(scene: &Scene, o: Vec3, d: Vec3, opts: &PathOptions, rng: &mut Rng, mut sink: impl FnMut(u32, Light, Rgb)) -> Option<Rgb> {
    let m = &scene.medium;
    let phase = m.optics.phase;
    let sun = &scene.sun;
    let ground = scene.ground.as_ref();
    // Sky NEE through `Sky::sample`/`Sky::pdf` (uniform sphere for the constant sky, map importance sampling otherwise).
    let sky = SkySampler::new(&scene.sky);
    let sun_on = sun.irradiance.max_element() > 0.0;
    let ground_t = |p: Vec3, dir: Vec3| ground.and_then(|g| g.intersect(p, dir));
    // Transmittance towards the sky or sun: zero if the ground is in the way.
    let shadow = |p: Vec3, dir: Vec3, rng: &mut Rng| -> Option<f32> {
        if ground_t(p, dir).is_some() {
            Some(0.0)
        } else {
            ratio_transmittance(m, p, dir, f32::INFINITY, rng, opts.deadline).ok()
        }
    };

    let (mut o, mut d) = (o, d);
    let mut l = Rgb::ZERO;
    let mut beta = Rgb::ONE;
    // Density of the direction sampled at the previous vertex (None: camera ray, no MIS).
    let mut prev_pdf: Option<f32> = None;
    let mut depth = 0u32;
    // Medium scattering events so far (the order), and whether the path has touched the ground.
    let mut order = 0u32;
    let mut via_ground = false;
    let light = |via_ground: bool, l: Light| if via_ground { Light::Ground } else { l };
    loop {
        if depth % DEADLINE_CHECK == DEADLINE_CHECK - 1 && opts.deadline.is_some_and(|t| Instant::now() >= t) {
            return None;
        }
        let tg = ground_t(o, d);
        let t_max = tg.unwrap_or(f32::INFINITY);
        if let Some(t) = sample_collision(m, o, d, t_max, rng, opts.deadline).ok()? {
            // Real collision in the medium.
            depth += 1;
            if depth > opts.max_depth {
                break;
            }
            order += 1;
            let p = o + d * t;
            beta *= m.optics.albedo;
            if sun_on {
                let tr = shadow(p, sun.dir, rng)?;
                if tr > 0.0 {
                    let c = beta * sun.irradiance * (phase.eval(sun.dir, -d) * tr);
                    l += c;
                    sink(order, light(via_ground, Light::Sun), c);
                }
            }
            let (wi, ls, pl) = sky.sample([rng.uniform(), rng.uniform()]);
            if pl > 0.0 && ls.max_element() > 0.0 {
                let f = phase.eval(wi, -d);
                let tr = shadow(p, wi, rng)?;
                if tr > 0.0 {
                    let c = beta * ls * (f * tr * power(pl, f) / pl);
                    l += c;
                    sink(order, light(via_ground, Light::Sky), c);
                }
            }
            if !roulette(&mut beta, rng) {
                break;
            }
            let nd = phase.sample(d, rng.uniform(), rng.uniform());
            prev_pdf = Some(phase.eval(nd, -d));
            o = p;
            d = nd;
        } else if let (Some(t), Some(g)) = (tg, ground) {
            // Lambertian ground.
            depth += 1;
            if depth > opts.max_depth {
                break;
            }
            let p = o + d * t;
            let p = Vec3::new(p.x, g.height + GROUND_EPS, p.z);
            beta *= g.albedo;
            via_ground = true;
            if sun_on && sun.dir.y > 0.0 {
                let tr = shadow(p, sun.dir, rng)?;
                if tr > 0.0 {
                    let c = beta * sun.irradiance * (sun.dir.y * FRAC_1_PI * tr);
                    l += c;
                    sink(order, Light::Ground, c);
                }
            }
            let (wi, ls, pl) = sky.sample([rng.uniform(), rng.uniform()]);
            if pl > 0.0 && wi.y > 0.0 && ls.max_element() > 0.0 {
                let f = wi.y * FRAC_1_PI;
                let tr = shadow(p, wi, rng)?;
                if tr > 0.0 {
                    let c = beta * ls * (f * tr * power(pl, f) / pl);
                    l += c;
                    sink(order, Light::Ground, c);
                }
            }
            if !roulette(&mut beta, rng) {
                break;
            }
            let local = cosine_hemisphere(rng.uniform(), rng.uniform());
            let nd = Frame::from_normal(Vec3::Y).to_world(local).normalize();
            prev_pdf = Some(nd.y.max(0.0) * FRAC_1_PI);
            o = p;
            d = nd;
        } else {
            // Escaped to the sky.
            let w = match prev_pdf {
                None => 1.0,
                Some(pp) => power(pp, sky.pdf(d)),
            };
            let c = beta * scene.sky.radiance(d) * w;
            l += c;
            sink(order, light(via_ground, Light::Sky), c);
            break;
        }
    }
    Some(l)
}

/// Russian roulette with survival probability min(1, max band of `beta`); re-weights survivors.
#[inline]
fn roulette(beta: &mut Rgb, rng: &mut Rng) -> bool {
    let q = beta.max_element().min(1.0);
    if q >= 1.0 {
        return true;
    }
    if q <= 0.0 || rng.uniform() >= q {
        return false;
    }
    *beta /= q;
    true
}
