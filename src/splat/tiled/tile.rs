//! Compositing a tile: its splats of a batch, nearest first, under its pixels, with the
//! portable pixel loop (the AVX2 one is in [`super::simd`]).

use std::sync::atomic::{AtomicBool, Ordering};

use super::TILE;
use super::bin::ChunkBins;
use super::project::Projected;

/// Pixels in a tile.
pub(super) const PIXELS: usize = TILE * TILE;
/// A plane of a tile's pixels, with room for a group of lanes starting at the last pixel, as
/// wide as a row for the AVX-512 loop (lanes past a row's end fall on the next row, or here,
/// and are never open), rounded up to
/// whole cache lines so that every plane of a [`TilePixels`] starts on one.
pub(super) const PLANE: usize = (PIXELS + 2 * LANES).next_multiple_of(16);

/// One tile's pixels as planes (premultiplied red, green, blue, alpha, and the meshes' reversed
/// depth), so that a row of pixels is a few vector registers. Aligned to a cache line: a row
/// then starts on one, and a group of lanes from its first pixel is one line. Left to the
/// allocator (16 bytes), the planes' offset within a line depends on what was allocated
/// before them, and the pixel loop's time moved between builds by up to a fifth (BENCHMARKS.md, "Tile planes on cache
/// lines").
#[derive(Debug, Clone)]
#[repr(C, align(64))]
pub(super) struct TilePixels {
    pub(super) r: [f32; PLANE],
    pub(super) g: [f32; PLANE],
    pub(super) b: [f32; PLANE],
    pub(super) a: [f32; PLANE],
    pub(super) depth: [f32; PLANE],
    /// Per row, a bit for each pixel of the image not yet opaque.
    pub(super) rows: [u16; TILE],
    /// Pixels of the image in the tile not yet opaque.
    pub(super) open: u32,
    pub(super) composited: usize,
    pub(super) skipped: usize,
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

impl TilePixels {
    /// Starts a frame: transparent, the meshes' depth (none where `depth` is all 0), and every
    /// pixel of the image open.
    pub(super) fn reset(&mut self, x0: usize, y0: usize, (w, h): (usize, usize), depth: &[f32]) {
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

    /// The planes' `N` values from pixel `at` on (`None` past the planes' ends).
    #[inline(always)]
    pub(super) fn lanes<const N: usize>(&mut self, at: usize) -> Option<Lanes<'_, N>> {
        let end = at.checked_add(N)?;
        Some(Lanes {
            r: self.r.get_mut(at..end)?.try_into().ok()?,
            g: self.g.get_mut(at..end)?.try_into().ok()?,
            b: self.b.get_mut(at..end)?.try_into().ok()?,
            a: self.a.get_mut(at..end)?.try_into().ok()?,
            depth: self.depth.get(at..end)?.try_into().ok()?,
        })
    }
}

/// A group of `N` pixels of a tile, plane by plane.
pub(super) struct Lanes<'a, const N: usize> {
    pub(super) r: &'a mut [f32; N],
    pub(super) g: &'a mut [f32; N],
    pub(super) b: &'a mut [f32; N],
    pub(super) a: &'a mut [f32; N],
    pub(super) depth: &'a [f32; N],
}

/// What every tile takes from a batch: its projected splats, their tile lists and the
/// opacity that stops a pixel.
#[derive(Clone, Copy)]
pub(super) struct Batch<'a> {
    pub(super) projected: &'a [Projected],
    pub(super) bins: &'a [ChunkBins],
    pub(super) opaque: f32,
    /// Per splat of `projected`, set once it reaches an open pixel.
    pub(super) drew: &'a [AtomicBool],
}

/// [`TilePixels::composite`], with the pixel loop `splat` inlined: it composites one splat
/// under a tile's pixels (its top-left pixel at the origin given) and returns how many pixels
/// turned opaque.
#[inline(always)]
pub(super) fn composite_tile_lanes(
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

/// Lanes of the pixel loop: a group of pixels along a row, starting where a footprint does.
pub(super) const LANES: usize = 8;

/// The part of a splat's pixel rectangle in a tile: its first and last columns, its first and
/// last rows, and a row mask of its columns.
pub(super) type TileRect = (usize, usize, usize, usize, u16);

/// The part of a splat's pixel rectangle in the tile at `origin`; `None` where they do not
/// meet.
#[inline(always)]
pub(super) fn splat_rect(origin: (usize, usize), p: &Projected) -> Option<TileRect> {
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
/// Plain loops over groups of [`LANES`] pixels of a row (half as many where the footprint is
/// at most that wide), with no branch and no library call inside (`exp` is [`exp_neg`]),
/// which the compiler turns into vector instructions, 4 lanes wide with the x86-64 baseline
/// (SSE2) and on AArch64 (NEON). Where the processor has AVX2 and FMA, `simd::avx2` does the
/// same in 8 lanes (chosen at run time). Rows and groups whose pixels are all opaque are
/// skipped from the tile's row masks. Within a group a pixel is left alone where it is opaque,
/// the meshes are in front, or it lies past the footprint's cut-off; the footprint's rectangle
/// always holds its cut-off ellipse, so the rectangle only chooses the rows and groups
/// walked.
pub(super) fn composite_splat_lanes(
    tile: &mut TilePixels,
    origin: (usize, usize),
    p: &Projected,
    (lx0, lx1, ly0, ly1, span): TileRect,
    opaque: f32,
) -> u32 {
    let mut turned = 0u32;
    for ly in ly0..=ly1 {
        let open = tile.rows[ly] & span;
        if open == 0 {
            continue;
        }
        let dy = (origin.1 + ly) as f32 + 0.5 - p.centre[1];
        let row = Row {
            ly,
            dx0: origin.0 as f32 + 0.5 - p.centre[0],
            by: 2.0 * p.conic[1] * dy,
            qy: p.conic[2] * dy * dy,
            opaque,
        };
        // A footprint at most half a group wide (as a voxel under a pixel across makes) takes
        // groups of half the lanes, rather than vectors half empty.
        if lx1 - lx0 < LANES / 2 {
            turned += row.under::<{ LANES / 2 }>(tile, p, lx0, u32::from(open));
            continue;
        }
        // Groups start at the rectangle's left edge: most rows of a footprint fit in one.
        for start in (lx0..=lx1).step_by(LANES) {
            turned += row.under::<LANES>(tile, p, start, u32::from(open));
        }
    }
    turned
}

/// One row of a footprint in a tile, for [`composite_splat_lanes`]: the row, the offset of
/// the tile's first pixel centre from the footprint's centre along x, the terms of the
/// exponent the row's pixels share (`2 b dy`, `c dy^2`), and the opacity that stops a pixel.
struct Row {
    ly: usize,
    dx0: f32,
    by: f32,
    qy: f32,
    opaque: f32,
}

impl Row {
    /// Composites splat `p` under the `N` pixels of the row from column `start` on (those of
    /// `open`, the row's open pixels, alone); returns how many turned opaque.
    #[inline(always)]
    fn under<const N: usize>(
        &self,
        tile: &mut TilePixels,
        p: &Projected,
        start: usize,
        open: u32,
    ) -> u32 {
        let lanes_open = (open >> start) & ((1 << N) - 1);
        if lanes_open == 0 {
            return 0;
        }
        let Some(Lanes {
            r,
            g,
            b,
            a,
            depth: d,
        }) = tile.lanes::<N>(self.ly * TILE + start)
        else {
            return 0;
        };
        let [ca, _, _] = p.conic;
        let [cr, cg, cbl, calpha] = p.color;
        let first = self.dx0 + start as f32;
        // Every lane computed, then masked: no branch, so the loops vectorise. (Plain
        // loops: `array::map` and `from_fn` are calls that are not built for AVX2.)
        let mut q = [0.0f32; N];
        for (l, q) in q.iter_mut().enumerate() {
            let dx = first + l as f32;
            *q = (ca * dx + self.by) * dx + self.qy;
        }
        let mut falloff = [0.0f32; N];
        for (e, &q) in falloff.iter_mut().zip(&q) {
            *e = exp_neg(0.5 * q);
        }
        let mut closing = 0u32;
        for l in 0..N {
            let alpha = a[l];
            let live = ((lanes_open >> l) & 1 != 0) & (q[l] <= p.cutoff) & (p.depth >= d[l]);
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
            closing |= u32::from(live & (after >= self.opaque)) << l;
        }
        tile.rows[self.ly] &= !((closing << start) as u16);
        closing.count_ones()
    }
}

/// `exp(-x)` for `x >= 0`, without a library call so that it vectorises: `2^n 2^f` with `n`
/// the nearest integer to `-x log2(e)` (by the 1.5 * 2^23 rounding trick) and
/// `2^f = e^(f ln 2)`, `|f ln 2| <= 0.35`, by its Taylor series to degree 6. The relative error
/// is below 8e-7 for `x` up to 8 (footprints use up to half their cut-off, 4.1 by default) and
/// grows with the rounding of `x log2(e)` to 5e-6 at 80. Below 2^-126 (`x` past 87) it gives
/// 2^-126.
#[inline(always)]
pub(super) fn exp_neg(x: f32) -> f32 {
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
