//! Picking: the BVH against brute force over every triangle, on real meshes and adversarial
//! geometry; picks against the rendered depth buffer; the voxel walk against dense sampling.

use std::sync::Arc;

use glam::{DMat4, DVec3};
use splatscene::mesh::{CpuMesh, Material, load_mesh};
use splatscene::pick::{Hit, PickOptions, Picker, Ray};
use splatscene::render::{FrameOptions, GpuContext, Renderer};
use splatscene::scene::shoulder::{add_model, prosthesis_model, shoulder_scene};
use splatscene::scene::{MeshNode, NodeContent, Scene, placed_geometry};

mod common;

/// A small deterministic generator (xorshift), so that failures repeat.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    fn in_box(&mut self, lo: DVec3, hi: DVec3) -> DVec3 {
        DVec3::new(self.next(), self.next(), self.next()) * (hi - lo) + lo
    }
}

/// Random rays into the bounds, rays aimed exactly at vertices and edge midpoints (grazing),
/// and axis-parallel rays.
fn rays(scene: &Scene, count: usize, seed: u64) -> Vec<Ray> {
    let (lo, hi) = scene.bounds().expect("something to hit");
    let pad = (hi - lo).max_element().max(1e-300);
    let (outer_lo, outer_hi) = (lo - DVec3::splat(pad), hi + DVec3::splat(pad));
    let targets: Vec<DVec3> = scene
        .meshes()
        .flat_map(|(_, node, world)| {
            let p = |i: u32| {
                world.transform_point3(DVec3::from(node.mesh.positions[i as usize].map(f64::from)))
            };
            node.mesh
                .indices
                .chunks_exact(3)
                .flat_map(move |t| [p(t[0]), 0.5 * (p(t[0]) + p(t[1]))])
                .collect::<Vec<_>>()
        })
        .collect();
    let mut rng = Rng(seed);
    (0..count)
        .filter_map(|i| {
            let origin = rng.in_box(outer_lo, outer_hi);
            let target = match i % 4 {
                0 | 1 => rng.in_box(lo, hi),
                2 => targets[(rng.next() * targets.len() as f64) as usize % targets.len()],
                _ => {
                    let axis = [
                        DVec3::X,
                        DVec3::Y,
                        DVec3::Z,
                        -DVec3::X,
                        -DVec3::Y,
                        -DVec3::Z,
                    ][i / 4 % 6];
                    return Ray::new(rng.in_box(lo, hi) - axis * 2.0 * pad, axis);
                }
            };
            Ray::new(origin, target - origin)
        })
        .collect()
}

/// BVH and brute force agree on every ray: both miss, or both hit at the same distance.
fn check_against_brute_force(scene: &Scene, count: usize, seed: u64) -> usize {
    let picker = Picker::new(scene);
    let mut hits = 0;
    for (i, ray) in rays(scene, count, seed).iter().enumerate() {
        let (fast, slow) = (picker.pick_mesh(ray), picker.pick_mesh_brute_force(ray));
        match (fast, slow) {
            (None, None) => {}
            (Some(f), Some(s)) => {
                hits += 1;
                let tolerance = 1e-6 * f.distance.abs().max(s.distance.abs()).max(1e-300);
                assert!(
                    (f.distance - s.distance).abs() <= tolerance,
                    "ray {i} {ray:?}: BVH {f:?}, brute force {s:?}"
                );
            }
            _ => panic!("ray {i} {ray:?}: BVH {fast:?}, brute force {slow:?}"),
        }
    }
    hits
}

fn mesh_scene(meshes: &[(CpuMesh, DMat4)]) -> Scene {
    let mut scene = Scene::new();
    for (i, (mesh, at)) in meshes.iter().enumerate() {
        let node = MeshNode {
            mesh: Arc::new(mesh.clone()),
            material: Material::default(),
        };
        scene
            .add(format!("mesh {i}"), *at, None, NodeContent::Mesh(node))
            .unwrap();
    }
    scene
}

fn shoulder_bones(scale: f64, offset: DVec3) -> Option<Scene> {
    let dir = common::data_dir()
        .expect("the shared test data")
        .join("meshes/myosim_shoulder");
    if !dir.is_dir() {
        assert!(
            std::env::var_os("CI").is_none(),
            "{} is missing under CI: set SPLATSCENE_DATA",
            dir.display()
        );
        eprintln!(
            "skipped: no shoulder bones under {} (set SPLATSCENE_DATA)",
            dir.display()
        );
        return None;
    }
    // MyoHub myo_sim shoulder bones (from OpenSim MoBL-ARMS), Apache-2.0; units are metres.
    let mut meshes = Vec::new();
    for name in ["humerus", "scapula", "clavicle"] {
        let model = load_mesh(&dir.join(format!("{name}.stl"))).unwrap();
        for part in model.parts {
            let at = DMat4::from_translation(offset)
                * DMat4::from_scale(DVec3::splat(scale))
                * part.transform;
            meshes.push((part.mesh, at));
        }
    }
    Some(mesh_scene(&meshes))
}

#[test]
fn bvh_equals_brute_force_on_the_shoulder_bones_and_the_prosthesis() {
    let Some(mut scene) = shoulder_bones(1000.0, DVec3::ZERO) else {
        return;
    };
    add_model(
        &mut scene,
        "prosthesis",
        DMat4::from_translation(DVec3::new(0.0, 0.0, -150.0)),
        &prosthesis_model().unwrap(),
        None,
    );
    let hits = check_against_brute_force(&scene, 12_000, 7);
    assert!(hits > 3_000, "{hits} of 12000 rays hit");
}

#[test]
fn bvh_equals_brute_force_on_gltf_files() {
    let dir = common::data_dir()
        .expect("the shared test data")
        .join("gltf/gltf_rs");
    if !dir.is_dir() {
        assert!(
            std::env::var_os("CI").is_none(),
            "{} is missing under CI: set SPLATSCENE_DATA",
            dir.display()
        );
        eprintln!("skipped: no glTF files under {}", dir.display());
        return;
    }
    // gltf-rs test files (MIT/Apache-2.0).
    let mut meshes = Vec::new();
    for (i, name) in ["Box.gltf", "Box.glb"].iter().enumerate() {
        let model = load_mesh(&dir.join(name)).unwrap();
        for part in model.parts {
            meshes.push((
                part.mesh,
                DMat4::from_translation(DVec3::X * 1.5 * i as f64) * part.transform,
            ));
        }
    }
    let hits = check_against_brute_force(&mesh_scene(&meshes), 10_000, 11);
    assert!(hits > 2_000, "{hits}");
}

/// A grid of unit squares in z = 0 (shared edges and vertices everywhere) plus zero-area
/// triangles: one with a repeated vertex, one with three collinear vertices.
fn adversarial() -> CpuMesh {
    let mut mesh = CpuMesh::default();
    for j in 0..=8 {
        for i in 0..=8 {
            mesh.positions.push([i as f32, j as f32, 0.0]);
        }
    }
    for j in 0..8 {
        for i in 0..8 {
            let a = j * 9 + i;
            mesh.indices
                .extend_from_slice(&[a, a + 1, a + 10, a, a + 10, a + 9]);
        }
    }
    let n = mesh.positions.len() as u32;
    mesh.positions
        .extend_from_slice(&[[2.0, 2.0, 1.0], [3.0, 3.0, 1.0], [4.0, 4.0, 1.0]]);
    mesh.indices
        .extend_from_slice(&[n, n, n + 1, n, n + 1, n + 2]);
    mesh.compute_normals();
    mesh
}

#[test]
fn bvh_equals_brute_force_on_adversarial_geometry_at_any_scale() {
    for (scale, offset) in [
        (1.0, 0.0),
        (1e-5, 0.0),
        (1.0, 1e5),
        (1e-5, 1e5),
        (1e3, -1e5),
    ] {
        let at =
            DMat4::from_translation(DVec3::splat(offset)) * DMat4::from_scale(DVec3::splat(scale));
        let scene = mesh_scene(&[(adversarial(), at)]);
        let hits = check_against_brute_force(&scene, 10_000, 3);
        assert!(hits > 1_000, "scale {scale}, offset {offset}: {hits} hits");
    }
    if let Some(bones) = shoulder_bones(1000.0, DVec3::splat(1e5)) {
        check_against_brute_force(&bones, 4_000, 5);
    }
}

#[test]
fn empty_scenes_and_bad_rays_hit_nothing() {
    let picker = Picker::new(&Scene::new());
    let ray = Ray::new(DVec3::ZERO, DVec3::X).unwrap();
    assert_eq!(picker.pick_mesh(&ray), None);
    assert_eq!(
        picker.pick(&Scene::new(), &ray, &PickOptions::default()),
        None
    );
    assert!(Ray::new(DVec3::ZERO, DVec3::ZERO).is_none());
    assert!(Ray::new(DVec3::splat(f64::NAN), DVec3::X).is_none());
}

#[test]
fn a_grid_hit_is_exact_far_from_the_origin() {
    // The BVH is f32 relative to the scene centre; the distance is refined in f64.
    let at = DMat4::from_translation(DVec3::new(1e5, 1e5, 1e5));
    let scene = mesh_scene(&[(adversarial(), at)]);
    let picker = Picker::new(&scene);
    let ray = Ray::new(DVec3::new(1e5 + 3.25, 1e5 + 4.75, 1e5 + 10.0), -DVec3::Z).unwrap();
    let hit = picker.pick_mesh(&ray).unwrap();
    assert!((hit.distance - 10.0).abs() < 1e-9, "{hit:?}");
    assert_eq!(hit.normal, [0.0, 0.0, 1.0], "the normal faces the ray");
}

#[test]
fn the_bvh_follows_a_moved_node() {
    let mut scene = mesh_scene(&[(adversarial(), DMat4::IDENTITY)]);
    let mut picker = Picker::new(&scene);
    let ray = Ray::new(DVec3::new(3.5, 3.5, 10.0), -DVec3::Z).unwrap();
    assert!((picker.pick_mesh(&ray).unwrap().distance - 10.0).abs() < 1e-9);
    let id = scene.find("mesh 0").unwrap();
    scene
        .set_local(id, DMat4::from_translation(DVec3::Z * 4.0))
        .unwrap();
    picker.update(&scene);
    assert!((picker.pick_mesh(&ray).unwrap().distance - 6.0).abs() < 1e-9);
}

#[test]
fn picks_agree_with_the_rendered_depth() {
    let scene = shoulder_scene().unwrap();
    let camera = scene.camera.unwrap();
    let size = (160, 120);
    let ctx = GpuContext::headless().expect("a GPU adapter (install mesa-vulkan-drivers)");
    let options = FrameOptions {
        measure: false,
        ..Default::default()
    };
    let shot = Renderer::new()
        .screenshot(&ctx, &scene, &camera, size, &options)
        .unwrap();
    let picker = Picker::new(&scene);
    let meshes_only = PickOptions {
        volumes: false,
        ..Default::default()
    };
    let (mut compared, mut hits) = (0, 0);
    for y in 0..size.1 {
        for x in 0..size.0 {
            let depth = shot.depth[(y * size.0 + x) as usize];
            let picked = picker.pick_pixel(&scene, &shot.view, x, y, &meshes_only);
            let Some(Hit::Mesh(hit)) = picked else {
                assert!(
                    depth == 0.0 || edge_pixel(&shot.depth, size, x, y),
                    "({x}, {y}): drawn but not picked"
                );
                continue;
            };
            hits += 1;
            let Some(drawn) = shot.view.distance_of(depth) else {
                assert!(
                    edge_pixel(&shot.depth, size, x, y),
                    "({x}, {y}): picked but not drawn"
                );
                continue;
            };
            // Compare distances along the view axis; rasterised depth is interpolated in f32.
            let along = (DVec3::from_array(hit.point) - camera.eye).dot(shot.view.axes.z_axis);
            if !edge_pixel(&shot.depth, size, x, y) {
                compared += 1;
                assert!(
                    (along - drawn).abs() < 1e-3 * drawn,
                    "({x}, {y}): pick {along}, depth {drawn}"
                );
            }
        }
    }
    assert!(
        hits > 100 && compared > 100,
        "{hits} hits, {compared} compared"
    );
}

/// Where `ray` enters and leaves voxel `k`'s cell (`k - 0.5 .. k + 0.5` in index space).
fn voxel_span(
    geometry: &splatscene::order::VolumeGeometry,
    ray: &Ray,
    k: [u32; 3],
) -> Option<(f64, f64)> {
    let o = geometry.world_to_index(ray.origin);
    let d = geometry.world_dir_to_index(ray.direction);
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    for a in 0..3 {
        let (lo, hi) = (f64::from(k[a]) - 0.5, f64::from(k[a]) + 0.5);
        if d[a] == 0.0 {
            if o[a] < lo || o[a] > hi {
                return None;
            }
            continue;
        }
        let (ta, tb) = ((lo - o[a]) / d[a], (hi - o[a]) / d[a]);
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
    }
    (t0 <= t1).then_some((t0, t1))
}

/// Whether a pixel borders the silhouette of the meshes, where one sample can go either way.
fn edge_pixel(depth: &[f32], size: (u32, u32), x: u32, y: u32) -> bool {
    let at = |x: i64, y: i64| {
        let (x, y) = (
            x.clamp(0, i64::from(size.0) - 1),
            y.clamp(0, i64::from(size.1) - 1),
        );
        depth[(y as u32 * size.0 + x as u32) as usize]
    };
    let (x, y) = (i64::from(x), i64::from(y));
    let centre = at(x, y);
    [(-1, 0), (1, 0), (0, -1), (0, 1)].iter().any(|(dx, dy)| {
        let n = at(x + dx, y + dy);
        (n == 0.0) != (centre == 0.0) || (n - centre).abs() > 0.02 * centre.abs().max(1e-6)
    })
}

#[test]
fn the_voxel_walk_finds_the_first_opaque_voxel_as_dense_sampling_does() {
    let scene = shoulder_scene().unwrap();
    let (_, node, world) = scene.volumes().next().unwrap();
    let geometry = placed_geometry(&node.volume, world).unwrap();
    let picker = Picker::new(&scene);
    let options = PickOptions::default();
    let (lo, hi) = scene.bounds().unwrap();
    let mut rng = Rng(99);
    let mut found = 0;
    for _ in 0..300 {
        let origin = rng.in_box(lo - DVec3::splat(60.0), hi + DVec3::splat(60.0));
        let ray = Ray::new(origin, rng.in_box(lo, hi) - origin).unwrap();
        let walked = splatscene::pick::march_volume(
            scene.find("shoulder CT").unwrap(),
            node,
            &geometry,
            &ray,
            (options.opacity_threshold, f64::INFINITY),
            &scene.clipping,
        );
        // Reference: sample the ray every 0.02 mm and take the voxel containing each sample.
        let dims = geometry.dims();
        let mut reference = None;
        let mut t = 0.0;
        while t < 600.0 && reference.is_none() {
            let k = geometry.world_to_index(ray.at(t)) + DVec3::splat(0.5);
            let inside = (0..3).all(|a| k[a] >= 0.0 && k[a] < f64::from(dims[a]));
            if inside {
                let v = k.floor().as_uvec3();
                let id = (v.x + dims[0] * (v.y + dims[1] * v.z)) as usize;
                if node.transfer.sample(node.volume.values.at(id))[3] > options.opacity_threshold {
                    reference = Some(([v.x, v.y, v.z], t));
                }
            }
            t += 0.02;
        }
        match (walked, reference) {
            (None, None) => {}
            (Some(w), reference) => {
                found += 1;
                assert!(
                    w.opacity > options.opacity_threshold && w.value > 150.0,
                    "{w:?}"
                );
                // The walk enters its voxel where it says, and nothing sampled before is opaque.
                let (t_in, t_out) =
                    voxel_span(&geometry, &ray, w.voxel).expect("the ray crosses the voxel");
                assert!(
                    (t_in.max(ray.t_min) - w.distance).abs() < 1e-6,
                    "{ray:?}: enters at {t_in}, reported {w:?}"
                );
                match reference {
                    Some((voxel, t)) if voxel == w.voxel => {
                        assert!(t - w.distance < 0.03, "{t} against {w:?}")
                    }
                    // Sampling every 0.02 mm may step over a corner the ray only grazes.
                    Some((_, t)) => assert!(
                        t_out - t_in < 0.02 && t >= w.distance,
                        "{ray:?}: {w:?} then {t}"
                    ),
                    None => assert!(t_out - t_in < 0.02, "{ray:?}: only the walk finds {w:?}"),
                }
            }
            (None, Some(r)) => panic!("{ray:?}: sampling finds {r:?}, the walk nothing"),
        }
    }
    assert!(found > 50, "{found} rays hit bone");
    // Mixed picks from the built-in camera: toward the prosthesis head the metal is nearest;
    // toward the glenoid, bone.
    let marks = splatscene::volume::shoulder_landmarks(
        splatscene::volume::phantom::DEFAULT_DIMS,
        splatscene::volume::phantom::DEFAULT_SPACING,
    );
    let eye = scene.camera.unwrap().eye;
    let toward = |p: [f64; 3]| Ray::new(eye, DVec3::from_array(p) - eye).unwrap();
    let head = picker.pick(&scene, &toward(marks.head_centre), &options);
    assert!(matches!(head, Some(Hit::Mesh(_))), "{head:?}");
    let glenoid = picker.pick(&scene, &toward(marks.glenoid_centre), &options);
    let Some(Hit::Volume(bone)) = glenoid else {
        panic!("{glenoid:?}");
    };
    assert!(
        bone.value > 150.0
            && bone.distance < (DVec3::from_array(marks.glenoid_centre) - eye).length() + 5.0
    );
}

#[test]
fn picks_pass_through_what_clipping_cuts_away() {
    let mut scene = shoulder_scene().unwrap();
    let marks = splatscene::volume::shoulder_landmarks(
        splatscene::volume::phantom::DEFAULT_DIMS,
        splatscene::volume::phantom::DEFAULT_SPACING,
    );
    let head = DVec3::from_array(marks.head_centre);
    let eye = scene.camera.unwrap().eye;
    let ray = Ray::new(eye, head - eye).unwrap();
    let picker = Picker::new(&scene);
    let options = PickOptions::default();
    let Some(Hit::Mesh(first)) = picker.pick(&scene, &ray, &options) else {
        panic!("the prosthesis head is in front");
    };
    // Cut away everything nearer to the eye than 5 mm in front of the head centre, meshes too.
    let toward_eye = (eye - head).normalize();
    scene
        .clipping
        .planes
        .push(splatscene::scene::ClipPlane::through(
            head + 5.0 * toward_eye,
            toward_eye,
            true,
        ));
    let behind = picker
        .pick(&scene, &ray, &options)
        .expect("something behind the cut");
    assert!(
        behind.distance() > first.distance + 10.0,
        "{behind:?} after {first:?}"
    );
    assert!(
        scene.clipping.keeps_mesh(behind.point()) && scene.clipping.keeps_splat(behind.point())
    );
}
