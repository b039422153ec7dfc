//! Refuse an image too large for this machine's memory before any work, instead of letting the
//! allocator abort mid-render.

use crate::diffusion::warm::DiffusionState;
use crate::diffusion::MAX_BOX_ROW_CELLS;
use crate::error::{Error, Result};
use crate::medium::Density;
use crate::scene::{Method, Scene, SceneDesc};
use crate::transport::TransportMemory;

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

/// Bytes as GiB with one decimal.
pub fn gib(b: u64) -> String {
    format!("{:.1} GiB", b as f64 / (1u64 << 30) as f64)
}

/// The image of `desc` (after the command line's overrides) must fit in `available` bytes.
pub fn check_image_fits(desc: &SceneDesc, source: &str, available: Option<u64>) -> Result<()> {
    let r = &desc.render;
    image_fits(
        [desc.camera.width, desc.camera.height],
        (r.method, r.aov, r.stderr),
        source,
        available,
    )
}

/// A `w`×`h` image rendered by `(method, aov, stderr)` must fit in `available` bytes.
fn image_fits([w, h]: [u32; 2], (method, aov, stderr): (Method, bool, bool), source: &str, available: Option<u64>) -> Result<()> {
    let (w, h) = (w as u64, h as u64);
    // Saturating: the camera's own limits are checked later, so any u32 size may arrive here.
    let need = (w * h).saturating_mul(bytes_per_pixel(method, aov, stderr));
    match available {
        Some(avail) if need > avail => Err(Error::invalid(
            source,
            "camera.width, camera.height",
            format!(
                "a {w}×{h} image with method {} needs about {} of memory but {} is available; \
                 lower camera.width and camera.height (or --width/--height)",
                method.name(),
                gib(need),
                gib(avail)
            ),
        )),
        _ => Ok(()),
    }
}

/// The command line's guards on a built scene as it will render (its method, image and cloud),
/// for [`crate::render`]: the image and the solver must fit this machine's available memory and
/// the cloud the diffusion solver's rows, so no caller's render aborts or panics midway.
pub fn check_scene(scene: &Scene) -> Result<()> {
    let available = crate::io::available_memory();
    let r = &scene.render;
    image_fits(
        [scene.camera.width, scene.camera.height],
        (r.method, r.aov, r.stderr),
        &scene.source,
        available,
    )?;
    check_solver_fits(scene, available, 0)
}

/// [`check_image_fits`] against this machine's available memory.
pub fn check_image(desc: &SceneDesc, source: &str) -> Result<()> {
    check_image_fits(desc, source, crate::io::available_memory())
}

/// The sizes of a cloud a grid method's memory follows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CloudSize {
    /// Voxels of the grid.
    pub grid: u64,
    /// Voxels of the tight box of the full voxels (the diffusion solver's domain).
    pub boxed: u64,
    /// Full voxels (ρ > 0).
    pub full: u64,
    /// Cells along x of that box (the diffusion solver's rows).
    pub row: u64,
}

impl CloudSize {
    /// Read them off a density (its full-voxel count and box).
    pub fn of(density: &Density) -> CloudSize {
        let (boxed, row) = density.full_box().map_or((0, 0), |(lo, hi)| {
            ((0..3).map(|a| (hi[a] - lo[a]) as u64).product(), (hi[0] - lo[0]) as u64)
        });
        CloudSize {
            grid: density.len() as u64,
            boxed,
            full: density.count() as u64,
            row,
        }
    }
}

/// Peak bytes of a grid method: a fixed part plus bytes per grid voxel, per voxel of the full
/// voxels' box and per full voxel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GridMemory {
    /// Fixed bytes (program, thread stacks, tables).
    pub fixed: u64,
    /// Per grid voxel: the full-voxel index's occupancy words (0.25 B; the density is stored per
    /// full voxel).
    pub per_grid: u64,
    /// Per voxel of the box of the full voxels: the sun transmittance (2 B, on the box grown by
    /// one voxel) and the solver's box-shaped bookkeeping.
    pub per_box: u64,
    /// Per full voxel: the density, the solver's hierarchy and vectors, stage 1's Q0/Q1, I0, I1,
    /// the lit volume and its pyramid, the gather's source records.
    pub per_full: u64,
}

impl GridMemory {
    /// Bytes for a cloud of `size`.
    pub fn bytes(&self, size: CloudSize) -> u64 {
        self.fixed
            .saturating_add(size.grid.saturating_mul(self.per_grid))
            .saturating_add(size.boxed.saturating_mul(self.per_box))
            .saturating_add(size.full.saturating_mul(self.per_full))
    }
}

/// The memory model of each grid method (docs/performance.md, "The memory guard"): fixed, per
/// grid voxel, per voxel of the full voxels' box and per full voxel terms, fitted to the peak
/// resident memory (`/usr/bin/time -f %M`) of 8×6-pixel renders of the procedural cumulus at
/// 50×40×30, 100×80×60, 200×160×120 and 400×320×240 and of two spheres in opposite corners of a
/// 200×160×120 grid (the fixed and per-box terms). Each term is kept above the measured
/// increments, so a cloud that fills its box is not under-estimated; the estimates err on the
/// safe side (docs/performance.md has the measured peaks and estimates). The index's 0.25 B per
/// grid voxel is rounded up to 1 B. `single` and `reference` hold the density, a dense copy of
/// its box and a majorant or transmittance grid (16 B per grid voxel, an upper bound).
pub fn grid_memory(method: Method) -> GridMemory {
    const MB: u64 = 1 << 20;
    match method {
        Method::Single | Method::Reference => GridMemory {
            fixed: 0,
            per_grid: 16,
            per_box: 0,
            per_full: 0,
        },
        Method::Diffusion => GridMemory {
            fixed: 16 * MB,
            per_grid: 1,
            per_box: 10,
            per_full: 170,
        },
        // full, and any method added later: the largest estimate.
        _ => GridMemory {
            fixed: 16 * MB,
            per_grid: 1,
            per_box: 10,
            per_full: 60,
        },
    }
}

/// Bytes a frame of a sequence holds for its warm starts beside its own solve: the state
/// `carried` in from the previous frame (held through the solve) and, for `diffusion` and
/// `full`, the state this frame keeps for the next (`transport` keeps its solve's moments, which
/// [`TransportMemory`] counts already). None without warm starts.
pub fn warm_state_bytes(scene: &Scene, carried: u64, warm: bool) -> u64 {
    if !warm {
        return 0;
    }
    let kept = match scene.render.method {
        Method::Diffusion | Method::Full => {
            let size = CloudSize::of(&scene.medium.density);
            DiffusionState::bytes_for(size.full, size.grid)
        }
        _ => 0,
    };
    carried.saturating_add(kept)
}

/// The solver's arrays, estimated from the loaded medium for the scene's method, and `warm`
/// bytes of warm-start state ([`warm_state_bytes`]) must fit in `available` bytes beside the
/// image: `transport` per full voxel ([`TransportMemory`]), the other methods from the grid's,
/// the cloud's box's and the full voxels' counts ([`grid_memory`]).
pub fn check_solver_fits(scene: &Scene, available: Option<u64>, warm: u64) -> Result<()> {
    check_solver_row(scene)?;
    let Some(avail) = available else {
        return Ok(());
    };
    let r = &scene.render;
    let image = (scene.camera.width as u64 * scene.camera.height as u64).saturating_mul(bytes_per_pixel(r.method, r.aov, r.stderr));
    let beside = avail.saturating_sub(image).saturating_sub(warm);
    let what = if warm > 0 {
        format!(
            "the memory available beside the image and the {} the sequence keeps for its warm starts \
             (--cold keeps none)",
            gib(warm)
        )
    } else {
        "the memory available beside the image".to_string()
    };
    if r.method == Method::Transport {
        return TransportMemory::of(&scene.medium, &r.transport).check(&scene.source, beside, &what, &scene.desc.medium.coarser_refine());
    }
    let size = CloudSize::of(&scene.medium.density);
    let model = grid_memory(r.method);
    let need = model.bytes(size);
    if need <= beside {
        return Ok(());
    }
    let other = match r.method {
        Method::Single | Method::Reference => "",
        _ => ", or use --method transport",
    };
    let per_cloud = match r.method {
        Method::Single | Method::Reference => String::new(),
        _ => format!(
            " + {} voxels of the cloud's box × {} B + {} full voxels × {} B + {} MB",
            size.boxed,
            model.per_box,
            size.full,
            model.per_full,
            model.fixed >> 20
        ),
    };
    Err(Error::invalid(
        &scene.source,
        "medium",
        format!(
            "method {} needs about {} ({} grid voxels × {} B{per_cloud}) but {what} is {}; coarsen the cloud ({}medium.downsample, \
             medium.resolution or medium.max_voxels){other}",
            r.method.name(),
            gib(need),
            size.grid,
            model.per_grid,
            gib(beside),
            scene.desc.medium.coarser_refine()
        ),
    ))
}

/// The diffusion solver (of `diffusion`, `full` and `transport`'s acceleration) takes clouds at
/// most [`MAX_BOX_ROW_CELLS`] voxels wide along x.
fn check_solver_row(scene: &Scene) -> Result<()> {
    if matches!(scene.render.method, Method::Single | Method::Reference) {
        return Ok(());
    }
    let row = CloudSize::of(&scene.medium.density).row;
    if row <= MAX_BOX_ROW_CELLS as u64 {
        return Ok(());
    }
    Err(Error::invalid(
        &scene.source,
        "medium",
        format!(
            "the cloud spans {row} voxels along x, and method {}'s diffusion solver takes at most {MAX_BOX_ROW_CELLS}; \
             coarsen the cloud ({}medium.downsample or medium.resolution), or use --method single or reference",
            scene.render.method.name(),
            scene.desc.medium.coarser_refine()
        ),
    ))
}

/// [`check_solver_fits`] against this machine's available memory, with `warm` bytes of
/// warm-start state.
pub fn check_solver(scene: &Scene, warm: u64) -> Result<()> {
    check_solver_fits(scene, crate::io::available_memory(), warm)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::medium::{Grid3, Medium};

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
        // The default cloud (44 k full voxels) peaked at 107.8 MB (`/usr/bin/time -f %M`, 8×6
        // pixels; docs/performance.md): the guard's estimate is at least that and at most 1.3×.
        let measured = 107_800_000.0;
        assert!((1.0..=1.3).contains(&(need as f64 / measured)), "{need}");
        let e = check_solver_fits(&scene, Some(need), 0).unwrap_err().to_string();
        assert!(e.contains("method transport") && e.contains("render.transport_order = 7"), "{e}");
        assert!(check_solver_fits(&scene, Some(2 * need), 0).is_ok());
        assert!(check_solver_fits(&scene, None, 0).is_ok());
    }

    #[test]
    fn a_sequence_counts_the_warm_start_state_it_keeps_between_frames() {
        let mut scene = Scene::default_scene().unwrap();
        (scene.camera.width, scene.camera.height) = (8, 8);
        let size = CloudSize::of(&scene.medium.density);
        // transport: the moments carried in from the last frame (768 B per full voxel at order
        // 7); the frame's own are its solve's.
        let carried = 768 * size.full;
        assert_eq!(warm_state_bytes(&scene, carried, true), carried);
        assert_eq!(warm_state_bytes(&scene, carried, false), 0, "--cold keeps none");
        let need =
            64 * bytes_per_pixel(Method::Transport, false, false) + TransportMemory::of(&scene.medium, &scene.render.transport).bytes;
        assert!(check_solver_fits(&scene, Some(need), 0).is_ok());
        let e = check_solver_fits(&scene, Some(need), carried).unwrap_err().to_string();
        assert!(e.contains("warm starts") && e.contains("--cold"), "{e}");
        assert!(check_solver_fits(&scene, Some(need + carried), carried).is_ok());
        // diffusion and full: also the I0 this frame keeps (12 B per full voxel and the grid's
        // occupancy).
        for method in [Method::Diffusion, Method::Full] {
            scene.render.method = method;
            let kept = warm_state_bytes(&scene, 0, true);
            assert_eq!(kept, 12 * size.full + size.grid.div_ceil(4));
            let need = 64 * bytes_per_pixel(method, false, false) + grid_memory(method).bytes(size);
            let e = check_solver_fits(&scene, Some(need + kept - 1), kept).unwrap_err().to_string();
            assert!(e.contains(&format!("method {}", method.name())) && e.contains("--cold"), "{e}");
            assert!(check_solver_fits(&scene, Some(need + kept), kept).is_ok());
        }
    }

    #[test]
    fn a_cloud_wider_than_the_solvers_rows_is_refused_for_its_methods() {
        let mut scene = Scene::default_scene().unwrap();
        let m = &scene.medium;
        let medium = |nx: usize| Medium::with_optics(Grid3::filled([nx, 1, 1], 1.0), m.origin, m.voxel_size, m.optics);
        let (wide, widest) = (medium(MAX_BOX_ROW_CELLS + 1), medium(MAX_BOX_ROW_CELLS));
        scene.medium = wide;
        for method in [Method::Full, Method::Diffusion, Method::Transport] {
            scene.render.method = method;
            let e = check_solver_fits(&scene, None, 0).unwrap_err().to_string();
            let spans = format!("spans {} voxels along x", MAX_BOX_ROW_CELLS + 1);
            assert!(e.contains(&spans) && e.contains("medium.downsample"), "{e}");
        }
        for method in [Method::Single, Method::Reference] {
            scene.render.method = method;
            assert!(check_solver_fits(&scene, None, 0).is_ok());
        }
        scene.medium = widest;
        scene.render.method = Method::Full;
        assert!(check_solver_fits(&scene, None, 0).is_ok());
    }

    #[test]
    fn the_grid_methods_are_refused_beyond_the_memory_and_named() {
        let mut scene = Scene::default_scene().unwrap();
        scene.camera.width = 8;
        scene.camera.height = 8;
        let size = CloudSize::of(&scene.medium.density);
        for method in [Method::Full, Method::Diffusion, Method::Single] {
            scene.render.method = method;
            let image = 64 * bytes_per_pixel(method, false, false);
            let need = grid_memory(method).bytes(size);
            let e = check_solver_fits(&scene, Some(image + need - 1), 0).unwrap_err().to_string();
            assert!(
                e.contains(&format!("method {}", method.name())) && e.contains("medium.downsample"),
                "{e}"
            );
            let sparse = method != Method::Single;
            assert_eq!(e.contains("--method transport"), sparse, "{e}");
            assert_eq!(e.contains(&format!("{} full voxels", size.full)), sparse, "{e}");
            assert!(!e.contains("medium.refine"), "{e}");
            assert!(check_solver_fits(&scene, Some(image + need), 0).is_ok());
        }
        // A refined grid is told to refine less first, by every method's guard.
        scene.desc.medium.refine = 3;
        for method in [Method::Single, Method::Transport] {
            scene.render.method = method;
            let e = check_solver_fits(&scene, Some(1), 0).unwrap_err().to_string();
            assert!(
                e.contains("a lower medium.refine (now 3: 27× the file's voxels), medium.downsample"),
                "{e}"
            );
        }
    }

    #[test]
    fn the_cloud_is_counted_by_its_full_voxels_and_their_box() {
        let mut g = Grid3::filled([6, 5, 4], 0.0);
        assert_eq!(
            CloudSize::of(&Density::from_grid(&g)),
            CloudSize {
                grid: 120,
                boxed: 0,
                full: 0,
                row: 0
            }
        );
        g.set(1, 1, 1, 0.5);
        g.set(3, 4, 2, 1.0);
        assert_eq!(
            CloudSize::of(&Density::from_grid(&g)),
            CloudSize {
                grid: 120,
                boxed: 3 * 4 * 2,
                full: 2,
                row: 3
            }
        );
        // The default cloud at 100×80×60: 9 % of the grid is full and the estimate is above the
        // 15.3 MB measured at 8×6 pixels, by less than half again (docs/performance.md).
        let scene = Scene::default_scene().unwrap();
        let size = CloudSize::of(&scene.medium.density);
        assert!((40_000..50_000).contains(&size.full), "{size:?}");
        let mb = grid_memory(Method::Full).bytes(size) >> 20;
        assert!((15..22).contains(&mb), "{mb} MB");
    }
}
