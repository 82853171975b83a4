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

pub mod text;

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
    /// The scale bar's label (`50 mm at the target`), when drawn.
    pub scale: Option<String>,
    /// Whether the orientation marker was drawn.
    pub marker: bool,
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
    let mut drawn = Drawn::default();
    let Some(cam) = ImageCamera::new(camera, image.width(), image.height()) else {
        return Ok(drawn);
    };
    let mut painter = Painter::new(image)?;
    if parts.edge_letters {
        drawn.edge_letters = edge_letters(&mut painter, &cam, patient);
    }
    if parts.orientation_marker {
        orientation_marker(&mut painter, &cam, patient);
        drawn.marker = true;
    }
    if parts.scale_bar {
        drawn.scale = scale_bar(&mut painter, &cam);
    }
    if parts.measurements {
        for label in labels {
            if let Some([x, y]) = cam.project(label.at) {
                let off = 0.6 * painter.text_px;
                painter.text(&label.text, x + off, y - off, Anchor::BottomLeft, LABEL);
            }
        }
    }
    if let Some(caption) = &parts.caption {
        let margin = 0.6 * painter.text_px;
        painter.text(caption, margin, margin, Anchor::TopLeft, WHITE);
    }
    Ok(drawn)
}

const WHITE: [u8; 4] = [255, 255, 255, 255];
/// Measurement labels, in the colour of the measurement markers.
const LABEL: [u8; 4] = [255, 214, 64, 255];

/// The patient direction toward each image edge, at its middle.
fn edge_letters(
    painter: &mut Painter<'_>,
    cam: &ImageCamera,
    patient: &PatientFrame,
) -> [String; 4] {
    let (w, h) = painter.size();
    let m = 0.5 * painter.text_px;
    let f = cam.frame;
    let edges = [
        (-f.right, m, h / 2.0, Anchor::TopLeft),
        (f.right, w - m, h / 2.0, Anchor::TopRight),
        (f.up, w / 2.0, m, Anchor::TopCentre),
        (-f.up, w / 2.0, h - m, Anchor::BottomCentre),
    ];
    edges.map(|(direction, x, y, anchor)| {
        let letters = patient.letters(direction);
        let (_, th) = painter.measure(&letters);
        // Side letters are centred on the edge's middle.
        let y = if matches!(anchor, Anchor::TopLeft | Anchor::TopRight) {
            y - th / 2.0
        } else {
            y
        };
        painter.text(&letters, x, y, anchor, WHITE);
        letters
    })
}

/// The patient axes as seen by the camera, drawn from a point in the lower right corner:
/// R red, A green, S blue (3D Slicer's colours), the positive half bold with its letter, the
/// negative half thin with its own.
fn orientation_marker(painter: &mut Painter<'_>, cam: &ImageCamera, patient: &PatientFrame) {
    let (w, h) = painter.size();
    let radius = 0.09 * w.min(h).max(120.0);
    let centre = [
        w - radius - 1.6 * painter.text_px,
        h - radius - 1.6 * painter.text_px,
    ];
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
    for (depth, positive, letter, [sx, sy], color) in halves {
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
        // The letter beyond the tip; an axis seen end-on gets its letter beside the centre,
        // for the end facing the viewer only.
        let reach = radius + 0.7 * painter.text_px;
        let at = if length > 0.25 {
            [
                centre[0] + reach * sx / length,
                centre[1] + reach * sy / length,
            ]
        } else if depth < 0.0 {
            [
                centre[0] + 0.8 * painter.text_px,
                centre[1] - 0.8 * painter.text_px,
            ]
        } else {
            continue;
        };
        painter.text(&letter.to_string(), at[0], at[1], Anchor::Centre, color);
    }
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
/// length holds at the target's depth only, and the label says so.
fn scale_bar(painter: &mut Painter<'_>, cam: &ImageCamera) -> Option<String> {
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
    painter.lines(
        &[
            ([m, y], [m + length, y]),
            ([m, y - tick], [m, y + tick]),
            ([m + length, y - tick], [m + length, y + tick]),
        ],
        stroke,
        WHITE,
    );
    let text = if cam.orthographic {
        format!("{} mm", format_length(mm))
    } else {
        format!("{} mm at the target", format_length(mm))
    };
    painter.text(
        &text,
        m,
        y - tick - 0.2 * painter.text_px,
        Anchor::BottomLeft,
        WHITE,
    );
    Some(text)
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
