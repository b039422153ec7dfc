//! Henyey–Greenstein sampling, tested as pbrt-v4 and Mitsuba 3 test their samplers: a chi-square
//! goodness-of-fit test of sampled directions against the density integrated over a grid of
//! (cosθ, φ) cells, plus the sample mean cosine against g.

use crate::math::{Frame, Rng, Vec3};
use crate::optics::Hg;

/// ln Γ(x) (Lanczos, g = 7), accurate to ~1e-14 for x > 0.
fn ln_gamma(x: f64) -> f64 {
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + 7.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// Upper regularised incomplete gamma Q(a, x) (Numerical Recipes: series / continued fraction).
fn gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    if x < a + 1.0 {
        let (mut sum, mut del, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..10_000 {
            ap += 1.0;
            del *= x / ap;
            sum += del;
            if del.abs() < sum.abs() * 1e-15 {
                break;
            }
        }
        1.0 - sum * (-x + a * x.ln() - ln_gamma(a)).exp()
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-15 {
                break;
            }
        }
        (-x + a * x.ln() - ln_gamma(a)).exp() * h
    }
}

/// p-value of a chi-square statistic with `dof` degrees of freedom.
fn chi2_p_value(stat: f64, dof: usize) -> f64 {
    gamma_q(dof as f64 / 2.0, stat / 2.0)
}

/// Chi-square test of `sample_hg` for one g: 10 × 20 (cosθ, φ) cells around a tilted axis,
/// expected counts from the exact CDF in cosθ (φ uniform), cells with expectation < 5 pooled.
fn chi2_hg(g: f32, n: usize, seed: u64) -> f64 {
    chi2_hg_against(g, g, n, seed)
}

/// As [`chi2_hg`], sampling with `g_sample` and testing against the density for `g`.
fn chi2_hg_against(g_sample: f32, g: f32, n: usize, seed: u64) -> f64 {
    let (nt, np) = (10usize, 20usize);
    let axis = Vec3::new(0.3, -0.5, 0.8).normalize();
    let frame = Frame::from_normal(axis);
    let mut rng = Rng::new(seed, 99);
    let mut counts = vec![0f64; nt * np];
    // cosθ bands squeezed towards the forward peak by a cubic map, so strongly forward-peaked g
    // still spreads its counts over many cells.
    let edge = |i: usize| -> f64 { 1.0 - 2.0 * (1.0 - i as f64 / nt as f64).powi(3) };
    for _ in 0..n {
        let d = sample_hg(axis, g_sample, rng.uniform(), rng.uniform());
        let (x, y, z) = (d.dot(frame.t) as f64, d.dot(frame.b) as f64, d.dot(axis) as f64);
        let it = (0..nt).find(|&i| z <= edge(i + 1)).unwrap_or(nt - 1);
        let phi = y.atan2(x).rem_euclid(2.0 * std::f64::consts::PI);
        let ip = ((phi / (2.0 * std::f64::consts::PI) * np as f64) as usize).min(np - 1);
        counts[it * np + ip] += 1.0;
    }
    // Exact probability of each cosθ band by fine integration of the f64 density.
    let band = |a: f64, b: f64| -> f64 {
        let m = 2000;
        let h = (b - a) / m as f64;
        (0..m).map(|k| Hg::new(g).eval_cos_f64(a + (k as f64 + 0.5) * h)).sum::<f64>() * h * 2.0 * std::f64::consts::PI
    };
    let mut expected = Vec::with_capacity(nt * np);
    for it in 0..nt {
        let p = band(edge(it), edge(it + 1));
        expected.extend(std::iter::repeat_n(p * n as f64 / np as f64, np));
    }
    // Pool cells with small expectation (the usual chi-square validity rule).
    let (mut stat, mut dof, mut pool_o, mut pool_e) = (0.0, 0usize, 0.0, 0.0);
    for (o, e) in counts.iter().zip(&expected) {
        if *e < 5.0 {
            pool_o += o;
            pool_e += e;
        } else {
            stat += (o - e) * (o - e) / e;
            dof += 1;
        }
    }
    if pool_e > 0.0 {
        stat += (pool_o - pool_e) * (pool_o - pool_e) / pool_e.max(1e-12);
        dof += 1;
    }
    chi2_p_value(stat, dof - 1)
}

#[test]
fn chi2_machinery_is_right() {
    // Known values: Q(1, x) = e^{−x}; chi-square with 2 dof at 5.991 has p = 0.05.
    assert!((gamma_q(1.0, 2.0) - (-2.0f64).exp()).abs() < 1e-12);
    assert!((chi2_p_value(5.991, 2) - 0.05).abs() < 1e-4);
    assert!((chi2_p_value(18.307, 10) - 0.05).abs() < 1e-4);
    assert!((chi2_p_value(149.449, 100) - 0.001).abs() < 2e-5);
}

#[test]
fn hg_sampling_passes_chi_square() {
    // Significance 0.01 with a Šidák correction over the 7 tests (as pbrt-v4).
    let gs = [-0.7f32, -0.2, 0.0, 0.3, 0.6, 0.9, 0.97];
    let alpha = 1.0 - (1.0f64 - 0.01).powf(1.0 / gs.len() as f64);
    for (i, &g) in gs.iter().enumerate() {
        let p = chi2_hg(g, 200_000, i as u64);
        assert!(p > alpha, "g = {g}: chi-square p-value {p} < {alpha}");
    }
}

#[test]
fn chi_square_detects_a_wrong_sampler() {
    // The same test must reject a sampler for a slightly different g, or it proves nothing.
    let p = chi2_hg_against(0.63, 0.6, 200_000, 1);
    assert!(p < 1e-6, "g 0.63 sampled, 0.6 expected: p = {p}");
    let p = chi2_hg_against(0.9, 0.88, 200_000, 2);
    assert!(p < 1e-6, "g 0.9 sampled, 0.88 expected: p = {p}");
}

#[test]
fn sampled_mean_cosine_is_g() {
    let mut rng = Rng::new(17, 3);
    for &g in &[-0.5f32, 0.0, 0.5, 0.9, 0.99] {
        let n = 200_000;
        let axis = Vec3::new(-0.2, 0.9, 0.1).normalize();
        let (mut s, mut s2) = (0.0f64, 0.0f64);
        for _ in 0..n {
            let c = sample_hg(axis, g, rng.uniform(), rng.uniform()).dot(axis) as f64;
            s += c;
            s2 += c * c;
        }
        let mean = s / n as f64;
        let se = ((s2 / n as f64 - mean * mean) / n as f64).sqrt();
        // 4 standard errors + float rounding of the f32 sampler.
        assert!((mean - g as f64).abs() < 4.0 * se + 1e-4, "g = {g}: mean cosine {mean} ± {se}");
    }
}

/// An HG-distributed direction after scattering from `dir`.
fn sample_hg(dir: Vec3, g: f32, u1: f32, u2: f32) -> Vec3 {
    Hg::new(g).sample(dir, u1, u2)
}
