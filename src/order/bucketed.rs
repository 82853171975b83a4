//! The bucketed distance order: a counting sort on world distance quantised into buckets,
//! farthest bucket first, IP-PBTF order inside each bucket. Two passes over the significant
//! voxels and no temporary the size of the volume: the first counts voxels per bucket, the
//! second walks IP-PBTF and writes each id straight to its place.

use super::OrderError;
use super::distance::{DistanceTable, is_orthogonal};
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

/// Bucket counts and write cursors kept between frames.
#[derive(Debug, Default)]
pub(crate) struct Scratch {
    cursors: Vec<u32>,
    table: DistanceTable,
    nearest: f64,
    inverse_width: f64,
}

impl Scratch {
    #[inline]
    fn bucket(&self, k: [u32; 3]) -> usize {
        let d = self.table.distance_squared(k).max(0.0).sqrt();
        // Saturating float-to-int casts: below the nearest bound is bucket 0.
        (((d - self.nearest) * self.inverse_width) as usize).min(self.cursors.len() - 1)
    }

    /// First pass: sizes the buckets for this view and counts the voxels in each; returns the
    /// number of voxels counted.
    pub(crate) fn count(
        &mut self,
        grid: &SparseGrid,
        view: &ViewCase,
        width: f64,
        id_order: &Plan<'_>,
        cull: Option<&ViewCase>,
    ) -> usize {
        self.table.prepare(view);
        let (nearest, farthest) = distance_bounds(view);
        let span = farthest - nearest;
        let mut buckets = (span / width).floor() as usize + 1;
        let mut width = width;
        if buckets > MAX_BUCKETS {
            buckets = MAX_BUCKETS;
            width = span / (MAX_BUCKETS - 1) as f64;
        }
        self.nearest = nearest;
        self.inverse_width = 1.0 / width;
        self.cursors.clear();
        self.cursors.resize(buckets, 0);
        struct Count<'a> {
            scratch: &'a mut Scratch,
            k: [u32; 3],
            axis: usize,
        }
        impl Sink for Count<'_> {
            #[inline]
            fn row(&mut self, k: [u32; 3], axis: usize) {
                self.k = k;
                self.axis = axis;
            }
            #[inline]
            fn voxel(&mut self, _id: u32, k: u32) {
                self.k[self.axis] = k;
                let b = self.scratch.bucket(self.k);
                self.scratch.cursors[b] += 1;
            }
        }
        walk(
            grid,
            id_order,
            cull,
            &mut Count {
                scratch: self,
                k: [0; 3],
                axis: 0,
            },
        );
        // Farthest bucket first: each cursor starts after all farther buckets.
        let mut start = 0u32;
        for c in self.cursors.iter_mut().rev() {
            let n = *c;
            *c = start;
            start += n;
        }
        start as usize
    }

    /// Second pass: walks `plan` (IP-PBTF) and places each voxel after the farther buckets.
    pub(crate) fn scatter(
        &mut self,
        grid: &SparseGrid,
        plan: &Plan<'_>,
        cull: Option<&ViewCase>,
        total: usize,
        out: &mut Vec<u32>,
    ) {
        out.clear();
        out.resize(total, 0);
        struct Scatter<'a> {
            scratch: &'a mut Scratch,
            out: &'a mut [u32],
            k: [u32; 3],
            axis: usize,
        }
        impl Sink for Scatter<'_> {
            #[inline]
            fn row(&mut self, k: [u32; 3], axis: usize) {
                self.k = k;
                self.axis = axis;
            }
            #[inline]
            fn voxel(&mut self, id: u32, k: u32) {
                self.k[self.axis] = k;
                let b = self.scratch.bucket(self.k);
                let slot = &mut self.scratch.cursors[b];
                self.out[*slot as usize] = id;
                *slot += 1;
            }
        }
        walk(
            grid,
            plan,
            cull,
            &mut Scatter {
                scratch: self,
                out,
                k: [0; 3],
                axis: 0,
            },
        );
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
