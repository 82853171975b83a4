//! Where a voxel grid sits in the world, on the second floor (see ARCHITECTURE.md): the volumes,
//! the orderings, the renderer and picking all stand on it.

use glam::{DAffine3, DMat3, DVec3};
use thiserror::Error;

use crate::grid::{GridError, voxel_count};

/// Why a grid cannot be placed in the world.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum GeometryError {
    /// Spacing must be finite and positive.
    #[error("voxel spacing {0:?} must be finite and positive on every axis")]
    BadSpacing([f64; 3]),
    /// The voxel-to-world transform cannot be inverted.
    #[error("the voxel-to-world transform is not finite and invertible")]
    SingularTransform,
    /// Grid size problems.
    #[error(transparent)]
    Grid(#[from] GridError),
}

/// A voxel grid placed in the world: voxel centres sit at integer index coordinates, and
/// `index_to_world` (orientation x spacing, then the origin, then any node transform) maps them
/// into world space.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VolumeGeometry {
    dims: [u32; 3],
    index_to_world: DAffine3,
    world_to_linear: DMat3,
}

impl VolumeGeometry {
    /// A grid of `dims` voxels placed by `index_to_world`, which must be finite and invertible.
    pub fn new(dims: [u32; 3], index_to_world: DAffine3) -> Result<Self, GeometryError> {
        voxel_count(dims)?;
        let linear = index_to_world.matrix3;
        let det = linear.determinant();
        let finite = linear.is_finite() && index_to_world.translation.is_finite();
        let scale = linear.x_axis.length() * linear.y_axis.length() * linear.z_axis.length();
        if !finite || !det.is_normal() || det.abs() < 1e-12 * scale {
            return Err(GeometryError::SingularTransform);
        }
        Ok(Self {
            dims,
            index_to_world,
            world_to_linear: linear.inverse(),
        })
    }

    /// An axis-aligned grid: voxel `(i, j, k)` sits at `origin + spacing * (i, j, k)`.
    pub fn axis_aligned(
        dims: [u32; 3],
        spacing: [f64; 3],
        origin: [f64; 3],
    ) -> Result<Self, GeometryError> {
        if spacing.iter().any(|s| !s.is_finite() || *s <= 0.0) {
            return Err(GeometryError::BadSpacing(spacing));
        }
        Self::new(
            dims,
            DAffine3::from_mat3_translation(DMat3::from_diagonal(spacing.into()), origin.into()),
        )
    }

    /// Grid size in voxels.
    pub fn dims(&self) -> [u32; 3] {
        self.dims
    }

    /// The voxel-to-world transform.
    pub fn index_to_world(&self) -> DAffine3 {
        self.index_to_world
    }

    /// A world point in index coordinates. The origin is subtracted before the inverse is
    /// applied, so a volume far from the world origin keeps full precision near itself.
    pub fn world_to_index(&self, world: DVec3) -> DVec3 {
        self.world_to_linear * (world - self.index_to_world.translation)
    }

    /// A world direction in index coordinates.
    pub fn world_dir_to_index(&self, dir: DVec3) -> DVec3 {
        self.world_to_linear * dir
    }

    /// World position of index coordinates.
    pub fn index_to_world_point(&self, index: DVec3) -> DVec3 {
        self.index_to_world.transform_point3(index)
    }

    /// Length in world units of one voxel step along each axis.
    pub fn spacing(&self) -> [f64; 3] {
        let m = self.index_to_world.matrix3;
        [m.x_axis.length(), m.y_axis.length(), m.z_axis.length()]
    }

    /// Centre of the grid in world space.
    pub fn centre_world(&self) -> DVec3 {
        let c = DVec3::from(self.dims.map(|n| (f64::from(n) - 1.0) / 2.0));
        self.index_to_world_point(c)
    }
}
