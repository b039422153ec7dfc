//! Refuse an image too large for this machine's memory before any work, instead of letting the
//! allocator abort mid-render.

use cloudgi::error::{Error, Result};
use cloudgi::scene::{Method, Scene, SceneDesc};
use cloudgi::transport::TransportMemory;

/// Bytes per pixel a render holds at its peak: the method's accumulators, the image, its layers
/// and their EXR/PNG encodings. Peak resident memory of 1500×1000 renders of an 8³ grid on the
/// development sandbox (`/usr/bin/time -f %M`), less the grid, was 33 B per pixel for `single`,
/// 78 B for `reference`, 271 B for `full` (its per-pixel gather components and low-density
/// segment lists) and 62 B for `transport` (120 B with its three AOV layers); these are those,
/// rounded up, plus 36 B per extra RGB layer.
pub fn bytes_per_pixel(method: Method, aov: bool, stderr: bool) -> u64 {
    const LAYER: u64 = 36;
    match method {
        Method::Single | Method::Diffusion => 48,
        Method::Reference => 96 + LAYER * u64::from(stderr),
        Method::Transport => 64 + 2 * LAYER * u64::from(aov),
        // full, and any method added later: the largest estimate.
        _ => 300 + 4 * LAYER * u64::from(aov),
    }
}

/// Bytes of memory available to new allocations (Linux `MemAvailable`), if known.
fn available_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Bytes as GiB with one decimal.
pub fn gib(b: u64) -> String {
    format!("{:.1} GiB", b as f64 / (1u64 << 30) as f64)
}

/// The image of `desc` (after the command line's overrides) must fit in `available` bytes.
pub fn check_image_fits(desc: &SceneDesc, source: &str, available: Option<u64>) -> Result<()> {
    let (w, h) = (desc.camera.width as u64, desc.camera.height as u64);
    let r = &desc.render;
    // Saturating: the camera's own limits are checked later, so any u32 size may arrive here.
    let need = (w * h).saturating_mul(bytes_per_pixel(r.method, r.aov, r.stderr));
    match available {
        Some(avail) if need > avail => Err(Error::invalid(
            source,
            "camera.width, camera.height",
            format!(
                "a {w}×{h} image with method {} needs about {} of memory but {} is available; \
                 lower camera.width and camera.height (or --width/--height)",
                r.method.name(),
                gib(need),
                gib(avail)
            ),
        )),
        _ => Ok(()),
    }
}

/// [`check_image_fits`] against this machine's available memory.
pub fn check_image(desc: &SceneDesc, source: &str) -> Result<()> {
    check_image_fits(desc, source, available_bytes())
}

/// Bytes per voxel of the grid the per-voxel stages hold at their peak, by method. Peak resident
/// memory of 8×8 renders of the noon evaluation cloud at 100×80×60 and at 200×160×120 voxels on
/// the development sandbox (`/usr/bin/time -f %M`) over the grid's voxels: `diffusion` 388 and
/// 352 B (stage 1's Q0/Q1, sun transmittances and sky harmonics per band, the solver's box),
/// `full` 482 and 443 B (plus the mip pyramid of the lit volume and the clear-air re-solve),
/// `single` and `reference` 16 and 6 B (the grid, a majorant or transmittance grid). Rounded up.
/// `transport` is estimated per full voxel instead ([`TransportMemory`]).
pub fn bytes_per_grid_voxel(method: Method) -> u64 {
    match method {
        Method::Single | Method::Reference => 16,
        Method::Diffusion => 400,
        // full, and any method added later: the largest estimate.
        _ => 500,
    }
}

/// The solver's arrays, estimated from the loaded medium for the scene's method, must fit in
/// `available` bytes beside the image: `transport` per full voxel ([`TransportMemory`]), the other
/// methods per grid voxel ([`bytes_per_grid_voxel`]).
pub fn check_solver_fits(scene: &Scene, available: Option<u64>) -> Result<()> {
    let Some(avail) = available else {
        return Ok(());
    };
    let r = &scene.render;
    let image = (scene.camera.width as u64 * scene.camera.height as u64).saturating_mul(bytes_per_pixel(r.method, r.aov, r.stderr));
    let beside = avail.saturating_sub(image);
    if r.method == Method::Transport {
        return TransportMemory::of(&scene.medium, &r.transport).check(&scene.source, beside, "the memory available beside the image");
    }
    let voxels = scene.medium.density.len() as u64;
    let per = bytes_per_grid_voxel(r.method);
    let need = voxels.saturating_mul(per);
    if need <= beside {
        return Ok(());
    }
    let other = match r.method {
        Method::Single | Method::Reference => "",
        _ => ", or use --method transport (memory per full voxel, not per grid voxel: sparse clouds need far less)",
    };
    Err(Error::invalid(
        &scene.source,
        "medium",
        format!(
            "method {} needs about {} ({voxels} grid voxels × {per} B) but the memory available beside \
             the image is {}; coarsen the cloud (medium.downsample, medium.resolution or \
             medium.max_voxels){other}",
            r.method.name(),
            gib(need),
            gib(beside)
        ),
    ))
}

/// [`check_solver_fits`] against this machine's available memory.
pub fn check_solver(scene: &Scene) -> Result<()> {
    check_solver_fits(scene, available_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_huge_image_is_refused_with_what_it_needs() {
        let mut d = SceneDesc::default();
        d.camera.width = 32768;
        d.camera.height = 32768;
        let e = check_image_fits(&d, "s.toml", Some(16 << 30)).unwrap_err().to_string();
        assert!(e.contains("camera.width") && e.contains("GiB") && e.contains("16.0 GiB"), "{e}");
        d.camera.width = 480;
        d.camera.height = 360;
        assert!(check_image_fits(&d, "s.toml", Some(16 << 30)).is_ok());
        assert!(check_image_fits(&d, "s.toml", None).is_ok());
    }

    #[test]
    fn the_transport_solver_is_refused_beyond_the_memory_and_named() {
        let scene = Scene::default_scene().unwrap();
        let need = TransportMemory::of(&scene.medium, &scene.render.transport).bytes;
        // The default cloud: ~44 k full voxels × 2.3 kB, about 0.13 GB.
        assert!((100_000_000..160_000_000).contains(&need), "{need}");
        let e = check_solver_fits(&scene, Some(need)).unwrap_err().to_string();
        assert!(e.contains("method transport") && e.contains("render.transport_order = 7"), "{e}");
        assert!(check_solver_fits(&scene, Some(2 * need)).is_ok());
        assert!(check_solver_fits(&scene, None).is_ok());
    }

    #[test]
    fn the_grid_methods_are_refused_beyond_the_memory_and_named() {
        let mut scene = Scene::default_scene().unwrap();
        scene.camera.width = 8;
        scene.camera.height = 8;
        let voxels = scene.medium.density.len() as u64;
        for (method, per) in [(Method::Full, 500), (Method::Diffusion, 400), (Method::Single, 16)] {
            scene.render.method = method;
            let image = 64 * bytes_per_pixel(method, false, false);
            let e = check_solver_fits(&scene, Some(image + voxels * per - 1)).unwrap_err().to_string();
            assert!(
                e.contains(&format!("method {}", method.name())) && e.contains("medium.downsample"),
                "{e}"
            );
            assert_eq!(e.contains("--method transport"), method != Method::Single, "{e}");
            assert!(check_solver_fits(&scene, Some(image + voxels * per)).is_ok());
        }
    }
}
