//! The MIP viewport widget hosted alone in a minimal eframe app, rendered through wgpu on the
//! test adapter (lavapipe) with egui_kittest and driven as a person would: the first frame shows
//! red vessels and yellow nodules, nothing re-renders while idle, a drag turns the picture, the
//! wheel zooms, shift + drag pans, and a click on a nodule lands inside it.
//!
//! It is also the example of wiring the widget into an app (see `Host::ui`).

use std::sync::Arc;

use egui_kittest::Harness;
use egui_kittest::kittest::Queryable as _;
use glam::DVec3;
use shapecast::app::mip_view::{MipScene, MipView};
use shapecast::compute::pipeline::{FeatureJob, JobState};
use shapecast::cpu::pipeline::{Method, Request};
use shapecast::gpu::GpuContext;
use shapecast::gpu::volume_texture::{FeatureTexture, RenderVolume};
use shapecast::phantom::{NODULE_RADIUS_MM, Phantom, bifurcation_nodule_centres};
use shapecast::render::raycast::{FramePacer, Pick};

/// The smallest app hosting the widget: the GPU textures, the widget, and the crosshair the
/// picks move.
struct Host {
    gpu: GpuContext,
    volume: RenderVolume,
    hessian: FeatureTexture,
    view: MipView,
    crosshair: Option<[usize; 3]>,
    last_pick: Option<Pick>,
}

impl Host {
    fn new(cc: &eframe::CreationContext<'_>, pacer: FramePacer) -> Self {
        let rs = cc.wgpu_render_state.as_ref().expect("wgpu renderer");
        let gpu = GpuContext::from_render_state(rs);
        let phantom = Phantom::by_name("bifurcation-nodules-far", None).expect("phantom");
        let volume = phantom.render([1.0; 3]);
        let mut job = FeatureJob::new(&gpu, &volume, &Request::new(Method::Hessian)).expect("job");
        while job.step(&gpu).expect("step") != JobState::Done {}
        let hessian = job.finish().expect("features");
        let render_volume = RenderVolume::upload(&gpu, &volume).expect("upload");
        let mut view = MipView::new();
        view.settings.window = (40.0, 140.0);
        view.pacer = pacer;
        Self {
            gpu,
            volume: render_volume,
            hessian,
            view,
            crosshair: None,
            last_pick: None,
        }
    }
}

impl eframe::App for Host {
    fn ui(&mut self, ui: &mut egui::Ui, frame: &mut eframe::Frame) {
        let Some(rs) = frame.wgpu_render_state() else {
            return;
        };
        let features = [("Hessian", &self.hessian)];
        let scene = MipScene {
            volume: &self.volume,
            features: &features,
        };
        egui::CentralPanel::default().show(ui, |ui| {
            self.view.controls_ui(ui, &scene);
            let out = self.view.image_ui(ui, &self.gpu, rs, &scene);
            if let Some(pick) = out.pick {
                self.crosshair = Some(pick.voxel);
                self.view.set_crosshair(Some(pick.world_mm));
                self.last_pick = Some(pick);
            }
        });
    }
}

/// Frames drawn whole: the interaction test below checks what each frame shows.
fn harness() -> Option<Harness<'static, Host>> {
    harness_with(FramePacer::new(None))
}

fn harness_with(pacer: FramePacer) -> Option<Harness<'static, Host>> {
    shapecast::gpu::context::test_context()?;
    let mut setup = egui_kittest::wgpu::default_wgpu_setup();
    if let eframe::egui_wgpu::WgpuSetup::CreateNew(create) = &mut setup {
        create.device_descriptor = Arc::new(shapecast::gpu::context::device_descriptor);
    }
    let mut harness = Harness::builder()
        .with_size(egui::vec2(640.0, 560.0))
        .wgpu_setup(setup)
        .build_eframe(move |cc| Host::new(cc, pacer));
    harness.run_steps(3);
    Some(harness)
}

fn count(image: &image::RgbaImage, f: impl Fn([u8; 4]) -> bool) -> usize {
    image.pixels().filter(|p| f(p.0)).count()
}

fn save(image: &image::RgbaImage, name: &str) {
    let out = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    image.save(&out).expect("save screenshot");
    eprintln!("screenshot: {}", out.display());
}

fn red(c: [u8; 4]) -> bool {
    c[0] > 150 && c[1] < 90 && c[2] < 90
}
fn yellow(c: [u8; 4]) -> bool {
    c[0] > 200 && c[1] > 170 && c[2] < 90
}

#[test]
fn mip_view_renders_turns_zooms_pans_and_picks_a_nodule() {
    let Some(mut h) = harness() else { return };
    assert_eq!(h.state().view.error(), None);
    let frames = h.state().view.frames_rendered();
    assert!(frames >= 1, "nothing rendered");
    let first = h.render().expect("render");
    save(&first, "mip_view_anterior.png");
    let (reds, yellows) = (count(&first, red), count(&first, yellow));
    eprintln!("{reds} red, {yellows} yellow pixels");
    assert!(reds > 2000 && yellows > 500, "{reds} red, {yellows} yellow");

    // Idle: nothing changes, nothing re-renders.
    h.run_steps(3);
    assert_eq!(h.state().view.frames_rendered(), frames);

    // Drag with the left button: the volume turns, the picture changes.
    let rotation = h.state().view.camera.rotation;
    let centre = h
        .state()
        .view
        .screen_pos_of(h.state().view.camera.centre_mm)
        .expect("centre");
    h.drag_at(centre);
    h.step();
    for dx in [10.0, 25.0, 45.0, 70.0] {
        h.hover_at(centre + egui::vec2(dx, 0.4 * dx));
        h.step();
    }
    assert!(
        h.state().view.showing_preview(),
        "a drag draws the reduced-resolution preview"
    );
    h.drop_at(centre + egui::vec2(70.0, 28.0));
    h.run_steps(2);
    assert!(
        !h.state().view.showing_preview(),
        "full resolution when the mouse stops"
    );
    let angle = h
        .state()
        .view
        .camera
        .rotation
        .angle_between(rotation)
        .to_degrees();
    assert!(
        angle > 10.0,
        "the drag turned the view by only {angle} degrees"
    );
    assert!(h.state().view.frames_rendered() > frames);
    assert!(h.state().last_pick.is_none(), "a drag must not pick");
    let turned = h.render().expect("render");
    save(&turned, "mip_view_turned.png");
    let changed = first
        .pixels()
        .zip(turned.pixels())
        .filter(|(a, b)| a.0.iter().zip(b.0).any(|(x, y)| x.abs_diff(y) > 40))
        .count();
    assert!(changed > 2000, "only {changed} pixels changed");

    // Back to the anterior view through its button, then click the nodule in the crotch.
    h.get_by_label("A").click();
    h.run_steps(2);
    h.run_steps(2);
    let nodule = DVec3::from(bifurcation_nodule_centres(3.0)[0]);
    let at = h
        .state()
        .view
        .screen_pos_of(nodule)
        .expect("nodule in view");
    h.drag_at(at);
    h.drop_at(at);
    // The readback finishes when the GPU (a CPU here) is done: keep repainting, as the app does.
    h.step();
    assert!(
        h.state().view.pick_pending() || h.state().last_pick.is_some(),
        "the click did not start a pick"
    );
    let started = std::time::Instant::now();
    while h.state().last_pick.is_none() && started.elapsed().as_secs() < 20 {
        std::thread::sleep(std::time::Duration::from_millis(5));
        h.step();
    }
    eprintln!("pick answered after {:?}", started.elapsed());
    assert!(
        h.state()
            .view
            .camera
            .rotation
            .angle_between(shapecast::render::camera::ViewPreset::Anterior.rotation())
            < 1e-6,
        "the A button did not set the anterior view"
    );
    let pick = h.state().last_pick.expect("the click picked a point");
    let d = (pick.world_mm - nodule).length();
    eprintln!(
        "pick {:?} ({:?}), {d:.2} mm from the nodule centre",
        pick.world_mm, pick.channel
    );
    assert!(
        d < NODULE_RADIUS_MM,
        "pick {:?} is {d:.2} mm from the nodule",
        pick.world_mm
    );
    assert_eq!(h.state().crosshair, Some(pick.voxel));
    h.run_steps(1);
    let clicked = h.render().expect("render");
    save(&clicked, "mip_view_picked.png");

    // The wheel zooms towards the pointer.
    let zoom = h.state().view.camera.zoom;
    h.hover_at(at);
    h.event(egui::Event::MouseWheel {
        unit: egui::MouseWheelUnit::Point,
        delta: egui::vec2(0.0, 120.0),
        phase: egui::TouchPhase::Move,
        source: egui::MouseWheelSource::Unknown,
        modifiers: egui::Modifiers::NONE,
    });
    h.run_steps(2);
    let zoomed = h.state().view.camera.zoom;
    assert!(zoomed > zoom * 1.1, "zoom {zoom} -> {zoomed}");
    // The nodule stays under the pointer.
    let still = h
        .state()
        .view
        .screen_pos_of(nodule)
        .expect("nodule still in view");
    assert!((still - at).length() < 2.0, "{at:?} -> {still:?}");

    // Shift + drag pans without turning.
    let (rotation, centre_mm) = (
        h.state().view.camera.rotation,
        h.state().view.camera.centre_mm,
    );
    h.event(egui::Event::ModifiersChanged(egui::Modifiers::SHIFT));
    h.drag_at(at);
    h.step();
    h.hover_at(at + egui::vec2(40.0, 0.0));
    h.step();
    h.hover_at(at + egui::vec2(60.0, 0.0));
    h.step();
    h.drop_at(at + egui::vec2(60.0, 0.0));
    h.run_steps(1);
    h.event(egui::Event::ModifiersChanged(egui::Modifiers::NONE));
    let cam = h.state().view.camera;
    assert!(
        cam.rotation.angle_between(rotation) < 1e-6,
        "shift-drag turned the view"
    );
    assert!(
        (cam.centre_mm - centre_mm).length() > 1.0,
        "shift-drag did not pan"
    );
    let moved = h
        .state()
        .view
        .screen_pos_of(nodule)
        .expect("nodule in view");
    assert!(
        moved.x > at.x + 20.0,
        "the content did not follow the pointer: {at:?} -> {moved:?}"
    );

    // Mode switch: intensity only shows no colour; back to the Hessian without recomputing
    // (the host computed its features once, in Host::new).
    h.state_mut().view.mode = None;
    h.run_steps(2);
    let grey = h.render().expect("render");
    let (reds, yellows) = (count(&grey, red), count(&grey, yellow));
    // (The orientation letters are drawn in a yellowish colour: ~60 pixels.)
    assert!(
        reds < 50 && yellows < 150,
        "intensity mode shows colour: {reds} red, {yellows} yellow"
    );
    h.state_mut().view.mode = Some("Hessian".to_owned());
    h.run_steps(2);
    let back = h.render().expect("render");
    assert!(count(&back, yellow) > 500);
}

/// Progressive rendering (issue "full-size scans", deliver 5): with a frame budget far below a
/// full frame's cost, the first frame is a coarse one within the budget, the full frame follows
/// in bands of rows, each band within the budget, and the settled picture is the same as the
/// frame drawn whole.
#[test]
fn a_frame_over_budget_is_drawn_coarse_first_then_in_bands() {
    let Some(mut whole) = harness() else { return };
    let reference = whole.render().expect("render");
    let whole_frames = whole.state().view.frames_rendered();
    drop(whole);

    // 100 k samples per frame: a fiftieth of this viewport's full frame or less.
    let budget_samples = 1.0e5;
    let Some(mut h) = harness_with(FramePacer::fixed(Some(1.0), budget_samples)) else {
        return;
    };
    // harness_with ran 3 frames: the coarse one and two bands.
    eprintln!(
        "after 3 frames: refining {}, preview {}, {} dispatches, last {} samples",
        h.state().view.refining(),
        h.state().view.showing_preview(),
        h.state().view.frames_rendered(),
        h.state().view.last_dispatch_samples()
    );
    assert!(
        h.state().view.refining() && h.state().view.showing_preview(),
        "a frame over budget starts coarse"
    );
    let coarse = h.render().expect("render");
    save(&coarse, "mip_view_coarse.png");
    let mut steps = 0;
    let mut largest: f64 = h.state().view.last_dispatch_samples();
    while h.state().view.refining() && steps < 2000 {
        h.step();
        steps += 1;
        largest = largest.max(h.state().view.last_dispatch_samples());
    }
    let frames = h.state().view.frames_rendered();
    eprintln!(
        "progressive: {frames} dispatches (whole: {whole_frames}), largest {largest:.0} samples"
    );
    assert!(!h.state().view.refining(), "not done after {steps} steps");
    assert!(!h.state().view.showing_preview());
    assert!(frames >= 10, "only {frames} dispatches");
    assert!(
        largest <= budget_samples,
        "a dispatch cost {largest} samples, over the budget of {budget_samples}"
    );
    let settled = h.render().expect("render");
    save(&settled, "mip_view_progressive.png");
    let differing = reference
        .pixels()
        .zip(settled.pixels())
        .filter(|(a, b)| a.0.iter().zip(b.0).any(|(x, y)| x.abs_diff(y) > 1))
        .count();
    assert_eq!(differing, 0, "the banded frame differs from the whole one");
    // Idle again: nothing re-renders.
    h.run_steps(3);
    assert_eq!(h.state().view.frames_rendered(), frames);
}

/// One window/level convention in every pane (issue "reading like a radiologist", deliver 4):
/// a right-drag down over the MIP darkens it (raises the level), right widens it, as over the
/// slice panes (`Window::dragged`).
#[test]
fn right_drag_down_darkens_the_mip_as_in_the_slice_panes() {
    let Some(mut h) = harness() else { return };
    let before = h.state().view.settings.window;
    let centre = h
        .state()
        .view
        .screen_pos_of(h.state().view.camera.centre_mm)
        .expect("centre");
    let press = |pos: egui::Pos2, pressed: bool| egui::Event::PointerButton {
        pos,
        button: egui::PointerButton::Secondary,
        pressed,
        modifiers: egui::Modifiers::NONE,
    };
    h.hover_at(centre);
    h.event(press(centre, true));
    h.step();
    for d in [10.0, 25.0, 40.0] {
        h.hover_at(centre + egui::vec2(0.5 * d, d));
        h.step();
    }
    let end = centre + egui::vec2(20.0, 40.0);
    h.event(press(end, false));
    h.run_steps(2);
    let after = h.state().view.settings.window;
    let level = |w: (f32, f32)| 0.5 * (w.0 + w.1);
    let width = |w: (f32, f32)| w.1 - w.0;
    eprintln!("window {before:?} -> {after:?}");
    assert!(
        level(after) > level(before) + 1.0,
        "down did not darken: {before:?} -> {after:?}"
    );
    assert!(
        width(after) > width(before),
        "right did not widen: {before:?} -> {after:?}"
    );
}
