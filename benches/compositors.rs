//! The two splat compositors side by side: the GPU splat pass (on whatever adapter wgpu finds,
//! lavapipe on machines without a GPU) and the CPU tile compositor, alternating frame by frame
//! on the same camera path, so that both see the same machine load. Whole frames: order,
//! composite and readback (the GPU's frame read back to memory; the CPU's is there already).
//!
//! Views: the engine (ramp 100-200 to opacity 0.5) and the CT head (ramp 1200-1800 to 0.6),
//! volumes only, fitted to their voxel centres looking along (-0.4, 1, -0.55) with a 35 degree
//! field of view, turning 7 degrees a frame about the scene's up: the views of
//! `benches/peers/vtk_raycast.py`. Then the CPU compositor's growth with the splat count (the
//! engine halved, as is, and doubled along every axis) and with the image size.
//!
//! `cargo bench --bench compositors` (data from `SPLATSCENE_DATA`, default `../shared/data`);
//! `-- quick` runs 3 frames a case instead of 9; `-- peers` only the first table; `-- cpu` only
//! the CPU compositor's frames of the first table (for profiling it alone); `-- growth` all but
//! the first table.
//!
//! `-- gpu [SCENE.toml ...]` times the two GPU compositors instead, the splat pass and the tile
//! compositor's compute passes (`--compositor gpu-tiles`), alternating frame by frame: the
//! engine and the CT head above, then each scene file given (its camera and size, 512 x 512
//! where it names none). For each case it prints the tile pass's picture against the CPU
//! tiles' (RMSE), whole frames read back (`screenshot`), the viewer's frames (drawn into a kept
//! target, waited for, nothing read back) and the tile pass's stages. Meant for a machine with
//! a GPU; on lavapipe the compute passes run on the CPU (`files-only` leaves the engine and
//! the head out). `full-grid` draws every volume from its own grid (`--lod off`).

use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::{DMat4, DVec3};
use splatscene::classify::TransferFunction;
use splatscene::render::{
    Compositor, FrameOptions, FrameTimings, GpuContext, RenderTarget, Renderer, ViewSetup,
};
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
    let bounds = scene.bounds().unwrap();
    scene.camera = Some(SceneCamera::fit(
        bounds,
        DVec3::new(-0.4, 1.0, -0.55),
        Default::default(),
        1.0,
    ));
    scene
}

/// Every voxel repeated twice along each axis, at half the spacing: eight times the splats.
fn doubled(v: &CpuVolume) -> CpuVolume {
    let [nx, ny, nz] = v.dims.map(|n| n as usize);
    let mut values = Vec::with_capacity(nx * ny * nz * 8);
    for z in 0..2 * nz {
        for y in 0..2 * ny {
            for x in 0..2 * nx {
                values.push(v.values.at(x / 2 + nx * (y / 2 + ny * (z / 2))));
            }
        }
    }
    CpuVolume {
        dims: v.dims.map(|n| 2 * n),
        spacing: v.spacing.map(|s| s / 2.0),
        values: values.into(),
        ..v.clone()
    }
}

const OPTIONS: FrameOptions = FrameOptions {
    ordering: None,
    background: Some([0.0, 0.0, 0.0]),
    measure: false,
    preview: 0,
    volume_divisor: 1,
};

fn median(mut v: Vec<Duration>) -> f64 {
    v.sort();
    v[v.len() / 2].as_secs_f64() * 1e3
}

/// Median whole-frame times of each renderer, frames alternating between them, after one
/// warm-up frame each (classification, shader compilation).
fn alternate(
    ctx: &GpuContext,
    scene: &Scene,
    size: (u32, u32),
    renderers: &mut [(&str, Renderer)],
    frames: usize,
) -> Vec<f64> {
    let base = scene.camera.unwrap();
    let up = scene.up_axis();
    let mut times = vec![Vec::new(); renderers.len()];
    for i in 0..=frames {
        let camera = base.orbit_about(up, 7.0 * i as f64, 0.0);
        for (k, (_, renderer)) in renderers.iter_mut().enumerate() {
            let started = Instant::now();
            let shot = renderer
                .screenshot(ctx, scene, &camera, size, &OPTIONS)
                .unwrap();
            let elapsed = started.elapsed();
            if i > 0 {
                times[k].push(elapsed);
            }
            if i == 1
                && let Some(t) = shot.report.tiles
            {
                let ms = |d: Duration| d.as_secs_f64() * 1e3;
                eprintln!(
                    "    {} splats: {} drew pixels, {} projected, {} left out unprojected, {} splat-tile pairs composited, {} skipped behind opaque pixels, {} tiles opaque; project {:.1} ms, bin {:.1} ms, tiles {:.1} ms, order {:.1} ms",
                    t.splats,
                    t.drew,
                    t.projected,
                    t.culled,
                    t.composited,
                    t.skipped_opaque,
                    t.tiles_opaque,
                    ms(t.project),
                    ms(t.bin),
                    ms(t.tiles),
                    ms(shot.report.timings.order)
                );
                let timings = &shot.report.timings;
                if timings.readback > Duration::ZERO {
                    eprintln!(
                        "    meshes: pass {:.1} ms, readback (waiting for the pass) {:.1} ms",
                        ms(timings.mesh_pass),
                        ms(timings.readback)
                    );
                }
            }
        }
    }
    times.into_iter().map(median).collect()
}

fn main() {
    let quick = std::env::args().any(|a| a == "quick");
    let frames = if quick { 3 } else { 9 };
    let ctx = GpuContext::headless().expect("a GPU adapter (install mesa-vulkan-drivers)");
    println!(
        "adapter: {}; {} threads",
        ctx.describe(),
        rayon::current_num_threads()
    );
    let engine = common::engine();
    if std::env::args().any(|a| a == "gpu") {
        gpu(&ctx, &engine, frames);
        return;
    }
    let cases = [
        (
            "engine",
            scene(
                engine.clone(),
                TransferFunction::ramp(100.0, 200.0, [0.85, 0.8, 0.75, 0.5]),
            ),
        ),
        (
            "cthead",
            scene(
                common::ct_head(),
                TransferFunction::ramp(1200.0, 1800.0, [1.0, 0.93, 0.85, 0.6]),
            ),
        ),
    ];
    println!(
        "\n| volume, 512x512 | GPU splat pass frame | CPU tiles frame | ratio |\n|---|---|---|---|"
    );
    if std::env::args().any(|a| a == "skip") {
        skipping(&ctx, &cases[1].1);
        return;
    }
    let cpu_only = std::env::args().any(|a| a == "cpu");
    let growth = std::env::args().any(|a| a == "growth");
    for (name, scene) in cases.iter().filter(|_| !growth) {
        if cpu_only {
            let mut renderers = [("cpu", Renderer::with_compositor(Compositor::Cpu))];
            let t = alternate(&ctx, scene, (512, 512), &mut renderers, frames);
            println!("| {name} | | {:.1} ms | |", t[0]);
            continue;
        }
        let mut renderers = [
            ("gpu", Renderer::with_compositor(Compositor::Gpu)),
            ("cpu", Renderer::with_compositor(Compositor::Cpu)),
        ];
        let t = alternate(&ctx, scene, (512, 512), &mut renderers, frames);
        println!(
            "| {name} | {:.1} ms | {:.1} ms | {:.1}x |",
            t[0],
            t[1],
            t[0] / t[1]
        );
    }
    if cpu_only || std::env::args().any(|a| a == "peers") {
        return;
    }
    let tf = TransferFunction::ramp(100.0, 200.0, [0.85, 0.8, 0.75, 0.5]);
    println!("\n| engine | splats | CPU tiles frame, 512x512 |\n|---|---|---|");
    for (label, volume) in [
        ("halved", engine.halved()),
        ("as is", engine.clone()),
        ("doubled", doubled(&engine)),
    ] {
        let scene = scene(volume, tf.clone());
        let mut renderers = [("cpu", Renderer::with_compositor(Compositor::Cpu))];
        let splats = Renderer::with_compositor(Compositor::Cpu)
            .screenshot(&ctx, &scene, &scene.camera.unwrap(), (64, 64), &OPTIONS)
            .unwrap()
            .report
            .splats;
        let t = alternate(&ctx, &scene, (512, 512), &mut renderers, frames);
        println!("| {label} | {splats} | {:.1} ms |", t[0]);
    }
    // The viewer's first picture: the built-in shoulder scene (meshes and a volume) at its
    // default window size, meshes drawn by the adapter and read back under the tiles.
    let shoulder = splatscene::scene::shoulder::shoulder_scene().unwrap();
    let mut renderers = [("cpu", Renderer::with_compositor(Compositor::Cpu))];
    let t = alternate(&ctx, &shoulder, (960, 720), &mut renderers, frames);
    println!(
        "\n| built-in shoulder scene, 960x720 | CPU tiles frame |\n|---|---|\n| full frame | {:.1} ms |",
        t[0]
    );
    println!("\n| engine, image | CPU tiles frame |\n|---|---|");
    let scene = scene(engine, tf);
    for side in [256, 512, 1024] {
        let mut renderers = [("cpu", Renderer::with_compositor(Compositor::Cpu))];
        let t = alternate(&ctx, &scene, (side, side), &mut renderers, frames);
        println!("| {side}x{side} | {:.1} ms |", t[0]);
    }
}

/// What the CPU compositor leaves out of the CT head's first view under bone transfer
/// functions of rising opacity, and how much of the image turns opaque.
fn skipping(ctx: &GpuContext, base: &Scene) {
    let ramps = [
        (
            "ramp 1200-1800 to 0.6 (the table's)",
            TransferFunction::ramp(1200.0, 1800.0, [1.0, 0.93, 0.85, 0.6]),
        ),
        (
            "ramp 1200-1800 to 0.9",
            TransferFunction::ramp(1200.0, 1800.0, [1.0, 0.93, 0.85, 0.9]),
        ),
        (
            "ramp 1200-1500 to 1.0",
            TransferFunction::ramp(1200.0, 1500.0, [1.0, 0.93, 0.85, 1.0]),
        ),
    ];
    let options = FrameOptions {
        background: None,
        ..OPTIONS
    };
    println!(
        "| CT head, 512x512 | splats | drew pixels | left out unprojected | pairs composited | pairs skipped | pixels covered | of those opaque |\n|---|---|---|---|---|---|---|---|"
    );
    let head = common::ct_head();
    for (label, tf) in ramps {
        let mut scene = scene(head.clone(), tf);
        scene.camera = base.camera;
        let mut renderer = Renderer::with_compositor(Compositor::Cpu);
        let shot = renderer
            .screenshot(ctx, &scene, &scene.camera.unwrap(), (512, 512), &options)
            .unwrap();
        let t = shot.report.tiles.unwrap();
        let covered = shot.frame.pixels.iter().filter(|p| p[3] > 0.01).count();
        let opaque = shot.frame.pixels.iter().filter(|p| p[3] >= 0.996).count();
        println!(
            "| {label} | {} | {} | {} | {} | {} | {covered} | {opaque} |",
            t.splats, t.drew, t.culled, t.composited, t.skipped_opaque
        );
    }
}

/// The two GPU compositors on the engine, the CT head and the scene files named on the command
/// line: pictures, whole frames, viewer frames and the tile pass's stages.
fn gpu(ctx: &GpuContext, engine: &CpuVolume, frames: usize) {
    let mut cases = vec![];
    // `files-only`: the scene files alone (a quick check of this mode on lavapipe).
    let builtin = !std::env::args().any(|a| a == "files-only");
    cases.extend(
        [
            (
                "engine".to_string(),
                scene(
                    engine.clone(),
                    TransferFunction::ramp(100.0, 200.0, [0.85, 0.8, 0.75, 0.5]),
                ),
                (512, 512),
            ),
            (
                "cthead".to_string(),
                scene(
                    common::ct_head(),
                    TransferFunction::ramp(1200.0, 1800.0, [1.0, 0.93, 0.85, 0.6]),
                ),
                (512, 512),
            ),
        ]
        .into_iter()
        .filter(|_| builtin),
    );
    for path in std::env::args().filter(|a| a.ends_with(".toml")) {
        let loaded = splatscene::scene::file::load_scene_file(std::path::Path::new(&path))
            .unwrap_or_else(|e| panic!("{path}: {e}"));
        cases.push((path, loaded.scene, loaded.size.unwrap_or((512, 512))));
    }
    println!(
        "\n| case | splats | GPU tiles vs CPU tiles, RMSE | screenshot: splat pass / GPU tiles | viewer frame: splat pass / GPU tiles | GPU tiles: order, upload, splat stage |\n|---|---|---|---|---|---|"
    );
    // `full-grid`: every volume drawn from its own grid (`--lod off`).
    let lod = !std::env::args().any(|a| a == "full-grid");
    let started = Instant::now();
    let progress = |what: &str| eprintln!("{:8.1} s  {what}", started.elapsed().as_secs_f64());
    for (name, scene, size) in &cases {
        let camera = scene.camera.unwrap();
        let renderer = |compositor| {
            let mut r = Renderer::with_compositor(compositor);
            r.set_level_of_detail(lod);
            r
        };
        progress(&format!("{name}: the CPU tiles' picture"));
        let mut cpu = renderer(Compositor::Cpu);
        let reference = cpu
            .screenshot(ctx, scene, &camera, *size, &OPTIONS)
            .unwrap();
        let mut renderers = [
            ("gpu", renderer(Compositor::Gpu)),
            ("gpu-tiles", renderer(Compositor::GpuTiles)),
        ];
        progress(&format!("{name}: the GPU tiles' picture"));
        let tiles = renderers[1]
            .1
            .screenshot(ctx, scene, &camera, *size, &OPTIONS)
            .unwrap();
        let difference =
            splatscene::splat::reference::compare(&reference.frame, &tiles.frame).unwrap();
        progress(&format!("{name}: screenshots"));
        let shots = alternate(ctx, scene, *size, &mut renderers, frames);
        progress(&format!("{name}: viewer frames"));
        let views = viewer_frames(ctx, scene, *size, &mut renderers, frames);
        progress(&format!("{name}: stages"));
        let measured = FrameOptions {
            measure: true,
            ..OPTIONS
        };
        let up = scene.up_axis();
        let timings: Vec<FrameTimings> = (0..7)
            .map(|i| {
                let turned = camera.orbit_about(up, 11.0 * f64::from(i), 0.0);
                renderers[1]
                    .1
                    .screenshot(ctx, scene, &turned, *size, &measured)
                    .unwrap()
                    .report
                    .timings
            })
            .collect();
        let stage = |f: fn(&FrameTimings) -> Duration| median(timings.iter().map(f).collect());
        println!(
            "| {name}, {}x{} | {} | {:.5} (largest {:.3}) | {:.2} / {:.2} ms | {:.2} / {:.2} ms | {:.2}, {:.2}, {:.2} ms |",
            size.0,
            size.1,
            tiles.report.splats,
            difference.rmse,
            difference.max_abs,
            shots[0],
            shots[1],
            views[0],
            views[1],
            stage(|t| t.order),
            stage(|t| t.upload),
            stage(|t| t.splat_pass),
        );
    }
}

/// Median viewer frames of each renderer: drawn into a kept target and waited for, nothing
/// read back, the camera turning 7 degrees a frame, renderers alternating, after one warm-up
/// frame each.
fn viewer_frames(
    ctx: &GpuContext,
    scene: &Scene,
    size: (u32, u32),
    renderers: &mut [(&str, Renderer)],
    frames: usize,
) -> Vec<f64> {
    let target = RenderTarget::new(ctx, size.0, size.1).unwrap();
    let base = scene.camera.unwrap();
    let up = scene.up_axis();
    let mut times = vec![Vec::new(); renderers.len()];
    // Three times the screenshots' frames: a GPU frame is short and the timer's noise is not.
    for i in 0..=3 * frames {
        let camera = base.orbit_about(up, 7.0 * i as f64, 0.0);
        let view = ViewSetup::new(&camera, size, scene.bounds()).unwrap();
        for (k, (_, renderer)) in renderers.iter_mut().enumerate() {
            let started = Instant::now();
            renderer
                .render(
                    ctx,
                    scene,
                    &view,
                    &target.color_view,
                    &target.depth_view,
                    &OPTIONS,
                )
                .unwrap();
            ctx.wait().unwrap();
            if i > 0 {
                times[k].push(started.elapsed());
            }
        }
    }
    times.into_iter().map(median).collect()
}
