//! The camera a scene file's `[camera]` table describes.

use glam::DVec3;

use super::CameraSpec;
use crate::camera::CameraError;
use crate::scene::patient::{NamedView, PatientError};
use crate::scene::{Projection, Scene, SceneCamera};

/// Why a scene file's `[camera]` table makes no camera.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CameraSpecError {
    /// `orthographic_height` not a positive number.
    #[error("orthographic_height {0} must be positive")]
    OrthographicHeight(f64),
    /// `fov` outside (0, 180) degrees.
    #[error("fov {0} is not between 0 and 180 degrees")]
    Fov(f64),
    /// `eye`, `target` or `up` with a NaN or infinite coordinate.
    #[error("camera.{key} {value} is not finite")]
    NotFinite {
        /// The key.
        key: &'static str,
        /// Its value.
        value: DVec3,
    },
    /// `up` of length zero.
    #[error("camera.up [0, 0, 0] has no direction")]
    NoUp,
    /// `view` given with `eye` or `view_from`.
    #[error("camera.view names a view: give it without eye or view_from")]
    ViewWithEye,
    /// `view` names no view.
    #[error("camera.view: {0}")]
    View(PatientError),
    /// `view_from` of length zero or not finite.
    #[error("camera.view_from {0} has no direction")]
    NoViewFrom(DVec3),
    /// The camera the keys make has no view (an eye on its target).
    #[error(transparent)]
    Camera(#[from] CameraError),
}

/// The camera a scene file's `[camera]` table describes for `scene`, fitted to it where the
/// table gives no eye; `aspect` is the image's width over its height.
///
/// # Errors
///
/// The key whose value cannot make a camera, and why.
pub fn camera(
    spec: Option<&CameraSpec>,
    scene: &Scene,
    aspect: f64,
) -> Result<SceneCamera, CameraSpecError> {
    let default = CameraSpec::default();
    let spec = spec.unwrap_or(&default);
    let bounds = scene.fit_bounds();
    let projection = match (spec.orthographic_height, spec.fov) {
        (Some(height), _) if height.is_finite() && height > 0.0 => {
            Projection::Orthographic { height }
        }
        (Some(height), _) => return Err(CameraSpecError::OrthographicHeight(height)),
        (None, Some(fov)) if fov > 0.0 && fov < 180.0 => {
            Projection::Perspective { fov_y_degrees: fov }
        }
        (None, Some(fov)) => return Err(CameraSpecError::Fov(fov)),
        (None, None) => Projection::default(),
    };
    let given = |v: Option<[f64; 3]>, key: &'static str| match v.map(DVec3::from) {
        Some(p) if !p.is_finite() => Err(CameraSpecError::NotFinite { key, value: p }),
        other => Ok(other),
    };
    let (eye, target, up) = (
        given(spec.eye, "eye")?,
        given(spec.target, "target")?,
        given(spec.up, "up")?,
    );
    if up.is_some_and(|u| u.length() == 0.0) {
        return Err(CameraSpecError::NoUp);
    }
    let mut camera = match (&spec.view, eye, spec.view_from) {
        (Some(_), Some(_), _) | (Some(_), _, Some(_)) => {
            return Err(CameraSpecError::ViewWithEye);
        }
        (Some(name), None, None) => {
            let view = NamedView::parse(name).map_err(CameraSpecError::View)?;
            named_view_camera(scene, &view, projection, aspect)
        }
        (None, Some(eye), _) => {
            let target = target.unwrap_or(0.5 * (bounds.0 + bounds.1));
            let mut camera = SceneCamera {
                projection,
                ..SceneCamera::look_at(eye, target)
            };
            camera.up = upright(camera.target - camera.eye, scene);
            camera
        }
        (None, None, from) => {
            let direction = DVec3::from(from.unwrap_or([-0.55, 1.0, -0.35]));
            if !direction.is_finite() || direction.length() == 0.0 {
                return Err(CameraSpecError::NoViewFrom(direction));
            }
            let mut fitted = SceneCamera::fit(bounds, direction, projection, aspect);
            if let Some(t) = target {
                fitted.target = t;
            }
            fitted.up = upright(fitted.target - fitted.eye, scene);
            fitted
        }
    };
    if let Some(up) = up {
        camera.up = up;
    }
    camera.near = spec.near;
    camera.pinhole(16, 16, 0.0)?;
    Ok(camera)
}

/// Screen up for a camera looking along `forward`: the scene's up axis, or where the view runs
/// along it, the patient's anterior (so a view from above has the face at the top).
pub fn upright(forward: DVec3, scene: &Scene) -> DVec3 {
    let axis = scene.up_axis();
    let forward = forward.normalize_or_zero();
    if forward.cross(axis).length() > 1e-3 {
        axis
    } else {
        let anterior = scene.patient_frame().world(DVec3::Y);
        if forward.cross(anterior).length() > 1e-3 {
            anterior
        } else {
            forward.any_orthonormal_vector()
        }
    }
}

/// A camera for a named view of the scene's patient, fitted to what is drawn of the scene
/// ([`Scene::fit_bounds`]: the crop box and clip planes cut it).
pub fn named_view_camera(
    scene: &Scene,
    view: &NamedView,
    projection: Projection,
    aspect: f64,
) -> SceneCamera {
    let bounds = scene.fit_bounds();
    let frame = scene.patient_frame();
    let mut camera = SceneCamera::fit(bounds, -frame.world(view.from), projection, aspect);
    camera.up = frame.world(view.up);
    camera
}
