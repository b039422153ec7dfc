//! When the iteration stops, when it diverges, and the extrapolation of its slowest mode.

use super::grid::Ctx;
use super::BandOptics;

/// The slowest error mode seen in a history of changes: their last ratio and how far it is from
/// the ratio before.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct SlowMode {
    /// r: the change shrinks by r per iteration.
    pub(super) ratio: f64,
    /// |r − r_before|: how uncertain r is.
    pub(super) spread: f64,
}

impl SlowMode {
    /// The factor to add the last step with: the geometric tail r/(1 − r).
    pub(super) fn factor(self) -> f32 {
        (self.ratio / (1.0 - self.ratio)) as f32
    }
}

/// Extrapolation of the slowest error mode (Lyusternik's): once DSA has removed the diffusive
/// modes, the change shrinks geometrically, by r per iteration (≈ 0.6–0.78 measured: the
/// anisotropic orders DSA does not reach), so the remaining error is r/(1 − r) times the last step
/// ([`SlowMode::factor`]). When the last two ratios agree within [`RATIO_AGREEMENT`] and
/// r ∈ (0.3, 0.9), the mode; None otherwise (an erratic history is left alone). Both ratios must
/// be of changes made after the last extrapolation (at iteration `last`, 0 for none), so at most
/// every third iteration. Measured on the five evaluation scenes: 13/13/6/13/13 → 8/8/5/9/8
/// iterations, the same images within the tolerance (docs/transport.md, "Iteration and
/// acceleration").
pub(super) fn dominant_mode_step(history: &[f64], last: usize) -> Option<SlowMode> {
    let n = history.len();
    if n < 4 || n < last + 3 {
        return None;
    }
    let (r0, r1) = (history[n - 2] / history[n - 3], history[n - 1] / history[n - 2]);
    let spread = (r1 - r0).abs();
    (r1 > 0.3 && r1 < 0.9 && spread < RATIO_AGREEMENT).then_some(SlowMode { ratio: r1, spread })
}

/// How far apart the last two ratios of the change may be for [`dominant_mode_step`]. After an
/// extrapolation the first ratio is still the faster modes' (0.66, then 0.77 on the noon scene);
/// 0.15 extrapolates there a sweep earlier (noon, backlit, the default scene and the glare
/// sweep's sun090: 9 → 8 iterations), 0.2 changes nothing more, and the images stay within
/// 0.09 % of a solve at a 10× tighter tolerance.
const RATIO_AGREEMENT: f64 = 0.15;

/// A change of I_00 this many times the smallest since the iteration (re)started means the
/// acceleration amplifies: a converging iteration's change falls (erratically by at most ~2 on the
/// evaluation scenes), a diverging one's grows by orders of magnitude within a few iterations.
pub(super) const DIVERGENCE_FACTOR: f64 = 4.0;

/// The floor of the divisors of the relative changes: below every non-zero f32 (2⁻¹⁴⁹), so a
/// field of zeros divides to 0 (never NaN) while the dimmest light is still measured against
/// itself. The iteration is linear in the light: its stopping rule must not depend on the
/// light's units (a floor of 1e-30 stopped a scene lit at 1e-30 W/m² after one iteration).
const NO_LIGHT: f64 = f64::MIN_POSITIVE;

/// (max |ΔI_00|, max |I_00|) over the full voxels and bands (W·m⁻²·sr⁻¹): inf for the first
/// when either iterate holds a non-finite value (so a NaN is never read as "no change").
pub(super) fn i00_change(next: &[f32], moments: &[f32], nsh: usize) -> (f64, f64) {
    next.iter()
        .step_by(nsh)
        .zip(moments.iter().step_by(nsh))
        .fold((0.0f64, NO_LIGHT), |(c, m), (x, y)| {
            let d = (x - y).abs() as f64;
            (if d.is_finite() { c.max(d) } else { f64::INFINITY }, m.max(x.abs() as f64))
        })
}

/// Σ|ΔI_00| / Σ|I_00| over the full voxels and bands: the change where the cloud is, as the
/// image sees it (a mean), where [`i00_change`] sees the largest voxel's.
pub(super) fn i00_mean_change(next: &[f32], moments: &[f32], nsh: usize) -> f64 {
    let (d, m) = next
        .iter()
        .step_by(nsh)
        .zip(moments.iter().step_by(nsh))
        .fold((0.0f64, NO_LIGHT), |(d, m), (x, y)| (d + (x - y).abs() as f64, m + x.abs() as f64));
    if d.is_finite() { d / m } else { f64::INFINITY }
}

/// Whether plain source iteration (after the acceleration was given up) has converged: its
/// change falls by r per iteration with r → 1 on thick media, so the error left is about
/// r/(1 − r) times the last change, not the change itself (a change of 4.9·10⁻³ at r = 0.957
/// left 22 times that). `changes`: the relative changes since the restart.
pub(super) fn plain_converged(changes: &[f64], tolerance: f64) -> bool {
    match changes {
        [.., a, b] if b < a => b * (b / (a - b)).max(1.0) < tolerance,
        _ => false,
    }
}

/// The largest scaled optical depth of a full voxel along its thinnest axis, max ρ σt′ h.
pub(super) fn max_voxel_optical_depth(c: &Ctx, voxels: &[usize], bands: &[BandOptics]) -> f64 {
    let rho = voxels.iter().fold(0.0f64, |a, &v| a.max(c.rho.at(v) as f64));
    let st = bands.iter().fold(0.0f64, |a, b| a.max(b.sigma_t));
    rho * st * c.h.iter().copied().fold(f64::INFINITY, f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dominant_mode_step_extrapolates_only_a_steady_geometric_decay() {
        let geometric: Vec<f64> = (0..7).map(|i| 0.75f64.powi(i)).collect();
        // r = 0.75: the remaining error is 3 steps.
        let factor = |h: &[f64], last| dominant_mode_step(h, last).map(SlowMode::factor);
        assert!((factor(&geometric[..4], 0).unwrap() - 3.0).abs() < 1e-5);
        assert_eq!(dominant_mode_step(&geometric[..5], 4), None, "two ratios since the last one");
        assert_eq!(dominant_mode_step(&geometric[..6], 4), None);
        assert!((factor(&geometric[..7], 4).unwrap() - 3.0).abs() < 1e-5);
        assert!((factor(&geometric[..5], 0).unwrap() - 3.0).abs() < 1e-5);
        assert_eq!(dominant_mode_step(&[1.0, 0.5, 0.6, 0.3], 0), None, "erratic");
        // The noon scene's changes after its first extrapolation: ratios 0.66, then 0.77.
        let noon = [1.0, 0.277, 0.14, 0.0847, 0.0226, 0.015, 0.0116];
        assert!((factor(&noon, 4).unwrap() - 3.41).abs() < 0.01);
        let mode = dominant_mode_step(&noon, 4).unwrap();
        assert!((mode.ratio - 0.773).abs() < 1e-3 && (mode.spread - 0.11).abs() < 0.01, "{mode:?}");
        assert_eq!(dominant_mode_step(&[1.0, 0.5, 0.3, 0.24], 0), None, "ratios 0.6 and 0.8 disagree");
        assert_eq!(dominant_mode_step(&[1.0, 0.95, 0.9025, 0.857], 0), None, "too slow to trust");
        assert_eq!(dominant_mode_step(&[1.0, 0.1, 0.01, 0.001], 0), None, "fast already");
    }

    /// The relative changes do not depend on the light's units: the same iterates at 2⁻¹¹⁰ (the
    /// I_00 of a scene lit at ~1e-32 W/m²) give the same ratios, bit for bit; a field of zeros
    /// changes by 0.
    #[test]
    fn relative_changes_are_independent_of_the_light_scale() {
        let nsh = 3;
        let next: Vec<f32> = (0..30).map(|i| 0.5 + (i % 7) as f32 * 0.25).collect();
        let moments: Vec<f32> = next.iter().enumerate().map(|(i, x)| x * (1.0 + 0.01 * (i % 5) as f32)).collect();
        let scaled = |v: &[f32]| v.iter().map(|x| x * 2f32.powi(-110)).collect::<Vec<f32>>();
        let (c, m) = i00_change(&next, &moments, nsh);
        let (cs, ms) = i00_change(&scaled(&next), &scaled(&moments), nsh);
        assert!(c > 0.0);
        assert_eq!(c / m, cs / ms, "max change: {c}/{m} vs {cs}/{ms}");
        let mean = i00_mean_change(&next, &moments, nsh);
        assert!(mean > 0.0);
        assert_eq!(mean, i00_mean_change(&scaled(&next), &scaled(&moments), nsh));
        let zeros = vec![0.0f32; 30];
        let (c0, m0) = i00_change(&zeros, &zeros, nsh);
        assert_eq!(c0 / m0, 0.0);
        assert_eq!(i00_mean_change(&zeros, &zeros, nsh), 0.0);
    }
}
