//! The bucketed distance order: a counting sort on world distance quantised into buckets,
//! farthest bucket first, IP-PBTF order inside each bucket. Two IP-PBTF walks over the
//! significant voxels and no temporary the size of the volume: the first counts the voxels of
//! each bucket, the second writes each id straight to its place.
//!
//! Distances come from per-axis tables of squared-distance terms in f32 (orthogonal grid axes)
//! or from the full quadratic form (sheared grids), summed the same way in both walks so that
//! every voxel lands in the bucket it was counted in.

use super::OrderError;
use super::distance::is_orthogonal;
use super::traverse::{Plan, Sink, walk};
use super::view::ViewCase;
use crate::grid::SparseGrid;

/// More buckets than this widen the buckets instead (bounds the scratch memory).
const MAX_BUCKETS: usize = 1 << 20;

/// The bucket width: the caller's, or half the smallest voxel spacing.
pub(crate) fn width(view: &ViewCase, requested: Option<f64>) -> Result<f64, OrderError> {
    match requested {
        Some(w) if w.is_finite() && w > 0.0 => Ok(w),
        Some(w) => Err(OrderError::BadBucketWidth(w)),
        None => {
            let g = view.gram;
            let smallest = g.x_axis.x.min(g.y_axis.y).min(g.z_axis.z).sqrt();
            Ok(0.5 * smallest)
        }
    }
}

/// Bucket cursors and distance tables kept between frames.
#[derive(Debug, Default)]
pub(crate) struct Scratch {
    cursors: Vec<u32>,
    terms: [Vec<f32>; 3],
    orthogonal: bool,
    view: Option<ViewCase>,
    nearest: f32,
    inverse_width: f32,
    last: usize,
}

/// Per-row state shared by both walks: the row's fixed squared-distance part.
struct RowDistance<'a> {
    scratch: &'a Scratch,
    k: [u32; 3],
    axis: usize,
    partial: f32,
}

impl RowDistance<'_> {
    #[inline]
    fn start_row(&mut self, k: [u32; 3], axis: usize) {
        self.k = k;
        self.axis = axis;
        if self.scratch.orthogonal {
            let t = &self.scratch.terms;
            let (b, c) = crate::grid::other_axes(axis);
            self.partial = t[b][k[b] as usize] + t[c][k[c] as usize];
        }
    }

    #[inline(always)]
    fn bucket(&mut self, k: u32) -> usize {
        let s = self.scratch;
        let q = if s.orthogonal {
            self.partial + s.terms[self.axis][k as usize]
        } else {
            self.k[self.axis] = k;
            s.view
                .as_ref()
                .map_or(0.0, |v| v.distance_squared(self.k) as f32)
        };
        // Saturating float-to-int cast: anything below the nearest bound is bucket 0.
        (((q.max(0.0).sqrt() - s.nearest) * s.inverse_width) as usize).min(s.last)
    }
}

impl Scratch {
    fn prepare(&mut self, view: &ViewCase, width: f64) {
        let g = view.gram;
        self.orthogonal = is_orthogonal(&g);
        self.view = Some(*view);
        for (a, terms) in self.terms.iter_mut().enumerate() {
            terms.clear();
            if self.orthogonal {
                let axis = &view.axes[a];
                let weight = g.col(a)[a];
                terms.extend((0..axis.n).map(|k| {
                    let d = f64::from(k) - axis.eye;
                    (weight * d * d) as f32
                }));
            }
        }
        let (nearest, farthest) = distance_bounds(view);
        let span = farthest - nearest;
        let mut buckets = (span / width).floor() as usize + 1;
        let mut width = width;
        if buckets > MAX_BUCKETS {
            buckets = MAX_BUCKETS;
            width = span / (MAX_BUCKETS - 1) as f64;
        }
        self.nearest = nearest as f32;
        self.inverse_width = (1.0 / width) as f32;
        self.last = buckets - 1;
        self.cursors.clear();
        self.cursors.resize(buckets, 0);
    }

    /// Orders the voxels: counts per bucket along `plan` (IP-PBTF), then walks it again and
    /// places each voxel after all farther buckets.
    pub(crate) fn order(
        &mut self,
        grid: &SparseGrid,
        view: &ViewCase,
        width: f64,
        plan: &Plan<'_>,
        cull: Option<&ViewCase>,
        out: &mut Vec<u32>,
    ) {
        self.prepare(view, width);
        let mut counts = std::mem::take(&mut self.cursors);
        let mut count = Count {
            row: self.row(),
            counts: &mut counts,
            current: 0,
            pending: 0,
        };
        walk(grid, plan, cull, &mut count);
        count.flush();
        // Farthest bucket first: each cursor starts after all farther buckets.
        let mut start = 0u32;
        for c in counts.iter_mut().rev() {
            let n = *c;
            *c = start;
            start += n;
        }
        out.clear();
        out.resize(start as usize, 0);
        let mut scatter = Scatter {
            row: self.row(),
            cursors: &mut counts,
            out,
            current: usize::MAX,
            slot: 0,
        };
        walk(grid, plan, cull, &mut scatter);
        scatter.flush();
        self.cursors = counts;
    }

    fn row(&self) -> RowDistance<'_> {
        RowDistance {
            scratch: self,
            k: [0; 3],
            axis: 0,
            partial: 0.0,
        }
    }
}

/// Counts voxels per bucket. Neighbouring voxels mostly share a bucket, so a run of equal
/// buckets is counted in a register and written once (no store-to-load chain per voxel).
struct Count<'a> {
    row: RowDistance<'a>,
    counts: &'a mut [u32],
    current: usize,
    pending: u32,
}

impl Count<'_> {
    fn flush(&mut self) {
        if self.pending > 0 {
            self.counts[self.current] += self.pending;
            self.pending = 0;
        }
    }
}

impl Sink for Count<'_> {
    #[inline]
    fn row(&mut self, k: [u32; 3], axis: usize) {
        self.row.start_row(k, axis);
    }

    #[inline(always)]
    fn voxel(&mut self, _id: u32, k: u32) {
        let b = self.row.bucket(k);
        if b != self.current {
            self.flush();
            self.current = b;
        }
        self.pending += 1;
    }
}

/// Writes each voxel after the farther buckets, keeping the current bucket's write position
/// in a register while the bucket stays the same.
struct Scatter<'a> {
    row: RowDistance<'a>,
    cursors: &'a mut [u32],
    out: &'a mut [u32],
    current: usize,
    slot: u32,
}

impl Scatter<'_> {
    fn flush(&mut self) {
        if let Some(c) = self.cursors.get_mut(self.current) {
            *c = self.slot;
        }
    }
}

impl Sink for Scatter<'_> {
    #[inline]
    fn row(&mut self, k: [u32; 3], axis: usize) {
        self.row.start_row(k, axis);
    }

    #[inline(always)]
    fn voxel(&mut self, id: u32, k: u32) {
        let b = self.row.bucket(k);
        if b != self.current {
            self.flush();
            self.current = b;
            self.slot = self.cursors[b];
        }
        self.out[self.slot as usize] = id;
        self.slot += 1;
    }
}

/// Lower and upper bounds of the world distance from the eye to any voxel centre. The upper
/// bound is exact (distance is convex, so its maximum is at a corner); the lower bound is the
/// distance to the nearest point of the grid's box, exact for orthogonal axes and otherwise
/// replaced by zero.
fn distance_bounds(view: &ViewCase) -> (f64, f64) {
    let mut farthest = 0.0f64;
    for corner in 0..8 {
        let k: [u32; 3] = std::array::from_fn(|a| {
            if corner >> a & 1 == 0 {
                0
            } else {
                view.axes[a].n - 1
            }
        });
        farthest = farthest.max(view.distance_squared(k));
    }
    let g = view.gram;
    let nearest = if is_orthogonal(&g) {
        let mut q = 0.0;
        for (a, axis) in view.axes.iter().enumerate() {
            let d = axis.eye - axis.eye.clamp(0.0, f64::from(axis.n - 1));
            q += g.col(a)[a] * d * d;
        }
        q.sqrt()
    } else {
        0.0
    };
    (nearest.min(farthest.sqrt()), farthest.sqrt())
}
