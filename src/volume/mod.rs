//! CPU volumes: scalar values on a regular grid, placed in the world.

use glam::{DAffine3, DMat3};

use crate::geometry::{GeometryError, VolumeGeometry};

pub mod dat;
pub mod detect;
pub mod dicom;
#[cfg(feature = "codecs")]
mod jpeg12;
pub mod loader;
pub mod metaimage;
pub mod nifti;
pub mod nrrd;
pub mod phantom;
pub mod raw;
pub mod voxels;
pub mod vtk;

pub use loader::{ByteOrder, ParseScalarError, ScalarFormat, ScalarType, VolumeError};
pub use phantom::{
    ShoulderLandmarks, shoulder_landmarks, shoulder_phantom, shoulder_phantom_default,
};
pub use raw::{RawSpec, load_raw, load_raw_slices, slice_stack};
pub use voxels::{Voxel, Voxels};

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
    /// One value per voxel, id = x + nx * (y + ny * z), in the type they were stored in;
    /// Hounsfield units for CT.
    pub values: Voxels,
}

impl CpuVolume {
    /// The voxel-to-world placement of this volume.
    pub fn geometry(&self) -> Result<VolumeGeometry, GeometryError> {
        if self.spacing.iter().any(|s| !s.is_finite() || *s <= 0.0) {
            return Err(GeometryError::BadSpacing(self.spacing));
        }
        let linear = self.direction * DMat3::from_diagonal(self.spacing.into());
        VolumeGeometry::new(
            self.dims,
            DAffine3::from_mat3_translation(linear, self.origin.into()),
        )
    }

    /// The smallest of the voxel spacings, in millimetres.
    pub fn finest_spacing(&self) -> f64 {
        self.spacing.iter().copied().fold(f64::INFINITY, f64::min)
    }

    /// The trilinear interpolation of the values at index coordinates `p` (voxel centres at
    /// whole numbers), the grid's faces extended outward: a point outside takes the value of
    /// the nearest face. (Written here: the loop is three lerps over the held type, which no
    /// interpolation crate reads.)
    pub fn trilinear(&self, p: [f64; 3]) -> f32 {
        let dims = self.dims.map(|n| n.max(1) as usize);
        let mut lower = [0usize; 3];
        let mut upper = [0usize; 3];
        let mut t = [0.0f32; 3];
        for a in 0..3 {
            let c = p[a].clamp(0.0, (dims[a] - 1) as f64);
            lower[a] = (c.floor() as usize).min(dims[a] - 1);
            upper[a] = (lower[a] + 1).min(dims[a] - 1);
            t[a] = (c - lower[a] as f64) as f32;
        }
        let value = |x: usize, y: usize, z: usize| {
            self.values
                .get(x + dims[0] * (y + dims[1] * z))
                .unwrap_or(0.0)
        };
        let line = |y: usize, z: usize| {
            let a = value(lower[0], y, z);
            a + t[0] * (value(upper[0], y, z) - a)
        };
        let plane = |z: usize| {
            let a = line(lower[1], z);
            a + t[1] * (line(upper[1], z) - a)
        };
        let a = plane(lower[2]);
        a + t[2] * (plane(upper[2]) - a)
    }

    /// The volume at half the resolution along every axis of more than one voxel: each value
    /// the mean of a 2x2x2 block (fewer at an odd end), each voxel at the centre of its whole
    /// block, the spacing doubled. A volume drawn from this has about an eighth of the splats,
    /// each twice as large: a preview for frames while the camera moves.
    pub fn halved(&self) -> CpuVolume {
        let [nx, ny, nz] = self.dims.map(|n| n as usize);
        let step = self.dims.map(|n| if n > 1 { 2usize } else { 1 });
        let out = [0, 1, 2].map(|a| self.dims[a].div_ceil(step[a] as u32));
        let [ox, oy, oz] = out.map(|n| n as usize);
        let mut values = Vec::with_capacity(ox * oy * oz);
        voxels::dispatch!(&self.values, held => {
            for k in 0..oz {
                for j in 0..oy {
                    for i in 0..ox {
                        let (mut sum, mut count) = (0.0f64, 0u32);
                        for z in k * step[2]..((k + 1) * step[2]).min(nz) {
                            for y in j * step[1]..((j + 1) * step[1]).min(ny) {
                                for x in i * step[0]..((i + 1) * step[0]).min(nx) {
                                    sum += f64::from(held[x + nx * (y + ny * z)].to_f32());
                                    count += 1;
                                }
                            }
                        }
                        values.push((sum / f64::from(count)) as f32);
                    }
                }
            }
        });
        let spacing = [0, 1, 2].map(|a| self.spacing[a] * step[a] as f64);
        // The first block's centre: half a fine voxel along each halved axis.
        let shift =
            glam::DVec3::from([0, 1, 2].map(|a| self.spacing[a] * (step[a] as f64 - 1.0) / 2.0));
        let origin = glam::DVec3::from(self.origin) + self.direction * shift;
        CpuVolume {
            dims: out,
            spacing,
            origin: origin.into(),
            direction: self.direction,
            values: values.into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;

    #[test]
    fn halved_averages_blocks_and_keeps_the_volume_in_place() {
        let dims = [5u32, 4, 1];
        let volume = CpuVolume {
            dims,
            spacing: [0.5, 1.0, 2.0],
            origin: [10.0, -3.0, 7.0],
            direction: DMat3::from_rotation_z(0.3),
            values: (0..20).map(|v| v as f32).collect::<Vec<_>>().into(),
        };
        let half = volume.halved();
        assert_eq!(half.dims, [3, 2, 1]);
        assert_eq!(half.spacing, [1.0, 2.0, 2.0]);
        // Block (0, 0): ids 0, 1, 5, 6; block (2, 1): the odd end, ids 14 and 19.
        assert_eq!(half.values.at(0), (1 + 5 + 6) as f32 / 4.0);
        assert_eq!(half.values.at(5), (14 + 19) as f32 / 2.0);
        // A whole block's coarse voxel sits at the mean of its fine voxels' centres.
        let (fine, coarse) = (volume.geometry().unwrap(), half.geometry().unwrap());
        let mean = [0.0, 1.0]
            .iter()
            .flat_map(|&x| [0.0, 1.0].map(|y| fine.index_to_world_point(DVec3::new(x, y, 0.0))))
            .sum::<DVec3>()
            / 4.0;
        let at = coarse.index_to_world_point(DVec3::ZERO);
        assert!(at.distance(mean) < 1e-12, "{at} against {mean}");
    }
}
