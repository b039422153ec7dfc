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

use super::render::{opposite_bin, BinMask, CubeOptions, CubeRenderer, LevelTables};
use crate::diffusion::boundary::hemisphere_radiance;
use crate::lighting::bins::{DirectionBins, CUBE_FACES, NUM_BINS};
use crate::lit::LitVolume;
use crate::math::{Rgb, Vec3};
use crate::medium::Density;
use crate::pipeline::Progress;
use crate::par;

/// Face offsets in [`crate::lighting::CUBE_FACES`] order: +x, −x, +y, −y, +z, −z.
pub const FACE_OFFSETS: [[isize; 3]; 6] = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]];

/// Border voxels of a density grid, in memory order (x fastest), each with the set of faces
/// (bit f = [`FACE_OFFSETS`]`[f]`) across which it touches a full voxel. Voxels outside the grid
/// are not considered (a cloud touching the grid's side gets no cubes there).
pub fn find_border_voxels(density: &Density) -> Vec<([usize; 3], u8)> {
    let d = density.dims();
    let (nx, nxy) = (d[0] as isize, (d[0] * d[1]) as isize);
    // Per face, the index offset of the neighbour and whether voxel (i, j, k) has one there.
    let strides = [1, -1, nx, -nx, nxy, -nxy];
    // Slices in parallel, each in memory order; concatenated in order.
    let slices = par::map_range(d[2], &|k| {
        let mut out = Vec::new();
        for j in 0..d[1] {
            for i in 0..d[0] {
                let n = i + d[0] * (j + d[1] * k);
                if density.is_full(n) {
                    continue;
                }
                let inside = [i + 1 < d[0], i > 0, j + 1 < d[1], j > 0, k + 1 < d[2], k > 0];
                let mut faces = 0u8;
                for f in 0..6 {
                    if inside[f] && density.is_full((n as isize + strides[f]) as usize) {
                        faces |= 1 << f;
                    }
                }
                if faces != 0 {
                    out.push(([i, j, k], faces));
                }
            }
        }
        out
    });
    slices.concat()
}

/// The rendered border cubes: per border voxel, the mean radiance in each needed bin. Only the
/// needed bins are stored (packed in bin order), and a voxel is found by binary search in
/// [`Self::voxels`] (memory order), so the cubes cost memory in proportion to the cloud's
/// surface, not the grid.
#[derive(Clone, Debug)]
pub struct BorderCubes {
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
    render_border_cubes_with(&border_renderer(lit, opts, LevelTables::new(lit, opts)), progress)
}

/// The border cubes' renderer over `lit` with `tables` ([`CubeRenderer::with_tables`]): the
/// border's options ([`border_options`]), and behind each pixel's one ray the sky's mean over
/// the pixel ([`CubeRenderer::with_sky_means`]), so a sun in a map sky reaches the border
/// voxels whose pixels hold it with its power.
pub fn border_renderer<'a>(lit: &'a LitVolume, opts: &CubeOptions, tables: LevelTables) -> CubeRenderer<'a> {
    CubeRenderer::with_tables(lit, &border_options(opts), tables).with_sky_means()
}

/// The border cubes' renderer options: `opts` with the border's step, cut-off and resolution.
pub fn border_options(opts: &CubeOptions) -> CubeOptions {
    CubeOptions {
        step_level_voxels: opts.border_step_level_voxels,
        t_cutoff: opts.border_t_cutoff,
        res: opts.border_res,
        ..opts.clone()
    }
}

/// Blocks of 2^[`SHARED_SCALES`] voxels per edge are the largest whose border voxels share rays.
pub const SHARED_SCALES: usize = 3;

/// Where a block of 2^`scale` voxels per edge takes over a pixel's ray (m), given the distance
/// `unit` at which the cone is one finest voxel wide: 2^(scale − 1)·[`SHARED_FOOTPRINTS`]·unit
/// (scale ≥ 1), where the cone is [`SHARED_FOOTPRINTS`]/2 times the block's edge wide.
fn piece_start(unit: f32, scale: usize) -> f32 {
    SHARED_FOOTPRINTS * unit * (1u32 << scale) as f32 * 0.5
}

/// Twice the cone widths per block edge at which a block's shared piece begins ([`piece_start`]).
/// Measured on two lobes against 16 rays per bin: at 4 the shared one-ray bins err 3 % more
/// than each voxel's own rays, at 3 10 %, at 2 (each block from its level's first distance) 60 %.
pub const SHARED_FOOTPRINTS: f32 = 4.0;

/// [`render_border_cubes`] with a renderer already built (pyramid and tables reused).
///
/// **Shared rays.** Where a pixel's cone is twice as wide as a block of 2^s voxels per edge
/// ([`piece_start`]), the rays of the border voxels in that block lie less than half the cone's
/// footprint apart: each block traces that piece of the ray (up to where the next
/// larger block takes over) once per pixel of the union of its voxels' needed bins, from the
/// mean of their centres, the largest blocks (2^[`SHARED_SCALES`]) to the end with what lies
/// behind; each voxel marches only the piece in front of the first block's. A pixel's radiance
/// is the pieces composited front to back: L₀ + T₀·(L₁ + T₁·(…)). The bins are as good
/// estimates of the bins' means as each voxel's own rays (unit test below); the clear-air stage
/// runs ~40 % fewer instructions (docs/performance.md).
pub fn render_border_cubes_with(renderer: &CubeRenderer<'_>, progress: &dyn Progress) -> BorderCubes {
    let found = find_border_voxels(&renderer.lit.medium.density);
    let needed: Vec<BinMask> = found.iter().map(|(_, f)| BinMask::for_faces(*f)).collect();
    let mut offsets = Vec::with_capacity(found.len() + 1);
    offsets.push(0);
    for m in &needed {
        offsets.push(offsets.last().copied().unwrap_or(0) + m.count() as usize);
    }
    let mut radiance = vec![Rgb::ZERO; offsets[found.len()]];
    render_each(renderer, progress, &found, &needed, |n, bins| {
        radiance[offsets[n]..offsets[n + 1]].copy_from_slice(bins);
    });
    BorderCubes {
        voxels: found.iter().map(|(v, _)| *v).collect(),
        faces: found.iter().map(|(_, f)| *f).collect(),
        needed,
        radiance,
        offsets,
    }
}

/// What the border cubes send into the cloud through its boundary faces, without their bins:
/// for each face between a border voxel and a full one, (the border voxel's grid index, the
/// full voxel's outward normal there as an index into [`CUBE_FACES`], the cube's cosine-weighted
/// mean radiance over that face's outer hemisphere) — the input of
/// [`crate::diffusion::BoundaryLight::with_ghosts`]. Each cube is reduced as its batch is
/// rendered, so the bins of only one batch are held (all cubes' bins took 66 B per full voxel
/// at 200×160×120, the peak of `full`). Returns the number of cubes too.
pub fn render_border_face_light_with(renderer: &CubeRenderer<'_>, progress: &dyn Progress) -> (usize, Vec<(usize, usize, Rgb)>) {
    let found = find_border_voxels(&renderer.lit.medium.density);
    let needed: Vec<BinMask> = found.iter().map(|(_, f)| BinMask::for_faces(*f)).collect();
    let d = renderer.lit.dims();
    let bins = DirectionBins::new();
    let mut light = Vec::new();
    render_each(renderer, progress, &found, &needed, |n, packed| {
        let mut all = [Rgb::ZERO; NUM_BINS];
        for (b, l) in needed[n].iter().zip(packed) {
            all[b] = *l;
        }
        let (v, faces) = found[n];
        let ghost = v[0] + d[0] * (v[1] + d[1] * v[2]);
        // The full neighbour lies along FACE_OFFSETS[f]; its face towards this voxel has the
        // opposite normal, the other index of the pair (+a, −a).
        for f in (0..6).filter(|f| faces & (1 << f) != 0) {
            let face = f ^ 1;
            light.push((ghost, face, hemisphere_radiance(&bins.bins, &all, CUBE_FACES[face].n)));
        }
    });
    (found.len(), light)
}

/// Render the cubes of the border voxels `found` (bins `needed`), handing each cube's packed
/// bins to `take` in an order that does not depend on the thread count.
fn render_each(
    renderer: &CubeRenderer<'_>,
    progress: &dyn Progress,
    found: &[([usize; 3], u8)],
    needed: &[BinMask],
    mut take: impl FnMut(usize, &[Rgb]),
) {
    let mut uniform = renderer.clone();
    uniform.uniform_short_levels = true;
    let renderer = &uniform;
    let lit = renderer.lit;
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
    let render_group = |members: &&[usize]| {
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
    };
    // Groups in batches, each batch's bins scattered into the packed array before the next is
    // rendered: the per-voxel vectors of only one batch are alive at a time (all of them at once
    // would be 2× the packed bins, 41 MB at 200×160×120). Eight groups per thread keep every
    // thread busy to a batch's end; 64 groups would hold 3.75 MB of them at 200×160×120 on two
    // threads, the largest item at `full`'s clear-air peak after the lit cells. The result does not depend
    // on the batch size (scattered in order).
    let batch_groups = 8 * rayon::current_num_threads().max(1);
    for batch in groups.chunks(batch_groups) {
        let per_group: Vec<Vec<(usize, Vec<Rgb>)>> = par::map_range(batch.len(), &|i| render_group(&batch[i]));
        for (n, bins) in per_group.into_iter().flatten() {
            take(n, &bins);
        }
    }
    progress.end();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::{Sky, Sun};
    use crate::medium::Grid3;
    use crate::pipeline::NoProgress;

    /// An empty scene under a 256×128 map of 0.5 W·m⁻²·sr⁻¹ with one pixel of 10⁷: the border
    /// renderer sees behind each pixel's ray the map's mean over that pixel, so the cube's pixels
    /// times their solid angles sum to the map's integral (to 5·10⁻³, the sub-pixels along the
    /// pixels' edges), the sun's power in the pixel holding it; the plain renderer's rays along the pixels' axes miss it.
    #[test]
    fn the_border_cubes_see_a_map_sky_by_its_pixels_means() {
        let (w, h) = (256, 128);
        let mut pixels = vec![Rgb::splat(0.5); w * h];
        pixels[40 * w + 77] = Rgb::splat(1e7);
        let sky = Sky::from_envmap(crate::lighting::envmap::EnvMap::new(w, h, pixels));
        let map = sky.map().unwrap().clone();
        let sun = Sun {
            dir: Vec3::Y,
            irradiance: Rgb::ZERO,
        };
        let empty = crate::medium::Medium::new(Grid3::filled([2, 2, 2], 0.0), Vec3::ZERO, Vec3::ONE, 1.0, Rgb::ONE, 0.0);
        let lit = LitVolume::new(empty, vec![Rgb::ZERO; 8], Grid3::filled([2, 2, 2], 1.0), sun, sky, None);
        let opts = CubeOptions::default();
        let mut exact = 0.0;
        map.for_each_subpixel(0..h, 2, &mut |_, l, d_omega| exact += l.x as f64 * d_omega);
        let total = |r: &CubeRenderer<'_>| -> f64 {
            let px = &r.pixels;
            let res = r.opts.res;
            let mut sum = 0.0;
            let image = crate::cube::CubeImage::new(res);
            for face in 0..6 {
                for j in 0..res {
                    for i in 0..res {
                        let k = image.index(face, i, j);
                        let l = r.trace(Vec3::splat(1.0), px.dirs[k], px.cone[j * res + i]);
                        sum += l.x as f64 * crate::cube::CubeImage::pixel_solid_angle(res, i, j);
                    }
                }
            }
            sum
        };
        let means = total(&border_renderer(&lit, &opts, LevelTables::new(&lit, &opts)));
        assert!((means / exact - 1.0).abs() < 5e-3, "{means} against {exact}");
        let axes = total(&CubeRenderer::new(&lit, &border_options(&opts)));
        assert!(axes < 0.5 * exact, "the axes miss it: {axes} against {exact}");
    }

    #[test]
    fn border_voxels_are_the_empty_ones_with_a_full_face_neighbour() {
        // A random sparse grid (voxels on every side of the box full too), against the definition
        // read voxel by voxel in memory order.
        let dims = [9, 7, 6];
        let mut g = Grid3::filled(dims, 0.0);
        let mut rng = crate::math::Rng::new(11, 5);
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    if rng.uniform() < 0.3 {
                        g.set(i, j, k, 0.5);
                    }
                }
            }
        }
        let mut want = Vec::new();
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let faces = FACE_OFFSETS.iter().enumerate().fold(0u8, |acc, (f, o)| {
                        let full = g.get_or_zero(i as isize + o[0], j as isize + o[1], k as isize + o[2]) > 0.0;
                        acc | (u8::from(full) << f)
                    });
                    if g.get(i, j, k) <= 0.0 && faces != 0 {
                        want.push(([i, j, k], faces));
                    }
                }
            }
        }
        assert!(want.len() > 50);
        assert_eq!(find_border_voxels(&Density::from_grid(&g)), want);
    }

    /// Two smooth lobes (peak 1) in a `dims` grid with a clear-air gap between them, lit with a
    /// constant I0, half sun transmittance and a grey sky.
    fn two_lobes(dims: [usize; 3], radius: f32) -> LitVolume {
        let g = crate::medium::test_grids::two_lobes(dims, radius);
        let n = g.len();
        let m = crate::medium::Medium::new(g, Vec3::ZERO, Vec3::ONE, 1.0, Rgb::splat(0.9), 0.8);
        let sun = Sun {
            dir: Vec3::new(0.2, 1.0, 0.1).normalize(),
            irradiance: Rgb::splat(2.0),
        };
        LitVolume::new(
            m,
            vec![Rgb::ONE; n],
            Grid3::filled(dims, 0.5),
            sun,
            Sky::constant(Rgb::splat(0.3)),
            None,
        )
    }

    /// Without the cut-off, a ray's pieces composited front to back are the whole ray: the near
    /// piece from the same point plus its transmittance times the rest (to rounding).
    #[test]
    fn ray_pieces_composite_to_the_whole_ray() {
        let v = two_lobes([24, 16, 16], 4.0);
        let opts = CubeOptions {
            res: 4,
            t_cutoff: 0.0,
            ..Default::default()
        };
        let r = CubeRenderer::new(&v, &opts);
        let mut rng = crate::math::Rng::new(5, 0);
        for _ in 0..300 {
            let o = Vec3::new(24.0 * rng.uniform(), 16.0 * rng.uniform(), 16.0 * rng.uniform());
            let d = Vec3::new(rng.uniform() - 0.5, rng.uniform() - 0.5, rng.uniform() - 0.5).normalize();
            let cone = 0.05 + 0.4 * rng.uniform();
            let whole = r.trace(o, d, cone);
            let s = piece_start(r.footprint_distance(cone), 1);
            let (l, tr) = r.trace_span(o, d, cone, 0.0, s);
            let split = l + r.trace_from(o, d, cone, s) * tr;
            let err = ((split - whole).abs() / whole.abs().max(Rgb::splat(1e-6))).max_element();
            assert!(err < 1e-4, "{o} {d} {cone}: {split} vs {whole}");
        }
    }

    /// Sharing the far pieces does not make the bins worse estimates of the bins' true means: against
    /// each voxel's own cube at 16 pixels per face edge (16 rays per bin), the shared one-ray
    /// bins err about as much as each voxel's own one-ray bins.
    #[test]
    fn shared_rays_estimate_the_bins_as_well_as_own_rays() {
        let v = two_lobes([24, 16, 16], 4.0);
        let opts = CubeOptions::default();
        let border = |res: usize| CubeOptions {
            step_level_voxels: opts.border_step_level_voxels,
            t_cutoff: opts.border_t_cutoff,
            res,
            ..opts.clone()
        };
        let r = CubeRenderer::new(&v, &border(opts.border_res));
        let fine = CubeRenderer::new(&v, &border(16));
        let shared = render_border_cubes_with(&r, &NoProgress);
        assert!(shared.len() > 100, "{} border voxels", shared.len());
        // Errors relative to each cube's brightest needed bin, so that dim bins do not dominate.
        let (mut e_shared, mut e_own) = (0f64, 0f64);
        for (n, v) in shared.voxels.iter().enumerate() {
            let p = r.lit.medium.voxel_center(v[0], v[1], v[2]);
            let own = r.bin_radiance(p, shared.needed[n]);
            let truth = fine.bin_radiance(p, shared.needed[n]);
            let scale = shared.needed[n].iter().map(|b| truth[b].max_element()).fold(1e-6, f32::max);
            for (b, l) in shared.needed[n]
                .iter()
                .zip(&shared.radiance[shared.offsets[n]..shared.offsets[n + 1]])
            {
                e_shared += ((*l - truth[b]).abs().max_element() / scale) as f64;
                e_own += ((own[b] - truth[b]).abs().max_element() / scale) as f64;
            }
        }
        assert!(e_shared < 1.1 * e_own, "shared {e_shared} against own {e_own}");
    }
}
