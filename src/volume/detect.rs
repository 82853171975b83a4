//! Loading a volume file of any supported format: [`load_volume`] tells the format from the
//! file's first bytes (a folder is a DICOM series), and [`volume_info`] describes what it loaded.
//!
//! Recognised, by content rather than by name (so a misnamed file still loads):
//! - a folder, or a file with the `DICM` magic at offset 128: a DICOM series (a single file
//!   loads the series in its folder);
//! - `NRRD000x`: NRRD, attached (`.nrrd`) or detached (`.nhdr`), see [`super::nrrd`];
//! - `# vtk DataFile`: legacy VTK `STRUCTURED_POINTS`, see [`super::vtk`];
//! - `<?xml` or `<VTKFile`: VTK XML `ImageData` (`.vti`), see [`super::vtk`];
//! - `n+1\0` or `ni1\0` at NIfTI-1's magic offset, `n+2\0` or `ni2\0` at NIfTI-2's, plain or
//!   gzip-compressed: NIfTI, see [`super::nifti`];
//! - a 348-byte header size without NIfTI's magic: Analyze 7.5 (`.hdr`), see [`super::nifti`];
//! - `ObjectType`, `NDims` or `ElementDataFile` lines: MetaImage, see [`super::metaimage`];
//! - text with an `ObjectFileName` key: a Voreen-style `.dat` header, see [`super::dat`].
//!
//! Anything else is taken for headerless raw data or a slice stack, which carries neither its
//! size nor its type: [`VolumeError::NoHeader`] says to give the raw options instead.
//!
//! What the loaders share (the loaded volume, errors, placement, bounded decompression, header
//! lines) lives in [`super::loader`]; this module only sniffs and dispatches.

use std::io::{BufReader, Read};
use std::path::Path;

use flate2::read::MultiGzDecoder;
use serde_json::Value;

pub use super::loader::{
    CoordinateFrame, LoadOptions, LoadedVolume, NiftiTransform, SeriesChoice, VolumeFormat,
    scalar_type_name,
};
use super::loader::{GZIP_MAGIC, io_error, read_head};
use super::{CpuVolume, VolumeError, dat, dicom, metaimage, nifti, nrrd, vtk};

/// Loads the volume at `path` in whatever supported format it is (see the module docs).
pub fn load_volume(path: &Path) -> Result<CpuVolume, VolumeError> {
    load_volume_with_info(path).map(|loaded| loaded.volume)
}

/// Loads the volume at `path` with its format and stored value type.
pub fn load_volume_with_info(path: &Path) -> Result<LoadedVolume, VolumeError> {
    load_volume_with(path, &LoadOptions::default())
}

/// Loads the volume at `path` as `options` say: the DICOM series, the 4-D NIfTI frame, the
/// NIfTI transform, the coordinate frame of a format that states none. An option that cannot
/// apply to the file's format is [`VolumeError::Unsupported`], naming it.
pub fn load_volume_with(path: &Path, options: &LoadOptions) -> Result<LoadedVolume, VolumeError> {
    load_format(path, options).map_err(|e| e.named_by_header(path))
}

fn load_format(path: &Path, options: &LoadOptions) -> Result<LoadedVolume, VolumeError> {
    let format = detect_format(path)?;
    options.check_applies(path, format)?;
    let loaded = match format {
        VolumeFormat::Dicom => {
            // The DICOM loader reads a whole folder; a single file picks its own series.
            let (volume, scalar_type) = if path.is_dir() {
                dicom::load_dicom_series_choosing(
                    path,
                    options.series.as_ref(),
                    options.skip_unreadable,
                )?
            } else {
                dicom::load_dicom_file_series(path, options.skip_unreadable)?
            };
            LoadedVolume {
                volume,
                format,
                scalar_type,
                patient_frame: true,
            }
        }
        VolumeFormat::Nrrd => nrrd::load_nrrd(path)?,
        VolumeFormat::VtkLegacy => vtk::load_vtk_legacy(path)?,
        VolumeFormat::VtkXml => vtk::load_vti(path)?,
        VolumeFormat::Nifti => nifti::load_nifti_with(
            path,
            options.frame,
            options.nifti_transform.unwrap_or_default(),
        )?,
        VolumeFormat::Analyze => nifti::load_analyze(path)?,
        VolumeFormat::Dat => dat::load_dat(path)?,
        VolumeFormat::MetaImage => metaimage::load_metaimage(path)?,
    };
    loaded.in_frame(path, options.coordinate_frame)
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
    } else if nifti::is_nifti(&head) {
        Ok(VolumeFormat::Nifti)
    } else if head.starts_with(&GZIP_MAGIC) {
        detect_gzip(path)
    } else if nifti::is_analyze(&head) {
        Ok(VolumeFormat::Analyze)
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

/// Gzip-compressed volumes are NIfTI (`.nii.gz`); the name decides only when the inflated
/// start is unreadable, so that the NIfTI loader can report what is wrong with it.
fn detect_gzip(path: &Path) -> Result<VolumeFormat, VolumeError> {
    let mut head = Vec::new();
    let file = crate::input::open_regular(path).map_err(io_error(path))?;
    // Errors are ignored: a damaged stream is reported by the loader, not here.
    let _ = MultiGzDecoder::new(BufReader::new(file))
        .take(348)
        .read_to_end(&mut head);
    let named = path
        .file_name()
        .and_then(|n| n.to_str())
        .is_some_and(|n| n.to_ascii_lowercase().ends_with(".nii.gz"));
    if nifti::is_nifti(&head) || named {
        Ok(VolumeFormat::Nifti)
    } else {
        Err(VolumeError::Unsupported {
            path: path.into(),
            feature: "gzip-compressed data that is not NIfTI".into(),
        })
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::loader::tests::{gzip, scratch};

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
}
