//! Order time of every ordering on the engine block (256x256x128) and the Stanford CT head
//! (256x256x113, 16-bit big-endian) classified at a bone-like threshold, and on a dense 256^3
//! grid, with a copy of the output list as the floor. Data from `SPLATSCENE_DATA` (default
//! `../shared/data`): the engine is courtesy of General Electric (via volvis.org), the CT head of
//! the University of North Carolina (Stanford volume archive).

use std::hint::black_box;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use glam::DVec3;
use splatscene::classify::{TransferFunction, classify};
use splatscene::grid::SparseGrid;
use splatscene::order::{OrderOptions, Orderer, Ordering, ViewCase, VolumeGeometry};
use splatscene::volume::CpuVolume;

mod common;

fn sparse(volume: &CpuVolume, threshold: f32) -> SparseGrid {
    let tf = TransferFunction::ramp(threshold, threshold + 1.0, [1.0; 4]);
    classify(volume, &tf, 0.0).expect("classify").grid
}

fn datasets() -> Vec<(&'static str, VolumeGeometry, SparseGrid)> {
    let (engine, head) = (common::engine(), common::ct_head());
    let dense = VolumeGeometry::axis_aligned([256; 3], [1.0; 3], [0.0; 3]).unwrap();
    vec![
        ("engine", engine.geometry().unwrap(), sparse(&engine, 100.0)),
        ("cthead", head.geometry().unwrap(), sparse(&head, 1200.0)),
        ("dense256", dense, SparseGrid::dense([256; 3]).unwrap()),
    ]
}

/// A close face-on eye and an eye inside the volume, in fractions of the grid size.
fn views(geometry: &VolumeGeometry) -> [(&'static str, ViewCase); 2] {
    let dims = geometry.dims().map(f64::from);
    let at = |f: [f64; 3]| {
        geometry.index_to_world_point(DVec3::new(f[0] * dims[0], f[1] * dims[1], f[2] * dims[2]))
    };
    let centre = geometry.centre_world();
    [
        (
            "face-on",
            ViewCase::new(geometry, at([0.43, 0.56, -0.35]), centre).unwrap(),
        ),
        (
            "volume-on",
            ViewCase::new(geometry, at([0.41, 0.37, 0.45]), centre).unwrap(),
        ),
    ]
}

fn orderings(c: &mut Criterion) {
    for (name, geometry, grid) in datasets() {
        let mut group = c.benchmark_group(format!("order/{name}"));
        group
            .sample_size(10)
            .warm_up_time(Duration::from_millis(500))
            .measurement_time(Duration::from_secs(3));
        let mut orderer = Orderer::new();
        let mut out = Vec::new();
        for (view_name, view) in views(&geometry) {
            for ordering in Ordering::ALL {
                group.bench_function(BenchmarkId::new(ordering.name(), view_name), |b| {
                    b.iter(|| {
                        orderer
                            .order(&grid, &view, ordering, &OrderOptions::default(), &mut out)
                            .unwrap();
                        black_box(out.len())
                    })
                });
            }
            // The floor: copying a list as long as the output into an existing buffer.
            let source = out.clone();
            let mut copy = Vec::with_capacity(source.len());
            group.bench_function(BenchmarkId::new("copy", view_name), |b| {
                b.iter(|| {
                    copy.clear();
                    copy.extend_from_slice(black_box(&source));
                    black_box(copy.len())
                })
            });
        }
        group.finish();
    }
}

criterion_group!(benches, orderings);
criterion_main!(benches);
