//! A field per full voxel in 16 bits: [`Signed16`] codes relative to one power-of-two scale
//! ([`crate::half`]): I0, stage 1's sun light (ρT̄). Here, beside [`VoxelField`], so that
//! `half` (the codes) does not depend on `medium`.

use super::sparse::{FullIndex, VoxelField};
use crate::half::{code_after, Signed16};
use crate::par;
use std::sync::Arc;

/// Values per full voxel in [`Signed16`] relative to one scale 2ᵏ (module docs): 2 B per full
/// voxel. The scale is the power of two with max |v|·2⁻ᵏ in [1, 2 − 2⁻¹²), so the largest
/// value uses the top binade without saturating.
#[derive(Clone, Debug, PartialEq)]
pub struct Field16 {
    codes: VoxelField<Signed16>,
    /// 2ᵏ (decoding multiplies by it: exact, a power of two).
    scale: f32,
}

impl Field16 {
    /// The full voxels' values `packed` (in grid order, `index.count()` of them) coded
    /// ([`Signed16::code_all`]); empty voxels read 0.
    pub fn new<T: Copy + Into<f64> + Sync>(index: Arc<FullIndex>, packed: &[T]) -> Field16 {
        let (codes, scale) = code_after(packed, 1);
        Field16 {
            codes: VoxelField::from_slots(index, codes),
            scale,
        }
    }

    /// Every voxel reads 0.
    pub fn zero(index: Arc<FullIndex>) -> Field16 {
        Field16 {
            codes: VoxelField::filled(index, Signed16::default()),
            scale: 1.0,
        }
    }

    /// The value in slot `s` of the index (0: an empty voxel).
    #[inline]
    pub fn at_slot(&self, s: usize) -> f32 {
        self.codes.at_slot(s).to_f32() * self.scale
    }

    /// The value of grid voxel `g`.
    #[inline]
    pub fn get(&self, g: usize) -> f32 {
        self.at_slot(self.codes.index().slot(g))
    }

    /// The value of the `r`-th full voxel in grid order.
    #[inline]
    pub fn packed_at(&self, r: usize) -> f32 {
        self.at_slot(r + 1)
    }

    /// The full voxels' values decoded, in grid order (4 B per full voxel).
    pub fn decoded(&self) -> Vec<f32> {
        let codes = self.codes.packed();
        let mut out = vec![0f32; codes.len()];
        par::for_chunks(&mut out, par::CHUNK, &|ci, out| {
            for (o, c) in out.iter_mut().zip(&codes[ci * par::CHUNK..]) {
                *o = c.to_f32() * self.scale;
            }
        });
        out
    }

    /// Every grid voxel's value in grid order (empty voxels read 0).
    pub fn iter(&self) -> impl Iterator<Item = f32> + '_ {
        self.codes.iter().map(|c| c.to_f32() * self.scale)
    }

    /// The index the field is addressed by.
    #[inline]
    pub fn index(&self) -> &Arc<FullIndex> {
        self.codes.index()
    }

    /// The scale 2ᵏ the codes are relative to.
    pub fn scale(&self) -> f32 {
        self.scale
    }

    /// Bytes held by the codes (the index is shared and counted apart).
    pub fn bytes(&self) -> usize {
        self.codes.bytes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Rng;

    /// A field of `values` on full voxels 0..n of a 1-D grid.
    fn field16(values: &[f64]) -> Field16 {
        let dims = [values.len(), 1, 1];
        let index = Arc::new(FullIndex::build(dims, &vec![1.0; values.len()]));
        Field16::new(index, values)
    }

    #[test]
    fn field16_scale_is_the_power_of_two_of_its_largest_value() {
        for (max, want) in [
            (1.0, 1.0),
            (1.5, 1.0),
            (0.75, 0.5),
            (-3000.0, 2048.0),
            (1e-20, 2f32.powi(-67)),
            (2.0 - 1e-5, 2.0),
        ] {
            let f = field16(&[0.1 * max, max]);
            assert_eq!(f.scale(), want, "{max}");
            let r = f64::from(f.get(1));
            assert!((r - max).abs() <= max.abs() / 4096.0, "{max} → {r}");
        }
        assert_eq!(field16(&[0.0, 0.0]).scale(), 1.0);
        assert_eq!(Field16::zero(field16(&[1.0]).index().clone()).get(0), 0.0);
    }

    #[test]
    fn field16_is_within_two_to_minus_12_above_the_floor_at_any_scale() {
        let mut rng = Rng::new(11, 2);
        for scale in [1e-30f64, 1e-3, 1.0, 7.0e4, 1e30] {
            // Both signs, magnitudes over 12 binades below the largest, which is `scale`.
            let mut v: Vec<f64> = (0..5000)
                .map(|_| {
                    scale * (-12.0 * f64::from(rng.uniform()) * std::f64::consts::LN_2).exp() * if rng.uniform() < 0.3 { -1.0 } else { 1.0 }
                })
                .collect();
            v.push(scale);
            let f = field16(&v);
            let back = f.decoded();
            for (k, (a, r)) in v.iter().zip(&back).enumerate() {
                assert!((f64::from(*r) - a).abs() <= a.abs() / 4096.0, "{a} → {r}");
                assert_eq!(f.get(k), *r);
                assert_eq!(f.packed_at(k), *r);
            }
            assert!(f.iter().zip(&back).all(|(a, b)| a == *b));
            // Far below the largest: an absolute bound of 2⁻²⁵ of it.
            let g = field16(&[scale, scale * 1e-6, -scale * 3e-9, 0.0]);
            for (k, a) in [scale, scale * 1e-6, -scale * 3e-9, 0.0].into_iter().enumerate() {
                assert!((f64::from(g.get(k)) - a).abs() <= scale * 2f64.powi(-25) + a.abs() / 4096.0, "{a}");
            }
            assert_eq!(g.bytes(), 2 * 5);
        }
    }
}
