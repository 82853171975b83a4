//! The plan being edited, with no window: the scene, the selected mesh and its moves, the
//! measurements clicked, selected, labelled and deleted, snap mode, and the undo history. The
//! window turns keys into [`Action`]s and clicks into picked points, and hands them here; what
//! an edit tells the user comes back as a [`Notice`].

use glam::{DMat4, DVec3};

use super::action::{Action, ScreenAxis};
use super::plan::{self, Edit, History, Pending};
use crate::measure::MeasureKind;
use crate::pick::contact::{Classes, contact};
use crate::scene::{NodeId, Scene, SceneCamera};

/// What an edit tells the user.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Notice {
    /// On screen for a few seconds, and on standard output.
    Say(String),
    /// On standard output alone (a line scripts read).
    Print(String),
}

/// What Escape did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Cancelled {
    /// Something under way was cancelled.
    Done(Option<Notice>),
    /// Nothing was under way: Escape quits.
    Nothing,
}

/// A key while a label is typed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LabelKey<'a> {
    /// Enter: the label is set (an empty one removes it).
    Enter,
    /// Escape: the label is left as it was.
    Escape,
    /// Backspace: the last character typed is removed.
    Backspace,
    /// Any other key, with the text it types, if any.
    Text(Option<&'a str>),
}

/// The longest label typed, in characters.
const MAX_LABEL: usize = 200;

/// The plan and what is being done to it.
#[derive(Debug)]
pub struct Editor {
    /// The scene: meshes, volumes and measurements.
    pub scene: Scene,
    /// The edits, for undo and redo, and whether the plan is saved.
    pub history: History,
    /// The selected mesh (a top node).
    pub selected: Option<NodeId>,
    /// The measurement being clicked, in measure mode.
    pub measuring: Option<Pending>,
    /// Snap mode: `Some(None)` waits for a point on the selected mesh, `Some(Some(p))` for
    /// the target that point moves to.
    pub snapping: Option<Option<DVec3>>,
    /// The selected measurement (an index into the scene's).
    pub chosen: Option<usize>,
    /// The label being typed for the selected measurement.
    pub labelling: Option<String>,
    /// The placement being typed for the selected mesh (see [`super::typed`]).
    pub placing: Option<String>,
    /// The last picked point, marked on screen.
    pub marker: Option<DVec3>,
}

impl Editor {
    /// An editor of `scene` with nothing selected and nothing edited.
    pub fn new(scene: Scene) -> Self {
        Self {
            scene,
            history: History::new(),
            selected: None,
            measuring: None,
            snapping: None,
            chosen: None,
            labelling: None,
            placing: None,
            marker: None,
        }
    }

    /// Escape: cancels snap mode, else the points clicked, else measure mode, else the
    /// selection; [`Cancelled::Nothing`] when none of them was under way.
    pub fn cancel(&mut self) -> Cancelled {
        if self.snapping.take().is_some() {
            return Cancelled::Done(Some(Notice::Print("snap off".into())));
        }
        if let Some(m) = &mut self.measuring {
            if m.points.is_empty() {
                self.measuring = None;
                return Cancelled::Done(Some(Notice::Print("measure off".into())));
            }
            m.points.clear();
            return Cancelled::Done(None);
        }
        if self.selected.take().is_some() {
            return Cancelled::Done(Some(Notice::Print("selected nothing".into())));
        }
        Cancelled::Nothing
    }

    /// Carries out an action that edits the plan, the screen's axes taken from `camera`;
    /// actions that only change the view do nothing here.
    pub fn act(&mut self, action: Action, camera: &SceneCamera) -> Option<Notice> {
        let (right, up, forward) = plan::screen_axes(camera);
        let axis = |a: ScreenAxis| match a {
            ScreenAxis::Right => right,
            ScreenAxis::Up => up,
            ScreenAxis::Forward => forward,
        };
        match action {
            Action::Nudge { along, mm } => {
                let delta = axis(along) * mm;
                self.move_selected(|l, _| plan::translated(l, delta))
            }
            Action::Turn { about, degrees } => {
                let about = axis(about);
                self.move_selected(|l, p| plan::rotated(l, p, about, degrees))
            }
            Action::Undo => Some(self.undo(false)),
            Action::Redo => Some(self.undo(true)),
            Action::NextMeasurement => {
                let n = self.scene.measurements.len();
                self.chosen = (n > 0).then(|| self.chosen.map_or(0, |i| (i + 1) % n));
                None
            }
            Action::DeleteMeasurement => self.delete_measurement(),
            Action::NextMeasureKind => {
                let kind = plan::next_kind(self.measuring.as_ref().map(|m| m.kind));
                self.measuring = kind.map(Pending::new);
                self.snapping = None;
                Some(Notice::Print(format!(
                    "measure {}",
                    kind.map_or("off", MeasureKind::name)
                )))
            }
            Action::Snap => Some(if self.selected.is_some() {
                self.snapping = Some(None);
                self.measuring = None;
                Notice::Say("snap: click a point of the selected mesh".into())
            } else {
                Notice::Say("snap: select a mesh first (click it)".into())
            }),
            Action::Contact => Some(self.contact()),
            Action::Place => Some(if self.selected.is_some() {
                self.placing = Some(String::new());
                Notice::Say(
                    "type a placement: x 2.5 (mm along R), rz -10 (degrees about S), x=12.5 (the pivot's x); Enter places, Escape cancels".into(),
                )
            } else {
                Notice::Say("select a mesh to place first (click it)".into())
            }),
            Action::ClearPoints => {
                if let Some(m) = &mut self.measuring {
                    m.points.clear();
                }
                self.marker = None;
                Some(Notice::Print("points cleared".into()))
            }
            Action::Label => {
                if self.chosen.is_none() {
                    self.chosen = self.scene.measurements.len().checked_sub(1);
                }
                if let Some(i) = self.chosen {
                    self.labelling =
                        Some(self.scene.measurements[i].label.clone().unwrap_or_default());
                }
                None
            }
            _ => None,
        }
    }

    /// The contact of the selected mesh (else the first) with the first volume, in a line:
    /// each class's share of the surface, and the share outside the volume.
    fn contact(&self) -> Notice {
        let name = self
            .selected
            .and_then(|id| self.scene.node(id).ok())
            .map(|n| n.name.clone());
        let classes = self
            .scene
            .volumes()
            .next()
            .map_or_else(Classes::none, |(_, v, _)| Classes::for_volume(&v.volume));
        Notice::Say(match contact(&self.scene, name.as_deref(), &classes) {
            Err(e) => format!("contact: {e}"),
            Ok(c) => {
                let mut parts: Vec<String> = c
                    .classes
                    .iter()
                    .map(|k| format!("{:.0}% {}", 100.0 * k.fraction, k.name))
                    .collect();
                if let Some(v) = c.value {
                    parts.push(format!("mean value {:.0}", v.mean));
                }
                if c.outside_mm2 > 0.0 {
                    parts.push(format!(
                        "{:.0}% outside the volume",
                        100.0 * c.outside_fraction
                    ));
                }
                format!(
                    "contact {} ({:.1} mm2): {}",
                    c.mesh,
                    c.area_mm2,
                    parts.join(", ")
                )
            }
        })
    }

    /// Deletes the selected measurement, or the last one when none is selected.
    fn delete_measurement(&mut self) -> Option<Notice> {
        let index = self
            .chosen
            .or_else(|| self.scene.measurements.len().checked_sub(1))?;
        let measurement = self.scene.measurements.get(index)?.clone();
        let edit = Edit::Remove { index, measurement };
        let said = edit.describe(&self.scene);
        self.history.apply(&mut self.scene, edit).ok()?;
        self.chosen = None;
        Some(Notice::Say(format!("measurement {} {said}", index + 1)))
    }

    /// Moves the selected mesh to `after(local, pivot)` (its local transform), as one
    /// undoable edit.
    pub fn move_selected(&mut self, after: impl Fn(DMat4, DVec3) -> DMat4) -> Option<Notice> {
        let top = self.selected?;
        let before = self.scene.node(top).ok()?.local();
        let (pivot, _) = self.scene.pivot(top);
        let edit = Edit::Move {
            node: top,
            before,
            after: after(before, pivot),
        };
        match self.history.apply(&mut self.scene, edit) {
            Err(e) => Some(Notice::Say(format!("move refused: {e}"))),
            Ok(()) => self.where_selected(),
        }
    }

    /// Where the selected mesh stands, as a line on standard output.
    pub fn where_selected(&self) -> Option<Notice> {
        let node = self.scene.node(self.selected?).ok()?;
        Some(Notice::Print(format!(
            "moved {} {}",
            node.name,
            serde_json::json!({ "matrix": node.local().to_cols_array() })
        )))
    }

    /// Undoes the last edit, or redoes the last undone.
    pub fn undo(&mut self, redo: bool) -> Notice {
        let word = if redo { "redo" } else { "undo" };
        let edit = if redo {
            self.history.redo(&mut self.scene)
        } else {
            self.history.undo(&mut self.scene)
        };
        let Some(edit) = edit else {
            return Notice::Say(format!("nothing to {word}"));
        };
        if let Some(i) = self.chosen
            && i >= self.scene.measurements.len()
        {
            self.chosen = self.scene.measurements.len().checked_sub(1);
        }
        Notice::Say(format!("{word} {}", edit.describe(&self.scene)))
    }

    /// A key while a label is typed ([`Editor::labelling`] is `Some`).
    pub fn label_key(&mut self, key: LabelKey<'_>) -> Option<Notice> {
        let typed = self.labelling.as_mut()?;
        match key {
            LabelKey::Enter => {
                let text = typed.trim().to_owned();
                self.labelling = None;
                let index = self.chosen?;
                let before = self.scene.measurements.get(index)?.label.clone();
                let edit = Edit::Relabel {
                    index,
                    before,
                    after: (!text.is_empty()).then_some(text),
                };
                let said = edit.describe(&self.scene);
                self.history.apply(&mut self.scene, edit).ok()?;
                Some(Notice::Say(format!("measurement {} {said}", index + 1)))
            }
            LabelKey::Escape => {
                self.labelling = None;
                None
            }
            LabelKey::Backspace => {
                typed.pop();
                None
            }
            LabelKey::Text(text) => {
                let room = MAX_LABEL.saturating_sub(typed.chars().count());
                if let Some(t) = text {
                    typed.extend(t.chars().filter(|c| !c.is_control()).take(room));
                }
                None
            }
        }
    }

    /// A click that picked `hit` (a world point, on the top mesh `on_mesh` where it is on a
    /// mesh): in snap mode, the point of the mesh and then where it goes; in measure mode, the
    /// measurement's next point; else it selects the mesh clicked (or nothing).
    pub fn click(&mut self, hit: Option<DVec3>, on_mesh: Option<NodeId>) -> Option<Notice> {
        self.marker = hit;
        if let Some(from) = self.snapping {
            let hit = hit?;
            return match (from, self.selected) {
                (None, Some(top)) if on_mesh == Some(top) => {
                    self.snapping = Some(Some(hit));
                    Some(Notice::Say("snap: now click where that point goes".into()))
                }
                (None, _) => Some(Notice::Say(
                    "snap: click a point of the selected mesh".into(),
                )),
                (Some(source), Some(_)) => {
                    self.snapping = None;
                    let delta = hit - source;
                    if let Some(Notice::Say(refused)) =
                        self.move_selected(|l, _| plan::translated(l, delta))
                    {
                        return Some(Notice::Say(refused));
                    }
                    Some(Notice::Say(format!(
                        "snapped by ({:.1}, {:.1}, {:.1}) mm",
                        delta.x, delta.y, delta.z
                    )))
                }
                (Some(_), None) => {
                    self.snapping = None;
                    None
                }
            };
        }
        if let Some(pending) = &mut self.measuring {
            let hit = hit?;
            return match pending.add(&self.scene, hit, on_mesh) {
                Ok(Some(measurement)) => {
                    let index = self.scene.measurements.len();
                    let edit = Edit::Add { index, measurement };
                    let said = edit.describe(&self.scene);
                    self.history.apply(&mut self.scene, edit).ok()?;
                    self.chosen = Some(index);
                    self.marker = None;
                    let value = self
                        .scene
                        .measure(&self.scene.measurements[index])
                        .ok()
                        .and_then(|m| m.value_text())
                        .unwrap_or_default();
                    Some(Notice::Say(format!(
                        "measurement {} {said} {value}",
                        index + 1
                    )))
                }
                Ok(None) => None,
                Err(e) => Some(Notice::Say(format!(
                    "measurement refused: {e}; click its points again"
                ))),
            };
        }
        if on_mesh == self.selected {
            return None;
        }
        self.selected = on_mesh;
        Some(Notice::Print(
            match on_mesh.and_then(|id| self.scene.node(id).ok()) {
                Some(node) => format!("selected {}", node.name),
                None => "selected nothing".into(),
            },
        ))
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::mesh::{CpuMesh, Material};
    use crate::scene::{MeshNode, NodeContent};

    /// A scene with one mesh, "implant", a unit triangle at the origin, and a camera looking
    /// down -z from +z with y up (screen right is +x, screen up +y, forward -z).
    fn editor() -> (Editor, NodeId, SceneCamera) {
        let mut scene = Scene::new();
        let mut mesh = CpuMesh {
            colors: Vec::new(),
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            normals: Vec::new(),
            indices: vec![0, 1, 2],
        };
        mesh.compute_normals();
        let node = MeshNode {
            mesh: Arc::new(mesh),
            material: Material::default(),
        };
        let id = scene
            .add("implant", DMat4::IDENTITY, None, NodeContent::Mesh(node))
            .unwrap();
        let camera = SceneCamera {
            up: DVec3::Y,
            ..SceneCamera::look_at(DVec3::new(0.0, 0.0, 100.0), DVec3::ZERO)
        };
        (Editor::new(scene), id, camera)
    }

    fn translation(editor: &Editor, id: NodeId) -> DVec3 {
        editor.scene.node(id).unwrap().local().w_axis.truncate()
    }

    #[test]
    fn a_nudge_moves_the_selected_mesh_along_the_screen_and_undo_puts_it_back() {
        let (mut editor, id, camera) = editor();
        let nudge = |mm| Action::Nudge {
            along: ScreenAxis::Right,
            mm,
        };
        // Nothing selected: nothing moves, nothing is recorded.
        assert_eq!(editor.act(nudge(5.0), &camera), None);
        assert!(!editor.history.unsaved());
        // Clicking the mesh selects it; a nudge moves it 5 mm to screen right (+x here).
        assert_eq!(
            editor.click(Some(DVec3::new(0.2, 0.2, 0.0)), Some(id)),
            Some(Notice::Print("selected implant".into()))
        );
        let said = editor.act(nudge(5.0), &camera);
        assert!(
            matches!(&said, Some(Notice::Print(line)) if line.starts_with("moved implant")),
            "{said:?}"
        );
        assert!((translation(&editor, id) - DVec3::new(5.0, 0.0, 0.0)).length() < 1e-12);
        // + (toward the eye) is -forward: +z here.
        editor.act(
            Action::Nudge {
                along: ScreenAxis::Forward,
                mm: -2.0,
            },
            &camera,
        );
        assert!((translation(&editor, id) - DVec3::new(5.0, 0.0, 2.0)).length() < 1e-12);
        assert!(editor.history.unsaved());
        assert_eq!(
            editor.act(Action::Undo, &camera),
            Some(Notice::Say("undo move implant".into()))
        );
        assert_eq!(
            editor.act(Action::Undo, &camera),
            Some(Notice::Say("undo move implant".into()))
        );
        assert_eq!(translation(&editor, id), DVec3::ZERO);
        assert_eq!(
            editor.act(Action::Undo, &camera),
            Some(Notice::Say("nothing to undo".into()))
        );
        editor.act(Action::Redo, &camera);
        assert!((translation(&editor, id) - DVec3::new(5.0, 0.0, 0.0)).length() < 1e-12);
    }

    #[test]
    fn a_turn_keeps_the_pivot_where_it_is() {
        let (mut editor, id, camera) = editor();
        editor.click(Some(DVec3::ZERO), Some(id));
        let (pivot, _) = editor.scene.pivot(id);
        editor.act(
            Action::Turn {
                about: ScreenAxis::Up,
                degrees: 90.0,
            },
            &camera,
        );
        let local = editor.scene.node(id).unwrap().local();
        assert!((local.transform_point3(pivot) - pivot).length() < 1e-9);
        // 90 degrees about +y takes +x to -z.
        let x = local.transform_vector3(DVec3::X);
        assert!((x - DVec3::new(0.0, 0.0, -1.0)).length() < 1e-9, "{x}");
    }

    #[test]
    fn a_distance_is_measured_in_two_clicks_labelled_and_deleted_with_undo() {
        let (mut editor, _, camera) = editor();
        editor.act(Action::NextMeasureKind, &camera);
        assert_eq!(
            editor.measuring.as_ref().unwrap().kind,
            MeasureKind::Distance
        );
        assert_eq!(editor.click(Some(DVec3::ZERO), None), None);
        let said = editor.click(Some(DVec3::new(3.0, 4.0, 0.0)), None);
        assert!(
            matches!(&said, Some(Notice::Say(s)) if s.starts_with("measurement 1 add") && s.contains("5.0")),
            "{said:?}"
        );
        assert_eq!(editor.scene.measurements.len(), 1);
        assert_eq!(editor.chosen, Some(0));
        // L, type, Backspace, Enter: the label is set, as one undoable edit.
        editor.act(Action::Label, &camera);
        for key in [
            LabelKey::Text(Some("neck")),
            LabelKey::Text(Some("x")),
            LabelKey::Backspace,
            LabelKey::Text(Some(" cut\n")),
        ] {
            editor.label_key(key);
        }
        editor.label_key(LabelKey::Enter);
        assert_eq!(
            editor.scene.measurements[0].label.as_deref(),
            Some("neck cut")
        );
        editor.act(Action::Undo, &camera);
        assert_eq!(editor.scene.measurements[0].label, None);
        // Delete takes the selected one; undo brings it back.
        editor.act(Action::DeleteMeasurement, &camera);
        assert!(editor.scene.measurements.is_empty());
        editor.act(Action::Undo, &camera);
        assert_eq!(editor.scene.measurements.len(), 1);
    }

    #[test]
    fn escape_cancels_one_thing_at_a_time_then_asks_to_quit() {
        let (mut editor, id, camera) = editor();
        editor.click(Some(DVec3::ZERO), Some(id));
        editor.act(Action::NextMeasureKind, &camera);
        editor.click(Some(DVec3::ZERO), None);
        assert_eq!(editor.measuring.as_ref().unwrap().points.len(), 1);
        // The point clicked, then measure mode, then the selection, then nothing.
        assert_eq!(editor.cancel(), Cancelled::Done(None));
        assert!(editor.measuring.as_ref().unwrap().points.is_empty());
        assert_eq!(
            editor.cancel(),
            Cancelled::Done(Some(Notice::Print("measure off".into())))
        );
        assert_eq!(
            editor.cancel(),
            Cancelled::Done(Some(Notice::Print("selected nothing".into())))
        );
        assert_eq!(editor.cancel(), Cancelled::Nothing);
    }

    #[test]
    fn k_reports_the_selected_meshs_contact_with_the_volume() {
        let (mut editor, id, camera) = editor();
        // No volume yet: said so.
        assert_eq!(
            editor.act(Action::Contact, &camera),
            Some(Notice::Say(
                "contact: the scene has no volume to sample under the mesh".into()
            ))
        );
        // A CT-like volume: air (-1000) below z = 0, cortical bone (1500) above, in 1 mm
        // voxels from -5 to 5 mm; the triangle, moved 1 mm toward the eye, lies in z = 1, in bone.
        let values = (0..11 * 11 * 11)
            .map(|i| if i / 121 >= 6 { 1500.0 } else { -1000.0 })
            .collect();
        let volume = crate::volume::CpuVolume {
            dims: [11; 3],
            spacing: [1.0; 3],
            origin: [-5.0; 3],
            direction: glam::DMat3::IDENTITY,
            values,
        };
        let node = crate::scene::VolumeNode {
            volume: Arc::new(volume),
            transfer: Arc::new(crate::classify::TransferFunction::ct_bone()),
            splats: crate::scene::SplatSettings::default(),
        };
        editor
            .scene
            .add("ct", DMat4::IDENTITY, None, NodeContent::Volume(node))
            .unwrap();
        editor.click(Some(DVec3::ZERO), Some(id));
        editor.act(
            Action::Nudge {
                along: ScreenAxis::Forward,
                mm: -1.0,
            },
            &camera,
        );
        assert_eq!(
            editor.act(Action::Contact, &camera),
            Some(Notice::Say(
                "contact implant (0.5 mm2): 0% soft tissue or air, 0% cancellous bone, 100% cortical bone, mean value 1500".into()
            ))
        );
    }

    #[test]
    fn snap_moves_the_point_clicked_on_the_mesh_onto_the_target() {
        let (mut editor, id, camera) = editor();
        assert_eq!(
            editor.act(Action::Snap, &camera),
            Some(Notice::Say("snap: select a mesh first (click it)".into()))
        );
        editor.click(Some(DVec3::ZERO), Some(id));
        editor.act(Action::Snap, &camera);
        // A point off the mesh is not taken as the source.
        editor.click(Some(DVec3::new(9.0, 9.0, 9.0)), None);
        assert_eq!(editor.snapping, Some(None));
        editor.click(Some(DVec3::new(0.5, 0.25, 0.0)), Some(id));
        let said = editor.click(Some(DVec3::new(10.5, 0.25, -3.0)), None);
        assert_eq!(
            said,
            Some(Notice::Say("snapped by (10.0, 0.0, -3.0) mm".into()))
        );
        assert!((translation(&editor, id) - DVec3::new(10.0, 0.0, -3.0)).length() < 1e-12);
        assert_eq!(editor.snapping, None);
    }
}
