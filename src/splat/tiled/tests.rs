//! Unit tests of the tile compositor's stages.

use super::bin::*;
use super::mask::*;
use super::project::*;
use super::simd::*;
use super::texels::*;
use super::tile::*;
use super::*;
use crate::grid::SparseGrid;
use glam::Vec3;
use strength_reduce::StrengthReducedU32;

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
    splats_of(0x2545_f491, 400, (0.3, 3.0))
}

/// `count` splats as [`splats`] gives them, from seed `state`, their variances along x and y
/// from `variance.0` to `variance.0 + variance.1`.
fn splats_of(mut state: u32, count: usize, variance: (f32, f32)) -> Vec<Projected> {
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        state as f32 / u32::MAX as f32
    };
    (0..count)
        .map(|_| {
            let centre = [12.0 + 24.0 * next(), 28.0 + 24.0 * next()];
            let (sx, sy) = (
                variance.0 + variance.1 * next(),
                variance.0 + variance.1 * next(),
            );
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
    lanes_composite_as_a_pixel_by_pixel_loop_does(&splats(), &depth, OPAQUE);
}

/// The portable loop's groups of half the lanes, for footprints at most 4 pixels wide.
#[test]
fn narrow_footprints_composite_as_a_pixel_by_pixel_loop_does() {
    let splats = splats_of(0x9e37_79b9, 2000, (0.05, 0.35));
    lanes_composite_as_a_pixel_by_pixel_loop_does(&splats, &narrow_depth(), 0.9);
}

/// The meshes in front of some splats in the left half of the 40x40 image, none in its right.
fn narrow_depth() -> Vec<f32> {
    (0..40 * 40)
        .map(|i| {
            if i % 40 < 24 {
                (i % 3) as f32 * 0.3
            } else {
                0.0
            }
        })
        .collect()
}

/// The portable loop (whatever the processor) against a scalar loop over every pixel.
fn lanes_composite_as_a_pixel_by_pixel_loop_does(splats: &[Projected], depth: &[f32], opaque: f32) {
    let mut tile = fresh_tile(depth);
    let mut reference = vec![[0.0f32; 4]; PIXELS];
    let bins = [one_list(splats.len())];
    let batch = Batch {
        opaque,
        ..batch(splats, &bins)
    };
    composite_tile_lanes(&mut tile, 0, (16, 32), batch, composite_splat_lanes);
    for &p in splats {
        // The old scalar loop, pixel by pixel over the quad's rectangle, with libm's exp.
        for y in p.y0.max(32)..=p.y1.min(32 + 15).min(39) {
            for x in p.x0.max(16)..=p.x1.min(16 + 15).min(39) {
                let px = &mut reference[(y as usize - 32) * TILE + x as usize - 16];
                if px[3] >= opaque || p.depth < depth[y as usize * 40 + x as usize] {
                    continue;
                }
                let (dx, dy) = (x as f32 + 0.5 - p.centre[0], y as f32 + 0.5 - p.centre[1]);
                let q = p.conic[0] * dx * dx + 2.0 * p.conic[1] * dx * dy + p.conic[2] * dy * dy;
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
    assert!(covered > 80, "the splats cover the tile ({covered} pixels)");
    assert!(worst < 1e-5, "largest difference {worst}");
}

#[test]
fn the_avx2_kernel_gives_the_pixels_of_the_baseline_kernel() {
    let depth: Vec<f32> = (0..40 * 40).map(|i| (i % 7) as f32 * 0.1).collect();
    avx2_kernel_gives_the_pixels_of_the_baseline_kernel(&splats(), &depth, OPAQUE);
}

/// Footprints at most 4 pixels wide, which the AVX2 kernel takes two rows a vector: among
/// them footprints that start in the tile's last columns (their lanes run past the row's
/// end), reach past the image's bottom edge (a pair's second row off the image) or straddle
/// the tile's edges, partly behind meshes.
#[test]
fn the_avx2_kernel_gives_the_baseline_pixels_for_narrow_footprints() {
    let splats = splats_of(0x9e37_79b9, 2000, (0.05, 0.35));
    let narrow = splats
        .iter()
        .filter(|p| p.x1 - p.x0 < 4 && p.y1 > p.y0)
        .count();
    assert!(narrow > 1500, "{narrow} footprints at most 4 pixels wide");
    let at_right = splats
        .iter()
        .filter(|p| p.x0 >= 16 + 13 && p.x0 < 32)
        .count();
    assert!(
        at_right > 20,
        "{at_right} footprints start in the tile's last columns"
    );
    // Pixels stop at 0.9, so that many turn opaque in a vector's either half.
    avx2_kernel_gives_the_pixels_of_the_baseline_kernel(&splats, &narrow_depth(), 0.9);
}

fn avx2_kernel_gives_the_pixels_of_the_baseline_kernel(
    splats: &[Projected],
    depth: &[f32],
    opaque: f32,
) {
    #[cfg(target_arch = "x86_64")]
    if has_avx2() {
        let (mut wide, mut narrow) = (fresh_tile(depth), fresh_tile(depth));
        let bins = [one_list(splats.len())];
        #[allow(unsafe_code)]
        // SAFETY: the features were checked above.
        unsafe {
            avx2::composite_tile(
                &mut wide,
                0,
                (16, 32),
                Batch {
                    opaque,
                    ..batch(splats, &bins)
                },
            )
        };
        composite_tile_lanes(
            &mut narrow,
            0,
            (16, 32),
            Batch {
                opaque,
                ..batch(splats, &bins)
            },
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
        // Most pixels covered, some turned opaque.
        let covered = narrow.a.iter().filter(|&&a| a > 0.5).count();
        assert!(covered > 80, "{covered} pixels covered");
        assert!(narrow.open < 8 * 16 - 8, "{} pixels open", narrow.open);
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
        stretches.extend((0..97).map(|k| (0..32).map(|i| (k * 31 + i * 211) % count).collect()));
        stretches.extend((0..count).step_by(7).map(|id| vec![id]));
        let mut tested = 0;
        for ids in &stretches {
            let rects: Vec<[i32; 4]> = ids
                .iter()
                .filter_map(|&id| {
                    place(&u, camera_centre(&u, voxel(&u, id)), 64, 48).map(|at| at.rect)
                })
                .collect();
            let voxels: Vec<[u32; 3]> = ids.iter().map(|&id| voxel(&u, id)).collect();
            let Some(group) = group_rect(&u, &voxels, &s) else {
                continue;
            };
            for r in &rects {
                assert!(
                    group[0] <= r[0] && group[1] <= r[1] && group[2] >= r[2] && group[3] >= r[3],
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
                let voxels: Vec<[u32; 3]> =
                    (0..20 * 18 * 16).rev().map(|id| voxel(&u, id)).collect();
                let mut wide = vec![Projected::default(); voxels.len()];
                let mut each = wide.clone();
                let (mut culled, mut kept) = ([0; 2], [0; 2]);
                for voxels in voxels.chunks(GROUP) {
                    for voxels in voxels.chunks(5) {
                        #[allow(unsafe_code)]
                        // SAFETY: the features were checked above.
                        let (c, k) = unsafe { avx2::project(&group, voxels, &mut wide[kept[0]..]) };
                        culled[0] += c;
                        kept[0] += k;
                    }
                    let (c, k) = group.project_each(voxels, &mut each[kept[1]..]);
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

/// A splat's pixel rectangle is its cut-off ellipse's bounding box: it holds every pixel
/// centre the ellipse holds (found by testing each pixel of the image, with the footprint
/// in f64), and no row or column of it lies farther from the centre than the ellipse reaches.
#[test]
fn a_splat_rectangle_is_the_bounding_box_of_its_cut_off_ellipse() {
    use crate::splat::footprint::{Lens, footprint};
    for orthographic in [false, true] {
        let (u, _) = grid_and_view(orthographic);
        let (w, h) = (64, 48);
        let lens = Lens {
            focal: f64::from(u.focal),
            centre: u.centre.map(f64::from),
            pixel_variance: f64::from(u.pixel_variance),
            orthographic,
        };
        let cov = u.cov.map(|r| r.to_array().map(f64::from));
        let radius = f64::from(u.cutoff).sqrt();
        let (mut checked, mut edge) = (0, 0);
        for id in 0..u.dims.iter().product::<u32>() {
            let p = camera_centre(&u, voxel(&u, id));
            let Some(at) = place(&u, p, w, h) else {
                continue;
            };
            let fp = footprint(p.to_array().map(f64::from), &cov, &lens).unwrap();
            let [a, b, c] = fp.cov;
            let det = a * c - b * b;
            let [x0, y0, x1, y1] = at.rect;
            for y in 0..h {
                for x in 0..w {
                    let (dx, dy) = (
                        f64::from(x) + 0.5 - fp.centre[0],
                        f64::from(y) + 0.5 - fp.centre[1],
                    );
                    let q = (c * dx * dx - 2.0 * b * dx * dy + a * dy * dy) / det;
                    let inside = (x0..=x1).contains(&x) && (y0..=y1).contains(&y);
                    // Pixels within rounding of the cut-off may go either way.
                    if q <= f64::from(u.cutoff) * (1.0 - 1e-4) {
                        assert!(inside, "pixel ({x}, {y}), q {q}, outside {:?}", at.rect);
                        edge += usize::from(q > f64::from(u.cutoff) * 0.8);
                    }
                    if inside {
                        assert!(
                            dx.abs() <= radius * a.sqrt() + 0.02
                                && dy.abs() <= radius * c.sqrt() + 0.02,
                            "pixel ({x}, {y}) past the ellipse's box, in {:?}",
                            at.rect
                        );
                    }
                }
            }
            checked += 1;
        }
        assert!(
            checked > 1000 && edge > 1000,
            "{checked} splats, {edge} edge pixels"
        );
    }
}

/// The opaque-pixel test of a rectangle against a pixel-by-pixel look, on masks with runs of
/// opaque pixels across word boundaries and rectangles of every shape.
#[test]
fn a_rectangle_is_covered_as_its_pixels_say() {
    let (w, h) = (150usize, 40usize);
    let mut state = 0x1234_5677u32;
    let mut next = move |n: usize| {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        state as usize % n
    };
    let (mut covered, mut open) = (0, 0);
    for round in 0..40 {
        // Opaque blocks of varied size; early rounds sparse, later ones dense.
        let mut opaque = vec![false; w * h];
        for _ in 0..(round * 3) {
            let (x, y, bw, bh) = (next(w), next(h), 1 + next(70), 1 + next(12));
            for yy in y..(y + bh).min(h) {
                for xx in x..(x + bw).min(w) {
                    opaque[yy * w + xx] = true;
                }
            }
        }
        let mut mask = OpaqueMask::default();
        mask.reset(w, h);
        for ty in 0..h.div_ceil(TILE) {
            for tx in 0..w.div_ceil(TILE) {
                let mut rows = [0u16; TILE];
                for (ly, row) in rows.iter_mut().enumerate() {
                    for lx in 0..TILE {
                        let (x, y) = (tx * TILE + lx, ty * TILE + ly);
                        if x < w && y < h && !opaque[y * w + x] {
                            *row |= 1 << lx;
                        }
                    }
                }
                mask.set_tile(tx * TILE, ty * TILE, &rows);
            }
        }
        for _ in 0..200 {
            let (x0, y0) = (next(w), next(h));
            let (x1, y1) = ((x0 + next(90)).min(w - 1), (y0 + next(9)).min(h - 1));
            let pixels: Vec<bool> = (y0..=y1)
                .flat_map(|y| (x0..=x1).map(move |x| (x, y)))
                .map(|(x, y)| opaque[y * w + x])
                .collect();
            let rect = [x0, y0, x1, y1].map(|v| v as i32);
            assert_eq!(
                mask.covers_rect(rect),
                pixels.iter().all(|&o| o),
                "{rect:?}"
            );
            covered += usize::from(mask.covers_rect(rect));
            open += usize::from(!pixels.iter().any(|&o| o));
        }
    }
    assert!(
        covered > 100 && open > 100,
        "covered {covered}, all open {open}"
    );
    // Rectangles empty or not on the image are not covered.
    let mut mask = OpaqueMask::default();
    mask.reset(w, h);
    mask.bits.fill(u64::MAX);
    assert!(mask.covers_rect([0, 0, 5, 5]));
    assert!(!mask.covers_rect([-1, 0, 5, 5]) && !mask.covers_rect([5, 0, 4, 5]));
}

#[test]
fn a_draw_order_cut_into_runs_of_several_sources_composites_as_one_order() {
    for orthographic in [false, true] {
        let (u, texels) = grid_and_view(orthographic);
        // Every significant voxel four times over (more splats than the first batch takes),
        // far and near in turn.
        let ids: Vec<u32> = (0..20 * 18 * 16)
            .rev()
            .filter(|&id| texels.get(id % 20, id / 20 % 18, id / 360).is_some())
            .collect::<Vec<_>>()
            .repeat(4);
        let size = (64, 48);
        let background = vec![[0.1, 0.2, 0.3, 1.0]; 64 * 48];
        let depth = vec![0.0; 64 * 48];
        let mut whole = background.clone();
        let mut compositor = TiledCompositor::new();
        let one = compositor.composite(size, &[(u.clone(), &texels, &ids)], &depth, &mut whole);
        // The same splats as runs of 1 to 700 splats (and empty ones), from two sources that
        // hold the same grid, taken in turn.
        let (other, other_texels) = grid_and_view(orthographic);
        let sources = [(&u, &texels), (&other, &other_texels)];
        let mut runs = Vec::new();
        let (mut at, mut cut) = (0, 1usize);
        while at < ids.len() {
            let end = (at + cut).min(ids.len());
            runs.push(Run {
                source: runs.len() % 2,
                ids: &ids[at..end],
            });
            runs.push(Run {
                source: 0,
                ids: &ids[end..end],
            });
            at = end;
            cut = cut * 7 % 701 + 1;
        }
        assert!(runs.len() > 20, "{} runs", runs.len());
        let mut cut_image = background.clone();
        let many =
            TiledCompositor::new().composite_runs(size, &sources, &runs, &depth, &mut cut_image);
        assert_eq!(whole, cut_image, "orthographic {orthographic}");
        assert_eq!(
            (one.splats, one.projected, one.drew, one.composited),
            (many.splats, many.projected, many.drew, many.composited)
        );
        assert!(one.drew > 1000, "{} splats drew", one.drew);
    }
}

/// The AVX-512 loop does each lane's arithmetic as the AVX2 loop does, so it leaves the same
/// bits: footprints 2 to 14 pixels wide (the AVX2 loop's two rows of 4, the AVX-512 loop's
/// two rows of 8 and its whole rows), some past the tile's edges and the image's bottom,
/// partly behind meshes, with pixels stopping at 0.9 and at the compositor's own opacity.
#[test]
fn the_avx512_kernel_gives_the_bits_of_the_avx2_kernel() {
    #[cfg(target_arch = "x86_64")]
    if super::simd512::has_avx512() {
        let mut splats = splats_of(0x1234_5679, 1500, (0.05, 0.6));
        splats.extend(splats_of(0x7f4a_7c15, 600, (0.3, 4.0)));
        let widths = |lo: i32, hi: i32| {
            splats
                .iter()
                .filter(|p| (lo..=hi).contains(&(p.x1 - p.x0 + 1)))
                .count()
        };
        for (lo, hi) in [(1, 4), (5, 8), (9, 16)] {
            assert!(
                widths(lo, hi) > 150,
                "{} footprints {lo}-{hi} wide",
                widths(lo, hi)
            );
        }
        for (depth, opaque) in [(narrow_depth(), 0.9), (narrow_depth(), OPAQUE)] {
            let bins = [one_list(splats.len())];
            let run = |kernel: unsafe fn(&mut TilePixels, usize, (usize, usize), Batch<'_>)| {
                let mut tile = fresh_tile(&depth);
                #[allow(unsafe_code)]
                // SAFETY: the processor has AVX-512, and so AVX2, checked above.
                unsafe {
                    kernel(
                        &mut tile,
                        0,
                        (16, 32),
                        Batch {
                            opaque,
                            ..batch(&splats, &bins)
                        },
                    )
                };
                tile
            };
            let (wide, narrow) = (
                run(super::simd512::composite_tile),
                run(avx2::composite_tile),
            );
            assert_eq!(wide.rows, narrow.rows);
            assert_eq!(wide.open, narrow.open);
            assert_eq!(wide.composited, narrow.composited);
            let bits = |t: &TilePixels| [&t.r, &t.g, &t.b, &t.a].map(|p| p.map(f32::to_bits));
            assert!(bits(&wide) == bits(&narrow), "the planes' bits differ");
            let covered = narrow.a.iter().filter(|&&a| a > 0.5).count();
            assert!(covered > 80, "{covered} pixels covered");
            assert!(narrow.open < 8 * 16 - 8, "{} pixels open", narrow.open);
        }
    } else {
        eprintln!("no AVX-512 here: the AVX-512 kernel is not tested");
    }
}
