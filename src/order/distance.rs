//! World squared distances from the eye to voxel centres, computed the same way whatever order
//! the voxels are visited in (so that two passes over the grid agree bit for bit).

use glam::DMat3;
use rdst::RadixKey;

use super::view::ViewCase;

/// Whether a metric has (numerically) no cross terms: the grid axes are orthogonal in the world.
pub(crate) fn is_orthogonal(g: &DMat3) -> bool {
    let scale = g.x_axis.x.max(g.y_axis.y).max(g.z_axis.z);
    [g.y_axis.x, g.z_axis.x, g.z_axis.y]
        .iter()
        .all(|v| v.abs() <= 1e-12 * scale)
}

/// Per-axis tables of squared distance terms when the grid axes are orthogonal in the world,
/// the full quadratic form otherwise.
#[derive(Debug, Clone, Default)]
pub(crate) struct DistanceTable {
    terms: [Vec<f64>; 3],
    orthogonal: bool,
    view: Option<ViewCase>,
}

/// The squared world distance along axis `a` from the eye's plane to each voxel coordinate,
/// `g_aa (k - e_a)^2`: summed over the three axes, a voxel's squared distance when the axes are
/// orthogonal.
pub(crate) fn axis_terms(view: &ViewCase, a: usize) -> impl Iterator<Item = f64> + '_ {
    let axis = &view.axes[a];
    let weight = view.gram.col(a)[a];
    (0..axis.n).map(move |k| {
        let d = f64::from(k) - axis.eye;
        weight * d * d
    })
}

impl DistanceTable {
    pub(crate) fn prepare(&mut self, view: &ViewCase) {
        self.orthogonal = is_orthogonal(&view.gram);
        self.view = Some(*view);
        for (a, terms) in self.terms.iter_mut().enumerate() {
            terms.clear();
            if self.orthogonal {
                terms.extend(axis_terms(view, a));
            }
        }
    }

    #[inline]
    pub(crate) fn distance_squared(&self, k: [u32; 3]) -> f64 {
        if self.orthogonal {
            (self.terms[0][k[0] as usize] + self.terms[1][k[1] as usize])
                + self.terms[2][k[2] as usize]
        } else {
            self.view.as_ref().map_or(0.0, |v| v.distance_squared(k))
        }
    }
}

/// A radix-sort key that puts the larger squared distance first and, among equal distances,
/// the lower index first.
#[derive(Debug, Clone, Copy)]
pub(crate) struct FarthestFirst {
    inverted_distance: u64,
    /// The voxel id or row index the key belongs to.
    pub index: u32,
}

impl FarthestFirst {
    /// The key of `index` at squared distance `q` (negative values and -0 count as 0).
    #[inline]
    pub fn new(q: f64, index: u32) -> Self {
        // Non-negative floats order like their bit patterns.
        let q = if q > 0.0 { q } else { 0.0 };
        Self {
            inverted_distance: !q.to_bits(),
            index,
        }
    }
}

impl RadixKey for FarthestFirst {
    const LEVELS: usize = 12;

    #[inline]
    fn get_level(&self, level: usize) -> u8 {
        // rdst reads levels from the least significant byte up.
        if level < 4 {
            (self.index >> (level * 8)) as u8
        } else {
            (self.inverted_distance >> ((level - 4) * 8)) as u8
        }
    }
}
