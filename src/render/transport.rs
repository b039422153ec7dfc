//! The gather of `--method transport`: each camera ray is marched through the δ-M medium
//! (extinction σt′), collecting the converged diffuse source evaluated from its spherical
//! harmonics in the eye's direction plus the sun's single scattering with the exact HG phase
//! function (TMS, Nakajima & Tanaka 1988: σs p(Θ) E T′_sun per unit length, i.e. a/(1 − a f)
//! p(Θ) E T′ per unit scaled optical depth). Behind the cloud: the sky, or the ground with the
//! solver's per-column irradiance (shadowed sun and the cloud's diffuse light).
//!
//! With `render.aov` the EXR has the layers `diffuse` (the converged diffuse source: orders ≥ 2 of the sun,
//! all orders of sky and ground light), `sun_single` (TMS) and `background`; they sum to the image.
//!
//! The eye-direction source is evaluated once per full voxel in the direction from the camera to
//! the voxel's centre (a voxel subtends a small angle from the eye), then interpolated
//! trilinearly over full voxels only, so empty neighbours do not darken the cloud's rim. Within
//! [`NEAR_EYE_VOXELS`] voxels of the eye (an eye in fog) it is evaluated along each ray instead.
//! The sun's part is kept in two pieces, the smooth phase's and the forward peak's, which the
//! march weights by the transmittance between its sample and the eye ([`SunSource::seen`]).

use crate::error::Result;
use crate::image::Image;
use crate::math::{real_sh, sh_count};
use crate::math::{Rgb, Vec3};
use crate::medium::sparse::FullIndex;
use crate::medium::march::march_with;
use crate::medium::Medium;
use crate::peak::PeakSpread;
use crate::pipeline::{render_rows, NoProgress, Progress, Timings};
use crate::render::edge_pixels::{refine_edges, EDGE_SAMPLES};
use crate::render::single::pixel_sample;
use crate::render::beam_check::{self, BeamCheck, BeamSums};
use crate::render::transport_ground::EyeGround;
use crate::render::warm::Warm;
use crate::scene::Scene;
use crate::transport::solve::{solve_warm, SolveOptions, TransportField, TransportSettings};
use crate::transport::TransportMemory;
use glam::DVec3;
use std::f64::consts::PI;
use std::ops::{Add, AddAssign, Div, Mul};

/// Source per unit scaled optical depth towards the eye, per full voxel (in grid order, as
/// [`TransportField::full`] indexes them): the diffuse (multiple-scattering) part and the sun's
/// single scattering with the forward peak that δ-M truncated put back ([`sun_phase`]).
pub fn eye_source(scene: &Scene, f: &TransportField) -> (Vec<Rgb>, Vec<SunSource>) {
    let m = &scene.medium;
    let [nx, ny, _] = m.dims();
    let nsh = sh_count(f.order);
    let eye = scene.camera.position;
    let peak = PeakSpread::truncated(f.optics.g, f.order);
    let voxels: Vec<usize> = f.full.full_voxels().collect();
    // Four voxels at a time: their peaks' Legendre series side by side; 64 such groups per task.
    const LANES: usize = 4;
    const PER_TASK: usize = 64 * LANES;
    let mut diffuse = vec![Rgb::ZERO; voxels.len()];
    let mut sun = vec![SunSource::default(); voxels.len()];
    let tasks: Vec<(&mut [Rgb], &mut [SunSource])> = diffuse.chunks_mut(PER_TASK).zip(sun.chunks_mut(PER_TASK)).collect();
    crate::par::map_each(tasks, &|task, (diffuse, sun)| {
        let mut y = vec![0.0; nsh];
        let first = task * PER_TASK;
        for (g, chunk) in voxels[first..first + diffuse.len()].chunks(LANES).enumerate() {
            let d: [Vec3; LANES] = std::array::from_fn(|k| chunk.get(k).map_or(Vec3::Y, |&v| (voxel_centre(m, v, nx, ny) - eye).normalize_or_zero()));
            let cos_theta = d.map(|d| (scene.sun.dir.dot(d) as f64).clamp(-1.0, 1.0));
            let legendre = peak.legendre_lanes(cos_theta);
            for (k, ((d, cos_theta), legendre)) in d.into_iter().zip(cos_theta).zip(legendre).take(chunk.len()).enumerate() {
                let (i, fi) = (g * LANES + k, first + g * LANES + k);
                // Radiance towards the eye travels along −d.
                real_sh(f.order, -DVec3::new(d.x as f64, d.y as f64, d.z as f64), &mut y);
                let angle = ScatteringAngle { cos_theta, legendre };
                (diffuse[i], sun[i]) = (voxel_diffuse(f, fi, &y), voxel_sun(scene, f, &peak, fi, &angle));
            }
        }
    });
    (diffuse, sun)
}

/// The centre of grid voxel `v` (m); `nx`, `ny` the grid's first two dimensions.
fn voxel_centre(m: &Medium, v: usize, nx: usize, ny: usize) -> Vec3 {
    m.voxel_center(v % nx, (v / nx) % ny, v / (nx * ny))
}

/// The diffuse source towards the eye of full voxel `fi` (its index in [`TransportField::full`])
/// for light leaving it along −d, from the harmonics `y` = Y_lm(−d).
fn voxel_diffuse(f: &TransportField, fi: usize, y: &[f64]) -> Rgb {
    let nsh = y.len();
    Rgb::from(std::array::from_fn(|b| {
        let base = (fi * 3 + b) * nsh;
        let js = &f.diffuse_source[base..base + nsh];
        js.iter().zip(y.iter()).map(|(j, y)| *j as f64 * y).sum::<f64>().max(0.0) as f32
    }))
}

/// The sun's single scattering towards the eye at a point, per band, in its two parts
/// ([`sun_phase`]): what the smooth phase scatters, and what the forward peak scatters, which the
/// light's own peak scatterings on its way to the eye take out of the ray (weight T_eye^{af}).
/// Per unit scaled optical depth (W·m⁻²·sr⁻¹).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SunSource {
    /// The smooth phase's part.
    pub smooth: Rgb,
    /// The forward peak's part, before the eye's leg takes its share.
    pub peak: Rgb,
}

impl SunSource {
    /// The radiance seen through `t_eye_af` = T_eye^{a f} per band, T_eye the exact
    /// transmittance from the point to the eye: the sum, at least 0 (p′'s truncated series dips
    /// below 0 at some angles, as the solver's source, clamped there too).
    pub fn seen(&self, t_eye_af: Rgb) -> Rgb {
        (self.smooth + self.peak * t_eye_af).max(Rgb::ZERO)
    }
}

impl Add for SunSource {
    type Output = SunSource;
    fn add(self, o: SunSource) -> SunSource {
        SunSource {
            smooth: self.smooth + o.smooth,
            peak: self.peak + o.peak,
        }
    }
}

impl AddAssign for SunSource {
    fn add_assign(&mut self, o: SunSource) {
        *self = *self + o;
    }
}

impl Mul<f32> for SunSource {
    type Output = SunSource;
    fn mul(self, w: f32) -> SunSource {
        SunSource {
            smooth: self.smooth * w,
            peak: self.peak * w,
        }
    }
}

impl Div<f32> for SunSource {
    type Output = SunSource;
    fn div(self, w: f32) -> SunSource {
        SunSource {
            smooth: self.smooth / w,
            peak: self.peak / w,
        }
    }
}

/// The gather's two layers at a sample, marched together: the diffuse source and the sun's
/// single scattering (W·m⁻²·sr⁻¹).
#[derive(Clone, Copy, Debug, Default)]
struct Layers {
    diffuse: Rgb,
    sun: Rgb,
}

impl AddAssign for Layers {
    fn add_assign(&mut self, o: Layers) {
        self.diffuse += o.diffuse;
        self.sun += o.sun;
    }
}

impl Mul<f32> for Layers {
    type Output = Layers;
    fn mul(self, w: f32) -> Layers {
        Layers {
            diffuse: self.diffuse * w,
            sun: self.sun * w,
        }
    }
}

/// The sun's single scattering towards the eye at full voxel `fi`, at the scattering angle
/// `angle`.
fn voxel_sun(scene: &Scene, f: &TransportField, peak: &PeakSpread, fi: usize, angle: &ScatteringAngle) -> SunSource {
    let (o, e_sun) = (&f.optics, scene.sun.irradiance);
    let (mut smooth, mut peaked) = ([0f32; 3], [0f32; 3]);
    // The last band's phase parts, its albedo, optics and T′_sun: a band alike takes them.
    let mut last: Option<(f64, &crate::transport::BandOptics, f64, (f64, f64))> = None;
    for b in 0..3 {
        let (a, band) = (o.albedo[b], &o.bands[b]);
        let t_sun = f.sun_t[fi][b] as f64;
        if t_sun > 0.0 {
            let p = match last {
                Some((la, lb, lt, p)) if la == a && lb == band && lt == t_sun => p,
                _ => sun_phase(peak, o.g, band, a, angle, t_sun),
            };
            last = Some((a, band, t_sun, p));
            let k = a / (1.0 - a * band.f) * e_sun[b] as f64 / (4.0 * PI) * t_sun;
            smooth[b] = (k * p.0) as f32;
            peaked[b] = (k * p.1) as f32;
        }
    }
    SunSource {
        smooth: Rgb::from(smooth),
        peak: Rgb::from(peaked),
    }
}

/// Within this many voxel edges of the eye the directions from a voxel's centre to the eye and
/// the rays through it part by more than about 1/8 rad (everywhere, for an eye inside the cloud):
/// the source there is evaluated along each ray ([`RaySource`]), blended into the per-voxel one
/// over the outer half. The per-voxel source there puts the sun's forward peak into the wrong
/// pixels: a homogeneous fog seen from inside would read +11.5 % against `reference`.
const NEAR_EYE_VOXELS: f32 = 8.0;

/// The source along one camera ray near the eye: Y_lm(−d) and the scattering angle, once per ray.
struct RaySource {
    y: Vec<f64>,
    angle: ScatteringAngle,
}

impl RaySource {
    fn new(f: &TransportField, peak: &PeakSpread, sun_dir: Vec3, d: Vec3) -> RaySource {
        let mut y = vec![0.0; sh_count(f.order)];
        real_sh(f.order, -DVec3::new(d.x as f64, d.y as f64, d.z as f64), &mut y);
        let angle = ScatteringAngle::new(peak, (sun_dir.dot(d) as f64).clamp(-1.0, 1.0));
        RaySource { y, angle }
    }
}

/// A scattering angle Θ between the sun's direction and the eye's: cos Θ and the Legendre
/// polynomials of the peak's orders there ([`PeakSpread::legendre`]), made once per voxel for
/// every band.
struct ScatteringAngle {
    cos_theta: f64,
    legendre: Vec<f64>,
}

impl ScatteringAngle {
    fn new(peak: &PeakSpread, cos_theta: f64) -> ScatteringAngle {
        ScatteringAngle {
            cos_theta,
            legendre: peak.legendre(cos_theta),
        }
    }
}

/// The sun's single-scattering phase function (4π-normalised) for the gather, from the δ-M
/// solution's pieces. δ-M splits HG as p = (1 − f) p′ + f P (P the truncated peak) and carries
/// every peak scattering on in the beam: the solver's sun beam T′ = T^{1 − af} holds the light
/// peak-scattered on the sun's leg, and the march's T′ the light peak-scattered on the eye's leg.
/// TMS (Nakajima & Tanaka 1988) scatters that whole beam through the exact p, which counts the
/// peak-only paths several times and too sharply: a path with k + 1 peak scatterings and nothing
/// else is counted k + 1 times (once per scattering taken as "the" one), all with P(Θ). The smooth
/// part (1 − f) p′ is exact as TMS has it (P is the identity on orders ≤ L). The peak part is
/// counted once by taking its scattering as the last one before the eye: no peak scattering on
/// the eye's leg, weight T_eye^{af} on top of the march's T′ (so the exact T there), and the
/// λ = af τ_sun peak scatterings before it spread its angle (moments g^{l−L−1} per scattering
/// beyond order L). Only where nothing is on either leg is it TMS. No other stage changes:
/// the solver, the march and the diffuse source keep δ-M's medium (σt′, a′, p′).
///
/// The phase in its two parts (smooth, peak): the phase is smooth + T_eye^{af} peak, at least 0
/// ([`SunSource::seen`]).
fn sun_phase(peak: &PeakSpread, g: f64, band: &crate::transport::BandOptics, albedo: f64, angle: &ScatteringAngle, t_sun: f64) -> (f64, f64) {
    let cos_theta = angle.cos_theta;
    let hg = {
        let denom = 1.0 + g * g - 2.0 * g * cos_theta;
        (1.0 - g * g) / (denom * denom.sqrt().max(1e-300))
    };
    let af = albedo * band.f;
    let smooth = (1.0 - band.f) * band.phase(cos_theta);
    // T′_sun = e^{−(1 − af) τ_sun}: the expected number of peak scatterings on the sun's leg.
    let lambda = -af * t_sun.ln() / (1.0 - af);
    (smooth, hg - smooth + peak.spread_with(lambda, &angle.legendre))
}

/// Trilinear interpolation of `values` (one per full voxel, [`eye_source`]) at continuous voxel
/// coordinates `v`, over full voxels only.
#[inline]
fn full_trilinear<T: Weighted>(m: &Medium, full: &FullIndex, values: &[T], v: Vec3) -> T {
    full_weighted(m, full, v, |fi| values[fi])
}

/// A value per full voxel that [`full_weighted`] interpolates.
pub(super) trait Weighted: Copy + Default + AddAssign + Mul<f32, Output = Self> + Div<f32, Output = Self> {}
impl<T: Copy + Default + AddAssign + Mul<f32, Output = T> + Div<f32, Output = T>> Weighted for T {}

/// The trilinear mean of `value(full voxel index)` over the full voxels among the eight around
/// continuous voxel coordinates `v`, their weights renormalised (zero where none is full).
#[inline]
pub(super) fn full_weighted<T: Weighted>(m: &Medium, full: &FullIndex, v: Vec3, mut value: impl FnMut(usize) -> T) -> T {
    let d = m.dims();
    let u = v - Vec3::splat(0.5);
    let b = u.floor();
    let t = u - b;
    let (mut sum, mut wsum) = (T::default(), 0.0f32);
    for dz in 0..2 {
        for dy in 0..2 {
            for dx in 0..2 {
                let c = [b.x as i64 + dx, b.y as i64 + dy, b.z as i64 + dz];
                if (0..3).any(|a| c[a] < 0 || c[a] >= d[a] as i64) {
                    continue;
                }
                let idx = c[0] as usize + d[0] * (c[1] as usize + d[1] * c[2] as usize);
                let Some(fi) = full.slot(idx).checked_sub(1) else {
                    continue;
                };
                let w = (if dx == 1 { t.x } else { 1.0 - t.x })
                    * (if dy == 1 { t.y } else { 1.0 - t.y })
                    * (if dz == 1 { t.z } else { 1.0 - t.z });
                sum += value(fi) * w;
                wsum += w;
            }
        }
    }
    if wsum > 0.0 {
        sum / wsum
    } else {
        T::default()
    }
}

/// The background along a ray: the ground as the eye sees it ([`EyeGround`]), or the sky.
fn background(scene: &Scene, ground: Option<&EyeGround>, o: Vec3, d: Vec3) -> Rgb {
    if let Some((g, t)) = ground.zip(scene.ground.as_ref().and_then(|g| g.intersect(o, d))) {
        return g.radiance(scene, o + d * t);
    }
    scene.sky.radiance(d)
}

/// Most memory a transport render may ask for (bytes), whatever the machine has; the CLI also
/// checks the estimate against the memory available before it starts.
const MAX_BYTES: u64 = 16 << 30;

/// The warning when the iteration stopped at `render.transport_max_iterations` with the last
/// relative change of I0 (`history`, one entry per iteration) still at or above the tolerance
/// (an empty medium does not iterate and is not warned about).
fn unconverged(source: &str, history: &[f64], s: &TransportSettings) -> Option<String> {
    let last = *history.last()?;
    (history.len() >= s.max_iterations && last >= s.tolerance).then(|| {
        format!(
            "{source}: the transport iteration stopped at render.transport_max_iterations = {} with a \
             relative change of I0 of {last:.1e}, above render.transport_tolerance = {:.1e}; raise \
             render.transport_max_iterations (the image is not converged)",
            s.max_iterations, s.tolerance
        )
    })
}

/// Render with `--method transport` and the scene's `render.transport_*` settings.
pub fn render(scene: &Scene, progress: &dyn Progress, timings: &mut Timings) -> Result<Image> {
    render_with(scene, progress, timings, None)
}

/// [`render`] as a frame of a sequence: the solve starts from `warm`'s state (when enabled) and
/// leaves its own there, with its iteration count (src/render/warm.rs).
pub fn render_with(scene: &Scene, progress: &dyn Progress, timings: &mut Timings, warm: Option<&mut Warm>) -> Result<Image> {
    let m = &scene.medium;
    let s = &scene.render.transport;
    // Refuse, with the fix, a cloud whose arrays would not fit (rather than abort).
    let memory = TransportMemory::of(m, s);
    memory.check(&scene.source, MAX_BYTES, "the library's limit", &scene.desc.medium.coarser_refine())?;
    let keep = warm.as_ref().is_some_and(|w| w.enabled);
    let start = warm.as_ref().and_then(|w| w.transport.as_ref()).filter(|_| keep);
    // A live view sees each iteration's iterate through the same gather (without its bar).
    let show = |f: &TransportField| {
        let mut t = Timings::default();
        if let Ok(img) = gather(scene, f, &NoProgress, &mut t, false) {
            progress.image(&img);
        }
    };
    let live: Option<&dyn Fn(&TransportField)> = progress.wants_images().then_some(&show);
    let (field, state) = timings.time("transport solve", || {
        let opts = SolveOptions { start, keep, live };
        solve_warm(m, &scene.sun, &scene.sky, scene.ground.as_ref(), s, progress, opts)
    })?;
    if let Some(w) = warm {
        w.transport = state;
        w.iterations = Some(field.iterations());
    }
    let last = field.history.last().copied().unwrap_or(0.0);
    progress.log(&format!(
        "transport: {} ordinates, order {}, {} iterations (last change {last:.1e}); memory ≈ {:.0} MB: \
         {} full voxels × {} B + grid and DSA box (estimate)",
        field.ordinates,
        field.order,
        field.iterations(),
        memory.bytes as f64 / 1e6,
        field.full_voxels,
        TransportMemory::bytes_per_full_voxel(field.order),
    ));
    if let Some(w) = unconverged(&scene.source, &field.history, s) {
        progress.warn(&w);
    }
    gather(scene, &field, progress, timings, true)
}

/// The image of a solved (or, for a live view, partly solved) field: the eye source and the
/// march per pixel; with `check`, the check on the sun's beam between centres
/// ([`beam_check`]) and its warning.
fn gather(scene: &Scene, field: &TransportField, progress: &dyn Progress, timings: &mut Timings, check: bool) -> Result<Image> {
    let m = &scene.medium;
    let (diffuse, sun) = timings.time("eye source", || eye_source(scene, field));
    let ground = EyeGround::new(scene, field);
    // March with the δ-M extinction of the middle band (the bands differ only by σt f Δa).
    let mut scaled = m.clone();
    scaled.optics.sigma_t = field.optics.bands[1].sigma_t as f32;
    let cam = &scene.camera;
    let spp = scene.render.aa_samples;
    // ρ from the dense copy on the cloud's box (built here, after the solve): the
    // same bits as the packed density's.
    let dense = m.dense_density();
    let step = scene.render.step_voxels * m.min_voxel();
    let peak = PeakSpread::truncated(field.optics.g, field.order);
    let near = NEAR_EYE_VOXELS * m.voxel_size.max_element();
    let ratio = (field.optics.bands[1].sigma_t / field.optics.sigma_t) as f32;
    // T_eye^{af} per band from the march's T′ (the middle band's): T_eye = T′^{σt/σt′}.
    let seen_powers = Rgb::from([0, 1, 2].map(|b| (field.optics.albedo[b] * field.optics.bands[b].f) as f32 / ratio));
    // Grey optics (every example): one power per sample serves the three bands.
    let grey = seen_powers.x == seen_powers.y && seen_powers.y == seen_powers.z;
    let t_eye_af = |t_march: f32| {
        if grey {
            Rgb::splat(t_march.powf(seen_powers.y))
        } else {
            Rgb::new(t_march.powf(seen_powers.x), t_march.powf(seen_powers.y), t_march.powf(seen_powers.z))
        }
    };
    // Per pixel: [diffuse source, sun single scattering, background]; the image is their sum.
    let shade = |x: u32, y: u32, spp: u32| {
        let mut sum = [Rgb::ZERO; 3];
        for smp in 0..spp {
            let (px, py, xi) = pixel_sample(scene, x, y, smp, spp);
            let ray = cam.ray(px, py);
            let (o, d) = (ray.origin, ray.dir);
            let t_max = scene.ground.as_ref().and_then(|g| g.intersect(o, d)).unwrap_or(f32::INFINITY);
            let rho = |v: [f32; 3]| dense.trilinear(v);
            // Near the eye the source along this ray, blended into the per-voxel one.
            let ray_source = (near > 0.0 && m.intersect(o, d, 0.0, near).is_some()).then(|| RaySource::new(field, &peak, scene.sun.dir, d));
            // (the ray's source, weight of the per-voxel source) where the ray's own source takes part.
            let near_eye = |v: Vec3| {
                let r = ray_source.as_ref()?;
                let dist = (m.origin + v * m.voxel_size - o).length();
                let w = ((dist - 0.5 * near) / (0.5 * near)).clamp(0.0, 1.0);
                (w < 1.0).then_some((r, w))
            };
            // The diffuse and the sun's layers in one march (each composited as alone).
            let march = march_with(&scaled, rho, o, d, 0.0, t_max, step, xi, |v, _, t| {
                let (diffuse_far, sun_far) = (full_trilinear(m, &field.full, &diffuse, v), full_trilinear(m, &field.full, &sun, v));
                let (diffuse, sun) = match near_eye(v) {
                    None => (diffuse_far, sun_far),
                    Some((r, w)) => (
                        full_weighted(m, &field.full, v, |fi| voxel_diffuse(field, fi, &r.y)) * (1.0 - w) + diffuse_far * w,
                        full_weighted(m, &field.full, v, |fi| voxel_sun(scene, field, &peak, fi, &r.angle)) * (1.0 - w) + sun_far * w,
                    ),
                };
                Layers {
                    diffuse,
                    sun: sun.seen(t_eye_af(t)),
                }
            });
            let bg = if march.transmittance > 0.0 {
                background(scene, ground.as_ref(), o, d)
            } else {
                Rgb::ZERO
            };
            sum[0] += march.radiance.diffuse;
            sum[1] += march.radiance.sun;
            sum[2] += bg * march.transmittance;
        }
        sum.map(|c| (c / spp as f32).max(Rgb::ZERO))
    };
    let mut px = timings.time("gather", || {
        render_rows(cam.width, cam.height, progress, "transport gather", |x, y| shade(x, y, spp))
    });
    if spp == 1 {
        timings.time("gather: edges", || {
            refine_edges(&mut px, cam.width, |x, y| shade(x, y, EDGE_SAMPLES));
        });
    }
    if check {
        let beam = BeamCheck::new(&sun, &field.sun_t);
        let share = timings.time("gather: beam check", || {
            beam_check::share_over_pixels(scene, |x, y, o, d, t_max| {
                let rho = |v: [f32; 3]| dense.trilinear(v);
                // Both marched here, at the pixel's centre with the per-voxel source, rather than
                // the image's own sun layer against one march: that layer is jittered, re-shaded at
                // edges and blended near the eye, and the difference would carry all of that. One
                // march carries both middle-band sources side by side (x: the beam exponential, y:
                // the gather's), the same samples and the same scalar attenuation for both.
                let both = march_with(&scaled, rho, o, d, 0.0, t_max, step, 0.5, |v, _, t| {
                    let seen = t_eye_af(t);
                    let gathered = full_trilinear(m, &field.full, &sun, v).seen(seen);
                    Rgb::new(beam.source(m, &field.full, v, seen.y), gathered.y, 0.0)
                });
                let p = px[(x + y * cam.width) as usize];
                // The pixels `cloudgi compare` scores: the exact transmittance T = T′^(σt/σt′) below 0.99.
                let in_cloud = both.transmittance.powf(1.0 / ratio) < 0.99;
                BeamSums::pixel(both.radiance.y, both.radiance.x, (p[0] + p[1] + p[2]).y, in_cloud)
            })
        });
        beam_check::report(scene, "transport", share, progress);
    }
    let mut img = Image::new(cam.width, cam.height);
    img.pixels = px.iter().map(|p| p[0] + p[1] + p[2]).collect();
    if scene.render.aov {
        for (c, name) in ["diffuse", "sun_single", "background"].iter().enumerate() {
            img.add_layer(name, px.iter().map(|p| p[c]).collect());
        }
    }
    Ok(img)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sun_phase_is_tms_with_nothing_on_either_leg_and_keeps_the_peaks_energy_when_spread() {
        let (g, order, a) = (0.9, 7, 0.999);
        let band = crate::transport::BandOptics::delta_m(0.05, a, g, order);
        let peak = PeakSpread::truncated(g, order);
        let hg = |c: f64| (1.0 - g * g) / (1.0 + g * g - 2.0 * g * c).powf(1.5);
        // The phase seen through T_eye^{af}, as the gather takes it.
        let phase = |c: f64, t_sun: f64, t_eye: f64| {
            let (smooth, peaked) = sun_phase(&peak, g, &band, a, &ScatteringAngle::new(&peak, c), t_sun);
            let parts = SunSource {
                smooth: Rgb::splat(smooth as f32),
                peak: Rgb::splat(peaked as f32),
            };
            parts.seen(Rgb::splat(t_eye.powf(a * band.f) as f32)).x as f64
        };
        for c in [-1.0, -0.3, 0.2, 0.9, 0.99, 1.0] {
            let p = phase(c, 1.0, 1.0);
            assert!((p - hg(c)).abs() < 1e-6 * hg(c).max(1.0), "cos {c}: {p} vs {}", hg(c));
        }
        // Spread by peak scatterings on the sun's leg: the same light in all (½∫ p dμ = 1), less
        // of it near the sun.
        let (x, w) = crate::transport::gauss_legendre(400);
        // (Past λ ≈ 0.5, T′ < 0.5 here, the spread δ-M peak's series has negative lobes that the
        // clamp cuts: +0.4 % of the energy at λ = 1, +5 % at λ = 2.3, T′ = 0.05.)
        for t_sun in [0.8, 0.5] {
            let norm: f64 = x
                .iter()
                .zip(&w)
                .map(|(x, w)| 0.5 * w * phase(*x, t_sun, 1.0))
                .sum();
            assert!((norm - 1.0).abs() < 1e-3, "T′ {t_sun}: {norm}");
            assert!(phase(1.0, t_sun, 1.0) < hg(1.0));
        }
        // A peak scattering on the eye's leg removes the peak's share: only the smooth part is left.
        let smooth = (1.0 - band.f) * band.phase(0.95);
        assert!((phase(0.95, 0.5, 0.0) - smooth).abs() < 1e-6 * smooth);
    }

    #[test]
    fn only_an_iteration_stopped_by_its_cap_above_the_tolerance_is_warned_about() {
        let s = TransportSettings {
            max_iterations: 3,
            tolerance: 1e-2,
            ..TransportSettings::default()
        };
        let w = unconverged("s.toml", &[1.0, 0.3, 0.05], &s).expect("stopped at the cap");
        assert!(
            w.contains("s.toml") && w.contains("= 3") && w.contains("5.0e-2") && w.contains("raise render.transport_max_iterations"),
            "{w}"
        );
        // Converged on the last allowed iteration, converged early, or nothing to iterate.
        assert_eq!(unconverged("s.toml", &[1.0, 0.3, 0.005], &s), None);
        assert_eq!(unconverged("s.toml", &[1.0, 0.005], &s), None);
        assert_eq!(unconverged("s.toml", &[], &s), None);
    }
}
