//! What the tests share: running the command line, scratch folders and the shared data
//! ([`files`]), test volumes and the reference frame (here), a plain ray marcher
//! ([`raymarch`]) and picture measures ([`pictures`]).

#![allow(dead_code)]

pub mod files;
pub mod pictures;
pub mod raymarch;
pub mod shapes;

#[allow(unused_imports)]
pub use files::{
    Scratch, command, data_dir, data_file, fails, have, ok, repo, scratch, splatscene, stderr,
};

use std::sync::Arc;

use glam::{DMat3, DMat4, DVec3};
use splatscene::camera::Camera;
use splatscene::classify::{TransferFunction, classify, view_step_mm};
use splatscene::order::{OrderOptions, Orderer, Ordering, ViewCase};
use splatscene::scene::{NodeContent, Scene, SceneCamera, SplatSettings, VolumeNode};
use splatscene::splat::reference::{Frame, SplatStyle, SplatVolume, composite};
use splatscene::volume::CpuVolume;

/// Whether this machine has a GPU device file, by the rule the automatic compositor states
/// (`GpuContext::hardware_may_exist`), written out again here: anything in `/dev/dri`, or a
/// `/dev/nvidia*`, `/dev/dxg` or `/dev/kfd`. Where one exists, `--compositor auto` looks for
/// an adapter even for volumes alone.
pub fn gpu_device_file() -> bool {
    std::fs::read_dir("/dev").map_or(true, |entries| {
        entries.flatten().any(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            match name.as_str() {
                "dri" => std::fs::read_dir(e.path()).map_or(true, |mut d| d.next().is_some()),
                "dxg" | "kfd" => true,
                other => other.starts_with("nvidia"),
            }
        })
    })
}

/// Nested shells of "bone" in an n^3 grid (denser outside).
pub fn shells(n: u32, spacing: [f64; 3]) -> CpuVolume {
    let c = (f64::from(n) - 1.0) / 2.0;
    let r_out = c;
    let values = (0..n * n * n)
        .map(|id| {
            let (x, y, z) = (id % n, id / n % n, id / n / n);
            let r = DVec3::new(f64::from(x) - c, f64::from(y) - c, f64::from(z) - c).length();
            match r / r_out {
                r if r > 0.98 => -1000.0,
                r if r > 0.82 => 1300.0,
                r if r > 0.45 => 400.0 + 40.0 * (id % 7) as f32,
                _ => 40.0,
            }
        })
        .collect();
    CpuVolume {
        dims: [n; 3],
        spacing,
        origin: [0.0; 3],
        direction: DMat3::IDENTITY,
        values,
    }
}

pub fn volume_scene(volume: CpuVolume, ordering: Ordering) -> Scene {
    let mut scene = Scene::new();
    let node = VolumeNode {
        volume: Arc::new(volume),
        transfer: Arc::new(TransferFunction::ct_bone()),
        // Flat colours: the CPU reference compositor does not shade.
        splats: SplatSettings {
            ordering,
            shading: 0.0,
            ..Default::default()
        },
    };
    scene
        .add("volume", DMat4::IDENTITY, None, NodeContent::Volume(node))
        .unwrap();
    scene
}

/// Shells with CT-like spacing (0.7, 0.7, 2.5), turned about z and x and placed at
/// (100, -50, 30) mm: the patient-orientation case.
pub fn rotated_anisotropic() -> CpuVolume {
    let mut volume = shells(20, [0.7, 0.7, 2.5]);
    volume.direction = DMat3::from_rotation_z(0.5) * DMat3::from_rotation_x(0.35);
    volume.origin = [100.0, -50.0, 30.0];
    volume
}

/// The CPU reference compositor's frame of `volume` (classified with the CT bone preset, in the
/// GPU's 8-bit colours) through `pinhole`, splats in `ordering` with those behind the eye left
/// out as the renderer leaves them; and the number of splats drawn.
pub fn reference_frame(volume: &CpuVolume, pinhole: &Camera, ordering: Ordering) -> (Frame, usize) {
    let geometry = volume.geometry().unwrap();
    let classified = classify(volume, &TransferFunction::ct_bone(), 1.0 / 255.0).unwrap();
    let step = view_step_mm(
        geometry.index_to_world().matrix3,
        pinhole.target - pinhole.eye,
    )
    .unwrap();
    let colors = classified.premultiplied(step as f32);
    let view = ViewCase::new(&geometry, pinhole.eye, pinhole.target).unwrap();
    let mut ids = Vec::new();
    let options = OrderOptions {
        cull_behind_eye: true,
        ..Default::default()
    };
    Orderer::new()
        .order(&classified.grid, &view, ordering, &options, &mut ids)
        .unwrap();
    let splats = SplatVolume {
        geometry: &geometry,
        grid: &classified.grid,
        colors: &colors,
    };
    let (frame, _) = composite(pinhole, &splats, &ids, &SplatStyle::default()).unwrap();
    (frame, ids.len())
}

/// The views two compositors are held to each other on: shaded shells in perspective and
/// orthographic, a rotated anisotropic volume far from the origin, a clip plane, and a wall
/// through, in front of and behind the shells; each with its name and camera.
pub fn compositor_cases() -> Vec<(&'static str, Scene, SceneCamera)> {
    use glam::DVec3;
    use shapes::{add_blue_mesh, camera_of, wall};
    use splatscene::scene::{ClipPlane, Projection};
    let mut shaded = volume_scene(shells(20, [1.0, 1.0, 1.5]), Ordering::IpPbtfImplicit);
    let (id, node, _) = shaded.volumes().next().unwrap();
    let mut node = node.clone();
    node.splats.shading = 1.0;
    shaded.set_content(id, NodeContent::Volume(node)).unwrap();
    let camera = camera_of(&shaded);
    let ortho = SceneCamera {
        projection: Projection::Orthographic { height: 40.0 },
        ..camera
    };
    let rotated = volume_scene(rotated_anisotropic(), Ordering::Bucketed);
    let rotated_camera = camera_of(&rotated);
    // (At offset 12 the refined grid drawn here differed at 0.3% of the pixels, by up to
    // 0.068, as a splat centre within f32 rounding of the plane, kept by one compositor and
    // cut by the other, would; the plane is moved off the grid's quarter-millimetre lattice.)
    let mut clipped = volume_scene(shells(20, [1.0; 3]), Ordering::Pbtf);
    clipped.clipping.planes.push(ClipPlane {
        normal: DVec3::new(1.0, 0.3, 0.0),
        offset: 12.03,
        meshes: false,
    });
    let clipped_camera = camera_of(&clipped);
    let mut cases = vec![
        ("perspective", shaded.clone(), camera),
        ("orthographic", shaded, ortho),
        ("rotated anisotropic", rotated, rotated_camera),
        ("clipped", clipped, clipped_camera),
    ];
    // A wall through the middle hides the splats behind it; one in front of the volume hides
    // all it covers, one behind hides none.
    let walls_camera = camera_of(&volume_scene(shells(20, [1.0; 3]), Ordering::Exact));
    for (name, y) in [("through", 9.5), ("in front", -3.0), ("behind", 25.0)] {
        let mut scene = volume_scene(shells(20, [1.0; 3]), Ordering::IpPbtfImplicit);
        add_blue_mesh(&mut scene, "wall", Arc::new(wall(y, 4.0, 15.0)));
        cases.push((name, scene, walls_camera));
    }
    cases
}

/// A real volume alone, seen as `benches/compositors.rs` and the VTK peer script see it: fitted
/// to its bounds looking along (-0.4, 1, -0.55), for an image of width over height `aspect`.
pub fn benchmark_view(
    volume: CpuVolume,
    transfer: TransferFunction,
    aspect: f64,
) -> (Scene, SceneCamera) {
    let mut scene = Scene::new();
    // Opacities per half millimetre: about the look these views had when a splat took the
    // ramp's opacity at its centre (a 1 mm voxel's splat now carries 1 / 1.87 mm of tissue's,
    // `2 pi sigma^2` of the default splat).
    let node = VolumeNode {
        volume: Arc::new(volume),
        transfer: Arc::new(transfer),
        splats: SplatSettings {
            opacity_reference_mm: 0.5,
            ..Default::default()
        },
    };
    scene
        .add("volume", DMat4::IDENTITY, None, NodeContent::Volume(node))
        .unwrap();
    let camera = SceneCamera::fit(
        scene.bounds().unwrap(),
        DVec3::new(-0.4, 1.0, -0.55),
        Default::default(),
        aspect,
    );
    (scene, camera)
}

/// The GE engine block (Open SciVis datasets, General Electric; 1.05M splats with its
/// benchmark ramp) in [`benchmark_view`] for `aspect`; `None` without the shared data.
pub fn engine_view(aspect: f64) -> Option<(Scene, SceneCamera)> {
    let path = data_file("volumes/engine/engine_256x256x128_uint8.raw")?;
    let spec = splatscene::volume::RawSpec::new(
        [256, 256, 128],
        splatscene::volume::ScalarType::U8,
        splatscene::volume::ByteOrder::Little,
    );
    let volume = splatscene::volume::load_raw(&path, &spec).unwrap();
    Some(benchmark_view(
        volume,
        TransferFunction::ramp(100.0, 200.0, [0.85, 0.8, 0.75, 0.5]),
        aspect,
    ))
}

/// A 128^3 grid of 1 mm voxels holding a translucent field of soft blobs and a denser shell,
/// with a colour ramp: much of its depth shows through.
pub fn translucent_blobs() -> Scene {
    let n = 128u32;
    let values: Vec<f32> = (0..n * n * n)
        .map(|id| {
            let k = [id % n, id / n % n, id / n / n].map(f64::from);
            let blobs = (k[0] / 7.0).sin() * (k[1] / 9.0).sin() * (k[2] / 11.0).sin();
            let r = glam::DVec3::from(k.map(|c| c - 63.5)).length();
            let shell = if (40.0..44.0).contains(&r) {
                300.0
            } else {
                0.0
            };
            (200.0 + 250.0 * blobs + shell) as f32
        })
        .collect();
    let volume = splatscene::volume::CpuVolume {
        dims: [n; 3],
        spacing: [1.0; 3],
        origin: [0.0; 3],
        direction: glam::DMat3::IDENTITY,
        values: values.into(),
    };
    let transfer = TransferFunction::new(vec![
        (250.0, [0.9, 0.5, 0.3, 0.0]),
        (450.0, [1.0, 0.9, 0.7, 0.03]),
        (600.0, [0.9, 0.9, 1.0, 0.3]),
    ]);
    shaded_scene(volume, transfer)
}

/// A scene of `volume` alone, classified by `transfer` and shaded (0.8) as the renderer shades
/// by default.
pub fn shaded_scene(volume: CpuVolume, transfer: TransferFunction) -> Scene {
    let mut scene = Scene::new();
    let node = VolumeNode {
        volume: Arc::new(volume),
        transfer: Arc::new(transfer),
        splats: SplatSettings {
            shading: 0.8,
            ..Default::default()
        },
    };
    scene
        .add("volume", DMat4::IDENTITY, None, NodeContent::Volume(node))
        .unwrap();
    scene
}

/// Looking along the z axis of [`translucent_blobs`] from `distance` mm before its face, at 50
/// degrees.
pub fn before_the_blobs(distance: f64) -> SceneCamera {
    SceneCamera {
        eye: glam::DVec3::new(63.5, 60.0, -distance),
        target: glam::DVec3::new(63.5, 66.0, 64.0),
        up: glam::DVec3::Y,
        projection: splatscene::scene::Projection::Perspective {
            fov_y_degrees: 50.0,
        },
        near: None,
    }
}

/// Looking at the centre of [`translucent_blobs`] from an oblique eye beyond one corner of its
/// face, at 50 degrees.
pub fn across_the_blobs() -> SceneCamera {
    SceneCamera {
        projection: splatscene::scene::Projection::Perspective {
            fov_y_degrees: 50.0,
        },
        ..SceneCamera::look_at(
            DVec3::new(-40.0, 150.0, -30.0),
            DVec3::new(63.5, 63.5, 63.5),
        )
    }
}
