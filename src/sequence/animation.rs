//! `[animation]`: the scene's frame range and keyframes for the sun, the camera and the
//! extinction, linearly interpolated between keyed frames.
//!
//! ```toml
//! [animation]
//! frames = "1-48"
//! [[animation.key]]
//! frame = 1
//! sun.elevation_deg = 40.0
//! [[animation.key]]
//! frame = 48
//! sun.elevation_deg = 2.0
//! ```
//!
//! Each key sets any of its channels (the scene's own key names); a channel is interpolated
//! between the keys that set it and held at its first and last keyed value outside them; a
//! channel no key sets keeps the scene's value.

use crate::error::{Error, Result};
use crate::scene::{AnimationDesc, KeyDesc, SceneDesc};

/// A keyable channel: its scene key, how a key reads it, and the values it may take.
struct Channel<const N: usize> {
    name: &'static str,
    get: fn(&KeyDesc) -> Option<[f32; N]>,
    allowed: fn(f32) -> bool,
    rule: &'static str,
}

const SCALARS: [Channel<1>; 4] = [
    Channel {
        name: "sun.elevation_deg",
        get: |k| k.sun.elevation_deg.map(|v| [v]),
        allowed: |v| (-90.0..=90.0).contains(&v),
        rule: "degrees in [-90, 90]",
    },
    Channel {
        name: "sun.azimuth_deg",
        get: |k| k.sun.azimuth_deg.map(|v| [v]),
        allowed: f32::is_finite,
        rule: "a finite number of degrees",
    },
    Channel {
        name: "camera.fov_deg",
        get: |k| k.camera.fov_deg.map(|v| [v]),
        allowed: |v| v > 0.0 && v < 180.0,
        rule: "degrees in (0, 180)",
    },
    Channel {
        name: "medium.sigma_t",
        get: |k| k.medium.sigma_t.map(|v| [v]),
        allowed: |v| v.is_finite() && v >= 0.0,
        rule: "a non-negative, finite extinction in m⁻¹",
    },
];

const VECTORS: [Channel<3>; 3] = [
    Channel {
        name: "sun.irradiance",
        get: |k| k.sun.irradiance,
        allowed: |v| v.is_finite() && v >= 0.0,
        rule: "non-negative, finite W/m² per band",
    },
    Channel {
        name: "camera.position",
        get: |k| k.camera.position,
        allowed: f32::is_finite,
        rule: "finite metres",
    },
    Channel {
        name: "camera.look_at",
        get: |k| k.camera.look_at,
        allowed: f32::is_finite,
        rule: "finite metres",
    },
];

impl<const N: usize> Channel<N> {
    /// The channel's value at `frame` (None: no key sets it).
    fn at(&self, keys: &[KeyDesc], frame: u32) -> Option<[f32; N]> {
        let keyed: Vec<(u32, [f32; N])> = keys.iter().filter_map(|k| Some((k.frame, (self.get)(k)?))).collect();
        let after = keyed.iter().position(|k| k.0 > frame);
        Some(match after {
            None => keyed.last()?.1,
            Some(0) => keyed[0].1,
            Some(i) => {
                let ((f0, a), (f1, b)) = (keyed[i - 1], keyed[i]);
                let t = (f64::from(frame) - f64::from(f0)) / (f64::from(f1) - f64::from(f0));
                std::array::from_fn(|c| (f64::from(a[c]) + t * (f64::from(b[c]) - f64::from(a[c]))) as f32)
            }
        })
    }

    /// Every key's value is allowed.
    fn check(&self, keys: &[KeyDesc], file: &str) -> Result<()> {
        for (i, k) in keys.iter().enumerate() {
            if let Some(v) = (self.get)(k) {
                if !v.iter().all(|&x| (self.allowed)(x)) {
                    return Err(Error::invalid(
                        file,
                        format!("animation.key[{i}].{}", self.name),
                        format!("{v:?} at frame {}: must be {}", k.frame, self.rule),
                    ));
                }
            }
        }
        Ok(())
    }

    fn keyed(&self, keys: &[KeyDesc]) -> bool {
        keys.iter().any(|k| (self.get)(k).is_some())
    }
}

/// The keyframes, checked and sorted by frame.
#[derive(Clone, Debug, Default)]
pub struct Animation {
    keys: Vec<KeyDesc>,
}

impl Animation {
    /// Check the keys against the scene they animate (`file` names it in messages).
    pub fn new(desc: &AnimationDesc, scene: &SceneDesc, file: &str) -> Result<Animation> {
        let mut keys = desc.key.clone();
        keys.sort_by_key(|k| k.frame);
        if let Some(w) = keys.windows(2).find(|w| w[0].frame == w[1].frame) {
            return Err(Error::invalid(
                file,
                "animation.key",
                format!("two keys for frame {}; give each frame at most one key", w[0].frame),
            ));
        }
        for c in &SCALARS {
            c.check(&desc.key, file)?;
        }
        for c in &VECTORS {
            c.check(&desc.key, file)?;
        }
        let (el, az) = (SCALARS[0].keyed(&keys), SCALARS[1].keyed(&keys));
        if (el && !az && scene.sun.azimuth_deg.is_none()) || (az && !el && scene.sun.elevation_deg.is_none()) {
            let (keyed, other) = if el {
                ("elevation_deg", "azimuth_deg")
            } else {
                ("azimuth_deg", "elevation_deg")
            };
            return Err(Error::invalid(
                file,
                format!("animation.key.sun.{keyed}"),
                format!("the sun's direction needs both angles: key sun.{other} too, or set sun.{other} in [sun] (without sun.direction)"),
            ));
        }
        if VECTORS[0].keyed(&keys) && scene.sun.from_atmosphere {
            return Err(Error::invalid(
                file,
                "animation.key.sun.irradiance",
                "sun.from_atmosphere = true derives the irradiance from the sun's elevation; key sun.elevation_deg instead, or set from_atmosphere = false",
            ));
        }
        // camera.fit places the camera on every frame and would replace a keyed one.
        let camera = SCALARS[2].keyed(&keys) || VECTORS[1..].iter().any(|c| c.keyed(&keys));
        if camera && scene.camera.fit {
            return Err(Error::invalid(
                file,
                "animation.key.camera",
                "camera.fit frames the cloud on every frame, which would replace the keyed camera: give the scene a \
                 [camera] table (camera.fit = false) to key it, or leave the camera unkeyed",
            ));
        }
        Ok(Animation { keys })
    }

    /// Whether any key sets a channel.
    pub fn is_keyed(&self) -> bool {
        SCALARS.iter().any(|c| c.keyed(&self.keys)) || VECTORS.iter().any(|c| c.keyed(&self.keys))
    }

    /// Whether any key sets a channel of the sun (its direction or irradiance).
    pub fn keys_sun(&self) -> bool {
        SCALARS[..2].iter().any(|c| c.keyed(&self.keys)) || VECTORS[0].keyed(&self.keys)
    }

    /// `desc` with every keyed channel set to its value at `frame`.
    pub fn apply(&self, desc: &mut SceneDesc, frame: u32) {
        let [elevation, azimuth, fov, sigma_t] = SCALARS.each_ref().map(|c| c.at(&self.keys, frame).map(|v| v[0]));
        let [irradiance, position, look_at] = VECTORS.each_ref().map(|c| c.at(&self.keys, frame));
        if elevation.is_some() || azimuth.is_some() {
            desc.sun.direction = None;
            desc.sun.elevation_deg = elevation.or(desc.sun.elevation_deg);
            desc.sun.azimuth_deg = azimuth.or(desc.sun.azimuth_deg);
        }
        desc.sun.irradiance = irradiance.unwrap_or(desc.sun.irradiance);
        desc.camera.position = position.unwrap_or(desc.camera.position);
        desc.camera.look_at = look_at.unwrap_or(desc.camera.look_at);
        desc.camera.fov_deg = fov.unwrap_or(desc.camera.fov_deg);
        desc.medium.sigma_t = sigma_t.unwrap_or(desc.medium.sigma_t);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn animation(text: &str) -> Result<Animation> {
        let scene = SceneDesc::from_toml(text, "s.toml")?;
        Animation::new(scene.animation.as_ref().unwrap(), &scene, "s.toml")
    }

    const SUNSET: &str = "[animation]\nframes = \"1-11\"\n\
        [[animation.key]]\nframe = 11\nsun.elevation_deg = 0.0\nsun.azimuth_deg = 90.0\n\
        [[animation.key]]\nframe = 1\nsun.elevation_deg = 50.0\nsun.azimuth_deg = 90.0\nmedium.sigma_t = 0.1\n";

    #[test]
    fn channels_interpolate_between_keys_and_hold_outside() {
        let a = animation(SUNSET).unwrap();
        let at = |f| {
            let mut d = SceneDesc::default();
            a.apply(&mut d, f);
            d
        };
        assert_eq!(at(6).sun.elevation_deg, Some(25.0));
        assert_eq!(at(6).sun.direction, None);
        assert_eq!(at(0).sun.elevation_deg, Some(50.0));
        assert_eq!(at(20).sun.elevation_deg, Some(0.0));
        assert_eq!(at(6).medium.sigma_t, 0.1, "one key holds everywhere");
        assert_eq!(at(6).camera, SceneDesc::default().camera, "unkeyed channels keep the scene's value");
    }

    #[test]
    fn any_number_of_keys_is_read() {
        let keys: String = (1..=5).map(|f| format!("[[animation.key]]\nframe = {f}\nsun.elevation_deg = {}.0\nsun.azimuth_deg = 90.0\n", 10 * f)).collect();
        let a = animation(&format!("[animation]\nframes = \"1-5\"\n{keys}")).unwrap();
        let mut d = SceneDesc::default();
        a.apply(&mut d, 4);
        assert_eq!(d.sun.elevation_deg, Some(40.0));
    }

    #[test]
    fn bad_keys_name_the_field() {
        for (text, field) in [
            (
                "[[animation.key]]\nframe = 1\nmedium.sigma_t = -1.0\n",
                "animation.key[0].medium.sigma_t",
            ),
            (
                "[[animation.key]]\nframe = 1\ncamera.fov_deg = 0.0\n",
                "animation.key[0].camera.fov_deg",
            ),
            (
                "[[animation.key]]\nframe = 1\nsun.elevation_deg = 10.0\n",
                "animation.key.sun.elevation_deg",
            ),
            ("[[animation.key]]\nframe = 1\n[[animation.key]]\nframe = 1\n", "animation.key"),
            (
                "[sun]\nfrom_atmosphere = true\n[[animation.key]]\nframe = 1\nsun.irradiance = [1.0, 1.0, 1.0]\n",
                "animation.key.sun.irradiance",
            ),
            // No [camera] table: camera.fit would replace the keyed camera.
            (
                "[[animation.key]]\nframe = 1\ncamera.position = [0.0, 350.0, 600.0]\n",
                "animation.key.camera",
            ),
        ] {
            let e = animation(text).unwrap_err().to_string();
            assert!(e.contains(&format!("`{field}`")), "{text}: {e}");
        }
        let e = animation("[[animation.key]]\nframe = 1\nsun.height = 1.0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("height"), "{e}");
    }
}
