//! Measurements between points (distances and angles) as values: what was measured, from
//! which world points, and its value and unit. Drawing them and taking them from a scene stand
//! above, in `pick::measure`.

use glam::DVec3;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// The farthest a measured point may lie from the origin, in millimetres (a thousand
/// kilometres).
pub const MAX_POINT_MM: f64 = 1e9;

/// What was measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MeasureKind {
    /// Distance between two points, millimetres.
    Distance,
    /// Angle at the middle of three points, degrees (0 to 180).
    Angle,
    /// Angle between the directed lines from the first point to the second and from the third
    /// to the fourth, degrees (0 to 180): a neck-shaft angle of 135 degrees reads 135, not 45.
    LineAngle,
    /// A marked point (a landmark); it has no value.
    Point,
}

impl MeasureKind {
    /// How many points a measurement of this kind takes.
    pub fn point_count(self) -> usize {
        match self {
            Self::Distance => 2,
            Self::Angle => 3,
            Self::LineAngle => 4,
            Self::Point => 1,
        }
    }

    /// The name in scene files and JSON.
    pub fn name(self) -> &'static str {
        match self {
            Self::Distance => "distance",
            Self::Angle => "angle",
            Self::LineAngle => "line-angle",
            Self::Point => "point",
        }
    }
}

/// A measurement: its kind, the world points it was taken from and its value.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Measurement {
    /// Distance, angle or point.
    pub kind: MeasureKind,
    /// The points, in world millimetres.
    pub points: Vec<[f64; 3]>,
    /// The value, in `unit` (none for a point).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub value: Option<f64>,
    /// "mm" or "degrees" (a point's coordinates are in mm).
    pub unit: &'static str,
}

/// Why points make no measurement.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum MeasureError {
    /// Not the number of points the kind takes.
    #[error("{} takes {} point{}, not {got}", kind_with_article(*.kind), .kind.point_count(), if .kind.point_count() == 1 { "" } else { "s" })]
    PointCount {
        /// The kind.
        kind: MeasureKind,
        /// The points given.
        got: usize,
    },
    /// A point with a NaN or infinite coordinate.
    #[error("point {0} is not finite")]
    NotFinite(DVec3),
    /// A point so far from the origin that differences of points lose every millimetre.
    #[error("point {0} lies more than {MAX_POINT_MM:e} mm from the origin")]
    TooFar(DVec3),
    /// An angle whose first or last point is on its vertex.
    #[error("an angle needs its first and last points apart from its vertex")]
    AngleAtVertex,
    /// A line of a line angle whose two points coincide.
    #[error("each line of a line angle needs two distinct points")]
    LineOfOnePoint,
}

/// "a distance", "an angle"...
fn kind_with_article(kind: MeasureKind) -> String {
    let article = if kind == MeasureKind::Angle {
        "an"
    } else {
        "a"
    };
    format!("{article} {}", kind.name())
}

impl Measurement {
    /// The measurement of `kind` over `points`.
    ///
    /// # Errors
    ///
    /// When the number of points is not the kind's, a point is not finite or lies past
    /// [`MAX_POINT_MM`], or the points make no angle (a point on its vertex, a line of one
    /// point).
    pub fn new(kind: MeasureKind, points: &[DVec3]) -> Result<Self, MeasureError> {
        if points.len() != kind.point_count() {
            return Err(MeasureError::PointCount {
                kind,
                got: points.len(),
            });
        }
        if let Some(bad) = points.iter().find(|p| !p.is_finite()) {
            return Err(MeasureError::NotFinite(*bad));
        }
        // Past this the differences of two points overflow or lose every millimetre; no
        // scene is that large.
        if let Some(bad) = points.iter().find(|p| p.abs().max_element() > MAX_POINT_MM) {
            return Err(MeasureError::TooFar(*bad));
        }
        match (kind, points) {
            (MeasureKind::Distance, [a, b]) => Ok(Self::distance(*a, *b)),
            (MeasureKind::Angle, [a, v, b]) => {
                Self::angle(*a, *v, *b).ok_or(MeasureError::AngleAtVertex)
            }
            (MeasureKind::LineAngle, [a0, a1, b0, b1]) => {
                Self::line_angle(*a0, *a1, *b0, *b1).ok_or(MeasureError::LineOfOnePoint)
            }
            (MeasureKind::Point, [p]) => Ok(Self::point(*p)),
            // The count was checked against the kind's above.
            _ => Err(MeasureError::PointCount {
                kind,
                got: points.len(),
            }),
        }
    }

    /// A marked point.
    pub fn point(p: DVec3) -> Self {
        Self {
            kind: MeasureKind::Point,
            points: vec![p.to_array()],
            value: None,
            unit: "mm",
        }
    }

    /// The value as text with its unit (`42.3 mm`, `131.9°`), none for a point.
    pub fn value_text(&self) -> Option<String> {
        let value = self.value?;
        Some(match self.kind {
            MeasureKind::Distance => format!("{value:.1} mm"),
            _ => format!("{value:.1}\u{b0}"),
        })
    }

    /// Where a label goes: the middle of a distance, the vertex of an angle, the middle of the
    /// first line of a line angle, the point itself.
    pub fn label_anchor(&self) -> DVec3 {
        let p: Vec<DVec3> = self.points.iter().map(|p| DVec3::from(*p)).collect();
        match (self.kind, p.as_slice()) {
            (MeasureKind::Angle, [_, v, _]) => *v,
            (_, [a, b, ..]) => 0.5 * (*a + *b),
            (_, [a]) => *a,
            _ => DVec3::ZERO,
        }
    }
    /// The distance from `a` to `b`.
    pub fn distance(a: DVec3, b: DVec3) -> Self {
        Self {
            kind: MeasureKind::Distance,
            points: vec![a.to_array(), b.to_array()],
            value: Some(a.distance(b)),
            unit: "mm",
        }
    }

    /// The angle at `vertex` between the rays to `a` and `b` (0 to 180 degrees); `None` when a
    /// point coincides with the vertex.
    pub fn angle(a: DVec3, vertex: DVec3, b: DVec3) -> Option<Self> {
        let value = angle_between(a - vertex, b - vertex)?;
        Some(Self {
            kind: MeasureKind::Angle,
            points: vec![a.to_array(), vertex.to_array(), b.to_array()],
            value: Some(value),
            unit: "degrees",
        })
    }

    /// The angle between the directed line from `a0` to `a1` and the directed line from `b0`
    /// to `b1` (0 to 180 degrees), as for a neck-shaft angle (the shaft axis drawn from distal
    /// to proximal, the neck axis from the shaft to the head); `None` for a line of one point.
    /// Swapping the points of one line gives 180 degrees less the angle.
    pub fn line_angle(a0: DVec3, a1: DVec3, b0: DVec3, b1: DVec3) -> Option<Self> {
        let value = angle_between(a1 - a0, b1 - b0)?;
        Some(Self {
            kind: MeasureKind::LineAngle,
            points: vec![a0.to_array(), a1.to_array(), b0.to_array(), b1.to_array()],
            value: Some(value),
            unit: "degrees",
        })
    }

    /// The segments to draw: the measured line, both arms of an angle, or both lines.
    pub fn segments(&self) -> Vec<(DVec3, DVec3)> {
        let p: Vec<DVec3> = self.points.iter().map(|p| DVec3::from_array(*p)).collect();
        match (self.kind, p.as_slice()) {
            (MeasureKind::Distance, [a, b]) => vec![(*a, *b)],
            (MeasureKind::Angle, [a, v, b]) => vec![(*v, *a), (*v, *b)],
            (MeasureKind::LineAngle, [a0, a1, b0, b1]) => vec![(*a0, *a1), (*b0, *b1)],
            _ => Vec::new(),
        }
    }
}

fn angle_between(u: DVec3, v: DVec3) -> Option<f64> {
    let (u, v) = (u.try_normalize()?, v.try_normalize()?);
    // atan2 of the cross and dot products stays accurate near 0 and 180 degrees.
    Some(u.cross(v).length().atan2(u.dot(v)).to_degrees())
}

/// The text written beside a measurement: `label: value`, the value alone, or for a point its
/// label (or `point`).
pub fn label_text(m: &Measurement, label: Option<&str>) -> String {
    match (label, m.value_text()) {
        (Some(l), Some(v)) => format!("{l}: {v}"),
        (None, Some(v)) => v,
        (Some(l), None) => l.to_owned(),
        (None, None) => "point".into(),
    }
}
