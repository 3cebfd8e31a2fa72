//! Headless device setup: one instance, adapter, device and queue that every
//! path of this crate shares. Creating a device costs 55-100 ms on lavapipe,
//! so callers keep one [`GpuContext`] alive.

use crate::{Error, Result};

/// An open GPU device and what we learnt about it.
pub struct GpuContext {
    /// The adapter the device was opened on.
    pub adapter: wgpu::Adapter,
    /// The device every pipeline and texture of this crate is made on.
    pub device: wgpu::Device,
    /// The device's one queue: uploads, passes and readbacks all go through it.
    pub queue: wgpu::Queue,
    /// Name, driver and backend, printed with every benchmark so figures say
    /// what they were measured on.
    pub info: wgpu::AdapterInfo,
    /// Whether the device was opened with timestamp queries (benchmarks).
    pub timestamps: bool,
    /// The limits the device was opened with: the largest 3D texture bounds the
    /// distance maps this device can take.
    pub limits: wgpu::Limits,
}

impl std::fmt::Debug for GpuContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuContext")
            .field("info", &self.info)
            .finish_non_exhaustive()
    }
}

impl GpuContext {
    /// Opens the default adapter without a window. Backends come from
    /// `WGPU_BACKEND` when set (`vulkan` avoids the GL probe's noise on
    /// lavapipe machines).
    pub fn new_headless() -> Result<Self> {
        pollster::block_on(Self::open())
    }

    /// Opens an adapter of `instance` that can present to `surface` (the
    /// viewer's window).
    pub fn for_surface(instance: &wgpu::Instance, surface: &wgpu::Surface) -> Result<Self> {
        pollster::block_on(Self::open_with(instance, Some(surface)))
    }

    async fn open() -> Result<Self> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        Self::open_with(&instance, None).await
    }

    async fn open_with(
        instance: &wgpu::Instance,
        surface: Option<&wgpu::Surface<'_>>,
    ) -> Result<Self> {
        let adapter = instance
            .request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                compatible_surface: surface,
                ..Default::default()
            })
            .await
            .map_err(|e| Error::NoAdapter(e.to_string()))?;
        let info = adapter.get_info();
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let mut required_features = wgpu::Features::empty();
        if timestamps {
            required_features |= wgpu::Features::TIMESTAMP_QUERY;
        }
        // Big distance maps need the adapter's real 3D texture and buffer
        // limits, not WebGPU's portable defaults.
        let limits = adapter.limits();
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("displace"),
                required_features,
                required_limits: limits.clone(),
                ..Default::default()
            })
            .await
            .map_err(|e| Error::Device {
                adapter: info.name.clone(),
                message: e.to_string(),
            })?;
        Ok(Self {
            adapter,
            device,
            queue,
            info,
            timestamps,
            limits,
        })
    }

    /// One line naming the adapter, for logs and benchmark headers.
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?}, driver {} {})",
            self.info.name,
            self.info.backend,
            self.info.device_type,
            self.info.driver,
            self.info.driver_info
        )
    }

    /// True for software rasterisers (lavapipe): their timings say nothing
    /// about a GPU.
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    /// Runs `f` inside validation and out-of-memory error scopes and turns
    /// a captured error into [`Error::Gpu`], so shader or binding mistakes
    /// and allocations the device cannot make surface as errors rather than
    /// as the default handler's panic.
    pub fn checked<T>(&self, during: &str, f: impl FnOnce() -> T) -> Result<T> {
        let memory = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let out = f();
        let validation = pollster::block_on(validation.pop());
        let memory = pollster::block_on(memory.pop());
        match validation.or(memory) {
            None => Ok(out),
            Some(e) => Err(Error::Gpu {
                during: during.to_string(),
                message: e.to_string(),
            }),
        }
    }

    /// Blocks until the queue is idle.
    pub fn wait(&self) -> Result<()> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| Error::Gpu {
                during: "waiting for the queue".into(),
                message: e.to_string(),
            })
    }

    /// Copies `buffer` (MAP_READ) back to the host.
    pub fn read_buffer(&self, buffer: &wgpu::Buffer) -> Result<Vec<u8>> {
        let slice = buffer.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.wait()?;
        rx.recv()
            .map_err(|e| Error::Gpu {
                during: "mapping a readback buffer".into(),
                message: e.to_string(),
            })?
            .map_err(|e| Error::Gpu {
                during: "mapping a readback buffer".into(),
                message: e.to_string(),
            })?;
        let bytes = slice.get_mapped_range().to_vec();
        buffer.unmap();
        Ok(bytes)
    }
}
