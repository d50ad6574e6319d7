//! `shapecast render` end to end on the paper's bifurcation phantom (three nodules r = 4 mm next
//! to a Y of vessels r = 3 mm): the PNG shows red vessels and yellow nodules where the camera
//! puts them, and `--pick` on a nodule's pixel lands inside that nodule.

use std::path::PathBuf;
use std::process::Command;

use glam::DVec3;
use shapecast::phantom::{NODULE_RADIUS_MM, Phantom, bifurcation_nodule_centres};
use shapecast::render::camera::{Camera, ViewPreset};

const PHANTOM: &str = "bifurcation-nodules-far";
const SIZE: [u32; 2] = [160, 160];

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_shapecast"))
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("shapecast-cli-render-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir.join(name)
}

/// Runs the command; `None` (skip) when there is no GPU adapter outside CI.
fn run(cmd: &mut Command) -> Option<String> {
    shapecast::gpu::context::test_context()?;
    let out = cmd.output().expect("runs");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{cmd:?} failed:\n{stdout}\n{stderr}");
    eprintln!("{stderr}");
    Some(stdout)
}

/// The camera the CLI uses for the phantom at 1 mm (the same framing rule).
fn camera(view: ViewPreset) -> Camera {
    let volume = Phantom::by_name(PHANTOM, None)
        .expect("phantom")
        .render([1.0; 3]);
    let dims = volume.dims.map(|d| d as u32);
    Camera::for_volume(&volume.world_from_voxel(), dims, view)
}

fn pixel_of(cam: &Camera, p: [f64; 3]) -> [u32; 2] {
    cam.project_to_pixel(DVec3::from(p), SIZE)
        .expect("point in view")
}

#[test]
fn rst_mip_shows_red_vessels_and_yellow_nodules_and_picks_a_nodule() {
    let out = tmp("bif_rst.png");
    let cam = camera(ViewPreset::Anterior);
    let nodules = bifurcation_nodule_centres(3.0);
    let n0 = pixel_of(&cam, nodules[0]);
    let Some(stdout) = run(bin()
        .args([
            "render",
            &format!("phantom:{PHANTOM}"),
            "--spacing-mm",
            "1",
            "--method",
            "rst",
            "--view",
            "anterior",
            "--size",
            &format!("{}x{}", SIZE[0], SIZE[1]),
            "--pick",
            &format!("{},{}", n0[0], n0[1]),
            "--out",
        ])
        .arg(&out))
    else {
        return;
    };
    let img = image::open(&out).expect("png").to_rgba8();
    assert_eq!(img.dimensions(), (SIZE[0], SIZE[1]));
    let px = |p: [u32; 2]| img.get_pixel(p[0], p[1]).0;
    let yellow = |c: [u8; 4]| c[0] > 200 && c[1] > 170 && c[2] < 90;
    let red = |c: [u8; 4]| c[0] > 150 && c[1] < 90 && c[2] < 90;
    // Not blank: many lit pixels, red and yellow both present.
    let lit = img
        .pixels()
        .filter(|p| p.0[..3].iter().any(|&c| c > 40))
        .count();
    let reds = img.pixels().filter(|p| red(p.0)).count();
    let yellows = img.pixels().filter(|p| yellow(p.0)).count();
    eprintln!("{lit} lit, {reds} red, {yellows} yellow pixels");
    assert!(lit > 2000 && reds > 300 && yellows > 200);
    // The nodule in the crotch and the one beside the +x branch are yellow; the trunk below the
    // branch point and a branch away from the nodules are red.
    for n in &nodules[..2] {
        let c = px(pixel_of(&cam, *n));
        assert!(yellow(c), "nodule {n:?}: {c:?}");
    }
    let (s, c) = shapecast::phantom::BRANCH_HALF_ANGLE_DEG
        .to_radians()
        .sin_cos();
    for p in [[0.0, 0.0, -12.0], [-25.0 * s, 0.0, 25.0 * c]] {
        let colour = px(pixel_of(&cam, p));
        assert!(red(colour), "vessel at {p:?}: {colour:?}");
    }
    // Patient left (+x) is on the screen's right in the anterior view.
    assert!(pixel_of(&cam, nodules[1])[0] > SIZE[0] / 2);

    let json: serde_json::Value = serde_json::from_str(&stdout).expect("JSON on stdout");
    assert_eq!(json["hit"], true, "{json}");
    assert_eq!(json["channel"], "blobness", "{json}");
    let lps: Vec<f64> = serde_json::from_value(json["lps_mm"].clone()).expect("lps_mm");
    let d = (DVec3::from_slice(&lps) - DVec3::from(nodules[0])).length();
    assert!(
        d < NODULE_RADIUS_MM,
        "pick {lps:?} is {d:.2} mm from the nodule: {json}"
    );
    let voxel: Vec<usize> = serde_json::from_value(json["voxel"].clone()).expect("voxel");
    assert_eq!(voxel.len(), 3);
    // The values there: inside the nodule (140 HU) with blobness.
    let hu = json["intensity"].as_f64().expect("intensity");
    assert!(hu > 100.0, "{json}");
    assert!(json["features"]["blobness"].as_f64().expect("blobness") > 0.0);
}

#[test]
fn pick_from_a_superior_oblique_view_lands_in_the_nodule_beside_the_branch() {
    let mut cam = camera(ViewPreset::Superior);
    cam.orbit(15.0, -20.0);
    let nodule = bifurcation_nodule_centres(3.0)[1];
    let p = pixel_of(&cam, nodule);
    let Some(stdout) = run(bin().args([
        "render",
        &format!("phantom:{PHANTOM}"),
        "--spacing-mm",
        "1",
        "--method",
        "hessian",
        "--view",
        "superior",
        "--yaw-deg",
        "15",
        "--pitch-deg",
        "-20",
        "--size",
        &format!("{}x{}", SIZE[0], SIZE[1]),
        "--pick",
        &format!("{},{}", p[0], p[1]),
    ])) else {
        return;
    };
    let json: serde_json::Value = serde_json::from_str(&stdout).expect("JSON on stdout");
    let lps: Vec<f64> = serde_json::from_value(json["lps_mm"].clone()).expect("lps_mm");
    let d = (DVec3::from_slice(&lps) - DVec3::from(nodule)).length();
    assert!(
        d < NODULE_RADIUS_MM,
        "pick {lps:?} is {d:.2} mm from the nodule: {json}"
    );
}

#[test]
fn intensity_only_pick_outside_the_volume_misses_and_bad_sizes_are_refused() {
    let Some(stdout) = run(bin().args([
        "render",
        "phantom:sphere",
        "--spacing-mm",
        "1",
        "--method",
        "intensity",
        "--size",
        "64x48",
        "--pick",
        "0,0",
    ])) else {
        return;
    };
    let json: serde_json::Value = serde_json::from_str(&stdout).expect("JSON");
    assert_eq!(json["hit"], false, "{json}");
    let out = bin()
        .args(["render", "phantom:sphere", "--size", "0x5", "--pick", "0,0"])
        .output()
        .expect("runs");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--size"));
}
