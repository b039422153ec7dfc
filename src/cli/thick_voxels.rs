//! A warning when light enters the cloud through voxels too thick for the deterministic methods
//! to resolve the layer it leaves from ([`crate::medium::skin`]): their images come out dark, and
//! the warning says by about how much and what to do.

use crate::medium::skin::median_entry_cell_depth;
use crate::scene::{Method, Scene};

/// Median optical depth of the voxels light enters through above which the warning is given.
/// On the clouds of docs/accuracy.md ("Optically thick voxels") `transport` is within 3 % of
/// `reference` up to a median of 2.45 and 3.6–8 % dark from 3 to 3.8.
pub const THICK_ENTRY: f32 = 2.5;

/// The warning for `scene`, if its method holds one value of the light per voxel and the median
/// voxel its light enters through is thicker than [`THICK_ENTRY`].
pub fn warning(scene: &Scene) -> Option<String> {
    if scene.render.method == Method::Reference {
        return None;
    }
    let median = median_entry_cell_depth(&scene.medium).filter(|d| *d > THICK_ENTRY)?;
    Some(format!(
        "{}: light enters the cloud through voxels {median:.1} optical depths thick (the median, from \
         medium.sigma_t × density × voxel size), too coarse for method {} to resolve the layer the light \
         leaves from: the image comes out dark (transport measured 4-8 % dark at 3-4, 22 % at 9, 39 % at 18; \
         full and diffusion more; docs/accuracy.md, \"Optically thick voxels\"); render with --method \
         reference, or give the cloud thinner voxels (a finer grid, or a smaller medium.sigma_t)",
        scene.source,
        scene.render.method.name()
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::SceneDesc;
    use std::path::Path;

    fn warning_for(sigma_t: f32, method: Method) -> Option<String> {
        let mut d = SceneDesc::default();
        d.medium.resolution = [20, 16, 12];
        d.medium.voxel_size = 25.0;
        d.medium.sigma_t = sigma_t;
        d.render.method = method;
        warning(&Scene::build(d, "s.toml", Path::new(".")).unwrap())
    }

    #[test]
    fn thick_entry_voxels_are_reported_for_every_method_but_reference() {
        assert_eq!(warning_for(0.05, Method::Transport), None);
        for m in [Method::Single, Method::Diffusion, Method::Full, Method::Transport] {
            let w = warning_for(1.0, m).unwrap_or_else(|| panic!("{m:?}: no warning"));
            assert!(w.contains(&format!("method {}", m.name())) && w.contains("--method reference"), "{w}");
        }
        assert_eq!(warning_for(1.0, Method::Reference), None);
    }
}
