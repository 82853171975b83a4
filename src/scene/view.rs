//! The scene camera (perspective or orthographic, look-at, fit to the scene) and the lights.

use glam::{DQuat, DVec3};

use crate::camera::{Camera, CameraError};

/// How the camera projects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Projection {
    /// A pinhole camera with this vertical field of view in degrees.
    Perspective {
        /// Vertical field of view in degrees.
        fov_y_degrees: f64,
    },
    /// Parallel rays; the image spans this height in world units.
    Orthographic {
        /// Visible height in world units.
        height: f64,
    },
}

impl Default for Projection {
    fn default() -> Self {
        Self::Perspective {
            fov_y_degrees: 35.0,
        }
    }
}

/// A look-at camera in f64 world coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneCamera {
    /// Eye position (for an orthographic camera, the plane the rays start from).
    pub eye: DVec3,
    /// A point on the view axis.
    pub target: DVec3,
    /// Roughly up on screen.
    pub up: DVec3,
    /// Perspective or orthographic.
    pub projection: Projection,
    /// Near plane in world units; `None` picks a small fraction of the scene size.
    pub near: Option<f64>,
}

impl SceneCamera {
    /// A perspective camera (35 degree field of view) at `eye` looking at `target`, with an up
    /// vector that is never parallel to the view direction.
    pub fn look_at(eye: DVec3, target: DVec3) -> Self {
        Self {
            eye,
            target,
            up: Camera::safe_up(eye, target),
            projection: Projection::default(),
            near: None,
        }
    }

    /// A camera looking along `direction` at the centre of `bounds`, far enough back that the
    /// bounding sphere fills the view at the given aspect ratio (width / height).
    pub fn fit(
        bounds: (DVec3, DVec3),
        direction: DVec3,
        projection: Projection,
        aspect: f64,
    ) -> Self {
        let centre = 0.5 * (bounds.0 + bounds.1);
        let radius = (0.5 * (bounds.1 - bounds.0).length()).max(1e-6);
        let forward = direction.try_normalize().unwrap_or(DVec3::NEG_Y);
        let aspect = if aspect.is_finite() && aspect > 0.0 {
            aspect
        } else {
            1.0
        };
        let (distance, projection) = match projection {
            Projection::Perspective { fov_y_degrees } => {
                let half_y = (0.5 * fov_y_degrees.to_radians()).tan();
                let half = half_y.min(half_y * aspect).atan();
                (radius / half.sin() * 1.02, projection)
            }
            Projection::Orthographic { .. } => (
                3.0 * radius,
                Projection::Orthographic {
                    height: 2.04 * radius / aspect.min(1.0),
                },
            ),
        };
        let eye = centre - forward * distance;
        Self {
            projection,
            ..Self::look_at(eye, centre)
        }
    }

    /// The same camera orbited about its target and its own up vector: see
    /// [`SceneCamera::orbit_about`].
    pub fn orbit(&self, yaw_degrees: f64, pitch_degrees: f64) -> Self {
        self.orbit_about(self.up, yaw_degrees, pitch_degrees)
    }

    /// The same camera orbited about its target like a turntable whose axis is `up` (the
    /// scene's up, such as the patient's superior axis): `yaw` turns the eye about `up`, then
    /// `pitch` raises it toward `up`, both in degrees; the distance stays the same. The
    /// camera's own frame turns with the eye, so the picture keeps its roll: a camera upright
    /// about `up` stays upright, and one looking straight along `up` (where `up` cannot be
    /// screen up) keeps its screen up instead of jumping. The pitch stops at the poles, so an
    /// orbit never turns the picture upside down. A zero or non-finite `up` orbits about the
    /// camera's own up.
    pub fn orbit_about(&self, up: DVec3, yaw_degrees: f64, pitch_degrees: f64) -> Self {
        let axis = up
            .try_normalize()
            .or_else(|| self.up.try_normalize())
            .unwrap_or(DVec3::Z);
        let yaw = DQuat::from_axis_angle(axis, yaw_degrees.to_radians());
        let (offset, screen_up) = (yaw * (self.eye - self.target), yaw * self.up);
        let Some(back) = offset.try_normalize() else {
            return *self;
        };
        // Elevation of the eye above the plane normal to the axis, kept within the poles.
        let elevation = back.dot(axis).clamp(-1.0, 1.0).asin();
        let limit = std::f64::consts::FRAC_PI_2;
        let turn = (elevation + pitch_degrees.to_radians()).clamp(-limit, limit) - elevation;
        let right = (-back).cross(screen_up);
        let right = right.try_normalize().unwrap_or_else(|| {
            // Looking along the camera's own up: any axis across the view will do.
            back.any_orthonormal_vector()
        });
        // Turning by -turn about screen right raises the eye toward screen up.
        let pitch = DQuat::from_axis_angle(right, -turn);
        Self {
            eye: self.target + pitch * offset,
            up: pitch * screen_up,
            ..*self
        }
    }

    /// The pinhole camera the CPU compositor and the orderings use, for an image of this size.
    /// An orthographic camera becomes a very distant pinhole with the same view, so that
    /// orderings see the parallel case.
    pub fn pinhole(&self, width: u32, height: u32, near: f64) -> Result<Camera, CameraError> {
        let mut camera = Camera {
            eye: self.eye,
            target: self.target,
            up: self.up,
            fov_y_degrees: 35.0,
            width,
            height,
            near,
        };
        match self.projection {
            Projection::Perspective { fov_y_degrees } => camera.fov_y_degrees = fov_y_degrees,
            Projection::Orthographic { height: h } => {
                let forward = (self.target - self.eye)
                    .try_normalize()
                    .ok_or(CameraError::NoViewDirection)?;
                let distance = 1e6 * h.abs().max(1e-6);
                camera.eye = self.target - forward * distance;
                camera.fov_y_degrees = 2.0 * (0.5 * h / distance).atan().to_degrees();
            }
        }
        camera.frame()?;
        Ok(camera)
    }
}

/// A directional light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Light {
    /// Direction the light travels (from the light into the scene), world space.
    pub direction: DVec3,
    /// Linear RGB colour times intensity.
    pub color: [f32; 3],
}

/// The lights of a scene: a headlight along the view direction, an ambient term and up to
/// four directional lights.
#[derive(Debug, Clone, PartialEq)]
pub struct Lights {
    /// Headlight intensity (0 turns it off).
    pub headlight: f32,
    /// Ambient intensity.
    pub ambient: f32,
    /// Directional lights; the renderer uses the first four.
    pub directional: Vec<Light>,
}

impl Default for Lights {
    fn default() -> Self {
        Self {
            headlight: 0.75,
            ambient: 0.18,
            directional: vec![Light {
                direction: DVec3::new(-0.3, 0.5, -1.0),
                color: [0.35, 0.35, 0.33],
            }],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(camera: &SceneCamera) -> crate::camera::CameraFrame {
        camera.pinhole(64, 64, 0.0).unwrap().frame().unwrap()
    }

    #[test]
    fn orbits_turn_about_the_given_up_and_stay_upright() {
        // A scene whose up is -z (a slice stack with +z inferior), seen from the front.
        let camera = SceneCamera {
            up: DVec3::NEG_Z,
            ..SceneCamera::look_at(DVec3::new(0.0, 300.0, 0.0), DVec3::ZERO)
        };
        for (yaw, pitch) in [(5.0, 0.0), (0.0, 5.0), (120.0, -40.0), (-30.0, 60.0)] {
            let turned = camera.orbit_about(DVec3::NEG_Z, yaw, pitch);
            assert!(
                (turned.eye.length() - 300.0).abs() < 1e-9,
                "the distance is kept"
            );
            let f = frame(&turned);
            // Upright: screen right stays level (normal to the up axis), screen up leans toward it.
            assert!(
                f.right.dot(DVec3::NEG_Z).abs() < 1e-9,
                "{yaw},{pitch}: {f:?}"
            );
            assert!(f.up.dot(DVec3::NEG_Z) > 0.0, "{yaw},{pitch}: {f:?}");
        }
        // Yaw turns about the axis: the eye keeps its height along it, and a positive yaw
        // carries the eye toward what was screen right (the scene turns the other way), a
        // quarter turn of it all the way there.
        let yawed = camera.orbit_about(DVec3::NEG_Z, 90.0, 0.0);
        let right = frame(&camera).right;
        assert!(
            yawed.eye.z.abs() < 1e-9 && yawed.eye.dot(right) > 299.0,
            "{} against screen right {right}",
            yawed.eye
        );
        let nudged = camera.orbit_about(DVec3::NEG_Z, 5.0, 0.0);
        assert!(nudged.eye.dot(right) > 0.0, "{}", nudged.eye);
        // Positive pitch raises the eye toward the up axis (-z here).
        assert!(camera.orbit_about(DVec3::NEG_Z, 0.0, 10.0).eye.z < -50.0);
    }

    #[test]
    fn the_pitch_stops_at_the_pole_and_the_view_along_up_does_not_jump() {
        let camera = SceneCamera::look_at(DVec3::new(0.0, -200.0, 0.0), DVec3::ZERO);
        let pole = camera.orbit_about(DVec3::Z, 0.0, 200.0);
        assert!(
            pole.eye.abs_diff_eq(DVec3::new(0.0, 0.0, 200.0), 1e-9),
            "{}",
            pole.eye
        );
        let f = frame(&pole);
        // Looking straight down: screen up is what it was turned to (+y), not a new guess.
        assert!(f.up.abs_diff_eq(DVec3::Y, 1e-9), "{f:?}");
        // A small yaw at the pole turns the picture a little, a small pitch leaves the pole.
        let spun = frame(&pole.orbit_about(DVec3::Z, 2.0, 0.0));
        assert!(spun.up.angle_between(f.up).to_degrees() < 2.0 + 1e-9);
        let back = pole.orbit_about(DVec3::Z, 0.0, -3.0);
        assert!(back.eye.y < 0.0 && (back.eye.length() - 200.0).abs() < 1e-9);
        // A degenerate axis falls back to the camera's own up.
        assert_eq!(
            camera.orbit_about(DVec3::ZERO, 10.0, 0.0),
            camera.orbit(10.0, 0.0)
        );
    }
}
