//! What the volume loaders share: the loaded volume and its format, error makers naming the
//! file, placement from axis vectors, bounded reading of compressed data, and text header lines
//! read ahead of binary data. Every format module imports this one; none imports another
//! format or the dispatcher in [`super::detect`], which only tells formats apart and calls them.

use std::fs::File;
use std::io::{self, BufRead, BufReader, Read, Take};
use std::path::{Path, PathBuf};

use glam::{DMat3, DVec3};
use serde_json::{Value, json};

use super::{CpuVolume, Voxels};

mod error;
mod values;

pub use error::{SeriesSummary, VolumeError, describe_series};
pub use values::{ByteOrder, ParseScalarError, ScalarFormat, ScalarType};
pub(crate) use values::{check_data_files, checked_voxels, decode, triple};

/// The volume file formats [`super::detect::load_volume`] recognises.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum VolumeFormat {
    /// A DICOM series (a folder of slice files).
    Dicom,
    /// NRRD with an attached or detached header.
    Nrrd,
    /// Legacy VTK `STRUCTURED_POINTS`.
    VtkLegacy,
    /// VTK XML `ImageData` (`.vti`).
    VtkXml,
    /// NIfTI-1 or NIfTI-2, plain, gzip-compressed or as a `.hdr`/`.img` pair.
    Nifti,
    /// Analyze 7.5 (`.hdr`/`.img`).
    Analyze,
    /// A Voreen-style `.dat` text header next to a raw file.
    Dat,
    /// MetaImage (`.mha`, or `.mhd` with a data file), ITK's format.
    MetaImage,
}

impl VolumeFormat {
    /// The short name used in [`super::detect::volume_info`]: `dicom`, `nrrd`, `vtk`, `vti`, `nifti`,
    /// `analyze`, `dat` or `metaimage`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Dicom => "dicom",
            Self::Nrrd => "nrrd",
            Self::VtkLegacy => "vtk",
            Self::VtkXml => "vti",
            Self::Nifti => "nifti",
            Self::Analyze => "analyze",
            Self::Dat => "dat",
            Self::MetaImage => "metaimage",
        }
    }
}

/// A loaded volume with what its file said about it.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedVolume {
    /// The voxels, converted to `f32` (and rescaled where the format says so), placed in the
    /// project's RAS world.
    pub volume: CpuVolume,
    /// The file's format.
    pub format: VolumeFormat,
    /// The value type stored in the file; `None` for DICOM, whose loader does not report it.
    pub scalar_type: Option<ScalarType>,
    /// Whether the file states its patient frame (NIfTI, DICOM, MetaImage, Analyze, NRRD with
    /// an anatomical `space`); the others take [`LoadOptions::coordinate_frame`].
    pub patient_frame: bool,
}

impl LoadedVolume {
    /// The volume read in `frame` where its file states no patient frame: LPS turns to RAS
    /// (x and y change sign, for positions and axis directions alike). A file that states its
    /// own frame refuses the choice.
    pub fn in_frame(
        mut self,
        path: &Path,
        frame: Option<CoordinateFrame>,
    ) -> Result<Self, VolumeError> {
        match frame {
            Some(_) if self.patient_frame => Err(unsupported(
                path,
                format!(
                    "a coordinate frame for a {} file, which states its own patient frame",
                    self.format.name()
                ),
            )),
            Some(CoordinateFrame::Lps) => {
                let flip = DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0));
                let v = &mut self.volume;
                v.origin = (flip * DVec3::from(v.origin)).to_array();
                v.direction = flip * v.direction;
                Ok(self)
            }
            Some(CoordinateFrame::Ras) | None => Ok(self),
        }
    }

    /// The description [`super::detect::volume_info`] gives, with `file` as the file name shown.
    pub fn info(&self, file: &Path) -> Value {
        describe(
            &self.volume,
            Some(file),
            Some(self.format.name()),
            self.scalar_type.map(scalar_type_name),
        )
    }
}

/// A volume described as [`LoadedVolume::info`] describes one, for a volume that may come from
/// no file: `file`, `format` and `scalar_type` are `null` where `None`.
pub fn describe(
    v: &CpuVolume,
    file: Option<&Path>,
    format: Option<&str>,
    scalar_type: Option<&str>,
) -> Value {
    let d = v.direction;
    let rows: Vec<[f64; 3]> = (0..3).map(|r| d.row(r).to_array()).collect();
    let (min, max, mean) = match value_range(&v.values) {
        Some((min, max, mean)) => (json!(min), json!(max), json!(mean)),
        None => (Value::Null, Value::Null, Value::Null),
    };
    json!({
        "file": file.map(|f| f.display().to_string()),
        "format": format,
        "size": v.dims,
        "spacing": v.spacing,
        "origin": v.origin,
        "direction": rows,
        "scalar_type": scalar_type,
        "min": min,
        "max": max,
        "mean": mean,
    })
}

/// The name [`super::detect::volume_info`] gives a stored value type: `uint8`, `int8`, `uint16`, `int16`,
/// `uint32`, `int32`, `float32` or `float64`.
pub fn scalar_type_name(scalar: ScalarType) -> &'static str {
    match scalar {
        ScalarType::U8 => "uint8",
        ScalarType::I8 => "int8",
        ScalarType::U16 => "uint16",
        ScalarType::I16 => "int16",
        ScalarType::U32 => "uint32",
        ScalarType::I32 => "int32",
        ScalarType::F32 => "float32",
        ScalarType::F64 => "float64",
    }
}

/// Minimum, maximum and mean of the finite values, or `None` when there are none. The mean
/// is summed in `f64` so that large volumes do not lose precision.
fn value_range(values: &Voxels) -> Option<(f64, f64, f64)> {
    let runs = values.par_chunks(1 << 16, |run| {
        let (mut min, mut max, mut sum, mut n) = (f64::INFINITY, f64::NEG_INFINITY, 0.0, 0u64);
        for &v in run.iter().filter(|v| v.is_finite()) {
            let v = f64::from(v);
            min = min.min(v);
            max = max.max(v);
            sum += v;
            n += 1;
        }
        (min, max, sum, n)
    });
    let (min, max, sum, n) = runs
        .into_iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY, 0.0, 0u64), |a, b| {
            (a.0.min(b.0), a.1.max(b.1), a.2 + b.2, a.3 + b.3)
        });
    (n > 0).then(|| (min, max, sum / n as f64))
}

/// Which DICOM series of a folder to load: `NUMBER` (SeriesNumber) or a SeriesInstanceUID.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SeriesChoice(pub String);

/// The patient frame of a file whose format has none (VTK, `.dat`, NRRD without an anatomical
/// `space`): its coordinates are taken in this frame and turned into the project's RAS world.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CoordinateFrame {
    /// +x toward the patient's right, +y anterior, +z head: the project's own world and the
    /// default.
    #[default]
    Ras,
    /// +x toward the patient's left, +y posterior, +z head: what ITK, DICOM and 3D Slicer's
    /// exports write.
    Lps,
}

impl std::str::FromStr for CoordinateFrame {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_uppercase().as_str() {
            "RAS" => Ok(Self::Ras),
            "LPS" => Ok(Self::Lps),
            _ => Err(format!("coordinate frame {s:?} is neither RAS nor LPS")),
        }
    }
}

impl std::fmt::Display for CoordinateFrame {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Ras => "RAS",
            Self::Lps => "LPS",
        })
    }
}

/// Which of a NIfTI file's two transforms places the grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum NiftiTransform {
    /// The sform when its code is set, else the qform, else `pixdim` alone: nibabel's choice
    /// and the default.
    #[default]
    Sform,
    /// The qform when its code is set, else the sform, else `pixdim` alone.
    Qform,
    /// ITK's rule (SimpleITK 2.5, 3D Slicer): the sform when its code is 1 (scanner
    /// anatomical) or there is no qform, else the qform.
    Itk,
}

impl std::str::FromStr for NiftiTransform {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "sform" => Ok(Self::Sform),
            "qform" => Ok(Self::Qform),
            "itk" => Ok(Self::Itk),
            _ => Err(format!(
                "NIfTI transform {s:?} is none of sform, qform, itk"
            )),
        }
    }
}

impl std::fmt::Display for NiftiTransform {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Sform => "sform",
            Self::Qform => "qform",
            Self::Itk => "itk",
        })
    }
}

/// What a caller may choose about how a volume file is read; the defaults read any file.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LoadOptions {
    /// DICOM: the series of a folder holding several (a file given alone picks its own).
    pub series: Option<SeriesChoice>,
    /// 4-D NIfTI: the 3-D frame, from 0 (the first by default, said on stderr).
    pub frame: Option<u32>,
    /// The frame of a file whose format states none; refused for one that states its own.
    pub coordinate_frame: Option<CoordinateFrame>,
    /// NIfTI: which transform places the grid; refused for other formats.
    pub nifti_transform: Option<NiftiTransform>,
    /// DICOM: load the series without its files that cannot be read (said on stderr) instead
    /// of refusing it; refused for other formats.
    pub skip_unreadable: bool,
}

impl LoadOptions {
    /// Refuses an option that cannot apply to a file of `format` at `path`, naming it.
    pub fn check_applies(&self, path: &Path, format: VolumeFormat) -> Result<(), VolumeError> {
        let refuse = |option: &str, applies: &str| {
            Err(unsupported(
                path,
                format!(
                    "{option} for a {} file; it applies to {applies}",
                    format.name()
                ),
            ))
        };
        if self.frame.is_some() && format != VolumeFormat::Nifti {
            return refuse("a frame", "4-D NIfTI");
        }
        if self.nifti_transform.is_some() && format != VolumeFormat::Nifti {
            return refuse("a NIfTI transform choice", "NIfTI");
        }
        if self.series.is_some() && format != VolumeFormat::Dicom {
            return refuse("a series", "DICOM");
        }
        if self.skip_unreadable && format != VolumeFormat::Dicom {
            return refuse("skipping unreadable files", "DICOM series");
        }
        if self.series.is_some() && !path.is_dir() {
            return Err(unsupported(
                path,
                "a series choice for one DICOM file, which loads its own series; give the folder to choose among its series",
            ));
        }
        Ok(())
    }
}

/// The two bytes every gzip stream starts with.
pub(super) const GZIP_MAGIC: [u8; 2] = [0x1f, 0x8b];

/// An [`VolumeError::Io`] maker naming `path`.
pub(super) fn io_error(path: &Path) -> impl FnOnce(io::Error) -> VolumeError + '_ {
    move |source| VolumeError::Io {
        path: path.into(),
        source,
    }
}

/// A [`VolumeError::Header`] naming `path`.
pub(super) fn header_error(path: &Path, message: impl Into<String>) -> VolumeError {
    VolumeError::Header {
        path: path.into(),
        message: message.into(),
    }
}

/// A [`VolumeError::Unsupported`] naming `path`.
pub(super) fn unsupported(path: &Path, feature: impl Into<String>) -> VolumeError {
    VolumeError::Unsupported {
        path: path.into(),
        feature: feature.into(),
    }
}

/// Up to `max` bytes from the start of the file.
pub(super) fn read_head(path: &Path, max: u64) -> Result<Vec<u8>, VolumeError> {
    let mut head = Vec::new();
    crate::input::open_regular(path)
        .and_then(|f| f.take(max).read_to_end(&mut head))
        .map_err(io_error(path))?;
    Ok(head)
}

/// Where a grid sits in the world: spacing, unit axis directions and origin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Placement {
    pub spacing: [f64; 3],
    pub direction: DMat3,
    pub origin: [f64; 3],
}

impl Placement {
    /// The placement whose axis `i` steps by `columns[i]` from voxel to voxel, starting at
    /// `origin`: the spacing is each column's length and the direction its unit vector, so a
    /// negative spacing in a header becomes a flipped axis. Zero or non-finite steps and a
    /// non-finite origin are [`VolumeError::BadPlacement`]; axes that do not span 3-D space
    /// (a singular grid) are a header error.
    pub fn from_columns(
        path: &Path,
        columns: [DVec3; 3],
        origin: DVec3,
    ) -> Result<Self, VolumeError> {
        let spacing = columns.map(DVec3::length);
        let bad = || VolumeError::BadPlacement {
            path: path.into(),
            spacing,
            origin: origin.to_array(),
        };
        if !origin.is_finite() || spacing.iter().any(|s| !s.is_finite() || *s <= 0.0) {
            return Err(bad());
        }
        let [x, y, z] = columns.map(DVec3::normalize);
        let direction = DMat3::from_cols(x, y, z);
        // Unit columns: |det| is the volume of their parallelepiped, 1 when orthogonal.
        if direction.determinant().abs() < 1e-6 {
            return Err(header_error(
                path,
                format!(
                    "axis directions {}, {} and {} do not span 3-D space",
                    triple(&columns[0].to_array()),
                    triple(&columns[1].to_array()),
                    triple(&columns[2].to_array())
                ),
            ));
        }
        Ok(Self {
            spacing,
            direction,
            origin: origin.to_array(),
        })
    }

    /// The axis-aligned placement with the given spacing and origin.
    pub fn axis_aligned(
        path: &Path,
        spacing: [f64; 3],
        origin: [f64; 3],
    ) -> Result<Self, VolumeError> {
        // Checked before the columns are made: an infinite step times a zero is NaN, and the
        // message should show the spacing given.
        if !DVec3::from(origin).is_finite() || spacing.iter().any(|s| !s.is_finite() || *s <= 0.0) {
            return Err(VolumeError::BadPlacement {
                path: path.into(),
                spacing,
                origin,
            });
        }
        let [sx, sy, sz] = spacing;
        let columns = [DVec3::X * sx, DVec3::Y * sy, DVec3::Z * sz];
        Self::from_columns(path, columns, DVec3::from(origin))
    }

    /// `volume` placed here (its values and size are kept).
    pub fn apply(self, volume: CpuVolume) -> CpuVolume {
        CpuVolume {
            spacing: self.spacing,
            direction: self.direction,
            origin: self.origin,
            ..volume
        }
    }
}

/// Reads exactly `bytes` bytes of `format` values from the decompressing `reader` into `out`,
/// which ends up holding at most `total` values. The output grows with the data actually
/// inflated (never past `total`), so a small stream that declares a huge volume costs only
/// what it really inflates to: the declared size is believed only as far as the data bear it
/// out. A stream that ends early is [`VolumeError::InflatesShort`]; a corrupt one is
/// [`VolumeError::Decompress`]. `path` names the file holding the stream.
pub(super) fn inflate_values(
    path: &Path,
    reader: &mut dyn Read,
    bytes: u64,
    format: ScalarFormat,
    total: usize,
    out: &mut Voxels,
) -> Result<(), VolumeError> {
    // A multiple of every value size, so that chunks never split a value.
    const CHUNK: usize = 1 << 16;
    let size = format.scalar.size();
    let mut buffer = vec![0u8; CHUNK];
    let mut done = 0u64;
    while done < bytes {
        let want = (bytes - done).min(CHUNK as u64) as usize;
        let got =
            read_full(reader, &mut buffer[..want]).map_err(|source| VolumeError::Decompress {
                path: path.into(),
                source,
            })?;
        if got < want {
            return Err(VolumeError::InflatesShort {
                path: path.into(),
                expected: bytes,
                actual: done + got as u64,
            });
        }
        out.reserve_capped(want / size, total);
        decode(&buffer[..want], format.scalar, format.order, out);
        done += want as u64;
    }
    Ok(())
}

/// Checks that `reader` has nothing left after the `declared` bytes read from it. Reading on
/// also makes the decompressor check the stream's trailer (gzip's CRC and length).
pub(super) fn expect_end(
    path: &Path,
    reader: &mut dyn Read,
    declared: u64,
) -> Result<(), VolumeError> {
    let mut byte = [0u8; 1];
    match read_full(reader, &mut byte) {
        Ok(0) => Ok(()),
        Ok(_) => Err(VolumeError::InflatesPast {
            path: path.into(),
            declared,
        }),
        Err(source) => Err(VolumeError::Decompress {
            path: path.into(),
            source,
        }),
    }
}

/// Skips `bytes` bytes of a decompressing reader without keeping them; a stream that ends
/// first is [`VolumeError::InflatesShort`] against the `bytes + declared` it should hold.
pub(super) fn skip_inflated(
    path: &Path,
    reader: &mut dyn Read,
    bytes: u64,
    declared: u64,
) -> Result<(), VolumeError> {
    let skipped = io::copy(&mut reader.take(bytes), &mut io::sink()).map_err(|source| {
        VolumeError::Decompress {
            path: path.into(),
            source,
        }
    })?;
    if skipped < bytes {
        return Err(VolumeError::InflatesShort {
            path: path.into(),
            expected: bytes.saturating_add(declared),
            actual: skipped,
        });
    }
    Ok(())
}

/// Appends the `count` numbers of `text` (separated by white space) to `out`; a word that is
/// not a number, or a count other than `count`, is a header error naming `path`. Words past
/// `count + 1` are not parsed.
pub(super) fn text_values(
    path: &Path,
    text: &str,
    count: usize,
    out: &mut Voxels,
) -> Result<(), VolumeError> {
    let before = out.len();
    let out_f32 = out.make_f32();
    for word in text.split_whitespace().take(count.saturating_add(1)) {
        let value: f64 = word.parse().map_err(|_| {
            header_error(path, format!("{word:?} in the text data is not a number"))
        })?;
        out_f32.push(value as f32);
    }
    let got = out.len() - before;
    if got != count {
        let got = if got > count {
            format!("more than {count}")
        } else {
            got.to_string()
        };
        let message = format!("the text data hold {got} values where {count} are declared");
        return Err(header_error(path, message));
    }
    Ok(())
}

/// `pattern` with its one integer conversion (`%d`, `%i`, `%u`, optionally `%0Nd` or `%Nd`)
/// replaced by `n`; `%%` is a percent sign. `None` for any other conversion or count of them.
pub(super) fn format_pattern(pattern: &str, n: i64) -> Option<String> {
    let mut out = String::new();
    let mut used = false;
    let mut rest = pattern;
    while let Some(at) = rest.find('%') {
        out.push_str(&rest[..at]);
        let spec = &rest[at + 1..];
        if let Some(after) = spec.strip_prefix('%') {
            out.push('%');
            rest = after;
            continue;
        }
        let digits = spec.bytes().take_while(u8::is_ascii_digit).count();
        let (flags, after) = spec.split_at(digits);
        let after = after.strip_prefix(['d', 'i', 'u'])?;
        if used {
            return None;
        }
        let width: usize = if flags.is_empty() {
            0
        } else {
            flags.parse().ok()?
        };
        // A width past any file name's would only build a huge string.
        if width > 32 {
            return None;
        }
        match flags.starts_with('0') {
            true => out.push_str(&format!("{n:0width$}")),
            false => out.push_str(&format!("{n:width$}")),
        }
        used = true;
        rest = after;
    }
    out.push_str(rest);
    used.then_some(out)
}

/// Fills as much of `buffer` as the reader can give; fewer bytes only at the end of the data.
fn read_full(reader: &mut dyn Read, buffer: &mut [u8]) -> io::Result<usize> {
    let mut filled = 0;
    while filled < buffer.len() {
        match reader.read(&mut buffer[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(filled)
}

/// Longest text header read before binary data (NRRD, legacy VTK); generous for a NRRD
/// `LIST` of thousands of slice files, small next to any volume.
pub(super) const HEADER_CAP: u64 = 4 << 20;

/// The text lines at the start of a file whose binary data follow a text header, read without
/// ever holding more than [`HEADER_CAP`] bytes of it, keeping count of the bytes consumed so
/// that the data's offset is known.
pub(super) struct HeaderLines {
    path: PathBuf,
    reader: BufReader<Take<File>>,
    offset: u64,
    number: usize,
}

impl HeaderLines {
    /// Starts reading `path` at its first line.
    pub fn open(path: &Path) -> Result<Self, VolumeError> {
        let file = crate::input::open_regular(path).map_err(io_error(path))?;
        Ok(Self {
            path: path.into(),
            reader: BufReader::new(file.take(HEADER_CAP)),
            offset: 0,
            number: 0,
        })
    }

    /// The next line without its line ending, or `None` at the end of the file. A line that
    /// is not UTF-8 text or runs past [`HEADER_CAP`] is a header error.
    pub fn next_line(&mut self) -> Result<Option<String>, VolumeError> {
        let mut line = Vec::new();
        let n = self
            .reader
            .read_until(b'\n', &mut line)
            .map_err(io_error(&self.path))?;
        if n == 0 {
            return Ok(None);
        }
        self.offset += n as u64;
        self.number += 1;
        if line.last() != Some(&b'\n') && self.offset == HEADER_CAP {
            let message = format!("no end of header within its first {HEADER_CAP} bytes");
            return Err(header_error(&self.path, message));
        }
        let text = String::from_utf8(line)
            .map_err(|_| header_error(&self.path, format!("line {} is not text", self.number)))?;
        Ok(Some(text.trim_end_matches(['\n', '\r']).to_owned()))
    }

    /// Bytes consumed so far: where the data start once the header's last line is read.
    pub fn offset(&self) -> u64 {
        self.offset
    }

    /// The number of the line last read, counting from 1.
    pub fn number(&self) -> usize {
        self.number
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use flate2::read::MultiGzDecoder;

    #[test]
    fn a_series_choice_or_a_skip_applies_to_a_dicom_folder_only() {
        let series = LoadOptions {
            series: Some(SeriesChoice("2".into())),
            ..LoadOptions::default()
        };
        let file = Path::new("slice.dcm");
        let e = series
            .check_applies(file, VolumeFormat::Dicom)
            .unwrap_err()
            .to_string();
        assert!(e.contains("one DICOM file") && e.contains("folder"), "{e}");
        let dir = scratch("series-choice");
        assert!(series.check_applies(&dir, VolumeFormat::Dicom).is_ok());
        let skip = LoadOptions {
            skip_unreadable: true,
            ..LoadOptions::default()
        };
        assert!(skip.check_applies(&dir, VolumeFormat::Dicom).is_ok());
        let e = skip
            .check_applies(Path::new("v.nrrd"), VolumeFormat::Nrrd)
            .unwrap_err()
            .to_string();
        assert!(e.contains("skipping unreadable files"), "{e}");
    }

    pub(crate) use crate::scratch::scratch;

    /// Gzip-compresses `bytes`.
    pub fn gzip(bytes: &[u8]) -> Vec<u8> {
        use std::io::Write;
        let mut encoder = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        encoder.write_all(bytes).unwrap();
        encoder.finish().unwrap()
    }

    #[test]
    fn inflation_is_bounded_by_the_declared_size() {
        let path = Path::new("x.gz");
        let format = ScalarFormat {
            scalar: ScalarType::U16,
            order: super::super::ByteOrder::Big,
        };
        let data: Vec<u8> = (0..20u8).collect();
        let compressed = gzip(&data);
        let mut out = Voxels::new(format.scalar);
        let mut reader = MultiGzDecoder::new(&compressed[..]);
        inflate_values(path, &mut reader, 16, format, 8, &mut out).unwrap();
        let Voxels::U16(out) = out else {
            panic!("u16 values held as {:?}", out.scalar_type())
        };
        assert_eq!(out[..2], [1, 2 * 256 + 3]);
        assert!(out.capacity() <= 8, "{}", out.capacity());
        let err = expect_end(path, &mut reader, 16).unwrap_err();
        assert!(
            matches!(err, VolumeError::InflatesPast { declared: 16, .. }),
            "{err}"
        );
        let mut reader = MultiGzDecoder::new(&compressed[..]);
        let err =
            inflate_values(path, &mut reader, 24, format, 12, &mut Voxels::default()).unwrap_err();
        assert!(
            matches!(
                err,
                VolumeError::InflatesShort {
                    expected: 24,
                    actual: 20,
                    ..
                }
            ),
            "{err}"
        );
        let mut reader = MultiGzDecoder::new(&compressed[..compressed.len() - 4]);
        let err = inflate_values(path, &mut reader, 20, format, 10, &mut Voxels::default())
            .and_then(|()| expect_end(path, &mut reader, 20))
            .unwrap_err();
        assert!(matches!(err, VolumeError::Decompress { .. }), "{err}");
    }

    #[test]
    fn placement_normalises_columns_and_refuses_degenerate_axes() {
        let path = Path::new("p.nrrd");
        let columns = [
            DVec3::new(-2.0, 0.0, 0.0),
            DVec3::new(0.0, 0.0, 3.0),
            DVec3::Y * 0.5,
        ];
        let placed = Placement::from_columns(path, columns, DVec3::ONE).unwrap();
        assert_eq!(placed.spacing, [2.0, 3.0, 0.5]);
        assert_eq!(
            placed.direction,
            DMat3::from_cols(-DVec3::X, DVec3::Z, DVec3::Y)
        );
        let flat = [DVec3::X, DVec3::Y, DVec3::X + DVec3::Y];
        let err = Placement::from_columns(path, flat, DVec3::ZERO).unwrap_err();
        assert!(matches!(err, VolumeError::Header { .. }), "{err}");
        let err = Placement::axis_aligned(path, [1.0, 0.0, 1.0], [0.0; 3]).unwrap_err();
        assert!(matches!(err, VolumeError::BadPlacement { .. }), "{err}");
        let err = Placement::axis_aligned(path, [1.0; 3], [f64::NAN, 0.0, 0.0]).unwrap_err();
        assert!(matches!(err, VolumeError::BadPlacement { .. }), "{err}");
    }
}
