//! The CPU tile compositor against the GPU splat pass (on whatever adapter wgpu finds,
//! lavapipe in CI) and against the CPU reference compositor: the same splats in the same
//! order must give the same picture, with meshes in front of and behind them, clip planes, a
//! rotated anisotropic volume and an orthographic camera; early termination leaves out at most
//! what its threshold allows; the command line picks the CPU on a CPU adapter.

use splatscene::classify::TransferFunction;
use splatscene::order::Ordering;
use splatscene::render::{Compositor, FrameOptions, GpuContext, Renderer, Screenshot};
use splatscene::scene::{NodeContent, Projection, Scene, SceneCamera};
use splatscene::splat::reference::{Frame, ImageDifference, SplatStyle, compare};

mod common;
use common::shapes::camera_of;
use common::{
    across_the_blobs, before_the_blobs, benchmark_view, compositor_cases, data_file, engine_view,
    reference_frame, shaded_scene, shells, translucent_blobs, volume_scene,
};

fn context() -> GpuContext {
    GpuContext::headless().expect("a GPU adapter (install mesa-vulkan-drivers)")
}

const OPTIONS: FrameOptions = FrameOptions {
    ordering: None,
    background: Some([0.05, 0.05, 0.1]),
    measure: false,
    preview: 0,
    volume_divisor: 1,
};

fn shoot(
    ctx: &GpuContext,
    compositor: Compositor,
    scene: &Scene,
    camera: &SceneCamera,
    size: (u32, u32),
) -> Frame {
    let mut renderer = Renderer::with_compositor(compositor);
    // One level a volume (drawn brick by brick in
    // `the_splat_pass_draws_the_mix_the_tiles_draw`).
    renderer.set_levels_by_brick(false);
    renderer
        .screenshot(ctx, scene, camera, size, &OPTIONS)
        .unwrap()
        .frame
}

/// What the two compositors may differ by: the GPU blends in 32-bit float where it can (else
/// 16-bit), the tiles in f32, over the same f32 footprints (see `assert_matches_reference` in tests/render_gpu.rs for the
/// edge jump between f32 and f64 footprints, which the reference adds).
fn assert_alike(d: &ImageDifference, what: &str) {
    let style = SplatStyle::default();
    let edge_jump = (-0.5 * (style.cutoff / style.sigma).powi(2)).exp();
    assert!(d.rmse < 0.002, "{what}: {d:?}");
    assert!(d.max_abs < edge_jump + 3.0 / 255.0, "{what}: {d:?}");
}

fn gpu_against_tiles(scene: &Scene, camera: &SceneCamera, what: &str) -> ImageDifference {
    gpu_against_tiles_at(scene, camera, (96, 80), what)
}

fn gpu_against_tiles_at(
    scene: &Scene,
    camera: &SceneCamera,
    size: (u32, u32),
    what: &str,
) -> ImageDifference {
    let ctx = context();
    let gpu = shoot(&ctx, Compositor::Gpu, scene, camera, size);
    let cpu = shoot(&ctx, Compositor::Cpu, scene, camera, size);
    let covered = gpu
        .pixels
        .iter()
        .zip(&cpu.pixels)
        .filter(|(a, b)| (a[0] - b[0]).abs() > 0.0 || a[3] > 0.0)
        .count();
    assert!(covered > 100, "{what}: the scene shows");
    let d = compare(&gpu, &cpu).unwrap();
    assert_alike(&d, what);
    d
}

#[test]
fn tiles_draw_what_the_gpu_draws() {
    for (name, scene, camera) in compositor_cases() {
        gpu_against_tiles(&scene, &camera, name);
    }
}

#[test]
fn tiles_match_the_cpu_reference_compositor() {
    let ctx = context();
    let volume = shells(20, [1.0, 1.0, 1.5]);
    let scene = volume_scene(volume.clone(), Ordering::IpPbtfImplicit);
    let camera = camera_of(&scene);
    let transparent = FrameOptions {
        background: None,
        ..OPTIONS
    };
    // The reference composites the volume's own grid.
    let mut renderer = Renderer::with_compositor(Compositor::Cpu);
    renderer.set_level_of_detail(false);
    let shot = renderer
        .screenshot(&ctx, &scene, &camera, (96, 80), &transparent)
        .unwrap();
    let (reference, drawn) = reference_frame(
        &volume,
        &shot.view.pinhole().unwrap(),
        Ordering::IpPbtfImplicit,
    );
    let d = compare(&shot.frame, &reference).unwrap();
    assert_alike(&d, "reference");
    let tiles = shot.report.tiles.expect("composited on the CPU");
    assert_eq!(tiles.splats, drawn);
}

#[test]
fn early_termination_leaves_out_no_more_than_its_threshold() {
    let ctx = context();
    // A dense, nearly opaque block: most splats lie behind opaque pixels.
    let mut volume = shells(24, [1.0; 3]);
    volume
        .values
        .make_f32()
        .iter_mut()
        .for_each(|v| *v = 1800.0);
    let mut scene = volume_scene(volume, Ordering::IpPbtfImplicit);
    // Opacity 0.8 per quarter millimetre: each 1 mm splat nearly opaque.
    let id = scene.find("volume").unwrap();
    let NodeContent::Volume(mut node) = scene.node(id).unwrap().content.clone() else {
        unreachable!()
    };
    node.splats.opacity_reference_mm = 0.25;
    scene.set_content(id, NodeContent::Volume(node)).unwrap();
    let camera = camera_of(&scene);
    // The own grid, whose 1 mm splats are each nearly opaque (a refined one's are not).
    let mut stopping = Renderer::with_compositor(Compositor::Cpu);
    let mut full = Renderer::with_compositor(Compositor::Cpu);
    stopping.set_level_of_detail(false);
    full.set_level_of_detail(false);
    full.tile_compositor_mut().opaque = 2.0;
    let a = stopping
        .screenshot(&ctx, &scene, &camera, (96, 80), &OPTIONS)
        .unwrap();
    let b = full
        .screenshot(&ctx, &scene, &camera, (96, 80), &OPTIONS)
        .unwrap();
    let (sa, sb) = (a.report.tiles.unwrap(), b.report.tiles.unwrap());
    assert_eq!(sb.skipped_opaque, 0);
    assert!(
        sa.skipped_opaque > sa.composited,
        "most splat-tile pairs are skipped: {sa:?}"
    );
    let d = compare(&a.frame, &b.frame).unwrap();
    let bound = f64::from(1.0 - splatscene::splat::tiled::OPAQUE);
    assert!(d.max_abs <= bound + 1e-5, "{d:?} against {bound}");
}

/// The tile compositor's picture of `scene` with its culling (splats hidden behind opaque
/// pixels, groups off the image) and without.
fn with_and_without_culling(
    ctx: &GpuContext,
    scene: &Scene,
    camera: &SceneCamera,
    size: (u32, u32),
) -> (Screenshot, Screenshot) {
    let mut culling = Renderer::with_compositor(Compositor::Cpu);
    let mut all = Renderer::with_compositor(Compositor::Cpu);
    all.tile_compositor_mut().cull_hidden = false;
    // The compositor's own culling, on every splat a refinement holds on the image (the look
    // for bricks shown would leave most of the hidden ones out before the compositor).
    for r in [&mut culling, &mut all] {
        r.set_refinement_where_seen(false);
    }
    let a = culling
        .screenshot(ctx, scene, camera, size, &OPTIONS)
        .unwrap();
    let b = all.screenshot(ctx, scene, camera, size, &OPTIONS).unwrap();
    (a, b)
}

#[test]
fn splats_left_out_behind_opaque_pixels_change_nothing() {
    let ctx = context();
    // A dense, nearly opaque block of 46,656 splats, more than the first batches: later
    // batches find most pixels opaque. Perspective, turned, and orthographic; an image whose
    // sides are multiples of neither a tile nor a word of the opaque pixels' rows.
    let mut volume = shells(36, [1.0; 3]);
    volume
        .values
        .make_f32()
        .iter_mut()
        .for_each(|v| *v = 1800.0);
    let scene = volume_scene(volume, Ordering::IpPbtfImplicit);
    let flat = SceneCamera {
        projection: Projection::Orthographic { height: 40.0 },
        ..camera_of(&scene)
    };
    let cameras = [
        camera_of(&scene),
        camera_of(&scene).orbit_about(scene.up_axis(), 50.0, 20.0),
        flat,
    ];
    let views = cameras
        .iter()
        .map(|c| (c, (96, 80)))
        .chain([(&cameras[1], (150, 71))]);
    for (camera, size) in views {
        let (a, b) = with_and_without_culling(&ctx, &scene, camera, size);
        let (sa, sb) = (a.report.tiles.unwrap(), b.report.tiles.unwrap());
        assert_eq!(sb.culled, 0);
        assert!(
            sa.culled > sa.splats / 3,
            "most splats are never projected: {sa:?}"
        );
        // Culled splats are counted once, and include any behind the eye or off the image
        // once every tile is opaque.
        assert!(sa.projected + sa.culled <= sa.splats);
        assert!(sa.projected + sa.culled >= sb.projected, "{sa:?} {sb:?}");
        // Pairs left out touch opaque pixels alone, which take nothing: the same pixels,
        // and the same splats reach pixels still open.
        assert!(sa.composited <= sb.composited, "{sa:?} {sb:?}");
        assert_eq!(sa.drew, sb.drew);
        assert_eq!(a.frame.pixels, b.frame.pixels);
    }
}

#[test]
fn groups_of_splats_off_the_image_are_left_out_and_change_nothing() {
    // Zoomed in on a corner of the shells: most of the volume lies off the image, perspective
    // and orthographic; and the view of the whole volume.
    let ctx = context();
    let scene = volume_scene(shells(36, [1.0; 3]), Ordering::IpPbtfImplicit);
    let whole = camera_of(&scene);
    let corner = glam::DVec3::new(4.0, 4.0, 30.0);
    let near = SceneCamera {
        eye: corner + (whole.eye - whole.target).normalize() * 14.0,
        target: corner,
        ..whole
    };
    let flat = SceneCamera {
        projection: Projection::Orthographic { height: 9.0 },
        ..near
    };
    for (camera, size) in [(&near, (96, 80)), (&flat, (150, 71)), (&whole, (96, 80))] {
        let (a, b) = with_and_without_culling(&ctx, &scene, camera, size);
        let (sa, sb) = (a.report.tiles.unwrap(), b.report.tiles.unwrap());
        assert_eq!(sb.off_image, 0);
        if camera.eye != whole.eye {
            assert!(
                sa.off_image > sa.splats / 2,
                "most splats are off the image: {sa:?}"
            );
        }
        // Left out unprojected: splats off the image and splats hidden; each would have been
        // projected, or not, to no effect.
        assert!(sa.projected + sa.culled >= sb.projected, "{sa:?} {sb:?}");
        assert!(
            sa.projected + sa.culled + sa.off_image <= sa.splats,
            "{sa:?}"
        );
        assert_eq!(sa.drew, sb.drew);
        assert!(sa.drew > 100, "the corner is drawn: {sa:?}");
        assert_eq!(a.frame.pixels, b.frame.pixels);
    }
}

#[test]
fn a_close_up_refines_only_what_lies_on_the_image_with_the_same_picture() {
    // Close up on a rotated, anisotropic grid: its voxels several pixels apart, so the grid is
    // drawn refined, part of it off the image. Refined within the bricks on the image, the
    // picture is the one refined whole, pixel for pixel; perspective and orthographic,
    // shaded; the shells, and a faint fog that fills the grid, so that splats just past the
    // image's edges reach into it everywhere (it fails with the bricks' boxes not grown).
    let ctx = context();
    let fog = |mut volume: splatscene::volume::CpuVolume| {
        let n = volume.dims[0];
        let values: Vec<f32> = (0..volume.dims.iter().product::<u32>())
            .map(|id| 180.0 + ((id % n) * 7 + (id / n % n) * 3 + (id / n / n) * 5) as f32 % 40.0)
            .collect();
        volume.values = values.into();
        volume
    };
    let shells = {
        let mut volume = common::shells(32, [0.7, 0.7, 1.5]);
        volume.direction = glam::DMat3::from_rotation_z(0.5) * glam::DMat3::from_rotation_x(0.35);
        volume.origin = [100.0, -50.0, 30.0];
        volume
    };
    // The fog square to the world axes, so that a brick's box is no larger than the brick.
    let square = splatscene::volume::CpuVolume {
        direction: glam::DMat3::IDENTITY,
        ..shells.clone()
    };
    for volume in [shells, fog(square)] {
        let scene = shaded_scene(volume, TransferFunction::ct_bone());
        let whole = camera_of(&scene);
        let corner = whole.target + glam::DVec3::new(2.0, 1.0, 12.0);
        let near = SceneCamera {
            eye: corner + (whole.eye - whole.target).normalize() * 45.0,
            target: corner,
            projection: Projection::Perspective {
                fov_y_degrees: 12.0,
            },
            ..whole
        };
        let flat = SceneCamera {
            projection: Projection::Orthographic { height: 9.0 },
            ..near
        };
        for (camera, size) in [(&near, (64, 48)), (&flat, (60, 47))] {
            let mut cropped = Renderer::with_compositor(Compositor::Cpu);
            let mut whole_grid = Renderer::with_compositor(Compositor::Cpu);
            whole_grid.set_refinement_on_image_only(false);
            let a = cropped
                .screenshot(&ctx, &scene, camera, size, &OPTIONS)
                .unwrap();
            let b = whole_grid
                .screenshot(&ctx, &scene, camera, size, &OPTIONS)
                .unwrap();
            assert!(a.report.refined.is_some(), "{:?}", a.report);
            assert_eq!(a.report.refined, b.report.refined);
            assert!(
                a.report.splats * 10 < b.report.splats * 9,
                "the refined grid off the image is left out: {} of {}",
                a.report.splats,
                b.report.splats
            );
            assert!(a.report.tiles.unwrap().drew > 100);
            let differ = |x: &Frame, y: &Frame| {
                x.pixels
                    .iter()
                    .zip(&y.pixels)
                    .filter(|(p, q)| p != q)
                    .count()
            };
            assert_eq!(differ(&a.frame, &b.frame), 0, "pixels that differ");
            // Turned to show bricks the first view left out, the same renderer draws them
            // too: its picture is a fresh renderer's.
            let turned = SceneCamera {
                eye: camera.target
                    + glam::DQuat::from_rotation_z(0.6) * (camera.eye - camera.target),
                ..*camera
            };
            let again = cropped
                .screenshot(&ctx, &scene, &turned, size, &OPTIONS)
                .unwrap();
            let fresh = Renderer::with_compositor(Compositor::Cpu)
                .screenshot(&ctx, &scene, &turned, size, &OPTIONS)
                .unwrap();
            assert_eq!(
                differ(&again.frame, &fresh.frame),
                0,
                "pixels that differ, turned"
            );
        }
    }
}

/// A closed-form phantom: a box of 48^3 voxels of 1.5 mm whose opaque "bone" walls are three
/// voxels thick around a translucent fill that varies, with a square window cut in the wall at
/// y = 0 (x and z 19..29).
fn windowed_box() -> splatscene::volume::CpuVolume {
    let n = 48u32;
    let window = |x: u32, z: u32| (19..29).contains(&x) && (19..29).contains(&z);
    let values: Vec<f32> = (0..n * n * n)
        .map(|id| {
            let [x, y, z] = [id % n, id / n % n, id / n / n];
            let wall = [x, y, z].iter().any(|&c| c < 3 || c >= n - 3);
            match (wall, y < 3 && window(x, z)) {
                (_, true) => -1000.0,
                (true, false) => 1300.0,
                // A fill that varies, so that its refined cells differ from its voxels.
                (false, false) => 230.0 + ((x * 7 + y * 3 + z * 5) % 11) as f32 * 9.0,
            }
        })
        .collect();
    splatscene::volume::CpuVolume {
        dims: [n; 3],
        spacing: [1.5; 3],
        origin: [0.0; 3],
        direction: glam::DMat3::IDENTITY,
        values: values.into(),
    }
}

/// The windowed box close up in perspective, obliquely, the camera turned `turn` radians
/// about the box's vertical axis: drawn refined.
fn windowed_box_close_up(turn: f64) -> SceneCamera {
    let centre = glam::DVec3::new(35.25, 35.25, 35.25);
    SceneCamera {
        eye: centre + glam::DQuat::from_rotation_z(turn) * glam::DVec3::new(-20.0, -70.0, 12.0),
        target: centre,
        up: glam::DVec3::Z,
        projection: Projection::Perspective {
            fov_y_degrees: 40.0,
        },
        near: None,
    }
}

#[test]
fn a_close_up_is_drawn_the_same_whatever_came_before() {
    // The windowed box close up in perspective, obliquely, the camera turning so that the
    // refinement's factors change and change back. Whatever views a renderer drew before, a
    // view's factors, splats and picture are a fresh renderer's.
    let ctx = context();
    let scene = shaded_scene(windowed_box(), TransferFunction::ct_bone());
    let camera = windowed_box_close_up;
    let size = (96, 72);
    let shoot = |renderer: &mut Renderer, turn: f64| {
        renderer
            .screenshot(&ctx, &scene, &camera(turn), size, &OPTIONS)
            .unwrap()
    };
    let mut history = Renderer::with_compositor(Compositor::Cpu);
    let turns = [0.0, 0.4, -0.3, 0.0, 0.4];
    let mut factors = Vec::new();
    for (i, &turn) in turns.iter().enumerate() {
        let shot = shoot(&mut history, turn);
        let fresh = shoot(&mut Renderer::with_compositor(Compositor::Cpu), turn);
        assert!(shot.report.refined.is_some(), "{:?}", shot.report);
        assert_eq!(shot.report.refined, fresh.report.refined, "view {i}");
        assert_eq!(shot.report.splats, fresh.report.splats, "view {i}");
        assert_eq!(shot.frame.pixels, fresh.frame.pixels, "view {i}");
        factors.push(shot.report.refined);
    }
    // The path changes the refinement's factors on the way, and back.
    assert_ne!(factors[0], factors[2], "{factors:?}");
}

#[test]
fn a_cancelled_frame_stops_and_the_next_is_a_fresh_renderers() {
    // The windowed box close up (refined, its bricks looked for): a frame whose cancel flag
    // is raised gives up with `Cancelled`; raised before the frame, it stops in the own grid's
    // classification. Raised at any moment of a frame from another thread, the frame either
    // finishes or gives up, and the next frame, its flag lowered, is the picture a fresh
    // renderer draws: nothing half made was kept.
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    let ctx = context();
    let scene = shaded_scene(windowed_box(), TransferFunction::ct_bone());
    let camera = windowed_box_close_up;
    let size = (160, 120);
    let fresh = |turn: f64| {
        Renderer::with_compositor(Compositor::Cpu)
            .screenshot(&ctx, &scene, &camera(turn), size, &OPTIONS)
            .unwrap()
    };
    let mut renderer = Renderer::with_compositor(Compositor::Cpu);
    let raised = Arc::new(AtomicBool::new(true));
    renderer.set_cancel(Some(Arc::clone(&raised)));
    let cancelled = renderer.screenshot(&ctx, &scene, &camera(0.0), size, &OPTIONS);
    assert!(
        matches!(cancelled, Err(splatscene::render::RenderError::Cancelled)),
        "{:?}",
        cancelled.map(|s| s.report)
    );
    renderer.set_cancel(None);
    let next = renderer
        .screenshot(&ctx, &scene, &camera(0.0), size, &OPTIONS)
        .unwrap();
    assert!(next.report.refined.is_some(), "{:?}", next.report);
    // The look was not kept from the cancelled frame: made in this one.
    assert!(!next.report.timings.seen.is_zero(), "{:?}", next.report);
    assert_eq!(next.frame.pixels, fresh(0.0).frame.pixels);
    // Raised from another thread at moments spread over a frame, on views that change.
    let mut outcomes = Vec::new();
    for (i, delay_us) in [0u64, 200, 1000, 3000, 8000, 20000, 60000, 150000]
        .into_iter()
        .enumerate()
    {
        let turn = 0.1 * i as f64;
        let flag = Arc::new(AtomicBool::new(false));
        renderer.set_cancel(Some(Arc::clone(&flag)));
        let raiser = std::thread::spawn(move || {
            std::thread::sleep(std::time::Duration::from_micros(delay_us));
            flag.store(true, Ordering::Relaxed);
        });
        let shot = renderer.screenshot(&ctx, &scene, &camera(turn), size, &OPTIONS);
        raiser.join().unwrap();
        outcomes.push(match shot {
            Ok(_) => "finished",
            Err(splatscene::render::RenderError::Cancelled) => "cancelled",
            Err(e) => panic!("raised after {delay_us} us: {e}"),
        });
        renderer.set_cancel(None);
        let next = renderer
            .screenshot(&ctx, &scene, &camera(turn), size, &OPTIONS)
            .unwrap();
        assert_eq!(
            next.frame.pixels,
            fresh(turn).frame.pixels,
            "after a frame raised at {delay_us} us ({outcomes:?})"
        );
    }
    // Which frames gave up depends on the threads' timing; each outcome above is checked.
    eprintln!("frames raised during: {outcomes:?}");
}

#[test]
fn a_refinement_leaves_out_the_bricks_hidden_behind_opaque_tissue() {
    // A closed-form phantom: a box of opaque "bone" walls three voxels thick around a
    // translucent fill, a square window cut in the wall the camera faces, seen so close that
    // its 1.5 mm voxels fall about 3 pixels apart (the grid is drawn refined). The refinement
    // then classifies the wall's bricks and those seen through the window, not the hidden
    // fill: fewer splats, and the picture of every brick on the image refined, within the
    // opacity the own grid's picture leaves to what lies behind an opaque pixel.
    let ctx = context();
    let volume = windowed_box();
    let scene = shaded_scene(volume, TransferFunction::ct_bone());
    // Orthographic, so that a turned view keeps the refinement's factors.
    let centre = glam::DVec3::new(35.25, 35.25, 35.25);
    let camera = SceneCamera {
        eye: centre - glam::DVec3::new(-4.0, 75.0, 3.0),
        target: centre,
        up: glam::DVec3::Z,
        projection: Projection::Orthographic { height: 24.0 },
        near: None,
    };
    let size = (64, 48);
    let shoot = |renderer: &mut Renderer, camera: &SceneCamera| {
        renderer
            .screenshot(&ctx, &scene, camera, size, &OPTIONS)
            .unwrap()
    };
    // The look is the default; `every` refines every brick on the image.
    let mut seen = Renderer::with_compositor(Compositor::Cpu);
    let mut every = Renderer::with_compositor(Compositor::Cpu);
    every.set_refinement_where_seen(false);
    let a = shoot(&mut seen, &camera);
    let b = shoot(&mut every, &camera);
    assert!(a.report.refined.is_some(), "{:?}", a.report);
    assert_eq!(a.report.refined, b.report.refined);
    assert!(!a.report.timings.seen.is_zero());
    assert!(b.report.timings.seen.is_zero());
    assert!(
        a.report.splats * 2 < b.report.splats,
        "the hidden fill is left out: {} of {} splats",
        a.report.splats,
        b.report.splats
    );
    let d = compare(&a.frame, &b.frame).unwrap();
    assert!(d.max_abs < 0.01, "{d:?}");
    // The same view again looks for nothing and classifies nothing.
    let same = shoot(&mut seen, &camera);
    assert_eq!(same.report.classified, 0);
    assert!(same.report.timings.seen.is_zero());
    assert_eq!(same.frame.pixels, a.frame.pixels);
    // Turned so that the window shows fill the first view hid: the same renderer looks
    // again, classifies the bricks its refinement lacks, once, joins them to it, and draws
    // the picture a renderer that never drew another view draws; the next frame from there
    // looks for nothing.
    let turned = SceneCamera {
        eye: centre + glam::DQuat::from_rotation_z(0.5) * (camera.eye - centre),
        ..camera
    };
    let again = shoot(&mut seen, &turned);
    let every_again = shoot(&mut every, &turned);
    let mut fresh = Renderer::with_compositor(Compositor::Cpu);
    let fresh_again = shoot(&mut fresh, &turned);
    assert_eq!(again.report.refined, a.report.refined);
    assert_eq!(again.report.classified, 1);
    assert!(!again.report.timings.seen.is_zero());
    assert_eq!(again.report.splats, fresh_again.report.splats);
    assert_eq!(again.frame.pixels, fresh_again.frame.pixels);
    let d = compare(&again.frame, &every_again.frame).unwrap();
    assert!(d.max_abs < 0.01, "{d:?}");
    let still = shoot(&mut seen, &turned);
    assert_eq!(still.report.classified, 0);
    assert!(still.report.timings.seen.is_zero());
    // Back at the first view, the refinement holds the bricks the turned view added; the
    // picture is still the first view's alone, splat for splat.
    let back = shoot(&mut seen, &camera);
    assert_eq!(back.report.classified, 0);
    assert_eq!(back.report.splats, a.report.splats);
    assert_eq!(back.frame.pixels, a.frame.pixels);
}

#[test]
fn the_built_in_scene_looks_the_same_on_either_compositor() {
    let scene = splatscene::scene::shoulder::shoulder_scene().unwrap();
    let camera = scene.camera.unwrap();
    gpu_against_tiles(&scene, &camera, "built-in");
}

#[test]
fn auto_takes_the_cpu_on_a_cpu_adapter() {
    let ctx = context();
    let on_cpu = ctx.adapter.get_info().device_type == wgpu::DeviceType::Cpu;
    assert_eq!(
        Renderer::with_compositor(Compositor::Auto).composites_on_cpu(&ctx),
        on_cpu
    );
    assert!(
        !Renderer::new().composites_on_cpu(&ctx),
        "the library's default is the GPU"
    );
    assert!(Renderer::with_compositor(Compositor::Cpu).composites_on_cpu(&ctx));
    let dir = common::scratch("tiled");
    let out = dir.join("out.png");
    let result = std::process::Command::new(env!("CARGO_BIN_EXE_splatscene"))
        .args(["render", "--size", "64x48", "--out"])
        .arg(&out)
        .env("NODEVICE_SELECT", "1")
        .output()
        .unwrap();
    assert!(result.status.success());
    let said = String::from_utf8_lossy(&result.stderr);
    assert_eq!(said.contains("splats on the CPU"), on_cpu, "{said}");
    let bad = std::process::Command::new(env!("CARGO_BIN_EXE_splatscene"))
        .args(["render", "--compositor", "fast", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&bad.stderr);
    assert!(
        !bad.status.success() && said.contains("auto, gpu, cpu or gpu-tiles"),
        "{said}"
    );
}

#[test]
fn a_volume_renders_without_any_gpu_adapter_and_meshes_say_what_they_need() {
    // A machine without an adapter: no Vulkan driver to load, and no other backend tried.
    let dir = common::scratch("no-adapter");
    std::fs::create_dir_all(&dir).unwrap();
    let raw = dir.join("block.raw");
    let mut bytes = vec![0u8; 16 * 16 * 16];
    for (i, b) in bytes.iter_mut().enumerate() {
        let (x, y, z) = (i % 16, i / 16 % 16, i / 256);
        if (4..12).contains(&x) && (4..12).contains(&y) && (4..12).contains(&z) {
            *b = 200;
        }
    }
    std::fs::write(&raw, bytes).unwrap();
    let out = dir.join("block.png");
    let run = |args: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_splatscene"))
            .args(args)
            .env("VK_ICD_FILENAMES", dir.join("no-such-driver.json"))
            .env("WGPU_BACKEND", "vulkan")
            .env("NODEVICE_SELECT", "1")
            .output()
            .unwrap()
    };
    // The block rendered into `out`, with `more` arguments.
    let block = |out: &std::path::Path, more: &[&str]| {
        let mut args = vec![
            "render",
            raw.to_str().unwrap(),
            "--dims",
            "16,16,16",
            "--scalar",
            "u8",
            "--window",
            "100,200",
            "--size",
            "64x48",
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(more);
        run(&args)
    };
    // The default compositor (auto): on a machine with no GPU device file it looks for no
    // adapter at all and says it draws on the CPU alone; where one exists it looks, finds none
    // and says so before compositing on the CPU.
    let gpu_device = common::gpu_device_file();
    let volume = block(&out, &[]);
    let said = String::from_utf8_lossy(&volume.stderr);
    assert!(volume.status.success(), "{said}");
    if gpu_device {
        assert!(
            said.contains("no GPU adapter") && said.contains("splats on the CPU"),
            "{said}"
        );
    } else {
        assert!(
            !said.contains("GPU adapter") && said.contains("on the CPU alone"),
            "{said}"
        );
    }
    let image = image::open(&out).unwrap().to_rgba8();
    let bright = image.pixels().filter(|p| p[0] > 100).count();
    assert!(bright > 100, "the block shows: {bright} bright pixels");
    // With the CPU tiles asked for, a scene of volumes looks for no adapter at all: nothing
    // said of one, and the same picture.
    let asked = dir.join("asked.png");
    let cpu = block(&asked, &["--compositor", "cpu"]);
    let said = String::from_utf8_lossy(&cpu.stderr);
    assert!(cpu.status.success(), "{said}");
    assert!(
        !said.contains("GPU adapter") && said.contains("on the CPU alone"),
        "{said}"
    );
    assert_eq!(image::open(&asked).unwrap().to_rgba8(), image);
    // The GPU's compositor asked for with no adapter: refused, saying what to install.
    let gpu = block(&dir.join("gpu.png"), &["--compositor", "gpu"]);
    let said = String::from_utf8_lossy(&gpu.stderr);
    assert!(
        !gpu.status.success() && said.contains("mesa-vulkan-drivers"),
        "{said}"
    );
    // The built-in scene has meshes: they need an adapter, and the error says so.
    let meshes = run(&["render", "--size", "64x48", "--out", out.to_str().unwrap()]);
    let said = String::from_utf8_lossy(&meshes.stderr);
    assert!(
        !meshes.status.success() && said.contains("mesa-vulkan-drivers"),
        "{said}"
    );
}

#[test]
fn the_engine_looks_the_same_on_either_compositor() {
    // The GE engine block (Open SciVis datasets, General Electric), 1.05M splats.
    let Some((scene, camera)) = engine_view(1.2) else {
        return;
    };
    // Many faint sub-pixel splats share each pixel here: a GPU blending in 16-bit float
    // drifts from the tiles' f32 (RMSE 0.0047, largest 0.052 on lavapipe), one blending in
    // 32-bit float, as the renderer asks where the device can, does not.
    gpu_against_tiles_at(&scene, &camera, (288, 240), "engine");
}

#[test]
fn a_bone_rendering_of_the_ct_head_skips_most_of_its_splats() {
    // The Stanford CT head (University of North Carolina), bone alone (a ramp from 1200 to
    // 1800, the benchmarks' view): 452k splats on 35k pixels, most of them behind the
    // nearest bone. Culling leaves them out before projection, and changes nothing.
    let Some(first) = data_file("volumes/stanford_cthead/CThead.1") else {
        return;
    };
    use splatscene::volume::raw::{ByteOrder, RawSpec, ScalarType, load_raw_slices, slice_stack};
    let spec = RawSpec {
        spacing: [1.0, 1.0, 2.0],
        ..RawSpec::new([256, 256, 113], ScalarType::U16, ByteOrder::Big)
    };
    let volume = load_raw_slices(&slice_stack(&first).unwrap(), &spec).unwrap();
    let (scene, camera) = benchmark_view(
        volume,
        TransferFunction::ramp(1200.0, 1800.0, [1.0, 0.93, 0.85, 0.6]),
        1.0,
    );
    let ctx = context();
    for camera in [camera, camera.orbit_about(scene.up_axis(), 70.0, 0.0)] {
        let (a, b) = with_and_without_culling(&ctx, &scene, &camera, (512, 512));
        let (sa, sb) = (a.report.tiles.unwrap(), b.report.tiles.unwrap());
        assert!(sa.splats > 400_000, "{sa:?}");
        assert!(
            2 * sa.drew < sa.splats,
            "most splats reach no open pixel: {sa:?}"
        );
        assert!(
            2 * sa.culled > sa.splats,
            "most splats are never projected: {sa:?}"
        );
        assert_eq!(sa.drew, sb.drew);
        assert_eq!(a.frame.pixels, b.frame.pixels);
    }
}

/// The CPU tile compositor reads back only the pixels that the meshes' bounding boxes can
/// cover, once for the opaque meshes, once for the translucent ones and once for the
/// overlays; the picture and the depth must be those of the whole targets, which the GPU
/// path reads back. Views with the meshes inside the image, cut by its edge, off it, around
/// the eye (the near plane through a bounding box) and orthographic.
#[test]
fn mesh_layers_read_back_by_their_rectangles_are_the_whole_layers() {
    use common::shapes::{cube, sphere};
    use glam::{DMat4, DVec3};
    use splatscene::mesh::Material;
    use splatscene::scene::MeshNode;
    use std::sync::Arc;
    let ctx = context();
    let mut scene = Scene::new();
    let node = |mesh, rgba: [f32; 4]| MeshNode {
        mesh: Arc::new(mesh),
        material: Material {
            base_color: rgba,
            ..Default::default()
        },
    };
    let at = |x: f64, y: f64, z: f64| Some(DMat4::from_translation(DVec3::new(x, y, z)));
    let mut add = |name: &str, world: Option<DMat4>, content| {
        scene.add(name, world.unwrap(), None, content).unwrap();
    };
    add(
        "cube",
        at(0.0, 0.0, 0.0),
        NodeContent::Mesh(node(cube(20.0), [0.2, 0.5, 0.9, 1.0])),
    );
    add(
        "far cube",
        at(-30.0, 40.0, 5.0),
        NodeContent::Mesh(node(cube(10.0), [0.9, 0.5, 0.2, 1.0])),
    );
    add(
        "glass",
        at(12.0, -6.0, 8.0),
        NodeContent::Mesh(node(sphere(9.0, 12, 16), [0.3, 0.9, 0.4, 0.5])),
    );
    add(
        "marker",
        at(-8.0, -12.0, 10.0),
        NodeContent::Overlay(node(sphere(2.0, 6, 8), [1.0, 1.0, 0.0, 1.0])),
    );
    let size = (96, 80);
    let pixels = 96 * 80;
    let look = |eye: DVec3, target: DVec3| SceneCamera::look_at(eye, target);
    let cases = [
        (
            "inside the image",
            look(DVec3::new(40.0, -160.0, 60.0), DVec3::ZERO),
            1..pixels,
        ),
        (
            "cut by the image's edge",
            look(DVec3::new(30.0, -70.0, 20.0), DVec3::new(22.0, 0.0, 15.0)),
            1..pixels,
        ),
        (
            "off the image",
            look(DVec3::new(0.0, -100.0, 0.0), DVec3::new(0.0, -200.0, 0.0)),
            0..1,
        ),
        (
            "around the eye",
            look(DVec3::new(2.0, -3.0, 1.0), DVec3::new(-30.0, 40.0, 5.0)),
            pixels..pixels * 4,
        ),
        (
            "orthographic",
            SceneCamera {
                projection: Projection::Orthographic { height: 70.0 },
                ..look(DVec3::new(-50.0, -150.0, 40.0), DVec3::ZERO)
            },
            1..pixels,
        ),
    ];
    for (what, camera, read_back) in cases {
        let gpu = Renderer::with_compositor(Compositor::Gpu)
            .screenshot(&ctx, &scene, &camera, size, &OPTIONS)
            .unwrap();
        let cpu = Renderer::with_compositor(Compositor::Cpu)
            .screenshot(&ctx, &scene, &camera, size, &OPTIONS)
            .unwrap();
        let worst = gpu
            .frame
            .pixels
            .iter()
            .zip(&cpu.frame.pixels)
            .flat_map(|(a, b)| (0..4).map(move |k| (a[k] - b[k]).abs()))
            .fold(0.0f32, f32::max);
        assert!(worst < 1e-5, "{what}: colour differs by {worst}");
        assert!(gpu.depth == cpu.depth, "{what}: the depth differs");
        let drawn = gpu.depth.iter().filter(|&&d| d > 0.0).count();
        assert!(
            read_back.contains(&cpu.report.read_back),
            "{what}: {} pixels read back",
            cpu.report.read_back
        );
        if what != "off the image" {
            assert!(drawn > 0, "{what}: the view shows no mesh");
        }
    }
}

#[test]
fn bricks_drawn_at_their_own_levels_give_the_picture_of_the_whole_grid() {
    // From 40 mm before the grid's face, looking along it, at 50 degrees and 48 x 48 pixels:
    // the near face's voxels fall about 1.3 pixels apart (the own grid), the far face's 0.3.
    // One level for the volume draws the own grid throughout; its bricks at their own levels
    // draw the far ones coarser, fewer splats for the same picture.
    let ctx = context();
    let scene = translucent_blobs();
    let camera = before_the_blobs(40.0);
    let size = (48, 48);
    let shot = |setup: &dyn Fn(&mut Renderer)| {
        let mut renderer = Renderer::with_compositor(Compositor::Cpu);
        setup(&mut renderer);
        renderer
            .screenshot(&ctx, &scene, &camera, size, &OPTIONS)
            .unwrap()
    };
    let by_brick = shot(&|_| {});
    let one_level = shot(&|r| r.set_levels_by_brick(false));
    let own = shot(&|r| r.set_level_of_detail(false));
    assert_eq!(by_brick.report.bricks_by_level, 1, "{:?}", by_brick.report);
    assert_eq!(one_level.report.bricks_by_level, 0);
    assert_eq!(one_level.report.levels, [0; 3], "{:?}", one_level.report);
    let d_mix = compare(&by_brick.frame, &own.frame).unwrap();
    let d_one = compare(&one_level.frame, &own.frame).unwrap();
    eprintln!(
        "splats: by brick {}, one level {}, own {}; against the own grid: by brick {d_mix:?}",
        by_brick.report.splats, one_level.report.splats, own.report.splats
    );
    assert_eq!(d_one.rmse, 0.0, "one level draws the own grid here");
    assert!(by_brick.report.levels.iter().any(|&l| l > 0));
    let covered = own.frame.pixels.iter().filter(|p| p[3] > 0.5).count();
    assert!(covered > 48 * 40, "{covered} pixels covered");
    assert!(
        by_brick.report.splats * 10 < one_level.report.splats * 8,
        "{} splats by brick against {}",
        by_brick.report.splats,
        one_level.report.splats
    );
    // The far bricks' levels smooth the shell's hard edge (0.020 measured; the whole grid at
    // level 1 is 0.025 from it). The bricks' order alone, every brick at the own grid, is
    // 0.0026 from the one order of the whole grid.
    assert!(d_mix.rmse < 0.025, "{d_mix:?}");
}

#[test]
fn a_close_up_refines_only_its_near_bricks() {
    // From 12 mm before the grid's face at 50 degrees, 64 x 64 pixels: the near face's voxels
    // fall about 5 pixels apart (refined), the far face's, 140 mm away, under half a pixel.
    // One level for the volume refines every brick on the image; by brick, only those whose
    // voxels fall more than a pixel apart are refined and the far ones drawn coarser, for
    // about the same picture (5.4M splats against 19.6M, RMSE 0.011 measured).
    let ctx = context();
    let scene = translucent_blobs();
    let camera = before_the_blobs(12.0);
    let size = (64, 64);
    let shot = |by_brick: bool| {
        let mut renderer = Renderer::with_compositor(Compositor::Cpu);
        renderer.set_levels_by_brick(by_brick);
        renderer
            .screenshot(&ctx, &scene, &camera, size, &OPTIONS)
            .unwrap()
    };
    let (by_brick, one_level) = (shot(true), shot(false));
    let d = compare(&by_brick.frame, &one_level.frame).unwrap();
    eprintln!(
        "splats: by brick {} ({:?}), one level {} ({:?}); {d:?}",
        by_brick.report.splats,
        by_brick.report.refined,
        one_level.report.splats,
        one_level.report.refined
    );
    assert!(one_level.report.refined.is_some(), "{:?}", one_level.report);
    assert_eq!(by_brick.report.refined, one_level.report.refined);
    assert_eq!(by_brick.report.bricks_by_level, 1);
    assert!(
        by_brick.report.splats * 2 < one_level.report.splats,
        "{} splats by brick against {}",
        by_brick.report.splats,
        one_level.report.splats
    );
    assert!(d.rmse < 0.02, "{d:?}");
}

#[test]
fn a_volume_drawn_at_one_detail_by_brick_is_the_one_detail_picture() {
    // From near and far before the blobs, at several sizes: wherever the bricks are not drawn each at
    // its own level (they all want one, or a mix would save too little), the picture is the
    // one-detail picture pixel for pixel, refined views included: a refinement made for a
    // volume drawn whole covers every brick on the image.
    let ctx = context();
    let scene = translucent_blobs();
    let (mut whole_refined, mut mixed) = (0, 0);
    // And from 400 mm through a 10 degree lens at 128 x 128, the grid's voxels 1.4-1.9
    // pixels apart from its near face to its far one: refined throughout.
    let telephoto = SceneCamera {
        projection: Projection::Perspective {
            fov_y_degrees: 10.0,
        },
        ..before_the_blobs(400.0)
    };
    let views = [
        (12.0, 64),
        (40.0, 96),
        (110.0, 160),
        (150.0, 160),
        (200.0, 200),
    ]
    .map(|(distance, size)| (distance, before_the_blobs(distance), size));
    for (distance, camera, size) in views.into_iter().chain([(400.0, telephoto, 128)]) {
        let shot = |by_brick: bool| {
            let mut renderer = Renderer::with_compositor(Compositor::Cpu);
            renderer.set_levels_by_brick(by_brick);
            renderer
                .screenshot(&ctx, &scene, &camera, (size, size), &OPTIONS)
                .unwrap()
        };
        let (a, b) = (shot(true), shot(false));
        if a.report.bricks_by_level > 0 {
            mixed += 1;
            continue;
        }
        whole_refined += usize::from(a.report.refined.is_some());
        assert_eq!(a.report.splats, b.report.splats, "{distance} mm");
        assert!(a.frame.pixels == b.frame.pixels, "{distance} mm");
    }
    eprintln!("{mixed} views mixed, {whole_refined} refined whole");
    assert!(
        whole_refined > 0 && mixed > 0,
        "{mixed} mixed, {whole_refined} refined whole"
    );
}

#[test]
fn the_splat_pass_draws_the_mix_the_tiles_draw() {
    // The translucent blobs from 40 mm before their face (near bricks at the own grid, far ones
    // coarser) and from an oblique eye, each volume drawn brick by brick: the GPU splat pass
    // draws the mix's runs of each level's order on the GPU, far to near, and gives the CPU
    // tiles' picture.
    let ctx = context();
    let scene = translucent_blobs();
    let oblique = across_the_blobs();
    for (what, camera) in [("before", before_the_blobs(40.0)), ("oblique", oblique)] {
        let shot = |compositor| {
            Renderer::with_compositor(compositor)
                .screenshot(&ctx, &scene, &camera, (64, 56), &OPTIONS)
                .unwrap()
        };
        let (gpu, cpu) = (shot(Compositor::Gpu), shot(Compositor::Cpu));
        assert_eq!(gpu.report.bricks_by_level, 1, "{what}: {:?}", gpu.report);
        assert_eq!(cpu.report.bricks_by_level, 1, "{what}: {:?}", cpu.report);
        assert_eq!(gpu.report.splats, cpu.report.splats, "{what}");
        assert_eq!(gpu.report.levels, cpu.report.levels, "{what}");
        let d = compare(&gpu.frame, &cpu.frame).unwrap();
        eprintln!(
            "{what}: {} splats, levels {:?}: {d:?}",
            cpu.report.splats, cpu.report.levels
        );
        assert_alike(&d, what);
    }
}

/// A preview whose volumes are composited at fewer pixels (`FrameOptions::volume_divisor`)
/// is the preview at the frame's own pixels within a little, meshes' silhouettes included:
/// on both sides of an opaque cube's edges, pixels take the volume of their own side. A plain
/// bilinear scaling of the preview drawn small (written here) blurs those edges by its
/// pixels' width. The GPU passes refuse any divisor but 1, and every path refuses 0.
#[test]
fn volumes_composited_at_fewer_pixels_keep_the_meshes_edges() {
    use common::shapes::cube;
    use glam::{DMat4, DVec3};
    use splatscene::mesh::Material;
    use splatscene::scene::MeshNode;
    use std::sync::Arc;
    let ctx = context();
    let mut scene = translucent_blobs();
    // A cube partly inside the blobs: the volume lies in front of some of it, behind the rest.
    scene
        .add(
            "cube",
            DMat4::from_translation(DVec3::new(40.0, 80.0, 30.0)),
            None,
            NodeContent::Mesh(MeshNode {
                mesh: Arc::new(cube(46.0)),
                material: Material {
                    base_color: [0.2, 0.5, 0.9, 1.0],
                    ..Default::default()
                },
            }),
        )
        .unwrap();
    let camera = across_the_blobs();
    let size = (192, 160);
    let options = |volume_divisor| FrameOptions {
        preview: 1,
        volume_divisor,
        ..OPTIONS
    };
    let shoot = |size, volume_divisor| {
        Renderer::with_compositor(Compositor::Cpu)
            .screenshot(&ctx, &scene, &camera, size, &options(volume_divisor))
            .unwrap()
    };
    let full = shoot(size, 1);
    // Pixels within 2 of a mesh silhouette (a jump in depth between neighbours).
    let (w, h) = (size.0 as usize, size.1 as usize);
    let edge_of = |depth: &[f32]| -> Vec<bool> {
        let jump = |a: f32, b: f32| (a - b).abs() > 0.02 * a.max(b);
        let mut edge = vec![false; w * h];
        for y in 0..h {
            for x in 0..w {
                let d = depth[y * w + x];
                let near = (x + 1 < w && jump(d, depth[y * w + x + 1]))
                    || (y + 1 < h && jump(d, depth[(y + 1) * w + x]));
                if near {
                    for yy in y.saturating_sub(2)..(y + 3).min(h) {
                        for xx in x.saturating_sub(2)..(x + 3).min(w) {
                            edge[yy * w + xx] = true;
                        }
                    }
                }
            }
        }
        edge
    };
    let edge = edge_of(&full.depth);
    let at_edges = edge.iter().filter(|&&e| e).count();
    assert!(at_edges > 300, "{at_edges} pixels by the cube's edges");
    let mean_off = |a: &Frame, b: &Frame, keep: &dyn Fn(usize) -> bool| {
        let (sum, n) = (a.pixels.iter().zip(&b.pixels).enumerate())
            .filter(|(i, _)| keep(*i))
            .fold((0.0f64, 0usize), |(s, n), (_, (p, q))| {
                let d: f32 = (0..3).map(|k| (p[k] - q[k]).abs()).sum();
                (s + f64::from(d) / 3.0, n + 1)
            });
        sum / n.max(1) as f64
    };
    // A plain bilinear scaling of `small` to the frame's size, pixel centres kept.
    let scaled_up = |small: &Frame| {
        let (sw, sh) = (small.width as usize, small.height as usize);
        let tap = |i: usize, n: usize, s: usize| {
            let at = ((i as f64 + 0.5) * s as f64 / n as f64 - 0.5).clamp(0.0, (s - 1) as f64);
            let lo = at.floor() as usize;
            (lo, (lo + 1).min(s - 1), (at - lo as f64) as f32)
        };
        let mut pixels = Vec::with_capacity(w * h);
        for y in 0..h {
            let (y0, y1, fy) = tap(y, h, sh);
            for x in 0..w {
                let (x0, x1, fx) = tap(x, w, sw);
                let p = |xx: usize, yy: usize| small.pixels[yy * sw + xx];
                pixels.push(std::array::from_fn(|k| {
                    let top = p(x0, y0)[k] * (1.0 - fx) + p(x1, y0)[k] * fx;
                    let bottom = p(x0, y1)[k] * (1.0 - fx) + p(x1, y1)[k] * fx;
                    top * (1.0 - fy) + bottom * fy
                }));
            }
        }
        Frame {
            width: size.0,
            height: size.1,
            pixels,
        }
    };
    for divisor in [2u32, 3] {
        let fewer = shoot(size, divisor);
        assert_eq!(fewer.report.levels, full.report.levels, "1/{divisor}");
        assert_eq!(fewer.depth, full.depth, "1/{divisor}: the meshes' depth");
        let d = compare(&fewer.frame, &full.frame).unwrap();
        let edges = mean_off(&fewer.frame, &full.frame, &|i| edge[i]);
        let small = shoot((size.0.div_ceil(divisor), size.1.div_ceil(divisor)), 1);
        let plain = mean_off(&scaled_up(&small.frame), &full.frame, &|i| edge[i]);
        eprintln!("1/{divisor}: {d:?}, by the edges {edges:.4} (scaled up {plain:.4})");
        assert!(d.rmse < 0.02, "1/{divisor}: {d:?}");
        assert!(
            edges < 0.5 * plain,
            "1/{divisor}: {edges} by the edges, scaled up {plain}"
        );
    }
    // Refused: 0 anywhere, and any other divisor than 1 on the GPU passes.
    let refused = |compositor, divisor| {
        Renderer::with_compositor(compositor)
            .screenshot(&ctx, &scene, &camera, size, &options(divisor))
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default()
    };
    assert!(refused(Compositor::Cpu, 0).contains("volume_divisor 0"));
    assert!(refused(Compositor::Gpu, 0).contains("volume_divisor 0"));
    assert!(refused(Compositor::Gpu, 2).contains("volume_divisor 2"));
}
