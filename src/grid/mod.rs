//! Sparse sets of significant voxels on a regular grid (space skipping).
//!
//! A [`SparseGrid`] records which voxels of an `nx x ny x nz` grid are significant. Voxel ids are
//! `x + nx * (y + ny * z)` as `u32`; a grid with more than 2^32 voxels is refused with
//! [`GridError::TooLarge`] rather than wrapping. Besides a bitmap (with a rank index, so that the
//! attributes of the significant voxels can be stored compactly; held by pages, the pages with
//! no significant voxel not stored), the grid keeps run-length rows along each of the three
//! axes: the inner loop of every ordering walks runs, so empty space costs nothing there. An
//! axis's rows are built the first time they are asked for (a view needs one or two of them),
//! slabs of rows in parallel. A dense grid is the case where every voxel is significant.

use std::sync::OnceLock;

use thiserror::Error;

mod pages;

pub use pages::BitsPart;
use pages::PagedBits;

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
    /// A region of voxels made for a grid of another size.
    #[error("a region made for a {region:?} grid was given for a {dims:?} grid")]
    RegionMismatch {
        /// The grid the region was made for.
        region: [u32; 3],
        /// The grid it was given for.
        dims: [u32; 3],
    },
    /// A classification holds another number of colours than its grid has significant voxels.
    #[error("a classification holds {colors} colours for {voxels} significant voxels")]
    ColorsMismatch {
        /// Colours held.
        colors: usize,
        /// Significant voxels of its grid.
        voxels: usize,
    },
    /// The classification was given up: its cancel flag was raised while it ran.
    #[error("the classification was cancelled before it was finished")]
    Cancelled,
    /// Two grids joined into one are of different sizes, or share a voxel.
    #[error(
        "grids of {a:?} and {b:?} voxels cannot be joined: they must be of one size and share no voxel"
    )]
    NotDisjoint {
        /// The first grid's size.
        a: [u32; 3],
        /// The second grid's size.
        b: [u32; 3],
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

/// Calls `f` with the index of each set bit of `words` (bit `i % 64` of word `i / 64`), in
/// increasing order.
#[inline(always)]
fn for_each_bit(words: &[u64], mut f: impl FnMut(usize)) {
    for (i, &w) in words.iter().enumerate() {
        let mut bits = w;
        while bits != 0 {
            f(i * 64 + bits.trailing_zeros() as usize);
            bits &= bits - 1;
        }
    }
}

/// The significant voxels of a grid, with run-length rows along each axis.
#[derive(Debug, Clone)]
pub struct SparseGrid {
    dims: [u32; 3],
    /// The bitmap, with its rank index: bit `id % 64` of word `id / 64` for voxel `id`.
    bits: PagedBits,
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
            bits: PagedBits::from_flat(bits),
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
        Ok(Self::from_paged(dims, PagedBits::from_flat(bits)))
    }

    /// The voxels listed in `ids`, which must be strictly increasing and inside the grid.
    pub fn from_sorted_ids(dims: [u32; 3], ids: &[u32]) -> Result<Self, GridError> {
        let mut part = BitsPart::default();
        for &id in ids {
            part.push(id);
        }
        Self::from_bit_parts(dims, vec![part])
    }

    /// The voxels set in `parts` one after the other (a classification's slabs), which
    /// together must be strictly increasing and inside the grid; the parts are freed as they
    /// are taken. No flat bitmap of the whole grid is made: the pages the parts hold are the
    /// grid's.
    pub fn from_bit_parts(dims: [u32; 3], parts: Vec<BitsPart>) -> Result<Self, GridError> {
        let count = voxel_count(dims)?;
        let (mut before, mut last) = (0usize, None::<u32>);
        for part in &parts {
            if let Some(at) = part.unsorted() {
                return Err(GridError::Unsorted(before + at));
            }
            if let Some(first) = part.first() {
                if last.is_some_and(|l| first <= l) {
                    return Err(GridError::Unsorted(before));
                }
                last = part.last();
            }
            if let Some(id) = part.last().filter(|&id| u64::from(id) >= count) {
                return Err(GridError::IdOutOfRange { id, dims });
            }
            before += part.len();
        }
        let words = count.div_ceil(64) as usize;
        Ok(Self::from_paged(dims, PagedBits::from_parts(words, parts)))
    }

    fn from_paged(dims: [u32; 3], bits: PagedBits) -> Self {
        Self {
            dims,
            bits,
            rows: Default::default(),
        }
    }

    /// Builds the run-length rows along `axis` in two passes over the bitmap: count the runs that
    /// start in each row, then fill them in. Both go a bitmap row (the voxels along x) a word
    /// at a time: the voxels that start a run along `axis` are those whose neighbour before
    /// them along it is empty, and those that end one those whose neighbour after it is, a few
    /// word operations for 64 voxels ([`SparseGrid::slab_edges`]); only these are visited one
    /// by one. (Visiting every significant voxel and testing its neighbour's bit took 0.2 s
    /// an axis on a 118M-voxel CT with 28M significant voxels.)
    fn build_rows(&self, axis: usize) -> AxisRows {
        use rayon::prelude::*;
        let (b, c) = other_axes(axis);
        let (nb, nc) = (self.dims[b] as usize, self.dims[c] as usize);
        let n_rows = nb * nc;
        let nx = self.dims[0] as usize;
        // Slabs of the rows' slowest coordinate `c`, a task each: a slab's rows are a stretch
        // of the table.
        let per = nc.div_ceil(4 * rayon::current_num_threads()).max(1);
        let slabs: Vec<(usize, usize)> = (0..nc)
            .step_by(per)
            .map(|c0| (c0, (c0 + per).min(nc)))
            .collect();
        // The row (within its slab's stretch of the table) of the run through voxel `x` of
        // bitmap row `(y, z)`, for the slab starting at `c0`.
        let row_in_slab = |x: usize, y: usize, z: usize, c0: usize| match axis {
            0 => y + nb * (z - c0),
            1 => x + nb * (z - c0),
            _ => x + nb * (y - c0),
        };
        let mut offsets = vec![0u32; n_rows + 1];
        offsets[1..]
            .par_chunks_mut(per * nb)
            .zip(&slabs)
            .for_each(|(counts, &(c0, c1))| {
                self.slab_edges(axis, c0..c1, |y, z, starts, _| {
                    if axis == 0 {
                        counts[row_in_slab(0, y, z, c0)] +=
                            starts.iter().map(|w| w.count_ones()).sum::<u32>();
                    } else {
                        for_each_bit(starts, |x| counts[row_in_slab(x, y, z, c0)] += 1);
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
                let mut put = |row: usize, run: Run| {
                    let slot = &mut fill[row];
                    part[*slot as usize] = run;
                    *slot += 1;
                };
                // Along y and z, where the run that a voxel ends began: per voxel of a
                // bitmap row (along y, per plane), or of the slab's rows (along z).
                let mut open = vec![0u32; if axis == 2 { nx * (c1 - c0) } else { nx }];
                let mut begun = Vec::new();
                self.slab_edges(axis, c0..c1, |y, z, starts, ends| {
                    if axis == 0 {
                        // Along x a run's start and end lie in the same bitmap row, in turn.
                        let row = row_in_slab(0, y, z, c0);
                        begun.clear();
                        for_each_bit(starts, |x| begun.push(x as u32));
                        let mut next = begun.iter();
                        for_each_bit(ends, |x| {
                            if let Some(&start) = next.next() {
                                put(
                                    row,
                                    Run {
                                        start,
                                        len: x as u32 + 1 - start,
                                    },
                                );
                            }
                        });
                        return;
                    }
                    let (at, base) = if axis == 1 {
                        (y, 0)
                    } else {
                        (z, nx * (y - c0))
                    };
                    for_each_bit(starts, |x| open[base + x] = at as u32);
                    for_each_bit(ends, |x| {
                        let start = open[base + x];
                        put(
                            row_in_slab(x, y, z, c0),
                            Run {
                                start,
                                len: at as u32 + 1 - start,
                            },
                        );
                    });
                });
            });
        AxisRows { offsets, runs }
    }

    /// Calls `f(y, z, starts, ends)` for each bitmap row (the voxels along x at `(y, z)`) of
    /// the rows along `axis` whose coordinate along the slowest of the other two axes lies in
    /// `range` (z for axes x and y, y for z), in the order each row along `axis` meets them
    /// (z then y for axes x and y; z, then y within the range, for z). `starts` has bit `x`
    /// set where voxel `x` of the bitmap row starts a run along `axis` (significant, and its
    /// neighbour before it along `axis` is not or lies off the grid), `ends` where it ends
    /// one, as words of 64 voxels. Bitmap rows in pages not stored may be left out: they
    /// start and end no run.
    fn slab_edges(
        &self,
        axis: usize,
        range: std::ops::Range<usize>,
        mut f: impl FnMut(usize, usize, &[u64], &[u64]),
    ) {
        let [nx, ny, nz] = self.dims.map(|n| n as usize);
        let words = nx.div_ceil(64);
        // The row itself, the ones before and after it along `axis` (y and z; empty off the
        // grid), and the edges.
        let [mut here, mut before, mut after, mut starts, mut ends] =
            std::array::from_fn(|_| vec![0u64; words]);
        let mut visit = |y: usize, z: usize| {
            // A row in pages of the bitmap not stored starts and ends no run: skipped, its
            // neighbours not read (most of a refinement classified within a few bricks).
            let start = nx * (y + ny * z);
            if self
                .bits
                .clear_between(start / 64, (start + nx).div_ceil(64))
            {
                return;
            }
            self.bitmap_row(y, z, &mut here);
            if axis == 0 {
                for i in 0..words {
                    // The bit before each voxel's (the previous word's last for bit 0) and the
                    // one after it; past the row's end the row's words are 0.
                    let carry = if i > 0 { here[i - 1] >> 63 } else { 0 };
                    let next = here.get(i + 1).map_or(0, |w| w << 63);
                    starts[i] = here[i] & !(here[i] << 1 | carry);
                    ends[i] = here[i] & !(here[i] >> 1 | next);
                }
            } else {
                let neighbour = |d: isize, out: &mut Vec<u64>| {
                    let (y, z) = if axis == 1 {
                        (y as isize + d, z as isize)
                    } else {
                        (y as isize, z as isize + d)
                    };
                    if y < 0 || z < 0 || y as usize >= ny || z as usize >= nz {
                        out.fill(0);
                    } else {
                        self.bitmap_row(y as usize, z as usize, out);
                    }
                };
                neighbour(-1, &mut before);
                neighbour(1, &mut after);
                for i in 0..words {
                    starts[i] = here[i] & !before[i];
                    ends[i] = here[i] & !after[i];
                }
            }
            f(y, z, &starts, &ends);
        };
        if axis == 2 {
            for z in 0..nz {
                for y in range.clone() {
                    visit(y, z);
                }
            }
        } else {
            for z in range {
                for y in 0..ny {
                    visit(y, z);
                }
            }
        }
    }

    /// The bits of the voxels along x at `(y, z)` into `out` (its length: the row's words),
    /// bit `x % 64` of word `x / 64` for voxel `x`, 0 past the row's end.
    fn bitmap_row(&self, y: usize, z: usize, out: &mut [u64]) {
        let [nx, ny, _] = self.dims.map(|n| n as usize);
        let start = nx * (y + ny * z);
        let (w0, shift) = (start / 64, (start % 64) as u32);
        for (i, o) in out.iter_mut().enumerate() {
            let lo = self.bits.word(w0 + i);
            *o = if shift == 0 {
                lo
            } else {
                let hi = self.bits.word(w0 + i + 1);
                lo >> shift | hi << (64 - shift)
            };
        }
        if nx % 64 != 0
            && let Some(last) = out.last_mut()
        {
            *last &= (1u64 << (nx % 64)) - 1;
        }
    }

    /// The significant voxels of this grid and of `other`, a grid of the same size that shares
    /// no significant voxel with it ([`GridError::NotDisjoint`] otherwise).
    pub fn joined_with(&self, other: &SparseGrid) -> Result<Self, GridError> {
        let refused = GridError::NotDisjoint {
            a: self.dims,
            b: other.dims,
        };
        if self.dims != other.dims {
            return Err(refused);
        }
        let bits = self.bits.union_of_disjoint(&other.bits).ok_or(refused)?;
        Ok(Self::from_paged(self.dims, bits))
    }

    /// The bitmap words of this grid and of `other`, a grid of the same size, in pairs, in
    /// id order, where either has a significant voxel among a word's page (other words are
    /// left out): voxel `id` is significant where bit `id % 64` of its word is set.
    pub(crate) fn word_pairs<'a>(
        &'a self,
        other: &'a SparseGrid,
    ) -> impl Iterator<Item = (u64, u64)> + 'a {
        self.bits.word_pairs(&other.bits)
    }

    /// Bytes the bitmap and its rank index hold.
    pub fn bitmap_bytes(&self) -> usize {
        self.bits.bytes()
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
        self.bits.count() as usize
    }

    /// Whether no voxel is significant.
    pub fn is_empty(&self) -> bool {
        self.bits.count() == 0
    }

    /// Whether every voxel is significant.
    pub fn is_dense(&self) -> bool {
        self.bits.count() == self.dims.iter().map(|&n| u64::from(n)).product::<u64>()
    }

    /// Whether voxel `id` is significant (false outside the grid).
    #[inline]
    pub fn contains(&self, id: u32) -> bool {
        self.bits.contains(id)
    }

    /// Position of voxel `id` among the significant voxels in id order, if it is significant.
    #[inline]
    pub fn rank(&self, id: u32) -> Option<u32> {
        self.bits.rank(id)
    }

    /// The bitmap and its rank index laid out for the GPU passes, which find a voxel's rank,
    /// and so its texel, from its id (`texel_of` in `shaders/splat.wgsl`).
    pub(crate) fn rank_words(&self) -> Vec<u32> {
        self.bits.to_gpu_words()
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
        self.bits.pages().flat_map(|(first, words)| {
            words.iter().enumerate().flat_map(move |(i, &word)| {
                let w = (first + i) as u32;
                let mut rest = word;
                std::iter::from_fn(move || {
                    (rest != 0).then(|| {
                        let bit = rest.trailing_zeros();
                        rest &= rest - 1;
                        w * 64 + bit
                    })
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
            // Rows either side of the 64-bit words and of two, runs along every axis
            // crossing the words the bitmap rows share, rows of one voxel, more slabs than
            // tasks, and grids all but full.
            ([63, 5, 9], 3),
            ([129, 4, 17], 2),
            ([128, 3, 40], 6),
            ([1, 1, 50], 3),
            ([200, 1, 1], 2),
            ([65, 33, 1], 3),
            ([70, 6, 12], 1000),
            ([64, 64, 3], 1000),
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
    fn a_sparse_grid_from_parts_stores_only_its_pages_and_ranks_as_a_list() {
        // Clusters of ids with long empty stretches between them (pages of the bitmap not
        // stored), parts cut inside words, inside pages and between clusters, some empty.
        let dims = [1000u32, 300, 20];
        let ids: Vec<u32> = (0..dims.iter().product::<u32>())
            .filter(|&id| (id / 2500) % 7 == 0 && id.wrapping_mul(2654435761) >> 30 != 0)
            .collect();
        let cuts = [0, 1, 30, 700, 701, 5000, 90_000, 90_000, 200_000, ids.len()];
        let grid = SparseGrid::from_bit_parts(dims, bit_parts(&ids, &cuts)).unwrap();
        assert_eq!(grid.len(), ids.len());
        let mut flat = vec![0u64; (dims.iter().product::<u32>() as usize).div_ceil(64)];
        for &id in &ids {
            flat[id as usize / 64] |= 1 << (id % 64);
        }
        let words: Vec<u64> = (0..flat.len()).map(|w| grid.bits.word(w)).collect();
        assert_eq!(words, flat);
        // Far less than the flat bitmap and its rank a word (12 bytes a word).
        assert!(
            grid.bitmap_bytes() * 3 < flat.len() * 12,
            "{} bytes",
            grid.bitmap_bytes()
        );
        for (rank, &id) in ids.iter().enumerate().step_by(97) {
            assert_eq!(grid.rank(id), Some(rank as u32));
            assert!(grid.rank(id + 2500).is_none_or(|r| r as usize > rank));
        }
        assert_eq!(grid.rank(2500 * 3), None);
        assert_eq!(grid.ids().collect::<Vec<_>>(), ids);
        // Joined with the voxels it lacks in a cluster, the ids of both in order.
        let more: Vec<u32> = (2500 * 7..2500 * 7 + 3000)
            .filter(|id| ids.binary_search(id).is_err())
            .collect();
        let joined = grid
            .joined_with(&SparseGrid::from_sorted_ids(dims, &more).unwrap())
            .unwrap();
        let mut all = [ids.clone(), more].concat();
        all.sort_unstable();
        assert_eq!(joined.ids().collect::<Vec<_>>(), all);
        assert_eq!(joined.rank(all[40_000]), Some(40_000));
    }

    /// The ids of `ids` cut at `cuts` into bit parts.
    fn bit_parts(ids: &[u32], cuts: &[usize]) -> Vec<BitsPart> {
        cuts.windows(2)
            .map(|c| {
                let mut part = BitsPart::default();
                for &id in &ids[c[0]..c[1]] {
                    part.push(id);
                }
                part
            })
            .collect()
    }

    #[test]
    fn a_grid_from_bit_parts_is_the_grid_of_its_ids() {
        // Parts cut inside pages (1024 voxels) and words and at their edges, empty ones among
        // them: the bitmap of a plain set of bits, word for word, and its ranks.
        let dims = [300u32, 200, 40];
        let ids: Vec<u32> = (0..dims.iter().product::<u32>())
            .filter(|&id| (id.wrapping_mul(2654435761) >> 27) < 3 || id % 1000 == 999)
            .collect();
        let cuts = [
            0,
            0,
            1,
            63,
            64,
            65,
            700,
            1500,
            1500,
            123_456,
            ids.len() - 1,
            ids.len(),
        ];
        let grid = SparseGrid::from_bit_parts(dims, bit_parts(&ids, &cuts)).unwrap();
        let mut bits = vec![0u64; (dims.iter().product::<u32>() as usize).div_ceil(64)];
        for &id in &ids {
            bits[id as usize / 64] |= 1 << (id % 64);
        }
        let words: Vec<u64> = (0..bits.len()).map(|w| grid.bits.word(w)).collect();
        assert_eq!(words, bits);
        assert_eq!(grid.len(), ids.len());
        for i in [0, 1, 64, 1000, ids.len() / 2, ids.len() - 1] {
            assert_eq!(grid.rank(ids[i]), Some(i as u32));
        }
        // Only the pages (1024 voxels) holding an id are stored: their words and their ranks
        // (8 and 2 bytes a word), a rank each, and the table of every page.
        let mut pages: Vec<u32> = ids.iter().map(|id| id / 1024).collect();
        pages.dedup();
        let table = (dims.iter().product::<u32>() as usize).div_ceil(1024);
        assert_eq!(grid.bitmap_bytes(), pages.len() * (16 * 10 + 4) + table * 4);
        // An empty grid, from no part and from empty parts.
        assert!(
            SparseGrid::from_bit_parts(dims, Vec::new())
                .unwrap()
                .is_empty()
        );
        assert!(
            SparseGrid::from_bit_parts(dims, vec![BitsPart::default(); 3])
                .unwrap()
                .is_empty()
        );
    }

    #[test]
    fn bit_parts_out_of_order_or_past_the_grid_are_refused() {
        let dims = [40u32, 30, 20];
        let ids: Vec<u32> = (0..dims.iter().product::<u32>()).step_by(7).collect();
        // An id repeated where two parts meet, past an empty part.
        let mut parts = bit_parts(&ids, &[0, 100, 100]);
        let mut again = BitsPart::default();
        for &id in &ids[99..200] {
            again.push(id);
        }
        parts.push(again);
        assert_eq!(
            SparseGrid::from_bit_parts(dims, parts).unwrap_err(),
            GridError::Unsorted(100)
        );
        // Within a part: the place of the id, which is not set.
        let mut part = BitsPart::default();
        for id in [3, 9, 9, 12] {
            part.push(id);
        }
        assert_eq!(
            (part.len(), part.unsorted(), part.last()),
            (3, Some(2), Some(12))
        );
        let first = bit_parts(&ids, &[0, 5]).remove(0);
        assert_eq!(
            SparseGrid::from_bit_parts(dims, vec![first, part]).unwrap_err(),
            GridError::Unsorted(7)
        );
        // Past the grid's last voxel.
        let mut far = BitsPart::default();
        far.push(dims.iter().product::<u32>());
        assert!(matches!(
            SparseGrid::from_bit_parts(dims, vec![BitsPart::default(), far]).unwrap_err(),
            GridError::IdOutOfRange { .. }
        ));
    }
}
