//! Memory that a long feature job or a long viewing session must not accumulate, per dispatch.
//! Found with `shapecast bench --whole-body` (issue "full-size scans"): lavapipe (Mesa 22.3)
//! specialises a shader on the uniforms its loops and branches read, compiling and keeping a new
//! variant at every dispatch (~260 KB and ~1.3 ms each, freed only with the pipeline): 2 GB over
//! a 512x512x2000 job of 7,000 paced steps. Kernels therefore take their parameters from a
//! read-only storage buffer (`kernel::params_buffer`). The suite's other tests allocate beside
//! it (68 MB of growth measured once in CI), so the test measures in a process of its own: it
//! runs its own binary again with only itself selected.

use crate::gpu_common;

use gpu_common::*;
use shapecast::compute::gaussian::{AxisPass, Gaussian, PassKernels, SeparableKernel};
use shapecast::gpu::context::test_context;
use shapecast::gpu::kernel::Recorder;

#[cfg(target_os = "linux")]
fn resident_mb() -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").expect("/proc/self/status");
    let line = status
        .lines()
        .find(|l| l.starts_with("VmRSS:"))
        .expect("VmRSS");
    let kb: f64 = line
        .split_whitespace()
        .nth(1)
        .and_then(|v| v.parse().ok())
        .expect("VmRSS value");
    kb / 1024.0
}

/// Set in the child process that measures alone.
#[cfg(target_os = "linux")]
const ALONE: &str = "SHAPECAST_MEMORY_TEST_ALONE";

#[cfg(target_os = "linux")]
#[test]
fn a_thousand_convolution_dispatches_keep_memory_flat() {
    if std::env::var_os(ALONE).is_some() {
        measure_alone();
        return;
    }
    let exe = std::env::current_exe().expect("the test binary's path");
    let out = std::process::Command::new(exe)
        .args([
            "memory::a_thousand_convolution_dispatches_keep_memory_flat",
            "--exact",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(ALONE, "1")
        .output()
        .expect("run the test binary again");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    eprintln!("{text}");
    assert!(out.status.success(), "measured alone, it failed: {text}");
    assert!(
        text.contains("1 passed"),
        "the measuring process ran no test: {text}"
    );
}

#[cfg(target_os = "linux")]
fn measure_alone() {
    let Some(ctx) = test_context() else { return };
    let (grid, values) = phantom();
    let sg = slab_grid(&grid);
    let gaussian = Gaussian::new(&ctx).expect("shader");
    let kernel = SeparableKernel::smooth(&ctx, 1.0, grid.spacing_mm);
    let a = upload(&ctx, &values);
    let b = buffer(&ctx, values.len());
    let run = |n: usize| {
        for i in 0..n {
            let mut enc = encoder(&ctx);
            let axis = i % 3;
            gaussian
                .record_pass(
                    &mut Recorder::new(&ctx, &mut enc),
                    &AxisPass {
                        grid: &sg,
                        axis,
                        region: None,
                        kernels: PassKernels::One(&kernel.axes[axis]),
                        src: &a,
                        dst: &[&b],
                    },
                )
                .expect("record");
            submit(&ctx, enc);
            ctx.device
                .poll(wgpu::PollType::wait_indefinitely())
                .expect("poll");
        }
    };
    // Warm up (pipelines, allocator pools), then measure.
    run(100);
    let before = resident_mb();
    run(1000);
    let grown = resident_mb() - before;
    eprintln!("1000 dispatches: resident memory grew by {grown:.1} MB");
    // A variant kept per dispatch would add ~250 MB here.
    assert!(
        grown < 25.0,
        "memory grew by {grown:.1} MB over 1000 dispatches"
    );
}
