//! Helpers shared by the crate's end-to-end tests.

use crate::image::Image;
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

/// A `.npy` (format 1.0) with header `dict` (padded here) and `body`.
pub fn npy_bytes(dict: &str, body: &[u8]) -> Vec<u8> {
    let mut h = dict.to_string();
    while (10 + h.len() + 1) % 64 != 0 {
        h.push(' ');
    }
    h.push('\n');
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    b.extend_from_slice(&(h.len() as u16).to_le_bytes());
    b.extend_from_slice(h.as_bytes());
    b.extend_from_slice(body);
    b
}
