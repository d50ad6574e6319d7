//! Progressive rendering's clock: how many samples ([`super::FrameCost`]) this device's GPU
//! projects per second, measured on the frames themselves, and from it how much of a frame fits
//! in one frame's GPU budget.
//!
//! A measurement is a [`GpuSpan`] around the frame's (or band's) submission: the device's
//! timestamps where it writes them, else the queue's callbacks, which may include queueing
//! behind other work and the wait for the next poll: an underestimate of the rate, so that bands
//! come out smaller than the budget rather than larger.

use crate::gpu::GpuContext;
use crate::gpu::timing::{GpuSpan, OpenSpan, Rate};

/// First guess of the rate (samples per second) before a kind of frame was measured: below a
/// software renderer's (lavapipe on two cores: ~100 M/s intensity only, ~15 M/s with features);
/// a real GPU measures higher within a few frames.
pub const INITIAL_SAMPLES_PER_S: f64 = 10e6;

/// The measured rate and the budget per frame.
pub struct FramePacer {
    /// GPU seconds one frame may take; `None`: frames are drawn whole, whatever they cost.
    pub budget_s: Option<f64>,
    /// Measured rates per kind of frame (intensity only, with features: a feature sample costs
    /// several times an intensity one, and skips less).
    rates: [Rate; 2],
    /// The kind of the frames being planned.
    kind: usize,
    /// The rate is given, never measured (tests, benchmarks).
    fixed: Option<f64>,
    measuring: Option<Measure>,
    /// What the spans' callback times count from.
    epoch: web_time::Instant,
}

struct Measure {
    samples: f64,
    kind: usize,
    span: GpuSpan,
}

impl FramePacer {
    pub fn new(budget_s: Option<f64>) -> Self {
        Self {
            budget_s,
            rates: [Rate::default(); 2],
            kind: 0,
            fixed: None,
            measuring: None,
            epoch: web_time::Instant::now(),
        }
    }

    /// A pacer with a given rate that it never measures (reproducible bands in tests).
    pub fn fixed(budget_s: Option<f64>, samples_per_s: f64) -> Self {
        Self {
            fixed: Some(samples_per_s.max(1.0)),
            ..Self::new(budget_s)
        }
    }

    /// Plans the following frames for a scene with or without features.
    pub fn set_scene(&mut self, with_features: bool) {
        self.kind = usize::from(with_features);
    }

    /// Samples per second of the current kind of frame, measured (or the first guess).
    pub fn rate(&self) -> f64 {
        self.fixed
            .or(self.rates[self.kind].get().map(|r| r.clamp(1e5, 1e13)))
            .unwrap_or(INITIAL_SAMPLES_PER_S)
    }

    /// Whether [`Self::rate`] comes from a measurement.
    pub fn measured(&self) -> bool {
        self.fixed.is_some() || self.rates[self.kind].get().is_some()
    }

    /// How many samples one frame may cost; infinite without a budget.
    pub fn budget_samples(&self) -> f64 {
        match self.budget_s {
            Some(s) if s.is_finite() && s > 0.0 => s * self.rate(),
            _ => f64::INFINITY,
        }
    }

    /// Call right before submitting a frame: opens its measurement unless one is running (or
    /// the rate is fixed). Hand the result to [`Self::submitted`].
    pub fn open(&self, ctx: &GpuContext) -> Option<OpenSpan> {
        (self.fixed.is_none() && self.measuring.is_none()).then(|| GpuSpan::open(ctx, self.epoch))
    }

    /// Call right after submitting `samples` samples of work, with what [`Self::open`] gave
    /// before the submission: times it.
    pub fn submitted(&mut self, ctx: &GpuContext, samples: f64, span: Option<OpenSpan>) {
        let Some(span) = span else {
            return;
        };
        let span = span.close(ctx, None);
        if self.measuring.is_some() || samples.is_nan() || samples <= 0.0 {
            return;
        }
        self.measuring = Some(Measure {
            samples,
            kind: self.kind,
            span,
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
        let Some(secs) = m.span.seconds() else {
            return true;
        };
        // A millisecond floor: a tiny frame's time is mostly overhead; and a rate of at
        // least 1e5 samples per second (a stall must not plan bands of a few pixels).
        let secs = secs.max(1e-3).min(m.samples / 1e5);
        self.rates[m.kind].observe(m.samples, secs);
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
