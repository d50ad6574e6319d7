//! The feature histograms the pack and pool kernels keep (shaders/feature_stats.wgsl) and what is read
//! from them: each feature's 99.9th percentile, what a gain of 1 shows as full colour.

use crate::cpu::Components3;

/// Bins of the feature histograms: 32 per octave from 2^-10 to 2^20 (2.2% wide), kept by the
/// pack and pool kernels (`shaders/feature_stats.wgsl`, the same binning) for
/// [`super::FeatureTexture::p999`].
pub const HISTOGRAM_BINS: usize = 960;
const BINS_PER_OCTAVE: f32 = 32.0;
const LOWEST_OCTAVE: f32 = -10.0;

/// The histogram bin of a positive value (the kernel's `bin_of`).
pub fn histogram_bin(v: f32) -> Option<usize> {
    if !(v > 0.0 && v.is_finite()) {
        return None;
    }
    let b = ((v.log2() - LOWEST_OCTAVE) * BINS_PER_OCTAVE).floor();
    Some(b.clamp(0.0, (HISTOGRAM_BINS - 1) as f32) as usize)
}

/// The upper edge of a bin (a percentile is reported as the upper edge of its bin).
pub fn histogram_bin_upper(bin: usize) -> f32 {
    2f32.powf((bin as f32 + 1.0) / BINS_PER_OCTAVE + LOWEST_OCTAVE)
}

/// The `q` quantile (0..1) of the values a histogram counted, as its bin's upper edge, clamped to
/// `max`; 0 when it counted nothing.
pub fn histogram_quantile(counts: &[u32], q: f64, max: f32) -> f32 {
    let total: u64 = counts.iter().map(|&c| u64::from(c)).sum();
    if total == 0 {
        return 0.0;
    }
    let want = (q * total as f64).ceil().max(1.0) as u64;
    let mut seen = 0u64;
    for (bin, &c) in counts.iter().enumerate() {
        seen += u64::from(c);
        if seen >= want {
            return histogram_bin_upper(bin).min(max);
        }
    }
    max
}

/// The maxima and the 99.9th percentiles of the positive values of three components, as the
/// pack kernel keeps them (the CPU twin of [`super::FeatureTexture::max`] and [`super::FeatureTexture::p999`]).
pub fn feature_statistics(components: &Components3) -> ([f32; 3], [f32; 3]) {
    let max: [f32; 3] = std::array::from_fn(|c| {
        components[c]
            .iter()
            .copied()
            .fold(0.0, f32::max)
            .min(65504.0)
    });
    let p999 = std::array::from_fn(|c| {
        let mut counts = vec![0u32; HISTOGRAM_BINS];
        for &v in &components[c] {
            if let Some(b) = histogram_bin(v.clamp(-65504.0, 65504.0)) {
                counts[b] += 1;
            }
        }
        histogram_quantile(&counts, 0.999, max[c])
    });
    (max, p999)
}

/// What a gain of 1 shows as full colour, from [`feature_statistics`].
pub fn reference_of(max: [f32; 3], p999: [f32; 3]) -> [f32; 3] {
    std::array::from_fn(|c| if p999[c] > 0.0 { p999[c] } else { max[c] })
}
