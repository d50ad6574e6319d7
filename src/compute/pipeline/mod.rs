//! The feature pipeline the app and `shapecast features --backend gpu` run: one volume in, one
//! method's features out, computed on the GPU slab by slab and kept there as a
//! [`FeatureTexture`] for rendering; read back only when asked (export, tests).
//!
//! A [`FeatureJob`] is advanced by [`FeatureJob::step`]: each call records and submits at most one
//! bounded piece of GPU work, and returns at once while the GPU is busy, so the app calls it once
//! per frame and stays responsive, shows progress, and cancels by dropping the job. Natively,
//! [`FeatureJob::run_blocking`] drives it to the end.
//!
//! What it computes is `crate::cpu::pipeline::compute` (the CPU reference), from the same
//! [`Request::resolve`]: thick axes refined by integer factors for the Hessian (z for the RST's
//! rays with `refine_slices`, cast at the input voxels only), the automatic
//! transfer function from the noise of the whole volume, Frangi's c over the whole volume per
//! scale, the multi-scale maximum, and results taken at the input voxels. Bricks (whole rows,
//! tiled in y and z) come from [`crate::compute::slab::plan`], sized from the device's binding
//! limit and a memory budget, with halos wide enough for the kernels and the rays; the RST
//! casts rays from core voxels only.

//!
//! The job's state and its task queue live here; planning it in `plan`, recording its tasks in
//! `record` (upload, gradient, Hessian) and `record_rst` (GST, RST, delivery), pacing its steps
//! in `pace`, its buffers in `buffers` and kernels in `kernels`.

mod buffers;
mod kernels;
mod pace;
mod plan;
mod record;
mod record_rst;

use crate::gpu::alloc::{AllocCheck, Allocation};
use std::collections::VecDeque;
use std::sync::Arc;

use crate::compute::eigen_features::{EigenPass, Mapping, TensorOutput};
use crate::compute::gradient::{GradientBuffers, GradientOutput};
use crate::compute::pack::PackBox;
use crate::compute::resample::{ResampleGeometry, Volumes};
use crate::compute::rst::{RstDispatch, RstInputs, RstOutput, RstRays};
use crate::compute::slab::{Brick, BrickLimits, PlanError, plan};
use crate::compute::{hessian, noise, pack};
use crate::cpu::features::FeatureMap;
use crate::cpu::gaussian::kernel_radius_vox;
use crate::cpu::pipeline::{Method, Request, RequestError, Resolved};
use crate::cpu::tf::{NOISE_BAND_HU, TransferFunction, auto_transfer_function, median};
use crate::cpu::{Components3, Grid};
use crate::gpu::kernel::SlabGrid;
use crate::gpu::readback::{PendingRead, ReadbackError};
use crate::gpu::volume_texture::{FeatureTexture, RenderVolumeError};
use crate::gpu::{GpuContext, shaders};
use crate::volume::Volume;

use crate::gpu::timing::GpuSpan;
use buffers::{Buffers, box_grid, bytes_per_voxel, core_in_slab, halo_of, starts, to_u32};
use kernels::Kernels;
use pace::StepPace;
pub use pace::Waker;

/// Why a feature computation failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PipelineError {
    #[error(transparent)]
    Request(#[from] RequestError),
    #[error(transparent)]
    Texture(#[from] RenderVolumeError),
    #[error("this GPU cannot hold the volume in bricks: {0}")]
    Plan(#[from] PlanError),
    #[error("a GPU kernel failed to build: {0}")]
    Shader(#[from] shaders::ShaderSourceError),
    #[error("reading results back from the GPU failed: {0}")]
    Readback(#[from] ReadbackError),
    #[error("a GPU kernel refused its inputs: {0}")]
    Record(#[from] crate::gpu::checks::RecordError),
    #[error("the RST's rays: {0}")]
    Rays(#[from] crate::compute::rst::RstConfigError),
    /// The device has no memory for `what`.
    #[error("the GPU has no memory for {what} ({:.0} MB): {detail}", *.bytes as f64 / 1e6)]
    OutOfMemory {
        what: &'static str,
        bytes: u64,
        detail: String,
    },
    /// A step ran before the one that prepares what it needs (a bug, not an input).
    #[error("the feature job's {0} is missing (steps out of order)")]
    Missing(&'static str),
}

/// Where a job is.
#[derive(Clone, Debug, PartialEq)]
pub enum JobState {
    /// `fraction` of the work done (0..1), and what it is doing now.
    Running {
        fraction: f32,
        stage: String,
    },
    Done,
}

/// How a job runs (the defaults suit the app).
#[derive(Clone, Debug)]
pub struct JobOptions {
    /// Working memory for brick buffers, bytes.
    pub memory_budget_bytes: u64,
    /// Caps compute voxels per brick below what the budget allows (tests force several bricks).
    pub max_slab_voxels: Option<u64>,
    /// The device limits to plan with, when smaller than the device's (tests force WebGPU's
    /// defaults on a device that has more).
    pub limits: Option<wgpu::Limits>,
    /// Also read the features back to the CPU (export, tests).
    pub export: bool,
    /// Output voxels per RST dispatch (a step); `None` picks from the adapter type. With
    /// [`Self::step_seconds`] this is the most a step may hold.
    pub rst_voxels_per_step: Option<u64>,
    /// GPU seconds one step should take (the viewer's frame rule: a frame never waits behind
    /// more than this): steps start at the least work there is and follow the device's
    /// measured speed. `None` (the CLI) gives whole passes and fixed ray steps of
    /// [`Self::rst_voxels_per_step`].
    pub step_seconds: Option<f64>,
    /// The RST reads (I, g) with eight `textureLoad`s per step, bit for bit the CPU twin's
    /// trilinear interpolation, instead of one hardware-filtered fetch (the default where the
    /// device filters f32 textures: ~1.9x faster on lavapipe, within a tolerance of the twin).
    pub exact_rst: bool,
    /// The level of the feature texture the job writes: 0 full resolution, L > 0 max-pooled
    /// by 2^L per axis (what the GPU budget allows: `gpu::budget::feature_level`). The
    /// features are computed at full resolution either way; an export reads them there.
    pub feature_level: u32,
}

impl Default for JobOptions {
    fn default() -> Self {
        Self {
            memory_budget_bytes: 384 << 20,
            max_slab_voxels: None,
            limits: None,
            export: false,
            rst_voxels_per_step: None,
            step_seconds: None,
            exact_rst: false,
            feature_level: 0,
        }
    }
}

/// A finished job's results.
pub struct FeatureResult {
    pub texture: FeatureTexture,
    /// The features on the input grid, when [`JobOptions::export`] asked for them.
    pub components: Option<Components3>,
    pub notes: Vec<String>,
    /// The transfer function the RST used.
    pub tf: Option<TransferFunction>,
    /// The measured noise of the smoothed intensity (auto TF), HU.
    pub noise_sigma_hu: Option<f64>,
    /// Number of bricks the volume was split into.
    pub slabs: usize,
    /// Computed voxels over delivered (compute-grid) voxels of the features' bricks.
    pub overhead: f64,
    /// The bricks.
    pub bricks: Vec<Brick>,
}

/// One bounded piece of work.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Task {
    /// Smoothed intensity of a whole-plane slab -> noise windows of its core slices (auto TF).
    Noise(usize),
    /// Median of the window sigmas -> transfer function.
    NoiseDone,
    /// Hessian at scale `s` of a slab -> largest norm of its core (Frangi's default c).
    FrangiC { scale: usize, slab: usize },
    /// Upload a slab and resample it; smoothing and gradient for the RST and the GST.
    Prepare(usize),
    /// One scale (GST) of a slab.
    Compute { slab: usize, part: usize },
    /// One pass of the Hessian at scale `part` of a slab (`pass < hessian::PASSES`), or its
    /// features from the six components (`pass == hessian::PASSES`): a step per dispatch, so
    /// that a frame of the viewer waits behind one pass, not a whole scale.
    HessianPass {
        slab: usize,
        part: usize,
        pass: usize,
    },
    /// The next rows or slices of a slab's core (RST): the task stays at the front of the
    /// queue until [`FeatureJob::rst_cursor`] has passed the core's last row.
    Rst(usize),
    /// Resample back onto the input grid, pack into the texture, read back if exporting.
    Deliver(usize),
    /// Read the features' maxima (for default gains).
    Maxima,
}

/// What a pending readback's bytes are for.
enum ReadFor {
    Noise,
    FrangiC(usize),
    Export(usize),
    Maxima,
}

/// One method's features for one volume, computed step by step.
pub struct FeatureJob {
    request: Request,
    input: Grid,
    compute: Grid,
    /// Integer refinement per axis (input voxel `i` is compute voxel `f * i`).
    factors: [usize; 3],
    slabs: Vec<Brick>,
    /// Whole-plane slabs for the noise measurement (windows tile whole slices).
    noise_slabs: Vec<Brick>,
    overhead: f64,
    tasks: VecDeque<Task>,
    total_tasks: usize,
    kernels: Kernels,
    buffers: Buffers,
    texture: FeatureTexture,
    /// The device's answer to the feature texture: nothing is recorded before it is in (a
    /// browser answers a frame or more later).
    alloc: AllocCheck,
    /// The same for the brick buffers.
    buffers_alloc: AllocCheck,
    /// The volume's values are read slice by slice from here (compact voxels, not f32).
    volume: Arc<Volume>,
    options: JobOptions,
    // Method parameters, resolved from the request and the preset.
    sigmas_mm: Vec<f64>,
    rays: Vec<[f64; 3]>,
    radius_mm: f64,
    step_mm: f64,
    tf: Option<TransferFunction>,
    noise_sigmas: Vec<f64>,
    noise_sigma: Option<f64>,
    frangi_c: Vec<f64>,
    /// Whole core slices one RST dispatch may hold (the output chunk buffer's size).
    rst_slices_per_step: usize,
    /// Output voxels per RST step without pacing, and the most a paced step holds.
    rst_max_step: u64,
    /// Where the next RST step starts: core slice and row within it (brick-local offsets
    /// from the core's first slice and row).
    rst_cursor: (usize, usize),
    /// Pacing (with [`JobOptions::step_seconds`]) of the RST's rays, the Hessian's
    /// convolution passes and the eigenvalue pass.
    rst_pace: StepPace,
    conv_pace: StepPace,
    eigen_pace: StepPace,
    pack_pace: StepPace,
    /// Lines of the current Hessian pass already recorded (its cut axis; core slices for the
    /// eigenvalue pass), or slices of the brick being stored.
    pass_cursor: u32,
    /// The slab's (I, gx, gy, gz) texture the rays read, with its dims.
    packed: Option<([u32; 3], wgpu::Texture)>,
    // GPU sync.
    /// The last submission, until its time is known ([`GpuSpan::seconds`]: the timestamps'
    /// readback, or the queue's completion callback).
    busy: Option<GpuSpan>,
    /// What [`GpuSpan`]'s callback times count from.
    epoch: web_time::Instant,
    /// Called when a submitted step is done (the viewer asks for a frame then).
    waker: Option<Waker>,
    pending: Option<(PendingRead, ReadFor)>,
    /// Steps that recorded and submitted work (a step may only find the GPU still busy).
    submissions: usize,
    /// GPU seconds of the last step whose completion was seen.
    last_step_s: Option<f64>,
    components: Option<Components3>,
    notes: Vec<String>,
    stage: String,
    done: bool,
}

impl FeatureJob {
    /// A job with the app's defaults.
    pub fn new(
        ctx: &GpuContext,
        volume: &Volume,
        request: &Request,
    ) -> Result<Self, PipelineError> {
        Self::with_options(ctx, volume, request, JobOptions::default())
    }

    pub fn with_options(
        ctx: &GpuContext,
        volume: &Volume,
        request: &Request,
        options: JobOptions,
    ) -> Result<Self, PipelineError> {
        Self::shared(ctx, Arc::new(volume.clone()), request, options)
    }

    /// The level of the feature texture the job writes (0: full resolution).
    pub fn feature_level(&self) -> u32 {
        self.texture.level
    }

    /// Steps so far that recorded and submitted work.
    pub fn submissions(&self) -> usize {
        self.submissions
    }

    /// GPU seconds of the last step seen done ([`GpuSpan::seconds`]).
    pub fn last_step_seconds(&self) -> Option<f64> {
        self.last_step_s
    }

    /// Calls `wake` whenever a step's work is done on the GPU and its time known: from the
    /// timestamps' readback, or the queue's completion callback without timestamps (in the
    /// browser these run as the queue finishes, so the page can take the next step without
    /// drawing frames in between; natively only when something polls the device).
    pub fn set_waker(&mut self, wake: Waker) {
        self.waker = Some(wake);
    }

    /// Changes [`JobOptions::step_seconds`] from the next step on (the viewer follows its own
    /// frame time); `None` makes the next steps whole.
    pub fn set_step_seconds(&mut self, seconds: Option<f64>) {
        for pace in [
            &mut self.rst_pace,
            &mut self.conv_pace,
            &mut self.eigen_pace,
            &mut self.pack_pace,
        ] {
            pace.seconds = seconds;
        }
    }

    /// Number of bricks the volume is processed in.
    pub fn slab_count(&self) -> usize {
        self.slabs.len()
    }

    /// Computed voxels over delivered voxels (compute grid) of the feature bricks.
    pub fn overhead(&self) -> f64 {
        self.overhead
    }

    /// Progress so far, without doing work.
    pub fn state(&self) -> JobState {
        if self.done {
            JobState::Done
        } else {
            let left = self.tasks.len() + usize::from(self.pending.is_some());
            let fraction = if self.request.method == Method::Rst {
                // The rays are nearly all the work: the fraction of core rows cast.
                // Output slices are the input voxels (`out`) of the core.
                let rows = |s: usize| self.slabs[s].core_c[1].len() * self.slabs[s].out[2].len();
                let total: usize = (0..self.slabs.len()).map(rows).sum();
                let ahead: usize = self
                    .tasks
                    .iter()
                    .filter_map(|t| match *t {
                        Task::Rst(s) => Some(rows(s)),
                        _ => None,
                    })
                    .sum();
                let in_current = match self.tasks.front() {
                    Some(&Task::Rst(s)) => {
                        let (z, j) = self.rst_cursor;
                        z * self.slabs[s].core_c[1].len() + j
                    }
                    _ => 0,
                };
                let done = total.saturating_sub(ahead) + in_current;
                // The last few tasks (storing, maxima) after the rays keep it below 1.
                (done as f32 / total.max(1) as f32).min(0.99)
            } else {
                1.0 - left as f32 / self.total_tasks.max(1) as f32
            };
            JobState::Running {
                fraction: fraction.clamp(0.0, 1.0),
                stage: self.stage.clone(),
            }
        }
    }

    /// What the user should be told (resampling, transfer function, warnings).
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// Does the next bounded piece of work, or nothing while the GPU is busy with the last.
    pub fn step(&mut self, ctx: &GpuContext) -> Result<JobState, PipelineError> {
        #[cfg(not(target_arch = "wasm32"))]
        ctx.device
            .poll(wgpu::PollType::Poll)
            .map_err(ReadbackError::from)?;
        match self.alloc.poll() {
            Allocation::Waiting => return Ok(self.state()),
            Allocation::Refused(detail) => {
                return Err(PipelineError::Texture(self.texture.out_of_memory(detail)));
            }
            Allocation::Granted => {}
        }
        match self.buffers_alloc.poll() {
            Allocation::Waiting => return Ok(self.state()),
            Allocation::Refused(detail) => return Err(self.buffers.refused(detail)),
            Allocation::Granted => {}
        }
        if let Some(flight) = &self.busy {
            let Some(secs) = flight.seconds() else {
                return Ok(self.state());
            };
            self.busy = None;
            self.last_step_s = Some(secs);
            self.rst_pace.finished(secs);
            self.conv_pace.finished(secs);
            self.eigen_pace.finished(secs);
            self.pack_pace.finished(secs);
        }
        if let Some((read, what)) = &mut self.pending {
            match read.poll(ctx) {
                None => return Ok(self.state()),
                Some(bytes) => {
                    let bytes = bytes?;
                    let what = match what {
                        ReadFor::Noise => ReadFor::Noise,
                        ReadFor::FrangiC(s) => ReadFor::FrangiC(*s),
                        ReadFor::Export(s) => ReadFor::Export(*s),
                        ReadFor::Maxima => ReadFor::Maxima,
                    };
                    self.pending = None;
                    self.take_read(what, &bytes);
                }
            }
        }
        let Some(task) = self.tasks.pop_front() else {
            self.done = true;
            return Ok(JobState::Done);
        };
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("feature job"),
            });
        let read = self.record(ctx, &mut encoder, task)?;
        if let Some((buffer, size, what)) = read {
            ctx.queue.submit([encoder.finish()]);
            self.pending = Some((PendingRead::start(ctx, &buffer, size), what));
            if let Some(wake) = self.waker.clone() {
                // The mapping completes with the copy or just after: a late wake costs only
                // the viewer's next regular frame.
                ctx.queue.on_submitted_work_done(move || wake());
            }
        } else {
            let span = GpuSpan::open(ctx, self.epoch);
            ctx.queue.submit([encoder.finish()]);
            self.busy = Some(span.close(ctx, self.waker.clone()));
        }
        self.submissions += 1;
        Ok(self.state())
    }

    /// Native only: runs the job to the end, waiting on the GPU between steps.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn run_blocking(&mut self, ctx: &GpuContext) -> Result<(), PipelineError> {
        loop {
            if self.step(ctx)? == JobState::Done {
                return Ok(());
            }
            ctx.device
                .poll(wgpu::PollType::wait_indefinitely())
                .map_err(ReadbackError::from)?;
        }
    }

    /// The features once [`JobState::Done`]; `None` before.
    pub fn finish(self) -> Option<FeatureTexture> {
        self.finish_result().map(|r| r.texture)
    }

    /// Everything a finished job produced; `None` before [`JobState::Done`].
    pub fn finish_result(self) -> Option<FeatureResult> {
        if !self.done {
            return None;
        }
        let slabs = self.slabs.len();
        let bricks = self.slabs.clone();
        Some(FeatureResult {
            texture: self.texture,
            components: self.components,
            notes: self.notes,
            tf: self.tf,
            noise_sigma_hu: self.noise_sigma,
            slabs,
            overhead: self.overhead,
            bricks,
        })
    }

    fn take_read(&mut self, what: ReadFor, bytes: &[u8]) {
        match what {
            ReadFor::Noise => self.noise_sigmas.extend(noise::NoiseWindows::decode(bytes)),
            ReadFor::FrangiC(scale) => {
                let m = bytes
                    .get(..4)
                    .map_or(0.0, |b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]));
                self.frangi_c[scale] = self.frangi_c[scale].max(0.5 * f64::from(m));
            }
            ReadFor::Export(s) => {
                let at = self.pack_box(s);
                let Some(out) = &mut self.components else {
                    return;
                };
                let [sx, sy, sz] = at.src_dims.map(|d| d as usize);
                let n = sx * sy * sz;
                let values: Vec<f32> = bytemuck::pod_collect_to_vec(bytes);
                let grid = self.input;
                for (c, comp) in out.iter_mut().enumerate() {
                    let Some(src) = values.get(c * n..(c + 1) * n) else {
                        continue;
                    };
                    for z in 0..sz {
                        for y in 0..at.ny as usize {
                            let from = sx * (y + at.src_y0 as usize + sy * z);
                            let to = grid.index(0, y + at.y0 as usize, z + at.z0 as usize);
                            comp[to..to + sx].copy_from_slice(&src[from..from + sx]);
                        }
                    }
                }
            }
            ReadFor::Maxima => {
                self.texture.max = pack::Pack::decode_maxima(bytes);
                self.texture.p999 = pack::Pack::decode_p999(bytes, self.texture.max);
            }
        }
    }
}
