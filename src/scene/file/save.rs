//! Saving: a scene file with the plan a scene holds now, its paths made absolute or relative to
//! where it is saved, as TOML.

use std::path::Path;

use glam::{DMat4, DVec3, EulerRot};

use crate::mesh::prosthesis::seat_in_phantom;
use crate::scene::{NodeId, Projection, Scene, SceneCamera};
use crate::volume::phantom::{DEFAULT_DIMS, DEFAULT_SPACING};
use crate::volume::shoulder_landmarks;

use super::Seat;
use super::load::file_frame;
use super::{BoxSpec, CameraSpec, ClipSpec, MeasurementSpec, SceneFile, TransformSpec};

/// Why a scene's plan could not be written as its scene file.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// The scene has fewer top nodes than the file has volumes and meshes.
    #[error("mesh {mesh}: no node in the scene")]
    NoNode {
        /// The mesh's number in the file, from 1.
        mesh: usize,
    },
    /// A mesh's seat or frame has no inverse, so its transform cannot be written.
    #[error("mesh {mesh}: its seat or frame is singular")]
    Singular {
        /// The mesh's number in the file, from 1.
        mesh: usize,
    },
    /// The scene has a crop box but the file no volume to hold it.
    #[error("a crop box needs a volume to keep it in the scene file")]
    CropWithoutVolume,
    /// The scene refused a node.
    #[error(transparent)]
    Scene(#[from] crate::scene::SceneError),
}

impl SceneFile {
    /// The same file with every relative volume and mesh path made absolute against `base`
    /// (the scene file's folder), so that it can be saved anywhere; `builtin:` and `data:`
    /// paths are kept as they are.
    pub fn with_paths_from(&self, base: &Path) -> Self {
        self.with_file_paths(|p| {
            if p.is_absolute() {
                None
            } else {
                let joined = base.join(p);
                Some(std::path::absolute(&joined).unwrap_or(joined))
            }
        })
    }

    /// The same file with every absolute volume and mesh path written relative to `dir`, the
    /// folder the file is to be saved in (`../ct/shoulder.nrrd`), so that the plan and its data
    /// move together; `builtin:` and `data:` paths, and paths with no relative form (another
    /// drive), are kept as they are.
    pub fn with_paths_relative_to(&self, dir: &Path) -> Self {
        let dir = std::path::absolute(dir).unwrap_or_else(|_| dir.to_path_buf());
        self.with_file_paths(|p| {
            let rel = pathdiff::diff_paths(p, &dir).filter(|_| p.is_absolute())?;
            (!rel.as_os_str().is_empty()).then_some(rel)
        })
    }

    /// The same file with each volume and mesh path that names a file (not `builtin:` or
    /// `data:`) replaced by what `fix` gives for it, where it gives one.
    fn with_file_paths(&self, fix: impl Fn(&Path) -> Option<std::path::PathBuf>) -> Self {
        let fixed = |path: &String| {
            if path.starts_with("builtin:") || path.starts_with("data:") {
                return path.clone();
            }
            fix(Path::new(path)).map_or_else(|| path.clone(), |p| p.to_string_lossy().into_owned())
        };
        let mut file = self.clone();
        for v in &mut file.volumes {
            v.path = fixed(&v.path);
        }
        for m in &mut file.meshes {
            m.path = fixed(&m.path);
        }
        file
    }

    /// The same file with the plan `scene` holds now: each mesh's transform as the node stands
    /// (as `translate`, `rotate_degrees` and `scale` where those load back to it, else as a
    /// matrix: the file loads to the same placement), and the scene's
    /// measurements (those attached to a node by the node's name). `scene` must have been
    /// loaded from this file: its mesh files are the top nodes after the volumes, in order.
    ///
    /// # Errors
    ///
    /// When a mesh node is missing, a mesh's placement cannot be expressed (a singular seat or
    /// frame), or a crop box has no volume to keep it.
    pub fn with_plan(&self, scene: &Scene) -> Result<Self, PlanError> {
        let mut file = self.clone();
        let roots: Vec<NodeId> = (0..scene.nodes().len())
            .map(NodeId)
            .filter(|id| scene.nodes()[id.0].parent().is_none())
            .collect();
        for (i, spec) in file.meshes.iter_mut().enumerate() {
            let id = *roots
                .get(self.volumes.len() + i)
                .ok_or(PlanError::NoNode { mesh: i + 1 })?;
            let local = scene.node(id)?.local();
            spec.transform = placement(spec, local).ok_or(PlanError::Singular { mesh: i + 1 })?;
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
                .ok_or(PlanError::CropWithoutVolume)?;
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
                    .filter(|_| m.anchors.is_empty())
                    .and_then(|id| scene.node(id).ok())
                    .map(|n| n.name.clone()),
                nodes: (!m.anchors.is_empty()).then(|| {
                    m.anchors
                        .iter()
                        .map(|a| {
                            a.and_then(|id| scene.node(id).ok())
                                .map_or(String::new(), |n| n.name.clone())
                        })
                        .collect()
                }),
            })
            .collect();
        Ok(file)
    }

    /// The file as TOML text, as [`SceneFile::parse`] reads it back.
    ///
    /// # Errors
    ///
    /// When serde cannot write a value as TOML (none of the file's values is such a value).
    pub fn to_toml(&self) -> Result<String, toml::ser::Error> {
        toml::to_string(self)
    }
}

impl SceneFile {
    /// The `transform` of mesh `mesh` (from 0, in the file's order) that places it as `local`,
    /// the transform of its node: in the file's convention, its seat and frame taken out.
    ///
    /// # Errors
    ///
    /// No such mesh, or its seat or frame is singular.
    pub fn mesh_transform(&self, mesh: usize, local: DMat4) -> Result<TransformSpec, PlanError> {
        let spec = self
            .meshes
            .get(mesh)
            .ok_or(PlanError::NoNode { mesh: mesh + 1 })?;
        placement(spec, local).ok_or(PlanError::Singular { mesh: mesh + 1 })
    }
}

/// The `transform` that places the mesh of `spec` as `local` (its seat and frame taken out);
/// `None` where its seat or frame is singular.
fn placement(spec: &super::MeshSpec, local: DMat4) -> Option<TransformSpec> {
    let seat = match spec.seat {
        Some(Seat::Phantom) => seat_in_phantom(&shoulder_landmarks(DEFAULT_DIMS, DEFAULT_SPACING)),
        None => DMat4::IDENTITY,
    };
    let frame = file_frame(spec);
    let (ds, df) = (seat.determinant(), frame.determinant());
    if !(ds.is_normal() && df.is_normal()) {
        return None;
    }
    Some(transform_spec(seat.inverse() * local * frame.inverse()))
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

/// A transform as people write it: `translate`, `rotate_degrees` (about x, then y, then z, as
/// the loader turns) and `scale`, each left out where it does nothing, where those load back to
/// `m` (to 1e-9 of its largest element); else, for a shear, the matrix. Round-off of turns by
/// whole angles (1e-17 for 0) is written as 0.
pub fn transform_spec(m: DMat4) -> TransformSpec {
    let clean = |x: f64| if x.abs() < 1e-12 { 0.0 } else { x };
    let matrix = TransformSpec {
        matrix: Some(m.to_cols_array().map(clean)),
        ..TransformSpec::default()
    };
    let (scale, rotation, translation) = m.to_scale_rotation_translation();
    let (rz, ry, rx) = rotation.to_euler(EulerRot::ZYX);
    let degrees = [rx, ry, rz].map(|a| {
        let d = a.to_degrees();
        // Whole degrees as they were typed, not 9.999999999999998.
        if (d - d.round()).abs() < 1e-9 {
            d.round() + 0.0
        } else {
            d
        }
    });
    let scale = scale
        .to_array()
        .map(|s| if (s - 1.0).abs() < 1e-12 { 1.0 } else { s });
    let translate = translation.to_array().map(clean);
    let spec = TransformSpec {
        translate: (translate != [0.0; 3]).then_some(translate),
        rotate_degrees: (degrees != [0.0; 3]).then_some(degrees),
        scale: (scale != [1.0; 3]).then_some(scale),
        matrix: None,
    };
    let tolerance = 1e-9 * m.to_cols_array().iter().fold(1.0f64, |a, x| a.max(x.abs()));
    match super::load::transform(&spec) {
        Ok(back) if back.abs_diff_eq(m, tolerance) => spec,
        _ => matrix,
    }
}
