//! The `shapecast` binary: natively the command line (and the viewer window without arguments),
//! on the web the page's entry point.

#[cfg(not(target_arch = "wasm32"))]
fn main() -> std::process::ExitCode {
    use clap::Parser as _;
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    let cli = shapecast::cli::Cli::parse();
    match shapecast::cli::run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("shapecast: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

#[cfg(target_arch = "wasm32")]
fn main() {
    shapecast::web::start();
}
