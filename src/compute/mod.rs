//! Feature compute on the GPU: one module per WGSL kernel (pipelines and the bytemuck structs
//! mirroring their WGSL structs, each with a CPU twin in `crate::cpu`), the brick plan, and the
//! feature job that runs a request brick by brick into a `crate::gpu::volume_texture`
//! feature texture. Uses `crate::gpu` and `crate::cpu`; never `crate::render`.

pub mod eigen_features;
pub mod gaussian;
pub mod gradient;
pub mod hessian;
pub mod noise;
pub mod pack;
pub mod pipeline;
pub mod resample;
pub mod rst;
pub mod slab;
pub mod structure_tensor;
