//! Level of detail: how finely each volume is drawn in a view, from how many pixels apart its
//! voxels fall (a coarser level of its pyramid, its own grid, or its grid refined).

use super::*;

/// Fine voxel indices to coarse ones for a grid `factors` times finer ([`classify_refined`]):
/// fine voxel `j` of coarse voxel `k` sits at `k - 1/2 + (j + 1/2) / f`.
pub(super) fn refinement(factors: [u32; 3]) -> DMat4 {
    let f = DVec3::from(factors.map(|f| f64::from(f.max(1))));
    DMat4::from_scale_rotation_translation(
        f.recip(),
        glam::DQuat::IDENTITY,
        0.5 * f.recip() - DVec3::splat(0.5),
    )
}

/// How finely a volume is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Detail {
    /// Level `n` of its pyramid, 2^n x 2^n x 2^n voxels a splat ([`Classified::halved`]); 0 is
    /// the volume's own grid.
    Level(u8),
    /// Its trilinear field classified on a grid `factors[a]` times finer along each axis `a`
    /// ([`classify_refined`]), for a grid whose voxels are more than [`REFINE_TO`] pixels
    /// apart.
    Refined([u32; 3]),
}

impl Default for Detail {
    fn default() -> Self {
        Detail::Level(0)
    }
}

/// The most levels of detail above a volume's own grid (a splat for 8^4 = 4,096 voxels).
pub const MAX_LEVEL: u8 = 4;

/// A grid whose voxels are more than this many pixels apart along an axis is refined along
/// it until they are at most this far apart ([`detail_for`]).
pub const REFINE_TO: f64 = 1.5;

/// A level of detail is drawn where its voxels are at most this many pixels apart where the
/// volume's content comes nearest the eye ([`detail_for`]). 1.5, as for refinement, was
/// measured and not kept: the LIDC2 CT resampled to 0.7 mm, seen from the front at 384 x 384,
/// went from level 0 to level 1 and from RMSE 0.027-0.028 to 0.038 against the reference ray
/// marcher (soft tissue and bone), though a 512^3 textured ball at 512 x 512 drawn at level 1
/// stayed within 0.025 of it (0.018 at level 0) for a sixth of the frame.
pub(super) const COARSEN_TO: f64 = 1.0;

/// The most a grid is refined along one axis ([`Detail::Refined`]).
pub const MAX_REFINE: u32 = 8;

/// The most voxels a refined grid has (2^28, a 645^3 grid; the LIDC2 CT's 256 x 256 x 133
/// grid refined 2 x 2 x 3 at 512 x 512 has 105M): past it the factors are lowered, largest
/// first.
pub const MAX_REFINED_VOXELS: u64 = 1 << 28;

/// The most voxels a refined grid has along an axis (the 3D texture size GPUs take).
pub(super) const MAX_REFINED_DIM: u64 = 2048;

/// The detail a volume placed as `geometry` is drawn at in `view`, from how many pixels apart
/// its voxels are along each axis where the volume comes nearest the eye (its grid's box, half
/// a voxel beyond the centres; the renderer takes the 16^3-voxel bricks that hold its splats
/// instead):
///
/// - Where they are more than [`REFINE_TO`] (1.5) pixels apart along some axis, its own grid
///   refined along each such axis until they are at most that far apart ([`Detail::Refined`],
///   at most [`MAX_REFINE`] times an axis and [`MAX_REFINED_VOXELS`] in all): splats a coarse
///   voxel wide are far softer than the trilinear field a ray caster samples. On the LIDC2
///   CT's 1.4 x 1.4 x 2.5 mm grid at 512 x 512 (voxels 2.2 and 3.9 pixels apart) refining it
///   2 x 2 x 3 brings the picture to 0.029-0.031 of the reference ray marcher, from
///   0.049-0.053, and to 0.015-0.017 of the 0.7 mm grid's; refining to a pixel (2 x 2 x 4)
///   gained 0.001 for 16-26% more frame time, and three times the classification on the
///   built-in scene (BENCHMARKS.md, "Grids coarser than the pixels").
/// - Else the coarsest level of its pyramid whose voxels are still at most a pixel apart, so
///   that the picture keeps the detail the pixels can show there while a grid two or more times
///   finer than the pixels does not put four or more splats under each. (A level one coarser,
///   with voxels up to two pixels apart, was measured on the LIDC2 CT resampled to 0.7 mm at
///   512 x 512: 3.4 times faster, but RMSE 0.037 against the reference ray marcher where the
///   full grid gives 0.024.)
///
/// The volume's own grid when the eye is inside the box.
pub fn detail_for(geometry: &VolumeGeometry, view: &ViewSetup) -> Detail {
    detail_at(geometry.dims(), pixels_apart(geometry, view))
}

/// [`detail_for`] a `dims` grid whose voxels are `apart` pixels apart along each axis where it
/// comes nearest the eye (`None`: the eye inside it).
pub(super) fn detail_at(dims: [u32; 3], apart: Option<[f64; 3]>) -> Detail {
    let Some(apart) = apart else {
        return Detail::Level(0);
    };
    if let Some(factors) = refine_factors(dims, apart) {
        return Detail::Refined(factors);
    }
    // Coarser while the next level's voxels are still at most a pixel apart.
    let mut apart = apart.into_iter().fold(f64::INFINITY, f64::min);
    let mut level = 0;
    while level < MAX_LEVEL && apart.is_finite() && apart > 0.0 && 2.0 * apart <= COARSEN_TO {
        apart *= 2.0;
        level += 1;
    }
    Detail::Level(level)
}

/// Side, in voxels, of the bricks whose occupancy tells where a volume's content comes
/// nearest the eye ([`Occupied`]).
pub(super) const BRICK: u32 = 16;

/// The bricks of [`BRICK`]^3 voxels of a classified grid that hold at least one splat: where a
/// volume's content lies, so that the level of detail goes by the nearest content rather
/// than by the nearest corner of a box that may hold only air (a CT's field of view around
/// the patient, a ball in its cube).
#[derive(Debug, Clone, Default)]
pub(super) struct Occupied {
    /// Brick coordinates (voxel index / [`BRICK`]).
    bricks: Vec<[u32; 3]>,
}

impl Occupied {
    /// The occupied bricks of `classified`'s grid, from its rows.
    pub(super) fn of(classified: &Classified) -> Self {
        let grid = &classified.grid;
        let [nx, ny, nz] = grid.dims();
        let [bx, by, bz] = [nx, ny, nz].map(|n| n.div_ceil(BRICK));
        let mut marked = vec![false; bx as usize * by as usize * bz as usize];
        for z in 0..nz {
            for y in 0..ny {
                let row = (y / BRICK + by * (z / BRICK)) as usize * bx as usize;
                for run in grid.row(0, y, z) {
                    if run.end() > run.start {
                        for x in run.start / BRICK..=(run.end() - 1) / BRICK {
                            marked[row + x as usize] = true;
                        }
                    }
                }
            }
        }
        let bricks = marked
            .iter()
            .enumerate()
            .filter(|(_, m)| **m)
            .map(|(i, _)| {
                let i = i as u32;
                [i % bx, i / bx % by, i / bx / by]
            })
            .collect();
        Self { bricks }
    }

    /// The distance from `eye` to the nearest point of the occupied bricks' world boxes (each
    /// brick's voxels' box, half a voxel beyond their centres, as a world axis-aligned box)
    /// for a grid placed as `geometry`; 0 when the eye is in one, `None` when none is
    /// occupied.
    pub(super) fn nearest(&self, geometry: &VolumeGeometry, eye: DVec3) -> Option<f64> {
        let to_world = geometry.index_to_world();
        let m = to_world.matrix3;
        let dims = geometry.dims();
        let abs = glam::DMat3::from_cols(m.x_axis.abs(), m.y_axis.abs(), m.z_axis.abs());
        self.bricks
            .iter()
            .map(|b| {
                let lo = DVec3::from(std::array::from_fn::<f64, 3, _>(|a| {
                    f64::from(b[a] * BRICK) - 0.5
                }));
                let hi = DVec3::from(std::array::from_fn::<f64, 3, _>(|a| {
                    f64::from(((b[a] + 1) * BRICK).min(dims[a])) - 0.5
                }));
                let centre = to_world.transform_point3(0.5 * (lo + hi));
                let half = abs * (0.5 * (hi - lo));
                (eye.clamp(centre - half, centre + half) - eye).length()
            })
            .min_by(f64::total_cmp)
    }
}

/// How many pixels apart the voxels of a grid placed as `geometry` are along each of its axes
/// where it comes nearest the eye in `view`; `None` when the eye is inside its box.
pub fn pixels_apart(geometry: &VolumeGeometry, view: &ViewSetup) -> Option<[f64; 3]> {
    pixels_apart_near(geometry, view, None)
}

/// [`pixels_apart`] where the grid's content comes nearest, where its `occupied` bricks are
/// known (the volume's own grid), else where its box does.
pub(super) fn pixels_apart_near(
    geometry: &VolumeGeometry,
    view: &ViewSetup,
    occupied: Option<&Occupied>,
) -> Option<[f64; 3]> {
    // The world size of a pixel where the volume comes nearest.
    let pixel = if view.is_orthographic() {
        1.0 / view.focal
    } else if let Some(nearest) = occupied.and_then(|o| o.nearest(geometry, view.camera.eye)) {
        if nearest <= 0.0 {
            return None;
        }
        nearest / view.focal
    } else {
        let dims = geometry.dims().map(|n| f64::from(n) - 0.5);
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for corner in 0..8 {
            let c = DVec3::from(std::array::from_fn::<f64, 3, _>(|a| {
                if corner >> a & 1 == 1 { dims[a] } else { -0.5 }
            }));
            let p = geometry.index_to_world_point(c);
            lo = lo.min(p);
            hi = hi.max(p);
        }
        let eye = view.camera.eye;
        let nearest = (eye.clamp(lo, hi) - eye).length();
        if nearest <= 0.0 {
            return None;
        }
        nearest / view.focal
    };
    (pixel.is_finite() && pixel > 0.0).then(|| geometry.spacing().map(|s| s / pixel))
}

/// The factors a `dims` grid whose voxels are `apart` pixels apart along each axis is refined
/// by (see [`detail_for`]); `None` where no axis is.
pub(super) fn refine_factors(dims: [u32; 3], apart: [f64; 3]) -> Option<[u32; 3]> {
    let mut factors = [0, 1, 2].map(|a| {
        let wanted = if apart[a].is_finite() {
            (apart[a] / REFINE_TO).ceil()
        } else {
            1.0
        };
        let most = (MAX_REFINED_DIM / u64::from(dims[a].max(1))).max(1) as f64;
        wanted.clamp(1.0, f64::from(MAX_REFINE).min(most)) as u32
    });
    let count = |f: &[u32; 3]| {
        (0..3)
            .map(|a| u64::from(dims[a]) * u64::from(f[a]))
            .product::<u64>()
    };
    while count(&factors) > MAX_REFINED_VOXELS.max(count(&[1; 3])) {
        let a = (0..3).max_by_key(|&a| factors[a]).unwrap_or(0);
        if factors[a] == 1 {
            break;
        }
        factors[a] -= 1;
    }
    (factors != [1; 3]).then_some(factors)
}
