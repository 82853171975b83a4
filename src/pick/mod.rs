//! Picking, with no GPU involved: the nearest hit of a ray over every mesh triangle (through an
//! obvhs BVH built over world-space triangles) and over the classified volumes (a voxel walk to
//! the first voxel above an opacity threshold).
//!
//! The BVH works in f32, so triangles are stored relative to the centre of the scene's bounds
//! (taken in f64): scenes far from the origin keep their precision. The hit distance is then
//! recomputed in f64 on the hit triangle.

use glam::{DVec3, Vec3A};
use obvhs::BvhBuildParams;
use obvhs::aabb::Aabb;
use obvhs::cwbvh::CwBvh;
use obvhs::cwbvh::builder::build_cwbvh;
use obvhs::ray::{Ray as BvhRay, RayHit};
use obvhs::triangle::Triangle;
use serde::Serialize;

use crate::render::ViewSetup;
use crate::scene::{ClipPlane, Clipping, NodeId, Scene, placed_geometry};

pub mod contact;
mod march;
pub mod measure;
pub mod paint;

pub use march::{first_surface, march_volume};

/// A ray in world space; `direction` is a unit vector, distances are world units along it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    /// Start point.
    pub origin: DVec3,
    /// Unit direction.
    pub direction: DVec3,
    /// Hits nearer than this are ignored (the near plane, for pixel rays).
    pub t_min: f64,
}

impl Ray {
    /// A ray from `origin` along `direction` (normalised here); `None` for a zero or
    /// non-finite direction or origin.
    pub fn new(origin: DVec3, direction: DVec3) -> Option<Self> {
        let direction = direction.try_normalize()?;
        origin.is_finite().then_some(Self {
            origin,
            direction,
            t_min: 0.0,
        })
    }

    /// The ray through pixel position `(x, y)` (pixel units from the top-left corner: the
    /// centre of pixel `(i, j)` is `(i + 0.5, j + 0.5)`), starting at the near plane as the
    /// renderer's does.
    pub fn through_pixel(view: &ViewSetup, x: f64, y: f64) -> Self {
        let (w, h) = (f64::from(view.size.0), f64::from(view.size.1));
        let (right, up, forward) = (view.axes.x_axis, view.axes.y_axis, view.axes.z_axis);
        let (sx, sy) = ((x - 0.5 * w) / view.focal, (0.5 * h - y) / view.focal);
        if view.is_orthographic() {
            Self {
                origin: view.camera.eye + sx * right + sy * up,
                direction: forward,
                t_min: view.near,
            }
        } else {
            let direction = (forward + sx * right + sy * up).normalize();
            Self {
                origin: view.camera.eye,
                direction,
                t_min: view.near / direction.dot(forward),
            }
        }
    }

    /// The point at distance `t`.
    pub fn at(&self, t: f64) -> DVec3 {
        self.origin + t * self.direction
    }
}

/// A ray hit on a mesh.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MeshHit {
    /// The mesh node.
    pub node: NodeId,
    /// Triangle index within the node's mesh.
    pub triangle: u32,
    /// World point.
    pub point: [f64; 3],
    /// Unit geometric normal facing the ray's origin.
    pub normal: [f64; 3],
    /// Distance along the ray.
    pub distance: f64,
}

/// A ray hit in a volume.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct VolumeHit {
    /// The volume node.
    pub node: NodeId,
    /// Voxel index coordinates.
    pub voxel: [u32; 3],
    /// World point where the ray enters the voxel.
    pub point: [f64; 3],
    /// The voxel's scalar value (Hounsfield units for CT).
    pub value: f32,
    /// Its opacity under the node's transfer function.
    pub opacity: f32,
    /// Distance along the ray.
    pub distance: f64,
}

/// The nearest hit of a pick.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Hit {
    /// A mesh triangle.
    Mesh(MeshHit),
    /// A voxel.
    Volume(VolumeHit),
}

impl Hit {
    /// Distance along the ray.
    pub fn distance(&self) -> f64 {
        match self {
            Self::Mesh(h) => h.distance,
            Self::Volume(h) => h.distance,
        }
    }

    /// World point.
    pub fn point(&self) -> DVec3 {
        DVec3::from_array(match self {
            Self::Mesh(h) => h.point,
            Self::Volume(h) => h.point,
        })
    }
}

impl Hit {
    /// The node hit.
    pub fn node(&self) -> NodeId {
        match self {
            Self::Mesh(h) => h.node,
            Self::Volume(h) => h.node,
        }
    }

    /// The hit as JSON, with the node's name, the frame and unit of its coordinates (`"frame":
    /// "RAS", "unit": "mm"`) and, for a voxel, the unit of its value (`"value_unit": "HU"` for
    /// CT in Hounsfield units, else `"file"`: whatever the file's values mean).
    pub fn to_json(&self, scene: &Scene) -> serde_json::Value {
        let mut value = serde_json::to_value(self).unwrap_or_default();
        let node = scene.node(self.node()).ok();
        if let Some(object) = value.as_object_mut() {
            object.insert("node_name".into(), serde_json::json!(node.map(|n| &n.name)));
            object.insert("frame".into(), "RAS".into());
            object.insert("unit".into(), "mm".into());
            if let Some(crate::scene::NodeContent::Volume(v)) = node.map(|n| &n.content) {
                let unit = if crate::classify::is_hounsfield(&v.volume.values) {
                    "HU"
                } else {
                    "file"
                };
                object.insert("value_unit".into(), unit.into());
            }
        }
        value
    }
}

/// The view distance (along the view axis) of every pixel's nearest volume surface: where the
/// opacity accumulated along the pixel's ray first reaches `threshold` (see [`first_surface`]),
/// nearer than `limits[pixel]` when given (the mesh depth, so that hidden voxels are not
/// walked). Row by row from the top; `None` where no volume reaches the threshold.
pub fn surface_distances(
    scene: &Scene,
    view: &ViewSetup,
    threshold: f32,
    limits: Option<&[Option<f64>]>,
) -> Vec<Option<f64>> {
    use rayon::prelude::*;
    let (w, h) = view.size;
    let forward = view.axes.z_axis;
    let volumes: Vec<_> = scene
        .volumes()
        .filter_map(|(_, node, world)| Some((node, placed_geometry(&node.volume, world).ok()?)))
        .collect();
    (0..w as usize * h as usize)
        .into_par_iter()
        .map(|i| {
            let (x, y) = ((i % w as usize) as f64 + 0.5, (i / w as usize) as f64 + 0.5);
            let ray = Ray::through_pixel(view, x, y);
            // Distances along this ray per unit of view distance.
            let along = ray.direction.dot(forward);
            let mut limit = limits
                .and_then(|l| l.get(i).copied().flatten())
                .map_or(f64::INFINITY, |d| d / along);
            let mut best = None;
            for (node, geometry) in &volumes {
                if let Some(t) =
                    first_surface(node, geometry, &ray, (threshold, limit), &scene.clipping)
                {
                    limit = t;
                    best = Some((ray.at(t) - view.camera.eye).dot(forward));
                }
            }
            best
        })
        .collect()
}

/// Picking options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PickOptions {
    /// A voxel is hit when its opacity exceeds this.
    pub opacity_threshold: f32,
    /// Whether volumes take part.
    pub volumes: bool,
}

impl Default for PickOptions {
    fn default() -> Self {
        Self {
            opacity_threshold: 0.1,
            volumes: true,
        }
    }
}

/// World triangles of every mesh in a BVH, rebuilt when the scene changes.
#[derive(Default)]
pub struct Picker {
    bvh: Option<CwBvh>,
    triangles: Vec<Triangle>,
    world: Vec<[DVec3; 3]>,
    owners: Vec<(NodeId, u32)>,
    centre: DVec3,
    /// World units per BVH unit: the BVH holds the scene scaled into about [-1, 1].
    scale: f64,
    generation: Option<u64>,
}

impl std::fmt::Debug for Picker {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Picker")
            .field("triangles", &self.triangles.len())
            .field("generation", &self.generation)
            .finish()
    }
}

impl Picker {
    /// A picker over `scene`'s meshes.
    pub fn new(scene: &Scene) -> Self {
        let mut picker = Self::default();
        picker.update(scene);
        picker
    }

    /// Rebuilds the BVH if the scene changed since the last build (a node moved, was added
    /// or changed content).
    pub fn update(&mut self, scene: &Scene) {
        if self.generation == Some(scene.generation()) {
            return;
        }
        self.generation = Some(scene.generation());
        self.centre = scene
            .bounds()
            .map_or(DVec3::ZERO, |(lo, hi)| 0.5 * (lo + hi));
        self.world.clear();
        self.owners.clear();
        for (id, node, world) in scene.meshes() {
            let p = |i: u32| {
                let v = node
                    .mesh
                    .positions
                    .get(i as usize)
                    .copied()
                    .unwrap_or_default();
                world.transform_point3(DVec3::from(v.map(f64::from)))
            };
            for (t, tri) in node.mesh.indices.chunks_exact(3).enumerate() {
                self.world.push([p(tri[0]), p(tri[1]), p(tri[2])]);
                self.owners.push((id, t as u32));
            }
        }
        // Centred and scaled to about [-1, 1]: f32 then keeps the same relative precision for
        // a scene at 1e5 mm as at the origin, and for one of 1e-5 mm as for one of metres
        // (obvhs has absolute epsilons that tiny scenes fall below).
        let extent = scene
            .bounds()
            .map_or(1.0, |(lo, hi)| 0.5 * (hi - lo).max_element());
        self.scale = if extent.is_normal() { extent } else { 1.0 };
        let (c, inv) = (self.centre, 1.0 / self.scale);
        let local = |v: DVec3| Vec3A::from(((v - c) * inv).as_vec3());
        self.triangles = self
            .world
            .iter()
            .map(|[a, b, d]| Triangle {
                v0: local(*a),
                v1: local(*b),
                v2: local(*d),
            })
            .collect();
        // Triangle boxes are padded by a hair of the scene size: a box of zero thickness (a
        // flat, axis-aligned patch) is otherwise missed by a ray along that axis after the
        // wide BVH's quantisation of child boxes. The padding only makes the BVH
        // conservative; hits still come from the exact triangle test.
        let pad = Vec3A::splat(1e-5);
        let boxes: Vec<Aabb> = self
            .triangles
            .iter()
            .map(|t| {
                let b = t.aabb();
                Aabb::new(b.min - pad, b.max + pad)
            })
            .collect();
        self.bvh = (!boxes.is_empty()).then(|| {
            build_cwbvh(
                &boxes,
                BvhBuildParams::medium_build(),
                &mut Default::default(),
            )
        });
    }

    /// Triangles in the BVH.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    fn bvh_ray(&self, ray: &Ray) -> BvhRay {
        let origin = Vec3A::from(((ray.origin - self.centre) / self.scale).as_vec3());
        // Adding zero turns -0.0 into +0.0: obvhs takes a zero component's sign for the
        // direction of travel, and rays along an axis came out of the traversal empty-handed.
        let direction = Vec3A::from(ray.direction.as_vec3()) + Vec3A::ZERO;
        BvhRay::new(
            origin,
            direction,
            (ray.t_min / self.scale) as f32,
            f32::INFINITY,
        )
    }

    /// The nearest mesh hit through the BVH.
    pub fn pick_mesh(&self, ray: &Ray) -> Option<MeshHit> {
        self.pick_mesh_clipped(ray, &Clipping::default())
    }

    /// The nearest mesh hit through the BVH that `clipping` keeps (hits on parts of meshes cut
    /// away by a plane or the crop box are passed through).
    pub fn pick_mesh_clipped(&self, ray: &Ray, clipping: &Clipping) -> Option<MeshHit> {
        let bvh = self.bvh.as_ref()?;
        let planes: Vec<ClipPlane> = clipping
            .all_planes()
            .into_iter()
            .filter(|p| p.meshes)
            .collect();
        let mut hit = RayHit::none();
        let found = bvh.ray_traverse(self.bvh_ray(ray), &mut hit, |r, id| {
            let t = self.triangles[bvh.primitive_indices[id] as usize].intersect(r);
            let at = || ray.at(f64::from(t) * self.scale);
            if planes.is_empty() || !t.is_finite() || planes.iter().all(|c| c.keeps(at())) {
                t
            } else {
                f32::INFINITY
            }
        });
        found.then(|| {
            self.mesh_hit(
                ray,
                bvh.primitive_indices[hit.primitive_id as usize] as usize,
                hit.t,
            )
        })
    }

    /// The nearest mesh hit by testing every triangle: the reference for [`Self::pick_mesh`].
    pub fn pick_mesh_brute_force(&self, ray: &Ray) -> Option<MeshHit> {
        let r = self.bvh_ray(ray);
        let (index, t) = self
            .triangles
            .iter()
            .enumerate()
            .map(|(i, tri)| (i, tri.intersect(&r)))
            .filter(|(_, t)| t.is_finite())
            .min_by(|a, b| a.1.total_cmp(&b.1))?;
        Some(self.mesh_hit(ray, index, t))
    }

    /// A hit on triangle `index` at BVH distance `t`, its distance and point refined in f64.
    fn mesh_hit(&self, ray: &Ray, index: usize, t: f32) -> MeshHit {
        let [a, b, c] = self.world[index];
        let n = (b - a).cross(c - a);
        let approx = f64::from(t) * self.scale;
        let exact = n.dot(a - ray.origin) / n.dot(ray.direction);
        // The f64 plane distance unless the triangle is too thin for it to be trusted.
        let close = (exact - approx).abs() <= 1e-3 * exact.abs().max(self.scale);
        let distance = if exact.is_finite() && close {
            exact
        } else {
            approx
        };
        let normal = n.try_normalize().unwrap_or(DVec3::Z);
        let facing = if normal.dot(ray.direction) > 0.0 {
            -normal
        } else {
            normal
        };
        let (node, triangle) = self.owners[index];
        MeshHit {
            node,
            triangle,
            point: ray.at(distance).to_array(),
            normal: facing.to_array(),
            distance,
        }
    }

    /// The nearest hit over meshes and (when `options.volumes`) volumes.
    pub fn pick(&self, scene: &Scene, ray: &Ray, options: &PickOptions) -> Option<Hit> {
        let mesh = self.pick_mesh_clipped(ray, &scene.clipping);
        let limit = mesh.map_or(f64::INFINITY, |h| h.distance);
        let mut best = mesh.map(Hit::Mesh);
        if options.volumes {
            for (id, node, world) in scene.volumes() {
                let Ok(geometry) = placed_geometry(&node.volume, world) else {
                    continue;
                };
                let best_distance = best.map_or(limit, |h| h.distance());
                let limits = (options.opacity_threshold, best_distance);
                if let Some(hit) = march_volume(id, node, &geometry, ray, limits, &scene.clipping) {
                    best = Some(Hit::Volume(hit));
                }
            }
        }
        best
    }

    /// The nearest hit through the centre of pixel `(x, y)` of `view`.
    pub fn pick_pixel(
        &self,
        scene: &Scene,
        view: &ViewSetup,
        x: u32,
        y: u32,
        options: &PickOptions,
    ) -> Option<Hit> {
        let ray = Ray::through_pixel(view, f64::from(x) + 0.5, f64::from(y) + 0.5);
        self.pick(scene, &ray, options)
    }
}
