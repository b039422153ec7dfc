//! The sweeps (module docs of [`super::solve`]): for an ordinate Ω, the axis a with the largest
//! |Ω_a|/h_a orders the voxel planes upwind. A voxel's centre looks back along −Ω to the plane of
//! the previous centres, a distance s = h_a/|Ω_a|; there, the radiance, source and density are
//! bilinear in the four upwind centres (the offsets are ≤ 1 voxel because a is the major axis).
//! Across the step the source is linear in optical path and integrated exactly:
//! I = I_b e^{−τ} + w_in S_b + w_out S (τ = σt′ s (ρ_b + ρ)/2). Empty voxels carry the radiance
//! unchanged. Outside the swept box the ordinate sees the sky or, going up, the ground
//! ([`GroundMap`]); light leaving the box downwards is splatted onto the ground map.

use super::grid::{cross_axes, Ctx, PREFETCH_AHEAD};
use super::ground::GroundMap;
use super::simd::has_avx;
use super::source::{moments_block, source_block, Lanes, PairTables, ORDINATE_BATCH, PAIRS};
use super::sphere::Quadrature;
use lanes::Vector;
use step::{record, step_row, Plane, Step};
use glam::DVec3;

mod ground_cut;
mod lanes;
mod step;

/// The per-voxel array of a sweep batch: per ordinate slot and full voxel, the source in that
/// ordinate, which its sweep replaces by the radiance (12 B × [`ORDINATE_BATCH`] per full voxel).
/// Made once per solve, so the iterations write pages already mapped.
pub(super) struct BatchArrays {
    light: Vec<[f32; 3]>,
}

impl BatchArrays {
    /// The array for `nfull` full voxels.
    pub(super) fn new(nfull: usize) -> BatchArrays {
        BatchArrays {
            light: vec![[0f32; 3]; ORDINATE_BATCH * nfull],
        }
    }
}

/// One sweep of every ordinate: the diffuse radiance moments I_lm per full voxel (inner harmonic
/// order) into `next`, and how much the cloud changes the ground's downward irradiance, per
/// ground map column.
///
/// `moments` are the last iterate's; the source J(Ω) = Σ a′χ′_l (I_lm + E T′ Y_lm(Ω_sun)) Y_lm(Ω)
/// is evaluated from them directly (no array of source coefficients is stored). Ordinates go in
/// batches of opposite pairs: (1) per full voxel, the source in both ordinates of each pair of the
/// batch from one pass over its coefficients; (2) the batch's sweeps, one ordinate per task, each
/// replacing its source by its radiance; (3) per full voxel, the moments of both ordinates of each
/// pair in one pass, the pairs in their fixed order (the first batch writes `next`, the others add
/// to it).
pub(super) fn sweep(
    c: &Ctx,
    q: &Quadrature,
    t: &PairTables,
    moments: &[f32],
    next: &mut [f32],
    ground: &GroundMap,
    arrays: &mut BatchArrays,
) -> Vec<[f64; 3]> {
    let nsh = c.nsh;
    let nfull = moments.len() / (3 * nsh);
    let light = &mut arrays.light;
    assert!(light.len() == ORDINATE_BATCH * nfull, "the batch array for these full voxels");
    // Change of the ground's downward irradiance by the cloud, per ground map column (W/m²).
    let mut e_down = vec![[0f64; 3]; ground.radiance.len()];
    // Full voxels per task in the per-voxel steps (1) and (3).
    let chunk = 256;
    for (bi, first) in (0..t.pairs.len()).step_by(PAIRS).enumerate() {
        let batch = first..(first + PAIRS).min(t.pairs.len());
        // (1) Source in each ordinate, clamped at 0 (the truncated expansion may dip); slot 2p
        // holds pair p's ordinate d, 2p + 1 its opposite.
        // Each task writes its voxels' entries of every slot: the slots' chunks, task by task.
        let mut slots: Vec<_> = light.chunks_mut(nfull.max(1)).map(|slot| slot.chunks_mut(chunk)).collect();
        let outs: Vec<Vec<&mut [[f32; 3]]>> = (0..nfull.div_ceil(chunk))
            .map(|_| slots.iter_mut().filter_map(Iterator::next).collect())
            .collect();
        let block_len = chunk * 3 * nsh;
        crate::par::map_each(outs, &|ci, mut out| {
            let block = &moments[ci * block_len..((ci + 1) * block_len).min(moments.len())];
            source_block(c, t, bi, batch.len(), block, ci * chunk, &mut out)
        });
        // (2) The sweeps.
        let dirs: Vec<usize> = batch.clone().flat_map(|p| t.pairs[p]).collect();
        let wts: Vec<f32> = batch.clone().flat_map(|p| t.weights[p]).collect();
        // One task per ordinate of the batch, each on its own slot of `light`.
        let swept = (dirs.len() * nfull.max(1)).min(light.len());
        let splats: Vec<Splats> = crate::par::map_chunks(&mut light[..swept], nfull.max(1), &|o, ld| {
            sweep_ordinate(c, q.dirs[dirs[o]], q.weights[dirs[o]], ground, ld)
        });
        let radiance = &**light;
        for splats in &splats {
            for (col, e) in splats {
                for band in 0..3 {
                    e_down[*col][band] += e[band];
                }
            }
        }
        // (3) Moments: I_lm += w I(Ω) Y_lm(Ω) + w′ I(−Ω) (−1)^l Y_lm(Ω).
        let nblk = t.y_acc.len() / t.pairs.len().div_ceil(PAIRS);
        let yb = &t.y_acc[bi * nblk..(bi + 1) * nblk];
        let lanes = Lanes {
            nfull,
            wts: &wts,
            radiance,
            y: yb,
            first: bi == 0,
            active: t.moment_active,
        };
        crate::par::for_chunks(next, chunk * 3 * nsh, &|ci, block| moments_block(c, &lanes, block, ci * chunk));
    }
    e_down
}

/// One ordinate's ground splats (map column, change of the downward irradiance in W/m² per band).
pub(super) type Splats = Vec<(usize, [f64; 3])>;

/// Sweep one ordinate `om` (weight `w`, sr) through the box upwind plane by plane: the radiance at
/// every full voxel's centre, and the ground splats (column, change of downward irradiance, W/m²)
/// of the light leaving the box downwards. `light` holds the source in this ordinate per full
/// voxel and receives the radiance there (all lie in the box): a cell reads its source before it
/// writes its radiance, and each full voxel is one cell of the sweep. The cells of a row are
/// stepped [`Vector::N`] at a time ([`step_row`]: the same bits for any lanes).
#[inline(always)]
fn sweep_kernel<V: Vector>(
    c: &Ctx,
    om: DVec3,
    w: f64,
    ground: &GroundMap,
    light: &mut [[f32; 3]],
) -> Splats {
    let mut splats = Vec::new();
    let skyr = c.sky.arriving(om);
    let splat = om.y < 0.0 && c.ground_height.is_some();
    // Major axis and the two others.
    let r = [om.x.abs() / c.h[0], om.y.abs() / c.h[1], om.z.abs() / c.h[2]];
    let a = (0..3).max_by(|p, q| r[*p].total_cmp(&r[*q])).unwrap_or(0);
    let (b, cc) = cross_axes(a);
    let (na, nb, nc) = (c.n[a], c.n[b], c.n[cc]);
    let cells = &c.cells[a];
    let oa = om[a];
    let s = (c.h[a] / oa.abs()) as f32;
    // Back point offsets in the previous plane (voxels), split into floor and fraction.
    // |offset| ≤ 1 as a is the major axis; clamp rounding and keep the floor in {−1, 0}, so
    // ties (|Ω_b|/h_b = |Ω_a|/h_a) stay inside the 2×2 upwind neighbourhood.
    let ob = (-(s as f64) * om[b] / c.h[b]).clamp(-1.0, 1.0);
    let oc = (-(s as f64) * om[cc] / c.h[cc]).clamp(-1.0, 1.0);
    let (fb, fc) = (ob.floor().min(0.0), oc.floor().min(0.0));
    let (tb, tc) = ((ob - fb) as f32, (oc - fc) as f32);
    let (fb, fc) = (fb as isize, fc as isize);
    let wts = [(1.0 - tb) * (1.0 - tc), tb * (1.0 - tc), (1.0 - tb) * tc, tb * tc];
    let stride = nb + 2;
    // Grid coordinates of box cell (pa, pb, pc) in the (a, b, c) frame.
    let coord = |pa: isize, pb: isize, pc: isize| {
        let mut v = [0isize; 3];
        v[a] = pa + c.lo[a] as isize;
        v[b] = pb + c.lo[b] as isize;
        v[cc] = pc + c.lo[cc] as isize;
        v
    };
    // What enters a cell of plane pa that no cloud cell upwind reaches: the boundary radiance
    // straight back along −Ω ([`Ctx::boundary`]), as the ghost ring's cells hold it.
    let clear_record = |pa: isize, ib: isize, ic: isize| {
        let v = coord(pa, ib, ic);
        record(c.boundary(om, v[0], v[1], v[2], ground, skyr), 0.0, [0.0; 3])
    };
    let sky_only = !(c.ground_height.is_some() && om.y > 0.0);
    let ghost = record([skyr.x, skyr.y, skyr.z], 0.0, [0.0; 3]);
    // Plane buffers with a one-cell ghost ring. Without a ground seen upwards every such cell
    // holds the sky: both buffers start as it (the cells write only the interior).
    let start = if sky_only { ghost } else { record([0.0; 3], 0.0, [0.0; 3]) };
    let (mut prev, mut cur) = (Plane::new(stride * (nc + 2), start), Plane::new(stride * (nc + 2), start));
    // Clear air: a cell that is empty and whose upwind cells hold what enters them from outside
    // the cloud holds that too (Ω's clear ray carries it unchanged). Per row of each plane
    // buffer, the span of cells that may differ from it; a plane's row steps only the cells its
    // own full cells or its upwind rows' spans reach. Under the sky the rest hold the sky's
    // record; seen from the ground upwards, the cells a stepped cell reads outside the upwind
    // spans are given their boundary record before it is stepped.
    let mut live_prev = vec![(0, 0); nc];
    let mut live_cur = live_prev.clone();
    let spans = &c.spans[a];
    // Downwind of the cloud: per (plane, row), the cells a full cell further on reads (its own
    // full cells and, through the next plane's, every cell upwind of one; [`needed_cells`]).
    // The rest are not stepped, except where the ground splats read the box's exit faces.
    let needed = if splat {
        Vec::new()
    } else {
        let mut needed = vec![(0, 0); na * nc];
        for step in (0..na).rev() {
            let pa = if oa > 0.0 { step } else { na - 1 - step };
            for ic in 0..nc {
                let own = spans[pa * nc + ic];
                needed[pa * nc + ic] = match (step + 1 < na).then(|| if oa > 0.0 { pa + 1 } else { pa - 1 }) {
                    Some(next) => needed_cells(&needed[next * nc..(next + 1) * nc], ic as isize, fc, fb, own, nb),
                    None => (own.0 as usize, own.1 as usize),
                };
            }
        }
        needed
    };
    // The cell step's unchecked source and radiance accesses rely on this: the box's full
    // voxels index `light` ([`box_cells`] checked each below `voxels.len()`).
    assert!(light.len() == c.voxels.len() && cells.len() == na * nb * nc + PREFETCH_AHEAD);
    // The upwind (0, 0) neighbour lies `up` cells off a cell in the plane buffer (floors in
    // {−1, 0}: inside the ghost ring).
    assert!((-1..=0).contains(&fb) && (-1..=0).contains(&fc));
    let k = Step {
        weights: wts,
        up: fb + fc * stride as isize,
        stride,
        s,
        sigma_t: c.sigma_t,
        grey: c.grey,
    };
    // Box rows (from the lowest) whose steps the ground plane cuts.
    let cut = c.ground_height.map_or(0, |gh| {
        ground_cut::cut_rows(c.origin.y + c.lo[1] as f64 * c.h[1], c.h[1], c.n[1], gh, om.y, s as f64)
    });
    for step in 0..na {
        let pa = if oa > 0.0 { step } else { na - 1 - step };
        // The previous plane (the ghost plane before the box's first).
        let pa_prev = if oa > 0.0 { pa as isize - 1 } else { pa as isize + 1 };
        let plane = &cells[pa * nb * nc..(pa + 1) * nb * nc];
        // The cells PREFETCH_AHEAD further on (past the plane's end: the next plane's, or the
        // padding).
        let ahead = &cells[pa * nb * nc + PREFETCH_AHEAD..][..nb * nc];
        for (ic, (row, row_ahead)) in plane.chunks_exact(nb).zip(ahead.chunks_exact(nb)).enumerate() {
            let l0 = stride * (ic + 1) + 1;
            let (mut lo, mut hi) = stepped_cells(&live_prev, ic as isize + fc, fb, spans[pa * nc + ic], nb);
            if let Some(&(need_lo, need_hi)) = needed.get(pa * nc + ic) {
                (lo, hi) = if lo.max(need_lo) < hi.min(need_hi) { (lo.max(need_lo), hi.min(need_hi)) } else { (0, 0) };
            }
            if sky_only {
                // Cells this buffer's row held off the sky two planes back and will not step now:
                // back to the sky's record.
                let (old_lo, old_hi) = live_cur[ic];
                for ib in (old_lo..old_hi).filter(|ib| *ib < lo || *ib >= hi) {
                    cur.set(l0 + ib, ghost);
                }
            } else if lo < hi {
                // Upwind rows ic + fc and ic + fc + 1, cells lo + fb ..= hi + fb (the ring's
                // included): those off the previous plane's spans.
                for r in [ic as isize + fc, ic as isize + fc + 1] {
                    let (a0, a1) = usize::try_from(r).ok().and_then(|r| live_prev.get(r)).map_or((0, 0), |&(a0, a1)| (a0 as isize, a1 as isize));
                    for j in (lo as isize + fb..=hi as isize + fb).filter(|j| *j < a0 || *j >= a1) {
                        prev.set((j + 1) as usize + stride * (r + 1) as usize, clear_record(pa_prev, j, r));
                    }
                }
            }
            live_cur[ic] = (lo, hi);
            // The row's cells the ground plane cuts ([`ground_cut`]): a run from the row's start
            // in x-major sweeps (rows run up along y), else the whole row or none.
            let (cut_lo, cut_hi) = match a {
                0 => (lo, hi.min(cut.max(lo))),
                1 if pa < cut => (lo, hi),
                2 if ic < cut => (lo, hi),
                _ => (lo, lo),
            };
            if cut_lo < cut_hi {
                let gh = c.ground_height.unwrap_or(0.0);
                for (ib, &cell) in row.iter().enumerate().take(cut_hi).skip(cut_lo) {
                    let v = coord(pa as isize, ib as isize, ic as isize);
                    let y = c.origin.y + (v[1] as f64 + 0.5) * c.h[1];
                    let at = ground_cut::cut(y, gh, om.y, s as f64, || c.boundary(om, v[0], v[1], v[2], ground, skyr));
                    ground_cut::step_cut(&k, &prev, &mut cur, light, cell, l0 + ib, at);
                }
            }
            if cut_hi < hi {
                step_row::<V>(&k, &prev, &mut cur, light, &row[cut_hi..hi], &row_ahead[cut_hi..hi], l0 + cut_hi);
            }
        }
        let pa = pa as isize;
        if splat {
            // Light leaving the box downwards lands on the ground along Ω: splat its flux
            // change against the sky it hides, (I − L_sky) w |Ω·n| A_face, per column area.
            // Before the next plane, the part of a cell's bilinear spread that lands off the box
            // leaves across b and c (|Ω_b| s / h_b of it across b); the corner cell's spread off
            // both, (1 − in_b)(1 − in_c), is counted across b only, so across c it sends its
            // in_b part. After the last plane its whole flux leaves across a.
            let exit_b = if om[b] > 0.0 { nb - 1 } else { 0 };
            let exit_c = if om[cc] > 0.0 { nc - 1 } else { 0 };
            let in_b = if om[b] > 0.0 { tb } else { 1.0 - tb };
            let faces: Vec<(usize, usize, usize, f32)> = if step + 1 < na {
                let across_c = (0..nb).map(|ib| (ib, exit_c, cc, if ib == exit_b { in_b } else { 1.0 }));
                (0..nc).map(|ic| (exit_b, ic, b, 1.0)).chain(across_c).collect()
            } else {
                (0..nc).flat_map(|ic| (0..nb).map(move |ib| (ib, ic, a, 1.0))).collect()
            };
            for (ib, ic, ax, part) in faces {
                let v = coord(pa, ib as isize, ic as isize);
                let mut face = c.origin
                    + DVec3::new(
                        (v[0] as f64 + 0.5) * c.h[0],
                        (v[1] as f64 + 0.5) * c.h[1],
                        (v[2] as f64 + 0.5) * c.h[2],
                    );
                face[ax] += 0.5 * c.h[ax] * om[ax].signum();
                let gh = c.ground_height.unwrap_or(0.0);
                // Where the ray meets the plane: further on from a face above it, back from one under
                // it (the light of a cell under the plane is that at the plane, [`ground_cut`]).
                let q = face + om * ((gh - face.y) / om.y);
                if let Some(col) = ground.column(q.x, q.z) {
                    let area = c.h[0] * c.h[1] * c.h[2] / c.h[ax];
                    let f = w as f32 as f64 * om[ax].abs() * area / (c.h[0] * c.h[2]);
                    let i = cur.radiance(ib + 1 + stride * (ic + 1));
                    splats.push((col, [0, 1, 2].map(|band| f * part as f64 * (i[band] as f64 - skyr[band] as f64))));
                }
            }
        }
        std::mem::swap(&mut prev, &mut cur);
        std::mem::swap(&mut live_prev, &mut live_cur);
    }
    splats
}

/// The cells [lo, hi) of row `ic` that a sweep steps (the rest hold the clear sky's record,
/// [`sweep_kernel`]): those whose upwind cells (rows `up` and `up` + 1 of the previous plane,
/// offsets `fb` and `fb` + 1 along the row) reach a cell of that plane's `live` spans, and the
/// row's own `full` span; a row of `nb` cells.
fn stepped_cells(live: &[(usize, usize)], up: isize, fb: isize, full: (u32, u32), nb: usize) -> (usize, usize) {
    let mut cells = (full.0 as usize, full.1 as usize);
    for r in [up, up + 1] {
        if let Some(&(a, b)) = usize::try_from(r).ok().and_then(|r| live.get(r)) {
            // Cell ib reads upwind cells ib + fb and ib + fb + 1.
            if a < b {
                let from = (a as isize - fb - 1).max(0) as usize;
                let to = ((b as isize - fb) as usize).min(nb);
                cells = span_union(cells, (from, to));
            }
        }
    }
    cells
}

/// The smallest span [lo, hi) holding both spans (an empty span, lo ≥ hi, adds nothing).
fn span_union((lo, hi): (usize, usize), (a, b): (usize, usize)) -> (usize, usize) {
    match (lo < hi, a < b) {
        (true, true) => (lo.min(a), hi.max(b)),
        (false, true) => (a, b),
        _ => (lo, hi),
    }
}

/// The cells [lo, hi) of row `ic` whose radiance a full cell downwind reads ([`sweep_kernel`]):
/// the row's own `full` span and the cells the next plane's `next` spans read (its rows `ic` − `fc`
/// and `ic` − `fc` − 1; cell ib there reads ib + `fb` and ib + `fb` + 1 here); a row of `nb` cells.
fn needed_cells(next: &[(usize, usize)], ic: isize, fc: isize, fb: isize, full: (u32, u32), nb: usize) -> (usize, usize) {
    let mut cells = (full.0 as usize, full.1 as usize);
    for r in [ic - fc, ic - fc - 1] {
        if let Some(&(a, b)) = usize::try_from(r).ok().and_then(|r| next.get(r)) {
            if a < b {
                let from = (a as isize + fb).max(0) as usize;
                let to = ((b as isize + fb + 1) as usize).min(nb);
                cells = span_union(cells, (from, to));
            }
        }
    }
    cells
}

/// [`sweep_kernel`] in AVX lanes where the processor has it, else in SSE2 lanes (x86-64) or one
/// lane at a time: the same bits.
pub(super) fn sweep_ordinate(c: &Ctx, om: DVec3, w: f64, ground: &GroundMap, light: &mut [[f32; 3]]) -> Splats {
    #[cfg(target_arch = "x86_64")]
    if has_avx() {
        // SAFETY: the processor has AVX.
        return unsafe { sweep_ordinate_avx(c, om, w, ground, light) };
    }
    #[cfg(target_arch = "x86_64")]
    return sweep_kernel::<lanes::Sse2>(c, om, w, ground, light);
    #[cfg(not(target_arch = "x86_64"))]
    sweep_kernel::<f32>(c, om, w, ground, light)
}

/// [`sweep_kernel`] compiled for AVX: the row steps' eight lanes in one register ([`lanes::Avx`],
/// made only here).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn sweep_ordinate_avx(c: &Ctx, om: DVec3, w: f64, ground: &GroundMap, light: &mut [[f32; 3]]) -> Splats {
    sweep_kernel::<lanes::Avx>(c, om, w, ground, light)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;
    use crate::transport::sky_cells::SkyCells;
    use crate::math::{real_sh, Rgb};
    use crate::medium::Density;
    use crate::transport::grid::{box_cells, full_spans};
    use crate::transport::source::{moments_kernel, parity_order, source_kernel};
    use crate::transport::BandOptics;

    /// A sweep's total splatted change Σ e per band (W/m² × columns).
    fn splat_total(splats: &Splats) -> [f64; 3] {
        let mut total = [0.0; 3];
        for (_, e) in splats {
            for band in 0..3 {
                total[band] += e[band];
            }
        }
        total
    }

    #[test]
    fn a_row_steps_what_its_full_cells_and_upwind_spans_reach() {
        // Upwind rows 1 and 2 of the previous plane; cell ib reads ib + fb and ib + fb + 1.
        let live = [(0, 0), (3, 5), (6, 7), (0, 0)];
        assert_eq!(stepped_cells(&live, 1, 0, (0, 0), 10), (2, 7));
        assert_eq!(stepped_cells(&live, 1, -1, (0, 0), 10), (3, 8));
        assert_eq!(stepped_cells(&live, 1, 0, (8, 10), 10), (2, 10), "the row's own full cells");
        assert_eq!(stepped_cells(&live, -1, 0, (0, 0), 10), (0, 0), "a ghost row and a clear row");
        assert_eq!(stepped_cells(&live, 3, 0, (4, 5), 10), (4, 5), "past the last row: the ghosts");
        assert_eq!(stepped_cells(&[(0, 2)], 0, 0, (0, 0), 10), (0, 2), "clipped at the row's start");
    }

    #[test]
    fn a_row_needs_its_full_cells_and_what_the_next_planes_needed_cells_read() {
        // Next plane's rows 1 and 2 read this plane's row 1 (fc = 0: rows 1 and 0 of it read it);
        // cell ib there reads ib + fb and ib + fb + 1 here.
        let next = [(0, 0), (3, 5), (6, 7), (0, 0)];
        assert_eq!(needed_cells(&next, 1, 0, 0, (0, 0), 10), (3, 6));
        assert_eq!(needed_cells(&next, 1, 0, -1, (0, 0), 10), (2, 5));
        assert_eq!(needed_cells(&next, 2, 0, 0, (0, 0), 10), (3, 8), "read by next rows 2 and 1");
        assert_eq!(needed_cells(&next, 1, 0, 0, (8, 10), 10), (3, 10), "the row's own full cells");
        assert_eq!(needed_cells(&next, 4, 0, 0, (0, 0), 10), (0, 0), "read by no next row");
        assert_eq!(needed_cells(&next, 0, -1, 0, (0, 0), 10), (3, 6), "fc = −1: next rows 1 and 0");
        assert_eq!(needed_cells(&[(0, 1)], 0, 0, -1, (0, 0), 10), (0, 1), "clipped at the row's start");
    }

    #[test]
    fn the_avx_kernels_give_the_same_bits_as_the_plain_ones() {
        // An 11×9×8 box, empty voxels inside the cloud and clear air around it, random moments:
        // each kernel as built and through its dispatcher (AVX where the processor has it) must
        // agree bit for bit, and the sweep stepping only the cells off the clear air upwind and
        // before the last cloud cell downwind agrees with stepping every cell.
        let dims = [11, 9, 8];
        let nv = dims[0] * dims[1] * dims[2];
        let inside = |v: usize| {
            let (i, j, k) = (v % dims[0], (v / dims[0]) % dims[1], v / (dims[0] * dims[1]));
            (2..dims[0] - 3).contains(&i) && (2..dims[1] - 2).contains(&j) && (1..dims[2] - 2).contains(&k)
        };
        let rho: Vec<f32> = (0..nv)
            .map(|v| if inside(v) { ((v as f32 * 0.618).fract() - 0.2).max(0.0) * 3.0 } else { 0.0 })
            .collect();
        let voxels: Vec<usize> = (0..nv).filter(|v| rho[*v] > 0.0).collect();
        let density = Density::from_grid(&crate::medium::Grid3::from_vec(dims, rho, "test").unwrap());
        let full = density.full_index();
        let nfull = voxels.len();
        let order = 7;
        let (perm, even) = parity_order(order);
        let nsh = perm.len();
        let sun_t: Vec<[f32; 3]> = voxels.iter().map(|v| [0.3, 0.5, 0.7].map(|t| t + 0.01 * (v % 7) as f32)).collect();
        let sky = SkyCells::Constant(Rgb::new(0.2, 0.3, 0.5));
        let c = Ctx {
            dims,
            lo: [0; 3],
            n: dims,
            h: [10.0, 8.0, 12.0],
            rho: &density,
            full: &full,
            nsh,
            even,
            voxels: &voxels,
            sun_t: &sun_t,
            cells: Arc::new([0, 1, 2].map(|a| box_cells(dims, [0; 3], dims, &density, &full, voxels.len(), a))),
            spans: Arc::new([0, 1, 2].map(|_| Vec::new())),
            sigma_t: [0.05, 0.06, 0.07],
            grey: false,
            sky: &sky,
            origin: DVec3::ZERO,
            ground_height: None,
        };
        let c = Ctx {
            spans: Arc::new([0, 1, 2].map(|a| full_spans(&c.cells[a], dims[cross_axes(a).0]))),
            ..c
        };
        let ground = GroundMap {
            margin: 0,
            dims: [dims[0], dims[2]],
            radiance: vec![Rgb::ZERO; dims[0] * dims[2]],
            diffuse: vec![Rgb::ZERO; dims[0] * dims[2]],
            clear: Rgb::ZERO,
            origin: [0.0; 2],
            h: [10.0, 12.0],
        };
        let bands: Vec<BandOptics> = (0..3)
            .map(|b| BandOptics::delta_m(0.05, 0.9 + 0.03 * b as f64, 0.85, order))
            .collect();
        let q = Quadrature::product(8, 16);
        let mut y_sun = vec![0.0; nsh];
        real_sh(order, DVec3::new(0.2, -0.9, 0.3).normalize(), &mut y_sun);
        let t = PairTables::new(&q, order, &perm, &bands, [2.0, 1.8, 1.5], &y_sun);
        let moments: Vec<f32> = (0..nfull * 3 * nsh)
            .map(|i| ((i as f32 * 0.37).sin() * 0.5 + 0.6) / (1 + i % nsh) as f32)
            .collect();
        let bits = |v: &[[f32; 3]]| v.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
        // Step (1).
        let (mut plain, mut disp) = (vec![[0f32; 3]; ORDINATE_BATCH * nfull], vec![[0f32; 3]; ORDINATE_BATCH * nfull]);
        source_kernel(&c, &t, 1, PAIRS, &moments, 0, &mut plain.chunks_mut(nfull).collect::<Vec<_>>());
        source_block(&c, &t, 1, PAIRS, &moments, 0, &mut disp.chunks_mut(nfull).collect::<Vec<_>>());
        assert_eq!(bits(&plain), bits(&disp));
        assert!(plain.iter().flatten().any(|x| *x > 0.0));
        // Step (2), every ordinate, with coloured and with grey optics: the rows' cells one at a
        // time, eight at a time in SSE2 lanes and through the dispatcher (AVX lanes).
        let grey = Ctx {
            sigma_t: [0.05; 3],
            grey: true,
            cells: c.cells.clone(),
            spans: c.spans.clone(),
            ..c
        };
        for c in [&c, &grey] {
            for d in 0..q.dirs.len() {
                let (mut one, mut ra, mut rb) = (plain[..nfull].to_vec(), plain[..nfull].to_vec(), plain[..nfull].to_vec());
                sweep_kernel::<f32>(c, q.dirs[d], q.weights[d], &ground, &mut one);
                #[cfg(target_arch = "x86_64")]
                sweep_kernel::<lanes::Sse2>(c, q.dirs[d], q.weights[d], &ground, &mut ra);
                #[cfg(not(target_arch = "x86_64"))]
                sweep_kernel::<f32>(c, q.dirs[d], q.weights[d], &ground, &mut ra);
                sweep_ordinate(c, q.dirs[d], q.weights[d], &ground, &mut rb);
                assert_eq!(bits(&one), bits(&ra), "ordinate {d}, grey {}", c.grey);
                assert_eq!(bits(&ra), bits(&rb), "ordinate {d}, grey {}", c.grey);
                assert!(ra.iter().flatten().any(|x| *x > 0.0));
            }
        }
        // Every cell stepped: each row's span the whole row.
        let every = Ctx {
            spans: Arc::new([0, 1, 2].map(|a| vec![(0, dims[cross_axes(a).0] as u32); c.spans[a].len()])),
            cells: c.cells.clone(),
            ..c
        };
        assert!(c.spans.iter().flatten().any(|s| s.0 == s.1), "some rows are clear");
        // And under a ground of one radiance (the clear air between it and the cloud carries it
        // unchanged, skipped or stepped), seen by the upward ordinates.
        let lit = GroundMap {
            radiance: vec![Rgb::new(0.05, 0.1, 0.15); ground.radiance.len()],
            clear: Rgb::new(0.05, 0.1, 0.15),
            ..ground.clone()
        };
        fn grounded<'a>(c: &Ctx<'a>) -> Ctx<'a> {
            Ctx {
                ground_height: Some(-50.0),
                cells: c.cells.clone(),
                spans: c.spans.clone(),
                ..*c
            }
        }
        let (c_lit, every_lit) = (grounded(&c), grounded(&every));
        for (skipping, stepping, g) in [(&c, &every, &ground), (&c_lit, &every_lit, &lit)] {
            for d in 0..q.dirs.len() {
                let (mut skip, mut all) = (plain[..nfull].to_vec(), plain[..nfull].to_vec());
                sweep_ordinate(skipping, q.dirs[d], q.weights[d], g, &mut skip);
                sweep_ordinate(stepping, q.dirs[d], q.weights[d], g, &mut all);
                for (x, y) in skip.iter().flatten().zip(all.iter().flatten()) {
                    assert!((x - y).abs() <= 1e-6 * y.abs(), "ordinate {d}: {x} vs {y}");
                }
            }
        }
        // Light leaves the cloud's box (the full voxels grown by one) in clear air, so the ground
        // splats' flux change per ordinate does not depend on the box: the box stepped to its
        // faces agrees with the whole grid's.
        let (lo, n) = ([1, 1, 0], [8, 7, 7]);
        let cells = [0, 1, 2].map(|a| box_cells(dims, lo, n, &density, &full, voxels.len(), a));
        let tight = Ctx {
            lo,
            n,
            spans: Arc::new([0, 1, 2].map(|a| full_spans(&cells[a], n[cross_axes(a).0]))),
            cells: Arc::new(cells),
            ..grounded(&c)
        };
        let wide = GroundMap {
            margin: 400,
            dims: [dims[0] + 800, dims[2] + 800],
            radiance: vec![Rgb::new(0.05, 0.1, 0.15); (dims[0] + 800) * (dims[2] + 800)],
            diffuse: vec![Rgb::ZERO; (dims[0] + 800) * (dims[2] + 800)],
            ..lit.clone()
        };
        for d in (0..q.dirs.len()).filter(|d| q.dirs[*d].y < 0.0) {
            let tt = splat_total(&sweep_ordinate(&tight, q.dirs[d], q.weights[d], &wide, &mut plain[..nfull].to_vec()));
            let tw = splat_total(&sweep_ordinate(&c_lit, q.dirs[d], q.weights[d], &wide, &mut plain[..nfull].to_vec()));
            for band in 0..3 {
                assert!((tt[band] - tw[band]).abs() <= 1e-5 * tw[band].abs(), "ordinate {d}: {tt:?} vs {tw:?}");
            }
        }
        // Step (3).
        let wts: Vec<f32> = t.weights[PAIRS..2 * PAIRS].iter().flatten().copied().collect();
        let nblk = t.y_acc.len() / t.pairs.len().div_ceil(PAIRS);
        let l = Lanes {
            nfull,
            wts: &wts,
            radiance: &plain,
            y: &t.y_acc[nblk..2 * nblk],
            first: false,
            active: t.moment_active,
        };
        let (mut ma, mut mb) = (moments.clone(), moments.clone());
        moments_kernel(&c, &l, &mut ma, 0);
        moments_block(&c, &l, &mut mb, 0);
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&ma), bits(&mb));
        // The sweep's first batch writes over the last iteration's values what adding to zeros
        // gives.
        let mut added = vec![0f32; moments.len()];
        moments_block(&c, &l, &mut added, 0);
        let mut written = moments.clone();
        moments_block(&c, &Lanes { first: true, ..l }, &mut written, 0);
        assert_eq!(bits(&written), bits(&added));
    }
}
