//! `shapecast render --turntable N --out DIR/` on the bifurcation phantom: N frames of the
//! requested size, the first one the plain render's picture, half a turn later the posterior
//! view (for a MIP, the anterior one mirrored left to right), and bad arguments refused with a
//! message naming them.

use std::path::PathBuf;
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_shapecast"))
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("shapecast-turntable-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir.join(name)
}

/// Runs the command; `None` (skip) when there is no GPU adapter outside CI.
fn run(cmd: &mut Command) -> Option<String> {
    shapecast::gpu::context::test_context()?;
    let out = cmd.output().expect("runs");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{cmd:?} failed:\n{stderr}");
    eprintln!("{stderr}");
    Some(stderr)
}

fn render_args(size: &str) -> Vec<String> {
    [
        "render",
        "phantom:bifurcation-nodules-far",
        "--spacing-mm",
        "1",
        "--method",
        "intensity",
        "--window",
        "0,200",
        "--size",
        size,
    ]
    .map(str::to_owned)
    .to_vec()
}

#[test]
fn turntable_writes_n_frames_of_a_full_turn() {
    let dir = tmp("frames");
    let single = tmp("single.png");
    let Some(_) = run(bin()
        .args(render_args("96x80"))
        .args(["--turntable", "8", "--out"])
        .arg(&dir))
    else {
        return;
    };
    let Some(_) = run(bin().args(render_args("96x80")).arg("--out").arg(&single)) else {
        return;
    };
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .expect("frames folder")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    let want: Vec<String> = (0..8).map(|f| format!("frame_{f:04}.png")).collect();
    assert_eq!(names, want);
    let frames: Vec<image::RgbaImage> = want
        .iter()
        .map(|n| image::open(dir.join(n)).expect("png").to_rgba8())
        .collect();
    for f in &frames {
        assert_eq!(f.dimensions(), (96, 80));
    }
    let plain = image::open(&single).expect("png").to_rgba8();
    assert!(frames[0] == plain, "frame 0 is the view asked for");
    // Half a turn: the posterior view, which for a maximum along the rays is the anterior view
    // mirrored (up to the sampling of the rays).
    let mirrored = image::imageops::flip_horizontal(&frames[0]);
    let diff = |a: &image::RgbaImage, b: &image::RgbaImage| {
        let sum: u64 = a
            .pixels()
            .zip(b.pixels())
            .map(|(p, q)| u64::from(p[0].abs_diff(q[0])))
            .sum();
        sum as f64 / f64::from(a.width() * a.height())
    };
    let (half, quarter) = (diff(&frames[4], &mirrored), diff(&frames[2], &frames[0]));
    eprintln!("mean |frame 4 - mirrored frame 0| = {half:.2}, |frame 2 - frame 0| = {quarter:.2}");
    assert!(half < 3.0, "{half}");
    assert!(
        quarter > 4.0 * half.max(0.5),
        "a quarter turn changes the picture: {quarter}"
    );
}

#[test]
fn turntable_arguments_are_checked() {
    for (extra, says) in [
        (vec!["--turntable", "0", "--out", "x"], "1 to 3600"),
        (vec!["--turntable", "5"], "nothing to do"),
    ] {
        let out = bin()
            .args(render_args("32x32"))
            .args(&extra)
            .output()
            .expect("runs");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{extra:?}");
        assert!(stderr.contains(says), "{extra:?}: {stderr}");
    }
    let file = tmp("a-file.png");
    std::fs::write(&file, b"x").expect("write");
    let out = bin()
        .args(render_args("32x32"))
        .args(["--turntable", "4", "--out"])
        .arg(&file)
        .output()
        .expect("runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("is a file"),
        "{stderr}"
    );
}
