//! Picking: building the BVH over a mesh of about a million triangles, and picking through it
//! (random rays from outside toward the mesh), against testing every triangle.
//!
//! `cargo bench --bench picking`

use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::{DMat4, DVec3};
use splatscene::mesh::{CpuMesh, Material};
use splatscene::pick::{Picker, Ray};
use splatscene::scene::{MeshNode, NodeContent, Scene};

/// A bumpy sphere of `2 * n * n` triangles (radius about 50 mm).
fn bumpy_sphere(n: u32) -> CpuMesh {
    let mut mesh = CpuMesh::default();
    for i in 0..=n {
        let theta = std::f64::consts::PI * f64::from(i) / f64::from(n);
        for j in 0..=n {
            let phi = 2.0 * std::f64::consts::PI * f64::from(j) / f64::from(n);
            let r = 50.0 + 2.0 * (7.0 * theta).sin() * (5.0 * phi).cos();
            let p = r * DVec3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            );
            mesh.positions.push(p.as_vec3().to_array());
        }
    }
    for i in 0..n {
        for j in 0..n {
            let a = i * (n + 1) + j;
            let b = a + n + 1;
            mesh.indices
                .extend_from_slice(&[a, b, a + 1, a + 1, b, b + 1]);
        }
    }
    mesh.compute_normals();
    mesh
}

fn scene(mesh: CpuMesh) -> Scene {
    let mut scene = Scene::new();
    let node = MeshNode {
        mesh: Arc::new(mesh),
        material: Material::default(),
    };
    scene
        .add("sphere", DMat4::IDENTITY, None, NodeContent::Mesh(node))
        .unwrap();
    scene
}

fn rays(count: usize) -> Vec<Ray> {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    (0..count)
        .filter_map(|_| {
            let origin = DVec3::new(next(), next(), next()).normalize_or(DVec3::X) * 200.0;
            let target = DVec3::new(next(), next(), next()) * 40.0;
            Ray::new(origin, target - origin)
        })
        .collect()
}

fn picking(c: &mut Criterion) {
    let scene = scene(bumpy_sphere(708));
    let triangles = Picker::new(&scene).triangle_count();
    eprintln!("{triangles} triangles");
    let mut group = c.benchmark_group(format!("pick/{triangles}-triangles"));
    group
        .sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(8));
    group.bench_function("build", |b| b.iter(|| black_box(Picker::new(&scene))));
    let picker = Picker::new(&scene);
    let rays = rays(1000);
    group.bench_function("1000 picks", |b| {
        b.iter(|| {
            rays.iter()
                .filter(|r| picker.pick_mesh(r).is_some())
                .count()
        })
    });
    group.bench_function("10 brute-force picks", |b| {
        b.iter(|| {
            rays[..10]
                .iter()
                .filter(|r| picker.pick_mesh_brute_force(r).is_some())
                .count()
        })
    });
    group.finish();
}

criterion_group!(benches, picking);
criterion_main!(benches);
