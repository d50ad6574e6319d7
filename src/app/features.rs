//! The features the app computes and keeps: the display mode (intensity, Hessian, RST, Li,
//! Frangi, GST), the parameters (preset, scales, rays, transfer function, map), the cache of
//! computed [`FeatureTexture`]s keyed by method and parameters (switching modes never recomputes
//! what exists), and the one running [`FeatureJob`], stepped once per frame and cancellable.

use super::error::AppError;
use crate::compute::pipeline::{FeatureJob, JobOptions, JobState, Waker};
use crate::cpu::features::FeatureMap;
use crate::cpu::pipeline::{Method, Request};
use crate::cpu::rays::RAY_COUNTS;
use crate::cpu::rst::DEFAULT_STEP_MM;
use crate::cpu::tf::{Preset, TransferFunction};
use crate::gpu::GpuContext;
use crate::gpu::budget::{GpuBudget, level_text};
use crate::gpu::volume_texture::FeatureTexture;
use crate::volume::Volume;
use std::sync::Arc;

mod ui;

pub use ui::{params_ui, preset_label};

/// GPU seconds of work per feature-job step while the viewer runs (the RST's rays, the
/// Hessian's passes, its eigenvalue pass and storing; issue "full-size scans", deliver 5: no
/// frame waits on more than ~100 ms of GPU work).
pub const STEP_SECONDS: f64 = 0.1;

/// The most a step may hold on a device whose own frames are slow (see [`step_seconds_for`]).
pub const MAX_STEP_SECONDS: f64 = 1.0;

/// The step the job may take in a frame that took `frame_s` (between the starts of the last
/// two frames), of which the last feature step took `step_s` on the GPU: [`STEP_SECONDS`], or,
/// where the viewer's own frames cost more than that (a software adapter: SwiftShader draws
/// about two frames a second), as much as a frame costs without the job, up to
/// [`MAX_STEP_SECONDS`]. A frame then waits at most as long again behind feature work, and the
/// job keeps about half of a slow device instead of a tenth or less.
pub fn step_seconds_for(frame_s: f64, step_s: f64) -> f64 {
    let own = frame_s - step_s;
    if own.is_finite() {
        own.clamp(STEP_SECONDS, MAX_STEP_SECONDS)
    } else {
        STEP_SECONDS
    }
}

/// Whether the viewer's feature jobs go in paced steps ([`STEP_SECONDS`]): natively, and in
/// the browser on a hardware adapter. A software adapter in the browser (SwiftShader) keeps
/// whole passes and fixed ray chunks: there the GPU process renders on the same CPU cores, a
/// step's completion can reach the page after frames queued behind it, and a step
/// took 0.25-0.38 s whether it held one line of a pass or two, so paced steps ran the job
/// about 4.5 times slower (bench.mjs 64, Li: 44% after 677 s, against done in 314 s with whole
/// passes; docs/performance.md).
pub fn paced(ctx: &GpuContext) -> bool {
    !(ctx.in_browser() && ctx.is_software())
}

/// What the MIP and the slice overlay show.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DisplayMode {
    Intensity,
    Features(Method),
}

impl DisplayMode {
    pub const ALL: [Self; 6] = [
        Self::Intensity,
        Self::Features(Method::Hessian),
        Self::Features(Method::Rst),
        Self::Features(Method::Li),
        Self::Features(Method::Frangi),
        Self::Features(Method::Gst),
    ];

    /// The name the status and URLs use.
    pub fn name(self) -> &'static str {
        match self {
            Self::Intensity => "intensity",
            Self::Features(m) => method_name(m),
        }
    }

    /// The label of its button.
    pub fn label(self) -> &'static str {
        match self {
            Self::Intensity => "Intensity",
            Self::Features(Method::Hessian) => "Hessian",
            Self::Features(Method::Rst) => "RST",
            Self::Features(Method::Li) => "Li",
            Self::Features(Method::Frangi) => "Frangi",
            Self::Features(Method::Gst) => "GST",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }

    pub fn method(self) -> Option<Method> {
        match self {
            Self::Intensity => None,
            Self::Features(m) => Some(m),
        }
    }
}

pub fn method_name(m: Method) -> &'static str {
    match m {
        Method::Hessian => "hessian",
        Method::Rst => "rst",
        Method::Li => "li",
        Method::Frangi => "frangi",
        Method::Gst => "gst",
    }
}

/// The mode the app opens on: the Hessian (blobness on the Li map), the lighter family,
/// computed in seconds; the RST (the paper's method, rays from every voxel: several times
/// longer) is one click away and never starts on its own.
pub const DEFAULT_MODE: DisplayMode = DisplayMode::Features(Method::Hessian);

/// The parameters the panel edits; a [`Request`] per method is made from them.
#[derive(Clone, Debug, PartialEq)]
pub struct FeatureParams {
    pub preset: Preset,
    /// Hessian scales (and the structure tensor's neighbourhood scales), mm.
    pub sigma_min_mm: f64,
    pub sigma_max_mm: f64,
    pub sigma_count: usize,
    pub rays: usize,
    pub radius_mm: f64,
    pub step_mm: f64,
    /// `None`: the automatic transfer function (the preset refined by the measured noise).
    pub tf: Option<TransferFunction>,
    /// Eq. 1 or Li's map, for the RST and the structure tensor.
    pub map: FeatureMap,
}

impl FeatureParams {
    pub fn from_preset(preset: Preset) -> Self {
        let s = preset.sigmas_mm();
        Self {
            preset,
            sigma_min_mm: s.first().copied().unwrap_or(1.0),
            sigma_max_mm: s.last().copied().unwrap_or(4.0),
            sigma_count: s.len().max(1),
            rays: 42,
            radius_mm: preset.radius_mm(),
            step_mm: DEFAULT_STEP_MM,
            tf: None,
            map: FeatureMap::Li,
        }
    }

    /// The scales: the preset's own list when the range is the preset's, else geometric from
    /// min to max.
    pub fn sigmas_mm(&self) -> Vec<f64> {
        let preset = self.preset.sigmas_mm();
        if preset.first() == Some(&self.sigma_min_mm)
            && preset.last() == Some(&self.sigma_max_mm)
            && preset.len() == self.sigma_count
        {
            return preset;
        }
        let n = self.sigma_count.max(1);
        let (lo, hi) = (self.sigma_min_mm, self.sigma_max_mm.max(self.sigma_min_mm));
        if n == 1 || hi <= lo {
            return vec![lo];
        }
        (0..n)
            .map(|i| {
                let t = i as f64 / (n - 1) as f64;
                let s = lo * (hi / lo).powf(t);
                (s * 1000.0).round() / 1000.0
            })
            .collect()
    }

    /// The request for `method`, with only the parameters that method uses (so that changing
    /// the RST's rays does not make the Hessian look stale).
    pub fn request(&self, method: Method) -> Request {
        let mut r = Request::new(method);
        r.preset = self.preset;
        match method {
            Method::Rst => {
                r.rays = Some(self.rays);
                r.radius_mm = Some(self.radius_mm);
                r.step_mm = Some(self.step_mm);
                r.tf = self.tf;
                r.rst_map = self.map;
            }
            Method::Gst => {
                r.sigmas_mm = Some(self.sigmas_mm());
                r.rst_map = self.map;
            }
            Method::Hessian | Method::Li | Method::Frangi => {
                // The preset's own scales go unnamed, so that the pipeline drops those below
                // half the slice spacing (docs/science.md, "Thick slices"); scales the user
                // changed are named and kept.
                let sigmas = self.sigmas_mm();
                r.sigmas_mm = (sigmas != self.preset.sigmas_mm()).then_some(sigmas);
            }
        }
        r
    }
}

/// On/off and gain of each feature (V, A, B) and the overlay's opacity on the slices.
#[derive(Clone, Debug, PartialEq)]
pub struct FeatureDisplay {
    pub enabled: [bool; 3],
    pub gain: [f32; 3],
    pub overlay_on_slices: bool,
    pub opacity: f32,
}

impl Default for FeatureDisplay {
    fn default() -> Self {
        Self {
            enabled: [true; 3],
            gain: [1.0; 3],
            overlay_on_slices: true,
            opacity: 1.0,
        }
    }
}

impl FeatureDisplay {
    /// Per feature: opacity = clamp(value * scale, 0, 1) with scale = gain / the feature's
    /// reference (`FeatureTexture::reference`: its 99.9th percentile of positive values), as
    /// the MIP composites it (gain 1: the reference is full colour; 2: half of it).
    /// While the maximum is unknown (0), 100 units stand in for it.
    pub fn scales(&self, max: [f32; 3]) -> [f32; 3] {
        std::array::from_fn(|c| {
            if !self.enabled[c] {
                return 0.0;
            }
            let reference = if max[c] > 0.0 { max[c] } else { 100.0 };
            self.gain[c] / reference
        })
    }
}

/// One computed method, kept on the GPU.
pub struct FeatureEntry {
    pub request: Request,
    pub texture: FeatureTexture,
    pub notes: Vec<String>,
    /// Unique per computation (slice panes redraw when it changes).
    pub id: u64,
    last_used: u64,
}

struct Running {
    request: Request,
    job: FeatureJob,
    fraction: f32,
    stage: String,
    started: web_time::Instant,
}

/// How the last job ended.
#[derive(Clone, Debug, PartialEq)]
pub enum JobOutcome {
    Done,
    Cancelled,
    Failed(String),
}

/// What [`FeatureManager::step`] reports.
pub enum JobEvent {
    Finished { method: Method, notes: Vec<String> },
    Failed(String),
}

/// Features kept on the GPU for the loaded volume, and the job computing one more.
pub struct FeatureManager {
    entries: Vec<FeatureEntry>,
    running: Option<Running>,
    last: Option<(Request, JobOutcome)>,
    next_id: u64,
    clock: u64,
    /// Bytes of feature textures kept at most (the newest is always kept).
    budget_bytes: u64,
    /// The GPU budget of the volume textures: what decides each job's feature level.
    gpu_budget: GpuBudget,
    /// Given to every job: asks the viewer for a frame when a step is done.
    waker: Option<Waker>,
}

impl Default for FeatureManager {
    fn default() -> Self {
        Self {
            entries: Vec::new(),
            running: None,
            last: None,
            next_id: 1,
            clock: 0,
            budget_bytes: 1 << 30,
            gpu_budget: GpuBudget::user_mib(1536),
            waker: None,
        }
    }
}

impl FeatureManager {
    /// A manager whose jobs keep their features within `budget` (with the intensity).
    pub fn with_budget(budget: GpuBudget) -> Self {
        Self {
            gpu_budget: budget,
            ..Self::default()
        }
    }

    /// The GPU budget the jobs plan with.
    pub fn gpu_budget(&self) -> GpuBudget {
        self.gpu_budget
    }

    /// What jobs call when a step is done on the GPU (the viewer: ask for a frame).
    pub fn set_waker(&mut self, wake: Waker) {
        self.waker = Some(wake);
    }

    /// Forgets everything (a new volume).
    pub fn clear(&mut self) {
        self.entries.clear();
        self.running = None;
        self.last = None;
    }

    pub fn find(&self, request: &Request) -> Option<&FeatureEntry> {
        self.entries.iter().find(|e| &e.request == request)
    }

    /// Marks an entry as used now (for eviction), returning it.
    pub fn touch(&mut self, request: &Request) -> Option<&FeatureEntry> {
        self.clock += 1;
        let clock = self.clock;
        let e = self.entries.iter_mut().find(|e| &e.request == request)?;
        e.last_used = clock;
        Some(e)
    }

    /// Every method kept (for a MIP widget that offers them by name).
    pub fn entries(&self) -> impl Iterator<Item = &FeatureEntry> {
        self.entries.iter()
    }

    /// How many methods are kept.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    pub fn running_request(&self) -> Option<&Request> {
        self.running.as_ref().map(|r| &r.request)
    }

    /// (fraction, stage) of the running job.
    pub fn progress(&self) -> Option<(f32, &str)> {
        self.running
            .as_ref()
            .map(|r| (r.fraction, r.stage.as_str()))
    }

    /// Seconds the running job has run, and an estimate of the seconds left from its progress
    /// so far (`None` until it has made some).
    pub fn timing(&self) -> Option<(f64, Option<f64>)> {
        let r = self.running.as_ref()?;
        let elapsed = r.started.elapsed().as_secs_f64();
        let f = f64::from(r.fraction);
        let left = (f > 0.01 && f < 1.0).then(|| elapsed * (1.0 - f) / f);
        Some((elapsed, left))
    }

    /// How the last job for `request` ended, if it was the last one.
    pub fn outcome(&self, request: &Request) -> Option<&JobOutcome> {
        self.last
            .as_ref()
            .filter(|(r, _)| r == request)
            .map(|(_, o)| o)
    }

    /// Starts computing `request` (cancelling any other job).
    pub fn start(
        &mut self,
        ctx: &GpuContext,
        volume: &Arc<Volume>,
        request: Request,
    ) -> Result<(), AppError> {
        self.cancel();
        // The job reads its slices from the loaded volume itself (no copy per computation).
        // Its steps follow the device's speed, so that a frame of the viewer never waits behind
        // more than `STEP_SECONDS` of feature work (more only where its own frames are slower):
        // a step is timed by the device's timestamps around it (or, without them, from when
        // the work queued before it was done), so a slow frame does not count as the step's.
        // The level that fits the budget beside the intensity (0: full resolution); the
        // methods kept share the same bytes.
        let dims = volume.dims.map(|d| u32::try_from(d).unwrap_or(u32::MAX));
        let feature_level = self
            .gpu_budget
            .feature_level(dims, ctx.limits.max_texture_dimension_3d);
        self.budget_bytes = self.gpu_budget.features_of(dims);
        let options = JobOptions {
            step_seconds: paced(ctx).then_some(STEP_SECONDS),
            feature_level,
            ..JobOptions::default()
        };
        let job = FeatureJob::shared(ctx, Arc::clone(volume), &request, options);
        match job {
            Ok(mut job) => {
                if let Some(wake) = &self.waker {
                    job.set_waker(Arc::clone(wake));
                }
                let (fraction, stage) = match job.state() {
                    JobState::Running { fraction, stage } => (fraction, stage),
                    JobState::Done => (1.0, "done".to_owned()),
                };
                self.running = Some(Running {
                    request,
                    job,
                    fraction,
                    stage,
                    started: web_time::Instant::now(),
                });
                Ok(())
            }
            Err(source) => {
                let e = AppError::Features {
                    method: method_name(request.method),
                    source,
                };
                self.last = Some((request, JobOutcome::Failed(e.message())));
                Err(e)
            }
        }
    }

    pub fn cancel(&mut self) {
        if let Some(r) = self.running.take() {
            self.last = Some((r.request, JobOutcome::Cancelled));
        }
    }

    /// Advances the running job by one step; `frame_s` is the time between the starts of the
    /// last two frames (the step follows [`step_seconds_for`]).
    pub fn step(&mut self, ctx: &GpuContext, frame_s: f64) -> Option<JobEvent> {
        let running = self.running.as_mut()?;
        // In the browser a frame waits for the job's waker or a timer, so the frame interval
        // is not what a frame costs: steps stay at `STEP_SECONDS` there.
        if let Some(step_s) = running.job.last_step_seconds()
            && paced(ctx)
            && !ctx.in_browser()
        {
            let seconds = step_seconds_for(frame_s, step_s);
            running.job.set_step_seconds(Some(seconds));
        }
        match running.job.step(ctx) {
            Ok(JobState::Running { fraction, stage }) => {
                running.fraction = fraction;
                running.stage = stage;
                None
            }
            Ok(JobState::Done) => {
                let r = self.running.take()?;
                let mut notes = r.job.notes().to_vec();
                let level = r.job.feature_level();
                if level > 0 {
                    notes.push(format!(
                        "features kept at {} within the GPU budget of {} MiB: the MIP shows every maximum; the slices and the probe show a block's maximum; findings need full resolution",
                        level_text(level),
                        self.gpu_budget.mib()
                    ));
                }
                let method = r.request.method;
                match r.job.finish() {
                    Some(texture) => {
                        self.insert(r.request.clone(), texture, notes.clone());
                        self.last = Some((r.request, JobOutcome::Done));
                        Some(JobEvent::Finished { method, notes })
                    }
                    None => {
                        let message = format!(
                            "{}: the computation ended without a result",
                            method_name(method)
                        );
                        self.last = Some((r.request, JobOutcome::Failed(message.clone())));
                        Some(JobEvent::Failed(message))
                    }
                }
            }
            Err(e) => {
                let r = self.running.take()?;
                let message = format!("{}: {e}", method_name(r.request.method));
                self.last = Some((r.request, JobOutcome::Failed(message.clone())));
                Some(JobEvent::Failed(message))
            }
        }
    }

    /// GPU memory the kept methods' textures hold, and the budget beyond which the least
    /// recently used is dropped, bytes.
    pub fn memory(&self) -> (u64, u64) {
        let used = self.entries.iter().map(|e| e.texture.bytes()).sum();
        (used, self.budget_bytes)
    }

    fn insert(&mut self, request: Request, texture: FeatureTexture, notes: Vec<String>) {
        self.entries.retain(|e| e.request != request);
        self.clock += 1;
        let bytes_each = texture.bytes();
        self.entries.push(FeatureEntry {
            request,
            texture,
            notes,
            id: self.next_id,
            last_used: self.clock,
        });
        self.next_id += 1;
        // Evict the least recently used until the rest fits (never the newest).
        while self.entries.len() > 1 && self.entries.len() as u64 * bytes_each > self.budget_bytes {
            let Some(oldest) = self
                .entries
                .iter()
                .enumerate()
                .min_by_key(|(_, e)| e.last_used)
                .map(|(i, _)| i)
            else {
                break;
            };
            self.entries.remove(oldest);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_step_is_100_ms_unless_the_viewers_own_frames_cost_more() {
        // A fast device: 16 ms frames plus the step.
        assert_eq!(step_seconds_for(0.116, 0.1), STEP_SECONDS);
        assert_eq!(step_seconds_for(0.016, 0.0), STEP_SECONDS);
        // A software adapter: frames of 0.5 s of their own get steps as long.
        assert!((step_seconds_for(0.6, 0.1) - 0.5).abs() < 1e-12);
        // Stable: a frame that waited behind such a step asks for the same again.
        assert!((step_seconds_for(1.0, 0.5) - 0.5).abs() < 1e-12);
        // Bounded, and sane on odd clocks.
        assert_eq!(step_seconds_for(30.0, 0.1), MAX_STEP_SECONDS);
        assert_eq!(step_seconds_for(0.05, 0.3), STEP_SECONDS);
        assert_eq!(step_seconds_for(f64::NAN, 0.1), STEP_SECONDS);
    }

    #[test]
    fn requests_carry_only_what_the_method_uses() {
        let mut p = FeatureParams::from_preset(Preset::LungNodules);
        let h = p.request(Method::Hessian);
        let r = p.request(Method::Rst);
        assert_eq!(h.sigmas_mm, None, "the preset's scales go unnamed");
        assert_eq!(r.radius_mm, Some(25.0));
        assert_eq!(r.rst_map, FeatureMap::Li);
        p.rays = 98;
        assert_eq!(
            p.request(Method::Hessian),
            h,
            "rays do not touch the Hessian"
        );
        assert_ne!(p.request(Method::Rst), r);
        p.sigma_min_mm = 1.0;
        p.sigma_max_mm = 8.0;
        p.sigma_count = 4;
        assert_eq!(p.sigmas_mm(), vec![1.0, 2.0, 4.0, 8.0]);
    }

    #[test]
    fn mode_names_round_trip() {
        for m in DisplayMode::ALL {
            assert_eq!(DisplayMode::from_name(m.name()), Some(m));
        }
        assert_eq!(DisplayMode::from_name("nope"), None);
    }

    #[test]
    fn display_scales() {
        let mut d = FeatureDisplay::default();
        assert_eq!(d.scales([100.0, 0.0, 40.0]), [0.01, 0.01, 0.025]);
        d.enabled[1] = false;
        d.gain[2] = 2.0;
        assert_eq!(d.scales([100.0, 0.0, 40.0]), [0.01, 0.0, 0.05]);
    }
}
