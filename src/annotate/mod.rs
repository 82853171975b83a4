//! Annotations for report figures, drawn onto a rendered image: an orientation marker (an axis
//! triad with the patient's R/L, A/P and S/I letters), patient-direction letters at the image
//! edges, a scale bar, measurement values beside their lines and a caption. Everything is
//! computed from the camera and the scene's patient frame (see [`crate::scene::patient`]), so
//! the letters are right for any volume orientation and any view.

use glam::DVec3;
use image::RgbaImage;

use crate::camera::CameraFrame;
use crate::scene::patient::PatientFrame;
use crate::scene::{Projection, SceneCamera};

pub mod layout;
pub mod text;

pub use layout::{Layout, Rect};
pub use text::{Anchor, NoFont, Painter, font_bytes};

/// Which annotations to draw; all on by default, no caption.
#[derive(Debug, Clone, PartialEq)]
pub struct Annotations {
    /// The axis triad in the lower right corner.
    pub orientation_marker: bool,
    /// Patient-direction letters at the middle of each image edge.
    pub edge_letters: bool,
    /// A scale bar in the lower left corner.
    pub scale_bar: bool,
    /// Measurement values beside their lines.
    pub measurements: bool,
    /// A caption along the top edge.
    pub caption: Option<String>,
}

impl Default for Annotations {
    fn default() -> Self {
        Self {
            orientation_marker: true,
            edge_letters: true,
            scale_bar: true,
            measurements: true,
            caption: None,
        }
    }
}

/// A name that is no part of the annotations.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0:?} is not an annotation: marker, letters, scale, measurements, all or none")]
pub struct UnknownAnnotation(pub String);

impl Annotations {
    /// The parts named in a comma-separated list (`marker`, `letters`, `scale`,
    /// `measurements`; `all` or `none`); an unknown name is an error listing the names.
    pub fn parse_parts(list: &str) -> Result<Self, UnknownAnnotation> {
        let mut parts = Self {
            orientation_marker: false,
            edge_letters: false,
            scale_bar: false,
            measurements: false,
            caption: None,
        };
        for name in list.split(',').map(str::trim) {
            match name {
                "all" => parts = Self::default(),
                "none" => {}
                "marker" => parts.orientation_marker = true,
                "letters" => parts.edge_letters = true,
                "scale" => parts.scale_bar = true,
                "measurements" => parts.measurements = true,
                other => return Err(UnknownAnnotation(other.to_owned())),
            }
        }
        Ok(parts)
    }

    /// The measurements' values alone, as a plain figure of a scene with measurements has.
    pub fn measurements_only() -> Self {
        Self {
            orientation_marker: false,
            edge_letters: false,
            scale_bar: false,
            measurements: true,
            caption: None,
        }
    }
}

/// A measurement value to write beside its place in the scene.
#[derive(Debug, Clone, PartialEq)]
pub struct Label {
    /// Where the text goes: the middle of a distance, the vertex of an angle (world).
    pub at: DVec3,
    /// The text (`42.3 mm`, `angle 131.9°`).
    pub text: String,
}

/// The camera of an image, for projecting world points to pixels.
#[derive(Debug, Clone, Copy)]
pub struct ImageCamera {
    eye: DVec3,
    frame: CameraFrame,
    width: f64,
    height: f64,
    /// Pixels per millimetre at the target's depth.
    pixels_per_mm: f64,
    orthographic: bool,
}

impl ImageCamera {
    /// The camera for an image of `width` x `height`; `None` for a camera that cannot be used.
    pub fn new(camera: &SceneCamera, width: u32, height: u32) -> Option<Self> {
        let pinhole = camera.pinhole(width, height, 0.0).ok()?;
        let frame = pinhole.frame().ok()?;
        let depth = (camera.target - pinhole.eye).dot(frame.forward);
        Some(Self {
            eye: pinhole.eye,
            frame,
            width: f64::from(width),
            height: f64::from(height),
            pixels_per_mm: frame.focal / depth.max(f64::MIN_POSITIVE),
            orthographic: matches!(camera.projection, Projection::Orthographic { .. }),
        })
    }

    /// The pixel of a world point (x right, y down, pixel centres at half integers), or `None`
    /// behind the eye.
    pub fn project(&self, p: DVec3) -> Option<[f32; 2]> {
        let d = p - self.eye;
        let z = d.dot(self.frame.forward);
        if z <= 0.0 {
            return None;
        }
        let x = 0.5 * self.width + self.frame.focal * d.dot(self.frame.right) / z;
        let y = 0.5 * self.height - self.frame.focal * d.dot(self.frame.up) / z;
        Some([x as f32, y as f32])
    }

    /// Pixels per millimetre at the target's depth (everywhere, for an orthographic camera).
    pub fn pixels_per_mm(&self) -> f64 {
        self.pixels_per_mm
    }
}

/// What [`annotate_image`] wrote, for the caller to report or check.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Drawn {
    /// The letters at the left, right, top and bottom edges (empty when not drawn).
    pub edge_letters: [String; 4],
    /// The scale bar's label (`50 mm at the target`), when drawn (a picture too small for it
    /// leaves it out).
    pub scale: Option<String>,
    /// Whether the orientation marker was drawn (a picture with no free corner for it leaves
    /// it out).
    pub marker: bool,
    /// The measurement labels (and a caption) left out for want of room: each free spot
    /// near its point was taken or outside the picture.
    pub dropped: Vec<String>,
    /// Every piece of text drawn, with the rectangle it covers: edge letters, the marker's
    /// letters, the scale bar's label, the caption and the measurement labels.
    pub texts: Vec<(String, Rect)>,
}

/// Draws the annotations onto `image`, rendered with `camera`, for a scene whose patient lies
/// as `patient` says. `labels` are the measurement values. A camera that cannot be used
/// draws nothing.
pub fn annotate_image(
    image: &mut RgbaImage,
    camera: &SceneCamera,
    patient: &PatientFrame,
    labels: &[Label],
    parts: &Annotations,
) -> Result<Drawn, NoFont> {
    annotate_image_clear_of(image, camera, patient, labels, parts, &[])
}

/// [`annotate_image`], keeping clear of the rectangles `clear` (a window's own text, a colour
/// bar). Every mark takes its place in one layout: the edge letters, the marker and the scale
/// bar where they belong; the caption along the top, below the top letter where it would
/// touch it, shortened with `…` to the picture's width; each measurement label in the first
/// free spot around its point, with a leader line when that spot is not beside it, or left
/// out (and listed in [`Drawn::dropped`]) when there is none.
pub fn annotate_image_clear_of(
    image: &mut RgbaImage,
    camera: &SceneCamera,
    patient: &PatientFrame,
    labels: &[Label],
    parts: &Annotations,
    clear: &[Rect],
) -> Result<Drawn, NoFont> {
    let mut drawn = Drawn::default();
    let Some(cam) = ImageCamera::new(camera, image.width(), image.height()) else {
        return Ok(drawn);
    };
    let mut painter = Painter::new(image)?;
    let (w, h) = painter.size();
    let mut layout = Layout::new(w, h);
    for r in clear {
        layout.take(*r);
    }
    let pad = 0.25 * painter.text_px;
    let mut top_letter = None;
    if parts.edge_letters {
        let (letters, rects) = edge_letters(&mut painter, &cam, patient);
        for (l, r) in letters.iter().zip(rects) {
            layout.take(layout::grown(r, pad));
            drawn.texts.push((l.clone(), r));
        }
        drawn.edge_letters = letters;
        top_letter = Some(rects[2]);
    }
    if parts.orientation_marker
        && let Some(r) = orientation_marker(&mut painter, &cam, patient, &layout, &mut drawn.texts)
    {
        layout.take(r);
        drawn.marker = true;
    }
    if parts.scale_bar
        && let Some((text, rect, label)) = scale_bar(&mut painter, &cam, &layout)
    {
        drawn.texts.push((text.clone(), label));
        drawn.scale = Some(text);
        layout.take(layout::grown(rect, pad));
    }
    if let Some(caption) = &parts.caption {
        let margin = 0.6 * painter.text_px;
        let text = shortened(&painter, caption, w - 2.0 * margin);
        let (tw, th) = painter.measure(&text);
        let mut top = margin;
        if let Some(letter) = top_letter
            && layout::overlaps(
                layout::grown(letter, pad),
                [margin, top, margin + tw, top + th],
            )
        {
            top = letter[3] + pad;
        }
        let rect = [margin, top, margin + tw, top + th];
        if layout.fits(rect) {
            let rect = painter.text(&text, margin, top, Anchor::TopLeft, WHITE);
            layout.take(layout::grown(rect, pad));
            drawn.texts.push((text, rect));
        } else {
            drawn.dropped.push(caption.clone());
        }
    }
    if parts.measurements {
        let gap = 0.6 * painter.text_px;
        for label in labels {
            let Some(at) = cam.project(label.at) else {
                continue;
            };
            let size = painter.measure(&label.text);
            match layout.place_label(at, size, gap) {
                Some(placed) => {
                    if placed.leader {
                        let end = layout::nearest_on(placed.rect, at);
                        painter.line(at, end, 1.0, LABEL);
                    }
                    let rect = painter.text(
                        &label.text,
                        placed.rect[0],
                        placed.rect[1],
                        Anchor::TopLeft,
                        LABEL,
                    );
                    layout.take(layout::grown(rect, pad));
                    drawn.texts.push((label.text.clone(), rect));
                }
                None => drawn.dropped.push(label.text.clone()),
            }
        }
    }
    Ok(drawn)
}

/// `text` cut to at most `width` pixels, ending in `…` where it was cut.
pub fn shortened(painter: &Painter<'_>, text: &str, width: f32) -> String {
    if painter.measure(text).0 <= width {
        return text.to_owned();
    }
    let chars: Vec<char> = text.chars().collect();
    let mut n = chars.len();
    while n > 0 {
        n -= 1;
        let cut: String = chars[..n].iter().collect::<String>().trim_end().to_owned() + "…";
        if painter.measure(&cut).0 <= width {
            return cut;
        }
    }
    String::new()
}

const WHITE: [u8; 4] = [255, 255, 255, 255];
/// Measurement labels, in the colour of the measurement markers.
const LABEL: [u8; 4] = [255, 214, 64, 255];

/// The patient direction toward each image edge, at its middle: the letters, and where each
/// was drawn (left, right, top, bottom).
fn edge_letters(
    painter: &mut Painter<'_>,
    cam: &ImageCamera,
    patient: &PatientFrame,
) -> ([String; 4], [Rect; 4]) {
    let (w, h) = painter.size();
    let m = 0.5 * painter.text_px;
    let f = cam.frame;
    let edges = [
        (-f.right, m, h / 2.0, Anchor::TopLeft),
        (f.right, w - m, h / 2.0, Anchor::TopRight),
        (f.up, w / 2.0, m, Anchor::TopCentre),
        (-f.up, w / 2.0, h - m, Anchor::BottomCentre),
    ];
    let mut rects = [[0.0; 4]; 4];
    let letters = std::array::from_fn(|i| {
        let (direction, x, y, anchor) = edges[i];
        let letters = patient.letters(direction);
        let (_, th) = painter.measure(&letters);
        // Side letters are centred on the edge's middle.
        let y = if matches!(anchor, Anchor::TopLeft | Anchor::TopRight) {
            y - th / 2.0
        } else {
            y
        };
        rects[i] = painter.text(&letters, x, y, anchor, WHITE);
        letters
    });
    (letters, rects)
}

/// The patient axes as seen by the camera, drawn from a point in the lower right corner:
/// R red, A green, S blue (3D Slicer's colours), the positive half bold with its letter, the
/// negative half thin with its own. Letters that would touch one another (two axes seen
/// along nearly the same line) are pushed apart along their axes. Returns the rectangle the
/// marker and its letters cover.
fn orientation_marker(
    painter: &mut Painter<'_>,
    cam: &ImageCamera,
    patient: &PatientFrame,
    layout: &Layout,
    texts: &mut Vec<(String, Rect)>,
) -> Option<Rect> {
    let (w, h) = painter.size();
    let radius = 0.09 * w.min(h).max(120.0);
    let home = [
        w - radius - 1.6 * painter.text_px,
        h - radius - 1.6 * painter.text_px,
    ];
    // Laid out about the origin, then moved to its place.
    let centre = [0.0f32, 0.0];
    let axes = [
        (DVec3::X, ['R', 'L'], [235, 80, 70, 255]),
        (DVec3::Y, ['A', 'P'], [90, 210, 90, 255]),
        (DVec3::Z, ['S', 'I'], [90, 150, 255, 255]),
    ];
    let mut halves = Vec::new();
    for (axis, letters, color) in axes {
        let world = patient.world(axis);
        for (sign, letter) in [(1.0, letters[0]), (-1.0, letters[1])] {
            let d = world * sign;
            let screen = [d.dot(cam.frame.right) as f32, -d.dot(cam.frame.up) as f32];
            halves.push((d.dot(cam.frame.forward), sign > 0.0, letter, screen, color));
        }
    }
    // Far halves first, so that the ones pointing at the viewer are drawn over them.
    halves.sort_by(|a, b| b.0.total_cmp(&a.0));
    let stroke = (painter.text_px / 6.0).max(1.5);
    let mut covered = [
        centre[0] - radius,
        centre[1] - radius,
        centre[0] + radius,
        centre[1] + radius,
    ];
    // The letters' places, found first (nearest the viewer first, as they matter most), so
    // that no two touch.
    let mut letters: Vec<Option<[f32; 2]>> = vec![None; halves.len()];
    let mut placed: Vec<Rect> = Vec::new();
    let order: Vec<usize> = (0..halves.len()).rev().collect();
    for i in order {
        let (depth, _, letter, [sx, sy], _) = halves[i];
        let length = (sx * sx + sy * sy).sqrt();
        let (tw, th) = painter.measure(&letter.to_string());
        let rect_at = |p: [f32; 2]| {
            layout::grown(
                [
                    p[0] - tw / 2.0,
                    p[1] - th / 2.0,
                    p[0] + tw / 2.0,
                    p[1] + th / 2.0,
                ],
                0.1 * painter.text_px,
            )
        };
        // The letter just beyond the tip (a foreshortened axis's letter stays by its short
        // line); an axis seen end-on gets its letter beside the centre, for the end facing
        // the viewer only.
        let (start, step) = if length > 0.25 {
            let reach = radius * length + 0.7 * painter.text_px;
            let (ux, uy) = (sx / length, sy / length);
            (
                [centre[0] + reach * ux, centre[1] + reach * uy],
                [0.5 * painter.text_px * ux, 0.5 * painter.text_px * uy],
            )
        } else if depth < 0.0 {
            (
                [
                    centre[0] + 0.8 * painter.text_px,
                    centre[1] - 0.8 * painter.text_px,
                ],
                [0.5 * painter.text_px, -0.5 * painter.text_px],
            )
        } else {
            continue;
        };
        let mut at = start;
        for _ in 0..6 {
            if !placed.iter().any(|r| layout::overlaps(*r, rect_at(at))) {
                break;
            }
            at = [at[0] + step[0], at[1] + step[1]];
        }
        let r = rect_at(at);
        placed.push(r);
        covered = [
            covered[0].min(r[0]),
            covered[1].min(r[1]),
            covered[2].max(r[2]),
            covered[3].max(r[3]),
        ];
        letters[i] = Some(at);
    }
    // In the lower right corner, else as near it (up, then left) as leaves the other marks
    // clear; nowhere, and it is left out.
    let step = 0.5 * painter.text_px;
    let at = |[x, y]: [f32; 2]| {
        [
            covered[0] + x,
            covered[1] + y,
            covered[2] + x,
            covered[3] + y,
        ]
    };
    let centre = (0..12)
        .flat_map(|up| (0..8).map(move |left| (up, left)))
        .map(|(up, left)| [home[0] - step * left as f32, home[1] - step * up as f32])
        .find(|c| layout.fits(at(*c)))?;
    let covered = at(centre);
    for (i, (_, positive, letter, [sx, sy], color)) in halves.into_iter().enumerate() {
        let tip = [centre[0] + radius * sx, centre[1] + radius * sy];
        let width = if positive { stroke } else { 0.5 * stroke };
        let color = if positive {
            color
        } else {
            [color[0] / 2 + 60, color[1] / 2 + 60, color[2] / 2 + 60, 255]
        };
        let length = (sx * sx + sy * sy).sqrt();
        if length > 0.05 {
            painter.line(centre, tip, width, color);
        }
        if let Some([x, y]) = letters[i] {
            let (x, y) = (x + centre[0], y + centre[1]);
            let rect = painter.text(&letter.to_string(), x, y, Anchor::Centre, color);
            texts.push((letter.to_string(), rect));
        }
    }
    Some(covered)
}

/// A colour bar legend in the upper right corner (clear of the edge letters): the colours `colour` gives over
/// `range` (greatest at the top), `ticks` marked and labelled on its left, `title` above it.
///
/// # Errors
///
/// No font to draw with.
pub fn colour_bar(
    image: &mut RgbaImage,
    colour: impl Fn(f64) -> [u8; 4],
    range: [f64; 2],
    ticks: &[(f64, String)],
    title: &str,
) -> Result<(), NoFont> {
    let (w, h) = (image.width() as f32, image.height() as f32);
    let text = Painter::new(image)?.text_px;
    let top = 2.6 * text;
    let height = (0.35 * h).min(0.5 * h - top - text).max(8.0);
    let width = (0.9 * text).max(6.0);
    let right = w - 1.2 * text;
    let left = right - width;
    let span = range[1] - range[0];
    let y_of = |v: f64| top + height * (1.0 - ((v - range[0]) / span).clamp(0.0, 1.0) as f32);
    // The bar filled a pixel at a time (a stroke's halo would darken the row above), in a
    // dark frame.
    let (x0, x1) = (left.round().max(0.0) as u32, right.round().max(0.0) as u32);
    let (y0, y1) = (
        top.round().max(0.0) as u32,
        (top + height).round().max(0.0) as u32,
    );
    for y in y0.saturating_sub(1)..(y1 + 1).min(image.height()) {
        for x in x0.saturating_sub(1)..(x1 + 1).min(image.width()) {
            let inside = (x0..x1).contains(&x) && (y0..y1).contains(&y);
            let c = if inside {
                let t = ((y as f32 + 0.5 - top) / height).clamp(0.0, 1.0);
                colour(range[1] - span * f64::from(t))
            } else {
                [20, 20, 20, 255]
            };
            image.put_pixel(x, y, image::Rgba(c));
        }
    }
    let mut painter = Painter::new(image)?;
    for (value, label) in ticks {
        let y = y_of(*value);
        painter.line([left - 0.5 * text, y], [left, y], 1.0, WHITE);
        let (_, th) = painter.measure(label);
        painter.text(
            label,
            left - 0.7 * text,
            y - th / 2.0,
            Anchor::TopRight,
            WHITE,
        );
    }
    painter.text(title, right, top - 0.6 * text, Anchor::BottomRight, WHITE);
    Ok(())
}

/// A bar of a round length (1, 2 or 5 times a power of ten millimetres) near a fifth of the
/// image width, in the lower left corner, labelled with its length; in a perspective view the
/// length holds at the target's depth only, and the label says so. Returns the label, the rectangle
/// the bar and label cover, and the label's own.
fn scale_bar(
    painter: &mut Painter<'_>,
    cam: &ImageCamera,
    layout: &Layout,
) -> Option<(String, Rect, Rect)> {
    let (w, h) = painter.size();
    let per_mm = cam.pixels_per_mm();
    if !(per_mm.is_finite() && per_mm > 0.0) {
        return None;
    }
    let mm = round_length(0.2 * f64::from(w) / per_mm)?;
    let length = (mm * per_mm) as f32;
    let m = 1.2 * painter.text_px;
    let y = h - m;
    let tick = 0.4 * painter.text_px;
    let stroke = (painter.text_px / 7.0).max(1.5);
    let text = if cam.orthographic {
        format!("{} mm", format_length(mm))
    } else {
        format!("{} mm at the target", format_length(mm))
    };
    let (tw, th) = painter.measure(&text);
    let base = y - tick - 0.2 * painter.text_px;
    let rect = [m, base - th, (m + length).max(m + tw), y + tick + stroke];
    // Left out where it would cover another mark or leave the picture.
    if !layout.fits(rect) {
        return None;
    }
    painter.lines(
        &[
            ([m, y], [m + length, y]),
            ([m, y - tick], [m, y + tick]),
            ([m + length, y - tick], [m + length, y + tick]),
        ],
        stroke,
        WHITE,
    );
    let label = painter.text(&text, m, base, Anchor::BottomLeft, WHITE);
    Some((text, rect, label))
}

/// The largest of 1, 2 or 5 times a power of ten that is at most `limit`.
fn round_length(limit: f64) -> Option<f64> {
    if !(limit.is_finite() && limit > 0.0) {
        return None;
    }
    let decade = 10f64.powf(limit.log10().floor());
    [5.0, 2.0, 1.0]
        .iter()
        .map(|m| m * decade)
        .find(|v| *v <= limit * (1.0 + 1e-9))
}

/// A length without trailing zeros: `50`, `0.2`, `2e-5`.
fn format_length(mm: f64) -> String {
    if (1e-3..1e6).contains(&mm) {
        let s = format!("{mm:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_owned()
    } else {
        format!("{mm:e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_lengths_are_round() {
        assert_eq!(round_length(73.0), Some(50.0));
        assert_eq!(round_length(20.0), Some(20.0));
        assert_eq!(round_length(0.31), Some(0.2));
        assert_eq!(round_length(0.0), None);
        assert_eq!(format_length(50.0), "50");
        assert_eq!(format_length(0.2), "0.2");
    }

    #[test]
    fn projection_matches_the_pixel_size_at_the_target() {
        let camera = SceneCamera {
            projection: Projection::Orthographic { height: 200.0 },
            ..SceneCamera::look_at(DVec3::new(0.0, -500.0, 0.0), DVec3::ZERO)
        };
        let cam = ImageCamera::new(&camera, 400, 400).unwrap();
        assert!(
            (cam.pixels_per_mm() - 2.0).abs() < 1e-6,
            "{}",
            cam.pixels_per_mm()
        );
        let [x, y] = cam.project(DVec3::new(10.0, 0.0, 10.0)).unwrap();
        assert!(
            (x - 220.0).abs() < 1e-3 && (y - 180.0).abs() < 1e-3,
            "{x},{y}"
        );
        let persp = SceneCamera::look_at(DVec3::new(0.0, -100.0, 0.0), DVec3::ZERO);
        let cam = ImageCamera::new(&persp, 400, 400).unwrap();
        let [x, _] = cam.project(DVec3::new(10.0, 0.0, 0.0)).unwrap();
        assert!(((x - 200.0) as f64 - 10.0 * cam.pixels_per_mm()).abs() < 1e-3);
        assert!(cam.project(DVec3::new(0.0, -200.0, 0.0)).is_none());
    }

    #[test]
    fn annotation_parts_parse() {
        let p = Annotations::parse_parts("marker,scale").unwrap();
        assert!(p.orientation_marker && p.scale_bar && !p.edge_letters && !p.measurements);
        assert_eq!(
            Annotations::parse_parts("all").unwrap(),
            Annotations::default()
        );
        assert!(
            Annotations::parse_parts("triad")
                .unwrap_err()
                .to_string()
                .contains("marker")
        );
    }
}
