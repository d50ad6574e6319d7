//! The WGSL kernels on a real device (lavapipe in CI) against their CPU twins, the ray caster, the
//! feature job and its memory; one binary so that the suite links once.

#[path = "../common/mod.rs"]
mod common;
#[path = "../eigen_common/mod.rs"]
mod eigen_common;
#[path = "../gpu_common/mod.rs"]
mod gpu_common;

mod alloc;
mod eigen;
mod hessian;
mod levels;
mod memory;
mod pipeline;
mod raycast;
mod real_ct;
mod resample;
mod roundtrip;
mod rst;
mod shader_validation;
mod slice;
