//! Clipping: up to six planes and a crop box in world space. Splats whose voxel centre is cut
//! away vanish (the order of the rest is unchanged: the draw order is the same list with the
//! clipped voxels skipped); meshes are cut too where a plane or the box says so. Picking
//! respects the same cuts.

use glam::DVec3;

/// The most planes a scene may have (the crop box comes on top).
pub const MAX_CLIP_PLANES: usize = 6;

/// The most planes in force at once ([`Clipping::all_planes`]): the scene's and the crop box's
/// six. The shaders' plane arrays are sized from it.
pub const MAX_PLANES_IN_FORCE: usize = MAX_CLIP_PLANES + 6;

/// A plane that keeps the half-space `normal . p <= offset` and cuts away the rest.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClipPlane {
    /// Points out of the kept half-space (need not be unit length).
    pub normal: DVec3,
    /// Kept where `normal . p <= offset`.
    pub offset: f64,
    /// Whether meshes are cut too (splats always are).
    pub meshes: bool,
}

impl ClipPlane {
    /// The plane through `point` cutting away the side `normal` points to.
    pub fn through(point: DVec3, normal: DVec3, meshes: bool) -> Self {
        Self {
            normal,
            offset: normal.dot(point),
            meshes,
        }
    }

    /// Whether `p` is kept.
    pub fn keeps(&self, p: DVec3) -> bool {
        self.normal.dot(p) <= self.offset
    }
}

/// A scene's clipping.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Clipping {
    /// Clip planes (the first [`MAX_CLIP_PLANES`] are used).
    pub planes: Vec<ClipPlane>,
    /// Keep only what lies inside this world box `(min, max)`.
    pub crop: Option<(DVec3, DVec3)>,
    /// Whether the crop box cuts meshes too.
    pub crop_meshes: bool,
}

impl Clipping {
    /// Every plane in force, the crop box as six of them.
    pub fn all_planes(&self) -> Vec<ClipPlane> {
        let mut planes: Vec<ClipPlane> =
            self.planes.iter().take(MAX_CLIP_PLANES).copied().collect();
        if let Some((lo, hi)) = self.crop {
            for axis in [DVec3::X, DVec3::Y, DVec3::Z] {
                planes.push(ClipPlane::through(hi, axis, self.crop_meshes));
                planes.push(ClipPlane::through(lo, -axis, self.crop_meshes));
            }
        }
        planes
    }

    /// Whether a voxel centre at `p` is kept.
    pub fn keeps_splat(&self, p: DVec3) -> bool {
        self.all_planes().iter().all(|c| c.keeps(p))
    }

    /// Whether a mesh point at `p` is kept.
    pub fn keeps_mesh(&self, p: DVec3) -> bool {
        self.all_planes()
            .iter()
            .filter(|c| c.meshes)
            .all(|c| c.keeps(p))
    }

    /// Whether nothing is clipped.
    pub fn is_empty(&self) -> bool {
        self.planes.is_empty() && self.crop.is_none()
    }

    /// The box around what the planes keep of the world box `(lo, hi)`: of a mesh's box
    /// (`mesh`, the planes that cut meshes) or a volume's (every plane); `None` when nothing
    /// is kept. Exact for the crop box and for one plane; for several oblique planes, a box
    /// around the part each cut leaves, in turn (the crop box first).
    pub fn cut_box(&self, lo: DVec3, hi: DVec3, mesh: bool) -> Option<(DVec3, DVec3)> {
        // The box's own faces first: each cut is then exact until the first oblique plane.
        let mut planes = self.all_planes();
        planes.sort_by_key(|p| p.normal.abs().max_element() != p.normal.abs().element_sum());
        planes
            .iter()
            .filter(|p| !mesh || p.meshes)
            .try_fold((lo, hi), cut)
    }
}

/// The box around the part of the box `(lo, hi)` that `plane` keeps: its kept corners and
/// where its edges cross the plane.
fn cut((lo, hi): (DVec3, DVec3), plane: &ClipPlane) -> Option<(DVec3, DVec3)> {
    let corners = super::box_corners(lo, hi);
    let side = corners.map(|c| plane.normal.dot(c) - plane.offset);
    let mut kept: Option<(DVec3, DVec3)> = None;
    let mut add = |p: DVec3| {
        kept = Some(kept.map_or((p, p), |(a, b)| (a.min(p), b.max(p))));
    };
    for (c, d) in corners.iter().zip(side) {
        if d <= 0.0 {
            add(*c);
        }
    }
    // The 12 edges join corners whose indices differ in one bit.
    for i in 0..8 {
        for bit in [1, 2, 4] {
            let j = i | bit;
            if j == i || (side[i] <= 0.0) == (side[j] <= 0.0) {
                continue;
            }
            let t = side[i] / (side[i] - side[j]);
            add(corners[i] + t * (corners[j] - corners[i]));
        }
    }
    kept
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn planes_and_the_crop_box_keep_their_insides() {
        let clip = Clipping {
            planes: vec![ClipPlane::through(
                DVec3::new(0.0, 5.0, 0.0),
                DVec3::Y,
                false,
            )],
            crop: Some((DVec3::splat(-10.0), DVec3::splat(10.0))),
            crop_meshes: true,
        };
        assert_eq!(clip.all_planes().len(), 7);
        assert!(clip.keeps_splat(DVec3::new(0.0, 4.9, 0.0)));
        assert!(!clip.keeps_splat(DVec3::new(0.0, 5.1, 0.0)));
        assert!(
            clip.keeps_mesh(DVec3::new(0.0, 5.1, 0.0)),
            "the plane spares meshes"
        );
        assert!(
            !clip.keeps_mesh(DVec3::new(0.0, 0.0, 10.5)),
            "the box does not"
        );
        assert!(!clip.keeps_splat(DVec3::new(-10.5, 0.0, 0.0)));
        assert!(
            Clipping::default().is_empty() && Clipping::default().keeps_splat(DVec3::splat(1e9))
        );
    }

    #[test]
    fn a_cut_box_holds_exactly_what_is_kept() {
        let clip = Clipping {
            planes: vec![ClipPlane::through(
                DVec3::ZERO,
                DVec3::new(1.0, 1.0, 0.0),
                false,
            )],
            crop: Some((DVec3::new(-5.0, -20.0, -20.0), DVec3::new(20.0, 20.0, 3.0))),
            crop_meshes: false,
        };
        let (lo, hi) = (DVec3::splat(-10.0), DVec3::splat(10.0));
        // A volume: the crop box leaves x >= -5 and z <= 3; the plane x + y <= 0 then leaves
        // y <= 5 at x = -5, and x <= 10 at y = -10.
        let (a, b) = clip.cut_box(lo, hi, false).unwrap();
        assert!(a.abs_diff_eq(DVec3::new(-5.0, -10.0, -10.0), 1e-12), "{a}");
        assert!(b.abs_diff_eq(DVec3::new(10.0, 5.0, 3.0), 1e-12), "{b}");
        // A mesh: neither the plane nor the box cuts it.
        assert_eq!(clip.cut_box(lo, hi, true), Some((lo, hi)));
        // Nothing kept.
        let away = Clipping {
            crop: Some((DVec3::splat(50.0), DVec3::splat(60.0))),
            ..Clipping::default()
        };
        assert_eq!(away.cut_box(lo, hi, false), None);
    }
}
