//! The typed error of the mesh loaders, and the naming of the file an error concerns.

use std::path::{Path, PathBuf};

/// Why a mesh file could not be loaded. Every variant names the file it concerns: a path on
/// disk, or `<embedded NAME>` for bytes handed to [`load_mesh_bytes`](super::load_mesh_bytes).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MeshError {
    /// The file (or a buffer or material file it refers to) could not be read.
    #[error("{}: cannot read: {source}", file.display())]
    Io {
        /// The file that could not be read.
        file: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// Neither the first bytes nor the extension say which mesh format this is.
    #[error("{}: unknown mesh format ({detail})", file.display())]
    UnknownFormat {
        /// The file.
        file: PathBuf,
        /// What was looked at.
        detail: String,
    },
    /// The file breaks its format: bad JSON, a bad GLB header or chunk, an unparsable OBJ line...
    #[error("{}: malformed {format}: {detail}", file.display())]
    Malformed {
        /// The file.
        file: PathBuf,
        /// The format it was read as (`"GLB"`, `"glTF"`, `"OBJ"`, `"STL"`, ...).
        format: &'static str,
        /// What is wrong, and where.
        detail: String,
    },
    /// Data that the file declares (an accessor, a buffer view, a buffer) runs past the end of
    /// the bytes that hold it.
    #[error("{}: {what} needs {needed} bytes but only {available} are there", file.display())]
    BufferTooShort {
        /// The file.
        file: PathBuf,
        /// Which piece of data.
        what: String,
        /// Bytes it needs.
        needed: u64,
        /// Bytes available.
        available: u64,
    },
    /// An index (a vertex index, a sparse index, an accessor number) points past the end of
    /// what it indexes.
    #[error("{}: {what}: index {index} is out of range (there are {len})", file.display())]
    IndexOutOfRange {
        /// The file.
        file: PathBuf,
        /// What holds the index.
        what: String,
        /// The offending index.
        index: u64,
        /// How many items there are.
        len: u64,
    },
    /// A coordinate or transform is NaN or infinite.
    #[error("{}: {what} holds NaN or infinite values", file.display())]
    NonFinite {
        /// The file.
        file: PathBuf,
        /// Which data.
        what: String,
    },
    /// A coordinate lies farther from the origin than [`super::MAX_COORDINATE`].
    #[error(
        "{}: {what} has a coordinate of {value:e}, beyond the {limit:e} that can be drawn and picked alike",
        file.display(),
        limit = super::MAX_COORDINATE
    )]
    FarCoordinate {
        /// The file.
        file: PathBuf,
        /// Which part.
        what: String,
        /// The coordinate.
        value: f32,
    },
    /// The file uses something this loader does not do (a buffer URI that is neither a data URI
    /// nor a relative file, a required glTF extension that changes geometry, GLB version 1...).
    #[error("{}: unsupported: {detail}", file.display())]
    Unsupported {
        /// The file.
        file: PathBuf,
        /// What is not supported.
        detail: String,
    },
    /// A size, declared or actual, is beyond what the file can hold or what the loader allows.
    #[error("{}: {what} is {size} bytes, more than the {limit} bytes possible", file.display())]
    TooLarge {
        /// The file.
        file: PathBuf,
        /// What is too large.
        what: String,
        /// Its size in bytes.
        size: u64,
        /// The limit it breaks, in bytes.
        limit: u64,
    },
    /// A glTF node is reached twice while walking the node hierarchy (a cycle, or a node with
    /// two parents).
    #[error("{}: node {node} is reached twice in the node hierarchy (a cycle?)", file.display())]
    NodeCycle {
        /// The file.
        file: PathBuf,
        /// The node reached twice.
        node: usize,
    },
    /// The glTF node hierarchy is deeper than the loader allows.
    #[error("{}: node {node} lies deeper than {limit} levels in the node hierarchy", file.display())]
    NodeTooDeep {
        /// The file.
        file: PathBuf,
        /// The node at which the limit was passed.
        node: usize,
        /// The depth limit.
        limit: usize,
    },
}

impl MeshError {
    /// The file the error concerns.
    pub fn file(&self) -> &Path {
        match self {
            Self::Io { file, .. }
            | Self::UnknownFormat { file, .. }
            | Self::Malformed { file, .. }
            | Self::BufferTooShort { file, .. }
            | Self::IndexOutOfRange { file, .. }
            | Self::NonFinite { file, .. }
            | Self::FarCoordinate { file, .. }
            | Self::Unsupported { file, .. }
            | Self::TooLarge { file, .. }
            | Self::NodeCycle { file, .. }
            | Self::NodeTooDeep { file, .. } => file,
        }
    }
}

/// Where the bytes being loaded came from: the name used in errors, and the directory that
/// relative references (glTF buffers, OBJ material libraries) resolve against, if any.
#[derive(Debug, Clone)]
pub(crate) struct Origin {
    /// The file path, or `<embedded NAME>`.
    pub(crate) label: PathBuf,
    /// The directory of the file; `None` for in-memory bytes.
    pub(crate) dir: Option<PathBuf>,
}

impl Origin {
    /// A file on disk.
    pub(crate) fn file(path: &Path) -> Self {
        Self {
            label: path.to_path_buf(),
            dir: Some(path.parent().map_or_else(PathBuf::new, Path::to_path_buf)),
        }
    }

    /// Bytes in memory, called `name`.
    pub(crate) fn embedded(name: &str) -> Self {
        Self {
            label: PathBuf::from(format!("<embedded {name}>")),
            dir: None,
        }
    }

    /// A short name for a part when the file gives none: the file stem, or `"mesh"`.
    pub(crate) fn stem(&self) -> String {
        let label = self.label.to_string_lossy();
        let inner = label.trim_start_matches("<embedded ").trim_end_matches('>');
        Path::new(inner)
            .file_stem()
            .map_or_else(|| "mesh".to_owned(), |s| s.to_string_lossy().into_owned())
    }

    pub(crate) fn malformed(&self, format: &'static str, detail: impl Into<String>) -> MeshError {
        MeshError::Malformed {
            file: self.label.clone(),
            format,
            detail: detail.into(),
        }
    }

    pub(crate) fn unsupported(&self, detail: impl Into<String>) -> MeshError {
        MeshError::Unsupported {
            file: self.label.clone(),
            detail: detail.into(),
        }
    }

    pub(crate) fn too_short(
        &self,
        what: impl Into<String>,
        needed: u64,
        available: u64,
    ) -> MeshError {
        MeshError::BufferTooShort {
            file: self.label.clone(),
            what: what.into(),
            needed,
            available,
        }
    }

    pub(crate) fn out_of_range(&self, what: impl Into<String>, index: u64, len: u64) -> MeshError {
        MeshError::IndexOutOfRange {
            file: self.label.clone(),
            what: what.into(),
            index,
            len,
        }
    }

    pub(crate) fn non_finite(&self, what: impl Into<String>) -> MeshError {
        MeshError::NonFinite {
            file: self.label.clone(),
            what: what.into(),
        }
    }

    pub(crate) fn too_large(&self, what: impl Into<String>, size: u64, limit: u64) -> MeshError {
        MeshError::TooLarge {
            file: self.label.clone(),
            what: what.into(),
            size,
            limit,
        }
    }
}
