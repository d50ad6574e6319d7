//! The opacity transfer function (paper eq. 3), the noise estimator, the automatic transfer
//! function and the presets (docs/science.md, RST item 8 and "Presets").

use super::{Grid, Samples};

/// Piecewise-linear opacity transfer function of the intensity difference d (HU).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TransferFunction {
    pub d_min: f64,
    pub d_max: f64,
}

impl TransferFunction {
    /// The paper's CT setting, 10/30 HU.
    pub const PAPER_CT: Self = Self {
        d_min: 10.0,
        d_max: 30.0,
    };

    pub fn new(d_min: f64, d_max: f64) -> Self {
        Self { d_min, d_max }
    }

    /// f(d): 0 for d <= d_min, linear between, 1 for d >= d_max. With d_max <= d_min it is a
    /// step at d_min.
    #[inline]
    pub fn eval(&self, d: f64) -> f64 {
        if d <= self.d_min {
            0.0
        } else if d >= self.d_max {
            1.0
        } else {
            (d - self.d_min) / (self.d_max - self.d_min)
        }
    }
}

/// The band of values a homogeneous soft-tissue window must lie in (CT, HU).
pub const NOISE_BAND_HU: (f32, f32) = (0.0, 100.0);
/// In-plane window size of the noise estimator.
pub const NOISE_WINDOW: usize = 11;

/// sigma_s: the noise standard deviation of `smoothed` (the intensity the rays read), as the
/// median over in-plane (i, j) 11 x 11 windows, tiled without overlap on every slice, of the
/// standard deviation in each window that lies wholly inside `band`. `None` if no window does.
pub fn estimate_noise_sigma<S: Samples + ?Sized>(
    grid: &Grid,
    smoothed: &S,
    band: (f32, f32),
) -> Option<f64> {
    let mut sigmas = Vec::new();
    for k in 0..grid.dims[2] {
        sigmas.extend(noise_window_sigmas(grid, smoothed, band, k));
    }
    median(sigmas)
}

/// Windows per row and per column of one slice of `dims` (tiled from (0, 0), no overlap).
pub fn noise_window_counts(dims: [usize; 3]) -> [usize; 2] {
    let w = NOISE_WINDOW;
    [0, 1].map(|a| dims[a].saturating_sub(w - 1).div_ceil(w))
}

/// The standard deviations of slice `k`'s windows that lie wholly inside `band`.
pub fn noise_window_sigmas<S: Samples + ?Sized>(
    grid: &Grid,
    smoothed: &S,
    band: (f32, f32),
    k: usize,
) -> Vec<f64> {
    let w = NOISE_WINDOW;
    let [nwx, nwy] = noise_window_counts(grid.dims);
    let mut sigmas = Vec::new();
    for j0 in (0..nwy).map(|t| t * w) {
        'window: for i0 in (0..nwx).map(|t| t * w) {
            let (mut s, mut s2) = (0.0f64, 0.0f64);
            for j in j0..j0 + w {
                for i in i0..i0 + w {
                    let v = smoothed.at(grid.index(i, j, k));
                    if !(v >= band.0 && v <= band.1) {
                        continue 'window;
                    }
                    s += f64::from(v);
                    s2 += f64::from(v) * f64::from(v);
                }
            }
            let n = (w * w) as f64;
            let var = (s2 - s * s / n) / (n - 1.0);
            sigmas.push(var.max(0.0).sqrt());
        }
    }
    sigmas
}

/// The median (mean of the middle two for an even count); `None` for no values.
pub fn median(mut values: Vec<f64>) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let m = values.len();
    Some(if m % 2 == 1 {
        values[m / 2]
    } else {
        0.5 * (values[m / 2 - 1] + values[m / 2])
    })
}

/// The automatic transfer function: the larger of the preset's values and the noise-based ones,
/// d_min = max(preset, 2 sigma_s), d_max = max(preset, 4 sigma_s).
pub fn auto_transfer_function(preset: TransferFunction, sigma_s: Option<f64>) -> TransferFunction {
    match sigma_s {
        Some(s) => TransferFunction::new(preset.d_min.max(2.0 * s), preset.d_max.max(4.0 * s)),
        None => preset,
    }
}

/// Named defaults for a clinical task (docs/science.md, "Presets").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Preset {
    /// Lymph nodes / soft tissue: TF 10/30 HU, Hessian sigma 1.5-5 mm, R 15 mm.
    #[default]
    LymphNodes,
    /// Lung nodules: TF 100/300 HU, sigma 1.5-9 mm, R 25 mm.
    LungNodules,
    /// Airways: TF 100/300 HU, sigma 1-4 mm, R 15 mm.
    Airways,
    /// Vessels / CTA: TF 50/150 HU (a contrast-enhanced lumen stands 200+ HU above tissue),
    /// sigma 1-4 mm, R 15 mm.
    Vessels,
}

impl Preset {
    pub const ALL: [Self; 4] = [
        Self::LymphNodes,
        Self::LungNodules,
        Self::Airways,
        Self::Vessels,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Self::LymphNodes => "lymph-nodes",
            Self::LungNodules => "lung-nodules",
            Self::Airways => "airways",
            Self::Vessels => "vessels",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|p| p.name() == name)
    }

    pub fn transfer_function(self) -> TransferFunction {
        match self {
            Self::LymphNodes => TransferFunction::PAPER_CT,
            Self::LungNodules | Self::Airways => TransferFunction::new(100.0, 300.0),
            Self::Vessels => TransferFunction::new(50.0, 150.0),
        }
    }

    /// Hessian scales, roughly geometric over the preset's range.
    pub fn sigmas_mm(self) -> Vec<f64> {
        match self {
            Self::LymphNodes => vec![1.5, 2.0, 3.0, 4.0, 5.0],
            Self::LungNodules => vec![1.5, 2.0, 3.0, 4.5, 6.5, 9.0],
            Self::Airways | Self::Vessels => vec![1.0, 1.5, 2.0, 3.0, 4.0],
        }
    }

    /// RST ray length R.
    pub fn radius_mm(self) -> f64 {
        match self {
            Self::LungNodules => 25.0,
            _ => 15.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transfer_function_shape() {
        let tf = TransferFunction::PAPER_CT;
        assert_eq!(tf.eval(0.0), 0.0);
        assert_eq!(tf.eval(10.0), 0.0);
        assert!((tf.eval(20.0) - 0.5).abs() < 1e-12);
        assert_eq!(tf.eval(31.0), 1.0);
        let auto = auto_transfer_function(tf, Some(7.0));
        assert_eq!((auto.d_min, auto.d_max), (14.0, 30.0));
    }

    #[test]
    fn noise_estimator_ignores_windows_outside_the_band() {
        let grid = Grid::new([33, 22, 2], [1.0; 3]);
        // Left tiles: alternating 40/60 (sd 10.04); rightmost tile column: out of band.
        let v: Vec<f32> = (0..grid.len())
            .map(|n| {
                let [i, j, _] = grid.ijk(n);
                if i >= 22 {
                    500.0
                } else if (i + j) % 2 == 0 {
                    40.0
                } else {
                    60.0
                }
            })
            .collect();
        let s = estimate_noise_sigma(&grid, &v, NOISE_BAND_HU).expect("windows");
        assert!((s - 10.04).abs() < 0.05, "{s}");
    }
}
