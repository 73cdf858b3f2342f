#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Every WGSL file in shaders/ parses and validates with naga (the compiler wgpu uses), so a
//! shader error is a failing test, not a blank viewport at run time.

use std::path::Path;

#[test]
fn every_wgsl_file_validates() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
    let mut checked = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().and_then(|e| e.to_str()) != Some("wgsl") {
            continue;
        }
        let source = std::fs::read_to_string(&path).unwrap();
        let module = naga::front::wgsl::parse_str(&source)
            .unwrap_or_else(|e| panic!("{}: {}", path.display(), e.emit_to_string(&source)));
        naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::default(),
        )
        .validate(&module)
        .unwrap_or_else(|e| panic!("{}: {}", path.display(), e.emit_to_string(&source)));
        checked += 1;
    }
    assert!(checked >= 1, "no WGSL files in {}", dir.display());
}

#[test]
fn a_broken_shader_is_rejected() {
    // The check above can fail: a type error must not validate.
    let source = "@fragment fn fs_main() -> @location(0) vec4<f32> { return 1.0; }";
    let module = naga::front::wgsl::parse_str(source);
    let rejected = match module {
        Err(_) => true,
        Ok(m) => naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::default(),
        )
        .validate(&m)
        .is_err(),
    };
    assert!(rejected);
}

#[test]
fn overlay_uniforms_are_272_bytes_as_the_app_uploads_them() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders/lidar_overlay.wgsl");
    let source = std::fs::read_to_string(path).unwrap();
    let module = naga::front::wgsl::parse_str(&source).unwrap();
    let span = module
        .types
        .iter()
        .find(|(_, t)| t.name.as_deref() == Some("Uniforms"))
        .map(|(_, t)| t.inner.size(module.to_ctx()))
        .unwrap();
    assert_eq!(span, 272);
}
