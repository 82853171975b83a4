//! The plan's files: saving it as a new scene file (never over one), screenshots with their
//! scene file, and reading the scene file again when it changes on disk.

use std::path::{Path, PathBuf};
use std::time::SystemTime;

use super::plan::History;
use super::{App, ViewerError};
use crate::annotate::{Annotations, annotate_image};
use crate::pick::Picker;
use crate::pick::measure::draw_scene_measurements;
use crate::render::{FrameOptions, encode_png, frame_to_rgba8};
use crate::scene::file::{CameraSpec, SceneFile};

impl App {
    /// Saves the plan as a new scene file: beside the scene's own file (NAME-plan.toml, then
    /// NAME-plan-2.toml...), or in the screenshot folder; never over an existing file.
    pub(super) fn save_plan(&mut self) {
        let size = self
            .gpu
            .as_ref()
            .map_or(self.options.size, |g| g.target.size);
        let (dir, stem) = self.plan_place();
        let mut tried = vec![dir];
        // A folder that cannot be written (a read-only data folder) is said, and the
        // screenshot folder tried next: the plan is never lost for want of a place.
        if !tried.contains(&self.options.screenshot_dir) {
            tried.push(self.options.screenshot_dir.clone());
        }
        let mut refused = Vec::new();
        for dir in tried {
            match self.save_plan_in(&dir, &stem, size) {
                Ok(path) => {
                    self.edit.history.mark_saved();
                    if let Some(first) = refused.first() {
                        self.say(format!("plan not saved in its folder: {first}"));
                    }
                    self.say(format!("saved plan {}", path.display()));
                    return;
                }
                Err(e) => {
                    eprintln!("the plan was not saved: {e}");
                    refused.push(e);
                }
            }
        }
        // Nothing is lost: the plan stays in the viewer, to be saved elsewhere.
        self.say(format!(
            "the plan was not saved: {} (it is kept here)",
            refused.join("; ")
        ));
    }

    /// Writes the plan into `dir` as the first free `STEM-plan.toml`, `STEM-plan-2.toml`...,
    /// created exclusively: its path, or why not.
    fn save_plan_in(&self, dir: &Path, stem: &str, size: (u32, u32)) -> Result<PathBuf, String> {
        let text = self.plan_file(size, dir)?;
        for n in 1..10_000 {
            let name = match n {
                1 => format!("{stem}-plan.toml"),
                n => format!("{stem}-plan-{n}.toml"),
            };
            let path = dir.join(name);
            let file = std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&path);
            match file {
                Ok(mut f) => {
                    use std::io::Write;
                    return match f.write_all(text.as_bytes()) {
                        Ok(()) => Ok(path),
                        Err(e) => {
                            let _ = std::fs::remove_file(&path);
                            Err(format!("{}: {e}", path.display()))
                        }
                    };
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                Err(e) => return Err(format!("{}: {e}", path.display())),
            }
        }
        Err(format!("{}: no free name", dir.display()))
    }

    /// Reads the scene file again, keeping the camera; the viewer's edits are dropped.
    pub(super) fn reload(&mut self) {
        let Some((path, _)) = self.watched.clone() else {
            self.say("no scene file to reload".into());
            return;
        };
        let loaded = SceneFile::read_with_text(&path).and_then(|(file, text)| {
            let base = path.parent().unwrap_or(Path::new("."));
            let loaded = file.load(&path, base)?;
            Ok((file.with_paths_from(base), loaded, text))
        });
        self.watched = Some((path.clone(), modified(&path)));
        match loaded {
            Ok((file, loaded, text)) => {
                // The file's clipping, measurements and placements replace the viewer's.
                self.options.scene_file = Some(file);
                self.options.scene_text = Some(text);
                self.adopt(loaded.scene, History::new());
                self.say(format!("reloaded {}", path.display()));
            }
            Err(e) => {
                self.say(format!("not reloaded: {e}"));
                eprintln!("not reloaded: {e}");
            }
        }
    }
    /// Puts `scene` in place of the plan, with `history`: nothing selected, measured or
    /// marked, the transfer functions and the picker the new scene's.
    pub(super) fn adopt(&mut self, scene: crate::scene::Scene, history: History) {
        self.edit.scene = scene;
        self.picker = Picker::new(&self.edit.scene);
        self.remember_transfers();
        self.edit.history = history;
        self.edit.selected = None;
        self.edit.measuring = None;
        self.edit.chosen = None;
        self.edit.marker = None;
        self.looks.clear();
    }
    /// Reloads the scene file when it changed on disk, unless that would drop unsaved edits.
    pub(super) fn watch(&mut self) {
        let Some((path, seen)) = &self.watched else {
            return;
        };
        let now = modified(path);
        if now.is_none() || now == *seen {
            return;
        }
        if self.edit.history.unsaved() {
            let text = format!(
                "{} changed on disk: F5 reads it again (the unsaved edits here would be dropped; Ctrl+S saves them first)",
                path.display()
            );
            self.watched = Some((path.clone(), now));
            self.say(text);
        } else {
            self.reload();
        }
    }
    pub(super) fn screenshot(&mut self) -> Result<(), ViewerError> {
        // The plan drawn afresh as `render` draws its scene file: the measurements, and none of
        // the window's marks (the selection's tint, the picked points, the selected
        // measurement's highlight, the crop box's edges, the four panes).
        let mut scene = self.edit.scene.clone();
        let labels = match draw_scene_measurements(&mut scene) {
            Ok(labels) => labels,
            Err(e) => {
                eprintln!("screenshot: measurements left out: {e}");
                scene = self.edit.scene.clone();
                Vec::new()
            }
        };
        // Annotated as the window shows it (as `render --annotate PARTS` annotates), else
        // with the measurements' values alone where there are any (as `render` writes them).
        let parts = match (&self.options.annotations, self.annotations_on) {
            (Some(parts), true) => Some(parts.clone()),
            _ if !labels.is_empty() => Annotations::parse_parts("measurements").ok(),
            _ => None,
        };
        let options = FrameOptions {
            ordering: Some(self.ordering),
            background: Some(self.options.background),
            measure: false,
            preview: 0,
            volume_divisor: 1,
        };
        // The renderer back from a refined frame under way (the frame is drawn again after).
        self.cancel_frame();
        self.frame_stale = true;
        let Some(gpu) = &mut self.gpu else {
            return Ok(());
        };
        let size = gpu.target.size;
        gpu.renderer.set_refinement(true);
        let shot = gpu
            .renderer
            .screenshot(&gpu.ctx, &scene, &self.camera, size, &options)?;
        let mut image = frame_to_rgba8(&shot.frame);
        if let Some(parts) = &parts
            && let Err(e) = annotate_image(
                &mut image,
                &self.camera,
                &self.edit.scene.patient_frame(),
                &labels,
                parts,
            )
        {
            eprintln!("screenshot: not annotated: {e}");
        }
        let size = image.dimensions();
        let png = encode_png(&image).map_err(|e| ViewerError::Window(e.to_string()))?;
        let dir = &self.options.screenshot_dir;
        // The first number whose picture and scene file are both free, each created
        // exclusively: nothing is replaced or written through a link.
        let mut saved = None;
        for n in 1..=100_000 {
            let path = dir.join(format!("splatscene-view-{n}.png"));
            if std::fs::symlink_metadata(path.with_extension("toml")).is_ok() {
                continue;
            }
            match crate::output::write_new(&path, &png) {
                Ok(true) => {
                    saved = Some(path);
                    break;
                }
                Ok(false) => continue,
                Err(e) => {
                    eprintln!("screenshot: {e}");
                    return Ok(());
                }
            }
        }
        let Some(path) = saved else {
            eprintln!("screenshot: no free name in {}", dir.display());
            return Ok(());
        };
        println!("screenshot {}", path.display());
        match self.plan_file(size, dir) {
            Err(e) => eprintln!("view: no scene file: {e}"),
            Ok(text) => {
                let toml = path.with_extension("toml");
                match crate::output::write_new(&toml, text.as_bytes()) {
                    Ok(true) => {
                        println!("view {}", toml.display());
                        let annotate = match (&self.options.annotations, self.annotations_on) {
                            (Some(p), true) => format!(" --annotate {}", parts_arg(p)),
                            _ => String::new(),
                        };
                        println!(
                            "the same picture: splatscene render {}{annotate} --out PNG",
                            toml.display()
                        );
                    }
                    Ok(false) => eprintln!("view {}: taken meanwhile; not written", toml.display()),
                    Err(e) => eprintln!("view: {e}"),
                }
            }
        }
        Ok(())
    }
    /// The scene file of what the window shows: the scene's own file with the plan (mesh
    /// transforms, measurements), the camera, the ordering, the image size and the transfer
    /// function chosen with `T`; paths relative to `dir`, where it is to be written, and
    /// written over the scene file's own text where there is one (its comments kept).
    pub(super) fn plan_file(&self, size: (u32, u32), dir: &Path) -> Result<String, String> {
        let file = self
            .options
            .scene_file
            .as_ref()
            .ok_or("the scene has no scene file")?;
        let mut file = file
            .with_plan(&self.edit.scene)
            .map_err(|e| e.to_string())?;
        file.camera = Some(CameraSpec::from_camera(
            &self.camera,
            self.edit.scene.up_axis(),
        ));
        file.output.size = Some([size.0, size.1]);
        // The looks set with O and Shift+O, on the mesh files they belong to (their top nodes
        // follow the volumes', in the file's order).
        let roots: Vec<crate::scene::NodeId> = (0..self.edit.scene.nodes().len())
            .map(crate::scene::NodeId)
            .filter(|id| self.edit.scene.nodes()[id.0].parent().is_none())
            .collect();
        let volumes = file.volumes.len();
        for (i, spec) in file.meshes.iter_mut().enumerate() {
            let Some(look) = roots.get(volumes + i).and_then(|id| self.looks.get(id)) else {
                continue;
            };
            if look.colour > 0 {
                let [r, g, b] = super::look::COLOURS[look.colour - 1].1;
                spec.color = Some(match spec.color.as_deref() {
                    Some([_, _, _, a]) => vec![r, g, b, *a],
                    _ => vec![r, g, b],
                });
            }
            if look.opacity > 0 {
                spec.opacity =
                    Some(spec.opacity.unwrap_or(1.0) * super::look::OPACITIES[look.opacity]);
            }
        }
        file.output.ordering = Some(self.ordering);
        for volume in &mut file.volumes {
            if let Some(choice) = &self.preset {
                (volume.transfer, volume.window, volume.color) = match choice.saved {
                    Ok(name) => (Some(name.to_owned()), None, None),
                    Err((window, colour)) => (Some("ramp".into()), Some(window), Some(colour)),
                };
                volume.level_width = None;
                volume.shift = None;
            }
            // A window over any function (preset, ramp or auto) is its level_width: the
            // loader stretches the function over it, as the drag did.
            if let Some((level, width)) = self.window {
                volume.level_width = Some([level, width]);
                volume.shift = None;
            }
        }
        let file = file.with_paths_relative_to(dir);
        let text = match &self.options.scene_text {
            Some(original) => file.to_toml_over(original).map_err(|e| e.to_string())?,
            None => file.to_toml().map_err(|e| e.to_string())?,
        };
        if text.starts_with(SAVED_BY) {
            return Ok(text);
        }
        Ok(format!("{SAVED_BY}\n\n{text}"))
    }
}

/// The first lines of a file the viewer saves.
const SAVED_BY: &str = "# Saved by splatscene's viewer: `splatscene render THIS.toml --out view.png` draws\n# the same picture, and `splatscene view THIS.toml` opens the plan again.";

/// When a file was last modified, if it can be told.
pub(super) fn modified(path: &Path) -> Option<SystemTime> {
    std::fs::metadata(path).and_then(|m| m.modified()).ok()
}

/// The `--annotate` value that asks `render` for these annotations (the caption apart).
fn parts_arg(parts: &Annotations) -> String {
    let names: Vec<&str> = [
        (parts.orientation_marker, "marker"),
        (parts.edge_letters, "letters"),
        (parts.scale_bar, "scale"),
        (parts.measurements, "measurements"),
    ]
    .iter()
    .filter(|(on, _)| *on)
    .map(|(_, name)| *name)
    .collect();
    if names.len() == 4 {
        "all".into()
    } else if names.is_empty() {
        "none".into()
    } else {
        names.join(",")
    }
}
