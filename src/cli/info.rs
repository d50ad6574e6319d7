//! `shapecast info PATH... [--json]`: what a volume file, a header + data pair or a DICOM folder
//! holds (dimensions, spacing, orientation, intensity range, modality, warnings).

use std::path::PathBuf;

use crate::io::{self, InputFile, Loaded};
use crate::volume::orientation_label;

/// Arguments of `shapecast info`.
#[derive(clap::Args, Debug)]
pub struct InfoArgs {
    /// Files and folders (folders are read recursively, e.g. a DICOM series). A header and its
    /// data file (.hdr/.img, .nhdr/.raw.gz, .mhd/.raw) are given together.
    #[arg(required_unless_present = "dicomweb", conflicts_with = "dicomweb")]
    pub paths: Vec<PathBuf>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub dicomweb: crate::cli::dicomweb::DicomWebArgs,
}

/// Reads files and (recursively) folders into `InputFile`s named by their path, sorted by name
/// within each folder so that the output does not depend on directory order (see
/// `crate::files`: regular files only, what is skipped is said on stderr). A zip archive is
/// replaced by the files it holds, as the viewer does (`io::zip::expand`).
pub fn read_inputs(paths: &[PathBuf]) -> anyhow::Result<Vec<InputFile>> {
    let (files, skipped) = crate::files::read_all(paths)?;
    for s in &skipped {
        eprintln!("warning: {s}");
    }
    let none_found = || {
        anyhow::anyhow!(
            "no files found in {}",
            paths
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        )
    };
    if files.is_empty() {
        return Err(none_found());
    }
    let (files, unpacked) = match io::zip::expand(files, &io::Limits::default()) {
        Ok(r) => r,
        Err(io::LoadError::NoFiles) => return Err(none_found()),
        Err(e) => return Err(e.into()),
    };
    for n in &unpacked {
        eprintln!("note: {n}");
    }
    Ok(files)
}

/// Runs `shapecast info`.
pub fn run(args: &InfoArgs) -> anyhow::Result<()> {
    let loaded = if args.dicomweb.is_set() {
        args.dicomweb.load()?
    } else {
        io::load(&read_inputs(&args.paths)?)?
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&to_json(&loaded))?);
    } else {
        print!("{}", to_text(&loaded));
    }
    Ok(())
}

/// The row-major 3x3 direction matrix (LPS; column c is the direction of voxel axis c).
fn direction_rows(loaded: &Loaded) -> [[f64; 3]; 3] {
    let d = loaded.volume.direction;
    // `+ 0.0` turns -0.0 (from RAS->LPS flips) into 0.0 for the reader.
    std::array::from_fn(|r| std::array::from_fn(|c| d.col(c)[r] + 0.0))
}

fn to_json(loaded: &Loaded) -> serde_json::Value {
    let v = &loaded.volume;
    let range = v.value_range();
    let axes: Vec<String> = (0..3)
        .map(|c| orientation_label(v.direction.col(c)))
        .collect();
    serde_json::json!({
        "source": v.source,
        "dims": v.dims,
        "spacing_mm": v.spacing_mm,
        "origin_mm": v.origin_mm.map(|x| x + 0.0),
        "direction": direction_rows(loaded),
        "orientation": axes,
        "voxel_type": v.voxels.type_name(),
        "modality": v.modality.as_str(),
        "unit": v.unit(),
        "min": range.map(|r| r.0),
        "max": range.map(|r| r.1),
        "suv": suv_json(v, range),
        "warnings": v.warnings,
        "notes": loaded.notes,
    })
}

/// A PET's SUV: the factor (SUVbw per unit of the rescaled stored value), the largest SUV and
/// the rule that gave the factor; null for other volumes and for a PET without a factor (its
/// warning says why).
fn suv_json(v: &crate::volume::Volume, range: Option<(f32, f32)>) -> serde_json::Value {
    match v
        .pet
        .as_ref()
        .and_then(|p| p.suv_factor.map(|f| (f, &p.rule)))
    {
        Some((factor, rule)) => serde_json::json!({
            "factor": factor,
            "max": range.map(|r| r.1),
            "rule": rule,
            "units": v.pet.as_ref().map(|p| p.units.as_str()),
        }),
        None => serde_json::Value::Null,
    }
}

fn to_text(loaded: &Loaded) -> String {
    use std::fmt::Write as _;
    let v = &loaded.volume;
    let mut s = String::new();
    let _ = writeln!(s, "source:      {}", v.source);
    let _ = writeln!(
        s,
        "dims:        {} x {} x {} ({})",
        v.dims[0],
        v.dims[1],
        v.dims[2],
        v.voxels.type_name()
    );
    let _ = writeln!(
        s,
        "spacing_mm:  {} x {} x {}",
        fmt_num(v.spacing_mm[0]),
        fmt_num(v.spacing_mm[1]),
        fmt_num(v.spacing_mm[2])
    );
    let _ = writeln!(
        s,
        "origin_mm:   ({}, {}, {}) LPS",
        fmt_num(v.origin_mm[0]),
        fmt_num(v.origin_mm[1]),
        fmt_num(v.origin_mm[2])
    );
    let labels: Vec<String> = (0..3)
        .map(|c| orientation_label(v.direction.col(c)))
        .collect();
    let _ = writeln!(
        s,
        "orientation: i -> {}, j -> {}, k -> {}",
        labels[0], labels[1], labels[2]
    );
    for (r, row) in direction_rows(loaded).iter().enumerate() {
        let head = if r == 0 {
            "direction:  "
        } else {
            "            "
        };
        let _ = writeln!(
            s,
            "{head} [{:>9.6} {:>9.6} {:>9.6}]",
            row[0], row[1], row[2]
        );
    }
    match v.value_range() {
        Some((lo, hi)) => {
            let unit = match v.unit() {
                "" => String::new(),
                u => format!(" {u}"),
            };
            let _ = writeln!(s, "intensity:   {lo} .. {hi}{unit}");
        }
        None => {
            let _ = writeln!(s, "intensity:   (no finite values)");
        }
    }
    let _ = writeln!(s, "modality:    {}", v.modality.as_str());
    if let Some(p) = &v.pet {
        match p.suv_factor {
            Some(f) => {
                let _ = writeln!(
                    s,
                    "suv:         factor {f:.6e} per {} ({})",
                    p.units, p.rule
                );
            }
            None => {
                let _ = writeln!(s, "suv:         none ({})", p.rule);
            }
        }
    }
    for w in &v.warnings {
        let _ = writeln!(s, "warning:     {w}");
    }
    for n in &loaded.notes {
        let _ = writeln!(s, "note:        {n}");
    }
    s
}

/// A number with at most 6 decimals and no trailing zeros.
fn fmt_num(x: f64) -> String {
    let s = format!("{x:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".to_owned()
    } else {
        s.to_owned()
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests {
    use super::*;
    use crate::volume::Volume;

    #[test]
    fn json_has_the_documented_keys() {
        let loaded = Loaded {
            volume: Volume::from_f32([2, 1, 1], [0.5, 1.0, 2.0], vec![-3.0, 4.0]),
            notes: Vec::new(),
            patient: None,
        };
        let j = to_json(&loaded);
        for key in [
            "dims",
            "spacing_mm",
            "origin_mm",
            "direction",
            "modality",
            "min",
            "max",
            "warnings",
        ] {
            assert!(j.get(key).is_some(), "{key}");
        }
        assert_eq!(j["min"], -3.0);
        assert_eq!(j["direction"][1][1], 1.0);
        let text = to_text(&loaded);
        assert!(text.contains("0.5 x 1 x 2"), "{text}");
        assert!(text.contains("i -> L, j -> P, k -> S"), "{text}");
    }
}
