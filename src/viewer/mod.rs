//! The viewer window (winit), a planning tool: orbit, pan and zoom with the mouse; click to
//! pick (the hit is printed as a JSON line on standard output and marked) and to select a mesh;
//! move the selected mesh by mouse or by steps; measure distances and angles by clicking; undo
//! and redo every edit; save the plan as a scene file; keys to switch the ordering and the
//! transfer function; on-screen text with the state of all this. [`KEYS`] lists the keys, as
//! the `H` key shows them in the window.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use glam::{DMat4, DVec3};
use winit::application::ApplicationHandler;
use winit::dpi::{PhysicalPosition, PhysicalSize};
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop, EventLoopProxy};
use winit::keyboard::{Key, ModifiersState, NamedKey};
use winit::window::{Window, WindowId};

use crate::annotate::Annotations;
use crate::classify::TransferFunction;
use crate::order::Ordering;
use crate::pick::{Hit, PickOptions, Picker};
use crate::render::{
    Blit, Compositor, FrameReport, GpuContext, RenderError, RenderTarget, Renderer, overlay_texture,
};
use crate::scene::file::SceneFile;
use crate::scene::{NodeId, Scene, SceneCamera};

pub mod action;
pub mod edit;
mod files;
mod guard;
mod look;
mod panes;
pub mod plan;
mod points;
pub mod typed;
mod view;
mod worker;

pub use action::{KEYS, keys_help};
use files::modified;
use panes::{Panes, Under};

use action::{Action, STEP, key_action};
use edit::{Cancelled, Editor, LabelKey, Notice};
use plan::Edit;

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
    /// frames a second), draw the volumes at a coarser level of detail
    /// ([`crate::render::FrameOptions::preview`]), with the CPU tiles composited at fewer
    /// pixels and laid over the meshes drawn at the window's size
    /// ([`crate::render::FrameOptions::volume_divisor`]): half its size, or a third or a
    /// quarter, then a level coarser, where previews take longer than 40 ms; the full frame
    /// follows when the button is released, or a quarter second after the last wheel step.
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
    /// changes. `None` watches nothing.
    pub scene_path: Option<PathBuf>,
    /// The text the scene file was read from: plans are written over it, keeping its comments
    /// and layout where they still hold. `None` writes plans afresh.
    pub scene_text: Option<String>,
    /// The folder plans and autosaves go to; `None` puts them beside the scene file, else in
    /// the screenshot folder.
    pub plan_dir: Option<PathBuf>,
    /// The name plans are saved under (`NAME-plan.toml`) when there is no scene file: the
    /// volume's, say; `None` is `splatscene`.
    pub plan_name: Option<String>,
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
            scene_text: None,
            plan_dir: None,
            plan_name: None,
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

/// What a preview frame may take: past it, the next preview is drawn cheaper
/// ([`next_preview_step`]).
const PREVIEW_BUDGET: Duration = Duration::from_millis(40);

/// How previews are drawn, cheapest last: the window's size divided by the first number is
/// what the volumes are composited at ([`crate::render::FrameOptions::volume_divisor`], the
/// meshes drawn at the window's size), the second is the coarseness of their levels of detail
/// ([`crate::render::FrameOptions::preview`]). Past a quarter of the window's size a level
/// coarser: its splats lie twice as far apart, about four of those pixels, so the pixels still
/// hold what they draw.
const PREVIEW_STEPS: [(u32, u8); 4] = [(2, 1), (3, 1), (4, 1), (4, 2)];

/// What a preview step costs, relative to another, by the model [`next_preview_step`]
/// follows: a frame's cost goes with the pixels its volumes are composited at, and halves
/// with each level coarser (its splats an eighth, each twice as large, with half the layers
/// before a pixel is opaque).
fn preview_cost(step: usize) -> f64 {
    let (divisor, coarseness) = PREVIEW_STEPS[step.min(PREVIEW_STEPS.len() - 1)];
    f64::from(divisor).powi(-2) * 0.5f64.powi(i32::from(coarseness) - 1)
}

/// The step of [`PREVIEW_STEPS`] the next preview is drawn at, from the last preview's `step`
/// and how long that frame took: one cheaper where it took longer than [`PREVIEW_BUDGET`]
/// (up to the last), one dearer where that one would still fit within the budget by the
/// model of [`preview_cost`] (a frame's cost goes with its pixels at least: fewer pixels also
/// draw a coarser level of detail). The gap between the two rules keeps a preview near the
/// budget from changing step every frame.
fn next_preview_step(step: usize, took: Duration) -> usize {
    let step = step.min(PREVIEW_STEPS.len() - 1);
    if took > PREVIEW_BUDGET {
        return (step + 1).min(PREVIEW_STEPS.len() - 1);
    }
    let dearer = step.checked_sub(1);
    match dearer {
        Some(d)
            if took.as_secs_f64() * preview_cost(d) / preview_cost(step)
                < 0.8 * PREVIEW_BUDGET.as_secs_f64() =>
        {
            d
        }
        _ => step,
    }
}

/// After the last wheel step of a zoom drawn as a preview, the full frame follows this late.
const SETTLE: Duration = Duration::from_millis(250);

/// Opens a window on `scene` and runs until it is closed.
pub fn run(scene: Scene, options: ViewerOptions) -> Result<(), ViewerError> {
    let event_loop = EventLoop::new().map_err(|e| ViewerError::Window(e.to_string()))?;
    let home = scene.camera.unwrap_or_else(|| {
        let bounds = scene.fit_bounds();
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
    let picker = Picker::new(&scene);
    let mut app = App {
        edit: Editor::new(scene),
        message: None,
        help: false,
        modifiers: ModifiersState::empty(),
        moving: None,
        point_drag: None,
        last_pick: None,
        watched,
        next_check: Instant::now() + WATCH_EVERY,
        picker,
        options,
        home,
        camera: home,
        ordering,
        preset: None,
        fitting: Vec::new(),
        histogram: None,
        looks: Default::default(),
        own: Vec::new(),
        window: None,
        windowing: None,
        gpu: None,
        cursor: (0.0, 0.0),
        drag: None,
        last: FrameReport::default(),
        full_frame: Duration::ZERO,
        this_frame: Duration::ZERO,
        preview_step: 0,
        settle: None,
        sharpen: None,
        sharp_at: None,
        frame_job: None,
        wake: event_loop.create_proxy(),
        drawn_frame: None,
        frame_stale: false,
        shown_frame: None,
        text_only: false,
        annotations_on: true,
        panes: None,
        contact_map: false,
        painted: None,
        prompt: None,
        autosave: None,
        error: None,
    };
    app.remember_transfers();
    app.start_autosave();
    event_loop
        .run_app(&mut app)
        .map_err(|e| ViewerError::Window(e.to_string()))?;
    // A frame under way on its thread is given up before the window's device goes.
    app.cancel_frame();
    app.error.map_or(Ok(()), Err)
}

struct Gpu {
    window: Arc<Window>,
    /// Shared with the thread that draws full and refined frames ([`worker`]).
    ctx: Arc<GpuContext>,
    /// Whether the renderer composites its splats on the CPU (its compositor and the
    /// adapter's kind, fixed for the session).
    tiles_on_cpu: bool,
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
    /// The slice pane the drag began over (four panes).
    slice: Option<usize>,
}

/// How often the scene file is looked at for changes.
const WATCH_EVERY: Duration = Duration::from_millis(500);

/// The window: the plan being edited ([`Editor`]), the camera, the GPU and what is drawn.
struct App {
    /// The plan: scene, selection, measurements, snap mode and the undo history.
    edit: Editor,
    /// A message on screen (saved, undone, an error) and when it was set.
    message: Option<(String, Instant)>,
    /// Whether the key help shows.
    help: bool,
    modifiers: ModifiersState,
    /// The selected mesh's transform when the drag that moves it began.
    moving: Option<DMat4>,
    /// The measurement point a drag takes (measurement, point) and the measurement before.
    point_drag: Option<(usize, usize, crate::scene::SceneMeasurement)>,
    /// The last pick, as the screen says it.
    last_pick: Option<String>,
    /// The scene file and when it was last modified, to read it again when it changes.
    watched: Option<(PathBuf, Option<SystemTime>)>,
    next_check: Instant,
    picker: Picker,
    options: ViewerOptions,
    home: SceneCamera,
    camera: SceneCamera,
    ordering: Ordering,
    /// The function the `T` key chose last; `None` while the scene's own functions hold.
    preset: Option<look::Choice>,
    /// The functions that fit the data: the CT presets for Hounsfield data, else ramps over
    /// the values' percentiles and the MR preset.
    fitting: Vec<look::Choice>,
    /// The meshes whose opacity or colour was changed with O or Shift+O, by top node.
    looks: std::collections::HashMap<NodeId, look::Look>,
    /// The first volume's histogram, drawn under the window while it is dragged.
    histogram: Option<crate::classify::Histogram>,
    /// Each volume's own transfer function, as the scene gave it.
    own: Vec<(NodeId, Arc<TransferFunction>)>,
    /// A window `(level, width)` set with Alt+drag over the chosen function.
    window: Option<(f32, f32)>,
    /// The window when an Alt+drag began.
    windowing: Option<(f32, f32)>,
    gpu: Option<Gpu>,
    cursor: (f64, f64),
    drag: Option<Drag>,
    last: FrameReport,
    /// How long the last full frame took to draw (whether moving the camera draws previews).
    full_frame: Duration,
    /// How long the frame on screen took to draw (what the on-screen text and title say).
    this_frame: Duration,
    /// The step of [`PREVIEW_STEPS`] previews are drawn at ([`next_preview_step`]).
    preview_step: usize,
    /// When a zoom drawn as previews gets its full frame.
    settle: Option<Instant>,
    /// When a full frame drawn without refining a volume that wanted it gets its refined
    /// frame ([`Renderer::set_refinement`]).
    sharpen: Option<Instant>,
    /// The camera refined frames are drawn at: the one the camera rested at.
    sharp_at: Option<SceneCamera>,
    /// The full or refined frame being drawn on its own thread (CPU tiles, one pane), which
    /// holds the renderer meanwhile.
    frame_job: Option<worker::FrameJob>,
    /// Wakes the event loop once the frame thread is done, to show its frame.
    wake: EventLoopProxy<()>,
    /// The frame drawn on its own thread, until shown.
    drawn_frame: Option<worker::DrawnFrame>,
    /// Whether something the frame shows may have changed since the frame under way on its
    /// thread began (an event handled asked for a redraw): it is then drawn again.
    frame_stale: bool,
    /// What the frame on screen was drawn for, when it came from the frame thread: shown
    /// again under new on-screen text while nothing it shows has changed.
    shown_frame: Option<worker::FrameKey>,
    /// Whether the event being handled changed the on-screen text alone (the help, a prompt, a
    /// line being typed, a plan saved): the frame on screen stays, and one under way goes on.
    text_only: bool,
    /// Whether the annotations show (the `A` key).
    annotations_on: bool,
    /// The four panes (the `V` key), when on.
    panes: Option<panes::Panes>,
    /// Whether the contact map shows (Shift+K).
    contact_map: bool,
    /// The contact map painted at a generation of the scene, for the mesh selected then.
    painted: Option<(u64, Option<NodeId>, crate::pick::paint::Painted)>,
    /// A question the window waits on (quit with unsaved edits, restore an autosave).
    prompt: Option<guard::Prompt>,
    /// Where the plan autosaves.
    autosave: Option<guard::Autosave>,
    error: Option<ViewerError>,
}

impl App {
    pub(super) fn start(&mut self, event_loop: &ActiveEventLoop) -> Result<(), ViewerError> {
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
        let renderer = Renderer::with_compositor(self.options.compositor);
        let tiles_on_cpu = renderer.composites_on_cpu(&ctx);
        self.gpu = Some(Gpu {
            window,
            ctx: Arc::new(ctx),
            tiles_on_cpu,
            surface,
            config,
            target,
            renderer,
            blit,
            overlay,
            cpu_frame,
        });
        Ok(())
    }

    pub(super) fn resize(&mut self, size: PhysicalSize<u32>) -> Result<(), ViewerError> {
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

    /// Says `text` on screen for a few seconds and on standard output.
    pub(super) fn say(&mut self, text: String) {
        println!("{text}");
        self.message = Some((text, Instant::now()));
    }

    /// What lies under window pixel `(x, y)` with four panes; `None` with one view.
    pub(super) fn under(&self, x: f64, y: f64) -> Option<Under> {
        let gpu = self.gpu.as_ref()?;
        self.panes.as_ref()?;
        Some(Panes::under(gpu.target.size, x, y))
    }

    /// A click at window pixel `(x, y)`: a pick in the 3D view, the crosshair in a slice.
    pub(super) fn pick(&mut self, x: f64, y: f64) -> Result<(), ViewerError> {
        let (x, y) = match self.under(x, y) {
            Some(Under::Slice(pane, lx, ly)) => {
                self.click_slice(pane, lx, ly);
                return Ok(());
            }
            Some(Under::View(lx, ly)) => (lx, ly),
            None => (x, y),
        };
        let Some(view) = self.view().transpose()? else {
            return Ok(());
        };
        let (px, py) = (x.max(0.0) as u32, y.max(0.0) as u32);
        if px >= view.size.0 || py >= view.size.1 {
            return Ok(());
        }
        self.picker.update(&self.edit.scene);
        let hit = self
            .picker
            .pick_pixel(&self.edit.scene, &view, px, py, &PickOptions::default());
        let hit_json = hit.map(|h| h.to_json(&self.edit.scene));
        let line = serde_json::json!({ "pixel": [px, py], "hit": hit_json });
        println!("pick {line}");
        self.last_pick = Some(match &hit {
            Some(h) => {
                let p = h.point();
                let on = match h {
                    Hit::Mesh(m) => self
                        .edit
                        .scene
                        .node(m.node)
                        .map_or("a mesh".into(), |n| n.name.clone()),
                    Hit::Volume(v) => format!("voxel value {}", v.value),
                };
                format!("({:.1}, {:.1}, {:.1}) mm RAS, {on}", p.x, p.y, p.z)
            }
            None => "nothing".into(),
        });
        // With four panes the slices go through what was clicked in 3D.
        if let (Some(panes), Some(h)) = (&mut self.panes, &hit) {
            panes.point = h.point();
        }
        let on_mesh = match &hit {
            Some(Hit::Mesh(m)) => Some(self.edit.scene.top_node(m.node)),
            _ => None,
        };
        let notice = self.edit.click(hit.map(|h| h.point()), on_mesh);
        self.tell(notice);
        Ok(())
    }

    /// Whether the window pixel `at` shows the selected mesh (meshes only, nearest hit).
    pub(super) fn on_selected(&mut self, at: (f64, f64)) -> bool {
        let at = match self.under(at.0, at.1) {
            Some(Under::Slice(pane, x, y)) => return self.on_selected_slice(pane, x, y),
            Some(Under::View(x, y)) => (x, y),
            None => at,
        };
        let (Some(top), Some(Ok(view))) = (self.edit.selected, self.view()) else {
            return false;
        };
        let (px, py) = (at.0.max(0.0) as u32, at.1.max(0.0) as u32);
        if px >= view.size.0 || py >= view.size.1 {
            return false;
        }
        self.picker.update(&self.edit.scene);
        let options = PickOptions {
            volumes: false,
            ..PickOptions::default()
        };
        match self
            .picker
            .pick_pixel(&self.edit.scene, &view, px, py, &options)
        {
            Some(Hit::Mesh(m)) => self.edit.scene.top_node(m.node) == top,
            _ => false,
        }
    }

    /// Typing a label: characters go into it, Enter keeps it, Escape drops it.
    /// A key pressed: typed into the label being edited, else its [`Action`] carried out.
    /// `repeat`: the system's repeat of a key held down, which types into a line and repeats
    /// the actions that [`Action::repeats`], and answers no question.
    pub(super) fn key(
        &mut self,
        event_loop: &ActiveEventLoop,
        key: &Key,
        text: Option<&str>,
        repeat: bool,
    ) -> Result<(), ViewerError> {
        if repeat && self.prompt.is_some() {
            // An answer is a key pressed for it, not one held from before the question.
            self.text_only = true;
            return Ok(());
        }
        // Answers to a prompt change the text on screen, bar restoring an autosave.
        let restoring = matches!(self.prompt, Some(guard::Prompt::Restore(_)))
            && matches!(key, Key::Character(c) if c.eq_ignore_ascii_case("r"));
        if self.answer(event_loop, key) {
            self.text_only = !restoring;
            return Ok(());
        }
        // A line being typed (a placement, a label) takes the keys first.
        let typed = match key {
            Key::Named(NamedKey::Enter) => LabelKey::Enter,
            Key::Named(NamedKey::Escape) => LabelKey::Escape,
            Key::Named(NamedKey::Backspace) => LabelKey::Backspace,
            _ => LabelKey::Text(text),
        };
        // Keys typed into a line change it alone, until Enter applies it.
        let typing = !matches!(typed, LabelKey::Enter);
        if self.edit.placing.is_some() {
            self.text_only = typing;
            let notice = self.edit.place_key(typed);
            self.tell(notice);
            return Ok(());
        }
        if self.edit.labelling.is_some() {
            self.text_only = typing;
            let notice = self.edit.label_key(typed);
            self.tell(notice);
            return Ok(());
        }
        let Some(action) = key_action(key, self.modifiers).filter(|a| !repeat || a.repeats())
        else {
            // A key that does nothing (a modifier alone, a toggle's repeat) changes nothing
            // drawn.
            self.text_only = true;
            return Ok(());
        };
        match action {
            Action::Cancel => match self.edit.cancel() {
                Cancelled::Done(notice) => self.tell(notice),
                Cancelled::Nothing => self.quit(event_loop),
            },
            Action::Quit => {
                // Unsaved edits: a question on screen.
                self.text_only = true;
                self.quit(event_loop);
            }
            Action::Reload => self.reload(),
            Action::SavePlan => {
                self.text_only = true;
                self.save_plan();
            }
            Action::Screenshot => self.screenshot()?,
            Action::NextPreset => self.next_preset(),
            Action::ToggleHelp => {
                self.text_only = true;
                self.help = !self.help;
            }
            Action::ToggleAnnotations => {
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
            Action::ResetCamera => self.camera = self.home,
            Action::TogglePanes => self.toggle_panes(),
            Action::ImplantPane => self.toggle_implant_pane(),
            Action::ToggleContactMap => self.toggle_contact_map(),
            Action::MeshOpacity => self.next_look(true),
            Action::MeshColour => self.next_look(false),
            Action::ToggleClip => self.toggle_clip(),
            Action::MoveClip(mm) => self.move_clip(mm),
            Action::ToggleCrop => self.toggle_crop(),
            Action::GrowCrop(mm) => self.grow_crop(mm),
            Action::Ordering(ordering) => {
                self.ordering = ordering;
                println!("ordering {ordering}");
            }
            edit => {
                let notice = self.edit.act(edit, &self.camera);
                self.tell(notice);
            }
        }
        Ok(())
    }

    /// Tells the user what an edit said: on screen and standard output, or standard output.
    pub(super) fn tell(&mut self, notice: Option<Notice>) {
        match notice {
            Some(Notice::Say(text)) => self.say(text),
            Some(Notice::Print(text)) => println!("{text}"),
            None => {}
        }
    }

    pub(super) fn mouse_moved(&mut self, position: PhysicalPosition<f64>) {
        self.cursor = (position.x, position.y);
        let Some(drag) = &mut self.drag else {
            return;
        };
        let (dx, dy) = (position.x - drag.last.0, position.y - drag.last.1);
        drag.last = self.cursor;
        if (self.cursor.0 - drag.start.0).abs() + (self.cursor.1 - drag.start.1).abs() > 3.0 {
            drag.moved = true;
        }
        if self.panes.as_ref().is_some_and(|p| p.windowing.is_some()) {
            let (tx, ty) = (self.cursor.0 - drag.start.0, self.cursor.1 - drag.start.1);
            self.window_slices(tx, ty);
            return;
        }
        let slice = drag.slice;
        let moved = drag.moved;
        if let Some((i, j, _)) = &self.point_drag {
            let (i, j) = (*i, *j);
            if moved {
                self.drag_point(i, j, self.cursor);
            }
            return;
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
            && let Some(top) = self.edit.selected
            && let Ok(node) = self.edit.scene.node(top)
        {
            // Shift drags the selected mesh in the view plane, its pivot following the cursor;
            // Ctrl turns it about its pivot, half a degree a pixel.
            let local = node.local();
            let (pivot, _) = self.edit.scene.pivot(top);
            let (right, up, _) = plan::screen_axes(&self.camera);
            let height = match self.view() {
                Some(Ok(view)) => view.size.1,
                _ => self.options.size.1,
            };
            let after = if let Some(pane) = slice {
                // Over a slice: moved in that slice's plane, following the cursor.
                self.moved_in_slice(pane, local, dx, dy)
            } else if self.modifiers.control_key() {
                let turned = plan::rotated(local, pivot, up, 0.5 * dx);
                plan::rotated(turned, pivot, right, 0.5 * dy)
            } else {
                let mm = plan::pixel_size(&self.camera, height, pivot);
                plan::translated(local, (dx * right - dy * up) * mm)
            };
            if let Err(e) = self.edit.scene.set_local(top, after) {
                eprintln!("move refused: {e}");
            }
            return;
        }
        if slice.is_some() {
            // Drags over a slice move nothing but the selected mesh.
            return;
        }
        match drag.button {
            MouseButton::Left => {
                let up = self.edit.scene.up_axis();
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

    /// Whether an Alt+drag is windowing the values, of the volume or of the slices.
    fn windowing_values(&self) -> bool {
        self.windowing.is_some() || self.panes.as_ref().is_some_and(|p| p.windowing.is_some())
    }

    pub(super) fn zoom(&mut self, steps: f64) {
        let offset = self.camera.eye - self.camera.target;
        self.camera.eye = self.camera.target + offset * 0.9f64.powf(steps);
        if self.previews_when_moving() {
            self.settle = Some(Instant::now() + SETTLE);
        }
    }

    pub(super) fn handle(
        &mut self,
        event_loop: &ActiveEventLoop,
        event: WindowEvent,
    ) -> Result<(), ViewerError> {
        self.text_only = false;
        match event {
            WindowEvent::CloseRequested => {
                // Unsaved edits: a question on screen.
                self.text_only = true;
                self.quit(event_loop);
            }
            WindowEvent::Resized(size) => self.resize(size)?,
            WindowEvent::RedrawRequested => return self.redraw(),
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed => {
                self.key(
                    event_loop,
                    &event.logical_key,
                    event.text.as_deref(),
                    event.repeat,
                )?;
            }
            WindowEvent::ModifiersChanged(modifiers) => {
                self.modifiers = modifiers.state();
                return Ok(());
            }
            WindowEvent::CursorMoved { position, .. } => {
                self.mouse_moved(position);
                // The cursor passing over the window changes nothing drawn, nor does a drag
                // within its first pixels (a click's jitter): only a drag that has moved, or
                // one that windows the values, which follows every pixel.
                if !self.windowing_values() && !self.drag.as_ref().is_some_and(|d| d.moved) {
                    return Ok(());
                }
            }
            WindowEvent::MouseInput { state, button, .. } => match state {
                ElementState::Pressed => {
                    let slice = match self.under(self.cursor.0, self.cursor.1) {
                        Some(Under::Slice(pane, _, _)) => Some(pane),
                        _ => None,
                    };
                    let alt = self.modifiers.alt_key() && button == MouseButton::Left;
                    if alt && slice.is_some() {
                        // Alt+drag over a slice windows the slices, not the 3D view.
                        let start = self.slice_window();
                        if let Some(p) = &mut self.panes {
                            p.windowing = Some(start);
                        }
                    }
                    self.windowing = (alt && slice.is_none())
                        .then(|| self.window.or_else(|| self.current_window()))
                        .flatten();
                    // A drag that starts on the selected mesh moves it (Ctrl: turns it), as does
                    // a Shift or Ctrl drag anywhere; other drags move the camera.
                    let modified = self.modifiers.shift_key() || self.modifiers.control_key();
                    // A plain left drag that starts on a measurement point's marker takes the
                    // point.
                    self.point_drag = (button == MouseButton::Left && !modified && !alt)
                        .then(|| self.point_at(self.cursor))
                        .flatten()
                        .and_then(|(i, j)| {
                            let before = self.edit.scene.measurements.get(i)?.clone();
                            Some((i, j, before))
                        });
                    let grabbed = self.point_drag.is_none()
                        && self.edit.selected.is_some()
                        && self.on_selected(self.cursor);
                    self.moving = match self.edit.selected {
                        Some(top)
                            if (modified || grabbed)
                                && self.point_drag.is_none()
                                && button == MouseButton::Left
                                && !alt =>
                        {
                            self.edit.scene.node(top).ok().map(|n| n.local())
                        }
                        _ => None,
                    };
                    self.drag = Some(Drag {
                        button,
                        start: self.cursor,
                        last: self.cursor,
                        moved: false,
                        slice,
                    });
                    // A press alone changes nothing drawn but the histogram an Alt+drag shows:
                    // the frame follows when the drag moves or the button is released, so a
                    // drag does not wait for a full frame of what is on screen already.
                    if !self.windowing_values() {
                        return Ok(());
                    }
                }
                ElementState::Released => {
                    let drag = self.drag.take();
                    if let Some(p) = &mut self.panes
                        && p.windowing.take().is_some()
                    {
                        let [lo, hi] = self.slice_window();
                        self.say(format!("slices window {lo:.0} to {hi:.0}"));
                        self.request_redraw();
                        return Ok(());
                    }
                    if self.windowing.take().is_some() {
                        // (The frame that classifies the volume for it follows; the title
                        // says what each frame's classification took.)
                        if let Some((level, width)) = self.window {
                            self.say(format!("window level {level:.0} width {width:.0}"));
                        }
                        self.request_redraw();
                        return Ok(());
                    }
                    let dragged = drag.as_ref().is_some_and(|d| d.moved);
                    if let Some((i, _, before)) = self.point_drag.take()
                        && dragged
                    {
                        self.dropped_point(i, before);
                    } else if let (Some(before), Some(top)) =
                        (self.moving.take(), self.edit.selected)
                        && let Ok(node) = self.edit.scene.node(top)
                        && dragged
                    {
                        // The drag moved the mesh as it went: keep the whole drag as one edit.
                        let after = node.local();
                        self.edit.history.record(Edit::Move {
                            node: top,
                            before,
                            after,
                        });
                        if before != after {
                            let notice = self.edit.where_selected();
                            self.tell(notice);
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
                if let Some(Under::Slice(pane, _, _)) = self.under(self.cursor.0, self.cursor.1) {
                    self.scroll_slice(pane, steps);
                } else if self.modifiers.shift_key() && self.edit.selected.is_some() {
                    // Away from the eye as the wheel turns down, toward it as it turns up.
                    let (_, _, forward) = plan::screen_axes(&self.camera);
                    let big = if self.modifiers.control_key() {
                        10.0
                    } else {
                        1.0
                    };
                    let notice = self
                        .edit
                        .move_selected(|l, _| plan::translated(l, forward * STEP * big * steps));
                    self.tell(notice);
                } else {
                    self.zoom(steps);
                }
            }
            _ => return Ok(()),
        }
        // Whatever else an event changed may be in the picture: it is drawn again, first as a
        // full frame (a close-up's refined frame takes a second or more); the refined frame
        // follows once nothing has changed for a moment, as after a camera move.
        if !std::mem::take(&mut self.text_only) {
            self.frame_stale = true;
            self.sharp_at = None;
            self.sharpen = None;
        }
        if let Some(gpu) = &self.gpu {
            gpu.window.request_redraw();
        }
        Ok(())
    }

    /// Gives up the frame under way on its thread, if any, the renderer back.
    pub(super) fn cancel_frame(&mut self) {
        if let Some(job) = self.frame_job.take() {
            let renderer = job.cancel();
            if let Some(gpu) = &mut self.gpu {
                gpu.renderer = renderer;
            }
        }
    }

    /// Takes the frame from its thread once drawn, to be shown.
    fn collect_frame(&mut self) {
        if self
            .frame_job
            .as_ref()
            .is_some_and(worker::FrameJob::is_finished)
            && let Some(job) = self.frame_job.take()
        {
            let (renderer, frame) = job.finish();
            self.drawn_frame = Some(frame);
            if let Some(gpu) = &mut self.gpu {
                gpu.renderer = renderer;
                gpu.window.request_redraw();
            }
        }
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

    /// Draws the full frame once a zoom has settled, and shows a frame drawn on its thread
    /// (which wakes the loop with a user event when it is done).
    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        self.collect_frame();
        self.plan_wake(event_loop);
    }
}

impl App {
    /// When the event loop wakes next: autosaves, the scene file's checks, a zoom's full
    /// frame and the refined frame.
    fn plan_wake(&mut self, event_loop: &ActiveEventLoop) {
        if self.autosave_due().is_some_and(|due| Instant::now() >= due) {
            self.autosave_now();
        }
        if self.watched.is_some() && Instant::now() >= self.next_check {
            self.next_check = Instant::now() + WATCH_EVERY;
            let before = self.edit.scene.generation();
            let said = self.message.as_ref().map(|(_, at)| *at);
            self.watch();
            if (self.edit.scene.generation() != before
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
        let check = wake(
            self.watched.as_ref().map(|_| self.next_check),
            self.autosave_due(),
        );
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn previews_grow_cheaper_while_over_their_budget_and_dearer_with_room_to_spare() {
        let ms = Duration::from_millis;
        // Over 40 ms: a third, a quarter, then a level coarser, no cheaper.
        assert_eq!(next_preview_step(0, ms(55)), 1);
        assert_eq!(next_preview_step(1, ms(41)), 2);
        assert_eq!(next_preview_step(2, ms(60)), 3);
        assert_eq!(next_preview_step(3, ms(90)), 3);
        assert_eq!(PREVIEW_STEPS[3], (4, 2));
        // Within it: one step dearer where that would still take under 32 ms by the model,
        // never dearer than half the window's size at one level coarser.
        assert_eq!(next_preview_step(0, ms(10)), 0);
        assert_eq!(next_preview_step(1, ms(12)), 0); // 12 x (3/2)^2 = 27 ms
        assert_eq!(next_preview_step(1, ms(20)), 1); // 20 x (3/2)^2 = 45 ms
        assert_eq!(next_preview_step(2, ms(15)), 1); // 15 x (4/3)^2 = 26.7 ms
        assert_eq!(next_preview_step(2, ms(20)), 2); // 20 x (4/3)^2 = 35.6 ms
        assert_eq!(next_preview_step(3, ms(15)), 2); // 15 x 2 = 30 ms
        assert_eq!(next_preview_step(3, ms(17)), 3); // 17 x 2 = 34 ms
        assert_eq!(next_preview_step(9, ms(10)), 2);
        // A preview that had to get cheaper because the dearer one took over the budget does
        // not grow back while the model holds: it takes over 40 ms times the ratio of their
        // costs, which grows back to over 40 ms, past the 32 ms the rule allows.
        for step in 0..PREVIEW_STEPS.len() - 1 {
            for over in [41, 50, 80] {
                let cheaper = next_preview_step(step, ms(over));
                let took = over as f64 * preview_cost(cheaper) / preview_cost(step);
                let again = next_preview_step(cheaper, Duration::from_secs_f64(took / 1e3));
                // (Still over the budget, it rightly gets cheaper again.)
                let want = if took > PREVIEW_BUDGET.as_secs_f64() * 1e3 {
                    (cheaper + 1).min(PREVIEW_STEPS.len() - 1)
                } else {
                    cheaper
                };
                assert_eq!(again, want, "step {step}, {over} ms");
            }
        }
    }
}
