//! The last iterate's moments I_lm as the next sweep reads them: 16-bit codes ([`Signed16`]: sign,
//! 11-bit mantissa) under one power-of-two scale per band, chosen from the band's largest
//! magnitude. Relative rounding ≤ 2⁻¹² for every coefficient above 2⁻¹³ of that largest,
//! absolute ≤ 2⁻²⁵ of it below: a perturbation of the source 20× below the iteration's default
//! tolerance (5·10⁻³ of the largest I_00), at half the bytes of f32 (docs/transport.md, "Storage").
//! The sweep's new moments are summed in f32 (8 batches add into them), and the converged field
//! is handed on in f32.

use crate::half::{power_of_two_scale, Signed16};
use rayon::prelude::*;

/// Moments per full voxel, band and harmonic (the solver's order), coded.
pub(super) struct Moments16 {
    codes: Vec<Signed16>,
    /// The decoding scale 2ᵏ per band (W·m⁻²·sr⁻¹).
    scale: [f32; 3],
    /// Harmonics per band.
    nsh: usize,
}

impl Moments16 {
    /// `values` (per full voxel, band and harmonic; `nsh` harmonics per band), coded.
    pub(super) fn of(values: &[f32], nsh: usize) -> Moments16 {
        let mut m = Moments16 {
            codes: vec![Signed16::default(); values.len()],
            scale: [1.0; 3],
            nsh,
        };
        m.store(values);
        m
    }

    /// Replace the codes by those of `values` (same length), each band under the scale of its
    /// largest magnitude.
    pub(super) fn store(&mut self, values: &[f32]) {
        let nsh = self.nsh;
        assert_eq!(values.len(), self.codes.len(), "moments of the same full voxels");
        let max = values
            .par_chunks(3 * nsh)
            .map(|v| [0, 1, 2].map(|b| v[b * nsh..(b + 1) * nsh].iter().fold(0f32, |m, x| m.max(x.abs()))))
            .reduce(|| [0f32; 3], |a, b| [0, 1, 2].map(|k| a[k].max(b[k])));
        self.scale = max.map(|m| power_of_two_scale(m as f64));
        // 2⁻ᵏ is exact (k within f32's normal exponents), so v·2⁻ᵏ is the value the code rounds.
        let inv = self.scale.map(|s| 1.0 / s);
        self.codes
            .par_chunks_mut(3 * nsh)
            .zip(values.par_chunks(3 * nsh))
            .for_each(|(c, v)| {
                for (k, (ck, vk)) in c.iter_mut().zip(v).enumerate() {
                    *ck = Signed16::from_f32(vk * inv[k / nsh]);
                }
            });
    }

    /// Coefficient `i` (full voxel × 3·nsh + band × nsh + harmonic).
    #[inline]
    pub(super) fn get(&self, i: usize) -> f32 {
        self.codes[i].to_f32() * self.scale[(i / self.nsh) % 3]
    }

    /// I_00 of every full voxel and band, in order.
    pub(super) fn i00(&self) -> impl Iterator<Item = f32> + '_ {
        self.codes.iter().step_by(self.nsh).enumerate().map(|(j, c)| c.to_f32() * self.scale[j % 3])
    }

    /// The codes of every full voxel in order, 3·nsh each.
    pub(super) fn codes(&self) -> &[Signed16] {
        &self.codes
    }

    /// One voxel's codes (`codes`, 3·nsh) decoded into `out`.
    #[inline(always)]
    pub(super) fn decode_voxel(&self, codes: &[Signed16], out: &mut [f32]) {
        let nsh = self.nsh;
        for (b, (o, c)) in out.chunks_exact_mut(nsh).zip(codes.chunks_exact(nsh)).enumerate() {
            let s = self.scale[b];
            for (ok, ck) in o.iter_mut().zip(c) {
                *ok = ck.to_f32() * s;
            }
        }
    }

    /// Coefficients stored.
    pub(super) fn len(&self) -> usize {
        self.codes.len()
    }

    /// Harmonics per band.
    pub(super) fn nsh(&self) -> usize {
        self.nsh
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_keep_each_band_to_its_stated_bound() {
        // Two voxels, nsh = 4; the bands' scales differ by 10⁶, and a band of zeros.
        let v = [
            1.0f32, -0.25, 3e-3, 0.0, 2e6, 1.5e6, -7e5, 1.0, 0.0, 0.0, 0.0, 0.0, //
            0.5, 1e-9, -0.9, 0.125, 1.2e6, 3.0, 0.0, -2e6, 0.0, 0.0, 0.0, 0.0,
        ];
        let m = Moments16::of(&v, 4);
        assert_eq!((m.len(), m.nsh()), (24, 4));
        let largest = [1.0f32, 2e6, 0.0];
        let mut dec = [0f32; 12];
        for f in 0..2 {
            m.decode_voxel(&m.codes()[f * 12..(f + 1) * 12], &mut dec);
            for k in 0..12 {
                let (want, got) = (v[f * 12 + k], m.get(f * 12 + k));
                assert_eq!(got.to_bits(), dec[k].to_bits());
                let band_max = largest[k / 4];
                let bound = if want.abs() >= band_max / 8192.0 {
                    want.abs() / 4096.0
                } else {
                    band_max / 33_554_432.0
                };
                assert!((got - want).abs() <= bound, "{want} read {got}");
            }
        }
        // Zero stays zero exactly, and storing again replaces the codes.
        assert_eq!(m.get(8), 0.0);
        assert!(m.i00().eq([0, 4, 8, 12, 16, 20].map(|i| m.get(i))));
        let mut m = m;
        m.store(&[0.0; 24]);
        assert!((0..24).all(|i| m.get(i) == 0.0));
    }
}
