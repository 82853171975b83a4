//! The contact map: an implant's surface painted with the volume's value under it (3D Slicer's
//! "Probe volume with model" colours a model's vertices so). Each triangle is cut into `n x n`
//! equal triangles no longer than the volume's finest spacing, so that the colours follow the
//! volume and not the mesh's tessellation, and every new vertex takes the value there
//! (trilinear) through a perceptual colour map (viridis). What lies outside the volume is grey.

use std::sync::Arc;

use glam::{DMat4, DVec3};

use super::contact::ContactError;
use crate::mesh::{CpuMesh, Material};
use crate::scene::{MeshNode, NodeContent, NodeId, Scene, SceneError, placed_geometry};

/// The most triangles a painted object takes: about 100 MB of vertices for the GPU.
pub const MAX_PAINTED_TRIANGLES: u64 = 1 << 20;

/// The colour of a surface outside the volume.
pub const OUTSIDE: [f32; 4] = [0.45, 0.45, 0.45, 1.0];

/// An object's meshes painted with the volume's value.
#[derive(Debug, Clone)]
pub struct Painted {
    /// Each mesh node of the object with its painted mesh, its material white (so that the
    /// colours show as they are) with the mesh's opacity, roughness and metalness kept.
    pub meshes: Vec<(NodeId, MeshNode)>,
    /// The values the colour map spans, least to greatest.
    pub range: [f64; 2],
    /// The edge of the painted triangles, in millimetres.
    pub step_mm: f64,
}

impl Painted {
    /// Puts the painted meshes into `scene` (the scene they were painted from, or a copy).
    ///
    /// # Errors
    ///
    /// A node that is not in `scene`.
    pub fn apply(&self, scene: &mut Scene) -> Result<(), SceneError> {
        for (id, node) in &self.meshes {
            scene.set_content(*id, NodeContent::Mesh(node.clone()))?;
        }
        Ok(())
    }
}

/// The colour of `value` in the map over `range`: viridis from dark blue at the bottom to
/// yellow at the top, clamped at the ends; [`OUTSIDE`] for NaN.
pub fn value_colour(value: f64, range: [f64; 2]) -> [f32; 4] {
    if value.is_nan() {
        return OUTSIDE;
    }
    let span = range[1] - range[0];
    let t = if span > 0.0 {
        ((value - range[0]) / span).clamp(0.0, 1.0)
    } else {
        0.5
    };
    let c = colorous::VIRIDIS.eval_continuous(t);
    [
        f32::from(c.r) / 255.0,
        f32::from(c.g) / 255.0,
        f32::from(c.b) / 255.0,
        1.0,
    ]
}

/// The value range a contact map of `volume` spans: `window` where one was given; else, for CT,
/// -100 to 1000 HU (fat and soft tissue through cancellous to cortical bone, the classes'
/// span); else the volume's default grey window.
pub fn contact_range(volume: &crate::volume::CpuVolume, window: Option<[f32; 2]>) -> [f64; 2] {
    let [lo, hi] = match window {
        Some(w) => w,
        None if crate::classify::is_hounsfield(&volume.values) => return [-100.0, 1000.0],
        None => crate::classify::default_window(volume),
    };
    [f64::from(lo), f64::from(hi)]
}

/// The meshes of the object named `mesh` (the first where `None`) painted with the scene's
/// first volume over `range`.
///
/// # Errors
///
/// When the mesh or the volume is missing, the volume cannot be placed, or `range` does not
/// increase.
pub fn paint(scene: &Scene, mesh: Option<&str>, range: [f64; 2]) -> Result<Painted, ContactError> {
    if !(range[0].is_finite() && range[1].is_finite() && range[0] < range[1]) {
        return Err(ContactError::BadEdges(range.to_vec()));
    }
    let (top, _) = scene.mesh_object(mesh)?;
    let (_, volume_node, volume_world) = scene.volumes().next().ok_or(ContactError::NoVolume)?;
    let geometry = placed_geometry(&volume_node.volume, volume_world)?;
    let parts: Vec<(NodeId, &MeshNode, DMat4)> = scene
        .meshes()
        .filter(|(id, _, _)| scene.is_under(*id, top))
        .collect();
    let finest = volume_node.volume.finest_spacing();
    let mut step = finest;
    let count = |step: f64| -> u64 {
        parts
            .iter()
            .map(|(_, m, world)| {
                triangles(&m.mesh, *world)
                    .map(|(t, _)| cuts(&t, step).pow(2))
                    .sum::<u64>()
            })
            .sum()
    };
    let wanted = count(step);
    if wanted > MAX_PAINTED_TRIANGLES {
        step *= (wanted as f64 / MAX_PAINTED_TRIANGLES as f64).sqrt();
        while count(step) > MAX_PAINTED_TRIANGLES {
            step *= 1.1;
        }
    }
    let dims = geometry.dims().map(f64::from);
    let value_at = |world: DVec3| -> f64 {
        let k = geometry.world_to_index(world);
        // Inside the grid's box, half a voxel beyond the outer centres, as the contact report
        // counts it.
        let inside = (0..3).all(|i| k[i] >= -0.5 && k[i] <= dims[i] - 0.5);
        if inside {
            f64::from(volume_node.volume.trilinear(k.to_array()))
        } else {
            f64::NAN
        }
    };
    let meshes = parts
        .iter()
        .map(|(id, node, world)| {
            let mesh = painted_mesh(&node.mesh, *world, step, &value_at, range);
            let material = Material {
                base_color: [1.0, 1.0, 1.0, node.material.base_color[3]],
                ..node.material
            };
            (
                *id,
                MeshNode {
                    mesh: Arc::new(mesh),
                    material,
                },
            )
        })
        .collect();
    Ok(Painted {
        meshes,
        range,
        step_mm: step,
    })
}

/// The mesh's triangles in world coordinates, with their corners' indices.
fn triangles(mesh: &CpuMesh, world: DMat4) -> impl Iterator<Item = ([DVec3; 3], [usize; 3])> + '_ {
    mesh.indices.chunks_exact(3).filter_map(move |t| {
        let i = [t[0] as usize, t[1] as usize, t[2] as usize];
        let p = |k: usize| {
            mesh.positions
                .get(k)
                .map(|p| world.transform_point3(DVec3::from(p.map(f64::from))))
        };
        Some(([p(i[0])?, p(i[1])?, p(i[2])?], i))
    })
}

/// Pieces each edge of `t` is cut into: its longest edge over `step`, at least one.
fn cuts(t: &[DVec3; 3], step: f64) -> u64 {
    let longest = (t[1] - t[0])
        .length()
        .max((t[2] - t[1]).length())
        .max((t[0] - t[2]).length());
    if longest.is_finite() && step > 0.0 {
        ((longest / step).ceil() as u64).max(1)
    } else {
        1
    }
}

/// `mesh` cut finely, in its own coordinates, each vertex coloured by the value at its world
/// point; normals interpolated from the mesh's own where it has them.
fn painted_mesh(
    mesh: &CpuMesh,
    world: DMat4,
    step: f64,
    value_at: &dyn Fn(DVec3) -> f64,
    range: [f64; 2],
) -> CpuMesh {
    let mut out = CpuMesh::default();
    let has_normals = mesh.normals.len() == mesh.positions.len();
    for (w, i) in triangles(mesh, world) {
        let n = cuts(&w, step) as u32;
        let local = i.map(|k| glam::Vec3::from(mesh.positions[k]));
        let normal = i.map(|k| {
            if has_normals {
                glam::Vec3::from(mesh.normals[k])
            } else {
                glam::Vec3::ZERO
            }
        });
        // Vertex (a, b) of the grid: corner 0 plus a/n of the way to corner 1 and b/n to 2.
        let mut index = Vec::with_capacity(((n + 1) * (n + 2) / 2) as usize);
        for a in 0..=n {
            let mut row = Vec::with_capacity((n + 1 - a) as usize);
            for b in 0..=n - a {
                let (u, v) = (a as f32 / n as f32, b as f32 / n as f32);
                let p = local[0] + (local[1] - local[0]) * u + (local[2] - local[0]) * v;
                let q = normal[0] + (normal[1] - normal[0]) * u + (normal[2] - normal[0]) * v;
                let (ud, vd) = (f64::from(a) / f64::from(n), f64::from(b) / f64::from(n));
                let world_point = w[0] + (w[1] - w[0]) * ud + (w[2] - w[0]) * vd;
                row.push(out.positions.len() as u32);
                out.positions.push(p.to_array());
                out.normals.push(q.normalize_or_zero().to_array());
                out.colors.push(value_colour(value_at(world_point), range));
            }
            index.push(row);
        }
        for a in 0..n as usize {
            for b in 0..(n as usize - a) {
                let (p, q, r) = (index[a][b], index[a + 1][b], index[a][b + 1]);
                out.indices.extend([p, q, r]);
                if b + 1 < n as usize - a {
                    let s = index[a + 1][b + 1];
                    out.indices.extend([q, s, r]);
                }
            }
        }
    }
    if !has_normals {
        out.compute_normals();
    }
    out
}
