//! MetaImage volumes (ITK's and 3D Slicer's everyday format): `.mha` with the data after the
//! header in the same file, or `.mhd` naming a data file.
//!
//! The header is `Key = Value` lines ending with `ElementDataFile`, which must come last.
//! Read: `NDims = 3`; `DimSize`; `ElementType` (`MET_CHAR`, `MET_UCHAR`, `MET_SHORT`,
//! `MET_USHORT`, `MET_INT`, `MET_UINT`, `MET_FLOAT`, `MET_DOUBLE`); `ElementSpacing` (else
//! `ElementSize`, else 1); `Offset` (or `Position`, `Origin`); `TransformMatrix` (or
//! `Rotation`, `Orientation`): nine numbers, each three the direction of one index axis, as ITK
//! writes them; `BinaryDataByteOrderMSB` (or `ElementByteOrderMSB`); `CompressedData` (a zlib
//! stream that must inflate to exactly the declared values); `ElementNumberOfChannels` (1
//! only); `HeaderSize` (bytes to skip in a data file, `-1`: the data end the file);
//! `ElementDataFile` = `LOCAL`, one file name (relative to the header's folder), `LIST` (or
//! `LIST 2D`) with one slice file per line after it, or a file pattern `name%03d.raw min max
//! step`, one slice file per number; slice files hold `HeaderSize` bytes then one z slice.
//!
//! **World frame.** ITK's physical space, which MetaImage files hold, is LPS (as DICOM's): the
//! x and y components of the origin and of the axis directions change sign on the way to this
//! project's RAS. `AnatomicalOrientation` only describes the axes and is not used, as in ITK.
//!
//! Not read (a typed [`VolumeError::Unsupported`]): other dimensions than 3, vector pixels,
//! 64-bit integers, lists of 3-D files, compressed slice files, and ASCII data
//! (`BinaryData = False`).

use std::io::{BufReader, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use flate2::read::ZlibDecoder;
use glam::DVec3;

use super::loader::{
    LoadedVolume, Placement, VolumeFormat, expect_end, format_pattern, header_error,
    inflate_values, io_error, read_head, unsupported,
};
use super::loader::{check_data_files, checked_voxels};
use super::{
    ByteOrder, CpuVolume, RawSpec, ScalarFormat, ScalarType, VolumeError, Voxels, load_raw,
    load_raw_slices,
};

/// Longest header read; real ones are well under a kilobyte.
const HEADER_CAP: u64 = 64 << 10;

/// Whether the start of a file is a MetaImage header: its first key is one MetaIO writes first.
pub(super) fn is_metaimage(head: &[u8]) -> bool {
    let start = head
        .iter()
        .position(|b| !b.is_ascii_whitespace())
        .unwrap_or(0);
    let first = &head[start..];
    ["ObjectType", "NDims", "Comment", "ObjectSubType"]
        .iter()
        .any(|key| {
            first.starts_with(key.as_bytes())
                && first[key.len()..]
                    .iter()
                    .find(|b| !b.is_ascii_whitespace() || **b == b'\n')
                    .is_some_and(|b| *b == b'=')
        })
}

/// Loads a MetaImage volume.
pub fn load_metaimage(path: &Path) -> Result<LoadedVolume, VolumeError> {
    let header = Header::read(path)?;
    let format = ScalarFormat {
        scalar: header.scalar,
        order: header.order,
    };
    let count = checked_voxels(path, header.dims, header.scalar)?;
    let bytes = count
        .checked_mul(header.scalar.size() as u64)
        .ok_or_else(|| header_error(path, "declared size overflows"))?;
    let (file, start) = match &header.data {
        Data::Local => (path.to_path_buf(), Some(header.data_offset)),
        Data::Slices(files) => {
            check_data_files(path, files)?;
            if header.compressed {
                return Err(unsupported(path, "compressed slice files"));
            }
            let Some(skip) = header.header_size else {
                return Err(unsupported(path, "HeaderSize = -1 with slice files"));
            };
            let spec = RawSpec {
                header_bytes: skip,
                ..RawSpec::new(header.dims, header.scalar, header.order)
            };
            let values = load_raw_slices(files, &spec)?.values;
            return finish(path, &header, values);
        }
        Data::File(file) => {
            check_data_files(path, std::slice::from_ref(file))?;
            (file.clone(), header.header_size)
        }
    };
    let values = if header.compressed {
        let mut f = crate::input::open_regular(&file).map_err(io_error(&file))?;
        f.seek(SeekFrom::Start(start.unwrap_or(0)))
            .map_err(io_error(&file))?;
        let mut reader = ZlibDecoder::new(BufReader::new(f));
        let total = usize::try_from(count).map_err(|_| header_error(path, "too many voxels"))?;
        let mut values = Voxels::new(format.scalar);
        inflate_values(&file, &mut reader, bytes, format, total, &mut values)?;
        expect_end(&file, &mut reader, bytes)?;
        values
    } else {
        let header_bytes = match start {
            Some(skip) => skip,
            // `HeaderSize = -1`: the data are the file's last bytes.
            None => {
                let len = std::fs::metadata(&file).map_err(io_error(&file))?.len();
                len.checked_sub(bytes).ok_or(VolumeError::TooShort {
                    path: file.clone(),
                    expected: bytes,
                    actual: len,
                })?
            }
        };
        let spec = RawSpec {
            header_bytes,
            ..RawSpec::new(header.dims, header.scalar, header.order)
        };
        load_raw(&file, &spec)?.values
    };
    finish(path, &header, values)
}

/// The volume of `values`, placed as the header says.
fn finish(path: &Path, header: &Header, values: Voxels) -> Result<LoadedVolume, VolumeError> {
    // LPS to RAS: x and y change sign.
    let flip = DVec3::new(-1.0, -1.0, 1.0);
    let columns = [0, 1, 2].map(|i| header.axes[i] * flip * header.spacing[i]);
    let placement = Placement::from_columns(path, columns, header.offset * flip)?;
    let volume = CpuVolume {
        dims: header.dims,
        spacing: [1.0; 3],
        origin: [0.0; 3],
        direction: glam::DMat3::IDENTITY,
        values,
    };
    Ok(LoadedVolume {
        volume: placement.apply(volume),
        format: VolumeFormat::MetaImage,
        scalar_type: Some(header.scalar),
        patient_frame: true,
    })
}

/// Where a MetaImage's data are.
enum Data {
    /// After the header (`LOCAL`).
    Local,
    /// In one file.
    File(PathBuf),
    /// One file per z slice (`LIST` or a file pattern), in order.
    Slices(Vec<PathBuf>),
}

/// What the header says.
struct Header {
    dims: [u32; 3],
    scalar: ScalarType,
    order: ByteOrder,
    spacing: [f64; 3],
    offset: DVec3,
    /// Each index axis's direction (LPS), unit length not required.
    axes: [DVec3; 3],
    compressed: bool,
    /// Where the data are.
    data: Data,
    /// Where `LOCAL` data start.
    data_offset: u64,
    /// Bytes to skip in a data file; `None` for `-1`.
    header_size: Option<u64>,
}

impl Header {
    fn read(path: &Path) -> Result<Self, VolumeError> {
        let head = read_head(path, HEADER_CAP)?;
        let mut keys: Vec<(String, String, usize)> = Vec::new();
        let mut at = 0usize;
        let mut data_offset = None;
        for (number, line) in head.split_inclusive(|b| *b == b'\n').enumerate() {
            at += line.len();
            let text = std::str::from_utf8(line)
                .map_err(|_| header_error(path, format!("line {}: not text", number + 1)))?
                .trim();
            if text.is_empty() {
                continue;
            }
            let (key, value) = text.split_once('=').ok_or_else(|| {
                header_error(
                    path,
                    format!("line {}: {text:?} is not `Key = Value`", number + 1),
                )
            })?;
            let key = key.trim().to_owned();
            if let Some((_, _, first)) = keys.iter().find(|(k, _, _)| k.eq_ignore_ascii_case(&key))
            {
                return Err(header_error(
                    path,
                    format!(
                        "line {}: {key} given twice (first on line {first})",
                        number + 1
                    ),
                ));
            }
            let last = key == "ElementDataFile";
            keys.push((key, value.trim().to_owned(), number + 1));
            if last {
                data_offset = Some(at as u64);
                break;
            }
        }
        let data_offset = data_offset.ok_or_else(|| {
            header_error(
                path,
                format!("no ElementDataFile line in the first {HEADER_CAP} bytes"),
            )
        })?;
        let get = |names: &[&str]| {
            keys.iter()
                .find(|(k, _, _)| names.iter().any(|n| k.eq_ignore_ascii_case(n)))
                .map(|(k, v, line)| (k.as_str(), v.as_str(), *line))
        };
        let numbers = |names: &[&str], count: usize| -> Result<Option<Vec<f64>>, VolumeError> {
            let Some((key, value, line)) = get(names) else {
                return Ok(None);
            };
            let parsed: Option<Vec<f64>> =
                value.split_whitespace().map(|w| w.parse().ok()).collect();
            match parsed {
                Some(v) if v.len() == count && v.iter().all(|x| x.is_finite()) => Ok(Some(v)),
                _ => Err(header_error(
                    path,
                    format!("line {line}: {key} needs {count} finite numbers, not {value:?}"),
                )),
            }
        };
        let flag = |names: &[&str]| -> Result<bool, VolumeError> {
            match get(names) {
                None => Ok(false),
                Some((_, v, _)) if v.eq_ignore_ascii_case("true") || v == "1" => Ok(true),
                Some((_, v, _)) if v.eq_ignore_ascii_case("false") || v == "0" => Ok(false),
                Some((key, v, line)) => Err(header_error(
                    path,
                    format!("line {line}: {key} is {v:?}, not True or False"),
                )),
            }
        };
        if let Some((_, v, _)) = get(&["ObjectType"])
            && !v.eq_ignore_ascii_case("Image")
        {
            return Err(unsupported(path, format!("MetaIO object {v}")));
        }
        match numbers(&["NDims"], 1)? {
            Some(n) if n[0] == 3.0 => {}
            Some(n) => {
                return Err(unsupported(
                    path,
                    format!("{}-D MetaImage; only 3-D volumes are read", n[0]),
                ));
            }
            None => return Err(header_error(path, "no NDims line")),
        }
        if let Some(channels) = numbers(&["ElementNumberOfChannels"], 1)?
            && channels[0] != 1.0
        {
            return Err(unsupported(path, "more than one channel per voxel"));
        }
        if get(&["BinaryData"]).is_some() && !flag(&["BinaryData"])? {
            return Err(unsupported(path, "ASCII data (BinaryData = False)"));
        }
        let dims =
            numbers(&["DimSize"], 3)?.ok_or_else(|| header_error(path, "no DimSize line"))?;
        if dims
            .iter()
            .any(|d| d.fract() != 0.0 || *d < 1.0 || *d > f64::from(u32::MAX))
        {
            return Err(header_error(
                path,
                format!("DimSize {dims:?} must be positive whole numbers"),
            ));
        }
        let dims = [dims[0] as u32, dims[1] as u32, dims[2] as u32];
        let (type_key, type_name, type_line) =
            get(&["ElementType"]).ok_or_else(|| header_error(path, "no ElementType line"))?;
        let scalar = match type_name {
            "MET_CHAR" => ScalarType::I8,
            "MET_UCHAR" => ScalarType::U8,
            "MET_SHORT" => ScalarType::I16,
            "MET_USHORT" => ScalarType::U16,
            "MET_INT" | "MET_LONG" => ScalarType::I32,
            "MET_UINT" | "MET_ULONG" => ScalarType::U32,
            "MET_FLOAT" => ScalarType::F32,
            "MET_DOUBLE" => ScalarType::F64,
            "MET_LONG_LONG" | "MET_ULONG_LONG" => {
                return Err(unsupported(path, format!("ElementType {type_name}")));
            }
            other if other.ends_with("_ARRAY") => {
                return Err(unsupported(path, format!("vector pixels ({other})")));
            }
            other => {
                return Err(header_error(
                    path,
                    format!("line {type_line}: unknown {type_key} {other:?}"),
                ));
            }
        };
        let order = if flag(&["BinaryDataByteOrderMSB", "ElementByteOrderMSB"])? {
            ByteOrder::Big
        } else {
            ByteOrder::Little
        };
        let spacing = numbers(&["ElementSpacing"], 3)?
            .or(numbers(&["ElementSize"], 3)?)
            .unwrap_or(vec![1.0; 3]);
        let offset = numbers(&["Offset", "Position", "Origin"], 3)?.unwrap_or(vec![0.0; 3]);
        let matrix = numbers(&["TransformMatrix", "Rotation", "Orientation"], 9)?
            .unwrap_or(vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
        let axes =
            [0, 1, 2].map(|i| DVec3::new(matrix[3 * i], matrix[3 * i + 1], matrix[3 * i + 2]));
        if axes.iter().any(|a| a.length() < 1e-12) {
            return Err(header_error(path, "TransformMatrix has a zero axis"));
        }
        let axes = axes.map(DVec3::normalize);
        let header_size = match get(&["HeaderSize"]) {
            None => Some(0),
            Some((_, "-1", _)) => None,
            Some((key, v, line)) => Some(v.parse::<u64>().map_err(|_| {
                header_error(
                    path,
                    format!("line {line}: {key} {v:?} is not a byte count (or -1)"),
                )
            })?),
        };
        let (_, file, line) =
            get(&["ElementDataFile"]).ok_or_else(|| header_error(path, "no ElementDataFile"))?;
        let folder = path.parent().unwrap_or(Path::new(""));
        // The grid's size and memory first: no list is read and no name built for a grid
        // that would be refused.
        checked_voxels(path, dims, scalar)?;
        let words: Vec<&str> = file.split_whitespace().collect();
        let data = match words.as_slice() {
            [local] if local.eq_ignore_ascii_case("local") => Data::Local,
            [list, rest @ ..] if *list == "LIST" => {
                if !matches!(rest, [] | ["2D" | "2d"]) {
                    return Err(unsupported(
                        path,
                        format!("ElementDataFile {file:?}: lists of 2-D slices are read"),
                    ));
                }
                Data::Slices(list_files(path, folder, data_offset, dims[2])?)
            }
            [pattern, min, max, step] => {
                let range: Option<Vec<i64>> =
                    [min, max, step].iter().map(|w| w.parse().ok()).collect();
                let bad = |why: &str| {
                    header_error(path, format!("line {line}: file pattern {file:?}: {why}"))
                };
                let range = range.ok_or_else(|| bad("min, max and step must be whole numbers"))?;
                let (min, max, step) = (range[0], range[1], range[2]);
                let count = max
                    .checked_sub(min)
                    .and_then(|span| span.checked_div(step))
                    .and_then(|n| n.checked_add(1))
                    .filter(|&n| n >= 1);
                if count != Some(i64::from(dims[2])) {
                    let named = count.map_or("no whole number of".into(), |n| n.to_string());
                    return Err(bad(&format!(
                        "names {named} files for the {} slices of DimSize",
                        dims[2]
                    )));
                }
                (0..i64::from(dims[2]))
                    .map(|k| {
                        format_pattern(pattern, min + k * step)
                            .map(|name| folder.join(name))
                            .ok_or_else(|| bad("it needs one %d conversion"))
                    })
                    .collect::<Result<_, _>>()
                    .map(Data::Slices)?
            }
            [] => {
                return Err(header_error(
                    path,
                    format!("line {line}: ElementDataFile is empty"),
                ));
            }
            // A single name, which may hold spaces.
            _ => Data::File(folder.join(file)),
        };
        Ok(Self {
            dims,
            scalar,
            order,
            spacing: [spacing[0], spacing[1], spacing[2]],
            offset: DVec3::new(offset[0], offset[1], offset[2]),
            axes,
            compressed: flag(&["CompressedData"])?,
            data,
            data_offset,
            header_size,
        })
    }
}

/// Longest header read for a `LIST` of slice files: thousands of names.
const LIST_CAP: u64 = 4 << 20;

/// The `count` file names listed after the header's last line (which ends at byte `after`),
/// one per line, relative to `folder`.
fn list_files(
    path: &Path,
    folder: &Path,
    after: u64,
    count: u32,
) -> Result<Vec<PathBuf>, VolumeError> {
    let text = read_head(path, LIST_CAP)?;
    let rest = text.get(after as usize..).unwrap_or_default();
    let rest = std::str::from_utf8(rest)
        .map_err(|_| header_error(path, "the LIST of slice files is not text"))?;
    let names: Vec<&str> = rest
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .take(count as usize + 1)
        .collect();
    if names.len() != count as usize {
        let got = if names.len() > count as usize {
            format!("more than {count}")
        } else {
            names.len().to_string()
        };
        return Err(header_error(
            path,
            format!("ElementDataFile LIST names {got} files for the {count} slices of DimSize"),
        ));
    }
    Ok(names.iter().map(|n| folder.join(n)).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::loader::tests::scratch;

    const HEAD: &str = "ObjectType = Image\nNDims = 3\nDimSize = 2 2 1\nElementType = MET_UCHAR\n";

    fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        path
    }

    #[test]
    fn bad_headers_and_data_are_errors_naming_the_file_and_key() {
        let dir = scratch("metaimage");
        let local = |head: &str, data: &[u8]| {
            let mut bytes = head.as_bytes().to_vec();
            bytes.extend(b"ElementDataFile = LOCAL\n");
            bytes.extend(data);
            bytes
        };
        let good = write(&dir, "good.mha", &local(HEAD, &[1, 2, 3, 4]));
        assert!(is_metaimage(&std::fs::read(&good).unwrap()));
        let v = load_metaimage(&good).unwrap().volume;
        assert_eq!(v.values, [1.0, 2.0, 3.0, 4.0]);
        // Big-endian shorts, and a data file whose header is skipped.
        let msb = "ObjectType = Image\nNDims = 3\nDimSize = 2 1 1\nElementType = MET_SHORT\nElementByteOrderMSB = True\nHeaderSize = 3\nElementDataFile = data.bin\n";
        write(&dir, "data.bin", &[9, 9, 9, 0x01, 0x02, 0xff, 0xfe]);
        let v = load_metaimage(&write(&dir, "msb.mhd", msb.as_bytes()))
            .unwrap()
            .volume;
        assert_eq!(v.values, [258.0, -2.0]);
        let tail = msb.replace("HeaderSize = 3", "HeaderSize = -1");
        let v = load_metaimage(&write(&dir, "tail.mhd", tail.as_bytes()))
            .unwrap()
            .volume;
        assert_eq!(v.values, [258.0, -2.0]);
        for (name, bytes, expected) in [
            ("short.mha", local(HEAD, &[1, 2]), "short.mha"),
            (
                "two.mha",
                local(&HEAD.replace("NDims = 3", "NDims = 2"), &[0; 4]),
                "2-D",
            ),
            (
                "type.mha",
                local(&HEAD.replace("MET_UCHAR", "MET_COMPLEX"), &[0; 4]),
                "unknown ElementType",
            ),
            (
                "dims.mha",
                local(&HEAD.replace("2 2 1", "2 0 1"), &[0; 4]),
                "DimSize",
            ),
            (
                "nan.mha",
                local(&format!("{HEAD}ElementSpacing = 1 nan 1\n"), &[0; 4]),
                "ElementSpacing needs 3 finite numbers",
            ),
            ("none.mha", HEAD.as_bytes().to_vec(), "no ElementDataFile"),
            (
                "list.mhd",
                format!("{HEAD}ElementDataFile = LIST\n").into_bytes(),
                "LIST names 0 files for the 1 slices",
            ),
            (
                "list3d.mhd",
                format!("{HEAD}ElementDataFile = LIST 3D\na.raw\n").into_bytes(),
                "lists of 2-D slices",
            ),
            (
                "listgone.mhd",
                format!("{HEAD}ElementDataFile = LIST\nmissing-slice.raw\n").into_bytes(),
                "missing-slice.raw",
            ),
            (
                "pattern.mhd",
                format!("{HEAD}ElementDataFile = s%d.raw 1 5 1\n").into_bytes(),
                "names 5 files for the 1 slices",
            ),
            (
                "pattern2.mhd",
                format!("{HEAD}ElementDataFile = s%s.raw 1 1 1\n").into_bytes(),
                "one %d",
            ),
            (
                "gone.mhd",
                format!("{HEAD}ElementDataFile = gone.raw\n").into_bytes(),
                "gone.raw",
            ),
            (
                "zero.mha",
                local(
                    &format!("{HEAD}TransformMatrix = 0 0 0 0 1 0 0 0 1\n"),
                    &[0; 4],
                ),
                "zero axis",
            ),
            (
                "zlib.mha",
                local(&format!("{HEAD}CompressedData = True\n"), &[1, 2, 3, 4]),
                "zlib.mha",
            ),
        ] {
            let path = write(&dir, name, &bytes);
            let e = load_metaimage(&path).unwrap_err().to_string();
            assert!(e.contains(expected), "{name}: {e}");
        }
        std::fs::remove_dir_all(dir).ok();
    }
}
