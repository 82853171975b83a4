//! The volume's values on a slice's pixels (trilinear), and their grey image under a window.

use image::{Rgba, RgbaImage};
use rayon::prelude::*;

use super::frame::{first_geometry, index_range};
use super::{SliceError, SliceFrame};
use crate::scene::Scene;
use crate::volume::CpuVolume;

/// The value at each pixel of a slice, row by row; NaN where the pixel lies outside the
/// volume's grid (or its crop box).
#[derive(Debug, Clone, PartialEq)]
pub struct SliceValues {
    /// Pixels across.
    pub width: u32,
    /// Pixels down.
    pub height: u32,
    /// `width * height` values.
    pub values: Vec<f32>,
}

/// The scene's first volume sampled (trilinear) at the centre of every pixel of `frame`.
///
/// # Errors
///
/// A scene without volumes, or a volume that cannot be placed.
pub fn resample(scene: &Scene, frame: &SliceFrame) -> Result<SliceValues, SliceError> {
    let geometry = first_geometry(scene)?;
    let volume: &CpuVolume = &scene.volumes().next().ok_or(SliceError::NoVolume)?.1.volume;
    let dims = geometry.dims();
    let ranges = dims.map(index_range);
    let crop = scene.clipping.crop;
    // A hair of tolerance, so that a plane along a face of the grid keeps its voxels.
    let tolerance = 1e-6;
    let width = frame.width as usize;
    let mut values = vec![f32::NAN; width * frame.height as usize];
    values
        .par_chunks_mut(width.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            for (x, out) in row.iter_mut().enumerate() {
                let p = frame.world(x as f64, y as f64);
                if let Some((lo, hi)) = crop
                    && (p.cmplt(lo).any() || p.cmpgt(hi).any())
                {
                    continue;
                }
                let i = geometry.world_to_index(p);
                let inside = (0..3)
                    .all(|a| i[a] >= ranges[a].0 - tolerance && i[a] <= ranges[a].1 + tolerance);
                if inside {
                    *out = volume.trilinear(i.to_array());
                }
            }
        });
    Ok(SliceValues {
        width: frame.width,
        height: frame.height,
        values,
    })
}

/// The values as grey: black at `window[0]` and below, white at `window[1]` and above, linear
/// between (as CT viewers map a window to the display); pixels outside the volume black.
pub fn grey(values: &SliceValues, window: [f32; 2]) -> RgbaImage {
    let [lo, hi] = window;
    let span = (hi - lo).max(f32::MIN_POSITIVE);
    let mut image = RgbaImage::new(values.width, values.height);
    for (pixel, &v) in image.pixels_mut().zip(&values.values) {
        let g = if v.is_nan() {
            0
        } else {
            (((v - lo) / span).clamp(0.0, 1.0) * 255.0).round() as u8
        };
        *pixel = Rgba([g, g, g, 255]);
    }
    image
}
