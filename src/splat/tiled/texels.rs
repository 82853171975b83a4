//! The splats' data as the compositor reads it: 8 bytes a significant voxel, brick by brick.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, Ordering};

use rayon::prelude::*;

use crate::cancel::Parts;
use crate::classify::{Classified, Front, RefinedGradients, refined_gradient_snorm8, snorm8};
use crate::grid::SparseGrid;
use crate::volume::CpuVolume;

/// A volume's splat data in 8 bytes a splat: straight RGB8 colour, the unit index-space
/// gradient as snorm8 (all zero where undefined), and the density as an f16 (see
/// [`crate::classify::SplatColor`]), for the significant voxels alone, stored brick by brick
/// (4x4x4 voxels).
///
/// Bricks, since the draw order runs along any axis: within a brick the next voxel along y or
/// z is as near as the next along x. Only significant voxels, since a frame reads the texel of
/// every splat it projects, and packed, the texels of neighbouring splats share cache lines
/// (the engine's 1.05M voxels with opacity, of 8.4M, take 8 MB of texels instead of 67 MB).
/// A brick's significant voxels are a bit mask, and a voxel's texel is found by counting the
/// bits before its own. The bricks are held by pages of 4x4x4 bricks, only the pages with a
/// significant voxel stored: a refinement classified within the bricks on the image holds
/// no table of its whole grid.
///
/// The texels of a classified grid are written as each brick is first read
/// ([`SplatTexels::new`]), their colours from the classification and their normals from the
/// volume's gradients: a frame reads the texels of the splats it projects, and where most
/// splats lie behind opaque ones (a close-up of bone, a dense volume) most would never be
/// asked for. Their room is allocated zeroed, so the memory pages of bricks never read are
/// never touched either: the 0.75 mm abdomen CT with a window of soft tissue (41M splats)
/// seen from behind reads 7M of them.
#[derive(Debug, Default)]
pub struct SplatTexels {
    pub(super) dims: [u32; 3],
    /// Bricks along x and y.
    pub(super) bricks: [usize; 2],
    /// Pages of [`PAGE`]^3 bricks along x, y and z.
    pages: [usize; 3],
    /// Per page (x fastest), its place among the stored pages, or [`EMPTY_PAGE`] where none of
    /// its bricks holds a significant voxel.
    page_table: Vec<u32>,
    /// The stored pages' bricks, [`PAGE`]^3 a page (x fastest within it), in page order. (A
    /// table of every brick took 16 bytes a brick of the whole grid: 418 MB for a refinement
    /// of 1.7G voxels classified within the few bricks on the image.)
    pub(super) table: Vec<Brick>,
    /// The texels' 8 bytes each as a little-endian `u64`; atomic, so that the thread that
    /// first reads a brick can write its normals while others read other bricks.
    pub(super) texels: Vec<AtomicU64>,
    /// Where the texels are made as their bricks are first read.
    normals: Option<LazyNormals>,
}

/// The texels of a grid, made a unit of bricks at a time as the unit is first read: their
/// colours and densities from the classification, their normals from `source`.
#[derive(Debug)]
struct LazyNormals {
    classified: Arc<Classified>,
    source: NormalSource,
    /// Per unit of [`NORMAL_UNIT`] bricks along x: [`NOT_MADE`], [`MAKING`] or [`MADE`].
    state: Vec<AtomicU8>,
}

/// Where the normals of texels made as they are read come from.
#[derive(Debug)]
enum NormalSource {
    /// The gradients of the volume the grid was classified from ([`SplatTexels::new`]).
    Gradients(RefinedGradients),
    /// The texels of the level below, block by block ([`SplatTexels::halved`]).
    Halved(HalvedFrom),
}

/// The level below a level's texels, and how a block of it becomes one of the level's
/// normals ([`SplatTexels::halved`]).
#[derive(Debug)]
struct HalvedFrom {
    /// The level below's texels; the bricks of them a block reads are made as they are read
    /// in turn, so a chain of levels makes only what the bricks drawn need. A brick's unit
    /// of the level is made while the units below it are, never the other way round, so the
    /// threads waiting on each other's units never wait in a circle.
    fine: Arc<SplatTexels>,
    /// 2 along each axis halved, else 1.
    step: [u32; 3],
    /// A front along the one axis halved, else none.
    front: Option<Front>,
    /// With a front, each voxel's opacity along it by the bits of its density.
    alphas: Vec<f32>,
}

impl HalvedFrom {
    /// The normal of voxel `k` of the level: the mean of its block's normals with the weights
    /// its colour had, as [`SplatTexels::halved`] says; `None` where they cancel.
    fn normal(&self, k: [u32; 3]) -> Option<[u8; 3]> {
        let step = self.step;
        let bits = |t: &[u8; 8]| u16::from_le_bytes([t[6], t[7]]);
        let alpha = |t: &[u8; 8]| {
            (self.alphas.get(usize::from(bits(t))))
                .copied()
                .unwrap_or(0.0)
        };
        let normal = |t: &[u8; 8]| {
            glam::Vec3::new(
                f32::from(t[3] as i8),
                f32::from(t[4] as i8),
                f32::from(t[5] as i8),
            )
        };
        let fine = |d: [u32; 3]| {
            let [x, y, z] = std::array::from_fn(|a| k[a] * step[a] + d[a]);
            self.fine.get(x, y, z)
        };
        let sum = match self.front {
            Some(front) => {
                // The pair along the axis, nearer first, weighted as a ray composites them.
                let mut ends = [[0; 3]; 2];
                ends[usize::from(!front.larger_nearer)][front.axis] = 1;
                let [near, far] = ends.map(&fine);
                let near_alpha = near.as_ref().map_or(0.0, alpha);
                let mut normals = [(0.0, glam::Vec3::ZERO); 2];
                if let Some(t) = &near {
                    normals[0] = (near_alpha, normal(t));
                }
                if let Some(t) = &far {
                    normals[1] = ((1.0 - near_alpha) * alpha(t), normal(t));
                }
                shading_normal(&normals, front.axis)
            }
            None => {
                let mut weighted = [(0.0, glam::Vec3::ZERO); 8];
                let mut n = 0;
                for dz in 0..step[2] {
                    for dy in 0..step[1] {
                        for dx in 0..step[0] {
                            if let Some(t) = fine([dx, dy, dz]) {
                                weighted[n] = (texel_density(bits(&t)), normal(&t));
                                n += 1;
                            }
                        }
                    }
                }
                one_sided_sum(&weighted[..n])
            }
        };
        snorm8(sum * glam::Vec3::from(step.map(|s| s as f32)))
    }
}

/// A texel's density from its f16 bits, as the colours' halving takes it: opaque voxels
/// count as the largest half, and a NaN as nothing.
fn texel_density(bits: u16) -> f32 {
    let d = half::f16::from_bits(bits).to_f32();
    if d.is_nan() { 0.0 } else { d.min(65504.0) }
}

/// Bricks along x whose normals are made together: neighbouring bricks along x read the
/// volume's same rows (cache lines) for their gradients.
const NORMAL_UNIT: usize = 4;

/// A unit whose normals are not made yet.
const NOT_MADE: u8 = 0;
/// A unit whose normals a thread is making.
const MAKING: u8 = 1;
/// A unit whose normals are made.
const MADE: u8 = 2;

/// Which voxels of a brick have opacity, and where their texels start.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Brick {
    /// Bit `(z * 4 + y) * 4 + x` for voxel `(x, y, z)` of the brick.
    pub(super) present: u64,
    /// The index in the texels of the brick's first voxel with opacity.
    pub(super) first: u32,
}

/// Brick side in voxels.
pub(super) const BRICK: usize = 4;

/// A texel of a voxel given its coordinates and rank ([`SplatTexels::build`]).
type Texel = fn([u32; 3], usize) -> [u8; 8];

/// Page side in bricks: the brick table is held by pages of 16^3 voxels, those with no
/// significant voxel not stored.
const PAGE: usize = 4;
/// Bricks a page.
const PAGE_BRICKS: usize = PAGE * PAGE * PAGE;
/// The page table's mark for a page not stored.
const EMPTY_PAGE: u32 = u32::MAX;

impl SplatTexels {
    /// The texels of a classified volume: its colours and densities, and the gradients of the
    /// volume it was classified from, on a grid `factors` times finer than the volume's
    /// ([`crate::classify::classify_refined`]; `[1, 1, 1]` for its own). Laid out brick by
    /// brick from the significant voxels; no buffer the size of the whole grid. Each brick's
    /// texels are written when the brick is first read ([`SplatTexels::get`]).
    pub fn new(classified: &Arc<Classified>, volume: &Arc<CpuVolume>, factors: [u32; 3]) -> Self {
        let Some(mut texels) = Self::build_unless_cancelled(&classified.grid, None::<Texel>, None)
        else {
            unreachable!("texels built with no cancel flag are never given up")
        };
        texels.normals = Some(LazyNormals {
            classified: Arc::clone(classified),
            source: NormalSource::Gradients(RefinedGradients::new(Arc::clone(volume), factors)),
            state: (0..texels.brick_rows() * texels.units_x())
                .map(|_| AtomicU8::new(NOT_MADE))
                .collect(),
        });
        texels
    }

    /// Makes every brick's normals not made yet, in parallel: for a whole grid's texels read
    /// at once.
    pub fn complete(&self) {
        self.complete_unless_cancelled(None);
    }

    /// [`SplatTexels::complete`], stopping once `cancel` is raised (looked at before each
    /// unit of bricks): whether every brick's normals are made. The normals made stay; the
    /// others are made when their bricks are first read, as before.
    pub fn complete_unless_cancelled(&self, cancel: Option<&AtomicBool>) -> bool {
        let parts = Parts::new(cancel);
        if let Some(lazy) = &self.normals {
            (0..lazy.state.len()).into_par_iter().for_each(|u| {
                if !parts.skip() {
                    self.ensure_unit(u, lazy);
                }
            });
        }
        !parts.skipped()
    }

    /// Makes, in parallel, the normals not made yet of the units of bricks that hold a voxel
    /// of any of `boxes` (each a half-open range of voxels along each axis): the bricks a
    /// frame is about to read, made before it rather than as its projection reads them.
    /// Returns how many units it made.
    pub fn complete_within(&self, boxes: &[[(u32, u32); 3]]) -> usize {
        let Some(lazy) = &self.normals else {
            return 0;
        };
        let brick_dims = [
            self.bricks[0],
            self.bricks[1],
            self.dims[2].div_ceil(BRICK as u32) as usize,
        ];
        let units_x = self.units_x();
        let made = |u: usize| {
            lazy.state
                .get(u)
                .is_none_or(|s| s.load(Ordering::Acquire) == MADE)
        };
        let mut units: Vec<usize> = boxes
            .par_iter()
            .flat_map_iter(|b| {
                let range = |a: usize| {
                    let (lo, hi) = (b[a].0 as usize / BRICK, (b[a].1 as usize).div_ceil(BRICK));
                    lo..hi.min(brick_dims[a])
                };
                let (xs, ys, zs) = (range(0), range(1), range(2));
                let units = xs.start / NORMAL_UNIT..xs.end.div_ceil(NORMAL_UNIT);
                zs.flat_map(move |bz| ys.clone().map(move |by| (by, bz)))
                    .flat_map(move |(by, bz)| {
                        let row = bz * brick_dims[1] + by;
                        units.clone().map(move |ux| row * units_x + ux)
                    })
                    .filter(|&u| !made(u))
            })
            .collect();
        units.par_sort_unstable();
        units.dedup();
        units.par_iter().for_each(|&u| self.ensure_unit(u, lazy));
        units.len()
    }

    /// Rows of bricks along x, all layers.
    fn brick_rows(&self) -> usize {
        self.bricks[1] * self.dims[2].div_ceil(BRICK as u32) as usize
    }

    /// Units of [`NORMAL_UNIT`] bricks along x in a row of bricks.
    fn units_x(&self) -> usize {
        self.bricks[0].div_ceil(NORMAL_UNIT)
    }

    /// The texels of `grid`'s voxels, each given by `texel(voxel, rank)`.
    pub fn build(grid: &SparseGrid, texel: impl Fn([u32; 3], usize) -> [u8; 8] + Sync) -> Self {
        match Self::build_unless_cancelled(grid, Some(texel), None) {
            Some(texels) => texels,
            None => unreachable!("texels built with no cancel flag are never given up"),
        }
    }

    /// [`SplatTexels::build`], given up (`None`, nothing kept) once `cancel` is raised:
    /// looked at before each layer of pages is surveyed and before each page's texels are
    /// written. With no `texel`, the texels are laid out and left zero.
    fn build_unless_cancelled(
        grid: &SparseGrid,
        texel: Option<impl Fn([u32; 3], usize) -> [u8; 8] + Sync>,
        cancel: Option<&AtomicBool>,
    ) -> Option<Self> {
        let parts = Parts::new(cancel);
        let dims = grid.dims();
        let [nx, ny, nz] = dims.map(|n| n as usize);
        let bricks = [nx.div_ceil(BRICK), ny.div_ceil(BRICK)];
        let layer = bricks[0] * bricks[1];
        let layers = nz.div_ceil(BRICK);
        if layer == 0 || layers == 0 {
            return Some(Self::default());
        }
        let pages = [bricks[0], bricks[1], layers].map(|n| n.div_ceil(PAGE));
        let page_layer = pages[0] * pages[1];
        // Which voxels are significant, a layer of pages (sixteen z-slices) a task, from the
        // grid's x rows; each layer's pages that hold one, with their bricks' masks.
        // The x rows are read from every task below: made first, not by the first task.
        grid.prepare_rows(0);
        let per_layer: Vec<Vec<(usize, [u64; PAGE_BRICKS])>> = (0..pages[2])
            .into_par_iter()
            .map(|pz| {
                if parts.skip() {
                    return Vec::new();
                }
                let mut masks = vec![[0u64; PAGE_BRICKS]; page_layer];
                for z in pz * PAGE * BRICK..((pz + 1) * PAGE * BRICK).min(nz) {
                    let bz = z / BRICK % PAGE;
                    for y in 0..ny {
                        let (py, by) = (y / BRICK / PAGE, y / BRICK % PAGE);
                        for run in grid.row(0, y as u32, z as u32) {
                            for x in run.start as usize..run.end() as usize {
                                let (px, bx) = (x / BRICK / PAGE, x / BRICK % PAGE);
                                masks[py * pages[0] + px][(bz * PAGE + by) * PAGE + bx] |=
                                    1 << within_brick(x, y, z);
                            }
                        }
                    }
                }
                masks
                    .into_iter()
                    .enumerate()
                    .filter(|(_, m)| m.iter().any(|&b| b != 0))
                    .map(|(i, m)| (pz * page_layer + i, m))
                    .collect()
            })
            .collect();
        if parts.skipped() {
            return None;
        }
        let mut page_table = vec![EMPTY_PAGE; page_layer * pages[2]];
        // Voxel ids are `u32`, so the count of significant voxels is too.
        let mut count = 0u32;
        let mut table = Vec::with_capacity(per_layer.iter().map(Vec::len).sum::<usize>());
        for (slot, (page, masks)) in per_layer.iter().flatten().enumerate() {
            page_table[*page] = slot as u32;
            for &present in masks {
                table.push(Brick {
                    present,
                    first: count,
                });
                count += present.count_ones();
            }
        }
        // The texels, page by page in the same layers: each layer's a contiguous stretch.
        // Allocated zeroed: pages of memory no texel is written to are never touched.
        let mut laid = Self {
            dims,
            bricks,
            pages,
            page_table,
            table,
            texels: bytemuck::zeroed_vec(count as usize),
            normals: None,
        };
        let Some(texel) = texel else {
            return parts.whole(laid);
        };
        let mut stretches = Vec::with_capacity(pages[2]);
        let (mut rest, mut bricks_left) = (laid.texels.as_mut_slice(), laid.table.as_slice());
        for of_layer in &per_layer {
            let (own, tail) = bricks_left.split_at(of_layer.len() * PAGE_BRICKS);
            let n: u32 = own.iter().map(|b| b.present.count_ones()).sum();
            let (stretch, rest_of) = std::mem::take(&mut rest).split_at_mut(n as usize);
            stretches.push((stretch, own, of_layer));
            rest = rest_of;
            bricks_left = tail;
        }
        stretches
            .into_par_iter()
            .for_each(|(stretch, bricks_of_layer, of_layer)| {
                let mut slots = stretch.iter_mut();
                for (page_bricks, (page, _)) in bricks_of_layer.chunks(PAGE_BRICKS).zip(of_layer) {
                    if parts.skip() {
                        return;
                    }
                    let (px, py, pz) = (
                        page % pages[0],
                        page / pages[0] % pages[1],
                        page / page_layer,
                    );
                    for (j, brick) in page_bricks.iter().enumerate() {
                        let bx = px * PAGE + j % PAGE;
                        let by = py * PAGE + j / PAGE % PAGE;
                        let bz = pz * PAGE + j / (PAGE * PAGE);
                        let mut bits = brick.present;
                        while bits != 0 {
                            let bit = bits.trailing_zeros() as usize;
                            bits &= bits - 1;
                            let x = bx * BRICK + bit % BRICK;
                            let y = by * BRICK + (bit / BRICK) % BRICK;
                            let z = bz * BRICK + bit / (BRICK * BRICK);
                            let k = [x, y, z].map(|c| c as u32);
                            let id = (x + nx * (y + ny * z)) as u32;
                            if let (Some(slot), Some(rank)) = (slots.next(), grid.rank(id)) {
                                *slot.get_mut() = u64::from_le_bytes(texel(k, rank as usize));
                            }
                        }
                    }
                }
            });
        parts.whole(laid)
    }

    /// The texels of the level above these texels' grid: `above` is the classification
    /// [`Classified::halved_along`] made from theirs, halving the axes whose `step` is 2, with
    /// the same `front`. Each splat takes its colour and density from `above`, and as its
    /// normal the mean of its block's normals with the weights its colour had (the densities,
    /// each normal turned to one side first, as the two-sided headlight sees them; along a
    /// `front`, the opacities as a ray composites them), taken into the coarser
    /// grid's index space (a gradient's component along an axis halved doubles) and made unit
    /// again: the block's surface, with no volume resampled for it. No normal where the
    /// block's cancel.
    ///
    /// Laid out at once and written as each brick is first read, like the texels of
    /// [`SplatTexels::new`]: a brick's texels read the texels below of its blocks, which are
    /// then made in turn where they are not made yet. A level made for a turned view then
    /// makes only the bricks it draws and does not hide, and none of the grid below that
    /// those do not cover. Given up (`None`, nothing kept) once `cancel` is raised, looked at
    /// while the layout is surveyed.
    pub fn halved(
        self: &Arc<Self>,
        above: &Arc<Classified>,
        step: [u32; 3],
        front: Option<Front>,
        cancel: Option<&AtomicBool>,
    ) -> Option<Self> {
        // As in the colours: a front along the one axis halved, else none.
        let front = front.filter(|f| f.axis < 3 && (0..3).all(|a| (step[a] == 2) == (a == f.axis)));
        // The opacity along the front by the density's bits, tabulated once.
        let alphas: Vec<f32> = match front {
            Some(f) => (0..=u16::MAX).map(|b| f.alpha(texel_density(b))).collect(),
            None => Vec::new(),
        };
        let mut texels = Self::build_unless_cancelled(&above.grid, None::<Texel>, cancel)?;
        texels.normals = Some(LazyNormals {
            classified: Arc::clone(above),
            source: NormalSource::Halved(HalvedFrom {
                fine: Arc::clone(self),
                step,
                front,
                alphas,
            }),
            state: (0..texels.brick_rows() * texels.units_x())
                .map(|_| AtomicU8::new(NOT_MADE))
                .collect(),
        });
        Some(texels)
    }

    /// The texel of voxel `(x, y, z)`: straight RGB8, the gradient as snorm8, the density's
    /// f16 bits (little-endian); `None` off the grid or where the voxel is not significant.
    /// Makes its brick's normals where they are not made yet.
    #[inline]
    pub fn get(&self, x: u32, y: u32, z: u32) -> Option<[u8; 8]> {
        let (brick, i) = self.index(x, y, z)?;
        let texel = self.texels.get(i)?;
        // A texel written is never zero (a significant voxel's density is not), and is
        // written whole by one store: read first, its unit's state is looked at only while
        // it is zero.
        let read = texel.load(Ordering::Relaxed);
        if read != 0 {
            return Some(read.to_le_bytes());
        }
        self.ensure_normals(brick);
        Some(texel.load(Ordering::Relaxed).to_le_bytes())
    }

    /// Where the texel of voxel `(x, y, z)` lies: its brick, and its index in `texels` (the
    /// brick's first texel plus the brick's significant voxels before it); `None` off the
    /// grid or where the voxel is not significant.
    #[inline(always)]
    fn index(&self, x: u32, y: u32, z: u32) -> Option<(usize, usize)> {
        let [nx, ny, nz] = self.dims;
        if x >= nx || y >= ny || z >= nz {
            return None;
        }
        let [x, y, z] = [x, y, z].map(|v| v as usize);
        let (bx, by, bz) = (x / BRICK, y / BRICK, z / BRICK);
        let b = (bz * self.bricks[1] + by) * self.bricks[0] + bx;
        let brick = self.brick(bx, by, bz)?;
        let bit = within_brick(x, y, z);
        if brick.present >> bit & 1 == 0 {
            return None;
        }
        let before = (brick.present & ((1u64 << bit) - 1)).count_ones();
        Some((b, (brick.first + before) as usize))
    }

    /// Brick `(bx, by, bz)`, where its page is stored (its mask may still be empty).
    #[inline(always)]
    fn brick(&self, bx: usize, by: usize, bz: usize) -> Option<&Brick> {
        let page = ((bz / PAGE) * self.pages[1] + by / PAGE) * self.pages[0] + bx / PAGE;
        let slot = *self.page_table.get(page)?;
        if slot == EMPTY_PAGE {
            return None;
        }
        let within = ((bz % PAGE) * PAGE + by % PAGE) * PAGE + bx % PAGE;
        self.table.get(slot as usize * PAGE_BRICKS + within)
    }

    /// Makes the normals of brick `b`'s unit where they are made lazily and not made yet.
    #[inline(always)]
    fn ensure_normals(&self, b: usize) {
        if let Some(lazy) = &self.normals {
            let nx = self.bricks[0];
            self.ensure_unit(b / nx * self.units_x() + b % nx / NORMAL_UNIT, lazy);
        }
    }

    /// Makes the normals of unit `u` where they are not made yet.
    #[inline(always)]
    fn ensure_unit(&self, u: usize, lazy: &LazyNormals) {
        if lazy
            .state
            .get(u)
            .is_some_and(|s| s.load(Ordering::Acquire) != MADE)
        {
            self.make_normals(u, lazy);
        }
    }

    /// Makes the texels of unit `u` (bricks `NORMAL_UNIT u..` along x of its row of
    /// bricks), or waits while another thread makes them.
    #[cold]
    fn make_normals(&self, u: usize, lazy: &LazyNormals) {
        match &lazy.source {
            NormalSource::Gradients(gradients) => self.fill_unit(u, lazy, |k| gradients.snorm8(k)),
            NormalSource::Halved(below) => self.fill_unit(u, lazy, |k| below.normal(k)),
        }
    }

    /// Takes over the normals that `previous` made, where this grid was joined from
    /// `previous`'s: the same size, its normals from the same volume at the same factors (a
    /// refinement that a turned view added bricks to). Each unit of bricks whose normals
    /// `previous` made is made here at once, a voxel that `previous` holds taking its normal
    /// and any other (of the bricks joined) having its own made, so that a joined refinement
    /// does not make its gradients again (on the LIDC2 CT refined 2 x 2 x 3, a hundred
    /// milliseconds of each turned frame). Nothing where the two grids differ in size, in
    /// volume or in factors, or where either makes no normals lazily from a volume's gradients.
    pub fn adopt_normals(&self, previous: &SplatTexels) {
        let (Some(lazy), Some(old)) = (&self.normals, &previous.normals) else {
            return;
        };
        let (NormalSource::Gradients(gradients), NormalSource::Gradients(old_gradients)) =
            (&lazy.source, &old.source)
        else {
            return;
        };
        if previous.dims != self.dims || !gradients.same_field(old_gradients) {
            return;
        }
        let normal = |k: [u32; 3]| match previous.index(k[0], k[1], k[2]) {
            Some((_, i)) => (previous.texels.get(i))
                .map(|t| t.load(Ordering::Relaxed).to_le_bytes())
                .and_then(|t| (t[3..6] != [0; 3]).then(|| [t[3], t[4], t[5]])),
            None => gradients.snorm8(k),
        };
        (0..lazy.state.len()).into_par_iter().for_each(|u| {
            if (old.state.get(u)).is_some_and(|s| s.load(Ordering::Acquire) == MADE)
                && previous.unit_holds_any(u)
            {
                self.fill_unit(u, lazy, normal);
            }
        });
    }

    /// Whether a brick of unit `u` holds a significant voxel.
    fn unit_holds_any(&self, u: usize) -> bool {
        let (xs, by, bz) = self.unit_bricks(u);
        xs.into_iter()
            .any(|bx| self.brick(bx, by, bz).is_some_and(|b| b.present != 0))
    }

    /// The bricks of unit `u`: their range along x, and their row's y and z.
    fn unit_bricks(&self, u: usize) -> (std::ops::Range<usize>, usize, usize) {
        let (row, first) = (u / self.units_x(), u % self.units_x() * NORMAL_UNIT);
        let (by, bz) = (row % self.bricks[1], row / self.bricks[1]);
        (first..(first + NORMAL_UNIT).min(self.bricks[0]), by, bz)
    }

    /// Writes the texels of unit `u`, each voxel's colour and density from the classification
    /// and its normal from `normal` (none: all zero, undefined), or waits while another
    /// thread writes them.
    fn fill_unit(
        &self,
        u: usize,
        lazy: &LazyNormals,
        normal: impl Fn([u32; 3]) -> Option<[u8; 3]>,
    ) {
        let Some(state) = lazy.state.get(u) else {
            return;
        };
        if state
            .compare_exchange(NOT_MADE, MAKING, Ordering::Acquire, Ordering::Acquire)
            .is_err()
        {
            // Another thread makes them: a few hundred gradients.
            while state.load(Ordering::Acquire) != MADE {
                std::thread::yield_now();
            }
            return;
        }
        let (xs, by, bz) = self.unit_bricks(u);
        let [nx, ny, _] = self.dims;
        let grid = &lazy.classified.grid;
        for bx in xs {
            let Some(brick) = self.brick(bx, by, bz) else {
                continue;
            };
            let mut bits = brick.present;
            let mut i = brick.first as usize;
            // The rank of the voxel before, where it lies in the same row of the brick: the
            // brick's voxels of a row are the grid's there, so the rank goes up by one.
            let mut before: Option<(usize, u32)> = None;
            while bits != 0 {
                let bit = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let k = [
                    bx * BRICK + bit % BRICK,
                    by * BRICK + (bit / BRICK) % BRICK,
                    bz * BRICK + bit / (BRICK * BRICK),
                ]
                .map(|c| c as u32);
                let rank = match before {
                    Some((row, r)) if row == bit / BRICK => Some(r + 1),
                    _ => grid.rank(k[0] + nx * (k[1] + ny * k[2])),
                };
                before = rank.map(|r| (bit / BRICK, r));
                let color = rank.and_then(|r| lazy.classified.colors.get(r as usize));
                if let (Some(&c), Some(texel)) = (color, self.texels.get(i)) {
                    texel.store(u64::from_le_bytes(packed(c, normal(k))), Ordering::Relaxed);
                }
                i += 1;
            }
        }
        state.store(MADE, Ordering::Release);
    }

    /// Asks the processor to bring the texel of voxel `(x, y, z)` into its caches, without
    /// waiting for it: the compositor asks for a group's texels while it projects the group
    /// before, so that the loads, which miss the caches where the order runs across the bricks'
    /// layout, overlap with that work. Nothing where the voxel has no texel.
    #[inline]
    pub(super) fn prefetch(&self, x: u32, y: u32, z: u32) {
        #[cfg(target_arch = "x86_64")]
        if let Some(texel) = self.index(x, y, z).and_then(|(_, i)| self.texels.get(i)) {
            use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
            #[allow(unsafe_code)]
            // SAFETY: SSE is part of every x86-64 processor; a prefetch is a hint that reads
            // nothing and faults on no address.
            unsafe {
                _mm_prefetch::<_MM_HINT_T0>(texel.as_ptr().cast_const().cast())
            };
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = (x, y, z);
    }
}

/// The 8-byte texel of significant voxel `k` (rank `rank`) of a classified volume, its grid
/// `factors` times finer than `volume`'s: straight RGB8, the gradient of `volume` there as
/// snorm8 (zero where undefined), the density's f16 bits little-endian. The GPU's splat pass
/// reads the same bytes as two `u32`.
pub fn texel(
    volume: &CpuVolume,
    factors: [u32; 3],
    classified: &Classified,
    k: [u32; 3],
    rank: usize,
) -> [u8; 8] {
    let c = classified.colors.get(rank).copied().unwrap_or_default();
    packed(c, refined_gradient_snorm8(volume, factors, k))
}

/// A splat's colour and gradient (zero where undefined) as [`texel`]'s 8 bytes.
fn packed(c: crate::classify::SplatColor, n: Option<[u8; 3]>) -> [u8; 8] {
    let n = n.unwrap_or([0; 3]);
    let d = c.density.to_bits().to_le_bytes();
    [c.rgb[0], c.rgb[1], c.rgb[2], n[0], n[1], n[2], d[0], d[1]]
}

/// One normal for a block of voxels a ray along `axis` composites with the weights given,
/// shading as they do together. Shading is two-sided (`|n . view|`, the splats' headlight), so
/// the weighted mean of the normals would not do: the two faces of a structure one voxel thin
/// along the view have opposite gradients, whose mean cancels to a normal across the view and
/// shades the structure dark, and turning them to one side first shades it too bright where
/// the normals scatter. The normal returned has the weighted mean of their shading along the
/// axis, `|n . axis|`, as its component along it, and across it the direction of their
/// weighted sum turned to one side of the axis. (The view runs along the axis within the
/// share [`detail_for`](crate::render::detail_for) allows; the index space is taken as
/// isotropic, as fine grids nearly are.)
fn shading_normal(normals: &[(f32, glam::Vec3)], axis: usize) -> glam::Vec3 {
    let along = glam::Vec3::AXES[axis];
    let total: f32 = normals.iter().map(|(w, _)| w).sum();
    if normals.is_empty() || total.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return glam::Vec3::ZERO;
    }
    let lit = normals
        .iter()
        // A voxel with no gradient is drawn unshaded, as lit as a normal along the view.
        .map(|&(w, n)| w * n.try_normalize().map_or(1.0, |n| n.dot(along).abs()))
        .sum::<f32>()
        / total;
    let lit = lit.clamp(0.0, 1.0);
    let across: glam::Vec3 = normals
        .iter()
        .map(|&(w, n)| {
            let n = if n.dot(along) < 0.0 { -n } else { n };
            w * (n - n.dot(along) * along)
        })
        .sum();
    let across = across
        .try_normalize()
        .unwrap_or(glam::Vec3::AXES[(axis + 1) % 3]);
    lit * along + (1.0 - lit * lit).max(0.0).sqrt() * across
}

/// The weighted sum of `normals` each turned to the side of the heaviest (largest weight
/// times length): shading is two-sided, so a normal and its opposite shade alike, and the two
/// faces of a structure thinner than a block (a rib, a vessel wall) have opposite gradients
/// whose plain sum cancels to whatever is left across the structure and shades it dark.
fn one_sided_sum(normals: &[(f32, glam::Vec3)]) -> glam::Vec3 {
    let Some(&(_, heaviest)) = normals
        .iter()
        .max_by(|a, b| (a.0 * a.1.length()).total_cmp(&(b.0 * b.1.length())))
    else {
        return glam::Vec3::ZERO;
    };
    normals
        .iter()
        .map(|&(w, n)| if n.dot(heaviest) < 0.0 { -w * n } else { w * n })
        .sum()
}

/// The bit of voxel `(x, y, z)` in its brick's mask.
#[inline(always)]
pub(super) fn within_brick(x: usize, y: usize, z: usize) -> usize {
    ((z % BRICK) * BRICK + y % BRICK) * BRICK + x % BRICK
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::classify::SplatColor;

    #[test]
    fn only_bricks_with_a_significant_voxel_are_held_and_every_voxel_finds_its_texel() {
        // Clusters of voxels with empty bricks and empty layers of bricks between them, a
        // grid whose sides are no multiple of a brick: each voxel's texel (its coordinates
        // and rank written into it) where it is significant, none elsewhere, as a plain set of
        // the ids says.
        let dims = [90u32, 45, 62];
        let [nx, ny, nz] = dims;
        let keep = |x: u32, y: u32, z: u32| {
            (x / 20 + y / 20 + z / 20).is_multiple_of(3) && !(x * 5 + y * 3 + z).is_multiple_of(4)
        };
        let mut ids = Vec::new();
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    if keep(x, y, z) {
                        ids.push(x + nx * (y + ny * z));
                    }
                }
            }
        }
        let grid = SparseGrid::from_sorted_ids(dims, &ids).unwrap();
        let encode = |k: [u32; 3], rank: usize| {
            let r = (rank as u16).to_le_bytes();
            [k[0] as u8, k[1] as u8, k[2] as u8, 0, 0, 0, r[0], r[1]]
        };
        let texels = SplatTexels::build(&grid, encode);
        let mut bricks: Vec<[u32; 3]> = ids
            .iter()
            .map(|&id| [id % nx / 4, id / nx % ny / 4, id / nx / ny / 4])
            .collect();
        bricks.sort_unstable();
        bricks.dedup();
        // Bricks held by pages of 4^3 bricks: the pages that hold one of these bricks, no more.
        let mut pages: Vec<[u32; 3]> = bricks.iter().map(|b| b.map(|c| c / 4)).collect();
        pages.dedup();
        pages.sort_unstable();
        pages.dedup();
        assert_eq!(texels.table.len(), pages.len() * 64);
        let held = texels.table.iter().filter(|b| b.present != 0).count();
        assert_eq!(held, bricks.len());
        let all = (nx.div_ceil(16) * ny.div_ceil(16) * nz.div_ceil(16)) as usize;
        assert!(pages.len() < all, "{} of {all}", pages.len());
        for z in 0..nz + 2 {
            for y in 0..ny + 2 {
                for x in 0..nx + 2 {
                    let id = x + nx * (y + ny * z);
                    let expected = (x < nx && y < ny && z < nz)
                        .then(|| ids.binary_search(&id).ok())
                        .flatten()
                        .map(|rank| encode([x, y, z], rank));
                    assert_eq!(texels.get(x, y, z), expected, "{x} {y} {z}");
                }
            }
        }
    }

    /// A field with structure along every axis, `dims` voxels 1 apart.
    fn structured_field(dims: [u32; 3]) -> Arc<CpuVolume> {
        let values: Vec<f32> = (0..dims.iter().product::<u32>())
            .map(|i| {
                let [x, y, z] = [i % dims[0], i / dims[0] % dims[1], i / dims[0] / dims[1]];
                ((x * 37 + y * y * 11 + z * z * z * 3) % 500) as f32
            })
            .collect();
        Arc::new(CpuVolume {
            dims,
            spacing: [1.0; 3],
            origin: [0.0; 3],
            direction: glam::DMat3::IDENTITY,
            values: values.into(),
        })
    }

    /// A classification of a grid of `fine` voxels with two thirds of them significant, each
    /// with a colour and density of its own; and their ids.
    fn two_thirds_classified(fine: [u32; 3]) -> (Arc<Classified>, Vec<u32>) {
        let ids: Vec<u32> = (0..fine.iter().product::<u32>())
            .filter(|id| id % 3 != 0)
            .collect();
        (classified_of(fine, &ids), ids)
    }

    /// A classification of the voxels `ids` (sorted) of a grid of `fine` voxels, each with a
    /// colour and density of its own (the same whatever other voxels are classified).
    fn classified_of(fine: [u32; 3], ids: &[u32]) -> Arc<Classified> {
        Arc::new(Classified {
            grid: SparseGrid::from_sorted_ids(fine, ids).unwrap(),
            colors: ids
                .iter()
                .map(|&id| SplatColor {
                    rgb: [id as u8, (id / 7) as u8, 90],
                    density: half::f16::from_f32(0.1 + (id % 5) as f32),
                })
                .collect(),
        })
    }

    #[test]
    fn a_joined_grid_takes_over_the_normals_its_part_made() {
        // A field refined 2 x 2 x 1, two thirds of its voxels significant. A part of them
        // (x < 7, cutting a brick) has every normal made; the whole, joined from it, takes
        // them over. A normal of the part marked by hand comes through (taken over, not made
        // again); the units the part never made are left to be made when read; every other
        // texel is the one made voxel by voxel from the volume, the voxels joined included.
        // Texels of another volume, or of the same volume at other factors, give nothing.
        let dims = [13u32, 11, 9];
        let volume = structured_field(dims);
        let factors = [2, 2, 1];
        let fine: [u32; 3] = std::array::from_fn(|a| dims[a] * factors[a]);
        let (whole, ids) = two_thirds_classified(fine);
        let part_ids: Vec<u32> = (ids.iter().copied())
            .filter(|id| id % fine[0] < 7)
            .collect();
        let part = classified_of(fine, &part_ids);
        let previous = SplatTexels::new(&part, &volume, factors);
        previous.complete();
        let coords = |id: u32| [id % fine[0], id / fine[0] % fine[1], id / fine[0] / fine[1]];
        let marked = (part_ids.iter().copied().map(coords))
            .find(|k| previous.get(k[0], k[1], k[2]).unwrap()[3..6] != [0; 3])
            .unwrap();
        let (_, i) = previous.index(marked[0], marked[1], marked[2]).unwrap();
        let mut t = previous.texels[i].load(Ordering::Relaxed).to_le_bytes();
        t[3..6].copy_from_slice(&[1, 2, 3]);
        previous.texels[i].store(u64::from_le_bytes(t), Ordering::Relaxed);

        let made = |t: &SplatTexels| -> Vec<u8> {
            let lazy = t.normals.as_ref().unwrap();
            lazy.state
                .iter()
                .map(|s| s.load(Ordering::Relaxed))
                .collect()
        };
        let joined = SplatTexels::new(&whole, &volume, factors);
        joined.adopt_normals(&previous);
        let units_x = joined.units_x();
        for (u, state) in made(&joined).into_iter().enumerate() {
            // The part lies within the first unit along x (bricks 0-3, x < 16).
            let want = if u % units_x == 0 { MADE } else { NOT_MADE };
            assert_eq!(state, want, "unit {u}");
        }
        let read = |t: &SplatTexels, k: [u32; 3]| t.get(k[0], k[1], k[2]).unwrap();
        assert_eq!(read(&joined, marked)[3..6], [1, 2, 3]);
        for &id in &ids {
            let k = coords(id);
            if k != marked {
                let rank = whole.grid.rank(id).unwrap() as usize;
                assert_eq!(
                    read(&joined, k),
                    texel(&volume, factors, &whole, k, rank),
                    "{k:?}"
                );
            }
        }

        let other_volume = Arc::new((*volume).clone());
        for (v, f) in [(&other_volume, factors), (&volume, [2, 1, 2])] {
            let fine: [u32; 3] = std::array::from_fn(|a| dims[a] * f[a]);
            let (whole, _) = two_thirds_classified(fine);
            let (part, _) = two_thirds_classified(fine);
            let previous = SplatTexels::new(&part, v, f);
            previous.complete();
            let joined = SplatTexels::new(&whole, &volume, factors);
            joined.adopt_normals(&previous);
            assert!(made(&joined).iter().all(|&s| s == NOT_MADE), "{f:?}");
        }
    }

    #[test]
    fn normals_made_as_their_bricks_are_read_are_the_volumes_gradients() {
        // A field with structure along every axis, its grid at its own spacing and refined
        // 2 x 2 x 1, two thirds of the voxels significant. Every texel read, by threads in
        // parallel reading each brick many times over, equals the texel made voxel by voxel
        // from the volume; no texel, colour or normal, is written before its brick is read.
        let dims = [13u32, 11, 9];
        let volume = structured_field(dims);
        for factors in [[1, 1, 1], [2, 2, 1]] {
            let fine: [u32; 3] = std::array::from_fn(|a| dims[a] * factors[a]);
            let (classified, ids) = two_thirds_classified(fine);
            let texels = SplatTexels::new(&classified, &volume, factors);
            assert!(
                texels.texels.iter().all(|t| t.load(Ordering::Relaxed) == 0),
                "nothing written before a read"
            );
            let want = |id: u32| {
                let k = classified.grid.coords(id);
                let rank = classified.grid.rank(id).unwrap() as usize;
                texel(&volume, factors, &classified, k, rank)
            };
            let with_normals = ids.iter().filter(|&&id| want(id)[3..6] != [0; 3]).count();
            assert!(with_normals * 2 > ids.len(), "{factors:?}: {with_normals}");
            // Eight reads of each voxel, scattered, in parallel.
            let reads: Vec<u32> = (0..ids.len() * 8)
                .map(|i| ids[(i * 7919) % ids.len()])
                .collect();
            reads.par_iter().for_each(|&id| {
                let k = classified.grid.coords(id);
                assert_eq!(
                    texels.get(k[0], k[1], k[2]),
                    Some(want(id)),
                    "{factors:?} {k:?}"
                );
            });
            texels.complete();
            for &id in &ids {
                let k = classified.grid.coords(id);
                assert_eq!(texels.get(k[0], k[1], k[2]), Some(want(id)));
            }
            // Voxels not significant, or off the grid, have none.
            assert_eq!(texels.get(0, 0, 0), None);
            assert_eq!(texels.get(fine[0], 0, 0), None);
        }
    }

    #[test]
    fn a_levels_texels_are_made_as_read_from_the_bricks_below_them_alone() {
        // A field with structure along every axis, two thirds of its voxels significant; a
        // level halved along every axis from its lazily made texels, and one above that
        // halved along z with a front. Nothing of any of the three is written before a read;
        // a read of the top level's last layer of bricks makes no texel of the grids below
        // outside the blocks under that layer; texels read by threads in parallel, in a
        // scattered order, from nothing made equal those read after every grid below was
        // completed first; and the first level's normals are the one-sided, density-weighted
        // sums of their blocks' normals, computed plainly here.
        let dims = [21u32, 19, 40];
        let volume = structured_field(dims);
        let (classified, _) = two_thirds_classified(dims);
        let front = Front {
            axis: 2,
            larger_nearer: false,
            step_mm: 2.0,
        };
        let chain = || {
            let own = Arc::new(SplatTexels::new(&classified, &volume, [1; 3]));
            let one = Arc::new(classified.halved_along([true; 3], None).unwrap());
            let two = Arc::new(one.halved_along([false, false, true], Some(front)).unwrap());
            let first = Arc::new(own.halved(&one, [2; 3], None, None).unwrap());
            let second = first.halved(&two, [1, 1, 2], Some(front), None).unwrap();
            (own, first, second, one, two)
        };
        let written = |t: &SplatTexels, k: [u32; 3]| {
            t.index(k[0], k[1], k[2])
                .is_some_and(|(_, i)| t.texels[i].load(Ordering::Relaxed) != 0)
        };
        let (own, first, second, one, two) = chain();
        for t in [&*own, &*first, &second] {
            assert!(t.texels.iter().all(|t| t.load(Ordering::Relaxed) == 0));
        }
        // The top level is 11 x 10 x 10 voxels: its last layer of bricks holds z 8 and 9,
        // over z 16-19 of the first level and z 32-39 of the own grid.
        let top: Vec<[u32; 3]> = two
            .grid
            .ids()
            .map(|id| two.grid.coords(id))
            .filter(|k| k[2] >= 8)
            .collect();
        assert!(!top.is_empty());
        for k in &top {
            assert!(second.get(k[0], k[1], k[2]).is_some());
        }
        let own_written: Vec<[u32; 3]> = (classified.grid.ids())
            .map(|id| classified.grid.coords(id))
            .filter(|&k| written(&own, k))
            .collect();
        assert!(
            !own_written.is_empty(),
            "the blocks under the layer were made"
        );
        assert!(
            own_written.iter().all(|k| k[2] >= 32),
            "{:?}",
            own_written[0]
        );
        assert!(
            (one.grid.ids())
                .map(|id| one.grid.coords(id))
                .all(|k| !written(&first, k) || k[2] >= 16)
        );
        // From nothing, in parallel and scattered; and after completing every grid below.
        let (own_a, first_a, second_a, _, _) = chain();
        let ids: Vec<u32> = two.grid.ids().collect();
        let scattered: Vec<u32> = (0..ids.len() * 4)
            .map(|i| ids[(i * 7919) % ids.len()])
            .collect();
        let read = |t: &SplatTexels, id: u32| {
            let k = two.grid.coords(id);
            t.get(k[0], k[1], k[2])
        };
        let in_parallel: Vec<_> = scattered
            .par_iter()
            .map(|&id| read(&second_a, id))
            .collect();
        own.complete();
        first.complete();
        for (&id, got) in scattered.iter().zip(&in_parallel) {
            assert_eq!(*got, read(&second, id), "{:?}", two.grid.coords(id));
        }
        drop((own_a, first_a));
        // The first level's normals, plainly.
        let mut with_normals = 0;
        for id in one.grid.ids() {
            let k = one.grid.coords(id);
            let t = first.get(k[0], k[1], k[2]).unwrap();
            let mut block = Vec::new();
            for d in 0..8u32 {
                let c = [
                    k[0] * 2 + (d & 1),
                    k[1] * 2 + (d >> 1 & 1),
                    k[2] * 2 + (d >> 2),
                ];
                if let Some(f) = own.get(c[0], c[1], c[2]) {
                    let n = Vec3::new(f[3] as i8 as f32, f[4] as i8 as f32, f[5] as i8 as f32);
                    let density = half::f16::from_bits(u16::from_le_bytes([f[6], f[7]]));
                    block.push((density.to_f32(), n));
                }
            }
            // The heaviest normal; of two as heavy, the later one.
            let heaviest = block
                .iter()
                .fold((0.0f32, Vec3::ZERO), |best, &(w, n)| {
                    if w * n.length() >= best.0 {
                        (w * n.length(), n)
                    } else {
                        best
                    }
                })
                .1;
            let sum: Vec3 = block
                .iter()
                .map(|&(w, n)| w * n * n.dot(heaviest).signum())
                .sum::<Vec3>()
                * 2.0;
            let got = Vec3::new(t[3] as i8 as f32, t[4] as i8 as f32, t[5] as i8 as f32);
            if sum.length() < 1e-3 {
                continue;
            }
            with_normals += 1;
            let want = sum.normalize() * 127.0;
            assert!((got - want).length() < 2.0, "{k:?}: {got} against {want}");
        }
        assert!(with_normals * 2 > one.grid.len(), "{with_normals}");
    }

    /// The shading a normal gets from a headlight along `axis`, as the compositors shade.
    fn lit(n: Vec3, axis: usize) -> f32 {
        n.try_normalize().map_or(1.0, |n| n[axis].abs())
    }

    #[test]
    fn a_blocks_opposite_normals_across_the_view_keep_their_direction() {
        // A wall one voxel thin across z, its two faces' gradients opposite along z and
        // tilted alike across it: their plain sum is mostly the tilt, a normal along the wall
        // (z 0.55 of it); turned to one side, the wall's own normal.
        let (top, bottom) = (Vec3::new(0.3, 0.1, 0.95), Vec3::new(0.3, 0.1, -0.95));
        let sum = one_sided_sum(&[(0.6, top), (0.4, bottom)]);
        assert!(sum.normalize().z > 0.99, "{sum}");
        assert!((0.6 * top + 0.4 * bottom).normalize().z < 0.6);
        // Normals on one side add as they are.
        let tilted = Vec3::new(0.6, 0.0, 0.8);
        let sum = one_sided_sum(&[(1.0, Vec3::Z), (1.0, tilted)]);
        assert!((sum - (Vec3::Z + tilted)).length() < 1e-6, "{sum}");
        // The heaviest sets the side: the lighter turns to it.
        let sum = one_sided_sum(&[(0.2, Vec3::Z), (0.8, -tilted)]);
        assert!(
            (sum - (-0.2 * Vec3::Z - 0.8 * tilted)).length() < 1e-6,
            "{sum}"
        );
        // No normals: none.
        assert_eq!(one_sided_sum(&[]), Vec3::ZERO);
    }

    #[test]
    fn a_blocks_normal_shades_as_its_voxels_do_together() {
        // The two faces of a structure one voxel thin along the view: opposite normals, both
        // fully lit; their mean would be no normal at all.
        let n = shading_normal(&[(0.7, Vec3::Z), (0.3, -Vec3::Z)], 2);
        assert!((lit(n, 2) - 1.0).abs() < 1e-6, "{n}");
        // Normals tilted 60 and 0 degrees off the view: lit as their weighted mean, tilted
        // towards the first.
        let tilted = Vec3::new(3f32.sqrt() / 2.0, 0.0, 0.5);
        let n = shading_normal(&[(0.25, tilted), (0.75, -Vec3::Z)], 2);
        let want = 0.25 * 0.5 + 0.75;
        assert!((lit(n, 2) - want).abs() < 1e-6, "{n}");
        assert!(n.x > 0.0 && n.y.abs() < 1e-6, "{n}");
        // A voxel with no gradient is drawn unshaded: it counts as fully lit.
        let n = shading_normal(&[(0.5, Vec3::ZERO), (0.5, Vec3::X)], 2);
        assert!((lit(n, 2) - 0.5).abs() < 1e-6, "{n}");
        // No weight: no normal.
        assert_eq!(shading_normal(&[], 2), Vec3::ZERO);
    }

    #[test]
    fn texels_halved_along_the_view_shade_as_the_pairs_they_replace() {
        // A 2 x 4 x 2 grid, every voxel present, halved along y; each voxel's normal and
        // density varied. Each coarse texel's shading along y against the pair's, weighted
        // nearer over farther, computed plainly; its colour and density from the coarse
        // classification.
        let dims = [2u32, 4, 2];
        let normal = |k: [u32; 3]| {
            let a = 0.4 * (k[0] + 3 * k[1] + 5 * k[2]) as f32;
            let flip = if (k[1] + k[2]).is_multiple_of(2) {
                1.0
            } else {
                -1.0
            };
            Vec3::new(a.cos(), flip * (0.3 + 0.1 * k[1] as f32), a.sin()).normalize()
        };
        let density = |k: [u32; 3]| 0.2 + 0.5 * ((k[0] + k[1] * 2 + k[2]) % 4) as f32;
        let ids: Vec<u32> = (0..16).collect();
        let fine = Classified {
            grid: SparseGrid::from_sorted_ids(dims, &ids).unwrap(),
            colors: ids
                .iter()
                .map(|&id| {
                    let k = [id % 2, id / 2 % 4, id / 8];
                    SplatColor {
                        rgb: [id as u8 * 10, 50, 200],
                        density: half::f16::from_f32(density(k)),
                    }
                })
                .collect(),
        };
        let texels = Arc::new(SplatTexels::build(&fine.grid, |k, rank| {
            let n = normal(k)
                .to_array()
                .map(|v| (v * 127.0).round() as i8 as u8);
            let d = fine.colors[rank].density.to_bits().to_le_bytes();
            [0, 0, 0, n[0], n[1], n[2], d[0], d[1]]
        }));
        for larger_nearer in [true, false] {
            let front = Front {
                axis: 1,
                larger_nearer,
                step_mm: 0.7,
            };
            let coarse = Arc::new(
                fine.halved_along([false, true, false], Some(front))
                    .unwrap(),
            );
            let halved = texels
                .halved(&coarse, [1, 2, 1], Some(front), None)
                .expect("no cancel flag");
            for id in coarse.grid.ids() {
                let k = coarse.grid.coords(id);
                let t = halved.get(k[0], k[1], k[2]).unwrap();
                let rank = coarse.grid.rank(id).unwrap() as usize;
                assert_eq!(t[..3], coarse.colors[rank].rgb);
                assert_eq!(t[6..], coarse.colors[rank].density.to_bits().to_le_bytes());
                // Back into the fine grid's index space: the y component halves.
                let n = Vec3::new(
                    f32::from(t[3] as i8),
                    f32::from(t[4] as i8) / 2.0,
                    f32::from(t[5] as i8),
                );
                let (lo, hi) = ([k[0], 2 * k[1], k[2]], [k[0], 2 * k[1] + 1, k[2]]);
                let (near, far) = if larger_nearer { (hi, lo) } else { (lo, hi) };
                let alpha = |k| front.alpha(density(k));
                let (wn, wf) = (alpha(near), (1.0 - alpha(near)) * alpha(far));
                let want = (wn * lit(normal(near), 1) + wf * lit(normal(far), 1)) / (wn + wf);
                // Within the snorm8 quantisation.
                assert!(
                    (lit(n, 1) - want).abs() < 0.02,
                    "{k:?}: {} against {want}",
                    lit(n, 1)
                );
            }
        }
    }

    #[test]
    fn texels_made_under_a_raised_flag_are_given_up_and_a_lowered_one_changes_nothing() {
        // A field with structure along every axis, two thirds of its voxels significant. A
        // raised flag stops the normals' completion before any unit (every texel then still
        // read right, its normals made on the read) and gives the halved texels up; a lowered
        // flag gives what no flag gives.
        let dims = [21u32, 19, 17];
        let volume = structured_field(dims);
        let (classified, ids) = two_thirds_classified(dims);
        let (raised, lowered) = (AtomicBool::new(true), AtomicBool::new(false));
        let texels = Arc::new(SplatTexels::new(&classified, &volume, [1; 3]));
        assert!(!texels.complete_unless_cancelled(Some(&raised)));
        assert!(
            texels.texels.iter().all(|t| t.load(Ordering::Relaxed) == 0),
            "no texel made under a raised flag"
        );
        for &id in &ids {
            let k = classified.grid.coords(id);
            let rank = classified.grid.rank(id).unwrap() as usize;
            assert_eq!(
                texels.get(k[0], k[1], k[2]),
                Some(texel(&volume, [1; 3], &classified, k, rank)),
                "{k:?}"
            );
        }
        let fresh = SplatTexels::new(&classified, &volume, [1; 3]);
        assert!(fresh.complete_unless_cancelled(Some(&lowered)));
        assert!(
            fresh
                .texels
                .iter()
                .any(|t| t.load(Ordering::Relaxed).to_le_bytes()[3..6] != [0; 3]),
            "normals made under a lowered flag"
        );
        for (axes, front) in [([true; 3], None), ([false, false, true], None)] {
            let step = axes.map(|h| if h { 2 } else { 1 });
            let above = Arc::new(classified.halved_along(axes, front).unwrap());
            assert!(
                texels.halved(&above, step, front, Some(&raised)).is_none(),
                "{axes:?}"
            );
            let read = |t: &SplatTexels| -> Vec<Option<[u8; 8]>> {
                above
                    .grid
                    .ids()
                    .map(|id| {
                        let k = above.grid.coords(id);
                        t.get(k[0], k[1], k[2])
                    })
                    .collect()
            };
            let plain = texels.halved(&above, step, front, None).unwrap();
            let under_lowered = texels.halved(&above, step, front, Some(&lowered)).unwrap();
            assert!(read(&plain).iter().all(Option::is_some));
            assert_eq!(read(&plain), read(&under_lowered), "{axes:?}");
        }
    }
}
