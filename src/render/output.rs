//! Frames to images: 8-bit RGBA colour, encoded as PNG (depth: see `depth_image`).

use image::{ImageBuffer, RgbaImage};

use crate::splat::reference::Frame;

/// A premultiplied frame as straight 8-bit RGBA (what PNG stores): opaque where the frame is,
/// and with the frame's coverage as alpha over a transparent background.
pub fn frame_to_rgba8(frame: &Frame) -> RgbaImage {
    use rayon::prelude::*;
    // `round()` without its library call: the integer part and the fraction of a value in
    // 0..=255 are exact in f32.
    let q = |v: f32| {
        let x = v.clamp(0.0, 1.0) * 255.0;
        let whole = x as u32;
        (whole + u32::from(x - whole as f32 >= 0.5)) as u8
    };
    let (w, h) = (frame.width as usize, frame.height as usize);
    let mut out = vec![0u8; w * h * 4];
    // Rows in parallel: a viewer's frame is a million pixels, each with a division.
    if w > 0 {
        out.par_chunks_exact_mut(w * 4)
            .zip(frame.pixels.par_chunks(w))
            .for_each(|(row, pixels)| {
                // Every pixel written, a clear one's colour chosen as 0 rather than branched
                // over, so that the loop can run in vectors.
                for (px, p) in row.chunks_exact_mut(4).zip(pixels) {
                    let a = p[3].clamp(0.0, 1.0);
                    let (d, keep) = if a > 0.0 { (a, 1.0) } else { (1.0, 0.0) };
                    px[0] = q(keep * (p[0] / d));
                    px[1] = q(keep * (p[1] / d));
                    px[2] = q(keep * (p[2] / d));
                    px[3] = q(a);
                }
            });
    }
    RgbaImage::from_raw(frame.width, frame.height, out)
        .unwrap_or_else(|| RgbaImage::new(frame.width, frame.height))
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

/// Encodes an 8-bit RGBA image as PNG bytes with text chunks (each value as its text, strings
/// without quotes; keys prefixed `splatscene:`), as calibrated figures carry what their pixels
/// mean.
pub fn encode_png_with_text(
    image: &RgbaImage,
    chunks: &[(&str, &serde_json::Value)],
) -> Result<Vec<u8>, png::EncodingError> {
    let mut bytes = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut bytes, image.width(), image.height());
        encoder.set_color(png::ColorType::Rgba);
        encoder.set_depth(png::BitDepth::Eight);
        for (key, value) in chunks {
            let text = match value {
                serde_json::Value::String(s) => s.clone(),
                other => other.to_string(),
            };
            encoder.add_text_chunk(format!("splatscene:{key}"), text)?;
        }
        let mut writer = encoder.write_header()?;
        writer.write_image_data(image.as_raw())?;
    }
    Ok(bytes)
}
