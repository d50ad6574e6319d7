//! Reading as a radiologist does, in the whole app rendered through wgpu on the test adapter
//! (lavapipe) with egui_kittest and driven with the mouse and keys: zooming a slice pane keeps
//! the point under the pointer, pans and fits; the wheel goes superior (anterior, left) in a file
//! stored either way along z; cine plays and stops; a ruler across the phantom sphere reads its
//! diameter; an ellipse's statistics equal a direct computation over the same pixels; the
//! measurements travel in the link; the number keys set the window presets (the MIP's too), 0
//! the default windows, and "?" shows the keys; "Save movie" writes an animated PNG of a full
//! turn of the MIP; with the ruler, a click in the MIP measures in 3D. Screenshots are saved for
//! a person to look at.

use crate::harness::{drag, harness, intensity_only, run_until, save, wheel};

use egui_kittest::Harness;
use egui_kittest::kittest::Queryable as _;
use glam::{DMat3, DVec3};
use shapecast::app::measure::{MeasureKind, Tool};
use shapecast::app::slices::{PaneView, pane_axes};
use shapecast::app::{AppOptions, LoadSource, ShapecastApp, SliceKind, StartWith};
use shapecast::app::{Window, WindowPreset};
use shapecast::volume::Volume;

fn pane(h: &Harness<'static, ShapecastApp>, kind: SliceKind) -> egui::Rect {
    h.state().pane_rect(kind).expect("pane drawn")
}

#[test]
fn slice_zoom_keeps_the_point_under_the_pointer_pans_and_fits() {
    let Some(mut h) = harness(intensity_only(StartWith::DemoCt)) else {
        return;
    };
    let fitted = pane(&h, SliceKind::Axial);
    let slice = h.state().pane_slice(SliceKind::Axial);
    // Ctrl + wheel up at a point off the centre: the voxel under the pointer stays there.
    let at = fitted.center() + egui::vec2(-0.2 * fitted.width(), 0.15 * fitted.height());
    h.hover_at(at);
    h.run_steps(1);
    let before = h
        .state()
        .pane_coord_at(SliceKind::Axial, at)
        .expect("coord");
    wheel(&mut h, 12.0, egui::Modifiers::CTRL);
    let zoomed = pane(&h, SliceKind::Axial);
    let after = h
        .state()
        .pane_coord_at(SliceKind::Axial, at)
        .expect("coord");
    eprintln!(
        "zoom {:?}: {before} -> {after}",
        h.state().pane_view(SliceKind::Axial)
    );
    assert!(
        zoomed.width() > 1.5 * fitted.width(),
        "{zoomed:?} vs {fitted:?}"
    );
    assert!((after - before).length() < 0.02, "{before} -> {after}");
    assert_eq!(
        h.state().pane_slice(SliceKind::Axial),
        slice,
        "ctrl + wheel zooms, it does not change the slice"
    );
    let image = h.render().expect("render");
    save(&image, "reading_axial_zoomed.png");

    // Middle drag and shift + drag pan by the pointer's move.
    let start = fitted.center();
    drag(
        &mut h,
        egui::PointerButton::Middle,
        start,
        start + egui::vec2(40.0, -25.0),
    );
    let panned = pane(&h, SliceKind::Axial);
    assert!(
        (panned.min - zoomed.min - egui::vec2(40.0, -25.0)).length() < 1.0,
        "{zoomed:?} -> {panned:?}"
    );
    let crosshair = h.state().crosshair();
    h.event(egui::Event::ModifiersChanged(egui::Modifiers::SHIFT));
    h.hover_at(start);
    h.drag_at(start);
    h.run_steps(1);
    for t in 1..=4 {
        h.hover_at(start + egui::vec2(-8.0 * t as f32, 0.0));
        h.run_steps(1);
    }
    h.drop_at(start + egui::vec2(-32.0, 0.0));
    h.run_steps(2);
    h.event(egui::Event::ModifiersChanged(egui::Modifiers::NONE));
    let shifted = pane(&h, SliceKind::Axial);
    assert!(
        (shifted.min.x - panned.min.x + 32.0).abs() < 1.0,
        "{panned:?} -> {shifted:?}"
    );
    assert_eq!(h.state().crosshair(), crosshair, "a pan is not a click");

    // "fit" shows the whole slice again; the other panes never moved.
    h.get_all_by_label("fit")
        .next()
        .expect("a fit button")
        .click();
    h.run_steps(2);
    assert_eq!(
        h.state().pane_view(SliceKind::Axial),
        Some(PaneView::default())
    );
    assert_eq!(pane(&h, SliceKind::Axial), fitted);
    // 1:1: one voxel per pixel (the demo's 120 voxels across the axial pane).
    h.get_all_by_label("1:1")
        .next()
        .expect("a 1:1 button")
        .click();
    h.run_steps(2);
    let one = pane(&h, SliceKind::Axial);
    let ppp = h.ctx.pixels_per_point();
    assert!((one.width() * ppp - 120.0).abs() < 0.5, "{one:?}");
}

/// The phantom sphere (1 mm voxels) written as NIfTI in LPS order, or with z stored the other
/// way (k running inferior).
fn nifti_bytes(flip_z: bool) -> Vec<u8> {
    let p = shapecast::phantom::Phantom::by_name("sphere", None).expect("phantom");
    let v = p.render([1.0, 1.0, 1.0]);
    let v = if flip_z { flipped_z(&v) } else { v };
    shapecast::io::nifti::write_volume("sphere.nii", &v).expect("nifti")
}

fn flipped_z(v: &Volume) -> Volume {
    let [nx, ny, nz] = v.dims;
    let mut values = Vec::with_capacity(v.voxel_count());
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                values.push(v.value_at(i, j, nz - 1 - k));
            }
        }
    }
    let mut out = Volume::from_f32(v.dims, v.spacing_mm, values);
    out.direction = DMat3::from_cols(v.direction.col(0), v.direction.col(1), -v.direction.col(2));
    out.origin_mm = v
        .world_from_voxel()
        .transform_point3(DVec3::new(0.0, 0.0, (nz - 1) as f64))
        .to_array();
    out
}

#[test]
fn the_wheel_goes_superior_anterior_left_in_files_stored_both_ways() {
    let Some(mut h) = harness(intensity_only(StartWith::Nothing)) else {
        return;
    };
    for flip in [false, true] {
        let name = if flip {
            "sphere-flipped.nii"
        } else {
            "sphere.nii"
        };
        h.state_mut().open(LoadSource::Files {
            label: name.into(),
            files: vec![shapecast::io::InputFile::new(name, nifti_bytes(flip))],
        });
        run_until(&mut h, "loaded", 40, |app| {
            app.volume().is_some_and(|v| v.source.contains(name))
        });
        h.run_steps(2);
        let k_sign = h.state().volume().expect("volume").direction.col(2).z;
        assert_eq!(k_sign < 0.0, flip, "the file's z order");
        // (pane, the LPS axis, + or - for superior / anterior / left)
        for (kind, axis, sign) in [
            (SliceKind::Axial, 2, 1.0),
            (SliceKind::Coronal, 1, -1.0),
            (SliceKind::Sagittal, 0, 1.0),
        ] {
            let r = pane(&h, kind);
            h.hover_at(r.center());
            h.run_steps(1);
            let before = h.state().crosshair_lps_mm().expect("crosshair");
            wheel(&mut h, 3.0, egui::Modifiers::NONE);
            let after = h.state().crosshair_lps_mm().expect("crosshair");
            let moved = (after - before)[axis] * sign;
            assert!(
                (moved - 3.0).abs() < 1e-9,
                "{name} {kind:?}: wheel-up moved {:?}",
                after - before
            );
            h.key_press(egui::Key::ArrowDown);
            h.run_steps(1);
            let back = h.state().crosshair_lps_mm().expect("crosshair");
            assert!(
                ((back - after)[axis] * sign + 1.0).abs() < 1e-9,
                "{name} {kind:?}: arrow-down moved {:?}",
                back - after
            );
        }
        // The axial header reads the position along superior in mm, the same in both files.
        let z = h.state().crosshair_lps_mm().expect("crosshair").z;
        let text = format!("{} {:.1} mm", if z >= 0.0 { "S" } else { "I" }, z.abs());
        h.get_by_label(&text);
    }
}

#[test]
fn cine_plays_through_the_slices_and_stops() {
    let Some(mut h) = harness(intensity_only(StartWith::Phantom("sphere".into()))) else {
        return;
    };
    let n = h.state().volume().expect("volume").dims[2];
    let first = h.state().pane_slice(SliceKind::Axial).expect("slice");
    // The first "cine" button is the axial pane's; 10 slices/s and 0.25 s per test frame.
    h.get_all_by_label("cine").next().expect("cine").click();
    h.run_steps(1);
    assert!(h.state().pane_playing(SliceKind::Axial));
    let mut seen = vec![first];
    for _ in 0..8 {
        h.step();
        seen.push(h.state().pane_slice(SliceKind::Axial).expect("slice"));
    }
    eprintln!("cine slices: {seen:?}");
    let moved: i64 = seen
        .windows(2)
        .map(|w| (w[1] as i64 - w[0] as i64).rem_euclid(n as i64))
        .sum();
    assert!(moved >= 15, "{seen:?}");
    assert!(seen.windows(2).all(|w| w[0] != w[1]), "{seen:?}");
    h.get_all_by_label("cine").next().expect("cine").click();
    h.run_steps(2);
    assert!(!h.state().pane_playing(SliceKind::Axial));
    let stopped = h.state().pane_slice(SliceKind::Axial);
    h.run_steps(4);
    assert_eq!(h.state().pane_slice(SliceKind::Axial), stopped);
    assert_eq!(
        h.state().pane_slice(SliceKind::Coronal),
        Some(h.state().crosshair()[1])
    );
}

/// Where the profile through `centre` along voxel axis `axis` crosses the level half way
/// between the background and the sphere (continuous voxel index), below and above the centre.
fn half_max_edges(v: &Volume, centre: [usize; 3], axis: usize) -> (f64, f64) {
    let at = |n: usize| {
        let mut p = centre;
        p[axis] = n;
        f64::from(v.value_at(p[0], p[1], p[2]))
    };
    let half = 0.5 * (40.0 + 140.0);
    let c = centre[axis];
    let mut lo = c;
    while lo > 0 && at(lo - 1) >= half {
        lo -= 1;
    }
    let mut hi = c;
    while hi + 1 < v.dims[axis] && at(hi + 1) >= half {
        hi += 1;
    }
    // Linear interpolation between the last voxel above and the first below.
    let edge = |inside: usize, outside: usize| {
        let (a, b) = (at(inside), at(outside));
        inside as f64 + (outside as f64 - inside as f64) * (a - half) / (a - b)
    };
    (edge(lo, lo - 1), edge(hi, hi + 1))
}

#[test]
fn a_ruler_reads_the_sphere_diameter_and_an_ellipse_its_statistics_and_both_go_in_the_link() {
    let Some(mut h) = harness(intensity_only(StartWith::Phantom("fig8-sphere".into()))) else {
        return;
    };
    let v = h.state().volume().expect("volume").clone();
    let centre = v.voxel_from_world().transform_point3(DVec3::ZERO).round();
    let centre = [centre.x as usize, centre.y as usize, centre.z as usize];
    h.state_mut().set_crosshair(centre);
    h.run_steps(2);
    // Zoomed in at the sphere, as a reader would for a 10 mm nodule.
    let axial = pane(&h, SliceKind::Axial);
    let at = h
        .state()
        .pane_screen_of(
            SliceKind::Axial,
            DVec3::new(centre[0] as f64, centre[1] as f64, 0.0),
        )
        .expect("on screen");
    h.hover_at(at);
    wheel(&mut h, 15.0, egui::Modifiers::CTRL);
    assert!(pane(&h, SliceKind::Axial).width() > 2.0 * axial.width());

    // The ruler tool from the side panel, dragged between the sphere's edges along i (the
    // edges where the profile crosses half way between background and sphere: noisy, so the
    // noise-free phantom gives them).
    h.get_by_label("ruler").click();
    h.run_steps(1);
    assert_eq!(h.state().tool(), Tool::Ruler);
    let clean = shapecast::phantom::Phantom::by_name("sphere", None)
        .expect("sphere")
        .render(v.spacing_mm);
    assert_eq!(clean.dims, v.dims);
    let (i0, i1) = half_max_edges(&clean, centre, 0);
    let screen = |h: &Harness<'static, ShapecastApp>, i: f64| {
        h.state()
            .pane_screen_of(SliceKind::Axial, DVec3::new(i, centre[1] as f64, 0.0))
            .expect("on screen")
    };
    let (a, b) = (screen(&h, i0), screen(&h, i1));
    drag(&mut h, egui::PointerButton::Primary, a, b);
    let list = h.state().measurements().to_vec();
    assert_eq!(list.len(), 1, "{list:?}");
    let ruler = list[0].measurement;
    assert_eq!(
        (ruler.kind, ruler.pane),
        (MeasureKind::Ruler, Some(SliceKind::Axial))
    );
    let diameter = 2.0 * 5.0;
    eprintln!(
        "ruler {:.3} mm (edges at i = {i0:.3}, {i1:.3}), sphere diameter {diameter} mm",
        ruler.length_mm()
    );
    assert!(
        (ruler.length_mm() - diameter).abs() <= 0.5 * v.spacing_mm[0],
        "{} mm",
        ruler.length_mm()
    );
    assert_eq!(
        h.state().crosshair(),
        centre,
        "measuring does not move the crosshair"
    );

    // An ellipse over the sphere and its border: the statistics of the pixels whose centres
    // are inside, computed here directly over the whole slice.
    h.get_by_label("ellipse").click();
    h.run_steps(1);
    let (a, b) = (screen(&h, i0 - 3.3), screen(&h, i1 + 1.6));
    let (a, b) = (a - egui::vec2(0.0, 30.0), b + egui::vec2(0.0, 45.0));
    drag(&mut h, egui::PointerButton::Primary, a, b);
    let list = h.state().measurements().to_vec();
    assert_eq!(list.len(), 2);
    let e = &list[1];
    let stats = e.stats.expect("pixels inside");
    let axes = pane_axes(&v, SliceKind::Axial);
    let to_voxel = v.voxel_from_world();
    let (pa, pb) = (
        to_voxel.transform_point3(e.measurement.a_mm),
        to_voxel.transform_point3(e.measurement.b_mm),
    );
    let (cu, cv) = (
        0.5 * (pa[axes.across] + pb[axes.across]),
        0.5 * (pa[axes.vertical] + pb[axes.vertical]),
    );
    let (ru, rv) = (
        0.5 * (pa[axes.across] - pb[axes.across]).abs(),
        0.5 * (pa[axes.vertical] - pb[axes.vertical]).abs(),
    );
    let k = 0.5 * (pa[axes.fixed] + pb[axes.fixed]);
    assert!(
        (k - centre[2] as f64).abs() < 1e-6,
        "drawn on the slice shown"
    );
    let mut inside = Vec::new();
    for j in 0..v.dims[1] {
        for i in 0..v.dims[0] {
            let (du, dv) = ((i as f64 - cu) / ru, (j as f64 - cv) / rv);
            if du * du + dv * dv <= 1.0 {
                inside.push(f64::from(v.value_at(i, j, centre[2])));
            }
        }
    }
    let n = inside.len() as f64;
    let mean = inside.iter().sum::<f64>() / n;
    let sd = (inside.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n).sqrt();
    let min = inside.iter().copied().fold(f64::INFINITY, f64::min);
    let max = inside.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let area = std::f64::consts::PI * ru * rv * v.spacing_mm[0] * v.spacing_mm[1];
    eprintln!(
        "ellipse {}: {stats:?}; direct: n {n} mean {mean} sd {sd}",
        e.reading("HU")
    );
    assert_eq!(stats.pixels, inside.len());
    assert!(
        (stats.mean - mean).abs() < 1e-9 * mean.abs().max(1.0),
        "{} vs {mean}",
        stats.mean
    );
    assert!(
        (stats.sd - sd).abs() < 1e-6 * sd.max(1.0),
        "{} vs {sd}",
        stats.sd
    );
    assert_eq!((f64::from(stats.min), f64::from(stats.max)), (min, max));
    assert!((stats.area_mm2 - area).abs() < 1e-9 * area);
    assert!(
        inside.len() > 100 && sd > 20.0,
        "sphere and background: {n} px, SD {sd}"
    );
    let image = h.render().expect("render");
    save(&image, "reading_measurements.png");

    // The link carries both; opened again (after deleting them) they come back with the same
    // readings.
    let view = h.state().view_state();
    let fragment = view.fragment();
    assert!(
        fragment.contains("&m=ruler,axial,") && fragment.contains("&m=ellipse,axial,"),
        "{fragment}"
    );
    // The list is at the bottom of the side panel: scroll down to it.
    let tools = h.get_by_label("ruler").rect();
    h.hover_at(egui::pos2(tools.center().x, 400.0));
    wheel(&mut h, -30.0, egui::Modifiers::NONE);
    h.get_by_label("delete all").click();
    h.run_steps(1);
    assert!(h.state().measurements().is_empty());
    h.state_mut().open_link(&fragment);
    h.run_steps(2);
    assert_eq!(h.state().measurements(), list.as_slice());
    assert!(h.state().errors().is_empty(), "{:?}", h.state().errors());
}

#[test]
fn number_keys_set_the_window_presets_and_question_mark_shows_the_keys() {
    let Some(mut h) = harness(intensity_only(StartWith::DemoCt)) else {
        return;
    };
    for (key, preset) in [
        (egui::Key::Num1, WindowPreset::Lung),
        (egui::Key::Num4, WindowPreset::Bone),
        (egui::Key::Num5, WindowPreset::Brain),
    ] {
        h.key_press(key);
        h.run_steps(1);
        let w = preset.window();
        assert_eq!(h.state().window(), w, "{key:?}");
        let mip = h.state().view_state().mip_window.expect("mip window");
        assert_eq!(Window::from_bounds(mip), w, "{key:?}: the MIP's window");
    }
    // 0: the volume's default windows, the slices' and the MIP's (a CT's MIP: -100..900 HU).
    let default = shapecast::app::window_level::default_window(h.state().volume().expect("volume"));
    h.key_press(egui::Key::Num0);
    h.run_steps(1);
    assert_eq!(h.state().window(), default);
    assert_eq!(
        h.state().view_state().mip_window,
        Some((-100.0, 900.0)),
        "0 resets the MIP's window too"
    );
    assert!(!h.state().keys_help_shown());
    h.event(egui::Event::Text("?".into()));
    h.run_steps(2);
    assert!(h.state().keys_help_shown());
    h.get_by_label("Keys and mouse");
    h.get_by_label_contains("window presets");
    h.run_steps(3);
    let image = h.render().expect("render");
    save(&image, "reading_keys_help.png");
    h.event(egui::Event::Text("?".into()));
    h.run_steps(2);
    assert!(!h.state().keys_help_shown());
    // Keys for the tools.
    h.key_press(egui::Key::D);
    h.run_steps(1);
    assert_eq!(h.state().tool(), Tool::Ruler);
    h.key_press(egui::Key::Escape);
    h.run_steps(1);
    assert_eq!(h.state().tool(), Tool::Navigate);
}

#[test]
fn the_mip_hover_shows_the_value_under_the_pointer() {
    let Some(mut h) = harness(intensity_only(StartWith::Phantom("sphere".into()))) else {
        return;
    };
    let mip = h
        .state()
        .status()
        .controls
        .iter()
        .find(|(n, _)| n == "pane:mip")
        .map(|(_, r)| egui::Rect::from_min_size(egui::pos2(r[0], r[1]), egui::vec2(r[2], r[3])))
        .expect("the MIP pane");
    // The sphere (140 against 40) sits in the middle of the anterior view.
    let at = mip.center() + egui::vec2(0.0, 30.0);
    h.hover_at(at);
    run_until(&mut h, "a hover value", 40, |app| {
        app.mip_hover_text().is_some()
    });
    let voxel = h.state().hovered_voxel().expect("hovered voxel");
    let v = h.state().volume().expect("volume");
    let value = v.value_at(voxel[0], voxel[1], voxel[2]);
    let text = h.state().mip_hover_text().expect("text").to_owned();
    eprintln!("MIP hover: {text}");
    assert!((value - 140.0).abs() < 1.0, "{value} at {voxel:?}");
    assert!(text.starts_with("140 at voxel ("), "{text}");
    let status = h.state().status().clone();
    assert!(status.error.is_none(), "{status:?}");
    h.run_steps(2);
    let image = h.render().expect("render");
    save(&image, "reading_mip_hover.png");
    // Off the volume (the pane's corner): no value.
    h.hover_at(mip.left_bottom() + egui::vec2(8.0, -8.0));
    run_until(&mut h, "no hover value", 20, |app| {
        app.mip_hover_text().is_none()
    });
}

/// Opened as a user opens it (default options): the Hessian is computed, the RST is not until
/// its button is clicked; while it runs the status says what runs and how long it will take.
#[test]
fn the_hessian_starts_by_default_and_the_rst_when_asked_with_a_time_estimate() {
    let Some(mut h) = harness(AppOptions {
        start: StartWith::Phantom("sphere-cylinder".into()),
        ..AppOptions::default()
    }) else {
        return;
    };
    let f = h.state().status().features.clone().expect("features");
    assert_eq!(
        (f.method.as_str(), f.state.as_str(), f.cached),
        ("hessian", "done", 1),
        "{f:?}"
    );
    h.run_steps(3);
    assert!(!h.state().computing(), "nothing else starts on its own");
    let rst = h
        .state()
        .status()
        .controls
        .iter()
        .find(|(n, _)| n == "mode:rst")
        .map(|(_, r)| egui::pos2(r[0] + 0.5 * r[2], r[1] + 0.5 * r[3]))
        .expect("the RST button");
    h.hover_at(rst);
    h.event(egui::Event::PointerButton {
        pos: rst,
        button: egui::PointerButton::Primary,
        pressed: true,
        modifiers: egui::Modifiers::NONE,
    });
    h.event(egui::Event::PointerButton {
        pos: rst,
        button: egui::PointerButton::Primary,
        pressed: false,
        modifiers: egui::Modifiers::NONE,
    });
    h.run_steps(1);
    assert!(h.state().computing(), "one click starts the RST");
    let mut tasks = Vec::new();
    run_until(&mut h, "an estimate of the time left", 400, |app| {
        app.status()
            .task
            .as_deref()
            .is_some_and(|t| t.contains("s left") || t.contains("min left"))
            || !app.computing()
    });
    tasks.extend(h.state().status().task.clone());
    eprintln!("status while computing: {tasks:?}");
    let task = tasks.first().expect("a task while computing");
    assert!(
        task.starts_with("computing rst features: ") && task.contains(" left"),
        "{task}"
    );
    h.state_mut().cancel_features();
    h.run_steps(1);
    assert!(!h.state().computing());
}

/// "Save picture" of the axial pane: a PNG of the pane as shown, with its orientation letters
/// and scale bar, written to the folder asked for.
#[test]
fn save_picture_writes_the_pane_with_letters_and_a_scale_bar() {
    let Some(mut h) = harness(intensity_only(StartWith::Phantom("sphere".into()))) else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("shapecast-pictures-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    h.state_mut().set_picture_dir(dir.clone());
    h.get_by_label("Save picture").click();
    h.run_steps(2);
    h.get_by_label("Axial pane").click();
    run_until(&mut h, "the picture", 20, |app| {
        app.last_picture().is_some()
    });
    let picture = h.state().last_picture().expect("picture").clone();
    eprintln!("picture {} {:?}", picture.name, picture.size);
    assert_eq!(picture.name, "phantom-sphere-axial.png");
    let file = dir.join(&picture.name);
    let bytes = std::fs::read(&file).expect("the file written");
    assert_eq!(bytes, picture.png);
    let image = image::load_from_memory(&bytes).expect("a PNG").to_rgba8();
    let frame = h
        .state()
        .status()
        .controls
        .iter()
        .find(|(n, _)| n == "pane:axial")
        .map(|(_, r)| egui::vec2(r[2], r[3]))
        .expect("axial pane");
    let ppp = h.ctx.pixels_per_point();
    assert_eq!(picture.size, [image.width(), image.height()]);
    // The image part of the pane: its width, its height less the header.
    let (w, h_) = (image.width() as f32 / ppp, image.height() as f32 / ppp);
    assert!(
        w <= frame.x && w >= frame.x - 10.0 && h_ <= frame.y - 18.0 && h_ >= frame.y - 40.0,
        "{:?} vs the pane's {frame:?}",
        image.dimensions()
    );
    save(&image, "reading_picture_axial.png");
    // The orientation letters (yellow) and the scale bar (light grey in its bottom-right
    // corner) are in the picture.
    let letters = image
        .pixels()
        .filter(|p| p[0] > 200 && p[1] > 160 && p[2] < 120)
        .count();
    let (w, h_) = (image.width(), image.height());
    let bar = (w - 120..w - 5)
        .flat_map(|x| (h_ - 16..h_ - 5).map(move |y| (x, y)))
        .filter(|&(x, y)| image.get_pixel(x, y)[0] > 220 && image.get_pixel(x, y)[2] > 220)
        .count();
    assert!(
        letters > 20 && bar > 20,
        "{letters} letter pixels, {bar} scale bar pixels"
    );
    // P over the coronal pane saves that pane.
    let coronal = pane(&h, SliceKind::Coronal);
    h.hover_at(coronal.center());
    h.key_press(egui::Key::P);
    run_until(&mut h, "the coronal picture", 20, |app| {
        app.last_picture()
            .is_some_and(|p| p.name.ends_with("-coronal.png"))
    });
    assert!(dir.join("phantom-sphere-coronal.png").exists());
    std::fs::remove_dir_all(&dir).ok();
}

/// The frames of an APNG, decoded with `png`: (frames announced, frames as RGBA rows, size).
fn apng_frames(bytes: &[u8]) -> (u32, Vec<Vec<u8>>, [u32; 2]) {
    let mut reader = png::Decoder::new(std::io::Cursor::new(bytes))
        .read_info()
        .expect("a PNG");
    let announced = reader
        .info()
        .animation_control()
        .expect("an animated PNG (acTL)")
        .num_frames;
    let size = [reader.info().width, reader.info().height];
    let mut frames = Vec::new();
    let mut buf = vec![0; reader.output_buffer_size().expect("size")];
    while let Ok(out) = reader.next_frame(&mut buf) {
        assert_eq!(
            [out.width, out.height],
            size,
            "every frame is the whole image"
        );
        frames.push(buf[..out.buffer_size()].to_vec());
    }
    (announced, frames, size)
}

/// Mean absolute difference of the red channel of two RGBA images of `width` pixels per row;
/// `mirror` compares `b` flipped left to right.
fn mean_red_diff(a: &[u8], b: &[u8], width: usize, mirror: bool) -> f64 {
    let rows = a.len() / (4 * width);
    let mut sum = 0u64;
    for y in 0..rows {
        for x in 0..width {
            let xb = if mirror { width - 1 - x } else { x };
            let (p, q) = (a[(y * width + x) * 4], b[(y * width + xb) * 4]);
            sum += u64::from(p.abs_diff(q));
        }
    }
    sum as f64 / (rows * width) as f64
}

/// "Save movie": N frames of a full turn of the MIP as an APNG written to the pictures' folder,
/// at the pane's size; the picture turns (a quarter turn changes it), half a turn is the first
/// frame mirrored (a maximum does not depend on the ray's direction). The key M starts the
/// menu's 36-frame movie, with its progress in the status, and Cancel stops it.
#[test]
fn save_movie_writes_an_animated_png_of_a_full_turn() {
    let Some(mut h) = harness(intensity_only(StartWith::Phantom(
        "bifurcation-nodules-far".into(),
    ))) else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("shapecast-movie-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    h.state_mut().set_picture_dir(dir.clone());
    let ctx = h.ctx.clone();
    let frames_before = h.state().status().frames;
    h.state_mut().save_movie(&ctx, 8);
    let started = std::time::Instant::now();
    run_until(&mut h, "the movie", 400, |app| app.last_movie().is_some());
    let app_frames = h.state().status().frames - frames_before;
    let movie = h.state().last_movie().expect("movie").clone();
    eprintln!(
        "movie {} {:?}: {} bytes, {app_frames} app frames, {:.1} s",
        movie.name,
        movie.size,
        movie.png.len(),
        started.elapsed().as_secs_f64()
    );
    assert_eq!(movie.name, "shapecast-rotation.png");
    assert!(app_frames > 8, "made over several frames: {app_frames}");
    let bytes = std::fs::read(dir.join(&movie.name)).expect("the file written");
    assert_eq!(bytes, movie.png);
    let (announced, frames, size) = apng_frames(&bytes);
    assert_eq!((announced, frames.len()), (8, 8));
    assert_eq!(size, movie.size);
    assert_eq!(Some(size), h.state().mip_frame_size(), "the pane's size");
    let w = size[0] as usize;
    let frame0 = image::RgbaImage::from_raw(size[0], size[1], frames[0].clone()).expect("rgba");
    save(&frame0, "reading_movie_frame0.png");
    let frame2 = image::RgbaImage::from_raw(size[0], size[1], frames[2].clone()).expect("rgba");
    save(&frame2, "reading_movie_frame2.png");
    let (half, quarter) = (
        mean_red_diff(&frames[4], &frames[0], w, true),
        mean_red_diff(&frames[2], &frames[0], w, false),
    );
    eprintln!("mean |frame 4 - mirrored frame 0| = {half:.2}, |frame 2 - frame 0| = {quarter:.2}");
    assert!(half < 3.0, "{half}");
    assert!(
        quarter > 4.0 * half.max(0.5),
        "a quarter turn changes the picture: {quarter}"
    );
    assert!(
        frames[0].chunks_exact(4).any(|p| p[0] > 100),
        "frame 0 shows the phantom"
    );

    // M: the menu's movie, 36 frames; its progress is in the status; Cancel stops it.
    std::fs::remove_file(dir.join(&movie.name)).expect("remove");
    h.key_press(egui::Key::M);
    h.run_steps(3);
    assert_eq!(h.state().movie_progress().map(|p| p.1), Some(36));
    let task = h.state().status().task.clone().unwrap_or_default();
    assert!(task.starts_with("saving the movie: frame "), "{task}");
    h.get_by_label("Cancel").click();
    h.run_steps(2);
    assert_eq!(h.state().movie_progress(), None);
    h.run_steps(5);
    assert!(
        !dir.join(&movie.name).exists(),
        "a cancelled movie is not saved"
    );
    assert!(h.state().errors().is_empty(), "{:?}", h.state().errors());
    std::fs::remove_dir_all(&dir).ok();
}

/// Two bright blobs (Gaussian, 1 mm voxels) in an empty volume, as NIfTI.
fn two_blobs(centres: [[f64; 3]; 2]) -> Vec<u8> {
    let dims = [48, 48, 48];
    let mut values = Vec::with_capacity(48 * 48 * 48);
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let p = DVec3::new(i as f64, j as f64, k as f64);
                let v: f64 = centres
                    .iter()
                    .map(|c| 1000.0 * (-(p - DVec3::from(*c)).length_squared() / 4.5).exp())
                    .sum();
                values.push(v as f32);
            }
        }
    }
    let v = Volume::from_f32(dims, [1.0, 1.0, 1.0], values);
    shapecast::io::nifti::write_volume("blobs.nii", &v).expect("nifti")
}

/// With the ruler, a click in the MIP measures in 3D from the crosshair to the point the pixel's
/// maximum came from: between the centres of two blobs at different depths, the ruler reads
/// their distance; it is in the list, in the link as a `3d` ruler, and comes back from it.
#[test]
fn a_click_in_the_mip_with_the_ruler_measures_in_3d() {
    let Some(mut h) = harness(intensity_only(StartWith::Nothing)) else {
        return;
    };
    let (a, b) = ([14.0, 12.0, 16.0], [33.0, 36.0, 30.0]);
    h.state_mut().open(LoadSource::Files {
        label: "blobs.nii".into(),
        files: vec![shapecast::io::InputFile::new(
            "blobs.nii",
            two_blobs([a, b]),
        )],
    });
    run_until(&mut h, "loaded", 40, |app| app.volume().is_some());
    h.run_steps(3);
    let v = h.state().volume().expect("volume").clone();
    let world = v.world_from_voxel();
    let (a_mm, b_mm) = (
        world.transform_point3(DVec3::from(a)),
        world.transform_point3(DVec3::from(b)),
    );
    h.state_mut().set_crosshair(a.map(|x| x as usize));
    h.state_mut().set_tool(Tool::Ruler);
    h.run_steps(3);
    let at = h
        .state()
        .mip_screen_pos_of(b_mm)
        .expect("blob b in the MIP");
    h.hover_at(at);
    h.run_steps(1);
    h.event(egui::Event::PointerButton {
        pos: at,
        button: egui::PointerButton::Primary,
        pressed: true,
        modifiers: egui::Modifiers::NONE,
    });
    h.event(egui::Event::PointerButton {
        pos: at,
        button: egui::PointerButton::Primary,
        pressed: false,
        modifiers: egui::Modifiers::NONE,
    });
    run_until(&mut h, "a ruler in 3D", 40, |app| {
        !app.measurements().is_empty()
    });
    let list = h.state().measurements().to_vec();
    assert_eq!(list.len(), 1, "{list:?}");
    let m = list[0].measurement;
    assert_eq!((m.kind, m.pane), (MeasureKind::Ruler, None));
    let want = (b_mm - a_mm).length();
    eprintln!(
        "3D ruler {:.3} mm from {:?} to {:?}; the blobs are {want:.3} mm apart",
        m.length_mm(),
        m.a_mm,
        m.b_mm
    );
    assert!((m.a_mm - a_mm).length() < 1e-9, "from the crosshair");
    // The click's pixel is within half a pixel of the blob's centre, the depth within a sample.
    assert!((m.b_mm - b_mm).length() < 1.0, "{:?} vs {b_mm:?}", m.b_mm);
    assert!((m.length_mm() - want).abs() < 1.0, "{} mm", m.length_mm());
    assert_eq!(
        h.state().crosshair(),
        b.map(|x| x as usize),
        "the crosshair moved to the picked point"
    );
    h.run_steps(3);
    let image = h.render().expect("render");
    save(&image, "reading_ruler_3d.png");

    let fragment = h.state().view_state().fragment();
    assert!(fragment.contains("&m=ruler,3d,"), "{fragment}");
    let (back, problems) = shapecast::app::view_link::ViewState::from_fragment(&fragment);
    assert!(problems.is_empty(), "{problems:?}");
    assert_eq!(back.measurements, Some(vec![m]));
    assert!(h.state().errors().is_empty(), "{:?}", h.state().errors());
}
