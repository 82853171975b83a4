//! The loaders against figures the reference readers give for the same files (nibabel,
//! SimpleITK, VTK, pynrrd, the DICOM tags worked by hand): files the project writes with those
//! tools' own writers (`tests/data/*/reference.json`, each folder with the script that made
//! it), and the pydicom and nibabel test files in the shared data
//! (`tests/data/reference/reader_tests.json`).
//!
//! A placement is checked where it shows its bugs: every file here is oblique (non-symmetric,
//! so a transposed rotation shows), with non-square pixels (so swapped spacings show), and
//! the world point of index (1, 2, 1) is compared as well as the origin, spacing and direction.

use std::path::{Path, PathBuf};

use glam::{DMat3, DVec3};
use serde_json::Value;
use splatscene::volume::CpuVolume;
use splatscene::volume::detect::{
    CoordinateFrame, LoadOptions, LoadedVolume, NiftiTransform, VolumeFormat, load_volume_with,
};

/// Spacing and origin within this many millimetres of the reference.
const MM: f64 = 1e-3;
/// Direction components within this of the reference.
const DIRECTION: f64 = 1e-4;

mod common;
use common::scratch;

fn data_dir(folder: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(folder)
}

fn reference(folder: &str) -> Value {
    read_json(&data_dir(folder).join("reference.json"))
}

fn read_json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path:?}: {e}"));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{path:?}: {e}"))
}

fn vec3(v: &Value) -> DVec3 {
    let a: Vec<f64> = v
        .as_array()
        .unwrap_or_else(|| panic!("{v} is not an array"))
        .iter()
        .map(|x| x.as_f64().expect("a number"))
        .collect();
    DVec3::new(a[0], a[1], a[2])
}

/// The reference's voxel-to-world map: direction rows, spacing and origin.
fn reference_affine(g: &Value) -> (DMat3, DVec3) {
    let rows: Vec<DVec3> = g["direction"]
        .as_array()
        .unwrap()
        .iter()
        .map(vec3)
        .collect();
    let direction = DMat3::from_cols(rows[0], rows[1], rows[2]).transpose();
    let linear = direction * DMat3::from_diagonal(vec3(&g["spacing"]));
    (linear, vec3(&g["origin"]))
}

fn world(v: &CpuVolume, index: DVec3) -> DVec3 {
    DVec3::from(v.origin) + v.direction * (DVec3::from(v.spacing) * index)
}

/// Checks that `v` is placed as the reference geometry `g` says: the same spacing, origin and
/// direction (within [`MM`] and [`DIRECTION`]) and the same world point of index (1, 2, 1).
fn check_same_axes(v: &CpuVolume, g: &Value, what: &str) {
    let spacing = vec3(&g["spacing"]);
    let origin = vec3(&g["origin"]);
    assert!(
        DVec3::from(v.spacing).abs_diff_eq(spacing, MM),
        "{what}: spacing {:?}, reference {spacing}",
        v.spacing
    );
    assert!(
        DVec3::from(v.origin).abs_diff_eq(origin, MM),
        "{what}: origin {:?}, reference {origin}",
        v.origin
    );
    let (linear, _) = reference_affine(g);
    let direction = linear * DMat3::from_diagonal(spacing.recip());
    assert!(
        v.direction.abs_diff_eq(direction, DIRECTION),
        "{what}: direction {:?}, reference {direction:?}",
        v.direction
    );
    if let Some(point) = g.get("point_1_2_1") {
        let ours = world(v, DVec3::new(1.0, 2.0, 1.0));
        assert!(
            ours.abs_diff_eq(vec3(point), MM),
            "{what}: index (1, 2, 1) at {ours}, reference {point}"
        );
    }
}

/// Checks that `v` covers the same voxel centres as the reference geometry `g` of `size`,
/// however its axes are ordered (a reader may walk the slices the other way): each of its
/// corners lands within [`MM`] of a whole reference index inside the reference grid. Returns
/// the map from a reference index to ours.
fn check_same_grid(
    v: &CpuVolume,
    g: &Value,
    size: [u32; 3],
    what: &str,
) -> impl Fn(DVec3) -> DVec3 {
    let (linear, origin) = reference_affine(g);
    let to_reference = |p: DVec3| linear.inverse() * (p - origin);
    for corner in 0..8 {
        let index = DVec3::new(
            f64::from((corner & 1) * (v.dims[0] - 1)),
            f64::from(((corner >> 1) & 1) * (v.dims[1] - 1)),
            f64::from(((corner >> 2) & 1) * (v.dims[2] - 1)),
        );
        let r = to_reference(world(v, index));
        let whole = r.round();
        let inside = (0..3).all(|a| whole[a] >= 0.0 && whole[a] <= f64::from(size[a] - 1));
        // Index units: the error in millimetres is at most this times the largest spacing.
        let spacing = vec3(&g["spacing"]).max_element();
        assert!(
            (r - whole).abs().max_element() * spacing < MM && inside,
            "{what}: our corner {index} is at reference index {r}"
        );
    }
    let ours = v.direction * DMat3::from_diagonal(DVec3::from(v.spacing));
    let our_origin = DVec3::from(v.origin);
    move |r: DVec3| (ours.inverse() * (linear * r + origin - our_origin)).round()
}

/// The value at `index` (x, y, z), which must lie inside the grid.
fn value_at(v: &CpuVolume, index: DVec3) -> f64 {
    let [i, j, k] = index.to_array().map(|x| x as usize);
    let [nx, ny, _] = v.dims.map(|n| n as usize);
    f64::from(v.values.at(i + nx * (j + ny * k)))
}

/// Sum, minimum and maximum of the values against the reference's.
fn check_values(v: &CpuVolume, values: &Value, what: &str) {
    let sum: f64 = v.values.iter().map(f64::from).sum();
    let min = v.values.iter().fold(f32::INFINITY, f32::min);
    let max = v.values.iter().fold(f32::NEG_INFINITY, f32::max);
    let close = |a: f64, b: &Value| {
        let b = b.as_f64().unwrap();
        (a - b).abs() <= 1e-4 * b.abs().max(1.0)
    };
    assert!(
        close(sum, &values["sum"])
            && close(min.into(), &values["min"])
            && close(max.into(), &values["max"]),
        "{what}: sum {sum}, min {min}, max {max}; reference {values}"
    );
}

fn load(path: &Path, options: &LoadOptions) -> LoadedVolume {
    load_volume_with(path, options).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn size_of(entry: &Value) -> [u32; 3] {
    let s = vec3(&entry["size"]);
    [s.x as u32, s.y as u32, s.z as u32]
}

/// Checks a whole file: size, values, the value at index (1, 2, 1) and the placement.
fn check_file(
    folder: &str,
    key: &str,
    file: &str,
    options: &LoadOptions,
    geometry: &str,
    format: VolumeFormat,
) {
    check_entry(
        &reference(folder),
        folder,
        key,
        file,
        options,
        geometry,
        format,
    );
}

/// [`check_file`] against the entry `key` of the reference JSON `reference`.
fn check_entry(
    reference: &Value,
    folder: &str,
    key: &str,
    file: &str,
    options: &LoadOptions,
    geometry: &str,
    format: VolumeFormat,
) {
    let entry = &reference["files"][key];
    assert!(entry.is_object(), "{folder}: the reference has no {key}");
    let what = format!("{folder}/{file} ({geometry})");
    let loaded = load(&data_dir(folder).join(file), options);
    assert_eq!(loaded.format, format, "{what}");
    let v = &loaded.volume;
    assert_eq!(v.dims, size_of(entry), "{what}");
    check_values(v, &entry["values"], &what);
    let g = &entry["geometry"][geometry];
    assert!(g.is_object(), "{what}: no such reference geometry");
    check_same_axes(v, g, &what);
    let at = value_at(v, DVec3::new(1.0, 2.0, 1.0));
    let want = entry["value_at_1_2_1"].as_f64().unwrap();
    assert!(
        (at - want).abs() < 1e-4,
        "{what}: value {at} at (1, 2, 1), reference {want}"
    );
}

#[test]
fn nifti2_follows_nibabel_sform_and_qform() {
    let sform = LoadOptions::default();
    let qform = LoadOptions {
        nifti_transform: Some(NiftiTransform::Qform),
        ..LoadOptions::default()
    };
    for file in ["oblique.nii", "oblique.nii.gz"] {
        check_file("nifti2", file, file, &sform, "sform", VolumeFormat::Nifti);
        check_file("nifti2", file, file, &qform, "qform", VolumeFormat::Nifti);
    }
}

#[test]
fn nifti_transform_choice_matches_nibabel_and_itk() {
    let itk = LoadOptions {
        nifti_transform: Some(NiftiTransform::Itk),
        ..LoadOptions::default()
    };
    let nifti = VolumeFormat::Nifti;
    // sform code 2 beside a qform: nibabel takes the sform, ITK the qform.
    let file = "sform-qform.nii";
    check_file(
        "nifti2",
        file,
        file,
        &LoadOptions::default(),
        "sform",
        nifti,
    );
    check_file("nifti2", file, file, &itk, "simpleitk", nifti);
    check_file("nifti2", file, file, &itk, "qform", nifti);
    // sform code 1 (scanner): both take the sform.
    let file = "sform1-qform.nii";
    check_file("nifti2", file, file, &itk, "simpleitk", nifti);
    check_file("nifti2", file, file, &itk, "sform", nifti);
}

/// NIfTI files in micrometres and metres written by nibabel: placed in millimetres as
/// nibabel's affine (times the unit) and SimpleITK place them.
#[test]
fn nifti_lengths_in_other_units_become_millimetres() {
    for file in ["micrometres.nii", "metres.nii"] {
        for geometry in ["nibabel_mm", "simpleitk"] {
            let options = LoadOptions::default();
            check_file(
                "nifti-units",
                file,
                file,
                &options,
                geometry,
                VolumeFormat::Nifti,
            );
        }
    }
}

#[test]
fn analyze_is_placed_as_nibabel_places_it() {
    for (key, file) in [("little", "little.hdr"), ("big", "big.hdr")] {
        let options = LoadOptions::default();
        check_file(
            "analyze",
            key,
            file,
            &options,
            "nibabel",
            VolumeFormat::Analyze,
        );
    }
    // The .img beside a .hdr is the data, not a volume by itself.
    let img = data_dir("analyze").join("little.img");
    assert!(load_volume_with(&img, &LoadOptions::default()).is_err());
}

#[test]
fn nrrd_bzip2_and_ascii_match_their_headers_and_itk() {
    let options = LoadOptions::default();
    let nrrd = VolumeFormat::Nrrd;
    check_file(
        "nrrd",
        "oblique-bzip2.nrrd",
        "oblique-bzip2.nrrd",
        &options,
        "header",
        nrrd,
    );
    check_file(
        "nrrd",
        "oblique-ascii.nrrd",
        "oblique-ascii.nrrd",
        &options,
        "simpleitk",
        nrrd,
    );
    check_file(
        "nrrd",
        "oblique-ascii.nrrd",
        "oblique-ascii.nrrd",
        &options,
        "header",
        nrrd,
    );
}

/// A scalar volume written as a 4-D NRRD with one single-sample non-spatial axis (a
/// 1-vector first, a list of one last), as pynrrd writes it: the 3-D volume SimpleITK and the
/// header make of it.
#[test]
fn nrrd_with_a_single_sample_non_spatial_axis_reads_as_its_volume() {
    let options = LoadOptions::default();
    for file in ["vector-first.nrrd", "list-last.nrrd"] {
        for geometry in ["header", "simpleitk"] {
            check_file("nrrd", file, file, &options, geometry, VolumeFormat::Nrrd);
        }
    }
}

/// Legacy VTK as VTK's own writer makes it: ASCII data, and negative spacings (VTK keeps
/// them, SimpleITK flips the axis; both put voxel (1, 2, 1) at one point with one value).
#[test]
fn legacy_vtk_ascii_and_negative_spacing_match_vtk_and_itk() {
    let reference = read_json(&data_dir("vtk").join("legacy-reference.json"));
    let options = LoadOptions::default();
    for file in [
        "legacy-ascii.vtk",
        "legacy-negative-spacing.vtk",
        "legacy-negative-spacing-ascii.vtk",
        "legacy-ascii-float.vtk",
    ] {
        let vtk = VolumeFormat::VtkLegacy;
        check_entry(&reference, "vtk", file, file, &options, "simpleitk", vtk);
        // VTK's own placement: the world point of (1, 2, 1) (its spacing may be negative,
        // which a spacing-and-direction placement states as a flipped axis).
        let g = &reference["files"][file]["geometry"]["vtk"];
        let v = load(&data_dir("vtk").join(file), &options).volume;
        let ours = world(&v, DVec3::new(1.0, 2.0, 1.0));
        assert!(
            ours.abs_diff_eq(vec3(&g["point_1_2_1"]), MM),
            "{file}: index (1, 2, 1) at {ours}, VTK {}",
            g["point_1_2_1"]
        );
    }
}

#[test]
fn vti_ascii_and_lz4_match_vtk() {
    let options = LoadOptions::default();
    for file in [
        "vtk-ascii.vti",
        "vtk-appended-raw-lz4.vti",
        "vtk-appended-base64-lz4.vti",
        "vtk-binary-lz4.vti",
        "vtk-appended-zlib.vti",
        "vtk-appended-base64.vti",
    ] {
        check_file("vtk", file, file, &options, "vtk", VolumeFormat::VtkXml);
    }
}

#[test]
fn a_vtk_file_written_in_lps_is_turned_to_ras_on_request() {
    let path = data_dir("vtk").join("vtk-appended-zlib.vti");
    let ras = load(&path, &LoadOptions::default()).volume;
    let lps = load(
        &path,
        &LoadOptions {
            coordinate_frame: Some(CoordinateFrame::Lps),
            ..LoadOptions::default()
        },
    )
    .volume;
    let flip = DVec3::new(-1.0, -1.0, 1.0);
    for index in [
        DVec3::ZERO,
        DVec3::new(1.0, 2.0, 1.0),
        DVec3::new(3.0, 0.0, 1.0),
    ] {
        let (a, b) = (world(&ras, index), world(&lps, index));
        assert!((a * flip).abs_diff_eq(b, 1e-9), "{index}: {a} and {b}");
    }
    assert_eq!(lps.values, ras.values);
    // A file that states its patient frame refuses one.
    let nifti = data_dir("nifti2").join("oblique.nii");
    let err = load_volume_with(
        &nifti,
        &LoadOptions {
            coordinate_frame: Some(CoordinateFrame::Lps),
            ..LoadOptions::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("coordinate frame") && err.contains("oblique.nii"),
        "{err}"
    );
    let err = load_volume_with(
        &path,
        &LoadOptions {
            nifti_transform: Some(NiftiTransform::Qform),
            ..LoadOptions::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("NIfTI transform") && err.contains("vtk-appended-zlib.vti"),
        "{err}"
    );
}

#[test]
fn metaimage_lists_patterns_and_orientation_match_itk() {
    let options = LoadOptions::default();
    for file in [
        "list.mhd",
        "pattern.mhd",
        "orientation-lpi.mhd",
        "orientation-lpi-oblique.mhd",
        "oblique.mhd",
        "oblique.mha",
        "oblique-zlib.mha",
        "oblique-zraw.mhd",
    ] {
        check_file(
            "metaimage",
            file,
            file,
            &options,
            "simpleitk",
            VolumeFormat::MetaImage,
        );
    }
}

#[test]
fn dicom_multiframe_objects_are_volumes() {
    let reference = reference("dicom-multiframe");
    for file in ["legacy-enhanced-ct.dcm", "rtdose.dcm"] {
        let entry = &reference["files"][file];
        let what = format!("dicom-multiframe/{file}");
        let loaded = load(
            &data_dir("dicom-multiframe").join(file),
            &LoadOptions::default(),
        );
        assert_eq!(loaded.format, VolumeFormat::Dicom);
        let v = &loaded.volume;
        assert_eq!(v.dims, size_of(entry), "{what}");
        // Values in modality units: HU, and Gy for the dose (DoseGridScaling applied).
        check_values(v, &entry["values"], &what);
        // The tags worked by hand and SimpleITK agree; slices are ordered along the normal,
        // which may walk the file's frames backwards, so the grid is compared voxel centre
        // for voxel centre.
        for reader in ["tags", "simpleitk"] {
            let g = &entry["geometry"][reader];
            let to_ours = check_same_grid(v, g, size_of(entry), &what);
            for (index, key) in [
                (DVec3::new(1.0, 2.0, 1.0), "value_at_1_2_1"),
                (DVec3::new(1.0, 2.0, 2.0), "value_at_1_2_2"),
            ] {
                let want = entry[key].as_f64().unwrap();
                let at = value_at(v, to_ours(index));
                assert!(
                    (at - want).abs() < 1e-4,
                    "{what}: {key} {at}, reference {want}"
                );
            }
        }
    }
}

/// The shared data's reader test files, or `None` (with a note) when the data are not there;
/// under CI they must be.
fn shared_reader_tests() -> Option<PathBuf> {
    Some(common::data_dir()?.join("reader_tests"))
}

/// What the loader must do with each shared test file: load it as the reference says, or
/// refuse it with a message holding these words (the references cannot read it either, or
/// disagree on its values).
fn refusal(file: &str) -> Option<&'static str> {
    Some(match file {
        // A truncated copy of MR_small: SimpleITK cannot read it, pydicom gives no pixels.
        "pydicom_test_files/MR_truncated.dcm" => "Could not read 8192 value bytes",
        // A stray byte before CT_small's data set: no reader reads it.
        "pydicom_test_files/no_meta.dcm" => "no volume header recognised",
        // RT Ion plans without pixel data.
        "pydicom_test_files/ExplVR_BigEndNoMeta.dcm"
        | "pydicom_test_files/ExplVR_LitEndNoMeta.dcm" => "no image",
        // A 1-bit segmentation: pydicom reads 0/1, SimpleITK 0/255.
        "pydicom_test_files/liver_1frame.dcm" => "1-bit",
        _ => return None,
    })
}

#[test]
fn shared_pydicom_and_nibabel_files_load_as_the_references_read_them() {
    let Some(dir) = shared_reader_tests() else {
        return;
    };
    let reference = read_json(&data_dir("reference").join("reader_tests.json"));
    let reference = reference["files"].as_object().expect("files");
    // Every volume file of the shared folders has its reference: a file added there is
    // checked, not passed over.
    for folder in ["pydicom_test_files", "nibabel_test_data"] {
        for entry in std::fs::read_dir(dir.join(folder)).expect("shared folder") {
            let name = entry.expect("folder entry").file_name();
            let name = name.to_string_lossy();
            let text = [".txt", ".rst"].iter().any(|e| name.ends_with(e));
            if text || ["LICENSE", "COPYING"].contains(&name.as_ref()) {
                continue;
            }
            let key = format!("{folder}/{name}");
            assert!(
                reference.contains_key(&key),
                "{key} has no reference in reader_tests.json (see tests/data/reference/)"
            );
        }
    }
    let mut checked = 0;
    for (file, entry) in reference {
        let path = dir.join(file);
        let result = load_volume_with(&path, &LoadOptions::default());
        if let Some(words) = refusal(file) {
            let err = match result {
                Err(e) => e.to_string(),
                Ok(_) => panic!("{file}: loaded, but the references cannot read it"),
            };
            assert!(
                err.contains(words) && err.contains(path.file_name().unwrap().to_str().unwrap()),
                "{file}: {err}"
            );
            eprintln!("{file}: refused: {err}");
            continue;
        }
        let loaded = result.unwrap_or_else(|e| panic!("{file}: {e}"));
        let v = &loaded.volume;
        let size = size_of(entry);
        assert_eq!(v.dims, size, "{file}");
        // The z spacing of a lone slice is a convention (SpacingBetweenSlices or
        // SliceThickness here, 1 mm in ITK without the former), not a measurement.
        let mut g = entry.clone();
        if size[2] == 1 {
            g["spacing"][2] = serde_json::json!(v.spacing[2]);
        }
        check_same_axes(v, &g, file);
        for (key, point) in entry["index_point"].as_object().expect("index points") {
            let index: Vec<f64> = key.split(',').map(|x| x.parse().unwrap()).collect();
            let ours = world(v, DVec3::new(index[0], index[1], index[2]));
            assert!(
                ours.abs_diff_eq(vec3(point), MM),
                "{file}: index ({key}) at {ours}, reference {point}"
            );
        }
        // 4-D files: frame 0, the default.
        let values = if entry["values"].is_object() {
            &entry["values"]
        } else {
            &entry["values_frame0"]
        };
        let lossy = entry["lossy"].as_bool().unwrap_or(false);
        check_spot_values(v, values, lossy, file);
        checked += 1;
    }
    assert!(checked >= 20, "only {checked} files checked");
}

/// Minimum, maximum, mean (over the finite values) and the values at the corners and the
/// middle, against the reference; lossy JPEG within 1 (decoders round differently).
fn check_spot_values(v: &CpuVolume, values: &Value, lossy: bool, what: &str) {
    let finite: Vec<f64> = v
        .values
        .iter()
        .filter(|x| x.is_finite())
        .map(f64::from)
        .collect();
    let stats = values.get("finite").unwrap_or(values);
    let mean = finite.iter().sum::<f64>() / finite.len() as f64;
    let min = finite.iter().copied().fold(f64::INFINITY, f64::min);
    let max = finite.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let slack = if lossy { 1.0 } else { 0.0 };
    let near = |ours: f64, key: &str| {
        let Some(want) = stats[key].as_f64() else {
            return;
        };
        let tolerance = slack + 1e-4 * want.abs().max(1.0);
        assert!(
            (ours - want).abs() <= tolerance,
            "{what}: {key} {ours}, reference {want}"
        );
    };
    near(min, "min");
    near(max, "max");
    near(mean, "mean");
    let [nx, ny, nz] = v.dims.map(f64::from);
    for (key, index) in [
        ("at_0_0_0", DVec3::ZERO),
        ("at_1_2_0", DVec3::new(1.0, 2.0, 0.0)),
        ("at_last", DVec3::new(nx - 1.0, ny - 1.0, nz - 1.0)),
        (
            "at_mid",
            DVec3::new((nx / 2.0).floor(), (ny / 2.0).floor(), (nz / 2.0).floor()),
        ),
    ] {
        let Some(want) = values[key].as_f64() else {
            continue;
        };
        let ours = value_at(v, index);
        assert!(
            (ours - want).abs() <= slack + 1e-4 * want.abs().max(1.0),
            "{what}: {key} {ours}, reference {want}"
        );
    }
}

#[test]
fn dicom_without_preamble_or_meta_group_loads_the_same() {
    let original = data_dir("dicom-multiframe").join("rtdose.dcm");
    let bytes = std::fs::read(&original).unwrap();
    assert_eq!(&bytes[128..132], b"DICM");
    // The file meta group: explicit VR little endian, its length in (0002,0000).
    let meta_len = u32::from_le_bytes(bytes[140..144].try_into().unwrap()) as usize;
    let data_set = &bytes[144 + meta_len..];
    assert_eq!(
        &data_set[..2],
        &[0x08, 0x00],
        "the data set starts in group 0008"
    );
    let dir = scratch("no-preamble");
    let want = load(&original, &LoadOptions::default());
    for (name, content) in [("no-preamble.dcm", &bytes[128..]), ("bare.dcm", data_set)] {
        let path = dir.join(name);
        std::fs::write(&path, content).unwrap();
        let loaded = load(&path, &LoadOptions::default());
        assert_eq!(loaded.format, VolumeFormat::Dicom, "{name}");
        assert_eq!(loaded.volume, want.volume, "{name}");
    }
}
