//! Everything that touches wgpu: the shared context, the shader sources, and one module per
//! kernel that owns its pipeline and the bytemuck structs mirroring its WGSL structs.

pub mod axis_mip;
pub mod context;
pub mod kernel;
pub mod pipeline;
pub mod raycast;
pub mod readback;
pub mod render_volume;
pub mod shaders;
pub mod volume;

pub use context::{AdapterPreference, GpuContext, GpuError};
pub use volume::GpuVolume;
