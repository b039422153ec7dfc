//! A warning when `full` or `diffusion` renders a medium darker (lower albedo) than the lowest at
//! which it was measured within its accuracy budget against `reference` (≤ 12 % block error,
//! |bias| ≤ 6 %; docs/accuracy.md, "Albedo below 1"), pointing to `transport`.

use crate::scene::{Method, Scene};

/// The lowest albedo at which `method` was measured within budget, and what it measured below it.
/// From the albedo sweep of docs/accuracy.md (the built-in cumulus, sun035's view, g = 0.9, 64×48,
/// `reference` at 2048 paths per pixel): `full` within budget down to 0.8 (5.6 % block error,
/// −0.7 % bias), 13.7 % at 0.65 and 23 % at 0.5; `diffusion` down to 0.9 (6.5 %, −4.4 %), 14.5 % and
/// −7.4 % at 0.8. `transport` is within 3 % bias at every albedo of the sweep (0.3–0.999).
fn measured_down_to(method: Method) -> Option<(f32, &'static str)> {
    match method {
        Method::Full => Some((0.8, "13.7 % block error at albedo 0.65, 23 % at 0.5")),
        Method::Diffusion => Some((0.9, "14.5 % block error and −7.4 % bias at albedo 0.8, 32 % at 0.5")),
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
        "{}: medium.albedo {albedo} is below {lowest}, the lowest at which method {} was measured within 12 % \
         block error of reference ({below}; docs/accuracy.md, \"Albedo below 1\"); render with --method transport \
         (the default; within 3 % bias down to albedo 0.3)",
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
        let w = warning_for([0.7, 0.7, 0.7], Method::Full).expect("full at 0.7");
        assert!(
            w.contains("method full") && w.contains("below 0.8") && w.contains("--method transport"),
            "{w}"
        );
        assert_eq!(warning_for([0.8, 0.8, 0.8], Method::Full), None);
        // One dark band is enough.
        assert!(warning_for([0.99, 0.9, 0.7], Method::Full).is_some());
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
