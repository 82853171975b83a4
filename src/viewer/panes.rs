//! The four-pane layout (the `V` key): the 3D view top right, the axial slice top left, the
//! sagittal bottom left and the coronal (or, with `I`, the selected implant's long-axis plane)
//! bottom right, 3D Slicer's four-up. The panes share one crosshair point, set by a click in a
//! slice pane or on what a click in the 3D view picks; the wheel over a slice moves its plane through the point; Alt+drag over a slice
//! windows the slices; a drag on the selected implant in a slice moves it in that plane (one
//! edit, undone with Ctrl+Z). The slices are drawn from the plan as it stands at every frame,
//! so the outlines follow the implant while it moves.

use glam::{DMat4, DVec3};
use image::RgbaImage;

use super::App;
use crate::slice::draw::{Pane, quad_panes};
use crate::slice::{PlaneKind, SliceFrame, default_window};

/// The layout's state.
#[derive(Debug, Clone)]
pub(super) struct Panes {
    /// The point the three planes go through.
    pub point: DVec3,
    /// The bottom right pane's plane: coronal or implant-long.
    pub fourth: PlaneKind,
    /// The slices' grey window, set by Alt+drag over a slice; the volume's default until then.
    pub window: Option<[f32; 2]>,
    /// The window when an Alt+drag over a slice began.
    pub windowing: Option<[f32; 2]>,
    /// Where the slices last drawn lay (axial, sagittal, fourth), to map the mouse.
    pub frames: Vec<SliceFrame>,
}

/// What lies under a window pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Under {
    /// The 3D view, at this pixel of it.
    View(f64, f64),
    /// A slice pane (0 axial, 1 sagittal, 2 the fourth), at this pixel of it.
    Slice(usize, f64, f64),
}

impl Panes {
    pub(super) fn new(point: DVec3) -> Self {
        Self {
            point,
            fourth: PlaneKind::Coronal,
            window: None,
            windowing: None,
            frames: Vec::new(),
        }
    }

    /// The size of each pane in a window of `size`.
    pub(super) fn pane_size(size: (u32, u32)) -> (u32, u32) {
        ((size.0 / 2).max(1), (size.1 / 2).max(1))
    }

    /// The top left corner of the 3D view and of the slice panes (axial, sagittal, fourth).
    pub(super) fn corners(size: (u32, u32)) -> [(u32, u32); 4] {
        let (w, h) = Self::pane_size(size);
        [(w, 0), (0, 0), (0, h), (w, h)]
    }

    /// What lies under window pixel `(x, y)`.
    pub(super) fn under(size: (u32, u32), x: f64, y: f64) -> Under {
        let (w, h) = Self::pane_size(size);
        let (right, down) = (x >= f64::from(w), y >= f64::from(h));
        let (lx, ly) = (
            x - if right { f64::from(w) } else { 0.0 },
            y - if down { f64::from(h) } else { 0.0 },
        );
        match (right, down) {
            (true, false) => Under::View(lx, ly),
            (false, false) => Under::Slice(0, lx, ly),
            (false, true) => Under::Slice(1, lx, ly),
            (true, true) => Under::Slice(2, lx, ly),
        }
    }
}

impl App {
    /// The `V` key: four panes on and off.
    pub(super) fn toggle_panes(&mut self) {
        if self.panes.take().is_some() {
            self.say("one 3D view".into());
        } else {
            self.panes = Some(Panes::new(self.camera.target));
            self.say(
                "four panes: click a slice to move the crosshair, the wheel moves its plane, Alt+drag windows the slices, I for the implant's long axis"
                    .into(),
            );
        }
    }

    /// The `I` key: the bottom right pane between coronal and the implant's long axis.
    pub(super) fn toggle_implant_pane(&mut self) {
        let Some(panes) = &mut self.panes else {
            self.say("I shows the implant's long axis in the four panes: V first".into());
            return;
        };
        panes.fourth = if panes.fourth == PlaneKind::Coronal {
            PlaneKind::ImplantLong
        } else {
            PlaneKind::Coronal
        };
        let name = panes.fourth.name();
        self.say(format!("bottom right pane: {name}"));
    }

    /// The slices' window: the one Alt+drag set, else the volume's default.
    pub(super) fn slice_window(&self) -> [f32; 2] {
        if let Some(w) = self.panes.as_ref().and_then(|p| p.window) {
            return w;
        }
        match self.edit.scene.volumes().next() {
            Some((_, v, _)) => default_window(&v.volume),
            None => [0.0, 1.0],
        }
    }

    /// The slice panes of the plan as it stands, or why there are none (said on screen).
    pub(super) fn draw_panes(&mut self, size: (u32, u32)) -> Option<Vec<Pane>> {
        let panes = self.panes.as_ref()?;
        let window = self.slice_window();
        let mesh = self
            .edit
            .selected
            .and_then(|id| self.edit.scene.node(id).ok())
            .map(|n| n.name.clone());
        let parts = match (&self.options.annotations, self.annotations_on) {
            (Some(parts), true) => Some(parts.clone()),
            _ => None,
        };
        let drawn = quad_panes(
            &self.edit.scene,
            panes.point,
            Panes::pane_size(size),
            window,
            parts.as_ref(),
            panes.fourth,
            mesh.as_deref(),
        );
        match drawn {
            Ok(drawn) => {
                if let Some(p) = &mut self.panes {
                    p.frames = drawn.iter().map(|pane| pane.slice.frame).collect();
                }
                Some(drawn)
            }
            Err(e) => {
                let fallback = panes.fourth != PlaneKind::Coronal;
                if let Some(p) = &mut self.panes {
                    p.frames.clear();
                    if fallback {
                        p.fourth = PlaneKind::Coronal;
                    }
                }
                self.say(format!("slices: {e}"));
                None
            }
        }
    }

    /// The window's picture in four panes: the 3D view's and the slices'.
    pub(super) fn compose_panes(
        size: (u32, u32),
        view: &RgbaImage,
        slices: &[Pane],
        background: [u8; 4],
    ) -> RgbaImage {
        let mut image = RgbaImage::from_pixel(size.0, size.1, image::Rgba(background));
        let corners = Panes::corners(size);
        image::imageops::overlay(
            &mut image,
            view,
            i64::from(corners[0].0),
            i64::from(corners[0].1),
        );
        for (pane, (x, y)) in slices.iter().zip(&corners[1..]) {
            image::imageops::overlay(&mut image, &pane.image, i64::from(*x), i64::from(*y));
        }
        image
    }

    /// Where slice pane `pane` lay when last drawn.
    fn pane_frame(&self, pane: usize) -> Option<SliceFrame> {
        self.panes.as_ref()?.frames.get(pane).copied()
    }

    /// A click on slice pane `pane` at its pixel `(x, y)`: the crosshair goes there.
    pub(super) fn click_slice(&mut self, pane: usize, x: f64, y: f64) {
        let Some(frame) = self.pane_frame(pane) else {
            return;
        };
        // The centre of the pixel clicked (integers at pixel centres).
        let p = frame.world(x.floor(), y.floor());
        if let Some(panes) = &mut self.panes {
            panes.point = p;
        }
        let ras = self.edit.scene.patient_frame().patient(p);
        println!(
            "crosshair {}",
            serde_json::json!({"point_mm": [ras.x, ras.y, ras.z], "frame": "RAS", "pane": frame.plane.spec.kind.name()})
        );
    }

    /// The wheel over slice pane `pane`: its plane moves through the point along its normal,
    /// a voxel a step.
    pub(super) fn scroll_slice(&mut self, pane: usize, steps: f64) {
        let Some(frame) = self.pane_frame(pane) else {
            return;
        };
        let step = self
            .edit
            .scene
            .volumes()
            .next()
            .map_or(1.0, |(_, v, _)| v.volume.finest_spacing());
        let normal = frame.plane.normal;
        if let Some(panes) = &mut self.panes {
            panes.point += normal * step * steps;
            let at = panes.point.dot(normal);
            let name = frame.plane.spec.kind.name();
            self.say(format!("{name} at {at:.1} mm"));
        }
    }

    /// Whether pixel `(x, y)` of slice pane `pane` lies on the selected mesh's section (inside
    /// its outline or within a few pixels of it).
    pub(super) fn on_selected_slice(&self, pane: usize, x: f64, y: f64) -> bool {
        let (Some(top), Some(frame)) = (self.edit.selected, self.pane_frame(pane)) else {
            return false;
        };
        let outlines = crate::slice::outlines(&self.edit.scene, &frame.plane);
        let Some(outline) = outlines.iter().find(|o| o.node == top) else {
            return false;
        };
        let at = [x - 0.5, y - 0.5];
        let mut inside = false;
        let mut near = false;
        for (points, closed) in &outline.polylines {
            let px: Vec<[f64; 2]> = points.iter().map(|p| frame.pixel(*p)).collect();
            let count = if *closed {
                px.len()
            } else {
                px.len().saturating_sub(1)
            };
            for i in 0..count {
                let (a, b) = (px[i], px[(i + 1) % px.len()]);
                if (a[1] > at[1]) != (b[1] > at[1]) {
                    let cross = a[0] + (at[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
                    if cross > at[0] {
                        inside = !inside;
                    }
                }
                near |= segment_distance(at, a, b) < 4.0;
            }
        }
        inside || near
    }

    /// The selected mesh's transform `before` moved by the pixels `(dx, dy)` of slice pane
    /// `pane`, in that pane's plane.
    pub(super) fn moved_in_slice(&self, pane: usize, before: DMat4, dx: f64, dy: f64) -> DMat4 {
        match self.pane_frame(pane) {
            Some(frame) => {
                let delta = frame.pixel_right() * dx + frame.pixel_down() * dy;
                super::plan::translated(before, delta)
            }
            None => before,
        }
    }

    /// Alt+drag over a slice: right raises the level, up narrows the window, from where the
    /// drag began.
    pub(super) fn window_slices(&mut self, tx: f64, ty: f64) {
        let start = self.panes.as_ref().and_then(|p| p.windowing);
        let Some([lo, hi]) = start else {
            return;
        };
        let (level, width) = (0.5 * (lo + hi), (hi - lo).max(1e-3));
        let width = width * (ty as f32 * 0.01).exp();
        let level = level + tx as f32 * width / 400.0;
        if let Some(p) = &mut self.panes {
            p.window = Some([level - 0.5 * width, level + 0.5 * width]);
        }
    }
}

/// The distance from `p` to the segment from `a` to `b`.
fn segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (ab, ap) = ([b[0] - a[0], b[1] - a[1]], [p[0] - a[0], p[1] - a[1]]);
    let len2 = ab[0] * ab[0] + ab[1] * ab[1];
    let t = if len2 > 0.0 {
        ((ap[0] * ab[0] + ap[1] * ab[1]) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (ap[0] - t * ab[0]).hypot(ap[1] - t * ab[1])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_window_splits_into_slicers_four_up() {
        let size = (800, 600);
        assert_eq!(Panes::pane_size(size), (400, 300));
        assert_eq!(Panes::under(size, 500.0, 100.0), Under::View(100.0, 100.0));
        assert_eq!(Panes::under(size, 10.0, 20.0), Under::Slice(0, 10.0, 20.0));
        assert_eq!(Panes::under(size, 10.0, 320.0), Under::Slice(1, 10.0, 20.0));
        assert_eq!(
            Panes::under(size, 410.0, 320.0),
            Under::Slice(2, 10.0, 20.0)
        );
        assert_eq!(
            Panes::corners(size),
            [(400, 0), (0, 0), (0, 300), (400, 300)]
        );
    }
}
