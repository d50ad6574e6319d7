//! The feature pipeline the app and `shapecast features --backend gpu` run: one volume in, one
//! method's features out, on the GPU, as a [`FeatureTexture`] for rendering (and read back only
//! for export and tests).
//!
//! It is a job advanced by [`FeatureJob::step`], a bounded amount of work per call, so the app
//! calls it once per frame and stays responsive, shows progress, and can cancel by dropping it.
//!
//! (First version: runs the CPU reference in one step. The slab-by-slab GPU version replaces the
//! inside; the API stays.)

use crate::cpu::Grid;
use crate::cpu::pipeline::{Outcome, Request, RequestError, compute};
use crate::gpu::GpuContext;
use crate::gpu::render_volume::{FeatureTexture, RenderVolumeError};
use crate::volume::Volume;

/// Why a feature computation failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PipelineError {
    #[error(transparent)]
    Request(#[from] RequestError),
    #[error(transparent)]
    Texture(#[from] RenderVolumeError),
}

/// Where a job is.
#[derive(Clone, Debug, PartialEq)]
pub enum JobState {
    /// `fraction` of the work done (0..1), and what it is doing now.
    Running {
        fraction: f32,
        stage: String,
    },
    Done,
}

/// One method's features for one volume, computed step by step.
pub struct FeatureJob {
    grid: Grid,
    values: Option<Vec<f32>>,
    request: Request,
    dims: [u32; 3],
    result: Option<(FeatureTexture, Outcome)>,
}

impl FeatureJob {
    pub fn new(
        _ctx: &GpuContext,
        volume: &Volume,
        request: &Request,
    ) -> Result<Self, PipelineError> {
        let dims = volume.dims.map(|d| u32::try_from(d).unwrap_or(u32::MAX));
        Ok(Self {
            grid: Grid::of(volume),
            values: Some(volume.to_f32()),
            request: request.clone(),
            dims,
            result: None,
        })
    }

    /// Does the next bounded piece of work.
    pub fn step(&mut self, ctx: &GpuContext) -> Result<JobState, PipelineError> {
        if let Some(values) = self.values.take() {
            let outcome = compute(&self.grid, &values, &self.request)?;
            let tex =
                FeatureTexture::from_components(ctx, self.dims, &outcome.components, "features")?;
            self.result = Some((tex, outcome));
        }
        Ok(JobState::Done)
    }

    /// Progress so far, without doing work.
    pub fn state(&self) -> JobState {
        if self.result.is_some() {
            JobState::Done
        } else {
            JobState::Running {
                fraction: 0.0,
                stage: "starting".to_owned(),
            }
        }
    }

    /// What the user should be told (resampling, transfer function, warnings).
    pub fn notes(&self) -> &[String] {
        self.result
            .as_ref()
            .map_or(&[], |(_, o)| o.notes.as_slice())
    }

    /// The features once [`JobState::Done`]; `None` before.
    pub fn finish(self) -> Option<FeatureTexture> {
        self.result.map(|(t, _)| t)
    }
}
