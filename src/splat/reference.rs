//! The CPU reference compositor and the error measure.
//!
//! Each significant voxel is an ellipsoidal Gaussian whose axes follow the grid (so its extent
//! is proportional to the spacing), projected in perspective with the local affine
//! approximation of the projection (EWA): its screen footprint grows toward the eye. Fragments
//! are composited with premultiplied "over", `dst = src + (1 - src.a) * dst`, in draw order,
//! so the image depends on the ordering exactly as a GPU blend would.
//!
//! The error of an ordering is its frame compared with the exact order's frame:
//! [`compare`] gives the RMSE over pixels and colour channels, the largest difference and the
//! share of pixels with a channel off by more than 4/255; [`FragmentStats`] gives, over every
//! pixel, the share of consecutive fragments drawn nearer-before-farther.

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use thiserror::Error;

use crate::camera::{Camera, CameraError};
use crate::geometry::VolumeGeometry;
use crate::grid::SparseGrid;
use crate::splat::footprint::{Lens, footprint};

/// Why a frame could not be composited.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum CompositeError {
    /// The camera is unusable.
    #[error(transparent)]
    Camera(#[from] CameraError),
    /// There must be one colour per significant voxel.
    #[error("{colors} colours for {voxels} significant voxels")]
    ColorCount {
        /// Colours given.
        colors: usize,
        /// Significant voxels in the grid.
        voxels: usize,
    },
    /// The draw order names a voxel that is not significant.
    #[error("draw order entry {position} is voxel {id}, which is not a significant voxel")]
    NotSignificant {
        /// Position in the draw order.
        position: usize,
        /// The voxel id.
        id: u32,
    },
    /// Grid and geometry disagree on the size.
    #[error("grid size {grid:?} differs from the geometry's {geometry:?}")]
    DimsMismatch {
        /// Size of the voxel set.
        grid: [u32; 3],
        /// Size of the placement.
        geometry: [u32; 3],
    },
    /// Images of different sizes cannot be compared.
    #[error("cannot compare a {0}x{1} image with a {2}x{3} image")]
    SizeMismatch(u32, u32, u32, u32),
    /// The image would take more memory than a CPU frame is allowed.
    #[error(
        "a {width}x{height} image is larger than the CPU compositor draws ({MAX_PIXELS} pixels at most, 8192x8192)"
    )]
    TooLarge {
        /// Width asked for.
        width: u32,
        /// Height asked for.
        height: u32,
    },
}

/// The most pixels the CPU compositor draws in one frame (8192 x 8192: 1 GiB of f32 RGBA).
pub const MAX_PIXELS: u64 = crate::budget::MAX_PIXELS;

/// Checks that a `width` x `height` frame is within [`MAX_PIXELS`].
pub fn check_frame_size(width: u32, height: u32) -> Result<(), CompositeError> {
    if u64::from(width) * u64::from(height) > MAX_PIXELS {
        return Err(CompositeError::TooLarge { width, height });
    }
    Ok(())
}

/// Splat shape, in voxel units along each grid axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SplatStyle {
    /// Standard deviation of the Gaussian (the original ShellSplatting used 0.7; the default is
    /// [`crate::classify::DEFAULT_SIGMA`]).
    pub sigma: f64,
    /// Footprint radius where the Gaussian is cut off (the original used 2.0; the default is
    /// [`crate::classify::DEFAULT_CUTOFF`]).
    pub cutoff: f64,
    /// Screen-space variance in square pixels added to every footprint, so that splats smaller
    /// than a pixel still cover one (the EWA low-pass filter); the splat's opacity shrinks so
    /// that the footprint's integral is that of the unwidened one (Mip-Splatting's 2-D filter),
    /// and sub-pixel splats do not pile up opacity.
    pub pixel_variance: f64,
}

impl Default for SplatStyle {
    fn default() -> Self {
        Self {
            sigma: crate::classify::DEFAULT_SIGMA,
            cutoff: crate::classify::DEFAULT_CUTOFF,
            pixel_variance: 0.3,
        }
    }
}

/// A classified volume ready to splat: placement, significant voxels, and one premultiplied
/// RGBA colour per significant voxel in id order.
#[derive(Debug, Clone, Copy)]
pub struct SplatVolume<'a> {
    /// Placement in the world.
    pub geometry: &'a VolumeGeometry,
    /// Significant voxels.
    pub grid: &'a SparseGrid,
    /// Premultiplied RGBA per significant voxel, in id order (index = [`SparseGrid::rank`]).
    pub colors: &'a [[f32; 4]],
}

/// A composited image: premultiplied RGBA, rows top to bottom, transparent background.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Pixels, row-major.
    pub pixels: Vec<[f32; 4]>,
}

impl Frame {
    /// The frame over an opaque background colour, as 8-bit RGB.
    pub fn to_rgb8(&self, background: [f32; 3]) -> image::RgbImage {
        image::RgbImage::from_fn(self.width, self.height, |x, y| {
            let p = self.pixels[(y * self.width + x) as usize];
            image::Rgb(std::array::from_fn(|c| {
                let v = p[c] + (1.0 - p[3]) * background[c];
                (v.clamp(0.0, 1.0) * 255.0).round() as u8
            }))
        })
    }
}

/// Counts of consecutive fragment pairs per pixel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FragmentStats {
    /// Fragments drawn.
    pub fragments: u64,
    /// Consecutive pairs of fragments on the same pixel.
    pub pairs: u64,
    /// Pairs where the first drawn was nearer than the second.
    pub inversions: u64,
}

impl FragmentStats {
    /// Share of consecutive fragment pairs drawn nearer-before-farther (0 when no pairs).
    pub fn inversion_share(&self) -> f64 {
        if self.pairs == 0 {
            0.0
        } else {
            self.inversions as f64 / self.pairs as f64
        }
    }
}

/// A splat projected to the screen.
#[derive(Debug, Clone, Copy)]
struct Placed {
    centre: [f64; 2],
    /// Inverse 2D covariance (conic): `q = a dx^2 + 2 b dx dy + c dy^2`.
    conic: [f64; 3],
    /// Pixel bounds, inclusive.
    bounds: [i64; 4],
    color: [f32; 4],
    depth: f64,
}

/// Composites `volume`'s splats in the order `order` as seen by `camera`.
pub fn composite(
    camera: &Camera,
    volume: &SplatVolume<'_>,
    order: &[u32],
    style: &SplatStyle,
) -> Result<(Frame, FragmentStats), CompositeError> {
    check_frame_size(camera.width, camera.height)?;
    let footprints = project(camera, volume, order, style)?;
    let (width, height) = (camera.width as usize, camera.height as usize);
    let limit = (style.cutoff / style.sigma).powi(2);
    const BAND: usize = 16;
    let mut pixels = vec![[0f32; 4]; width * height];
    let stats = pixels
        .par_chunks_mut(width * BAND)
        .enumerate()
        .map(|(band, chunk)| {
            let y0 = (band * BAND) as i64;
            let rows = (chunk.len() / width) as i64;
            let mut last_depth = vec![f64::NAN; chunk.len()];
            let mut stats = FragmentStats::default();
            for f in &footprints {
                let (ya, yb) = (f.bounds[2].max(y0), f.bounds[3].min(y0 + rows - 1));
                for y in ya..=yb {
                    let dy = y as f64 + 0.5 - f.centre[1];
                    for x in f.bounds[0]..=f.bounds[1] {
                        let dx = x as f64 + 0.5 - f.centre[0];
                        let q = f.conic[0] * dx * dx
                            + 2.0 * f.conic[1] * dx * dy
                            + f.conic[2] * dy * dy;
                        if q > limit {
                            continue;
                        }
                        let w = (-0.5 * q).exp() as f32;
                        let i = (y - y0) as usize * width + x as usize;
                        let dst = &mut chunk[i];
                        let src_a = f.color[3] * w;
                        for (d, s) in dst.iter_mut().zip(f.color) {
                            *d = s * w + (1.0 - src_a) * *d;
                        }
                        let last = last_depth[i];
                        if !last.is_nan() {
                            stats.pairs += 1;
                            if last < f.depth * (1.0 - 1e-12) {
                                stats.inversions += 1;
                            }
                        }
                        last_depth[i] = f.depth;
                        stats.fragments += 1;
                    }
                }
            }
            stats
        })
        .reduce(FragmentStats::default, |a, b| FragmentStats {
            fragments: a.fragments + b.fragments,
            pairs: a.pairs + b.pairs,
            inversions: a.inversions + b.inversions,
        });
    let frame = Frame {
        width: camera.width,
        height: camera.height,
        pixels,
    };
    Ok((frame, stats))
}

/// Projects every splat of `order` (in order) to its screen footprint; splats whose centre is
/// nearer than the camera's near plane, or than a tenth of a voxel (where the local affine
/// projection is meaningless), are left out.
fn project(
    camera: &Camera,
    volume: &SplatVolume<'_>,
    order: &[u32],
    style: &SplatStyle,
) -> Result<Vec<Placed>, CompositeError> {
    let frame = camera.frame()?;
    let grid = volume.grid;
    if volume.colors.len() != grid.len() {
        return Err(CompositeError::ColorCount {
            colors: volume.colors.len(),
            voxels: grid.len(),
        });
    }
    if grid.dims() != volume.geometry.dims() {
        return Err(CompositeError::DimsMismatch {
            grid: grid.dims(),
            geometry: volume.geometry.dims(),
        });
    }
    // Camera coordinates of index point k: m * (k - eye_index); computed relative to the eye so
    // that far-away volumes keep their precision.
    let linear = volume.geometry.index_to_world().matrix3;
    let rows = DMat3::from_cols(frame.right, frame.up, frame.forward).transpose();
    let m = rows * linear;
    let eye_index = volume.geometry.world_to_index(camera.eye);
    let cov = m * m.transpose() * (style.sigma * style.sigma);
    let min_spacing = volume
        .geometry
        .spacing()
        .into_iter()
        .fold(f64::INFINITY, f64::min);
    let near = camera.near.max(0.1 * min_spacing);
    let radius = style.cutoff / style.sigma;
    let lens = Lens {
        focal: frame.focal,
        centre: [
            0.5 * f64::from(camera.width),
            0.5 * f64::from(camera.height),
        ],
        pixel_variance: style.pixel_variance,
        orthographic: false,
    };
    let cov = cov.transpose().to_cols_array_2d();
    let beside = crate::splat::footprint::beside_the_view(
        frame.focal,
        (f64::from(camera.width), f64::from(camera.height)),
        &cov,
        radius * radius,
        style.pixel_variance,
    );
    let (w, h) = (i64::from(camera.width), i64::from(camera.height));
    let mut out = Vec::with_capacity(order.len());
    for (position, &id) in order.iter().enumerate() {
        let rank = grid
            .rank(id)
            .ok_or(CompositeError::NotSignificant { position, id })?;
        let color = volume.colors[rank as usize];
        if color[3] <= 0.0 {
            continue;
        }
        let k = DVec3::from(grid.coords(id).map(f64::from));
        let p = m * (k - eye_index);
        if p.z <= near
            || beside
                .iter()
                .any(|c| c[0] * p.x + c[1] * p.y + c[2] * p.z > c[3])
        {
            continue;
        }
        let Some(footprint) = footprint(p.to_array(), &cov, &lens) else {
            continue;
        };
        let ([a, _, c], centre) = (footprint.cov, footprint.centre);
        let det = a * c - footprint.cov[1] * footprint.cov[1];
        if det.is_infinite() {
            continue;
        }
        let (ex, ey) = (radius * a.sqrt(), radius * c.sqrt());
        let bounds = [
            ((centre[0] - ex - 0.5).floor() as i64).max(0),
            ((centre[0] + ex - 0.5).ceil() as i64).min(w - 1),
            ((centre[1] - ey - 0.5).floor() as i64).max(0),
            ((centre[1] + ey - 0.5).ceil() as i64).min(h - 1),
        ];
        if bounds[0] > bounds[1] || bounds[2] > bounds[3] {
            continue;
        }
        out.push(Placed {
            centre,
            conic: footprint.conic(),
            bounds,
            color: color.map(|v| v * footprint.kept as f32),
            depth: p.length(),
        });
    }
    Ok(out)
}

/// Differences between two frames, over the colour channels of premultiplied RGBA (the image
/// over a black background); alpha is left out because it does not depend on the order.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ImageDifference {
    /// Root mean square difference over pixels and the three colour channels.
    pub rmse: f64,
    /// Largest absolute difference of any channel.
    pub max_abs: f64,
    /// Share of pixels with any colour channel off by more than 4/255.
    pub bad_pixel_share: f64,
}

/// Compares two frames of the same size.
pub fn compare(a: &Frame, b: &Frame) -> Result<ImageDifference, CompositeError> {
    if (a.width, a.height) != (b.width, b.height) {
        return Err(CompositeError::SizeMismatch(
            a.width, a.height, b.width, b.height,
        ));
    }
    let mut sum = 0.0f64;
    let mut max_abs = 0.0f64;
    let mut bad = 0usize;
    for (p, q) in a.pixels.iter().zip(&b.pixels) {
        let mut worst = 0.0f64;
        for c in 0..3 {
            let d = f64::from(p[c] - q[c]).abs();
            sum += d * d;
            worst = worst.max(d);
        }
        max_abs = max_abs.max(worst);
        bad += usize::from(worst > 4.0 / 255.0);
    }
    let n = a.pixels.len().max(1) as f64;
    Ok(ImageDifference {
        rmse: (sum / (3.0 * n)).sqrt(),
        max_abs,
        bad_pixel_share: bad as f64 / n,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::order::{OrderOptions, Ordering, ViewCase, order};

    #[test]
    fn frames_beyond_the_pixel_limit_are_refused() {
        assert!(check_frame_size(8192, 8192).is_ok());
        assert_eq!(
            check_frame_size(8192, 8193),
            Err(CompositeError::TooLarge {
                width: 8192,
                height: 8193
            })
        );
        assert!(check_frame_size(u32::MAX, u32::MAX).is_err());
    }

    fn two_voxels() -> (VolumeGeometry, SparseGrid, Vec<[f32; 4]>) {
        // Voxels 0 and 1 along x; the camera looks along +x so voxel 1 is behind voxel 0.
        let geometry = VolumeGeometry::axis_aligned([2, 1, 1], [1.0; 3], [0.0; 3]).unwrap();
        let grid = SparseGrid::dense([2, 1, 1]).unwrap();
        let colors = vec![[0.5, 0.0, 0.0, 0.5], [0.0, 0.0, 0.8, 0.8]];
        (geometry, grid, colors)
    }

    fn camera() -> Camera {
        Camera::looking_at(
            DVec3::new(-10.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            33,
            33,
        )
    }

    #[test]
    fn a_splat_is_a_gaussian_at_its_projected_centre() {
        let (geometry, grid, colors) = two_voxels();
        let volume = SplatVolume {
            geometry: &geometry,
            grid: &grid,
            colors: &colors,
        };
        let style = SplatStyle {
            pixel_variance: 0.0,
            ..SplatStyle::default()
        };
        let (frame, stats) = composite(&camera(), &volume, &[1], &style).unwrap();
        // Odd size: the view axis hits the centre of pixel (16, 16) where the weight is 1.
        let centre = frame.pixels[16 * 33 + 16];
        assert!(
            (centre[2] - 0.8).abs() < 1e-6 && (centre[3] - 0.8).abs() < 1e-6,
            "{centre:?}"
        );
        // One pixel to the right: sigma voxels at distance 11 with focal f.
        let f = 0.5 * 33.0 / 25f64.to_radians().tan();
        let sigma_px = style.sigma * f / 11.0;
        let expected = 0.8 * (-0.5 / (sigma_px * sigma_px)).exp();
        assert!((f64::from(frame.pixels[16 * 33 + 17][3]) - expected).abs() < 1e-5);
        assert_eq!(stats.pairs, 0);
        assert!(stats.fragments > 1);
    }

    #[test]
    fn over_is_order_dependent_and_inversions_are_counted() {
        let (geometry, grid, colors) = two_voxels();
        let volume = SplatVolume {
            geometry: &geometry,
            grid: &grid,
            colors: &colors,
        };
        // No low-pass: a splat's centre keeps its full opacity.
        let style = SplatStyle {
            pixel_variance: 0.0,
            ..SplatStyle::default()
        };
        let (back_to_front, good) = composite(&camera(), &volume, &[1, 0], &style).unwrap();
        let (front_to_back, bad) = composite(&camera(), &volume, &[0, 1], &style).unwrap();
        let c = back_to_front.pixels[16 * 33 + 16];
        // Near red (a 0.5) over far blue (a 0.8): blue keeps half its weight.
        assert!(
            (c[0] - 0.5).abs() < 1e-5 && (c[2] - 0.4).abs() < 1e-5,
            "{c:?}"
        );
        assert!(good.pairs > 0 && good.inversions == 0);
        assert_eq!(bad.inversions, bad.pairs);
        assert!(compare(&back_to_front, &front_to_back).unwrap().max_abs > 0.3);
        assert_eq!(
            compare(&back_to_front, &back_to_front).unwrap(),
            ImageDifference::default()
        );
    }

    #[test]
    fn the_low_pass_keeps_a_splats_integral_over_the_image() {
        // A splat far away, well below a pixel: widened by the pixel variance, its summed
        // opacity over the image stays its own footprint's integral, 2 pi alpha sigma_px^2
        // (the cut-off keeps all but exp(-cutoff^2 / 2 sigma^2) of it).
        let geometry = VolumeGeometry::axis_aligned([1, 1, 1], [1.0; 3], [0.0; 3]).unwrap();
        let grid = SparseGrid::dense([1, 1, 1]).unwrap();
        let colors = vec![[0.0, 0.0, 0.02, 0.02]];
        let volume = SplatVolume {
            geometry: &geometry,
            grid: &grid,
            colors: &colors,
        };
        let camera = Camera::looking_at(DVec3::new(-80.0, 0.0, 0.0), DVec3::ZERO, 33, 33);
        let style = SplatStyle::default();
        let (frame, _) = composite(&camera, &volume, &[0], &style).unwrap();
        let sum: f64 = frame.pixels.iter().map(|p| f64::from(p[3])).sum();
        let f = 0.5 * 33.0 / 25f64.to_radians().tan();
        let sigma_px = style.sigma * f / 80.0;
        assert!(sigma_px < 0.3, "below a pixel: {sigma_px}");
        let kept = 1.0 - (-0.5 * (style.cutoff / style.sigma).powi(2)).exp();
        let want = std::f64::consts::TAU * 0.02 * sigma_px * sigma_px * kept;
        // The pixel grid samples the widened Gaussian (sigma over half a pixel): its sum is
        // the integral within a few per cent.
        assert!((sum / want - 1.0).abs() < 0.05, "{sum} against {want}");
        // Without the low-pass the tiny footprint falls between pixel centres or not: no
        // integral is kept at all, which is what the filter is for.
        let sharp = SplatStyle {
            pixel_variance: 0.0,
            ..style
        };
        let (frame, _) = composite(&camera, &volume, &[0], &sharp).unwrap();
        let sharp_sum: f64 = frame.pixels.iter().map(|p| f64::from(p[3])).sum();
        assert!(
            (sharp_sum / want - 1.0).abs() > 0.5,
            "{sharp_sum} against {want}"
        );
    }

    #[test]
    fn the_exact_order_has_no_inversions_and_transparent_voxels_change_nothing() {
        let geometry = VolumeGeometry::axis_aligned([6, 5, 4], [0.7, 0.7, 2.5], [0.0; 3]).unwrap();
        let grid = SparseGrid::dense([6, 5, 4]).unwrap();
        let mut colors: Vec<[f32; 4]> = (0..120)
            .map(|i| [0.1, 0.2, (i % 7) as f32 * 0.05, 0.3])
            .collect();
        let eye = DVec3::new(1.3, -6.0, 4.2);
        let target = geometry.centre_world();
        let view = ViewCase::new(&geometry, eye, target).unwrap();
        let exact = order(&grid, &view, Ordering::Exact, &OrderOptions::default()).unwrap();
        let camera = Camera::looking_at(eye, target, 48, 40);
        let style = SplatStyle::default();
        let volume = SplatVolume {
            geometry: &geometry,
            grid: &grid,
            colors: &colors,
        };
        let (before, stats) = composite(&camera, &volume, &exact, &style).unwrap();
        assert!(stats.pairs > 1000);
        assert_eq!(stats.inversions, 0);
        // A voxel made fully transparent contributes nothing.
        colors[17] = [0.0; 4];
        let volume = SplatVolume {
            geometry: &geometry,
            grid: &grid,
            colors: &colors,
        };
        let without: Vec<u32> = exact.iter().copied().filter(|&id| id != 17).collect();
        let (a, _) = composite(&camera, &volume, &exact, &style).unwrap();
        let (b, _) = composite(&camera, &volume, &without, &style).unwrap();
        assert_eq!(a, b);
        assert_ne!(a, before);
    }

    #[test]
    fn bad_input_is_a_typed_error() {
        let (geometry, grid, colors) = two_voxels();
        let volume = SplatVolume {
            geometry: &geometry,
            grid: &grid,
            colors: &colors[..1],
        };
        let err = composite(&camera(), &volume, &[0], &SplatStyle::default()).unwrap_err();
        assert_eq!(
            err,
            CompositeError::ColorCount {
                colors: 1,
                voxels: 2
            }
        );
        let volume = SplatVolume {
            geometry: &geometry,
            grid: &grid,
            colors: &colors,
        };
        let err = composite(&camera(), &volume, &[0, 7], &SplatStyle::default()).unwrap_err();
        assert_eq!(err, CompositeError::NotSignificant { position: 1, id: 7 });
        let mut cam = camera();
        cam.target = cam.eye;
        assert!(matches!(
            composite(&cam, &volume, &[0], &SplatStyle::default()),
            Err(CompositeError::Camera(CameraError::NoViewDirection))
        ));
    }
}
