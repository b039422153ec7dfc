//! A warning when light enters the cloud through voxels too thick for the deterministic methods
//! to resolve the layer it leaves from ([`crate::medium::skin`]): their images come out dark, and
//! the warning says by about how much and what to do.

use crate::medium::skin::median_entry_cell_depth;
use crate::medium::MAX_REFINE;
use crate::scene::{Method, Scene};

/// Median optical depth of the voxels light enters through above which the warning is given.
/// On the clouds of docs/accuracy.md ("Optically thick voxels") `transport` is within 3 % of
/// `reference` up to a median of 2.45 and 3.6–8 % dark from 3 to 3.8.
pub const THICK_ENTRY: f32 = 2.5;

/// The phase function's g down to which [`THICK_ENTRY`] holds (the clouds of docs/accuracy.md
/// have g = 0.88 and 0.9).
const THICK_ENTRY_G: f32 = 0.85;

/// The threshold at g ≤ [`LOW_G`]: the layer the light leaves a lit face from is thinner the less
/// forward the phase function. On the built-in cloud at 40-m voxels `transport` measured 2.7, 1.3
/// and 0.3 % dark at a median of 1.3 and 7.6, 4.9 and 2.9 % at 1.5 for g = 0, 0.5 and 0.7
/// (docs/accuracy.md, "Thick voxels at low g").
const LOW_G_ENTRY: f32 = 1.4;
const LOW_G: f32 = 0.7;

/// The median entry depth above which a medium of HG parameter `g` is warned about:
/// [`LOW_G_ENTRY`] up to g = [`LOW_G`], [`THICK_ENTRY`] from [`THICK_ENTRY_G`], linear between.
pub fn thick_entry(g: f32) -> f32 {
    let t = ((g - LOW_G) / (THICK_ENTRY_G - LOW_G)).clamp(0.0, 1.0);
    LOW_G_ENTRY + t * (THICK_ENTRY - LOW_G_ENTRY)
}

/// The warning for `scene`, if its method holds one value of the light per voxel and the median
/// voxel its light enters through is thicker than [`thick_entry`] of its g; it names the
/// `medium.refine` that brings the median to that or below, where one within [`MAX_REFINE`] does.
pub fn warning(scene: &Scene) -> Option<String> {
    if scene.render.method == Method::Reference {
        return None;
    }
    let threshold = thick_entry(scene.desc.medium.g);
    let median = median_entry_cell_depth(&scene.medium).filter(|d| *d > threshold)?;
    let d = &scene.desc.medium;
    // Refining k times makes the entry cells k times thinner. (Their ramps from the empty voxels
    // thin faster, as 1/k², but transport on such refined clouds was measured 3.4-3.8 % dark where
    // that estimate was 2.5: docs/accuracy.md.)
    let more = (3..=MAX_REFINE).step_by(2).find(|k| median / *k as f32 <= threshold);
    let finer = match more.map(|k| k * d.refine).filter(|k| *k <= MAX_REFINE) {
        _ if d.downsample > 1 => "a lower medium.downsample".to_string(),
        Some(k) => format!("medium.refine = {k} ({}× the voxels, memory and time)", k.pow(3) / d.refine.pow(3)),
        None => "a finer grid (medium.refine goes up to 7)".to_string(),
    };
    let m = scene.render.method;
    // Refining resolves the layer for transport; the other methods' darkness there is mostly their
    // own approximations' (docs/accuracy.md), so they are pointed to transport.
    let remedy = if m == Method::Transport {
        format!("resolve the layer with {finer}, or render with --method reference")
    } else {
        format!("render with --method transport and {finer}, or with --method reference")
    };
    // Below THICK_ENTRY_G the threshold is lower: say why at this g.
    let low_g = match threshold < THICK_ENTRY {
        true => format!(
            "; with medium.g = {} the layer is thinner and the limit {threshold:.2} (transport measured 8 % dark at 1.5 \
             with g = 0, 5 % with g = 0.5; docs/accuracy.md, \"Thick voxels at low g\")",
            d.g
        ),
        false => String::new(),
    };
    Some(format!(
        "{}: light enters the cloud through voxels {median:.1} optical depths thick (the median over the cloud's \
         surface; medium.sigma_t × density × the voxel's side the light crosses), too thick for method {} to resolve the layer the light leaves from: the image comes \
         out dark (transport measured 4-8 % dark at 3-4, 22 % at 9, 39 % at 18 where the density ramps up from \
         the cloud's edge, 38 % at 10 and 91 % at 20 on the sunlit faces of a uniform block; full and diffusion \
         10-25 %; docs/accuracy.md, \"Optically thick voxels\"){low_g}; {remedy}",
        scene.source,
        m.name()
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::SceneDesc;
    use std::path::Path;

    fn warning_for(sigma_t: f32, method: Method) -> Option<String> {
        warning_with(sigma_t, method, |_| ())
    }

    fn warning_with(sigma_t: f32, method: Method, edit: impl FnOnce(&mut SceneDesc)) -> Option<String> {
        let mut d = SceneDesc::default();
        d.medium.resolution = [20, 16, 12];
        d.medium.voxel_size = 25.0.into();
        d.medium.sigma_t = sigma_t;
        d.render.method = method;
        edit(&mut d);
        warning(&Scene::build(d, "s.toml", Path::new(".")).unwrap())
    }

    #[test]
    fn thick_entry_voxels_are_reported_for_every_method_but_reference() {
        assert_eq!(warning_for(0.05, Method::Transport), None);
        for m in [Method::Single, Method::Diffusion, Method::Full, Method::Transport] {
            let w = warning_for(1.0, m).unwrap_or_else(|| panic!("{m:?}: no warning"));
            assert!(
                w.contains(&format!("method {}", m.name())) && w.contains("--method reference"),
                "{w}"
            );
        }
        assert_eq!(warning_for(1.0, Method::Reference), None);
    }

    #[test]
    fn a_phase_function_less_forward_than_measured_is_warned_about_at_thinner_voxels() {
        // The built-in cloud at 40-m voxels, σt = 0.05: entry voxels 1.5 thick, where transport
        // measured −7.6 % at g = 0, −4.9 % at 0.5 and 0.0 % at 0.9.
        let at = |g: f32| {
            warning_with(0.05, Method::Transport, |d| {
                d.medium.resolution = [24, 20, 16];
                d.medium.voxel_size = 40.0.into();
                d.medium.g = g;
            })
        };
        assert!(at(0.0).is_some_and(|w| w.contains("medium.g = 0") && w.contains("limit 1.40")));
        assert!(at(0.5).is_some() && at(-0.3).is_some());
        assert_eq!(at(0.9), None);
        // σt = 0.025 (entry voxels 1.3, transport −2.7 % at g = 0): no warning.
        let thinner = warning_with(0.025, Method::Transport, |d| {
            d.medium.resolution = [24, 20, 16];
            d.medium.voxel_size = 40.0.into();
            d.medium.g = 0.0;
        });
        assert_eq!(thinner, None);
        assert_eq!(
            (thick_entry(0.9), thick_entry(0.85), thick_entry(0.0)),
            (THICK_ENTRY, THICK_ENTRY, LOW_G_ENTRY)
        );
        assert!((thick_entry(0.775) - 0.5 * (THICK_ENTRY + LOW_G_ENTRY)).abs() < 1e-6);
    }

    #[test]
    fn flat_voxels_are_judged_across_the_faces_the_light_enters() {
        // 25 × 25 × 1 m voxels (σt·h = 25 along x and y, 1 along z): no warning; as cubes, one.
        let flat = |d: &mut SceneDesc| {
            d.medium.resolution = [20, 16, 40];
            d.medium.voxel_size = crate::medium::VoxelSize::Box([25.0, 25.0, 1.0]);
        };
        assert_eq!(warning_with(1.0, Method::Transport, flat), None);
        assert!(warning_with(1.0, Method::Transport, |d| d.medium.resolution = [20, 16, 40]).is_some());
    }

    #[test]
    fn the_warning_names_the_refinement_that_resolves_the_entry_layer() {
        // σt·h = 7.5 on the built-in cloud: entry voxels about 3 thick, refined 3× about 1.
        let w = warning_for(0.3, Method::Transport).unwrap();
        assert!(w.contains("medium.refine = 3 (27× the voxels"), "{w}");
        assert_eq!(warning_with(0.3, Method::Transport, |d| d.medium.refine = 3), None);
        // A cloud refined 3× and still thick has no odd multiple of 3 left within 7.
        let w = warning_with(5.0, Method::Transport, |d| d.medium.refine = 3).unwrap();
        assert!(w.contains("a finer grid"), "{w}");
        // Past what refine offers, a finer grid; with downsample set, less of it.
        let w = warning_for(5.0, Method::Transport).unwrap();
        assert!(w.contains("a finer grid"), "{w}");
        let w = warning_with(1.0, Method::Transport, |d| {
            d.medium.resolution = [10, 8, 6];
            d.medium.downsample = 2;
        });
        assert!(w.is_some_and(|w| w.contains("a lower medium.downsample")));
    }
}
