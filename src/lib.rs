//! splatscene: shoulder-prosthesis planning scenes, with CT volumes drawn as one splat per
//! significant voxel in the IP-PBTF visibility order (Botha & Post 2005).
//!
//! The GPU-free core (ARCHITECTURE.md gives the floors the modules stand on):
//! - [`grid`]: sparse sets of significant voxels with run-length rows (space skipping);
//! - [`geometry`], [`measure`]: where a grid sits in the world; measurements as values;
//! - [`order`]: the view case and every visibility ordering (BTF, WBTF, PBTF, IP-PBTF explicit
//!   and implicit, the exact sort, and a bucketed distance order);
//! - [`splat`]: the splats' shared footprint, the reference compositor (the oracle and the
//!   error measure) and the CPU tile compositor (the fast one);
//! - [`volume`], [`classify`]: CT volumes, loaders, the built-in phantom, transfer functions;
//! - [`mesh`]: triangle meshes with glTF, OBJ and STL loaders, and the prosthesis generator;
//! - [`scene`]: the scene graph, camera, lights, scene files and the built-in shoulder scene.
//!
//! [`slice`](mod@slice) reformats the volume on a plane with the meshes' cross-sections, for judging an
//! implant's fit. On top, [`render`]: a wgpu renderer (headless by default) that draws the meshes with a depth
//! buffer, then the splats in visibility order, depth-tested against them.
//!
//! ```
//! use splatscene::grid::SparseGrid;
//! use splatscene::order::{order, OrderOptions, Ordering, ViewCase, VolumeGeometry};
//! use glam::DVec3;
//!
//! let geometry = VolumeGeometry::axis_aligned([16, 16, 8], [0.7, 0.7, 2.5], [0.0; 3])?;
//! let grid = SparseGrid::dense(geometry.dims())?;
//! let eye = DVec3::new(5.0, 40.0, 9.0);
//! let view = ViewCase::new(&geometry, eye, geometry.centre_world())?;
//! let ids = order(&grid, &view, Ordering::IpPbtfImplicit, &OrderOptions::default())?;
//! assert_eq!(ids.len(), 16 * 16 * 8);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#[cfg(feature = "annotate")]
pub mod annotate;
pub mod budget;
pub mod camera;
pub mod cancel;
pub mod classify;
#[cfg(feature = "annotate")]
pub mod figure;
pub mod geometry;
pub mod grid;
pub mod input;
pub mod measure;
pub mod mesh;
pub mod order;
pub mod output;
pub mod pick;
pub mod render;
#[cfg(feature = "report")]
pub mod report;
pub mod scene;
#[cfg(test)]
mod scratch;
pub mod simd;
pub mod slice;
pub mod splat;
#[cfg(feature = "viewer")]
pub mod viewer;
pub mod volume;
