//! The error every volume loader returns, and the DICOM series summaries it can carry.

use std::path::{Path, PathBuf};

use thiserror::Error;

use super::{ScalarType, triple};
use crate::grid::GridError;

/// Problems loading a volume; each names the file concerned.
#[derive(Debug, Error)]
pub enum VolumeError {
    /// A DICOM file or series could not be used (see `volume::dicom`).
    #[error("{}: {message}", path.display())]
    Dicom {
        /// The file or series folder.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A DICOM folder holds several series and none was chosen, or the chosen one is not
    /// there.
    #[error(
        "{}: {problem}; choose one with --series NUMBER or --series UID (series = \"...\" in a scene file):\n{}",
        path.display(),
        describe_series(series)
    )]
    DicomSeries {
        /// The folder.
        path: PathBuf,
        /// What is wrong: several series, or no series matches the choice.
        problem: String,
        /// The series found.
        series: Vec<SeriesSummary>,
    },
    /// The file could not be opened or read.
    #[error("{}: cannot read: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        source: std::io::Error,
    },
    /// The declared grid size is empty or has more voxels than `u32` ids address.
    #[error("{}: declared grid size refused: {source}", path.display())]
    Grid {
        /// The file.
        path: PathBuf,
        /// Why the size was refused.
        source: GridError,
    },
    /// The declared grid needs more memory than the budget (see [`crate::budget`]).
    #[error("{}: declared grid size refused: {source}", path.display())]
    OverBudget {
        /// The file.
        path: PathBuf,
        /// The size and the budget.
        source: crate::budget::SizeError,
    },
    /// The declared sizes do not fit in 64-bit byte counts.
    #[error("{}: {values} {scalar} values after {header_bytes} bytes overflow", path.display())]
    SizeOverflow {
        /// The file.
        path: PathBuf,
        /// Values the file should hold.
        values: u64,
        /// Their type.
        scalar: ScalarType,
        /// Bytes to skip before them.
        header_bytes: u64,
    },
    /// The file is shorter than the declared header and values need.
    #[error("{}: needs {expected} bytes for the declared size but has {actual}", path.display())]
    TooShort {
        /// The file.
        path: PathBuf,
        /// Header plus value bytes the spec declares.
        expected: u64,
        /// The file's length.
        actual: u64,
    },
    /// A data file a header names is shorter than the header declares.
    #[error(
        "{}: its data file {} needs {expected} bytes for the declared size but has {actual}",
        path.display(),
        data_file.display()
    )]
    DataFileTooShort {
        /// The header naming the data file.
        path: PathBuf,
        /// The data file.
        data_file: PathBuf,
        /// Bytes the header declares.
        expected: u64,
        /// The data file's length.
        actual: u64,
    },
    /// Spacing is not finite and positive, or the origin is not finite.
    #[error(
        "{}: voxel spacing {} mm must be finite and positive and origin {} mm finite",
        path.display(),
        triple(spacing),
        triple(origin)
    )]
    BadPlacement {
        /// The file.
        path: PathBuf,
        /// The declared spacing.
        spacing: [f64; 3],
        /// The declared origin.
        origin: [f64; 3],
    },
    /// A slice stack has a different number of files than the grid has z slices.
    #[error("{}: first of {files} slice files for {nz} z slices", path.display())]
    SliceCount {
        /// The first file of the stack.
        path: PathBuf,
        /// Files given.
        files: usize,
        /// Slices declared.
        nz: u32,
    },
    /// A slice stack was given no files at all, so there is no file to name.
    #[error("no slice files given for a {dims:?} grid")]
    NoSlices {
        /// The declared grid size.
        dims: [u32; 3],
    },
    /// A slice-stack file name does not end in `.<number>`.
    #[error("{}: a slice-stack file name must end in .<number>", path.display())]
    NotNumbered {
        /// The file.
        path: PathBuf,
    },
    /// A slice-stack number is missing while a later number exists.
    #[error("{}: slice missing from the stack, yet {} exists", path.display(), later.display())]
    MissingSlice {
        /// The missing file.
        path: PathBuf,
        /// The first file numbered after the gap.
        later: PathBuf,
    },
    /// A volume header is malformed: a field is missing, repeated, unknown or has a value that
    /// cannot be used (an unknown type or byte order, a size that is not a number).
    #[error("{}: bad header: {message}", path.display())]
    Header {
        /// The header file.
        path: PathBuf,
        /// What is wrong, naming the field.
        message: String,
    },
    /// The file uses a variant of its format that is not read (an encoding, a data layout).
    #[error("{}: unsupported: {feature}", path.display())]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// The variant, and what is read instead.
        feature: String,
    },
    /// No volume header was recognised: headerless data needs its layout stated.
    #[error(
        "{}: no volume header recognised (DICOM, NIfTI, Analyze, NRRD, MetaImage, VTK or .dat); a headerless raw \
         file or slice stack needs the raw options (size, scalar type, byte order, spacing)",
        path.display()
    )]
    NoHeader {
        /// The file.
        path: PathBuf,
    },
    /// A data file that a header names does not exist or is not a regular file.
    #[error("{}: data file {} {problem}", path.display(), data_file.display())]
    MissingDataFile {
        /// What is wrong with it: "does not exist", "is a named pipe (FIFO), not a regular
        /// file", ...
        problem: String,
        /// The header naming it.
        path: PathBuf,
        /// The missing data file.
        data_file: PathBuf,
    },
    /// Compressed data could not be decompressed.
    #[error("{}: corrupt compressed data: {source}", path.display())]
    Decompress {
        /// The file holding the compressed data.
        path: PathBuf,
        /// What the decompressor said.
        source: std::io::Error,
    },
    /// Compressed data inflate to more bytes than the header declares.
    #[error("{}: compressed data inflate past the declared {declared} bytes", path.display())]
    InflatesPast {
        /// The file holding the compressed data.
        path: PathBuf,
        /// Bytes the header declares.
        declared: u64,
    },
    /// Compressed data end before the bytes the header declares.
    #[error(
        "{}: compressed data end after {actual} of the declared {expected} bytes",
        path.display()
    )]
    InflatesShort {
        /// The file holding the compressed data.
        path: PathBuf,
        /// Bytes the header declares.
        expected: u64,
        /// Bytes the data inflated to.
        actual: u64,
    },
}

impl VolumeError {
    /// This error as the user's `header` sees it: a data file found short is named with the
    /// header that declared its size, since that is the file the user gave.
    pub fn named_by_header(self, header: &Path) -> Self {
        match self {
            Self::TooShort {
                path,
                expected,
                actual,
            } if path != header => Self::DataFileTooShort {
                path: header.into(),
                data_file: path,
                expected,
                actual,
            },
            other => other,
        }
    }
}

/// One DICOM series of a folder, as `volume::dicom::list_series` finds it.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SeriesSummary {
    /// The folder holding it.
    pub folder: PathBuf,
    /// SeriesInstanceUID (empty when the files have none).
    pub uid: String,
    /// SeriesNumber.
    pub number: Option<String>,
    /// SeriesDescription.
    pub description: Option<String>,
    /// Modality (CT, MR...).
    pub modality: Option<String>,
    /// Columns and rows of its first usable slice.
    pub size: Option<[u16; 2]>,
    /// Image files in it.
    pub images: usize,
}

/// The series as lines for a message: number, description, modality, size and image count.
pub fn describe_series(series: &[SeriesSummary]) -> String {
    series
        .iter()
        .map(|s| {
            let size = s.size.map_or("?".into(), |[c, r]| format!("{c}x{r}"));
            format!(
                "  series {} {:?} {} {size}, {} images, UID {}",
                s.number.as_deref().unwrap_or("-"),
                s.description.as_deref().unwrap_or(""),
                s.modality.as_deref().unwrap_or("?"),
                s.images,
                s.uid
            )
        })
        .collect::<Vec<_>>()
        .join("\n")
}
