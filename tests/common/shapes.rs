//! Meshes whose sections and areas are known in closed form, for the tests that check
//! geometry against them, and a writer of OBJ files for the command line.

use std::sync::Arc;

use glam::{DMat4, DVec3};
use splatscene::classify::TransferFunction;
use splatscene::mesh::{CpuMesh, Material};
use splatscene::scene::{MeshNode, NodeContent, Scene, SceneCamera, SplatSettings, VolumeNode};
use splatscene::volume::CpuVolume;

/// A scene of `volume` (node "ct", ct-bone) and, where given, a mesh placed so (node "stem").
pub fn scene_of(volume: CpuVolume, mesh: Option<(CpuMesh, DMat4)>) -> Scene {
    let mut scene = Scene::new();
    let node = VolumeNode {
        volume: Arc::new(volume),
        transfer: Arc::new(TransferFunction::ct_bone()),
        splats: SplatSettings::default(),
    };
    scene
        .add("ct", DMat4::IDENTITY, None, NodeContent::Volume(node))
        .unwrap();
    if let Some((mesh, placed)) = mesh {
        let node = MeshNode {
            mesh: Arc::new(mesh),
            material: Material::default(),
        };
        scene
            .add("stem", placed, None, NodeContent::Mesh(node))
            .unwrap();
    }
    scene
}

/// Writes the values of `volume` as raw little-endian f32.
pub fn write_raw_f32(path: &std::path::Path, volume: &CpuVolume) {
    let bytes: Vec<u8> = volume.values.iter().flat_map(f32::to_le_bytes).collect();
    std::fs::write(path, bytes).unwrap();
}

/// A cube of side `side` centred on the origin, two triangles a face; the faces at the
/// negative end of each axis wound inward (as some files are).
pub fn cube(side: f32) -> CpuMesh {
    let h = side / 2.0;
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let base = positions.len() as u32;
            for (a, b) in [(-h, -h), (h, -h), (h, h), (-h, h)] {
                let mut p = [0.0; 3];
                p[axis] = sign * h;
                p[u] = a;
                p[v] = b;
                positions.push(p);
            }
            indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
        }
    }
    let mut mesh = CpuMesh {
        colors: Vec::new(),
        positions,
        normals: Vec::new(),
        indices,
    };
    mesh.compute_normals();
    mesh
}

/// A UV sphere of radius `r`.
pub fn sphere(r: f32, rings: u32, segments: u32) -> CpuMesh {
    let mut positions = Vec::new();
    for i in 0..=rings {
        let theta = std::f32::consts::PI * i as f32 / rings as f32;
        for j in 0..segments {
            let phi = std::f32::consts::TAU * j as f32 / segments as f32;
            positions.push([
                r * theta.sin() * phi.cos(),
                r * theta.sin() * phi.sin(),
                r * theta.cos(),
            ]);
        }
    }
    let mut indices = Vec::new();
    for i in 0..rings {
        for j in 0..segments {
            let a = i * segments + j;
            let b = i * segments + (j + 1) % segments;
            let (c, d) = (a + segments, b + segments);
            indices.extend([a, c, b, b, c, d]);
        }
    }
    let mut mesh = CpuMesh {
        colors: Vec::new(),
        positions,
        normals: Vec::new(),
        indices,
    };
    mesh.compute_normals();
    mesh
}

/// A closed cylinder of radius `r` from z = -`half_length` to `half_length` along z, its
/// side `segments` quads, its ends fans.
pub fn cylinder(r: f32, half_length: f32, segments: u32) -> CpuMesh {
    let mut positions = Vec::new();
    for z in [-half_length, half_length] {
        for j in 0..segments {
            let phi = std::f32::consts::TAU * j as f32 / segments as f32;
            positions.push([r * phi.cos(), r * phi.sin(), z]);
        }
    }
    let bottom = positions.len() as u32;
    positions.push([0.0, 0.0, -half_length]);
    positions.push([0.0, 0.0, half_length]);
    let top = bottom + 1;
    let mut indices = Vec::new();
    for j in 0..segments {
        let (a, b) = (j, (j + 1) % segments);
        let (c, d) = (a + segments, b + segments);
        // Outward: counter-clockwise seen from outside.
        indices.extend([a, b, d, a, d, c]);
        indices.extend([bottom, b, a]);
        indices.extend([top, c, d]);
    }
    let mut mesh = CpuMesh {
        colors: Vec::new(),
        positions,
        normals: Vec::new(),
        indices,
    };
    mesh.compute_normals();
    mesh
}

/// The same mesh with a vertex per triangle corner, as STL stores it.
pub fn unindexed(mesh: &CpuMesh) -> CpuMesh {
    let positions: Vec<[f32; 3]> = mesh
        .indices
        .iter()
        .map(|&i| mesh.positions[i as usize])
        .collect();
    let mut out = CpuMesh {
        colors: Vec::new(),
        indices: (0..positions.len() as u32).collect(),
        positions,
        normals: Vec::new(),
    };
    out.compute_normals();
    out
}

/// The mesh as an OBJ file's text.
pub fn obj_text(mesh: &CpuMesh) -> String {
    let mut obj = String::new();
    for p in &mesh.positions {
        obj.push_str(&format!("v {} {} {}\n", p[0], p[1], p[2]));
    }
    for t in mesh.indices.chunks(3) {
        obj.push_str(&format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1));
    }
    obj
}

/// A square in the plane y = `y`, spanning `lo..hi` in x and z, facing -y.
pub fn wall(y: f32, lo: f32, hi: f32) -> CpuMesh {
    let mut mesh = CpuMesh {
        colors: Vec::new(),
        positions: vec![[lo, y, lo], [hi, y, lo], [hi, y, hi], [lo, y, hi]],
        normals: Vec::new(),
        indices: vec![0, 1, 2, 0, 2, 3],
    };
    mesh.compute_normals();
    mesh
}

/// Adds `mesh` to `scene` at the identity as node `name`, opaque blue.
pub fn add_blue_mesh(scene: &mut Scene, name: &str, mesh: Arc<CpuMesh>) {
    let node = MeshNode {
        mesh,
        material: Material {
            base_color: [0.2, 0.5, 0.9, 1.0],
            ..Default::default()
        },
    };
    scene
        .add(name, DMat4::IDENTITY, None, NodeContent::Mesh(node))
        .unwrap();
}

/// A camera on the centre of `scene`'s bounds from (14, -42, 18) mm off it.
pub fn camera_of(scene: &Scene) -> SceneCamera {
    let centre = {
        let (lo, hi) = scene.bounds().unwrap();
        0.5 * (lo + hi)
    };
    SceneCamera::look_at(centre + DVec3::new(14.0, -42.0, 18.0), centre)
}
