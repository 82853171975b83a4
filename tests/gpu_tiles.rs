//! The tile compositor's GPU compute passes (`--compositor gpu-tiles`) against the CPU tile
//! compositor on the same adapter (lavapipe in CI): the same splats, in the same order, with
//! the same early termination, must give the same picture. Perspective and orthographic,
//! shaded, clipped, a rotated anisotropic volume, meshes in front of and behind the splats,
//! two volumes, images whose sides are not multiples of a tile, zoomed views with most splats
//! off the image, orders long enough to take several batches, a transparent background, and
//! a real CT volume.

use glam::{DMat4, DVec3};
use splatscene::order::Ordering;
use splatscene::render::{Compositor, FrameOptions, GpuContext, Renderer};
use splatscene::scene::{NodeContent, Projection, Scene, SceneCamera};
use splatscene::splat::reference::{Frame, ImageDifference, compare};

mod common;
use common::shapes::camera_of;
use common::{
    across_the_blobs, before_the_blobs, compositor_cases, engine_view, shells, translucent_blobs,
    volume_scene,
};

const OPTIONS: FrameOptions = FrameOptions {
    ordering: None,
    background: Some([0.05, 0.05, 0.1]),
    measure: false,
    preview: 0,
    volume_divisor: 1,
};

/// Splats a batch of the GPU tiles in these tests.
const BATCH: usize = 16_384;

fn context() -> GpuContext {
    GpuContext::headless().expect("a GPU adapter (install mesa-vulkan-drivers)")
}

/// The frame of `scene` composited by `compositor`, with the level of detail as given and the
/// opacity that stops a pixel.
fn shoot(
    ctx: &GpuContext,
    compositor: Compositor,
    scene: &Scene,
    camera: &SceneCamera,
    size: (u32, u32),
    options: &FrameOptions,
    opaque: f32,
) -> Frame {
    let mut renderer = Renderer::with_compositor(compositor);
    renderer.tile_compositor_mut().opaque = opaque;
    // Small batches on the GPU, so that the tests' orders take several.
    renderer.set_gpu_tile_batch(std::num::NonZeroUsize::new(BATCH).unwrap());
    // One level a volume (drawn brick by brick in `volumes_drawn_brick_by_brick`).
    renderer.set_levels_by_brick(false);
    renderer
        .screenshot(ctx, scene, camera, size, options)
        .unwrap()
        .frame
}

/// The two compositors do the same f32 arithmetic but for the exponential (the CPU's
/// polynomial, relative error under 1e-6, against the GPU's `exp`) and the fusing of
/// multiply-adds, so a pixel differs by rounding, or, where rounding moves it across the
/// stopping opacity, by at most what the last splat it took or left out adds: `1 - OPAQUE` of
/// a channel. (Measured on lavapipe: RMSE 1e-7 to 8e-6, largest difference 1e-3.)
fn assert_same(d: &ImageDifference, what: &str) {
    let stop = f64::from(1.0 - splatscene::splat::tiled::OPAQUE);
    assert!(d.rmse < 3e-5, "{what}: {d:?}");
    assert!(d.max_abs <= stop + 1e-4, "{what}: {d:?}");
}

fn compare_at(
    scene: &Scene,
    camera: &SceneCamera,
    size: (u32, u32),
    options: &FrameOptions,
    what: &str,
) -> ImageDifference {
    let ctx = context();
    let opaque = splatscene::splat::tiled::OPAQUE;
    let gpu = shoot(
        &ctx,
        Compositor::GpuTiles,
        scene,
        camera,
        size,
        options,
        opaque,
    );
    let cpu = shoot(&ctx, Compositor::Cpu, scene, camera, size, options, opaque);
    let lit = cpu.pixels.iter().filter(|p| p[0] > 0.2).count();
    assert!(lit > 100, "{what}: the scene shows ({lit} lit pixels)");
    let d = compare(&gpu, &cpu).unwrap();
    assert_same(&d, what);
    d
}

fn compare_views(scene: &Scene, camera: &SceneCamera, what: &str) -> ImageDifference {
    compare_at(scene, camera, (96, 80), &OPTIONS, what)
}

/// `scene`'s volume made a dense, nearly opaque block (every value 1800).
fn solid(n: u32) -> Scene {
    let mut volume = shells(n, [1.0; 3]);
    volume
        .values
        .make_f32()
        .iter_mut()
        .for_each(|v| *v = 1800.0);
    volume_scene(volume, Ordering::IpPbtfImplicit)
}

#[test]
fn the_views_the_splat_pass_is_held_to() {
    for (name, scene, camera) in compositor_cases() {
        compare_views(&scene, &camera, name);
    }
    // A transparent background.
    let (_, scene, camera) = compositor_cases().swap_remove(0);
    let transparent = FrameOptions {
        background: None,
        ..OPTIONS
    };
    compare_at(&scene, &camera, (96, 80), &transparent, "transparent");
}

#[test]
fn two_volumes_are_taken_near_to_far() {
    // Two shells side by side along the view, the nearer one half covering the farther.
    let mut scene = volume_scene(shells(20, [1.0; 3]), Ordering::IpPbtfImplicit);
    let (_, node, _) = scene.volumes().next().unwrap();
    let node = node.clone();
    scene
        .add(
            "second",
            DMat4::from_translation(DVec3::new(8.0, 26.0, 4.0)),
            None,
            NodeContent::Volume(node),
        )
        .unwrap();
    compare_at(
        &scene,
        &camera_of(&scene),
        (128, 96),
        &OPTIONS,
        "two volumes",
    );
}

#[test]
fn long_orders_odd_images_and_early_termination() {
    // 42,875 splats (not a multiple of the 64 ids an order is bound from): three batches,
    // later ones finding most pixels opaque, and one batch (the default size); an image whose
    // sides are not multiples of a tile; a turned view; and the same with no pixel ever
    // stopping.
    let scene = solid(35);
    let turned = camera_of(&scene).orbit_about(scene.up_axis(), 50.0, 20.0);
    let ctx = context();
    for (camera, size) in [(camera_of(&scene), (96, 80)), (turned, (150, 71))] {
        compare_at(&scene, &camera, size, &OPTIONS, "dense block");
        let mut whole = Renderer::with_compositor(Compositor::GpuTiles);
        whole.set_levels_by_brick(false);
        let one = whole
            .screenshot(&ctx, &scene, &camera, size, &OPTIONS)
            .unwrap();
        let cpu = shoot(
            &ctx,
            Compositor::Cpu,
            &scene,
            &camera,
            size,
            &OPTIONS,
            splatscene::splat::tiled::OPAQUE,
        );
        assert!(one.report.splats > 2 * BATCH, "{}", one.report.splats);
        let one = compare(&one.frame, &cpu).unwrap();
        assert_same(&one, "dense block, one batch");
        let gpu = shoot(
            &ctx,
            Compositor::GpuTiles,
            &scene,
            &camera,
            size,
            &OPTIONS,
            2.0,
        );
        let cpu = shoot(&ctx, Compositor::Cpu, &scene, &camera, size, &OPTIONS, 2.0);
        let d = compare(&gpu, &cpu).unwrap();
        assert!(d.rmse < 2e-4 && d.max_abs < 1e-3, "never stopping: {d:?}");
        // Stopping leaves out at most the threshold's share, on the GPU too.
        let stopping = shoot(
            &ctx,
            Compositor::GpuTiles,
            &scene,
            &camera,
            size,
            &OPTIONS,
            splatscene::splat::tiled::OPAQUE,
        );
        let d = compare(&stopping, &gpu).unwrap();
        let bound = f64::from(1.0 - splatscene::splat::tiled::OPAQUE);
        assert!(d.max_abs <= bound + 1e-4, "{d:?} against {bound}");
    }
}

#[test]
fn zoomed_views_with_most_splats_off_the_image() {
    let scene = volume_scene(shells(36, [1.0; 3]), Ordering::IpPbtfImplicit);
    let whole = camera_of(&scene);
    let corner = DVec3::new(4.0, 4.0, 30.0);
    let near = SceneCamera {
        eye: corner + (whole.eye - whole.target).normalize() * 14.0,
        target: corner,
        ..whole
    };
    let flat = SceneCamera {
        projection: Projection::Orthographic { height: 9.0 },
        ..near
    };
    compare_at(&scene, &near, (96, 80), &OPTIONS, "zoomed");
    compare_at(&scene, &flat, (150, 71), &OPTIONS, "zoomed orthographic");
}

#[test]
fn the_built_in_scene_and_the_engine() {
    let scene = splatscene::scene::shoulder::shoulder_scene().unwrap();
    let camera = scene.camera.unwrap();
    compare_at(&scene, &camera, (160, 120), &OPTIONS, "built-in");
    // The GE engine block (Open SciVis datasets, General Electric): 1.05M faint sub-pixel
    // splats, in batches up to the largest.
    let Some((engine, camera)) = engine_view(1.2) else {
        return;
    };
    compare_at(&engine, &camera, (144, 120), &OPTIONS, "engine");
}

#[test]
fn volumes_drawn_brick_by_brick() {
    // The translucent blobs from 40 mm before their face (near bricks at the own grid, far ones
    // coarser) and from an oblique eye, each volume drawn brick by brick: a batch holds runs of
    // several levels' orders, each projected from its own grid, and the picture is the CPU
    // tiles' (in small batches, and in one).
    let ctx = context();
    let scene = translucent_blobs();
    let oblique = across_the_blobs();
    // And a second field beyond the first, offset so that it shows beside it: one volume drawn
    // brick by brick, the other at one level or brick by brick, in one batch.
    let mut two = translucent_blobs();
    let (_, node, _) = two.volumes().next().unwrap();
    let node = node.clone();
    two.add(
        "beyond",
        DMat4::from_translation(DVec3::new(70.0, 20.0, 150.0)),
        None,
        NodeContent::Volume(node),
    )
    .unwrap();
    let opaque = splatscene::splat::tiled::OPAQUE;
    let cases = [
        ("before", &scene, before_the_blobs(40.0)),
        ("oblique", &scene, oblique),
        ("two volumes", &two, before_the_blobs(40.0)),
    ];
    for (what, scene, camera) in cases {
        let shot = |compositor, batch: usize| {
            let mut renderer = Renderer::with_compositor(compositor);
            renderer.tile_compositor_mut().opaque = opaque;
            renderer.set_gpu_tile_batch(std::num::NonZeroUsize::new(batch).unwrap());
            renderer
                .screenshot(&ctx, scene, &camera, (64, 56), &OPTIONS)
                .unwrap()
        };
        let cpu = shot(Compositor::Cpu, BATCH);
        assert!(cpu.report.bricks_by_level >= 1, "{what}: {:?}", cpu.report);
        assert!(cpu.report.levels.iter().any(|&l| l > 0), "{what}");
        for batch in [BATCH, 1 << 22] {
            let gpu = shot(Compositor::GpuTiles, batch);
            let by_brick = cpu.report.bricks_by_level;
            assert_eq!(
                gpu.report.bricks_by_level, by_brick,
                "{what}: {:?}",
                gpu.report
            );
            assert_eq!(gpu.report.splats, cpu.report.splats, "{what}");
            let d = compare(&gpu.frame, &cpu.frame).unwrap();
            eprintln!(
                "{what}, batch {batch}: {} splats, levels {:?}, {by_brick} by brick: {d:?}",
                cpu.report.splats, cpu.report.levels
            );
            assert_same(&d, what);
        }
    }
}
