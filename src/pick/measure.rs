//! Measurements between picked points (distances and angles), written as JSON and drawn into
//! the scene as markers and lines that show in screenshots.

use std::f64::consts::PI;
use std::sync::Arc;

use glam::{DMat4, DQuat, DVec3};

pub use crate::measure::{MAX_POINT_MM, MeasureKind, Measurement, label_text};
use crate::mesh::{CpuMesh, Material};
use crate::scene::{MeshNode, NodeContent, NodeId, Scene, SceneError};

/// How measurements are drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MarkerStyle {
    /// Radius of the point markers, world units.
    pub point_radius: f64,
    /// Radius of the lines, world units.
    pub line_radius: f64,
    /// Colour and shading.
    pub material: Material,
}

impl Default for MarkerStyle {
    fn default() -> Self {
        Self {
            point_radius: 1.6,
            line_radius: 0.45,
            material: Material {
                base_color: [1.0, 0.78, 0.1, 1.0],
                roughness: 0.5,
                metallic: 0.0,
            },
        }
    }
}

impl MarkerStyle {
    /// Markers sized for `scene`: points of 0.6% of its diagonal.
    pub fn for_scene(scene: &Scene) -> Self {
        let radius = scene
            .bounds()
            .map_or(1.0, |(lo, hi)| (hi - lo).length() * 0.006);
        Self {
            point_radius: radius,
            line_radius: radius * 0.3,
            ..Self::default()
        }
    }
}

#[cfg(feature = "annotate")]
/// Draws the scene's own measurements into it (markers and lines, as [`annotate`] does) and
/// returns their values as text with where to write them.
///
/// # Errors
///
/// The measurement whose points no longer make one (a node moved onto another point), or the
/// scene refusing a marker.
pub fn draw_scene_measurements(
    scene: &mut Scene,
) -> Result<Vec<crate::annotate::Label>, DrawMeasurementError> {
    let style = MarkerStyle::for_scene(scene);
    let mut labels = Vec::new();
    for (i, m) in scene.measurements.clone().iter().enumerate() {
        let value = scene
            .measure(m)
            .map_err(|source| DrawMeasurementError::Measure {
                number: i + 1,
                source,
            })?;
        annotate(scene, &value, &style)?;
        labels.push(crate::annotate::Label {
            at: value.label_anchor(),
            text: label_text(&value, m.label.as_deref()),
        });
    }
    Ok(labels)
}

/// Why a scene's measurements could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum DrawMeasurementError {
    /// A measurement's points make no measurement (now that its node moved).
    #[error("measurement {number}: {source}")]
    Measure {
        /// Its number in the scene, from 1.
        number: usize,
        /// Why.
        source: crate::measure::MeasureError,
    },
    /// The scene refused a marker node.
    #[error(transparent)]
    Scene(#[from] SceneError),
}

/// Adds `measurement` to the scene as a group of marker spheres and line cylinders, drawn as
/// overlays (always visible, never picked); returns the group node.
pub fn annotate(
    scene: &mut Scene,
    measurement: &Measurement,
    style: &MarkerStyle,
) -> Result<NodeId, SceneError> {
    let group = scene.add("measurement", DMat4::IDENTITY, None, NodeContent::Empty)?;
    // One sphere and one cylinder for every marker ever drawn: the renderer keeps a mesh's
    // upload while its `Arc` is the same, so markers redrawn each frame (the viewer's) are not
    // uploaded again.
    static SPHERE: std::sync::OnceLock<Arc<CpuMesh>> = std::sync::OnceLock::new();
    static CYLINDER: std::sync::OnceLock<Arc<CpuMesh>> = std::sync::OnceLock::new();
    let sphere = Arc::clone(SPHERE.get_or_init(|| Arc::new(uv_sphere(12, 8))));
    let cylinder = Arc::clone(CYLINDER.get_or_init(|| Arc::new(unit_cylinder(12))));
    let node = |mesh: &Arc<CpuMesh>| {
        NodeContent::Overlay(MeshNode {
            mesh: Arc::clone(mesh),
            material: style.material,
        })
    };
    for p in &measurement.points {
        let at = DMat4::from_scale_rotation_translation(
            DVec3::splat(style.point_radius),
            DQuat::IDENTITY,
            DVec3::from_array(*p),
        );
        scene.add("marker", at, Some(group), node(&sphere))?;
    }
    for (a, b) in measurement.segments() {
        let along = b - a;
        let Some(axis) = along.try_normalize() else {
            continue;
        };
        let scale = DVec3::new(style.line_radius, style.line_radius, along.length());
        let at = DMat4::from_scale_rotation_translation(
            scale,
            DQuat::from_rotation_arc(DVec3::Z, axis),
            a,
        );
        scene.add("line", at, Some(group), node(&cylinder))?;
    }
    Ok(group)
}

/// A unit sphere of `segments` around and `rings` from pole to pole.
fn uv_sphere(segments: u32, rings: u32) -> CpuMesh {
    let mut mesh = CpuMesh::default();
    for r in 0..=rings {
        let theta = PI * f64::from(r) / f64::from(rings);
        for s in 0..=segments {
            let phi = 2.0 * PI * f64::from(s) / f64::from(segments);
            let n = DVec3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            )
            .as_vec3();
            mesh.positions.push(n.to_array());
            mesh.normals.push(n.to_array());
        }
    }
    let row = segments + 1;
    for r in 0..rings {
        for s in 0..segments {
            let (a, b) = (r * row + s, (r + 1) * row + s);
            mesh.indices
                .extend_from_slice(&[a, b, a + 1, a + 1, b, b + 1]);
        }
    }
    mesh
}

/// A unit-radius open cylinder from z = 0 to z = 1.
fn unit_cylinder(segments: u32) -> CpuMesh {
    let mut mesh = CpuMesh::default();
    for s in 0..=segments {
        let phi = 2.0 * std::f32::consts::PI * s as f32 / segments as f32;
        let (x, y) = (phi.cos(), phi.sin());
        for z in [0.0, 1.0] {
            mesh.positions.push([x, y, z]);
            mesh.normals.push([x, y, 0.0]);
        }
    }
    for s in 0..segments {
        let a = 2 * s;
        mesh.indices
            .extend_from_slice(&[a, a + 2, a + 1, a + 1, a + 2, a + 3]);
    }
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distances_and_angles() {
        let d = Measurement::distance(DVec3::ZERO, DVec3::new(3.0, 4.0, 0.0));
        assert_eq!((d.value, d.unit), (Some(5.0), "mm"));
        assert_eq!(d.value_text().unwrap(), "5.0 mm");
        let a = Measurement::angle(DVec3::X, DVec3::ZERO, DVec3::new(-1.0, 1.0, 0.0)).unwrap();
        let value = a.value.unwrap();
        assert!((value - 135.0).abs() < 1e-12, "{value}");
        assert_eq!(a.value_text().unwrap(), "135.0\u{b0}");
        let tiny = Measurement::angle(DVec3::X, DVec3::ZERO, DVec3::new(1.0, 1e-9, 0.0)).unwrap();
        assert!(
            (tiny.value.unwrap() - 1e-9f64.to_degrees()).abs() < 1e-15,
            "accurate near zero"
        );
        assert!(Measurement::angle(DVec3::ZERO, DVec3::ZERO, DVec3::X).is_none());
        // Lines are directed: 150 degrees between the directions, 30 with one line reversed.
        let down = DVec3::new(0.5, 0.0, -(0.75f64).sqrt());
        let l = Measurement::line_angle(DVec3::ZERO, DVec3::Z, DVec3::ZERO, down).unwrap();
        assert!((l.value.unwrap() - 150.0).abs() < 1e-9, "{:?}", l.value);
        let r = Measurement::line_angle(DVec3::Z, DVec3::ZERO, DVec3::ZERO, down).unwrap();
        assert!((r.value.unwrap() - 30.0).abs() < 1e-9, "{:?}", r.value);
        let json = serde_json::to_string(&a).unwrap();
        assert!(
            json.contains("\"kind\":\"angle\"") && json.contains("\"unit\":\"degrees\""),
            "{json}"
        );
        let p = Measurement::point(DVec3::ONE);
        assert_eq!(p.value_text(), None);
        assert!(!serde_json::to_string(&p).unwrap().contains("value"));
    }

    #[test]
    fn measurements_are_checked() {
        let p = [DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z];
        for kind in [
            MeasureKind::Distance,
            MeasureKind::Angle,
            MeasureKind::LineAngle,
            MeasureKind::Point,
        ] {
            let n = kind.point_count();
            assert!(Measurement::new(kind, &p[..n]).is_ok(), "{kind:?}");
            let e = Measurement::new(kind, &p[..n - 1]).unwrap_err().to_string();
            assert!(e.contains(&format!("takes {n} point")), "{e}");
        }
        let nan = DVec3::new(f64::NAN, 0.0, 0.0);
        assert!(Measurement::new(MeasureKind::Distance, &[nan, DVec3::X]).is_err());
        assert!(Measurement::new(MeasureKind::Angle, &[DVec3::X, DVec3::X, DVec3::Y]).is_err());
        assert!(
            Measurement::new(
                MeasureKind::LineAngle,
                &[DVec3::X, DVec3::X, DVec3::Y, DVec3::Z]
            )
            .is_err()
        );
        let a = Measurement::new(MeasureKind::Angle, &[DVec3::X, DVec3::ZERO, DVec3::Y]).unwrap();
        assert_eq!(a.label_anchor(), DVec3::ZERO);
    }

    #[test]
    fn annotation_adds_markers_and_lines() {
        let mut scene = Scene::new();
        let m = Measurement::angle(DVec3::X * 10.0, DVec3::ZERO, DVec3::Y * 10.0).unwrap();
        let group = annotate(&mut scene, &m, &MarkerStyle::default()).unwrap();
        let children = scene.node(group).unwrap().children().len();
        assert_eq!(children, 3 + 2, "three markers, two arms");
        let (lo, hi) = scene.bounds().unwrap();
        assert!(
            lo.x < -1.0 && hi.x > 11.0 && hi.y > 11.0,
            "markers around the points: {lo} {hi}"
        );
    }
}
