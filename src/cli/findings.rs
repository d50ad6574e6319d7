//! `shapecast findings INPUT --preset P [--json]`: the ranked candidates of a CT
//! ([`crate::cpu::findings`], the code behind the app's findings panel), as a table or JSON.

use std::path::PathBuf;

use anyhow::{Context, bail};
use serde_json::json;

use crate::cli::features::{BackendArg, compute_components, load_volume, read_input};
use crate::cpu::findings::{self, Findings, SHOWN};
use crate::cpu::hot_spots::{self, CtShape, HotSpots};
use crate::cpu::pipeline::{Method, Request};
use crate::cpu::{FeatureMap, Grid};
use crate::io;
use crate::volume::{Modality, Volume};

#[derive(clap::Args, Debug)]
pub struct FindingsArgs {
    /// A CT: a volume file or a folder holding a DICOM series.
    #[arg(required_unless_present = "dicomweb", conflicts_with = "dicomweb")]
    pub input: Option<PathBuf>,
    #[command(flatten)]
    pub dicomweb: crate::cli::dicomweb::DicomWebArgs,
    /// lung-nodules (in or against the lung), lymph-nodes (soft tissue in the body), airways or
    /// vessels (anywhere in the body).
    #[arg(long, default_value = "lung-nodules")]
    pub preset: String,
    /// The blobness read: rst (its Li map, as the viewer computes it; the paper's method, and
    /// the one that ranks real lesions first: docs/science.md, "Findings"), hessian (eq. 1) or
    /// li (the Hessian's eq. 2 map).
    #[arg(long, default_value = "rst")]
    pub method: Method,
    /// A PET of the same patient (a file or a series folder): its hot spots are listed too,
    /// each with the CT's shape there ("round on CT" or not), and each CT finding gets the
    /// SUVpeak at its peak.
    #[arg(long)]
    pub pet: Option<PathBuf>,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    /// List every candidate, not only the first 30.
    #[arg(long)]
    pub all: bool,
    #[arg(long, value_enum, default_value = "auto")]
    pub backend: BackendArg,
    /// Store the findings listed (the first 30, or all with --all) back into the --dicomweb
    /// archive as a DICOM Structured Report (TID 1500 measurement report, each candidate a
    /// "Finding" group at its 3D point) in the source study, with the same credentials.
    #[arg(long, requires = "dicomweb")]
    pub store: bool,
    /// RST: refine thick slices for the rays (as `features --refine-slices`; on the lung CTs
    /// measured it ranked the lesion lower: docs/science.md, "Thick slices").
    #[arg(long)]
    pub refine_slices: bool,
}

/// The request whose blobness the findings read (the RST's Li map, as the viewer's).
pub fn request(method: Method, preset: crate::cpu::Preset) -> anyhow::Result<Request> {
    match method {
        Method::Hessian | Method::Li | Method::Rst => {}
        other => bail!(
            "--method {}: findings read blobness, which hessian and rst have",
            other.name()
        ),
    }
    let mut req = Request::new(method);
    req.preset = preset;
    req.rst_map = FeatureMap::Li;
    Ok(req)
}

pub fn run(args: FindingsArgs) -> anyhow::Result<()> {
    let preset = crate::cli::preset(&args.preset)?;
    let mut req = request(args.method, preset)?;
    req.refine_slices = args.refine_slices;
    let (volume, archive) = if args.store {
        let (loaded, archive) = args.dicomweb.open()?;
        (crate::cli::features::loaded_volume(loaded), Some(archive))
    } else {
        (load_volume(args.input.as_deref(), &args.dicomweb)?, None)
    };
    // Findings' gates read HU (lung air, soft tissue, dense above 700 HU): an MR or a PET has
    // none, and its list would be noise. (A file that does not say, such as a NIfTI, is taken
    // at its word: its values may well be HU.)
    if matches!(volume.modality, Modality::Mr | Modality::Pt) {
        anyhow::bail!(
            "{}: findings read Hounsfield units and this volume is {} ({}), not a CT; give the CT (a PET goes with it as --pet)",
            volume.source,
            volume.modality.as_str(),
            if volume.unit().is_empty() {
                "no known unit".to_string()
            } else {
                format!("values in {}", volume.unit())
            }
        );
    }
    // The PET first: a wrong path or unit fails before the features' minutes.
    let pet = match &args.pet {
        Some(path) => Some(load_pet(path)?),
        None => None,
    };
    let started = std::time::Instant::now();
    let (components, notes, backend) = compute_components(&volume, &req, args.backend, false)?;
    for n in &notes {
        eprintln!("{n}");
    }
    let features_s = started.elapsed().as_secs_f64();
    let started = std::time::Instant::now();
    let grid = Grid::of(&volume);
    let hu = volume.to_f32();
    let found = findings::find(&grid, &hu, &components[2], preset)?;
    let findings_s = started.elapsed().as_secs_f64();
    let shown = if args.all {
        found.findings.len()
    } else {
        SHOWN
    };
    let pet = pet.map(|pet| {
        let started = std::time::Instant::now();
        let spots = hot_spots::hot_spots(
            &pet,
            Some(&CtShape {
                ct: &volume,
                blobness: &components[2],
                reference: findings::reference(
                    &grid,
                    &hu,
                    &components[2],
                    findings::Gate::SoftTissue,
                ),
            }),
        );
        (pet, spots, started.elapsed().as_secs_f64())
    });
    if args.json {
        let mut out = to_json(&volume, &found, shown);
        if let Some((pet, spots, seconds)) = &pet {
            add_pet_json(&mut out, &volume, &found, pet, spots, args.all);
            out["seconds_hot_spots"] = json!(seconds);
        }
        out["method"] = json!(args.method.name());
        out["preset"] = json!(preset.name());
        out["backend"] = json!(backend);
        out["seconds"] = json!({"features": features_s, "findings": findings_s});
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        print!("{}", table(&volume, &found, shown));
        if let Some((pet, spots, _)) = &pet {
            print!("{}", hot_spot_table(pet, spots, args.all));
        }
        println!(
            "{} {} blobness ({backend}): features {features_s:.1} s, findings {findings_s:.2} s",
            preset.name(),
            args.method.name()
        );
    }
    if let Some(archive) = &archive {
        let groups = report_groups(&volume, &found.findings, preset, shown);
        if groups.is_empty() {
            eprintln!("no findings: nothing stored");
        } else {
            let n = groups.len();
            let report = crate::io::dicomweb::sr::Report {
                description: format!(
                    "findings, {} {} ({n} candidates)",
                    args.method.name().to_uppercase(),
                    preset.name()
                ),
                groups,
                stable_key: None,
            };
            archive.store_report(&report)?;
        }
    }
    Ok(())
}

/// The first `shown` findings as a report's groups ("candidate N", each at its peak).
pub fn report_groups(
    volume: &Volume,
    list: &[findings::Finding],
    preset: crate::cpu::Preset,
    shown: usize,
) -> Vec<crate::io::dicomweb::sr::Group> {
    let world = volume.world_from_voxel();
    list.iter()
        .take(shown)
        .map(|f| {
            let p = world.transform_point3(glam::DVec3::from(f.voxel.map(|v| v as f64)));
            crate::app::report::finding_group(
                format!("candidate {}", f.rank),
                f,
                p,
                preset,
                volume.modality == Modality::Ct,
            )
        })
        .collect()
}

/// The findings as JSON: `{"findings": [{rank, lps_mm, voxel, score, ...}], "more": N, ...}`,
/// the first `shown` of them listed.
pub fn to_json(volume: &Volume, found: &Findings, shown: usize) -> serde_json::Value {
    let world = volume.world_from_voxel();
    let list: Vec<serde_json::Value> = found
        .findings
        .iter()
        .take(shown)
        .map(|f| {
            let p = world.transform_point3(glam::DVec3::from(f.voxel.map(|v| v as f64)));
            json!({
                "rank": f.rank,
                "lps_mm": [round2(p.x), round2(p.y), round2(p.z)],
                "voxel": f.voxel,
                "score": round2(f.score),
                "feature": f.feature,
                "diameter_mm": round2(f.diameter_mm),
                "volume_ml": (f.volume_ml * 1000.0).round() / 1000.0,
                "mean_hu": round2(f.mean_hu),
                "max_hu": round2(f.max_hu),
                "bounded": f.bounded,
                "merged": f.merged,
            })
        })
        .collect();
    json!({
        "findings": list,
        "more": found.findings.len().saturating_sub(shown),
        "reference": found.reference,
        "gate": found.gate.describe(),
        "transfer_function_hu": [found.tf.d_min, found.tf.d_max],
        "noise_hu": found.noise_hu,
        "dropped": {"outside": found.outside, "dense": found.dense, "cut": found.cut, "small": found.small},
    })
}

/// The PET of `--pet`, in SUV (hot spots are cut in SUV: a PET in another unit is refused by
/// name).
fn load_pet(path: &std::path::Path) -> anyhow::Result<Volume> {
    let loaded = io::load(&read_input(path)?)
        .with_context(|| format!("loading the PET {}", path.display()))?;
    for n in &loaded.notes {
        eprintln!("note: PET: {n}");
    }
    let pet = loaded.volume;
    if pet.unit() != "SUV" {
        bail!(
            "--pet {}: its values are in {} (modality {}), not SUV: hot spots are cut in SUV (docs/science.md, \"PET hot spots\")",
            path.display(),
            if pet.unit().is_empty() {
                "no known unit"
            } else {
                pet.unit()
            },
            pet.modality.as_str()
        );
    }
    Ok(pet)
}

/// Adds the PET's part to the findings' JSON: each listed CT finding's `suv_peak` (the 1 cm³
/// sphere at its peak; `null` outside the PET) and `"pet": {reference, hot_spots, more}`, the
/// first [`SHOWN`] hot spots unless `all`.
pub fn add_pet_json(
    out: &mut serde_json::Value,
    ct: &Volume,
    found: &Findings,
    pet: &Volume,
    spots: &HotSpots,
    all: bool,
) {
    let shown = if all { spots.spots.len() } else { SHOWN };
    let world = ct.world_from_voxel();
    if let Some(list) = out["findings"].as_array_mut() {
        for (entry, f) in list.iter_mut().zip(&found.findings) {
            let p = world.transform_point3(glam::DVec3::from(f.voxel.map(|v| v as f64)));
            entry["suv_peak"] =
                json!(hot_spots::sphere_mean(pet, p, hot_spots::PEAK_SPHERE_RADIUS_MM).map(round2));
        }
    }
    let r = &spots.reference;
    let list: Vec<serde_json::Value> = spots
        .spots
        .iter()
        .take(shown)
        .map(|h| {
            json!({
                "rank": h.rank,
                "lps_mm": [round2(h.lps_mm.x), round2(h.lps_mm.y), round2(h.lps_mm.z)],
                "pet_voxel": h.pet_voxel,
                "suv_max": round2(h.suv_max),
                "suv_peak": round2(h.suv_peak),
                "volume_ml": round2(h.volume_ml),
                "ct_blobness": h.ct_blobness,
                "ct_score": h.ct_score.map(round2),
                "ct_round": h.ct_round(),
            })
        })
        .collect();
    out["pet"] = json!({
        "unit": pet.unit(),
        "reference": {
            "rule": r.rule(),
            "threshold_suv": round2(r.threshold),
            "liver": r.liver.map(|(p, mean, sd)| json!({
                "lps_mm": [round2(p.x), round2(p.y), round2(p.z)],
                "mean": round2(mean),
                "sd": round2(sd),
            })),
        },
        "hot_spots": list,
        "more": spots.spots.len().saturating_sub(shown),
    });
}

/// The PET's hot spots as a table, the first [`SHOWN`] of them unless `all`.
pub fn hot_spot_table(pet: &Volume, spots: &HotSpots, all: bool) -> String {
    let shown = if all { spots.spots.len() } else { SHOWN };
    let mut out = format!(
        "\nPET hot spots ({}; {}):\n{:>4} {:>8} {:>8} {:>26} {:>8} {:>9} {}\n",
        pet.unit(),
        spots.reference.rule(),
        "rank",
        "SUVpeak",
        "SUVmax",
        "LPS mm",
        "vol ml",
        "CT score",
        "CT shape"
    );
    for h in spots.spots.iter().take(shown) {
        out += &format!(
            "{:>4} {:>8.2} {:>8.2} {:>26} {:>8.1} {:>9} {}\n",
            h.rank,
            h.suv_peak,
            h.suv_max,
            format!("{:.1}, {:.1}, {:.1}", h.lps_mm.x, h.lps_mm.y, h.lps_mm.z),
            h.volume_ml,
            h.ct_score.map_or("-".to_owned(), |s| format!("{s:.2}")),
            h.ct_shape()
        );
    }
    let more = spots.spots.len().saturating_sub(shown);
    if more > 0 {
        out += &format!("... {more} more (--all lists them)\n");
    }
    out
}

fn round2(v: f64) -> f64 {
    (v * 100.0).round() / 100.0
}

/// The findings as a table, the first `shown` of them.
pub fn table(volume: &Volume, found: &Findings, shown: usize) -> String {
    let world = volume.world_from_voxel();
    let mut out = format!(
        "{:>4} {:>7} {:>26} {:>16} {:>8} {:>9} {:>8} {:>8}\n",
        "rank", "score", "LPS mm", "voxel", "diam mm", "vol ml", "mean HU", "max HU"
    );
    for f in found.findings.iter().take(shown) {
        let p = world.transform_point3(glam::DVec3::from(f.voxel.map(|v| v as f64)));
        out += &format!(
            "{:>4} {:>7.2} {:>26} {:>16} {:>7.1}{} {:>9.3} {:>8.0} {:>8.0}\n",
            f.rank,
            f.score,
            format!("{:.1}, {:.1}, {:.1}", p.x, p.y, p.z),
            format!("{}, {}, {}", f.voxel[0], f.voxel[1], f.voxel[2]),
            f.diameter_mm,
            if f.bounded { "+" } else { " " },
            f.volume_ml,
            f.mean_hu,
            f.max_hu,
        );
    }
    let more = found.findings.len().saturating_sub(shown);
    if more > 0 {
        out += &format!("... {more} more (--all lists them)\n");
    }
    out += &format!(
        "{} finding(s) {}; score 1 = the blobness's 99.9th percentile there ({:.3}); dropped: {} outside, {} dense (mean above {} HU), {} cut by the volume's edge, {} smaller than {} mm; + = reached the ray length\n",
        found.findings.len(),
        found.gate.describe(),
        found.reference,
        found.outside,
        found.dense,
        findings::DENSE_ABOVE_HU,
        found.cut,
        found.small,
        findings::SMALLEST_MM
    );
    out
}
