//! The scene graph, with no GPU involved: named nodes with local transforms and children; mesh
//! nodes, volume nodes, a camera and lights. World transforms and bounds are computed once per
//! change (a generation counter tells renderers what moved), not per frame.

use std::sync::Arc;

use glam::{DMat4, DVec3};
use thiserror::Error;

use crate::classify::TransferFunction;
use crate::geometry::{GeometryError, VolumeGeometry};
use crate::measure::{MeasureError, MeasureKind, Measurement};
use crate::mesh::{CpuMesh, Material};
use crate::order::Ordering;
use crate::splat::reference::SplatStyle;
use crate::volume::CpuVolume;

mod clip;
pub mod file;
mod objects;
pub mod patient;
pub mod shoulder;
pub mod slice_spec;
mod view;

pub use clip::{ClipPlane, Clipping, MAX_CLIP_PLANES, MAX_PLANES_IN_FORCE};
pub use objects::{ObjectError, world_triangles};
pub use view::{Light, Lights, Projection, SceneCamera};

/// Index of a node in its [`Scene`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
#[serde(transparent)]
pub struct NodeId(pub usize);

/// Why a scene edit was refused.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum SceneError {
    /// The node id is not in this scene.
    #[error("no node {0:?} in the scene")]
    NoSuchNode(NodeId),
    /// A transform has NaN or infinite entries, or is singular.
    #[error("node {name:?}: transform is not finite and invertible")]
    BadTransform {
        /// The node's name.
        name: String,
    },
}

/// A mesh drawn opaque with its material.
#[derive(Debug, Clone)]
pub struct MeshNode {
    /// The triangles, shared between nodes that draw the same mesh.
    pub mesh: Arc<CpuMesh>,
    /// Colour and shading parameters.
    pub material: Material,
}

/// How a volume becomes splats.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SplatSettings {
    /// Footprint shape.
    pub style: SplatStyle,
    /// Voxels with opacity at or below this are left out.
    pub min_opacity: f32,
    /// The draw order.
    pub ordering: Ordering,
    /// Headlight shading from the gradient: 0 keeps the transfer function's flat colour
    /// (what the CPU reference compositor draws), 1 fully shades.
    pub shading: f32,
    /// The transfer function's opacities hold for this many millimetres of tissue (1 mm by
    /// default, VTK's scalar opacity unit distance); see [`crate::classify::Opacity`]: a volume
    /// looks alike at any resolution and splat size.
    pub opacity_reference_mm: f64,
    /// Shell mode: only voxels with a neighbour at or below this opacity become splats (the
    /// hidden inside of opaque tissue is left out); `None` keeps every visible voxel.
    pub shell: Option<f32>,
}

impl Default for SplatSettings {
    fn default() -> Self {
        Self {
            style: SplatStyle::default(),
            min_opacity: 1.0 / 255.0,
            ordering: Ordering::IpPbtfImplicit,
            shading: 0.8,
            opacity_reference_mm: 1.0,
            shell: None,
        }
    }
}

/// A CT volume splatted one splat per significant voxel.
#[derive(Debug, Clone)]
pub struct VolumeNode {
    /// Scalar values and their placement (the node transform goes on top).
    pub volume: Arc<CpuVolume>,
    /// Scalar to colour and opacity.
    pub transfer: Arc<TransferFunction>,
    /// Splat shape, threshold and ordering.
    pub splats: SplatSettings,
}

/// What a node carries besides its transform.
#[derive(Debug, Clone)]
pub enum NodeContent {
    /// A grouping node.
    Empty,
    /// An opaque mesh.
    Mesh(MeshNode),
    /// A volume.
    Volume(VolumeNode),
    /// A mesh drawn over everything else, such as a measurement's markers: neither hidden by
    /// nor hiding the scene, and never picked.
    Overlay(MeshNode),
}

/// A node: a name, a transform relative to its parent, children and content.
#[derive(Debug, Clone)]
pub struct Node {
    /// Name, unique or not.
    pub name: String,
    local: DMat4,
    parent: Option<NodeId>,
    children: Vec<NodeId>,
    /// What the node draws.
    pub content: NodeContent,
}

impl Node {
    /// Transform from this node's frame to its parent's.
    pub fn local(&self) -> DMat4 {
        self.local
    }

    /// The parent node, if any.
    pub fn parent(&self) -> Option<NodeId> {
        self.parent
    }

    /// The child nodes.
    pub fn children(&self) -> &[NodeId] {
        &self.children
    }
}

/// A scene: nodes, a camera and lights.
#[derive(Debug, Clone, Default)]
pub struct Scene {
    nodes: Vec<Node>,
    world: Vec<DMat4>,
    /// Bounds of each node's own content in its frame (meshes and volumes).
    local_bounds: Vec<Option<(DVec3, DVec3)>>,
    /// World bounds of everything, redone on every edit.
    bounds: Option<(DVec3, DVec3)>,
    generation: u64,
    /// The camera; [`SceneCamera::fit`] frames the scene when none was set.
    pub camera: Option<SceneCamera>,
    /// The lights.
    pub lights: Lights,
    /// Clip planes and crop box (world space); changing them needs no new classification.
    pub clipping: Clipping,
    /// The scene's up, the axis orbits turn about; `None` takes the patient's superior axis
    /// (see [`Scene::up_axis`]).
    pub up: Option<DVec3>,
    /// Measurements kept with the scene (a plan's distances, angles and landmarks).
    pub measurements: Vec<SceneMeasurement>,
}

/// A measurement kept in a scene: its points in world millimetres, or in a node's frame so
/// that they move with the node (a landmark on an implant).
#[derive(Debug, Clone, PartialEq)]
pub struct SceneMeasurement {
    /// Distance, angle, line angle or point.
    pub kind: MeasureKind,
    /// The points, each in the frame of the node it moves with (see
    /// [`SceneMeasurement::frame_of`]), else in the world.
    pub points: Vec<DVec3>,
    /// The node the points move with.
    pub node: Option<NodeId>,
    /// For a measurement between things (an implant point and a bone point): the node each
    /// point moves with, one a point (`None`: the world); empty where `node` holds for all.
    pub anchors: Vec<Option<NodeId>>,
    /// The name written beside the value (`neck-shaft angle`).
    pub label: Option<String>,
}

impl SceneMeasurement {
    /// The node point `i` moves with: its anchor where there are anchors, else `node`.
    pub fn frame_of(&self, i: usize) -> Option<NodeId> {
        if self.anchors.is_empty() {
            self.node
        } else {
            self.anchors.get(i).copied().flatten()
        }
    }
}

impl Scene {
    /// An empty scene with the default lights (a headlight).
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a node under `parent` (a root when `None`) and returns its id.
    pub fn add(
        &mut self,
        name: impl Into<String>,
        local: DMat4,
        parent: Option<NodeId>,
        content: NodeContent,
    ) -> Result<NodeId, SceneError> {
        let name = name.into();
        check_transform(&name, &local)?;
        if let Some(p) = parent {
            self.node(p)?;
        }
        let id = NodeId(self.nodes.len());
        let world = parent.map_or(DMat4::IDENTITY, |p| self.world[p.0]) * local;
        self.local_bounds.push(content_bounds(&content));
        self.nodes.push(Node {
            name,
            local,
            parent,
            children: Vec::new(),
            content,
        });
        self.world.push(world);
        if let Some(p) = parent {
            self.nodes[p.0].children.push(id);
        }
        // The bounds grow by the new node alone: recomputing them over every node made adding
        // n nodes cost n^2.
        self.generation += 1;
        if let Some((lo, hi)) = self.local_bounds[id.0] {
            let corners = box_corners(lo, hi).map(|c| world.transform_point3(c));
            self.bounds = corners.into_iter().fold(self.bounds, grow);
        }
        Ok(id)
    }

    /// Sets a node's local transform and updates the world transforms below it.
    pub fn set_local(&mut self, id: NodeId, local: DMat4) -> Result<(), SceneError> {
        let node = self.node(id)?;
        check_transform(&node.name, &local)?;
        self.nodes[id.0].local = local;
        let mut stack = vec![id];
        while let Some(n) = stack.pop() {
            let parent = self.nodes[n.0].parent;
            self.world[n.0] =
                parent.map_or(DMat4::IDENTITY, |p| self.world[p.0]) * self.nodes[n.0].local;
            stack.extend_from_slice(&self.nodes[n.0].children);
        }
        self.edited();
        Ok(())
    }

    /// Replaces a node's content (a new transfer function, say).
    pub fn set_content(&mut self, id: NodeId, content: NodeContent) -> Result<(), SceneError> {
        self.node(id)?;
        self.local_bounds[id.0] = content_bounds(&content);
        self.nodes[id.0].content = content;
        self.edited();
        Ok(())
    }

    /// A node by id.
    pub fn node(&self, id: NodeId) -> Result<&Node, SceneError> {
        self.nodes.get(id.0).ok_or(SceneError::NoSuchNode(id))
    }

    /// Every node, indexed by [`NodeId`].
    pub fn nodes(&self) -> &[Node] {
        &self.nodes
    }

    /// A node's transform to world space (kept up to date on every edit).
    pub fn world(&self, id: NodeId) -> DMat4 {
        self.world.get(id.0).copied().unwrap_or(DMat4::IDENTITY)
    }

    /// The value of a measurement of this scene, its points in the world.
    ///
    /// # Errors
    ///
    /// When the points make no measurement of its kind (see [`Measurement::new`]).
    pub fn measure(&self, m: &SceneMeasurement) -> Result<Measurement, MeasureError> {
        let points: Vec<DVec3> = m
            .points
            .iter()
            .enumerate()
            .map(|(i, p)| {
                m.frame_of(i)
                    .map_or(*p, |id| self.world(id).transform_point3(*p))
            })
            .collect();
        Measurement::new(m.kind, &points)
    }

    /// Counts edits; a renderer compares it with the value it last saw to know what to redo.
    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// The first node with this name.
    pub fn find(&self, name: &str) -> Option<NodeId> {
        self.nodes.iter().position(|n| n.name == name).map(NodeId)
    }

    /// Nodes whose content `pick` selects, with their world transforms.
    fn contents<'a, T: 'a>(
        &'a self,
        pick: impl Fn(&'a NodeContent) -> Option<&'a T> + 'a,
    ) -> impl Iterator<Item = (NodeId, &'a T, DMat4)> + 'a {
        let world = &self.world;
        (self.nodes.iter().enumerate())
            .filter_map(move |(i, n)| Some((NodeId(i), pick(&n.content)?, world[i])))
    }

    /// Mesh nodes with their world transforms.
    pub fn meshes(&self) -> impl Iterator<Item = (NodeId, &MeshNode, DMat4)> + '_ {
        self.contents(|c| match c {
            NodeContent::Mesh(m) => Some(m),
            _ => None,
        })
    }

    /// Overlay mesh nodes with their world transforms.
    pub fn overlays(&self) -> impl Iterator<Item = (NodeId, &MeshNode, DMat4)> + '_ {
        self.contents(|c| match c {
            NodeContent::Overlay(m) => Some(m),
            _ => None,
        })
    }

    /// Volume nodes with their world transforms.
    pub fn volumes(&self) -> impl Iterator<Item = (NodeId, &VolumeNode, DMat4)> + '_ {
        self.contents(|c| match c {
            NodeContent::Volume(v) => Some(v),
            _ => None,
        })
    }

    /// World bounds of a node's content and everything below it, or `None` when none of it
    /// has anything to draw.
    pub fn subtree_bounds(&self, id: NodeId) -> Option<(DVec3, DVec3)> {
        let own = self
            .local_bounds
            .get(id.0)
            .copied()
            .flatten()
            .map(|(lo, hi)| {
                let corners = box_corners(lo, hi).map(|c| self.world[id.0].transform_point3(c));
                corners
                    .iter()
                    .fold((corners[0], corners[0]), |(a, b), c| (a.min(*c), b.max(*c)))
            });
        let children = self.nodes.get(id.0)?.children.iter();
        children
            .filter_map(|&c| self.subtree_bounds(c))
            .chain(own)
            .reduce(|(a, b), (c, d)| (a.min(c), b.max(d)))
    }

    /// How the patient lies in the world: the frame of the first volume's node (volumes are
    /// placed in patient RAS, so this is the identity unless that node turns the volume), or
    /// RAS itself in a scene without volumes.
    pub fn patient_frame(&self) -> patient::PatientFrame {
        self.volumes()
            .next()
            .map_or_else(patient::PatientFrame::default, |(_, _, world)| {
                patient::PatientFrame::from_linear(glam::DMat3::from_mat4(world))
            })
    }

    /// The axis orbits turn about: [`Scene::up`] when set and non-zero, else the patient's
    /// superior axis.
    pub fn up_axis(&self) -> DVec3 {
        self.up
            .and_then(DVec3::try_normalize)
            .unwrap_or_else(|| self.patient_frame().superior())
    }

    /// World-space bounds `(min, max)` of every mesh and volume, or `None` for a scene with
    /// nothing to draw (kept up to date on every edit).
    pub fn bounds(&self) -> Option<(DVec3, DVec3)> {
        self.bounds
    }

    /// World-space bounds `(min, max)` of what is drawn: each volume and mesh (not the
    /// measurement markers over them) as the clip
    /// planes and the crop box cut it (meshes by those that cut meshes), or `None` where
    /// nothing is left. Views are fitted to these, so that a cropped shoulder fills the
    /// picture.
    pub fn drawn_bounds(&self) -> Option<(DVec3, DVec3)> {
        self.nodes
            .iter()
            .zip(&self.local_bounds)
            .zip(&self.world)
            .filter_map(|((node, b), world)| {
                let (lo, hi) = (*b)?;
                // A mesh by its vertices (its box turned with it would hold more than it
                // does); a volume by its box's corners, which bound it exactly.
                let (wlo, whi) = match &node.content {
                    // Measurement markers are drawn over the scene, not part of it.
                    NodeContent::Overlay(_) => return None,
                    NodeContent::Mesh(m) => m
                        .mesh
                        .positions
                        .iter()
                        .map(|p| world.transform_point3(DVec3::from(p.map(f64::from))))
                        .fold(None, grow)?,
                    _ => box_corners(lo, hi)
                        .map(|c| world.transform_point3(c))
                        .into_iter()
                        .fold(None, grow)?,
                };
                let mesh = !matches!(node.content, NodeContent::Volume(_));
                self.clipping.cut_box(wlo, whi, mesh)
            })
            .fold(None, |acc, (lo, hi)| grow(grow(acc, lo), hi))
    }

    /// What views are fitted to: [`Scene::drawn_bounds`], else (everything clipped away)
    /// [`Scene::bounds`], else a unit box about the origin.
    pub fn fit_bounds(&self) -> (DVec3, DVec3) {
        self.drawn_bounds()
            .or(self.bounds)
            .unwrap_or((DVec3::splat(-1.0), DVec3::ONE))
    }

    /// World-space bounds `(min, max)` of the volumes alone, or `None` for a scene without
    /// volumes.
    pub fn volume_bounds(&self) -> Option<(DVec3, DVec3)> {
        self.nodes
            .iter()
            .zip(&self.local_bounds)
            .zip(&self.world)
            .filter(|((node, _), _)| matches!(node.content, NodeContent::Volume(_)))
            .filter_map(|((_, b), world)| {
                b.map(|(lo, hi)| box_corners(lo, hi).map(|c| world.transform_point3(c)))
            })
            .flatten()
            .fold(None, grow)
    }

    fn edited(&mut self) {
        self.generation += 1;
        let corners = self
            .local_bounds
            .iter()
            .zip(&self.world)
            .filter_map(|(b, world)| {
                b.map(|(lo, hi)| box_corners(lo, hi).map(|c| world.transform_point3(c)))
            })
            .flatten();
        self.bounds = corners.fold(None, grow);
    }
}

/// `bounds` grown to hold `p`.
fn grow(bounds: Option<(DVec3, DVec3)>, p: DVec3) -> Option<(DVec3, DVec3)> {
    Some(match bounds {
        None => (p, p),
        Some((lo, hi)) => (lo.min(p), hi.max(p)),
    })
}

/// Bounds of a node's content in its own frame.
fn content_bounds(content: &NodeContent) -> Option<(DVec3, DVec3)> {
    match content {
        NodeContent::Empty => None,
        NodeContent::Mesh(m) | NodeContent::Overlay(m) => m.mesh.bounds().map(|(lo, hi)| {
            (
                DVec3::from(lo.map(f64::from)),
                DVec3::from(hi.map(f64::from)),
            )
        }),
        NodeContent::Volume(v) => {
            let placement = volume_placement(&v.volume);
            let hi = DVec3::from(v.volume.dims.map(|n| f64::from(n.max(1)) - 1.0));
            let corners = box_corners(DVec3::ZERO, hi).map(|c| placement.transform_point3(c));
            let lo = corners.iter().fold(corners[0], |a, c| a.min(*c));
            let hi = corners.iter().fold(corners[0], |a, c| a.max(*c));
            Some((lo, hi))
        }
    }
}

/// The index-to-world placement of a volume under its node's world transform.
pub fn placed_geometry(volume: &CpuVolume, world: DMat4) -> Result<VolumeGeometry, GeometryError> {
    placed_grid(volume.dims, world * volume_placement(volume))
}

/// The geometry of a `dims` grid whose index coordinates `index_to_world` places; refused
/// where that is projective.
pub fn placed_grid(dims: [u32; 3], index_to_world: DMat4) -> Result<VolumeGeometry, GeometryError> {
    let m = index_to_world;
    if !m.row(3).abs_diff_eq(glam::DVec4::W, 1e-12) {
        return Err(GeometryError::SingularTransform);
    }
    let linear = glam::DMat3::from_mat4(m);
    VolumeGeometry::new(
        dims,
        glam::DAffine3::from_mat3_translation(linear, m.w_axis.truncate()),
    )
}

/// Voxel index coordinates to the volume node's frame: direction x spacing, then the origin.
pub fn volume_placement(volume: &CpuVolume) -> DMat4 {
    let linear = volume.direction * glam::DMat3::from_diagonal(volume.spacing.into());
    DMat4::from_cols(
        linear.x_axis.extend(0.0),
        linear.y_axis.extend(0.0),
        linear.z_axis.extend(0.0),
        DVec3::from(volume.origin).extend(1.0),
    )
}

fn box_corners(lo: DVec3, hi: DVec3) -> [DVec3; 8] {
    std::array::from_fn(|i| {
        DVec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        )
    })
}

fn check_transform(name: &str, m: &DMat4) -> Result<(), SceneError> {
    let det = m.determinant();
    if !m.is_finite() || !det.is_normal() {
        return Err(SceneError::BadTransform {
            name: name.to_owned(),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube() -> NodeContent {
        let mut mesh = CpuMesh {
            colors: Vec::new(),
            positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 1.0]],
            normals: Vec::new(),
            indices: vec![0, 1, 2, 1, 3, 2],
        };
        mesh.compute_normals();
        NodeContent::Mesh(MeshNode {
            mesh: Arc::new(mesh),
            material: Material::default(),
        })
    }

    #[test]
    fn bounds_grown_node_by_node_equal_bounds_recomputed() {
        let mut scene = Scene::new();
        let group = scene
            .add("g", DMat4::from_rotation_z(0.7), None, NodeContent::Empty)
            .unwrap();
        for i in 0..50 {
            let local = DMat4::from_translation(DVec3::new(i as f64, -2.0 * i as f64, 0.5))
                * DMat4::from_rotation_x(0.1 * i as f64);
            let parent = (i % 2 == 0).then_some(group);
            scene.add(format!("m{i}"), local, parent, cube()).unwrap();
        }
        let grown = scene.bounds().unwrap();
        scene.edited();
        let recomputed = scene.bounds().unwrap();
        assert!(
            grown.0.abs_diff_eq(recomputed.0, 1e-12),
            "{grown:?} {recomputed:?}"
        );
        assert!(
            grown.1.abs_diff_eq(recomputed.1, 1e-12),
            "{grown:?} {recomputed:?}"
        );
    }

    #[test]
    fn world_transforms_and_bounds_follow_edits() {
        let mut scene = Scene::new();
        assert_eq!(scene.bounds(), None);
        let group = scene
            .add(
                "group",
                DMat4::from_translation(DVec3::X * 10.0),
                None,
                NodeContent::Empty,
            )
            .unwrap();
        let child = scene
            .add(
                "cube",
                DMat4::from_scale(DVec3::splat(2.0)),
                Some(group),
                cube(),
            )
            .unwrap();
        assert_eq!(
            scene.bounds(),
            Some((DVec3::new(10.0, 0.0, 0.0), DVec3::new(12.0, 2.0, 2.0)))
        );
        let before = scene.generation();
        scene
            .set_local(group, DMat4::from_translation(DVec3::Z * -5.0))
            .unwrap();
        assert!(scene.generation() > before);
        let moved = scene.world(child).transform_point3(DVec3::ONE);
        assert_eq!(moved, DVec3::new(2.0, 2.0, -3.0));
        assert_eq!(
            scene.bounds(),
            Some((DVec3::new(0.0, 0.0, -5.0), DVec3::new(2.0, 2.0, -3.0)))
        );
        assert_eq!(scene.node(group).unwrap().children(), &[child]);
        assert_eq!(scene.find("cube"), Some(child));
    }

    #[test]
    fn bad_transforms_and_unknown_nodes_are_refused() {
        let mut scene = Scene::new();
        let nan = DMat4::from_translation(DVec3::new(f64::NAN, 0.0, 0.0));
        assert!(matches!(
            scene.add("bad", nan, None, cube()),
            Err(SceneError::BadTransform { .. })
        ));
        let flat = DMat4::from_scale(DVec3::new(1.0, 0.0, 1.0));
        assert!(scene.add("flat", flat, None, cube()).is_err());
        assert!(matches!(
            scene.add("orphan", DMat4::IDENTITY, Some(NodeId(7)), cube()),
            Err(SceneError::NoSuchNode(NodeId(7)))
        ));
        assert!(scene.nodes().is_empty(), "nothing half-added");
    }
}
