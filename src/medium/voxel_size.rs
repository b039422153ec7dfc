//! `medium.voxel_size`: one edge length for cubic voxels, or one per axis `[x, y, z]` for grids
//! whose cells are not cubes (a weather or large-eddy simulation's 50-m columns of 20-m layers),
//! in metres and in the grid file's axes, as `medium.origin` (turned with it by `medium.up_axis`).

use crate::math::Vec3;
use serde::de::{self, SeqAccess, Visitor};
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;

/// A voxel's edge lengths (m).
#[derive(Clone, Copy, PartialEq)]
pub enum VoxelSize {
    /// Cubic voxels of this edge (m).
    Cube(f32),
    /// Edges along x, y and z (m).
    Box([f32; 3]),
}

impl VoxelSize {
    /// The edges along x, y and z (m).
    pub fn to_vec3(self) -> Vec3 {
        match self {
            VoxelSize::Cube(h) => Vec3::splat(h),
            VoxelSize::Box(h) => Vec3::from(h),
        }
    }

    /// Every edge finite and positive.
    pub fn is_valid(self) -> bool {
        self.to_vec3().to_array().iter().all(|h| h.is_finite() && *h > 0.0)
    }

    /// Every edge times `factor`.
    pub fn scaled(self, factor: f32) -> VoxelSize {
        match self {
            VoxelSize::Cube(h) => VoxelSize::Cube(h * factor),
            VoxelSize::Box(h) => VoxelSize::Box(h.map(|x| x * factor)),
        }
    }
}

impl From<f32> for VoxelSize {
    fn from(h: f32) -> Self {
        VoxelSize::Cube(h)
    }
}

impl From<[f32; 3]> for VoxelSize {
    fn from(h: [f32; 3]) -> Self {
        VoxelSize::Box(h)
    }
}

/// As a scene file writes it: `10` or `[50, 20, 50]`.
impl fmt::Display for VoxelSize {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            VoxelSize::Cube(h) => write!(f, "{h}"),
            VoxelSize::Box([x, y, z]) => write!(f, "[{x}, {y}, {z}]"),
        }
    }
}

/// As written (messages quote the value the user gave).
impl fmt::Debug for VoxelSize {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self, f)
    }
}

impl Serialize for VoxelSize {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            VoxelSize::Cube(h) => s.serialize_f32(*h),
            VoxelSize::Box(h) => h.serialize(s),
        }
    }
}

/// A number or a list of exactly three numbers; anything else is refused with what is expected
/// (serde's untagged enums would say only that no variant matched).
impl<'de> Deserialize<'de> for VoxelSize {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Edges;
        impl<'de> Visitor<'de> for Edges {
            type Value = VoxelSize;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a voxel edge in metres (e.g. 10) or one per axis [x, y, z] (e.g. [50, 20, 50])")
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<VoxelSize, E> {
                Ok(VoxelSize::Cube(v as f32))
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<VoxelSize, E> {
                Ok(VoxelSize::Cube(v as f32))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<VoxelSize, E> {
                Ok(VoxelSize::Cube(v as f32))
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<VoxelSize, A::Error> {
                let mut h = [0f32; 3];
                for (i, x) in h.iter_mut().enumerate() {
                    *x = seq.next_element()?.ok_or_else(|| de::Error::invalid_length(i, &self))?;
                }
                match seq.next_element::<de::IgnoredAny>()? {
                    None => Ok(VoxelSize::Box(h)),
                    Some(_) => Err(de::Error::invalid_length(4, &self)),
                }
            }
        }
        d.deserialize_any(Edges)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Deserialize, Serialize, Debug, PartialEq)]
    struct M {
        voxel_size: VoxelSize,
    }

    fn parse(text: &str) -> Result<VoxelSize, String> {
        toml::from_str::<M>(text).map(|m| m.voxel_size).map_err(|e| e.to_string())
    }

    #[test]
    fn a_number_is_a_cube_and_three_are_a_box_and_both_write_back_as_read() {
        assert_eq!(parse("voxel_size = 10").unwrap(), VoxelSize::Cube(10.0));
        assert_eq!(parse("voxel_size = 2.5").unwrap(), VoxelSize::Cube(2.5));
        let b = parse("voxel_size = [50, 20.5, 50]").unwrap();
        assert_eq!(b, VoxelSize::Box([50.0, 20.5, 50.0]));
        assert_eq!(b.to_vec3(), Vec3::new(50.0, 20.5, 50.0));
        assert_eq!(b.to_string(), "[50, 20.5, 50]");
        assert_eq!(b.scaled(2.0), VoxelSize::Box([100.0, 41.0, 100.0]));
        for v in [VoxelSize::Cube(7.5), b] {
            let text = toml::to_string(&M { voxel_size: v }).unwrap();
            assert_eq!(parse(&text).unwrap(), v, "{text}");
        }
        let json = serde_json::to_string(&M { voxel_size: b }).unwrap();
        assert_eq!(serde_json::from_str::<M>(&json).unwrap().voxel_size, b);
    }

    #[test]
    fn other_shapes_are_refused_saying_what_is_expected() {
        for bad in ["voxel_size = [1, 2]", "voxel_size = [1, 2, 3, 4]", "voxel_size = \"10\"", "voxel_size = [1, \"a\", 3]"] {
            let e = parse(bad).expect_err(bad);
            assert!(e.contains("voxel_size"), "{bad}: {e}");
        }
        let e = parse("voxel_size = [1, 2]").unwrap_err();
        assert!(e.contains("one per axis [x, y, z]"), "{e}");
        assert!(VoxelSize::Cube(1.0).is_valid() && VoxelSize::Box([1.0, 2.0, 3.0]).is_valid());
        for bad in [VoxelSize::Cube(0.0), VoxelSize::Cube(f32::NAN), VoxelSize::Box([1.0, -2.0, 3.0]), VoxelSize::Box([1.0, 2.0, f32::INFINITY])] {
            assert!(!bad.is_valid(), "{bad:?}");
        }
    }
}
