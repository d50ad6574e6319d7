//! Recording the feature job's tasks: the GST's scales, the RST's rows of rays and the delivery
//! of a brick (back onto the input grid, packed into the texture, read back when exporting).

use super::*;
use crate::gpu::kernel::Recorder;

impl FeatureJob {
    pub(super) fn record_compute(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        s: usize,
        part: usize,
    ) -> Result<(), PipelineError> {
        let slab = self.slabs[s].clone();
        let grid = box_grid(&self.compute, &slab.slab_c);
        let (core, _) = core_in_slab(&slab);
        let n_slabs = self.slabs.len();
        match self.request.method {
            Method::Gst => {
                self.stage = format!(
                    "brick {}/{n_slabs}: structure tensor, rho {} mm",
                    s + 1,
                    self.sigmas_mm[part]
                );
                let b = &self.buffers;
                let gst = self
                    .kernels
                    .gst
                    .as_ref()
                    .ok_or(PipelineError::Missing("structure tensor kernel"))?;
                let tensor: [&wgpu::Buffer; 6] = std::array::from_fn(|c| &b.work[4 + c]);
                gst.record(
                    &mut Recorder::new(ctx, encoder),
                    &grid,
                    &self.kernels.rho[part],
                    [&b.work[1], &b.work[2], &b.work[3]],
                    [&b.tmp[0], &b.tmp[1]],
                    tensor,
                )?;
                let rows = core_in_slab(&slab).1;
                self.record_features_of_tensor(
                    &mut crate::gpu::kernel::Recorder::new(ctx, encoder),
                    &grid,
                    4,
                    (core, rows),
                    0..core.1,
                    part,
                )?;
            }
            // Their steps are `Task::HessianPass` and `Task::Rst`.
            Method::Hessian | Method::Li | Method::Frangi | Method::Rst => {
                return Err(PipelineError::Missing("a step of this method"));
            }
        }
        Ok(())
    }

    /// The next step of the RST over brick `s`'s core, from [`Self::rst_cursor`]: whole core
    /// slices while a step holds at least one, else rows of one slice. True when the core is done.
    pub(super) fn record_rst(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        s: usize,
        grid: SlabGrid,
    ) -> Result<bool, PipelineError> {
        let slab = self.slabs[s].clone();
        let tf = self
            .tf
            .unwrap_or_else(|| self.request.preset.transfer_function());
        if self.kernels.rays.is_none() {
            self.notes.push(format!(
                "transfer function: d_min {:.1} HU, d_max {:.1} HU",
                tf.d_min, tf.d_max
            ));
            let params = crate::cpu::rst::RstParams {
                rays: self.rays.clone(),
                radius_mm: self.radius_mm,
                step_mm: self.step_mm,
                tf,
                rule: self.request.rule,
            };
            // Steps on the (refined) compute grid, opacity lengths from the input spacing.
            let rays = RstRays::refined(
                ctx,
                &params,
                self.compute.spacing_mm,
                self.input.spacing_mm,
                self.request.sigma_g_mm,
            )?;
            self.kernels.rays = Some(rays);
            self.tf = Some(tf);
        }
        // The core's output slices are its input voxels: compute slices `zc.start + f k` for
        // k < n_out (f, z's refinement, is 1 unless the slices were refined for the rays).
        // This step: output slices `dz..dz + count`, rows `j0..j0 + nj` of the brick's core.
        let (zc, yc) = (&slab.core_c[2], &slab.core_c[1]);
        let f = self.factors[2].max(1);
        let n_out = slab.out[2].len();
        if zc.is_empty() || yc.is_empty() || n_out == 0 {
            return Ok(true);
        }
        let nx = self.compute.dims[0].max(1) as u64;
        let core_plane = nx * yc.len() as u64;
        let voxels = self.rst_pace.work(nx as f64, self.rst_max_step as f64) as u64;
        let (dz, j0) = self.rst_cursor;
        let first = zc.start + f * dz;
        let (count, nj) = if j0 == 0 && voxels >= core_plane {
            let slices = ((voxels / core_plane.max(1)) as usize)
                .clamp(1, self.rst_slices_per_step)
                .min(n_out - dz);
            (slices, yc.len())
        } else {
            let rows = ((voxels / nx) as usize).clamp(1, yc.len() - j0);
            (1, rows)
        };
        let y_local = to_u32(yc.start - slab.slab_c[1].start);
        let rows = [y_local + to_u32(j0), to_u32(nj)];
        self.stage = format!(
            "brick {}/{}: RST, slices {}-{} of {}",
            s + 1,
            self.slabs.len(),
            slab.out[2].start + dz + 1,
            slab.out[2].start + dz + count,
            self.input.dims[2]
        );
        let (Some(rst), Some(rays)) = (&self.kernels.rst, &self.kernels.rays) else {
            return Err(PipelineError::Missing("RST kernel"));
        };
        let b = &self.buffers;
        let output = if self.request.eigen {
            RstOutput::Eigen
        } else {
            RstOutput::Features(self.request.rst_map)
        };
        let dispatch = RstDispatch {
            z_stride: to_u32(f),
            grid,
            out_z0: to_u32(first - slab.slab_c[2].start),
            out_nz: to_u32(count),
            rows: Some(rows),
            output,
        };
        let Some((_, volume)) = &self.packed else {
            return Err(PipelineError::Missing("(I, g) texture"));
        };
        let inputs = RstInputs { volume, rays };
        let chunk = b
            .chunk_out
            .as_ref()
            .ok_or(PipelineError::Missing("RST output buffer"))?;
        rst.record(&mut Recorder::new(ctx, encoder), &inputs, &dispatch, chunk)?;
        // Into the core's component-major block of output slices (whole brick planes, one per
        // input slice of the core; rows outside the core are never read): the slices computed,
        // or within one slice only the rows computed.
        let row = u64::from(grid.dims[0]);
        let plane = row * u64::from(grid.dims[1]);
        let n_chunk = plane * count as u64;
        let n_core = plane * n_out as u64;
        let at = plane * dz as u64;
        let (skip, len) = if count == 1 {
            (u64::from(rows[0]) * row, u64::from(rows[1]) * row)
        } else {
            (0, n_chunk)
        };
        for c in 0..3u64 {
            encoder.copy_buffer_to_buffer(
                chunk,
                (c * n_chunk + skip) * 4,
                &b.out_core,
                (c * n_core + at + skip) * 4,
                len * 4,
            );
        }
        self.rst_pace
            .submitted((nj as u64 * nx * count as u64) as f64);
        self.rst_cursor = if j0 + nj < yc.len() {
            (dz, j0 + nj)
        } else {
            (dz + count, 0)
        };
        Ok(self.rst_cursor.0 >= n_out)
    }

    /// Where brick `s`'s features lie in the buffer [`Self::record_deliver`] packs from, and
    /// where they go in the texture.
    pub(super) fn pack_box(&self, s: usize) -> PackBox {
        let b = &self.slabs[s];
        let ny = to_u32(b.out[1].len());
        let (y0, z0) = (to_u32(b.out[1].start), to_u32(b.out[2].start));
        if self.buffers.out_in.is_some() {
            // Subsampled onto the input grid: exactly the delivered box.
            PackBox {
                src_dims: [to_u32(self.input.dims[0]), ny, to_u32(b.out[2].len())],
                src_y0: 0,
                ny,
                y0,
                z0,
            }
        } else {
            // The core's slices with the brick's halo rows (its input slices: the compute
            // grid's when nothing was refined, the RST's output slices when z was).
            PackBox {
                src_dims: [
                    to_u32(self.compute.dims[0]),
                    to_u32(b.slab_c[1].len()),
                    to_u32(b.out[2].len()),
                ],
                src_y0: to_u32(b.core_c[1].start - b.slab_c[1].start),
                ny,
                y0,
                z0,
            }
        }
    }

    /// The next part of storing brick `s`, from [`Self::pass_cursor`] (slices of its box): the
    /// first step takes the core back onto the input grid when it was refined, then each step
    /// packs as many slices into the texture as the measured rate does in a step (all without
    /// pacing). Returns the export readback once the last slice is stored, and whether it is.
    #[allow(clippy::type_complexity)]
    pub(super) fn record_deliver(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        s: usize,
    ) -> Result<(Option<(wgpu::Buffer, u64, ReadFor)>, bool), PipelineError> {
        let slab = self.slabs[s].clone();
        let at = self.pack_box(s);
        let b = &self.buffers;
        let done = self.pass_cursor;
        let features = match &b.out_in {
            Some(out_in) => {
                if done == 0 {
                    let core_dims = [
                        to_u32(self.compute.dims[0]),
                        to_u32(slab.slab_c[1].len()),
                        to_u32(slab.core_c[2].len()),
                    ];
                    let geometry = ResampleGeometry::subsample(
                        self.factors.map(to_u32),
                        self.compute.dims.map(to_u32),
                    )
                    .blocks(
                        [
                            0,
                            to_u32(slab.slab_c[1].start),
                            to_u32(slab.core_c[2].start),
                        ],
                        starts(&slab.out),
                    );
                    self.kernels.resample.record(
                        &mut Recorder::new(ctx, encoder),
                        Volumes::new(&b.out_core, core_dims),
                        Volumes::new(out_in, at.src_dims),
                        3,
                        &geometry,
                    )?;
                }
                out_in.clone()
            }
            None => b.out_core.clone(),
        };
        let slices = at.src_dims[2];
        let left = slices.saturating_sub(done);
        let per_slice = f64::from(at.src_dims[0]) * f64::from(at.ny);
        let all = per_slice * f64::from(left);
        let work = self.pack_pace.work(per_slice, all);
        let n = if work >= all {
            left
        } else {
            ((work / per_slice) as u32).clamp(left.min(1), left)
        };
        self.pack_pace.submitted(per_slice * f64::from(n));
        self.kernels.pack.record_slices(
            &mut Recorder::new(ctx, encoder),
            &features,
            &self.texture,
            at,
            done..done + n,
        );
        let finished = done + n >= slices;
        self.pass_cursor = if finished { 0 } else { done + n };
        let bytes = 3 * at.src_dims.iter().map(|&d| u64::from(d)).product::<u64>() * 4;
        let read =
            (finished && self.options.export).then_some((features, bytes, ReadFor::Export(s)));
        Ok((read, finished))
    }
}
