//! How finely the voxels resolve the layer where light enters the cloud. Along every grid line of
//! the three axes, in both directions, light from outside crosses the dual cells between voxel
//! centres (ρ linear between two centres, as the trilinear field is along a grid line). The first
//! cell in which its optical depth from outside reaches 1 holds the layer that the light leaving
//! the cloud comes from (its radiance is about the source at one optical depth,
//! Eddington–Barbier). Every deterministic method holds one value of the light per voxel: where
//! that cell is many optical depths thick, the layer is not resolved and the image comes out dark
//! (docs/accuracy.md, "Optically thick voxels").

use super::Medium;

/// The optical depths (σt · h · mean ρ, unitless, h the voxel's side along the line) of the dual
/// cells in which light entering along a grid line first reaches one optical depth: one per grid
/// line and direction that reaches it.
pub fn entry_cell_depths(m: &Medium) -> Vec<f32> {
    entry_cells(m).into_iter().map(|(depth, _)| depth).collect()
}

/// [`entry_cell_depths`], each with the axis of its grid line (0, 1, 2: x, y, z).
fn entry_cells(m: &Medium) -> Vec<(f32, usize)> {
    let Some((lo, hi)) = m.active_box(0) else {
        return Vec::new();
    };
    let sigma_t = m.optics.sigma_t as f64;
    let h = [m.voxel_size.x as f64, m.voxel_size.y as f64, m.voxel_size.z as f64];
    let lines: Vec<(usize, usize, usize)> = (0..3)
        .flat_map(|a| {
            let (b, c) = ((a + 1) % 3, (a + 2) % 3);
            (lo[b]..hi[b]).flat_map(move |jb| (lo[c]..hi[c]).map(move |jc| (a, jb, jc)))
        })
        .collect();
    let line_depths = |&(a, jb, jc): &(usize, usize, usize)| {
        let (b, c) = ((a + 1) % 3, (a + 2) % 3);
        // The line's densities from one empty centre before the active box to one after.
        let rho: Vec<f64> = (lo[a] as isize - 1..=hi[a] as isize)
            .map(|ka| {
                let mut v = [0isize; 3];
                v[a] = ka;
                v[b] = jb as isize;
                v[c] = jc as isize;
                m.density.get_or_zero(v[0], v[1], v[2]) as f64
            })
            .collect();
        let cell = |p: f64, q: f64| sigma_t * h[a] * 0.5 * (p + q);
        let forward = first_cell_past_one(rho.windows(2).map(|w| cell(w[0], w[1])));
        let backward = first_cell_past_one(rho.windows(2).rev().map(|w| cell(w[0], w[1])));
        forward.into_iter().chain(backward).map(move |d| (d, a))
    };
    // Lines per task: a few hundred; the tasks' depths joined in the lines' order.
    const LINES: usize = 256;
    crate::par::map_range(lines.len().div_ceil(LINES), &|ci| {
        lines[ci * LINES..((ci + 1) * LINES).min(lines.len())].iter().flat_map(line_depths).collect::<Vec<_>>()
    })
    .concat()
}

/// The first of `cells` (optical depths, in the order light crosses them) in which the optical
/// depth from the first one's entry reaches 1.
fn first_cell_past_one(cells: impl Iterator<Item = f64>) -> Option<f32> {
    let mut tau = 0.0;
    for cell in cells {
        if tau + cell >= 1.0 {
            return Some(cell as f32);
        }
        tau += cell;
    }
    None
}

/// The median of [`entry_cell_depths`] over the cloud's surface (`None`: no grid line reaches one
/// optical depth): each line stands for the voxel face it enters through, of area h_b · h_c across
/// its axis, so light entering a cloud of flat voxels through their broad faces counts for their
/// area and the thin edges their few square metres. With cubic voxels every line weighs the same.
pub fn median_entry_cell_depth(m: &Medium) -> Option<f32> {
    let mut cells = entry_cells(m);
    if cells.is_empty() {
        return None;
    }
    let h = m.voxel_size.to_array().map(f64::from);
    let face = |a: usize| h[(a + 1) % 3] * h[(a + 2) % 3];
    let largest = face(0).max(face(1)).max(face(2));
    // Relative to the largest face: 1 exactly for cubic voxels, where the sums below then count.
    let weight = [0, 1, 2].map(|a| face(a) / largest);
    cells.sort_unstable_by(|p, q| p.0.total_cmp(&q.0));
    let half = 0.5 * cells.iter().map(|c| weight[c.1]).sum::<f64>();
    let mut below = 0.0;
    // The first cell past half the surface: the upper median for cubic voxels, as `len / 2`.
    cells.iter().find(|c| {
        below += weight[c.1];
        below > half
    }).map(|c| c.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Rgb, Vec3};
    use crate::medium::Grid3;

    /// A box of density 1 with one empty voxel around it, `sigma_t` per metre, 2-m voxels.
    fn uniform_box(sigma_t: f32) -> Medium {
        box_of(sigma_t, Vec3::splat(2.0))
    }

    /// [`uniform_box`] with voxels of edges `voxel`.
    fn box_of(sigma_t: f32, voxel: Vec3) -> Medium {
        let dims = [8, 7, 6];
        let mut g = Grid3::filled(dims, 0.0);
        for k in 1..dims[2] - 1 {
            for j in 1..dims[1] - 1 {
                for i in 1..dims[0] - 1 {
                    g.set(i, j, k, 1.0);
                }
            }
        }
        Medium::new(g, Vec3::ZERO, voxel, sigma_t, Rgb::ONE, 0.0)
    }

    #[test]
    fn a_thick_uniform_box_is_entered_through_its_first_half_voxel() {
        // σt·h = 10: the half voxel from the empty centre to the first full one holds 5.
        let depths = entry_cell_depths(&uniform_box(5.0));
        // Every grid line through the box's 6×5×4 full voxels, both ways.
        assert_eq!(depths.len(), 2 * (5 * 4 + 4 * 6 + 6 * 5));
        assert!(depths.iter().all(|d| *d == 5.0), "{depths:?}");
        assert_eq!(median_entry_cell_depth(&uniform_box(5.0)), Some(5.0));
    }

    #[test]
    fn flat_voxels_count_the_light_entering_through_their_broad_faces() {
        // 1 × 1 × 0.05 m voxels: σt·h is 1 across the thin axis and 20 along the others.
        let flat = box_of(20.0, Vec3::new(1.0, 1.0, 0.05));
        // Most grid lines run along x and y, entering in a half voxel 10 optical depths thick,
        // but through the 0.05-m² edges; the 1-m² faces take the light in cells of 1.
        let depths = entry_cell_depths(&flat);
        assert_eq!(depths.iter().filter(|d| **d == 10.0).count(), 2 * (5 * 4 + 4 * 6), "{depths:?}");
        assert_eq!(median_entry_cell_depth(&flat), Some(1.0));
    }

    #[test]
    fn a_thin_uniform_box_reaches_one_optical_depth_in_its_interior() {
        // σt·h = 0.5: cells of 0.25 then 0.5, 0.5: one optical depth is reached in the third.
        assert_eq!(median_entry_cell_depth(&uniform_box(0.25)), Some(0.5));
        // σt·h = 0.1: the longest line, 6 full voxels and two empty half voxels, holds 0.6.
        assert_eq!(median_entry_cell_depth(&uniform_box(0.05)), None);
    }
}
