//! Wavefront OBJ with MTL material libraries, through `tobj`.
//!
//! Polygons are triangulated and every vertex gets one index (`single_index`), so positions and
//! normals line up. A material library that is missing or unreadable is not an error: its
//! materials fall back to [`Material::default`] and [`Model::warnings`] says so. The diffuse
//! colour `Kd` (with the dissolve `d` as alpha) becomes the base colour; the PBR extension
//! parameters `Pr` and `Pm`, when present, give roughness and metalness.

use std::cell::RefCell;
use std::path::Path;

use glam::DMat4;

use super::{CpuMesh, Material, MeshError, MeshPart, Model, Origin};

/// Loads an OBJ file held in `bytes`; material libraries are looked up next to the file.
pub(super) fn load(bytes: &[u8], origin: &Origin) -> Result<Model, MeshError> {
    let warnings = RefCell::new(Vec::new());
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    let mut reader = bytes;
    let (models, materials) = tobj::load_obj_buf(&mut reader, &options, |lib| {
        load_mtl(lib, origin, &warnings)
    })
    .map_err(|e| origin.malformed("OBJ", e.to_string()))?;
    let mut warnings = warnings.into_inner();
    // tobj reports a failed library only when no library loaded; load_mtl has warned already.
    let materials = materials.unwrap_or_default();
    let mut parts = Vec::with_capacity(models.len());
    for (index, model) in models.into_iter().enumerate() {
        let name = if model.name.trim().is_empty() {
            format!("object{index}")
        } else {
            model.name
        };
        match to_cpu_mesh(&model.mesh, &name, origin)? {
            Some(mesh) => {
                let material = material_of(&model.mesh, &materials);
                parts.push(MeshPart {
                    name,
                    transform: DMat4::IDENTITY,
                    mesh,
                    material,
                });
            }
            None => warnings.push(format!("object {name:?} has no faces and was skipped")),
        }
    }
    if parts.is_empty() {
        warnings.push("the OBJ file holds no triangles".to_owned());
    }
    Ok(Model { parts, warnings })
}

/// tobj's material loader: reads the library `lib` named by an `mtllib` line from the OBJ's
/// directory. `mtllib a.mtl b.mtl` names two libraries, which tobj passes as one name; when no
/// file has the whole name, each word is tried as a library of its own.
fn load_mtl(lib: &Path, origin: &Origin, warnings: &RefCell<Vec<String>>) -> tobj::MTLLoadResult {
    let warn = |text: String| warnings.borrow_mut().push(text);
    let Some(dir) = &origin.dir else {
        warn(format!(
            "material library {lib:?} not loaded: in-memory input has no directory; default materials used"
        ));
        return Err(tobj::LoadError::OpenFileFailed);
    };
    let whole = dir.join(lib);
    let text = lib.to_string_lossy();
    let names: Vec<&str> = if whole.is_file() || !text.contains(char::is_whitespace) {
        vec![text.as_ref()]
    } else {
        text.split_whitespace().collect()
    };
    let mut merged = None;
    for name in names {
        let parsed = super::resolve_beside(dir, name)
            .and_then(|path| super::read_file(&path).map_err(|e| e.to_string()))
            .and_then(|bytes| tobj::load_mtl_buf(&mut bytes.as_slice()).map_err(|e| e.to_string()));
        match (parsed, &mut merged) {
            (Ok(lib), None) => merged = Some(lib),
            (Ok((materials, map)), Some((all, all_map))) => {
                let offset = all.len();
                all.extend(materials);
                all_map.extend(map.into_iter().map(|(k, v)| (k, v + offset)));
            }
            (Err(e), _) => warn(format!(
                "material library not loaded ({e}); its materials fall back to the default"
            )),
        }
    }
    merged.ok_or(tobj::LoadError::OpenFileFailed)
}

/// The triangles of one tobj mesh, or `None` if it has none. Coordinates must be finite and
/// indices within the positions.
fn to_cpu_mesh(
    mesh: &tobj::Mesh,
    name: &str,
    origin: &Origin,
) -> Result<Option<CpuMesh>, MeshError> {
    if !mesh.positions.len().is_multiple_of(3) || !mesh.indices.len().is_multiple_of(3) {
        let detail = format!("object {name:?}: positions or indices not in threes");
        return Err(origin.malformed("OBJ", detail));
    }
    if mesh.indices.is_empty() {
        return Ok(None);
    }
    let positions = triples(&mesh.positions);
    if positions.iter().flatten().any(|c| !c.is_finite()) {
        return Err(origin.non_finite(format!("object {name:?}: vertex positions")));
    }
    let len = positions.len() as u64;
    if let Some(&bad) = mesh.indices.iter().find(|&&i| u64::from(i) >= len) {
        let what = format!("object {name:?}: face");
        return Err(origin.out_of_range(what, u64::from(bad), len));
    }
    let mut cpu = CpuMesh {
        colors: Vec::new(),
        positions,
        normals: triples(&mesh.normals),
        indices: mesh.indices.clone(),
    };
    let normals_usable = cpu.normals.len() == cpu.positions.len()
        && cpu.normals.iter().flatten().all(|c| c.is_finite());
    if !normals_usable {
        cpu.compute_normals();
    }
    Ok(Some(cpu))
}

fn triples(flat: &[f32]) -> Vec<[f32; 3]> {
    flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

/// The material a tobj mesh refers to, or the default.
fn material_of(mesh: &tobj::Mesh, materials: &[tobj::Material]) -> Material {
    let Some(m) = mesh.material_id.and_then(|i| materials.get(i)) else {
        return Material::default();
    };
    let default = Material::default();
    let unit = |x: f32| {
        if x.is_finite() {
            x.clamp(0.0, 1.0)
        } else {
            0.0
        }
    };
    let param = |key: &str| {
        m.unknown_param
            .get(key)
            .and_then(|v| v.trim().parse::<f32>().ok())
            .map(unit)
    };
    let [r, g, b] = m.diffuse.map_or(
        [
            default.base_color[0],
            default.base_color[1],
            default.base_color[2],
        ],
        |kd| kd.map(unit),
    );
    Material {
        base_color: [r, g, b, m.dissolve.map_or(1.0, unit)],
        roughness: param("Pr").unwrap_or(default.roughness),
        metallic: param("Pm").unwrap_or(default.metallic),
    }
}

#[cfg(test)]
mod tests {
    use super::super::{load_mesh, load_mesh_bytes};
    use super::*;

    const QUAD: &str = "mtllib missing.mtl\no quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
                        usemtl red\nf 1 2 3 4\n";

    /// A fresh scratch directory for one test.
    use crate::scratch::scratch;

    #[test]
    fn missing_mtllib_is_a_warning_with_default_material() {
        let dir = scratch("missing");
        let path = dir.join("quad.obj");
        std::fs::write(&path, QUAD).unwrap();
        let model = load_mesh(&path).unwrap();
        assert_eq!(model.parts.len(), 1);
        let part = &model.parts[0];
        assert_eq!(part.name, "quad");
        assert_eq!(part.mesh.triangle_count(), 2);
        assert_eq!(part.material, Material::default());
        assert_eq!(part.mesh.normals, vec![[0.0, 0.0, 1.0]; 4]);
        assert!(
            model.warnings.iter().any(|w| w.contains("missing.mtl")),
            "{:?}",
            model.warnings
        );
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn in_memory_obj_warns_about_its_library() {
        let model = load_mesh_bytes(QUAD.as_bytes(), "quad.obj").unwrap();
        assert_eq!(model.parts[0].mesh.triangle_count(), 2);
        assert_eq!(model.warnings.len(), 1, "{:?}", model.warnings);
    }

    #[test]
    fn kd_becomes_the_base_colour_and_file_normals_are_kept() {
        let dir = scratch("kd");
        let mtl = "newmtl red\nKd 1 0 0\nd 0.5\nPr 0.25\n";
        std::fs::write(dir.join("missing.mtl"), mtl).unwrap();
        let obj = QUAD.replace("f 1 2 3 4", "vn 0 0 -1\nf 1//1 2//1 3//1 4//1");
        std::fs::write(dir.join("quad.obj"), obj).unwrap();
        let model = load_mesh(&dir.join("quad.obj")).unwrap();
        let part = &model.parts[0];
        assert_eq!(part.material.base_color, [1.0, 0.0, 0.0, 0.5]);
        assert_eq!(part.material.roughness, 0.25);
        assert_eq!(part.mesh.normals, vec![[0.0, 0.0, -1.0]; 4]);
        assert!(model.warnings.is_empty(), "{:?}", model.warnings);
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn nan_coordinates_and_bad_indices_are_errors() {
        let nan = "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n";
        let err = load_mesh_bytes(nan.as_bytes(), "nan.obj").unwrap_err();
        assert!(matches!(err, MeshError::NonFinite { .. }), "{err}");
        let bad = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n";
        assert!(load_mesh_bytes(bad.as_bytes(), "bad.obj").is_err());
    }

    #[test]
    fn points_only_is_an_empty_model_with_a_warning() {
        let model = load_mesh_bytes(b"v 0 0 0\nv 1 0 0\np 1 2\n", "points.obj").unwrap();
        assert!(model.parts.is_empty());
        assert!(!model.warnings.is_empty());
    }
}
