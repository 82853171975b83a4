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
//!
//! The pixel loop works on rows of 8 pixels held as planes. It is written twice: in plain
//! loops the compiler vectorises for the x86-64 baseline (SSE2) and any other processor, and
//! in AVX2 and FMA intrinsics, chosen at run time where the processor has them, since the
//! compiler neither fuses multiply-adds nor gathers lane masks well on its own (no `wide`: it
//! picks its instructions from the features the whole build targets, so it cannot follow a
//! choice made at run time). Projection runs 8 splats a vector in the AVX2
//! build too. rayon runs the chunks of a batch and the tiles in parallel. Every buffer lives in the
//! [`TiledCompositor`] and is reused from frame to frame; none grows with the volume past one
//! batch.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use glam::Vec3;
use rayon::prelude::*;
use strength_reduce::StrengthReducedU32;

use crate::classify::{Classified, refined_gradient_snorm8};
use crate::grid::SparseGrid;
use crate::volume::CpuVolume;

/// Tile side in pixels.
pub const TILE: usize = 16;
/// A pixel whose accumulated opacity reaches this takes no more splats; a tile whose pixels
/// all do stops.
pub const OPAQUE: f32 = 0.996;

/// One volume's splats for a frame, in the splat pass's terms (see `SplatUniforms` in
/// `src/render/splat_pass.rs`; this mirrors it on the CPU).
#[derive(Debug, Clone)]
pub struct SplatProjection {
    /// Rows of the index-offset to camera matrix (x right, y up, z forward).
    pub m: [Vec3; 3],
    /// The eye in voxel index coordinates.
    pub eye_index: Vec3,
    /// Splats nearer than this (perspective) are left out.
    pub near_cut: f32,
    /// Rows of the camera-space covariance of a splat.
    pub cov: [Vec3; 3],
    /// Image centre in pixels.
    pub centre: [f32; 2],
    /// Focal length in pixels (perspective), or pixels per world unit (orthographic).
    pub focal: f32,
    /// Screen-space variance added to every footprint.
    pub pixel_variance: f32,
    /// Cut-off of the Gaussian's exponent (radius^2 / sigma^2).
    pub cutoff: f32,
    /// Orthographic projection.
    pub orthographic: bool,
    /// Near plane (perspective depth scale; orthographic near) and far plane (orthographic).
    pub near: f32,
    /// Orthographic far plane.
    pub far: f32,
    /// Grid size.
    pub dims: [u32; 3],
    /// Voxels in a row (x) and in a plane (x y) of the grid, for dividing voxel ids.
    pub row: StrengthReducedU32,
    /// See `row`.
    pub plane: StrengthReducedU32,
    /// Rows of the index-space gradient to camera-space normal matrix.
    pub normal: [Vec3; 3],
    /// Shading strength (0 flat, 1 fully headlight-shaded).
    pub shading: f32,
    /// Clip planes in camera space: a splat is kept where `dot(xyz, p) <= w` for each.
    pub clip: Vec<[f32; 4]>,
    /// A splat's peak opacity in this view by the f16 bits of its density
    /// ([`alpha_table`]).
    pub alpha: std::sync::Arc<[f32]>,
}

impl SplatProjection {
    /// The peak opacity of the splat whose texel is `texel`.
    #[inline(always)]
    fn alpha_of(&self, texel: &[u8; 8]) -> f32 {
        let bits = u16::from_le_bytes([texel[6], texel[7]]);
        self.alpha.get(usize::from(bits)).copied().unwrap_or(0.0)
    }
}

/// The peak opacity of a splat by the f16 bits of its density (all 65,536 of them), in a view
/// whose index step spans `step_mm` millimetres: [`crate::classify::splat_alpha`] of each.
/// The last few views' tables are kept, so a frame does not remake its table (65,536
/// exponentials, about half a millisecond).
pub fn alpha_table(step_mm: f32) -> std::sync::Arc<[f32]> {
    use std::sync::{Arc, Mutex};
    static KEPT: Mutex<Vec<(u32, Arc<[f32]>)>> = Mutex::new(Vec::new());
    let key = step_mm.to_bits();
    if let Ok(kept) = KEPT.lock()
        && let Some((_, table)) = kept.iter().find(|(k, _)| *k == key)
    {
        return Arc::clone(table);
    }
    let table: Arc<[f32]> = (0..=u16::MAX)
        .map(|bits| {
            let density = half::f16::from_bits(bits).to_f32();
            // Negative or NaN densities (never written) stay transparent.
            crate::classify::splat_alpha(density, step_mm)
        })
        .collect();
    if let Ok(mut kept) = KEPT.lock() {
        if kept.len() >= 8 {
            kept.remove(0);
        }
        kept.push((key, Arc::clone(&table)));
    }
    table
}

/// A volume's splat data in 8 bytes a splat: straight RGB8 colour, the unit index-space
/// gradient as snorm8 (all zero where undefined), and the density as an f16 (see
/// [`crate::classify::SplatColor`]), for the significant voxels alone, stored brick by brick
/// (4x4x4 voxels).
///
/// Bricks, since the draw order runs along any axis: within a brick the next voxel along y or
/// z is as near as the next along x. Only significant voxels, since a frame reads the texel of
/// every splat it projects, and packed, the texels of neighbouring splats share cache lines
/// (the engine's 1.05M voxels with opacity, of 8.4M, take 8 MB of texels and 2 MB of bricks
/// instead of 67 MB). A brick's significant voxels are a bit mask, and a voxel's texel is
/// found by counting the bits before its own.
#[derive(Debug, Clone, Default)]
pub struct SplatTexels {
    dims: [u32; 3],
    /// Bricks along x and y.
    bricks: [usize; 2],
    /// Per brick, x fastest.
    table: Vec<Brick>,
    texels: Vec<[u8; 8]>,
}

/// Which voxels of a brick have opacity, and where their texels start.
#[derive(Debug, Clone, Copy, Default)]
struct Brick {
    /// Bit `(z * 4 + y) * 4 + x` for voxel `(x, y, z)` of the brick.
    present: u64,
    /// The index in the texels of the brick's first voxel with opacity.
    first: u32,
}

/// Brick side in voxels.
const BRICK: usize = 4;

impl SplatTexels {
    /// The texels of a classified volume: its colours and densities, and the gradients of the
    /// volume it was classified from, on a grid `factors` times finer than the volume's
    /// ([`crate::classify::classify_refined`]; `[1, 1, 1]` for its own). Built brick by brick
    /// from the significant voxels; no buffer the size of the whole grid.
    pub fn new(classified: &Classified, volume: &CpuVolume, factors: [u32; 3]) -> Self {
        Self::build(&classified.grid, |k, rank| {
            texel(volume, factors, classified, k, rank)
        })
    }

    /// The texels of `grid`'s voxels, each given by `texel(voxel, rank)`.
    pub fn build(grid: &SparseGrid, texel: impl Fn([u32; 3], usize) -> [u8; 8] + Sync) -> Self {
        let dims = grid.dims();
        let [nx, ny, nz] = dims.map(|n| n as usize);
        let bricks = [nx.div_ceil(BRICK), ny.div_ceil(BRICK)];
        let layer = bricks[0] * bricks[1];
        let layers = nz.div_ceil(BRICK);
        if layer == 0 || layers == 0 {
            return Self::default();
        }
        // Which voxels are significant, a layer of bricks (four z-slices) a task, from the
        // grid's x rows.
        let mut table = vec![Brick::default(); layer * layers];
        table
            .par_chunks_mut(layer)
            .enumerate()
            .for_each(|(bz, bricks_of_layer)| {
                for z in bz * BRICK..((bz + 1) * BRICK).min(nz) {
                    for y in 0..ny {
                        for run in grid.row(0, y as u32, z as u32) {
                            for x in run.start as usize..run.end() as usize {
                                let brick =
                                    &mut bricks_of_layer[(y / BRICK) * bricks[0] + x / BRICK];
                                brick.present |= 1 << within_brick(x, y, z);
                            }
                        }
                    }
                }
            });
        // Voxel ids are `u32`, so the count of significant voxels is too.
        let mut count = 0u32;
        for brick in &mut table {
            brick.first = count;
            count += brick.present.count_ones();
        }
        // The texels, brick by brick in the same layers: each layer's a contiguous stretch.
        let mut texels = vec![[0u8; 8]; count as usize];
        let mut stretches = Vec::with_capacity(layers);
        let mut rest = texels.as_mut_slice();
        for bz in 0..layers {
            let end = table.get((bz + 1) * layer).map_or(count, |b| b.first);
            let (stretch, tail) = rest.split_at_mut((end - table[bz * layer].first) as usize);
            stretches.push(stretch);
            rest = tail;
        }
        stretches
            .into_par_iter()
            .zip(table.par_chunks(layer))
            .enumerate()
            .for_each(|(bz, (stretch, bricks_of_layer))| {
                let mut slots = stretch.iter_mut();
                for (i, brick) in bricks_of_layer.iter().enumerate() {
                    let (bx, by) = (i % bricks[0], i / bricks[0]);
                    let mut bits = brick.present;
                    while bits != 0 {
                        let bit = bits.trailing_zeros() as usize;
                        bits &= bits - 1;
                        let x = bx * BRICK + bit % BRICK;
                        let y = by * BRICK + (bit / BRICK) % BRICK;
                        let z = bz * BRICK + bit / (BRICK * BRICK);
                        let k = [x, y, z].map(|c| c as u32);
                        let id = (x + nx * (y + ny * z)) as u32;
                        if let (Some(slot), Some(rank)) = (slots.next(), grid.rank(id)) {
                            *slot = texel(k, rank as usize);
                        }
                    }
                }
            });
        Self {
            dims,
            bricks,
            table,
            texels,
        }
    }

    /// The texel of voxel `(x, y, z)`: straight RGB8, the gradient as snorm8, the density's
    /// f16 bits (little-endian); `None` off the grid or where the voxel is not significant.
    #[inline]
    fn get(&self, x: u32, y: u32, z: u32) -> Option<&[u8; 8]> {
        let [nx, ny, nz] = self.dims;
        if x >= nx || y >= ny || z >= nz {
            return None;
        }
        let [x, y, z] = [x, y, z].map(|v| v as usize);
        let brick = ((z / BRICK) * self.bricks[1] + y / BRICK) * self.bricks[0] + x / BRICK;
        let brick = self.table.get(brick)?;
        let bit = within_brick(x, y, z);
        if brick.present >> bit & 1 == 0 {
            return None;
        }
        let before = (brick.present & ((1u64 << bit) - 1)).count_ones();
        self.texels.get((brick.first + before) as usize)
    }
}

/// The 8-byte texel of significant voxel `k` (rank `rank`) of a classified volume, its grid
/// `factors` times finer than `volume`'s: straight RGB8, the gradient of `volume` there as
/// snorm8 (zero where undefined), the density's f16 bits little-endian. The GPU's splat pass
/// reads the same bytes as two `u32`.
pub fn texel(
    volume: &CpuVolume,
    factors: [u32; 3],
    classified: &Classified,
    k: [u32; 3],
    rank: usize,
) -> [u8; 8] {
    let c = classified.colors.get(rank).copied().unwrap_or_default();
    let n = refined_gradient_snorm8(volume, factors, k).unwrap_or([0; 3]);
    let d = c.density.to_bits().to_le_bytes();
    [c.rgb[0], c.rgb[1], c.rgb[2], n[0], n[1], n[2], d[0], d[1]]
}

/// The bit of voxel `(x, y, z)` in its brick's mask.
#[inline(always)]
fn within_brick(x: usize, y: usize, z: usize) -> usize {
    ((z % BRICK) * BRICK + y % BRICK) * BRICK + x % BRICK
}

/// A splat projected to the screen.
#[derive(Debug, Clone, Copy, Default)]
struct Projected {
    centre: [f32; 2],
    /// Inverse screen covariance: `q = a dx^2 + 2 b dx dy + c dy^2`.
    conic: [f32; 3],
    /// Premultiplied colour.
    color: [f32; 4],
    /// Reversed depth, compared with the mesh depth as the GPU's depth test does.
    depth: f32,
    cutoff: f32,
    /// Covered pixel rectangle, inclusive (`x0 > x1` for a splat that is left out).
    x0: i32,
    y0: i32,
    x1: i32,
    y1: i32,
}

impl Projected {
    /// A splat left out.
    const NONE: Self = Self {
        centre: [0.0; 2],
        conic: [0.0; 3],
        color: [0.0; 4],
        depth: 0.0,
        cutoff: 0.0,
        x0: 1,
        y0: 0,
        x1: 0,
        y1: 0,
    };
}

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
}

/// The tile lists of one chunk of a batch: `entries[starts[t]..starts[t + 1]]` are the chunk's
/// splats touching tile `t`, in draw order.
#[derive(Debug, Default)]
struct ChunkBins {
    starts: Vec<u32>,
    entries: Vec<u32>,
    next: Vec<u32>,
    /// Splats of the chunk that landed on the image.
    projected: usize,
}

/// Pixels in a tile.
const PIXELS: usize = TILE * TILE;
/// A plane of a tile's pixels, with room for a group of lanes starting at the last pixel
/// (lanes past a row's end fall on the next row, or here, and are never open).
const PLANE: usize = PIXELS + LANES;

/// One tile's pixels as planes (premultiplied red, green, blue, alpha, and the meshes' reversed
/// depth), so that a row of pixels is a few vector registers.
#[derive(Debug, Clone)]
struct TilePixels {
    r: [f32; PLANE],
    g: [f32; PLANE],
    b: [f32; PLANE],
    a: [f32; PLANE],
    depth: [f32; PLANE],
    /// Per row, a bit for each pixel of the image not yet opaque.
    rows: [u16; TILE],
    /// Pixels of the image in the tile not yet opaque.
    open: u32,
    composited: usize,
    skipped: usize,
}

impl Default for TilePixels {
    fn default() -> Self {
        Self {
            r: [0.0; PLANE],
            g: [0.0; PLANE],
            b: [0.0; PLANE],
            a: [0.0; PLANE],
            depth: [0.0; PLANE],
            rows: [0; TILE],
            open: 0,
            composited: 0,
            skipped: 0,
        }
    }
}

/// The compositor, with its buffers kept between frames.
#[derive(Debug)]
pub struct TiledCompositor {
    /// The accumulated opacity past which a pixel takes no more splats ([`OPAQUE`] by
    /// default; above 1 no pixel and no tile ever stops).
    pub opaque: f32,
    /// Leave out, before projecting them, splats whose footprint covers opaque pixels alone
    /// (on by default; the image is the same either way, see [`TiledCompositor::composite`]).
    pub cull_hidden: bool,
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
        let (w, h) = (size.0 as usize, size.1 as usize);
        let (tx, ty) = (w.div_ceil(TILE), h.div_ceil(TILE));
        let mut stats = TileStats {
            splats: volumes.iter().map(|(_, _, ids)| ids.len()).sum(),
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
        // Nearest first: the volumes near to far, each one's order from its end.
        let mut batch = FIRST_BATCH;
        'volumes: for (v, (projection, texels, ids)) in volumes.iter().enumerate().rev() {
            let mut end = ids.len();
            while end > 0 {
                let begin = end.saturating_sub(batch);
                let ids = &ids[begin..end];
                end = begin;
                batch = (batch * 2).min(MAX_BATCH);
                if open_pixels == 0 && self.cull_hidden {
                    // Every tile is opaque: nothing further can show.
                    let farther: usize = volumes[..v].iter().map(|(_, _, ids)| ids.len()).sum();
                    stats.culled += ids.len() + end + farther;
                    break 'volumes;
                }
                let chunk = (ids.len() / 4).clamp(2048, 1 << 15);
                let chunks = ids.len().div_ceil(chunk);
                // Project and bin each chunk (one task: no wait in between), keeping the order
                // within each tile.
                let started = std::time::Instant::now();
                if self.projected.len() < ids.len() {
                    self.projected.resize(ids.len(), Projected::default());
                }
                if self.bins.len() < chunks {
                    self.bins.resize_with(chunks, ChunkBins::default);
                }
                if self.drew.len() < ids.len() {
                    self.drew.resize_with(ids.len(), AtomicBool::default);
                }
                // No test while no pixel is opaque.
                let mask = (self.cull_hidden && open_pixels < w * h).then_some(&self.mask);
                let (culled, project_time, bin_time) = self.projected[..ids.len()]
                    .par_chunks_mut(chunk)
                    .zip(ids.par_chunks(chunk))
                    .zip(self.bins[..chunks].par_iter_mut())
                    .enumerate()
                    .map(|(c, ((out, ids), bins))| {
                        let started = std::time::Instant::now();
                        let mut culled = 0;
                        let group = Group {
                            u: projection,
                            texels,
                            screen: &screen,
                            mask,
                        };
                        // The chunk's splats on the image, in order, packed at the front of
                        // its share of the buffer.
                        let mut kept = 0;
                        for ids in ids.chunks(GROUP) {
                            if let Some(mask) = mask
                                && group_hidden(projection, ids, &screen, mask)
                            {
                                culled += ids.len();
                                continue;
                            }
                            let (hidden, placed) = group.project(ids, &mut out[kept..]);
                            culled += hidden;
                            kept += placed;
                        }
                        let projected = started.elapsed();
                        bin_chunk(&out[..kept], (c * chunk) as u32, tx, ty, bins);
                        (culled, projected, started.elapsed() - projected)
                    })
                    .reduce(
                        || (0, Duration::ZERO, Duration::ZERO),
                        |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2),
                    );
                // The phase's time, shared between its two stages as their processor time.
                let wall = started.elapsed().as_secs_f64();
                let share = project_time.as_secs_f64()
                    / (project_time + bin_time)
                        .as_secs_f64()
                        .max(f64::MIN_POSITIVE);
                stats.project += Duration::from_secs_f64(wall * share);
                stats.bin += Duration::from_secs_f64(wall * (1.0 - share));
                stats.culled += culled;
                stats.projected += self.bins[..chunks]
                    .iter()
                    .map(|b| b.projected)
                    .sum::<usize>();
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
                    tile.composite(t, origin, batch);
                });
                for (t, tile) in self.tiles.iter().enumerate() {
                    self.mask
                        .set_tile((t % tx) * TILE, (t / tx) * TILE, &tile.rows);
                }
                // Counted and cleared through `&mut`: plain loads and stores, no locked
                // instruction per splat.
                stats.drew += self.drew[..ids.len()]
                    .iter_mut()
                    .map(|d| usize::from(std::mem::take(d.get_mut())))
                    .sum::<usize>();
                open_pixels = self.tiles.iter().map(|t| t.open as usize).sum();
                stats.tiles += started.elapsed();
            }
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

/// The voxel `(x, y, z)` of id `id`, by divisions by the grid's row and plane sizes done as
/// multiplications (the hardware divide was a fifth of the projection's time).
#[inline(always)]
fn voxel(u: &SplatProjection, id: u32) -> [u32; 3] {
    let z = id / u.plane;
    let rest = id - z * u.plane.get();
    let y = rest / u.row;
    [rest - y * u.row.get(), y, z]
}

/// The image's size in pixels.
struct Screen {
    w: usize,
    h: usize,
}

/// Which pixels of the image are opaque, a bit each, in rows of 64-pixel words: splats are
/// tested against it before they are projected. A pixel each, not a tile or a square of
/// pixels, since along a silhouette and round a thin bone's open pixels whole squares never
/// turn opaque while most of their pixels do.
#[derive(Debug, Default)]
struct OpaqueMask {
    /// Words in a row of the image.
    words: usize,
    /// Bit `x % 64` of word `y * words + x / 64` for pixel `(x, y)`, set where opaque.
    bits: Vec<u64>,
}

impl OpaqueMask {
    /// No pixel of a `w` by `h` image opaque.
    fn reset(&mut self, w: usize, h: usize) {
        self.words = w.div_ceil(64);
        self.bits.clear();
        self.bits.resize(self.words * h, 0);
    }

    /// Takes the opaque pixels of the tile whose top-left pixel is `(x0, y0)` from its rows
    /// of open pixels (rows and columns past the image's edges are never read).
    fn set_tile(&mut self, x0: usize, y0: usize, rows: &[u16; TILE]) {
        let (word, shift) = (x0 / 64, x0 % 64);
        for (ly, &open) in rows.iter().enumerate() {
            if let Some(bits) = self.bits.get_mut((y0 + ly) * self.words + word) {
                *bits = (*bits & !(0xffff << shift)) | u64::from(!open) << shift;
            }
        }
    }

    /// Whether every pixel from `(x0, y0)` to `(x1, y1)` (inclusive, on the image, `x0 <= x1`,
    /// `y0 <= y1`) is opaque.
    #[inline(always)]
    fn covers(&self, x0: usize, x1: usize, y0: usize, y1: usize) -> bool {
        let (w0, w1) = (x0 / 64, x1 / 64);
        let first = u64::MAX << (x0 % 64);
        let last = u64::MAX >> (63 - x1 % 64);
        let Some(rows) = self.bits.get(y0 * self.words..(y1 + 1) * self.words) else {
            return false;
        };
        if w1 >= self.words {
            return false;
        }
        let mut rows = rows.chunks_exact(self.words);
        if w0 == w1 {
            let span = first & last;
            rows.all(|row| row[w0] & span == span)
        } else {
            rows.all(|row| {
                row[w0] & first == first
                    && row[w1] & last == last
                    && row[w0 + 1..w1].iter().all(|&b| b == u64::MAX)
            })
        }
    }

    /// [`OpaqueMask::covers`] for a splat's pixel rectangle as [`Projected`] holds it.
    #[inline(always)]
    fn covers_rect(&self, [x0, y0, x1, y1]: [i32; 4]) -> bool {
        x0 <= x1 && y0 <= y1 && x0 >= 0 && y0 >= 0 && {
            let [x0, y0, x1, y1] = [x0, y0, x1, y1].map(|v| v as usize);
            self.covers(x0, x1, y0, y1)
        }
    }
}

/// What projecting a stretch of one volume's draw order takes.
#[derive(Clone, Copy)]
struct Group<'a> {
    u: &'a SplatProjection,
    texels: &'a SplatTexels,
    screen: &'a Screen,
    /// The pixels opaque before this batch (`None` while none is).
    mask: Option<&'a OpaqueMask>,
}

impl Group<'_> {
    /// Projects the splats `ids`, writing those that land on the image, in order, to the
    /// front of `out` (at least as long as `ids`): neither the splats left out nor their
    /// places are written, read or binned. Returns how many were left out as hidden behind
    /// opaque pixels, and how many were written. Eight at a time in AVX2 vectors where the
    /// processor has them.
    fn project(&self, ids: &[u32], out: &mut [Projected]) -> (usize, usize) {
        #[cfg(target_arch = "x86_64")]
        if has_avx2() {
            let (mut culled, mut kept) = (0, 0);
            for ids in ids.chunks(LANES) {
                #[allow(unsafe_code)]
                // SAFETY: the processor has the features the function is built for, checked
                // above.
                let (hidden, placed) = unsafe { avx2::project(self, ids, &mut out[kept..]) };
                culled += hidden;
                kept += placed;
            }
            return (culled, kept);
        }
        self.project_each(ids, out)
    }

    /// [`Group::project`] a splat at a time.
    fn project_each(&self, ids: &[u32], out: &mut [Projected]) -> (usize, usize) {
        let (w, h) = (self.screen.w as i32, self.screen.h as i32);
        let (mut culled, mut kept) = (0, 0);
        for &id in ids {
            let [x, y, z] = voxel(self.u, id);
            let centre = camera_centre(self.u, [x, y, z]);
            let Some(at) = place(self.u, centre, w, h) else {
                continue;
            };
            if self.mask.is_some_and(|m| m.covers_rect(at.rect)) {
                culled += 1;
                continue;
            }
            let p = project(self.u, self.texels, [x, y, z], centre, &at);
            if p.x0 <= p.x1 {
                out[kept] = p;
                kept += 1;
            }
        }
        (culled, kept)
    }
}

/// Whether every splat of `ids` (a stretch of the draw order) is hidden behind the opaque
/// pixels `mask`: the pixel rectangle that holds every one of their footprints, as
/// [`place`] would give them, lies on opaque pixels alone. Decoding a voxel id and taking the
/// box's bounds costs less than a splat's own test; the order's rows make most stretches short
/// segments.
///
/// The rectangle: the voxels' box projected (its corners' centres bound every centre in it,
/// and its corners' slopes `x / z` and `y / z` every slope, a linear-fractional function
/// taking its extremes at a convex set's vertices), grown by the largest quad half extent
/// `radius sqrt(a) + 1/2` of a splat in the box. The screen variance
/// `a = (f / z)^2 (S00 - 2 S02 s + S22 s^2) + pixel variance` is largest at the nearest depth
/// and, convex in the slope `s`, at one of the slope's bounds (likewise `c` with `S11`, `S12`
/// and the slope `y / z`; orthographic, both are constant).
fn group_hidden(u: &SplatProjection, ids: &[u32], s: &Screen, mask: &OpaqueMask) -> bool {
    group_rect(u, ids, s).is_some_and(|rect| mask.covers_rect(rect))
}

/// The pixel rectangle `[x0, y0, x1, y1]` of [`group_hidden`]; `None` where it cannot be
/// bounded (a splat behind the near cut, no splat, NaN).
fn group_rect(u: &SplatProjection, ids: &[u32], s: &Screen) -> Option<[i32; 4]> {
    let (mut lo, mut hi) = ([u32::MAX; 3], [0u32; 3]);
    for &id in ids {
        let [x, y, z] = voxel(u, id);
        lo = [lo[0].min(x), lo[1].min(y), lo[2].min(z)];
        hi = [hi[0].max(x), hi[1].max(y), hi[2].max(z)];
    }
    if ids.is_empty() {
        return None;
    }
    let (mut left, mut right, mut top, mut bottom) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
    let (mut sx, mut sy) = ([f32::MAX, f32::MIN], [f32::MAX, f32::MIN]);
    let mut nearest = f32::MAX;
    let f = u.focal;
    for corner in 0..8 {
        let pick = |axis: usize| {
            if corner >> axis & 1 == 0 {
                lo[axis]
            } else {
                hi[axis]
            }
        };
        let p = camera_centre(u, [pick(0), pick(1), pick(2)]);
        let (centre, slope) = if u.orthographic {
            if p.z <= u.near {
                return None;
            }
            ([u.centre[0] + f * p.x, u.centre[1] - f * p.y], [0.0; 2])
        } else {
            if p.z <= u.near_cut {
                return None;
            }
            let iz = 1.0 / p.z;
            let slope = [p.x * iz, p.y * iz];
            (
                [u.centre[0] + f * slope[0], u.centre[1] - f * slope[1]],
                slope,
            )
        };
        nearest = nearest.min(p.z);
        left = left.min(centre[0]);
        right = right.max(centre[0]);
        top = top.min(centre[1]);
        bottom = bottom.max(centre[1]);
        sx = [sx[0].min(slope[0]), sx[1].max(slope[0])];
        sy = [sy[0].min(slope[1]), sy[1].max(slope[1])];
    }
    let scale = if u.orthographic { f } else { f / nearest };
    let variance = |diagonal: f32, cross: f32, [s0, s1]: [f32; 2]| {
        let q = |s: f32| diagonal - 2.0 * cross * s + u.cov[2][2] * s * s;
        scale * scale * q(s0).max(q(s1)) + u.pixel_variance
    };
    let radius = u.cutoff.sqrt();
    // A hundredth of a pixel more, against rounding that differs from `place`'s.
    let reach = |v: f32| radius * v.sqrt() * 1.0001 + 0.51;
    let (ex, ey) = (
        reach(variance(u.cov[0][0], u.cov[0][2], sx)),
        reach(variance(u.cov[1][1], u.cov[1][2], sy)),
    );
    if !(ex.is_finite() && ey.is_finite()) {
        return None;
    }
    let (w, h) = (s.w as i32, s.h as i32);
    let lim = |v: f32, hi: i32| v.clamp(-1.0, hi as f32 + 1.0);
    let x0 = ceil(lim(left - ex - 0.5, w)).max(0);
    let x1 = floor(lim(right + ex - 0.5, w)).min(w - 1);
    let y0 = ceil(lim(top - ey - 0.5, h)).max(0);
    let y1 = floor(lim(bottom + ey - 0.5, h)).min(h - 1);
    Some([x0, y0, x1, y1])
}

/// The camera-space centre of voxel `k`.
#[inline(always)]
fn camera_centre(u: &SplatProjection, k: [u32; 3]) -> Vec3 {
    let d = Vec3::new(k[0] as f32, k[1] as f32, k[2] as f32) - u.eye_index;
    Vec3::new(u.m[0].dot(d), u.m[1].dot(d), u.m[2].dot(d))
}

/// Where a splat falls on the screen, as the splat pass's vertex shader places it: all that
/// its camera-space centre decides, before its texel is read.
struct Placement {
    centre: [f32; 2],
    /// Reversed depth.
    depth: f32,
    /// The screen covariance `[[a, b], [b, c]]`, the pixel variance added.
    a: f32,
    b: f32,
    c: f32,
    /// Covered pixel rectangle, inclusive: `[x0, y0, x1, y1]`.
    rect: [i32; 4],
}

/// The placement of a splat centred at `p` (camera space) on a `w` by `h` image; `None` where
/// the splat pass leaves it out: behind the near cut, a footprint that is not an ellipse, or
/// no pixel centre inside its quad.
fn place(u: &SplatProjection, p: Vec3, w: i32, h: i32) -> Option<Placement> {
    let f = u.focal;
    let (j0, j1, centre, depth) = if u.orthographic {
        if p.z <= u.near {
            return None;
        }
        let z = ((u.far - p.z) / (u.far - u.near)).clamp(0.0, 1.0);
        (
            Vec3::new(f, 0.0, 0.0),
            Vec3::new(0.0, -f, 0.0),
            [u.centre[0] + f * p.x, u.centre[1] - f * p.y],
            z,
        )
    } else {
        if p.z <= u.near_cut {
            return None;
        }
        let iz = 1.0 / p.z;
        (
            Vec3::new(f * iz, 0.0, -f * p.x * iz * iz),
            Vec3::new(0.0, -f * iz, f * p.y * iz * iz),
            [u.centre[0] + f * p.x * iz, u.centre[1] - f * p.y * iz],
            u.near * iz,
        )
    };
    let cov = |v: Vec3| Vec3::new(u.cov[0].dot(v), u.cov[1].dot(v), u.cov[2].dot(v));
    let a = j0.dot(cov(j0)) + u.pixel_variance;
    let b = j0.dot(cov(j1));
    let c = j1.dot(cov(j1)) + u.pixel_variance;
    // Also refuses a NaN determinant.
    if (a * c - b * b).partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    // The quad of the vertex shader: +-(radius sqrt(a) + 0.5) by +-(radius sqrt(c) + 0.5);
    // the pixels whose centres it holds.
    let radius = u.cutoff.sqrt();
    let (ex, ey) = (radius * a.sqrt() + 0.5, radius * c.sqrt() + 0.5);
    // The first and last pixel centres inside the quad, clamped to the image.
    let lim = |v: f32, hi: i32| v.clamp(-1.0, hi as f32 + 1.0);
    let x0 = ceil(lim(centre[0] - ex - 0.5, w)).max(0);
    let x1 = floor(lim(centre[0] + ex - 0.5, w)).min(w - 1);
    let y0 = ceil(lim(centre[1] - ey - 0.5, h)).max(0);
    let y1 = floor(lim(centre[1] + ey - 0.5, h)).min(h - 1);
    (x0 <= x1 && y0 <= y1).then_some(Placement {
        centre,
        depth,
        a,
        b,
        c,
        rect: [x0, y0, x1, y1],
    })
}

/// A splat on the screen, as the splat pass's vertex shader places and colours it, from its
/// voxel, camera-space centre `p` and placement; a splat left out (no texel, no opacity,
/// clipped) gets an empty rectangle.
fn project(
    u: &SplatProjection,
    texels: &SplatTexels,
    [x, y, z]: [u32; 3],
    p: Vec3,
    at: &Placement,
) -> Projected {
    let none = Projected::NONE;
    let Some(texel) = texels.get(x, y, z) else {
        return none;
    };
    let peak = u.alpha_of(texel);
    if peak <= 0.0 {
        return none;
    }
    if u.clip
        .iter()
        .any(|c| Vec3::new(c[0], c[1], c[2]).dot(p) > c[3])
    {
        return none;
    }
    let mut rgb = [texel[0], texel[1], texel[2]].map(|v| f32::from(v) / 255.0);
    let g = [3, 4, 5].map(|i| f32::from(texel[i] as i8));
    if u.shading > 0.0 && g != [0.0; 3] {
        let g = Vec3::from(g) / 127.0;
        let n = Vec3::new(u.normal[0].dot(g), u.normal[1].dot(g), u.normal[2].dot(g));
        let lambert = n.normalize_or_zero().z.abs();
        let scale = 1.0 - u.shading + u.shading * lambert;
        rgb = rgb.map(|v| v * scale);
    }
    let alpha = peak * kept_integral(at.a, at.b, at.c, u.pixel_variance);
    let inv_det = 1.0 / (at.a * at.c - at.b * at.b);
    let [x0, y0, x1, y1] = at.rect;
    Projected {
        centre: at.centre,
        conic: [at.c * inv_det, -at.b * inv_det, at.a * inv_det],
        color: [rgb[0] * alpha, rgb[1] * alpha, rgb[2] * alpha, alpha],
        depth: at.depth,
        cutoff: u.cutoff,
        x0,
        y0,
        x1,
        y1,
    }
}

/// The share of a splat's opacity a footprint widened by the pixel variance keeps, so that its
/// integral over the image stays that of the unwidened footprint (Mip-Splatting's 2-D
/// filter: `sqrt(det S / det(S + v I))` for the screen covariance `S` and pixel variance `v`;
/// Yu et al. 2024, eq. 8): a splat smaller than a pixel covers a pixel with the opacity it
/// would have spread over its own area, instead of the full opacity. `a`, `b` and `c` are the
/// widened covariance's entries.
#[inline(always)]
fn kept_integral(a: f32, b: f32, c: f32, v: f32) -> f32 {
    let wide = a * c - b * b;
    let own = (a - v) * (c - v) - b * b;
    if own > 0.0 && wide > 0.0 {
        (own / wide).sqrt().min(1.0)
    } else {
        0.0
    }
}

/// `v.floor()` for values well inside `i32`'s range, without the library call that
/// `f32::floor` is on x86-64 before SSE 4.1 (a fifth of the projection's time).
fn floor(v: f32) -> i32 {
    let i = v as i32;
    if (i as f32) > v { i - 1 } else { i }
}

/// `v.ceil()`, as [`floor`].
fn ceil(v: f32) -> i32 {
    let i = v as i32;
    if (i as f32) < v { i + 1 } else { i }
}

/// Counts, then lists, the tiles each splat of a chunk touches (a counting sort by tile, which
/// keeps the draw order within every tile). `splats` are those of the chunk that landed on the
/// image, as [`Group::project`] packs them; `first` is the index of the first.
fn bin_chunk(splats: &[Projected], first: u32, tx: usize, ty: usize, bins: &mut ChunkBins) {
    let tiles = tx * ty;
    bins.starts.clear();
    bins.starts.resize(tiles + 1, 0);
    let range = |p: &Projected| {
        let t = TILE as i32;
        (p.x0 / t, p.x1 / t, p.y0 / t, p.y1 / t)
    };
    bins.projected = splats.len();
    for p in splats {
        let (a, b, c, d) = range(p);
        for y in c..=d {
            for x in a..=b {
                bins.starts[y as usize * tx + x as usize + 1] += 1;
            }
        }
    }
    for t in 0..tiles {
        bins.starts[t + 1] += bins.starts[t];
    }
    bins.entries.clear();
    bins.entries.resize(bins.starts[tiles] as usize, 0);
    bins.next.clear();
    bins.next.extend_from_slice(&bins.starts[..tiles]);
    for (i, p) in splats.iter().enumerate() {
        let (a, b, c, d) = range(p);
        for y in c..=d {
            for x in a..=b {
                let slot = &mut bins.next[y as usize * tx + x as usize];
                bins.entries[*slot as usize] = first + i as u32;
                *slot += 1;
            }
        }
    }
}

impl TilePixels {
    /// Starts a frame: transparent, the meshes' depth (none where `depth` is all 0), and every
    /// pixel of the image open.
    fn reset(&mut self, x0: usize, y0: usize, (w, h): (usize, usize), depth: &[f32]) {
        self.r = [0.0; PLANE];
        self.g = [0.0; PLANE];
        self.b = [0.0; PLANE];
        self.a = [0.0; PLANE];
        self.depth = [0.0; PLANE];
        self.composited = 0;
        self.skipped = 0;
        let (x1, y1) = ((x0 + TILE).min(w), (y0 + TILE).min(h));
        self.open = ((x1 - x0) * (y1 - y0)) as u32;
        let row = u16::MAX >> (TILE - (x1 - x0));
        for (ly, bits) in self.rows.iter_mut().enumerate() {
            *bits = if y0 + ly < y1 { row } else { 0 };
        }
        for y in y0..y1 {
            if let Some(d) = depth.get(y * w + x0..y * w + x1) {
                let at = (y - y0) * TILE;
                self.depth[at..at + (x1 - x0)].copy_from_slice(d);
            }
        }
    }

    /// The planes' [`LANES`] values from pixel `at` on (`None` past the planes' ends).
    #[inline(always)]
    fn lanes(&mut self, at: usize) -> Option<Lanes<'_>> {
        let end = at.checked_add(LANES)?;
        Some(Lanes {
            r: self.r.get_mut(at..end)?.try_into().ok()?,
            g: self.g.get_mut(at..end)?.try_into().ok()?,
            b: self.b.get_mut(at..end)?.try_into().ok()?,
            a: self.a.get_mut(at..end)?.try_into().ok()?,
            depth: self.depth.get(at..end)?.try_into().ok()?,
        })
    }

    /// Composites this batch's splats touching tile `t` (its top-left pixel at `origin`),
    /// nearest first, under what the tile holds: 8 lanes wide where the processor has AVX2
    /// and FMA.
    fn composite(&mut self, t: usize, origin: (usize, usize), batch: Batch<'_>) {
        #[cfg(target_arch = "x86_64")]
        if has_avx2() {
            #[allow(unsafe_code)]
            // SAFETY: the processor has the features the function is built for, checked above.
            return unsafe { avx2::composite_tile(self, t, origin, batch) };
        }
        composite_tile_lanes(self, t, origin, batch, composite_splat_lanes);
    }
}

/// A group of [`LANES`] pixels of a tile, plane by plane.
struct Lanes<'a> {
    r: &'a mut [f32; LANES],
    g: &'a mut [f32; LANES],
    b: &'a mut [f32; LANES],
    a: &'a mut [f32; LANES],
    depth: &'a [f32; LANES],
}

/// What every tile takes from a batch: its projected splats, their tile lists and the
/// opacity that stops a pixel.
#[derive(Clone, Copy)]
struct Batch<'a> {
    projected: &'a [Projected],
    bins: &'a [ChunkBins],
    opaque: f32,
    /// Per splat of `projected`, set once it reaches an open pixel.
    drew: &'a [AtomicBool],
}

/// [`TilePixels::composite`], with the pixel loop `splat` inlined: it composites one splat
/// under a tile's pixels (its top-left pixel at the origin given) and returns how many pixels
/// turned opaque.
#[inline(always)]
fn composite_tile_lanes(
    tile: &mut TilePixels,
    t: usize,
    origin: (usize, usize),
    batch: Batch<'_>,
    splat: impl Fn(&mut TilePixels, (usize, usize), &Projected, TileRect, f32) -> u32,
) {
    let Batch {
        projected,
        bins,
        opaque,
        drew,
    } = batch;
    let lists = bins.iter().rev().map(|b| {
        let (s, e) = (b.starts[t] as usize, b.starts[t + 1] as usize);
        &b.entries[s..e]
    });
    for list in lists {
        let mut splats = list.iter().rev();
        for &i in splats.by_ref() {
            if tile.open == 0 {
                tile.skipped += 1;
                break;
            }
            let p = &projected[i as usize];
            // The splat's rows in the tile from the first with an open pixel under it; none,
            // and it takes nothing.
            let rows = splat_rect(origin, p).and_then(|(lx0, lx1, ly0, ly1, span)| {
                let first = (ly0..=ly1).find(|&ly| tile.rows[ly] & span != 0)?;
                Some((lx0, lx1, first, ly1, span))
            });
            let Some(rows) = rows else {
                tile.skipped += 1;
                continue;
            };
            tile.composited += 1;
            drew[i as usize].store(true, Ordering::Relaxed);
            tile.open -= splat(tile, origin, p, rows, opaque);
        }
        tile.skipped += splats.len();
    }
}

/// The environment variable that, set to `off`, keeps the tile compositor on its portable
/// loops on any processor, so that they are tested where AVX2 is there too (CI runs the image
/// tests both ways). Read once a process.
pub const SIMD_VAR: &str = "SPLATSCENE_SIMD";

/// Whether [`avx2`]'s code runs: the processor has it and [`SIMD_VAR`] does not turn it off.
#[cfg(target_arch = "x86_64")]
fn has_avx2() -> bool {
    static USE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *USE.get_or_init(|| {
        let wanted = match std::env::var(SIMD_VAR).as_deref() {
            Ok("off") => false,
            Ok("on") | Err(_) => true,
            Ok(other) => {
                eprintln!("warning: {SIMD_VAR}={other:?} has no effect: give off or on");
                true
            }
        };
        wanted
            && std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
            && std::arch::is_x86_feature_detected!("popcnt")
    })
}

/// Lanes of the pixel loop: a group of pixels along a row, starting where a footprint does.
const LANES: usize = 8;

/// The part of a splat's pixel rectangle in a tile: its first and last columns, its first and
/// last rows, and a row mask of its columns.
type TileRect = (usize, usize, usize, usize, u16);

/// The part of a splat's pixel rectangle in the tile at `origin`; `None` where they do not
/// meet.
#[inline(always)]
fn splat_rect(origin: (usize, usize), p: &Projected) -> Option<TileRect> {
    let (ox, oy) = (origin.0 as i32, origin.1 as i32);
    let (lx0, lx1) = ((p.x0 - ox).max(0), (p.x1 - ox).min(TILE as i32 - 1));
    let (ly0, ly1) = ((p.y0 - oy).max(0), (p.y1 - oy).min(TILE as i32 - 1));
    if lx0 > lx1 || ly0 > ly1 {
        return None;
    }
    let [lx0, lx1, ly0, ly1] = [lx0, lx1, ly0, ly1].map(|v| v as usize);
    Some((
        lx0,
        lx1,
        ly0,
        ly1,
        (u16::MAX >> (TILE - 1 - (lx1 - lx0))) << lx0,
    ))
}

/// Composites one splat under the tile's pixels; returns how many pixels turned opaque.
///
/// Plain loops over groups of [`LANES`] pixels, with no branch and no library call inside
/// (`exp` is [`exp_neg`]), which the compiler turns into vector instructions, 4 lanes wide
/// with the x86-64 baseline (SSE2). Where the processor has AVX2 and FMA, [`avx2`] does the
/// same in 8 lanes (chosen at run time, see [`TilePixels::composite`]). Rows and groups whose pixels are all opaque are
/// skipped from the tile's row masks. Within a group a pixel is left alone where it is opaque,
/// the meshes are in front, or it lies past the footprint's cut-off; the footprint's quad
/// always holds its cut-off ellipse, so the quad's rectangle only chooses the rows and groups
/// walked.
fn composite_splat_lanes(
    tile: &mut TilePixels,
    origin: (usize, usize),
    p: &Projected,
    (lx0, lx1, ly0, ly1, span): TileRect,
    opaque: f32,
) -> u32 {
    let dx0 = origin.0 as f32 + 0.5 - p.centre[0];
    let [ca, cb, cc] = p.conic;
    let (cutoff, depth) = (p.cutoff, p.depth);
    let [cr, cg, cbl, calpha] = p.color;
    let mut turned = 0u32;
    for ly in ly0..=ly1 {
        let open = tile.rows[ly] & span;
        if open == 0 {
            continue;
        }
        let dy = (origin.1 + ly) as f32 + 0.5 - p.centre[1];
        let (by, qy) = (2.0 * cb * dy, cc * dy * dy);
        // Groups start at the rectangle's left edge: most rows of a footprint fit in one.
        for start in (lx0..=lx1).step_by(LANES) {
            let lanes_open = (u32::from(open) >> start) & 0xff;
            if lanes_open == 0 {
                continue;
            }
            let Some(Lanes {
                r,
                g,
                b,
                a,
                depth: d,
            }) = tile.lanes(ly * TILE + start)
            else {
                continue;
            };
            let first = dx0 + start as f32;
            // Every lane computed, then masked: no branch, so the loops vectorise. (Plain
            // loops: `array::map` and `from_fn` are calls that are not built for AVX2.)
            let mut q = [0.0f32; LANES];
            for (l, q) in q.iter_mut().enumerate() {
                let dx = first + l as f32;
                *q = (ca * dx + by) * dx + qy;
            }
            let mut falloff = [0.0f32; LANES];
            for (e, &q) in falloff.iter_mut().zip(&q) {
                *e = exp_neg(0.5 * q);
            }
            let mut closing = 0u32;
            for l in 0..LANES {
                let alpha = a[l];
                let live = ((lanes_open >> l) & 1 != 0) & (q[l] <= cutoff) & (depth >= d[l]);
                let weight = if live {
                    (1.0 - alpha) * falloff[l]
                } else {
                    0.0
                };
                r[l] += weight * cr;
                g[l] += weight * cg;
                b[l] += weight * cbl;
                let after = alpha + weight * calpha;
                a[l] = after;
                closing |= u32::from(live & (after >= opaque)) << l;
            }
            tile.rows[ly] &= !((closing << start) as u16);
            turned += closing.count_ones();
        }
    }
    turned
}

/// `exp(-x)` for `x >= 0`, without a library call so that it vectorises: `2^n 2^f` with `n`
/// the nearest integer to `-x log2(e)` (by the 1.5 * 2^23 rounding trick) and
/// `2^f = e^(f ln 2)`, `|f ln 2| <= 0.35`, by its Taylor series to degree 6. The relative error
/// is below 8e-7 for `x` up to 8 (footprints use up to half their cut-off, 4.1 by default) and
/// grows with the rounding of `x log2(e)` to 5e-6 at 80. Below 2^-126 (`x` past 87) it gives
/// 2^-126.
#[inline(always)]
fn exp_neg(x: f32) -> f32 {
    const ROUND: f32 = 12_582_912.0;
    let t = (-x * std::f32::consts::LOG2_E).max(-126.0);
    let shifted = t + ROUND;
    let n = shifted.to_bits().wrapping_sub(ROUND.to_bits());
    let g = (t - (shifted - ROUND)) * std::f32::consts::LN_2;
    let poly = 1.0
        + g * (1.0
            + g * (1.0 / 2.0
                + g * (1.0 / 6.0 + g * (1.0 / 24.0 + g * (1.0 / 120.0 + g * (1.0 / 720.0))))));
    poly * f32::from_bits(n.wrapping_add(127) << 23)
}

/// The pixel loop written with AVX2 and FMA intrinsics, for processors that have them (see
/// [`has_avx2`]): the same arithmetic as [`composite_splat_lanes`], 8 lanes a vector, with
/// fused multiply-adds and the lanes that turn opaque read as one mask. (The plain loops
/// built for AVX2 gave neither: the compiler does not fuse `a * b + c` on its own, and it
/// gathered the lanes' bits with a dozen shuffles.)
#[cfg(target_arch = "x86_64")]
mod avx2 {
    use std::arch::x86_64::*;

    use super::{
        Batch, Group, LANES, Lanes, Projected, TILE, TilePixels, TileRect, composite_tile_lanes,
        voxel,
    };

    /// [`composite_tile_lanes`] with [`composite_splat`].
    ///
    /// # Safety
    ///
    /// The processor must have AVX2, FMA and POPCNT.
    #[target_feature(enable = "avx2,fma,popcnt")]
    #[allow(unsafe_code)]
    pub(super) unsafe fn composite_tile(
        tile: &mut TilePixels,
        t: usize,
        origin: (usize, usize),
        batch: Batch<'_>,
    ) {
        composite_tile_lanes(tile, t, origin, batch, |tile, origin, p, rect, opaque| {
            composite_splat(tile, origin, p, rect, opaque)
        });
    }

    /// [`super::composite_splat_lanes`] in AVX2 vectors.
    #[target_feature(enable = "avx2,fma,popcnt")]
    #[inline]
    fn composite_splat(
        tile: &mut TilePixels,
        origin: (usize, usize),
        p: &Projected,
        (lx0, lx1, ly0, ly1, span): TileRect,
        opaque: f32,
    ) -> u32 {
        let dx0 = origin.0 as f32 + 0.5 - p.centre[0];
        let [ca, cb, cc] = p.conic;
        let conic_a = _mm256_set1_ps(ca);
        let cutoff = _mm256_set1_ps(p.cutoff);
        let depth = _mm256_set1_ps(p.depth);
        let [cr, cg, cbl, calpha] = p.color.map(|c| _mm256_set1_ps(c));
        let opaque = _mm256_set1_ps(opaque);
        let one = _mm256_set1_ps(1.0);
        let iota = _mm256_setr_ps(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0);
        let bits = lane_bits();
        let mut turned = 0;
        for ly in ly0..=ly1 {
            let open = tile.rows[ly] & span;
            if open == 0 {
                continue;
            }
            let dy = (origin.1 + ly) as f32 + 0.5 - p.centre[1];
            let (by, qy) = (_mm256_set1_ps(2.0 * cb * dy), _mm256_set1_ps(cc * dy * dy));
            let mut closing = 0u32;
            for start in (lx0..=lx1).step_by(LANES) {
                let lanes_open = (u32::from(open) >> start) & 0xff;
                if lanes_open == 0 {
                    continue;
                }
                let Some(Lanes {
                    r,
                    g,
                    b,
                    a,
                    depth: d,
                }) = tile.lanes(ly * TILE + start)
                else {
                    continue;
                };
                let dx = _mm256_add_ps(_mm256_set1_ps(dx0 + start as f32), iota);
                let q = _mm256_fmadd_ps(_mm256_fmadd_ps(conic_a, dx, by), dx, qy);
                let falloff = exp_neg_half(q);
                let mask = _mm256_and_si256(_mm256_set1_epi32(lanes_open as i32), bits);
                let open = _mm256_castsi256_ps(_mm256_cmpeq_epi32(mask, bits));
                #[allow(unsafe_code)]
                // SAFETY: each plane's group is an array of LANES floats.
                unsafe {
                    let d = _mm256_loadu_ps(d.as_ptr());
                    let live = _mm256_and_ps(
                        _mm256_and_ps(open, _mm256_cmp_ps::<_CMP_LE_OQ>(q, cutoff)),
                        _mm256_cmp_ps::<_CMP_GE_OQ>(depth, d),
                    );
                    let alpha = _mm256_loadu_ps(a.as_ptr());
                    let weight =
                        _mm256_and_ps(live, _mm256_mul_ps(_mm256_sub_ps(one, alpha), falloff));
                    for (plane, c) in [(r, cr), (g, cg), (b, cbl)] {
                        let v = _mm256_fmadd_ps(weight, c, _mm256_loadu_ps(plane.as_ptr()));
                        _mm256_storeu_ps(plane.as_mut_ptr(), v);
                    }
                    let after = _mm256_fmadd_ps(weight, calpha, alpha);
                    _mm256_storeu_ps(a.as_mut_ptr(), after);
                    let done = _mm256_and_ps(live, _mm256_cmp_ps::<_CMP_GE_OQ>(after, opaque));
                    closing |= (_mm256_movemask_ps(done) as u32) << start;
                }
            }
            // Lanes past the row's end were never open: `closing` has no bit there.
            tile.rows[ly] &= !(closing as u16);
            turned += closing.count_ones();
        }
        turned
    }

    /// [`super::Group::project`] for up to [`LANES`] splats: [`super::project`] with the
    /// splats' arithmetic in vectors. Reading the voxels' ids and texels, testing the opaque pixels
    /// and writing the results stay a lane at a time.
    ///
    /// # Safety
    ///
    /// The processor must have AVX2, FMA and POPCNT.
    #[target_feature(enable = "avx2,fma,popcnt")]
    #[allow(unsafe_code)]
    pub(super) unsafe fn project(
        group: &Group<'_>,
        ids: &[u32],
        out: &mut [Projected],
    ) -> (usize, usize) {
        let n = ids.len().min(out.len()).min(LANES);
        if n == 0 {
            return (0, 0);
        }
        let u = group.u;
        let mut voxels = [[0u32; 3]; LANES];
        let mut k = [[0.0f32; LANES]; 3];
        for l in 0..LANES {
            // Lanes past the end repeat the last splat; their results are dropped.
            voxels[l] = voxel(u, ids[l.min(n - 1)]);
            for axis in 0..3 {
                k[axis][l] = voxels[l][axis] as f32;
            }
        }
        let splat = |v: f32| _mm256_set1_ps(v);
        let [kx, ky, kz] = k.map(|k| lanes(&k));
        let d = [
            _mm256_sub_ps(kx, splat(u.eye_index.x)),
            _mm256_sub_ps(ky, splat(u.eye_index.y)),
            _mm256_sub_ps(kz, splat(u.eye_index.z)),
        ];
        let [px, py, pz] = [0, 1, 2].map(|r| dot3(u.m[r], d));
        let f = splat(u.focal);
        // Perspective: f / z scales the centre and the Jacobian, whose third column is the
        // centre's slope; orthographic: f alone, and no slope.
        let (fiz, slope_x, slope_y, depth, front) = if u.orthographic {
            let depth = _mm256_div_ps(_mm256_sub_ps(splat(u.far), pz), splat(u.far - u.near));
            let depth = _mm256_min_ps(_mm256_max_ps(depth, splat(0.0)), splat(1.0));
            let zero = splat(0.0);
            (
                f,
                zero,
                zero,
                depth,
                _mm256_cmp_ps::<_CMP_GT_OQ>(pz, splat(u.near)),
            )
        } else {
            let iz = _mm256_div_ps(splat(1.0), pz);
            (
                _mm256_mul_ps(f, iz),
                _mm256_mul_ps(px, iz),
                _mm256_mul_ps(py, iz),
                _mm256_mul_ps(splat(u.near), iz),
                _mm256_cmp_ps::<_CMP_GT_OQ>(pz, splat(u.near_cut)),
            )
        };
        let cx = _mm256_fmadd_ps(fiz, px, splat(u.centre[0]));
        let cy = _mm256_fnmadd_ps(fiz, py, splat(u.centre[1]));
        let (centre_x, centre_y) = (unlanes(cx), unlanes(cy));
        // The screen covariance J S J^T + pixel variance, with J's rows f/z (1, 0, -x/z) and
        // f/z (0, -1, y/z) (S symmetric).
        let s = |r: usize, c: usize| splat(u.cov[r][c]);
        let fiz2 = _mm256_mul_ps(fiz, fiz);
        let pv = splat(u.pixel_variance);
        let sxx = _mm256_mul_ps(slope_x, slope_x);
        let syy = _mm256_mul_ps(slope_y, slope_y);
        let sxy = _mm256_mul_ps(slope_x, slope_y);
        let two = splat(2.0);
        let a = _mm256_fmadd_ps(
            _mm256_fmadd_ps(
                s(2, 2),
                sxx,
                _mm256_fnmadd_ps(_mm256_mul_ps(two, s(0, 2)), slope_x, s(0, 0)),
            ),
            fiz2,
            pv,
        );
        let c = _mm256_fmadd_ps(
            _mm256_fmadd_ps(
                s(2, 2),
                syy,
                _mm256_fnmadd_ps(_mm256_mul_ps(two, s(1, 2)), slope_y, s(1, 1)),
            ),
            fiz2,
            pv,
        );
        // -S01 + S02 y/z + S12 x/z - S22 (x/z)(y/z)
        let b = _mm256_mul_ps(
            _mm256_fnmadd_ps(
                s(2, 2),
                sxy,
                _mm256_fmadd_ps(s(0, 2), slope_y, _mm256_fmsub_ps(s(1, 2), slope_x, s(0, 1))),
            ),
            fiz2,
        );
        let det = _mm256_fmsub_ps(a, c, _mm256_mul_ps(b, b));
        let mut placed = _mm256_and_ps(front, _mm256_cmp_ps::<_CMP_GT_OQ>(det, splat(0.0)));
        let radius = splat(u.cutoff.sqrt());
        let half = splat(0.5);
        let ex = _mm256_fmadd_ps(radius, _mm256_sqrt_ps(a), half);
        let ey = _mm256_fmadd_ps(radius, _mm256_sqrt_ps(c), half);
        let (w, h) = (group.screen.w as f32, group.screen.h as f32);
        let lim =
            |v: __m256, hi: f32| _mm256_min_ps(_mm256_max_ps(v, splat(-1.0)), splat(hi + 1.0));
        let edge = |v: __m256, hi: f32| lim(_mm256_sub_ps(v, half), hi);
        let x0 = _mm256_ceil_ps(edge(_mm256_sub_ps(cx, ex), w));
        let x1 = _mm256_floor_ps(edge(_mm256_add_ps(cx, ex), w));
        let y0 = _mm256_ceil_ps(edge(_mm256_sub_ps(cy, ey), h));
        let y1 = _mm256_floor_ps(edge(_mm256_add_ps(cy, ey), h));
        let x0 = _mm256_max_ps(x0, splat(0.0));
        let x1 = _mm256_min_ps(x1, splat(w - 1.0));
        let y0 = _mm256_max_ps(y0, splat(0.0));
        let y1 = _mm256_min_ps(y1, splat(h - 1.0));
        placed = _mm256_and_ps(placed, _mm256_cmp_ps::<_CMP_LE_OQ>(x0, x1));
        placed = _mm256_and_ps(placed, _mm256_cmp_ps::<_CMP_LE_OQ>(y0, y1));
        let rect = [x0, y0, x1, y1].map(|v| unlanes_i32(_mm256_cvtps_epi32(v)));
        // Which lanes go on: placed on the image, not hidden, with a texel that has opacity.
        let placed = _mm256_movemask_ps(placed) as u32;
        let mut culled = 0;
        let mut texel = [[0.0f32; LANES]; 7];
        let mut go = 0u32;
        for l in 0..n {
            if placed >> l & 1 == 0 {
                continue;
            }
            if let Some(mask) = group.mask
                && mask.covers_rect([rect[0][l], rect[1][l], rect[2][l], rect[3][l]])
            {
                culled += 1;
                continue;
            }
            let [x, y, z] = voxels[l];
            let Some(t) = group.texels.get(x, y, z) else {
                continue;
            };
            let peak = u.alpha_of(t);
            if peak <= 0.0 {
                continue;
            }
            go |= 1 << l;
            for c in 0..3 {
                texel[c][l] = f32::from(t[c]);
                texel[3 + c][l] = f32::from(t[3 + c] as i8);
            }
            texel[6][l] = peak;
        }
        if go == 0 {
            return (culled, 0);
        }
        let mut keep = _mm256_castsi256_ps(_mm256_cmpeq_epi32(
            _mm256_and_si256(_mm256_set1_epi32(go as i32), lane_bits()),
            lane_bits(),
        ));
        for c in &u.clip {
            let side = _mm256_fmadd_ps(
                splat(c[0]),
                px,
                _mm256_fmadd_ps(splat(c[1]), py, _mm256_mul_ps(splat(c[2]), pz)),
            );
            keep = _mm256_and_ps(keep, _mm256_cmp_ps::<_CMP_LE_OQ>(side, splat(c[3])));
        }
        let inv_det = _mm256_div_ps(splat(1.0), det);
        // Headlight shading where the gradient is defined (w > 63).
        let inv255 = splat(1.0 / 255.0);
        let mut rgb = [0, 1, 2].map(|i| _mm256_mul_ps(lanes(&texel[i]), inv255));
        if u.shading > 0.0 {
            let g = [3, 4, 5].map(|i| lanes(&texel[i]));
            let [nx, ny, nz] = [0, 1, 2].map(|r| dot3(u.normal[r], g));
            let len2 = _mm256_fmadd_ps(nx, nx, _mm256_fmadd_ps(ny, ny, _mm256_mul_ps(nz, nz)));
            let abs_nz = _mm256_andnot_ps(splat(-0.0), nz);
            let lambert = _mm256_and_ps(
                _mm256_div_ps(abs_nz, _mm256_sqrt_ps(len2)),
                _mm256_cmp_ps::<_CMP_GT_OQ>(len2, splat(0.0)),
            );
            let scale = _mm256_fmadd_ps(splat(u.shading), lambert, splat(1.0 - u.shading));
            // An undefined gradient is stored as zero.
            let shaded = _mm256_cmp_ps::<_CMP_GT_OQ>(len2, splat(0.0));
            let scale = _mm256_blendv_ps(splat(1.0), scale, shaded);
            rgb = rgb.map(|v| _mm256_mul_ps(v, scale));
        }
        // The peak opacity times the share of the footprint's integral the pixel variance
        // keeps (see `kept_integral`).
        let own = _mm256_fmsub_ps(
            _mm256_sub_ps(a, pv),
            _mm256_sub_ps(c, pv),
            _mm256_mul_ps(b, b),
        );
        let kept = _mm256_min_ps(
            _mm256_sqrt_ps(_mm256_max_ps(_mm256_div_ps(own, det), splat(0.0))),
            splat(1.0),
        );
        let alpha = _mm256_mul_ps(lanes(&texel[6]), kept);
        let [r, g, bl] = rgb.map(|v| unlanes(_mm256_mul_ps(v, alpha)));
        let alpha = unlanes(alpha);
        let conic = [
            unlanes(_mm256_mul_ps(c, inv_det)),
            unlanes(_mm256_mul_ps(_mm256_sub_ps(splat(0.0), b), inv_det)),
            unlanes(_mm256_mul_ps(a, inv_det)),
        ];
        let depth = unlanes(depth);
        let keep = _mm256_movemask_ps(keep) as u32;
        let mut kept = 0;
        for l in (0..n).filter(|l| keep >> l & 1 != 0) {
            out[kept] = Projected {
                centre: [centre_x[l], centre_y[l]],
                conic: [conic[0][l], conic[1][l], conic[2][l]],
                color: [r[l], g[l], bl[l], alpha[l]],
                depth: depth[l],
                cutoff: u.cutoff,
                x0: rect[0][l],
                y0: rect[1][l],
                x1: rect[2][l],
                y1: rect[3][l],
            };
            kept += 1;
        }
        (culled, kept)
    }

    /// `row . v` for vectors of three lanes.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn dot3(row: glam::Vec3, v: [__m256; 3]) -> __m256 {
        _mm256_fmadd_ps(
            _mm256_set1_ps(row.x),
            v[0],
            _mm256_fmadd_ps(
                _mm256_set1_ps(row.y),
                v[1],
                _mm256_mul_ps(_mm256_set1_ps(row.z), v[2]),
            ),
        )
    }

    /// Bit `l` in lane `l`.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn lane_bits() -> __m256i {
        _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128)
    }

    #[target_feature(enable = "avx")]
    #[inline]
    fn lanes(v: &[f32; LANES]) -> __m256 {
        #[allow(unsafe_code)]
        // SAFETY: `v` holds 8 floats.
        unsafe {
            _mm256_loadu_ps(v.as_ptr())
        }
    }

    #[target_feature(enable = "avx")]
    #[inline]
    fn unlanes(v: __m256) -> [f32; LANES] {
        let mut out = [0.0; LANES];
        #[allow(unsafe_code)]
        // SAFETY: `out` holds 8 floats.
        unsafe {
            _mm256_storeu_ps(out.as_mut_ptr(), v)
        };
        out
    }

    #[target_feature(enable = "avx")]
    #[inline]
    fn unlanes_i32(v: __m256i) -> [i32; LANES] {
        let mut out = [0; LANES];
        #[allow(unsafe_code)]
        // SAFETY: `out` holds 8 integers.
        unsafe {
            _mm256_storeu_si256(out.as_mut_ptr().cast(), v)
        };
        out
    }

    /// `exp(-q / 2)` per lane, as [`super::exp_neg`] computes `exp(-x)`.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn exp_neg_half(q: __m256) -> __m256 {
        const ROUND: f32 = 12_582_912.0;
        let t = _mm256_max_ps(
            _mm256_mul_ps(q, _mm256_set1_ps(-0.5 * std::f32::consts::LOG2_E)),
            _mm256_set1_ps(-126.0),
        );
        let shifted = _mm256_add_ps(t, _mm256_set1_ps(ROUND));
        let n = _mm256_sub_epi32(
            _mm256_castps_si256(shifted),
            _mm256_set1_epi32(ROUND.to_bits() as i32),
        );
        let g = _mm256_mul_ps(
            _mm256_sub_ps(t, _mm256_sub_ps(shifted, _mm256_set1_ps(ROUND))),
            _mm256_set1_ps(std::f32::consts::LN_2),
        );
        let mut poly = _mm256_set1_ps(1.0 / 720.0);
        for c in [1.0 / 120.0, 1.0 / 24.0, 1.0 / 6.0, 1.0 / 2.0, 1.0, 1.0] {
            poly = _mm256_fmadd_ps(poly, g, _mm256_set1_ps(c));
        }
        let scale = _mm256_slli_epi32::<23>(_mm256_add_epi32(n, _mm256_set1_epi32(127)));
        _mm256_mul_ps(poly, _mm256_castsi256_ps(scale))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_neg_is_within_its_stated_error() {
        let worst = |top: f32| {
            (0..=100_000)
                .map(|i| {
                    let x = top * i as f32 / 100_000.0;
                    let exact = (-f64::from(x)).exp();
                    ((f64::from(exp_neg(x)) - exact) / exact).abs()
                })
                .fold(0.0f64, f64::max)
        };
        // Over the footprints' range (half the cut-off, 4.1 by default), and far past it.
        assert!(worst(8.0) < 8e-7, "relative error {}", worst(8.0));
        assert!(worst(80.0) < 5e-6, "relative error {}", worst(80.0));
        // Far past the cut-off it stays finite and tiny; a NaN gives no NaN.
        assert!(exp_neg(1e30) < 1e-37 && exp_neg(1e30) >= 0.0);
        assert!(exp_neg(f32::NAN).is_finite());
    }

    /// Splats of varied size, shape and colour around a tile at (16, 32).
    fn splats() -> Vec<Projected> {
        let mut state = 0x2545_f491u32;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state as f32 / u32::MAX as f32
        };
        (0..400)
            .map(|_| {
                let centre = [12.0 + 24.0 * next(), 28.0 + 24.0 * next()];
                let (sx, sy) = (0.3 + 3.0 * next(), 0.3 + 3.0 * next());
                let b = (next() - 0.5) * 0.9 * (sx * sy).sqrt();
                let (a, c) = (sx, sy);
                let det = a * c - b * b;
                let cutoff = 9.0;
                let (ex, ey) = (3.0 * a.sqrt() + 0.5, 3.0 * c.sqrt() + 0.5);
                let alpha = 0.1 + 0.8 * next();
                Projected {
                    centre,
                    conic: [c / det, -b / det, a / det],
                    color: [next() * alpha, next() * alpha, next() * alpha, alpha],
                    depth: next(),
                    cutoff,
                    x0: (centre[0] - ex - 0.5).ceil() as i32,
                    x1: (centre[0] + ex - 0.5).floor() as i32,
                    y0: (centre[1] - ey - 0.5).ceil() as i32,
                    y1: (centre[1] + ey - 0.5).floor() as i32,
                }
            })
            .collect()
    }

    /// Bins holding splats `0..n` for tile 0, so that tile 0 takes them in that order (the
    /// nearest, taken first, is last in a list).
    fn one_list(n: usize) -> ChunkBins {
        ChunkBins {
            starts: vec![0, n as u32],
            entries: (0..n as u32).rev().collect(),
            ..ChunkBins::default()
        }
    }

    fn batch<'a>(projected: &'a [Projected], bins: &'a [ChunkBins]) -> Batch<'a> {
        Batch {
            projected,
            bins,
            opaque: OPAQUE,
            drew: (0..projected.len())
                .map(|_| AtomicBool::new(false))
                .collect::<Vec<_>>()
                .leak(),
        }
    }

    fn fresh_tile(depth: &[f32]) -> TilePixels {
        let mut tile = TilePixels::default();
        // A 40x40 image whose depth varies, with the tile at (16, 32) cut by its bottom edge.
        tile.reset(16, 32, (40, 40), depth);
        tile
    }

    #[test]
    fn the_lanes_composite_as_a_pixel_by_pixel_loop_does() {
        let depth: Vec<f32> = (0..40 * 40).map(|i| (i % 7) as f32 * 0.1).collect();
        let mut tile = fresh_tile(&depth);
        let mut reference = vec![[0.0f32; 4]; PIXELS];
        let splats = splats();
        let bins = [one_list(splats.len())];
        tile.composite(0, (16, 32), batch(&splats, &bins));
        for &p in &splats {
            // The old scalar loop, pixel by pixel over the quad's rectangle, with libm's exp.
            for y in p.y0.max(32)..=p.y1.min(32 + 15).min(39) {
                for x in p.x0.max(16)..=p.x1.min(16 + 15).min(39) {
                    let px = &mut reference[(y as usize - 32) * TILE + x as usize - 16];
                    if px[3] >= OPAQUE || p.depth < depth[y as usize * 40 + x as usize] {
                        continue;
                    }
                    let (dx, dy) = (x as f32 + 0.5 - p.centre[0], y as f32 + 0.5 - p.centre[1]);
                    let q =
                        p.conic[0] * dx * dx + 2.0 * p.conic[1] * dx * dy + p.conic[2] * dy * dy;
                    if q > p.cutoff {
                        continue;
                    }
                    let weight = (1.0 - px[3]) * (-0.5 * q).exp();
                    for (v, c) in px.iter_mut().zip(p.color) {
                        *v += weight * c;
                    }
                }
            }
        }
        let bits: u32 = tile.rows.iter().map(|r| r.count_ones()).sum();
        assert_eq!(tile.open, bits);
        assert!(tile.open < 8 * 16, "some pixels turned opaque");
        assert_eq!(tile.composited + tile.skipped, splats.len());
        let mut worst = 0.0f32;
        let mut covered = 0;
        for (i, want) in reference.iter().enumerate() {
            let got = [tile.r[i], tile.g[i], tile.b[i], tile.a[i]];
            for k in 0..4 {
                worst = worst.max((got[k] - want[k]).abs());
            }
            covered += usize::from(want[3] > 0.5);
            // Pixels below the image's edge take nothing.
            if i / TILE >= 40 - 32 {
                assert_eq!(got, [0.0; 4]);
            }
        }
        assert!(
            covered > 100,
            "the splats cover the tile ({covered} pixels)"
        );
        assert!(worst < 1e-5, "largest difference {worst}");
    }

    #[test]
    fn the_avx2_kernel_gives_the_pixels_of_the_baseline_kernel() {
        #[cfg(target_arch = "x86_64")]
        if has_avx2() {
            let depth: Vec<f32> = (0..40 * 40).map(|i| (i % 7) as f32 * 0.1).collect();
            let (mut wide, mut narrow) = (fresh_tile(&depth), fresh_tile(&depth));
            let (splats, bins) = (splats(), [one_list(400)]);
            #[allow(unsafe_code)]
            // SAFETY: the features were checked above.
            unsafe {
                avx2::composite_tile(&mut wide, 0, (16, 32), batch(&splats, &bins))
            };
            composite_tile_lanes(
                &mut narrow,
                0,
                (16, 32),
                batch(&splats, &bins),
                composite_splat_lanes,
            );
            // The same pixels turn opaque; values differ by the fused multiply-adds' rounding.
            assert_eq!(wide.rows, narrow.rows);
            assert_eq!(wide.open, narrow.open);
            assert_eq!(wide.composited, narrow.composited);
            let planes = [
                (&wide.r, &narrow.r),
                (&wide.g, &narrow.g),
                (&wide.b, &narrow.b),
                (&wide.a, &narrow.a),
            ];
            for (w, n) in planes {
                let worst = w
                    .iter()
                    .zip(n)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f32::max);
                assert!(worst < 2e-6, "largest difference {worst}");
            }
            assert!(narrow.a.iter().filter(|&&a| a > 0.5).count() > 100);
        }
    }

    /// A 20x18x16 grid of texels, a third of them transparent, with varied colours and
    /// gradients (some undefined), seen by a camera turned off its axes.
    fn grid_and_view(orthographic: bool) -> (SplatProjection, SplatTexels) {
        let dims = [20u32, 18, 16];
        let count = (dims[0] * dims[1] * dims[2]) as usize;
        let mut state = 0x9e37_79b9u32;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state
        };
        // A third of the voxels left out; densities from clear to nearly opaque; a quarter of
        // the gradients undefined (zero).
        let mut ids = Vec::new();
        let mut texel_of = std::collections::HashMap::new();
        for id in 0..count as u32 {
            let (c, n) = (next().to_le_bytes(), next().to_le_bytes());
            if c[3] % 3 == 0 {
                continue;
            }
            let density = half::f16::from_f32(f32::from(c[3]) / 64.0)
                .to_bits()
                .to_le_bytes();
            let g = if n[3] % 4 == 0 {
                [0; 3]
            } else {
                [n[0], n[1], n[2]]
            };
            ids.push(id);
            texel_of.insert(
                id,
                [c[0], c[1], c[2], g[0], g[1], g[2], density[0], density[1]],
            );
        }
        let grid = SparseGrid::from_sorted_ids(dims, &ids).unwrap();
        let texels = SplatTexels::build(&grid, |[x, y, z], _| {
            texel_of[&(x + dims[0] * (y + dims[1] * z))]
        });
        let turn = glam::Mat3::from_euler(glam::EulerRot::XYZ, 0.4, -0.7, 0.2);
        let m = [turn.row(0), turn.row(1), turn.row(2)];
        let cov = glam::Mat3::from_diagonal(Vec3::new(0.3, 0.5, 0.2));
        let cov = turn * cov * turn.transpose();
        let u = SplatProjection {
            m,
            eye_index: Vec3::new(9.0, 8.0, 8.0) - turn.transpose() * Vec3::new(0.0, 0.0, 30.0),
            near_cut: 0.5,
            cov: [cov.row(0), cov.row(1), cov.row(2)],
            centre: [32.0, 24.0],
            focal: if orthographic { 2.5 } else { 70.0 },
            pixel_variance: 0.3,
            cutoff: 8.2,
            orthographic,
            near: 1.0,
            far: 60.0,
            dims,
            row: StrengthReducedU32::new(dims[0]),
            plane: StrengthReducedU32::new(dims[0] * dims[1]),
            normal: [turn.row(0), turn.row(1), turn.row(2)],
            shading: 0.7,
            clip: vec![[0.3, -0.2, 0.9, 29.0]],
            alpha: alpha_table(0.8),
        };
        (u, texels)
    }

    #[test]
    fn a_group_rectangle_holds_every_footprint_of_its_splats_and_no_more() {
        for orthographic in [false, true] {
            let (u, _) = grid_and_view(orthographic);
            let s = Screen { w: 64, h: 48 };
            let count = u.dims.iter().product::<u32>();
            // Stretches as the order gives them (runs along rows), spread ones, single voxels.
            let mut stretches: Vec<Vec<u32>> = (0..count / 32)
                .map(|c| (c * 32..c * 32 + 32).collect())
                .collect();
            stretches
                .extend((0..97).map(|k| (0..32).map(|i| (k * 31 + i * 211) % count).collect()));
            stretches.extend((0..count).step_by(7).map(|id| vec![id]));
            let mut tested = 0;
            for ids in &stretches {
                let rects: Vec<[i32; 4]> = ids
                    .iter()
                    .filter_map(|&id| {
                        place(&u, camera_centre(&u, voxel(&u, id)), 64, 48).map(|at| at.rect)
                    })
                    .collect();
                let Some(group) = group_rect(&u, ids, &s) else {
                    continue;
                };
                for r in &rects {
                    assert!(
                        group[0] <= r[0]
                            && group[1] <= r[1]
                            && group[2] >= r[2]
                            && group[3] >= r[3],
                        "{group:?} does not hold {r:?}"
                    );
                }
                if let [r] = rects[..] {
                    // One splat: its own rectangle, give or take the pixel that rounding may add.
                    assert!(
                        (0..4).all(|k| (group[k] - r[k]).abs() <= 1),
                        "{group:?} against {r:?}"
                    );
                    tested += 1;
                }
            }
            assert!(tested > 100, "{tested} single splats");
        }
    }

    #[test]
    fn the_avx2_projection_places_splats_as_the_scalar_one_does() {
        #[cfg(target_arch = "x86_64")]
        if has_avx2() {
            for orthographic in [false, true] {
                let (u, texels) = grid_and_view(orthographic);
                let screen = Screen { w: 64, h: 48 };
                // Every pixel opaque but those of four squares of 8x8 and one pixel, then
                // none.
                let mut mask = OpaqueMask::default();
                mask.reset(64, 48);
                mask.bits.fill(u64::MAX);
                for (x0, y0) in [(16, 8), (24, 16), (40, 16), (32, 32)] {
                    for y in y0..y0 + 8 {
                        mask.bits[y] &= !(0xff << x0);
                    }
                }
                mask.bits[3] &= !(1 << 50);
                for mask in [Some(&mask), None] {
                    let group = Group {
                        u: &u,
                        texels: &texels,
                        screen: &screen,
                        mask,
                    };
                    let ids: Vec<u32> = (0..20 * 18 * 16).rev().collect();
                    let mut wide = vec![Projected::default(); ids.len()];
                    let mut each = wide.clone();
                    let (mut culled, mut kept) = ([0; 2], [0; 2]);
                    for ids in ids.chunks(GROUP) {
                        for ids in ids.chunks(5) {
                            #[allow(unsafe_code)]
                            // SAFETY: the features were checked above.
                            let (c, k) =
                                unsafe { avx2::project(&group, ids, &mut wide[kept[0]..]) };
                            culled[0] += c;
                            kept[0] += k;
                        }
                        let (c, k) = group.project_each(ids, &mut each[kept[1]..]);
                        culled[1] += c;
                        kept[1] += k;
                    }
                    assert_eq!(culled[0], culled[1]);
                    assert_eq!(culled[0] > 0, mask.is_some());
                    assert_eq!(kept[0], kept[1]);
                    wide.truncate(kept[0]);
                    each.truncate(kept[1]);
                    let mut shown = 0;
                    for (a, b) in wide.iter().zip(&each) {
                        assert_eq!(
                            [a.x0, a.x1, a.y0, a.y1],
                            [b.x0, b.x1, b.y0, b.y1],
                            "{a:?} {b:?}"
                        );
                        assert!(b.x0 <= b.x1 && b.y0 <= b.y1, "{b:?}");
                        shown += 1;
                        let close = |x: f32, y: f32| (x - y).abs() <= 1e-4 * (1.0 + y.abs());
                        let values = |p: &Projected| {
                            [
                                p.centre.as_slice(),
                                &p.conic,
                                &p.color,
                                &[p.depth, p.cutoff],
                            ]
                            .concat()
                        };
                        for (x, y) in values(a).into_iter().zip(values(b)) {
                            assert!(close(x, y), "{a:?} {b:?}");
                        }
                    }
                    assert!(shown > 300, "{shown} splats shown");
                }
            }
        }
    }
}
