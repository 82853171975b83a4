//! The splat pass: one instanced quad per significant voxel, drawn in the order the `order`
//! module gives, premultiplied "over", depth-tested against the meshes without writing depth.
//!
//! Per volume the GPU holds a 3D texture of the tile compositor's 8-byte texels (straight RGB8
//! colour, snorm8 gradient, f16 density; uploaded when the volume or its transfer function
//! changes) and the draw order as an instance vertex buffer of u32 voxel
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
    /// The texels, for the tile pass's projection.
    pub(super) texels: wgpu::TextureView,
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

fn texture_3d(
    ctx: &GpuContext,
    dims: [u32; 3],
    format: wgpu::TextureFormat,
    texels: &[u8],
    label: &str,
) -> wgpu::Texture {
    let size = wgpu::Extent3d {
        width: dims[0],
        height: dims[1],
        depth_or_array_layers: dims[2],
    };
    let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D3,
        format,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    ctx.queue.write_texture(
        texture.as_image_copy(),
        texels,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(8 * dims[0]),
            rows_per_image: Some(dims[1]),
        },
        size,
    );
    texture
}

fn texture_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::VERTEX,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Uint,
            view_dimension: wgpu::TextureViewDimension::D3,
            multisampled: false,
        },
        count: None,
    }
}

/// The 8-byte texel of every voxel of the grid (zero where not significant), as the tile
/// compositor stores them ([`crate::splat::tiled::SplatTexels`]): the splat pass's one texture. One
/// z-slice a task, walking the slice's x rows, so only significant voxels are visited.
fn splat_texels(
    classified: &Classified,
    texel: &(dyn Fn([u32; 3], usize) -> [u8; 8] + Sync),
) -> Vec<u8> {
    let grid = &classified.grid;
    let [nx, ny, nz] = grid.dims().map(|n| n as usize);
    let mut texels = vec![0u8; nx * ny * nz * 8];
    // The x rows are read from every task below: made first, not by the first task.
    grid.prepare_rows(0);
    texels
        .par_chunks_mut((nx * ny * 8).max(1))
        .enumerate()
        .for_each(|(z, slice)| {
            for y in 0..ny {
                for run in grid.row(0, y as u32, z as u32) {
                    for x in run.start..run.end() {
                        let id = x + (nx * (y + ny * z)) as u32;
                        if let Some(rank) = grid.rank(id) {
                            let k = [x, y as u32, z as u32];
                            let i = (x as usize + nx * y) * 8;
                            slice[i..i + 8].copy_from_slice(&texel(k, rank as usize));
                        }
                    }
                }
            }
        });
    texels
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

    /// Uploads a classified volume's texels as a dense 3D texture.
    pub(crate) fn upload(
        &self,
        ctx: &GpuContext,
        classified: &Classified,
        texel: &(dyn Fn([u32; 3], usize) -> [u8; 8] + Sync),
    ) -> Result<GpuVolume, RenderError> {
        let dims = classified.grid.dims();
        let max = ctx.device.limits().max_texture_dimension_3d;
        if dims.iter().any(|&n| n > max) {
            return Err(RenderError::VolumeTooLarge { dims, max });
        }
        // The texture is dense: 8 bytes a voxel of the grid, significant or not (a refined
        // grid's included), held once on the CPU while it is written.
        let voxels: u64 = dims.iter().map(|&n| u64::from(n)).product();
        crate::budget::check_memory(format!("a {voxels}-voxel splat texture"), voxels, 8)?;
        let texels = texture_3d(
            ctx,
            dims,
            wgpu::TextureFormat::Rg32Uint,
            &splat_texels(classified, texel),
            "splat texels",
        );
        let uniforms = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("splat uniforms"),
            size: size_of::<SplatUniforms>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let texels = texels.create_view(&Default::default());
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
            ],
        });
        Ok(GpuVolume {
            uniforms,
            group,
            texels,
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
