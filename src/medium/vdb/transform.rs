//! Index-to-world transforms. Only axis-aligned ones are accepted: a voxel of a dense grid must
//! be a box. world = index × scale + translation, with the voxel (i, j, k) centred at world(i, j, k).

use super::bytes::Cursor;
use crate::error::Result;

/// An axis-aligned index-to-world map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transform {
    /// OpenVDB map type name, e.g. `UniformScaleTranslateMap`.
    pub map: &'static str,
    /// Voxel edge lengths (world units per index step), all positive.
    pub scale: [f64; 3],
    /// World position of index (0, 0, 0).
    pub translation: [f64; 3],
}

impl Transform {
    /// World position of an index-space point.
    pub fn index_to_world(&self, ijk: [f64; 3]) -> [f64; 3] {
        [
            ijk[0] * self.scale[0] + self.translation[0],
            ijk[1] * self.scale[1] + self.translation[1],
            ijk[2] * self.scale[2] + self.translation[2],
        ]
    }
}

const KNOWN: [&str; 6] = [
    "ScaleMap",
    "UniformScaleMap",
    "ScaleTranslateMap",
    "UniformScaleTranslateMap",
    "TranslationMap",
    "AffineMap",
];

/// Read a grid transform; `grid` names the grid in errors.
pub(crate) fn read_transform(c: &mut Cursor, grid: &str) -> Result<Transform> {
    let ty = c.string("transform type")?;
    let map = KNOWN.iter().copied().find(|k| *k == ty);
    let (scale, translation) = match map {
        Some("ScaleMap") | Some("UniformScaleMap") => {
            let s = c.vec3d("transform scale")?;
            c.skip(4 * 24, "transform")?; // voxel size, inverse scale, 1/scale², 1/(2 scale): derived
            (s, [0.0; 3])
        }
        Some("ScaleTranslateMap") | Some("UniformScaleTranslateMap") => {
            let t = c.vec3d("transform translation")?;
            let s = c.vec3d("transform scale")?;
            c.skip(4 * 24, "transform")?;
            (s, t)
        }
        Some("TranslationMap") => ([1.0; 3], c.vec3d("transform translation")?),
        Some("AffineMap") => {
            // Row-major 4×4, row vectors: world = [i j k 1] · M. Accept only a diagonal 3×3 part.
            let mut m = [0.0f64; 16];
            for v in &mut m {
                *v = c.f64("affine matrix")?;
            }
            let off_diag = [1, 2, 4, 6, 8, 9];
            if off_diag.iter().any(|&i| m[i] != 0.0) || m[3] != 0.0 || m[7] != 0.0 || m[11] != 0.0 || m[15] != 1.0 {
                return Err(c.err(format!(
                    "grid `{grid}`: its AffineMap transform rotates, shears or projects; only scale and translation \
                     are supported (resample the grid to an axis-aligned transform, e.g. with Houdini's VDB Resample)"
                )));
            }
            ([m[0], m[5], m[10]], [m[12], m[13], m[14]])
        }
        _ => {
            return Err(c.err(format!(
                "grid `{grid}`: transform `{ty}` is not supported; only scale and translation maps \
                 ({}) are, not rotations or frustums (resample the grid to an axis-aligned transform)",
                KNOWN.join(", ")
            )))
        }
    };
    if !scale.iter().all(|s| s.is_finite() && *s > 0.0) || !translation.iter().all(|t| t.is_finite()) {
        return Err(c.err(format!(
            "grid `{grid}`: transform has scale {scale:?} and translation {translation:?}; \
             the voxel size must be positive and finite (mirrored grids are not supported)"
        )));
    }
    Ok(Transform {
        map: map.expect("known map"),
        scale,
        translation,
    })
}
