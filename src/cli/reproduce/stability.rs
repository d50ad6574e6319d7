//! Report sections of `reproduce`: smoothness and invariance of the two opacity rules, cost,
//! and the scikit-image comparison.

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use super::experiments as ex;
use super::plot::{self, Series};
use super::table;
use crate::cpu::{self, OpacityRule};
use crate::phantom::{self, NODULE_RADIUS_MM};

pub fn section_stability(md: &mut String, dir: &Path) -> anyhow::Result<()> {
    let _ = writeln!(
        md,
        "## Smoothness and invariance: consistent rule vs the paper's literal rule\n"
    );
    let rules = [
        ("consistent", OpacityRule::Consistent),
        ("paper rule", OpacityRule::Paper),
    ];
    let radii: Vec<f64> = (0..=10).map(|n| 4.5 + 0.1 * n as f64).collect();
    let mut series = Vec::new();
    let mut rows = Vec::new();
    for (name, rule) in rules {
        let b: Vec<f64> = radii
            .iter()
            .enumerate()
            .map(|(n, &r)| {
                let off = [
                    0.05 * (n % 5) as f64,
                    0.07 * (n % 3) as f64,
                    0.11 * (n % 4) as f64,
                ];
                ex::sphere_blob(r, 100.0, [0.5; 3], off, rule, None)
            })
            .collect();
        let (m, s) = ex::mean_sd(&b);
        series.push(Series::new(
            name,
            radii
                .iter()
                .zip(&b)
                .map(|(r, x)| (*r, x / m, 0.0))
                .collect(),
        ));
        let iso = ex::sphere_blob(5.0, 100.0, [0.5; 3], [0.0; 3], rule, None);
        let spacing: Vec<f64> = [[0.6, 0.6, 1.2], [0.7, 0.7, 2.5], [1.0; 3]]
            .iter()
            .map(|sp| ex::sphere_blob(5.0, 100.0, *sp, [0.0; 3], rule, None) / iso)
            .collect();
        let dr = match rule {
            OpacityRule::Consistent => 0.25,
            OpacityRule::Paper => 0.5,
        };
        let half = ex::sphere_blob(5.0, 100.0, [0.5; 3], [0.1, 0.2, 0.05], rule, Some(dr / 2.0))
            / ex::sphere_blob(5.0, 100.0, [0.5; 3], [0.1, 0.2, 0.05], rule, Some(dr));
        let contrast: Vec<f64> = [50.0, 100.0, 200.0, 400.0]
            .iter()
            .map(|c| ex::sphere_blob(5.0, *c, [0.5; 3], [0.0; 3], rule, None))
            .collect();
        let orient = ex::cylinder_vesselness([1.0, 1.0, 1.0], rule)
            / ex::cylinder_vesselness([0.0, 0.0, 1.0], rule);
        rows.push(vec![
            name.to_owned(),
            format!("{:.4}", s / m),
            list(&spacing, 3),
            format!("{half:.3}"),
            list(&contrast, 2),
            format!("{orient:.3}"),
        ]);
    }
    let _ = writeln!(
        md,
        "Sphere r = 4.5..5.5 mm in 0.1 mm steps with sub-voxel offsets (CV of the blobness); the r = 5 mm sphere at 0.6x0.6x1.2, 0.7x0.7x2.5 and 1.0 mm iso relative to 0.5 mm iso; halving dr (0.25 -> 0.125 mm consistent, 0.5 -> 0.25 mm paper); blobness at 50, 100, 200, 400 HU contrast; vesselness of a cylinder along (1,1,1) relative to along z.\n"
    );
    table(
        md,
        &[
            "rule",
            "CV over radius",
            "spacing ratios",
            "dr halved ratio",
            "blobness vs contrast (HU)",
            "orientation ratio",
        ],
        &rows,
    );
    plot::line_plot(
        &dir.join("radius_sweep.png"),
        "Blobness vs sphere radius (relative to its mean)",
        "radius (mm)",
        "blobness / mean",
        &series,
    )?;
    let _ = writeln!(md, "![radius sweep](reproduction/radius_sweep.png)\n");
    Ok(())
}

pub fn section_timing(md: &mut String) {
    // A 24^3 crop around a nodule at 0.5 mm: the cost per voxel is what extrapolates.
    let mut p = phantom::sphere(NODULE_RADIUS_MM, 100.0);
    p.min_mm = [-6.0; 3];
    p.max_mm = [5.5; 3];
    let s = ex::Scene::new(p, [0.5; 3]);
    let n = s.grid.len();
    let t = Instant::now();
    let _ = cpu::rst_features(&s.gv, &ex::consistent(), cpu::FeatureMap::Li);
    let rst_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let _ = cpu::hessian_features_multiscale(
        &s.grid,
        &s.values,
        &[2.0],
        cpu::features::HessianMethod::Map(cpu::FeatureMap::Simple),
    );
    let hes_s = t.elapsed().as_secs_f64();
    let big = 512.0 * 512.0 * 541.0;
    let _ = writeln!(md, "## Cost (section 4.3)\n");
    let _ = writeln!(
        md,
        "CPU reference on this machine ({} threads), {n} voxels: RST features {rst_s:.2} s ({:.1} us/voxel), one-scale Hessian features at sigma 2 mm {hes_s:.2} s. Extrapolated to the paper's 512 x 512 x 541 CT: RST {:.0} s, Hessian {:.0} s per scale (the paper: 20 s and 5 s in CUDA on a 2010 GPU). The CPU reference is the definition, not the fast path. The WGSL kernels compute the same features; on this machine they run on lavapipe, Vulkan on the same 2 CPU cores, so their timings measure the kernels' efficiency, not a GPU's speed: `shapecast bench` measured 2.5e7 RST ray samples/s there against the CPU reference's 1.5e7, and the 5-scale Hessian features at 1.6 M voxels/s (4.9x the CPU reference); docs/performance.md has the runs and an estimate for a current desktop GPU (RST about 5-15 s for the paper's CT with the exact fetch, 1-3 s with hardware filtering).\n",
        std::thread::available_parallelism().map_or(1, |n| n.get()),
        rst_s / n as f64 * 1e6,
        rst_s / n as f64 * big,
        hes_s / n as f64 * big
    );
}

pub fn section_skimage(md: &mut String, dir: &Path) {
    let _ = writeln!(md, "## Hessian against scikit-image on a real CT\n");
    match std::fs::read_to_string(dir.join("hessian_vs_skimage.md")) {
        Ok(text) => md.push_str(&text),
        Err(_) => {
            let _ = writeln!(
                md,
                "Not run here: `python3 scripts/hessian_vs_skimage.py --out {}` writes the comparison, which the next `reproduce` includes.\n",
                dir.display()
            );
        }
    }
}

/// Thick slices (docs/science.md): the refinement rule, and one physical sphere's RST blobness
/// through the pipeline users run at thin, thick and very thick slices.
pub fn section_thick_slices(md: &mut String, dir: &Path) {
    use crate::cpu::pipeline::{Method, Request, compute};
    let _ = writeln!(md, "## Thick slices: the refinement rule\n");
    let _ = writeln!(
        md,
        "The Hessian refines an axis by the integer ceil(spacing / sigma_min) when its spacing exceeds the smallest sigma; input voxels stay grid points and the features are taken back there by subsampling (never interpolated). The RST runs on the input grid unless asked (`--refine-slices`, the consistent rule): then it refines the slice axis z by ceil(s_z / max(4 dr, s_min)) (at most 8; 5 at 0.6 x 0.6 x 5 mm and dr 0.25 mm, 3 at 0.7 x 0.7 x 2.5 mm), linearly between the acquired slices, before its smoothing and gradient; its opacity lengths L_i come from the acquired spacing, since refinement adds no sharpness, and it is evaluated at the input voxels only. It is not the default because on a real 5 mm lung CT it lets slice-thick vessel junctions outrank the mass (docs/science.md, \"Thick slices\"). Blobness (eq. 1, |l2|) at the centre voxel of one sphere, r = 4.7 mm, 100 HU, through `cpu::pipeline::compute` (42 rays, R = 8 mm, TF 10/30 HU):\n"
    );
    let mut req = Request::new(Method::Rst);
    req.tf = Some(crate::cpu::TransferFunction::PAPER_CT);
    req.rst_map = cpu::FeatureMap::Simple;
    req.rays = Some(42);
    req.radius_mm = Some(8.0);
    let mut rows = Vec::new();
    let mut b = Vec::new();
    let mut unrefined = Vec::new();
    for spacing in [[0.5; 3], [0.7, 0.7, 2.5], [0.9; 3], [0.6, 0.6, 5.0]] {
        let p = phantom::sphere(4.7, 100.0).boxed_on_grid([9.0, 9.0, 15.0], spacing);
        let volume = p.render(spacing);
        let grid = cpu::Grid::of(&volume);
        let c = grid.nearest_voxel(p.grid_mm([0.0; 3]));
        let mut row = vec![format!("{spacing:?}")];
        for refine in [false, true] {
            let req = Request {
                refine_slices: refine,
                ..req.clone()
            };
            let Ok(out) = compute(&grid, &volume.to_f32(), &req) else {
                row.push("-".to_owned());
                continue;
            };
            let v = f64::from(out.components[2][grid.index(c[0], c[1], c[2])]);
            if refine { &mut b } else { &mut unrefined }.push(v);
            row.push(format!("{v:.3}"));
        }
        rows.push(row);
    }
    table(
        md,
        &["spacing (mm)", "RST blobness", "with --refine-slices"],
        &rows,
    );
    if b.len() == 4 && unrefined.len() == 4 {
        let three = &b[..3];
        let lo = three.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = three.iter().copied().fold(0.0, f64::max);
        let _ = writeln!(
            md,
            "\nWith --refine-slices, spread (max / min) over 0.5, 0.7 x 0.7 x 2.5 and 0.9 mm: {:.3} (the issue asks <= 1.10). At 5 mm slices the sphere lies in one slice and its neighbours' partial volume, and keeps {:.2} of the thin value ({:.2} on the input grid; tests/cpu/rst_invariance.rs and tests/cpu/thick_slices.rs bound it from below).\n",
            hi / lo,
            b[3] / b[0],
            unrefined[3] / unrefined[0]
        );
    }
    thick_slice_refinement(md);
    thick_slice_rays(md);
    thick_slice_independent(md, dir);
    eigen_order_on_thick_slices(md);
}

/// The Hessian's `--eigen` output where z is refined: sorted by magnitude at every input voxel,
/// since features are taken back by subsampling, not by interpolating eigenvalues.
fn eigen_order_on_thick_slices(md: &mut String) {
    use crate::cpu::pipeline::{Method, Request, compute};
    let p = phantom::sphere(4.7, 100.0).boxed_on_grid([9.0, 9.0, 15.0], [0.6, 0.6, 5.0]);
    let volume = p.render([0.6, 0.6, 5.0]);
    let grid = cpu::Grid::of(&volume);
    let mut req = Request::new(Method::Hessian);
    req.eigen = true;
    let resolved = req.resolve(&grid);
    let factors = resolved.as_ref().map_or([1; 3], |r| r.factors);
    let sigmas = resolved.map_or_else(|_| "?".to_owned(), |r| format!("{:?}", r.sigmas_mm));
    let Ok(out) = compute(&grid, &volume.to_f32(), &req) else {
        return;
    };
    let [l0, l1, l2] = &out.components;
    let unsorted = (0..grid.len())
        .filter(|&i| !(l0[i].abs() >= l1[i].abs() && l1[i].abs() >= l2[i].abs()))
        .count();
    let _ = writeln!(
        md,
        "`features --method hessian --eigen` on that sphere at 0.6 x 0.6 x 5 mm (the lymph-node preset's sigma {sigmas} mm, those below half the slice spacing dropped; z refined by {}): {unsorted} of {} voxels not sorted by magnitude (tests/gpu/real_ct.rs checks the same on the three real CTs, on CPU and GPU).\n",
        factors[2],
        grid.len()
    );
}

/// Spheres of a few sizes at the four spacings, here and in an independent implementation
/// (`dir`/rst_independent.json, from scripts/rst_independent.py): centred on a grid point and
/// half a slice off, with that script's cubic-reading experiment beside them.
fn thick_slice_independent(md: &mut String, dir: &Path) {
    let path = dir.join("rst_independent.json");
    let json = super::read_json(&path);
    let Some(spheres) = json.as_ref().and_then(|j| j["spheres"].as_array()) else {
        let _ = writeln!(
            md,
            "The independent implementation was not run here: `python3 scripts/rst_independent.py --out {}` writes its numbers, which the next `reproduce` includes.\n",
            path.display()
        );
        return;
    };
    let num = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    let triple = |v: &serde_json::Value| -> [f64; 3] { std::array::from_fn(|a| num(&v[a])) };
    let mut rows = Vec::new();
    // The largest relative difference to the independent numbers (NaN when one is missing),
    // and per sphere what 5 mm slices keep of the thin value (centred, between slices).
    let mut worst = 0.0f64;
    let mut compared = 0usize;
    let mut radii = Vec::new();
    let mut kept_5mm = Vec::new();
    for sphere in spheres {
        let radius = num(&sphere["radius_mm"]);
        radii.push(format!("{radius}"));
        let params = cpu::RstParams {
            radius_mm: sphere["ray_mm"].as_f64().unwrap_or(8.0),
            ..ex::consistent()
        };
        let rows_of = sphere["rows"].as_array().map(Vec::as_slice).unwrap_or(&[]);
        let thin = |key: &str| rows_of.first().map_or(f64::NAN, |r| num(&r[key]));
        let (thin_b, thin_between, thin_cubic) = (
            thin("blobness"),
            thin("between_slices"),
            thin("cubic_experiment"),
        );
        for row in rows_of {
            let spacing = triple(&row["spacing_mm"]);
            let half = triple(&row["half_extent_mm"]);
            // A phantom of the script's box: a few hundred voxels a side at most.
            let plausible = (0..3).all(|a| {
                spacing[a].is_finite()
                    && spacing[a] >= 0.1
                    && half[a].is_finite()
                    && (0.0..=100.0).contains(&half[a])
            });
            if !plausible {
                worst = f64::NAN;
                continue;
            }
            // On the input grid (the definition both implement), or refined as --refine-slices
            // refines it.
            let ours = |dz: f64, refine: bool| {
                let mut p = phantom::sphere(radius, 100.0).shifted([0.0, 0.0, dz]);
                p.min_mm = half.map(|h| -h);
                p.max_mm = half;
                let volume = p.render(spacing);
                let grid = cpu::Grid::of(&volume);
                let f = if refine {
                    cpu::rst_refinement_factors(&grid, params.step_mm)
                } else {
                    [1; 3]
                };
                let gv = cpu::GradientVolume::refined(&grid, &volume.to_f32(), 0.7, f);
                ex::blob(cpu::rst_eigen_at(&gv, p.grid_mm([0.0, 0.0, dz]), &params))
            };
            let (centred, between) = (ours(0.0, false), ours(0.5 * spacing[2], false));
            let (refined, refined_between) = (ours(0.0, true), ours(0.5 * spacing[2], true));
            let (theirs, theirs_between) = (num(&row["blobness"]), num(&row["between_slices"]));
            let cubic = num(&row["cubic_experiment"]);
            compared += 2;
            for d in [centred / theirs - 1.0, between / theirs_between - 1.0] {
                worst = if d.is_nan() || worst.is_nan() {
                    f64::NAN
                } else {
                    worst.max(d.abs())
                };
            }
            if spacing[2] >= 5.0 {
                kept_5mm.push(format!(
                    "{:.2} / {:.2} on the input grid and {:.2} / {:.2} refined (r {radius} mm)",
                    centred / thin_b,
                    between / thin_between,
                    refined / thin_b,
                    refined_between / thin_between
                ));
            }
            rows.push(vec![
                format!("{radius}"),
                format!("{spacing:?}"),
                format!("{centred:.3} ({:.2})", centred / thin_b),
                format!("{theirs:.3}"),
                format!("{between:.3} ({:.2})", between / thin_between),
                format!("{theirs_between:.3}"),
                format!("{cubic:.3} ({:.2})", cubic / thin_cubic),
                format!("{refined:.3} ({:.2})", refined / thin_b),
                format!(
                    "{refined_between:.3} ({:.2})",
                    refined_between / thin_between
                ),
            ]);
        }
    }
    let _ = writeln!(
        md,
        "The same in an independent implementation of SCIENCE.md's consistent rule (`scripts/rst_independent.py`: numpy and scipy, its own partial-volume spheres, scipy's smoothing, `np.gradient`, `map_coordinates`), for spheres of radius {} mm (R = max(8, r + 5) mm): blobness at the sphere's centre, a grid point, and with the centre half a slice along z, between two slices (evaluated exactly there); relative to 0.5 mm iso in brackets. The cubic column is an experiment outside SCIENCE.md (centred): rays read a cubic B-spline of the smoothed intensity and its exact gradient, rho keeping only the slices' partial-volume box. The last two columns are Shapecast with z refined as `--refine-slices` refines it (L_i from the acquired spacing), centred and between slices.\n",
        radii.join(", ")
    );
    table(
        md,
        &[
            "radius (mm)",
            "spacing (mm)",
            "Shapecast, centred",
            "independent",
            "Shapecast, between slices",
            "independent",
            "cubic reading (experiment)",
            "refined, centred",
            "refined, between",
        ],
        &rows,
    );
    let agreement = if compared == 0 || worst.is_nan() {
        "The independent numbers cannot be compared (none, or one is missing or out of range)."
            .to_owned()
    } else if worst <= 0.01 {
        format!(
            "Shapecast and the independent implementation agree within {:.2}% at all {compared} points, every sphere, spacing and position (tests/cpu/rst_invariance.rs checks 1%), so the input grid's thick-slice loss is the definition's reading and not this code's.",
            100.0 * worst
        )
    } else {
        format!(
            "Shapecast and the independent implementation DISAGREE: the largest relative difference is {worst:.4}."
        )
    };
    let _ = writeln!(md, "\n{agreement}");
    if !kept_5mm.is_empty() {
        let _ = writeln!(
            md,
            "At 5 mm slices the spheres keep {} of their thin-slice blobness (centred / between slices): on the input grid the loss grows as the sphere shrinks against the slice and depends on where the centre falls; refined, r >= 4.7 mm keeps >= 0.85 wherever it falls, and r = 3 mm (0.6 of the slice) is still a blob (three negative eigenvalues) whose value depends on the position. The cubic reading lifts some sizes and lowers others (between slices it aliases).",
            kept_5mm.join(", ")
        );
    }
    md.push('\n');
}

/// The refinement experiment, corrected (issue 33): the r = 4.7 mm sphere on 0.6 x 0.6 x 5 mm,
/// centre on a slice and between slices, z refined by f with L_i from the acquired spacing (the
/// rule) and from the refined spacing (the earlier experiment, which concluded that refinement
/// makes it worse), relative to 0.5 mm iso.
fn thick_slice_refinement(md: &mut String) {
    let mut params = ex::consistent();
    params.radius_mm = 9.7;
    let blob_at = |spacing: [f64; 3], dz: f64, f: usize, l_from_refined: bool| {
        let mut p = phantom::sphere(4.7, 100.0).shifted([0.0, 0.0, dz]);
        let half = 18.0;
        let half_z = (half / spacing[2]).ceil() * spacing[2];
        p.min_mm = [-half, -half, -half_z];
        p.max_mm = [half, half, half_z];
        let volume = p.render(spacing);
        let grid = cpu::Grid::of(&volume);
        let mut gv = cpu::GradientVolume::refined(&grid, &volume.to_f32(), 0.7, [1, 1, f]);
        if l_from_refined {
            gv.acquired = gv.grid;
        }
        ex::blob(cpu::rst_eigen_at(&gv, p.grid_mm([0.0, 0.0, dz]), &params))
    };
    let thin = [
        blob_at([0.5; 3], 0.0, 1, false),
        blob_at([0.5; 3], 0.25, 1, false),
    ];
    let mut rows = Vec::new();
    for f in [1, 2, 3, 4, 5, 8] {
        let mut row = vec![format!("{f}")];
        for l_from_refined in [false, true] {
            for (i, dz) in [0.0, 2.5].into_iter().enumerate() {
                let b = blob_at([0.6, 0.6, 5.0], dz, f, l_from_refined);
                row.push(format!("{:.3}", b / thin[i]));
            }
        }
        rows.push(row);
    }
    let _ = writeln!(
        md,
        "The refinement, one thing varied at a time: the same sphere (R = 9.7 mm) at 0.6 x 0.6 x 5 mm, z refined by f before the smoothing, blobness relative to 0.5 mm iso (centre on a slice / between slices), with L_i from the acquired spacing (the rule) and from the refined spacing. An earlier version of this page refined with L_i from the refined spacing, found 7.43, 6.80, 6.05 for f = 2, 4, 8 against 6.53, and concluded that refinement makes the RST worse; the loss came from the shorter L_i (a refined grid is not a sharper acquisition), not from the refinement:\n"
    );
    table(
        md,
        &[
            "f",
            "L_i acquired, centred",
            "between",
            "L_i refined, centred",
            "between",
        ],
        &rows,
    );
    md.push('\n');
}

/// Why the 5 mm slices halve the sphere's blobness: each ray's radial contribution
/// `r . L_i sum (alpha_k - alpha_{k-1}) g` (the consistent rule's ray, `cpu::consistent_ray`) and
/// where it stops, at 0.5 mm iso and 0.6 x 0.6 x 5 mm; the z profile of the smoothed intensity;
/// and the blobness for longer rays.
fn thick_slice_rays(md: &mut String) {
    let scene = |spacing: [f64; 3]| {
        let p = phantom::sphere(4.7, 100.0).boxed_on_grid([9.0, 9.0, 15.0], spacing);
        let volume = p.render(spacing);
        let grid = cpu::Grid::of(&volume);
        let x = p.grid_mm([0.0; 3]);
        (cpu::GradientVolume::new(&grid, &volume.to_f32(), 0.7), x)
    };
    let mut params = ex::consistent();
    params.radius_mm = 8.0;
    let (thin, x_thin) = scene([0.5; 3]);
    let (thick, x_thick) = scene([0.6, 0.6, 5.0]);
    // The same 5 mm slices refined for the rays as `--refine-slices` refines them.
    let refined = {
        let p = phantom::sphere(4.7, 100.0).boxed_on_grid([9.0, 9.0, 15.0], [0.6, 0.6, 5.0]);
        let volume = p.render([0.6, 0.6, 5.0]);
        let grid = cpu::Grid::of(&volume);
        let f = cpu::rst_refinement_factors(&grid, params.step_mm);
        cpu::GradientVolume::refined(&grid, &volume.to_f32(), 0.7, f)
    };
    let s3 = 1.0 / 3f64.sqrt();
    let s2 = 1.0 / 2f64.sqrt();
    let mut rows = Vec::new();
    for (name, r) in [
        ("x (in-plane)", [1.0, 0.0, 0.0]),
        ("45 degrees from z", [s2, 0.0, s2]),
        ("diagonal (1,1,1)", [s3, s3, s3]),
        ("z (across slices)", [0.0, 0.0, 1.0]),
    ] {
        let ray = |gv: &cpu::GradientVolume, x: [f64; 3]| {
            let (acc, steps, _) = cpu::consistent_ray(gv, x, gv.sample(x), r, &params);
            (
                -(0..3).map(|a| acc[a] * r[a]).sum::<f64>(),
                steps as f64 * params.step_mm,
                cpu::rst::opacity_length_mm(&gv.acquired, gv.sigma_g_mm, r),
            )
        };
        let (c0, l0, o0) = ray(&thin, x_thin);
        let (c1, l1, o1) = ray(&thick, x_thick);
        let (c2, l2, _) = ray(&refined, x_thick);
        rows.push(vec![
            name.to_owned(),
            format!("{c0:.2} ({o0:.2} mm, stops at {l0:.2} mm)"),
            format!("{c1:.2} ({o1:.2} mm, stops at {l1:.2} mm)"),
            format!("{:.2}", c1 / c0),
            format!("{c2:.2} (stops at {l2:.2} mm)"),
            format!("{:.2}", c2 / c0),
        ]);
    }
    let _ = writeln!(
        md,
        "Where the 5 mm loss came from: the radial contribution of single rays from the sphere's centre (R = 8 mm, TF 10/30 HU), with the ray's opacity length L_i and where it stops, on the input grid and with z refined for the rays (the same L_i):\n"
    );
    table(
        md,
        &[
            "ray",
            "0.5 mm iso: contribution (L_i)",
            "0.6 x 0.6 x 5 mm, input grid",
            "ratio",
            "5 mm, z refined",
            "ratio",
        ],
        &rows,
    );
    let profile = |gv: &cpu::GradientVolume, x: [f64; 3]| {
        (0..=5)
            .map(|k| format!("{:.0}", gv.sample([x[0], x[1], x[2] + 2.0 * k as f64]).0))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let g_max = |gv: &cpu::GradientVolume, x: [f64; 3], a: usize| {
        (0..=40)
            .map(|k| {
                let mut p = x;
                p[a] += 0.25 * k as f64;
                -gv.sample(p).1[a]
            })
            .fold(0.0, f64::max)
    };
    let longer: Vec<String> = [15.0, 25.0]
        .iter()
        .map(|&radius| {
            let q = cpu::RstParams {
                radius_mm: radius,
                ..params.clone()
            };
            format!(
                "{:.3}",
                ex::blob(cpu::rst_eigen_at(&thick, x_thick, &q))
                    / ex::blob(cpu::rst_eigen_at(&thin, x_thin, &q))
            )
        })
        .collect();
    let _ = writeln!(
        md,
        "In-plane rays keep their contribution; rays with a z component lose part of it (table). The data hold less: the smoothed intensity along z from the centre, every 2 mm, is {} HU at 0.5 mm iso and {} HU at 5 mm slices (the sphere, 9.4 mm across, is one slice and two partial-volume neighbours, so trilinear sampling sees a 10 mm ramp), and the largest z gradient is {:.1} against {:.1} HU/mm in-plane (thin: {:.1}). The consistent rule weights a ray by L_i times the gradient where its opacity builds up: along z that gradient is {:.2} of the in-plane one, and the longer L_i of a z ray (from the spacing term of rho) makes up only part of it; an oblique ray meets the sharp in-plane edge, whose gradient has little z component; and Ts_zz, which the blobness (the smallest eigenvalue) is here, sums the rays' z components. Longer rays do not help (relative blobness at R = 15 and 25 mm on the input grid: {}), nor would a larger sigma_g along z (it only blurs the ramp). What helps is the reading: on the refined slices the central difference spans 2 mm instead of 10, the z gradient at the sphere's edge is the acquired ramp's own, and every ray keeps most of its contribution (last columns).\n",
        profile(&thin, x_thin),
        profile(&thick, x_thick),
        g_max(&thick, x_thick, 2),
        g_max(&thick, x_thick, 0),
        g_max(&thin, x_thin, 2),
        g_max(&thick, x_thick, 2) / g_max(&thick, x_thick, 0),
        longer.join(", ")
    );
}

/// `values` with `decimals` digits after the point, comma-separated.
fn list(values: &[f64], decimals: usize) -> String {
    values
        .iter()
        .map(|x| format!("{x:.decimals$}"))
        .collect::<Vec<_>>()
        .join(", ")
}
