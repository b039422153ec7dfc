//! A warning when a fast method renders a strongly back-scattering medium (g below −0.9): their
//! phase expansions (transport's order-L series, `full`'s orders) hold a backward peak poorly, and
//! the image comes out too bright; `reference` renders it exactly.

use crate::scene::{Method, Scene};

/// The g below which the fast methods are warned about.
const WARN_BELOW_G: f32 = -0.9;

/// What each fast method measured below [`WARN_BELOW_G`] (docs/accuracy.md, "Extreme phase
/// functions": the built-in cumulus at 20×16×12 voxels, 32×24 pixels, `reference` at 512 paths
/// per pixel; cloud block bias): `transport` +3 % at g = −0.9, +10 % at −0.95, +44 % at −0.99;
/// `full` +4 %, +7 %, +17 %; `diffusion` +31 %, +41 %, +61 %.
fn measured(method: Method) -> Option<&'static str> {
    match method {
        Method::Transport => Some("+10 % at g = −0.95, +44 % at −0.99"),
        Method::Full => Some("+7 % at g = −0.95, +17 % at −0.99"),
        Method::Diffusion => Some("+41 % at g = −0.95, +61 % at −0.99"),
        Method::Single | Method::Reference => None,
    }
}

/// The warning for `scene`, if its method is a fast one that multiply scatters and its g is below
/// [`WARN_BELOW_G`].
pub fn warning(scene: &Scene) -> Option<String> {
    let m = scene.render.method;
    let bias = measured(m)?;
    let g = scene.desc.medium.g;
    if g >= WARN_BELOW_G {
        return None;
    }
    Some(format!(
        "{}: medium.g = {g} scatters strongly backwards, which method {}'s phase expansion holds poorly: the image \
         comes out too bright ({bias} on the built-in cumulus; docs/accuracy.md, \"Extreme phase functions\"); render \
         with --method reference for the exact image",
        scene.source,
        m.name()
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::SceneDesc;
    use std::path::Path;

    fn warning_for(g: f32, method: Method) -> Option<String> {
        let mut d = SceneDesc::default();
        d.medium.resolution = [20, 16, 12];
        d.medium.g = g;
        d.render.method = method;
        warning(&Scene::build(d, "s.toml", Path::new(".")).unwrap())
    }

    #[test]
    fn the_fast_methods_warn_below_minus_0_9_and_reference_never() {
        for m in [Method::Transport, Method::Full, Method::Diffusion] {
            let w = warning_for(-0.95, m).expect("g = −0.95");
            assert!(
                w.contains("s.toml") && w.contains("medium.g = -0.95") && w.contains("--method reference"),
                "{w}"
            );
            assert_eq!(warning_for(-0.9, m), None);
            assert_eq!(warning_for(0.9, m), None);
        }
        assert_eq!(warning_for(-0.99, Method::Reference), None);
        assert_eq!(warning_for(-0.99, Method::Single), None);
    }
}
