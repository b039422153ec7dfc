//! Mip pyramid of the lit volume for cone-matched volume rendering (the modern stand-in for the
//! paper's octree of least-squares approximations, Schussman and Max 2001).
//!
//! Level 0 holds, per voxel, the pre-multiplied quantities (ρ, ρ·I0 (RGB), ρ·T_sun): it is the lit
//! volume's own cells ([`LitVolume::cells`], the same allocation, not a copy); level l+1
//! averages 2×2×2 blocks of level l (decoded), counting cells beyond the grid as empty, so every
//! level keeps the cloud's total mass and the mass-weighted mean colour (to the cells' rounding,
//! [`Cells`]). A sample at level l interpolates
//! trilinearly and divides by ρ to recover the colour, so empty space never darkens the colour.
//! Each level has a block occupancy grid for empty-space skipping. Every level stores its cells
//! only where ρ > 0 ([`crate::medium::sparse`]; level 0 shares the density grid's index).

use super::LitVolume;
use crate::half::Scaled16;
use crate::math::{Rgb, Trilinear, Vec3};
use crate::medium::sparse::{FullIndex, VoxelField};
use crate::medium::MajorantGrid;
use glam::Vec4;
use std::sync::Arc;

/// Block edge (in the level's voxels) of each level's occupancy grid.
pub const BLOCK: usize = 4;

/// A cell's values (decoded): ρ, ρ·I0.r, ρ·I0.g, ρ·I0.b, ρ·T_sun.
pub type Cell = [f32; 5];

/// A cell as stored: each channel a [`Scaled16`] code under its channel's scale (10 B).
type Code = [Scaled16; 5];

/// Cells stored per full voxel in 16 bits a channel (10 B a cell against 20 B in f32: the lit
/// volume's cells are `full`'s largest field at its clear-air cubes and last stage), one
/// power-of-two scale per channel chosen from the channel's largest value. Every channel is ≥ 0
/// (ρ, ρ·max(I0, 0), ρ·T_sun), which is what [`Scaled16`] codes. **Rounding:** every value from
/// 2⁻²⁹ of its channel's largest up reads back within 2⁻¹² relative (round to nearest); smaller
/// ones read 0 (an absolute error below 2⁻²⁹ of the largest); 0 reads exactly 0. Readers decode
/// (a shift and a multiply a channel, the four colour channels in one SSE2 step, then the second
/// factor) and keep their arithmetic in f32. Any light and density f32 holds fits: a channel whose
/// largest value is above 2³¹ (ρ·I0 of light brighter than ~2e9 W·m⁻²·sr⁻¹) takes a second
/// factor beyond one f32 scale ([`Scaled16::split_scale`]); one scale saturated above 2³².
#[derive(Clone, Debug)]
pub struct Cells {
    codes: VoxelField<Code>,
    /// 2^k per channel: the first factor of [`Scaled16::split_scale`] …
    scale: [f32; 5],
    /// … and the second, 1 unless the channel's largest value is above 2³¹.
    high: [f32; 5],
}

/// The scales ([`Cells::scale`], [`Cells::high`]) of channels coded under exponents `k`.
fn scales(k: [i32; 5]) -> ([f32; 5], [f32; 5]) {
    let s = k.map(Scaled16::split_scale);
    (s.map(|s| s[0]), s.map(|s| s[1]))
}

/// The scale exponents the cells are coded under.
fn exponents(max: [f32; 5]) -> [i32; 5] {
    max.map(|m| Scaled16::wide_exponent_for(f64::from(m)))
}

impl Cells {
    /// `at(grid index)` for every full voxel of `index` (each channel ≥ 0; it is called twice
    /// per voxel: once for the channels' largest values, once to encode), zero elsewhere.
    pub fn from_fn(index: Arc<FullIndex>, at: impl Fn(usize) -> Cell + Sync) -> Cells {
        // max is exact and order-free: the same scales with any thread count.
        let mut max = [0f32; 5];
        for g in index.full_voxels() {
            max = std::array::from_fn(|a| max[a].max(at(g)[a]));
        }
        let k = exponents(max);
        let codes = VoxelField::from_fn(index, [Scaled16::ZERO; 5], |g| encode(at(g), k));
        let (scale, high) = scales(k);
        Cells { codes, scale, high }
    }

    /// From every full voxel's cell in grid order (`cells.len()` = `index.count()`).
    fn from_packed(index: Arc<FullIndex>, cells: &[Cell]) -> Cells {
        let max = cells.iter().fold([0f32; 5], |m, c| std::array::from_fn(|a| m[a].max(c[a])));
        let k = exponents(max);
        let (scale, high) = scales(k);
        Cells {
            codes: VoxelField::new(index, [Scaled16::ZERO; 5], cells.iter().map(|c| encode(*c, k))),
            scale,
            high,
        }
    }

    /// `t` over the cells' slots ([`VoxelField::slots`]).
    #[inline]
    pub fn slots(&self, t: &Trilinear) -> Trilinear {
        self.codes.slots(t)
    }

    /// ρ in slot `s` under the channel's first factor only ([`Self::high`] not applied).
    #[inline(always)]
    fn rho_first(&self, s: usize) -> f32 {
        self.codes.at_slot(s)[0].decode(self.scale[0])
    }

    /// ρ·I0 (RGB) and ρ·T_sun in slot `s`, decoded at once, under their first factors only.
    #[inline(always)]
    fn rest_first(&self, s: usize) -> [f32; 4] {
        let c = self.codes.at_slot(s);
        let sc = &self.scale;
        Scaled16::decode4([c[1], c[2], c[3], c[4]], [sc[1], sc[2], sc[3], sc[4]])
    }

    /// ρ blended over `t`'s slots (from [`Self::slots`]). The second factor multiplies the
    /// blend once, not each corner (the same value: powers of two; 1 at ordinary scales).
    #[inline(always)]
    pub fn rho_blend(&self, t: &Trilinear) -> f32 {
        t.blend(|s| self.rho_first(s)) * self.high[0]
    }

    /// ρ·I0 (RGB) and ρ·T_sun blended over `t`'s slots, as [`Self::rho_blend`].
    #[inline(always)]
    pub fn rest_blend(&self, t: &Trilinear) -> Vec4 {
        let h = &self.high;
        t.blend(|s| Vec4::from_array(self.rest_first(s))) * Vec4::new(h[1], h[2], h[3], h[4])
    }

    /// ρ·I0 (RGB) blended over `t`'s slots, as [`Self::rho_blend`].
    #[inline(always)]
    pub fn rho_i0_blend(&self, t: &Trilinear) -> Rgb {
        let h = &self.high;
        t.blend(|s| {
            let c = self.rest_first(s);
            Rgb::new(c[0], c[1], c[2])
        }) * Rgb::new(h[1], h[2], h[3])
    }

    /// The cell in slot `s` (from [`Self::slots`]).
    #[inline(always)]
    pub fn at_slot(&self, s: usize) -> Cell {
        let (r, h) = (self.rest_first(s), &self.high);
        [self.rho_first(s) * h[0], r[0] * h[1], r[1] * h[2], r[2] * h[3], r[3] * h[4]]
    }

    /// The cell of grid voxel `g` (zero where empty).
    #[inline]
    pub fn get(&self, g: usize) -> Cell {
        self.at_slot(self.codes.index().slot(g))
    }

    /// The full voxels' cells in grid order.
    pub fn packed(&self) -> impl Iterator<Item = Cell> + '_ {
        (1..=self.codes.index().count()).map(|s| self.at_slot(s))
    }

    /// The index the cells are addressed by.
    #[inline]
    pub fn index(&self) -> &Arc<FullIndex> {
        self.codes.index()
    }

    /// Bytes held by the codes (the index is shared and counted apart).
    pub fn bytes(&self) -> usize {
        self.codes.bytes()
    }
}

/// `c` coded under the channels' scale exponents `k`.
#[inline]
fn encode(c: Cell, k: [i32; 5]) -> Code {
    std::array::from_fn(|a| Scaled16::encode(f64::from(c[a]), k[a]))
}

/// One level of the pyramid.
#[derive(Clone, Debug)]
pub struct Level {
    /// Cells per axis.
    pub dims: [usize; 3],
    /// Voxel edge lengths at this level (m).
    pub voxel_size: Vec3,
    /// Pre-multiplied cells, x fastest, stored where ρ > 0 (zero elsewhere); level 0's are the
    /// lit volume's cells (shared).
    pub cells: Arc<Cells>,
    /// Upper bounds of ρ per block of [`BLOCK`]³ cells (with a one-cell apron).
    pub occupancy: MajorantGrid,
}

impl Level {
    /// Trilinear sample at continuous level-voxel coordinates `v` (inside the level's box);
    /// None where the interpolated density is zero (the colour channels are then not gathered).
    #[inline]
    pub fn sample(&self, v: Vec3) -> Option<Cell> {
        let t = self.cells.slots(&Trilinear::new(self.dims, v.to_array()));
        let rho = self.cells.rho_blend(&t);
        if rho <= 1e-12 {
            return None;
        }
        let c = self.cells.rest_blend(&t);
        Some([rho, c.x, c.y, c.z, c.w])
    }
}

/// The pyramid, finest level first.
#[derive(Clone, Debug)]
pub struct LitPyramid {
    /// Levels 0 (the voxel grid) to the coarsest.
    pub levels: Vec<Level>,
    /// Minimum corner shared by every level (m).
    pub origin: Vec3,
}

impl LitPyramid {
    /// Build from a lit volume, down to a level whose largest axis has at most [`BLOCK`] cells or
    /// `max_levels` levels in all (at least 1).
    pub fn build(lit: &LitVolume, max_levels: usize) -> LitPyramid {
        let m = &lit.medium;
        // Level 0's occupancy is the medium's majorant grid where its blocks are the same.
        let occupancy = match m.majorant.block {
            BLOCK => (*m.majorant).clone(),
            _ => MajorantGrid::of_density(&m.density, BLOCK),
        };
        let level0 = Level {
            dims: m.dims(),
            voxel_size: m.voxel_size,
            cells: lit.cells().clone(),
            occupancy,
        };
        let mut levels = vec![level0];
        while levels.len() < max_levels.max(1) {
            let last = levels.last().expect("at least one level");
            if last.dims.iter().all(|&d| d <= BLOCK) {
                break;
            }
            let next = downsample(last);
            levels.push(next);
        }
        LitPyramid { levels, origin: m.origin }
    }
}

/// Grid indices (x fastest, in that order) of the cells of a `d` grid that the coarser cell `c`
/// averages: its 2×2×2 block, less the cells beyond the grid (they count as empty, so the mean
/// still divides by 8).
pub fn children(d: [usize; 3], c: [usize; 3]) -> impl Iterator<Item = usize> {
    let span = move |a: usize| 2 * c[a]..(2 * c[a] + 2).min(d[a]);
    span(2).flat_map(move |kk| span(1).flat_map(move |jj| span(0).map(move |ii| ii + d[0] * (jj + d[1] * kk))))
}

/// Average 2×2×2 blocks of the decoded cells, then code them ([`Cells`]); cells beyond the grid
/// count as empty (mass-preserving). Walks the finer level's full cells only, in grid order, so
/// each coarse cell adds its full children in the order of [`children`] (its empty ones add
/// nothing): the coarse level is never held for every cell of its grid (20 B per coarse cell,
/// the 200×160×120 cloud's `full` peak), only its ρ (4 B per coarse cell, for its index) while
/// it is built, and its full cells in f32 until they are coded.
fn downsample(l: &Level) -> Level {
    let d = l.dims;
    let nd = [d[0].div_ceil(2), d[1].div_ceil(2), d[2].div_ceil(2)];
    let coarse = |n: usize| {
        let (i, j, k) = (n % d[0], (n / d[0]) % d[1], n / (d[0] * d[1]));
        i / 2 + nd[0] * (j / 2 + nd[1] * (k / 2))
    };
    let fine = || l.cells.index().full_voxels().zip(l.cells.packed());
    let mut rho = vec![0f32; nd[0] * nd[1] * nd[2]];
    for (n, c) in fine() {
        rho[coarse(n)] += c[0];
    }
    rho.iter_mut().for_each(|r| *r *= 0.125);
    let index = Arc::new(FullIndex::build(nd, &rho));
    let occupancy = MajorantGrid::build(nd, index.full_voxels().map(|n| (n, rho[n])), BLOCK);
    drop(rho);
    let mut cells = vec![[0f32; 5]; index.count() + 1];
    for (n, c) in fine() {
        // Slot 0: a coarse cell whose mean ρ rounds to 0 is empty.
        let s = index.slot(coarse(n));
        if s != 0 {
            for (a, v) in cells[s].iter_mut().zip(c) {
                *a += v;
            }
        }
    }
    cells[1..].iter_mut().for_each(|c| *c = c.map(|x| x * 0.125));
    let cells = Cells::from_packed(index, &cells[1..]);
    Level {
        dims: nd,
        voxel_size: l.voxel_size * 2.0,
        cells: Arc::new(cells),
        occupancy,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::{Sky, Sun};
    use crate::math::Rgb;
    use crate::medium::{Grid3, Medium};

    #[test]
    fn every_level_keeps_mass_and_mean_colour() {
        let dims = [7, 5, 6];
        let mut g = Grid3::filled(dims, 0.0);
        let mut i0 = vec![Rgb::ZERO; 7 * 5 * 6];
        for (n, x) in g.data_mut().iter_mut().enumerate() {
            *x = ((n * 13) % 5) as f32 * 0.5;
            i0[n] = Rgb::new(n as f32 % 3.0, 1.0, 2.0);
        }
        let m = Medium::new(g, Vec3::ZERO, Vec3::ONE, 1.0, Rgb::ONE, 0.5);
        let sun = Sun {
            dir: Vec3::Y,
            irradiance: Rgb::ONE,
        };
        let lit = LitVolume::new(m, i0, Grid3::filled(dims, 0.5), sun, Sky::constant(Rgb::ONE), None);
        let p = LitPyramid::build(&lit, 10);
        assert!(p.levels.len() >= 2);
        let total = |l: &Level| {
            let vol = l.voxel_size.x * l.voxel_size.y * l.voxel_size.z;
            let mut s = [0f64; 5];
            for c in l.cells.packed() {
                for a in 0..5 {
                    s[a] += (c[a] * vol) as f64;
                }
            }
            s
        };
        // Level l averages level l − 1's decoded cells exactly (to f32) and codes them: every
        // value ≥ 0 within 2⁻¹² of itself, so each level's total within 2⁻¹² of the one above.
        let t0 = total(&p.levels[0]);
        for (li, l) in p.levels.iter().enumerate().skip(1) {
            let t = total(l);
            for a in 0..5 {
                let tol = (li as f64 / 4096.0 + 1e-5) * t0[a];
                assert!((t[a] - t0[a]).abs() <= tol, "level {:?}: {t:?} vs {t0:?}", l.dims);
            }
        }
    }

    /// The cell codec: each channel under its own scale (magnitudes 10⁻⁶ to 10⁶ apart) reads
    /// back within 2⁻¹² relative, zeros stay exactly 0, values far below their channel's largest
    /// (< 2⁻³⁰ of it) read 0, a channel of zeros reads 0, and 10 B a cell.
    #[test]
    fn cells_round_trip_each_channel_under_its_own_scale() {
        let n = 4000;
        let dims = [n, 1, 1];
        let index = Arc::new(FullIndex::build(dims, &vec![1.0; n]));
        let mut rng = crate::math::Rng::new(7, 3);
        let mag = [3e-6f32, 1.0, 7e5, 0.02, 0.0];
        let want: Vec<Cell> = (0..n)
            .map(|g| {
                let x = |a: usize| match g % 97 {
                    // Zeros, and values far below the channel's largest.
                    0 => 0.0,
                    1 => mag[a] * 2f32.powi(-31),
                    _ => mag[a] * (-20.0 * rng.uniform()).exp2(),
                };
                std::array::from_fn(x)
            })
            .collect();
        let cells = Cells::from_fn(index, |g| want[g]);
        assert_eq!(cells.bytes(), 10 * (n + 1));
        let mut worst = [0f32; 5];
        for (g, w) in want.iter().enumerate() {
            let c = cells.get(g);
            assert_eq!(c, cells.packed().nth(g).unwrap());
            for a in 0..5 {
                if g % 97 <= 1 {
                    assert_eq!(c[a], 0.0, "voxel {g} channel {a}: {} → {}", w[a], c[a]);
                } else if w[a] > 0.0 {
                    worst[a] = worst[a].max((c[a] - w[a]).abs() / w[a]);
                } else {
                    assert_eq!(c[a], 0.0);
                }
            }
        }
        for (a, w) in worst[..4].iter().enumerate() {
            assert!(*w <= 1.0 / 4096.0 && *w > 1.0 / 8192.0, "channel {a}: relative error {w}");
        }
        assert_eq!(worst[4], 0.0, "a channel of zeros");
        // Each channel's scale is its own: the code's top exponent at each channel's largest.
        for a in 0..4 {
            let k = Scaled16::exponent_for(f64::from(want.iter().map(|c| c[a]).fold(0.0, f32::max)));
            assert_eq!(cells.scale[a], Scaled16::scale(k), "channel {a}");
            assert_eq!(cells.high[a], 1.0, "channel {a}");
        }
    }

    /// Channels above 2³¹ (ρ·I0 under light of 1e10 to 1e30 W·m⁻²·sr⁻¹, a density of 1e12) read
    /// back within 2⁻¹² like any other: one f32 scale saturated them (1e10 read as ~4.3e9).
    #[test]
    fn cells_keep_channels_above_two_to_the_31() {
        let n = 500;
        let index = Arc::new(FullIndex::build([n, 1, 1], &vec![1.0; n]));
        let mag = [1e12f32, 1e10, 3e20, 1e30, 0.5];
        let want: Vec<Cell> = (0..n).map(|g| mag.map(|m| m * (1.0 + (g % 17) as f32 / 17.0))).collect();
        let cells = Cells::from_fn(index, |g| want[g]);
        for (g, w) in want.iter().enumerate() {
            let c = cells.get(g);
            for a in 0..5 {
                assert!((c[a] - w[a]).abs() <= w[a] / 4096.0, "voxel {g} channel {a}: {} vs {}", c[a], w[a]);
            }
        }
    }
}
