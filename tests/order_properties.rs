//! Property tests: every fast ordering against its comparison-sort reference, over random grid
//! sizes, spacings, eyes and sparsity.

use glam::DVec3;
use proptest::prelude::*;
use splatscene::grid::SparseGrid;
use splatscene::order::{OrderOptions, Orderer, Ordering, ViewCase, VolumeGeometry, reference};

#[derive(Debug, Clone)]
struct Case {
    dims: [u32; 3],
    spacing: [f64; 3],
    eye: [f64; 3],
    target: [f64; 3],
    keep: u32,
    seed: u32,
    cull: bool,
}

/// Eye coordinates that hit the special places often: voxel planes, half-way points, the
/// boundary at -0.5 and n - 0.5, and far outside.
fn eye_coord(n: u32) -> impl Strategy<Value = f64> {
    let n = f64::from(n);
    prop_oneof![
        (-3.0 * n - 4.0..4.0 * n + 4.0),
        (-2i32..(n as i32 + 2)).prop_map(f64::from),
        (-2i32..(n as i32 + 2)).prop_map(|k| f64::from(k) + 0.5),
        Just(-0.5),
        Just(n - 0.5),
        Just(-0.5 - 1e-9),
        Just(n - 0.5 + 1e-9),
    ]
}

fn case() -> impl Strategy<Value = Case> {
    (1u32..14, 1u32..12, 1u32..10)
        .prop_flat_map(|(nx, ny, nz)| {
            (
                Just([nx, ny, nz]),
                prop::array::uniform3(prop_oneof![Just(1.0), Just(0.7), Just(2.5), 0.1f64..10.0]),
                (eye_coord(nx), eye_coord(ny), eye_coord(nz)),
                prop::array::uniform3(-5.0f64..15.0),
                0u32..=4,
                any::<u32>(),
                any::<bool>(),
            )
        })
        .prop_map(
            |(dims, spacing, (ex, ey, ez), target, keep, seed, cull)| Case {
                dims,
                spacing,
                eye: [ex, ey, ez],
                target,
                keep,
                seed,
                cull,
            },
        )
}

/// A grid where about `keep`/4 of the voxels are significant, picked by a hash.
fn grid(case: &Case) -> SparseGrid {
    SparseGrid::from_mask(case.dims, |id| {
        let h = (id ^ case.seed)
            .wrapping_mul(0x9E37_79B9)
            .rotate_left(13)
            .wrapping_mul(0x85EB_CA6B);
        h % 4 < case.keep
    })
    .unwrap()
}

fn view(case: &Case) -> Option<(VolumeGeometry, ViewCase)> {
    let geometry = VolumeGeometry::axis_aligned(case.dims, case.spacing, [0.0; 3]).unwrap();
    let to_world = |p: [f64; 3]| geometry.index_to_world_point(DVec3::from(p));
    let view = ViewCase::new(&geometry, to_world(case.eye), to_world(case.target)).ok()?;
    Some((geometry, view))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 500, ..ProptestConfig::default() })]

    #[test]
    fn grid_orderings_equal_their_definitions(case in case()) {
        let grid = grid(&case);
        let Some((_, view)) = view(&case) else { return Ok(()) };
        let options = OrderOptions { cull_behind_eye: case.cull, ..Default::default() };
        let mut orderer = Orderer::new();
        let mut out = Vec::new();
        for ordering in [Ordering::Btf, Ordering::Wbtf, Ordering::Pbtf, Ordering::IpPbtfExplicit, Ordering::IpPbtfImplicit, Ordering::Pyramid, Ordering::Rows] {
            orderer.order(&grid, &view, ordering, &options, &mut out).unwrap();
            let expected = reference::order(&grid, &view, ordering, case.cull);
            prop_assert_eq!(&out, &expected, "{} on {:?}", ordering, view.kind);
        }
    }

    #[test]
    fn exact_and_bucketed_are_permutations_sorted_by_distance(case in case()) {
        let grid = grid(&case);
        let Some((geometry, view)) = view(&case) else { return Ok(()) };
        let options = OrderOptions { cull_behind_eye: case.cull, ..Default::default() };
        let mut orderer = Orderer::new();
        let mut exact = Vec::new();
        orderer.order(&grid, &view, Ordering::Exact, &options, &mut exact).unwrap();
        prop_assert_eq!(&exact, &reference::order(&grid, &view, Ordering::Exact, case.cull));

        let mut bucketed = Vec::new();
        orderer.order(&grid, &view, Ordering::Bucketed, &options, &mut bucketed).unwrap();
        let mut sorted = bucketed.clone();
        sorted.sort_unstable();
        let mut expected = exact.clone();
        expected.sort_unstable();
        prop_assert_eq!(sorted, expected);
        // Never more than one bucket out of distance order.
        let width = 0.5 * geometry.spacing().iter().copied().fold(f64::INFINITY, f64::min);
        let distance = |id: u32| view.distance_squared(grid.coords(id)).sqrt();
        for pair in bucketed.windows(2) {
            prop_assert!(distance(pair[1]) <= distance(pair[0]) + width * (1.0 + 1e-9));
        }
    }
}

#[test]
fn every_ordering_is_a_permutation_of_a_dense_grid() {
    let geometry = VolumeGeometry::axis_aligned([13, 7, 9], [0.7, 0.7, 2.5], [0.0; 3]).unwrap();
    let grid = SparseGrid::dense(geometry.dims()).unwrap();
    let view = ViewCase::new(
        &geometry,
        DVec3::new(3.3, 2.1, 30.0),
        geometry.centre_world(),
    )
    .unwrap();
    let mut out = Vec::new();
    for ordering in Ordering::ALL {
        Orderer::new()
            .order(&grid, &view, ordering, &OrderOptions::default(), &mut out)
            .unwrap();
        let mut sorted = out.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..13 * 7 * 9).collect::<Vec<_>>(), "{ordering}");
    }
}
