//! Helpers shared by the rendering examples: safe file writes, PNG output of a screenshot and a
//! one-line frame report.

// Each example includes this module with `mod common;` and uses only part of it.
#![allow(dead_code)]

use std::path::Path;

use anyhow::{Context, Result};
use splatscene::render::{
    DepthImage, DepthMode, FrameOptions, FrameReport, GpuContext, Renderer, Screenshot, encode_png,
    frame_to_rgba8,
};
use splatscene::scene::file::LoadedScene;

/// Writes `bytes` to `path` through a temporary file next to it and a rename, so that a failed
/// or interrupted write never leaves a truncated image where a reader expects a whole one (an
/// earlier file stays as it was).
pub fn write_replacing(path: &Path, bytes: &[u8]) -> Result<()> {
    let name = path
        .file_name()
        .with_context(|| format!("{} has no file name", path.display()))?;
    // Same folder, so that the rename stays on one file system and replaces atomically.
    let partial = path.with_file_name(format!(".{}.partial", name.to_string_lossy()));
    if let Err(e) = std::fs::write(&partial, bytes) {
        // A partly written temporary file is of no use to anybody.
        let _ = std::fs::remove_file(&partial);
        return Err(e).with_context(|| format!("writing {}", partial.display()));
    }
    std::fs::rename(&partial, path)
        .with_context(|| format!("renaming {} to {}", partial.display(), path.display()))
}

/// Writes the colour of a screenshot as an 8-bit RGBA PNG.
pub fn write_color_png(shot: &Screenshot, path: &Path) -> Result<()> {
    let png = encode_png(&frame_to_rgba8(&shot.frame)).context("encoding the colour PNG")?;
    write_replacing(path, &png)
}

/// Writes the mesh depth of a screenshot as a calibrated 16-bit grey PNG (see
/// `splatscene::render::DepthImage`), near black and far white, and returns its calibration.
pub fn write_depth_png(shot: &Screenshot, path: &Path) -> Result<serde_json::Value> {
    let image = DepthImage {
        size: shot.view.size,
        distances: shot
            .depth
            .iter()
            .map(|&d| shot.view.distance_of(d))
            .collect(),
        mode: DepthMode::Mesh,
        surface_opacity: None,
    };
    let (png, calibration) = image
        .encode_png(&shot.view)
        .context("encoding the depth PNG")?;
    write_replacing(path, &png)?;
    Ok(calibration)
}

/// What a frame drew and where its time went, on one line.
pub fn describe(report: &FrameReport) -> String {
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    let t = &report.timings;
    format!(
        "{} meshes ({} triangles), {} splats, {} volumes classified; classify {:.0} ms, order {:.1} ms, upload {:.1} ms, mesh pass {:.1} ms, splat pass {:.1} ms, readback {:.1} ms",
        report.meshes,
        report.triangles,
        report.splats,
        report.classified,
        ms(t.classify),
        ms(t.order),
        ms(t.upload),
        ms(t.mesh_pass),
        ms(t.splat_pass),
        ms(t.readback)
    )
}

/// Renders a loaded scene file with its own camera, ordering and background, at its own size
/// or `default_size`.
pub fn render_loaded(loaded: &LoadedScene, default_size: (u32, u32)) -> Result<Screenshot> {
    let camera = loaded.scene.camera.context("the scene has no camera")?;
    let size = loaded.size.unwrap_or(default_size);
    let options = FrameOptions {
        ordering: loaded.ordering,
        background: loaded.background,
        ..FrameOptions::default()
    };
    let ctx = GpuContext::headless()?;
    Ok(Renderer::new().screenshot(&ctx, &loaded.scene, &camera, size, &options)?)
}
