//! The device: the shared GPU context and its limits, the shader sources, the helpers every
//! kernel module uses (storage buffers, uniform structs, size checks, bind groups, dispatch),
//! the one readback, and the 3D volume textures that feature compute writes and rendering
//! reads (the hand-off between `crate::compute` and `crate::render`). Kernels live in
//! `crate::compute` (features) and `crate::render` (projections and slices).

pub mod alloc;
pub mod budget;
pub mod checks;
pub mod context;
pub mod kernel;
pub mod readback;
pub mod shaders;
pub mod timing;
pub mod volume_texture;

pub use context::{AdapterPreference, GpuContext, GpuError};
