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
//! Why this file is over 600 lines: it has one job, the task queue of the feature job (plan the
//! bricks, then upload, record and read back one bounded task per step), and the recording of
//! each task needs the job's whole state; cutting it apart would spread one state machine over
//! several files. Its buffers (`buffers`) and kernels (`kernels`) live beside it.

mod buffers;
mod kernels;

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use crate::compute::eigen_features::{EigenPass, Mapping, TensorOutput};
use crate::compute::gradient::{GradientBuffers, GradientOutput};
use crate::compute::pack::PackBox;
use crate::compute::resample::ResampleGeometry;
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

use buffers::{Buffers, box_grid, bytes_per_voxel, core_in_slab, halo_of, starts, to_u32};
use kernels::Kernels;

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
        }
    }
}

/// Paces a kind of step to [`JobOptions::step_seconds`] of GPU time: the first step holds the
/// least work allowed; each finished step measures the device's work per second over the step's
/// own time on the queue ([`InFlight`]: from when the work queued before it was done, or its
/// submission if later, to its own completion), so that the viewer's frames queued before it do
/// not count as the step's; the step follows a slower rate at once and a faster one at most
/// doubling per step. Work is counted in a unit of the step's kind: ray
/// voxels for the RST, storage accesses for the Hessian's convolutions, voxels for the
/// eigenvalue pass.
struct StepPace {
    seconds: Option<f64>,
    /// Work per second, once measured.
    rate: Option<f64>,
    /// Work of the step in flight.
    in_flight: Option<f64>,
    /// The last step's work.
    last: f64,
}

impl StepPace {
    fn new(seconds: Option<f64>) -> Self {
        Self {
            seconds,
            rate: None,
            in_flight: None,
            last: 0.0,
        }
    }

    /// Work for the next step: `max` without pacing; with it, what the measured rate does in
    /// the step's seconds, between `min` (the smallest step there is) and `max`.
    fn work(&self, min: f64, max: f64) -> f64 {
        let Some(seconds) = self.seconds else {
            return max;
        };
        let want = match self.rate {
            None => min,
            Some(rate) => (rate * seconds).min(2.0 * self.last),
        };
        want.clamp(min.min(max), max)
    }

    fn submitted(&mut self, work: f64) {
        self.last = work;
        self.in_flight = self.seconds.map(|_| work);
    }

    /// The step in flight, if it was this kind's, took `secs` on the queue ([`InFlight`]).
    fn finished(&mut self, secs: f64) {
        let Some(work) = self.in_flight.take() else {
            return;
        };
        let rate = work / secs.max(1e-4);
        self.rate = Some(match self.rate {
            Some(old) if rate > old => old + 0.5 * (rate - old),
            _ => rate,
        });
    }
}

/// One submitted step and the queue's word on it, in microseconds since the job's epoch
/// (`u64::MAX` until the callback has run).
///
/// In the browser, the step's own GPU time runs from when everything queued before it was done
/// (`before`: the viewer's last frame, say) or its submission, whichever is later, to `done`;
/// natively (callbacks run only when something polls) from the submission. Timing from the
/// submission alone counted a slow frame queued ahead as the step's (on SwiftShader a frame is
/// ~0.2-0.3 s, so the step never grew); the callbacks come as the queue finishes (the browser
/// resolves them within milliseconds while the page waits), not when the job next looks.
struct InFlight {
    submitted: u64,
    before: Arc<AtomicU64>,
    done: Arc<AtomicU64>,
}

/// What a job calls when a step is done on the GPU ([`FeatureJob::set_waker`]).
pub type Waker = Arc<dyn Fn() + Send + Sync>;

/// Callbacks stamped closer than this ran together (one poll, one task of the page).
const STAMPED_APART_MICROS: u64 = 1000;

impl InFlight {
    fn submit(
        ctx: &GpuContext,
        epoch: web_time::Instant,
        commands: wgpu::CommandBuffer,
        wake: Option<Waker>,
    ) -> Self {
        let stamp = |flag: &Arc<AtomicU64>| {
            let flag = Arc::clone(flag);
            move || {
                let micros = u64::try_from(epoch.elapsed().as_micros()).unwrap_or(u64::MAX - 1);
                flag.store(micros.min(u64::MAX - 1), Ordering::Release);
            }
        };
        let before = Arc::new(AtomicU64::new(u64::MAX));
        let done = Arc::new(AtomicU64::new(u64::MAX));
        // Natively callbacks run when something polls, so `before` would not be used
        // ([`Self::seconds`]); registering it would only cost a submission per step.
        if cfg!(target_arch = "wasm32") {
            ctx.queue.on_submitted_work_done(stamp(&before));
        }
        let submitted = u64::try_from(epoch.elapsed().as_micros()).unwrap_or(u64::MAX - 1);
        ctx.queue.submit([commands]);
        let stamp_done = stamp(&done);
        ctx.queue.on_submitted_work_done(move || {
            stamp_done();
            if let Some(wake) = wake {
                wake();
            }
        });
        Self {
            submitted,
            before,
            done,
        }
    }

    /// The step's own GPU seconds once it is done.
    fn seconds(&self) -> Option<f64> {
        let done = self.done.load(Ordering::Acquire);
        if done == u64::MAX {
            return None;
        }
        // The callbacks run in submission order, so `before` has been stored. Natively they run
        // when something polls, so `before` may be stamped while the step already runs (it
        // would look shorter than it was): there, and where both were stamped together (a
        // page busy while the queue finished), the step counts from its submission, which
        // errs towards smaller steps.
        let before = self.before.load(Ordering::Acquire);
        let start = if cfg!(target_arch = "wasm32")
            && done.saturating_sub(before) >= STAMPED_APART_MICROS
        {
            self.submitted.max(before)
        } else {
            self.submitted
        };
        Some(done.saturating_sub(start) as f64 * 1e-6)
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
    /// The last submission, until the queue's completion callback has been seen.
    busy: Option<InFlight>,
    /// What [`InFlight`]'s times count from.
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
        let texture = FeatureTexture::new(ctx, dims, "features")?;
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
        let buffers = Buffers::new(
            ctx,
            &slabs,
            &noise_slabs,
            resampled,
            &req,
            rst_slices_per_step,
        );
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

    /// Steps so far that recorded and submitted work.
    pub fn submissions(&self) -> usize {
        self.submissions
    }

    /// GPU seconds of the last step seen done ([`InFlight::seconds`]).
    pub fn last_step_seconds(&self) -> Option<f64> {
        self.last_step_s
    }

    /// Calls `wake` whenever a step's work is done on the GPU, from the queue's completion
    /// callback (in the browser it runs as the queue finishes, so the page can take the next
    /// step without drawing frames in between; natively only when something polls the device).
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
            let flight = InFlight::submit(ctx, self.epoch, encoder.finish(), self.waker.clone());
            self.busy = Some(flight);
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

impl FeatureJob {
    /// Uploads the input box `ranges` (whole rows) into `buffers.input` (f32, physical values).
    fn upload(&self, ctx: &GpuContext, ranges: &[std::ops::Range<usize>; 3]) {
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
    fn record_slab_values(
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
                ctx,
                encoder,
                &self.buffers.input,
                src.dims,
                vol,
                dst.dims,
                1,
                &geometry,
            )?;
        }
        Ok(())
    }

    fn vol(&self) -> &wgpu::Buffer {
        self.buffers.vol.as_ref().unwrap_or(&self.buffers.input)
    }

    /// Smoothed intensity (`work[0]`) and gradient (`work[1..4]`) of the slab in `vol()`; for the
    /// RST, (I, g) packed into the texture the rays read instead of `work[1..4]`.
    fn record_gradient(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        grid: &SlabGrid,
    ) -> Result<(), PipelineError> {
        let b = &self.buffers;
        self.kernels.gaussian.record_separable(
            ctx,
            encoder,
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
                    ctx,
                    encoder,
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
                ctx,
                encoder,
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
    fn record_hessian(
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
                ctx,
                encoder,
                grid,
                &self.kernels.hessian_kernels[scale],
                self.vol(),
                &b.tmp[0],
                out,
            )
            .map_err(PipelineError::from)
    }

    /// Records one task; returns a buffer to read back when the task ends with a readback.
    fn record(
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
                    ctx,
                    encoder,
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
                    ctx,
                    encoder,
                    grid,
                    &b.work[0],
                    z0,
                    nz,
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
                self.kernels.eigen.record_part_rows(
                    ctx,
                    encoder,
                    &grid,
                    tensor,
                    z,
                    0..z.1,
                    Some([y.0, y.1]),
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
    fn record_hessian_part(
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
                ctx,
                encoder,
                &grid,
                &self.kernels.hessian_kernels[part],
                self.vol(),
                &b.tmp[0],
                out,
                pass,
                &core_box,
                first + cut.start..first + cut.end,
            )?;
        } else {
            self.record_features_of_tensor(
                ctx,
                encoder,
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

    fn tensor_output(&self, part: usize) -> TensorOutput {
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
    #[allow(clippy::too_many_arguments)]
    fn record_features_of_tensor(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
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
            .record_part_rows(
                ctx,
                encoder,
                grid,
                tensor,
                core,
                slices,
                Some([rows.0, rows.1]),
                EigenPass::Output {
                    what: self.tensor_output(part),
                    accumulate: part > 0,
                    out: &b.out_core,
                },
            )
            .map_err(PipelineError::from)
    }

    fn record_compute(
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
                    ctx,
                    encoder,
                    &grid,
                    &self.kernels.rho[part],
                    [&b.work[1], &b.work[2], &b.work[3]],
                    [&b.tmp[0], &b.tmp[1]],
                    tensor,
                )?;
                let rows = core_in_slab(&slab).1;
                self.record_features_of_tensor(
                    ctx,
                    encoder,
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
    fn record_rst(
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
        rst.record(ctx, encoder, &inputs, &dispatch, chunk)?;
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
    fn pack_box(&self, s: usize) -> PackBox {
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
    fn record_deliver(
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
                        ctx,
                        encoder,
                        &b.out_core,
                        core_dims,
                        out_in,
                        at.src_dims,
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
        self.kernels
            .pack
            .record_slices(ctx, encoder, &features, &self.texture, at, done..done + n);
        let finished = done + n >= slices;
        self.pass_cursor = if finished { 0 } else { done + n };
        let bytes = 3 * at.src_dims.iter().map(|&d| u64::from(d)).product::<u64>() * 4;
        let read =
            (finished && self.options.export).then_some((features, bytes, ReadFor::Export(s)));
        Ok((read, finished))
    }
}
/// Convolution work of the Hessian's passes over `slabs` (each pass over [`hessian::pass_region`]
/// of its brick's core, weighed by its storage accesses) over the same work if every brick were
/// its core alone: the halo overhead of the Hessian methods.
fn hessian_work_overhead(
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

#[cfg(test)]
mod tests {
    use super::*;

    fn flight(submitted: u64, before: u64, done: u64) -> InFlight {
        InFlight {
            submitted,
            before: Arc::new(AtomicU64::new(before)),
            done: Arc::new(AtomicU64::new(done)),
        }
    }

    #[test]
    fn a_step_is_timed_from_when_the_work_queued_before_it_was_done() {
        // Microseconds of a step's measured seconds (`None` while not done).
        let micros = |f: InFlight| f.seconds().map(|s| (s * 1e6).round() as u64);
        // Not done yet.
        assert_eq!(micros(flight(0, 500_000, u64::MAX)), None);
        // A frame queued ahead ran 0.5 s after the submission: in the browser the step is the
        // 0.25 s after it; natively (stamps taken when polled) from the submission.
        let want = if cfg!(target_arch = "wasm32") {
            250_000
        } else {
            750_000
        };
        assert_eq!(micros(flight(100_000, 600_000, 850_000)), Some(want));
        // The queue was idle at the submission (its callback ran at once, before it).
        assert_eq!(micros(flight(100_000, 90_000, 400_000)), Some(300_000));
        // Both callbacks stamped by one poll: when the step started is unknown, so from the
        // submission (the step never looks shorter than it may have been).
        assert_eq!(micros(flight(100_000, 700_000, 700_050)), Some(600_050));
    }
}
