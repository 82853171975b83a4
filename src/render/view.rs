//! Per-frame view set-up shared by the passes: the camera frame, projection and depth range.

use glam::{DMat3, DMat4, DVec3, Mat4};

use super::RenderError;
use super::target::PixelRect;
use crate::camera::Camera;
use crate::scene::{Projection, SceneCamera};

/// The camera of one frame, resolved against the scene bounds and the image size.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewSetup {
    /// The scene camera it came from.
    pub camera: SceneCamera,
    /// Image width and height in pixels.
    pub size: (u32, u32),
    /// Screen right, screen up and view direction (world, orthonormal).
    pub axes: DMat3,
    /// Perspective: focal length in pixels; orthographic: pixels per world unit.
    pub focal: f64,
    /// Near plane distance from the eye (world units).
    pub near: f64,
    /// Far plane distance (orthographic only; perspective depth reaches infinity).
    pub far: f64,
}

impl ViewSetup {
    /// Resolves `camera` for an image of `size`; `bounds` (the scene's world bounds) sets the
    /// near plane when the camera names none, and the orthographic depth range.
    pub fn new(
        camera: &SceneCamera,
        size: (u32, u32),
        bounds: Option<(DVec3, DVec3)>,
    ) -> Result<Self, RenderError> {
        let pinhole = camera.pinhole(size.0, size.1, 0.0)?;
        let frame = pinhole.frame()?;
        let axes = DMat3::from_cols(frame.right, frame.up, frame.forward);
        let (centre, radius) = bounds.map_or((camera.target, 1.0), |(lo, hi)| {
            (0.5 * (lo + hi), (0.5 * (hi - lo).length()).max(1e-9))
        });
        let along = (centre - camera.eye).dot(frame.forward);
        let (focal, near, far) = match camera.projection {
            Projection::Perspective { .. } => {
                let auto = (along - radius).max(radius * 1e-3);
                (frame.focal, camera.near.unwrap_or(auto), f64::INFINITY)
            }
            Projection::Orthographic { height } => {
                if !(height.is_finite() && height > 0.0) {
                    return Err(RenderError::BadCamera(format!(
                        "orthographic height {height}"
                    )));
                }
                let near = camera.near.unwrap_or((along - 1.5 * radius).max(0.0));
                let far = (along + 1.5 * radius).max(near + radius * 1e-3);
                (f64::from(size.1) / height, near, far)
            }
        };
        Ok(Self {
            camera: *camera,
            size,
            axes,
            focal,
            near,
            far,
        })
    }

    /// The distance from the eye within which a perspective view leaves the splats of a grid
    /// whose finest voxel edge is `finest_spacing` out: the near plane, and at least a tenth of
    /// that edge, since a splat nearer than that would cover the image many times over.
    pub fn splat_near(&self, finest_spacing: f64) -> f64 {
        self.near.max(0.1 * finest_spacing)
    }

    /// Whether the projection is orthographic.
    pub fn is_orthographic(&self) -> bool {
        matches!(self.camera.projection, Projection::Orthographic { .. })
    }

    /// The pinhole camera the orderings and the CPU compositor use for this frame (a distant
    /// pinhole for an orthographic view), with the same near plane as the GPU.
    pub fn pinhole(&self) -> Result<Camera, RenderError> {
        Ok(self.camera.pinhole(self.size.0, self.size.1, self.near)?)
    }

    /// Camera-relative world (eye at the origin) to clip space, reversed depth: 1 at the near
    /// plane, 0 at infinity (perspective) or at the far plane (orthographic).
    pub fn view_proj(&self) -> Mat4 {
        let (w, h) = (f64::from(self.size.0), f64::from(self.size.1));
        // Rows: right, up, -forward (a right-handed view looking down -z).
        let a = self.axes;
        let view = DMat4::from_mat3(DMat3::from_cols(a.x_axis, a.y_axis, -a.z_axis).transpose());
        let proj = if self.is_orthographic() {
            let (sx, sy) = (2.0 * self.focal / w, 2.0 * self.focal / h);
            let range = self.far - self.near;
            DMat4::from_cols_array(&[
                sx,
                0.0,
                0.0,
                0.0, //
                0.0,
                sy,
                0.0,
                0.0, //
                0.0,
                0.0,
                1.0 / range,
                0.0, //
                0.0,
                0.0,
                self.far / range,
                1.0,
            ])
        } else {
            // Infinite reversed perspective: clip z = near, w = distance, so depth = near / d.
            let (sx, sy) = (2.0 * self.focal / w, 2.0 * self.focal / h);
            DMat4::from_cols_array(&[
                sx, 0.0, 0.0, 0.0, //
                0.0, sy, 0.0, 0.0, //
                0.0, 0.0, 0.0, -1.0, //
                0.0, 0.0, self.near, 0.0,
            ])
        };
        (proj * view).as_mat4()
    }

    /// A world transform made relative to the eye, in f32 (the translation is taken in f64
    /// first so that huge coordinates keep their precision near the viewer).
    pub fn relative(&self, world: DMat4) -> Mat4 {
        let mut m = world;
        m.w_axis -= self.camera.eye.extend(0.0);
        m.as_mat4()
    }

    /// The pixels that anything within the convex hull of `points` (world) can cover: their
    /// projections' bounding rectangle, two pixels wider each side, on the image. The whole
    /// image where a point is not beyond the near plane (the hull may then reach past the
    /// image's edges, or behind the eye); an empty rectangle where every pixel lies off it or
    /// every point before the near plane.
    pub(crate) fn screen_rect(&self, points: impl IntoIterator<Item = DVec3>) -> PixelRect {
        let (w, h) = (f64::from(self.size.0), f64::from(self.size.1));
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        let (mut before, mut beyond) = (false, false);
        for p in points {
            let d = p - self.camera.eye;
            let (x, y, z) = (
                d.dot(self.axes.x_axis),
                d.dot(self.axes.y_axis),
                d.dot(self.axes.z_axis),
            );
            let scale = if self.is_orthographic() {
                self.focal
            } else if z > self.near && z.is_finite() {
                beyond = true;
                self.focal / z
            } else {
                before = true;
                continue;
            };
            let pixel = [0.5 * w + scale * x, 0.5 * h - scale * y];
            if !pixel.iter().all(|v| v.is_finite()) {
                return PixelRect::whole(self.size);
            }
            for a in 0..2 {
                lo[a] = lo[a].min(pixel[a]);
                hi[a] = hi[a].max(pixel[a]);
            }
        }
        match (before, beyond) {
            // Wholly before the near plane: clipped away.
            (true, false) => return PixelRect::EMPTY,
            (true, true) => return PixelRect::whole(self.size),
            _ => {}
        }
        // Rasterisation covers pixels whose centres lie inside; the margin takes rounding.
        let edge = |v: f64, n: f64| (v.clamp(-1.0, n + 1.0) as i64).clamp(0, n as i64) as u32;
        let rect = PixelRect([
            edge((lo[0] - 2.0).floor(), w),
            edge((lo[1] - 2.0).floor(), h),
            edge((hi[0] + 2.0).ceil(), w),
            edge((hi[1] + 2.0).ceil(), h),
        ]);
        if rect.is_empty() {
            PixelRect::EMPTY
        } else {
            rect
        }
    }

    /// Reversed depth of a point at view distance `d` (along the view direction).
    pub fn depth_of(&self, d: f64) -> f64 {
        if self.is_orthographic() {
            ((self.far - d) / (self.far - self.near)).clamp(0.0, 1.0)
        } else {
            self.near / d
        }
    }

    /// View distance of a reversed depth value (`None` where nothing was drawn).
    pub fn distance_of(&self, depth: f32) -> Option<f64> {
        let z = f64::from(depth);
        if z <= 0.0 {
            return None;
        }
        Some(if self.is_orthographic() {
            self.far - z * (self.far - self.near)
        } else {
            self.near / z
        })
    }
}
