//! Stage 1: the reduced incident radiance I_ri (eq. 2) and its first scattering, Q0 (eq. 5) and
//! the vector Q1 (eq. 6), per voxel and RGB band.
//!
//! **Sky and ground.** Each of the 96 direction bins carries the bin's mean radiance
//! P_b / Δω_b, where the power P_b = ∫_bin L(ω) dω comes from
//! [`DirectionBins::integrate`] over the sky's radiance, so any sky model works. Bins whose
//! directions point below the horizon see the Lambertian ground instead (the ground "as an
//! upward sky"), lit by the unshadowed sun and the sky's hemisphere irradiance.
//!
//! **Rays.** For bin b light flows along ω = −(direction towards the bin). The box enclosing every
//! non-empty voxel plus one voxel of margin (clipped to the grid) is crossed by families of parallel
//! rays: one family along the bin's centre direction (`rays_per_face_edge` = 1, the paper), or n²
//! families along jittered directions, one per stratum of the bin's (u, v) square, weighted by the
//! stratum's exact solid angle. A family starts on the plane perpendicular to the dominant axis of
//! its direction, one ray per voxel face (a lattice shifted by one random offset), covering the
//! box's shadow, so in every plane across the box each voxel face is crossed by exactly one ray:
//! every voxel is reached. A ray whose cross-section perpendicular to its direction is
//! w = A·|ω·n| walks the voxels with an exact DDA. In a voxel of density ρ (piecewise constant, the voxel value, as the diffusion
//! stage uses) and extinction κ = ρσt it adds w·∫I ds = w·I_in·(1 − e^{−κl})/κ to the voxel's
//! radiance sum and w·l to its weight sum, then attenuates I by e^{−κl}. The voxel's mean radiance
//! from the bin is Ī_b = Σ w∫I ds / Σ w l: the paper's segment-length weighting, normalised by
//! the (cross-section weighted) sum of segment lengths. A full voxel that no ray happens to cross
//! (possible with direction jitter) is given one ray through its centre.
//!
//! **Q0 and Q1** (eqs. 5, 6, with the 1/4π of their definitions):
//! Q0 = ρσs/(4π) · Σ_b Δω_b Ī_b, Q1 = ρσs·g/(4π) · Σ_b Δω_b Ī_b (−m_b), where m_b is the bin's
//! exact mean direction ∫ω dω/Δω (towards the sky, length < 1). This uses ∫p(ω, ω′)ω dω = g ω′
//! for the HG phase function. σs = a·σt per band.
//!
//! **Sun.** The sun is traced apart, as one more parallel-ray direction without jitter, carrying
//! its irradiance; it adds ρσs/(4π)·E·T̄ to Q0 and ρσs g/(4π)·E·T̄·(−sun dir) to Q1, with T̄ the
//! voxel-mean transmittance. The reduced sun radiance for the gather's exact single scattering is
//! kept at voxel centres (exact optical depth of the trilinear field, [`SunTransmittance`]).
//!
//! **Clear-air hook** ([`EntryRadiance`]). When a sky-bin ray steps from an empty voxel X_e into a
//! face-adjacent full voxel, [`compute`] asks `entry(X_e, b)`. `Some(L)` means: the radiance
//! arriving at X_e from the directions of bin b (flowing along −dir_b) is L (W·m⁻²·sr⁻¹ per band),
//! and the ray carries L from there on instead of its attenuated sky value (the paper's section 3:
//! the viewing cube's bin replaces the propagating radiance). `None` keeps the attenuated value.
//! The hook is never asked for the sun, nor where a full voxel lies on the grid's own boundary
//! (no empty voxel precedes it).
//!
//! **Determinism.** Each ray's jitter comes from a counter-based stream keyed by (seed, bin, ray);
//! bins are traced in parallel into their own buffers and reduced into Q0/Q1 per voxel in bin
//! order, so the result is bit-identical at any thread count.

use crate::lighting::bins::{Bin, DirectionBins, NUM_BINS};
use crate::lighting::{Ground, Sky, Sun};
use crate::math::{mix64, Rgb, Rng, Vec3};
use crate::math::{sh9, SH_COEFFS};
use crate::medium::{Dda, Medium};
use crate::sunlight::SunTransmittance;
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::PI;

/// The clear-air hook: `(empty voxel, bin) → Some(radiance arriving from that bin)`; see the module docs.
pub type EntryRadiance<'h> = dyn Fn([usize; 3], usize) -> Option<Rgb> + Sync + 'h;

/// Stage-1 sampling settings.
#[derive(Clone, Debug)]
pub struct IncidentSettings {
    /// Direction strata per bin edge: 1 traces each bin along its centre direction (the paper);
    /// n > 1 traces n² parallel families per bin, one per jittered sub-square of the bin, each
    /// weighted by its exact solid angle.
    pub rays_per_face_edge: usize,
    /// Sub-rectangles per bin edge when integrating the sky's radiance over a bin.
    pub sky_subdivisions: usize,
    /// Seed of the ray jitter.
    pub seed: u64,
    /// Also project the reduced sky and ground radiance per voxel onto degree-≤ 2 spherical
    /// harmonics ([`IncidentLight::sky_sh`]) for the gather's single scattering of sky and ground
    /// light ([`crate::lit::sky_single`], `render.sky_single_scattering`, default on). `false`:
    /// the paper's gather, which leaves it out.
    pub sky_single: bool,
}

impl Default for IncidentSettings {
    fn default() -> Self {
        IncidentSettings {
            rays_per_face_edge: 1,
            sky_subdivisions: 8,
            seed: 0,
            sky_single: true,
        }
    }
}

/// What lights the medium from outside.
#[derive(Clone, Debug)]
pub struct IncidentSources {
    /// Mean radiance arriving from each of the 96 bins (W·m⁻²·sr⁻¹ per band), in [`DirectionBins`] order.
    pub bin_radiance: Vec<Rgb>,
    /// Unit direction towards the sun and its irradiance (W/m² per band), if any.
    pub sun: Option<(Vec3, Rgb)>,
}

impl IncidentSources {
    /// The sky (any model, through [`DirectionBins::integrate`]), the ground below the
    /// horizon (unshadowed), and the sun.
    pub fn from_lighting(sun: &Sun, sky: &Sky, ground: Option<&Ground>, bins: &DirectionBins, sky_subdivisions: usize) -> IncidentSources {
        let power = bins.integrate(sky_subdivisions.max(1), |d| {
            if d.y < 0.0 {
                if let Some(g) = ground {
                    // The Lambertian ground is uniform: its radiance does not depend on the point.
                    return g.radiance(Vec3::ZERO, sun, sky, 1.0);
                }
            }
            sky.radiance(d)
        });
        let bin_radiance = power.iter().zip(&bins.bins).map(|(p, b)| *p / b.solid_angle as f32).collect();
        IncidentSources {
            bin_radiance,
            sun: Some((sun.dir, sun.irradiance)),
        }
    }
}

/// Stage-1 output: first-scattered light per voxel, and the sun for the gather.
#[derive(Clone, Debug)]
pub struct IncidentLight {
    /// Grid resolution (same as the medium's).
    pub dims: [usize; 3],
    /// Q0 per voxel (eq. 5, W·m⁻³·sr⁻¹ per band); zero where ρ = 0.
    pub q0: Vec<Rgb>,
    /// Q1 per voxel (eq. 6), `q1[axis][voxel]` is the axis component per band (W·m⁻³·sr⁻¹).
    pub q1: [Vec<Rgb>; 3],
    /// Voxel-mean transmittance of the direct sun (piecewise-constant ρ), used for Q0/Q1.
    pub sun_mean_transmittance: Vec<f32>,
    /// Sun transmittance at voxel centres (exact), for the gather's single scattering.
    pub sun_transmittance: SunTransmittance,
    /// Sun irradiance (W/m² per band); zero without a sun.
    pub sun_irradiance: Rgb,
    /// The mean radiance per bin that was propagated (W·m⁻²·sr⁻¹).
    pub bin_radiance: Vec<Rgb>,
    /// With [`IncidentSettings::sky_single`]: per voxel, the reduced sky and ground radiance (all
    /// bins, not the sun) projected onto the real spherical harmonics of degree ≤ 2 of the flow
    /// direction, L_lm = Σ_b Δω_b Ī_b Y_lm(ω_b), `[band * 9 + lm]` (W·m⁻²·sr⁻¹); zero where ρ = 0.
    pub sky_sh: Option<Vec<[f32; 3 * SH_COEFFS]>>,
    /// Rays that crossed the medium's active box (all bins and the sun).
    pub rays: u64,
    /// Extra rays traced through the centre of a full voxel that no ray had crossed.
    pub fallback_rays: u64,
}

/// Index box [lo, hi) of every non-empty voxel grown by `margin` voxels, clipped to the grid.
pub(crate) fn active_box(m: &Medium, margin: usize) -> Option<([usize; 3], [usize; 3])> {
    let d = m.dims();
    let mut lo = d;
    let mut hi = [0usize; 3];
    let data = m.density.data();
    for k in 0..d[2] {
        for j in 0..d[1] {
            for i in 0..d[0] {
                if data[i + d[0] * (j + d[1] * k)] > 0.0 {
                    let c = [i, j, k];
                    for a in 0..3 {
                        lo[a] = lo[a].min(c[a]);
                        hi[a] = hi[a].max(c[a] + 1);
                    }
                }
            }
        }
    }
    if hi[0] == 0 {
        return None;
    }
    for a in 0..3 {
        lo[a] = lo[a].saturating_sub(margin);
        hi[a] = (hi[a] + margin).min(d[a]);
    }
    Some((lo, hi))
}

/// One propagated direction: a sky bin (jittered within it) or the sun (exact).
struct Source<'a> {
    bin: Option<(usize, &'a Bin)>,
    /// Flow direction when there is no bin (the sun).
    flow: Vec3,
    radiance: Rgb,
}

/// Per-voxel sums of one direction over the active box: (w∫I ds per band, w·l).
type Sums = Vec<[f32; 4]>;

struct Ctx<'a> {
    m: &'a Medium,
    lo: [usize; 3],
    bd: [usize; 3],
    rho: Vec<f32>,
    entry: Option<&'a EntryRadiance<'a>>,
    seed: u64,
    ss: usize,
    /// Extinction per unit density the incident light decays with, per band (m⁻¹).
    atten: [f64; 3],
}

impl Ctx<'_> {
    #[inline]
    fn lin(&self, c: [usize; 3]) -> usize {
        c[0] + self.bd[0] * (c[1] + self.bd[1] * c[2])
    }

    /// Trace one ray (origin `o` in active-box voxel coordinates, world unit direction `d`)
    /// carrying `l0`, calling `sink(cell, w∫I ds, l)` for every full voxel.
    fn trace(&self, src: &Source, o: DVec3, d: Vec3, l0: Rgb, mut sink: impl FnMut(usize, Rgb, f32)) {
        let h = self.m.voxel_size.as_dvec3();
        let dv = d.as_dvec3() / h;
        let hi = DVec3::new(self.bd[0] as f64, self.bd[1] as f64, self.bd[2] as f64);
        let Some((t0, t1)) = crate::medium::ray_box(DVec3::ZERO, hi, o, dv, f64::NEG_INFINITY, f64::INFINITY) else {
            return;
        };
        let atten = self.atten;
        let mut l = l0;
        let mut prev: Option<([usize; 3], bool)> = None;
        // The active box in voxel coordinates (t in metres, since `dv` is d / h).
        for seg in Dda::new(DVec3::ZERO, DVec3::ONE, self.bd, o, dv, t0, t1) {
            let (c, len) = (seg.cell, seg.len());
            let idx = self.lin(c);
            let rho = self.rho[idx];
            let full = rho > 0.0;
            if full {
                if let (Some(hook), Some((pc, false)), Some((b, _))) = (self.entry, prev, src.bin) {
                    let g = [pc[0] + self.lo[0], pc[1] + self.lo[1], pc[2] + self.lo[2]];
                    if let Some(lh) = hook(g, b) {
                        l = lh;
                    }
                }
                let mut e = [0f32; 3];
                let mut integral = [0f32; 3];
                for c in 0..3 {
                    let tau = atten[c] * rho as f64 * len;
                    let (ec, ic) = if tau < 1e-6 {
                        (1.0 - tau, len * (1.0 - 0.5 * tau))
                    } else {
                        let ec = (-tau).exp();
                        (ec, (1.0 - ec) * len / tau)
                    };
                    e[c] = ec as f32;
                    integral[c] = ic as f32;
                }
                sink(idx, l * Rgb::from_array(integral), len as f32);
                l *= Rgb::from_array(e);
            }
            prev = Some((c, full));
        }
    }

    /// One family of parallel rays along `d` (world, unit): launched from the plane perpendicular
    /// to the dominant axis of `d`, one ray per voxel face of that plane (a lattice with one random offset), covering the
    /// box's shadow along `d`, so in every plane x_a = const the rays form a lattice of one per
    /// voxel face and every voxel is crossed. Cross-section weight area·|d_a|·`share`.
    fn trace_family(&self, src: &Source, d: Vec3, share: f32, rng: &mut Rng, sums: &mut Sums) -> u64 {
        let h = self.m.voxel_size;
        let a = if d.x.abs() >= d.y.abs() && d.x.abs() >= d.z.abs() {
            0
        } else if d.y.abs() >= d.z.abs() {
            1
        } else {
            2
        };
        let (u, v) = ((a + 1) % 3, (a + 2) % 3);
        let plane = if d[a] > 0.0 { 0.0 } else { self.bd[a] as f64 };
        let fv = d.as_dvec3() / h.as_dvec3();
        let reach = |x: usize| -> (i64, i64) {
            // A ray launched at coordinate o moves by `shift` (voxels) along axis x while crossing
            // the box; it can touch [0, bd_x] when o ∈ [−max(shift, 0), bd_x + max(−shift, 0)].
            let shift = fv[x] / fv[a].abs() * self.bd[a] as f64;
            (
                -(shift.max(0.0).ceil() as i64) - 1,
                self.bd[x] as i64 + (-shift).max(0.0).ceil() as i64 + 1,
            )
        };
        let (u0, u1) = reach(u);
        let (v0, v1) = reach(v);
        let w = h[u] * h[v] * d[a].abs() * share;
        let mut rays = 0u64;
        // One random offset for the whole family: a rigid lattice keeps exactly one ray per voxel
        // face in every plane (independent per-ray jitter would leave gaps downstream).
        let (ou, ov) = (rng.uniform_f64(), rng.uniform_f64());
        for jv in v0..v1 {
            for ju in u0..u1 {
                let mut o = DVec3::ZERO;
                o[a] = plane;
                o[u] = ju as f64 + ou;
                o[v] = jv as f64 + ov;
                let mut hit = false;
                self.trace(src, o, d, src.radiance, |idx, li, len| {
                    hit = true;
                    let s = &mut sums[idx];
                    s[0] += w * li.x;
                    s[1] += w * li.y;
                    s[2] += w * li.z;
                    s[3] += w * len;
                });
                rays += hit as u64;
            }
        }
        rays
    }

    /// All rays of one direction into per-voxel sums over the active box.
    fn trace_source(&self, src: &Source, src_id: u64) -> (Sums, u64, u64) {
        let mut fallback = 0u64;
        let n = self.bd[0] * self.bd[1] * self.bd[2];
        let mut sums: Sums = vec![[0.0; 4]; n];
        let h = self.m.voxel_size;
        let flow0 = match src.bin {
            Some((_, b)) => -b.center,
            None => src.flow,
        };
        let ss = self.ss;
        let mut rays = 0u64;
        for stratum in 0..ss * ss {
            let mut rng = Rng::new(mix64(self.seed ^ mix64(src_id)), stratum as u64);
            // The family's direction and its share of the bin's solid angle.
            let (d, share) = match src.bin {
                Some((_, b)) if ss > 1 => {
                    let (su, sv) = (stratum % ss, stratum / ss);
                    let (fu, fv) = ((su as f32 + rng.uniform()) / ss as f32, (sv as f32 + rng.uniform()) / ss as f32);
                    let du = (b.u[1] - b.u[0]) / ss as f64;
                    let dv = (b.v[1] - b.v[0]) / ss as f64;
                    let (ua, va) = (b.u[0] + su as f64 * du, b.v[0] + sv as f64 * dv);
                    let sa = crate::lighting::bins::rect_solid_angle(ua, ua + du, va, va + dv);
                    (-b.direction_at(fu, fv), (sa / b.solid_angle) as f32)
                }
                Some((_, b)) => (-b.center, 1.0),
                None => (src.flow, 1.0),
            };
            rays += self.trace_family(src, d, share, &mut rng, &mut sums);
        }
        // A full voxel no ray crossed: one ray through its centre, from where it enters the box.
        for k in 0..self.bd[2] {
            for j in 0..self.bd[1] {
                for i in 0..self.bd[0] {
                    let idx = self.lin([i, j, k]);
                    if self.rho[idx] > 0.0 && sums[idx][3] == 0.0 {
                        let c = DVec3::new(i as f64 + 0.5, j as f64 + 0.5, k as f64 + 0.5);
                        let dv = flow0.as_dvec3() / h.as_dvec3();
                        let back = c - dv * 1e9;
                        fallback += 1;
                        let mut acc = [0.0f32; 4];
                        self.trace(src, back, flow0, src.radiance, |id2, li, len| {
                            if id2 == idx {
                                acc = [li.x, li.y, li.z, len];
                            }
                        });
                        sums[idx] = acc;
                    }
                }
            }
        }
        (sums, rays, fallback)
    }
}

/// Stage 1: propagate every bin and the sun through `m`; see the module docs.
pub fn compute(
    m: &Medium,
    bins: &DirectionBins,
    sources: &IncidentSources,
    settings: &IncidentSettings,
    entry: Option<&EntryRadiance<'_>>,
) -> IncidentLight {
    let sun_dir = sources.sun.map_or(Vec3::Y, |s| s.0);
    compute_with_sun(m, bins, sources, settings, entry, SunTransmittance::compute(m, sun_dir))
}

/// [`compute`] with the sun transmittance at voxel centres already known (it depends only on
/// the medium and the sun, so a run computes it once; `sun_transmittance.dir` must be the
/// sources' sun direction).
pub fn compute_with_sun(
    m: &Medium,
    bins: &DirectionBins,
    sources: &IncidentSources,
    settings: &IncidentSettings,
    entry: Option<&EntryRadiance<'_>>,
    sun_transmittance: SunTransmittance,
) -> IncidentLight {
    let dims = m.dims();
    let n = dims[0] * dims[1] * dims[2];
    let (sun_dir, sun_e) = sources.sun.unwrap_or((Vec3::Y, Rgb::ZERO));
    let mut out = IncidentLight {
        dims,
        q0: vec![Rgb::ZERO; n],
        q1: [vec![Rgb::ZERO; n], vec![Rgb::ZERO; n], vec![Rgb::ZERO; n]],
        sun_mean_transmittance: vec![1.0; n],
        sun_transmittance,
        sun_irradiance: sun_e,
        bin_radiance: sources.bin_radiance.clone(),
        sky_sh: None,
        rays: 0,
        fallback_rays: 0,
    };
    let Some((lo, hi)) = active_box(m, 1) else {
        return out;
    };
    let bd = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
    let nb = bd[0] * bd[1] * bd[2];
    let mut rho = vec![0f32; nb];
    for k in 0..bd[2] {
        for j in 0..bd[1] {
            for i in 0..bd[0] {
                rho[i + bd[0] * (j + bd[1] * k)] = m.density.get(i + lo[0], j + lo[1], k + lo[2]);
            }
        }
    }
    // The medium's optics per band. A similarity transform is never applied here alone: it is
    // already in `m.optics` when `render.forward_fraction` asks for one (`render::delta_m`, the
    // same medium for every stage).
    let optics = m.optics.similarity(0.0);
    let ctx = Ctx {
        m,
        lo,
        bd,
        rho,
        entry,
        seed: settings.seed,
        ss: settings.rays_per_face_edge.max(1),
        atten: optics.sigma_t,
    };
    // Sources: the 96 bins, then the sun. Each contributes Δω·Ī to Σ0 and Δω·Ī·flow to Σ1.
    let mut list: Vec<(Source, Rgb, Vec3)> = bins
        .bins
        .iter()
        .enumerate()
        .filter(|(b, _)| sources.bin_radiance[*b].max_element() > 0.0 || entry.is_some())
        .map(|(b, bin)| {
            (
                Source {
                    bin: Some((b, bin)),
                    flow: -bin.center,
                    radiance: sources.bin_radiance[b],
                },
                Rgb::splat(bin.solid_angle as f32),
                -bin.mean_dir,
            )
        })
        .collect();
    let sun_index = list.len();
    if sun_e.max_element() > 0.0 {
        list.push((
            Source {
                bin: None,
                flow: -sun_dir,
                radiance: Rgb::ONE,
            },
            sun_e,
            -sun_dir,
        ));
    }
    // Accumulators over the active box: Σ0 (3) and Σ1 (3 axes × 3 bands), f64, in source order.
    let mut s0 = vec![[0f64; 3]; nb];
    let mut s1 = vec![[0f64; 9]; nb];
    let mut sun_t = vec![1f32; nb];
    // Σ_b Δω_b Ī_b Y_lm(ω_b) over the sky and ground bins (not the sun), when asked for.
    let mut sh = if settings.sky_single {
        vec![[0f32; 3 * SH_COEFFS]; nb]
    } else {
        Vec::new()
    };
    let sh_basis: Vec<[f32; SH_COEFFS]> = list.iter().map(|(_, _, flow)| sh9(flow.normalize())).collect();
    let chunk = rayon::current_num_threads().max(1) * 2;
    let mut rays = 0u64;
    let mut fallback = 0u64;
    for (ci, group) in list.chunks(chunk).enumerate() {
        let results: Vec<(Sums, u64, u64)> = group
            .par_iter()
            .enumerate()
            .map(|(gi, (src, _, _))| {
                let id = (ci * chunk + gi) as u64;
                let id = src.bin.map_or(NUM_BINS as u64 + 1, |(b, _)| b as u64) ^ (id << 32);
                ctx.trace_source(src, id)
            })
            .collect();
        rays += results.iter().map(|r| r.1).sum::<u64>();
        fallback += results.iter().map(|r| r.2).sum::<u64>();
        let base = ci * chunk;
        // Without the projection `sh` is empty: give every chunk an empty slice of it.
        let sh_chunk = if sh.is_empty() { 0 } else { 4096 };
        let mut sh_chunks: Vec<&mut [[f32; 3 * SH_COEFFS]]> = if sh.is_empty() {
            (0..nb.div_ceil(4096)).map(|_| &mut [][..]).collect()
        } else {
            sh.chunks_mut(sh_chunk).collect()
        };
        s0.par_chunks_mut(4096)
            .zip(s1.par_chunks_mut(4096))
            .zip(sun_t.par_chunks_mut(4096))
            .zip(sh_chunks.par_iter_mut())
            .enumerate()
            .for_each(|(bi, (((a0, a1), st), ash))| {
                for (o, ((v0, v1), t)) in a0.iter_mut().zip(a1.iter_mut()).zip(st.iter_mut()).enumerate() {
                    let idx = bi * 4096 + o;
                    let mut vsh = ash.get_mut(o);
                    for (gi, (res, _, _)) in results.iter().enumerate() {
                        let s = res[idx];
                        if s[3] <= 0.0 {
                            continue;
                        }
                        let (_, dw, flow) = &group[gi];
                        let inv = 1.0 / s[3] as f64;
                        let mean = [s[0] as f64 * inv, s[1] as f64 * inv, s[2] as f64 * inv];
                        if base + gi == sun_index {
                            *t = mean[0] as f32;
                        }
                        for c in 0..3 {
                            let p = mean[c] * dw[c] as f64;
                            v0[c] += p;
                            for ax in 0..3 {
                                v1[3 * ax + c] += p * flow[ax] as f64;
                            }
                        }
                        if let Some(acc) = vsh.as_mut() {
                            if base + gi != sun_index {
                                let y = &sh_basis[base + gi];
                                for c in 0..3 {
                                    let p = (mean[c] * dw[c] as f64) as f32;
                                    for k in 0..SH_COEFFS {
                                        acc[c * SH_COEFFS + k] += p * y[k];
                                    }
                                }
                            }
                        }
                    }
                }
            });
    }
    out.rays = rays;
    out.fallback_rays = fallback;
    let mut sky_sh = settings.sky_single.then(|| vec![[0f32; 3 * SH_COEFFS]; n]);
    // Scatter into the full grid with ρσs/(4π) and ρσs·g/(4π).
    // With δ-scaling (f = g) the scattering that changes direction is σs(1 − g), isotropic (g' = 0).
    let (sigma_s, g) = (optics.sigma_s, optics.phase.mean_cosine());
    for k in 0..bd[2] {
        for j in 0..bd[1] {
            for i in 0..bd[0] {
                let bi = i + bd[0] * (j + bd[1] * k);
                let rho = ctx.rho[bi] as f64;
                if rho <= 0.0 {
                    continue;
                }
                let gi = (i + lo[0]) + dims[0] * ((j + lo[1]) + dims[1] * (k + lo[2]));
                let f = [
                    rho * sigma_s.x as f64 / (4.0 * PI),
                    rho * sigma_s.y as f64 / (4.0 * PI),
                    rho * sigma_s.z as f64 / (4.0 * PI),
                ];
                out.q0[gi] = Rgb::new((f[0] * s0[bi][0]) as f32, (f[1] * s0[bi][1]) as f32, (f[2] * s0[bi][2]) as f32);
                for ax in 0..3 {
                    out.q1[ax][gi] = Rgb::new(
                        (f[0] * g * s1[bi][3 * ax]) as f32,
                        (f[1] * g * s1[bi][3 * ax + 1]) as f32,
                        (f[2] * g * s1[bi][3 * ax + 2]) as f32,
                    );
                }
                out.sun_mean_transmittance[gi] = sun_t[bi];
                if let Some(full) = sky_sh.as_mut() {
                    full[gi] = sh[bi];
                }
            }
        }
    }
    out.sky_sh = sky_sh;
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::medium::Grid3;

    /// A 4³ block of density 1 in a 6³ grid, optically thin (τ = 4·10⁻⁴ across), albedo 0.9.
    fn thin_block() -> Medium {
        let mut g = Grid3::filled([6, 6, 6], 0.0);
        for k in 1..5 {
            for j in 1..5 {
                for i in 1..5 {
                    g.set(i, j, k, 1.0);
                }
            }
        }
        Medium::new(g, Vec3::ZERO, Vec3::ONE, 1e-4, Rgb::splat(0.9), 0.7)
    }

    fn uniform_sky(l: f32) -> IncidentSources {
        IncidentSources {
            bin_radiance: vec![Rgb::splat(l); NUM_BINS],
            sun: None,
        }
    }

    #[test]
    fn active_box_is_the_occupied_box_grown_and_clipped() {
        let m = thin_block();
        assert_eq!(active_box(&m, 0), Some(([1, 1, 1], [5, 5, 5])));
        assert_eq!(active_box(&m, 1), Some(([0, 0, 0], [6, 6, 6])));
        assert_eq!(active_box(&m, 3), Some(([0, 0, 0], [6, 6, 6])));
        let empty = Medium::new(Grid3::filled([3, 3, 3], 0.0), Vec3::ZERO, Vec3::ONE, 1.0, Rgb::ONE, 0.0);
        assert_eq!(active_box(&empty, 1), None);
    }

    /// Optically thin, uniform sky L: every voxel sees L from all 4π, so Q0 = ρσs·L (eq. 5 with
    /// ΣΔω = 4π) and Q1 = 0 (the bins' mean directions cancel), up to the attenuation ~τ.
    #[test]
    fn thin_block_under_a_uniform_sky_has_q0_of_the_sky_and_no_q1() {
        let m = thin_block();
        let inc = compute(&m, &DirectionBins::new(), &uniform_sky(2.0), &IncidentSettings::default(), None);
        let want = 0.9 * 1e-4 * 2.0;
        for (n, q) in inc.q0.iter().enumerate() {
            if m.density.data()[n] > 0.0 {
                assert!((q.x - want).abs() < 1e-3 * want, "voxel {n}: Q0 {q:?} vs {want}");
                for ax in 0..3 {
                    assert!(inc.q1[ax][n].x.abs() < 1e-3 * want, "voxel {n}: Q1 {:?}", inc.q1[ax][n]);
                }
            } else {
                assert_eq!(*q, Rgb::ZERO);
            }
        }
        assert_eq!(inc.fallback_rays, 0, "every full voxel is crossed by a family's lattice");
    }

    /// The clear-air hook replaces the radiance a ray carries where it enters the cloud from an
    /// empty voxel: a black sky with a hook that returns L everywhere gives the uniform-sky Q0.
    #[test]
    fn entry_hook_replaces_the_entering_radiance() {
        let m = thin_block();
        let hook = |_: [usize; 3], _: usize| Some(Rgb::splat(2.0));
        let inc = compute(
            &m,
            &DirectionBins::new(),
            &uniform_sky(0.0),
            &IncidentSettings::default(),
            Some(&hook),
        );
        let want = 0.9 * 1e-4 * 2.0;
        for (n, q) in inc.q0.iter().enumerate() {
            if m.density.data()[n] > 0.0 {
                assert!((q.x - want).abs() < 1e-3 * want, "voxel {n}: Q0 {q:?} vs {want}");
            }
        }
        let none = compute(
            &m,
            &DirectionBins::new(),
            &uniform_sky(0.0),
            &IncidentSettings::default(),
            Some(&|_, _| None),
        );
        assert!(none.q0.iter().all(|q| *q == Rgb::ZERO));
    }
}
