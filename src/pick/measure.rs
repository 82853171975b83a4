//! Measurements between picked points (distances and angles), written as JSON and drawn into
//! the scene as markers and lines that show in screenshots.

use std::f64::consts::PI;
use std::sync::Arc;

use glam::{DMat4, DQuat, DVec3};
use serde::Serialize;

use crate::mesh::{CpuMesh, Material};
use crate::scene::{MeshNode, NodeContent, NodeId, Scene, SceneError};

/// What was measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum MeasureKind {
    /// Distance between two points, millimetres.
    Distance,
    /// Angle at the middle of three points, degrees.
    Angle,
    /// Angle between the lines through two pairs of points, degrees (0 to 90).
    LineAngle,
}

/// A measurement: its kind, the world points it was taken from and its value.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Measurement {
    /// Distance or angle.
    pub kind: MeasureKind,
    /// The points, in world millimetres.
    pub points: Vec<[f64; 3]>,
    /// The value, in `unit`.
    pub value: f64,
    /// "mm" or "degrees".
    pub unit: &'static str,
}

impl Measurement {
    /// The distance from `a` to `b`.
    pub fn distance(a: DVec3, b: DVec3) -> Self {
        Self {
            kind: MeasureKind::Distance,
            points: vec![a.to_array(), b.to_array()],
            value: a.distance(b),
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
            value,
            unit: "degrees",
        })
    }

    /// The angle between the line through `a0, a1` and the line through `b0, b1` (0 to 90
    /// degrees: lines have no direction), as for the inclination of a prosthesis against the
    /// shaft axis; `None` for a degenerate line.
    pub fn line_angle(a0: DVec3, a1: DVec3, b0: DVec3, b1: DVec3) -> Option<Self> {
        let value = angle_between(a1 - a0, b1 - b0)?;
        Some(Self {
            kind: MeasureKind::LineAngle,
            points: vec![a0.to_array(), a1.to_array(), b0.to_array(), b1.to_array()],
            value: value.min(180.0 - value),
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

/// Adds `measurement` to the scene as a group of marker spheres and line cylinders, drawn as
/// overlays (always visible, never picked); returns the group node.
pub fn annotate(
    scene: &mut Scene,
    measurement: &Measurement,
    style: &MarkerStyle,
) -> Result<NodeId, SceneError> {
    let group = scene.add("measurement", DMat4::IDENTITY, None, NodeContent::Empty)?;
    let sphere = Arc::new(uv_sphere(12, 8));
    let cylinder = Arc::new(unit_cylinder(12));
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
        assert_eq!((d.value, d.unit), (5.0, "mm"));
        let a = Measurement::angle(DVec3::X, DVec3::ZERO, DVec3::new(-1.0, 1.0, 0.0)).unwrap();
        assert!((a.value - 135.0).abs() < 1e-12, "{}", a.value);
        let tiny = Measurement::angle(DVec3::X, DVec3::ZERO, DVec3::new(1.0, 1e-9, 0.0)).unwrap();
        assert!(
            (tiny.value - 1e-9f64.to_degrees()).abs() < 1e-15,
            "accurate near zero"
        );
        assert!(Measurement::angle(DVec3::ZERO, DVec3::ZERO, DVec3::X).is_none());
        // Lines have no direction: 150 degrees between directions is 30 between lines.
        let l = Measurement::line_angle(
            DVec3::ZERO,
            DVec3::Z,
            DVec3::ZERO,
            DVec3::new(0.5, 0.0, -(0.75f64).sqrt()),
        )
        .unwrap();
        assert!((l.value - 30.0).abs() < 1e-9, "{}", l.value);
        let json = serde_json::to_string(&a).unwrap();
        assert!(
            json.contains("\"kind\":\"angle\"") && json.contains("\"unit\":\"degrees\""),
            "{json}"
        );
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
