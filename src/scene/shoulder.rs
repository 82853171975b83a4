//! The built-in shoulder scene: the CT-like phantom of a right shoulder with its humeral head
//! resected, and the humeral-stem prosthesis (stored in `models/`, embedded in the binary)
//! seated in the humerus, so that the stem runs down the canal and the prosthesis head takes
//! the place of the resected bone.

use std::sync::Arc;

use glam::{DMat4, DVec3};

use super::{MeshNode, NodeContent, Scene, SceneCamera, SplatSettings, VolumeNode};
use crate::classify::TransferFunction;
use crate::mesh::prosthesis::seat_in_phantom;
use crate::mesh::{MeshError, Model, load_mesh_bytes};
use crate::scene::Projection;
use crate::volume::phantom::{DEFAULT_DIMS, DEFAULT_SPACING};
use crate::volume::{CpuVolume, ShoulderLandmarks, shoulder_landmarks, shoulder_phantom_default};

/// The prosthesis as stored in `models/prosthesis.gltf`.
pub const PROSTHESIS_GLTF: &[u8] = include_bytes!("../../models/prosthesis.gltf");

/// Soft tissue in Hounsfield units, what fills the space of resected bone.
const SOFT_TISSUE_HU: f32 = 45.0;

/// The embedded prosthesis model (parts `stem`, `neck`, `head` in the prosthesis frame).
pub fn prosthesis_model() -> Result<Model, MeshError> {
    load_mesh_bytes(PROSTHESIS_GLTF, "prosthesis.gltf")
}

/// Replaces the articular part of the humeral head, everything beyond the resection plane
/// through the head centre (normal along the anatomical neck), with soft tissue.
pub fn resect_humeral_head(volume: &mut CpuVolume, marks: &ShoulderLandmarks) {
    let centre = DVec3::from_array(marks.head_centre);
    let normal = DVec3::from_array(marks.neck_normal);
    let reach = marks.head_radius + 3.0;
    soften_where(volume, |p| {
        (p - centre).length() < reach && (p - centre).dot(normal) > 0.0
    });
}

/// Cuts away the anterior half of the humerus (bone in front of the plane through the shaft
/// axis, within `reach` millimetres of it), as a planning cutaway, so that the stem shows in
/// its canal.
pub fn cut_away_anterior_humerus(volume: &mut CpuVolume, marks: &ShoulderLandmarks, reach: f64) {
    let axis = DVec3::from_array(marks.shaft_axis_bottom);
    soften_where(volume, |p| p.y > axis.y && (p.x - axis.x).abs() < reach);
}

/// Lowers every voxel whose centre (in the volume's frame) satisfies `inside` to soft tissue.
fn soften_where(volume: &mut CpuVolume, inside: impl Fn(DVec3) -> bool) {
    let [nx, ny, _] = volume.dims.map(|n| n as usize);
    let placement = super::volume_placement(volume);
    for (id, value) in volume.values.make_f32().iter_mut().enumerate() {
        let k = DVec3::new(
            (id % nx) as f64,
            (id / nx % ny) as f64,
            (id / (nx * ny)) as f64,
        );
        if inside(placement.transform_point3(k)) {
            *value = value.min(SOFT_TISSUE_HU);
        }
    }
}

/// The built-in scene: the phantom with its humeral head resected and the front of the
/// humerus cut away, the seated prosthesis, and a camera from the front, a little lateral and
/// above.
pub fn shoulder_scene() -> Result<Scene, MeshError> {
    let mut volume = shoulder_phantom_default();
    let marks = shoulder_landmarks(DEFAULT_DIMS, DEFAULT_SPACING);
    resect_humeral_head(&mut volume, &marks);
    cut_away_anterior_humerus(&mut volume, &marks, 30.0);
    let mut scene = Scene::new();
    let ct = VolumeNode {
        volume: Arc::new(volume),
        transfer: Arc::new(TransferFunction::ct_bone()),
        splats: SplatSettings::default(),
    };
    scene
        .add(
            "shoulder CT",
            DMat4::IDENTITY,
            None,
            NodeContent::Volume(ct),
        )
        .expect("identity is a valid transform");
    add_model(
        &mut scene,
        "prosthesis",
        seat_in_phantom(&marks),
        &prosthesis_model()?,
        None,
    );
    let bounds = scene.bounds().unwrap_or((DVec3::ZERO, DVec3::ONE));
    let direction = DVec3::new(-0.3, -1.0, -0.35);
    scene.camera = Some(SceneCamera::fit(
        bounds,
        direction,
        Projection::Perspective {
            fov_y_degrees: 35.0,
        },
        4.0 / 3.0,
    ));
    Ok(scene)
}

/// Adds a model as a group node placed by `transform`, one mesh node per part; the part's
/// triangles are `shared[i]` when given (a file drawn by several nodes is held once), else a
/// copy of the part's own.
pub fn add_model(
    scene: &mut Scene,
    name: &str,
    transform: DMat4,
    model: &Model,
    shared: Option<&[Arc<crate::mesh::CpuMesh>]>,
) -> Option<super::NodeId> {
    let group = scene.add(name, transform, None, NodeContent::Empty).ok()?;
    for (i, part) in model.parts.iter().enumerate() {
        let mesh = match shared.and_then(|meshes| meshes.get(i)) {
            Some(mesh) => Arc::clone(mesh),
            None => Arc::new(part.mesh.clone()),
        };
        let node = MeshNode {
            mesh,
            material: part.material,
        };
        // A part whose transform is singular is left out rather than failing the scene.
        let _ = scene.add(
            &part.name,
            part.transform,
            Some(group),
            NodeContent::Mesh(node),
        );
    }
    Some(group)
}
