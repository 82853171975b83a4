//! What the viewer edits, with no window involved: the selected mesh and its moves, the
//! measurement being clicked, and the undo history of every edit.

use glam::{DMat4, DQuat, DVec3};

use crate::measure::{MeasureError, MeasureKind, Measurement};
use crate::scene::{NodeId, Projection, Scene, SceneCamera, SceneError, SceneMeasurement};

/// One edit of the plan, with what undoes it.
#[derive(Debug, Clone, PartialEq)]
pub enum Edit {
    /// A node moved from `before` to `after` (its local transform).
    Move {
        /// The node.
        node: NodeId,
        /// Its transform before.
        before: DMat4,
        /// Its transform after.
        after: DMat4,
    },
    /// A measurement added at `index`.
    Add {
        /// Where in the scene's list.
        index: usize,
        /// The measurement.
        measurement: SceneMeasurement,
    },
    /// The measurement at `index` removed.
    Remove {
        /// Where in the scene's list it was.
        index: usize,
        /// The measurement.
        measurement: SceneMeasurement,
    },
    /// A measurement replaced by another (its points dragged).
    Replace {
        /// Which.
        index: usize,
        /// The measurement before.
        before: SceneMeasurement,
        /// The measurement after.
        after: SceneMeasurement,
    },
    /// A measurement's label changed.
    Relabel {
        /// Which.
        index: usize,
        /// The label before.
        before: Option<String>,
        /// The label after.
        after: Option<String>,
    },
}

impl Edit {
    /// What the edit did, for the screen and standard output.
    pub fn describe(&self, scene: &Scene) -> String {
        match self {
            Self::Move { node, .. } => format!(
                "move {}",
                scene.node(*node).map_or("a node", |n| n.name.as_str())
            ),
            Self::Add { measurement, .. } => {
                format!("add {}", measurement_name(measurement))
            }
            Self::Remove { measurement, .. } => {
                format!("delete {}", measurement_name(measurement))
            }
            Self::Replace { index, after, .. } => {
                format!(
                    "move a point of measurement {} {}",
                    index + 1,
                    measurement_name(after)
                )
            }
            Self::Relabel { after, .. } => {
                format!("label {:?}", after.as_deref().unwrap_or(""))
            }
        }
    }

    /// The edit that undoes this one.
    fn inverse(&self) -> Self {
        match self.clone() {
            Self::Move {
                node,
                before,
                after,
            } => Self::Move {
                node,
                before: after,
                after: before,
            },
            Self::Add { index, measurement } => Self::Remove { index, measurement },
            Self::Remove { index, measurement } => Self::Add { index, measurement },
            Self::Replace {
                index,
                before,
                after,
            } => Self::Replace {
                index,
                before: after,
                after: before,
            },
            Self::Relabel {
                index,
                before,
                after,
            } => Self::Relabel {
                index,
                before: after,
                after: before,
            },
        }
    }

    /// Makes the edit in `scene`.
    fn apply(&self, scene: &mut Scene) -> Result<(), SceneError> {
        match self {
            Self::Move { node, after, .. } => scene.set_local(*node, *after),
            Self::Add { index, measurement } => {
                let at = (*index).min(scene.measurements.len());
                scene.measurements.insert(at, measurement.clone());
                Ok(())
            }
            Self::Remove { index, .. } => {
                if *index < scene.measurements.len() {
                    scene.measurements.remove(*index);
                }
                Ok(())
            }
            Self::Replace { index, after, .. } => {
                if let Some(m) = scene.measurements.get_mut(*index) {
                    *m = after.clone();
                }
                Ok(())
            }
            Self::Relabel { index, after, .. } => {
                if let Some(m) = scene.measurements.get_mut(*index) {
                    m.label = after.clone();
                }
                Ok(())
            }
        }
    }
}

/// A measurement's name: its label, or its kind.
pub fn measurement_name(m: &SceneMeasurement) -> String {
    match &m.label {
        Some(l) => format!("{} {l:?}", m.kind.name()),
        None => m.kind.name().to_owned(),
    }
}

/// The edits made, those undone (for redo), and where the last save stood.
#[derive(Debug, Default)]
pub struct History {
    done: Vec<Edit>,
    undone: Vec<Edit>,
    /// How many edits were done when the plan was last saved (or loaded).
    saved_at: Option<usize>,
}

impl History {
    /// A history with nothing to undo, the plan as saved.
    pub fn new() -> Self {
        Self {
            saved_at: Some(0),
            ..Self::default()
        }
    }

    /// A history with nothing to undo, of a plan that was never saved as it stands (one
    /// restored from an autosave).
    pub fn restored() -> Self {
        Self {
            saved_at: None,
            ..Self::default()
        }
    }

    /// Makes `edit` and keeps it for undo; redo is forgotten.
    pub fn apply(&mut self, scene: &mut Scene, edit: Edit) -> Result<(), SceneError> {
        edit.apply(scene)?;
        self.record(edit);
        Ok(())
    }

    /// Keeps `edit`, already made (a drag moves the node as it goes), for undo.
    pub fn record(&mut self, edit: Edit) {
        if let Edit::Move { before, after, .. } = &edit
            && before == after
        {
            return;
        }
        if let Edit::Replace { before, after, .. } = &edit
            && before == after
        {
            return;
        }
        if self.saved_at.is_some_and(|s| s > self.done.len()) {
            // The saved state lay among the undone edits, which are now gone for good.
            self.saved_at = None;
        }
        self.done.push(edit);
        self.undone.clear();
    }

    /// Undoes the last edit; returns it.
    pub fn undo(&mut self, scene: &mut Scene) -> Option<Edit> {
        let edit = self.done.pop()?;
        if edit.inverse().apply(scene).is_err() {
            self.done.push(edit);
            return None;
        }
        self.undone.push(edit.clone());
        Some(edit)
    }

    /// Redoes the last undone edit; returns it.
    pub fn redo(&mut self, scene: &mut Scene) -> Option<Edit> {
        let edit = self.undone.pop()?;
        if edit.apply(scene).is_err() {
            self.undone.push(edit);
            return None;
        }
        self.done.push(edit.clone());
        Some(edit)
    }

    /// Whether the plan differs from what was last saved or loaded.
    pub fn unsaved(&self) -> bool {
        self.saved_at != Some(self.done.len())
    }

    /// The plan as it stands is saved.
    pub fn mark_saved(&mut self) {
        self.saved_at = Some(self.done.len());
    }
}

/// `local` (of a top node, so its world transform) moved by `delta` in the world.
pub fn translated(local: DMat4, delta: DVec3) -> DMat4 {
    DMat4::from_translation(delta) * local
}

/// `local` (of a top node) turned by `degrees` about the world axis `axis` through `pivot`.
pub fn rotated(local: DMat4, pivot: DVec3, axis: DVec3, degrees: f64) -> DMat4 {
    let Some(axis) = axis.try_normalize() else {
        return local;
    };
    let turn = DMat4::from_quat(DQuat::from_axis_angle(axis, degrees.to_radians()));
    DMat4::from_translation(pivot) * turn * DMat4::from_translation(-pivot) * local
}

/// The camera's right, up and forward directions on screen (unit, world).
pub fn screen_axes(camera: &SceneCamera) -> (DVec3, DVec3, DVec3) {
    let forward = (camera.target - camera.eye).normalize_or(DVec3::Y);
    let right = forward.cross(camera.up).normalize_or(DVec3::X);
    let up = right.cross(forward);
    (right, up, forward)
}

/// World millimetres per pixel at `point`, for an image `height` pixels high: in perspective,
/// at the point's depth along the view axis; in orthographic views, everywhere.
pub fn pixel_size(camera: &SceneCamera, height: u32, point: DVec3) -> f64 {
    let (_, _, forward) = screen_axes(camera);
    let h = f64::from(height.max(1));
    match camera.projection {
        Projection::Perspective { fov_y_degrees } => {
            let depth = (point - camera.eye).dot(forward).max(1e-6);
            2.0 * depth * (0.5 * fov_y_degrees.to_radians()).tan() / h
        }
        Projection::Orthographic { height } => height / h,
    }
}

/// A measurement being clicked: its kind and the points so far, each with the top mesh node it
/// was picked on (if any).
#[derive(Debug, Clone, PartialEq)]
pub struct Pending {
    /// What is measured.
    pub kind: MeasureKind,
    /// Points picked so far (world) and the mesh each lies on.
    pub points: Vec<(DVec3, Option<NodeId>)>,
}

impl Pending {
    /// Starts a measurement of `kind`.
    pub fn new(kind: MeasureKind) -> Self {
        Self {
            kind,
            points: Vec::new(),
        }
    }

    /// Adds a point; when the kind has all its points, the finished measurement: in the frame
    /// of the mesh every point lies on (so that it moves with it), else in the world.
    ///
    /// # Errors
    ///
    /// When the points make no measurement (an angle's point on its vertex); the points are
    /// then cleared.
    pub fn add(
        &mut self,
        scene: &Scene,
        point: DVec3,
        on: Option<NodeId>,
    ) -> Result<Option<SceneMeasurement>, MeasureError> {
        self.points.push((point, on));
        if self.points.len() < self.kind.point_count() {
            return Ok(None);
        }
        let points: Vec<(DVec3, Option<NodeId>)> = std::mem::take(&mut self.points);
        let world: Vec<DVec3> = points.iter().map(|(p, _)| *p).collect();
        Measurement::new(self.kind, &world)?;
        let first = points[0].1;
        let same = points.iter().all(|(_, n)| *n == first);
        // All on one mesh: in its frame; on different things: each point with its own
        // (an implant point follows the implant, a bone point stays).
        let (node, anchors) = if same {
            (first, Vec::new())
        } else {
            (None, points.iter().map(|(_, n)| *n).collect())
        };
        let frame = |i: usize| if same { first } else { points[i].1 };
        let points = world
            .iter()
            .enumerate()
            .map(|(i, p)| frame(i).map_or(*p, |id| scene.world(id).inverse().transform_point3(*p)))
            .collect();
        Ok(Some(SceneMeasurement {
            kind: self.kind,
            points,
            node,
            anchors,
            label: None,
        }))
    }
}

/// The measure mode after `kind`: distance, angle, line angle, point, then off.
pub fn next_kind(kind: Option<MeasureKind>) -> Option<MeasureKind> {
    match kind {
        None => Some(MeasureKind::Distance),
        Some(MeasureKind::Distance) => Some(MeasureKind::Angle),
        Some(MeasureKind::Angle) => Some(MeasureKind::LineAngle),
        Some(MeasureKind::LineAngle) => Some(MeasureKind::Point),
        Some(MeasureKind::Point) => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::NodeContent;

    fn scene_with_group() -> (Scene, NodeId, NodeId) {
        let mut scene = Scene::new();
        let top = scene
            .add(
                "implant",
                DMat4::from_translation(DVec3::new(10.0, 0.0, 0.0)),
                None,
                NodeContent::Empty,
            )
            .unwrap();
        let part = scene
            .add("stem", DMat4::IDENTITY, Some(top), NodeContent::Empty)
            .unwrap();
        (scene, top, part)
    }

    #[test]
    fn moves_undo_and_redo() {
        let (mut scene, top, part) = scene_with_group();
        assert_eq!(scene.top_node(part), top);
        let mut history = History::new();
        assert!(!history.unsaved());
        let before = scene.node(top).unwrap().local();
        let after = translated(before, DVec3::new(0.0, 5.0, 0.0));
        history
            .apply(
                &mut scene,
                Edit::Move {
                    node: top,
                    before,
                    after,
                },
            )
            .unwrap();
        assert!(history.unsaved());
        assert_eq!(
            scene.world(part).transform_point3(DVec3::ZERO),
            DVec3::new(10.0, 5.0, 0.0)
        );
        let undone = history.undo(&mut scene).unwrap();
        assert_eq!(undone.describe(&scene), "move implant");
        assert_eq!(scene.node(top).unwrap().local(), before);
        assert!(!history.unsaved(), "back where it was saved");
        history.redo(&mut scene).unwrap();
        assert_eq!(scene.node(top).unwrap().local(), after);
        assert!(history.undo(&mut scene).is_some());
        assert!(history.undo(&mut scene).is_none(), "nothing more to undo");
        // A new edit forgets what was undone.
        history
            .apply(
                &mut scene,
                Edit::Relabel {
                    index: 0,
                    before: None,
                    after: Some("x".into()),
                },
            )
            .unwrap();
        assert!(history.redo(&mut scene).is_none());
    }

    #[test]
    fn turns_keep_the_pivot_and_measurements_follow_their_node() {
        let (mut scene, top, _) = scene_with_group();
        let (origin, name) = scene.pivot(top);
        assert_eq!(
            (origin, name.as_str()),
            (DVec3::new(10.0, 0.0, 0.0), "origin")
        );
        scene.measurements.push(SceneMeasurement {
            kind: MeasureKind::Point,
            points: vec![DVec3::new(0.0, 0.0, 7.0)],
            node: Some(top),
            anchors: Vec::new(),
            label: Some("head centre".into()),
        });
        let (p, name) = scene.pivot(top);
        assert_eq!(
            (p, name.as_str()),
            (DVec3::new(10.0, 0.0, 7.0), "head centre")
        );
        let local = scene.node(top).unwrap().local();
        let turned = rotated(local, p, DVec3::Y, 90.0);
        scene.set_local(top, turned).unwrap();
        let (after, _) = scene.pivot(top);
        assert!(after.distance(p) < 1e-9, "the pivot stays put: {after}");
        // The origin swings about it: 7 mm below the pivot turns to 7 mm along -x... about y.
        let origin = scene.world(top).transform_point3(DVec3::ZERO);
        assert!((origin.distance(p) - 7.0).abs() < 1e-9);
    }

    #[test]
    fn clicked_measurements_take_the_frame_of_their_mesh() {
        let (scene, top, _) = scene_with_group();
        let mut pending = Pending::new(MeasureKind::Distance);
        assert!(
            pending
                .add(&scene, DVec3::new(10.0, 0.0, 0.0), Some(top))
                .unwrap()
                .is_none()
        );
        let m = pending
            .add(&scene, DVec3::new(10.0, 3.0, 4.0), Some(top))
            .unwrap()
            .unwrap();
        assert_eq!(m.node, Some(top));
        assert_eq!(m.points[0], DVec3::ZERO, "in the implant's frame");
        assert_eq!(scene.measure(&m).unwrap().value, Some(5.0));
        // Points on different things: each in the frame of what it lies on.
        let mut pending = Pending::new(MeasureKind::Distance);
        pending
            .add(&scene, DVec3::new(10.0, 0.0, 0.0), Some(top))
            .unwrap();
        let m = pending.add(&scene, DVec3::X, None).unwrap().unwrap();
        assert_eq!((m.node, m.anchors.clone()), (None, vec![Some(top), None]));
        assert_eq!(m.points, vec![DVec3::ZERO, DVec3::X]);
        assert_eq!(scene.measure(&m).unwrap().value, Some(9.0));
        // An angle on its vertex is refused, and the points start again.
        let mut pending = Pending::new(MeasureKind::Angle);
        pending.add(&scene, DVec3::X, None).unwrap();
        pending.add(&scene, DVec3::X, None).unwrap();
        assert!(pending.add(&scene, DVec3::Y, None).is_err());
        assert!(pending.points.is_empty());
        assert_eq!(next_kind(Some(MeasureKind::Point)), None);
    }

    #[test]
    fn a_pixel_at_the_target_spans_what_the_view_height_says() {
        let camera = SceneCamera {
            eye: DVec3::new(0.0, -100.0, 0.0),
            target: DVec3::ZERO,
            up: DVec3::Z,
            projection: Projection::Perspective {
                fov_y_degrees: 90.0,
            },
            near: None,
        };
        // 90 degrees at 100 mm: 200 mm over 400 pixels.
        assert!((pixel_size(&camera, 400, DVec3::ZERO) - 0.5).abs() < 1e-12);
        let ortho = SceneCamera {
            projection: Projection::Orthographic { height: 80.0 },
            ..camera
        };
        assert_eq!(pixel_size(&ortho, 400, DVec3::new(5.0, 50.0, 0.0)), 0.2);
    }
}
