//! A scene file to a colour PNG and, if asked, a 16-bit depth PNG of its meshes (near black,
//! far white; splats write no depth).
//!
//! ```sh
//! cargo run --release --example screenshot -- SCENE.toml OUT.png [DEPTH.png]
//! ```
//!
//! The image size, background and ordering come from the scene file's `[output]` table (800x600
//! when it gives no size), the camera from its `[camera]` table.

mod common;

use std::path::PathBuf;

use anyhow::{Result, bail};
use splatscene::scene::file::load_scene_file;

const USAGE: &str = "usage: screenshot SCENE.toml OUT.png [DEPTH.png]";

fn main() -> Result<()> {
    let args: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    let (scene_path, out, depth) = match args.as_slice() {
        [scene, out] => (scene, out, None),
        [scene, out, depth] => (scene, out, Some(depth)),
        _ => bail!("{USAGE}"),
    };

    let loaded = load_scene_file(scene_path)?;
    let scene = &loaded.scene;
    let shot = common::render_loaded(&loaded, (800, 600))?;
    common::write_color_png(&shot, out)?;
    println!("{}: {}", out.display(), common::describe(&shot.report));
    if let Some(depth) = depth {
        if scene.meshes().next().is_none() {
            bail!("the scene has no meshes, so its mesh depth would be empty");
        }
        let calibration = common::write_depth_png(&shot, depth)?;
        println!(
            "{}: mesh depth, 16-bit grey, {} to {} mm",
            depth.display(),
            calibration["near_mm"],
            calibration["far_mm"]
        );
    }
    Ok(())
}
