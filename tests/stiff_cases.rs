//! Stiff and extreme views: eyes on voxel planes, half-way, on the boundary, inside a voxel,
//! very far; degenerate grids; extreme anisotropy; a volume far from the origin; bad eyes.

use glam::DVec3;
use splatscene::camera::Camera;
use splatscene::grid::SparseGrid;
use splatscene::order::{
    CaseKind, OrderError, OrderOptions, Orderer, Ordering, ViewCase, VolumeGeometry, reference,
};
use splatscene::splat::reference::{SplatStyle, SplatVolume, compare, composite};

const GRID_ORDERINGS: [Ordering; 5] = [
    Ordering::Btf,
    Ordering::Wbtf,
    Ordering::Pbtf,
    Ordering::IpPbtfExplicit,
    Ordering::IpPbtfImplicit,
];

/// Orderings checked against their comparison-sort definitions in [`reference`]: the grid
/// orderings and ours that have one. (The exact order is checked by distance instead.)
const WITH_REFERENCE: [Ordering; 7] = [
    Ordering::Btf,
    Ordering::Wbtf,
    Ordering::Pbtf,
    Ordering::IpPbtfExplicit,
    Ordering::IpPbtfImplicit,
    Ordering::Pyramid,
    Ordering::Rows,
];

fn view_at(geometry: &VolumeGeometry, eye_index: [f64; 3]) -> ViewCase {
    let eye = geometry.index_to_world_point(DVec3::from(eye_index));
    ViewCase::new(geometry, eye, geometry.centre_world()).unwrap()
}

fn all_orders(grid: &SparseGrid, view: &ViewCase) -> Vec<(Ordering, Vec<u32>)> {
    let mut orderer = Orderer::new();
    Ordering::ALL
        .iter()
        .map(|&o| {
            let mut out = Vec::new();
            orderer
                .order(grid, view, o, &OrderOptions::default(), &mut out)
                .unwrap();
            (o, out)
        })
        .collect()
}

/// Every ordering is a permutation; the grid orderings equal their definitions.
fn check_all(grid: &SparseGrid, view: &ViewCase) -> Vec<(Ordering, Vec<u32>)> {
    let orders = all_orders(grid, view);
    let mut ids: Vec<u32> = grid.ids().collect();
    ids.sort_unstable();
    for (ordering, out) in &orders {
        let mut sorted = out.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, ids, "{ordering} is not a permutation");
        if WITH_REFERENCE.contains(ordering) {
            assert_eq!(
                out,
                &reference::order(grid, view, *ordering, false),
                "{ordering}"
            );
        }
    }
    orders
}

fn dense(dims: [u32; 3], spacing: [f64; 3]) -> (VolumeGeometry, SparseGrid) {
    let geometry = VolumeGeometry::axis_aligned(dims, spacing, [0.0; 3]).unwrap();
    (geometry, SparseGrid::dense(dims).unwrap())
}

#[test]
fn eye_on_a_voxel_plane_and_half_way() {
    let (geometry, grid) = dense([9, 8, 7], [1.0, 1.0, 1.0]);
    for eye in [
        [4.0, 3.0, -5.0],
        [4.5, 3.5, -5.0],
        [4.5, 3.0, 3.5],
        [0.0, 0.0, 0.0],
    ] {
        let view = view_at(&geometry, eye);
        let orders = check_all(&grid, &view);
        let explicit = &orders
            .iter()
            .find(|(o, _)| *o == Ordering::IpPbtfExplicit)
            .unwrap()
            .1;
        let implicit = &orders
            .iter()
            .find(|(o, _)| *o == Ordering::IpPbtfImplicit)
            .unwrap()
            .1;
        assert_eq!(explicit, implicit, "eye {eye:?}");
    }
}

#[test]
fn eye_on_the_boundary_and_either_side_of_it() {
    let (geometry, grid) = dense([6, 5, 4], [1.0, 1.0, 1.0]);
    for (axis, n) in [(0usize, 6.0), (2, 4.0)] {
        for edge in [-0.5, n - 0.5] {
            let mut orders = Vec::new();
            for nudge in [-1e-9, 0.0, 1e-9] {
                let mut eye = [2.3, 1.7, 1.4];
                eye[axis] = edge + nudge;
                let view = view_at(&geometry, eye);
                let inside = (-0.5..=n - 0.5).contains(&eye[axis]);
                let expected = if inside {
                    CaseKind::VolumeOn
                } else {
                    CaseKind::FaceOn
                };
                assert_eq!(view.kind, expected, "axis {axis} at {}", eye[axis]);
                orders.push(check_all(&grid, &view));
            }
            // Crossing the boundary changes the case but not a single voxel of the grid orders:
            // the split there has one empty side. (The exact order may swap near-ties.)
            for ordering in [
                Ordering::Pbtf,
                Ordering::IpPbtfExplicit,
                Ordering::IpPbtfImplicit,
            ] {
                let pick = |i: usize| {
                    orders[i]
                        .iter()
                        .find(|(o, _)| *o == ordering)
                        .unwrap()
                        .1
                        .clone()
                };
                assert_eq!(pick(0), pick(1), "{ordering} at axis {axis} edge {edge}");
                assert_eq!(pick(1), pick(2), "{ordering} at axis {axis} edge {edge}");
            }
        }
    }
}

#[test]
fn eye_inside_one_voxel_draws_that_voxel_last() {
    let (geometry, grid) = dense([10, 10, 10], [0.7, 0.7, 2.5]);
    let view = view_at(&geometry, [5.2, 3.7, 4.1]);
    assert_eq!(view.kind, CaseKind::VolumeOn);
    let inside = 5 + 10 * (4 + 10 * 4);
    for (ordering, out) in check_all(&grid, &view) {
        // PBTF ends with the nearest corner of its last subvolume, not necessarily this voxel.
        if matches!(
            ordering,
            Ordering::IpPbtfImplicit
                | Ordering::IpPbtfExplicit
                | Ordering::Exact
                | Ordering::Bucketed
                | Ordering::Pyramid
                | Ordering::Rows
        ) {
            assert_eq!(*out.last().unwrap(), inside, "{ordering}");
        }
    }
}

#[test]
fn degenerate_grids() {
    for dims in [[1, 1, 1], [1, 7, 1], [7, 1, 1], [1, 1, 5]] {
        let (geometry, grid) = dense(dims, [1.0, 2.0, 0.5]);
        for eye in [
            [0.0, 0.0, 0.0],
            [0.2, 3.1, -0.4],
            [-4.0, 9.0, 2.0],
            [0.5, 0.5, 0.5],
        ] {
            let view = ViewCase::new(
                &geometry,
                geometry.index_to_world_point(DVec3::from(eye)),
                DVec3::new(10.0, -3.0, 1.0),
            )
            .unwrap();
            let orders = check_all(&grid, &view);
            if dims == [1, 1, 1] {
                assert!(orders.iter().all(|(_, o)| o == &[0]));
            }
        }
    }
}

#[test]
fn extreme_anisotropy() {
    let (geometry, grid) = dense([16, 16, 12], [0.1, 0.1, 10.0]);
    for eye in [[8.3, 7.6, -3.0], [7.5, 20.0, 6.2], [3.1, 4.4, 5.5]] {
        let view = view_at(&geometry, eye);
        check_all(&grid, &view);
    }
}

#[test]
fn far_origin_orders_like_the_same_view_at_the_origin() {
    // Eye about 1 mm from a volume whose origin is at 1e5 mm; the offsets differ by less than
    // f32 resolves at 1e5 (about 0.008 mm).
    let dims = [12, 10, 8];
    let grid = SparseGrid::dense(dims).unwrap();
    let mut orderer = Orderer::new();
    for offset in [
        [2.9995, 4.0, -1.0],
        [3.0005, 4.0, -1.0],
        [-0.4999, 4.5, 7.0],
    ] {
        let mut runs = Vec::new();
        for origin in [0.0, 1e5] {
            let geometry = VolumeGeometry::axis_aligned(dims, [1.0; 3], [origin; 3]).unwrap();
            let eye = DVec3::from(offset) + DVec3::splat(origin);
            let view = ViewCase::new(&geometry, eye, geometry.centre_world()).unwrap();
            let per: Vec<Vec<u32>> = Ordering::ALL
                .iter()
                .map(|&ordering| {
                    let mut out = Vec::new();
                    orderer
                        .order(&grid, &view, ordering, &OrderOptions::default(), &mut out)
                        .unwrap();
                    out
                })
                .collect();
            runs.push((view, per));
        }
        let (near, far) = (&runs[0], &runs[1]);
        assert_eq!(
            near.0.axes.map(|a| a.view),
            far.0.axes.map(|a| a.view),
            "split at {offset:?}"
        );
        for (i, ordering) in Ordering::ALL.iter().enumerate() {
            if GRID_ORDERINGS.contains(ordering) {
                assert!(
                    near.1[i] == far.1[i],
                    "{ordering} differs at offset {offset:?}"
                );
            }
        }
        // Exact ties (mirror-image voxels) fall to rounding, so compare the far volume's exact
        // order by the distances of the view at the origin.
        let exact = Ordering::ALL
            .iter()
            .position(|o| *o == Ordering::Exact)
            .unwrap();
        let d = |id: u32| near.0.distance_squared(grid.coords(id));
        for pair in far.1[exact].windows(2) {
            assert!(
                d(pair[1]) <= d(pair[0]) + 1e-9,
                "exact order at offset {offset:?}"
            );
        }
    }
    // The split these offsets straddle is one f32 cannot see.
    assert_eq!((1e5f32 + 2.9995) - 1e5, (1e5f32 + 3.0005) - 1e5);
}

#[test]
fn non_finite_eyes_are_errors() {
    let (geometry, _) = dense([4, 4, 4], [1.0; 3]);
    for eye in [
        DVec3::new(f64::NAN, 0.0, 0.0),
        DVec3::new(0.0, f64::INFINITY, 0.0),
    ] {
        let err = ViewCase::new(&geometry, eye, DVec3::ZERO).unwrap_err();
        assert!(matches!(err, OrderError::NonFiniteEye(_)), "{err}");
    }
    let err = ViewCase::new(
        &geometry,
        DVec3::ONE,
        DVec3::new(f64::NEG_INFINITY, 0.0, 0.0),
    )
    .unwrap_err();
    assert!(matches!(err, OrderError::NonFiniteTarget(_)));
    assert_eq!(
        ViewCase::new(&geometry, DVec3::ONE, DVec3::ONE).unwrap_err(),
        OrderError::DegenerateView
    );
    assert!(VolumeGeometry::axis_aligned([4, 4, 4], [1.0, 0.0, 1.0], [0.0; 3]).is_err());
    assert!(VolumeGeometry::axis_aligned([4, 0, 4], [1.0; 3], [0.0; 3]).is_err());
}

/// A million voxels away the projection is nearly parallel: PBTF and IP-PBTF reduce to BTF
/// (one subvolume, every axis walked away from the eye) and WBTF, and the images of every
/// ordering agree with BTF's to within a small tolerance.
#[test]
fn a_million_voxels_away_every_ordering_agrees_with_btf() {
    let dims = [12, 12, 12];
    let geometry = VolumeGeometry::axis_aligned(dims, [1.0; 3], [0.0; 3]).unwrap();
    let grid = SparseGrid::from_mask(dims, |id| id % 3 != 0).unwrap();
    let colors: Vec<[f32; 4]> = grid
        .ids()
        .map(|id| {
            let a = 0.15 + 0.5 * ((id * 37) % 11) as f32 / 11.0;
            let [r, g, b] = [(id % 5) as f32 / 4.0, (id % 7) as f32 / 6.0, 0.5];
            [r * a, g * a, b * a, a]
        })
        .collect();
    let centre = geometry.centre_world();
    let direction = DVec3::new(0.55, -0.45, 0.7).normalize();
    let eye = centre + direction * 1e6;
    let view = ViewCase::new(&geometry, eye, centre).unwrap();
    assert_eq!(view.kind, CaseKind::CornerOn);
    let orders = all_orders(&grid, &view);
    let get = |o: Ordering| orders.iter().find(|(x, _)| *x == o).unwrap().1.clone();
    assert_eq!(get(Ordering::Pbtf), get(Ordering::Btf));
    assert_eq!(get(Ordering::IpPbtfImplicit), get(Ordering::Wbtf));

    // A field of view that fits the volume from a million voxels away.
    let mut camera = Camera::looking_at(eye, centre, 96, 96);
    camera.up = Camera::safe_up(eye, centre);
    camera.fov_y_degrees = (2.0 * (12.0f64 / 1e6).atan()).to_degrees();
    let volume = SplatVolume {
        geometry: &geometry,
        grid: &grid,
        colors: &colors,
    };
    let style = SplatStyle::default();
    let (btf, _) = composite(&camera, &volume, &get(Ordering::Btf), &style).unwrap();
    assert!(
        btf.pixels.iter().any(|p| p[3] > 0.5),
        "the volume is on screen"
    );
    for ordering in Ordering::ALL {
        let (frame, _) = composite(&camera, &volume, &get(ordering), &style).unwrap();
        let d = compare(&frame, &btf).unwrap();
        assert!(d.rmse < 0.02, "{ordering}: rmse {} against BTF", d.rmse);
    }
}
