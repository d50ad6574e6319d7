//! `shapecast phantom NAME --out FILE.nii.gz`: writes one of the paper's phantoms as NIfTI.

use std::path::PathBuf;

use anyhow::{Context, bail};

use crate::phantom::{self, Phantom};

#[derive(clap::Args, Debug)]
pub struct PhantomArgs {
    /// sphere, dark-sphere, cylinder, slab, sphere-cylinder, sphere-string,
    /// bifurcation-nodules-far, bifurcation-nodules-near, bifurcation, airway, fig8-sphere, demo.
    pub name: String,
    /// Output file (.nii or .nii.gz).
    #[arg(long)]
    pub out: PathBuf,
    /// Voxel spacing in mm: one value (isotropic) or X,Y,Z.
    #[arg(long, value_delimiter = ',', default_value = "0.5")]
    pub spacing_mm: Vec<f64>,
    /// Standard deviation of added Gaussian noise, HU (fig8-sphere defaults to 20).
    #[arg(long)]
    pub noise_hu: Option<f64>,
    /// Seed of the noise generator (same seed, same volume, on every platform).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Surface gap between nodules and vessels for the adjacency phantoms, mm.
    #[arg(long)]
    pub gap_mm: Option<f64>,
}

/// Parses one or three spacings (all > 0).
pub fn spacing3(v: &[f64]) -> anyhow::Result<[f64; 3]> {
    let s = match v {
        [x] => [*x; 3],
        [x, y, z] => [*x, *y, *z],
        _ => bail!(
            "--spacing-mm takes one value or three (X,Y,Z), got {}",
            v.len()
        ),
    };
    if s.iter().any(|x| !(x.is_finite() && *x > 0.0)) {
        bail!("spacings must be positive, got {s:?}");
    }
    Ok(s)
}

pub fn run(args: PhantomArgs) -> anyhow::Result<()> {
    let volume = if args.name == "demo" {
        phantom::demo()
    } else {
        let p = Phantom::by_name(&args.name, args.gap_mm).with_context(|| {
            format!(
                "unknown phantom {:?}; known: {}, {}",
                args.name,
                phantom::NAMES.join(", "),
                phantom::EXTRA_NAMES.join(", ")
            )
        })?;
        let spacing = spacing3(&args.spacing_mm)?;
        let noise = args.noise_hu.unwrap_or(p.default_noise_hu);
        if !(noise.is_finite() && noise >= 0.0) {
            bail!("--noise-hu must be >= 0");
        }
        p.render_noisy(spacing, noise, args.seed)
    };
    let name = args.out.to_string_lossy().into_owned();
    let bytes = crate::io::nifti::write_volume(&name, &volume)?;
    std::fs::write(&args.out, bytes).with_context(|| format!("writing {name}"))?;
    println!(
        "{}: {:?} voxels at {:?} mm -> {name}",
        volume.source, volume.dims, volume.spacing_mm
    );
    Ok(())
}
