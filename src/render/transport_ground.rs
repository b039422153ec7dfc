//! The ground as the eye sees it in `--method transport`. The solver's ground map
//! ([`GroundMap`]) is a column per voxel with the sun's transmittance at the column's centre and
//! the cloud's diffuse light splatted per ordinate: good enough for the light the ground sends back
//! into the cloud, but seen directly it shows the columns (a blocky shadow) and the ordinates (each
//! one lands in its own band: stripes and hatching). For the eye, the ground's radiance is
//! ρ_g/π (E μ_⊙ T′_⊙(p) + E_down(p)) with
//! - the sun's transmittance T′ marched from the ground point itself (the δ-M scaled T′ = T^{σt′/σt}
//!   the solver uses, per band), so the shadow is exact;
//! - E_down, the map's sky and cloud light, box-filtered over the distance between neighbouring
//!   ordinates' landing points there (so no ordinate is visible) and bilinear between columns;
//!   beyond the map (which reaches as far as the cloud's shadow) the cloud's light on the ground
//!   falls off from the map's edge as a distant source's does, so the edge leaves no seam.

use crate::math::{Rgb, Vec3};
use crate::scene::Scene;
use crate::transport::solve::{GroundMap, TransportField};

/// The ground's radiance for the eye (W·m⁻²·sr⁻¹).
pub struct EyeGround {
    /// Filtered ρ_g/π E_down per map column, x fastest.
    diffuse: Vec<Rgb>,
    /// Beyond the map: the clear sky's ρ_g/π E_sky.
    clear: Rgb,
    dims: [usize; 2],
    /// World x, z of column (0, 0)'s centre (m).
    first: [f64; 2],
    /// Column size (m).
    h: [f64; 2],
    /// ρ_g/π E μ_⊙ per band (W·m⁻²·sr⁻¹), to be multiplied by the marched T′.
    sun: Rgb,
    /// σt′/σt per band: T′ = T^{this}.
    scale: [f64; 3],
    /// The cloud's centre, world x, z (m), and height above the ground (m): where its light on
    /// the ground beyond the map seems to come from.
    cloud: [f64; 3],
}

impl EyeGround {
    /// From the solved field; `None` without a ground.
    pub fn new(scene: &Scene, f: &TransportField) -> Option<EyeGround> {
        let g = scene.ground.as_ref()?;
        let m = &scene.medium;
        let map = &f.ground;
        let mu_s = scene.sun.dir.y.max(0.0);
        let sun = g.albedo * scene.sun.irradiance * (mu_s / std::f32::consts::PI);
        let clear = g.albedo * scene.sky.irradiance_up / std::f32::consts::PI;
        let scale = [0, 1, 2].map(|b| f.optics.bands[b].sigma_t / f.optics.sigma_t);
        let first = [0, 1].map(|a| map.origin[a] + (0.5 - map.margin as f64) * map.h[a]);
        // Where the ordinates leave the cloud: the box of full voxels, and its bottom's height
        // above the ground (at least a voxel).
        let (lo, hi) = m.active_box(0).unwrap_or(([0; 3], [0; 3]));
        let (o, vs) = (m.origin, m.voxel_size);
        let foot = [
            [o.x as f64 + lo[0] as f64 * vs.x as f64, o.x as f64 + hi[0] as f64 * vs.x as f64],
            [o.z as f64 + lo[2] as f64 * vs.z as f64, o.z as f64 + hi[2] as f64 * vs.z as f64],
        ];
        let height = ((o.y + lo[1] as f32 * vs.y - g.height) as f64).max(vs.y as f64);
        let centre_height = ((o.y + 0.5 * (lo[1] + hi[1]) as f32 * vs.y - g.height) as f64).max(vs.y as f64);
        let cloud = [0.5 * (foot[0][0] + foot[0][1]), 0.5 * (foot[1][0] + foot[1][1]), centre_height];
        // Neighbouring ordinates are π/n_μ apart in angle (polar and azimuthal).
        let spacing = std::f64::consts::PI / scene.render.transport.n_mu as f64;
        let column = map.h[0].min(map.h[1]);
        let diffuse = filtered(map, first, |x, z| {
            let dx = (foot[0][0] - x).max(x - foot[0][1]).max(0.0);
            let dz = (foot[1][0] - z).max(z - foot[1][1]).max(0.0);
            filter_half_width(height, spacing, dx, dz, column)
        });
        Some(EyeGround {
            diffuse,
            clear,
            dims: map.dims,
            first,
            h: map.h,
            sun,
            scale,
            cloud,
        })
    }

    /// Radiance of the ground point `p` (on the plane) towards the eye.
    pub fn radiance(&self, scene: &Scene, p: Vec3) -> Rgb {
        // Marched on the dense copy of the density, as the eye rays are (the same bits).
        let t = scene.medium.dense_transmittance(p, scene.sun.dir, 0.0, f32::INFINITY) as f64;
        let t_scaled = Rgb::from(self.scale.map(|s| t.powf(s) as f32));
        self.sun * t_scaled + self.diffuse_at(p.x as f64, p.z as f64)
    }

    /// Bilinear in the filtered columns. Beyond the map: the clear sky's plus the map's nearest
    /// edge's excess over it, scaled by the irradiance ratio of a small source at the cloud's
    /// centre, (H² + r_e²)^{3/2}/(H² + r²)^{3/2} (cos θ/distance², H its height, r and r_e the
    /// horizontal distances of the point and of the edge from it).
    fn diffuse_at(&self, x: f64, z: f64) -> Rgb {
        let u = (x - self.first[0]) / self.h[0];
        let v = (z - self.first[1]) / self.h[1];
        let (n, m) = (self.dims[0] as f64, self.dims[1] as f64);
        let (uc, vc) = (u.clamp(-0.5, n - 0.5), v.clamp(-0.5, m - 0.5));
        if (uc, vc) == (u, v) {
            return self.bilinear(u, v);
        }
        let edge = self.bilinear(uc, vc);
        let (xe, ze) = (self.first[0] + uc * self.h[0], self.first[1] + vc * self.h[1]);
        let h2 = self.cloud[2] * self.cloud[2];
        let r2 = |x: f64, z: f64| (x - self.cloud[0]).powi(2) + (z - self.cloud[1]).powi(2);
        let falloff = ((h2 + r2(xe, ze)) / (h2 + r2(x, z))).powf(1.5).min(1.0) as f32;
        self.clear + (edge - self.clear) * falloff
    }

    /// Bilinear in the filtered columns at column coordinates (u, v), clamped to the map.
    fn bilinear(&self, u: f64, v: f64) -> Rgb {
        let (n, m) = (self.dims[0] as f64, self.dims[1] as f64);
        let (u, v) = (u.clamp(0.0, n - 1.0), v.clamp(0.0, m - 1.0));
        let (i, k) = (
            (u.floor() as usize).min(self.dims[0].saturating_sub(2)),
            (v.floor() as usize).min(self.dims[1].saturating_sub(2)),
        );
        let (tu, tv) = ((u - i as f64) as f32, (v - k as f64) as f32);
        let at = |i: usize, k: usize| self.diffuse[i.min(self.dims[0] - 1) + self.dims[0] * k.min(self.dims[1] - 1)];
        (at(i, k) * (1.0 - tu) + at(i + 1, k) * tu) * (1.0 - tv) + (at(i, k + 1) * (1.0 - tu) + at(i + 1, k + 1) * tu) * tv
    }
}

/// Half-width (m) of the box that filters the map at horizontal distances `dx`, `dz` (m) from the
/// cloud's footprint, for a cloud bottom `height` (m) above the ground and ordinates `spacing`
/// (rad) apart, on the map's columns of size `column` (m). Two ordinates a polar step apart,
/// leaving the bottom, land (H² + X²)/H Δθ apart at horizontal distance X (and X Δφ apart
/// sideways, less). Beside the footprint the box stops short of it (it reaches no column centre
/// under it: half-width at most the distance to it less half a column, as [`filtered`] rounds to
/// whole columns; at least the width under the cloud): under a cloud near the ground the columns
/// hold its glow, far brighter than the light beside it (a box reaching under a fog bank makes
/// the ground in front of it +23 % against `reference`).
fn filter_half_width(height: f64, spacing: f64, dx: f64, dz: f64, column: f64) -> f64 {
    let landing = (height * height + dx * dx + dz * dz) / height * spacing;
    landing.min((dx.max(dz) - 0.5 * column).max(height * spacing))
}

/// The map's diffuse part, each column the mean over the square of half-width `width(x, z)` (m)
/// around it (clipped to the map), by a summed-area table.
fn filtered(map: &GroundMap, first: [f64; 2], width: impl Fn(f64, f64) -> f64) -> Vec<Rgb> {
    let [nx, nz] = map.dims;
    let mut sat = vec![[0f64; 3]; (nx + 1) * (nz + 1)];
    for k in 0..nz {
        for i in 0..nx {
            let c = map.diffuse[i + nx * k];
            let s = |i: usize, k: usize| sat[i + (nx + 1) * k];
            let (a, b, d) = (s(i, k + 1), s(i + 1, k), s(i, k));
            sat[i + 1 + (nx + 1) * (k + 1)] = [0, 1, 2].map(|band| c[band] as f64 + a[band] + b[band] - d[band]);
        }
    }
    (0..nx * nz)
        .map(|c| {
            let (i, k) = (c % nx, c / nx);
            let (x, z) = (first[0] + i as f64 * map.h[0], first[1] + k as f64 * map.h[1]);
            let w = width(x, z);
            let r = [0, 1].map(|a| (w / map.h[a]).round().clamp(0.0, 4096.0) as usize);
            let (i0, i1) = (i.saturating_sub(r[0]), (i + r[0] + 1).min(nx));
            let (k0, k1) = (k.saturating_sub(r[1]), (k + r[1] + 1).min(nz));
            let s = |i: usize, k: usize| sat[i + (nx + 1) * k];
            let area = ((i1 - i0) * (k1 - k0)) as f64;
            Rgb::from([0, 1, 2].map(|b| ((s(i1, k1)[b] - s(i0, k1)[b] - s(i1, k0)[b] + s(i0, k0)[b]) / area) as f32))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4×4 map of 10-m columns whose diffuse light is 0.5 above a clear 0.2: inside it reads the
    /// map, at its edge the same, beyond it falls towards the clear value, never past it.
    #[test]
    fn the_ground_beyond_the_map_continues_its_edge_and_falls_to_the_clear_value() {
        let g = EyeGround {
            diffuse: vec![Rgb::splat(0.5); 16],
            clear: Rgb::splat(0.2),
            dims: [4, 4],
            first: [5.0, 5.0],
            h: [10.0, 10.0],
            sun: Rgb::ZERO,
            scale: [1.0; 3],
            cloud: [20.0, 20.0, 100.0],
        };
        let at = |x: f64| g.diffuse_at(x, 20.0).x;
        assert!((at(20.0) - 0.5).abs() < 1e-6);
        // The map ends at x = 40 (column 3's centre 35 plus half a column).
        assert!((at(40.0) - 0.5).abs() < 1e-6 && (at(40.001) - 0.5).abs() < 1e-4);
        let (near, far) = (at(100.0), at(1000.0));
        assert!(near < 0.5 && far < near && far > 0.2 && far < 0.21, "{near} {far}");
    }

    /// A fog bank 10 m above the ground over columns 10–19 of a 40-column map, its glow under it
    /// (5) far above the light beside it (1): the ground 50 m beside it reads its own columns,
    /// not the glow (the landing spacing there, (H² + X²)/H Δθ ≈ 100 m, would reach under it);
    /// under it the box is H Δθ wide.
    #[test]
    fn the_filter_beside_a_low_cloud_does_not_reach_under_it() {
        let (n, h) = (40usize, 10.0);
        let glow = |i: usize, k: usize| (10..20).contains(&i) && (10..20).contains(&k);
        let diffuse: Vec<Rgb> = (0..n * n).map(|c| Rgb::splat(if glow(c % n, c / n) { 5.0 } else { 1.0 })).collect();
        let map = GroundMap {
            margin: 0,
            dims: [n, n],
            radiance: diffuse.clone(),
            diffuse,
            clear: Rgb::splat(1.0),
            origin: [0.0, 0.0],
            h: [h, h],
        };
        let (height, spacing) = (10.0, std::f64::consts::PI / 8.0);
        let foot = [100.0, 200.0];
        let out = filtered(&map, [5.0, 5.0], |x, z| {
            let d = |v: f64| (foot[0] - v).max(v - foot[1]).max(0.0);
            filter_half_width(height, spacing, d(x), d(z), h)
        });
        // Column 25 (centre x = 255 m) lies 55 m beside the footprint's edge at x = 200 m.
        assert_eq!(out[25 + n * 15].x, 1.0, "beside the fog");
        assert_eq!(out[15 + n * 15].x, 5.0, "under the fog");
        assert_eq!(out[20 + n * 15].x, 1.0, "just beside the fog");
        assert!((filter_half_width(height, spacing, 0.0, 0.0, h) - height * spacing).abs() < 1e-12);
        // A cloud far above the ground: 400 m beside it the landing spacing is the narrower and
        // stays; 100 m beside it the box is as wide as under it.
        assert!((filter_half_width(300.0, spacing, 400.0, 0.0, h) - 25e4 / 300.0 * spacing).abs() < 1e-9);
        assert!((filter_half_width(300.0, spacing, 100.0, 0.0, h) - 300.0 * spacing).abs() < 1e-9);
    }
}
