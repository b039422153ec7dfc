//! Adaptive angular resolution (after SHDOM's per-grid-point truncation of the source's
//! spherical-harmonic series, Evans 1998): each full voxel keeps its own order l_v ≤ L, and the
//! sweeps' source and moment steps run over its harmonics of l ≤ l_v only. In the optically
//! thick interior the radiance is nearly isotropic and a′χ′_l I_lm falls fast with l, so most
//! voxels keep a few orders of the L = 7 the edges need.
//!
//! After each iteration a voxel's order becomes one above the highest l at which a source term
//! is at least `tolerance` × I_00 in some band (|χ′_l I_lm| ≥ tolerance · |I_00|; a′ cancels),
//! at least 1 (the acceleration's current lives in l = 1) and at most L. The one order above
//! is the probe: its moments are accumulated, so a voxel whose radiance grows anisotropic
//! regains an order per iteration. Moments above a voxel's order are zero.

use rayon::prelude::*;

use super::BandOptics;
use crate::math::sh_count;

/// Default `render.transport_truncation` (docs/transport.md, "Adaptive angular resolution").
pub const DEFAULT_TRUNCATION: f64 = 1e-3;

/// Harmonics of l ≤ `order` in each part of the solver's parity order
/// ([`parity_order`](super::source::parity_order)): (even l, odd l). The sums of 2l + 1 over
/// l = p, p − 2, … are (p + 1)(p + 2)/2 with p the highest l of the parity.
#[inline(always)]
pub(super) fn kept(order: u8) -> (usize, usize) {
    let o = order as usize;
    let part = |p: usize| (p + 1) * (p + 2) / 2;
    let even = part(o - o % 2);
    let odd = if o == 0 { 0 } else { part(o - (1 - o % 2)) };
    (even, odd)
}

/// Index of (l, first m) inside its parity part: the harmonics of l′ < l of the same parity.
fn part_start(l: usize) -> usize {
    l * l.saturating_sub(1) / 2
}

/// Per full voxel, the SH order the sweeps evaluate and accumulate ([`kept`]).
pub(super) struct Orders {
    pub(super) of: Vec<u8>,
    /// The solver's order L (the most any voxel keeps).
    full: u8,
}

impl Orders {
    /// Every one of `voxels` full voxels at the solver's order `order`.
    pub(super) fn full(voxels: usize, order: usize) -> Orders {
        let full = u8::try_from(order).expect("the SH order fits a byte (render.transport_order ≤ 15)");
        Orders {
            of: vec![full; voxels],
            full,
        }
    }

    /// Back to the solver's order everywhere (a restart from zero).
    pub(super) fn reset(&mut self) {
        self.of.fill(self.full);
    }

    /// The orders for the next sweep from its moments `next` (per full voxel, band and harmonic
    /// in parity order, `nsh` each with `even` even ones), which were accumulated at these
    /// orders; the moments above each voxel's new order (and anything the extrapolation left
    /// above the old one) are set to zero. A `tolerance` of 0 keeps every order.
    pub(super) fn update(&mut self, next: &mut [f32], bands: &[BandOptics; 3], nsh: usize, even: usize, tolerance: f64) {
        if tolerance <= 0.0 {
            return;
        }
        let full = self.full;
        next.par_chunks_mut(3 * nsh).zip(self.of.par_iter_mut()).for_each(|(mom, order)| {
            let old = *order as usize;
            let highest = (1..=old)
                .rev()
                .find(|&l| significant(mom, bands, nsh, even, l, tolerance))
                .unwrap_or(0);
            let new = (highest + 1).clamp(1, full as usize);
            zero_above(mom, nsh, even, new.min(old), full as usize);
            *order = new as u8;
        });
    }

    /// Share of the order-L harmonics kept, over the voxels (1 with none).
    pub(super) fn kept_share(&self) -> f64 {
        let all = sh_count(self.full as usize) * self.of.len();
        let kept: usize = self.of.iter().map(|o| sh_count(*o as usize)).sum();
        if all == 0 {
            1.0
        } else {
            kept as f64 / all as f64
        }
    }
}

/// Whether some band's source term of degree `l` is at least `tolerance` × its I_00.
fn significant(mom: &[f32], bands: &[BandOptics; 3], nsh: usize, even: usize, l: usize, tolerance: f64) -> bool {
    let start = if l % 2 == 0 { 0 } else { even } + part_start(l);
    bands.iter().enumerate().any(|(b, bo)| {
        let m = &mom[b * nsh..(b + 1) * nsh];
        let bound = tolerance * (m[0] as f64).abs();
        let chi = bo.chi[l].abs();
        m[start..start + 2 * l + 1].iter().any(|x| chi * (*x as f64).abs() >= bound && *x != 0.0)
    })
}

/// Zero a voxel's moments of l > `keep` (up to `full`), every band.
fn zero_above(mom: &mut [f32], nsh: usize, even: usize, keep: usize, full: usize) {
    let (ke, ko) = kept(keep as u8);
    let (fe, fo) = kept(full as u8);
    for b in 0..3 {
        let m = &mut mom[b * nsh..(b + 1) * nsh];
        m[ke..fe].fill(0.0);
        m[even + ko..even + fo].fill(0.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transport::source::parity_order;

    #[test]
    fn kept_counts_the_parity_parts_of_each_order() {
        let l_of = |k: usize| (k as f64).sqrt().floor() as usize;
        let (perm, ne) = parity_order(7);
        for order in 0..=7u8 {
            let (e, o) = kept(order);
            assert!(perm[..e].iter().all(|k| l_of(*k) <= order as usize), "order {order}");
            assert!(perm[e..ne].iter().all(|k| l_of(*k) > order as usize), "order {order}");
            assert!(perm[ne..ne + o].iter().all(|k| l_of(*k) <= order as usize), "order {order}");
            assert!(perm[ne + o..].iter().all(|k| l_of(*k) > order as usize), "order {order}");
            assert_eq!(e + o, sh_count(order as usize));
        }
        for l in 0..=7 {
            let start = if l % 2 == 0 { 0 } else { ne } + part_start(l);
            assert_eq!(l_of(perm[start]), l);
            assert!(start == 0 || l_of(perm[start - 1]) != l);
        }
    }

    #[test]
    fn a_voxel_keeps_one_order_above_its_highest_significant_term() {
        let order = 7;
        let nsh = sh_count(order);
        let (perm, ne) = parity_order(order);
        let bands = [0, 1, 2].map(|_| BandOptics::delta_m(1.0, 0.99, 0.5, order));
        let inner = |k: usize| perm.iter().position(|p| *p == k).unwrap();
        // Per voxel I_00 = 1 in every band, and: voxel 0 a term of 0.1 at l = 3 in band 1
        // (a′χ′_3 · 0.1 above 1e-3: significant, order 4); voxel 1 the same at 1e-5 (below: the
        // floor, order 1); voxel 2 a term at l = 7 (stays at 7).
        let mut mom = vec![0f32; 3 * 3 * nsh];
        for v in 0..3 {
            for b in 0..3 {
                mom[(v * 3 + b) * nsh] = 1.0;
            }
        }
        mom[nsh + inner(11)] = 0.1;
        mom[(3 + 1) * nsh + inner(11)] = 1e-5;
        mom[(6 + 2) * nsh + inner(60)] = 0.5;
        let mut o = Orders::full(3, order);
        o.update(&mut mom, &bands, nsh, ne, 1e-3);
        assert_eq!(o.of, vec![4, 1, 7]);
        assert_eq!(o.kept_share(), (25 + 4 + 64) as f64 / (3 * 64) as f64);
        assert_eq!(mom[(3 + 1) * nsh + inner(11)], 0.0, "the dropped term is zeroed");
        assert_eq!(mom[nsh + inner(11)], 0.1, "the kept term is kept");
        // A probe order regains one order per update once its term becomes significant.
        mom[(3 + 1) * nsh + inner(3)] = 0.5;
        o.update(&mut mom, &bands, nsh, ne, 1e-3);
        assert_eq!(o.of[1], 2);
        // Tolerance 0 keeps every order.
        let mut all = Orders::full(3, order);
        all.update(&mut mom, &bands, nsh, ne, 0.0);
        assert_eq!(all.of, vec![7, 7, 7]);
    }
}
