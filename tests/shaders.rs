//! Every WGSL file in `shaders/` parses and validates with naga, with no GPU involved (those
//! that use the shared footprint with `footprint.wgsl` before them, and the tile passes with
//! the splat pass too, as the renderer builds them).

#[test]
fn every_shader_parses_and_validates() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
    let mut checked = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "wgsl") {
            continue;
        }
        let mut source = std::fs::read_to_string(&path).unwrap();
        // A shader that calls the shared footprint has it prepended, as the renderer does.
        // The tile passes share the splat pass's uniforms and helpers too, as the renderer
        // builds them.
        if path.ends_with("tiles.wgsl") {
            source = std::fs::read_to_string(dir.join("splat.wgsl")).unwrap() + &source;
        }
        if source.contains("footprint(") && !path.ends_with("footprint.wgsl") {
            source = std::fs::read_to_string(dir.join("footprint.wgsl")).unwrap() + &source;
        }
        let module = naga::front::wgsl::parse_str(&source)
            .unwrap_or_else(|e| panic!("{}: {}", path.display(), e.emit_to_string(&source)));
        naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::empty(),
        )
        .validate(&module)
        .unwrap_or_else(|e| panic!("{}: {}", path.display(), e.emit_to_string(&source)));
        checked += 1;
    }
    assert!(checked >= 2, "found {checked} shaders in {}", dir.display());
}
