//! Planning a feature job: the request resolved, the bricks planned, the buffers and kernels
//! made and the task queue filled ([`FeatureJob::shared`]).

use super::*;

impl FeatureJob {
    /// A job that reads its slices from a volume the caller shares (no copy).
    pub fn shared(
        ctx: &GpuContext,
        volume: Arc<Volume>,
        request: &Request,
        options: JobOptions,
    ) -> Result<Self, PipelineError> {
        let req = request.clone();
        let input = Grid::of(&volume);
        let resolved = req.resolve(&input)?;
        let dims = volume.dims.map(to_u32);
        let (texture, alloc) =
            FeatureTexture::new_level_checked(ctx, dims, options.feature_level, "features")?;
        let compute = resolved.compute;
        let factors = resolved.factors;
        let mut notes = resolved.notes.clone();
        let halo = halo_of(&req, &resolved);
        let resampled = compute != input;
        let limits = options.limits.as_ref().unwrap_or(&ctx.limits);
        let binding = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        let budget_voxels = options.memory_budget_bytes / bytes_per_voxel(req.method, resampled);
        // A brick's buffers hold one f32 per voxel; the feature output 3 (4 for eigenvalues
        // with their scale's norm) per voxel of whole rows of the core slices.
        let out_components = if req.eigen && req.method != Method::Rst {
            4
        } else {
            3
        };
        let mut limits = BrickLimits {
            slab_voxels: (binding / 4).min(budget_voxels),
            out_voxels: binding / (4 * out_components),
        };
        if let Some(cap) = options.max_slab_voxels {
            limits.slab_voxels = limits.slab_voxels.min(cap);
        }
        let planned = plan(&input, factors, halo, limits, None)?;
        let overhead = planned.overhead;
        let slabs = planned.bricks;
        let noise_slabs = if req.method == Method::Rst && req.tf.is_none() {
            // Whole planes, but only the input, the smoothed intensity and scratch: 16 bytes
            // per voxel.
            let noise_halo = [
                0,
                0,
                kernel_radius_vox(req.sigma_g_mm / compute.spacing_mm[2]),
            ];
            let noise_limits = BrickLimits {
                slab_voxels: (binding / 4).min(options.memory_budget_bytes / 16),
                out_voxels: u64::MAX,
            };
            plan(&input, factors, noise_halo, noise_limits, Some(1))?.bricks
        } else {
            Vec::new()
        };
        let Resolved {
            sigmas_mm,
            rays,
            radius_mm,
            step_mm,
            ..
        } = resolved;
        let kernels = Kernels::new(ctx, &req, &compute, &sigmas_mm, options.exact_rst)?;
        // The Hessian's passes compute only what the core needs: their halo costs less than
        // the bricks hold.
        let held = overhead;
        let overhead = if kernels.hessian_kernels.is_empty() {
            held
        } else {
            hessian_work_overhead(&compute, &slabs, &kernels.hessian_kernels)
        };
        if slabs.len() > 1 {
            notes.push(format!(
                "{} bricks, halo overhead {overhead:.2} (computed / delivered voxels; the bricks hold {held:.2})",
                slabs.len()
            ));
        }
        let mut tasks = VecDeque::new();
        let tf = if req.method == Method::Rst {
            req.tf
        } else {
            None
        };
        if req.method == Method::Rst && tf.is_none() {
            tasks.extend((0..noise_slabs.len()).map(Task::Noise));
            tasks.push_back(Task::NoiseDone);
        }
        let frangi_default = req.method == Method::Frangi && req.frangi_c.is_none() && !req.eigen;
        if frangi_default {
            for scale in 0..sigmas_mm.len() {
                tasks.extend((0..slabs.len()).map(|slab| Task::FrangiC { scale, slab }));
            }
        }
        // RST dispatches cover a brick's core rows; a step is at most `per_step` voxels.
        let core_plane = slabs
            .iter()
            .map(|b| (b.core_c[0].len() * b.core_c[1].len()) as u64)
            .max()
            .unwrap_or(1);
        let per_step = options.rst_voxels_per_step.unwrap_or(
            if ctx.adapter_info.device_type == wgpu::DeviceType::Cpu {
                1 << 15
            } else {
                1 << 20
            },
        );
        let rst_slices_per_step = ((per_step / core_plane.max(1)) as usize).max(1);
        let step_seconds = options.step_seconds;
        let (buffers, mut buffers_alloc) = AllocCheck::around(ctx, || {
            Buffers::new(
                ctx,
                &slabs,
                &noise_slabs,
                resampled,
                &req,
                rst_slices_per_step,
            )
        });
        if let Allocation::Refused(detail) = buffers_alloc.poll() {
            return Err(buffers.refused(detail));
        }
        for s in 0..slabs.len() {
            tasks.push_back(Task::Prepare(s));
            match req.method {
                Method::Rst => tasks.push_back(Task::Rst(s)),
                Method::Hessian | Method::Li | Method::Frangi => {
                    for part in 0..sigmas_mm.len() {
                        tasks.extend((0..=hessian::PASSES).map(|pass| Task::HessianPass {
                            slab: s,
                            part,
                            pass,
                        }));
                    }
                }
                Method::Gst => {
                    let parts = if req.eigen { 1 } else { sigmas_mm.len() };
                    tasks.extend((0..parts).map(|part| Task::Compute { slab: s, part }));
                }
            }
            tasks.push_back(Task::Deliver(s));
        }
        tasks.push_back(Task::Maxima);
        if req.method == Method::Gst && req.eigen && sigmas_mm.len() > 1 {
            notes.push(format!(
                "--eigen with the structure tensor uses the first scale, {} mm",
                sigmas_mm[0]
            ));
        }
        let components = options
            .export
            .then(|| std::array::from_fn(|_| vec![0.0f32; input.len()]));
        let total_tasks = tasks.len();
        Ok(Self {
            frangi_c: vec![0.0; sigmas_mm.len()],
            request: req,
            input,
            compute,
            factors,
            slabs,
            noise_slabs,
            overhead,
            tasks,
            total_tasks,
            kernels,
            buffers,
            texture,
            alloc,
            buffers_alloc,
            volume,
            options,
            sigmas_mm,
            rays,
            radius_mm,
            step_mm,
            tf,
            noise_sigmas: Vec::new(),
            noise_sigma: None,
            rst_slices_per_step,
            rst_max_step: per_step.max(1),
            rst_cursor: (0, 0),
            rst_pace: StepPace::new(step_seconds),
            conv_pace: StepPace::new(step_seconds),
            eigen_pace: StepPace::new(step_seconds),
            pack_pace: StepPace::new(step_seconds),
            pass_cursor: 0,
            packed: None,
            busy: None,
            epoch: web_time::Instant::now(),
            waker: None,
            pending: None,
            submissions: 0,
            last_step_s: None,
            components,
            notes,
            stage: "starting".to_owned(),
            done: false,
        })
    }
}

/// Convolution work of the Hessian's passes over `slabs` (each pass over [`hessian::pass_region`]
/// of its brick's core, weighed by its storage accesses) over the same work if every brick were
/// its core alone: the halo overhead of the Hessian methods.
pub(super) fn hessian_work_overhead(
    compute: &Grid,
    slabs: &[Brick],
    kernels: &[hessian::HessianKernels],
) -> f64 {
    let (mut done, mut needed) = (0.0, 0.0);
    for slab in slabs {
        let grid = box_grid(compute, &slab.slab_c);
        let (core, rows) = core_in_slab(slab);
        let core_box = [
            0..grid.dims[0],
            rows.0..rows.0 + rows.1,
            core.0..core.0 + core.1,
        ];
        let core_voxels = slab.core_len() as f64;
        for k in kernels {
            for pass in 0..hessian::PASSES {
                let a = hessian::pass_accesses_per_voxel(k, pass);
                done += hessian::pass_voxels(&grid, &core_box, pass) as f64 * a;
                needed += core_voxels * a;
            }
        }
    }
    if needed > 0.0 { done / needed } else { 1.0 }
}
