//! The prosthesis overlaid on a real chest CT: renders `examples/scenes/overlay-lidc2.toml`
//! (the LIDC2 scan's right shoulder with the prosthesis at its humeral head) to a PNG.
//!
//! ```sh
//! cargo run --release --example overlay -- [OUT.png]   # default overlay.png
//! ```
//!
//! The CT comes from the shared test data, which is not in the repository: set
//! `SPLATSCENE_DATA` to the folder that holds `volumes/lidc2/`, or run from the repository root
//! of a checkout that has it at `../shared/data`.

mod common;

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use splatscene::scene::file::{DATA_ENV, SceneFileError, load_scene_file};

fn main() -> Result<()> {
    let out = std::env::args_os()
        .nth(1)
        .map_or_else(|| PathBuf::from("overlay.png"), PathBuf::from);
    // Found from the crate, so that the example runs from any working directory.
    let scene_path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenes/overlay-lidc2.toml");

    let loaded = match load_scene_file(&scene_path) {
        Ok(loaded) => loaded,
        Err(e @ SceneFileError::DataNotFound { .. }) => bail!(
            "{e}\n\nThis example needs the LIDC2 chest CT from the shared test data \
             (volumes/lidc2/lidc2_256x256x133_uint8.raw). Set {DATA_ENV} to the folder that \
             holds volumes/, for example\n    {DATA_ENV}=/path/to/shared/data cargo run --release --example overlay"
        ),
        Err(e) => return Err(e.into()),
    };
    let shot = common::render_loaded(&loaded, (512, 512))?;
    let camera = shot.view.camera;
    let size = shot.view.size;
    common::write_color_png(&shot, &out)?;
    println!(
        "{} ({}x{}, eye {:?}, target {:?}): {}",
        out.display(),
        size.0,
        size.1,
        camera.eye.to_array(),
        camera.target.to_array(),
        common::describe(&shot.report)
    );
    Ok(())
}
