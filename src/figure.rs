//! Figures of a scene as `splatscene render` draws them, for every front end that draws one
//! (the command line and the Python module): the GPU context a scene needs, the scene's
//! measurements drawn in with their labels, the annotations, and the depth behind each pixel.

use glam::DVec3;
use image::RgbaImage;

use crate::annotate::{Annotations, Drawn, Label, NoFont, annotate_image};
use crate::pick::measure::{DrawMeasurementError, draw_scene_measurements};
use crate::pick::surface_distances;
use crate::render::{Compositor, DepthMode, GpuContext, RenderError, Screenshot, frame_to_rgba8};
use crate::scene::patient::NamedView;
use crate::scene::{Projection, Scene, SceneCamera};

/// The GPU context for drawing `scene`, or none where the CPU can draw the whole scene (volumes
/// only, with a compositor other than the GPU's) and either no adapter need be looked for
/// ([`Compositor::volumes_without_adapter`]) or there is none (that fallback is said on
/// stderr). (Where a GPU device exists, [`Compositor::Auto`] must look, to learn whether the
/// adapter is a CPU.)
pub fn context_for(
    compositor: Compositor,
    scene: &Scene,
) -> Result<Option<GpuContext>, RenderError> {
    let volumes_only = scene.meshes().chain(scene.overlays()).next().is_none();
    if volumes_only && compositor.volumes_without_adapter() {
        return Ok(None);
    }
    match GpuContext::headless() {
        Ok(ctx) => Ok(Some(ctx)),
        Err(e @ RenderError::NoAdapter(_))
            if compositor != Compositor::Gpu
                && scene.meshes().chain(scene.overlays()).next().is_none() =>
        {
            eprintln!("{e}\ncompositing the volumes on the CPU");
            Ok(None)
        }
        Err(e) => Err(e),
    }
}

/// A scene with its measurements drawn in, ready to be rendered into a figure.
pub struct Measured {
    /// The scene, with a marker mesh for every measurement.
    pub scene: Scene,
    /// The measurements' value labels (none where `parts` leaves measurements out).
    pub labels: Vec<Label>,
    /// The annotations to draw: `parts` as asked, or the labels alone where nothing was asked
    /// and the scene has measurements.
    pub parts: Option<Annotations>,
}

/// `scene` with its measurements drawn in, and the annotations that write their values beside
/// them unless `parts` leaves measurements out.
pub fn measured(
    scene: &Scene,
    parts: Option<&Annotations>,
) -> Result<Measured, DrawMeasurementError> {
    let mut drawn = scene.clone();
    let mut labels = draw_scene_measurements(&mut drawn)?;
    if parts.is_some_and(|p| !p.measurements) {
        labels.clear();
    }
    let parts = match (parts, labels.is_empty()) {
        (None, false) => Some(Annotations::measurements_only()),
        (p, _) => p.cloned(),
    };
    Ok(Measured {
        scene: drawn,
        labels,
        parts,
    })
}

/// A caption with its placeholders filled: `{view}` the view's name (`scene` for the scene's
/// own camera), `{size}` the image's `WxH`, `{ordering}` the ordering asked for (`the
/// scene's` where none was).
pub fn fill_caption(
    caption: &str,
    view: &str,
    size: (u32, u32),
    ordering: Option<crate::order::Ordering>,
) -> String {
    caption
        .replace("{view}", view)
        .replace("{size}", &format!("{}x{}", size.0, size.1))
        .replace(
            "{ordering}",
            &ordering.map_or("the scene's".into(), |o| o.to_string()),
        )
}

/// The image of a screenshot, annotated when `parts` asks (with the patient frame of
/// `scene`), and what the annotation drew.
pub fn figure_image(
    shot: &Screenshot,
    scene: &Scene,
    camera: &SceneCamera,
    parts: Option<&Annotations>,
    labels: &[Label],
) -> Result<(RgbaImage, Option<Drawn>), NoFont> {
    let mut image = frame_to_rgba8(&shot.frame);
    let drawn = match parts {
        Some(parts) => Some(annotate_image(
            &mut image,
            camera,
            &scene.patient_frame(),
            labels,
            parts,
        )?),
        None => None,
    };
    Ok((image, drawn))
}

/// The view distance in millimetres behind every pixel of `shot`, row by row from the top:
/// the nearest mesh, and with [`DepthMode::Surface`] also each volume's first surface, where
/// the opacity accumulated along the pixel's ray reaches `surface_opacity`; `None` where
/// nothing was hit.
pub fn depth_distances(
    shot: &Screenshot,
    scene: &Scene,
    mode: DepthMode,
    surface_opacity: f32,
) -> Vec<Option<f64>> {
    let view = &shot.view;
    let mut distances: Vec<Option<f64>> = shot.depth.iter().map(|&d| view.distance_of(d)).collect();
    if mode == DepthMode::Surface {
        let surface = surface_distances(scene, view, surface_opacity, Some(&distances));
        for (d, s) in distances.iter_mut().zip(surface) {
            if s.is_some() {
                *d = s;
            }
        }
    }
    distances
}

/// The depth mode a figure takes when none is asked for: the meshes where the scene has any,
/// else the volumes' surface.
pub fn default_depth_mode(scene: &Scene) -> DepthMode {
    if scene.meshes().next().is_some() {
        DepthMode::Mesh
    } else {
        DepthMode::Surface
    }
}

/// Where a figure's camera goes: the scene's own camera changed by what is given.
#[derive(Debug, Clone, Default)]
pub struct CameraChoice {
    /// A named view of the patient, fitted to what is drawn; `None` keeps the scene's camera.
    pub view: Option<NamedView>,
    /// The eye, in world millimetres (not with `view`).
    pub eye: Option<DVec3>,
    /// The point looked at, in world millimetres.
    pub target: Option<DVec3>,
    /// Turns about the target and the scene's up axis: yaw and pitch in degrees.
    pub orbit: Option<[f64; 2]>,
    /// The projection; `None` keeps the scene camera's.
    pub projection: Option<Projection>,
}

impl CameraChoice {
    /// The camera this choice makes of the scene camera `base` for an image of `aspect`
    /// (width over height). A named view keeps the scene camera's near plane; a new eye or
    /// target keeps its up vector unless the view runs along it.
    pub fn camera(&self, scene: &Scene, base: SceneCamera, aspect: f64) -> SceneCamera {
        let projection = self.projection.unwrap_or(base.projection);
        let camera = match &self.view {
            Some(view) => {
                let mut camera =
                    crate::scene::file::named_view_camera(scene, view, projection, aspect);
                if let Some(target) = self.target {
                    camera.target = target;
                }
                camera.near = base.near;
                camera
            }
            None => {
                let mut camera = base;
                if let Some(eye) = self.eye {
                    camera.eye = eye;
                }
                if let Some(target) = self.target {
                    camera.target = target;
                }
                if self.eye.is_some() || self.target.is_some() {
                    let forward = (camera.target - camera.eye).normalize_or_zero();
                    if forward.cross(camera.up.normalize_or_zero()).length() < 1e-6 {
                        camera.up = crate::camera::Camera::safe_up(camera.eye, camera.target);
                    }
                }
                camera.projection = projection;
                camera
            }
        };
        match self.orbit {
            Some([yaw, pitch]) => camera.orbit_about(scene.up_axis(), yaw, pitch),
            None => camera,
        }
    }
}
