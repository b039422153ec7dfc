//! The paper's speed-up for the final gather (section 4): K_ij changes slowly across the image
//! where the cube centres c_j of neighbouring pixels lie at similar depths, so it is computed on a
//! sparse lattice and bilinearly interpolated, refining as a quadtree where depths differ.
//!
//! Each pixel's top-level segment j is matched, at each corner of its quadtree square, with the
//! corner pixel's segment whose centre distance is nearest; if all corners that carry weight match
//! within `depth_tolerance`, K is interpolated from the corners' K (each rendered once, on demand,
//! and cached per pixel and segment). Otherwise the square is halved, down to the pixel itself;
//! on squares of at most `partial_size` pixels the corners that match suffice (renormalised
//! weights), so a silhouette's pixels seldom need their own cube.
//! Squares start at `block` pixels (the paper's 8; its 9×9 vertex blocks), or at `coarse_block`
//! (16) where the four corners match and the cube part of E_j they give the pixel agrees within
//! `smooth_tolerance` (3 %): there the inner lattice's cubes are not needed. Only whole, unbridged
//! segments are interpolated; bridge variants (rare) always get their own cube. The q_ij and the
//! sun's orders are evaluated per pixel, as in the paper.
//!
//! The paper's further split of each cube into three parts sampled at 8, 4 and 2 pixels (rear five
//! faces, front face at doubled resolution, central quarter) is not implemented: it needs partial
//! cube renders from the cube renderer. See docs/edges.md for measured time and error.

use super::gather::{EdgeAov, EdgeGather};
use super::segments::LowSegment;
use crate::math::{Rgb, Vec3};
use crate::par;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::OnceLock;

/// Pixels per parallel task: a row of 480 in about eight tasks, enough tasks to balance the
/// pixels' uneven cost (a pixel through the cloud gathers cubes, one beside it none).
const PIXELS_PER_TASK: usize = 64;

/// One pixel's camera ray.
#[derive(Clone, Copy, Debug, Default)]
pub struct PixelRay {
    /// Origin (m).
    pub o: Vec3,
    /// Unit direction.
    pub d: Vec3,
    /// End of the medium part (m): the ground hit or infinity.
    pub t_max: f32,
    /// Radiance arriving from beyond (sky or ground).
    pub background: Rgb,
}

/// Settings of the sparse gather.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SparseSettings {
    /// Initial square size in pixels (a power of two; the paper's 8).
    pub block: u32,
    /// Largest difference of cube-centre distance (m) between a pixel and a corner for interpolation.
    /// 150 m: on the default scene (480×360) 1919 cubes instead of 4323 at 40 m, image within
    /// 8·10⁻⁶ mean relative difference over the cloud; the five evaluation scenes within 6·10⁻⁴
    /// (closeup; the rest ≤ 1.1·10⁻⁴), none changing between 100 and 200 m.
    pub depth_tolerance: f32,
    /// Squares of at most this many pixels (a power of two; 0: none) whose corners do not all
    /// match interpolate from the corners that do, weights renormalised, instead of halving
    /// down to the pixel's own cube. These are the silhouettes' pixels, where a corner's ray
    /// hits another part of the cloud. 4: on the default scene 1156 cubes instead of 2031
    /// (the gather's cubes ~40 % cheaper), image within 3·10⁻⁵ block MRE on it and the five
    /// evaluation scenes; 8 reaches 3·10⁻³ (backlit).
    pub partial_size: u32,
    /// Squares larger than `block`, up to this size (a power of two; ≤ `block`: none), are tried
    /// first where K is smooth: all four corners must match in depth and the cube part of E_j
    /// their K give this pixel's segment (Σ q_i a^i K_i) agree within `smooth_tolerance`, else
    /// the square is halved as usual. Where the cloud's light changes little across a square,
    /// its inner lattice cubes are never rendered.
    pub coarse_block: u32,
    /// Largest spread of the corners' cube part of E_j, per band, relative to the largest band
    /// of their mean, for interpolating over a coarse square.
    pub smooth_tolerance: f32,
}

impl Default for SparseSettings {
    fn default() -> Self {
        SparseSettings {
            block: 8,
            depth_tolerance: 150.0,
            partial_size: 4,
            coarse_block: 16,
            smooth_tolerance: 0.03,
        }
    }
}

/// Counts from one image gather.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GatherStats {
    /// Cubes rendered.
    pub cubes: u64,
    /// Segments whose K was interpolated.
    pub interpolated: u64,
    /// Segments whose K came from their own cube.
    pub direct: u64,
}

/// Gather a `width`×`height` image. `ray(x, y)` gives each pixel's ray. With `sparse` = None every
/// segment renders its own cube (the reference); otherwise K is interpolated where allowed.
/// Pixels in row-major order. Deterministic at any thread count: every cached K is a pure
/// function of its pixel and segment.
pub fn gather_image(
    g: &EdgeGather,
    width: u32,
    height: u32,
    ray: &(dyn Fn(u32, u32) -> PixelRay + Sync),
    sparse: Option<SparseSettings>,
) -> (Vec<EdgeAov>, GatherStats) {
    gather_pixels(g, width, height, ray, sparse, &|_| true)
}

/// [`gather_image`] for the pixels `wanted(row-major index)` only; the others are left
/// [`EdgeAov::default`] (a wanted pixel's interpolation still reads the lattice's corners).
pub fn gather_pixels(
    g: &EdgeGather,
    width: u32,
    height: u32,
    ray: &(dyn Fn(u32, u32) -> PixelRay + Sync),
    sparse: Option<SparseSettings>,
    wanted: &(dyn Fn(usize) -> bool + Sync),
) -> (Vec<EdgeAov>, GatherStats) {
    let (w, h) = (width as usize, height as usize);
    let cubes = AtomicU64::new(0);
    let interp = AtomicU64::new(0);
    let direct = AtomicU64::new(0);
    let Some(sp) = sparse else {
        let px: Vec<EdgeAov> = par::map_items(w * h, PIXELS_PER_TASK, &|i| {
            if !wanted(i) {
                return EdgeAov::default();
            }
            let r = ray((i % w) as u32, (i / w) as u32);
            g.radiance(r.o, r.d, r.t_max, r.background)
        });
        let n: u64 = px.iter().map(|a| a.cubes as u64).sum();
        return (
            px,
            GatherStats {
                cubes: n,
                interpolated: 0,
                direct: n,
            },
        );
    };
    let rays: Vec<PixelRay> = par::map_items(w * h, PIXELS_PER_TASK, &|i| ray((i % w) as u32, (i / w) as u32));
    // Top-level segments of a pixel (no cubes) with a K cache per segment, made on first use: only
    // the quadtree's corners and the pixels that fall back to their own cube ever need them
    // (a quarter of the profiles a pass over every pixel would trace).
    let tops: Vec<OnceLock<PixelTops>> = (0..w * h).map(|_| OnceLock::new()).collect();
    let top = |i: usize| -> &PixelTops {
        tops[i].get_or_init(|| {
            let r = rays[i];
            let t = g.settings().threshold;
            let mut prof = g.profile(r.o, r.d, r.t_max, &[t]);
            let surface_end = g.cut_surface(&mut prof);
            let segs = g.top_segments(&prof, surface_end);
            let k = (0..segs.len()).map(|_| OnceLock::new()).collect();
            PixelTops { segs, k }
        })
    };
    // K of segment j of pixel i, from its own cube (cached).
    let own_k = |i: usize, j: usize| -> &Vec<Rgb> {
        let t = top(i);
        t.k[j].get_or_init(|| {
            cubes.fetch_add(1, Ordering::Relaxed);
            let seg = &t.segs[j];
            // Enough orders for the deeper segments that may borrow this K.
            let orders = g.orders_for(seg).max(8) * 2;
            g.segment_k(rays[i].o, rays[i].d, seg, orders)
        })
    };
    let block = sp.block.max(1).next_power_of_two() as usize;
    let coarse = (sp.coarse_block.max(1).next_power_of_two() as usize).max(block);
    let px: Vec<EdgeAov> = par::map_items(w * h, PIXELS_PER_TASK, &|i| {
        if !wanted(i) {
            return EdgeAov::default();
        }
        let (x, y) = (i % w, i / w);
        let r = rays[i];
        let plan = g.plan(r.o, r.d, r.t_max);
        let mut n_cubes = 0u32;
        let e: Vec<Rgb> = plan
            .jobs
            .iter()
            .map(|job| {
                let Some(_) = job.top else {
                    n_cubes += 1;
                    cubes.fetch_add(1, Ordering::Relaxed);
                    direct.fetch_add(1, Ordering::Relaxed);
                    return g.segment_radiance(&plan, &job.seg);
                };
                // The plan's top segments are the same as `top(i).segs` (same threshold and surface
                // layer) but its profile is also cut at T_lo: match by centre distance.
                let tc = job.seg.t_center;
                let mut q = None;
                let mut s = coarse;
                while s > 1 {
                    let (x0, y0) = ((x / s) * s, (y / s) * s);
                    if x0 == x && y0 == y {
                        break;
                    }
                    let (x1, y1) = ((x0 + s).min(w - 1), (y0 + s).min(h - 1));
                    let fx = if x1 > x0 { (x - x0) as f32 / (x1 - x0) as f32 } else { 0.0 };
                    let fy = if y1 > y0 { (y - y0) as f32 / (y1 - y0) as f32 } else { 0.0 };
                    let corners = [
                        (x0, y0, (1.0 - fx) * (1.0 - fy)),
                        (x1, y0, fx * (1.0 - fy)),
                        (x0, y1, (1.0 - fx) * fy),
                        (x1, y1, fx * fy),
                    ];
                    let mut ok = true;
                    let mut picks = [(0usize, 0usize, 0f32); 4];
                    // On small squares (corners at most `partial_size` pixels away) the
                    // corners that match are enough: their weights are renormalised.
                    let partial = s <= sp.partial_size as usize;
                    // Above `block` only a whole square whose corners' K agree.
                    let smooth_only = s > block;
                    let mut matched = 0f32;
                    for (c, &(cx, cy, wt)) in corners.iter().enumerate() {
                        if wt <= 0.0 {
                            continue;
                        }
                        let ci = cy * w + cx;
                        match nearest(&top(ci).segs, tc) {
                            Some((j, dist)) if dist <= sp.depth_tolerance as f64 => {
                                picks[c] = (ci, j, wt);
                                matched += wt;
                            }
                            _ => {
                                ok = false;
                                if !partial {
                                    break;
                                }
                            }
                        }
                    }
                    if ok && smooth_only {
                        let es: Vec<Rgb> = picks
                            .iter()
                            .filter(|p| p.2 > 0.0)
                            .map(|&(ci, j, _)| g.cube_part(q.get_or_insert_with(|| g.orders(job.seg.depth)), own_k(ci, j)))
                            .collect();
                        ok = agree(&es, sp.smooth_tolerance);
                    }
                    if !ok && partial && matched > 0.0 {
                        for p in &mut picks {
                            p.2 /= matched;
                        }
                        ok = true;
                    }
                    if ok {
                        let mut k: Vec<Rgb> = Vec::new();
                        for &(ci, j, wt) in picks.iter().filter(|p| p.2 > 0.0) {
                            let kc = own_k(ci, j);
                            if k.len() < kc.len() {
                                let last = k.last().copied().unwrap_or(Rgb::ZERO);
                                k.resize(kc.len(), last);
                            }
                            for (a, b) in k.iter_mut().zip(kc.iter().chain(std::iter::repeat(&kc[kc.len() - 1]))) {
                                *a += *b * wt;
                            }
                        }
                        interp.fetch_add(1, Ordering::Relaxed);
                        return g.segment_radiance_from_k(&plan, &job.seg, &k);
                    }
                    s /= 2;
                }
                direct.fetch_add(1, Ordering::Relaxed);
                match nearest(&top(i).segs, tc).map(|(j, _)| j) {
                    Some(j) => g.segment_radiance_from_k(&plan, &job.seg, own_k(i, j)),
                    None => {
                        n_cubes += 1;
                        cubes.fetch_add(1, Ordering::Relaxed);
                        g.segment_radiance(&plan, &job.seg)
                    }
                }
            })
            .collect();
        let mut a = g.composite(&plan, &e, r.background);
        a.cubes = n_cubes;
        a
    });
    (
        px,
        GatherStats {
            cubes: cubes.into_inner(),
            interpolated: interp.into_inner(),
            direct: direct.into_inner(),
        },
    )
}

/// A pixel's top-level segments and the K of each from its own cube.
struct PixelTops {
    segs: Vec<LowSegment>,
    k: Vec<OnceLock<Vec<Rgb>>>,
}

/// Whether the corners' values agree: each band of each within `tol` times the largest band of
/// their mean.
fn agree(es: &[Rgb], tol: f32) -> bool {
    let mean = es.iter().fold(Rgb::ZERO, |a, b| a + *b) / es.len().max(1) as f32;
    let bound = tol * mean.max_element();
    es.iter().all(|e| (*e - mean).abs().max_element() <= bound)
}

/// The segment whose centre distance is nearest `tc`, and that distance.
fn nearest(segs: &[LowSegment], tc: f64) -> Option<(usize, f64)> {
    segs.iter()
        .enumerate()
        .map(|(j, s)| (j, (s.t_center - tc).abs()))
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corners_agree_within_the_tolerance_of_their_mean() {
        let es = [Rgb::new(1.0, 2.0, 0.5), Rgb::new(1.25, 2.0, 0.5), Rgb::new(0.75, 2.0, 0.5)];
        // The mean's largest band is 2; the spread is 0.25 (band 0): agree at 12.5 %, not at 12 %.
        assert!(agree(&es, 0.125));
        assert!(!agree(&es, 0.12));
        assert!(agree(&[Rgb::ZERO; 4], 0.0));
    }
}
