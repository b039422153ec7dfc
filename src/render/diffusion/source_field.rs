//! The `diffusion` gather's source term packed per voxel: [`crate::lit::LitVolume::source`]'s
//! rule (I0 and g·I1·ω density-weighted and clamped at 0, the sky and ground single scattering's
//! spherical harmonics density-weighted and clamped at 0, the sun through its transmittance at
//! voxel centres and the phase function), with every field one voxel needs in one record.
//!
//! The lit volume keeps each field in its own grid, so a sample locates its eight corners once per
//! field and evaluates the phase function and the SH basis of the (per-ray constant) view
//! direction again. Here a sample locates the corners once and blends one record per corner
//! (12 floats, 39 with the sky's harmonics; contiguous, vectorisable); what depends on the
//! direction only is computed once per ray ([`SourceField::along`]). Same values up to float
//! rounding (the blend order differs). The records are density-weighted, so they are stored only
//! at the full voxels (an empty corner reads the zero record): the field costs 48 B per full
//! voxel, not the 160 B per voxel of the cloud's box that a record per box voxel would take.

use crate::lighting::Sun;
use crate::lit::sunlight::SunGrid;
use crate::math::{Rgb, Trilinear, Vec3, SH_COEFFS};
use crate::medium::field16::Field16;
use crate::medium::sparse::{FullIndex, VoxelField};
use crate::medium::Medium;
use crate::optics::Optics;
use crate::par;
use std::sync::Arc;

/// Floats per band in a record without the sky's single scattering: ρ·I0, ρ·g·I1 (x, y, z).
const ANISO: usize = 4;
/// Floats per band with it: then ρ·g^l·L_lm (9).
const BAND: usize = ANISO + SH_COEFFS;
/// Degree of each SH coefficient ([`crate::math::sh9`] order).
const DEGREE: [i32; SH_COEFFS] = [0, 1, 1, 1, 2, 2, 2, 2, 2];

/// The density-weighted records, one per full voxel (zero at empty voxels, as ρ·X is): three
/// bands of `B` floats each, `B` = [`ANISO`] or [`BAND`] (the sky's harmonics only when they
/// exist, so the default record is 48 B).
#[derive(Clone, Debug)]
enum Records {
    Aniso(VoxelField<[f32; 3 * ANISO]>),
    WithSky(VoxelField<[f32; 3 * BAND]>),
}

/// One density-weighted record per full voxel (whatever the source at a point with non-zero
/// density interpolates from; an empty corner's record is zero) and the sun transmittance at
/// voxel centres (shared with stage 1, stored on the cloud's box).
#[derive(Clone, Debug)]
pub struct SourceField {
    /// Per band: ρ·max(I0, 0), ρ·g·I1 (W·m⁻²·sr⁻¹ per unit density), with the sky's single
    /// scattering ρ·g^l·L_lm of the reduced sky and ground radiance (W·m⁻²·sr⁻¹ per unit density).
    rec: Records,
    /// The sun's transmittance at voxel centres (unitless).
    sun_t: Arc<SunGrid>,
    dims: [usize; 3],
    optics: Optics,
    sun: Sun,
}

/// The source seen along one view direction.
pub struct RaySource<'a> {
    field: &'a SourceField,
    /// The direction the scattered light leaves in, towards the eye (unit).
    to_eye: Vec3,
    /// The SH basis of `to_eye`.
    y: [f32; SH_COEFFS],
    /// E_sun · p(ω_sun → to_eye) (W·m⁻²·sr⁻¹ per band).
    sun: Rgb,
}

impl SourceField {
    /// From I0 per voxel (W·m⁻²·sr⁻¹, `i0[band][voxel]`), the first moment I1 per band at each
    /// full voxel (`i1(grid index)`, W·m⁻²·sr⁻¹, evaluated once per record and kept only in it,
    /// in f32; `render.diffuse_anisotropy`), the SH projection of the reduced sky and ground
    /// radiance per voxel (`[band * 9 + lm]`, W·m⁻²·sr⁻¹; `render.sky_single_scattering`) and
    /// the sun transmittance at voxel centres, all on `m`'s grid.
    pub fn new(
        m: &Medium,
        i0: &[Field16; 3],
        i1: Option<&(dyn Fn(usize) -> [Vec3; 3] + Sync)>,
        sky_sh: Option<&VoxelField<[f32; 3 * SH_COEFFS]>>,
        sun_t: &Arc<SunGrid>,
        sun: &Sun,
    ) -> SourceField {
        let g = m.optics.phase.mean_cosine() as f32;
        let index = m.density.full_index();
        // Every input is stored on the medium's full voxels, so record r reads their packed
        // values r (no slot look-ups) and ρ of the r-th full voxel.
        let same = |f: &Arc<FullIndex>| Arc::ptr_eq(f, &index);
        assert!(
            i0.iter().all(|f| same(f.index())) && sky_sh.is_none_or(|f| same(f.index())),
            "the diffusion's fields are stored on the medium's full voxels"
        );
        let rho = m.density.packed();
        // I1 is evaluated at grid indices: the r-th full voxel's (8 B per full voxel while the
        // records are built).
        let mut grid = Vec::with_capacity(if i1.is_some() { index.count() } else { 0 });
        if i1.is_some() {
            // Sized up front: a collected list grew to 1.5 times its length.
            grid.extend(index.full_voxels());
        }
        let i1_of = |r: usize| i1.map(|f| f(grid[r]));
        // Bands of `b` floats: ρ·max(I0, 0), ρ·g·I1 (I1 of record r, `i1r`), then (if `b` =
        // BAND) ρ·g^l·L_lm.
        let fill = |r: usize, i1r: &Option<[Vec3; 3]>, b: usize, o: &mut [f32]| {
            let p = rho[r];
            o[0] = i0[b].packed_at(r).max(0.0) * p;
            if let Some(i1) = i1r {
                for ax in 0..3 {
                    o[1 + ax] = i1[b][ax] * p * g;
                }
            }
        };
        let rec = match sky_sh {
            None => Records::Aniso(packed_field(index, |r| {
                let mut rec = [0f32; 3 * ANISO];
                let i1r = i1_of(r);
                for (b, o) in rec.chunks_exact_mut(ANISO).enumerate() {
                    fill(r, &i1r, b, o);
                }
                rec
            })),
            Some(sh) => {
                let gl: [f32; SH_COEFFS] = std::array::from_fn(|k| g.powi(DEGREE[k]));
                let sh = sh.packed();
                Records::WithSky(packed_field(index, |r| {
                    let mut rec = [0f32; 3 * BAND];
                    let i1r = i1_of(r);
                    for (b, o) in rec.chunks_exact_mut(BAND).enumerate() {
                        fill(r, &i1r, b, o);
                        for k in 0..SH_COEFFS {
                            o[ANISO + k] = sh[r][b * SH_COEFFS + k] * gl[k] * rho[r];
                        }
                    }
                    rec
                }))
            }
        };
        SourceField {
            rec,
            sun_t: sun_t.clone(),
            dims: m.dims(),
            optics: m.optics,
            sun: sun.clone(),
        }
    }

    /// The source towards the eye along `to_eye` (unit).
    #[inline]
    pub fn along(&self, to_eye: Vec3) -> RaySource<'_> {
        RaySource {
            field: self,
            to_eye,
            y: crate::math::sh9(to_eye),
            sun: self.sun.irradiance * self.optics.sun_scatter(self.sun.dir, to_eye),
        }
    }
}

/// Voxels per task when the records are built.
const CHUNK: usize = 4096;

/// A field on `index` whose r-th full voxel holds `at(r)` and whose empty voxels read zero,
/// built in parallel.
fn packed_field<const N: usize>(index: Arc<FullIndex>, at: impl Fn(usize) -> [f32; N] + Sync) -> VoxelField<[f32; N]> {
    let mut slots = vec![[0.0; N]; index.count() + 1];
    par::for_chunks(&mut slots[1..], CHUNK, &|c, chunk| {
        for (i, s) in chunk.iter_mut().enumerate() {
            *s = at(c * CHUNK + i);
        }
    });
    VoxelField::from_slots(index, slots)
}

/// The records of `field` blended at the 8 corners of `t` (grid indices), one slot look-up each.
#[inline]
fn blend<const N: usize>(field: &VoxelField<[f32; N]>, t: &Trilinear) -> [f32; N] {
    let t = field.slots(t);
    let [fx, fy, fz] = t.f;
    let wx = [1.0 - fx, fx];
    let wy = [1.0 - fy, fy];
    let wz = [1.0 - fz, fz];
    let mut acc = [0f32; N];
    for (c, &s) in t.idx.iter().enumerate() {
        let w = wx[c & 1] * wy[(c >> 1) & 1] * wz[c >> 2];
        for (a, x) in acc.iter_mut().zip(field.at_slot(s)) {
            *a += w * x;
        }
    }
    acc
}

impl RaySource<'_> {
    /// The source J per unit extinction (W·m⁻²·sr⁻¹) at continuous grid voxel coordinates `v`
    /// where the trilinear density is `rho` > 0: a·(max(0, I0 + g·I1·ω) + max(0, Σ g^l L_lm Y_lm(ω)))
    /// + E·p·T_sun (see [`crate::lit`]).
    #[inline]
    pub fn at(&self, v: Vec3, rho: f32) -> Rgb {
        let f = self.field;
        let t = Trilinear::new(f.dims, v.to_array());
        // The same corners for the sun's transmittance, located again: taking them out of
        // `Trilinear::new`, which every march inlines, made `single`'s gather 7 % slower.
        let (lo, hi, fr) = Trilinear::corners(f.dims, v.to_array());
        let e = self.to_eye;
        let aniso = |o: &[f32]| o[0] + o[1] * e.x + o[2] * e.y + o[3] * e.z;
        let diffuse: [f32; 3] = match &f.rec {
            Records::Aniso(field) => {
                let acc = blend(field, &t);
                std::array::from_fn(|b| aniso(&acc[b * ANISO..]).max(0.0) / rho)
            }
            Records::WithSky(field) => {
                let acc = blend(field, &t);
                std::array::from_fn(|b| {
                    let o = &acc[b * BAND..(b + 1) * BAND];
                    let sky: f32 = o[ANISO..].iter().zip(&self.y).map(|(c, y)| c * y).sum();
                    (aniso(o).max(0.0) + sky.max(0.0)) / rho
                })
            }
        };
        f.optics.albedo * Rgb::from_array(diffuse) + self.sun * f.sun_t.trilinear_at_corners(lo, hi, fr)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diffusion::flux::{decode_band, FluxField};
    use crate::lighting::Sky;
    use crate::lit::sky_single::SkySingle;
    use crate::lit::LitVolume;
    use crate::math::Rng;
    use crate::medium::Grid3;

    /// The packed source against the lit volume's, at random points and view directions of an
    /// irregular cloud whose I0, I1, sky SH and sun transmittance are random (I0 and the SH
    /// partly negative, so both clamps act).
    #[test]
    fn packed_source_is_the_lit_volumes() {
        let dims = [9, 7, 8];
        let n = dims[0] * dims[1] * dims[2];
        let mut rng = Rng::new(3, 1);
        let mut g = Grid3::filled(dims, 0.0);
        for k in 1..dims[2] - 1 {
            for j in 2..dims[1] {
                for i in 1..dims[0] - 2 {
                    if rng.uniform() < 0.7 {
                        g.set(i, j, k, 0.1 + rng.uniform());
                    }
                }
            }
        }
        let m = Medium::new(
            g,
            Vec3::new(-3.0, 1.0, 2.0),
            Vec3::new(1.0, 0.7, 1.2),
            0.3,
            Rgb::new(0.9, 0.8, 0.99),
            0.6,
        );
        let mut r = || rng.uniform() * 2.0 - 0.5;
        let i0: [Vec<f32>; 3] = std::array::from_fn(|_| (0..n).map(|_| r()).collect());
        let i1: Vec<[Vec3; 3]> = (0..n).map(|_| std::array::from_fn(|_| Vec3::new(r(), r(), r()))).collect();
        let sh: Vec<[f32; 3 * SH_COEFFS]> = (0..n).map(|_| std::array::from_fn(|_| r())).collect();
        let sun_t = Grid3::from_vec(dims, (0..n).map(|_| r().abs().min(1.0)).collect(), "test").unwrap();
        let sun = Sun {
            dir: Vec3::new(0.3, 0.8, 0.5).normalize(),
            irradiance: Rgb::new(3.0, 2.5, 2.0),
        };
        let idx = m.density.full_index();
        // I0 as the solution holds it (16 bits), read the same by the lit volume.
        let i0f: [Field16; 3] = std::array::from_fn(|b| {
            let packed: Vec<f32> = idx.full_voxels().map(|g| i0[b][g]).collect();
            Field16::new(idx.clone(), &packed)
        });
        let i0_rgb: Vec<Rgb> = (0..n).map(|k| Rgb::new(i0f[0].get(k), i0f[1].get(k), i0f[2].get(k))).collect();
        let sh = VoxelField::from_fn(idx.clone(), [0.0; 3 * SH_COEFFS], |g| sh[g]);
        let flux = FluxField::new(&m, |g| i1[g]);
        // The records get the I1 the lit volume holds after its bf16 rounding of ρ·I1, so the two
        // differ by f32 rounding and the cells' 16-bit ρ·I0 only.
        let coded = flux.rho_i1().clone();
        let i1_held = |g: usize| coded[g].map(|b| decode_band(&b) / m.density.at(g));
        let lit = LitVolume::new(m.clone(), i0_rgb, sun_t.clone(), sun.clone(), Sky::constant(Rgb::ONE), None)
            .with_flux(flux)
            .with_sky_single(SkySingle::new(&m, &sh));
        let field = SourceField::new(&m, &i0f, Some(&i1_held), Some(&sh), &Arc::new(sun_t.clone().into()), &sun);
        let mut checked = 0;
        for _ in 0..2000 {
            let v = Vec3::new(rng.uniform() * 9.0, rng.uniform() * 7.0, rng.uniform() * 8.0);
            let rho = m.density.trilinear(v.to_array());
            if rho <= 0.0 {
                continue;
            }
            let to_eye = crate::math::uniform_sphere(rng.uniform(), rng.uniform());
            let (got, want) = (field.along(to_eye).at(v, rho), lit.source(v, rho, to_eye));
            // The lit volume's cells hold ρ·I0 in 16 bits (≤ 2⁻¹² relative a corner, all ≥ 0, so
            // its I0 within 2⁻¹² of itself; the clamp max(0, ·) does not enlarge a difference):
            // the source's diffuse term a·I0 may differ by that much beyond f32 rounding.
            let coded = m.optics.albedo * lit.i0(v, rho) / 4096.0;
            for c in 0..3 {
                assert!(
                    (got[c] - want[c]).abs() <= 1e-5 * want[c].abs() + 1e-6 + coded[c],
                    "{v:?} {to_eye:?} band {c}: {got:?} vs {want:?}"
                );
            }
            checked += 1;
        }
        assert!(checked > 1000);
    }
}
