//! A ramp's cell sums written with AVX2 intrinsics, eight voxels of a row a vector (see
//! [`super::RowSamples::ramp_sums`]).

use std::arch::x86_64::*;

use super::{BINS, Ramp};

/// Voxels a vector.
pub(super) const LANES: usize = 8;

/// Writes to `sums[c][j]`, for each voxel `j` of a block of [`LANES`] voxels (`j / LANES`
/// below `whole / LANES`) holding an open voxel (`open[j] != 0`), what
/// [`super::ExtinctionTable::weighted_sums`] gives for its eight samples `corners[..][j]`
/// with the ramp `ramp`: per lane the same operations in the same order (no fused
/// multiply-add, which would round differently), so the same sums, bit for bit. Blocks with no
/// open voxel are left as they were: a stretch of a row between tissue boundaries may hold few.
///
/// # Safety
///
/// The processor must have AVX2; `whole` must be a multiple of [`LANES`], and `open`, every
/// corner and every `sums` must hold at least `whole` values.
#[target_feature(enable = "avx2")]
#[allow(unsafe_code)]
pub(super) unsafe fn ramp_sums(
    corners: &[Vec<f32>; 8],
    open: &[u8],
    whole: usize,
    ramp: Ramp<'_>,
    sums: &mut [Vec<f32>; 4],
) {
    debug_assert!(whole.is_multiple_of(LANES) && open.len() >= whole);
    debug_assert!(corners.iter().all(|c| c.len() >= whole));
    debug_assert!(sums.iter().all(|s| s.len() >= whole));
    let table = ramp.entries.as_ptr().cast::<f32>();
    let start = _mm256_set1_ps(ramp.start);
    let scale = _mm256_set1_ps(ramp.scale);
    let zero = _mm256_setzero_ps();
    let top = _mm256_set1_ps(BINS as f32);
    let last = _mm256_set1_epi32(BINS as i32 - 1);
    for (block, open) in open[..whole].chunks_exact(LANES).enumerate() {
        if open.iter().all(|&o| o == 0) {
            continue;
        }
        let s = block * LANES;
        let mut acc = [zero; 4];
        for corner in corners {
            #[allow(unsafe_code)]
            // SAFETY: `s + LANES <= whole <= corner.len()`.
            let value = unsafe { _mm256_loadu_ps(corner.as_ptr().add(s)) };
            // `max` with zero second: a NaN lane takes zero, as `f32::max` gives it.
            let x = _mm256_min_ps(
                _mm256_max_ps(_mm256_mul_ps(_mm256_sub_ps(value, start), scale), zero),
                top,
            );
            // In [0, BINS]: the truncation is exact, the index at most BINS - 1.
            let i = _mm256_min_epi32(_mm256_cvttps_epi32(x), last);
            let f = _mm256_sub_ps(x, _mm256_cvtepi32_ps(i));
            // Entries `i` and `i + 1` lie side by side: one load a lane takes both, then
            // turned so that vector `c` holds channel `c` of each lane's entry `i`, vector
            // `4 + c` of its entry `i + 1`. (Eight loads and a transposition took less time
            // than eight gathers on this project's machines.) Float `4 i + 7` lies inside the
            // table's `4 (BINS + 1)`, `i` being at most `BINS - 1`.
            let mut lanes = [0i32; LANES];
            #[allow(unsafe_code)]
            // SAFETY: `lanes` holds eight i32.
            unsafe {
                _mm256_storeu_si256(lanes.as_mut_ptr().cast(), i)
            };
            #[allow(unsafe_code)]
            // SAFETY: each index lies in [0, BINS - 1], so its two entries inside the table.
            let rows: [__m256; LANES] = std::array::from_fn(|l| unsafe {
                _mm256_loadu_ps(table.add(4 * lanes[l] as usize))
            });
            let cols = transpose(rows);
            let e: [__m256; 4] = std::array::from_fn(|c| {
                let (a, b) = (cols[c], cols[4 + c]);
                _mm256_add_ps(a, _mm256_mul_ps(f, _mm256_sub_ps(b, a)))
            });
            // Colour weighted by extinction, and the extinction (times one, exactly itself).
            for c in 0..3 {
                acc[c] = _mm256_add_ps(acc[c], _mm256_mul_ps(e[3], e[c]));
            }
            acc[3] = _mm256_add_ps(acc[3], e[3]);
        }
        for (out, acc) in sums.iter_mut().zip(acc) {
            #[allow(unsafe_code)]
            // SAFETY: `s + LANES <= whole <= out.len()`.
            unsafe {
                _mm256_storeu_ps(out.as_mut_ptr().add(s), acc)
            };
        }
    }
}

/// The 8 x 8 transposition of `r`: element `l` of vector `k` is element `k` of `r[l]`.
#[target_feature(enable = "avx2")]
#[inline]
fn transpose(r: [__m256; LANES]) -> [__m256; LANES] {
    let t: [__m256; 8] = std::array::from_fn(|k| {
        let (a, b) = (r[k / 2 * 2], r[k / 2 * 2 + 1]);
        if k % 2 == 0 {
            _mm256_unpacklo_ps(a, b)
        } else {
            _mm256_unpackhi_ps(a, b)
        }
    });
    // Per half of the lanes (rows 0-3, 4-7): columns 0 and 4, 1 and 5, 2 and 6, 3 and 7.
    let u = |lo: usize| {
        [
            _mm256_shuffle_ps::<0x44>(t[lo], t[lo + 2]),
            _mm256_shuffle_ps::<0xEE>(t[lo], t[lo + 2]),
            _mm256_shuffle_ps::<0x44>(t[lo + 1], t[lo + 3]),
            _mm256_shuffle_ps::<0xEE>(t[lo + 1], t[lo + 3]),
        ]
    };
    let (lo, hi) = (u(0), u(4));
    std::array::from_fn(|k| {
        if k < 4 {
            _mm256_permute2f128_ps::<0x20>(lo[k], hi[k])
        } else {
            _mm256_permute2f128_ps::<0x31>(lo[k - 4], hi[k - 4])
        }
    })
}
