//! Grids and eyes shared by the unit tests of the orderings.

use glam::{DAffine3, DMat3, DVec3};

use crate::geometry::VolumeGeometry;

/// About two thirds of the ids, scattered: a sparse set of significant voxels.
pub(crate) fn sparse(id: u32) -> bool {
    !id.wrapping_mul(0x9E37_79B9)
        .rotate_left(11)
        .is_multiple_of(3)
}

/// An axis-aligned grid with CT-like spacing (0.7, 0.7, 2.5) and a sheared grid whose axes are
/// neither orthogonal nor of unit length.
pub(crate) fn anisotropic_and_sheared() -> [VolumeGeometry; 2] {
    let axis_aligned =
        VolumeGeometry::axis_aligned([23, 17, 11], [0.7, 0.7, 2.5], [3.0, -2.0, 1.0]).unwrap();
    let sheared = VolumeGeometry::new(
        [13, 9, 15],
        DAffine3::from_mat3_translation(
            DMat3::from_cols(
                DVec3::new(1.0, 0.2, 0.0),
                DVec3::new(0.0, 0.8, 0.3),
                DVec3::new(0.1, 0.0, 2.0),
            ),
            DVec3::new(-4.0, 5.0, 0.5),
        ),
    )
    .unwrap();
    [axis_aligned, sheared]
}

/// The world point at fractions `f` of the grid's size along each axis, in index space.
pub(crate) fn eye_at(geometry: &VolumeGeometry, f: [f64; 3]) -> DVec3 {
    let dims = geometry.dims().map(f64::from);
    geometry.index_to_world_point(DVec3::new(f[0] * dims[0], f[1] * dims[1], f[2] * dims[2]))
}
