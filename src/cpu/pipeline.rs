//! The whole CPU feature computation for one volume, as `shapecast features` runs it: preset
//! defaults, thick axes refined by an integer factor for the Hessian (and z for the RST when
//! asked; cpu::resample), the automatic transfer function, the chosen method, and the result taken at
//! the input's voxels (docs/science.md, "Thick slices" and "Conventions of the command line and
//! the app").

use super::features::{
    FeatureMap, HessianMethod, hessian_eigen_multiscale, hessian_features_multiscale,
};
use super::resample::{
    refine_linear, refined_grid, refinement_factors, rst_refinement_factors, subsample,
};
use super::rst::{
    DEFAULT_SIGMA_G_MM, DEFAULT_STEP_MM, GradientVolume, OpacityRule, RstParams, rst_eigen,
    rst_features,
};
use super::structure_tensor::{structure_tensor_eigen, structure_tensor_features};
use super::tf::{
    NOISE_BAND_HU, Preset, TransferFunction, auto_transfer_function, estimate_noise_sigma,
};
use super::{Components3, Grid, rays};

/// Which feature to compute.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// Hessian, eq. 1 map.
    Hessian,
    /// Hessian, eq. 2 (Li) map.
    Li,
    /// Hessian, Frangi vesselness.
    Frangi,
    /// General structure tensor (comparison only).
    Gst,
    /// Radial structure tensor.
    Rst,
}

impl Method {
    /// Every method, in the order the command line lists them.
    pub const ALL: [Self; 5] = [Self::Hessian, Self::Li, Self::Frangi, Self::Gst, Self::Rst];

    /// The lower-case name the command line (and the app's URLs) use.
    pub fn name(self) -> &'static str {
        match self {
            Self::Hessian => "hessian",
            Self::Li => "li",
            Self::Frangi => "frangi",
            Self::Gst => "gst",
            Self::Rst => "rst",
        }
    }
}

/// Everything `features` can be told; `None` means "the preset's value".
#[derive(Clone, Debug, PartialEq)]
pub struct Request {
    pub method: Method,
    pub preset: Preset,
    pub sigmas_mm: Option<Vec<f64>>,
    pub rays: Option<usize>,
    pub radius_mm: Option<f64>,
    pub step_mm: Option<f64>,
    pub rule: OpacityRule,
    /// Explicit transfer function; `None` is the automatic one.
    pub tf: Option<TransferFunction>,
    /// Map of the RST features (the Hessian's is fixed by the method).
    pub rst_map: FeatureMap,
    pub eigen: bool,
    pub frangi_c: Option<f64>,
    pub sigma_g_mm: f64,
    /// RST (consistent rule) only: refine the slice axis for the rays
    /// ([`super::resample::rst_refinement_factors`]; docs/science.md, "Thick slices"). Off by
    /// default: it keeps small spheres on thick slices but lets slice-thick vessel junctions
    /// outrank real masses (measured on lung2).
    pub refine_slices: bool,
}

impl Request {
    pub fn new(method: Method) -> Self {
        Self {
            method,
            preset: Preset::default(),
            sigmas_mm: None,
            rays: None,
            radius_mm: None,
            step_mm: None,
            rule: OpacityRule::Consistent,
            tf: None,
            rst_map: FeatureMap::Li,
            eigen: false,
            frangi_c: None,
            sigma_g_mm: DEFAULT_SIGMA_G_MM,
            refine_slices: false,
        }
    }
}

/// Three components on the input grid, and what the user should be told.
#[derive(Clone, Debug)]
pub struct Outcome {
    pub components: Components3,
    pub notes: Vec<String>,
    /// The transfer function the RST used.
    pub tf: Option<TransferFunction>,
    /// The measured noise of the smoothed intensity (auto TF), HU.
    pub noise_sigma_hu: Option<f64>,
}

/// Why a request cannot run.
#[derive(Debug, thiserror::Error, PartialEq)]
#[non_exhaustive]
pub enum RequestError {
    #[error("--rays {0}: the ray sets have {1:?} rays")]
    RayCount(usize, [usize; 5]),
    #[error("sigma {0} mm: scales must be positive")]
    Sigma(f64),
    #[error("{0} must be positive")]
    NotPositive(&'static str),
    #[error("the volume is empty")]
    Empty,
    #[error("no scales given")]
    NoScales,
}

/// A request checked once and resolved against a grid: what both the CPU pipeline and the GPU
/// job ([`crate::compute::pipeline::FeatureJob`]) compute with.
#[derive(Clone, Debug, PartialEq)]
pub struct Resolved {
    /// Scales (Hessian, structure tensor), mm.
    pub sigmas_mm: Vec<f64>,
    /// Ray directions (RST only; empty otherwise).
    pub rays: Vec<[f64; 3]>,
    /// Ray length and step (RST only; 0 otherwise), mm.
    pub radius_mm: f64,
    pub step_mm: f64,
    /// Integer refinement per axis ([`super::resample::refinement_factors`]).
    pub factors: [usize; 3],
    /// The grid the method computes on: the input refined by `factors`.
    pub compute: Grid,
    /// What the user should be told (refinement, scale warnings).
    pub notes: Vec<String>,
}

const AXES: [&str; 3] = ["x", "y", "z"];

impl Request {
    /// Checks the request and resolves the preset's defaults, the refinement and the warnings
    /// for a volume on `grid` (the one request check of both pipelines).
    pub fn resolve(&self, grid: &Grid) -> Result<Resolved, RequestError> {
        if grid.is_empty() {
            return Err(RequestError::Empty);
        }
        let sigmas_mm = self
            .sigmas_mm
            .clone()
            .unwrap_or_else(|| self.preset.sigmas_mm());
        if sigmas_mm.is_empty() {
            return Err(RequestError::NoScales);
        }
        if let Some(&s) = sigmas_mm.iter().find(|s| !(s.is_finite() && **s > 0.0)) {
            return Err(RequestError::Sigma(s));
        }
        if !(self.sigma_g_mm.is_finite() && self.sigma_g_mm > 0.0) {
            return Err(RequestError::NotPositive("--sigma-g-mm"));
        }
        // A scale wider than the grid holds only costs time (kernels of millions of taps on a
        // grid of microscopic spacing): cap it at a sixth of the volume's largest extent, so
        // that a kernel reaches about half of it, and say so.
        let extent_mm = (0..3)
            .map(|a| grid.dims[a] as f64 * grid.spacing_mm[a])
            .fold(0.0, f64::max);
        let cap_mm = extent_mm / 6.0;
        let mut capped = Vec::new();
        let sigmas_mm: Vec<f64> = sigmas_mm
            .into_iter()
            .map(|s| {
                if cap_mm > 0.0 && s > cap_mm {
                    capped.push(s);
                    cap_mm
                } else {
                    s
                }
            })
            .collect();
        // A preset's Hessian scales below half the thick spacing answer to the slices, not to
        // shape (docs/science.md, "Thick slices"): they are dropped on this volume (the largest
        // is kept if none is left). Scales the user chose are kept, with the warning below.
        let thick_mm = (0..3)
            .filter(|&a| grid.dims[a] > 1)
            .map(|a| grid.spacing_mm[a])
            .fold(0.0, f64::max);
        // The preset's scales are those of a request that names none (the app names its
        // scales only once the user changed them; the CLI with --sigma-mm).
        let from_preset = self.sigmas_mm.is_none();
        let mut dropped = Vec::new();
        let sigmas_mm = if from_preset
            && matches!(self.method, Method::Hessian | Method::Li | Method::Frangi)
        {
            let largest = sigmas_mm.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let (keep, drop): (Vec<f64>, Vec<f64>) = sigmas_mm
                .into_iter()
                .partition(|&s| s >= 0.5 * thick_mm || s == largest);
            dropped = drop;
            keep
        } else {
            sigmas_mm
        };
        let sigma_min = sigmas_mm.iter().copied().fold(f64::INFINITY, f64::min);
        let factors = match self.method {
            Method::Hessian | Method::Li | Method::Frangi => refinement_factors(grid, sigma_min),
            Method::Rst if self.rule == OpacityRule::Consistent && self.refine_slices => {
                rst_refinement_factors(grid, self.step_mm.unwrap_or(DEFAULT_STEP_MM))
            }
            Method::Gst | Method::Rst => [1; 3],
        };
        // The RST's refinement is of z only: its output is laid out on the input's rows.
        debug_assert!(self.method != Method::Rst || factors[..2] == [1, 1]);
        let compute = refined_grid(grid, factors);
        let mut notes = Vec::new();
        if self.refine_slices
            && !(self.method == Method::Rst && self.rule == OpacityRule::Consistent)
        {
            notes.push(
                "--refine-slices refines for the RST's rays with the consistent rule only: ignored here"
                    .to_owned(),
            );
        }
        if !capped.is_empty()
            && matches!(
                self.method,
                Method::Hessian | Method::Li | Method::Frangi | Method::Gst
            )
        {
            notes.push(format!(
                "warning: scales {capped:?} mm are wider than the volume holds ({extent_mm:.3} mm at most): capped at {cap_mm:.4} mm"
            ));
        }
        if !dropped.is_empty() {
            notes.push(format!(
                "the preset's scales {dropped:?} mm are below half the slice spacing ({thick_mm:.3} mm) and answer to the slices, not to shape: dropped on this volume (scales {sigmas_mm:?} mm)"
            ));
        }
        if compute != *grid {
            notes.push(if self.method == Method::Rst {
                format!(
                    "slices refined for the rays by {factors:?} ({:?} mm -> {:.3?} mm), opacity lengths from the acquired spacing; features at the input voxels",
                    grid.spacing_mm, compute.spacing_mm
                )
            } else {
                format!(
                    "thick axes refined for the Hessian by {factors:?} ({:?} mm -> {:.3?} mm); features taken at the input voxels",
                    grid.spacing_mm, compute.spacing_mm
                )
            });
        }
        // Scale warnings on the input grid, per axis: what the data can show at that scale.
        let (scale_name, scales): (&str, Vec<f64>) = match self.method {
            Method::Hessian | Method::Li | Method::Frangi => ("sigma", sigmas_mm.clone()),
            Method::Gst | Method::Rst => ("the gradient scale sigma_g", vec![self.sigma_g_mm]),
        };
        for s in scales {
            for a in 0..3 {
                let sp = grid.spacing_mm[a];
                if grid.dims[a] > 1 && s < 0.5 * sp {
                    notes.push(format!(
                        "warning: {scale_name} {s} mm is below half the {} spacing ({sp:.3} mm) of the input: detail along {} is limited by the slices{}",
                        AXES[a],
                        AXES[a],
                        if factors[a] > 1 {
                            format!(" (refined by {} for the kernels)", factors[a])
                        } else {
                            String::new()
                        }
                    ));
                }
            }
        }
        let (mut rays, mut radius_mm, mut step_mm) = (Vec::new(), 0.0, 0.0);
        if self.method == Method::Rst {
            let n_rays = self.rays.unwrap_or(42);
            rays = rays::ray_set(n_rays).ok_or(RequestError::RayCount(n_rays, rays::RAY_COUNTS))?;
            radius_mm = self.radius_mm.unwrap_or_else(|| self.preset.radius_mm());
            // The paper's rule steps one voxel unless told otherwise.
            step_mm = self.step_mm.unwrap_or(match self.rule {
                OpacityRule::Consistent => DEFAULT_STEP_MM,
                OpacityRule::Paper => compute.min_spacing_mm(),
            });
            if !(radius_mm.is_finite() && radius_mm > 0.0) {
                return Err(RequestError::NotPositive("--radius-mm"));
            }
            if !(step_mm.is_finite() && step_mm > 0.0) {
                return Err(RequestError::NotPositive("--step-mm"));
            }
        }
        Ok(Resolved {
            sigmas_mm,
            rays,
            radius_mm,
            step_mm,
            factors,
            compute,
            notes,
        })
    }
}

/// Runs `req` on `values` (physical values on `grid`).
pub fn compute(grid: &Grid, values: &[f32], req: &Request) -> Result<Outcome, RequestError> {
    let resolved = req.resolve(grid)?;
    let mut notes = resolved.notes.clone();
    let sigmas = resolved.sigmas_mm.clone();
    let (cgrid, cvalues) = refine_linear(grid, values, resolved.factors);
    let mut tf_used = None;
    let mut noise = None;
    let comps = match req.method {
        Method::Hessian | Method::Li | Method::Frangi => {
            if req.eigen {
                hessian_eigen_multiscale(&cgrid, &cvalues, &sigmas)
            } else {
                let m = match req.method {
                    Method::Hessian => HessianMethod::Map(FeatureMap::Simple),
                    Method::Li => HessianMethod::Map(FeatureMap::Li),
                    _ => HessianMethod::Frangi { c: req.frangi_c },
                };
                hessian_features_multiscale(&cgrid, &cvalues, &sigmas, m)
            }
        }
        Method::Gst => {
            let gv = GradientVolume::new(&cgrid, &cvalues, req.sigma_g_mm);
            if req.eigen {
                if sigmas.len() > 1 {
                    notes.push(format!(
                        "--eigen with the structure tensor uses the first scale, {} mm",
                        sigmas[0]
                    ));
                }
                structure_tensor_eigen(&gv, sigmas[0])
            } else {
                let mut best: Option<Components3> = None;
                for &rho in &sigmas {
                    let f = structure_tensor_features(&gv, rho, req.rst_map);
                    best = Some(match best {
                        None => f,
                        Some(mut b) => {
                            for c in 0..3 {
                                for (x, y) in b[c].iter_mut().zip(&f[c]) {
                                    *x = x.max(*y);
                                }
                            }
                            b
                        }
                    });
                }
                best.unwrap_or_else(|| std::array::from_fn(|_| vec![0.0; cgrid.len()]))
            }
        }
        Method::Rst => {
            // On the refined grid; L_i and the output from the acquired one.
            let mut gv = GradientVolume::new(&cgrid, &cvalues, req.sigma_g_mm);
            gv.acquired = *grid;
            let tf = match req.tf {
                Some(tf) => tf,
                None => {
                    noise = estimate_noise_sigma(&cgrid, &gv.intensity, NOISE_BAND_HU);
                    match noise {
                        Some(s) => notes.push(format!("noise of the smoothed intensity: {s:.2} HU (median of 11x11 windows in 0..100 HU)")),
                        None => notes.push("noise: no 11x11 window lies wholly in 0..100 HU; the preset's transfer function is used".to_owned()),
                    }
                    auto_transfer_function(req.preset.transfer_function(), noise)
                }
            };
            notes.push(format!(
                "transfer function: d_min {:.1} HU, d_max {:.1} HU",
                tf.d_min, tf.d_max
            ));
            tf_used = Some(tf);
            let params = RstParams {
                rays: resolved.rays.clone(),
                radius_mm: resolved.radius_mm,
                step_mm: resolved.step_mm,
                tf,
                rule: req.rule,
            };
            if req.eigen {
                rst_eigen(&gv, &params)
            } else {
                rst_features(&gv, &params, req.rst_map)
            }
        }
    };
    // The RST is evaluated at the input voxels only (`GradientVolume::acquired`).
    let components = if cgrid == *grid || req.method == Method::Rst {
        comps
    } else {
        comps.map(|c| subsample(&cgrid, &c, resolved.factors, grid))
    };
    Ok(Outcome {
        components,
        notes,
        tf: tf_used,
        noise_sigma_hu: noise,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On 5 mm slices the lung preset's scales below 2.5 mm are dropped (and said so), the
    /// refinement follows the smallest kept scale; scales the user gave are kept with a
    /// warning; thin slices keep every scale; the RST is not touched.
    #[test]
    fn a_presets_scales_below_half_the_slice_spacing_are_dropped() {
        let thick = Grid::new([64, 64, 20], [0.7, 0.7, 5.0]);
        let mut req = Request::new(Method::Hessian);
        req.preset = Preset::LungNodules;
        let r = req.resolve(&thick).expect("resolves");
        assert_eq!(r.sigmas_mm, [3.0, 4.5, 6.5, 9.0]);
        assert!(
            r.notes
                .iter()
                .any(|n| n.contains("[1.5, 2.0] mm") && n.contains("dropped")),
            "{:?}",
            r.notes
        );
        // Scales a user names stay, even the preset's own list (with the warning).
        req.sigmas_mm = Some(Preset::LungNodules.sigmas_mm());
        assert_eq!(req.resolve(&thick).expect("resolves").sigmas_mm.len(), 6);
        // A user's own scales stay, with the warning.
        req.sigmas_mm = Some(vec![1.0, 2.0]);
        let own = req.resolve(&thick).expect("resolves");
        assert_eq!(own.sigmas_mm, [1.0, 2.0]);
        assert!(
            own.notes
                .iter()
                .any(|n| n.contains("below half the z spacing"))
        );
        // Thin slices: all six.
        req.sigmas_mm = None;
        let thin = Grid::new([64, 64, 64], [0.7, 0.7, 1.0]);
        assert_eq!(req.resolve(&thin).expect("resolves").sigmas_mm.len(), 6);
        // Every scale below half the spacing: the largest stays.
        req.preset = Preset::Vessels;
        let very = Grid::new([64, 64, 10], [0.7, 0.7, 10.0]);
        assert_eq!(req.resolve(&very).expect("resolves").sigmas_mm, [4.0]);
        let rst = Request::new(Method::Rst).resolve(&thick).expect("resolves");
        assert!(rst.notes.iter().all(|n| !n.contains("dropped")));
    }
}
