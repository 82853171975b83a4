//! What the volume looks like: transfer functions (the scene's, the presets that fit the data,
//! a window dragged with Alt), the clip plane and the crop box.

use std::sync::Arc;

use glam::DVec3;

use super::{App, PRESETS};
use crate::classify::{Histogram, TransferFunction};
use crate::mesh::Material;
use crate::scene::{ClipPlane, NodeContent, NodeId};

/// A transfer function the `T` key offers: a preset, or for data that are no Hounsfield units
/// a ramp over percentiles of the values.
#[derive(Debug, Clone)]
pub(super) struct Choice {
    /// Its name on screen and on standard output.
    pub name: String,
    /// The function.
    pub transfer: Arc<TransferFunction>,
    /// How a scene file names it: the preset's name, else a ramp's window and colour.
    pub saved: Result<&'static str, ([f32; 2], [f32; 4])>,
}

/// The percentile spans of the ramps offered for data that are no Hounsfield units: the
/// brightest structures (as the automatic function), the upper half, most of the range.
const RAMPS: [(f64, f64); 3] = [(0.90, 0.995), (0.60, 0.95), (0.25, 0.90)];

/// The ramps' colour, as the automatic function's.
const RAMP_COLOUR: [f32; 4] = [1.0, 0.93, 0.85, 0.7];

/// The choices for data whose values `histogram` counts: the CT presets for Hounsfield data;
/// else ramps over the values' percentiles, then the MR preset.
pub(super) fn choices(hounsfield: bool, histogram: Option<&Histogram>) -> Vec<Choice> {
    let preset = |name: &'static str| {
        TransferFunction::preset(name).map(|t| Choice {
            name: name.to_owned(),
            transfer: Arc::new(t),
            saved: Ok(name),
        })
    };
    let mut out = Vec::new();
    if !hounsfield && let Some(h) = histogram {
        for (a, b) in RAMPS {
            let (from, to) = (h.quantile(a), h.quantile(b));
            if to > from {
                out.push(Choice {
                    name: format!(
                        "ramp p{}-p{} ({}..{})",
                        a * 100.0,
                        b * 100.0,
                        short(from, h.hi - h.lo),
                        short(to, h.hi - h.lo)
                    ),
                    transfer: Arc::new(TransferFunction::ramp(from, to, RAMP_COLOUR)),
                    saved: Err(([from, to], RAMP_COLOUR)),
                });
            }
        }
    }
    out.extend(
        PRESETS
            .iter()
            .filter(|p| p.starts_with("ct-") == hounsfield)
            .filter_map(|p| preset(p)),
    );
    out
}

/// The opacities O steps through.
pub(super) const OPACITIES: [f32; 3] = [1.0, 0.6, 0.3];

/// The colours Shift+O steps through after the mesh's own: bone, implant steel, bone cement,
/// and red, green and blue to tell parts apart.
pub(super) const COLOURS: [(&str, [f32; 3]); 6] = [
    ("bone", [0.89, 0.85, 0.76]),
    ("steel", [0.72, 0.75, 0.80]),
    ("cement", [0.80, 0.86, 0.62]),
    ("red", [0.85, 0.30, 0.25]),
    ("green", [0.35, 0.75, 0.40]),
    ("blue", [0.35, 0.55, 0.90]),
];

/// A mesh's look as O and Shift+O set it.
#[derive(Debug, Clone, Default)]
pub(super) struct Look {
    /// Which of [`OPACITIES`].
    pub opacity: usize,
    /// 0 for the mesh's own colours, else which of [`COLOURS`] (from 1).
    pub colour: usize,
    /// The materials of the meshes under the node as they were loaded.
    pub own: Vec<(NodeId, Material)>,
}

impl Look {
    /// What it is called on screen.
    pub fn describe(&self) -> String {
        let colour = match self.colour {
            0 => "its own colour",
            n => COLOURS[n - 1].0,
        };
        format!("opacity {:.0}%, {colour}", OPACITIES[self.opacity] * 100.0)
    }

    /// The material `own` looks like under this look.
    fn material(&self, own: &Material) -> Material {
        let mut m = *own;
        if self.colour > 0 {
            let [r, g, b] = COLOURS[self.colour - 1].1;
            m.base_color = [r, g, b, own.base_color[3]];
        }
        m.base_color[3] = own.base_color[3] * OPACITIES[self.opacity];
        m
    }
}

/// `v` to about a thousandth of `span`: `102`, `0.153`.
fn short(v: f32, span: f32) -> String {
    let decimals = (3.0 - span.abs().max(1e-6).log10().floor()).clamp(0.0, 6.0) as usize;
    format!("{v:.decimals$}")
}

impl App {
    /// O (`opacity`) or Shift+O: the selected mesh's next opacity or colour, drawn at once
    /// and saved with the plan.
    pub(super) fn next_look(&mut self, opacity: bool) {
        let Some(top) = self.edit.selected else {
            self.say("select a mesh first (click it)".into());
            return;
        };
        let scene = &self.edit.scene;
        let look = self.looks.entry(top).or_insert_with(|| {
            let mut own = Vec::new();
            let mut stack = vec![top];
            while let Some(id) = stack.pop() {
                if let Ok(node) = scene.node(id) {
                    stack.extend_from_slice(node.children());
                    if let NodeContent::Mesh(m) = &node.content {
                        own.push((id, m.material));
                    }
                }
            }
            Look {
                own,
                ..Look::default()
            }
        });
        if opacity {
            look.opacity = (look.opacity + 1) % OPACITIES.len();
        } else {
            look.colour = (look.colour + 1) % (COLOURS.len() + 1);
        }
        let look = look.clone();
        for (id, own) in &look.own {
            if let Ok(node) = self.edit.scene.node(*id)
                && let NodeContent::Mesh(m) = &node.content
            {
                let mut m = m.clone();
                m.material = look.material(own);
                let _ = self.edit.scene.set_content(*id, NodeContent::Mesh(m));
            }
        }
        let name = self
            .edit
            .scene
            .node(top)
            .map_or_else(|_| "the mesh".to_owned(), |n| n.name.clone());
        self.say(format!("look {name}: {}", look.describe()));
    }

    /// Keeps each volume's own transfer function, the first volume's histogram, and the
    /// functions that fit its data, for the `T` key.
    pub(super) fn remember_transfers(&mut self) {
        self.own = self
            .edit
            .scene
            .volumes()
            .map(|(id, v, _)| (id, Arc::clone(&v.transfer)))
            .collect();
        let first = self.edit.scene.volumes().next();
        let hounsfield =
            first.is_some_and(|(_, v, _)| crate::classify::is_hounsfield(&v.volume.values));
        self.histogram = first.and_then(|(_, v, _)| Histogram::of(&v.volume.values));
        self.fitting = choices(hounsfield, self.histogram.as_ref());
        self.preset = None;
        self.window = None;
    }
    /// What the transfer function is called on screen.
    pub(super) fn transfer_label(&self) -> String {
        let mut name = match &self.preset {
            Some(c) => c.name.clone(),
            None => format!("scene: {}", self.transfer_name()),
        };
        if let Some((level, width)) = self.window {
            name.push_str(&format!(", window level {level:.0} width {width:.0}"));
        }
        name
    }
    /// Gives every volume the chosen function (its own, or the preset) under the window.
    pub(super) fn apply_transfer(&mut self) {
        let preset = self.preset.as_ref().map(|c| Arc::clone(&c.transfer));
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
    /// The `T` key: the scene's own function, then each choice that fits the data and draws
    /// otherwise, in turn.
    pub(super) fn next_preset(&mut self) {
        let own = self.own.first().map(|(_, t)| Arc::clone(t));
        let choices: Vec<&Choice> = self
            .fitting
            .iter()
            .filter(|c| Some(c.transfer.as_ref()) != own.as_deref())
            .collect();
        let next = match &self.preset {
            None => choices.first(),
            Some(p) => choices
                .iter()
                .position(|c| c.name == p.name)
                .and_then(|i| choices.get(i + 1)),
        };
        self.preset = next.map(|c| (*c).clone());
        self.window = None;
        self.apply_transfer();
        println!(
            "transfer function {}",
            self.preset
                .as_ref()
                .map_or("of the scene", |c| c.name.as_str())
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
            Some((_, v, _)) => crate::pick::paint::contact_range(&v.volume, None),
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
