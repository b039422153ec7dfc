//! The light entering the cloud through the diffusion's boundary (`render.sky_boundary`).
//!
//! # Why
//!
//! The paper splits the sky's light into the reduced part I_ri, propagated by stage 1 and left out
//! of I0, and the diffuse part I0 + I1·ω, which starts with no inward flux at the boundary (eq. 7).
//! Near the surface — the layer the eye sees — that split is poor: for a half-space of albedo 1
//! under a uniform sky of radiance 1 (the exact radiance is 1 everywhere), the P1 field of the
//! split gives I0(τ) = 1 − (3/2)E₄(τ) and Ī_ri = E₂(τ)/2, so the mean radiance I0 + Ī_ri is 1 at the
//! surface and deep inside but 0.87 at τ = 0.5 and 0.94 at τ = 1 (Eₙ the exponential integrals),
//! and with that split the gather's images are 12–14 % too dark in the furnace (docs/budget.md).
//!
//! # What
//!
//! With the switch on, stage 1 propagates the sun only, and the sky and ground light enter as the
//! incoming radiance of eq. 7's Marshak condition on every boundary face of the cloud:
//!
//! ```text
//!   ∫_{ω·n_in > 0} I (ω·n_in) dω = ∫_{ω·n_in > 0} L_in (ω·n_in) dω = π L_face
//!   ⇒ I0 − (2/(3ρσtr)) n_in·∇I0 + (2/(ρσtr)) n_in·Q1 = L_face
//! ```
//!
//! L_face is the cosine-weighted mean radiance arriving at the face from its outer hemisphere.
//! The solver's ghost value then gives the face's outward flux (β(I_P − L_face) + f)/(1 + 2β),
//! the eq. 7 flux of [`super`] with I_P − L_face in place of I_P. A uniform sky over an albedo-1
//! cloud gives I0 = L exactly (every term vanishes), which is the furnace's exact answer.
//!
//! Without clear-air cubes, L_face is the unoccluded sky and ground ([`BoundaryLight::uniform`],
//! one value per face orientation). `full`'s clear-air iteration replaces it, on every face whose
//! empty neighbour has a viewing cube, by that cube's hemisphere ([`BoundaryLight::with_ghosts`]):
//! the sky seen through the rest of the cloud plus the light the other cloud parts and the lit
//! ground send — the paper's section 3, entering through the boundary condition instead of stage 1.

use crate::half::{power_of_two_scale, Signed16};
use crate::lighting::bins::{Bin, CUBE_FACES};
use crate::math::Rgb;

/// Incoming radiance L_face (W·m⁻²·sr⁻¹ per band) on the boundary faces of the diffusion's cloud.
/// Faces are indexed by their outward normal (from the full voxel towards its empty neighbour) in
/// [`CUBE_FACES`] order: +x, −x, +y, −y, +z, −z.
#[derive(Clone, Debug, Default)]
pub struct BoundaryLight {
    /// L_face per face orientation where no ghost value is known; zero: the paper's eq. 7.
    pub uniform: [Rgb; 6],
    /// The faces with their own light, ascending by [`ghost_key`] (empty voxel, the full voxel's
    /// outward normal), and that light beside them relative to `light_scale`, in 16 bits
    /// ([`Signed16`]: ≤ 2⁻¹² relative down to 2⁻¹³ of the brightest face): only faces next to a
    /// full voxel, 10 B each (20 with u64 keys and f32 light; it is held through the re-solve,
    /// the peak of `full`).
    ghost_faces: GhostKeys,
    ghost_light: Vec<[Signed16; 3]>,
    /// 2ᵏ, the scale of `ghost_light`.
    light_scale: f32,
}

/// The sorted keys of the faces with their own light: in 4 B each while every key fits (grids
/// below 2³²/6 ≈ 7·10⁸ voxels), else in 8.
#[derive(Clone, Debug)]
enum GhostKeys {
    Narrow(Vec<u32>),
    Wide(Vec<u64>),
}

impl Default for GhostKeys {
    fn default() -> Self {
        GhostKeys::Narrow(Vec::new())
    }
}

impl GhostKeys {
    /// From keys in ascending order.
    fn new(keys: Vec<u64>) -> GhostKeys {
        match keys.iter().map(|k| u32::try_from(*k)).collect::<Result<Vec<u32>, _>>() {
            Ok(narrow) => GhostKeys::Narrow(narrow),
            Err(_) => {
                // A collect in place may have kept the larger buffer it came from.
                let mut keys = keys;
                keys.shrink_to_fit();
                GhostKeys::Wide(keys)
            }
        }
    }

    /// The position of `key`, if listed.
    #[inline]
    fn find(&self, key: u64) -> Option<usize> {
        match self {
            GhostKeys::Narrow(v) => u32::try_from(key).ok().and_then(|k| v.binary_search(&k).ok()),
            GhostKeys::Wide(v) => v.binary_search(&key).ok(),
        }
    }

    fn is_empty(&self) -> bool {
        match self {
            GhostKeys::Narrow(v) => v.is_empty(),
            GhostKeys::Wide(v) => v.is_empty(),
        }
    }
}

/// Sort key of the face with outward normal `face` whose empty neighbour is grid voxel `ghost`.
#[inline]
fn ghost_key(ghost: usize, face: usize) -> u64 {
    6 * ghost as u64 + face as u64
}

/// The cosine-weighted mean radiance (1/π)∫_{ω·n > 0} L(ω) (ω·n) dω (W·m⁻²·sr⁻¹) over the
/// hemisphere of arrival directions around `n`, for radiance constant over each bin (`radiance[b]`
/// arriving from the directions of `bins[b]`). The hemisphere is a union of whole bins (their
/// edges lie on the cube's axis planes), and each bin contributes its exact first moment.
pub fn hemisphere_radiance(bins: &[Bin], radiance: &[Rgb], n: crate::math::Vec3) -> Rgb {
    let mut sum = [0f64; 3];
    for (b, r) in bins.iter().zip(radiance) {
        let cos_weight = b.mean_dir.dot(n) as f64 * b.solid_angle;
        if cos_weight > 0.0 {
            for (s, v) in sum.iter_mut().zip([r.x, r.y, r.z]) {
                *s += cos_weight * v as f64;
            }
        }
    }
    let k = 1.0 / std::f64::consts::PI;
    Rgb::new((sum[0] * k) as f32, (sum[1] * k) as f32, (sum[2] * k) as f32)
}

impl BoundaryLight {
    /// No incoming light: eq. 7 as the paper writes it (the sky enters through stage 1).
    pub fn none() -> Self {
        Self::default()
    }

    /// The same incoming light on every face of one orientation: the bins' radiance (sky and
    /// ground as seen unoccluded) over each face's outer hemisphere.
    pub fn uniform(bins: &[Bin], radiance: &[Rgb]) -> Self {
        BoundaryLight {
            uniform: std::array::from_fn(|f| hemisphere_radiance(bins, radiance, CUBE_FACES[f].n)),
            ..Self::default()
        }
    }

    /// `self` with its own light on some faces next to empty voxels: `ghosts` yields (grid index
    /// of the empty voxel, the full voxel's outward normal, L_face), each face once. A face not
    /// listed keeps the uniform value.
    pub fn with_ghosts(mut self, ghosts: impl IntoIterator<Item = (usize, usize, Rgb)>) -> Self {
        let mut faces: Vec<(u64, Rgb)> = ghosts.into_iter().map(|(g, f, l)| (ghost_key(g, f), l)).collect();
        faces.sort_by_key(|e| e.0);
        let max = faces.iter().map(|(_, l)| l.abs().max_element()).fold(0f32, f32::max);
        self.light_scale = power_of_two_scale(f64::from(max));
        let inv = 1.0 / f64::from(self.light_scale);
        self.ghost_light = faces
            .iter()
            .map(|(_, l)| [l.x, l.y, l.z].map(|v| Signed16::from_f32((f64::from(v) * inv) as f32)))
            .collect();
        self.ghost_faces = GhostKeys::new(faces.into_iter().map(|(k, _)| k).collect());
        self
    }

    /// L_face of band `c` on the face of a full voxel with outward normal `face` (index into
    /// [`CUBE_FACES`]) whose empty neighbour is grid voxel `ghost` (None outside the grid).
    #[inline]
    pub fn at(&self, ghost: Option<usize>, face: usize, c: usize) -> f64 {
        match ghost.and_then(|g| self.ghost_faces.find(ghost_key(g, face))) {
            Some(p) => f64::from(self.ghost_light[p][c].to_f32() * self.light_scale),
            None => f64::from(self.uniform[face][c]),
        }
    }

    /// True when no face receives light (the paper's eq. 7).
    pub fn is_dark(&self) -> bool {
        self.uniform.iter().all(|v| *v == Rgb::ZERO) && self.ghost_faces.is_empty()
    }
}

/// Index into [`CUBE_FACES`] of the face on `axis` with outward sign `side` (±1).
#[inline]
pub fn face_index(axis: usize, side: i64) -> usize {
    2 * axis + usize::from(side < 0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::bins::DirectionBins;

    #[test]
    fn a_uniform_sky_gives_its_radiance_on_every_face() {
        let bins = DirectionBins::new();
        let l = vec![Rgb::new(1.0, 2.0, 0.5); bins.bins.len()];
        let b = BoundaryLight::uniform(&bins.bins, &l);
        for f in 0..6 {
            for (c, want) in [1.0, 2.0, 0.5].into_iter().enumerate() {
                assert!((b.at(None, f, c) - want).abs() < 1e-6, "face {f} band {c}: {}", b.at(None, f, c));
            }
        }
    }

    #[test]
    fn sky_above_ground_below_splits_the_side_faces_evenly() {
        // Radiance 1 from above the horizon, 0 below: the top face (+y) sees 1, the bottom face
        // none, a side face half (its hemisphere is cut in two by the horizon, symmetrically).
        let bins = DirectionBins::new();
        let l: Vec<Rgb> = bins
            .bins
            .iter()
            .map(|b| if b.mean_dir.y > 0.0 { Rgb::splat(1.0) } else { Rgb::ZERO })
            .collect();
        let b = BoundaryLight::uniform(&bins.bins, &l);
        assert!((b.at(None, 2, 0) - 1.0).abs() < 1e-6);
        assert!(b.at(None, 3, 0).abs() < 1e-6);
        for f in [0, 1, 4, 5] {
            assert!((b.at(None, f, 0) - 0.5).abs() < 1e-6, "face {f}: {}", b.at(None, f, 0));
        }
        // A single bin: its exact first moment over π.
        let one: Vec<Rgb> = (0..bins.bins.len())
            .map(|i| if i == 0 { Rgb::splat(1.0) } else { Rgb::ZERO })
            .collect();
        let n = CUBE_FACES[bins.bins[0].face].n;
        let want = bins.bins[0].mean_dir.dot(n) as f64 * bins.bins[0].solid_angle / std::f64::consts::PI;
        assert!((hemisphere_radiance(&bins.bins, &one, n).x as f64 - want).abs() < 1e-7);
        assert_eq!(hemisphere_radiance(&bins.bins, &one, -n), Rgb::ZERO);
    }

    #[test]
    fn ghost_light_overrides_the_uniform_value_on_its_faces_only() {
        let b = BoundaryLight {
            uniform: [Rgb::splat(1.0); 6],
            ..BoundaryLight::default()
        }
        .with_ghosts([(42, 1, Rgb::splat(3.0)), (7, 5, Rgb::splat(2.0)), (7, 0, Rgb::splat(4.0))]);
        assert_eq!(b.at(Some(42), 1, 0), 3.0);
        assert_eq!(b.at(Some(42), 0, 0), 1.0, "face 0 of voxel 42 has no light of its own");
        assert_eq!(b.at(Some(7), 5, 2), 2.0);
        assert_eq!(b.at(Some(7), 0, 1), 4.0);
        assert_eq!(b.at(Some(8), 5, 2), 1.0);
        assert_eq!(b.at(None, 0, 0), 1.0);
        assert!(!b.is_dark());
        assert!(BoundaryLight::none().is_dark());
        assert_eq!(face_index(1, -1), 3);
        assert_eq!(face_index(2, 1), 4);
    }

    #[test]
    fn ghost_light_is_within_its_16_bit_rounding_with_narrow_and_wide_keys() {
        let mut rng = crate::math::Rng::new(4, 4);
        // Beyond 2³²/6 voxels the keys no longer fit 4 B.
        for base in [0usize, 1 << 31] {
            let ghosts: Vec<(usize, usize, Rgb)> = (0..500)
                .map(|k| {
                    let l = Rgb::new(rng.uniform(), rng.uniform(), rng.uniform()) * 1e3;
                    (base + 3 * k, k % 6, l)
                })
                .collect();
            let b = BoundaryLight::none().with_ghosts(ghosts.iter().rev().copied());
            assert_eq!(matches!(b.ghost_faces, GhostKeys::Wide(_)), base > 0);
            for (g, f, l) in &ghosts {
                for c in 0..3 {
                    let (got, want) = (b.at(Some(*g), *f, c), f64::from(l[c]));
                    assert!((got - want).abs() <= want / 4096.0 + 1e3 * 2f64.powi(-25), "{got} vs {want}");
                }
                assert_eq!(b.at(Some(*g), (*f + 1) % 6, 0), 0.0, "not listed: the uniform value");
            }
            assert_eq!(b.at(Some(base + 1), 0, 0), 0.0);
        }
    }
}
