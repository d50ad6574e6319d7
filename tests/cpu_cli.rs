//! The `phantom` and `features` subcommands end to end on small volumes: files written, geometry
//! kept, three components, thick axes handled, the GPU backend refused with a clear message.

use std::path::{Path, PathBuf};
use std::process::Command;

use shapecast::io::{self, InputFile};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_shapecast"))
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("shapecast-cpu-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir.join(name)
}

fn load(path: &Path) -> shapecast::Volume {
    let bytes = std::fs::read(path).expect("output exists");
    io::load(&[InputFile::new(path.to_string_lossy(), bytes)])
        .expect("loads")
        .volume
}

fn run(cmd: &mut Command) -> String {
    let out = cmd.output().expect("runs");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "{cmd:?} failed: {text}");
    text
}

#[test]
fn phantom_is_deterministic_and_keeps_its_spacing() {
    let (a, b) = (tmp("a.nii.gz"), tmp("b.nii.gz"));
    for p in [&a, &b] {
        run(bin()
            .args([
                "phantom",
                "fig8-sphere",
                "--spacing-mm",
                "1,1.2,2",
                "--seed",
                "9",
                "--out",
            ])
            .arg(p));
    }
    assert_eq!(std::fs::read(&a).expect("a"), std::fs::read(&b).expect("b"));
    let v = load(&a);
    assert_eq!(
        v.spacing_mm.map(|s| (s * 100.0).round() / 100.0),
        [1.0, 1.2, 2.0]
    );
    // fig8-sphere carries 20 HU of noise by default: the background is not flat.
    let values = v.to_f32();
    let n = values.len() as f64;
    let mean = values.iter().map(|&x| f64::from(x)).sum::<f64>() / n;
    let sd = (values
        .iter()
        .map(|&x| (f64::from(x) - mean).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    assert!(sd > 15.0, "sd {sd}");
}

#[test]
fn features_write_three_components_on_the_input_grid() {
    let input = tmp("thick.nii.gz");
    // A thick z axis (2 mm): the Hessian with a scale below it refines z by an integer factor
    // and takes the features back at the input voxels; the RST runs on the input grid.
    run(bin()
        .args(["phantom", "sphere", "--spacing-mm", "1,1,2", "--out"])
        .arg(&input));
    let vin = load(&input);
    for (method, extra) in [
        ("hessian", vec!["--sigma-mm", "1,3"]),
        ("frangi", vec!["--sigma-mm", "2", "--frangi-c", "20"]),
        (
            "rst",
            vec![
                "--radius-mm",
                "8",
                "--step-mm",
                "0.5",
                "--dmin",
                "10",
                "--dmax",
                "30",
            ],
        ),
    ] {
        let out = tmp(&format!("{method}.nii.gz"));
        let text = run(bin()
            .args(["features"])
            .arg(&input)
            .args(["--method", method])
            .args(&extra)
            .arg("--out")
            .arg(&out));
        let refined = text.contains("refined for the Hessian by [1, 1, 2]");
        assert_eq!(refined, method == "hessian", "{method}: {text}");
        let v = load(&out);
        assert_eq!(v.dims, vin.dims);
        assert_eq!(v.spacing_mm, vin.spacing_mm);
        assert_eq!(v.origin_mm, vin.origin_mm);
    }
}

#[test]
fn eigen_output_and_auto_transfer_function() {
    let input = tmp("noisy.nii.gz");
    run(bin()
        .args([
            "phantom",
            "sphere",
            "--spacing-mm",
            "1",
            "--noise-hu",
            "10",
            "--out",
        ])
        .arg(&input));
    let out = tmp("eig.nii.gz");
    let text = run(bin()
        .arg("features")
        .arg(&input)
        .args([
            "--method",
            "rst",
            "--eigen",
            "--radius-mm",
            "8",
            "--step-mm",
            "0.5",
            "--out",
        ])
        .arg(&out));
    // The noise estimate is reported: white noise of 10 HU smoothed by sigma_g = 0.7 mm at 1 mm
    // keeps 10 * (2 sqrt(pi) 0.7)^(-3/2) = 2.56 HU. Below 5 HU the 10/30 preset stands.
    let sigma_s: f64 = text
        .split("noise of the smoothed intensity: ")
        .nth(1)
        .and_then(|t| t.split(" HU").next())
        .and_then(|t| t.trim().parse().ok())
        .unwrap_or_else(|| panic!("no noise estimate in: {text}"));
    assert!((sigma_s - 2.56).abs() < 0.4, "sigma_s {sigma_s}");
    assert!(text.contains("d_min 10.0 HU, d_max 30.0 HU"), "{text}");
    assert!(out.exists());
}

#[test]
fn gpu_and_cpu_backends_write_the_same_features() {
    let input = tmp("backends.nii.gz");
    run(bin()
        .args(["phantom", "sphere", "--spacing-mm", "1,1,1.6", "--out"])
        .arg(&input));
    for (method, extra) in [
        ("li", vec!["--sigma-mm", "2,3"]),
        (
            "rst",
            vec!["--radius-mm", "6", "--step-mm", "0.5", "--rays", "26"],
        ),
    ] {
        let mut outs = Vec::new();
        for backend in ["cpu", "gpu"] {
            let out = tmp(&format!("{method}-{backend}.nii.gz"));
            let text = run(bin()
                .args(["features"])
                .arg(&input)
                .args(["--method", method, "--backend", backend])
                .args(&extra)
                .arg("--out")
                .arg(&out));
            assert!(text.contains(&format!("({backend})")), "{text}");
            outs.push(load(&out).to_f32());
        }
        let max = outs[0].iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let worst = outs[0]
            .iter()
            .zip(&outs[1])
            .fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
        eprintln!("{method}: max {max}, worst |gpu - cpu| {worst}");
        assert!(max > 1.0, "{method}: no features");
        assert!(
            worst <= 1e-3 * max,
            "{method}: gpu and cpu differ by {worst} (max {max})"
        );
    }
}
