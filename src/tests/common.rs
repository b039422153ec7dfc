//! Helpers shared by the crate's end-to-end tests.

use crate::image::Image;
use crate::math::{Rng, Vec3};
use crate::medium::Grid3;
use crate::scene::Method;
use std::path::PathBuf;

/// Every rendering method.
pub const METHODS: [Method; 5] = [
    Method::Single,
    Method::Diffusion,
    Method::Full,
    Method::Transport,
    Method::Reference,
];

/// A file under tests/data.
pub fn data(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(path)
}

/// The rows of the adding-doubling slab table (tests/data/slab_adding_doubling.csv): optical
/// thickness, albedo, g, UR1, UT1, URU, UTU.
pub fn slab_rows() -> Vec<[f64; 7]> {
    let text = include_str!("../../tests/data/slab_adding_doubling.csv");
    let mut lines = text.lines();
    assert_eq!(lines.next().unwrap().trim(), "optical_thickness,albedo,g,UR1,UT1,URU,UTU");
    lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|x| x.trim().parse().unwrap()).collect();
            [v[0], v[1], v[2], v[3], v[4], v[5], v[6]]
        })
        .collect()
}

/// Every pixel of the image and of its layers (but those named in `skip`) is finite and ≥ 0.
pub fn assert_finite_nonnegative(label: &str, img: &Image, skip: &[&str]) {
    let mut layers = vec![("rgb".to_string(), img.pixels.clone())];
    layers.extend(img.layers.iter().filter(|(n, _)| !skip.contains(&n.as_str())).cloned());
    for (name, px) in &layers {
        for (k, p) in px.iter().enumerate() {
            let a = p.to_array();
            assert!(
                a.iter().all(|x| x.is_finite() && *x >= 0.0),
                "{label}, layer {name}, pixel {k}: {a:?}"
            );
        }
    }
}

/// Two smooth lobes of density (peak 1) centred in a `dims` grid with a gap of clear air between
/// them, so that some viewing cubes look across clear air at cloud.
pub fn two_lobes(dims: [usize; 3], radius: f32) -> Grid3 {
    let mut g = Grid3::filled(dims, 0.0);
    let c = Vec3::new(dims[0] as f32, dims[1] as f32, dims[2] as f32) * 0.5;
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let p = Vec3::new(i as f32 + 0.5, j as f32 + 0.5, k as f32 + 0.5);
                let a = (p - c - Vec3::new(radius, 0.0, 0.0)).length() / radius;
                let b = (p - c + Vec3::new(radius * 1.2, 0.0, 0.0)).length() / (0.8 * radius);
                g.set(i, j, k, (1.0 - a * a).max(0.0) + (1.0 - b * b).max(0.0));
            }
        }
    }
    g
}

/// An irregular cloud: each voxel of a `dims` grid full with probability `fill`, its density
/// `lo + span·u` (u uniform in [0, 1)), drawn from `rng` in grid order.
pub fn random_cloud(dims: [usize; 3], rng: &mut Rng, fill: f32, lo: f32, span: f32) -> Grid3 {
    let mut g = Grid3::filled(dims, 0.0);
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                if rng.uniform() < fill {
                    g.set(i, j, k, lo + span * rng.uniform());
                }
            }
        }
    }
    g
}
