//! The GPU context: instance, adapter, device and queue, headless by default.

use super::RenderError;

/// A wgpu device and queue with what was learnt about the adapter.
#[derive(Debug)]
pub struct GpuContext {
    /// The instance the adapter came from (a window surface needs it).
    pub instance: wgpu::Instance,
    /// The adapter.
    pub adapter: wgpu::Adapter,
    /// The logical device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
}

impl GpuContext {
    /// A context on whatever adapter wgpu finds, a real GPU preferred, else Mesa's software
    /// Vulkan (lavapipe) or GL. No window is needed.
    pub fn headless() -> Result<Self, RenderError> {
        pollster::block_on(Self::new(None))
    }

    /// A context whose adapter can present to `surface` when one is given.
    pub async fn new(surface: Option<&wgpu::Surface<'_>>) -> Result<Self, RenderError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        Self::with_instance(instance, surface).await
    }

    /// A context on an instance made by the caller (a window needs its display handle there).
    pub async fn with_instance(
        instance: wgpu::Instance,
        surface: Option<&wgpu::Surface<'_>>,
    ) -> Result<Self, RenderError> {
        let adapter = instance
            .request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                force_fallback_adapter: false,
                compatible_surface: surface,
                apply_limit_buckets: false,
            })
            .await
            .map_err(|e| RenderError::NoAdapter(e.to_string()))?;
        // Ask for all the adapter can do: large volumes need big buffers and textures
        // (wgpu's defaults stop at 256 MiB buffers and 2048 texels).
        let required_limits = adapter.limits();
        // Blending into 32-bit float targets where the adapter can (see `color_format`).
        let required_features = adapter.features() & wgpu::Features::FLOAT32_BLENDABLE;
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("splatscene"),
                required_features,
                required_limits,
                ..Default::default()
            })
            .await
            .map_err(|e| RenderError::Device(e.to_string()))?;
        Ok(Self {
            instance,
            adapter,
            device,
            queue,
        })
    }

    /// Adapter name, backend and device type, for reports.
    pub fn describe(&self) -> String {
        let info = self.adapter.get_info();
        format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type)
    }

    /// Waits until the GPU has finished all submitted work. The GL backend reports a timeout
    /// on long submissions, so this waits again until the queue is empty.
    pub fn wait(&self) -> Result<(), RenderError> {
        for _ in 0..600 {
            match self.device.poll(wgpu::PollType::Wait {
                submission_index: None,
                timeout: Some(std::time::Duration::from_secs(60)),
            }) {
                Ok(status) if status.wait_finished() => return Ok(()),
                Ok(_) | Err(wgpu::PollError::Timeout) => continue,
                Err(e) => return Err(RenderError::Device(e.to_string())),
            }
        }
        Err(RenderError::Device(
            "the GPU did not finish within 10 hours".into(),
        ))
    }
}
