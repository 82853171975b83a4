//! The viewer window (winit), a planning tool: orbit, pan and zoom with the mouse; click to
//! pick (the hit is printed as a JSON line on standard output and marked) and to select a mesh;
//! move the selected mesh by mouse or by steps; measure distances and angles by clicking; undo
//! and redo every edit; save the plan as a scene file; keys to switch the ordering and the
//! transfer function; on-screen text with the state of all this. [`KEYS`] lists the keys, as
//! the `H` key shows them in the window.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use glam::{DMat4, DVec3};
use winit::application::ApplicationHandler;
use winit::dpi::{PhysicalPosition, PhysicalSize};
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{Key, ModifiersState, NamedKey};
use winit::window::{Window, WindowId};

use crate::annotate::{Anchor, Annotations, Label, Painter, annotate_image};
use crate::classify::TransferFunction;
use crate::order::Ordering;
use crate::pick::measure::{
    MarkerStyle, MeasureKind, Measurement, annotate, draw_scene_measurements,
};
use crate::pick::{Hit, PickOptions, Picker};
use crate::render::{
    Blit, Compositor, FrameOptions, FrameReport, GpuContext, RenderError, RenderTarget, Renderer,
    ViewSetup, encode_png, frame_to_rgba8, overlay_texture, write_overlay,
};
use crate::scene::file::{CameraSpec, SceneFile};
use crate::scene::{ClipPlane, NodeContent, NodeId, Scene, SceneCamera};

pub mod plan;

use plan::{Edit, History, Pending};

/// Every key of the viewer and what it does, as `H` shows them and `view --help` lists them.
pub const KEYS: &[(&str, &str)] = &[
    ("left drag", "orbit about the scene's up"),
    ("right drag", "pan"),
    ("wheel", "zoom"),
    (
        "click",
        "pick (a JSON line on stdout); on a mesh, select it",
    ),
    (
        "drag on it",
        "move the selected mesh in the view plane (also Shift+drag)",
    ),
    ("Ctrl+drag", "turn the selected mesh about its pivot"),
    (
        "Shift+wheel",
        "move the selected mesh along the view direction",
    ),
    ("arrows", "move the selected mesh by 1 mm (Shift: 10 mm)"),
    ("Ctrl+arrows", "turn it by 1 degree (Shift: 10)"),
    ("+ / -", "move it toward / away from the eye by 1 mm"),
    ("Ctrl+Z, Ctrl+Y", "undo, redo"),
    ("M", "measure: distance, angle, line angle, point, off"),
    (
        "N",
        "snap: click a point of the selected mesh, then where it goes",
    ),
    ("X", "clear the points clicked so far"),
    ("Tab", "select the next measurement"),
    ("L", "label the selected measurement (type, Enter)"),
    ("Delete", "delete the selected measurement"),
    ("Ctrl+S", "save the plan as a new scene file"),
    ("F5", "reload the scene file from disk"),
    (
        "1-7",
        "ordering: BTF, PBTF, IP-PBTF, exact, bucketed, pyramid, rows",
    ),
    (
        "T",
        "transfer function: the scene's, then the presets that fit the data",
    ),
    (
        "Alt+drag",
        "window: right raises the level, up narrows the width",
    ),
    ("A", "annotations off and on"),
    ("S", "screenshot and its scene file"),
    ("C, [, ]", "clip plane on and off, move it"),
    (
        "B, {, }",
        "crop box around the selected mesh on and off, shrink, grow by 5 mm",
    ),
    ("R", "reset the camera"),
    ("H", "this help"),
    ("Escape", "cancel, deselect; with nothing to cancel, quit"),
    ("Q", "quit"),
];

/// The keys as text, one per line (for `view --help`).
pub fn keys_help() -> String {
    let mut text = String::from("Keys and mouse in the window:\n");
    for (keys, what) in KEYS {
        text.push_str(&format!("  {keys:<16} {what}\n"));
    }
    text
}

/// A step of the arrow and +/- keys: 1 mm, or 1 degree with Ctrl.
const STEP: f64 = 1.0;

/// Viewer settings.
#[derive(Debug, Clone)]
pub struct ViewerOptions {
    /// Initial window size in pixels.
    pub size: (u32, u32),
    /// Where the screenshot key writes.
    pub screenshot_dir: PathBuf,
    /// Background colour.
    pub background: [f32; 3],
    /// While the camera is dragged or zoomed and a full frame takes longer than 50 ms (20
    /// frames a second), draw the volumes at half resolution ([`FrameOptions::preview`]); the
    /// full frame follows when the button is released, or a quarter second after the last
    /// wheel step.
    pub preview_while_moving: bool,
    /// The scene file the scene was loaded from, with absolute paths: the screenshot key
    /// saves it beside each screenshot with the camera of the moment, so that `render` of
    /// that file gives the same picture. `None` saves pixels only.
    pub scene_file: Option<SceneFile>,
    /// The first ordering (IP-PBTF when `None`).
    pub ordering: Option<Ordering>,
    /// Annotations drawn over the picture (orientation marker, edge letters, scale bar);
    /// `A` turns them off and on. `None` draws none until `A` is pressed.
    pub annotations: Option<Annotations>,
    /// Who composites the splats: [`Compositor::Auto`] takes the CPU tile compositor where
    /// the adapter is itself a CPU (lavapipe).
    pub compositor: Compositor,
    /// The scene file on disk: plans are saved beside it, and it is read again when it
    /// changes. `None` saves plans into the screenshot folder and watches nothing.
    pub scene_path: Option<PathBuf>,
}

impl Default for ViewerOptions {
    fn default() -> Self {
        Self {
            size: (960, 720),
            screenshot_dir: PathBuf::from("."),
            background: [0.06, 0.07, 0.09],
            preview_while_moving: true,
            scene_file: None,
            ordering: None,
            annotations: Some(Annotations::default()),
            compositor: Compositor::Auto,
            scene_path: None,
        }
    }
}

/// Why the viewer stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    /// No window system, or the event loop failed.
    #[error("window system: {0}")]
    Window(String),
    /// The GPU side failed.
    #[error(transparent)]
    Render(#[from] RenderError),
}

/// Transfer functions the `T` key cycles through: the presets, by name.
const PRESETS: [&str; 4] = TransferFunction::PRESETS;

/// A drag or a zoom draws preview frames when a full frame took longer than this.
const PREVIEW_ABOVE: Duration = Duration::from_millis(50);

/// After the last wheel step of a zoom drawn as a preview, the full frame follows this late.
const SETTLE: Duration = Duration::from_millis(250);

const ORDERINGS: [(&str, Ordering); 7] = [
    ("1", Ordering::Btf),
    ("2", Ordering::Pbtf),
    ("3", Ordering::IpPbtfImplicit),
    ("4", Ordering::Exact),
    ("5", Ordering::Bucketed),
    ("6", Ordering::Pyramid),
    ("7", Ordering::Rows),
];

/// Opens a window on `scene` and runs until it is closed.
pub fn run(scene: Scene, options: ViewerOptions) -> Result<(), ViewerError> {
    let event_loop = EventLoop::new().map_err(|e| ViewerError::Window(e.to_string()))?;
    let home = scene.camera.unwrap_or_else(|| {
        let bounds = scene.bounds().unwrap_or((DVec3::splat(-1.0), DVec3::ONE));
        SceneCamera::fit(
            bounds,
            DVec3::new(-0.3, -1.0, -0.35),
            Default::default(),
            4.0 / 3.0,
        )
    });
    let ordering = options.ordering.unwrap_or(Ordering::IpPbtfImplicit);
    let watched = options
        .scene_path
        .as_ref()
        .map(|p| (p.clone(), modified(p)));
    let mut app = App {
        history: History::new(),
        selected: None,
        measuring: None,
        snapping: None,
        chosen: None,
        labelling: None,
        message: None,
        help: false,
        modifiers: ModifiersState::empty(),
        moving: None,
        last_pick: None,
        watched,
        next_check: Instant::now() + WATCH_EVERY,
        picker: Picker::new(&scene),
        scene,
        options,
        home,
        camera: home,
        ordering,
        preset: None,
        fitting: Vec::new(),
        own: Vec::new(),
        window: None,
        windowing: None,
        gpu: None,
        cursor: (0.0, 0.0),
        drag: None,
        hit: None,
        last: FrameReport::default(),
        full_frame: Duration::ZERO,
        settle: None,
        sharpen: None,
        sharp_at: None,
        annotations_on: true,
        error: None,
    };
    app.remember_transfers();
    event_loop
        .run_app(&mut app)
        .map_err(|e| ViewerError::Window(e.to_string()))?;
    app.error.map_or(Ok(()), Err)
}

struct Gpu {
    window: Arc<Window>,
    ctx: GpuContext,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    target: RenderTarget,
    renderer: Renderer,
    blit: Blit,
    /// Annotations over the frame, the window's size.
    overlay: wgpu::Texture,
    /// The frame the CPU tile compositor drew, as the window shows it (the window's size),
    /// and its pixels, which screenshots save; `None` while the GPU composites.
    cpu_frame: (wgpu::Texture, Option<image::RgbaImage>),
}

struct Drag {
    button: MouseButton,
    start: (f64, f64),
    last: (f64, f64),
    moved: bool,
}

/// How often the scene file is looked at for changes.
const WATCH_EVERY: Duration = Duration::from_millis(500);

/// When a file was last modified, if it can be told.
fn modified(path: &Path) -> Option<SystemTime> {
    std::fs::metadata(path).and_then(|m| m.modified()).ok()
}

struct App {
    /// The edits, for undo and redo, and whether the plan is saved.
    history: History,
    /// The selected mesh (a top node).
    selected: Option<NodeId>,
    /// The measurement being clicked, in measure mode.
    measuring: Option<Pending>,
    /// Snap mode: `Some(None)` waits for a point on the selected mesh, `Some(Some(p))` for
    /// the target that point moves to.
    snapping: Option<Option<DVec3>>,
    /// The selected measurement (an index into the scene's).
    chosen: Option<usize>,
    /// The label being typed for the selected measurement.
    labelling: Option<String>,
    /// A message on screen (saved, undone, an error) and when it was set.
    message: Option<(String, Instant)>,
    /// Whether the key help shows.
    help: bool,
    modifiers: ModifiersState,
    /// The selected mesh's transform when the drag that moves it began.
    moving: Option<DMat4>,
    /// The last pick, as the screen says it.
    last_pick: Option<String>,
    /// The scene file and when it was last modified, to read it again when it changes.
    watched: Option<(PathBuf, Option<SystemTime>)>,
    next_check: Instant,
    scene: Scene,
    picker: Picker,
    options: ViewerOptions,
    home: SceneCamera,
    camera: SceneCamera,
    ordering: Ordering,
    /// The preset the `T` key chose last; `None` while the scene's own functions hold.
    preset: Option<&'static str>,
    /// The presets that fit the data: the CT ones for Hounsfield data, else the MR one.
    fitting: Vec<&'static str>,
    /// Each volume's own transfer function, as the scene gave it.
    own: Vec<(NodeId, Arc<TransferFunction>)>,
    /// A window `(level, width)` set with Alt+drag over the chosen function.
    window: Option<(f32, f32)>,
    /// The window when an Alt+drag began.
    windowing: Option<(f32, f32)>,
    gpu: Option<Gpu>,
    cursor: (f64, f64),
    drag: Option<Drag>,
    /// The last picked point, marked.
    hit: Option<DVec3>,
    last: FrameReport,
    /// How long the last full frame took to draw and present.
    full_frame: Duration,
    /// When a zoom drawn as previews gets its full frame.
    settle: Option<Instant>,
    /// When a full frame drawn without refining a volume that wanted it gets its refined
    /// frame ([`Renderer::set_refinement`]).
    sharpen: Option<Instant>,
    /// The camera refined frames are drawn at: the one the camera rested at.
    sharp_at: Option<SceneCamera>,
    /// Whether the annotations show (the `A` key).
    annotations_on: bool,
    error: Option<ViewerError>,
}

impl App {
    fn start(&mut self, event_loop: &ActiveEventLoop) -> Result<(), ViewerError> {
        let (w, h) = self.options.size;
        let attributes = Window::default_attributes()
            .with_title("splatscene")
            .with_inner_size(PhysicalSize::new(w, h));
        let window = Arc::new(
            event_loop
                .create_window(attributes)
                .map_err(|e| ViewerError::Window(e.to_string()))?,
        );
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let surface = instance
            .create_surface(Arc::clone(&window))
            .map_err(|e| ViewerError::Window(e.to_string()))?;
        let ctx = pollster::block_on(GpuContext::with_instance(instance, Some(&surface)))?;
        let caps = surface.get_capabilities(&ctx.adapter);
        // Frames hold display values already (as the PNGs do): present them unconverted.
        let format = caps
            .formats
            .iter()
            .copied()
            .find(|f| !f.is_srgb())
            .or_else(|| caps.formats.first().copied())
            .ok_or_else(|| ViewerError::Window("the surface offers no format".into()))?;
        let size = window.inner_size();
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            format,
            width: size.width.max(1),
            height: size.height.max(1),
            present_mode: wgpu::PresentMode::AutoVsync,
            desired_maximum_frame_latency: 2,
            alpha_mode: caps
                .alpha_modes
                .first()
                .copied()
                .unwrap_or(wgpu::CompositeAlphaMode::Auto),
            view_formats: vec![],
            color_space: wgpu::SurfaceColorSpace::Auto,
        };
        surface.configure(&ctx.device, &config);
        let target = RenderTarget::new(&ctx, config.width, config.height)?;
        let blit = Blit::new(&ctx, format);
        let overlay = overlay_texture(&ctx, config.width, config.height);
        let cpu_frame = (overlay_texture(&ctx, config.width, config.height), None);
        self.gpu = Some(Gpu {
            window,
            ctx,
            surface,
            config,
            target,
            renderer: Renderer::with_compositor(self.options.compositor),
            blit,
            overlay,
            cpu_frame,
        });
        Ok(())
    }

    fn resize(&mut self, size: PhysicalSize<u32>) -> Result<(), ViewerError> {
        let Some(gpu) = &mut self.gpu else {
            return Ok(());
        };
        gpu.config.width = size.width.max(1);
        gpu.config.height = size.height.max(1);
        gpu.surface.configure(&gpu.ctx.device, &gpu.config);
        gpu.target = RenderTarget::new(&gpu.ctx, gpu.config.width, gpu.config.height)?;
        gpu.overlay = overlay_texture(&gpu.ctx, gpu.config.width, gpu.config.height);
        gpu.cpu_frame = (
            overlay_texture(&gpu.ctx, gpu.config.width, gpu.config.height),
            None,
        );
        gpu.window.request_redraw();
        Ok(())
    }

    fn view(&self) -> Option<Result<ViewSetup, RenderError>> {
        let gpu = self.gpu.as_ref()?;
        Some(ViewSetup::new(
            &self.camera,
            gpu.target.size,
            self.scene.bounds(),
        ))
    }

    /// Whether moving the camera draws previews: asked for, and full frames are slow.
    fn previews_when_moving(&self) -> bool {
        self.options.preview_while_moving && self.full_frame > PREVIEW_ABOVE
    }

    /// Whether this frame is a preview: the camera is being dragged or zoomed, and full frames
    /// are slow.
    fn previewing(&self) -> bool {
        self.previews_when_moving()
            && (self.settle.is_some() || self.drag.as_ref().is_some_and(|d| d.moved))
    }

    fn redraw(&mut self) -> Result<(), ViewerError> {
        let Some(view) = self.view().transpose()? else {
            return Ok(());
        };
        let preview = self.previewing();
        let options = FrameOptions {
            ordering: Some(self.ordering),
            background: Some(self.options.background),
            measure: false,
            preview,
        };
        let started = std::time::Instant::now();
        let (drawn, labels) = self.drawn_scene();
        let hud = self.hud_lines();
        let preset = self.transfer_label();
        let Some(gpu) = &mut self.gpu else {
            return Ok(());
        };
        let target = &gpu.target;
        // Volumes coarser than the pixels are drawn refined only once the camera rests: the
        // refinement's classification and its splats cost more than a frame.
        let sharp = !preview && self.sharp_at == Some(self.camera);
        gpu.renderer.set_refinement(sharp);
        let on_cpu = gpu.renderer.composites_on_cpu(&gpu.ctx);
        if on_cpu {
            // The tile compositor's frame, shown through the present pass like the GPU's.
            let shot =
                gpu.renderer
                    .screenshot(&gpu.ctx, &drawn, &self.camera, target.size, &options)?;
            self.last = shot.report;
            let image = frame_to_rgba8(&shot.frame);
            let (w, h) = target.size;
            write_overlay(&gpu.ctx, &gpu.cpu_frame.0, image.as_raw(), w, h);
            gpu.cpu_frame.1 = Some(image);
        } else {
            self.last = gpu.renderer.render(
                &gpu.ctx,
                &drawn,
                &view,
                &target.color_view,
                &target.depth_view,
                &options,
            )?;
            gpu.cpu_frame.1 = None;
        }
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
        let (w, h) = target.size;
        let mut image = image::RgbaImage::new(w, h);
        if let (Some(parts), true) = (&self.options.annotations, self.annotations_on)
            && let Err(e) = annotate_image(
                &mut image,
                &self.camera,
                &self.scene.patient_frame(),
                &labels,
                parts,
            )
        {
            eprintln!("annotations off: {e}");
            self.annotations_on = false;
        }
        let help = self.help;
        draw_hud(&mut image, &hud, help);
        write_overlay(&gpu.ctx, &gpu.overlay, image.as_raw(), w, h);
        let overlay = Some(gpu.overlay.create_view(&Default::default()));
        let cpu_view = on_cpu.then(|| gpu.cpu_frame.0.create_view(&Default::default()));
        let source = cpu_view.as_ref().unwrap_or(&target.color_view);
        gpu.blit
            .copy(&gpu.ctx, source, overlay.as_ref(), &surface_view);
        gpu.window.pre_present_notify();
        gpu.ctx.queue.present(frame);
        let elapsed = started.elapsed();
        if !preview && !sharp {
            self.full_frame = elapsed;
        }
        self.sharpen = (!preview && self.last.unrefined).then(|| Instant::now() + SETTLE);
        gpu.window.set_title(&format!(
            "splatscene: {}{} | {preset} | frame {:.0} ms, order {:.1} ms | {} splats{}",
            self.ordering,
            if on_cpu { " (CPU tiles)" } else { "" },
            elapsed.as_secs_f64() * 1e3,
            self.last.timings.order.as_secs_f64() * 1e3,
            self.last.splats,
            match (options.preview, self.last.refined, self.sharpen.is_some()) {
                (true, _, _) => " (preview)".to_string(),
                (false, Some([x, y, z]), _) => format!(" (refined {x}x{y}x{z})"),
                (false, None, true) => " (refining)".to_string(),
                (false, None, false) => String::new(),
            }
        ));
        Ok(())
    }

    /// The scene as drawn: the plan's measurements, the points of the one being clicked and
    /// the last pick marked, the selected mesh tinted; and the measurements' values with where
    /// to write them.
    fn drawn_scene(&self) -> (Scene, Vec<Label>) {
        let mut scene = self.scene.clone();
        let labels = match draw_scene_measurements(&mut scene) {
            Ok(labels) => labels,
            Err(e) => {
                eprintln!("measurements: {e}");
                Vec::new()
            }
        };
        let style = MarkerStyle::for_scene(&self.scene);
        let pending = self
            .measuring
            .iter()
            .flat_map(|m| m.points.iter().map(|(p, _)| *p));
        let snap = self.snapping.flatten();
        for point in pending.chain(self.hit).chain(snap) {
            let _ = annotate(&mut scene, &Measurement::point(point), &style);
        }
        // The crop box's edges and each clip plane's cut through the scene's box, thin.
        let thin = MarkerStyle {
            point_radius: style.line_radius,
            line_radius: 0.5 * style.line_radius,
            ..style
        };
        let mut outline = Vec::new();
        if let Some((lo, hi)) = self.scene.clipping.crop {
            outline.extend(box_edges(lo, hi));
        }
        if let Some((lo, hi)) = self.scene.bounds() {
            for plane in &self.scene.clipping.planes {
                outline.extend(plane_outline(plane, lo, hi));
            }
        }
        for (a, b) in outline {
            let _ = annotate(&mut scene, &Measurement::distance(a, b), &thin);
        }
        if let Some(top) = self.selected {
            tint(&mut scene, top);
        }
        (scene, labels)
    }

    /// The lines of on-screen text.
    fn hud_lines(&self) -> Vec<String> {
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        let transfer = self.transfer_label();
        let mut lines = vec![format!(
            "{} | {transfer} | frame {:.0} ms, order {:.1} ms, classify {:.0} ms | {} splats",
            self.ordering,
            ms(self.full_frame),
            ms(self.last.timings.order),
            ms(self.last.timings.classify),
            self.last.splats
        )];
        if let Some(top) = self.selected
            && let Ok(node) = self.scene.node(top)
        {
            let (_, turn, at) = node.local().to_scale_rotation_translation();
            let (_, angle) = turn.to_axis_angle();
            let (_, pivot) = plan::pivot(&self.scene, top);
            lines.push(format!(
                "selected {}: at ({:.1}, {:.1}, {:.1}) mm, turned {:.1}\u{b0}; pivot {pivot}; steps {STEP} mm, {STEP}\u{b0} (Shift x10)",
                node.name,
                at.x,
                at.y,
                at.z,
                angle.to_degrees()
            ));
        }
        match self.snapping {
            Some(None) => {
                lines.push("snap: click a point of the selected mesh (Escape cancels)".into());
            }
            Some(Some(_)) => {
                lines.push("snap: click where that point goes (Escape cancels)".into());
            }
            None => {}
        }
        if let Some(m) = &self.measuring {
            lines.push(format!(
                "measure {}: point {} of {} (click; X clears, M next kind)",
                m.kind.name(),
                m.points.len() + 1,
                m.kind.point_count()
            ));
        }
        if let Some(text) = &self.labelling {
            lines.push(format!("label: {text}_ (Enter keeps it, Escape cancels)"));
        }
        for (i, m) in self.scene.measurements.iter().enumerate() {
            let value = self
                .scene
                .measure(m)
                .map(|v| crate::pick::measure::label_text(&v, m.label.as_deref()))
                .unwrap_or_else(|e| format!("({e})"));
            let mark = if self.chosen == Some(i) { ">" } else { " " };
            lines.push(format!("{mark} {}. {value}", i + 1));
        }
        if let Some(pick) = &self.last_pick {
            lines.push(format!("pick: {pick}"));
        }
        if self.history.unsaved() {
            lines.push("unsaved edits (Ctrl+S saves the plan)".into());
        }
        if let Some((text, at)) = &self.message
            && at.elapsed() < Duration::from_secs(6)
        {
            lines.push(text.clone());
        }
        lines.push("H: keys".into());
        lines
    }

    /// The name of the scene's own transfer function (of its first volume).
    fn transfer_name(&self) -> String {
        if self.scene.volumes().next().is_none() {
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

    fn request_redraw(&self) {
        if let Some(gpu) = &self.gpu {
            gpu.window.request_redraw();
        }
    }

    /// Says `text` on screen for a few seconds and on standard output.
    fn say(&mut self, text: String) {
        println!("{text}");
        self.message = Some((text, Instant::now()));
    }

    fn pick(&mut self, x: f64, y: f64) -> Result<(), ViewerError> {
        let Some(view) = self.view().transpose()? else {
            return Ok(());
        };
        let (px, py) = (x.max(0.0) as u32, y.max(0.0) as u32);
        if px >= view.size.0 || py >= view.size.1 {
            return Ok(());
        }
        self.picker.update(&self.scene);
        let hit = self
            .picker
            .pick_pixel(&self.scene, &view, px, py, &PickOptions::default());
        let hit_json = hit.map(|h| h.to_json(&self.scene));
        let line = serde_json::json!({ "pixel": [px, py], "hit": hit_json });
        println!("pick {line}");
        self.hit = hit.map(|h| h.point());
        self.last_pick = Some(match &hit {
            Some(h) => {
                let p = h.point();
                let on = match h {
                    Hit::Mesh(m) => self
                        .scene
                        .node(m.node)
                        .map_or("a mesh".into(), |n| n.name.clone()),
                    Hit::Volume(v) => format!("voxel value {}", v.value),
                };
                format!("({:.1}, {:.1}, {:.1}) mm RAS, {on}", p.x, p.y, p.z)
            }
            None => "nothing".into(),
        });
        let on_mesh = match &hit {
            Some(Hit::Mesh(m)) => Some(plan::top_node(&self.scene, m.node)),
            _ => None,
        };
        if let Some(from) = self.snapping {
            let Some(hit) = hit else {
                return Ok(());
            };
            match (from, self.selected) {
                (None, Some(top)) if on_mesh == Some(top) => {
                    self.snapping = Some(Some(hit.point()));
                    self.say("snap: now click where that point goes".into());
                }
                (None, _) => self.say("snap: click a point of the selected mesh".into()),
                (Some(source), Some(_)) => {
                    self.snapping = None;
                    let delta = hit.point() - source;
                    self.move_selected(|l, _| plan::translated(l, delta));
                    self.say(format!(
                        "snapped by ({:.1}, {:.1}, {:.1}) mm",
                        delta.x, delta.y, delta.z
                    ));
                }
                (Some(_), None) => self.snapping = None,
            }
            return Ok(());
        }
        if let Some(pending) = &mut self.measuring {
            let Some(hit) = hit else {
                return Ok(());
            };
            match pending.add(&self.scene, hit.point(), on_mesh) {
                Ok(Some(measurement)) => {
                    let index = self.scene.measurements.len();
                    let edit = Edit::Add { index, measurement };
                    let said = edit.describe(&self.scene);
                    if self.history.apply(&mut self.scene, edit).is_ok() {
                        self.chosen = Some(index);
                        let value = self
                            .scene
                            .measure(&self.scene.measurements[index])
                            .ok()
                            .and_then(|m| m.value_text())
                            .unwrap_or_default();
                        self.say(format!("measurement {} {said} {value}", index + 1));
                        self.hit = None;
                    }
                }
                Ok(None) => {}
                Err(e) => self.say(format!("measurement refused: {e}; click its points again")),
            }
            return Ok(());
        }
        if on_mesh != self.selected {
            self.selected = on_mesh;
            match on_mesh.and_then(|id| self.scene.node(id).ok()) {
                Some(node) => println!("selected {}", node.name),
                None => println!("selected nothing"),
            }
        }
        Ok(())
    }

    /// Whether the window pixel `at` shows the selected mesh (meshes only, nearest hit).
    fn on_selected(&mut self, at: (f64, f64)) -> bool {
        let (Some(top), Some(Ok(view))) = (self.selected, self.view()) else {
            return false;
        };
        let (px, py) = (at.0.max(0.0) as u32, at.1.max(0.0) as u32);
        if px >= view.size.0 || py >= view.size.1 {
            return false;
        }
        self.picker.update(&self.scene);
        let options = PickOptions {
            volumes: false,
            ..PickOptions::default()
        };
        match self.picker.pick_pixel(&self.scene, &view, px, py, &options) {
            Some(Hit::Mesh(m)) => plan::top_node(&self.scene, m.node) == top,
            _ => false,
        }
    }

    /// Moves the selected mesh to `after` (its local transform), as one undoable edit.
    fn move_selected(&mut self, after: impl Fn(DMat4, DVec3) -> DMat4) {
        let Some(top) = self.selected else {
            return;
        };
        let Ok(node) = self.scene.node(top) else {
            return;
        };
        let before = node.local();
        let (pivot, _) = plan::pivot(&self.scene, top);
        let edit = Edit::Move {
            node: top,
            before,
            after: after(before, pivot),
        };
        if let Err(e) = self.history.apply(&mut self.scene, edit) {
            self.say(format!("move refused: {e}"));
        } else {
            self.report_selected();
        }
    }

    /// Prints where the selected mesh stands.
    fn report_selected(&self) {
        if let Some(top) = self.selected
            && let Ok(node) = self.scene.node(top)
        {
            let m = node.local();
            println!(
                "moved {} {}",
                node.name,
                serde_json::json!({ "matrix": m.to_cols_array() })
            );
        }
    }

    fn undo(&mut self, redo: bool) {
        let edit = if redo {
            self.history.redo(&mut self.scene)
        } else {
            self.history.undo(&mut self.scene)
        };
        match edit {
            Some(edit) => {
                let what = edit.describe(&self.scene);
                if let Some(i) = self.chosen
                    && i >= self.scene.measurements.len()
                {
                    self.chosen = self.scene.measurements.len().checked_sub(1);
                }
                self.say(format!("{} {what}", if redo { "redo" } else { "undo" }));
            }
            None => self.say(format!("nothing to {}", if redo { "redo" } else { "undo" })),
        }
    }

    /// Saves the plan as a new scene file: beside the scene's own file (NAME-plan.toml, then
    /// NAME-plan-2.toml...), or in the screenshot folder; never over an existing file.
    fn save_plan(&mut self) {
        let size = self
            .gpu
            .as_ref()
            .map_or(self.options.size, |g| g.target.size);
        let text = match self.plan_file(size) {
            Ok(text) => text,
            Err(e) => {
                self.say(format!("the plan was not saved: {e}"));
                eprintln!("the plan was not saved: {e}");
                return;
            }
        };
        let (dir, stem) = match &self.options.scene_path {
            Some(p) => (
                p.parent().unwrap_or(Path::new(".")).to_path_buf(),
                p.file_stem()
                    .map_or("splatscene".into(), |s| s.to_string_lossy().into_owned()),
            ),
            None => (self.options.screenshot_dir.clone(), "splatscene".into()),
        };
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
                    if let Err(e) = f.write_all(text.as_bytes()) {
                        let _ = std::fs::remove_file(&path);
                        self.say(format!("the plan was not saved: {}: {e}", path.display()));
                        eprintln!("the plan was not saved: {}: {e}", path.display());
                        return;
                    }
                    self.history.mark_saved();
                    self.say(format!("saved plan {}", path.display()));
                    return;
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                Err(e) => {
                    // Nothing is lost: the plan stays in the viewer, to be saved elsewhere.
                    self.say(format!(
                        "the plan was not saved: {}: {e} (it is kept here)",
                        path.display()
                    ));
                    eprintln!("the plan was not saved: {}: {e}", path.display());
                    return;
                }
            }
        }
        self.say("the plan was not saved: no free name".into());
    }

    /// Reads the scene file again, keeping the camera; the viewer's edits are dropped.
    fn reload(&mut self) {
        let Some((path, _)) = self.watched.clone() else {
            self.say("no scene file to reload".into());
            return;
        };
        let loaded = SceneFile::read(&path).and_then(|file| {
            let base = path.parent().unwrap_or(Path::new("."));
            let loaded = file.load(&path, base)?;
            Ok((file.with_paths_from(base), loaded))
        });
        self.watched = Some((path.clone(), modified(&path)));
        match loaded {
            Ok((file, loaded)) => {
                // The file's clipping, measurements and placements replace the viewer's.
                self.scene = loaded.scene;
                self.picker = Picker::new(&self.scene);
                self.options.scene_file = Some(file);
                self.remember_transfers();
                self.history = History::new();
                self.selected = None;
                self.measuring = None;
                self.chosen = None;
                self.hit = None;
                self.say(format!("reloaded {}", path.display()));
            }
            Err(e) => {
                self.say(format!("not reloaded: {e}"));
                eprintln!("not reloaded: {e}");
            }
        }
    }

    /// Reloads the scene file when it changed on disk, unless that would drop unsaved edits.
    fn watch(&mut self) {
        let Some((path, seen)) = &self.watched else {
            return;
        };
        let now = modified(path);
        if now.is_none() || now == *seen {
            return;
        }
        if self.history.unsaved() {
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

    /// Keeps each volume's own transfer function, and the presets that fit the data, for
    /// the `T` key.
    fn remember_transfers(&mut self) {
        self.own = self
            .scene
            .volumes()
            .map(|(id, v, _)| (id, Arc::clone(&v.transfer)))
            .collect();
        let hounsfield = self
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
    fn transfer_label(&self) -> String {
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
    fn apply_transfer(&mut self) {
        let preset = self.preset.and_then(TransferFunction::preset).map(Arc::new);
        for (id, own) in self.own.clone() {
            let base = preset.clone().unwrap_or(own);
            let transfer = match self.window {
                Some((level, width)) => Arc::new(base.windowed(level, width)),
                None => base,
            };
            if let Ok(node) = self.scene.node(id)
                && let NodeContent::Volume(v) = &node.content
                && !Arc::ptr_eq(&v.transfer, &transfer)
            {
                let mut v = v.clone();
                v.transfer = transfer;
                let _ = self.scene.set_content(id, NodeContent::Volume(v));
            }
        }
    }

    /// The `T` key: the scene's own function, then each preset that fits the data and draws
    /// otherwise, in turn.
    fn next_preset(&mut self) {
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
    fn current_window(&self) -> Option<(f32, f32)> {
        let (_, node, _) = self.scene.volumes().next()?;
        let points = node.transfer.points();
        let (first, last) = (points.first()?.0, points.last()?.0);
        Some((0.5 * (first + last), (last - first).max(1.0)))
    }

    fn toggle_clip(&mut self) {
        if self.scene.clipping.planes.pop().is_none() {
            let toward_eye = (self.camera.eye - self.camera.target).normalize_or(DVec3::Y);
            let plane = ClipPlane::through(self.camera.target, toward_eye, false);
            self.scene.clipping.planes.push(plane);
            println!("clip plane on, offset {:.1}", plane.offset);
        } else {
            println!("clip plane off");
        }
    }

    /// The `B` key: a crop box around the selected mesh (20 mm beyond it), or around the
    /// middle of the scene; off again.
    fn toggle_crop(&mut self) {
        if self.scene.clipping.crop.take().is_some() {
            println!("crop box off");
            return;
        }
        let around = match self.selected {
            Some(top) => self
                .scene
                .subtree_bounds(top)
                .map(|(lo, hi)| (lo - DVec3::splat(20.0), hi + DVec3::splat(20.0))),
            None => self.scene.bounds().map(|(lo, hi)| {
                let inset = 0.15 * (hi - lo);
                (lo + inset, hi - inset)
            }),
        };
        if let Some((lo, hi)) = around {
            self.scene.clipping.crop = Some((lo, hi));
            println!(
                "crop box on, min ({:.1}, {:.1}, {:.1}) max ({:.1}, {:.1}, {:.1})",
                lo.x, lo.y, lo.z, hi.x, hi.y, hi.z
            );
        }
    }

    /// Grows the crop box by `mm` on every side (shrinks it for negative `mm`, down to 1 mm).
    fn grow_crop(&mut self, mm: f64) {
        if let Some((lo, hi)) = &mut self.scene.clipping.crop {
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
    fn move_clip(&mut self, sign: f64) {
        let step = self
            .scene
            .bounds()
            .map_or(1.0, |(lo, hi)| (hi - lo).length() * 0.02);
        if let Some(plane) = self.scene.clipping.planes.last_mut() {
            plane.offset += sign * step * plane.normal.length();
            println!("clip plane offset {:.1}", plane.offset);
        }
    }

    fn screenshot(&mut self) -> Result<(), ViewerError> {
        let Some(gpu) = &self.gpu else {
            return Ok(());
        };
        let image = match &gpu.cpu_frame.1 {
            Some(image) => image.clone(),
            None => frame_to_rgba8(&gpu.target.read_color(&gpu.ctx)?),
        };
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
        match self.plan_file(size) {
            Err(e) => eprintln!("view: no scene file: {e}"),
            Ok(text) => {
                let toml = path.with_extension("toml");
                match crate::output::write_new(&toml, text.as_bytes()) {
                    Ok(true) => println!("view {}", toml.display()),
                    Ok(false) => eprintln!("view {}: taken meanwhile; not written", toml.display()),
                    Err(e) => eprintln!("view: {e}"),
                }
            }
        }
        Ok(())
    }

    /// The scene file of what the window shows: the scene's own file with the plan (mesh
    /// transforms, measurements), the camera, the ordering, the image size and the transfer
    /// function chosen with `T`.
    fn plan_file(&self, size: (u32, u32)) -> Result<String, String> {
        let file = self
            .options
            .scene_file
            .as_ref()
            .ok_or("the scene has no scene file")?;
        let mut file = file.with_plan(&self.scene)?;
        file.camera = Some(CameraSpec::from_camera(&self.camera, self.scene.up_axis()));
        file.output.size = Some([size.0, size.1]);
        file.output.ordering = Some(self.ordering.to_string());
        for volume in &mut file.volumes {
            if let Some(p) = self.preset {
                volume.transfer = Some(p.to_owned());
                volume.window = None;
                volume.color = None;
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
        let text = file.to_toml()?;
        Ok(format!(
            "# Saved by splatscene's viewer: `splatscene render THIS.toml --out view.png` draws\n# the same picture, and `splatscene view THIS.toml` opens the plan again.\n\n{text}"
        ))
    }

    /// Typing a label: characters go into it, Enter keeps it, Escape drops it.
    fn label_key(&mut self, key: &Key, text: Option<&str>) {
        let Some(typed) = &mut self.labelling else {
            return;
        };
        match key {
            Key::Named(NamedKey::Enter) => {
                let text = typed.trim().to_owned();
                self.labelling = None;
                if let Some(index) = self.chosen
                    && let Some(m) = self.scene.measurements.get(index)
                {
                    let after = (!text.is_empty()).then_some(text);
                    let edit = Edit::Relabel {
                        index,
                        before: m.label.clone(),
                        after,
                    };
                    let said = edit.describe(&self.scene);
                    if self.history.apply(&mut self.scene, edit).is_ok() {
                        self.say(format!("measurement {} {said}", index + 1));
                    }
                }
            }
            Key::Named(NamedKey::Escape) => self.labelling = None,
            Key::Named(NamedKey::Backspace) => {
                typed.pop();
            }
            _ => {
                if let Some(t) = text {
                    typed.extend(t.chars().filter(|c| !c.is_control()).take(200));
                }
            }
        }
    }

    fn key(
        &mut self,
        event_loop: &ActiveEventLoop,
        key: &Key,
        text: Option<&str>,
    ) -> Result<(), ViewerError> {
        if self.labelling.is_some() {
            self.label_key(key, text);
            return Ok(());
        }
        let ctrl = self.modifiers.control_key();
        let big = if self.modifiers.shift_key() {
            10.0
        } else {
            1.0
        };
        let (right, up, forward) = plan::screen_axes(&self.camera);
        match key {
            Key::Named(NamedKey::Escape) => {
                if self.snapping.take().is_some() {
                    println!("snap off");
                } else if self
                    .measuring
                    .as_ref()
                    .is_some_and(|m| !m.points.is_empty())
                {
                    if let Some(m) = &mut self.measuring {
                        m.points.clear();
                    }
                } else if self.measuring.is_some() {
                    self.measuring = None;
                    println!("measure off");
                } else if self.selected.is_some() {
                    self.selected = None;
                    println!("selected nothing");
                } else {
                    event_loop.exit();
                }
            }
            Key::Named(NamedKey::F5) => self.reload(),
            Key::Named(NamedKey::Tab) => {
                let n = self.scene.measurements.len();
                self.chosen = (n > 0).then(|| self.chosen.map_or(0, |i| (i + 1) % n));
            }
            Key::Named(NamedKey::Delete | NamedKey::Backspace) => {
                let index = self
                    .chosen
                    .or_else(|| self.scene.measurements.len().checked_sub(1));
                if let Some(index) = index
                    && let Some(m) = self.scene.measurements.get(index).cloned()
                {
                    let edit = Edit::Remove {
                        index,
                        measurement: m,
                    };
                    let said = edit.describe(&self.scene);
                    if self.history.apply(&mut self.scene, edit).is_ok() {
                        self.chosen = None;
                        self.say(format!("measurement {} {said}", index + 1));
                    }
                }
            }
            Key::Named(
                arrow @ (NamedKey::ArrowLeft
                | NamedKey::ArrowRight
                | NamedKey::ArrowUp
                | NamedKey::ArrowDown),
            ) => {
                let (axis, sign) = match arrow {
                    NamedKey::ArrowLeft => (right, -1.0),
                    NamedKey::ArrowRight => (right, 1.0),
                    NamedKey::ArrowUp => (up, 1.0),
                    _ => (up, -1.0),
                };
                let step = sign * STEP * big;
                if ctrl {
                    // Left and right turn about the screen's up, up and down about its right.
                    let turn_axis = if axis == right { up } else { -right };
                    self.move_selected(|l, p| plan::rotated(l, p, turn_axis, step));
                } else {
                    self.move_selected(|l, _| plan::translated(l, axis * step));
                }
            }
            Key::Character(c) => match (ctrl, c.to_lowercase().as_str()) {
                (true, "z") if self.modifiers.shift_key() => self.undo(true),
                (true, "z") => self.undo(false),
                (true, "y") => self.undo(true),
                (true, "s") => self.save_plan(),
                (true, _) => {}
                (false, "+" | "=") => {
                    self.move_selected(|l, _| plan::translated(l, -forward * STEP * big));
                }
                (false, "-") => {
                    self.move_selected(|l, _| plan::translated(l, forward * STEP * big));
                }
                (false, "q") => event_loop.exit(),
                (false, "s") => self.screenshot()?,
                (false, "t") => self.next_preset(),
                (false, "h") => self.help = !self.help,
                (false, "m") => {
                    let kind = plan::next_kind(self.measuring.as_ref().map(|m| m.kind));
                    self.measuring = kind.map(Pending::new);
                    self.snapping = None;
                    println!("measure {}", kind.map_or("off", MeasureKind::name));
                }
                (false, "n") => {
                    if self.selected.is_some() {
                        self.snapping = Some(None);
                        self.measuring = None;
                        self.say("snap: click a point of the selected mesh".into());
                    } else {
                        self.say("snap: select a mesh first (click it)".into());
                    }
                }
                (false, "x") => {
                    if let Some(m) = &mut self.measuring {
                        m.points.clear();
                    }
                    self.hit = None;
                    println!("points cleared");
                }
                (false, "l") => {
                    if self.chosen.is_none() {
                        self.chosen = self.scene.measurements.len().checked_sub(1);
                    }
                    if let Some(i) = self.chosen {
                        self.labelling =
                            Some(self.scene.measurements[i].label.clone().unwrap_or_default());
                    }
                }
                (false, "a") => {
                    if self.options.annotations.is_none() {
                        self.options.annotations = Some(Annotations::default());
                        self.annotations_on = false;
                    }
                    self.annotations_on = !self.annotations_on;
                    println!(
                        "annotations {}",
                        if self.annotations_on { "on" } else { "off" }
                    );
                }
                (false, "r") => self.camera = self.home,
                (false, "c") => self.toggle_clip(),
                (false, "b") => self.toggle_crop(),
                (false, "{") => self.grow_crop(-5.0),
                (false, "}") => self.grow_crop(5.0),
                (false, "[") => self.move_clip(-1.0),
                (false, "]") => self.move_clip(1.0),
                (false, digit) => {
                    if let Some((_, ordering)) = ORDERINGS.iter().find(|(k, _)| *k == digit) {
                        self.ordering = *ordering;
                        println!("ordering {ordering}");
                    }
                }
            },
            _ => {}
        }
        Ok(())
    }

    fn mouse_moved(&mut self, position: PhysicalPosition<f64>) {
        self.cursor = (position.x, position.y);
        let Some(drag) = &mut self.drag else {
            return;
        };
        let (dx, dy) = (position.x - drag.last.0, position.y - drag.last.1);
        drag.last = self.cursor;
        if (self.cursor.0 - drag.start.0).abs() + (self.cursor.1 - drag.start.1).abs() > 3.0 {
            drag.moved = true;
        }
        if let Some((level0, width0)) = self.windowing {
            // Alt+drag: right raises the level, up narrows the window, both from where the
            // drag began.
            let (tx, ty) = (self.cursor.0 - drag.start.0, self.cursor.1 - drag.start.1);
            let width = width0 * (ty as f32 * 0.01).exp();
            let level = level0 + tx as f32 * width0 / 400.0;
            self.window = Some((level, width.max(1e-3)));
            self.apply_transfer();
            return;
        }
        if drag.button == MouseButton::Left
            && self.moving.is_some()
            && let Some(top) = self.selected
            && let Ok(node) = self.scene.node(top)
        {
            // Shift drags the selected mesh in the view plane, its pivot following the cursor;
            // Ctrl turns it about its pivot, half a degree a pixel.
            let local = node.local();
            let (pivot, _) = plan::pivot(&self.scene, top);
            let (right, up, _) = plan::screen_axes(&self.camera);
            let height = self
                .gpu
                .as_ref()
                .map_or(self.options.size.1, |g| g.target.size.1);
            let after = if self.modifiers.control_key() {
                let turned = plan::rotated(local, pivot, up, 0.5 * dx);
                plan::rotated(turned, pivot, right, 0.5 * dy)
            } else {
                let mm = plan::pixel_size(&self.camera, height, pivot);
                plan::translated(local, (dx * right - dy * up) * mm)
            };
            if let Err(e) = self.scene.set_local(top, after) {
                eprintln!("move refused: {e}");
            }
            return;
        }
        match drag.button {
            MouseButton::Left => {
                let up = self.scene.up_axis();
                self.camera = self.camera.orbit_about(up, -0.4 * dx, 0.4 * dy);
            }
            MouseButton::Right => {
                let distance = (self.camera.target - self.camera.eye).length();
                let forward = (self.camera.target - self.camera.eye).normalize_or(DVec3::Y);
                let right = forward.cross(self.camera.up).normalize_or(DVec3::X);
                let up = right.cross(forward);
                let shift = (-dx * right + dy * up) * distance * 0.0015;
                self.camera.eye += shift;
                self.camera.target += shift;
            }
            _ => {}
        }
    }

    fn zoom(&mut self, steps: f64) {
        let offset = self.camera.eye - self.camera.target;
        self.camera.eye = self.camera.target + offset * 0.9f64.powf(steps);
        if self.previews_when_moving() {
            self.settle = Some(Instant::now() + SETTLE);
        }
    }

    fn handle(
        &mut self,
        event_loop: &ActiveEventLoop,
        event: WindowEvent,
    ) -> Result<(), ViewerError> {
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) => self.resize(size)?,
            WindowEvent::RedrawRequested => return self.redraw(),
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed => {
                self.key(event_loop, &event.logical_key, event.text.as_deref())?;
            }
            WindowEvent::ModifiersChanged(modifiers) => {
                self.modifiers = modifiers.state();
                return Ok(());
            }
            WindowEvent::CursorMoved { position, .. } => self.mouse_moved(position),
            WindowEvent::MouseInput { state, button, .. } => match state {
                ElementState::Pressed => {
                    self.windowing = (self.modifiers.alt_key() && button == MouseButton::Left)
                        .then(|| self.window.or_else(|| self.current_window()))
                        .flatten();
                    // A drag that starts on the selected mesh moves it (Ctrl: turns it), as does
                    // a Shift or Ctrl drag anywhere; other drags move the camera.
                    let modified = self.modifiers.shift_key() || self.modifiers.control_key();
                    let grabbed = self.selected.is_some() && self.on_selected(self.cursor);
                    self.moving = match self.selected {
                        Some(top)
                            if (modified || grabbed)
                                && button == MouseButton::Left
                                && self.windowing.is_none() =>
                        {
                            self.scene.node(top).ok().map(|n| n.local())
                        }
                        _ => None,
                    };
                    self.drag = Some(Drag {
                        button,
                        start: self.cursor,
                        last: self.cursor,
                        moved: false,
                    });
                }
                ElementState::Released => {
                    let drag = self.drag.take();
                    if self.windowing.take().is_some() {
                        if let Some((level, width)) = self.window {
                            self.say(format!(
                                "window level {level:.0} width {width:.0} (classified in {:.0} ms)",
                                self.last.timings.classify.as_secs_f64() * 1e3
                            ));
                        }
                        self.request_redraw();
                        return Ok(());
                    }
                    let dragged = drag.as_ref().is_some_and(|d| d.moved);
                    if let (Some(before), Some(top)) = (self.moving.take(), self.selected)
                        && let Ok(node) = self.scene.node(top)
                        && dragged
                    {
                        // The drag moved the mesh as it went: keep the whole drag as one edit.
                        let after = node.local();
                        self.history.record(Edit::Move {
                            node: top,
                            before,
                            after,
                        });
                        if before != after {
                            self.report_selected();
                        }
                    } else if drag.is_some_and(|d| !d.moved && d.button == MouseButton::Left) {
                        self.pick(self.cursor.0, self.cursor.1)?;
                    }
                }
            },
            WindowEvent::MouseWheel { delta, .. } => {
                let steps = match delta {
                    MouseScrollDelta::LineDelta(_, y) => f64::from(y),
                    MouseScrollDelta::PixelDelta(p) => p.y / 40.0,
                };
                if self.modifiers.shift_key() && self.selected.is_some() {
                    // Away from the eye as the wheel turns down, toward it as it turns up.
                    let (_, _, forward) = plan::screen_axes(&self.camera);
                    let big = if self.modifiers.control_key() {
                        10.0
                    } else {
                        1.0
                    };
                    self.move_selected(|l, _| plan::translated(l, forward * STEP * big * steps));
                } else {
                    self.zoom(steps);
                }
            }
            _ => return Ok(()),
        }
        if let Some(gpu) = &self.gpu {
            gpu.window.request_redraw();
        }
        Ok(())
    }
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.gpu.is_none()
            && let Err(e) = self.start(event_loop)
        {
            self.error = Some(e);
            event_loop.exit();
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        if let Err(e) = self.handle(event_loop, event) {
            self.error = Some(e);
            event_loop.exit();
        }
    }

    /// Draws the full frame once a zoom has settled.
    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        if self.watched.is_some() && Instant::now() >= self.next_check {
            self.next_check = Instant::now() + WATCH_EVERY;
            let before = self.scene.generation();
            let said = self.message.as_ref().map(|(_, at)| *at);
            self.watch();
            if (self.scene.generation() != before
                || self.message.as_ref().map(|(_, at)| *at) != said)
                && let Some(gpu) = &self.gpu
            {
                gpu.window.request_redraw();
            }
        }
        let wake = |due: Option<Instant>, check: Option<Instant>| match (due, check) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        };
        let check = self.watched.as_ref().map(|_| self.next_check);
        if let Some(due) = self.sharpen
            && self.settle.is_none()
            && self.drag.is_none()
        {
            if Instant::now() >= due {
                self.sharpen = None;
                self.sharp_at = Some(self.camera);
                if let Some(gpu) = &self.gpu {
                    gpu.window.request_redraw();
                }
            } else {
                let at = check.map_or(due, |c| c.min(due));
                event_loop.set_control_flow(ControlFlow::WaitUntil(at));
                return;
            }
        }
        match self.settle {
            Some(due) if Instant::now() >= due => {
                self.settle = None;
                event_loop.set_control_flow(match check {
                    Some(at) => ControlFlow::WaitUntil(at),
                    None => ControlFlow::Wait,
                });
                if let Some(gpu) = &self.gpu {
                    gpu.window.request_redraw();
                }
            }
            due => match wake(due, check) {
                Some(at) => event_loop.set_control_flow(ControlFlow::WaitUntil(at)),
                None => event_loop.set_control_flow(ControlFlow::Wait),
            },
        }
    }
}

/// Tints the meshes under `top` toward amber, so that the selection shows.
fn tint(scene: &mut Scene, top: NodeId) {
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
fn shade(image: &mut image::RgbaImage, x0: u32, y0: u32, x1: u32, y1: u32) {
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

/// Writes the on-screen text into the top left of `image`, and the keys over it when `help`.
fn draw_hud(image: &mut image::RgbaImage, lines: &[String], help: bool) {
    if help {
        let top = 28 + 16 * (lines.len() as u32 + 1);
        shade(image, 4, top - 4, 480, top + 16 * KEYS.len() as u32 + 4);
    }
    let Ok(mut painter) = Painter::new(image) else {
        return;
    };
    painter.text_px = 13.0;
    painter.halo_px = 1.5;
    let step = 16.0;
    // Below the top edge's direction letter and any caption.
    let mut y = 28.0;
    for line in lines {
        painter.text(line, 10.0, y, Anchor::TopLeft, [235, 235, 235, 255]);
        y += step;
    }
    if help {
        y += step;
        for (keys, what) in KEYS {
            painter.text(keys, 10.0, y, Anchor::TopLeft, [255, 200, 90, 255]);
            painter.text(what, 130.0, y, Anchor::TopLeft, [235, 235, 235, 255]);
            y += step;
        }
    }
}

/// The twelve edges of the box `lo`..`hi`.
fn box_edges(lo: DVec3, hi: DVec3) -> Vec<(DVec3, DVec3)> {
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
fn plane_outline(plane: &ClipPlane, lo: DVec3, hi: DVec3) -> Vec<(DVec3, DVec3)> {
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
