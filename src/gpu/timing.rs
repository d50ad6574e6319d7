//! How long submitted GPU work took: the one clock of both pacers, the feature job's
//! (`compute::pipeline::pace`) and progressive rendering's (`render::raycast::pace`).
//!
//! A [`GpuSpan`] is opened right before the work's submissions and closed right after them.
//! Where the device has timestamp queries (wgpu's `TIMESTAMP_QUERY`, WebGPU's "timestamp-query":
//! Chrome has them, on SwiftShader too, and so does lavapipe), the span writes a timestamp in an
//! empty compute pass submitted before the work and one submitted after it, and the work's time
//! is their difference, however late the page hears of it. That is the device's time from the
//! first stamp to the second: the work, and whatever keeps the device waiting for it in between
//! (so open a span only once the CPU's part of the work is done). The query set and buffers of a
//! span are destroyed when it is closed and dropped (a browser on Metal has only a few dozen
//! timestamp query sets per device; dropping one in wasm would leave it to the garbage
//! collector).
//!
//! Without timestamps the span is timed by the queue's callbacks. In the browser the work's time
//! runs from when everything queued before it was done (`before`: the viewer's last frame, say)
//! or its submission, whichever is later, to `done`; natively (callbacks run only when something
//! polls) from the submission. In the browser these callbacks arrive when the page next hears
//! from the GPU process, often both at once and a whole frame late (on SwiftShader, 0.4-1.3 s
//! for a band of the MIP that took a millisecond): that measures the page's frame, not the
//! work, and kept the pacers' steps at their smallest (the MIP refined one row a frame). So the
//! timestamps come first.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use super::GpuContext;

/// What is called when a span's work is done (and its time known): the viewer repaints.
pub type Wake = Arc<dyn Fn() + Send + Sync>;

/// Callbacks stamped closer than this ran together (one poll, one task of the page).
const STAMPED_APART_MICROS: u64 = 1000;

/// Bytes of the two resolved timestamps.
const STAMP_BYTES: u64 = 16;

/// What a device does per second of one kind of work, learnt from measured spans: the one rule
/// of both pacers. A slower measurement is followed at once (a band over dense tissue after
/// bands of air, a Hessian pass of a larger kernel, must not be planned at the faster rate); a
/// faster one only by the geometric mean of the old rate and the new (one quick span does not
/// make the next step a long one).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Rate(Option<f64>);

impl Rate {
    /// Work per second, once measured.
    pub fn get(&self) -> Option<f64> {
        self.0
    }

    /// Takes in `work` done in `secs` (at least 0.1 ms: a browser's timestamps are no finer).
    pub fn observe(&mut self, work: f64, secs: f64) {
        if !(work.is_finite() && work > 0.0 && secs.is_finite()) {
            return;
        }
        let sample = work / secs.max(1e-4);
        self.0 = Some(match self.0 {
            Some(old) if sample > old => (old * sample).sqrt(),
            _ => sample,
        });
    }
}

/// A span opened before the work is submitted ([`GpuSpan::open`]).
pub struct OpenSpan {
    epoch: web_time::Instant,
    submitted: u64,
    before: Arc<AtomicU64>,
    stamps: Option<wgpu::QuerySet>,
}

/// Submitted work and what the device and the queue said of it, in microseconds since the
/// owner's epoch (`u64::MAX` until the callback has run).
pub struct GpuSpan {
    submitted: u64,
    before: Arc<AtomicU64>,
    done: Arc<AtomicU64>,
    /// The timestamps' readback: the buffer and whether (and how) its mapping ended.
    stamps: Option<Stamps>,
}

struct Stamps {
    buffer: wgpu::Buffer,
    mapped: Arc<Mutex<Option<bool>>>,
    period_ns: f64,
}

fn micros_since(epoch: web_time::Instant) -> u64 {
    u64::try_from(epoch.elapsed().as_micros())
        .unwrap_or(u64::MAX - 1)
        .min(u64::MAX - 1)
}

fn stamp_into(flag: &Arc<AtomicU64>, epoch: web_time::Instant) -> impl Fn() + Send + 'static {
    let flag = Arc::clone(flag);
    move || flag.store(micros_since(epoch), Ordering::Release)
}

/// An empty compute pass that writes timestamp `index` of `set` (at its start for 0, its end
/// for 1), in a submission of its own.
fn write_stamp(
    ctx: &GpuContext,
    set: &wgpu::QuerySet,
    index: u32,
    then: impl FnOnce(&mut wgpu::CommandEncoder),
) {
    let mut encoder = ctx
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("timestamp"),
        });
    {
        let (beginning, end) = if index == 0 {
            (Some(0), None)
        } else {
            (None, Some(index))
        };
        let _pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("timestamp"),
            timestamp_writes: Some(wgpu::ComputePassTimestampWrites {
                query_set: set,
                beginning_of_pass_write_index: beginning,
                end_of_pass_write_index: end,
            }),
        });
    }
    then(&mut encoder);
    ctx.queue.submit([encoder.finish()]);
}

impl GpuSpan {
    /// Opens a span: call right before submitting the work. `epoch` is what the callbacks'
    /// stamps count from (any instant before the span).
    pub fn open(ctx: &GpuContext, epoch: web_time::Instant) -> OpenSpan {
        let before = Arc::new(AtomicU64::new(u64::MAX));
        // Natively callbacks run when something polls, so `before` would not be used
        // ([`Self::seconds`]); registering it would only cost a submission.
        if cfg!(target_arch = "wasm32") {
            ctx.queue.on_submitted_work_done(stamp_into(&before, epoch));
        }
        let stamps = ctx
            .features
            .contains(wgpu::Features::TIMESTAMP_QUERY)
            .then(|| {
                let set = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("span"),
                    ty: wgpu::QueryType::Timestamp,
                    count: 2,
                });
                write_stamp(ctx, &set, 0, |_| {});
                set
            });
        OpenSpan {
            epoch,
            submitted: micros_since(epoch),
            before,
            stamps,
        }
    }

    /// The work's own GPU seconds once it is done: the timestamps' difference where the device
    /// wrote them, else the callbacks' reading.
    pub fn seconds(&self) -> Option<f64> {
        if let Some(s) = &self.stamps {
            let Ok(mapped) = s.mapped.lock().map(|m| *m) else {
                return self.callback_seconds();
            };
            match mapped {
                None => return None,
                Some(true) => {
                    let Ok(range) = s.buffer.slice(..).get_mapped_range() else {
                        return self.callback_seconds();
                    };
                    let at = |i: usize| {
                        let mut b = [0u8; 8];
                        b.copy_from_slice(&range[i * 8..i * 8 + 8]);
                        u64::from_le_bytes(b)
                    };
                    let (t0, t1) = (at(0), at(1));
                    // A zero first stamp was never written (an invalid submission resolves
                    // zeros); the second alone would be the device's clock, not a time.
                    if t0 != 0 && t1 > t0 {
                        return Some((t1 - t0) as f64 * s.period_ns * 1e-9);
                    }
                    // Equal stamps (a browser quantises them, to 0.1 ms in Chrome): shorter
                    // than that, counted as such.
                    if t1 == t0 && t0 != 0 {
                        return Some(1e-4);
                    }
                }
                // The readback failed: the callbacks say what they can.
                Some(false) => {}
            }
        }
        self.callback_seconds()
    }

    /// The callbacks' reading (see the module's comment), `None` until `done` ran.
    fn callback_seconds(&self) -> Option<f64> {
        let done = self.done.load(Ordering::Acquire);
        if done == u64::MAX {
            return None;
        }
        // The callbacks run in submission order, so `before` has been stored. Natively they run
        // when something polls, so `before` may be stamped while the work already runs (it
        // would look shorter than it was): there, and where both were stamped together (a
        // page busy while the queue finished), the work counts from its submission, which
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

    /// Whether the span was timed by the device's timestamps (else by the queue's callbacks).
    pub fn timestamped(&self) -> bool {
        self.stamps.is_some()
    }
}

impl OpenSpan {
    /// Closes the span: call right after submitting the work. `wake` is called once its time
    /// is known.
    pub fn close(self, ctx: &GpuContext, wake: Option<Wake>) -> GpuSpan {
        let done = Arc::new(AtomicU64::new(u64::MAX));
        let stamps = self.stamps.map(|set| {
            let resolve = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("span stamps"),
                size: STAMP_BYTES,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("span stamps readback"),
                size: STAMP_BYTES,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            write_stamp(ctx, &set, 1, |encoder| {
                encoder.resolve_query_set(&set, 0..2, &resolve, 0);
                encoder.copy_buffer_to_buffer(&resolve, 0, &buffer, 0, STAMP_BYTES);
            });
            // Freed once the submitted work is done (WebGPU and wgpu defer it).
            set.destroy();
            resolve.destroy();
            let mapped = Arc::new(Mutex::new(None));
            let m = Arc::clone(&mapped);
            let wake = wake.clone();
            buffer.slice(..).map_async(wgpu::MapMode::Read, move |r| {
                if let Ok(mut m) = m.lock() {
                    *m = Some(r.is_ok());
                }
                if let Some(wake) = wake {
                    wake();
                }
            });
            Stamps {
                buffer,
                mapped,
                period_ns: f64::from(ctx.queue.get_timestamp_period()),
            }
        });
        let stamp_done = stamp_into(&done, self.epoch);
        let wake_on_done = if stamps.is_some() { None } else { wake };
        ctx.queue.on_submitted_work_done(move || {
            stamp_done();
            if let Some(wake) = wake_on_done {
                wake();
            }
        });
        GpuSpan {
            submitted: self.submitted,
            before: self.before,
            done,
            stamps,
        }
    }
}

impl Drop for GpuSpan {
    fn drop(&mut self) {
        if let Some(s) = &self.stamps {
            // Unmaps it if mapped; a mapping still pending ends with an error nobody reads.
            s.buffer.destroy();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rate_follows_a_slower_span_at_once_and_a_faster_one_by_the_geometric_mean() {
        let mut r = Rate::default();
        assert_eq!(r.get(), None);
        r.observe(100.0, 1.0);
        assert_eq!(r.get(), Some(100.0));
        r.observe(10_000.0, 1.0);
        assert_eq!(r.get(), Some(1000.0));
        r.observe(10.0, 1.0);
        assert_eq!(r.get(), Some(10.0));
        // Nothing learnt from no work or a broken time; a zero time counts as 0.1 ms.
        r.observe(0.0, 1.0);
        r.observe(5.0, f64::NAN);
        assert_eq!(r.get(), Some(10.0));
        r.observe(1e-3, 0.0);
        assert_eq!(r.get(), Some(10.0));
    }

    fn span(submitted: u64, before: u64, done: u64) -> GpuSpan {
        GpuSpan {
            submitted,
            before: Arc::new(AtomicU64::new(before)),
            done: Arc::new(AtomicU64::new(done)),
            stamps: None,
        }
    }

    #[test]
    fn without_timestamps_work_is_timed_from_when_the_work_queued_before_it_was_done() {
        // Microseconds of a span's measured seconds (`None` while not done).
        let micros = |f: GpuSpan| f.seconds().map(|s| (s * 1e6).round() as u64);
        // Not done yet.
        assert_eq!(micros(span(0, 500_000, u64::MAX)), None);
        // A frame queued ahead ran 0.5 s after the submission: in the browser the work is the
        // 0.25 s after it; natively (stamps taken when polled) from the submission.
        let want = if cfg!(target_arch = "wasm32") {
            250_000
        } else {
            750_000
        };
        assert_eq!(micros(span(100_000, 600_000, 850_000)), Some(want));
        // The queue was idle at the submission (its callback ran at once, before it).
        assert_eq!(micros(span(100_000, 90_000, 400_000)), Some(300_000));
        // Both callbacks stamped by one poll: when the work started is unknown, so from the
        // submission (the work never looks shorter than it may have been).
        assert_eq!(micros(span(100_000, 700_000, 700_050)), Some(600_050));
    }
}
