//! Frame times of a scene file, meshes included, the camera turning about the scene's up: each
//! frame's stages on one line, then the median of the frames after the first (whose times
//! include whatever they made). The measurement
//! behind the viewer's full frames in BENCHMARKS.md ("Magnified bricks").
//!
//! ```sh
//! cargo run --release --example scene_frames -- SCENE.toml WxH FRAMES TURN_DEGREES [full|preview[N]|rest|window[N]] [copies|no-copies] [png=PATH] [volumes=D] [compositor=C]
//! ```
//!
//! Frames are drawn as the viewer draws them with the CPU tiles on a CPU adapter (lavapipe):
//! meshes on the GPU adapter, splats by the tile compositor. `full` (the default) draws the
//! viewer's full frames (no refinement of grids coarser than the pixels), `preview` its
//! previews while the camera moves (at least one level of detail coarser; drawn here at the
//! size given; `previewN`, such as `preview2`, a preview of coarseness N,
//! `FrameOptions::preview`), `rest` the refined frame once the camera rests, `window` the
//! previews while a
//! window is dragged over the values (the camera still, each volume's transfer function
//! windowed one value further each frame, TURN_DEGREES then ignored). `no-copies`
//! draws previews without coarse copies (`Renderer::set_preview_copies`). `png=PATH` writes
//! the last frame to PATH; `volumes=D` composites the volumes at 1/D of the pixels, laid over
//! the meshes at the size given (`FrameOptions::volume_divisor`). `compositor=gpu` or
//! `compositor=gpu-tiles` draws the splats with a GPU pass instead (its upload and splat
//! stage then on each line).

use anyhow::{Context, Result, bail};
use splatscene::render::{Compositor, FrameOptions, GpuContext, Renderer};
use splatscene::scene::NodeContent;
use splatscene::scene::file::load_scene_file;
use std::sync::Arc;

const USAGE: &str = "usage: scene_frames SCENE.toml WxH FRAMES TURN_DEGREES [full|preview[N]|rest|window[N]] [copies|no-copies] [png=PATH] [volumes=D] [compositor=cpu|gpu|gpu-tiles]";

fn main() -> Result<()> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    // `png=PATH` anywhere: the last frame written there.
    let png = args
        .iter()
        .position(|a| a.starts_with("png="))
        .map(|i| args.remove(i)[4..].to_string());
    // `volumes=D`: the volumes composited at 1/D of the pixels (`FrameOptions::volume_divisor`).
    let compositor = match args.iter().position(|a| a.starts_with("compositor=")) {
        Some(i) => match &args.remove(i)[11..] {
            "cpu" => Compositor::Cpu,
            "gpu" => Compositor::Gpu,
            "gpu-tiles" => Compositor::GpuTiles,
            other => bail!("compositor={other}: cpu, gpu or gpu-tiles; {USAGE}"),
        },
        None => Compositor::Cpu,
    };
    let volume_divisor = match args.iter().position(|a| a.starts_with("volumes=")) {
        Some(i) => args.remove(i)[8..].parse::<u32>().context("volumes=D")?,
        None => 1,
    };
    if !(4..=6).contains(&args.len()) {
        bail!("{USAGE}");
    }
    let loaded = load_scene_file(std::path::Path::new(&args[0]))?;
    let (w, h) = args[1]
        .split_once('x')
        .and_then(|(w, h)| Some((w.parse::<u32>().ok()?, h.parse::<u32>().ok()?)))
        .context("WxH")?;
    let frames: usize = args[2].parse().context("FRAMES")?;
    let turn: f64 = args[3].parse().context("TURN_DEGREES")?;
    // The viewer's three kinds of frame: previews while the camera moves, full frames once
    // it stops, and the refined frame once it rests.
    let windowing = args.get(4).is_some_and(|a| a.starts_with("window"));
    let coarseness = |rest: &str| match rest {
        "" => Some(1),
        n => n.parse::<u8>().ok().filter(|&n| n > 0),
    };
    let (preview, refined) = match args.get(4).map(String::as_str) {
        None | Some("full") => (0, false),
        Some("rest") => (0, true),
        Some(kind) => match kind
            .strip_prefix("preview")
            .or_else(|| kind.strip_prefix("window"))
            .and_then(coarseness)
        {
            Some(n) => (n, false),
            None => bail!("{kind:?}: full, preview[N], rest or window[N]; {USAGE}"),
        },
    };
    let mut scene = loaded.scene;
    // Each volume's function and the window its points span, for `window`.
    let own: Vec<_> = scene
        .volumes()
        .map(|(id, v, _)| {
            let (lo, hi) = v.transfer.points().iter().fold(
                (f32::INFINITY, f32::NEG_INFINITY),
                |(lo, hi), (value, _)| (lo.min(*value), hi.max(*value)),
            );
            (id, Arc::clone(&v.transfer), (lo + hi) / 2.0, hi - lo)
        })
        .collect();
    let camera = scene.camera.context("the scene has no camera")?;
    let ctx = GpuContext::headless()?;
    let mut renderer = Renderer::with_compositor(compositor);
    renderer.set_refinement(refined);
    match args.get(5).map(String::as_str) {
        None | Some("copies") => {}
        Some("no-copies") => renderer.set_preview_copies(false),
        Some(other) => bail!("{other:?}: copies or no-copies; {USAGE}"),
    }
    let options = FrameOptions {
        background: loaded.background,
        preview,
        volume_divisor,
        ..FrameOptions::default()
    };
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    let mut kept = Vec::new();
    for f in 0..=frames {
        let turned = if windowing {
            for (id, transfer, level, width) in &own {
                let windowed = Arc::new(transfer.windowed(level + f as f32, width.max(1.0)));
                if let Ok(node) = scene.node(*id)
                    && let NodeContent::Volume(v) = &node.content
                {
                    let mut v = v.clone();
                    v.transfer = windowed;
                    scene.set_content(*id, NodeContent::Volume(v))?;
                }
            }
            camera
        } else {
            camera.orbit_about(camera.up, turn * f as f64, 0.0)
        };
        let started = std::time::Instant::now();
        let shot = renderer.screenshot(&ctx, &scene, &turned, (w, h), &options)?;
        let total = ms(started.elapsed());
        let t = shot.report.timings;
        let made = ms(t.classify + t.levels + t.texels);
        let s = shot.report.tiles.unwrap_or_default();
        println!(
            "frame {f}: {total:.0} ms (making {made:.0}: classify {:.0}, levels {:.0}, texels {:.0}; look {:.0}, order {:.0}, upload {:.0}, splat pass {:.0}, mesh pass {:.0}, readback {:.0}, project {:.0}, bin {:.0}, tiles {:.0}), {} splats, {} projected, {} culled, {} off image, {} drew, {} composited, levels {:?}{}, refined {:?}, coarse copies {}",
            ms(t.classify),
            ms(t.levels),
            ms(t.texels),
            ms(t.seen),
            ms(t.order),
            ms(t.upload),
            ms(t.splat_pass),
            ms(t.mesh_pass),
            ms(t.readback),
            ms(s.project),
            ms(s.bin),
            ms(s.tiles),
            shot.report.splats,
            s.projected,
            s.culled,
            s.off_image,
            s.drew,
            s.composited,
            shot.report.levels,
            if shot.report.levels_short_of_memory {
                " (a level short of memory)"
            } else {
                ""
            },
            shot.report.refined,
            shot.report.coarse_copies,
        );
        if f > 0 {
            kept.push(total);
        }
        if let (Some(path), true) = (&png, f == frames) {
            splatscene::render::frame_to_rgba8(&shot.frame)
                .save(path)
                .with_context(|| format!("writing {path}"))?;
        }
    }
    kept.sort_by(f64::total_cmp);
    if let Some(median) = kept.get(kept.len() / 2) {
        println!("median {median:.0} ms a frame");
    }
    Ok(())
}
