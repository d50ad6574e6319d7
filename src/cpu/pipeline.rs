//! The whole CPU feature computation for one volume, as `shapecast features` runs it: preset
//! defaults, thick axes resampled to <= 1.25 mm, the automatic transfer function, the chosen
//! method, and the result put back on the input's grid (SCIENCE.md, "What real scans taught us"
//! and "Conventions of the command line and the app").

use super::features::{
    FeatureMap, HessianMethod, hessian_eigen_multiscale, hessian_features_multiscale,
};
use super::resample::{resample_linear, resample_thick_axes};
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
}

/// Runs `req` on `values` (physical values on `grid`).
pub fn compute(grid: &Grid, values: &[f32], req: &Request) -> Result<Outcome, RequestError> {
    if grid.is_empty() {
        return Err(RequestError::Empty);
    }
    let mut notes = Vec::new();
    let sigmas = req
        .sigmas_mm
        .clone()
        .unwrap_or_else(|| req.preset.sigmas_mm());
    if let Some(&s) = sigmas.iter().find(|s| !(s.is_finite() && **s > 0.0)) {
        return Err(RequestError::Sigma(s));
    }
    let (cgrid, cvalues) = resample_thick_axes(grid, values);
    if cgrid != *grid {
        notes.push(format!(
            "thick axes resampled for the features: {:?} mm -> {:.3?} mm ({:?} voxels); output on the input grid",
            grid.spacing_mm, cgrid.spacing_mm, cgrid.dims
        ));
    }
    let uses_sigmas = matches!(
        req.method,
        Method::Hessian | Method::Li | Method::Frangi | Method::Gst
    );
    let max_spacing = cgrid.spacing_mm.iter().copied().fold(0.0, f64::max);
    if uses_sigmas {
        for s in &sigmas {
            if *s < 0.5 * max_spacing {
                notes.push(format!(
                    "warning: sigma {s} mm is below half the spacing ({max_spacing:.3} mm)"
                ));
            }
        }
    }
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
            let n_rays = req.rays.unwrap_or(42);
            let rays =
                rays::ray_set(n_rays).ok_or(RequestError::RayCount(n_rays, rays::RAY_COUNTS))?;
            let radius_mm = req.radius_mm.unwrap_or_else(|| req.preset.radius_mm());
            // The paper's rule steps one voxel unless told otherwise.
            let step_mm = req.step_mm.unwrap_or(match req.rule {
                OpacityRule::Consistent => DEFAULT_STEP_MM,
                OpacityRule::Paper => cgrid.min_spacing_mm(),
            });
            if radius_mm.is_nan() || radius_mm <= 0.0 {
                return Err(RequestError::NotPositive("--radius-mm"));
            }
            if step_mm.is_nan() || step_mm <= 0.0 {
                return Err(RequestError::NotPositive("--step-mm"));
            }
            let gv = GradientVolume::new(&cgrid, &cvalues, req.sigma_g_mm);
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
                rays,
                radius_mm,
                step_mm,
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
    let components = if cgrid == *grid {
        comps
    } else {
        comps.map(|c| resample_linear(&cgrid, &c, grid))
    };
    Ok(Outcome {
        components,
        notes,
        tf: tf_used,
        noise_sigma_hu: noise,
    })
}
