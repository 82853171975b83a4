//! Full and refined frames of the CPU tiles, drawn on a thread of its own so that the window
//! keeps answering while they are drawn (a full frame of a thin-slice CT at the window's size
//! takes 0.1-0.3 s, a close-up's refinement a second or more): a drag begun meanwhile gives
//! the frame up within a batch of the compositor's time, as does an edit during a refined
//! frame; a full frame of the same view is finished and shown, the edit drawn after it.
//! Previews, which are short, are drawn on the window's thread. The thread wakes the event
//! loop when it ends.
//!
//! The renderer goes to the thread with the frame and comes back with it: one renderer, so
//! that the classifications, levels and texels it keeps are made once, whichever thread draws.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::render::{Compositor, FrameOptions, GpuContext, RenderError, Renderer, Screenshot};
use crate::scene::{Scene, SceneCamera};

/// What a frame was drawn for: the camera, the scene's generation, the size and whether
/// volumes coarser than the pixels are refined.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct FrameKey {
    pub(super) camera: SceneCamera,
    pub(super) generation: u64,
    pub(super) size: (u32, u32),
    pub(super) refined: bool,
}

/// What the thread gives back: the renderer, the frame (or why not) and how long it took.
type Outcome = (Renderer, Result<Screenshot, RenderError>, Duration);

/// A frame being drawn on its own thread.
pub(super) struct FrameJob {
    pub(super) key: FrameKey,
    cancel: Arc<AtomicBool>,
    /// Raised by the thread just before it wakes the event loop: the frame is drawn, and
    /// joining the thread waits only for it to return.
    done: Arc<AtomicBool>,
    /// The renderer's compositor, for a fresh renderer should the thread panic.
    compositor: Compositor,
    handle: JoinHandle<Outcome>,
}

/// Raises the job's `done` and wakes the event loop as the thread ends, whether it returns or
/// panics.
struct Finished {
    done: Arc<AtomicBool>,
    wake: winit::event_loop::EventLoopProxy<()>,
}

impl Drop for Finished {
    fn drop(&mut self) {
        self.done.store(true, Ordering::Release);
        // An event loop already closed has no frame to show.
        let _ = self.wake.send_event(());
    }
}

/// A frame drawn, waiting to be shown.
pub(super) struct DrawnFrame {
    pub(super) key: FrameKey,
    pub(super) shot: Result<Screenshot, RenderError>,
    /// How long the thread took to draw it.
    pub(super) took: Duration,
}

impl FrameJob {
    /// Starts drawing `scene` from `key`'s camera at its size with `renderer` (refining as
    /// the key says) on a thread of its own, which sends `wake` a user event once done.
    pub(super) fn start(
        mut renderer: Renderer,
        ctx: Arc<GpuContext>,
        scene: Scene,
        key: FrameKey,
        options: FrameOptions,
        wake: winit::event_loop::EventLoopProxy<()>,
    ) -> Self {
        let cancel = Arc::new(AtomicBool::new(false));
        let compositor = renderer.compositor();
        let done = Arc::new(AtomicBool::new(false));
        let raised = Arc::clone(&done);
        renderer.set_refinement(key.refined);
        renderer.set_cancel(Some(Arc::clone(&cancel)));
        let handle = std::thread::spawn(move || {
            let _finished = Finished { done: raised, wake };
            let started = Instant::now();
            let shot = renderer.screenshot(&ctx, &scene, &key.camera, key.size, &options);
            renderer.set_cancel(None);
            (renderer, shot, started.elapsed())
        });
        Self {
            key,
            cancel,
            done,
            compositor,
            handle,
        }
    }

    /// Whether the frame is drawn (or given up).
    pub(super) fn is_finished(&self) -> bool {
        self.done.load(Ordering::Acquire) || self.handle.is_finished()
    }

    /// Waits for the thread: the renderer back and the frame.
    pub(super) fn finish(self) -> (Renderer, DrawnFrame) {
        let (renderer, shot, took) = match self.handle.join() {
            Ok(outcome) => outcome,
            Err(_) => (
                Renderer::with_compositor(self.compositor),
                Err(RenderError::Device(
                    "drawing the frame failed (its thread panicked)".into(),
                )),
                Duration::ZERO,
            ),
        };
        let frame = DrawnFrame {
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
