//! Voreen-style `.dat` headers: a few `Key: value` text lines naming a headerless raw file.
//!
//! ```text
//! ObjectFileName: tooth_103x94x161_uint8.raw
//! Resolution:  103  94  161
//! SliceThickness: 1.0 1.0 1.0
//! Format:         UCHAR
//! ```
//!
//! Read: `ObjectFileName` (relative to the `.dat` file's folder), `Resolution`,
//! `SliceThickness` (the spacing; unit spacing when absent), `Format` (`UCHAR`, `CHAR`,
//! `USHORT`, `USHORT_12`, `SHORT`, `UINT`, `INT`, `FLOAT`, `DOUBLE`) and `ObjectModel` (only
//! `I`, one scalar per voxel). Other keys (`TaggedFileName`, `GridType`, ...) are ignored. The
//! format has no byte-order key: multi-byte values are read little-endian, as Voreen writes
//! them. The raw file's length is checked against the declared size before allocating.

use std::path::Path;

use super::loader::{LoadedVolume, Placement, VolumeFormat, header_error, read_head, unsupported};
use super::{ByteOrder, RawSpec, ScalarType, VolumeError, load_raw};

/// Longest `.dat` header read; real ones are a few hundred bytes.
const DAT_CAP: u64 = 64 << 10;

/// Loads the raw volume a `.dat` header describes.
pub fn load_dat(path: &Path) -> Result<LoadedVolume, VolumeError> {
    let header = DatHeader::read(path)?;
    let placement = Placement::axis_aligned(path, header.spacing, [0.0; 3])?;
    let data = path.parent().unwrap_or(Path::new("")).join(&header.object);
    super::loader::check_data_files(path, std::slice::from_ref(&data))?;
    let spec = RawSpec::new(header.dims, header.scalar, ByteOrder::Little);
    Ok(LoadedVolume {
        volume: placement.apply(load_raw(&data, &spec)?),
        format: VolumeFormat::Dat,
        scalar_type: Some(header.scalar),
        patient_frame: false,
    })
}

/// What a `.dat` header says.
struct DatHeader {
    object: String,
    dims: [u32; 3],
    spacing: [f64; 3],
    scalar: ScalarType,
}

impl DatHeader {
    fn read(path: &Path) -> Result<Self, VolumeError> {
        let bytes = read_head(path, DAT_CAP + 1)?;
        if bytes.len() as u64 > DAT_CAP {
            return Err(header_error(path, format!("longer than {DAT_CAP} bytes")));
        }
        let text = std::str::from_utf8(&bytes).map_err(|_| header_error(path, "not text"))?;
        let mut keys = DatKeys::default();
        for (i, line) in text.lines().enumerate() {
            if !line.trim().is_empty() {
                keys.take(path, i + 1, line)?;
            }
        }
        let missing = |key: &str| header_error(path, format!("no {key}"));
        Ok(Self {
            object: keys
                .object
                .filter(|o| !o.is_empty())
                .ok_or_else(|| missing("ObjectFileName"))?,
            dims: keys.dims.ok_or_else(|| missing("Resolution"))?,
            spacing: keys.spacing.unwrap_or([1.0; 3]),
            scalar: keys.scalar.ok_or_else(|| missing("Format"))?,
        })
    }
}

/// The keys of a `.dat` header read so far.
#[derive(Default)]
struct DatKeys {
    object: Option<String>,
    dims: Option<[u32; 3]>,
    spacing: Option<[f64; 3]>,
    scalar: Option<ScalarType>,
}

impl DatKeys {
    /// Takes one `Key: value` line; unknown keys are ignored.
    fn take(&mut self, path: &Path, number: usize, line: &str) -> Result<(), VolumeError> {
        let at = |message: String| header_error(path, format!("line {number}: {message}"));
        let (key, value) = line
            .split_once(':')
            .ok_or_else(|| at(format!("{line:?} is not `Key: value`")))?;
        let value = value.trim();
        match key.trim().to_ascii_lowercase().as_str() {
            "objectfilename" => self.object = Some(value.to_owned()),
            "resolution" => {
                let dims = numbers(value)
                    .ok_or_else(|| at(format!("Resolution {value:?} is not 3 counts")))?;
                self.dims = Some(dims);
            }
            "slicethickness" => {
                let spacing = numbers(value)
                    .ok_or_else(|| at(format!("SliceThickness {value:?} is not 3 numbers")))?;
                self.spacing = Some(spacing);
            }
            "format" => match scalar_type(value) {
                Some(Some(scalar)) => self.scalar = Some(scalar),
                Some(None) => return Err(unsupported(path, format!("Format {value}"))),
                None => return Err(at(format!("unknown Format {value:?}"))),
            },
            "objectmodel" if !value.eq_ignore_ascii_case("I") => {
                let feature = format!("ObjectModel {value}; only I (one scalar per voxel) is read");
                return Err(unsupported(path, feature));
            }
            _ => {}
        }
        Ok(())
    }
}

/// Exactly three whitespace-separated numbers.
fn numbers<T: std::str::FromStr>(value: &str) -> Option<[T; 3]> {
    let parsed: Option<Vec<T>> = value.split_whitespace().map(|w| w.parse().ok()).collect();
    parsed?.try_into().ok()
}

/// The type a `Format` names: `Some(None)` for a known type that is not read, `None` for an
/// unknown name.
fn scalar_type(name: &str) -> Option<Option<ScalarType>> {
    Some(Some(match name.to_ascii_uppercase().as_str() {
        "UCHAR" => ScalarType::U8,
        "CHAR" => ScalarType::I8,
        // 12-bit CT values stored in 16-bit words.
        "USHORT" | "USHORT_12" => ScalarType::U16,
        "SHORT" => ScalarType::I16,
        "UINT" => ScalarType::U32,
        "INT" => ScalarType::I32,
        "FLOAT" => ScalarType::F32,
        "DOUBLE" => ScalarType::F64,
        // 4 or 8 bytes, depending on the writer's platform.
        "ULONG" | "LONG" => return Some(None),
        _ => return None,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::loader::tests::scratch;

    fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path
    }

    #[test]
    fn reads_the_raw_file_it_names() {
        let dir = scratch("dat");
        let values: Vec<u16> = (0..12).map(|v| v * 1000).collect();
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        std::fs::write(dir.join("v.raw"), bytes).unwrap();
        let dat = write(
            &dir,
            "v.dat",
            "ObjectFileName: v.raw\nTaggedFileName: ---\nResolution: 3 2 2\nSliceThickness: 0.5 0.5 2\nFormat: USHORT\n\n\n",
        );
        let loaded = load_dat(&dat).unwrap();
        assert_eq!(
            loaded.volume.values,
            values.iter().map(|&v| f32::from(v)).collect::<Vec<_>>()
        );
        assert_eq!(
            (loaded.volume.dims, loaded.volume.spacing),
            ([3, 2, 2], [0.5, 0.5, 2.0])
        );
        assert_eq!(loaded.scalar_type, Some(ScalarType::U16));
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn bad_headers_name_the_file_and_the_problem() {
        let dir = scratch("dat-bad");
        std::fs::write(dir.join("v.raw"), [0u8; 8]).unwrap();
        let cases = [
            (
                "fmt.dat",
                "ObjectFileName: v.raw\nResolution: 2 2 2\nFormat: UCHAR3\n",
                "unknown Format",
            ),
            (
                "res.dat",
                "ObjectFileName: v.raw\nResolution: 2 2\nFormat: UCHAR\n",
                "Resolution",
            ),
            (
                "noobj.dat",
                "Resolution: 2 2 2\nFormat: UCHAR\n",
                "no ObjectFileName",
            ),
            (
                "model.dat",
                "ObjectFileName: v.raw\nResolution: 2 2 2\nFormat: UCHAR\nObjectModel: RGBA\n",
                "ObjectModel",
            ),
            (
                "gone.dat",
                "ObjectFileName: gone.raw\nResolution: 2 2 2\nFormat: UCHAR\n",
                "gone.raw",
            ),
            (
                "short.dat",
                "ObjectFileName: v.raw\nResolution: 2 2 3\nFormat: UCHAR\n",
                "needs 12 bytes",
            ),
            (
                "flat.dat",
                "ObjectFileName: v.raw\nResolution: 2 2 2\nSliceThickness: 1 0 1\nFormat: UCHAR\n",
                "spacing",
            ),
            ("line.dat", "ObjectFileName: v.raw\ngarbage\n", "line 2"),
        ];
        for (name, text, expected) in cases {
            let err = load_dat(&write(&dir, name, text)).unwrap_err().to_string();
            assert!(err.contains(expected), "{name}: {err}");
            let named = if name == "short.dat" { "v.raw" } else { name };
            assert!(err.contains(named), "{name}: {err}");
        }
        std::fs::remove_dir_all(dir).ok();
    }
}
