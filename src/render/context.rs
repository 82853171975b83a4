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

    /// Whether this machine may hold a hardware GPU for wgpu to find. On Linux a GPU driver is
    /// reached through device files (DRM's `/dev/dri/*`, NVIDIA's `/dev/nvidia*`, WSL's
    /// `/dev/dxg`, AMD's `/dev/kfd`); where none exists, the only adapter wgpu could find is a CPU (Mesa's
    /// lavapipe or llvmpipe), so the CPU tiles can be chosen without looking: the look loads
    /// lavapipe, which then holds about 50 MB of LLVM's code for the rest of the run, even
    /// with every wgpu object dropped. Elsewhere, and where a device file exists, true: the
    /// adapter must be looked at.
    pub fn hardware_may_exist() -> bool {
        cfg!(not(target_os = "linux")) || gpu_device_files_in(std::path::Path::new("/dev"))
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

/// Whether folder `dev` (a Linux `/dev`) holds a device file through which a GPU driver is
/// reached: anything in `dri/` (DRM's render and card nodes: AMD, Intel, NVIDIA's open and
/// virtual GPUs), an `nvidia*` file (NVIDIA's driver), `dxg` (WSL's GPU) or `kfd` (AMD's
/// compute). A folder that cannot be read counts as holding one, so that the adapter is
/// looked at.
fn gpu_device_files_in(dev: &std::path::Path) -> bool {
    let Ok(entries) = std::fs::read_dir(dev) else {
        return true;
    };
    entries.flatten().any(|entry| {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        match name.as_ref() {
            "dri" => std::fs::read_dir(entry.path()).map_or(true, |mut d| d.next().is_some()),
            "dxg" | "kfd" => true,
            other => other.starts_with("nvidia"),
        }
    })
}

#[cfg(test)]
mod tests {
    use super::gpu_device_files_in;
    use crate::scratch::scratch;

    #[test]
    fn a_gpu_is_looked_for_where_a_gpu_device_file_exists() {
        let dev = scratch("dev");
        // A container's /dev: no GPU.
        for name in ["null", "zero", "tty", "shm", "pts", "nvme0n1", "fuse"] {
            std::fs::write(dev.join(name), b"").unwrap();
        }
        assert!(!gpu_device_files_in(&dev));
        // An empty dri folder (a display left with no node) holds no GPU.
        std::fs::create_dir(dev.join("dri")).unwrap();
        assert!(!gpu_device_files_in(&dev));
        std::fs::write(dev.join("dri/renderD128"), b"").unwrap();
        assert!(gpu_device_files_in(&dev));
        for (name, gpu) in [
            ("nvidiactl", true),
            ("nvidia0", true),
            ("dxg", true),
            ("kfd", true),
        ] {
            let other = scratch("dev");
            std::fs::write(other.join(name), b"").unwrap();
            assert_eq!(gpu_device_files_in(&other), gpu, "{name}");
        }
        // A folder that cannot be read: looked at.
        assert!(gpu_device_files_in(&dev.join("no-such-folder")));
    }
}
