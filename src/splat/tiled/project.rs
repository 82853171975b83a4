//! Projection: each splat of the draw order placed on the screen (its centre, its footprint,
//! its pixel rectangle) and coloured from its texel, as the splat pass's vertex shader does.

use glam::Vec3;
use strength_reduce::StrengthReducedU32;

use super::Screen;
use super::mask::OpaqueMask;
use super::texels::SplatTexels;
use crate::splat::footprint::{Footprint, Lens, footprint};

/// One volume's splats for a frame, in the splat pass's terms (see `SplatUniforms` in
/// `src/render/splat_pass.rs`; this mirrors it on the CPU).
#[derive(Debug, Clone)]
pub struct SplatProjection {
    /// Rows of the index-offset to camera matrix (x right, y up, z forward).
    pub m: [Vec3; 3],
    /// The eye in voxel index coordinates.
    pub eye_index: Vec3,
    /// Splats nearer than this (perspective) are left out.
    pub near_cut: f32,
    /// Rows of the camera-space covariance of a splat.
    pub cov: [Vec3; 3],
    /// Image centre in pixels.
    pub centre: [f32; 2],
    /// Focal length in pixels (perspective), or pixels per world unit (orthographic).
    pub focal: f32,
    /// Screen-space variance added to every footprint.
    pub pixel_variance: f32,
    /// Cut-off of the Gaussian's exponent (radius^2 / sigma^2).
    pub cutoff: f32,
    /// Orthographic projection.
    pub orthographic: bool,
    /// Near plane (perspective depth scale; orthographic near) and far plane (orthographic).
    pub near: f32,
    /// Orthographic far plane.
    pub far: f32,
    /// Grid size.
    pub dims: [u32; 3],
    /// Voxels in a row (x) and in a plane (x y) of the grid, for dividing voxel ids.
    pub row: StrengthReducedU32,
    /// See `row`.
    pub plane: StrengthReducedU32,
    /// Rows of the index-space gradient to camera-space normal matrix.
    pub normal: [Vec3; 3],
    /// Shading strength (0 flat, 1 fully headlight-shaded).
    pub shading: f32,
    /// Clip planes in camera space: a splat is kept where `dot(xyz, p) <= w` for each.
    pub clip: Vec<[f32; 4]>,
    /// A splat's peak opacity in this view by the f16 bits of its density
    /// ([`alpha_table`]).
    pub alpha: std::sync::Arc<[f32]>,
}

impl SplatProjection {
    /// The peak opacity of the splat whose texel is `texel`.
    #[inline(always)]
    pub(super) fn alpha_of(&self, texel: &[u8; 8]) -> f32 {
        let bits = u16::from_le_bytes([texel[6], texel[7]]);
        self.alpha.get(usize::from(bits)).copied().unwrap_or(0.0)
    }
}

/// The peak opacity of a splat by the f16 bits of its density (all 65,536 of them), in a view
/// whose index step spans `step_mm` millimetres: [`crate::classify::splat_alpha`] of each.
/// The last few views' tables are kept, so a frame does not remake its table (65,536
/// exponentials, about half a millisecond).
pub fn alpha_table(step_mm: f32) -> std::sync::Arc<[f32]> {
    use std::sync::{Arc, Mutex};
    static KEPT: Mutex<Vec<(u32, Arc<[f32]>)>> = Mutex::new(Vec::new());
    let key = step_mm.to_bits();
    if let Ok(kept) = KEPT.lock()
        && let Some((_, table)) = kept.iter().find(|(k, _)| *k == key)
    {
        return Arc::clone(table);
    }
    let table: Arc<[f32]> = (0..=u16::MAX)
        .map(|bits| {
            let density = half::f16::from_bits(bits).to_f32();
            // Negative or NaN densities (never written) stay transparent.
            crate::classify::splat_alpha(density, step_mm)
        })
        .collect();
    if let Ok(mut kept) = KEPT.lock() {
        if kept.len() >= 8 {
            kept.remove(0);
        }
        kept.push((key, Arc::clone(&table)));
    }
    table
}

/// A splat projected to the screen.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Projected {
    pub(super) centre: [f32; 2],
    /// Inverse screen covariance: `q = a dx^2 + 2 b dx dy + c dy^2`.
    pub(super) conic: [f32; 3],
    /// Premultiplied colour.
    pub(super) color: [f32; 4],
    /// Reversed depth, compared with the mesh depth as the GPU's depth test does.
    pub(super) depth: f32,
    pub(super) cutoff: f32,
    /// Covered pixel rectangle, inclusive (`x0 > x1` for a splat that is left out).
    pub(super) x0: i32,
    pub(super) y0: i32,
    pub(super) x1: i32,
    pub(super) y1: i32,
}

impl Projected {
    /// A splat left out.
    pub(super) const NONE: Self = Self {
        centre: [0.0; 2],
        conic: [0.0; 3],
        color: [0.0; 4],
        depth: 0.0,
        cutoff: 0.0,
        x0: 1,
        y0: 0,
        x1: 0,
        y1: 0,
    };
}

/// The voxel `(x, y, z)` of id `id`, by divisions by the grid's row and plane sizes done as
/// multiplications (the hardware divide was a fifth of the projection's time).
#[inline(always)]
pub(super) fn voxel(u: &SplatProjection, id: u32) -> [u32; 3] {
    let z = id / u.plane;
    let rest = id - z * u.plane.get();
    let y = rest / u.row;
    [rest - y * u.row.get(), y, z]
}

/// What projecting a stretch of one volume's draw order takes.
#[derive(Clone, Copy)]
pub(super) struct Group<'a> {
    pub(super) u: &'a SplatProjection,
    pub(super) texels: &'a SplatTexels,
    pub(super) screen: &'a Screen,
    /// The pixels opaque before this batch (`None` while none is).
    pub(super) mask: Option<&'a OpaqueMask>,
}

impl Group<'_> {
    /// [`super::simd::project_group`] a splat at a time, in plain code.
    pub(super) fn project_each(
        &self,
        voxels: &[[u32; 3]],
        out: &mut [Projected],
    ) -> (usize, usize) {
        let (w, h) = (self.screen.w as i32, self.screen.h as i32);
        let (mut culled, mut kept) = (0, 0);
        for &[x, y, z] in voxels {
            let centre = camera_centre(self.u, [x, y, z]);
            let Some(at) = place(self.u, centre, w, h) else {
                continue;
            };
            if self.mask.is_some_and(|m| m.covers_rect(at.rect)) {
                culled += 1;
                continue;
            }
            let p = project(self.u, self.texels, [x, y, z], centre, &at);
            if p.x0 <= p.x1 {
                out[kept] = p;
                kept += 1;
            }
        }
        (culled, kept)
    }
}

/// The pixel rectangle `[x0, y0, x1, y1]` that holds every footprint of the splats of `ids`
/// (a stretch of the draw order), as [`place`] would give them, clamped to the image (empty,
/// `x0 > x1` or `y0 > y1`, where all of them lie off it); `None` where it cannot be bounded
/// (a splat behind the near cut, no splat, NaN). Decoding a voxel id and taking the box's
/// bounds costs less than a splat's own test; the order's rows make most stretches short
/// segments.
///
/// The rectangle: the voxels' box projected (its corners' centres bound every centre in it,
/// and its corners' slopes `x / z` and `y / z` every slope, a linear-fractional function
/// taking its extremes at a convex set's vertices), grown by the largest half extent
/// `radius sqrt(a)` of a splat's rectangle in the box ([`place`]). The screen variance
/// `a = (f / z)^2 (S00 - 2 S02 s + S22 s^2) + pixel variance` is largest at the nearest depth
/// and, convex in the slope `s`, at one of the slope's bounds (likewise `c` with `S11`, `S12`
/// and the slope `y / z`; orthographic, both are constant).
pub(super) fn group_rect(u: &SplatProjection, voxels: &[[u32; 3]], s: &Screen) -> Option<[i32; 4]> {
    let (mut lo, mut hi) = ([u32::MAX; 3], [0u32; 3]);
    for &[x, y, z] in voxels {
        lo = [lo[0].min(x), lo[1].min(y), lo[2].min(z)];
        hi = [hi[0].max(x), hi[1].max(y), hi[2].max(z)];
    }
    if voxels.is_empty() {
        return None;
    }
    let (mut left, mut right, mut top, mut bottom) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
    let (mut sx, mut sy) = ([f32::MAX, f32::MIN], [f32::MAX, f32::MIN]);
    let mut nearest = f32::MAX;
    let f = u.focal;
    for corner in 0..8 {
        let pick = |axis: usize| {
            if corner >> axis & 1 == 0 {
                lo[axis]
            } else {
                hi[axis]
            }
        };
        let p = camera_centre(u, [pick(0), pick(1), pick(2)]);
        let (centre, slope) = if u.orthographic {
            if p.z <= u.near {
                return None;
            }
            ([u.centre[0] + f * p.x, u.centre[1] - f * p.y], [0.0; 2])
        } else {
            if p.z <= u.near_cut {
                return None;
            }
            let iz = 1.0 / p.z;
            let slope = [p.x * iz, p.y * iz];
            (
                [u.centre[0] + f * slope[0], u.centre[1] - f * slope[1]],
                slope,
            )
        };
        nearest = nearest.min(p.z);
        left = left.min(centre[0]);
        right = right.max(centre[0]);
        top = top.min(centre[1]);
        bottom = bottom.max(centre[1]);
        sx = [sx[0].min(slope[0]), sx[1].max(slope[0])];
        sy = [sy[0].min(slope[1]), sy[1].max(slope[1])];
    }
    let scale = if u.orthographic { f } else { f / nearest };
    let variance = |diagonal: f32, cross: f32, [s0, s1]: [f32; 2]| {
        let q = |s: f32| diagonal - 2.0 * cross * s + u.cov[2][2] * s * s;
        scale * scale * q(s0).max(q(s1)) + u.pixel_variance
    };
    let radius = u.cutoff.sqrt();
    // A hundredth of a pixel more, against rounding that differs from `place`'s.
    let reach = |v: f32| radius * v.sqrt() * 1.0001 + RECT_MARGIN + 0.01;
    let (ex, ey) = (
        reach(variance(u.cov[0][0], u.cov[0][2], sx)),
        reach(variance(u.cov[1][1], u.cov[1][2], sy)),
    );
    if !(ex.is_finite() && ey.is_finite()) {
        return None;
    }
    let (w, h) = (s.w as i32, s.h as i32);
    let lim = |v: f32, hi: i32| v.clamp(-1.0, hi as f32 + 1.0);
    let x0 = ceil(lim(left - ex - 0.5, w)).max(0);
    let x1 = floor(lim(right + ex - 0.5, w)).min(w - 1);
    let y0 = ceil(lim(top - ey - 0.5, h)).max(0);
    let y1 = floor(lim(bottom + ey - 0.5, h)).min(h - 1);
    Some([x0, y0, x1, y1])
}

/// How far, in pixels, a splat's pixel rectangle reaches past its cut-off ellipse's bounding
/// box: against rounding, so that no pixel centre the ellipse holds is left out of it. (A
/// pixel just past the ellipse that it takes in anyway gets nothing: the pixel loop tests
/// the cut-off at each pixel.)
pub(super) const RECT_MARGIN: f32 = 0.01;

/// The camera-space centre of voxel `k`.
#[inline(always)]
pub(super) fn camera_centre(u: &SplatProjection, k: [u32; 3]) -> Vec3 {
    let d = Vec3::new(k[0] as f32, k[1] as f32, k[2] as f32) - u.eye_index;
    Vec3::new(u.m[0].dot(d), u.m[1].dot(d), u.m[2].dot(d))
}

/// Where a splat falls on the screen, as the splat pass's vertex shader places it: all that
/// its camera-space centre decides, before its texel is read.
pub(super) struct Placement {
    /// The footprint (centre, widened covariance, kept share of opacity).
    pub(super) footprint: Footprint<f32>,
    /// Reversed depth.
    pub(super) depth: f32,
    /// Covered pixel rectangle, inclusive: `[x0, y0, x1, y1]`.
    pub(super) rect: [i32; 4],
}

/// The placement of a splat centred at `p` (camera space) on a `w` by `h` image; `None` where
/// the splat pass leaves it out: behind the near cut, a footprint that is not an ellipse, or
/// no pixel centre inside its cut-off ellipse's bounding box.
pub(super) fn place(u: &SplatProjection, p: Vec3, w: i32, h: i32) -> Option<Placement> {
    let depth = if u.orthographic {
        if p.z <= u.near {
            return None;
        }
        ((u.far - p.z) / (u.far - u.near)).clamp(0.0, 1.0)
    } else {
        if p.z <= u.near_cut {
            return None;
        }
        u.near / p.z
    };
    let lens = Lens {
        focal: u.focal,
        centre: u.centre,
        pixel_variance: u.pixel_variance,
        orthographic: u.orthographic,
    };
    let cov = u.cov.map(|row| row.to_array());
    let footprint = footprint(p.to_array(), &cov, &lens)?;
    let ([a, _, c], centre) = (footprint.cov, footprint.centre);
    // The cut-off ellipse's bounding box, `+-radius sqrt(a)` by `+-radius sqrt(c)` (a hair
    // wider, [`RECT_MARGIN`]), as the splat pass's quad: the pixels whose centres it holds.
    // (Half a pixel wider each way, as the quad was, the rectangle took in a band of pixels
    // past the cut-off, which take nothing: a fifth more rows and tiles walked.)
    let radius = u.cutoff.sqrt();
    let (ex, ey) = (
        radius * a.sqrt() + RECT_MARGIN,
        radius * c.sqrt() + RECT_MARGIN,
    );
    // The first and last pixel centres inside the box, clamped to the image.
    let lim = |v: f32, hi: i32| v.clamp(-1.0, hi as f32 + 1.0);
    let x0 = ceil(lim(centre[0] - ex - 0.5, w)).max(0);
    let x1 = floor(lim(centre[0] + ex - 0.5, w)).min(w - 1);
    let y0 = ceil(lim(centre[1] - ey - 0.5, h)).max(0);
    let y1 = floor(lim(centre[1] + ey - 0.5, h)).min(h - 1);
    (x0 <= x1 && y0 <= y1).then_some(Placement {
        footprint,
        depth,
        rect: [x0, y0, x1, y1],
    })
}

/// A splat on the screen, as the splat pass's vertex shader places and colours it, from its
/// voxel, camera-space centre `p` and placement; a splat left out (no texel, no opacity,
/// clipped) gets an empty rectangle.
pub(super) fn project(
    u: &SplatProjection,
    texels: &SplatTexels,
    [x, y, z]: [u32; 3],
    p: Vec3,
    at: &Placement,
) -> Projected {
    let none = Projected::NONE;
    let Some(texel) = texels.get(x, y, z) else {
        return none;
    };
    let peak = u.alpha_of(&texel);
    if peak <= 0.0 {
        return none;
    }
    if u.clip
        .iter()
        .any(|c| Vec3::new(c[0], c[1], c[2]).dot(p) > c[3])
    {
        return none;
    }
    let mut rgb = [texel[0], texel[1], texel[2]].map(|v| f32::from(v) / 255.0);
    let g = [3, 4, 5].map(|i| f32::from(texel[i] as i8));
    if u.shading > 0.0 && g != [0.0; 3] {
        let g = Vec3::from(g) / 127.0;
        let n = Vec3::new(u.normal[0].dot(g), u.normal[1].dot(g), u.normal[2].dot(g));
        let lambert = n.normalize_or_zero().z.abs();
        let scale = 1.0 - u.shading + u.shading * lambert;
        rgb = rgb.map(|v| v * scale);
    }
    let alpha = peak * at.footprint.kept;
    let [x0, y0, x1, y1] = at.rect;
    Projected {
        centre: at.footprint.centre,
        conic: at.footprint.conic(),
        color: [rgb[0] * alpha, rgb[1] * alpha, rgb[2] * alpha, alpha],
        depth: at.depth,
        cutoff: u.cutoff,
        x0,
        y0,
        x1,
        y1,
    }
}

/// `v.floor()` for values well inside `i32`'s range, without the library call that
/// `f32::floor` is on x86-64 before SSE 4.1 (a fifth of the projection's time).
pub(super) fn floor(v: f32) -> i32 {
    let i = v as i32;
    if (i as f32) > v { i - 1 } else { i }
}

/// `v.ceil()`, as [`floor`].
pub(super) fn ceil(v: f32) -> i32 {
    let i = v as i32;
    if (i as f32) < v { i + 1 } else { i }
}
