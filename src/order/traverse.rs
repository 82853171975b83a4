//! The one traversal engine behind every grid ordering: two outer axes walked through given
//! coordinate sequences, the inner axis walked over run-length rows.

use super::view::ViewCase;
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
    /// upper voxel `ku` exactly when `kl + ku <= c`.
    Merge { kv: u32, c: i64 },
    /// Every position of the sequence in turn, each tested for significance (explicit
    /// interleaving, paper Algorithms 2 and 3).
    Explicit(&'a [u32]),
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
    let axis = plan.perm[2];
    let (b, c) = other_axes(axis);
    let strides = grid.strides();
    let stride = strides[axis];
    let n = grid.dims()[axis];
    for &k0 in plan.outer[0] {
        for &k1 in plan.outer[1] {
            let mut k = [0u32; 3];
            k[plan.perm[0]] = k0;
            k[plan.perm[1]] = k1;
            let runs = grid.row(axis, k[b], k[c]);
            if runs.is_empty() {
                continue;
            }
            let (clo, chi) = match cull {
                Some(view) => in_front(view, k, axis, n),
                None => (0, n),
            };
            if clo >= chi {
                continue;
            }
            let base = k0 * strides[plan.perm[0]] + k1 * strides[plan.perm[1]];
            sink.row(k, axis);
            match plan.inner {
                Inner::Up { lo, hi } => walk_up(runs, base, stride, lo.max(clo), hi.min(chi), sink),
                Inner::Down { lo, hi } => {
                    walk_down(runs, base, stride, lo.max(clo), hi.min(chi), sink)
                }
                Inner::Merge { kv, c } => {
                    merge(runs, base, stride, (clo, kv.clamp(clo, chi), chi), c, sink)
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

/// Merges the lower side `lo..kv` (walked up) with the upper side `kv..hi` (walked down).
/// Each step emits the largest batch of one side that precedes the other side's next voxel.
#[inline]
fn merge<S: Sink>(
    runs: &[Run],
    base: u32,
    stride: u32,
    (lo, kv, hi): (u32, u32, u32),
    c: i64,
    sink: &mut S,
) {
    // Lower cursor: run index and next voxel; upper cursor: run index and one past next voxel.
    let mut li = runs.partition_point(|r| r.end() <= lo);
    let lower_runs_end = runs.partition_point(|r| r.start < kv);
    let mut lk = runs.get(li).map_or(kv, |r| r.start.max(lo));
    let mut ui = runs.partition_point(|r| r.start < hi);
    let upper_runs_start = runs.partition_point(|r| r.end() <= kv);
    let mut uk = if ui > upper_runs_start {
        runs[ui - 1].end().min(hi)
    } else {
        kv
    };
    loop {
        let lower_live = li < lower_runs_end && lk < kv;
        let upper_live = ui > upper_runs_start && uk > kv;
        match (lower_live, upper_live) {
            (false, false) => return,
            (true, false) => {
                let end = runs[li].end().min(kv);
                sink.run_up(base, stride, lk, end);
                li += 1;
                lk = runs.get(li).map_or(kv, |r| r.start);
            }
            (false, true) => {
                let start = runs[ui - 1].start.max(kv);
                sink.run_down(base, stride, start, uk);
                ui -= 1;
                uk = if ui > upper_runs_start {
                    runs[ui - 1].end()
                } else {
                    kv
                };
            }
            (true, true) => {
                let ku = i64::from(uk - 1);
                if i64::from(lk) + ku <= c {
                    // Lower voxels up to c - ku come first.
                    let run_end = runs[li].end().min(kv);
                    let end = (c - ku + 1).min(i64::from(run_end)) as u32;
                    sink.run_up(base, stride, lk, end);
                    lk = end;
                    if lk == run_end {
                        li += 1;
                        lk = runs.get(li).map_or(kv, |r| r.start);
                    }
                } else {
                    // Upper voxels down to c - kl + 1 come first.
                    let run_start = runs[ui - 1].start.max(kv);
                    let start = (c - i64::from(lk) + 1).max(i64::from(run_start)) as u32;
                    sink.run_down(base, stride, start, uk);
                    uk = start;
                    if uk == run_start {
                        ui -= 1;
                        uk = if ui > upper_runs_start {
                            runs[ui - 1].end()
                        } else {
                            kv
                        };
                    }
                }
            }
        }
    }
}
