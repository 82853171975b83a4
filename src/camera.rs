//! A pinhole camera in f64 world coordinates.

use glam::DVec3;
use thiserror::Error;

/// Why a camera cannot be used.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum CameraError {
    /// A position or direction has a NaN or infinite coordinate.
    #[error("camera {0} is not finite")]
    NotFinite(&'static str),
    /// Eye and target coincide.
    #[error("camera eye and target coincide")]
    NoViewDirection,
    /// The up vector is parallel to the view direction.
    #[error("camera up vector is parallel to the view direction")]
    UpParallel,
    /// The field of view must lie strictly between 0 and 180 degrees.
    #[error("field of view {0} degrees is not between 0 and 180")]
    BadFieldOfView(f64),
    /// The image must have pixels.
    #[error("image size {0}x{1} has no pixels")]
    EmptyImage(u32, u32),
}

/// A perspective camera looking from `eye` at `target`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Centre of projection.
    pub eye: DVec3,
    /// A point on the view axis.
    pub target: DVec3,
    /// Roughly up on screen.
    pub up: DVec3,
    /// Vertical field of view in degrees.
    pub fov_y_degrees: f64,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Near plane distance in world units: splats whose centre is nearer along the view axis
    /// are left out (a renderer's near clip).
    pub near: f64,
}

/// Orthonormal camera frame: `right` and `up` span the image plane, `forward` points into the
/// scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraFrame {
    /// Screen right.
    pub right: DVec3,
    /// Screen up.
    pub up: DVec3,
    /// View direction.
    pub forward: DVec3,
    /// Focal length in pixels.
    pub focal: f64,
}

impl Camera {
    /// A camera with a 50 degree vertical field of view, +z up and no near plane.
    pub fn looking_at(eye: DVec3, target: DVec3, width: u32, height: u32) -> Self {
        Self {
            eye,
            target,
            up: DVec3::Z,
            fov_y_degrees: 50.0,
            width,
            height,
            near: 0.0,
        }
    }

    /// Checks the camera and returns its frame.
    pub fn frame(&self) -> Result<CameraFrame, CameraError> {
        for (name, v) in [("eye", self.eye), ("target", self.target), ("up", self.up)] {
            if !v.is_finite() {
                return Err(CameraError::NotFinite(name));
            }
        }
        if !(self.fov_y_degrees > 0.0 && self.fov_y_degrees < 180.0) {
            return Err(CameraError::BadFieldOfView(self.fov_y_degrees));
        }
        if !(self.near.is_finite() && self.near >= 0.0) {
            return Err(CameraError::NotFinite("near plane"));
        }
        if self.width == 0 || self.height == 0 {
            return Err(CameraError::EmptyImage(self.width, self.height));
        }
        let forward = (self.target - self.eye)
            .try_normalize()
            .ok_or(CameraError::NoViewDirection)?;
        let right = forward.cross(self.up);
        if right.length() <= 1e-9 * self.up.length() {
            return Err(CameraError::UpParallel);
        }
        let right = right.normalize();
        let up = right.cross(forward);
        let focal = 0.5 * f64::from(self.height) / (0.5 * self.fov_y_degrees.to_radians()).tan();
        Ok(CameraFrame {
            right,
            up,
            forward,
            focal,
        })
    }

    /// An up vector that is never parallel to the view direction: +z unless the view is
    /// nearly vertical, then +y.
    pub fn safe_up(eye: DVec3, target: DVec3) -> DVec3 {
        let forward = (target - eye).normalize_or_zero();
        if forward.dot(DVec3::Z).abs() > 0.99 {
            DVec3::Y
        } else {
            DVec3::Z
        }
    }
}
