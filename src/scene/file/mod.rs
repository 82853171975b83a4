//! Scene files: a TOML description of volumes, meshes, camera, lights and output, read with
//! serde. Every table refuses fields it does not know, so a misspelt key is an error naming the
//! file and the key rather than a setting silently left at its default.
//!
//! Paths of volumes and meshes are read as follows:
//! - `builtin:shoulder-phantom` (volumes) and `builtin:prosthesis` (meshes) name the built-in
//!   phantom and prosthesis;
//! - `data:REST` names `REST` inside the shared test data folder: `$SPLATSCENE_DATA/REST`, or
//!   `../shared/data/REST` relative to the current directory when `SPLATSCENE_DATA` is unset or
//!   empty. `REST` must be a relative path that stays inside that folder (no `..`), so that a
//!   scene file written against the data works on every machine that has the data, wherever it
//!   lies;
//! - any other relative path is taken from the scene file's folder; absolute paths are used as
//!   they are.
//!
//! ```toml
//! [output]
//! size = [800, 600]
//! ordering = "ip-pbtf"
//!
//! [camera]
//! view_from = [-0.55, 1.0, -0.35]   # fit the scene, looking along this direction
//!
//! [[volume]]
//! path = "builtin:shoulder-phantom"
//! transfer = "ct-bone"
//! resect_humeral_head = true
//!
//! [[volume]]
//! path = "data:volumes/engine/engine_256x256x128_uint8.raw"
//! dims = [256, 256, 128]
//! scalar = "u8"
//! transfer = "ramp"
//! window = [90, 200]
//!
//! [[mesh]]
//! path = "builtin:prosthesis"
//! seat = "phantom"
//! ```
//!
//! `examples/scenes/` holds complete scene files.

mod camera;
mod edit;
mod load;
mod save;
mod schema;
#[cfg(test)]
mod tests;
mod validate;

pub use camera::{CameraSpecError, camera, named_view_camera, upright};
pub use edit::EditError;
pub use load::{
    DataPathError, Given, apply_transfer, load_scene_file, read_volume, resolve_path,
    scale_warnings,
};
pub use save::{PlanError, transform_spec};
pub use schema::*;
pub use validate::extra_elements;

use std::ffi::OsStr;
use std::path::{Path, PathBuf};

use glam::DVec3;
use thiserror::Error;

use super::Scene;
use crate::mesh::MeshError;
use crate::volume::VolumeError;

/// Why a scene file could not be used.
#[derive(Debug, Error)]
pub enum SceneFileError {
    /// The file could not be read.
    #[error("{}: cannot read: {source}", path.display())]
    Io {
        /// The scene file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The TOML is malformed or has unknown or mistyped fields.
    #[error("{}: {message}", path.display())]
    Parse {
        /// The scene file.
        path: PathBuf,
        /// What the parser said, with the line.
        message: String,
    },
    /// A value is out of range or a combination makes no sense.
    #[error("{}: {message}", path.display())]
    Invalid {
        /// The scene file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A mesh did not load.
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// A volume did not load.
    #[error(transparent)]
    Volume(#[from] VolumeError),
    /// A `data:` path names a file that is not in the shared data folder, most likely because
    /// `SPLATSCENE_DATA` is not set to where the data lie.
    #[error(
        "{}: {} not found: `data:` paths are read from ${DATA_ENV} ({}); set {DATA_ENV} to the shared data folder",
        path.display(),
        file.display(),
        describe_data_dir(data_var.as_deref())
    )]
    DataNotFound {
        /// The scene file.
        path: PathBuf,
        /// The file the `data:` path resolved to.
        file: PathBuf,
        /// The value of `SPLATSCENE_DATA` when the path was resolved (`None` when unset).
        data_var: Option<std::ffi::OsString>,
    },
}

/// The environment variable naming the shared data folder that `data:` paths point into.
pub const DATA_ENV: &str = "SPLATSCENE_DATA";

/// The shared data folder when [`DATA_ENV`] is unset or empty, relative to the current
/// directory (where it lies next to a checkout of the repository run from its root).
pub const DEFAULT_DATA_DIR: &str = "../shared/data";

/// The shared data folder: `$SPLATSCENE_DATA`, or [`DEFAULT_DATA_DIR`] when that is unset or
/// empty.
pub fn data_dir() -> PathBuf {
    data_dir_from(std::env::var_os(DATA_ENV).as_deref())
}

pub(super) fn data_dir_from(var: Option<&OsStr>) -> PathBuf {
    match var {
        // An empty value is far more likely a blank export than a wish for the current
        // directory, so it counts as unset.
        Some(v) if !v.is_empty() => PathBuf::from(v),
        _ => PathBuf::from(DEFAULT_DATA_DIR),
    }
}

pub(super) fn describe_data_dir(var: Option<&OsStr>) -> String {
    match var {
        Some(v) if !v.is_empty() => format!("now {}", Path::new(v).display()),
        _ => format!("unset, so {DEFAULT_DATA_DIR} relative to the current directory"),
    }
}

/// The data folder as read once per scene load, with the variable's value for error messages.
pub(super) struct DataRoot {
    pub(super) dir: PathBuf,
    pub(super) var: Option<std::ffi::OsString>,
}

impl DataRoot {
    pub(super) fn from_env() -> Self {
        let var = std::env::var_os(DATA_ENV);
        Self {
            dir: data_dir_from(var.as_deref()),
            var,
        }
    }
}

/// How many nodes are named `name` apart from a parent of that name (the parts of a mesh
/// file may take its name): more than one, and a name does not say which node it means.
pub(super) fn named_apart(scene: &Scene, name: &str) -> usize {
    let nodes = scene.nodes();
    nodes
        .iter()
        .filter(|node| node.name == name && node.parent().is_none_or(|p| nodes[p.0].name != name))
        .count()
}

/// A world point for a message: `[x, y, z]` to 0.1 mm.
pub(super) fn mm(p: DVec3) -> String {
    format!("[{:.1}, {:.1}, {:.1}]", p.x, p.y, p.z)
}

/// At most the first 60 characters of a text a user wrote, for an error message: a label or
/// name of a megabyte is not repeated whole.
pub fn shortened(text: &str) -> String {
    const SHOWN: usize = 60;
    match text.char_indices().nth(SHOWN) {
        Some((end, _)) => format!("{}... ({} characters)", &text[..end], text.chars().count()),
        None => text.to_owned(),
    }
}
