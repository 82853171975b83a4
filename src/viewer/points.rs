//! Measurement points moved by hand: a drag that starts on a point's marker in the 3D view
//! takes the point along the surfaces under the cursor (meshes or the volume, as picks find
//! them), the value following live; the whole drag is one edit, undone with Ctrl+Z. A point
//! of a measurement attached to a mesh stays in that mesh's frame.

use glam::DVec3;

use super::App;
use super::panes::Under;
use super::plan::Edit;
use crate::annotate::ImageCamera;
use crate::pick::PickOptions;
use crate::scene::SceneMeasurement;

/// How near a marker, in pixels, a drag must start to take its point.
const GRAB_PX: f64 = 8.0;

impl App {
    /// The 3D view's pixel under window pixel `at` (the window's own with one view), or
    /// `None` over a slice pane.
    pub(super) fn in_view(&self, at: (f64, f64)) -> Option<(f64, f64)> {
        match self.under(at.0, at.1) {
            Some(Under::View(x, y)) => Some((x, y)),
            Some(Under::Slice(..)) => None,
            None => Some(at),
        }
    }

    /// The measurement point whose marker lies nearest window pixel `at` in the 3D view,
    /// within a few pixels: (measurement, point).
    pub(super) fn point_at(&self, at: (f64, f64)) -> Option<(usize, usize)> {
        let (x, y) = self.in_view(at)?;
        let view = self.view()?.ok()?;
        let camera = ImageCamera::new(&self.camera, view.size.0, view.size.1)?;
        let scene = &self.edit.scene;
        let mut best: Option<(f64, usize, usize)> = None;
        for (i, m) in scene.measurements.iter().enumerate() {
            let Ok(value) = scene.measure(m) else {
                continue;
            };
            for (j, p) in value.points.iter().enumerate() {
                let Some([px, py]) = camera.project(DVec3::from(*p)) else {
                    continue;
                };
                let d = (f64::from(px) - x).hypot(f64::from(py) - y);
                if d <= GRAB_PX && best.is_none_or(|(b, _, _)| d < b) {
                    best = Some((d, i, j));
                }
            }
        }
        best.map(|(_, i, j)| (i, j))
    }

    /// Moves point `j` of measurement `i` to the surface under window pixel `at`, where there
    /// is one and the points still make a measurement.
    pub(super) fn drag_point(&mut self, i: usize, j: usize, at: (f64, f64)) {
        let Some((x, y)) = self.in_view(at) else {
            return;
        };
        let Some(Ok(view)) = self.view() else {
            return;
        };
        if x < 0.0 || y < 0.0 || x >= f64::from(view.size.0) || y >= f64::from(view.size.1) {
            return;
        }
        self.picker.update(&self.edit.scene);
        let Some(hit) = self.picker.pick_pixel(
            &self.edit.scene,
            &view,
            x as u32,
            y as u32,
            &PickOptions::default(),
        ) else {
            return;
        };
        let Some(m) = self.edit.scene.measurements.get(i) else {
            return;
        };
        let world = hit.point();
        let stored = match m.frame_of(j) {
            Some(id) => self.edit.scene.world(id).inverse().transform_point3(world),
            None => world,
        };
        let mut after = m.clone();
        let Some(point) = after.points.get_mut(j) else {
            return;
        };
        *point = stored;
        if self.edit.scene.measure(&after).is_ok() {
            self.edit.scene.measurements[i] = after;
        }
    }

    /// The end of a point's drag: the move kept as one edit, its new value said.
    pub(super) fn dropped_point(&mut self, i: usize, before: SceneMeasurement) {
        let Some(after) = self.edit.scene.measurements.get(i).cloned() else {
            return;
        };
        if after == before {
            return;
        }
        let value = self
            .edit
            .scene
            .measure(&after)
            .ok()
            .and_then(|m| m.value_text())
            .unwrap_or_default();
        let edit = Edit::Replace {
            index: i,
            before,
            after,
        };
        let said = edit.describe(&self.edit.scene);
        self.edit.history.record(edit);
        self.edit.chosen = Some(i);
        self.say(format!("{said}: {value}"));
    }
}
