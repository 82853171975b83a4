//! Offscreen render targets and the one readback helper (rows padded to 256 bytes on the GPU,
//! packed tightly on the CPU).

use super::{GpuContext, RenderError};
use crate::splat::reference::Frame;

/// Colour format of offscreen targets on `device`: 32-bit float where the device blends it
/// (wgpu's `FLOAT32_BLENDABLE`, which [`GpuContext`] asks for when the adapter has it), else
/// 16-bit float. Thousands of faint splats share a pixel of a dense volume seen from afar, each
/// adding less than a 16-bit float's step near opacity 1: in 16 bits the sum stalls short of
/// opaque (0.90 at 48x48 for a 136 mm cube of 0.5 mm voxels), in 32 bits it does not.
pub fn color_format(device: &wgpu::Device) -> wgpu::TextureFormat {
    if device
        .features()
        .contains(wgpu::Features::FLOAT32_BLENDABLE)
    {
        wgpu::TextureFormat::Rgba32Float
    } else {
        wgpu::TextureFormat::Rgba16Float
    }
}

/// The colour target of a pipeline that lays premultiplied colour "over" what the target
/// holds (the splat pass, the tile pass's finished layer).
pub(crate) fn over_target(device: &wgpu::Device) -> wgpu::ColorTargetState {
    let over = wgpu::BlendComponent {
        src_factor: wgpu::BlendFactor::One,
        dst_factor: wgpu::BlendFactor::OneMinusSrcAlpha,
        operation: wgpu::BlendOperation::Add,
    };
    wgpu::ColorTargetState {
        format: color_format(device),
        blend: Some(wgpu::BlendState {
            color: over,
            alpha: over,
        }),
        write_mask: wgpu::ColorWrites::ALL,
    }
}

/// Bytes a texel of the colour target on `device` takes.
fn color_bytes(device: &wgpu::Device) -> u32 {
    match color_format(device) {
        wgpu::TextureFormat::Rgba32Float => 16,
        _ => 8,
    }
}
/// Depth format: 32-bit float with reversed depth (1 at the near plane, 0 at infinity).
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// A colour and a depth texture of one size, to render into and read back.
#[derive(Debug)]
pub struct RenderTarget {
    /// Width and height in pixels.
    pub size: (u32, u32),
    /// Premultiplied linear RGBA.
    pub color: wgpu::Texture,
    /// View of `color`.
    pub color_view: wgpu::TextureView,
    /// Reversed depth.
    pub depth: wgpu::Texture,
    /// View of `depth`.
    pub depth_view: wgpu::TextureView,
}

impl RenderTarget {
    /// Targets of `width` x `height` pixels (any size the adapter allows, odd ones too).
    pub fn new(ctx: &GpuContext, width: u32, height: u32) -> Result<Self, RenderError> {
        let max = ctx.device.limits().max_texture_dimension_2d;
        if width == 0 || height == 0 || width > max || height > max {
            return Err(RenderError::BadSize { width, height, max });
        }
        // The colour readback is the larger one: 8 or 16 bytes a texel.
        let bytes = readback_bytes(width, height, color_bytes(&ctx.device));
        let max_buffer = ctx.device.limits().max_buffer_size;
        if bytes > max_buffer {
            return Err(RenderError::TooLargeToRead {
                width,
                height,
                bytes,
                max: max_buffer,
            });
        }
        let make = |format, label| {
            ctx.device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d {
                    width,
                    height,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                    | wgpu::TextureUsages::COPY_SRC
                    | wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            })
        };
        let color = make(color_format(&ctx.device), "colour target");
        let depth = make(DEPTH_FORMAT, "depth target");
        Ok(Self {
            size: (width, height),
            color_view: color.create_view(&Default::default()),
            depth_view: depth.create_view(&Default::default()),
            color,
            depth,
        })
    }

    /// Reads the colour target back as a premultiplied RGBA frame, converted row by row from
    /// the mapped buffer (no copy of the bytes in between).
    pub fn read_color(&self, ctx: &GpuContext) -> Result<Frame, RenderError> {
        let whole = PixelRect::whole(self.size);
        let (frame, _) = self.read_region(ctx, whole, None, false)?;
        Ok(frame)
    }

    /// Reads the depth target back: reversed depth per pixel, 0 where nothing was drawn.
    pub fn read_depth(&self, ctx: &GpuContext) -> Result<Vec<f32>, RenderError> {
        let w = self.size.0 as usize;
        let mut depth = vec![0.0f32; w * self.size.1 as usize];
        let whole = PixelRect::whole(self.size);
        let mut rows = depth.chunks_exact_mut(w);
        read_regions(
            ctx,
            &[(&self.depth, wgpu::TextureAspect::DepthOnly, 4, whole)],
            |_, row| {
                if let Some(out) = rows.next() {
                    depth_row(row, out);
                }
            },
        )?;
        Ok(depth)
    }

    /// The colour within `rect`, and the depth when `with_depth` (else no depth), read back
    /// together (one copy each, one wait). With a `fill`, the frame is the whole image and
    /// every pixel outside `rect` takes `fill`: for a layer whose drawing lies within `rect`
    /// on a target cleared to `fill`, the whole layer at the cost of the rectangle. Without,
    /// the frame is the rectangle alone. The depth is the whole image's, all 0 (as cleared)
    /// where `rect` is empty.
    pub(crate) fn read_region(
        &self,
        ctx: &GpuContext,
        rect: PixelRect,
        fill: Option<[f32; 4]>,
        with_depth: bool,
    ) -> Result<(Frame, Vec<f32>), RenderError> {
        let (w, h) = (self.size.0 as usize, self.size.1 as usize);
        let rect = rect.within(self.size);
        let [rx0, ry0, rx1, ry1] = rect.0.map(|v| v as usize);
        let (width, height, mut pixels) = match fill {
            Some(fill) => (self.size.0, self.size.1, vec![fill; w * h]),
            None => {
                let (rw, rh) = (rx1 - rx0, ry1 - ry0);
                (rw as u32, rh as u32, vec![[0.0; 4]; rw * rh])
            }
        };
        let mut depth = if with_depth {
            vec![0.0f32; w * h]
        } else {
            Vec::new()
        };
        let texel = color_bytes(&ctx.device);
        // Depth textures are copied whole (WebGPU allows no partial copy of one).
        let mut textures = Vec::with_capacity(2);
        if !rect.is_empty() {
            textures.push((&self.color, wgpu::TextureAspect::All, texel, rect));
        }
        // Nothing drawn outside `rect`: with no pixel in it, the depth is as cleared.
        if with_depth && !rect.is_empty() {
            let whole = PixelRect::whole(self.size);
            textures.push((&self.depth, wgpu::TextureAspect::DepthOnly, 4, whole));
        }
        if !textures.is_empty() {
            let mut rows = [0; 2];
            read_regions(ctx, &textures, |i, row| {
                let r = rows[i];
                rows[i] += 1;
                if textures[i].1 == wgpu::TextureAspect::DepthOnly {
                    depth_row(row, &mut depth[r * w..(r + 1) * w]);
                } else {
                    let span = match fill {
                        Some(_) => (ry0 + r) * w + rx0..(ry0 + r) * w + rx1,
                        None => r * (rx1 - rx0)..(r + 1) * (rx1 - rx0),
                    };
                    color_row(texel, row, &mut pixels[span]);
                }
            })?;
        }
        Ok((
            Frame {
                width,
                height,
                pixels,
            },
            depth,
        ))
    }
}

/// One row of a depth texture read back (32-bit floats, little-endian) into `out`.
fn depth_row(row: &[u8], out: &mut [f32]) {
    for (d, p) in out.iter_mut().zip(row.chunks_exact(4)) {
        *d = f32::from_le_bytes([p[0], p[1], p[2], p[3]]);
    }
}

/// A rectangle of pixels, `[x0, y0, x1, y1]`: columns `x0..x1`, rows `y0..y1`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct PixelRect(pub(crate) [u32; 4]);

impl PixelRect {
    /// Every pixel of an image of `size`.
    pub(crate) fn whole(size: (u32, u32)) -> Self {
        Self([0, 0, size.0, size.1])
    }

    /// No pixel.
    pub(crate) const EMPTY: Self = Self([0; 4]);

    /// How many pixels it holds.
    pub(crate) fn pixels(&self) -> usize {
        let [x0, y0, x1, y1] = self.0;
        x1.saturating_sub(x0) as usize * y1.saturating_sub(y0) as usize
    }

    /// Whether it holds no pixel.
    pub(crate) fn is_empty(&self) -> bool {
        let [x0, y0, x1, y1] = self.0;
        x0 >= x1 || y0 >= y1
    }

    /// The smallest rectangle holding both.
    pub(crate) fn union(self, other: Self) -> Self {
        match (self.is_empty(), other.is_empty()) {
            (true, _) => other,
            (_, true) => self,
            _ => {
                let ([a0, b0, a1, b1], [c0, d0, c1, d1]) = (self.0, other.0);
                Self([a0.min(c0), b0.min(d0), a1.max(c1), b1.max(d1)])
            }
        }
    }

    /// Its part on an image of `size`.
    pub(crate) fn within(self, size: (u32, u32)) -> Self {
        let [x0, y0, x1, y1] = self.0;
        let r = Self([x0, y0, x1.min(size.0), y1.min(size.1)]);
        if r.is_empty() { Self::EMPTY } else { r }
    }
}

/// Converts one row of the colour target's texels (`texel` bytes each) to premultiplied RGBA.
fn color_row(texel: u32, row: &[u8], out: &mut [[f32; 4]]) {
    if texel == 16 {
        match bytemuck::try_cast_slice::<u8, [f32; 4]>(row) {
            Ok(texels) if cfg!(target_endian = "little") => out.copy_from_slice(texels),
            _ => {
                for (o, p) in out.iter_mut().zip(row.chunks_exact(16)) {
                    *o = std::array::from_fn(|c| {
                        f32::from_le_bytes([p[4 * c], p[4 * c + 1], p[4 * c + 2], p[4 * c + 3]])
                    });
                }
            }
        }
    } else {
        for (o, p) in out.iter_mut().zip(row.chunks_exact(8)) {
            *o = std::array::from_fn(|c| f16_to_f32(u16::from_le_bytes([p[2 * c], p[2 * c + 1]])));
        }
    }
}

/// An IEEE half-precision float, given by its bits, as f32 (exact: every half is an f32).
///
/// The exponent and mantissa are moved into f32 position and the result scaled by 2^112, the
/// difference of the two exponent biases, which also gives subnormal halves their value;
/// infinities and NaNs keep an all-ones exponent. No branch on the value, so a frame's worth
/// vectorises: twice as fast as `half::f16::to_f32` on CPUs whose f16c instructions the build
/// does not assume.
#[inline]
fn f16_to_f32(h: u16) -> f32 {
    let h = u32::from(h);
    let magnitude = f32::from_bits((h & 0x7fff) << 13) * f32::from_bits(0x7780_0000);
    let special = if h & 0x7c00 == 0x7c00 { 0x7f80_0000 } else { 0 };
    f32::from_bits(magnitude.to_bits() | special | (h & 0x8000) << 16)
}

/// Bytes of one row in a readback buffer: the texels, padded to wgpu's row alignment.
fn padded_row(width: u32, bytes_per_texel: u32) -> u32 {
    let row = width * bytes_per_texel;
    row.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT
}

/// Bytes of a readback buffer for a `width` x `height` texture.
fn readback_bytes(width: u32, height: u32, bytes_per_texel: u32) -> u64 {
    u64::from(padded_row(width, bytes_per_texel)) * u64::from(height)
}

/// Copies a 2D texture to the CPU with rows packed tightly (`bytes_per_texel` each).
pub fn read_texture(
    ctx: &GpuContext,
    texture: &wgpu::Texture,
    aspect: wgpu::TextureAspect,
    bytes_per_texel: u32,
) -> Result<Vec<u8>, RenderError> {
    let (width, height) = (texture.width(), texture.height());
    let mut out = Vec::with_capacity((width * bytes_per_texel * height) as usize);
    let whole = PixelRect::whole((width, height));
    read_regions(
        ctx,
        &[(texture, aspect, bytes_per_texel, whole)],
        |_, row| {
            out.extend_from_slice(row);
        },
    )?;
    Ok(out)
}

/// Copies a rectangle of each of `textures` (a texture, its aspect, the bytes of its texels
/// and the rectangle: on its image, not empty, the whole image for a depth texture) to a
/// buffer, all in one submission and one wait, then hands each row to `each_row` with the
/// texture's index: texture by texture, top to bottom, from the mapped buffers (the padding
/// left out).
fn read_regions(
    ctx: &GpuContext,
    textures: &[(&wgpu::Texture, wgpu::TextureAspect, u32, PixelRect)],
    mut each_row: impl FnMut(usize, &[u8]),
) -> Result<(), RenderError> {
    let depth_copies = ctx
        .adapter
        .get_downlevel_capabilities()
        .flags
        .contains(wgpu::DownlevelFlags::DEPTH_TEXTURE_AND_BUFFER_COPIES);
    if !depth_copies
        && textures
            .iter()
            .any(|(_, aspect, _, _)| *aspect == wgpu::TextureAspect::DepthOnly)
    {
        return Err(RenderError::Unsupported {
            adapter: ctx.describe(),
            what: "copy a depth texture to memory (screenshots read the depth back)",
        });
    }
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    let buffers: Vec<(wgpu::Buffer, u32, u32)> = textures
        .iter()
        .map(|&(texture, aspect, bytes_per_texel, rect)| {
            let [x0, y0, x1, y1] = rect.0;
            let (width, height) = (x1 - x0, y1 - y0);
            let padded = padded_row(width, bytes_per_texel);
            let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("readback"),
                size: readback_bytes(width, height, bytes_per_texel),
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            });
            encoder.copy_texture_to_buffer(
                wgpu::TexelCopyTextureInfo {
                    texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d { x: x0, y: y0, z: 0 },
                    aspect,
                },
                wgpu::TexelCopyBufferInfo {
                    buffer: &buffer,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(padded),
                        rows_per_image: Some(height),
                    },
                },
                wgpu::Extent3d {
                    width,
                    height,
                    depth_or_array_layers: 1,
                },
            );
            (buffer, padded, width * bytes_per_texel)
        })
        .collect();
    ctx.queue.submit([encoder.finish()]);
    let (sender, receiver) = std::sync::mpsc::channel();
    for (buffer, _, _) in &buffers {
        let sender = sender.clone();
        buffer.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = sender.send(r);
        });
    }
    drop(sender);
    ctx.wait()?;
    for _ in &buffers {
        receiver
            .recv()
            .map_err(|e| RenderError::Readback(e.to_string()))?
            .map_err(|e| RenderError::Readback(e.to_string()))?;
    }
    for (i, (buffer, padded, row)) in buffers.iter().enumerate() {
        let mapped = buffer
            .get_mapped_range(..)
            .map_err(|e| RenderError::Readback(e.to_string()))?;
        for r in mapped.chunks_exact(*padded as usize) {
            each_row(i, &r[..*row as usize]);
        }
        drop(mapped);
        buffer.unmap();
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::f16_to_f32;

    /// Every one of the 65,536 halves converts as the `half` crate converts it, bit for bit
    /// (any NaN to a NaN).
    #[test]
    fn every_half_converts_exactly() {
        for h in 0..=u16::MAX {
            let (ours, theirs) = (f16_to_f32(h), half::f16::from_bits(h).to_f32());
            assert!(
                ours.to_bits() == theirs.to_bits() || (ours.is_nan() && theirs.is_nan()),
                "{h:#06x}: {ours} against {theirs}"
            );
        }
    }
}
