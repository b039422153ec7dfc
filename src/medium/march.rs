//! Front-to-back ray marching through the medium with empty-space skipping: the shared core of
//! every gather. Each step treats ρ as constant over its sub-interval (sampled at a jittered
//! point), which makes the compositing exact for piecewise-constant media and unconditionally
//! stable for optically thick steps: a sub-interval of optical depth δ adds
//! T·(1 − e^{−δ})·S, where S is the source per unit extinction (radiance), and multiplies T by e^{−δ}.

use crate::math::{Rgb, Vec3};
use crate::medium::Medium;
use std::ops::{AddAssign, Mul};

/// Transmittance below which a march stops (its remaining contribution is below this fraction).
pub const T_CUTOFF: f32 = 1e-6;

/// Result of a march: `S` the radiance's type (one [`Rgb`], or several layers marched at once).
#[derive(Clone, Copy, Debug)]
pub struct March<S = Rgb> {
    /// Radiance gathered in the medium (W·m⁻²·sr⁻¹).
    pub radiance: S,
    /// Transmittance of the whole marched interval (0 if cut off).
    pub transmittance: f32,
}

/// March `o + t·d` for t ∈ [t_min, t_max] with steps of at most `step_m` metres, sampling each
/// sub-interval at fraction `xi` ∈ [0, 1). `source(p_voxel, rho)` returns S (W·m⁻²·sr⁻¹) at a
/// point given in continuous voxel coordinates with density ρ > 0.
#[inline]
pub fn march(m: &Medium, o: Vec3, d: Vec3, t_min: f32, t_max: f32, step_m: f32, xi: f32, mut source: impl FnMut(Vec3, f32) -> Rgb) -> March {
    march_with(m, |v| m.density.trilinear(v), o, d, t_min, t_max, step_m, xi, |v, rho, _| source(v, rho))
}

/// [`march`] with ρ at continuous voxel coordinates (clamped to the box) from `rho`, which must
/// give the medium's trilinear density (e.g. from [`Medium::dense_density`], the same bits), and
/// the source also given the transmittance from `o` to its sample point (`source(p_voxel, rho,
/// t)`), for a source that depends on how much of the medium lies between it and the eye. The
/// source may be several radiances at once (`S`, e.g. an image's layers), each composited as one
/// [`Rgb`] alone would be (the same bits).
#[inline]
pub fn march_with<S: Copy + Default + AddAssign + Mul<f32, Output = S>>(
    m: &Medium,
    rho: impl Fn([f32; 3]) -> f32,
    o: Vec3,
    d: Vec3,
    t_min: f32,
    t_max: f32,
    step_m: f32,
    xi: f32,
    mut source: impl FnMut(Vec3, f32, f32) -> S,
) -> March<S> {
    let mut out = March {
        radiance: S::default(),
        transmittance: 1.0,
    };
    let Some((t0, t1)) = m.intersect(o, d, t_min, t_max) else {
        return out;
    };
    let dims = m.dims();
    let inv_h = Vec3::ONE / m.voxel_size;
    let sigma_t = m.optics.sigma_t;
    let mut t_acc = 1.0f32;
    let mut l = S::default();
    m.majorant.for_each_block(m, o, d, t0, t1, |ta, tb, maj| {
        if maj <= 0.0 {
            return true;
        }
        let n = ((tb - ta) / step_m).ceil().max(1.0);
        let len = (tb - ta) / n;
        for k in 0..n as u32 {
            let t = ta + (k as f32 + xi) * len;
            let v = ((o + d * t) - m.origin) * inv_h;
            let v = v.clamp(Vec3::ZERO, Vec3::new(dims[0] as f32, dims[1] as f32, dims[2] as f32));
            let rho = rho(v.to_array());
            if rho <= 0.0 {
                continue;
            }
            let delta = sigma_t * rho * len;
            let e = (-delta).exp();
            // (The transmittance to the sample is unused by most sources, and then not computed.)
            l += source(v, rho, t_acc * (-delta * xi).exp()) * (t_acc * (1.0 - e));
            t_acc *= e;
            if t_acc < T_CUTOFF {
                t_acc = 0.0;
                return false;
            }
        }
        true
    });
    out.radiance = l;
    out.transmittance = t_acc;
    out
}
