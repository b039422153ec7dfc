//! Light sources: the sun (a directional light, never binned), the sky, and the Lambertian ground.

pub mod atmosphere;
pub mod bins;
pub mod desc;
pub mod envmap;
pub mod map_sun;
pub mod sun_clip;

use crate::error::Result;
use crate::error::{check, rgb_in_unit, rgb_nonneg};
use crate::image::Image;
use crate::math::{Rgb, Vec3};
pub use desc::{GroundDesc, SkyDesc, SkyModel, SunDesc};
use glam::Vec2;
use std::f32::consts::PI;
use std::path::Path;
use std::sync::Arc;

pub use atmosphere::{Atmosphere, AtmosphereParams};
pub use bins::{DirectionBins, CUBE_FACES};
use bins::{narrowest_pixel_edge, BINS_PER_EDGE, NUM_BINS};
pub use envmap::EnvMap;

/// The sun: a directional light.
#[derive(Clone, Debug)]
pub struct Sun {
    /// Unit direction towards the sun.
    pub dir: Vec3,
    /// Irradiance on a plane perpendicular to the rays (W/m² per band).
    pub irradiance: Rgb,
}

impl Sun {
    /// Validate `[sun]`.
    pub fn from_desc(d: &SunDesc, file: &str) -> Result<Sun> {
        let dir = match (d.direction, d.elevation_deg, d.azimuth_deg) {
            (Some(v), None, None) => {
                let unit = crate::math::unit_vector(v);
                check(
                    file,
                    "sun.direction",
                    unit.is_some(),
                    v,
                    "must be a finite non-zero vector towards the sun",
                )?;
                unit.unwrap_or(Vec3::Y)
            }
            (None, Some(el), az) => {
                let az = az.unwrap_or(0.0);
                check(
                    file,
                    "sun.elevation_deg",
                    el.is_finite() && (-90.0..=90.0).contains(&el),
                    el,
                    "elevation must be in [-90, 90] degrees",
                )?;
                check(
                    file,
                    "sun.azimuth_deg",
                    az.is_finite(),
                    az,
                    "azimuth must be a finite number of degrees",
                )?;
                let (el, az) = (el.to_radians(), az.to_radians());
                Vec3::new(el.cos() * az.cos(), el.sin(), el.cos() * az.sin()).normalize()
            }
            (None, None, Some(_)) => {
                return Err(crate::Error::invalid(
                    file,
                    "sun.azimuth_deg",
                    "given without sun.elevation_deg: give both, or sun.direction",
                ));
            }
            // A `[sun]` table without a direction: the default scene's sun.
            (None, None, None) => Vec3::from(SunDesc::default().direction.unwrap_or([0.3, 0.8, 0.5])).normalize(),
            (Some(_), _, _) => {
                return Err(crate::Error::invalid(
                    file,
                    "sun.direction",
                    "given together with sun.elevation_deg/azimuth_deg: give one or the other",
                ));
            }
        };
        check(
            file,
            "sun.angular_diameter_deg",
            d.angular_diameter_deg.is_finite() && (0.0..=20.0).contains(&d.angular_diameter_deg),
            d.angular_diameter_deg,
            "the sun's angular diameter must be in [0, 20] degrees (0 = a point; the real sun is 0.53)",
        )?;
        check(
            file,
            "sun.irradiance",
            rgb_nonneg(d.irradiance),
            d.irradiance,
            "irradiance must be finite and non-negative (W/m²)",
        )?;
        Ok(Sun {
            dir,
            irradiance: Rgb::from(d.irradiance),
        })
    }
}

/// The sky's radiance model.
#[derive(Clone, Debug)]
pub enum SkyKind {
    /// The same radiance (W·m⁻²·sr⁻¹ per band) from every direction.
    Constant(Rgb),
    /// The physically based atmosphere ([`atmosphere`]), precomputed into an equirectangular map.
    Atmosphere {
        /// The atmosphere and its LUTs.
        atmosphere: Arc<Atmosphere>,
        /// Observer altitude above the planet's ground (m).
        altitude_m: f32,
        /// Unit direction towards the sun the map was computed for.
        sun_dir: Vec3,
        /// The sky as an equirectangular map (W·m⁻²·sr⁻¹ per band).
        map: Arc<EnvMap>,
    },
    /// An equirectangular HDR environment map read from a file (already scaled).
    EnvMap {
        /// The map (W·m⁻²·sr⁻¹ per band).
        map: Arc<EnvMap>,
    },
}

/// The sky: radiance arriving from each direction, plus cached integrals.
#[derive(Clone, Debug)]
pub struct Sky {
    /// The model.
    pub kind: SkyKind,
    /// Irradiance on an upward-facing horizontal plane from the whole unoccluded upper
    /// hemisphere (W/m² per band).
    pub irradiance_up: Rgb,
    /// The clipped top of the sun `sky.extract_sun` took out of this sky's map, if it had one:
    /// the scene's sun is then a lower bound on the map's.
    pub extracted_sun_clip: Option<sun_clip::SunClip>,
    /// How the scene's sun came out of this sky's map, if it did.
    pub sun_from_map: Option<SunFromMap>,
}

/// Why the scene's sun was taken out of the sky's map (`sky.extract_sun`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SunFromMap {
    /// `sky.extract_sun = true`.
    Asked,
    /// `sky.extract_sun` left out, the map holding a sun ([`map_sun::CompactSource::is_sun`])
    /// and the scene's `[sun]` no light of its own.
    Found,
}

/// Default width of the atmosphere's equirectangular map (pixels; height = width / 2).
pub const DEFAULT_MAP_WIDTH: u32 = 512;

/// Validate `[sun]` and `[sky]` together (the atmosphere needs the sun's direction, and
/// `sun.from_atmosphere` needs the atmosphere). Relative `sky.path` resolves against `base_dir`.
pub fn sun_and_sky(sun: &SunDesc, sky: &SkyDesc, file: &str, base_dir: &Path) -> Result<(Sun, Sky)> {
    let mut s = Sun::from_desc(sun, file)?;
    let k = Sky::from_desc_with_sun(sky, s.dir, file, base_dir)?;
    match sky.extract_sun {
        Some(true) => return map_sun_and_sky(sun, sky, &k, file),
        Some(false) => {}
        None => {
            if let Some(found) = found_map_sun(sun, sky, &k) {
                return Ok(found);
            }
        }
    }
    if sun.from_atmosphere {
        let atm = match &k.kind {
            SkyKind::Atmosphere { atmosphere, .. } => atmosphere.clone(),
            _ => Arc::new(Atmosphere::new(atmosphere_params(sky, file)?)),
        };
        check_altitude(sky, file)?;
        s.irradiance = atm.sun_irradiance(sky.altitude_m as f64, s.dir.as_dvec3()).as_vec3();
    }
    Ok((s, k))
}

/// Whether `sun` gives the scene a sun of its own: a `[sun]` other than the default (the table
/// left out) with light.
fn has_own_sun(sun: &SunDesc) -> bool {
    *sun != SunDesc::default() && (sun.from_atmosphere || sun.irradiance.iter().any(|&e| e > 0.0))
}

/// The scene's sun taken out of the map, and the map left, as `how` asked.
fn taken_out(x: map_sun::ExtractedSun, how: SunFromMap) -> (Sun, Sky) {
    let sun = Sun {
        dir: x.direction,
        irradiance: x.irradiance,
    };
    let sky = Sky {
        extracted_sun_clip: x.clip,
        sun_from_map: Some(how),
        ..Sky::from_envmap(x.map)
    };
    (sun, sky)
}

/// `sky.extract_sun` left out: the map's sun taken out as the scene's where an environment map
/// holds one ([`map_sun::CompactSource::is_sun`]) and the scene no sun of its own. Every method
/// but `reference` carries a directional sun exactly and a map's sun only blurred over cells
/// about 20° wide (docs/sky.md, "A sun in the map"); `reference` renders the same scene either way.
fn found_map_sun(sun: &SunDesc, sky: &SkyDesc, built: &Sky) -> Option<(Sun, Sky)> {
    let map = built.map().filter(|_| sky.model == SkyModel::Envmap && !has_own_sun(sun))?;
    map.compact_source().filter(map_sun::CompactSource::is_sun)?;
    map.extract_sun().ok().map(|x| taken_out(x, SunFromMap::Found))
}

/// `sky.extract_sun = true`: the map's sun taken out of it ([`EnvMap::extract_sun`]) as the
/// scene's one sun, so a `[sun]` with light of its own is refused.
fn map_sun_and_sky(sun: &SunDesc, sky: &SkyDesc, built: &Sky, file: &str) -> Result<(Sun, Sky)> {
    let key = "sky.extract_sun";
    let map = match (sky.model, built.map()) {
        (SkyModel::Envmap, Some(map)) => map,
        _ => {
            return Err(crate::Error::invalid(
                file,
                key,
                "takes a sun out of an environment map: it needs sky.model = \"envmap\" (the atmosphere's sun is \
                 the scene's [sun] already); leave sky.extract_sun out or set it false",
            ))
        }
    };
    if has_own_sun(sun) {
        return Err(crate::Error::invalid(
            file,
            key,
            "makes the map's sun the scene's sun, and the [sun] table gives another; a scene has one sun: leave \
             the [sun] table out (or set sun.irradiance = [0, 0, 0]), or set sky.extract_sun = false",
        ));
    }
    let path = sky.path.as_deref().unwrap_or_default();
    let why = match map.extract_sun() {
        Ok(x) => return Ok(taken_out(x, SunFromMap::Asked)),
        Err(map_sun::NoSun::Black) => format!("`{path}` is black: it holds no sun"),
        Err(map_sun::NoSun::NotBright(ratio)) => {
            let clipped = match map.plateau_at_max() {
                Some((top, pixels)) => format!(
                    " ({pixels} pixels hold its brightest value, {} in the file: if its sun was clipped there, at a format's or \
                     camera's ceiling, the map has lost the sun's light; use an HDRI whose sun is not clipped)",
                    top / sky.scale
                ),
                None => String::new(),
            };
            format!(
                "the brightest pixel of `{path}` is {ratio:.1} times the map's mean radiance; a sun's pixels are over \
                 {} times it{clipped}",
                map_sun::BRIGHT_OVER_MEAN
            )
        }
        Err(map_sun::NoSun::TooWide(sr)) => format!(
            "the bright pixels around the brightest one of `{path}` cover {sr:.2e} sr, more than a sun's {:.0e} sr (a \
             cap about 3° in radius): a directional sun would not stand for them",
            map_sun::MAX_SUN_SOLID_ANGLE
        ),
    };
    Err(crate::Error::invalid(file, key, format!("{why}; set sky.extract_sun = false")))
}

fn check_altitude(d: &SkyDesc, file: &str) -> Result<()> {
    check(
        file,
        "sky.altitude_m",
        d.altitude_m.is_finite() && (0.0..90_000.0).contains(&d.altitude_m),
        d.altitude_m,
        "the observer's altitude must be in [0, 90000) m (the atmosphere's top is at 100 km)",
    )
}

/// Earth atmosphere parameters with the scene's `sky.planet_albedo`.
fn atmosphere_params(d: &SkyDesc, file: &str) -> Result<AtmosphereParams> {
    check(
        file,
        "sky.planet_albedo",
        rgb_in_unit(d.planet_albedo),
        d.planet_albedo,
        "each band must be in [0, 1]",
    )?;
    Ok(AtmosphereParams {
        ground_albedo: Vec3::from(d.planet_albedo).as_dvec3(),
        ..Default::default()
    })
}

impl Sky {
    /// Validate `[sky]` for models that do not depend on the sun (`constant`, `envmap`); the
    /// atmosphere needs the sun: use [`Sky::from_desc_with_sun`] or [`sun_and_sky`].
    pub fn from_desc(d: &SkyDesc, file: &str, base_dir: &Path) -> Result<Sky> {
        if d.model == SkyModel::Atmosphere {
            return Err(crate::Error::invalid(
                file,
                "sky.model",
                "\"atmosphere\" depends on the sun: build it with lighting::sun_and_sky (Scene::build does)",
            ));
        }
        Sky::from_desc_with_sun(d, Vec3::Y, file, base_dir)
    }

    /// Validate `[sky]` for a sun in unit direction `sun_dir` and precompute what it needs.
    pub fn from_desc_with_sun(d: &SkyDesc, sun_dir: Vec3, file: &str, base_dir: &Path) -> Result<Sky> {
        match d.model {
            SkyModel::Constant => {
                check(
                    file,
                    "sky.radiance",
                    rgb_nonneg(d.radiance),
                    d.radiance,
                    "radiance must be finite and non-negative (W/(m² sr))",
                )?;
                Ok(Sky::constant(Rgb::from(d.radiance)))
            }
            SkyModel::Atmosphere => {
                check_altitude(d, file)?;
                check(
                    file,
                    "sky.map_width",
                    (16..=8192).contains(&d.map_width) && d.map_width % 2 == 0,
                    d.map_width,
                    "the map width must be even and in [16, 8192] pixels (height = width / 2)",
                )?;
                let atm = Arc::new(Atmosphere::new(atmosphere_params(d, file)?));
                Ok(Sky::atmosphere(atm, d.altitude_m, sun_dir, d.map_width as usize))
            }
            SkyModel::Envmap => {
                let rel = d.path.as_deref().filter(|p| !p.is_empty()).ok_or_else(|| {
                    crate::Error::invalid(
                        file,
                        "sky.path",
                        "missing: sky.model = \"envmap\" needs sky.path, an equirectangular .exr relative to the scene file",
                    )
                })?;
                check(
                    file,
                    "sky.scale",
                    d.scale.is_finite() && d.scale >= 0.0,
                    d.scale,
                    "the radiance scale must be finite and non-negative",
                )?;
                let path = base_dir.join(rel);
                if !path.is_file() {
                    return Err(crate::Error::invalid(
                        file,
                        "sky.path",
                        format!("`{}` is not a file (paths are relative to the scene file)", path.display()),
                    ));
                }
                let img = crate::image::Image::read_exr(&path)?;
                let map = EnvMap::from_image(&img, d.scale, &path.display().to_string())?;
                // The scaled radiance obeys the scene's light bound (limits::MAX_LIGHT), in f64 so
                // that the product itself cannot overflow.
                let brightest = img.pixels.iter().map(|p| p.max_element()).fold(0.0_f32, f32::max);
                let scaled = f64::from(brightest) * f64::from(d.scale);
                if scaled > f64::from(crate::limits::MAX_LIGHT) {
                    return Err(crate::Error::invalid(
                        file,
                        "sky.scale",
                        format!(
                            "{} times the brightest pixel of `{}` ({brightest:e}) is {scaled:e}, above the light bound \
                             {:e} (larger values overflow f32 in the methods); lower sky.scale",
                            d.scale,
                            path.display(),
                            crate::limits::MAX_LIGHT
                        ),
                    ));
                }
                Ok(Sky::from_envmap(map))
            }
        }
    }

    /// A constant sky.
    pub fn constant(l: Rgb) -> Sky {
        Sky {
            kind: SkyKind::Constant(l),
            irradiance_up: l * PI,
            extracted_sun_clip: None,
            sun_from_map: None,
        }
    }

    /// A sky from an environment map.
    pub fn from_envmap(map: EnvMap) -> Sky {
        let irradiance_up = map.irradiance_up();
        Sky {
            kind: SkyKind::EnvMap { map: Arc::new(map) },
            irradiance_up,
            extracted_sun_clip: None,
            sun_from_map: None,
        }
    }

    /// The atmosphere seen from `altitude_m` with the sun towards `sun_dir`, precomputed into a
    /// `width` × `width/2` map.
    pub fn atmosphere(atmosphere: Arc<Atmosphere>, altitude_m: f32, sun_dir: Vec3, width: usize) -> Sky {
        let sun_dir = sun_dir.normalize();
        let h = (width / 2).max(1);
        let px = atmosphere.render_map(altitude_m as f64, sun_dir, width, h);
        let map = EnvMap::new(width, h, px);
        let irradiance_up = map.irradiance_up();
        Sky {
            kind: SkyKind::Atmosphere {
                atmosphere,
                altitude_m,
                sun_dir,
                map: Arc::new(map),
            },
            irradiance_up,
            extracted_sun_clip: None,
            sun_from_map: None,
        }
    }

    /// The largest radiance of any band from any direction (W·m⁻²·sr⁻¹).
    pub fn brightest(&self) -> f32 {
        match (&self.kind, self.map()) {
            (SkyKind::Constant(l), _) => l.max_element(),
            (_, Some(map)) => map.pixels.iter().fold(0.0, |m, p| m.max(p.max_element())),
            (_, None) => unreachable!("every sky but the constant one has a map"),
        }
    }

    /// The equirectangular map behind this sky, if it has one.
    pub fn map(&self) -> Option<&EnvMap> {
        match &self.kind {
            SkyKind::Constant(_) => None,
            SkyKind::Atmosphere { map, .. } | SkyKind::EnvMap { map } => Some(map),
        }
    }

    /// Radiance arriving from direction `dir` (unit, pointing away from the observer towards the sky).
    #[inline]
    pub fn radiance(&self, dir: Vec3) -> Rgb {
        match &self.kind {
            SkyKind::Constant(l) => {
                let _ = dir;
                *l
            }
            SkyKind::Atmosphere { map, .. } | SkyKind::EnvMap { map } => map.radiance(dir),
        }
    }

    /// Draw a direction from two uniforms in [0, 1): (unit direction, its radiance, its
    /// solid-angle density in sr⁻¹). Constant sky: uniform on the sphere; map skies: density
    /// ∝ (Y_max + ε)·sin θ per pixel, Y_max over the pixel and its neighbours (see [`envmap`]).
    /// The sun is never sampled here.
    pub fn sample(&self, u: Vec2) -> (Vec3, Rgb, f32) {
        match &self.kind {
            SkyKind::Constant(l) => (crate::math::uniform_sphere(u.x, u.y), *l, 1.0 / (4.0 * PI)),
            SkyKind::Atmosphere { map, .. } | SkyKind::EnvMap { map } => map.sample(u),
        }
    }

    /// Solid-angle density (sr⁻¹) with which [`Sky::sample`] draws unit direction `dir`.
    pub fn pdf(&self, dir: Vec3) -> f32 {
        match &self.kind {
            SkyKind::Constant(_) => 1.0 / (4.0 * PI),
            SkyKind::Atmosphere { map, .. } | SkyKind::EnvMap { map } => map.pdf(dir),
        }
    }

    /// Power ∫_bin L dω (W/m² per band) of the sky in each of the 96 direction bins (constant:
    /// exactly L·Δω; maps: the map's mean over the bin, [`EnvMap::cell_means`], times Δω). The
    /// sun is never binned.
    pub fn bin_powers(&self, bins: &DirectionBins) -> Vec<Rgb> {
        match &self.kind {
            SkyKind::Constant(l) => bins.bins.iter().map(|b| *l * b.solid_angle as f32).collect(),
            SkyKind::Atmosphere { map, .. } | SkyKind::EnvMap { map } => {
                let means = map.cell_means(NUM_BINS, narrowest_pixel_edge(BINS_PER_EDGE), &|d| bins.bin_of(d), None);
                means.iter().zip(&bins.bins).map(|(l, b)| *l * b.solid_angle as f32).collect()
            }
        }
    }

    /// The sky as an equirectangular image (convention of [`envmap`]), `width` × `width/2`
    /// pixels; `None` keeps a map sky's own resolution (constant: 512 × 256). The atmosphere is
    /// recomputed at a new width, an envmap resampled.
    pub fn to_image(&self, width: Option<usize>) -> Image {
        match &self.kind {
            SkyKind::Constant(l) => {
                let w = width.unwrap_or(DEFAULT_MAP_WIDTH as usize);
                let mut img = Image::new(w as u32, (w / 2).max(1) as u32);
                img.pixels.iter_mut().for_each(|p| *p = *l);
                img
            }
            SkyKind::Atmosphere {
                atmosphere,
                altitude_m,
                sun_dir,
                map,
            } => match width {
                Some(w) if w != map.width => {
                    let h = (w / 2).max(1);
                    let mut img = Image::new(w as u32, h as u32);
                    img.pixels = atmosphere.render_map(*altitude_m as f64, *sun_dir, w, h);
                    img
                }
                _ => map.to_image(),
            },
            SkyKind::EnvMap { map } => match width {
                Some(w) if w != map.width => map.resample(w, (w / 2).max(1)).to_image(),
                _ => map.to_image(),
            },
        }
    }
}

/// The ground: the infinite Lambertian plane y = height.
#[derive(Clone, Debug)]
pub struct Ground {
    /// Height of the plane (m).
    pub height: f32,
    /// Lambertian albedo per band.
    pub albedo: Rgb,
}

impl Ground {
    /// Validate `[ground]`.
    pub fn from_desc(d: &GroundDesc, file: &str) -> Result<Ground> {
        check(file, "ground.height", d.height.is_finite(), d.height, "must be a finite height (m)")?;
        check(
            file,
            "ground.albedo",
            rgb_in_unit(d.albedo),
            d.albedo,
            "each band must be in [0, 1]",
        )?;
        Ok(Ground {
            height: d.height,
            albedo: Rgb::from(d.albedo),
        })
    }

    /// Distance along a ray to the plane, seen from above only.
    #[inline]
    pub fn intersect(&self, origin: Vec3, dir: Vec3) -> Option<f32> {
        if origin.y > self.height && dir.y < -GRAZING_COSINE {
            Some((self.height - origin.y) / dir.y)
        } else {
            None
        }
    }

    /// Irradiance (W/m² per band) at a ground point from the sun with visibility `sun_visibility`
    /// (cloud transmittance towards the sun) and the unoccluded sky.
    #[inline]
    pub fn irradiance(&self, sun: &Sun, sky: &Sky, sun_visibility: f32) -> Rgb {
        sun.irradiance * (sun.dir.y.max(0.0) * sun_visibility) + sky.irradiance_up
    }

    /// Outgoing radiance (W·m⁻²·sr⁻¹) of the ground at `_p`.
    #[inline]
    pub fn radiance(&self, _p: Vec3, sun: &Sun, sky: &Sky, sun_visibility: f32) -> Rgb {
        self.albedo * self.irradiance(sun, sky, sun_visibility) / PI
    }
}

/// Cosine below which a ray going down meets the ground plane (a ray closer to horizontal runs
/// along it, as the sun on the horizon does).
const GRAZING_COSINE: f32 = 1e-7;

/// The sun as the scene above `ground` receives it: a sun below the ground's horizon is hidden by
/// the opaque plane from every point above it (every shadow ray towards it meets the plane), so
/// it lights nothing directly and only the sky lights the scene. Applied once to the scene, so
/// every method (and `reference`) sees the same sun. A medium is taken to lie above its ground.
pub fn sun_over_ground(sun: Sun, ground: Option<&Ground>) -> Sun {
    match ground {
        Some(_) if sun.dir.y < -GRAZING_COSINE => Sun {
            irradiance: Rgb::ZERO,
            ..sun
        },
        _ => sun,
    }
}
