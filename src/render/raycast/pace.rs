//! Progressive rendering's clock: how many samples ([`super::FrameCost`]) this device's GPU
//! projects per second, measured on the frames themselves, and from it how much of a frame fits
//! in one frame's GPU budget.
//!
//! A measurement runs from just before a submission to the queue's "work done" callback, so it
//! includes queueing behind other work and the wait for the next poll: the rate is an
//! underestimate, and bands come out smaller than the budget rather than larger.

use std::sync::{Arc, Mutex};

use web_time::Instant;

use crate::gpu::GpuContext;

/// First guess of the rate (samples per second) before a kind of frame was measured: below a
/// software renderer's (lavapipe on two cores: ~100 M/s intensity only, ~15 M/s with features);
/// a real GPU measures higher within a few frames.
pub const INITIAL_SAMPLES_PER_S: f64 = 10e6;

/// The measured rate and the budget per frame.
pub struct FramePacer {
    /// GPU seconds one frame may take; `None`: frames are drawn whole, whatever they cost.
    pub budget_s: Option<f64>,
    /// Measured rates per kind of frame (intensity only, with features: a feature sample costs
    /// several times an intensity one, and skips less), `None` until measured.
    rates: [Option<f64>; 2],
    /// The kind of the frames being planned.
    kind: usize,
    /// The rate is given, never measured (tests, benchmarks).
    fixed: Option<f64>,
    measuring: Option<Measure>,
}

struct Measure {
    start: Instant,
    samples: f64,
    kind: usize,
    done: Arc<Mutex<Option<Instant>>>,
}

impl FramePacer {
    pub fn new(budget_s: Option<f64>) -> Self {
        Self {
            budget_s,
            rates: [None; 2],
            kind: 0,
            fixed: None,
            measuring: None,
        }
    }

    /// A pacer with a given rate that it never measures (reproducible bands in tests).
    pub fn fixed(budget_s: Option<f64>, samples_per_s: f64) -> Self {
        Self {
            budget_s,
            rates: [None; 2],
            kind: 0,
            fixed: Some(samples_per_s.max(1.0)),
            measuring: None,
        }
    }

    /// Plans the following frames for a scene with or without features.
    pub fn set_scene(&mut self, with_features: bool) {
        self.kind = usize::from(with_features);
    }

    /// Samples per second of the current kind of frame, measured (or the first guess).
    pub fn rate(&self) -> f64 {
        self.fixed
            .or(self.rates[self.kind])
            .unwrap_or(INITIAL_SAMPLES_PER_S)
    }

    /// Whether [`Self::rate`] comes from a measurement.
    pub fn measured(&self) -> bool {
        self.fixed.is_some() || self.rates[self.kind].is_some()
    }

    /// How many samples one frame may cost; infinite without a budget.
    pub fn budget_samples(&self) -> f64 {
        match self.budget_s {
            Some(s) if s.is_finite() && s > 0.0 => s * self.rate(),
            _ => f64::INFINITY,
        }
    }

    /// Call right after submitting `samples` samples of work, with the time taken just before
    /// the submission: times it if no other measurement is running.
    pub fn submitted(&mut self, ctx: &GpuContext, samples: f64, start: Instant) {
        if self.fixed.is_some() || self.measuring.is_some() || samples.is_nan() || samples <= 0.0 {
            return;
        }
        let done = Arc::new(Mutex::new(None));
        let d = Arc::clone(&done);
        ctx.queue.on_submitted_work_done(move || {
            if let Ok(mut d) = d.lock() {
                *d = Some(Instant::now());
            }
        });
        self.measuring = Some(Measure {
            start,
            samples,
            kind: self.kind,
            done,
        });
    }

    /// Takes a finished measurement into the rate; true while one is still running (the
    /// caller keeps polling and repainting).
    pub fn poll(&mut self, ctx: &GpuContext) -> bool {
        let Some(m) = &self.measuring else {
            return false;
        };
        #[cfg(not(target_arch = "wasm32"))]
        let _ = ctx.device.poll(wgpu::PollType::Poll);
        #[cfg(target_arch = "wasm32")]
        let _ = ctx;
        let done = m.done.lock().ok().and_then(|d| *d);
        let Some(done) = done else {
            return true;
        };
        // A millisecond floor: a tiny frame's time is mostly overhead.
        let secs = done.duration_since(m.start).as_secs_f64().max(1e-3);
        let sample = (m.samples / secs).clamp(1e5, 1e13);
        let rate = &mut self.rates[m.kind];
        *rate = Some(match *rate {
            // Up slowly (the geometric mean of the old rate and the new sample), down at once:
            // a band over dense tissue after bands of air must not be planned at air's rate.
            Some(old) if sample > old => (old * sample).sqrt(),
            _ => sample,
        });
        self.measuring = None;
        false
    }
}

/// How a frame of `full_samples` samples is drawn within `budget_samples`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FramePlan {
    /// It fits: draw it whole.
    Whole,
    /// First a coarse frame at this fraction of the resolution (within the budget), then the
    /// full one in bands of rows over the following frames.
    Progressive { coarse_scale: f32 },
}

/// The coarsest resolution a progressive frame starts from.
pub const MIN_COARSE_SCALE: f32 = 1.0 / 16.0;

impl FramePlan {
    pub fn of(full_samples: f64, budget_samples: f64) -> Self {
        // NaN budgets or costs draw whole.
        if full_samples.partial_cmp(&budget_samples) != Some(std::cmp::Ordering::Greater) {
            return Self::Whole;
        }
        let s = (budget_samples / full_samples).sqrt() as f32;
        Self::Progressive {
            coarse_scale: s.clamp(MIN_COARSE_SCALE, 0.5),
        }
    }
}

/// The largest resolution scale (at most `cap`) whose frame costs at most `budget_samples`
/// (the preview drawn while the mouse moves the view), never below [`MIN_COARSE_SCALE`].
pub fn scale_within(full_samples: f64, budget_samples: f64, cap: f32) -> f32 {
    let cap = cap.clamp(MIN_COARSE_SCALE, 1.0);
    if full_samples.partial_cmp(&budget_samples) != Some(std::cmp::Ordering::Greater) {
        return cap;
    }
    ((budget_samples / full_samples).sqrt() as f32).clamp(MIN_COARSE_SCALE, cap)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plans() {
        assert_eq!(FramePlan::of(10.0, 100.0), FramePlan::Whole);
        assert_eq!(FramePlan::of(100.0, f64::INFINITY), FramePlan::Whole);
        assert_eq!(
            FramePlan::of(400.0, 100.0),
            FramePlan::Progressive { coarse_scale: 0.5 }
        );
        assert_eq!(
            FramePlan::of(1600.0, 1.0),
            FramePlan::Progressive {
                coarse_scale: MIN_COARSE_SCALE
            }
        );
        assert_eq!(
            FramePlan::of(1e4, 100.0),
            FramePlan::Progressive { coarse_scale: 0.1 }
        );
        assert_eq!(scale_within(10.0, 100.0, 0.5), 0.5);
        assert_eq!(scale_within(1e4, 100.0, 0.5), 0.1);
        assert_eq!(scale_within(1e9, 1.0, 0.5), MIN_COARSE_SCALE);
    }
}
