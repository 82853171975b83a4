//! Visibility orderings of voxel splats, computed on the CPU without any GPU.
//!
//! Every ordering is a permutation of the significant voxels of a [`SparseGrid`], first drawn
//! first (back to front). The grid orderings (BTF, WBTF, PBTF, IP-PBTF) share one traversal
//! engine whose inner loop walks run-length rows, so empty space costs nothing there; the exact
//! order is a parallel radix sort by world distance; three orderings are ours, all O(N) in the
//! voxels: the bucketed order, a bucket sort on quantised distance with IP-PBTF order inside
//! each bucket; the pyramid order, which gives every voxel the slab axis its own ray runs
//! along; and the rows order, which sorts the rows of the grid rather than its voxels.
//!
//! # Definitions
//! Voxel centres sit at integer index coordinates; the eye `e` is taken into index space in f64
//! ([`ViewCase`]). Along one axis a voxel is farther the larger `|k - e_a|` is; equal distances
//! put the lower coordinate first (this only happens when the eye lies on a voxel plane or
//! exactly half-way between two).
//!
//! - **BTF**: each axis walked from the far end given by the sign of the view direction, z
//!   slowest, x fastest.
//! - **WBTF**: BTF with the axis most nearly along the view direction slowest.
//! - **PBTF**: the planes through the eye cut the grid into up to eight subvolumes; each is
//!   drawn whole, in BTF nesting, every axis walked toward the eye. Subvolumes go farthest first
//!   (by the distance of their farthest voxel centre), ties by lower subvolume index.
//! - **IP-PBTF**: lexicographic by `(|k_p0 - e_p0|, |k_p1 - e_p1|, |k_p2 - e_p2|)` descending,
//!   ties lower coordinate first, with the permutation `p` of [`ViewCase::permutation`]. The
//!   explicit variant walks the inner axis through every position and tests each (paper
//!   Algorithms 2 and 3); the implicit variant merges the two sides of each run-length row
//!   (paper Algorithm 4). Both follow this one definition and so produce the same list on every
//!   input. The paper's printed Algorithm 3 differs in one detail: at equal step count from the
//!   split voxel it always draws the larger section first, which is the farther voxel only when
//!   the eye lies on the larger section's side of that voxel; here the farther voxel always goes
//!   first, which is what the distance test of Algorithm 4 does.
//! - **Exact**: world distance from the eye, descending; equal distances by increasing id.
//! - **Bucketed**: world distance quantised into buckets (half the smallest spacing wide by
//!   default), farthest bucket first, IP-PBTF order inside each bucket.
//! - **Pyramid**: the planes through the eye where two axes' weighted distances
//!   `|k_a - e_a| * g_aa` are equal cut the grid into six pyramids; each is drawn slab by slab
//!   along its own axis, all slabs interleaved far to near (see the `pyramid` module for the
//!   exact rule and the tie order).
//! - **Rows**: the grid cut into rows along the row axis (the axis `a` with the smallest
//!   `g_aa * mean |k_a - e_a|` over the grid's coordinates, ties to the lower axis); rows
//!   drawn by the world squared distance from the eye to the row's line, farthest first, ties
//!   by lower row index `k_b + n_b * k_c` (`b < c` the other two axes); each row far to near
//!   along its axis as IP-PBTF's inner axis (`|k_a - e_a|` descending, ties lower first). On
//!   sheared grids the row's nearest point to the eye need not be at `e_a`; the walk along the
//!   row stays IP-PBTF's.

mod bucketed;
mod distance;
mod exact;
#[cfg(test)]
mod fixtures;
mod pyramid;
pub mod reference;
mod rows;
mod traverse;
mod view;

use std::fmt;
use std::str::FromStr;

use thiserror::Error;

pub use crate::geometry::{GeometryError, VolumeGeometry};
use crate::grid::{GridError, SparseGrid};
use traverse::{Collect, CollectKept, Inner, Plan, walk};
pub use view::{AxisCase, AxisView, CaseKind, ViewCase};

/// Why an ordering could not be computed.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum OrderError {
    /// The eye has a NaN or infinite coordinate.
    #[error("the eye position {0:?} is not finite")]
    NonFiniteEye([f64; 3]),
    /// The target has a NaN or infinite coordinate.
    #[error("the target position {0:?} is not finite")]
    NonFiniteTarget([f64; 3]),
    /// Eye and target coincide, so there is no view direction.
    #[error("the eye and the target coincide: no view direction")]
    DegenerateView,
    /// The grid cannot be placed in the world.
    #[error(transparent)]
    Geometry(#[from] GeometryError),
    /// The grid and the view were made for different grid sizes.
    #[error("the view was computed for a {view:?} grid but the voxels are on a {grid:?} grid")]
    DimsMismatch {
        /// Size the view case was computed for.
        view: [u32; 3],
        /// Size of the voxel set.
        grid: [u32; 3],
    },
    /// A bucket width must be finite and positive.
    #[error("bucket width {0} must be finite and positive")]
    BadBucketWidth(f64),
    /// Grid size problems.
    #[error(transparent)]
    Grid(#[from] GridError),
}

/// A visibility ordering.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Ordering {
    /// Frieder et al. 1985.
    Btf,
    /// Westover 1990.
    Wbtf,
    /// Anderson, Max, Swan.
    Pbtf,
    /// Botha & Post 2005 with explicit interleaving of every axis.
    IpPbtfExplicit,
    /// Botha & Post 2005 with implicit interleaving of the inner axis over run-length rows.
    IpPbtfImplicit,
    /// Sorted by world distance from the eye.
    Exact,
    /// Counting sort on quantised distance, IP-PBTF inside a bucket.
    Bucketed,
    /// Six pyramids with their apex at the eye, each walked slab by slab along its own axis,
    /// the slabs of all six interleaved far to near.
    Pyramid,
    /// Rows along one axis sorted by the distance from the eye to each row's line, each row
    /// far to near.
    Rows,
}

impl Ordering {
    /// Every ordering, in report order.
    pub const ALL: [Ordering; 9] = [
        Self::Btf,
        Self::Wbtf,
        Self::Pbtf,
        Self::IpPbtfExplicit,
        Self::IpPbtfImplicit,
        Self::Pyramid,
        Self::Rows,
        Self::Bucketed,
        Self::Exact,
    ];

    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Self::Btf => "btf",
            Self::Wbtf => "wbtf",
            Self::Pbtf => "pbtf",
            Self::IpPbtfExplicit => "ip-pbtf-explicit",
            Self::IpPbtfImplicit => "ip-pbtf-implicit",
            Self::Exact => "exact",
            Self::Bucketed => "bucketed",
            Self::Pyramid => "pyramid",
            Self::Rows => "rows",
        }
    }
}

impl fmt::Display for Ordering {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// An ordering name that is not known.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
#[error(
    "unknown ordering {0:?}; expected one of btf, wbtf, pbtf, ip-pbtf, ip-pbtf-explicit, ip-pbtf-implicit, exact, bucketed, pyramid, rows"
)]
pub struct UnknownOrdering(pub String);

impl FromStr for Ordering {
    type Err = UnknownOrdering;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "btf" => Ok(Self::Btf),
            "wbtf" => Ok(Self::Wbtf),
            "pbtf" => Ok(Self::Pbtf),
            "ip-pbtf" | "ip-pbtf-implicit" | "ippbtf" => Ok(Self::IpPbtfImplicit),
            "ip-pbtf-explicit" => Ok(Self::IpPbtfExplicit),
            "exact" | "sort" => Ok(Self::Exact),
            "bucketed" | "bucket" => Ok(Self::Bucketed),
            "pyramid" => Ok(Self::Pyramid),
            "rows" => Ok(Self::Rows),
            _ => Err(UnknownOrdering(s.to_owned())),
        }
    }
}

/// Options shared by every ordering.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct OrderOptions {
    /// Leave out voxels whose centre lies on or behind the plane through the eye orthogonal to
    /// the view direction.
    pub cull_behind_eye: bool,
    /// Bucket width in world units for [`Ordering::Bucketed`]; `None` is half the smallest
    /// voxel spacing.
    pub bucket_width: Option<f64>,
}

/// Computes orderings, keeping its scratch buffers between frames so that a steady camera path
/// allocates nothing beyond the first frame.
#[derive(Debug, Default)]
pub struct Orderer {
    sequences: [Vec<u32>; 3],
    offsets: Vec<u32>,
    exact: exact::Scratch,
    buckets: bucketed::Scratch,
    pyramid: pyramid::Scratch,
    rows: rows::Scratch,
}

impl Orderer {
    /// A new orderer with empty scratch buffers.
    pub fn new() -> Self {
        Self::default()
    }

    /// Writes the draw order of the significant voxels of `grid` into `out` (replacing its
    /// contents), first drawn first.
    pub fn order(
        &mut self,
        grid: &SparseGrid,
        view: &ViewCase,
        ordering: Ordering,
        options: &OrderOptions,
        out: &mut Vec<u32>,
    ) -> Result<(), OrderError> {
        let view_dims = view.axes.map(|a| a.n);
        if view_dims != grid.dims() {
            return Err(OrderError::DimsMismatch {
                view: view_dims,
                grid: grid.dims(),
            });
        }
        out.clear();
        out.reserve(grid.len());
        let cull = options.cull_behind_eye.then_some(view);
        match ordering {
            Ordering::Btf => self.btf(grid, view, [2, 1, 0], cull, out),
            Ordering::Wbtf => self.btf(grid, view, view.wbtf_permutation, cull, out),
            Ordering::Pbtf => self.pbtf(grid, view, cull, out),
            Ordering::IpPbtfImplicit | Ordering::IpPbtfExplicit => {
                let explicit = ordering == Ordering::IpPbtfExplicit;
                let [s0, s1, s2] = &mut self.sequences;
                let plan = ip_pbtf_plan(grid, view, explicit, [s0, s1, s2], &mut self.offsets);
                walk_in_slabs(grid, &plan, cull, out);
            }
            Ordering::Exact => {
                let [s0, s1, _] = &mut self.sequences;
                let plan = id_order_plan(grid.dims(), [s0, s1]);
                self.exact.order(grid, view, &plan, cull, out);
            }
            Ordering::Bucketed => {
                let width = bucketed::width(view, options.bucket_width)?;
                let [s0, s1, s2] = &mut self.sequences;
                let plan = ip_pbtf_plan(grid, view, false, [s0, s1, s2], &mut self.offsets);
                self.buckets.order(grid, view, width, &plan, cull, out);
            }
            Ordering::Pyramid => self.pyramid.order(grid, view, cull, &mut Collect(out)),
            Ordering::Rows => self.rows.order(grid, view, cull, &mut Collect(out)),
        }
        Ok(())
    }

    /// The draw order of `grid`'s significant voxels within each of `boxes` (per axis, the
    /// voxel range `lo..hi`; bricks of a grid drawn brick by brick), box after box into `out`
    /// (replacing its contents), with `ends[i]` one past the last of box `i`'s voxels in
    /// `out`. Each box's voxels come in the order [`Orderer::order`] gives them within the
    /// whole grid: IP-PBTF (either interleaving) is a nesting of per-axis far-to-near walks,
    /// and a walk restricted to a range keeps the whole walk's order (the implicit merge
    /// decides each pair of voxels by their two coordinates alone). The boxes are walked in
    /// parallel, each only over its own rows, so the cost follows the boxes' voxels, not the
    /// grid's. `Ok(false)`, with nothing written, for the other orderings.
    pub fn order_boxes(
        grid: &SparseGrid,
        view: &ViewCase,
        ordering: Ordering,
        options: &OrderOptions,
        boxes: &[[(u32, u32); 3]],
        out: &mut Vec<u32>,
        ends: &mut Vec<usize>,
    ) -> Result<bool, OrderError> {
        type Keep = fn(usize, [u32; 3]) -> bool;
        Self::order_boxes_kept(
            grid,
            view,
            (ordering, options),
            boxes,
            None::<&Keep>,
            out,
            ends,
        )
    }

    /// [`Orderer::order_boxes`] that keeps, of box `i`'s voxels, only those `k` for which
    /// `keep(i, k)` holds (every one where `keep` is `None`), in the same order: the boxes'
    /// walks test each voxel as they write it, so nothing they leave out is written and no
    /// pass over the ids follows. (The bricks of a level drawn as one run are walked over the
    /// least box holding them, and the box's other bricks left out.)
    pub fn order_boxes_kept<F: Fn(usize, [u32; 3]) -> bool + Sync>(
        grid: &SparseGrid,
        view: &ViewCase,
        (ordering, options): (Ordering, &OrderOptions),
        boxes: &[[(u32, u32); 3]],
        keep: Option<&F>,
        out: &mut Vec<u32>,
        ends: &mut Vec<usize>,
    ) -> Result<bool, OrderError> {
        use rayon::prelude::*;
        let explicit = match ordering {
            Ordering::IpPbtfImplicit => false,
            Ordering::IpPbtfExplicit => true,
            _ => return Ok(false),
        };
        let view_dims = view.axes.map(|a| a.n);
        if view_dims != grid.dims() {
            return Err(OrderError::DimsMismatch {
                view: view_dims,
                grid: grid.dims(),
            });
        }
        let cull = options.cull_behind_eye.then_some(view);
        let perm = view.permutation;
        let inner_axis = &view.axes[perm[2]];
        // The inner axis's whole far-to-near order and its offsets, which the implicit merge
        // slices whatever range it walks.
        let mut sequence = Vec::new();
        inner_axis.far_to_near(&mut sequence);
        let stride = grid.strides()[perm[2]];
        let offsets: Vec<u32> = sequence.iter().map(|&k| k * stride).collect();
        let threshold = inner_axis.merge_threshold();
        // The rows along the inner axis are read from every task: made first.
        grid.prepare_rows(perm[2]);
        const BOXES_A_TASK: usize = 64;
        let parts: Vec<(Vec<u32>, Vec<usize>)> = boxes
            .par_chunks(BOXES_A_TASK)
            .enumerate()
            .map(|(task, chunk)| {
                let (mut ids, mut chunk_ends) = (Vec::new(), Vec::with_capacity(chunk.len()));
                let (mut s0, mut s1, mut s2) = (Vec::new(), Vec::new(), Vec::new());
                for (at, range) in (task * BOXES_A_TASK..).zip(chunk) {
                    let within = |a: usize| {
                        let (lo, hi) = range[a];
                        (lo.min(grid.dims()[a]), hi.min(grid.dims()[a]))
                    };
                    for (seq, a) in [(&mut s0, perm[0]), (&mut s1, perm[1])] {
                        seq.clear();
                        let (lo, hi) = within(a);
                        view.axes[a].far_to_near_within(lo, hi, seq);
                    }
                    let inner_range = within(perm[2]);
                    let inner = if explicit {
                        s2.clear();
                        inner_axis.far_to_near_within(inner_range.0, inner_range.1, &mut s2);
                        Inner::Explicit(&s2)
                    } else {
                        Inner::far_to_near(inner_axis, inner_range, threshold, &sequence, &offsets)
                    };
                    let ranges = [0, 1, 2].map(within);
                    if ranges.iter().all(|(lo, hi)| lo < hi) {
                        let plan = Plan {
                            perm,
                            outer: [&s0, &s1],
                            inner,
                        };
                        // A box wholly in front of the eye plane (its corners are: the plane
                        // is linear in the coordinates) needs no row tested against it.
                        let in_front = cull.is_some_and(|view| {
                            (0..8).all(|corner| {
                                let k = std::array::from_fn(|a| {
                                    let (lo, hi) = ranges[a];
                                    if corner >> a & 1 == 0 { lo } else { hi - 1 }
                                });
                                view.eye_plane(k) > 0.0
                            })
                        });
                        let cull = if in_front { None } else { cull };
                        match keep {
                            Some(keep) => {
                                walk(grid, &plan, cull, &mut CollectKept::new(&mut ids, keep, at))
                            }
                            None => walk(grid, &plan, cull, &mut Collect(&mut ids)),
                        }
                    }
                    chunk_ends.push(ids.len());
                }
                (ids, chunk_ends)
            })
            .collect();
        out.clear();
        ends.clear();
        out.reserve(parts.iter().map(|(ids, _)| ids.len()).sum());
        for (ids, chunk_ends) in parts {
            let before = out.len();
            out.extend_from_slice(&ids);
            ends.extend(chunk_ends.into_iter().map(|e| before + e));
        }
        Ok(true)
    }

    fn btf(
        &mut self,
        grid: &SparseGrid,
        view: &ViewCase,
        perm: [usize; 3],
        cull: Option<&ViewCase>,
        out: &mut Vec<u32>,
    ) {
        let [s0, s1, _] = &mut self.sequences;
        for (seq, axis) in [(&mut *s0, perm[0]), (&mut *s1, perm[1])] {
            seq.clear();
            let n = view.axes[axis].n;
            if view.btf_descending(axis) {
                seq.extend((0..n).rev());
            } else {
                seq.extend(0..n);
            }
        }
        let n = view.axes[perm[2]].n;
        let inner = if view.btf_descending(perm[2]) {
            Inner::Down { lo: 0, hi: n }
        } else {
            Inner::Up { lo: 0, hi: n }
        };
        let plan = Plan {
            perm,
            outer: [s0, s1],
            inner,
        };
        walk(grid, &plan, cull, &mut Collect(out));
    }

    fn pbtf(
        &mut self,
        grid: &SparseGrid,
        view: &ViewCase,
        cull: Option<&ViewCase>,
        out: &mut Vec<u32>,
    ) {
        for part in pbtf_subvolumes(view) {
            let [s0, s1, _] = &mut self.sequences;
            // BTF nesting, z slowest: outer axes z and y, inner x.
            for (seq, axis) in [(&mut *s0, 2), (&mut *s1, 1)] {
                seq.clear();
                let (lo, hi, down) = part[axis];
                if down {
                    seq.extend((lo..hi).rev());
                } else {
                    seq.extend(lo..hi);
                }
            }
            let (lo, hi, down) = part[0];
            let inner = if down {
                Inner::Down { lo, hi }
            } else {
                Inner::Up { lo, hi }
            };
            let plan = Plan {
                perm: [2, 1, 0],
                outer: [s0, s1],
                inner,
            };
            walk(grid, &plan, cull, &mut Collect(out));
        }
    }
}

/// The IP-PBTF traversal: interleaved far-to-near sequences for the outer axes, the inner axis
/// merged over runs (implicit) or walked through its whole sequence (explicit).
fn ip_pbtf_plan<'a>(
    grid: &SparseGrid,
    view: &ViewCase,
    explicit: bool,
    seqs: [&'a mut Vec<u32>; 3],
    offsets: &'a mut Vec<u32>,
) -> Plan<'a> {
    let perm = view.permutation;
    let [s0, s1, s2] = seqs;
    for (seq, axis) in [
        (&mut *s0, perm[0]),
        (&mut *s1, perm[1]),
        (&mut *s2, perm[2]),
    ] {
        seq.clear();
        view.axes[axis].far_to_near(seq);
    }
    let inner_axis = &view.axes[perm[2]];
    let inner = if explicit {
        Inner::Explicit(s2)
    } else {
        let stride = grid.strides()[perm[2]];
        offsets.clear();
        offsets.extend(s2.iter().map(|&k| k * stride));
        Inner::far_to_near(
            inner_axis,
            (0, inner_axis.n),
            inner_axis.merge_threshold(),
            s2,
            offsets,
        )
    };
    Plan {
        perm,
        outer: [s0, s1],
        inner,
    }
}

/// [`walk`] into `out`, the outer axis cut into slabs of slices walked in parallel, each into
/// its own list, joined in the outer axis's order: the same list, made on every core. A grid of
/// fewer than [`SLAB_SPLATS`] splats is walked on one.
fn walk_in_slabs(grid: &SparseGrid, plan: &Plan<'_>, cull: Option<&ViewCase>, out: &mut Vec<u32>) {
    use rayon::prelude::*;
    /// Splats under which one thread walks the whole grid.
    const SLAB_SPLATS: usize = 1 << 16;
    let slices = plan.outer[0].len();
    let tasks = (rayon::current_num_threads() * 4).min(grid.len() / SLAB_SPLATS);
    if tasks < 2 || slices < 2 {
        walk(grid, plan, cull, &mut Collect(out));
        return;
    }
    // Every task reads the rows along the inner axis: made before, outside the tasks (the
    // rows are built in parallel themselves, see `SparseGrid::prepare_rows`).
    grid.prepare_rows(plan.perm[2]);
    let per_task = slices.div_ceil(tasks);
    let parts: Vec<Vec<u32>> = plan.outer[0]
        .par_chunks(per_task)
        .map(|slab| {
            let mut ids = Vec::new();
            let part = Plan {
                outer: [slab, plan.outer[1]],
                ..*plan
            };
            walk(grid, &part, cull, &mut Collect(&mut ids));
            ids
        })
        .collect();
    out.reserve(parts.iter().map(Vec::len).sum());
    for part in parts {
        out.extend_from_slice(&part);
    }
}

/// Every significant voxel in id order (z slowest, x fastest, all upwards).
fn id_order_plan<'a>(dims: [u32; 3], seqs: [&'a mut Vec<u32>; 2]) -> Plan<'a> {
    let [s0, s1] = seqs;
    s0.clear();
    s0.extend(0..dims[2]);
    s1.clear();
    s1.extend(0..dims[1]);
    Plan {
        perm: [2, 1, 0],
        outer: [s0, s1],
        inner: Inner::Up { lo: 0, hi: dims[0] },
    }
}

/// PBTF subvolumes in drawing order: per axis `(lo, hi, walk downwards)`.
fn pbtf_subvolumes(view: &ViewCase) -> Vec<[(u32, u32, bool); 3]> {
    let parts: [Vec<(u32, u32, bool)>; 3] = std::array::from_fn(|a| {
        let axis = &view.axes[a];
        let n = axis.n;
        match axis.view {
            AxisView::Below => vec![(0, n, true)],
            AxisView::Above => vec![(0, n, false)],
            AxisView::Split { kv } => [(0, kv, false), (kv, n, true)]
                .into_iter()
                .filter(|(lo, hi, _)| lo < hi)
                .collect(),
        }
    });
    let mut subvolumes = Vec::with_capacity(8);
    for &pz in &parts[2] {
        for &py in &parts[1] {
            for &px in &parts[0] {
                subvolumes.push([px, py, pz]);
            }
        }
    }
    let farthest = |s: &[(u32, u32, bool); 3]| {
        let mut best = 0.0f64;
        for corner in 0..8 {
            let k: [u32; 3] = std::array::from_fn(|a| {
                if corner >> a & 1 == 0 {
                    s[a].0
                } else {
                    s[a].1 - 1
                }
            });
            best = best.max(view.distance_squared(k));
        }
        best
    };
    // Stable sort: equal distances keep subvolume index order.
    subvolumes.sort_by(|a, b| farthest(b).total_cmp(&farthest(a)));
    subvolumes
}

/// Convenience: one ordering into a new list.
pub fn order(
    grid: &SparseGrid,
    view: &ViewCase,
    ordering: Ordering,
    options: &OrderOptions,
) -> Result<Vec<u32>, OrderError> {
    let mut out = Vec::new();
    Orderer::new().order(grid, view, ordering, options, &mut out)?;
    Ok(out)
}

/// About how many bytes ordering a dense grid of `dims` takes: the voxel bits, a run table
/// per axis (a row offset and a run per row), the order and its bytes, and the sort keys of
/// the exact and bucketed orders.
pub fn dense_order_bytes(dims: [u32; 3], ordering: Ordering) -> u64 {
    let n = dims.iter().map(|&d| u64::from(d)).product::<u64>();
    let rows: u64 = dims.iter().map(|&d| n / u64::from(d.max(1))).sum();
    let keys = match ordering {
        Ordering::Exact => 32 * n,
        Ordering::Bucketed => 8 * n,
        _ => 0,
    };
    n / 8 + 12 * rows + 8 * n + keys
}

#[cfg(test)]
mod box_tests {
    use super::*;
    use crate::order::fixtures::{anisotropic_and_sheared, eye_at, sparse};

    /// Each box's voxels come as the comparison-sort definition orders them within the whole
    /// grid, for boxes that cut the grid in irregular pieces (some holding the eye's
    /// coordinate on an axis, some empty, some reaching past the grid), eyes outside and
    /// inside, with and without culling, both interleavings.
    #[test]
    fn boxes_keep_the_order_of_the_whole_grid() {
        for geometry in &anisotropic_and_sheared() {
            let dims = geometry.dims();
            let grid = SparseGrid::from_mask(dims, sparse).unwrap();
            // Cuts along each axis at irregular places, the last past the grid's end.
            let cuts = |n: u32| -> Vec<(u32, u32)> {
                let mut at = vec![0, 3, 4, n / 2 + 1, n - 2, n + 5];
                at.dedup();
                at.windows(2).map(|w| (w[0], w[1])).collect()
            };
            let mut boxes = Vec::new();
            for &z in &cuts(dims[2]) {
                for &y in &cuts(dims[1]) {
                    for &x in &cuts(dims[0]) {
                        boxes.push([x, y, z]);
                    }
                }
            }
            boxes.push([(2, 2), (0, dims[1]), (0, dims[2])]);
            // Reversed so that the boxes do not come in id order.
            boxes.reverse();
            for f in [
                [0.43, 0.56, -0.35],
                [0.41, 0.37, 0.45],
                [-0.6, -0.5, 1.45],
                [1.8, 0.5, 0.52],
            ] {
                let eye = eye_at(geometry, f);
                let view = ViewCase::new(geometry, eye, geometry.centre_world()).unwrap();
                for ordering in [Ordering::IpPbtfImplicit, Ordering::IpPbtfExplicit] {
                    for cull in [false, true] {
                        let options = OrderOptions {
                            cull_behind_eye: cull,
                            ..OrderOptions::default()
                        };
                        let (mut out, mut ends) = (vec![7], vec![9]);
                        let done = Orderer::order_boxes(
                            &grid, &view, ordering, &options, &boxes, &mut out, &mut ends,
                        )
                        .unwrap();
                        assert!(done);
                        let whole = reference::order(&grid, &view, ordering, cull);
                        // Each box's voxels that `keep` holds: the whole order's, in its order.
                        let check = |out: &[u32],
                                     ends: &[usize],
                                     keep: &dyn Fn(usize, [u32; 3]) -> bool,
                                     what: &str| {
                            assert_eq!(ends.len(), boxes.len());
                            let mut start = 0;
                            for (at, (range, &end)) in boxes.iter().zip(ends).enumerate() {
                                let inside = |id: &u32| {
                                    let k = grid.coords(*id);
                                    (0..3).all(|a| k[a] >= range[a].0 && k[a] < range[a].1)
                                        && keep(at, k)
                                };
                                let expected: Vec<u32> =
                                    whole.iter().copied().filter(inside).collect();
                                assert_eq!(
                                    out[start..end],
                                    expected[..],
                                    "{what}{ordering:?} eye {f:?} cull {cull} box {range:?}"
                                );
                                start = end;
                            }
                            assert_eq!(start, out.len());
                        };
                        check(&out, &ends, &|_, _| true, "");
                        // With some of each box's voxels left out as they are walked.
                        let keep = |at: usize, k: [u32; 3]| {
                            !(k[0] + 2 * k[1] + k[2] + at as u32).is_multiple_of(3)
                        };
                        Orderer::order_boxes_kept(
                            &grid,
                            &view,
                            (ordering, &options),
                            &boxes,
                            Some(&keep),
                            &mut out,
                            &mut ends,
                        )
                        .unwrap();
                        check(&out, &ends, &keep, "kept: ");
                    }
                }
            }
            // Other orderings are left to the whole grid's order.
            let view = ViewCase::new(
                geometry,
                eye_at(geometry, [2.0; 3]),
                geometry.centre_world(),
            )
            .unwrap();
            let (mut out, mut ends) = (Vec::new(), Vec::new());
            assert!(
                !Orderer::order_boxes(
                    &grid,
                    &view,
                    Ordering::Btf,
                    &OrderOptions::default(),
                    &boxes,
                    &mut out,
                    &mut ends
                )
                .unwrap()
            );
        }
    }
}
