//! Pinhole camera. The image's right is normalize(cross(forward, up)); pixel rows run top to bottom.

pub mod fit;

use crate::error::Result;
use crate::error::{check, finite3};
use crate::math::{Ray, Vec3};
use serde::{Deserialize, Serialize};

/// `[camera]`: a pinhole camera.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct CameraDesc {
    /// Eye position (m).
    pub position: [f32; 3],
    /// Point looked at (m).
    pub look_at: [f32; 3],
    /// Up hint; must not be parallel to the view direction.
    pub up: [f32; 3],
    /// Vertical field of view (degrees).
    pub fov_deg: f32,
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// Place the camera to frame the cloud's box (`camera::fit::framed`): it keeps the direction from
    /// `look_at` to `position` and the field of view, looks at the box's centre and moves to the
    /// distance where the box fills the frame. A scene file without a `[camera]` table sets it.
    pub fit: bool,
}

impl Default for CameraDesc {
    fn default() -> Self {
        CameraDesc {
            position: [0.0, 350.0, 1500.0],
            look_at: [0.0, 330.0, 0.0],
            up: [0.0, 1.0, 0.0],
            fov_deg: 40.0,
            width: 480,
            height: 360,
            fit: false,
        }
    }
}

/// A validated pinhole camera.
#[derive(Clone, Debug)]
pub struct Camera {
    /// Eye position (m).
    pub position: Vec3,
    /// Unit view direction.
    pub forward: Vec3,
    /// Unit image-right direction.
    pub right: Vec3,
    /// Unit image-up direction.
    pub up: Vec3,
    /// tan(fov_y / 2) (unitless).
    pub tan_half_fov: f32,
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
}

/// The world axis least aligned with `v` (unit): an up that is never parallel to a view along `v`.
fn perpendicular_axis(v: Vec3) -> Vec3 {
    let a = v.abs();
    if a.y <= a.x && a.y <= a.z {
        Vec3::Y
    } else if a.z <= a.x {
        Vec3::NEG_Z
    } else {
        Vec3::X
    }
}

impl Camera {
    /// Validate `[camera]`.
    pub fn from_desc(d: &CameraDesc, file: &str) -> Result<Camera> {
        check(
            file,
            "camera.position",
            finite3(d.position),
            d.position,
            "must be three finite numbers (m)",
        )?;
        check(
            file,
            "camera.look_at",
            finite3(d.look_at),
            d.look_at,
            "must be three finite numbers (m)",
        )?;
        let pos = Vec3::from(d.position);
        let to = Vec3::from(d.look_at) - pos;
        check(
            file,
            "camera.look_at",
            to.length() > 1e-6,
            d.look_at,
            "must differ from camera.position",
        )?;
        let forward = to.normalize();
        let up_hint = crate::math::unit_vector(d.up);
        check(file, "camera.up", up_hint.is_some(), d.up, "must be a finite non-zero vector")?;
        let cross = forward.cross(up_hint.unwrap_or(Vec3::Y));
        if cross.length() <= 1e-4 {
            // A camera looking straight down or up with the default up: name an up that works.
            // (Each zero written 0.0: negating the axis would show -0.0.)
            let (a, b) = (perpendicular_axis(forward), -perpendicular_axis(forward));
            let (a, b) = (a.to_array(), b.to_array().map(|x| if x == 0.0 { 0.0 } else { x }));
            return Err(crate::error::Error::invalid(
                file,
                "camera.up",
                format!(
                    "{:?} is not allowed: it is parallel to the view direction (look_at - position = {:?}), so \
                     the image's top is undefined; set camera.up to the direction the top should face, e.g. \
                     {:?} or {:?}",
                    d.up,
                    to.to_array(),
                    a,
                    b
                ),
            ));
        }
        check(
            file,
            "camera.fov_deg",
            d.fov_deg.is_finite() && d.fov_deg > 0.0 && d.fov_deg < 179.0,
            d.fov_deg,
            "the vertical field of view must be in (0, 179) degrees",
        )?;
        check(
            file,
            "camera.width",
            d.width > 0 && d.width <= 32768,
            d.width,
            "the image width must be 1 to 32768 pixels",
        )?;
        check(
            file,
            "camera.height",
            d.height > 0 && d.height <= 32768,
            d.height,
            "the image height must be 1 to 32768 pixels",
        )?;
        let right = cross.normalize();
        let up = right.cross(forward).normalize();
        Ok(Camera {
            position: pos,
            forward,
            right,
            up,
            tan_half_fov: (d.fov_deg.to_radians() * 0.5).tan(),
            width: d.width,
            height: d.height,
        })
    }

    /// The ray through image position (px, py) in pixels, (0, 0) the top-left corner.
    #[inline]
    pub fn ray(&self, px: f32, py: f32) -> Ray {
        let aspect = self.width as f32 / self.height as f32;
        let sx = (2.0 * px / self.width as f32 - 1.0) * self.tan_half_fov * aspect;
        let sy = (1.0 - 2.0 * py / self.height as f32) * self.tan_half_fov;
        Ray::new(self.position, self.forward + self.right * sx + self.up * sy)
    }
}
