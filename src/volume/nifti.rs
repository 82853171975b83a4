//! NIfTI-1 and NIfTI-2 volumes (`.nii`, `.nii.gz` told by its gzip magic, and `.hdr`/`.img`
//! pairs), and Analyze 7.5 (`.hdr`/`.img`), whose 348-byte header NIfTI-1 extends.
//!
//! The headers are read here, field by field at the offsets the standards give, rather than
//! through the `nifti` crate: that crate reads NIfTI-1 only, and the three layouts share every
//! step after the fields are known.
//!
//! **Values.** Every integer type up to 32 bits, `float32` and `float64`, in the header's byte
//! order (told by the header size, 348 or 540, read in either order), converted to `f32` and
//! then rescaled as `value * scl_slope + scl_inter` when `scl_slope` is finite and not 0 (0
//! means "no scaling", as the standard says): Hounsfield units for CT. Analyze has no scaling
//! fields (SPM's use of `funused1` is not read, as ITK does not).
//!
//! **Placement.** NIfTI's world is RAS+ (+x right, +y anterior, +z superior), the same as this
//! project's, so coordinates are used as they are. By default ([`NiftiTransform::Sform`], as
//! nibabel does), with `sform_code > 0` the sform rows give the voxel-to-world matrix: its
//! columns' lengths are the spacing (equal to `pixdim` in consistent files) and their unit
//! vectors the direction, its last column the origin. Otherwise, with `qform_code > 0`, the
//! quaternion (`quatern_b/c/d`), `pixdim` and `qfac` (`pixdim[0]`) give the rotation, spacing
//! and a z flip, and `quatern_x/y/z` the origin. Otherwise `pixdim` alone gives the spacing,
//! with the identity orientation and the origin at 0. [`NiftiTransform::Qform`] tries the
//! qform first; [`NiftiTransform::Itk`] takes the sform only when its code is 1 (scanner
//! anatomical) or there is no qform, as ITK 5 (SimpleITK, 3D Slicer) does. Lengths are in the header's spatial unit (`xyzt_units`): metres
//! and micrometres are turned to millimetres, an unknown unit is taken as millimetres (as ITK
//! does; nibabel leaves lengths as they are).
//!
//! **Analyze 7.5** has no orientation: the grid is placed as nibabel places it, the x axis
//! flipped (Analyze's radiological storage: +i toward the patient's left) and the origin
//! at minus the grid's centre, `-(dim - 1) / 2 * pixdim` per axis with x's sign reversed, so
//! that the grid's centre sits at the world origin.
//!
//! **Sizes.** `dim` is checked against the grid limit (at most 2^32 voxels) and the memory budget
//! before anything is read. A plain file must hold `vox_offset` plus every declared frame
//! (checked against its length before allocating); a `.nii.gz` stream must inflate to exactly
//! that many bytes, the output growing only as the data actually inflate.
//!
//! Not read (a typed [`VolumeError::Unsupported`]): volumes with more dimensions than 3-D
//! frames (`dim[4]`), complex, RGB, 64-bit integer and 128-bit types, and compressed pairs
//! (`.hdr.gz`/`.img.gz`).

use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};

use flate2::read::MultiGzDecoder;
use glam::{DMat3, DQuat, DVec3};

use super::loader::checked_voxels;
use super::loader::{
    GZIP_MAGIC, LoadedVolume, NiftiTransform, Placement, VolumeFormat, expect_end, header_error,
    inflate_values, io_error, read_head, skip_inflated, unsupported,
};
use super::voxels::{Voxel, dispatch};
use super::{
    ByteOrder, CpuVolume, RawSpec, ScalarFormat, ScalarType, VolumeError, Voxels, load_raw,
};

/// Bytes of a NIfTI-1 (and Analyze 7.5) header.
const NIFTI1_BYTES: usize = 348;
/// Bytes of a NIfTI-2 header.
const NIFTI2_BYTES: usize = 540;

/// Whether `head` (a file's first bytes) starts with a NIfTI-1 or NIfTI-2 header.
pub(super) fn is_nifti(head: &[u8]) -> bool {
    let nifti1 = matches!(head.get(344..348), Some(b"n+1\0" | b"ni1\0"));
    nifti1 || matches!(head.get(4..8), Some(b"n+2\0" | b"ni2\0"))
}

/// Whether `head` is an Analyze 7.5 header: 348 bytes declared in either byte order, no NIfTI
/// magic, 1 to 7 dimensions and a data type Analyze defines.
pub(super) fn is_analyze(head: &[u8]) -> bool {
    if head.len() < NIFTI1_BYTES || is_nifti(head) {
        return false;
    }
    let Some(order) = order_from_size(head, NIFTI1_BYTES as i32) else {
        return false;
    };
    let fields = Fields { bytes: head, order };
    (1..=7).contains(&fields.i16(40)) && matches!(fields.i16(70), 2 | 4 | 8 | 16 | 64)
}

/// The byte order in which the header size at the start of `bytes` reads `size`.
fn order_from_size(bytes: &[u8], size: i32) -> Option<ByteOrder> {
    let word: [u8; 4] = bytes.get(..4)?.try_into().ok()?;
    if i32::from_le_bytes(word) == size {
        Some(ByteOrder::Little)
    } else if i32::from_be_bytes(word) == size {
        Some(ByteOrder::Big)
    } else {
        None
    }
}

/// Loads a NIfTI volume, plain or gzip-compressed; of a 4-D file, its first frame (said on
/// stderr); placed by the sform first.
pub fn load_nifti(path: &Path) -> Result<LoadedVolume, VolumeError> {
    load_nifti_with(path, None, NiftiTransform::Sform)
}

/// Loads frame `frame` (from 0) of a 4-D NIfTI-1 volume (`dim[4]` frames); `None` takes the
/// first and says so when there are others. A 3-D file has one frame, 0.
pub fn load_nifti_frame(path: &Path, frame: Option<u32>) -> Result<LoadedVolume, VolumeError> {
    load_nifti_with(path, frame, NiftiTransform::Sform)
}

/// [`load_nifti_frame`], placed by the `transform` chosen.
pub fn load_nifti_with(
    path: &Path,
    frame: Option<u32>,
    transform: NiftiTransform,
) -> Result<LoadedVolume, VolumeError> {
    let gz = read_head(path, 2)?.starts_with(&GZIP_MAGIC);
    let file = crate::input::open_regular(path).map_err(io_error(path))?;
    let mut reader: Box<dyn Read> = match gz {
        true => Box::new(MultiGzDecoder::new(BufReader::new(file))),
        false => Box::new(BufReader::new(file)),
    };
    let header = Header::read(path, &mut reader, false)?;
    let placement = header.placement(path, transform)?;
    load_with_header(
        path,
        &header,
        reader,
        gz,
        frame,
        placement,
        VolumeFormat::Nifti,
    )
}

/// Loads an Analyze 7.5 volume from its `.hdr` (the data in the `.img` beside it).
pub fn load_analyze(path: &Path) -> Result<LoadedVolume, VolumeError> {
    let file = crate::input::open_regular(path).map_err(io_error(path))?;
    let mut reader: Box<dyn Read> = Box::new(BufReader::new(file));
    let header = Header::read(path, &mut reader, true)?;
    let placement = header.placement(path, NiftiTransform::Sform)?;
    let format = match header.kind {
        Kind::Analyze => VolumeFormat::Analyze,
        _ => VolumeFormat::Nifti,
    };
    load_with_header(path, &header, reader, false, None, placement, format)
}

/// The values of the chosen frame, placed, after the header has been read from `reader`.
fn load_with_header(
    path: &Path,
    header: &Header,
    mut reader: Box<dyn Read>,
    gz: bool,
    frame: Option<u32>,
    placement: Placement,
    format: VolumeFormat,
) -> Result<LoadedVolume, VolumeError> {
    let mut layout = Layout::from_header(path, header)?;
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
    let data = match &header.data_file {
        Some(img) => img.clone(),
        None => path.to_path_buf(),
    };
    let mut volume = if gz && header.data_file.is_none() {
        layout.inflate(path, &mut reader, header.bytes as u64)?
    } else {
        drop(reader);
        if read_head(&data, 2)?.starts_with(&GZIP_MAGIC) {
            return Err(unsupported(
                &data,
                "a gzip-compressed .img; decompress the pair first",
            ));
        }
        // Every frame must be there, not only the one drawn.
        let expected = layout
            .frame_bytes(path)?
            .checked_mul(u64::from(layout.frames))
            .and_then(|b| b.checked_add(layout.vox_offset))
            .ok_or_else(|| header_error(path, "declared size overflows"))?;
        let actual = std::fs::metadata(&data).map_err(io_error(&data))?.len();
        if actual < expected {
            return Err(VolumeError::TooShort {
                path: data,
                expected,
                actual,
            });
        }
        load_raw(&data, &layout.raw_spec(path)?)?
    };
    rescale(path, &mut volume.values, header.scl_slope, header.scl_inter)?;
    Ok(LoadedVolume {
        volume: placement.apply(volume),
        format,
        scalar_type: Some(layout.format.scalar),
        patient_frame: true,
    })
}

/// Which header layout a file has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Nifti1,
    Nifti2,
    Analyze,
}

/// Reads numbers at byte offsets of a header in its byte order.
struct Fields<'a> {
    bytes: &'a [u8],
    order: ByteOrder,
}

impl Fields<'_> {
    fn array<const N: usize>(&self, at: usize) -> [u8; N] {
        let mut word: [u8; N] = self.bytes[at..at + N]
            .try_into()
            .expect("within the header");
        if self.order == ByteOrder::Big {
            word.reverse();
        }
        word
    }
    fn i16(&self, at: usize) -> i16 {
        i16::from_le_bytes(self.array(at))
    }
    fn i32(&self, at: usize) -> i32 {
        i32::from_le_bytes(self.array(at))
    }
    fn i64(&self, at: usize) -> i64 {
        i64::from_le_bytes(self.array(at))
    }
    fn f32(&self, at: usize) -> f64 {
        f64::from(f32::from_le_bytes(self.array(at)))
    }
    fn f64(&self, at: usize) -> f64 {
        f64::from_le_bytes(self.array(at))
    }
}

/// The header fields this loader uses, widened to NIfTI-2's types.
struct Header {
    kind: Kind,
    /// Bytes of the header (348 or 540).
    bytes: usize,
    order: ByteOrder,
    dim: [i64; 8],
    datatype: i16,
    pixdim: [f64; 8],
    vox_offset: f64,
    scl_slope: f64,
    scl_inter: f64,
    xyzt_units: i32,
    qform_code: i32,
    sform_code: i32,
    /// quatern_b, c, d and qoffset_x, y, z.
    quatern: [f64; 6],
    srow: [[f64; 4]; 3],
    /// The `.img` of a pair; `None` when the data follow the header in the same file.
    data_file: Option<PathBuf>,
}

impl Header {
    /// The header at the start of `reader`, which is left just after it; a 348-byte header
    /// without NIfTI's magic is Analyze 7.5 where `analyze` allows it, else an error.
    fn read(path: &Path, reader: &mut dyn Read, analyze: bool) -> Result<Self, VolumeError> {
        let mut bytes = vec![0u8; NIFTI1_BYTES];
        reader
            .read_exact(&mut bytes[..4])
            .map_err(|e| header_error(path, format!("cannot read the header size: {e}")))?;
        let nifti2 = order_from_size(&bytes, NIFTI2_BYTES as i32).is_some();
        reader.read_exact(&mut bytes[4..]).map_err(|e| {
            let what = match nifti2 {
                true => format!("{NIFTI2_BYTES}-byte NIfTI-2"),
                false => format!("{NIFTI1_BYTES}-byte NIfTI-1 or Analyze"),
            };
            header_error(path, format!("cannot read a {what} header: {e}"))
        })?;
        if let Some(order) = order_from_size(&bytes, NIFTI2_BYTES as i32) {
            bytes.resize(NIFTI2_BYTES, 0);
            reader.read_exact(&mut bytes[NIFTI1_BYTES..]).map_err(|e| {
                header_error(
                    path,
                    format!("cannot read a {NIFTI2_BYTES}-byte NIfTI-2 header: {e}"),
                )
            })?;
            return Self::nifti2(path, &bytes, order);
        }
        let Some(order) = order_from_size(&bytes, NIFTI1_BYTES as i32) else {
            let size = i32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]);
            return Err(header_error(
                path,
                format!("header size {size} is neither {NIFTI1_BYTES} nor {NIFTI2_BYTES}"),
            ));
        };
        if !analyze && !is_nifti(&bytes) {
            return Err(header_error(
                path,
                format!(
                    "not a NIfTI-1 header: magic {:?} is not n+1 or ni1",
                    &bytes[344..348]
                ),
            ));
        }
        Self::nifti1(path, &bytes, order)
    }

    /// A NIfTI-1 or Analyze 7.5 header (the offsets of the NIfTI-1 standard, `nifti1.h`).
    fn nifti1(path: &Path, bytes: &[u8], order: ByteOrder) -> Result<Self, VolumeError> {
        let f = Fields { bytes, order };
        let (kind, pair) = match &bytes[344..348] {
            b"n+1\0" => (Kind::Nifti1, false),
            b"ni1\0" => (Kind::Nifti1, true),
            _ => (Kind::Analyze, true),
        };
        let analyze = kind == Kind::Analyze;
        let row = |at: usize| [0, 1, 2, 3].map(|i| f.f32(at + 4 * i));
        Ok(Self {
            kind,
            bytes: NIFTI1_BYTES,
            order,
            dim: [0, 1, 2, 3, 4, 5, 6, 7].map(|i| i64::from(f.i16(40 + 2 * i))),
            datatype: f.i16(70),
            pixdim: [0, 1, 2, 3, 4, 5, 6, 7].map(|i| f.f32(76 + 4 * i)),
            vox_offset: f.f32(108),
            scl_slope: if analyze { 0.0 } else { f.f32(112) },
            scl_inter: if analyze { 0.0 } else { f.f32(116) },
            xyzt_units: if analyze { 0 } else { i32::from(bytes[123]) },
            qform_code: if analyze { 0 } else { i32::from(f.i16(252)) },
            sform_code: if analyze { 0 } else { i32::from(f.i16(254)) },
            quatern: [0, 1, 2, 3, 4, 5].map(|i| f.f32(256 + 4 * i)),
            srow: [row(280), row(296), row(312)],
            data_file: if pair { Some(image_file(path)?) } else { None },
        })
    }

    /// A NIfTI-2 header (the offsets of `nifti2.h`).
    fn nifti2(path: &Path, bytes: &[u8], order: ByteOrder) -> Result<Self, VolumeError> {
        let f = Fields { bytes, order };
        let pair = match &bytes[4..8] {
            b"n+2\0" => false,
            b"ni2\0" => true,
            other => {
                return Err(header_error(
                    path,
                    format!("NIfTI-2 header size with the magic {other:?}, not n+2 or ni2"),
                ));
            }
        };
        let row = |at: usize| [0, 1, 2, 3].map(|i| f.f64(at + 8 * i));
        let vox_offset = f.i64(168);
        Ok(Self {
            kind: Kind::Nifti2,
            bytes: NIFTI2_BYTES,
            order,
            dim: [0, 1, 2, 3, 4, 5, 6, 7].map(|i| f.i64(16 + 8 * i)),
            datatype: f.i16(12),
            pixdim: [0, 1, 2, 3, 4, 5, 6, 7].map(|i| f.f64(104 + 8 * i)),
            // Exact for every offset a file can have (below 2^53).
            vox_offset: vox_offset as f64,
            scl_slope: f.f64(176),
            scl_inter: f.f64(184),
            xyzt_units: f.i32(500),
            qform_code: f.i32(344),
            sform_code: f.i32(348),
            quatern: [0, 1, 2, 3, 4, 5].map(|i| f.f64(352 + 8 * i)),
            srow: [row(400), row(432), row(464)],
            data_file: if pair { Some(image_file(path)?) } else { None },
        })
    }

    /// The voxel-to-world placement (see the module docs), in millimetres whatever the
    /// header's spatial unit.
    fn placement(&self, path: &Path, transform: NiftiTransform) -> Result<Placement, VolumeError> {
        let mm = millimetres_per_unit(path, self.xyzt_units)?;
        let pixdim = [1, 2, 3].map(|i| self.pixdim[i] * mm);
        if self.kind == Kind::Analyze {
            let dims = [1, 2, 3].map(|i| self.dim[i].max(1) as f64);
            let steps = [-pixdim[0], pixdim[1], pixdim[2]];
            let origin = DVec3::from([0, 1, 2].map(|i| -(dims[i] - 1.0) / 2.0 * steps[i]));
            let columns = [
                DVec3::X * steps[0],
                DVec3::Y * steps[1],
                DVec3::Z * steps[2],
            ];
            return Placement::from_columns(path, columns, origin);
        }
        let sform = || {
            let rows = self.srow.map(|r| r.map(|x| x * mm));
            let column = |j: usize| DVec3::new(rows[0][j], rows[1][j], rows[2][j]);
            Placement::from_columns(path, [column(0), column(1), column(2)], column(3))
        };
        let qform = || {
            let rotation = DMat3::from_quat(qform_quaternion(path, self.quatern)?);
            let qfac = if self.pixdim[0] < 0.0 { -1.0 } else { 1.0 };
            let steps = [pixdim[0], pixdim[1], pixdim[2] * qfac];
            let columns = [0, 1, 2].map(|i| rotation.col(i) * steps[i]);
            let [_, _, _, x, y, z] = self.quatern;
            Placement::from_columns(path, columns, DVec3::new(x, y, z) * mm)
        };
        let (s, q) = (self.sform_code > 0, self.qform_code > 0);
        let use_sform = match transform {
            NiftiTransform::Sform => s,
            NiftiTransform::Qform => s && !q,
            NiftiTransform::Itk => self.sform_code == 1 || (s && !q),
        };
        if use_sform {
            sform()
        } else if q {
            qform()
        } else {
            Placement::axis_aligned(path, pixdim, [0.0; 3])
        }
    }
}

/// The `.img` beside a `.hdr` (`.IMG` beside `.HDR`), which must exist.
fn image_file(path: &Path) -> Result<PathBuf, VolumeError> {
    let upper = path
        .extension()
        .is_some_and(|e| e.to_string_lossy().chars().all(|c| c.is_ascii_uppercase()));
    let img = path.with_extension(if upper { "IMG" } else { "img" });
    if img == path {
        return Err(header_error(
            path,
            "a header of a .hdr/.img pair named .img; give the .hdr",
        ));
    }
    if !img.is_file() {
        return Err(header_error(
            path,
            format!(
                "the header of a .hdr/.img pair, but its data file {} is missing",
                img.display()
            ),
        ));
    }
    Ok(img)
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
    fn from_header(path: &Path, header: &Header) -> Result<Self, VolumeError> {
        let (dims, frames) = dims(path, &header.dim)?;
        // The grid is checked before the type, whose error comes second. Values a rescale
        // changes are counted as f32 (an integer rescale holds them in 2 bytes, less).
        let scalar = scalar_type(path, header.datatype);
        let inter = if header.scl_inter.is_nan() {
            0.0
        } else {
            header.scl_inter
        };
        let slope = header.scl_slope;
        let kept = slope == 0.0 || slope.is_nan() || (slope == 1.0 && inter == 0.0);
        let held = match scalar {
            Ok(scalar) if kept => scalar,
            _ => ScalarType::F32,
        };
        let count = checked_voxels(path, dims, held)?;
        let format = ScalarFormat {
            scalar: scalar?,
            order: header.order,
        };
        // A pair's data start at vox_offset in the .img (usually 0); a single file's past
        // the header.
        let least = if header.data_file.is_some() {
            0
        } else {
            header.bytes as u64
        };
        Ok(Self {
            dims,
            count,
            format,
            vox_offset: vox_offset(path, header.vox_offset, least)?,
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

    /// Where the chosen frame starts in the (inflated) data file.
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

    /// Reads the values from a decompressing reader positioned just after the header of
    /// `header_bytes` bytes.
    fn inflate(
        &self,
        path: &Path,
        reader: &mut dyn Read,
        header_bytes: u64,
    ) -> Result<CpuVolume, VolumeError> {
        let bytes = self.frame_bytes(path)?;
        let count = usize::try_from(self.count)
            .map_err(|_| header_error(path, "declared size overflows"))?;
        let start = self.frame_start(path)?;
        skip_inflated(path, reader, start - header_bytes, bytes)?;
        let mut values = Voxels::new(self.format.scalar);
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

/// `vox_offset` as the whole byte count it must be, at least `least`.
fn vox_offset(path: &Path, offset: f64, least: u64) -> Result<u64, VolumeError> {
    // The upper bound only keeps the conversion exact; no real file comes near it.
    if offset >= least as f64 && offset.fract() == 0.0 && offset < 1e15 {
        Ok(offset as u64)
    } else {
        let message = format!("vox_offset {offset} is not a byte offset at or past {least}");
        Err(header_error(path, message))
    }
}

/// The 3-D size and the number of 3-D frames (`dim[4]`), from `dim`: `dim[0]` axes, missing
/// ones of size 1.
fn dims(path: &Path, dim: &[i64; 8]) -> Result<([u32; 3], u32), VolumeError> {
    let rank = dim[0];
    if !(1..=7).contains(&rank) {
        return Err(header_error(path, format!("dim[0] = {rank} is not 1 to 7")));
    }
    let rank = rank as usize;
    let size = |i: usize| if i <= rank { dim[i] } else { 1 };
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
    let narrow = |i: usize| {
        u32::try_from(size(i))
            .map_err(|_| header_error(path, format!("dim[{i}] = {} is past 2^32", size(i))))
    };
    Ok(([narrow(1)?, narrow(2)?, narrow(3)?], narrow(4)?))
}

/// The stored type of NIfTI's (and Analyze's) `datatype` code.
fn scalar_type(path: &Path, datatype: i16) -> Result<ScalarType, VolumeError> {
    Ok(match datatype {
        2 => ScalarType::U8,
        256 => ScalarType::I8,
        512 => ScalarType::U16,
        4 => ScalarType::I16,
        768 => ScalarType::U32,
        8 => ScalarType::I32,
        16 => ScalarType::F32,
        64 => ScalarType::F64,
        1 | 32 | 128 | 1024 | 1280 | 1536 | 1792 | 2048 | 2304 => {
            let name = match datatype {
                1 => "binary",
                32 => "complex64",
                128 => "RGB24",
                1024 => "int64",
                1280 => "uint64",
                1536 => "float128",
                1792 => "complex128",
                2048 => "complex256",
                _ => "RGBA32",
            };
            return Err(unsupported(path, format!("datatype {datatype} ({name})")));
        }
        other => return Err(header_error(path, format!("unknown datatype {other}"))),
    })
}

/// Applies `scl_slope` and `scl_inter`; a slope of 0 or NaN means none (as the standard and
/// nibabel say). An infinite slope or intercept, or a rescale that takes a value past `f32`,
/// means nothing and is a header error. Integers rescaled by an integer slope and intercept
/// stay 16-bit where every result fits ([`rescaled_integers`]); other results are `f32`.
fn rescale(path: &Path, values: &mut Voxels, slope: f64, inter: f64) -> Result<(), VolumeError> {
    if slope == 0.0 || slope.is_nan() {
        return Ok(());
    }
    let inter = if inter.is_nan() { 0.0 } else { inter };
    if !slope.is_finite() || !inter.is_finite() {
        let message = format!("scl_slope {slope} and scl_inter {inter} are not finite");
        return Err(header_error(path, message));
    }
    if slope == 1.0 && inter == 0.0 {
        return Ok(());
    }
    if let Some(exact) = rescaled_integers(values, slope, inter) {
        *values = exact;
        return Ok(());
    }
    let values = values.make_f32();
    for v in values.iter_mut() {
        *v = (f64::from(*v) * slope + inter) as f32;
    }
    if let Some(v) = values.iter().find(|v| v.is_infinite()) {
        let message = format!(
            "scl_slope {slope} and scl_inter {inter} take a value to {v}, past 32-bit floats"
        );
        return Err(header_error(path, message));
    }
    Ok(())
}

/// Integer values rescaled by an integer `slope` and `inter` as 16-bit integers, where every
/// result fits `i16` (or else `u16`): CT stored unsigned with an intercept of -1024 keeps two
/// bytes a voxel. `None` for fractions, floats, or results past both.
fn rescaled_integers(values: &Voxels, slope: f64, inter: f64) -> Option<Voxels> {
    if slope.fract() != 0.0 || inter.fract() != 0.0 || matches!(values, Voxels::F32(_)) {
        return None;
    }
    let runs = values.par_chunks(1 << 16, |run| {
        run.iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            })
    });
    let (lo, hi) = runs
        .into_iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |a, b| {
            (a.0.min(b.0), a.1.max(b.1))
        });
    if lo > hi {
        return None;
    }
    let ends = [f64::from(lo) * slope + inter, f64::from(hi) * slope + inter];
    let (lo, hi) = (ends[0].min(ends[1]), ends[0].max(ends[1]));
    let map = |v: f32| f64::from(v) * slope + inter;
    if lo >= f64::from(i16::MIN) && hi <= f64::from(i16::MAX) {
        let out = dispatch!(values, v => v.iter().map(|x| map(x.to_f32()) as i16).collect());
        Some(Voxels::I16(out))
    } else if lo >= 0.0 && hi <= f64::from(u16::MAX) {
        let out = dispatch!(values, v => v.iter().map(|x| map(x.to_f32()) as u16).collect());
        Some(Voxels::U16(out))
    } else {
        None
    }
}

/// Millimetres per unit of the header's spatial unit (`xyzt_units & 7`): metres 1000,
/// millimetres and unknown 1 (as ITK takes it), micrometres 0.001.
fn millimetres_per_unit(path: &Path, xyzt_units: i32) -> Result<f64, VolumeError> {
    match xyzt_units & 0x07 {
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

/// The qform rotation from `quatern_b/c/d`: `a` is implied by unit length; rounding that
/// pushes `b² + c² + d²` past 1 leaves `a = 0` and the rest normalised, as the NIfTI
/// reference code does. Components that are not finite are a header error.
fn qform_quaternion(path: &Path, quatern: [f64; 6]) -> Result<DQuat, VolumeError> {
    let [b, c, d, ..] = quatern;
    if ![b, c, d].iter().all(|x| x.is_finite()) {
        let message = format!("quatern_b, c, d [{b}, {c}, {d}] are not finite");
        return Err(header_error(path, message));
    }
    let a = (1.0 - (b * b + c * c + d * d)).max(0.0).sqrt();
    let q = DQuat::from_xyzw(b, c, d, a);
    Ok(if q.length() > 0.0 {
        q.normalize()
    } else {
        DQuat::IDENTITY
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::loader::tests::{gzip, scratch};

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
    fn integer_rescales_stay_16_bit_and_others_become_f32() {
        let dir = scratch("nifti-held");
        // u16 CT with intercept -1024, as many scanners' converters write it.
        let stored = [0u16, 1024, 4095, 30000];
        let file = |slope: f32, inter: f32, name: &str| {
            let mut bytes = header_bytes([2, 1, 2], 512, 16);
            put_f32(&mut bytes, 112, &[slope, inter]);
            bytes.extend(stored.iter().flat_map(|v| v.to_le_bytes()));
            load_nifti(&write(&dir, name, &bytes))
                .unwrap()
                .volume
                .values
        };
        let hu = file(1.0, -1024.0, "hu.nii");
        assert_eq!(hu.scalar_type(), ScalarType::I16);
        assert_eq!(hu, [-1024.0, 0.0, 3071.0, 28976.0]);
        // Past i16 but within u16: u16.
        let shifted = file(2.0, 100.0, "shifted.nii");
        assert_eq!(shifted.scalar_type(), ScalarType::U16);
        assert_eq!(shifted, [100.0, 2148.0, 8290.0, 60100.0]);
        // Past both: f32, exactly.
        let wide = file(3.0, -5.0, "wide.nii");
        assert_eq!(wide.scalar_type(), ScalarType::F32);
        assert_eq!(wide, [-5.0, 3067.0, 12280.0, 89995.0]);
        // A fractional slope: f32.
        let half = file(0.5, 0.0, "half.nii");
        assert_eq!(half.scalar_type(), ScalarType::F32);
        assert_eq!(half, [0.0, 512.0, 2047.5, 15000.0]);
        // No rescale: as stored.
        let plain = file(1.0, 0.0, "plain.nii");
        assert_eq!(plain.scalar_type(), ScalarType::U16);
        assert_eq!(plain, stored.map(f32::from));
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

    /// A little-endian NIfTI-2 header for `dim` of int16, unit pixdim, vox_offset 544, and
    /// the sform `rows` (code 1).
    fn nifti2_bytes(dim: [i64; 4], rows: [[f64; 4]; 3]) -> Vec<u8> {
        let mut h = vec![0u8; 544];
        h[0..4].copy_from_slice(&540i32.to_le_bytes());
        h[4..12].copy_from_slice(b"n+2\0\r\n\x1a\n");
        h[12..14].copy_from_slice(&4i16.to_le_bytes());
        h[14..16].copy_from_slice(&16i16.to_le_bytes());
        for (i, d) in [dim[0], dim[1], dim[2], dim[3], 1, 1, 1, 1]
            .iter()
            .enumerate()
        {
            h[16 + 8 * i..24 + 8 * i].copy_from_slice(&d.to_le_bytes());
        }
        for i in 0..8 {
            h[104 + 8 * i..112 + 8 * i].copy_from_slice(&1f64.to_le_bytes());
        }
        h[168..176].copy_from_slice(&544i64.to_le_bytes());
        h[348..352].copy_from_slice(&1i32.to_le_bytes());
        for (r, row) in rows.iter().enumerate() {
            for (c, v) in row.iter().enumerate() {
                let at = 400 + 32 * r + 8 * c;
                h[at..at + 8].copy_from_slice(&v.to_le_bytes());
            }
        }
        h
    }

    #[test]
    fn nifti2_reads_its_wide_fields_and_refuses_impossible_sizes() {
        let dir = scratch("nifti2");
        // A non-symmetric sform: x along +y (2 mm), y along -x (3 mm), z along +z (4 mm).
        let rows = [
            [0.0, -3.0, 0.0, 5.0],
            [2.0, 0.0, 0.0, 6.0],
            [0.0, 0.0, 4.0, 7.0],
        ];
        let mut bytes = nifti2_bytes([3, 2, 1, 2], rows);
        bytes.extend([1i16, 2, 3, 4].iter().flat_map(|v| v.to_le_bytes()));
        let v = load_nifti(&write(&dir, "good.nii", &bytes)).unwrap().volume;
        assert_eq!(
            (v.dims, v.values.clone()),
            ([2, 1, 2], vec![1.0f32, 2.0, 3.0, 4.0].into())
        );
        assert_eq!((v.spacing, v.origin), ([2.0, 3.0, 4.0], [5.0, 6.0, 7.0]));
        assert_eq!(v.direction, DMat3::from_cols(DVec3::Y, -DVec3::X, DVec3::Z));
        let huge = nifti2_bytes([3, 1 << 40, 1, 1], rows);
        let e = load_nifti(&write(&dir, "huge.nii", &huge))
            .unwrap_err()
            .to_string();
        assert!(e.contains("huge.nii") && e.contains("dim[1]"), "{e}");
        let mut negative = nifti2_bytes([3, 2, -1, 2], rows);
        negative.extend([0u8; 8]);
        let e = load_nifti(&write(&dir, "neg.nii", &negative))
            .unwrap_err()
            .to_string();
        assert!(e.contains("neg.nii") && e.contains("dim[2] = -1"), "{e}");
        let mut early = nifti2_bytes([3, 2, 1, 2], rows);
        early[168..176].copy_from_slice(&100i64.to_le_bytes());
        let e = load_nifti(&write(&dir, "early.nii", &early))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("early.nii") && e.contains("vox_offset 100"),
            "{e}"
        );
        // The declared data must be there.
        let short = nifti2_bytes([3, 2, 1, 2], rows);
        let e = load_nifti(&write(&dir, "short.nii", &short))
            .unwrap_err()
            .to_string();
        assert!(e.contains("short.nii") && e.contains("552"), "{e}");
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn a_nifti_pair_reads_its_data_from_the_img_beside_it() {
        let dir = scratch("nifti-pair");
        let mut header = header_bytes([2, 1, 2], 4, 16);
        header[344..348].copy_from_slice(b"ni1\0");
        put_f32(&mut header, 108, &[0.0]);
        put_f32(&mut header, 80, &[0.5, 0.25, 3.0]);
        write(&dir, "pair.hdr", &header[..348]);
        let data: Vec<u8> = [1i16, -2, 3, 400]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        write(&dir, "pair.img", &data);
        let loaded = crate::volume::detect::load_volume_with_info(&dir.join("pair.hdr")).unwrap();
        assert_eq!(loaded.format, VolumeFormat::Nifti);
        assert_eq!(loaded.volume.values, [1.0, -2.0, 3.0, 400.0]);
        assert_eq!(loaded.volume.spacing, [0.5, 0.25, 3.0]);
        // Short data, and a missing .img, are errors naming the file.
        write(&dir, "pair.img", &data[..6]);
        let e = load_nifti(&dir.join("pair.hdr")).unwrap_err().to_string();
        assert!(e.contains("pair.img") && e.contains("8 bytes"), "{e}");
        std::fs::remove_file(dir.join("pair.img")).unwrap();
        let e = load_nifti(&dir.join("pair.hdr")).unwrap_err().to_string();
        assert!(e.contains("pair.img") && e.contains("missing"), "{e}");
        std::fs::remove_dir_all(dir).ok();
    }
}
