//! Viewing cubes at the cloud's border voxels (paper section 3, Figure 1).
//!
//! A border voxel is an empty voxel (ρ = 0) of the grid that shares a face with a full one
//! (ρ > 0). Stage 1 of the diffusion pipeline propagates light in bin i along parallel rays of
//! travel direction ω_i; where such a ray steps from a border voxel X_e across face F into a full
//! voxel, the paper replaces the propagating (attenuated sky) radiance by what a cube at X_e's
//! centre sees in bin −ω_i.
//!
//! **Sign convention.** A cube's bin b holds the radiance *arriving* at the cube's centre from the
//! directions of bin b, i.e. what one sees *looking towards* ω_b. A ray *travelling* in direction
//! d carries the radiance that arrived from −d, so [`BorderCubes::entry_radiance`]`(v, i)` for a
//! travel bin i returns bin [`opposite_bin`]`(i)` of the cube. A ray crossing face F (outward
//! normal n from X_e towards the full neighbour) travels with d·n > 0, so it needs the cube bins
//! looking away from the neighbour, ω·n < 0: the half cube of Figure 1b. A voxel with full
//! neighbours across several faces needs the union of those half cubes (for two faces sharing an
//! edge, 72 of the 96 bins; the paper rendered 80).

use super::render::{opposite_bin, BinMask, CubeOptions, CubeRenderer};
use crate::lighting::bins::NUM_BINS;
use crate::lit::LitVolume;
use crate::math::{Rgb, Vec3};
use crate::medium::Grid3;
use crate::pipeline::Progress;
use rayon::prelude::*;

/// Face offsets in [`crate::lighting::CUBE_FACES`] order: +x, −x, +y, −y, +z, −z.
pub const FACE_OFFSETS: [[isize; 3]; 6] = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]];

/// Border voxels of a density grid, in memory order (x fastest), each with the set of faces
/// (bit f = [`FACE_OFFSETS`]`[f]`) across which it touches a full voxel. Voxels outside the grid
/// are not considered (a cloud touching the grid's side gets no cubes there).
pub fn find_border_voxels(density: &Grid3) -> Vec<([usize; 3], u8)> {
    let d = density.dims();
    let mut out = Vec::new();
    for k in 0..d[2] {
        for j in 0..d[1] {
            for i in 0..d[0] {
                if density.get(i, j, k) > 0.0 {
                    continue;
                }
                let mut faces = 0u8;
                for (f, o) in FACE_OFFSETS.iter().enumerate() {
                    if density.get_or_zero(i as isize + o[0], j as isize + o[1], k as isize + o[2]) > 0.0 {
                        faces |= 1 << f;
                    }
                }
                if faces != 0 {
                    out.push(([i, j, k], faces));
                }
            }
        }
    }
    out
}

/// The rendered border cubes: per border voxel, the mean radiance in each needed bin. Only the
/// needed bins are stored (packed in bin order), and a voxel is found by binary search in
/// [`Self::voxels`] (memory order), so the cubes cost memory in proportion to the cloud's
/// surface, not the grid.
#[derive(Clone, Debug)]
pub struct BorderCubes {
    /// Grid dims the voxel indices refer to.
    pub dims: [usize; 3],
    /// Border voxels, in memory order.
    pub voxels: Vec<[usize; 3]>,
    /// Faces with a full neighbour, per voxel (bit f = [`FACE_OFFSETS`]`[f]`).
    pub faces: Vec<u8>,
    /// Bins rendered, per voxel.
    pub needed: Vec<BinMask>,
    /// Mean radiance arriving from each needed bin's directions (W·m⁻²·sr⁻¹): cube n's needed
    /// bins in bin order, from `offsets[n]`.
    pub radiance: Vec<Rgb>,
    /// Start of each cube's bins in `radiance` (one more entry than cubes).
    offsets: Vec<usize>,
}

impl BorderCubes {
    /// Number of cubes.
    #[inline]
    pub fn len(&self) -> usize {
        self.voxels.len()
    }

    /// True when the grid has no border voxel.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.voxels.is_empty()
    }

    /// Position of `voxel` in [`Self::voxels`], if it is a border voxel.
    #[inline]
    pub fn find(&self, voxel: [usize; 3]) -> Option<usize> {
        let key = |v: &[usize; 3]| (v[2], v[1], v[0]);
        self.voxels.binary_search_by_key(&key(&voxel), key).ok()
    }

    /// The 96 bin radiances of cube `n` (zero where not rendered).
    pub fn bins(&self, n: usize) -> [Rgb; NUM_BINS] {
        let mut out = [Rgb::ZERO; NUM_BINS];
        for (b, l) in self.needed[n].iter().zip(&self.radiance[self.offsets[n]..self.offsets[n + 1]]) {
            out[b] = *l;
        }
        out
    }

    /// Mean radiance arriving at `voxel`'s centre from the directions of bin `bin` (looking
    /// towards them), if `voxel` is a border voxel and the bin was rendered.
    #[inline]
    pub fn lookup(&self, voxel: [usize; 3], bin: usize) -> Option<Rgb> {
        let n = self.find(voxel)?;
        let mask = self.needed[n];
        // The bin's rank among the needed bins: how many needed bins come before it.
        let rank = (mask.0 & ((1u128 << bin) - 1)).count_ones() as usize;
        mask.contains(bin).then(|| self.radiance[self.offsets[n] + rank])
    }

    /// Radiance carried by a stage-1 ray that *travels* in bin `travel_bin` out of border voxel
    /// `voxel` into the cloud: the cube's bin opposite to `travel_bin` (the light comes from
    /// −ω). None if `voxel` is not a border voxel or that bin was not needed (then the ray
    /// cannot be entering a full neighbour from here).
    #[inline]
    pub fn entry_radiance(&self, voxel: [usize; 3], travel_bin: usize) -> Option<Rgb> {
        self.lookup(voxel, opposite_bin(travel_bin))
    }

    /// The stage-1 hook ([`crate::incident::EntryRadiance`]): stage 1 asks with the *source* bin b
    /// (the sky direction its rays come from, flowing along −ω_b), which is the cube's own bin b,
    /// so this is [`Self::lookup`], not [`Self::entry_radiance`] (which takes the travel bin).
    pub fn hook(&self) -> impl Fn([usize; 3], usize) -> Option<Rgb> + Sync + '_ {
        move |v, b| self.lookup(v, b)
    }
}

/// Render a cube at every border voxel of `lit`'s density grid (its needed bins only), in
/// parallel, marching with `opts.border_step_level_voxels` and `opts.border_t_cutoff`; the result does not depend on the
/// thread count.
pub fn render_border_cubes(lit: &LitVolume, opts: &CubeOptions, progress: &dyn Progress) -> BorderCubes {
    let opts = CubeOptions {
        step_level_voxels: opts.border_step_level_voxels,
        t_cutoff: opts.border_t_cutoff,
        res: opts.border_res,
        ..opts.clone()
    };
    let renderer = CubeRenderer::new(lit, &opts);
    render_border_cubes_with(&renderer, progress)
}

/// Blocks of 2^[`SHARED_SCALES`] voxels per edge are the largest whose border voxels share rays.
pub const SHARED_SCALES: usize = 3;

/// Where a block of 2^`scale` voxels per edge takes over a pixel's ray (m), given the distance
/// `unit` at which the cone is one finest voxel wide: 2^(scale − 1)·[`SHARED_FOOTPRINTS`]·unit
/// (scale ≥ 1), where the cone is that many times the block's edge wide.
fn piece_start(unit: f32, scale: usize) -> f32 {
    SHARED_FOOTPRINTS * unit * (1u32 << scale) as f32 * 0.5
}

/// Cone widths per block edge at which a block's shared piece begins (see [`piece_start`]).
pub const SHARED_FOOTPRINTS: f32 = 2.0;

/// [`render_border_cubes`] with a renderer already built (pyramid and tables reused).
///
/// **Shared rays.** A pixel's ray marches pyramid level l where its cone is 2^l finest voxels
/// wide, so there the rays of the border voxels in one block of 2^l voxels per edge differ by
/// less than the cone's footprint. Each such block traces that level's piece once per pixel of
/// the union of its voxels' needed bins, from the mean of their centres (level
/// [`SHARED_SCALES`] and coarser from the largest block, with what lies behind); each voxel
/// marches only the finest level itself. A pixel's radiance is the pieces composited front to
/// back: L₀ + T₀·(L₁ + T₁·(…)). Measured in docs/performance.md.
pub fn render_border_cubes_with(renderer: &CubeRenderer<'_>, progress: &dyn Progress) -> BorderCubes {
    let lit = renderer.lit;
    let found = find_border_voxels(&lit.medium.density);
    let needed: Vec<BinMask> = found.iter().map(|(_, f)| BinMask::for_faces(*f)).collect();
    let mut offsets = Vec::with_capacity(found.len() + 1);
    offsets.push(0);
    for m in &needed {
        offsets.push(offsets.last().copied().unwrap_or(0) + m.count() as usize);
    }
    let top = SHARED_SCALES.min(renderer.levels().saturating_sub(1));
    // The voxels of each largest block, blocks in memory order of their first voxel.
    let key = |n: usize, scale: usize| {
        let v = found[n].0;
        (v[2] >> scale, v[1] >> scale, v[0] >> scale)
    };
    let mut order: Vec<usize> = (0..found.len()).collect();
    order.sort_by_key(|&n| (key(n, top), n));
    let groups: Vec<&[usize]> = order.chunk_by(|&a, &b| key(a, top) == key(b, top)).collect();
    progress.begin("border cubes", found.len() as u64);
    // Groups in parallel, each returning its voxels' packed bins; scattered in order after, so
    // the result does not depend on the thread count.
    let res = renderer.opts.res;
    let px = &renderer.pixels;
    let centre = |n: usize| {
        let [i, j, k] = found[n].0;
        lit.medium.voxel_center(i, j, k)
    };
    // The radiance behind level `scale`'s piece, per cube pixel, for the members of one block.
    let shared = |members: &[usize], scale: usize, behind: Option<&[Rgb]>| -> Vec<Rgb> {
        let q = members.iter().fold(Vec3::ZERO, |acc, &n| acc + centre(n)) / members.len() as f32;
        let union = members.iter().fold(BinMask::NONE, |m, &n| m.union(needed[n]));
        let mut out = vec![Rgb::ZERO; 6 * res * res];
        for b in union.iter() {
            for (face, i, j) in px.bin_pixels(b) {
                let k = (face * res + j) * res + i;
                let (d, cone) = (px.dirs[k], px.cone[j * res + i]);
                let start = piece_start(renderer.footprint_distance(cone), scale);
                out[k] = match behind {
                    None => renderer.trace_from(q, d, cone, start),
                    Some(far) => {
                        let end = piece_start(renderer.footprint_distance(cone), scale + 1);
                        let (l, tr) = renderer.trace_span(q, d, cone, start, end);
                        if tr > 0.0 {
                            l + far[k] * tr
                        } else {
                            l
                        }
                    }
                };
            }
        }
        out
    };
    let per_group: Vec<Vec<(usize, Vec<Rgb>)>> = groups
        .par_iter()
        .map(|members| {
            let mut out = Vec::with_capacity(members.len());
            // Blocks from the largest down to single voxels, each with the radiance behind it.
            let mut stack: Vec<(Vec<usize>, usize, Option<Vec<Rgb>>)> = vec![(members.to_vec(), top, None)];
            while let Some((mut ms, scale, behind)) = stack.pop() {
                if scale == 0 {
                    let far = behind.as_deref();
                    for &n in &ms {
                        let p = centre(n);
                        let bins = needed[n]
                            .iter()
                            .map(|b| {
                                renderer.bin_mean(b, |k, cone| match far {
                                    None => renderer.trace(p, px.dirs[k], cone),
                                    Some(far) => {
                                        let end = piece_start(renderer.footprint_distance(cone), 1);
                                        let (l, tr) = renderer.trace_span(p, px.dirs[k], cone, 0.0, end);
                                        if tr > 0.0 {
                                            l + far[k] * tr
                                        } else {
                                            l
                                        }
                                    }
                                })
                            })
                            .collect();
                        out.push((n, bins));
                    }
                    continue;
                }
                let here = shared(&ms, scale, behind.as_deref());
                ms.sort_by_key(|&n| (key(n, scale - 1), n));
                for sub in ms.chunk_by(|&a, &b| key(a, scale - 1) == key(b, scale - 1)) {
                    stack.push((sub.to_vec(), scale - 1, Some(here.clone())));
                }
            }
            progress.advance(members.len() as u64);
            out
        })
        .collect();
    let mut radiance = vec![Rgb::ZERO; offsets[found.len()]];
    for (n, bins) in per_group.into_iter().flatten() {
        radiance[offsets[n]..offsets[n + 1]].copy_from_slice(&bins);
    }
    progress.end();
    BorderCubes {
        dims: lit.dims(),
        voxels: found.iter().map(|(v, _)| *v).collect(),
        faces: found.iter().map(|(_, f)| *f).collect(),
        needed,
        radiance,
        offsets,
    }
}
