use crate::TraceError;

/// How to install the CPU Vulkan driver, said wherever no adapter is found.
pub const INSTALL_HINT: &str = "no Vulkan adapter found: install the CPU driver with \
`apt-get install -y libvulkan1 mesa-vulkan-drivers` (select it with \
VK_DRIVER_FILES=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json) or a GPU driver";

/// A wgpu device and queue, and what adapter they came from.
///
/// Acquiring a device is separate from rendering, so callers (and tests) can bring their own.
#[derive(Debug)]
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
}

impl GpuContext {
    /// Opens the adapter wgpu prefers among Vulkan, Metal and DX12 (never OpenGL: hush does not
    /// fall back silently). `WGPU_BACKEND` narrows the backends; `HUSH_ADAPTER=<substring>`
    /// demands an adapter whose name contains the substring and fails otherwise.
    pub fn new() -> Result<GpuContext, TraceError> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        let allowed = wgpu::Backends::VULKAN | wgpu::Backends::METAL | wgpu::Backends::DX12;
        desc.backends = wgpu::Backends::from_env().unwrap_or(allowed) & allowed;
        let instance = wgpu::Instance::new(desc);
        let adapter = match std::env::var("HUSH_ADAPTER") {
            Ok(want) => {
                let all = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
                let names: Vec<String> = all.iter().map(|a| a.get_info().name).collect();
                all.into_iter().find(|a| a.get_info().name.contains(&want)).ok_or_else(|| {
                    TraceError::NoAdapter(format!("HUSH_ADAPTER={want} matches none of the adapters {names:?}"))
                })?
            }
            Err(_) => pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                force_fallback_adapter: false,
                ..Default::default()
            }))
            .map_err(|_| TraceError::NoAdapter(INSTALL_HINT.to_string()))?,
        };
        let info = adapter.get_info();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("hush"),
            required_features: wgpu::Features::empty(),
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .map_err(|e| TraceError::Gpu(format!("cannot open a device on {}: {e}", info.name)))?;
        Ok(GpuContext { device, queue, info })
    }

    /// One line naming the adapter, its driver and backend, e.g. for logs and reports.
    pub fn describe(&self) -> String {
        let i = &self.info;
        format!("{} ({} {}) [{:?}, {:?}]", i.name, i.driver, i.driver_info, i.backend, i.device_type)
    }

    /// Whether the adapter is a CPU implementation (such as lavapipe).
    pub fn is_cpu(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }
}
