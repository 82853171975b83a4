//! The one traversal engine behind every grid ordering: two outer axes walked through given
//! coordinate sequences, the inner axis walked over run-length rows.

use super::view::{AxisCase, AxisView, ViewCase};
use crate::grid::{Run, SparseGrid, other_axes};

/// Receives voxels in traversal order.
pub(crate) trait Sink {
    /// Called before the voxels of a row; `k` holds the row's two fixed coordinates (the inner
    /// coordinate is 0).
    #[inline]
    fn row(&mut self, _k: [u32; 3], _inner_axis: usize) {}

    /// One voxel: its id and its inner-axis coordinate.
    fn voxel(&mut self, id: u32, k: u32);

    /// Voxels `from..to` of the row, upwards.
    #[inline]
    fn run_up(&mut self, base: u32, stride: u32, from: u32, to: u32) {
        for k in from..to {
            self.voxel(base + k * stride, k);
        }
    }

    /// Voxels `from..to` of the row, downwards (`to - 1` first).
    #[inline]
    fn run_down(&mut self, base: u32, stride: u32, from: u32, to: u32) {
        for k in (from..to).rev() {
            self.voxel(base + k * stride, k);
        }
    }

    /// Voxels at inner coordinates `coords` in this order; `offsets` holds `coord * stride`
    /// for each of them.
    #[inline]
    fn slice(&mut self, base: u32, coords: &[u32], offsets: &[u32]) {
        for (&k, &offset) in coords.iter().zip(offsets) {
            self.voxel(base + offset, k);
        }
    }
}

/// Appends ids to a list.
pub(crate) struct Collect<'a>(pub &'a mut Vec<u32>);

impl Sink for Collect<'_> {
    #[inline]
    fn voxel(&mut self, id: u32, _k: u32) {
        self.0.push(id);
    }

    #[inline]
    fn run_up(&mut self, base: u32, stride: u32, from: u32, to: u32) {
        self.0.extend((from..to).map(|k| base + k * stride));
    }

    #[inline]
    fn run_down(&mut self, base: u32, stride: u32, from: u32, to: u32) {
        self.0.extend((from..to).rev().map(|k| base + k * stride));
    }

    #[inline]
    fn slice(&mut self, base: u32, _coords: &[u32], offsets: &[u32]) {
        self.0.extend(offsets.iter().map(|&offset| base + offset));
    }
}

/// Appends the ids of the voxels `keep` holds for box `at` to a list: a walk and a filter in
/// one pass, so that the voxels a box's walk leaves out are never written.
pub(crate) struct CollectKept<'a, F> {
    out: &'a mut Vec<u32>,
    keep: &'a F,
    /// The box walked.
    at: usize,
    /// The row's coordinates (set by [`Sink::row`]) and its axis.
    k: [u32; 3],
    axis: usize,
}

impl<'a, F> CollectKept<'a, F> {
    /// Collects into `out` the voxels of box `at` that `keep` holds.
    pub fn new(out: &'a mut Vec<u32>, keep: &'a F, at: usize) -> Self {
        Self {
            out,
            keep,
            at,
            k: [0; 3],
            axis: 0,
        }
    }
}

impl<F: Fn(usize, [u32; 3]) -> bool> Sink for CollectKept<'_, F> {
    #[inline]
    fn row(&mut self, k: [u32; 3], inner_axis: usize) {
        (self.k, self.axis) = (k, inner_axis);
    }

    #[inline]
    fn voxel(&mut self, id: u32, k: u32) {
        let mut at = self.k;
        at[self.axis] = k;
        if (self.keep)(self.at, at) {
            self.out.push(id);
        }
    }
}

/// How the inner axis of each row is walked.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Inner<'a> {
    /// `lo..hi` upwards.
    Up { lo: u32, hi: u32 },
    /// `lo..hi` downwards.
    Down { lo: u32, hi: u32 },
    /// A split axis, implicitly interleaved (paper Algorithm 4): the lower side `..kv` walked up
    /// and the upper side `kv..` walked down, merged so that a lower voxel `kl` comes before an
    /// upper voxel `ku` exactly when `kl + ku <= c`. `sequence` is the whole axis in that
    /// order and `offsets` its coordinates times the axis stride: where a lower and an upper
    /// run overlap in the order, their voxels are one slice of it. Only `lo..hi` is walked.
    Merge {
        lo: u32,
        hi: u32,
        kv: u32,
        c: i64,
        sequence: &'a [u32],
        offsets: &'a [u32],
    },
    /// Every position of the sequence in turn, each tested for significance (explicit
    /// interleaving, paper Algorithms 2 and 3).
    Explicit(&'a [u32]),
}

impl<'a> Inner<'a> {
    /// The far-to-near walk of one axis over `lo..hi`: downwards or upwards when the eye is
    /// beyond one end, merged with threshold `c` ([`AxisCase::merge_threshold`]) when the axis
    /// is split. `sequence` is the axis' far-to-near order and `offsets` its coordinates times
    /// the axis stride.
    pub(crate) fn far_to_near(
        case: &AxisCase,
        (lo, hi): (u32, u32),
        c: i64,
        sequence: &'a [u32],
        offsets: &'a [u32],
    ) -> Self {
        match case.view {
            AxisView::Below => Self::Down { lo, hi },
            AxisView::Above => Self::Up { lo, hi },
            AxisView::Split { kv } => Self::Merge {
                lo,
                hi,
                kv,
                c,
                sequence,
                offsets,
            },
        }
    }
}

/// A traversal: axis nesting (slowest first), the coordinate sequences of the two outer axes,
/// and the inner walk.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Plan<'a> {
    pub perm: [usize; 3],
    pub outer: [&'a [u32]; 2],
    pub inner: Inner<'a>,
}

/// Walks `plan` over the significant voxels of `grid`, leaving out voxels at or behind the eye
/// plane of `cull` when given.
pub(crate) fn walk<S: Sink>(
    grid: &SparseGrid,
    plan: &Plan<'_>,
    cull: Option<&ViewCase>,
    sink: &mut S,
) {
    let strides = grid.strides();
    for &k0 in plan.outer[0] {
        for &k1 in plan.outer[1] {
            let mut k = [0u32; 3];
            k[plan.perm[0]] = k0;
            k[plan.perm[1]] = k1;
            let base = k0 * strides[plan.perm[0]] + k1 * strides[plan.perm[1]];
            walk_row(grid, k, base, plan.perm[2], &plan.inner, cull, sink);
        }
    }
}

/// Walks one row along `axis`: `k` holds its two fixed coordinates (the inner one is
/// ignored) and `base` their part of the id.
#[inline]
pub(crate) fn walk_row<S: Sink>(
    grid: &SparseGrid,
    k: [u32; 3],
    base: u32,
    axis: usize,
    inner: &Inner<'_>,
    cull: Option<&ViewCase>,
    sink: &mut S,
) {
    let (b, c) = other_axes(axis);
    let runs = grid.row(axis, k[b], k[c]);
    if runs.is_empty() {
        return;
    }
    let n = grid.dims()[axis];
    let (clo, chi) = match cull {
        Some(view) => in_front(view, k, axis, n),
        None => (0, n),
    };
    if clo >= chi {
        return;
    }
    let stride = grid.strides()[axis];
    sink.row(k, axis);
    match *inner {
        Inner::Up { lo, hi } => walk_up(runs, base, stride, lo.max(clo), hi.min(chi), sink),
        Inner::Down { lo, hi } => walk_down(runs, base, stride, lo.max(clo), hi.min(chi), sink),
        Inner::Merge {
            lo,
            hi,
            kv,
            c,
            sequence,
            offsets,
        } => {
            let axis = MergeAxis {
                n,
                kv,
                c,
                sequence,
                offsets,
            };
            let range = (lo.max(clo), hi.min(chi));
            if range.0 < range.1 {
                merge(runs, base, stride, range, &axis, sink)
            }
        }
        Inner::Explicit(seq) => {
            for &kk in seq {
                let id = base + kk * stride;
                if kk >= clo && kk < chi && grid.contains(id) {
                    sink.voxel(id, kk);
                }
            }
        }
    }
}

/// The interval of inner coordinates whose voxels lie strictly in front of the eye plane.
/// An estimate from the plane equation is corrected against [`ViewCase::eye_plane`] itself, so
/// the result agrees exactly with a voxel-by-voxel test.
fn in_front(view: &ViewCase, k: [u32; 3], axis: usize, n: u32) -> (u32, u32) {
    let front = |kk: u32| {
        let mut at = k;
        at[axis] = kk;
        view.eye_plane(at) > 0.0
    };
    let slope = view.eye_normal[axis];
    if slope == 0.0 {
        return if front(0) { (0, n) } else { (0, 0) };
    }
    let mut at0 = k;
    at0[axis] = 0;
    let crossing = (-view.eye_plane(at0) / slope).clamp(-1.0, f64::from(n) + 1.0);
    let mut g = crossing.floor().clamp(0.0, f64::from(n - 1)) as u32;
    // `rising`: the row is behind the plane below the boundary and in front from it on.
    let rising = slope > 0.0;
    // Find the boundary: the first coordinate whose side differs from the low end's.
    let low_side = !rising;
    while g > 0 && front(g - 1) != low_side {
        g -= 1;
    }
    while g < n && front(g) == low_side {
        g += 1;
    }
    if rising { (g, n) } else { (0, g) }
}

#[inline]
fn walk_up<S: Sink>(runs: &[Run], base: u32, stride: u32, lo: u32, hi: u32, sink: &mut S) {
    if lo >= hi {
        return;
    }
    let first = runs.partition_point(|r| r.end() <= lo);
    for run in &runs[first..] {
        if run.start >= hi {
            break;
        }
        sink.run_up(base, stride, run.start.max(lo), run.end().min(hi));
    }
}

#[inline]
fn walk_down<S: Sink>(runs: &[Run], base: u32, stride: u32, lo: u32, hi: u32, sink: &mut S) {
    if lo >= hi {
        return;
    }
    let last = runs.partition_point(|r| r.start < hi);
    for run in runs[..last].iter().rev() {
        if run.end() <= lo {
            break;
        }
        sink.run_down(base, stride, run.start.max(lo), run.end().min(hi));
    }
}

/// The far-to-near order of a split inner axis, with the position of each coordinate in it
/// computed rather than looked up.
pub(crate) struct MergeAxis<'a> {
    n: u32,
    kv: u32,
    c: i64,
    sequence: &'a [u32],
    offsets: &'a [u32],
}

impl MergeAxis<'_> {
    /// Number of lower voxels drawn before upper voxel `ku`: those with `kl + ku <= c`.
    #[inline]
    fn lower_before(&self, ku: u32) -> u32 {
        (self.c - i64::from(ku) + 1).clamp(0, i64::from(self.kv)) as u32
    }

    /// The first upper coordinate drawn before lower voxel `kl`: upper voxels from it to the
    /// top are those with `kl + ku > c`.
    #[inline]
    fn upper_from(&self, kl: u32) -> u32 {
        (self.c - i64::from(kl) + 1).clamp(i64::from(self.kv), i64::from(self.n)) as u32
    }

    /// Position of lower voxel `kl` in the order.
    #[inline]
    fn rank_lower(&self, kl: u32) -> usize {
        (kl + self.n - self.upper_from(kl)) as usize
    }

    /// Position of upper voxel `ku` in the order.
    #[inline]
    fn rank_upper(&self, ku: u32) -> usize {
        (self.n - 1 - ku + self.lower_before(ku)) as usize
    }
}

/// Merges the lower side `lo..kv` (walked up) with the upper side `kv..hi` (walked down) of one
/// row. While a lower run and an upper run are both live, the voxels of one that precede the
/// other's next voxel go first; from there on, every voxel of the axis order up to the end of
/// the first of the two runs to finish belongs to one of them, so that stretch is one slice of
/// the precomputed order, however finely the two sides alternate.
#[inline]
fn merge<S: Sink>(
    runs: &[Run],
    base: u32,
    stride: u32,
    (lo, hi): (u32, u32),
    axis: &MergeAxis<'_>,
    sink: &mut S,
) {
    let kv = axis.kv.clamp(lo, hi);
    let c = axis.c;
    // Lower cursor: run index and next voxel; upper cursor: run index and one past next voxel.
    // Runs wholly below the split, and whether the next one straddles it.
    let upper_runs_start = runs.partition_point(|r| r.end() <= kv);
    let lower_runs_end =
        upper_runs_start + usize::from(runs.get(upper_runs_start).is_some_and(|r| r.start < kv));
    let mut li = if lo == 0 {
        0
    } else {
        runs[..lower_runs_end].partition_point(|r| r.end() <= lo)
    };
    let mut lk = runs.get(li).map_or(kv, |r| r.start.max(lo));
    let mut ui = if hi == axis.n {
        runs.len()
    } else {
        upper_runs_start + runs[upper_runs_start..].partition_point(|r| r.start < hi)
    };
    let mut uk = if ui > upper_runs_start {
        runs[ui - 1].end().min(hi)
    } else {
        kv
    };
    loop {
        let lower_live = li < lower_runs_end && lk < kv;
        let upper_live = ui > upper_runs_start && uk > kv;
        if lower_live && upper_live {
            let lend = runs[li].end().min(kv);
            let ustart = runs[ui - 1].start.max(kv);
            let (rl, ru) = (axis.rank_lower(lk), axis.rank_upper(uk - 1));
            // The side that comes first runs alone up to the other side's next voxel.
            if rl < ru {
                let m = axis.lower_before(uk - 1);
                if m < lend {
                    sink.run_up(base, stride, lk, m);
                    lk = m;
                } else {
                    sink.run_up(base, stride, lk, lend);
                    li += 1;
                    lk = runs.get(li).map_or(kv, |r| r.start);
                    continue;
                }
            } else {
                let s = axis.upper_from(lk);
                if s > ustart {
                    sink.run_down(base, stride, s, uk);
                    uk = s;
                } else {
                    sink.run_down(base, stride, ustart, uk);
                    ui -= 1;
                    uk = next_upper(runs, ui, upper_runs_start, kv);
                    continue;
                }
            }
            // Both runs interleave from `rl.max(ru)` until the first of them ends.
            let (ql, qu) = (axis.rank_lower(lend - 1), axis.rank_upper(ustart));
            let (from, to) = (rl.max(ru), ql.min(qu) + 1);
            sink.slice(base, &axis.sequence[from..to], &axis.offsets[from..to]);
            if ql < qu {
                uk = (c - i64::from(lend) + 2).clamp(i64::from(ustart), i64::from(uk)) as u32;
                li += 1;
                lk = runs.get(li).map_or(kv, |r| r.start);
            } else {
                lk = (c - i64::from(ustart) + 1).clamp(i64::from(lk), i64::from(lend)) as u32;
                ui -= 1;
                uk = next_upper(runs, ui, upper_runs_start, kv);
            }
        } else if lower_live {
            let end = runs[li].end().min(kv);
            sink.run_up(base, stride, lk, end);
            li += 1;
            lk = runs.get(li).map_or(kv, |r| r.start);
        } else if upper_live {
            let start = runs[ui - 1].start.max(kv);
            sink.run_down(base, stride, start, uk);
            ui -= 1;
            uk = next_upper(runs, ui, upper_runs_start, kv);
        } else {
            return;
        }
    }
}

/// One past the top voxel of the upper run before index `ui`, or `kv` when none is left.
#[inline]
fn next_upper(runs: &[Run], ui: usize, upper_runs_start: usize, kv: u32) -> u32 {
    if ui > upper_runs_start {
        runs[ui - 1].end()
    } else {
        kv
    }
}
