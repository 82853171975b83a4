use super::super::load_mesh_bytes;
use super::*;

/// A GLB container of `json` and, if not empty, a BIN chunk of `bin` (both padded).
fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
    let mut j = json.as_bytes().to_vec();
    j.resize(j.len().next_multiple_of(4), b' ');
    let mut b = bin.to_vec();
    b.resize(b.len().next_multiple_of(4), 0);
    let total = 12 + 8 + j.len() + if b.is_empty() { 0 } else { 8 + b.len() };
    let mut out = b"glTF".to_vec();
    for word in [2, total as u32, j.len() as u32] {
        out.extend_from_slice(&word.to_le_bytes());
    }
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&j);
    if !b.is_empty() {
        out.extend_from_slice(&(b.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&b);
    }
    out
}

/// Three f32 positions of the triangle (0,0,0), (1,0,0), (0,1,0), then u16 indices 0 1 2.
fn triangle_bin() -> Vec<u8> {
    let mut bin = Vec::new();
    for c in [0f32, 0., 0., 1., 0., 0., 0., 1., 0.] {
        bin.extend_from_slice(&c.to_le_bytes());
    }
    for i in [0u16, 1, 2] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    bin
}

const TRIANGLE: &str = r#"{
    "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
    "nodes": [{"name": "tri", "translation": [1, 2, 3], "children": [1]},
              {"mesh": 0, "scale": [2, 2, 2]}],
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
    "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [1, 0, 0, 1],
                   "roughnessFactor": 0.25, "metallicFactor": 0.5}}],
    "buffers": [{"byteLength": 42}],
    "bufferViews": [{"buffer": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 6}],
    "accessors": [
        {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
         "min": [0, 0, 0], "max": [1, 1, 0]},
        {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}]
}"#;

fn load_glb(json: &str, bin: &[u8]) -> Result<Model, MeshError> {
    load_mesh_bytes(&glb(json, bin), "test.glb")
}

/// `json` with its one buffer given as a data URI of `bin`.
fn with_data_uri(json: &str, bin: &[u8]) -> String {
    let uri = format!(
        r#""uri": "data:application/octet-stream;base64,{}", "byteLength""#,
        BASE64.encode(bin)
    );
    json.replacen(r#""byteLength""#, &uri, 1)
}

#[test]
fn triangle_glb_loads_with_transform_and_material() {
    let model = load_glb(TRIANGLE, &triangle_bin()).unwrap();
    assert_eq!(model.parts.len(), 1, "{:?}", model.warnings);
    let part = &model.parts[0];
    assert_eq!(part.name, "node 1");
    assert_eq!(part.mesh.triangle_count(), 1);
    assert_eq!(part.mesh.indices, [0, 1, 2]);
    assert_eq!(part.mesh.bounds(), Some(([0.0; 3], [1.0, 1.0, 0.0])));
    assert_eq!(part.mesh.normals, vec![[0.0, 0.0, 1.0]; 3]);
    let corner = part.transform.transform_point3(DVec3::new(1.0, 0.0, 0.0));
    assert_eq!(corner, DVec3::new(3.0, 2.0, 3.0));
    let m = part.material;
    assert_eq!(
        (m.base_color, m.roughness, m.metallic),
        ([1.0, 0.0, 0.0, 1.0], 0.25, 0.5)
    );
    assert!(model.warnings.is_empty(), "{:?}", model.warnings);
}

#[test]
fn same_triangle_as_gltf_with_a_data_uri() {
    let json = with_data_uri(TRIANGLE, &triangle_bin());
    let model = load_mesh_bytes(json.as_bytes(), "tri.gltf").unwrap();
    assert_eq!(model.parts[0].mesh.triangle_count(), 1);
}

#[test]
fn gltf_buffer_without_uri_skips_its_primitives() {
    let model = load_mesh(TRIANGLE, "tri.gltf").unwrap();
    assert!(model.parts.is_empty());
    assert!(
        model.warnings[0].contains("buffer 0"),
        "{:?}",
        model.warnings
    );
    let err = load_glb(TRIANGLE, &[]).unwrap_err();
    assert!(matches!(err, MeshError::Malformed { .. }), "{err}");
}

#[test]
fn in_memory_gltf_cannot_name_files() {
    let json = TRIANGLE.replacen(
        r#""byteLength": 42"#,
        r#""uri": "tri.bin", "byteLength": 42"#,
        1,
    );
    let err = load_mesh_bytes(json.as_bytes(), "tri.gltf").unwrap_err();
    assert!(matches!(err, MeshError::Unsupported { .. }), "{err}");
    let json = json.replace("tri.bin", "https://example.com/tri.bin");
    let err = load_mesh(&json, "x.gltf");
    assert!(matches!(err, Err(MeshError::Unsupported { .. })));
}

fn load_mesh(json: &str, name: &str) -> Result<Model, MeshError> {
    load_mesh_bytes(json.as_bytes(), name)
}

#[test]
fn broken_containers_are_typed_errors() {
    let good = glb(TRIANGLE, &triangle_bin());
    let mut bad_magic = good.clone();
    bad_magic[0] = b'g' ^ 0x20;
    let truncated = &good[..good.len() - 10];
    let mut long_chunk = good.clone();
    long_chunk[12..16].copy_from_slice(&10_000u32.to_le_bytes());
    for (bytes, what) in [
        (&bad_magic[..], "magic"),
        (truncated, "truncated"),
        (&long_chunk, "chunk"),
        (&good[..5], "header"),
    ] {
        let err = load_mesh_bytes(bytes, "broken.glb").unwrap_err();
        assert!(
            matches!(err, MeshError::Malformed { format: "GLB", .. }),
            "{what}: {err}"
        );
    }
    let mut extra = good;
    extra.extend_from_slice(b"junk");
    let model = load_mesh_bytes(&extra, "extra.glb").unwrap();
    assert_eq!(model.warnings.len(), 1);
}

#[test]
fn accessor_past_its_view_and_short_buffer_are_refused() {
    let json = TRIANGLE.replace(
        r#""count": 3, "type": "VEC3""#,
        r#""count": 300000000, "type": "VEC3""#,
    );
    let err = load_glb(&json, &triangle_bin()).unwrap_err();
    assert!(
        matches!(
            err,
            MeshError::BufferTooShort {
                needed: 3_600_000_000,
                ..
            }
        ),
        "{err}"
    );
    let err = load_glb(TRIANGLE, &triangle_bin()[..20]).unwrap_err();
    assert!(
        matches!(
            err,
            MeshError::BufferTooShort {
                needed: 42,
                available: 20,
                ..
            }
        ),
        "{err}"
    );
}

#[test]
fn index_out_of_range_is_an_error() {
    let mut bin = triangle_bin();
    bin[40] = 9;
    let err = load_glb(TRIANGLE, &bin).unwrap_err();
    assert!(
        matches!(
            err,
            MeshError::IndexOutOfRange {
                index: 9,
                len: 3,
                ..
            }
        ),
        "{err}"
    );
    let json = TRIANGLE.replace(r#""POSITION": 0"#, r#""POSITION": 7"#);
    let err = load_glb(&json, &triangle_bin()).unwrap_err();
    assert!(
        matches!(err, MeshError::IndexOutOfRange { index: 7, .. }),
        "{err}"
    );
}

#[test]
fn nan_position_is_an_error() {
    let mut bin = triangle_bin();
    bin[12..16].copy_from_slice(&f32::NAN.to_le_bytes());
    let err = load_glb(TRIANGLE, &bin).unwrap_err();
    assert!(matches!(err, MeshError::NonFinite { .. }), "{err}");
}

#[test]
fn cyclic_and_deep_node_graphs_are_errors() {
    let cycle = r#"{"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}],
        "nodes": [{"children": [1]}, {"children": [0]}]}"#;
    let err = load_mesh(cycle, "cycle.gltf").unwrap_err();
    assert!(matches!(err, MeshError::NodeCycle { .. }), "{err}");
    let sceneless =
        r#"{"asset": {"version": "2.0"}, "nodes": [{}, {"children": [2]}, {"children": [1]}]}"#;
    let err = load_mesh(sceneless, "cycle.gltf").unwrap_err();
    assert!(matches!(err, MeshError::NodeCycle { node: 1, .. }), "{err}");
    let chain: Vec<String> = (1..=70)
        .map(|i| format!(r#"{{"children": [{i}]}}"#))
        .collect();
    let deep = format!(
        r#"{{"asset": {{"version": "2.0"}}, "scenes": [{{"nodes": [0]}}], "nodes": [{}, {{}}]}}"#,
        chain.join(",")
    );
    let err = load_mesh(&deep, "deep.gltf").unwrap_err();
    assert!(
        matches!(err, MeshError::NodeTooDeep { node: 64, .. }),
        "{err}"
    );
}

#[test]
fn no_meshes_is_an_empty_model() {
    let model = load_mesh(
        r#"{"asset": {"version": "2.0"}, "nodes": [{}]}"#,
        "empty.gltf",
    )
    .unwrap();
    assert!(model.parts.is_empty() && model.warnings.is_empty());
}

#[test]
fn sparse_positions_are_substituted() {
    // The triangle's positions, with vertex 2 replaced by (5, 6, 7) through a sparse block
    // appended to the buffer: index u8 2 (padded to 4 bytes), then the value.
    let mut bin = triangle_bin();
    bin.extend_from_slice(&[0, 0, 2, 0, 0, 0]);
    for c in [5f32, 6., 7.] {
        bin.extend_from_slice(&c.to_le_bytes());
    }
    let json = TRIANGLE
        .replace(r#""byteLength": 42}"#, r#""byteLength": 60}"#)
        .replace(
            r#"{"buffer": 0, "byteOffset": 36, "byteLength": 6}"#,
            r#"{"buffer": 0, "byteOffset": 36, "byteLength": 6},
               {"buffer": 0, "byteOffset": 44, "byteLength": 1},
               {"buffer": 0, "byteOffset": 48, "byteLength": 12}"#,
        )
        .replace(
            r#""max": [1, 1, 0]}"#,
            r#""max": [5, 6, 7], "sparse": {"count": 1,
               "indices": {"bufferView": 2, "componentType": 5121},
               "values": {"bufferView": 3}}}"#,
        );
    let model = load_glb(&json, &bin).unwrap();
    let positions = &model.parts[0].mesh.positions;
    assert_eq!(
        positions,
        &[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [5.0, 6.0, 7.0]]
    );
    let out_of_range = json.replace(r#""count": 1,"#, r#""count": 1, "x": 0,"#);
    let mut bad = bin.clone();
    bad[44] = 3;
    let err = load_glb(&out_of_range, &bad).unwrap_err();
    assert!(
        matches!(
            err,
            MeshError::IndexOutOfRange {
                index: 3,
                len: 3,
                ..
            }
        ),
        "{err}"
    );
}

#[test]
fn quantized_strip_without_indices() {
    // Four normalized i16 vertices of a unit square (8 bytes a vertex with padding), as a
    // triangle strip: two triangles, both facing +z.
    let mut bin = Vec::new();
    for [x, y] in [[0i16, 0], [32767, 0], [0, 32767], [32767, 32767]] {
        for c in [x, y, 0, 0] {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    let json = r#"{"asset": {"version": "2.0"}, "extensionsRequired": ["KHR_mesh_quantization"],
        "extensionsUsed": ["KHR_mesh_quantization"], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "mode": 5}]}],
        "buffers": [{"byteLength": 32}],
        "bufferViews": [{"buffer": 0, "byteLength": 32, "byteStride": 8}],
        "accessors": [{"bufferView": 0, "componentType": 5122, "normalized": true,
            "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [32767, 32767, 0]}]}"#;
    let model = load_glb(json, &bin).unwrap();
    let mesh = &model.parts[0].mesh;
    assert_eq!(mesh.indices, [0, 1, 2, 1, 3, 2]);
    assert_eq!(mesh.bounds(), Some(([0.0; 3], [1.0, 1.0, 0.0])));
    assert!(mesh.normals.iter().all(|n| *n == [0.0, 0.0, 1.0]));
    assert_eq!(
        triangle_list(Mode::TriangleFan, vec![0, 1, 2, 3]).0,
        [1, 2, 0, 2, 3, 0]
    );
}

#[test]
fn lines_are_skipped_with_a_warning_and_unknown_required_extensions_refused() {
    let lines = TRIANGLE.replace(r#""indices": 1,"#, r#""indices": 1, "mode": 1,"#);
    let model = load_glb(&lines, &triangle_bin()).unwrap();
    assert!(model.parts.is_empty());
    assert_eq!(model.warnings.len(), 1, "{:?}", model.warnings);
    let draco = TRIANGLE.replacen(
        "{",
        r#"{"extensionsRequired": ["KHR_draco_mesh_compression"],"#,
        1,
    );
    let err = load_glb(&draco, &triangle_bin()).unwrap_err();
    assert!(matches!(err, MeshError::Unsupported { .. }), "{err}");
}

#[test]
fn integers_written_as_floats_are_accepted() {
    let json = TRIANGLE.replace(r#""bufferView": 1,"#, r#""bufferView": 1.0e0,"#);
    assert!(load_glb(&json, &triangle_bin()).is_ok());
    let bad = TRIANGLE.replace(r#""bufferView": 1,"#, r#""bufferView": 1.5,"#);
    assert!(matches!(
        load_glb(&bad, &triangle_bin()),
        Err(MeshError::Malformed { .. })
    ));
}

#[test]
fn uri_helpers() {
    assert_eq!(
        percent_decode("a%20b%2Fc.bin").as_deref(),
        Some("a b/c.bin")
    );
    assert_eq!(percent_decode("bad%2"), None);
    assert_eq!(percent_decode("bad%+1x"), None);
    let origin = Origin::embedded("x.gltf");
    assert_eq!(
        decode_data_uri("application/gltf-buffer;base64,AAEC", "b", &origin).unwrap(),
        [0, 1, 2]
    );
    assert_eq!(
        decode_data_uri(";base64,AAE", "b", &origin).unwrap(),
        [0, 1]
    );
    assert!(matches!(
        decode_data_uri("text/plain,hello", "b", &origin),
        Err(MeshError::Unsupported { .. })
    ));
    assert!(matches!(
        decode_data_uri(";base64,!!", "b", &origin),
        Err(MeshError::Malformed { .. })
    ));
}

#[test]
fn matrix_layout_pads_columns() {
    let layout = Layout {
        data_type: DataType::U8,
        dims: Dimensions::Mat3,
        normalized: false,
    };
    assert_eq!(layout.element_size(), 12);
    let bytes = [1u8, 2, 3, 0, 4, 5, 6, 0, 7, 8, 9, 0];
    let mut out = [0f32; 9];
    layout.decode(&bytes, &mut out, |v| v as f32).unwrap();
    assert_eq!(out, [1., 2., 3., 4., 5., 6., 7., 8., 9.]);
    assert_eq!(extent(4, 12, 0, 12), 4);
    assert_eq!(extent(0, usize::MAX, 3, 12), u64::MAX);
}
