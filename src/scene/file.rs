//! Scene files: a TOML description of volumes, meshes, camera, lights and output, read with
//! serde. Every table refuses fields it does not know, so a misspelt key is an error naming the
//! file and the key rather than a setting silently left at its default.
//!
//! Paths of volumes and meshes are read as follows:
//! - `builtin:shoulder-phantom` (volumes) and `builtin:prosthesis` (meshes) name the built-in
//!   phantom and prosthesis;
//! - `data:REST` names `REST` inside the shared test data folder: `$SPLATSCENE_DATA/REST`, or
//!   `../shared/data/REST` relative to the current directory when `SPLATSCENE_DATA` is unset or
//!   empty. `REST` must be a relative path that stays inside that folder (no `..`), so that a
//!   scene file written against the data works on every machine that has the data, wherever it
//!   lies;
//! - any other relative path is taken from the scene file's folder; absolute paths are used as
//!   they are.
//!
//! ```toml
//! [output]
//! size = [800, 600]
//! ordering = "ip-pbtf"
//!
//! [camera]
//! view_from = [-0.55, 1.0, -0.35]   # fit the scene, looking along this direction
//!
//! [[volume]]
//! path = "builtin:shoulder-phantom"
//! transfer = "ct-bone"
//! resect_humeral_head = true
//!
//! [[volume]]
//! path = "data:volumes/engine/engine_256x256x128_uint8.raw"
//! dims = [256, 256, 128]
//! scalar = "u8"
//! transfer = "ramp"
//! window = [90, 200]
//!
//! [[mesh]]
//! path = "builtin:prosthesis"
//! seat = "phantom"
//! ```
//!
//! `examples/scenes/` holds complete scene files.

mod validate;
pub use validate::extra_elements;

use std::ffi::OsStr;
use std::path::{Component, Path, PathBuf};
use std::sync::Arc;

use glam::{DMat4, DQuat, DVec3, EulerRot};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use super::patient::{NamedView, OrientationCode};
use super::shoulder::{
    add_model, cut_away_anterior_humerus, prosthesis_model, resect_humeral_head,
};
use super::{
    ClipPlane, Clipping, Light, Lights, MAX_CLIP_PLANES, NodeContent, NodeId, Projection, Scene,
    SceneCamera, SceneMeasurement, SplatSettings, VolumeNode,
};
use crate::classify::{TransferFunction, auto_transfer};
use crate::measure::MeasureKind;
use crate::mesh::prosthesis::seat_in_phantom;
use crate::mesh::{MeshError, load_mesh};
use crate::order::Ordering;
use crate::volume::detect::{LoadOptions, SeriesChoice};
use crate::volume::phantom::{DEFAULT_DIMS, DEFAULT_SPACING};
use crate::volume::{
    CpuVolume, RawSpec, ScalarFormat, VolumeError, load_raw, load_raw_slices, shoulder_landmarks,
    shoulder_phantom_default, slice_stack,
};

/// Why a scene file could not be used.
#[derive(Debug, Error)]
pub enum SceneFileError {
    /// The file could not be read.
    #[error("{}: cannot read: {source}", path.display())]
    Io {
        /// The scene file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The TOML is malformed or has unknown or mistyped fields.
    #[error("{}: {message}", path.display())]
    Parse {
        /// The scene file.
        path: PathBuf,
        /// What the parser said, with the line.
        message: String,
    },
    /// A value is out of range or a combination makes no sense.
    #[error("{}: {message}", path.display())]
    Invalid {
        /// The scene file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A mesh did not load.
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// A volume did not load.
    #[error(transparent)]
    Volume(#[from] VolumeError),
    /// A `data:` path names a file that is not in the shared data folder, most likely because
    /// `SPLATSCENE_DATA` is not set to where the data lie.
    #[error(
        "{}: {} not found: `data:` paths are read from ${DATA_ENV} ({}); set {DATA_ENV} to the shared data folder",
        path.display(),
        file.display(),
        describe_data_dir(data_var.as_deref())
    )]
    DataNotFound {
        /// The scene file.
        path: PathBuf,
        /// The file the `data:` path resolved to.
        file: PathBuf,
        /// The value of `SPLATSCENE_DATA` when the path was resolved (`None` when unset).
        data_var: Option<std::ffi::OsString>,
    },
}

/// The environment variable naming the shared data folder that `data:` paths point into.
pub const DATA_ENV: &str = "SPLATSCENE_DATA";

/// The shared data folder when [`DATA_ENV`] is unset or empty, relative to the current
/// directory (where it lies next to a checkout of the repository run from its root).
pub const DEFAULT_DATA_DIR: &str = "../shared/data";

/// The shared data folder: `$SPLATSCENE_DATA`, or [`DEFAULT_DATA_DIR`] when that is unset or
/// empty.
pub fn data_dir() -> PathBuf {
    data_dir_from(std::env::var_os(DATA_ENV).as_deref())
}

fn data_dir_from(var: Option<&OsStr>) -> PathBuf {
    match var {
        // An empty value is far more likely a blank export than a wish for the current
        // directory, so it counts as unset.
        Some(v) if !v.is_empty() => PathBuf::from(v),
        _ => PathBuf::from(DEFAULT_DATA_DIR),
    }
}

fn describe_data_dir(var: Option<&OsStr>) -> String {
    match var {
        Some(v) if !v.is_empty() => format!("now {}", Path::new(v).display()),
        _ => format!("unset, so {DEFAULT_DATA_DIR} relative to the current directory"),
    }
}

/// Output settings.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct OutputSpec {
    /// Image width and height in pixels.
    pub size: Option<[u32; 2]>,
    /// Opaque background colour, linear RGB.
    pub background: Option<[f32; 3]>,
    /// A transparent background instead.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub transparent: bool,
    /// Ordering for every volume (btf, wbtf, pbtf, ip-pbtf, exact, bucketed...).
    pub ordering: Option<String>,
}

/// The camera; without `eye` the scene is fitted, seen along `view_from`.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    /// Eye position (world).
    pub eye: Option<[f64; 3]>,
    /// Look-at point; the scene centre by default.
    pub target: Option<[f64; 3]>,
    /// Up vector on screen, and the scene's up that orbits turn about; the patient's superior
    /// axis by default (anterior for a view along it).
    pub up: Option<[f64; 3]>,
    /// A named view of the patient (`anterior`, `superior`, `anterolateral-right`...; see
    /// [`super::patient::NamedView`]), fitted to the scene; instead of `eye` and `view_from`.
    pub view: Option<String>,
    /// Viewing direction used to fit the scene when no eye is given.
    pub view_from: Option<[f64; 3]>,
    /// Vertical field of view in degrees (perspective).
    pub fov: Option<f64>,
    /// Visible height in world units: makes the camera orthographic.
    pub orthographic_height: Option<f64>,
    /// Near plane distance.
    pub near: Option<f64>,
}

/// A directional light.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LightSpec {
    /// Direction the light travels.
    pub direction: [f64; 3],
    /// Linear RGB times intensity.
    pub color: [f32; 3],
}

/// Lights; absent fields keep the defaults.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LightsSpec {
    /// Headlight intensity.
    pub headlight: Option<f32>,
    /// Ambient intensity.
    pub ambient: Option<f32>,
    /// Directional lights (replace the default one when given).
    pub directional: Option<Vec<LightSpec>>,
}

/// A node transform: scale, then rotation (degrees about x, y, z in that order), then
/// translation; or a full column-major matrix.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct TransformSpec {
    /// Translation.
    pub translate: Option<[f64; 3]>,
    /// Rotation in degrees about x, then y, then z.
    pub rotate_degrees: Option<[f64; 3]>,
    /// Per-axis scale.
    pub scale: Option<[f64; 3]>,
    /// A column-major 4x4 matrix (replaces the other fields).
    pub matrix: Option<[f64; 16]>,
}

/// A volume.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct VolumeSpec {
    /// Node name.
    pub name: Option<String>,
    /// A raw file (or the first of a slice stack ending in `.1`), or `builtin:shoulder-phantom`.
    pub path: String,
    /// Raw: grid size.
    pub dims: Option<[u32; 3]>,
    /// Raw: scalar type and byte order, such as `u8`, `i16le`, `u16be`, `f32`.
    pub scalar: Option<String>,
    /// Raw: bytes to skip at the start of each file.
    pub header_bytes: Option<u64>,
    /// Raw: voxel spacing in millimetres.
    pub spacing: Option<[f64; 3]>,
    /// Raw: world position of the first voxel.
    pub origin: Option<[f64; 3]>,
    /// DICOM: the series to load from a folder holding several, by SeriesNumber or
    /// SeriesInstanceUID.
    pub series: Option<String>,
    /// DICOM: load the series without its files that cannot be read (said on stderr); by
    /// default such a file is an error naming it.
    pub skip_unreadable: Option<bool>,
    /// 4-D NIfTI: the 3-D frame to draw, from 0 (the first by default, said on stderr).
    pub frame: Option<u32>,
    /// NIfTI: which transform places the grid when both are set, `sform` (the default, as
    /// nibabel), `qform`, or `itk` (ITK's and 3D Slicer's rule: the sform only when its code
    /// is 1, scanner, else the qform).
    pub nifti_transform: Option<String>,
    /// A file whose format states no patient frame (VTK `.vtk`/`.vti`, `.dat`, NRRD without
    /// an anatomical `space`): the frame its coordinates are in, `RAS` (the default) or `LPS`
    /// (what ITK-based tools write). Refused for a file that states its own.
    pub coordinate_frame: Option<String>,
    /// Raw: where the index axes run in the patient frame, one letter per axis naming the
    /// side it increases toward (`RAS`, the default, puts the grid along world +x, +y, +z;
    /// `LPS`, `LPI`...; see [`super::patient`]).
    pub orientation: Option<String>,
    /// Transfer function: a preset (`ct-bone`, the default, `ct-soft-tissue`, `ct-metal`,
    /// `mr-default`) or `ramp` (with `window` and `color`).
    pub transfer: Option<String>,
    /// Moves the transfer function along the value axis (after `level_width`).
    pub shift: Option<f32>,
    /// Stretches the transfer function over the window `[level, width]`.
    pub level_width: Option<[f32; 2]>,
    /// The transfer function's opacities hold for this many millimetres of tissue (1 by
    /// default, whatever the voxel size).
    pub opacity_reference_mm: Option<f64>,
    /// Headlight shading of the splats from 0 (flat) to 1.
    pub shading: Option<f32>,
    /// Shell mode: only voxels with a neighbour at or below this opacity become splats.
    pub shell: Option<f32>,
    /// Ramp: transparent at the first value, `color` at the second.
    pub window: Option<[f32; 2]>,
    /// Ramp: straight RGBA at the top of the window.
    pub color: Option<[f32; 4]>,
    /// Voxels at or below this opacity are left out.
    pub min_opacity: Option<f32>,
    /// The phantom only: remove the humeral head above the resection plane.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub resect_humeral_head: bool,
    /// The phantom only: cut away the bone in front of the humeral shaft within this many
    /// millimetres of its axis (the built-in scene uses 30), so that a stem shows in its canal.
    pub cut_away_anterior_humerus: Option<f64>,
    /// Node transform.
    #[serde(default)]
    pub transform: TransformSpec,
    /// Keep only what lies inside this box, in world millimetres (it cuts every volume of the
    /// scene; one crop box per scene).
    pub crop_box: Option<BoxSpec>,
    /// Whether the crop box cuts the meshes too (it cuts only the volumes by default).
    pub clip_meshes: Option<bool>,
}

/// A box in world millimetres.
#[derive(Debug, Clone, Copy, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct BoxSpec {
    /// The low corner.
    pub min: [f64; 3],
    /// The high corner.
    pub max: [f64; 3],
}

/// A clip plane: through a point, cutting away the side its normal points to; volumes always,
/// meshes when `meshes` is true.
#[derive(Debug, Clone, Copy, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ClipSpec {
    /// A point of the plane (world millimetres).
    pub through: [f64; 3],
    /// Points to the side cut away.
    pub normal: [f64; 3],
    /// Whether the plane cuts the meshes too.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub meshes: bool,
}

/// A mesh file.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct MeshSpec {
    /// Node name.
    pub name: Option<String>,
    /// A glTF, OBJ or STL file, or `builtin:prosthesis`.
    pub path: String,
    /// Base colour (RGB or RGBA, linear) replacing the file's; an alpha below 1 draws the
    /// mesh translucent.
    pub color: Option<Vec<f32>>,
    /// Opacity from 0 (exclusive) to 1, multiplying the colour's alpha: below 1 the mesh is
    /// drawn translucent, over the volume, so that what lies inside shows.
    pub opacity: Option<f32>,
    /// Roughness replacing the file's.
    pub roughness: Option<f32>,
    /// Metalness replacing the file's.
    pub metallic: Option<f32>,
    /// `phantom`: seat the prosthesis in the built-in phantom's humerus (before `transform`).
    pub seat: Option<String>,
    /// Length unit of the file's coordinates: `mm` (the default), `cm` or `m` (OpenSim and
    /// many STL exports are in metres); scaled to millimetres before `transform`.
    pub units: Option<String>,
    /// Patient frame of the file's coordinates: `RAS` (the default, the scene's) or `LPS`
    /// (DICOM's, and 3D Slicer's model export); turned to RAS before `transform`.
    pub frame: Option<String>,
    /// Node transform.
    #[serde(default)]
    pub transform: TransformSpec,
}

/// A measurement of the plan: `kind = "distance" | "angle" | "line-angle" | "point"` and its
/// 2, 3, 4 or 1 `points`, in world millimetres or, with `node`, in that node's frame (so that
/// a landmark on an implant moves with it).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct MeasurementSpec {
    /// What is measured.
    pub kind: MeasureKind,
    /// The points.
    pub points: Vec<[f64; 3]>,
    /// The name written beside the value.
    pub label: Option<String>,
    /// The name of the node (a mesh or volume) whose frame the points are in.
    pub node: Option<String>,
}

/// A whole scene file.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// Output settings.
    #[serde(default)]
    pub output: OutputSpec,
    /// The camera.
    pub camera: Option<CameraSpec>,
    /// The lights.
    #[serde(default)]
    pub lights: LightsSpec,
    /// Volumes.
    #[serde(default, rename = "volume")]
    pub volumes: Vec<VolumeSpec>,
    /// Meshes.
    #[serde(default, rename = "mesh")]
    pub meshes: Vec<MeshSpec>,
    /// Measurements.
    #[serde(default, rename = "measurement", skip_serializing_if = "Vec::is_empty")]
    pub measurements: Vec<MeasurementSpec>,
    /// Clip planes.
    #[serde(default, rename = "clip", skip_serializing_if = "Vec::is_empty")]
    pub clip: Vec<ClipSpec>,
}

/// A loaded scene with the output settings of its file.
#[derive(Debug, Clone)]
pub struct LoadedScene {
    /// The scene, its camera set.
    pub scene: Scene,
    /// Image size.
    pub size: Option<(u32, u32)>,
    /// Background; `None` is transparent.
    pub background: Option<[f32; 3]>,
    /// Ordering override.
    pub ordering: Option<Ordering>,
}

/// The longest scene file read: most are a few kilobytes of TOML, and a scene that places one
/// mesh file tens of thousands of times (screws, beads, a lattice) takes about 50 bytes a node.
pub const MAX_SCENE_BYTES: u64 = 16 << 20;

impl SceneFile {
    /// Reads and parses a scene file (at most [`MAX_SCENE_BYTES`]).
    pub fn read(path: &Path) -> Result<Self, SceneFileError> {
        let io = |source| SceneFileError::Io {
            path: path.into(),
            source,
        };
        // The length comes from the file's metadata, which a named pipe or a device cannot
        // hold up.
        let len = std::fs::metadata(path).map_err(io)?.len();
        if len > MAX_SCENE_BYTES {
            return Err(SceneFileError::Invalid {
                path: path.into(),
                message: format!("{len} bytes is too large for a scene file (16 MiB at most)"),
            });
        }
        let text = crate::input::read_regular_text(path, MAX_SCENE_BYTES).map_err(io)?;
        Self::parse(&text, path)
    }

    /// Parses scene TOML; `path` names it in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self, SceneFileError> {
        let error = |message: String| SceneFileError::Parse {
            path: path.into(),
            message,
        };
        let file: Self = toml::from_str(text).map_err(|e| error(e.to_string()))?;
        // serde fills a fixed-size array from the first elements of a longer one and drops the
        // rest without a word (`size = [160, 120, 999]`): the lengths are compared with what
        // the file reads as.
        let written: toml::Value = toml::from_str(text).map_err(|e| error(e.to_string()))?;
        let read = toml::Value::try_from(&file).map_err(|e| error(e.to_string()))?;
        if let Some(message) = validate::extra_elements(&written, &read, "") {
            return Err(error(message));
        }
        Ok(file)
    }

    /// Loads everything the file names; relative paths are taken from `base`.
    pub fn load(&self, path: &Path, base: &Path) -> Result<LoadedScene, SceneFileError> {
        let invalid = |message: String| SceneFileError::Invalid {
            path: path.into(),
            message,
        };
        // The cheap checks come first, so that a typo is reported before volumes are read.
        validate::check(self).map_err(&invalid)?;
        let size = self.output.size.map(|[w, h]| (w, h));
        let ordering = match &self.output.ordering {
            Some(name) => Some(
                name.parse::<Ordering>()
                    .map_err(|e| invalid(format!("output.ordering: {e}")))?,
            ),
            None => None,
        };
        let data = DataRoot::from_env();
        let mut scene = Scene::new();
        for (i, spec) in self.volumes.iter().enumerate() {
            let node = load_volume(spec, path, base, &data, &invalid)?;
            let name = spec
                .name
                .clone()
                .unwrap_or_else(|| format!("volume {}", i + 1));
            let local = transform(&spec.transform).map_err(&invalid)?;
            scene
                .add(name, local, None, NodeContent::Volume(node))
                .map_err(|e| invalid(e.to_string()))?;
        }
        let mut meshes = Vec::with_capacity(self.meshes.len());
        // Each mesh file is read once; nodes that name it again share its triangles.
        let mut loaded_files = MeshFiles::default();
        for (i, spec) in self.meshes.iter().enumerate() {
            let files = &mut loaded_files;
            let id = load_mesh_spec(&mut scene, spec, i, (path, base, &data), files, &invalid)?;
            meshes.push((
                scene
                    .node(id)
                    .map_err(|e| invalid(e.to_string()))?
                    .name
                    .clone(),
                id,
            ));
        }
        for (i, spec) in self.measurements.iter().enumerate() {
            let m = measurement(&scene, spec, i).map_err(&invalid)?;
            scene.measurements.push(m);
        }
        scene.clipping = clipping(self).map_err(&invalid)?;
        if let (Some((lo, hi)), Some((vlo, vhi))) = (scene.clipping.crop, scene.volume_bounds())
            && !(lo.cmplt(vhi).all() && vlo.cmplt(hi).all())
        {
            return Err(invalid(format!(
                "crop_box from {} to {} mm lies wholly outside the volumes, which span {} to {} mm: it would leave nothing to draw",
                mm(lo),
                mm(hi),
                mm(vlo),
                mm(vhi)
            )));
        }
        for warning in scale_warnings(&scene, &meshes) {
            eprintln!("warning: {}: {warning}", path.display());
        }
        scene.lights = lights(&self.lights);
        scene.up = self.camera.as_ref().and_then(|c| c.up).map(DVec3::from);
        let aspect = size.map_or(4.0 / 3.0, |(w, h)| f64::from(w) / f64::from(h));
        scene.camera = Some(camera(self.camera.as_ref(), &scene, aspect).map_err(&invalid)?);
        let background = if self.output.transparent {
            None
        } else {
            Some(self.output.background.unwrap_or([0.06, 0.07, 0.09]))
        };
        Ok(LoadedScene {
            scene,
            size,
            background,
            ordering,
        })
    }
}

impl SceneFile {
    /// The same file with every relative volume and mesh path made absolute against `base`
    /// (the scene file's folder), so that it can be saved anywhere; `builtin:` and `data:`
    /// paths are kept as they are.
    pub fn with_paths_from(&self, base: &Path) -> Self {
        let fix = |path: &str| {
            let p = Path::new(path);
            if path.starts_with("builtin:") || path.starts_with("data:") || p.is_absolute() {
                path.to_owned()
            } else {
                std::path::absolute(base.join(p))
                    .unwrap_or_else(|_| base.join(p))
                    .to_string_lossy()
                    .into_owned()
            }
        };
        let mut file = self.clone();
        for v in &mut file.volumes {
            v.path = fix(&v.path);
        }
        for m in &mut file.meshes {
            m.path = fix(&m.path);
        }
        file
    }

    /// What cannot be found among the files the scene names, one message each, without
    /// reading them: paths that do not resolve or do not exist. Relative paths are taken from
    /// `base`, `data:` paths from [`data_dir`].
    pub fn missing_files(&self, base: &Path) -> Vec<String> {
        let data = data_dir();
        let named = self
            .volumes
            .iter()
            .enumerate()
            .map(|(i, v)| (format!("volume {}", i + 1), &v.name, &v.path))
            .chain(
                self.meshes
                    .iter()
                    .enumerate()
                    .map(|(i, m)| (format!("mesh {}", i + 1), &m.name, &m.path)),
            );
        let mut missing = Vec::new();
        for (what, name, path) in named {
            if path.starts_with("builtin:") {
                continue;
            }
            let what = match name {
                Some(n) => format!("{what} ({n})"),
                None => what,
            };
            match resolve_path(path, base, &data) {
                Err(e) => missing.push(format!("{what}: {e}")),
                Ok(file) if !file.exists() => missing.push(if path.starts_with("data:") {
                    format!(
                        "{what}: {} not found: `data:` paths are read from ${DATA_ENV} ({})",
                        file.display(),
                        describe_data_dir(std::env::var_os(DATA_ENV).as_deref())
                    )
                } else {
                    format!("{what}: {} not found", file.display())
                }),
                Ok(_) => {}
            }
        }
        missing
    }

    /// The same file with the plan `scene` holds now: each mesh's transform as the node stands
    /// (written as a matrix, so that the file loads to the same placement), and the scene's
    /// measurements (those attached to a node by the node's name). `scene` must have been
    /// loaded from this file: its mesh files are the top nodes after the volumes, in order.
    ///
    /// # Errors
    ///
    /// A message when a mesh's placement cannot be expressed (a singular seat or frame) or a
    /// mesh node is missing.
    pub fn with_plan(&self, scene: &Scene) -> Result<Self, String> {
        let mut file = self.clone();
        let roots: Vec<NodeId> = (0..scene.nodes().len())
            .map(NodeId)
            .filter(|id| scene.nodes()[id.0].parent().is_none())
            .collect();
        let invalid = |message: String| SceneFileError::Invalid {
            path: PathBuf::new(),
            message,
        };
        for (i, spec) in file.meshes.iter_mut().enumerate() {
            let id = *roots
                .get(self.volumes.len() + i)
                .ok_or_else(|| format!("mesh {}: no node in the scene", i + 1))?;
            let local = scene.node(id).map_err(|e| e.to_string())?.local();
            let seat = match spec.seat.as_deref() {
                Some("phantom") => {
                    seat_in_phantom(&shoulder_landmarks(DEFAULT_DIMS, DEFAULT_SPACING))
                }
                _ => DMat4::IDENTITY,
            };
            let frame = file_frame(spec, &invalid).map_err(|e| e.to_string())?;
            let (ds, df) = (seat.determinant(), frame.determinant());
            if !(ds.is_normal() && df.is_normal()) {
                return Err(format!("mesh {}: its seat or frame is singular", i + 1));
            }
            // Round-off of turns by whole angles (1e-17 for 0) is written as 0.
            let matrix = (seat.inverse() * local * frame.inverse())
                .to_cols_array()
                .map(|x| if x.abs() < 1e-12 { 0.0 } else { x });
            spec.transform = TransformSpec {
                matrix: Some(matrix),
                ..TransformSpec::default()
            };
        }
        file.clip = scene
            .clipping
            .planes
            .iter()
            .map(|p| ClipSpec {
                through: (p.normal * (p.offset / p.normal.length_squared())).to_array(),
                normal: p.normal.to_array(),
                meshes: p.meshes,
            })
            .collect();
        for v in &mut file.volumes {
            v.crop_box = None;
            v.clip_meshes = None;
        }
        if let Some((lo, hi)) = scene.clipping.crop {
            let v = file
                .volumes
                .first_mut()
                .ok_or("a crop box needs a volume to keep it in the scene file")?;
            v.crop_box = Some(BoxSpec {
                min: lo.to_array(),
                max: hi.to_array(),
            });
            v.clip_meshes = scene.clipping.crop_meshes.then_some(true);
        }
        file.measurements = scene
            .measurements
            .iter()
            .map(|m| MeasurementSpec {
                kind: m.kind,
                points: m.points.iter().map(|p| p.to_array()).collect(),
                label: m.label.clone(),
                node: m
                    .node
                    .and_then(|id| scene.node(id).ok())
                    .map(|n| n.name.clone()),
            })
            .collect();
        Ok(file)
    }

    /// The file as TOML text, as [`SceneFile::parse`] reads it back.
    pub fn to_toml(&self) -> Result<String, String> {
        toml::to_string(self).map_err(|e| e.to_string())
    }
}

impl CameraSpec {
    /// The spec that gives `camera` back: its eye, target and projection, and as `up` the
    /// scene's up axis `scene_up` where the camera is upright about it (so that the saved
    /// scene orbits as this one does), else the camera's own up.
    pub fn from_camera(camera: &SceneCamera, scene_up: DVec3) -> Self {
        let forward = (camera.target - camera.eye).normalize_or_zero();
        let screen_up = camera.up.normalize_or_zero();
        let right = forward.cross(screen_up);
        let upright = scene_up.try_normalize().is_some_and(|u| {
            u.dot(right).abs() < 1e-9 * (1.0 + right.length())
                && forward.cross(u).length() > 1e-6
                && u.dot(screen_up) > 0.0
        });
        let up = if upright { scene_up } else { camera.up };
        let (fov, orthographic_height) = match camera.projection {
            Projection::Perspective { fov_y_degrees } => (Some(fov_y_degrees), None),
            Projection::Orthographic { height } => (None, Some(height)),
        };
        Self {
            eye: Some(camera.eye.to_array()),
            target: Some(camera.target.to_array()),
            up: Some(up.to_array()),
            view: None,
            view_from: None,
            fov,
            orthographic_height,
            near: camera.near,
        }
    }
}

/// Reads a scene file and loads what it names.
pub fn load_scene_file(path: &Path) -> Result<LoadedScene, SceneFileError> {
    let file = SceneFile::read(path)?;
    let base = path.parent().unwrap_or(Path::new("."));
    file.load(path, base)
}

/// The data folder as read once per scene load, with the variable's value for error messages.
struct DataRoot {
    dir: PathBuf,
    var: Option<std::ffi::OsString>,
}

impl DataRoot {
    fn from_env() -> Self {
        let var = std::env::var_os(DATA_ENV);
        Self {
            dir: data_dir_from(var.as_deref()),
            var,
        }
    }
}

/// How many nodes are named `name` apart from a parent of that name (the parts of a mesh
/// file may take its name): more than one, and a name does not say which node it means.
fn named_apart(scene: &Scene, name: &str) -> usize {
    let nodes = scene.nodes();
    nodes
        .iter()
        .filter(|node| node.name == name && node.parent().is_none_or(|p| nodes[p.0].name != name))
        .count()
}

/// A world point for a message: `[x, y, z]` to 0.1 mm.
fn mm(p: DVec3) -> String {
    format!("[{:.1}, {:.1}, {:.1}]", p.x, p.y, p.z)
}

/// At most the first 60 characters of a text a user wrote, for an error message: a label or
/// name of a megabyte is not repeated whole.
pub fn shortened(text: &str) -> String {
    const SHOWN: usize = 60;
    match text.char_indices().nth(SHOWN) {
        Some((end, _)) => format!("{}... ({} characters)", &text[..end], text.chars().count()),
        None => text.to_owned(),
    }
}

impl SceneFile {
    /// The files and folders this scene's volumes and meshes name, resolved as loading resolves
    /// them (built-in names and paths that cannot be resolved left out): what a run must never
    /// write, known before anything is loaded.
    pub fn named_paths(&self, base: &Path) -> Vec<PathBuf> {
        let data = DataRoot::from_env();
        self.volumes
            .iter()
            .map(|v| &v.path)
            .chain(self.meshes.iter().map(|m| &m.path))
            .filter(|p| !p.starts_with("builtin:"))
            .filter_map(|p| resolve_path(p, base, &data.dir).ok())
            .collect()
    }
}

/// Where a volume or mesh `path` of a scene file points (see the module documentation): a
/// `data:` path inside `data_dir`, a relative path inside `base` (the scene file's folder), an
/// absolute path as it is. Built-in names are not paths and must be handled before.
///
/// # Errors
///
/// A message when a `data:` path is empty, absolute, or climbs out of the data folder.
pub fn resolve_path(path: &str, base: &Path, data_dir: &Path) -> Result<PathBuf, String> {
    let Some(rest) = path.strip_prefix("data:") else {
        let p = Path::new(path);
        return Ok(if p.is_absolute() {
            p.into()
        } else {
            base.join(p)
        });
    };
    let rel = Path::new(rest);
    let mut names = 0;
    for component in rel.components() {
        match component {
            Component::Normal(_) => names += 1,
            Component::CurDir => {}
            // A data: path that leaves the data folder would make scene files depend on what
            // lies around it, which is what the prefix exists to avoid.
            Component::ParentDir | Component::RootDir | Component::Prefix(_) => {
                return Err(format!(
                    "{path:?}: a data: path must stay inside the data folder (relative, no ..)"
                ));
            }
        }
    }
    if names == 0 {
        return Err(format!(
            "{path:?}: a data: path needs a file name after data:"
        ));
    }
    Ok(data_dir.join(rel))
}

/// [`resolve_path`] with the scene's error types, and a missing `data:` file reported as
/// [`SceneFileError::DataNotFound`] (which says what to set) instead of a bare read error.
fn resolve_spec_path(
    path: &str,
    scene_file: &Path,
    base: &Path,
    data: &DataRoot,
    invalid: &dyn Fn(String) -> SceneFileError,
) -> Result<PathBuf, SceneFileError> {
    let resolved = resolve_path(path, base, &data.dir).map_err(invalid)?;
    if path.starts_with("data:") && !resolved.exists() {
        return Err(SceneFileError::DataNotFound {
            path: scene_file.into(),
            file: resolved,
            data_var: data.var.clone(),
        });
    }
    Ok(resolved)
}

fn load_volume(
    spec: &VolumeSpec,
    scene_file: &Path,
    base: &Path,
    data: &DataRoot,
    invalid: &dyn Fn(String) -> SceneFileError,
) -> Result<VolumeNode, SceneFileError> {
    let volume = if spec.path == "builtin:shoulder-phantom" {
        if spec.dims.is_some() || spec.scalar.is_some() || spec.orientation.is_some() {
            return Err(invalid(
                "builtin:shoulder-phantom is made in code: dims, scalar and orientation do not apply"
                    .into(),
            ));
        }
        let mut volume = shoulder_phantom_default();
        let marks = shoulder_landmarks(DEFAULT_DIMS, DEFAULT_SPACING);
        if spec.resect_humeral_head {
            resect_humeral_head(&mut volume, &marks);
        }
        if let Some(reach) = spec.cut_away_anterior_humerus {
            if !(reach.is_finite() && reach > 0.0) {
                return Err(invalid(format!(
                    "cut_away_anterior_humerus {reach} must be a positive number of millimetres"
                )));
            }
            cut_away_anterior_humerus(&mut volume, &marks, reach);
        }
        volume
    } else {
        if spec.cut_away_anterior_humerus.is_some() {
            // The cut is placed by the phantom's landmarks, which no other volume has.
            return Err(invalid(format!(
                "volume {}: cut_away_anterior_humerus applies to builtin:shoulder-phantom only",
                spec.path
            )));
        }
        let file = resolve_spec_path(&spec.path, scene_file, base, data, invalid)?;
        load_raw_volume(spec, &file, invalid)?
    };
    let mut transfer = match spec.transfer.as_deref().unwrap_or("auto") {
        "ramp" => {
            let [lo, hi] = spec.window.ok_or_else(|| {
                invalid("the ramp transfer function needs window = [lo, hi]".into())
            })?;
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(invalid(format!(
                    "window [{lo}, {hi}] must be two finite values, low below high"
                )));
            }
            TransferFunction::ramp(lo, hi, spec.color.unwrap_or([1.0, 0.93, 0.85, 0.6]))
        }
        other => {
            for (key, given) in [
                ("window", spec.window.is_some()),
                ("color", spec.color.is_some()),
            ] {
                if given {
                    return Err(invalid(format!(
                        "{key} applies to transfer = \"ramp\" only, not {other:?} (a preset is stretched with level_width and moved with shift)"
                    )));
                }
            }
            if other == "auto" {
                let auto = auto_transfer(&volume.values);
                eprintln!("{}: transfer function {}", spec.path, auto.reason);
                auto.transfer
            } else {
                TransferFunction::preset(other).ok_or_else(|| {
                    invalid(format!(
                        "unknown transfer function {other:?} (auto, ramp, {})",
                        TransferFunction::PRESETS.join(", ")
                    ))
                })?
            }
        }
    };
    if let Some([level, width]) = spec.level_width {
        transfer = transfer.windowed(level, width);
    }
    if let Some(shift) = spec.shift {
        transfer = transfer.shifted(shift);
    }
    if spec
        .opacity_reference_mm
        .is_some_and(|r| !(r.is_finite() && r > 0.0))
    {
        return Err(invalid("opacity_reference_mm must be positive".into()));
    }
    let min_opacity = spec.min_opacity.unwrap_or(1.0 / 255.0);
    if !(0.0..1.0).contains(&min_opacity) {
        return Err(invalid(format!(
            "min_opacity {min_opacity} is not in [0, 1)"
        )));
    }
    Ok(VolumeNode {
        volume: Arc::new(volume),
        transfer: Arc::new(transfer),
        splats: SplatSettings {
            min_opacity,
            opacity_reference_mm: spec.opacity_reference_mm.unwrap_or(1.0),
            shell: spec.shell.map(|v| v.clamp(0.0, 1.0)),
            shading: spec
                .shading
                .map_or(SplatSettings::default().shading, |v| v.clamp(0.0, 1.0)),
            ..Default::default()
        },
    })
}

/// The value of a volume key that names a choice, parsed.
fn parse_key<T: std::str::FromStr<Err = String>>(
    path: &Path,
    key: &str,
    value: &Option<String>,
) -> Result<Option<T>, String> {
    value
        .as_deref()
        .map(str::parse)
        .transpose()
        .map_err(|e| format!("volume {}: {key}: {e}", path.display()))
}

fn load_raw_volume(
    spec: &VolumeSpec,
    path: &Path,
    invalid: &dyn Fn(String) -> SceneFileError,
) -> Result<CpuVolume, SceneFileError> {
    let raw_keys = [
        ("dims", spec.dims.is_some()),
        ("scalar", spec.scalar.is_some()),
        ("header_bytes", spec.header_bytes.is_some()),
        ("spacing", spec.spacing.is_some()),
        ("origin", spec.origin.is_some()),
        ("orientation", spec.orientation.is_some()),
    ];
    let file_keys = [
        ("series", spec.series.is_some(), "DICOM"),
        ("skip_unreadable", spec.skip_unreadable.is_some(), "DICOM"),
        ("frame", spec.frame.is_some(), "4-D NIfTI"),
        ("nifti_transform", spec.nifti_transform.is_some(), "NIfTI"),
        (
            "coordinate_frame",
            spec.coordinate_frame.is_some(),
            "files whose format states no frame (a raw volume takes orientation)",
        ),
    ];
    if (spec.dims.is_some() || spec.scalar.is_some())
        && let Some((key, _, applies)) = file_keys.iter().find(|(_, given, _)| *given)
    {
        return Err(invalid(format!(
            "volume {}: {key} applies to {applies}, not to a raw volume",
            path.display()
        )));
    }
    if spec.dims.is_none() && spec.scalar.is_none() {
        // Not described as raw: a format with its own header (NRRD, NIfTI, VTK, Voreen .dat)
        // or a DICOM series folder, found from the first bytes and the name.
        let options = LoadOptions {
            series: spec.series.clone().map(SeriesChoice),
            skip_unreadable: spec.skip_unreadable.unwrap_or(false),
            frame: spec.frame,
            coordinate_frame: parse_key(path, "coordinate_frame", &spec.coordinate_frame)
                .map_err(invalid)?,
            nifti_transform: parse_key(path, "nifti_transform", &spec.nifti_transform)
                .map_err(invalid)?,
        };
        let loaded = match crate::volume::detect::load_volume_with(path, &options) {
            Err(VolumeError::NoHeader { .. }) if looks_like_scene_file(path) => {
                return Err(invalid(format!(
                    "volume {}: this is a scene file, not a volume; give it to render or view as the scene, or name the volume file it holds",
                    path.display()
                )));
            }
            Err(VolumeError::NoHeader { .. }) => {
                return Err(invalid(format!(
                    "volume {}: neither a volume format splatscene recognises nor a DICOM folder; a raw volume needs dims and scalar",
                    path.display()
                )));
            }
            other => other?,
        };
        let volume = loaded.volume;
        // The file's header places the grid; a raw key here would silently do nothing.
        if let Some((key, _)) = raw_keys.iter().find(|(_, given)| *given) {
            return Err(invalid(format!(
                "volume {}: {key} applies to raw volumes only; this file's header places its grid",
                path.display()
            )));
        }
        return Ok(volume);
    }
    let (Some(dims), Some(scalar)) = (spec.dims, &spec.scalar) else {
        return Err(invalid(format!(
            "volume {}: a raw volume needs dims and scalar",
            path.display()
        )));
    };
    let format: ScalarFormat = scalar
        .parse()
        .map_err(|e| invalid(format!("volume {}: {e}", path.display())))?;
    let orientation = match &spec.orientation {
        Some(code) => code
            .parse::<OrientationCode>()
            .map_err(|e| invalid(format!("volume {}: {e}", path.display())))?,
        None => OrientationCode::RAS,
    };
    let raw = RawSpec {
        header_bytes: spec.header_bytes.unwrap_or(0),
        spacing: spec.spacing.unwrap_or([1.0; 3]),
        origin: spec.origin.unwrap_or([0.0; 3]),
        ..RawSpec::new(dims, format.scalar, format.order)
    };
    let is_stack = path.extension().is_some_and(|e| e == "1");
    let mut volume = if is_stack {
        load_raw_slices(&slice_stack(path)?, &raw)?
    } else {
        load_raw(path, &raw)?
    };
    volume.direction = orientation.direction();
    Ok(volume)
}

/// The mesh files a scene file's load has read, by resolved path: their parts, with triangles
/// shared by every node drawn from them.
#[derive(Default)]
struct MeshFiles {
    models: std::collections::HashMap<PathBuf, Arc<SharedModel>>,
}

/// A mesh file's parts, its triangles behind shared pointers.
struct SharedModel {
    parts: Vec<crate::mesh::MeshPart>,
    meshes: Vec<Arc<crate::mesh::CpuMesh>>,
}

impl MeshFiles {
    /// The model of the file at `key` (a resolved path, or the built-in prosthesis's name),
    /// read by `load` the first time; its warnings are printed then.
    fn get(
        &mut self,
        key: PathBuf,
        load: impl FnOnce() -> Result<crate::mesh::Model, SceneFileError>,
    ) -> Result<Arc<SharedModel>, SceneFileError> {
        if let Some(model) = self.models.get(&key) {
            return Ok(Arc::clone(model));
        }
        let mut model = load()?;
        for warning in &model.warnings {
            eprintln!("warning: {warning}");
        }
        let meshes = model
            .parts
            .iter_mut()
            .map(|part| Arc::new(std::mem::take(&mut part.mesh)))
            .collect();
        let shared = Arc::new(SharedModel {
            parts: model.parts,
            meshes,
        });
        self.models.insert(key, Arc::clone(&shared));
        Ok(shared)
    }
}

fn load_mesh_spec(
    scene: &mut Scene,
    spec: &MeshSpec,
    index: usize,
    (scene_file, base, data): (&Path, &Path, &DataRoot),
    files: &mut MeshFiles,
    invalid: &dyn Fn(String) -> SceneFileError,
) -> Result<NodeId, SceneFileError> {
    let shared = if spec.path == "builtin:prosthesis" {
        files.get(spec.path.clone().into(), || Ok(prosthesis_model()?))?
    } else {
        let path = resolve_spec_path(&spec.path, scene_file, base, data, invalid)?;
        let key = std::fs::canonicalize(&path).unwrap_or_else(|_| path.clone());
        files.get(key, || Ok(load_mesh(&path)?))?
    };
    let mut model = crate::mesh::Model {
        parts: shared
            .parts
            .iter()
            .map(|p| crate::mesh::MeshPart {
                name: p.name.clone(),
                transform: p.transform,
                mesh: crate::mesh::CpuMesh::default(),
                material: p.material,
            })
            .collect(),
        warnings: Vec::new(),
    };
    for part in &mut model.parts {
        if let Some(c) = &spec.color {
            match c.as_slice() {
                [r, g, b] => part.material.base_color = [*r, *g, *b, 1.0],
                [r, g, b, a] => part.material.base_color = [*r, *g, *b, *a],
                _ => {
                    return Err(invalid(format!(
                        "mesh {}: color needs 3 or 4 numbers",
                        spec.path
                    )));
                }
            }
        }
        if let Some(r) = spec.roughness {
            part.material.roughness = r.clamp(0.0, 1.0);
        }
        if let Some(o) = spec.opacity {
            if !(o > 0.0 && o <= 1.0) {
                return Err(invalid(format!(
                    "mesh {}: opacity {o} must lie in (0, 1]",
                    spec.path
                )));
            }
            part.material.base_color[3] *= o;
        }
        if let Some(m) = spec.metallic {
            part.material.metallic = m.clamp(0.0, 1.0);
        }
    }
    let seat = match spec.seat.as_deref() {
        None => DMat4::IDENTITY,
        Some("phantom") => seat_in_phantom(&shoulder_landmarks(DEFAULT_DIMS, DEFAULT_SPACING)),
        Some(other) => return Err(invalid(format!("unknown seat {other:?} (phantom)"))),
    };
    let local = seat * transform(&spec.transform).map_err(invalid)? * file_frame(spec, invalid)?;
    let name = spec
        .name
        .clone()
        .unwrap_or_else(|| format!("mesh {}", index + 1));
    add_model(scene, &name, local, &model, Some(&shared.meshes))
        .ok_or_else(|| invalid(format!("mesh {name}: transform is singular")))
}

/// The clip planes and the crop box of a scene file, checked.
fn clipping(file: &SceneFile) -> Result<Clipping, String> {
    let mut clipping = Clipping::default();
    if file.clip.len() > MAX_CLIP_PLANES {
        return Err(format!(
            "{} clip planes: at most {MAX_CLIP_PLANES}",
            file.clip.len()
        ));
    }
    for (i, c) in file.clip.iter().enumerate() {
        let finite = c.through.iter().chain(&c.normal).all(|x| x.is_finite());
        let normal = DVec3::from(c.normal);
        if !finite || normal.length() == 0.0 {
            return Err(format!(
                "clip {}: through and normal must be finite, the normal not zero",
                i + 1
            ));
        }
        clipping
            .planes
            .push(ClipPlane::through(DVec3::from(c.through), normal, c.meshes));
    }
    let mut boxes = file
        .volumes
        .iter()
        .enumerate()
        .filter_map(|(i, v)| v.crop_box.map(|b| (i, b, v.clip_meshes)));
    if let Some((i, b, meshes)) = boxes.next() {
        if let Some((j, ..)) = boxes.next() {
            return Err(format!(
                "volumes {} and {} both have a crop_box: a scene has one",
                i + 1,
                j + 1
            ));
        }
        let (lo, hi) = (DVec3::from(b.min), DVec3::from(b.max));
        if !(lo.is_finite() && hi.is_finite() && lo.cmplt(hi).all()) {
            return Err(format!(
                "volume {}: crop_box min {:?} must lie below max {:?} on every axis",
                i + 1,
                b.min,
                b.max
            ));
        }
        clipping.crop = Some((lo, hi));
        clipping.crop_meshes = meshes.unwrap_or(false);
    }
    if let Some((i, v)) = file
        .volumes
        .iter()
        .enumerate()
        .find(|(_, v)| v.clip_meshes.is_some() && v.crop_box.is_none())
    {
        return Err(format!(
            "volume {} ({}): clip_meshes has no effect without a crop_box",
            i + 1,
            v.path
        ));
    }
    Ok(clipping)
}

/// Longest measurement label, in characters.
const MAX_LABEL: usize = 200;

/// A scene file's measurement, checked against the scene loaded so far.
fn measurement(
    scene: &Scene,
    spec: &MeasurementSpec,
    index: usize,
) -> Result<SceneMeasurement, String> {
    let name = match &spec.label {
        Some(l) => format!("measurement {} ({:?})", index + 1, shortened(l)),
        None => format!("measurement {}", index + 1),
    };
    if let Some(label) = &spec.label
        && (label.trim().is_empty()
            || label.chars().count() > MAX_LABEL
            || label.chars().any(char::is_control))
    {
        return Err(format!(
            "{name}: label must be 1 to {MAX_LABEL} characters of text on one line"
        ));
    }
    let node = match &spec.node {
        None => None,
        Some(n) if named_apart(scene, n) > 1 => {
            return Err(format!(
                "{name}: node {:?} names {} meshes or volumes of the scene, so the measurement cannot tell which one it follows; give each its own `name`",
                shortened(n),
                named_apart(scene, n)
            ));
        }
        Some(n) => Some(scene.find(n).ok_or_else(|| {
            let names: Vec<&str> = scene
                .nodes()
                .iter()
                .filter(|node| node.parent().is_none())
                .map(|node| node.name.as_str())
                .collect();
            format!(
                "{name}: node {:?} is not in the scene (its top nodes: {})",
                shortened(n),
                names.join(", ")
            )
        })?),
    };
    let m = SceneMeasurement {
        kind: spec.kind,
        points: spec.points.iter().map(|p| DVec3::from(*p)).collect(),
        node,
        label: spec.label.clone(),
    };
    scene
        .measure(&m)
        .map_err(|e| format!("{name}: points: {e}"))?;
    Ok(m)
}

/// Warnings for meshes whose size is under 1/100 or over 100 times the largest volume's: most
/// likely a file in other units than the scene (an STL in metres in a millimetre CT).
pub fn scale_warnings(scene: &Scene, meshes: &[(String, NodeId)]) -> Vec<String> {
    let size = |(lo, hi): (DVec3, DVec3)| (hi - lo).length();
    let volume = scene
        .volumes()
        .filter_map(|(id, ..)| scene.subtree_bounds(id).map(size))
        .fold(0.0, f64::max);
    if volume <= 0.0 {
        return Vec::new();
    }
    meshes
        .iter()
        .filter_map(|(name, id)| {
            let mesh = size(scene.subtree_bounds(*id)?);
            let ratio = mesh / volume;
            let hint = if ratio < 0.01 {
                "units = \"m\" or \"cm\" if the file is in metres or centimetres"
            } else if ratio > 100.0 {
                "units = \"mm\" with a scale, or check the file's units"
            } else {
                return None;
            };
            Some(format!(
                "mesh {name:?} is {mesh:.3} mm across, {ratio:.2e} times the volume ({volume:.1} mm); set {hint}"
            ))
        })
        .collect()
}

/// Whether a file that is no volume is a scene file: named `.toml`, or text whose first line
/// that is neither blank nor a comment opens a TOML table.
fn looks_like_scene_file(path: &Path) -> bool {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("toml"))
    {
        return true;
    }
    let mut head = Vec::new();
    let read = crate::input::open_regular(path).and_then(|f| {
        use std::io::Read;
        f.take(4096).read_to_end(&mut head)
    });
    read.is_ok()
        && std::str::from_utf8(&head).is_ok_and(|text| {
            text.lines()
                .map(str::trim)
                .find(|l| !l.is_empty() && !l.starts_with('#'))
                .is_some_and(|l| l.starts_with('['))
        })
}

/// The mesh file's coordinates to scene millimetres in RAS: its `units` scaled, its `frame`
/// turned.
fn file_frame(
    spec: &MeshSpec,
    invalid: &dyn Fn(String) -> SceneFileError,
) -> Result<DMat4, SceneFileError> {
    let scale = match spec.units.as_deref() {
        None | Some("mm") => 1.0,
        Some("cm") => 10.0,
        Some("m") => 1000.0,
        Some(other) => {
            return Err(invalid(format!(
                "mesh {}: units {other:?} is not mm, cm or m",
                spec.path
            )));
        }
    };
    let turn = match spec
        .frame
        .as_deref()
        .map(str::to_ascii_uppercase)
        .as_deref()
    {
        None | Some("RAS") => DVec3::ONE,
        // LPS to RAS: x and y change sign.
        Some("LPS") => DVec3::new(-1.0, -1.0, 1.0),
        Some(_) => {
            return Err(invalid(format!(
                "mesh {}: frame {:?} is not RAS or LPS",
                spec.path,
                spec.frame.as_deref().unwrap_or_default()
            )));
        }
    };
    Ok(DMat4::from_scale(turn * scale))
}

fn transform(spec: &TransformSpec) -> Result<DMat4, String> {
    let m = match spec.matrix {
        Some(mut cols) => {
            // The last row was checked to be 0, 0, 0, 1 within rounding: made exact.
            [cols[3], cols[7], cols[11], cols[15]] = [0.0, 0.0, 0.0, 1.0];
            DMat4::from_cols_array(&cols)
        }
        None => {
            let [rx, ry, rz] = spec.rotate_degrees.unwrap_or([0.0; 3]).map(f64::to_radians);
            DMat4::from_scale_rotation_translation(
                DVec3::from(spec.scale.unwrap_or([1.0; 3])),
                DQuat::from_euler(EulerRot::ZYX, rz, ry, rx),
                DVec3::from(spec.translate.unwrap_or([0.0; 3])),
            )
        }
    };
    if !m.is_finite() || !m.determinant().is_normal() {
        return Err("transform: its matrix is not finite and invertible".into());
    }
    Ok(m)
}

fn lights(spec: &LightsSpec) -> Lights {
    let mut lights = Lights::default();
    if let Some(h) = spec.headlight {
        lights.headlight = h.max(0.0);
    }
    if let Some(a) = spec.ambient {
        lights.ambient = a.max(0.0);
    }
    if let Some(list) = &spec.directional {
        lights.directional = list
            .iter()
            .map(|l| Light {
                direction: DVec3::from(l.direction),
                color: l.color,
            })
            .collect();
    }
    lights
}

/// The camera a scene file's `[camera]` table describes for `scene`, fitted to it where the
/// table gives no eye; `aspect` is the image's width over its height.
///
/// # Errors
///
/// A message naming the key whose value cannot make a camera.
pub fn camera(
    spec: Option<&CameraSpec>,
    scene: &Scene,
    aspect: f64,
) -> Result<SceneCamera, String> {
    let default = CameraSpec::default();
    let spec = spec.unwrap_or(&default);
    let bounds = scene.bounds().unwrap_or((DVec3::splat(-1.0), DVec3::ONE));
    let projection = match (spec.orthographic_height, spec.fov) {
        (Some(height), _) if height.is_finite() && height > 0.0 => {
            Projection::Orthographic { height }
        }
        (Some(height), _) => return Err(format!("orthographic_height {height} must be positive")),
        (None, Some(fov)) if fov > 0.0 && fov < 180.0 => {
            Projection::Perspective { fov_y_degrees: fov }
        }
        (None, Some(fov)) => return Err(format!("fov {fov} is not between 0 and 180 degrees")),
        (None, None) => Projection::default(),
    };
    let given = |v: Option<[f64; 3]>, key: &str| -> Result<Option<DVec3>, String> {
        match v.map(DVec3::from) {
            Some(p) if !p.is_finite() => Err(format!("camera.{key} {p} is not finite")),
            other => Ok(other),
        }
    };
    let (eye, target, up) = (
        given(spec.eye, "eye")?,
        given(spec.target, "target")?,
        given(spec.up, "up")?,
    );
    if up.is_some_and(|u| u.length() == 0.0) {
        return Err("camera.up [0, 0, 0] has no direction".into());
    }
    let mut camera = match (&spec.view, eye, spec.view_from) {
        (Some(_), Some(_), _) | (Some(_), _, Some(_)) => {
            return Err("camera.view names a view: give it without eye or view_from".into());
        }
        (Some(name), None, None) => {
            let view = NamedView::parse(name).map_err(|e| format!("camera.view: {e}"))?;
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
                return Err(format!("camera.view_from {direction} has no direction"));
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
    camera.pinhole(16, 16, 0.0).map_err(|e| e.to_string())?;
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

/// A camera for a named view of the scene's patient, fitted to the scene.
pub fn named_view_camera(
    scene: &Scene,
    view: &NamedView,
    projection: Projection,
    aspect: f64,
) -> SceneCamera {
    let bounds = scene.bounds().unwrap_or((DVec3::splat(-1.0), DVec3::ONE));
    let frame = scene.patient_frame();
    let mut camera = SceneCamera::fit(bounds, -frame.world(view.from), projection, aspect);
    camera.up = frame.world(view.up);
    camera
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::NodeId;
    use crate::scene::shoulder::shoulder_scene;

    /// A fresh folder for one test's files, removed when dropped.
    struct TempDir(PathBuf);

    impl TempDir {
        fn new(name: &str) -> Self {
            let dir = std::env::temp_dir().join(format!(
                "splatscene-scene-file-{}-{name}",
                std::process::id()
            ));
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir).expect("create a temporary folder");
            Self(dir)
        }

        fn write(&self, name: &str, text: &str) -> PathBuf {
            let path = self.0.join(name);
            std::fs::write(&path, text).expect("write a temporary file");
            path
        }
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    fn manifest_path(rel: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
    }

    #[test]
    fn data_paths_resolve_inside_the_data_folder() {
        let base = Path::new("/scenes");
        let data = Path::new("/mnt/data");
        assert_eq!(
            resolve_path("data:volumes/lidc2/ct.raw", base, data).unwrap(),
            Path::new("/mnt/data/volumes/lidc2/ct.raw")
        );
        assert_eq!(
            resolve_path("data:./meshes/bone.stl", base, data).unwrap(),
            Path::new("/mnt/data/meshes/bone.stl")
        );
        // Paths without the prefix keep their old meaning.
        assert_eq!(
            resolve_path("meshes/bone.stl", base, data).unwrap(),
            Path::new("/scenes/meshes/bone.stl")
        );
        assert_eq!(
            resolve_path("/abs/bone.stl", base, data).unwrap(),
            Path::new("/abs/bone.stl")
        );
        for bad in [
            "data:",
            "data:.",
            "data:../secret",
            "data:a/../../b",
            "data:/etc/passwd",
        ] {
            let message = resolve_path(bad, base, data).unwrap_err();
            assert!(message.contains(bad), "{bad}: {message}");
        }
    }

    #[test]
    fn the_data_folder_comes_from_the_variable_or_the_default() {
        let default = Path::new(DEFAULT_DATA_DIR);
        assert_eq!(data_dir_from(None), default);
        assert_eq!(data_dir_from(Some(OsStr::new(""))), default);
        assert_eq!(
            data_dir_from(Some(OsStr::new("/srv/data"))),
            Path::new("/srv/data")
        );
        assert_eq!(
            data_dir(),
            data_dir_from(std::env::var_os(DATA_ENV).as_deref())
        );
    }

    #[test]
    fn a_data_volume_loads_through_the_data_folder() {
        let rel = "volumes/datraw_small/Bucky_32x32x32_uint8.raw";
        if !data_dir().join(rel).exists() {
            assert!(
                std::env::var_os("CI").is_none(),
                "{} has no {rel} under CI: set {DATA_ENV}",
                data_dir().display()
            );
            eprintln!(
                "skipped: {} has no {rel} (set {DATA_ENV})",
                data_dir().display()
            );
            return;
        }
        let dir = TempDir::new("data-volume");
        let path = dir.write(
            "bucky.toml",
            &format!(
                "[[volume]]\npath = \"data:{rel}\"\ndims = [32, 32, 32]\nscalar = \"u8\"\n\
                 transfer = \"ramp\"\nwindow = [40, 200]\n"
            ),
        );
        let loaded = load_scene_file(&path).unwrap();
        let (_, node, _) = loaded.scene.volumes().next().unwrap();
        assert_eq!(node.volume.dims, [32, 32, 32]);
    }

    #[test]
    fn a_missing_data_file_says_what_to_set() {
        let dir = TempDir::new("missing-data");
        let path = dir.write("scene.toml", "[[mesh]]\npath = \"data:no/such/bone.stl\"\n");
        let err = load_scene_file(&path).unwrap_err();
        let SceneFileError::DataNotFound { file, .. } = &err else {
            panic!("expected DataNotFound, got {err:?}");
        };
        assert!(file.ends_with("no/such/bone.stl"), "{}", file.display());
        let message = err.to_string();
        assert!(message.contains(DATA_ENV), "{message}");
        assert!(message.contains("scene.toml"), "{message}");
    }

    #[test]
    fn measurements_load_with_their_node_and_bad_ones_name_the_key() {
        let dir = TempDir::new("measurements");
        let scene = |measurement: &str| {
            format!(
                "[[mesh]]\nname = \"stem\"\npath = \"builtin:prosthesis\"\ntransform = {{ translate = [10, 0, 0] }}\n{measurement}"
            )
        };
        let good = dir.write(
            "good.toml",
            &scene(
                "[[measurement]]\nkind = \"line-angle\"\nlabel = \"neck-shaft angle\"\nnode = \"stem\"\npoints = [[0, 0, 0], [0, 0, -40], [0, 0, 0], [-7, 0, 7]]\n\n[[measurement]]\nkind = \"distance\"\npoints = [[0, 0, 0], [3, 4, 0]]\n\n[[measurement]]\nkind = \"point\"\nnode = \"stem\"\npoints = [[1, 2, 3]]\n",
            ),
        );
        let loaded = load_scene_file(&good).unwrap();
        let s = &loaded.scene;
        assert_eq!(s.measurements.len(), 3);
        let angle = s.measure(&s.measurements[0]).unwrap();
        assert!((angle.value.unwrap() - 135.0).abs() < 1e-9, "{angle:?}");
        assert_eq!(s.measure(&s.measurements[1]).unwrap().value, Some(5.0));
        // Points given in a node's frame move with it.
        let point = s.measure(&s.measurements[2]).unwrap();
        assert_eq!(point.points, vec![[11.0, 2.0, 3.0]]);
        // The file written back keeps them.
        let file = SceneFile::read(&good).unwrap();
        let again = SceneFile::parse(&file.to_toml().unwrap(), &good).unwrap();
        assert_eq!(again.measurements.len(), 3);

        for (text, expected) in [
            (
                "[[measurement]]\nkind = \"angle\"\npoints = [[0, 0, 0], [1, 0, 0]]\n",
                "measurement 1: points: an angle takes 3 points, not 2",
            ),
            (
                "[[measurement]]\nkind = \"diameter\"\npoints = [[0, 0, 0]]\n",
                "unknown variant `diameter`",
            ),
            (
                "[[measurement]]\nkind = \"distance\"\npoints = [[nan, 0, 0], [1, 0, 0]]\n",
                "not finite",
            ),
            (
                "[[measurement]]\nkind = \"point\"\nlabel = 7\npoints = [[0, 0, 0]]\n",
                "label",
            ),
            (
                "[[measurement]]\nkind = \"point\"\nnode = \"humerus\"\npoints = [[0, 0, 0]]\n",
                "node \"humerus\" is not in the scene (its top nodes: stem)",
            ),
            (
                "[[measurement]]\nkind = \"point\"\nlabel = \"  \"\npoints = [[0, 0, 0]]\n",
                "label must be",
            ),
            (
                "[[measurement]]\nkind = \"point\"\npoints = [[0, 0]]\n",
                "measurement",
            ),
        ] {
            let path = dir.write("bad.toml", &scene(text));
            let e = load_scene_file(&path).unwrap_err().to_string();
            assert!(e.contains(expected), "{text}: {e}");
            assert!(e.contains("bad.toml"), "{e}");
        }
    }

    #[test]
    fn a_plan_saved_from_a_scene_loads_to_the_same_placement() {
        let dir = TempDir::new("plan");
        let path = dir.write(
            "plan.toml",
            "[[mesh]]\nname = \"implant\"\npath = \"builtin:prosthesis\"\nseat = \"phantom\"\nunits = \"cm\"\nframe = \"LPS\"\ntransform = { rotate_degrees = [0, 10, 0] }\n\n[[mesh]]\nname = \"second\"\npath = \"builtin:prosthesis\"\n\n[[measurement]]\nkind = \"point\"\nlabel = \"head centre\"\nnode = \"implant\"\npoints = [[1, 2, 3]]\n",
        );
        let file = SceneFile::read(&path).unwrap();
        let mut scene = file.load(&path, dir.0.as_path()).unwrap().scene;
        let implant = scene.find("implant").unwrap();
        let moved = DMat4::from_translation(DVec3::new(5.0, -3.0, 2.0))
            * scene.node(implant).unwrap().local();
        scene.set_local(implant, moved).unwrap();
        scene.measurements.push(SceneMeasurement {
            kind: MeasureKind::Distance,
            points: vec![DVec3::ZERO, DVec3::X],
            node: None,
            label: Some("gap".into()),
        });
        let saved = file.with_plan(&scene).unwrap();
        let text = saved.to_toml().unwrap();
        let again = dir.write("again.toml", &text);
        let reloaded = load_scene_file(&again).unwrap().scene;
        let id = reloaded.find("implant").unwrap();
        let a = reloaded.node(id).unwrap().local().to_cols_array();
        for (x, y) in a.iter().zip(moved.to_cols_array()) {
            assert!((x - y).abs() < 1e-9, "{a:?} against {moved:?}");
        }
        let second = reloaded.find("second").unwrap();
        assert_eq!(reloaded.node(second).unwrap().local(), DMat4::IDENTITY);
        assert_eq!(reloaded.measurements.len(), 2);
        let landmark = reloaded.measure(&reloaded.measurements[0]).unwrap();
        let before = scene.measure(&scene.measurements[0]).unwrap();
        for (p, q) in landmark.points[0].iter().zip(before.points[0]) {
            assert!((p - q).abs() < 1e-9, "the landmark moved with its mesh");
        }
        assert_eq!(reloaded.measurements[1].label.as_deref(), Some("gap"));
    }

    #[test]
    fn clip_planes_and_the_crop_box_load_check_and_save() {
        let dir = TempDir::new("clipping");
        let volume = "[[volume]]\npath = \"builtin:shoulder-phantom\"\n";
        let path = dir.write(
            "clip.toml",
            &format!(
                "{volume}crop_box = {{ min = [0, 0, 0], max = [60, 50, 40] }}\nclip_meshes = true\n\n[[clip]]\nthrough = [0, 20, 0]\nnormal = [0, 2, 0]\nmeshes = true\n"
            ),
        );
        let file = SceneFile::read(&path).unwrap();
        let scene = file.load(&path, dir.0.as_path()).unwrap().scene;
        let c = &scene.clipping;
        assert_eq!(c.crop, Some((DVec3::ZERO, DVec3::new(60.0, 50.0, 40.0))));
        assert!(c.crop_meshes);
        assert_eq!(c.planes.len(), 1);
        assert!(c.planes[0].keeps(DVec3::new(5.0, 19.0, 5.0)));
        assert!(!c.planes[0].keeps(DVec3::new(5.0, 21.0, 5.0)));
        // Saved and read again: the same clipping.
        let again = dir.write(
            "again.toml",
            &file.with_plan(&scene).unwrap().to_toml().unwrap(),
        );
        let reloaded = load_scene_file(&again).unwrap().scene;
        assert_eq!(reloaded.clipping, scene.clipping);

        for (text, expected) in [
            (
                format!("{volume}crop_box = {{ min = [0, 0, 0], max = [60, 0, 40] }}\n"),
                "must lie below max",
            ),
            (
                format!("{volume}clip_meshes = true\n"),
                "no effect without a crop_box",
            ),
            (
                format!("{volume}\n[[clip]]\nthrough = [0, 0, 0]\nnormal = [0, 0, 0]\n"),
                "the normal not zero",
            ),
            (
                format!(
                    "{volume}crop_box = {{ min = [0, 0, 0], max = [1, 1, 1] }}\n{volume}crop_box = {{ min = [0, 0, 0], max = [1, 1, 1] }}\n"
                ),
                "both have a crop_box",
            ),
            (
                format!("{volume}\n[[clip]]\nthrough = [0, 0, 0]\nnormal = [0, 0, 1]\nside = 2\n"),
                "side",
            ),
        ] {
            let path = dir.write("bad.toml", &text);
            let e = load_scene_file(&path).unwrap_err().to_string();
            assert!(e.contains(expected), "{text}: {e}");
        }
    }

    #[test]
    fn an_unknown_field_is_a_parse_error_naming_file_and_field() {
        let dir = TempDir::new("unknown-field");
        let path = dir.write(
            "typo.toml",
            "[[volume]]\npath = \"builtin:shoulder-phantom\"\ntransfer_function = \"ct-bone\"\n",
        );
        let err = SceneFile::read(&path).unwrap_err();
        assert!(matches!(err, SceneFileError::Parse { .. }), "{err:?}");
        let message = err.to_string();
        assert!(message.contains("typo.toml"), "{message}");
        assert!(message.contains("transfer_function"), "{message}");
    }

    #[test]
    fn a_missing_mesh_file_is_a_typed_error_naming_the_path() {
        let dir = TempDir::new("missing-mesh");
        let path = dir.write("scene.toml", "[[mesh]]\npath = \"implants/stem.stl\"\n");
        let err = load_scene_file(&path).unwrap_err();
        let SceneFileError::Mesh(MeshError::Io { file, .. }) = &err else {
            panic!("expected a mesh read error, got {err:?}");
        };
        assert_eq!(file, &dir.0.join("implants/stem.stl"));
        assert!(err.to_string().contains("stem.stl"), "{err}");
    }

    #[test]
    fn a_bad_ordering_is_named() {
        let err = SceneFile::parse("[output]\nordering = \"zigzag\"\n", Path::new("o.toml"))
            .unwrap()
            .load(Path::new("o.toml"), Path::new("."))
            .unwrap_err();
        assert!(matches!(err, SceneFileError::Invalid { .. }), "{err:?}");
        let message = err.to_string();
        assert!(message.contains("zigzag"), "{message}");
        assert!(message.contains("o.toml"), "{message}");
    }

    #[test]
    fn transfer_presets_windows_shifts_and_opacity_reference() {
        let load = |extra: &str| {
            let text = format!("[[volume]]\npath = \"builtin:shoulder-phantom\"\n{extra}");
            SceneFile::parse(&text, Path::new("tf.toml"))
                .unwrap()
                .load(Path::new("tf.toml"), Path::new("."))
        };
        let loaded = load("transfer = \"ct-metal\"\nlevel_width = [1500, 2000]\nshift = 100\nopacity_reference_mm = 1.0\nshading = 0.0\n").unwrap();
        let (_, node, _) = loaded.scene.volumes().next().unwrap();
        let expected = TransferFunction::ct_metal()
            .windowed(1500.0, 2000.0)
            .shifted(100.0);
        assert_eq!(*node.transfer, expected);
        assert_eq!(node.splats.opacity_reference_mm, 1.0);
        assert_eq!(node.splats.shading, 0.0);
        let err = load("transfer = \"ct-lung\"\n").unwrap_err().to_string();
        assert!(
            err.contains("ct-lung") && err.contains("ct-soft-tissue"),
            "{err}"
        );
        assert!(load("opacity_reference_mm = -1\n").is_err());
    }

    #[test]
    fn a_raw_volume_without_dims_is_invalid() {
        // The file does not exist: the missing dims must be reported before any read.
        let err = SceneFile::parse(
            "[[volume]]\npath = \"ct.raw\"\nscalar = \"u8\"\n",
            Path::new("raw.toml"),
        )
        .unwrap()
        .load(Path::new("raw.toml"), Path::new("."))
        .unwrap_err();
        assert!(matches!(err, SceneFileError::Invalid { .. }), "{err:?}");
        assert!(err.to_string().contains("dims"), "{err}");
    }

    #[test]
    fn a_scene_file_over_the_limit_is_refused() {
        let dir = TempDir::new("large");
        let comment = format!("#{}\n", "x".repeat(MAX_SCENE_BYTES as usize));
        let path = dir.write("large.toml", &comment);
        let err = SceneFile::read(&path).unwrap_err();
        assert!(matches!(err, SceneFileError::Invalid { .. }), "{err:?}");
        assert!(err.to_string().contains("too large"), "{err}");
        // Exactly at the limit a file is read (an empty scene, all comment).
        let at_limit = MAX_SCENE_BYTES as usize - 2;
        let path = dir.write("limit.toml", &format!("#{}\n", "x".repeat(at_limit)));
        assert_eq!(std::fs::metadata(&path).unwrap().len(), MAX_SCENE_BYTES);
        // `is_ok` rather than `unwrap`: a failure would print a mebibyte of parser context.
        assert!(SceneFile::read(&path).is_ok());
    }

    #[test]
    fn the_anterior_cutaway_applies_to_the_phantom_only() {
        let load = |text: &str| {
            SceneFile::parse(text, Path::new("c.toml"))
                .unwrap()
                .load(Path::new("c.toml"), Path::new("."))
        };
        let err = load(
            "[[volume]]\npath = \"ct.raw\"\ndims = [2, 2, 2]\nscalar = \"u8\"\ncut_away_anterior_humerus = 30.0\n",
        )
        .unwrap_err();
        assert!(
            err.to_string().contains("builtin:shoulder-phantom"),
            "{err}"
        );
        let err = load(
            "[[volume]]\npath = \"builtin:shoulder-phantom\"\ncut_away_anterior_humerus = -1.0\n",
        )
        .unwrap_err();
        assert!(err.to_string().contains("positive"), "{err}");
    }

    #[test]
    fn the_shoulder_example_is_the_built_in_scene() {
        let loaded = load_scene_file(&manifest_path("examples/scenes/shoulder.toml")).unwrap();
        let built_in = shoulder_scene().unwrap();
        let (file, code) = (&loaded.scene, &built_in);
        assert_eq!(loaded.size, Some((800, 600)));
        assert_eq!(file.nodes().len(), code.nodes().len());
        for (i, (a, b)) in file.nodes().iter().zip(code.nodes()).enumerate() {
            assert_eq!(a.name, b.name);
            let (wa, wb) = (file.world(NodeId(i)), code.world(NodeId(i)));
            assert!(wa.abs_diff_eq(wb, 1e-9), "{}: {wa} vs {wb}", a.name);
        }
        let (_, va, _) = file.volumes().next().unwrap();
        let (_, vb, _) = code.volumes().next().unwrap();
        assert!(*va.volume == *vb.volume, "the volumes differ");
        assert_eq!(va.transfer, vb.transfer);
        assert_eq!(va.splats, vb.splats);
        let (ca, cb) = (file.camera.unwrap(), code.camera.unwrap());
        assert!(ca.eye.abs_diff_eq(cb.eye, 1e-9), "{ca:?} vs {cb:?}");
        assert!(ca.target.abs_diff_eq(cb.target, 1e-9));
        assert_eq!(ca.up, cb.up);
        assert_eq!(ca.projection, cb.projection);
        assert_eq!(file.lights, code.lights);
    }

    #[test]
    fn rotate_degrees_turn_about_x_then_y_then_z_and_matrices_are_column_major() {
        let spec = TransformSpec {
            rotate_degrees: Some([90.0, 90.0, 0.0]),
            ..TransformSpec::default()
        };
        // +y turned 90 degrees about x is +z; +z turned 90 degrees about y is +x.
        let m = transform(&spec).unwrap();
        assert!(m.transform_vector3(DVec3::Y).abs_diff_eq(DVec3::X, 1e-12));
        let mut cols = [0.0; 16];
        cols[0] = 1.0;
        cols[6] = 1.0; // y goes to z
        cols[9] = -1.0; // z goes to -y
        cols[12..16].copy_from_slice(&[5.0, 6.0, 7.0, 1.0]);
        let spec = TransformSpec {
            matrix: Some(cols),
            ..TransformSpec::default()
        };
        let m = transform(&spec).unwrap();
        assert_eq!(m.transform_point3(DVec3::Y), DVec3::new(5.0, 6.0, 8.0));
    }

    #[test]
    fn mesh_units_and_frames_apply_before_the_transform() {
        let dir = TempDir::new("mesh-units");
        let plain = dir.write("plain.toml", "[[mesh]]\npath = \"builtin:prosthesis\"\n");
        let turned = dir.write(
            "turned.toml",
            "[[mesh]]\npath = \"builtin:prosthesis\"\nunits = \"cm\"\nframe = \"LPS\"\n\
             transform = { translate = [1, 2, 3] }\n",
        );
        let (lo, hi) = load_scene_file(&plain).unwrap().scene.bounds().unwrap();
        let (tlo, thi) = load_scene_file(&turned).unwrap().scene.bounds().unwrap();
        // Ten times larger, x and y mirrored through the origin (LPS to RAS), then moved.
        let expected_lo =
            DVec3::new(-10.0 * hi.x, -10.0 * hi.y, 10.0 * lo.z) + DVec3::new(1.0, 2.0, 3.0);
        let expected_hi =
            DVec3::new(-10.0 * lo.x, -10.0 * lo.y, 10.0 * hi.z) + DVec3::new(1.0, 2.0, 3.0);
        assert!(tlo.abs_diff_eq(expected_lo, 1e-3), "{tlo} vs {expected_lo}");
        assert!(thi.abs_diff_eq(expected_hi, 1e-3), "{thi} vs {expected_hi}");
        let bad = dir.write(
            "bad.toml",
            "[[mesh]]\npath = \"builtin:prosthesis\"\nunits = \"in\"\n",
        );
        let message = load_scene_file(&bad).unwrap_err().to_string();
        assert!(
            message.contains("\"in\"") && message.contains("mm, cm or m"),
            "{message}"
        );
    }

    #[test]
    fn raw_volumes_take_an_orientation_and_header_files_refuse_raw_keys() {
        let dir = TempDir::new("orientation");
        std::fs::write(dir.0.join("v.raw"), [0u8; 24]).unwrap();
        let scene = |extra: &str| {
            dir.write(
                "v.toml",
                &format!(
                    "[[volume]]\npath = \"v.raw\"\ndims = [2, 3, 4]\nscalar = \"u8\"\n\
                     transfer = \"ramp\"\nwindow = [1, 2]\n{extra}"
                ),
            )
        };
        let loaded = load_scene_file(&scene("orientation = \"LPI\"\n")).unwrap();
        let (_, node, _) = loaded.scene.volumes().next().unwrap();
        assert_eq!(
            node.volume.direction,
            glam::DMat3::from_diagonal(DVec3::splat(-1.0))
        );
        // The patient's superior is still world +z: the scene's up does not follow the grid.
        assert_eq!(loaded.scene.up_axis(), DVec3::Z);
        let message = load_scene_file(&scene("orientation = \"LPP\"\n"))
            .unwrap_err()
            .to_string();
        assert!(
            message.contains("LPP") && message.contains("R/L"),
            "{message}"
        );
        let message = load_scene_file(&scene("color = [1, 1, 1, 1]\ntransfer = \"ct-bone\"\n"));
        assert!(message.is_err(), "a key given twice");
        let phantom = dir.write(
            "p.toml",
            "[[volume]]\npath = \"builtin:shoulder-phantom\"\norientation = \"LPS\"\n",
        );
        let message = load_scene_file(&phantom).unwrap_err().to_string();
        assert!(message.contains("orientation"), "{message}");
        let preset = dir.write(
            "w.toml",
            "[[volume]]\npath = \"builtin:shoulder-phantom\"\ntransfer = \"ct-bone\"\nwindow = [1, 2]\n",
        );
        let message = load_scene_file(&preset).unwrap_err().to_string();
        assert!(
            message.contains("window applies to transfer = \"ramp\""),
            "{message}"
        );
    }

    #[test]
    fn a_scene_file_given_as_a_volume_is_named_as_one() {
        let dir = TempDir::new("scene-as-volume");
        dir.write("inner.txt", "# a plan\n\n[camera]\nfov = 30\n");
        let path = dir.write("outer.toml", "[[volume]]\npath = \"inner.txt\"\n");
        let message = load_scene_file(&path).unwrap_err().to_string();
        assert!(
            message.contains("inner.txt") && message.contains("scene file, not a volume"),
            "{message}"
        );
    }

    #[test]
    fn a_named_view_in_a_scene_file_looks_from_that_side() {
        let dir = TempDir::new("named-view");
        let path = dir.write(
            "v.toml",
            "[camera]\nview = \"superior\"\n\n[[volume]]\npath = \"builtin:shoulder-phantom\"\n",
        );
        let camera = load_scene_file(&path).unwrap().scene.camera.unwrap();
        let forward = (camera.target - camera.eye).normalize();
        assert!(forward.abs_diff_eq(DVec3::NEG_Z, 1e-9), "{forward}");
        assert!(
            camera.up.abs_diff_eq(DVec3::Y, 1e-9),
            "anterior at the top: {}",
            camera.up
        );
        let both = dir.write(
            "both.toml",
            "[camera]\nview = \"left\"\neye = [0, 0, 100]\n\n[[volume]]\npath = \"builtin:shoulder-phantom\"\n",
        );
        let message = load_scene_file(&both).unwrap_err().to_string();
        assert!(message.contains("camera.view"), "{message}");
        let unknown = dir.write("u.toml", "[camera]\nview = \"sideways\"\n");
        let message = load_scene_file(&unknown).unwrap_err().to_string();
        assert!(
            message.contains("sideways") && message.contains("anterior"),
            "{message}"
        );
    }

    #[test]
    fn a_saved_view_loads_back_to_the_same_camera() {
        let dir = TempDir::new("saved-view");
        let path = dir.write(
            "s.toml",
            "[camera]\nview_from = [0.2, -1.0, -0.3]\n\n[[volume]]\npath = \"builtin:shoulder-phantom\"\n",
        );
        let loaded = load_scene_file(&path).unwrap();
        let camera = loaded
            .scene
            .camera
            .unwrap()
            .orbit_about(loaded.scene.up_axis(), 40.0, 20.0);
        let mut file = SceneFile::read(&path).unwrap().with_paths_from(&dir.0);
        file.camera = Some(CameraSpec::from_camera(&camera, loaded.scene.up_axis()));
        let saved = dir.write("saved.toml", &file.to_toml().unwrap());
        let again = load_scene_file(&saved).unwrap().scene.camera.unwrap();
        assert!(
            again.eye.abs_diff_eq(camera.eye, 1e-9)
                && again.target.abs_diff_eq(camera.target, 1e-9)
        );
        let (a, b) = (
            camera.pinhole(64, 64, 0.0).unwrap().frame().unwrap(),
            again.pinhole(64, 64, 0.0).unwrap().frame().unwrap(),
        );
        assert!(a.up.abs_diff_eq(b.up, 1e-9) && a.right.abs_diff_eq(b.right, 1e-9));
    }

    #[test]
    fn the_overlay_example_parses_and_loads_when_the_data_is_there() {
        let path = manifest_path("examples/scenes/overlay-lidc2.toml");
        let file = SceneFile::read(&path).unwrap();
        assert_eq!(file.output.size, Some([512, 512]));
        let ct = "volumes/lidc2/lidc2_256x256x133_uint8.raw";
        if !data_dir().join(ct).exists() {
            assert!(
                std::env::var_os("CI").is_none(),
                "{} has no {ct} under CI: set SPLATSCENE_DATA",
                data_dir().display()
            );
            eprintln!("skipped loading: {} has no {ct}", data_dir().display());
            return;
        }
        let loaded = load_scene_file(&path).unwrap();
        let (_, node, _) = loaded.scene.volumes().next().unwrap();
        assert_eq!(node.volume.dims, [256, 256, 133]);
        // The prosthesis head centre, (-7.0004, 0, 7.0004) in its own frame, sits at the
        // humeral head centre found in the scan, voxel (25.7, 116.2, 7.8).
        let group = loaded.scene.find("prosthesis").unwrap();
        let head = loaded
            .scene
            .world(group)
            .transform_point3(DVec3::new(-7.0004, 0.0, 7.0004));
        // Orientation LAI: index x runs to the patient's left (-x), z inferior (-z).
        let expected = DVec3::new(-25.71 * 1.40625, 116.19 * 1.40625, -7.82 * 2.5);
        assert!(head.distance(expected) < 0.05, "{head} vs {expected}");
    }

    #[test]
    fn a_mesh_file_named_by_several_nodes_is_read_once_and_shared() {
        let dir = TempDir::new("instanced");
        let mut stl = vec![0u8; 80];
        stl.extend(1u32.to_le_bytes());
        for v in [0f32, 0., 1., 0., 0., 0., 10., 0., 0., 0., 10., 0.] {
            stl.extend(v.to_le_bytes());
        }
        stl.extend([0u8; 2]);
        std::fs::write(dir.0.join("bone.stl"), &stl).unwrap();
        let mut text = String::new();
        for x in 0..30 {
            text.push_str(&format!(
                "[[mesh]]\npath = \"bone.stl\"\ntransform = {{ translate = [{x}, 0, 0] }}\n"
            ));
        }
        text.push_str("[[mesh]]\npath = \"./bone.stl\"\ncolor = [1, 0, 0]\n");
        let path = dir.write("many.toml", &text);
        let scene = load_scene_file(&path).unwrap().scene;
        let meshes: Vec<&crate::scene::MeshNode> = scene
            .nodes()
            .iter()
            .filter_map(|n| match &n.content {
                NodeContent::Mesh(m) => Some(m),
                _ => None,
            })
            .collect();
        assert_eq!(meshes.len(), 31);
        assert!(meshes.iter().all(|m| Arc::ptr_eq(&m.mesh, &meshes[0].mesh)));
        assert_eq!(meshes[0].mesh.indices.len(), 3);
        // Materials stay each node's own.
        assert_eq!(meshes[30].material.base_color, [1.0, 0.0, 0.0, 1.0]);
        assert_ne!(
            meshes[0].material.base_color,
            meshes[30].material.base_color
        );
    }
}
