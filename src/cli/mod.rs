//! The `shapecast` command line: subcommands over the library (native only).

use clap::{Parser, Subcommand};

pub mod batch;
pub mod bench;
pub mod dicomweb;
pub mod features;
pub mod findings;
pub mod info;
pub mod phantom;
pub mod render;
pub mod reproduce;
pub mod whole_body;

/// Command-line values of a type that lists itself in `ALL` and names each value with `name()`,
/// so that the command line spells them as the rest of Shapecast does.
macro_rules! value_enum_by_name {
    ($($ty:ty),*) => {$(
        impl clap::ValueEnum for $ty {
            fn value_variants<'a>() -> &'a [Self] {
                &Self::ALL
            }

            fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
                Some(clap::builder::PossibleValue::new(self.name()))
            }
        }
    )*};
}

/// The feature preset named `name`, or an error listing the known ones.
pub fn preset(name: &str) -> anyhow::Result<crate::cpu::Preset> {
    use crate::cpu::Preset;
    Preset::from_name(name).ok_or_else(|| {
        let names: Vec<&str> = Preset::ALL.iter().map(|p| p.name()).collect();
        anyhow::anyhow!("unknown preset {name:?}; known: {}", names.join(", "))
    })
}

value_enum_by_name!(
    crate::cpu::pipeline::Method,
    crate::render::camera::ViewPreset
);

/// Shape-encoding MIPs of CT and MRI: Hessian and radial structure tensor features.
///
/// Run without a subcommand to open the viewer in a window.
#[derive(Parser, Debug)]
#[command(name = "shapecast", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Open the viewer in a native window (the default without a subcommand): on the given files
    /// and folders (a volume, a header with its data file, a DICOM folder), else on the demo CT.
    View(ViewArgs),
    /// Print the GPU adapter this machine offers and the limits Shapecast requests from it.
    Gpu,
    /// Write one of the paper's phantoms (anti-aliased, in HU) as NIfTI.
    Phantom(phantom::PhantomArgs),
    /// Compute Hessian, Frangi, structure-tensor or RST features of a volume (GPU or CPU).
    Features(features::FeaturesArgs),
    /// The ranked findings of a CT: round candidates from the preset's blobness, where the
    /// preset looks (the lung for lung nodules, soft tissue for lymph nodes), as a table or JSON.
    Findings(findings::FindingsArgs),
    /// Time every GPU feature stage against the CPU reference (and scikit-image).
    Bench(bench::BenchArgs),
    /// Print a volume's dimensions, spacing, orientation, intensity range, modality and warnings.
    Info(info::InfoArgs),
    /// The shape MIP and findings of every CT and MR series of a DICOMweb archive (or one shard
    /// of them), stored back into each study; series already done are skipped.
    Batch(batch::BatchArgs),
    /// Render a shape-encoding MIP to PNG (the viewer's ray caster); --pick PX,PY prints where
    /// a pixel's maximum came from.
    Render(render::RenderArgs),
    /// Reproduce the paper's experiments on the phantoms: Markdown report and PNG plots.
    Reproduce(reproduce::ReproduceArgs),
}

#[derive(clap::Args, Debug, Default)]
pub struct ViewArgs {
    /// Files and folders to open (read together as one volume).
    pub paths: Vec<std::path::PathBuf>,
    /// Open a phantom instead: sphere, cylinder, bifurcation, airway, ... (see `phantom`).
    #[arg(long, conflicts_with = "paths")]
    pub phantom: Option<String>,
    /// The display mode to open in: intensity, hessian, rst, li, frangi or gst (the Hessian,
    /// the lighter one, as the page opens).
    #[arg(long, default_value = "hessian")]
    pub method: String,
    /// The feature preset: lymph-nodes, lung-nodules, airways or vessels.
    #[arg(long)]
    pub preset: Option<String>,
    /// A PET of the same patient (file or folder) fused over the CT, read on its own grid.
    #[arg(long)]
    pub pet: Option<std::path::PathBuf>,
    /// GPU memory for the volume textures, MiB (default: 3 GiB on a discrete GPU, 1.5 GiB
    /// otherwise). Over it the features are kept max-pooled at 1/2, 1/4, ... resolution.
    #[arg(long)]
    pub gpu_budget_mib: Option<u64>,
}

fn view(args: ViewArgs) -> anyhow::Result<()> {
    use crate::app::{AppOptions, DisplayMode, StartWith};
    let mode = DisplayMode::from_name(&args.method).ok_or_else(|| {
        anyhow::anyhow!(
            "--method {}: one of intensity, hessian, rst, li, frangi, gst",
            args.method
        )
    })?;
    let preset = match &args.preset {
        Some(p) => Some(crate::cpu::tf::Preset::from_name(p).ok_or_else(|| {
            anyhow::anyhow!("--preset {p}: one of lymph-nodes, lung-nodules, airways, vessels")
        })?),
        None => None,
    };
    let start = match (args.phantom, args.paths.is_empty()) {
        (Some(name), _) => StartWith::Phantom(name),
        (None, true) => StartWith::DemoCt,
        (None, false) => StartWith::Paths(args.paths),
    };
    crate::app::platform::native::run_native(AppOptions {
        start,
        mode,
        preset,
        gpu_budget_mib: args.gpu_budget_mib,
        pet: args.pet.map(|p| vec![p]),
        ..AppOptions::default()
    })
    .map_err(|e| anyhow::anyhow!("could not open the viewer window: {e}"))
}

/// Runs a parsed command line; the error is printed by `main` as one line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command.unwrap_or_else(|| {
        Command::View(ViewArgs {
            method: "hessian".to_owned(),
            ..ViewArgs::default()
        })
    }) {
        Command::View(args) => view(args),
        Command::Gpu => gpu_info(),
        Command::Phantom(args) => phantom::run(args),
        Command::Features(args) => features::run(args),
        Command::Findings(args) => findings::run(args),
        Command::Bench(args) => bench::run(args),
        Command::Render(args) => render::run(args),
        Command::Batch(args) => batch::run(args),
        Command::Reproduce(args) => reproduce::run(args),
        Command::Info(args) => info::run(&args),
    }
}

fn gpu_info() -> anyhow::Result<()> {
    let ctx = pollster::block_on(crate::gpu::GpuContext::new_headless())?;
    println!("{}", ctx.describe());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn view_takes_paths_or_a_phantom() {
        let parse = |args: &[&str]| Cli::try_parse_from(args).map(|c| c.command);
        match parse(&["shapecast", "view", "a.nii.gz", "dicom/"]) {
            Ok(Some(Command::View(v))) => {
                assert_eq!(v.paths.len(), 2);
                assert_eq!(
                    v.method, "hessian",
                    "the viewer opens on the Hessian, as the page does"
                );
            }
            other => panic!("{other:?}"),
        }
        match parse(&["shapecast", "view", "--phantom", "sphere", "--method", "li"]) {
            Ok(Some(Command::View(v))) => {
                assert_eq!(v.phantom.as_deref(), Some("sphere"));
                assert_eq!(v.method, "li");
            }
            other => panic!("{other:?}"),
        }
        assert!(parse(&["shapecast", "view", "--phantom", "sphere", "a.nii"]).is_err());
        assert!(matches!(parse(&["shapecast"]), Ok(None)));
    }
}
