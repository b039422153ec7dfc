//! Rendering the lit scene onto viewing cubes.
//!
//! Each cube pixel is a cone of angular width α = √(pixel solid angle). Its ray is marched front
//! to back through the [`LitPyramid`], at distance t on the level whose voxel edge is about the
//! cone's footprint α·t (level l from t = 2^l·h/α on, h the finest voxel edge), with steps of a
//! fixed fraction of that level's voxel, skipping empty blocks of the level's occupancy grid and
//! stopping once the transmittance drops below a cut-off. Each step of length Δ and density ρ adds
//! T·(1 − e^{−σt ρ Δ})·J (J from [`LitVolume::source`]) and multiplies T by e^{−σt ρ Δ}; what
//! is left is T × (lit ground or sky).
//!
//! Only the bins in a [`BinMask`] are rendered (the paper's half- and partial cubes); the other
//! pixels stay black and their bins are reported as absent.

use super::image::CubeImage;
use super::skip::DualMask;
use crate::diffusion::flux::{decode_band, encode_flux, CodedFlux, FluxField, CODED_ZERO};
use crate::error::{Error, Result};
use crate::lighting::bins::{cube_pixel, narrowest_pixel_edge, DirectionBins, BINS_PER_EDGE, NUM_BINS};
use crate::lit::pyramid::{Cell, LitPyramid, BLOCK};
use crate::lit::LitVolume;
use crate::math::{small_int, Rgb, Trilinear, Vec3};
use crate::medium::sparse::VoxelField;
use std::sync::Arc;
use std::sync::OnceLock;

/// Settings of the cube renderer.
#[derive(Clone, Debug, PartialEq)]
pub struct CubeOptions {
    /// Pixels per face edge (a multiple of 4, so pixels nest in the 4×4 bins of a face).
    pub res: usize,
    /// March step in voxels of the current pyramid level (a fraction of its smallest voxel edge).
    pub step_level_voxels: f32,
    /// The march step of the final gather's view-aligned cubes (the edge and surface layer's,
    /// `crate::render::full::GatherCubes`), likewise. Measured 1.5 against 1 on the default
    /// scene and the five evaluation scenes: block MRE ≤ 1.8·10⁻⁴, a third fewer samples in
    /// the gather's most expensive loop; 2 against 1.5: block MRE ≤ 1.2·10⁻⁴ (dense), the
    /// gather's cubes 11 % fewer instructions.
    pub gather_step_level_voxels: f32,
    /// The march step of the border cubes ([`super::border`]), likewise. Coarser than the other
    /// cubes': their light reaches the image only through stage 1 and the clear-air change of I0
    /// (1.4 % on the default scene); measured there, 2 against 1 moves the image by 7·10⁻⁶ (mean
    /// relative difference) and halves the samples in occupied blocks.
    pub border_step_level_voxels: f32,
    /// A ray stops when its transmittance falls below this (the dropped rest is at most this
    /// fraction of the brightest radiance behind).
    pub t_cutoff: f32,
    /// The cut-off of the border cubes, likewise coarser (1e-2 against 1e-3: the image within
    /// 8·10⁻⁷ mean relative difference over the cloud on the default scene).
    pub border_t_cutoff: f32,
    /// Level-of-detail bias in octaves: the footprint is taken as α·t·2^bias (0 = matched,
    /// negative = sharper and slower).
    pub lod_bias: f32,
    /// Pyramid levels used (1 = always the finest grid, no level of detail).
    pub max_levels: usize,
    /// Pixels per face edge of the clear-air border cubes ([`super::border`]; a multiple of 4):
    /// one pixel per bin by default. Their light enters the diffusion only as bin means (stage 1's
    /// hook) or as each face's cosine-weighted hemisphere (`render.sky_boundary`); measured 4
    /// against 8 on the default scene: 1.5·10⁻⁴ block MRE, the evaluation scenes within ±0.003,
    /// the clear-air stage 2.6× faster.
    pub border_res: usize,
    /// Ground sample grid edge (N×N hemicubes).
    pub ground_samples: usize,
    /// Pixels per face edge of the ground's hemicubes (a multiple of 4). Finer than the border
    /// cubes by default: the ground's shadow edges are sharp and there are few hemicubes.
    pub ground_res: usize,
}

/// Default pixels per face edge (see docs/cubes.md for the measurement behind it).
pub const DEFAULT_CUBE_RESOLUTION: usize = 8;
/// Default ground sample grid edge.
pub const DEFAULT_GROUND_SAMPLES: usize = 32;

impl Default for CubeOptions {
    fn default() -> Self {
        CubeOptions {
            res: DEFAULT_CUBE_RESOLUTION,
            step_level_voxels: 1.0,
            gather_step_level_voxels: 2.0,
            border_step_level_voxels: 2.0,
            t_cutoff: 1e-3,
            border_t_cutoff: 1e-2,
            lod_bias: 0.0,
            max_levels: 8,
            ground_samples: DEFAULT_GROUND_SAMPLES,
            ground_res: 16,
            border_res: 4,
        }
    }
}

impl CubeOptions {
    /// Check the options; `file` names the scene file for messages.
    pub fn validate(&self, file: &str) -> Result<()> {
        if self.res < 4 || self.res > 256 || self.res % BINS_PER_EDGE != 0 {
            return Err(Error::invalid(
                file,
                "render.cube_resolution",
                format!("{} is not allowed: use a multiple of 4 from 4 to 256 (default 8)", self.res),
            ));
        }
        if self.ground_res < 4 || self.ground_res > 256 || self.ground_res % BINS_PER_EDGE != 0 {
            return Err(Error::invalid(
                file,
                "ground hemicube resolution",
                format!("{} is not allowed: use a multiple of 4 from 4 to 256", self.ground_res),
            ));
        }
        if self.ground_samples < 2 || self.ground_samples > 1024 {
            return Err(Error::invalid(
                file,
                "render.ground_samples",
                format!(
                    "{} is not allowed: use 2 to 1024 samples per edge (default 32)",
                    self.ground_samples
                ),
            ));
        }
        for step in [self.step_level_voxels, self.gather_step_level_voxels, self.border_step_level_voxels] {
            if !(step.is_finite() && step > 0.0 && step <= 4.0) {
                return Err(Error::invalid(file, "cube step", format!("{step} is not in (0, 4]")));
            }
        }
        for cut in [self.t_cutoff, self.border_t_cutoff] {
            if !(cut.is_finite() && (0.0..1.0).contains(&cut)) {
                return Err(Error::invalid(file, "cube cut-off", format!("{cut} is not in [0, 1)")));
            }
        }
        if !self.lod_bias.is_finite() || self.max_levels == 0 {
            return Err(Error::invalid(file, "cube level of detail", "bias must be finite and levels ≥ 1"));
        }
        Ok(())
    }
}

/// A set of the 96 direction bins (bit b = bin b).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Hash)]
pub struct BinMask(pub u128);

fn bins() -> &'static DirectionBins {
    static B: OnceLock<DirectionBins> = OnceLock::new();
    B.get_or_init(DirectionBins::new)
}

/// The bin holding the directions opposite to bin `b`'s (the bin layout is point-symmetric, so
/// this is exact for every direction in the bin).
pub fn opposite_bin(b: usize) -> usize {
    static T: OnceLock<[usize; NUM_BINS]> = OnceLock::new();
    T.get_or_init(|| {
        let d = bins();
        let mut t = [0; NUM_BINS];
        for (i, bin) in d.bins.iter().enumerate() {
            t[i] = d.bin_of(-bin.center);
        }
        t
    })[b]
}

impl BinMask {
    /// Every bin.
    pub const ALL: BinMask = BinMask((1u128 << NUM_BINS) - 1);
    /// No bin.
    pub const NONE: BinMask = BinMask(0);

    /// Is bin `b` in the set?
    #[inline]
    pub fn contains(self, b: usize) -> bool {
        (self.0 >> b) & 1 == 1
    }

    /// Add bin `b`.
    #[inline]
    pub fn insert(&mut self, b: usize) {
        self.0 |= 1u128 << b;
    }

    /// Number of bins in the set.
    #[inline]
    pub fn count(self) -> u32 {
        self.0.count_ones()
    }

    /// Union.
    #[inline]
    pub fn union(self, o: BinMask) -> BinMask {
        BinMask(self.0 | o.0)
    }

    /// The bins in increasing order.
    pub fn iter(self) -> impl Iterator<Item = usize> {
        (0..NUM_BINS).filter(move |&b| self.contains(b))
    }

    /// Bins whose directions satisfy `pred` at their centre.
    pub fn from_centres(pred: impl Fn(Vec3) -> bool) -> BinMask {
        let mut m = BinMask::NONE;
        for (b, bin) in bins().bins.iter().enumerate() {
            if pred(bin.center) {
                m.insert(b);
            }
        }
        m
    }

    /// Bins looking away from the neighbour across face `face` (an index into
    /// [`crate::lighting::CUBE_FACES`]: +x, −x, +y, −y, +z, −z): directions ω with ω·n < 0. Bin
    /// edges lie on the planes ω·n = 0, so a bin is wholly on one side.
    pub fn looking_away_from(face: usize) -> BinMask {
        let n = crate::lighting::CUBE_FACES[face].n;
        BinMask::from_centres(|c| c.dot(n) < 0.0)
    }

    /// Union of [`Self::looking_away_from`] over the faces set in `faces` (bit f = face f).
    pub fn for_faces(faces: u8) -> BinMask {
        // Tabulated once for the 64 face sets (every border voxel asks).
        static T: OnceLock<[BinMask; 64]> = OnceLock::new();
        T.get_or_init(|| {
            std::array::from_fn(|set| {
                (0..6)
                    .filter(|f| set >> f & 1 == 1)
                    .fold(BinMask::NONE, |m, f| m.union(BinMask::looking_away_from(f)))
            })
        })[faces as usize & 63]
    }

    /// Bins of the upper hemisphere (ω·y > 0): a ground point's hemicube.
    pub fn upper_hemisphere() -> BinMask {
        BinMask::from_centres(|c| c.y > 0.0)
    }
}

/// Per-resolution pixel tables: directions, solid angles, cone widths.
#[derive(Clone, Debug)]
pub struct PixelTable {
    /// Pixels per face edge.
    pub res: usize,
    /// Unit direction per pixel, index as [`CubeImage::index`].
    pub dirs: Vec<Vec3>,
    /// Exact solid angle per face pixel, index j·res + i (sr).
    pub solid_angle: Vec<f64>,
    /// Cone width √(solid angle) per face pixel (rad).
    pub cone: Vec<f32>,
}

impl PixelTable {
    /// Tables for `res`.
    pub fn new(res: usize) -> PixelTable {
        let mut dirs = Vec::with_capacity(6 * res * res);
        for face in 0..6 {
            for j in 0..res {
                for i in 0..res {
                    dirs.push(CubeImage::local_direction(res, face, i, j));
                }
            }
        }
        let solid_angle = CubeImage::face_solid_angles(res);
        let cone = solid_angle.iter().map(|s| s.sqrt() as f32).collect();
        PixelTable {
            res,
            dirs,
            solid_angle,
            cone,
        }
    }

    /// Face pixels (i, j) of bin `b`.
    pub fn bin_pixels(&self, b: usize) -> impl Iterator<Item = (usize, usize, usize)> + use<> {
        let per = self.res / BINS_PER_EDGE;
        let face = b / (BINS_PER_EDGE * BINS_PER_EDGE);
        let bv = (b / BINS_PER_EDGE) % BINS_PER_EDGE;
        let bu = b % BINS_PER_EDGE;
        (bv * per..(bv + 1) * per).flat_map(move |j| (bu * per..(bu + 1) * per).map(move |i| (face, i, j)))
    }
}

/// Renders cubes of one lit volume; build once, use from many threads.
#[derive(Clone, Debug)]
pub struct CubeRenderer<'a> {
    /// The scene.
    pub lit: &'a LitVolume,
    /// Its mip pyramid (shared with every renderer of the same lit volume).
    pub pyramid: Arc<LitPyramid>,
    /// Levels used: the first `opts.max_levels` of the pyramid.
    levels: usize,
    /// The empty dual cells of each level used.
    masks: Arc<Vec<DualMask>>,
    /// Per level used, the world box (m) of its occupied blocks (None: none occupied); a ray
    /// walks a level's blocks only inside it, and misses every level outside their union.
    occupied: Arc<Vec<Option<(Vec3, Vec3)>>>,
    occupied_union: Option<(Vec3, Vec3)>,
    /// Per level used, its march constants, computed once instead of per ray and level.
    walk: Arc<Vec<LevelWalk>>,
    /// The options.
    pub opts: CubeOptions,
    /// Pixel tables at `opts.res`.
    pub pixels: PixelTable,
    h_min: f32,
    /// Add the gather's own diffuse terms beyond I0 (g·I1·ω and the sky's single scattering,
    /// [`LitVolume::diffuse`]) to the source, so a cube sees the cloud as the final gather does
    /// (the edge and surface cubes); false: I0 only, the paper's cubes. Evaluated on the fine
    /// grid at level 0; at coarser levels from the level's own ρ·I0 and ρ·I1 (mass-weighted
    /// means like the level's other cells, [`CoarseFlux`]) when only the first moment is attached,
    /// else a point sample of the fine grid (measured: the furnace −14.2 → −12.5 % against the
    /// finest level only).
    pub gather_source: bool,
    /// March a coarse level (≥ 1) whose stretch of the ray spans at most two occupancy blocks
    /// in uniform steps over the whole stretch instead of block by block (the border cubes,
    /// whose one-pixel bins' cones stay on each level for ~3 level voxels); false: the block walk.
    pub uniform_short_levels: bool,
    /// ρ·I1 of levels 1.. of the pyramid, built on first use by a gather-source march.
    coarse_flux: Arc<OnceLock<Option<CoarseFlux>>>,
    /// Per pixel of the cube at `opts.res`, the sky's mean radiance over it (W·m⁻²·sr⁻¹), taken
    /// behind a ray that leaves the scene instead of the sky on the ray ([`Self::with_sky_means`]);
    /// None: the sky on the ray.
    sky_means: Option<Arc<Vec<Rgb>>>,
    /// The sun's single scattering in the cube with the transformed medium's own albedo and phase
    /// (a′, HG(g′)) instead of the exact TMS pair: right where the cube's light is scattered again
    /// (the edge and surface orders), whose forward peak the δ-M transmittance already carries.
    pub sun_transformed: bool,
}

/// A renderer's per-level tables (the pyramid's levels used, their empty-cell masks, occupied
/// boxes and march constants). They depend on the lit volume's pyramid and `max_levels` only, so
/// renderers over lit volumes that share one pyramid (the clear-air stage's ground hemicubes and
/// border cubes: adding the lit ground keeps it) build them once.
#[derive(Clone)]
pub struct LevelTables {
    pyramid: Arc<LitPyramid>,
    levels: usize,
    masks: Arc<Vec<DualMask>>,
    occupied: Arc<Vec<Option<(Vec3, Vec3)>>>,
    occupied_union: Option<(Vec3, Vec3)>,
    walk: Arc<Vec<LevelWalk>>,
    max_levels: usize,
}

impl LevelTables {
    /// The tables of `lit`'s pyramid for `opts.max_levels`.
    pub fn new(lit: &LitVolume, opts: &CubeOptions) -> LevelTables {
        let pyramid = lit.pyramid();
        let levels = opts.max_levels.max(1).min(pyramid.levels.len());
        let masks = Arc::new(pyramid.levels[..levels].iter().map(DualMask::new).collect());
        // Cut at the coarsest level's box, which contains every level's cells.
        let top = pyramid.levels[levels - 1].voxel_size * dims_f(pyramid.levels[levels - 1].dims);
        let occupied: Vec<Option<(Vec3, Vec3)>> = pyramid.levels[..levels]
            .iter()
            .map(|lev| occupied_box(lev).map(|(lo, hi)| (pyramid.origin + lo, pyramid.origin + hi.min(top))))
            .collect();
        let occupied_union = occupied.iter().flatten().copied().reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)));
        let occupied = Arc::new(occupied);
        let h_min = lit.medium.min_voxel();
        let walk = Arc::new(
            pyramid.levels[..levels]
                .iter()
                .enumerate()
                .map(|(li, lev)| LevelWalk::new(lev, li, h_min))
                .collect(),
        );
        LevelTables {
            pyramid,
            levels,
            masks,
            occupied,
            occupied_union,
            walk,
            max_levels: opts.max_levels,
        }
    }
}

impl<'a> CubeRenderer<'a> {
    /// Build the pyramid and tables.
    pub fn new(lit: &'a LitVolume, opts: &CubeOptions) -> CubeRenderer<'a> {
        Self::with_tables(lit, opts, LevelTables::new(lit, opts))
    }

    /// A renderer with `tables` made for `lit`'s pyramid (or a lit volume sharing it); made anew
    /// when they were made for another pyramid or `max_levels`.
    pub fn with_tables(lit: &'a LitVolume, opts: &CubeOptions, tables: LevelTables) -> CubeRenderer<'a> {
        let tables = if Arc::ptr_eq(&tables.pyramid, &lit.pyramid()) && tables.max_levels == opts.max_levels {
            tables
        } else {
            LevelTables::new(lit, opts)
        };
        CubeRenderer {
            lit,
            pyramid: tables.pyramid,
            levels: tables.levels,
            masks: tables.masks,
            occupied: tables.occupied,
            occupied_union: tables.occupied_union,
            walk: tables.walk,
            opts: opts.clone(),
            pixels: PixelTable::new(opts.res),
            h_min: lit.medium.min_voxel(),
            gather_source: false,
            sun_transformed: false,
            uniform_short_levels: false,
            coarse_flux: Arc::default(),
            sky_means: None,
        }
    }

    /// The coarse levels' ρ·I1 when the gather source is I0 and the first moment only.
    fn coarse_flux(&self) -> Option<&CoarseFlux> {
        self.coarse_flux
            .get_or_init(|| match (&self.lit.flux, &self.lit.sky_single) {
                (Some(f), None) => Some(CoarseFlux::build(&self.pyramid.levels[..self.levels], f)),
                _ => None,
            })
            .as_ref()
    }

    /// Pyramid levels used.
    pub fn levels(&self) -> usize {
        self.levels.min(self.pyramid.levels.len())
    }

    /// Radiance (W·m⁻²·sr⁻¹) arriving at `o` from direction `d` (unit), for a cone of angular
    /// width `cone` (rad).
    pub fn trace(&self, o: Vec3, d: Vec3, cone: f32) -> Rgb {
        let t_ground = self.lit.ground_hit(o, d);
        let (l, tr) = self.march(o, d, cone, t_ground, 0.0..f32::INFINITY);
        self.finish(o, d, t_ground, l, tr)
    }

    /// [`Self::trace`] with `sky` (W·m⁻²·sr⁻¹) behind the ray where it leaves the scene instead
    /// of the sky on its axis: the caller's mean of the sky over the cone's pixel.
    pub fn trace_to_sky(&self, o: Vec3, d: Vec3, cone: f32, sky: Rgb) -> Rgb {
        let t_ground = self.lit.ground_hit(o, d);
        let (mut l, tr) = self.march(o, d, cone, t_ground, 0.0..f32::INFINITY);
        if tr > 0.0 {
            let behind = if t_ground.is_some() { self.lit.background(o, d, t_ground) } else { sky };
            l += behind * tr;
        }
        l
    }

    /// Distance (m) at which a cone of width `cone` is one finest voxel wide: where
    /// [`Self::trace`] leaves the finest level for the next it is twice that.
    pub fn footprint_distance(&self, cone: f32) -> f32 {
        self.h_min / (cone.max(1e-6) * self.lod_scale())
    }

    /// 2^`lod_bias`: 1 exactly at the default bias, without a libm call per ray.
    #[inline]
    fn lod_scale(&self) -> f32 {
        if self.opts.lod_bias == 0.0 {
            1.0
        } else {
            self.opts.lod_bias.exp2()
        }
    }

    /// Radiance gathered and transmittance left along `o + t·d` (cone width `cone`) for
    /// t ∈ [t0, t1) only (each level where [`Self::trace`] marches it): a piece of the ray, whose
    /// far pieces nearby points can share (the border cubes).
    pub fn trace_span(&self, o: Vec3, d: Vec3, cone: f32, t0: f32, t1: f32) -> (Rgb, f32) {
        self.march(o, d, cone, self.lit.ground_hit(o, d), t0..t1)
    }

    /// The last piece of a ray for [`Self::trace_span`]: t ≥ `t0`, with what lies behind.
    pub fn trace_from(&self, o: Vec3, d: Vec3, cone: f32, t0: f32) -> Rgb {
        let t_ground = self.lit.ground_hit(o, d);
        let (l, tr) = self.march(o, d, cone, t_ground, t0..f32::INFINITY);
        self.finish(o, d, t_ground, l, tr)
    }

    /// `l` plus the background behind, seen with transmittance `tr`: the lit ground, or the sky
    /// (its mean over the ray's pixel with [`Self::with_sky_means`]).
    #[inline]
    fn finish(&self, o: Vec3, d: Vec3, t_ground: Option<f32>, l: Rgb, tr: f32) -> Rgb {
        let mut l = l;
        if tr > 0.0 {
            let behind = match (t_ground, &self.sky_means) {
                (None, Some(means)) => means[cube_pixel(self.opts.res, d)],
                _ => self.lit.background(o, d, t_ground),
            };
            l += behind * tr;
        }
        l
    }

    /// `self` seeing, behind each ray that leaves the scene, a map sky's mean radiance over the
    /// cube pixel the ray lies in ([`EnvMap::cell_means`](crate::lighting::envmap::EnvMap::cell_means))
    /// rather than the sky on the ray: for renderers that trace one ray per pixel of their cube
    /// along its axis (the border cubes), so a pixel holding a sun one map pixel wide carries its
    /// power. A constant sky is its own mean and is left on the ray.
    pub fn with_sky_means(mut self) -> Self {
        if let Some(map) = self.lit.sky.map() {
            let res = self.opts.res;
            let means = map.cell_means(6 * res * res, narrowest_pixel_edge(res), &|d| cube_pixel(res, d), None);
            self.sky_means = Some(Arc::new(means));
        }
        self
    }

    /// Radiance gathered and transmittance left along `o + t·d` through the pyramid (each level
    /// at the distances where the cone's footprint matches it), for t in `span` only, stopping
    /// at the ground (`t_ground`); transmittance 0 once cut off.
    #[inline]
    fn march(&self, o: Vec3, d: Vec3, cone: f32, t_ground: Option<f32>, span: std::ops::Range<f32>) -> (Rgb, f32) {
        let lit = self.lit;
        let m = &lit.medium;
        let t_end = t_ground.unwrap_or(f32::INFINITY);
        // Sunlight travels along −sun.dir; the scattered light travels towards the eye, −d.
        // The sun's exact single scattering per unit extinction (albedo included; TMS under δ-M).
        // Under δ-M the TMS pair is split (`Optics::sun_scatter_split`): the truncated peak's
        // part counts only where no peak scattering follows on the way to the cube's centre,
        // weighted by T′^k (T′ the δ-M transmittance marched from the centre), as in the final
        // gather; the whole pair would count a path of several peak scatterings once per
        // scattering (the aureole 2–3× too bright, docs/full.md).
        let (sun_e, sun_peak, peak_k) = if self.sun_transformed {
            (lit.sun.irradiance * m.optics.albedo * m.optics.phase.eval(lit.sun.dir, -d), Rgb::ZERO, 0.0)
        } else {
            let (smooth, peak, k) = m.optics.sun_scatter_split(lit.sun.dir, -d);
            (lit.sun.irradiance * smooth, lit.sun.irradiance * peak, k)
        };
        let albedo = m.optics.albedo;
        let sigma_t = m.optics.sigma_t;
        let cut = self.opts.t_cutoff;
        // Without the first moment or the sky's single scattering the gather adds nothing to I0.
        let gather = self.gather_source && (lit.flux.is_some() || lit.sky_single.is_some());
        let coarse = if gather { self.coarse_flux() } else { None };
        // Level 0's cells share the flux's index: its slots serve ρ·I1 too.
        let flux0 = lit
            .flux
            .as_deref()
            .filter(|f| Arc::ptr_eq(f.rho_i1().index(), self.pyramid.levels[0].cells.index()));
        let inv_cone = 1.0 / (cone.max(1e-6) * self.lod_scale());
        let levels = &self.pyramid.levels[..self.levels.min(self.pyramid.levels.len())];
        let nlev = levels.len();
        let masks = &self.masks[..nlev];
        let walk = &self.walk[..nlev];
        let origin = self.pyramid.origin;
        // Components of d below 1e-20 are nudged so the slab and block arithmetic stay finite.
        let dn = Vec3::select(d.abs().cmplt(Vec3::splat(1e-20)), Vec3::splat(1e-20), d);
        let inv_d = Vec3::ONE / dn;
        let positive = d.cmpgt(Vec3::ZERO);
        let slab = |lo: Vec3, hi: Vec3| {
            let (ta, tb) = ((lo - o) * inv_d, (hi - o) * inv_d);
            (ta.min(tb).max_element().max(0.0), ta.max(tb).min_element().min(t_end))
        };
        // Only the occupied blocks hold density: the union of the levels' occupied boxes bounds it.
        let (t_box0, t_box1) = match self.occupied_union {
            Some((lo, hi)) => slab(lo, hi),
            None => (0.0, 0.0),
        };
        let mut tr = 1.0f32;
        let mut l = Rgb::ZERO;
        if t_box0 < t_box1 {
            'levels: for (li, lev) in levels.iter().enumerate() {
                let lw = &walk[li];
                let ts = if li == 0 { 0.0 } else { lw.reach * inv_cone };
                // Levels lie in order of distance: none after one starting beyond the ray's end.
                if ts >= t_box1.min(span.end) {
                    break;
                }
                let te = if li + 1 == nlev {
                    f32::INFINITY
                } else {
                    walk[li + 1].reach * inv_cone
                };
                if te <= span.start {
                    continue;
                }
                let Some((lo, hi)) = self.occupied[li] else {
                    continue;
                };
                let (oa, ob) = slab(lo, hi);
                let (ta, tb) = (ts.max(oa).max(span.start), te.min(ob).min(span.end));
                if ta >= tb {
                    continue;
                }
                let step = self.opts.step_level_voxels * lw.voxel_min;
                let (inv_vs, cell, inv_cell, nudge) = (lw.inv_voxel, lw.cell, lw.inv_cell, lw.nudge);
                let bd = lev.occupancy.dims;
                // A coarse level's span of at most two blocks in one go (the dual-cell bits still
                // skip empty samples): no block walk, and no extra samples where blocks cut it
                // short. Level 0 keeps the walk: there those extra samples near the cube's centre
                // matter (uniform there, the border bins err 13 % more than own rays against 16
                // rays per bin, unit test in border.rs; 4 % with level 0 walked).
                let whole = self.uniform_short_levels && li > 0 && tb - ta <= lw.two_cells;
                // Walk the occupancy blocks (f32 Amanatides–Woo, each block located afresh).
                let mut t = ta;
                while t < tb {
                    let (t_exit, occupied) = if whole {
                        (tb, true)
                    } else {
                        let f = ((o + d * (t + nudge)) - origin) * inv_cell;
                        let bi = f.floor();
                        let next = origin + (bi + Vec3::select(positive, Vec3::ONE, Vec3::ZERO)) * cell;
                        let t_exit = ((next - o) * inv_d).min_element().min(tb).max(t + nudge);
                        // Block indices as integers once; a negative one wraps above the bound.
                        // Within a nudge of the level's occupied box they are far below 2²².
                        let (bx, by, bz) = (
                            small_int(bi.x) as u32 as usize,
                            small_int(bi.y) as u32 as usize,
                            small_int(bi.z) as u32 as usize,
                        );
                        let inside = bx < bd[0] && by < bd[1] && bz < bd[2];
                        (t_exit, inside && lev.occupancy.max_density[bx + bd[0] * (by + bd[1] * bz)] > 0.0)
                    };
                    if occupied {
                        let n = ((t_exit - t) / step).ceil().max(1.0);
                        let len = (t_exit - t) / n;
                        for k in 0..n as u32 {
                            let ts = t + (k as f32 + 0.5) * len;
                            let v = ((o + d * ts) - origin) * inv_vs;
                            // Outside the level's box or in an empty dual cell ρ = 0: no blend there.
                            let Some((c, slots)) = masks[li].sample_slots(lev, v) else {
                                continue;
                            };
                            let rho = c[0];
                            let e = (-sigma_t * rho * len).exp();
                            // T(1 − e)·J with J = (a ρI0 + a p E_sun ρT_sun)/ρ from the pre-multiplied cell.
                            let w = tr * (1.0 - e) / rho;
                            let sun = if peak_k > 0.0 { sun_e + sun_peak * tr.powf(peak_k) } else { sun_e };
                            let mut src = albedo * Rgb::new(c[1], c[2], c[3]) + sun * c[4];
                            if gather {
                                // The fine field at the sample (at coarser levels a point sample
                                // of it, scaled by the level's ρ like its I0).
                                let beyond = if li == 0 {
                                    // Level 0's cell is the fine field's ρ·I0: I0 without a second lookup.
                                    let i0 = Rgb::new(c[1], c[2], c[3]) / rho;
                                    match flux0 {
                                        Some(f) if lit.sky_single.is_none() => {
                                            (i0 + f.anisotropic_at_slots(&slots, rho, -d)).max(Rgb::ZERO) - i0
                                        }
                                        _ => beyond_i0(lit, v, rho, i0, -d),
                                    }
                                } else if let Some(cf) = coarse {
                                    // The level's own means: no fine look-ups far from the cube.
                                    cf.beyond_i0(li, &slots, &c, -d)
                                } else {
                                    let v0 = m.to_voxel(o + d * ts);
                                    let r0 = m.density.trilinear(v0.to_array());
                                    if r0 > 0.0 {
                                        beyond_i0(lit, v0, r0, lit.i0(v0, r0), -d)
                                    } else {
                                        Rgb::ZERO
                                    }
                                };
                                src += albedo * beyond * rho;
                            }
                            l += src * w;
                            tr *= e;
                            if tr < cut {
                                tr = 0.0;
                                break 'levels;
                            }
                        }
                    }
                    t = t_exit;
                }
            }
        }
        (l, tr)
    }

    /// Render the bins in `needed` of a world-aligned cube at `p` (m); other pixels stay black.
    pub fn render_cube(&self, p: Vec3, needed: BinMask) -> CubeImage {
        let res = self.opts.res;
        let mut cube = CubeImage::new(res);
        for b in needed.iter() {
            for (face, i, j) in self.pixels.bin_pixels(b) {
                let k = cube.index(face, i, j);
                cube.pixels[k] = self.trace(p, self.pixels.dirs[k], self.pixels.cone[j * res + i]);
            }
        }
        cube
    }

    /// Mean radiance (solid-angle weighted, W·m⁻²·sr⁻¹) of each bin in `needed` seen from `p`;
    /// bins not in `needed` are zero. Same numbers as `render_cube(p, needed).bin_averages()`
    /// without storing the image.
    pub fn bin_radiance(&self, p: Vec3, needed: BinMask) -> [Rgb; NUM_BINS] {
        let mut out = [Rgb::ZERO; NUM_BINS];
        for b in needed.iter() {
            out[b] = self.bin_mean(b, |k, cone| self.trace(p, self.pixels.dirs[k], cone));
        }
        out
    }

    /// Solid-angle weighted mean over bin `b`'s pixels of `radiance(pixel index, cone width)`.
    pub fn bin_mean(&self, b: usize, radiance: impl Fn(usize, f32) -> Rgb) -> Rgb {
        let res = self.opts.res;
        if res == BINS_PER_EDGE {
            // One pixel per bin (the border cubes): its radiance is the mean, and the f64 sums
            // below would give back the same f32.
            let (face, i, j) = (
                b / (BINS_PER_EDGE * BINS_PER_EDGE),
                b % BINS_PER_EDGE,
                (b / BINS_PER_EDGE) % BINS_PER_EDGE,
            );
            return radiance((face * res + j) * res + i, self.pixels.cone[j * res + i]);
        }
        let mut acc = [0f64; 3];
        let mut area = 0f64;
        for (face, i, j) in self.pixels.bin_pixels(b) {
            let k = (face * res + j) * res + i;
            let sa = self.pixels.solid_angle[j * res + i];
            let l = radiance(k, self.pixels.cone[j * res + i]);
            acc[0] += l.x as f64 * sa;
            acc[1] += l.y as f64 * sa;
            acc[2] += l.z as f64 * sa;
            area += sa;
        }
        Rgb::new((acc[0] / area) as f32, (acc[1] / area) as f32, (acc[2] / area) as f32)
    }
}

/// One level's constants for [`CubeRenderer::march`] (the same expressions it evaluated per ray
/// and level before, so the same bits).
#[derive(Clone, Debug)]
struct LevelWalk {
    /// h_min·2^level (m): the level begins where the cone is this wide, at reach / cone.
    reach: f32,
    /// The smallest voxel edge (m).
    voxel_min: f32,
    /// 1 / voxel edge (m⁻¹).
    inv_voxel: Vec3,
    /// The occupancy block's edges (m) and their inverses.
    cell: Vec3,
    inv_cell: Vec3,
    /// Step past a block face (m): 10⁻³ of the smallest block edge.
    nudge: f32,
    /// Twice the smallest block edge (m): the longest stretch marched in one go.
    two_cells: f32,
}

impl LevelWalk {
    fn new(lev: &crate::lit::pyramid::Level, li: usize, h_min: f32) -> LevelWalk {
        let cell = lev.voxel_size * BLOCK as f32;
        LevelWalk {
            reach: h_min * (1u32 << li) as f32,
            voxel_min: lev.voxel_size.min_element(),
            inv_voxel: Vec3::ONE / lev.voxel_size,
            cell,
            inv_cell: Vec3::ONE / cell,
            nudge: 1e-3 * cell.min_element(),
            two_cells: 2.0 * cell.min_element(),
        }
    }
}

/// What [`LitVolume::diffuse`] adds to I0 (the first moment's max(0, I0 + g·I1·ω) − I0 and the
/// sky's single scattering) at voxel coordinates `v` (density `rho` > 0) given I0 there (`i0` =
/// [`LitVolume::i0`]`(v, rho)`), so I0 is looked up once, not twice; the same operations in the
/// same order as its per-voxel path, so the same bits.
#[inline]
fn beyond_i0(lit: &LitVolume, v: Vec3, rho: f32, i0: Rgb, to_eye: Vec3) -> Rgb {
    let d = match &lit.flux {
        Some(f) => (i0 + f.anisotropic_at_voxel(v, rho, to_eye)).max(Rgb::ZERO),
        None => i0,
    };
    let d = match &lit.sky_single {
        Some(s) => d + s.at_voxel(v, rho, to_eye),
        None => d,
    };
    d - i0
}

/// ρ·I1 (`[band]`) on pyramid levels 1.. (each on its level's index), averaged 2×2×2 like the
/// levels' cells (cells beyond the grid empty), so a coarse sample's first moment is the
/// mass-weighted mean of the fine one's, as its I0 is.
#[derive(Debug)]
struct CoarseFlux {
    /// ρ·I1 per level 1.. in bf16, as level 0's ([`FluxField::rho_i1`]).
    levels: Vec<VoxelField<CodedFlux>>,
    g: f32,
}

impl CoarseFlux {
    fn build(levels: &[crate::lit::pyramid::Level], flux: &FluxField) -> CoarseFlux {
        let mut out: Vec<VoxelField<CodedFlux>> = Vec::with_capacity(levels.len().saturating_sub(1));
        for w in levels.windows(2) {
            let parent = out.last().unwrap_or(flux.rho_i1());
            let (d, nd) = (w[0].dims, w[1].dims);
            let next = VoxelField::from_fn(w[1].cells.index().clone(), CODED_ZERO, |n| {
                let (i, j, k) = (n % nd[0], (n / nd[0]) % nd[1], n / (nd[0] * nd[1]));
                let mut s = [Vec3::ZERO; 3];
                for q in crate::lit::pyramid::children(d, [i, j, k]) {
                    let c = &parent[q];
                    for b in 0..3 {
                        s[b] += decode_band(&c[b]);
                    }
                }
                encode_flux(s.map(|x| x * 0.125))
            });
            out.push(next);
        }
        CoarseFlux { levels: out, g: flux.g() }
    }

    /// [`beyond_i0`] from level `li`'s (≥ 1) own cell `c` (ρ, ρ·I0, …) and ρ·I1 blended at
    /// `slots`: max(0, I0 + g·I1·ω) − I0 per band.
    #[inline]
    fn beyond_i0(&self, li: usize, slots: &Trilinear, c: &Cell, to_eye: Vec3) -> Rgb {
        let f = &self.levels[li - 1];
        let s: [Vec3; 3] = std::array::from_fn(|b| slots.blend(|q| decode_band(&f.at_slot(q)[b])));
        let inv = 1.0 / c[0];
        let i0 = Rgb::new(c[1], c[2], c[3]) * inv;
        let aniso = Rgb::new(s[0].dot(to_eye), s[1].dot(to_eye), s[2].dot(to_eye)) * (self.g * inv);
        (i0 + aniso).max(Rgb::ZERO) - i0
    }
}

/// The box (m, from the pyramid's origin) of `lev`'s occupied blocks (ρ bound > 0), None when
/// none is.
fn occupied_box(lev: &crate::lit::pyramid::Level) -> Option<(Vec3, Vec3)> {
    let occ = &lev.occupancy;
    let d = occ.dims;
    let (mut lo, mut hi) = ([usize::MAX; 3], [0usize; 3]);
    for k in 0..d[2] {
        for j in 0..d[1] {
            for i in 0..d[0] {
                if occ.get([i, j, k]) > 0.0 {
                    for (a, x) in [i, j, k].into_iter().enumerate() {
                        lo[a] = lo[a].min(x);
                        hi[a] = hi[a].max(x + 1);
                    }
                }
            }
        }
    }
    if lo[0] == usize::MAX {
        return None;
    }
    let cell = lev.voxel_size * BLOCK as f32;
    Some((cell * dims_f(lo), cell * dims_f(hi)))
}

#[inline]
fn dims_f(d: [usize; 3]) -> Vec3 {
    Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32)
}

/// Brute-force reference: each pixel centre's ray marched on the exact trilinear fields (density
/// of the medium, I0 (density-weighted) and T_sun, no pyramid) with steps of `step_voxels`
/// voxels, cut off only at transmittance 1e-6. Bins outside `needed` stay black.
pub fn render_cube_brute(lit: &LitVolume, p: Vec3, res: usize, needed: BinMask, step_voxels: f32) -> CubeImage {
    let table = PixelTable::new(res);
    let mut cube = CubeImage::new(res);
    let m = &lit.medium;
    let step = step_voxels * m.min_voxel();
    for b in needed.iter() {
        for (face, i, j) in table.bin_pixels(b) {
            let k = cube.index(face, i, j);
            let d = table.dirs[k];
            let tg = lit.ground_hit(p, d);
            let r = crate::medium::march::march(m, p, d, 0.0, tg.unwrap_or(f32::INFINITY), step, 0.5, |v, rho| {
                lit.source(v, rho, -d)
            });
            cube.pixels[k] = r.radiance + lit.background(p, d, tg) * r.transmittance;
        }
    }
    cube
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::{Sky, Sun};
    use crate::medium::{Grid3, Medium};

    /// With I0 and I1 uniform over the cloud, every level's mass-weighted means are those same
    /// values, so the coarse levels' g·I1·ω term must equal the exact one at any sample.
    #[test]
    fn coarse_flux_of_a_uniform_field_is_exact() {
        let dims = [13, 9, 11];
        let mut g = Grid3::filled(dims, 0.0);
        for (n, x) in g.data_mut().iter_mut().enumerate() {
            *x = ((n * 7) % 5) as f32 * 0.3;
        }
        let m = Medium::new(g, Vec3::ZERO, Vec3::ONE, 1.0, Rgb::ONE, 0.6);
        let i0 = Rgb::new(0.2, 1.0, 2.0);
        let i1 = [Vec3::new(3.0, -1.0, 0.5), Vec3::new(-0.4, 0.2, 1.0), Vec3::new(0.0, 0.0, -2.5)];
        let n = dims[0] * dims[1] * dims[2];
        let field = VoxelField::from_fn(m.density.full_index(), [Vec3::ZERO; 3], |_| i1);
        let flux = FluxField::new(&m, |g| field[g]);
        let sun = Sun {
            dir: Vec3::Y,
            irradiance: Rgb::ONE,
        };
        let lit = LitVolume::new(m, vec![i0; n], Grid3::filled(dims, 0.5), sun, Sky::constant(Rgb::ONE), None).with_flux(flux);
        let r = CubeRenderer::new(&lit, &CubeOptions::default());
        let cf = r.coarse_flux().expect("the first moment alone is attached");
        let g = lit.flux.as_ref().unwrap().g();
        let to_eye = Vec3::new(0.48, -0.6, 0.64);
        let exact = (i0 + Rgb::new(i1[0].dot(to_eye), i1[1].dot(to_eye), i1[2].dot(to_eye)) * g).max(Rgb::ZERO) - i0;
        // ρ·I1 is rounded to bf16 at level 0 and again at each coarse level (≤ 2⁻⁸ of each
        // component per rounding, the level's mean of the level below's): ≤ 2⁻⁷·g·Σ|I1_a| per band
        // (|ω_a| ≤ 1), where a wrong mean would be off by the order of I1 itself.
        let l1 = |v: Vec3| v.abs().element_sum();
        let tol = Rgb::new(l1(i1[0]), l1(i1[1]), l1(i1[2])) * (g / 128.0);
        let mut checked = 0;
        for li in 1..r.levels() {
            let lev = &r.pyramid.levels[li];
            for k in 0..40 {
                let v = Vec3::new(0.37 + 0.13 * k as f32, 0.61 + 0.07 * k as f32, 0.29 + 0.11 * k as f32) % dims_f(lev.dims);
                let Some((c, slots)) = r.masks[li].sample_slots(lev, v) else {
                    continue;
                };
                let got = cf.beyond_i0(li, &slots, &c, to_eye);
                assert!(
                    (0..3).all(|b| (got[b] - exact[b]).abs() <= tol[b]),
                    "level {li}: {got} vs {exact} (±{tol})"
                );
                checked += 1;
            }
        }
        assert!(checked > 10, "{checked} samples");
    }
}
