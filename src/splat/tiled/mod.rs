//! A sort-free tile compositor for splats on the CPU, with the mathematics of the GPU splat
//! pass (`shaders/splat.wgsl`): the same EWA footprint, the same 8-bit colours and normals, the
//! same headlight shading, clip planes and depth test against the mesh depth.
//!
//! An a-priori visibility order (IP-PBTF and the others) needs no sort, and binning keeps it:
//! splats are projected in draw order and appended to each 16x16-pixel tile their footprint
//! touches, so each tile holds its splats in draw order, and each tile is composited on its
//! own, in parallel, front to back (the reverse of a back-to-front order) with the "under"
//! operator `C += (1 - A) c; A += (1 - A) a`. A pixel whose opacity reaches [`OPAQUE`] takes
//! no more splats, and a tile whose pixels all do takes none: early ray termination, for
//! splats, so the hidden inside of a bone costs nothing. What a stopped pixel leaves out is at
//! most `1 - OPAQUE` of every channel.
//!
//! The order is walked nearest first in batches (4,096 splats, doubling to 32,768): each batch
//! is projected and binned, then composited, before the next. A splat's pixel rectangle follows
//! from its centre alone (the covariance is the volume's), so a splat whose rectangle holds
//! only pixels opaque by then (a bit per pixel) is left out before its texel is even read;
//! stretches of the order whose box of voxels is hidden are left out before each splat's
//! centre is. Projection is the part of a frame that early termination alone does not shrink.
//! It takes the order in groups of 32 splats, each group's fate settled one group ahead, so that
//! the texels of the next group to be projected are fetched while this one is: they miss the
//! caches where the order's rows cross the texels' bricks.
//!
//! The pixel loop works on rows of 8 pixels held as planes (in the AVX2 loop, a footprint at
//! most 4 pixels wide, as a voxel under a pixel across makes, takes two rows a vector, four
//! pixels of each, rather than half-empty vectors row by row). It is written twice: in plain
//! loops the compiler vectorises for the x86-64 baseline (SSE2) and any other processor, and
//! in AVX2 and FMA intrinsics, chosen at run time where the processor has them, since the
//! compiler neither fuses multiply-adds nor gathers lane masks well on its own (no `wide`: it
//! picks its instructions from the features the whole build targets, so it cannot follow a
//! choice made at run time). Projection runs 8 splats a vector in the AVX2
//! build too. rayon runs the chunks of a batch and the tiles in parallel. Every buffer lives in the
//! [`TiledCompositor`] and is reused from frame to frame; none grows with the volume past one
//! batch.

mod bin;
mod mask;
mod project;
mod simd;
#[cfg(target_arch = "x86_64")]
mod simd512;
#[cfg(test)]
mod tests;
mod texels;
mod tile;

use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use rayon::prelude::*;

use bin::{ChunkBins, bin_chunk};
use mask::OpaqueMask;
use project::{Group, Projected, group_rect};
pub use project::{SplatProjection, alpha_table};
pub use simd::SIMD_VAR;
pub use texels::{SplatTexels, texel};
use tile::{Batch, TilePixels};

/// Tile side in pixels.
pub const TILE: usize = 16;
/// A pixel whose accumulated opacity reaches this takes no more splats; a tile whose pixels
/// all do stops.
pub const OPAQUE: f32 = 0.996;

/// What a frame cost, in splats and time.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TileStats {
    /// Projecting the splats.
    pub project: Duration,
    /// Binning them to tiles.
    pub bin: Duration,
    /// Compositing the tiles and laying them over what lies under them.
    pub tiles: Duration,
    /// Splats in the draw orders.
    pub splats: usize,
    /// Splats projected onto the image (in front of the eye, kept by the clip planes, on
    /// screen).
    pub projected: usize,
    /// Splats left out before their texel was read because every pixel of their footprint was
    /// opaque already (and, once every pixel of the image is opaque, all the splats left).
    pub culled: usize,
    /// Splats left out before projection because the pixel rectangle that holds every
    /// footprint of their group (32 consecutive splats of the order) lies off the image.
    pub off_image: usize,
    /// Splats that reached at least one pixel still open: all the others added nothing to
    /// the image.
    pub drew: usize,
    /// Splat-tile pairs composited: the splat reached a pixel of the tile still open.
    pub composited: usize,
    /// Splat-tile pairs skipped because every pixel the splat covers in the tile had turned
    /// opaque (within the batch that held them, after the opaque pixels were last taken
    /// for culling).
    pub skipped_opaque: usize,
    /// Tiles whose pixels all turned opaque.
    pub tiles_opaque: usize,
    /// Whether the compositing stopped before its last batch because the compositor's cancel
    /// flag was raised ([`TiledCompositor::cancel`]): the image is then unfinished.
    pub cancelled: bool,
}

/// The compositor, with its buffers kept between frames.
#[derive(Debug)]
pub struct TiledCompositor {
    /// The accumulated opacity past which a pixel takes no more splats ([`OPAQUE`] by
    /// default; above 1 no pixel and no tile ever stops).
    pub opaque: f32,
    /// Leave out, before projecting them, splats whose footprint covers opaque pixels alone,
    /// and groups of splats whose footprints all lie off the image (on by default; the image
    /// is the same either way, see [`TiledCompositor::composite`]).
    pub cull_hidden: bool,
    /// Raised from another thread, the compositing stops before its next batch (within a
    /// batch's time: milliseconds) and reports [`TileStats::cancelled`].
    pub cancel: Option<Arc<AtomicBool>>,
    projected: Vec<Projected>,
    bins: Vec<ChunkBins>,
    tiles: Vec<TilePixels>,
    /// The pixels opaque when the batch began.
    mask: OpaqueMask,
    /// Per splat of the batch, whether it reached a pixel still open.
    drew: Vec<AtomicBool>,
}

/// The first batch of splats (the nearest) and the largest; batches double in between, so
/// that tiles close early in a frame while later batches still keep both threads busy.
const FIRST_BATCH: usize = 4096;
/// See [`FIRST_BATCH`].
const MAX_BATCH: usize = 1 << 15;
/// Splats whose voxels' box is tested against the opaque pixels before each is tested alone.
const GROUP: usize = 32;

impl Default for TiledCompositor {
    fn default() -> Self {
        Self {
            opaque: OPAQUE,
            cull_hidden: true,
            cancel: None,
            projected: Vec::new(),
            bins: Vec::new(),
            tiles: Vec::new(),
            mask: OpaqueMask::default(),
            drew: Vec::new(),
        }
    }
}

impl TiledCompositor {
    /// A compositor with nothing allocated yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Composites the volumes' splats over `under` (premultiplied RGBA, the background and the
    /// meshes, row by row, `size` pixels) with the meshes' reversed `depth` per pixel (0 where
    /// none). `volumes` come far to near, each with its draw order back to front. The result
    /// replaces `under`.
    ///
    /// The splats are taken nearest first in batches (the first small, then doubling): a batch
    /// is projected, binned and composited before the next, and a splat of a later batch whose
    /// footprint can only touch pixels that are opaque by then is not projected at all. This
    /// leaves out nothing that compositing every splat would have drawn: such a splat's
    /// splat-tile pairs would all have been skipped.
    pub fn composite(
        &mut self,
        size: (u32, u32),
        volumes: &[(SplatProjection, &SplatTexels, &[u32])],
        depth: &[f32],
        under: &mut [[f32; 4]],
    ) -> TileStats {
        let sources: Vec<_> = volumes.iter().map(|(p, t, _)| (p, *t)).collect();
        let runs: Vec<_> = volumes
            .iter()
            .enumerate()
            .map(|(source, (_, _, ids))| Run { source, ids })
            .collect();
        self.composite_runs(size, &sources, &runs, depth, under)
    }

    /// [`TiledCompositor::composite`] for a draw order made of `runs`, far to near, each a
    /// stretch of the splats of one of `sources` (a grid's projection and texels): the bricks
    /// of a volume drawn at several levels of detail, each level a source. Batches take
    /// splats across runs as they take them within one, so the image is the one the runs'
    /// splats give as one order, however it is cut into runs.
    pub fn composite_runs(
        &mut self,
        size: (u32, u32),
        sources: &[(&SplatProjection, &SplatTexels)],
        runs: &[Run<'_>],
        depth: &[f32],
        under: &mut [[f32; 4]],
    ) -> TileStats {
        self.composite_runs_seen(size, sources, runs, depth, under, &mut [])
    }

    /// [`TiledCompositor::composite_runs`] that also marks, in `seen` (one flag a run, or
    /// empty for none), each run of which some splat reached a pixel still open: the runs
    /// that add to the image. A run left unmarked added nothing: its splats were off the
    /// image, behind opaque pixels or transparent.
    pub(crate) fn composite_runs_seen(
        &mut self,
        size: (u32, u32),
        sources: &[(&SplatProjection, &SplatTexels)],
        runs: &[Run<'_>],
        depth: &[f32],
        under: &mut [[f32; 4]],
        seen: &mut [bool],
    ) -> TileStats {
        let marks = seen.len() == runs.len();
        let (w, h) = (size.0 as usize, size.1 as usize);
        let (tx, ty) = (w.div_ceil(TILE), h.div_ceil(TILE));
        let mut stats = TileStats {
            splats: runs.iter().map(|r| r.ids.len()).sum(),
            ..TileStats::default()
        };
        let started = std::time::Instant::now();
        self.tiles.resize_with(tx * ty, TilePixels::default);
        self.tiles
            .par_iter_mut()
            .enumerate()
            .for_each(|(t, tile)| tile.reset((t % tx) * TILE, (t / tx) * TILE, (w, h), depth));
        self.mask.reset(w, h);
        let mut open_pixels = w * h;
        stats.tiles += started.elapsed();
        let screen = Screen { w, h };
        // Nearest first: the runs near to far, each one's splats from its end. `run` runs are
        // left, the last of them up to `end`.
        let mut batch = FIRST_BATCH;
        let mut run = runs.len();
        let mut end = runs.last().map_or(0, |r| r.ids.len());
        // A batch's stretches of runs in draw order (source, splats, run), and its chunks
        // (source, splats, index of the first in the batch, run).
        let mut pieces: Vec<(usize, &[u32], usize)> = Vec::new();
        let mut work: Vec<(usize, &[u32], usize, usize)> = Vec::new();
        loop {
            if self
                .cancel
                .as_ref()
                .is_some_and(|c| c.load(std::sync::atomic::Ordering::Relaxed))
            {
                stats.cancelled = true;
                break;
            }
            pieces.clear();
            let mut wanted = batch;
            while wanted > 0 && run > 0 {
                let begin = end.saturating_sub(wanted);
                if begin < end {
                    let r = &runs[run - 1];
                    pieces.push((r.source, &r.ids[begin..end], run - 1));
                    wanted -= end - begin;
                }
                end = begin;
                if end == 0 {
                    run -= 1;
                    end = run.checked_sub(1).map_or(0, |r| runs[r].ids.len());
                }
            }
            if pieces.is_empty() {
                break;
            }
            pieces.reverse();
            let count: usize = pieces.iter().map(|(_, ids, _)| ids.len()).sum();
            batch = (batch * 2).min(MAX_BATCH);
            if open_pixels == 0 && self.cull_hidden {
                // Every tile is opaque: nothing further can show.
                let farther: usize = runs[..run.saturating_sub(1)]
                    .iter()
                    .map(|r| r.ids.len())
                    .sum();
                stats.culled += count + end + farther;
                break;
            }
            let chunk = (count / 4).clamp(2048, 1 << 15);
            work.clear();
            let mut first = 0;
            for &(source, ids, run) in &pieces {
                for ids in ids.chunks(chunk) {
                    work.push((source, ids, first, run));
                    first += ids.len();
                }
            }
            let chunks = work.len();
            // Project and bin each chunk (one task: no wait in between), keeping the order
            // within each tile.
            let started = std::time::Instant::now();
            if self.projected.len() < count {
                self.projected.resize(count, Projected::default());
            }
            if self.bins.len() < chunks {
                self.bins.resize_with(chunks, ChunkBins::default);
            }
            if self.drew.len() < count {
                self.drew.resize_with(count, AtomicBool::default);
            }
            let mut outs: Vec<&mut [Projected]> = Vec::with_capacity(chunks);
            let mut rest = &mut self.projected[..count];
            for &(_, ids, _, _) in &work {
                let (out, after) = rest.split_at_mut(ids.len());
                outs.push(out);
                rest = after;
            }
            // No test while no pixel is opaque.
            let mask = (self.cull_hidden && open_pixels < w * h).then_some(&self.mask);
            let cull = self.cull_hidden;
            let (culled, off_image, project_time, bin_time) = outs
                .par_iter_mut()
                .zip(work.par_iter())
                .zip(self.bins[..chunks].par_iter_mut())
                .map(|((out, &(source, ids, first, _)), bins)| {
                    let started = std::time::Instant::now();
                    let (projection, texels) = sources[source];
                    let (mut culled, mut off_image) = (0, 0);
                    let group = Group {
                        u: projection,
                        texels,
                        screen: &screen,
                        mask,
                    };
                    // The chunk's splats on the image, in order, packed at the front of its
                    // share of the buffer.
                    let mut kept = 0;
                    // Each group is decoded and its fate settled one group ahead, so that the
                    // texels of the next group to be projected are asked for while this one
                    // is. (The opaque pixels do not change within a batch's projection.)
                    let mut groups = ids
                        .chunks(GROUP)
                        .map(|ids| Decoded::new(projection, ids, cull, &screen, mask));
                    let mut next = groups.next();
                    while let Some(this) = next {
                        next = groups.next();
                        if let Some(ahead) = &next
                            && ahead.fate == Fate::Project
                        {
                            for &[x, y, z] in ahead.voxels() {
                                texels.prefetch(x, y, z);
                            }
                        }
                        let n = this.voxels().len();
                        match this.fate {
                            Fate::OffImage => off_image += n,
                            Fate::Hidden => culled += n,
                            Fate::Project => {
                                let (hidden, placed) =
                                    simd::project_group(&group, this.voxels(), &mut out[kept..]);
                                culled += hidden;
                                kept += placed;
                            }
                        }
                    }
                    let projected = started.elapsed();
                    bin_chunk(&out[..kept], first as u32, tx, ty, bins);
                    (culled, off_image, projected, started.elapsed() - projected)
                })
                .reduce(
                    || (0, 0, Duration::ZERO, Duration::ZERO),
                    |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2, a.3 + b.3),
                );
            drop(outs);
            // The phase's time, shared between its two stages as their processor time.
            let wall = started.elapsed().as_secs_f64();
            let share = project_time.as_secs_f64()
                / (project_time + bin_time)
                    .as_secs_f64()
                    .max(f64::MIN_POSITIVE);
            stats.project += Duration::from_secs_f64(wall * share);
            stats.bin += Duration::from_secs_f64(wall * (1.0 - share));
            stats.culled += culled;
            stats.off_image += off_image;
            let projected = self.bins[..chunks]
                .iter()
                .map(|b| b.projected)
                .sum::<usize>();
            stats.projected += projected;
            if projected == 0 {
                // Nothing of this batch is on the image (a view zoomed in on part of the
                // volume passes many such): no tile changes.
                continue;
            }
            // Composite every tile, nearest splat first.
            let started = std::time::Instant::now();
            let batch = Batch {
                projected: &self.projected,
                bins: &self.bins[..chunks],
                opaque: self.opaque,
                drew: &self.drew,
            };
            self.tiles.par_iter_mut().enumerate().for_each(|(t, tile)| {
                let origin = ((t % tx) * TILE, (t / tx) * TILE);
                simd::composite_tile(tile, t, origin, batch);
            });
            for (t, tile) in self.tiles.iter().enumerate() {
                self.mask
                    .set_tile((t % tx) * TILE, (t / tx) * TILE, &tile.rows);
            }
            if marks {
                // A chunk's splats on the image lie packed from its first index, all of one
                // run.
                for &(_, ids, first, run) in &work {
                    if !seen[run]
                        && self.drew[first..first + ids.len()]
                            .iter_mut()
                            .any(|d| *d.get_mut())
                    {
                        seen[run] = true;
                    }
                }
            }
            // Counted and cleared through `&mut`: plain loads and stores, no locked
            // instruction per splat.
            stats.drew += self.drew[..count]
                .iter_mut()
                .map(|d| usize::from(std::mem::take(d.get_mut())))
                .sum::<usize>();
            open_pixels = self.tiles.iter().map(|t| t.open as usize).sum();
            stats.tiles += started.elapsed();
        }
        let started = std::time::Instant::now();
        for tile in &self.tiles {
            stats.composited += tile.composited;
            stats.skipped_opaque += tile.skipped;
            stats.tiles_opaque += usize::from(tile.open == 0);
        }
        // The splats over what lies under them.
        let tiles = &self.tiles;
        under.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for (x, px) in row.iter_mut().enumerate() {
                let tile = &tiles[(y / TILE) * tx + x / TILE];
                let i = (y % TILE) * TILE + x % TILE;
                let s = [tile.r[i], tile.g[i], tile.b[i], tile.a[i]];
                let keep = 1.0 - s[3];
                *px = std::array::from_fn(|k| s[k] + keep * px[k]);
            }
        });
        stats.tiles += started.elapsed();
        stats
    }
}

/// A stretch of a draw order: splats `ids` of the grid `source` (an index into the sources
/// given to [`TiledCompositor::composite_runs`]), back to front.
#[derive(Debug, Clone, Copy)]
pub struct Run<'a> {
    /// The grid the splats' ids are voxels of.
    pub source: usize,
    /// The splats, back to front.
    pub ids: &'a [u32],
}

/// What becomes of a group of splats (consecutive in the order) in a batch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Fate {
    /// The pixel rectangle that holds every footprint of the group lies off the image.
    OffImage,
    /// That rectangle holds opaque pixels alone.
    Hidden,
    /// Projected splat by splat.
    Project,
}

/// A group of splats' voxels, decoded once from their ids for the group's test, the
/// prefetch of its texels and its projection, and its [`Fate`].
struct Decoded {
    voxels: [[u32; 3]; GROUP],
    len: usize,
    fate: Fate,
}

impl Decoded {
    /// Group `ids` (at most [`GROUP`]) decoded, its rectangle tested when `cull` is on (its
    /// bounds cost less than a splat's own test; the order's rows make most groups short
    /// segments).
    #[inline]
    fn new(
        u: &SplatProjection,
        ids: &[u32],
        cull: bool,
        screen: &Screen,
        mask: Option<&OpaqueMask>,
    ) -> Self {
        let mut voxels = [[0; 3]; GROUP];
        let len = ids.len().min(GROUP);
        for (v, &id) in voxels.iter_mut().zip(ids) {
            *v = project::voxel(u, id);
        }
        let fate = match cull
            .then(|| group_rect(u, &voxels[..len], screen))
            .flatten()
        {
            Some([x0, y0, x1, y1]) if x0 > x1 || y0 > y1 => Fate::OffImage,
            Some(rect) if mask.is_some_and(|m| m.covers_rect(rect)) => Fate::Hidden,
            _ => Fate::Project,
        };
        Self { voxels, len, fate }
    }

    fn voxels(&self) -> &[[u32; 3]] {
        &self.voxels[..self.len]
    }
}

/// The image's size in pixels.
struct Screen {
    w: usize,
    h: usize,
}
