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
use crate::math::Rgb;
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

/// The rendered border cubes: per border voxel, the mean radiance in each needed bin.
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
    /// Mean radiance arriving from each bin's directions (W·m⁻²·sr⁻¹), 96 per voxel
    /// (voxel-major); zero for bins not rendered.
    pub radiance: Vec<Rgb>,
    /// Dense map voxel → position in `voxels` (u32::MAX for none).
    index: Vec<u32>,
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
        let d = self.dims;
        if voxel[0] >= d[0] || voxel[1] >= d[1] || voxel[2] >= d[2] {
            return None;
        }
        let n = self.index[voxel[0] + d[0] * (voxel[1] + d[1] * voxel[2])];
        (n != u32::MAX).then_some(n as usize)
    }

    /// The 96 bin radiances of cube `n` (zero where not rendered).
    #[inline]
    pub fn bins(&self, n: usize) -> &[Rgb] {
        &self.radiance[n * NUM_BINS..(n + 1) * NUM_BINS]
    }

    /// Mean radiance arriving at `voxel`'s centre from the directions of bin `bin` (looking
    /// towards them), if `voxel` is a border voxel and the bin was rendered.
    #[inline]
    pub fn lookup(&self, voxel: [usize; 3], bin: usize) -> Option<Rgb> {
        let n = self.find(voxel)?;
        self.needed[n].contains(bin).then(|| self.radiance[n * NUM_BINS + bin])
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

/// [`render_border_cubes`] with a renderer already built (pyramid and tables reused).
pub fn render_border_cubes_with(renderer: &CubeRenderer<'_>, progress: &dyn Progress) -> BorderCubes {
    let lit = renderer.lit;
    let dims = lit.dims();
    let found = find_border_voxels(&lit.medium.density);
    let mut index = vec![u32::MAX; dims[0] * dims[1] * dims[2]];
    for (n, (v, _)) in found.iter().enumerate() {
        index[v[0] + dims[0] * (v[1] + dims[1] * v[2])] = n as u32;
    }
    let needed: Vec<BinMask> = found.iter().map(|(_, f)| BinMask::for_faces(*f)).collect();
    progress.begin("border cubes", found.len() as u64);
    let mut radiance = vec![Rgb::ZERO; found.len() * NUM_BINS];
    const CHUNK: usize = 64;
    radiance.par_chunks_mut(NUM_BINS * CHUNK).enumerate().for_each(|(c, out)| {
        let lo = c * CHUNK;
        for (q, bins) in out.chunks_mut(NUM_BINS).enumerate() {
            let n = lo + q;
            let [i, j, k] = found[n].0;
            let p = lit.medium.voxel_center(i, j, k);
            bins.copy_from_slice(&renderer.bin_radiance(p, needed[n]));
        }
        progress.advance((out.len() / NUM_BINS) as u64);
    });
    progress.end();
    BorderCubes {
        dims,
        voxels: found.iter().map(|(v, _)| *v).collect(),
        faces: found.iter().map(|(_, f)| *f).collect(),
        needed,
        radiance,
        index,
    }
}
