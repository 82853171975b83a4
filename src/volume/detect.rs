//! Loading a volume file of any supported format: [`load_volume`] tells the format from the
//! file's first bytes (a folder is a DICOM series), and [`volume_info`] describes what it loaded.
//!
//! Recognised, by content rather than by name (so a misnamed file still loads):
//! - a folder, or a file with the `DICM` magic at offset 128: a DICOM series (a single file
//!   loads the series in its folder);
//! - `NRRD000x`: NRRD, attached (`.nrrd`) or detached (`.nhdr`), see [`super::nrrd`];
//! - `# vtk DataFile`: legacy VTK `STRUCTURED_POINTS`, see [`super::vtk`];
//! - `<?xml` or `<VTKFile`: VTK XML `ImageData` (`.vti`), see [`super::vtk`];
//! - `n+1\0` (or `ni1\0`, `n+2\0`) at NIfTI's magic offset, plain or gzip-compressed: NIfTI,
//!   see [`super::nifti`];
//! - text with an `ObjectFileName` key: a Voreen-style `.dat` header, see [`super::dat`].
//!
//! Anything else is taken for headerless raw data or a slice stack, which carries neither its
//! size nor its type: [`VolumeError::NoHeader`] says to give the raw options instead.
//!
//! This module also holds what the header formats' loaders share: placement from axis vectors,
//! bounded reading of compressed data, and reading text header lines ahead of binary data.

use std::fs::File;
use std::io::{self, BufRead, BufReader, Read, Take};
use std::path::{Path, PathBuf};

use flate2::read::MultiGzDecoder;
use glam::{DMat3, DVec3};
use serde_json::{Value, json};

use super::raw::decode;
use super::{
    CpuVolume, ScalarFormat, ScalarType, VolumeError, dat, dicom, metaimage, nifti, nrrd, vtk,
};

/// The volume file formats [`load_volume`] recognises.
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
    /// NIfTI-1, plain or gzip-compressed.
    Nifti,
    /// A Voreen-style `.dat` text header next to a raw file.
    Dat,
    /// MetaImage (`.mha`, or `.mhd` with a data file), ITK's format.
    MetaImage,
}

impl VolumeFormat {
    /// The short name used in [`volume_info`]: `dicom`, `nrrd`, `vtk`, `vti`, `nifti` or `dat`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Dicom => "dicom",
            Self::Nrrd => "nrrd",
            Self::VtkLegacy => "vtk",
            Self::VtkXml => "vti",
            Self::Nifti => "nifti",
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
}

impl LoadedVolume {
    /// The description [`volume_info`] gives, with `file` as the file name shown.
    pub fn info(&self, file: &Path) -> Value {
        let v = &self.volume;
        let d = v.direction;
        let rows: Vec<[f64; 3]> = (0..3).map(|r| d.row(r).to_array()).collect();
        let (min, max, mean) = match value_range(&v.values) {
            Some((min, max, mean)) => (json!(min), json!(max), json!(mean)),
            None => (Value::Null, Value::Null, Value::Null),
        };
        json!({
            "file": file.display().to_string(),
            "format": self.format.name(),
            "size": v.dims,
            "spacing": v.spacing,
            "origin": v.origin,
            "direction": rows,
            "scalar_type": self.scalar_type.map(scalar_type_name),
            "min": min,
            "max": max,
            "mean": mean,
        })
    }
}

/// The name [`volume_info`] gives a stored value type: `uint8`, `int8`, `uint16`, `int16`,
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
fn value_range(values: &[f32]) -> Option<(f64, f64, f64)> {
    let (mut min, mut max, mut sum, mut n) = (f64::INFINITY, f64::NEG_INFINITY, 0.0, 0u64);
    for &v in values.iter().filter(|v| v.is_finite()) {
        let v = f64::from(v);
        min = min.min(v);
        max = max.max(v);
        sum += v;
        n += 1;
    }
    (n > 0).then(|| (min, max, sum / n as f64))
}

/// Loads the volume at `path` in whatever supported format it is (see the module docs).
pub fn load_volume(path: &Path) -> Result<CpuVolume, VolumeError> {
    load_volume_with_info(path).map(|loaded| loaded.volume)
}

/// Loads the volume at `path` with its format and stored value type.
pub fn load_volume_with_info(path: &Path) -> Result<LoadedVolume, VolumeError> {
    load_volume_choosing(path, None)
}

/// [`load_volume_with_info`], with the DICOM series to load from a folder that holds several
/// (a DICOM file given alone loads its own series).
pub fn load_volume_choosing(
    path: &Path,
    series: Option<&dicom::SeriesChoice>,
) -> Result<LoadedVolume, VolumeError> {
    load_volume_frame(path, series, None)
}

/// [`load_volume_choosing`], with the 3-D frame to read from a 4-D NIfTI file (`None`: the
/// first); a frame given for another format is [`VolumeError::Unsupported`].
pub fn load_volume_frame(
    path: &Path,
    series: Option<&dicom::SeriesChoice>,
    frame: Option<u32>,
) -> Result<LoadedVolume, VolumeError> {
    let format = detect_format(path)?;
    if frame.is_some() && format != VolumeFormat::Nifti {
        return Err(unsupported(
            path,
            format!(
                "a frame of a {} file; frames are read from 4-D NIfTI",
                format.name()
            ),
        ));
    }
    if format == VolumeFormat::Nifti {
        return nifti::load_nifti_frame(path, frame);
    }
    match format {
        VolumeFormat::Dicom => {
            // The DICOM loader reads a whole folder; a single slice stands for its series.
            let (dir, own) = match path.parent() {
                _ if path.is_dir() => (path, None),
                Some(parent) if !parent.as_os_str().is_empty() => {
                    (parent, Some(dicom::series_of(path)?))
                }
                _ => (Path::new("."), Some(dicom::series_of(path)?)),
            };
            let own = own.map(dicom::SeriesChoice);
            let (volume, scalar_type) =
                dicom::load_dicom_series_choosing(dir, series.or(own.as_ref()))?;
            Ok(LoadedVolume {
                volume,
                format,
                scalar_type,
            })
        }
        VolumeFormat::Nrrd => nrrd::load_nrrd(path),
        VolumeFormat::VtkLegacy => vtk::load_vtk_legacy(path),
        VolumeFormat::VtkXml => vtk::load_vti(path),
        VolumeFormat::Nifti => nifti::load_nifti(path),
        VolumeFormat::Dat => dat::load_dat(path),
        VolumeFormat::MetaImage => metaimage::load_metaimage(path),
    }
}

/// Loads the volume at `path` and describes it as JSON: `file`, `format` (see
/// [`VolumeFormat::name`]), `size` `[nx, ny, nz]`, `spacing`, `origin`, `direction` (three
/// rows of the orientation matrix, whose columns are the grid axes), `scalar_type` (the stored
/// type, see [`scalar_type_name`]; `null` when a DICOM series stores a type it does not name) and the `min`, `max` and `mean` of the
/// finite loaded values (after any rescale; `null` when there are none).
pub fn volume_info(path: &Path) -> Result<Value, VolumeError> {
    load_volume_with_info(path).map(|loaded| loaded.info(path))
}

/// Bytes read from the start of a file to tell its format: enough for NIfTI's 348-byte
/// header and for a `.dat` header's `ObjectFileName` line.
const SNIFF_BYTES: u64 = 4096;

/// The format of the file or folder at `path`, from its first bytes (see the module docs).
pub fn detect_format(path: &Path) -> Result<VolumeFormat, VolumeError> {
    let meta = std::fs::metadata(path).map_err(io_error(path))?;
    if meta.is_dir() {
        return Ok(VolumeFormat::Dicom);
    }
    let head = read_head(path, SNIFF_BYTES)?;
    if head.starts_with(b"NRRD000") {
        Ok(VolumeFormat::Nrrd)
    } else if head.starts_with(b"# vtk DataFile") {
        Ok(VolumeFormat::VtkLegacy)
    } else if is_xml(&head) {
        Ok(VolumeFormat::VtkXml)
    } else if is_nifti(&head) {
        Ok(VolumeFormat::Nifti)
    } else if head.starts_with(&GZIP_MAGIC) {
        detect_gzip(path)
    } else if dicom::is_dicom(&head) {
        Ok(VolumeFormat::Dicom)
    } else if metaimage::is_metaimage(&head) {
        Ok(VolumeFormat::MetaImage)
    } else if is_dat(&head) {
        Ok(VolumeFormat::Dat)
    } else {
        Err(VolumeError::NoHeader { path: path.into() })
    }
}

/// The two bytes every gzip stream starts with.
pub(super) const GZIP_MAGIC: [u8; 2] = [0x1f, 0x8b];

/// Gzip-compressed volumes are NIfTI (`.nii.gz`); the name decides only when the inflated
/// start is unreadable, so that the NIfTI loader can report what is wrong with it.
fn detect_gzip(path: &Path) -> Result<VolumeFormat, VolumeError> {
    let mut head = Vec::new();
    let file = File::open(path).map_err(io_error(path))?;
    // Errors are ignored: a damaged stream is reported by the loader, not here.
    let _ = MultiGzDecoder::new(BufReader::new(file))
        .take(NIFTI_MAGIC_END as u64)
        .read_to_end(&mut head);
    let named = path
        .file_name()
        .and_then(|n| n.to_str())
        .is_some_and(|n| n.to_ascii_lowercase().ends_with(".nii.gz"));
    if is_nifti(&head) || named {
        Ok(VolumeFormat::Nifti)
    } else {
        Err(VolumeError::Unsupported {
            path: path.into(),
            feature: "gzip-compressed data that is not NIfTI".into(),
        })
    }
}

/// One past the last byte of the NIfTI-1 magic.
const NIFTI_MAGIC_END: usize = 348;

fn is_nifti(head: &[u8]) -> bool {
    let nifti1 = matches!(head.get(344..NIFTI_MAGIC_END), Some(b"n+1\0" | b"ni1\0"));
    // NIfTI-2 keeps its magic right after the 4-byte header size; the loader refuses it by name.
    nifti1 || matches!(head.get(4..8), Some(b"n+2\0" | b"ni2\0"))
}

fn is_xml(head: &[u8]) -> bool {
    let text = head.strip_prefix(b"\xef\xbb\xbf").unwrap_or(head);
    let start = text.iter().position(|b| !b.is_ascii_whitespace());
    let text = &text[start.unwrap_or(text.len())..];
    text.starts_with(b"<?xml") || text.starts_with(b"<VTKFile")
}

fn is_dat(head: &[u8]) -> bool {
    let text = match std::str::from_utf8(head) {
        Ok(text) => text,
        // The sniffed prefix may end inside a multi-byte character.
        Err(e) => std::str::from_utf8(&head[..e.valid_up_to()]).unwrap_or_default(),
    };
    text.lines().any(|line| {
        let key = line.trim_start().split(':').next().unwrap_or_default();
        key.trim().eq_ignore_ascii_case("ObjectFileName")
    })
}

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
    File::open(path)
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
                format!("axis directions {columns:?} do not span 3-D space"),
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
    out: &mut Vec<f32>,
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
        reserve_capped(out, want / size, total);
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

/// Grows `out` to take `adding` more values, doubling as a `Vec` would but never past `total`.
fn reserve_capped(out: &mut Vec<f32>, adding: usize, total: usize) {
    let needed = out.len() + adding;
    if needed > out.capacity() {
        let target = out
            .capacity()
            .saturating_mul(2)
            .clamp(needed, total.max(needed));
        out.reserve_exact(target - out.len());
    }
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
        let file = File::open(path).map_err(io_error(path))?;
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

    /// A fresh directory per test, so that parallel tests and earlier runs never collide.
    pub fn scratch(tag: &str) -> PathBuf {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_nanos();
        let dir =
            std::env::temp_dir().join(format!("splatscene-{tag}-{}-{nanos}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// Gzip-compresses `bytes`.
    pub fn gzip(bytes: &[u8]) -> Vec<u8> {
        use std::io::Write;
        let mut encoder = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        encoder.write_all(bytes).unwrap();
        encoder.finish().unwrap()
    }

    #[test]
    fn formats_are_told_by_content() {
        let dir = scratch("detect");
        let cases: [(&str, Vec<u8>, Result<VolumeFormat, &str>); 7] = [
            (
                "a.raw",
                b"NRRD0004\ntype: uchar\n".to_vec(),
                Ok(VolumeFormat::Nrrd),
            ),
            (
                "b",
                b"# vtk DataFile Version 3.0\n".to_vec(),
                Ok(VolumeFormat::VtkLegacy),
            ),
            (
                "c.xml",
                b"\n  <VTKFile type=\"ImageData\">".to_vec(),
                Ok(VolumeFormat::VtkXml),
            ),
            (
                "d.dat",
                b"ObjectFileName: d.raw\n".to_vec(),
                Ok(VolumeFormat::Dat),
            ),
            ("e.raw", vec![7u8; 1000], Err("raw options")),
            ("f.gz", gzip(b"not a volume"), Err("not NIfTI")),
            ("g.nii.gz", gzip(b"short"), Ok(VolumeFormat::Nifti)),
        ];
        for (name, bytes, expected) in cases {
            let path = dir.join(name);
            std::fs::write(&path, bytes).unwrap();
            match (detect_format(&path), expected) {
                (Ok(format), Ok(want)) => assert_eq!(format, want, "{name}"),
                (Err(err), Err(text)) => {
                    let message = err.to_string();
                    assert!(
                        message.contains(text) && message.contains(name),
                        "{message}"
                    );
                }
                (got, want) => panic!("{name}: got {got:?}, expected {want:?}"),
            }
        }
        let mut nifti = vec![0u8; 352];
        nifti[344..348].copy_from_slice(b"n+1\0");
        std::fs::write(dir.join("h.bin"), &nifti).unwrap();
        assert_eq!(
            detect_format(&dir.join("h.bin")).unwrap(),
            VolumeFormat::Nifti
        );
        std::fs::write(dir.join("i.gz"), gzip(&nifti)).unwrap();
        assert_eq!(
            detect_format(&dir.join("i.gz")).unwrap(),
            VolumeFormat::Nifti
        );
        assert_eq!(detect_format(&dir).unwrap(), VolumeFormat::Dicom);
        let err = detect_format(&dir.join("absent.nrrd")).unwrap_err();
        assert!(matches!(err, VolumeError::Io { .. }), "{err}");
        std::fs::remove_dir_all(dir).ok();
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
        let mut out = Vec::new();
        let mut reader = MultiGzDecoder::new(&compressed[..]);
        inflate_values(path, &mut reader, 16, format, 8, &mut out).unwrap();
        assert_eq!(out[..2], [1.0, 2.0 * 256.0 + 3.0]);
        assert!(out.capacity() <= 8, "{}", out.capacity());
        let err = expect_end(path, &mut reader, 16).unwrap_err();
        assert!(
            matches!(err, VolumeError::InflatesPast { declared: 16, .. }),
            "{err}"
        );
        let mut reader = MultiGzDecoder::new(&compressed[..]);
        let err = inflate_values(path, &mut reader, 24, format, 12, &mut Vec::new()).unwrap_err();
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
        let err = inflate_values(path, &mut reader, 20, format, 10, &mut Vec::new())
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
