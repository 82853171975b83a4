//! `splatscene view`: the viewer window.

use std::path::PathBuf;

use anyhow::Result;

use splatscene::annotate::Annotations;
use splatscene::render::Compositor;
use splatscene::scene::file::SceneFile;

use super::input::{View, ViewArgs};

/// `splatscene view`.
#[derive(clap::Args)]
pub struct ViewerArgs {
    #[command(flatten)]
    view: ViewArgs,
    /// Folder for screenshots taken with the S key.
    #[arg(long, default_value = ".")]
    screenshots: PathBuf,
    /// Folder for plans (Ctrl+S) and their autosaves (default: beside the scene file, else
    /// beside the volume or mesh given, else the screenshot folder).
    #[arg(long, value_name = "DIR")]
    plans: Option<PathBuf>,
    /// Draw every frame in full, also while the camera moves (by default, where a full frame
    /// takes over 50 ms, a drag or a zoom draws the volumes at half resolution, about an eighth
    /// of the splats).
    #[arg(long)]
    no_preview: bool,
    /// The annotations drawn over the picture: marker, letters, scale, or all (the default);
    /// the A key turns them off and on.
    #[arg(long, default_value = "all", value_name = "PARTS")]
    annotate: String,
    /// No annotations until the A key is pressed.
    #[arg(long, conflicts_with = "annotate")]
    no_annotate: bool,
    /// Who composites the splats: auto (the CPU tile compositor where the GPU adapter is
    /// itself a CPU, else the GPU's splat pass), gpu (the splat pass), cpu (the tile
    /// compositor on the CPU) or gpu-tiles (the tile compositor as GPU compute passes).
    #[arg(long, default_value = "auto")]
    compositor: Compositor,
}
pub fn run_viewer(args: ViewerArgs) -> Result<()> {
    let annotations = if args.no_annotate {
        None
    } else {
        Some(
            Annotations::parse_parts(&args.annotate)
                .map_err(|e| anyhow::anyhow!("--annotate: {e}"))?,
        )
    };
    let scene_path = args.view.input.scene_path();
    let (plan_dir, plan_name) = match (&args.plans, args.view.input.plan_place()) {
        (Some(dir), place) => (Some(dir.clone()), place.map(|(_, name)| name)),
        (None, Some((dir, name))) => (Some(dir), Some(name)),
        (None, None) => (None, None),
    };
    if let Some(dir) = &args.plans
        && !dir.is_dir()
    {
        anyhow::bail!("--plans {}: no such folder", dir.display());
    }
    let view = args.view.load()?;
    let camera = view.single_camera()?;
    // The text of the scene file, for plans written over it with its comments kept.
    let scene_text = match &scene_path {
        Some(p) => Some(SceneFile::read_with_text(p)?.1),
        None => None,
    };
    let View {
        mut loaded,
        size,
        file,
        ..
    } = view;
    loaded.scene.camera = Some(camera);
    let options = splatscene::viewer::ViewerOptions {
        size,
        screenshot_dir: args.screenshots,
        background: loaded.background.unwrap_or([0.06, 0.07, 0.09]),
        preview_while_moving: !args.no_preview,
        scene_file: Some(file),
        ordering: loaded.ordering,
        annotations,
        compositor: args.compositor,
        scene_path,
        scene_text,
        plan_dir,
        plan_name,
    };
    eprintln!(
        "drag to orbit, right drag to pan, wheel to zoom, click to pick and select a mesh; H in the window (or view --help) lists every key"
    );
    splatscene::viewer::run(loaded.scene, options)?;
    Ok(())
}
