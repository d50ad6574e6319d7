//! Helpers for the crate's own unit tests (here, where every module may use them).

/// A reproducible stream of uniform numbers (a 64-bit LCG, Knuth's MMIX constants): random
/// cases that are the same on every run.
pub(crate) struct Lcg(u64);

impl Lcg {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// The next number in [0, 1), on a grid of 2^-24 (exact in f32).
    pub fn unit(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
}
