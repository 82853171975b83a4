//! What the volume looks like: transfer functions (the scene's, the presets that fit the data,
//! a window dragged with Alt), the clip plane and the crop box.

use std::sync::Arc;

use glam::DVec3;

use super::{App, PRESETS};
use crate::classify::TransferFunction;
use crate::scene::{ClipPlane, NodeContent};

impl App {
    /// Keeps each volume's own transfer function, and the presets that fit the data, for
    /// the `T` key.
    pub(super) fn remember_transfers(&mut self) {
        self.own = self
            .edit
            .scene
            .volumes()
            .map(|(id, v, _)| (id, Arc::clone(&v.transfer)))
            .collect();
        let hounsfield = self
            .edit
            .scene
            .volumes()
            .next()
            .is_some_and(|(_, v, _)| crate::classify::is_hounsfield(&v.volume.values));
        self.fitting = PRESETS
            .iter()
            .copied()
            .filter(|p| p.starts_with("ct-") == hounsfield)
            .collect();
        self.preset = None;
        self.window = None;
    }
    /// What the transfer function is called on screen.
    pub(super) fn transfer_label(&self) -> String {
        let mut name = match self.preset {
            Some(p) => p.to_owned(),
            None => format!("scene: {}", self.transfer_name()),
        };
        if let Some((level, width)) = self.window {
            name.push_str(&format!(", window level {level:.0} width {width:.0}"));
        }
        name
    }
    /// Gives every volume the chosen function (its own, or the preset) under the window.
    pub(super) fn apply_transfer(&mut self) {
        let preset = self.preset.and_then(TransferFunction::preset).map(Arc::new);
        for (id, own) in self.own.clone() {
            let base = preset.clone().unwrap_or(own);
            let transfer = match self.window {
                Some((level, width)) => Arc::new(base.windowed(level, width)),
                None => base,
            };
            if let Ok(node) = self.edit.scene.node(id)
                && let NodeContent::Volume(v) = &node.content
                && !Arc::ptr_eq(&v.transfer, &transfer)
            {
                let mut v = v.clone();
                v.transfer = transfer;
                let _ = self.edit.scene.set_content(id, NodeContent::Volume(v));
            }
        }
    }
    /// The `T` key: the scene's own function, then each preset that fits the data and draws
    /// otherwise, in turn.
    pub(super) fn next_preset(&mut self) {
        let own = self.own.first().map(|(_, t)| Arc::clone(t));
        let choices: Vec<&'static str> = self
            .fitting
            .iter()
            .copied()
            .filter(|p| TransferFunction::preset(p).as_ref() != own.as_deref())
            .collect();
        self.preset = match self.preset {
            None => choices.first().copied(),
            Some(p) => choices
                .iter()
                .position(|c| *c == p)
                .and_then(|i| choices.get(i + 1))
                .copied(),
        };
        self.window = None;
        self.apply_transfer();
        println!(
            "transfer function {}",
            self.preset.unwrap_or("of the scene")
        );
    }
    /// The window of the function now drawn: its points' span.
    pub(super) fn current_window(&self) -> Option<(f32, f32)> {
        let (_, node, _) = self.edit.scene.volumes().next()?;
        let points = node.transfer.points();
        let (first, last) = (points.first()?.0, points.last()?.0);
        Some((0.5 * (first + last), (last - first).max(1.0)))
    }
    pub(super) fn toggle_clip(&mut self) {
        if self.edit.scene.clipping.planes.pop().is_none() {
            let toward_eye = (self.camera.eye - self.camera.target).normalize_or(DVec3::Y);
            let plane = ClipPlane::through(self.camera.target, toward_eye, false);
            self.edit.scene.clipping.planes.push(plane);
            println!("clip plane on, offset {:.1}", plane.offset);
        } else {
            println!("clip plane off");
        }
    }
    /// The `B` key: a crop box around the selected mesh (20 mm beyond it), or around the
    /// middle of the scene; off again.
    pub(super) fn toggle_crop(&mut self) {
        if self.edit.scene.clipping.crop.take().is_some() {
            println!("crop box off");
            return;
        }
        let around = match self.edit.selected {
            Some(top) => self
                .edit
                .scene
                .subtree_bounds(top)
                .map(|(lo, hi)| (lo - DVec3::splat(20.0), hi + DVec3::splat(20.0))),
            None => self.edit.scene.bounds().map(|(lo, hi)| {
                let inset = 0.15 * (hi - lo);
                (lo + inset, hi - inset)
            }),
        };
        if let Some((lo, hi)) = around {
            self.edit.scene.clipping.crop = Some((lo, hi));
            println!(
                "crop box on, min ({:.1}, {:.1}, {:.1}) max ({:.1}, {:.1}, {:.1})",
                lo.x, lo.y, lo.z, hi.x, hi.y, hi.z
            );
        }
    }
    /// Grows the crop box by `mm` on every side (shrinks it for negative `mm`, down to 1 mm).
    pub(super) fn grow_crop(&mut self, mm: f64) {
        if let Some((lo, hi)) = &mut self.edit.scene.clipping.crop {
            let centre = 0.5 * (*lo + *hi);
            let half = (0.5 * (*hi - *lo) + DVec3::splat(mm)).max(DVec3::splat(0.5));
            (*lo, *hi) = (centre - half, centre + half);
            println!(
                "crop box size ({:.1}, {:.1}, {:.1})",
                2.0 * half.x,
                2.0 * half.y,
                2.0 * half.z
            );
        }
    }
    /// Moves the clip plane by 2% of the scene's size: `sign` 1 toward the eye (cutting less).
    pub(super) fn move_clip(&mut self, sign: f64) {
        let step = self
            .edit
            .scene
            .bounds()
            .map_or(1.0, |(lo, hi)| (hi - lo).length() * 0.02);
        if let Some(plane) = self.edit.scene.clipping.planes.last_mut() {
            plane.offset += sign * step * plane.normal.length();
            println!("clip plane offset {:.1}", plane.offset);
        }
    }
}

impl App {
    /// Shift+K: the selected mesh (the first where none is) painted with the volume's value
    /// under its surface, a colour bar beside the view; off again.
    pub(super) fn toggle_contact_map(&mut self) {
        self.contact_map = !self.contact_map;
        if !self.contact_map {
            self.painted = None;
            self.say("contact map off".into());
            return;
        }
        self.refresh_contact_map();
        if let Some((_, _, painted)) = &self.painted {
            let [lo, hi] = painted.range;
            self.say(format!(
                "contact map: the value under the surface, {lo} (dark) to {hi} (yellow); grey outside the volume"
            ));
        }
    }

    /// Paints the mesh again where the plan changed since it was painted (it follows the
    /// implant while it moves).
    pub(super) fn refresh_contact_map(&mut self) {
        if !self.contact_map {
            self.painted = None;
            return;
        }
        let generation = self.edit.scene.generation();
        let target = self.edit.selected;
        if matches!(&self.painted, Some((g, t, _)) if *g == generation && *t == target) {
            return;
        }
        let name = target
            .and_then(|id| self.edit.scene.node(id).ok())
            .map(|n| n.name.clone());
        let range = match self.edit.scene.volumes().next() {
            Some((_, v, _)) if crate::classify::is_hounsfield(&v.volume.values) => [-100.0, 1000.0],
            Some((_, v, _)) => {
                let [lo, hi] = crate::slice::default_window(&v.volume);
                [f64::from(lo), f64::from(hi)]
            }
            None => [0.0, 1.0],
        };
        match crate::pick::paint::paint(&self.edit.scene, name.as_deref(), range) {
            Ok(painted) => self.painted = Some((generation, target, painted)),
            Err(e) => {
                self.contact_map = false;
                self.painted = None;
                self.say(format!("contact map: {e}"));
            }
        }
    }
}

/// The marks of a contact map's colour bar: its ends, and the CT classes' edges (200 and 700
/// HU) where the range is CT's.
pub(super) fn contact_ticks(range: [f64; 2]) -> Vec<(f64, String)> {
    let mut ticks = vec![
        (range[0], format!("{}", range[0])),
        (range[1], format!("{}", range[1])),
    ];
    if range == [-100.0, 1000.0] {
        ticks.extend([200.0, 700.0].map(|v| (v, format!("{v}"))));
    }
    ticks
}
