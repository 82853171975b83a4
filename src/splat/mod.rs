//! Splatting: a volume's significant voxels drawn as Gaussian splats in a visibility order.
//!
//! Three compositors draw the same splats, and one footprint is the mathematics they share:
//!
//! - [`footprint`]: a splat's ellipse on the screen (EWA projection with the pixel variance
//!   added, and the share of opacity that keeps its integral), generic over the float type and
//!   mirrored by `shaders/footprint.wgsl`.
//! - [`reference`](mod@reference): the reference compositor, in f64, a plain loop over every splat and pixel,
//!   "over" in draw order. It is slow on purpose: it is the oracle the tests and the orderings'
//!   error measure compare against, and it keeps the fragment order it saw.
//! - [`tiled`]: the tile compositor, the fast one on the CPU: project, bin into 16x16-pixel
//!   tiles, composite each tile front to back with early termination, with the GPU splat pass's
//!   8-bit texels, shading and depth test. One file a stage.
//!
//! The GPU's splat pass (`render::splat_pass`, `shaders/splat.wgsl`) is the third.

pub mod footprint;
pub mod reference;
pub mod tiled;

pub use reference::{Frame, ImageDifference, SplatStyle, check_frame_size, compare};
