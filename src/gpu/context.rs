//! The one GPU context everything shares: the app takes eframe's device and queue, the CLI and
//! the tests create their own (preferring the CPU adapter, lavapipe, under tests).
//!
//! It always asks for the adapter's real limits (3D texture size, storage buffer size, workgroup
//! limits) instead of wgpu's small defaults, and for FLOAT32_FILTERABLE and TIMESTAMP_QUERY where
//! the adapter has them.

use std::fmt::Write as _;

/// Why no usable GPU context could be made.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum GpuError {
    #[error(
        "no GPU adapter found (backends tried: {backends}); install a Vulkan driver, e.g. `apt-get install mesa-vulkan-drivers` for the CPU adapter lavapipe{env_hint}"
    )]
    NoAdapter { backends: String, env_hint: String },
    #[error("the GPU adapter {adapter:?} cannot run compute shaders (downlevel flags: {flags})")]
    NoCompute { adapter: String, flags: String },
    #[error("the GPU adapter {adapter:?} refused to create a device: {source}")]
    RequestDevice {
        adapter: String,
        #[source]
        source: wgpu::RequestDeviceError,
    },
}

/// Which adapter to prefer when more than one is available.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AdapterPreference {
    /// A real GPU if there is one (the CLI).
    HighPerformance,
    /// The CPU adapter (lavapipe): deterministic and present on every CI machine (tests).
    Cpu,
}

/// Device, queue and what they can do.
#[derive(Clone, Debug)]
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub adapter_info: wgpu::AdapterInfo,
    /// The limits the device was created with (the adapter's own).
    pub limits: wgpu::Limits,
    pub features: wgpu::Features,
}

/// Features Shapecast asks for where the adapter offers them: filtering of 32-bit float
/// textures, and timestamps, which time the pacers' steps ([`super::timing`]).
pub fn wanted_features(adapter: &wgpu::Adapter) -> wgpu::Features {
    adapter.features() & (wgpu::Features::FLOAT32_FILTERABLE | wgpu::Features::TIMESTAMP_QUERY)
}

/// The device descriptor Shapecast uses everywhere: the adapter's own limits and wanted features.
pub fn device_descriptor(adapter: &wgpu::Adapter) -> wgpu::DeviceDescriptor<'static> {
    wgpu::DeviceDescriptor {
        label: Some("shapecast device"),
        required_features: wanted_features(adapter),
        required_limits: adapter.limits(),
        ..Default::default()
    }
}

impl GpuContext {
    /// Wraps a device somebody else created (eframe's), reading back what it can do.
    pub fn from_parts(
        device: wgpu::Device,
        queue: wgpu::Queue,
        adapter_info: wgpu::AdapterInfo,
    ) -> Self {
        let limits = device.limits();
        let features = device.features();
        Self {
            device,
            queue,
            adapter_info,
            limits,
            features,
        }
    }

    /// Takes eframe's wgpu device and queue.
    pub fn from_render_state(rs: &eframe::egui_wgpu::RenderState) -> Self {
        Self::from_parts(rs.device.clone(), rs.queue.clone(), rs.adapter.get_info())
    }

    /// Creates a device of its own (CLI): a real GPU preferred.
    pub async fn new_headless() -> Result<Self, GpuError> {
        Self::new_headless_with(AdapterPreference::HighPerformance).await
    }

    /// Creates a device of its own. `WGPU_BACKEND` limits the backends and `WGPU_ADAPTER_NAME`
    /// picks an adapter by (part of) its name; otherwise `preference` decides.
    pub async fn new_headless_with(preference: AdapterPreference) -> Result<Self, GpuError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pick_adapter(&instance, preference).await?;
        let info = adapter.get_info();
        let downlevel = adapter.get_downlevel_capabilities();
        if !downlevel
            .flags
            .contains(wgpu::DownlevelFlags::COMPUTE_SHADERS)
        {
            return Err(GpuError::NoCompute {
                adapter: info.name.clone(),
                flags: format!("{:?}", downlevel.flags),
            });
        }
        let (device, queue) = adapter
            .request_device(&device_descriptor(&adapter))
            .await
            .map_err(|source| GpuError::RequestDevice {
                adapter: info.name.clone(),
                source,
            })?;
        Ok(Self::from_parts(device, queue, info))
    }

    /// Whether 32-bit float textures can be sampled with linear filtering.
    pub fn float32_filterable(&self) -> bool {
        self.features.contains(wgpu::Features::FLOAT32_FILTERABLE)
    }

    /// Whether the device is the browser's WebGPU (the page), not a native one.
    pub fn in_browser(&self) -> bool {
        self.adapter_info.backend == wgpu::Backend::BrowserWebGpu
    }

    /// Whether the adapter renders on the CPU (lavapipe natively; in the browser a fallback
    /// adapter such as SwiftShader, which WebGPU reports as `isFallbackAdapter`).
    pub fn is_software(&self) -> bool {
        #[cfg(target_arch = "wasm32")]
        let name = browser_adapter_name().unwrap_or_default() + " " + &self.adapter_info.name;
        #[cfg(not(target_arch = "wasm32"))]
        let name = self.adapter_info.name.clone();
        self.adapter_info.device_type == wgpu::DeviceType::Cpu
            || name.to_lowercase().contains("swiftshader")
    }

    /// A short name of the adapter and its backend, e.g. "llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan)".
    pub fn adapter_label(&self) -> String {
        format!(
            "{} ({:?})",
            self.adapter_info.name, self.adapter_info.backend
        )
    }

    /// Natively, runs the callbacks of work the GPU finished (queue-done and map callbacks run
    /// only when the device is polled or something is submitted), without waiting; in the
    /// browser they run by themselves and this does nothing.
    pub fn poll_callbacks(&self) {
        #[cfg(not(target_arch = "wasm32"))]
        let _ = self.device.poll(wgpu::PollType::Poll);
    }

    /// A human-readable report of the adapter and the limits that matter for volumes.
    pub fn describe(&self) -> String {
        let l = &self.limits;
        let i = &self.adapter_info;
        let mut s = String::new();
        let _ = writeln!(s, "adapter:                          {}", i.name);
        let _ = writeln!(s, "backend:                          {:?}", i.backend);
        let _ = writeln!(s, "device type:                      {:?}", i.device_type);
        let _ = writeln!(
            s,
            "driver:                           {} {}",
            i.driver, i.driver_info
        );
        let _ = writeln!(
            s,
            "max_texture_dimension_3d:         {}",
            l.max_texture_dimension_3d
        );
        let _ = writeln!(
            s,
            "max_texture_dimension_2d:         {}",
            l.max_texture_dimension_2d
        );
        let _ = writeln!(s, "max_buffer_size:                  {}", l.max_buffer_size);
        let _ = writeln!(
            s,
            "max_storage_buffer_binding_size:  {}",
            l.max_storage_buffer_binding_size
        );
        let _ = writeln!(
            s,
            "max_compute_workgroup_size:       {}x{}x{}",
            l.max_compute_workgroup_size_x,
            l.max_compute_workgroup_size_y,
            l.max_compute_workgroup_size_z
        );
        let _ = writeln!(
            s,
            "max_compute_invocations_per_wg:   {}",
            l.max_compute_invocations_per_workgroup
        );
        let _ = writeln!(
            s,
            "max_compute_workgroups_per_dim:   {}",
            l.max_compute_workgroups_per_dimension
        );
        let _ = write!(
            s,
            "float32_filterable:               {}",
            self.float32_filterable()
        );
        let _ = write!(
            s,
            "\ntimestamps:                       {}",
            self.features.contains(wgpu::Features::TIMESTAMP_QUERY)
        );
        s
    }
}

async fn pick_adapter(
    instance: &wgpu::Instance,
    preference: AdapterPreference,
) -> Result<wgpu::Adapter, GpuError> {
    let env_name = std::env::var("WGPU_ADAPTER_NAME").ok();
    if env_name.is_some()
        && let Ok(a) = wgpu::util::initialize_adapter_from_env(instance, None).await
    {
        return Ok(a);
    }
    #[cfg(not(target_arch = "wasm32"))]
    if preference == AdapterPreference::Cpu {
        let adapters = instance.enumerate_adapters(wgpu::Backends::all()).await;
        if let Some(cpu) = adapters
            .into_iter()
            .find(|a| a.get_info().device_type == wgpu::DeviceType::Cpu)
        {
            return Ok(cpu);
        }
    }
    let power_preference = match preference {
        AdapterPreference::HighPerformance => wgpu::PowerPreference::HighPerformance,
        AdapterPreference::Cpu => wgpu::PowerPreference::LowPower,
    };
    instance
        .request_adapter(&wgpu::RequestAdapterOptions {
            power_preference,
            force_fallback_adapter: false,
            compatible_surface: None,
            ..Default::default()
        })
        .await
        .map_err(|_| GpuError::NoAdapter {
            backends: format!(
                "{:?}",
                wgpu::Backends::from_env().unwrap_or(wgpu::Backends::all())
            ),
            env_hint: match env_name {
                Some(n) => format!("; WGPU_ADAPTER_NAME={n:?} matched no adapter"),
                None => String::new(),
            },
        })
}

/// The device for tests: the CPU adapter (lavapipe) preferred, created once per test process.
///
/// Where there is no adapter, GPU tests may skip on a developer's machine (with a visible
/// message), but never under `CI=true`: there a missing adapter is a failure, so a broken install
/// cannot pass as green.
#[cfg(not(target_arch = "wasm32"))]
pub fn test_context() -> Option<GpuContext> {
    use std::sync::OnceLock;
    static CONTEXT: OnceLock<Result<GpuContext, String>> = OnceLock::new();
    let result = CONTEXT.get_or_init(|| {
        pollster::block_on(GpuContext::new_headless_with(AdapterPreference::Cpu))
            .map_err(|e| e.to_string())
    });
    match result {
        Ok(ctx) => Some(ctx.clone()),
        Err(e) if std::env::var("CI").is_ok_and(|v| v == "true") => {
            panic!("CI=true and no GPU adapter for the GPU tests: {e}")
        }
        Err(e) => {
            eprintln!("SKIPPED: no GPU adapter for the GPU tests ({e})");
            None
        }
    }
}

#[cfg(target_arch = "wasm32")]
thread_local! {
    static BROWSER_ADAPTER: std::cell::RefCell<Option<String>> =
        const { std::cell::RefCell::new(None) };
}

/// Web only: the adapter as the browser describes it (vendor, architecture, description), which
/// the page's entry (`crate::web`) asks `navigator.gpu` for before the app starts; wgpu's
/// `AdapterInfo` on the web carries only the often empty description.
#[cfg(target_arch = "wasm32")]
pub fn set_browser_adapter_name(name: String) {
    BROWSER_ADAPTER.with(|a| *a.borrow_mut() = Some(name));
}

/// Web only: what [`set_browser_adapter_name`] stored.
#[cfg(target_arch = "wasm32")]
pub fn browser_adapter_name() -> Option<String> {
    BROWSER_ADAPTER.with(|a| a.borrow().clone())
}

impl GpuContext {
    /// The adapter's name as the status shows it: the browser's description of it on the web
    /// ([`set_browser_adapter_name`]), wgpu's natively.
    pub fn adapter_name(&self) -> String {
        #[cfg(target_arch = "wasm32")]
        if let Some(name) = browser_adapter_name() {
            return name;
        }
        self.adapter_info.name.clone()
    }
}
