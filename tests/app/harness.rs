//! The one harness of the app tests: the whole app rendered through wgpu on the test adapter
//! (lavapipe) with egui_kittest, and the person's moves (clicks on published controls, drags,
//! the wheel) and the screenshots the tests share. The io tests include it too (the viewer
//! opening a study from a real archive).
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::Arc;

use egui_kittest::Harness;
use shapecast::app::{AppOptions, DisplayMode, ShapecastApp, StartWith};
use shapecast::status::Phase;

/// The app at 1280 x 800 once it is ready (with its volume, where it was given one) or has
/// failed; `None`, a visible skip, without an adapter (a failure under CI=true).
pub fn harness(options: AppOptions) -> Option<Harness<'static, ShapecastApp>> {
    // The same adapter rule as the GPU tests: skip visibly without one, fail under CI=true.
    shapecast::gpu::context::test_context()?;
    let wants_volume = options.start != StartWith::Nothing;
    let mut setup = egui_kittest::wgpu::default_wgpu_setup();
    if let eframe::egui_wgpu::WgpuSetup::CreateNew(create) = &mut setup {
        create.device_descriptor = Arc::new(shapecast::gpu::context::device_descriptor);
    }
    let mut harness = Harness::builder()
        .with_size(egui::vec2(1280.0, 800.0))
        .wgpu_setup(setup)
        .build_eframe(move |cc| ShapecastApp::with_options(cc, options));
    run_until(&mut harness, "ready", 60, |app| {
        let s = app.status();
        s.phase == Phase::Error
            || (s.phase == Phase::Ready
                && (app.volume().is_some() || !wants_volume || s.error.is_some()))
    });
    harness.run_steps(2);
    Some(harness)
}

/// Steps until `done`, or fails naming `what` after `max` frames and at least 120 s (GPU work
/// runs asynchronously to the frames; lavapipe takes its time).
pub fn run_until(
    harness: &mut Harness<'static, ShapecastApp>,
    what: &str,
    max: usize,
    done: impl Fn(&ShapecastApp) -> bool,
) {
    let started = std::time::Instant::now();
    let mut frames = 0;
    while frames < max || started.elapsed() < std::time::Duration::from_secs(120) {
        harness.step();
        frames += 1;
        if done(harness.state()) {
            return;
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    panic!(
        "not {what} after {max} frames: {:?}",
        harness.state().status()
    );
}

/// Options that open `start` without computing features.
pub fn intensity_only(start: StartWith) -> AppOptions {
    AppOptions {
        start,
        mode: DisplayMode::Intensity,
        compute_on_load: false,
        preset: None,
        ..AppOptions::default()
    }
}

/// Saves a screenshot for a person to look at; its path.
pub fn save(image: &image::RgbaImage, name: &str) -> PathBuf {
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    image.save(&out).expect("save screenshot");
    eprintln!("screenshot: {}", out.display());
    out
}

/// The mouse wheel turned by `lines` with `modifiers`.
pub fn wheel(harness: &mut Harness<'static, ShapecastApp>, lines: f32, modifiers: egui::Modifiers) {
    harness.event(egui::Event::MouseWheel {
        unit: egui::MouseWheelUnit::Line,
        delta: egui::vec2(0.0, lines),
        phase: egui::TouchPhase::Move,
        source: egui::MouseWheelSource::Wheel,
        modifiers,
    });
    harness.run_steps(2);
}

/// A drag with `button` from `a` to `b` in a few moves.
pub fn drag(
    harness: &mut Harness<'static, ShapecastApp>,
    button: egui::PointerButton,
    a: egui::Pos2,
    b: egui::Pos2,
) {
    let press = |pos, pressed| egui::Event::PointerButton {
        pos,
        button,
        pressed,
        modifiers: egui::Modifiers::NONE,
    };
    harness.hover_at(a);
    harness.event(press(a, true));
    harness.run_steps(1);
    for t in 1..=4 {
        harness.hover_at(a + (b - a) * (t as f32 / 4.0));
        harness.run_steps(1);
    }
    harness.event(press(b, false));
    harness.run_steps(2);
}

/// A click on a control the app published (`status().controls`) by name.
pub fn click_control(h: &mut Harness<'static, ShapecastApp>, name: &str) {
    let at = h
        .state()
        .status()
        .controls
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, r)| egui::pos2(r[0] + 0.5 * r[2], r[1] + 0.5 * r[3]))
        .unwrap_or_else(|| panic!("no control {name}: {:?}", h.state().status().controls));
    h.hover_at(at);
    for pressed in [true, false] {
        h.event(egui::Event::PointerButton {
            pos: at,
            button: egui::PointerButton::Primary,
            pressed,
            modifiers: egui::Modifiers::NONE,
        });
    }
    h.run_steps(1);
}

/// Pixels of `image` inside `rect` (a pane) for which `pred` holds.
pub fn pixels_where(
    image: &image::RgbaImage,
    rect: egui::Rect,
    pred: impl Fn(&image::Rgba<u8>) -> bool,
) -> usize {
    let mut n = 0;
    for y in rect.top().ceil() as u32..rect.bottom().floor() as u32 {
        for x in rect.left().ceil() as u32..rect.right().floor() as u32 {
            if x < image.width() && y < image.height() {
                n += usize::from(pred(image.get_pixel(x, y)));
            }
        }
    }
    n
}
