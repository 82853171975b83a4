//! Drawing the window: the frame (previews while moving, refined when the camera rests), the
//! scene as drawn (the selection tinted, the clip plane and crop box outlined), the on-screen
//! text and the key help.

use std::time::{Duration, Instant};

use glam::DVec3;

use super::action::{KEYS, STEP};
use super::look::contact_ticks;
use super::{App, PREVIEW_ABOVE, PREVIEW_STEPS, SETTLE, ViewerError, next_preview_step, worker};
use crate::annotate::{Anchor, Label, Painter, Rect, annotate_image_clear_of, colour_bar};
use crate::pick::measure::{MarkerStyle, Measurement, annotate, draw_scene_measurements};
use crate::pick::paint::value_colour;
use crate::render::{
    Compositor, FrameOptions, RenderError, ViewSetup, frame_to_rgba8, write_overlay,
};
use crate::scene::file::transform_spec;
use crate::scene::{ClipPlane, NodeContent, NodeId, Scene};
use crate::slice::draw::colour8;

impl App {
    /// The 3D view's setup: the window's size, or a pane's with four panes.
    pub(super) fn view(&self) -> Option<Result<ViewSetup, RenderError>> {
        let gpu = self.gpu.as_ref()?;
        let size = if self.panes.is_some() {
            super::panes::Panes::pane_size(gpu.target.size)
        } else {
            gpu.target.size
        };
        Some(ViewSetup::new(&self.camera, size, self.edit.scene.bounds()))
    }
    /// Whether moving the camera draws previews: asked for, and full frames are slow.
    pub(super) fn previews_when_moving(&self) -> bool {
        self.options.preview_while_moving && self.full_frame > PREVIEW_ABOVE
    }
    /// Whether this frame is a preview: the camera is being dragged or zoomed, and full frames
    /// are slow.
    pub(super) fn previewing(&self) -> bool {
        self.previews_when_moving()
            && (self.settle.is_some() || self.drag.as_ref().is_some_and(|d| d.moved))
    }
    pub(super) fn redraw(&mut self) -> Result<(), ViewerError> {
        let Some(view) = self.view().transpose()? else {
            return Ok(());
        };
        let preview = self.previewing();
        let mut options = FrameOptions {
            ordering: Some(self.ordering),
            background: Some(self.options.background),
            measure: false,
            preview: u8::from(preview),
            volume_divisor: 1,
        };
        let started = std::time::Instant::now();
        // Time spent drawing this frame on the frame thread ([`worker`]).
        let mut drawn_before = Duration::ZERO;
        // Volumes coarser than the pixels are drawn refined only once the camera rests: the
        // refinement's classification and its splats cost more than a frame.
        let sharp = !preview && self.sharp_at == Some(self.camera);
        let window_size = match &self.gpu {
            Some(gpu) => gpu.target.size,
            None => return Ok(()),
        };
        // With the CPU tiles in one pane, full and refined frames are drawn on a thread of
        // their own: started here, shown here once drawn, given up for any other frame.
        let on_thread =
            !preview && self.panes.is_none() && self.gpu.as_ref().is_some_and(|g| g.tiles_on_cpu);
        let stale = std::mem::take(&mut self.frame_stale);
        let key = worker::FrameKey {
            camera: self.camera,
            generation: self.edit.scene.generation(),
            size: view.size,
            refined: sharp,
        };
        let mut drawn_frame = None;
        // The frame on screen shown again, under the text on screen now, while a frame of the
        // same view is drawn or when nothing it shows has changed.
        let mut reshown = false;
        if on_thread {
            // A frame of this view: the same camera and size, whatever changed in the scene.
            let of_this_view = |k: &worker::FrameKey| k.camera == key.camera && k.size == key.size;
            let current = |k: &worker::FrameKey| !stale && *k == key;
            let shown = self.shown_frame;
            let running = self.frame_job.as_ref().map(|j| j.key);
            let mut start = false;
            match self.drawn_frame.take() {
                Some(frame) if current(&frame.key) => drawn_frame = Some(frame),
                // Drawn before the latest change to the scene: shown while the frame for it is
                // drawn.
                Some(frame) if of_this_view(&frame.key) && running.is_none() => {
                    drawn_frame = Some(frame);
                    start = true;
                }
                _ if running.is_none() && shown.is_some_and(|s| current(&s)) => reshown = true,
                _ => match running {
                    // Under way: the frame for this very state, or a full frame of this view,
                    // shown once drawn, the change drawn after it (a key held down would else
                    // give up frame after frame, and show none).
                    Some(r) if current(&r) || (!r.refined && of_this_view(&r)) => {
                        if !current(&r) {
                            self.frame_stale = true;
                        }
                        if !shown.is_some_and(|s| of_this_view(&s)) {
                            return Ok(());
                        }
                        reshown = true;
                    }
                    _ => {
                        start = true;
                        // The frame on screen stays until the new one is drawn.
                        reshown = shown.is_some_and(|s| of_this_view(&s));
                    }
                },
            }
            if start {
                self.cancel_frame();
                self.refresh_contact_map();
                let (drawn, _) = self.drawn_scene();
                let Some(gpu) = &mut self.gpu else {
                    return Ok(());
                };
                let renderer = std::mem::take(&mut gpu.renderer);
                self.frame_job = Some(worker::FrameJob::start(
                    renderer,
                    std::sync::Arc::clone(&gpu.ctx),
                    drawn,
                    key,
                    options,
                    self.wake.clone(),
                ));
                if drawn_frame.is_none() && !reshown {
                    return Ok(());
                }
            }
        } else {
            self.drawn_frame = None;
            self.cancel_frame();
        }
        let thread_frame = drawn_frame.as_ref().map(|f| f.key);
        self.refresh_contact_map();
        let (drawn, labels) = self.drawn_scene();
        let slices = if self.panes.is_some() {
            self.draw_panes(window_size)
        } else {
            None
        };
        // Labels keep clear of the on-screen text (as wrapped now; its numbers change, its
        // lines seldom) in the window, not in the 3D pane of four.
        let clear: Vec<Rect> = if self.panes.is_some() {
            Vec::new()
        } else {
            vec![hud_block(&self.hud_lines(), window_size.0).1]
        };
        let Some(gpu) = &mut self.gpu else {
            return Ok(());
        };
        gpu.renderer.set_refinement(sharp);
        // Four panes are put together on the CPU: the 3D view drawn at a pane's size and read
        // back, the slices beside it.
        // (A frame of the frame thread is the tiles' frame, whichever thread holds the
        // renderer now.)
        let on_cpu = on_thread || gpu.renderer.composites_on_cpu(&gpu.ctx) || self.panes.is_some();
        let annotate_3d = |image: &mut image::RgbaImage, annotations_on: &mut bool| {
            if let (Some(parts), true) = (&self.options.annotations, *annotations_on)
                && let Err(e) = annotate_image_clear_of(
                    image,
                    &self.camera,
                    &self.edit.scene.patient_frame(),
                    &labels,
                    parts,
                    &clear,
                )
            {
                eprintln!("annotations off: {e}");
                *annotations_on = false;
            }
            if let Some(map) = &self.painted
                && self.contact_map
            {
                let range = map.2.range;
                if let Err(e) = colour_bar(
                    image,
                    |v| colour8(value_colour(v, range)),
                    range,
                    &contact_ticks(range),
                    "at the surface",
                ) {
                    eprintln!("colour bar: {e}");
                }
            }
        };
        let mut overlay = image::RgbaImage::new(window_size.0, window_size.1);
        // A preview in one pane on the CPU tiles composites its volumes at half the window's
        // size (or a third or a quarter, where previews are slow), a quarter of the pixels or
        // fewer and coarser splats, and lays them over the meshes drawn at the window's size.
        let small = preview && on_cpu && self.panes.is_none();
        let (divisor, coarseness) = PREVIEW_STEPS[self.preview_step.min(PREVIEW_STEPS.len() - 1)];
        if small {
            options.volume_divisor = divisor;
            options.preview = coarseness;
        }
        if reshown {
            // The picture is in the texture still: the text over it is drawn anew.
            annotate_3d(&mut overlay, &mut self.annotations_on);
        } else if on_cpu {
            // The tile compositor's frame, shown through the present pass like the GPU's.
            let size = view.size;
            let shot = match drawn_frame {
                Some(frame) => {
                    // The thread's time is the frame's.
                    drawn_before += frame.took;
                    frame.shot?
                }
                None => gpu
                    .renderer
                    .screenshot(&gpu.ctx, &drawn, &self.camera, size, &options)?,
            };
            self.last = shot.report;
            let mut image = frame_to_rgba8(&shot.frame);
            if self.panes.is_some() {
                annotate_3d(&mut image, &mut self.annotations_on);
                let background = self
                    .options
                    .background
                    .map(|c| (c.clamp(0.0, 1.0) * 255.0) as u8);
                image = App::compose_panes(
                    window_size,
                    &image,
                    slices.as_deref().unwrap_or(&[]),
                    [background[0], background[1], background[2], 255],
                );
            } else {
                annotate_3d(&mut overlay, &mut self.annotations_on);
            }
            let (w, h) = window_size;
            write_overlay(&gpu.ctx, &gpu.cpu_frame.0, image.as_raw(), w, h);
            gpu.cpu_frame.1 = Some(image);
        } else {
            self.last = gpu.renderer.render(
                &gpu.ctx,
                &drawn,
                &view,
                &gpu.target.color_view,
                &gpu.target.depth_view,
                &options,
            )?;
            gpu.cpu_frame.1 = None;
            annotate_3d(&mut overlay, &mut self.annotations_on);
        }
        if !reshown {
            self.shown_frame = thread_frame;
        }
        // The on-screen text of this frame (its splats, its time to draw), not the last one's.
        let drawn_in = started.elapsed() + drawn_before;
        if !reshown {
            self.this_frame = drawn_in;
        }
        let hud = self.hud_lines();
        let slices_window = self
            .panes
            .as_ref()
            .is_some_and(|p| p.windowing.is_some())
            .then(|| self.slice_window());
        let Some(gpu) = &mut self.gpu else {
            return Ok(());
        };
        let frame = match gpu.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(frame)
            | wgpu::CurrentSurfaceTexture::Suboptimal(frame) => frame,
            other => {
                // Lost or outdated: configure again and draw on the next request.
                log::warn!("surface: {other:?}");
                gpu.surface.configure(&gpu.ctx.device, &gpu.config);
                gpu.window.request_redraw();
                return Ok(());
            }
        };
        let surface_view = frame.texture.create_view(&Default::default());
        let (w, h) = window_size;
        // Under a window being dragged, the histogram of the values it spans: the volume's
        // transfer function in 3D, the slices' grey ramp in the four panes.

        if let (Some(histogram), Some((_, volume, _))) =
            (&self.histogram, self.edit.scene.volumes().next())
        {
            if let Some([lo, hi]) = slices_window {
                let grey = crate::classify::TransferFunction::ramp(lo, hi, [1.0; 4]);
                draw_histogram(&mut overlay, histogram, &grey);
            } else if self.windowing.is_some() && self.panes.is_none() {
                draw_histogram(&mut overlay, histogram, &volume.transfer);
            }
        }
        draw_hud(&mut overlay, &hud, self.help);
        write_overlay(&gpu.ctx, &gpu.overlay, overlay.as_raw(), w, h);
        let overlay = Some(gpu.overlay.create_view(&Default::default()));
        let cpu_view = on_cpu.then(|| gpu.cpu_frame.0.create_view(&Default::default()));
        let source = cpu_view.as_ref().unwrap_or(&gpu.target.color_view);
        gpu.blit
            .copy(&gpu.ctx, source, overlay.as_ref(), &surface_view);
        gpu.window.pre_present_notify();
        gpu.ctx.queue.present(frame);
        if reshown {
            // The frame, its times and the title are the ones shown before.
            return Ok(());
        }
        let elapsed = drawn_in;
        // Whether moving draws previews goes by the whole frame, presenting included.
        if !preview && !sharp {
            self.full_frame = started.elapsed() + drawn_before;
        }
        // The size this preview was drawn at (the title's), and the next one's.
        let preview_step = (divisor, coarseness);
        if small {
            // By what a preview costs frame after frame: not what this one spent making a
            // classification, a level or texels the next ones reuse.
            let t = &self.last.timings;
            let steady = started
                .elapsed()
                .saturating_sub(t.classify + t.levels + t.texels);
            self.preview_step = next_preview_step(self.preview_step, steady);
        }
        // (Not while the frame for a later change is drawn: it is shown first.)
        self.sharpen = (!preview && self.last.unrefined && self.frame_job.is_none())
            .then(|| Instant::now() + SETTLE);
        let preset = self.transfer_label();
        let Some(gpu) = &self.gpu else {
            return Ok(());
        };
        gpu.window.set_title(&format!(
            "splatscene: {}{}{} | {preset} | frame {:.0} ms, order {:.1} ms | {} splats{}{}",
            self.ordering,
            if on_cpu && self.panes.is_none() {
                " (CPU tiles)"
            } else if gpu.renderer.compositor() == Compositor::GpuTiles {
                " (GPU tiles)"
            } else {
                ""
            },
            if self.panes.is_some() {
                " (four panes)"
            } else {
                ""
            },
            elapsed.as_secs_f64() * 1e3,
            self.last.timings.order.as_secs_f64() * 1e3,
            self.last.splats,
            match (
                options.preview > 0,
                self.last.refined,
                self.sharpen.is_some()
            ) {
                (true, _, _) if small => format!(
                    " (preview, volumes at 1/{} size{})",
                    preview_step.0,
                    match preview_step.1 {
                        1 => String::new(),
                        n => format!(", {} level{} coarser", n - 1, if n > 2 { "s" } else { "" }),
                    }
                ),
                (true, _, _) => " (preview)".to_string(),
                (false, Some([x, y, z]), _) => format!(" (refined {x}x{y}x{z})"),
                (false, None, true) => " (refining)".to_string(),
                (false, None, false) => String::new(),
            },
            if self.last.levels_short_of_memory {
                " (a coarser level not made: memory short)"
            } else {
                ""
            }
        ));
        Ok(())
    }
    /// The scene as drawn: the plan's measurements, the points of the one being clicked and
    /// the last pick marked, the selected mesh tinted; and the measurements' values with where
    /// to write them.
    pub(super) fn drawn_scene(&self) -> (Scene, Vec<Label>) {
        let mut scene = self.edit.scene.clone();
        if let Some((_, _, painted)) = &self.painted
            && self.contact_map
            && let Err(e) = painted.apply(&mut scene)
        {
            eprintln!("contact map: {e}");
        }
        let labels = match draw_scene_measurements(&mut scene) {
            Ok(labels) => labels,
            Err(e) => {
                eprintln!("measurements: {e}");
                Vec::new()
            }
        };
        let style = MarkerStyle::for_scene(&self.edit.scene);
        // The selected measurement drawn over, thicker and in cyan, so that it shows in the
        // picture and not only in the on-screen text.
        if let Some(m) = self
            .edit
            .chosen
            .and_then(|i| self.edit.scene.measurements.get(i))
            .and_then(|m| self.edit.scene.measure(m).ok())
        {
            let chosen = MarkerStyle {
                point_radius: 1.5 * style.point_radius,
                line_radius: 1.8 * style.line_radius,
                material: crate::mesh::Material {
                    base_color: [0.2, 0.85, 1.0, 1.0],
                    ..style.material
                },
            };
            let _ = annotate(&mut scene, &m, &chosen);
        }
        let pending = self
            .edit
            .measuring
            .iter()
            .flat_map(|m| m.points.iter().map(|(p, _)| *p));
        let snap = self.edit.snapping.flatten();
        for point in pending.chain(self.edit.marker).chain(snap) {
            let _ = annotate(&mut scene, &Measurement::point(point), &style);
        }
        // The crop box's edges and each clip plane's cut through the scene's box, thin.
        let thin = MarkerStyle {
            point_radius: style.line_radius,
            line_radius: 0.5 * style.line_radius,
            ..style
        };
        let mut outline = Vec::new();
        if let Some((lo, hi)) = self.edit.scene.clipping.crop {
            outline.extend(box_edges(lo, hi));
        }
        if let Some((lo, hi)) = self.edit.scene.bounds() {
            for plane in &self.edit.scene.clipping.planes {
                outline.extend(plane_outline(plane, lo, hi));
            }
        }
        for (a, b) in outline {
            let _ = annotate(&mut scene, &Measurement::distance(a, b), &thin);
        }
        // The contact map shows its own colours, untinted.
        if let Some(top) = self.edit.selected
            && !self.contact_map
        {
            tint(&mut scene, top);
        }
        (scene, labels)
    }
    /// The lines of on-screen text.
    pub(super) fn hud_lines(&self) -> Vec<String> {
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        let transfer = self.transfer_label();
        let mut lines = vec![format!(
            "{} | {transfer} | frame {:.0} ms, order {:.1} ms, classify {:.0} ms | {} splats",
            self.ordering,
            ms(self.this_frame),
            ms(self.last.timings.order),
            ms(self.last.timings.classify),
            self.last.splats
        )];
        if let Some(top) = self.edit.selected
            && let Ok(node) = self.edit.scene.node(top)
        {
            // The placement in the scene file's words, as the plan would save it: the mesh
            // files' top nodes follow the volumes', in the file's order.
            let spec = self
                .options
                .scene_file
                .as_ref()
                .and_then(|f| {
                    let root = (0..top.0)
                        .filter(|i| self.edit.scene.nodes()[*i].parent().is_none())
                        .count();
                    let mesh = root.checked_sub(f.volumes.len())?;
                    f.mesh_transform(mesh, node.local()).ok()
                })
                .unwrap_or_else(|| transform_spec(node.local()));
            let (_, pivot) = self.edit.scene.pivot(top);
            let placement = match (spec.matrix, spec.translate, spec.rotate_degrees) {
                (Some(_), _, _) => "a sheared matrix".to_owned(),
                (None, t, r) => {
                    let [x, y, z] = t.unwrap_or([0.0; 3]);
                    let [a, b, c] = r.unwrap_or([0.0; 3]);
                    format!(
                        "translate [{x:.1}, {y:.1}, {z:.1}] mm, rotate_degrees [{a:.1}, {b:.1}, {c:.1}]"
                    )
                }
            };
            lines.push(format!(
                "selected {}: {placement}; pivot {pivot}; steps {STEP} mm, {STEP}\u{b0} (Shift x10)",
                node.name,
            ));
            if let Some(look) = self.looks.get(&top) {
                lines.push(format!("{}: {}", node.name, look.describe()));
            }
        }
        if let Some(panes) = &self.panes {
            let p = self.edit.scene.patient_frame().patient(panes.point);
            let [lo, hi] = self.slice_window();
            lines.push(format!(
                "four panes: crosshair ({:.1}, {:.1}, {:.1}) mm RAS; slices window {lo:.0} to {hi:.0}; bottom right {}",
                p.x,
                p.y,
                p.z,
                panes.fourth.name()
            ));
        }
        match self.edit.snapping {
            Some(None) => {
                lines.push("snap: click a point of the selected mesh (Escape cancels)".into());
            }
            Some(Some(_)) => {
                lines.push("snap: click where that point goes (Escape cancels)".into());
            }
            None => {}
        }
        if let Some(m) = &self.edit.measuring {
            lines.push(format!(
                "measure {}: point {} of {} (click; X clears, M next kind)",
                m.kind.name(),
                m.points.len() + 1,
                m.kind.point_count()
            ));
        }
        if let Some(text) = &self.edit.placing {
            lines.push(format!(
                "place: {text}_ (x/y/z MM moves, rx/ry/rz DEG turns about the pivot, x=MM sets; Enter, Escape)"
            ));
        }
        if let Some(text) = &self.edit.labelling {
            lines.push(format!("label: {text}_ (Enter keeps it, Escape cancels)"));
        }
        for (i, m) in self.edit.scene.measurements.iter().enumerate() {
            let value = self
                .edit
                .scene
                .measure(m)
                .map(|v| crate::pick::measure::label_text(&v, m.label.as_deref()))
                .unwrap_or_else(|e| format!("({e})"));
            let mark = if self.edit.chosen == Some(i) {
                ">"
            } else {
                " "
            };
            lines.push(format!("{mark} {}. {value}", i + 1));
        }
        if let Some(pick) = &self.last_pick {
            lines.push(format!("pick: {pick}"));
        }
        if self.edit.history.unsaved() {
            lines.push("unsaved edits (Ctrl+S saves the plan)".into());
        }
        if let Some((text, at)) = &self.message
            && at.elapsed() < Duration::from_secs(6)
        {
            lines.push(text.clone());
        }
        lines.push("H: keys".into());
        // A question the window waits on comes first, whatever else is said.
        if let Some(prompt) = &self.prompt {
            lines.insert(0, prompt.text());
        }
        lines
    }
    /// The name of the scene's own transfer function (of its first volume).
    pub(super) fn transfer_name(&self) -> String {
        if self.edit.scene.volumes().next().is_none() {
            return "no volume".into();
        }
        let Some(spec) = self
            .options
            .scene_file
            .as_ref()
            .and_then(|f| f.volumes.first())
        else {
            return "the scene's transfer function".into();
        };
        let mut name = spec.transfer.clone().unwrap_or_else(|| "auto".into());
        if let Some([lo, hi]) = spec.window {
            name.push_str(&format!(" {lo}..{hi}"));
        }
        if let Some([level, width]) = spec.level_width {
            name.push_str(&format!(" level {level} width {width}"));
        }
        if let Some(shift) = spec.shift {
            name.push_str(&format!(" shifted {shift:+}"));
        }
        name
    }
    pub(super) fn request_redraw(&self) {
        if let Some(gpu) = &self.gpu {
            gpu.window.request_redraw();
        }
    }
}

/// Tints the meshes under `top` toward amber, so that the selection shows.
pub(super) fn tint(scene: &mut Scene, top: NodeId) {
    let mut stack = vec![top];
    while let Some(id) = stack.pop() {
        let Ok(node) = scene.node(id) else {
            continue;
        };
        stack.extend_from_slice(node.children());
        if let NodeContent::Mesh(mesh) = &node.content {
            let mut mesh = mesh.clone();
            let c = &mut mesh.material.base_color;
            for (channel, amber) in c.iter_mut().zip([1.0, 0.55, 0.1]) {
                *channel = 0.55 * *channel + 0.45 * amber;
            }
            let _ = scene.set_content(id, NodeContent::Mesh(mesh));
        }
    }
}

/// Darkens a rectangle of the overlay, so that text over a bright picture stays readable.
pub(super) fn shade(image: &mut image::RgbaImage, x0: u32, y0: u32, x1: u32, y1: u32) {
    let (w, h) = image.dimensions();
    for y in y0.min(h)..y1.min(h) {
        for x in x0.min(w)..x1.min(w) {
            let p = image.get_pixel_mut(x, y);
            if p[3] < 170 {
                *p = image::Rgba([0, 0, 0, 170]);
            }
        }
    }
}

/// The histogram of the volume's values (log counts, the background value left out) in a
/// panel along the bottom of `image`, with the transfer function's opacity drawn over it and
/// its colours (over black) in a strip beneath: what an Alt+drag of the window moves over the
/// data.
pub(super) fn draw_histogram(
    image: &mut image::RgbaImage,
    histogram: &crate::classify::Histogram,
    transfer: &crate::classify::TransferFunction,
) {
    let (w, h) = (image.width() as f32, image.height() as f32);
    let (x0, x1) = ((0.1 * w).round(), (0.9 * w).round());
    let height = (0.15 * h).max(40.0).round();
    let bottom = (h - 56.0).max(height + 8.0).round();
    let top = bottom - height;
    let strip = 6.0;
    shade(
        image,
        (x0 - 4.0) as u32,
        (top - 4.0) as u32,
        (x1 + 4.0) as u32,
        (bottom + strip + 18.0) as u32,
    );
    let columns = (x1 - x0) as usize;
    let counts = histogram.coarse(columns);
    let most = counts.iter().copied().max().unwrap_or(0).max(1) as f32;
    let span = histogram.hi - histogram.lo;
    let value_at = |c: usize| histogram.lo + span * (c as f32 + 0.5) / columns as f32;
    for (c, &n) in counts.iter().enumerate() {
        let x = x0 as u32 + c as u32;
        let bar = height * (1.0 + n as f32).ln() / (1.0 + most).ln();
        for y in (bottom - bar).round() as u32..bottom as u32 {
            image.put_pixel(x, y, image::Rgba([150, 150, 150, 220]));
        }
        // The colour as it shows over black: straight colour times opacity (a grey ramp
        // shows black to white).
        let [r, g, b, a] = transfer.sample(value_at(c));
        for y in (bottom + 2.0) as u32..(bottom + 2.0 + strip) as u32 {
            let px = |v: f32| (v.clamp(0.0, 1.0) * a.clamp(0.0, 1.0) * 255.0) as u8;
            image.put_pixel(x, y, image::Rgba([px(r), px(g), px(b), 255]));
        }
    }
    let Ok(mut painter) = Painter::new(image) else {
        return;
    };
    painter.text_px = HUD_PX;
    painter.halo_px = 1.5;
    let curve: Vec<([f32; 2], [f32; 2])> = (0..columns.saturating_sub(1))
        .map(|c| {
            let y = |c: usize| bottom - height * transfer.sample(value_at(c))[3].clamp(0.0, 1.0);
            ([x0 + c as f32, y(c)], [x0 + c as f32 + 1.0, y(c + 1)])
        })
        .collect();
    painter.lines(&curve, 1.5, [255, 200, 90, 255]);
    let below = bottom + strip + 3.0;
    painter.text(
        &format!("{}", histogram.lo),
        x0,
        below,
        Anchor::TopLeft,
        [235, 235, 235, 255],
    );
    painter.text(
        &format!("{}", histogram.hi),
        x1,
        below,
        Anchor::TopRight,
        [235, 235, 235, 255],
    );
}

/// Where the on-screen text starts: below the top edge's direction letter.
const HUD_TOP: f32 = 28.0;
/// The on-screen text's left margin, size and line step, in pixels.
const HUD_LEFT: f32 = 10.0;
const HUD_PX: f32 = 13.0;
const HUD_STEP: f32 = 16.0;

/// `text` broken at spaces into lines of at most `width` pixels as `painter` measures them (a
/// word longer than that is a line of its own, shortened with `…`).
fn wrapped(painter: &Painter<'_>, text: &str, width: f32) -> Vec<String> {
    let mut lines: Vec<String> = Vec::new();
    let mut current = String::new();
    for word in text.split(' ') {
        let tried = if current.is_empty() {
            word.to_owned()
        } else {
            format!("{current} {word}")
        };
        if painter.measure(&tried).0 <= width || current.is_empty() {
            current = tried;
        } else {
            lines.push(std::mem::take(&mut current));
            current = word.to_owned();
        }
    }
    lines.push(current);
    lines
        .into_iter()
        .map(|l| crate::annotate::shortened(painter, &l, width))
        .collect()
}

/// The on-screen text laid out for a window `width` pixels wide: its lines wrapped to fit,
/// with the rectangle they cover.
pub(super) fn hud_block(lines: &[String], width: u32) -> (Vec<String>, Rect) {
    let mut scratch = image::RgbaImage::new(1, 1);
    let Ok(mut painter) = Painter::new(&mut scratch) else {
        return (lines.to_vec(), [0.0; 4]);
    };
    painter.text_px = HUD_PX;
    let room = (width as f32 - 2.0 * HUD_LEFT).max(40.0);
    let out: Vec<String> = lines
        .iter()
        .flat_map(|l| wrapped(&painter, l, room))
        .collect();
    let widest = out
        .iter()
        .map(|l| painter.measure(l).0)
        .fold(0.0f32, f32::max);
    let rect = [
        HUD_LEFT - 2.0,
        HUD_TOP - 2.0,
        HUD_LEFT + widest + 2.0,
        HUD_TOP + HUD_STEP * out.len() as f32 + 2.0,
    ];
    (out, rect)
}

/// Writes the on-screen text into the top left of `image`, wrapped to its width, and the keys
/// under it on a dark panel sized to them when `help`: descriptions wrapped beside their
/// keys, and where the window is too short for them all, the last line says where the rest
/// are.
pub(super) fn draw_hud(image: &mut image::RgbaImage, lines: &[String], help: bool) {
    let (w, h) = image.dimensions();
    let (lines, _) = hud_block(lines, w);
    let mut rows: Vec<(String, String)> = Vec::new();
    let mut panel = [0.0f32; 4];
    if help {
        let mut scratch = image::RgbaImage::new(1, 1);
        let Ok(mut measure) = Painter::new(&mut scratch) else {
            return;
        };
        measure.text_px = HUD_PX;
        let key_width = KEYS
            .iter()
            .map(|(k, _)| measure.measure(k).0)
            .fold(0.0f32, f32::max)
            + 12.0;
        let room = (w as f32 - 2.0 * HUD_LEFT - key_width - 8.0).max(60.0);
        for (keys, what) in KEYS {
            for (i, part) in wrapped(&measure, what, room).into_iter().enumerate() {
                let key = if i == 0 {
                    (*keys).to_owned()
                } else {
                    String::new()
                };
                rows.push((key, part));
            }
        }
        let top = HUD_TOP + HUD_STEP * (lines.len() as f32 + 1.0);
        let fit = (((h as f32 - top - 8.0) / HUD_STEP).floor().max(1.0)) as usize;
        if rows.len() > fit {
            rows.truncate(fit.saturating_sub(1));
            rows.push(("…".into(), "more keys: splatscene view --help".into()));
        }
        let widest = rows
            .iter()
            .map(|(_, what)| measure.measure(what).0)
            .fold(0.0f32, f32::max);
        panel = [
            HUD_LEFT - 6.0,
            top - 4.0,
            (HUD_LEFT + key_width + widest + 6.0).min(w as f32),
            (top + HUD_STEP * rows.len() as f32 + 4.0).min(h as f32),
        ];
        // Over whatever the overlay holds there (the annotations' letters and scale bar):
        // the keys are read on a plain panel.
        for y in (panel[1] as u32).min(h)..(panel[3] as u32).min(h) {
            for x in (panel[0] as u32).min(w)..(panel[2] as u32).min(w) {
                image.put_pixel(x, y, image::Rgba([0, 0, 0, 200]));
            }
        }
        panel[0] = key_width;
    }
    let Ok(mut painter) = Painter::new(image) else {
        return;
    };
    painter.text_px = HUD_PX;
    painter.halo_px = 1.5;
    let mut y = HUD_TOP;
    for line in &lines {
        painter.text(line, HUD_LEFT, y, Anchor::TopLeft, [235, 235, 235, 255]);
        y += HUD_STEP;
    }
    if help {
        y += HUD_STEP;
        for (keys, what) in &rows {
            painter.text(keys, HUD_LEFT, y, Anchor::TopLeft, [255, 200, 90, 255]);
            painter.text(
                what,
                HUD_LEFT + panel[0],
                y,
                Anchor::TopLeft,
                [235, 235, 235, 255],
            );
            y += HUD_STEP;
        }
    }
}

/// The twelve edges of the box `lo`..`hi`.
pub(super) fn box_edges(lo: DVec3, hi: DVec3) -> Vec<(DVec3, DVec3)> {
    let corner = |i: u32| {
        DVec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        )
    };
    let mut edges = Vec::with_capacity(12);
    for a in 0..8u32 {
        for bit in [1, 2, 4] {
            if a & bit == 0 {
                edges.push((corner(a), corner(a | bit)));
            }
        }
    }
    edges
}

/// Where a clip plane cuts the box `lo`..`hi`: the sides of that polygon.
pub(super) fn plane_outline(plane: &ClipPlane, lo: DVec3, hi: DVec3) -> Vec<(DVec3, DVec3)> {
    let Some(n) = plane.normal.try_normalize() else {
        return Vec::new();
    };
    let d = plane.offset / plane.normal.length();
    let mut points: Vec<DVec3> = Vec::new();
    for (a, b) in box_edges(lo, hi) {
        let (da, db) = (n.dot(a) - d, n.dot(b) - d);
        if (da <= 0.0) != (db <= 0.0) {
            points.push(a + (b - a) * (da / (da - db)));
        }
    }
    if points.len() < 3 {
        return Vec::new();
    }
    // Around their centre, in the plane.
    let centre = points.iter().copied().sum::<DVec3>() / points.len() as f64;
    let u = (points[0] - centre).normalize_or(n.any_orthonormal_vector());
    let v = n.cross(u);
    points.sort_by(|p, q| {
        let angle = |x: &DVec3| (*x - centre).dot(v).atan2((*x - centre).dot(u));
        angle(p).total_cmp(&angle(q))
    });
    (0..points.len())
        .map(|i| (points[i], points[(i + 1) % points.len()]))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_clip_plane_is_outlined_where_it_cuts_the_box() {
        let plane = ClipPlane::through(DVec3::new(0.0, 0.0, 0.5), DVec3::Z * 2.0, false);
        let sides = plane_outline(&plane, DVec3::ZERO, DVec3::ONE);
        assert_eq!(sides.len(), 4);
        let mut length = 0.0;
        for (a, b) in &sides {
            assert!((a.z - 0.5).abs() < 1e-12 && (b.z - 0.5).abs() < 1e-12);
            length += a.distance(*b);
        }
        assert!((length - 4.0).abs() < 1e-12, "a unit square: {length}");
        let outside = ClipPlane::through(DVec3::splat(5.0), DVec3::X, false);
        assert!(plane_outline(&outside, DVec3::ZERO, DVec3::ONE).is_empty());
        assert_eq!(box_edges(DVec3::ZERO, DVec3::ONE).len(), 12);
    }
}
