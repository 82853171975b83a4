//! `splatscene pick`: the point under a pixel, on a mesh or in a volume, as JSON.

use anyhow::{Result, bail};
use serde_json::json;

use splatscene::pick::{PickOptions, Picker};
use splatscene::render::ViewSetup;

use super::args::{parse_opacity, parse_u32x2};
use super::input::{View, ViewArgs};

/// `splatscene pick`.
#[derive(clap::Args)]
pub struct PickArgs {
    #[command(flatten)]
    view: ViewArgs,
    /// The pixel X,Y (0,0 is the top-left pixel).
    #[arg(long, value_parser = parse_u32x2)]
    pixel: [u32; 2],
    /// Opacity a voxel must exceed to be hit (0 to 1).
    #[arg(long, default_value_t = 0.1, value_parser = parse_opacity)]
    opacity: f32,
    /// Pick meshes only.
    #[arg(long)]
    meshes_only: bool,
}
pub(crate) fn check_pixel(pixel: [u32; 2], size: (u32, u32)) -> Result<()> {
    if pixel[0] >= size.0 || pixel[1] >= size.1 {
        bail!(
            "pixel {},{} is outside the {}x{} image",
            pixel[0],
            pixel[1],
            size.0,
            size.1
        );
    }
    Ok(())
}
pub fn run_pick(args: PickArgs) -> Result<()> {
    let view = args.view.load()?;
    let camera = view.single_camera()?;
    let View { loaded, size, .. } = view;
    check_pixel(args.pixel, size)?;
    let scene = &loaded.scene;
    let view = ViewSetup::new(&camera, size, scene.bounds())?;
    let options = PickOptions {
        opacity_threshold: args.opacity,
        volumes: !args.meshes_only,
    };
    let hit = Picker::new(scene).pick_pixel(scene, &view, args.pixel[0], args.pixel[1], &options);
    let hit = hit.map(|h| h.to_json(scene));
    let out = json!({ "pixel": args.pixel, "size": [size.0, size.1], "hit": hit });
    println!("{}", serde_json::to_string_pretty(&out)?);
    Ok(())
}
