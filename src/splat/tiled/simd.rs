//! The choice between the tile compositor's portable loops, its AVX2 and FMA code and its
//! AVX-512 pixel loop (`simd512`), made at run time from the processor (and [`SIMD_VAR`]),
//! and that AVX2 code: projection eight splats a vector, and the pixel loop eight pixels a
//! vector.

use super::project::{Group, Projected};
#[cfg(target_arch = "x86_64")]
use super::tile::LANES;
use super::tile::{Batch, TilePixels, composite_splat_lanes, composite_tile_lanes};
pub use crate::simd::SIMD_VAR;
#[cfg(target_arch = "x86_64")]
pub(super) use crate::simd::has_avx2;

/// Projects the splats of a group, its voxels given, writing those that land on the image, in order, to
/// the front of `out` (at least as long as `voxels`): neither the splats left out nor their
/// places are written, read or binned. Returns how many were left out as hidden behind opaque
/// pixels, and how many were written. Eight at a time in AVX2 vectors where the processor has
/// them, else [`Group::project_each`].
pub(super) fn project_group(
    group: &Group<'_>,
    voxels: &[[u32; 3]],
    out: &mut [Projected],
) -> (usize, usize) {
    #[cfg(target_arch = "x86_64")]
    if has_avx2() {
        let (mut culled, mut kept) = (0, 0);
        for voxels in voxels.chunks(LANES) {
            #[allow(unsafe_code)]
            // SAFETY: the processor has the features the function is built for, checked above.
            let (hidden, placed) = unsafe { avx2::project(group, voxels, &mut out[kept..]) };
            culled += hidden;
            kept += placed;
        }
        return (culled, kept);
    }
    group.project_each(voxels, out)
}

/// Composites a batch's splats touching tile `t` (its top-left pixel at `origin`), nearest
/// first, under what the tile holds: 16 lanes wide where the processor has AVX-512
/// (`simd512`), 8 where it has AVX2 and FMA, else the portable loop.
pub(super) fn composite_tile(
    tile: &mut TilePixels,
    t: usize,
    origin: (usize, usize),
    batch: Batch<'_>,
) {
    #[cfg(target_arch = "x86_64")]
    if super::simd512::has_avx512() {
        #[allow(unsafe_code)]
        // SAFETY: the processor has the features the function is built for, checked above.
        return unsafe { super::simd512::composite_tile(tile, t, origin, batch) };
    }
    #[cfg(target_arch = "x86_64")]
    if has_avx2() {
        #[allow(unsafe_code)]
        // SAFETY: the processor has the features the function is built for, checked above.
        return unsafe { avx2::composite_tile(tile, t, origin, batch) };
    }
    composite_tile_lanes(tile, t, origin, batch, composite_splat_lanes);
}

/// The pixel loop written with AVX2 and FMA intrinsics, for processors that have them (see
/// [`has_avx2`]): the same arithmetic as [`composite_splat_lanes`], 8 lanes a vector, with
/// fused multiply-adds and the lanes that turn opaque read as one mask. (The plain loops
/// built for AVX2 gave neither: the compiler does not fuse `a * b + c` on its own, and it
/// gathered the lanes' bits with a dozen shuffles.)
#[cfg(target_arch = "x86_64")]
pub(super) mod avx2 {
    use std::arch::x86_64::*;

    use crate::splat::tiled::TILE;
    use crate::splat::tiled::project::{Group, Projected, RECT_MARGIN};
    use crate::splat::tiled::tile::{Batch, LANES, TilePixels, TileRect, composite_tile_lanes};

    /// [`composite_tile_lanes`] with [`composite_splat`].
    ///
    /// # Safety
    ///
    /// The processor must have AVX2, FMA and POPCNT.
    #[target_feature(enable = "avx2,fma,popcnt")]
    #[allow(unsafe_code)]
    pub(in crate::splat::tiled) unsafe fn composite_tile(
        tile: &mut TilePixels,
        t: usize,
        origin: (usize, usize),
        batch: Batch<'_>,
    ) {
        composite_tile_lanes(tile, t, origin, batch, |tile, origin, p, rect, opaque| {
            composite_splat(tile, origin, p, rect, opaque)
        });
    }

    /// [`super::composite_splat_lanes`] in AVX2 vectors. A footprint at most [`HALF`] pixels
    /// wide (a splat of a voxel under a pixel across, with the screen's low-pass filter) takes
    /// two rows a vector, one in each half; a wider one a row at a time, [`LANES`] pixels a
    /// vector.
    #[target_feature(enable = "avx2,fma,popcnt")]
    #[inline]
    pub(in crate::splat::tiled) fn composite_splat(
        tile: &mut TilePixels,
        origin: (usize, usize),
        p: &Projected,
        (lx0, lx1, ly0, ly1, span): TileRect,
        opaque: f32,
    ) -> u32 {
        let dx0 = origin.0 as f32 + 0.5 - p.centre[0];
        let [_, cb, cc] = p.conic;
        let splat = Broadcast::new(p, opaque);
        // The terms of the footprint's exponent that rows `dy` share (`2 b dy`, `c dy^2`).
        let row_terms = |ly: usize| {
            let dy = (origin.1 + ly) as f32 + 0.5 - p.centre[1];
            (2.0 * cb * dy, cc * dy * dy)
        };
        let mut turned = 0;
        let mut ly = ly0;
        while ly <= ly1 {
            if lx1 - lx0 < HALF && ly < ly1 {
                // This row's columns in the low half, the next row's in the high half.
                let rows = [tile.rows[ly] & span, tile.rows[ly + 1] & span];
                let lanes_open = ((u32::from(rows[0]) >> lx0) & 0xf)
                    | ((u32::from(rows[1]) >> lx0) & 0xf) << HALF;
                if lanes_open != 0 {
                    let [(by0, qy0), (by1, qy1)] = [row_terms(ly), row_terms(ly + 1)];
                    let halves =
                        |lo: f32, hi: f32| _mm256_set_m128(_mm_set1_ps(hi), _mm_set1_ps(lo));
                    let iota = _mm256_setr_ps(0.0, 1.0, 2.0, 3.0, 0.0, 1.0, 2.0, 3.0);
                    let dx = _mm256_add_ps(_mm256_set1_ps(dx0 + lx0 as f32), iota);
                    let at = ly * TILE + lx0;
                    let terms = (dx, halves(by0, by1), halves(qy0, qy1));
                    let done = splat.under::<TILE>(tile, at, terms, lanes_open);
                    // Lanes past a row's end were never open.
                    tile.rows[ly] &= !(((done & 0xf) << lx0) as u16);
                    tile.rows[ly + 1] &= !(((done >> HALF) << lx0) as u16);
                    turned += done.count_ones();
                }
                ly += 2;
                continue;
            }
            let open = tile.rows[ly] & span;
            if open == 0 {
                ly += 1;
                continue;
            }
            let (by, qy) = row_terms(ly);
            let (by, qy) = (_mm256_set1_ps(by), _mm256_set1_ps(qy));
            let iota = _mm256_setr_ps(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0);
            let mut closing = 0u32;
            // Groups start at the rectangle's left edge: most rows of a footprint fit in one.
            for start in (lx0..=lx1).step_by(LANES) {
                let lanes_open = (u32::from(open) >> start) & 0xff;
                if lanes_open == 0 {
                    continue;
                }
                let dx = _mm256_add_ps(_mm256_set1_ps(dx0 + start as f32), iota);
                let at = ly * TILE + start;
                closing |= splat.under::<HALF>(tile, at, (dx, by, qy), lanes_open) << start;
            }
            // Lanes past the row's end were never open: `closing` has no bit there.
            tile.rows[ly] &= !(closing as u16);
            turned += closing.count_ones();
            ly += 1;
        }
        turned
    }

    /// Columns a footprint spans at most for [`composite_splat`] to take two of its rows a
    /// vector: half its lanes.
    pub(in crate::splat::tiled) const HALF: usize = LANES / 2;

    /// A splat's values in every lane, for [`Broadcast::under`].
    struct Broadcast {
        conic_a: __m256,
        cutoff: __m256,
        depth: __m256,
        color: [__m256; 4],
        opaque: __m256,
    }

    impl Broadcast {
        #[target_feature(enable = "avx2")]
        #[inline]
        fn new(p: &Projected, opaque: f32) -> Self {
            Self {
                conic_a: _mm256_set1_ps(p.conic[0]),
                cutoff: _mm256_set1_ps(p.cutoff),
                depth: _mm256_set1_ps(p.depth),
                color: p.color.map(|c| _mm256_set1_ps(c)),
                opaque: _mm256_set1_ps(opaque),
            }
        }

        /// Composites the splat under eight pixels of the tile: lanes 0-3 from pixel `at`
        /// of the planes on, lanes 4-7 from pixel `at + HI` on (`HI` [`HALF`]: eight pixels
        /// along a row; [`TILE`]: four of a row and the four below them). `dx` is each
        /// lane's offset from the centre along x, `by` and `qy` its row's terms of the
        /// exponent, and bit `l` of `lanes_open` says whether lane `l`'s pixel is open.
        /// Returns the lanes that turned opaque, a bit each.
        #[target_feature(enable = "avx2,fma")]
        #[inline]
        fn under<const HI: usize>(
            &self,
            tile: &mut TilePixels,
            at: usize,
            (dx, by, qy): (__m256, __m256, __m256),
            lanes_open: u32,
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
            let q = _mm256_fmadd_ps(_mm256_fmadd_ps(self.conic_a, dx, by), dx, qy);
            let falloff = exp_neg_half(q);
            let bits = lane_bits();
            let mask = _mm256_and_si256(_mm256_set1_epi32(lanes_open as i32), bits);
            let open = _mm256_castsi256_ps(_mm256_cmpeq_epi32(mask, bits));
            let [cr, cg, cb, calpha] = self.color;
            #[allow(unsafe_code)]
            // SAFETY: each stretch holds HI + HALF floats, so a half at 0 and one at HI.
            unsafe {
                let load = |v: *const f32| {
                    if HI == HALF {
                        _mm256_loadu_ps(v)
                    } else {
                        _mm256_loadu2_m128(v.add(HI), v)
                    }
                };
                let store = |v: *mut f32, x: __m256| {
                    if HI == HALF {
                        _mm256_storeu_ps(v, x)
                    } else {
                        _mm256_storeu2_m128(v.add(HI), v, x)
                    }
                };
                let live = _mm256_and_ps(
                    _mm256_and_ps(open, _mm256_cmp_ps::<_CMP_LE_OQ>(q, self.cutoff)),
                    _mm256_cmp_ps::<_CMP_GE_OQ>(self.depth, load(d.as_ptr())),
                );
                let alpha = load(a.as_ptr());
                let weight = _mm256_and_ps(
                    live,
                    _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(1.0), alpha), falloff),
                );
                for (plane, c) in [(r, cr), (g, cg), (b, cb)] {
                    store(
                        plane.as_mut_ptr(),
                        _mm256_fmadd_ps(weight, c, load(plane.as_ptr())),
                    );
                }
                let after = _mm256_fmadd_ps(weight, calpha, alpha);
                store(a.as_mut_ptr(), after);
                let done = _mm256_and_ps(live, _mm256_cmp_ps::<_CMP_GE_OQ>(after, self.opaque));
                _mm256_movemask_ps(done) as u32
            }
        }
    }

    /// [`super::Group::project`] for up to [`LANES`] splats: [`super::project`] with the
    /// splats' arithmetic in vectors. Reading the voxels' texels, testing the opaque pixels
    /// and writing the results stay a lane at a time.
    ///
    /// # Safety
    ///
    /// The processor must have AVX2, FMA and POPCNT.
    #[target_feature(enable = "avx2,fma,popcnt")]
    #[allow(unsafe_code)]
    pub(in crate::splat::tiled) unsafe fn project(
        group: &Group<'_>,
        voxels: &[[u32; 3]],
        out: &mut [Projected],
    ) -> (usize, usize) {
        let n = voxels.len().min(out.len()).min(LANES);
        if n == 0 {
            return (0, 0);
        }
        let u = group.u;
        let mut k = [[0.0f32; LANES]; 3];
        for l in 0..LANES {
            // Lanes past the end repeat the last splat; their results are dropped.
            for axis in 0..3 {
                k[axis][l] = voxels[l.min(n - 1)][axis] as f32;
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
        let margin = splat(RECT_MARGIN);
        let ex = _mm256_fmadd_ps(radius, _mm256_sqrt_ps(a), margin);
        let ey = _mm256_fmadd_ps(radius, _mm256_sqrt_ps(c), margin);
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
            let peak = u.alpha_of(&t);
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
