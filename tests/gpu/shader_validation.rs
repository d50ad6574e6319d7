//! Parses and validates every WGSL file (with its imports resolved) with naga, so a broken shader
//! fails on a machine with no GPU at all.

use shapecast::gpu::shaders;

#[test]
fn every_shader_file_is_listed() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
    let mut on_disk: Vec<String> = std::fs::read_dir(&dir)
        .expect("shaders/ is readable")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".wgsl"))
        .collect();
    on_disk.sort();
    let mut listed: Vec<String> = shaders::FILES.iter().map(|(n, _)| n.to_string()).collect();
    listed.sort();
    assert_eq!(
        on_disk, listed,
        "shaders/ and gpu::shaders::FILES must agree"
    );
}

#[test]
fn every_shader_validates() {
    for (name, _) in shaders::FILES {
        let source = shaders::source(name).expect("imports resolve");
        let module = naga::front::wgsl::parse_str(&source)
            .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(&source)));
        let mut validator = naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::all(),
        );
        validator
            .validate(&module)
            .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(&source)));
    }
}

#[test]
fn import_errors_are_reported() {
    assert!(matches!(
        shaders::source("no_such.wgsl"),
        Err(shaders::ShaderSourceError::Unknown(_))
    ));
}
