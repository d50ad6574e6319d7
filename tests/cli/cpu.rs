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
    let iso = tmp("iso.nii.gz");
    // A thick z axis (2 mm): the Hessian with a scale below it refines z by an integer factor
    // and takes the features back at the input voxels; the RST runs on the input grid.
    run(bin()
        .args(["phantom", "sphere", "--spacing-mm", "1,1,2", "--out"])
        .arg(&input));
    run(bin()
        .args(["phantom", "sphere", "--spacing-mm", "1", "--out"])
        .arg(&iso));
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
        // Uncompressed, so that the test reads all three components.
        let features = |input: &Path, name: &str| {
            let out = tmp(&format!("{method}-{name}.nii"));
            let text = run(bin()
                .args(["features"])
                .arg(input)
                .args(["--method", method])
                .args(&extra)
                .arg("--out")
                .arg(&out));
            (out, text)
        };
        let (out, text) = features(&input, "thick");
        let refined = text.contains("refined for the Hessian by [1, 1, 2]");
        assert_eq!(refined, method == "hessian", "{method}: {text}");
        let v = load(&out);
        assert_eq!(v.dims, vin.dims);
        assert_eq!(v.spacing_mm, vin.spacing_mm);
        assert_eq!(v.origin_mm, vin.origin_mm);
        if method == "hessian" {
            // The numbers, not only the files: blobness 1 mm above the sphere's centre (a
            // voxel centre on both grids) as on the 1 mm grid, within 10% (measured 25.66 vs
            // 28.16). The RST's is `rst_blobness_through_thick_slices` below.
            let (iso_out, _) = features(&iso, "iso");
            let b_thick = blobness_at(&out, &vin, [0.0, 0.0, 1.0]);
            let b_iso = blobness_at(&iso_out, &load(&iso), [0.0, 0.0, 1.0]);
            eprintln!(
                "{method}: blobness at (0, 0, 1) mm: {b_thick:.3} at 1x1x2 mm, {b_iso:.3} at 1 mm"
            );
            assert!(b_iso > 1.0, "{method}: no blobness at 1 mm ({b_iso})");
            assert!(
                (b_thick / b_iso - 1.0).abs() <= 0.1,
                "{method}: {b_thick} at 1x1x2 mm vs {b_iso} at 1 mm"
            );
        }
    }
}

/// The RST's blobness through the delivered pipeline at a thick-slice spacing, against the
/// same sphere at 1 mm (issue 13, items 1 and 6): within 10% (with the old non-integer
/// thick-axis resampling, 1x1x2 mm kept 9.75 of the 12.51 at 1 mm, 0.78).
#[test]
fn rst_blobness_through_thick_slices() {
    let rst = [
        "--method",
        "rst",
        "--radius-mm",
        "8",
        "--step-mm",
        "0.5",
        "--dmin",
        "10",
        "--dmax",
        "30",
    ];
    let mut b = Vec::new();
    for (name, spacing) in [("iso", "1"), ("thick", "1,1,2")] {
        let input = tmp(&format!("rst-{name}.nii.gz"));
        run(bin()
            .args(["phantom", "sphere", "--spacing-mm", spacing, "--out"])
            .arg(&input));
        let out = tmp(&format!("rst-{name}-features.nii"));
        run(bin()
            .arg("features")
            .arg(&input)
            .args(rst)
            .arg("--out")
            .arg(&out));
        b.push(blobness_at(&out, &load(&input), [0.0, 0.0, 1.0]));
    }
    eprintln!(
        "RST blobness at (0, 0, 1) mm: {:.3} at 1 mm, {:.3} at 1x1x2 mm",
        b[0], b[1]
    );
    assert!(b[0] > 1.0, "no blobness at 1 mm ({})", b[0]);
    assert!(
        (b[1] / b[0] - 1.0).abs() <= 0.1,
        "{} at 1x1x2 mm vs {} at 1 mm",
        b[1],
        b[0]
    );
}

/// Blobness (the third component) of the features file `out` written for `input`, at the voxel
/// nearest to the LPS point `p_mm`.
fn blobness_at(out: &Path, input: &shapecast::Volume, p_mm: [f64; 3]) -> f32 {
    let (dims, values) = read_vector_nifti(out);
    assert_eq!(dims, input.dims);
    let p = input
        .voxel_from_world()
        .transform_point3(glam::DVec3::from(p_mm));
    let c = input.linear_index(
        p.x.round() as usize,
        p.y.round() as usize,
        p.z.round() as usize,
    );
    values[2 * dims[0] * dims[1] * dims[2] + c]
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
    // Uncompressed, so that the test reads all three components (the loader shows the first).
    let out = tmp("eig.nii");
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
    // The eigenvalues themselves: sorted by magnitude at every voxel, and at the sphere's
    // centre three similar negative ones of the size the CPU reference gives there.
    let (dims, l) = read_vector_nifti(&out);
    let n = dims[0] * dims[1] * dims[2];
    for i in 0..n {
        let (a, b, c) = (l[i].abs(), l[n + i].abs(), l[2 * n + i].abs());
        assert!(
            a >= b && b >= c,
            "voxel {i}: {a} {b} {c} not sorted by magnitude"
        );
    }
    let v = load(&input);
    let centre = v.voxel_from_world().transform_point3(glam::DVec3::ZERO);
    let c = v.linear_index(
        centre.x.round() as usize,
        centre.y.round() as usize,
        centre.z.round() as usize,
    );
    let at = [l[c], l[n + c], l[2 * n + c]];
    eprintln!("RST eigenvalues at the sphere's centre: {at:?}");
    assert!(at.iter().all(|&x| x < 0.0), "{at:?}");
    assert!(at[0] / at[2] <= 1.3, "not isotropic: {at:?}");
    assert!(
        (RST_CENTRE_L2_MIN..=RST_CENTRE_L2_MAX).contains(&at[2].abs()),
        "{at:?}"
    );
}

/// |l2| of the RST at the centre of the noisy 10 mm sphere above (10 HU of noise, R = 8 mm,
/// dr = 0.5 mm, 42 rays): 12.05 measured; the bounds allow +-15%.
const RST_CENTRE_L2_MIN: f32 = 10.2;
const RST_CENTRE_L2_MAX: f32 = 13.9;

/// Dims and f32 values (component-major) of an uncompressed NIfTI-1 file written by `features`.
fn read_vector_nifti(path: &Path) -> ([usize; 3], Vec<f32>) {
    let b = std::fs::read(path).expect("output exists");
    let i16_at = |o: usize| i16::from_le_bytes([b[o], b[o + 1]]);
    let dims = [i16_at(42), i16_at(44), i16_at(46)].map(|d| d as usize);
    let offset = f32::from_le_bytes(b[108..112].try_into().expect("4 bytes")) as usize;
    let values = b[offset..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
        .collect();
    (dims, values)
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

/// `findings` on the demo phantom (four spheres beside and between vessels, 200 HU in 0 HU):
/// the spheres are found, each once, with their sizes, ranked in JSON.
#[test]
fn findings_list_the_demo_spheres_once_each_with_their_sizes() {
    let input = tmp("demo-findings.nii.gz");
    run(bin().args(["phantom", "demo", "--out"]).arg(&input));
    let out = bin()
        .arg("findings")
        .arg(&input)
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
        .expect("runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let list = json["findings"].as_array().expect("findings");
    // (centre voxel, radius mm) of the demo's spheres (src/phantom/catalogue.rs).
    let spheres = [
        ([30.0, 40.0, 48.0], 5.0),
        ([62.0, 58.0, 40.0], 4.0),
        ([48.0, 70.0, 66.0], 6.0),
        ([70.0, 30.0, 60.0], 3.0),
    ];
    for (c, r) in spheres {
        let near: Vec<&serde_json::Value> = list
            .iter()
            .filter(|f| {
                let v: Vec<f64> = (0..3)
                    .map(|a| f["voxel"][a].as_f64().expect("a number"))
                    .collect();
                (0..3).map(|a| (v[a] - c[a]).powi(2)).sum::<f64>().sqrt() <= r
            })
            .collect();
        assert_eq!(near.len(), 1, "one finding per sphere at {c:?}: {json}");
        let f = near[0];
        let d = f["diameter_mm"].as_f64().expect("a number");
        assert!(
            (d - 2.0 * r).abs() <= 0.25 * 2.0 * r,
            "sphere r = {r} mm at {c:?}: diameter {d} mm"
        );
        assert!(f["score"].as_f64().expect("a number") > 1.0);
        assert!((f["mean_hu"].as_f64().expect("a number") - 200.0).abs() < 40.0);
    }
    // The four spheres rank above everything else (vessel junctions, cylinder ends).
    for f in list.iter().take(4) {
        let v: Vec<f64> = (0..3)
            .map(|a| f["voxel"][a].as_f64().expect("a number"))
            .collect();
        assert!(
            spheres
                .iter()
                .any(|(c, r)| { (0..3).map(|a| (v[a] - c[a]).powi(2)).sum::<f64>().sqrt() <= *r }),
            "rank {} at {v:?} is not one of the spheres: {json}",
            f["rank"]
        );
    }
    let ranks: Vec<u64> = list
        .iter()
        .map(|f| f["rank"].as_u64().expect("a rank"))
        .collect();
    assert_eq!(ranks, (1..=list.len() as u64).collect::<Vec<_>>());
    // A table without --json, and a method without blobness is refused by name.
    let table = run(bin().arg("findings").arg(&input).args([
        "--preset",
        "lymph-nodes",
        "--method",
        "hessian",
        "--backend",
        "cpu",
    ]));
    assert!(
        table.contains("rank") && table.contains("diam mm"),
        "{table}"
    );
    let out = bin()
        .arg("findings")
        .arg(&input)
        .args(["--method", "frangi", "--backend", "cpu"])
        .output()
        .expect("runs");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("blobness"));
}

/// `findings` on an MR: refused by name before any features are computed (its values are not
/// HU, which every gate reads).
#[test]
fn findings_refuse_an_mr_by_name() {
    let mr = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/dicom/emri_small_RLE.dcm");
    let out = bin()
        .arg("findings")
        .arg(&mr)
        .args(["--method", "hessian", "--backend", "cpu"])
        .output()
        .expect("run shapecast");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("Hounsfield") && err.contains("MR") && err.contains("emri_small_RLE"),
        "{err}"
    );
}
