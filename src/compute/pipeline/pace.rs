//! How much work a feature-job step holds (issue "full-size scans", deliver 5: no frame of the
//! viewer waits on more than ~100 ms of GPU work, or on much more than the viewer's own frame
//! costs on a device whose frames are slow).
//!
//! Two ways to know what a step cost:
//! - natively the queue's completion callback times each step ([`StepPace::finished`]);
//! - in the browser that callback reaches the page with its next task, a frame later, so a
//!   step's measured time is at least a frame and says nothing about its work. There the step
//!   follows the viewer's frames instead ([`FramePace`]): the frame intervals while a step was
//!   in flight against those without one.

/// Paces a kind of step to [`super::JobOptions::step_seconds`] of GPU time: the first step
/// holds the least work allowed; each finished step measures the device's work per second,
/// from the submission to the queue's completion callback (work of the viewer's frames queued
/// before it counts too, which errs towards smaller steps); the step follows a slower rate at
/// once and a faster one at most doubling per step. Work is counted in a unit of the step's
/// kind: ray voxels for the RST, storage accesses for the Hessian's convolutions, voxels for
/// the eigenvalue pass.
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

    /// The step in flight, if it was this kind's, took `secs` from its submission to the
    /// queue's completion callback.
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

    /// The step in flight, if it was this kind's, is done, and the viewer's frames while it
    /// ran stayed within their target (`over` false) or did not: the next step of this kind
    /// holds twice its work, or half of it (never less than the smallest step, see
    /// [`Self::work`]).
    pub(super) fn finished_by_frames(&mut self, over: bool) {
        let (Some(seconds), Some(work)) = (self.seconds, self.in_flight.take()) else {
            return;
        };
        let factor = if over { 0.5 } else { 2.0 };
        self.rate = Some(work * factor / seconds);
    }
}

/// The browser's measure of a step: frame intervals. An interval during which a step was in
/// flight (from its submission to the frame that sees it done) is "busy"; one during which
/// none was is "idle" and shows what the viewer's own frames cost. A step is over when a busy
/// interval exceeds the idle one by more than the step's allowance: as much as an idle frame,
/// at least [`Self::MIN_ALLOWANCE_S`], at most [`Self::MAX_ALLOWANCE_S`] (the native viewer's
/// rule, `app::features::step_seconds_for`). Every [`Self::IDLE_EVERY`] steps the job leaves
/// one frame without a step ([`Self::wants_idle_frame`]), so the idle interval stays measured
/// while the job runs.
#[derive(Clone, Debug)]
pub struct FramePace {
    /// The idle frame interval: a running mean of idle intervals, following a faster one at once.
    idle_s: Option<f64>,
    /// A step is in flight.
    in_flight: bool,
    /// The interval now running carries a step.
    carried: bool,
    /// The longest busy interval of the step in flight (or just done).
    worst_busy_s: f64,
    /// Steps since the last idle interval.
    steps_since_idle: usize,
}

impl Default for FramePace {
    fn default() -> Self {
        Self::new()
    }
}

impl FramePace {
    pub const MIN_ALLOWANCE_S: f64 = 0.1;
    pub const MAX_ALLOWANCE_S: f64 = 1.0;
    pub const IDLE_EVERY: usize = 4;

    pub fn new() -> Self {
        Self {
            idle_s: None,
            in_flight: false,
            carried: false,
            worst_busy_s: 0.0,
            steps_since_idle: 0,
        }
    }

    /// A frame started, `frame_s` after the last one.
    pub fn frame(&mut self, frame_s: f64) {
        if frame_s.is_finite() && frame_s > 0.0 {
            if self.carried {
                self.worst_busy_s = self.worst_busy_s.max(frame_s);
            } else {
                self.steps_since_idle = 0;
                self.idle_s = Some(match self.idle_s {
                    Some(idle) if frame_s > idle => idle + 0.2 * (frame_s - idle),
                    _ => frame_s,
                });
            }
        }
        self.carried = self.in_flight;
    }

    /// A step was submitted.
    pub fn submitted(&mut self) {
        self.in_flight = true;
        self.carried = true;
        self.worst_busy_s = 0.0;
        self.steps_since_idle += 1;
    }

    /// The step in flight is seen done: whether it made a frame wait longer than
    /// [`Self::target_s`].
    pub fn completed(&mut self) -> bool {
        self.in_flight = false;
        self.carried = false;
        self.worst_busy_s > self.target_s()
    }

    /// The longest frame interval a step may cause.
    pub fn target_s(&self) -> f64 {
        let idle = self.idle_s.unwrap_or(0.0);
        idle + idle.clamp(Self::MIN_ALLOWANCE_S, Self::MAX_ALLOWANCE_S)
    }

    /// The job should leave this frame without a step (the idle interval is due, or unknown).
    pub fn wants_idle_frame(&self) -> bool {
        !self.in_flight && (self.idle_s.is_none() || self.steps_since_idle >= Self::IDLE_EVERY)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A simulated browser: a frame costs `idle` plus the work of a step submitted before it
    /// (`work / rate`), a share `spill` of it showing one frame later; the step's completion
    /// is seen two frames after its submission (the callback a frame late). The step must grow
    /// from its smallest size to about the allowance and stay there: frames near the target,
    /// never far beyond it.
    fn simulate(idle: f64, rate: f64, spill: f64) -> (Vec<f64>, f64, usize) {
        let seconds = 0.1;
        let mut pace = StepPace::new(Some(seconds));
        let mut frames = FramePace::new();
        let (min, max) = (1.0, 1e12);
        let mut intervals = Vec::new();
        let mut in_flight: Option<usize> = None; // the frame it was submitted in
        let (mut now, mut next) = (0.0, 0.0);
        let mut steps = 0;
        for frame in 0..600 {
            let frame_s = idle + now;
            (now, next) = (next, 0.0);
            frames.frame(frame_s);
            intervals.push(frame_s);
            if let Some(at) = in_flight
                && frame >= at + 2
            {
                in_flight = None;
                pace.finished_by_frames(frames.completed());
            }
            if in_flight.is_none() && !frames.wants_idle_frame() {
                let work = pace.work(min, max);
                pace.submitted(work);
                frames.submitted();
                in_flight = Some(frame);
                steps += 1;
                now += (1.0 - spill) * work / rate;
                next += spill * work / rate;
            }
        }
        (intervals, frames.target_s(), steps)
    }

    #[test]
    fn steps_follow_the_frames_to_the_allowance() {
        // SwiftShader-like frames of 0.45 s, a fast GPU, a very slow device; the work seen in
        // the next frame, or half of it a frame later still.
        for (idle, rate) in [(0.45, 1e6), (0.016, 1e8), (2.0, 1e5)] {
            for spill in [0.0, 0.5] {
                let (intervals, target, steps) = simulate(idle, rate, spill);
                let allowance = idle.clamp(FramePace::MIN_ALLOWANCE_S, FramePace::MAX_ALLOWANCE_S);
                assert!(
                    (target - (idle + allowance)).abs() < 1e-9,
                    "idle {idle}, spill {spill}: target {target}"
                );
                // After the start, no frame waits more than twice the allowance beyond idle
                // (one doubling past the target before it is seen).
                let settled = &intervals[100..];
                let worst = settled.iter().copied().fold(0.0, f64::max);
                assert!(
                    worst <= idle + 2.0 * allowance + 1e-9,
                    "idle {idle}, rate {rate}, spill {spill}: a frame took {worst} s"
                );
                // The steps do grow: the job's work over the settled frames is at least a
                // fifth of the allowance per frame (a step stuck at its smallest size, 1 unit,
                // would carry ~nothing).
                let work: f64 = settled.iter().map(|s| s - idle).sum();
                assert!(
                    work >= 0.2 * allowance * settled.len() as f64,
                    "idle {idle}, rate {rate}, spill {spill}: {work} s of work in {} frames, {steps} steps",
                    settled.len()
                );
            }
        }
    }

    #[test]
    fn an_idle_frame_that_gets_slower_moves_the_target_slowly_and_a_faster_one_at_once() {
        let mut f = FramePace::new();
        assert!(f.wants_idle_frame());
        f.frame(0.5);
        assert!((f.target_s() - 1.0).abs() < 1e-12);
        assert!(!f.wants_idle_frame());
        f.frame(1.5);
        assert_eq!(f.idle_s.map(|s| (s - 0.7).abs() < 1e-12), Some(true));
        f.frame(0.1);
        assert!((f.target_s() - 0.2).abs() < 1e-12);
        // Nonsense intervals are ignored.
        f.frame(f64::NAN);
        f.frame(-1.0);
        assert!((f.target_s() - 0.2).abs() < 1e-12);
    }

    #[test]
    fn a_frame_over_the_target_halves_the_next_step() {
        let mut pace = StepPace::new(Some(0.1));
        let mut frames = FramePace::new();
        frames.frame(0.2); // idle: target 0.4
        pace.submitted(1000.0);
        frames.submitted();
        frames.frame(0.9);
        pace.finished_by_frames(frames.completed());
        assert_eq!(pace.work(1.0, 1e9), 500.0);
        pace.submitted(500.0);
        frames.submitted();
        frames.frame(0.3);
        pace.finished_by_frames(frames.completed());
        assert_eq!(pace.work(1.0, 1e9), 1000.0);
    }
}
