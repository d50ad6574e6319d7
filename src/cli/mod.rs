//! The `shapecast` command line: subcommands over the library (native only).

use clap::{Parser, Subcommand};

pub mod features;
pub mod info;
pub mod phantom;
pub mod render;
pub mod reproduce;

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
    /// Open the viewer in a native window (the default without a subcommand).
    View,
    /// Print the GPU adapter this machine offers and the limits Shapecast requests from it.
    Gpu,
    /// Write one of the paper's phantoms (anti-aliased, in HU) as NIfTI.
    Phantom(phantom::PhantomArgs),
    /// Compute Hessian, Frangi, structure-tensor or RST features of a volume (CPU reference).
    Features(features::FeaturesArgs),
    /// Print a volume's dimensions, spacing, orientation, intensity range, modality and warnings.
    Info(info::InfoArgs),
    /// Render a shape-encoding MIP to PNG (the viewer's ray caster); --pick PX,PY prints where
    /// a pixel's maximum came from.
    Render(render::RenderArgs),
    /// Reproduce the paper's experiments on the phantoms: Markdown report and PNG plots.
    Reproduce(reproduce::ReproduceArgs),
}

/// Runs a parsed command line; the error is printed by `main` as one line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command.unwrap_or(Command::View) {
        Command::View => crate::app::run_native(),
        Command::Gpu => gpu_info(),
        Command::Phantom(args) => phantom::run(args),
        Command::Features(args) => features::run(args),
        Command::Render(args) => render::run(args),
        Command::Reproduce(args) => reproduce::run(args),
        Command::Info(args) => info::run(&args),
    }
}

fn gpu_info() -> anyhow::Result<()> {
    let ctx = pollster::block_on(crate::gpu::GpuContext::new_headless())?;
    println!("{}", ctx.describe());
    Ok(())
}
