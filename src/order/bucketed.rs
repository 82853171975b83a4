//! The bucketed distance order: world distance quantised into buckets, farthest bucket first,
//! IP-PBTF order inside each bucket, with no temporary the size of the volume.
//!
//! Where the buckets are few against the voxels, one IP-PBTF walk appends each id to its
//! bucket's chain of fixed-size blocks, and the chains are then copied out farthest first.
//! Otherwise (a chain's last block would be mostly empty) a counting sort does it in two
//! walks: the first counts the voxels of each bucket, the second writes each id straight to its
//! place. Both give the same list.
//!
//! Distances come from per-axis tables of squared-distance terms in f32 (orthogonal grid axes)
//! or from the full quadratic form (sheared grids), summed the same way in both walks so that
//! every voxel lands in the bucket it was counted in.

use super::OrderError;
use super::distance::{axis_terms, is_orthogonal};
use super::traverse::{Plan, Sink, walk};
use super::view::ViewCase;
use crate::grid::SparseGrid;

/// More buckets than this widen the buckets instead (bounds the scratch memory).
const MAX_BUCKETS: usize = 1 << 20;

/// Ids per block of the one-walk path. It runs only where `buckets * BLOCK` is at most the
/// number of significant voxels, so the blocks hold at most twice the list.
const BLOCK: u32 = 64;

/// No block.
const NONE: u32 = u32::MAX;

/// Nearer buckets tried one by one before a voxel's bucket is searched for.
const NEARER_TRIED: usize = 8;

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

/// Bucket cursors, block chains and distance tables kept between frames.
#[derive(Debug, Default)]
pub(crate) struct Scratch {
    cursors: Vec<u32>,
    chains: Chains,
    terms: [Vec<f32>; 3],
    /// `edges[b]` is the smallest squared distance of bucket `b` (`edges[0]` is minus
    /// infinity and a last entry of plus infinity closes the last bucket), so a voxel's bucket
    /// is the `b` with `edges[b] <= q < edges[b + 1]`: one definition, whichever way it is
    /// found.
    edges: Vec<f32>,
    orthogonal: bool,
    view: Option<ViewCase>,
    nearest: f32,
    inverse_width: f32,
}

impl Scratch {
    fn prepare(&mut self, view: &ViewCase, width: f64) {
        // Distances are bucketed in f32. Measured in a power-of-two unit near the farthest
        // distance they stay in f32's range for any spacing (1e-20 or 1e30 mm), and since the
        // scaling is exact, every voxel lands in the same bucket as in the view's own unit.
        let (nearest, farthest) = distance_bounds(view);
        let unit = if farthest.is_finite() && farthest > 0.0 {
            2f64.powi(farthest.log2().round().clamp(-1000.0, 1000.0) as i32)
        } else {
            1.0
        };
        let view = &ViewCase {
            gram: view.gram * (1.0 / (unit * unit)),
            ..*view
        };
        let (nearest, farthest, width) = (nearest / unit, farthest / unit, width / unit);
        self.orthogonal = is_orthogonal(&view.gram);
        self.view = Some(*view);
        for (a, terms) in self.terms.iter_mut().enumerate() {
            terms.clear();
            if self.orthogonal {
                terms.extend(axis_terms(view, a).map(|t| t as f32));
            }
        }
        let span = farthest - nearest;
        // In f64 before any cast: a width far below the span asks for more buckets than a
        // usize holds.
        let count = (span / width).floor();
        let (buckets, width) = if count < (MAX_BUCKETS - 1) as f64 {
            (count as usize + 1, width)
        } else {
            (MAX_BUCKETS, span / (MAX_BUCKETS - 1) as f64)
        };
        self.nearest = nearest as f32;
        self.inverse_width = (1.0 / width) as f32;
        self.edges.clear();
        self.edges.push(f32::NEG_INFINITY);
        self.edges.extend((1..buckets).map(|b| {
            let r = nearest + b as f64 * width;
            (r * r) as f32
        }));
        self.edges.push(f32::INFINITY);
        self.cursors.clear();
        self.cursors.resize(buckets, 0);
    }

    /// Orders the voxels along `plan` (IP-PBTF) into `out`: in one walk into block chains
    /// where the buckets are few enough, otherwise by counting.
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
        if chains_fit(self.cursors.len(), grid.len()) {
            self.order_chained(grid, plan, cull, out);
        } else {
            self.order_counted(grid, plan, cull, out);
        }
    }

    /// One walk: each voxel appended to its bucket's chain of blocks; the chains then copied
    /// to `out`, farthest bucket first.
    fn order_chained(
        &mut self,
        grid: &SparseGrid,
        plan: &Plan<'_>,
        cull: Option<&ViewCase>,
        out: &mut Vec<u32>,
    ) {
        let mut chains = std::mem::take(&mut self.chains);
        let buckets = self.cursors.len();
        // Every bucket's last block may be partly empty: at most one block per bucket beyond
        // the full ones.
        let blocks = pool_blocks(buckets, grid.len());
        chains.reset(buckets, blocks);
        let mut append = Append {
            row: self.row(),
            chains: &mut chains,
            slot: 0,
            end: 0,
        };
        walk(grid, plan, cull, &mut append);
        append.flush();
        chains.copy_out(out);
        self.chains = chains;
    }

    /// Two walks: count the voxels of each bucket, then place each after all farther
    /// buckets.
    fn order_counted(
        &mut self,
        grid: &SparseGrid,
        plan: &Plan<'_>,
        cull: Option<&ViewCase>,
        out: &mut Vec<u32>,
    ) {
        let mut counts = std::mem::take(&mut self.cursors);
        let mut count = Count {
            row: self.row(),
            counts: &mut counts,
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
            slot: 0,
        };
        walk(grid, plan, cull, &mut scatter);
        scatter.flush();
        self.cursors = counts;
    }

    fn row(&self) -> RowBuckets<'_> {
        RowBuckets {
            scratch: self,
            k: [0; 3],
            axis: 0,
            partial: 0.0,
            terms: &self.terms[0],
            current: Current {
                bucket: 0,
                lo: f32::NEG_INFINITY,
                hi: f32::NEG_INFINITY,
            },
        }
    }
}

/// The bucket of the last voxel and its bounds in squared distance.
#[derive(Debug, Clone, Copy)]
struct Current {
    bucket: usize,
    lo: f32,
    hi: f32,
}

impl Current {
    /// Whether the bucket changes for a voxel at squared distance `q`.
    #[inline(always)]
    fn leaves(&self, q: f32) -> bool {
        !(q >= self.lo && q < self.hi)
    }

    /// Moves to the bucket of `q`. Along a run toward the eye that is mostly one of the next
    /// few nearer buckets (a step along a thick axis crosses several), tried first.
    #[inline(always)]
    fn locate(&mut self, q: f32, scratch: &Scratch) {
        let b = self.bucket;
        if q < self.lo {
            let mut hi = self.lo;
            for nearer in (b.saturating_sub(NEARER_TRIED)..b).rev() {
                let lo = scratch.edges[nearer];
                if q >= lo {
                    *self = Self {
                        bucket: nearer,
                        lo,
                        hi,
                    };
                    return;
                }
                hi = lo;
            }
        }
        self.search(q, scratch);
    }

    /// Moves to the bucket of `q` from a square-root estimate, corrected against the edges.
    #[inline(never)]
    fn search(&mut self, q: f32, scratch: &Scratch) {
        let edges = &scratch.edges;
        let last = edges.len() - 2;
        // Saturating float-to-int cast: anything below the nearest bound is bucket 0.
        let mut b =
            (((q.max(0.0).sqrt() - scratch.nearest) * scratch.inverse_width) as usize).min(last);
        while b > 0 && q < edges[b] {
            b -= 1;
        }
        while b < last && q >= edges[b + 1] {
            b += 1;
        }
        *self = Self {
            bucket: b,
            lo: edges[b],
            hi: edges[b + 1],
        };
    }
}

/// Per-row state shared by both walks: the row's fixed squared-distance part and the bucket of
/// the last voxel. Neighbouring voxels of a row mostly share a bucket or sit in the next one,
/// so most voxels cost two comparisons and no square root.
struct RowBuckets<'a> {
    scratch: &'a Scratch,
    k: [u32; 3],
    axis: usize,
    partial: f32,
    terms: &'a [f32],
    current: Current,
}

impl RowBuckets<'_> {
    #[inline]
    fn start_row(&mut self, k: [u32; 3], axis: usize) {
        self.k = k;
        self.axis = axis;
        if self.scratch.orthogonal {
            let t = &self.scratch.terms;
            let (b, c) = crate::grid::other_axes(axis);
            self.partial = t[b][k[b] as usize] + t[c][k[c] as usize];
            self.terms = &t[axis];
        }
    }
}

/// Runs `$body` for each `(id, k)` of `$voxels` with `$q` bound to its squared distance, summed
/// the same way in both walks (per-axis table terms for orthogonal axes, the quadratic form
/// otherwise). A macro, so that the loop body is inlined in both branches.
macro_rules! each_voxel {
    ($row:expr, $voxels:expr, |$id:pat_param, $q:ident| $body:block) => {{
        let row = &$row;
        if row.scratch.orthogonal {
            let (partial, terms) = (row.partial, row.terms);
            for ($id, k) in $voxels {
                let $q = partial + terms[k as usize];
                $body
            }
        } else if let Some(view) = &row.scratch.view {
            let (mut at, axis) = (row.k, row.axis);
            for ($id, k) in $voxels {
                at[axis] = k;
                let $q = view.distance_squared(at) as f32;
                $body
            }
        }
    }};
}

/// Counts voxels per bucket, the current bucket's count held in a register.
struct Count<'a> {
    row: RowBuckets<'a>,
    counts: &'a mut [u32],
    pending: u32,
}

impl Count<'_> {
    fn flush(&mut self) {
        if self.pending > 0 {
            self.counts[self.row.current.bucket] += self.pending;
            self.pending = 0;
        }
    }

    #[inline(always)]
    fn add(&mut self, voxels: impl Iterator<Item = (u32, u32)>) {
        let scratch = self.row.scratch;
        let counts = &mut *self.counts;
        let mut current = self.row.current;
        let mut pending = self.pending;
        each_voxel!(self.row, voxels, |_, q| {
            if current.leaves(q) {
                if pending > 0 {
                    counts[current.bucket] += pending;
                    pending = 0;
                }
                current.locate(q, scratch);
            }
            pending += 1;
        });
        self.row.current = current;
        self.pending = pending;
    }
}

impl Pass for Count<'_> {
    #[inline]
    fn start_row(&mut self, k: [u32; 3], axis: usize) {
        self.row.start_row(k, axis);
    }

    #[inline(always)]
    fn feed(&mut self, voxels: impl Iterator<Item = (u32, u32)>) {
        self.add(voxels);
    }
}

/// Writes each voxel after the farther buckets, keeping the current bucket's write position
/// in a register while the bucket stays the same.
struct Scatter<'a> {
    row: RowBuckets<'a>,
    cursors: &'a mut [u32],
    out: &'a mut [u32],
    slot: u32,
}

impl Scatter<'_> {
    fn flush(&mut self) {
        if self.row.current.lo < self.row.current.hi {
            self.cursors[self.row.current.bucket] = self.slot;
        }
    }

    #[inline(always)]
    fn put(&mut self, voxels: impl Iterator<Item = (u32, u32)>) {
        let scratch = self.row.scratch;
        let (cursors, out) = (&mut *self.cursors, &mut *self.out);
        let mut current = self.row.current;
        let mut slot = self.slot;
        each_voxel!(self.row, voxels, |id, q| {
            if current.leaves(q) {
                if current.lo < current.hi {
                    cursors[current.bucket] = slot;
                }
                current.locate(q, scratch);
                slot = cursors[current.bucket];
            }
            out[slot as usize] = id;
            slot += 1;
        });
        self.row.current = current;
        self.slot = slot;
    }
}

impl Pass for Scatter<'_> {
    #[inline]
    fn start_row(&mut self, k: [u32; 3], axis: usize) {
        self.row.start_row(k, axis);
    }

    #[inline(always)]
    fn feed(&mut self, voxels: impl Iterator<Item = (u32, u32)>) {
        self.put(voxels);
    }
}

/// Blocks enough for `voxels` ids in `buckets` chains: the full ones and at most one partly
/// empty block per bucket.
fn pool_blocks(buckets: usize, voxels: usize) -> usize {
    voxels / BLOCK as usize + buckets + 1
}

/// Whether the one-walk path is taken: the blocks hold at most twice the list, and every
/// position in the pool is a u32.
fn chains_fit(buckets: usize, voxels: usize) -> bool {
    buckets.saturating_mul(BLOCK as usize) <= voxels
        && pool_blocks(buckets, voxels).saturating_mul(BLOCK as usize) <= u32::MAX as usize
}

/// Per bucket, a chain of blocks in one pool: the write position in its last block and that
/// block's end (both 0 before the bucket's first voxel) and its first block; per block, the
/// next block of the same bucket.
#[derive(Debug, Default)]
struct Chains {
    pool: Vec<u32>,
    next: Vec<u32>,
    used: u32,
    first: Vec<u32>,
    cursor: Vec<(u32, u32)>,
}

impl Chains {
    fn reset(&mut self, buckets: usize, blocks: usize) {
        self.pool.resize(blocks * BLOCK as usize, 0);
        self.next.clear();
        self.next.resize(blocks, NONE);
        self.used = 0;
        self.first.clear();
        self.first.resize(buckets, NONE);
        self.cursor.clear();
        self.cursor.resize(buckets, (0, 0));
    }

    /// A new block at the end of `bucket`'s chain, whose last block ended at `end`; returns
    /// the new block's start and end.
    #[inline(never)]
    fn grow(&mut self, bucket: usize, end: u32) -> (u32, u32) {
        let block = self.used;
        self.used += 1;
        if end == 0 {
            self.first[bucket] = block;
        } else {
            self.next[(end / BLOCK - 1) as usize] = block;
        }
        (block * BLOCK, (block + 1) * BLOCK)
    }

    /// Appends every chain to `out`, farthest bucket first.
    fn copy_out(&self, out: &mut Vec<u32>) {
        out.clear();
        for (bucket, &(slot, end)) in self.cursor.iter().enumerate().rev() {
            let mut block = self.first[bucket];
            while block != NONE {
                let start = block * BLOCK;
                let stop = if start + BLOCK == end {
                    slot
                } else {
                    start + BLOCK
                };
                out.extend_from_slice(&self.pool[start as usize..stop as usize]);
                block = self.next[block as usize];
            }
        }
    }
}

/// Appends each voxel to its bucket's chain, the current bucket's write position and block
/// end held in registers.
struct Append<'a> {
    row: RowBuckets<'a>,
    chains: &'a mut Chains,
    slot: u32,
    end: u32,
}

impl Append<'_> {
    fn flush(&mut self) {
        if self.row.current.lo < self.row.current.hi {
            self.chains.cursor[self.row.current.bucket] = (self.slot, self.end);
        }
    }
}

impl Pass for Append<'_> {
    #[inline]
    fn start_row(&mut self, k: [u32; 3], axis: usize) {
        self.row.start_row(k, axis);
    }

    #[inline(always)]
    fn feed(&mut self, voxels: impl Iterator<Item = (u32, u32)>) {
        let scratch = self.row.scratch;
        let chains = &mut *self.chains;
        let mut current = self.row.current;
        let (mut slot, mut end) = (self.slot, self.end);
        each_voxel!(self.row, voxels, |id, q| {
            if current.leaves(q) {
                if current.lo < current.hi {
                    chains.cursor[current.bucket] = (slot, end);
                }
                current.locate(q, scratch);
                (slot, end) = chains.cursor[current.bucket];
            }
            if slot == end {
                (slot, end) = chains.grow(current.bucket, end);
            }
            chains.pool[slot as usize] = id;
            slot += 1;
        });
        self.row.current = current;
        (self.slot, self.end) = (slot, end);
    }
}

/// One of the walks: it takes the voxels of a row as `(id, inner coordinate)` pairs, in
/// walk order, whichever way the traversal hands them over.
trait Pass {
    fn start_row(&mut self, k: [u32; 3], axis: usize);
    fn feed(&mut self, voxels: impl Iterator<Item = (u32, u32)>);
}

impl<P: Pass> Sink for P {
    #[inline]
    fn row(&mut self, k: [u32; 3], axis: usize) {
        self.start_row(k, axis);
    }

    #[inline(always)]
    fn voxel(&mut self, id: u32, k: u32) {
        self.feed(std::iter::once((id, k)));
    }

    #[inline]
    fn run_up(&mut self, base: u32, stride: u32, from: u32, to: u32) {
        self.feed((from..to).map(|k| (base + k * stride, k)));
    }

    #[inline]
    fn run_down(&mut self, base: u32, stride: u32, from: u32, to: u32) {
        self.feed((from..to).rev().map(|k| (base + k * stride, k)));
    }

    #[inline]
    fn slice(&mut self, base: u32, coords: &[u32], offsets: &[u32]) {
        self.feed(coords.iter().zip(offsets).map(|(&k, &o)| (base + o, k)));
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

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;
    use crate::order::fixtures::{anisotropic_and_sheared, eye_at, sparse};
    use crate::order::{OrderOptions, Ordering, VolumeGeometry, order};

    /// The bucketed order is, by definition, the IP-PBTF list stably sorted by bucket, farthest
    /// first. Checked with the bucket of each voxel found by searching the edges, the squared
    /// distance summed as the walks sum it.
    /// Returns whether a bucket took more than one block.
    fn check(
        geometry: &VolumeGeometry,
        eye: DVec3,
        keep: impl Fn(u32) -> bool,
        cull: bool,
    ) -> bool {
        let dims = geometry.dims();
        let grid = SparseGrid::from_mask(dims, keep).unwrap();
        let view = ViewCase::new(geometry, eye, geometry.centre_world()).unwrap();
        let options = OrderOptions {
            cull_behind_eye: cull,
            ..OrderOptions::default()
        };
        let mut scratch = Scratch::default();
        scratch.prepare(&view, width(&view, None).unwrap());
        let inner = view.permutation[2];
        let (b, c) = crate::grid::other_axes(inner);
        let bucket = |id: u32| {
            let k = grid.coords(id);
            let q = if scratch.orthogonal {
                let t = &scratch.terms;
                (t[b][k[b] as usize] + t[c][k[c] as usize]) + t[inner][k[inner] as usize]
            } else {
                scratch.view.unwrap().distance_squared(k) as f32
            };
            // The last edge at or below `q` (the edges never decrease): the bucket with
            // `edges[b] <= q < edges[b + 1]`.
            let b = scratch.edges.partition_point(|&e| e <= q) - 1;
            assert!(scratch.edges[b] <= q && q < scratch.edges[b + 1]);
            b
        };
        let mut expected = order(&grid, &view, Ordering::IpPbtfImplicit, &options).unwrap();
        expected.sort_by_key(|&id| std::cmp::Reverse(bucket(id)));
        let got = order(&grid, &view, Ordering::Bucketed, &options).unwrap();
        assert_eq!(got, expected, "eye {eye} on {:?}", view.kind);
        let mut sizes = vec![0u32; scratch.edges.len() - 1];
        for &id in &expected {
            sizes[bucket(id)] += 1;
        }
        let blocks: u32 = sizes.iter().map(|n| n.div_ceil(BLOCK)).sum();
        // Both paths, whichever the grid's size picks, and the block chains with more than
        // one block in a chain wherever a bucket holds more than a block.
        let (mut seqs, mut offsets) = (<[Vec<u32>; 3]>::default(), Vec::new());
        let [s0, s1, s2] = &mut seqs;
        let plan = crate::order::ip_pbtf_plan(&grid, &view, false, [s0, s1, s2], &mut offsets);
        let cull = cull.then_some(&view);
        let mut out = Vec::new();
        scratch.order_counted(&grid, &plan, cull, &mut out);
        assert_eq!(out, expected, "counted, eye {eye} on {:?}", view.kind);
        scratch.order_chained(&grid, &plan, cull, &mut out);
        assert_eq!(out, expected, "chained, eye {eye} on {:?}", view.kind);
        assert_eq!(
            scratch.chains.used, blocks,
            "one block per {BLOCK} ids of a bucket"
        );
        sizes.iter().any(|&n| n > BLOCK)
    }

    #[test]
    fn bucketed_is_ip_pbtf_stably_sorted_by_bucket() {
        let mut long_chains = false;
        for geometry in &anisotropic_and_sheared() {
            for f in [
                [0.43, 0.56, -0.35],
                [0.41, 0.37, 0.45],
                [0.47, -0.45, -0.4],
                [-0.6, -0.5, 1.45],
                [0.5, 0.5, 0.5],
            ] {
                let eye = eye_at(geometry, f);
                for cull in [false, true] {
                    long_chains |= check(geometry, eye, sparse, cull);
                    long_chains |= check(geometry, eye, |_| true, cull);
                }
            }
        }
        assert!(long_chains, "some bucket fills more than one block");
    }

    /// Spacings from 1e-20 to 1e30 mm and eyes 1e15 mm away keep every squared distance
    /// within f32 and every voxel in its bucket; a width far below the span asks for more
    /// buckets than exist and gets the most there are.
    #[test]
    fn extreme_spacings_and_widths_stay_in_range() {
        let cases = [
            ([4, 4, 4], [1.0, 1.0, 1e-20], [-0.75, -0.75, -0.75]),
            ([4, 3, 5], [1e15, 1.0, 1.0], [2.5e14, 1e15, 1e15]),
            ([4, 4, 4], [1e30, 1.0, 1e-30], [-0.75, -0.75, -0.75]),
            ([5, 4, 3], [1e-20, 1e-20, 1e-20], [0.4, 0.6, 1.5]),
        ];
        for (dims, spacing, f) in cases {
            let geometry = VolumeGeometry::axis_aligned(dims, spacing, [0.0; 3]).unwrap();
            let eye = eye_at(&geometry, f);
            for cull in [false, true] {
                check(&geometry, eye, sparse, cull);
                check(&geometry, eye, |_| true, cull);
            }
        }
        let geometry = VolumeGeometry::axis_aligned([4, 4, 4], [1.0; 3], [0.0; 3]).unwrap();
        let view = ViewCase::new(&geometry, DVec3::ZERO, geometry.centre_world()).unwrap();
        let grid = SparseGrid::dense([4, 4, 4]).unwrap();
        for w in [1e-20, 1e-300, f64::MIN_POSITIVE] {
            let options = OrderOptions {
                bucket_width: Some(w),
                ..OrderOptions::default()
            };
            let mut got = order(&grid, &view, Ordering::Bucketed, &options).unwrap();
            got.sort_unstable();
            assert_eq!(got, (0..64).collect::<Vec<u32>>(), "width {w}");
        }
    }
}
