//! Sparse sets of significant voxels on a regular grid (space skipping).
//!
//! A [`SparseGrid`] records which voxels of an `nx x ny x nz` grid are significant. Voxel ids are
//! `x + nx * (y + ny * z)` as `u32`; a grid with more than 2^32 voxels is refused with
//! [`GridError::TooLarge`] rather than wrapping. Besides a bitmap (with a rank index, so that the
//! attributes of the significant voxels can be stored compactly), the grid keeps run-length rows
//! along each of the three axes: the inner loop of every ordering walks runs, so empty space costs
//! nothing there. An axis's rows are built the first time they are asked for (a view needs one
//! or two of them), slabs of rows in parallel. A dense grid is the case where every voxel is significant.

use std::sync::OnceLock;

use thiserror::Error;

/// Problems with a grid's size or with a list of voxel ids.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
pub enum GridError {
    /// An axis has no voxels.
    #[error("grid {0:?} has an axis without voxels")]
    EmptyAxis([u32; 3]),
    /// The grid has more voxels than `u32` ids address.
    #[error(
        "grid {}x{}x{} has {} voxels; u32 voxel ids address at most 4294967296",
        dims[0], dims[1], dims[2], voxel_words(*count)
    )]
    TooLarge {
        /// The grid size.
        dims: [u32; 3],
        /// Its voxel count.
        count: u64,
    },
    /// An id lies outside the grid.
    #[error("voxel id {id} lies outside the {dims:?} grid")]
    IdOutOfRange {
        /// The offending id.
        id: u32,
        /// The grid size.
        dims: [u32; 3],
    },
    /// Ids given as a list must be strictly increasing.
    #[error("voxel ids must be strictly increasing; position {0} breaks that")]
    Unsorted(usize),
    /// A volume holds fewer values than its grid has voxels.
    #[error("the volume holds {values} values for {voxels} voxels")]
    TooFewValues {
        /// Values held.
        values: usize,
        /// Voxels of the grid.
        voxels: usize,
    },
}

/// A run of consecutive significant voxels along one axis: `start..start + len`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Run {
    /// First coordinate of the run along the row's axis.
    pub start: u32,
    /// Number of voxels in the run (at least one).
    pub len: u32,
}

impl Run {
    /// One past the last coordinate of the run.
    pub fn end(self) -> u32 {
        self.start + self.len
    }
}

/// Run-length rows along one axis. Row `r` holds `runs[offsets[r]..offsets[r + 1]]`, sorted by
/// start. A row is named by the two other coordinates: `k_b + n_b * k_c` with `b < c`.
#[derive(Debug, Clone, Default)]
struct AxisRows {
    offsets: Vec<u32>,
    runs: Vec<Run>,
}

/// The significant voxels of a grid, with run-length rows along each axis.
#[derive(Debug, Clone)]
pub struct SparseGrid {
    dims: [u32; 3],
    count: u64,
    bits: Vec<u64>,
    /// Number of set bits before each word of `bits`.
    word_rank: Vec<u32>,
    /// Per axis, its rows once asked for.
    rows: [OnceLock<AxisRows>; 3],
}

/// The two axes other than `axis`, in increasing order.
pub fn other_axes(axis: usize) -> (usize, usize) {
    match axis {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    }
}

/// A voxel count for a message; [`u64::MAX`] stands for one past what `u64` holds.
fn voxel_words(count: u64) -> String {
    match count {
        u64::MAX => "more than 2^64".into(),
        n => n.to_string(),
    }
}

/// Checks a grid size and returns its voxel count.
pub fn voxel_count(dims: [u32; 3]) -> Result<u64, GridError> {
    if dims.contains(&0) {
        return Err(GridError::EmptyAxis(dims));
    }
    // Checked: three u32 sizes can multiply past u64 (2^31 x 2^31 x 4 wraps to 0).
    let count = dims
        .iter()
        .try_fold(1u64, |acc, &n| acc.checked_mul(u64::from(n)))
        .unwrap_or(u64::MAX);
    if count > 1 << 32 {
        return Err(GridError::TooLarge { dims, count });
    }
    Ok(count)
}

impl SparseGrid {
    /// A grid where every voxel is significant.
    pub fn dense(dims: [u32; 3]) -> Result<Self, GridError> {
        let count = voxel_count(dims)?;
        let words = count.div_ceil(64) as usize;
        let mut bits = vec![u64::MAX; words];
        if count % 64 != 0 {
            bits[words - 1] = (1u64 << (count % 64)) - 1;
        }
        let word_rank = (0..words).map(|w| (w * 64) as u32).collect();
        let rows = std::array::from_fn(|axis| {
            let (b, c) = other_axes(axis);
            let n_rows = dims[b] as usize * dims[c] as usize;
            OnceLock::from(AxisRows {
                offsets: (0..=n_rows as u32).collect(),
                runs: vec![
                    Run {
                        start: 0,
                        len: dims[axis]
                    };
                    n_rows
                ],
            })
        });
        Ok(Self {
            dims,
            count,
            bits,
            word_rank,
            rows,
        })
    }

    /// The voxels for which `significant(id)` holds.
    pub fn from_mask(
        dims: [u32; 3],
        mut significant: impl FnMut(u32) -> bool,
    ) -> Result<Self, GridError> {
        let count = voxel_count(dims)?;
        let mut bits = vec![0u64; count.div_ceil(64) as usize];
        for id in 0..count {
            if significant(id as u32) {
                bits[(id / 64) as usize] |= 1 << (id % 64);
            }
        }
        Ok(Self::from_bits(dims, bits))
    }

    /// The voxels listed in `ids`, which must be strictly increasing and inside the grid.
    pub fn from_sorted_ids(dims: [u32; 3], ids: &[u32]) -> Result<Self, GridError> {
        Self::from_sorted_parts(dims, &[ids])
    }

    /// The voxels listed in `parts` one after the other, which together must be strictly
    /// increasing and inside the grid (the per-slab lists of a classification), with no
    /// copy of them joined: stretches of them are checked and set in parallel, each into the
    /// words its ids span, which are then laid into the bitmap (a word two stretches share
    /// takes both).
    pub fn from_sorted_parts(dims: [u32; 3], parts: &[&[u32]]) -> Result<Self, GridError> {
        use rayon::prelude::*;
        let count = voxel_count(dims)?;
        // Each stretch with the index of its first id in the parts joined.
        let mut stretches: Vec<(usize, &[u32])> = Vec::new();
        let mut at = 0;
        for stretch in parts.iter().flat_map(|p| p.chunks(1 << 20)) {
            stretches.push((at, stretch));
            at += stretch.len();
        }
        // Where two stretches meet, the second must start past the first's end.
        for pair in stretches.windows(2) {
            if let (Some(&last), Some(&first)) = (pair[0].1.last(), pair[1].1.first())
                && first <= last
            {
                return Err(GridError::Unsorted(pair[1].0));
            }
        }
        let words = stretches
            .par_iter()
            .map(|&(at, ids)| {
                let (Some(&first), Some(&last)) = (ids.first(), ids.last()) else {
                    return Ok((0, Vec::new()));
                };
                if u64::from(last) >= count {
                    let id = ids.iter().copied().find(|&id| u64::from(id) >= count);
                    return Err(GridError::IdOutOfRange {
                        id: id.unwrap_or(last),
                        dims,
                    });
                }
                let base = (first / 64) as usize;
                let mut words = vec![0u64; (last / 64) as usize + 1 - base];
                for (i, &id) in ids.iter().enumerate() {
                    if i > 0 && ids[i - 1] >= id {
                        return Err(GridError::Unsorted(at + i));
                    }
                    words[(id / 64) as usize - base] |= 1 << (id % 64);
                }
                Ok((base, words))
            })
            .collect::<Result<Vec<_>, GridError>>()?;
        let mut bits = vec![0u64; count.div_ceil(64) as usize];
        for (base, words) in words {
            for (b, w) in bits[base..].iter_mut().zip(words) {
                *b |= w;
            }
        }
        Ok(Self::from_bits(dims, bits))
    }

    fn from_bits(dims: [u32; 3], bits: Vec<u64>) -> Self {
        let mut word_rank = Vec::with_capacity(bits.len());
        let mut total = 0u64;
        for w in &bits {
            word_rank.push(total as u32);
            total += u64::from(w.count_ones());
        }
        Self {
            dims,
            count: total,
            bits,
            word_rank,
            rows: Default::default(),
        }
    }

    /// Builds the run-length rows along `axis` in two passes over the bitmap: count the runs that
    /// start in each row, then fill them in.
    fn build_rows(&self, axis: usize) -> AxisRows {
        use rayon::prelude::*;
        let (b, c) = other_axes(axis);
        let (nb, nc) = (self.dims[b] as usize, self.dims[c] as usize);
        let n_rows = nb * nc;
        let stride = self.strides()[axis];
        let n = self.dims[axis];
        let is_start = |id: u32, k: [u32; 3]| k[axis] == 0 || !self.contains(id - stride);
        // Slabs of the rows' slowest coordinate `c`, a task each: a slab's rows are a stretch
        // of the table, and its voxels a few stretches of ids (one, or one a z-slice).
        let per = nc.div_ceil(4 * rayon::current_num_threads()).max(1);
        let slabs: Vec<(usize, usize)> = (0..nc)
            .step_by(per)
            .map(|c0| (c0, (c0 + per).min(nc)))
            .collect();
        let row_of = |k: [u32; 3]| k[b] as usize + nb * k[c] as usize;
        let mut offsets = vec![0u32; n_rows + 1];
        offsets[1..]
            .par_chunks_mut(per * nb)
            .zip(&slabs)
            .for_each(|(counts, &(c0, c1))| {
                self.for_each_in_slab(c, c0..c1, |id, k| {
                    if is_start(id, k) {
                        counts[row_of(k) - c0 * nb] += 1;
                    }
                });
            });
        for r in 0..n_rows {
            offsets[r + 1] += offsets[r];
        }
        let mut runs = vec![Run { start: 0, len: 0 }; offsets[n_rows] as usize];
        let mut parts = Vec::with_capacity(slabs.len());
        let mut rest = runs.as_mut_slice();
        for &(c0, c1) in &slabs {
            let (part, tail) = rest.split_at_mut((offsets[c1 * nb] - offsets[c0 * nb]) as usize);
            parts.push(part);
            rest = tail;
        }
        parts
            .into_par_iter()
            .zip(&slabs)
            .for_each(|(part, &(c0, c1))| {
                let first = offsets[c0 * nb];
                let mut fill: Vec<u32> = offsets[c0 * nb..c1 * nb]
                    .iter()
                    .map(|o| o - first)
                    .collect();
                self.for_each_in_slab(c, c0..c1, |id, k| {
                    if is_start(id, k) {
                        let mut len = 1;
                        while k[axis] + len < n && self.contains(id + len * stride) {
                            len += 1;
                        }
                        let slot = &mut fill[row_of(k) - c0 * nb];
                        part[*slot as usize] = Run {
                            start: k[axis],
                            len,
                        };
                        *slot += 1;
                    }
                });
            });
        AxisRows { offsets, runs }
    }

    /// [`SparseGrid::for_each_significant_in`] for the voxels whose coordinate along axis `c`
    /// (1 or 2) lies in `range`, in id order.
    fn for_each_in_slab(
        &self,
        c: usize,
        range: std::ops::Range<usize>,
        mut f: impl FnMut(u32, [u32; 3]),
    ) {
        let [nx, ny, nz] = self.dims.map(u64::from);
        let (row, plane) = (nx, nx * ny);
        let (c0, c1) = (range.start as u64, range.end as u64);
        if c == 2 {
            self.for_each_significant_in(c0 * plane..c1 * plane, f);
        } else {
            for z in 0..nz {
                self.for_each_significant_in(z * plane + c0 * row..z * plane + c1 * row, &mut f);
            }
        }
    }

    /// Calls `f` with the id and coordinates of every significant voxel whose id lies in
    /// `ids`, in id order. The bitmap is walked a word at a time: an empty word (64 voxels of
    /// air) costs one test, and coordinates advance by addition rather than division.
    /// (Walking every voxel and testing its bit made the run tables most of a 67M-voxel
    /// classification.)
    fn for_each_significant_in(&self, ids: std::ops::Range<u64>, mut f: impl FnMut(u32, [u32; 3])) {
        let [nx, ny, _] = self.dims;
        if ids.start >= ids.end {
            return;
        }
        let (w0, w1) = (ids.start / 64, ids.end.div_ceil(64));
        // Coordinates of the first voxel of the current word.
        let first = w0 * 64;
        let (plane, row) = (u64::from(nx) * u64::from(ny), u64::from(nx));
        let (mut x0, mut y0, mut z0) = (
            (first % row) as u32,
            (first % plane / row) as u32,
            (first / plane) as u32,
        );
        let advance = |x: &mut u32, y: &mut u32, z: &mut u32, by: u32| {
            *x += by;
            while *x >= nx {
                *x -= nx;
                *y += 1;
                if *y == ny {
                    *y = 0;
                    *z += 1;
                }
            }
        };
        let words = self
            .bits
            .get(w0 as usize..(w1 as usize).min(self.bits.len()))
            .unwrap_or(&[]);
        for (i, &word) in words.iter().enumerate() {
            let w = w0 + i as u64;
            // Bits of the word inside `ids`.
            // (`lo` < 64 and `hi` >= 1: the word holds at least one id of the range.)
            let lo = ids.start.saturating_sub(w * 64) as u32;
            let hi = (ids.end - w * 64).min(64) as u32;
            let below_hi = if hi == 64 { u64::MAX } else { (1 << hi) - 1 };
            let mut bits = word & below_hi & (u64::MAX << lo);
            let (mut x, mut y, mut z, mut at) = (x0, y0, z0, 0u32);
            while bits != 0 {
                let bit = bits.trailing_zeros();
                bits &= bits - 1;
                advance(&mut x, &mut y, &mut z, bit - at);
                at = bit;
                f((w as u32).wrapping_mul(64).wrapping_add(bit), [x, y, z]);
            }
            advance(&mut x0, &mut y0, &mut z0, 64);
        }
    }

    /// Grid size in voxels along x, y and z.
    pub fn dims(&self) -> [u32; 3] {
        self.dims
    }

    /// Id steps along x, y and z.
    pub fn strides(&self) -> [u32; 3] {
        [1, self.dims[0], self.dims[0].wrapping_mul(self.dims[1])]
    }

    /// Number of significant voxels.
    pub fn len(&self) -> usize {
        self.count as usize
    }

    /// Whether no voxel is significant.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Whether every voxel is significant.
    pub fn is_dense(&self) -> bool {
        self.count == self.dims.iter().map(|&n| u64::from(n)).product::<u64>()
    }

    /// Whether voxel `id` is significant (false outside the grid).
    #[inline]
    pub fn contains(&self, id: u32) -> bool {
        self.bits
            .get((id / 64) as usize)
            .is_some_and(|w| w >> (id % 64) & 1 == 1)
    }

    /// Position of voxel `id` among the significant voxels in id order, if it is significant.
    #[inline]
    pub fn rank(&self, id: u32) -> Option<u32> {
        let word = *self.bits.get((id / 64) as usize)?;
        let bit = id % 64;
        if word >> bit & 1 == 0 {
            return None;
        }
        let below = word & ((1u64 << bit) - 1);
        Some(self.word_rank[(id / 64) as usize] + below.count_ones())
    }

    /// Index coordinates of voxel `id`.
    #[inline]
    pub fn coords(&self, id: u32) -> [u32; 3] {
        let [nx, ny, _] = self.dims;
        [id % nx, (id / nx) % ny, id / nx / ny]
    }

    /// The rows along `axis`, built on first use.
    ///
    /// They are built outside the lock. [`SparseGrid::build_rows`] runs on rayon, and a rayon
    /// thread that waits inside `OnceLock::get_or_init` for that parallel build may meanwhile
    /// take another task that asks for the same rows, and then wait on itself for ever (seen
    /// with 16 threads, drawing from a parallel loop over bricks). Two threads that find the
    /// rows missing at once each build them and one result is kept; parallel loops that read
    /// rows build them first ([`SparseGrid::prepare_rows`]) so that this does not happen.
    #[inline]
    fn rows_along(&self, axis: usize) -> &AxisRows {
        if let Some(rows) = self.rows[axis].get() {
            return rows;
        }
        let built = self.build_rows(axis);
        self.rows[axis].get_or_init(|| built)
    }

    /// Builds the rows along `axis` if they are not built yet: for a caller about to read
    /// them from many tasks at once.
    pub fn prepare_rows(&self, axis: usize) {
        self.rows_along(axis);
    }

    /// The runs of the row along `axis` whose other two coordinates are `k_b` and `k_c` (the
    /// other axes in increasing order, see [`other_axes`]).
    #[inline]
    pub fn row(&self, axis: usize, k_b: u32, k_c: u32) -> &[Run] {
        let (b, _) = other_axes(axis);
        let rows = self.rows_along(axis);
        let r = k_b as usize + self.dims[b] as usize * k_c as usize;
        &rows.runs[rows.offsets[r] as usize..rows.offsets[r + 1] as usize]
    }

    /// Significant voxel ids in increasing order.
    pub fn ids(&self) -> impl Iterator<Item = u32> + '_ {
        self.bits.iter().enumerate().flat_map(|(w, &word)| {
            let mut rest = word;
            std::iter::from_fn(move || {
                (rest != 0).then(|| {
                    let bit = rest.trailing_zeros();
                    rest &= rest - 1;
                    w as u32 * 64 + bit
                })
            })
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_match_the_bitmap_on_every_axis() {
        // Rows shorter than a bitmap word, longer than one, crossing words, one voxel wide;
        // masks sparse and dense.
        for (dims, keep) in [
            ([5, 4, 3], 3),
            ([70, 3, 2], 2),
            ([1, 9, 20], 4),
            ([130, 1, 3], 5),
            ([64, 2, 2], 2),
            ([3, 65, 2], 7),
        ] {
            rows_match_the_bitmap(dims, keep);
        }
    }

    fn rows_match_the_bitmap(dims: [u32; 3], keep: u32) {
        let count = dims.iter().product::<u32>();
        let ids: Vec<u32> = (0..count)
            .filter(|i| (i * 7 + i / 5 + i / 13) % keep != 0)
            .collect();
        let grid = SparseGrid::from_sorted_ids(dims, &ids).unwrap();
        assert_eq!(grid.len(), ids.len());
        let strides = grid.strides();
        for axis in 0..3 {
            let (b, c) = other_axes(axis);
            let mut seen = Vec::new();
            for kc in 0..dims[c] {
                for kb in 0..dims[b] {
                    let mut last_end = None;
                    for run in grid.row(axis, kb, kc) {
                        assert!(run.len > 0);
                        // Runs are maximal: separated by at least one empty voxel.
                        assert!(last_end.is_none_or(|e| run.start > e));
                        last_end = Some(run.end());
                        for k in run.start..run.end() {
                            let mut coord = [0; 3];
                            coord[axis] = k;
                            coord[b] = kb;
                            coord[c] = kc;
                            seen.push(coord.iter().zip(strides).map(|(k, s)| k * s).sum::<u32>());
                        }
                    }
                }
            }
            seen.sort_unstable();
            assert_eq!(seen, ids, "{dims:?} axis {axis}");
        }
        for (rank, id) in grid.ids().enumerate() {
            assert_eq!(grid.rank(id), Some(rank as u32));
        }
    }

    /// Rows first asked for from many rayon tasks at once, as the texel build asks for them
    /// from a parallel loop over bricks, are built and read without a deadlock. Asked for
    /// inside the lock, a task waiting on their parallel build could take another task that
    /// asks for the same rows and wait on itself. Each round is a fresh grid (rows not built);
    /// the count is checked against the bitmap.
    #[test]
    fn rows_first_asked_for_from_many_tasks_at_once_are_built_without_a_deadlock() {
        use rayon::prelude::*;
        // A small grid drawn in layers of four slices, as the texel build reads it: fewer
        // outer tasks than threads, so that idle threads take parts of the build, and the
        // thread that builds, waiting for them, looks for work among the outer tasks.
        let dims = [12u32, 12, 12];
        let keep = |id: u32| !(id / 3 + id / 41).is_multiple_of(4);
        let expected = (0..dims.iter().product::<u32>())
            .filter(|&id| keep(id))
            .count();
        let (sender, receiver) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(16)
                .build()
                .unwrap();
            let counts: Vec<usize> = (0..2000)
                .map(|_| {
                    let grid = SparseGrid::from_mask(dims, keep).unwrap();
                    let mut per_layer = vec![0usize; 3];
                    pool.install(|| {
                        per_layer.par_iter_mut().enumerate().for_each(|(layer, n)| {
                            for z in 4 * layer as u32..4 * (layer as u32 + 1) {
                                for y in 0..dims[1] {
                                    *n += grid
                                        .row(0, y, z)
                                        .iter()
                                        .map(|r| r.len as usize)
                                        .sum::<usize>();
                                }
                            }
                        })
                    });
                    per_layer.iter().sum()
                })
                .collect();
            let _ = sender.send(counts);
        });
        let counts = receiver
            .recv_timeout(std::time::Duration::from_secs(60))
            .expect("the rows were not built within a minute: a deadlock");
        assert!(
            counts.iter().all(|&n| n == expected),
            "{counts:?} != {expected}"
        );
    }

    #[test]
    fn dense_grid_is_every_voxel() {
        let grid = SparseGrid::dense([7, 3, 5]).unwrap();
        assert!(grid.is_dense());
        assert_eq!(grid.ids().collect::<Vec<_>>(), (0..105).collect::<Vec<_>>());
        assert_eq!(grid.row(1, 6, 4), &[Run { start: 0, len: 3 }]);
        assert_eq!(grid.rank(104), Some(104));
        assert_eq!(grid.rank(105), None);
        let masked = SparseGrid::from_mask([7, 3, 5], |_| true).unwrap();
        assert!(masked.is_dense());
        assert_eq!(masked.row(2, 1, 2), grid.row(2, 1, 2));
    }

    #[test]
    fn sizes_that_do_not_fit_u32_ids_are_refused() {
        assert!(matches!(
            voxel_count([65536, 65536, 2]),
            Err(GridError::TooLarge {
                count: 8589934592,
                ..
            })
        ));
        assert_eq!(voxel_count([65536, 65536, 1]), Ok(1 << 32));
        assert_eq!(voxel_count([3, 0, 2]), Err(GridError::EmptyAxis([3, 0, 2])));
        assert_eq!(
            SparseGrid::from_sorted_ids([2, 2, 2], &[1, 8]).unwrap_err(),
            GridError::IdOutOfRange {
                id: 8,
                dims: [2, 2, 2]
            }
        );
        assert_eq!(
            SparseGrid::from_sorted_ids([2, 2, 2], &[3, 3]).unwrap_err(),
            GridError::Unsorted(1)
        );
    }

    #[test]
    fn a_grid_from_parts_is_the_grid_of_its_ids_joined() {
        // Parts of every size around the 64-bit words and the stretches of 2^20 ids, empty
        // ones among them, sharing words where they meet: the same bitmap as a plain set of
        // bits, and the joined list's errors.
        let dims = [300u32, 200, 40];
        let ids: Vec<u32> = (0..dims.iter().product::<u32>())
            .filter(|&id| (id.wrapping_mul(2654435761) >> 29) != 0 || id % 64 == 63)
            .collect();
        assert!(ids.len() > 1 << 21);
        let cuts = [
            0,
            0,
            1,
            63,
            64,
            65,
            5000,
            1 << 20,
            (1 << 20) + 7,
            2_000_000,
            ids.len(),
        ];
        let parts: Vec<&[u32]> = cuts.windows(2).map(|c| &ids[c[0]..c[1]]).collect();
        let grid = SparseGrid::from_sorted_parts(dims, &parts).unwrap();
        let mut bits = vec![0u64; (dims.iter().product::<u32>() as usize).div_ceil(64)];
        for &id in &ids {
            bits[id as usize / 64] |= 1 << (id % 64);
        }
        assert_eq!(grid.bits, bits);
        assert_eq!(grid.len(), ids.len());
        assert_eq!(grid.rank(ids[1 << 20]), Some(1 << 20));
        // An id repeated where two parts meet, past an empty part; one out of the grid in the
        // last part.
        let (a, b) = (&ids[..100], &ids[99..200]);
        assert_eq!(
            SparseGrid::from_sorted_parts(dims, &[a, &[], b]).unwrap_err(),
            GridError::Unsorted(100)
        );
        let far = [ids[0], dims.iter().product::<u32>()];
        assert!(matches!(
            SparseGrid::from_sorted_parts(dims, &[&ids[..5], &[], &far[1..]]).unwrap_err(),
            GridError::IdOutOfRange { .. }
        ));
        assert_eq!(
            SparseGrid::from_sorted_parts(dims, &[&ids[..5], &ids[7..9], &ids[8..9]]).unwrap_err(),
            GridError::Unsorted(7)
        );
    }
}
