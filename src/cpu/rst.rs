//! The radial structure tensor (paper sections 3.1, 3.2; docs/science.md RST items 1-7): gradient
//! volume, trilinear sampling of (I, g), ray casting with the consistent opacity rule (default)
//! or the paper's literal rule, and the symmetrised tensor per point.

use super::eigen::{Sym3, eigenvalues_sorted};
use super::features::{FeatureMap, map_eigenvalues};
use super::gaussian::gaussian_smooth;
use super::tf::TransferFunction;
use super::{Components3, Grid, parallel};

/// Default gradient scale sigma_g.
pub const DEFAULT_SIGMA_G_MM: f64 = 0.7;
/// Default ray length R.
pub const DEFAULT_RADIUS_MM: f64 = 15.0;
/// Default step dr (0.5 mm is the fast setting).
pub const DEFAULT_STEP_MM: f64 = 0.25;
/// Opacity at which a ray stops.
pub const ALPHA_STOP: f64 = 0.99;

/// The smoothed intensity I and its gradient g (HU/mm) on the grid the rays read.
#[derive(Clone, Debug)]
pub struct GradientVolume {
    /// The grid of `intensity` and `gradient`: the acquired grid, or it refined along thick axes
    /// ([`Self::refined`]).
    pub grid: Grid,
    /// The grid the data were acquired on: its spacing sets the opacity lengths L_i (the blur
    /// of the data, which refinement does not sharpen), and features are computed at its voxels
    /// (voxel `i` is voxel `f i` of `grid`, at the same mm position).
    pub acquired: Grid,
    pub sigma_g_mm: f64,
    pub intensity: Vec<f32>,
    pub gradient: Vec<[f32; 3]>,
}

impl GradientVolume {
    /// Smooths with `sigma_g_mm` (Gaussian, kernels as in `gaussian.rs`), then takes central
    /// differences in mm, `(I[i+1] - I[i-1]) / (2 s)`, with replicated borders (so at the first
    /// and last voxel of an axis the difference spans one voxel but is still divided by 2 s).
    pub fn new(grid: &Grid, values: &[f32], sigma_g_mm: f64) -> Self {
        let intensity = gaussian_smooth(grid, values, sigma_g_mm);
        let n = grid.len();
        let gradient = parallel::map_indices(n, |idx| {
            let ijk = grid.ijk(idx);
            std::array::from_fn(|a| {
                let mut lo = ijk;
                let mut hi = ijk;
                lo[a] = ijk[a].saturating_sub(1);
                hi[a] = (ijk[a] + 1).min(grid.dims[a] - 1);
                let d = intensity[grid.index(hi[0], hi[1], hi[2])]
                    - intensity[grid.index(lo[0], lo[1], lo[2])];
                (f64::from(d) / (2.0 * grid.spacing_mm[a])) as f32
            })
        });
        Self {
            grid: *grid,
            acquired: *grid,
            sigma_g_mm,
            intensity,
            gradient,
        }
    }

    /// The rays' (I, g) on `grid` refined by the integer `factors` (linear between the acquired
    /// voxels, [`super::resample::refine_linear`]), then smoothed and differenced as [`Self::new`]
    /// on the refined grid; `acquired` stays `grid` (docs/science.md, "Thick slices").
    pub fn refined(grid: &Grid, values: &[f32], sigma_g_mm: f64, factors: [usize; 3]) -> Self {
        let (fine, fine_values) = super::resample::refine_linear(grid, values, factors);
        let mut gv = Self::new(&fine, &fine_values, sigma_g_mm);
        gv.acquired = *grid;
        gv
    }

    /// Trilinear (I, g) at a grid-mm position; positions outside are clamped onto the grid
    /// (replicated border).
    pub fn sample(&self, p_mm: [f64; 3]) -> (f64, [f64; 3]) {
        let g = &self.grid;
        let mut i0 = [0usize; 3];
        let mut i1 = [0usize; 3];
        let mut t = [0.0f64; 3];
        for a in 0..3 {
            let max = (g.dims[a] - 1) as f64;
            let u = (p_mm[a] / g.spacing_mm[a]).clamp(0.0, max);
            let f = u.floor();
            i0[a] = f as usize;
            i1[a] = (i0[a] + 1).min(g.dims[a] - 1);
            t[a] = u - f;
        }
        let mut value = 0.0;
        let mut grad = [0.0; 3];
        for corner in 0..8 {
            let pick = |a: usize| (corner >> a) & 1 == 1;
            let idx = g.index(
                if pick(0) { i1[0] } else { i0[0] },
                if pick(1) { i1[1] } else { i0[1] },
                if pick(2) { i1[2] } else { i0[2] },
            );
            let w: f64 = (0..3)
                .map(|a| if pick(a) { t[a] } else { 1.0 - t[a] })
                .product();
            if w == 0.0 {
                continue;
            }
            value += w * f64::from(self.intensity[idx]);
            for (a, ga) in grad.iter_mut().enumerate() {
                *ga += w * f64::from(self.gradient[idx][a]);
            }
        }
        (value, grad)
    }
}

/// How opacity accumulates along a ray.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum OpacityRule {
    /// Extinction in mm with the per-ray opacity length L_i = 0.6 rho(r_i), steps weighted by
    /// the opacity they add (docs/science.md RST items 4, 5).
    #[default]
    Consistent,
    /// The paper's eq. 4 and 7 taken literally (docs/science.md RST item 7).
    Paper,
}

/// Parameters of the RST at one point.
#[derive(Clone, Debug, PartialEq)]
pub struct RstParams {
    /// Unit ray directions (see `rays.rs`).
    pub rays: Vec<[f64; 3]>,
    pub radius_mm: f64,
    pub step_mm: f64,
    pub tf: TransferFunction,
    pub rule: OpacityRule,
}

impl RstParams {
    /// 42 rays, R 15 mm, dr 0.25 mm, TF 10/30 HU, consistent rule.
    pub fn paper_defaults() -> Self {
        Self {
            rays: super::rays::ray_set(42).unwrap_or_default(),
            radius_mm: DEFAULT_RADIUS_MM,
            step_mm: DEFAULT_STEP_MM,
            tf: TransferFunction::PAPER_CT,
            rule: OpacityRule::Consistent,
        }
    }

    /// Number of steps K = floor(R / dr + 1e-6).
    pub fn steps(&self) -> usize {
        (self.radius_mm / self.step_mm + 1e-6).floor() as usize
    }
}

/// Opacity length L_i = 0.6 rho(r_i), rho^2 = sigma_g^2 + sum_a s_a^2 (r_a^2/4 + r_a^4/3).
pub fn opacity_length_mm(grid: &Grid, sigma_g_mm: f64, r: [f64; 3]) -> f64 {
    let mut rho2 = sigma_g_mm * sigma_g_mm;
    for (s, ra) in grid.spacing_mm.iter().zip(r) {
        rho2 += s * s * (ra * ra / 4.0 + ra.powi(4) / 3.0);
    }
    0.6 * rho2.sqrt()
}

/// The symmetrised RST `Ts = T + T^T` at the grid-mm position `x_mm`.
pub fn rst_tensor_at(gv: &GradientVolume, x_mm: [f64; 3], p: &RstParams) -> Sym3 {
    let mut t = [[0.0f64; 3]; 3];
    let (i_centre, g_centre) = gv.sample(x_mm);
    let k_max = p.steps();
    let dr = p.step_mm;
    let dr_vox = dr / gv.grid.min_spacing_mm();
    for r in &p.rays {
        // The ray's weighted gradient sum, later multiplied by r^T.
        let acc = match p.rule {
            OpacityRule::Consistent => consistent_ray(gv, x_mm, (i_centre, g_centre), *r, p).0,
            OpacityRule::Paper => {
                let mut acc = [0.0f64; 3];
                let mut alpha_prev = 0.0f64;
                for k in 1..=k_max {
                    let s = k as f64 * dr;
                    let (ik, gk) = gv.sample(std::array::from_fn(|a| x_mm[a] + s * r[a]));
                    let fk = p.tf.eval((ik - i_centre).abs());
                    let alpha = alpha_prev + (1.0 - alpha_prev) * (fk * dr_vox).min(1.0);
                    for a in 0..3 {
                        acc[a] += alpha * gk[a];
                    }
                    if alpha >= ALPHA_STOP {
                        break;
                    }
                    alpha_prev = alpha;
                }
                acc.map(|v| v * dr)
            }
        };
        for (a, row) in t.iter_mut().enumerate() {
            for (b, v) in row.iter_mut().enumerate() {
                *v += acc[a] * r[b];
            }
        }
    }
    let n = p.rays.len().max(1) as f64;
    let ts = |a: usize, b: usize| (t[a][b] + t[b][a]) / n;
    [ts(0, 0), ts(1, 1), ts(2, 2), ts(0, 1), ts(0, 2), ts(1, 2)]
}

/// One ray of the consistent rule (docs/science.md RST items 4 and 5) from `x_mm`, whose
/// smoothed intensity and gradient are `centre`, along the unit direction `r`: the ray's weighted
/// gradient sum `L_i sum_k (alpha_k - alpha_{k-1}) 0.5 (g_{k-1} + g_k)`, the number of steps
/// taken (the ray stops after the step where alpha_k >= 0.99, or at K) and the opacity reached.
pub fn consistent_ray(
    gv: &GradientVolume,
    x_mm: [f64; 3],
    centre: (f64, [f64; 3]),
    r: [f64; 3],
    p: &RstParams,
) -> ([f64; 3], usize, f64) {
    let (i_centre, g_centre) = centre;
    let dr = p.step_mm;
    let k_max = p.steps();
    let l_mm = opacity_length_mm(&gv.acquired, gv.sigma_g_mm, r);
    let mut acc = [0.0f64; 3];
    let mut alpha_prev = 0.0f64;
    let mut f_prev = 0.0f64;
    let mut g_prev = g_centre;
    let mut taken = k_max;
    for k in 1..=k_max {
        let s = k as f64 * dr;
        let (ik, gk) = gv.sample(std::array::from_fn(|a| x_mm[a] + s * r[a]));
        let fk = p.tf.eval((ik - i_centre).abs());
        let tau = 0.5 * (f_prev + fk) * dr / l_mm;
        let alpha = 1.0 - (1.0 - alpha_prev) * (-tau).exp();
        let w = alpha - alpha_prev;
        for a in 0..3 {
            acc[a] += w * 0.5 * (g_prev[a] + gk[a]);
        }
        alpha_prev = alpha;
        if alpha >= ALPHA_STOP {
            taken = k;
            break;
        }
        f_prev = fk;
        g_prev = gk;
    }
    (acc.map(|v| v * l_mm), taken, alpha_prev)
}

/// The length (mm) each ray of the consistent rule runs from `x_mm` before it stops, in the
/// order of `p.rays`: `dr` times the steps taken (R's K steps when it never becomes opaque).
pub fn ray_lengths_mm(gv: &GradientVolume, x_mm: [f64; 3], p: &RstParams) -> Vec<f64> {
    let centre = gv.sample(x_mm);
    p.rays
        .iter()
        .map(|r| consistent_ray(gv, x_mm, centre, *r, p).1 as f64 * p.step_mm)
        .collect()
}

/// Eigenvalues of the RST at `x_mm`, sorted by magnitude.
pub fn rst_eigen_at(gv: &GradientVolume, x_mm: [f64; 3], p: &RstParams) -> [f64; 3] {
    eigenvalues_sorted(&rst_tensor_at(gv, x_mm, p))
}

/// Runs `f` on the RST eigenvalues at every voxel centre of the acquired grid and stores three
/// components.
fn per_voxel(
    gv: &GradientVolume,
    p: &RstParams,
    f: impl Fn([f64; 3]) -> [f64; 3] + Sync + Send,
) -> Components3 {
    let grid = gv.acquired;
    let per: Vec<[f32; 3]> = parallel::map_indices(grid.len(), |idx| {
        let x = grid.position_mm(grid.ijk(idx));
        f(rst_eigen_at(gv, x, p)).map(|v| v as f32)
    });
    std::array::from_fn(|c| per.iter().map(|v| v[c]).collect())
}

/// `[V, A, B]` of the RST at every voxel of the acquired grid.
pub fn rst_features(gv: &GradientVolume, p: &RstParams, map: FeatureMap) -> Components3 {
    per_voxel(gv, p, |l| map_eigenvalues(l, map))
}

/// RST eigenvalues `[l0, l1, l2]` at every voxel of the acquired grid.
pub fn rst_eigen(gv: &GradientVolume, p: &RstParams) -> Components3 {
    per_voxel(gv, p, |l| l)
}
