//! A slice as a figure: the grey image under its window, every mesh's cross-section in the
//! mesh's colour (anti-aliased, 1.5 pixels), the measurements on the plane, and the
//! annotations of 3D figures (patient letters at the edges, an exact scale bar, a caption).

use glam::DVec3;
use image::RgbaImage;

use super::{Extent, Pixels, Plane, PlaneKind, Slice, SliceError, SliceFrame, SliceSpec, grey};
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

/// Draws the line where the plane through `point` with normal `other` meets the slice, in
/// `colour`, one pixel wide, through the centre of the pixel the point falls in (so that a line
/// along the rows or columns stays crisp); nothing where the planes are parallel.
///
/// # Errors
///
/// No font to draw with (the painter needs one).
pub fn trace(
    image: &mut RgbaImage,
    frame: &SliceFrame,
    point: DVec3,
    other: DVec3,
    colour: [u8; 4],
) -> Result<(), NoFont> {
    let along = frame.plane.normal.cross(other);
    let (dx, dy) = (along.dot(frame.plane.right), along.dot(frame.plane.down));
    let length = dx.hypot(dy);
    if length < 1e-9 {
        return Ok(());
    }
    let [x, y] = frame.pixel(point);
    let (x, y) = (x.round() + 0.5, y.round() + 0.5);
    let reach = f64::from(image.width() + image.height());
    let (ux, uy) = (dx / length * reach, dy / length * reach);
    let mut painter = Painter::new(image)?;
    painter.line(
        [(x - ux) as f32, (y - uy) as f32],
        [(x + ux) as f32, (y + uy) as f32],
        1.0,
        colour,
    );
    Ok(())
}

/// 3D Slicer's colours of the planes: axial red, coronal green, sagittal yellow; an implant
/// plane orange.
pub fn plane_colour(kind: PlaneKind) -> [u8; 4] {
    match kind {
        PlaneKind::Axial => [241, 89, 70, 255],
        PlaneKind::Coronal => [110, 176, 75, 255],
        PlaneKind::Sagittal => [237, 214, 80, 255],
        PlaneKind::ImplantLong | PlaneKind::ImplantCross => [235, 140, 50, 255],
    }
}

/// A slice pane of the four-pane layout: its slice and its figure.
#[derive(Debug, Clone)]
pub struct Pane {
    /// The slice.
    pub slice: Slice,
    /// Its figure, with the other panes' planes traced and a border in its plane's colour.
    pub image: RgbaImage,
}

/// Why the panes could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum PaneError {
    /// A slice could not be made.
    #[error(transparent)]
    Slice(#[from] SliceError),
    /// No font to draw with.
    #[error(transparent)]
    Font(#[from] NoFont),
}

/// The slice panes of the four-pane layout through `point`: axial, sagittal and `fourth`
/// (coronal, or implant-long through the pivot of the mesh named `mesh`), each `pane` pixels at
/// one shared pixel size (the largest that fits every section into its pane), with the traces
/// of the other panes' planes through the point.
///
/// # Errors
///
/// A plane that misses the volume, an implant plane without its mesh, no font.
pub fn quad_panes(
    scene: &Scene,
    point: DVec3,
    pane: (u32, u32),
    window: [f32; 2],
    parts: Option<&Annotations>,
    fourth: PlaneKind,
    mesh: Option<&str>,
) -> Result<Vec<Pane>, PaneError> {
    let kinds = [PlaneKind::Axial, PlaneKind::Sagittal, fourth];
    let planes = kinds
        .iter()
        .map(|&kind| Plane::of(scene, SliceSpec { kind, at_mm: None }, point, mesh))
        .collect::<Result<Vec<_>, _>>()?;
    let mm = planes
        .iter()
        .map(|p| Extent::of(scene, p).map(|e| e.fit_mm(pane.0, pane.1)))
        .collect::<Result<Vec<_>, _>>()?
        .into_iter()
        .fold(0.0, f64::max);
    let mut out = Vec::new();
    for (i, plane) in planes.iter().enumerate() {
        let slice = Slice::new(
            scene,
            *plane,
            Pixels::Fixed {
                size: pane,
                mm_per_pixel: mm,
            },
        )?;
        let labels = (parts.is_some() || !slice.measurements.is_empty())
            .then(|| parts.cloned().unwrap_or_else(measurements_only));
        let (mut image, _) = figure(&slice, scene, window, labels.as_ref())?;
        for (j, other) in planes.iter().enumerate() {
            if j != i {
                trace(
                    &mut image,
                    &slice.frame,
                    point,
                    other.normal,
                    plane_colour(kinds[j]),
                )?;
            }
        }
        border(&mut image, plane_colour(kinds[i]));
        out.push(Pane { slice, image });
    }
    Ok(out)
}

/// Annotations of the measurements' values alone.
fn measurements_only() -> Annotations {
    Annotations {
        orientation_marker: false,
        edge_letters: false,
        scale_bar: false,
        measurements: true,
        caption: None,
    }
}

/// A one-pixel border in `colour`.
pub fn border(image: &mut RgbaImage, colour: [u8; 4]) {
    let (w, h) = (image.width(), image.height());
    if w == 0 || h == 0 {
        return;
    }
    for x in 0..w {
        image.put_pixel(x, 0, image::Rgba(colour));
        image.put_pixel(x, h - 1, image::Rgba(colour));
    }
    for y in 0..h {
        image.put_pixel(0, y, image::Rgba(colour));
        image.put_pixel(w - 1, y, image::Rgba(colour));
    }
}

/// A mesh's colour as 8-bit RGBA, as the 3D figures show it (their frames are written to the
/// PNG as they are, without a transfer function), opaque: an outline is drawn whole, whatever
/// the mesh's opacity in 3D.
pub fn colour8(color: [f32; 4]) -> [u8; 4] {
    let q = |c: f32| (c.clamp(0.0, 1.0) * 255.0).round() as u8;
    [q(color[0]), q(color[1]), q(color[2]), 255]
}
