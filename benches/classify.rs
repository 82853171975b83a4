//! Classification: the engine (256x256x128 u8) and the CT head (256x256x113 u16) turned into
//! significant voxels with their colours, in full and in shell mode.
//!
//! `cargo bench --bench classify`; the data comes from `SPLATSCENE_DATA` (default
//! `../shared/data`).

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use splatscene::classify::{ClassifyOptions, TransferFunction, classify, classify_with};

mod common;

fn classification(c: &mut Criterion) {
    let (engine, head) = (common::engine(), common::ct_head());
    let cases = [
        (
            "engine",
            engine,
            TransferFunction::ramp(100.0, 200.0, [0.85, 0.8, 0.75, 0.5]),
        ),
        (
            "cthead",
            head,
            TransferFunction::ramp(1200.0, 1800.0, [1.0, 0.93, 0.85, 0.6]),
        ),
    ];
    let mut group = c.benchmark_group("classify");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(5));
    let shell = ClassifyOptions {
        shell: Some(0.5),
        ..Default::default()
    };
    for (name, volume, tf) in &cases {
        let full = classify(volume, tf, 1.0 / 255.0).unwrap().grid.len();
        let on_shell = classify_with(volume, tf, &shell).unwrap().grid.len();
        eprintln!(
            "{name}: {full} significant voxels, {on_shell} on the shell (neighbour at or below 0.5)"
        );
        group.bench_function(format!("{name}/full"), |b| {
            b.iter(|| black_box(classify(volume, tf, 1.0 / 255.0)))
        });
        group.bench_function(format!("{name}/shell"), |b| {
            b.iter(|| black_box(classify_with(volume, tf, &shell)))
        });
    }
    group.finish();
}

criterion_group!(benches, classification);
criterion_main!(benches);
