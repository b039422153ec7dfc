//! The participating medium: the density field ρ(X), its optical properties, and exact ray queries.
//!
//! **The density field.** Voxel (i, j, k) holds ρ at its centre; between centres ρ is trilinear,
//! clamped to the edge values inside the grid's box and zero outside it (Mitsuba 3's `gridvolume`
//! with trilinear filtering and clamp wrap mode, so an exported scene is the same medium). Every
//! method and the reference tracer see this one field; the diffusion stages use its voxel values.
//!
//! Along a ray inside one *dual* cell (between adjacent voxel centres) the trilinear field is a
//! cubic polynomial in the distance, so Simpson's rule integrates it exactly: [`Medium::optical_depth`]
//! is exact up to floating-point rounding.

pub mod dda;
pub mod density;
pub mod field16;
pub mod grid;
pub mod loaders;
pub mod majorant;
pub mod march;
pub mod npy_dtype;
pub mod procedural;
pub mod remap;
pub mod skin;
pub mod sparse;
pub mod subgrid;
#[cfg(test)]
pub(crate) mod test_grids;
pub mod up_axis;
pub mod vdb;
pub mod voxel_size;

use crate::error::{check, finite3, rgb_in_unit};
use crate::error::{Error, Result};
use crate::math::{Rgb, Vec3};
use crate::optics::Optics;
use glam::DVec3;
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::sync::{Arc, OnceLock};

pub use dda::{ray_box, Dda};
pub use density::Density;
pub use grid::Grid3;
pub use majorant::MajorantGrid;
pub use subgrid::SubGrid;
pub use up_axis::UpAxis;
pub use voxel_size::VoxelSize;

/// Largest voxel edge accepted (m): beyond about 1e15 m the diffusion solve's squared voxel
/// sizes overflow f32; no cloud has voxels of 1000 km.
pub const MAX_VOXEL_SIZE: f32 = 1.0e6;

/// Smallest voxel edge accepted, as a fraction of the grid's farthest coordinate: 2⁻²⁰, so an
/// f32 position resolves at least 8 steps across a voxel (at the 1e7-m limit, voxels of 9.5 m);
/// smaller voxels collapse the box and the camera framing it.
const MIN_VOXEL_OF_COORDINATE: f32 = 1.0 / (1 << 20) as f32;

/// Largest |g| of the Henyey–Greenstein phase function accepted. Measured against `reference` on
/// the built-in cumulus (docs/accuracy.md, "Extreme phase functions"): `transport` within 0.5 %
/// bias up to g = 0.9995, +2.6 % at 0.9997, +19 % at 0.9998 and +139 % at 0.9999 (its sun
/// single scattering's Legendre series cannot hold a peak that narrow), `full` the same beyond
/// 0.9997 and negative on the ground at 0.99998. Back-scattering is warned about from −0.9.
pub const MAX_ABS_G: f32 = 0.999;

/// Smallest voxel edge accepted near the world's origin (m): 0.1 mm, well below any cloud's and
/// a unit mistake's (a file in metres read as kilometres), above the camera's 1e-6-m framing.
const MIN_VOXEL_SIZE: f32 = 1e-4;

/// Optical depth beyond which exp(−τ) rounds to 0 in f32 (its smallest subnormal is e^{−103.3}).
pub(crate) const TAU_ZERO: f64 = 110.0;

/// `[medium]`: the cloud's density grid and its optical properties.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct MediumDesc {
    /// `"procedural"` or a path relative to the scene file: `.vol`, `.npy`, `.raw` (+ `.json`), `.vdb`.
    pub grid: String,
    /// Seed of the procedural cumulus.
    pub seed: u64,
    /// Procedural resolution (nx, ny, nz).
    pub resolution: [usize; 3],
    /// Voxel edge length (m), or one per axis `[x, y, z]` in the file's axes, for `.npy`, `.raw`
    /// and procedural grids.
    pub voxel_size: VoxelSize,
    /// Minimum corner of the grid (m), for `.npy`, `.raw` and procedural grids.
    pub origin: [f32; 3],
    /// Extinction coefficient at density 1 (m⁻¹).
    pub sigma_t: f32,
    /// Single-scattering albedo per RGB band (unitless, in [0, 1]).
    pub albedo: [f32; 3],
    /// Henyey–Greenstein mean cosine (unitless, |g| ≤ 0.999: `MAX_ABS_G`).
    pub g: f32,
    /// Grid to read from a `.vdb` file.
    pub grid_name: String,
    /// Extra factor on a `.vdb` file's index-to-world transform (unitless).
    pub scale: f32,
    /// Largest dense grid accepted, in voxels (memory guard; 4 bytes each plus solver storage).
    pub max_voxels: u64,
    /// Average N×N×N blocks after loading (1 = off).
    pub downsample: usize,
    /// Split each voxel into K×K×K after loading (K odd; 1 = off), the same trilinear density
    /// field at K times the resolution (`Grid3::refine`): for clouds whose light enters through
    /// optically thick voxels (docs/accuracy.md, "Optically thick voxels").
    pub refine: usize,
    /// The grid file's up axis: `"y"` (this program, Houdini) or `"z"` (Blender), turned to y-up.
    pub up_axis: UpAxis,
}

impl Default for MediumDesc {
    fn default() -> Self {
        MediumDesc {
            grid: "procedural".into(),
            seed: 1,
            resolution: [100, 80, 60],
            voxel_size: VoxelSize::Cube(10.0),
            origin: [-500.0, 0.0, -300.0],
            sigma_t: 0.05,
            albedo: [0.999, 0.999, 0.999],
            g: 0.9,
            grid_name: "density".into(),
            scale: 1.0,
            max_voxels: 200_000_000,
            downsample: 1,
            refine: 1,
            up_axis: UpAxis::Y,
        }
    }
}

impl MediumDesc {
    /// The first way to coarsen a refined cloud, for the memory guards' messages: "a lower
    /// medium.refine (now K: K³× the file's voxels), " where `refine` is above 1, else "".
    pub fn coarser_refine(&self) -> String {
        match self.refine {
            1 => String::new(),
            k => format!("a lower medium.refine (now {k}: {}× the file's voxels), ", k.pow(3)),
        }
    }
}

/// Largest `medium.refine` (each voxel becomes refine³: 343 at 7).
pub const MAX_REFINE: usize = 7;

/// A validated medium.
#[derive(Clone, Debug)]
pub struct Medium {
    /// Density ρ per voxel (unitless, ≥ 0), stored per full voxel.
    pub density: Arc<Density>,
    /// Minimum corner of the grid (m).
    pub origin: Vec3,
    /// Voxel edge lengths (m).
    pub voxel_size: Vec3,
    /// σt, albedo and phase function at density 1 (the only place they are kept).
    pub optics: Optics,
    /// Per-block bounds of ρ for empty-space skipping and delta tracking.
    pub majorant: Arc<MajorantGrid>,
    /// ρ dense on the grown cloud box, built by the first [`Self::dense_density`]: only the path
    /// tracer and `single` read it (their point look-ups cost 10 % and 6 % more instructions on
    /// the packed density); every other method reads [`Self::density`].
    dense_box: OnceLock<Arc<SubGrid>>,
}

impl Medium {
    /// Wrap a density grid; densities must already be validated (finite, ≥ 0).
    pub fn new(density: Grid3, origin: Vec3, voxel_size: Vec3, sigma_t: f32, albedo: Rgb, g: f32) -> Medium {
        Medium::with_optics(density, origin, voxel_size, Optics::new(sigma_t, albedo, g))
    }

    /// [`Medium::new`] from an [`Optics`] (e.g. another medium's). The dense grid is packed
    /// ([`Density::from_grid`]) and dropped.
    pub fn with_optics(density: Grid3, origin: Vec3, voxel_size: Vec3, optics: Optics) -> Medium {
        let density = Density::from_grid(&density);
        let majorant = MajorantGrid::of_density(&density, 4);
        Medium {
            density: Arc::new(density),
            origin,
            voxel_size,
            optics,
            majorant: Arc::new(majorant),
            dense_box: OnceLock::new(),
        }
    }

    /// [`Medium::from_desc`] with the grid `given` in memory instead of `medium.grid`'s (the
    /// library's [`crate::Density`]); it is checked like a loaded one. Returns the medium and the
    /// loader's notes for the user ([`loaders::Loaded::notes`]).
    pub fn from_desc_with(d: &MediumDesc, file: &str, base_dir: &Path, given: Option<loaders::Loaded>) -> Result<(Medium, Vec<String>)> {
        check(
            file,
            "medium.sigma_t",
            d.sigma_t.is_finite() && (d.sigma_t == 0.0 || d.sigma_t >= crate::limits::MIN_SIGMA_T),
            d.sigma_t,
            &format!(
                "extinction must be finite and non-negative (m⁻¹), and 0 or at least {:e} (below it f32 loses \
                 it; for a medium that thin, scale the grid's densities down and medium.sigma_t up by the same \
                 power of ten: only their product, the extinction, is physical)",
                crate::limits::MIN_SIGMA_T
            ),
        )?;
        check(
            file,
            "medium.albedo",
            rgb_in_unit(d.albedo),
            d.albedo,
            "each band must be in [0, 1]",
        )?;
        check(
            file,
            "medium.g",
            d.g.is_finite() && d.g.abs() <= MAX_ABS_G,
            d.g,
            &format!(
                "the Henyey-Greenstein g must be within ±{MAX_ABS_G}: a narrower peak is beyond the fast methods' \
                 phase expansions (transport and full come out 20 % too bright at g = 0.9998 and worse beyond); \
                 water clouds have g ≈ 0.85"
            ),
        )?;
        check(
            file,
            "medium.downsample",
            d.downsample >= 1 && d.downsample <= 64,
            d.downsample,
            "must be an integer from 1 (off) to 64",
        )?;
        check(
            file,
            "medium.refine",
            (1..=MAX_REFINE).contains(&d.refine) && d.refine % 2 == 1,
            d.refine,
            &format!("must be an odd integer from 1 (off) to {MAX_REFINE} (each voxel becomes refine³)"),
        )?;
        check(
            file,
            "medium.refine",
            d.refine == 1 || d.downsample == 1,
            d.refine,
            "cannot be combined with medium.downsample; set one of them to 1",
        )?;
        check(file, "medium.max_voxels", d.max_voxels >= 1, d.max_voxels, "must be at least 1")?;
        let loaded = match given {
            Some(loaded) => loaded,
            None => loaders::load(d, file, base_dir)?,
        };
        let mut grid = loaded.grid;
        let mut voxel = loaded.voxel_size;
        if d.downsample > 1 && !loaded.downsampled {
            grid = grid.downsample(d.downsample);
            voxel *= d.downsample as f32;
        }
        let (mut grid, origin, mut voxel) = up_axis::to_y_up(d.up_axis, (grid, loaded.origin, voxel));
        // Counted with the refinement, before it allocates.
        let n = (grid.len() as u64).saturating_mul((d.refine as u64).pow(3));
        let fix = match d.refine {
            1 => "raise it or set medium.downsample".to_string(),
            k => format!("lower medium.refine (= {k}: {}× the file's voxels) or raise medium.max_voxels", k.pow(3)),
        };
        check(
            &loaded.name,
            "medium.max_voxels",
            n <= d.max_voxels,
            n,
            &format!("the grid has {n} voxels, more than medium.max_voxels = {}; {fix}", d.max_voxels),
        )?;
        if let Some((idx, v)) = grid.data().iter().enumerate().find(|(_, v)| !v.is_finite() || **v < 0.0) {
            let dims = grid.dims();
            let (i, j, k) = (idx % dims[0], (idx / dims[0]) % dims[1], idx / (dims[0] * dims[1]));
            return Err(Error::format(
                &loaded.name,
                // Both orders: a numpy user indexes the array [z][y][x].
                format!(
                    "density at voxel (x, y, z) = ({i}, {j}, {k}), array index [{k}, {j}, {i}], is {v}: \
                     densities must be finite and non-negative"
                ),
            ));
        }
        let densest = grid.data().iter().fold(0.0f32, |m, &v| m.max(v));
        check(
            &loaded.name,
            "density",
            densest <= crate::limits::MAX_DENSITY,
            densest,
            &format!(
                "the grid's densities reach {densest:e}, above {:e}, where the methods' f32 products of densities \
                 overflow; scale the densities down and medium.sigma_t up by the same power of ten (only their \
                 product, the extinction, is physical)",
                crate::limits::MAX_DENSITY
            ),
        )?;
        let sigma_max = d.sigma_t as f64 * densest as f64;
        check(
            file,
            "medium.sigma_t",
            sigma_max <= crate::limits::MAX_SIGMA_T as f64,
            d.sigma_t,
            &format!(
                "times the grid's largest density {densest:e} gives an extinction of {sigma_max:e} m⁻¹, more than {:e}; lower medium.sigma_t or the grid's densities",
                crate::limits::MAX_SIGMA_T
            ),
        )?;
        // The file's voxels checked (refining keeps the largest density), each split into
        // refine³ holding the same trilinear field.
        if d.refine > 1 {
            grid = grid.refine(d.refine);
            voxel /= d.refine as f32;
        }
        check(
            &loaded.name,
            "medium.voxel_size",
            finite3(voxel.to_array()) && voxel.min_element() > 0.0 && voxel.max_element() <= MAX_VOXEL_SIZE,
            voxel.to_array(),
            "voxel size must be positive and at most 1e6 m (1000 km); check the grid's units",
        )?;
        check(
            &loaded.name,
            "medium.origin",
            finite3(origin.to_array()) && origin.abs().max_element() <= crate::limits::MAX_COORDINATE,
            origin.to_array(),
            &format!(
                "the grid's minimum corner must be finite and within ±{:e} m of the world's origin (m); \
                 move the cloud nearer 0",
                crate::limits::MAX_COORDINATE
            ),
        )?;
        check_voxel_resolvable(&loaded.name, grid.dims(), origin, voxel)?;
        let medium = Medium::new(grid, origin, voxel, d.sigma_t, Rgb::from(d.albedo), d.g);
        Ok((medium, loaded.notes))
    }

    /// Grid resolution.
    #[inline]
    pub fn dims(&self) -> [usize; 3] {
        self.density.dims()
    }

    /// The box (m) of the voxels that hold density (the whole grid if none do): what
    /// `camera.fit` frames.
    pub fn cloud_box(&self) -> (Vec3, Vec3) {
        match self.active_box(0) {
            Some((lo, hi)) => {
                let at = |i: [usize; 3]| self.origin + self.voxel_size * Vec3::new(i[0] as f32, i[1] as f32, i[2] as f32);
                (at(lo), at(hi))
            }
            None => self.bbox(),
        }
    }

    /// The box [min, max] (m).
    #[inline]
    pub fn bbox(&self) -> (Vec3, Vec3) {
        let d = self.dims();
        (
            self.origin,
            self.origin + self.voxel_size * Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32),
        )
    }

    /// World point → continuous voxel coordinates (voxel centres at half-integers).
    #[inline]
    pub fn to_voxel(&self, p: Vec3) -> Vec3 {
        (p - self.origin) / self.voxel_size
    }

    /// Centre of voxel (i, j, k) (m).
    #[inline]
    pub fn voxel_center(&self, i: usize, j: usize, k: usize) -> Vec3 {
        self.origin + self.voxel_size * Vec3::new(i as f32 + 0.5, j as f32 + 0.5, k as f32 + 0.5)
    }

    /// ρ at a world point: trilinear inside the box, zero outside.
    #[inline]
    pub fn density_at(&self, p: Vec3) -> f32 {
        self.inside_voxel(p).map_or(0.0, |v| self.density.trilinear(v))
    }

    /// A dense copy of ρ on the cloud's box grown by one voxel (0 beyond it), built on the first
    /// call and kept: 4 B per box voxel for fewer instructions per look-up; its `trilinear` gives
    /// the same bits as [`Density::trilinear`]. For `reference`, `single`, and `diffusion`'s and
    /// `transport`'s gathers (built after their solves, below their peaks) only: `full` must not
    /// build it (it would be alive at its peak).
    pub fn dense_density(&self) -> &SubGrid {
        self.dense_box.get_or_init(|| {
            let (lo, hi) = self.active_box(1).unwrap_or(([0; 3], [0; 3]));
            Arc::new(self.density.box_copy(lo, hi))
        })
    }

    /// [`Self::density_at`] (the same bits) from [`Self::dense_density`].
    #[inline]
    pub fn dense_density_at(&self, p: Vec3) -> f32 {
        let dense = self.dense_density();
        self.inside_voxel(p).map_or(0.0, |v| dense.trilinear(v))
    }

    /// [`Self::transmittance`] (the same bits) from [`Self::dense_density`].
    pub fn dense_transmittance(&self, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> f32 {
        let dense = self.dense_density();
        self.transmittance_with(|v| dense.trilinear(v), o, d, t_min, t_max)
    }

    /// The continuous voxel coordinates of world point `p` if it lies in the box.
    #[inline(always)]
    fn inside_voxel(&self, p: Vec3) -> Option<[f32; 3]> {
        let v = self.to_voxel(p);
        let d = self.dims();
        let outside = v.x < 0.0 || v.y < 0.0 || v.z < 0.0 || v.x > d[0] as f32 || v.y > d[1] as f32 || v.z > d[2] as f32;
        (!outside).then(|| v.to_array())
    }

    /// Ray–box interval (m) clipped to [t_min, t_max].
    #[inline]
    pub fn intersect(&self, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> Option<(f32, f32)> {
        let (lo, hi) = self.bbox();
        ray_box(lo.as_dvec3(), hi.as_dvec3(), o.as_dvec3(), d.as_dvec3(), t_min as f64, t_max as f64).map(|(a, b)| (a as f32, b as f32))
    }

    /// Exact ∫ ρ ds (m, density × length) along `o + t·d`, t ∈ [t_min, t_max], `d` unit.
    /// Skips empty majorant blocks; inside the others walks the dual lattice with Simpson's rule.
    pub fn density_integral(&self, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> f64 {
        self.density_integral_until(o, d, t_min, t_max, f64::INFINITY)
    }

    /// [`Self::density_integral`], stopped once the sum reaches `limit` (then some value
    /// ≥ `limit`: every dual cell adds a non-negative Simpson term); below it, the same bits.
    pub fn density_integral_until(&self, o: Vec3, d: Vec3, t_min: f32, t_max: f32, limit: f64) -> f64 {
        self.density_integral_until_with(|v| self.density.trilinear(v), o, d, t_min, t_max, limit)
    }

    /// [`Self::density_integral_until`] with ρ at continuous voxel coordinates from `rho`, which
    /// must give the medium's trilinear density (e.g. from [`Self::dense_density`], the same bits).
    pub fn density_integral_until_with(&self, rho: impl Fn([f32; 3]) -> f32, o: Vec3, d: Vec3, t_min: f32, t_max: f32, limit: f64) -> f64 {
        let Some((t0, t1)) = self.intersect(o, d, t_min, t_max) else {
            return 0.0;
        };
        let (od, dd) = (o.as_dvec3(), d.as_dvec3());
        let h = self.voxel_size.as_dvec3();
        let inv_h = DVec3::ONE / h;
        let orig = self.origin.as_dvec3();
        let rho = |t: f64| -> f64 {
            let v = ((od + dd * t) - orig) * inv_h;
            rho([v.x as f32, v.y as f32, v.z as f32]) as f64
        };
        let mut sum = 0.0;
        self.majorant.for_each_block(self, o, d, t0, t1, |ta, tb, maj| {
            if maj <= 0.0 {
                return true;
            }
            let mut r0 = rho(ta as f64);
            for s in self.dual_dda(o, d, ta as f64, tb as f64) {
                let rm = rho(0.5 * (s.t0 + s.t1));
                let r1 = rho(s.t1);
                sum += (s.t1 - s.t0) / 6.0 * (r0 + 4.0 * rm + r1);
                if sum >= limit {
                    return false;
                }
                r0 = r1;
            }
            true
        });
        sum
    }

    /// The DDA over the dual lattice's cells (between adjacent voxel centres, where the trilinear
    /// ρ is a cubic in t, so Simpson's rule on a cell is exact; cell c spans voxel coordinates
    /// [c − ½, c + ½]) crossed by `o + t·d` for t ∈ [ta, tb].
    #[inline]
    pub fn dual_dda(&self, o: Vec3, d: Vec3, ta: f64, tb: f64) -> Dda {
        let h = self.voxel_size.as_dvec3();
        let dims = self.dims();
        let dual_dims = [dims[0] + 1, dims[1] + 1, dims[2] + 1];
        Dda::new(self.origin.as_dvec3() - 0.5 * h, h, dual_dims, o.as_dvec3(), d.as_dvec3(), ta, tb)
    }

    /// The dual lattice's cells along `o + t·d`, t ∈ [t0, t1] (inside the box), in the runs of
    /// consecutive non-empty majorant blocks: `f(cells)` once per run, with one DDA over it.
    /// Empty blocks are skipped. (A DDA per block would cut every dual cell that straddles a
    /// block face into two: more cells, pieces, sun look-ups and compositing steps per ray.)
    pub fn for_each_dual_run(&self, o: Vec3, d: Vec3, t0: f32, t1: f32, mut f: impl FnMut(Dda)) {
        let mut walk = |a: f32, b: f32| f(self.dual_dda(o, d, a as f64, b as f64));
        let mut run: Option<(f32, f32)> = None;
        self.majorant.for_each_block(self, o, d, t0, t1, |ta, tb, maj| {
            run = match run {
                _ if maj <= 0.0 => {
                    if let Some((a, b)) = run {
                        walk(a, b);
                    }
                    None
                }
                Some((a, b)) if b == ta => Some((a, tb)),
                Some((a, b)) => {
                    walk(a, b);
                    Some((ta, tb))
                }
                None => Some((ta, tb)),
            };
            true
        });
        if let Some((a, b)) = run {
            walk(a, b);
        }
    }

    /// The dual cells per non-empty majorant block, `f(t_enter, cells)`: the per-block walk the
    /// tests check [`Self::for_each_dual_run`] against.
    #[cfg(test)]
    pub fn for_each_dual_block(&self, o: Vec3, d: Vec3, t0: f32, t1: f32, mut f: impl FnMut(f32, Dda)) {
        self.majorant.for_each_block(self, o, d, t0, t1, |ta, tb, maj| {
            if maj > 0.0 {
                f(ta, self.dual_dda(o, d, ta as f64, tb as f64));
            }
            true
        });
    }

    /// Optical depth ∫ σt ρ ds (unitless) along a ray segment; exact.
    #[inline]
    pub fn optical_depth(&self, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> f32 {
        (self.optics.sigma_t as f64 * self.density_integral(o, d, t_min, t_max)) as f32
    }

    /// Transmittance exp(−optical depth) along a ray segment; exact.
    #[inline]
    pub fn transmittance(&self, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> f32 {
        self.transmittance_with(|v| self.density.trilinear(v), o, d, t_min, t_max)
    }

    /// [`Self::transmittance`] with ρ from `rho`, as [`Self::density_integral_until_with`]: the
    /// same bits.
    pub fn transmittance_with(&self, rho: impl Fn([f32; 3]) -> f32, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> f32 {
        // Beyond TAU_ZERO the rest of the ray cannot change the result (0): it is not walked.
        let sigma_t = self.optics.sigma_t as f64;
        let sum = self.density_integral_until_with(rho, o, d, t_min, t_max, TAU_ZERO / sigma_t);
        (-((sigma_t * sum) as f32)).exp()
    }

    /// Smallest voxel edge (m).
    #[inline]
    pub fn min_voxel(&self) -> f32 {
        self.voxel_size.min_element()
    }

    /// The medium with every voxel emptied whose density reaches only points below the plane
    /// y = `height` (m): its centre a voxel or more below it, so the trilinear field at and above
    /// the plane is unchanged. Under an opaque ground that density is never lit and never seen;
    /// the methods that solve on the grid would light it and let it shine up into the cloud (a fog
    /// bank half under the ground: `transport` +20 % over the cloud). `None` where no such voxel
    /// holds density.
    pub fn emptied_below(&self, height: f32) -> Option<Medium> {
        let [nx, ny, nz] = self.dims();
        // Rows j with centre + one voxel at or below the plane.
        let rows = (0..ny)
            .take_while(|&j| self.origin.y + (j as f32 + 1.5) * self.voxel_size.y <= height)
            .count();
        let slab = nx * ny;
        let occupied = (0..nz).any(|k| (0..rows).any(|j| (0..nx).any(|i| self.density.get(i, j, k) > 0.0)));
        if !occupied {
            return None;
        }
        let mut grid = self.density.to_grid();
        for plane in grid.data_mut().chunks_mut(slab) {
            plane[..rows * nx].fill(0.0);
        }
        Some(Medium::with_optics(grid, self.origin, self.voxel_size, self.optics))
    }

    /// Index box [lo, hi) of every non-empty voxel grown by `margin` voxels, clipped to the grid.
    pub fn active_box(&self, margin: usize) -> Option<([usize; 3], [usize; 3])> {
        let d = self.dims();
        let (mut lo, mut hi) = self.density.full_box()?;
        for a in 0..3 {
            lo[a] = lo[a].saturating_sub(margin);
            hi[a] = (hi[a] + margin).min(d[a]);
        }
        Some((lo, hi))
    }
}

/// Refuse voxels too small for f32 positions where the grid lies (`MIN_VOXEL_OF_COORDINATE`,
/// `MIN_VOXEL_SIZE`): such a box collapses to a point and every method renders it wrongly.
fn check_voxel_resolvable(file: &str, dims: [usize; 3], origin: Vec3, voxel: Vec3) -> Result<()> {
    let far_corner = origin + voxel * Vec3::new(dims[0] as f32, dims[1] as f32, dims[2] as f32);
    let farthest = origin.abs().max(far_corner.abs()).max_element();
    let smallest = (farthest * MIN_VOXEL_OF_COORDINATE).max(MIN_VOXEL_SIZE);
    check(
        file,
        "medium.voxel_size",
        voxel.min_element() >= smallest,
        voxel.to_array(),
        &format!(
            "a voxel must be at least {smallest:.1e} m here ({MIN_VOXEL_SIZE:e} m, and 2⁻²⁰ of the grid's farthest \
             coordinate, {farthest:.0} m, for f32 positions to resolve it); check the grid's units \
             (medium.voxel_size, or medium.scale for a .vdb) or move medium.origin nearer 0"
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn box_medium(rho: f32) -> Medium {
        Medium::new(
            Grid3::filled([8, 5, 6], rho),
            Vec3::new(-4.0, 0.0, -3.0),
            Vec3::new(1.0, 2.0, 1.0),
            0.3,
            Rgb::ONE,
            0.0,
        )
    }

    /// Rows 0–1 of 2-m voxels from y = 0 have centres 1 and 3 m: with the ground at 4 m only row
    /// 0 (its field ends at 3 m) is emptied, and the field from the ground up is unchanged.
    #[test]
    fn emptied_below_clears_only_the_density_under_the_ground() {
        let m = box_medium(0.5);
        assert!(m.emptied_below(2.9).is_none() && m.emptied_below(-1.0).is_none());
        let cut = m.emptied_below(4.0).expect("row 0 lies under the plane");
        assert_eq!(cut.density.get(3, 0, 2), 0.0);
        assert_eq!(cut.density.get(3, 1, 2), 0.5);
        for y in [4.0f32, 4.5, 7.0, 9.9] {
            let p = Vec3::new(0.1, y, 0.2);
            assert_eq!(cut.density_at(p), m.density_at(p), "y = {y}");
        }
        assert!(cut.density_at(Vec3::new(0.1, 2.0, 0.2)) < 0.5);
        assert!(cut.emptied_below(4.0).is_none());
    }

    #[test]
    fn a_given_grid_far_from_the_origin_is_refused_naming_medium_origin() {
        // The API's and Python's densities bring their own origin, past the scene file's check.
        let medium = |origin: Vec3| {
            let given = loaders::Loaded {
                grid: Grid3::filled([2, 2, 2], 1.0),
                origin,
                voxel_size: Vec3::splat(10.0),
                name: "in-memory density".into(),
                downsampled: false,
                notes: Vec::new(),
            };
            Medium::from_desc_with(&MediumDesc::default(), "s.toml", Path::new("."), Some(given))
        };
        assert!(medium(Vec3::new(-1e7, 0.0, 0.0)).is_ok());
        let e = medium(Vec3::new(1e30, 0.0, 0.0)).unwrap_err().to_string();
        assert!(e.contains("in-memory density") && e.contains("medium.origin") && e.contains("1e7"), "{e}");
    }

    #[test]
    fn voxels_too_small_for_f32_positions_are_refused_naming_the_fix() {
        let dims = [20, 16, 12];
        let ok = |origin: [f32; 3], voxel: f32| check_voxel_resolvable("s.toml", dims, Vec3::from(origin), Vec3::splat(voxel));
        assert!(ok([0.0; 3], 1e-4).is_ok());
        assert!(ok([-500.0, 0.0, -300.0], 1e-3).is_ok());
        assert!(ok([1e7, 0.0, 0.0], 10.0).is_ok(), "10-m voxels at the coordinate limit");
        // A voxel of 1e-30 m would collapse the box, and the framing would blame camera.look_at.
        for (origin, voxel) in [([0.0; 3], 1e-30), ([0.0; 3], 5e-5), ([-500.0, 0.0, -300.0], 1e-6), ([1e7, 0.0, 0.0], 1.0)] {
            let e = ok(origin, voxel).unwrap_err().to_string();
            assert!(e.contains("medium.voxel_size") && e.contains("units"), "{origin:?} {voxel}: {e}");
        }
    }

    #[test]
    fn active_box_is_the_occupied_box_grown_and_clipped() {
        let mut g = Grid3::filled([6, 6, 6], 0.0);
        g.set(1, 2, 1, 0.5);
        g.set(4, 4, 3, 1.0);
        let m = Medium::new(g, Vec3::ZERO, Vec3::ONE, 1.0, Rgb::ONE, 0.0);
        assert_eq!(m.active_box(0), Some(([1, 2, 1], [5, 5, 4])));
        assert_eq!(m.active_box(1), Some(([0, 1, 0], [6, 6, 5])));
        assert_eq!(m.active_box(3), Some(([0, 0, 0], [6, 6, 6])));
        let empty = Medium::new(Grid3::filled([3, 3, 3], 0.0), Vec3::ZERO, Vec3::ONE, 1.0, Rgb::ONE, 0.0);
        assert_eq!(empty.active_box(1), None);
    }

    #[test]
    fn the_dense_copy_reads_the_same_bits_as_the_packed_density() {
        let mut g = Grid3::filled([9, 7, 6], 0.0);
        let mut rng = crate::math::Rng::new(3, 9);
        for k in 1..5 {
            for j in 2..6 {
                for i in 1..7 {
                    if rng.uniform() < 0.6 {
                        g.set(i, j, k, 0.1 + rng.uniform());
                    }
                }
            }
        }
        let m = Medium::new(g, Vec3::new(-4.0, 0.0, -3.0), Vec3::new(1.0, 2.0, 1.5), 0.3, Rgb::ONE, 0.0);
        for _ in 0..5000 {
            // The whole box and beyond it on every side.
            let p = Vec3::new(rng.uniform() * 13.0 - 6.0, rng.uniform() * 18.0 - 2.0, rng.uniform() * 12.0 - 5.0);
            assert_eq!(m.dense_density_at(p).to_bits(), m.density_at(p).to_bits(), "at {p}");
        }
    }

    #[test]
    fn homogeneous_box_transmittance_is_beer_lambert() {
        let m = box_medium(0.7);
        let mut rng = crate::math::Rng::new(5, 5);
        for _ in 0..500 {
            let o = Vec3::new(rng.uniform() * 20.0 - 10.0, rng.uniform() * 20.0 - 5.0, rng.uniform() * 20.0 - 10.0);
            let d = crate::math::uniform_sphere(rng.uniform(), rng.uniform());
            let chord = m.intersect(o, d, 0.0, f32::INFINITY).map_or(0.0, |(a, b)| b - a);
            let t = m.transmittance(o, d, 0.0, f32::INFINITY);
            let exact = (-0.3f32 * 0.7 * chord).exp();
            assert!((t - exact).abs() < 1e-5, "{t} vs {exact}");
        }
    }

    #[test]
    fn simpson_is_exact_on_trilinear_field() {
        // A linear ramp in x: ∫ρ ds has a closed form along an axis-aligned ray through centres.
        let mut g = Grid3::filled([6, 3, 3], 0.0);
        for k in 0..3 {
            for j in 0..3 {
                for i in 0..6 {
                    g.set(i, j, k, i as f32);
                }
            }
        }
        let m = Medium::new(g, Vec3::ZERO, Vec3::ONE, 1.0, Rgb::ONE, 0.0);
        // Along x at y=z=1.5: ρ(x) = clamp(x - 0.5, 0, 5); ∫_0^6 = 5*0.5 (flat top) + ∫_{0.5}^{5.5}(x-0.5) = 2.5 + 12.5.
        let i = m.density_integral(Vec3::new(-1.0, 1.5, 1.5), Vec3::X, 0.0, 100.0);
        assert!((i - 15.0).abs() < 1e-4, "{i}");
        // Oblique ray: compare with a fine midpoint rule.
        let (o, d) = (Vec3::new(-0.5, 0.2, 0.1), Vec3::new(1.0, 0.4, 0.3).normalize());
        let exact = m.density_integral(o, d, 0.0, 100.0);
        let n = 200_000;
        let (t0, t1) = m.intersect(o, d, 0.0, 100.0).unwrap();
        let dt = (t1 - t0) as f64 / n as f64;
        let brute: f64 = (0..n)
            .map(|k| m.density_at(o + d * (t0 + ((k as f64 + 0.5) * dt) as f32)) as f64 * dt)
            .sum();
        assert!((exact - brute).abs() < 1e-4 * brute, "{exact} vs {brute}");
    }
}
