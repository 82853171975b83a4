//! Scenes: read from a scene file or built from volumes and meshes, drawn as `splatscene
//! render` draws them, with a renderer kept between calls so that each volume is classified
//! once per transfer function.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use glam::DVec3;
use numpy::PyArrayMethods;
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyString, PyTuple};

use splatscene::annotate::Annotations;
use splatscene::figure::{
    CameraChoice, Measured, context_for, default_depth_mode, depth_distances, figure_image,
    fill_caption, measured,
};
use splatscene::order::Ordering;
use splatscene::pick::contact::{Classes, contact};
use splatscene::pick::{PickOptions, Picker};
use splatscene::render::{
    Compositor, DepthMode, FrameOptions, FrameReport, GpuContext, LevelOfDetail, Renderer,
    ViewSetup,
};
use splatscene::scene::file::{
    BoxSpec, CameraSpec, Given, LoadedScene, SceneFile, VolumeSpec, apply_transfer,
};
use splatscene::scene::patient::NamedView;
use splatscene::scene::{Projection, SceneCamera};

use crate::convert::{bad, fail, image_array, json_to_py, three, two};
use crate::mesh::Mesh;
use crate::volume::{Volume, load_volume};

/// What a scene keeps between calls.
struct State {
    loaded: LoadedScene,
    renderer: Renderer,
    /// The GPU context, made on the first picture (`Some(None)`: no adapter, volumes only).
    ctx: Option<Option<GpuContext>>,
    /// What the last picture drew and where its time went.
    report: Option<FrameReport>,
}

/// A planning scene: volumes and meshes, a camera, lights, clip planes and measurements.
#[pyclass(frozen, module = "splatscene")]
pub struct Scene {
    state: Mutex<State>,
    /// Where it was read from, `None` for a scene built in Python.
    path: Option<PathBuf>,
}

impl Scene {
    fn new_loaded(loaded: LoadedScene, path: Option<PathBuf>) -> Self {
        // The command line's compositor: the CPU tiles where the GPU is a CPU (lavapipe).
        Self {
            state: Mutex::new(State {
                loaded,
                renderer: Renderer::with_compositor(Compositor::Auto),
                ctx: None,
                report: None,
            }),
            path,
        }
    }

    fn lock(&self) -> PyResult<std::sync::MutexGuard<'_, State>> {
        self.state
            .lock()
            .map_err(|_| fail("the scene was left broken by an earlier failure"))
    }
}

/// The camera arguments shared by `render` and `pick`.
struct CameraArgs<'a, 'py> {
    view: Option<&'a str>,
    eye: Option<&'a Bound<'py, PyAny>>,
    target: Option<&'a Bound<'py, PyAny>>,
    orbit: Option<&'a Bound<'py, PyAny>>,
    fov: Option<f64>,
    orthographic: Option<f64>,
}

impl CameraArgs<'_, '_> {
    /// The choice these arguments make, checked as the command line checks its flags.
    fn choice(&self) -> PyResult<CameraChoice> {
        let view = match self.view.map(str::trim) {
            None | Some("scene") => None,
            Some(name) => Some(NamedView::parse(name).map_err(|e| bad(format!("view: {e}")))?),
        };
        if view.is_some() && self.eye.is_some() {
            return Err(bad("view and eye both place the camera: give one"));
        }
        if let Some(fov) = self.fov
            && !(fov.is_finite() && (0.1..=170.0).contains(&fov))
        {
            return Err(bad(format!(
                "fov: {fov} is not an angle from 0.1 to 170 degrees"
            )));
        }
        if let Some(h) = self.orthographic
            && !(h.is_finite() && h > 0.0)
        {
            return Err(bad(format!(
                "orthographic: {h}; the visible height must be a positive number of mm"
            )));
        }
        if self.fov.is_some() && self.orthographic.is_some() {
            return Err(bad("fov has no effect with orthographic: give one"));
        }
        let eye = self.eye.map(|e| three(e, "eye")).transpose()?;
        let target = self.target.map(|t| three(t, "target")).transpose()?;
        if let (Some(e), Some(t)) = (eye, target)
            && e == t
        {
            return Err(bad(
                "eye and target are one point: there is no view direction",
            ));
        }
        Ok(CameraChoice {
            view,
            eye: eye.map(DVec3::from),
            target: target.map(DVec3::from),
            orbit: self.orbit.map(|o| two(o, "orbit")).transpose()?,
            projection: match (self.orthographic, self.fov) {
                (Some(height), _) => Some(Projection::Orthographic { height }),
                (None, Some(fov_y_degrees)) => Some(Projection::Perspective { fov_y_degrees }),
                (None, None) => None,
            },
        })
    }
}

/// The image size asked for, else the scene file's, else 800 x 600 (as the command line).
fn size_or_default(asked: Option<(u32, u32)>, loaded: &LoadedScene) -> (u32, u32) {
    asked.unwrap_or(loaded.size.unwrap_or((800, 600)))
}

/// The camera of a scene for an image of `size`.
fn camera_of(
    loaded: &LoadedScene,
    choice: &CameraChoice,
    size: (u32, u32),
) -> Result<SceneCamera, String> {
    let base = loaded.scene.camera.ok_or("the scene has no camera")?;
    let aspect = f64::from(size.0) / f64::from(size.1);
    Ok(choice.camera(&loaded.scene, base, aspect))
}

/// The annotations asked for: `True` all, a comma-separated list of parts (marker, letters,
/// scale, measurements), `False` none; a caption alone when only a caption is given.
fn annotations(
    annotate: Option<&Bound<'_, PyAny>>,
    caption: Option<String>,
) -> PyResult<Option<Annotations>> {
    let list = match annotate {
        None => None,
        Some(a) if a.is_instance_of::<PyBool>() => a.extract::<bool>()?.then(|| "all".to_owned()),
        Some(a) if a.is_instance_of::<PyString>() => Some(a.extract::<String>()?),
        Some(_) => {
            return Err(PyTypeError::new_err(
                "annotate: True, False, or parts such as \"marker,letters,scale\"",
            ));
        }
    };
    let mut parts = match (list, &caption) {
        (Some(list), _) => {
            Annotations::parse_parts(&list).map_err(|e| bad(format!("annotate: {e}")))?
        }
        (None, Some(_)) => Annotations::parse_parts("none").map_err(fail)?,
        (None, None) => return Ok(None),
    };
    if caption.as_deref().is_some_and(|c| c.trim().is_empty()) {
        return Err(bad("caption: empty"));
    }
    parts.caption = caption;
    Ok(Some(parts))
}

/// A volume argument: a `Volume`, or a path read with the defaults.
fn volume_arg(
    py: Python<'_>,
    item: &Bound<'_, PyAny>,
) -> PyResult<(Arc<splatscene::volume::CpuVolume>, String)> {
    if let Ok(v) = item.cast::<Volume>() {
        let v = v.get();
        let name = v
            .path
            .as_ref()
            .and_then(|p| p.file_name())
            .map_or("<array>".into(), |n| n.to_string_lossy().into_owned());
        return Ok((Arc::clone(&v.inner), name));
    }
    let path: PathBuf = item
        .extract()
        .map_err(|_| PyTypeError::new_err("volumes: each must be a splatscene.Volume or a path"))?;
    let v = load_volume(
        py, path, None, false, None, None, None, None, None, None, None, None, None,
    )?;
    let name = v
        .path
        .as_ref()
        .and_then(|p| p.file_name())
        .map_or("volume".into(), |n| n.to_string_lossy().into_owned());
    Ok((v.inner, name))
}

#[pymethods]
impl Scene {
    /// A scene of `volumes` (each a `Volume` or a path) and `meshes` (each a `Mesh` or a
    /// path), seen from the named `view` (anterior by default). `transfer` is a preset
    /// (ct-bone, ct-soft-tissue, ct-metal, mr-default), `"ramp"` (with `window`), or `"auto"`
    /// (the default: chosen from the data); with a preset, `window` (lo, hi) stretches it over
    /// those values; `shift` moves it along the values. `crop_box` ((x0, y0, z0), (x1, y1,
    /// z1)) in RAS millimetres keeps what lies inside (the meshes too with `clip_meshes`).
    /// `background` is linear RGB, `transparent` leaves it out; `size` and `ordering` are the
    /// scene's defaults for `render`.
    #[new]
    #[pyo3(signature = (volumes=None, meshes=None, *, transfer=None, window=None, shift=None, crop_box=None, clip_meshes=None, background=None, transparent=false, size=None, ordering=None, view="anterior"))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        volumes: Option<Vec<Bound<'_, PyAny>>>,
        meshes: Option<Vec<Bound<'_, PyAny>>>,
        transfer: Option<&str>,
        window: Option<&Bound<'_, PyAny>>,
        shift: Option<f32>,
        crop_box: Option<&Bound<'_, PyAny>>,
        clip_meshes: Option<bool>,
        background: Option<&Bound<'_, PyAny>>,
        transparent: bool,
        size: Option<&Bound<'_, PyAny>>,
        ordering: Option<&str>,
        view: &str,
    ) -> PyResult<Self> {
        let mut file = SceneFile::default();
        let mut given = Given::default();
        let window = window
            .map(|w| two(w, "window").map(|[lo, hi]| [lo as f32, hi as f32]))
            .transpose()?;
        if let Some([lo, hi]) = window
            && lo >= hi
        {
            return Err(bad(format!(
                "window: ({lo}, {hi}); the low value must lie below the high one"
            )));
        }
        if let Some(s) = shift
            && !s.is_finite()
        {
            return Err(bad(format!("shift: {s} is not a finite number")));
        }
        for (i, item) in volumes.unwrap_or_default().iter().enumerate() {
            let (volume, name) = volume_arg(py, item)?;
            let mut spec = VolumeSpec {
                name: Some(name.clone()),
                path: name,
                ..VolumeSpec::default()
            };
            match transfer {
                Some("ramp") => {
                    spec.transfer = Some("ramp".into());
                    spec.window =
                        Some(window.ok_or_else(|| bad("transfer=\"ramp\" needs window=(lo, hi)"))?);
                    spec.shift = shift;
                }
                None | Some("auto") if window.is_some() => {
                    apply_transfer(&mut spec, None, window, shift);
                }
                None | Some("auto") => spec.shift = shift,
                Some(preset) => apply_transfer(&mut spec, Some(preset), window, shift),
            }
            if i == 0
                && let Some(b) = crop_box
            {
                let corners = crate::convert::matrix(b, 2, 3, "crop_box")?;
                spec.crop_box = Some(BoxSpec {
                    min: [corners[0][0], corners[0][1], corners[0][2]],
                    max: [corners[1][0], corners[1][1], corners[1][2]],
                });
                spec.clip_meshes = clip_meshes;
            }
            file.volumes.push(spec);
            given.volumes.push(Some(volume));
        }
        if file.volumes.is_empty() {
            for (key, given) in [
                ("transfer", transfer.is_some()),
                ("window", window.is_some()),
                ("shift", shift.is_some()),
                ("crop_box", crop_box.is_some()),
            ] {
                if given {
                    return Err(bad(format!("{key} applies to volumes; the scene has none")));
                }
            }
        }
        if clip_meshes.is_some() && crop_box.is_none() {
            return Err(bad("clip_meshes has no effect without a crop_box"));
        }
        for item in meshes.unwrap_or_default() {
            let mesh: PyRef<'_, Mesh> = match item.cast::<Mesh>() {
                Ok(m) => m.borrow(),
                Err(_) => {
                    let path: PathBuf = item.extract().map_err(|_| {
                        PyTypeError::new_err("meshes: each must be a splatscene.Mesh or a path")
                    })?;
                    let mesh = Mesh::from_file(
                        py, path, None, None, None, None, None, None, None, None, None,
                    )?;
                    Bound::new(py, mesh)?.borrow()
                }
            };
            file.meshes.push(mesh.spec.clone());
            given.meshes.push(Some((*mesh.model).clone()));
        }
        file.camera = Some(CameraSpec {
            view: Some(view.to_owned()),
            ..CameraSpec::default()
        });
        file.output.size = size
            .map(crate::convert::size)
            .transpose()?
            .map(|(w, h)| [w, h]);
        file.output.transparent = transparent;
        file.output.background = background
            .map(|b| three(b, "background").map(|c| c.map(|v| v as f32)))
            .transpose()?;
        if transparent && file.output.background.is_some() {
            return Err(bad("background has no effect with transparent=True"));
        }
        file.output.ordering = ordering
            .map(|o| {
                o.parse::<Ordering>()
                    .map_err(|e| bad(format!("ordering: {e}")))
            })
            .transpose()?;
        let base = std::env::current_dir().unwrap_or_else(|_| PathBuf::from("."));
        let loaded = py
            .detach(|| file.load_given(Path::new("the Python scene"), &base, given))
            .map_err(fail)?;
        Ok(Self::new_loaded(loaded, None))
    }

    /// Reads a scene file (TOML) and what it names, as `splatscene render FILE` does.
    #[staticmethod]
    fn from_file(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let loaded = py
            .detach(|| {
                let file = SceneFile::read(&path)?;
                let base = path.parent().unwrap_or(Path::new(".")).to_path_buf();
                file.load(&path, &base)
            })
            .map_err(fail)?;
        Ok(Self::new_loaded(loaded, Some(path)))
    }

    /// Draws the scene as `splatscene render` does: the `size` (width, height; the scene's,
    /// else 800 x 600), seen from its camera, a named `view` ("anterior", "left",
    /// "anterolateral-right"...; "scene" is the scene's own camera) or an `eye` (and
    /// `target`), turned by `orbit` (yaw, pitch in degrees), with `fov` or an `orthographic`
    /// height; `ordering` of the splats; `annotate` (True, or parts "marker,letters,scale,
    /// measurements") and a `caption`; `lod`, the level of detail as `splatscene render
    /// --lod` takes it: "auto" (the default: a level of the pyramid made only where it pays within the picture),
    /// "on" or True (levels made, which pays over many frames of one scene, an orbit),
    /// "volume", "off" or False. Returns the RGBA
    /// image, (height, width, 4) uint8; with `depth=True` also the depth, (height, width)
    /// float32 millimetres along the view axis, NaN where nothing was hit (`depth_mode`
    /// "mesh" or "surface", the volumes' first surface where the accumulated opacity reaches
    /// `surface_opacity`).
    #[pyo3(signature = (size=None, *, view=None, eye=None, target=None, orbit=None, fov=None, orthographic=None, ordering=None, annotate=None, caption=None, depth=false, depth_mode=None, surface_opacity=0.3, lod=None, transparent=false))]
    #[allow(clippy::too_many_arguments)]
    fn render<'py>(
        &self,
        py: Python<'py>,
        size: Option<&Bound<'py, PyAny>>,
        view: Option<&str>,
        eye: Option<&Bound<'py, PyAny>>,
        target: Option<&Bound<'py, PyAny>>,
        orbit: Option<&Bound<'py, PyAny>>,
        fov: Option<f64>,
        orthographic: Option<f64>,
        ordering: Option<&str>,
        annotate: Option<&Bound<'py, PyAny>>,
        caption: Option<String>,
        depth: bool,
        depth_mode: Option<&str>,
        surface_opacity: f32,
        lod: Option<&Bound<'py, PyAny>>,
        transparent: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        let lod: LevelOfDetail = match lod {
            None => LevelOfDetail::Auto,
            Some(v) => match v.extract::<bool>() {
                Ok(true) => LevelOfDetail::On,
                Ok(false) => LevelOfDetail::Off,
                Err(_) => v
                    .extract::<String>()
                    .map_err(|_| PyTypeError::new_err("lod: expected True, False or a string"))?
                    .parse()
                    .map_err(|e: String| bad(format!("lod: {e}")))?,
            },
        };
        let choice = CameraArgs {
            view,
            eye,
            target,
            orbit,
            fov,
            orthographic,
        }
        .choice()?;
        let ordering = ordering
            .map(|o| {
                o.parse::<Ordering>()
                    .map_err(|e| bad(format!("ordering: {e}")))
            })
            .transpose()?;
        let parts = annotations(annotate, caption)?;
        let mode = match depth_mode {
            None => None,
            Some("mesh") => Some(DepthMode::Mesh),
            Some("surface") => Some(DepthMode::Surface),
            Some(other) => {
                return Err(bad(format!(
                    "depth_mode: {other:?}; \"mesh\" or \"surface\""
                )));
            }
        };
        if mode.is_some() && !depth {
            return Err(bad("depth_mode has no effect without depth=True"));
        }
        if !(surface_opacity > 0.0 && surface_opacity <= 1.0) {
            return Err(bad(format!(
                "surface_opacity: {surface_opacity} is not in (0, 1]"
            )));
        }
        let asked = size.map(crate::convert::size).transpose()?;
        let drawn = py.detach(|| -> Result<_, String> {
            let mut guard = self
                .state
                .lock()
                .map_err(|_| "the scene was left broken by an earlier failure".to_owned())?;
            let state = &mut *guard;
            let size = size_or_default(asked, &state.loaded);
            let camera = camera_of(&state.loaded, &choice, size)?;
            let scene = &state.loaded.scene;
            let mode = mode.unwrap_or_else(|| default_depth_mode(scene));
            if depth && mode == DepthMode::Mesh && scene.meshes().next().is_none() {
                return Err(
                    "depth_mode \"mesh\": the scene has no meshes, so the depth would be empty; use depth_mode=\"surface\"".into(),
                );
            }
            let Measured {
                scene: with_marks,
                labels,
                mut parts,
            } = measured(scene, parts.as_ref()).map_err(|e| e.to_string())?;
            // The caption's placeholders, as the command line fills them.
            let view_name = choice.view.as_ref().map_or("scene", |v| v.name.as_str());
            let ordering = ordering.or(state.loaded.ordering);
            if let Some(p) = parts.as_mut() {
                p.caption = p
                    .caption
                    .take()
                    .map(|c| fill_caption(&c, view_name, size, ordering));
            }
            if state.ctx.is_none() {
                state.ctx =
                    Some(context_for(Compositor::Auto, &with_marks).map_err(|e| e.to_string())?);
            }
            state.renderer.set_lod(lod);
            let options = FrameOptions {
                ordering,
                background: if transparent {
                    None
                } else {
                    state.loaded.background
                },
                measure: true,
                preview: 0,
                volume_divisor: 1,
            };
            let shot = match state.ctx.as_ref().and_then(Option::as_ref) {
                Some(ctx) => state
                    .renderer
                    .screenshot(ctx, &with_marks, &camera, size, &options),
                None => state
                    .renderer
                    .screenshot_without_gpu(&with_marks, &camera, size, &options),
            }
            .map_err(|e| e.to_string())?;
            state.report = Some(shot.report);
            let (image, _) = figure_image(&shot, scene, &camera, parts.as_ref(), &labels)
                .map_err(|e| e.to_string())?;
            let depth = depth.then(|| {
                depth_distances(&shot, scene, mode, surface_opacity)
                    .into_iter()
                    .map(|d| d.map_or(f32::NAN, |d| d as f32))
                    .collect::<Vec<f32>>()
            });
            Ok((image, depth, size))
        });
        let (image, depth, size) = drawn.map_err(fail)?;
        let image = image_array(py, image)?.into_any();
        match depth {
            None => Ok(image),
            Some(d) => {
                let d = numpy::PyArray1::from_vec(py, d)
                    .reshape([size.1 as usize, size.0 as usize])?
                    .into_any();
                Ok(PyTuple::new(py, [image, d])?.into_any())
            }
        }
    }

    /// The point under `pixel` (x, y; 0, 0 the top-left) of the picture `render` draws with
    /// the same `size` and camera arguments, as `splatscene pick` gives it: a dict with
    /// `pixel`, `size` and `hit` (None where nothing is hit; else the point in RAS mm, what
    /// was hit, the distance). `opacity` is what a voxel must exceed to be hit.
    #[pyo3(signature = (pixel, size=None, *, view=None, eye=None, target=None, orbit=None, fov=None, orthographic=None, opacity=0.1, meshes_only=false))]
    #[allow(clippy::too_many_arguments)]
    fn pick<'py>(
        &self,
        py: Python<'py>,
        pixel: &Bound<'py, PyAny>,
        size: Option<&Bound<'py, PyAny>>,
        view: Option<&str>,
        eye: Option<&Bound<'py, PyAny>>,
        target: Option<&Bound<'py, PyAny>>,
        orbit: Option<&Bound<'py, PyAny>>,
        fov: Option<f64>,
        orthographic: Option<f64>,
        opacity: f32,
        meshes_only: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        let choice = CameraArgs {
            view,
            eye,
            target,
            orbit,
            fov,
            orthographic,
        }
        .choice()?;
        if !(0.0..=1.0).contains(&opacity) {
            return Err(bad(format!("opacity: {opacity} is not from 0 to 1")));
        }
        let [x, y] = two(pixel, "pixel")?;
        let asked = size.map(crate::convert::size).transpose()?;
        let state = self.lock()?;
        let size = size_or_default(asked, &state.loaded);
        if x.fract() != 0.0 || y.fract() != 0.0 || x < 0.0 || y < 0.0 {
            return Err(bad(format!(
                "pixel: ({x}, {y}) is not two whole numbers from 0"
            )));
        }
        let (x, y) = (x as u32, y as u32);
        if x >= size.0 || y >= size.1 {
            return Err(bad(format!(
                "pixel: ({x}, {y}) is outside the {}x{} image",
                size.0, size.1
            )));
        }
        let camera = camera_of(&state.loaded, &choice, size).map_err(fail)?;
        let scene = &state.loaded.scene;
        let out = py.detach(|| -> Result<serde_json::Value, String> {
            let view = ViewSetup::new(&camera, size, scene.bounds()).map_err(|e| e.to_string())?;
            let options = PickOptions {
                opacity_threshold: opacity,
                volumes: !meshes_only,
            };
            let hit = Picker::new(scene).pick_pixel(scene, &view, x, y, &options);
            Ok(serde_json::json!({
                "pixel": [x, y],
                "size": [size.0, size.1],
                "hit": hit.map(|h| h.to_json(scene)),
            }))
        });
        json_to_py(py, &out.map_err(fail)?)
    }

    /// What a mesh's surface touches in the first volume, as `splatscene contact` reports it:
    /// the area by value class (CT classes by default, or the `classes` edges given), the
    /// least, mean and greatest value, and the area outside the volume. `mesh` names a mesh of
    /// the scene (the first by default).
    #[pyo3(signature = (mesh=None, *, classes=None))]
    fn contact<'py>(
        &self,
        py: Python<'py>,
        mesh: Option<&str>,
        classes: Option<Vec<f64>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let state = self.lock()?;
        let scene = &state.loaded.scene;
        let classes = match classes {
            Some(edges) => Classes::from_edges(&edges).map_err(|e| bad(format!("classes: {e}")))?,
            None => scene
                .volumes()
                .next()
                .map_or_else(Classes::none, |(_, v, _)| Classes::for_volume(&v.volume)),
        };
        let report = py.detach(|| contact(scene, mesh, &classes)).map_err(fail)?;
        json_to_py(py, &serde_json::to_value(&report).map_err(fail)?)
    }

    /// The scene's own image size, `None` where it sets none.
    #[getter]
    fn size(&self) -> PyResult<Option<(u32, u32)>> {
        Ok(self.lock()?.loaded.size)
    }

    /// The names of the scene's volumes.
    #[getter]
    fn volumes(&self) -> PyResult<Vec<String>> {
        let state = self.lock()?;
        let scene = &state.loaded.scene;
        Ok(scene
            .volumes()
            .filter_map(|(id, ..)| scene.node(id).ok().map(|n| n.name.clone()))
            .collect())
    }

    /// The names of the scene's meshes (the top node of each mesh file).
    #[getter]
    fn meshes(&self) -> PyResult<Vec<String>> {
        let state = self.lock()?;
        let scene = &state.loaded.scene;
        Ok(scene
            .nodes()
            .iter()
            .filter(|n| {
                n.parent().is_none()
                    && !matches!(n.content, splatscene::scene::NodeContent::Volume(_))
            })
            .map(|n| n.name.clone())
            .collect())
    }

    /// The scene's camera: eye, target and up in RAS millimetres.
    #[getter]
    fn camera<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let state = self.lock()?;
        let camera = state
            .loaded
            .scene
            .camera
            .ok_or_else(|| fail("the scene has no camera"))?;
        json_to_py(
            py,
            &serde_json::json!({
                "eye": camera.eye.to_array(),
                "target": camera.target.to_array(),
                "up": camera.up.to_array(),
            }),
        )
    }

    /// What the last `render` drew and where its time went, as `splatscene render` says it on
    /// stderr: meshes, triangles, splats, the level of detail and refinement, how many volumes
    /// were classified (0 when the renderer kept them), the CPU tiles' counts, and the stages'
    /// milliseconds; `None` before the first picture.
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let Some(r) = self.lock()?.report else {
            return Ok(py.None().into_bound(py));
        };
        let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
        let t = r.timings;
        let tiles = r.tiles.map(|t| {
            serde_json::json!({
                "projected": t.projected,
                "culled": t.culled,
                "off_image": t.off_image,
                "drew": t.drew,
                "composited": t.composited,
                "skipped_opaque": t.skipped_opaque,
                "tiles_opaque": t.tiles_opaque,
                "project_ms": ms(t.project),
                "bin_ms": ms(t.bin),
                "tiles_ms": ms(t.tiles),
            })
        });
        json_to_py(
            py,
            &serde_json::json!({
                "meshes": r.meshes,
                "triangles": r.triangles,
                "splats": r.splats,
                "level": r.level,
                "levels": r.levels,
                "refined": r.refined,
                "classified": r.classified,
                "levels_made": r.levels_made,
                "tiles": tiles,
                "classify_ms": ms(t.classify),
                "levels_ms": ms(t.levels),
                "texels_ms": ms(t.texels),
                "order_ms": ms(t.order),
                "upload_ms": ms(t.upload),
                "mesh_pass_ms": ms(t.mesh_pass),
                "splat_pass_ms": ms(t.splat_pass),
                "readback_ms": ms(t.readback),
                "read_back_pixels": r.read_back,
            }),
        )
    }

    fn __repr__(&self) -> PyResult<String> {
        let volumes = self.volumes()?;
        let meshes = self.meshes()?;
        Ok(format!(
            "Scene(volumes={volumes:?}, meshes={meshes:?}{})",
            self.path
                .as_ref()
                .map_or(String::new(), |p| format!(", from {}", p.display()))
        ))
    }
}
