//! The view case: where the eye sits relative to the voxel grid, computed in f64.

use std::fmt;

use glam::{DMat3, DVec3};

use super::OrderError;
use crate::geometry::VolumeGeometry;

/// How the planes through the eye cut the grid (paper section 3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CaseKind {
    /// No axis split: one subvolume.
    CornerOn,
    /// One axis split: two subvolumes.
    EdgeOn,
    /// Two axes split: four subvolumes.
    FaceOn,
    /// The eye is inside the grid's extent on every axis: eight subvolumes.
    VolumeOn,
}

impl CaseKind {
    /// Lower-case name with a hyphen, as printed in reports.
    pub fn name(self) -> &'static str {
        match self {
            Self::CornerOn => "corner-on",
            Self::EdgeOn => "edge-on",
            Self::FaceOn => "face-on",
            Self::VolumeOn => "volume-on",
        }
    }
}

/// Where the eye lies along one axis, and so which way that axis runs from far to near.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AxisView {
    /// The eye is below the grid (`e < -0.5`): the far end is `n - 1`, walked downwards.
    Below,
    /// The eye is above the grid (`e > n - 0.5`): the far end is `0`, walked upwards.
    Above,
    /// The eye is within `[-0.5, n - 0.5]`, so the plane through it cuts the grid's extent. The
    /// lower side `0..kv` is walked upwards and the upper side `kv..n` downwards, both toward
    /// the eye. The plane passes through the eye itself (paper section 3), so `kv = ceil(e)`:
    /// the first voxel whose centre is not below the eye; a centre exactly on the plane goes to
    /// the upper side. (The paper's Algorithm 1 rounds to the nearest voxel instead, which moves
    /// the voxel holding the eye to the upper side even when its centre lies below the eye, and
    /// makes PBTF jump as the eye crosses `n - 0.5`.) At `e <= 0` the lower side is empty and at
    /// `e > n - 1` the upper side is.
    Split {
        /// First voxel of the upper side.
        kv: u32,
    },
}

/// Far-to-near structure of one axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisCase {
    /// Voxels along the axis.
    pub n: u32,
    /// Eye coordinate in index units.
    pub eye: f64,
    /// Where the eye lies.
    pub view: AxisView,
}

impl AxisCase {
    fn new(n: u32, eye: f64) -> Self {
        let hi = f64::from(n) - 0.5;
        let view = if eye < -0.5 {
            AxisView::Below
        } else if eye > hi {
            AxisView::Above
        } else {
            AxisView::Split {
                kv: eye.ceil() as u32,
            }
        };
        Self { n, eye, view }
    }

    /// Whether the eye lies within the axis' extent (a split plane cuts the grid).
    pub fn is_split(&self) -> bool {
        matches!(self.view, AxisView::Split { .. })
    }

    /// Whether voxels lie on both sides of the eye along this axis.
    pub fn has_two_sides(&self) -> bool {
        matches!(self.view, AxisView::Split { kv } if kv > 0 && kv < self.n)
    }

    /// Whether `a` is farther from the eye than `b` along this axis, ties going to the lower
    /// coordinate. Exact: compares the integer `a + b` with `2e`.
    #[inline]
    pub fn farther(&self, a: u32, b: u32) -> bool {
        let sum = f64::from(a) + f64::from(b);
        let twice = 2.0 * self.eye;
        match a.cmp(&b) {
            std::cmp::Ordering::Greater => sum > twice,
            std::cmp::Ordering::Less => sum <= twice,
            std::cmp::Ordering::Equal => false,
        }
    }

    /// The largest integer `c` such that a lower voxel `kl` is drawn before an upper voxel `ku`
    /// exactly when `kl + ku <= c` (the tie rule of [`AxisCase::farther`]).
    pub fn merge_threshold(&self) -> i64 {
        (2.0 * self.eye).floor() as i64
    }

    /// Appends the axis' coordinates from far to near (ties: lower coordinate first).
    pub fn far_to_near(&self, out: &mut Vec<u32>) {
        self.far_to_near_within(0, self.n, out);
    }

    /// Like [`AxisCase::far_to_near`] restricted to `lo..hi`.
    pub fn far_to_near_within(&self, lo: u32, hi: u32, out: &mut Vec<u32>) {
        match self.view {
            AxisView::Below => out.extend((lo..hi).rev()),
            AxisView::Above => out.extend(lo..hi),
            AxisView::Split { kv } => {
                let c = self.merge_threshold();
                let (mut l, l_end) = (lo, kv.clamp(lo, hi));
                let (mut u, u_end) = (hi, kv.clamp(lo, hi));
                // Lower side walks up from `lo`, upper side down from `hi - 1`.
                while l < l_end && u > u_end {
                    if i64::from(l) + i64::from(u - 1) <= c {
                        out.push(l);
                        l += 1;
                    } else {
                        u -= 1;
                        out.push(u);
                    }
                }
                out.extend(l..l_end);
                out.extend((u_end..u).rev());
            }
        }
    }
}

/// Everything the orderings need to know about one view of one grid, computed once per frame
/// in f64 from the grid, its placement and the world eye.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewCase {
    /// How the grid is cut.
    pub kind: CaseKind,
    /// Per axis: the eye and the far-to-near structure.
    pub axes: [AxisCase; 3],
    /// IP-PBTF axis nesting, slowest first. An axis with voxels on only one side of the eye goes
    /// before the split ones; within each group, the axis most nearly along the view direction
    /// comes first. So the slowest axis is never orthogonal to a split plane unless all three
    /// are split (volume-on), where it is the axis most perpendicular to the view plane.
    pub permutation: [usize; 3],
    /// WBTF axis nesting: most nearly along the view direction slowest.
    pub wbtf_permutation: [usize; 3],
    /// The eye in index coordinates.
    pub eye: DVec3,
    /// The view direction in index coordinates (not normalised).
    pub view_dir: DVec3,
    /// Normal of the plane through the eye, in index coordinates: a voxel `k` is in front of
    /// the eye when `eye_normal . (k - eye) > 0`.
    pub eye_normal: DVec3,
    /// Metric of index space: world squared distance of an index offset `d` is `d . gram d`.
    pub gram: DMat3,
}

impl ViewCase {
    /// The view of `geometry` from `eye` looking at `target` (both in world space).
    pub fn new(geometry: &VolumeGeometry, eye: DVec3, target: DVec3) -> Result<Self, OrderError> {
        if !eye.is_finite() {
            return Err(OrderError::NonFiniteEye(eye.to_array()));
        }
        if !target.is_finite() {
            return Err(OrderError::NonFiniteTarget(target.to_array()));
        }
        let forward = target - eye;
        let len = forward.length();
        if !(len > 0.0 && len.is_finite()) {
            return Err(OrderError::DegenerateView);
        }
        let forward = forward / len;
        let eye_index = geometry.world_to_index(eye);
        if !eye_index.is_finite() {
            return Err(OrderError::NonFiniteEye(eye.to_array()));
        }
        let dims = geometry.dims();
        let axes: [AxisCase; 3] = std::array::from_fn(|a| AxisCase::new(dims[a], eye_index[a]));
        let kind = match axes.iter().filter(|a| a.is_split()).count() {
            0 => CaseKind::CornerOn,
            1 => CaseKind::EdgeOn,
            2 => CaseKind::FaceOn,
            _ => CaseKind::VolumeOn,
        };
        let linear = geometry.index_to_world().matrix3;
        let alignment: [f64; 3] =
            std::array::from_fn(|a| (linear.col(a).normalize().dot(forward)).abs());
        let by_alignment = |x: &usize, y: &usize| alignment[*y].total_cmp(&alignment[*x]);
        let mut wbtf_permutation = [0, 1, 2];
        wbtf_permutation.sort_by(by_alignment);
        let mut permutation = [0, 1, 2];
        permutation.sort_by(|x, y| {
            axes[*x]
                .has_two_sides()
                .cmp(&axes[*y].has_two_sides())
                .then_with(|| by_alignment(x, y))
        });
        Ok(Self {
            kind,
            axes,
            permutation,
            wbtf_permutation,
            eye: eye_index,
            view_dir: geometry.world_dir_to_index(forward),
            eye_normal: linear.transpose() * forward,
            gram: linear.transpose() * linear,
        })
    }

    /// BTF direction of an axis: `true` when the far end is the high end (walk downwards), from
    /// the sign of the view direction; a direction orthogonal to the axis takes the end farther
    /// from the eye.
    pub fn btf_descending(&self, axis: usize) -> bool {
        let d = self.view_dir[axis];
        if d != 0.0 {
            d > 0.0
        } else {
            let a = &self.axes[axis];
            a.eye < (f64::from(a.n) - 1.0) / 2.0
        }
    }

    /// World squared distance from the eye to the centre of voxel `k`.
    #[inline]
    pub fn distance_squared(&self, k: [u32; 3]) -> f64 {
        let d = DVec3::new(
            f64::from(k[0]) - self.eye.x,
            f64::from(k[1]) - self.eye.y,
            f64::from(k[2]) - self.eye.z,
        );
        d.dot(self.gram * d)
    }

    /// Signed value of the eye plane at voxel `k`, positive in front of the eye. Monotone in
    /// each coordinate, so the voxels in front along any row form one interval.
    #[inline]
    pub fn eye_plane(&self, k: [u32; 3]) -> f64 {
        let n = self.eye_normal;
        n.x * (f64::from(k[0]) - self.eye.x)
            + n.y * (f64::from(k[1]) - self.eye.y)
            + n.z * (f64::from(k[2]) - self.eye.z)
    }
}

const AXIS_NAMES: [char; 3] = ['x', 'y', 'z'];

impl fmt::Display for ViewCase {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "view case: {} (eye in index coordinates {:.6}, {:.6}, {:.6})",
            self.kind.name(),
            self.eye.x,
            self.eye.y,
            self.eye.z
        )?;
        for (a, axis) in self.axes.iter().enumerate() {
            let name = AXIS_NAMES[a];
            match axis.view {
                AxisView::Below => writeln!(
                    f,
                    "  {name}: not split, eye below, far to near {}..0",
                    axis.n - 1
                )?,
                AxisView::Above => writeln!(
                    f,
                    "  {name}: not split, eye above, far to near 0..{}",
                    axis.n - 1
                )?,
                AxisView::Split { kv } => writeln!(
                    f,
                    "  {name}: split by the plane through the eye, upper side from voxel {kv} (ceil; a centre on the plane is upper); lower side 0..{kv} walked up, upper side {kv}..{} walked down; equal distances: lower first",
                    axis.n
                )?,
            }
        }
        let names = |p: [usize; 3]| p.map(|a| AXIS_NAMES[a].to_string()).join(",");
        write!(
            f,
            "  permutation (slowest first): IP-PBTF {}, WBTF {}, BTF z,y,x",
            names(self.permutation),
            names(self.wbtf_permutation)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn far_to_near_interleaves_by_distance() {
        let mut out = Vec::new();
        AxisCase::new(6, 1.2).far_to_near(&mut out);
        assert_eq!(out, [5, 4, 3, 0, 2, 1]);
        out.clear();
        // Eye on a voxel plane: equal distances, lower first.
        AxisCase::new(5, 2.0).far_to_near(&mut out);
        assert_eq!(out, [0, 4, 1, 3, 2]);
        out.clear();
        // Half-way: ties go lower first.
        AxisCase::new(4, 1.5).far_to_near(&mut out);
        assert_eq!(out, [0, 3, 1, 2]);
        out.clear();
        AxisCase::new(4, -3.0).far_to_near(&mut out);
        assert_eq!(out, [3, 2, 1, 0]);
    }

    #[test]
    fn boundary_eyes_keep_one_side_empty() {
        let at_low = AxisCase::new(4, -0.5);
        assert_eq!(at_low.view, AxisView::Split { kv: 0 });
        assert!(!at_low.has_two_sides());
        let at_high = AxisCase::new(4, 3.5);
        assert_eq!(at_high.view, AxisView::Split { kv: 4 });
        let mut a = Vec::new();
        let mut b = Vec::new();
        at_high.far_to_near(&mut a);
        AxisCase::new(4, 3.5 + 1e-9).far_to_near(&mut b);
        assert_eq!(a, b);
    }

    #[test]
    fn far_origin_keeps_the_split() {
        let geometry = VolumeGeometry::axis_aligned([8, 8, 8], [1.0; 3], [1e5; 3]).unwrap();
        let target = geometry.centre_world();
        for (offset, kv) in [(2.9995, 3), (3.0005, 4)] {
            let eye = DVec3::new(1e5 + offset, 1e5 - 1.0, 1e5 - 1.0);
            let view = ViewCase::new(&geometry, eye, target).unwrap();
            assert_eq!(view.axes[0].view, AxisView::Split { kv });
            assert_eq!(view.kind, CaseKind::EdgeOn);
        }
        // The same offsets in f32 collapse onto one value.
        assert_eq!((1e5f32 + 2.9995) - 1e5, (1e5f32 + 3.0005) - 1e5);
    }
}
