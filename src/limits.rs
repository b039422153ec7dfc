//! The magnitudes a scene may hold: past them f32 arithmetic in the methods overflows or loses
//! the voxels. Scene validation, the loaders and the lighting check against them.

/// Largest light the scene may carry, in W/m² (sun irradiance) or W/(m²·sr) (sky radiance, an
/// environment map's scale on its radiance): 1e30, the brightest sun every method is tested to
/// render finitely (src/tests/nonnegative.rs). The methods multiply it by phase-function peaks (up to
/// ~1e4 sr⁻¹) and sum it over orders and samples in f32, whose largest value is 3.4e38, so a
/// brighter light overflows to inf or NaN; the real sun gives 1361 W/m².
pub const MAX_LIGHT: f32 = 1e30;

/// Largest distance from the world's origin of the medium's corner and the camera (m): 1e7, past
/// the Earth's radius (6.4e6 m). An f32 position there resolves 1 m, a fraction of any voxel;
/// much farther, ray–box intersections lose the voxels and the methods give NaN.
pub const MAX_COORDINATE: f32 = 1e7;

/// Largest extinction σt (m⁻¹): 1e9, an optical depth of 1 per nanometre, denser than any medium
/// light crosses. The optical depths σt·ρ·length the methods form in f32 then stay below 1e30
/// across any grid of at most 1e6-m voxels with densities up to 1e15.
pub const MAX_SIGMA_T: f32 = 1e9;

/// Largest density a grid may hold (unitless, in units of `medium.sigma_t`): 1e30. Only the
/// product σt·ρ is physical, but the methods also form density products and sums on their own
/// (weights ρ·X and trilinear(ρ), squared densities, 16-bit codes of ρ-weighted fields) in f32:
/// a grid at 1e38 overflows them (`full` and `transport` give inf, NaN or a 27 % error at 1e37).
pub const MAX_DENSITY: f32 = 1e30;

/// Largest product of a grid's largest density and the brightest light (sun irradiance or sky
/// radiance): 1e33, [`MAX_LIGHT`] at densities up to 1000 (a uint8 grid read by value under the
/// brightest sun). Each bound alone is not enough: the methods weight light by density in f32
/// (ρ·I0, ρ·Q), so a grid of 1e20 under light of 3e20 (product 3e40) gives inf or NaN in
/// `diffusion`, `full` and `transport`, and 1e12 under 3e26 (3e38) in `full`; products up to 3e36
/// render in proportion, and 1e34 with g = 0.999 seen against the sun (its phase peak 1.6e5
/// sr⁻¹) rendered finitely.
pub const MAX_DENSITY_TIMES_LIGHT: f64 = 1e33;

/// Smallest non-zero extinction σt (m⁻¹): 1e-30. Below f32's normal range (1.2e-38) a σt
/// carries fewer bits and its products underflow; a medium that thin across the largest grid
/// (1e6-m voxels, densities up to [`MAX_DENSITY`]) is still described above it.
pub const MIN_SIGMA_T: f32 = 1e-30;

/// Largest |exposure| of the PNG preview (stops): 2^64 spans any radiance from 1e-19 to 1e19;
/// past 2^127 the f32 scale factor itself overflows.
pub const MAX_EXPOSURE: f32 = 64.0;

/// Longest duration a setting may give (s): 1e9, about 32 years, longer than any render runs.
/// A deadline far past it overflows the clock (`Instant + Duration` panics past ~1.8e19 s), and
/// one near it is no limit at all.
pub const MAX_SECONDS: f64 = 1e9;

/// A duration `s` (seconds) as messages write it: `15 s`, `0.25 s`, and `1e-300 s` rather than
/// 300 digits of `0.000…1`.
pub fn seconds_text(s: f64) -> String {
    match (1e-3..1e7).contains(&s.abs()) || s == 0.0 {
        true => format!("{s} s"),
        false => format!("{s:e} s"),
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_duration_reads_as_written_not_as_hundreds_of_digits() {
        assert_eq!(super::seconds_text(15.0), "15 s");
        assert_eq!(super::seconds_text(0.25), "0.25 s");
        assert_eq!(super::seconds_text(1e-9), "1e-9 s");
        assert_eq!(super::seconds_text(1e300), "1e300 s");
    }
}
