//! Pacing of the feature job's steps: how much work the next step holds ([`StepPace`]) and how
//! long a submitted step took on the queue ([`InFlight`]).

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use crate::gpu::GpuContext;

/// Paces a kind of step to [`JobOptions::step_seconds`](super::JobOptions::step_seconds) of GPU time: the first step holds the
/// least work allowed; each finished step measures the device's work per second over the step's
/// own time on the queue ([`InFlight`]: from when the work queued before it was done, or its
/// submission if later, to its own completion), so that the viewer's frames queued before it do
/// not count as the step's; the step follows a slower rate at once and a faster one at most
/// doubling per step. Work is counted in a unit of the step's kind: ray
/// voxels for the RST, storage accesses for the Hessian's convolutions, voxels for the
/// eigenvalue pass.
pub(super) struct StepPace {
    pub(super) seconds: Option<f64>,
    /// Work per second, once measured.
    rate: Option<f64>,
    /// Work of the step in flight.
    in_flight: Option<f64>,
    /// The last step's work.
    last: f64,
}

impl StepPace {
    pub(super) fn new(seconds: Option<f64>) -> Self {
        Self {
            seconds,
            rate: None,
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
        let want = match self.rate {
            None => min,
            Some(rate) => (rate * seconds).min(2.0 * self.last),
        };
        want.clamp(min.min(max), max)
    }

    pub(super) fn submitted(&mut self, work: f64) {
        self.last = work;
        self.in_flight = self.seconds.map(|_| work);
    }

    /// The step in flight, if it was this kind's, took `secs` on the queue ([`InFlight`]).
    pub(super) fn finished(&mut self, secs: f64) {
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
pub(super) struct InFlight {
    submitted: u64,
    before: Arc<AtomicU64>,
    done: Arc<AtomicU64>,
}

/// What a job calls when a step is done on the GPU ([`FeatureJob::set_waker`]).
pub type Waker = Arc<dyn Fn() + Send + Sync>;

/// Callbacks stamped closer than this ran together (one poll, one task of the page).
const STAMPED_APART_MICROS: u64 = 1000;

impl InFlight {
    pub(super) fn submit(
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
    pub(super) fn seconds(&self) -> Option<f64> {
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
