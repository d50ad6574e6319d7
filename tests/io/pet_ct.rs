//! PET/CT on real data (../shared/data/petct): a whole-body FDG PET in Bq/ml opens in SUVbw by
//! the QIBA rule and reproduces the SUV series the same study was converted to; `info --json`
//! reports the factor; its MIP's brightest pixel picks the hottest voxel; a PET fused over its
//! study's CT reports the SUV at the picked point.

use crate::common;

use std::process::Command;

use glam::DVec3;
use shapecast::gpu::context::test_context;
use shapecast::gpu::volume_texture::RenderVolume;
use shapecast::io;
use shapecast::render::camera::{Camera, ViewPreset};
use shapecast::render::raycast::{RaycastTarget, Raycaster, RenderSettings, Scene};
use shapecast::volume::{Modality, Volume};

/// The raw PET's SUV factor by the QIBA rule (../shared/data/README.md: decay from SeriesTime
/// over 2,711 s), g/ml per Bq/ml.
const STS001_FACTOR: f64 = 2.4290e-4;

fn load(rel: &str) -> Option<Volume> {
    let dir = common::shared_data(rel)?;
    let loaded = io::load(&common::inputs_in(&dir)).unwrap_or_else(|e| panic!("{rel}: {e}"));
    Some(loaded.volume)
}

fn shapecast() -> Command {
    Command::new(env!("CARGO_BIN_EXE_shapecast"))
}

#[test]
fn a_raw_pet_opens_in_suv_and_matches_the_study_s_suv_series() {
    let Some(raw) = load("petct/sts001-raw/PT") else {
        return;
    };
    let Some(reference) = load("petct/sts-cropped/STS_001/PET") else {
        return;
    };
    assert_eq!(raw.modality, Modality::Pt);
    assert_eq!(raw.unit(), "SUV");
    let pet = raw.pet.as_ref().expect("PET scale");
    assert_eq!(pet.units, "BQML");
    let factor = pet.suv_factor.expect("an SUV factor");
    assert!(
        (factor / STS001_FACTOR - 1.0).abs() < 1e-4,
        "factor {factor:e} vs {STS001_FACTOR:e} ({})",
        pet.rule
    );
    // The converted series is SUV already (Units GML).
    assert_eq!(reference.unit(), "SUV");
    assert_eq!(reference.pet.as_ref().and_then(|p| p.suv_factor), Some(1.0));
    assert_eq!(raw.frame_of_reference, reference.frame_of_reference);
    // Every voxel of the cropped SUV series against the raw PET read at the same LPS point.
    // Both series store integers with a per-slice slope, so each value is quantised to about
    // 1/32767 of its slice's maximum (8e-4 SUV here): the bound is relative (0.1%) plus 0.001
    // SUV, and the sums, where quantisation averages out, agree within 0.01%.
    let (mut compared, mut worst, mut max_ref, mut max_raw) = (0usize, 0.0f64, 0.0f32, 0.0f32);
    let (mut sum_raw, mut sum_ref) = (0.0f64, 0.0f64);
    let world = reference.world_from_voxel();
    for k in 0..reference.dims[2] {
        for j in 0..reference.dims[1] {
            for i in 0..reference.dims[0] {
                let p = world.transform_point3(DVec3::new(i as f64, j as f64, k as f64));
                let Some(v) = raw.value_at_world(p) else {
                    continue;
                };
                let r = reference.value_at(i, j, k);
                max_ref = max_ref.max(r);
                max_raw = max_raw.max(v);
                compared += 1;
                sum_raw += f64::from(v);
                sum_ref += f64::from(r);
                // In units of the bound: 1 is 0.1% of the value plus 0.001 SUV.
                let d = f64::from((v - r).abs()) / (1e-3 * f64::from(r.abs()) + 1e-3);
                worst = worst.max(d);
            }
        }
    }
    let sums = sum_raw / sum_ref - 1.0;
    eprintln!(
        "{compared} voxels compared; worst difference {worst:.2} of the bound; sums {sums:.2e}; max SUV {max_raw} vs {max_ref}"
    );
    assert!(
        compared > reference.voxel_count() / 2,
        "{compared} compared"
    );
    assert!(worst <= 1.0, "worst difference {worst} of the bound");
    assert!(sums.abs() < 1e-4, "sums differ by {sums}");
    assert!((max_raw / max_ref - 1.0).abs() < 1e-3);
}

#[test]
fn info_json_of_a_pet_gives_modality_and_suv() {
    let Some(dir) = common::shared_data("petct/sts001-raw/PT") else {
        return;
    };
    let out = shapecast()
        .args(["info", "--json"])
        .arg(&dir)
        .output()
        .expect("run shapecast");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert_eq!(json["modality"], "PT");
    assert_eq!(json["unit"], "SUV");
    let factor = json["suv"]["factor"].as_f64().expect("suv.factor");
    assert!((factor / STS001_FACTOR - 1.0).abs() < 1e-4, "{factor}");
    let max = json["suv"]["max"].as_f64().expect("suv.max");
    assert_eq!(Some(max), json["max"].as_f64());
    assert!(max > 1.0 && max < 100.0, "largest SUV {max}");
    assert!(json["suv"]["rule"].as_str().is_some_and(|r| !r.is_empty()));
}

#[test]
fn the_study_s_ct_has_no_suv() {
    let Some(ct) = load("petct/sts-cropped/STS_001/CT") else {
        return;
    };
    assert_eq!(ct.modality, Modality::Ct);
    assert!(ct.pet.is_none());
    assert_eq!(ct.unit(), "HU");
}

/// The brightest pixel of the PET's MIP, with the whole SUV range as window, picks within 8 mm
/// of the hottest voxel (it landed 305 mm away while values were clipped at 65,504).
#[test]
fn the_pet_mip_s_brightest_pixel_picks_the_hottest_voxel() {
    let Some(volume) = load("petct/sts001-raw/PT") else {
        return;
    };
    let Some(ctx) = test_context() else {
        return;
    };
    let (hottest, max) = (0..volume.voxel_count())
        .map(|n| (n, volume.value(n)))
        .fold((0, f32::MIN), |b, c| if c.1 > b.1 { c } else { b });
    let d = volume.dims;
    let hot = [
        hottest % d[0],
        (hottest / d[0]) % d[1],
        hottest / (d[0] * d[1]),
    ];
    let hot_world = volume.world_from_voxel().transform_point3(DVec3::new(
        hot[0] as f64,
        hot[1] as f64,
        hot[2] as f64,
    ));
    let rv = RenderVolume::upload(&ctx, &volume).expect("upload");
    let caster = Raycaster::new(&ctx).expect("shaders");
    let camera = Camera::for_volume(&rv.world_from_voxel, rv.dims, ViewPreset::Anterior);
    let settings = RenderSettings {
        window: (0.0, max),
        ..Default::default()
    };
    let size = [256, 256];
    let mut target = RaycastTarget::new(&ctx, size).expect("target");
    let scene = Scene {
        volume: &rv,
        features: None,
        bricks: None,
        feature_bricks: None,
    };
    caster
        .render(&ctx, &scene, &camera, &settings, &mut target, ..)
        .expect("render");
    let image = target.read_image_blocking(&ctx).expect("image");
    let brightest = (0..(size[0] * size[1]) as usize)
        .max_by_key(|&p| image[4 * p])
        .expect("pixels");
    let pixel = [brightest as u32 % size[0], brightest as u32 / size[0]];
    let pick = target
        .pick_blocking(&ctx, pixel)
        .expect("pick")
        .expect("a hit");
    let off = (pick.world_mm - hot_world).length();
    eprintln!(
        "hottest voxel {hot:?} ({max:.2} SUV); brightest pixel {pixel:?} (grey {}) picks {:?}, {off:.1} mm away",
        image[4 * brightest],
        pick.voxel
    );
    assert!(off <= 8.0, "{off:.1} mm from the hottest voxel");
}

/// `render CT --pet PET --pick`: the PET is fused over the CT's picture and the pick reports the
/// PET's SUV at the picked 3D point, read on the PET's own grid.
#[test]
fn a_fused_render_reports_the_suv_at_the_pick() {
    let (Some(ct_dir), Some(pet_dir)) = (
        common::shared_data("petct/sts-cropped/STS_001/CT"),
        common::shared_data("petct/sts001-raw/PT"),
    ) else {
        return;
    };
    if test_context().is_none() {
        return;
    }
    let out_png = std::env::temp_dir().join(format!("shapecast-fused-{}.png", std::process::id()));
    let out = shapecast()
        .arg("render")
        .arg(&ct_dir)
        .arg("--pet")
        .arg(&pet_dir)
        .args([
            "--method",
            "intensity",
            "--size",
            "128x128",
            "--pick",
            "64,64",
        ])
        .arg("--out")
        .arg(&out_png)
        .output()
        .expect("run shapecast");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert_eq!(json["hit"], true, "{json}");
    let lps: Vec<f64> = (0..3)
        .map(|a| json["lps_mm"][a].as_f64().expect("lps"))
        .collect();
    let suv = json["suv"].as_f64().expect("suv at the pick") as f32;
    let pet = load("petct/sts001-raw/PT").expect("present");
    let expected = pet
        .value_at_world(DVec3::new(lps[0], lps[1], lps[2]))
        .expect("inside the PET");
    assert!(
        (suv - expected).abs() <= 1e-4 * expected.abs().max(1.0),
        "{suv} vs {expected}"
    );
    // The picture: the CT's grey with hot iron where the PET is warm (red above green).
    let img = image::open(&out_png).expect("the PNG").to_rgba8();
    let warm = img
        .pixels()
        .filter(|p| p[0] > p[1].saturating_add(20))
        .count();
    assert!(warm > 0, "no hot-iron pixel in the fused picture");
    let _ = std::fs::remove_file(&out_png);
}

/// `findings CT --pet PET`: the PET's hot spots above the PERCIST threshold of the liver the
/// whole-body PET holds (found on the patient's right, between the heart and the pelvis), ranked
/// by SUVpeak; the bladder is the hottest and lies in the CT, which gives its shape there;
/// spots beyond the cropped CT have no CT shape; each CT finding reads the SUVpeak at its peak.
#[test]
fn findings_with_a_pet_list_its_hot_spots_with_their_ct_shape() {
    let (Some(ct_dir), Some(pet_dir)) = (
        common::shared_data("petct/sts-cropped/STS_001/CT"),
        common::shared_data("petct/sts001-raw/PT"),
    ) else {
        return;
    };
    let out = shapecast()
        .arg("findings")
        .arg(&ct_dir)
        .arg("--pet")
        .arg(&pet_dir)
        .args([
            "--preset",
            "lymph-nodes",
            "--method",
            "hessian",
            "--backend",
            "cpu",
            "--json",
            "--all",
        ])
        .output()
        .expect("run shapecast");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    let pet = &json["pet"];
    let num = |v: &serde_json::Value| v.as_f64().unwrap_or_else(|| panic!("a number: {v}"));
    let liver = &pet["reference"]["liver"];
    let (mean, sd) = (num(&liver["mean"]), num(&liver["sd"]));
    assert!((1.5..=3.0).contains(&mean) && sd < 0.2 * mean, "{liver}");
    // LPS: x < 0 is the patient's right; below the heart (z -290), above the bladder (-680).
    let at: Vec<f64> = (0..3).map(|a| num(&liver["lps_mm"][a])).collect();
    assert!(
        at[0] < -30.0 && (-520.0..=-330.0).contains(&at[2]),
        "{liver}"
    );
    let threshold = num(&pet["reference"]["threshold_suv"]);
    assert!((threshold - (1.5 * mean + 2.0 * sd)).abs() < 0.02, "{pet}");
    let spots = pet["hot_spots"].as_array().expect("hot spots");
    assert!(spots.len() >= 5, "{pet}");
    let peaks: Vec<f64> = spots.iter().map(|h| num(&h["suv_peak"])).collect();
    assert!(
        peaks.windows(2).all(|w| w[0] >= w[1]),
        "ranked by SUVpeak: {peaks:?}"
    );
    assert!(peaks.iter().all(|&p| p > threshold), "{peaks:?}");
    let bladder = &spots[0];
    assert!(num(&bladder["suv_peak"]) > 30.0, "{bladder}");
    assert!(
        bladder["ct_round"].is_boolean() && bladder["ct_score"].is_number(),
        "{bladder}"
    );
    let outside = spots.iter().filter(|h| h["ct_round"].is_null()).count();
    assert!(outside > 0 && outside < spots.len(), "{pet}");
    for h in spots.iter().filter(|h| h["ct_round"].is_boolean()) {
        assert_eq!(
            h["ct_round"].as_bool(),
            Some(num(&h["ct_score"]) >= 1.0),
            "{h}"
        );
    }
    // The lymph-node preset finds nothing round in soft tissue on this crop (a thigh sarcoma
    // and the pelvis); the vessels preset's findings (inside the body) read the PET's SUVpeak.
    let out = shapecast()
        .arg("findings")
        .arg(&ct_dir)
        .arg("--pet")
        .arg(&pet_dir)
        .args([
            "--preset",
            "vessels",
            "--method",
            "hessian",
            "--backend",
            "cpu",
            "--json",
        ])
        .output()
        .expect("run shapecast");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    let findings = json["findings"].as_array().expect("findings");
    assert!(!findings.is_empty(), "{json}");
    let pet = load("petct/sts001-raw/PT").expect("present");
    for f in findings {
        let p = DVec3::new(
            num(&f["lps_mm"][0]),
            num(&f["lps_mm"][1]),
            num(&f["lps_mm"][2]),
        );
        let expected = shapecast::cpu::hot_spots::sphere_mean(
            &pet,
            p,
            shapecast::cpu::hot_spots::PEAK_SPHERE_RADIUS_MM,
        )
        .expect("the PET holds the CT");
        // lps_mm is rounded to 0.01 mm: the sphere may gain or lose a voxel at its rim only.
        assert!(
            (num(&f["suv_peak"]) - expected).abs() <= 0.02 + 0.2 * expected,
            "{f}: {expected}"
        );
    }
}
