//! A sort-free tile compositor for splats on the CPU, with the mathematics of the GPU splat
//! pass (`shaders/splat.wgsl`): the same EWA footprint, the same 8-bit colours and normals, the
//! same headlight shading, clip planes and depth test against the mesh depth.
//!
//! An a-priori visibility order (IP-PBTF and the others) needs no sort, and binning keeps it:
//! every splat is projected in draw order and appended to each 16x16-pixel tile its footprint
//! touches, so each tile holds its splats in draw order. Each tile is then composited on its
//! own, in parallel, walking its list backwards (the reverse of a back-to-front order is front
//! to back) with the "under" operator `C += (1 - A) c; A += (1 - A) a`. A tile stops as soon as
//! every one of its pixels is opaque past [`OPAQUE`]: early ray termination, for splats, so the
//! hidden inside of a bone costs nothing. What a stopped pixel leaves out is at most
//! `1 - OPAQUE` of every channel.
//!
//! The loops are plain scalar Rust that the compiler vectorises where it can; the parallelism
//! is rayon's, over chunks of the draw order (projection and binning) and over tiles
//! (compositing). Every buffer lives in the [`TiledCompositor`] and is reused from frame to
//! frame.

use glam::Vec3;
use rayon::prelude::*;
use strength_reduce::StrengthReducedU32;

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
}

/// A volume's splat data as the GPU keeps it (straight RGBA8 colour, and the unit index-space
/// gradient as snorm8 with w = 127 where defined), both in one 8-byte texel per voxel, stored
/// in 4x4x4 bricks: the draw order runs along any axis, and in bricks the next voxel along y or
/// z is as often in the same cache line as the next along x is in a plain x-fastest layout
/// (measured: projecting the engine's splats took 33 ms with two separate x-fastest arrays).
#[derive(Debug, Clone, Default)]
pub struct SplatTexels {
    dims: [u32; 3],
    /// Bricks along x and y.
    bricks: [usize; 2],
    texels: Vec<[u8; 8]>,
}

/// Brick side in voxels.
const BRICK: usize = 4;

impl SplatTexels {
    /// The texels of a grid of `dims` from the splat pass's colour and normal textures (four
    /// bytes per voxel each, x fastest).
    pub fn new(dims: [u32; 3], colors: &[u8], normals: &[u8]) -> Self {
        let [nx, ny, nz] = dims.map(|n| n as usize);
        let bricks = [nx.div_ceil(BRICK), ny.div_ceil(BRICK)];
        let count = bricks[0] * bricks[1] * nz.div_ceil(BRICK) * BRICK.pow(3);
        let mut out = Self {
            dims,
            bricks,
            texels: vec![[0; 8]; count],
        };
        // One layer of bricks (four z-slices, a contiguous stretch of the texels) a task.
        let layer = bricks[0] * bricks[1] * BRICK.pow(3);
        out.texels
            .par_chunks_mut(layer.max(1))
            .enumerate()
            .for_each(|(bz, texels)| {
                for z in bz * BRICK..((bz + 1) * BRICK).min(nz) {
                    for y in 0..ny {
                        for x in 0..nx {
                            let id = 4 * (x + nx * (y + ny * z));
                            let (Some(c), Some(n)) =
                                (colors.get(id..id + 4), normals.get(id..id + 4))
                            else {
                                continue;
                            };
                            let slot = brick_slot(bricks, x, y, z) - bz * layer;
                            texels[slot] = [c[0], c[1], c[2], c[3], n[0], n[1], n[2], n[3]];
                        }
                    }
                }
            });
        out
    }

    /// The texel of voxel `(x, y, z)`: straight RGBA8, then the gradient as snorm8.
    fn get(&self, x: u32, y: u32, z: u32) -> Option<&[u8; 8]> {
        let [nx, ny, nz] = self.dims;
        if x >= nx || y >= ny || z >= nz {
            return None;
        }
        self.texels
            .get(brick_slot(self.bricks, x as usize, y as usize, z as usize))
    }
}

/// Where voxel `(x, y, z)` sits in texels laid out as `bricks` (bricks along x and y).
fn brick_slot(bricks: [usize; 2], x: usize, y: usize, z: usize) -> usize {
    let brick = ((z / BRICK) * bricks[1] + y / BRICK) * bricks[0] + x / BRICK;
    brick * BRICK.pow(3) + ((z % BRICK) * BRICK + y % BRICK) * BRICK + x % BRICK
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

/// What a frame cost, in splats and time.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TileStats {
    /// Projecting the splats.
    pub project: std::time::Duration,
    /// Binning them to tiles.
    pub bin: std::time::Duration,
    /// Compositing the tiles and laying them over what lies under them.
    pub tiles: std::time::Duration,
    /// Splats in the draw orders.
    pub splats: usize,
    /// Splats projected onto the image (in front of the eye, kept by the clip planes, on
    /// screen).
    pub projected: usize,
    /// Splat-tile pairs composited.
    pub composited: usize,
    /// Splat-tile pairs skipped because their tile was opaque already.
    pub skipped_opaque: usize,
    /// Tiles that stopped early.
    pub tiles_stopped: usize,
}

/// The tile lists of one chunk of the draw order: `entries[starts[t]..starts[t + 1]]` are the
/// chunk's splats touching tile `t`, in draw order.
#[derive(Debug, Default)]
struct ChunkBins {
    starts: Vec<u32>,
    entries: Vec<u32>,
    /// Splats of the chunk that landed on the image.
    projected: usize,
}

/// The compositor, with its buffers kept between frames.
#[derive(Debug)]
pub struct TiledCompositor {
    /// The accumulated opacity past which a pixel takes no more splats ([`OPAQUE`] by
    /// default; 1 or more never stops a tile).
    pub opaque: f32,
    projected: Vec<Projected>,
    bins: Vec<ChunkBins>,
    tiles: Vec<[f32; 4]>,
    tile_stats: Vec<(usize, usize, bool)>,
}

/// Splats projected per rayon task.
const CHUNK: usize = 1 << 15;

impl Default for TiledCompositor {
    fn default() -> Self {
        Self {
            opaque: OPAQUE,
            projected: Vec::new(),
            bins: Vec::new(),
            tiles: Vec::new(),
            tile_stats: Vec::new(),
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
    pub fn composite(
        &mut self,
        size: (u32, u32),
        volumes: &[(SplatProjection, &SplatTexels, &[u32])],
        depth: &[f32],
        under: &mut [[f32; 4]],
    ) -> TileStats {
        let (w, h) = (size.0 as usize, size.1 as usize);
        let (tx, ty) = (w.div_ceil(TILE), h.div_ceil(TILE));
        let mut stats = TileStats::default();
        let started = std::time::Instant::now();
        // Project every splat in draw order, all volumes one after another.
        let total: usize = volumes.iter().map(|(_, _, ids)| ids.len()).sum();
        stats.splats = total;
        // Every entry is written below: no need to clear what the last frame left.
        if self.projected.len() != total {
            self.projected.resize(total, Projected::default());
        }
        let mut rest = self.projected.as_mut_slice();
        for (projection, texels, ids) in volumes {
            let (mine, others) = rest.split_at_mut(ids.len());
            rest = others;
            mine.par_chunks_mut(CHUNK)
                .zip(ids.par_chunks(CHUNK))
                .for_each(|(out, ids)| {
                    for (p, &id) in out.iter_mut().zip(ids) {
                        *p = project(projection, texels, id, w as i32, h as i32);
                    }
                });
        }
        stats.project = started.elapsed();
        let started = std::time::Instant::now();
        // Bin each chunk of splats into the tiles, keeping the order within each tile.
        let chunks = total.div_ceil(CHUNK);
        self.bins.resize_with(chunks, ChunkBins::default);
        self.projected
            .par_chunks(CHUNK)
            .zip(self.bins.par_iter_mut())
            .enumerate()
            .for_each(|(c, (splats, bins))| bin_chunk(splats, (c * CHUNK) as u32, tx, ty, bins));
        stats.projected = self.bins[..chunks].iter().map(|b| b.projected).sum();
        stats.bin = started.elapsed();
        let started = std::time::Instant::now();
        // Composite every tile front to back.
        self.tiles.resize(tx * ty * TILE * TILE, [0.0; 4]);
        self.tile_stats.resize(tx * ty, (0, 0, false));
        let (projected, bins, opaque) = (&self.projected, &self.bins[..chunks], self.opaque);
        // Without meshes the depth is the far plane everywhere and every splat passes.
        let depth = depth.iter().any(|&d| d != 0.0).then_some(depth);
        self.tiles
            .par_chunks_mut(TILE * TILE)
            .zip(self.tile_stats.par_iter_mut())
            .enumerate()
            .for_each(|(t, (pixels, tile_stats))| {
                let origin = ((t % tx) * TILE, (t / tx) * TILE);
                let input = TileInput {
                    projected,
                    bins,
                    depth,
                    opaque,
                };
                *tile_stats = composite_tile(t, origin, (w, h), &input, pixels);
            });
        for &(done, skipped, stopped) in &self.tile_stats {
            stats.composited += done;
            stats.skipped_opaque += skipped;
            stats.tiles_stopped += usize::from(stopped);
        }
        // The splats over what lies under them.
        under.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for (x, px) in row.iter_mut().enumerate() {
                let t = (y / TILE) * tx + x / TILE;
                let s = self.tiles[t * TILE * TILE + (y % TILE) * TILE + x % TILE];
                let keep = 1.0 - s[3];
                *px = std::array::from_fn(|k| s[k] + keep * px[k]);
            }
        });
        stats.tiles = started.elapsed();
        stats
    }
}

/// One splat on the screen, as the splat pass's vertex shader places it; a splat left out
/// gets an empty rectangle.
fn project(u: &SplatProjection, texels: &SplatTexels, id: u32, w: i32, h: i32) -> Projected {
    let none = Projected {
        x0: 1,
        x1: 0,
        ..Projected::default()
    };
    // Divisions by the grid's row and plane sizes, done by multiplication (the hardware
    // divide was a fifth of the projection's time).
    let z = id / u.plane;
    let rest = id - z * u.plane.get();
    let y = rest / u.row;
    let x = rest - y * u.row.get();
    let k = Vec3::new(x as f32, y as f32, z as f32);
    let Some(texel) = texels.get(x, y, z) else {
        return none;
    };
    let straight = [texel[0], texel[1], texel[2], texel[3]].map(|v| f32::from(v) / 255.0);
    let d = k - u.eye_index;
    let p = Vec3::new(u.m[0].dot(d), u.m[1].dot(d), u.m[2].dot(d));
    if straight[3] <= 0.0
        || (!u.orthographic && p.z <= u.near_cut)
        || (u.orthographic && p.z <= u.near)
    {
        return none;
    }
    if u.clip
        .iter()
        .any(|c| Vec3::new(c[0], c[1], c[2]).dot(p) > c[3])
    {
        return none;
    }
    let f = u.focal;
    let (j0, j1, centre, depth) = if u.orthographic {
        let z = ((u.far - p.z) / (u.far - u.near)).clamp(0.0, 1.0);
        (
            Vec3::new(f, 0.0, 0.0),
            Vec3::new(0.0, -f, 0.0),
            [u.centre[0] + f * p.x, u.centre[1] - f * p.y],
            z,
        )
    } else {
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
    let det = a * c - b * b;
    // Also refuses a NaN determinant.
    if det.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return none;
    }
    let inv_det = 1.0 / det;
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
    if !(x0 <= x1 && y0 <= y1) {
        return none;
    }
    let mut rgb = [straight[0], straight[1], straight[2]];
    let g = [4, 5, 6, 7].map(|i| texel[i] as i8);
    if u.shading > 0.0 && g[3] > 63 {
        let g = Vec3::new(f32::from(g[0]), f32::from(g[1]), f32::from(g[2])) / 127.0;
        let n = Vec3::new(u.normal[0].dot(g), u.normal[1].dot(g), u.normal[2].dot(g));
        let lambert = n.normalize_or_zero().z.abs();
        let scale = 1.0 - u.shading + u.shading * lambert;
        rgb = rgb.map(|v| v * scale);
    }
    let alpha = straight[3];
    Projected {
        centre,
        conic: [c * inv_det, -b * inv_det, a * inv_det],
        color: [rgb[0] * alpha, rgb[1] * alpha, rgb[2] * alpha, alpha],
        depth,
        cutoff: u.cutoff,
        x0,
        y0,
        x1,
        y1,
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
/// keeps the draw order within every tile). `first` is the chunk's first splat index.
fn bin_chunk(splats: &[Projected], first: u32, tx: usize, ty: usize, bins: &mut ChunkBins) {
    let tiles = tx * ty;
    bins.starts.clear();
    bins.starts.resize(tiles + 1, 0);
    let range = |p: &Projected| {
        let t = TILE as i32;
        (p.x0 / t, p.x1 / t, p.y0 / t, p.y1 / t)
    };
    bins.projected = 0;
    for p in splats.iter().filter(|p| p.x0 <= p.x1) {
        bins.projected += 1;
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
    let mut next: Vec<u32> = bins.starts[..tiles].to_vec();
    for (i, p) in splats.iter().enumerate().filter(|(_, p)| p.x0 <= p.x1) {
        let (a, b, c, d) = range(p);
        for y in c..=d {
            for x in a..=b {
                let slot = &mut next[y as usize * tx + x as usize];
                bins.entries[*slot as usize] = first + i as u32;
                *slot += 1;
            }
        }
    }
}

/// Composites tile `t` (its top-left pixel at `origin`) front to back into `pixels` (TILE x
/// TILE, premultiplied, transparent where nothing covers); returns the splats composited, the
/// splats skipped once the tile was opaque, and whether it stopped early.
/// What every tile reads.
struct TileInput<'a> {
    projected: &'a [Projected],
    bins: &'a [ChunkBins],
    /// The meshes' depth; `None` where there are no meshes to test against.
    depth: Option<&'a [f32]>,
    opaque: f32,
}

fn composite_tile(
    t: usize,
    origin: (usize, usize),
    (w, h): (usize, usize),
    input: &TileInput<'_>,
    pixels: &mut [[f32; 4]],
) -> (usize, usize, bool) {
    let TileInput {
        projected,
        bins,
        depth,
        opaque,
    } = *input;
    pixels.fill([0.0; 4]);
    let (x_end, y_end) = ((origin.0 + TILE).min(w), (origin.1 + TILE).min(h));
    let mut open = (x_end - origin.0) * (y_end - origin.1);
    let (mut done, mut left) = (0, 0);
    let lists = bins.iter().rev().map(|b| {
        let (s, e) = (b.starts[t] as usize, b.starts[t + 1] as usize);
        &b.entries[s..e]
    });
    let total: usize = lists.clone().map(<[u32]>::len).sum();
    'splats: for list in lists {
        for &i in list.iter().rev() {
            if open == 0 {
                left = total - done;
                break 'splats;
            }
            done += 1;
            let p = &projected[i as usize];
            let xs = (p.x0 as usize).max(origin.0)..=(p.x1 as usize).min(x_end - 1);
            for y in (p.y0 as usize).max(origin.1)..=(p.y1 as usize).min(y_end - 1) {
                let dy = y as f32 + 0.5 - p.centre[1];
                let row = (y - origin.1) * TILE;
                for x in xs.clone() {
                    let px = &mut pixels[row + x - origin.0];
                    if px[3] >= opaque || depth.is_some_and(|d| p.depth < d[y * w + x]) {
                        continue;
                    }
                    let dx = x as f32 + 0.5 - p.centre[0];
                    let q =
                        p.conic[0] * dx * dx + 2.0 * p.conic[1] * dx * dy + p.conic[2] * dy * dy;
                    if q > p.cutoff {
                        continue;
                    }
                    let weight = (1.0 - px[3]) * (-0.5 * q).exp();
                    for (v, c) in px.iter_mut().zip(p.color) {
                        *v += weight * c;
                    }
                    if px[3] >= opaque {
                        open -= 1;
                    }
                }
            }
        }
    }
    (done, left, left > 0)
}
