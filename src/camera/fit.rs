//! `camera.fit`: place the camera so the cloud's box fills the frame.
//!
//! The rule: the camera keeps the direction from `camera.look_at` to `camera.position` (the
//! default camera's: from +z, 0.8° above level), its `up`, field of view and image size; it looks
//! at the centre of the box and stands at the smallest distance where all eight corners of the box
//! project inside the central [`FILL`] of the frame on both axes (so the box touches that margin on
//! one axis and lies within it on the other).

use super::CameraDesc;
use crate::math::Vec3;

/// Share of the frame's half-width and half-height the box may reach (unitless).
pub const FILL: f32 = 0.9;

/// `d` with `position` and `look_at` moved to frame the box `lo..hi` (m); `d` must be a valid
/// camera ([`super::Camera::from_desc`] accepted it).
pub fn framed(d: &CameraDesc, lo: Vec3, hi: Vec3) -> CameraDesc {
    let back = (Vec3::from(d.position) - Vec3::from(d.look_at)).normalize();
    let forward = -back;
    let right = forward.cross(Vec3::from(d.up).normalize()).normalize();
    let up = right.cross(forward);
    let ty = (d.fov_deg.to_radians() * 0.5).tan() * FILL;
    let tx = ty * d.width as f32 / d.height as f32;
    let centre = (lo + hi) * 0.5;
    // A corner at offset v from the centre is at depth z = distance + v·forward; it lies inside the
    // margin when |v·right| ≤ tx·z and |v·up| ≤ ty·z.
    let mut distance = 0.0f32;
    for c in 0..8 {
        let corner = Vec3::new(
            if c & 1 == 0 { lo.x } else { hi.x },
            if c & 2 == 0 { lo.y } else { hi.y },
            if c & 4 == 0 { lo.z } else { hi.z },
        );
        let v = corner - centre;
        let depth = v.dot(forward);
        distance = distance.max(v.dot(right).abs() / tx - depth).max(v.dot(up).abs() / ty - depth);
    }
    // A box of zero size (one voxel of size 0 cannot happen; kept for safety) still gets a camera
    // outside it.
    let distance = distance.max(1e-3 * (hi - lo).length().max(1e-3));
    CameraDesc {
        position: (centre + back * distance).to_array(),
        look_at: centre.to_array(),
        ..d.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;

    /// The corners' image positions in pixels.
    fn corners_px(cam: &Camera, lo: Vec3, hi: Vec3) -> Vec<(f32, f32)> {
        let (w, h) = (cam.width as f32, cam.height as f32);
        (0..8)
            .map(|c| {
                let q = Vec3::new(
                    if c & 1 == 0 { lo.x } else { hi.x },
                    if c & 2 == 0 { lo.y } else { hi.y },
                    if c & 4 == 0 { lo.z } else { hi.z },
                );
                let v = q - cam.position;
                let z = v.dot(cam.forward);
                assert!(z > 0.0, "every corner is in front of the camera");
                let sx = v.dot(cam.right) / (z * cam.tan_half_fov * w / h);
                let sy = v.dot(cam.up) / (z * cam.tan_half_fov);
                ((sx + 1.0) * 0.5 * w, (1.0 - sy) * 0.5 * h)
            })
            .collect()
    }

    #[test]
    fn the_box_fills_the_margin_from_any_direction() {
        for (lo, hi, position) in [
            // A 3 m sphere's box at the origin, seen from the default direction.
            (Vec3::splat(-1.5), Vec3::splat(1.5), [0.0, 350.0, 1500.0]),
            // A wide flat cloud far from the origin, seen from above at an angle.
            (Vec3::new(1e4, 500.0, -2e3), Vec3::new(1.4e4, 900.0, 1e3), [3.0, 8.0, -1.0]),
        ] {
            let d = CameraDesc {
                position,
                look_at: [0.0, 330.0, 0.0],
                width: 160,
                height: 90,
                ..CameraDesc::default()
            };
            let cam = Camera::from_desc(&framed(&d, lo, hi), "test").unwrap();
            let px = corners_px(&cam, lo, hi);
            let (w, h) = (160.0f32, 90.0f32);
            let reach = px
                .iter()
                .map(|&(x, y)| ((x / w - 0.5).abs() * 2.0).max((y / h - 0.5).abs() * 2.0))
                .fold(0.0f32, f32::max);
            assert!((reach - FILL).abs() < 1e-3, "{reach}");
            let keep = (Vec3::from(d.position) - Vec3::from(d.look_at)).normalize();
            assert!((-cam.forward).dot(keep) > 0.9999, "the view direction is kept");
        }
    }
}
