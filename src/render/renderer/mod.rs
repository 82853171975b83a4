//! The renderer: keeps GPU copies of what the scene holds, builds each pipeline only when the
//! scene has content for it, and records a frame as a mesh pass then a splat pass.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::{DMat3, DMat4, DVec3};
use rayon::prelude::*;

use super::mesh_pass::{GpuMesh, MeshPass};
use super::splat_pass::{GpuVolume, SplatPass, projection};
use super::target::{PixelRect, RenderTarget};
use super::tile_pass::TilePass;
use super::view::ViewSetup;
use super::{GpuContext, RenderError};
use crate::classify::{Classified, ClassifyOptions, Front, Opacity, Region, classify_refined_in};
use crate::geometry::{GeometryError, VolumeGeometry};
use crate::order::{OrderOptions, Orderer, Ordering, ViewCase};
use crate::scene::{
    NodeId, Scene, SceneCamera, VolumeNode, placed_geometry, placed_grid, volume_placement,
};
use crate::splat::reference::Frame;
use crate::splat::tiled::{Run, SplatTexels, TileStats, TiledCompositor};
use crate::volume::CpuVolume;

mod detail;
mod fewer_pixels;
mod seen;

use detail::*;
pub use detail::{
    Detail, MAX_DEPTH_LEVELS, MAX_LEVEL, MAX_REFINE, MAX_REFINED_VOXELS, REFINE_TO, detail_for,
    pixels_apart, preview_level,
};
use seen::seen_bricks;

/// Per-frame choices that are not part of the scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameOptions {
    /// Draw every volume in this order instead of its node's own.
    pub ordering: Option<Ordering>,
    /// Opaque background colour (linear RGB); `None` for a transparent background.
    pub background: Option<[f32; 3]>,
    /// Wait for the GPU after each stage so that [`FrameTimings`] splits the frame (costs a
    /// little throughput; screenshots and benchmarks want it, a window does not).
    pub measure: bool,
    /// A preview's coarseness: 0 for a full frame; `n` draws every volume `n - 1` levels of
    /// detail coarser than the view calls for, and at least `n` above its own grid (see
    /// [`Renderer::set_level_of_detail`], [`preview_level`]), never refined. Each level is
    /// about an eighth of the splats of the one below it, each twice as large: a frame whose
    /// grid is finer than its pixels costs about half as much a level. For frames while the
    /// camera moves; each level is made once and kept beside the full grid.
    pub preview: u8,
    /// The volumes composited at the frame's size divided by this (rounded up; 1, the
    /// default, for the frame's own pixels), their levels of detail chosen for those pixels,
    /// and laid over the meshes, drawn at the frame's size, by their depth: the meshes' edges
    /// stay sharp at a fraction of the splats' cost. For previews of the CPU tile compositor
    /// (the GPU passes refuse any other value than 1); 0 is refused.
    pub volume_divisor: u32,
}

impl Default for FrameOptions {
    fn default() -> Self {
        Self {
            ordering: None,
            background: Some([0.06, 0.07, 0.09]),
            measure: true,
            preview: 0,
            volume_divisor: 1,
        }
    }
}

/// Wall-clock time of each stage of a frame (stages overlap unless measured).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrameTimings {
    /// Classification (only on frames where a volume or transfer function changed).
    pub classify: Duration,
    /// Making levels of detail from the classification (only on frames that draw a level
    /// not made yet).
    pub levels: Duration,
    /// Making the splats' texels for the CPU tile compositor (only on frames that draw a grid
    /// whose texels are not made yet).
    pub texels: Duration,
    /// Drawing a volume's own grid alone to find the bricks a refinement shows (only on frames
    /// whose view the refinement has not looked for, [`Renderer::set_refinement_where_seen`]).
    pub seen: Duration,
    /// Computing the draw orders on the CPU.
    pub order: Duration,
    /// Writing the draw orders and uniforms to the GPU.
    pub upload: Duration,
    /// The mesh pass (or the clear, without meshes).
    pub mesh_pass: Duration,
    /// The splat pass.
    pub splat_pass: Duration,
    /// Copying the image back (screenshots only).
    pub readback: Duration,
}

/// What the renderer built and drew; the way to check that a scene without meshes builds no
/// mesh pipeline, and one without a volume no splat pipeline.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrameReport {
    /// Whether the mesh pipeline exists.
    pub mesh_pipeline: bool,
    /// Whether the splat pipeline exists.
    pub splat_pipeline: bool,
    /// Whether the overlay pipeline (measurement markers) exists.
    pub overlay_pipeline: bool,
    /// Meshes drawn.
    pub meshes: usize,
    /// Triangles drawn (opaque meshes).
    pub triangles: usize,
    /// Overlay meshes drawn over everything.
    pub overlays: usize,
    /// Splats drawn (significant voxels in front of the eye).
    pub splats: usize,
    /// The coarsest level of detail a volume was drawn at, the most halvings along any axis
    /// (0: every volume from its own grid or finer).
    pub level: u8,
    /// The most halvings of a volume's grid along each of its axes ([`Detail::Level`]).
    pub levels: [u8; 3],
    /// The most a volume's grid was refined along each axis, where one was
    /// ([`Detail::Refined`]).
    pub refined: Option<[u32; 3]>,
    /// Whether a volume drawn from its own grid wanted it refined, with refinement off
    /// ([`Renderer::set_refinement`]).
    pub unrefined: bool,
    /// Whether a volume or a brick that wanted a level of detail not made yet drew a finer
    /// one or its own grid instead, the level not paying within the frame
    /// ([`Renderer::set_levels_for_one_frame`]).
    pub levels_not_made: bool,
    /// Whether a level of detail was not made for want of memory, even with the levels kept
    /// from earlier frames given up: a finer level or the own grid drew instead
    /// ([`crate::budget::headroom`]).
    pub levels_short_of_memory: bool,
    /// Volumes drawn brick by brick at more than one level ([`Renderer::set_levels_by_brick`]).
    pub bricks_by_level: usize,
    /// Volumes a preview drew from a coarse copy of their values
    /// ([`Renderer::set_preview_copies`]), their own grids not classified for their
    /// transfer functions.
    pub coarse_copies: usize,
    /// Volumes classified this frame (0 when nothing changed).
    pub classified: usize,
    /// Levels of detail made this frame from a classification (0 when every level drawn was
    /// made already).
    pub levels_made: usize,
    /// What the CPU tile compositor did, when it composited the splats.
    pub tiles: Option<TileStats>,
    /// Pixels of the mesh and overlay layers' colour read back for the CPU tile compositor:
    /// only those that their meshes' bounding boxes can cover (the depth, when a mesh is on
    /// the image, is read whole).
    pub read_back: usize,
    /// Where the time went.
    pub timings: FrameTimings,
}

/// A rendered frame read back to the CPU.
#[derive(Debug, Clone)]
pub struct Screenshot {
    /// Premultiplied linear RGBA.
    pub frame: Frame,
    /// Reversed depth per pixel (0 where no mesh was drawn; splats write no depth).
    pub depth: Vec<f32>,
    /// The resolved camera.
    pub view: ViewSetup,
    /// What was drawn and how long it took.
    pub report: FrameReport,
}

/// Identity of a classification: the volume, the transfer function and the threshold.
type ClassKey = (usize, usize, u32, u64, u64, u64, Option<u32>);

struct VolumeState {
    key: ClassKey,
    /// The node's volume (the splats' placement, and the gradients of its own grid and its
    /// refinement).
    volume: Arc<CpuVolume>,
    /// How many times finer than `volume`'s the grid is along each axis.
    factors: [u32; 3],
    /// How many times the grid was halved along each axis (a level of detail above the own
    /// grid, whose texels are made from the level below's as their bricks are first read or
    /// drawn).
    levels: [u8; 3],
    /// The frame that last drew this grid or made a level from it (levels halved along some
    /// axes more than others are dropped, least recently used first, past
    /// [`KEPT_UNEVEN_SPLATS`]).
    used: u64,
    /// Its classification, shared with its texels, which write their colours from it as
    /// their bricks are first read.
    classified: Arc<Classified>,
    /// The GPU copy, made on the first frame the splat pass draws it.
    gpu: Option<GpuVolume>,
    /// The colours and normals of the CPU tile compositor, laid out on its first frame (or
    /// when a level is made from this grid) and written as their bricks are first read;
    /// shared with the texels of the levels made from them.
    texels: Option<Arc<SplatTexels>>,
    /// The texels of the refinement this one was joined from, until this one's are made:
    /// they take over its normals ([`SplatTexels::adopt_normals`]). They hold that
    /// refinement's classification too, for the colours of the bricks they never wrote.
    adopted: Option<Arc<SplatTexels>>,
    orderer: Orderer,
    ids: Vec<u32>,
    /// The view class `ids` was ordered for, where a view of the same class may reuse it.
    ordered_for: Option<OrderKey>,
    /// Whether `ids` is on the GPU as `gpu`'s draw order.
    ids_on_gpu: bool,
    /// Where its splats lie, by bricks (the volume's own grid only).
    occupied: Option<Occupied>,
    /// The own grid's bricks a refinement was classified within (`None`: all of them).
    region: Option<Region>,
    /// The view (with the node's placement, splat settings and the clip planes) whose bricks
    /// shown ([`seen_bricks`]) `within` holds: redrawn from that view, no look is needed.
    seen_for: Option<seen::SeenFor>,
    /// The own grid's bricks this refinement is drawn within (`None`: all it holds): the
    /// bricks the current view shows ([`seen_bricks`]), so that the picture is the view's
    /// alone, whatever bricks earlier views joined to the refinement.
    within: Option<Region>,
    /// What halving this grid along every axis that has more than one voxel would lose,
    /// brick by brick, once asked for ([`Renderer::spread_of`]).
    spread: Option<Arc<BrickSpread>>,
}

/// The class of views that share one draw order of a grid: the ordering, its axis
/// permutation and, per axis, where the eye lies against the voxel centres and the midpoints
/// between them (`AxisCase::view` and, where the eye's plane cuts the grid, the merge
/// threshold `floor(2 e)`). IP-PBTF (either interleaving) decides every pair of voxels by these
/// alone, so two views of one class give the same list, as long as culling behind the eye
/// leaves every voxel in: while a camera orbits a grid from outside, the order changes only
/// when the axis nearest the view direction does.
#[derive(Debug, Clone, Copy, PartialEq)]
struct OrderKey {
    ordering: Ordering,
    permutation: [usize; 3],
    axes: [(crate::order::AxisView, i64); 3],
}

impl OrderKey {
    /// The class of `view` for `ordering`, or `None` where the order cannot be reused: the
    /// orderings that depend on distances, not on the class, and views whose eye plane culls
    /// some voxel centre of the grid (or comes within a hair of one).
    fn of(view: &ViewCase, ordering: Ordering, options: &OrderOptions) -> Option<Self> {
        if !matches!(
            ordering,
            Ordering::IpPbtfImplicit | Ordering::IpPbtfExplicit
        ) {
            return None;
        }
        if options.cull_behind_eye {
            // The eye-plane distance is linear over the grid's box: positive at its eight
            // corner voxels, it is positive at every voxel.
            let n = view.axes.map(|a| a.n.saturating_sub(1));
            let margin = 1e-6 * (1.0 + view.eye.abs().max_element());
            let corners =
                (0..8u32).map(|c| [0, 1, 2].map(|a| if c >> a & 1 == 1 { n[a] } else { 0 }));
            // NaN fails the test too.
            if !corners.into_iter().all(|k| view.eye_plane(k) > margin) {
                return None;
            }
        }
        Some(Self {
            ordering,
            permutation: view.permutation,
            axes: view.axes.map(|a| match a.view {
                crate::order::AxisView::Split { .. } => (a.view, a.merge_threshold()),
                other => (other, 0),
            }),
        })
    }
}

/// What halving a grid along some axes loses, per brick of [`BRICK`]^3 own voxels: the root
/// mean square, over the brick's splats at the halved grid, of the spread of their blocks'
/// premultiplied colours ([`Classified::halved_measured`]).
#[derive(Debug)]
struct BrickSpread {
    /// Bricks along each axis.
    dims: [u32; 3],
    /// Per brick, x fastest.
    rms: Vec<f32>,
}

impl BrickSpread {
    /// The spread of the splats `spreads` (in id order of `classified`, a grid halved
    /// `levels` times along each axis from the own grid), brick by brick.
    fn of(classified: &Classified, levels: [u8; 3], spreads: &[f32]) -> Self {
        // (At most [`MAX_LEVEL`] halvings, 16 = BRICK voxels: as many bricks as the own grid.)
        let level_dims = classified.grid.dims();
        let dims: [u32; 3] = std::array::from_fn(|a| (level_dims[a] << levels[a]).div_ceil(BRICK));
        let bricks = dims.iter().map(|&n| n as usize).product();
        let mut sums = vec![(0f64, 0u32); bricks];
        for (id, &spread) in classified.grid.ids().zip(spreads) {
            let k = classified.grid.coords(id);
            let b: [u32; 3] = std::array::from_fn(|a| (k[a] << levels[a]) / BRICK);
            let slot = &mut sums[(b[0] + dims[0] * (b[1] + dims[1] * b[2])) as usize];
            slot.0 += f64::from(spread);
            slot.1 += 1;
        }
        let rms = sums
            .into_iter()
            .map(|(sum, n)| {
                if n == 0 {
                    0.0
                } else {
                    (sum / f64::from(n)).sqrt() as f32
                }
            })
            .collect();
        Self { dims, rms }
    }

    /// The spread of `brick`; infinite for a brick outside the grid.
    fn at(&self, brick: [u32; 3]) -> f64 {
        if (0..3).any(|a| brick[a] >= self.dims[a]) {
            return f64::INFINITY;
        }
        let [nx, ny, _] = self.dims;
        f64::from(self.rms[(brick[0] + nx * (brick[1] + ny * brick[2])) as usize])
    }
}

impl VolumeState {
    fn new(
        key: ClassKey,
        volume: Arc<CpuVolume>,
        factors: [u32; 3],
        classified: Classified,
        orderer: Orderer,
        ids: Vec<u32>,
    ) -> Self {
        Self {
            key,
            volume,
            factors,
            levels: [0; 3],
            used: 0,
            classified: Arc::new(classified),
            gpu: None,
            texels: None,
            adopted: None,
            orderer,
            ids,
            ordered_for: None,
            ids_on_gpu: false,
            occupied: None,
            region: None,
            seen_for: None,
            within: None,
            spread: None,
        }
    }
}

impl VolumeState {
    /// Where the splats of this state's grid lie when its node is placed by `world`.
    fn geometry(&self, world: DMat4) -> Result<VolumeGeometry, GeometryError> {
        placed_grid(
            self.classified.grid.dims(),
            world
                * volume_placement(&self.volume)
                * refinement(self.factors)
                * coarsening(self.levels),
        )
    }

    /// The 8-byte texel of significant voxel `k` (rank `rank`) of this state's grid: from its
    /// texels where they are made (a level above the own grid has them from the start), else
    /// from the volume's gradients.
    fn texel(&self, k: [u32; 3], rank: usize) -> [u8; 8] {
        match &self.texels {
            Some(texels) => texels.get(k[0], k[1], k[2]).unwrap_or([0; 8]),
            None => {
                crate::splat::tiled::texel(&self.volume, self.factors, &self.classified, k, rank)
            }
        }
    }

    /// Makes this state's texels where they are not made yet; returns the time it took.
    fn make_texels(&mut self) -> Duration {
        if self.texels.is_some() {
            return Duration::ZERO;
        }
        let started = Instant::now();
        let texels = SplatTexels::new(&self.classified, &self.volume, self.factors);
        if let Some(previous) = self.adopted.take() {
            texels.adopt_normals(&previous);
        }
        self.texels = Some(Arc::new(texels));
        started.elapsed()
    }

    /// Orders this state's splats into `ids` for the eye and target given, its node placed by
    /// `world`.
    fn order(
        &mut self,
        world: DMat4,
        (eye, target): (DVec3, DVec3),
        (ordering, options): (Ordering, &OrderOptions),
    ) -> Result<(), String> {
        let geometry = self.geometry(world).map_err(|e| e.to_string())?;
        let case = ViewCase::new(&geometry, eye, target).map_err(|e| e.to_string())?;
        let key = OrderKey::of(&case, ordering, options);
        if key.is_some() && key == self.ordered_for {
            return Ok(());
        }
        self.ordered_for = None;
        self.ids_on_gpu = false;
        self.orderer
            .order(
                &self.classified.grid,
                &case,
                ordering,
                options,
                &mut self.ids,
            )
            .map_err(|e| e.to_string())?;
        // A refinement drawn within the bricks the view shows, where it holds more: the whole
        // order with the rest left out (a visibility order of a set keeps one for any part of
        // it, and IP-PBTF's order of a part is the whole's restricted to it, so the picture is
        // the one a refinement made within those bricks alone draws). Walking the bricks one
        // by one in brick order would be cheaper, but splats overlap across the bricks' faces,
        // and the two orders' pictures differ there by up to 0.1 on opaque tissue.
        if let Some(within) = &self.within
            && self
                .region
                .as_ref()
                .is_none_or(|made| !within.contains(made))
        {
            keep_within(
                &mut self.ids,
                self.classified.grid.dims(),
                self.factors,
                within,
            );
        }
        self.ordered_for = key;
        Ok(())
    }
}

/// Whether a classification made within `made` (`None`: the whole grid) holds every brick of
/// `wanted` (`None`: the whole grid).
fn region_covers(made: Option<&Region>, wanted: Option<&Region>) -> bool {
    match (made, wanted) {
        (None, _) => true,
        (Some(made), Some(wanted)) => made.contains(wanted),
        (Some(made), None) => made.is_whole(),
    }
}

/// [`FrameOptions::volume_divisor`] where it can mean something (at least 1).
fn check_volume_divisor(divisor: u32) -> Result<u32, RenderError> {
    match divisor {
        0 => Err(RenderError::Options(
            "volume_divisor 0: the volumes' pixels are the frame's divided by it, at least 1"
                .into(),
        )),
        d => Ok(d),
    }
}

/// Lays the premultiplied `layer`, the pixels of `rect` row by row, over `frame` (`width`
/// pixels a row).
fn lay_over(frame: &mut [[f32; 4]], layer: &[[f32; 4]], rect: PixelRect, width: u32) {
    let [x0, y0, x1, _] = rect.0.map(|v| v as usize);
    let (w, rw) = (width as usize, x1 - x0);
    if rw == 0 {
        return;
    }
    for (r, layer) in layer.chunks_exact(rw).enumerate() {
        let y = y0 + r;
        for (px, o) in frame[y * w + x0..y * w + x1].iter_mut().zip(layer) {
            *px = std::array::from_fn(|k| o[k] + (1.0 - o[3]) * px[k]);
        }
    }
}

/// The level above `below` made by halving its grid along `axes` (its levels then `levels`;
/// `front` where the one axis halved runs along the view):
/// its classification combined ([`Classified::halved_along`]) and its texels laid out, to be
/// made from the level below's as their bricks are first read ([`SplatTexels::halved`]; the
/// level below's texels laid out first where they are not yet). `None` where the level would
/// have no splat. Gives up with [`crate::grid::GridError::Cancelled`] once `cancel` is raised:
/// looked at within the classification's halving and within the texels' layout.
fn make_level(
    below: &mut VolumeState,
    axes: [bool; 3],
    front: Option<Front>,
    levels: [u8; 3],
    cancel: Option<&std::sync::atomic::AtomicBool>,
) -> Result<Option<VolumeState>, crate::grid::GridError> {
    let (classified, _) = below
        .classified
        .halved_unless_cancelled(axes, front, None, cancel)?;
    if classified.grid.is_empty() {
        return Ok(None);
    }
    if cancel.is_some_and(|c| c.load(std::sync::atomic::Ordering::Relaxed)) {
        return Err(crate::grid::GridError::Cancelled);
    }
    let step = axes.map(|h| if h { 2 } else { 1 });
    below.make_texels();
    let mut state = VolumeState::new(
        below.key,
        Arc::clone(&below.volume),
        below.factors,
        classified,
        Orderer::new(),
        Vec::new(),
    );
    let Some(fine) = &below.texels else {
        unreachable!("the level below's texels were just laid out")
    };
    let Some(texels) = fine.halved(&state.classified, step, front, cancel) else {
        return Err(crate::grid::GridError::Cancelled);
    };
    state.levels = levels;
    state.texels = Some(Arc::new(texels));
    Ok(Some(state))
}

/// A volume drawn brick by brick at the levels its bricks want
/// ([`Renderer::set_levels_by_brick`]).
#[derive(Debug, Default)]
struct Mix {
    /// The occupied bricks of [`BRICK`]^3 own voxels on the image, in draw order (far to near
    /// once ordered), each with the level it is drawn from.
    bricks: Vec<([u32; 3], Detail)>,
    /// Their splats: run after run ([`brick_runs`]), each run's in its level's draw order.
    ids: Vec<u32>,
    /// Stretches of `ids` drawn from one level, far to near.
    runs: Vec<(Detail, std::ops::Range<usize>)>,
    /// Per level drawn, the place in the draw order of each splat's brick (kept between
    /// frames, as `ids` is, so that a frame does not allocate them anew).
    places: Vec<Vec<u32>>,
}

impl Mix {
    /// The grids its bricks are drawn from, each once.
    fn details(&self) -> Vec<Detail> {
        let mut details: Vec<Detail> = Vec::new();
        for (_, d) in &self.bricks {
            if !details.contains(d) {
                details.push(*d);
            }
        }
        details
    }
}

/// The most bricks the least box of bricks holding a run ([`brick_runs`]) may hold for each
/// brick of the run: a run is walked over its box, and the splats of the box's other bricks
/// are walked and dropped.
const RUN_BOX_SPARE: u32 = 2;

/// Bricks that follow one another in a mix's draw order at one detail, drawn as one: their
/// splats in their level's order over all of them, so that no face between two of them is
/// drawn as one brick's splats after the other's (a seam where a surface crosses it).
#[derive(Debug, Clone, Copy, PartialEq)]
struct BrickRun {
    /// One past its last brick in the draw order.
    end: usize,
    detail: Detail,
    /// The least box of bricks holding it, brick coordinates, inclusive.
    lo: [u32; 3],
    hi: [u32; 3],
    /// Its bricks.
    bricks: u32,
}

impl BrickRun {
    /// Whether every brick of its box is one of its own.
    fn fills_its_box(&self) -> bool {
        (0..3).map(|a| self.hi[a] - self.lo[a] + 1).product::<u32>() == self.bricks
    }
}

/// `bricks` (in draw order) cut into runs: bricks that follow one another at one detail, each
/// such stretch halved (at its middle, again and again) until the least box holding each part
/// holds at most [`RUN_BOX_SPARE`] bricks for each of its own. (The brick order takes the rows
/// of a slab from both sides of the eye in turn, so a stretch's box fills only once it is
/// whole: cut greedily, a slab would be cut at every row.) A run's splats in its level's order
/// are a visibility order of them (a level's IP-PBTF order restricted to some of its voxels is
/// one), and runs are drawn in the bricks' order, so the mix is a visibility order of whole
/// bricks between runs.
fn brick_runs(bricks: &[([u32; 3], Detail)]) -> Vec<BrickRun> {
    fn cut(bricks: &[([u32; 3], Detail)], start: usize, runs: &mut Vec<BrickRun>) {
        let (mut lo, mut hi) = (bricks[0].0, bricks[0].0);
        for (b, _) in bricks {
            lo = std::array::from_fn(|a| lo[a].min(b[a]));
            hi = std::array::from_fn(|a| hi[a].max(b[a]));
        }
        let boxed: u64 = (0..3).map(|a| u64::from(hi[a] - lo[a] + 1)).product();
        if bricks.len() > 1 && boxed > u64::from(RUN_BOX_SPARE) * bricks.len() as u64 {
            let half = bricks.len() / 2;
            cut(&bricks[..half], start, runs);
            cut(&bricks[half..], start + half, runs);
        } else {
            runs.push(BrickRun {
                end: start + bricks.len(),
                detail: bricks[0].1,
                lo,
                hi,
                bricks: bricks.len() as u32,
            });
        }
    }
    let mut runs = Vec::new();
    let mut start = 0;
    while start < bricks.len() {
        let detail = bricks[start].1;
        let end = bricks[start..]
            .iter()
            .position(|(_, d)| *d != detail)
            .map_or(bricks.len(), |n| start + n);
        cut(&bricks[start..end], start, &mut runs);
        start = end;
    }
    runs
}

/// Per brick of a grid of `[bx, by, bz]` bricks (x fastest), the place in the draw order
/// (the index in `runs`) of the run at `detail` it is drawn in, or `u32::MAX`.
fn bricks_in_runs(
    bricks: &[([u32; 3], Detail)],
    runs: &[BrickRun],
    [bx, by, bz]: [u32; 3],
    detail: Detail,
) -> Vec<u32> {
    let (bx, by) = (bx as usize, by as usize);
    let mut slot = vec![u32::MAX; bx * by * bz as usize];
    let mut start = 0;
    for (r, run) in runs.iter().enumerate() {
        if run.detail == detail {
            for (b, _) in &bricks[start..run.end] {
                let [x, y, z] = b.map(|c| c as usize);
                if let Some(s) = slot.get_mut(x + bx * (y + by * z)) {
                    *s = r as u32;
                }
            }
        }
        start = run.end;
    }
    slot
}

/// The brick of `side`^3 own voxels each voxel of a grid lies in, the grid a level or a
/// refinement of the own grid: looked up axis by axis rather than divided per splat.
struct BrickOf {
    /// Per axis, per voxel coordinate, its brick's.
    tables: [Vec<u32>; 3],
    /// The grid's voxels along x and y.
    row: u32,
    plane: u32,
}

impl BrickOf {
    /// For a grid of `dims`, halved and refined from the own grid as `(halvings, factors)`
    /// say: a level's voxel `k` lies in brick `floor(k 2^l / side)`, a refinement's in
    /// `floor(k / (f side))`.
    fn new(dims: [u32; 3], (halvings, factors): ([u32; 3], [u32; 3]), side: u32) -> Self {
        Self {
            tables: std::array::from_fn(|a| {
                (0..dims[a])
                    .map(|k| (k << halvings[a]) / (side * factors[a].max(1)))
                    .collect()
            }),
            row: dims[0].max(1),
            plane: dims[1].max(1),
        }
    }

    /// The brick of the grid's voxel at `k`.
    fn at(&self, k: [u32; 3]) -> [u32; 3] {
        std::array::from_fn(|a| self.tables[a][k[a] as usize])
    }

    /// The brick of voxel `id` (x fastest) of the grid.
    fn of(&self, id: u32) -> [u32; 3] {
        let (x, y, z) = (
            id % self.row,
            (id / self.row) % self.plane,
            id / self.row / self.plane,
        );
        [
            self.tables[0][x as usize],
            self.tables[1][y as usize],
            self.tables[2][z as usize],
        ]
    }
}

/// Orders volume `id`'s splats drawn brick by brick as `mix` says, its node placed by
/// `world`, for the eye and target `view`: the bricks put far to near ([`brick_order`]) and
/// cut into runs of one detail ([`brick_runs`]), each run's splats in its level's order, into
/// `mix.ids`, cut into stretches of one level. In the IP-PBTF orders each run's splats are
/// walked within the least box of bricks holding it ([`Orderer::order_boxes`]), so the cost
/// follows the splats drawn; in the others each level is ordered whole and its splats sorted
/// into runs ([`order_mix_from_whole_levels`]).
fn order_mix(
    volumes: &mut HashMap<(NodeId, Detail), VolumeState>,
    id: NodeId,
    world: DMat4,
    (eye, target): (DVec3, DVec3),
    (ordering, options): (Ordering, &OrderOptions),
    mix: &mut Mix,
) -> Result<(), String> {
    let own = volumes
        .get(&(id, Detail::default()))
        .ok_or("the volume's own grid is not classified")?;
    let own_geometry = own.geometry(world).map_err(|e| e.to_string())?;
    brick_order(&own_geometry, eye, target, BRICK, &mut mix.bricks).map_err(|e| e.to_string())?;
    let own_bricks = own_geometry.dims().map(|n| n.div_ceil(BRICK));
    let runs = brick_runs(&mix.bricks);
    let details = mix.details();
    // Per level, its runs' splats run after run in draw order, and where each ends.
    let mut parts: Vec<(Vec<u32>, Vec<usize>)> = Vec::with_capacity(details.len());
    for &detail in &details {
        let state = volumes
            .get(&(id, detail))
            .ok_or("a level of detail a brick is drawn at is not made")?;
        let geometry = state.geometry(world).map_err(|e| e.to_string())?;
        let case = ViewCase::new(&geometry, eye, target).map_err(|e| e.to_string())?;
        let (halvings, factors) = brick_scale(detail);
        // A run is walked over the least box of bricks that holds it ([`bricks_voxels`]).
        let (places, level_runs): (Vec<u32>, Vec<&BrickRun>) = runs
            .iter()
            .enumerate()
            .filter(|(_, r)| r.detail == detail)
            .map(|(i, r)| (i as u32, r))
            .unzip();
        let boxes: Vec<[(u32, u32); 3]> = level_runs
            .iter()
            .map(|run| bricks_voxels(run.lo, run.hi, (halvings, factors)))
            .collect();
        // A run's box may hold bricks of other runs, and a refinement bricks the view does
        // not show: the walk leaves their voxels out as it goes.
        let dims = state.classified.grid.dims();
        let in_runs = level_runs.iter().any(|r| !r.fills_its_box()).then(|| {
            (
                BrickOf::new(dims, (halvings, factors), BRICK),
                bricks_in_runs(&mix.bricks, &runs, own_bricks, detail),
            )
        });
        let within = (state.within.as_ref())
            .map(|within| (BrickOf::new(dims, ([0; 3], factors), REGION_BRICK), within));
        let [bx, by, _] = own_bricks;
        let keep = |at: usize, k: [u32; 3]| {
            in_runs.as_ref().is_none_or(|(brick_of, in_run)| {
                let b = brick_of.at(k);
                in_run.get((b[0] + bx * (b[1] + by * b[2])) as usize) == places.get(at)
            }) && within
                .as_ref()
                .is_none_or(|(brick_of, within)| within.covers_brick(brick_of.at(k)))
        };
        let keep = (in_runs.is_some() || within.is_some()).then_some(&keep);
        let (mut ids, mut ends) = (Vec::new(), Vec::new());
        let walked = Orderer::order_boxes_kept(
            &state.classified.grid,
            &case,
            (ordering, options),
            &boxes,
            keep,
            &mut ids,
            &mut ends,
        )
        .map_err(|e| e.to_string())?;
        if !walked {
            return order_mix_from_whole_levels(
                volumes,
                (id, world),
                (eye, target),
                (ordering, options),
                own_bricks,
                mix,
            );
        }
        parts.push((ids, ends));
    }
    mix.ids.clear();
    mix.runs.clear();
    // Per level, the runs of it taken so far and where the next one's splats start.
    let mut next = vec![(0usize, 0usize); details.len()];
    for BrickRun { detail, .. } in &runs {
        let level = details.iter().position(|d| d == detail).unwrap_or(0);
        let ((ids, ends), (taken, start)) = (&parts[level], &mut next[level]);
        let end = ends.get(*taken).copied().unwrap_or(*start);
        let from = mix.ids.len();
        mix.ids.extend_from_slice(&ids[*start..end]);
        (*taken, *start) = (*taken + 1, end);
        match mix.runs.last_mut() {
            Some((d, run)) if *d == *detail => run.end = mix.ids.len(),
            _ => mix.runs.push((*detail, from..mix.ids.len())),
        }
    }
    Ok(())
}

/// The voxels of a grid drawn at a detail of `(halvings, factors)` ([`brick_scale`]) that lie
/// in the own grid's bricks `lo..=hi`, as a half-open range along each axis: a level's voxel
/// `k` lies in brick `floor(k 2^l / BRICK)`, a refinement's in brick `floor(k / (f BRICK))`,
/// so the voxels of brick `b` are those from `ceil(b side / step)`.
fn bricks_voxels(
    lo: [u32; 3],
    hi: [u32; 3],
    (halvings, factors): ([u32; 3], [u32; 3]),
) -> [(u32, u32); 3] {
    std::array::from_fn(|a| {
        let side = BRICK * factors[a];
        let step = 1u32 << halvings[a];
        (
            (lo[a] * side).div_ceil(step),
            ((hi[a] + 1) * side).div_ceil(step),
        )
    })
}

/// Leaves out of `ids` (voxel ids of a grid of `dims`, refined by `factors` from the own
/// grid) the splats outside the own grid's bricks `within`, keeping the order of the rest.
fn keep_within(ids: &mut Vec<u32>, dims: [u32; 3], factors: [u32; 3], within: &Region) {
    let brick_of = BrickOf::new(dims, ([0; 3], factors), REGION_BRICK);
    let inside = |id: u32| within.covers_brick(brick_of.of(id));
    let kept: Vec<Vec<u32>> = ids
        .par_chunks(1 << 20)
        .map(|c| c.iter().copied().filter(|&id| inside(id)).collect())
        .collect();
    ids.clear();
    for k in kept {
        ids.extend_from_slice(&k);
    }
}

/// How a grid drawn at `detail` relates to its own grid's voxels: the times each axis was
/// halved (a level) and the factors it was refined by.
fn brick_scale(detail: Detail) -> ([u32; 3], [u32; 3]) {
    match detail {
        Detail::Level(l, _) => (l.map(u32::from), [1; 3]),
        Detail::Refined(f) => ([0; 3], f.map(|f| f.max(1))),
    }
}

/// [`order_mix`] for the orderings that cannot walk a brick alone: each level the bricks use
/// ordered whole by `ordering`, then each run's splats ([`brick_runs`]) taken from its level's
/// order in the bricks' order, `mix.bricks` as ordered already in a grid of `bricks` bricks
/// (a counting sort by run, which keeps the level's order within each run).
fn order_mix_from_whole_levels(
    volumes: &mut HashMap<(NodeId, Detail), VolumeState>,
    (id, world): (NodeId, DMat4),
    (eye, target): (DVec3, DVec3),
    (ordering, options): (Ordering, &OrderOptions),
    bricks: [u32; 3],
    mix: &mut Mix,
) -> Result<(), String> {
    let details = mix.details();
    let runs = brick_runs(&mix.bricks);
    for &detail in &details {
        volumes
            .get_mut(&(id, detail))
            .ok_or("a level of detail a brick is drawn at is not made")?
            .order(world, (eye, target), (ordering, options))?;
    }
    // A brick a level does not draw.
    const NONE: u32 = u32::MAX;
    let [bx, by, _] = bricks.map(|n| n as usize);
    let mut starts = vec![0usize; runs.len() + 1];
    // Per level, each splat's brick's place (a splat's brick: its voxel's first own voxel
    // over the brick's side; `k 2^l` on a level, `k / f` on a refinement), found in parallel.
    let mut places = std::mem::take(&mut mix.places);
    places.resize_with(details.len(), Vec::new);
    for (&detail, place) in details.iter().zip(places.iter_mut()) {
        // The place in the draw order of the run of each brick the level draws, by the
        // brick's index in the grid of bricks.
        let slot = bricks_in_runs(&mix.bricks, &runs, bricks, detail);
        place.clear();
        let Some(state) = volumes.get(&(id, detail)) else {
            continue;
        };
        let [nx, ny, _] = state.classified.grid.dims();
        let (row, plane) = (
            strength_reduce::StrengthReducedU32::new(nx.max(1)),
            strength_reduce::StrengthReducedU32::new((nx * ny).max(1)),
        );
        let (halvings, factors) = brick_scale(detail);
        // A refinement's bricks are `f` times the brick's side along each axis.
        let sides = factors.map(|f| strength_reduce::StrengthReducedU32::new(f * BRICK));
        let slot = &slot;
        state
            .ids
            .par_iter()
            .map(|&i| {
                let z = i / plane;
                let rest = i - z * plane.get();
                let y = rest / row;
                let k = [rest - y * row.get(), y, z];
                let b: [usize; 3] = std::array::from_fn(|a| {
                    if factors[a] == 1 {
                        (k[a] << halvings[a] >> BRICK.trailing_zeros()) as usize
                    } else {
                        (k[a] / sides[a]) as usize
                    }
                });
                slot.get(b[0] + bx * (b[1] + by * b[2]))
                    .copied()
                    .unwrap_or(NONE)
            })
            .collect_into_vec(place);
        for &s in place.iter() {
            if s != NONE {
                starts[s as usize + 1] += 1;
            }
        }
    }
    for s in 0..runs.len() {
        starts[s + 1] += starts[s];
    }
    mix.ids.resize(starts[runs.len()], 0);
    let mut next = starts.clone();
    for (&detail, place) in details.iter().zip(&places) {
        if let Some(state) = volumes.get(&(id, detail)) {
            for (&i, &s) in state.ids.iter().zip(place) {
                if s != NONE {
                    mix.ids[next[s as usize]] = i;
                    next[s as usize] += 1;
                }
            }
        }
    }
    mix.places = places;
    mix.runs.clear();
    for (s, BrickRun { detail, .. }) in runs.iter().enumerate() {
        let range = starts[s]..starts[s + 1];
        match mix.runs.last_mut() {
            Some((d, run)) if *d == *detail => run.end = range.end,
            _ => mix.runs.push((*detail, range)),
        }
    }
    Ok(())
}

/// How many splats a grid drawn at `detail` has for each of its own grid's: `2^-l` a level,
/// the product of the factors a refinement.
fn splat_share(detail: Detail) -> f64 {
    match detail {
        Detail::Level(l, _) => 0.5f64.powi(l.iter().map(|&l| i32::from(l)).sum()),
        Detail::Refined(f) => f.iter().map(|&f| f64::from(f)).product(),
    }
}

/// A level of detail that is not made yet is made for a mix only where the bricks that want it
/// hold at least this share of the own grid's splats, or where drawing them finer instead
/// would add more than [`FALL_BACK_EXTRA`] to the mix's splats. A level is made whole, so one
/// that few bricks draw costs its whole size for their few splats: on the 0.7 mm LIDC2 CT
/// turned 45 degrees, levels halved along one axis of the view (0/1/0 and 1/0/0, about 2.9M
/// splats each, 1/1/0 1.6M) were made for bricks holding 13%, 5% and 0.1% of its splats, and
/// the render peaked at 672 MB; without the last two, 514 MB.
const LEVEL_USE: f64 = 0.1;

/// The most that drawing bricks finer than the rare levels they want may add to a mix's
/// splats, as a share of them ([`LEVEL_USE`]).
const FALL_BACK_EXTRA: f64 = 0.05;

/// Gives the bricks of `wants` that want a rare level (one not wanted by bricks holding
/// [`LEVEL_USE`] of `own_splats`) the coarsest level that is kept and no coarser along any axis
/// than the one they wanted, the rare levels that cost the fewest added splats first, while
/// the added splats stay within [`FALL_BACK_EXTRA`] of the mix's. The own grid stands in only
/// where some brick draws it anyway (its texels are then made). Levels made for earlier views
/// do not count: the view's bricks alone decide, so that its picture is the same whatever was
/// drawn before (the viewer's screenshot is `render`'s picture of its scene file).
fn fall_back_from_rare_levels(wants: &mut [BrickWant], own_splats: usize) {
    let mut held: HashMap<Detail, f64> = HashMap::new();
    for w in wants.iter() {
        *held.entry(w.detail).or_default() += f64::from(w.splats);
    }
    let own = own_splats.max(1) as f64;
    let kept = |d: &Detail| held.get(d).is_some_and(|&n| n >= LEVEL_USE * own);
    let own_drawn = held.contains_key(&Detail::default());
    let mut standing: Vec<Detail> = held.keys().copied().filter(|d| kept(d)).collect();
    standing.retain(|d| *d != Detail::default() || own_drawn);
    // Coarseness first; equally coarse levels by their halvings and facing, so that the
    // choice does not follow the hash maps' order.
    let coarseness = |d: &Detail| match *d {
        Detail::Level(l, f) => (l.iter().map(|&l| u32::from(l)).sum::<u32>(), l, f),
        Detail::Refined(_) => (0, [0; 3], [0; 3]),
    };
    // Each rare level, the level its bricks would draw instead and the splats that adds.
    let mut rare: Vec<(Detail, Detail, f64)> = held
        .iter()
        .filter(|(d, _)| matches!(d, Detail::Level(..)) && !kept(d))
        .filter_map(|(&d, &n)| {
            let Detail::Level(wanted, _) = d else {
                return None;
            };
            let instead = standing
                .iter()
                .copied()
                .filter(|s| matches!(s, Detail::Level(l, _) if (0..3).all(|a| l[a] <= wanted[a])))
                .max_by_key(coarseness)?;
            Some((d, instead, n * (splat_share(instead) - splat_share(d))))
        })
        .collect();
    rare.sort_by(|a, b| {
        a.2.total_cmp(&b.2)
            .then_with(|| coarseness(&a.0).cmp(&coarseness(&b.0)))
    });
    let drawn: f64 = wants
        .iter()
        .map(|w| f64::from(w.splats) * splat_share(w.detail))
        .sum();
    let mut added = 0.0;
    for (rare, instead, extra) in rare {
        if added + extra > FALL_BACK_EXTRA * drawn {
            break;
        }
        added += extra;
        for w in wants.iter_mut().filter(|w| w.detail == rare) {
            w.detail = instead;
            w.smooth = None;
        }
    }
}

/// The time a level takes to be made, for each splat of the grid it is halved from (that
/// grid's texels made), in the time one splat takes to be drawn (ordered, projected, binned
/// and composited). On this project's 2-core machine (BENCHMARKS.md, "Levels made where
/// they pay in one frame"), a level halved from the own grid's texels took 18-25 ns an own splat, and a
/// frame 34-52 ns a splat drawn (the 0.5 mm CT head, the 0.7 mm LIDC2 CT and the dense ball
/// at 512 x 512).
const LEVEL_COST: f64 = 0.55;

/// What the volume or bricks that want each of `asked` (levels of detail not made yet, each
/// with the own grid's splats of the volume or bricks that want it) draw in one frame where
/// levels are made only where they pay: the levels made are those of the set that saves the
/// most drawing net of their making, among the sets of the levels asked that save the most
/// alone (the first one, the first two, ...). A level costs [`LEVEL_COST`] times the
/// splats of each grid it is halved from on its way from the own grid of `own_splats` splats
/// (the steps of `Renderer::make_levels`), no step of `made` or of another level of the set
/// counted twice. Each level asked draws the coarsest level made or on the way to one made,
/// no coarser along any axis than itself, else the own grid ([`Detail::default`]). The own
/// grid's texels are taken as made either way: a volume that draws any brick of its own grid
/// has them made, and one that makes a level has them made first.
fn levels_that_pay(
    asked: &[(Detail, f64)],
    made: &[Detail],
    own_splats: usize,
) -> Vec<(Detail, Detail)> {
    let own = own_splats as f64;
    let coarseness = |d: &Detail| match *d {
        Detail::Level(l, f) => (l.iter().map(|&l| u32::from(l)).sum::<u32>(), l, f),
        Detail::Refined(_) => (0, [0; 3], [0; 3]),
    };
    let mut asked: Vec<(Detail, f64)> = asked
        .iter()
        .copied()
        .filter(|(d, _)| matches!(d, Detail::Level(..)))
        .collect();
    // The most saved alone first; equal savings by the level, so that the choice does not
    // follow the order asked.
    let alone = |(d, n): &(Detail, f64)| n * (1.0 - splat_share(*d));
    asked.sort_by(|a, b| {
        alone(b)
            .total_cmp(&alone(a))
            .then_with(|| coarseness(&a.0).cmp(&coarseness(&b.0)))
    });
    // What each level asked draws where `standing` are made.
    let drawn = |standing: &[Detail], wanted: Detail| -> Detail {
        let Detail::Level(want, _) = wanted else {
            return Detail::default();
        };
        if standing.contains(&wanted) {
            return wanted;
        }
        standing
            .iter()
            .copied()
            .filter(|s| matches!(s, Detail::Level(l, _) if (0..3).all(|a| l[a] <= want[a])))
            .max_by_key(coarseness)
            .unwrap_or_default()
    };
    let mut standing: Vec<Detail> = made.to_vec();
    let mut cost = 0.0;
    let mut best = (0.0, standing.clone());
    for &(wanted, _) in &asked {
        let Detail::Level(wanted, facing) = wanted else {
            continue;
        };
        // The steps not made yet, each halving every axis still short of the level asked.
        let mut level = [0u8; 3];
        while level != wanted {
            let next: [u8; 3] = std::array::from_fn(|a| level[a] + u8::from(level[a] < wanted[a]));
            let key = level_facing(next, facing);
            if !standing.contains(&key) {
                cost += LEVEL_COST * own * splat_share(Detail::Level(level, [0; 3]));
                standing.push(key);
            }
            level = next;
        }
        let saved: f64 = asked
            .iter()
            .map(|&(d, n)| n * (1.0 - splat_share(drawn(&standing, d))))
            .sum();
        if saved - cost > best.0 {
            best = (saved - cost, standing.clone());
        }
    }
    asked.iter().map(|&(d, _)| (d, drawn(&best.1, d))).collect()
}

/// A volume's bricks are drawn each at its own level where that draws at most two thirds of
/// the splats its one level would (by the own grid's splats in each brick). A mix walks each
/// brick's splats alone, about 9 ns a splat drawn on this project's 2-core machine against
/// 2 ns a splat of the whole grid for one level. Where the splats it leaves out are far ones
/// that early termination skips anyway, it gains little: on the 0.7 mm LIDC2 CT seen from
/// 240 and 320 mm (its far bricks halved along the view, 55-70% of the splats) the mix and
/// the one level took the same time, where a translucent volume seen deep (28%) took a
/// third (BENCHMARKS.md, "Bricks walked alone"). Smooth bricks drawn a level coarser save
/// splats at every depth: the LIDC2 CT turned 49 degrees from the front drew 53% of the
/// splats in 164 ms against 263 ms (BENCHMARKS.md, "Smooth bricks a level coarser").
const MIX_SAVING: f64 = 1.5;

/// The splats, in own-grid splats, that a volume's levels of detail halved along some axes
/// more than others keep between frames together, least recently used dropped first. A camera
/// orbiting a volume wants one for each axis its view runs along and each pair of axes across
/// it, and each end of each axis along the view: the dense ball 512^3 turned 7 degrees a
/// frame wants six in 20 frames, 27M splats against its own grid's 14.75M. Keeping two
/// levels, as this rule replaced, made a level again in every third frame of that path
/// (BENCHMARKS.md, "Uneven levels kept by their splats").
const KEPT_UNEVEN_SPLATS: f64 = 2.0;

/// Of the uneven levels kept from earlier frames (each with the frame that last used it and its
/// splats), those to give up, least recently used first, so that `need` bytes fit `headroom`
/// and what giving them up frees, at [`crate::budget::LEVEL_SPLAT_BYTES`] a splat (the estimate
/// `need` is made at, so that a level's true bytes a splat, being fewer, keep the sum sound);
/// `None`, and none given up, where all of them would not make room.
fn levels_given_up<K>(mut spare: Vec<(K, u64, u64)>, need: u64, headroom: u64) -> Option<Vec<K>> {
    spare.sort_by_key(|&(_, used, _)| used);
    let mut room = headroom;
    let mut given = Vec::new();
    for (key, _, splats) in spare {
        if need <= room {
            break;
        }
        room = room.saturating_add(splats.saturating_mul(crate::budget::LEVEL_SPLAT_BYTES));
        given.push(key);
    }
    (need <= room).then_some(given)
}

/// Whether `detail` is a level of detail halved along some axes more than others.
fn is_uneven(detail: Detail) -> bool {
    matches!(detail, Detail::Level(l, _) if l[0] != l[1] || l[1] != l[2])
}

/// Of a volume's uneven levels (each with the frame that last drew it or made a level from it
/// and its splats), those dropped after frame `frame`: least recently used first, until the
/// rest hold at most [`KEPT_UNEVEN_SPLATS`] times `own_splats`; none that `frame` used.
fn uneven_levels_dropped(
    mut uneven: Vec<(Detail, u64, usize)>,
    own_splats: usize,
    frame: u64,
) -> Vec<Detail> {
    uneven.sort_by_key(|&(_, used, _)| std::cmp::Reverse(used));
    let allowed = KEPT_UNEVEN_SPLATS * own_splats as f64;
    let mut kept = 0.0;
    uneven
        .into_iter()
        .filter(|&(_, used, splats)| {
            kept += splats as f64;
            used != frame && kept > allowed
        })
        .map(|(d, _, _)| d)
        .collect()
}

/// Who composites the splats of screenshots.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Compositor {
    /// The CPU tile compositor where the adapter is a CPU (lavapipe), else the GPU (the
    /// command line's default).
    Auto,
    /// The GPU's splat pass (the library's default).
    #[default]
    Gpu,
    /// The CPU tile compositor ([`crate::splat::tiled`]); meshes keep their GPU pass.
    Cpu,
    /// The tile compositor as GPU compute passes: the CPU tile compositor's projection,
    /// binning, order and early termination, with the meshes' colour and depth kept on the
    /// GPU.
    GpuTiles,
}

impl Compositor {
    /// Whether volumes alone are composited on the CPU with no GPU adapter looked for: the
    /// CPU tiles asked for, or [`Compositor::Auto`] on a machine with no GPU device
    /// ([`GpuContext::hardware_may_exist`]), where the only adapter to be found is a CPU.
    /// Looking loads Mesa's lavapipe, which holds about 80 MB and takes 50 ms to start.
    pub fn volumes_without_adapter(self) -> bool {
        match self {
            Self::Cpu => true,
            Self::Auto => !GpuContext::hardware_may_exist(),
            Self::Gpu | Self::GpuTiles => false,
        }
    }
}

impl std::str::FromStr for Compositor {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "auto" => Ok(Self::Auto),
            "gpu" => Ok(Self::Gpu),
            "cpu" => Ok(Self::Cpu),
            "gpu-tiles" => Ok(Self::GpuTiles),
            other => Err(format!(
                "unknown compositor {other:?}: auto, gpu, cpu or gpu-tiles"
            )),
        }
    }
}

/// How the level of detail is set, as `splatscene render --lod` and the Python module's
/// `lod` name it ([`Renderer::set_lod`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LevelOfDetail {
    /// As [`LevelOfDetail::On`], but a level of the pyramid is made only where it pays within
    /// the frame, and no brick goes coarser for being smooth
    /// ([`Renderer::set_levels_for_one_frame`]); for a few pictures.
    #[default]
    Auto,
    /// Each brick at the level its distance calls for, levels made as wanted (the viewer's).
    On,
    /// One level a volume ([`Renderer::set_levels_by_brick`] off).
    Volume,
    /// Every volume from its own grid ([`Renderer::set_level_of_detail`] off).
    Off,
}

impl std::str::FromStr for LevelOfDetail {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "auto" => Ok(Self::Auto),
            "on" => Ok(Self::On),
            "volume" => Ok(Self::Volume),
            "off" => Ok(Self::Off),
            other => Err(format!(
                "unknown level of detail {other:?}: auto, on, volume or off"
            )),
        }
    }
}

/// Draws scenes; keeps GPU resources between frames so that a camera move uploads only the
/// draw orders and a few uniforms.
#[derive(Default)]
pub struct Renderer {
    mesh_pass: Option<MeshPass>,
    splat_pass: Option<SplatPass>,
    meshes: HashMap<NodeId, GpuMesh>,
    /// Each volume's classified grid at each level of detail made so far, and at most one
    /// refinement of its own grid.
    volumes: HashMap<(NodeId, Detail), VolumeState>,
    /// The detail each volume is drawn at in the current frame.
    levels: HashMap<NodeId, Detail>,
    /// The volumes drawn brick by brick at more than one level in the current frame.
    mixes: HashMap<NodeId, Mix>,
    /// The buffers of the last frame's mixes, for this frame's.
    spare_mixes: Vec<Mix>,
    /// What the GPU passes draw of each volume in the current frame, far to near: runs of the
    /// draw order on the GPU of one of its grids (the grid's whole order, or a mix's runs of
    /// that level, which its order on the GPU then holds one after another).
    gpu_runs: HashMap<NodeId, Vec<(Detail, std::ops::Range<usize>)>>,
    /// Every volume's bricks drawn at the volume's one level
    /// ([`Renderer::set_levels_by_brick`]).
    one_level: bool,
    /// Every volume drawn from its own grid (`--lod off`).
    full_grid: bool,
    /// No brick drawn coarser for being smooth ([`Renderer::set_smooth_bricks`]).
    no_smooth: bool,
    /// No volume drawn refined ([`Renderer::set_refinement`]).
    no_refinement: bool,
    /// Levels of detail made only where they pay within the frame
    /// ([`Renderer::set_levels_for_one_frame`]).
    levels_for_one_frame: bool,
    /// Refinements classified over the whole grid, not only where the image shows it
    /// ([`Renderer::set_refinement_on_image_only`]).
    refine_whole: bool,
    /// Refinements classified and drawn within every brick on the image, not only those the
    /// own grid shows ([`Renderer::set_refinement_where_seen`]).
    refine_hidden: bool,
    /// Who composites the splats of screenshots.
    compositor: Compositor,
    /// The CPU tile compositor's buffers.
    tiles: TiledCompositor,
    /// The tile compositor on the GPU ([`Compositor::GpuTiles`]), made on its first frame.
    tile_pass: Option<TilePass>,
    /// Splats the GPU tile compositor takes in one batch, where not its own default.
    gpu_tile_batch: Option<std::num::NonZeroUsize>,
    /// Frames whose levels of detail were chosen, counted (to drop levels least recently
    /// used).
    frame: u64,
    /// The memory levels of detail may take, in place of what the machine has left (tests).
    headroom_set: Option<u64>,
    /// The targets the CPU tile compositor's screenshots draw their meshes into, kept from
    /// frame to frame for the last two sizes drawn, the latest first.
    layer_targets: Vec<RenderTarget>,
    /// Each volume's coarse copies, for previews while its own grid is not classified.
    coarse_copies: HashMap<NodeId, CoarseCopy>,
    /// Previews never drawn from coarse copies ([`Renderer::set_preview_copies`]).
    no_preview_copies: bool,
}

/// A volume's values averaged over blocks of 2^3, 4^3, ... voxels ([`CpuVolume::halved`] once,
/// twice, ...), made as previews first ask for them.
struct CoarseCopy {
    /// The volume they were made from (the node's, while it stays the same).
    of: std::sync::Weak<CpuVolume>,
    /// The copy halved `i + 1` times at `i`, with its halvings along each axis (an axis of one
    /// voxel is not halved).
    halved: Vec<([u8; 3], Arc<CpuVolume>)>,
}

/// The coarsest spacing, in millimetres, of a preview's coarse copy of a volume
/// ([`Renderer::set_preview_copies`]): about the 1.4 mm of a thick-slice CT, whose picture the
/// one opacity per millimetre keeps within 0.03 (RMSE) of a 0.7 mm grid's. Averaged coarser,
/// thin bright structures fall below a bone window: the ribs of the 0.7 mm LIDC2 CT all but
/// vanished from a copy averaged over 4^3 voxels (2.8 mm), which the own grid's level of
/// that spacing keeps, since it averages the classified opacities (BENCHMARKS.md, "Previews
/// while the values are windowed").
pub const PREVIEW_COPY_SPACING_MM: f64 = 1.5;

impl std::fmt::Debug for Renderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Renderer")
            .field("mesh_pipeline", &self.mesh_pass.is_some())
            .field("splat_pipeline", &self.splat_pass.is_some())
            .field("meshes", &self.meshes.len())
            .field("volumes", &self.volumes.len())
            .field("full_grid", &self.full_grid)
            .finish()
    }
}

impl Renderer {
    /// A renderer with nothing built yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// A flag that, raised from another thread, makes a screenshot drawn by the CPU tile
    /// compositor give up with [`RenderError::Cancelled`]: checked between the frame's stages,
    /// between the compositor's batches (the look for a refinement's bricks included), between
    /// the z-slices of a classification (the own grid's, a coarse copy's, a refinement's) and
    /// of the halving that makes a level or measures its spread, and before a level's texels,
    /// so it stops within milliseconds, or once a level's texels or a preview's coarse copy
    /// under way are made. What was made whole before (classifications, levels, texels,
    /// looks) is kept for the next frame; nothing half made is. `None` (the default) for
    /// frames that always finish.
    pub fn set_cancel(&mut self, flag: Option<Arc<std::sync::atomic::AtomicBool>>) {
        self.tiles.cancel = flag;
    }

    /// Whether the cancel flag ([`Renderer::set_cancel`]) is raised.
    fn cancelled(&self) -> bool {
        self.tiles
            .cancel
            .as_ref()
            .is_some_and(|c| c.load(std::sync::atomic::Ordering::Relaxed))
    }

    /// A renderer whose screenshots composite their splats with `compositor`.
    pub fn with_compositor(compositor: Compositor) -> Self {
        Self {
            compositor,
            ..Self::default()
        }
    }

    /// Sets the memory levels of detail may take, in place of what the machine has left.
    #[cfg(test)]
    pub(crate) fn set_headroom(&mut self, bytes: Option<u64>) {
        self.headroom_set = bytes;
    }

    /// Whether volumes are drawn at a level of detail (on by default): each volume from the
    /// level of its pyramid ([`Classified::halved`], 2 x 2 x 2 voxels a splat a level, up to
    /// [`MAX_LEVEL`]) that [`detail_for`] chooses, one level for the whole volume, so that a
    /// grid finer than the image does not cost splats that fall under one pixel; within the
    /// level the draw order is the node's, over that level's grid; and a grid coarser than the
    /// pixels drawn refined ([`Renderer::set_refinement`]). Off, every volume is drawn from its
    /// own grid.
    pub fn set_level_of_detail(&mut self, on: bool) {
        self.full_grid = !on;
    }

    /// Whether each 16^3-voxel brick of a volume is drawn at the level its own distance and
    /// sight lines call for (on by default, with the level of detail), rather than the whole
    /// volume at the level its nearest brick on the image does. Bricks go far
    /// to near in the IP-PBTF order of the grid of bricks and each brick's splats in its
    /// level's draw order, so the order keeps every brick behind the bricks that can hide it;
    /// bricks whose splats cannot land on the image are left out before their splats are
    /// walked. A brick whose content loses little by it is drawn a level coarser than its
    /// spacing alone allows (a spread of at most 0.015, `SMOOTH_SPREAD`). A view whose bricks
    /// all want one level, or where the bricks' levels would draw more than two thirds of the
    /// splats of the volume's one level (`MIX_SAVING`), draws that one level as one grid, as
    /// before. Every compositor draws the same mix: the GPU passes draw the stretches of the
    /// draw order of one level after another, far to near, as the CPU tiles do.
    pub fn set_levels_by_brick(&mut self, on: bool) {
        self.one_level = !on;
    }

    /// Whether previews of a volume whose own grid is not classified for its transfer
    /// function (a window dragged over the values) are drawn from a copy of its values
    /// averaged over blocks of 2^3 voxels (4^3, ... where the level the preview draws is that
    /// coarse), classified anew (on by default): a thin-slice CT's classification takes most
    /// of a second, its copy's a few tens of milliseconds. Only a volume whose copy's voxels
    /// are at most [`PREVIEW_COPY_SPACING_MM`] apart is copied; the own grid is classified by
    /// the next frame that is not a preview. The copy's picture is the preview's within about
    /// what two grids of one CT differ by (tested against the own grid's preview).
    pub fn set_preview_copies(&mut self, on: bool) {
        self.no_preview_copies = !on;
    }

    /// Splats the GPU tile compositor ([`Compositor::GpuTiles`]) projects and composites in
    /// one batch, at most (and no more than the adapter binds; 4,194,304 by default; rounded
    /// up to a whole workgroup of 256). Each batch is one projecting dispatch for each stretch
    /// of a grid's order it holds and one compositing dispatch; fewer, larger batches are
    /// faster on a GPU, and the picture is the same for any size.
    pub fn set_gpu_tile_batch(&mut self, splats: std::num::NonZeroUsize) {
        self.gpu_tile_batch = Some(splats);
    }

    /// Whether a brick whose content loses little by it is drawn a level coarser than its
    /// spacing alone allows (on by default, with the levels by brick;
    /// [`Renderer::set_levels_by_brick`]). Off, each brick draws the level its spacing calls
    /// for, whatever it holds.
    pub fn set_smooth_bricks(&mut self, on: bool) {
        self.no_smooth = !on;
    }

    /// Whether a level of detail that a volume or a brick wants is made and drawn only where
    /// it pays within the frame (off by default: made wherever wanted, for the frames to
    /// come). On, a level is drawn where the splats it saves take longer to draw than it
    /// takes to make, about half a splat drawn for each splat of the grid it is halved from,
    /// as though no level were made yet (one made by an earlier frame is reused, not made
    /// again, but drawn only where it would pay), so the picture is the frame's alone; the
    /// volumes and bricks that want another draw the coarsest level the frame draws that is
    /// no coarser, else their own grid (refined where its voxels fall too far apart, as
    /// before); no brick is drawn coarser for being smooth ([`Renderer::set_smooth_bricks`];
    /// that measures the level above). For a few frames of a scene, as `splatscene render`
    /// draws: a grid drawn about a pixel apart saves too few splats by its levels to pay for
    /// them in one frame, one seen a quarter as large pays in its first (BENCHMARKS.md,
    /// "Levels made only where they pay" and "Levels made where they pay in one frame").
    pub fn set_levels_for_one_frame(&mut self, on: bool) {
        self.levels_for_one_frame = on;
    }

    /// Sets the level of detail as `lod` names it: [`Renderer::set_level_of_detail`],
    /// [`Renderer::set_levels_by_brick`] and [`Renderer::set_levels_for_one_frame`] together.
    pub fn set_lod(&mut self, lod: LevelOfDetail) {
        self.set_level_of_detail(lod != LevelOfDetail::Off);
        self.set_levels_by_brick(matches!(lod, LevelOfDetail::Auto | LevelOfDetail::On));
        self.set_levels_for_one_frame(lod == LevelOfDetail::Auto);
    }

    /// Whether volumes whose voxels are more than [`REFINE_TO`] pixels apart may be drawn
    /// from their grid refined ([`Detail::Refined`]; on by default, with the level of detail).
    /// Its classification takes time the first time a view wants it (0.35-0.86 s for the
    /// LIDC2 CT refined 2 x 2 x 3 here), and its frames more splats: a viewer turns it off
    /// while the camera moves and on once it rests.
    pub fn set_refinement(&mut self, on: bool) {
        self.no_refinement = !on;
    }

    /// Whether a refinement is classified only within the own grid's bricks whose splats can
    /// land on the image (on by default): a close-up refines what it shows, not the whole
    /// grid. A view that shows a brick the refinement left out classifies it anew. Off, the
    /// whole grid is refined, the same picture at a higher cost. The same holds for the
    /// coarse copies that previews draw while the values are windowed
    /// ([`Renderer::set_preview_copies`]).
    pub fn set_refinement_on_image_only(&mut self, on: bool) {
        self.refine_whole = !on;
    }

    /// Whether a refinement is classified and drawn only within the own grid's bricks on the
    /// image that add to the own grid's picture drawn alone (a pixel counting as opaque past
    /// 0.9999), with the empty bricks beside them, rather than within every brick on the image
    /// (on by default; no effect where the refinement is not limited to the image,
    /// [`Renderer::set_refinement_on_image_only`]). A close-up of a thick-slice CT then
    /// classifies and draws the refined splats in front of the opaque tissue, not behind it:
    /// the 1.5 mm aorta CT's close-up 3 times faster in a third of the memory (BENCHMARKS.md,
    /// "A refinement classifies only the bricks a view shows"). Each view pays a drawing of
    /// the own grid to find its bricks (once: redrawn from the same view, they stand); the
    /// bricks it shows that the refinement lacks are classified and joined to it, and the
    /// refinement is drawn within the view's bricks alone, so that the picture is the view's
    /// whatever views came before (the viewer's screenshot is `render`'s picture of its
    /// scene file). Where a pixel opaque to the own grid is not quite opaque to the refinement,
    /// a brick left out would have shown through it by a few 8-bit levels.
    pub fn set_refinement_where_seen(&mut self, on: bool) {
        self.refine_hidden = !on;
    }

    /// The CPU tile compositor, to set its opacity threshold.
    pub fn tile_compositor_mut(&mut self) -> &mut TiledCompositor {
        &mut self.tiles
    }

    /// Who composites the splats, as asked.
    pub fn compositor(&self) -> Compositor {
        self.compositor
    }

    /// Whether screenshots on `ctx` composite on the CPU: asked for, or chosen by
    /// [`Compositor::Auto`] for an adapter that is itself a CPU.
    pub fn composites_on_cpu(&self, ctx: &GpuContext) -> bool {
        match self.compositor {
            Compositor::Gpu | Compositor::GpuTiles => false,
            Compositor::Cpu => true,
            Compositor::Auto => ctx.adapter.get_info().device_type == wgpu::DeviceType::Cpu,
        }
    }

    /// Renders `scene` seen through `view` into the given colour and depth views (formats
    /// [`super::color_format`] and [`super::DEPTH_FORMAT`], of `view.size`).
    pub fn render(
        &mut self,
        ctx: &GpuContext,
        scene: &Scene,
        view: &ViewSetup,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        options: &FrameOptions,
    ) -> Result<FrameReport, RenderError> {
        if options.volume_divisor != 1 {
            return Err(RenderError::Options(format!(
                "volume_divisor {}: the GPU passes draw volumes at the frame's own pixels (1); only the CPU tile compositor's screenshots take fewer",
                options.volume_divisor
            )));
        }
        let mut report = FrameReport::default();
        self.sync_meshes(ctx, scene);
        let started = Instant::now();
        report.classified =
            self.sync_volumes(scene, view, options.preview, !self.one_level, &mut report)?;
        // Levels, texels and the look for bricks shown made on the way have their own timings.
        report.timings.classify = started
            .elapsed()
            .saturating_sub(report.timings.levels + report.timings.texels + report.timings.seen);
        let ordered = self.order_volumes(scene, view, options, &mut report)?;
        let started = Instant::now();
        self.upload(ctx, scene, view, &ordered, &mut report)?;
        if options.measure {
            // Queue writes are staged until the next submission: submit nothing to flush them.
            ctx.queue.submit([]);
            ctx.wait()?;
        }
        report.timings.upload = started.elapsed();
        let started = Instant::now();
        self.mesh_stage(ctx, scene, color, depth, options);
        if options.measure {
            finish_drawing(ctx, color)?;
        }
        report.timings.mesh_pass = started.elapsed();
        let started = Instant::now();
        self.splat_stage(ctx, view.size, &ordered, color, depth)?;
        if options.measure {
            finish_drawing(ctx, color)?;
        }
        report.timings.splat_pass = started.elapsed();
        self.translucent_stage(ctx, scene, view, color, depth);
        if report.overlays > 0 {
            self.overlay_stage(ctx, scene, color, depth);
        }
        report.mesh_pipeline = self.mesh_pass.is_some();
        report.splat_pipeline = self.splat_pass.is_some();
        report.overlay_pipeline = self.mesh_pass.as_ref().is_some_and(MeshPass::has_overlay);
        Ok(report)
    }

    /// Renders into a new offscreen target of `size` and reads colour and depth back.
    pub fn screenshot(
        &mut self,
        ctx: &GpuContext,
        scene: &Scene,
        camera: &SceneCamera,
        size: (u32, u32),
        options: &FrameOptions,
    ) -> Result<Screenshot, RenderError> {
        crate::budget::check_image(size.0.into(), size.1.into())?;
        if self.composites_on_cpu(ctx) {
            return self.screenshot_tiled(Some(ctx), scene, camera, size, options);
        }
        let target = RenderTarget::new(ctx, size.0, size.1)?;
        let view = ViewSetup::new(camera, size, scene.bounds())?;
        let mut report = self.render(
            ctx,
            scene,
            &view,
            &target.color_view,
            &target.depth_view,
            options,
        )?;
        let started = Instant::now();
        let (frame, depth) = target.read_region(ctx, PixelRect::whole(size), None, true)?;
        report.timings.readback = started.elapsed();
        Ok(Screenshot {
            frame,
            depth,
            view,
            report,
        })
    }

    /// A screenshot of a scene without meshes on a machine with no GPU adapter at all: the
    /// splats composited by the CPU tile compositor. A scene with meshes needs an adapter for
    /// them ([`RenderError::NoAdapter`] says so).
    pub fn screenshot_without_gpu(
        &mut self,
        scene: &Scene,
        camera: &SceneCamera,
        size: (u32, u32),
        options: &FrameOptions,
    ) -> Result<Screenshot, RenderError> {
        crate::budget::check_image(size.0.into(), size.1.into())?;
        self.screenshot_tiled(None, scene, camera, size, options)
    }

    /// A screenshot whose splats the CPU tile compositor draws over the meshes (drawn and read
    /// back by the GPU, when the scene has any).
    fn screenshot_tiled(
        &mut self,
        ctx: Option<&GpuContext>,
        scene: &Scene,
        camera: &SceneCamera,
        size: (u32, u32),
        options: &FrameOptions,
    ) -> Result<Screenshot, RenderError> {
        crate::splat::reference::check_frame_size(size.0, size.1)
            .map_err(|e| RenderError::BadCamera(e.to_string()))?;
        let view = ViewSetup::new(camera, size, scene.bounds())?;
        // The view the volumes are composited in: the frame's, or its camera at fewer pixels.
        let divisor = check_volume_divisor(options.volume_divisor)?;
        let volume_view = match divisor {
            1 => view,
            d => ViewSetup::new(
                camera,
                (size.0.div_ceil(d), size.1.div_ceil(d)),
                scene.bounds(),
            )?,
        };
        let mut report = FrameReport::default();
        let started = Instant::now();
        let by_brick = !self.one_level;
        report.classified =
            self.sync_volumes(scene, &volume_view, options.preview, by_brick, &mut report)?;
        // Levels, texels and the look for bricks shown made on the way have their own timings.
        report.timings.classify = started
            .elapsed()
            .saturating_sub(report.timings.levels + report.timings.texels + report.timings.seen);
        if self.cancelled() {
            return Err(RenderError::Cancelled);
        }
        let ordered = self.order_volumes(scene, &volume_view, options, &mut report)?;
        if self.cancelled() {
            return Err(RenderError::Cancelled);
        }
        // What lies under the splats: the meshes on the GPU, or the background alone.
        let has_meshes = scene.meshes().chain(scene.overlays()).next().is_some();
        let pixels = size.0 as usize * size.1 as usize;
        let fill = options
            .background
            .map_or([0.0; 4], |[r, g, b]| [r, g, b, 1.0]);
        let (mut frame, mut depth, target) = match ctx {
            Some(ctx) if has_meshes => {
                self.sync_meshes(ctx, scene);
                let kept = self.layer_targets.iter().position(|t| t.size == size);
                let target = match kept {
                    Some(i) => self.layer_targets.remove(i),
                    None => RenderTarget::new(ctx, size.0, size.1)?,
                };
                self.upload(ctx, scene, &view, &[], &mut report)?;
                let started = Instant::now();
                self.mesh_stage(ctx, scene, &target.color_view, &target.depth_view, options);
                report.timings.mesh_pass = started.elapsed();
                let started = Instant::now();
                // Only the pixels the opaque meshes can cover are read back; the others hold
                // the clear colour and no depth.
                let opaque = scene.meshes().filter(|(_, m, _)| !is_translucent(m));
                let rect = self.layer_rect(&view, opaque);
                let (frame, depth) = target.read_region(ctx, rect, Some(fill), true)?;
                report.timings.readback = started.elapsed();
                report.read_back += rect.pixels();
                (frame, depth, Some((ctx, target)))
            }
            None if has_meshes => {
                return Err(RenderError::NoAdapter(
                    "the scene has meshes, which need a GPU adapter; only its volumes could be drawn without one".into(),
                ));
            }
            _ => {
                let frame = Frame {
                    width: size.0,
                    height: size.1,
                    pixels: vec![fill; pixels],
                };
                (frame, vec![0.0; pixels], None)
            }
        };
        let started = Instant::now();
        let (tiles, texels) = if divisor == 1 {
            self.composite_tiles(scene, &view, &ordered, &depth, &mut frame)
        } else {
            // Composited over nothing at the fewer pixels, against the meshes' nearest depth
            // in each, then laid over the meshes at the frame's size.
            let scale = fewer_pixels::scale_between(&view, &volume_view);
            let coarse = volume_view.size;
            let coarse_depth = fewer_pixels::coarse_depth(&depth, size, coarse, scale);
            let mut volumes = Frame {
                width: coarse.0,
                height: coarse.1,
                pixels: vec![[0.0; 4]; coarse.0 as usize * coarse.1 as usize],
            };
            let done =
                self.composite_tiles(scene, &volume_view, &ordered, &coarse_depth, &mut volumes);
            if !done.0.cancelled {
                fewer_pixels::lay_volume_over(&mut frame, &depth, &volumes, &coarse_depth, scale);
            }
            done
        };
        if tiles.cancelled {
            // The mesh layers' targets go back for the next frame.
            if let Some((_, target)) = target {
                self.layer_targets.insert(0, target);
                self.layer_targets.truncate(2);
            }
            return Err(RenderError::Cancelled);
        }
        report.tiles = Some(tiles);
        report.timings.texels += texels;
        report.timings.splat_pass = started.elapsed();
        let translucent: Vec<_> = scene
            .meshes()
            .filter(|(_, m, _)| is_translucent(m))
            .collect();
        if let Some((ctx, target)) = &target
            && !translucent.is_empty()
        {
            // Translucent meshes go over the splats: drawn alone on a clear colour against
            // the opaque meshes' depth, then laid over the frame.
            let started = Instant::now();
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            {
                let _ = begin_keeping_depth(&mut encoder, &target.color_view, &target.depth_view);
            }
            ctx.queue.submit([encoder.finish()]);
            self.translucent_stage(ctx, scene, &view, &target.color_view, &target.depth_view);
            let rect = self.layer_rect(&view, translucent.into_iter());
            let (layer, layer_depth) = target.read_region(ctx, rect, None, true)?;
            lay_over(&mut frame.pixels, &layer.pixels, rect, size.0);
            // The depth now holds the translucent surfaces too, as the GPU path's does (none
            // drawn, it is as it was).
            if !rect.is_empty() {
                depth = layer_depth;
            }
            report.timings.readback += started.elapsed();
            report.read_back += rect.pixels();
        }
        if let Some((ctx, target)) = &target
            && scene.overlays().next().is_some()
        {
            // Measurement markers go over everything: drawn alone, then laid over the frame.
            let started = Instant::now();
            self.overlay_alone(ctx, scene, &target.color_view, &target.depth_view);
            let rect = self.layer_rect(&view, scene.overlays());
            let (overlay, _) = target.read_region(ctx, rect, None, false)?;
            lay_over(&mut frame.pixels, &overlay.pixels, rect, size.0);
            report.timings.readback += started.elapsed();
            report.read_back += rect.pixels();
        }
        if let Some((_, target)) = target {
            // The last two sizes drawn are kept: the viewer's previews and full frames share the
            // window's, and a caller alternating two sizes draws into kept targets.
            self.layer_targets.insert(0, target);
            self.layer_targets.truncate(2);
        }
        report.mesh_pipeline = self.mesh_pass.is_some();
        report.overlay_pipeline = self.mesh_pass.as_ref().is_some_and(MeshPass::has_overlay);
        Ok(Screenshot {
            frame,
            depth,
            view,
            report,
        })
    }

    /// The ordered volumes' splats composited by the tile compositor over `frame`, and the
    /// time taken making texels that were not made yet.
    fn composite_tiles(
        &mut self,
        scene: &Scene,
        view: &ViewSetup,
        ordered: &[(NodeId, VolumeGeometry)],
        depth: &[f32],
        frame: &mut Frame,
    ) -> (TileStats, Duration) {
        let Self {
            volumes,
            levels,
            mixes,
            tiles,
            ..
        } = self;
        // The grids each volume draws: the levels of its bricks, or its one level.
        let drawn = |id: &NodeId| -> Vec<Detail> {
            match mixes.get(id) {
                Some(mix) => mix.details(),
                None => vec![levels.get(id).copied().unwrap_or_default()],
            }
        };
        let mut texels = Duration::ZERO;
        for (id, _) in ordered {
            for detail in drawn(id) {
                if let Some(state) = volumes.get_mut(&(*id, detail)) {
                    texels += state.make_texels();
                }
            }
            // The texels of the bricks drawn at a level, made in parallel before the frame
            // composites where they are not made yet (a level made for this view, or a brick
            // come to want a level): made as the projection reads them, the two threads
            // wait at each batch's end for whichever met more of them, and a level's
            // bricks took 2-3 times as long (BENCHMARKS.md, "Levels' texels made for the
            // bricks drawn at them"). The own grid's are still made as they are read: most
            // of a dense volume's are hidden.
            let Some(mix) = mixes.get(id) else {
                let level = levels.get(id).copied().unwrap_or_default();
                if let (Detail::Level(..), Some(state)) = (level, volumes.get(&(*id, level)))
                    && let Some(level_texels) = &state.texels
                {
                    let started = Instant::now();
                    let whole = state.classified.grid.dims().map(|n| (0, n));
                    if level_texels.complete_within(&[whole]) > 0 {
                        texels += started.elapsed();
                    }
                }
                continue;
            };
            {
                let (started, mut made) = (Instant::now(), 0);
                for detail in mix.details() {
                    let Detail::Level(halvings, _) = detail else {
                        continue;
                    };
                    let Some(level_texels) =
                        volumes.get(&(*id, detail)).and_then(|s| s.texels.as_ref())
                    else {
                        continue;
                    };
                    let boxes: Vec<[(u32, u32); 3]> = (mix.bricks.iter())
                        .filter(|(_, d)| *d == detail)
                        .map(|(b, _)| bricks_voxels(*b, *b, (halvings.map(u32::from), [1; 3])))
                        .collect();
                    made += level_texels.complete_within(&boxes);
                }
                if made > 0 {
                    texels += started.elapsed();
                }
            }
        }
        // Sources (a grid's projection and texels) and runs of splats, far to near.
        let mut sources = Vec::new();
        let mut runs = Vec::new();
        for (id, _) in ordered {
            let Some((_, node, world)) = scene.volumes().find(|(v, _, _)| v == id) else {
                continue;
            };
            let first = sources.len();
            let details = drawn(id);
            for &detail in &details {
                let Some(state) = volumes.get(&(*id, detail)) else {
                    continue;
                };
                let (Some(texels), Ok(geometry)) = (state.texels.as_deref(), state.geometry(world))
                else {
                    continue;
                };
                let projection = projection(&geometry, view, &node.splats, &scene.clipping);
                sources.push((detail, projection, texels, state.ids.as_slice()));
            }
            let source = |d: &Detail| (first..sources.len()).find(|&s| sources[s].0 == *d);
            match mixes.get(id) {
                Some(mix) => {
                    for (d, range) in &mix.runs {
                        if let Some(source) = source(d) {
                            runs.push((source, &mix.ids[range.clone()]));
                        }
                    }
                }
                None => {
                    if let Some(source) = source(&details[0]) {
                        runs.push((source, sources[source].3));
                    }
                }
            }
        }
        let projections: Vec<_> = sources.iter().map(|(_, p, t, _)| (p, *t)).collect();
        let runs: Vec<_> = runs
            .into_iter()
            .map(|(source, ids)| Run { source, ids })
            .collect();
        let stats = tiles.composite_runs(view.size, &projections, &runs, depth, &mut frame.pixels);
        (stats, texels)
    }

    /// Draws the overlay meshes alone into cleared targets (transparent, far depth).
    /// The pixels that the drawn meshes among `nodes` can cover in this view: the union of
    /// their bounding boxes' screen rectangles ([`ViewSetup::screen_rect`]).
    fn layer_rect<'a>(
        &self,
        view: &ViewSetup,
        nodes: impl Iterator<Item = (NodeId, &'a crate::scene::MeshNode, DMat4)>,
    ) -> PixelRect {
        let mut rect = PixelRect::EMPTY;
        for (id, _, world) in nodes {
            let Some((lo, hi)) = self.meshes.get(&id).and_then(|m| m.bounds) else {
                continue;
            };
            let corners = (0..8).map(|c| {
                let pick = |a: usize| f64::from(if c >> a & 1 == 0 { lo[a] } else { hi[a] });
                world.transform_point3(DVec3::new(pick(0), pick(1), pick(2)))
            });
            rect = rect.union(view.screen_rect(corners));
        }
        rect
    }

    fn overlay_alone(
        &self,
        ctx: &GpuContext,
        scene: &Scene,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
    ) {
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let _ = begin(
                &mut encoder,
                color,
                depth,
                Some(wgpu::Color::TRANSPARENT),
                "clear",
            );
        }
        ctx.queue.submit([encoder.finish()]);
        self.overlay_stage(ctx, scene, color, depth);
    }

    fn sync_meshes(&mut self, ctx: &GpuContext, scene: &Scene) {
        let mut live = std::collections::HashSet::new();
        // The node that holds each mesh's buffers, so that nodes drawing one mesh share them.
        let mut uploaded: HashMap<*const crate::mesh::CpuMesh, NodeId> = HashMap::new();
        if scene.overlays().next().is_some() {
            let pass = self.mesh_pass.get_or_insert_with(|| MeshPass::new(ctx));
            pass.prepare_overlay(ctx);
        }
        if scene.meshes().any(|(_, m, _)| is_translucent(m)) {
            let pass = self.mesh_pass.get_or_insert_with(|| MeshPass::new(ctx));
            pass.prepare_translucent(ctx);
        }
        for (id, node, _) in scene.meshes().chain(scene.overlays()) {
            if node.mesh.indices.len() < 3 {
                continue;
            }
            live.insert(id);
            let fresh = self
                .meshes
                .get(&id)
                .is_some_and(|m| Arc::ptr_eq(&m.source, &node.mesh));
            if !fresh {
                let pass = self.mesh_pass.get_or_insert_with(|| MeshPass::new(ctx));
                let gpu = {
                    let shared = uploaded
                        .get(&Arc::as_ptr(&node.mesh))
                        .and_then(|other| self.meshes.get(other));
                    pass.upload_sharing(ctx, &node.mesh, shared)
                };
                self.meshes.insert(id, gpu);
            }
            uploaded.entry(Arc::as_ptr(&node.mesh)).or_insert(id);
        }
        self.meshes.retain(|id, _| live.contains(id));
    }

    /// The state a volume is drawn from in the current frame.
    fn drawn_mut(&mut self, id: NodeId) -> Option<&mut VolumeState> {
        let level = self.levels.get(&id).copied().unwrap_or_default();
        self.volumes.get_mut(&(id, level))
    }

    /// Makes the texels of volume `id`'s own grid, where they are not made yet, for a frame
    /// that draws it. (A level halved from a grid lays out that grid's texels itself, and
    /// reads them as its own bricks are made.)
    fn make_own_texels(&mut self, id: NodeId, report: &mut FrameReport) {
        if let Some(state) = self.volumes.get_mut(&(id, Detail::default())) {
            report.timings.texels += state.make_texels();
        }
    }

    /// Draws each of `wants` (volume `id`'s bricks on the image) that has a coarser level
    /// allowed ([`BrickWant::smooth`]) at that level where halving the level it wants,
    /// across the view, loses at most [`SMOOTH_SPREAD`] in the brick
    /// ([`Renderer::spread_of`]). Where bricks draw the own grid, its texels are made first
    /// ([`Renderer::make_own_texels`]).
    fn draw_smooth_coarser(
        &mut self,
        id: NodeId,
        spacing: [f64; 3],
        wants: &mut [BrickWant],
        report: &mut FrameReport,
    ) -> Result<(), crate::grid::GridError> {
        let own = (id, Detail::default());
        if wants.iter().any(|w| w.detail == own.1) {
            self.make_own_texels(id, report);
        }
        let dims = match self.volumes.get(&own) {
            Some(state) => state.classified.grid.dims(),
            None => return Ok(()),
        };
        let axes = dims.map(|n| n > 1);
        // Per level even across the axes, what halving it once more loses.
        let mut spreads: HashMap<u8, Option<Arc<BrickSpread>>> = HashMap::new();
        for want in wants {
            let (Some(smooth @ Detail::Level(coarse, _)), Detail::Level(fine, _)) =
                (want.smooth, want.detail)
            else {
                continue;
            };
            // One halving more along some axes, none fewer.
            if (0..3).any(|a| coarse[a] < fine[a] || coarse[a] > fine[a] + 1) {
                continue;
            }
            // Measured on the level below the brick's that is even across the axes (the
            // one its level is halved from, along the view, or the own grid): the spread
            // across the view is what the coarser level loses, and that level is made on
            // the way to the brick's own.
            let least = (0..3)
                .filter(|&a| axes[a])
                .map(|a| fine[a])
                .min()
                .unwrap_or(0);
            let spread = match spreads.entry(least) {
                std::collections::hash_map::Entry::Occupied(known) => known.into_mut(),
                std::collections::hash_map::Entry::Vacant(slot) => {
                    let even = axes.map(|h| if h { least } else { 0 });
                    let got = self.make_levels(id, spacing, even, [0; 3], report)?;
                    let spread = if got == Detail::Level(even, [0; 3]) {
                        self.spread_of((id, got), spacing, report)?
                    } else {
                        None
                    };
                    slot.insert(spread)
                }
            };
            if spread
                .as_ref()
                .is_some_and(|s| s.at(want.brick) <= SMOOTH_SPREAD)
            {
                want.detail = smooth;
            }
        }
        Ok(())
    }

    /// What halving the grid `key` along every axis with more than one voxel would lose,
    /// brick by brick ([`BrickSpread`]), each voxel's opacity that of its own edge's length of
    /// tissue (the geometric mean of its spacing, `spacing` being the own grid's); measured
    /// once a grid, timed as making levels. `None` where the grid is not made.
    fn spread_of(
        &mut self,
        key: (NodeId, Detail),
        spacing: [f64; 3],
        report: &mut FrameReport,
    ) -> Result<Option<Arc<BrickSpread>>, crate::grid::GridError> {
        let cancel = self.tiles.cancel.clone();
        let Some(state) = self.volumes.get_mut(&key) else {
            return Ok(None);
        };
        if let Some(spread) = &state.spread {
            return Ok(Some(Arc::clone(spread)));
        }
        let axes = state.classified.grid.dims().map(|n| n > 1);
        let started = Instant::now();
        let mm = (0..3)
            .map(|a| spacing[a] * f64::from(1u32 << state.levels[a]))
            .product::<f64>()
            .cbrt() as f32;
        let (halved, spreads) =
            state
                .classified
                .halved_unless_cancelled(axes, None, Some(mm), cancel.as_deref())?;
        let levels = std::array::from_fn(|a| state.levels[a] + u8::from(axes[a]));
        let spread = Arc::new(BrickSpread::of(&halved, levels, &spreads));
        state.spread = Some(Arc::clone(&spread));
        report.timings.levels += started.elapsed();
        Ok(Some(spread))
    }

    /// Makes the levels of volume `id`'s pyramid up to `wanted` halvings along each axis (facing
    /// the eye as `facing` says) that are missing, each from the one below by halving every
    /// axis still below its level (the levels even across axes first, shared by other views;
    /// then the axes along the view, their voxels weighted as the rays composite them), and
    /// marks them used in the current frame. A level that would have no splat, or whose axes
    /// cannot be halved further, is not made: returns the level reached. `spacing` is the own
    /// grid's voxel size in the world (the opacities' step).
    fn make_levels(
        &mut self,
        id: NodeId,
        spacing: [f64; 3],
        wanted: [u8; 3],
        facing: [i8; 3],
        report: &mut FrameReport,
    ) -> Result<Detail, crate::grid::GridError> {
        let frame = self.frame;
        let cancel = self.tiles.cancel.clone();
        let mut level = [0u8; 3];
        let mut key = Detail::default();
        while let Some(state) = self.volumes.get_mut(&(id, key)) {
            state.used = frame;
            let dims = state.classified.grid.dims();
            // A level holds at most one splat for each splat of the level below it.
            let below = state.classified.grid.len() as u64;
            let axes: [bool; 3] = std::array::from_fn(|a| level[a] < wanted[a] && dims[a] > 1);
            if axes == [false; 3] {
                break;
            }
            let next: [u8; 3] = std::array::from_fn(|a| level[a] + u8::from(axes[a]));
            let above = level_facing(next, facing);
            if !self.volumes.contains_key(&(id, above)) {
                // The one axis halved along the view, where this step halves it alone.
                let Detail::Level(_, along) = above else {
                    break;
                };
                let mut halved = (0..3).filter(|&a| axes[a]);
                let front = match (halved.next(), halved.next()) {
                    (Some(a), None) if along[a] != 0 => Some(Front {
                        axis: a,
                        larger_nearer: along[a] > 0,
                        step_mm: (spacing[a] * f64::from(1u32 << level[a])) as f32,
                    }),
                    _ => None,
                };
                if !self.room_for_level(below, frame) {
                    report.levels_short_of_memory = true;
                    break;
                }
                let Some(state) = self.volumes.get_mut(&(id, key)) else {
                    break;
                };
                let started = Instant::now();
                let made_level = make_level(state, axes, front, next, cancel.as_deref())?;
                report.timings.levels += started.elapsed();
                let Some(made_level) = made_level else {
                    break;
                };
                report.levels_made += 1;
                self.volumes.insert((id, above), made_level);
            }
            level = next;
            key = above;
        }
        if let Some(state) = self.volumes.get_mut(&(id, key)) {
            state.used = frame;
        }
        Ok(key)
    }

    /// Whether a level of `splats` splats at most, at [`crate::budget::LEVEL_SPLAT_BYTES`] each, fits
    /// the memory left ([`Renderer::headroom`]), once the uneven levels kept from earlier
    /// frames that [`levels_given_up`] chooses are dropped.
    fn room_for_level(&mut self, splats: u64, frame: u64) -> bool {
        let need = splats.saturating_mul(crate::budget::LEVEL_SPLAT_BYTES);
        let headroom = self.headroom();
        if need <= headroom {
            return true;
        }
        let spare = (self.volumes.iter())
            .filter(|((_, d), state)| is_uneven(*d) && state.used != frame)
            .map(|(&key, state)| (key, state.used, state.classified.grid.len() as u64))
            .collect();
        match levels_given_up(spare, need, headroom) {
            Some(keys) => {
                for key in keys {
                    self.volumes.remove(&key);
                }
                true
            }
            None => false,
        }
    }

    /// The memory a level of detail may take: [`crate::budget::headroom`], or the bytes set
    /// for tests.
    fn headroom(&self) -> u64 {
        self.headroom_set.unwrap_or_else(crate::budget::headroom)
    }

    /// Classifies volumes whose data, transfer function or threshold changed, chooses the
    /// level of detail each is drawn at in `view` (at least 1 for a preview frame) and makes
    /// the levels up to it that are missing (counted in `report.levels_made`); returns how
    /// many classifications were made. With `by_brick`, a volume drawn at a level has its
    /// bricks on the image drawn each at its own ([`Renderer::set_levels_by_brick`]) where
    /// they want more than one.
    fn sync_volumes(
        &mut self,
        scene: &Scene,
        view: &ViewSetup,
        preview: u8,
        by_brick: bool,
        report: &mut FrameReport,
    ) -> Result<usize, RenderError> {
        let mut live = Vec::new();
        let mut made = 0;
        self.levels.clear();
        self.spare_mixes.extend(self.mixes.drain().map(|(_, m)| m));
        for (id, node, world) in scene.volumes() {
            live.push(id);
            let key = class_key(node);
            let name = &scene.nodes()[id.0].name;
            let fail = |message: String| RenderError::Volume {
                node: name.clone(),
                message,
            };
            let style = &node.splats.style;
            let options = ClassifyOptions {
                min_opacity: node.splats.min_opacity,
                opacity: Opacity {
                    reference_mm: node.splats.opacity_reference_mm,
                    sigma: style.sigma,
                    cutoff: style.cutoff,
                },
                shell: node.splats.shell,
            };
            // What drawing a classification's splats takes, before any of it is made.
            let afford = |result: &Classified| {
                let splats = result.grid.len() as u64;
                crate::budget::check_memory_left(
                    format!("drawing {splats} splats"),
                    splats,
                    crate::budget::SPLAT_BYTES,
                )
                .map_err(|e| fail(e.to_string()))
            };
            let own = (id, Detail::default());
            let stale = self.volumes.get(&own).is_none_or(|v| v.key != key);
            if preview > 0 && stale && !self.full_grid && !self.no_preview_copies {
                // The level the preview would draw of the own grid, the same for every axis:
                // the least it wants along any (where its content lay before, or its box).
                let geometry =
                    placed_geometry(&node.volume, world).map_err(|e| fail(e.to_string()))?;
                let occupied = self.volumes.get(&own).and_then(|s| s.occupied.as_ref());
                let apart = apart_near(&geometry, view, occupied);
                let least = match detail_at(geometry.dims(), apart, Within::WHOLE) {
                    Detail::Level(levels, _) => levels.into_iter().min().unwrap_or(0),
                    Detail::Refined(_) => 0,
                };
                let least = preview_level(least, preview);
                let halvings = copy_halvings(geometry.spacing(), geometry.dims(), least);
                if halvings > 0
                    && let Some((detail, classified)) = self.classify_coarse_copy(
                        (id, node, world),
                        view,
                        (key, &options),
                        halvings,
                        &fail,
                    )?
                {
                    if let Some(state) = self.volumes.get(&(id, detail)) {
                        afford(&state.classified)?;
                    }
                    made += usize::from(classified);
                    report.coarse_copies += 1;
                    self.levels.insert(id, detail);
                    continue;
                }
            }
            // A coarse copy's grid drawn by earlier previews goes once the own grid is drawn.
            self.volumes
                .retain(|(v, _), state| *v != id || Arc::ptr_eq(&state.volume, &node.volume));
            if stale {
                // Given up when the frame is (139M voxels take about 0.4 s).
                let result = classify_refined_in(
                    &node.volume,
                    &node.transfer,
                    &options,
                    [1; 3],
                    None,
                    self.tiles.cancel.as_deref(),
                )
                .map_err(|e| grid_failure(e, &fail))?;
                afford(&result)?;
                made += 1;
                // The other levels of the old classification go with it; its order buffers
                // are kept.
                let old = self.volumes.remove(&own);
                self.volumes.retain(|(v, _), _| *v != id);
                if result.grid.is_empty() {
                    continue;
                }
                let (orderer, ids) = old.map(|o| (o.orderer, o.ids)).unwrap_or_default();
                let mut state =
                    VolumeState::new(key, Arc::clone(&node.volume), [1; 3], result, orderer, ids);
                state.occupied = Some(Occupied::of(&state.classified));
                self.volumes.insert(own, state);
            }
            let Some(full) = self.volumes.get(&own) else {
                continue;
            };
            // The own grid's bricks on the image, where the factors counted them (kept for the
            // refinement's region below).
            let mut on_image_counted: Option<Option<Region>> = None;
            let wanted = if self.full_grid {
                Detail::default()
            } else {
                let geometry =
                    placed_geometry(&full.volume, world).map_err(|e| fail(e.to_string()))?;
                let apart = apart_near(&geometry, view, full.occupied.as_ref());
                // The view's own detail, whatever was drawn before: a refinement made for
                // other factors is not kept while its voxels stay near enough a pixel apart, as
                // it once was, since the picture would then depend on the views before it (and
                // the viewer's screenshot would not be `render`'s picture of its scene file).
                // A refinement classified within the occupied bricks on the image may count
                // those alone, its splats bounded by the pixels; else the whole grid
                // ([`refine_factors`]). A preview draws no refinement: the bricks
                // on the image are not looked for.
                let within = match (&full.occupied, self.refine_whole) {
                    (Some(occupied), false) if preview == 0 => {
                        let shown = on_image(&geometry, view);
                        let (voxels, splats) =
                            on_image_within(geometry.dims(), occupied, shown.as_ref());
                        on_image_counted = Some(shown);
                        Within {
                            voxels,
                            splats: Some((splats, most_refined_splats(view.size))),
                        }
                    }
                    _ => Within::WHOLE,
                };
                detail_at(geometry.dims(), apart, within)
            };
            let mut wanted = match wanted {
                Detail::Level(level, facing) if preview > 0 => {
                    level_facing(level.map(|l| preview_level(l, preview)), facing)
                }
                Detail::Refined(_) if preview > 0 => {
                    Detail::Level([preview_level(0, preview); 3], [0; 3])
                }
                Detail::Refined(_) if self.no_refinement => {
                    report.unrefined = true;
                    Detail::default()
                }
                wanted => wanted,
            };
            // What each brick on the image wants, where they may differ. In a volume drawn
            // refined, a brick whose voxels fall more than a pixel apart is refined too:
            // splats a coarse voxel wide are far softer than the field (BENCHMARKS.md,
            // "Bricks at their own levels").
            let brick_wants = match (&full.occupied, by_brick && !self.full_grid) {
                (Some(occupied), true) => {
                    let geometry =
                        placed_geometry(&full.volume, world).map_err(|e| fail(e.to_string()))?;
                    let refine_from = match wanted {
                        Detail::Refined(_) => COARSEN_TO,
                        Detail::Level(..) => REFINE_TO,
                    };
                    Some(brick_details(
                        &geometry,
                        view,
                        occupied,
                        preview,
                        refine_from,
                    ))
                }
                _ => None,
            };
            // The own grid's voxel size in the world (the opacities' step).
            let spacing = placed_geometry(&node.volume, world)
                .map_err(|e| fail(e.to_string()))?
                .spacing();
            self.frame += 1;
            let frame = self.frame;
            // The bricks that want refining take the refinement wanted, or the own grid
            // without one.
            let refined_or_own = match wanted {
                Detail::Refined(_) => wanted,
                Detail::Level(..) => Detail::default(),
            };
            let levels_for_one_frame = self.levels_for_one_frame;
            let mut brick_wants = brick_wants.map(|wants| {
                wants
                    .into_iter()
                    .map(|w| match w.detail {
                        Detail::Refined(_) => BrickWant {
                            detail: refined_or_own,
                            smooth: None,
                            ..w
                        },
                        // No smooth brick coarser where levels are made only where they pay
                        // (its spread would be measured on a level).
                        Detail::Level(..) if levels_for_one_frame => {
                            BrickWant { smooth: None, ..w }
                        }
                        Detail::Level(..) => w,
                    })
                    .collect::<Vec<_>>()
            });
            // Where levels are made only where they pay, the levels not made yet that save
            // more drawing in this frame than their making costs are made; the volume or
            // bricks that want others draw the coarsest level made no coarser, else the own
            // grid ([`levels_that_pay`]).
            let mut paying_levels = false;
            if levels_for_one_frame {
                // Decided as if no level were made yet: the levels earlier frames made are
                // reused where this frame makes them, but drawn only where they pay in it, so
                // that the picture is the one a fresh renderer draws (a script's frames are
                // `splatscene render`'s pictures, whatever it drew before).
                let made: Vec<Detail> = vec![Detail::default()];
                let unmade = |d: &Detail| matches!(d, Detail::Level(..)) && !made.contains(d);
                let mut asked: Vec<(Detail, f64)> = Vec::new();
                for w in brick_wants.iter().flatten().filter(|w| unmade(&w.detail)) {
                    match asked.iter_mut().find(|(d, _)| *d == w.detail) {
                        Some((_, n)) => *n += f64::from(w.splats),
                        None => asked.push((w.detail, f64::from(w.splats))),
                    }
                }
                // The volume's own level, where no brick asks for it, saves nothing alone.
                if unmade(&wanted) && !asked.iter().any(|(d, _)| *d == wanted) {
                    let n = match brick_wants {
                        Some(_) => 0.0,
                        None => full.classified.grid.len() as f64,
                    };
                    asked.push((wanted, n));
                }
                let instead = levels_that_pay(&asked, &made, full.classified.grid.len());
                paying_levels = instead.iter().any(|(_, d)| !made.contains(d));
                report.levels_not_made |= instead.iter().any(|(a, d)| a != d);
                let drawn = |d: Detail| {
                    instead
                        .iter()
                        .find(|(a, _)| *a == d)
                        .map_or(d, |(_, instead)| *instead)
                };
                wanted = drawn(wanted);
                for w in brick_wants.iter_mut().flatten() {
                    w.detail = drawn(w.detail);
                }
            }
            // How many splats the bricks draw, each at its detail (or the volume's one).
            let share = |wants: &[BrickWant], one: Option<Detail>| -> f64 {
                wants
                    .iter()
                    .map(|w| f64::from(w.splats) * splat_share(one.unwrap_or(w.detail)))
                    .sum()
            };
            // Smooth bricks go one level coarser where the mix could then be drawn at all.
            if let Some(wants) = brick_wants.as_mut().filter(|_| !self.no_smooth) {
                let coarsest: Vec<BrickWant> = wants
                    .iter()
                    .map(|w| BrickWant {
                        detail: w.smooth.unwrap_or(w.detail),
                        ..*w
                    })
                    .collect();
                if wants.iter().any(|w| w.smooth.is_some())
                    && share(&coarsest, None) * MIX_SAVING <= share(wants, Some(wanted))
                {
                    self.draw_smooth_coarser(id, spacing, wants, report)
                        .map_err(|e| grid_failure(e, &fail))?;
                }
            }
            // Levels few bricks want are not made for them.
            if let Some(wants) = brick_wants.as_mut() {
                let own_splats = self
                    .volumes
                    .get(&(id, Detail::default()))
                    .map_or(0, |s| s.classified.grid.len());
                fall_back_from_rare_levels(wants, own_splats);
            }
            // Drawn brick by brick where that draws at most 1 / MIX_SAVING of the splats of
            // the one detail, by the own grid's splats in each brick; decided before any
            // refinement is made, so that a refinement for a volume drawn whole covers every
            // brick on the image.
            let brick_wants = brick_wants
                .filter(|w| {
                    w.iter().any(|w| w.detail != wanted)
                        && share(w, None) * MIX_SAVING <= share(w, Some(wanted))
                })
                .map(|w| {
                    w.into_iter()
                        .map(|w| (w.brick, w.detail, w.splats))
                        .collect::<Vec<_>>()
                });
            // A volume drawn from its own grid in part has its texels made before the levels;
            // so does one whose levels are made only where they pay, which counts on them.
            if paying_levels
                || brick_wants
                    .as_ref()
                    .is_some_and(|w| w.iter().any(|(_, d, _)| *d == Detail::default()))
            {
                self.make_own_texels(id, report);
            }
            let drawn = match wanted {
                Detail::Level(wanted, facing) => self
                    .make_levels(id, spacing, wanted, facing, report)
                    .map_err(|e| grid_failure(e, &fail))?,
                Detail::Refined(factors) => {
                    let refined = (id, wanted);
                    let region = if self.refine_whole {
                        None
                    } else {
                        let geometry = placed_geometry(&node.volume, world)
                            .map_err(|e| fail(e.to_string()))?;
                        let shown = on_image_counted
                            .take()
                            .unwrap_or_else(|| on_image(&geometry, view));
                        match &brick_wants {
                            // Drawn brick by brick: only the bricks that want refining.
                            Some(wants) => {
                                let refined: std::collections::HashSet<[u32; 3]> = wants
                                    .iter()
                                    .filter(|(_, d, _)| matches!(d, Detail::Refined(_)))
                                    .map(|(b, _, _)| *b)
                                    .collect();
                                Region::new(geometry.dims(), REGION_BRICK, |b| {
                                    shown.as_ref().is_none_or(|r| r.covers_brick(b))
                                        && refined.contains(&b.map(|c| c * REGION_BRICK / BRICK))
                                })
                                .filter(|r| !r.is_whole())
                            }
                            None => shown,
                        }
                    };
                    // Whether a refinement made covers the bricks this view shows (else the
                    // bricks it lacks are classified and joined to it, below).
                    let covered = |made: &VolumeState, region: &Option<Region>| {
                        region_covers(made.region.as_ref(), region.as_ref())
                    };
                    // Where refinements go where the own grid shows, each view has the
                    // bricks on the image that the own grid drawn alone shows looked for (once
                    // a view: redrawn from the same view, the bricks stand), the refinement
                    // classified within them, and drawn within them alone, so that the
                    // picture is the view's whatever earlier views joined to the refinement.
                    let looking = !self.refine_whole && !self.refine_hidden;
                    let looked = || seen::SeenFor {
                        view: *view,
                        world,
                        splats: node.splats,
                        clipping: scene.clipping.clone(),
                    };
                    let mut within = None;
                    if looking {
                        let standing = self
                            .volumes
                            .get(&refined)
                            .filter(|r| r.seen_for.as_ref().is_some_and(|s| *s == looked()));
                        within = match standing {
                            Some(state) => state.within.clone(),
                            None => {
                                self.make_own_texels(id, report);
                                match self.volumes.get(&own) {
                                    Some(state) => {
                                        let started = Instant::now();
                                        let geometry = state
                                            .geometry(world)
                                            .map_err(|e| fail(e.to_string()))?;
                                        let projection = projection(
                                            &geometry,
                                            view,
                                            &node.splats,
                                            &scene.clipping,
                                        );
                                        let seen = seen_bricks(
                                            &mut self.tiles,
                                            state,
                                            world,
                                            view,
                                            &projection,
                                            region.as_ref(),
                                        )
                                        .map_err(fail)?;
                                        // A look cut short is not a look: not kept.
                                        if self.cancelled() {
                                            return Err(RenderError::Cancelled);
                                        }
                                        report.timings.seen += started.elapsed();
                                        seen
                                    }
                                    None => None,
                                }
                            }
                        };
                    }
                    let region = within.clone().or(region);
                    let kept = self
                        .volumes
                        .get(&refined)
                        .is_some_and(|made| covered(made, &region));
                    if !kept {
                        // The refinement made at these factors, within fewer bricks than this
                        // view shows: only the bricks it lacks are classified, and joined to it.
                        let previous = self
                            .volumes
                            .remove(&refined)
                            .and_then(|mut p| p.region.take().map(|made| (p, made)))
                            // A refinement that holds over twice the bricks this view wants is
                            // made anew within them: joined for ever, a camera that travels
                            // would hold every brick it passed, and the memory budget could
                            // refuse a view that alone fits.
                            .filter(|(_, made)| {
                                region.as_ref().is_none_or(|wanted| {
                                    made.bricks_covered() <= 2 * wanted.bricks_covered()
                                })
                            });
                        let view_region = region.clone();
                        let (mut region, extra) = match (&previous, region) {
                            (Some((_, made)), wanted) => {
                                let extra = match &wanted {
                                    Some(wanted) => wanted.without(made),
                                    None => Some(made.complement()),
                                };
                                let union = match wanted {
                                    Some(wanted) => made.union(&wanted).filter(|r| !r.is_whole()),
                                    None => None,
                                };
                                (union, extra)
                            }
                            (None, region) => (region, None),
                        };
                        // One refinement a volume is kept: a view that wants another makes it
                        // anew.
                        self.volumes
                            .retain(|(v, d), _| *v != id || matches!(d, Detail::Level(..)));
                        // Given up when the frame is (a close-up's refinement takes up to a
                        // second); nothing of it is kept.
                        let cancel = self.tiles.cancel.clone();
                        let classify = |region: Option<&Region>| {
                            classify_refined_in(
                                &node.volume,
                                &node.transfer,
                                &options,
                                factors,
                                region,
                                cancel.as_deref(),
                            )
                            .map_err(|e| match e {
                                crate::grid::GridError::Cancelled => RenderError::Cancelled,
                                e => fail(e.to_string()),
                            })
                        };
                        let (result, orderer, ids, adopted) = match (previous, extra) {
                            (Some((mut previous, made)), Some(extra)) => {
                                let more = match classify(Some(&extra)) {
                                    Err(RenderError::Cancelled) => {
                                        // Given up: the refinement made before stays whole.
                                        previous.region = Some(made);
                                        self.volumes.insert(refined, previous);
                                        return Err(RenderError::Cancelled);
                                    }
                                    more => more?,
                                };
                                let VolumeState {
                                    classified,
                                    orderer,
                                    mut ids,
                                    texels,
                                    gpu,
                                    ..
                                } = previous;
                                // Made anew for the joined grid, the texels taking over the
                                // normals made for this one.
                                drop(gpu);
                                afford(&more)?;
                                let joined = classified
                                    .joined_with(more)
                                    .map_err(|e| fail(e.to_string()))?;
                                ids.clear();
                                if afford(&joined).is_ok() {
                                    (joined, orderer, ids, texels)
                                } else {
                                    // Past the budget joined: the view's bricks alone.
                                    drop((joined, texels));
                                    region = view_region;
                                    (classify(region.as_ref())?, orderer, ids, None)
                                }
                            }
                            _ => (classify(region.as_ref())?, Orderer::new(), Vec::new(), None),
                        };
                        afford(&result)?;
                        made += 1;
                        let mut state = VolumeState::new(
                            key,
                            Arc::clone(&node.volume),
                            factors,
                            result,
                            orderer,
                            ids,
                        );
                        state.region = region;
                        state.adopted = adopted;
                        self.volumes.insert(refined, state);
                    }
                    if let Some(state) = self.volumes.get_mut(&refined) {
                        state.seen_for = looking.then(looked);
                        if state.within != within {
                            state.within = within;
                            state.ordered_for = None;
                        }
                    }
                    wanted
                }
            };
            if let Some(wants) = brick_wants {
                // Each level the bricks want, made once (a level that could not be made as
                // wanted stands for the one reached on its way).
                let mut reached: HashMap<Detail, Detail> = HashMap::new();
                let mut bricks = Vec::with_capacity(wants.len());
                for (brick, want, _) in wants {
                    let got = match (reached.get(&want), want) {
                        (Some(got), _) => *got,
                        (None, Detail::Level(levels, facing)) if want != drawn => {
                            let got = self
                                .make_levels(id, spacing, levels, facing, report)
                                .map_err(|e| grid_failure(e, &fail))?;
                            reached.insert(want, got);
                            got
                        }
                        _ => want,
                    };
                    bricks.push((brick, got));
                }
                if bricks.iter().any(|(_, d)| *d != drawn) {
                    let mut mix = self.spare_mixes.pop().unwrap_or_default();
                    mix.bricks = bricks;
                    self.mixes.insert(id, mix);
                }
            }
            // Uneven levels past the splats kept go, least recently used first.
            let uneven: Vec<(Detail, u64, usize)> = self
                .volumes
                .iter()
                .filter(|((v, d), _)| *v == id && is_uneven(*d))
                .map(|((_, d), state)| (*d, state.used, state.classified.grid.len()))
                .collect();
            let own_splats = (self.volumes.get(&(id, Detail::default())))
                .map_or(0, |own| own.classified.grid.len());
            for d in uneven_levels_dropped(uneven, own_splats, frame) {
                self.volumes.remove(&(id, d));
            }
            self.levels.insert(id, drawn);
        }
        self.volumes.retain(|(id, _), _| live.contains(id));
        self.coarse_copies.retain(|id, _| live.contains(id));
        Ok(made)
    }

    /// For a preview of volume `id` (placed by `world`) whose own grid is not classified for
    /// `key`, its coarse copy halved `halvings` times (at least once), classified for `key`
    /// (the copy made now where it was not): the detail its grid is held at in `volumes`, and
    /// whether it was classified now; `None` where the memory left cannot hold a copy not yet
    /// made (the preview then draws the own grid, as a full frame would: a copy is an eighth
    /// of the values, and a sparse volume's classified grid can take less). The copy is
    /// classified only within its bricks whose splats can land on `view`'s image
    /// ([`on_image`]), unless refinements are classified whole
    /// ([`Renderer::set_refinement_on_image_only`]); a view that shows a brick the
    /// classification left out classifies it anew.
    fn classify_coarse_copy(
        &mut self,
        (id, node, world): (NodeId, &VolumeNode, DMat4),
        view: &ViewSetup,
        (key, options): (ClassKey, &ClassifyOptions),
        halvings: u8,
        fail: &dyn Fn(String) -> RenderError,
    ) -> Result<Option<(Detail, bool)>, RenderError> {
        let halvings = usize::from(halvings.max(1));
        let headroom = self.headroom();
        let copies = self.coarse_copies.entry(id).or_insert_with(|| CoarseCopy {
            of: Arc::downgrade(&node.volume),
            halved: Vec::new(),
        });
        if !std::ptr::eq(copies.of.as_ptr(), Arc::as_ptr(&node.volume)) {
            copies.of = Arc::downgrade(&node.volume);
            copies.halved.clear();
        }
        // Each copy halved from the one before.
        while copies.halved.len() < halvings {
            let (levels, above) = match copies.halved.last() {
                Some((levels, volume)) => (*levels, Arc::clone(volume)),
                None => ([0; 3], Arc::clone(&node.volume)),
            };
            let dims = above.dims.map(|n| u64::from(n.div_ceil(2)));
            let bytes = crate::volume::Voxels::held_bytes(above.values.scalar_type()) as u64;
            if dims.iter().product::<u64>().saturating_mul(bytes) > headroom {
                return Ok(None);
            }
            let levels = [0, 1, 2].map(|a| levels[a] + u8::from(above.dims[a] > 1));
            let halved = above
                .halved_unless_cancelled(self.tiles.cancel.as_deref())
                .ok_or(RenderError::Cancelled)?;
            copies.halved.push((levels, Arc::new(halved)));
        }
        let Some((levels, copy)) = copies.halved.get(halvings - 1) else {
            return Err(fail("no coarse copy was made".into()));
        };
        let (detail, copy) = (Detail::Level(*levels, [0; 3]), Arc::clone(copy));
        // While the values are windowed the camera stands: each preview classifies the copy
        // anew, and a view that shows part of the volume (a shoulder close up) pays for that
        // part alone.
        let region = if self.refine_whole {
            None
        } else {
            let geometry = placed_geometry(&copy, world).map_err(|e| fail(e.to_string()))?;
            on_image(&geometry, view)
        };
        let same_function = (self.volumes.get(&(id, detail)))
            .filter(|s| s.key == key && Arc::ptr_eq(&s.volume, &copy));
        if same_function.is_some_and(|s| region_covers(s.region.as_ref(), region.as_ref())) {
            return Ok(Some((detail, false)));
        }
        // The function stands and the camera moves (the camera turned before the own grid was
        // classified): the next views would want other bricks again, and the whole copy,
        // classified once, serves them all.
        let region = region.filter(|_| same_function.is_none());
        let classified = classify_refined_in(
            &copy,
            &node.transfer,
            options,
            [1; 3],
            region.as_ref(),
            self.tiles.cancel.as_deref(),
        )
        .map_err(|e| grid_failure(e, fail))?;
        let (orderer, ids) = self
            .volumes
            .remove(&(id, detail))
            .map(|o| (o.orderer, o.ids))
            .unwrap_or_default();
        let mut state = VolumeState::new(key, copy, [1; 3], classified, orderer, ids);
        state.region = region;
        self.volumes.insert((id, detail), state);
        Ok(Some((detail, true)))
    }

    /// Orders every volume's splats for this view; returns the volumes far to near.
    fn order_volumes(
        &mut self,
        scene: &Scene,
        view: &ViewSetup,
        options: &FrameOptions,
        report: &mut FrameReport,
    ) -> Result<Vec<(NodeId, VolumeGeometry)>, RenderError> {
        let started = Instant::now();
        let pinhole = view.pinhole()?;
        let mut ordered = Vec::new();
        for (id, node, world) in scene.volumes() {
            let name = &scene.nodes()[id.0].name;
            let fail = |message: String| RenderError::Volume {
                node: name.clone(),
                message,
            };
            let ordering = options.ordering.unwrap_or(node.splats.ordering);
            let order_options = OrderOptions {
                cull_behind_eye: true,
                ..Default::default()
            };
            if let Some(mix) = self.mixes.get_mut(&id) {
                order_mix(
                    &mut self.volumes,
                    id,
                    world,
                    (pinhole.eye, pinhole.target),
                    (ordering, &order_options),
                    mix,
                )
                .map_err(fail)?;
                report.splats += mix.ids.len();
                report.bricks_by_level += 1;
                for (d, _) in &mix.runs {
                    if let Detail::Level(level, _) = d {
                        for (most, l) in report.levels.iter_mut().zip(level) {
                            *most = (*most).max(*l);
                        }
                    }
                }
            }
            let mixed = self.mixes.contains_key(&id);
            let Some(state) = self.drawn_mut(id) else {
                continue;
            };
            let geometry = state.geometry(world).map_err(|e| fail(e.to_string()))?;
            if !mixed {
                state
                    .order(
                        world,
                        (pinhole.eye, pinhole.target),
                        (ordering, &order_options),
                    )
                    .map_err(fail)?;
                report.splats += state.ids.len();
            }
            match self.levels.get(&id).copied().unwrap_or_default() {
                // A mix's levels are counted from its runs above.
                Detail::Level(_, _) if mixed => {}
                Detail::Level(level, _) => {
                    for (most, l) in report.levels.iter_mut().zip(level) {
                        *most = (*most).max(l);
                    }
                }
                Detail::Refined(factors) => {
                    let most = report.refined.get_or_insert([1; 3]);
                    for a in 0..3 {
                        most[a] = most[a].max(factors[a]);
                    }
                }
            }
            report.level = report.levels.into_iter().max().unwrap_or(0);
            ordered.push((id, geometry));
        }
        // Between volumes: farthest centre first (volumes that interpenetrate are not sorted
        // splat by splat against each other).
        let eye = view.camera.eye;
        let distance = |g: &VolumeGeometry| (g.centre_world() - eye).length();
        ordered.sort_by(|a, b| distance(&b.1).total_cmp(&distance(&a.1)));
        report.timings.order = started.elapsed();
        Ok(ordered)
    }

    fn upload(
        &mut self,
        ctx: &GpuContext,
        scene: &Scene,
        view: &ViewSetup,
        ordered: &[(NodeId, VolumeGeometry)],
        report: &mut FrameReport,
    ) -> Result<(), RenderError> {
        let Self {
            splat_pass,
            volumes,
            levels,
            mixes,
            gpu_runs,
            ..
        } = self;
        gpu_runs.clear();
        for (id, _) in ordered {
            let Some((_, node, world)) = scene.volumes().find(|(v, _, _)| v == id) else {
                continue;
            };
            let mix = mixes.get(id);
            let details = match mix {
                Some(mix) => mix.details(),
                None => vec![levels.get(id).copied().unwrap_or_default()],
            };
            // A mix's runs of each level, one after another, as that level's order on the GPU.
            let mut mixed: Vec<Vec<u32>> = vec![Vec::new(); details.len()];
            let mut runs = Vec::new();
            match mix {
                Some(mix) => {
                    for (d, range) in &mix.runs {
                        if let Some(i) = details.iter().position(|x| x == d) {
                            let start = mixed[i].len();
                            mixed[i].extend_from_slice(&mix.ids[range.clone()]);
                            runs.push((*d, start..mixed[i].len()));
                        }
                    }
                }
                None => {
                    if let Some(state) = volumes.get(&(*id, details[0])) {
                        runs.push((details[0], 0..state.ids.len()));
                    }
                }
            }
            for (detail, ids) in details.iter().zip(&mixed) {
                let Some(state) = volumes.get_mut(&(*id, *detail)) else {
                    continue;
                };
                if state.gpu.is_none() {
                    let pass = splat_pass.get_or_insert_with(|| SplatPass::new(ctx));
                    // Every texel is read: their normals made in parallel first.
                    if let Some(texels) = &state.texels {
                        texels.complete();
                    }
                    let gpu =
                        pass.upload(ctx, &state.classified, &|k, rank| state.texel(k, rank))?;
                    state.gpu = Some(gpu);
                    state.ids_on_gpu = false;
                }
                let geometry = state.geometry(world).map_err(|e| RenderError::Volume {
                    node: scene.nodes()[id.0].name.clone(),
                    message: e.to_string(),
                })?;
                let Some(gpu) = &mut state.gpu else {
                    continue;
                };
                if mix.is_some() {
                    // The level's own order is no longer the one on the GPU.
                    SplatPass::upload_order(ctx, gpu, ids)?;
                    state.ids_on_gpu = false;
                } else if !state.ids_on_gpu {
                    SplatPass::upload_order(ctx, gpu, &state.ids)?;
                    state.ids_on_gpu = true;
                }
                SplatPass::write_uniforms(ctx, gpu, &geometry, view, &node.splats, &scene.clipping);
            }
            gpu_runs.insert(*id, runs);
        }
        if let Some(pass) = &self.mesh_pass {
            pass.write_frame(ctx, view, &scene.lights, &scene.clipping);
        }
        for (id, node, world) in scene.overlays() {
            if let Some(gpu) = self.meshes.get(&id) {
                let model = view.relative(world);
                MeshPass::write_object(ctx, gpu, model, linear_part(world), &node.material);
                report.overlays += 1;
            }
        }
        for (id, node, world) in scene.meshes() {
            if let Some(gpu) = self.meshes.get(&id) {
                MeshPass::write_object(
                    ctx,
                    gpu,
                    view.relative(world),
                    linear_part(world),
                    &node.material,
                );
                report.meshes += 1;
                report.triangles += node.mesh.triangle_count();
            }
        }
        Ok(())
    }

    fn mesh_stage(
        &self,
        ctx: &GpuContext,
        scene: &Scene,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        options: &FrameOptions,
    ) {
        let clear = options
            .background
            .map_or(wgpu::Color::TRANSPARENT, |[r, g, b]| wgpu::Color {
                r: f64::from(r),
                g: f64::from(g),
                b: f64::from(b),
                a: 1.0,
            });
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = begin(&mut encoder, color, depth, Some(clear), "mesh pass");
            if let Some(mesh_pass) = &self.mesh_pass {
                let meshes = scene
                    .meshes()
                    .filter(|(_, m, _)| !is_translucent(m))
                    .filter_map(|(id, _, _)| self.meshes.get(&id));
                mesh_pass.draw(&mut pass, meshes);
            }
        }
        ctx.queue.submit([encoder.finish()]);
    }

    fn splat_stage(
        &mut self,
        ctx: &GpuContext,
        size: (u32, u32),
        ordered: &[(NodeId, VolumeGeometry)],
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
    ) -> Result<(), RenderError> {
        if self.compositor == Compositor::GpuTiles {
            if !super::splat_pass::computes(ctx) {
                return Err(RenderError::Unsupported {
                    adapter: ctx.describe(),
                    what: "run compute shaders (the GPU tile compositor, --compositor gpu-tiles)",
                });
            }
            // The tile pass reads the meshes' depth as a texture (every `RenderTarget` allows it).
            if !depth
                .texture()
                .usage()
                .contains(wgpu::TextureUsages::TEXTURE_BINDING)
            {
                return Err(RenderError::Device(
                    "the GPU tile compositor reads the depth target as a texture, and this one was made without TEXTURE_BINDING".into(),
                ));
            }
            // The grids drawn, and their runs near to far, as the tile pass walks them.
            let mut keys: Vec<(NodeId, Detail)> = Vec::new();
            let mut runs = Vec::new();
            for (id, _) in ordered.iter().rev() {
                for (detail, range) in self.gpu_runs.get(id).into_iter().flatten().rev() {
                    let key = (*id, *detail);
                    let Some(gpu) = self.volumes.get_mut(&key).and_then(|s| s.gpu.as_mut()) else {
                        continue;
                    };
                    let source = match keys.iter().position(|k| *k == key) {
                        Some(source) => source,
                        None => {
                            TilePass::prepare(ctx, gpu);
                            keys.push(key);
                            keys.len() - 1
                        }
                    };
                    runs.push((source, range.clone()));
                }
            }
            let volumes: Vec<&GpuVolume> = keys
                .iter()
                .filter_map(|key| self.volumes.get(key).and_then(|s| s.gpu.as_ref()))
                .collect();
            if volumes.len() < keys.len() || runs.is_empty() {
                return Ok(());
            }
            let pass = self.tile_pass.get_or_insert_with(|| TilePass::new(ctx));
            if let Some(batch) = self.gpu_tile_batch {
                pass.set_batch(batch);
            }
            return pass.draw(ctx, &volumes, &runs, size, self.tiles.opaque, color, depth);
        }
        let Some(splat_pass) = &self.splat_pass else {
            return Ok(());
        };
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = begin(&mut encoder, color, depth, None, "splat pass");
            for (id, _) in ordered {
                for (detail, range) in self.gpu_runs.get(id).into_iter().flatten() {
                    if let Some(gpu) = self
                        .volumes
                        .get(&(*id, *detail))
                        .and_then(|s| s.gpu.as_ref())
                    {
                        splat_pass.draw(&mut pass, gpu, range.clone());
                    }
                }
            }
        }
        ctx.queue.submit([encoder.finish()]);
        Ok(())
    }

    /// Draws overlay meshes over the finished frame.
    /// Draws the translucent meshes far to near (by their centres' distance from the eye):
    /// each one's nearest surface blended over what is there, hidden by the opaque meshes and
    /// by nearer translucent ones. Approximate in two ways: splats in front of a translucent
    /// mesh are drawn under it (translucent meshes come after all splats), and of a
    /// translucent mesh seen through another, only the parts the sort puts behind show. The
    /// depth is left holding the translucent surfaces (so depth images and picks see them).
    fn translucent_stage(
        &self,
        ctx: &GpuContext,
        scene: &Scene,
        view: &ViewSetup,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
    ) {
        let Some(mesh_pass) = &self.mesh_pass else {
            return;
        };
        let eye = view.camera.eye;
        let mut far_to_near: Vec<(f64, NodeId)> = scene
            .meshes()
            .filter(|(_, m, _)| is_translucent(m))
            .map(|(id, m, world)| {
                let centre = m.mesh.bounds().map_or(DVec3::ZERO, |(lo, hi)| {
                    0.5 * (DVec3::from(lo.map(f64::from)) + DVec3::from(hi.map(f64::from)))
                });
                (world.transform_point3(centre).distance_squared(eye), id)
            })
            .collect();
        if far_to_near.is_empty() {
            return;
        }
        far_to_near.sort_by(|a, b| b.0.total_cmp(&a.0));
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = begin(&mut encoder, color, depth, None, "translucent pass");
            let meshes = far_to_near.iter().filter_map(|(_, id)| self.meshes.get(id));
            mesh_pass.draw_translucent(&mut pass, meshes);
        }
        ctx.queue.submit([encoder.finish()]);
    }

    fn overlay_stage(
        &self,
        ctx: &GpuContext,
        scene: &Scene,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
    ) {
        let Some(mesh_pass) = self.mesh_pass.as_ref().filter(|p| p.has_overlay()) else {
            return;
        };
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = begin(&mut encoder, color, depth, None, "overlay pass");
            let overlays = scene
                .overlays()
                .filter_map(|(id, _, _)| self.meshes.get(&id));
            mesh_pass.draw_overlay(&mut pass, overlays);
        }
        ctx.queue.submit([encoder.finish()]);
    }
}

/// Waits until everything drawn into `color` is really there. Software rasterisers such as
/// llvmpipe bin geometry at submission and rasterise only when the pixels are needed, so a
/// plain wait would leave the fragment work to whatever reads the target next: reading one
/// texel back forces it.
fn finish_drawing(ctx: &GpuContext, color: &wgpu::TextureView) -> Result<(), RenderError> {
    let texture = color.texture();
    let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("finish drawing"),
        size: 256,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    encoder.copy_texture_to_buffer(
        texture.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: None,
                rows_per_image: None,
            },
        },
        wgpu::Extent3d::default(),
    );
    ctx.queue.submit([encoder.finish()]);
    buffer.map_async(wgpu::MapMode::Read, .., |_| {});
    ctx.wait()
}

/// Whether a mesh is drawn translucent: its material's alpha is below 1.
fn is_translucent(mesh: &crate::scene::MeshNode) -> bool {
    mesh.material.base_color[3] < 1.0
}

/// A pass that clears the colour to transparent and keeps the depth.
fn begin_keeping_depth<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    color: &wgpu::TextureView,
    depth: &wgpu::TextureView,
) -> wgpu::RenderPass<'e> {
    let clear = wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT);
    begin_with(
        encoder,
        (color, clear),
        (depth, wgpu::LoadOp::Load),
        "clear the colour",
    )
}

/// A render pass on the targets; `clear` clears colour (and depth to 0, reversed far),
/// `None` keeps what is there.
fn begin<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    color: &wgpu::TextureView,
    depth: &wgpu::TextureView,
    clear: Option<wgpu::Color>,
    label: &str,
) -> wgpu::RenderPass<'e> {
    let load = clear.map_or(wgpu::LoadOp::Load, wgpu::LoadOp::Clear);
    let depth_load = if clear.is_some() {
        wgpu::LoadOp::Clear(0.0)
    } else {
        wgpu::LoadOp::Load
    };
    begin_with(encoder, (color, load), (depth, depth_load), label)
}

/// A render pass on the targets with each one's load operation.
fn begin_with<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    (color, load): (&wgpu::TextureView, wgpu::LoadOp<wgpu::Color>),
    (depth, depth_load): (&wgpu::TextureView, wgpu::LoadOp<f32>),
    label: &str,
) -> wgpu::RenderPass<'e> {
    encoder
        .begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some(label),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: color,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load,
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: depth,
                depth_ops: Some(wgpu::Operations {
                    load: depth_load,
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        })
        .forget_lifetime()
}

/// How many times a volume of `dims` voxels `spacing` millimetres apart is halved
/// ([`CpuVolume::halved`]) for a preview's coarse copy: as often as the level the preview
/// draws, `least` (at least once), while the copy's voxels stay at most
/// [`PREVIEW_COPY_SPACING_MM`] apart along every axis it halves; 0 where once is too coarse.
fn copy_halvings(spacing: [f64; 3], dims: [u32; 3], least: u8) -> u8 {
    let fine_enough = |h: u8| {
        (0..3).all(|a| dims[a] <= 1 || spacing[a] * f64::from(1u32 << h) <= PREVIEW_COPY_SPACING_MM)
    };
    (1..=least.clamp(1, MAX_LEVEL))
        .take_while(|&h| fine_enough(h))
        .last()
        .unwrap_or(0)
}

/// A grid's error as a frame's: [`RenderError::Cancelled`] for a classification or level given
/// up, else `fail`'s message.
fn grid_failure(e: crate::grid::GridError, fail: &dyn Fn(String) -> RenderError) -> RenderError {
    match e {
        crate::grid::GridError::Cancelled => RenderError::Cancelled,
        e => fail(e.to_string()),
    }
}

fn class_key(node: &VolumeNode) -> ClassKey {
    (
        Arc::as_ptr(&node.volume) as usize,
        Arc::as_ptr(&node.transfer) as usize,
        node.splats.min_opacity.to_bits(),
        node.splats.opacity_reference_mm.to_bits(),
        node.splats.style.sigma.to_bits(),
        node.splats.style.cutoff.to_bits(),
        node.splats.shell.map(f32::to_bits),
    )
}

fn linear_part(m: DMat4) -> DMat3 {
    DMat3::from_mat4(m)
}

#[cfg(test)]
mod tests;
