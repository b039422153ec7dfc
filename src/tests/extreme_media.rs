//! Every method on media at the edges of the valid range: a real production cloud full
//! of tiny densities, and a family of small media with optical depths per voxel 0.001–1000, HG g
//! −0.95…0.99, albedo 0 and 1, and densities down to 1e-38. Each render is finite and
//! non-negative, or (the transport solve that cannot converge on voxels 1000 optical depths
//! thick) an error naming the stage. Tiny grids and images keep it fast.

use super::common::{assert_finite_nonnegative, data, METHODS};
use crate::error::Error;
use crate::{Method, NoProgress, Scene, SceneDesc};
use std::path::Path;

/// The Disney cloud (tests/data/clouds, CC BY-SA 3.0) at a quarter of its 1/16 resolution,
/// 48×36 pixels. Block MRE against a 256-spp `reference` of the same view, measured with
/// `cloudgi compare` (2-core x86-64 sandbox): transport 0.017, full 0.047, diffusion 0.24,
/// single 0.88 (sun single scattering alone). The bounds leave room for the reference's noise.
#[test]
fn the_disney_cloud_renders_near_reference_with_every_method() {
    let path = data("clouds/wdas.toml");
    let render = |m: Method| {
        let s = Scene::load(Some(&path), |d: &mut SceneDesc| {
            d.render.method = m;
            d.render.spp = 256;
            d.render.aov = m == Method::Full || m == Method::Transport;
        })
        .unwrap();
        crate::render::render(&s, &NoProgress).unwrap().image
    };
    let reference = render(Method::Reference);
    let mask = crate::tools::compare::choose_mask(&reference, None);
    for (m, bound) in [
        (Method::Transport, 0.04),
        (Method::Full, 0.09),
        (Method::Diffusion, 0.35),
        (Method::Single, 0.95),
    ] {
        let img = render(m);
        assert_finite_nonnegative(m.name(), &img, &["stderr"]);
        let metrics = crate::tools::compare::compare(&img, &reference, mask.as_deref()).unwrap();
        let mre = metrics.block_mean_relative_error.unwrap();
        assert!(mre < bound, "{}: block MRE {mre:.3} against reference (bound {bound})", m.name());
        // Not black: the cloud's mean luminance is a real fraction of the reference's (a transport
        // solve that mishandles its tiny densities renders 3 % of it: docs/transport.md, "Tiny densities").
        assert!(
            metrics.luminance_bias.unwrap() > -0.9,
            "{}: luminance bias {:?}",
            m.name(),
            metrics.luminance_bias
        );
    }
}

/// A 6³ `.npy` grid: a dense core of density 1 in a shell of tiny positive densities (1e-38,
/// subnormal in f32, up to 1e-6).
fn write_grid(dir: &Path) -> std::path::PathBuf {
    let n = 6usize;
    let tiny = [1e-38f32, 1.7e-37, 1e-30, 1e-20, 1e-6];
    let mut vals = Vec::with_capacity(n * n * n);
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let core = (1..5).contains(&x) && (1..5).contains(&y) && (1..5).contains(&z);
                vals.push(if core { 1.0 } else { tiny[(x + 2 * y + 3 * z) % tiny.len()] });
            }
        }
    }
    let header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({n}, {n}, {n}), }}");
    let body: Vec<u8> = vals.iter().flat_map(|v: &f32| v.to_le_bytes()).collect();
    let p = dir.join("grid.npy");
    std::fs::write(&p, super::common::npy_bytes(&header, &body)).unwrap();
    p
}

#[test]
fn every_method_is_finite_on_extreme_media() {
    let dir = tempfile::tempdir().unwrap();
    let grid = write_grid(dir.path());
    let voxel = 50.0f32;
    for tau in [1e-3f32, 1.0, 1e3] {
        for g in [-0.95f32, 0.0, 0.99] {
            for albedo in [0.0f32, 1.0] {
                for m in METHODS {
                    let label = format!("τ/voxel {tau}, g {g}, albedo {albedo}, {}", m.name());
                    let s = Scene::load(None, |d: &mut SceneDesc| {
                        d.medium.grid = grid.to_str().unwrap().to_string();
                        d.medium.voxel_size = voxel.into();
                        d.medium.origin = [-150.0, 100.0, -150.0];
                        d.medium.sigma_t = tau / voxel;
                        d.medium.albedo = [albedo; 3];
                        d.medium.g = g;
                        d.camera.position = [0.0, 250.0, 700.0];
                        d.camera.look_at = [0.0, 250.0, 0.0];
                        d.camera.width = 12;
                        d.camera.height = 9;
                        d.render.method = m;
                        d.render.aov = m == Method::Full || m == Method::Transport;
                        // A path in a conservative medium 1000 optical depths per voxel scatters
                        // ~10⁷ times: a cap keeps the test short (the estimate is then biased low,
                        // and must still be finite).
                        d.render.max_depth = Some(64);
                        d.render.spp = if m == Method::Reference { 2 } else { 1 };
                    })
                    .unwrap();
                    match crate::render::render(&s, &NoProgress) {
                        Ok(out) => assert_finite_nonnegative(&label, &out.image, &["stderr"]),
                        // The one allowed refusal: transport's solve on voxels too thick for its
                        // acceleration, with what to do.
                        Err(Error::Numerical { stage, message }) if m == Method::Transport && tau >= 1e3 => {
                            assert!(
                                stage == "transport solve" && message.contains("--method reference"),
                                "{label}: {message}"
                            );
                        }
                        Err(e) => panic!("{label}: {e}"),
                    }
                }
            }
        }
    }
}
