//! Objects of a scene: the top nodes that hold meshes (a mesh file's node moves as one, its
//! parts below it), found by name, with the point they turn about and their surface in world
//! coordinates. Contact reports, slice planes and the viewer's moves all take an object this way.

use glam::{DMat4, DVec3};
use thiserror::Error;

use super::{NodeId, Scene};
use crate::measure::MeasureKind;

/// Why no object could be chosen.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum ObjectError {
    /// No node of that name holds a mesh.
    #[error("no mesh named {name:?} in the scene (its meshes: {known})")]
    NoMesh {
        /// The name asked for.
        name: String,
        /// The meshes there are, comma-separated and quoted.
        known: String,
    },
    /// The scene has no mesh at all.
    #[error("the scene has no mesh")]
    NoMeshes,
}

impl Scene {
    /// The top node above `node` (the node of a whole mesh file, which moves as one).
    pub fn top_node(&self, mut node: NodeId) -> NodeId {
        while let Some(parent) = self.node(node).ok().and_then(|n| n.parent()) {
            node = parent;
        }
        node
    }

    /// Whether `node` is `top` or lies below it.
    pub fn is_under(&self, node: NodeId, top: NodeId) -> bool {
        let mut at = Some(node);
        while let Some(id) = at {
            if id == top {
                return true;
            }
            at = self.nodes().get(id.0).and_then(|n| n.parent());
        }
        false
    }

    /// The object named `name` (a node holding meshes, itself or below it), or the first top
    /// node holding meshes where `None`; with its name.
    ///
    /// # Errors
    ///
    /// When no node of that name holds a mesh, or the scene has no mesh.
    pub fn mesh_object(&self, name: Option<&str>) -> Result<(NodeId, String), ObjectError> {
        let holds_mesh = |top: NodeId| self.meshes().any(|(id, _, _)| self.is_under(id, top));
        let tops: Vec<NodeId> = (0..self.nodes().len())
            .map(NodeId)
            .filter(|&id| self.nodes()[id.0].parent().is_none() && holds_mesh(id))
            .collect();
        let Some(name) = name else {
            let top = *tops.first().ok_or(ObjectError::NoMeshes)?;
            return Ok((top, self.nodes()[top.0].name.clone()));
        };
        let found = (0..self.nodes().len())
            .map(NodeId)
            .find(|&id| self.nodes()[id.0].name == name && holds_mesh(id));
        match found {
            Some(id) => Ok((id, name.to_owned())),
            None if tops.is_empty() => Err(ObjectError::NoMeshes),
            None => Err(ObjectError::NoMesh {
                name: name.to_owned(),
                known: tops
                    .iter()
                    .map(|t| format!("{:?}", self.nodes()[t.0].name))
                    .collect::<Vec<_>>()
                    .join(", "),
            }),
        }
    }

    /// Where a node turns about: its first point measurement (a landmark such as the head
    /// centre of a prosthesis, named by its label), else its origin; in world coordinates,
    /// with what it is.
    pub fn pivot(&self, node: NodeId) -> (DVec3, String) {
        let landmark = self
            .measurements
            .iter()
            .find(|m| m.kind == MeasureKind::Point && m.node == Some(node));
        if let Some(m) = landmark
            && let Ok(value) = self.measure(m)
        {
            let at = DVec3::from(value.points[0]);
            return (at, m.label.clone().unwrap_or_else(|| "landmark".into()));
        }
        (
            self.world(node).transform_point3(DVec3::ZERO),
            "origin".into(),
        )
    }

    /// The triangles of every mesh at or below `top`, in world coordinates (triangles whose
    /// indices are out of range left out).
    pub fn object_triangles(&self, top: NodeId) -> Vec<[DVec3; 3]> {
        self.meshes()
            .filter(|(id, _, _)| self.is_under(*id, top))
            .flat_map(|(_, m, to_world)| {
                world_triangles(&m.mesh.positions, &m.mesh.indices, to_world)
            })
            .collect()
    }
}

/// A mesh's triangles in world coordinates (those whose indices are out of range left out).
pub fn world_triangles<'a>(
    positions: &'a [[f32; 3]],
    indices: &'a [u32],
    to_world: DMat4,
) -> impl Iterator<Item = [DVec3; 3]> + 'a {
    indices.chunks_exact(3).filter_map(move |t| {
        let p = |i: u32| {
            positions
                .get(i as usize)
                .map(|p| to_world.transform_point3(DVec3::from(p.map(f64::from))))
        };
        Some([p(t[0])?, p(t[1])?, p(t[2])?])
    })
}
