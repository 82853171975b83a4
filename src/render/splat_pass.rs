//! The splat pass: one instanced quad per significant voxel, drawn in the order the `order`
//! module gives, premultiplied "over", depth-tested against the meshes without writing depth.
//!
//! Per volume the GPU holds the tile compositor's 8-byte texels of its significant voxels in id
//! order (straight RGB8 colour, snorm8 gradient, f16 density; uploaded when the volume or its
//! transfer function changes) with the grid's bitmap and rank index, from which a shader finds
//! a voxel's texel by its id, and the draw order as an instance vertex buffer of u32 voxel
//! ids, the one thing uploaded per frame. Vertex buffers are not bound by the 128 MiB storage
//! binding ceiling: their size is limited only by the adapter's `max_buffer_size`.

use bytemuck::{Pod, Zeroable};
use glam::DVec3;
use rayon::prelude::*;

use super::target::{DEPTH_FORMAT, over_target};
use super::view::ViewSetup;
use super::{GpuContext, RenderError};
use crate::classify::{Classified, view_step_mm};
use crate::geometry::VolumeGeometry;
use crate::scene::{ClipPlane, Clipping, MAX_PLANES_IN_FORCE, SplatSettings};

/// Keep in sync with `Splat` in shaders/splat.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct SplatUniforms {
    m: [[f32; 4]; 3],
    eye: [f32; 4],
    cov: [[f32; 4]; 3],
    screen: [f32; 4],
    size: [f32; 4],
    depth: [f32; 4],
    dims: [u32; 4],
    normal: [[f32; 4]; 3],
    clip: [[f32; 4]; CLIP_SLOTS],
}
const _: () = assert!(size_of::<SplatUniforms>() == 480);

/// Planes a splat is tested against: the scene's clip planes and crop box
/// ([`MAX_PLANES_IN_FORCE`]), and, in perspective, the four beside the view
/// ([`crate::splat::footprint::beside_the_view`]). `shaders/splat.wgsl` holds as many.
const CLIP_SLOTS: usize = MAX_PLANES_IN_FORCE + 4;

/// The splat pipeline.
#[derive(Debug)]
pub(crate) struct SplatPass {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
}

/// One classified volume on the GPU.
#[derive(Debug)]
pub(crate) struct GpuVolume {
    pub(super) uniforms: wgpu::Buffer,
    group: wgpu::BindGroup,
    /// The texels of the significant voxels in id order, and the grid's bitmap with its rank
    /// index (`texel_of` in `shaders/splat.wgsl`), for the tile pass's projection.
    pub(super) texels: wgpu::TextureView,
    pub(super) bitmap: wgpu::TextureView,
    /// The draw order (a vertex buffer for the splat pass, a storage buffer for the tile
    /// pass).
    pub(super) order: Option<wgpu::Buffer>,
    pub(super) count: u32,
    /// The millimetres one index step spans along the view, as the uniforms last written
    /// hold it (the tile pass's opacity table follows it).
    pub(super) step_mm: f32,
    /// The cut-off of the Gaussian's exponent, as the uniforms last written hold it.
    pub(super) cutoff: f32,
    /// The tile pass's opacity table and the bits of the step it was made for.
    pub(super) alpha: Option<(u32, wgpu::Buffer)>,
}

fn texture_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::VERTEX,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Uint,
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        },
        count: None,
    }
}

/// The 8-byte texel of every significant voxel in id order, as the tile compositor stores
/// them ([`crate::splat::tiled::SplatTexels`]). A dense 3-D texture held 8 bytes a voxel of
/// the grid, significant or not, and a temporary as large on the CPU: drawing the 0.7 mm
/// LIDC2 CT peaked at 2.5 GB with either GPU pass on lavapipe, against 0.56-0.63 GB so
/// (BENCHMARKS.md). One z-slice a task, walking the slice's x rows, so only significant voxels
/// are visited and each task writes its own stretch.
fn splat_texels(
    classified: &Classified,
    texel: &(dyn Fn([u32; 3], usize) -> [u8; 8] + Sync),
) -> Vec<u8> {
    let grid = &classified.grid;
    let [_, ny, nz] = grid.dims();
    // The x rows are read from every task below: made first, not by the first task.
    grid.prepare_rows(0);
    let counts: Vec<usize> = (0..nz)
        .into_par_iter()
        .map(|z| {
            (0..ny)
                .flat_map(|y| grid.row(0, y, z))
                .map(|run| run.len as usize)
                .sum()
        })
        .collect();
    let mut texels = vec![0u8; grid.len() * 8];
    let mut slices = Vec::with_capacity(counts.len());
    let (mut rest, mut first) = (texels.as_mut_slice(), 0usize);
    for &count in &counts {
        let (slice, tail) = rest.split_at_mut(count * 8);
        slices.push((first, slice));
        (rest, first) = (tail, first + count);
    }
    slices
        .into_par_iter()
        .enumerate()
        .for_each(|(z, (first, slice))| {
            let mut rank = first;
            let mut out = slice.chunks_exact_mut(8);
            for y in 0..ny {
                for run in grid.row(0, y, z as u32) {
                    for x in run.start..run.end() {
                        let k = [x, y, z as u32];
                        if let Some(place) = out.next() {
                            place.copy_from_slice(&texel(k, rank));
                        }
                        rank += 1;
                    }
                }
            }
        });
    texels
}

/// A list of `bytes.len() / texel_bytes` texels of `format` as a 2-D texture read row by row
/// (`at` in `shaders/splat.wgsl`): rows as wide as the adapter allows, the last one padded.
/// A storage buffer would be plainer, but some adapters bind less of one than a volume's
/// texels take (lavapipe 128 MiB: 16M splats). `None` where the list is longer than the
/// adapter's largest 2-D texture holds.
fn list_texture(
    ctx: &GpuContext,
    bytes: &[u8],
    format: wgpu::TextureFormat,
    texel_bytes: usize,
    label: &str,
) -> Option<wgpu::TextureView> {
    let n = bytes.len() / texel_bytes;
    let max = ctx.device.limits().max_texture_dimension_2d as usize;
    let width = n.clamp(1, max.max(1));
    let rows = n.div_ceil(width).max(1);
    if rows > max {
        return None;
    }
    let size = wgpu::Extent3d {
        width: width as u32,
        height: rows as u32,
        depth_or_array_layers: 1,
    };
    let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    let row_bytes = width * texel_bytes;
    let whole = (n / width) * row_bytes;
    let layout = |rows: usize| wgpu::TexelCopyBufferLayout {
        offset: 0,
        bytes_per_row: Some(row_bytes as u32),
        rows_per_image: Some(rows as u32),
    };
    if whole > 0 {
        ctx.queue.write_texture(
            texture.as_image_copy(),
            &bytes[..whole],
            layout(n / width),
            wgpu::Extent3d {
                height: (n / width) as u32,
                ..size
            },
        );
    }
    // The last row, padded with zeros.
    if whole < bytes.len() {
        let mut last = bytes[whole..].to_vec();
        last.resize(row_bytes, 0);
        ctx.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                origin: wgpu::Origin3d {
                    x: 0,
                    y: (n / width) as u32,
                    z: 0,
                },
                ..texture.as_image_copy()
            },
            &last,
            layout(1),
            wgpu::Extent3d { height: 1, ..size },
        );
    }
    Some(texture.create_view(&Default::default()))
}

/// Whether the adapter runs compute shaders (every Vulkan, Metal and D3D12 adapter does; some
/// GL ones do not).
pub(crate) fn computes(ctx: &GpuContext) -> bool {
    ctx.adapter
        .get_downlevel_capabilities()
        .flags
        .contains(wgpu::DownlevelFlags::COMPUTE_SHADERS)
}

/// The splat pass's shader: the footprint shared with the CPU compositors
/// (`shaders/footprint.wgsl`), then the pass itself (`shaders/splat.wgsl`).
const SPLAT_WGSL: &str = concat!(
    include_str!("../../shaders/footprint.wgsl"),
    include_str!("../../shaders/splat.wgsl")
);

impl SplatPass {
    pub(crate) fn new(ctx: &GpuContext) -> Self {
        let device = &ctx.device;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("splat.wgsl"),
            source: wgpu::ShaderSource::Wgsl(SPLAT_WGSL.into()),
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("splat"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                texture_entry(1),
                texture_entry(7),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("splat"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let attributes = wgpu::vertex_attr_array![0 => Uint32];
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("splat"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[Some(wgpu::VertexBufferLayout {
                    array_stride: 4,
                    step_mode: wgpu::VertexStepMode::Instance,
                    attributes: &attributes,
                })],
            },
            primitive: wgpu::PrimitiveState {
                topology: wgpu::PrimitiveTopology::TriangleStrip,
                ..Default::default()
            },
            depth_stencil: Some(wgpu::DepthStencilState {
                format: DEPTH_FORMAT,
                depth_write_enabled: Some(false),
                depth_compare: Some(wgpu::CompareFunction::GreaterEqual),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[Some(over_target(device))],
            }),
            multiview_mask: None,
            cache: None,
        });
        Self { pipeline, layout }
    }

    /// Uploads a classified volume's texels, one a significant voxel, with its grid's bitmap
    /// and rank index, from which the passes find a voxel's texel by its id.
    pub(crate) fn upload(
        &self,
        ctx: &GpuContext,
        classified: &Classified,
        texel: &(dyn Fn([u32; 3], usize) -> [u8; 8] + Sync),
    ) -> Result<GpuVolume, RenderError> {
        let splats = classified.grid.len();
        // Held once on the CPU while it is written: 8 bytes a splat.
        crate::budget::check_memory(format!("the texels of {splats} splats"), splats as u64, 8)?;
        let texels = list_texture(
            ctx,
            &splat_texels(classified, texel),
            wgpu::TextureFormat::Rg32Uint,
            8,
            "splat texels",
        )
        .ok_or_else(|| {
            let side = u64::from(ctx.device.limits().max_texture_dimension_2d);
            RenderError::TooManySplats {
                splats,
                max_bytes: side * side * 8,
            }
        })?;
        let bitmap = list_texture(
            ctx,
            bytemuck::cast_slice(&classified.grid.rank_words()),
            wgpu::TextureFormat::R32Uint,
            4,
            "splat bitmap",
        )
        .ok_or_else(|| RenderError::Unsupported {
            adapter: ctx.describe(),
            what: "hold this grid's bitmap in one 2-D texture",
        })?;
        let uniforms = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("splat uniforms"),
            size: size_of::<SplatUniforms>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("splat"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: uniforms.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&texels),
                },
                wgpu::BindGroupEntry {
                    binding: 7,
                    resource: wgpu::BindingResource::TextureView(&bitmap),
                },
            ],
        });
        Ok(GpuVolume {
            uniforms,
            group,
            texels,
            bitmap,
            order: None,
            count: 0,
            step_mm: 0.0,
            cutoff: 0.0,
            alpha: None,
        })
    }

    /// Uploads this frame's draw order (voxel ids, first drawn first), growing the buffer only
    /// when the list outgrows it.
    pub(crate) fn upload_order(
        ctx: &GpuContext,
        volume: &mut GpuVolume,
        ids: &[u32],
    ) -> Result<(), RenderError> {
        let bytes = (ids.len() * 4) as u64;
        if bytes > ctx.device.limits().max_buffer_size {
            return Err(RenderError::TooManySplats {
                splats: ids.len(),
                max_bytes: ctx.device.limits().max_buffer_size,
            });
        }
        let fits = volume.order.as_ref().is_some_and(|b| b.size() >= bytes);
        if !fits && bytes > 0 {
            volume.order = Some(ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("splat order"),
                size: bytes.next_multiple_of(4096),
                // A storage buffer too for the tile pass, where the adapter runs compute
                // shaders (a GLES adapter may not, and refuses the usage).
                usage: wgpu::BufferUsages::VERTEX
                    | wgpu::BufferUsages::COPY_DST
                    | if computes(ctx) {
                        wgpu::BufferUsages::STORAGE
                    } else {
                        wgpu::BufferUsages::empty()
                    },
                mapped_at_creation: false,
            }));
        }
        if let (Some(buffer), false) = (&volume.order, ids.is_empty()) {
            ctx.queue.write_buffer(buffer, 0, bytemuck::cast_slice(ids));
        }
        volume.count = ids.len() as u32;
        Ok(())
    }

    /// Writes the projection of this frame for one volume.
    pub(crate) fn write_uniforms(
        ctx: &GpuContext,
        volume: &mut GpuVolume,
        geometry: &VolumeGeometry,
        view: &ViewSetup,
        settings: &SplatSettings,
        clipping: &Clipping,
    ) {
        let u = uniforms(geometry, view, settings, clipping);
        volume.step_mm = u.depth[3];
        volume.cutoff = u.size[2];
        ctx.queue
            .write_buffer(&volume.uniforms, 0, bytemuck::bytes_of(&u));
    }

    /// Records the draw of `splats`, a stretch of one volume's draw order on the GPU (far to
    /// near).
    pub(crate) fn draw(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        volume: &GpuVolume,
        splats: std::ops::Range<usize>,
    ) {
        let Some(order) = &volume.order else {
            return;
        };
        let end = splats.end.min(volume.count as usize) as u32;
        let begin = (splats.start as u32).min(end);
        if begin == end {
            return;
        }
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &volume.group, &[]);
        pass.set_vertex_buffer(0, order.slice(..u64::from(volume.count) * 4));
        pass.draw(0..4, begin..end);
    }
}

/// The splat pass's uniforms for one volume in one view.
fn uniforms(
    geometry: &VolumeGeometry,
    view: &ViewSetup,
    settings: &SplatSettings,
    clipping: &Clipping,
) -> SplatUniforms {
    let style = &settings.style;
    let linear = geometry.index_to_world().matrix3;
    let m = view.axes.transpose() * linear;
    let cov = m * m.transpose() * (style.sigma * style.sigma);
    let eye_index = geometry.world_to_index(view.camera.eye);
    let min_spacing = geometry.spacing().into_iter().fold(f64::INFINITY, f64::min);
    let row = |v: DVec3| [v.x as f32, v.y as f32, v.z as f32, 0.0];
    let (w, h) = (f64::from(view.size.0), f64::from(view.size.1));
    let cutoff = (style.cutoff / style.sigma).powi(2);
    let ortho = view.is_orthographic();
    let mut planes = camera_planes(view, clipping.all_planes().iter());
    if !ortho {
        let rows = cov.transpose().to_cols_array_2d();
        planes.extend(
            crate::splat::footprint::beside_the_view(
                view.focal,
                (w, h),
                &rows,
                cutoff,
                style.pixel_variance,
            )
            .map(|p| p.map(|v| v as f32)),
        );
    }
    SplatUniforms {
        m: [row(m.row(0)), row(m.row(1)), row(m.row(2))],
        eye: [
            eye_index.x as f32,
            eye_index.y as f32,
            eye_index.z as f32,
            view.splat_near(min_spacing) as f32,
        ],
        cov: [row(cov.row(0)), row(cov.row(1)), row(cov.row(2))],
        screen: [
            (0.5 * w) as f32,
            (0.5 * h) as f32,
            view.focal as f32,
            style.pixel_variance as f32,
        ],
        size: [
            w as f32,
            h as f32,
            cutoff as f32,
            if ortho { 1.0 } else { 0.0 },
        ],
        depth: [
            view.near as f32,
            view.near as f32,
            view.far.min(f64::MAX) as f32,
            view_step_mm(linear, view.axes.col(2)).unwrap_or(0.0) as f32,
        ],
        dims: {
            let d = geometry.dims();
            [d[0], d[1], d[2], planes.len() as u32]
        },
        normal: {
            let n = view.axes.transpose() * linear.inverse().transpose();
            let mut rows = [row(n.row(0)), row(n.row(1)), row(n.row(2))];
            rows[0][3] = settings.shading.clamp(0.0, 1.0);
            rows
        },
        clip: {
            let mut slots = [[0.0; 4]; CLIP_SLOTS];
            for (slot, plane) in slots.iter_mut().zip(&planes) {
                *slot = *plane;
            }
            slots
        },
    }
}

/// The same projection for the CPU tile compositor, taken from the very f32 values the GPU
/// gets, so that both draw the same splats.
pub(crate) fn projection(
    geometry: &VolumeGeometry,
    view: &ViewSetup,
    settings: &SplatSettings,
    clipping: &Clipping,
) -> crate::splat::tiled::SplatProjection {
    let u = uniforms(geometry, view, settings, clipping);
    let v = |r: [f32; 4]| glam::Vec3::new(r[0], r[1], r[2]);
    crate::splat::tiled::SplatProjection {
        m: u.m.map(v),
        eye_index: v(u.eye),
        near_cut: u.eye[3],
        cov: u.cov.map(v),
        centre: [u.screen[0], u.screen[1]],
        focal: u.screen[2],
        pixel_variance: u.screen[3],
        cutoff: u.size[2],
        orthographic: u.size[3] > 0.5,
        near: u.depth[1],
        far: u.depth[2],
        dims: [u.dims[0], u.dims[1], u.dims[2]],
        row: strength_reduce::StrengthReducedU32::new(u.dims[0].max(1)),
        plane: strength_reduce::StrengthReducedU32::new((u.dims[0] * u.dims[1]).max(1)),
        normal: u.normal.map(v),
        shading: u.normal[0][3],
        clip: u.clip[..u.dims[3] as usize].to_vec(),
        alpha: crate::splat::tiled::alpha_table(u.depth[3]),
    }
}

/// Clip planes in camera space (rows right, up, forward; the eye at the origin), taken in f64
/// relative to the eye before they become f32.
pub(crate) fn camera_planes<'a>(
    view: &ViewSetup,
    planes: impl Iterator<Item = &'a ClipPlane>,
) -> Vec<[f32; 4]> {
    planes
        .take(MAX_PLANES_IN_FORCE)
        .map(|plane| {
            let n = view.axes.transpose() * plane.normal;
            let d = plane.offset - plane.normal.dot(view.camera.eye);
            [n.x as f32, n.y as f32, n.z as f32, d as f32]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shader_holds_as_many_planes_as_the_uniforms() {
        let wgsl = include_str!("../../shaders/splat.wgsl");
        assert!(wgsl.contains(&format!("clip: array<vec4<f32>, {CLIP_SLOTS}>")));
    }
}
