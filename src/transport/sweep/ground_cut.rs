//! The sweep's cells at the ground plane. The ground bounds the transport domain: no light
//! travels under it. The cell step ([`super::step`]) runs from the back point in the previous
//! plane to the cell's centre through a medium linear between them; where that segment crosses
//! the plane it is cut there (docs/transport.md, "The ground as a boundary"):
//!
//! - going up from a centre under the plane, the cell holds the ground's radiance at the plane
//!   ([`Cut::Ground`]);
//! - going up across the plane, the step starts at the plane with the ground's radiance, over
//!   the part of the segment above it ([`Cut::From`]);
//! - going down to a centre under the plane, the step ends at the plane ([`Cut::To`]); a
//!   segment wholly under it carries the radiance unchanged.
//!
//! So a cell whose centre lies under the plane holds the light at the plane above it, and the
//! medium under the plane takes no part in the transport. A row of voxels straddling the plane
//! keeps its density, which shapes the field between the plane and the next centres (the
//! trilinear field every method renders).

use super::step::{step_weights, Plane, Record, Step, I, RHO, RHO_WEIGHT_MIN, RS};

/// How the ground plane cuts one cell's step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Cut {
    /// Going up, the centre under the plane: the ground's radiance there, per band.
    Ground([f32; 3]),
    /// Going up across the plane: the ground's radiance where the segment meets the plane, and
    /// the fraction of the segment above the plane (from the centre back), in [0, 1).
    From { ground: [f32; 3], above: f32 },
    /// Going down, the centre under the plane: the fraction of the segment above the plane (from
    /// the back point on), in [0, 1]; 0 where it lies wholly under.
    To { above: f32 },
}

/// Box rows (from the box's lowest, `n_y` in all) whose cells' steps the plane at height `gh`
/// (m) cuts, for an ordinate with direction cosine `om_y` and step length `s` (m): the rows with
/// their centre under the plane and, going up, those whose back point (s·Ω_y lower) is under it.
/// Centres at `y0` + (j + ½)·`h_y` (m) for box row j. They are the lowest rows: a prefix.
pub(super) fn cut_rows(y0: f64, h_y: f64, n_y: usize, gh: f64, om_y: f64, s: f64) -> usize {
    let reach = if om_y > 0.0 { s * om_y } else { 0.0 };
    (0..n_y).take_while(|&j| y0 + (j as f64 + 0.5) * h_y < gh + reach).count()
}

/// The cut of a cell at height `y` (m; one of [`cut_rows`]' rows) for an ordinate with direction
/// cosine `om_y` and step length `s` (m) under the plane at `gh` (m); `ground` gives the ground's
/// radiance where the ray through the centre meets the plane (straight back along −Ω going up).
pub(super) fn cut(y: f64, gh: f64, om_y: f64, s: f64, ground: impl FnOnce() -> [f32; 3]) -> Cut {
    let rise = s * om_y.abs();
    if om_y > 0.0 {
        if y < gh {
            Cut::Ground(ground())
        } else {
            Cut::From {
                ground: ground(),
                above: ((y - gh) / rise).clamp(0.0, 1.0) as f32,
            }
        }
    } else {
        let above = if rise > 0.0 { ((y + rise - gh) / rise).clamp(0.0, 1.0) } else { 0.0 };
        Cut::To { above: above as f32 }
    }
}

/// Step cell `l` of the plane buffer `cur` (density and full-voxel index `cell`) cut by the
/// ground ([`Cut`]): its upwind record from `prev`, its source in `light` (which receives its
/// radiance if it is full), as [`super::step::step_row`] steps the others. Every weight is ≥ 0,
/// so the radiance is ≥ 0 where the sources and the ground's radiance are.
pub(super) fn step_cut(k: &Step, prev: &Plane, cur: &mut Plane, light: &mut [[f32; 3]], cell: (f32, u32), l: usize, cut: Cut) {
    let (rho, fi) = cell;
    let full = fi != u32::MAX;
    let own = if full { light[fi as usize] } else { [0.0; 3] };
    let back = prev.upwind(k, l);
    let rho_b = back[RHO];
    let mut out = [0f32; 3];
    for (band, o) in out.iter_mut().enumerate() {
        // The sources at the back point and the centre, as the row step takes them.
        let j_b = if rho_b > RHO_WEIGHT_MIN { back[RS + band] / rho_b } else { own[band] };
        let j_c = if full { own[band] } else { j_b };
        let sigma = k.sigma_t[band];
        *o = match cut {
            Cut::Ground(g) => g[band],
            Cut::From { ground, above } => {
                // Medium and source linear along the segment: their values at the plane.
                let (rho_p, j_p) = (rho + above * (rho_b - rho), j_c + above * (j_b - j_c));
                let tau = sigma * k.s * above * 0.5 * (rho_p + rho);
                if tau > 0.0 {
                    let (e, wi, wo) = step_weights(tau);
                    ground[band] * e + wi * j_p + wo * j_c
                } else {
                    ground[band]
                }
            }
            Cut::To { above } => {
                let (rho_p, j_p) = (rho_b + above * (rho - rho_b), j_b + above * (j_c - j_b));
                let tau = sigma * k.s * above * 0.5 * (rho_b + rho_p);
                let i_b = back[I + band];
                if tau > 0.0 {
                    let (e, wi, wo) = step_weights(tau);
                    i_b * e + wi * j_b + wo * j_p
                } else {
                    i_b
                }
            }
        };
    }
    let rec: Record = [out[0], out[1], out[2], rho, rho * own[0], rho * own[1], rho * own[2]];
    cur.set(l, rec);
    if full {
        light[fi as usize] = out;
    }
}

#[cfg(test)]
mod tests {
    use super::super::step::record;
    use super::*;

    /// A y-major step of 10 m (voxels of 10 m) between the centres of a 3 × 3 buffer.
    fn one_cell(prev_rec: Record, rho: f32, source: [f32; 3], cut: Cut) -> ([f32; 3], Record) {
        let k = Step {
            weights: [1.0, 0.0, 0.0, 0.0],
            up: 0,
            stride: 3,
            s: 10.0,
            sigma_t: [0.05, 0.1, 0.2],
            grey: false,
        };
        let (prev, mut cur) = (Plane::new(9, prev_rec), Plane::new(9, record([0.0; 3], 0.0, [0.0; 3])));
        let mut light = vec![source];
        step_cut(&k, &prev, &mut cur, &mut light, (rho, 0), 4, cut);
        assert_eq!(cur.radiance(4), light[0], "the buffer and the full voxel hold the same radiance");
        (light[0], cur.record(4))
    }

    #[test]
    fn the_rows_cut_are_those_under_the_plane_and_going_up_those_stepping_from_under_it() {
        // Centres at −5, 5, 15, … m; the plane at 0.
        assert_eq!(cut_rows(-10.0, 10.0, 6, 0.0, -0.7, 12.0), 1, "going down: the centre under it");
        assert_eq!(cut_rows(-10.0, 10.0, 6, 0.0, 1.0, 10.0), 2, "going up: and the row stepping from under it");
        assert_eq!(cut_rows(-10.0, 10.0, 6, 0.0, 0.3, 10.0), 1, "going up, the back point 3 m under the centre at 5 m");
        assert_eq!(cut_rows(20.0, 10.0, 6, 0.0, 1.0, 10.0), 0, "a box a voxel or more over the plane");
        assert_eq!(cut_rows(-100.0, 10.0, 3, 0.0, -1.0, 10.0), 3, "a box wholly under it");
    }

    #[test]
    fn a_cut_starts_or_ends_the_step_at_the_plane() {
        let g = || [0.1, 0.2, 0.3];
        assert_eq!(cut(-5.0, 0.0, 0.8, 10.0, g), Cut::Ground([0.1, 0.2, 0.3]));
        assert_eq!(cut(5.0, 0.0, 1.0, 10.0, g), Cut::From { ground: [0.1, 0.2, 0.3], above: 0.5 });
        assert_eq!(cut(-5.0, 0.0, -1.0, 10.0, g), Cut::To { above: 0.5 });
        assert_eq!(cut(-5.0, 0.0, -0.4, 10.0, g), Cut::To { above: 0.0 }, "back point 1 m under the plane");
        assert_eq!(cut(-5.0, 0.0, -0.6, 10.0, g), Cut::To { above: 1.0 / 6.0 });
    }

    #[test]
    fn a_cut_step_integrates_only_the_segment_above_the_plane() {
        let (rho, source) = (0.8f32, [0.4f32, 0.5, 0.6]);
        let back = record([1.0, 2.0, 3.0], rho, source.map(|s| rho * s));
        // Going up from a centre under the plane: the ground's radiance, whatever the medium.
        assert_eq!(one_cell(back, rho, source, Cut::Ground([0.1, 0.2, 0.3])).0, [0.1, 0.2, 0.3]);
        // Nothing of the segment above the plane: the ground's radiance, or the back radiance.
        assert_eq!(one_cell(back, rho, source, Cut::From { ground: [0.1, 0.2, 0.3], above: 0.0 }).0, [0.1, 0.2, 0.3]);
        assert_eq!(one_cell(back, rho, source, Cut::To { above: 0.0 }).0, [1.0, 2.0, 3.0]);
        // A uniform medium and source over half the step: I = I₀ e^{−τ} + J (1 − e^{−τ}), τ = σt ρ 5 m.
        for (cut, i0) in [(Cut::From { ground: [0.1, 0.2, 0.3], above: 0.5 }, [0.1, 0.2, 0.3]), (Cut::To { above: 0.5 }, [1.0, 2.0, 3.0])] {
            let (got, rec) = one_cell(back, rho, source, cut);
            for band in 0..3 {
                let e = (-([0.05f32, 0.1, 0.2][band] * rho * 5.0)).exp();
                let want = i0[band] * e + source[band] * (1.0 - e);
                assert!((got[band] - want).abs() <= 1e-6 * want, "{cut:?} band {band}: {} vs {want}", got[band]);
            }
            assert_eq!(rec[3..], [rho, rho * source[0], rho * source[1], rho * source[2]], "the cell's own density and source");
        }
    }
}
