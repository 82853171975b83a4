//! The voxel walk: from where a ray enters the grid, voxel by voxel in the order the ray
//! crosses them (Amanatides & Woo 1987), to the first voxel whose opacity exceeds a threshold.

use glam::DVec3;

use super::{Ray, VolumeHit};
use crate::geometry::VolumeGeometry;
use crate::scene::{Clipping, NodeId, VolumeNode};

/// The first voxel of `node` along `ray`, nearer than `max_distance`, whose opacity under the
/// node's transfer function exceeds `threshold` and whose centre `clipping` keeps (as the
/// renderer keeps its splat). Voxel `k` fills the cell `k - 0.5 .. k + 0.5` in index space.
pub fn march_volume(
    id: NodeId,
    node: &VolumeNode,
    geometry: &VolumeGeometry,
    ray: &Ray,
    (threshold, max_distance): (f32, f64),
    clipping: &Clipping,
) -> Option<VolumeHit> {
    walk_kept(
        node,
        geometry,
        ray,
        max_distance,
        clipping,
        |k, t, value, opacity| {
            (opacity > threshold).then(|| VolumeHit {
                node: id,
                voxel: k.map(|v| v as u32),
                point: ray.at(t).to_array(),
                value,
                opacity,
                distance: t,
            })
        },
    )
}

/// The distance along `ray` at which the opacity of `node`'s voxels, accumulated front to back
/// over the voxels the ray crosses (`A += (1 - A) a`, each voxel's transfer-function opacity
/// once, clipped voxels left out), first reaches `threshold`: the volume's first surface.
pub fn first_surface(
    node: &VolumeNode,
    geometry: &VolumeGeometry,
    ray: &Ray,
    (threshold, max_distance): (f32, f64),
    clipping: &Clipping,
) -> Option<f64> {
    let mut accumulated = 0.0f32;
    walk_kept(
        node,
        geometry,
        ray,
        max_distance,
        clipping,
        |_, t, _, opacity| {
            accumulated += (1.0 - accumulated) * opacity.clamp(0.0, 1.0);
            (accumulated >= threshold).then_some(t)
        },
    )
}

/// Walks the voxels `ray` crosses, nearest first, and returns the first answer `visit` gives
/// for a voxel that `clipping` keeps; `visit` sees the voxel, the distance where the ray enters
/// it, its value and its opacity.
fn walk_kept<T>(
    node: &VolumeNode,
    geometry: &VolumeGeometry,
    ray: &Ray,
    max_distance: f64,
    clipping: &Clipping,
    mut visit: impl FnMut([i64; 3], f64, f32, f32) -> Option<T>,
) -> Option<T> {
    let dims = geometry.dims();
    let o = geometry.world_to_index(ray.origin);
    let d = geometry.world_dir_to_index(ray.direction);
    let (mut t, t_exit) = enter_grid(o, d, dims)?;
    t = t.max(ray.t_min);
    if t >= t_exit.min(max_distance) {
        return None;
    }
    let start = o + d * t;
    let mut k: [i64; 3] = std::array::from_fn(|a| {
        (start[a] + 0.5)
            .floor()
            .clamp(0.0, f64::from(dims[a]) - 1.0) as i64
    });
    let mut step = [0i64; 3];
    let mut t_next = [f64::INFINITY; 3];
    let mut t_delta = [f64::INFINITY; 3];
    for a in 0..3 {
        if d[a] != 0.0 {
            step[a] = if d[a] > 0.0 { 1 } else { -1 };
            let boundary = k[a] as f64 + 0.5 * step[a] as f64;
            t_next[a] = (boundary - o[a]) / d[a];
            t_delta[a] = 1.0 / d[a].abs();
        }
    }
    let [nx, ny, _] = dims.map(|n| n as usize);
    let limit = t_exit.min(max_distance);
    let planes = clipping.all_planes();
    let steps = dims.iter().map(|&n| n as usize).sum::<usize>() + 3;
    for _ in 0..steps {
        let [x, y, z] = k.map(|v| v as usize);
        let value = node
            .volume
            .values
            .get(x + nx * (y + ny * z))
            .unwrap_or(f32::NAN);
        let opacity = node.transfer.sample(value)[3];
        let kept = || {
            let centre = DVec3::new(k[0] as f64, k[1] as f64, k[2] as f64);
            let p = geometry.index_to_world_point(centre);
            planes.iter().all(|c| c.keeps(p))
        };
        if opacity > 0.0
            && kept()
            && let Some(answer) = visit(k, t, value, opacity)
        {
            return Some(answer);
        }
        let a = (0..3).min_by(|&i, &j| t_next[i].total_cmp(&t_next[j]))?;
        t = t_next[a];
        if t >= limit {
            return None;
        }
        k[a] += step[a];
        if k[a] < 0 || k[a] >= i64::from(dims[a]) {
            return None;
        }
        t_next[a] += t_delta[a];
    }
    None
}

/// Where the ray `o + t d` enters and leaves the grid's box `[-0.5, n - 0.5]` on every axis.
fn enter_grid(o: DVec3, d: DVec3, dims: [u32; 3]) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    for a in 0..3 {
        let (lo, hi) = (-0.5, f64::from(dims[a]) - 0.5);
        if d[a] == 0.0 {
            if o[a] < lo || o[a] > hi {
                return None;
            }
            continue;
        }
        let (ta, tb) = ((lo - o[a]) / d[a], (hi - o[a]) / d[a]);
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
    }
    // The direction is not zero, so some axis bounds t0 and t1.
    (t0 <= t1 && t1 >= 0.0).then_some((t0.max(0.0), t1))
}
