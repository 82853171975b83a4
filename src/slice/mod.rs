//! Slices: the CT reformatted on a plane (axial, coronal, sagittal, or along and across an
//! implant's long axis), with every mesh's exact cross-section and the measurements that lie
//! on the plane; calibrated in patient millimetres the way depth images are. Planning tools
//! judge an implant's fit on such slices.
//!
//! - [`plane`]: which plane, and the directions its image's pixels step in;
//! - [`frame`]: the section of the volume by the plane, covered by square pixels;
//! - [`resample`](mod@resample): the volume's values on the pixels (trilinear) and their grey image;
//! - [`section`]: the meshes' cross-sections, joined into polylines;
//! - [`draw`] (with the `annotate` feature): the figure: grey, outlines, measurements and
//!   annotations.

use glam::DVec3;
use serde_json::{Value, json};
use thiserror::Error;

use crate::geometry::GeometryError;
use crate::measure::{Measurement, label_text};
use crate::scene::{ObjectError, Scene};

#[cfg(feature = "annotate")]
pub mod draw;
pub mod frame;
pub mod plane;
pub mod resample;
pub mod section;

pub use crate::classify::default_window;
pub use frame::{Extent, SliceFrame};
pub use plane::{BadSliceSpec, Plane, PlaneKind, SliceSpec, long_axis};
pub use resample::{SliceValues, grey, resample};
pub use section::{Outline, outlines};

/// Why a slice could not be made.
#[derive(Debug, Error)]
pub enum SliceError {
    /// A name that is no plane.
    #[error(transparent)]
    BadSpec(#[from] BadSliceSpec),
    /// The mesh an implant plane follows is not in the scene.
    #[error("the implant plane's mesh: {0}")]
    Object(#[from] ObjectError),
    /// The mesh has no single longest direction.
    #[error(
        "mesh {0:?} has no long axis (no area, or as long every way), so no plane can follow it"
    )]
    NoLongAxis(String),
    /// The scene has no volume to slice.
    #[error("the scene has no volume to slice")]
    NoVolume,
    /// The plane misses the volume.
    #[error(
        "the {plane} plane at {at_mm:.2} mm misses the volume{}, which spans {:.2} to {:.2} mm along the plane's normal",
        if *cropped { " (as its crop box cuts it)" } else { "" },
        extent[0],
        extent[1]
    )]
    Misses {
        /// The plane's name.
        plane: String,
        /// Its coordinate along its normal.
        at_mm: f64,
        /// The volume's extent along the normal.
        extent: [f64; 2],
        /// Whether the scene's crop box cut the volume.
        cropped: bool,
    },
    /// A pixel size that is no positive number.
    #[error("{0} mm a pixel: a slice's pixel size must be a positive number of millimetres")]
    BadPixelSize(f64),
    /// The slice would take more pixels than an image may hold.
    #[error(
        "the {plane} slice would take {width}x{height} pixels at {mm_per_pixel} mm a pixel, more than an image may hold; give a larger pixel size"
    )]
    TooLarge {
        /// The plane's name.
        plane: String,
        /// Pixels across.
        width: f64,
        /// Pixels down.
        height: f64,
        /// The pixel size asked for.
        mm_per_pixel: f64,
    },
    /// The volume's placement has no inverse.
    #[error("the volume cannot be placed: {0}")]
    Geometry(#[from] GeometryError),
}

/// A measurement drawn on a slice.
#[derive(Debug, Clone, PartialEq)]
pub struct SliceMeasurement {
    /// The measurement.
    pub measurement: Measurement,
    /// Its label with its value (`glenoid version 12.3°`).
    pub text: String,
}

/// A slice: its pixels, the volume's values on them, the meshes' cross-sections and the
/// measurements within half a slice of the plane.
#[derive(Debug, Clone, PartialEq)]
pub struct Slice {
    /// Where the pixels lie.
    pub frame: SliceFrame,
    /// The volume's values.
    pub values: SliceValues,
    /// The meshes' cross-sections.
    pub outlines: Vec<Outline>,
    /// The measurements on the plane.
    pub measurements: Vec<SliceMeasurement>,
    /// The name of the volume sliced.
    pub volume: String,
}

/// How a slice's pixels are chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pixels {
    /// Square pixels of this many millimetres covering the section (the volume's finest
    /// spacing where `None`).
    Size(Option<f64>),
    /// Exactly this many pixels, at this many millimetres a pixel, centred on the section.
    Fixed {
        /// Pixels across and down.
        size: (u32, u32),
        /// Millimetres a pixel.
        mm_per_pixel: f64,
    },
}

impl Slice {
    /// The slice of `scene` on `plane`.
    ///
    /// # Errors
    ///
    /// See [`SliceError`]: no volume, a plane that misses it, a bad pixel size.
    pub fn new(scene: &Scene, plane: Plane, pixels: Pixels) -> Result<Self, SliceError> {
        let extent = Extent::of(scene, &plane)?;
        let (volume_id, node, _) = scene.volumes().next().ok_or(SliceError::NoVolume)?;
        let frame = match pixels {
            Pixels::Size(mm) => {
                let finest = node.volume.finest_spacing();
                SliceFrame::new(plane, &extent, mm.unwrap_or(finest), None)?
            }
            Pixels::Fixed { size, mm_per_pixel } => {
                SliceFrame::new(plane, &extent, mm_per_pixel, Some(size))?
            }
        };
        let values = resample(scene, &frame)?;
        let outlines = outlines(scene, &plane);
        let half = 0.5 * slice_thickness(scene, &frame)?;
        let measurements = scene
            .measurements
            .iter()
            .filter_map(|m| {
                let measurement = scene.measure(m).ok()?;
                let on_plane = measurement
                    .points
                    .iter()
                    .all(|p| plane.distance(DVec3::from(*p)).abs() <= half);
                on_plane.then(|| SliceMeasurement {
                    text: label_text(&measurement, m.label.as_deref()),
                    measurement,
                })
            })
            .collect();
        Ok(Self {
            frame,
            values,
            outlines,
            measurements,
            volume: scene
                .node(volume_id)
                .map_or_else(|_| "volume".into(), |n| n.name.clone()),
        })
    }

    /// The slice's calibration, as the JSON beside its figure holds it: the patient frame
    /// (`"frame": "RAS"`, `"unit": "mm"`), the world point at the centre of pixel (0, 0)
    /// (`origin_mm`) and the world steps of one pixel right and down, the window, and per
    /// mesh its outline's length and the area it encloses.
    pub fn calibration(&self, scene: &Scene, window: [f32; 2]) -> Value {
        let patient = scene.patient_frame();
        let ras = |v: DVec3| {
            let p = patient.patient(v);
            json!([round(p.x), round(p.y), round(p.z)])
        };
        let f = &self.frame;
        json!({
            "frame": "RAS",
            "unit": "mm",
            "plane": f.plane.spec.to_string(),
            "at_mm": round(f.plane.offset()),
            "normal": ras(f.plane.normal),
            "size": [f.width, f.height],
            "mm_per_pixel": f.mm_per_pixel,
            "origin_mm": ras(f.origin),
            "pixel_right_mm": ras(f.pixel_right()),
            "pixel_down_mm": ras(f.pixel_down()),
            "window": window,
            "volume": self.volume,
            "meshes": self.outlines.iter().map(|o| json!({
                "name": o.name,
                "outline_mm": round(o.length_mm),
                "area_mm2": round(o.area_mm2),
                "polylines": o.polylines.len(),
                "closed": o.polylines.iter().all(|(_, closed)| *closed),
            })).collect::<Vec<_>>(),
            "measurements": self.measurements.iter().map(|m| json!({
                "kind": m.measurement.kind.name(),
                "text": m.text,
                "value": m.measurement.value,
            })).collect::<Vec<_>>(),
        })
    }
}

/// A number to a millionth of a millimetre, so that the JSON reads cleanly (and no `-0`).
fn round(v: f64) -> f64 {
    (v * 1e6).round() / 1e6 + 0.0
}

/// How thick a slice stands for: its pixel size, or the volume's spacing along the normal where
/// that is larger (the distance between the grid's planes met along it).
fn slice_thickness(scene: &Scene, frame: &SliceFrame) -> Result<f64, SliceError> {
    let geometry = frame::first_geometry(scene)?;
    let step = geometry.world_dir_to_index(frame.plane.normal);
    let largest = step.abs().max_element();
    let spacing = if largest > 0.0 { 1.0 / largest } else { 0.0 };
    Ok(frame.mm_per_pixel.max(spacing))
}
