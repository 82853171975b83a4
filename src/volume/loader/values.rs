//! Stored value types and their decoding, and the checks every loader makes of what a header
//! declares: grid sizes against the memory budget, data files, placement numbers.

use std::fmt;
use std::path::Path;
use std::str::FromStr;

use thiserror::Error;

use super::VolumeError;
use crate::grid::voxel_count;
use crate::volume::Voxels;

/// Three numbers as people write them: `(0.5, 0.5, inf)`.
pub(crate) fn triple(v: &[f64; 3]) -> String {
    format!("({}, {}, {})", v[0], v[1], v[2])
}

/// What keeps the data file at `path` from being read, in words, or `None` for a regular
/// file: a header may name a device or a pipe, which is refused before it is opened.
fn data_file_problem(path: &Path) -> Option<String> {
    match std::fs::metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Some("does not exist".into()),
        Err(e) => Some(format!("cannot be read: {e}")),
        Ok(meta) if !meta.is_file() => Some(format!(
            "is {}, not a regular file",
            crate::input::kind(&meta)
        )),
        Ok(_) => None,
    }
}

/// Refuses the first of the data `files` a header at `path` names that does not exist, is not
/// a regular file, or is the header itself (by any name or link), saying which and what it is.
pub(crate) fn check_data_files(
    path: &Path,
    files: &[std::path::PathBuf],
) -> Result<(), VolumeError> {
    let header = std::fs::metadata(path)
        .ok()
        .map(|m| crate::input::FileId::of(&m));
    for file in files {
        let itself = header.is_some()
            && std::fs::metadata(file)
                .ok()
                .map(|m| crate::input::FileId::of(&m))
                == header;
        if itself {
            return Err(VolumeError::MissingDataFile {
                path: path.into(),
                data_file: file.clone(),
                problem: "is the header itself, whose text is not voxel data (data that follow the header in its own file need no data file field)".into(),
            });
        }
        if let Some(problem) = data_file_problem(file) {
            return Err(VolumeError::MissingDataFile {
                path: path.into(),
                data_file: file.clone(),
                problem,
            });
        }
    }
    Ok(())
}

/// The voxel count of a grid of `dims` of `scalar` values that the file at `path` declares,
/// checked against the grid limit and against the memory that drawing it takes (each value as
/// [`Voxels`] hold it and [`crate::budget::DRAW_BYTES_PER_VOXEL`] more), before anything is
/// allocated.
pub(crate) fn checked_voxels(
    path: &Path,
    dims: [u32; 3],
    scalar: ScalarType,
) -> Result<u64, VolumeError> {
    let count = voxel_count(dims).map_err(|source| VolumeError::Grid {
        path: path.into(),
        source,
    })?;
    let what = format!("a {}x{}x{} grid", dims[0], dims[1], dims[2]);
    let each = Voxels::held_bytes(scalar) as u64 + crate::budget::DRAW_BYTES_PER_VOXEL;
    crate::budget::check_memory(what, count, each).map_err(|source| VolumeError::OverBudget {
        path: path.into(),
        source,
    })?;
    Ok(count)
}

/// The type of one stored value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ScalarType {
    /// Unsigned 8-bit integer.
    U8,
    /// Signed 8-bit integer.
    I8,
    /// Unsigned 16-bit integer.
    U16,
    /// Signed 16-bit integer.
    I16,
    /// Unsigned 32-bit integer.
    U32,
    /// Signed 32-bit integer.
    I32,
    /// 32-bit IEEE float.
    F32,
    /// 64-bit IEEE float.
    F64,
}

/// Byte order of multi-byte values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum ByteOrder {
    /// Least significant byte first (x86, most files written today).
    #[default]
    Little,
    /// Most significant byte first (older Unix workstations, e.g. the Stanford CT head).
    Big,
}

/// A value type with its byte order, parsed from names like `u8`, `u16be`, `int16_le`, `f32`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ScalarFormat {
    /// The value type.
    pub scalar: ScalarType,
    /// The byte order; little-endian when the name gives none.
    pub order: ByteOrder,
}

/// A scalar-type name that is not understood.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("unknown scalar type {0:?}; expected e.g. u8, i16, uint16, f32 (plus le/be for a format)")]
pub struct ParseScalarError(pub String);

impl ScalarType {
    /// Bytes per value.
    pub fn size(self) -> usize {
        match self {
            Self::U8 | Self::I8 => 1,
            Self::U16 | Self::I16 => 2,
            Self::U32 | Self::I32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    fn from_base_name(name: &str) -> Option<Self> {
        Some(match name {
            "u8" | "uint8" | "uchar" => Self::U8,
            "i8" | "int8" | "schar" => Self::I8,
            "u16" | "uint16" | "ushort" => Self::U16,
            "i16" | "int16" | "short" => Self::I16,
            "u32" | "uint32" | "uint" => Self::U32,
            "i32" | "int32" | "int" => Self::I32,
            "f32" | "float32" | "float" => Self::F32,
            "f64" | "float64" | "double" => Self::F64,
            _ => return None,
        })
    }
}

impl fmt::Display for ScalarType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let name = match self {
            Self::U8 => "u8",
            Self::I8 => "i8",
            Self::U16 => "u16",
            Self::I16 => "i16",
            Self::U32 => "u32",
            Self::I32 => "i32",
            Self::F32 => "f32",
            Self::F64 => "f64",
        };
        f.write_str(name)
    }
}

/// Accepts a bare type name (`u16`, `uint16`, `float`); a byte-order suffix is refused here so
/// that it is never silently dropped: parse a [`ScalarFormat`] for that.
impl FromStr for ScalarType {
    type Err = ParseScalarError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::from_base_name(&s.trim().to_ascii_lowercase())
            .ok_or_else(|| ParseScalarError(s.into()))
    }
}

/// The name [`ScalarFormat`]'s `FromStr` reads back: the type alone when little-endian (the
/// default), else with `be`.
impl fmt::Display for ScalarFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.order {
            ByteOrder::Little => write!(f, "{}", self.scalar),
            ByteOrder::Big => write!(f, "{}be", self.scalar),
        }
    }
}

impl FromStr for ScalarFormat {
    type Err = ParseScalarError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let name = s.trim().to_ascii_lowercase();
        // The whole name first: "double" ends in "le" without being little-endian.
        if let Some(scalar) = ScalarType::from_base_name(&name) {
            return Ok(Self {
                scalar,
                order: ByteOrder::Little,
            });
        }
        let (base, order) = match name.len().checked_sub(2).map(|i| name.split_at(i)) {
            Some((base, "le")) => (base, ByteOrder::Little),
            Some((base, "be")) => (base, ByteOrder::Big),
            _ => return Err(ParseScalarError(s.into())),
        };
        let base = base.trim_end_matches(['_', '-']);
        ScalarType::from_base_name(base)
            .map(|scalar| Self { scalar, order })
            .ok_or_else(|| ParseScalarError(s.into()))
    }
}

/// Appends the values in `bytes` (whole values only; a trailing partial value is ignored).
/// Shared with the header formats' loaders, which read compressed or embedded data.
pub(crate) fn decode(bytes: &[u8], scalar: ScalarType, order: ByteOrder, out: &mut Voxels) {
    let big = order == ByteOrder::Big;
    match (scalar, out) {
        (ScalarType::U8, Voxels::U8(out)) => out.extend_from_slice(bytes),
        (ScalarType::I8, Voxels::I8(out)) => out.extend(bytes.iter().map(|&b| b as i8)),
        (ScalarType::U16, Voxels::U16(out)) => extend(bytes, big, out, u16::from_le_bytes),
        (ScalarType::I16, Voxels::I16(out)) => extend(bytes, big, out, i16::from_le_bytes),
        (_, out) => {
            let out = out.make_f32();
            match scalar {
                ScalarType::U8 => out.extend(bytes.iter().map(|&b| f32::from(b))),
                ScalarType::I8 => out.extend(bytes.iter().map(|&b| f32::from(b as i8))),
                ScalarType::U16 => extend(bytes, big, out, |w| f32::from(u16::from_le_bytes(w))),
                ScalarType::I16 => extend(bytes, big, out, |w| f32::from(i16::from_le_bytes(w))),
                ScalarType::U32 => extend(bytes, big, out, |w| u32::from_le_bytes(w) as f32),
                ScalarType::I32 => extend(bytes, big, out, |w| i32::from_le_bytes(w) as f32),
                ScalarType::F32 => extend(bytes, big, out, f32::from_le_bytes),
                ScalarType::F64 => extend(bytes, big, out, |w| f64::from_le_bytes(w) as f32),
            }
        }
    }
}

/// Converts each `N`-byte word, reversed first when big-endian, so that every type needs only
/// its little-endian conversion.
fn extend<const N: usize, T>(
    bytes: &[u8],
    big: bool,
    out: &mut Vec<T>,
    convert: impl Fn([u8; N]) -> T,
) {
    let (words, _) = bytes.as_chunks::<N>();
    out.extend(words.iter().map(|&w| {
        let mut w = w;
        if big {
            w.reverse();
        }
        convert(w)
    }));
}
