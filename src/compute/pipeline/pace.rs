//! Pacing of the feature job's steps: how much work the next step holds ([`StepPace`]); how
//! long a submitted step took is [`GpuSpan`]'s to say, the clock progressive rendering shares.
//!
//! [`GpuSpan`]: crate::gpu::timing::GpuSpan

use crate::gpu::timing::Rate;

/// Paces a kind of step to [`JobOptions::step_seconds`](super::JobOptions::step_seconds) of GPU
/// time: the first step holds the least work allowed; each finished step measures the device's
/// work per second over the step's own GPU time ([`GpuSpan`](crate::gpu::timing::GpuSpan): the
/// device's timestamps, else the queue's callbacks), so that the viewer's frames queued before
/// it do not count as the step's; the rate learns by [`Rate`]'s rule, and a step holds at most
/// twice the last one's work. Work is counted in a unit of the step's kind: ray voxels for the RST,
/// storage accesses for the Hessian's convolutions, voxels for the eigenvalue pass.
pub(super) struct StepPace {
    pub(super) seconds: Option<f64>,
    /// Work per second, once measured.
    rate: Rate,
    /// Work of the step in flight.
    in_flight: Option<f64>,
    /// The last step's work.
    last: f64,
}

impl StepPace {
    pub(super) fn new(seconds: Option<f64>) -> Self {
        Self {
            seconds,
            rate: Rate::default(),
            in_flight: None,
            last: 0.0,
        }
    }

    /// Work for the next step: `max` without pacing; with it, what the measured rate does in
    /// the step's seconds, between `min` (the smallest step there is) and `max`.
    pub(super) fn work(&self, min: f64, max: f64) -> f64 {
        let Some(seconds) = self.seconds else {
            return max;
        };
        let want = match self.rate.get() {
            None => min,
            Some(rate) => (rate * seconds).min(2.0 * self.last),
        };
        want.clamp(min.min(max), max)
    }

    pub(super) fn submitted(&mut self, work: f64) {
        self.last = work;
        self.in_flight = self.seconds.map(|_| work);
    }

    /// The step in flight, if it was this kind's, took `secs` of GPU time.
    pub(super) fn finished(&mut self, secs: f64) {
        let Some(work) = self.in_flight.take() else {
            return;
        };
        self.rate.observe(work, secs);
    }
}

/// What a job calls when a step is done on the GPU ([`FeatureJob::set_waker`]).
///
/// [`FeatureJob::set_waker`]: super::FeatureJob::set_waker
pub type Waker = crate::gpu::timing::Wake;
