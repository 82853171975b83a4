//! Frame time of the renderer: the built-in shoulder scene at the viewer's default 960x720,
//! and the engine and the CT head (classified with a ramp transfer function) with the
//! prosthesis seated in them at 512x512, on whatever adapter wgpu finds
//! (lavapipe on machines without a GPU). Criterion times whole frames read back to the CPU;
//! afterwards a few frames with stage timing print the split (order, upload, mesh pass, splat
//! pass, readback), medians over the frames.
//!
//! The group `viewer-frame` draws the shoulder scene as the viewer does, into a window-sized
//! target that is kept, with no readback, the camera turning 7 degrees a frame as in a drag:
//! in full and as a preview frame (volumes at half resolution).
//!
//! The group `frame-order` times the engine frame once per ordering (the same camera turn),
//! so the cost of each ordering can be read against the whole frame on the adapter at hand:
//! `cargo bench --bench frame -- frame-order`.
//!
//! `cargo bench --bench frame`; the data comes from `SPLATSCENE_DATA` (default
//! `../shared/data`).

use std::sync::Arc;
use std::time::Duration;

use criterion::measurement::WallTime;
use criterion::{BenchmarkGroup, Criterion, criterion_group, criterion_main};
use glam::{DMat4, DVec3};
use splatscene::classify::TransferFunction;
use splatscene::order::Ordering;
use splatscene::render::{
    FrameOptions, FrameTimings, GpuContext, RenderTarget, Renderer, ViewSetup,
};
use splatscene::scene::shoulder::{add_model, prosthesis_model};
use splatscene::scene::{NodeContent, Scene, SceneCamera, SplatSettings, VolumeNode};
use splatscene::volume::CpuVolume;

mod common;

fn scene(volume: CpuVolume, tf: TransferFunction) -> Scene {
    let mut scene = Scene::new();
    let node = VolumeNode {
        volume: Arc::new(volume),
        transfer: Arc::new(tf),
        splats: SplatSettings::default(),
    };
    scene
        .add("ct", DMat4::IDENTITY, None, NodeContent::Volume(node))
        .unwrap();
    let (lo, hi) = scene.bounds().unwrap();
    let at = DMat4::from_translation(0.5 * (lo + hi) + DVec3::new(0.0, 0.0, 0.2 * (hi.z - lo.z)));
    add_model(
        &mut scene,
        "prosthesis",
        at,
        &prosthesis_model().unwrap(),
        None,
    );
    let bounds = scene.bounds().unwrap();
    scene.camera = Some(SceneCamera::fit(
        bounds,
        DVec3::new(-0.4, 1.0, -0.55),
        Default::default(),
        1.0,
    ));
    scene
}

fn scenes() -> Vec<(&'static str, Scene)> {
    let (engine, head) = (common::engine(), common::ct_head());
    // The built-in scene as `splatscene view` first shows it, at the viewer's default size.
    let shoulder = splatscene::scene::shoulder::shoulder_scene().unwrap();
    vec![
        ("shoulder", shoulder),
        (
            "engine",
            scene(
                engine,
                TransferFunction::ramp(100.0, 200.0, [0.85, 0.8, 0.75, 0.5]),
            ),
        ),
        (
            "cthead",
            scene(
                head,
                TransferFunction::ramp(1200.0, 1800.0, [1.0, 0.93, 0.85, 0.6]),
            ),
        ),
    ]
}

fn median(mut v: Vec<Duration>) -> f64 {
    v.sort();
    v[v.len() / 2].as_secs_f64() * 1e3
}

/// Times whole frames of `scene` turning 7 degrees a frame under `name`, then returns the
/// stage timings of 7 measured frames 11 degrees apart; `None` when criterion's filter left
/// the benchmark out.
fn bench_and_split(
    group: &mut BenchmarkGroup<'_, WallTime>,
    name: &str,
    renderer: &mut Renderer,
    ctx: &GpuContext,
    scene: &Scene,
    size: (u32, u32),
    options: FrameOptions,
) -> Option<Vec<FrameTimings>> {
    let base = scene.camera.unwrap();
    let mut turn = 0.0;
    let mut ran = false;
    group.bench_function(name, |b| {
        ran = true;
        b.iter(|| {
            turn += 7.0;
            renderer
                .screenshot(ctx, scene, &base.orbit(turn, 0.0), size, &options)
                .unwrap()
        })
    });
    if !ran {
        return None;
    }
    let measured = FrameOptions {
        measure: true,
        ..options
    };
    let runs = (0..7)
        .map(|i| {
            let camera = base.orbit(f64::from(i) * 11.0, 0.0);
            renderer
                .screenshot(ctx, scene, &camera, size, &measured)
                .unwrap()
                .report
                .timings
        })
        .collect();
    Some(runs)
}

/// A group of whole frames: ten samples, one second of warm-up, `seconds` of measuring.
fn frame_group<'a>(c: &'a mut Criterion, name: &str, seconds: u64) -> BenchmarkGroup<'a, WallTime> {
    let mut group = c.benchmark_group(name);
    group
        .sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(seconds));
    group
}

fn frames(c: &mut Criterion) {
    let ctx = GpuContext::headless().expect("a GPU adapter (install mesa-vulkan-drivers)");
    eprintln!("adapter: {}", ctx.describe());
    let size_of = |name: &str| {
        if name == "shoulder" {
            (960, 720)
        } else {
            (512, 512)
        }
    };
    let mut group = frame_group(c, "frame", 10);
    for (name, scene) in scenes() {
        let size = size_of(name);
        let mut renderer = Renderer::new();
        let base = scene.camera.unwrap();
        let options = FrameOptions {
            measure: false,
            ..Default::default()
        };
        let Some(runs) =
            bench_and_split(&mut group, name, &mut renderer, &ctx, &scene, size, options)
        else {
            continue;
        };
        let report = renderer
            .screenshot(&ctx, &scene, &base, size, &options)
            .unwrap()
            .report;
        let stage = |f: fn(&FrameTimings) -> Duration| median(runs.iter().map(f).collect());
        eprintln!(
            "{name}: {} splats, {} triangles; median ms over 7 frames: order {:.1}, upload {:.1}, mesh pass {:.1}, splat pass {:.1}, readback {:.1}",
            report.splats,
            report.triangles,
            stage(|t| t.order),
            stage(|t| t.upload),
            stage(|t| t.mesh_pass),
            stage(|t| t.splat_pass),
            stage(|t| t.readback),
        );
    }
    group.finish();
}

/// The engine frame at 512x512 drawn in each ordering, and the stage split per ordering.
fn frames_per_ordering(c: &mut Criterion) {
    let ctx = GpuContext::headless().expect("a GPU adapter (install mesa-vulkan-drivers)");
    let scene = scene(
        common::engine(),
        TransferFunction::ramp(100.0, 200.0, [0.85, 0.8, 0.75, 0.5]),
    );
    let mut renderer = Renderer::new();
    let mut group = frame_group(c, "frame-order", 5);
    for ordering in Ordering::ALL {
        let options = FrameOptions {
            ordering: Some(ordering),
            measure: false,
            ..Default::default()
        };
        let Some(runs) = bench_and_split(
            &mut group,
            ordering.name(),
            &mut renderer,
            &ctx,
            &scene,
            (512, 512),
            options,
        ) else {
            continue;
        };
        let stage = |f: fn(&FrameTimings) -> Duration| median(runs.iter().map(f).collect());
        eprintln!(
            "engine, {}: median ms over 7 frames: order {:.2}, upload {:.2}, splat pass {:.2}",
            ordering.name(),
            stage(|t| t.order),
            stage(|t| t.upload),
            stage(|t| t.splat_pass),
        );
    }
    group.finish();
}

/// The viewer's frame of the shoulder scene at 960x720, in full and as a preview.
fn viewer_frames(c: &mut Criterion) {
    let ctx = GpuContext::headless().expect("a GPU adapter (install mesa-vulkan-drivers)");
    let scene = splatscene::scene::shoulder::shoulder_scene().unwrap();
    let base = scene.camera.unwrap();
    let size = (960, 720);
    let target = RenderTarget::new(&ctx, size.0, size.1).unwrap();
    let mut renderer = Renderer::new();
    let mut group = frame_group(c, "viewer-frame", 10);
    for (name, preview) in [("shoulder", 0), ("shoulder-preview", 1)] {
        let options = FrameOptions {
            measure: false,
            preview,
            ..Default::default()
        };
        let mut turn = 0.0;
        group.bench_function(name, |b| {
            b.iter(|| {
                turn += 7.0;
                let view = ViewSetup::new(&base.orbit(turn, 0.0), size, scene.bounds()).unwrap();
                let report = renderer
                    .render(
                        &ctx,
                        &scene,
                        &view,
                        &target.color_view,
                        &target.depth_view,
                        &options,
                    )
                    .unwrap();
                ctx.wait().unwrap();
                report.splats
            })
        });
    }
    group.finish();
}

criterion_group!(benches, frames, frames_per_ordering, viewer_frames);
criterion_main!(benches);
