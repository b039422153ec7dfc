//! A warning when `full` or `diffusion` renders a medium darker (lower albedo) than the lowest at
//! which it was measured near its accuracy budget against `reference` (≤ 12 % block error,
//! |bias| ≤ 6 %; docs/accuracy.md, "Albedo below 1"): `full` comes out dark there and `diffusion`
//! blotchy, and the warning says by about how much and points to `transport`.

use crate::scene::{Method, Scene};

/// The lowest albedo at which `method` was measured near its budget, and what it measured below.
/// From docs/accuracy.md, "Albedo below 1" (the built-in cumulus at 64×48, g = 0.9, `reference`
/// at 2048 paths per pixel): `full` is −5.1 % at albedo 0.999 and −6.6 % at 0.99 on sun035's view,
/// −10 % at 0.97 and −19 % at 0.9, and −15 to −20 % at 0.9 on four of five views (its orders' a^i
/// and an excess of light at low albedo do not cancel); `diffusion`'s block error is 9.6 % at
/// 0.999, 9.9 % at 0.9, 16 % at 0.8 and 31 % at 0.5. `transport` is within 2 % bias at every
/// albedo of the sweep (0.3–0.999; 4 % at g = 0).
fn measured_down_to(method: Method) -> Option<(f32, &'static str)> {
    match method {
        Method::Full => Some((0.99, "−10 % at albedo 0.97, −15 to −20 % at 0.9")),
        Method::Diffusion => Some((0.9, "16 % block error at albedo 0.8, 31 % at 0.5")),
        _ => None,
    }
}

/// The warning for `scene`, if its method is `full` or `diffusion` and a band of its albedo is
/// below the lowest that method was measured within budget at ([`measured_down_to`]).
pub fn warning(scene: &Scene) -> Option<String> {
    let m = scene.render.method;
    let (lowest, below) = measured_down_to(m)?;
    let albedo = scene.desc.medium.albedo.iter().copied().fold(f32::INFINITY, f32::min);
    if albedo >= lowest {
        return None;
    }
    Some(format!(
        "{}: medium.albedo {albedo} is below {lowest}, the lowest at which method {} was measured near its accuracy \
         budget against reference; below it the image comes out wrong ({below}; docs/accuracy.md, \"Albedo below 1\"); render \
         with --method transport (the default; within 2 % down to albedo 0.3 on the measured views, 4 % with isotropic \
         scattering)",
        scene.source,
        m.name()
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::SceneDesc;
    use std::path::Path;

    fn warning_for(albedo: [f32; 3], method: Method) -> Option<String> {
        let mut d = SceneDesc::default();
        d.medium.resolution = [20, 16, 12];
        d.medium.albedo = albedo;
        d.render.method = method;
        warning(&Scene::build(d, "s.toml", Path::new(".")).unwrap())
    }

    #[test]
    fn full_and_diffusion_warn_below_their_measured_albedo() {
        let w = warning_for([0.97, 0.97, 0.97], Method::Full).expect("full at 0.97");
        assert!(
            w.contains("method full") && w.contains("below 0.99") && w.contains("--method transport"),
            "{w}"
        );
        assert_eq!(warning_for([0.99, 0.99, 0.99], Method::Full), None);
        assert_eq!(warning_for([0.999, 0.999, 0.999], Method::Full), None);
        // One dark band is enough.
        assert!(warning_for([0.999, 0.999, 0.98], Method::Full).is_some());
        let w = warning_for([0.85, 0.85, 0.85], Method::Diffusion).expect("diffusion at 0.85");
        assert!(w.contains("method diffusion") && w.contains("below 0.9"), "{w}");
        assert_eq!(warning_for([0.9, 0.9, 0.9], Method::Diffusion), None);
    }

    #[test]
    fn the_other_methods_do_not_warn() {
        for m in [Method::Transport, Method::Reference, Method::Single] {
            assert_eq!(warning_for([0.3, 0.3, 0.3], m), None, "{m:?}");
        }
    }
}
