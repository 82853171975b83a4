//! The exact cross-section of a mesh by a plane: every triangle that crosses it gives a
//! segment, and segments that meet on a mesh edge are joined into polylines (closed loops for
//! a closed mesh).
//!
//! A vertex on the plane counts as lying on its positive side, so that no vertex is ever "on"
//! the plane: each crossing lies inside an edge whose ends lie on either side, and the two
//! triangles sharing that edge find the same point. Edges are keyed by their ends' positions
//! (exact bits), which joins meshes stored with a vertex per triangle corner (STL) as well as
//! indexed ones.

use std::collections::HashMap;

use glam::{DMat4, DVec3};

use super::Plane;
use crate::scene::{NodeId, Scene};

/// The cross-section of one object (a top node holding meshes) by a plane.
#[derive(Debug, Clone, PartialEq)]
pub struct Outline {
    /// The object's node.
    pub node: NodeId,
    /// Its name.
    pub name: String,
    /// The base colour of its first mesh (linear RGBA).
    pub color: [f32; 4],
    /// The polylines, in world coordinates, each with whether it closes on itself (its last
    /// point joined to its first, which is not repeated).
    pub polylines: Vec<(Vec<DVec3>, bool)>,
    /// The outline's length in millimetres.
    pub length_mm: f64,
    /// The area its closed polylines enclose in square millimetres: within each mesh a loop
    /// inside another taken out of it (even-odd: a tube's wall, not its bore), whatever way
    /// the triangles wind; across the object's meshes their union.
    pub area_mm2: f64,
}

/// The cross-sections by `plane` of the scene's objects that it cuts (overlays left out).
pub fn outlines(scene: &Scene, plane: &Plane) -> Vec<Outline> {
    let mut by_top: Vec<(NodeId, Vec<Segment>, [f32; 4])> = Vec::new();
    for (id, mesh, world) in scene.meshes() {
        let top = scene.top_node(id);
        let segments = mesh_segments(&mesh.mesh.positions, &mesh.mesh.indices, world, plane, id);
        match by_top.iter_mut().find(|(t, _, _)| *t == top) {
            Some((_, all, _)) => all.extend(segments),
            None => by_top.push((top, segments, mesh.material.base_color)),
        }
    }
    by_top
        .into_iter()
        .filter(|(_, segments, _)| !segments.is_empty())
        .map(|(node, segments, color)| {
            let length_mm = segments.iter().map(|s| (s.b - s.a).length()).sum();
            let joined = join(&segments);
            let area_mm2 = enclosed_area(&joined, plane);
            let polylines = joined
                .into_iter()
                .map(|(p, closed, _)| (p, closed))
                .collect();
            Outline {
                node,
                name: scene
                    .node(node)
                    .map_or_else(|_| String::new(), |n| n.name.clone()),
                color,
                polylines,
                length_mm,
                area_mm2,
            }
        })
        .collect()
}

/// The area the closed loops enclose: within each mesh (part) of the object by the even-odd
/// rule (a loop inside another is a hole), across its parts the union (a head that overlaps
/// its neck counts once). Integrated exactly band by band between the loops' corners, where
/// the covered length of a line across the section is linear, save in the few bands where two
/// parts' edges cross.
fn enclosed_area(polylines: &[(Vec<DVec3>, bool, usize)], plane: &Plane) -> f64 {
    // Edges (in plane coordinates) with their part.
    let mut edges: Vec<([f64; 2], [f64; 2], usize)> = Vec::new();
    for (points, closed, part) in polylines {
        if !*closed || points.len() < 3 {
            continue;
        }
        let flat: Vec<[f64; 2]> = points
            .iter()
            .map(|p| {
                let d = *p - plane.point;
                [d.dot(plane.right), d.dot(plane.down)]
            })
            .collect();
        for (a, b) in flat.iter().zip(flat.iter().cycle().skip(1)) {
            if a[1] != b[1] {
                edges.push(if a[1] < b[1] {
                    (*a, *b, *part)
                } else {
                    (*b, *a, *part)
                });
            }
        }
    }
    if edges.is_empty() {
        return 0.0;
    }
    edges.sort_by(|e, f| e.0[1].total_cmp(&f.0[1]));
    let mut ys: Vec<f64> = edges.iter().flat_map(|e| [e.0[1], e.1[1]]).collect();
    ys.sort_by(f64::total_cmp);
    ys.dedup();
    let mut area = 0.0;
    let mut next = 0;
    let mut active: Vec<([f64; 2], [f64; 2], usize)> = Vec::new();
    let mut crossings: Vec<(usize, f64)> = Vec::new();
    let mut spans: Vec<(f64, f64)> = Vec::new();
    for band in ys.windows(2) {
        let y = 0.5 * (band[0] + band[1]);
        while next < edges.len() && edges[next].0[1] < y {
            active.push(edges[next]);
            next += 1;
        }
        active.retain(|e| e.1[1] > y);
        crossings.clear();
        crossings.extend(
            active
                .iter()
                .map(|(a, b, part)| (*part, a[0] + (y - a[1]) / (b[1] - a[1]) * (b[0] - a[0]))),
        );
        crossings.sort_by(|p, q| p.0.cmp(&q.0).then(p.1.total_cmp(&q.1)));
        // Each part's inside, even-odd: its crossings paired in order.
        spans.clear();
        for pair in crossings.chunks_exact(2) {
            if pair[0].0 == pair[1].0 {
                spans.push((pair[0].1, pair[1].1));
            }
        }
        // The union of the parts' spans.
        spans.sort_by(|p, q| p.0.total_cmp(&q.0));
        let mut covered = 0.0;
        let mut reach = f64::NEG_INFINITY;
        for &(lo, hi) in &spans {
            let lo = lo.max(reach);
            if hi > lo {
                covered += hi - lo;
                reach = hi;
            }
        }
        area += covered * (band[1] - band[0]);
    }
    area
}

/// An edge of a mesh: its node and its ends' positions (exact bits), lesser end first.
type EdgeKey = (usize, [u32; 3], [u32; 3]);

/// A piece of the section: from `a` to `b`, which lie on the edges `ka` and `kb`.
#[derive(Debug, Clone, Copy)]
struct Segment {
    a: DVec3,
    b: DVec3,
    ka: EdgeKey,
    kb: EdgeKey,
}

fn mesh_segments(
    positions: &[[f32; 3]],
    indices: &[u32],
    world: DMat4,
    plane: &Plane,
    node: NodeId,
) -> Vec<Segment> {
    let mut out = Vec::new();
    for t in indices.chunks_exact(3) {
        let Some(local) = t
            .iter()
            .map(|&i| positions.get(i as usize).copied())
            .collect::<Option<Vec<[f32; 3]>>>()
        else {
            continue;
        };
        let p: Vec<DVec3> = local
            .iter()
            .map(|v| world.transform_point3(DVec3::from(v.map(f64::from))))
            .collect();
        let d: Vec<f64> = p.iter().map(|&q| plane.distance(q)).collect();
        if d.iter().any(|v| !v.is_finite()) {
            continue;
        }
        let side: Vec<bool> = d.iter().map(|&v| v >= 0.0).collect();
        let mut cuts = Vec::with_capacity(2);
        for (i, j) in [(0, 1), (1, 2), (2, 0)] {
            if side[i] == side[j] {
                continue;
            }
            let s = d[i] / (d[i] - d[j]);
            let point = p[i] + (p[j] - p[i]) * s;
            let (bi, bj) = (local[i].map(f32::to_bits), local[j].map(f32::to_bits));
            let key = if bi <= bj {
                (node.0, bi, bj)
            } else {
                (node.0, bj, bi)
            };
            cuts.push((point, key));
        }
        let [(a, ka), (b, kb)] = cuts[..] else {
            continue;
        };
        out.push(Segment { a, b, ka, kb });
    }
    out
}

/// Segments joined end to end where they share an edge, each chain followed both ways from
/// where it starts; with whether it closes and the node of its mesh.
fn join(segments: &[Segment]) -> Vec<(Vec<DVec3>, bool, usize)> {
    let mut at: HashMap<EdgeKey, Vec<usize>> = HashMap::new();
    for (i, s) in segments.iter().enumerate() {
        at.entry(s.ka).or_default().push(i);
        at.entry(s.kb).or_default().push(i);
    }
    let mut used = vec![false; segments.len()];
    let mut out = Vec::new();
    for start in 0..segments.len() {
        if used[start] {
            continue;
        }
        used[start] = true;
        let s = segments[start];
        // Forward from `b` until the chain ends or comes back to `a`, then backward from `a`.
        let mut forward = vec![s.a, s.b];
        let closed = walk(segments, &at, &mut used, s.kb, Some(s.ka), &mut forward);
        if !closed {
            let mut backward = Vec::new();
            walk(segments, &at, &mut used, s.ka, None, &mut backward);
            backward.reverse();
            backward.extend(forward);
            forward = backward;
        }
        out.push((forward, closed, s.ka.0));
    }
    out
}

/// Follows the chain of unused segments from edge `key`, pushing each next point, until it
/// ends or reaches edge `home` (then `true`: the chain closed).
fn walk(
    segments: &[Segment],
    at: &HashMap<EdgeKey, Vec<usize>>,
    used: &mut [bool],
    mut key: EdgeKey,
    home: Option<EdgeKey>,
    points: &mut Vec<DVec3>,
) -> bool {
    while let Some(next) = take_next(at, used, key) {
        let n = segments[next];
        let (point, other) = if n.ka == key {
            (n.b, n.kb)
        } else {
            (n.a, n.ka)
        };
        if Some(other) == home {
            return true;
        }
        points.push(point);
        key = other;
    }
    false
}

/// An unused segment with an end on edge `key`, marked used.
fn take_next(at: &HashMap<EdgeKey, Vec<usize>>, used: &mut [bool], key: EdgeKey) -> Option<usize> {
    let next = *at.get(&key)?.iter().find(|&&i| !used[i])?;
    used[next] = true;
    Some(next)
}
