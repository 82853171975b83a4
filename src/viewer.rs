//! The viewer window (winit): orbit, pan and zoom with the mouse; click to pick (the hit is
//! printed as a JSON line on standard output and marked); keys to switch the ordering and the
//! transfer function; a screenshot key; frame and order time in the title.
//!
//! Keys: `1` BTF, `2` PBTF, `3` IP-PBTF, `4` exact, `5` bucketed, `6` pyramid, `7` rows; `T` next transfer function;
//! `A` annotations (orientation marker, patient-direction letters, scale bar) off and on;
//! `S` screenshot (a new `splatscene-view-N.png` in the screenshot folder, without the
//! annotations, and beside it `splatscene-view-N.toml`, the scene file that `render` turns into
//! the same picture); `C` a clip plane
//! facing the eye through the target (cutting the volume, not the meshes), or off again, and
//! `[` / `]` move it away from or toward the eye; `R` reset the camera; `Q` or Escape quits. Mouse: left drag orbits about the scene's up, right drag pans, the wheel zooms, a
//! left click without dragging picks.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::DVec3;
use winit::application::ApplicationHandler;
use winit::dpi::{PhysicalPosition, PhysicalSize};
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{Key, NamedKey};
use winit::window::{Window, WindowId};

use crate::annotate::{Annotations, annotate_image};
use crate::classify::TransferFunction;
use crate::order::Ordering;
use crate::pick::measure::{MarkerStyle, Measurement, annotate};
use crate::pick::{PickOptions, Picker};
use crate::render::{
    Blit, Compositor, FrameOptions, FrameReport, GpuContext, RenderError, RenderTarget, Renderer,
    ViewSetup, encode_png, frame_to_rgba8, overlay_texture, write_overlay,
};
use crate::scene::file::{CameraSpec, SceneFile};
use crate::scene::{ClipPlane, NodeContent, NodeId, Scene, SceneCamera};

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
    let mut app = App {
        picker: Picker::new(&scene),
        scene,
        options,
        home,
        camera: home,
        ordering,
        preset: None,
        gpu: None,
        cursor: (0.0, 0.0),
        drag: None,
        marker: None,
        last: FrameReport::default(),
        full_frame: Duration::ZERO,
        settle: None,
        annotations_on: true,
        error: None,
    };
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

struct App {
    scene: Scene,
    picker: Picker,
    options: ViewerOptions,
    home: SceneCamera,
    camera: SceneCamera,
    ordering: Ordering,
    /// The preset the `T` key chose last; `None` while the scene's own functions hold.
    preset: Option<usize>,
    gpu: Option<Gpu>,
    cursor: (f64, f64),
    drag: Option<Drag>,
    marker: Option<NodeId>,
    last: FrameReport,
    /// How long the last full frame took to draw and present.
    full_frame: Duration,
    /// When a zoom drawn as previews gets its full frame.
    settle: Option<Instant>,
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
        let Some(gpu) = &mut self.gpu else {
            return Ok(());
        };
        let options = FrameOptions {
            ordering: Some(self.ordering),
            background: Some(self.options.background),
            measure: false,
            preview,
        };
        let started = std::time::Instant::now();
        let target = &gpu.target;
        let on_cpu = gpu.renderer.composites_on_cpu(&gpu.ctx);
        if on_cpu {
            // The tile compositor's frame, shown through the present pass like the GPU's.
            let shot = gpu.renderer.screenshot(
                &gpu.ctx,
                &self.scene,
                &self.camera,
                target.size,
                &options,
            )?;
            self.last = shot.report;
            let image = frame_to_rgba8(&shot.frame);
            let (w, h) = target.size;
            write_overlay(&gpu.ctx, &gpu.cpu_frame.0, image.as_raw(), w, h);
            gpu.cpu_frame.1 = Some(image);
        } else {
            self.last = gpu.renderer.render(
                &gpu.ctx,
                &self.scene,
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
        let overlay = match (&self.options.annotations, self.annotations_on) {
            (Some(parts), true) => {
                let (w, h) = target.size;
                let mut image = image::RgbaImage::new(w, h);
                match annotate_image(
                    &mut image,
                    &self.camera,
                    &self.scene.patient_frame(),
                    &[],
                    parts,
                ) {
                    Ok(_) => {
                        write_overlay(&gpu.ctx, &gpu.overlay, image.as_raw(), w, h);
                        Some(gpu.overlay.create_view(&Default::default()))
                    }
                    Err(e) => {
                        eprintln!("annotations off: {e}");
                        self.annotations_on = false;
                        None
                    }
                }
            }
            _ => None,
        };
        let cpu_view = on_cpu.then(|| gpu.cpu_frame.0.create_view(&Default::default()));
        let source = cpu_view.as_ref().unwrap_or(&target.color_view);
        gpu.blit
            .copy(&gpu.ctx, source, overlay.as_ref(), &surface_view);
        gpu.window.pre_present_notify();
        gpu.ctx.queue.present(frame);
        let elapsed = started.elapsed();
        if !preview {
            self.full_frame = elapsed;
        }
        let preset = self
            .preset
            .map_or("scene transfer function", |p| PRESETS[p]);
        gpu.window.set_title(&format!(
            "splatscene: {}{} | {preset} | frame {:.0} ms, order {:.1} ms | {} splats{}",
            self.ordering,
            if on_cpu { " (CPU tiles)" } else { "" },
            elapsed.as_secs_f64() * 1e3,
            self.last.timings.order.as_secs_f64() * 1e3,
            self.last.splats,
            if options.preview { " (preview)" } else { "" }
        ));
        Ok(())
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
        if let Some(old) = self.marker.take() {
            // Hide the previous marker: an empty group in its place.
            let _ = self.scene.set_content(old, NodeContent::Empty);
            for child in self
                .scene
                .node(old)
                .map(|n| n.children().to_vec())
                .unwrap_or_default()
            {
                let _ = self.scene.set_content(child, NodeContent::Empty);
            }
        }
        if let Some(hit) = hit {
            let radius = self
                .scene
                .bounds()
                .map_or(1.0, |(lo, hi)| (hi - lo).length() * 0.006);
            let style = MarkerStyle {
                point_radius: radius,
                ..MarkerStyle::default()
            };
            let point = Measurement::distance(hit.point(), hit.point());
            self.marker = annotate(&mut self.scene, &point, &style).ok();
        }
        Ok(())
    }

    fn next_preset(&mut self) {
        // The first press moves to the first preset that differs from what the scene shows.
        let current = self
            .scene
            .volumes()
            .next()
            .map(|(_, v, _)| Arc::clone(&v.transfer));
        let next = match self.preset {
            Some(p) => (p + 1) % PRESETS.len(),
            None => (0..PRESETS.len())
                .find(|&i| TransferFunction::preset(PRESETS[i]).as_ref() != current.as_deref())
                .unwrap_or(0),
        };
        self.preset = Some(next);
        let Some(transfer) = TransferFunction::preset(PRESETS[next]).map(Arc::new) else {
            return;
        };
        let ids: Vec<NodeId> = self.scene.volumes().map(|(id, _, _)| id).collect();
        for id in ids {
            if let Ok(node) = self.scene.node(id)
                && let NodeContent::Volume(v) = &node.content
            {
                let mut v = v.clone();
                v.transfer = Arc::clone(&transfer);
                let _ = self.scene.set_content(id, NodeContent::Volume(v));
            }
        }
        println!("transfer function {}", PRESETS[next]);
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
        // The first number whose picture and scene file are both free: nothing is replaced.
        let path = (1..)
            .map(|n| dir.join(format!("splatscene-view-{n}.png")))
            .find(|p| !p.exists() && !p.with_extension("toml").exists())
            .unwrap_or_else(|| dir.join("splatscene-view.png"));
        match std::fs::write(&path, png) {
            Ok(()) => println!("screenshot {}", path.display()),
            Err(e) => {
                eprintln!("screenshot {}: {e}", path.display());
                return Ok(());
            }
        }
        if let Some(text) = self.view_file(size) {
            let toml = path.with_extension("toml");
            match std::fs::write(&toml, text) {
                Ok(()) => println!("view {}", toml.display()),
                Err(e) => eprintln!("view {}: {e}", toml.display()),
            }
        }
        Ok(())
    }

    /// The scene file of what the window shows: the scene's own file with the camera, the
    /// ordering, the image size and the transfer function chosen with `T`.
    fn view_file(&self, size: (u32, u32)) -> Option<String> {
        let mut file = self.options.scene_file.clone()?;
        file.camera = Some(CameraSpec::from_camera(&self.camera, self.scene.up_axis()));
        file.output.size = Some([size.0, size.1]);
        file.output.ordering = Some(self.ordering.to_string());
        if let Some(p) = self.preset {
            for volume in &mut file.volumes {
                volume.transfer = Some(PRESETS[p].to_owned());
                volume.window = None;
                volume.color = None;
                volume.level_width = None;
                volume.shift = None;
            }
        }
        if !self.scene.clipping.planes.is_empty() {
            eprintln!("note: the clip plane is not saved in the view's scene file");
        }
        match file.to_toml() {
            Ok(text) => Some(format!(
                "# The view saved by splatscene's viewer: `splatscene render THIS.toml --out view.png`\n# draws the same picture.\n\n{text}"
            )),
            Err(e) => {
                eprintln!("view: cannot write the scene file: {e}");
                None
            }
        }
    }

    fn key(&mut self, event_loop: &ActiveEventLoop, key: &Key) -> Result<(), ViewerError> {
        match key {
            Key::Named(NamedKey::Escape) => event_loop.exit(),
            Key::Character(c) => match c.to_lowercase().as_str() {
                "q" => event_loop.exit(),
                "s" => self.screenshot()?,
                "t" => self.next_preset(),
                "a" => {
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
                "r" => self.camera = self.home,
                "c" => self.toggle_clip(),
                "[" => self.move_clip(-1.0),
                "]" => self.move_clip(1.0),
                digit => {
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
                self.key(event_loop, &event.logical_key)?;
            }
            WindowEvent::CursorMoved { position, .. } => self.mouse_moved(position),
            WindowEvent::MouseInput { state, button, .. } => match state {
                ElementState::Pressed => {
                    self.drag = Some(Drag {
                        button,
                        start: self.cursor,
                        last: self.cursor,
                        moved: false,
                    });
                }
                ElementState::Released => {
                    let click = self
                        .drag
                        .take()
                        .filter(|d| !d.moved && d.button == MouseButton::Left);
                    if click.is_some() {
                        self.pick(self.cursor.0, self.cursor.1)?;
                    }
                }
            },
            WindowEvent::MouseWheel { delta, .. } => self.zoom(match delta {
                MouseScrollDelta::LineDelta(_, y) => f64::from(y),
                MouseScrollDelta::PixelDelta(p) => p.y / 40.0,
            }),
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
        match self.settle {
            Some(due) if Instant::now() >= due => {
                self.settle = None;
                event_loop.set_control_flow(ControlFlow::Wait);
                if let Some(gpu) = &self.gpu {
                    gpu.window.request_redraw();
                }
            }
            Some(due) => event_loop.set_control_flow(ControlFlow::WaitUntil(due)),
            None => event_loop.set_control_flow(ControlFlow::Wait),
        }
    }
}
