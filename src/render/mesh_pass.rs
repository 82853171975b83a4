//! The mesh pass: opaque meshes lit with their normals, writing depth.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};
use glam::{DMat3, Mat4};
use wgpu::util::DeviceExt;

use super::GpuContext;
use super::target::{DEPTH_FORMAT, color_format};
use super::view::ViewSetup;
use crate::mesh::{CpuMesh, Material};
use crate::scene::{ClipPlane, Clipping, Lights, MAX_PLANES_IN_FORCE};

/// Keep in sync with `Frame` in shaders/mesh.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct FrameUniforms {
    view_proj: [[f32; 4]; 4],
    forward: [f32; 4],
    params: [f32; 4],
    light_dir: [[f32; 4]; 4],
    light_color: [[f32; 4]; 4],
    clip: [[f32; 4]; MAX_PLANES_IN_FORCE],
}
const _: () = assert!(size_of::<FrameUniforms>() == 416);

/// Keep in sync with `Object` in shaders/mesh.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct ObjectUniforms {
    model: [[f32; 4]; 4],
    normal: [[f32; 4]; 4],
    base_color: [f32; 4],
    material: [f32; 4],
}
const _: () = assert!(size_of::<ObjectUniforms>() == 160);

/// Keep in sync with the vertex inputs of shaders/mesh.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct Vertex {
    position: [f32; 3],
    normal: [f32; 3],
    /// Multiplies the material's colour (white where the mesh has no colours).
    color: [f32; 4],
}

/// The mesh pipelines and their per-frame uniforms.
#[derive(Debug)]
pub(crate) struct MeshPass {
    pipeline: wgpu::RenderPipeline,
    /// Overlays (measurement markers) drawn over everything: built on first use.
    overlay: Option<wgpu::RenderPipeline>,
    /// Translucent meshes: first their nearest surface's depth (tested against what is
    /// there), then their colour blended where the depth is that surface's, so that a closed
    /// mesh blends once, not once per layer.
    translucent: Option<(wgpu::RenderPipeline, wgpu::RenderPipeline)>,
    layout: wgpu::PipelineLayout,
    module: wgpu::ShaderModule,
    object_layout: wgpu::BindGroupLayout,
    frame_buffer: wgpu::Buffer,
    frame_group: wgpu::BindGroup,
}

/// A mesh on the GPU with its own uniforms.
#[derive(Debug)]
pub(crate) struct GpuMesh {
    /// The CPU mesh it was made from (compared by pointer to know when to upload again).
    pub(crate) source: Arc<CpuMesh>,
    /// The mesh's bounding box in its own frame (none without vertices).
    pub(crate) bounds: Option<([f32; 3], [f32; 3])>,
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    index_count: u32,
    uniforms: wgpu::Buffer,
    group: wgpu::BindGroup,
}

fn uniform_layout(
    device: &wgpu::Device,
    label: &str,
    visibility: wgpu::ShaderStages,
) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(label),
        entries: &[wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        }],
    })
}

impl MeshPass {
    pub(crate) fn new(ctx: &GpuContext) -> Self {
        let device = &ctx.device;
        let module = device.create_shader_module(wgpu::include_wgsl!("../../shaders/mesh.wgsl"));
        let both = wgpu::ShaderStages::VERTEX_FRAGMENT;
        let frame_layout = uniform_layout(device, "mesh frame", both);
        let object_layout = uniform_layout(device, "mesh object", both);
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("mesh"),
            bind_group_layouts: &[Some(&frame_layout), Some(&object_layout)],
            immediate_size: 0,
        });
        let pipeline = mesh_pipeline(
            device,
            &layout,
            &module,
            wgpu::CompareFunction::Greater,
            true,
            None,
            wgpu::ColorWrites::ALL,
        );
        let frame_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("mesh frame"),
            size: size_of::<FrameUniforms>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let frame_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("mesh frame"),
            layout: &frame_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: frame_buffer.as_entire_binding(),
            }],
        });
        Self {
            pipeline,
            overlay: None,
            translucent: None,
            layout,
            module,
            object_layout,
            frame_buffer,
            frame_group,
        }
    }

    /// A node's mesh on the GPU. Where `shared` was made from the same mesh, its vertex and
    /// index buffers are used again (wgpu buffers are shared handles): a file named by
    /// thousands of nodes is uploaded once, each node keeping only its own transform.
    pub(crate) fn upload_sharing(
        &self,
        ctx: &GpuContext,
        mesh: &Arc<CpuMesh>,
        shared: Option<&GpuMesh>,
    ) -> GpuMesh {
        let device = &ctx.device;
        let buffers = shared
            .filter(|g| Arc::ptr_eq(&g.source, mesh))
            .map(|g| (g.vertices.clone(), g.indices.clone(), g.bounds))
            .unwrap_or_else(|| {
                let (vertices, indices) = self.buffers(ctx, mesh);
                (vertices, indices, mesh.bounds())
            });
        let (vertices, indices, bounds) = buffers;
        let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("mesh object"),
            size: size_of::<ObjectUniforms>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("mesh object"),
            layout: &self.object_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: uniforms.as_entire_binding(),
            }],
        });
        GpuMesh {
            source: Arc::clone(mesh),
            bounds,
            vertices,
            indices,
            index_count: (mesh.indices.len() / 3 * 3) as u32,
            uniforms,
            group,
        }
    }

    /// The vertex and index buffers of `mesh`.
    fn buffers(&self, ctx: &GpuContext, mesh: &CpuMesh) -> (wgpu::Buffer, wgpu::Buffer) {
        let device = &ctx.device;
        // Colours that do not match the positions one for one are left out (white).
        let colors: &[[f32; 4]] = if mesh.colors.len() == mesh.positions.len() {
            &mesh.colors
        } else {
            &[]
        };
        let vertices: Vec<Vertex> = mesh
            .positions
            .iter()
            .zip(
                mesh.normals
                    .iter()
                    .chain(std::iter::repeat(&[0.0, 0.0, 1.0])),
            )
            .zip(colors.iter().chain(std::iter::repeat(&[1.0; 4])))
            .map(|((p, n), c)| Vertex {
                position: *p,
                normal: *n,
                color: *c,
            })
            .collect();
        let vertices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("mesh vertices"),
            contents: bytemuck::cast_slice(&vertices),
            usage: wgpu::BufferUsages::VERTEX,
        });
        let indices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("mesh indices"),
            contents: bytemuck::cast_slice(&mesh.indices),
            usage: wgpu::BufferUsages::INDEX,
        });
        (vertices, indices)
    }

    /// Writes the camera and lights of this frame.
    pub(crate) fn write_frame(
        &self,
        ctx: &GpuContext,
        view: &ViewSetup,
        lights: &Lights,
        clipping: &Clipping,
    ) {
        let forward = view.axes.z_axis.as_vec3();
        let planes: Vec<ClipPlane> = clipping
            .all_planes()
            .into_iter()
            .filter(|p| p.meshes)
            .take(MAX_PLANES_IN_FORCE)
            .collect();
        let mut u = FrameUniforms {
            view_proj: view.view_proj().to_cols_array_2d(),
            forward: forward.extend(lights.headlight).to_array(),
            params: [
                lights.ambient,
                lights.directional.len().min(4) as f32,
                if view.is_orthographic() { 1.0 } else { 0.0 },
                planes.len() as f32,
            ],
            light_dir: [[0.0; 4]; 4],
            light_color: [[0.0; 4]; 4],
            clip: [[0.0; 4]; MAX_PLANES_IN_FORCE],
        };
        for (slot, plane) in u.clip.iter_mut().zip(&planes) {
            // Camera-relative world: the offset moves with the eye, in f64.
            let d = plane.offset - plane.normal.dot(view.camera.eye);
            *slot = plane.normal.as_vec3().extend(d as f32).to_array();
        }
        for (i, light) in lights.directional.iter().take(4).enumerate() {
            let d = light.direction.normalize_or(glam::DVec3::NEG_Z).as_vec3();
            u.light_dir[i] = d.extend(0.0).to_array();
            u.light_color[i] = [light.color[0], light.color[1], light.color[2], 0.0];
        }
        ctx.queue
            .write_buffer(&self.frame_buffer, 0, bytemuck::bytes_of(&u));
    }

    /// Writes a mesh's placement (relative to the eye) and material for this frame.
    pub(crate) fn write_object(
        ctx: &GpuContext,
        mesh: &GpuMesh,
        model: Mat4,
        world_linear: DMat3,
        material: &Material,
    ) {
        let normal = world_linear.inverse().transpose().as_mat3();
        let u = ObjectUniforms {
            model: model.to_cols_array_2d(),
            normal: Mat4::from_mat3(normal).to_cols_array_2d(),
            base_color: material.base_color,
            material: [material.roughness, material.metallic, 0.0, 0.0],
        };
        ctx.queue
            .write_buffer(&mesh.uniforms, 0, bytemuck::bytes_of(&u));
    }

    /// Records the draws of `meshes` into a pass that clears or keeps the targets.
    pub(crate) fn draw<'a>(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        meshes: impl Iterator<Item = &'a GpuMesh>,
    ) {
        self.draw_with(&self.pipeline, pass, meshes);
    }

    /// Builds the overlay pipeline if it is not there yet.
    pub(crate) fn prepare_overlay(&mut self, ctx: &GpuContext) {
        if self.overlay.is_none() {
            let compare = wgpu::CompareFunction::Always;
            self.overlay = Some(mesh_pipeline(
                &ctx.device,
                &self.layout,
                &self.module,
                compare,
                false,
                None,
                wgpu::ColorWrites::ALL,
            ));
        }
    }

    /// Builds the translucent pipeline if it is not there yet.
    pub(crate) fn prepare_translucent(&mut self, ctx: &GpuContext) {
        if self.translucent.is_none() {
            let depth = mesh_pipeline(
                &ctx.device,
                &self.layout,
                &self.module,
                wgpu::CompareFunction::Greater,
                true,
                None,
                wgpu::ColorWrites::empty(),
            );
            let color = mesh_pipeline(
                &ctx.device,
                &self.layout,
                &self.module,
                wgpu::CompareFunction::Equal,
                false,
                Some(wgpu::BlendState::PREMULTIPLIED_ALPHA_BLENDING),
                wgpu::ColorWrites::ALL,
            );
            self.translucent = Some((depth, color));
        }
    }

    /// Records translucent meshes, in the order given (far to near): each one's nearest
    /// surface, hidden behind what is nearer, blended over what is there (after
    /// [`Self::prepare_translucent`]). The depth is left holding those surfaces.
    pub(crate) fn draw_translucent<'a>(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        meshes: impl Iterator<Item = &'a GpuMesh>,
    ) {
        if let Some((depth, color)) = &self.translucent {
            for mesh in meshes {
                self.draw_with(depth, pass, std::iter::once(mesh));
                self.draw_with(color, pass, std::iter::once(mesh));
            }
        }
    }

    /// Whether the overlay pipeline exists.
    pub(crate) fn has_overlay(&self) -> bool {
        self.overlay.is_some()
    }

    /// Records overlay meshes, drawn over whatever is there (after [`Self::prepare_overlay`]).
    pub(crate) fn draw_overlay<'a>(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        meshes: impl Iterator<Item = &'a GpuMesh>,
    ) {
        if let Some(pipeline) = &self.overlay {
            self.draw_with(pipeline, pass, meshes);
        }
    }

    fn draw_with<'a>(
        &self,
        pipeline: &wgpu::RenderPipeline,
        pass: &mut wgpu::RenderPass<'_>,
        meshes: impl Iterator<Item = &'a GpuMesh>,
    ) {
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &self.frame_group, &[]);
        for mesh in meshes {
            pass.set_bind_group(1, &mesh.group, &[]);
            pass.set_vertex_buffer(0, mesh.vertices.slice(..));
            pass.set_index_buffer(mesh.indices.slice(..), wgpu::IndexFormat::Uint32);
            pass.draw_indexed(0..mesh.index_count, 0, 0..1);
        }
    }
}

/// A mesh pipeline with the given depth test and blending; opaque meshes write depth,
/// overlays and translucent meshes do not.
fn mesh_pipeline(
    device: &wgpu::Device,
    layout: &wgpu::PipelineLayout,
    module: &wgpu::ShaderModule,
    compare: wgpu::CompareFunction,
    write_depth: bool,
    blend: Option<wgpu::BlendState>,
    write_mask: wgpu::ColorWrites,
) -> wgpu::RenderPipeline {
    let attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x4];
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(
            match (write_depth, blend.is_some(), write_mask.is_empty()) {
                (true, _, true) => "translucent mesh depth",
                (true, _, false) => "mesh",
                (false, false, _) => "overlay",
                (false, true, _) => "translucent mesh",
            },
        ),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: &[Some(wgpu::VertexBufferLayout {
                array_stride: size_of::<Vertex>() as u64,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &attributes,
            })],
        },
        // Meshes from the wild are not reliably closed or consistently wound: draw both
        // faces and flip the normal of back faces in the shader.
        primitive: wgpu::PrimitiveState::default(),
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(write_depth),
            depth_compare: Some(compare),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::ColorTargetState {
                format: color_format(device),
                blend,
                write_mask,
            })],
        }),
        multiview_mask: None,
        cache: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shader_holds_as_many_planes_as_the_uniforms() {
        let wgsl = include_str!("../../shaders/mesh.wgsl");
        assert!(wgsl.contains(&format!("clip: array<vec4<f32>, {MAX_PLANES_IN_FORCE}>")));
    }
}
