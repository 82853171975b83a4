//! The pyramid order: the grid cut by planes through the eye into six pyramids, one per axis
//! and side, each with its apex at the eye and its base on the grid's boundary; each pyramid is
//! drawn slab by slab along its own axis toward the eye, and the slabs of all six are
//! interleaved far to near. Inside a slab the same rule is applied once more, in two
//! dimensions: the slab is cut by the lines through the eye's foot point into four triangles,
//! each drawn row by row along its own axis, the rows of all four interleaved far to near.
//!
//! Axis-nested orders (WBTF, PBTF, IP-PBTF) draw whole slabs of one axis for the whole volume.
//! Where a viewing ray runs more than about 45 degrees from that axis, a voxel of a farther slab
//! can be nearer than its neighbour in the next slab, and the two overlap on screen in the wrong
//! order; inside a slab the same happens between its two axes. Here each voxel is drawn in the
//! slab of the axis along which it is farthest from the eye, weighted by the squared spacing, so
//! the slab axis is the one its ray runs most nearly along (for two neighbours one step apart on
//! two axes, the weighting is, to first order, the condition for slab order to agree with
//! distance).
//! Every ray from the eye crosses the slabs of its pyramid in distance order, and two pyramids
//! meet only along planes through the eye, which project to lines on the screen.
//!
//! # Definition
//! With `e` the eye in index coordinates and `g` the metric ([`ViewCase::gram`]), voxel `k` has
//! per axis the weighted distance `m_a = |k_a - e_a| * g_aa`.
//!
//! 1. Its pyramid is the axis `a` with the largest `m_a` (ties: the axis earlier in
//!    [`ViewCase::permutation`]); its slab key is that largest value. Voxels go by slab key
//!    descending; equal keys by pyramid axis in permutation order, then lower slab coordinate
//!    first.
//! 2. Inside a slab of axis `a`, the other two axes are `(o, i)`: `(z, y)` for x slabs,
//!    `(z, x)` for y slabs, `(y, x)` for z slabs. The voxel's row axis is `o` when
//!    `m_o >= m_i` (a row along `i` at fixed `o`), otherwise `i` (a row along `o` at fixed
//!    `i`); its row key is `max(m_o, m_i)`. Rows go by row key descending; equal keys rows at
//!    fixed `o` first, then lower fixed coordinate first.
//! 3. Inside a row, far to near along it, ties lower coordinate first, as in IP-PBTF.
//!
//! Every slab face is a rectangle and every row a segment: the coordinates allowed on an axis
//! are those below a key, the nearest ones, which is a suffix of the axis' far-to-near order
//! and an interval of coordinates. So the traversal walks one run-length row per segment, with
//! the two sides of a split row merged as in IP-PBTF (paper Algorithm 4), and does no
//! per-voxel work beyond that walk.

use std::cmp::Ordering as Cmp;

use super::traverse::{Inner, Sink, walk_row};
use super::view::ViewCase;
use crate::grid::SparseGrid;

/// The two other axes `(o, i)` of a slab of each axis.
const SLAB_AXES: [(usize, usize); 3] = [(2, 1), (2, 0), (1, 0)];

/// Weighted distance of coordinate `k` from the eye along `axis`: `|k - e| * g_aa`.
#[inline]
fn weighted(view: &ViewCase, axis: usize, k: u32) -> f64 {
    (f64::from(k) - view.axes[axis].eye).abs() * view.gram.col(axis)[axis]
}

/// Rank of `axis` in the tie order between pyramids.
fn priority(view: &ViewCase, axis: usize) -> usize {
    view.permutation
        .iter()
        .position(|&a| a == axis)
        .expect("a permutation holds every axis")
}

/// The pyramid axis and slab key of voxel `k`.
fn pyramid_of(view: &ViewCase, k: [u32; 3]) -> (usize, f64) {
    let mut best = view.permutation[0];
    let mut key = weighted(view, best, k[best]);
    for &axis in &view.permutation[1..] {
        let m = weighted(view, axis, k[axis]);
        if m > key {
            best = axis;
            key = m;
        }
    }
    (best, key)
}

/// Inside a slab of `axis`: the row key, whether the row is at fixed `o` (drawn first on equal
/// keys), the row's fixed coordinate and the axis the row runs along.
fn row_of(view: &ViewCase, axis: usize, k: [u32; 3]) -> (f64, bool, u32, usize) {
    let (o, i) = SLAB_AXES[axis];
    let (mo, mi) = (weighted(view, o, k[o]), weighted(view, i, k[i]));
    if mo >= mi {
        (mo, true, k[o], i)
    } else {
        (mi, false, k[i], o)
    }
}

/// The comparison of the definition: `Less` when `a` is drawn first.
pub(crate) fn compare(view: &ViewCase, a: [u32; 3], b: [u32; 3]) -> Cmp {
    let (pa, ka) = pyramid_of(view, a);
    let (pb, kb) = pyramid_of(view, b);
    kb.total_cmp(&ka)
        .then_with(|| priority(view, pa).cmp(&priority(view, pb)))
        .then_with(|| a[pa].cmp(&b[pa]))
        .then_with(|| {
            let (ra, fixed_o_a, ca, along) = row_of(view, pa, a);
            let (rb, fixed_o_b, cb, _) = row_of(view, pa, b);
            rb.total_cmp(&ra)
                .then(fixed_o_b.cmp(&fixed_o_a))
                .then(ca.cmp(&cb))
                .then_with(|| {
                    let (x, y) = (a[along], b[along]);
                    if x == y {
                        Cmp::Equal
                    } else if view.axes[along].farther(x, y) {
                        Cmp::Less
                    } else {
                        Cmp::Greater
                    }
                })
        })
}

/// One slab of one pyramid.
#[derive(Debug, Clone, Copy)]
struct Face {
    key: f64,
    priority: u8,
    axis: u8,
    k: u32,
}

/// Per-axis tables and the face list, kept between frames.
#[derive(Debug, Default)]
pub(crate) struct Scratch {
    /// Far-to-near coordinates of each axis.
    sequences: [Vec<u32>; 3],
    /// `weighted` of each entry of `sequences` (non-increasing).
    weights: [Vec<f64>; 3],
    /// Smallest and largest coordinate of each suffix of `sequences`.
    suffix_min: [Vec<u32>; 3],
    suffix_max: [Vec<u32>; 3],
    /// `sequences` times the axis stride.
    offsets: [Vec<u32>; 3],
    /// The merge threshold of each axis (see [`Inner::Merge`]).
    thresholds: [i64; 3],
    faces: Vec<Face>,
}

impl Scratch {
    fn prepare(&mut self, grid: &SparseGrid, view: &ViewCase) {
        for (axis, stride) in grid.strides().into_iter().enumerate() {
            let seq = &mut self.sequences[axis];
            seq.clear();
            view.axes[axis].far_to_near(seq);
            let weights = &mut self.weights[axis];
            weights.clear();
            weights.extend(seq.iter().map(|&k| weighted(view, axis, k)));
            let (min, max) = (&mut self.suffix_min[axis], &mut self.suffix_max[axis]);
            min.clear();
            max.clear();
            min.resize(seq.len(), 0);
            max.resize(seq.len(), 0);
            let (mut lo, mut hi) = (u32::MAX, 0);
            for (j, &k) in seq.iter().enumerate().rev() {
                lo = lo.min(k);
                hi = hi.max(k);
                min[j] = lo;
                max[j] = hi;
            }
            self.thresholds[axis] = view.axes[axis].merge_threshold();
            let offsets = &mut self.offsets[axis];
            offsets.clear();
            offsets.extend(seq.iter().map(|&k| k * stride));
        }
        self.faces.clear();
        for axis in 0..3 {
            let priority = priority(view, axis) as u8;
            self.faces.extend((0..view.axes[axis].n).map(|k| Face {
                key: weighted(view, axis, k),
                priority,
                axis: axis as u8,
                k,
            }));
        }
        self.faces.sort_unstable_by(|a, b| {
            b.key
                .total_cmp(&a.key)
                .then(a.priority.cmp(&b.priority))
                .then(a.k.cmp(&b.k))
        });
    }

    /// Index of the first entry of `axis`' sequence whose voxels may lie in `face`: the entries
    /// before it have a larger weighted distance (or an equal one and a higher priority), so
    /// those voxels belong to another pyramid.
    fn allowed_from(&self, axis: usize, face: &Face, view: &ViewCase) -> usize {
        let weights = &self.weights[axis];
        if priority(view, axis) < usize::from(face.priority) {
            weights.partition_point(|&m| m >= face.key)
        } else {
            weights.partition_point(|&m| m > face.key)
        }
    }

    /// The walk of `axis` over the coordinates of its sequence from index `from` on (an
    /// interval around the eye's coordinate).
    fn inner(&self, view: &ViewCase, axis: usize, from: usize) -> Inner<'_> {
        Inner::far_to_near(
            &view.axes[axis],
            (self.suffix_min[axis][from], self.suffix_max[axis][from] + 1),
            self.thresholds[axis],
            &self.sequences[axis],
            &self.offsets[axis],
        )
    }

    /// Walks every face, farthest first, and inside each face every row, into `sink`.
    pub(crate) fn order<S: Sink>(
        &mut self,
        grid: &SparseGrid,
        view: &ViewCase,
        cull: Option<&ViewCase>,
        sink: &mut S,
    ) {
        self.prepare(grid, view);
        let strides = grid.strides();
        for face in &self.faces {
            let axis = usize::from(face.axis);
            let (o, i) = SLAB_AXES[axis];
            let (wo, wi) = (&self.weights[o], &self.weights[i]);
            let (so, si) = (&self.sequences[o], &self.sequences[i]);
            let (o_from, i_from) = (
                self.allowed_from(o, face, view),
                self.allowed_from(i, face, view),
            );
            if o_from == so.len() || i_from == si.len() {
                continue;
            }
            let slab_base = face.k * strides[axis];
            // Rows at fixed `o` (along `i`) and at fixed `i` (along `o`), merged by row key.
            // Each row's extent is a suffix of its axis' sequence that only shrinks as the key
            // falls, so its start is found by moving forward.
            let (mut p, mut q) = (o_from, i_from);
            let (mut along_i_from, mut along_o_from) = (i_from, o_from);
            loop {
                let fixed_o = p < so.len() && (q == si.len() || wo[p] >= wi[q]);
                let (fixed, along, from) = if fixed_o {
                    let key = wo[p];
                    while along_i_from < si.len() && wi[along_i_from] > key {
                        along_i_from += 1;
                    }
                    p += 1;
                    ((o, so[p - 1]), i, along_i_from)
                } else if q < si.len() {
                    let key = wi[q];
                    while along_o_from < so.len() && wo[along_o_from] >= key {
                        along_o_from += 1;
                    }
                    q += 1;
                    ((i, si[q - 1]), o, along_o_from)
                } else {
                    break;
                };
                if from == self.sequences[along].len() {
                    continue;
                }
                let mut k = [0; 3];
                k[axis] = face.k;
                k[fixed.0] = fixed.1;
                let base = slab_base + fixed.1 * strides[fixed.0];
                let inner = self.inner(view, along, from);
                walk_row(grid, k, base, along, &inner, cull, sink);
            }
        }
    }
}
