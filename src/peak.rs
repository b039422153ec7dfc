//! The forward peak that a δ-M (similarity) transform takes out of the phase function, spread by
//! the peak scatterings on the sun's leg. δ-M writes HG as p = (1 − f) p′ + f P and carries the
//! peak P on in the beam, as if unscattered: the beam T′ = T^{1 − af} reaching a point holds the
//! light peak-scattered k times on its way, k Poisson with mean λ = af τ (τ the true optical
//! depth along the leg). Each peak scattering multiplies the light's Legendre moments by P's
//! moments χ_l, so the peak's scattering towards the eye, counted once as the last one, has the
//! moments f χ_l e^{−λ(1 − χ_l)} (the mean of χ_l^{k+1} under Poisson weights, with T′'s e^{λ}).
//! [`PeakSpread::spread`] is what that takes from f P = p − (1 − f) p′ at a given λ. Two
//! transforms use it: `transport`'s δ-M truncated after order L (χ_l = 1 for l ≤ L, g^{l−L−1}
//! beyond) and `full`'s forward fraction f with HG(g′) (χ_l = (g^l − (1 − f) g′^l)/f). In
//! `full`'s, χ_l < 1 where HG(g′) has orders too, so the smooth part (1 − f) HG(g′) is spread as
//! well: by the sun's leg's peak scatterings and by those on the eye's leg, which δ-M's T′ to the
//! eye carries as unscattered ([`PeakSpread::spread_split_with`]).

/// The Legendre series of a δ-M peak beyond the orders its transform keeps exactly.
pub struct PeakSpread {
    /// First order with χ_l < 1.
    first: usize,
    /// (2l + 1) f for l < first (χ_l = 1 there).
    low: Vec<f64>,
    /// (2l + 1) f χ_l for l = first.. (the peak's own part of the 4π-normalised series).
    weight: Vec<f64>,
    /// χ_l for l = first...
    moment: Vec<f64>,
    /// (2l + 1)(1 − f) g′^l for l = first.. (the smooth part's series at the same orders): empty
    /// where the peak is the identity on the smooth part's orders (`transport`'s truncation).
    smooth: Vec<f64>,
}

impl PeakSpread {
    /// `transport`'s δ-M of HG(g) truncated after order `order` (f = g^{L+1}).
    pub fn truncated(g: f64, order: usize) -> PeakSpread {
        // f χ_l = g^l, χ_l = g^{l−L−1} beyond L.
        Self::from_moments(g, order + 1, |l| g.powi(l as i32), |l| g.powi((l - order - 1) as i32))
    }

    /// `full`'s similarity transform: forward fraction `f`, HG(g′) with g′ = (g − f)/(1 − f) for
    /// what is left (f = 0: no peak).
    pub fn similarity(g: f64, f: f64) -> PeakSpread {
        if f <= 0.0 {
            return PeakSpread {
                first: 0,
                low: Vec::new(),
                weight: Vec::new(),
                moment: Vec::new(),
                smooth: Vec::new(),
            };
        }
        let gp = (g - f) / (1.0 - f);
        let f_chi = move |l: usize| g.powi(l as i32) - (1.0 - f) * gp.powi(l as i32);
        // χ_0 = χ_1 = 1 (δ-M keeps the normalisation and the mean cosine).
        let mut s = Self::from_moments(g, 2, f_chi, move |l| f_chi(l) / f);
        // P's χ_l < 1 from l = 2 on, where HG(g′) has orders too: the light peak-scattered on
        // either leg reaches the eye through the smooth part spread as well. Its series ends
        // sooner than the peak's (g′ < g): where (2l + 1)(1 − f) g′^l < 10⁻⁶.
        s.smooth = (0..s.weight.len())
            .map(|i| {
                let l = s.first + i;
                (2 * l + 1) as f64 * (1.0 - f) * gp.powi(l as i32)
            })
            .take_while(|w| w.abs() >= 1e-6)
            .collect();
        s
    }

    /// Orders from `first` until (2l + 1) g^l < 10⁻⁶ (at least 8 of them).
    fn from_moments(g: f64, first: usize, f_chi: impl Fn(usize) -> f64, chi: impl Fn(usize) -> f64) -> PeakSpread {
        let (mut weight, mut moment) = (Vec::new(), Vec::new());
        let mut l = first;
        while l < 20_000 {
            if (2 * l + 1) as f64 * g.abs().powi(l as i32) < 1e-6 && l >= first + 8 {
                break;
            }
            weight.push((2 * l + 1) as f64 * f_chi(l));
            moment.push(chi(l));
            l += 1;
        }
        PeakSpread {
            first,
            low: (0..first).map(|l| (2 * l + 1) as f64 * f_chi(l)).collect(),
            weight,
            moment,
            smooth: Vec::new(),
        }
    }

    /// The Legendre polynomials P_l(cos Θ) of this series' orders, for [`Self::spread_with`]
    /// (one ray, many points).
    pub fn legendre(&self, cos_theta: f64) -> Vec<f64> {
        let [p] = self.legendre_from(self.first, [cos_theta]);
        p
    }

    /// [`Self::legendre`] at `K` angles at once: the same values, the `K` recurrences side by
    /// side (each is a chain of dependent divisions, which then overlap).
    pub fn legendre_lanes<const K: usize>(&self, cos_theta: [f64; K]) -> [Vec<f64>; K] {
        self.legendre_from(self.first, cos_theta)
    }

    /// The Legendre polynomials P_l(cos Θ) from order 0 to this series' last, for
    /// [`Self::peak_with`].
    pub fn legendre_all(&self, cos_theta: f64) -> Vec<f64> {
        let [p] = self.legendre_from(0, [cos_theta]);
        p
    }

    /// P_l at each of `cos_theta` for l from `from` to this series' last order (Bonnet's
    /// recurrence, (l + 1) P_{l+1} = (2l + 1) x P_l − l P_{l−1}).
    fn legendre_from<const K: usize>(&self, from: usize, cos_theta: [f64; K]) -> [Vec<f64>; K] {
        let n = self.first + self.weight.len();
        let mut out: [Vec<f64>; K] = std::array::from_fn(|_| Vec::with_capacity(n.saturating_sub(from)));
        let (mut p0, mut p1) = ([1.0; K], cos_theta);
        for l in 0..n {
            let p = match l {
                0 => [1.0; K],
                1 => cos_theta,
                _ => {
                    let mut p2 = [0.0; K];
                    for k in 0..K {
                        p2[k] = ((2 * l - 1) as f64 * cos_theta[k] * p1[k] - (l - 1) as f64 * p0[k]) / l as f64;
                    }
                    (p0, p1) = (p1, p2);
                    p2
                }
            };
            if l >= from {
                for (o, pk) in out.iter_mut().zip(p) {
                    o.push(pk);
                }
            }
        }
        out
    }

    /// Σ_l (2l + 1) f χ_l e^{−λ(1 − χ_l)} P_l(cos Θ) (4π-normalised; χ_l = 1 below the first
    /// order), with `legendre` from [`Self::legendre_all`]: the peak f P scattering light that λ
    /// peak scatterings on the sun's leg have spread before (f P itself at λ = 0; its integral
    /// over the sphere is f whatever λ).
    pub fn peak_with(&self, lambda: f64, legendre: &[f64]) -> f64 {
        let low: f64 = self.low.iter().zip(legendre).map(|(w, p)| w * p).sum();
        let high: f64 = self
            .weight
            .iter()
            .zip(&self.moment)
            .zip(&legendre[self.first..])
            .map(|((w, m), p)| w * (-lambda * (1.0 - m)).exp() * p)
            .sum();
        low + high
    }

    /// Σ_l (2l + 1) f χ_l (e^{−λ(1 − χ_l)} − 1) P_l(cos Θ) (4π-normalised): what λ peak
    /// scatterings on the sun's leg take from the peak f P.
    pub fn spread(&self, lambda: f64, cos_theta: f64) -> f64 {
        if lambda <= 0.0 || self.weight.is_empty() {
            return 0.0;
        }
        self.spread_with(lambda, &self.legendre(cos_theta))
    }

    /// [`Self::spread`] with the P_l already evaluated ([`Self::legendre`]).
    pub fn spread_with(&self, lambda: f64, legendre: &[f64]) -> f64 {
        if lambda <= 0.0 {
            return 0.0;
        }
        self.weight
            .iter()
            .zip(&self.moment)
            .zip(legendre)
            .map(|((w, m), p)| w * ((-lambda * (1.0 - m)).exp() - 1.0) * p)
            .sum()
    }

    /// ([`Self::spread_with`], the same for the smooth part): the scattering towards the eye
    /// spread in both parts, f P by the `lambda_sun` peak scatterings on the sun's leg, and
    /// (1 − f) HG(g′) by those and the `lambda_eye` on the eye's leg: Σ_l (2l + 1)(1 − f) g′^l
    /// (e^{−(λ_sun + λ_eye)(1 − χ_l)} − 1) P_l(cos Θ) is what the smooth part loses (0 where the
    /// peak leaves the smooth part's orders alone, as `transport`'s does). The peak part is the
    /// last scattering before the eye (weighted by T_eye^{af}, no peak scattering after it), so
    /// only the sun's leg spreads it; the smooth part reaches the eye through δ-M's T′, which
    /// carries the light peak-scattered on the way as if unscattered: each of those scatterings
    /// multiplies the angular distribution's moments by χ_l, as on the sun's leg (small-angle
    /// spreads around the two legs' directions compose as a product of zonal kernels).
    pub fn spread_split_with(&self, lambda_sun: f64, lambda_eye: f64, legendre: &[f64]) -> (f64, f64) {
        let lambda_smooth = lambda_sun + lambda_eye;
        if lambda_smooth <= 0.0 {
            return (0.0, 0.0);
        }
        let smooth = self
            .smooth
            .iter()
            .zip(&self.moment)
            .zip(legendre)
            .map(|((w, m), p)| w * ((-lambda_smooth * (1.0 - m)).exp() - 1.0) * p)
            .sum();
        (smooth, self.spread_with(lambda_sun, legendre))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ½∫ Σ (2l+1) c_l P_l dμ = c_0: a spread moves the peak's light in angle but keeps it (its
    /// orders start at 2), and the mean cosine (orders ≥ 2 have no first moment either).
    #[test]
    fn a_spread_keeps_the_peaks_energy_and_mean_cosine_and_flattens_it() {
        let (x, w) = crate::transport::gauss_legendre(600);
        for s in [PeakSpread::truncated(0.9, 7), PeakSpread::similarity(0.9, 0.65)] {
            for lambda in [0.1, 1.0, 4.0] {
                let e: f64 = x.iter().zip(&w).map(|(x, w)| 0.5 * w * s.spread(lambda, *x)).sum();
                let mu: f64 = x.iter().zip(&w).map(|(x, w)| 0.5 * w * x * s.spread(lambda, *x)).sum();
                assert!(e.abs() < 1e-9 && mu.abs() < 1e-9, "λ {lambda}: {e} {mu}");
                // Less light straight ahead, more the further λ spreads it.
                assert!(s.spread(lambda, 1.0) < 0.0);
                assert!(s.spread(2.0 * lambda, 1.0) < s.spread(lambda, 1.0));
            }
            assert_eq!(s.spread(0.0, 0.7), 0.0);
        }
    }

    /// g = 0.9 split at f = 0.65: g, f, the smooth part's g′ and the peak's series.
    fn similarity_case() -> (f64, f64, f64, PeakSpread) {
        let (g, f) = (0.9, 0.65);
        (g, f, (g - f) / (1.0 - f), PeakSpread::similarity(g, f))
    }

    /// Henyey–Greenstein's phase function, 4π-normalised.
    fn hg(g: f64, cos: f64) -> f64 {
        (1.0 - g * g) / (1.0 + g * g - 2.0 * g * cos).powf(1.5)
    }

    /// The similarity transform's smooth part is spread too, keeping its energy and mean cosine:
    /// fully spread, the whole HG(g) (both parts) keeps only 1 + 3gμ, the light peak-scattered
    /// many times on the sun's leg having lost its direction beyond the first moment.
    #[test]
    fn a_similarity_spread_flattens_the_smooth_part_too_down_to_its_first_two_orders() {
        let (g, f, gp, s) = similarity_case();
        let (x, w) = crate::transport::gauss_legendre(600);
        for lambda in [0.5, 3.0] {
            let parts: Vec<(f64, f64)> = x.iter().map(|c| s.spread_split_with(lambda, 0.0, &s.legendre(*c))).collect();
            let e: f64 = parts.iter().zip(&w).map(|(p, w)| 0.5 * w * p.0).sum();
            let mu: f64 = parts.iter().zip(&w).zip(&x).map(|((p, w), x)| 0.5 * w * x * p.0).sum();
            assert!(e.abs() < 1e-9 && mu.abs() < 1e-9, "λ {lambda}: {e} {mu}");
            let (smooth, peak) = s.spread_split_with(lambda, 0.0, &s.legendre(1.0));
            assert!(smooth < 0.0 && (peak - s.spread(lambda, 1.0)).abs() < 1e-9 * peak.abs());
        }
        for c in [-0.9, 0.0, 0.5, 0.9] {
            let (smooth, peak) = s.spread_split_with(1e4, 0.0, &s.legendre(c));
            let left = hg(g, c) + smooth + peak;
            assert!((left - (1.0 + 3.0 * g * c)).abs() < 1e-5, "cos {c}: {left}");
            assert!((hg(gp, c) * (1.0 - f) + smooth - (1.0 - f) * (1.0 + 3.0 * gp * c)).abs() < 1e-5);
        }
        // The eye's leg spreads the smooth part as the sun's does, and the peak part not at all:
        // at λ_sun = 0 the peak is unspread, and the smooth part takes the two legs' sum.
        for c in [-0.5, 0.3, 0.95, 1.0] {
            let legendre = s.legendre(c);
            let (smooth, peak) = s.spread_split_with(0.0, 1.5, &legendre);
            assert_eq!(peak, 0.0);
            assert!((smooth - s.spread_split_with(1.5, 0.0, &legendre).0).abs() < 1e-12);
            let (smooth, peak) = s.spread_split_with(0.5, 1.0, &legendre);
            assert!((smooth - s.spread_split_with(1.5, 0.0, &legendre).0).abs() < 1e-12);
            assert!((peak - s.spread_split_with(0.5, 0.0, &legendre).1).abs() < 1e-12);
        }
        assert_eq!(s.spread_split_with(0.0, 0.0, &s.legendre(0.9)), (0.0, 0.0));
        // `transport`'s truncation leaves its smooth part (orders ≤ L) alone.
        let t = PeakSpread::truncated(0.9, 7);
        assert_eq!(t.spread_split_with(2.0, 1.0, &t.legendre(0.8)).0, 0.0);
    }

    /// The similarity transform's peak, p − (1 − f) HG(g′), is its series' sum at λ → ∞ taken
    /// away: f χ_l (e^{−∞} − 1) leaves only orders 0 and 1 of f P, i.e. f (1 + 3 μ).
    #[test]
    fn a_fully_spread_similarity_peak_keeps_only_its_first_two_orders() {
        let (g, f, gp, s) = similarity_case();
        for c in [-0.9, 0.0, 0.5, 0.9] {
            let peak = hg(g, c) - (1.0 - f) * hg(gp, c);
            let left = peak + s.spread(1e4, c);
            assert!((left - f * (1.0 + 3.0 * c)).abs() < 1e-5, "cos {c}: {left}");
        }
    }
}
