//! The WGSL sources, embedded with `include_str!` (the wasm build has no file system), and a tiny
//! `#import name.wgsl` resolver in the spirit of rerun's and vello's.

/// `(file name, source)` of each named file in `shaders/`.
macro_rules! shader_files {
    ($($name:literal),* $(,)?) => {
        &[$(($name, include_str!(concat!("../../shaders/", $name)))),*]
    };
}

/// Every shader file in `shaders/`, by file name.
pub const FILES: &[(&str, &str)] = shader_files![
    "common.wgsl",
    "noise_windows.wgsl",
    "rgb9e5.wgsl",
    "feature_stats.wgsl",
    "pack_features.wgsl",
    "pool_features.wgsl",
    "eigen.wgsl",
    "feature_maps.wgsl",
    "gaussian.wgsl",
    "eigen_features.wgsl",
    "structure_tensor.wgsl",
    "resample.wgsl",
    "gradient.wgsl",
    "rst.wgsl",
    "slice.wgsl",
    "raycast.wgsl",
    "raycast_bricks.wgsl",
];

/// Why a shader source could not be assembled.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ShaderSourceError {
    #[error("no shader named {0:?} in shaders/")]
    Unknown(String),
    #[error("shader {0:?} imports itself, directly or indirectly")]
    ImportCycle(String),
}

/// The source of `name` with every `#import other.wgsl` line replaced by that file's source
/// (each file at most once, depth first).
pub fn source(name: &str) -> Result<String, ShaderSourceError> {
    let mut out = String::new();
    let mut done = Vec::new();
    let mut stack = Vec::new();
    append(name, &mut out, &mut done, &mut stack)?;
    Ok(out)
}

fn raw(name: &str) -> Result<&'static str, ShaderSourceError> {
    FILES
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, s)| *s)
        .ok_or_else(|| ShaderSourceError::Unknown(name.to_owned()))
}

fn append<'a>(
    name: &'a str,
    out: &mut String,
    done: &mut Vec<&'a str>,
    stack: &mut Vec<&'a str>,
) -> Result<(), ShaderSourceError> {
    if stack.contains(&name) {
        return Err(ShaderSourceError::ImportCycle(name.to_owned()));
    }
    if done.contains(&name) {
        return Ok(());
    }
    stack.push(name);
    let text = raw(name)?;
    for line in text.lines() {
        if let Some(dep) = line.trim().strip_prefix("#import ") {
            let dep = FILES
                .iter()
                .map(|(n, _)| *n)
                .find(|n| *n == dep.trim())
                .ok_or_else(|| ShaderSourceError::Unknown(dep.trim().to_owned()))?;
            append(dep, out, done, stack)?;
        } else {
            out.push_str(line);
            out.push('\n');
        }
    }
    stack.pop();
    done.push(name);
    Ok(())
}

/// Creates a shader module from an assembled source.
pub fn create_module(
    device: &wgpu::Device,
    name: &str,
) -> Result<wgpu::ShaderModule, ShaderSourceError> {
    let src = source(name)?;
    Ok(device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(name),
        source: wgpu::ShaderSource::Wgsl(src.into()),
    }))
}
