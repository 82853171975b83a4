//! Loads the project's real raw volumes and checks them against figures computed here straight
//! from the file bytes, plus figures measured once with an independent Python script.
//!
//! The data live outside the repository: `$SPLATSCENE_DATA`, by default `../shared/data` next to
//! the crate. A missing data directory fails these tests rather than skipping them, since CI
//! has the data and a silent pass would hide a broken setup.
//!
//! Attribution: the engine block is "CT scan of two cylinders of an engine block", courtesy of
//! volvis.org and General Electric, from the Open SciVis Datasets repository by Pavol Klacansky.
//! The CT head is the Stanford volume archive's CT head, public domain, credit "University of
//! North Carolina".

use std::path::PathBuf;
use std::time::Instant;

use splatscene::volume::{
    ByteOrder, CpuVolume, RawSpec, ScalarType, VolumeError, load_raw, load_raw_slices, slice_stack,
};

mod common;

/// Range, sum and a 16-bin histogram over `0..=top`, computed the same way for the file's
/// integers and the loaded floats.
#[derive(Debug, PartialEq)]
struct Summary {
    min: u32,
    max: u32,
    sum: u64,
    bins: [u64; 16],
}

fn summarise(values: impl Iterator<Item = u32>, top: u32) -> Summary {
    let mut s = Summary {
        min: u32::MAX,
        max: 0,
        sum: 0,
        bins: [0; 16],
    };
    for v in values {
        s.min = s.min.min(v);
        s.max = s.max.max(v);
        s.sum += u64::from(v);
        s.bins[(u64::from(v) * 16 / (u64::from(top) + 1)) as usize] += 1;
    }
    s
}

/// The loaded values as integers, refusing any that are not exact non-negative integers.
fn integers(volume: &CpuVolume) -> impl Iterator<Item = u32> + '_ {
    volume.values.iter().map(|v| {
        assert!(
            v >= 0.0 && v.fract() == 0.0,
            "value {v} is not a non-negative integer"
        );
        v as u32
    })
}

fn voxel(volume: &CpuVolume, [x, y, z]: [u32; 3]) -> f32 {
    let [nx, ny, _] = volume.dims;
    volume.values.at((x + nx * (y + ny * z)) as usize)
}

fn engine_path() -> PathBuf {
    common::data_dir()
        .expect("the shared test data")
        .join("volumes/engine/engine_256x256x128_uint8.raw")
}

#[test]
fn engine_matches_its_bytes() {
    let path = engine_path();
    let spec = RawSpec::new([256, 256, 128], ScalarType::U8, ByteOrder::Little);
    let start = Instant::now();
    let volume = load_raw(&path, &spec).unwrap();
    println!(
        "engine 256x256x128 u8 loaded in {:.1} ms",
        start.elapsed().as_secs_f64() * 1e3
    );
    assert_eq!((volume.dims, volume.spacing), ([256, 256, 128], [1.0; 3]));
    assert_eq!(volume.values.len(), 256 * 256 * 128);

    let bytes = std::fs::read(&path).unwrap();
    let expected = summarise(bytes.iter().map(|&b| u32::from(b)), 255);
    assert_eq!(summarise(integers(&volume), 255), expected);
    // Measured once on the file with a separate Python script.
    assert_eq!(
        (expected.min, expected.max, expected.sum),
        (0, 255, 187_475_057)
    );
    assert_eq!(expected.bins[0], 6_939_152);
    assert_eq!(expected.bins[8], 465_554);
    for (k, value) in [
        ([128, 128, 64], 133.0),
        ([100, 60, 30], 2.0),
        ([200, 180, 100], 120.0),
        ([0, 0, 0], 0.0),
    ] {
        assert_eq!(voxel(&volume, k), value, "engine voxel {k:?}");
    }
}

#[test]
fn engine_with_a_wrong_size_gives_typed_errors_naming_the_file() {
    let path = engine_path();
    let too_deep = RawSpec::new([256, 256, 256], ScalarType::U8, ByteOrder::Little);
    let err = load_raw(&path, &too_deep).unwrap_err();
    assert!(
        matches!(err, VolumeError::TooShort { expected: 16_777_216, actual: 8_388_608, ref path } if path.ends_with("engine_256x256x128_uint8.raw")),
        "{err}"
    );
    assert!(
        err.to_string().contains("engine_256x256x128_uint8.raw"),
        "{err}"
    );
    let wider_type = RawSpec::new([256, 256, 128], ScalarType::U16, ByteOrder::Little);
    assert!(matches!(
        load_raw(&path, &wider_type),
        Err(VolumeError::TooShort { .. })
    ));
    let huge = RawSpec::new([65536, 65536, 65536], ScalarType::U8, ByteOrder::Little);
    let err = load_raw(&path, &huge).unwrap_err();
    assert!(matches!(err, VolumeError::Grid { .. }), "{err}");
    assert!(
        err.to_string().contains("engine_256x256x128_uint8.raw"),
        "{err}"
    );
}

#[test]
fn ct_head_slice_stack_matches_its_big_endian_bytes() {
    let first = common::data_dir()
        .expect("the shared test data")
        .join("volumes/stanford_cthead/CThead.1");
    let start = Instant::now();
    let paths = slice_stack(&first).unwrap();
    let spec = RawSpec {
        spacing: [1.0, 1.0, 2.0],
        ..RawSpec::new([256, 256, 113], ScalarType::U16, ByteOrder::Big)
    };
    let volume = load_raw_slices(&paths, &spec).unwrap();
    println!(
        "CT head 256x256x113 u16be (113 files) found and loaded in {:.1} ms",
        start.elapsed().as_secs_f64() * 1e3
    );
    assert_eq!(paths.len(), 113);
    assert!(
        paths[9].ends_with("CThead.10") && paths[112].ends_with("CThead.113"),
        "numeric order"
    );
    assert_eq!(
        (volume.dims, volume.spacing),
        ([256, 256, 113], [1.0, 1.0, 2.0])
    );

    let mut words = Vec::with_capacity(256 * 256 * 113);
    for path in &paths {
        let bytes = std::fs::read(path).unwrap();
        assert_eq!(bytes.len(), 256 * 256 * 2, "{}", path.display());
        words.extend(
            bytes
                .chunks_exact(2)
                .map(|w| u32::from(w[0]) << 8 | u32::from(w[1])),
        );
    }
    let expected = summarise(words.iter().copied(), 3272);
    assert_eq!(summarise(integers(&volume), 3272), expected);
    // Measured once on the files with a separate Python script.
    assert_eq!(
        (expected.min, expected.max, expected.sum),
        (0, 3272, 2_810_724_494)
    );
    for (k, value) in [
        ([128, 128, 56], 2322.0),
        ([128, 60, 20], 0.0),
        ([90, 150, 100], 1060.0),
        ([0, 0, 0], 25.0),
    ] {
        assert_eq!(voxel(&volume, k), value, "CT head voxel {k:?}");
    }
}

/// The engine at CT-like spacing (0.7, 0.7, 2.5 mm), seen from three views of the report's
/// orbit: the rows order's image error is well under IP-PBTF's (the orderings report measures
/// 0.42 of it over the whole path).
#[test]
fn rows_order_beats_ip_pbtf_on_the_engine_at_ct_spacing() {
    use splatscene::classify::{TransferFunction, classify};
    use splatscene::order::Ordering;
    use splatscene::report::{self, Entry, ReportSettings};

    let spec = RawSpec {
        spacing: [0.7, 0.7, 2.5],
        ..RawSpec::new([256, 256, 128], ScalarType::U8, ByteOrder::Little)
    };
    let volume = load_raw(&engine_path(), &spec).expect("engine volume");
    // Colour changes with the value, as in the orderings report: with one colour every order
    // gives the same image.
    let tf = TransferFunction::new(vec![
        (100.0, [0.85, 0.45, 0.3, 0.0]),
        (138.75, [1.0, 0.93, 0.85, 0.6]),
        (255.0, [0.7, 0.85, 1.0, 0.8]),
    ]);
    let classified = classify(&volume, &tf, 1.0 / 255.0).unwrap();
    let geometry = volume.geometry().unwrap();
    let views: Vec<_> = report::camera_path(&geometry, 8, 0)
        .into_iter()
        .step_by(2)
        .take(3)
        .collect();
    let settings = ReportSettings {
        orderings: vec![
            Entry::from(Ordering::IpPbtfImplicit),
            Entry::from(Ordering::Rows),
        ],
        ..ReportSettings::default()
    };
    let results = report::measure_views(&geometry, &classified, &views, &settings, || {}).unwrap();
    let (mut ip, mut rows) = (0.0, 0.0);
    for result in &results {
        let [a, b] = [0, 1].map(|i| result.per_ordering[i].difference);
        eprintln!("{}: IP-PBTF {:.4}, rows {:.4}", result.name, a.rmse, b.rmse);
        ip += a.rmse;
        rows += b.rmse;
    }
    assert!(rows < 0.6 * ip, "rows {rows} against IP-PBTF {ip}");
}
