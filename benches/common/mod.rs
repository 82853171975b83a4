//! The real volumes the benchmarks use, from `SPLATSCENE_DATA` (default `../shared/data`).

#![allow(dead_code)]

use std::path::PathBuf;

use splatscene::volume::CpuVolume;
use splatscene::volume::raw::{
    ByteOrder, RawSpec, ScalarType, load_raw, load_raw_slices, slice_stack,
};

fn volumes_dir() -> PathBuf {
    std::env::var_os("SPLATSCENE_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"))
        .join("volumes")
}

/// The GE engine block, 256x256x128 u8 (Open SciVis datasets, General Electric).
pub fn engine() -> CpuVolume {
    load_raw(
        &volumes_dir().join("engine/engine_256x256x128_uint8.raw"),
        &RawSpec::new([256, 256, 128], ScalarType::U8, ByteOrder::Little),
    )
    .expect("engine volume (set SPLATSCENE_DATA)")
}

/// The Stanford CT head, 256x256x113 u16 big-endian, spacing 1, 1, 2 (University of North
/// Carolina).
pub fn ct_head() -> CpuVolume {
    let spec = RawSpec {
        spacing: [1.0, 1.0, 2.0],
        ..RawSpec::new([256, 256, 113], ScalarType::U16, ByteOrder::Big)
    };
    let slices = slice_stack(&volumes_dir().join("stanford_cthead/CThead.1"))
        .expect("CT head (set SPLATSCENE_DATA)");
    load_raw_slices(&slices, &spec).expect("CT head volume")
}
