//! Everything that touches wgpu: the shared context, the shader sources, and one module per
//! kernel that owns its pipeline and the bytemuck structs mirroring its WGSL structs.

pub mod checks;
pub mod context;
pub mod eigen_features;
pub mod gaussian;
pub mod gradient;
pub mod hessian;
pub mod kernel;
pub mod noise;
pub mod pack;
pub mod pipeline;
pub mod probe;
pub mod raycast;
pub mod readback;
pub mod render_volume;
pub mod resample;
pub mod rst;
pub mod shaders;
pub mod slab;
pub mod slice;
pub mod structure_tensor;

pub use context::{AdapterPreference, GpuContext, GpuError};
