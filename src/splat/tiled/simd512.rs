//! The pixel loop in AVX-512 vectors of 16 lanes, for processors that have AVX-512F, DQ and
//! BW beside AVX2 and FMA ([`has_avx512`]): the arithmetic of the AVX2 loop
//! (`simd::avx2`), lane for lane and in the same order, so the same bits, with the lanes
//! that are open and those that turn opaque held in mask registers. A footprint 5 to 8
//! pixels wide takes two rows a vector, a wider one a whole row from its left edge; a
//! narrower one goes to the AVX2 loop, which takes two rows of 4 pixels a vector, where 16
//! lanes would be half empty. Where the footprints are about 8 pixels wide (voxels about 2.5
//! pixels apart) a frame's tiles took a quarter to two fifths less time than with the AVX2
//! loop, on a processor that runs 512-bit operations as two 256-bit halves; with footprints
//! of 3 to 6 pixels, about the same (BENCHMARKS.md, "The pixel loop in AVX-512 vectors").
//! The splat's broadcast values and the exponential are written again for 512-bit vectors
//! rather than shared through a trait over both widths: the intrinsics differ in every call.

use std::arch::x86_64::*;

use super::TILE;
use super::project::Projected;
use super::tile::{Batch, TilePixels, TileRect, composite_tile_lanes};

pub(super) use crate::simd::has_avx512;

/// Lanes of a vector.
const WIDE: usize = 16;
/// Columns of a row in each half of a vector that takes two rows.
const HALF: usize = WIDE / 2;

/// [`composite_tile_lanes`] with [`composite_splat`].
///
/// # Safety
///
/// The processor must have AVX-512F, DQ and BW, AVX2, FMA and POPCNT.
#[target_feature(enable = "avx512f,avx512dq,avx512bw,avx2,fma,popcnt")]
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

#[target_feature(enable = "avx512f,avx512dq,avx512bw,avx2,fma,popcnt")]
#[inline]
fn composite_splat(
    tile: &mut TilePixels,
    origin: (usize, usize),
    p: &Projected,
    (lx0, lx1, ly0, ly1, span): TileRect,
    opaque: f32,
) -> u32 {
    if lx1 - lx0 < super::simd::avx2::HALF {
        return super::simd::avx2::composite_splat(
            tile,
            origin,
            p,
            (lx0, lx1, ly0, ly1, span),
            opaque,
        );
    }
    let dx0 = origin.0 as f32 + 0.5 - p.centre[0];
    let [_, cb, cc] = p.conic;
    let splat = Broadcast::new(p, opaque);
    let row_terms = |ly: usize| {
        let dy = (origin.1 + ly) as f32 + 0.5 - p.centre[1];
        (2.0 * cb * dy, cc * dy * dy)
    };
    let iota = _mm512_setr_ps(
        0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0, 13.0, 14.0, 15.0,
    );
    let dx_row = _mm512_add_ps(_mm512_set1_ps(dx0 + lx0 as f32), iota);
    let pairs = lx1 - lx0 < HALF;
    let dx_pair = if pairs {
        // Lanes 8-15 repeat lanes 0-7's columns, a row lower.
        _mm512_add_ps(
            _mm512_set1_ps(dx0 + lx0 as f32),
            _mm512_setr_ps(
                0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0,
            ),
        )
    } else {
        dx_row
    };
    let mut turned = 0;
    let mut ly = ly0;
    while ly <= ly1 {
        if pairs && ly < ly1 {
            let rows = [tile.rows[ly] & span, tile.rows[ly + 1] & span];
            let lanes_open =
                ((u32::from(rows[0]) >> lx0) & 0xff) | ((u32::from(rows[1]) >> lx0) & 0xff) << HALF;
            if lanes_open != 0 {
                let [(by0, qy0), (by1, qy1)] = [row_terms(ly), row_terms(ly + 1)];
                let halves = |lo: f32, hi: f32| {
                    _mm512_mask_mov_ps(_mm512_set1_ps(lo), 0xff00, _mm512_set1_ps(hi))
                };
                let at = ly * TILE + lx0;
                let terms = (dx_pair, halves(by0, by1), halves(qy0, qy1));
                let done = splat.under::<TILE>(tile, at, terms, lanes_open as u16);
                tile.rows[ly] &= !(((done & 0xff) << lx0) as u16);
                tile.rows[ly + 1] &= !(((done >> HALF) << lx0) as u16);
                turned += done.count_ones();
            }
            ly += 2;
            continue;
        }
        let open = tile.rows[ly] & span;
        if open != 0 {
            let (by, qy) = row_terms(ly);
            let at = ly * TILE + lx0;
            let terms = (dx_row, _mm512_set1_ps(by), _mm512_set1_ps(qy));
            let done = splat.under::<HALF>(tile, at, terms, open >> lx0);
            // Lanes past the row's end were never open: `done` has no bit there.
            tile.rows[ly] &= !((done << lx0) as u16);
            turned += done.count_ones();
        }
        ly += 1;
    }
    turned
}

/// A splat's values in every lane, for [`Broadcast::under`].
struct Broadcast {
    conic_a: __m512,
    cutoff: __m512,
    depth: __m512,
    color: [__m512; 4],
    opaque: __m512,
}

impl Broadcast {
    #[target_feature(enable = "avx512f")]
    #[inline]
    fn new(p: &Projected, opaque: f32) -> Self {
        Self {
            conic_a: _mm512_set1_ps(p.conic[0]),
            cutoff: _mm512_set1_ps(p.cutoff),
            depth: _mm512_set1_ps(p.depth),
            color: p.color.map(|c| _mm512_set1_ps(c)),
            opaque: _mm512_set1_ps(opaque),
        }
    }

    /// Composites the splat under 16 pixels of the tile: lanes 0-7 from pixel `at` of the
    /// planes on, lanes 8-15 from pixel `at + HI` on (`HI` [`HALF`]: 16 pixels along a row;
    /// [`TILE`]: 8 of a row and the 8 below them). `dx` is each lane's offset from the centre
    /// along x, `by` and `qy` its row's terms of the exponent, and bit `l` of `lanes_open`
    /// says whether lane `l`'s pixel is open. Returns the lanes that turned opaque, a bit
    /// each.
    #[target_feature(enable = "avx512f,avx512dq,avx512bw,fma")]
    #[inline]
    fn under<const HI: usize>(
        &self,
        tile: &mut TilePixels,
        at: usize,
        (dx, by, qy): (__m512, __m512, __m512),
        lanes_open: u16,
    ) -> u32 {
        let stretch = at..at + HI + HALF;
        let (Some(r), Some(g), Some(b), Some(a), Some(d)) = (
            tile.r.get_mut(stretch.clone()),
            tile.g.get_mut(stretch.clone()),
            tile.b.get_mut(stretch.clone()),
            tile.a.get_mut(stretch.clone()),
            tile.depth.get(stretch),
        ) else {
            return 0;
        };
        let q = _mm512_fmadd_ps(_mm512_fmadd_ps(self.conic_a, dx, by), dx, qy);
        let falloff = exp_neg_half(q);
        let [cr, cg, cb, calpha] = self.color;
        #[allow(unsafe_code)]
        // SAFETY: each stretch holds HI + HALF floats, so a half at 0 and one at HI.
        unsafe {
            let load = |v: *const f32| {
                if HI == HALF {
                    _mm512_loadu_ps(v)
                } else {
                    _mm512_insertf32x8::<1>(
                        _mm512_castps256_ps512(_mm256_loadu_ps(v)),
                        _mm256_loadu_ps(v.add(HI)),
                    )
                }
            };
            let store = |v: *mut f32, x: __m512| {
                if HI == HALF {
                    _mm512_storeu_ps(v, x)
                } else {
                    _mm256_storeu_ps(v, _mm512_castps512_ps256(x));
                    _mm256_storeu_ps(v.add(HI), _mm512_extractf32x8_ps::<1>(x));
                }
            };
            let live = _mm512_mask_cmp_ps_mask::<_CMP_LE_OQ>(lanes_open, q, self.cutoff);
            let live = _mm512_mask_cmp_ps_mask::<_CMP_GE_OQ>(live, self.depth, load(d.as_ptr()));
            let alpha = load(a.as_ptr());
            let weight =
                _mm512_maskz_mul_ps(live, _mm512_sub_ps(_mm512_set1_ps(1.0), alpha), falloff);
            for (plane, c) in [(r, cr), (g, cg), (b, cb)] {
                store(
                    plane.as_mut_ptr(),
                    _mm512_fmadd_ps(weight, c, load(plane.as_ptr())),
                );
            }
            let after = _mm512_fmadd_ps(weight, calpha, alpha);
            store(a.as_mut_ptr(), after);
            u32::from(_mm512_mask_cmp_ps_mask::<_CMP_GE_OQ>(
                live,
                after,
                self.opaque,
            ))
        }
    }
}

/// `exp(-q / 2)` per lane, with the operations of `simd::avx2`'s.
#[target_feature(enable = "avx512f,fma")]
#[inline]
fn exp_neg_half(q: __m512) -> __m512 {
    const ROUND: f32 = 12_582_912.0;
    let t = _mm512_max_ps(
        _mm512_mul_ps(q, _mm512_set1_ps(-0.5 * std::f32::consts::LOG2_E)),
        _mm512_set1_ps(-126.0),
    );
    let shifted = _mm512_add_ps(t, _mm512_set1_ps(ROUND));
    let n = _mm512_sub_epi32(
        _mm512_castps_si512(shifted),
        _mm512_set1_epi32(ROUND.to_bits() as i32),
    );
    let g = _mm512_mul_ps(
        _mm512_sub_ps(t, _mm512_sub_ps(shifted, _mm512_set1_ps(ROUND))),
        _mm512_set1_ps(std::f32::consts::LN_2),
    );
    let mut poly = _mm512_set1_ps(1.0 / 720.0);
    for c in [1.0 / 120.0, 1.0 / 24.0, 1.0 / 6.0, 1.0 / 2.0, 1.0, 1.0] {
        poly = _mm512_fmadd_ps(poly, g, _mm512_set1_ps(c));
    }
    let scale = _mm512_slli_epi32::<23>(_mm512_add_epi32(n, _mm512_set1_epi32(127)));
    _mm512_mul_ps(poly, _mm512_castsi512_ps(scale))
}
