//! Recording the feature job's tasks: the slab's upload, the gradient, the Hessian's passes and
//! the eigenvalue features of a tensor.

use super::*;
use crate::compute::eigen_features::TensorPart;
use crate::compute::hessian::HessianPass;
use crate::gpu::kernel::Recorder;

impl FeatureJob {
    /// Uploads the input box `ranges` (whole rows) into `buffers.input` (f32, physical values).
    pub(super) fn upload(&self, ctx: &GpuContext, ranges: &[std::ops::Range<usize>; 3]) {
        let [nx, ny, _] = self.input.dims;
        let rows = ranges[1].len();
        let row = ranges[0].len();
        if row != nx || rows == 0 {
            return;
        }
        // At most 16 MiB of f32 converted at a time, whole slices of the box at once.
        let plane = rows * nx;
        let per = ((4usize << 20) / plane.max(1)).max(1);
        let mut chunk = vec![0f32; plane * per.min(ranges[2].len())];
        let mut z = ranges[2].start;
        while z < ranges[2].end {
            let nz = per.min(ranges[2].end - z);
            for dz in 0..nz {
                let first = self.input.index(0, ranges[1].start, z + dz);
                let dst = &mut chunk[dz * plane..(dz + 1) * plane];
                if rows == ny {
                    self.volume.values_into(first, dst);
                } else {
                    for (j, out) in dst.chunks_exact_mut(nx).enumerate() {
                        self.volume.values_into(first + j * nx, out);
                    }
                }
            }
            ctx.queue.write_buffer(
                &self.buffers.input,
                ((z - ranges[2].start) * plane * 4) as u64,
                bytemuck::cast_slice(&chunk[..nz * plane]),
            );
            z += nz;
        }
    }

    /// Brick `b` (of `self.slabs`, or of the noise slabs) on the compute grid in
    /// [`Self::vol`]: uploaded, and refined when needed.
    pub(super) fn record_slab_values(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        brick: &Brick,
    ) -> Result<(), PipelineError> {
        self.upload(ctx, &brick.input);
        if let Some(vol) = &self.buffers.vol {
            let src = box_grid(&self.input, &brick.input);
            let dst = box_grid(&self.compute, &brick.slab_c);
            let geometry =
                ResampleGeometry::refine(self.factors.map(to_u32), self.input.dims.map(to_u32))
                    .blocks(starts(&brick.input), starts(&brick.slab_c));
            self.kernels.resample.record(
                &mut Recorder::new(ctx, encoder),
                Volumes::new(&self.buffers.input, src.dims),
                Volumes::new(vol, dst.dims),
                1,
                &geometry,
            )?;
        }
        Ok(())
    }

    pub(super) fn vol(&self) -> &wgpu::Buffer {
        self.buffers.vol.as_ref().unwrap_or(&self.buffers.input)
    }

    /// Smoothed intensity (`work[0]`) and gradient (`work[1..4]`) of the slab in `vol()`; for the
    /// RST, (I, g) packed into the texture the rays read instead of `work[1..4]`.
    pub(super) fn record_gradient(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        grid: &SlabGrid,
    ) -> Result<(), PipelineError> {
        let b = &self.buffers;
        self.kernels.gaussian.record_separable(
            &mut Recorder::new(ctx, encoder),
            grid,
            &self.kernels.smooth_g,
            self.vol(),
            &b.tmp[0],
            &b.work[0],
        )?;
        if self.request.method == Method::Rst {
            if self.packed.as_ref().is_none_or(|(d, _)| *d != grid.dims) {
                let tex = crate::compute::gradient::packed_texture(ctx, grid, "slab (I, g)")?;
                self.packed = Some((grid.dims, tex));
            }
            let Some((_, tex)) = &self.packed else {
                return Err(PipelineError::Missing("(I, g) texture"));
            };
            return self
                .kernels
                .gradient
                .record(
                    &mut Recorder::new(ctx, encoder),
                    grid,
                    &self.buffers.work[0],
                    GradientOutput::Packed(tex),
                )
                .map_err(PipelineError::from);
        }
        let b = &self.buffers;
        self.kernels
            .gradient
            .record(
                &mut Recorder::new(ctx, encoder),
                grid,
                &b.work[0],
                GradientOutput::Buffers(GradientBuffers {
                    gx: &b.work[1],
                    gy: &b.work[2],
                    gz: &b.work[3],
                }),
            )
            .map_err(PipelineError::from)
    }

    /// The six Hessian components at scale `scale` in `work[0..6]`.
    pub(super) fn record_hessian(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        grid: &SlabGrid,
        scale: usize,
    ) -> Result<(), PipelineError> {
        let b = &self.buffers;
        let out: [&wgpu::Buffer; 6] = std::array::from_fn(|c| &b.work[c]);
        self.kernels
            .hessian
            .record(
                &mut Recorder::new(ctx, encoder),
                grid,
                &self.kernels.hessian_kernels[scale],
                self.vol(),
                &b.tmp[0],
                out,
            )
            .map_err(PipelineError::from)
    }

    /// Records one task; returns a buffer to read back when the task ends with a readback.
    pub(super) fn record(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        task: Task,
    ) -> Result<Option<(wgpu::Buffer, u64, ReadFor)>, PipelineError> {
        let n_slabs = self.slabs.len();
        match task {
            Task::Noise(s) => {
                let n = self.noise_slabs.len();
                self.stage = format!("measuring noise, slab {}/{n}", s + 1);
                let slab = self.noise_slabs[s].clone();
                let grid = box_grid(&self.compute, &slab.slab_c);
                self.record_slab_values(ctx, encoder, &slab)?;
                let b = &self.buffers;
                self.kernels.gaussian.record_separable(
                    &mut Recorder::new(ctx, encoder),
                    &grid,
                    &self.kernels.smooth_g,
                    self.vol(),
                    &b.tmp[0],
                    &b.work[0],
                )?;
                // Cores tile the volume: each slice is measured once.
                let z0 = to_u32(slab.core_c[2].start - slab.slab_c[2].start);
                let nz = to_u32(slab.core_c[2].len());
                let len = noise::output_len(grid, nz);
                if len == 0 {
                    return Ok(None);
                }
                self.kernels.noise.record(
                    &mut Recorder::new(ctx, encoder),
                    grid,
                    &b.work[0],
                    z0..z0 + nz,
                    NOISE_BAND_HU,
                    &b.small,
                );
                Ok(Some((b.small.clone(), len * 4, ReadFor::Noise)))
            }
            Task::NoiseDone => {
                self.noise_sigma = median(std::mem::take(&mut self.noise_sigmas));
                match self.noise_sigma {
                    Some(s) => self.notes.push(format!(
                        "noise of the smoothed intensity: {s:.2} HU (median of 11x11 windows in 0..100 HU)"
                    )),
                    None => self.notes.push(
                        "noise: no 11x11 window lies wholly in 0..100 HU; the preset's transfer function is used"
                            .to_owned(),
                    ),
                }
                self.tf = Some(auto_transfer_function(
                    self.request.preset.transfer_function(),
                    self.noise_sigma,
                ));
                Ok(None)
            }
            Task::FrangiC { scale, slab: s } => {
                self.stage = format!(
                    "Frangi's c, scale {}/{}, slab {}/{n_slabs}",
                    scale + 1,
                    self.sigmas_mm.len(),
                    s + 1
                );
                let slab = self.slabs[s].clone();
                let grid = box_grid(&self.compute, &slab.slab_c);
                self.record_slab_values(ctx, encoder, &slab)?;
                self.record_hessian(ctx, encoder, &grid, scale)?;
                let b = &self.buffers;
                let tensor: [&wgpu::Buffer; 6] = std::array::from_fn(|c| &b.work[c]);
                self.kernels.eigen.record_clear_norm(encoder, &b.norm);
                let (z, y) = core_in_slab(&slab);
                self.kernels.eigen.record_part(
                    &mut Recorder::new(ctx, encoder),
                    &TensorPart {
                        grid: &grid,
                        tensor,
                        out_z: z,
                        slices: 0..z.1,
                        rows: Some([y.0, y.1]),
                    },
                    EigenPass::MaxNorm { norm_bits: &b.norm },
                )?;
                Ok(Some((b.norm.clone(), 4, ReadFor::FrangiC(scale))))
            }
            Task::Prepare(s) => {
                self.stage = format!("brick {}/{n_slabs}: upload", s + 1);
                let slab = self.slabs[s].clone();
                self.record_slab_values(ctx, encoder, &slab)?;
                if matches!(self.request.method, Method::Rst | Method::Gst) {
                    let grid = box_grid(&self.compute, &slab.slab_c);
                    self.record_gradient(ctx, encoder, &grid)?;
                }
                Ok(None)
            }
            Task::Compute { slab: s, part } => {
                self.record_compute(ctx, encoder, s, part)?;
                Ok(None)
            }
            Task::HessianPass {
                slab: s,
                part,
                pass,
            } => {
                self.stage = format!(
                    "brick {}/{n_slabs}: Hessian, sigma {} mm",
                    s + 1,
                    self.sigmas_mm[part]
                );
                if !self.record_hessian_part(ctx, encoder, s, part, pass)? {
                    self.tasks.push_front(task);
                }
                Ok(None)
            }
            Task::Rst(s) => {
                let slab = &self.slabs[s];
                let grid = box_grid(&self.compute, &slab.slab_c);
                if self.record_rst(ctx, encoder, s, grid)? {
                    self.rst_cursor = (0, 0);
                } else {
                    self.tasks.push_front(Task::Rst(s));
                }
                Ok(None)
            }
            Task::Deliver(s) => {
                self.stage = format!("brick {}/{n_slabs}: storing", s + 1);
                let (read, finished) = self.record_deliver(ctx, encoder, s)?;
                if !finished {
                    self.tasks.push_front(task);
                }
                Ok(read)
            }
            Task::Maxima => {
                self.stage = "finishing".to_owned();
                Ok(Some((
                    self.kernels.pack.maxima.clone(),
                    pack::Pack::MAXIMA_BYTES,
                    ReadFor::Maxima,
                )))
            }
        }
    }

    /// The next part of Hessian pass `pass` (the eigenvalue pass when `pass ==
    /// hessian::PASSES`) at scale `part` of brick `s`, from [`Self::pass_cursor`]: the whole
    /// pass without pacing, else as many lines as the measured rate does in a step. True when
    /// the pass is done.
    pub(super) fn record_hessian_part(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        s: usize,
        part: usize,
        pass: usize,
    ) -> Result<bool, PipelineError> {
        let slab = &self.slabs[s];
        let grid = box_grid(&self.compute, &slab.slab_c);
        let (core, rows) = core_in_slab(slab);
        let core_box = [
            0..grid.dims[0],
            rows.0..rows.0 + rows.1,
            core.0..core.0 + core.1,
        ];
        let conv = pass < hessian::PASSES;
        let (first, lines, per_line) = if conv {
            let lines = hessian::pass_lines(&grid, &core_box, pass);
            let n = lines.end - lines.start;
            let accesses =
                hessian::pass_accesses_per_voxel(&self.kernels.hessian_kernels[part], pass);
            let voxels = hessian::pass_voxels(&grid, &core_box, pass);
            (
                lines.start,
                n,
                voxels as f64 / f64::from(n.max(1)) * accesses,
            )
        } else {
            // The eigenvalues of the core's rows.
            let plane = u64::from(grid.dims[0]) * u64::from(rows.1);
            (0, core.1, plane as f64)
        };
        let done = self.pass_cursor.min(lines);
        let left = lines - done;
        let pace = if conv {
            &mut self.conv_pace
        } else {
            &mut self.eigen_pace
        };
        let all = per_line * f64::from(left);
        let work = pace.work(per_line, all);
        // Whole lines; all that is left when the step may hold it (no rounding short of it).
        let n = if work >= all {
            left
        } else {
            ((work / per_line) as u32).clamp(left.min(1), left)
        };
        pace.submitted(per_line * f64::from(n));
        let cut = done..done + n;
        if conv {
            let b = &self.buffers;
            let out: [&wgpu::Buffer; 6] = std::array::from_fn(|c| &b.work[c]);
            self.kernels.hessian.record_pass(
                &mut Recorder::new(ctx, encoder),
                &HessianPass {
                    grid: &grid,
                    kernels: &self.kernels.hessian_kernels[part],
                    input: self.vol(),
                    tmp: &b.tmp[0],
                    out,
                    pass,
                    core: &core_box,
                    cut: first + cut.start..first + cut.end,
                },
            )?;
        } else {
            self.record_features_of_tensor(
                &mut Recorder::new(ctx, encoder),
                &grid,
                0,
                (core, rows),
                cut.clone(),
                part,
            )?;
        }
        let finished = cut.end >= lines;
        self.pass_cursor = if finished { 0 } else { cut.end };
        Ok(finished)
    }

    pub(super) fn tensor_output(&self, part: usize) -> TensorOutput {
        if self.request.eigen {
            return TensorOutput::Eigen;
        }
        match self.request.method {
            Method::Hessian => TensorOutput::hessian(Mapping::Map(FeatureMap::Simple)),
            Method::Li => TensorOutput::hessian(Mapping::Map(FeatureMap::Li)),
            Method::Frangi => TensorOutput::hessian(Mapping::Frangi {
                c: self.request.frangi_c.unwrap_or(self.frangi_c[part]),
            }),
            _ => TensorOutput::structure_tensor(self.request.rst_map),
        }
    }

    /// Eigenvalues or features of the six tensor components in `work[first..first + 6]` for the
    /// core slices, into `out_core` (the multi-scale maximum from the second scale on).
    pub(super) fn record_features_of_tensor(
        &self,
        rec: &mut Recorder<'_>,
        grid: &SlabGrid,
        first: usize,
        (core, rows): ((u32, u32), (u32, u32)),
        slices: std::ops::Range<u32>,
        part: usize,
    ) -> Result<(), PipelineError> {
        let b = &self.buffers;
        let tensor: [&wgpu::Buffer; 6] = std::array::from_fn(|c| &b.work[first + c]);
        self.kernels
            .eigen
            .record_part(
                rec,
                &TensorPart {
                    grid,
                    tensor,
                    out_z: core,
                    slices,
                    rows: Some([rows.0, rows.1]),
                },
                EigenPass::Output {
                    what: self.tensor_output(part),
                    accumulate: part > 0,
                    out: &b.out_core,
                },
            )
            .map_err(PipelineError::from)
    }
}
