//! The mesh loaders against real corpora: every file loads or returns a typed error, without a
//! panic or a hang, and every file the glTF validator calls valid loads.
//!
//! The data directory is `$SPLATSCENE_DATA`, by default `../shared/data` next to the crate; the
//! tests are skipped with a note when it does not exist. Its corpora come from:
//! - `gltf/gltf_validator_tests/`: KhronosGroup glTF-Validator conformance tests, Apache-2.0;
//! - `gltf/gltf_rs/`: the gltf-rs crate's test assets, MIT/Apache-2.0;
//! - `gltf/aleph_khronos_samples/`: Khronos glTF sample models (Cesium), CC BY 4.0;
//! - `obj/tobj/`: the tobj crate's test models, MIT;
//! - `obj/tinyobjloader/`: tinyobjloader's test models, MIT;
//! - `meshes/myosim_shoulder/`: MyoHub myo_sim shoulder bones (from OpenSim MoBL-ARMS), Apache-2.0.

use std::collections::BTreeMap;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use splatscene::mesh::{MeshError, Model, load_mesh, read_gltf_accessor};

mod common;
use common::data_dir;

/// Every file under `dir`, recursively, sorted.
fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    let mut pending = vec![dir.to_path_buf()];
    while let Some(d) = pending.pop() {
        let entries = std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display()));
        for entry in entries {
            let path = entry.expect("directory entry").path();
            if path.is_dir() {
                pending.push(path);
            } else {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

/// Loads one file, turning a panic into an `Err` naming the file.
fn load_catching(path: &Path) -> Result<Result<Model, MeshError>, String> {
    catch_unwind(AssertUnwindSafe(|| load_mesh(path))).map_err(|payload| {
        let message = payload
            .downcast_ref::<&str>()
            .map(|s| (*s).to_owned())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        format!("{}: panicked: {message}", path.display())
    })
}

/// Whether the glTF validator found the asset valid, from its `ASSET.report.json`: the number
/// after `"numErrors":` is 0. `None` when there is no report.
fn validator_says_valid(asset: &Path) -> Option<bool> {
    let mut report = asset.as_os_str().to_owned();
    report.push(".report.json");
    let text = std::fs::read_to_string(PathBuf::from(report)).ok()?;
    let after = text.split_once("\"numErrors\":")?.1.trim_start();
    let digits: String = after.chars().take_while(char::is_ascii_digit).collect();
    Some(digits.parse::<u64>().ok()? == 0)
}

fn extension(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

/// Tally of one corpus walk.
#[derive(Default)]
struct Tally {
    loaded: usize,
    errors: usize,
    /// Error variants and how often each came up.
    kinds: BTreeMap<String, usize>,
    /// Files the glTF validator calls valid.
    validator_valid: usize,
    failures: Vec<String>,
    /// Print each file's outcome.
    verbose: bool,
}

impl Tally {
    /// Loads `path` and records the outcome. A panic is a failure, and so is an error on a file
    /// the glTF validator calls valid, or an error that names no file.
    fn visit(&mut self, path: &Path) {
        let outcome = load_catching(path);
        let valid = validator_says_valid(path) == Some(true);
        self.validator_valid += usize::from(valid);
        if self.verbose {
            match &outcome {
                Ok(Ok(m)) => println!(
                    "ok    {} {} parts {:?}",
                    path.display(),
                    m.parts.len(),
                    m.warnings
                ),
                Ok(Err(e)) => println!("error {e}"),
                Err(panic) => println!("panic {panic}"),
            }
        }
        let e = match outcome {
            Ok(Ok(_)) => return self.loaded += 1,
            Ok(Err(e)) => e,
            Err(panic) => return self.failures.push(panic),
        };
        self.errors += 1;
        let kind = format!("{e:?}")
            .split([' ', '{', '('])
            .next()
            .unwrap_or("?")
            .to_owned();
        *self.kinds.entry(kind).or_default() += 1;
        if valid {
            self.failures
                .push(format!("the validator calls it valid, but: {e}"));
        }
        if e.file().as_os_str().is_empty() {
            self.failures
                .push(format!("{}: error names no file: {e}", path.display()));
        }
    }
}

#[test]
fn every_corpus_file_loads_or_fails_cleanly() {
    let Some(data) = data_dir() else { return };
    let start = Instant::now();
    // MESH_CORPUS_VERBOSE=1 prints each mesh file's outcome.
    let verbose = std::env::var_os("MESH_CORPUS_VERBOSE").is_some();
    let mut meshes = Tally {
        verbose,
        ..Tally::default()
    };
    // Every file is loaded, buffers, images, material libraries and reports included: none may
    // panic, whatever it holds.
    let mut others = Tally::default();
    for corpus in ["gltf", "obj/tobj", "obj/tinyobjloader"] {
        let files = files_under(&data.join(corpus));
        assert!(!files.is_empty(), "no files under {corpus}");
        for path in files {
            let is_mesh = matches!(extension(&path).as_str(), "gltf" | "glb" | "obj");
            if is_mesh { &mut meshes } else { &mut others }.visit(&path);
        }
    }
    let elapsed = start.elapsed();
    println!(
        ".gltf/.glb/.obj: {} loaded, {} typed errors {:?}; other files: {} loaded, {} errors; \
         {} validator-valid files; {elapsed:.2?}",
        meshes.loaded,
        meshes.errors,
        meshes.kinds,
        others.loaded,
        others.errors,
        meshes.validator_valid
    );
    let failures: Vec<_> = meshes.failures.iter().chain(&others.failures).collect();
    assert!(
        failures.is_empty(),
        "{} failures:\n{failures:#?}",
        failures.len()
    );
    assert_eq!(
        meshes.validator_valid, 129,
        "the validator corpus has 129 valid assets"
    );
    assert!(
        elapsed < Duration::from_secs(20),
        "the walk took {elapsed:?}"
    );
}

/// Triangle count and bounds of a one-part model, with the part's transform applied to the
/// bounds' corners.
fn single_part(path: &Path) -> (usize, [f32; 3], [f32; 3], Model) {
    let model = load_mesh(path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(model.parts.len(), 1, "{}", path.display());
    let part = &model.parts[0];
    let (lo, hi) = part.mesh.bounds().expect("a non-empty mesh");
    (part.mesh.triangle_count(), lo, hi, model)
}

#[test]
fn shoulder_bones_have_their_triangle_counts() {
    let Some(data) = data_dir() else { return };
    let dir = data.join("meshes/myosim_shoulder");
    for (bone, triangles) in [("humerus", 588), ("scapula", 1550), ("clavicle", 398)] {
        let (count, lo, hi, model) = single_part(&dir.join(format!("{bone}.stl")));
        assert_eq!(count, triangles, "{bone}");
        let part = &model.parts[0];
        assert!(
            part.mesh.positions.len() < count * 3,
            "{bone}: vertices are shared"
        );
        assert_eq!(part.mesh.normals.len(), part.mesh.positions.len());
        // Bones in metres: tens of centimetres at most.
        let extent = (0..3).map(|a| hi[a] - lo[a]).fold(0.0, f32::max);
        assert!(extent > 0.01 && extent < 0.5, "{bone}: extent {extent} m");
        assert!(model.warnings.is_empty(), "{bone}: {:?}", model.warnings);
    }
}

#[test]
fn khronos_box_has_twelve_triangles_in_a_unit_cube() {
    let Some(data) = data_dir() else { return };
    for file in ["gltf/gltf_rs/Box.gltf", "gltf/gltf_rs/Box.glb"] {
        let (count, lo, hi, model) = single_part(&data.join(file));
        assert_eq!(count, 12, "{file}");
        assert_eq!((lo, hi), ([-0.5; 3], [0.5; 3]), "{file}");
        let part = &model.parts[0];
        assert_eq!(
            part.mesh.positions.len(),
            24,
            "{file}: split vertices with face normals"
        );
        // The Box's root node turns Z-up into Y-up: a rotation, so the cube stays a unit cube.
        let corner = part.transform.transform_point3(glam::DVec3::splat(0.5));
        let off = (corner.abs() - glam::DVec3::splat(0.5)).abs().max_element();
        assert!(off < 1e-12, "{file}: corner goes to {corner}");
        assert_eq!(corner.z, -0.5, "{file}: +y goes to -z");
        let unit = |n: &[f32; 3]| (n[0] * n[0] + n[1] * n[1] + n[2] * n[2] - 1.0).abs() < 1e-5;
        assert!(
            part.mesh.normals.iter().all(unit),
            "{file}: normals from the file"
        );
        let red = part.material.base_color;
        assert!(
            red[0] > 0.7 && red[1] < 0.1 && red[2] < 0.1,
            "{file}: {red:?}"
        );
    }
}

#[test]
fn draco_compressed_samples_are_unsupported() {
    let Some(data) = data_dir() else { return };
    // The sample-model copies of Box and BoxTextured are Draco-compressed
    // (extensionsRequired: KHR_draco_mesh_compression), which this loader does not decode: a
    // typed error naming the extension, not a silently empty model.
    for file in ["Box.glb", "BoxTextured.glb"] {
        let path = data.join("gltf/aleph_khronos_samples").join(file);
        match load_mesh(&path) {
            Err(e @ MeshError::Unsupported { .. }) => {
                assert!(e.to_string().contains("KHR_draco_mesh_compression"), "{e}");
                assert_eq!(e.file(), path);
            }
            other => panic!("{file}: expected Unsupported, got {other:?}"),
        }
    }
}

#[test]
fn sparse_box_substitution_takes_effect() {
    let Some(data) = data_dir() else { return };
    for file in ["box_sparse.gltf", "box_sparse.glb"] {
        let path = data.join("gltf/gltf_rs").join(file);
        // Accessor 2 (morph weights over time) has no buffer view: its base is two zeros, and
        // its sparse block sets element 1 to 1.0.
        let weights = read_gltf_accessor(&path, 2).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(weights, [0.0, 1.0], "{file}");
        // Its plain neighbour is read as stored.
        assert_eq!(read_gltf_accessor(&path, 3).unwrap(), [1.0, 2.0], "{file}");
        let (count, lo, hi, _) = single_part(&path);
        assert_eq!((count, lo, hi), (12, [-0.5; 3], [0.5; 3]), "{file}");
    }
    let missing = read_gltf_accessor(&data.join("gltf/gltf_rs/box_sparse.gltf"), 99);
    assert!(matches!(
        missing,
        Err(MeshError::IndexOutOfRange {
            index: 99,
            len: 5,
            ..
        })
    ));
}

#[test]
fn obj_corpus_details() {
    let Some(data) = data_dir() else { return };
    let tiny = data.join("obj/tinyobjloader");
    // "nan" and "inf" parse as floats, "1.#IND" does not: either way an error.
    let nan = load_mesh(&tiny.join("test-nan.obj"));
    assert!(
        matches!(
            nan,
            Err(MeshError::NonFinite { .. } | MeshError::Malformed { .. })
        ),
        "{nan:?}"
    );
    let missing = load_mesh(&tiny.join("missing_material_file.obj")).unwrap();
    assert!(!missing.parts.is_empty());
    let cornell = load_mesh(&data.join("obj/tobj/cornell_box.obj")).unwrap();
    assert!(cornell.warnings.is_empty(), "{:?}", cornell.warnings);
    let red = cornell
        .parts
        .iter()
        .find(|p| p.material.base_color[..3] == [1.0, 0.0, 0.0]);
    assert!(red.is_some(), "a part with Kd 1 0 0");
    let invalid = load_mesh(&data.join("obj/tobj/invalid_index.obj"));
    assert!(invalid.is_err(), "{invalid:?}");
}
