//! The Lambertian ground under the transport solve: its radiance per column of the grid's
//! horizontal spacing, ρ_g/π (E_sun μ_s T′ + E_down), over the footprint grown as far as the
//! cloud's shadow reaches. E_down is the clear sky's plus the cloud's change to it in the last
//! sweep (light leaving the box downwards minus the sky it hides), so every ground bounce is
//! iterated.

use super::TransportOptics;
use crate::lighting::{Ground, Sky, Sun};
use crate::math::{Rgb, Vec3};
use crate::medium::Medium;
use std::f64::consts::PI;

/// Radiance of the Lambertian ground (W·m⁻²·sr⁻¹) on columns of the grid's horizontal spacing,
/// over the grid's footprint grown by `margin` columns (as far as the cloud's shadow reaches);
/// `clear`, the unshadowed ground, beyond.
#[derive(Clone, Debug)]
pub struct GroundMap {
    /// Columns added on every side of the footprint.
    pub margin: usize,
    /// Columns per axis (x, z).
    pub dims: [usize; 2],
    /// Per column, x fastest.
    pub radiance: Vec<Rgb>,
    /// Per column, the part of `radiance` from the sky's and the cloud's diffuse light
    /// (ρ_g/π E_down; the rest is the shadowed sun), for the gather to filter.
    pub diffuse: Vec<Rgb>,
    /// Beyond the map.
    pub clear: Rgb,
    /// World x, z of the grid's minimum corner (m) and the column size (m).
    pub origin: [f64; 2],
    /// Column size (m).
    pub h: [f64; 2],
}

impl GroundMap {
    /// Column index (x, z) of world (x, z), if on the map.
    #[inline]
    pub(super) fn column(&self, x: f64, z: f64) -> Option<usize> {
        let gi = ((x - self.origin[0]) / self.h[0]).floor() + self.margin as f64;
        let gk = ((z - self.origin[1]) / self.h[1]).floor() + self.margin as f64;
        (gi >= 0.0 && gk >= 0.0 && (gi as usize) < self.dims[0] && (gk as usize) < self.dims[1])
            .then(|| gi as usize + self.dims[0] * gk as usize)
    }

    /// Radiance at world (x, z).
    #[inline]
    pub fn at(&self, x: f64, z: f64) -> Rgb {
        self.column(x, z).map_or(self.clear, |c| self.radiance[c])
    }
}

/// What the ground map is made of that stays fixed through the iteration: the columns, the δ-M
/// sun transmittance T′ at each, the sun and the clear sky's downward irradiance.
pub(super) struct GroundLight<'a> {
    ground: Option<&'a Ground>,
    margin: usize,
    dims: [usize; 2],
    /// δ-M sun transmittance T′ per column and band.
    sun_t: Vec<[f64; 3]>,
    /// Sun irradiance per band (W/m²) and the cosine of its zenith angle.
    e_sun: [f64; 3],
    mu_s: f64,
    /// The clear sky's downward irradiance per band (W/m²).
    sky_down: [f64; 3],
    clear: Rgb,
    origin: [f64; 2],
    h: [f64; 2],
}

impl<'a> GroundLight<'a> {
    /// The columns under medium `m`: the footprint grown by the reach of the cloud's shadow
    /// (at most twice the footprint), and T′ = T^{σt′/σt} of the sun at each.
    pub(super) fn new(m: &Medium, sun: &Sun, sky: &Sky, ground: Option<&'a Ground>, optics: &TransportOptics) -> GroundLight<'a> {
        let [nx, ny, nz] = m.dims();
        let (hx, hz) = (m.voxel_size.x as f64, m.voxel_size.z as f64);
        let margin = match ground {
            Some(g) => {
                let top = (m.origin.y + m.voxel_size.y * ny as f32 - g.height).max(0.0) as f64;
                let tan = (1.0 - (sun.dir.y as f64).powi(2)).max(0.0).sqrt() / (sun.dir.y as f64).max(1e-3);
                ((top * tan / hx.min(hz)).ceil() as usize).min(2 * nx.max(nz))
            }
            None => 0,
        };
        let dims = [nx + 2 * margin, nz + 2 * margin];
        let col_xz = |c: usize| {
            let (i, k) = ((c % dims[0]) as f64 - margin as f64, (c / dims[0]) as f64 - margin as f64);
            (m.origin.x as f64 + (i + 0.5) * hx, m.origin.z as f64 + (k + 0.5) * hz)
        };
        let bands = &optics.bands;
        // A march per column: a few dozen columns per task.
        let sun_t = crate::par::map_items(dims[0] * dims[1], 64, &|c| match ground {
            Some(g) => {
                let (x, z) = col_xz(c);
                let t = m.transmittance(Vec3::new(x as f32, g.height, z as f32), sun.dir, 0.0, f32::INFINITY) as f64;
                [0, 1, 2].map(|b| t.powf(bands[b].sigma_t / optics.sigma_t))
            }
            None => [0.0; 3],
        });
        GroundLight {
            ground,
            margin,
            dims,
            sun_t,
            e_sun: [sun.irradiance.x as f64, sun.irradiance.y as f64, sun.irradiance.z as f64],
            mu_s: sun.dir.y.max(0.0) as f64,
            sky_down: [sky.irradiance_up.x as f64, sky.irradiance_up.y as f64, sky.irradiance_up.z as f64],
            clear: ground.map_or(Rgb::ZERO, |g| g.radiance(Vec3::ZERO, sun, sky, 1.0)),
            origin: [m.origin.x as f64, m.origin.z as f64],
            h: [hx, hz],
        }
    }

    /// The cloud's change to the sky's downward irradiance (W/m² per column and band) that
    /// `old`, another frame's map, implies at each of these columns' centres: its downward
    /// diffuse irradiance there, less this sky's; zero off `old` (a warm start's, src/transport/warm.rs).
    /// None without a ground.
    pub(super) fn e_down_from(&self, old: &GroundMap) -> Option<Vec<[f64; 3]>> {
        let g = self.ground?;
        let [nx, _] = self.dims;
        let e = (0..self.dims[0] * self.dims[1])
            .map(|c| {
                let (i, k) = ((c % nx) as f64 - self.margin as f64, (c / nx) as f64 - self.margin as f64);
                let (x, z) = (self.origin[0] + (i + 0.5) * self.h[0], self.origin[1] + (k + 0.5) * self.h[1]);
                let Some(o) = old.column(x, z) else {
                    return [0.0; 3];
                };
                let d = old.diffuse[o].to_array();
                [0, 1, 2].map(|b| {
                    let albedo = g.albedo[b] as f64;
                    if albedo > 0.0 {
                        d[b] as f64 * PI / albedo - self.sky_down[b]
                    } else {
                        0.0
                    }
                })
            })
            .collect();
        Some(e)
    }

    /// The ground's radiance with the cloud's change `e_down` (W/m² per column and band) to the
    /// sky's downward irradiance; None: the clear sky's alone.
    pub(super) fn map(&self, e_down: Option<&[[f64; 3]]>) -> GroundMap {
        let columns = self.dims[0] * self.dims[1];
        let (radiance, diffuse) = match self.ground {
            Some(g) => (0..columns)
                .map(|c| {
                    let de = e_down.map_or([0.0; 3], |e| e[c]);
                    let e = [0, 1, 2].map(|b| (self.sky_down[b] + de[b]).max(0.0));
                    let total = [0, 1, 2].map(|b| (g.albedo[b] as f64 / PI * (self.e_sun[b] * self.mu_s * self.sun_t[c][b] + e[b])) as f32);
                    let diffuse = [0, 1, 2].map(|b| (g.albedo[b] as f64 / PI * e[b]) as f32);
                    (Rgb::from(total), Rgb::from(diffuse))
                })
                .unzip(),
            None => (vec![Rgb::ZERO; columns], vec![Rgb::ZERO; columns]),
        };
        GroundMap {
            margin: self.margin,
            dims: self.dims,
            radiance,
            diffuse,
            clear: self.clear,
            origin: self.origin,
            h: self.h,
        }
    }
}
