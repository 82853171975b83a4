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
    /// the mean of a 2x2x2 block (fewer at an odd end), held in the volume's own type (rounded
    /// to the nearest for integers), each voxel at the centre of its whole block, the spacing
    /// doubled. A volume drawn from this has about an eighth of the splats, each twice as
    /// large, and classifies eight times faster: the renderer's previews of a large volume
    /// whose transfer function has just changed are drawn from it. Blocks of output z-slices
    /// on every core; no temporary larger than a slice's sums.
    pub fn halved(&self) -> CpuVolume {
        match self.halved_unless_cancelled(None) {
            Some(volume) => volume,
            None => unreachable!("a halving with no cancel flag is never given up"),
        }
    }

    /// [`CpuVolume::halved`], given up (`None`, nothing kept) once `cancel` is raised: looked
    /// at before each output z-slice. (A viewer's first preview of a thin-slice CT windowed
    /// anew makes this copy, 100-250 ms of both cores, and a drag meanwhile wants them.)
    pub fn halved_unless_cancelled(
        &self,
        cancel: Option<&std::sync::atomic::AtomicBool>,
    ) -> Option<CpuVolume> {
        let step = self.dims.map(|n| if n > 1 { 2usize } else { 1 });
        let out = [0, 1, 2].map(|a| self.dims[a].div_ceil(step[a] as u32));
        let values = voxels::dispatch!(&self.values, held => {
            Voxels::from(halve(held, self.dims.map(|n| n as usize), step, cancel)?)
        });
        let spacing = [0, 1, 2].map(|a| self.spacing[a] * step[a] as f64);
        // The first block's centre: half a fine voxel along each halved axis.
        let shift =
            glam::DVec3::from([0, 1, 2].map(|a| self.spacing[a] * (step[a] as f64 - 1.0) / 2.0));
        let origin = glam::DVec3::from(self.origin) + self.direction * shift;
        Some(CpuVolume {
            dims: out,
            spacing,
            origin: origin.into(),
            direction: self.direction,
            values,
        })
    }
}

/// The means of the `step[0] x step[1] x step[2]` blocks of `held`, a grid of `dims` (the
/// blocks at an odd end hold fewer voxels; each step 1 or 2), output z-slice by z-slice on
/// every core. Sums of at most 8 values are taken in `f32`, exact for the integer types.
/// `None` once `cancel` is raised, looked at before each output slice. (Written here: a box
/// filter over a stored type, which the image crates do in 2-D and over their own pixel
/// types.)
fn halve<T: Voxel>(
    held: &[T],
    [nx, ny, nz]: [usize; 3],
    step: [usize; 3],
    cancel: Option<&std::sync::atomic::AtomicBool>,
) -> Option<Vec<T>> {
    use rayon::prelude::*;
    let parts = crate::cancel::Parts::new(cancel);
    let [ox, oy, oz] = [
        nx.div_ceil(step[0]),
        ny.div_ceil(step[1]),
        nz.div_ceil(step[2]),
    ];
    let mut out = vec![T::nearest(0.0); ox * oy * oz];
    if out.is_empty() || held.len() < nx * ny * nz {
        return Some(out);
    }
    out.par_chunks_mut(ox * oy).enumerate().for_each_init(
        Vec::new,
        |sums: &mut Vec<f32>, (k, slice)| {
            // What a cancelled halving made is dropped whole below.
            if parts.skip() {
                return;
            }
            sums.clear();
            sums.resize(ox * oy, 0.0);
            let zs = k * step[2]..((k + 1) * step[2]).min(nz);
            let depth = zs.len();
            for z in zs {
                for y in 0..ny {
                    let row = &held[nx * (y + ny * z)..][..nx];
                    let into = &mut sums[ox * (y / step[1])..][..ox];
                    if step[0] == 2 {
                        let pairs = row.chunks_exact(2);
                        let odd = pairs.remainder().first().map(|v| v.to_f32());
                        for (sum, pair) in into.iter_mut().zip(pairs) {
                            *sum += pair[0].to_f32() + pair[1].to_f32();
                        }
                        if let (Some(v), Some(last)) = (odd, into.last_mut()) {
                            *last += v;
                        }
                    } else {
                        for (sum, v) in into.iter_mut().zip(row) {
                            *sum += v.to_f32();
                        }
                    }
                }
            }
            for (j, (value, sum)) in slice.iter_mut().zip(sums.iter()).enumerate() {
                let (i, j) = (j % ox, j / ox);
                let width = ((i + 1) * step[0]).min(nx) - i * step[0];
                let height = ((j + 1) * step[1]).min(ny) - j * step[1];
                *value = T::nearest(f64::from(*sum) / (width * height * depth) as f64);
            }
        },
    );
    parts.whole(out)
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

    #[test]
    fn a_halving_under_a_raised_flag_is_given_up_and_a_lowered_one_changes_nothing() {
        let dims = [9u32, 6, 7];
        let values: Vec<u16> = (0..dims.iter().product::<u32>())
            .map(|i| (i * 97 % 1000) as u16)
            .collect();
        let volume = CpuVolume {
            dims,
            spacing: [0.5, 0.7, 1.1],
            origin: [3.0, -2.0, 1.0],
            direction: glam::DMat3::IDENTITY,
            values: values.into(),
        };
        let raised = std::sync::atomic::AtomicBool::new(true);
        let lowered = std::sync::atomic::AtomicBool::new(false);
        assert!(volume.halved_unless_cancelled(Some(&raised)).is_none());
        let plain = volume.halved();
        let under_lowered = volume.halved_unless_cancelled(Some(&lowered)).unwrap();
        assert_eq!(plain.dims, [5, 3, 4]);
        assert_eq!(under_lowered.dims, plain.dims);
        assert_eq!(under_lowered.origin, plain.origin);
        assert_eq!(under_lowered.spacing, plain.spacing);
        assert!((0..5 * 3 * 4).all(|i| under_lowered.values.get(i) == plain.values.get(i)));
    }

    #[test]
    fn halved_integers_keep_their_type_and_round_each_blocks_mean() {
        // 3 x 3 x 3 bytes, value x + 3 y + 9 z with (2, 2, 2) at 255: the odd ends' blocks hold
        // 4, 2 and 1 voxels.
        let mut bytes: Vec<u8> = (0..27u8).collect();
        bytes[26] = 255;
        let volume = CpuVolume {
            dims: [3, 3, 3],
            spacing: [1.0; 3],
            origin: [0.0; 3],
            direction: DMat3::IDENTITY,
            values: Voxels::U8(bytes.clone()),
        };
        let half = volume.halved();
        let Voxels::U8(held) = &half.values else {
            panic!("held as {:?}", half.values.scalar_type());
        };
        assert_eq!(half.dims, [2, 2, 2]);
        let value = |x: usize, y: usize, z: usize| f64::from(bytes[x + 3 * y + 9 * z]);
        for (i, &got) in held.iter().enumerate() {
            let [bx, by, bz] = [i % 2, (i / 2) % 2, i / 4];
            let block = |b: usize| (2 * b..(2 * b + 2).min(3)).collect::<Vec<_>>();
            let mut all = Vec::new();
            for z in block(bz) {
                for y in block(by) {
                    for x in block(bx) {
                        all.push(value(x, y, z));
                    }
                }
            }
            let mean = all.iter().sum::<f64>() / all.len() as f64;
            assert_eq!(f64::from(got), mean.round(), "block {i}: {all:?}");
        }
        assert_eq!(held[7], 255);
    }
}
