//! The whole app rendered through wgpu on the test adapter (lavapipe) with egui_kittest: it must
//! reach "ready" on its demo volume, draw a non-blank picture (saved for a person to look at),
//! and move the crosshair where a slice pane is clicked.

use std::sync::Arc;

use egui_kittest::Harness;
use egui_kittest::kittest::Queryable as _;
use shapecast::app::ShapecastApp;
use shapecast::status::Phase;

fn harness() -> Option<Harness<'static, ShapecastApp>> {
    // The same adapter rule as the GPU tests: skip visibly without one, fail under CI=true.
    shapecast::gpu::context::test_context()?;
    let mut setup = egui_kittest::wgpu::default_wgpu_setup();
    if let eframe::egui_wgpu::WgpuSetup::CreateNew(create) = &mut setup {
        create.device_descriptor = Arc::new(shapecast::gpu::context::device_descriptor);
    }
    let mut harness = Harness::builder()
        .with_size(egui::vec2(1280.0, 800.0))
        .wgpu_setup(setup)
        .build_eframe(|cc| ShapecastApp::new(cc));
    for _ in 0..20 {
        harness.step();
        if harness.state().status().phase == Phase::Ready {
            break;
        }
    }
    harness.run_steps(2);
    Some(harness)
}

#[test]
fn app_reaches_ready_and_draws() {
    let Some(mut harness) = harness() else { return };
    let status = harness.state().status().clone();
    assert_eq!(status.phase, Phase::Ready, "{status:?}");
    assert_eq!(status.volume.as_ref().map(|v| v.dims), Some([96, 96, 96]));
    let image = harness.render().expect("render");
    let out = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("app_native.png");
    image.save(&out).expect("save screenshot");
    eprintln!("screenshot: {}", out.display());
    // The MIP in the middle of the central panel shows the bright vessels of the demo phantom.
    let mut distinct = std::collections::HashSet::new();
    let mut bright = 0usize;
    for p in image.pixels() {
        distinct.insert([p[0], p[1], p[2]]);
        if p[0] > 200 && p[1] > 200 && p[2] > 200 {
            bright += 1;
        }
    }
    assert!(distinct.len() >= 64, "only {} colours", distinct.len());
    assert!(
        bright > 5000,
        "only {bright} bright pixels: the MIP is missing"
    );
}

#[test]
fn clicking_the_axial_pane_moves_the_crosshair() {
    let Some(mut harness) = harness() else { return };
    let before = harness.state().crosshair();
    // The axial pane is the first image in the right-hand panel; find it through its label.
    let label = harness
        .query_by_label_contains("axial")
        .map(|n| n.rect())
        .expect("axial pane label");
    let target = egui::pos2(label.left() + 30.0, label.bottom() + 40.0);
    harness.drag_at(target);
    harness.run_steps(1);
    harness.drop_at(target);
    harness.run_steps(2);
    let after = harness.state().crosshair();
    assert_eq!(after[2], before[2], "the axial slice itself stays");
    assert_ne!(
        (after[0], after[1]),
        (before[0], before[1]),
        "crosshair did not move"
    );
}
