//! The built-in procedural cumulus: deterministic from its seed, at any resolution, with the
//! paper's proportions (in a 100×80×60 box the non-zero region is about 91×51×25 voxels): a dense
//! core, billowing towers, tenuous fBm-eroded edges and a flatter base.
//!
//! The shape is defined in normalised box coordinates, so a finer resolution samples the same
//! cloud more finely.

use super::Grid3;
use crate::math::{mix64, Rng};
use crate::par;

/// Peak density of the core (unitless; with σt = 0.05 m⁻¹ and 10 m voxels, optical depth 0.75 per voxel).
const CORE_DENSITY: f32 = 1.5;

/// Improved Perlin gradient noise with a seeded permutation.
struct Noise {
    perm: [u8; 512],
}

impl Noise {
    fn new(seed: u64) -> Self {
        let mut p: Vec<u8> = (0..=255).collect();
        let mut rng = Rng::new(mix64(seed), 0x6e6f697365);
        for i in (1..256).rev() {
            let j = (rng.next_u32() as usize) % (i + 1);
            p.swap(i, j);
        }
        let mut perm = [0u8; 512];
        for i in 0..512 {
            perm[i] = p[i & 255];
        }
        Noise { perm }
    }

    #[inline]
    fn grad(h: u8, x: f32, y: f32, z: f32) -> f32 {
        let h = h & 15;
        let u = if h < 8 { x } else { y };
        let v = if h < 4 {
            y
        } else if h == 12 || h == 14 {
            x
        } else {
            z
        };
        (if h & 1 == 0 { u } else { -u }) + (if h & 2 == 0 { v } else { -v })
    }

    /// Gradient noise in about [-1, 1].
    fn noise(&self, x: f32, y: f32, z: f32) -> f32 {
        let fade = |t: f32| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
        let (xf, yf, zf) = (x.floor(), y.floor(), z.floor());
        let (xi, yi, zi) = ((xf as i32 & 255) as usize, (yf as i32 & 255) as usize, (zf as i32 & 255) as usize);
        let (x, y, z) = (x - xf, y - yf, z - zf);
        let (u, v, w) = (fade(x), fade(y), fade(z));
        let p = &self.perm;
        let a = p[xi] as usize + yi;
        let (aa, ab) = (p[a] as usize + zi, p[a + 1] as usize + zi);
        let b = p[xi + 1] as usize + yi;
        let (ba, bb) = (p[b] as usize + zi, p[b + 1] as usize + zi);
        let lerp = |t: f32, a: f32, b: f32| a + t * (b - a);
        lerp(
            w,
            lerp(
                v,
                lerp(u, Self::grad(p[aa], x, y, z), Self::grad(p[ba], x - 1.0, y, z)),
                lerp(u, Self::grad(p[ab], x, y - 1.0, z), Self::grad(p[bb], x - 1.0, y - 1.0, z)),
            ),
            lerp(
                v,
                lerp(u, Self::grad(p[aa + 1], x, y, z - 1.0), Self::grad(p[ba + 1], x - 1.0, y, z - 1.0)),
                lerp(
                    u,
                    Self::grad(p[ab + 1], x, y - 1.0, z - 1.0),
                    Self::grad(p[bb + 1], x - 1.0, y - 1.0, z - 1.0),
                ),
            ),
        )
    }

    /// Billowy fBm: Σ |noise| · gain^o, normalised to about [0, 1].
    fn billow(&self, x: f32, y: f32, z: f32, octaves: u32) -> f32 {
        let (mut sum, mut amp, mut freq, mut norm) = (0.0, 1.0, 1.0, 0.0);
        for o in 0..octaves {
            let off = o as f32 * 17.31;
            sum += amp * self.noise(x * freq + off, y * freq - off, z * freq + 2.0 * off).abs();
            norm += amp;
            amp *= 0.5;
            freq *= 2.03;
        }
        (sum / norm * 1.6).min(1.0)
    }
}

/// An ellipsoidal puff in normalised cloud coordinates.
#[derive(Clone, Copy, Debug)]
struct Puff {
    c: [f32; 3],
    r: [f32; 3],
}

fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The puffs of the cumulus: a wide flat-bottomed base and seeded towers, all inside
/// X ∈ [-1, 1], Y ∈ [0, 1], Z ∈ [-1, 1].
fn puffs(seed: u64) -> Vec<Puff> {
    let mut rng = Rng::new(mix64(seed), 0x7075666673);
    let mut v = vec![
        Puff {
            c: [0.0, 0.15, 0.0],
            r: [0.97, 0.42, 0.9],
        },
        Puff {
            c: [0.0, 0.35, 0.0],
            r: [0.6, 0.35, 0.8],
        },
        Puff {
            c: [-0.55, 0.22, 0.05],
            r: [0.42, 0.30, 0.75],
        },
        Puff {
            c: [0.55, 0.22, -0.05],
            r: [0.42, 0.32, 0.75],
        },
    ];
    // Towers: bigger and higher towards the middle, like a growing cumulus.
    for t in 0..9 {
        let x = -0.7 + 1.4 * (t as f32 + rng.uniform()) / 9.0;
        let centrality = 1.0 - x.abs();
        let ry = 0.18 + 0.12 * centrality + 0.05 * rng.uniform();
        let cy = (0.25 + 0.45 * centrality * (0.7 + 0.3 * rng.uniform())).min(1.0 - ry);
        let rx = 0.18 + 0.1 * rng.uniform();
        let rz = 0.5 + 0.3 * rng.uniform();
        let cz = (rng.uniform() - 0.5) * 0.3;
        v.push(Puff {
            c: [x.clamp(-1.0 + rx, 1.0 - rx), cy, cz.clamp(-1.0 + rz, 1.0 - rz)],
            r: [rx, ry, rz],
        });
    }
    // Make sure the top tower reaches the top of the region.
    if let Some(top) = v.iter_mut().skip(3).max_by(|a, b| (a.c[1] + a.r[1]).total_cmp(&(b.c[1] + b.r[1]))) {
        top.c[1] = 1.0 - top.r[1];
    }
    v
}

/// Generate the cumulus on a grid of `dims` voxels.
pub fn cumulus(dims: [usize; 3], seed: u64) -> Grid3 {
    let noise = Noise::new(seed);
    let puffs = puffs(seed);
    // Region of the box the cloud may occupy (fractions of the box), after the paper's 91×51×25 of 100×80×60.
    let (x_half, y0, y_span, z_half) = (0.455f32, 0.17f32, 0.6375f32, 0.2083f32);
    let n = dims[0] * dims[1] * dims[2];
    let mut data = vec![0f32; n];
    par::for_chunks(&mut data, dims[0] * dims[1], &|k, slab| {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let u = (i as f32 + 0.5) / dims[0] as f32;
                let v = (j as f32 + 0.5) / dims[1] as f32;
                let w = (k as f32 + 0.5) / dims[2] as f32;
                let (x, y, z) = ((u - 0.5) / x_half, (v - y0) / y_span, (w - 0.5) / z_half);
                if x.abs() >= 1.0 || !(0.0..1.0).contains(&y) || z.abs() >= 1.0 {
                    continue;
                }
                // Union of puffs: 1 at a puff's centre, 0 on its surface.
                let mut f = 0f32;
                for p in &puffs {
                    let dx = (x - p.c[0]) / p.r[0];
                    let dy = (y - p.c[1]) / p.r[1];
                    let dz = (z - p.c[2]) / p.r[2];
                    f = f.max(1.0 - (dx * dx + dy * dy + dz * dz));
                }
                if f <= 0.0 {
                    continue;
                }
                // Noise in metres-like units: the same features at every resolution.
                let (nx, ny, nz) = (u * 9.0, v * 7.2, w * 5.4);
                let erosion = 0.5 * noise.billow(nx, ny, nz, 5) + 0.5 * noise.billow(nx * 3.1 + 5.2, ny * 3.1, nz * 3.1, 3);
                // Erode the edges most: wisps outside, an intact dense core.
                let s = f - 0.5 * erosion * (1.0 - 0.6 * f);
                // Flat base: a quick ramp over the bottom 6 % of the region.
                let s = s * smoothstep(0.0, 0.06, y);
                if s <= 0.0 {
                    continue;
                }
                slab[i + dims[0] * j] = CORE_DENSITY * smoothstep(0.0, 0.55, s).powf(1.3);
            }
        }
    });
    Grid3::from_vec(dims, data, "procedural cloud").expect("dims checked by caller")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deterministic_and_seed_dependent() {
        let a = cumulus([40, 32, 24], 1);
        let b = cumulus([40, 32, 24], 1);
        let c = cumulus([40, 32, 24], 2);
        assert_eq!(a, b);
        assert_ne!(a, c);
    }
}
