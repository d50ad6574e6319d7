//! The RST's rays on the GPU ([`RstRays`]): the ray set with each ray's opacity length and step,
//! checked and uploaded once per run, and how far they reach (the slab's halo).

use super::*;

/// Why a ray configuration was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum RstConfigError {
    #[error("the RST needs between 1 and {MAX_RAYS} rays, got {0}")]
    RayCount(usize),
    #[error("ray {index} is not a finite unit vector: {dir:?}")]
    BadRay { index: usize, dir: [f64; 3] },
    #[error(
        "the RST step ({step_mm} mm) and ray length ({radius_mm} mm) must be finite, step > 0, length >= 0"
    )]
    BadLength { step_mm: f64, radius_mm: f64 },
    #[error("the RST would take {steps} steps per ray (at most {MAX_STEPS})")]
    TooManySteps { steps: f64 },
    #[error("the voxel spacing {0:?} mm must be finite and positive")]
    BadSpacing([f64; 3]),
    #[error("sigma_g ({0} mm) must be finite and >= 0")]
    BadSigma(f64),
    #[error("the transfer function ({d_min}, {d_max}) must be finite")]
    BadTransferFunction { d_min: f64, d_max: f64 },
}

/// Everything constant over an RST run, on the GPU: the ray set with each ray's opacity length
/// L_i and step in voxels (f64 on the CPU, then f32), the step count K, transfer function and
/// rule. Valid for one voxel spacing and one sigma_g.
pub struct RstRays {
    pub(super) buffer: wgpu::Buffer,
    pub(super) n_rays: u32,
    pub(super) steps: u32,
    pub(super) step_mm: f64,
    pub(super) dr_vox: f64,
    pub(super) d_min: f64,
    pub(super) d_max: f64,
    pub(super) rule: OpacityRule,
    pub(super) spacing_mm: [f64; 3],
    /// Largest |r_z| * K * dr / s_z over the rays: how many slices a ray reaches along z.
    pub(super) reach_z_vox: f64,
}

impl RstRays {
    /// Uploads the rays of `params` for a grid of `spacing_mm` whose gradient volume was made
    /// with `sigma_g_mm`. The opacity lengths come from the twin's [`opacity_length_mm`], K from
    /// [`RstParams::steps`].
    pub fn new(
        ctx: &GpuContext,
        params: &RstParams,
        spacing_mm: [f64; 3],
        sigma_g_mm: f64,
    ) -> Result<Self, RstConfigError> {
        Self::refined(ctx, params, spacing_mm, spacing_mm, sigma_g_mm)
    }

    /// [`Self::new`] for a gradient volume on a grid of `spacing_mm` refined from data acquired
    /// at `acquired_spacing_mm` (`GradientVolume::refined` in the twin): steps in refined
    /// voxels, opacity lengths from the acquired spacing.
    pub fn refined(
        ctx: &GpuContext,
        params: &RstParams,
        spacing_mm: [f64; 3],
        acquired_spacing_mm: [f64; 3],
        sigma_g_mm: f64,
    ) -> Result<Self, RstConfigError> {
        let n = params.rays.len();
        if n == 0 || n > MAX_RAYS {
            return Err(RstConfigError::RayCount(n));
        }
        for spacing in [spacing_mm, acquired_spacing_mm] {
            if !spacing.iter().all(|s| s.is_finite() && *s > 0.0) {
                return Err(RstConfigError::BadSpacing(spacing));
            }
        }
        if !(sigma_g_mm.is_finite() && sigma_g_mm >= 0.0) {
            return Err(RstConfigError::BadSigma(sigma_g_mm));
        }
        let (step_mm, radius_mm) = (params.step_mm, params.radius_mm);
        if !(step_mm.is_finite() && step_mm > 0.0 && radius_mm.is_finite() && radius_mm >= 0.0) {
            return Err(RstConfigError::BadLength { step_mm, radius_mm });
        }
        let steps_f = (radius_mm / step_mm + 1e-6).floor();
        if steps_f > MAX_STEPS as f64 {
            return Err(RstConfigError::TooManySteps { steps: steps_f });
        }
        let (d_min, d_max) = (params.tf.d_min, params.tf.d_max);
        if !(d_min.is_finite() && d_max.is_finite()) {
            return Err(RstConfigError::BadTransferFunction { d_min, d_max });
        }
        let steps = params.steps();
        let acquired = crate::cpu::Grid::new([1, 1, 1], acquired_spacing_mm);
        let mut rays = Vec::with_capacity(n);
        let mut max_rz = 0.0f64;
        for (index, r) in params.rays.iter().enumerate() {
            let norm = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
            let unit = r.iter().all(|c| c.is_finite()) && (norm - 1.0).abs() < 1e-6;
            if !unit {
                return Err(RstConfigError::BadRay { index, dir: *r });
            }
            let len = opacity_length_mm(&acquired, sigma_g_mm, *r);
            max_rz = max_rz.max(r[2].abs());
            rays.push(GpuRay {
                dir_len: [r[0] as f32, r[1] as f32, r[2] as f32, len as f32],
                step_vox: [
                    (step_mm * r[0] / spacing_mm[0]) as f32,
                    (step_mm * r[1] / spacing_mm[1]) as f32,
                    (step_mm * r[2] / spacing_mm[2]) as f32,
                    0.0,
                ],
            });
        }
        let buffer = crate::gpu::kernel::storage_buffer_init(&ctx.device, "rst rays", &rays);
        let min_spacing = spacing_mm.iter().copied().fold(f64::INFINITY, f64::min);
        Ok(Self {
            buffer,
            n_rays: n as u32,
            steps: steps as u32,
            step_mm,
            dr_vox: step_mm / min_spacing,
            d_min,
            d_max,
            rule: params.rule,
            spacing_mm,
            reach_z_vox: max_rz * steps as f64 * step_mm / spacing_mm[2],
        })
    }

    pub fn ray_count(&self) -> u32 {
        self.n_rays
    }

    /// K, the most steps a ray takes.
    pub fn steps(&self) -> u32 {
        self.steps
    }

    /// The most ray samples (trilinear reads of I and g) per output voxel: N_R * K. Early ray
    /// termination makes the real count smaller (about 60 per ray in homogeneous tissue at the
    /// defaults, 24 inside an object; [`RstOutput::SampleCount`] measures it).
    pub fn max_samples_per_voxel(&self) -> u64 {
        u64::from(self.n_rays) * u64::from(self.steps)
    }

    /// Slices of smoothed intensity and gradient the rays read beyond each side of the output
    /// range: ceil(max_i |r_i,z| K dr / s_z). (A sample exactly on a slice also touches the next
    /// one with weight 0, or ~1e-7 after f32 rounding; that slice may be missing.)
    pub fn halo_slices(&self) -> u32 {
        ((self.reach_z_vox - 1e-6).ceil().max(0.0)) as u32
    }

    /// Slices of *smoothed intensity* the RST plus the gradient kernel need beyond each side of
    /// the output range: [`Self::halo_slices`] + [`Gradient::HALO_SLICES`]. The Gaussian
    /// smoothing that produces it needs its own kernel radius more of raw intensity.
    pub fn total_halo_slices(&self) -> u32 {
        self.halo_slices() + Gradient::HALO_SLICES
    }

    /// The spacing the rays were built for.
    pub fn spacing_mm(&self) -> [f64; 3] {
        self.spacing_mm
    }
}
