//! A slice as a figure: the grey image under its window, every mesh's cross-section in the
//! mesh's colour (anti-aliased, 1.5 pixels), the measurements on the plane, and the
//! annotations of 3D figures (patient letters at the edges, an exact scale bar, a caption).

use glam::DVec3;
use image::RgbaImage;

use super::{Slice, SliceFrame, grey};
use crate::annotate::text::{NoFont, Painter};
use crate::annotate::{Annotations, Drawn, Label, annotate_image};
use crate::scene::Scene;

/// The width of an outline in pixels.
pub const OUTLINE_PX: f32 = 1.5;
/// The colour measurements are drawn in (that of the 3D figures' markers).
const MEASURE: [u8; 4] = [255, 214, 64, 255];

/// The figure of `slice`: grey by `window`, outlines and measurements drawn, annotated as
/// `parts` asks (measurement values written where `parts` holds measurements). Returns what
/// the annotation drew.
///
/// # Errors
///
/// No font to draw with.
pub fn figure(
    slice: &Slice,
    scene: &Scene,
    window: [f32; 2],
    parts: Option<&Annotations>,
) -> Result<(RgbaImage, Option<Drawn>), NoFont> {
    let mut image = grey(&slice.values, window);
    let frame = &slice.frame;
    let to_px = |p: DVec3| {
        let [x, y] = frame.pixel(p);
        // Painter coordinates put pixel centres at half-integers.
        [(x + 0.5) as f32, (y + 0.5) as f32]
    };
    {
        let mut painter = Painter::new(&mut image)?;
        for outline in &slice.outlines {
            let mut segments = Vec::new();
            for (points, closed) in &outline.polylines {
                let pixels: Vec<[f32; 2]> = points.iter().map(|p| to_px(*p)).collect();
                segments.extend(pixels.windows(2).map(|w| (w[0], w[1])));
                if *closed && pixels.len() > 2 {
                    segments.push((pixels[pixels.len() - 1], pixels[0]));
                }
            }
            painter.lines(&segments, OUTLINE_PX, colour8(outline.color));
        }
        for m in &slice.measurements {
            let mut segments: Vec<([f32; 2], [f32; 2])> = m
                .measurement
                .segments()
                .into_iter()
                .map(|(a, b)| (to_px(a), to_px(b)))
                .collect();
            // Each point a small cross.
            let r = 0.35 * painter.text_px;
            for p in &m.measurement.points {
                let [x, y] = to_px(DVec3::from(*p));
                segments.push(([x - r, y - r], [x + r, y + r]));
                segments.push(([x - r, y + r], [x + r, y - r]));
            }
            painter.lines(&segments, 1.5, MEASURE);
        }
    }
    let labels: Vec<Label> = slice
        .measurements
        .iter()
        .map(|m| Label {
            at: m.measurement.label_anchor(),
            text: m.text.clone(),
        })
        .collect();
    let drawn = match parts {
        Some(parts) => Some(annotate_image(
            &mut image,
            &frame.camera(),
            &scene.patient_frame(),
            &labels,
            parts,
        )?),
        None => None,
    };
    Ok((image, drawn))
}

/// Draws the lines where two other planes through `point` meet the slice: along the image's
/// rows in `across` and along its columns in `along`, as planning tools mark where the other
/// panes cut.
///
/// # Errors
///
/// No font to draw with (the painter needs one).
pub fn crosshair(
    image: &mut RgbaImage,
    frame: &SliceFrame,
    point: DVec3,
    across: [u8; 4],
    along: [u8; 4],
) -> Result<(), NoFont> {
    // Through the centre of the pixel the point falls in, so that the lines stay one crisp
    // pixel wide (they lie within half a pixel of the point).
    let [x, y] = frame.pixel(point);
    let (x, y) = (x.round() as f32 + 0.5, y.round() as f32 + 0.5);
    let (w, h) = (image.width() as f32, image.height() as f32);
    let mut painter = Painter::new(image)?;
    painter.line([0.0, y], [w, y], 1.0, across);
    painter.line([x, 0.0], [x, h], 1.0, along);
    Ok(())
}

/// A mesh's colour as 8-bit RGBA, as the 3D figures show it (their frames are written to the
/// PNG as they are, without a transfer function), opaque: an outline is drawn whole, whatever
/// the mesh's opacity in 3D.
pub fn colour8(color: [f32; 4]) -> [u8; 4] {
    let q = |c: f32| (c.clamp(0.0, 1.0) * 255.0).round() as u8;
    [q(color[0]), q(color[1]), q(color[2]), 255]
}
