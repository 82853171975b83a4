//! The built-in shoulder scene (the phantom's right shoulder with its humeral head resected and
//! the front of the humerus cut away, and the prosthesis seated in it) seen from the views a
//! planning review goes through: the scene's own camera, then anterior, lateral, superior and
//! posterior views fitted to the scene. One PNG per view.
//!
//! ```sh
//! cargo run --release --example shoulder_planning -- [OUT_DIR]   # default shoulder-views/
//! ```

mod common;

use std::path::PathBuf;

use anyhow::{Context, Result};
use glam::DVec3;
use splatscene::render::{FrameOptions, GpuContext, Renderer};
use splatscene::scene::shoulder::shoulder_scene;
use splatscene::scene::{Projection, SceneCamera};

const SIZE: (u32, u32) = (640, 480);

fn main() -> Result<()> {
    let out_dir = std::env::args_os()
        .nth(1)
        .map_or_else(|| PathBuf::from("shoulder-views"), PathBuf::from);
    std::fs::create_dir_all(&out_dir).with_context(|| format!("creating {}", out_dir.display()))?;

    let scene = shoulder_scene()?;
    let bounds = scene
        .bounds()
        .context("the built-in scene has nothing to draw")?;
    let planning = scene.camera.context("the built-in scene has no camera")?;
    let aspect = f64::from(SIZE.0) / f64::from(SIZE.1);
    let fitted =
        |direction: DVec3| SceneCamera::fit(bounds, direction, Projection::default(), aspect);
    // The phantom's frame: +x lateral, +y anterior, +z superior. A fitted camera looks along
    // the direction it is given, so each view looks from its side toward the opposite one.
    let views = [
        ("planning", planning),
        ("anterior", fitted(DVec3::NEG_Y)),
        ("lateral", fitted(DVec3::NEG_X)),
        ("superior", fitted(DVec3::NEG_Z)),
        ("posterior", fitted(DVec3::Y)),
    ];

    let ctx = GpuContext::headless()?;
    println!("rendering on {}", ctx.describe());
    // One renderer for every view: the volume is classified and uploaded once, later views
    // only order the splats again.
    let mut renderer = Renderer::new();
    let options = FrameOptions::default();
    for (name, camera) in views {
        let shot = renderer.screenshot(&ctx, &scene, &camera, SIZE, &options)?;
        let path = out_dir.join(format!("{name}.png"));
        common::write_color_png(&shot, &path)?;
        println!("{}: {}", path.display(), common::describe(&shot.report));
    }
    Ok(())
}
