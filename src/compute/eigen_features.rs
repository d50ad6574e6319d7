//! Eigenvalues and feature maps of a symmetric tensor field on a slab (shaders/eigen_features.wgsl):
//! six component buffers `[xx, yy, zz, xy, xz, yz]` in (the Hessian of [`crate::compute::hessian`],
//! the structure tensor of [`crate::compute::structure_tensor`]), one component-major buffer out for
//! the output slices `(out_z0, out_nz)`. Twins: `crate::cpu::features`,
//! `crate::cpu::structure_tensor`.
//!
//! Multi-scale (docs/science.md): record scale 1 with `accumulate = false`, every further scale with
//! `accumulate = true`, into the same output buffer.
//! - Features (3 components `[V, A, B]`): per voxel and feature the maximum over scales.
//! - Eigenvalues (4 components `[l0, l1, l2, norm]`): the eigenvalues of the scale whose
//!   normalised Hessian has the largest Frobenius norm; the 4th component keeps that norm so the
//!   next scale can compare (strictly larger wins, so the first scale wins a tie, as on the CPU).
//!   The caller uses the first three components and ignores the fourth.
//!
//! Frangi's default c (half the largest Frobenius norm of the normalised Hessian over the whole
//! volume, never a slab): clear a 4-byte buffer with [`EigenFeatures::record_clear_norm`],
//! record [`EigenPass::MaxNorm`] on every slab's output slices, read the `u32` back
//! and convert with [`frangi_c_from_norm_bits`].

use crate::cpu::features::FeatureMap;
use crate::gpu::checks::{self, RecordError};
use crate::gpu::kernel::{Recorder, SlabGrid, WORKGROUP};
use crate::gpu::{GpuContext, shaders};
use std::ops::Range;

/// Mirrors `Params` in eigen_features.wgsl (keep in sync).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    dims: [u32; 3],
    out_z0: u32,
    out_nz: u32,
    mode: u32,
    map: u32,
    accumulate: u32,
    frangi_c: f32,
    negate: u32,
    /// `max_norm` only: rows `[row0, n_rows]` (n_rows 0 = all).
    rows: [u32; 2],
    /// The output slices this dispatch computes, `[k0, nk]` within `out_z`.
    part: [u32; 2],
    _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<Params>() == 64);

/// How sorted eigenvalues become `[V, A, B]` (the numbers are feature_maps.wgsl's MAP_*).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Mapping {
    /// Paper eq. 1 or eq. 2.
    Map(FeatureMap),
    /// Frangi (alpha = beta = 0.5) with an explicit `c`: V bright tubes, A dark tubes, B = 0.
    Frangi { c: f64 },
}

impl Mapping {
    fn code(self) -> (u32, f32) {
        match self {
            Mapping::Map(FeatureMap::Simple) => (0, 0.0),
            Mapping::Map(FeatureMap::Li) => (1, 0.0),
            Mapping::Frangi { c } => (2, c as f32),
        }
    }
}

/// What the kernel writes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TensorOutput {
    /// `[V, A, B]` of `mapping`; `negate` maps `-l` (the structure tensor's eigenvalues are never
    /// negative and are mapped as a bright structure's would be).
    Features { mapping: Mapping, negate: bool },
    /// `[l0, l1, l2, norm]`: eigenvalues sorted by magnitude and the tensor's Frobenius norm.
    Eigen,
}

impl TensorOutput {
    /// The Hessian's features.
    pub fn hessian(mapping: Mapping) -> Self {
        Self::Features {
            mapping,
            negate: false,
        }
    }

    /// The general structure tensor's features (eq. 1 or eq. 2 of `-l`).
    pub fn structure_tensor(map: FeatureMap) -> Self {
        Self::Features {
            mapping: Mapping::Map(map),
            negate: true,
        }
    }

    /// Components in the output buffer (3 features, or 3 eigenvalues + the norm).
    pub fn components(self) -> u32 {
        match self {
            TensorOutput::Features { .. } => 3,
            TensorOutput::Eigen => 4,
        }
    }

    /// Bytes of the output buffer per output voxel.
    pub fn bytes_per_voxel(self) -> u64 {
        u64::from(self.components()) * 4
    }
}

/// Bytes per slab voxel of the six tensor component buffers this kernel reads.
pub const TENSOR_BYTES_PER_VOXEL: u64 = 6 * 4;

/// Frangi's c from the largest norm's bits: half the largest Frobenius norm.
pub fn frangi_c_from_norm_bits(bits: u32) -> f64 {
    0.5 * f64::from(f32::from_bits(bits))
}

/// A 4-byte buffer for [`EigenPass::MaxNorm`] (starts at 0 = norm 0.0).
pub fn norm_buffer(ctx: &GpuContext) -> wgpu::Buffer {
    crate::gpu::kernel::f32_buffer(&ctx.device, "largest tensor norm", 1)
}

/// The two pipelines.
pub struct EigenFeatures {
    features: wgpu::ComputePipeline,
    max_norm: wgpu::ComputePipeline,
}

impl EigenFeatures {
    pub fn new(ctx: &GpuContext) -> Result<Self, shaders::ShaderSourceError> {
        let [features, max_norm] =
            checks::pipelines(ctx, "eigen_features.wgsl", ["eigen_features", "max_norm"])?;
        Ok(Self { features, max_norm })
    }

    fn check(
        ctx: &GpuContext,
        grid: &SlabGrid,
        tensor: &[&wgpu::Buffer; 6],
        out_z: (u32, u32),
        part: &Range<u32>,
    ) -> Result<[u32; 3], RecordError> {
        let (z0, nz) = out_z;
        if z0.checked_add(nz).is_none_or(|end| end > grid.dims[2]) {
            return Err(RecordError::OutputRange {
                z0,
                nz,
                depth: grid.dims[2],
            });
        }
        if part.start > part.end || part.end > nz {
            return Err(RecordError::Invalid(
                "eigen_features: the part must lie within the output slices",
            ));
        }
        let bytes = checks::f32_bytes(grid.len(), 1);
        for t in tensor {
            checks::buffer(ctx, "tensor component", t, bytes)?;
        }
        let out_grid = SlabGrid::new(
            [grid.dims[0], grid.dims[1], part.len() as u32],
            grid.spacing_mm,
        );
        checks::workgroups(ctx, "eigen_features", out_grid.workgroups(WORKGROUP))
    }

    fn params(grid: &SlabGrid, out_z: (u32, u32), what: TensorOutput, accumulate: bool) -> Params {
        let (mode, map, c, negate) = match what {
            TensorOutput::Features { mapping, negate } => {
                let (map, c) = mapping.code();
                (0, map, c, u32::from(negate))
            }
            TensorOutput::Eigen => (1, 0, 0.0, 0),
        };
        Params {
            dims: grid.dims,
            out_z0: out_z.0,
            out_nz: out_z.1,
            mode,
            map,
            accumulate: u32::from(accumulate),
            frangi_c: c,
            negate,
            rows: [0; 2],
            part: [0, out_z.1],
            _pad: [0; 2],
        }
    }

    /// Records `pass` on the tensor `[xx, yy, zz, xy, xz, yz]` (each `grid.len()` f32) for the
    /// slab's slices `out_z = (out_z0, out_nz)`.
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        grid: &SlabGrid,
        tensor: [&wgpu::Buffer; 6],
        out_z: (u32, u32),
        pass: EigenPass<'_>,
    ) -> Result<(), RecordError> {
        let part = TensorPart {
            grid,
            tensor,
            out_z,
            slices: 0..out_z.1,
            rows: None,
        };
        self.record_part(rec, &part, pass)
    }

    /// [`Self::record`] for part of the output block ([`TensorPart`]).
    pub fn record_part(
        &self,
        rec: &mut Recorder<'_>,
        p: &TensorPart<'_>,
        pass: EigenPass<'_>,
    ) -> Result<(), RecordError> {
        let (ctx, grid, tensor, out_z, part, rows) =
            (rec.ctx, p.grid, p.tensor, p.out_z, p.slices.clone(), p.rows);
        let groups = Self::check(ctx, grid, &tensor, out_z, &part)?;
        if grid.is_empty() || part.is_empty() {
            return Ok(());
        }
        let (label, pipeline, mut params, last) = match pass {
            EigenPass::Output {
                what,
                accumulate,
                out,
            } => {
                let n_out = u64::from(grid.dims[0]) * u64::from(grid.dims[1]) * u64::from(out_z.1);
                let out_bytes = checks::f32_bytes(n_out, u64::from(what.components()));
                checks::buffer(ctx, "eigen_features output", out, out_bytes)?;
                if tensor.contains(&out) {
                    return Err(RecordError::Invalid(
                        "eigen_features: the output cannot be a tensor component",
                    ));
                }
                (
                    "eigen_features",
                    &self.features,
                    Self::params(grid, out_z, what, accumulate),
                    checks::entry(7, out),
                )
            }
            EigenPass::MaxNorm { norm_bits } => {
                checks::buffer(ctx, "largest norm", norm_bits, 4)?;
                let params = Self::params(grid, out_z, TensorOutput::Eigen, false);
                let norm = wgpu::BindGroupEntry {
                    binding: 8,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: norm_bits,
                        offset: 0,
                        size: wgpu::BufferSize::new(4),
                    }),
                };
                ("max_norm", &self.max_norm, params, norm)
            }
        };
        params.part = [part.start, part.len() as u32];
        params.rows = rows.unwrap_or([0, 0]);
        let params = crate::gpu::kernel::params_buffer(&ctx.device, label, &params);
        let mut entries = vec![checks::entry(0, &params)];
        entries.extend((0..6).map(|c| checks::entry(c as u32 + 1, tensor[c])));
        entries.push(last);
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &entries,
        });
        checks::dispatch(rec.encoder, label, pipeline, &bind_group, groups);
        Ok(())
    }

    /// Records `norm_bits = 0` (before the first slab).
    pub fn record_clear_norm(&self, encoder: &mut wgpu::CommandEncoder, norm_bits: &wgpu::Buffer) {
        encoder.clear_buffer(norm_bits, 0, Some(4));
    }
}

/// Part of a tensor's output block: the output slices `slices` (within `0..out_nz` of
/// `out_z = (out_z0, out_nz)`), written where the whole block has them (the parts of a block
/// give the whole block's bits), and when given only the rows `rows = [row0, n_rows]` (a
/// brick's core: `Output` leaves the block's halo rows as they are, `MaxNorm` ignores them).
#[derive(Clone, Debug)]
pub struct TensorPart<'a> {
    pub grid: &'a SlabGrid,
    /// `[xx, yy, zz, xy, xz, yz]`, `grid.len()` f32 each.
    pub tensor: [&'a wgpu::Buffer; 6],
    pub out_z: (u32, u32),
    pub slices: Range<u32>,
    pub rows: Option<[u32; 2]>,
}

/// What [`EigenFeatures::record`] records.
#[derive(Clone, Copy, Debug)]
pub enum EigenPass<'a> {
    /// `what` of the tensor into `out`, which holds `what.components() * nx * ny * out_nz` f32,
    /// component-major. `accumulate`: see the module documentation (false for the first scale).
    Output {
        what: TensorOutput,
        accumulate: bool,
        out: &'a wgpu::Buffer,
    },
    /// `norm_bits = max(norm_bits, bits of the largest Frobenius norm over the output slices)`
    /// (of the rows [`TensorPart::rows`] is given); `norm_bits` is a 4-byte buffer
    /// (e.g. [`norm_buffer`]), cleared once before the first brick.
    MaxNorm { norm_bits: &'a wgpu::Buffer },
}
