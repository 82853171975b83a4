//! The refined frame, drawn on a thread of its own once the camera rests, so that the window
//! keeps answering while it is drawn (a close-up's refinement takes a second or more): a drag
//! or a key pressed meanwhile gives it up within a batch of the compositor's time.
//!
//! The renderer goes to the thread with the frame and comes back with it: one renderer, so
//! that the classifications, levels and texels it keeps are made once, whichever thread draws.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::render::{Compositor, FrameOptions, GpuContext, RenderError, Renderer, Screenshot};
use crate::scene::{Scene, SceneCamera};

/// What a refined frame was drawn for: the camera, the scene's generation and the size.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct SharpKey {
    pub(super) camera: SceneCamera,
    pub(super) generation: u64,
    pub(super) size: (u32, u32),
}

/// What the thread gives back: the renderer, the frame (or why not) and how long it took.
type Outcome = (Renderer, Result<Screenshot, RenderError>, Duration);

/// A refined frame being drawn on its own thread.
pub(super) struct SharpJob {
    pub(super) key: SharpKey,
    cancel: Arc<AtomicBool>,
    /// The renderer's compositor, for a fresh renderer should the thread panic.
    compositor: Compositor,
    handle: JoinHandle<Outcome>,
}

/// A refined frame drawn, waiting to be shown.
pub(super) struct SharpFrame {
    pub(super) key: SharpKey,
    pub(super) shot: Result<Screenshot, RenderError>,
    /// How long the thread took to draw it.
    pub(super) took: Duration,
}

impl SharpJob {
    /// Starts drawing `scene` from `key`'s camera at its size with `renderer` (refinement on)
    /// on a thread of its own.
    pub(super) fn start(
        mut renderer: Renderer,
        ctx: Arc<GpuContext>,
        scene: Scene,
        key: SharpKey,
        options: FrameOptions,
    ) -> Self {
        let cancel = Arc::new(AtomicBool::new(false));
        let compositor = renderer.compositor();
        renderer.set_refinement(true);
        renderer.set_cancel(Some(Arc::clone(&cancel)));
        let handle = std::thread::spawn(move || {
            let started = Instant::now();
            let shot = renderer.screenshot(&ctx, &scene, &key.camera, key.size, &options);
            renderer.set_cancel(None);
            (renderer, shot, started.elapsed())
        });
        Self {
            key,
            cancel,
            compositor,
            handle,
        }
    }

    /// Whether the frame is drawn (or given up).
    pub(super) fn is_finished(&self) -> bool {
        self.handle.is_finished()
    }

    /// Waits for the thread: the renderer back and the frame.
    pub(super) fn finish(self) -> (Renderer, SharpFrame) {
        let (renderer, shot, took) = match self.handle.join() {
            Ok(outcome) => outcome,
            Err(_) => (
                Renderer::with_compositor(self.compositor),
                Err(RenderError::Device(
                    "drawing the refined frame failed (its thread panicked)".into(),
                )),
                Duration::ZERO,
            ),
        };
        let frame = SharpFrame {
            key: self.key,
            shot,
            took,
        };
        (renderer, frame)
    }

    /// Gives the frame up: the thread stops at its next check and the renderer comes back.
    pub(super) fn cancel(self) -> Renderer {
        self.cancel.store(true, Ordering::Relaxed);
        self.finish().0
    }
}
