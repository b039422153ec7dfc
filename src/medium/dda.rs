//! The one 3-D DDA (Amanatides & Woo 1987) over a regular lattice: yields every cell a ray
//! crosses with the ray-parameter interval inside it. The entry boundaries come from the integer
//! cell index, then each step adds one cell's ray length (no division per step); each segment
//! starts where the previous ended, so the lengths telescope exactly to the chord length. Users:
//! the dual-lattice Simpson walks ([`super::Medium::dual_dda`]: the exact optical depth, the
//! sun's transmittance, the eye rays' profiles) and the majorant blocks; stage 1
//! ([`crate::incident`]) sweeps its ray lattices plane by plane instead and is tested against a
//! per-ray walk with this DDA.

use glam::DVec3;

/// One cell crossed by a ray: its index and the interval [t0, t1] (m) inside it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    /// Cell index (x, y, z).
    pub cell: [usize; 3],
    /// Entry distance (m).
    pub t0: f64,
    /// Exit distance (m).
    pub t1: f64,
}

impl Segment {
    /// Length of the segment (m).
    #[inline]
    pub fn len(&self) -> f64 {
        self.t1 - self.t0
    }
}

/// Iterator over the cells of a lattice crossed by a ray.
#[derive(Clone, Debug)]
pub struct Dda {
    origin: DVec3,
    cell_size: DVec3,
    ray_o: DVec3,
    ray_d: DVec3,
    dims: [usize; 3],
    cell: [i64; 3],
    step: [i64; 3],
    /// Ray parameter of the current cell's exit boundary per axis.
    tb: [f64; 3],
    /// Ray-parameter length of one cell per axis, cell_size/|ray_d| (∞ for a zero component).
    t_delta: [f64; 3],
    t: f64,
    t_end: f64,
    done: bool,
}

/// Slab intersection of a ray with the box [lo, hi]; returns (t_enter, t_exit) clipped to [t_min, t_max].
#[inline]
pub fn ray_box(lo: DVec3, hi: DVec3, o: DVec3, d: DVec3, t_min: f64, t_max: f64) -> Option<(f64, f64)> {
    let mut t0 = t_min;
    let mut t1 = t_max;
    for a in 0..3 {
        if d[a] == 0.0 {
            if o[a] < lo[a] || o[a] > hi[a] {
                return None;
            }
        } else {
            let inv = 1.0 / d[a];
            let (mut ta, mut tb) = ((lo[a] - o[a]) * inv, (hi[a] - o[a]) * inv);
            if ta > tb {
                std::mem::swap(&mut ta, &mut tb);
            }
            t0 = t0.max(ta);
            t1 = t1.min(tb);
        }
    }
    (t0 < t1).then_some((t0, t1))
}

impl Dda {
    /// Walk the lattice with minimum corner `origin`, cell edge `cell_size` (m) and `dims` cells,
    /// along `ray_o + t·ray_d` for t ∈ [t_min, t_max]. `ray_d` need not be unit length (t is then
    /// in its units).
    pub fn new(origin: DVec3, cell_size: DVec3, dims: [usize; 3], ray_o: DVec3, ray_d: DVec3, t_min: f64, t_max: f64) -> Self {
        let hi = origin + cell_size * DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64);
        let mut dda = Dda {
            origin,
            cell_size,
            ray_o,
            ray_d,
            dims,
            cell: [0; 3],
            step: [0; 3],
            tb: [f64::INFINITY; 3],
            t_delta: [f64::INFINITY; 3],
            t: 0.0,
            t_end: 0.0,
            done: true,
        };
        let Some((t0, t1)) = ray_box(origin, hi, ray_o, ray_d, t_min, t_max) else {
            return dda;
        };
        // Locate the entry cell from the midpoint side of the entry to be robust at faces.
        let p = ray_o + ray_d * t0;
        for a in 0..3 {
            let c = ((p[a] - origin[a]) / cell_size[a]).floor() as i64;
            let mut c = c.clamp(0, dims[a] as i64 - 1);
            // On a boundary, moving backwards: the cell is the lower one.
            if ray_d[a] < 0.0 && c > 0 && (origin[a] + c as f64 * cell_size[a] - p[a]).abs() < 1e-12 * cell_size[a].max(1.0) {
                c -= 1;
            }
            dda.cell[a] = c;
            dda.step[a] = if ray_d[a] > 0.0 {
                1
            } else if ray_d[a] < 0.0 {
                -1
            } else {
                0
            };
        }
        dda.tb = [dda.t_boundary(0), dda.t_boundary(1), dda.t_boundary(2)];
        for a in 0..3 {
            if dda.step[a] != 0 {
                dda.t_delta[a] = cell_size[a] / ray_d[a].abs();
            }
        }
        dda.t = t0;
        dda.t_end = t1;
        dda.done = false;
        dda
    }

    /// Ray parameter where the current cell's boundary on axis `a` is crossed.
    #[inline]
    fn t_boundary(&self, a: usize) -> f64 {
        if self.step[a] == 0 {
            return f64::INFINITY;
        }
        let idx = if self.step[a] > 0 { self.cell[a] + 1 } else { self.cell[a] };
        (self.origin[a] + idx as f64 * self.cell_size[a] - self.ray_o[a]) / self.ray_d[a]
    }
}

impl Iterator for Dda {
    type Item = Segment;

    #[inline]
    fn next(&mut self) -> Option<Segment> {
        loop {
            if self.done {
                return None;
            }
            let tb = self.tb;
            let axis = if tb[0] <= tb[1] && tb[0] <= tb[2] {
                0
            } else if tb[1] <= tb[2] {
                1
            } else {
                2
            };
            let t_next = tb[axis].min(self.t_end).max(self.t);
            let seg = Segment {
                cell: [self.cell[0] as usize, self.cell[1] as usize, self.cell[2] as usize],
                t0: self.t,
                t1: t_next,
            };
            self.t = t_next;
            if t_next >= self.t_end {
                self.done = true;
            } else {
                self.cell[axis] += self.step[axis];
                if self.cell[axis] < 0 || self.cell[axis] >= self.dims[axis] as i64 {
                    self.done = true;
                } else {
                    self.tb[axis] += self.t_delta[axis];
                }
            }
            if seg.t1 > seg.t0 {
                return Some(seg);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Rng;

    #[test]
    fn lengths_sum_to_chord_for_random_rays() {
        let mut rng = Rng::new(3, 0);
        let origin = DVec3::new(-5.0, 1.0, 2.0);
        let cs = DVec3::new(0.7, 1.3, 0.9);
        let dims = [13, 7, 21];
        let hi = origin + cs * DVec3::new(13.0, 7.0, 21.0);
        let mut hits = 0;
        for _ in 0..2000 {
            let o = DVec3::new(
                rng.uniform_f64() * 30.0 - 15.0,
                rng.uniform_f64() * 30.0 - 15.0,
                rng.uniform_f64() * 40.0 - 10.0,
            );
            let mut d = DVec3::new(rng.uniform_f64() - 0.5, rng.uniform_f64() - 0.5, rng.uniform_f64() - 0.5);
            if hits % 7 == 0 {
                d.x = 0.0; // axis-parallel cases
            }
            let d = d.normalize();
            let chord = ray_box(origin, hi, o, d, 0.0, f64::INFINITY).map_or(0.0, |(a, b)| b - a);
            let segs: Vec<_> = Dda::new(origin, cs, dims, o, d, 0.0, f64::INFINITY).collect();
            let sum: f64 = segs.iter().map(|s| s.len()).sum();
            assert!((sum - chord).abs() < 1e-9 * chord.max(1.0), "sum {sum} chord {chord}");
            for w in segs.windows(2) {
                let moved: i64 = (0..3).map(|a| (w[1].cell[a] as i64 - w[0].cell[a] as i64).abs()).sum();
                assert_eq!(moved, 1, "cells must be face neighbours");
                assert_eq!(w[0].t1, w[1].t0);
            }
            for s in &segs {
                // Midpoint must lie in the reported cell.
                let p = o + d * (0.5 * (s.t0 + s.t1));
                for a in 0..3 {
                    let c = (p[a] - origin[a]) / cs[a];
                    assert!(c >= s.cell[a] as f64 - 1e-9 && c <= s.cell[a] as f64 + 1.0 + 1e-9);
                }
            }
            hits += (chord > 0.0) as usize;
        }
        assert!(hits > 200);
    }
}
