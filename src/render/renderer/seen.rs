//! Which of a grid's bricks a view shows: the own grid drawn alone, brick by brick, before a
//! refinement, so that the refinement classifies the bricks that show and leaves out those
//! hidden behind opaque tissue. A close-up of a thick-slice CT refines its grid by up to
//! 5 x 5 x 4, and of the refined splats on the image most lie behind the skin or the bone
//! (BENCHMARKS.md, "A refinement classifies only the bricks a view shows"). On by default
//! (`Renderer::set_refinement_where_seen`): each view looks once, and the refinement is drawn
//! within the bricks its view shows, so that the picture depends on the view alone.

use glam::DMat4;

use super::detail::{Detail, REGION_BRICK, brick_order};
use super::{ViewSetup, VolumeState};
use crate::classify::Region;
use crate::order::{OrderOptions, Orderer, Ordering, ViewCase};
use crate::scene::{Clipping, SplatSettings};
use crate::splat::tiled::{Run, SplatProjection, TiledCompositor};

/// What the bricks a view shows depend on: the view, the node's placement and splat settings,
/// and the scene's clip planes (the own grid and its classification are the refinement's).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct SeenFor {
    pub(super) view: ViewSetup,
    pub(super) world: DMat4,
    pub(super) splats: SplatSettings,
    pub(super) clipping: Clipping,
}

/// The opacity past which a pixel of the own grid's picture counts as hiding what lies behind
/// it: deeper into the tissue than the compositor's own [`crate::splat::tiled::OPAQUE`]
/// (optical depth 9.2 against 5.5), so that a refinement, whose splats are narrower and whose
/// field is sharper than the own grid's, is opaque there too.
pub(super) const SEEN_OPAQUE: f32 = 0.9999;

/// The bricks of [`REGION_BRICK`]^3 voxels of `own` (a volume's own grid, its texels made)
/// among `shown` (`None`: all of them) that add to the image when the grid alone is drawn
/// through `projection` in `view` (its node placed by `world`), with the bricks next to one of
/// them (across a face, an edge or a corner) that hold no splat: a fine voxel's cell samples
/// the coarse voxels around it, so a refinement can put splats there. `Ok(None)` where the own
/// grid has no texels.
///
/// The meshes and the other volumes are left out of the drawing: they can only hide more, so
/// a brick they hide is kept, never a brick they would show left out. A brick that holds no
/// splat is never seen alone: its neighbours bring it in where a refinement could put splats
/// in it.
pub(super) fn seen_bricks(
    tiles: &mut TiledCompositor,
    own: &VolumeState,
    world: DMat4,
    view: &ViewSetup,
    projection: &SplatProjection,
    shown: Option<&Region>,
) -> Result<Option<Region>, String> {
    let Some(texels) = &own.texels else {
        return Ok(None);
    };
    let geometry = own.geometry(world).map_err(|e| e.to_string())?;
    let dims = geometry.dims();
    let n = dims.map(|d| d.div_ceil(REGION_BRICK));
    let mut bricks: Vec<([u32; 3], Detail)> = Vec::new();
    for z in 0..n[2] {
        for y in 0..n[1] {
            for x in 0..n[0] {
                if shown.is_none_or(|r| r.covers_brick([x, y, z])) {
                    bricks.push(([x, y, z], Detail::default()));
                }
            }
        }
    }
    let (eye, target) = (view.camera.eye, view.camera.target);
    brick_order(&geometry, eye, target, REGION_BRICK, &mut bricks).map_err(|e| e.to_string())?;
    let boxes: Vec<[(u32, u32); 3]> = bricks
        .iter()
        .map(|(b, _)| {
            std::array::from_fn(|a| {
                (
                    b[a] * REGION_BRICK,
                    ((b[a] + 1) * REGION_BRICK).min(dims[a]),
                )
            })
        })
        .collect();
    let case = ViewCase::new(&geometry, eye, target).map_err(|e| e.to_string())?;
    let options = OrderOptions {
        cull_behind_eye: true,
        ..Default::default()
    };
    let (mut ids, mut ends) = (Vec::new(), Vec::new());
    // IP-PBTF whatever the node draws with: any visibility order shows the same bricks.
    Orderer::order_boxes(
        &own.classified.grid,
        &case,
        Ordering::IpPbtfImplicit,
        &options,
        &boxes,
        &mut ids,
        &mut ends,
    )
    .map_err(|e| e.to_string())?;
    // One run a brick that holds splats, far to near.
    let mut runs = Vec::new();
    let mut of_run = Vec::new();
    let mut start = 0;
    for (i, &end) in ends.iter().enumerate() {
        if end > start {
            runs.push(Run {
                source: 0,
                ids: &ids[start..end],
            });
            of_run.push(i);
        }
        start = end;
    }
    let mut seen = vec![false; runs.len()];
    let (w, h) = (view.size.0 as usize, view.size.1 as usize);
    let depth = vec![0.0f32; w * h];
    let mut under = vec![[0.0f32; 4]; w * h];
    let opaque = std::mem::replace(&mut tiles.opaque, SEEN_OPAQUE);
    tiles.composite_runs_seen(
        view.size,
        &[(projection, texels)],
        &runs,
        &depth,
        &mut under,
        &mut seen,
    );
    tiles.opaque = opaque;
    // The bricks seen and their neighbours that hold no splat, among those shown.
    let index = |b: [u32; 3]| (b[0] + n[0] * (b[1] + n[1] * b[2])) as usize;
    let count = n.iter().map(|&c| c as usize).product();
    let mut holds = vec![false; count];
    for &i in &of_run {
        holds[index(bricks[i].0)] = true;
    }
    let mut marked = vec![false; count];
    for (run, _) in seen.iter().enumerate().filter(|(_, s)| **s) {
        let b = bricks[of_run[run]].0;
        marked[index(b)] = true;
        for dz in 0..3u32 {
            for dy in 0..3u32 {
                for dx in 0..3u32 {
                    let c = [b[0] + dx, b[1] + dy, b[2] + dz];
                    if (0..3).all(|a| c[a] >= 1 && c[a] - 1 < n[a]) {
                        let i = index(c.map(|v| v - 1));
                        marked[i] |= !holds[i];
                    }
                }
            }
        }
    }
    Ok(Region::new(dims, REGION_BRICK, |b| {
        marked[index(b)] && shown.is_none_or(|r| r.covers_brick(b))
    }))
}
