//! The whole app rendered through wgpu on the test adapter (lavapipe) with egui_kittest, driven
//! as a person would: it opens on the demo CT and on a phantom and draws the slice panes
//! (screenshots saved for a person to look at), the wheel moves through slices, a click in one
//! pane moves the others, a right-button or ctrl drag changes the window, features are computed
//! once and reused when switching modes, a corrupt file shows an error and keeps the volume, and
//! a dropped folder (a DICOM series) loads, and a folder of several series lists them and
//! loads the one clicked.

use crate::common;
use crate::counting;
use crate::harness::{click_control, drag, harness, intensity_only, pixels_where, run_until, save};

use std::path::{Path, PathBuf};
use std::sync::Arc;

use egui_kittest::Harness;
use shapecast::app::{
    AppOptions, DisplayMode, Layout, LoadSource, PaneId, ShapecastApp, SliceKind, StartWith,
};
use shapecast::cpu::pipeline::Method;
use shapecast::status::Phase;

/// Distinct grey levels and coloured pixels of the image inside `rect` (points = pixels here).
fn region_stats(image: &image::RgbaImage, rect: egui::Rect) -> (usize, usize) {
    let mut greys = std::collections::HashSet::new();
    let mut coloured = 0;
    for y in rect.top().ceil() as u32..rect.bottom().floor() as u32 {
        for x in rect.left().ceil() as u32..rect.right().floor() as u32 {
            if x >= image.width() || y >= image.height() {
                continue;
            }
            let p = image.get_pixel(x, y);
            greys.insert(p[0] / 2);
            let (mx, mn) = (p[0].max(p[1]).max(p[2]), p[0].min(p[1]).min(p[2]));
            if mx - mn > 40 {
                coloured += 1;
            }
        }
    }
    (greys.len(), coloured)
}

#[test]
fn demo_ct_opens_and_draws_the_slice_panes() {
    let Some(mut harness) = harness(intensity_only(StartWith::DemoCt)) else {
        return;
    };
    let status = harness.state().status().clone();
    let volume = status.volume.as_ref().expect("a volume");
    assert_eq!(volume.dims, shapecast::app::demo::DEMO_DIMS);
    assert_eq!(volume.source, shapecast::app::demo::DEMO_FILE);
    assert_eq!(status.error, None);
    assert_eq!(status.layout, "mip+slices");
    let crosshair = status.crosshair.expect("crosshair");
    assert_eq!(crosshair.voxel, [60, 63, 82]);
    let image = harness.render().expect("render");
    save(&image, "app_demo_ct.png");
    let app = harness.state();
    for kind in SliceKind::ALL {
        let rect = app.pane_rect(kind).expect("pane drawn");
        // True aspect in mm: the demo is isotropic 1.5 mm, so voxel counts set the shape.
        let (w, h) = match kind {
            SliceKind::Axial => (120.0, 126.0),
            SliceKind::Coronal => (120.0, 164.0),
            SliceKind::Sagittal => (126.0, 164.0),
        };
        let ratio = rect.width() / rect.height();
        assert!(
            (ratio - w / h).abs() < 0.02,
            "{kind:?}: aspect {ratio} vs {}",
            w / h
        );
        // A CT slice in a soft-tissue window has many grey levels (a blank or flat pane has one).
        let (greys, _) = region_stats(&image, rect.shrink(3.0));
        assert!(greys > 40, "{kind:?}: only {greys} grey levels in {rect:?}");
    }
    // The demo's licence and attribution are in the About window.
    use egui_kittest::kittest::Queryable as _;
    harness.get_by_label("About & data").click();
    harness.run_steps(2);
    harness.get_by_label_contains("Wasserthal");
    harness.get_by_label("Apache License 2.0");
    harness
        .get_by_role_and_label(egui::accesskit::Role::Button, "About & data")
        .click();
    harness.run_steps(2);
    let app = harness.state();

    // Maximising a pane gives it the whole area.
    let small = app.pane_rect(SliceKind::Coronal).expect("coronal");
    harness
        .state_mut()
        .set_layout(Layout::Single(PaneId::Slice(SliceKind::Coronal)));
    harness.run_steps(2);
    let big = harness
        .state()
        .pane_rect(SliceKind::Coronal)
        .expect("coronal");
    assert!(big.area() > 3.0 * small.area(), "{big:?} vs {small:?}");
    assert_eq!(harness.state().pane_rect(SliceKind::Axial), None);
    assert_eq!(harness.state().status().layout, "coronal");
    let image = harness.render().expect("render");
    save(&image, "app_demo_ct_coronal.png");
}

#[test]
fn slice_panes_scroll_link_and_window() {
    let Some(mut harness) = harness(intensity_only(StartWith::DemoCt)) else {
        return;
    };
    let app = harness.state();
    let axial = app.pane_rect(SliceKind::Axial).expect("axial");
    let before = app.crosshair();
    let axial_slice = app.pane_slice(SliceKind::Axial).expect("slice");

    // Wheel over the axial pane: three lines up, three slices on; 100 points (a browser's
    // notch) two more.
    harness.hover_at(axial.center());
    harness.event(egui::Event::MouseWheel {
        unit: egui::MouseWheelUnit::Line,
        delta: egui::vec2(0.0, 3.0),
        phase: egui::TouchPhase::Move,
        source: egui::MouseWheelSource::Wheel,
        modifiers: egui::Modifiers::NONE,
    });
    harness.run_steps(2);
    assert_eq!(
        harness.state().pane_slice(SliceKind::Axial),
        Some(axial_slice + 3),
        "the wheel did not move the axial slice"
    );
    harness.event(egui::Event::MouseWheel {
        unit: egui::MouseWheelUnit::Point,
        delta: egui::vec2(0.0, -100.0),
        phase: egui::TouchPhase::Move,
        source: egui::MouseWheelSource::Wheel,
        modifiers: egui::Modifiers::NONE,
    });
    harness.run_steps(2);
    assert_eq!(
        harness.state().pane_slice(SliceKind::Axial),
        Some(axial_slice + 1)
    );
    // The other panes keep their slices.
    let after_wheel = harness.state().crosshair();
    assert_eq!((after_wheel[0], after_wheel[1]), (before[0], before[1]));

    // A click in the axial pane, up and to the left of the centre, moves the coronal and
    // sagittal slices (j and i) to the voxel clicked, and not the axial one.
    let target = axial.center() + egui::vec2(-0.25 * axial.width(), -0.2 * axial.height());
    let expected = harness
        .state()
        .pane_voxel_at(SliceKind::Axial, target)
        .expect("inside the axial image");
    harness.hover_at(target);
    harness.drag_at(target);
    harness.run_steps(1);
    harness.drop_at(target);
    harness.run_steps(2);
    let clicked = harness.state().crosshair();
    assert_eq!(clicked, expected);
    assert_eq!(clicked[2], after_wheel[2], "the axial slice itself stays");
    // Patient left is on the right of the axial pane and anterior up: the click went to the
    // patient's right (smaller i) and anterior (smaller j).
    assert!(
        clicked[0] < before[0] && clicked[1] < before[1],
        "{clicked:?} vs {before:?}"
    );
    assert_eq!(
        harness.state().pane_slice(SliceKind::Coronal),
        Some(clicked[1])
    );
    assert_eq!(
        harness.state().pane_slice(SliceKind::Sagittal),
        Some(clicked[0])
    );
    let status = harness.state().status().clone();
    assert_eq!(status.crosshair.expect("crosshair").voxel, clicked);

    // Right-button drag on the coronal pane: right widens, down raises the level.
    let coronal = harness
        .state()
        .pane_rect(SliceKind::Coronal)
        .expect("coronal");
    let w0 = harness.state().window();
    let start = coronal.center();
    let end = start + egui::vec2(80.0, 30.0);
    drag(&mut harness, egui::PointerButton::Secondary, start, end);
    let w1 = harness.state().window();
    assert!(
        w1.width > w0.width * 1.2,
        "width {} -> {}",
        w0.width,
        w1.width
    );
    assert!(w1.level > w0.level, "level {} -> {}", w0.level, w1.level);
    assert_eq!(
        harness.state().crosshair(),
        clicked,
        "a window drag is not a click"
    );

    // Ctrl + left drag to the left narrows it again.
    harness.event(egui::Event::ModifiersChanged(egui::Modifiers::CTRL));
    harness.hover_at(start);
    harness.drag_at(start);
    harness.run_steps(1);
    for t in 1..=4 {
        harness.hover_at(start - egui::vec2(25.0 * t as f32, 0.0));
        harness.run_steps(1);
    }
    harness.drop_at(start - egui::vec2(100.0, 0.0));
    harness.run_steps(2);
    harness.event(egui::Event::ModifiersChanged(egui::Modifiers::NONE));
    let w2 = harness.state().window();
    assert!(
        w2.width < w1.width * 0.8,
        "width {} -> {}",
        w1.width,
        w2.width
    );
    assert_eq!(
        harness.state().crosshair(),
        clicked,
        "a ctrl drag is not a click"
    );
}

#[test]
fn phantom_features_overlay_and_mode_switch_reuse() {
    let Some(mut harness) = harness(AppOptions {
        start: StartWith::Phantom("sphere-cylinder".into()),
        mode: DisplayMode::Features(Method::Li),
        compute_on_load: true,
        preset: None,
        ..AppOptions::default()
    }) else {
        return;
    };
    run_until(&mut harness, "features done", 200, |app| {
        app.status()
            .features
            .as_ref()
            .is_some_and(|f| f.state == "done")
    });
    // The crosshair on the sphere's centre (the phantom frame's origin, 0.5 mm voxels).
    let v = harness.state().volume().expect("volume").clone();
    let centre = v
        .voxel_from_world()
        .transform_point3(glam::DVec3::ZERO)
        .round();
    let centre = [centre.x as usize, centre.y as usize, centre.z as usize];
    harness.state_mut().set_crosshair(centre);
    run_until(&mut harness, "feature values read back", 50, |app| {
        app.features_at_crosshair().is_some()
    });
    let [vessel, airway, blob] = harness.state().features_at_crosshair().expect("values");
    eprintln!("Li at the sphere centre: V {vessel} A {airway} B {blob}");
    assert!(
        blob > 1.0 && blob > vessel && airway < 0.1 * blob,
        "V {vessel} A {airway} B {blob}"
    );
    harness.run_steps(2);
    let image = harness.render().expect("render");
    save(&image, "app_phantom_li.png");
    // The overlay colours the sphere and the vessel in every slice pane through them.
    for kind in SliceKind::ALL {
        let rect = harness.state().pane_rect(kind).expect("pane");
        let (_, coloured) = region_stats(&image, rect);
        assert!(coloured > 50, "{kind:?}: {coloured} coloured pixels");
    }

    // Another mode computes once; switching back to Li is instant (no job, still one entry
    // each).
    harness
        .state_mut()
        .set_mode(DisplayMode::Features(Method::Hessian));
    run_until(&mut harness, "Hessian done", 200, |app| {
        app.status()
            .features
            .as_ref()
            .is_some_and(|f| f.state == "done" && f.method == "hessian")
    });
    assert_eq!(
        harness.state().status().features.as_ref().map(|f| f.cached),
        Some(2)
    );
    harness
        .state_mut()
        .set_mode(DisplayMode::Features(Method::Li));
    assert!(!harness.state().computing(), "switching back recomputed");
    harness.step();
    let f = harness.state().status().features.clone().expect("features");
    assert_eq!(
        (f.method.as_str(), f.state.as_str(), f.cached),
        ("li", "done", 2)
    );
    assert_eq!(
        harness.state().status().phase,
        Phase::Ready,
        "nothing recomputed"
    );

    // Changing a parameter and recomputing computes a third entry; cancelling a job keeps
    // the app ready with the old ones.
    harness.state_mut().params_mut().sigma_count = 2;
    harness.state_mut().recompute();
    assert!(harness.state().computing());
    harness.state_mut().cancel_features();
    harness.step();
    let f = harness.state().status().features.clone().expect("features");
    assert_eq!(f.state, "cancelled", "{f:?}");
    assert_eq!(f.cached, 2);
}

#[derive(Debug)]
struct DroppedPath(PathBuf);

impl egui::DroppedFile for DroppedPath {
    fn path(&self) -> &Path {
        &self.0
    }
    fn bytes(&self) -> Result<Vec<u8>, String> {
        std::fs::read(&self.0).map_err(|e| e.to_string())
    }
}

#[test]
fn corrupt_file_shows_an_error_and_keeps_the_volume_then_a_folder_drop_loads() {
    let Some(mut harness) = harness(intensity_only(StartWith::Phantom("sphere".into()))) else {
        return;
    };
    let dims = harness.state().volume().expect("phantom").dims;
    let crosshair = harness.state().crosshair();
    // A NIfTI header with garbage after it.
    let mut bytes = vec![0u8; 352];
    bytes[0..4].copy_from_slice(&348i32.to_le_bytes());
    bytes[344..348].copy_from_slice(b"n+1\0");
    bytes.extend_from_slice(&[0xAB; 100]);
    harness.state_mut().open(LoadSource::Files {
        label: "broken.nii".into(),
        files: vec![shapecast::io::InputFile::new("broken.nii", bytes)],
    });
    run_until(&mut harness, "done loading", 20, |app| {
        app.status().phase != Phase::Loading
    });
    harness.run_steps(2);
    let status = harness.state().status().clone();
    assert_eq!(status.phase, Phase::Ready, "{status:?}");
    let error = status.error.clone().expect("an error");
    assert!(error.contains("broken.nii"), "{error}");
    assert_eq!(
        harness.state().volume().map(|v| v.dims),
        Some(dims),
        "volume kept"
    );
    assert_eq!(harness.state().crosshair(), crosshair);
    let image = harness.render().expect("render");
    save(&image, "app_error.png");
    // The message is on screen, with a Dismiss button that removes it.
    use egui_kittest::kittest::Queryable as _;
    harness.get_by_label_contains("broken.nii");
    harness.get_by_label("Dismiss").click();
    harness.run_steps(2);
    assert!(harness.state().errors().is_empty());
    assert_eq!(harness.state().status().error, None);
    // The volume still works: scrolling still moves the slice.
    let axial = harness.state().pane_rect(SliceKind::Axial).expect("axial");
    let slice = harness.state().pane_slice(SliceKind::Axial).expect("slice");
    harness.hover_at(axial.center());
    harness.event(egui::Event::MouseWheel {
        unit: egui::MouseWheelUnit::Line,
        delta: egui::vec2(0.0, -2.0),
        phase: egui::TouchPhase::Move,
        source: egui::MouseWheelSource::Wheel,
        modifiers: egui::Modifiers::NONE,
    });
    harness.run_steps(2);
    assert_eq!(
        harness.state().pane_slice(SliceKind::Axial),
        Some(slice - 2)
    );

    // Dropping a folder (six slices of a DICOM series) loads it.
    let folder = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/dicom/ct-head-64px");
    harness
        .input_mut()
        .dropped_files
        .push(Arc::new(DroppedPath(folder)));
    run_until(&mut harness, "the series loaded", 40, |app| {
        app.volume().is_some_and(|v| v.dims != dims)
    });
    harness.run_steps(2);
    let v = harness.state().volume().expect("series");
    assert_eq!(v.dims, [64, 64, 6]);
    assert_eq!(harness.state().status().error, None);
    assert_eq!(harness.state().crosshair(), [32, 32, 3]);
}

/// Clicks the control `name` of the published status (as the browser test does).
/// Scrolls the side panel to its end, where the findings are.
fn scroll_side_panel_down(h: &mut Harness<'static, ShapecastApp>) {
    h.hover_at(egui::pos2(150.0, 400.0));
    for _ in 0..10 {
        h.event(egui::Event::MouseWheel {
            unit: egui::MouseWheelUnit::Point,
            delta: egui::vec2(0.0, -400.0),
            phase: egui::TouchPhase::Move,
            source: egui::MouseWheelSource::Unknown,
            modifiers: egui::Modifiers::NONE,
        });
        h.run_steps(1);
    }
    h.run_steps(10);
}

/// A folder holding three of ../shared/data's series (linked, in sub-folders) opens on the CT
/// with the most images and lists all three with their counts; clicking another loads it with
/// the geometry it has alone, and the list stays.
#[test]
fn a_folder_of_several_series_lists_them_and_loads_the_one_clicked() {
    let dirs = [
        "series/ct-3slice-liver",
        "series/ct-head-64px",
        "series/mr-prostate-adc-oblique",
    ];
    let Some(sources) = dirs
        .iter()
        .map(|d| common::shared_data(d))
        .collect::<Option<Vec<PathBuf>>>()
    else {
        return;
    };
    let folder = Path::new(env!("CARGO_TARGET_TMPDIR")).join("several-series");
    let _ = std::fs::remove_dir_all(&folder);
    for src in &sources {
        let sub = folder.join(src.file_name().expect("a folder name"));
        std::fs::create_dir_all(&sub).expect("temp folder");
        for entry in std::fs::read_dir(src).expect("series folder") {
            let path = entry.expect("entry").path();
            let link = sub.join(path.file_name().expect("a file name"));
            #[cfg(unix)]
            std::os::unix::fs::symlink(&path, &link).expect("link");
            #[cfg(not(unix))]
            std::fs::copy(&path, &link).expect("copy");
        }
    }
    let Some(mut harness) = harness(intensity_only(StartWith::Paths(vec![folder.clone()]))) else {
        return;
    };
    let status = harness.state().status().clone();
    assert_eq!(status.error, None);
    let rows = &status.series;
    let mut listed: Vec<(String, usize, String)> = rows
        .iter()
        .map(|r| (r.modality.clone(), r.images, r.orientation.clone()))
        .collect();
    listed.sort();
    assert_eq!(
        listed,
        [
            ("CT".to_owned(), 3, "axial".to_owned()),
            ("CT".to_owned(), 93, "axial".to_owned()),
            ("MR".to_owned(), 20, "oblique".to_owned()),
        ]
    );
    let chosen: Vec<usize> = rows.iter().filter(|r| r.chosen).map(|r| r.images).collect();
    assert_eq!(chosen, [93], "{rows:?}");
    assert_eq!(status.volume.as_ref().expect("a volume").dims, [64, 64, 93]);
    let head_line = harness.state().patient_line().unwrap_or_default();
    assert!(!head_line.contains("1971"), "{head_line}");
    let image = harness.render().expect("render");
    save(&image, "app_series_list.png");
    let liver = rows.iter().position(|r| r.images == 3).expect("liver row");
    assert_eq!(rows[liver].thickness_mm, Some(1.25));
    assert_eq!((rows[liver].cols, rows[liver].rows), (512, 512));

    // One click on the MR row loads the MR, as its folder alone does.
    let mr = rows
        .iter()
        .position(|r| r.modality == "MR")
        .expect("MR row");
    let alone = shapecast::io::load(&common::inputs_in(&sources[2])).expect("MR alone");
    click_control(&mut harness, &format!("series:{mr}"));
    run_until(&mut harness, "the MR loaded", 40, |app| {
        app.volume().is_some_and(|v| v.dims == alone.volume.dims)
    });
    harness.run_steps(2);
    let app = harness.state();
    let v = app.volume().expect("MR");
    assert_eq!(v.spacing_mm, alone.volume.spacing_mm);
    assert_eq!(v.origin_mm, alone.volume.origin_mm);
    assert!(
        *v == alone.volume,
        "the MR differs from its folder loaded alone"
    );
    let status = app.status();
    assert_eq!(status.error, None);
    assert_eq!(status.series.len(), 3, "the list stays");
    assert!(status.series[mr].chosen && !status.series[mr].loading);
    assert_eq!(status.series.iter().filter(|r| r.chosen).count(), 1);
    // The patient line follows the series shown: the MR's study date (1971), not the head's.
    let line = app.patient_line().unwrap_or_default();
    assert!(line.contains("study 1971-07-14"), "{line}");

    // A link to this view names the MR: opened on the same folder, the MR is loaded (not the
    // default head CT) and the link's view applied to it.
    let view = app.view_state();
    let key = view
        .choice
        .clone()
        .expect("the link names the series shown");
    assert!(
        view.fragment().contains(&format!("choice={key}")),
        "{}",
        view.fragment()
    );
    let (read, problems) = shapecast::app::ViewState::from_fragment(&view.fragment());
    assert!(problems.is_empty(), "{problems:?}");
    assert_eq!(read.choice.as_deref(), Some(key.as_str()));
    let mut options = intensity_only(StartWith::Paths(vec![folder.clone()]));
    options.apply_link(read);
    let Some(mut opened) = self::harness(options) else {
        return;
    };
    run_until(&mut opened, "the link's series loaded", 60, |app| {
        app.volume().is_some_and(|v| v.dims == alone.volume.dims)
            && app
                .status()
                .series
                .iter()
                .any(|r| r.chosen && r.modality == "MR")
    });
    opened.run_steps(2);
    assert_eq!(
        opened.state().view_state().choice.as_deref(),
        Some(key.as_str())
    );
    assert_eq!(opened.state().crosshair_lps_mm(), app.crosshair_lps_mm());
    drop(opened);

    // A file of another format has no list.
    harness
        .state_mut()
        .open(LoadSource::Phantom("sphere".into()));
    run_until(&mut harness, "the phantom loaded", 40, |app| {
        app.volume()
            .is_some_and(|v| v.modality == shapecast::Modality::Phantom)
    });
    harness.run_steps(1);
    assert!(harness.state().status().series.is_empty());
    let _ = std::fs::remove_dir_all(&folder);
}

/// A loaded volume opens on the preset that fits it, and the note says which and why.
#[test]
fn the_preset_fits_what_was_loaded() {
    use shapecast::app::preset_for;
    use shapecast::cpu::Preset;
    use shapecast::volume::{Modality, Volume};
    let ct = |lung_fraction: f64| {
        let n = 40 * 40 * 10;
        let values = (0..n)
            .map(|i| {
                if (i as f64) < lung_fraction * n as f64 {
                    -820.0
                } else {
                    40.0
                }
            })
            .collect();
        let mut v = Volume::from_f32([40, 40, 10], [0.7, 0.7, 2.0], values);
        v.modality = Modality::Ct;
        v
    };
    let (p, why) = preset_for(&ct(0.4), true);
    assert_eq!(p, Preset::LungNodules, "{why}");
    assert!(why.contains("40% of the voxels are lung"), "{why}");
    let (p, why) = preset_for(&ct(0.0), true);
    assert_eq!(p, Preset::LymphNodes, "{why}");
    let mut mr = ct(0.0);
    mr.modality = Modality::Mr;
    let (_, why) = preset_for(&mr, false);
    assert!(why.contains("Hounsfield"), "{why}");
}

/// A link restores the view: the MIP turned by a left drag, the slice window right-dragged and
/// the layout changed in one app; its link's fragment read back (with an unknown field, ignored,
/// and a bad one, named in an error) opens a second app on the same view, camera included (set
/// once the MIP has framed the new volume).
#[test]
fn a_link_restores_the_view() {
    use shapecast::app::ViewState;
    let start = || intensity_only(StartWith::Phantom("sphere".into()));
    let Some(mut harness) = harness(start()) else {
        return;
    };
    let control = |h: &Harness<'static, ShapecastApp>, name: &str| {
        let r = h
            .state()
            .status()
            .controls
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, r)| *r)
            .unwrap_or_else(|| panic!("no control {name}"));
        egui::Rect::from_min_size(egui::pos2(r[0], r[1]), egui::vec2(r[2], r[3]))
    };
    let before = harness.state().view_state();
    let mip = control(&harness, "pane:mip").center() + egui::vec2(0.0, 60.0);
    harness.hover_at(mip);
    harness.drag_at(mip);
    harness.run_steps(1);
    for t in 1..=5 {
        harness.hover_at(mip + egui::vec2(15.0 * t as f32, -6.0 * t as f32));
        harness.run_steps(1);
    }
    harness.drop_at(mip + egui::vec2(75.0, -30.0));
    harness.run_steps(2);
    let axial = control(&harness, "pane:axial").center();
    drag(
        &mut harness,
        egui::PointerButton::Secondary,
        axial,
        axial + egui::vec2(40.0, 20.0),
    );
    harness.state_mut().set_layout(Layout::Grid);
    harness.run_steps(2);
    let view = harness.state().view_state();
    assert_ne!(view.camera, before.camera, "the drag turned the MIP");
    assert_ne!(
        view.window, before.window,
        "the right-drag changed the window"
    );
    let fragment = view.fragment();
    assert!(
        fragment.starts_with("v=1&phantom=sphere&mode=intensity"),
        "{fragment}"
    );
    drop(harness);

    let (read, problems) = ViewState::from_fragment(&format!("#{fragment}&future=1&opacity=7"));
    let mut options = start();
    options.link_problems = problems;
    options.apply_link(read);
    let Some(mut opened) = self::harness(options) else {
        return;
    };
    run_until(&mut opened, "the linked view", 50, |app| {
        app.view_state() == view && Some(app.mip_camera()) == view.camera
    });
    assert_eq!(opened.state().layout(), Layout::Grid);
    let errors = opened.state().errors().join("\n");
    assert!(errors.contains("opacity=\"7\""), "{errors}");
    assert!(!errors.contains("future"), "{errors}");
}

/// A large volume's texture is written over several frames, a slab at a time: the viewer keeps
/// showing the volume it had, the status says "uploading", and the new volume is installed once
/// the last slab is in (a whole-body CT would otherwise stop the window for seconds).
#[test]
fn a_large_volume_is_uploaded_over_frames() {
    use shapecast::volume::Volume;
    let Some(mut harness) = harness(intensity_only(StartWith::Phantom("sphere".into()))) else {
        return;
    };
    let before = harness.state().volume().expect("the phantom").dims;
    // 512 x 512 x 256: eight slabs of 16 MiB as half floats.
    let dims = [512, 512, 256];
    let values: Vec<f32> = (0..dims.iter().product::<usize>())
        .map(|i| ((i * 7) % 2000) as f32 - 1000.0)
        .collect();
    let volume = Volume::from_f32(dims, [0.7, 0.7, 0.8], values);
    let bytes = shapecast::io::nifti::write_volume("big.nii", &volume).expect("NIfTI");
    drop(volume);
    let big = || LoadSource::Files {
        label: "big.nii".into(),
        files: vec![shapecast::io::InputFile::new("big.nii", bytes.clone())],
    };
    harness.state_mut().open(big());
    let uploading = std::cell::Cell::new(0usize);
    run_until(&mut harness, "the large volume installed", 200, |app| {
        let s = app.status();
        if s.task.as_deref().is_some_and(|t| t.contains("uploading")) {
            assert_eq!(s.phase, Phase::Loading);
            assert_eq!(
                app.volume().map(|v| v.dims),
                Some(before),
                "the volume shown stays while the next one uploads"
            );
            uploading.set(uploading.get() + 1);
        }
        app.volume().is_some_and(|v| v.dims == dims)
    });
    assert!(
        uploading.get() >= 1,
        "no frame was drawn while the texture was written"
    );
    harness.run_steps(2);
    let s = harness.state().status();
    assert_eq!(s.phase, Phase::Ready, "{s:?}");
    assert_eq!(s.error, None);
    eprintln!("frames drawn while uploading: {}", uploading.get());

    // A newer load while one uploads: the upload stops, and the newer volume is the one
    // installed (the older never replaces it afterwards).
    harness.state_mut().open(big());
    run_until(&mut harness, "uploading again", 200, |app| {
        app.status()
            .task
            .as_deref()
            .is_some_and(|t| t.contains("uploading"))
    });
    harness
        .state_mut()
        .open(LoadSource::Phantom("sphere".into()));
    run_until(&mut harness, "the phantom installed", 200, |app| {
        app.volume().is_some_and(|v| v.dims == before)
    });
    harness.run_steps(12);
    assert_eq!(harness.state().volume().map(|v| v.dims), Some(before));
    assert_eq!(harness.state().status().phase, Phase::Ready);
}

/// A PET/CT study's folder (the CT and the PET of one scan) opens the CT, reads the PET after
/// it and fuses it over the slice panes in hot iron; the status gives the PET's SUV at the
/// crosshair, read on the PET's own grid at the CT voxel's patient position.
#[test]
fn a_pet_ct_folder_opens_the_ct_with_its_pet_fused() {
    let (Some(folder), Some(ct_dir), Some(pet_dir)) = (
        common::shared_data("petct/sts-cropped/STS_001"),
        common::shared_data("petct/sts-cropped/STS_001/CT"),
        common::shared_data("petct/sts-cropped/STS_001/PET"),
    ) else {
        return;
    };
    let Some(mut harness) = harness(intensity_only(StartWith::Paths(vec![folder]))) else {
        return;
    };
    run_until(&mut harness, "the PET loaded", 200, |app| {
        app.status().pet.is_some() && !app.status().pet_loading
    });
    harness.run_steps(3);
    let status = harness.state().status().clone();
    assert_eq!(status.error, None);
    assert_eq!(status.volume.as_ref().expect("a volume").modality, "CT");
    let pet = status.pet.clone().expect("the PET");
    assert_eq!(pet.unit, "SUV");
    assert_eq!(pet.window, (0.0, 10.0));
    let ct = shapecast::io::load(&common::inputs_in(&ct_dir))
        .expect("CT")
        .volume;
    let pet_volume = shapecast::io::load(&common::inputs_in(&pet_dir))
        .expect("PET")
        .volume;
    assert_eq!(pet.dims, pet_volume.dims);
    let c = status.crosshair.as_ref().expect("crosshair").lps_mm;
    let expected = pet_volume
        .value_at_world(glam::DVec3::from(c))
        .expect("the crosshair inside the PET");
    let got = pet.at_crosshair.expect("SUV at the crosshair");
    assert!((got - expected).abs() < 1e-5, "{got} vs {expected}");
    assert_eq!(ct.dims, status.volume.as_ref().expect("volume").dims);
    // The slice panes show the PET in hot iron: red well above green somewhere in the axial
    // pane, none when the PET is hidden.
    let image = harness.render().expect("render");
    save(&image, "app_pet_ct.png");
    let axial = harness
        .state()
        .pane_rect(SliceKind::Axial)
        .expect("axial pane");
    let warm = |image: &image::RgbaImage| {
        pixels_where(image, axial, |p| {
            p[0] > p[1].saturating_add(40) && p[0] > p[2].saturating_add(40)
        })
    };
    let fused = warm(&image);
    assert!(fused > 100, "{fused} hot-iron pixels in the axial pane");
    click_control(&mut harness, "pet-visible");
    harness.run_steps(3);
    assert!(!harness.state().status().pet.as_ref().expect("PET").visible);
    let hidden = warm(&harness.render().expect("render"));
    assert!(
        hidden * 10 < fused,
        "{hidden} warm pixels with the PET hidden, {fused} shown"
    );
    // Shown again, an SUV preset of the panel sets the PET's window; "PET alone" turns the
    // slice panes into the PET's own slices (inverted grey: no hot iron, dark where hot), and
    // the link carries both.
    click_control(&mut harness, "pet-visible");
    click_control(&mut harness, "pet-preset:0-5");
    harness.run_steps(3);
    assert_eq!(
        harness.state().status().pet.as_ref().expect("PET").window,
        (0.0, 5.0)
    );
    click_control(&mut harness, "pet-alone");
    harness.run_steps(3);
    let alone = harness.render().expect("render");
    save(&alone, "app_pet_alone.png");
    let grey_dark = pixels_where(&alone, axial, |p| {
        p[0] < 128 && p[0].abs_diff(p[1]) < 4 && p[1].abs_diff(p[2]) < 4
    });
    let grey_white = pixels_where(&alone, axial, |p| p[0] > 250 && p[1] > 250 && p[2] > 250);
    assert!(
        warm(&alone) * 10 < fused && grey_dark > 20 && grey_white > 1000,
        "PET alone: {} warm, {grey_dark} dark grey, {grey_white} white pixels",
        warm(&alone)
    );
    let link = harness.state().status().link.clone();
    assert!(
        link.contains("petwin=0,5") && link.contains("petalone=1"),
        "{link}"
    );
    // With the PET alone, a right drag on a slice pane sets the PET's window (wider, in SUV),
    // not the CT's.
    let ct_window = harness.state().window();
    let start = axial.center();
    drag(
        &mut harness,
        egui::PointerButton::Secondary,
        start,
        start + egui::vec2(80.0, 0.0),
    );
    let (lo, hi) = harness.state().status().pet.as_ref().expect("PET").window;
    assert!(hi - lo > 5.5, "PET window after the drag: {lo}..{hi}");
    assert_eq!(harness.state().window(), ct_window, "the CT's window stays");
}

/// Whole-body sizes: a PET of 200 x 200 x 700 (float Bq/ml, 112 MB of voxels) over a CT
/// larger than it (512 x 512 x 120) is read, uploaded for its MIP and fused over the slice
/// panes, and what stays in memory afterwards is the PET's own voxels and the panes'
/// overlays: no CT-sized copy of the PET (that would be 126 MB more) and no second copy of
/// its voxels. The peak while it arrives is printed.
#[test]
fn a_whole_body_pet_adds_its_own_voxels_and_no_ct_sized_copy() {
    use shapecast::volume::Volume;
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("whole-body-pet");
    std::fs::create_dir_all(&dir).expect("temp dir");
    let (ct_path, pet_path) = (dir.join("ct.nii"), dir.join("pet.nii"));
    let ct_dims = [512, 512, 120];
    let ct = Volume::from_f32(
        ct_dims,
        [0.8, 0.8, 2.5],
        (0..ct_dims.iter().product::<usize>())
            .map(|i| ((i * 7) % 1200) as f32 - 1000.0)
            .collect(),
    );
    std::fs::write(
        &ct_path,
        shapecast::io::nifti::write_volume("ct.nii", &ct).expect("NIfTI"),
    )
    .expect("write the CT");
    drop(ct);
    let pet_dims = [200, 200, 700];
    let pet_voxels = pet_dims.iter().product::<usize>();
    // Background 2,000 Bq/ml, a hot sphere of 40,000 in the CT's field.
    let pet = Volume::from_f32(
        pet_dims,
        [4.0, 4.0, 4.0],
        (0..pet_voxels)
            .map(|i| {
                let (x, y, z) = (i % 200, (i / 200) % 200, i / 40_000);
                let d2 = (x as f32 - 50.0).powi(2)
                    + (y as f32 - 50.0).powi(2)
                    + (z as f32 - 40.0).powi(2);
                if d2 < 25.0 { 40_000.0 } else { 2_000.0 }
            })
            .collect(),
    );
    std::fs::write(
        &pet_path,
        shapecast::io::nifti::write_volume("pet.nii", &pet).expect("NIfTI"),
    )
    .expect("write the PET");
    drop(pet);
    let Some(mut harness) = harness(intensity_only(StartWith::Paths(vec![ct_path]))) else {
        return;
    };
    assert_eq!(harness.state().volume().expect("the CT").dims, ct_dims);
    harness.run_steps(3);
    let before = counting::live();
    let ((), peak) = counting::peak_during(|| {
        harness
            .state_mut()
            .open_pet(LoadSource::Paths(vec![pet_path.clone()]));
        run_until(&mut harness, "the whole-body PET fused", 400, |app| {
            app.status().pet.is_some() && !app.status().pet_loading
        });
        harness.run_steps(5);
    });
    let added = counting::live().saturating_sub(before);
    let status = harness.state().status().clone();
    assert_eq!(status.error, None);
    assert_eq!(status.pet.as_ref().expect("the PET").dims, pet_dims);
    let voxel_bytes = pet_voxels * 4;
    let mb = |b: usize| b as f64 / 1e6;
    eprintln!(
        "whole-body PET: voxels {:.1} MB, kept {:.1} MB, peak while it arrived {:.1} MB",
        mb(voxel_bytes),
        mb(added),
        mb(peak)
    );
    // Its voxels, plus the three panes' overlays (a 512 x 512 RGBA image each) and slack.
    assert!(
        added <= voxel_bytes + 16_000_000,
        "the PET kept {:.1} MB for {:.1} MB of voxels",
        mb(added),
        mb(voxel_bytes)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The PET MIP beside the shape MIP: inverted grey (hot is dark), and a click on its darkest
/// pixel moves the crosshair to the PET's maximum along that ray: the hottest voxel.
#[test]
fn a_click_in_the_pet_mip_goes_to_the_hot_spot() {
    let (Some(folder), Some(pet_dir)) = (
        common::shared_data("petct/sts-cropped/STS_001"),
        common::shared_data("petct/sts-cropped/STS_001/PET"),
    ) else {
        return;
    };
    let Some(mut harness) = harness(intensity_only(StartWith::Paths(vec![folder]))) else {
        return;
    };
    run_until(&mut harness, "the PET loaded", 200, |app| {
        app.status().pet.is_some() && !app.status().pet_loading
    });
    // The whole SUV range as window (as the check asks): the darkest pixel is then the
    // hottest projection, not any of several saturated at the default 10 SUV.
    harness.state_mut().set_pet_window((0.0, 30.0));
    harness.run_steps(2);
    run_until(&mut harness, "both MIPs drawn in full", 200, |app| {
        app.status().mip == "done" && app.status().pet_mip == "done"
    });
    let rect = harness
        .state()
        .status()
        .controls
        .iter()
        .find(|(n, _)| n == "pane:pet-mip")
        .map(|(_, r)| egui::Rect::from_min_size(egui::pos2(r[0], r[1]), egui::vec2(r[2], r[3])))
        .expect("the PET MIP pane");
    let image = harness.render().expect("render");
    save(&image, "app_pet_mip.png");
    // The darkest pixel of the PET MIP (inverted: the hottest projection), above the scale bar
    // (drawn on a dark outline in the bottom 40 points).
    let mut darkest = (255u8, egui::Pos2::ZERO);
    for y in rect.top().ceil() as u32 + 2..rect.bottom().floor() as u32 - 40 {
        for x in rect.left().ceil() as u32 + 2..rect.right().floor() as u32 - 2 {
            let p = image.get_pixel(x, y);
            if p[0] < darkest.0 && p[0] == p[1] && p[1] == p[2] {
                darkest = (p[0], egui::pos2(x as f32 + 0.5, y as f32 + 0.5));
            }
        }
    }
    assert!(
        darkest.0 < 200,
        "the PET MIP shows its hot spot: darkest {}",
        darkest.0
    );
    let pet = shapecast::io::load(&common::inputs_in(&pet_dir))
        .expect("PET")
        .volume;
    let (hot, max) = (0..pet.voxel_count())
        .map(|n| (n, pet.value(n)))
        .fold((0, f32::MIN), |b, c| if c.1 > b.1 { c } else { b });
    harness.hover_at(darkest.1);
    for pressed in [true, false] {
        harness.event(egui::Event::PointerButton {
            pos: darkest.1,
            button: egui::PointerButton::Primary,
            pressed,
            modifiers: egui::Modifiers::NONE,
        });
    }
    let before = harness.state().status().crosshair.clone();
    run_until(&mut harness, "the crosshair moved", 60, |app| {
        app.status().crosshair != before
    });
    let c = harness
        .state()
        .status()
        .crosshair
        .clone()
        .expect("crosshair");
    let at = glam::DVec3::from(c.lps_mm);
    let suv = pet.value_at_world(at).expect("inside the PET");
    let d = pet.dims;
    let hot_mm = pet.world_from_voxel().transform_point3(glam::DVec3::new(
        (hot % d[0]) as f64,
        ((hot / d[0]) % d[1]) as f64,
        (hot / (d[0] * d[1])) as f64,
    ));
    eprintln!(
        "clicked grey {} at {:?}: crosshair {:?} (SUV {suv:.2}), hottest {max:.2} SUV at {hot_mm:?}",
        darkest.0, darkest.1, c.lps_mm
    );
    // The pick is where the ray has its maximum: at least what the pixel shows (inverted grey
    // over the 0-30 SUV window; the ray's samples may pass beside a one-voxel peak that the
    // crosshair, rounded to a CT voxel, lands nearer), and the darkest pixel's ray passes the
    // hottest voxel: the crosshair lands within 8 mm of it.
    let shown = f32::from(255 - darkest.0) / 255.0 * 30.0;
    assert!(
        suv >= shown - 1.0,
        "SUV {suv} at the crosshair, {shown} shown"
    );
    let off = (at - hot_mm).length();
    assert!(off <= 8.0, "{off:.1} mm from the hottest voxel");
}

/// Findings on the demo: with the Hessian shown (lymph-node preset, as the demo opens), the
/// panel lists each of the demo's four spheres once; a click on a row moves the crosshair to
/// it, a dismissed row is skipped by N, and the marks go into the link and come back from it.
#[test]
fn findings_list_the_demo_spheres_and_n_skips_the_dismissed() {
    use shapecast::app::ViewState;
    let start = || AppOptions {
        start: StartWith::Phantom("demo".into()),
        mode: DisplayMode::Features(Method::Hessian),
        compute_on_load: true,
        preset: Some(shapecast::cpu::Preset::LymphNodes),
        ..AppOptions::default()
    };
    let Some(mut harness) = harness(start()) else {
        return;
    };
    // No list until the reader asks: the panel's button.
    run_until(&mut harness, "the features", 400, |app| {
        app.status()
            .features
            .as_ref()
            .is_some_and(|f| f.state == "done")
    });
    harness.run_steps(2);
    assert_eq!(harness.state().findings_status().state, "not asked");
    scroll_side_panel_down(&mut harness);
    click_control(&mut harness, "findings:list");
    run_until(&mut harness, "findings listed", 400, |app| {
        app.findings_status().state == "done"
    });
    let status = harness.state().findings_status();
    // (centre voxel, radius in voxels) of the demo's spheres (src/phantom/catalogue.rs).
    let spheres = [
        ([30.0, 40.0, 48.0], 5.0),
        ([62.0, 58.0, 40.0], 4.0),
        ([48.0, 70.0, 66.0], 6.0),
        ([70.0, 30.0, 60.0], 3.0),
    ];
    let voxels: Vec<[usize; 3]> = status
        .listed
        .iter()
        .map(|f| f.voxel.expect("a made list has voxels"))
        .collect();
    for (c, r) in spheres {
        let near = voxels
            .iter()
            .filter(|v| {
                (0..3)
                    .map(|a| (v[a] as f64 - c[a]).powi(2))
                    .sum::<f64>()
                    .sqrt()
                    <= r
            })
            .count();
        assert_eq!(near, 1, "one finding per sphere at {c:?}: {voxels:?}");
    }
    scroll_side_panel_down(&mut harness);
    save(&harness.render().expect("render"), "app_findings.png");

    click_control(&mut harness, "finding:1");
    assert_eq!(harness.state().crosshair(), voxels[1]);
    click_control(&mut harness, "finding:2:dismiss");
    click_control(&mut harness, "finding:0:confirm");
    // From row 1, N skips the dismissed row 2; Shift+N comes back to row 1.
    harness.state_mut().next_finding(true);
    assert_eq!(harness.state().crosshair(), voxels[3]);
    harness.state_mut().next_finding(false);
    assert_eq!(harness.state().crosshair(), voxels[1]);
    let marks: Vec<String> = harness
        .state()
        .findings_status()
        .listed
        .iter()
        .map(|f| f.mark.clone())
        .collect();
    assert_eq!(&marks[..3], ["confirmed", "open", "dismissed"]);
    // Another method and back makes the list again: the reader's marks stay.
    harness
        .state_mut()
        .set_mode(DisplayMode::Features(Method::Li));
    run_until(&mut harness, "the Li list", 400, |app| {
        app.findings_status().state == "done"
            && app
                .status()
                .features
                .as_ref()
                .is_some_and(|f| f.method == "li")
    });
    harness
        .state_mut()
        .set_mode(DisplayMode::Features(Method::Hessian));
    run_until(&mut harness, "the Hessian list again", 400, |app| {
        app.findings_status().state == "done"
            && app
                .status()
                .features
                .as_ref()
                .is_some_and(|f| f.method == "hessian")
    });
    let kept: Vec<String> = harness
        .state()
        .findings_status()
        .listed
        .iter()
        .map(|f| f.mark.clone())
        .collect();
    assert_eq!(kept, marks, "marks after Li and back");

    // The link carries the list and its marks; a second app opened from it shows them.
    let view = harness.state().view_state();
    let fragment = view.fragment();
    assert!(fragment.contains("&find="), "{fragment}");
    drop(harness);
    let (read, problems) = ViewState::from_fragment(&format!("#{fragment}"));
    assert!(problems.is_empty(), "{problems:?}");
    let mut options = start();
    options.apply_link(read);
    let Some(mut opened) = self::harness(options) else {
        return;
    };
    run_until(&mut opened, "the linked findings", 400, |app| {
        app.findings_status().state == "done"
    });
    let again: Vec<String> = opened
        .state()
        .findings_status()
        .listed
        .iter()
        .map(|f| f.mark.clone())
        .collect();
    assert_eq!(again, marks);
}

/// Findings with a PET fused (STS_001: CT and the PET cropped around the sarcoma): the panel
/// lists the PET's hot spots with their CT shape, cut at SUV 2.5 since the crop holds no liver;
/// a click on the first moves the crosshair to it.
#[test]
fn findings_list_the_pet_hot_spots_and_a_click_goes_to_one() {
    let Some(folder) = common::shared_data("petct/sts-cropped/STS_001") else {
        return;
    };
    let Some(mut harness) = harness(AppOptions {
        start: StartWith::Paths(vec![folder]),
        mode: DisplayMode::Features(Method::Hessian),
        compute_on_load: true,
        preset: Some(shapecast::cpu::Preset::LymphNodes),
        ..AppOptions::default()
    }) else {
        return;
    };
    harness.state_mut().list_findings();
    run_until(&mut harness, "hot spots listed", 600, |app| {
        let f = app.findings_status();
        f.state == "done" && !f.hot_spots.is_empty()
    });
    let f = harness.state().findings_status();
    assert_eq!(
        f.pet_threshold,
        Some(shapecast::cpu::hot_spots::FALLBACK_SUV),
        "no liver in the crop"
    );
    let peaks: Vec<f64> = f.hot_spots.iter().map(|h| h.suv_peak).collect();
    assert!(peaks.windows(2).all(|w| w[0] >= w[1]), "{peaks:?}");
    assert!(peaks.iter().all(|&p| p > 2.5), "{peaks:?}");
    let first = f.hot_spots[0].clone();
    assert!(
        first.ct_round.is_some(),
        "the CT holds the sarcoma: {first:?}"
    );
    harness.run_steps(2);
    scroll_side_panel_down(&mut harness);
    save(&harness.render().expect("render"), "app_findings_pet.png");
    click_control(&mut harness, "hot-spot:0");
    let at = harness.state().crosshair_lps_mm().expect("crosshair");
    let d = at.distance(glam::DVec3::from(first.lps_mm));
    assert!(d <= 2.5, "crosshair {d} mm from the hot spot");
    // The axial pane, now through the hot spot, rings it in magenta ("P1"), which neither the
    // CT's grey, the hot-iron PET nor the findings' orange rings draw.
    harness.run_steps(3);
    let image = harness.render().expect("render");
    save(&image, "app_findings_pet_rings.png");
    let axial = harness
        .state()
        .pane_rect(SliceKind::Axial)
        .expect("axial pane");
    let magenta = pixels_where(&image, axial, |p| p[0] > 180 && p[2] > 180 && p[1] < 140);
    assert!(
        magenta > 20,
        "{magenta} magenta pixels: no hot-spot ring in the axial pane"
    );
}

/// A NIfTI-1 file of int16 voxels of `dims`, voxel `(i, j, k)` holding `value(i, j, k)`.
fn nifti_i16(dims: [usize; 3], value: impl Fn(usize, usize, usize) -> i16) -> Vec<u8> {
    let mut b = vec![0u8; 352];
    b[0..4].copy_from_slice(&348i32.to_le_bytes());
    b[40..42].copy_from_slice(&3i16.to_le_bytes());
    for (a, d) in dims.iter().enumerate() {
        b[42 + 2 * a..44 + 2 * a].copy_from_slice(&(*d as i16).to_le_bytes());
    }
    b[70..72].copy_from_slice(&4i16.to_le_bytes()); // DT_INT16
    b[72..74].copy_from_slice(&16i16.to_le_bytes());
    for a in 0..4 {
        b[76 + 4 * a..80 + 4 * a].copy_from_slice(&1f32.to_le_bytes());
    }
    b[108..112].copy_from_slice(&352f32.to_le_bytes());
    b[344..348].copy_from_slice(b"n+1\0");
    b.reserve(2 * dims.iter().product::<usize>());
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                b.extend_from_slice(&value(i, j, k).to_le_bytes());
            }
        }
    }
    b
}

/// A large CT is kept packed once shown (`app::PACK_FROM_BYTES`), and what reads the CPU copy
/// (the values the status bar, measurements and findings read) gets the file's values.
#[test]
fn a_large_volume_is_kept_packed_and_reads_the_file_s_values() {
    let Some(mut harness) = harness(intensity_only(StartWith::Phantom("sphere".into()))) else {
        return;
    };
    // 256 x 256 x 512 int16 = 64 MiB: air with noise, a body of soft tissue, bone up to 3000 HU.
    let dims = [256, 256, 512];
    assert_eq!(
        2 * dims.iter().product::<usize>(),
        shapecast::app::PACK_FROM_BYTES
    );
    let value = |i: usize, j: usize, k: usize| -> i16 {
        let (x, y) = (i as i64 - 128, j as i64 - 128);
        let noise = ((i * 7 + j * 13 + k * 29) % 23) as i16;
        match x * x + y * y {
            r2 if r2 < 20 * 20 => 3000 - noise,
            r2 if r2 < 100 * 100 => 40 + noise,
            _ => -1000 + noise,
        }
    };
    harness.state_mut().open(LoadSource::Files {
        label: "large.nii".into(),
        files: vec![shapecast::io::InputFile::new(
            "large.nii",
            nifti_i16(dims, value),
        )],
    });
    run_until(&mut harness, "the large volume shown", 400, |app| {
        app.volume().is_some_and(|v| v.dims == dims)
    });
    let volume = harness.state().volume().expect("shown");
    assert!(
        matches!(volume.voxels, shapecast::Voxels::Packed(_)),
        "{}",
        volume.voxels.type_name()
    );
    assert!(volume.voxels.byte_len() < shapecast::app::PACK_FROM_BYTES / 2);
    for (i, j, k) in [
        (0, 0, 0),
        (128, 128, 256),
        (200, 128, 17),
        (255, 255, 511),
        (130, 131, 400),
    ] {
        assert_eq!(
            volume.value_at(i, j, k),
            f32::from(value(i, j, k)),
            "({i}, {j}, {k})"
        );
    }
    assert_eq!(volume.value_range(), Some((-1000.0, 3000.0)));
    // The status bar reads the crosshair's value from the packed copy: 2997, odd and above
    // 2048, which the R16Float texture cannot hold (it would say 2996 or 2998).
    harness.state_mut().set_crosshair([128, 128, 260]);
    harness.run_steps(2);
    use egui_kittest::kittest::Queryable as _;
    let hu = value(128, 128, 260);
    assert_eq!(hu, 2997);
    assert!(
        harness
            .query_all_by_label_contains(&hu.to_string())
            .next()
            .is_some(),
        "the value {hu} is not on screen"
    );
}
