//! Level of detail: how finely each volume is drawn in a view, from how many pixels apart its
//! voxels fall (a coarser level of its pyramid, its own grid, or its grid refined).

use rayon::prelude::*;

use super::*;

/// Fine voxel indices to coarse ones for a grid `factors` times finer
/// ([`crate::classify::classify_refined`]): fine voxel `j` of coarse voxel `k` sits at
/// `k - 1/2 + (j + 1/2) / f`.
pub(super) fn refinement(factors: [u32; 3]) -> DMat4 {
    let f = DVec3::from(factors.map(|f| f64::from(f.max(1))));
    DMat4::from_scale_rotation_translation(
        f.recip(),
        glam::DQuat::IDENTITY,
        0.5 * f.recip() - DVec3::splat(0.5),
    )
}

/// Fine voxel indices of a grid to those of the grid halved `levels[a]` times along each axis
/// `a` (inverse of [`coarsening`]'s map, which takes coarse indices to fine ones).
///
/// Coarse voxel `k` of a grid halved `l` times along an axis sits at the centre of its block
/// of `s = 2^l` fine voxels: `k s + (s - 1) / 2`, whatever the order of the halvings.
pub(super) fn coarsening(levels: [u8; 3]) -> DMat4 {
    let s = DVec3::from(levels.map(|l| f64::from(1u32 << l.min(31))));
    DMat4::from_scale_rotation_translation(s, glam::DQuat::IDENTITY, 0.5 * (s - DVec3::ONE))
}

/// How finely a volume is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Detail {
    /// Its grid halved `n[a]` times along each axis `a`, `2^n[a]` voxels a splat along it
    /// ([`Classified::halved_along`]); `[0, 0, 0]` is the volume's own grid. Levels differ
    /// between axes where the voxels fall nearer together on the screen along one axis than
    /// along another: most along the view direction, whose voxels lie on top of each other.
    /// The second array tells, for the axis halved more than both others where one is, which
    /// of its ends faces the eye (1: the larger indices, -1: the smaller; 0 for the other
    /// axes): a ray meets the voxels of each pair along it in that order
    /// ([`crate::classify::Front`]).
    Level([u8; 3], [i8; 3]),
    /// Its trilinear field classified on a grid `factors[a]` times finer along each axis `a`
    /// ([`crate::classify::classify_refined`]), for a grid whose voxels are more than
    /// [`REFINE_TO`] pixels apart.
    Refined([u32; 3]),
}

impl Default for Detail {
    fn default() -> Self {
        Detail::Level([0; 3], [0; 3])
    }
}

/// The most levels of detail above a volume's own grid along an axis (a splat for 16 voxels
/// along it).
pub const MAX_LEVEL: u8 = 4;

/// A grid whose voxels are more than this many pixels apart along an axis is refined along
/// it until they are at most this far apart ([`detail_for`]).
pub const REFINE_TO: f64 = 1.5;

/// A level of detail is drawn along an axis where its voxels are at most this many pixels
/// apart on the screen, where the volume's content is drawn largest ([`detail_for`]). 1.5,
/// as for refinement, was measured and not kept: the LIDC2 CT resampled to 0.7 mm, seen from
/// the front at 384 x 384, went from level 0 to level 1 and from RMSE 0.027-0.028 to 0.038
/// against the reference ray marcher (soft tissue and bone), though a 512^3 textured ball at
/// 512 x 512 drawn at level 1 stayed within 0.025 of it (0.018 at level 0) for a sixth of
/// the frame. Measured again once levels halved across the view kept their shading, 1.4 drew
/// the ball and LIDC2's turning path 1.5-3.5 times faster, but the CT head at 160 x 160 (1 mm,
/// oblique, bone) went from 0.032 to 0.039 against the marcher (BENCHMARKS.md, "Levels halved
/// across the view").
pub(super) const COARSEN_TO: f64 = 1.0;

/// A brick whose content is smooth ([`SMOOTH_SPREAD`]) is drawn at the level whose voxels
/// are at most this many pixels apart, one level coarser than [`COARSEN_TO`] allows
/// ([`brick_details`]). What a level loses goes by the content as much as by the spacing:
/// on the Stanford CT head resampled to 0.5 mm, drawn with its voxels 1.3 pixels apart, the
/// picture stayed within 0.017-0.024 of the reference ray marcher, where the LIDC2 CT's
/// 0.7 mm grid, its edges kept sharp, went to 0.043 (BENCHMARKS.md, "A second CT").
pub(super) const SMOOTH_COARSEN_TO: f64 = 2.0;

/// The most a brick's splats may lose on average to be drawn at the coarser level
/// [`SMOOTH_COARSEN_TO`] allows: the mean, over the splats of the brick halved across the
/// view, of the squared spread of their blocks' premultiplied colours about the block's
/// mean ([`crate::classify::Classified::halved_measured`], each voxel's opacity that of its
/// own length of tissue), square-rooted. Soft tissue against the reference ray marcher, from
/// no brick drawn coarser to 0.01, 0.015 and 0.02: the 0.5 mm CT head seen obliquely at 512
/// x 512 0.0096, 0.0140, 0.0150, 0.0159 (28.3M, 9.9M, 5.8M and 4.2M splats); the 0.7 mm
/// LIDC2 CT turned 45 degrees 0.0210, 0.0210, 0.0246, 0.0259, and from the front at 384 x
/// 384 0.0280, 0.0280, 0.0296, 0.0307, past the 0.03 this project holds a picture to
/// (BENCHMARKS.md, "Smooth bricks a level coarser").
pub(super) const SMOOTH_SPREAD: f64 = 0.015;

/// The most levels an axis is halved beyond the axis halved least ([`detail_for`]). An axis
/// along the view direction has its voxels on top of each other on the screen and would be
/// halved [`MAX_LEVEL`] times by the pixels alone; each splat would then carry the emission
/// of 16 voxels in depth as one, losing which of them lies in front.
pub const MAX_DEPTH_LEVELS: u8 = 1;

/// The most a grid is refined along one axis ([`Detail::Refined`]).
pub const MAX_REFINE: u32 = 8;

/// The most fine voxels a refinement is classified in (2^28, a 645^3 grid; the LIDC2 CT's
/// 256 x 256 x 133 grid refined 2 x 1 x 3 at 512 x 512 has 52M): past it the factors are
/// lowered, largest first. Where a refinement is classified within the bricks on the image
/// ([`Renderer::set_refinement_on_image_only`]), it may instead count the fine
/// voxels of the own grid's occupied bricks on the image alone, its splats then bounded by
/// the pixels (64 a pixel), where that refines further: so that a close-up of a thin-slice CT
/// is refined as its thick-slice original is.
pub const MAX_REFINED_VOXELS: u64 = 1 << 28;

/// The most voxels a refined grid spans in all, classified or not (2^31). What spans the
/// whole refined grid is its tables' indexes (the significance bitmap's and the texels' page
/// tables, the marks of the texels' normals, the rows' offsets): about 1/60 of a byte a fine
/// voxel, some 36 MiB at 2^31; the bitmap and the texels are held only where a voxel is
/// significant. (Before they were held by pages, the bitmap's ranks and the texels' bricks
/// took 7/16 of a byte a fine voxel, and set this cap.) The LIDC2 CT resampled to 0.7 mm
/// (512 x 512 x 532) refined 2 x 2 x 3 spans 1.67G.
pub(super) const MAX_REFINED_GRID: u64 = 1 << 31;

/// The most splats a refinement counted by the bricks on the image may hold, a pixel of the
/// picture (the own grid's splats on the image times the factors' product,
/// [`most_refined_splats`]): so that a close-up's cost follows its pixels, not its voxels. Measured on the LIDC2 CT's 1.4 x
/// 1.4 x 2.5 mm grid and its 0.7 mm resampling at 512 x 512 close up (BENCHMARKS.md, "A
/// close-up refined by the bricks on the image"): a bound of 64 kept the thick grid as near
/// its ray marcher as no bound did (0.015; refined 5 x 4 x 4, not 6 x 6 x 5) in half the time
/// and memory, and brought the thin grid from 0.022 unrefined to 0.014 (0.011 with no bound,
/// at twice the time). The bound is on the splats of the bricks on the image, hidden or not,
/// so a view that hides most of them (the aorta CT's opaque close-up) keeps the factors the
/// whole grid's cap gives it ([`refine_factors`]).
pub(super) const MAX_REFINED_SPLATS_PER_PIXEL: u64 = 64;

/// The splats a refinement may hold however small the picture ([`most_refined_splats`]): a
/// 256 x 256 picture's 64 a pixel.
pub(super) const MIN_REFINED_SPLATS: u64 = 1 << 22;

/// The most splats a refinement drawn into a picture of `size` may hold
/// ([`MAX_REFINED_SPLATS_PER_PIXEL`], at least [`MIN_REFINED_SPLATS`]).
pub(super) fn most_refined_splats(size: (u32, u32)) -> u64 {
    (u64::from(size.0) * u64::from(size.1))
        .saturating_mul(MAX_REFINED_SPLATS_PER_PIXEL)
        .max(MIN_REFINED_SPLATS)
}

/// The most voxels a refined grid has along an axis (the side of the 3-D textures the GPU
/// passes once held a grid in; kept so that the compositors refine alike).
pub(super) const MAX_REFINED_DIM: u64 = 2048;

/// The detail a volume placed as `geometry` is drawn at in `view`, from how many pixels apart
/// its voxels fall on the screen along each of its axes where the volume is drawn largest
/// ([`pixels_apart`]: the voxel's edge along the axis projected across the line of sight,
/// so an axis along the view direction has its voxels nearly on top of each other):
///
/// - Where a voxel's edge along some axis spans more than [`REFINE_TO`] (1.5) pixels at that
///   distance (whether it lies across the view or along it), its own grid refined along each
///   such axis until they span at most that ([`Detail::Refined`], at most [`MAX_REFINE`]
///   times an axis and [`MAX_REFINED_VOXELS`] over the whole grid, or counted in the occupied
///   bricks on the image alone, the splats bounded by the pixels): splats a coarse voxel wide are far softer than the trilinear field a ray
///   caster samples. On the LIDC2 CT's 1.4 x 1.4 x 2.5
///   mm grid at 512 x 512 (voxels 2.2 and 3.9 pixels apart) refining it 2 x 2 x 3 brought the
///   picture to 0.029-0.031 of the reference ray marcher, from 0.049-0.053 (BENCHMARKS.md,
///   "Grids coarser than the pixels"). The axis along the view is refined too: one splat
///   for a coarse voxel's depth takes the mean of its field's colours and gradients where a
///   ray composites them one after the other (refined 2 x 1 x 3 the same view was 0.036-0.037
///   from the marcher).
/// - Else, along each axis, the coarsest level of its pyramid whose voxels are still at most
///   a pixel apart there, and at most [`MAX_DEPTH_LEVELS`] more than along
///   the axis halved least, so that the picture keeps the detail the pixels can show while a
///   grid finer than the pixels does not put several splats under each. (A level one
///   coarser across the view, with voxels up to two pixels apart, was measured on the LIDC2 CT
///   resampled to 0.7 mm at 512 x 512: 3.4 times faster, but RMSE 0.037 against the reference
///   ray marcher where the full grid gives 0.024.)
///
/// With the eye inside the box (or nearer it than splats are drawn), the grid's voxels may lie
/// as near the eye as the splats' near cut ([`ViewSetup::splat_near`]), so it is refined as far
/// as [`MAX_REFINE`] and [`MAX_REFINED_VOXELS`] allow: drawn from its own grid there, its splats
/// a few millimetres from the eye span hundreds of pixels and blur the image into one tone
/// (RMSE 0.19 against the reference marcher on a view from inside a CT's lung, BENCHMARKS.md,
/// "The eye inside the volume").
pub fn detail_for(geometry: &VolumeGeometry, view: &ViewSetup) -> Detail {
    detail_at(
        geometry.dims(),
        apart_near(geometry, view, None),
        Within::WHOLE,
    )
}

/// [`detail_for`] a `dims` grid whose voxels are `apart` pixels apart on the screen along
/// each axis where it is drawn largest, facing the eye as `apart` says. Where `apart` is not
/// known (`None`), the own grid.
/// A refinement is classified `within` ([`refine_factors`]).
pub(super) fn detail_at(dims: [u32; 3], apart: Option<Apart>, within: Within) -> Detail {
    detail_within(dims, apart, within, COARSEN_TO)
}

/// [`detail_at`], a level drawn along an axis where its voxels are at most `coarsen_to`
/// pixels apart.
fn detail_within(dims: [u32; 3], apart: Option<Apart>, within: Within, coarsen_to: f64) -> Detail {
    let Some(Apart {
        pixels: apart,
        full,
        facing,
    }) = apart
    else {
        return Detail::Level([0; 3], [0; 3]);
    };
    if let Some(factors) = refine_factors(dims, full, within) {
        return Detail::Refined(factors);
    }
    // Coarser along each axis while the next level's voxels are still at most a pixel apart
    // and the axis still has more than one voxel.
    let levels: [u8; 3] = std::array::from_fn(|a| {
        let (mut apart, mut level, mut n) = (apart[a], 0, dims[a]);
        while level < MAX_LEVEL && apart.is_finite() && apart >= 0.0 && 2.0 * apart <= coarsen_to {
            if n <= 1 {
                break;
            }
            apart *= 2.0;
            level += 1;
            n = n.div_ceil(2);
        }
        level
    });
    // (Axes of one voxel are never halved and do not count.)
    let least = (0..3)
        .filter(|&a| dims[a] > 1)
        .map(|a| levels[a])
        .min()
        .unwrap_or(0);
    level_facing(
        levels.map(|l| l.min(least.saturating_add(MAX_DEPTH_LEVELS))),
        facing,
    )
}

/// The level of `levels` halvings along each axis, with which end of the axis halved more
/// than both others faces the eye (`facing`, as [`Apart::facing`]), where one is. Such an
/// axis whose sight lines run both ways (a grid finer along it than across) is halved as the
/// others are, its voxels weighted by density alone.
///
/// Only that axis's end tells levels apart: the steps from the own grid halve every axis
/// still short of its level together, so a step halves one axis alone, merging its pairs
/// nearer over farther, only past the other axes' levels, and only the axis halved most
/// takes such steps. A level halved as much along two axes ([1, 1, 0]) has no pairs merged
/// by their ends and is the same level from either side: keyed by its ends, a camera turning
/// about the volume made it again each time the view crossed an axis.
pub(super) fn level_facing(levels: [u8; 3], facing: [i8; 3]) -> Detail {
    let most = |a: usize| (0..3).all(|b| b == a || levels[a] > levels[b]);
    Detail::Level(
        levels,
        std::array::from_fn(|a| if most(a) { facing[a] } else { 0 }),
    )
}

/// The level a preview of coarseness `preview` ([`FrameOptions::preview`]) draws along an axis
/// where the view calls for `level`: `preview - 1` levels coarser, at least `preview` above
/// the own grid, at most [`MAX_LEVEL`]; `level` itself for a full frame (0). Adding the same
/// to every axis, and flooring all at one value, never widens the gap between two axes' levels
/// ([`MAX_DEPTH_LEVELS`]).
pub fn preview_level(level: u8, preview: u8) -> u8 {
    match preview {
        0 => level,
        n => level.saturating_add(n - 1).max(n).min(MAX_LEVEL),
    }
}

/// Side, in voxels, of the bricks whose occupancy tells where a volume's content comes
/// nearest the eye ([`Occupied`]).
pub(super) const BRICK: u32 = 16;

/// The voxels of one brick of [`BRICK`]^3.
const BRICK_VOXELS: u64 = (BRICK as u64).pow(3);

/// The bricks of [`BRICK`]^3 voxels of a classified grid that hold at least one splat: where a
/// volume's content lies, so that the level of detail goes by the nearest content rather
/// than by the nearest corner of a box that may hold only air (a CT's field of view around
/// the patient, a ball in its cube).
#[derive(Debug, Clone, Default)]
pub(super) struct Occupied {
    /// Brick coordinates (voxel index / [`BRICK`]).
    bricks: Vec<[u32; 3]>,
    /// The splats in each brick (0 for a brick added as a neighbour).
    splats: Vec<u32>,
}

impl Occupied {
    /// The occupied bricks of `classified`'s grid, from its rows.
    pub(super) fn of(classified: &Classified) -> Self {
        let grid = &classified.grid;
        let [nx, ny, nz] = grid.dims();
        let [bx, by, bz] = [nx, ny, nz].map(|n| n.div_ceil(BRICK));
        let mut counts = vec![0u32; bx as usize * by as usize * bz as usize];
        for z in 0..nz {
            for y in 0..ny {
                let row = (y / BRICK + by * (z / BRICK)) as usize * bx as usize;
                for run in grid.row(0, y, z) {
                    if run.end() > run.start {
                        for x in run.start / BRICK..=(run.end() - 1) / BRICK {
                            let (from, to) =
                                (run.start.max(x * BRICK), run.end().min((x + 1) * BRICK));
                            counts[row + x as usize] += to - from;
                        }
                    }
                }
            }
        }
        let (bricks, splats) = counts
            .iter()
            .enumerate()
            .filter(|(_, c)| **c > 0)
            .map(|(i, c)| {
                let i = i as u32;
                ([i % bx, i / bx % by, i / bx / by], *c)
            })
            .unzip();
        Self { bricks, splats }
    }

    /// These bricks and every brick next to one (across a face, an edge or a corner), within a
    /// grid of `dims` voxels: where a refinement of the grid can hold splats, since a fine
    /// voxel's cell samples the field of the coarse voxels around it.
    pub(super) fn with_neighbours(&self, dims: [u32; 3]) -> Self {
        let n = dims.map(|d| d.div_ceil(BRICK));
        let index = |b: [u32; 3]| (b[0] + n[0] * (b[1] + n[1] * b[2])) as usize;
        let mut marked = vec![None; n.iter().map(|&c| c as usize).product()];
        for (b, &splats) in self.bricks.iter().zip(&self.splats) {
            marked[index(*b)] = Some(splats);
        }
        for b in &self.bricks {
            for dz in 0..3u32 {
                for dy in 0..3u32 {
                    for dx in 0..3u32 {
                        let c = [b[0] + dx, b[1] + dy, b[2] + dz];
                        if (0..3).all(|a| c[a] >= 1 && c[a] - 1 < n[a]) {
                            let m = &mut marked[index(c.map(|v| v - 1))];
                            *m = Some(m.unwrap_or(0));
                        }
                    }
                }
            }
        }
        let (bricks, splats) = marked
            .iter()
            .enumerate()
            .filter_map(|(i, m)| {
                let i = i as u32;
                Some(([i % n[0], i / n[0] % n[1], i / n[0] / n[1]], (*m)?))
            })
            .unzip();
        Self { bricks, splats }
    }

    /// The world boxes of the occupied bricks (each brick's voxels' box, half a voxel beyond
    /// their centres, as a world axis-aligned box: centre and half size) for a grid placed as
    /// `geometry`.
    fn world_boxes<'a>(
        &'a self,
        geometry: &VolumeGeometry,
    ) -> impl Iterator<Item = (DVec3, DVec3)> + 'a {
        let to_world = geometry.index_to_world();
        let m = to_world.matrix3;
        let dims = geometry.dims();
        let abs = glam::DMat3::from_cols(m.x_axis.abs(), m.y_axis.abs(), m.z_axis.abs());
        self.bricks.iter().map(move |b| {
            let lo = DVec3::from(std::array::from_fn::<f64, 3, _>(|a| {
                f64::from(b[a] * BRICK) - 0.5
            }));
            let hi = DVec3::from(std::array::from_fn::<f64, 3, _>(|a| {
                f64::from(((b[a] + 1) * BRICK).min(dims[a])) - 0.5
            }));
            (
                to_world.transform_point3(0.5 * (lo + hi)),
                abs * (0.5 * (hi - lo)),
            )
        })
    }

    /// The distance from `eye` to the nearest point of the occupied bricks' world boxes for a
    /// grid placed as `geometry`; 0 when the eye is in one, `None` when none is occupied.
    #[cfg(test)]
    pub(super) fn nearest(&self, geometry: &VolumeGeometry, eye: DVec3) -> Option<f64> {
        self.world_boxes(geometry)
            .map(|(centre, half)| (eye.clamp(centre - half, centre + half) - eye).length())
            .min_by(f64::total_cmp)
    }
}

/// How many pixels apart on the screen the voxels of a grid placed as `geometry` fall along
/// each of its axes in `view`, where the grid is drawn largest: a voxel's edge along the axis
/// projected across the line of sight, at the distance of the grid's box from the eye (at
/// least the splats' near cut, [`ViewSetup::splat_near`]: an eye inside the box sees voxels
/// drawn as near as that). `None` where a value is not finite.
pub fn pixels_apart(geometry: &VolumeGeometry, view: &ViewSetup) -> Option<[f64; 3]> {
    pixels_apart_near(geometry, view, None)
}

/// [`pixels_apart`] where the grid's content is drawn largest, where its `occupied` bricks
/// are known (the volume's own grid), else where its box is; bricks off the image do not
/// count. Along each axis, the largest over the bricks of the voxel's edge across the line of
/// sight (the least cosine between the axis and the lines of sight to the brick's corners;
/// none where they fall on both sides of it) over the world size of a pixel at the brick's
/// nearest point.
pub(super) fn pixels_apart_near(
    geometry: &VolumeGeometry,
    view: &ViewSetup,
    occupied: Option<&Occupied>,
) -> Option<[f64; 3]> {
    apart_near(geometry, view, occupied).map(|a| a.pixels)
}

/// How many pixels apart a grid's voxels fall on the screen along each of its axes, and
/// which end of each axis faces the eye ([`apart_near`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Apart {
    /// Pixels apart along each axis where the grid is drawn largest.
    pub(super) pixels: [f64; 3],
    /// Pixels a voxel's whole edge along each axis would span there, were it across the
    /// view.
    pub(super) full: [f64; 3],
    /// Per axis, 1 where every sight line to the grid's content runs towards its smaller
    /// indices (the larger face the eye), -1 where every one runs towards the larger, 0 where
    /// they run both ways.
    pub(super) facing: [i8; 3],
}

/// How many pixels apart the voxels of a grid placed as `geometry` fall on the screen along
/// each of its axes in `view` at the world box `(centre, half size)` of some of its voxels
/// (see [`apart_near`]), at least the splats' near cut away; `None` where a value is not
/// finite.
fn apart_in_box(
    geometry: &VolumeGeometry,
    view: &ViewSetup,
    (centre, half): (DVec3, DVec3),
) -> Option<Apart> {
    let m = geometry.index_to_world().matrix3;
    let spacing = geometry.spacing();
    let axes: [DVec3; 3] = [m.x_axis, m.y_axis, m.z_axis].map(|c| c.normalize_or_zero());
    let eye = view.camera.eye;
    let forward = view.axes.z_axis;
    // Which end of an axis faces the eye along sight lines whose cosines with it span
    // `[lo, hi]`.
    let facing_of = |lo: f64, hi: f64| -> i8 {
        if hi < 0.0 {
            1
        } else if lo > 0.0 {
            -1
        } else {
            0
        }
    };
    // The share of an edge along `axis` that lies across sight lines whose cosines with it
    // span `[lo, hi]`.
    let across = |lo: f64, hi: f64| {
        if lo <= 0.0 && hi >= 0.0 {
            1.0
        } else {
            let least = lo.abs().min(hi.abs()).min(1.0);
            (1.0 - least * least).sqrt()
        }
    };
    let pixel = if view.is_orthographic() {
        1.0 / view.focal
    } else {
        // An eye in the box (or nearer it than splats are drawn) may have the box's voxels
        // as near as the splats' near cut: that is where they are drawn largest.
        let finest = spacing.into_iter().fold(f64::INFINITY, f64::min);
        let nearest = (eye.clamp(centre - half, centre + half) - eye).length();
        nearest.max(view.splat_near(finest)) / view.focal
    };
    // The sight lines to the box's corners (one, the view direction, orthographic).
    let sights: [DVec3; 8] = std::array::from_fn(|corner| {
        if view.is_orthographic() {
            return forward;
        }
        let sign = DVec3::from(std::array::from_fn::<f64, 3, _>(|k| {
            if corner >> k & 1 == 1 { 1.0 } else { -1.0 }
        }));
        (centre + sign * half - eye).normalize_or_zero()
    });
    let cosines: [(f64, f64); 3] = std::array::from_fn(|a| {
        sights
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), s| {
                let c = axes[a].dot(*s);
                (lo.min(c), hi.max(c))
            })
    });
    let pixels: [f64; 3] = std::array::from_fn(|a| {
        let (lo, hi) = cosines[a];
        spacing[a] * across(lo, hi) / pixel
    });
    let full: [f64; 3] = std::array::from_fn(|a| spacing[a] / pixel);
    let facing = cosines.map(|(lo, hi)| facing_of(lo, hi));
    pixels
        .iter()
        .chain(&full)
        .all(|v| v.is_finite())
        .then_some(Apart {
            pixels,
            full,
            facing,
        })
}

/// [`pixels_apart_near`], with which end of each axis faces the eye.
pub(super) fn apart_near(
    geometry: &VolumeGeometry,
    view: &ViewSetup,
    occupied: Option<&Occupied>,
) -> Option<Apart> {
    let of_box = |b| apart_in_box(geometry, view, b);
    let worst = |boxes: &mut dyn Iterator<Item = (DVec3, DVec3)>| {
        let mut most: Option<Apart> = None;
        for b in boxes {
            // Content off the image draws no pixel, however fine or coarse.
            if off_image(view, b) {
                continue;
            }
            // A value that is not finite: the own grid.
            let apart = of_box(b)?;
            let m = most.get_or_insert(apart);
            for a in 0..3 {
                m.pixels[a] = m.pixels[a].max(apart.pixels[a]);
                m.full[a] = m.full[a].max(apart.full[a]);
                if m.facing[a] != apart.facing[a] {
                    m.facing[a] = 0;
                }
            }
        }
        most
    };
    match occupied {
        Some(occupied) if !occupied.bricks.is_empty() => worst(&mut occupied.world_boxes(geometry)),
        _ => {
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
            worst(&mut std::iter::once((0.5 * (lo + hi), 0.5 * (hi - lo))))
        }
    }
}

/// Side, in voxels, of the bricks a refinement is classified within or left out by
/// ([`on_image`]).
pub(super) const REGION_BRICK: u32 = 8;

/// The bricks of [`REGION_BRICK`]^3 voxels of a grid placed as `geometry` whose splats,
/// refined or not, can land on `view`'s image; `None` where every brick's can. A brick's box
/// is grown by two of its voxels each way (a splat's footprint reaches past its voxel, and a
/// fine voxel's cell samples the field a voxel around it) and by three pixels at its far side
/// (the screen's low-pass), then tested against the image's edges ([`off_image`]).
///
/// Settled block by block ([`Region::by_blocks`]): a block of bricks is off the image where
/// its box, grown by more than any of its bricks' boxes is, lies off it, and on it where its
/// box (ungrown) lies wholly inside the image's edges; only the blocks across an edge are cut
/// down to bricks. The bricks are the ones tested one by one give (a test checks this).
pub(super) fn on_image(geometry: &VolumeGeometry, view: &ViewSetup) -> Option<Region> {
    let to_world = geometry.index_to_world();
    let m = to_world.matrix3;
    let abs = glam::DMat3::from_cols(m.x_axis.abs(), m.y_axis.abs(), m.z_axis.abs());
    let dims = geometry.dims();
    let eye = view.camera.eye;
    let region = Region::by_blocks(dims, REGION_BRICK, |lo_brick, hi_brick| {
        let lo = DVec3::from(std::array::from_fn::<f64, 3, _>(|a| {
            f64::from(lo_brick[a] * REGION_BRICK) - 2.5
        }));
        let hi = DVec3::from(std::array::from_fn::<f64, 3, _>(|a| {
            f64::from((hi_brick[a] * REGION_BRICK).min(dims[a])) + 1.5
        }));
        let centre = to_world.transform_point3(0.5 * (lo + hi));
        let half = abs * (0.5 * (hi - lo));
        let single = (0..3).all(|a| hi_brick[a] - lo_brick[a] == 1);
        // A pixel's world size at the far side of the box; for a block, at least any of its
        // bricks': a brick's centre lies within the block's half diagonal of the block's
        // centre, and its offset plus its own half diagonal is at most sqrt 2 times the
        // block's.
        let reach = if single { 1.0 } else { 2.0 };
        let pixel = if view.is_orthographic() {
            1.0 / view.focal
        } else {
            ((centre - eye).length() + reach * half.length()) / view.focal
        };
        let grown = half + DVec3::splat(3.0 * pixel);
        // A box that is not finite (a degenerate placement) is kept: nothing is left out
        // that cannot be shown to be off the image.
        let finite = centre.is_finite() && grown.is_finite();
        if single {
            Some(!(finite && off_image(view, (centre, grown))))
        } else if !finite {
            None
        } else if off_image(view, (centre, grown)) {
            Some(false)
        } else if inside_image(view, (centre, half)) {
            Some(true)
        } else {
            None
        }
    })?;
    (!region.is_whole()).then_some(region)
}

/// The own grid's voxels and splats in the `occupied` bricks (of [`BRICK`]^3 voxels) that
/// hold a brick of `on_image` ([`on_image`]; `None`: every brick is on the image): where a
/// refinement classified within the bricks on the image has its splats, the bricks with
/// none of the own grid's (air, or their neighbours, whose fine voxels only the edges of
/// the field's cells reach) left uncounted.
pub(super) fn on_image_within(
    dims: [u32; 3],
    occupied: &Occupied,
    on_image: Option<&Region>,
) -> (u64, u64) {
    let per = BRICK / REGION_BRICK;
    occupied
        .bricks
        .iter()
        .zip(&occupied.splats)
        .filter(|(b, _)| {
            on_image.is_none_or(|region| {
                (0..per * per * per).any(|i| {
                    let d = [i % per, i / per % per, i / per / per];
                    region.covers_brick(std::array::from_fn(|a| b[a] * per + d[a]))
                })
            })
        })
        .map(|(b, &splats)| {
            let voxels = (0..3)
                .map(|a| u64::from(BRICK.min(dims[a] - b[a] * BRICK)))
                .product::<u64>();
            (voxels, u64::from(splats))
        })
        .fold((0, 0), |(v, s), (bv, bs)| (v + bv, s + bs))
}

/// Whether the world box `(centre, half size)` lies wholly outside what `view` sees: beyond
/// one of the planes through the image's edges (for perspective, through the eye), or
/// behind the eye.
pub(super) fn off_image(view: &ViewSetup, (centre, half): (DVec3, DVec3)) -> bool {
    let to = centre - view.camera.eye;
    // The box lies beyond the plane of outward normal `n` at `offset` from the eye.
    image_planes(view)
        .iter()
        .any(|&(n, offset)| n.dot(to) - n.abs().dot(half) > offset)
}

/// Whether the world box `(centre, half size)` lies wholly inside what `view` sees: on the
/// inner side of every plane [`off_image`] tests. A box inside is beyond none of them, nor is
/// any box that meets it.
pub(super) fn inside_image(view: &ViewSetup, (centre, half): (DVec3, DVec3)) -> bool {
    let to = centre - view.camera.eye;
    image_planes(view)
        .iter()
        .all(|&(n, offset)| n.dot(to) + n.abs().dot(half) <= offset)
}

/// The planes that bound what `view` sees, as outward normals and offsets from the eye: the
/// planes through the image's edges (for perspective, through the eye) and the eye's own.
fn image_planes(view: &ViewSetup) -> [(DVec3, f64); 5] {
    let [right, up, forward] = [view.axes.x_axis, view.axes.y_axis, view.axes.z_axis];
    let (w, h) = (f64::from(view.size.0), f64::from(view.size.1));
    let (tan_x, tan_y) = (0.5 * w / view.focal, 0.5 * h / view.focal);
    if view.is_orthographic() {
        [
            (right, tan_x),
            (-right, tan_x),
            (up, tan_y),
            (-up, tan_y),
            (-forward, 0.0),
        ]
    } else {
        [
            (right - tan_x * forward, 0.0),
            (-right - tan_x * forward, 0.0),
            (up - tan_y * forward, 0.0),
            (-up - tan_y * forward, 0.0),
            (-forward, 0.0),
        ]
    }
}

/// What a refinement of a grid is classified in ([`refine_factors`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Within {
    /// The own grid's voxels (counted at most as the whole grid's).
    pub voxels: u64,
    /// The own grid's splats among them, and the most splats the refinement may hold (bounded
    /// by those splats times the factors' product); `None`: no bound.
    pub splats: Option<(u64, u64)>,
}

impl Within {
    /// The whole grid, the splats unbounded.
    pub const WHOLE: Within = Within {
        voxels: u64::MAX,
        splats: None,
    };

    /// `voxels` of the own grid, the splats unbounded.
    pub fn voxels(voxels: u64) -> Self {
        Self {
            voxels,
            splats: None,
        }
    }
}

/// The factors a `dims` grid whose voxels are `apart` pixels apart along each axis is refined
/// by (see [`detail_for`]), its refinement classified `within`; `None` where no axis is. The
/// factors wanted are lowered, largest first, until the whole refined grid holds at most
/// [`MAX_REFINED_VOXELS`]; or, where they come out larger so, until the refined voxels
/// `within` do, the whole refined grid holds at most [`MAX_REFINED_GRID`] and the refinement
/// at most `within.splats` splats: a refinement bounded by what a view shows is never coarser
/// than one bounded by the whole grid (whose cost the views that show little of the grid, or
/// little of it unhidden, keep).
pub(super) fn refine_factors(dims: [u32; 3], apart: [f64; 3], within: Within) -> Option<[u32; 3]> {
    let wanted = [0, 1, 2].map(|a| {
        let wanted = if apart[a].is_finite() {
            (apart[a] / REFINE_TO).ceil()
        } else {
            1.0
        };
        let most = (MAX_REFINED_DIM / u64::from(dims[a].max(1))).max(1) as f64;
        wanted.clamp(1.0, f64::from(MAX_REFINE).min(most)) as u32
    });
    let whole: u64 = dims.iter().map(|&n| u64::from(n)).product();
    let voxels = within.voxels.min(whole);
    let fine = |f: &[u32; 3], voxels: u64| {
        f.iter()
            .fold(voxels, |n, &f| n.saturating_mul(u64::from(f)))
    };
    let lowered = |too_many: &dyn Fn(&[u32; 3]) -> bool| {
        let mut factors = wanted;
        while too_many(&factors) {
            let a = (0..3).max_by_key(|&a| factors[a]).unwrap_or(0);
            if factors[a] == 1 {
                break;
            }
            factors[a] -= 1;
        }
        factors
    };
    let by_whole = lowered(&|f| fine(f, whole) > MAX_REFINED_VOXELS);
    let by_view = lowered(&|f| {
        fine(f, voxels) > MAX_REFINED_VOXELS
            || fine(f, whole) > MAX_REFINED_GRID
            || within
                .splats
                .is_some_and(|(splats, most)| fine(f, splats) > most)
    });
    let product = |f: &[u32; 3]| fine(f, 1);
    let factors = if product(&by_view) > product(&by_whole) {
        by_view
    } else {
        by_whole
    };
    (factors != [1; 3]).then_some(factors)
}

/// The detail each occupied brick of a volume's own grid (placed as `geometry`), and each brick
/// next to one, is drawn at in
/// `view` when its bricks are drawn each at its own level ([`Renderer::set_levels_by_brick`]),
/// for the bricks whose splats can land on the image: [`detail_at`] the brick's own distance
/// and sight lines, the rule a volume's level follows at its nearest brick: a level of its
/// pyramid, or its grid refined where its voxels fall more than [`REFINE_TO`] pixels apart. A
/// brick the eye is in is seen from the splats' near cut; a `preview` draws every brick at
/// the level [`preview_level`] makes of it. With each brick comes the level, halved once more along the axes
/// halved least (and at most once more along the others), it may be drawn at where its
/// content is smooth ([`SMOOTH_COARSEN_TO`]; `None` for a preview, a brick drawn refined, or
/// one whose voxels would fall too far apart). A brick whose voxels fall more than
/// `refine_from` pixels apart (whole edges) wants refining whatever the rule says
/// ([`REFINE_TO`] is the rule's own threshold). A brick is left out where its box, grown by
/// two of its splats' voxels each way and by three pixels at its far side (the footprints'
/// reach past their voxels and the screen's low-pass), lies off the image ([`off_image`]).
/// Each brick comes with the own grid's splats in it.
pub(super) fn brick_details(
    geometry: &VolumeGeometry,
    view: &ViewSetup,
    occupied: &Occupied,
    preview: u8,
    refine_from: f64,
) -> Vec<BrickWant> {
    let dims = geometry.dims();
    let m = geometry.index_to_world().matrix3;
    let abs = glam::DMat3::from_cols(m.x_axis.abs(), m.y_axis.abs(), m.z_axis.abs());
    let eye = view.camera.eye;
    // A brick with no splat of the own grid next to one that has can hold splats of a
    // refinement.
    let bricks = occupied.with_neighbours(dims);
    // Tens of thousands of bricks on a thin-slice grid, every frame: on every core.
    let boxes: Vec<(DVec3, DVec3)> = bricks.world_boxes(geometry).collect();
    bricks
        .bricks
        .par_iter()
        .zip(&bricks.splats)
        .zip(boxes)
        .filter_map(|((&brick, &splats), (centre, half))| {
            let apart = apart_in_box(geometry, view, (centre, half));
            let wanted = apart.map(|apart| {
                match detail_at(dims, Some(apart), Within::voxels(BRICK_VOXELS)) {
                    Detail::Level(..) if apart.full.iter().any(|&f| f > refine_from) => {
                        Detail::Refined([1; 3])
                    }
                    wanted => wanted,
                }
            });
            let (levels, facing) = match wanted {
                Some(Detail::Level(levels, facing)) => (levels, facing),
                _ => ([0; 3], [0; 3]),
            };
            let levels = levels.map(|l| preview_level(l, preview));
            let smooth = match (wanted, preview) {
                (Some(Detail::Level(..)), 0) => {
                    apart.and_then(|apart| {
                        // Halved once more along each axis halved least (those across the
                        // view), and at most once more along the others.
                        let least = (0..3)
                            .filter(|&a| dims[a] > 1)
                            .map(|a| levels[a])
                            .min()
                            .unwrap_or(0);
                        match detail_within(
                            dims,
                            Some(apart),
                            Within::voxels(BRICK_VOXELS),
                            SMOOTH_COARSEN_TO,
                        ) {
                            Detail::Level(coarser, facing)
                                if (0..3).all(|a| {
                                    let more = coarser[a].checked_sub(levels[a]);
                                    match (dims[a] > 1 && levels[a] == least, more) {
                                        (true, more) => more == Some(1),
                                        (false, more) => more.is_some_and(|m| m <= 1),
                                    }
                                }) =>
                            {
                                Some((coarser, facing))
                            }
                            _ => None,
                        }
                    })
                }
                _ => None,
            };
            // The splats' reach at the coarser of the levels the brick may be drawn at.
            let reach_levels = smooth.map_or(levels, |(coarser, _)| coarser);
            let reach = abs * DVec3::from(reach_levels.map(|l| 2.0 * f64::from(1u32 << l)));
            let pixel = if view.is_orthographic() {
                1.0 / view.focal
            } else {
                ((centre - eye).length() + (half + reach).length()) / view.focal
            };
            let grown = half + reach + DVec3::splat(3.0 * pixel);
            let shown =
                !(centre.is_finite() && grown.is_finite() && off_image(view, (centre, grown)));
            let detail = match wanted {
                Some(Detail::Refined(factors)) if preview == 0 => Detail::Refined(factors),
                _ => level_facing(levels, facing),
            };
            shown.then_some(BrickWant {
                brick,
                detail,
                splats,
                smooth: smooth.map(|(levels, facing)| Detail::Level(levels, facing)),
            })
        })
        .collect()
}

/// What a brick on the image wants drawn ([`brick_details`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct BrickWant {
    /// The brick, in bricks of [`BRICK`] own voxels.
    pub(super) brick: [u32; 3],
    /// The detail its distance and sight lines call for.
    pub(super) detail: Detail,
    /// The own grid's splats in it.
    pub(super) splats: u32,
    /// The level, coarser than `detail`, its content may be drawn at where that content
    /// loses little by it ([`SMOOTH_COARSEN_TO`], [`SMOOTH_SPREAD`]).
    pub(super) smooth: Option<Detail>,
}

/// Sorts `bricks` (coordinates in bricks of `side`^3 voxels of a grid placed as `geometry`:
/// [`BRICK`] for a mix, [`REGION_BRICK`] for the bricks a refinement is classified within)
/// into a visibility order for the eye `eye` looking at `target` (world), far to near: the
/// IP-PBTF order of the grid of bricks (lexicographic by the bricks' distances from the eye in
/// brick units along the axes of [`ViewCase::permutation`], descending; equal distances, lower
/// coordinate first).
///
/// Any order lexicographic in the axes' distances puts, of two bricks that share a face, the
/// one on the far side of that face's plane first, and in a grid of boxes those pairs are
/// what hiding follows: a brick drawn later never lies behind one drawn earlier. It is the
/// order the voxels' IP-PBTF keeps between voxels of different bricks, given to whole bricks;
/// within a brick, its level's own order.
pub(super) fn brick_order(
    geometry: &VolumeGeometry,
    eye: DVec3,
    target: DVec3,
    side: u32,
    bricks: &mut [([u32; 3], Detail)],
) -> Result<(), crate::order::OrderError> {
    let dims = geometry.dims().map(|n| n.div_ceil(side));
    let side = f64::from(side);
    let to_own = glam::DAffine3::from_scale_rotation_translation(
        DVec3::splat(side),
        glam::DQuat::IDENTITY,
        DVec3::splat(0.5 * (side - 1.0)),
    );
    let of_bricks = VolumeGeometry::new(dims, geometry.index_to_world() * to_own)?;
    let case = ViewCase::new(&of_bricks, eye, target)?;
    let key = |b: &[u32; 3], a: usize| (f64::from(b[a]) - case.eye[a]).abs();
    bricks.sort_by(|(x, _), (y, _)| {
        case.permutation
            .iter()
            .map(|&a| key(y, a).total_cmp(&key(x, a)).then(x[a].cmp(&y[a])))
            .find(|o| o.is_ne())
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    Ok(())
}
