//! The kernels a feature job uses, built once per job for its method (the RST's ray set is
//! added once the transfer function is known).

use crate::compute::eigen_features::EigenFeatures;
use crate::compute::gaussian::{Gaussian, SeparableKernel};
use crate::compute::gradient::Gradient;
use crate::compute::hessian::{Hessian, HessianKernels};
use crate::compute::resample::Resample;
use crate::compute::rst::{Rst, RstRays};
use crate::compute::structure_tensor::StructureTensor;
use crate::compute::{noise, pack};
use crate::cpu::Grid;
use crate::cpu::pipeline::{Method, Request};
use crate::gpu::GpuContext;

use super::PipelineError;

/// The kernels a method needs, built once per job.
pub(super) struct Kernels {
    pub(super) gaussian: Gaussian,
    pub(super) hessian: Hessian,
    pub(super) eigen: EigenFeatures,
    pub(super) resample: Resample,
    pub(super) gradient: Gradient,
    pub(super) rst: Option<Rst>,
    /// The ray set, built once the transfer function is known.
    pub(super) rays: Option<RstRays>,
    pub(super) gst: Option<StructureTensor>,
    pub(super) noise: noise::NoiseWindows,
    pub(super) pack: pack::Pack,
    /// Per-scale kernels, uploaded once.
    pub(super) hessian_kernels: Vec<HessianKernels>,
    pub(super) smooth_g: SeparableKernel,
    pub(super) rho: Vec<SeparableKernel>,
}

impl Kernels {
    pub(super) fn new(
        ctx: &GpuContext,
        req: &Request,
        compute: &Grid,
        sigmas_mm: &[f64],
        exact_rst: bool,
    ) -> Result<Self, PipelineError> {
        let spacing = compute.spacing_mm;
        let hessian_scales = matches!(req.method, Method::Hessian | Method::Li | Method::Frangi);
        let gst = req.method == Method::Gst;
        Ok(Self {
            gaussian: Gaussian::new(ctx)?,
            hessian: Hessian::new(ctx)?,
            eigen: EigenFeatures::new(ctx)?,
            resample: Resample::new(ctx)?,
            gradient: Gradient::new(ctx)?,
            rst: if req.method == Method::Rst {
                Some(Rst::with_options(
                    ctx,
                    crate::compute::rst::RstOptions {
                        hardware_filtering: !exact_rst,
                        ..Default::default()
                    },
                )?)
            } else {
                None
            },
            rays: None,
            gst: if gst {
                Some(StructureTensor::new(ctx)?)
            } else {
                None
            },
            noise: noise::NoiseWindows::new(ctx)?,
            pack: pack::Pack::new(ctx)?,
            hessian_kernels: if hessian_scales {
                sigmas_mm
                    .iter()
                    .map(|&s| HessianKernels::new(ctx, s, spacing, true))
                    .collect()
            } else {
                Vec::new()
            },
            smooth_g: SeparableKernel::smooth(ctx, req.sigma_g_mm, spacing),
            rho: if gst {
                sigmas_mm
                    .iter()
                    .map(|&s| SeparableKernel::smooth(ctx, s, spacing))
                    .collect()
            } else {
                Vec::new()
            },
        })
    }
}
