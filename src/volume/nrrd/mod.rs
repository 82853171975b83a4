//! NRRD volumes (teem's "nearly raw raster data"), with the header attached (`.nrrd`) or
//! detached (`.nhdr`).
//!
//! Read: 3-D arrays of 8- to 32-bit integers, `float` and `double`; encodings `raw`,
//! `gzip` and `bzip2`; `endian`; `byte skip` (including `-1`, data at the end of a raw file) and
//! `line skip`; `data file` as a single name, a `LIST` of names on the following lines, or a
//! printf-style pattern (`quarter.%d 1 93 1`, `slice%03d.raw 0 9 1`), each file holding an
//! equal run of whole z slices; placement from `space directions` and `space origin`, or from
//! `spacings` when there are no space directions.
//!
//! **World frame.** This project's world is RAS (+x toward the patient's right, +y anterior,
//! +z head). A `space` of `left-posterior-superior` (LPS, as ITK and DICOM write) is converted
//! by negating the x and y components of the space directions and the space origin, and
//! `left-anterior-superior` by negating x. Non-anatomical spaces (`scanner-xyz`,
//! `3D-right-handed`, `3D-left-handed`) and a bare `space dimension: 3` are taken as they are.
//!
//! `ascii` (`text`, `txt`) data are white-space-separated numbers (no `endian` needed). Without
//! a `space`, `axis mins` place the first sample as teem and ITK do: at the minimum for
//! `node`-centred axes, half a step past it for `cell`-centred ones (teem's default).
//!
//! A 4-D header whose one non-spatial axis has a single sample (`kinds: vector space space
//! space` with `sizes: 1 ...`, or a `list` of one last; its space direction `none`) is the 3-D
//! volume it holds, as SimpleITK and pynrrd read it.
//!
//! Not read (a typed [`VolumeError::Unsupported`]): other dimensions (vectors of several
//! components, time series, images), 64-bit integers and `block`, the `hex` encoding, `none`
//! axes among the spatial `space directions`, spaces with a time axis, and data files that do
//! not each hold whole z slices.
//!
//! Every declared size is checked before voxel memory is allocated: raw data against the data
//! files' lengths (through [`load_raw`] and [`load_raw_slices`]), gzip data by inflating at
//! most the declared bytes, with output memory growing only as the data actually inflate.

use std::io::{BufRead, BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use bzip2::read::MultiBzDecoder;
use flate2::read::MultiGzDecoder;
use glam::DVec3;

use super::loader::{
    HeaderLines, LoadedVolume, Placement, VolumeFormat, expect_end, format_pattern, header_error,
    inflate_values, io_error, skip_inflated, text_values, unsupported,
};
use super::loader::{check_data_files, checked_voxels};
use super::{
    ByteOrder, CpuVolume, RawSpec, ScalarFormat, ScalarType, VolumeError, Voxels, load_raw,
    load_raw_slices,
};

/// Loads an NRRD volume from its attached (`.nrrd`) or detached (`.nhdr`) header.
pub fn load_nrrd(path: &Path) -> Result<LoadedVolume, VolumeError> {
    let header = Header::read(path)?;
    let placement = Placement::from_columns(path, header.columns, header.origin)?;
    let volume = match header.encoding {
        Encoding::Raw => read_raw(path, &header)?,
        Encoding::Gzip | Encoding::Bzip2 => read_compressed(path, &header)?,
        Encoding::Ascii => read_ascii(path, &header)?,
    };
    Ok(LoadedVolume {
        volume: placement.apply(volume),
        format: VolumeFormat::Nrrd,
        scalar_type: Some(header.format.scalar),
        patient_frame: header.anatomical,
    })
}

/// How the data are stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Encoding {
    Raw,
    Gzip,
    Bzip2,
    /// Numbers written as text, separated by white space.
    Ascii,
}

/// Where the data are: after the header in the same file, or in other files.
#[derive(Debug, Clone, PartialEq)]
enum Data {
    /// In the header's own file, from this byte on.
    Attached(u64),
    /// In these files, each holding an equal run of z slices.
    Files(Vec<PathBuf>),
}

/// What the header says, checked and interpreted.
#[derive(Debug, Clone, PartialEq)]
struct Header {
    dims: [u32; 3],
    format: ScalarFormat,
    encoding: Encoding,
    /// Bytes before the data in each data file (after decompression for gzip); `None` for
    /// `-1`: the data end the file.
    byte_skip: Option<u64>,
    line_skip: u64,
    data: Data,
    /// The step between neighbouring voxels along each axis, in RAS.
    columns: [DVec3; 3],
    /// Whether `space` names an anatomical frame (RAS, LAS, LPS).
    anatomical: bool,
    /// The position of the first voxel, in RAS.
    origin: DVec3,
}

/// One `field: description` line of the header.
#[derive(Debug, Clone)]
struct Field {
    /// The field name, lower case and without spaces (`data file` and `datafile` alike).
    key: String,
    /// The field name as written, for messages.
    name: String,
    value: String,
    line: usize,
}

/// The fields of a header, with the names a `data file: LIST` gives after it.
struct Fields {
    path: PathBuf,
    fields: Vec<Field>,
    list: Vec<String>,
}

impl Fields {
    /// Reads the header lines up to the blank line that ends them (or the end of a detached
    /// header); returns the fields and the offset of the data that may follow.
    fn read(path: &Path) -> Result<(Self, u64), VolumeError> {
        let mut lines = HeaderLines::open(path)?;
        match lines.next_line()? {
            Some(magic) if is_magic(&magic) => {}
            _ => return Err(header_error(path, "no NRRD000x magic on the first line")),
        }
        let mut fields = Self {
            path: path.into(),
            fields: Vec::new(),
            list: Vec::new(),
        };
        let mut listing = false;
        while let Some(line) = lines.next_line()? {
            if line.trim().is_empty() {
                break;
            }
            if listing {
                fields.list.push(line.trim().to_owned());
            } else if !line.starts_with('#') {
                fields.add(&line, lines.number())?;
                listing = fields.fields.last().is_some_and(|f| {
                    f.key == "datafile" && f.value.split_whitespace().next() == Some("LIST")
                });
            }
        }
        Ok((fields, lines.offset()))
    }

    /// Adds a `field: value` line; `key:=value` pairs carry no geometry and are skipped.
    fn add(&mut self, line: &str, number: usize) -> Result<(), VolumeError> {
        let field_end = line.find(": ");
        if let Some(pair) = line.find(":=")
            && field_end.is_none_or(|f| pair < f)
        {
            return Ok(());
        }
        let Some(at) = field_end.or_else(|| line.strip_suffix(':').map(str::len)) else {
            return Err(self.error(number, format!("{line:?} is not `field: value`")));
        };
        let key: String = line[..at]
            .chars()
            .filter(|c| *c != ' ')
            .collect::<String>()
            .to_ascii_lowercase();
        if self.fields.iter().any(|f| f.key == key) {
            return Err(self.error(number, format!("field {:?} given twice", &line[..at])));
        }
        self.fields.push(Field {
            key,
            name: line[..at].trim().to_owned(),
            value: line.get(at + 2..).unwrap_or_default().trim().to_owned(),
            line: number,
        });
        Ok(())
    }

    fn error(&self, line: usize, message: impl std::fmt::Display) -> VolumeError {
        header_error(&self.path, format!("line {line}: {message}"))
    }

    /// Makes a 4-D header whose one non-spatial axis has a single sample (a scalar volume
    /// written as a 1-vector, `kinds: vector space space space`, or a list of one, `list`
    /// last, as ITK, Slicer and pynrrd write them) the 3-D header of the same data: an axis of
    /// size 1 does not change where any sample lies, so only the per-axis fields lose its
    /// entry. The axis must be non-spatial: its `kinds` entry not `space` or `domain`, or its
    /// `space directions` entry `none`. Any other 4-D array is refused.
    fn drop_single_axis(&mut self) -> Result<(), VolumeError> {
        let field = self.require("sizes", "sizes")?;
        let sizes: [u64; 4] = self.numbers(field).map_err(|_| {
            self.error(
                field.line,
                format!(
                    "a 4-D NRRD (dimension 4) needs 4 sizes, not {:?}",
                    field.value
                ),
            )
        })?;
        let kinds: Vec<String> = self.get("kinds").map_or(Vec::new(), |f| {
            f.value
                .split_whitespace()
                .map(str::to_ascii_lowercase)
                .collect()
        });
        let directions = match self.get("spacedirections") {
            Some(f) => vectors(self, f)?,
            None => Vec::new(),
        };
        let spatial_kind = |k: &str| matches!(k, "space" | "domain");
        let non_spatial = |axis: usize| {
            kinds.get(axis).is_some_and(|k| !spatial_kind(k))
                || directions.get(axis).is_some_and(Option::is_none)
        };
        let single: Vec<usize> = (0..4)
            .filter(|&a| sizes[a] == 1 && non_spatial(a))
            .collect();
        let [axis] = single[..] else {
            let described = (0..4)
                .map(|a| match kinds.get(a) {
                    Some(k) => format!("{} ({k})", sizes[a]),
                    None => sizes[a].to_string(),
                })
                .collect::<Vec<_>>()
                .join(", ");
            return Err(unsupported(
                &self.path,
                format!(
                    "a 4-D NRRD of sizes {described}; read are 3-D volumes and 4-D ones whose one non-spatial axis (a kind other than space or domain, or a `none` space direction) has a single sample"
                ),
            ));
        };
        for field in &mut self.fields {
            match field.key.as_str() {
                "spacedirections" => {
                    let words: Vec<String> = directions
                        .iter()
                        .enumerate()
                        .filter(|(a, _)| *a != axis)
                        .map(|(_, d)| match d {
                            Some(v) => format!("({},{},{})", v.x, v.y, v.z),
                            None => "none".into(),
                        })
                        .collect();
                    field.value = words.join(" ");
                }
                "sizes" | "spacings" | "thicknesses" | "axismins" | "axismaxs" | "centers"
                | "centerings" | "kinds" => {
                    let words: Vec<&str> = field.value.split_whitespace().collect();
                    if words.len() == 4 {
                        field.value = words
                            .iter()
                            .enumerate()
                            .filter(|(a, _)| *a != axis)
                            .map(|(_, w)| *w)
                            .collect::<Vec<_>>()
                            .join(" ");
                    }
                }
                _ => {}
            }
        }
        Ok(())
    }

    fn get(&self, key: &str) -> Option<&Field> {
        self.fields.iter().find(|f| f.key == key)
    }

    fn require(&self, key: &str, name: &str) -> Result<&Field, VolumeError> {
        self.get(key)
            .ok_or_else(|| header_error(&self.path, format!("no `{name}` field")))
    }

    /// Parses a field's whitespace-separated numbers, which must number `N`.
    fn numbers<T: std::str::FromStr, const N: usize>(
        &self,
        field: &Field,
    ) -> Result<[T; N], VolumeError> {
        let parsed: Option<Vec<T>> = field
            .value
            .split_whitespace()
            .map(|w| w.parse().ok())
            .collect();
        parsed.and_then(|v| v.try_into().ok()).ok_or_else(|| {
            self.error(
                field.line,
                format!(
                    "{}: expected {N} numbers, got {:?}",
                    field.name, field.value
                ),
            )
        })
    }
}

fn is_magic(line: &str) -> bool {
    line.strip_prefix("NRRD000")
        .is_some_and(|v| matches!(v.trim_end(), "1" | "2" | "3" | "4" | "5"))
}

impl Header {
    fn read(path: &Path) -> Result<Self, VolumeError> {
        let (mut fields, offset) = Fields::read(path)?;
        let dimension = fields.require("dimension", "dimension")?;
        let [n]: [u32; 1] = fields.numbers(dimension)?;
        if n == 4 {
            fields.drop_single_axis()?;
        } else if n != 3 {
            return Err(unsupported(
                path,
                format!("{n}-D NRRD; only 3-D volumes are read"),
            ));
        }
        let dims = fields.numbers(fields.require("sizes", "sizes")?)?;
        let encoding = encoding(&fields)?;
        let format = scalar_format(&fields, encoding)?;
        let (byte_skip, line_skip) = skips(&fields, encoding)?;
        // The grid's size and memory first: a file list or pattern is never built for a grid
        // that would be refused.
        let held = match encoding {
            Encoding::Ascii => ScalarType::F32,
            _ => format.scalar,
        };
        checked_voxels(&fields.path, dims, held)?;
        let data = match fields.get("datafile") {
            None => Data::Attached(offset),
            Some(field) => Data::Files(data_files(&fields, field, dims[2])?),
        };
        let (columns, origin) = placement(&fields)?;
        let anatomical = fields.get("space").is_some_and(|f| {
            matches!(
                f.value.to_ascii_lowercase().as_str(),
                "right-anterior-superior"
                    | "ras"
                    | "left-anterior-superior"
                    | "las"
                    | "left-posterior-superior"
                    | "lps"
            )
        });
        Ok(Self {
            anatomical,
            dims,
            format,
            encoding,
            byte_skip,
            line_skip,
            data,
            columns,
            origin,
        })
    }

    /// The files holding the data, each with the offset its data (or stream) start at.
    fn sources(&self, path: &Path) -> Result<Vec<(PathBuf, u64)>, VolumeError> {
        let files = match &self.data {
            Data::Attached(offset) => {
                return Ok(vec![(path.into(), self.after_lines(path, *offset)?)]);
            }
            Data::Files(files) => files,
        };
        check_data_files(path, files)?;
        files
            .iter()
            .map(|f| Ok((f.clone(), self.after_lines(f, 0)?)))
            .collect()
    }

    /// The offset `line_skip` lines after `start` in `file`; scanning stops at the file's
    /// length so that a device file cannot keep it reading.
    fn after_lines(&self, file: &Path, start: u64) -> Result<u64, VolumeError> {
        if self.line_skip == 0 {
            return Ok(start);
        }
        let mut f = crate::input::open_regular(file).map_err(io_error(file))?;
        let len = f.metadata().map_err(io_error(file))?.len();
        f.seek(SeekFrom::Start(start)).map_err(io_error(file))?;
        let mut reader = BufReader::new(f.take(len.saturating_sub(start)));
        let mut offset = start;
        for skipped in 0..self.line_skip {
            // Skipping, not reading, so that one long "line" costs no memory.
            let n = reader.skip_until(b'\n').map_err(io_error(file))?;
            if n == 0 {
                let message = format!("line skip {} but only {skipped} lines", self.line_skip);
                return Err(header_error(file, message));
            }
            offset += n as u64;
        }
        Ok(offset)
    }
}

/// NRRD's type names, and what each reads as; `None` for types not read.
const TYPE_NAMES: [(&[&str], Option<ScalarType>); 9] = [
    (&["signed char", "int8", "int8_t"], Some(ScalarType::I8)),
    (
        &["uchar", "unsigned char", "uint8", "uint8_t"],
        Some(ScalarType::U8),
    ),
    (
        &[
            "short",
            "short int",
            "signed short",
            "signed short int",
            "int16",
            "int16_t",
        ],
        Some(ScalarType::I16),
    ),
    (
        &[
            "ushort",
            "unsigned short",
            "unsigned short int",
            "uint16",
            "uint16_t",
        ],
        Some(ScalarType::U16),
    ),
    (
        &["int", "signed int", "int32", "int32_t"],
        Some(ScalarType::I32),
    ),
    (
        &["uint", "unsigned int", "uint32", "uint32_t"],
        Some(ScalarType::U32),
    ),
    (&["float"], Some(ScalarType::F32)),
    (&["double"], Some(ScalarType::F64)),
    (
        &[
            "longlong",
            "long long",
            "long long int",
            "signed long long",
            "signed long long int",
            "int64",
            "int64_t",
            "ulonglong",
            "unsigned long long",
            "unsigned long long int",
            "uint64",
            "uint64_t",
            "block",
        ],
        None,
    ),
];

/// The value type and byte order; `endian` is needed only for multi-byte types in binary
/// encodings (text has no byte order) but checked whenever given.
fn scalar_format(fields: &Fields, encoding: Encoding) -> Result<ScalarFormat, VolumeError> {
    let field = fields.require("type", "type")?;
    let name = field.value.split_whitespace().collect::<Vec<_>>().join(" ");
    let lower = name.to_ascii_lowercase();
    let scalar = match TYPE_NAMES
        .iter()
        .find(|(names, _)| names.contains(&lower.as_str()))
    {
        Some((_, Some(scalar))) => *scalar,
        Some((_, None)) => return Err(unsupported(&fields.path, format!("type {name}"))),
        None => return Err(fields.error(field.line, format!("unknown type {name:?}"))),
    };
    let order = match fields.get("endian") {
        Some(f) if f.value.eq_ignore_ascii_case("little") => ByteOrder::Little,
        Some(f) if f.value.eq_ignore_ascii_case("big") => ByteOrder::Big,
        Some(f) => {
            let message = format!("endian {:?} is neither little nor big", f.value);
            return Err(fields.error(f.line, message));
        }
        None if scalar.size() == 1 || encoding == Encoding::Ascii => ByteOrder::Little,
        None => {
            let message = format!("no `endian` field for {name}");
            return Err(header_error(&fields.path, message));
        }
    };
    Ok(ScalarFormat { scalar, order })
}

fn encoding(fields: &Fields) -> Result<Encoding, VolumeError> {
    let field = fields.require("encoding", "encoding")?;
    match field.value.to_ascii_lowercase().as_str() {
        "raw" => Ok(Encoding::Raw),
        "gzip" | "gz" => Ok(Encoding::Gzip),
        "txt" | "text" | "ascii" => Ok(Encoding::Ascii),
        "bzip2" | "bz2" => Ok(Encoding::Bzip2),
        "hex" => Err(unsupported(
            &fields.path,
            format!(
                "encoding {}; only raw, gzip, bzip2 and ascii are read",
                field.value
            ),
        )),
        other => Err(fields.error(field.line, format!("unknown encoding {other:?}"))),
    }
}

/// `byte skip` (`None` for -1) and `line skip`.
fn skips(fields: &Fields, encoding: Encoding) -> Result<(Option<u64>, u64), VolumeError> {
    let byte_skip = match fields.get("byteskip") {
        None => Some(0),
        Some(f) if f.value == "-1" && encoding == Encoding::Raw => None,
        Some(f) => match f.value.parse::<u64>() {
            Ok(n) => Some(n),
            Err(_) => {
                let message = format!("byte skip {:?} is not a count (or -1 for raw)", f.value);
                return Err(fields.error(f.line, message));
            }
        },
    };
    let line_skip = match fields.get("lineskip") {
        None => 0,
        Some(f) => {
            let [n]: [u64; 1] = fields.numbers(f)?;
            n
        }
    };
    Ok((byte_skip, line_skip))
}

/// The data files a `data file` field names, relative to the header's folder; there must be a
/// whole number of z slices per file.
fn data_files(fields: &Fields, field: &Field, nz: u32) -> Result<Vec<PathBuf>, VolumeError> {
    let words: Vec<&str> = field.value.split_whitespace().collect();
    let names = match words.as_slice() {
        ["LIST", ..] => fields.list.clone(),
        [pattern, min, max, step, ..] if pattern.contains('%') => {
            let range = [min, max, step].map(|w| w.parse::<i64>().ok());
            let [Some(min), Some(max), Some(step)] = range else {
                return Err(fields.error(field.line, "pattern range is not three integers"));
            };
            expand_pattern(fields, field, pattern, (min, max, step), nz)?
        }
        _ => vec![field.value.clone()],
    };
    if names.is_empty() || names.iter().any(String::is_empty) {
        return Err(fields.error(field.line, "empty data file name"));
    }
    if names.len() > nz as usize || !nz.is_multiple_of(names.len() as u32) {
        let message = format!(
            "{} data files do not split {nz} z slices evenly",
            names.len()
        );
        return Err(fields.error(field.line, message));
    }
    let dir = fields.path.parent().unwrap_or(Path::new(""));
    Ok(names.iter().map(|n| dir.join(n)).collect())
}

/// The names of a `<format> <min> <max> <step>` file list; more files than z slices is an
/// error found before any name is made.
fn expand_pattern(
    fields: &Fields,
    field: &Field,
    pattern: &str,
    (min, max, step): (i64, i64, i64),
    nz: u32,
) -> Result<Vec<String>, VolumeError> {
    let count = max
        .checked_sub(min)
        .and_then(|span| span.checked_div(step))
        .filter(|&n| n >= 0)
        .and_then(|n| n.checked_add(1));
    let count = match count {
        Some(n) if n <= i64::from(nz) => n,
        _ => {
            let message = format!(
                "pattern range {min}..={max} step {step} is empty, backwards or longer than \
                 the {nz} slices"
            );
            return Err(fields.error(field.line, message));
        }
    };
    (0..count)
        .map(|i| {
            format_pattern(pattern, min + i * step).ok_or_else(|| {
                fields.error(field.line, format!("pattern {pattern:?} needs one %d"))
            })
        })
        .collect()
}

/// The voxel steps and the origin in RAS, from `space directions` (else `spacings`, else unit
/// steps) and `space origin`.
fn placement(fields: &Fields) -> Result<([DVec3; 3], DVec3), VolumeError> {
    let flip = space_flip(fields)?;
    let columns = match (fields.get("spacedirections"), fields.get("spacings")) {
        (Some(f), _) => {
            let vectors = vectors(fields, f)?;
            match <[Option<DVec3>; 3]>::try_from(vectors) {
                Ok([Some(x), Some(y), Some(z)]) => [x, y, z],
                Ok(_) => {
                    return Err(unsupported(
                        &fields.path,
                        "a `none` axis in space directions",
                    ));
                }
                Err(_) => return Err(fields.error(f.line, "expected 3 space directions")),
            }
        }
        (None, Some(f)) => {
            // `nan` marks an unknown spacing: a unit step keeps the volume usable.
            let s: [f64; 3] = fields.numbers(f)?;
            let s = s.map(|v| if v.is_nan() { 1.0 } else { v });
            if s.iter().any(|v| !v.is_finite() || *v == 0.0) {
                return Err(fields.error(
                    f.line,
                    format!(
                        "spacings ({}, {}, {}) must be finite and non-zero",
                        s[0], s[1], s[2]
                    ),
                ));
            }
            [DVec3::X * s[0], DVec3::Y * s[1], DVec3::Z * s[2]]
        }
        (None, None) => [DVec3::X, DVec3::Y, DVec3::Z],
    };
    let origin = match fields.get("spaceorigin") {
        Some(f) => match vectors(fields, f)?.as_slice() {
            [Some(o)] => *o,
            _ => return Err(fields.error(f.line, "expected one origin vector")),
        },
        // Without a space, `axis mins` place the grid as teem (and so ITK) does: the first
        // sample at the minimum, half a step further for cell-centred axes (the default).
        None if fields.get("space").is_none() && fields.get("spacedimension").is_none() => {
            axis_mins_origin(fields, &columns)?
        }
        None => DVec3::ZERO,
    };
    Ok((columns.map(|c| c * flip), origin * flip))
}

/// The first sample's position from `axis mins` (and `centers`), for headers without a space;
/// the origin when there are no mins.
fn axis_mins_origin(fields: &Fields, columns: &[DVec3; 3]) -> Result<DVec3, VolumeError> {
    let Some(f) = fields.get("axismins") else {
        return Ok(DVec3::ZERO);
    };
    let mins: [f64; 3] = fields.numbers(f)?;
    let centers: [String; 3] = match fields.get("centers").or_else(|| fields.get("centerings")) {
        Some(c) => {
            let words: Vec<String> = c
                .value
                .split_whitespace()
                .map(str::to_ascii_lowercase)
                .collect();
            words
                .try_into()
                .map_err(|_| fields.error(c.line, "expected 3 centers"))?
        }
        None => std::array::from_fn(|_| "cell".to_owned()),
    };
    let mut origin = DVec3::ZERO;
    for axis in 0..3 {
        if !mins[axis].is_finite() {
            // `nan`: no minimum on this axis; teem then places none of them.
            return Ok(DVec3::ZERO);
        }
        let half_step = match centers[axis].as_str() {
            "cell" | "???" | "none" => 0.5 * columns[axis][axis],
            "node" => 0.0,
            other => {
                let line = fields.get("centers").map_or(0, |c| c.line);
                return Err(fields.error(line, format!("unknown center {other:?} (cell or node)")));
            }
        };
        origin[axis] = mins[axis] + half_step;
    }
    Ok(origin)
}

/// The sign flips that take the header's `space` into RAS.
fn space_flip(fields: &Fields) -> Result<DVec3, VolumeError> {
    let ras = DVec3::ONE;
    let Some(field) = fields.get("space") else {
        return match fields.get("spacedimension") {
            Some(f) if f.value.trim() != "3" => Err(unsupported(
                &fields.path,
                format!("space dimension {}", f.value),
            )),
            _ => Ok(ras),
        };
    };
    match field.value.to_ascii_lowercase().as_str() {
        "right-anterior-superior" | "ras" => Ok(ras),
        "left-anterior-superior" | "las" => Ok(DVec3::new(-1.0, 1.0, 1.0)),
        "left-posterior-superior" | "lps" => Ok(DVec3::new(-1.0, -1.0, 1.0)),
        "scanner-xyz" | "3d-right-handed" | "3d-left-handed" => Ok(ras),
        "right-anterior-superior-time"
        | "rast"
        | "left-anterior-superior-time"
        | "last"
        | "left-posterior-superior-time"
        | "lpst"
        | "scanner-xyz-time"
        | "3d-right-handed-time"
        | "3d-left-handed-time" => Err(unsupported(&fields.path, format!("space {}", field.value))),
        _ => Err(fields.error(field.line, format!("unknown space {:?}", field.value))),
    }
}

/// The `(x,y,z)` vectors of a field, `None` for each `none`; every vector must have 3 finite
/// components (a non-finite one is refused later, by the placement).
fn vectors(fields: &Fields, field: &Field) -> Result<Vec<Option<DVec3>>, VolumeError> {
    let bad = || {
        fields.error(
            field.line,
            format!(
                "{}: {:?} is not a list of (x,y,z) vectors",
                field.name, field.value
            ),
        )
    };
    let mut out = Vec::new();
    let mut rest = field.value.trim();
    while !rest.is_empty() {
        if let Some(after) = rest.strip_prefix("none") {
            out.push(None);
            rest = after.trim_start();
            continue;
        }
        let inner = rest.strip_prefix('(').ok_or_else(bad)?;
        let (inside, after) = inner.split_once(')').ok_or_else(bad)?;
        let parts: Option<Vec<f64>> = inside.split(',').map(|p| p.trim().parse().ok()).collect();
        let v: [f64; 3] = parts.and_then(|p| p.try_into().ok()).ok_or_else(bad)?;
        out.push(Some(DVec3::from(v)));
        rest = after.trim_start();
    }
    Ok(out)
}

/// Bytes of values in each data file.
fn bytes_per_file(path: &Path, header: &Header, files: usize) -> Result<(usize, u64), VolumeError> {
    let held = match header.encoding {
        Encoding::Ascii => ScalarType::F32,
        _ => header.format.scalar,
    };
    let count = checked_voxels(path, header.dims, held)?;
    let per_file = count / files as u64;
    let bytes = per_file
        .checked_mul(header.format.scalar.size() as u64)
        .ok_or_else(|| header_error(path, "declared size overflows"))?;
    let count =
        usize::try_from(count).map_err(|_| header_error(path, "declared size overflows"))?;
    Ok((count, bytes))
}

/// Raw data: every file's length is checked against the declared size by the raw loaders
/// before the volume is allocated.
fn read_raw(path: &Path, header: &Header) -> Result<CpuVolume, VolumeError> {
    let sources = header.sources(path)?;
    let (_, bytes) = bytes_per_file(path, header, sources.len())?;
    let spec = RawSpec {
        header_bytes: common_start(path, header, &sources, bytes)?,
        ..RawSpec::new(header.dims, header.format.scalar, header.format.order)
    };
    let mut volume = match sources.as_slice() {
        [(file, _)] => load_raw(file, &spec)?,
        _ => {
            let files: Vec<PathBuf> = sources.into_iter().map(|(f, _)| f).collect();
            load_raw_slices(&files, &slab_spec(path, spec, files.len())?)?
        }
    };
    volume.dims = header.dims;
    Ok(volume)
}

/// The offset of the data in every file, which must be the same for all of them.
fn common_start(
    path: &Path,
    header: &Header,
    sources: &[(PathBuf, u64)],
    bytes: u64,
) -> Result<u64, VolumeError> {
    let mut starts = Vec::with_capacity(sources.len());
    for (file, start) in sources {
        starts.push(match header.byte_skip {
            Some(skip) => start
                .checked_add(skip)
                .ok_or_else(|| header_error(path, "byte skip overflows"))?,
            None => data_at_end(file, bytes)?,
        });
    }
    match starts.split_first() {
        Some((first, rest)) if rest.iter().all(|s| s == first) => Ok(*first),
        _ => Err(unsupported(
            path,
            "data files whose data start at different offsets",
        )),
    }
}

/// The raw slice loader wants one z slice per file: a file holding a run of z slices is
/// loaded as one taller slice, which is the same bytes in the same order.
fn slab_spec(path: &Path, spec: RawSpec, files: usize) -> Result<RawSpec, VolumeError> {
    let [nx, ny, nz] = spec.dims;
    let files = u32::try_from(files).map_err(|_| header_error(path, "too many data files"))?;
    let tall = ny
        .checked_mul(nz / files)
        .ok_or_else(|| header_error(path, "a data file holds too many slices"))?;
    Ok(RawSpec {
        dims: [nx, tall, files],
        ..spec
    })
}

/// Where `bytes` bytes of data start when they end the file (`byte skip: -1`).
fn data_at_end(file: &Path, bytes: u64) -> Result<u64, VolumeError> {
    let len = std::fs::metadata(file).map_err(io_error(file))?.len();
    len.checked_sub(bytes).ok_or(VolumeError::TooShort {
        path: file.into(),
        expected: bytes,
        actual: len,
    })
}

/// Gzip data: each file's stream must inflate to exactly its share of the declared size.
/// Reads gzip- or bzip2-compressed data, inflating at most the declared bytes of each file.
fn read_compressed(path: &Path, header: &Header) -> Result<CpuVolume, VolumeError> {
    let sources = header.sources(path)?;
    let (count, bytes) = bytes_per_file(path, header, sources.len())?;
    let skip = header.byte_skip.unwrap_or(0);
    let mut values = Voxels::new(header.format.scalar);
    for (file, start) in &sources {
        let mut f = crate::input::open_regular(file).map_err(io_error(file))?;
        f.seek(SeekFrom::Start(*start)).map_err(io_error(file))?;
        let mut reader: Box<dyn Read> = match header.encoding {
            Encoding::Bzip2 => Box::new(MultiBzDecoder::new(BufReader::new(f))),
            _ => Box::new(MultiGzDecoder::new(BufReader::new(f))),
        };
        skip_inflated(file, &mut reader, skip, bytes)?;
        inflate_values(file, &mut reader, bytes, header.format, count, &mut values)?;
        expect_end(file, &mut reader, skip.saturating_add(bytes))?;
    }
    Ok(CpuVolume {
        dims: header.dims,
        spacing: [1.0; 3],
        origin: [0.0; 3],
        direction: glam::DMat3::IDENTITY,
        values,
    })
}

/// Text data: the declared number of values, as white-space-separated numbers, after the
/// skipped lines (and bytes) of each data file.
fn read_ascii(path: &Path, header: &Header) -> Result<CpuVolume, VolumeError> {
    let sources = header.sources(path)?;
    let (total, _) = bytes_per_file(path, header, sources.len())?;
    let count = total / sources.len().max(1);
    let mut values = Voxels::F32(Vec::with_capacity(total.min(1 << 24)));
    for (file, start) in &sources {
        let mut f = crate::input::open_regular(file).map_err(io_error(file))?;
        let len = f.metadata().map_err(io_error(file))?.len();
        f.seek(SeekFrom::Start(
            start.saturating_add(header.byte_skip.unwrap_or(0)),
        ))
        .map_err(io_error(file))?;
        // Nothing longer than the file is read (a device file cannot keep it reading).
        let mut text = String::new();
        f.take(len)
            .read_to_string(&mut text)
            .map_err(|e| header_error(file, format!("the text data are not UTF-8 text: {e}")))?;
        text_values(file, &text, count, &mut values)?;
    }
    Ok(CpuVolume {
        dims: header.dims,
        spacing: [1.0; 3],
        origin: [0.0; 3],
        direction: glam::DMat3::IDENTITY,
        values,
    })
}

#[cfg(test)]
mod tests;
