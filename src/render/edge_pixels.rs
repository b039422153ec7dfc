//! Anti-aliasing of a one-sample image's edges, shared by `transport` and `full`: a point sample
//! on an edge is the wrong estimate of the pixel's mean. At `sunset` (docs/accuracy.md) the
//! cloud's sunlit base meets the ground inside one pixel row, and its centre sample read the
//! bright base (+45 % on that row, +2.6 % over the cloud for `transport`).

use crate::math::Rgb;

/// Sub-pixels per pixel edge where a one-sample image has an edge: a stratified grid of
/// [`EDGE_SAMPLES`] = `EDGE_GRID`² samples ([`crate::render::single::pixel_sample`]'s strata,
/// sample s at column s mod `EDGE_GRID`, row s div `EDGE_GRID`).
pub const EDGE_GRID: u32 = 4;

/// Samples per pixel where a one-sample image has an edge ([`refine_edges`]).
pub const EDGE_SAMPLES: u32 = EDGE_GRID * EDGE_GRID;

/// Relative luminance step between neighbouring pixels above which both are re-shaded with
/// [`EDGE_SAMPLES`].
const EDGE_CONTRAST: f32 = 0.1;

/// The edges of a one-sample image whose pixels are split into `N` parts (AOVs) that add up to
/// the pixel, in row-major order: the pixels whose luminance differs from one of their eight
/// neighbours' by more than [`EDGE_CONTRAST`] of the larger.
pub fn edge_pixels<const N: usize>(px: &[[Rgb; N]], width: u32) -> Vec<usize> {
    let (w, h) = (width as usize, px.len() / width.max(1) as usize);
    let lum: Vec<f32> = px
        .iter()
        .map(|p| p.iter().fold(Rgb::ZERO, |a, c| a + *c).dot(Rgb::new(0.2126, 0.7152, 0.0722)))
        .collect();
    let edge = |i: usize| {
        let (x, y) = ((i % w) as i64, (i / w) as i64);
        (-1..=1).flat_map(|dy| (-1..=1).map(move |dx| (x + dx, y + dy))).any(|(nx, ny)| {
            if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                return false;
            }
            let (a, b) = (lum[i], lum[nx as usize + w * ny as usize]);
            (a - b).abs() > EDGE_CONTRAST * a.max(b)
        })
    };
    (0..px.len()).filter(|&i| edge(i)).collect()
}

/// Re-shade the [`edge_pixels`] of a one-sample image with `shade` (the pixel's mean over a
/// stratified grid of [`EDGE_SAMPLES`], as `reference` integrates the pixel's box). The edges
/// come from the first pass only, so the result does not depend on the thread count. Returns
/// the number of pixels re-shaded.
pub fn refine_edges<const N: usize>(px: &mut [[Rgb; N]], width: u32, shade: impl Fn(u32, u32) -> [Rgb; N] + Sync) -> usize {
    let w = width.max(1) as usize;
    let edges = edge_pixels(px, width);
    let shaded: Vec<[Rgb; N]> = crate::par::map_range(edges.len(), &|e| shade((edges[e] % w) as u32, (edges[e] / w) as u32));
    let n = edges.len();
    for (i, p) in edges.into_iter().zip(shaded) {
        px[i] = p;
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_pixels_beside_an_edge_are_reshaded() {
        // 5×3, a step between columns 1 and 2 (luminance 1 → 2), and a 5 % ripple at (4, 0);
        // the step lies in the first part, or in the second (the parts' sum is what is judged).
        let (w, h) = (5u32, 3u32);
        for part in 0..2 {
            let mut px: Vec<[Rgb; 2]> = (0..w * h)
                .map(|i| {
                    let (x, y) = (i % w, i / w);
                    let v = if x < 2 {
                        1.0
                    } else if (x, y) == (4, 0) {
                        2.1
                    } else {
                        2.0
                    };
                    let mut p = [Rgb::splat(0.5); 2];
                    p[part] = Rgb::splat(v);
                    p
                })
                .collect();
            let n = refine_edges(&mut px, w, |_, _| [Rgb::splat(-1.0), Rgb::ZERO]);
            assert_eq!(n, 6);
            for (i, p) in px.iter().enumerate() {
                let x = i as u32 % w;
                assert_eq!(p[0].x == -1.0, x == 1 || x == 2, "part {part}, pixel {i}: {:?}", p[0]);
            }
        }
    }
}
