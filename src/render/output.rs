//! Frames to images: 8-bit RGBA colour and 16-bit depth, encoded as PNG.

use image::{ImageBuffer, Luma, RgbaImage};

use super::ViewSetup;
use crate::composite::Frame;

/// A premultiplied frame as straight 8-bit RGBA (what PNG stores): opaque where the frame is,
/// and with the frame's coverage as alpha over a transparent background.
pub fn frame_to_rgba8(frame: &Frame) -> RgbaImage {
    RgbaImage::from_fn(frame.width, frame.height, |x, y| {
        let p = frame.pixels[(y * frame.width + x) as usize];
        let a = p[3].clamp(0.0, 1.0);
        let q = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
        if a <= 0.0 {
            return image::Rgba([0, 0, 0, 0]);
        }
        image::Rgba([q(p[0] / a), q(p[1] / a), q(p[2] / a), q(a)])
    })
}

/// Depth as a 16-bit grey image: the view distance of each mesh pixel mapped linearly from
/// `range.0` (black) to `range.1` (white); pixels with no mesh are white. Splats write no
/// depth, so only meshes show.
pub fn depth_to_luma16(
    depth: &[f32],
    view: &ViewSetup,
    range: (f64, f64),
) -> ImageBuffer<Luma<u16>, Vec<u16>> {
    let (w, h) = view.size;
    let span = (range.1 - range.0).max(f64::MIN_POSITIVE);
    ImageBuffer::from_fn(w, h, |x, y| {
        let d = depth.get((y * w + x) as usize).copied().unwrap_or(0.0);
        let v = view
            .distance_of(d)
            .map_or(1.0, |d| ((d - range.0) / span).clamp(0.0, 1.0));
        Luma([(v * 65535.0).round() as u16])
    })
}

/// The range of view distances of a scene's bounding box corners, for [`depth_to_luma16`].
pub fn depth_range(view: &ViewSetup, bounds: (glam::DVec3, glam::DVec3)) -> (f64, f64) {
    let forward = view.axes.z_axis;
    let (lo, hi) = bounds;
    (0..8)
        .map(|i| {
            let c = glam::DVec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            );
            (c - view.camera.eye).dot(forward)
        })
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), d| {
            (a.min(d), b.max(d))
        })
}

/// Encodes an 8-bit RGBA or 16-bit grey image as PNG bytes.
pub fn encode_png<P, C>(image: &ImageBuffer<P, C>) -> Result<Vec<u8>, image::ImageError>
where
    P: image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
    C: std::ops::Deref<Target = [P::Subpixel]>,
{
    let mut bytes = Vec::new();
    image.write_to(
        &mut std::io::Cursor::new(&mut bytes),
        image::ImageFormat::Png,
    )?;
    Ok(bytes)
}
