//! Loads the shared clinical CT series with `volume::dicom` and checks it against values read
//! here straight from the files with `dicom-object` and `dicom-pixeldata`; then feeds the loader
//! damaged copies of the series, which must give typed errors rather than panics.
//!
//! The data live outside the repository: `$SPLATSCENE_DATA`, by default `../shared/data` next to
//! the crate. Tests that need the series print a note and pass when its folder is missing.
//!
//! Attribution: `volumes/totalseg_ct/example_ct_dicom` is the example CT series from the
//! TotalSegmentator tests (Wasserthal et al.), Apache-2.0.

use std::fs;
use std::path::{Path, PathBuf};
use std::time::Instant;

use dicom_dictionary_std::{tags, uids};
use dicom_object::{FileMetaTableBuilder, InMemDicomObject, open_file};
use dicom_pixeldata::PixelDecoder;
use glam::{DMat3, DVec3};
use splatscene::volume::dicom::{is_dicom, load_dicom_series};
use splatscene::volume::{CpuVolume, VolumeError};

mod common;
use common::{Scratch, scratch};

fn series_dir() -> Option<PathBuf> {
    common::data_file("volumes/totalseg_ct/example_ct_dicom")
}

fn series_files(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = fs::read_dir(dir)
        .expect("list series")
        .map(|e| e.expect("list series").path())
        .collect();
    files.sort();
    files
}

/// One file's placement, read independently of the loader.
struct Header {
    path: PathBuf,
    /// ImagePositionPatient, LPS.
    position: DVec3,
    /// ImageOrientationPatient row and column directions, LPS.
    row: DVec3,
    col: DVec3,
    /// PixelSpacing: between rows, between columns.
    pixel_spacing: [f64; 2],
}

fn header(path: &Path) -> Header {
    let obj = open_file(path).expect("open series file");
    let floats = |tag| {
        obj.element(tag)
            .expect("attribute")
            .to_multi_float64()
            .expect("numbers")
    };
    let (ipp, iop, ps) = (
        floats(tags::IMAGE_POSITION_PATIENT),
        floats(tags::IMAGE_ORIENTATION_PATIENT),
        floats(tags::PIXEL_SPACING),
    );
    Header {
        path: path.into(),
        position: DVec3::from_slice(&ipp),
        row: DVec3::from_slice(&iop[..3]),
        col: DVec3::from_slice(&iop[3..]),
        pixel_spacing: [ps[0], ps[1]],
    }
}

/// The series' headers from the lowest to the highest position along the slice normal.
fn headers_in_order(dir: &Path) -> Vec<Header> {
    let mut headers: Vec<Header> = series_files(dir).iter().map(|p| header(p)).collect();
    let normal = headers[0].row.cross(headers[0].col);
    headers.sort_by(|a, b| a.position.dot(normal).total_cmp(&b.position.dot(normal)));
    headers
}

fn lps_to_ras(v: DVec3) -> DVec3 {
    DVec3::new(-v.x, -v.y, v.z)
}

fn world(volume: &CpuVolume, index: [f64; 3]) -> DVec3 {
    DVec3::from(volume.origin)
        + volume.direction * (DVec3::from(volume.spacing) * DVec3::from(index))
}

fn block_mean(
    volume: &CpuVolume,
    z: usize,
    xs: std::ops::Range<usize>,
    ys: std::ops::Range<usize>,
) -> f64 {
    let [nx, ny, _] = volume.dims.map(|n| n as usize);
    let ids = ys.flat_map(|y| xs.clone().map(move |x| x + nx * (y + ny * z)));
    let (sum, count) = ids.fold((0.0, 0), |(s, n), id| {
        (s + f64::from(volume.values.at(id)), n + 1)
    });
    sum / f64::from(count)
}

#[test]
fn shared_series_loads_with_its_geometry() {
    let Some(dir) = series_dir() else { return };
    let start = Instant::now();
    let volume = load_dicom_series(&dir).expect("load the shared series");
    eprintln!(
        "loaded 512x512x20 JPEG 2000 series in {:?}",
        start.elapsed()
    );

    assert_eq!(volume.dims, [512, 512, 20]);
    assert_eq!(volume.values.len(), 512 * 512 * 20);
    let headers = headers_in_order(&dir);
    let (first, last) = (&headers[0], &headers[headers.len() - 1]);
    // PixelSpacing lists the distance between rows (y) first.
    assert_eq!(volume.spacing[0], first.pixel_spacing[1]);
    assert_eq!(volume.spacing[1], first.pixel_spacing[0]);
    assert!((volume.spacing[0] - 0.977).abs() < 1e-3 && (volume.spacing[2] - 2.0).abs() < 1e-9);

    let expected = DMat3::from_cols(
        lps_to_ras(first.row),
        lps_to_ras(first.col),
        lps_to_ras(first.row.cross(first.col)),
    );
    assert!(
        volume.direction.abs_diff_eq(expected, 1e-12),
        "{:?}",
        volume.direction
    );
    // This series is axial with identity orientation in LPS, so RAS flips x and y.
    assert_eq!(
        volume.direction,
        DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0))
    );
    assert!(DVec3::from(volume.origin).abs_diff_eq(lps_to_ras(first.position), 1e-9));
    let top = world(&volume, [0.0, 0.0, 19.0]);
    assert!(
        top.abs_diff_eq(lps_to_ras(last.position), 1e-9),
        "{top} vs {}",
        last.position
    );
    for (k, h) in headers.iter().enumerate() {
        let placed = world(&volume, [0.0, 0.0, k as f64]);
        assert!(
            placed.abs_diff_eq(lps_to_ras(h.position), 1e-6),
            "slice {k}"
        );
    }
}

#[test]
fn shared_series_values_are_hounsfield_units_in_slice_order() {
    let Some(dir) = series_dir() else { return };
    let volume = load_dicom_series(&dir).expect("load the shared series");
    let plane = 512 * 512;
    // Decode each file with dicom-pixeldata's own modality LUT: an independent path to HU.
    for (k, h) in headers_in_order(&dir).iter().enumerate() {
        let obj = open_file(&h.path).expect("open slice");
        let hu: Vec<f32> = obj
            .decode_pixel_data()
            .and_then(|p| p.to_vec())
            .expect("decode slice");
        assert!(
            hu == volume.values.to_f32_vec()[k * plane..(k + 1) * plane],
            "slice {k}"
        );
    }

    let corner = block_mean(&volume, 10, 0..32, 0..32);
    let above_patient = block_mean(&volume, 10, 224..288, 64..96);
    eprintln!("corner {corner:.1} HU, air above the patient {above_patient:.1} HU");
    assert!((-1100.0..=-900.0).contains(&corner), "corner {corner}");
    assert!(
        (-1050.0..=-950.0).contains(&above_patient),
        "air {above_patient}"
    );
    let (min, max) = volume
        .values
        .iter()
        .fold((f32::MAX, f32::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let bone = volume.values.iter().filter(|&v| v > 300.0).count() as f64;
    let share = bone / volume.values.len() as f64;
    eprintln!("HU range {min}..{max}, {:.2}% above 300 HU", share * 100.0);
    assert!(min >= -1100.0 && max > 300.0 && max < 4000.0);
    assert!((0.002..0.2).contains(&share), "share above 300 HU: {share}");
}

#[test]
fn magic_is_checked_at_offset_128() {
    let mut bytes = vec![0u8; 132];
    assert!(!is_dicom(&bytes));
    bytes[128..].copy_from_slice(b"DICM");
    assert!(is_dicom(&bytes));
    assert!(!is_dicom(&bytes[..131]));
    // Without the preamble the magic starts the file.
    assert!(is_dicom(b"DICM"));
    assert!(!is_dicom(b"DICX"));
}

/// A CT instance with position and orientation but no PixelData, built in memory.
fn write_no_pixel_file(path: &Path, series: &str) {
    // dicom-core is not a direct dependency, so VR values come from their names.
    let vr = |name: &str| name.parse().expect("a VR name");
    let mut obj = InMemDicomObject::new_empty();
    obj.put_str(tags::SOP_CLASS_UID, vr("UI"), uids::CT_IMAGE_STORAGE);
    obj.put_str(tags::SOP_INSTANCE_UID, vr("UI"), "2.25.1001");
    obj.put_str(tags::SERIES_INSTANCE_UID, vr("UI"), series);
    obj.put_str(tags::MODALITY, vr("CS"), "CT");
    obj.put_str(tags::IMAGE_POSITION_PATIENT, vr("DS"), "0\\0\\0");
    obj.put_str(
        tags::IMAGE_ORIENTATION_PATIENT,
        vr("DS"),
        "1\\0\\0\\0\\1\\0",
    );
    obj.put_str(tags::PIXEL_SPACING, vr("DS"), "1\\1");
    let meta = FileMetaTableBuilder::new().transfer_syntax(uids::EXPLICIT_VR_LITTLE_ENDIAN);
    let file = obj.with_meta(meta).expect("meta table");
    file.write_to_file(path).expect("write DICOM file");
}

fn expect_dicom_error(result: Result<CpuVolume, VolumeError>, path: &Path, words: &str) {
    match result {
        Err(VolumeError::Dicom { path: p, message }) => {
            eprintln!("{}: {message}", p.display());
            assert_eq!(p, path, "{message}");
            assert!(message.contains(words), "{message:?} lacks {words:?}");
        }
        other => panic!("expected a DICOM error about {words:?}, got {other:?}"),
    }
}

#[test]
fn folder_without_image_slices_is_an_error() {
    let dir = scratch("no_pixels");
    let file = dir.join("no_pixels.dcm");
    write_no_pixel_file(&file, "2.25.2002");
    let bytes = fs::read(&file).expect("read back");
    assert!(is_dicom(&bytes));
    fs::write(dir.join("notes.txt"), "not DICOM").expect("write text file");
    expect_dicom_error(load_dicom_series(&dir), &dir, "no DICOM image slices");
}

#[test]
fn missing_folder_is_an_io_error() {
    let parent = scratch("missing");
    let dir = parent.join("absent");
    assert!(matches!(load_dicom_series(&dir), Err(VolumeError::Io { path, .. }) if path == dir));
}

/// Copies the shared series into a scratch folder, leaving out the files `skip` picks.
fn copy_series(from: &Path, test: &str, skip: impl Fn(&Path) -> bool) -> Scratch {
    let dir = scratch(test);
    for file in series_files(from).iter().filter(|f| !skip(f)) {
        let name = file.file_name().expect("file name");
        fs::copy(file, dir.join(name)).expect("copy series file");
    }
    dir
}

#[test]
fn a_folder_of_two_series_lists_them_and_loads_the_one_chosen() {
    let Some(shared) = series_dir() else { return };
    let dir = copy_series(&shared, "extras", |_| false);
    write_no_pixel_file(&dir.join("DICOMDIR"), "2.25.3003");
    fs::write(dir.join("README.txt"), "a non-DICOM file").expect("write text file");
    fs::write(dir.join("short"), b"DICM").expect("write short file");
    // Slices of the series rewritten as another series, at positions the main one uses; one
    // has lost its position, which only matters in the series that is loaded.
    let vr = |name: &str| name.parse().expect("a VR name");
    for (i, file) in series_files(&shared).iter().take(3).enumerate() {
        let mut obj = open_file(file).expect("open slice");
        obj.put_str(tags::SERIES_INSTANCE_UID, vr("UI"), "2.25.4004");
        obj.put_str(tags::SERIES_NUMBER, vr("IS"), "7");
        obj.put_str(tags::SERIES_DESCRIPTION, vr("LO"), "scout copy");
        obj.put_str(tags::SOP_INSTANCE_UID, vr("UI"), format!("2.25.400{i}"));
        if i == 0 {
            obj.remove_element(tags::IMAGE_POSITION_PATIENT);
        }
        obj.write_to_file(dir.join(format!("other_series_{i}.dcm")))
            .expect("write slice");
    }
    // Two series: the folder lists them and asks which.
    let listed = load_dicom_series(&dir).expect_err("two series need a choice");
    let message = listed.to_string();
    assert!(matches!(listed, VolumeError::DicomSeries { ref series, .. } if series.len() == 2));
    assert!(
        message.contains("--series") && message.contains("\"scout copy\""),
        "{message}"
    );
    assert!(
        message.contains("20 images") && message.contains("3 images"),
        "{message}"
    );
    let listing = splatscene::volume::dicom::list_series(&dir).unwrap();
    let main = listing
        .iter()
        .find(|s| s.images == 20)
        .expect("the shared series");
    assert_eq!(main.size, Some([512, 512]));
    // Chosen by UID, the main series loads as it does alone; by number, the other series
    // fails on its own slice without a position.
    let choose = |c: &str| {
        splatscene::volume::dicom::load_dicom_series_choosing(
            &dir,
            Some(&splatscene::volume::dicom::SeriesChoice(c.into())),
            false,
        )
    };
    let (copied, _) = choose(&main.uid).expect("load the chosen series");
    let original = load_dicom_series(&shared).expect("load the shared series");
    assert_eq!(copied, original);
    let other = choose("7").expect_err("the other series lacks a position");
    assert!(other.to_string().contains("other_series_0.dcm"), "{other}");
    let none = choose("12").expect_err("no series 12");
    assert!(none.to_string().contains("no series is \"12\""), "{none}");
    // A file given alone loads its own series.
    let file = series_files(&shared)[0].file_name().unwrap().to_owned();
    let own =
        splatscene::volume::detect::load_volume(&dir.join(file)).expect("a file's own series");
    assert_eq!(own, original);
}

#[test]
fn a_missing_slice_is_reported_with_its_position() {
    let Some(shared) = series_dir() else { return };
    let headers = headers_in_order(&shared);
    let removed = headers[9].path.clone();
    let dir = copy_series(&shared, "gap", |f| f == removed);
    let result = load_dicom_series(&dir);
    expect_dicom_error(
        result,
        &dir,
        "missing slice: gap of 4.000 mm where the step is 2.000 mm",
    );
}

#[test]
fn a_slice_without_position_names_the_file() {
    let Some(shared) = series_dir() else { return };
    let dir = copy_series(&shared, "no_position", |_| false);
    let victim = series_files(&dir)[7].clone();
    let mut obj = open_file(&victim).expect("open slice");
    obj.remove_element(tags::IMAGE_POSITION_PATIENT);
    obj.write_to_file(&victim).expect("write slice");
    expect_dicom_error(load_dicom_series(&dir), &victim, "no ImagePositionPatient");
}

/// Overwrites the value of the first explicit-VR little-endian element `header` (tag, VR and
/// length bytes) in `bytes`.
fn patch(bytes: &mut [u8], header: &[u8], value: &[u8]) {
    let at = bytes
        .windows(header.len())
        .position(|w| w == header)
        .expect("element in file")
        + header.len();
    bytes[at..at + value.len()].copy_from_slice(value);
}

#[test]
fn mismatched_pixel_spacing_names_the_file() {
    let Some(shared) = series_dir() else { return };
    let dir = copy_series(&shared, "spacing", |_| false);
    let victim = series_files(&dir)[5].clone();
    let mut bytes = fs::read(&victim).expect("read slice");
    patch(
        &mut bytes,
        b"\x28\x00\x30\x00DS\x14\x00",
        b"0.8765625\\0.8765625 ",
    );
    fs::write(&victim, bytes).expect("write slice");
    expect_dicom_error(load_dicom_series(&dir), &victim, "PixelSpacing differs");
}

#[test]
fn rows_smaller_than_the_coded_image_is_an_error_not_a_panic() {
    let Some(shared) = series_dir() else { return };
    let dir = scratch("rows");
    let file = dir.join("slice.dcm");
    let mut bytes = fs::read(&series_files(&shared)[0]).expect("read slice");
    // 256 rows: the JPEG 2000 stream still holds 512 x 512 samples.
    patch(
        &mut bytes,
        b"\x28\x00\x10\x00US\x02\x00",
        &256u16.to_le_bytes(),
    );
    fs::write(&file, bytes).expect("write slice");
    let result = load_dicom_series(&dir);
    assert!(
        matches!(result, Err(VolumeError::Dicom { ref path, .. }) if *path == file),
        "{result:?}"
    );
}

#[test]
fn truncated_files_give_typed_errors() {
    let Some(shared) = series_dir() else { return };
    let dir = scratch("truncated");
    let file = dir.join("slice.dcm");
    let bytes = fs::read(&series_files(&shared)[0]).expect("read slice");
    fs::write(&file, &bytes).expect("write slice");
    let intact = load_dicom_series(&dir).expect("load one intact slice");
    // The file ends with an 8-byte sequence delimiter; cutting into the data before it, from
    // the JPEG 2000 end marker back to the file meta group, must fail.
    let n = bytes.len();
    for len in [
        140,
        200,
        1000,
        2560,
        4830,
        5000,
        n / 2,
        n - 100,
        n - 10,
        n - 9,
    ] {
        fs::write(&file, &bytes[..len]).expect("write truncated slice");
        match load_dicom_series(&dir) {
            Err(VolumeError::Dicom { path, message }) => {
                assert_eq!(path, file, "{len} bytes: {message}");
                eprintln!("{len} bytes: {message}");
            }
            other => panic!("{len} bytes: expected a DICOM error, got {other:?}"),
        }
    }
    // Without its closing delimiter the pixel data are still complete, and load unchanged.
    fs::write(&file, &bytes[..n - 8]).expect("write truncated slice");
    assert_eq!(
        load_dicom_series(&dir).expect("load without delimiter"),
        intact
    );
    // Cut before the magic, the file is no longer DICOM and the folder holds no image.
    fs::write(&file, &bytes[..100]).expect("write truncated slice");
    expect_dicom_error(load_dicom_series(&dir), &dir, "no DICOM image slices");
}

#[test]
fn info_reports_the_stored_type_of_the_series() {
    let Some(dir) = series_dir() else {
        return;
    };
    let info = splatscene::volume::detect::volume_info(&dir).unwrap();
    assert_eq!(info["format"], "dicom");
    // BitsAllocated 16, PixelRepresentation 0 in the shared series; HU come from the rescale.
    assert_eq!(info["scalar_type"], "uint16", "{info}");
    assert_eq!(info["size"], serde_json::json!([512, 512, 20]));
    assert!(
        info["min"].as_f64().unwrap() <= -1000.0 && info["max"].as_f64().unwrap() > 300.0,
        "{info}"
    );
}

#[test]
fn a_file_picks_its_own_series_and_grid_and_the_rest_of_the_folder_is_ignored() {
    let Some(shared) = series_dir() else { return };
    let dir = copy_series(&shared, "own-series", |_| false);
    let files = series_files(&dir);
    let vr = |name: &str| name.parse().expect("a VR name");
    // A localizer in the same series (another orientation), a copy of a slice under
    // another name (the same SOPInstanceUID), a truncated file and a foreign one.
    let mut scout = open_file(&files[3]).expect("open slice");
    scout.put_str(
        tags::IMAGE_ORIENTATION_PATIENT,
        vr("DS"),
        "0\\1\\0\\0\\0\\-1",
    );
    scout.put_str(tags::SOP_INSTANCE_UID, vr("UI"), "2.25.5005");
    scout
        .write_to_file(dir.join("scout.dcm"))
        .expect("write scout");
    fs::copy(&files[5], dir.join("zz-copy.dcm")).expect("copy a slice");
    let bytes = fs::read(&files[6]).expect("read slice");
    fs::write(dir.join("truncated.dcm"), &bytes[..bytes.len() / 3]).expect("write truncated");
    fs::write(
        dir.join("foreign.dcm"),
        [&[0u8; 128][..], b"DICM", &[7u8; 50]].concat(),
    )
    .expect("write foreign");
    let original = load_dicom_series(&shared).expect("load the shared series");
    // Given a slice, the series loads as it does alone: the scout, the copy and the broken
    // files are left out (and counted on stderr).
    let own = splatscene::volume::detect::load_volume(&files[0]).expect("a file's own series");
    assert_eq!(own, original);
    // Given the copy, the copy stands for its original.
    let copy = splatscene::volume::detect::load_volume(&dir.join("zz-copy.dcm")).expect("copy");
    assert_eq!(copy, original);
    // Given the scout, the scout alone.
    let scout = splatscene::volume::detect::load_volume(&dir.join("scout.dcm")).expect("scout");
    assert_eq!(scout.dims, [512, 512, 1]);
    // The folder itself holds one series whose images disagree: refused, naming one.
    let err = load_dicom_series(&dir).expect_err("mixed orientations in a series");
    assert!(err.to_string().contains("ImageOrientationPatient"), "{err}");
}

#[test]
fn a_dangling_link_in_the_folder_is_counted_not_fatal() {
    let Some(shared) = series_dir() else { return };
    let dir = copy_series(&shared, "dangling", |_| false);
    std::os::unix::fs::symlink(dir.join("nowhere.dcm"), dir.join("dangling.dcm"))
        .expect("make a dangling link");
    let original = load_dicom_series(&shared).expect("load the shared series");
    let loaded = load_dicom_series(&dir).expect("the series beside a dangling link");
    assert_eq!(loaded, original);
}

#[test]
fn a_gantry_tilted_stack_is_refused() {
    let Some(shared) = series_dir() else { return };
    let dir = copy_series(&shared, "tilt", |_| false);
    // Each slice moved along the column direction by its depth times tan(5 degrees): the
    // stack of a CT whose gantry was tilted 5 degrees, which no regular grid holds.
    let headers = headers_in_order(&dir);
    let normal = headers[0].row.cross(headers[0].col);
    let first = headers[0].position.dot(normal);
    let vr = "DS".parse().expect("a VR name");
    for h in &headers {
        let depth = h.position.dot(normal) - first;
        let p = h.position + h.col * depth * 5f64.to_radians().tan();
        let mut obj = open_file(&h.path).expect("open slice");
        obj.put_str(
            tags::IMAGE_POSITION_PATIENT,
            vr,
            format!("{:.4}\\{:.4}\\{:.4}", p.x, p.y, p.z),
        );
        obj.write_to_file(&h.path).expect("write slice");
    }
    expect_dicom_error(load_dicom_series(&dir), &dir, "gantry tilt");
}

/// The shared series rewritten as an oblique stack with non-square pixels: each slice's
/// orientation turned by a rotation with no symmetry, its PixelSpacing set to 0.75 between
/// rows and 0.5 between columns, and its position stepped 2.5 mm along the new normal. The
/// placement is then checked voxel by voxel against the DICOM definition, written out here:
/// pixel (column c, row r) of slice k lies at IPP_k + c * (column spacing) * row direction +
/// r * (row spacing) * column direction. A loader that swapped the two spacings, transposed
/// the orientation or misread the step would put these points millimetres away.
#[test]
fn an_oblique_series_with_non_square_pixels_is_placed_as_dicom_defines() {
    let Some(shared) = series_dir() else { return };
    let dir = copy_series(&shared, "oblique", |_| false);
    let turn = glam::DQuat::from_euler(glam::EulerRot::ZYX, 0.5, -0.3, 0.2);
    let (row, col) = (turn * DVec3::X, turn * DVec3::Y);
    let normal = row.cross(col);
    let origin = DVec3::new(-120.25, 80.5, -33.0);
    let (row_spacing, col_spacing, step) = (0.75, 0.5, 2.5);
    let vr = |name: &str| name.parse().expect("a VR name");
    let headers = headers_in_order(&dir);
    for (k, h) in headers.iter().enumerate() {
        let p = origin + normal * (step * k as f64);
        let mut obj = open_file(&h.path).expect("open slice");
        obj.put_str(
            tags::IMAGE_ORIENTATION_PATIENT,
            vr("DS"),
            format!(
                "{:.8}\\{:.8}\\{:.8}\\{:.8}\\{:.8}\\{:.8}",
                row.x, row.y, row.z, col.x, col.y, col.z
            ),
        );
        obj.put_str(
            tags::IMAGE_POSITION_PATIENT,
            vr("DS"),
            format!("{:.6}\\{:.6}\\{:.6}", p.x, p.y, p.z),
        );
        obj.put_str(
            tags::PIXEL_SPACING,
            vr("DS"),
            format!("{row_spacing}\\{col_spacing}"),
        );
        obj.write_to_file(&h.path).expect("write slice");
    }
    let volume = load_dicom_series(&dir).expect("the oblique series");
    let rewritten = headers_in_order(&dir);
    for (c, r, k) in [(0, 0, 0), (1, 0, 0), (0, 1, 0), (511, 3, 7), (17, 400, 19)] {
        let h = &rewritten[k];
        let lps = h.position
            + h.row * (h.pixel_spacing[1] * c as f64)
            + h.col * (h.pixel_spacing[0] * r as f64);
        let ours = world(&volume, [c as f64, r as f64, k as f64]);
        assert!(
            ours.abs_diff_eq(lps_to_ras(lps), 1e-4),
            "pixel ({c}, {r}) of slice {k}: at {ours}, DICOM puts it at {}",
            lps_to_ras(lps)
        );
    }
    // The values are the original ones: only the placement changed.
    let original = load_dicom_series(&shared).expect("the shared series");
    let mut sorted = volume.values.to_f32_vec();
    let mut expected = original.values.to_f32_vec();
    sorted.sort_by(f32::total_cmp);
    expected.sort_by(f32::total_cmp);
    assert_eq!(sorted, expected);
}

/// Images without a SOPInstanceUID: a byte-for-byte copy at the same position is one image,
/// and the images at other positions are all kept (they cannot be copies, and are not hashed).
#[test]
fn images_without_instance_uids_keep_their_slices_and_drop_their_copies() {
    let Some(shared) = series_dir() else { return };
    let dir = copy_series(&shared, "no_uid", |_| false);
    for file in series_files(&dir) {
        let mut obj = open_file(&file).expect("open slice");
        obj.remove_element(tags::SOP_INSTANCE_UID);
        obj.write_to_file(&file).expect("write slice");
    }
    let files = series_files(&dir);
    fs::copy(&files[4], dir.join("zz-copy.dcm")).expect("copy a slice");
    let original = load_dicom_series(&shared).expect("the shared series");
    let own = splatscene::volume::detect::load_volume(&files[0]).expect("a file's own series");
    assert_eq!(own, original);
    let copy = splatscene::volume::detect::load_volume(&dir.join("zz-copy.dcm")).expect("copy");
    assert_eq!(copy, original);
}

/// An image of the same series with another size (a reformat or a thumbnail saved with it)
/// is of another grid: a file of the main stack loads the stack without it.
#[test]
fn an_image_of_another_size_in_the_series_is_left_out() {
    let Some(shared) = series_dir() else { return };
    let dir = copy_series(&shared, "other_size", |_| false);
    let files = series_files(&dir);
    let vr = |name: &str| name.parse().expect("a VR name");
    let mut small = open_file(&files[2]).expect("open slice");
    small.put(dicom_object::mem::InMemElement::new(
        tags::ROWS,
        vr("US"),
        dicom_core::PrimitiveValue::from(256u16),
    ));
    small.put(dicom_object::mem::InMemElement::new(
        tags::COLUMNS,
        vr("US"),
        dicom_core::PrimitiveValue::from(256u16),
    ));
    small.put_str(tags::SOP_INSTANCE_UID, vr("UI"), "2.25.7007");
    small
        .write_to_file(dir.join("small.dcm"))
        .expect("write the small image");
    let original = load_dicom_series(&shared).expect("the shared series");
    let own = splatscene::volume::detect::load_volume(&files[0]).expect("a file's own series");
    assert_eq!(own, original);
}

/// A series holding two time points (every position twice, each image its own instance) is
/// refused with a message that says so, not only that two slices share a position.
#[test]
fn two_time_points_in_one_series_are_named_as_such() {
    let Some(shared) = series_dir() else { return };
    let dir = copy_series(&shared, "time_points", |_| false);
    let vr = |name: &str| name.parse().expect("a VR name");
    for (k, file) in series_files(&dir).iter().enumerate() {
        let mut obj = open_file(file).expect("open slice");
        obj.put_str(tags::SOP_INSTANCE_UID, vr("UI"), format!("2.25.9{k:04}"));
        obj.write_to_file(dir.join(format!("t2-{k:02}.dcm")))
            .expect("write the second time point");
    }
    expect_dicom_error(load_dicom_series(&dir), &dir, "several time points");
}

/// Five neighbouring slices of the shared series written again with native (uncompressed)
/// pixel data, in which a cut inside the pixel data stops the parser, as in most CT series.
fn native_series(shared: &Path, test: &str) -> Scratch {
    let dir = scratch(test);
    let vr = |name: &str| name.parse().expect("a VR name");
    for (k, h) in headers_in_order(shared).iter().skip(10).take(5).enumerate() {
        let obj = open_file(&h.path).expect("open slice");
        let decoded = obj.decode_pixel_data().expect("decode slice");
        let bytes = decoded.data().to_vec();
        let mut inner = obj.into_inner();
        inner.put(dicom_object::mem::InMemElement::new(
            tags::PIXEL_DATA,
            vr("OW"),
            dicom_core::PrimitiveValue::from(bytes),
        ));
        let meta = FileMetaTableBuilder::new()
            .transfer_syntax(uids::EXPLICIT_VR_LITTLE_ENDIAN)
            .media_storage_sop_class_uid(uids::CT_IMAGE_STORAGE)
            .media_storage_sop_instance_uid(format!("2.25.55{k}"));
        let file = inner.with_meta(meta).expect("meta table");
        file.write_to_file(dir.join(format!("n{k}.dcm")))
            .expect("write native slice");
    }
    dir
}

/// The first or last slice of a series cut inside its pixel data (as an interrupted copy
/// leaves it) would leave the volume a slice short with no gap to show it: the load names the
/// file and says how to go on without it; with that option the series loads without the
/// slice, and a damaged file of another series is ignored as before.
#[test]
fn a_slice_of_the_series_cut_short_is_an_error_unless_skipped() {
    use splatscene::volume::detect::{LoadOptions, load_volume_with};
    let Some(shared) = series_dir() else { return };
    let native = native_series(&shared, "native");
    let headers = headers_in_order(&native);
    let original = load_dicom_series(&native).expect("load the native series");
    for (end, header) in [
        ("first", &headers[0]),
        ("last", &headers[headers.len() - 1]),
    ] {
        let dir = copy_series(&native, &format!("cut-{end}"), |_| false);
        let victim = dir.join(header.path.file_name().expect("file name"));
        let bytes = fs::read(&victim).expect("read slice");
        fs::write(&victim, &bytes[..bytes.len() * 2 / 3]).expect("cut the slice");
        let result = load_dicom_series(&dir).map(|v| v.dims);
        assert!(
            matches!(&result, Err(VolumeError::Dicom { path, message }) if *path == victim && message.contains("--skip-unreadable")),
            "{end}: {result:?}"
        );
        // A file of the series given alone reaches the same slice.
        let other = dir.join(headers[headers.len() / 2].path.file_name().unwrap());
        let given = load_volume_with(&other, &LoadOptions::default());
        assert!(
            matches!(&given, Err(VolumeError::Dicom { path, .. }) if *path == victim),
            "{end}: {given:?}"
        );
        let skip = LoadOptions {
            skip_unreadable: true,
            ..LoadOptions::default()
        };
        let loaded = load_volume_with(&dir, &skip).expect("load without the cut slice");
        assert_eq!(loaded.volume.dims[2], original.dims[2] - 1, "{end}");
        let loaded = load_volume_with(&other, &skip).expect("load the file's series without it");
        assert_eq!(loaded.volume.dims[2], original.dims[2] - 1, "{end}");
    }
    // A cut file of another series stays ignored.
    let dir = copy_series(&native, "cut-other", |_| false);
    let stranger = dir.join("other-series.dcm");
    let mut obj = open_file(&series_files(&native)[0]).expect("open slice");
    obj.put_str(
        tags::SERIES_INSTANCE_UID,
        dicom_core::VR::UI,
        "1.2.826.0.1.3680043.2.1125.99",
    );
    obj.put_str(
        tags::SOP_INSTANCE_UID,
        dicom_core::VR::UI,
        "1.2.826.0.1.3680043.2.1125.98",
    );
    obj.write_to_file(&stranger)
        .expect("write the other series' file");
    let bytes = fs::read(&stranger).expect("read it");
    fs::write(&stranger, &bytes[..bytes.len() / 2]).expect("cut it");
    assert_eq!(load_dicom_series(&dir).expect("the series loads"), original);
}

/// Integer samples with an integer rescale are held in 16 bits, the type the loader reads them
/// into first; a series whose values leave that range is read again as f32, with the same
/// numbers a plain computation gives.
#[test]
fn integral_rescales_are_held_in_16_bits_and_wider_values_in_f32() {
    use splatscene::volume::ScalarType;
    let Some(shared) = series_dir() else { return };
    let volume = load_dicom_series(&shared).expect("load the shared series");
    assert_eq!(volume.values.scalar_type(), ScalarType::I16);
    // The same slices with RescaleIntercept 40000 higher: values past i16.
    let dir = copy_series(&shared, "wide_intercept", |_| false);
    let vr = |name: &str| name.parse().expect("a VR name");
    for file in series_files(&dir) {
        let mut obj = open_file(&file).expect("open slice");
        let intercept: f64 = obj
            .element(tags::RESCALE_INTERCEPT)
            .expect("a RescaleIntercept")
            .to_str()
            .expect("text")
            .trim()
            .parse()
            .expect("a number");
        obj.put_str(
            tags::RESCALE_INTERCEPT,
            vr("DS"),
            format!("{}", intercept + 40000.0),
        );
        obj.write_to_file(&file).expect("rewrite slice");
    }
    let wide = load_dicom_series(&dir).expect("load the raised series");
    assert_eq!(wide.values.scalar_type(), ScalarType::F32);
    assert_eq!(wide.values.len(), volume.values.len());
    let off = wide
        .values
        .iter()
        .zip(volume.values.iter())
        .filter(|&(w, v)| w != v + 40000.0)
        .count();
    assert_eq!(off, 0, "values not raised by exactly 40000");
}

/// A file's series is the one its SeriesInstanceUID names: three slices copied into a second
/// series with the same SeriesNumber (as scanners number a reconstruction of the same
/// acquisition) and their own UIDs and places stay apart from the first.
#[test]
fn a_file_picks_its_series_by_uid_not_by_number() {
    let Some(shared) = series_dir() else { return };
    let dir = copy_series(&shared, "same-number", |_| false);
    let files = series_files(&dir);
    let vr = |name: &str| name.parse().expect("a VR name");
    let number = open_file(&files[0])
        .expect("open slice")
        .element(tags::SERIES_NUMBER)
        .map(|e| e.to_str().expect("text").trim().to_string())
        .unwrap_or_else(|_| "1".into());
    let mut copies = Vec::new();
    for (k, file) in files.iter().take(3).enumerate() {
        let mut obj = open_file(file).expect("open slice");
        obj.put_str(tags::SERIES_INSTANCE_UID, vr("UI"), "2.25.6006");
        obj.put_str(tags::SERIES_NUMBER, vr("IS"), number.as_str());
        obj.put_str(tags::SOP_INSTANCE_UID, vr("UI"), format!("2.25.6006{k}"));
        obj.put_str(
            tags::IMAGE_POSITION_PATIENT,
            vr("DS"),
            format!("0\\0\\{}", 1000 + 5 * k),
        );
        let copy = dir.join(format!("recon-{k}.dcm"));
        obj.write_to_file(&copy).expect("write the copy");
        copies.push(copy);
    }
    let original = load_dicom_series(&shared).expect("load the shared series");
    let own = splatscene::volume::detect::load_volume(&files[0]).expect("a file's own series");
    assert_eq!(
        own, original,
        "the first series, without the second's slices"
    );
    let recon = splatscene::volume::detect::load_volume(&copies[0]).expect("the second series");
    assert_eq!(recon.dims, [512, 512, 3]);
}
