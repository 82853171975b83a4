//! Calibrated depth images: the view distance of every pixel as 16-bit grey, with the distances
//! its black and white stand for written into the PNG (text chunks) and into a JSON sidecar, so
//! that a grey value can be turned back into millimetres.
//!
//! Encoding: grey `v` from 0 to 65534 is the distance `near + (far - near) * v / 65534`
//! millimetres along the view axis (the eye's forward direction; for an orthographic camera,
//! from the plane the rays start from); 65535 is a pixel where nothing was hit.

use glam::DVec3;
use serde_json::{Value, json};

use super::ViewSetup;

/// The grey value of a pixel where nothing was hit.
pub const NOTHING: u16 = u16::MAX;
/// The largest grey value of a hit (the far distance).
const FAR: u16 = u16::MAX - 1;

/// What a depth image holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DepthMode {
    /// Meshes only (splats write no depth).
    Mesh,
    /// Meshes and the first surface of every volume: where the opacity accumulated along the
    /// pixel's ray first passes a threshold.
    Surface,
}

impl DepthMode {
    /// `mesh` or `surface`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Mesh => "mesh",
            Self::Surface => "surface",
        }
    }
}

/// View distances of every pixel, row by row from the top (`None`: nothing there).
#[derive(Debug, Clone, PartialEq)]
pub struct DepthImage {
    /// Width and height.
    pub size: (u32, u32),
    /// Distance along the view axis, millimetres.
    pub distances: Vec<Option<f64>>,
    /// What the distances include.
    pub mode: DepthMode,
    /// The accumulated opacity that makes a volume surface (surface mode).
    pub surface_opacity: Option<f32>,
}

impl DepthImage {
    /// The smallest and largest distance, or `None` when nothing was hit. Equal ends are
    /// widened by a millimetre so the mapping stays defined.
    pub fn range(&self) -> Option<(f64, f64)> {
        let (lo, hi) = self
            .distances
            .iter()
            .flatten()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &d| {
                (a.min(d), b.max(d))
            });
        if !(lo.is_finite() && hi.is_finite()) {
            return None;
        }
        Some(if hi > lo {
            (lo, hi)
        } else {
            (lo - 0.5, hi + 0.5)
        })
    }

    /// The grey values, with the range they span.
    pub fn grey(&self) -> (Vec<u16>, Option<(f64, f64)>) {
        let range = self.range();
        let grey = self
            .distances
            .iter()
            .map(|d| match (d, range) {
                (Some(d), Some((near, far))) => {
                    let t = ((d - near) / (far - near)).clamp(0.0, 1.0);
                    (t * f64::from(FAR)).round() as u16
                }
                _ => NOTHING,
            })
            .collect();
        (grey, range)
    }

    /// The calibration as JSON: the sidecar's content and, key by key, the PNG's text chunks.
    pub fn calibration(&self, range: Option<(f64, f64)>, view: &ViewSetup) -> Value {
        let (near, far) = range.map_or((Value::Null, Value::Null), |(n, f)| (json!(n), json!(f)));
        let camera = &view.camera;
        json!({
            "near_mm": near,
            "far_mm": far,
            "encoding": format!(
                "distance along the view axis in mm = near_mm + (far_mm - near_mm) * grey / {FAR}; grey {NOTHING}: nothing hit"
            ),
            "nothing": NOTHING,
            "mode": self.mode.name(),
            "surface_opacity": self.surface_opacity,
            "frame": "RAS",
            "unit": "mm",
            "size": [self.size.0, self.size.1],
            "eye": camera.eye.to_array(),
            "target": camera.target.to_array(),
            "forward": (camera.target - camera.eye).normalize_or(DVec3::Z).to_array(),
            "orthographic": view.is_orthographic(),
        })
    }

    /// The image as a 16-bit grey PNG whose text chunks hold the calibration (`near_mm`,
    /// `far_mm`, `encoding`, `mode`; keys prefixed `splatscene:`).
    pub fn encode_png(&self, view: &ViewSetup) -> Result<(Vec<u8>, Value), png::EncodingError> {
        let (grey, range) = self.grey();
        let calibration = self.calibration(range, view);
        let mut bytes = Vec::new();
        {
            let mut encoder = png::Encoder::new(&mut bytes, self.size.0, self.size.1);
            encoder.set_color(png::ColorType::Grayscale);
            encoder.set_depth(png::BitDepth::Sixteen);
            for key in ["near_mm", "far_mm", "encoding", "mode"] {
                let text = match &calibration[key] {
                    Value::String(s) => s.clone(),
                    other => other.to_string(),
                };
                encoder.add_text_chunk(format!("splatscene:{key}"), text)?;
            }
            let mut writer = encoder.write_header()?;
            let data: Vec<u8> = grey.iter().flat_map(|v| v.to_be_bytes()).collect();
            writer.write_image_data(&data)?;
        }
        Ok((bytes, calibration))
    }
}
