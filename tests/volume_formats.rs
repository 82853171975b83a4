//! Loads every non-DICOM volume of the project's real test data through the format loaders
//! (`volume::detect`), and checks each against the size, spacing and type its data README
//! states and against figures computed here independently: straight from the files' bytes
//! where that is simple, else measured once with a separate Python/NumPy script whose results
//! are written in below.
//!
//! The data live outside the repository: `$SPLATSCENE_DATA`, by default `../shared/data` next
//! to the crate. When that directory does not exist the tests print a note and pass.
//!
//! Attribution, as the data README asks:
//! - `engine`: "CT scan of two cylinders of an engine block", volvis.org and General Electric;
//!   `datraw_small` (bucky, fuel, neghip, silicium, tooth): Open SciVis Datasets, Pavol
//!   Klacansky (https://klacansky.com/open-scivis-datasets/).
//! - `stanford_cthead`: Stanford volume archive, public domain, credit "University of North
//!   Carolina".
//! - `vtk_headsq` (quarter), `vtk_hydrogen`, `vtk_ironprot`: VTKData, BSD (VTK-Copyright.txt).
//! - `lidc2`: vtk-js test data (LIDC-IDRI), BSD-3.
//! - `totalseg_ct`: TotalSegmentator tests, Apache-2.0.

use std::io::Read;
use std::path::{Path, PathBuf};

use glam::{DMat3, DVec3};
use splatscene::volume::detect::{
    LoadedVolume, VolumeFormat, detect_format, load_volume, load_volume_with_info, volume_info,
};
use splatscene::volume::{
    ByteOrder, CpuVolume, RawSpec, ScalarType, VolumeError, load_raw, load_raw_slices, slice_stack,
};

mod common;

/// The shared data's volumes, or `None` where the data is missing outside CI.
fn volumes_dir() -> Option<PathBuf> {
    Some(common::data_dir()?.join("volumes"))
}

fn voxel(volume: &CpuVolume, [x, y, z]: [u32; 3]) -> f32 {
    let [nx, ny, _] = volume.dims;
    volume.values.at((x + nx * (y + ny * z)) as usize)
}

/// Loads through format detection and checks the size, spacing and stored type.
fn load_checked(
    path: &Path,
    format: VolumeFormat,
    scalar: ScalarType,
    dims: [u32; 3],
    spacing: [f64; 3],
) -> LoadedVolume {
    let loaded = load_volume_with_info(path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(loaded.format, format, "{}", path.display());
    assert_eq!(loaded.scalar_type, Some(scalar), "{}", path.display());
    assert_eq!(loaded.volume.dims, dims, "{}", path.display());
    for (got, want) in loaded.volume.spacing.iter().zip(spacing) {
        assert!(
            (got - want).abs() < 1e-9,
            "{}: spacing {:?}",
            path.display(),
            loaded.volume.spacing
        );
    }
    assert_eq!(
        loaded.volume.values.len() as u64,
        dims.iter().map(|&d| u64::from(d)).product::<u64>()
    );
    loaded
}

/// Sum and 16-bin histogram of byte values, computed the same way for file bytes and the
/// loaded floats (which must then be exact byte values).
fn byte_summary(values: impl Iterator<Item = u8>) -> (u64, [u64; 16]) {
    let mut bins = [0u64; 16];
    let mut sum = 0;
    for v in values {
        sum += u64::from(v);
        bins[usize::from(v / 16)] += 1;
    }
    (sum, bins)
}

fn as_bytes(volume: &CpuVolume) -> impl Iterator<Item = u8> + '_ {
    volume.values.iter().map(|v| {
        assert!(
            (0.0..=255.0).contains(&v) && v.fract() == 0.0,
            "value {v} is not a byte"
        );
        v as u8
    })
}

#[test]
fn dat_volumes_match_their_raw_bytes() {
    let Some(dir) = volumes_dir() else { return };
    let dir = dir.join("datraw_small");
    let cases = [
        (
            "Bucky_32x32x32_uint8",
            [32, 32, 32],
            "Bucky_32x32x32_uint8.raw",
        ),
        (
            "fuel_64x64x64_uint8",
            [64, 64, 64],
            "fuel_64x64x64_uint8.raw",
        ),
        (
            "neghip_64x64x64_uint8",
            [64, 64, 64],
            "neghip_64x64x64_uint8.raw",
        ),
        (
            "silicium_98_34_34_uint8",
            [98, 34, 34],
            "silicium_98x34x34_uint8.raw",
        ),
        (
            "tooth_103x94x161_uint8",
            [103, 94, 161],
            "tooth_103x94x161_uint8.raw",
        ),
    ];
    for (stem, dims, raw) in cases {
        let path = dir.join(format!("{stem}.dat"));
        let loaded = load_checked(&path, VolumeFormat::Dat, ScalarType::U8, dims, [1.0; 3]);
        let bytes = std::fs::read(dir.join(raw)).unwrap();
        assert_eq!(
            byte_summary(as_bytes(&loaded.volume)),
            byte_summary(bytes.into_iter()),
            "{stem}"
        );
        assert_eq!(loaded.volume.direction, DMat3::IDENTITY);
    }
}

#[test]
fn headerless_volumes_ask_for_raw_options_and_load_with_them() {
    let Some(dir) = volumes_dir() else { return };
    let engine = dir.join("engine/engine_256x256x128_uint8.raw");
    let lidc = dir.join("lidc2/lidc2_256x256x133_uint8.raw");
    let head = dir.join("stanford_cthead/CThead.1");
    for path in [&engine, &lidc, &head] {
        let err = load_volume(path).unwrap_err();
        assert!(matches!(err, VolumeError::NoHeader { .. }), "{err}");
        assert!(err.to_string().contains("raw options"), "{err}");
    }
    let spec = RawSpec::new([256, 256, 128], ScalarType::U8, ByteOrder::Little);
    let volume = load_raw(&engine, &spec).unwrap();
    let bytes = std::fs::read(&engine).unwrap();
    assert_eq!(
        byte_summary(as_bytes(&volume)),
        byte_summary(bytes.into_iter())
    );
    let spec = RawSpec {
        spacing: [1.40625, 1.40625, 2.5],
        ..RawSpec::new([256, 256, 133], ScalarType::U8, ByteOrder::Little)
    };
    let volume = load_raw(&lidc, &spec).unwrap();
    let bytes = std::fs::read(&lidc).unwrap();
    assert_eq!(
        byte_summary(as_bytes(&volume)),
        byte_summary(bytes.into_iter())
    );
    let spec = RawSpec {
        spacing: [1.0, 1.0, 2.0],
        ..RawSpec::new([256, 256, 113], ScalarType::U16, ByteOrder::Big)
    };
    let volume = load_raw_slices(&slice_stack(&head).unwrap(), &spec).unwrap();
    // Slice 57 (file CThead.57), voxel (128, 100): big-endian u16 read straight from the file.
    let slice = std::fs::read(dir.join("stanford_cthead/CThead.57")).unwrap();
    let at = 2 * (128 + 256 * 100);
    let expected = u16::from_be_bytes([slice[at], slice[at + 1]]);
    assert_eq!(voxel(&volume, [128, 100, 56]), f32::from(expected));
}

#[test]
fn nrrd_pattern_stack_matches_its_slice_files() {
    let Some(dir) = volumes_dir() else { return };
    let dir = dir.join("vtk_headsq");
    let loaded = load_checked(
        &dir.join("quarter.nhdr"),
        VolumeFormat::Nrrd,
        ScalarType::I16,
        [64, 64, 93],
        [3.2, 3.2, 1.5],
    );
    // `space: 3D-left-handed` is not anatomical: axes stay as they are.
    assert_eq!(loaded.volume.direction, DMat3::IDENTITY);
    assert_eq!(loaded.volume.origin, [0.0; 3]);
    let mut sum = 0i64;
    for z in 0..93u32 {
        let bytes = std::fs::read(dir.join(format!("quarter.{}", z + 1))).unwrap();
        let slice: Vec<i16> = bytes
            .chunks_exact(2)
            .map(|w| i16::from_le_bytes([w[0], w[1]]))
            .collect();
        sum += slice.iter().map(|&v| i64::from(v)).sum::<i64>();
        for (x, y) in [(0, 0), (32, 32), (10, 50), (63, 20)] {
            let expected = f32::from(slice[(x + 64 * y) as usize]);
            assert_eq!(
                voxel(&loaded.volume, [x, y, z]),
                expected,
                "({x}, {y}, {z})"
            );
        }
    }
    assert_eq!(
        loaded.volume.values.iter().map(|v| v as i64).sum::<i64>(),
        sum
    );
    // Measured once with NumPy over the 93 files: sum 193392317, range 0..=3926.
    assert_eq!(sum, 193_392_317);
}

#[test]
fn legacy_vtk_iron_protein_matches_its_bytes() {
    let Some(dir) = volumes_dir() else { return };
    let path = dir.join("vtk_ironprot/ironProt.vtk");
    let loaded = load_checked(
        &path,
        VolumeFormat::VtkLegacy,
        ScalarType::U8,
        [68; 3],
        [1.0; 3],
    );
    let bytes = std::fs::read(&path).unwrap();
    let marker = b"LOOKUP_TABLE default\n";
    let start = bytes
        .windows(marker.len())
        .position(|w| w == marker)
        .unwrap()
        + marker.len();
    let data = &bytes[start..start + 68 * 68 * 68];
    let expected = byte_summary(data.iter().copied());
    assert_eq!(byte_summary(as_bytes(&loaded.volume)), expected);
    // NumPy on the same bytes, once: sum 4131089.
    assert_eq!(expected.0, 4_131_089);
}

#[test]
fn vti_hydrogen_matches_independent_figures() {
    let Some(dir) = volumes_dir() else { return };
    let path = dir.join("vtk_hydrogen/hydrogen.vti");
    let loaded = load_checked(
        &path,
        VolumeFormat::VtkXml,
        ScalarType::F32,
        [64; 3],
        [1.0; 3],
    );
    let v = &loaded.volume;
    // Measured once in Python: the base64 header and 32 zlib blocks decoded with the `base64`
    // and `zlib` modules, the floats read with NumPy (little-endian float32, x fastest).
    let sum: f64 = v.values.iter().map(f64::from).sum();
    assert!((sum - 4856.008970333326).abs() < 1e-6, "{sum}");
    assert_eq!(v.values.iter().filter(|&x| x > 0.5).count(), 1184);
    assert_eq!(v.values.iter().filter(|&x| x == 0.0).count(), 12544);
    assert_eq!(voxel(v, [10, 20, 30]), 0.015506);
    assert_eq!(voxel(v, [31, 31, 40]), 1.0);
    let info = volume_info(&path).unwrap();
    assert_eq!(info["format"], "vti");
    assert_eq!(info["scalar_type"], "float32");
    assert_eq!(info["size"], serde_json::json!([64, 64, 64]));
    assert_eq!(
        (info["min"].as_f64(), info["max"].as_f64()),
        (Some(0.0), Some(1.0))
    );
    assert!((info["mean"].as_f64().unwrap() - 0.01852420414098101).abs() < 1e-9);
}

/// The int32/int16 voxels of a `.nii.gz` decoded here with flate2 and byte arithmetic only,
/// for a check independent of the loader (both files have slope 1 and intercept 0).
fn nifti_voxels(path: &Path) -> Vec<f32> {
    let mut bytes = Vec::new();
    flate2::read::GzDecoder::new(std::fs::File::open(path).unwrap())
        .read_to_end(&mut bytes)
        .unwrap();
    let datatype = i16::from_le_bytes([bytes[70], bytes[71]]);
    let data = &bytes[352..];
    match datatype {
        8 => data
            .chunks_exact(4)
            .map(|w| i32::from_le_bytes(w.try_into().unwrap()) as f32)
            .collect(),
        4 => data
            .chunks_exact(2)
            .map(|w| f32::from(i16::from_le_bytes([w[0], w[1]])))
            .collect(),
        other => panic!("datatype {other}"),
    }
}

#[test]
fn nifti_abdomen_ct_is_in_hounsfield_units_with_its_sform() {
    let Some(dir) = volumes_dir() else { return };
    let path = dir.join("totalseg_ct/example_ct.nii.gz");
    let loaded = load_checked(
        &path,
        VolumeFormat::Nifti,
        ScalarType::I32,
        [122, 101, 112],
        [3.0; 3],
    );
    let v = &loaded.volume;
    assert_eq!(v.values, nifti_voxels(&path));
    // sform (code 2): diagonal 3 mm, origin from its last column (read with Python's struct).
    assert_eq!(v.direction, DMat3::IDENTITY);
    let origin = DVec3::from(v.origin);
    assert!(origin.abs_diff_eq(
        DVec3::new(-177.95632934570312, 11.319000244140625, 94.3017578125),
        1e-9
    ));
    // Air near -1000 HU, bone above 300 HU; counts measured once with NumPy.
    let air = v.values.iter().filter(|&x| x < -900.0).count();
    let bone = v.values.iter().filter(|&x| x > 300.0).count();
    assert_eq!((air, bone), (445_487, 14_401));
    assert_eq!(voxel(v, [0, 0, 0]), -1023.0);
    assert_eq!(voxel(v, [60, 50, 56]), 281.0);
}

#[test]
fn nifti_aorta_ct_has_metal_bright_voxels_and_a_flipped_sform() {
    let Some(dir) = volumes_dir() else { return };
    let path = dir.join("totalseg_ct/aorta_ct_cropped.nii.gz");
    let loaded = load_checked(
        &path,
        VolumeFormat::Nifti,
        ScalarType::I16,
        [120, 126, 164],
        [1.5; 3],
    );
    let v = &loaded.volume;
    assert_eq!(v.values, nifti_voxels(&path));
    // sform diag(-1.5, -1.5, 1.5): x and y run toward patient left and posterior.
    assert_eq!(
        v.direction,
        DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0))
    );
    let origin = DVec3::from(v.origin);
    assert!(origin.abs_diff_eq(
        DVec3::new(71.658203125, 255.658203125, 540.2000122070312),
        1e-9
    ));
    // The stent graft: 3032 voxels above 2000 HU, up to 3343 (NumPy, once).
    let metal = v.values.iter().filter(|&x| x > 2000.0).count();
    let max = v.values.iter().fold(f32::MIN, f32::max);
    assert_eq!((metal, max), (3032, 3343.0));
    let info = volume_info(&path).unwrap();
    assert_eq!(
        info["direction"],
        serde_json::json!([[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])
    );
    assert_eq!(info["scalar_type"], "int16");
    assert!((info["mean"].as_f64().unwrap() - -200.7137308039747).abs() < 1e-6);
}

/// Every data file that format detection recognises (except DICOM, loaded elsewhere) loads.
#[test]
fn every_recognised_volume_file_loads() {
    let Some(dir) = volumes_dir() else { return };
    let mut stack = vec![dir];
    let mut loaded = 0;
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                // A folder is a DICOM series to format detection; DICOM is not tested here.
                assert_eq!(detect_format(&path).unwrap(), VolumeFormat::Dicom);
                if !path.ends_with("example_ct_dicom") {
                    stack.push(path);
                }
                continue;
            }
            match detect_format(&path) {
                Ok(VolumeFormat::Dicom) => {}
                Ok(_) => {
                    load_volume(&path).unwrap_or_else(|e| panic!("{e}"));
                    loaded += 1;
                }
                Err(VolumeError::NoHeader { .. }) => {}
                Err(e) => panic!("{e}"),
            }
        }
    }
    // 5 .dat, quarter.nhdr, hydrogen.vti, ironProt.vtk, 2 .nii.gz.
    assert_eq!(loaded, 10);
}

/// `.vti` files as VTK's own writer makes them by default: appended base64, the header encoded
/// on its own and the zlib blocks after it, a second array behind the first, and the closing
/// tags after the data (`tests/data/vtk/`, written by VTK 9.7.2).
#[test]
fn vti_files_written_by_vtk_load() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/vtk");
    for name in ["vtk-appended-zlib.vti", "vtk-appended-base64.vti"] {
        let loaded = load_checked(
            &dir.join(name),
            VolumeFormat::VtkXml,
            ScalarType::I16,
            [5, 4, 3],
            [0.5, 0.75, 2.0],
        );
        let v = &loaded.volume;
        assert_eq!(v.origin, [-10.0, 20.0, 5.5], "{name}");
        let expected: Vec<f32> = (0..60).map(|i| (7 * i - 100) as f32).collect();
        assert_eq!(v.values, expected, "{name}");
    }
}

/// MetaImage as ITK writes it (`tests/data/metaimage/`, by SimpleITK 2.5.7): an oblique,
/// non-symmetric direction, plain, zlib-compressed and with a detached `.raw`. ITK puts index
/// (1, 2, 1) at LPS (9.683012701892219, -19.228420609430803, 32.40918747649227): RAS with x and
/// y negated.
#[test]
fn metaimage_files_written_by_itk_land_where_itk_puts_them() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/metaimage");
    let expected = DVec3::new(-9.683012701892219, 19.228420609430803, 32.40918747649227);
    for name in ["oblique.mha", "oblique-zlib.mha", "oblique.mhd"] {
        let loaded = load_checked(
            &dir.join(name),
            VolumeFormat::MetaImage,
            ScalarType::I16,
            [4, 3, 2],
            [0.5, 0.75, 2.0],
        );
        let v = &loaded.volume;
        let values: Vec<f32> = (0..24).map(|i| (5 * i - 30) as f32).collect();
        assert_eq!(v.values, values, "{name}");
        let at = DVec3::from(v.origin)
            + v.direction * (DVec3::from(v.spacing) * DVec3::new(1.0, 2.0, 1.0));
        assert!(
            at.distance(expected) < 1e-9,
            "{name}: {at} against {expected}"
        );
        assert!(
            (v.direction.determinant() - 1.0).abs() < 1e-9,
            "{name}: a rotation"
        );
    }
}

/// 4-D NIfTI from nibabel's test data: each 3-D frame is read (the first by default), its
/// values rescaled; a frame past the last is an error naming the file. The sums were computed
/// once in Python from the file's own bytes (`gzip`, `struct` and NumPy: the frame's int16
/// values times `scl_slope` plus `scl_inter`).
#[test]
fn four_dimensional_nifti_frames() {
    let Some(dir) = volumes_dir() else { return };
    let dir = dir.join("../reader_tests/nibabel_test_data");
    use splatscene::volume::VolumeError;
    use splatscene::volume::detect::{LoadOptions, LoadedVolume};
    let load_volume_frame =
        |path: &Path, _: Option<()>, frame: Option<u32>| -> Result<LoadedVolume, VolumeError> {
            let options = LoadOptions {
                frame,
                ..LoadOptions::default()
            };
            splatscene::volume::detect::load_volume_with(path, &options)
        };
    let sum = |path: &Path, frame: Option<u32>| -> f64 {
        let loaded = load_volume_frame(path, None, frame).unwrap_or_else(|e| panic!("{e}"));
        loaded.volume.values.iter().map(f64::from).sum()
    };
    let functional = dir.join("functional.nii");
    let first = load_volume_with_info(&functional).unwrap().volume;
    assert_eq!(first.dims, [17, 21, 3]);
    for (frame, expected) in [
        (None, 3883746.552329719),
        (Some(0), 3883746.552329719),
        (Some(1), 3884191.0010026097),
        (Some(19), 3888072.273083091),
    ] {
        let got = sum(&functional, frame);
        assert!(
            (got - expected).abs() < 0.5,
            "frame {frame:?}: {got} against {expected}"
        );
    }
    let example = dir.join("example4d.nii.gz");
    assert!((sum(&example, Some(1)) - 50990959.0).abs() < 0.5);
    assert!((sum(&example, None) - 50994397.0).abs() < 0.5);
    let e = load_volume_frame(&functional, None, Some(20))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("functional.nii") && e.contains("frame 20") && e.contains("20 frames"),
        "{e}"
    );
    // A frame of a 3-D file past 0, or of another format, is refused.
    let anatomical = dir.join("anatomical.nii");
    assert!(load_volume_frame(&anatomical, None, Some(0)).is_ok());
    assert!(load_volume_frame(&anatomical, None, Some(1)).is_err());
}
