//! `shapecast features INPUT --method ... --out OUT.nii.gz`: the CPU reference features of a
//! volume as a float32 NIfTI with the input's geometry and three components (V, A, B, or with
//! `--eigen` the eigenvalues sorted by magnitude).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};

use crate::compute::pipeline::{FeatureJob, JobOptions};
use crate::cpu::pipeline::{self, Method, Request};
use crate::cpu::{FeatureMap, Grid, OpacityRule, TransferFunction};
use crate::gpu::GpuContext;
use crate::io::{self, InputFile};

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum OpacityArg {
    Consistent,
    Paper,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum TfArg {
    /// The preset's transfer function refined by the measured noise.
    Auto,
    /// The preset's transfer function as it is.
    Preset,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum MapArg {
    /// Paper eq. 1.
    Simple,
    /// Paper eq. 2 (Li et al.).
    Li,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum BackendArg {
    /// The GPU where an adapter exists, else the CPU reference.
    Auto,
    /// The CPU reference (src/cpu).
    Cpu,
    /// The WGSL kernels (src/gpu), slab by slab.
    Gpu,
}

#[derive(clap::Args, Debug)]
pub struct FeaturesArgs {
    /// A volume file (NIfTI, NRRD, MetaImage, DICOM) or a folder holding a DICOM series or a
    /// header with its data file.
    #[arg(required_unless_present = "dicomweb", conflicts_with = "dicomweb")]
    pub input: Option<PathBuf>,
    #[command(flatten)]
    pub dicomweb: crate::cli::dicomweb::DicomWebArgs,
    #[arg(long, value_enum)]
    pub method: Method,
    /// Output file (.nii or .nii.gz).
    #[arg(long)]
    pub out: PathBuf,
    /// lymph-nodes, lung-nodules, airways or vessels: transfer function, scales and ray length.
    #[arg(long, default_value = "lymph-nodes")]
    pub preset: String,
    /// Scales in mm (Hessian sigma; neighbourhood scale of the general structure tensor).
    #[arg(long, value_delimiter = ',')]
    pub sigma_mm: Option<Vec<f64>>,
    /// RST ray count: 26, 42, 98, 218 or 386.
    #[arg(long)]
    pub rays: Option<usize>,
    /// RST ray length R, mm.
    #[arg(long)]
    pub radius_mm: Option<f64>,
    /// RST step dr, mm (0.25 by default, one voxel for --opacity paper).
    #[arg(long)]
    pub step_mm: Option<f64>,
    #[arg(long, value_enum, default_value = "consistent")]
    pub opacity: OpacityArg,
    /// Transfer function lower end, HU (with --dmax; overrides the automatic one).
    #[arg(long, requires = "dmax")]
    pub dmin: Option<f64>,
    /// Transfer function upper end, HU.
    #[arg(long, requires = "dmin")]
    pub dmax: Option<f64>,
    #[arg(long, value_enum, default_value = "auto", conflicts_with = "dmin")]
    pub tf: TfArg,
    /// Map of the RST and structure-tensor features.
    #[arg(long, value_enum, default_value = "li")]
    pub map: MapArg,
    /// Gradient scale sigma_g of the RST and the structure tensor, mm.
    #[arg(long, default_value_t = crate::cpu::rst::DEFAULT_SIGMA_G_MM)]
    pub sigma_g_mm: f64,
    /// RST: refine thick slices for the rays (z by ceil(s_z / max(4 dr, finest spacing)), the
    /// opacity lengths from the acquired spacing). Keeps nodules a slice thick (a 9 mm sphere on
    /// 5 mm slices: 0.94 of its thin value, 0.52 without), but vessel junctions a slice thick
    /// answer as strongly: on a 5 mm lung CT the mass ranked 17th among findings instead of 2nd,
    /// and the features took twice as long (docs/science.md, "Thick slices").
    #[arg(long)]
    pub refine_slices: bool,
    /// Frangi's c (default: half the largest Hessian norm of the whole volume, per scale).
    #[arg(long)]
    pub frangi_c: Option<f64>,
    #[arg(long, value_enum, default_value = "auto")]
    pub backend: BackendArg,
    /// Write the three eigenvalues sorted by magnitude instead of V, A, B.
    #[arg(long)]
    pub eigen: bool,
    /// GPU RST: interpolate (I, g) in the shader, bit for bit the CPU twin's, instead of one
    /// hardware-filtered fetch per step (the default; faster, within a tolerance).
    #[arg(long)]
    pub exact_rst: bool,
}

/// Reads a file (with the data file beside a header), or every file of a folder, into loader
/// inputs: the same reader as every subcommand (`crate::cli::info::read_inputs`).
pub fn read_input(path: &Path) -> anyhow::Result<Vec<InputFile>> {
    crate::cli::info::read_inputs(&[path.to_path_buf()])
}

pub fn request(args: &FeaturesArgs) -> anyhow::Result<Request> {
    let method = args.method;
    let preset = crate::cli::preset(&args.preset)?;
    let mut req = Request::new(method);
    req.preset = preset;
    req.sigmas_mm = args.sigma_mm.clone();
    req.rays = args.rays;
    req.radius_mm = args.radius_mm;
    req.step_mm = args.step_mm;
    req.rule = match args.opacity {
        OpacityArg::Consistent => OpacityRule::Consistent,
        OpacityArg::Paper => OpacityRule::Paper,
    };
    req.tf = match (args.dmin, args.dmax, args.tf) {
        (Some(lo), Some(hi), _) => {
            if !(lo >= 0.0 && hi >= lo) {
                bail!("--dmin {lo} --dmax {hi}: need 0 <= dmin <= dmax");
            }
            Some(TransferFunction::new(lo, hi))
        }
        (_, _, TfArg::Preset) => Some(preset.transfer_function()),
        _ => None,
    };
    req.rst_map = match args.map {
        MapArg::Simple => FeatureMap::Simple,
        MapArg::Li => FeatureMap::Li,
    };
    req.eigen = args.eigen;
    req.frangi_c = args.frangi_c;
    req.sigma_g_mm = args.sigma_g_mm;
    req.refine_slices = args.refine_slices;
    Ok(req)
}

/// The GPU context a backend choice asks for: `None` is the CPU reference.
fn backend_context(backend: BackendArg) -> anyhow::Result<Option<GpuContext>> {
    match backend {
        BackendArg::Cpu => Ok(None),
        BackendArg::Gpu => Ok(Some(
            pollster::block_on(GpuContext::new_headless()).context("--backend gpu")?,
        )),
        BackendArg::Auto => match pollster::block_on(GpuContext::new_headless()) {
            Ok(ctx) => Ok(Some(ctx)),
            Err(e) => {
                eprintln!("note: no GPU ({e}); using the CPU reference");
                Ok(None)
            }
        },
    }
}

/// The features of `volume` on the backend asked for (the GPU job, read back, or the CPU
/// reference), with the pipeline's notes and the backend's name.
pub fn compute_components(
    volume: &std::sync::Arc<crate::volume::Volume>,
    req: &Request,
    backend: BackendArg,
    exact_rst: bool,
) -> anyhow::Result<(crate::cpu::Components3, Vec<String>, &'static str)> {
    match backend_context(backend)? {
        Some(ctx) => {
            let options = JobOptions {
                export: true,
                exact_rst,
                ..JobOptions::default()
            };
            let mut job = FeatureJob::shared(&ctx, std::sync::Arc::clone(volume), req, options)?;
            eprintln!(
                "GPU: {} ({} brick{}, halo overhead {:.2})",
                ctx.adapter_label(),
                job.slab_count(),
                if job.slab_count() == 1 { "" } else { "s" },
                job.overhead()
            );
            job.run_blocking(&ctx)?;
            let result = job.finish_result().context("the GPU job did not finish")?;
            let comps = result
                .components
                .context("the GPU job returned no features")?;
            Ok((comps, result.notes, "gpu"))
        }
        None => {
            let outcome = pipeline::compute(&Grid::of(volume), &volume.to_f32(), req)?;
            Ok((outcome.components, outcome.notes, "cpu"))
        }
    }
}

/// The volume of a file or folder, or of an archive's series, its loader's notes and warnings
/// printed; shared with the feature job (one copy of the voxels).
pub fn load_volume(
    input: Option<&std::path::Path>,
    dicomweb: &crate::cli::dicomweb::DicomWebArgs,
) -> anyhow::Result<std::sync::Arc<crate::volume::Volume>> {
    let loaded = match input {
        Some(input) => {
            io::load(&read_input(input)?).with_context(|| format!("loading {}", input.display()))?
        }
        None => dicomweb.load()?,
    };
    Ok(loaded_volume(loaded))
}

/// A loaded volume, its loader's notes and warnings printed.
pub fn loaded_volume(loaded: io::Loaded) -> std::sync::Arc<crate::volume::Volume> {
    for n in &loaded.notes {
        eprintln!("note: {n}");
    }
    let volume = std::sync::Arc::new(loaded.volume);
    for w in &volume.warnings {
        eprintln!("warning: {w}");
    }
    volume
}

pub fn run(args: FeaturesArgs) -> anyhow::Result<()> {
    let req = request(&args)?;
    let volume = load_volume(args.input.as_deref(), &args.dicomweb)?;
    let started = std::time::Instant::now();
    let (components, notes, backend) =
        compute_components(&volume, &req, args.backend, args.exact_rst)?;
    for n in &notes {
        eprintln!("{n}");
    }
    let name = args.out.to_string_lossy().into_owned();
    let channels: Vec<&[f32]> = components.iter().map(|c| c.as_slice()).collect();
    let bytes = io::nifti::write(&name, &volume, &channels, io::nifti::WriteIntent::Vector)?;
    std::fs::write(&args.out, bytes).with_context(|| format!("writing {name}"))?;
    let what = if args.eigen {
        "eigenvalues l0, l1, l2"
    } else {
        "vesselness, airwayness, blobness"
    };
    println!(
        "{:?} ({backend}) on {:?} voxels in {:.1} s -> {name} ({what})",
        args.method,
        volume.dims,
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
