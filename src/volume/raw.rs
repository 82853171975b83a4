//! Headerless raw volumes: one file holding every slice, or one file per z slice.
//!
//! Raw files carry neither their size nor their value type, so the caller states both in a
//! [`RawSpec`]. Every declared size is checked, with overflow-safe arithmetic, against the file
//! lengths before any voxel memory is allocated: a wrong spec gives a [`VolumeError`] naming the
//! file, never a panic or an allocation the file could not fill. Values are converted to `f32` as
//! they are, without rescaling (32-bit integers and `f64` round to the nearest `f32`).

use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use glam::DMat3;

pub use super::loader::{ByteOrder, ParseScalarError, ScalarFormat, ScalarType, VolumeError};
use super::loader::{checked_voxels, decode};
use super::{CpuVolume, Voxels};

/// What a headerless raw file holds and where the volume sits in the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RawSpec {
    /// Voxels along x, y and z (x fastest in the file).
    pub dims: [u32; 3],
    /// The stored value type.
    pub scalar: ScalarType,
    /// The byte order of multi-byte values.
    pub order: ByteOrder,
    /// Bytes to skip at the start of each file.
    pub header_bytes: u64,
    /// Distance between voxel centres, in millimetres.
    pub spacing: [f64; 3],
    /// World position of voxel (0, 0, 0), in millimetres.
    pub origin: [f64; 3],
}

impl RawSpec {
    /// A spec with no header, unit spacing and the origin at zero; change fields as needed:
    /// `RawSpec { spacing: [1.0, 1.0, 2.0], ..RawSpec::new(dims, ScalarType::U16, ByteOrder::Big) }`.
    pub fn new(dims: [u32; 3], scalar: ScalarType, order: ByteOrder) -> Self {
        Self {
            dims,
            scalar,
            order,
            header_bytes: 0,
            spacing: [1.0; 3],
            origin: [0.0; 3],
        }
    }

    /// Checks what does not depend on the file contents; returns the voxel count.
    fn check(&self, path: &Path) -> Result<usize, VolumeError> {
        let count = checked_voxels(path, self.dims, self.scalar)?;
        let finite = self
            .spacing
            .iter()
            .chain(&self.origin)
            .all(|v| v.is_finite());
        if !finite || self.spacing.iter().any(|&s| s <= 0.0) {
            return Err(VolumeError::BadPlacement {
                path: path.into(),
                spacing: self.spacing,
                origin: self.origin,
            });
        }
        usize::try_from(count).map_err(|_| self.overflow(path, count))
    }

    /// Bytes a file holding `values` values after the header must at least have.
    fn needed_bytes(&self, path: &Path, values: u64) -> Result<u64, VolumeError> {
        values
            .checked_mul(self.scalar.size() as u64)
            .and_then(|b| b.checked_add(self.header_bytes))
            .ok_or_else(|| self.overflow(path, values))
    }

    fn overflow(&self, path: &Path, values: u64) -> VolumeError {
        VolumeError::SizeOverflow {
            path: path.into(),
            values,
            scalar: self.scalar,
            header_bytes: self.header_bytes,
        }
    }

    fn volume(&self, values: Voxels) -> CpuVolume {
        CpuVolume {
            dims: self.dims,
            spacing: self.spacing,
            origin: self.origin,
            direction: DMat3::IDENTITY,
            values,
        }
    }
}

/// Loads one headerless file holding all `nx * ny * nz` values (x fastest) after
/// `spec.header_bytes`. Bytes past the declared size are ignored, since some writers pad files
/// or append a trailer; a file shorter than the declared size is an error.
pub fn load_raw(path: &Path, spec: &RawSpec) -> Result<CpuVolume, VolumeError> {
    let count = spec.check(path)?;
    let needed = spec.needed_bytes(path, count as u64)?;
    check_length(path, needed)?;
    let mut values = Voxels::new(spec.scalar);
    values.reserve_capped(count, count);
    read_values(path, spec, count as u64, &mut values)?;
    Ok(spec.volume(values))
}

/// Loads a stack of headerless files, one per z slice in order: each holds `spec.header_bytes`
/// then `nx * ny` values; `spec.dims[2]` must equal the number of files. Every file's length is
/// checked before the volume is allocated; bytes past a slice are ignored as in [`load_raw`].
pub fn load_raw_slices(paths: &[PathBuf], spec: &RawSpec) -> Result<CpuVolume, VolumeError> {
    let first = paths
        .first()
        .ok_or(VolumeError::NoSlices { dims: spec.dims })?;
    let count = spec.check(first)?;
    if u64::from(spec.dims[2]) != paths.len() as u64 {
        return Err(VolumeError::SliceCount {
            path: first.clone(),
            files: paths.len(),
            nz: spec.dims[2],
        });
    }
    let per_slice = u64::from(spec.dims[0]) * u64::from(spec.dims[1]);
    let needed = spec.needed_bytes(first, per_slice)?;
    for path in paths {
        check_length(path, needed)?;
    }
    let mut values = Voxels::new(spec.scalar);
    values.reserve_capped(count, count);
    for path in paths {
        read_values(path, spec, per_slice, &mut values)?;
    }
    Ok(spec.volume(values))
}

/// The numbered files of a slice stack starting at `first` (e.g. `dir/CThead.1` gives
/// `CThead.1`, `CThead.2`, ... in numeric order, not name order), up to the first missing
/// number. Zero-padded numbers (`slice.001`) keep their width. A file numbered past the first
/// gap means a slice is missing, which is an error rather than a silently shorter volume.
pub fn slice_stack(first: &Path) -> Result<Vec<PathBuf>, VolumeError> {
    let not_numbered = || VolumeError::NotNumbered { path: first.into() };
    let name = first
        .file_name()
        .and_then(|n| n.to_str())
        .ok_or_else(not_numbered)?;
    let (stem, digits) = split_number(name).ok_or_else(not_numbered)?;
    let start: u64 = digits.parse().map_err(|_| not_numbered())?;
    let width = if digits.starts_with('0') {
        digits.len()
    } else {
        0
    };
    let dir = match first.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let io = |source| VolumeError::Io {
        path: first.into(),
        source,
    };
    if !std::fs::metadata(first).map_err(io)?.is_file() {
        return Err(io(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "not a regular file",
        )));
    }
    let numbered = |n: u64| dir.join(format!("{stem}.{n:0width$}"));
    let mut paths = Vec::new();
    let mut next = start;
    while next < u64::MAX && numbered(next).is_file() {
        paths.push(numbered(next));
        next += 1;
    }
    if let Some(later) = first_numbered_after(dir, stem, next)? {
        return Err(VolumeError::MissingSlice {
            path: numbered(next),
            later,
        });
    }
    Ok(paths)
}

/// Splits `stem.123` into `("stem", "123")`.
fn split_number(name: &str) -> Option<(&str, &str)> {
    name.rsplit_once('.').filter(|(stem, digits)| {
        !stem.is_empty() && !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit())
    })
}

/// The lowest-numbered `stem.<n>` file in `dir` with `n > after`, if any.
fn first_numbered_after(
    dir: &Path,
    stem: &str,
    after: u64,
) -> Result<Option<PathBuf>, VolumeError> {
    let io = |source| VolumeError::Io {
        path: dir.into(),
        source,
    };
    let mut best: Option<(u64, PathBuf)> = None;
    for entry in std::fs::read_dir(dir).map_err(io)? {
        let entry = entry.map_err(io)?;
        let name = entry.file_name();
        let Some((s, digits)) = name.to_str().and_then(split_number) else {
            continue;
        };
        let Ok(n) = digits.parse::<u64>() else {
            continue;
        };
        if s == stem && n > after && best.as_ref().is_none_or(|(b, _)| n < *b) {
            best = Some((n, entry.path()));
        }
    }
    Ok(best.map(|(_, path)| path))
}

/// Checks that `path` holds at least `needed` bytes.
fn check_length(path: &Path, needed: u64) -> Result<(), VolumeError> {
    let actual = std::fs::metadata(path)
        .map_err(|source| VolumeError::Io {
            path: path.into(),
            source,
        })?
        .len();
    if actual < needed {
        return Err(VolumeError::TooShort {
            path: path.into(),
            expected: needed,
            actual,
        });
    }
    Ok(())
}

/// Reads `count` values after the header, in chunks, so that no second full-size byte buffer
/// is needed next to the values. A file that shrank since its length was checked gives
/// an I/O error (unexpected end of file).
fn read_values(
    path: &Path,
    spec: &RawSpec,
    count: u64,
    out: &mut Voxels,
) -> Result<(), VolumeError> {
    const CHUNK_BYTES: usize = 1 << 20;
    let io = |source| VolumeError::Io {
        path: path.into(),
        source,
    };
    let mut file = crate::input::open_regular(path).map_err(io)?;
    file.seek(SeekFrom::Start(spec.header_bytes)).map_err(io)?;
    let size = spec.scalar.size();
    let mut buffer = vec![0u8; CHUNK_BYTES];
    let mut left = count;
    while left > 0 {
        let n = left.min((CHUNK_BYTES / size) as u64) as usize;
        let bytes = &mut buffer[..n * size];
        file.read_exact(bytes).map_err(io)?;
        decode(bytes, spec.scalar, spec.order, out);
        left -= n as u64;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::GridError;

    /// A fresh directory per test, so that parallel tests and earlier runs never collide.
    use crate::scratch::scratch;

    fn format(s: &str) -> ScalarFormat {
        s.parse().unwrap()
    }

    #[test]
    fn names_parse_with_and_without_byte_order() {
        let f = |scalar, order| ScalarFormat { scalar, order };
        assert_eq!(format("u8"), f(ScalarType::U8, ByteOrder::Little));
        assert_eq!(format("u16be"), f(ScalarType::U16, ByteOrder::Big));
        assert_eq!(format("i16le"), f(ScalarType::I16, ByteOrder::Little));
        assert_eq!(format("UInt16_BE"), f(ScalarType::U16, ByteOrder::Big));
        assert_eq!(format("double"), f(ScalarType::F64, ByteOrder::Little));
        assert_eq!(format("float64-be"), f(ScalarType::F64, ByteOrder::Big));
        assert_eq!("uint16".parse::<ScalarType>(), Ok(ScalarType::U16));
        assert_eq!("f32".parse::<ScalarType>(), Ok(ScalarType::F32));
        // A bare scalar type must not swallow a byte order.
        assert!("u16be".parse::<ScalarType>().is_err());
        for bad in ["", "be", "u12", "u16xe", "_le"] {
            assert_eq!(
                bad.parse::<ScalarFormat>(),
                Err(ParseScalarError(bad.into())),
                "{bad:?}"
            );
        }
    }

    #[test]
    fn every_type_decodes_in_both_byte_orders() {
        let cases: [(&str, Vec<u8>, f32); 8] = [
            ("u8", vec![200], 200.0),
            ("i8", vec![0xfe], -2.0),
            ("u16be", vec![0x12, 0x34], 4660.0),
            ("i16le", vec![0x18, 0xfc], -1000.0),
            ("u32be", vec![0, 1, 0, 0], 65536.0),
            ("i32le", vec![0xff, 0xff, 0xff, 0xff], -1.0),
            ("f32be", 1.5f32.to_be_bytes().to_vec(), 1.5),
            ("f64le", (-0.25f64).to_le_bytes().to_vec(), -0.25),
        ];
        for (name, bytes, value) in cases {
            let f = format(name);
            let mut out = Voxels::new(f.scalar);
            decode(&bytes, f.scalar, f.order, &mut out);
            assert_eq!(out, [value], "{name}");
        }
    }

    #[test]
    fn big_endian_u16_after_a_header_with_trailing_bytes() {
        let dir = scratch("be16");
        let path = dir.join("v.raw");
        let values: Vec<u16> = (0..24).map(|i| i * 1000 + 7).collect();
        let mut bytes = vec![0xaa; 5];
        bytes.extend(values.iter().flat_map(|v| v.to_be_bytes()));
        bytes.extend([1, 2, 3]);
        std::fs::write(&path, bytes).unwrap();
        let spec = RawSpec {
            header_bytes: 5,
            spacing: [0.5, 0.5, 2.0],
            ..RawSpec::new([4, 3, 2], ScalarType::U16, ByteOrder::Big)
        };
        let volume = load_raw(&path, &spec).unwrap();
        assert_eq!(
            volume.values,
            values.iter().map(|&v| f32::from(v)).collect::<Vec<_>>()
        );
        assert_eq!(
            (volume.dims, volume.spacing, volume.direction),
            ([4, 3, 2], [0.5, 0.5, 2.0], DMat3::IDENTITY)
        );
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn truncated_file_names_expected_and_actual_bytes() {
        let dir = scratch("short");
        let path = dir.join("short.raw");
        std::fs::write(&path, [0u8; 10]).unwrap();
        let spec = RawSpec {
            header_bytes: 4,
            ..RawSpec::new([2, 2, 2], ScalarType::U16, ByteOrder::Little)
        };
        let err = load_raw(&path, &spec).unwrap_err();
        assert!(
            matches!(
                err,
                VolumeError::TooShort {
                    expected: 20,
                    actual: 10,
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("short.raw"), "{err}");
        let missing = dir.join("absent.raw");
        let err = load_raw(&missing, &spec).unwrap_err();
        assert!(
            matches!(err, VolumeError::Io { ref path, .. } if *path == missing),
            "{err}"
        );
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn sizes_that_overflow_are_refused_before_reading() {
        // No file exists: every one of these must be refused from the spec alone.
        let path = Path::new("never/read.raw");
        let huge = RawSpec::new([65536, 65536, 65536], ScalarType::F64, ByteOrder::Little);
        let err = load_raw(path, &huge).unwrap_err();
        assert!(
            matches!(
                err,
                VolumeError::Grid {
                    source: GridError::TooLarge { .. },
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("never/read.raw"), "{err}");
        let header = RawSpec {
            header_bytes: u64::MAX - 3,
            ..RawSpec::new([2, 2, 1], ScalarType::U8, ByteOrder::Little)
        };
        assert!(matches!(
            load_raw(path, &header),
            Err(VolumeError::SizeOverflow { values: 4, .. })
        ));
        let flat = RawSpec {
            spacing: [1.0, 0.0, 1.0],
            ..header
        };
        assert!(matches!(
            load_raw(path, &flat),
            Err(VolumeError::BadPlacement { .. })
        ));
        let empty = RawSpec::new([4, 0, 4], ScalarType::U8, ByteOrder::Little);
        assert!(matches!(
            load_raw(path, &empty),
            Err(VolumeError::Grid {
                source: GridError::EmptyAxis(_),
                ..
            })
        ));
    }

    /// Writes `stem.<n>` files (numbers zero-padded to `width`) of three bytes: n, 2n, 9.
    fn write_slices(dir: &Path, stem: &str, width: usize, numbers: impl IntoIterator<Item = u8>) {
        for n in numbers {
            std::fs::write(dir.join(format!("{stem}.{n:0width$}")), [n, 2 * n, 9]).unwrap();
        }
    }

    #[test]
    fn slice_stack_is_numeric_and_loads_in_order() {
        let dir = scratch("stack");
        write_slices(&dir, "ct", 0, 1..=11);
        write_slices(&dir, "other", 0, 1..=3);
        let paths = slice_stack(&dir.join("ct.1")).unwrap();
        let names: Vec<_> = paths
            .iter()
            .map(|p| p.file_name().unwrap().to_str().unwrap())
            .collect();
        assert_eq!(
            names,
            (1..=11).map(|n| format!("ct.{n}")).collect::<Vec<_>>()
        );
        // Starting later takes the rest of the stack.
        assert_eq!(slice_stack(&dir.join("ct.9")).unwrap().len(), 3);
        let spec = RawSpec::new([2, 1, 11], ScalarType::U8, ByteOrder::Little);
        let volume = load_raw_slices(&paths, &spec).unwrap();
        let expected: Vec<f32> = (1..=11u8)
            .flat_map(|n| [f32::from(n), f32::from(2 * n)])
            .collect();
        assert_eq!(volume.values, expected);
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn every_slice_is_checked_before_loading() {
        let dir = scratch("stack-checks");
        write_slices(&dir, "ct", 0, 1..=11);
        let paths = slice_stack(&dir.join("ct.1")).unwrap();
        let spec = RawSpec::new([2, 1, 11], ScalarType::U8, ByteOrder::Little);
        let err = load_raw_slices(&paths[..10], &spec).unwrap_err();
        assert!(
            matches!(
                err,
                VolumeError::SliceCount {
                    files: 10,
                    nz: 11,
                    ..
                }
            ),
            "{err}"
        );
        std::fs::write(&paths[10], [7]).unwrap();
        let err = load_raw_slices(&paths, &spec).unwrap_err();
        assert!(
            matches!(err, VolumeError::TooShort { expected: 2, actual: 1, ref path } if *path == paths[10]),
            "{err}"
        );
        assert!(matches!(
            load_raw_slices(&[], &spec),
            Err(VolumeError::NoSlices { .. })
        ));
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn slice_stack_with_a_missing_slice_is_an_error() {
        let dir = scratch("gap");
        write_slices(&dir, "head", 0, (1..=3).chain(5..=6));
        let err = slice_stack(&dir.join("head.1")).unwrap_err();
        match &err {
            VolumeError::MissingSlice { path, later } => {
                assert_eq!((path, later), (&dir.join("head.4"), &dir.join("head.5")));
            }
            other => panic!("expected a missing slice, got {other}"),
        }
        assert!(err.to_string().contains("head.4"), "{err}");
        write_slices(&dir, "pad", 3, 8..=12);
        let padded = slice_stack(&dir.join("pad.008")).unwrap();
        assert_eq!(padded.last().unwrap(), &dir.join("pad.012"));
        assert!(matches!(
            slice_stack(&dir.join("head")),
            Err(VolumeError::NotNumbered { .. })
        ));
        assert!(matches!(
            slice_stack(&dir.join("head.7")),
            Err(VolumeError::Io { .. })
        ));
        std::fs::create_dir(dir.join("sub.1")).unwrap();
        assert!(matches!(
            slice_stack(&dir.join("sub.1")),
            Err(VolumeError::Io { .. })
        ));
        std::fs::remove_dir_all(dir).ok();
    }
}
