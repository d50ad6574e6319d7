//! Separable Gaussian and Gaussian-derivative passes in mm (shaders/gaussian.wgsl): one 1-D
//! correlation along one axis of a slab per dispatch, replicated borders, taps from the CPU
//! twin's own [`crate::cpu::derivative_kernel`] (same taps, including the tail mass on the end
//! taps), so the GPU and `crate::cpu::gaussian` compute the same sums (f32 against f64).
//!
//! Taps are uploaded once per (sigma, spacing, order) as an [`AxisTaps`] (or several orders of
//! one axis as an [`AxisTapSet`]) and reused for every slab; [`Gaussian::record_pass`] (an
//! [`AxisPass`]) and [`Gaussian::record_separable`] only record into the caller's encoder (no
//! submit).
//!
//! Speed (lavapipe, where every storage-buffer load or store is a per-lane scalar loop): each
//! invocation of the block kernels computes [`BLOCK`] consecutive outputs along the pass axis from
//! one sliding window of inputs, so a pass costs about `(BLOCK + 2 radius) / BLOCK` loads per
//! voxel instead of `2 radius + 1`, with the taps in a uniform array;
//! [`Gaussian::record_pass`] with a [`PassKernels::Set`] applies up to three kernels of one axis (e.g. orders 0, 1, 2)
//! in one read of the input. Kernels longer than [`MAX_TAPS`] fall back to one output per
//! invocation with the taps in a storage buffer.

use crate::cpu::gaussian::{GaussianOrder, derivative_kernel, kernel_radius_vox, tap_sum};
use crate::gpu::checks::{self, RecordError};
use crate::gpu::kernel::{Recorder, SlabGrid, WORKGROUP};
use crate::gpu::{GpuContext, shaders};
use std::ops::Range;

/// Mirrors `Params` in gaussian.wgsl (keep in sync).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    dims: [u32; 3],
    axis: u32,
    radius: u32,
    outputs: u32,
    lo: [u32; 3],
    hi: [u32; 3],
    tap_sum: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<Params>() == 64);

/// A box of a slab's voxels, `[x, y, z]` ranges: the outputs one dispatch of a pass computes.
pub type Region = [Range<u32>; 3];

/// The whole slab `grid`.
pub fn whole(grid: &SlabGrid) -> Region {
    grid.dims.map(|n| 0..n)
}

/// The axis across which a pass along `axis` may be cut into parts (z for the x and y passes,
/// y for the z pass): each part is a range of lines of the pass, whose outputs depend on those
/// lines only, so a pass recorded in parts gives the same bits as in one dispatch (the feature
/// job's paced steps). Any [`Region`] of a pass gives the bits of the whole slab's pass inside
/// it: the block kernels keep their blocks aligned to the line.
pub fn cut_axis(axis: usize) -> usize {
    if axis == 2 { 1 } else { 2 }
}

/// Outputs per invocation of `convolve_block` along the pass axis (`BLOCK` in gaussian.wgsl).
pub const BLOCK: u32 = 16;
/// Outputs per invocation of `convolve_block3` (`BLOCK3` in gaussian.wgsl).
pub const BLOCK3: u32 = 12;
/// Taps the block kernels' uniform array holds (`MAX_TAPS` in gaussian.wgsl): radius <= 127.
pub const MAX_TAPS: usize = 256;

/// The uniform array of the block kernels: `MAX_TAPS` vec4, kernel `c` in component `c`, or
/// `None` when a kernel is too long for it.
fn uniform_taps(ctx: &GpuContext, kernels: &[&[f64]], radius: usize) -> Option<wgpu::Buffer> {
    if 2 * radius + 1 > MAX_TAPS || kernels.len() > 4 {
        return None;
    }
    let mut data = vec![0.0f32; 4 * MAX_TAPS];
    for (c, k) in kernels.iter().enumerate() {
        // Centred kernels of any radius <= `radius`, zero-padded to it.
        let pad = radius.checked_sub(k.len() / 2)?;
        for (t, &w) in k.iter().enumerate() {
            data[4 * (t + pad) + c] = w as f32;
        }
    }
    use wgpu::util::DeviceExt as _;
    Some(
        ctx.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("gaussian taps (uniform)"),
                contents: bytemuck::cast_slice(&data),
                usage: wgpu::BufferUsages::UNIFORM,
            }),
    )
}

/// One 1-D kernel on the GPU: `2 radius + 1` f32 taps for offsets `-radius..=radius`.
#[derive(Debug)]
pub struct AxisTaps {
    /// Storage buffer (the fallback kernel).
    buffer: wgpu::Buffer,
    /// Uniform array (the block kernel), when the kernel fits.
    uniform: Option<wgpu::Buffer>,
    radius: u32,
    sum: f32,
}

impl AxisTaps {
    /// The CPU twin's kernel of `order` for `sigma_mm` on an axis of `spacing_mm` (per mm),
    /// multiplied by `scale` (e.g. sigma^2 for the gamma-normalised Hessian, folded into one
    /// pass; 1 otherwise).
    pub fn new(
        ctx: &GpuContext,
        sigma_mm: f64,
        spacing_mm: f64,
        order: GaussianOrder,
        scale: f64,
    ) -> Self {
        Self::from_weights(ctx, &scaled_kernel(sigma_mm, spacing_mm, order, scale))
    }

    /// Any odd-length centred kernel (correlation weights for offsets `-r..=r`).
    pub fn from_weights(ctx: &GpuContext, weights: &[f64]) -> Self {
        let taps: Vec<f32> = weights.iter().map(|&w| w as f32).collect();
        let sum = tap_sum(weights) as f32;
        let radius = weights.len() / 2;
        Self {
            buffer: crate::gpu::kernel::f32_buffer_init(&ctx.device, "gaussian taps", &taps),
            uniform: uniform_taps(ctx, &[weights], radius),
            radius: radius as u32,
            sum,
        }
    }

    /// Kernel radius in voxels (the halo one pass along this axis needs).
    pub fn radius(&self) -> u32 {
        self.radius
    }

    /// Loads and stores per output voxel of a pass with this kernel.
    pub fn accesses_per_voxel(&self) -> f64 {
        Gaussian::accesses_per_voxel(self.radius, 1, self.uniform.is_some())
    }
}

fn scaled_kernel(sigma_mm: f64, spacing_mm: f64, order: GaussianOrder, scale: f64) -> Vec<f64> {
    derivative_kernel(sigma_mm, spacing_mm, order)
        .into_iter()
        .map(|v| v * scale)
        .collect()
}

/// The kernels of orders 0, 1 and 2 of one axis (same sigma, spacing and scale), each usable
/// alone ([`Self::order`]) and all together by [`Gaussian::record_pass`], which reads the
/// input once for up to three of them.
#[derive(Debug)]
pub struct AxisTapSet {
    orders: [AxisTaps; 3],
    /// The three kernels in components x, y, z, zero-padded to the longest.
    packed: Option<wgpu::Buffer>,
    radius: u32,
    sums: [f32; 3],
}

impl AxisTapSet {
    /// Orders 0, 1, 2 for `sigma_mm` on an axis of `spacing_mm`, times `scale`.
    pub fn new(ctx: &GpuContext, sigma_mm: f64, spacing_mm: f64, scale: f64) -> Self {
        const ORDERS: [GaussianOrder; 3] = [
            GaussianOrder::Smooth,
            GaussianOrder::First,
            GaussianOrder::Second,
        ];
        let w = ORDERS.map(|o| scaled_kernel(sigma_mm, spacing_mm, o, scale));
        let radius = w.iter().map(|k| k.len() / 2).max().unwrap_or(0);
        Self {
            packed: uniform_taps(ctx, &[&w[0], &w[1], &w[2]], radius),
            radius: radius as u32,
            sums: std::array::from_fn(|o| tap_sum(&w[o]) as f32),
            orders: std::array::from_fn(|o| AxisTaps::from_weights(ctx, &w[o])),
        }
    }

    /// The kernel of one order (0, 1 or 2; larger values give order 2).
    pub fn order(&self, order: usize) -> &AxisTaps {
        &self.orders[order.min(2)]
    }

    /// The longest radius of the three kernels.
    pub fn radius(&self) -> u32 {
        self.radius
    }

    /// Loads and stores per output voxel of [`Gaussian::record_pass`] with `outputs`
    /// kernels of this set.
    pub fn accesses_per_voxel(&self, outputs: usize) -> f64 {
        match (&self.packed, outputs) {
            (Some(_), 2..) => Gaussian::accesses_per_voxel(self.radius, outputs, true),
            _ => (0..outputs.min(3))
                .map(|o| self.orders[o].accesses_per_voxel())
                .sum(),
        }
    }
}

/// Three 1-D kernels (x, y, z) of one separable filter: smoothing or a derivative with per-axis
/// orders, for `sigma_mm` on a grid of `spacing_mm` (anisotropic: per-axis sigma in voxels).
#[derive(Debug)]
pub struct SeparableKernel {
    pub axes: [AxisTaps; 3],
}

impl SeparableKernel {
    /// Derivative of `orders` (x, y, z) at `sigma_mm`, per mm.
    pub fn new(
        ctx: &GpuContext,
        sigma_mm: f64,
        spacing_mm: [f64; 3],
        orders: [GaussianOrder; 3],
    ) -> Self {
        Self {
            axes: std::array::from_fn(|a| {
                AxisTaps::new(ctx, sigma_mm, spacing_mm[a], orders[a], 1.0)
            }),
        }
    }

    /// Plain Gaussian smoothing at `sigma_mm` (as [`crate::cpu::gaussian_smooth`]).
    pub fn smooth(ctx: &GpuContext, sigma_mm: f64, spacing_mm: [f64; 3]) -> Self {
        Self::new(ctx, sigma_mm, spacing_mm, [GaussianOrder::Smooth; 3])
    }
}

/// Slices of halo a Gaussian (or Gaussian-derivative) pass of `sigma_mm` along z needs on each
/// side of a slab, for z spacing `spacing_z_mm`: the kernel radius (3 sigma + 1 voxel; the
/// central difference's 1 voxel when `sigma_mm <= 0`).
pub fn halo_slices(sigma_mm: f64, spacing_z_mm: f64) -> u32 {
    let sigma_vox = sigma_mm / spacing_z_mm;
    if sigma_vox > 0.0 {
        u32::try_from(kernel_radius_vox(sigma_vox)).unwrap_or(u32::MAX)
    } else {
        1
    }
}

/// Bytes per slab voxel of the working buffers of a separable filter besides its input: the
/// output and one temporary, f32 each.
pub const SEPARABLE_BYTES_PER_VOXEL: u64 = 8;

/// The convolution pipelines.
pub struct Gaussian {
    /// One output per invocation, storage taps (kernels longer than [`MAX_TAPS`]).
    fallback: wgpu::ComputePipeline,
    block: wgpu::ComputePipeline,
    block3: wgpu::ComputePipeline,
    /// Bound to the outputs `convolve_block3` does not write.
    unused: wgpu::Buffer,
}

/// The kernels of a pass: one, or up to three of one axis applied in one read of the input.
#[derive(Clone, Copy, Debug)]
pub enum PassKernels<'a> {
    One(&'a AxisTaps),
    Set(&'a AxisTapSet),
}

/// One convolution pass along `axis` of the slab `grid`: `dst[o] = src (*) kernel o` (one
/// output for [`PassKernels::One`], one to three for [`PassKernels::Set`]), replicated borders.
#[derive(Clone, Copy, Debug)]
pub struct AxisPass<'a> {
    pub grid: &'a SlabGrid,
    /// 0, 1 or 2.
    pub axis: usize,
    /// The outputs written, a box of the slab (`None`: all of it); the rest of `dst` is left as
    /// it is, and the inputs are read wherever the kernel reaches.
    pub region: Option<&'a Region>,
    pub kernels: PassKernels<'a>,
    /// `grid.len()` f32, different from every output.
    pub src: &'a wgpu::Buffer,
    /// `grid.len()` f32 each, all different buffers.
    pub dst: &'a [&'a wgpu::Buffer],
}

/// Which kernel a pass applies: the bindings and uniforms that differ between passes.
struct PassTaps<'a> {
    storage: Option<&'a wgpu::Buffer>,
    uniform: Option<&'a wgpu::Buffer>,
    radius: u32,
    sums: [f32; 4],
}

impl Gaussian {
    pub fn new(ctx: &GpuContext) -> Result<Self, shaders::ShaderSourceError> {
        let [fallback, block, block3] = checks::pipelines(
            ctx,
            "gaussian.wgsl",
            ["convolve", "convolve_block", "convolve_block3"],
        )?;
        Ok(Self {
            fallback,
            block,
            block3,
            unused: crate::gpu::kernel::f32_buffer(&ctx.device, "gaussian unused output", 4),
        })
    }

    fn check_pass(
        ctx: &GpuContext,
        grid: &SlabGrid,
        axis: usize,
        region: &Region,
        src: &wgpu::Buffer,
        dst: &[&wgpu::Buffer],
    ) -> Result<(), RecordError> {
        if axis > 2 {
            return Err(RecordError::Invalid("axis must be 0, 1 or 2"));
        }
        if (0..3).any(|a| region[a].start > region[a].end || region[a].end > grid.dims[a]) {
            return Err(RecordError::Invalid(
                "a convolution's part must lie within the slab",
            ));
        }
        if dst.contains(&src) {
            return Err(RecordError::Invalid(
                "a convolution cannot run in place (src == dst)",
            ));
        }
        checks::distinct(dst, "a convolution's outputs must be different buffers")?;
        if grid.is_empty() {
            return Ok(());
        }
        let bytes = checks::f32_bytes(grid.len(), 1);
        checks::buffer(ctx, "gaussian src", src, bytes)?;
        for d in dst {
            checks::buffer(ctx, "gaussian dst", d, bytes)?;
        }
        Ok(())
    }

    /// Records one dispatch of `pass` over `region`: the block kernel (`outputs` 1:
    /// `convolve_block`, 2 or 3: `convolve_block3`) when `taps.uniform` is there, else the
    /// fallback (one output).
    fn dispatch(
        &self,
        rec: &mut Recorder<'_>,
        pass: &AxisPass<'_>,
        region: &Region,
        taps: &PassTaps<'_>,
    ) -> Result<(), RecordError> {
        let (ctx, grid, axis, src, dst) = (rec.ctx, pass.grid, pass.axis, pass.src, pass.dst);
        let params = Params {
            dims: grid.dims,
            axis: axis as u32,
            radius: taps.radius,
            outputs: dst.len() as u32,
            lo: region.clone().map(|r| r.start),
            hi: region.clone().map(|r| r.end),
            tap_sum: taps.sums,
        };
        let params = crate::gpu::kernel::params_buffer(&ctx.device, "gaussian params", &params);
        // The dispatch spans the box only.
        let d: [u32; 3] = std::array::from_fn(|a| region[a].len() as u32);
        // (a, b) = the other two axes, the faster first (b is the cut axis).
        let (a, b) = match axis {
            0 => (d[1], d[2]),
            1 => (d[0], d[2]),
            _ => (d[0], d[1]),
        };
        // Blocks along the pass axis start at the block boundary at or below the box's start.
        let along =
            |block: u32| (region[axis].end - region[axis].start / block * block).div_ceil(block);
        let (pipeline, entries, groups) = match (taps.uniform, dst) {
            (Some(u), [d0, more @ ..]) => {
                let mut entries = vec![
                    checks::entry(0, &params),
                    checks::entry(1, src),
                    checks::entry(3, d0),
                    checks::entry(4, u),
                ];
                match more {
                    [] => (
                        &self.block,
                        entries,
                        [a.div_ceil(8), b.div_ceil(8), along(BLOCK)],
                    ),
                    [d1, rest @ ..] => {
                        entries.push(checks::entry(5, d1));
                        let d2 = rest.first().copied().unwrap_or(&self.unused);
                        entries.push(checks::entry(6, d2));
                        (
                            &self.block3,
                            entries,
                            [a.div_ceil(8), b.div_ceil(8), along(BLOCK3)],
                        )
                    }
                }
            }
            (None, [d0]) => match taps.storage {
                Some(t) => (
                    &self.fallback,
                    vec![
                        checks::entry(0, &params),
                        checks::entry(1, src),
                        checks::entry(2, t),
                        checks::entry(3, d0),
                    ],
                    SlabGrid::new(d, grid.spacing_mm).workgroups(WORKGROUP),
                ),
                None => return Err(RecordError::Invalid("gaussian: no taps for this pass")),
            },
            _ => {
                return Err(RecordError::Invalid(
                    "gaussian: one to three outputs per pass",
                ));
            }
        };
        let groups = checks::workgroups(ctx, "gaussian", groups.map(|g| g.max(1)))?;
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("gaussian"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &entries,
        });
        checks::dispatch(rec.encoder, "gaussian", pipeline, &bind_group, groups);
        Ok(())
    }

    /// Records the convolution `pass` (see [`AxisPass`]).
    pub fn record_pass(
        &self,
        rec: &mut Recorder<'_>,
        pass: &AxisPass<'_>,
    ) -> Result<(), RecordError> {
        let (grid, dst) = (pass.grid, pass.dst);
        let whole_grid = whole(grid);
        let region = pass.region.unwrap_or(&whole_grid);
        let outputs_ok = match pass.kernels {
            PassKernels::One(_) => dst.len() == 1,
            PassKernels::Set(_) => (1..=3).contains(&dst.len()),
        };
        if !outputs_ok {
            return Err(RecordError::Invalid(
                "gaussian: one to three outputs per pass, one per kernel",
            ));
        }
        Self::check_pass(rec.ctx, grid, pass.axis, region, pass.src, dst)?;
        if grid.is_empty() || region.iter().any(|r| r.is_empty()) {
            return Ok(());
        }
        match pass.kernels {
            PassKernels::One(taps) => {
                let taps = PassTaps {
                    storage: Some(&taps.buffer),
                    uniform: taps.uniform.as_ref(),
                    radius: taps.radius,
                    sums: [taps.sum, 0.0, 0.0, 0.0],
                };
                self.dispatch(rec, pass, region, &taps)
            }
            PassKernels::Set(set) => match (&set.packed, dst) {
                (Some(u), [_, _, ..]) => {
                    let taps = PassTaps {
                        storage: None,
                        uniform: Some(u),
                        radius: set.radius,
                        sums: [set.sums[0], set.sums[1], set.sums[2], 0.0],
                    };
                    self.dispatch(rec, pass, region, &taps)
                }
                // One output, or kernels too long for the uniform array: one pass per order.
                _ => dst.iter().enumerate().try_for_each(|(o, d)| {
                    self.record_pass(
                        rec,
                        &AxisPass {
                            kernels: PassKernels::One(&set.orders[o]),
                            dst: &[*d],
                            ..*pass
                        },
                    )
                }),
            },
        }
    }

    /// Loads and stores per output voxel of a pass (what a pass costs on lavapipe, where
    /// storage accesses dominate): the block kernels' sliding window reads `(B + 2 radius) / B`
    /// inputs per output (`B` = [`BLOCK`] for one kernel, [`BLOCK3`] for several), the
    /// fallback `2 radius + 1`; each output stores once.
    pub fn accesses_per_voxel(radius: u32, outputs: usize, uniform: bool) -> f64 {
        let r = f64::from(radius);
        let loads = match (uniform, outputs) {
            (false, _) => (2.0 * r + 1.0) * outputs as f64,
            (true, 1) => (f64::from(BLOCK) + 2.0 * r) / f64::from(BLOCK),
            (true, _) => (f64::from(BLOCK3) + 2.0 * r) / f64::from(BLOCK3),
        };
        loads + outputs as f64
    }

    /// Records the separable filter `kernel` (x, then y, then z, as the CPU's `separable`):
    /// `src -> dst -> tmp -> dst`. Three different buffers of `grid.len()` f32.
    pub fn record_separable(
        &self,
        rec: &mut Recorder<'_>,
        grid: &SlabGrid,
        kernel: &SeparableKernel,
        src: &wgpu::Buffer,
        tmp: &wgpu::Buffer,
        dst: &wgpu::Buffer,
    ) -> Result<(), RecordError> {
        if src == tmp || src == dst || tmp == dst {
            return Err(RecordError::Invalid(
                "separable filter: src, tmp and dst must be different buffers",
            ));
        }
        for (axis, (from, to)) in [(src, dst), (dst, tmp), (tmp, dst)].into_iter().enumerate() {
            self.record_pass(
                rec,
                &AxisPass {
                    grid,
                    axis,
                    region: None,
                    kernels: PassKernels::One(&kernel.axes[axis]),
                    src: from,
                    dst: &[to],
                },
            )?;
        }
        Ok(())
    }
}
