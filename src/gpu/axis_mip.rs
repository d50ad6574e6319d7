//! Axis-aligned MIP kernel (shaders/axis_mip.wgsl): the first compute kernel, used by the app's
//! overview image and as the compute round trip test. Its CPU twin is `cpu_twin`.

use crate::gpu::{GpuContext, GpuVolume, shaders};

/// Mirrors `Params` in axis_mip.wgsl (keep in sync).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    dims: [u32; 3],
    axis: u32,
    out_size: [u32; 2],
    window_lo: f32,
    window_hi: f32,
}
const _: () = assert!(std::mem::size_of::<Params>() == 32);

/// The two pipelines of the kernel.
pub struct AxisMip {
    project: wgpu::ComputePipeline,
    colorize: wgpu::ComputePipeline,
}

/// A projection on the GPU: the raw maxima and a windowed rgba8 image of them.
pub struct AxisMipOutput {
    pub mip: wgpu::Buffer,
    pub texture: wgpu::Texture,
    pub view: wgpu::TextureView,
    pub size: [u32; 2],
}

/// Width and height of the projection along `axis` (0, 1, 2) of a volume of `dims`.
pub fn out_size(dims: [u32; 3], axis: usize) -> [u32; 2] {
    match axis {
        0 => [dims[1], dims[2]],
        1 => [dims[0], dims[2]],
        _ => [dims[0], dims[1]],
    }
}

impl AxisMip {
    pub fn new(ctx: &GpuContext) -> Result<Self, shaders::ShaderSourceError> {
        let module = shaders::create_module(&ctx.device, "axis_mip.wgsl")?;
        let make = |entry: &str| {
            ctx.device
                .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(entry),
                    layout: None,
                    module: &module,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    cache: None,
                })
        };
        Ok(Self {
            project: make("project"),
            colorize: make("colorize"),
        })
    }

    /// Projects `volume` along `axis` and windows it to [window_lo, window_hi].
    pub fn run(
        &self,
        ctx: &GpuContext,
        volume: &GpuVolume,
        axis: usize,
        window: (f32, f32),
    ) -> AxisMipOutput {
        let device = &ctx.device;
        let size = out_size(volume.dims, axis);
        let params = Params {
            dims: volume.dims,
            axis: axis.min(2) as u32,
            out_size: size,
            window_lo: window.0,
            window_hi: window.1,
        };
        let params_buf = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("axis_mip params"),
            size: std::mem::size_of::<Params>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        ctx.queue
            .write_buffer(&params_buf, 0, bytemuck::bytes_of(&params));
        let mip = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("axis_mip values"),
            size: u64::from(size[0]) * u64::from(size[1]) * 4,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("axis_mip image"),
            size: wgpu::Extent3d {
                width: size[0],
                height: size[1],
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba8Unorm,
            usage: wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());

        let project_bg = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("axis_mip project"),
            layout: &self.project.get_bind_group_layout(0),
            entries: &[
                entry(0, params_buf.as_entire_binding()),
                entry(1, volume.buffer.as_entire_binding()),
                entry(2, mip.as_entire_binding()),
            ],
        });
        let colorize_bg = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("axis_mip colorize"),
            layout: &self.colorize.get_bind_group_layout(0),
            entries: &[
                entry(0, params_buf.as_entire_binding()),
                entry(2, mip.as_entire_binding()),
                entry(3, wgpu::BindingResource::TextureView(&view)),
            ],
        });
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("axis_mip"),
        });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("axis_mip"),
                timestamp_writes: None,
            });
            let groups = [size[0].div_ceil(8), size[1].div_ceil(8)];
            pass.set_pipeline(&self.project);
            pass.set_bind_group(0, &project_bg, &[]);
            pass.dispatch_workgroups(groups[0], groups[1], 1);
            pass.set_pipeline(&self.colorize);
            pass.set_bind_group(0, &colorize_bg, &[]);
            pass.dispatch_workgroups(groups[0], groups[1], 1);
        }
        ctx.queue.submit([encoder.finish()]);
        AxisMipOutput {
            mip,
            texture,
            view,
            size,
        }
    }
}

fn entry(binding: u32, resource: wgpu::BindingResource<'_>) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry { binding, resource }
}

/// The CPU twin: the maximum of every line along `axis`, image u along the first remaining axis.
pub fn cpu_twin(values: &[f32], dims: [usize; 3], axis: usize) -> Vec<f32> {
    let [nx, ny, _] = dims;
    let size = out_size(dims.map(|d| d as u32), axis).map(|s| s as usize);
    let mut out = vec![f32::NEG_INFINITY; size[0] * size[1]];
    for v in 0..size[1] {
        for u in 0..size[0] {
            let mut m = f32::NEG_INFINITY;
            for t in 0..dims[axis.min(2)] {
                let (i, j, k) = match axis {
                    0 => (t, u, v),
                    1 => (u, t, v),
                    _ => (u, v, t),
                };
                m = m.max(values[i + nx * (j + ny * k)]);
            }
            out[u + size[0] * v] = m;
        }
    }
    out
}
