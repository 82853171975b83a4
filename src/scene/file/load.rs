//! Resolving and loading what a scene file names: paths (`builtin:`, `data:`, relative),
//! volumes, meshes and their placement, clip planes, measurements and lights.

use std::path::{Component, Path, PathBuf};
use std::sync::Arc;

use glam::{DMat4, DQuat, DVec3, EulerRot};

use super::camera::camera;
use super::{
    DATA_ENV, DataRoot, LightsSpec, LoadedScene, MeasurementSpec, MeshSpec, SceneFile,
    SceneFileError, TransformSpec, VolumeSpec, data_dir, describe_data_dir, mm, named_apart,
    shortened, validate,
};
use super::{Seat, Units};
use crate::classify::{TransferFunction, auto_transfer};
use crate::mesh::load_mesh;
use crate::mesh::prosthesis::seat_in_phantom;
use crate::scene::patient::OrientationCode;
use crate::scene::shoulder::{
    add_model, cut_away_anterior_humerus, prosthesis_model, resect_humeral_head,
};
use crate::scene::{
    ClipPlane, Clipping, Light, Lights, MAX_CLIP_PLANES, NodeContent, NodeId, Scene,
    SceneMeasurement, SplatSettings, VolumeNode,
};
use crate::volume::detect::CoordinateFrame;
use crate::volume::detect::{LoadOptions, SeriesChoice};
use crate::volume::phantom::{DEFAULT_DIMS, DEFAULT_SPACING};
use crate::volume::{
    CpuVolume, RawSpec, VolumeError, load_raw, load_raw_slices, shoulder_landmarks,
    shoulder_phantom_default, slice_stack,
};

impl SceneFile {
    /// Loads everything the file names; relative paths are taken from `base`.
    pub fn load(&self, path: &Path, base: &Path) -> Result<LoadedScene, SceneFileError> {
        self.load_given(path, base, Given::default())
    }

    /// [`SceneFile::load`], with the volumes and meshes `given` holds taken as they are
    /// instead of read from their paths (which then only name them in messages): a front end
    /// that already holds a volume or a mesh in memory (the Python module's arrays) loads the
    /// rest of the file as any other. Raw and file keys (`dims`, `series`...) are refused on
    /// a given volume, having nothing to read.
    pub fn load_given(
        &self,
        path: &Path,
        base: &Path,
        mut given: Given,
    ) -> Result<LoadedScene, SceneFileError> {
        let invalid = |message: String| SceneFileError::Invalid {
            path: path.into(),
            message,
        };
        // The cheap checks come first, so that a typo is reported before volumes are read.
        validate::check(self).map_err(&invalid)?;
        let size = self.output.size.map(|[w, h]| (w, h));
        let ordering = self.output.ordering;
        let data = DataRoot::from_env();
        let mut scene = Scene::new();
        for (i, spec) in self.volumes.iter().enumerate() {
            let held = given.volumes.get_mut(i).and_then(Option::take);
            let node = load_volume(spec, held, path, base, &data, &invalid)?;
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
            if let Some(model) = given.meshes.get_mut(i).and_then(Option::take) {
                files.give(given_key(i), model);
            }
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
        scene.camera =
            Some(camera(self.camera.as_ref(), &scene, aspect).map_err(|e| invalid(e.to_string()))?);
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
}

/// Reads a scene file and loads what it names.
pub fn load_scene_file(path: &Path) -> Result<LoadedScene, SceneFileError> {
    let file = SceneFile::read(path)?;
    let base = path.parent().unwrap_or(Path::new("."));
    file.load(path, base)
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

/// Why a `data:` path of a scene file names no file in the data folder.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DataPathError {
    /// It climbs out of the data folder, or is absolute.
    #[error("{0:?}: a data: path must stay inside the data folder (relative, no ..)")]
    Outside(String),
    /// Nothing follows `data:`.
    #[error("{0:?}: a data: path needs a file name after data:")]
    NoName(String),
}

/// Where a volume or mesh `path` of a scene file points (see the module documentation): a
/// `data:` path inside `data_dir`, a relative path inside `base` (the scene file's folder), an
/// absolute path as it is. Built-in names are not paths and must be handled before.
///
/// # Errors
///
/// When a `data:` path is empty, absolute, or climbs out of the data folder.
pub fn resolve_path(path: &str, base: &Path, data_dir: &Path) -> Result<PathBuf, DataPathError> {
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
                return Err(DataPathError::Outside(path.to_owned()));
            }
        }
    }
    if names == 0 {
        return Err(DataPathError::NoName(path.to_owned()));
    }
    Ok(data_dir.join(rel))
}

/// [`resolve_path`] with the scene's error types, and a missing `data:` file reported as
/// [`SceneFileError::DataNotFound`] (which says what to set) instead of a bare read error.
pub(super) fn resolve_spec_path(
    path: &str,
    scene_file: &Path,
    base: &Path,
    data: &DataRoot,
    invalid: &dyn Fn(String) -> SceneFileError,
) -> Result<PathBuf, SceneFileError> {
    let resolved = resolve_path(path, base, &data.dir).map_err(|e| invalid(e.to_string()))?;
    if path.starts_with("data:") && !resolved.exists() {
        return Err(SceneFileError::DataNotFound {
            path: scene_file.into(),
            file: resolved,
            data_var: data.var.clone(),
        });
    }
    Ok(resolved)
}

/// A preset, a value window and a shift given for every volume (`--preset`, `--window`,
/// `--shift`, and their batch manifest keys) applied to one volume's spec: a preset replaces
/// the transfer function (stretched over the window when one is given); a window alone makes a
/// ramp over it.
pub fn apply_transfer(
    spec: &mut super::VolumeSpec,
    preset: Option<&str>,
    window: Option<[f32; 2]>,
    shift: Option<f32>,
) {
    match (preset, window) {
        (Some(preset), window) => {
            spec.transfer = Some(preset.to_owned());
            spec.window = None;
            spec.color = None;
            spec.level_width = window.map(|[lo, hi]| [0.5 * (lo + hi), hi - lo]);
        }
        (None, Some(window)) => {
            if spec.transfer.as_deref() != Some("ramp") {
                spec.color = None;
            }
            spec.transfer = Some("ramp".into());
            spec.window = Some(window);
            spec.level_width = None;
        }
        (None, None) => {}
    }
    if let Some(shift) = shift {
        spec.shift = Some(shift);
    }
}

/// Volumes and meshes a scene file's load takes as they are ([`SceneFile::load_given`]), by
/// their index among the file's volumes and meshes.
#[derive(Default)]
pub struct Given {
    /// The volume of each volume spec, where one is held.
    pub volumes: Vec<Option<Arc<CpuVolume>>>,
    /// The mesh file's content of each mesh spec, where one is held.
    pub meshes: Vec<Option<crate::mesh::Model>>,
}

/// The key under which a given mesh is kept among the files read: no path can be it.
fn given_key(index: usize) -> PathBuf {
    PathBuf::from(format!("\0given mesh {index}"))
}

pub(super) fn load_volume(
    spec: &VolumeSpec,
    held: Option<Arc<CpuVolume>>,
    scene_file: &Path,
    base: &Path,
    data: &DataRoot,
    invalid: &dyn Fn(String) -> SceneFileError,
) -> Result<VolumeNode, SceneFileError> {
    let volume = if let Some(held) = held {
        let keys = raw_keys(spec)
            .into_iter()
            .chain(file_keys(spec).map(|(key, given, _)| (key, given)))
            .chain([
                ("resect_humeral_head", spec.resect_humeral_head),
                (
                    "cut_away_anterior_humerus",
                    spec.cut_away_anterior_humerus.is_some(),
                ),
            ]);
        if let Some((key, _)) = keys.into_iter().find(|(_, g)| *g) {
            return Err(invalid(format!(
                "volume {}: {key} has no effect on a volume given in memory, which is read already",
                spec.path
            )));
        }
        held
    } else if spec.path == "builtin:shoulder-phantom" {
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
        Arc::new(volume)
    } else {
        if spec.cut_away_anterior_humerus.is_some() {
            // The cut is placed by the phantom's landmarks, which no other volume has.
            return Err(invalid(format!(
                "volume {}: cut_away_anterior_humerus applies to builtin:shoulder-phantom only",
                spec.path
            )));
        }
        let file = resolve_spec_path(&spec.path, scene_file, base, data, invalid)?;
        Arc::new(load_raw_volume(spec, &file, invalid)?)
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
                let preset = TransferFunction::preset(other).ok_or_else(|| {
                    invalid(format!(
                        "unknown transfer function {other:?} (auto, ramp, {})",
                        TransferFunction::PRESETS.join(", ")
                    ))
                })?;
                if let Some(warning) = preset_mismatch(other, spec, &volume.values) {
                    eprintln!("warning: {}: {warning}", spec.path);
                }
                preset
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
        volume,
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

/// Reads the volume `spec` describes from `path` (resolved already) as a scene file reads it:
/// a raw file with `dims` and `scalar`, else any format with a header or a DICOM folder; keys
/// that cannot apply to it refused, naming them.
pub fn read_volume(spec: &VolumeSpec, path: &Path) -> Result<CpuVolume, SceneFileError> {
    load_raw_volume(spec, path, &|message| SceneFileError::Invalid {
        path: path.into(),
        message,
    })
}

/// The keys of a volume spec that describe a headerless raw file, each with whether it is set.
fn raw_keys(spec: &VolumeSpec) -> [(&'static str, bool); 6] {
    [
        ("dims", spec.dims.is_some()),
        ("scalar", spec.scalar.is_some()),
        ("header_bytes", spec.header_bytes.is_some()),
        ("spacing", spec.spacing.is_some()),
        ("origin", spec.origin.is_some()),
        ("orientation", spec.orientation.is_some()),
    ]
}

/// The keys of a volume spec that choose how a file with a header is read, each with whether it
/// is set and the files it applies to.
fn file_keys(spec: &VolumeSpec) -> [(&'static str, bool, &'static str); 5] {
    [
        ("series", spec.series.is_some(), "DICOM"),
        ("skip_unreadable", spec.skip_unreadable.is_some(), "DICOM"),
        ("frame", spec.frame.is_some(), "4-D NIfTI"),
        ("nifti_transform", spec.nifti_transform.is_some(), "NIfTI"),
        (
            "coordinate_frame",
            spec.coordinate_frame.is_some(),
            "files whose format states no frame (a raw volume takes orientation)",
        ),
    ]
}

pub(super) fn load_raw_volume(
    spec: &VolumeSpec,
    path: &Path,
    invalid: &dyn Fn(String) -> SceneFileError,
) -> Result<CpuVolume, SceneFileError> {
    let raw_keys = raw_keys(spec);
    let file_keys = file_keys(spec);
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
            coordinate_frame: spec.coordinate_frame,
            nifti_transform: spec.nifti_transform,
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
    let format = *scalar;
    let orientation = spec.orientation.unwrap_or(OrientationCode::RAS);
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

/// A mesh file's content with its triangles behind shared pointers; its warnings are printed.
fn shared(mut model: crate::mesh::Model) -> Arc<SharedModel> {
    for warning in &model.warnings {
        eprintln!("warning: {warning}");
    }
    let meshes = model
        .parts
        .iter_mut()
        .map(|part| Arc::new(std::mem::take(&mut part.mesh)))
        .collect();
    Arc::new(SharedModel {
        parts: model.parts,
        meshes,
    })
}

/// The mesh files a scene file's load has read, by resolved path: their parts, with triangles
/// shared by every node drawn from them.
#[derive(Default)]
pub(super) struct MeshFiles {
    models: std::collections::HashMap<PathBuf, Arc<SharedModel>>,
}

/// A mesh file's parts, its triangles behind shared pointers.
pub(super) struct SharedModel {
    parts: Vec<crate::mesh::MeshPart>,
    meshes: Vec<Arc<crate::mesh::CpuMesh>>,
}

impl MeshFiles {
    /// Keeps `model` as the content of `key`, its warnings printed now.
    fn give(&mut self, key: PathBuf, model: crate::mesh::Model) {
        self.models.insert(key, shared(model));
    }

    /// The model kept under `key`, if one is.
    fn given(&self, key: &Path) -> Option<Arc<SharedModel>> {
        self.models.get(key).cloned()
    }

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
        let shared = shared(load()?);
        self.models.insert(key, Arc::clone(&shared));
        Ok(shared)
    }
}

pub(super) fn load_mesh_spec(
    scene: &mut Scene,
    spec: &MeshSpec,
    index: usize,
    (scene_file, base, data): (&Path, &Path, &DataRoot),
    files: &mut MeshFiles,
    invalid: &dyn Fn(String) -> SceneFileError,
) -> Result<NodeId, SceneFileError> {
    let shared = if let Some(model) = files.given(&given_key(index)) {
        model
    } else if spec.path == "builtin:prosthesis" {
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
    let seat = match spec.seat {
        None => DMat4::IDENTITY,
        Some(Seat::Phantom) => seat_in_phantom(&shoulder_landmarks(DEFAULT_DIMS, DEFAULT_SPACING)),
    };
    let local = seat * transform(&spec.transform).map_err(invalid)? * file_frame(spec);
    let name = spec
        .name
        .clone()
        .unwrap_or_else(|| format!("mesh {}", index + 1));
    add_model(scene, &name, local, &model, Some(&shared.meshes))
        .ok_or_else(|| invalid(format!("mesh {name}: transform is singular")))
}

/// The clip planes and the crop box of a scene file, checked.
pub(super) fn clipping(file: &SceneFile) -> Result<Clipping, String> {
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
pub(super) const MAX_LABEL: usize = 200;

/// A scene file's measurement, checked against the scene loaded so far.
pub(super) fn measurement(
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
    let find = |n: &str| {
        if named_apart(scene, n) > 1 {
            return Err(format!(
                "{name}: node {:?} names {} meshes or volumes of the scene, so the measurement cannot tell which one it follows; give each its own `name`",
                shortened(n),
                named_apart(scene, n)
            ));
        }
        scene.find(n).ok_or_else(|| {
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
        })
    };
    let node = spec.node.as_deref().map(find).transpose()?;
    let anchors = match &spec.nodes {
        None => Vec::new(),
        Some(_) if spec.node.is_some() => {
            return Err(format!(
                "{name}: give node (every point) or nodes (one a point), not both"
            ));
        }
        Some(names) if names.len() != spec.points.len() => {
            return Err(format!(
                "{name}: nodes names {} nodes for {} points: one a point (\"\" for the world)",
                names.len(),
                spec.points.len()
            ));
        }
        Some(names) => names
            .iter()
            .map(|n| match n.as_str() {
                "" => Ok(None),
                n => find(n).map(Some),
            })
            .collect::<Result<_, _>>()?,
    };
    let m = SceneMeasurement {
        kind: spec.kind,
        points: spec.points.iter().map(|p| DVec3::from(*p)).collect(),
        node,
        anchors,
        label: spec.label.clone(),
    };
    scene
        .measure(&m)
        .map_err(|e| format!("{name}: points: {e}"))?;
    Ok(m)
}

/// Why the CT preset `name` will draw these values badly, if it will: they are no Hounsfield
/// units (LIDC-like 0..255 data), and neither `level_width` nor `shift` moves the preset onto
/// them.
fn preset_mismatch(
    name: &str,
    spec: &VolumeSpec,
    values: &crate::volume::Voxels,
) -> Option<String> {
    if !name.starts_with("ct-")
        || spec.level_width.is_some()
        || spec.shift.is_some()
        || crate::classify::is_hounsfield(values)
    {
        return None;
    }
    let (lo, hi) = crate::classify::finite_range(values);
    Some(format!(
        "{name} is made for Hounsfield units, but the values run from {lo} to {hi} (no air at -1000): the picture will be faint or empty; leave transfer out for a ramp over the data's percentiles, or move the preset with level_width or shift"
    ))
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
                "units = \"m\" or \"cm\" in the scene file (--mesh-units m or cm on the command line) if the file is in metres or centimetres"
            } else if ratio > 100.0 {
                "units = \"mm\" with a scale in the scene file, or check the file's units (--mesh-units on the command line)"
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
pub(super) fn looks_like_scene_file(path: &Path) -> bool {
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
pub(super) fn file_frame(spec: &MeshSpec) -> DMat4 {
    let scale = spec.units.map_or(1.0, Units::millimetres);
    let turn = match spec.frame.unwrap_or_default() {
        CoordinateFrame::Ras => DVec3::ONE,
        // LPS to RAS: x and y change sign.
        CoordinateFrame::Lps => DVec3::new(-1.0, -1.0, 1.0),
    };
    DMat4::from_scale(turn * scale)
}

pub(super) fn transform(spec: &TransformSpec) -> Result<DMat4, String> {
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

pub(super) fn lights(spec: &LightsSpec) -> Lights {
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
