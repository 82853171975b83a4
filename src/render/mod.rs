//! The GPU layer: a wgpu context, offscreen targets with one readback helper, and the renderer
//! with its two passes (opaque meshes with depth write, then splats in visibility order,
//! depth-tested against the meshes). Everything below `render` draws into caller-given texture
//! views, so windows, screenshots and tests share one code path.

use thiserror::Error;

mod blit;
mod context;
mod depth_image;
mod mesh_pass;
mod output;
mod renderer;
mod splat_pass;
mod target;
mod tile_pass;
mod view;

pub use blit::{Blit, OVERLAY_FORMAT, overlay_texture, write_overlay};
pub use context::GpuContext;
pub use depth_image::{DepthImage, DepthMode};
pub use output::{encode_png, encode_png_with_text, frame_to_rgba8};
pub use renderer::{
    Compositor, Detail, FrameOptions, FrameReport, FrameTimings, LevelOfDetail, MAX_DEPTH_LEVELS,
    MAX_LEVEL, MAX_REFINE, MAX_REFINED_VOXELS, PREVIEW_COPY_SPACING_MM, REFINE_TO, Renderer,
    Screenshot, detail_for, pixels_apart, preview_level,
};
pub use target::{DEPTH_FORMAT, RenderTarget, color_format, read_texture};
pub use view::ViewSetup;

/// Why a frame could not be rendered.
#[derive(Debug, Error)]
pub enum RenderError {
    /// wgpu found no adapter at all.
    #[error(
        "no GPU adapter found ({0}); on Debian or Ubuntu without a GPU install Mesa's software Vulkan driver: apt-get install mesa-vulkan-drivers"
    )]
    NoAdapter(String),
    /// The adapter refused to make a device, or the device failed.
    #[error("GPU device error: {0}")]
    Device(String),
    /// The image is past the size any output takes (see [`crate::budget`]).
    #[error("{0}")]
    ImageSize(#[from] crate::budget::SizeError),
    /// The image size is zero or beyond the adapter's limit.
    #[error("image size {width}x{height} is not between 1x1 and {max}x{max}")]
    BadSize {
        /// Requested width.
        width: u32,
        /// Requested height.
        height: u32,
        /// The adapter's largest 2D texture side.
        max: u32,
    },
    /// The image is larger than the adapter can copy back to memory in one buffer.
    #[error(
        "image size {width}x{height} needs a {bytes}-byte readback buffer; the adapter allows {max} bytes"
    )]
    TooLargeToRead {
        /// Requested width.
        width: u32,
        /// Requested height.
        height: u32,
        /// Bytes of the colour readback (rows padded to 256 bytes).
        bytes: u64,
        /// The adapter's largest buffer.
        max: u64,
    },
    /// The camera is unusable.
    #[error("camera: {0}")]
    BadCamera(String),
    /// A frame option that cannot mean anything, or none where it stands.
    #[error("frame options: {0}")]
    Options(String),
    /// The draw order, or the splats' texels, do not fit in one GPU buffer.
    #[error("{splats} splats exceed the adapter's largest buffer of {max_bytes} bytes")]
    TooManySplats {
        /// Splats in the draw order.
        splats: usize,
        /// The adapter's largest buffer.
        max_bytes: u64,
    },
    /// Reading the image back failed.
    #[error("reading the frame back failed: {0}")]
    Readback(String),
    /// The frame was given up before it was finished: its renderer's cancel flag was raised
    /// ([`Renderer::set_cancel`]). What the renderer keeps between frames stays whole.
    #[error("the frame was cancelled before it was finished")]
    Cancelled,
    /// The adapter lacks something this needs (an OpenGL adapter cannot copy depth to memory).
    #[error(
        "the GPU adapter {adapter} cannot {what}; Mesa's software Vulkan driver can (apt-get install mesa-vulkan-drivers)"
    )]
    Unsupported {
        /// The adapter, as [`GpuContext::describe`] gives it.
        adapter: String,
        /// What it cannot do.
        what: &'static str,
    },
    /// A volume node could not be classified or ordered.
    #[error("volume node {node:?}: {message}")]
    Volume {
        /// The node's name.
        node: String,
        /// What went wrong.
        message: String,
    },
}

impl From<crate::camera::CameraError> for RenderError {
    fn from(e: crate::camera::CameraError) -> Self {
        Self::BadCamera(e.to_string())
    }
}
