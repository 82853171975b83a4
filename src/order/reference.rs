//! Slow, obviously correct orderings by comparison sort, straight from the definitions in the
//! [module documentation](super). Tests compare every fast path against these.

use std::cmp::Ordering as Cmp;

use super::view::ViewCase;
use super::{Ordering, pbtf_subvolumes};
use crate::grid::SparseGrid;

/// The draw order of `ordering` by sorting the significant voxels with its comparison; voxels
/// at or behind the eye plane are left out when `cull` holds.
pub fn order(grid: &SparseGrid, view: &ViewCase, ordering: Ordering, cull: bool) -> Vec<u32> {
    let mut ids: Vec<u32> = grid
        .ids()
        .filter(|&id| !cull || view.eye_plane(grid.coords(id)) > 0.0)
        .collect();
    let key = |id: u32| grid.coords(id);
    match ordering {
        Ordering::Btf => ids.sort_by(|&a, &b| btf_cmp(view, [2, 1, 0], key(a), key(b))),
        Ordering::Wbtf => {
            ids.sort_by(|&a, &b| btf_cmp(view, view.wbtf_permutation, key(a), key(b)))
        }
        Ordering::Pbtf => {
            let parts = pbtf_subvolumes(view);
            let part_of = |k: [u32; 3]| {
                parts
                    .iter()
                    .position(|p| (0..3).all(|a| k[a] >= p[a].0 && k[a] < p[a].1))
                    .expect("subvolumes cover the grid")
            };
            ids.sort_by(|&a, &b| {
                let (ka, kb) = (key(a), key(b));
                part_of(ka)
                    .cmp(&part_of(kb))
                    .then_with(|| toward_eye_cmp(view, [2, 1, 0], ka, kb))
            });
        }
        Ordering::IpPbtfExplicit | Ordering::IpPbtfImplicit => {
            ids.sort_by(|&a, &b| toward_eye_cmp(view, view.permutation, key(a), key(b)));
        }
        Ordering::Exact => ids.sort_by(|&a, &b| {
            let (da, db) = (view.distance_squared(key(a)), view.distance_squared(key(b)));
            db.total_cmp(&da).then(a.cmp(&b))
        }),
        Ordering::Pyramid => ids.sort_by(|&a, &b| super::pyramid::compare(view, key(a), key(b))),
        Ordering::Rows => ids.sort_by(|&a, &b| super::rows::compare(view, key(a), key(b))),
        Ordering::Bucketed => {
            panic!("the bucketed order has no comparison-sort reference; test it against exact")
        }
    }
    ids
}

/// Lexicographic by axis in `perm` order, each axis far to near by `|k - e|`, ties lower first.
fn toward_eye_cmp(view: &ViewCase, perm: [usize; 3], a: [u32; 3], b: [u32; 3]) -> Cmp {
    for axis in perm {
        let (x, y) = (a[axis], b[axis]);
        if x != y {
            return if view.axes[axis].farther(x, y) {
                Cmp::Less
            } else {
                Cmp::Greater
            };
        }
    }
    Cmp::Equal
}

/// Lexicographic by axis in `perm` order, each axis in its BTF direction.
fn btf_cmp(view: &ViewCase, perm: [usize; 3], a: [u32; 3], b: [u32; 3]) -> Cmp {
    for axis in perm {
        let (x, y) = (a[axis], b[axis]);
        if x != y {
            let descending = view.btf_descending(axis);
            return if (x > y) == descending {
                Cmp::Less
            } else {
                Cmp::Greater
            };
        }
    }
    Cmp::Equal
}
