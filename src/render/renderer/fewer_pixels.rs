//! Volumes composited at fewer pixels than the frame ([`FrameOptions::volume_divisor`]) and
//! laid over the frame's meshes at its own size.
//!
//! A coarse level of detail's splats lie several pixels apart, and their footprints are as
//! wide: the picture of the volume holds nothing finer than them, and compositing it at a
//! pixel every two or three loses little. The meshes' silhouettes are as sharp as the pixels,
//! though, and each splat is depth-tested against them. So the meshes are drawn at the frame's
//! size, the volume composited at the smaller size against their depth taken at the nearest
//! surface within each coarse pixel, and the result scaled up with its depth in mind: each
//! frame pixel takes the coarse pixels around it (bilinearly) whose depth is its own, so that
//! the volume behind a mesh's silhouette reaches the silhouette instead of leaving a rim of
//! its coarse pixels' width around it. This is the joint upsampling of off-screen particles
//! in games ("nearest-depth upsampling": Cantlay, "High-Speed, Off-Screen Particles", GPU Gems
//! 3, ch. 23, 2007), done here on the CPU; no crate does it for our frames.

use rayon::prelude::*;

use crate::render::view::ViewSetup;
use crate::splat::reference::Frame;

/// Two reversed depths (1 at the near plane, 0 where no surface lies) are one surface's where
/// they differ by at most this fraction of the larger: a perspective depth is the near plane's
/// distance over the pixel's, so this is the same fraction of the distance.
const SAME_SURFACE: f32 = 0.02;

/// Where the centre of frame pixel `x` (one axis) falls in the coarse image, in its pixels
/// (coarse pixel `i` centred at `i`), for a frame `full` pixels across and a coarse image
/// `coarse` across whose pixels are `1 / scale` frame pixels: both share the principal point
/// at their centres.
fn coarse_at(x: f64, full: u32, coarse: u32, scale: f64) -> f64 {
    (x + 0.5 - 0.5 * f64::from(full)) * scale + 0.5 * f64::from(coarse) - 0.5
}

/// The pixels of `coarse`'s image per pixel of `full`'s: the two views must be one camera's.
pub(super) fn scale_between(full: &ViewSetup, coarse: &ViewSetup) -> f64 {
    coarse.focal / full.focal
}

/// The depth of each coarse pixel: the nearest surface (the largest reversed depth) among the
/// frame pixels whose centres lie within it (the one nearest its centre where none does).
pub(super) fn coarse_depth(
    depth: &[f32],
    full: (u32, u32),
    coarse: (u32, u32),
    scale: f64,
) -> Vec<f32> {
    // The frame pixels a coarse pixel spans along one axis.
    let span = |i: u32, full_n: u32, coarse_n: u32| {
        // Coarse pixel i's centre and half width, in frame pixel coordinates (edges at
        // integers).
        let centre =
            (f64::from(i) + 0.5 - 0.5 * f64::from(coarse_n)) / scale + 0.5 * f64::from(full_n);
        let half = 0.5 / scale;
        let last = f64::from(full_n - 1);
        let lo = (centre - half - 0.5).ceil().clamp(0.0, last) as usize;
        let hi = (centre + half - 0.5).floor().clamp(0.0, last) as usize;
        let nearest = (centre - 0.5).round().clamp(0.0, last) as usize;
        if lo <= hi {
            (lo, hi)
        } else {
            (nearest, nearest)
        }
    };
    let columns: Vec<_> = (0..coarse.0).map(|i| span(i, full.0, coarse.0)).collect();
    let width = full.0 as usize;
    let mut out = vec![0.0; coarse.0 as usize * coarse.1 as usize];
    out.par_chunks_mut(coarse.0 as usize)
        .enumerate()
        .for_each(|(j, row)| {
            let (y0, y1) = span(j as u32, full.1, coarse.1);
            for (d, &(x0, x1)) in row.iter_mut().zip(&columns) {
                *d = (y0..=y1)
                    .flat_map(|y| &depth[y * width + x0..=y * width + x1])
                    .fold(0.0f32, |m, &v| m.max(v));
            }
        });
    out
}

/// Lays the coarse volume image `volume` (premultiplied, composited over nothing against
/// `volume_depth`, [`coarse_depth`]'s) over `frame` (the meshes and the background, whose
/// reversed depth per pixel is `depth`), scaled up to the frame: each frame pixel takes the
/// four coarse pixels around its centre, bilinearly weighted, of those whose depth is its
/// own surface's ([`SAME_SURFACE`]); where none is, the one whose depth is nearest its own.
pub(super) fn lay_volume_over(
    frame: &mut Frame,
    depth: &[f32],
    volume: &Frame,
    volume_depth: &[f32],
    scale: f64,
) {
    let (fw, fh) = (frame.width, frame.height);
    let (cw, ch) = (volume.width as usize, volume.height as usize);
    // Per frame column: the two coarse columns around it and the weight of the second.
    let along = |x: u32, full: u32, coarse: usize| {
        let at = coarse_at(f64::from(x), full, coarse as u32, scale);
        let last = coarse.saturating_sub(1);
        let i0 = at.floor();
        let t = (at - i0) as f32;
        let clamp = |i: f64| (i.max(0.0) as usize).min(last);
        (clamp(i0), clamp(i0 + 1.0), t)
    };
    let columns: Vec<_> = (0..fw).map(|x| along(x, fw, cw)).collect();
    frame
        .pixels
        .par_chunks_mut(fw as usize)
        .zip(depth.par_chunks(fw as usize))
        .enumerate()
        .for_each(|(y, (row, depth_row))| {
            let (j0, j1, ty) = along(y as u32, fh, ch);
            for ((px, &d), &(i0, i1, tx)) in row.iter_mut().zip(depth_row).zip(&columns) {
                let around = [
                    (j0 * cw + i0, (1.0 - tx) * (1.0 - ty)),
                    (j0 * cw + i1, tx * (1.0 - ty)),
                    (j1 * cw + i0, (1.0 - tx) * ty),
                    (j1 * cw + i1, tx * ty),
                ];
                // Most of a frame lies where the volume is clear: nothing to lay over.
                if around.iter().all(|&(k, _)| volume.pixels[k][3] <= 0.0) {
                    continue;
                }
                let gap = |k: usize| (volume_depth[k] - d).abs();
                let same = |k: usize| gap(k) <= SAME_SURFACE * volume_depth[k].max(d);
                let mut sum = [0.0f32; 4];
                let mut weight = 0.0f32;
                for &(k, w) in &around {
                    if same(k) {
                        let v = volume.pixels[k];
                        for c in 0..4 {
                            sum[c] += w * v[c];
                        }
                        weight += w;
                    }
                }
                let v = if weight > 1e-3 {
                    sum.map(|s| s / weight)
                } else {
                    let (k, _) = around
                        .iter()
                        .min_by(|a, b| gap(a.0).total_cmp(&gap(b.0)))
                        .copied()
                        .unwrap_or((0, 0.0));
                    volume.pixels[k]
                };
                *px = std::array::from_fn(|c| v[c] + (1.0 - v[3]) * px[c]);
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_pixels_map_to_the_coarse_pixels_that_cover_them() {
        // Half the pixels: frame pixels 0 and 1 straddle coarse pixel 0's centre.
        assert_eq!(coarse_at(0.0, 8, 4, 0.5), -0.25);
        assert_eq!(coarse_at(1.0, 8, 4, 0.5), 0.25);
        assert_eq!(coarse_at(7.0, 8, 4, 0.5), 3.25);
        // One scale: the same pixel.
        assert_eq!(coarse_at(5.0, 9, 9, 1.0), 5.0);
    }

    #[test]
    fn a_coarse_pixel_takes_the_nearest_surface_within_it() {
        // 4 x 2 frame pixels, halved: each coarse pixel spans a 2 x 2 block.
        let depth = [0.0, 0.5, 0.0, 0.0, 0.2, 0.0, 0.0, 0.1];
        assert_eq!(coarse_depth(&depth, (4, 2), (2, 1), 0.5), vec![0.5, 0.1]);
    }

    #[test]
    fn a_pixel_beside_a_silhouette_takes_the_volume_of_its_own_surface() {
        // A frame 4 pixels wide, 1 high; a mesh in front over pixels 0 and 1 (depth 0.5, red,
        // opaque), nothing behind pixels 2 and 3. The coarse image (2 pixels): the volume in
        // front of the mesh is clear (pixel 0, depth 0.5), behind it, white at half opacity
        // (pixel 1, depth 0).
        let mesh = [1.0, 0.0, 0.0, 1.0];
        let mut frame = Frame {
            width: 4,
            height: 1,
            pixels: vec![mesh, mesh, [0.0; 4], [0.0; 4]],
        };
        let depth = [0.5, 0.5, 0.0, 0.0];
        let volume = Frame {
            width: 2,
            height: 1,
            pixels: vec![[0.0; 4], [0.5; 4]],
        };
        lay_volume_over(&mut frame, &depth, &volume, &[0.5, 0.0], 0.5);
        // Pixel 1 lies between both coarse pixels, bilinearly 3/4 of pixel 0's: it takes
        // pixel 0's alone, its own surface; pixel 2 (3/4 of pixel 1's) takes pixel 1's alone.
        assert_eq!(frame.pixels, vec![mesh, mesh, [0.5; 4], [0.5; 4]]);
    }

    #[test]
    fn one_surface_is_scaled_up_bilinearly() {
        let mut frame = Frame {
            width: 4,
            height: 1,
            pixels: vec![[0.0; 4]; 4],
        };
        let volume = Frame {
            width: 2,
            height: 1,
            pixels: vec![[0.0; 4], [0.4; 4]],
        };
        lay_volume_over(&mut frame, &[0.0; 4], &volume, &[0.0; 2], 0.5);
        let red: Vec<f32> = frame.pixels.iter().map(|p| p[0]).collect();
        // Clamped at the edges, 1/4 and 3/4 between the centres.
        for (got, want) in red.iter().zip([0.0, 0.1, 0.3, 0.4]) {
            assert!((got - want).abs() < 1e-6, "{red:?}");
        }
    }
}
