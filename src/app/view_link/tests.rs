use super::*;
use crate::app::measure::MeasureKind;
use crate::cpu::pipeline::Method;

fn full() -> ViewState {
    let mut params = FeatureParams::from_preset(Preset::Airways);
    params.sigma_count = 3;
    params.rays = 98;
    params.tf = Some(TransferFunction {
        d_min: 12.5,
        d_max: 40.0,
    });
    params.map = FeatureMap::Simple;
    ViewState {
        source: Some(ViewSource::Urls(vec![
            "https://example.org/a b/x.nhdr?token=1&y=2".to_owned(),
            "https://example.org/a b/x.raw.gz".to_owned(),
        ])),
        mode: Some(DisplayMode::Features(Method::Li)),
        params: Some(params),
        display: Some(FeatureDisplay {
            enabled: [true, false, true],
            gain: [1.0, 0.1, 2.345_678_9],
            overlay_on_slices: false,
            opacity: 0.3,
        }),
        camera: Some(Camera {
            centre_mm: DVec3::new(-12.25, 0.1 + 0.2, 1e-9),
            rotation: DQuat::from_rotation_y(0.7) * DQuat::from_rotation_x(-0.3),
            fov_mm: 231.123_456_789,
            zoom: 1.7,
        }),
        slab_mm: Some(Some(12.5)),
        crosshair_mm: Some([1.0 / 3.0, -250.0, 7.5]),
        mip_window: Some((-100.0, 900.5)),
        projection: Some(Projection::MinIp),
        grey: Some(false),
        window: Some(Window::new(1500.0, -600.0)),
        layout: Some(Layout::Single(super::super::PaneId::Slice(
            super::super::SliceKind::Coronal,
        ))),
        measurements: Some(vec![
            Measurement {
                kind: MeasureKind::Ruler,
                pane: Some(super::super::SliceKind::Axial),
                a_mm: DVec3::new(-12.25, 1.0 / 3.0, 40.0),
                b_mm: DVec3::new(3.5, 0.1, 40.0),
            },
            Measurement {
                kind: MeasureKind::Ellipse,
                pane: Some(super::super::SliceKind::Sagittal),
                a_mm: DVec3::new(7.0, -20.0, 1e-3),
                b_mm: DVec3::new(7.0, -5.5, 18.0),
            },
            // A ruler in 3D (an end picked in the MIP).
            Measurement {
                kind: MeasureKind::Ruler,
                pane: None,
                a_mm: DVec3::new(1.5, -2.0, 30.25),
                b_mm: DVec3::new(-8.0, 14.125, -3.0),
            },
        ]),
        choice: Some("1.2.840.113619.2.55.3.604688119:1".to_owned()),
        pet: Some(PetView {
            urls: vec!["https://example.org/pet/PT.zip".to_owned()],
            window: Some((0.0, 7.5)),
            opacity: Some(0.35),
            visible: Some(true),
            alone: Some(true),
        }),
        findings: Some(vec![
            FindingMark {
                lps_mm: [-40.5, 12.0, 101.25],
                mark: super::super::findings::Mark::Confirmed,
            },
            FindingMark {
                lps_mm: [1.0 / 3.0, 0.0, -7.0],
                mark: super::super::findings::Mark::Open,
            },
        ]),
    }
}

#[test]
fn a_view_reads_back_bit_for_bit() {
    let v = full();
    let fragment = v.fragment();
    let (back, problems) = ViewState::from_fragment(&format!("#{fragment}"));
    assert!(problems.is_empty(), "{problems:?}");
    assert_eq!(back, v, "{fragment}");
    assert_eq!(back.fragment(), fragment);
    assert_eq!(back.json(), v.json());
    // Every layout and source kind too.
    for layout in [
        Layout::MipAndSlices,
        Layout::Grid,
        Layout::Single(super::super::PaneId::Mip),
    ] {
        for source in [
            ViewSource::Demo,
            ViewSource::Phantom("fig8-sphere".into()),
            ViewSource::Dropped {
                name: "ct-head (93 files)".into(),
                bytes: 1_234_567,
            },
            ViewSource::DicomWeb {
                base: "/dicom-web".into(),
                study: "1.2.3".into(),
                series: "1.2.3.4".into(),
            },
        ] {
            let v = ViewState {
                layout: Some(layout),
                source: Some(source),
                slab_mm: Some(None),
                ..full()
            };
            let (back, problems) = ViewState::from_fragment(&v.fragment());
            assert!(problems.is_empty(), "{problems:?}");
            assert_eq!(back, v);
        }
    }
}

#[test]
fn the_fragment_is_readable_and_the_json_valid() {
    let v = full();
    let f = v.fragment();
    assert!(
        f.starts_with("v=1&url=https://example.org/a%20b/x.nhdr%3Ftoken%3D1%26y%3D2&url="),
        "{f}"
    );
    assert!(f.contains("&mode=li&preset=airways&sigma="), "{f}");
    assert!(f.contains("&layout=coronal"), "{f}");
    let json: serde_json::Value = serde_json::from_str(&v.json()).unwrap();
    assert_eq!(json["v"], 1);
    assert_eq!(json["url"][1], "https://example.org/a b/x.raw.gz");
    assert_eq!(json["gain"][2].as_f64().unwrap() as f32, 2.345_678_9_f32);
    assert_eq!(json["on"][1], false);
    assert_eq!(json["tf"][0], 12.5);
    assert_eq!(json["layout"], "coronal");
    let mut mip = full();
    mip.layout = Some(Layout::MipAndSlices);
    assert!(mip.fragment().contains("layout=mip%2Bslices"));
}

#[test]
fn preset_defaults_are_left_out() {
    let v = ViewState {
        params: Some(FeatureParams::from_preset(Preset::Vessels)),
        ..Default::default()
    };
    assert_eq!(v.fragment(), "v=1&preset=vessels");
    let (back, _) = ViewState::from_fragment("preset=vessels");
    assert_eq!(
        back.params,
        Some(FeatureParams::from_preset(Preset::Vessels))
    );
}

#[test]
fn bad_fields_are_named_and_the_rest_applies() {
    let (v, problems) = ViewState::from_fragment(
        "#v=1&mode=li&gain=1,x,1&layout=grid&rays=7&future=42&rot=0,0,0,0&zoom=2&centre=1,2,3&fov=100&cross=1,2",
    );
    assert_eq!(v.mode, Some(DisplayMode::Features(Method::Li)));
    assert_eq!(v.layout, Some(Layout::Grid));
    assert_eq!(
        v.display.unwrap().gain,
        [1.0; 3],
        "a bad gain keeps the default"
    );
    assert_eq!(v.params.unwrap().rays, 42);
    assert_eq!(v.camera, None, "a bad rotation drops the whole camera");
    assert_eq!(v.crosshair_mm, None);
    let joined = problems.join("\n");
    for field in ["gain=\"1,x,1\"", "rays=\"7\"", "rot=", "cross="] {
        assert!(joined.contains(field), "{field} not named in {joined}");
    }
    assert!(
        !joined.contains("future"),
        "unknown fields are ignored: {joined}"
    );
    assert_eq!(problems.len(), 4, "{problems:?}");
    // A bad measurement is named; the good ones are kept.
    let (v, problems) = ViewState::from_fragment(
        "m=ruler,axial,1,2,3,4,5,6&m=ruler,axial,1,2&m=ellipse,coronal,0,0,0,1,1,1",
    );
    assert_eq!(v.measurements.map(|m| m.len()), Some(2));
    assert!(
        problems.len() == 1 && problems[0].contains("m=\"ruler,axial,1,2\""),
        "{problems:?}"
    );
    // A newer version is said, and still read.
    let (v, problems) = ViewState::from_fragment("v=9&mode=rst");
    assert_eq!(v.mode, Some(DisplayMode::Features(Method::Rst)));
    assert!(problems[0].contains("newer"), "{problems:?}");
    // Garbage never panics.
    for s in [
        "",
        "#",
        "&&&",
        "=",
        "v",
        "%",
        "%zz&%4",
        "url=",
        "file=x",
        "bytes=9&file=",
    ] {
        let _ = ViewState::from_fragment(s);
    }
}
