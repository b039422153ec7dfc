//! `full`'s dense source against `transport`'s, voxel by voxel, at the same δ-M (docs/accuracy.md,
//! "`full`'s parts, sun only"): `full` is run with `render.forward_fraction` set to transport's own
//! f = g^(order+1), so both solve the same medium; each voxel's diffuse source towards the camera
//! (radiance per unit scaled optical depth, the sun's single scattering left out of both) is
//! weighted by what the eye sees of it, ρ·T_eye (T_eye the exact transmittance to the camera), and
//! summed by the sun's δ-M depth τ′_⊙ = −ln T′_⊙ (transport's T′). Printed per bin: the bin's
//! share of transport's seen source; full's isotropic part a′I0 over transport's a′I_00·Y_00; each
//! method's source towards the eye over its own isotropic part (transport: its whole SH series;
//! full: a′(I0 + g′I1·ω), eq. 3); full's source towards the eye over transport's; transport's
//! source towards the eye with its series cut after l = 1 (the P1 closure's shape) and after l = 2,
//! over its whole series. `render.transport_order = 3` in the scene makes f = g⁴ = 0.656 for
//! g = 0.9, `full`'s own forward fraction.
//!
//! With OUT.exr (and MODE: none, i0, i1 or both) it instead renders `full`'s image with
//! transport's I0 and/or I1 (the l ≤ 1 moments of its diffuse field) in place of the
//! diffusion's: how far exact first moments would take `full` (docs/accuracy.md).
//!
//! `cargo run --release --features internals --example dense_source SCENE.toml [OUT.exr [MODE]]`

use cloudgi::pipeline::{NoProgress, Timings};
use cloudgi::render::full::propagate;
use cloudgi::render::transport::eye_source;
use cloudgi::scene::Scene;
use cloudgi::transport::solve::solve;
use std::path::Path;

/// Upper ends of the τ′_⊙ bins (the last bin is open).
const SUN_DEPTHS: [f64; 7] = [0.5, 1.0, 1.5, 2.0, 3.0, 5.0, 10.0];

fn main() {
    let path = std::env::args().nth(1).expect("usage: dense_source SCENE.toml");
    let mut scene = Scene::from_file(Path::new(&path)).unwrap_or_else(|e| panic!("{e}"));
    let g = scene.medium.optics.phase.mean_cosine() as f64;
    let f = g.powi(scene.render.transport.order as i32 + 1);
    scene.render.forward_fraction = f as f32;
    let field = solve(
        &scene.medium,
        &scene.sun,
        &scene.sky,
        scene.ground.as_ref(),
        &scene.render.transport,
        &NoProgress,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let (tr_diffuse, _) = eye_source(&scene, &field);
    let dm = cloudgi::render::delta_m(&scene).into_owned();
    let prop = propagate(&dm, &NoProgress, &mut Timings::default()).unwrap_or_else(|e| panic!("{e}"));
    if let Some(out) = std::env::args().nth(2) {
        swap_render(&dm, &field, &prop, &out, &std::env::args().nth(3).unwrap_or_else(|| "both".into()));
        return;
    }
    let (lit, m) = (&prop.lit, &dm.medium);
    let a = m.optics.albedo.y;
    let [nx, ny, nz] = m.dims();
    let eye = scene.camera.position;
    // Per bin: Σw·transport, Σw·full (isotropic), Σw·full (whole).
    let mut bins = vec![[0f64; 6]; SUN_DEPTHS.len() + 1];
    let nsh = cloudgi::math::sh_count(field.order);
    let mut y = vec![0f64; nsh];
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let v = i + nx * (j + ny * k);
                let rho = m.density.at(v);
                if rho <= 0.0 {
                    continue;
                }
                let c = m.voxel_center(i, j, k);
                let to_voxel = c - eye;
                let d = to_voxel.normalize_or_zero();
                let w = rho as f64 * scene.medium.transmittance(c, -d, 0.0, to_voxel.length()) as f64;
                let fi = field.full.slot(v) - 1;
                let tau_sun = -(field.sun_t[fi][1] as f64).max(1e-30).ln();
                let b = SUN_DEPTHS.iter().position(|&t| tau_sun < t).unwrap_or(SUN_DEPTHS.len());
                // The gather's own look-ups at the centre (m.to_voxel, the trilinear density).
                let i0 = lit.i0(m.to_voxel(c), m.density_at(c));
                bins[b][0] += w * tr_diffuse[fi].y as f64;
                bins[b][1] += w * (a * i0.y) as f64;
                bins[b][2] += w * (a * lit.diffuse_at(c, -d).y) as f64;
                // Transport's isotropic part a′I_00·Y_00 (band 1), Y_00 = 1/√(4π).
                bins[b][3] += w * field.diffuse_source[(fi * 3 + 1) * nsh] as f64 / (4.0 * std::f64::consts::PI).sqrt();
                // Transport's source towards the eye truncated to l ≤ 1 (the P1 closure's) and l ≤ 2.
                cloudgi::math::real_sh(field.order, -glam::DVec3::new(d.x as f64, d.y as f64, d.z as f64), &mut y);
                let js = &field.diffuse_source[(fi * 3 + 1) * nsh..(fi * 3 + 2) * nsh];
                bins[b][4] += w * js[..4].iter().zip(&y).map(|(j, y)| *j as f64 * y).sum::<f64>();
                bins[b][5] += w * js[..9].iter().zip(&y).map(|(j, y)| *j as f64 * y).sum::<f64>();
            }
        }
    }
    let total: f64 = bins.iter().map(|b| b[0]).sum();
    println!("{path}: f = {f:.3}");
    println!("| τ′_⊙ | share of transport's seen source | isotropic part: full / transport | towards the eye / isotropic: transport | full | towards the eye: full / transport | transport's l ≤ 1 / its whole | l ≤ 2 / whole |");
    println!("|---|---|---|---|---|---|---|---|");
    let mut lo = 0.0;
    let mut sums = [0f64; 6];
    for (b, s) in bins.iter().enumerate() {
        let hi = SUN_DEPTHS.get(b).map_or("∞".to_string(), |t| t.to_string());
        if s[0] > 0.0 {
            println!("| {lo}–{hi} | {:.3} | {} |", s[0] / total, ratios(s));
        }
        lo = SUN_DEPTHS.get(b).copied().unwrap_or(f64::INFINITY);
        for c in 0..6 {
            sums[c] += s[c];
        }
    }
    println!("| all | 1 | {} |", ratios(&sums));
}

/// The ratios of one bin's sums [transport, full isotropic, full whole, transport isotropic,
/// transport l ≤ 1, transport l ≤ 2].
fn ratios(s: &[f64; 6]) -> String {
    format!(
        "{:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3}",
        s[1] / s[3],
        s[0] / s[3],
        s[2] / s[1],
        s[2] / s[0],
        s[4] / s[0],
        s[5] / s[0]
    )
}

/// `full`'s image with transport's I0 and/or I1 (the first moments of its diffuse field) in
/// place of the diffusion's: `mode` none, i0, i1 or both.
fn swap_render(
    dm: &Scene,
    field: &cloudgi::transport::solve::TransportField,
    prop: &cloudgi::render::full::Propagation,
    out: &str,
    mode: &str,
) {
    use cloudgi::math::{Rgb, Vec3};
    let m = &dm.medium;
    let nsh = cloudgi::math::sh_count(field.order);
    let four_pi = 4.0 * std::f64::consts::PI;
    let (y00, c1) = (1.0 / four_pi.sqrt(), (3.0 / four_pi).sqrt());
    let n = m.dims().iter().product::<usize>();
    let own_i0 = cloudgi::render::diffusion::visible_i0_rgb(dm, &prop.incident, &prop.solution);
    let own_i1 = cloudgi::diffusion::flux::diffuse_flux(m, &prop.incident, &prop.solution, dm.render.solver.min_optical_depth);
    let tr = |v: usize| -> Option<[(f64, [f64; 3]); 3]> {
        let s = field.full.slot(v);
        (s > 0).then(|| {
            std::array::from_fn(|b| {
                let bo = &field.optics.bands[b];
                let js = &field.diffuse_source[((s - 1) * 3 + b) * nsh..((s - 1) * 3 + b + 1) * nsh];
                let i0 = js[0] as f64 * y00 / bo.albedo;
                let k = c1 / (bo.albedo * bo.chi[1]);
                (i0, [js[3] as f64 * k, js[2] as f64 * k, js[1] as f64 * k])
            })
        })
    };
    let i0: Vec<Rgb> = (0..n)
        .map(|v| match (tr(v), mode == "i0" || mode == "both") {
            (Some(t), true) => Rgb::new(t[0].0 as f32, t[1].0 as f32, t[2].0 as f32),
            _ => own_i0[v],
        })
        .collect();
    let i1 = |v: usize| -> [Vec3; 3] {
        match (tr(v), mode == "i1" || mode == "both") {
            (Some(t), true) => t.map(|(_, a)| Vec3::new(a[0] as f32, a[1] as f32, a[2] as f32)),
            _ => own_i1(v),
        }
    };
    let lit = cloudgi::lit::LitVolume::new(m.clone(), i0, prop.lit.sun_t().clone(), dm.sun.clone(), dm.sky.clone(), None)
        .with_ground(prop.lit.ground.clone())
        .with_flux(cloudgi::diffusion::flux::FluxField::new(m, i1));
    let img = cloudgi::render::full::gather(dm, &lit, &NoProgress);
    img.write_exr(Path::new(out)).unwrap_or_else(|e| panic!("{e}"));
}
