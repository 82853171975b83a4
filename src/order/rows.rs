//! The rows order: the grid cut into rows along one axis, the rows drawn by their distance from
//! the eye, farthest first, each row far to near along its axis.
//!
//! IP-PBTF draws the rows of a slab lexicographically by the two slower axes, so on a grid with
//! one thick axis (CT slices 2.5 mm apart, 0.7 mm pixels) a row one slice farther goes before a
//! nearer-looking row one slice nearer even where, off to the side, the second is the farther.
//! Sorting the rows by the distance from the eye to each row's line puts every pair of voxels
//! at the same position along the row axis in exact order; only pairs that differ along the
//! row axis and lie in different rows can still be swapped. The row axis is the one along
//! which voxels are, on average, least far from the eye's plane in world units times spacing
//! ([`row_axis`]), so that those remaining swaps are as rare as they can be.
//!
//! The cost is one sort of the rows (a few tens of thousands for a CT volume, against hundreds
//! of thousands to millions of voxels) and the same row walks as IP-PBTF's inner loop.

use glam::DVec3;
use rdst::RadixSort;

use super::distance::FarthestFirst;
use super::traverse::{Inner, Sink, walk_row};
use super::view::ViewCase;
use crate::grid::{SparseGrid, other_axes};

/// The axis the rows run along: the one whose `g_aa * mean_k |k - e_a|` over the grid's
/// coordinates `k` is smallest (world spacing times the mean world offset from the eye along
/// the axis), ties to the lower axis. A step along a row changes a voxel's distance by about
/// that much, and a smaller change leaves fewer pairs of neighbouring rows out of order.
pub(crate) fn row_axis(view: &ViewCase) -> usize {
    let score = |a: usize| {
        let axis = &view.axes[a];
        view.gram.col(a)[a] * mean_offset(axis.n, axis.eye)
    };
    (0..3)
        .min_by(|&x, &y| score(x).total_cmp(&score(y)))
        .expect("three axes")
}

/// The mean of `|k - e|` over `k` in `0..n`, in closed form.
fn mean_offset(n: u32, e: f64) -> f64 {
    let n = f64::from(n);
    // `m`: the last coordinate at or below the eye, -1 when there is none.
    let m = e.floor().clamp(-1.0, n - 1.0);
    // Below the eye: sum over k in 0..=m of (e - k); above: sum over k in m+1..n of (k - e).
    let below = (m + 1.0) * e - m * (m + 1.0) / 2.0;
    let above = (n - 1.0) * n / 2.0 - m * (m + 1.0) / 2.0 - (n - 1.0 - m) * e;
    (below + above) / n
}

/// World squared distance from the eye to the line of the row along `axis` through `k` (the
/// coordinate along `axis` is ignored), never negative. For orthogonal grid axes this is
/// `g_bb (k_b - e_b)^2 + g_cc (k_c - e_c)^2`.
pub(crate) fn row_distance_squared(view: &ViewCase, axis: usize, k: [u32; 3]) -> f64 {
    let mut d = DVec3::new(
        f64::from(k[0]) - view.eye.x,
        f64::from(k[1]) - view.eye.y,
        f64::from(k[2]) - view.eye.z,
    );
    d[axis] = 0.0;
    // The point of the line nearest the eye: `d + t * unit(axis)` with the gradient along
    // the axis zero.
    let g = view.gram;
    let t = -g.col(axis).dot(d) / g.col(axis)[axis];
    d[axis] = t;
    let q = d.dot(g * d);
    if q > 0.0 { q } else { 0.0 }
}

/// Row keys and the row axis' far-to-near order, kept between frames.
#[derive(Debug, Default)]
pub(crate) struct Scratch {
    /// Per row: its squared distance and its index `k_b + n_b * k_c`.
    keys: Vec<FarthestFirst>,
    sequence: Vec<u32>,
    offsets: Vec<u32>,
}

impl Scratch {
    /// Feeds the significant voxels of `grid` to `sink` in the rows order, leaving out voxels
    /// at or behind the eye plane of `cull` when given.
    pub(crate) fn order<S: Sink>(
        &mut self,
        grid: &SparseGrid,
        view: &ViewCase,
        cull: Option<&ViewCase>,
        sink: &mut S,
    ) {
        let axis = row_axis(view);
        let (b, c) = other_axes(axis);
        let dims = grid.dims();
        self.keys.clear();
        for kc in 0..dims[c] {
            for kb in 0..dims[b] {
                if grid.row(axis, kb, kc).is_empty() {
                    continue;
                }
                let mut k = [0; 3];
                k[b] = kb;
                k[c] = kc;
                let q = row_distance_squared(view, axis, k);
                // At most the number of voxels, which fits a u32.
                self.keys.push(FarthestFirst::new(q, kb + dims[b] * kc));
            }
        }
        self.keys.radix_sort_unstable();

        let case = &view.axes[axis];
        let stride = grid.strides()[axis];
        self.sequence.clear();
        case.far_to_near(&mut self.sequence);
        self.offsets.clear();
        self.offsets
            .extend(self.sequence.iter().map(|&k| k * stride));
        let inner = Inner::far_to_near(
            case,
            (0, case.n),
            case.merge_threshold(),
            &self.sequence,
            &self.offsets,
        );
        let strides = grid.strides();
        for key in &self.keys {
            let (kb, kc) = (key.index % dims[b], key.index / dims[b]);
            let mut k = [0; 3];
            k[b] = kb;
            k[c] = kc;
            let base = kb * strides[b] + kc * strides[c];
            walk_row(grid, k, base, axis, &inner, cull, sink);
        }
    }
}

/// Compares two voxels by the rows order: the farther row first (ties: lower row index), then
/// far to near along the row axis. `Less` means `a` is drawn first.
pub(crate) fn compare(view: &ViewCase, a: [u32; 3], b: [u32; 3]) -> std::cmp::Ordering {
    let axis = row_axis(view);
    let (u, v) = other_axes(axis);
    let n = view.axes[u].n;
    let row = |k: [u32; 3]| k[u] + n * k[v];
    let (qa, qb) = (
        row_distance_squared(view, axis, a),
        row_distance_squared(view, axis, b),
    );
    qb.total_cmp(&qa).then(row(a).cmp(&row(b))).then_with(|| {
        let (x, y) = (a[axis], b[axis]);
        if x == y {
            std::cmp::Ordering::Equal
        } else if view.axes[axis].farther(x, y) {
            std::cmp::Ordering::Less
        } else {
            std::cmp::Ordering::Greater
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::order::fixtures::{anisotropic_and_sheared, eye_at, sparse};
    use crate::order::{OrderOptions, Ordering, VolumeGeometry, order, reference};

    fn eyes(geometry: &VolumeGeometry) -> impl Iterator<Item = DVec3> + '_ {
        [
            [0.43, 0.56, -0.35],
            [0.41, 0.37, 0.45],
            [0.47, -0.45, -0.4],
            [-0.6, -0.5, 1.45],
            [1.8, 0.5, 0.52],
        ]
        .into_iter()
        .map(move |f| eye_at(geometry, f))
    }

    /// The walk gives the comparison-sort definition, on an anisotropic and on a sheared grid,
    /// dense and sparse, with and without culling.
    #[test]
    fn rows_order_is_its_definition() {
        for geometry in &anisotropic_and_sheared() {
            for keep in [sparse as fn(u32) -> bool, |_| true] {
                let grid = SparseGrid::from_mask(geometry.dims(), keep).unwrap();
                for eye in eyes(geometry) {
                    let view = ViewCase::new(geometry, eye, geometry.centre_world()).unwrap();
                    for cull in [false, true] {
                        let options = OrderOptions {
                            cull_behind_eye: cull,
                            ..OrderOptions::default()
                        };
                        let got = order(&grid, &view, Ordering::Rows, &options).unwrap();
                        let expected = reference::order(&grid, &view, Ordering::Rows, cull);
                        assert_eq!(got, expected, "eye {eye} cull {cull}");
                    }
                }
            }
        }
    }

    /// What the order promises on orthogonal grids: two voxels at the same coordinate along
    /// the row axis, or in the same row, are drawn in exact distance order (farther first).
    #[test]
    fn voxels_level_along_the_row_axis_are_in_distance_order() {
        let geometry = VolumeGeometry::axis_aligned([12, 9, 7], [0.7, 0.7, 2.5], [0.0; 3]).unwrap();
        let grid = SparseGrid::dense(geometry.dims()).unwrap();
        let mut axes_seen = [false; 3];
        for eye in eyes(&geometry) {
            let view = ViewCase::new(&geometry, eye, geometry.centre_world()).unwrap();
            let axis = row_axis(&view);
            axes_seen[axis] = true;
            let list = order(&grid, &view, Ordering::Rows, &OrderOptions::default()).unwrap();
            let mut position = vec![0usize; list.len()];
            for (i, &id) in list.iter().enumerate() {
                position[id as usize] = i;
            }
            let (b, c) = other_axes(axis);
            let mut checked = 0;
            for x in 0..list.len() as u32 {
                for y in 0..list.len() as u32 {
                    let (kx, ky) = (grid.coords(x), grid.coords(y));
                    let level = kx[axis] == ky[axis];
                    let same_row = kx[b] == ky[b] && kx[c] == ky[c];
                    let (dx, dy) = (view.distance_squared(kx), view.distance_squared(ky));
                    if (level || same_row) && dx > dy * (1.0 + 1e-12) {
                        assert!(
                            position[x as usize] < position[y as usize],
                            "eye {eye}: {kx:?} is farther than {ky:?} but drawn after it"
                        );
                        checked += 1;
                    }
                }
            }
            assert!(checked > 1000);
        }
        assert!(
            axes_seen.iter().filter(|&&s| s).count() >= 2,
            "the eyes pick more than one row axis: {axes_seen:?}"
        );
    }

    #[test]
    fn mean_offset_matches_the_sum() {
        for n in [1u32, 2, 7, 64] {
            for e in [-3.2, -0.5, 0.0, 0.3, 2.5, 3.0, 6.9, 63.0, 70.0] {
                let sum: f64 = (0..n).map(|k| (f64::from(k) - e).abs()).sum();
                let mean = mean_offset(n, e);
                assert!(
                    (mean - sum / f64::from(n)).abs() < 1e-9,
                    "n {n} e {e}: {mean} against {}",
                    sum / f64::from(n)
                );
            }
        }
    }
}
