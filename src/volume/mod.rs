//! CPU volumes: scalar values on a regular grid, placed in the world.

use glam::{DAffine3, DMat3};

use crate::order::{OrderError, VolumeGeometry};

pub mod dat;
pub mod detect;
pub mod dicom;
pub mod nifti;
pub mod nrrd;
pub mod phantom;
pub mod raw;
pub mod vtk;

pub use phantom::{
    ShoulderLandmarks, shoulder_landmarks, shoulder_phantom, shoulder_phantom_default,
};
pub use raw::{
    ByteOrder, ParseScalarError, RawSpec, ScalarFormat, ScalarType, VolumeError, load_raw,
    load_raw_slices, slice_stack,
};

/// Scalar values on an `nx x ny x nz` grid (x fastest), with their placement in the world:
/// voxel `k` sits at `origin + direction * (spacing * k)`.
#[derive(Debug, Clone, PartialEq)]
pub struct CpuVolume {
    /// Voxels along x, y and z.
    pub dims: [u32; 3],
    /// Distance between voxel centres along each axis, in millimetres.
    pub spacing: [f64; 3],
    /// World position of voxel (0, 0, 0).
    pub origin: [f64; 3],
    /// Orientation of the grid axes (columns are unit axis directions).
    pub direction: DMat3,
    /// One value per voxel, id = x + nx * (y + ny * z); Hounsfield units for CT.
    pub values: Vec<f32>,
}

impl CpuVolume {
    /// The voxel-to-world placement of this volume.
    pub fn geometry(&self) -> Result<VolumeGeometry, OrderError> {
        if self.spacing.iter().any(|s| !s.is_finite() || *s <= 0.0) {
            return Err(OrderError::BadSpacing(self.spacing));
        }
        let linear = self.direction * DMat3::from_diagonal(self.spacing.into());
        VolumeGeometry::new(
            self.dims,
            DAffine3::from_mat3_translation(linear, self.origin.into()),
        )
    }
}
