//! Shapecast: shape-encoding maximum intensity projections of CT and MRI volumes (Hessian and
//! radial structure tensor features after Wiemker et al. 2013), in the browser and natively.
//!
//! ARCHITECTURE.md at the repository root is the map of this crate.

pub mod app;
pub mod compute;
pub mod cpu;
pub mod error;
pub mod gpu;
pub mod io;
pub mod phantom;
pub mod render;
pub mod status;
pub mod volume;

#[cfg(not(target_arch = "wasm32"))]
pub mod cli;
pub mod files;

pub use volume::{Modality, Volume, Voxels};

#[cfg(target_arch = "wasm32")]
pub mod web;
