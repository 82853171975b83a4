//! NIfTI-1 volumes (`.nii`, and `.nii.gz` told by its gzip magic), through the `nifti` crate's
//! header parser; the voxel data are read here so that their size is checked first.
//!
//! **Values.** Every integer type up to 32 bits, `float32` and `float64`, in the header's byte
//! order, converted to `f32` and then rescaled as `value * scl_slope + scl_inter` when
//! `scl_slope` is finite and not 0 (0 means "no scaling", as the standard says): Hounsfield
//! units for CT.
//!
//! **Placement.** NIfTI's world is RAS+ (+x right, +y anterior, +z superior), the same as this
//! project's, so coordinates are used as they are. With `sform_code > 0` the sform rows give the
//! voxel-to-world matrix: its columns' lengths are the spacing (equal to `pixdim` in consistent
//! files) and their unit vectors the direction, its last column the origin. Otherwise, with
//! `qform_code > 0`, the quaternion (`quatern_b/c/d`), `pixdim` and `qfac` (`pixdim[0]`) give
//! the rotation, spacing and a z flip, and `quatern_x/y/z` the origin. Otherwise `pixdim` alone
//! gives the spacing, with the identity orientation and the origin at 0. Lengths are in the
//! header's spatial unit (`xyzt_units`): metres and micrometres are turned to millimetres,
//! an unknown unit is taken as millimetres (as ITK does; nibabel leaves lengths as they are).
//!
//! **Sizes.** `dim` is checked against the grid limit ([`voxel_count`]: at most 2^32 voxels)
//! before anything is read. A plain `.nii` must hold `vox_offset` plus the declared values
//! (checked against its length, by [`load_raw`], before allocating); a `.nii.gz` stream must
//! inflate to exactly that many bytes, the output growing only as the data actually inflate.
//!
//! Not read (a typed [`VolumeError::Unsupported`]): NIfTI-2, `.hdr`/`.img` pairs, 4-D and
//! higher volumes with more than one 3-D frame, complex, RGB, 64-bit integer and 128-bit types.

use std::fs::File;
use std::io::{BufReader, Read};
use std::path::Path;

use flate2::read::MultiGzDecoder;
use glam::{DMat3, DQuat, DVec3};
use nifti::{Endianness, NiftiHeader, NiftiType};

use super::detect::{
    GZIP_MAGIC, LoadedVolume, Placement, VolumeFormat, expect_end, header_error, inflate_values,
    io_error, read_head, skip_inflated, unsupported,
};
use super::{ByteOrder, CpuVolume, RawSpec, ScalarFormat, ScalarType, VolumeError, load_raw};
use crate::grid::voxel_count;

/// Bytes of a NIfTI-1 header.
const HEADER_BYTES: u64 = 348;

/// Loads a NIfTI-1 volume, plain or gzip-compressed; of a 4-D file, its first frame (said on
/// stderr).
pub fn load_nifti(path: &Path) -> Result<LoadedVolume, VolumeError> {
    load_nifti_frame(path, None)
}

/// Loads frame `frame` (from 0) of a 4-D NIfTI-1 volume (`dim[4]` frames); `None` takes the
/// first and says so when there are others. A 3-D file has one frame, 0.
pub fn load_nifti_frame(path: &Path, frame: Option<u32>) -> Result<LoadedVolume, VolumeError> {
    let gz = read_head(path, 2)?.starts_with(&GZIP_MAGIC);
    let file = File::open(path).map_err(io_error(path))?;
    let mut reader: Box<dyn Read> = match gz {
        true => Box::new(MultiGzDecoder::new(BufReader::new(file))),
        false => Box::new(BufReader::new(file)),
    };
    let header = read_header(path, &mut reader)?;
    let mut layout = Layout::from_header(path, &header)?;
    let chosen = frame.unwrap_or(0);
    if chosen >= layout.frames {
        return Err(header_error(
            path,
            format!(
                "frame {chosen}: the file has {} frame{} (dim[4]), counted from 0",
                layout.frames,
                if layout.frames == 1 { "" } else { "s" }
            ),
        ));
    }
    if frame.is_none() && layout.frames > 1 {
        eprintln!(
            "{}: 4-D NIfTI with {} frames; frame 0 is drawn (frame = N in a scene file, --frame N on the command line, picks another)",
            path.display(),
            layout.frames
        );
    }
    layout.frame = chosen;
    let placement = placement(path, &header)?;
    let mut volume = match gz {
        true => layout.inflate(path, &mut reader)?,
        false => {
            // Every frame must be there, not only the one drawn.
            let expected = layout
                .frame_bytes(path)?
                .checked_mul(u64::from(layout.frames))
                .and_then(|b| b.checked_add(layout.vox_offset))
                .ok_or_else(|| header_error(path, "declared size overflows"))?;
            let actual = std::fs::metadata(path).map_err(io_error(path))?.len();
            if actual < expected {
                return Err(VolumeError::TooShort {
                    path: path.into(),
                    expected,
                    actual,
                });
            }
            load_raw(path, &layout.raw_spec(path)?)?
        }
    };
    rescale(&mut volume.values, header.scl_slope, header.scl_inter);
    Ok(LoadedVolume {
        volume: placement.apply(volume),
        format: VolumeFormat::Nifti,
        scalar_type: Some(layout.format.scalar),
    })
}

/// Where and how the voxel data are stored.
struct Layout {
    dims: [u32; 3],
    count: u64,
    format: ScalarFormat,
    vox_offset: u64,
    /// 3-D frames in the file (`dim[4]`), and the one to read.
    frames: u32,
    frame: u32,
}

impl Layout {
    fn from_header(path: &Path, header: &NiftiHeader) -> Result<Self, VolumeError> {
        if &header.magic != b"n+1\0" {
            return Err(unsupported(
                path,
                "a .hdr/.img pair; only single-file .nii is read",
            ));
        }
        let (dims, frames) = dims(path, &header.dim)?;
        let count = voxel_count(dims).map_err(|source| VolumeError::Grid {
            path: path.into(),
            source,
        })?;
        let order = match header.endianness {
            Endianness::Little => ByteOrder::Little,
            Endianness::Big => ByteOrder::Big,
        };
        let format = ScalarFormat {
            scalar: scalar_type(path, header)?,
            order,
        };
        Ok(Self {
            dims,
            count,
            format,
            vox_offset: vox_offset(path, header.vox_offset)?,
            frames,
            frame: 0,
        })
    }

    /// Bytes of one frame.
    fn frame_bytes(&self, path: &Path) -> Result<u64, VolumeError> {
        self.count
            .checked_mul(self.format.scalar.size() as u64)
            .ok_or_else(|| header_error(path, "declared size overflows"))
    }

    /// Where the chosen frame starts in the (inflated) file.
    fn frame_start(&self, path: &Path) -> Result<u64, VolumeError> {
        self.frame_bytes(path)?
            .checked_mul(u64::from(self.frame))
            .and_then(|b| b.checked_add(self.vox_offset))
            .ok_or_else(|| header_error(path, "declared size overflows"))
    }

    fn raw_spec(&self, path: &Path) -> Result<RawSpec, VolumeError> {
        Ok(RawSpec {
            header_bytes: self.frame_start(path)?,
            ..RawSpec::new(self.dims, self.format.scalar, self.format.order)
        })
    }

    /// Reads the values from a decompressing reader positioned just after the header.
    fn inflate(&self, path: &Path, reader: &mut dyn Read) -> Result<CpuVolume, VolumeError> {
        let bytes = self
            .count
            .checked_mul(self.format.scalar.size() as u64)
            .ok_or_else(|| header_error(path, "declared size overflows"))?;
        let count = usize::try_from(self.count)
            .map_err(|_| header_error(path, "declared size overflows"))?;
        let start = self.frame_start(path)?;
        skip_inflated(path, reader, start - HEADER_BYTES, bytes)?;
        let mut values = Vec::new();
        inflate_values(path, reader, bytes, self.format, count, &mut values)?;
        // The frames after this one must be there too, and nothing past them.
        let after = bytes
            .checked_mul(u64::from(self.frames - self.frame - 1))
            .ok_or_else(|| header_error(path, "declared size overflows"))?;
        let end = start + bytes + after;
        skip_inflated(path, reader, after, 0)?;
        expect_end(path, reader, end)?;
        Ok(CpuVolume {
            dims: self.dims,
            spacing: [1.0; 3],
            origin: [0.0; 3],
            direction: DMat3::IDENTITY,
            values,
        })
    }
}

/// `vox_offset`, a float for Analyze compatibility, as the whole byte count it must be.
fn vox_offset(path: &Path, offset: f32) -> Result<u64, VolumeError> {
    // The upper bound only keeps the conversion exact; no real file comes near it.
    if offset >= HEADER_BYTES as f32 && offset.fract() == 0.0 && offset < 1e15 {
        Ok(offset as u64)
    } else {
        let message = format!("vox_offset {offset} is not a byte offset past the header");
        Err(header_error(path, message))
    }
}

/// The NIfTI-1 header at the start of `reader`, which is left just after it.
fn read_header(path: &Path, reader: &mut dyn Read) -> Result<NiftiHeader, VolumeError> {
    let mut bytes = [0u8; HEADER_BYTES as usize];
    reader.read_exact(&mut bytes).map_err(|e| {
        header_error(
            path,
            format!("cannot read a {HEADER_BYTES}-byte NIfTI-1 header: {e}"),
        )
    })?;
    // The header size comes first, in the file's byte order.
    let size = i32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]);
    if size == 540 || size.swap_bytes() == 540 {
        return Err(unsupported(path, "NIfTI-2; only NIfTI-1 is read"));
    }
    if size != HEADER_BYTES as i32 && size.swap_bytes() != HEADER_BYTES as i32 {
        return Err(header_error(
            path,
            format!("header size {size} is not {HEADER_BYTES}"),
        ));
    }
    NiftiHeader::from_reader(&bytes[..])
        .map_err(|e| header_error(path, format!("not a NIfTI-1 header: {e}")))
}

/// The grid size from `dim`: `dim[0]` axes, missing ones of size 1, any past the third of
/// size 1 (a 4-D file with one frame is a 3-D volume).
/// The 3-D size and the number of 3-D frames (`dim[4]`).
fn dims(path: &Path, dim: &[u16; 8]) -> Result<([u32; 3], u32), VolumeError> {
    let rank = usize::from(dim[0]);
    if !(1..=7).contains(&rank) {
        return Err(header_error(
            path,
            format!("dim[0] = {} is not 1 to 7", dim[0] as i16),
        ));
    }
    // The standard stores dim as signed 16-bit numbers.
    let size = |i: usize| {
        if i <= rank {
            i32::from(dim[i] as i16)
        } else {
            1
        }
    };
    if let Some(i) = (1..=rank).find(|&i| size(i) <= 0) {
        return Err(header_error(
            path,
            format!("dim[{i}] = {} is not positive", size(i)),
        ));
    }
    if let Some(i) = (5..=rank).find(|&i| size(i) != 1) {
        return Err(unsupported(
            path,
            format!(
                "dim[{i}] = {}: volumes of 3-D frames (dim[4]) are read, not more dimensions",
                size(i)
            ),
        ));
    }
    Ok(([1, 2, 3].map(|i| size(i) as u32), size(4) as u32))
}

fn scalar_type(path: &Path, header: &NiftiHeader) -> Result<ScalarType, VolumeError> {
    let datatype = header
        .data_type()
        .map_err(|_| header_error(path, format!("unknown datatype {}", header.datatype)))?;
    Ok(match datatype {
        NiftiType::Uint8 => ScalarType::U8,
        NiftiType::Int8 => ScalarType::I8,
        NiftiType::Uint16 => ScalarType::U16,
        NiftiType::Int16 => ScalarType::I16,
        NiftiType::Uint32 => ScalarType::U32,
        NiftiType::Int32 => ScalarType::I32,
        NiftiType::Float32 => ScalarType::F32,
        NiftiType::Float64 => ScalarType::F64,
        other => return Err(unsupported(path, format!("datatype {other:?}"))),
    })
}

/// Applies `scl_slope` and `scl_inter`; a slope of 0 (or not finite) means none.
fn rescale(values: &mut [f32], slope: f32, inter: f32) {
    let inter = if inter.is_finite() {
        f64::from(inter)
    } else {
        0.0
    };
    if slope == 0.0 || !slope.is_finite() || (slope == 1.0 && inter == 0.0) {
        return;
    }
    let slope = f64::from(slope);
    for v in values {
        *v = (f64::from(*v) * slope + inter) as f32;
    }
}

/// Millimetres per unit of the header's spatial unit (`xyzt_units & 7`): metres 1000,
/// millimetres and unknown 1 (as ITK takes it), micrometres 0.001.
fn millimetres_per_unit(path: &Path, h: &NiftiHeader) -> Result<f64, VolumeError> {
    match h.xyzt_units & 0x07 {
        0 | 2 => Ok(1.0),
        1 => Ok(1000.0),
        3 => Ok(0.001),
        other => Err(header_error(
            path,
            format!(
                "xyzt_units spatial code {other} is none of 0 (unknown), 1 (m), 2 (mm), 3 (um)"
            ),
        )),
    }
}

/// The voxel-to-world placement: sform, else qform, else pixdim alone (see the module docs),
/// in millimetres whatever the header's spatial unit.
fn placement(path: &Path, h: &NiftiHeader) -> Result<Placement, VolumeError> {
    let mm = millimetres_per_unit(path, h)?;
    let pixdim = [1, 2, 3].map(|i| f64::from(h.pixdim[i]) * mm);
    if h.sform_code > 0 {
        let rows = [h.srow_x, h.srow_y, h.srow_z].map(|r| r.map(|x| f64::from(x) * mm));
        let column = |j: usize| DVec3::new(rows[0][j], rows[1][j], rows[2][j]);
        Placement::from_columns(path, [column(0), column(1), column(2)], column(3))
    } else if h.qform_code > 0 {
        let rotation = DMat3::from_quat(qform_quaternion(h));
        let qfac = if h.pixdim[0] < 0.0 { -1.0 } else { 1.0 };
        let steps = [pixdim[0], pixdim[1], pixdim[2] * qfac];
        let columns = [0, 1, 2].map(|i| rotation.col(i) * steps[i]);
        let origin = DVec3::new(h.quatern_x.into(), h.quatern_y.into(), h.quatern_z.into()) * mm;
        Placement::from_columns(path, columns, origin)
    } else {
        Placement::axis_aligned(path, pixdim, [0.0; 3])
    }
}

/// The qform rotation: `a` is implied by unit length; rounding that pushes `b² + c² + d²` past
/// 1 leaves `a = 0` and the rest normalised, as the NIfTI reference code does.
fn qform_quaternion(h: &NiftiHeader) -> DQuat {
    let [b, c, d] = [h.quatern_b, h.quatern_c, h.quatern_d].map(f64::from);
    let a = (1.0 - (b * b + c * c + d * d)).max(0.0).sqrt();
    let q = DQuat::from_xyzw(b, c, d, a);
    if q.is_finite() && q.length() > 0.0 {
        q.normalize()
    } else {
        DQuat::IDENTITY
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::detect::tests::{gzip, scratch};

    /// A little-endian NIfTI-1 header (352 bytes with the extension flag) for `dims` of
    /// `datatype`, unit pixdim, no transforms.
    fn header_bytes(dims: [i16; 3], datatype: i16, bitpix: i16) -> Vec<u8> {
        let mut h = vec![0u8; 352];
        h[0..4].copy_from_slice(&348i32.to_le_bytes());
        let dim = [3, dims[0], dims[1], dims[2], 1, 1, 1, 1];
        for (i, d) in dim.iter().enumerate() {
            h[40 + 2 * i..42 + 2 * i].copy_from_slice(&d.to_le_bytes());
        }
        h[70..72].copy_from_slice(&datatype.to_le_bytes());
        h[72..74].copy_from_slice(&bitpix.to_le_bytes());
        for i in 0..8 {
            h[76 + 4 * i..80 + 4 * i].copy_from_slice(&1f32.to_le_bytes());
        }
        h[108..112].copy_from_slice(&352f32.to_le_bytes());
        h[344..348].copy_from_slice(b"n+1\0");
        h
    }

    fn put_f32(h: &mut [u8], at: usize, values: &[f32]) {
        for (i, v) in values.iter().enumerate() {
            h[at + 4 * i..at + 4 * i + 4].copy_from_slice(&v.to_le_bytes());
        }
    }

    fn put_i16(h: &mut [u8], at: usize, v: i16) {
        h[at..at + 2].copy_from_slice(&v.to_le_bytes());
    }

    fn write(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        path
    }

    #[test]
    fn rescales_and_places_by_sform_then_qform_then_pixdim() {
        let dir = scratch("nifti");
        let mut bytes = header_bytes([2, 1, 2], 4, 16);
        put_f32(&mut bytes, 112, &[2.0, -1000.0]);
        put_f32(&mut bytes, 80, &[0.5, 0.5, 3.0]);
        bytes.extend([1i16, 2, -3, 500].iter().flat_map(|v| v.to_le_bytes()));
        let plain = load_nifti(&write(&dir, "p.nii", &bytes)).unwrap();
        assert_eq!(plain.volume.values, [-998.0, -996.0, -1006.0, 0.0]);
        assert_eq!(
            (plain.volume.spacing, plain.volume.direction),
            ([0.5, 0.5, 3.0], DMat3::IDENTITY)
        );
        assert_eq!(plain.scalar_type, Some(ScalarType::I16));
        // qform: 180 degrees about z (quaternion d = 1) with qfac -1 flips x, y and z.
        put_i16(&mut bytes, 252, 1);
        put_f32(&mut bytes, 256, &[0.0, 0.0, 1.0, 10.0, 20.0, 30.0]);
        put_f32(&mut bytes, 76, &[-1.0]);
        let q = load_nifti(&write(&dir, "q.nii.gz", &gzip(&bytes))).unwrap();
        assert_eq!(q.volume.values, plain.volume.values);
        assert_eq!(
            (q.volume.spacing, q.volume.origin),
            ([0.5, 0.5, 3.0], [10.0, 20.0, 30.0])
        );
        assert!(
            q.volume
                .direction
                .abs_diff_eq(DMat3::from_diagonal(DVec3::new(-1.0, -1.0, -1.0)), 1e-12)
        );
        // sform wins over qform: a shear-free matrix with axes permuted.
        put_i16(&mut bytes, 254, 2);
        put_f32(
            &mut bytes,
            280,
            &[0.0, 0.0, -2.0, 5.0, 1.5, 0.0, 0.0, 6.0, 0.0, 4.0, 0.0, 7.0],
        );
        let s = load_nifti(&write(&dir, "s.nii", &bytes)).unwrap();
        assert_eq!(
            (s.volume.spacing, s.volume.origin),
            ([1.5, 4.0, 2.0], [5.0, 6.0, 7.0])
        );
        assert_eq!(
            s.volume.direction,
            DMat3::from_cols(DVec3::Y, DVec3::Z, -DVec3::X)
        );
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn lengths_in_metres_or_micrometres_become_millimetres() {
        let dir = scratch("nifti-units");
        let mut bytes = header_bytes([2, 1, 2], 4, 16);
        put_f32(&mut bytes, 80, &[0.5, 0.25, 3.0]);
        // qform: a quarter turn about z, origin (10, 20, 30) in the file's unit.
        put_i16(&mut bytes, 252, 1);
        let d = std::f32::consts::FRAC_1_SQRT_2;
        put_f32(&mut bytes, 256, &[0.0, 0.0, d, 10.0, 20.0, 30.0]);
        bytes.extend([1i16, 2, 3, 4].iter().flat_map(|v| v.to_le_bytes()));
        for (units, mm) in [(0u8, 1.0), (2, 1.0), (1, 1000.0), (3, 0.001), (10, 1.0)] {
            // xyzt_units: the spatial code in the low 3 bits (10 = mm with seconds).
            bytes[123] = units;
            let v = load_nifti(&write(&dir, "u.nii", &bytes)).unwrap().volume;
            for (got, want) in v.spacing.iter().zip([0.5, 0.25, 3.0]) {
                assert!(
                    (got - want * mm).abs() < 1e-9 * mm,
                    "{units}: {:?}",
                    v.spacing
                );
            }
            for (got, want) in v.origin.iter().zip([10.0, 20.0, 30.0]) {
                assert!(
                    (got - want * mm).abs() < 1e-6 * mm,
                    "{units}: {:?}",
                    v.origin
                );
            }
            assert!(
                v.direction.col(0).abs_diff_eq(DVec3::Y, 1e-6),
                "the turn stays"
            );
        }
        // The sform too.
        put_i16(&mut bytes, 254, 1);
        put_f32(
            &mut bytes,
            280,
            &[
                0.002, 0.0, 0.0, 0.1, 0.0, 0.003, 0.0, 0.2, 0.0, 0.0, 0.004, 0.3,
            ],
        );
        bytes[123] = 1;
        let v = load_nifti(&write(&dir, "m.nii", &bytes)).unwrap().volume;
        assert!(
            v.spacing
                .iter()
                .zip([2.0, 3.0, 4.0])
                .all(|(a, b)| (a - b).abs() < 1e-4),
            "{:?}",
            v.spacing
        );
        assert!((v.origin[2] - 300.0).abs() < 1e-3, "{:?}", v.origin);
        bytes[123] = 5;
        let e = load_nifti(&write(&dir, "x.nii", &bytes))
            .unwrap_err()
            .to_string();
        assert!(e.contains("xyzt_units"), "{e}");
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn bad_headers_and_sizes_are_typed_errors() {
        let dir = scratch("nifti-bad");
        let data = [0u8; 16];
        let with = |mut h: Vec<u8>, edit: &dyn Fn(&mut Vec<u8>)| {
            edit(&mut h);
            h.extend(data);
            h
        };
        let base = header_bytes([2, 2, 2], 2, 8);
        let cases: Vec<(&str, Vec<u8>, &str)> = vec![
            (
                "type.nii",
                with(base.clone(), &|h| put_i16(h, 70, 1536)),
                "datatype",
            ),
            (
                "unknown.nii",
                with(base.clone(), &|h| put_i16(h, 70, 3)),
                "unknown datatype 3",
            ),
            (
                // Three frames of 8 bytes declared, two there.
                "4d.nii",
                with(base.clone(), &|h| {
                    put_i16(h, 40, 4);
                    put_i16(h, 48, 3)
                }),
                "bytes",
            ),
            (
                "5d.nii",
                with(base.clone(), &|h| {
                    put_i16(h, 40, 5);
                    put_i16(h, 50, 2)
                }),
                "not more dimensions",
            ),
            (
                "neg.nii",
                with(base.clone(), &|h| put_i16(h, 44, -2)),
                "not positive",
            ),
            (
                "offset.nii",
                with(base.clone(), &|h| put_f32(h, 108, &[100.0])),
                "vox_offset",
            ),
            (
                "pair.nii",
                with(base.clone(), &|h| h[344..348].copy_from_slice(b"ni1\0")),
                ".hdr/.img",
            ),
            (
                "short.nii",
                with(base.clone(), &|h| put_i16(h, 46, 6)),
                "needs 376 bytes",
            ),
            (
                "huge.nii",
                with(base.clone(), &|h| {
                    for i in 1..4 {
                        put_i16(h, 40 + 2 * i, 32767)
                    }
                }),
                "declared grid size",
            ),
            (
                "flat.nii",
                with(base.clone(), &|h| put_f32(h, 80, &[0.0])),
                "spacing",
            ),
            ("trunc.nii", base[..200].to_vec(), "cannot read a 348-byte"),
            (
                "two.nii",
                with(base.clone(), &|h| {
                    h[..4].copy_from_slice(&540i32.to_le_bytes())
                }),
                "NIfTI-2",
            ),
            (
                "magic.nii",
                with(base.clone(), &|h| h[344..348].copy_from_slice(b"xyz\0")),
                "not a NIfTI-1 header",
            ),
        ];
        for (name, bytes, expected) in cases {
            let err = load_nifti(&write(&dir, name, &bytes))
                .unwrap_err()
                .to_string();
            assert!(
                err.contains(expected) && err.contains(name),
                "{name}: {err}"
            );
        }
        let mut long = base.clone();
        long.extend([0u8; 9]);
        let err = load_nifti(&write(&dir, "long.nii.gz", &gzip(&long))).unwrap_err();
        assert!(
            matches!(err, VolumeError::InflatesPast { declared: 360, .. }),
            "{err}"
        );
        let mut short = base.clone();
        short.extend([0u8; 7]);
        let err = load_nifti(&write(&dir, "short.nii.gz", &gzip(&short))).unwrap_err();
        assert!(
            matches!(
                err,
                VolumeError::InflatesShort {
                    expected: 8,
                    actual: 7,
                    ..
                }
            ),
            "{err}"
        );
        std::fs::remove_dir_all(dir).ok();
    }
}
