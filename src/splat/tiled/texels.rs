//! The splats' data as the compositor reads it: 8 bytes a significant voxel, brick by brick.

use rayon::prelude::*;

use crate::classify::{Classified, refined_gradient_snorm8};
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
/// (the engine's 1.05M voxels with opacity, of 8.4M, take 8 MB of texels and 2 MB of bricks
/// instead of 67 MB). A brick's significant voxels are a bit mask, and a voxel's texel is
/// found by counting the bits before its own.
#[derive(Debug, Clone, Default)]
pub struct SplatTexels {
    pub(super) dims: [u32; 3],
    /// Bricks along x and y.
    pub(super) bricks: [usize; 2],
    /// Per brick, x fastest.
    pub(super) table: Vec<Brick>,
    pub(super) texels: Vec<[u8; 8]>,
}

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

impl SplatTexels {
    /// The texels of a classified volume: its colours and densities, and the gradients of the
    /// volume it was classified from, on a grid `factors` times finer than the volume's
    /// ([`crate::classify::classify_refined`]; `[1, 1, 1]` for its own). Built brick by brick
    /// from the significant voxels; no buffer the size of the whole grid.
    pub fn new(classified: &Classified, volume: &CpuVolume, factors: [u32; 3]) -> Self {
        Self::build(&classified.grid, |k, rank| {
            texel(volume, factors, classified, k, rank)
        })
    }

    /// The texels of `grid`'s voxels, each given by `texel(voxel, rank)`.
    pub fn build(grid: &SparseGrid, texel: impl Fn([u32; 3], usize) -> [u8; 8] + Sync) -> Self {
        let dims = grid.dims();
        let [nx, ny, nz] = dims.map(|n| n as usize);
        let bricks = [nx.div_ceil(BRICK), ny.div_ceil(BRICK)];
        let layer = bricks[0] * bricks[1];
        let layers = nz.div_ceil(BRICK);
        if layer == 0 || layers == 0 {
            return Self::default();
        }
        // Which voxels are significant, a layer of bricks (four z-slices) a task, from the
        // grid's x rows.
        let mut table = vec![Brick::default(); layer * layers];
        table
            .par_chunks_mut(layer)
            .enumerate()
            .for_each(|(bz, bricks_of_layer)| {
                for z in bz * BRICK..((bz + 1) * BRICK).min(nz) {
                    for y in 0..ny {
                        for run in grid.row(0, y as u32, z as u32) {
                            for x in run.start as usize..run.end() as usize {
                                let brick =
                                    &mut bricks_of_layer[(y / BRICK) * bricks[0] + x / BRICK];
                                brick.present |= 1 << within_brick(x, y, z);
                            }
                        }
                    }
                }
            });
        // Voxel ids are `u32`, so the count of significant voxels is too.
        let mut count = 0u32;
        for brick in &mut table {
            brick.first = count;
            count += brick.present.count_ones();
        }
        // The texels, brick by brick in the same layers: each layer's a contiguous stretch.
        let mut texels = vec![[0u8; 8]; count as usize];
        let mut stretches = Vec::with_capacity(layers);
        let mut rest = texels.as_mut_slice();
        for bz in 0..layers {
            let end = table.get((bz + 1) * layer).map_or(count, |b| b.first);
            let (stretch, tail) = rest.split_at_mut((end - table[bz * layer].first) as usize);
            stretches.push(stretch);
            rest = tail;
        }
        stretches
            .into_par_iter()
            .zip(table.par_chunks(layer))
            .enumerate()
            .for_each(|(bz, (stretch, bricks_of_layer))| {
                let mut slots = stretch.iter_mut();
                for (i, brick) in bricks_of_layer.iter().enumerate() {
                    let (bx, by) = (i % bricks[0], i / bricks[0]);
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
                            *slot = texel(k, rank as usize);
                        }
                    }
                }
            });
        Self {
            dims,
            bricks,
            table,
            texels,
        }
    }

    /// The texel of voxel `(x, y, z)`: straight RGB8, the gradient as snorm8, the density's
    /// f16 bits (little-endian); `None` off the grid or where the voxel is not significant.
    #[inline]
    pub(super) fn get(&self, x: u32, y: u32, z: u32) -> Option<&[u8; 8]> {
        let [nx, ny, nz] = self.dims;
        if x >= nx || y >= ny || z >= nz {
            return None;
        }
        let [x, y, z] = [x, y, z].map(|v| v as usize);
        let brick = ((z / BRICK) * self.bricks[1] + y / BRICK) * self.bricks[0] + x / BRICK;
        let brick = self.table.get(brick)?;
        let bit = within_brick(x, y, z);
        if brick.present >> bit & 1 == 0 {
            return None;
        }
        let before = (brick.present & ((1u64 << bit) - 1)).count_ones();
        self.texels.get((brick.first + before) as usize)
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
    let n = refined_gradient_snorm8(volume, factors, k).unwrap_or([0; 3]);
    let d = c.density.to_bits().to_le_bytes();
    [c.rgb[0], c.rgb[1], c.rgb[2], n[0], n[1], n[2], d[0], d[1]]
}

/// The bit of voxel `(x, y, z)` in its brick's mask.
#[inline(always)]
pub(super) fn within_brick(x: usize, y: usize, z: usize) -> usize {
    ((z % BRICK) * BRICK + y % BRICK) * BRICK + x % BRICK
}
