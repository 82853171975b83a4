//! DICOM volumes: a folder of single-frame slice images (CT, MR), or one multi-frame object
//! (enhanced CT/MR, RT dose grids), loaded as one [`CpuVolume`].
//!
//! **Which files.** Every regular file in the folder (not its subfolders) that looks like DICOM
//! is read: the `DICM` magic after the 128-byte preamble, the magic at the very start (no
//! preamble), or a bare data set starting with a group-0008 element (no preamble and no file
//! meta group, as some old tools wrote; its transfer syntax is told from the bytes). DICOM files
//! without pixel data (a `DICOMDIR`, structured reports, presentation states) are skipped; the
//! `DICOMDIR` index is not used to find files. Files that cannot be parsed are ignored and
//! counted in a note on stderr, since their series is unknown; only a folder with no readable
//! image is an error.
//!
//! **Which series.** Images are grouped by SeriesInstanceUID. A file given alone selects its
//! own series and, within it, the images of its own orientation and size (a localizer stored
//! in the same series is left out); every other file of the folder is ignored, however
//! damaged, and counted in the note. A multi-frame file given alone is a volume by itself, and
//! so is an image without a position. A
//! folder holding one series loads it; a folder holding several is
//! [`VolumeError::DicomSeries`], which lists them (number, description, modality, size, image
//! count, UID) until one is chosen by SeriesNumber or UID ([`SeriesChoice`]); then every image
//! of the chosen series must be a usable slice. Copies of one image (the same SOPInstanceUID,
//! as when a file is stored in several encodings, or the same bytes when it has none) count
//! once: the file given, else the first by name. Given a file, of other slices at one position
//! (a damaged copy, a second version) the first by name that decodes is kept.
//!
//! **Geometry.** Slices are ordered by their ImagePositionPatient projected on the slice normal,
//! the cross product of the ImageOrientationPatient row and column directions. The grid's x axis
//! runs along a row (column index), y down the columns (row index) and z along the normal, so
//! `dims = [Columns, Rows, slices]` and `spacing = [PixelSpacing[1], PixelSpacing[0], step]`:
//! PixelSpacing lists the distance between rows first. The origin is the position of the first
//! slice. Every slice must lie on the line `origin + k * step * normal` to within a tenth of a
//! step; a gap of about two or more steps is reported as a missing slice, and a stack sheared by
//! gantry tilt is refused rather than placed wrongly. A lone slice takes its
//! SpacingBetweenSlices, else its SliceThickness (1 mm when both are absent) as the z spacing. A
//! lone image with neither ImagePositionPatient nor ImageOrientationPatient (a radiograph, a
//! secondary capture) is placed as ITK places it, at the origin along the patient axes, with
//! PixelSpacing, else ImagerPixelSpacing, else 1 mm (said on stderr); in a stack such an image
//! is refused.
//!
//! **Multi-frame objects.** Each frame is a slice. An enhanced image gives each frame's
//! position, orientation, pixel spacing and rescale in its functional groups (per frame, else
//! shared: PlanePositionSequence, PlaneOrientationSequence, PixelMeasuresSequence,
//! PixelValueTransformationSequence). A grid with a GridFrameOffsetVector (RT dose) places
//! frame k at `ImagePositionPatient + (offset[k] - offset[0]) * normal`, which holds for both
//! the relative form (first offset 0) and the absolute one (first offset the position's z), and
//! scales its values by DoseGridScaling (Gy). Multi-frame images with neither are refused.
//!
//! **World frame.** DICOM patient coordinates are LPS (+x toward the patient's left, +y
//! posterior, +z head); this project's world is RAS (+x toward the patient's right, +y anterior,
//! +z head), as in NIfTI. Positions and direction vectors are converted by negating x and y.
//! Because that flip has determinant +1, the converted normal is still the cross product of the
//! converted row and column directions.
//!
//! **Values.** Pixel data are decoded with `dicom-pixeldata` (native, deflate, RLE, JPEG
//! baseline, extended and lossless, JPEG-LS through CharLS, JPEG 2000 through the pure-Rust
//! `openjp2`), then mapped through each slice's (or frame's) RescaleSlope and RescaleIntercept:
//! Hounsfield units for CT. No window or VOI LUT is applied.
//!
//! **Not supported:** colour images, slices of one series with different pixel spacings,
//! and transfer syntaxes this build has no decoder for (JPEG XL, HTJ2K).

use std::collections::{BTreeMap, HashSet};
use std::fs;
use std::io::{BufReader, Read};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

use dicom_core::VR;
use dicom_dictionary_std::{tags, uids};
use dicom_object::{
    DefaultDicomObject, FileMetaTableBuilder, InMemDicomObject, OpenFileOptions, Tag,
};
use dicom_pixeldata::{DecodedPixelData, PixelDecoder, PixelRepresentation};
use dicom_transfer_syntax_registry::{TransferSyntaxIndex, TransferSyntaxRegistry};
use glam::{DMat3, DVec3};
use rayon::prelude::*;

pub use super::loader::SeriesChoice;
use super::loader::{Placement, io_error};
use super::loader::{ScalarType, VolumeError, checked_voxels};
pub use super::loader::{SeriesSummary, describe_series};
use super::{CpuVolume, Voxels};

mod decode;
mod header;
mod place;

use decode::*;
use header::*;
use place::*;

/// Bytes before the `DICM` magic in a DICOM file.
const PREAMBLE_LEN: usize = 128;
/// The magic that marks a DICOM file (DICOM PS3.10, section 7.1).
const MAGIC: &[u8; 4] = b"DICM";
/// Bytes read from the start of a file to tell whether it is DICOM.
pub(super) const SNIFF_LEN: usize = 512;
/// Largest allowed difference between slices' unit orientation components. DS strings carry
/// about six significant digits, so equal orientations agree far closer than this.
const ORIENTATION_TOLERANCE: f64 = 1e-4;
/// Largest allowed relative difference between slices' pixel spacings.
const SPACING_TOLERANCE: f64 = 1e-4;
/// How far, as a fraction of the slice step, a slice may sit from its place on the stack line.
/// Loose enough for positions rounded to 0.1 mm, tight enough that tilt or drift shows.
const POSITION_TOLERANCE: f64 = 0.1;
/// A step this many times the smallest step means at least one slice is missing.
const GAP_FACTOR: f64 = 1.5;
/// Upper bound on output bytes per byte of the series' files, so that a small file declaring a
/// huge image is refused before allocation. Lossless CT compresses about 2-5x, and an `f32` per
/// 16-bit sample doubles that; 256 leaves room for slices that are mostly padding.
const MAX_EXPANSION: u64 = 256;
/// Output always allowed whatever the files' size: lossy JPEG 2000 shrinks an image by far
/// more than [`MAX_EXPANSION`], and 16 MiB (a 2048 x 2048 slice) costs nothing to allow.
const ALWAYS_ALLOWED_BYTES: u64 = 16 << 20;
/// Most frames read from one multi-frame object, far above any CT or dose grid.
const MAX_FRAMES: u32 = 65_536;

/// Whether `bytes` (the start of a file; the first 512 bytes tell every case) look like
/// DICOM: the `DICM` magic after the 128-byte preamble or at the very start, or a bare data
/// set (see the [module documentation](self)).
pub fn is_dicom(bytes: &[u8]) -> bool {
    let magic_at = |at: usize| bytes.get(at..at + MAGIC.len()) == Some(MAGIC.as_slice());
    magic_at(PREAMBLE_LEN) || magic_at(0) || bare_data_set(bytes).is_some()
}

/// The value representations whose explicit-VR length takes 4 bytes after 2 reserved ones.
const LONG_VRS: [&[u8; 2]; 13] = [
    b"OB", b"OD", b"OF", b"OL", b"OV", b"OW", b"SQ", b"SV", b"UC", b"UN", b"UR", b"UT", b"UV",
];
/// The other value representations.
const SHORT_VRS: [&[u8; 2]; 21] = [
    b"AE", b"AS", b"AT", b"CS", b"DA", b"DS", b"DT", b"FL", b"FD", b"IS", b"LO", b"LT", b"PN",
    b"SH", b"SL", b"SS", b"ST", b"TM", b"UI", b"UL", b"US",
];

/// The transfer syntax of a file that is a bare data set: no preamble, no file meta group,
/// its first two elements in group 0008 (identifying attributes, which every image has). The
/// byte order comes from how the group reads, explicit VR from two known VR letters after the
/// tag; the second element must follow where the first one's length says.
fn bare_data_set(bytes: &[u8]) -> Option<&'static str> {
    let big = match bytes.get(0..2)? {
        [0x08, 0x00] => false,
        [0x00, 0x08] => true,
        _ => return None,
    };
    let u16_at = |at: usize| -> Option<u16> {
        let w: [u8; 2] = bytes.get(at..at + 2)?.try_into().ok()?;
        Some(if big {
            u16::from_be_bytes(w)
        } else {
            u16::from_le_bytes(w)
        })
    };
    let u32_at = |at: usize| -> Option<u32> {
        let w: [u8; 4] = bytes.get(at..at + 4)?.try_into().ok()?;
        Some(if big {
            u32::from_be_bytes(w)
        } else {
            u32::from_le_bytes(w)
        })
    };
    let vr: &[u8; 2] = bytes.get(4..6)?.try_into().ok()?;
    let explicit = |big: bool| match big {
        // Explicit VR big endian, retired from the standard but still in old files.
        true => "1.2.840.10008.1.2.2",
        false => uids::EXPLICIT_VR_LITTLE_ENDIAN,
    };
    let (next, ts) = if LONG_VRS.contains(&vr) {
        (12 + u32_at(8)? as usize, explicit(big))
    } else if SHORT_VRS.contains(&vr) {
        (8 + usize::from(u16_at(6)?), explicit(big))
    } else if !big {
        (8 + u32_at(4)? as usize, uids::IMPLICIT_VR_LITTLE_ENDIAN)
    } else {
        // Implicit VR is always little-endian.
        return None;
    };
    (u16_at(next)? == 0x0008).then_some(ts)
}

/// A DICOM file with pixel data: its series, and its slices (one per frame) or why they
/// cannot be slices.
struct Image {
    path: PathBuf,
    series: String,
    /// SOPInstanceUID, to count copies of one image once (empty when absent).
    instance: String,
    tags: SeriesTags,
    slices: Result<Vec<SliceHeader>, VolumeError>,
}

/// What a file says about its series, for listing.
#[derive(Debug, Clone, Default, PartialEq)]
struct SeriesTags {
    number: Option<String>,
    description: Option<String>,
    modality: Option<String>,
}

/// Whether `choice` names the series `uid` with these tags.
fn chosen(choice: &SeriesChoice, uid: &str, tags: &SeriesTags) -> bool {
    choice.0 == uid || tags.number.as_deref() == Some(choice.0.trim())
}

/// What one slice (an image, or one frame of a multi-frame image) says about itself, read
/// before any pixel is decoded.
#[derive(Debug, Clone)]
struct SliceHeader {
    path: PathBuf,
    /// The frame within a multi-frame file, from 0; `None` for a single-frame image.
    frame: Option<u32>,
    rows: u16,
    columns: u16,
    /// ImageOrientationPatient row and column directions, unit length, LPS.
    row_dir: DVec3,
    col_dir: DVec3,
    /// ImagePositionPatient, LPS.
    position: DVec3,
    /// PixelSpacing as stored: between rows, then between columns.
    pixel_spacing: [f64; 2],
    slice_thickness: Option<f64>,
    /// The file's length, shared among its frames.
    file_len: u64,
    /// The stored value type (BitsAllocated and PixelRepresentation), when it is one of ours.
    stored: Option<ScalarType>,
    /// Modality value = stored value x slope + intercept.
    slope: f64,
    intercept: f64,
    /// No ImagePositionPatient nor ImageOrientationPatient: at the origin, along the axes.
    unplaced: bool,
}

impl SliceHeader {
    fn name(&self) -> String {
        match self.frame {
            Some(k) => format!("{} frame {}", name(&self.path), k + 1),
            None => name(&self.path),
        }
    }
}

/// Loads the DICOM series in `dir` as a volume in RAS millimetres with values in modality units
/// (Hounsfield units for CT). See the [module documentation](self) for how files and the series
/// are chosen and placed.
///
/// Errors: [`VolumeError::Io`] when the folder or a file cannot be read,
/// [`VolumeError::Grid`] when the series has too many voxels, and [`VolumeError::Dicom`] naming
/// the file or folder for everything else (no image slices, a missing slice, mismatched slices,
/// a file that cannot be parsed or decoded).
pub fn load_dicom_series(dir: &Path) -> Result<CpuVolume, VolumeError> {
    load_dicom_series_with_type(dir).map(|(volume, _)| volume)
}

/// [`load_dicom_series`], with the stored value type of the first slice (before rescale), when
/// it is a type [`ScalarType`] names.
pub fn load_dicom_series_with_type(
    dir: &Path,
) -> Result<(CpuVolume, Option<ScalarType>), VolumeError> {
    load_dicom_series_choosing(dir, None, false)
}

/// [`load_dicom_series_with_type`], loading the series `choice` names when the folder holds
/// several ([`VolumeError::DicomSeries`] lists them when none is chosen). A file of that
/// series that cannot be read (cut inside its pixel data) is an error naming it, unless
/// `skip_unreadable`, which loads the series without it and says so.
pub fn load_dicom_series_choosing(
    dir: &Path,
    choice: Option<&SeriesChoice>,
    skip_unreadable: bool,
) -> Result<(CpuVolume, Option<ScalarType>), VolumeError> {
    let (images, unreadable, damaged) = read_folder(dir)?;
    let mut ignored = Ignored::unreadable(&unreadable);
    if images.is_empty()
        && let Some(first) = unreadable.into_iter().next()
    {
        return Err(first);
    }
    let images = select_series(dir, images, choice)?;
    let series = images.first().map(|i| i.series.clone()).unwrap_or_default();
    refuse_damaged(&series, &images, damaged, skip_unreadable, &mut ignored)?;
    let images = without_copies(images, None, &mut ignored);
    let slices = images
        .into_iter()
        .map(|image| image.slices)
        .collect::<Result<Vec<_>, _>>()?
        .into_iter()
        .flatten()
        .collect();
    ignored.note(dir);
    build_volume(dir, slices)
}

/// Loads the series of the DICOM file at `path` from its folder: the file's own series, and
/// within it the images of the file's orientation and size; every other file is ignored and
/// counted in a note on stderr. A multi-frame file is a volume by itself.
/// A file of the series that cannot be read is an error, unless `skip_unreadable`, as for
/// [`load_dicom_series_choosing`].
pub fn load_dicom_file_series(
    path: &Path,
    skip_unreadable: bool,
) -> Result<(CpuVolume, Option<ScalarType>), VolumeError> {
    let own = read_image(path)?
        .ok_or_else(|| dicom_error(path, "this DICOM file holds no image (no PixelData)"))?;
    let own_slices = match &own.slices {
        Ok(slices) => slices.clone(),
        Err(e) => return Err(dicom_error(path, e.to_string())),
    };
    // A multi-frame object is a volume by itself; an image with no place in the patient
    // cannot stack with others.
    if own_slices.len() > 1 || own_slices[0].unplaced {
        return build_volume(path, own_slices);
    }
    let first = &own_slices[0];
    let dir = match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent,
        _ => Path::new("."),
    };
    let (images, unreadable, damaged) = read_folder(dir)?;
    let mut ignored = Ignored::unreadable(&unreadable);
    refuse_damaged(&own.series, &images, damaged, skip_unreadable, &mut ignored)?;
    let own_path = fs::canonicalize(path).map_err(io_error(path))?;
    let mut kept = Vec::new();
    for image in images {
        if fs::canonicalize(&image.path).is_ok_and(|p| p == own_path) {
            continue;
        }
        if image.series != own.series {
            ignored.other_series += 1;
            continue;
        }
        match &image.slices {
            Ok(slices)
                if slices.len() == 1 && !slices[0].unplaced && same_grid(&slices[0], first) =>
            {
                kept.push(image)
            }
            _ => ignored.other_grid += 1,
        }
    }
    kept.push(own);
    let kept = without_copies(kept, Some(&own_path), &mut ignored);
    let slices: Vec<SliceHeader> = kept
        .into_iter()
        .flat_map(|image| image.slices.unwrap_or_default())
        .collect();
    let slices = one_per_position(slices, &own_path, &mut ignored);
    ignored.note(dir);
    build_volume(dir, slices)
}

/// Of single-frame slices at one position (within a micrometre), the file given when it is one
/// of them, else the first by name whose pixel data decode: a damaged or second copy of a
/// slice beside the file given must not stop its series from loading.
fn one_per_position(
    mut slices: Vec<SliceHeader>,
    own: &Path,
    ignored: &mut Ignored,
) -> Vec<SliceHeader> {
    let key = |s: &SliceHeader| (s.position * 1e3).round().to_array().map(|x| x as i64);
    slices.sort_by(|a, b| key(a).cmp(&key(b)).then_with(|| a.path.cmp(&b.path)));
    let mut kept: Vec<SliceHeader> = Vec::with_capacity(slices.len());
    let mut start = 0;
    while start < slices.len() {
        let end = start
            + slices[start..]
                .iter()
                .take_while(|s| key(s) == key(&slices[start]))
                .count();
        let group = &slices[start..end];
        let decodes = |s: &SliceHeader| {
            let mut values = vec![0.0f32; usize::from(s.rows) * usize::from(s.columns)];
            decode_file(&s.path, vec![(s, values.as_mut_slice())]).is_ok()
        };
        let chosen = match group {
            [only] => Some(only),
            _ => group
                .iter()
                .find(|s| fs::canonicalize(&s.path).is_ok_and(|p| p == own))
                .or_else(|| group.iter().find(|s| decodes(s))),
        };
        ignored.same_position += group.len() - usize::from(chosen.is_some());
        kept.extend(chosen.cloned());
        start = end;
    }
    kept
}

/// Whether two single-frame slices share their size and orientation.
fn same_grid(a: &SliceHeader, b: &SliceHeader) -> bool {
    (a.rows, a.columns) == (b.rows, b.columns)
        && a.row_dir.abs_diff_eq(b.row_dir, ORIENTATION_TOLERANCE)
        && a.col_dir.abs_diff_eq(b.col_dir, ORIENTATION_TOLERANCE)
}

/// Files of a folder that a load left out, for the note on stderr.
#[derive(Debug, Default)]
struct Ignored {
    unreadable: usize,
    /// The first few unreadable files, named in the note.
    unreadable_names: Vec<String>,
    other_series: usize,
    other_grid: usize,
    copies: usize,
    same_position: usize,
}

impl Ignored {
    /// Counts the files that could not be read, naming the first three.
    fn unreadable(errors: &[VolumeError]) -> Self {
        let names = errors.iter().take(3).map(error_file).collect();
        Self {
            unreadable: errors.len(),
            unreadable_names: names,
            ..Self::default()
        }
    }

    fn note(&self, dir: &Path) {
        let more = if self.unreadable > self.unreadable_names.len() {
            ", ..."
        } else {
            ""
        };
        let unreadable = format!(
            "not readable as DICOM ({}{more})",
            self.unreadable_names.join(", ")
        );
        let parts: Vec<String> = [
            (self.unreadable, &unreadable as &str),
            (self.other_series, "of other series"),
            (
                self.other_grid,
                "of another orientation or size, or not slices",
            ),
            (
                self.copies,
                "copies of an image already loaded (same SOPInstanceUID or bytes)",
            ),
            (
                self.same_position,
                "at the position of another slice (damaged, or a second version)",
            ),
        ]
        .iter()
        .filter(|(n, _)| *n > 0)
        .map(|(n, what)| format!("{n} {what}"))
        .collect();
        if !parts.is_empty() {
            eprintln!(
                "note: {}: ignored {} file(s): {}",
                dir.display(),
                self.unreadable
                    + self.other_series
                    + self.other_grid
                    + self.copies
                    + self.same_position,
                parts.join(", ")
            );
        }
    }
}

/// The images, one per SOPInstanceUID (or per content, for images without one): `prefer` (the
/// file given) when it is among the copies, else the first by name.
fn without_copies(
    mut images: Vec<Image>,
    prefer: Option<&Path>,
    ignored: &mut Ignored,
) -> Vec<Image> {
    let preferred =
        |image: &Image| prefer.is_some_and(|p| fs::canonicalize(&image.path).is_ok_and(|c| c == p));
    images.sort_by_cached_key(|image| (!preferred(image), image.path.clone()));
    // Where an image sits (its first slice, to a micrometre), and how many images sit there.
    let position = |image: &Image| {
        let slice = image.slices.as_ref().ok()?.first()?;
        Some((slice.position * 1e3).round().to_array().map(|x| x as i64))
    };
    let mut at = std::collections::HashMap::new();
    for p in images.iter().filter_map(position) {
        *at.entry(p).or_insert(0usize) += 1;
    }
    let mut seen = HashSet::new();
    let before = images.len();
    // An image without a SOPInstanceUID is known by its bytes where another image shares its
    // position (a copied file is a copy); elsewhere it cannot be one, and is not read again.
    let key = |image: &Image| match image.instance.is_empty() {
        false => Some(format!("uid {}", image.instance)),
        true if position(image).is_some_and(|p| at.get(&p) > Some(&1)) => fs::read(&image.path)
            .ok()
            .map(|bytes| format!("content {}", blake3::hash(&bytes))),
        true => None,
    };
    images.retain(|image| key(image).is_none_or(|k| seen.insert(k)));
    ignored.copies += before - images.len();
    images
}

/// Reads every DICOM-looking file of `dir`: the images, and the errors of files that could
/// not be parsed (in name order).
fn read_folder(dir: &Path) -> Result<FolderFiles, VolumeError> {
    let (paths, mut unreadable) = dicom_files(dir)?;
    let read: Vec<FileRead> = paths
        .par_iter()
        .map(|p| match read_image(p) {
            Ok(image) => FileRead::Image(image),
            Err(error) => match header_of_damaged(p) {
                Some((series, instance, position)) => FileRead::Damaged(Damaged {
                    series,
                    instance,
                    position,
                    error,
                }),
                None => FileRead::Unreadable(error),
            },
        })
        .collect();
    let mut images = Vec::new();
    let mut damaged = Vec::new();
    for result in read {
        match result {
            FileRead::Image(Some(image)) => images.push(image),
            FileRead::Image(None) => {}
            FileRead::Damaged(d) => damaged.push(d),
            FileRead::Unreadable(e) => unreadable.push(e),
        }
    }
    Ok((images, unreadable, damaged))
}

/// What reading one file of a folder came to.
enum FileRead {
    /// An image, or `None` for a DICOM file without pixel data.
    Image(Option<Image>),
    /// A file whose header names its series but which cannot be read whole.
    Damaged(Damaged),
    /// A file that cannot be read as DICOM at all.
    Unreadable(VolumeError),
}

/// A folder's images, the files that could not be read as DICOM at all, and those whose
/// header names their series but whose whole file could not be read.
type FolderFiles = (Vec<Image>, Vec<VolumeError>, Vec<Damaged>);

/// A file whose header, up to its pixel data, names its series, but which cannot be read
/// whole: a slice cut inside its pixel data, a damaged pixel element.
struct Damaged {
    series: String,
    /// SOPInstanceUID (empty when absent).
    instance: String,
    /// ImagePositionPatient, LPS.
    position: Option<DVec3>,
    error: VolumeError,
}

/// The SeriesInstanceUID, SOPInstanceUID and ImagePositionPatient in the header of a file
/// that could not be read whole, read up to its pixel data; `None` where even that cannot be
/// read.
fn header_of_damaged(path: &Path) -> Option<(String, String, Option<DVec3>)> {
    let read = catch_unwind(AssertUnwindSafe(|| {
        let obj = OpenFileOptions::new()
            .read_until(tags::PIXEL_DATA)
            .open_file(path)
            .ok()?;
        // Grouped as readable images are: a file without the UID joins the others without it.
        let series = optional_text(&obj, tags::SERIES_INSTANCE_UID).unwrap_or_default();
        let instance = optional_text(&obj, tags::SOP_INSTANCE_UID).unwrap_or_default();
        let position = floats::<3>(&obj, tags::IMAGE_POSITION_PATIENT, "ImagePositionPatient")
            .ok()
            .map(DVec3::from);
        Some((series, instance, position))
    }));
    read.ok().flatten()
}

/// Whether a damaged file stands for nothing the readable `images` lack: a copy of one of
/// them (its SOPInstanceUID), or a second version of a slice at one of their positions.
fn has_stand_in(d: &Damaged, images: &[Image]) -> bool {
    let key = |p: DVec3| (p * 1e3).round().to_array().map(|x| x as i64);
    images
        .iter()
        .filter(|image| image.series == d.series)
        .any(|image| {
            (!d.instance.is_empty() && image.instance == d.instance)
                || d.position.is_some_and(|p| {
                    image
                        .slices
                        .iter()
                        .flatten()
                        .any(|s| key(s.position) == key(p))
                })
        })
}

/// Refuses a load of `series` (read as `images`) that would leave out one of its files that
/// cannot be read (the volume would lack its slice without a word), unless `skip`, which says
/// on stderr which files it leaves out. Damaged files of other series, and damaged copies or
/// second versions of slices the series has, are counted as ignored.
fn refuse_damaged(
    series: &str,
    images: &[Image],
    damaged: Vec<Damaged>,
    skip: bool,
    ignored: &mut Ignored,
) -> Result<(), VolumeError> {
    let (own, other): (Vec<Damaged>, Vec<Damaged>) = damaged
        .into_iter()
        .partition(|d| d.series == series && !has_stand_in(d, images));
    ignored.unreadable += other.len();
    ignored
        .unreadable_names
        .extend(other.iter().take(3).map(|d| error_file(&d.error)));
    ignored.unreadable_names.truncate(3);
    let Some(first) = own.first() else {
        return Ok(());
    };
    if !skip {
        let others = match own.len() {
            1 => String::new(),
            n => format!(" ({} files of the series cannot be read)", n),
        };
        return Err(dicom_error(
            Path::new(&error_file_path(&first.error)),
            format!(
                "a file of the series being loaded cannot be read{others}, so the volume would lack its slice ({}); to load the series without the files that cannot be read, give --skip-unreadable (scene files and manifests: skip_unreadable = true)",
                match &first.error {
                    VolumeError::Dicom { message, .. } => message.clone(),
                    other => other.to_string(),
                }
            ),
        ));
    }
    let names: Vec<String> = own.iter().map(|d| error_file(&d.error)).collect();
    eprintln!(
        "warning: skipping {} file(s) of the series that cannot be read, as --skip-unreadable asks: {}",
        own.len(),
        names.join(", ")
    );
    Ok(())
}

/// The file an error of a damaged file names.
fn error_file_path(e: &VolumeError) -> PathBuf {
    match e {
        VolumeError::Dicom { path, .. } | VolumeError::Io { path, .. } => path.clone(),
        _ => PathBuf::new(),
    }
}

/// The name of the file an error names, for a list.
fn error_file(e: &VolumeError) -> String {
    match e {
        VolumeError::Dicom { path, .. } | VolumeError::Io { path, .. } => name(path),
        other => other.to_string(),
    }
}

/// The volume of `slices` (of one grid), placed and decoded. `at` names the folder or file in
/// errors about the whole stack.
fn build_volume(
    at: &Path,
    mut slices: Vec<SliceHeader>,
) -> Result<(CpuVolume, Option<ScalarType>), VolumeError> {
    if slices.is_empty() {
        return Err(dicom_error(at, "no DICOM image slices here"));
    }
    if let Some(lost) = slices.iter().find(|s| s.unplaced) {
        if slices.len() > 1 {
            let message =
                "no ImagePositionPatient (nor ImageOrientationPatient) in a stack of slices";
            return Err(dicom_error(&lost.path, message));
        }
        eprintln!(
            "note: {}: no ImagePositionPatient or ImageOrientationPatient; the image is placed \
             at the origin along the patient axes, as ITK places it",
            lost.path.display()
        );
    }
    check_consistent(&slices)?;
    let placement = place_slices(at, &mut slices)?;
    let first = &slices[0];
    let count = u32::try_from(slices.len()).map_err(|_| dicom_error(at, "too many slices"))?;
    let dims = [u32::from(first.columns), u32::from(first.rows), count];
    // Integer samples with integer rescales are held as 16-bit integers (two bytes a voxel
    // where f32 takes four) unless a value turns out not to fit; then the stack is decoded again
    // as f32.
    let integral = slices.iter().all(|s| {
        s.slope.fract() == 0.0
            && s.intercept.fract() == 0.0
            && matches!(
                s.stored,
                Some(ScalarType::U8 | ScalarType::I8 | ScalarType::U16 | ScalarType::I16)
            )
    });
    let narrow = if integral {
        decode_stack::<i16>(at, dims, &slices)?.map(Voxels::I16)
    } else {
        None
    };
    let values = match narrow {
        Some(values) => values,
        None => match decode_stack::<f32>(at, dims, &slices)? {
            Some(values) => Voxels::F32(values),
            None => unreachable!("every modality value fits f32 once its ends are checked"),
        },
    };
    let volume = CpuVolume {
        dims,
        spacing: placement.spacing,
        origin: placement.origin,
        direction: placement.direction,
        values,
    };
    Ok((volume, slices[0].stored))
}

/// A slice and the place its values go.
type SliceOut<'a, T> = (&'a SliceHeader, &'a mut [T]);

/// The first error in file order, so that a folder with several bad files always reports the
/// same one whatever the thread timing.
fn first_error<T>(results: Vec<Result<T, VolumeError>>) -> Result<Vec<T>, VolumeError> {
    results.into_iter().collect()
}

fn dicom_error(path: &Path, message: impl Into<String>) -> VolumeError {
    VolumeError::Dicom {
        path: path.into(),
        message: message.into(),
    }
}

fn name(path: &Path) -> String {
    path.file_name()
        .unwrap_or(path.as_os_str())
        .to_string_lossy()
        .into_owned()
}

/// The regular files of `dir` that start like DICOM, in name order, and the errors of the
/// entries that could not be looked at (a dangling link, a file without read permission):
/// those are counted among the unreadable files, never fatal to the series beside them.
fn dicom_files(dir: &Path) -> Result<(Vec<PathBuf>, Vec<VolumeError>), VolumeError> {
    let mut paths = Vec::new();
    let mut unreadable = Vec::new();
    for entry in fs::read_dir(dir).map_err(io_error(dir))? {
        let path = entry.map_err(io_error(dir))?.path();
        // Follows symlinks, so a linked slice counts like a copied one.
        let looked = fs::metadata(&path)
            .map_err(io_error(&path))
            .and_then(|meta| Ok(meta.is_file() && looks_like_dicom(&path)?));
        match looked {
            Ok(true) => paths.push(path),
            Ok(false) => {}
            Err(e) => unreadable.push(e),
        }
    }
    paths.sort();
    unreadable.sort_by_key(|e| e.to_string());
    Ok((paths, unreadable))
}

/// Reads only the first bytes, so large non-DICOM files in the folder cost nothing.
fn looks_like_dicom(path: &Path) -> Result<bool, VolumeError> {
    let mut start = Vec::with_capacity(SNIFF_LEN);
    crate::input::open_regular(path)
        .and_then(|f| f.take(SNIFF_LEN as u64).read_to_end(&mut start))
        .map_err(io_error(path))?;
    Ok(is_dicom(&start))
}

/// Runs a parser or decoder on one file, turning a panic inside it into an error: the codecs
/// index their buffers by sizes taken from the file, which a damaged file can make inconsistent.
fn guarded<T>(path: &Path, f: impl FnOnce() -> Result<T, String>) -> Result<T, VolumeError> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(result) => result.map_err(|message| dicom_error(path, message)),
        Err(_) => Err(dicom_error(path, "the DICOM reader panicked on this file")),
    }
}

/// `context` and the error with its chain of sources: the top-level messages of the DICOM
/// crates ("Could not decode pixel data") leave out what actually went wrong.
fn describe(context: &str, error: &dyn std::error::Error) -> String {
    let mut message = format!("{context}: {error}");
    let mut source = error.source();
    while let Some(cause) = source {
        message = format!("{message}: {cause}");
        source = cause.source();
    }
    message
}

/// The images of the chosen series: the only one, or the one `choice` names.
fn select_series(
    dir: &Path,
    images: Vec<Image>,
    choice: Option<&SeriesChoice>,
) -> Result<Vec<Image>, VolumeError> {
    let groups = group_series(images);
    if groups.is_empty() {
        return Err(dicom_error(dir, "no DICOM image slices in this folder"));
    }
    let listing = |groups: &[(String, Vec<Image>)]| {
        groups.iter().map(|(uid, g)| summary(dir, uid, g)).collect()
    };
    let index = match choice {
        Some(c) => {
            let matching: Vec<usize> = (0..groups.len())
                .filter(|&i| chosen(c, &groups[i].0, &groups[i].1[0].tags))
                .collect();
            match matching.as_slice() {
                [i] => *i,
                found => {
                    let problem = if found.is_empty() {
                        format!("no series is {:?}", c.0)
                    } else {
                        format!("several series are numbered {:?}; give the UID", c.0)
                    };
                    return Err(VolumeError::DicomSeries {
                        path: dir.into(),
                        problem,
                        series: listing(&groups),
                    });
                }
            }
        }
        None if groups.len() == 1 => 0,
        None => {
            return Err(VolumeError::DicomSeries {
                path: dir.into(),
                problem: format!("{} DICOM series in this folder", groups.len()),
                series: listing(&groups),
            });
        }
    };
    let mut groups = groups;
    Ok(groups.swap_remove(index).1)
}

/// Images grouped by SeriesInstanceUID, in UID order.
fn group_series(images: Vec<Image>) -> Vec<(String, Vec<Image>)> {
    let mut by_series = BTreeMap::<String, Vec<Image>>::new();
    for image in images {
        by_series
            .entry(image.series.clone())
            .or_default()
            .push(image);
    }
    by_series.into_iter().collect()
}

fn summary(folder: &Path, uid: &str, images: &[Image]) -> SeriesSummary {
    let tags = &images[0].tags;
    SeriesSummary {
        folder: folder.into(),
        uid: uid.to_owned(),
        number: tags.number.clone(),
        description: tags.description.clone(),
        modality: tags.modality.clone(),
        size: images.iter().find_map(|i| {
            i.slices
                .as_ref()
                .ok()
                .and_then(|s| s.first())
                .map(|s| [s.columns, s.rows])
        }),
        images: images.len(),
    }
}

/// The series of DICOM images in `dir` (not its subfolders), without decoding any pixel data.
/// Files that cannot be read as DICOM are left out here; loading the folder reports them.
pub fn list_series(dir: &Path) -> Result<Vec<SeriesSummary>, VolumeError> {
    let (images, ..) = read_folder(dir)?;
    Ok(group_series(images)
        .iter()
        .map(|(uid, g)| summary(dir, uid, g))
        .collect())
}

/// The SeriesInstanceUID of one DICOM file.
pub fn series_of(path: &Path) -> Result<String, VolumeError> {
    guarded(path, || {
        let obj = open(path)?;
        Ok(optional_text(&obj, tags::SERIES_INSTANCE_UID).unwrap_or_default())
    })
}

#[cfg(test)]
mod tests;
