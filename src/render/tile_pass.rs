//! The tile compositor on the GPU: the CPU tile compositor's projection, binning to tiles (8x8
//! pixels here, 16x16 on the CPU), front-to-back "under" compositing and early termination
//! ([`crate::splat::tiled`]), as compute passes (`shaders/tiles.wgsl`), then the finished
//! layer laid "over" the meshes already in the colour target.
//!
//! The draw orders are walked nearest first in batches of up to [`MAX_BATCH`] splats (fewer
//! where the adapter binds less). A batch is one or more pieces, each a stretch of one grid's
//! order (a volume's one level, or a run of a volume drawn brick by brick) padded to a whole
//! workgroup of [`GROUP`] splats; each piece is one dispatch that projects it, and the batch
//! one that composites every tile. The layer of accumulated colour lives in a storage buffer
//! between them. A tile stops within a batch once its pixels are opaque, so small batches gain no
//! early termination, while each batch waits for its slowest tile: on an NVIDIA H200, batches
//! doubling from 16,384 to 524,288 splats took 6.9 ms for the engine's 1.1M splats, batches of
//! 2,097,152 3.8-4.0 ms (BENCHMARKS.md). Nothing is
//! read back: the meshes' colour and depth stay on the GPU, where the CPU compositor must read
//! both back first.
//!
//! Binning differs in form from the CPU's counting sort, not in result: a GPU workgroup (a
//! tile) gathers, in order, the blocks of [`BLOCK_SPANS`] spans whose rectangle meets it, then
//! a block at a time the spans of [`SPAN`] consecutive splats whose rectangle meets it, and
//! then, two such spans at a time, their splats that meet it, by prefix sums in workgroup
//! memory, so that every tile takes its splats in the draw order without a global sort. A
//! dispatch between projection and compositing bounds each block's spans.

use bytemuck::{Pod, Zeroable};

use super::splat_pass::GpuVolume;
use super::target::over_target;
use super::{GpuContext, RenderError};

/// Splats in a batch, unless the adapter binds fewer or [`TilePass::set_batch`] asks for
/// fewer: 192 MiB of projected splats.
const MAX_BATCH: usize = 1 << 22;
/// Splats a workgroup projects.
const GROUP: usize = 256;
/// Consecutive splats whose footprints one rectangle bounds, the rectangles the tiles test
/// (`SPAN` in `shaders/tiles.wgsl`).
const SPAN: usize = 32;
/// Consecutive spans whose rectangles one block's rectangle bounds (`BLOCK_SPANS` in
/// `shaders/tiles.wgsl`): a tile tests the blocks' rectangles first and a block's spans only
/// where its rectangle meets the tile.
const BLOCK_SPANS: usize = 64;
/// Tile side in pixels, as `shaders/tiles.wgsl` has it.
const TILE: u32 = 8;
/// Bytes of a projected splat (`Projected` in `shaders/tiles.wgsl`).
const PROJECTED_BYTES: u64 = 48;
/// Uniform slots are this far apart (wgpu's largest `min_uniform_buffer_offset_alignment`).
const SLOT: u64 = 256;

/// Keep in sync with `Batch` in shaders/tiles.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct BatchUniforms {
    count: u32,
    first: u32,
    width: u32,
    height: u32,
    opaque: f32,
    cutoff: f32,
    spans: u32,
    out: u32,
}

/// The tile pass's shader: the footprint and the splat pass's uniforms and helpers, then the
/// passes themselves.
const TILES_WGSL: &str = concat!(
    include_str!("../../shaders/footprint.wgsl"),
    include_str!("../../shaders/splat.wgsl"),
    include_str!("../../shaders/tiles.wgsl")
);

/// The tile pass's pipelines and the buffers it reuses from frame to frame.
#[derive(Debug)]
pub(crate) struct TilePass {
    project: wgpu::ComputePipeline,
    bound_blocks: wgpu::ComputePipeline,
    composite: wgpu::ComputePipeline,
    cover: wgpu::RenderPipeline,
    /// Projected splats of one batch.
    projected: Option<wgpu::Buffer>,
    /// The span rectangles of one batch.
    rects: Option<wgpu::Buffer>,
    /// The block rectangles of one batch.
    blocks: Option<wgpu::Buffer>,
    /// The accumulated layer, premultiplied RGBA as f32 a pixel.
    layer: Option<wgpu::Buffer>,
    /// The uniforms: a slot for each piece, one for each batch, then the image's.
    batches: Option<wgpu::Buffer>,
    /// Splats in a batch, at most.
    batch: usize,
}

/// A buffer of at least `bytes`, kept where the one held is large enough.
fn ensure(
    ctx: &GpuContext,
    slot: &mut Option<wgpu::Buffer>,
    bytes: u64,
    usage: wgpu::BufferUsages,
    label: &str,
) -> wgpu::Buffer {
    if let Some(buffer) = slot.as_ref().filter(|b| b.size() >= bytes) {
        return buffer.clone();
    }
    let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.max(16).next_multiple_of(256),
        usage,
        mapped_at_creation: false,
    });
    *slot = Some(buffer.clone());
    buffer
}

fn entry(binding: u32, resource: wgpu::BindingResource<'_>) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry { binding, resource }
}

/// A stretch of one grid's draw order (`begin..end` of the order bound for `source`), projected
/// by one dispatch into its batch's splats from `out` on.
#[derive(Debug, Clone, PartialEq)]
struct Piece {
    source: usize,
    begin: usize,
    end: usize,
    out: usize,
}

/// Pieces composited by one dispatch: their splats one after another, each piece padded to a
/// whole [`GROUP`] (`len` in all).
#[derive(Debug, Default)]
struct Batch {
    pieces: Vec<Piece>,
    len: usize,
}

/// The batches of `runs` (each a source and a range of its draw order; nearest first, each
/// walked from its end): up to `batch` splats a batch (rounded up to a whole [`GROUP`]), pieces
/// of sources whose cut-offs (`cutoffs`) differ in different batches, since compositing reads
/// one.
fn batches(runs: &[(usize, std::ops::Range<usize>)], cutoffs: &[f32], batch: usize) -> Vec<Batch> {
    let cap = batch.max(1).next_multiple_of(GROUP);
    let mut out = Vec::new();
    let mut current = Batch::default();
    let mut cutoff: Option<u32> = None;
    for (source, range) in runs {
        let bits = cutoffs.get(*source).map(|c| c.to_bits());
        let mut end = range.end;
        while end > range.start {
            if current.len == cap || (current.len > 0 && cutoff != bits) {
                out.push(std::mem::take(&mut current));
            }
            cutoff = bits;
            let begin = end.saturating_sub(cap - current.len).max(range.start);
            current.pieces.push(Piece {
                source: *source,
                begin,
                end,
                out: current.len,
            });
            current.len += (end - begin).next_multiple_of(GROUP);
            end = begin;
        }
    }
    if current.len > 0 {
        out.push(current);
    }
    out
}

impl TilePass {
    pub(crate) fn new(ctx: &GpuContext) -> Self {
        let device = &ctx.device;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("tiles.wgsl"),
            source: wgpu::ShaderSource::Wgsl(TILES_WGSL.into()),
        });
        let compute = |entry: &str| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: None,
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let cover = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("tile layer"),
            layout: None,
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("cover_vs"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: Default::default(),
            depth_stencil: None,
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("cover_fs"),
                compilation_options: Default::default(),
                targets: &[Some(over_target(device))],
            }),
            multiview_mask: None,
            cache: None,
        });
        Self {
            project: compute("project"),
            bound_blocks: compute("bound_blocks"),
            composite: compute("composite"),
            cover,
            projected: None,
            rects: None,
            blocks: None,
            layer: None,
            batches: None,
            batch: MAX_BATCH,
        }
    }

    /// Composites at most `splats` splats a batch (still no more than the adapter binds).
    pub(crate) fn set_batch(&mut self, splats: std::num::NonZeroUsize) {
        self.batch = splats.get();
    }

    /// Makes `volume`'s opacity table for the step its uniforms were last written with, where
    /// the one it has was made for another.
    pub(crate) fn prepare(ctx: &GpuContext, volume: &mut GpuVolume) {
        let bits = volume.step_mm.to_bits();
        if volume.alpha.as_ref().is_some_and(|(b, _)| *b == bits) {
            return;
        }
        let table = crate::splat::tiled::alpha_table(volume.step_mm);
        let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("opacity table"),
            size: (table.len() * 4) as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        ctx.queue
            .write_buffer(&buffer, 0, bytemuck::cast_slice(&table));
        volume.alpha = Some((bits, buffer));
    }

    /// Composites `runs` (nearest first; each a stretch of the draw order of one of
    /// `volumes`, each with its order and uniforms written and [`TilePass::prepare`]d, drawn
    /// from its end) over the colour target `color` of `size`, depth-tested against `depth`
    /// (the meshes' reversed depth; its texture must allow binding), stopping a pixel at the
    /// accumulated opacity `opaque`.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn draw(
        &mut self,
        ctx: &GpuContext,
        volumes: &[&GpuVolume],
        runs: &[(usize, std::ops::Range<usize>)],
        size: (u32, u32),
        opaque: f32,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
    ) -> Result<(), RenderError> {
        let device = &ctx.device;
        let limits = device.limits();
        let (w, h) = size;
        let layer_bytes = u64::from(w) * u64::from(h) * 16;
        if layer_bytes > limits.max_storage_buffer_binding_size {
            return Err(RenderError::Unsupported {
                adapter: ctx.describe(),
                what: "hold the tile compositor's layer for an image this large in one storage buffer",
            });
        }
        // The projected splats of a batch, and a piece's stretch of its order, are bound whole.
        let bindable = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size)
            / PROJECTED_BYTES;
        // Whole groups, since a batch's pieces are padded to them.
        // A piece's projection is one dispatch of at most the adapter's workgroups along x.
        let dispatchable = limits.max_compute_workgroups_per_dimension as usize * GROUP;
        let bindable = usize::try_from(bindable)
            .unwrap_or(usize::MAX)
            .min(dispatchable)
            .max(GROUP)
            / GROUP
            * GROUP;
        // Runs of a volume with nothing to draw from are left out (their pieces would be
        // composited unprojected).
        let runs: Vec<(usize, std::ops::Range<usize>)> = runs
            .iter()
            .filter(|(v, range)| {
                volumes.get(*v).is_some_and(|v| {
                    v.order.is_some() && v.alpha.is_some() && range.end <= v.count as usize
                })
            })
            .cloned()
            .collect();
        let cutoffs: Vec<f32> = volumes.iter().map(|v| v.cutoff).collect();
        let batches = batches(&runs, &cutoffs, self.batch.min(bindable));
        let largest = batches.iter().map(|b| b.len).max().unwrap_or(0);
        let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let projected = ensure(
            ctx,
            &mut self.projected,
            largest as u64 * PROJECTED_BYTES,
            storage,
            "projected splats",
        );
        let rects = ensure(
            ctx,
            &mut self.rects,
            (largest / SPAN) as u64 * 16,
            storage,
            "span rectangles",
        );
        let blocks = ensure(
            ctx,
            &mut self.blocks,
            (largest / SPAN).div_ceil(BLOCK_SPANS) as u64 * 16,
            storage,
            "block rectangles",
        );
        let layer = ensure(ctx, &mut self.layer, layer_bytes, storage, "tile layer");
        // A uniform slot a piece, then one a batch, then the image's.
        let pieces: usize = batches.iter().map(|b| b.pieces.len()).sum();
        let slots = pieces + batches.len() + 1;
        let uniform_buffer = ensure(
            ctx,
            &mut self.batches,
            slots as u64 * SLOT,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            "tile batches",
        );
        let mut uniforms = vec![0u8; slots * SLOT as usize];
        let mut put = |slot: usize, u: BatchUniforms| {
            let at = slot * SLOT as usize;
            uniforms[at..at + size_of::<BatchUniforms>()].copy_from_slice(bytemuck::bytes_of(&u));
        };
        let image = BatchUniforms {
            count: 0,
            first: 0,
            width: w,
            height: h,
            opaque,
            cutoff: 0.0,
            spans: 0,
            out: 0,
        };
        // An order is bound from a 256-byte boundary (64 ids) before the stretch.
        let align = (limits.min_storage_buffer_offset_alignment / 4).max(1) as usize;
        let mut slot = 0;
        for b in &batches {
            let cutoff = b.pieces.first().map_or(0.0, |p| cutoffs[p.source]);
            for p in &b.pieces {
                let count = p.end - p.begin;
                put(
                    slot,
                    BatchUniforms {
                        count: count as u32,
                        first: (p.begin % align) as u32,
                        cutoff,
                        spans: count.div_ceil(SPAN) as u32,
                        out: p.out as u32,
                        ..image
                    },
                );
                slot += 1;
            }
            put(
                slot,
                BatchUniforms {
                    count: b.len as u32,
                    cutoff,
                    spans: (b.len / SPAN) as u32,
                    ..image
                },
            );
            slot += 1;
        }
        put(slot, image);
        ctx.queue.write_buffer(&uniform_buffer, 0, &uniforms);
        let slot_binding = |i: usize| wgpu::BufferBinding {
            buffer: &uniform_buffer,
            offset: i as u64 * SLOT,
            size: wgpu::BufferSize::new(size_of::<BatchUniforms>() as u64),
        };
        let mut encoder = device.create_command_encoder(&Default::default());
        encoder.clear_buffer(&layer, 0, Some(layer_bytes));
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            let project_layout = self.project.get_bind_group_layout(0);
            let blocks_layout = self.bound_blocks.get_bind_group_layout(0);
            let composite_layout = self.composite.get_bind_group_layout(0);
            let mut slot = 0;
            for b in &batches {
                for p in &b.pieces {
                    let this = slot;
                    slot += 1;
                    let volume = &volumes[p.source];
                    let (Some(order), Some((_, alpha))) = (&volume.order, &volume.alpha) else {
                        continue;
                    };
                    let from = p.begin - p.begin % align;
                    let order_range = wgpu::BufferBinding {
                        buffer: order,
                        offset: from as u64 * 4,
                        size: wgpu::BufferSize::new((p.end - from) as u64 * 4),
                    };
                    let project = device.create_bind_group(&wgpu::BindGroupDescriptor {
                        label: Some("tile projection"),
                        layout: &project_layout,
                        entries: &[
                            entry(0, volume.uniforms.as_entire_binding()),
                            entry(1, wgpu::BindingResource::TextureView(&volume.texels)),
                            entry(7, wgpu::BindingResource::TextureView(&volume.bitmap)),
                            entry(2, wgpu::BindingResource::Buffer(order_range)),
                            entry(3, alpha.as_entire_binding()),
                            entry(4, projected.as_entire_binding()),
                            entry(5, rects.as_entire_binding()),
                            entry(6, wgpu::BindingResource::Buffer(slot_binding(this))),
                        ],
                    });
                    pass.set_pipeline(&self.project);
                    pass.set_bind_group(0, &project, &[]);
                    pass.dispatch_workgroups((p.end - p.begin).div_ceil(GROUP) as u32, 1, 1);
                }
                let bound = device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("tile blocks"),
                    layout: &blocks_layout,
                    entries: &[
                        entry(15, rects.as_entire_binding()),
                        entry(16, blocks.as_entire_binding()),
                        entry(17, wgpu::BindingResource::Buffer(slot_binding(slot))),
                    ],
                });
                pass.set_pipeline(&self.bound_blocks);
                pass.set_bind_group(0, &bound, &[]);
                let block_count = (b.len / SPAN).div_ceil(BLOCK_SPANS) as u32;
                pass.dispatch_workgroups(block_count.div_ceil(64), 1, 1);
                let composite = device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("tile compositing"),
                    layout: &composite_layout,
                    entries: &[
                        entry(8, projected.as_entire_binding()),
                        entry(9, rects.as_entire_binding()),
                        entry(10, layer.as_entire_binding()),
                        entry(11, wgpu::BindingResource::TextureView(depth)),
                        entry(12, wgpu::BindingResource::Buffer(slot_binding(slot))),
                        entry(18, blocks.as_entire_binding()),
                    ],
                });
                slot += 1;
                pass.set_pipeline(&self.composite);
                pass.set_bind_group(0, &composite, &[]);
                pass.dispatch_workgroups(w.div_ceil(TILE), h.div_ceil(TILE), 1);
            }
        }
        let cover = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("tile layer"),
            layout: &self.cover.get_bind_group_layout(0),
            entries: &[
                entry(13, layer.as_entire_binding()),
                entry(14, wgpu::BindingResource::Buffer(slot_binding(slots - 1))),
            ],
        });
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("tile layer"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: color,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Load,
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&self.cover);
            pass.set_bind_group(0, &cover, &[]);
            pass.draw(0..3, 0..1);
        }
        ctx.queue.submit([encoder.finish()]);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The batches cover every run exactly once, nearest first: runs in the order given, each
    /// from its end, no batch longer than asked for (in whole groups), every piece starting
    /// at a group, and pieces of different cut-offs never in one batch.
    #[test]
    fn batches_cover_the_runs_nearest_first() {
        let runs = [
            (0, 0..100_000),
            (1, 5..5),
            (2, 0..3),
            (0, 100_000..100_700),
            (3, 17..2_000_017),
            (2, 3..300),
        ];
        let cutoffs = [9.0, 9.0, 9.0, 4.0];
        for batch in [0, 1, 300, 16_384, MAX_BATCH] {
            let cap = batch.max(1).next_multiple_of(GROUP);
            let got = batches(&runs, &cutoffs, batch);
            let pieces: Vec<&Piece> = got.iter().flat_map(|b| &b.pieces).collect();
            let mut next = pieces.iter();
            for (source, range) in &runs {
                let mut end = range.end;
                while end > range.start {
                    let p = next.next().expect("a piece for every stretch of a run");
                    assert_eq!((p.source, p.end), (*source, end), "batch {batch}");
                    assert!(p.begin < p.end && p.begin >= range.start);
                    end = p.begin;
                }
            }
            assert!(next.next().is_none());
            for b in &got {
                assert!(b.len <= cap && b.len > 0 && b.len % GROUP == 0, "{b:?}");
                let mut out = 0;
                for p in &b.pieces {
                    assert_eq!(p.out, out);
                    out += (p.end - p.begin).next_multiple_of(GROUP);
                }
                assert_eq!(out, b.len);
                let c = cutoffs[b.pieces[0].source];
                assert!(b.pieces.iter().all(|p| cutoffs[p.source] == c), "{b:?}");
            }
            // Runs of one cut-off share batches where they fit.
            if batch == MAX_BATCH {
                assert_eq!(got.len(), 3, "{got:?}");
            }
        }
    }
}
