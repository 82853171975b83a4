//! DICOM series: a folder of single-frame slice images (CT, MR) loaded as one [`CpuVolume`].
//!
//! **Which files.** Every regular file in the folder (not its subfolders) whose bytes carry the
//! `DICM` magic after the 128-byte preamble is read; other files are skipped. DICOM files without
//! pixel data (a `DICOMDIR`, structured reports, presentation states) are skipped as well; the
//! `DICOMDIR` index is not used to find files. A DICOM file that cannot be parsed or decoded
//! fails the whole load rather than leaving a hole in the volume.
//!
//! **Which series.** Images are grouped by SeriesInstanceUID. A folder holding one series
//! loads it; a folder holding several is [`VolumeError::DicomSeries`], which lists them
//! (number, description, modality, size, image count, UID) until one is chosen by
//! SeriesNumber or UID ([`SeriesChoice`]); a single file given instead of its folder chooses its
//! own series. Images of the other series are ignored even when they could not be slices (a
//! dose report saved as a secondary capture without a position, a multi-frame image), but every
//! image of the loaded series must be a usable slice.
//!
//! **Geometry.** Slices are ordered by their ImagePositionPatient projected on the slice normal,
//! the cross product of the ImageOrientationPatient row and column directions. The grid's x axis
//! runs along a row (column index), y down the columns (row index) and z along the normal, so
//! `dims = [Columns, Rows, slices]` and `spacing = [PixelSpacing[1], PixelSpacing[0], step]`:
//! PixelSpacing lists the distance between rows first. The origin is the position of the first
//! slice. Every slice must lie on the line `origin + k * step * normal` to within a tenth of a
//! step; a gap of about two or more steps is reported as a missing slice, and a stack sheared by
//! gantry tilt is refused rather than placed wrongly. A lone slice takes its SliceThickness
//! (1 mm when absent) as the z spacing.
//!
//! **World frame.** DICOM patient coordinates are LPS (+x toward the patient's left, +y
//! posterior, +z head); this project's world is RAS (+x toward the patient's right, +y anterior,
//! +z head), as in NIfTI. Positions and direction vectors are converted by negating x and y.
//! Because that flip has determinant +1, the converted normal is still the cross product of the
//! converted row and column directions.
//!
//! **Values.** Pixel data are decoded with `dicom-pixeldata` (native, RLE, JPEG baseline and
//! lossless, JPEG 2000 via the pure-Rust `openjp2`), then mapped through each slice's own
//! RescaleSlope and RescaleIntercept: Hounsfield units for CT. No window or VOI LUT is applied.
//!
//! **Not supported:** multi-frame (enhanced) images, colour images, files without the 128-byte
//! preamble and `DICM` magic, slices of one series with different sizes, orientations or pixel
//! spacings, and transfer syntaxes this build has no decoder for (JPEG-LS, JPEG XL, deflate).

use std::collections::BTreeMap;
use std::fs::{self, File};
use std::io::Read;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

use dicom_dictionary_std::tags;
use dicom_object::{DefaultDicomObject, OpenFileOptions, Tag};
use dicom_pixeldata::{DecodedPixelData, PixelDecoder, PixelRepresentation};
use glam::{DMat3, DVec3};

use super::raw::ScalarType;
use rayon::prelude::*;

use super::CpuVolume;
use super::raw::VolumeError;
use crate::grid::voxel_count;

/// Bytes before the `DICM` magic in a DICOM file.
const PREAMBLE_LEN: usize = 128;
/// The magic that marks a DICOM file (DICOM PS3.10, section 7.1).
const MAGIC: &[u8; 4] = b"DICM";
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

/// Whether `bytes` (the start of a file, at least 132 bytes) carry the DICOM `DICM` magic after
/// the 128-byte preamble.
pub fn is_dicom(bytes: &[u8]) -> bool {
    bytes.get(PREAMBLE_LEN..PREAMBLE_LEN + MAGIC.len()) == Some(MAGIC.as_slice())
}

/// A DICOM file with pixel data: its series, and its slice header or why it cannot be a slice.
struct Image {
    series: String,
    tags: SeriesTags,
    slice: Result<SliceHeader, VolumeError>,
}

/// What a file says about its series, for listing.
#[derive(Debug, Clone, Default, PartialEq)]
struct SeriesTags {
    number: Option<String>,
    description: Option<String>,
    modality: Option<String>,
}

/// One series of a folder, as [`list_series`] finds it.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SeriesSummary {
    /// The folder holding it.
    pub folder: PathBuf,
    /// SeriesInstanceUID (empty when the files have none).
    pub uid: String,
    /// SeriesNumber.
    pub number: Option<String>,
    /// SeriesDescription.
    pub description: Option<String>,
    /// Modality (CT, MR...).
    pub modality: Option<String>,
    /// Columns and rows of its first usable slice.
    pub size: Option<[u16; 2]>,
    /// Image files in it.
    pub images: usize,
}

/// Which series of a folder to load: `NUMBER` (SeriesNumber) or a SeriesInstanceUID.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SeriesChoice(pub String);

impl SeriesChoice {
    fn matches(&self, uid: &str, tags: &SeriesTags) -> bool {
        self.0 == uid || tags.number.as_deref() == Some(self.0.trim())
    }
}

/// The series as lines for a message: number, description, modality, size and image count.
pub fn describe_series(series: &[SeriesSummary]) -> String {
    series
        .iter()
        .map(|s| {
            let size = s.size.map_or("?".into(), |[c, r]| format!("{c}x{r}"));
            format!(
                "  series {} {:?} {} {size}, {} images, UID {}",
                s.number.as_deref().unwrap_or("-"),
                s.description.as_deref().unwrap_or(""),
                s.modality.as_deref().unwrap_or("?"),
                s.images,
                s.uid
            )
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// What one image file says about its slice, read before any pixel is decoded.
#[derive(Debug, Clone)]
struct SliceHeader {
    path: PathBuf,
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
    file_len: u64,
    /// The stored value type (BitsAllocated and PixelRepresentation), when it is one of ours.
    stored: Option<ScalarType>,
}

/// Where the ordered slices sit in the RAS world.
struct Placement {
    spacing: [f64; 3],
    origin: [f64; 3],
    direction: DMat3,
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
    load_dicom_series_choosing(dir, None)
}

/// [`load_dicom_series_with_type`], loading the series `choice` names when the folder holds
/// several ([`VolumeError::DicomSeries`] lists them when none is chosen).
pub fn load_dicom_series_choosing(
    dir: &Path,
    choice: Option<&SeriesChoice>,
) -> Result<(CpuVolume, Option<ScalarType>), VolumeError> {
    let paths = dicom_files(dir)?;
    let read: Vec<_> = paths.par_iter().map(|p| read_image(p)).collect();
    let (images, unreadable): (Vec<_>, Vec<_>) = read.into_iter().partition(Result::is_ok);
    let images: Vec<Image> = images
        .into_iter()
        .filter_map(Result::ok)
        .flatten()
        .collect();
    // A file that cannot be parsed belongs to no known series: it fails the load only when
    // nothing else in the folder is an image.
    if let Some(Err(first)) = unreadable.into_iter().next() {
        if images.is_empty() {
            return Err(first);
        }
        eprintln!("note: ignored a file that is not readable DICOM: {first}");
    }
    let mut slices = select_series(dir, images, choice)?;
    check_consistent(&slices)?;
    let placement = place_slices(dir, &mut slices)?;
    let first = &slices[0];
    let count = u32::try_from(slices.len()).map_err(|_| dicom_error(dir, "too many slices"))?;
    let dims = [u32::from(first.columns), u32::from(first.rows), count];
    let mut values = allocate(dir, dims, &slices)?;
    let plane = values.len() / slices.len();
    let decoded: Vec<_> = values
        .par_chunks_mut(plane)
        .zip(slices.par_iter())
        .map(|(out, slice)| decode_slice(slice, out))
        .collect();
    first_error(decoded)?;
    let volume = CpuVolume {
        dims,
        spacing: placement.spacing,
        origin: placement.origin,
        direction: placement.direction,
        values,
    };
    Ok((volume, slices[0].stored))
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

fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> VolumeError + '_ {
    move |source| VolumeError::Io {
        path: path.into(),
        source,
    }
}

fn name(path: &Path) -> String {
    path.file_name()
        .unwrap_or(path.as_os_str())
        .to_string_lossy()
        .into_owned()
}

/// The regular files in `dir` with the DICOM magic, sorted by name.
fn dicom_files(dir: &Path) -> Result<Vec<PathBuf>, VolumeError> {
    let mut paths = Vec::new();
    for entry in fs::read_dir(dir).map_err(io_error(dir))? {
        let path = entry.map_err(io_error(dir))?.path();
        // Follows symlinks, so a linked slice counts like a copied one.
        if fs::metadata(&path).map_err(io_error(&path))?.is_file() && has_magic(&path)? {
            paths.push(path);
        }
    }
    paths.sort();
    Ok(paths)
}

/// Reads only the preamble and magic, so large non-DICOM files in the folder cost nothing.
fn has_magic(path: &Path) -> Result<bool, VolumeError> {
    let mut start = Vec::with_capacity(PREAMBLE_LEN + MAGIC.len());
    File::open(path)
        .and_then(|f| f.take(start.capacity() as u64).read_to_end(&mut start))
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

fn open(path: &Path) -> Result<DefaultDicomObject, String> {
    OpenFileOptions::new()
        .open_file(path)
        .map_err(|e| describe("cannot parse DICOM", &e))
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
        let series = optional_text(&obj, tags::SERIES_INSTANCE_UID).unwrap_or_default();
        let tags = SeriesTags {
            number: optional_text(&obj, tags::SERIES_NUMBER).filter(|t| !t.is_empty()),
            description: optional_text(&obj, tags::SERIES_DESCRIPTION).filter(|t| !t.is_empty()),
            modality: optional_text(&obj, tags::MODALITY).filter(|t| !t.is_empty()),
        };
        let slice = slice_header(&obj, path, file_len).map_err(|m| dicom_error(path, m));
        Ok(Some(Image {
            series,
            tags,
            slice,
        }))
    })
}

fn slice_header(
    obj: &DefaultDicomObject,
    path: &Path,
    file_len: u64,
) -> Result<SliceHeader, String> {
    let frames = optional_text(obj, tags::NUMBER_OF_FRAMES).unwrap_or_default();
    if !matches!(frames.as_str(), "" | "1") {
        return Err(format!(
            "{frames} frames: multi-frame images are not supported"
        ));
    }
    let orientation = floats::<6>(
        obj,
        tags::IMAGE_ORIENTATION_PATIENT,
        "ImageOrientationPatient",
    )?;
    let (row_dir, col_dir) = unit_axes(orientation)?;
    let position = floats::<3>(obj, tags::IMAGE_POSITION_PATIENT, "ImagePositionPatient")?;
    let pixel_spacing = floats::<2>(obj, tags::PIXEL_SPACING, "PixelSpacing")?;
    if pixel_spacing.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
        return Err(format!("PixelSpacing {pixel_spacing:?} is not positive"));
    }
    let slice_thickness = floats::<1>(obj, tags::SLICE_THICKNESS, "SliceThickness")
        .ok()
        .map(|[t]| t)
        .filter(|t| t.is_finite() && *t > 0.0);
    let bits = unsigned(obj, tags::BITS_ALLOCATED, "BitsAllocated").ok();
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
    Ok(SliceHeader {
        stored,
        path: path.into(),
        rows: unsigned(obj, tags::ROWS, "Rows")?,
        columns: unsigned(obj, tags::COLUMNS, "Columns")?,
        row_dir,
        col_dir,
        position: DVec3::from(position),
        pixel_spacing,
        slice_thickness,
        file_len,
    })
}

/// A text attribute without DICOM's space or NUL padding; `None` when absent or unreadable.
fn optional_text(obj: &DefaultDicomObject, tag: Tag) -> Option<String> {
    let value = obj.get(tag)?.to_str().ok()?;
    Some(value.trim_matches(['\0', ' ']).to_owned())
}

fn unsigned(obj: &DefaultDicomObject, tag: Tag, name: &str) -> Result<u16, String> {
    let element = obj.get(tag).ok_or_else(|| format!("no {name}"))?;
    match element.to_int::<u16>() {
        Ok(0) | Err(_) => Err(format!("{name} is not a positive 16-bit number")),
        Ok(n) => Ok(n),
    }
}

/// Exactly `N` finite numbers from a decimal-string attribute.
fn floats<const N: usize>(
    obj: &DefaultDicomObject,
    tag: Tag,
    name: &str,
) -> Result<[f64; N], String> {
    let element = obj.get(tag).ok_or_else(|| format!("no {name}"))?;
    let values = element
        .to_multi_float64()
        .map_err(|e| format!("{name} is not numeric: {e}"))?;
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

/// The slices of the series with the most usable slices (ties: the UID that sorts first), all
/// of whose images must be usable slices.
fn select_series(
    dir: &Path,
    images: Vec<Image>,
    choice: Option<&SeriesChoice>,
) -> Result<Vec<SliceHeader>, VolumeError> {
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
                .filter(|&i| c.matches(&groups[i].0, &groups[i].1[0].tags))
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
    groups
        .swap_remove(index)
        .1
        .into_iter()
        .map(|image| image.slice)
        .collect()
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
        size: images
            .iter()
            .find_map(|i| i.slice.as_ref().ok().map(|s| [s.columns, s.rows])),
        images: images.len(),
    }
}

/// The series of DICOM images in `dir` (not its subfolders), without decoding any pixel data.
/// Files that cannot be read as DICOM are left out here; loading the folder reports them.
pub fn list_series(dir: &Path) -> Result<Vec<SeriesSummary>, VolumeError> {
    let paths = dicom_files(dir)?;
    let images: Vec<Image> = paths
        .par_iter()
        .filter_map(|p| read_image(p).ok().flatten())
        .collect();
    Ok(group_series(images)
        .iter()
        .map(|(uid, g)| summary(dir, uid, g))
        .collect())
}

/// The SeriesInstanceUID of one DICOM file, so that a file given alone loads its own series.
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
        let message = format!(
            "{problem} differs from {} of the same series",
            name(&first.path)
        );
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
                name(&slice.path)
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
    let bad = |step: f64| step <= 1e-6 || step > GAP_FACTOR * smallest;
    let Some(i) = steps.iter().position(|&step| bad(step)) else {
        return Ok(());
    };
    let what = if steps[i] <= 1e-6 {
        "two slices at the same position".to_owned()
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
        name(&slices[i].path),
        depths[i],
        name(&slices[i + 1].path),
        depths[i + 1]
    );
    Err(dicom_error(dir, message))
}

/// The zeroed output, after checking its size against the grid limit and the files' bytes.
fn allocate(dir: &Path, dims: [u32; 3], slices: &[SliceHeader]) -> Result<Vec<f32>, VolumeError> {
    let count = voxel_count(dims).map_err(|source| VolumeError::Grid {
        path: dir.into(),
        source,
    })?;
    let file_bytes: u64 = slices.iter().map(|s| s.file_len).sum();
    let out_bytes = count.saturating_mul(size_of::<f32>() as u64);
    if out_bytes > file_bytes.saturating_mul(MAX_EXPANSION) {
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
    values.resize(count, 0.0);
    Ok(values)
}

/// Decodes one slice's pixel data into `out` (Rows x Columns values, rows in order).
fn decode_slice(slice: &SliceHeader, out: &mut [f32]) -> Result<(), VolumeError> {
    guarded(&slice.path, || {
        let obj = open(&slice.path)?;
        let pixels = obj
            .decode_pixel_data()
            .map_err(|e| describe("cannot decode pixel data", &e))?;
        let size = (pixels.rows(), pixels.columns(), pixels.number_of_frames());
        let expected = (u32::from(slice.rows), u32::from(slice.columns), 1);
        if size != expected {
            return Err(format!(
                "decoded rows, columns, frames {size:?} differ from the header's {expected:?}"
            ));
        }
        if pixels.samples_per_pixel() != 1 || !pixels.photometric_interpretation().is_monochrome() {
            return Err("colour images are not supported".into());
        }
        modality_values(&pixels, out)
    })
}

/// How to read one slice's decoded samples.
struct SampleFormat {
    /// Bytes per sample.
    width: usize,
    /// Bits per sample that carry the value, from bit 0.
    stored: u32,
    signed: bool,
    slope: f64,
    intercept: f64,
}

/// The sample format of a decoded single-sample slice, checked against its `voxels` count.
fn sample_format(pixels: &DecodedPixelData, voxels: usize) -> Result<SampleFormat, String> {
    let allocated = u32::from(pixels.bits_allocated());
    let stored = u32::from(pixels.bits_stored());
    if !matches!(allocated, 8 | 16 | 32) || stored == 0 || stored > allocated {
        return Err(format!(
            "{stored} of {allocated} bits per sample is not supported"
        ));
    }
    if u32::from(pixels.high_bit()) + 1 != stored {
        return Err("samples not aligned to bit 0 (HighBit != BitsStored - 1)".into());
    }
    let width = allocated as usize / 8;
    let size = pixels.data().len();
    if Some(size) != voxels.checked_mul(width) {
        return Err(format!(
            "decoded {size} bytes, but Rows x Columns x 1 sample x {width} bytes is {}",
            voxels.saturating_mul(width)
        ));
    }
    let rescale = pixels.rescale().map_err(|e| describe("bad rescale", &e))?;
    let (slope, intercept) = rescale
        .first()
        .map_or((1.0, 0.0), |r| (r.slope, r.intercept));
    if !(slope.is_finite() && intercept.is_finite()) {
        return Err(format!(
            "rescale slope {slope} or intercept {intercept} is not finite"
        ));
    }
    let signed = pixels.pixel_representation() == PixelRepresentation::Signed;
    Ok(SampleFormat {
        width,
        stored,
        signed,
        slope,
        intercept,
    })
}

/// Converts decoded samples to modality values (HU for CT) with the slice's rescale. Samples
/// are read little-endian: the codecs write them so, and native pixel data come in the
/// machine's order, which is little-endian on the x86-64 and aarch64 targets of this project.
fn modality_values(pixels: &DecodedPixelData, out: &mut [f32]) -> Result<(), String> {
    let format = sample_format(pixels, out.len())?;
    // Shifting the stored bits to the top and back drops any bits above them (old overlay
    // planes) and, for signed samples, extends the sign.
    let shift = 32 - format.stored;
    for (value, bytes) in out.iter_mut().zip(pixels.data().chunks_exact(format.width)) {
        let mut word = [0u8; 4];
        word[..format.width].copy_from_slice(bytes);
        let top = u32::from_le_bytes(word) << shift;
        let sample = if format.signed {
            f64::from((top as i32) >> shift)
        } else {
            f64::from(top >> shift)
        };
        *value = (sample * format.slope + format.intercept) as f32;
    }
    Ok(())
}
