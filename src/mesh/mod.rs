//! CPU meshes and their loaders (glTF 2.0, OBJ with MTL, STL), with no GPU involved.
//!
//! A file loads as a [`Model`]: a list of [`MeshPart`]s, each a triangle mesh in its own
//! coordinates with the transform that places it in the file's frame (a glTF node hierarchy is
//! flattened into these transforms) and a material.

use glam::DMat4;

/// An indexed triangle mesh in single precision (model coordinates, millimetres by convention).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CpuMesh {
    /// Vertex positions.
    pub positions: Vec<[f32; 3]>,
    /// Unit vertex normals, one per position.
    pub normals: Vec<[f32; 3]>,
    /// Triangle list: three indices into `positions` per triangle.
    pub indices: Vec<u32>,
}

impl CpuMesh {
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Axis-aligned bounds `(min, max)` of the positions, or `None` for an empty mesh.
    pub fn bounds(&self) -> Option<([f32; 3], [f32; 3])> {
        let first = *self.positions.first()?;
        Some(self.positions.iter().fold((first, first), |(lo, hi), p| {
            (
                std::array::from_fn(|a| lo[a].min(p[a])),
                std::array::from_fn(|a| hi[a].max(p[a])),
            )
        }))
    }

    /// Replaces the normals with area-weighted vertex normals computed from the triangles;
    /// vertices on no triangle (or only degenerate ones) get +z.
    pub fn compute_normals(&mut self) {
        let mut sums = vec![[0f64; 3]; self.positions.len()];
        for t in self.indices.chunks_exact(3) {
            let [a, b, c] = [t[0], t[1], t[2]].map(|i| {
                let p = self.positions[i as usize];
                glam::DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))
            });
            let n = (b - a).cross(c - a);
            for &i in t {
                let s = &mut sums[i as usize];
                s[0] += n.x;
                s[1] += n.y;
                s[2] += n.z;
            }
        }
        self.normals = sums
            .into_iter()
            .map(|s| {
                let n = glam::DVec3::from(s).try_normalize().unwrap_or(glam::DVec3::Z);
                [n.x as f32, n.y as f32, n.z as f32]
            })
            .collect();
    }
}

/// Surface appearance of a mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// Linear RGBA base colour (alpha is kept but meshes are drawn opaque).
    pub base_color: [f32; 4],
    /// Perceptual roughness in 0..1 (0 is mirror-like).
    pub roughness: f32,
    /// Metalness in 0..1.
    pub metallic: f32,
}

impl Default for Material {
    fn default() -> Self {
        Self {
            base_color: [0.8, 0.8, 0.8, 1.0],
            roughness: 0.6,
            metallic: 0.0,
        }
    }
}

/// One mesh of a model, placed in the model's frame.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshPart {
    /// Name from the file (node or object name), or a generated one.
    pub name: String,
    /// Part coordinates to model-file coordinates.
    pub transform: DMat4,
    /// The triangles.
    pub mesh: CpuMesh,
    /// Its material.
    pub material: Material,
}

/// What one mesh file holds.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Model {
    /// The meshes.
    pub parts: Vec<MeshPart>,
    /// Things the loader worked around (a missing MTL file, say), for the user to see.
    pub warnings: Vec<String>,
}
