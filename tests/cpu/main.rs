//! The CPU references (src/cpu), checked against the equations, analytic phantoms and independent
//! implementations; one binary so that the suite links once. The counting allocator (per thread) counts every
//! allocation of this binary.

#[path = "../common/mod.rs"]
mod common;
#[path = "../common/counting.rs"]
mod counting;
#[path = "../cpu_common/mod.rs"]
mod cpu_common;
#[path = "../eigen_common/mod.rs"]
mod eigen_common;

mod adjacency;
mod analytic;
mod bifurcation;
mod eigen;
mod findings_memory;
mod noise;
mod phantoms;
mod real_ct_conspicuity;
mod rst_invariance;
mod structure_tensor;
mod thick_slices;
mod vs_skimage;
