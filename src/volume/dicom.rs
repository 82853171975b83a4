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

/// A type modality values are written in.
trait Modality: Copy + Default + Send + Sync {
    /// The value, `None` where this type cannot hold it exactly.
    fn from_modality(v: f64) -> Option<Self>;
}

impl Modality for f32 {
    fn from_modality(v: f64) -> Option<Self> {
        Some(v as f32)
    }
}

impl Modality for i16 {
    fn from_modality(v: f64) -> Option<Self> {
        let fits = v.fract() == 0.0 && v >= f64::from(i16::MIN) && v <= f64::from(i16::MAX);
        fits.then_some(v as i16)
    }
}

/// The stack's modality values in `T`, each file decoded once and its frames written to their
/// places; `None` when a value does not fit `T`.
fn decode_stack<T: Modality>(
    at: &Path,
    dims: [u32; 3],
    slices: &[SliceHeader],
) -> Result<Option<Vec<T>>, VolumeError> {
    let mut values = allocate::<T>(at, dims, slices)?;
    let plane = values.len() / slices.len();
    let mut by_file: BTreeMap<&Path, Vec<(usize, &SliceHeader)>> = BTreeMap::new();
    for (k, slice) in slices.iter().enumerate() {
        by_file.entry(&slice.path).or_default().push((k, slice));
    }
    let mut chunks: Vec<Option<&mut [T]>> = values.chunks_mut(plane).map(Some).collect();
    let work: Vec<(&Path, Vec<SliceOut<T>>)> = by_file
        .into_iter()
        .map(|(path, list)| {
            let outs = list
                .into_iter()
                .map(|(k, slice)| (slice, chunks[k].take().expect("one slice per place")))
                .collect();
            (path, outs)
        })
        .collect();
    let decoded: Vec<_> = work
        .into_par_iter()
        .map(|(path, outs)| decode_file(path, outs))
        .collect();
    let fits = first_error(decoded)?.into_iter().all(|fits| fits);
    Ok(fits.then_some(values))
}

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

/// Opens a DICOM file, with or without its preamble; a bare data set is read with the
/// transfer syntax its bytes show and given a file meta group.
fn open(path: &Path) -> Result<DefaultDicomObject, String> {
    check_deflated_size(path)?;
    let parsed = OpenFileOptions::new().open_file(path);
    let error = match parsed {
        Ok(obj) => return Ok(obj),
        Err(e) => describe("cannot parse DICOM", &e),
    };
    let mut head = Vec::with_capacity(SNIFF_LEN);
    crate::input::open_regular(path)
        .and_then(|f| f.take(SNIFF_LEN as u64).read_to_end(&mut head))
        .map_err(|e| format!("cannot read: {e}"))?;
    let Some(ts) = bare_data_set(&head) else {
        return Err(error);
    };
    let syntax = TransferSyntaxRegistry
        .get(ts)
        .ok_or_else(|| format!("no transfer syntax {ts} in this build"))?;
    let file = crate::input::open_regular(path).map_err(|e| format!("cannot read: {e}"))?;
    let data = InMemDicomObject::read_dataset_with_ts(BufReader::new(file), syntax)
        .map_err(|e| describe("cannot parse a DICOM data set without meta group", &e))?;
    // The SOP identifiers are the data set's own when it has them (with_meta takes those).
    let meta = FileMetaTableBuilder::new()
        .transfer_syntax(ts)
        .media_storage_sop_class_uid(uids::SECONDARY_CAPTURE_IMAGE_STORAGE)
        .media_storage_sop_instance_uid("2.25.0");
    data.with_meta(meta)
        .map_err(|e| describe("cannot give the data set a meta group", &e))
}

/// The Deflated Explicit VR Little Endian transfer syntax.
const DEFLATED: &str = "1.2.840.10008.1.2.1.99";

/// Refuses a deflated data set that inflates to more than [`MAX_EXPANSION`] times its file
/// (or [`ALWAYS_ALLOWED_BYTES`]), counted while inflating into nothing: the DICOM reader
/// inflates a deflated data set whole into memory, so a small file could otherwise take
/// gigabytes before any size is checked. No slice of such a file could be loaded anyway
/// ([`allocate`] applies the same bound to the volume).
fn check_deflated_size(path: &Path) -> Result<(), String> {
    let mut file = crate::input::open_regular(path).map_err(|e| format!("cannot read: {e}"))?;
    let file_len = file
        .metadata()
        .map_err(|e| format!("cannot read: {e}"))?
        .len();
    let mut head = Vec::with_capacity(SNIFF_LEN);
    (&mut file)
        .take(SNIFF_LEN as u64)
        .read_to_end(&mut head)
        .map_err(|e| format!("cannot read: {e}"))?;
    // The meta group: its length (0002,0000) right after the magic, then its elements,
    // explicit VR little endian; the transfer syntax UID is (0002,0010).
    let group = PREAMBLE_LEN + 4;
    let Some(len) = head
        .get(group..group + 12)
        .filter(|e| e[..6] == [2, 0, 0, 0, b'U', b'L'])
        .map(|e| u64::from(u32::from_le_bytes([e[8], e[9], e[10], e[11]])))
    else {
        return Ok(());
    };
    let start = group as u64 + 12;
    let meta = head.get(start as usize..(start + len).min(head.len() as u64) as usize);
    let deflated = meta.is_some_and(|m| {
        m.windows(6)
            .position(|w| w == [2, 0, 0x10, 0, b'U', b'I'])
            .and_then(|at| {
                let n = usize::from(u16::from_le_bytes([*m.get(at + 6)?, *m.get(at + 7)?]));
                m.get(at + 8..at + 8 + n)
            })
            .is_some_and(|uid| {
                // UIDs are padded to an even length with a NUL.
                let uid = uid.strip_suffix(&[0]).unwrap_or(uid);
                uid.trim_ascii() == DEFLATED.as_bytes()
            })
    });
    if !deflated {
        return Ok(());
    }
    let cap = file_len
        .saturating_mul(MAX_EXPANSION)
        .max(ALWAYS_ALLOWED_BYTES);
    std::io::Seek::seek(&mut file, std::io::SeekFrom::Start(start + len))
        .map_err(|e| format!("cannot read: {e}"))?;
    let mut inflated = flate2::read::DeflateDecoder::new(BufReader::new(file)).take(cap + 1);
    let n = std::io::copy(&mut inflated, &mut std::io::sink())
        .map_err(|e| format!("the deflated data set cannot be inflated: {e}"))?;
    if n > cap {
        return Err(format!(
            "the deflated data set inflates to more than {cap} bytes, {MAX_EXPANSION} times \
             its {file_len}-byte file: refused before reading it"
        ));
    }
    Ok(())
}

/// The image in a DICOM file, or `None` for a file without pixel data. A file that cannot be
/// parsed is an error here, since its series is unknown; one that parses but cannot be a slice
/// only matters if its series is the one loaded.
fn read_image(path: &Path) -> Result<Option<Image>, VolumeError> {
    let file_len = fs::metadata(path).map_err(io_error(path))?.len();
    guarded(path, || {
        let obj = open(path)?;
        if obj.get(tags::PIXEL_DATA).is_none() {
            return Ok(None);
        }
        let text = |tag| optional_text(&obj, tag).filter(|t| !t.is_empty());
        let slices = slice_headers(&obj, path, file_len).map_err(|m| dicom_error(path, m));
        Ok(Some(Image {
            path: path.into(),
            series: text(tags::SERIES_INSTANCE_UID).unwrap_or_default(),
            instance: text(tags::SOP_INSTANCE_UID).unwrap_or_default(),
            tags: SeriesTags {
                number: text(tags::SERIES_NUMBER),
                description: text(tags::SERIES_DESCRIPTION),
                modality: text(tags::MODALITY),
            },
            slices,
        }))
    })
}

/// The first item of sequence `tag` in `obj`.
fn first_item(obj: &InMemDicomObject, tag: Tag) -> Option<&InMemDicomObject> {
    obj.get(tag)?.items()?.first()
}

/// Where a frame's functional group attributes are: its own item of the per-frame
/// sequence, then the shared item.
struct Groups<'a> {
    own: Option<&'a InMemDicomObject>,
    shared: Option<&'a InMemDicomObject>,
}

impl<'a> Groups<'a> {
    /// The item of macro sequence `sequence` holding this frame's attributes.
    fn macro_item(&self, sequence: Tag) -> Option<&'a InMemDicomObject> {
        self.own
            .and_then(|o| first_item(o, sequence))
            .or_else(|| self.shared.and_then(|s| first_item(s, sequence)))
    }
}

/// The slices of an image: one for a single-frame image, one per frame otherwise.
fn slice_headers(
    obj: &DefaultDicomObject,
    path: &Path,
    file_len: u64,
) -> Result<Vec<SliceHeader>, String> {
    let frames = match optional_text(obj, tags::NUMBER_OF_FRAMES).as_deref() {
        None | Some("") => 1,
        Some(text) => text
            .parse::<u32>()
            .ok()
            .filter(|n| (1..=MAX_FRAMES).contains(n))
            .ok_or_else(|| format!("NumberOfFrames {text:?} is not 1 to {MAX_FRAMES}"))?,
    };
    let rows = unsigned(obj, tags::ROWS, "Rows")?;
    let columns = unsigned(obj, tags::COLUMNS, "Columns")?;
    let bits = unsigned(obj, tags::BITS_ALLOCATED, "BitsAllocated").ok();
    if bits == Some(1) {
        return Err(
            "1-bit pixels (a binary segmentation or overlay) are not read as a volume".into(),
        );
    }
    let signed = unsigned(obj, tags::PIXEL_REPRESENTATION, "PixelRepresentation").ok() == Some(1);
    let stored = match (bits, signed) {
        (Some(8), false) => Some(ScalarType::U8),
        (Some(8), true) => Some(ScalarType::I8),
        (Some(16), false) => Some(ScalarType::U16),
        (Some(16), true) => Some(ScalarType::I16),
        (Some(32), false) => Some(ScalarType::U32),
        (Some(32), true) => Some(ScalarType::I32),
        _ => None,
    };
    let (top_slope, top_intercept) = rescale_of(obj)?;
    let base = SliceHeader {
        path: path.into(),
        frame: None,
        rows,
        columns,
        row_dir: DVec3::X,
        col_dir: DVec3::Y,
        position: DVec3::ZERO,
        pixel_spacing: [1.0; 2],
        slice_thickness: None,
        file_len: file_len / u64::from(frames),
        stored,
        slope: top_slope,
        intercept: top_intercept,
        unplaced: false,
    };
    let per_frame = obj
        .get(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE)
        .and_then(|e| e.items());
    let offsets = obj.get(tags::GRID_FRAME_OFFSET_VECTOR);
    if frames == 1 && per_frame.is_none() {
        if obj.get(tags::IMAGE_POSITION_PATIENT).is_none()
            && obj.get(tags::IMAGE_ORIENTATION_PATIENT).is_none()
        {
            // A projection or a secondary capture: no place in the patient. Alone it is
            // placed as ITK places it; in a stack it is refused (see build_volume).
            let spacing = floats::<2>(obj, tags::PIXEL_SPACING, "PixelSpacing")
                .or_else(|_| floats::<2>(obj, tags::IMAGER_PIXEL_SPACING, "ImagerPixelSpacing"))
                .unwrap_or([1.0, 1.0]);
            if spacing.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
                return Err(format!("PixelSpacing {spacing:?} is not positive"));
            }
            return Ok(vec![SliceHeader {
                pixel_spacing: spacing,
                unplaced: true,
                ..base
            }]);
        }
        return Ok(vec![plane_of(obj, obj, obj, base)?]);
    }
    if let Some(items) = per_frame {
        // Enhanced images: every frame's geometry in its functional groups.
        if items.len() != frames as usize {
            return Err(format!(
                "{} per-frame functional groups for {frames} frames",
                items.len()
            ));
        }
        let shared = first_item(obj, tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE);
        return items
            .iter()
            .enumerate()
            .map(|(k, item)| {
                let groups = Groups {
                    own: Some(item),
                    shared,
                };
                let missing = |what: &str| format!("frame {}: no {what}", k + 1);
                let position = groups
                    .macro_item(tags::PLANE_POSITION_SEQUENCE)
                    .ok_or_else(|| missing("PlanePositionSequence"))?;
                let orientation = groups
                    .macro_item(tags::PLANE_ORIENTATION_SEQUENCE)
                    .ok_or_else(|| missing("PlaneOrientationSequence"))?;
                let measures = groups
                    .macro_item(tags::PIXEL_MEASURES_SEQUENCE)
                    .ok_or_else(|| missing("PixelMeasuresSequence"))?;
                let mut slice = SliceHeader {
                    frame: Some(k as u32),
                    ..base.clone()
                };
                if let Some(transform) =
                    groups.macro_item(tags::PIXEL_VALUE_TRANSFORMATION_SEQUENCE)
                {
                    (slice.slope, slice.intercept) = rescale_of(transform)?;
                }
                plane_of(position, orientation, measures, slice)
                    .map_err(|m| format!("frame {}: {m}", k + 1))
            })
            .collect();
    }
    let Some(offsets) = offsets else {
        return Err(format!(
            "{frames} frames without per-frame positions (no functional groups or \
             GridFrameOffsetVector): not a volume"
        ));
    };
    // A grid of frames along the normal (RT dose).
    let offsets = numbers_of(offsets, "GridFrameOffsetVector")?;
    if offsets.len() != frames as usize || offsets.iter().any(|o| !o.is_finite()) {
        return Err(format!(
            "GridFrameOffsetVector has {} finite values for {frames} frames",
            offsets.len()
        ));
    }
    let mut first = plane_of(obj, obj, obj, base)?;
    if let Some(scaling) = obj.get(tags::DOSE_GRID_SCALING) {
        let [scale] = floats_of::<1>(scaling, "DoseGridScaling")?;
        first.slope *= scale;
        first.intercept *= scale;
    }
    let normal = first.row_dir.cross(first.col_dir);
    Ok((0..frames)
        .map(|k| SliceHeader {
            frame: Some(k),
            position: first.position + normal * (offsets[k as usize] - offsets[0]),
            ..first.clone()
        })
        .collect())
}

/// `slice` with its position, orientation and spacing from the three objects that hold
/// them (the image itself, or a frame's functional group items).
fn plane_of(
    position: &InMemDicomObject,
    orientation: &InMemDicomObject,
    measures: &InMemDicomObject,
    slice: SliceHeader,
) -> Result<SliceHeader, String> {
    let iop = floats::<6>(
        orientation,
        tags::IMAGE_ORIENTATION_PATIENT,
        "ImageOrientationPatient",
    )?;
    let (row_dir, col_dir) = unit_axes(iop)?;
    let ipp = floats::<3>(
        position,
        tags::IMAGE_POSITION_PATIENT,
        "ImagePositionPatient",
    )?;
    let pixel_spacing = floats::<2>(measures, tags::PIXEL_SPACING, "PixelSpacing")?;
    if pixel_spacing.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
        return Err(format!("PixelSpacing {pixel_spacing:?} is not positive"));
    }
    // A lone slice's depth: SpacingBetweenSlices, else SliceThickness.
    let slice_thickness = floats::<1>(
        measures,
        tags::SPACING_BETWEEN_SLICES,
        "SpacingBetweenSlices",
    )
    .or_else(|_| floats::<1>(measures, tags::SLICE_THICKNESS, "SliceThickness"))
    .ok()
    .map(|[t]| t)
    .filter(|t| t.is_finite() && *t > 0.0);
    Ok(SliceHeader {
        row_dir,
        col_dir,
        position: DVec3::from(ipp),
        pixel_spacing,
        slice_thickness,
        ..slice
    })
}

/// RescaleSlope and RescaleIntercept of `obj` (1 and 0 when absent), which must be finite.
fn rescale_of(obj: &InMemDicomObject) -> Result<(f64, f64), String> {
    let get = |tag, name, default| match obj.get(tag) {
        Some(e) => floats_of::<1>(e, name).map(|[v]| v),
        None => Ok(default),
    };
    Ok((
        get(tags::RESCALE_SLOPE, "RescaleSlope", 1.0)?,
        get(tags::RESCALE_INTERCEPT, "RescaleIntercept", 0.0)?,
    ))
}

/// A text attribute without DICOM's space or NUL padding; `None` when absent or unreadable.
fn optional_text(obj: &InMemDicomObject, tag: Tag) -> Option<String> {
    let value = obj.get(tag)?.to_str().ok()?;
    Some(value.trim_matches(['\0', ' ']).to_owned())
}

fn unsigned(obj: &InMemDicomObject, tag: Tag, name: &str) -> Result<u16, String> {
    let element = obj.get(tag).ok_or_else(|| format!("no {name}"))?;
    match element.to_int::<u16>() {
        Ok(0) | Err(_) => Err(format!("{name} is not a positive 16-bit number")),
        Ok(n) => Ok(n),
    }
}

/// Exactly `N` finite numbers from a decimal-string attribute.
fn floats<const N: usize>(
    obj: &InMemDicomObject,
    tag: Tag,
    name: &str,
) -> Result<[f64; N], String> {
    let element = obj.get(tag).ok_or_else(|| format!("no {name}"))?;
    floats_of(element, name)
}

/// The numbers of an element. An element whose VR is UN (as some writers store attributes
/// they do not know) holds its decimal strings as bytes, which are read as text.
fn numbers_of(element: &dicom_object::mem::InMemElement, name: &str) -> Result<Vec<f64>, String> {
    if element.vr() != VR::UN {
        return element
            .to_multi_float64()
            .map_err(|e| format!("{name} is not numeric: {e}"));
    }
    let bytes = element
        .to_bytes()
        .map_err(|e| format!("{name} is not numeric: {e}"))?;
    let text = std::str::from_utf8(&bytes).map_err(|_| format!("{name} is not numeric text"))?;
    text.trim_matches(['\0', ' '])
        .split('\\')
        .map(|word| {
            word.trim()
                .parse::<f64>()
                .map_err(|_| format!("{name} holds {word:?}, not a number"))
        })
        .collect()
}

/// Exactly `N` finite numbers from an element.
fn floats_of<const N: usize>(
    element: &dicom_object::mem::InMemElement,
    name: &str,
) -> Result<[f64; N], String> {
    let values = numbers_of(element, name)?;
    let array: [f64; N] = values
        .as_slice()
        .try_into()
        .map_err(|_| format!("{name} has {} values instead of {N}", values.len()))?;
    if array.iter().all(|v| v.is_finite()) {
        Ok(array)
    } else {
        Err(format!("{name} {array:?} is not finite"))
    }
}

/// The row and column directions of ImageOrientationPatient, which must be (close to) unit
/// length and perpendicular; they are renormalised to remove the rounding of their DS strings.
fn unit_axes(orientation: [f64; 6]) -> Result<(DVec3, DVec3), String> {
    let row = DVec3::new(orientation[0], orientation[1], orientation[2]);
    let col = DVec3::new(orientation[3], orientation[4], orientation[5]);
    let unit = |v: DVec3| (v.length() - 1.0).abs() < 1e-3;
    if !unit(row) || !unit(col) || row.dot(col).abs() > 1e-3 {
        return Err(format!(
            "ImageOrientationPatient {orientation:?} is not two perpendicular unit vectors"
        ));
    }
    Ok((row.normalize(), col.normalize()))
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

/// Every slice must share the first slice's size, orientation and pixel spacing.
fn check_consistent(slices: &[SliceHeader]) -> Result<(), VolumeError> {
    let Some(first) = slices.first() else {
        return Ok(());
    };
    for slice in &slices[1..] {
        let problem = if (slice.rows, slice.columns) != (first.rows, first.columns) {
            "Rows x Columns"
        } else if !slice
            .row_dir
            .abs_diff_eq(first.row_dir, ORIENTATION_TOLERANCE)
            || !slice
                .col_dir
                .abs_diff_eq(first.col_dir, ORIENTATION_TOLERANCE)
        {
            "ImageOrientationPatient"
        } else if (0..2).any(|i| {
            let (a, b) = (slice.pixel_spacing[i], first.pixel_spacing[i]);
            (a - b).abs() > SPACING_TOLERANCE * b
        }) {
            "PixelSpacing"
        } else {
            continue;
        };
        let message = format!("{problem} differs from {} of the same series", first.name());
        let message = match slice.frame {
            Some(k) => format!("frame {}: {message}", k + 1),
            None => message,
        };
        return Err(dicom_error(&slice.path, message));
    }
    Ok(())
}

/// Sorts the slices along their normal and works out the grid's placement in RAS.
fn place_slices(dir: &Path, slices: &mut [SliceHeader]) -> Result<Placement, VolumeError> {
    let first = &slices[0];
    let normal = first.row_dir.cross(first.col_dir);
    let depth = |s: &SliceHeader| s.position.dot(normal);
    slices.sort_by(|a, b| {
        depth(a)
            .total_cmp(&depth(b))
            .then_with(|| a.path.cmp(&b.path))
            .then_with(|| a.frame.cmp(&b.frame))
    });
    let step = match slices {
        [only] => only.slice_thickness.unwrap_or(1.0),
        _ => slice_step(dir, slices, normal)?,
    };
    let first = &slices[0];
    let [dy, dx] = first.pixel_spacing;
    let lps_to_ras = DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0));
    Ok(Placement {
        spacing: [dx, dy, step],
        origin: (lps_to_ras * first.position).into(),
        direction: lps_to_ras * DMat3::from_cols(first.row_dir, first.col_dir, normal),
    })
}

/// The distance between consecutive slices, which must be the same all along the stack.
fn slice_step(dir: &Path, slices: &[SliceHeader], normal: DVec3) -> Result<f64, VolumeError> {
    let depths: Vec<f64> = slices.iter().map(|s| s.position.dot(normal)).collect();
    check_gaps(dir, slices, &depths)?;
    let step = (depths[depths.len() - 1] - depths[0]) / (depths.len() - 1) as f64;
    let origin = slices[0].position;
    for (k, slice) in slices.iter().enumerate() {
        let off = (slice.position - origin - normal * (step * k as f64)).length();
        if off > POSITION_TOLERANCE * step {
            let message = format!(
                "slice {} is {off:.3} mm from its place in an evenly spaced stack of {step:.3} mm \
                 steps (uneven spacing or gantry tilt, not supported)",
                slice.name()
            );
            return Err(dicom_error(dir, message));
        }
    }
    Ok(step)
}

/// Refuses two slices at one position, and a step well over the smallest one: a missing slice.
/// `depths` are the sorted slices' positions along the normal, the same in LPS and RAS since
/// the flip between them is a rotation.
fn check_gaps(dir: &Path, slices: &[SliceHeader], depths: &[f64]) -> Result<(), VolumeError> {
    let steps: Vec<f64> = depths.windows(2).map(|w| w[1] - w[0]).collect();
    let smallest = steps.iter().copied().fold(f64::INFINITY, f64::min);
    // Two slices at one position first: with a zero step, every other step looks like a gap.
    let Some(i) = steps
        .iter()
        .position(|&step| step <= 1e-6)
        .or_else(|| steps.iter().position(|&step| step > GAP_FACTOR * smallest))
    else {
        return Ok(());
    };
    let what = if steps[i] <= 1e-6 {
        // Every position held the same number of times: time points or repeated stacks.
        let positions = 1 + steps.iter().filter(|&&step| step > 1e-6).count();
        let each = slices.len() / positions;
        if positions > 1 && each > 1 && each * positions == slices.len() {
            format!(
                "{} slices at {positions} positions, {each} at each: several time points or                  stacks in one series, which one 3-D volume cannot hold (split the series,                  for example by acquisition or temporal position, first); two slices at the                  same position",
                slices.len()
            )
        } else {
            "two slices at the same position".to_owned()
        }
    } else {
        let missing = (steps[i] / smallest).round() - 1.0;
        format!(
            "missing slice: gap of {:.3} mm where the step is {smallest:.3} mm, so about \
             {missing} slice(s) missing",
            steps[i]
        )
    };
    let message = format!(
        "{what}, between {} at {:.3} mm and {} at {:.3} mm along the slice normal",
        slices[i].name(),
        depths[i],
        slices[i + 1].name(),
        depths[i + 1]
    );
    Err(dicom_error(dir, message))
}

/// The zeroed output, after checking its size against the grid limit and the files' bytes.
fn allocate<T: Modality>(
    dir: &Path,
    dims: [u32; 3],
    slices: &[SliceHeader],
) -> Result<Vec<T>, VolumeError> {
    let held = if size_of::<T>() == 2 {
        ScalarType::I16
    } else {
        ScalarType::F32
    };
    let count = checked_voxels(dir, dims, held)?;
    let file_bytes: u64 = slices.iter().map(|s| s.file_len).sum::<u64>().max(1);
    let out_bytes = count.saturating_mul(size_of::<T>() as u64);
    if out_bytes
        > file_bytes
            .saturating_mul(MAX_EXPANSION)
            .max(ALWAYS_ALLOWED_BYTES)
    {
        let message = format!(
            "{dims:?} voxels would need {out_bytes} bytes, more than {MAX_EXPANSION} times the \
             {file_bytes} bytes of its files"
        );
        return Err(dicom_error(dir, message));
    }
    let too_big = || dicom_error(dir, format!("cannot allocate {out_bytes} bytes"));
    let count = usize::try_from(count).map_err(|_| too_big())?;
    let mut values = Vec::new();
    values.try_reserve_exact(count).map_err(|_| too_big())?;
    values.resize(count, T::default());
    Ok(values)
}

/// Decodes the pixel data of one file and writes each of its slices (frames) into its place
/// (Rows x Columns values, rows in order); `false` when a value does not fit `T`.
fn decode_file<T: Modality>(path: &Path, outs: Vec<SliceOut<T>>) -> Result<bool, VolumeError> {
    guarded(path, || {
        let obj = open(path)?;
        let first = outs.first().map(|(s, _)| *s).ok_or("no slices")?;
        let frames = outs
            .iter()
            .filter_map(|(s, _)| s.frame)
            .max()
            .map_or(1, |k| k + 1);
        let voxels = usize::from(first.rows) * usize::from(first.columns);
        let decoded = obj.decode_pixel_data();
        let samples = match &decoded {
            Ok(pixels) => Samples::from_decoded(pixels, first, frames)?,
            Err(e) => {
                let message = describe("cannot decode pixel data", e);
                if obj.meta().transfer_syntax().trim_end_matches('\0') == RLE_LOSSLESS
                    && message.contains("BitsAllocated")
                {
                    // dicom-pixeldata's RLE decoder reads 8- and 16-bit samples only; RT dose
                    // grids store 32.
                    Samples::from_rle(&obj, voxels, frames)?
                } else if message.contains("SamplePrecision(12)") {
                    // jpeg-decoder reads 8-bit DCT data only; 12-bit goes to libjpeg-turbo.
                    let size = (usize::from(first.columns), usize::from(first.rows));
                    Samples::from_jpeg12(&obj, size, frames)?
                } else {
                    return Err(message);
                }
            }
        };
        let mut fits = true;
        for (slice, out) in outs {
            fits &= samples.modality_values(slice, out)?;
        }
        Ok(fits)
    })
}

/// The RLE Lossless transfer syntax.
const RLE_LOSSLESS: &str = "1.2.840.10008.1.2.5";

/// One file's decoded samples, little-endian, frame after frame.
struct Samples<'a> {
    data: std::borrow::Cow<'a, [u8]>,
    /// Bytes per sample.
    width: usize,
    /// Bits per sample that carry the value, from bit 0.
    stored: u32,
    signed: bool,
}

impl<'a> Samples<'a> {
    /// The samples `dicom-pixeldata` decoded, checked to hold at least `frames` frames of the
    /// slice's size with one grey sample per pixel.
    fn from_decoded(
        pixels: &'a DecodedPixelData,
        slice: &SliceHeader,
        frames: u32,
    ) -> Result<Self, String> {
        let size = (pixels.rows(), pixels.columns());
        let expected = (u32::from(slice.rows), u32::from(slice.columns));
        if size != expected || pixels.number_of_frames() < frames {
            return Err(format!(
                "decoded rows, columns {size:?} and {} frames differ from the header's \
                 {expected:?} and {frames}",
                pixels.number_of_frames()
            ));
        }
        if pixels.samples_per_pixel() != 1 || !pixels.photometric_interpretation().is_monochrome() {
            return Err("colour images are not supported".into());
        }
        let samples = Self::checked(
            pixels.data(),
            u32::from(pixels.bits_allocated()),
            u32::from(pixels.bits_stored()),
            u32::from(pixels.high_bit()),
            pixels.pixel_representation() == PixelRepresentation::Signed,
        )?;
        samples.check_len(size.0 as usize * size.1 as usize, frames)?;
        Ok(samples)
    }

    /// Samples from bytes and the bit layout, which must be one this loader reads.
    fn checked(
        data: impl Into<std::borrow::Cow<'a, [u8]>>,
        allocated: u32,
        stored: u32,
        high_bit: u32,
        signed: bool,
    ) -> Result<Self, String> {
        if !matches!(allocated, 8 | 16 | 32) || stored == 0 || stored > allocated {
            return Err(format!(
                "{stored} of {allocated} bits per sample is not supported"
            ));
        }
        if high_bit + 1 != stored {
            return Err("samples not aligned to bit 0 (HighBit != BitsStored - 1)".into());
        }
        Ok(Self {
            data: data.into(),
            width: allocated as usize / 8,
            stored,
            signed,
        })
    }

    /// The data must hold `frames` frames of `voxels` samples; more is padding (to an even
    /// length, or by the writer), which readers ignore.
    fn check_len(&self, voxels: usize, frames: u32) -> Result<(), String> {
        let size = self.data.len();
        let expected = voxels
            .checked_mul(self.width)
            .and_then(|b| b.checked_mul(frames as usize));
        if expected.is_none_or(|e| size < e) {
            return Err(format!(
                "decoded {size} bytes, but Rows x Columns x {frames} frame(s) x {} bytes is {}",
                self.width,
                voxels
                    .saturating_mul(self.width)
                    .saturating_mul(frames as usize)
            ));
        }
        Ok(())
    }

    /// Decodes RLE Lossless pixel data (DICOM PS3.5 annex G) of any sample width: each
    /// frame's fragment holds one PackBits segment per byte of the sample, most significant
    /// first. Written here for the 32-bit samples `dicom-pixeldata`'s decoder leaves out.
    fn from_rle(obj: &DefaultDicomObject, voxels: usize, frames: u32) -> Result<Self, String> {
        let allocated = u32::from(unsigned(obj, tags::BITS_ALLOCATED, "BitsAllocated")?);
        let stored = u32::from(unsigned(obj, tags::BITS_STORED, "BitsStored")?);
        let high_bit = obj
            .get(tags::HIGH_BIT)
            .and_then(|e| e.to_int::<u32>().ok())
            .unwrap_or(stored.saturating_sub(1));
        let samples_per_pixel = obj
            .get(tags::SAMPLES_PER_PIXEL)
            .and_then(|e| e.to_int::<u16>().ok())
            .unwrap_or(1);
        if samples_per_pixel != 1 {
            return Err("colour images are not supported".into());
        }
        let signed =
            unsigned(obj, tags::PIXEL_REPRESENTATION, "PixelRepresentation").ok() == Some(1);
        let width = allocated as usize / 8;
        let fragments = obj
            .get(tags::PIXEL_DATA)
            .and_then(|e| e.value().fragments())
            .ok_or("RLE pixel data without fragments")?;
        if fragments.len() < frames as usize {
            return Err(format!(
                "{} RLE fragments for {frames} frames",
                fragments.len()
            ));
        }
        let frame_bytes = voxels
            .checked_mul(width)
            .ok_or("the frame size overflows")?;
        let mut data = vec![0u8; frame_bytes * frames as usize];
        for (k, fragment) in fragments.iter().take(frames as usize).enumerate() {
            let frame = &mut data[k * frame_bytes..(k + 1) * frame_bytes];
            rle_frame(fragment, width, voxels, frame)
                .map_err(|m| format!("frame {}: {m}", k + 1))?;
        }
        Self::checked(data, allocated, stored, high_bit, signed)
    }

    /// The samples of 12-bit JPEG frames (see `volume::jpeg12`): one fragment a frame, or
    /// every fragment together for a file of one frame.
    #[cfg(feature = "codecs")]
    fn from_jpeg12(
        obj: &DefaultDicomObject,
        (columns, rows): (usize, usize),
        frames: u32,
    ) -> Result<Self, String> {
        let stored = u32::from(unsigned(obj, tags::BITS_STORED, "BitsStored")?);
        if !(9..=12).contains(&stored) {
            return Err(format!(
                "BitsStored {stored} in a 12-bit JPEG (Extended) file"
            ));
        }
        let signed =
            unsigned(obj, tags::PIXEL_REPRESENTATION, "PixelRepresentation").ok() == Some(1);
        let fragments = obj
            .get(tags::PIXEL_DATA)
            .and_then(|e| e.value().fragments())
            .ok_or("JPEG pixel data without fragments")?;
        let frames_data: Vec<std::borrow::Cow<'_, [u8]>> = if fragments.len() == frames as usize {
            fragments.iter().map(|f| f.as_slice().into()).collect()
        } else if frames == 1 {
            vec![fragments.concat().into()]
        } else {
            return Err(format!(
                "{} JPEG fragments for {frames} frames",
                fragments.len()
            ));
        };
        let mut data = Vec::new();
        for (k, frame) in frames_data.iter().enumerate() {
            super::jpeg12::decode_frame(frame, columns, rows, &mut data)
                .map_err(|m| format!("frame {}: {m}", k + 1))?;
        }
        Self::checked(data, 16, stored, stored - 1, signed)
    }

    /// 12-bit JPEG needs libjpeg-turbo, which this build leaves out.
    #[cfg(not(feature = "codecs"))]
    fn from_jpeg12(
        _obj: &DefaultDicomObject,
        _size: (usize, usize),
        _frames: u32,
    ) -> Result<Self, String> {
        Err(
            "12-bit JPEG needs the C codecs, which this build of splatscene leaves out \
             (the `codecs` feature)"
                .into(),
        )
    }

    /// Converts one slice's samples to modality values (HU for CT) with its rescale. Samples
    /// are read little-endian: the codecs write them so, and native pixel data come in the
    /// machine's order, which is little-endian on the x86-64 and aarch64 targets of this
    /// project.
    /// `false` (and the slice left part written) when a value does not fit `T`.
    fn modality_values<T: Modality>(
        &self,
        slice: &SliceHeader,
        out: &mut [T],
    ) -> Result<bool, String> {
        if !(slice.slope.is_finite() && slice.intercept.is_finite()) {
            return Err(format!(
                "rescale slope {} or intercept {} is not finite",
                slice.slope, slice.intercept
            ));
        }
        // The stored range's ends, rescaled, must be f32 numbers: a slope that takes a sample
        // to infinity is refused here, not drawn as infinite values.
        let (lo, hi) = if self.signed {
            (
                -(2f64.powi(self.stored as i32 - 1)),
                2f64.powi(self.stored as i32 - 1) - 1.0,
            )
        } else {
            (0.0, 2f64.powi(self.stored as i32) - 1.0)
        };
        for end in [lo, hi] {
            let v = end * slice.slope + slice.intercept;
            if !(v.is_finite() && v.abs() <= f64::from(f32::MAX)) {
                return Err(format!(
                    "rescale slope {} and intercept {} take the stored value {end} to {v:e}, past what a 32-bit float holds",
                    slice.slope, slice.intercept
                ));
            }
        }
        let frame_bytes = out.len() * self.width;
        let start = slice.frame.unwrap_or(0) as usize * frame_bytes;
        let data = self
            .data
            .get(start..start + frame_bytes)
            .ok_or("the decoded data end before this frame")?;
        // Shifting the stored bits to the top and back drops any bits above them (old overlay
        // planes) and, for signed samples, extends the sign.
        let shift = 32 - self.stored;
        for (value, bytes) in out.iter_mut().zip(data.chunks_exact(self.width)) {
            let mut word = [0u8; 4];
            word[..self.width].copy_from_slice(bytes);
            let top = u32::from_le_bytes(word) << shift;
            let sample = if self.signed {
                f64::from((top as i32) >> shift)
            } else {
                f64::from(top >> shift)
            };
            match T::from_modality(sample * slice.slope + slice.intercept) {
                Some(v) => *value = v,
                None => return Ok(false),
            }
        }
        Ok(true)
    }
}

/// Decodes one RLE frame into `out` (`voxels` little-endian samples of `width` bytes).
fn rle_frame(fragment: &[u8], width: usize, voxels: usize, out: &mut [u8]) -> Result<(), String> {
    let word = |i: usize| -> Option<usize> {
        let b: [u8; 4] = fragment.get(4 * i..4 * i + 4)?.try_into().ok()?;
        Some(u32::from_le_bytes(b) as usize)
    };
    let segments = word(0).ok_or("no RLE header")?;
    if segments != width {
        return Err(format!("{segments} RLE segments for {width}-byte samples"));
    }
    for segment in 0..segments {
        let start = word(1 + segment).ok_or("short RLE header")?;
        let end = match segment + 1 < segments {
            true => word(2 + segment).ok_or("short RLE header")?,
            false => fragment.len(),
        };
        let coded = fragment
            .get(start..end)
            .ok_or("an RLE segment runs past its fragment")?;
        // Segment 0 holds the most significant bytes; little-endian puts them last.
        let byte = width - 1 - segment;
        let mut written = 0usize;
        let mut at = 0usize;
        let mut put = |value: u8, written: &mut usize| {
            if *written < voxels {
                out[*written * width + byte] = value;
            }
            *written += 1;
        };
        while at < coded.len() && written < voxels {
            let n = coded[at] as i8;
            at += 1;
            if n >= 0 {
                let run = coded
                    .get(at..at + n as usize + 1)
                    .ok_or("an RLE literal run past the segment")?;
                for &b in run {
                    put(b, &mut written);
                }
                at += n as usize + 1;
            } else if n != -128 {
                let b = *coded.get(at).ok_or("an RLE repeat past the segment")?;
                at += 1;
                for _ in 0..(1 - n as isize) {
                    put(b, &mut written);
                }
            }
        }
        if written < voxels {
            return Err(format!(
                "RLE segment {segment} decodes to {written} of {voxels} bytes"
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bare_data_sets_are_told_by_their_first_two_elements() {
        // (0008,0005) CS "ISO_IR 100" then (0008,0008): explicit VR little endian.
        let mut explicit = vec![0x08, 0x00, 0x05, 0x00, b'C', b'S', 10, 0];
        explicit.extend(b"ISO_IR 100");
        explicit.extend([0x08, 0x00, 0x08, 0x00]);
        assert_eq!(
            bare_data_set(&explicit),
            Some(uids::EXPLICIT_VR_LITTLE_ENDIAN)
        );
        // The same implicit: a 4-byte length after the tag.
        let mut implicit = vec![0x08, 0x00, 0x05, 0x00, 10, 0, 0, 0];
        implicit.extend(b"ISO_IR 100");
        implicit.extend([0x08, 0x00, 0x08, 0x00]);
        assert_eq!(
            bare_data_set(&implicit),
            Some(uids::IMPLICIT_VR_LITTLE_ENDIAN)
        );
        // Big endian, explicit VR.
        let mut big = vec![0x00, 0x08, 0x00, 0x05, b'C', b'S', 0, 10];
        big.extend(b"ISO_IR 100");
        big.extend([0x00, 0x08, 0x00, 0x08]);
        assert_eq!(bare_data_set(&big), Some("1.2.840.10008.1.2.2"));
        assert!(is_dicom(&big));
        // Raw samples that happen to start with 8 do not pass: the second element is not
        // where the first one's length puts it.
        let raw: Vec<u8> = [8u16, 0, 5, 0, 300, 301, 302, 303, 304]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        assert_eq!(bare_data_set(&raw), None);
        assert!(!is_dicom(&raw));
        assert!(!is_dicom(&explicit[..12]));
    }

    #[test]
    fn sixteen_bit_modality_values_are_exact_integers_in_range() {
        assert_eq!(i16::from_modality(-1024.0), Some(-1024));
        assert_eq!(i16::from_modality(32767.0), Some(i16::MAX));
        assert_eq!(i16::from_modality(-32768.0), Some(i16::MIN));
        for wide in [32768.0, -32769.0, 0.5, f64::NAN, f64::INFINITY] {
            assert_eq!(i16::from_modality(wide), None, "{wide}");
        }
        assert_eq!(f32::from_modality(0.25), Some(0.25));
    }

    #[test]
    fn rle_segments_decode_to_little_endian_samples() {
        // Two 32-bit samples, 0x01020304 and 0x0A0B0C0D: four segments, most significant
        // byte first, each a literal run of 2 (or a repeat run).
        let segments: [&[u8]; 4] = [
            &[1, 0x01, 0x0A],
            &[1, 0x02, 0x0B],
            &[1, 0x03, 0x0C],
            &[0xff, 0x04],
        ];
        let mut fragment = vec![0u8; 64];
        fragment[..4].copy_from_slice(&4u32.to_le_bytes());
        for (i, segment) in segments.iter().enumerate() {
            let at = fragment.len() as u32;
            fragment[4 + 4 * i..8 + 4 * i].copy_from_slice(&at.to_le_bytes());
            fragment.extend(*segment);
        }
        let mut out = [0u8; 8];
        rle_frame(&fragment, 4, 2, &mut out).unwrap();
        // The last segment repeats 0x04 twice.
        assert_eq!(u32::from_le_bytes(out[..4].try_into().unwrap()), 0x01020304);
        assert_eq!(u32::from_le_bytes(out[4..].try_into().unwrap()), 0x0A0B0C04);
        let err = rle_frame(&fragment[..66], 4, 2, &mut out).unwrap_err();
        assert!(err.contains("RLE"), "{err}");
        let err = rle_frame(&fragment, 2, 2, &mut [0u8; 4]).unwrap_err();
        assert!(err.contains("4 RLE segments for 2-byte samples"), "{err}");
    }
}
