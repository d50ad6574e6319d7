//! The noise estimator's per-window part on the GPU (shaders/noise_windows.wgsl): standard
//! deviations of the in-plane 11 x 11 windows of smoothed slices, so that only a few numbers per
//! slice are read back. Twin: [`crate::cpu::tf::noise_window_sigmas`]; the median is taken on
//! the CPU over the whole volume ([`crate::cpu::tf::median`]).

use crate::cpu::tf::{NOISE_WINDOW, noise_window_counts};
use crate::gpu::kernel::Recorder;
use crate::gpu::kernel::{self, SlabGrid, params_buffer};
use crate::gpu::{GpuContext, checks, shaders};

/// Mirrors `Params` in noise_windows.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    dims: [u32; 3],
    z0: u32,
    nz: u32,
    nwx: u32,
    nwy: u32,
    w: u32,
    band_lo: f32,
    band_hi: f32,
    pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<Params>() == 48);

pub struct NoiseWindows {
    pipeline: wgpu::ComputePipeline,
}

/// Number of window values (`f32`) measuring `nz` slices of a slab writes.
pub fn output_len(slab: SlabGrid, nz: u32) -> u64 {
    let [nwx, nwy] = noise_window_counts(slab.dims.map(|d| d as usize));
    (nwx * nwy) as u64 * u64::from(nz)
}

impl NoiseWindows {
    pub fn new(ctx: &GpuContext) -> Result<Self, shaders::ShaderSourceError> {
        let module = shaders::create_module(&ctx.device, "noise_windows.wgsl")?;
        let pipeline = checks::labelled_pipeline(ctx, "noise_windows", &module, "main");
        Ok(Self { pipeline })
    }

    /// Records the window sigmas of `slices` of `smoothed` (a slab of `slab`) into `out` (at
    /// least [`output_len`] f32): a standard deviation, or -1 for a window not wholly inside
    /// `band`.
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        slab: SlabGrid,
        smoothed: &wgpu::Buffer,
        slices: std::ops::Range<u32>,
        band: (f32, f32),
        out: &wgpu::Buffer,
    ) {
        let (z0, nz) = (slices.start, slices.end.saturating_sub(slices.start));
        let [nwx, nwy] = noise_window_counts(slab.dims.map(|d| d as usize)).map(|n| n as u32);
        if nwx == 0 || nwy == 0 || nz == 0 {
            return;
        }
        let params = params_buffer(
            &rec.ctx.device,
            "noise params",
            &Params {
                dims: slab.dims,
                z0,
                nz,
                nwx,
                nwy,
                w: NOISE_WINDOW as u32,
                band_lo: band.0,
                band_hi: band.1,
                pad: [0; 2],
            },
        );
        let bind = kernel::bind_group(
            &rec.ctx.device,
            "noise windows",
            &self.pipeline,
            [
                params.as_entire_binding(),
                smoothed.as_entire_binding(),
                out.as_entire_binding(),
            ],
        );
        let groups = [nwx.div_ceil(8), nwy.div_ceil(8), nz];
        checks::dispatch(rec.encoder, "noise windows", &self.pipeline, &bind, groups);
    }

    /// The sigmas of windows inside the band, from the bytes of a readback of `out`.
    pub fn decode(bytes: &[u8]) -> Vec<f64> {
        bytemuck::pod_collect_to_vec::<u8, f32>(bytes)
            .into_iter()
            .filter(|s| *s >= 0.0)
            .map(f64::from)
            .collect()
    }
}
