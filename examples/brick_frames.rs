//! Frame times of a u8 or u16 volume (by the file's size) drawn by the CPU tiles with each
//! brick at its own level and with one detail a volume, in turn, the camera turning about the
//! superior axis: the measurement of "Bricks at their own levels" in BENCHMARKS.md.
//!
//! ```sh
//! cargo run --release --example brick_frames -- VOLUME.raw NX,NY,NZ SX,SY,SZ LO,HI \
//!     EYE TARGET WxH FRAMES TURN_DEGREES [OUT_PREFIX]
//! ```
//!
//! The volume is placed as orientation LAI (the LIDC2 CT's), its transfer function a ramp from
//! clear at LO to (1, 0.93, 0.85, 0.6) at HI, shading 0.8, a 35 degree field of view. Each
//! frame prints both renderers' times, splats and details; at the end, the median of the
//! frames after the first, less the time spent making classifications, levels and texels.
//! With OUT_PREFIX, the last frame of each is written to OUT_PREFIX-brick.png and
//! OUT_PREFIX-volume.png.

use std::sync::Arc;

use anyhow::{Context, Result, bail};
use glam::{DMat3, DMat4, DVec3};
use splatscene::classify::TransferFunction;
use splatscene::render::{FrameOptions, Renderer, frame_to_rgba8};
use splatscene::scene::{NodeContent, Projection, Scene, SceneCamera, SplatSettings, VolumeNode};
use splatscene::volume::{ByteOrder, RawSpec, ScalarType, load_raw};

const USAGE: &str = "usage: brick_frames VOLUME.raw NX,NY,NZ SX,SY,SZ LO,HI EYE TARGET WxH FRAMES TURN_DEGREES [OUT_PREFIX]";

fn numbers<const N: usize>(text: &str) -> Result<[f64; N]> {
    let parts = text
        .split([',', 'x'])
        .map(|v| v.trim().parse::<f64>())
        .collect::<Result<Vec<_>, _>>()
        .with_context(|| format!("{text:?} is not a list of numbers"))?;
    parts
        .try_into()
        .map_err(|_| anyhow::anyhow!("{text:?}: {N} numbers wanted"))
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if !(9..=10).contains(&args.len()) {
        bail!("{USAGE}");
    }
    let dims = numbers::<3>(&args[1])?.map(|v| v as u32);
    let spacing = numbers::<3>(&args[2])?;
    let [lo, hi] = numbers::<2>(&args[3])?;
    let eye = DVec3::from(numbers::<3>(&args[4])?);
    let target = DVec3::from(numbers::<3>(&args[5])?);
    let [w, h] = numbers::<2>(&args[6])?.map(|v| v as u32);
    let frames: usize = args[7].parse().context("FRAMES")?;
    let turn: f64 = args[8].parse().context("TURN_DEGREES")?;
    // u8 or little-endian u16, by the file's size.
    let voxels: u64 = dims.iter().map(|&n| u64::from(n)).product();
    let bytes = std::fs::metadata(&args[0])
        .with_context(|| args[0].clone())?
        .len();
    let scalar = match bytes / voxels.max(1) {
        2 => ScalarType::U16,
        _ => ScalarType::U8,
    };
    let spec = RawSpec::new(dims, scalar, ByteOrder::Little);
    let mut volume = load_raw(std::path::Path::new(&args[0]), &spec)?;
    volume.spacing = spacing;
    volume.direction = DMat3::from_diagonal(DVec3::new(-1.0, 1.0, -1.0));
    let transfer = TransferFunction::ramp(lo as f32, hi as f32, [1.0, 0.93, 0.85, 0.6]);
    let mut scene = Scene::new();
    scene.add(
        "ct",
        DMat4::IDENTITY,
        None,
        NodeContent::Volume(VolumeNode {
            volume: Arc::new(volume),
            transfer: Arc::new(transfer),
            splats: SplatSettings {
                shading: 0.8,
                ..Default::default()
            },
        }),
    )?;
    let base = SceneCamera {
        eye,
        target,
        up: DVec3::Z,
        projection: Projection::Perspective {
            fov_y_degrees: 35.0,
        },
        near: None,
    };
    let mut renderers = [Renderer::new(), Renderer::new()];
    renderers[1].set_levels_by_brick(false);
    let names = ["brick", "volume"];
    let options = FrameOptions::default();
    let mut kept: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
    for f in 0..=frames {
        let camera = base.orbit_about(DVec3::Z, turn * f as f64, 0.0);
        for (m, renderer) in renderers.iter_mut().enumerate() {
            let started = std::time::Instant::now();
            let shot = renderer.screenshot_without_gpu(&scene, &camera, (w, h), &options)?;
            let ms = started.elapsed().as_secs_f64() * 1e3;
            let t = shot.report.timings;
            let made = (t.classify + t.levels + t.texels).as_secs_f64() * 1e3;
            let stages = shot.report.tiles.unwrap_or_default();
            let ms_of = |d: std::time::Duration| d.as_secs_f64() * 1e3;
            println!(
                "frame {f} {}: {ms:.0} ms (making {made:.0}: classify {:.0}, texels {:.0}; look {:.0}, order {:.0}, project {:.0}, bin {:.0}, tiles {:.0}), {} splats, levels {:?}, refined {:?}, by brick {}",
                names[m],
                ms_of(t.classify),
                ms_of(t.texels),
                ms_of(t.seen),
                ms_of(t.order),
                ms_of(stages.project),
                ms_of(stages.bin),
                ms_of(stages.tiles),
                shot.report.splats,
                shot.report.levels,
                shot.report.refined,
                shot.report.bricks_by_level
            );
            if f > 0 {
                kept[m].push(ms - made);
            }
            if let (true, Some(prefix)) = (f == frames, args.get(9)) {
                frame_to_rgba8(&shot.frame).save(format!("{prefix}-{}.png", names[m]))?;
            }
        }
    }
    for (m, times) in kept.iter_mut().enumerate() {
        times.sort_by(f64::total_cmp);
        if let Some(median) = times.get(times.len() / 2) {
            println!("{}: median {median:.0} ms a frame", names[m]);
        }
    }
    Ok(())
}
