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
//! w = A·|ω·n| crosses the voxels with exact segment lengths (those of a DDA). In a voxel of
//! density ρ (piecewise constant, the voxel value, as the diffusion stage uses) and extinction
//! κ = ρσt it adds w·∫I ds = w·I_in·(1 − e^{−κl})/κ to the voxel's radiance sum and w·l to its
//! weight sum, then attenuates I by e^{−κl}. The voxel's mean radiance from the bin is
//! Ī_b = Σ w∫I ds / Σ w l: the paper's segment-length weighting, normalised by the (cross-section
//! weighted) sum of segment lengths.
//!
//! **Sweeps.** The lattice makes every ray of a family cross the slab between two planes of the
//! dominant axis at the same fractional position, so the cells a ray crosses in a slab, and the
//! lengths inside them, are one pattern for the whole family up to an integer translation. A
//! family is therefore propagated plane by plane: per slab its pattern (at most 1 + the cells
//! moved sideways, ≤ 3 segments for cubic voxels) is applied to the whole plane of rays at once,
//! over the plane's full voxels only. Each voxel of a plane receives exactly one segment per
//! pattern entry, so its weight sum is one slab's ray length times w for every voxel (w·T = voxel
//! volume × share), known in advance, and no box-sized buffer per direction is needed: the families
//! of one axis and direction sweep the same plane at the same step, and that plane's voxels are
//! reduced into Σ0, Σ1 (and the sky SH) at once, while they are in cache.
//!
//! **Q0 and Q1** (eqs. 5, 6, with the 1/4π of their definitions):
//! Q0 = ρσs/(4π) · Σ_b Δω_b Ī_b, Q1 = ρσs·g/(4π) · Σ_b Δω_b Ī_b (−m_b), where m_b is the bin's
//! exact mean direction ∫ω dω/Δω (towards the sky, length < 1). This uses ∫p(ω, ω′)ω dω = g ω′
//! for the HG phase function. σs = a·σt per band.
//!
//! **Sun.** The sun is traced apart, as one more parallel-ray direction without jitter, carrying
//! its irradiance; it adds ρσs/(4π)·E·T̄ to Q0 and ρσs g/(4π)·E·T̄·(−sun dir) to Q1, with T̄ the
//! voxel-mean transmittance. The reduced sun radiance for the gather's exact single scattering is
//! not part of stage 1: it is kept at voxel centres by [`crate::lit::sunlight::SunTransmittance`]
//! (exact optical depth of the trilinear field), which the renderers compute where it is read.
//!
//! **Clear-air hook** ([`EntryRadiance`]). When a sky-bin ray steps from an empty voxel X_e into a
//! face-adjacent full voxel, [`compute`] asks `entry(X_e, b)`. `Some(L)` means: the radiance
//! arriving at X_e from the directions of bin b (flowing along −dir_b) is L (W·m⁻²·sr⁻¹ per band),
//! and the ray carries L from there on instead of its attenuated sky value (the paper's section 3:
//! the viewing cube's bin replaces the propagating radiance). `None` keeps the attenuated value.
//! The hook is never asked for the sun, nor where a full voxel lies on the grid's own boundary
//! (no empty voxel precedes it).
//!
//! **Determinism.** Each family's lattice offset (and jitter) comes from a counter-based stream
//! keyed by (seed, bin, stratum); families step a plane in parallel, each into its own plane
//! buffer, and the plane is reduced per voxel in a fixed order of groups (axis and direction) and
//! families, so the result is bit-identical at any thread count.

use crate::lighting::bins::{narrowest_pixel_edge, DirectionBins, BINS_PER_EDGE, NUM_BINS};
use crate::lighting::{Ground, Sky, Sun};
use crate::math::{mix64, Rgb, Rng, Vec3};
use crate::math::{sh9, SH_COEFFS};
use crate::medium::sparse::VoxelField;
use crate::medium::Medium;
use crate::par;
pub use scattering::FirstScattering;

mod scattering;

/// The clear-air hook: `(empty voxel, bin) → Some(radiance arriving from that bin)`; see the module docs.
pub type EntryRadiance<'h> = dyn Fn([usize; 3], usize) -> Option<Rgb> + Sync + 'h;

/// Stage-1 sampling settings.
#[derive(Clone, Debug)]
pub struct IncidentSettings {
    /// Direction strata per bin edge: 1 traces each bin along its centre direction (the paper);
    /// n > 1 traces n² parallel families per bin, one per jittered sub-square of the bin, each
    /// weighted by its exact solid angle.
    pub rays_per_face_edge: usize,
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
    /// The sky, the ground below the horizon (unshadowed) and the sun. Each bin carries its mean
    /// radiance: a map sky's pixels summed into the bins ([`crate::lighting::envmap::EnvMap::cell_means`], so a sun in the
    /// map enters its bin with its power); a constant sky over a ground is exact with any
    /// sub-rectangles, the horizon being a bin edge.
    pub fn from_lighting(sun: &Sun, sky: &Sky, ground: Option<&Ground>, bins: &DirectionBins) -> IncidentSources {
        // The Lambertian ground is uniform: its radiance does not depend on the point.
        let below = ground.map(|g| g.radiance(Vec3::ZERO, sun, sky, 1.0));
        let bin_radiance = match sky.map() {
            Some(map) => map.cell_means(NUM_BINS, narrowest_pixel_edge(BINS_PER_EDGE), &|d| bins.bin_of(d), below),
            None => {
                let power = bins.integrate(8, &|d| match below {
                    Some(g) if d.y < 0.0 => g,
                    _ => sky.radiance(d),
                });
                power.iter().zip(&bins.bins).map(|(p, b)| *p / b.solid_angle as f32).collect()
            }
        };
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
    /// Q0 (eq. 5) and Q1 (eq. 6) per voxel, read with [`Self::q0`] and [`Self::q1`]; zero where
    /// ρ = 0. Like every field here, stored per full voxel and read by grid index
    /// ([`crate::medium::sparse`]); with the sun as the only source, as ρ times its voxel-mean
    /// transmittance alone.
    pub scattering: FirstScattering,
    /// Sun irradiance (W/m² per band); zero without a sun.
    pub sun_irradiance: Rgb,
    /// The mean radiance per bin that was propagated (W·m⁻²·sr⁻¹).
    pub bin_radiance: Vec<Rgb>,
    /// With [`IncidentSettings::sky_single`]: per voxel, the reduced sky and ground radiance (all
    /// bins, not the sun) projected onto the real spherical harmonics of degree ≤ 2 of the flow
    /// direction, L_lm = Σ_b Δω_b Ī_b Y_lm(ω_b), `[band * 9 + lm]` (W·m⁻²·sr⁻¹); zero where ρ = 0.
    pub sky_sh: Option<VoxelField<[f32; 3 * SH_COEFFS]>>,
}

impl IncidentLight {
    /// Q0 of grid voxel `g` in `band` (eq. 5, W·m⁻³·sr⁻¹).
    #[inline(always)]
    pub fn q0(&self, g: usize, band: usize) -> f32 {
        self.scattering.q0(g, band)
    }

    /// The `axis` component of Q1 of grid voxel `g` in `band` (eq. 6, W·m⁻³·sr⁻¹).
    #[inline(always)]
    pub fn q1(&self, axis: usize, g: usize, band: usize) -> f32 {
        self.scattering.q1(axis, g, band)
    }
}

/// One propagated direction: a sky bin or the sun.
struct Source {
    /// The bin's index; `None` for the sun.
    bin: Option<usize>,
    /// Radiance the rays carry into the box (W·m⁻²·sr⁻¹ per band; 1 for the sun).
    radiance: Rgb,
    /// Weight of the voxel-mean radiance in Σ0 and Σ1: Δω_b (sr) for a bin, E (W/m²) for the sun.
    weight: Rgb,
    /// Σ1's direction: −m_b for a bin, the flow direction for the sun.
    flow: Vec3,
    /// Degree-≤ 2 SH of the normalised flow direction (bins only: the sun is not projected).
    sh: Option<[f32; SH_COEFFS]>,
    /// Σ over the source's families of the weight sum Σ w·l every voxel receives (m³ · share):
    /// the normaliser of the voxel mean Ī_b.
    norm: f64,
}

/// The active box seen along axis `a`: planes of constant `a`, rows of constant `v`, `u` fastest.
struct Layout {
    a: usize,
    u: usize,
    v: usize,
    /// Box size along (u, v, a).
    nu: usize,
    nv: usize,
    na: usize,
    /// ρ at (cu, cv, ca), index (ca·nv + cv)·nu + cu.
    rho: Vec<f32>,
    /// Per (ca, cv): the range [lo, hi) of cu that holds every full voxel of the row.
    ext: Vec<(usize, usize)>,
}

impl Layout {
    fn new(a: usize, bd: [usize; 3], rho: &[f32]) -> Layout {
        let (u, v) = ((a + 1) % 3, (a + 2) % 3);
        let (nu, nv, na) = (bd[u], bd[v], bd[a]);
        let mut out = vec![0f32; nu * nv * na];
        let mut ext = vec![(usize::MAX, 0); nv * na];
        // One plane per task: serial, this transposed copy took a tenth of stage 1.
        let stride = [1, bd[0], bd[0] * bd[1]];
        let mut planes: Vec<_> = out.chunks_mut(nu * nv).zip(ext.chunks_mut(nv)).collect();
        par::for_chunks(&mut planes, 1, &|ca, part| {
            let (plane, ext) = &mut part[0];
            for (cv, (row, e)) in plane.chunks_exact_mut(nu).zip(ext.iter_mut()).enumerate() {
                let base = ca * stride[a] + cv * stride[v];
                for (cu, o) in row.iter_mut().enumerate() {
                    let r = rho[base + cu * stride[u]];
                    *o = r;
                    if r > 0.0 {
                        *e = (e.0.min(cu), cu + 1);
                    }
                }
            }
            });
        Layout {
            a,
            u,
            v,
            nu,
            nv,
            na,
            rho: out,
            ext,
        }
    }

    /// Box coordinates (x, y, z) of layout cell (cu, cv, ca).
    #[inline]
    fn cell(&self, cu: usize, cv: usize, ca: usize) -> [usize; 3] {
        let mut c = [0; 3];
        c[self.a] = ca;
        c[self.u] = cu;
        c[self.v] = cv;
        c
    }
}

/// One family of parallel rays: a bin's stratum direction (or the sun's) with its rigid lattice of
/// one ray per voxel face, swept plane by plane along the dominant axis of its direction.
///
/// Every ray of the lattice crosses a slab between two consecutive planes x_a = p, p + 1 at the
/// same fractional position, so the cells it crosses there and the lengths inside them are the
/// same for all rays up to an integer translation: `segs` holds that pattern once per slab, and
/// the sweep applies it to the whole plane of rays at once (the exact segment lengths of a
/// per-ray DDA, without walking each ray).
struct Family {
    /// Index of the source in the source list.
    src: usize,
    /// Sweep direction along the layout's axis: true for increasing a.
    forward: bool,
    /// Cross-section weight of one ray, area·|d_a|·share (m²).
    w: f32,
    /// Per slab p (counted from the entry plane), the range of `segs` crossed in it.
    slab: Vec<std::ops::Range<usize>>,
    /// The pattern: cell offset (u, v) from the ray's lattice index, and length (m).
    segs: Vec<(i64, i64, f64)>,
    /// Lattice index of ray (0, 0) and rays per lattice row: ray (ju, jv) is element
    /// (jv − v0)·nru + ju − u0.
    u0: i64,
    v0: i64,
    nru: usize,
    /// Radiance each ray carries (W·m⁻²·sr⁻¹ per band).
    l: Vec<Rgb>,
    /// Σ w∫I ds per band over the current plane's voxels (index cv·nu + cu).
    sums: Vec<[f32; 3]>,
}

/// Parameters q ∈ [0, 1) where a ray at fractional position `f` ∈ [0, 1) moving `s` cells per
/// slab crosses a cell boundary, with the cell offset after each crossing, appended to `out`
/// tagged with `axis` (0 = u, 1 = v).
fn crossings(s: f64, f: f64, axis: usize, out: &mut Vec<(f64, usize, i64)>) {
    if s > 0.0 {
        let mut k = 1i64;
        loop {
            let q = (k as f64 - f) / s;
            if q >= 1.0 {
                break;
            }
            out.push((q, axis, k));
            k += 1;
        }
    } else if s < 0.0 {
        // On a boundary moving backwards the ray is in the lower cell at once (q = 0).
        let mut j = 0i64;
        loop {
            let q = (f + j as f64) / -s;
            if q >= 1.0 {
                break;
            }
            out.push((q, axis, -(j + 1)));
            j += 1;
        }
    }
}

/// Cross-section of one lattice ray along unit `d` with dominant axis `a`, area·|d_a|·share (m²).
fn cross_section(h: Vec3, d: Vec3, a: usize, share: f32) -> f32 {
    h[(a + 1) % 3] * h[(a + 2) % 3] * d[a].abs() * share
}

/// Length of a ray along unit `d` between two lattice planes of axis `a`, h_a/|d_a| (m).
fn slab_length(h: Vec3, d: Vec3, a: usize) -> f64 {
    1.0 / (d.as_dvec3() / h.as_dvec3())[a].abs()
}

impl Family {
    /// The planned family `f` swept through `lay` (voxel size `h`, m), its rays carrying
    /// `radiance` (W·m⁻²·sr⁻¹ per band) into the box.
    fn new(f: &Planned, lay: &Layout, h: Vec3, radiance: Rgb) -> Family {
        let (a, u, v) = (lay.a, lay.u, lay.v);
        let (d, ou, ov) = (f.d, f.ou, f.ov);
        let fv = d.as_dvec3() / h.as_dvec3();
        // Cells moved along u and v per slab, and the ray length across one slab (m).
        let (su, sv, t_slab) = (fv[u] / fv[a].abs(), fv[v] / fv[a].abs(), slab_length(h, d, a));
        let mut slab = Vec::with_capacity(lay.na);
        let mut segs = Vec::new();
        let mut cross = Vec::new();
        let (mut umin, mut umax, mut vmin, mut vmax) = (i64::MAX, i64::MIN, i64::MAX, i64::MIN);
        for p in 0..lay.na {
            let (pu, pv) = (ou + p as f64 * su, ov + p as f64 * sv);
            let (bu, bv) = (pu.floor(), pv.floor());
            cross.clear();
            crossings(su, pu - bu, 0, &mut cross);
            crossings(sv, pv - bv, 1, &mut cross);
            cross.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
            let start = segs.len();
            let (mut off, mut q0) = ([0i64; 2], 0.0);
            let mut push = |off: [i64; 2], len: f64| {
                let o = (bu as i64 + off[0], bv as i64 + off[1]);
                umin = umin.min(o.0);
                umax = umax.max(o.0);
                vmin = vmin.min(o.1);
                vmax = vmax.max(o.1);
                segs.push((o.0, o.1, len));
            };
            for &(q, axis, o) in &cross {
                // Zero-length pieces (a crossing on a plane, two at once) are no segment.
                if q > q0 {
                    push(off, (q - q0) * t_slab);
                    q0 = q;
                }
                off[axis] = o;
            }
            if q0 < 1.0 {
                push(off, (1.0 - q0) * t_slab);
            }
            slab.push(start..segs.len());
        }
        // The rays whose cells cover the plane: cell = ray + offset for every offset.
        let (u0, v0) = (-umax, -vmax);
        let nru = (lay.nu as i64 - 1 - umin - u0 + 1) as usize;
        let nrv = (lay.nv as i64 - 1 - vmin - v0 + 1) as usize;
        Family {
            src: f.src,
            forward: d[a] > 0.0,
            w: cross_section(h, d, a, f.share),
            slab,
            segs,
            u0,
            v0,
            nru,
            l: vec![radiance; nru * nrv],
            sums: vec![[0.0; 3]; lay.nu * lay.nv],
        }
    }

    /// Box plane crossed in slab p.
    #[inline]
    fn plane(&self, lay: &Layout, p: usize) -> usize {
        if self.forward {
            p
        } else {
            lay.na - 1 - p
        }
    }

    /// Propagate every ray across slab p: deposit w∫I ds into `sums` for the plane's full voxels
    /// and attenuate, asking the clear-air hook where a ray steps from an empty voxel into a full
    /// one.
    fn step(&mut self, ctx: &Sweep, lay: &Layout, p: usize) {
        let (nu, nv) = (lay.nu, lay.nv);
        let ca = self.plane(lay, p);
        let np = nu * nv;
        let rho = &lay.rho[ca * np..(ca + 1) * np];
        let ext = &lay.ext[ca * nv..(ca + 1) * nv];
        for (cv, &(lo, hi)) in ext.iter().enumerate() {
            if lo < hi {
                self.sums[cv * nu + lo..cv * nu + hi].fill([0.0; 3]);
            }
        }
        let src = &ctx.sources[self.src];
        let hook = src.bin.and_then(|b| ctx.entry.map(|h| (h, b)));
        let kappa = ctx.kappa;
        let w = self.w;
        let range = self.slab[p].clone();
        for i in range.clone() {
            let (du, dv, len) = self.segs[i];
            // The cell each ray was in before this segment: the previous segment of this slab, or
            // the last of the previous slab (none before the entry plane).
            let prev = if i > range.start {
                let (pu, pv, _) = self.segs[i - 1];
                Some((pu - du, pv - dv, ca))
            } else if p > 0 {
                let (pu, pv, _) = self.segs[self.slab[p - 1].end - 1];
                Some((pu - du, pv - dv, self.plane(lay, p - 1)))
            } else {
                None
            };
            for (cv, &(lo, hi)) in ext.iter().enumerate() {
                if lo >= hi {
                    continue;
                }
                let jv = (cv as i64 - dv - self.v0) as usize;
                let base = jv as i64 * self.nru as i64 - du - self.u0;
                for cu in lo..hi {
                    let r = rho[cv * nu + cu];
                    if r <= 0.0 {
                        continue;
                    }
                    let ri = (cu as i64 + base) as usize;
                    let mut l = self.l[ri];
                    if let (Some((hook, b)), Some((pu, pv, pa))) = (hook, prev) {
                        let (qu, qv) = (cu as i64 + pu, cv as i64 + pv);
                        if qu >= 0 && qv >= 0 && (qu as usize) < nu && (qv as usize) < nv {
                            let (qu, qv) = (qu as usize, qv as usize);
                            if lay.rho[(pa * nv + qv) * nu + qu] <= 0.0 {
                                let c = lay.cell(qu, qv, pa);
                                if let Some(lh) = hook([c[0] + ctx.lo[0], c[1] + ctx.lo[1], c[2] + ctx.lo[2]], b) {
                                    l = lh;
                                }
                            }
                        }
                    }
                    // Eq. 2 across the segment: ∫I ds = I_in (1 − e^{−κl})/κ, then I_in e^{−κl}.
                    let tau = kappa * r as f64 * len;
                    let (e, integral) = if tau < 1e-6 {
                        (1.0 - tau, len * (1.0 - 0.5 * tau))
                    } else {
                        let e = (-tau).exp();
                        (e, (1.0 - e) * len / tau)
                    };
                    let li = l * Rgb::splat(integral as f32);
                    let s = &mut self.sums[cv * nu + cu];
                    s[0] += w * li.x;
                    s[1] += w * li.y;
                    s[2] += w * li.z;
                    self.l[ri] = l * Rgb::splat(e as f32);
                }
            }
        }
    }
}

/// Per full voxel: Σ0 (3 bands) then Σ1 (3 axes × 3 bands) in f64. The sky SH, when asked
/// for, lives in its own array: 108 B per voxel saved without it. All zero at first, so the
/// allocator hands the pages over zeroed (no serial fill of 96 B a voxel).
type Acc = [f64; 12];

/// The lanes of [`Acc`], in order: a sweep accumulates lanes `lanes[..]` of it per voxel.
const ALL_LANES: [usize; 12] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11];

/// The accumulators of one box row (y, z) of full voxels, in x order, and the row's cursor: the
/// rank of the next voxel an x-axis sweep reaches (its planes cross the row one voxel at a time).
struct Row<'a, const L: usize> {
    acc: &'a mut [[f64; L]],
    /// Empty without the sky SH.
    sh: &'a mut [[f32; 3 * SH_COEFFS]],
    cursor: usize,
}

impl<const L: usize> Row<'_, L> {
    /// Reduce lanes `lanes` into the row's voxel of rank `r`.
    #[inline]
    fn reduce(&mut self, fams: &[Family], coef: &[Coef], lay: &Layout, c: [usize; 3], r: usize, lanes: &[usize; L]) {
        reduce_voxel(fams, coef, lay, c, &mut self.acc[r], lanes, self.sh.get_mut(r));
    }
}

/// What every family's sweep reads.
struct Sweep<'a> {
    sources: Vec<Source>,
    entry: Option<&'a EntryRadiance<'a>>,
    lo: [usize; 3],
    /// Extinction per unit density the incident light decays with, the same in every band (m⁻¹).
    kappa: f64,
}

/// What one family's voxel sums S (Σ w∫I ds per band) add to the accumulators: Σ0 and Σ1 gain
/// Δω·Ī·(1, flow) with Ī = S / Σ w l, precomputed as one coefficient per band and term.
struct Coef {
    /// Σ0 per band, then Σ1 per (axis, band): Δω_c·flow_ax / Σ w l.
    m: [f64; 12],
    /// The sky SH per (band, lm): Δω_c·Y_lm / Σ w l (bins only).
    sh: Option<[f32; 3 * SH_COEFFS]>,
}

impl Coef {
    fn new(src: &Source) -> Coef {
        let inv = 1.0 / src.norm;
        let k = [src.weight.x as f64 * inv, src.weight.y as f64 * inv, src.weight.z as f64 * inv];
        let mut m = [0.0; 12];
        for c in 0..3 {
            m[c] = k[c];
            for ax in 0..3 {
                m[3 + 3 * ax + c] = k[c] * src.flow[ax] as f64;
            }
        }
        Coef {
            m,
            sh: src.sh.map(|y| std::array::from_fn(|j| k[j / SH_COEFFS] as f32 * y[j % SH_COEFFS])),
        }
    }
}

/// Add the current plane's sums of `fams` (coefficients `coef`) into voxel `c`'s accumulators,
/// in family order.
#[inline]
fn reduce_voxel<const L: usize>(
    fams: &[Family],
    coef: &[Coef],
    lay: &Layout,
    c: [usize; 3],
    acc: &mut [f64; L],
    lanes: &[usize; L],
    mut sh: Option<&mut [f32; 3 * SH_COEFFS]>,
) {
    let pi = c[lay.v] * lay.nu + c[lay.u];
    for (f, k) in fams.iter().zip(coef) {
        let s = f.sums[pi];
        let sd = [s[0] as f64, s[1] as f64, s[2] as f64];
        // Lane t is band t % 3 of term t / 3.
        for (a, &t) in acc.iter_mut().zip(lanes) {
            *a += sd[t % 3] * k.m[t];
        }
        if let (Some(ksh), Some(sh)) = (&k.sh, sh.as_deref_mut()) {
            for ((a, kc), sc) in sh.chunks_exact_mut(SH_COEFFS).zip(ksh.chunks_exact(SH_COEFFS)).zip(s) {
                for (a, kj) in a.iter_mut().zip(kc) {
                    *a += sc * kj;
                }
            }
        }
    }
}

/// What stage 1's sweeps read: the cloud box's density `rho` (box dims `bd`), voxel size `h`,
/// the families `plan` of the sources in `sw`.
struct Swept<'a> {
    rho: &'a [f32],
    bd: [usize; 3],
    h: Vec3,
    plan: &'a [Planned],
    sw: &'a Sweep<'a>,
    sky_single: bool,
    /// Full voxels (the accumulators).
    full: usize,
}

impl Swept<'_> {
    /// Sweep every family, accumulating lanes `lanes` of [`Acc`] per full voxel (in grid order);
    /// also the sky SH (in its field's slots, when asked for).
    fn sweep<const L: usize>(&self, lanes: &[usize; L]) -> (Vec<[f64; L]>, Vec<[f32; 3 * SH_COEFFS]>) {
        let (rho, bd, h, plan, sw) = (self.rho, self.bd, self.h, self.plan, self.sw);
        // Accumulators per full voxel in box order (= grid order: they are the fields' packed
        // storage), split into rows (y, z) for the parallel reduction.
        let row_len: Vec<usize> = rho.chunks_exact(bd[0]).map(|r| r.iter().filter(|v| **v > 0.0).count()).collect();
        let full: usize = row_len.iter().sum();
        assert_eq!(full, self.full, "stage 1 accumulates every full voxel once");
        let mut acc: Vec<[f64; L]> = vec![[0.0; L]; full];
        // The sky SH in its field's slots (slot 0 the empty voxels' zero), filled in place.
        let mut sh = vec![[0f32; 3 * SH_COEFFS]; if self.sky_single { full + 1 } else { 0 }];
        {
            let mut rows: Vec<Row<L>> = Vec::with_capacity(row_len.len());
            let (mut rest, mut rest_sh) = (&mut acc[..], sh.get_mut(1..).unwrap_or_default());
            for &len in &row_len {
                let (row, r) = rest.split_at_mut(len);
                let (row_sh, r_sh) = rest_sh.split_at_mut(if self.sky_single { len } else { 0 });
                rows.push(Row {
                    acc: row,
                    sh: row_sh,
                    cursor: 0,
                });
                (rest, rest_sh) = (r, r_sh);
            }
            // Sweep the families in groups of one axis and direction, in a fixed order: within a
            // group every family crosses the same plane at the same step, so its voxels are reduced
            // into the accumulators while that plane is in cache. One axis's layout at a time.
            for a in 0..3 {
                if !plan.iter().any(|f| f.axis == a) {
                    continue;
                }
                let lay = Layout::new(a, bd, rho);
                for forward in [true, false] {
                    let group: Vec<_> = plan.iter().filter(|f| f.axis == a && (f.d[a] > 0.0) == forward).collect();
                    if group.is_empty() {
                        continue;
                    }
                    let mut fams: Vec<Family> = group.iter().map(|f| Family::new(f, &lay, h, sw.sources[f.src].radiance)).collect();
                    let coef: Vec<Coef> = fams.iter().map(|f| Coef::new(&sw.sources[f.src])).collect();
                    // An x sweep meets each row's voxels in x order (backwards: from its end).
                    for (row, &len) in rows.iter_mut().zip(&row_len) {
                        row.cursor = if forward { 0 } else { len };
                    }
                    for p in 0..lay.na {
                        par::for_chunks(&mut fams, 1, &|_, f| f[0].step(sw, &lay, p));
                        let ca = fams[0].plane(&lay, p);
                        let by = bd[1];
                        let (fams, coef, lay) = (&fams[..], &coef[..], &lay);
                        match a {
                            2 => par::for_chunks(&mut rows[ca * by..(ca + 1) * by], 1, &|y, row| {
                                let row = &mut row[0];
                                let mut r = 0;
                                for x in 0..bd[0] {
                                    if rho[x + bd[0] * (y + by * ca)] > 0.0 {
                                        row.reduce(fams, coef, lay, [x, y, ca], r, lanes);
                                        r += 1;
                                    }
                                }
                            }),
                            _ => par::for_chunks(&mut rows, by, &|z, rz: &mut [Row<L>]| {
                                if a == 0 {
                                    for (y, row) in rz.iter_mut().enumerate() {
                                        if rho[ca + bd[0] * (y + by * z)] > 0.0 {
                                            if !forward {
                                                row.cursor -= 1;
                                            }
                                            let r = row.cursor;
                                            row.reduce(fams, coef, lay, [ca, y, z], r, lanes);
                                            if forward {
                                                row.cursor += 1;
                                            }
                                        }
                                    }
                                } else {
                                    let mut r = 0;
                                    for x in 0..bd[0] {
                                        if rho[x + bd[0] * (ca + by * z)] > 0.0 {
                                            rz[ca].reduce(fams, coef, lay, [x, ca, z], r, lanes);
                                            r += 1;
                                        }
                                    }
                                }
                            }),
                        }
                    }
                }
            }
        }
        (acc, sh)
    }
}

/// The propagated directions: the bins (those with light, or all with a clear-air hook), then
/// the sun if it shines. Each contributes Δω·Ī to Σ0 and Δω·Ī·flow to Σ1.
fn source_list(bins: &DirectionBins, sources: &IncidentSources, settings: &IncidentSettings, hook: bool) -> Vec<Source> {
    let mut srcs: Vec<Source> = bins
        .bins
        .iter()
        .enumerate()
        .filter(|(b, _)| sources.bin_radiance[*b].max_element() > 0.0 || hook)
        .map(|(b, bin)| Source {
            bin: Some(b),
            radiance: sources.bin_radiance[b],
            weight: Rgb::splat(bin.solid_angle as f32),
            flow: -bin.mean_dir,
            sh: settings.sky_single.then(|| sh9((-bin.mean_dir).normalize())),
            norm: 0.0,
        })
        .collect();
    if let Some((sun_dir, sun_e)) = sources.sun.filter(|s| s.1.max_element() > 0.0) {
        srcs.push(Source {
            bin: None,
            radiance: Rgb::ONE,
            weight: sun_e,
            flow: -sun_dir,
            sh: None,
            norm: 0.0,
        });
    }
    srcs
}

/// A family before its sweep: source index, dominant axis of its direction, the flow direction
/// (world, unit), its share of the source's solid angle and its lattice offset (voxels).
struct Planned {
    src: usize,
    axis: usize,
    d: Vec3,
    share: f32,
    ou: f64,
    ov: f64,
}

/// Every source's families: its strata, each along its own direction with one random lattice
/// offset, from the stream of (seed, source, stratum).
fn plan_families(srcs: &[Source], bins: &DirectionBins, settings: &IncidentSettings) -> Vec<Planned> {
    let ss = settings.rays_per_face_edge.max(1);
    let dominant = |d: Vec3| {
        if d.x.abs() >= d.y.abs() && d.x.abs() >= d.z.abs() {
            0
        } else if d.y.abs() >= d.z.abs() {
            1
        } else {
            2
        }
    };
    let mut plan = Vec::new();
    for (si, src) in srcs.iter().enumerate() {
        let id = src.bin.map_or(NUM_BINS as u64 + 1, |b| b as u64) ^ ((si as u64) << 32);
        for stratum in 0..ss * ss {
            let mut rng = Rng::new(mix64(settings.seed ^ mix64(id)), stratum as u64);
            // The family's direction and its share of the bin's solid angle.
            let (d, share) = match src.bin.map(|b| &bins.bins[b]) {
                Some(b) if ss > 1 => {
                    let (su, sv) = (stratum % ss, stratum / ss);
                    let (fu, fv) = ((su as f32 + rng.uniform()) / ss as f32, (sv as f32 + rng.uniform()) / ss as f32);
                    let du = (b.u[1] - b.u[0]) / ss as f64;
                    let dv = (b.v[1] - b.v[0]) / ss as f64;
                    let (ua, va) = (b.u[0] + su as f64 * du, b.v[0] + sv as f64 * dv);
                    let sa = crate::lighting::bins::rect_solid_angle(ua, ua + du, va, va + dv);
                    (-b.direction_at(fu, fv), (sa / b.solid_angle) as f32)
                }
                Some(b) => (-b.center, 1.0),
                None => (src.flow, 1.0),
            };
            // One random offset for the whole family: a rigid lattice keeps exactly one ray per
            // voxel face in every plane.
            let (ou, ov) = (rng.uniform_f64(), rng.uniform_f64());
            plan.push(Planned {
                src: si,
                axis: dominant(d),
                d,
                share,
                ou,
                ov,
            });
        }
    }
    plan
}

/// Stage 1: propagate every bin and the sun through `m`; see the module docs.
pub fn compute(
    m: &Medium,
    bins: &DirectionBins,
    sources: &IncidentSources,
    settings: &IncidentSettings,
    entry: Option<&EntryRadiance<'_>>,
) -> IncidentLight {
    let dims = m.dims();
    let sun_e = sources.sun.map_or(Rgb::ZERO, |s| s.1);
    // Stored per full voxel; the empty medium's fields (no full voxel) until the sweeps fill them.
    let index = m.density.full_index();
    let Some((lo, hi)) = m.active_box(1) else {
        return IncidentLight {
            dims,
            scattering: FirstScattering::zero(index),
            sun_irradiance: sun_e,
            bin_radiance: sources.bin_radiance.clone(),
            sky_sh: None,
        };
    };
    let bd = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
    let nb = bd[0] * bd[1] * bd[2];
    let mut rho = vec![0f32; nb];
    m.density.fill_box(lo, hi, &mut rho);
    // The medium's optics. A similarity transform is never applied here alone: it is already in
    // `m.optics` when `render.forward_fraction` asks for one (`render::delta_m`, the same medium
    // for every stage).
    let optics = m.optics;
    let mut srcs = source_list(bins, sources, settings, entry.is_some());
    let h = m.voxel_size;
    let plan = plan_families(&srcs, bins, settings);
    // Σ w·l per voxel and source: every voxel of a plane is crossed by one ray per pattern
    // segment, so it receives one slab's ray length, w·T, from each family.
    for f in &plan {
        srcs[f.src].norm += cross_section(h, f.d, f.axis, f.share) as f64 * slab_length(h, f.d, f.axis);
    }
    let sw = Sweep {
        sources: srcs,
        entry,
        lo,
        kappa: optics.sigma_t as f64,
    };
    // With the sun the only source and one extinction for every band, Q0 and Q1 follow from
    // ρT̄ (4 B per full voxel instead of 48), and the sweep accumulates Σ0 of one band only: 8 B
    // per full voxel instead of 96 (all twelve sums would be `full`'s peak at 200×160×120).
    let sun_only = sw.sources.iter().all(|s| s.bin.is_none());
    let (dir, e) = sources.sun.unwrap_or((Vec3::Y, Rgb::ZERO));
    let swept = Swept {
        rho: &rho,
        bd,
        h,
        plan: &plan,
        sw: &sw,
        sky_single: settings.sky_single,
        full: index.count(),
    };
    // ρ of the full voxels in box order, the accumulators' order (the box is dropped first).
    let pack = |rho: Vec<f32>| -> Vec<f32> { rho.into_iter().filter(|&r| r > 0.0).collect() };
    let (scattering, sh) = if sun_only {
        let (acc, sh) = swept.sweep(&[FirstScattering::sun_band(e)]);
        let packed_rho = pack(rho);
        (FirstScattering::sun(index.clone(), &optics, &acc, &packed_rho, dir, e), sh)
    } else {
        let (acc, sh) = swept.sweep(&ALL_LANES);
        let packed_rho = pack(rho);
        (FirstScattering::general(index.clone(), &optics, &acc, &packed_rho), sh)
    };
    IncidentLight {
        dims,
        scattering,
        sun_irradiance: sun_e,
        bin_radiance: sources.bin_radiance.clone(),
        sky_sh: settings.sky_single.then(|| VoxelField::from_slots(index, sh)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::medium::Grid3;
    use std::f64::consts::PI;

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

    /// A 256×128 map of 0.5 W·m⁻²·sr⁻¹ with one pixel of 10⁷ above the horizon, over a ground:
    /// the bins' powers, Σ Δω·L̄, are the map's integral over the upper hemisphere (its sum over
    /// pixels times their solid angles) plus the ground's π-sr hemisphere, the sun's pixel in one
    /// bin (to 5·10⁻³: a mean times the bin's exact solid angle, its sub-pixels along the bin's
    /// edges in or out); each bin below the horizon holds the ground's radiance. Samples at fixed
    /// directions miss the sun's pixel or count it over a whole sub-rectangle.
    #[test]
    fn a_map_sky_enters_the_bins_with_its_power() {
        let (w, h) = (256, 128);
        let (si, sj) = (77, 40);
        let mut pixels = vec![Rgb::splat(0.5); w * h];
        pixels[sj * w + si] = Rgb::splat(1e7);
        let sky = Sky::from_envmap(crate::lighting::envmap::EnvMap::new(w, h, pixels));
        let sun = Sun {
            dir: Vec3::Y,
            irradiance: Rgb::ZERO,
        };
        let ground = Ground {
            height: 0.0,
            albedo: Rgb::splat(0.3),
        };
        let bins = DirectionBins::new();
        let src = IncidentSources::from_lighting(&sun, &sky, Some(&ground), &bins);
        let map = sky.map().unwrap();
        let mut upper = 0.0;
        map.for_each_subpixel(0..h / 2, 2, &mut |_, l, d_omega| upper += l.x as f64 * d_omega);
        let ground_l = ground.radiance(Vec3::ZERO, &sun, &sky, 1.0).x as f64;
        let exact = upper + 2.0 * PI * ground_l;
        let sum: f64 = src.bin_radiance.iter().zip(&bins.bins).map(|(l, b)| l.x as f64 * b.solid_angle).sum();
        assert!((sum / exact - 1.0).abs() < 5e-3, "{sum} against {exact}");
        let sun_bin = bins.bin_of(crate::lighting::envmap::direction((si as f32 + 0.5) / w as f32, (sj as f32 + 0.5) / h as f32));
        let brightest = (0..NUM_BINS).max_by(|&a, &b| src.bin_radiance[a].x.total_cmp(&src.bin_radiance[b].x)).unwrap();
        assert_eq!(brightest, sun_bin);
        for (l, b) in src.bin_radiance.iter().zip(&bins.bins).filter(|(_, b)| b.mean_dir.y < 0.0) {
            assert!((l.x as f64 / ground_l - 1.0).abs() < 1e-5, "bin {b:?}: {l}");
        }
        let point = bins.integrate(8, &|d| if d.y < 0.0 { Rgb::splat(ground_l as f32) } else { sky.radiance(d) });
        let point: f64 = point.iter().map(|p| p.x as f64).sum();
        assert!((point / exact - 1.0).abs() > 0.1, "samples miss it or count it too often: {point} against {exact}");
    }

    /// Q0 of every grid voxel, in grid order.
    fn q0_of(inc: &IncidentLight) -> Vec<Rgb> {
        (0..inc.dims.iter().product())
            .map(|g| Rgb::new(inc.q0(g, 0), inc.q0(g, 1), inc.q0(g, 2)))
            .collect()
    }

    fn uniform_sky(l: f32) -> IncidentSources {
        IncidentSources {
            bin_radiance: vec![Rgb::splat(l); NUM_BINS],
            sun: None,
        }
    }

    /// Optically thin, uniform sky L: every voxel sees L from all 4π, so Q0 = ρσs·L (eq. 5 with
    /// ΣΔω = 4π) and Q1 = 0 (the bins' mean directions cancel), up to the attenuation ~τ.
    #[test]
    fn thin_block_under_a_uniform_sky_has_q0_of_the_sky_and_no_q1() {
        let m = thin_block();
        let inc = compute(&m, &DirectionBins::new(), &uniform_sky(2.0), &IncidentSettings::default(), None);
        let want = 0.9 * 1e-4 * 2.0;
        for (n, q) in q0_of(&inc).into_iter().enumerate() {
            if m.density.at(n) > 0.0 {
                assert!((q.x - want).abs() < 1e-3 * want, "voxel {n}: Q0 {q:?} vs {want}");
                for ax in 0..3 {
                    assert!(inc.q1(ax, n, 0).abs() < 1e-3 * want, "voxel {n}: Q1 {}", inc.q1(ax, n, 0));
                }
            } else {
                assert_eq!(q, Rgb::ZERO);
            }
        }
    }

    /// The sun alone is kept as ρT̄ (2 B per full voxel), with the thin block's Q0 = ρσs/(4π)·E·T̄
    /// (T̄ ≈ 1) and Q1 = g·Q0·(−sun dir); a lit bin beside it needs the general form.
    #[test]
    fn sun_alone_is_kept_in_two_bytes_per_full_voxel() {
        let m = thin_block();
        let dir = Vec3::new(0.2, 0.9, -0.4).normalize();
        let sun = IncidentSources {
            bin_radiance: vec![Rgb::ZERO; NUM_BINS],
            sun: Some((dir, Rgb::new(2.0, 3.0, 1.0))),
        };
        let inc = compute(&m, &DirectionBins::new(), &sun, &IncidentSettings::default(), None);
        assert!(matches!(inc.scattering, FirstScattering::Sun { .. }));
        assert_eq!(inc.scattering.bytes(), 2 * (64 + 1));
        let want = 0.9 * 1e-4 / (4.0 * PI) as f32 * Rgb::new(2.0, 3.0, 1.0);
        let n = 1 + 6 * (2 + 6 * 3);
        let (q0, g) = (q0_of(&inc)[n], 0.7);
        assert!((0..3).all(|c| (q0[c] - want[c]).abs() < 1e-3 * want[c]), "{q0:?} vs {want:?}");
        for ax in 0..3 {
            let q1 = |c| inc.q1(ax, n, c);
            assert!((0..3).all(|c| (q1(c) + g * dir[ax] * q0[c]).abs() < 1e-6 * q0[c]), "axis {ax}");
        }
        let mut lit = sun.clone();
        lit.bin_radiance[40] = Rgb::ONE;
        let both = compute(&m, &DirectionBins::new(), &lit, &IncidentSettings::default(), None);
        assert!(matches!(both.scattering, FirstScattering::General { .. }));
        assert!(both.q0(n, 0) > q0.x);
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
        for (n, q) in q0_of(&inc).into_iter().enumerate() {
            if m.density.at(n) > 0.0 {
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
        assert!(q0_of(&none).iter().all(|q| *q == Rgb::ZERO));
    }

    /// The scheme the sweep replaces, as an independent oracle: every lattice ray of source `si`'s
    /// families walked on its own with the shared DDA (with the clear-air hook), giving the
    /// voxel-mean radiance Σ w∫I ds / Σ w l per box voxel (zero where no ray deposits).
    fn per_ray_mean(m: &Medium, srcs: &[Source], plan: &[Planned], si: usize, entry: Option<&EntryRadiance<'_>>) -> Vec<[f64; 3]> {
        use crate::medium::{ray_box, Dda};
        use glam::DVec3;
        let bd = m.dims();
        let (h, atten) = (m.voxel_size, [m.optics.sigma_t as f64; 3]);
        let lin = |c: [usize; 3]| c[0] + bd[0] * (c[1] + bd[1] * c[2]);
        let mut sums = vec![[0f64; 4]; bd[0] * bd[1] * bd[2]];
        let hi = DVec3::new(bd[0] as f64, bd[1] as f64, bd[2] as f64);
        for f in plan.iter().filter(|f| f.src == si) {
            let (a, u, v) = (f.axis, (f.axis + 1) % 3, (f.axis + 2) % 3);
            let dv = f.d.as_dvec3() / h.as_dvec3();
            let w = cross_section(h, f.d, a, f.share) as f64;
            let n = 2 * (bd[0] + bd[1] + bd[2]) as i64;
            for jv in -n..n {
                for ju in -n..n {
                    let mut o = DVec3::ZERO;
                    o[a] = if f.d[a] > 0.0 { 0.0 } else { bd[a] as f64 };
                    o[u] = ju as f64 + f.ou;
                    o[v] = jv as f64 + f.ov;
                    let Some((t0, t1)) = ray_box(DVec3::ZERO, hi, o, dv, f64::NEG_INFINITY, f64::INFINITY) else {
                        continue;
                    };
                    let mut l = srcs[si].radiance.as_dvec3();
                    let mut prev: Option<([usize; 3], bool)> = None;
                    for seg in Dda::new(DVec3::ZERO, DVec3::ONE, bd, o, dv, t0, t1) {
                        let (c, len) = (seg.cell, seg.len());
                        let rho = m.density.get(c[0], c[1], c[2]) as f64;
                        if rho > 0.0 {
                            if let (Some(hook), Some((pc, false)), Some(b)) = (entry, prev, srcs[si].bin) {
                                if let Some(lh) = hook(pc, b) {
                                    l = lh.as_dvec3();
                                }
                            }
                            let s = &mut sums[lin(c)];
                            for band in 0..3 {
                                let k = atten[band] * rho;
                                s[band] += w * l[band] * (1.0 - (-k * len).exp()) / k;
                                l[band] *= (-k * len).exp();
                            }
                            s[3] += w * len;
                        }
                        prev = Some((c, rho > 0.0));
                    }
                }
            }
        }
        sums.iter()
            .map(|s| {
                if s[3] > 0.0 {
                    [s[0] / s[3], s[1] / s[3], s[2] / s[3]]
                } else {
                    [0.0; 3]
                }
            })
            .collect()
    }

    /// The sweep against the per-ray oracle, one lit bin on each cube face, on an irregular cloud
    /// of non-cubic voxels (up to ~1 optical depth each, so up to 2 cells moved sideways per slab),
    /// with jittered strata and a clear-air hook, and without either: Q0 = ρσs/(4π)·Δω_b·Ī_b.
    #[test]
    fn sweep_matches_a_per_ray_dda_walk() {
        let dims = [7, 6, 5];
        let mut rng = Rng::new(11, 0);
        let g = crate::medium::test_grids::random_cloud(dims, &mut rng, 0.7, 0.2, 1.0);
        let m = Medium::new(g, Vec3::ZERO, Vec3::new(1.0, 0.45, 1.3), 0.8, Rgb::new(0.9, 0.8, 0.7), 0.0);
        assert_eq!(m.active_box(1), Some(([0; 3], dims)), "the oracle walks the whole grid");
        let bins = DirectionBins::new();
        let hook = |c: [usize; 3], _: usize| ((c[0] + c[1] + c[2]) % 2 == 0).then(|| Rgb::new(5.0, 4.0, 3.0));
        for (ss, with_hook) in [(1, false), (2, true)] {
            let settings = IncidentSettings {
                rays_per_face_edge: ss,
                sky_single: false,
                seed: 5,
            };
            for b in [3, 18, 37, 52, 65, 90] {
                let mut radiance = vec![Rgb::ZERO; NUM_BINS];
                radiance[b] = Rgb::new(2.0, 1.5, 1.0);
                let sources = IncidentSources {
                    bin_radiance: radiance,
                    sun: None,
                };
                // Other bins stay dark: the hook lights only bin b.
                let lit_hook = |c: [usize; 3], bb: usize| if bb == b { hook(c, bb) } else { None };
                let entry: Option<&EntryRadiance<'_>> = if with_hook { Some(&lit_hook) } else { None };
                let inc = compute(&m, &bins, &sources, &settings, entry);
                let srcs = source_list(&bins, &sources, &settings, with_hook);
                let si = srcs.iter().position(|s| s.bin == Some(b)).unwrap();
                let mean = per_ray_mean(&m, &srcs, &plan_families(&srcs, &bins, &settings), si, entry);
                let (sigma_s, dw) = (m.optics.sigma_s(), bins.bins[b].solid_angle);
                for (n, q) in q0_of(&inc).into_iter().enumerate() {
                    let rho = m.density.at(n) as f64;
                    for band in 0..3 {
                        let want = rho * sigma_s[band] as f64 / (4.0 * PI) * dw * mean[n][band];
                        let got = q[band] as f64;
                        assert!(
                            (got - want).abs() <= 1e-5 * want.abs() + 1e-12,
                            "ss {ss}, hook {with_hook}, bin {b}, voxel {n}, band {band}: sweep {got} vs per-ray {want}"
                        );
                    }
                }
                assert!(q0_of(&inc).iter().filter(|q| q.x > 0.0).count() > 100);
            }
        }
    }
}
