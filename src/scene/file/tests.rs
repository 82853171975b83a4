//! Unit tests of scene files: reading, resolving, loading, cameras and saving.

use std::sync::Arc;

use glam::{DMat4, DVec3};

use crate::classify::TransferFunction;
use crate::measure::MeasureKind;
use crate::order::Ordering;
use crate::scene::{NodeContent, SceneMeasurement};

use super::load::*;
use super::*;
use crate::scene::NodeId;
use crate::scene::shoulder::shoulder_scene;

/// A fresh folder for one test's files, removed when dropped.
struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> Self {
        let dir = std::env::temp_dir().join(format!(
            "splatscene-scene-file-{}-{name}",
            std::process::id()
        ));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("create a temporary folder");
        Self(dir)
    }

    fn write(&self, name: &str, text: &str) -> PathBuf {
        let path = self.0.join(name);
        std::fs::write(&path, text).expect("write a temporary file");
        path
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn manifest_path(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

#[test]
fn data_paths_resolve_inside_the_data_folder() {
    let base = Path::new("/scenes");
    let data = Path::new("/mnt/data");
    assert_eq!(
        resolve_path("data:volumes/lidc2/ct.raw", base, data).unwrap(),
        Path::new("/mnt/data/volumes/lidc2/ct.raw")
    );
    assert_eq!(
        resolve_path("data:./meshes/bone.stl", base, data).unwrap(),
        Path::new("/mnt/data/meshes/bone.stl")
    );
    // Paths without the prefix keep their old meaning.
    assert_eq!(
        resolve_path("meshes/bone.stl", base, data).unwrap(),
        Path::new("/scenes/meshes/bone.stl")
    );
    assert_eq!(
        resolve_path("/abs/bone.stl", base, data).unwrap(),
        Path::new("/abs/bone.stl")
    );
    for bad in [
        "data:",
        "data:.",
        "data:../secret",
        "data:a/../../b",
        "data:/etc/passwd",
    ] {
        let message = resolve_path(bad, base, data).unwrap_err().to_string();
        assert!(message.contains(bad), "{bad}: {message}");
    }
}

#[test]
fn the_data_folder_comes_from_the_variable_or_the_default() {
    let default = Path::new(DEFAULT_DATA_DIR);
    assert_eq!(data_dir_from(None), default);
    assert_eq!(data_dir_from(Some(OsStr::new(""))), default);
    assert_eq!(
        data_dir_from(Some(OsStr::new("/srv/data"))),
        Path::new("/srv/data")
    );
    assert_eq!(
        data_dir(),
        data_dir_from(std::env::var_os(DATA_ENV).as_deref())
    );
}

#[test]
fn a_data_volume_loads_through_the_data_folder() {
    let rel = "volumes/datraw_small/Bucky_32x32x32_uint8.raw";
    if !data_dir().join(rel).exists() {
        assert!(
            std::env::var_os("CI").is_none(),
            "{} has no {rel} under CI: set {DATA_ENV}",
            data_dir().display()
        );
        eprintln!(
            "skipped: {} has no {rel} (set {DATA_ENV})",
            data_dir().display()
        );
        return;
    }
    let dir = TempDir::new("data-volume");
    let path = dir.write(
        "bucky.toml",
        &format!(
            "[[volume]]\npath = \"data:{rel}\"\ndims = [32, 32, 32]\nscalar = \"u8\"\n\
             transfer = \"ramp\"\nwindow = [40, 200]\n"
        ),
    );
    let loaded = load_scene_file(&path).unwrap();
    let (_, node, _) = loaded.scene.volumes().next().unwrap();
    assert_eq!(node.volume.dims, [32, 32, 32]);
}

#[test]
fn a_missing_data_file_says_what_to_set() {
    let dir = TempDir::new("missing-data");
    let path = dir.write("scene.toml", "[[mesh]]\npath = \"data:no/such/bone.stl\"\n");
    let err = load_scene_file(&path).unwrap_err();
    let SceneFileError::DataNotFound { file, .. } = &err else {
        panic!("expected DataNotFound, got {err:?}");
    };
    assert!(file.ends_with("no/such/bone.stl"), "{}", file.display());
    let message = err.to_string();
    assert!(message.contains(DATA_ENV), "{message}");
    assert!(message.contains("scene.toml"), "{message}");
}

#[test]
fn measurements_load_with_their_node_and_bad_ones_name_the_key() {
    let dir = TempDir::new("measurements");
    let scene = |measurement: &str| {
        format!(
            "[[mesh]]\nname = \"stem\"\npath = \"builtin:prosthesis\"\ntransform = {{ translate = [10, 0, 0] }}\n{measurement}"
        )
    };
    let good = dir.write(
        "good.toml",
        &scene(
            "[[measurement]]\nkind = \"line-angle\"\nlabel = \"neck-shaft angle\"\nnode = \"stem\"\npoints = [[0, 0, 0], [0, 0, -40], [0, 0, 0], [-7, 0, 7]]\n\n[[measurement]]\nkind = \"distance\"\npoints = [[0, 0, 0], [3, 4, 0]]\n\n[[measurement]]\nkind = \"point\"\nnode = \"stem\"\npoints = [[1, 2, 3]]\n",
        ),
    );
    let loaded = load_scene_file(&good).unwrap();
    let s = &loaded.scene;
    assert_eq!(s.measurements.len(), 3);
    let angle = s.measure(&s.measurements[0]).unwrap();
    assert!((angle.value.unwrap() - 135.0).abs() < 1e-9, "{angle:?}");
    assert_eq!(s.measure(&s.measurements[1]).unwrap().value, Some(5.0));
    // Points given in a node's frame move with it.
    let point = s.measure(&s.measurements[2]).unwrap();
    assert_eq!(point.points, vec![[11.0, 2.0, 3.0]]);
    // The file written back keeps them.
    let file = SceneFile::read(&good).unwrap();
    let again = SceneFile::parse(&file.to_toml().unwrap(), &good).unwrap();
    assert_eq!(again.measurements.len(), 3);

    for (text, expected) in [
        (
            "[[measurement]]\nkind = \"angle\"\npoints = [[0, 0, 0], [1, 0, 0]]\n",
            "measurement 1: points: an angle takes 3 points, not 2",
        ),
        (
            "[[measurement]]\nkind = \"diameter\"\npoints = [[0, 0, 0]]\n",
            "unknown variant `diameter`",
        ),
        (
            "[[measurement]]\nkind = \"distance\"\npoints = [[nan, 0, 0], [1, 0, 0]]\n",
            "not finite",
        ),
        (
            "[[measurement]]\nkind = \"point\"\nlabel = 7\npoints = [[0, 0, 0]]\n",
            "label",
        ),
        (
            "[[measurement]]\nkind = \"point\"\nnode = \"humerus\"\npoints = [[0, 0, 0]]\n",
            "node \"humerus\" is not in the scene (its top nodes: stem)",
        ),
        (
            "[[measurement]]\nkind = \"point\"\nlabel = \"  \"\npoints = [[0, 0, 0]]\n",
            "label must be",
        ),
        (
            "[[measurement]]\nkind = \"point\"\npoints = [[0, 0]]\n",
            "measurement",
        ),
    ] {
        let path = dir.write("bad.toml", &scene(text));
        let e = load_scene_file(&path).unwrap_err().to_string();
        assert!(e.contains(expected), "{text}: {e}");
        assert!(e.contains("bad.toml"), "{e}");
    }
}

#[test]
fn a_plan_saved_from_a_scene_loads_to_the_same_placement() {
    let dir = TempDir::new("plan");
    let path = dir.write(
        "plan.toml",
        "[[mesh]]\nname = \"implant\"\npath = \"builtin:prosthesis\"\nseat = \"phantom\"\nunits = \"cm\"\nframe = \"LPS\"\ntransform = { rotate_degrees = [0, 10, 0] }\n\n[[mesh]]\nname = \"second\"\npath = \"builtin:prosthesis\"\n\n[[measurement]]\nkind = \"point\"\nlabel = \"head centre\"\nnode = \"implant\"\npoints = [[1, 2, 3]]\n",
    );
    let file = SceneFile::read(&path).unwrap();
    let mut scene = file.load(&path, dir.0.as_path()).unwrap().scene;
    let implant = scene.find("implant").unwrap();
    let moved =
        DMat4::from_translation(DVec3::new(5.0, -3.0, 2.0)) * scene.node(implant).unwrap().local();
    scene.set_local(implant, moved).unwrap();
    scene.measurements.push(SceneMeasurement {
        kind: MeasureKind::Distance,
        points: vec![DVec3::ZERO, DVec3::X],
        node: None,
        anchors: Vec::new(),
        label: Some("gap".into()),
    });
    let saved = file.with_plan(&scene).unwrap();
    let text = saved.to_toml().unwrap();
    let again = dir.write("again.toml", &text);
    let reloaded = load_scene_file(&again).unwrap().scene;
    let id = reloaded.find("implant").unwrap();
    let a = reloaded.node(id).unwrap().local().to_cols_array();
    for (x, y) in a.iter().zip(moved.to_cols_array()) {
        assert!((x - y).abs() < 1e-9, "{a:?} against {moved:?}");
    }
    let second = reloaded.find("second").unwrap();
    assert_eq!(reloaded.node(second).unwrap().local(), DMat4::IDENTITY);
    assert_eq!(reloaded.measurements.len(), 2);
    let landmark = reloaded.measure(&reloaded.measurements[0]).unwrap();
    let before = scene.measure(&scene.measurements[0]).unwrap();
    for (p, q) in landmark.points[0].iter().zip(before.points[0]) {
        assert!((p - q).abs() < 1e-9, "the landmark moved with its mesh");
    }
    assert_eq!(reloaded.measurements[1].label.as_deref(), Some("gap"));
}

#[test]
fn clip_planes_and_the_crop_box_load_check_and_save() {
    let dir = TempDir::new("clipping");
    let volume = "[[volume]]\npath = \"builtin:shoulder-phantom\"\n";
    let path = dir.write(
        "clip.toml",
        &format!(
            "{volume}crop_box = {{ min = [0, 0, 0], max = [60, 50, 40] }}\nclip_meshes = true\n\n[[clip]]\nthrough = [0, 20, 0]\nnormal = [0, 2, 0]\nmeshes = true\n"
        ),
    );
    let file = SceneFile::read(&path).unwrap();
    let scene = file.load(&path, dir.0.as_path()).unwrap().scene;
    let c = &scene.clipping;
    assert_eq!(c.crop, Some((DVec3::ZERO, DVec3::new(60.0, 50.0, 40.0))));
    assert!(c.crop_meshes);
    assert_eq!(c.planes.len(), 1);
    assert!(c.planes[0].keeps(DVec3::new(5.0, 19.0, 5.0)));
    assert!(!c.planes[0].keeps(DVec3::new(5.0, 21.0, 5.0)));
    // Saved and read again: the same clipping.
    let again = dir.write(
        "again.toml",
        &file.with_plan(&scene).unwrap().to_toml().unwrap(),
    );
    let reloaded = load_scene_file(&again).unwrap().scene;
    assert_eq!(reloaded.clipping, scene.clipping);

    for (text, expected) in [
        (
            format!("{volume}crop_box = {{ min = [0, 0, 0], max = [60, 0, 40] }}\n"),
            "must lie below max",
        ),
        (
            format!("{volume}clip_meshes = true\n"),
            "no effect without a crop_box",
        ),
        (
            format!("{volume}\n[[clip]]\nthrough = [0, 0, 0]\nnormal = [0, 0, 0]\n"),
            "the normal not zero",
        ),
        (
            format!(
                "{volume}crop_box = {{ min = [0, 0, 0], max = [1, 1, 1] }}\n{volume}crop_box = {{ min = [0, 0, 0], max = [1, 1, 1] }}\n"
            ),
            "both have a crop_box",
        ),
        (
            format!("{volume}\n[[clip]]\nthrough = [0, 0, 0]\nnormal = [0, 0, 1]\nside = 2\n"),
            "side",
        ),
    ] {
        let path = dir.write("bad.toml", &text);
        let e = load_scene_file(&path).unwrap_err().to_string();
        assert!(e.contains(expected), "{text}: {e}");
    }
}

#[test]
fn an_unknown_field_is_a_parse_error_naming_file_and_field() {
    let dir = TempDir::new("unknown-field");
    let path = dir.write(
        "typo.toml",
        "[[volume]]\npath = \"builtin:shoulder-phantom\"\ntransfer_function = \"ct-bone\"\n",
    );
    let err = SceneFile::read(&path).unwrap_err();
    assert!(matches!(err, SceneFileError::Parse { .. }), "{err:?}");
    let message = err.to_string();
    assert!(message.contains("typo.toml"), "{message}");
    assert!(message.contains("transfer_function"), "{message}");
}

#[test]
fn a_missing_mesh_file_is_a_typed_error_naming_the_path() {
    let dir = TempDir::new("missing-mesh");
    let path = dir.write("scene.toml", "[[mesh]]\npath = \"implants/stem.stl\"\n");
    let err = load_scene_file(&path).unwrap_err();
    let SceneFileError::Mesh(MeshError::Io { file, .. }) = &err else {
        panic!("expected a mesh read error, got {err:?}");
    };
    assert_eq!(file, &dir.0.join("implants/stem.stl"));
    assert!(err.to_string().contains("stem.stl"), "{err}");
}

#[test]
fn a_bad_ordering_is_named() {
    // Refused as the file is read, at its line, with the names accepted.
    let err =
        SceneFile::parse("[output]\nordering = \"zigzag\"\n", Path::new("o.toml")).unwrap_err();
    assert!(matches!(err, SceneFileError::Parse { .. }), "{err:?}");
    let message = err.to_string();
    for said in ["zigzag", "o.toml", "line 2", "ordering = ", "ip-pbtf"] {
        assert!(message.contains(said), "{said}: {message}");
    }
}

/// Every key whose value is one of a closed set is read into its type, refused by name when
/// it is none of them, and written back as the same name.
#[test]
fn closed_sets_are_read_by_name_and_written_back() {
    let text = "[output]\nordering = \"pbtf\"\n\n\
        [[volume]]\npath = \"v.raw\"\ndims = [2, 2, 2]\nscalar = \"u16be\"\norientation = \"LPI\"\n\n\
        [[volume]]\npath = \"v.nii\"\nnifti_transform = \"itk\"\n\n\
        [[volume]]\npath = \"v.vtk\"\ncoordinate_frame = \"LPS\"\n\n\
        [[mesh]]\npath = \"m.stl\"\nunits = \"m\"\nframe = \"LPS\"\nseat = \"phantom\"\n";
    let file = SceneFile::parse(text, Path::new("s.toml")).unwrap();
    assert_eq!(file.output.ordering, Some(Ordering::Pbtf));
    assert_eq!(file.meshes[0].units, Some(Units::M));
    assert_eq!(file.meshes[0].seat, Some(Seat::Phantom));
    let written = file.to_toml().unwrap();
    let again = SceneFile::parse(&written, Path::new("again.toml")).unwrap();
    assert_eq!(again.to_toml().unwrap(), written);
    for key in [
        "scalar = \"u16be\"",
        "orientation = \"LPI\"",
        "nifti_transform = \"itk\"",
        "coordinate_frame = \"LPS\"",
    ] {
        assert!(written.contains(key), "{key}: {written}");
    }
    for (bad, said) in [
        (
            "[[mesh]]\npath = \"m.stl\"\nunits = \"inch\"\n",
            "is not mm, cm or m",
        ),
        (
            "[[mesh]]\npath = \"m.stl\"\nframe = \"XYZ\"\n",
            "neither RAS nor LPS",
        ),
        (
            "[[mesh]]\npath = \"m.stl\"\nseat = \"scapula\"\n",
            "unknown seat",
        ),
        ("[[volume]]\npath = \"v.raw\"\nscalar = \"u12\"\n", "u12"),
        (
            "[[volume]]\npath = \"v.nii\"\nnifti_transform = \"best\"\n",
            "none of sform, qform, itk",
        ),
    ] {
        let err = SceneFile::parse(bad, Path::new("bad.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(said) && err.contains("bad.toml"),
            "{bad}: {err}"
        );
    }
}

#[test]
fn transfer_presets_windows_shifts_and_opacity_reference() {
    let load = |extra: &str| {
        let text = format!("[[volume]]\npath = \"builtin:shoulder-phantom\"\n{extra}");
        SceneFile::parse(&text, Path::new("tf.toml"))
            .unwrap()
            .load(Path::new("tf.toml"), Path::new("."))
    };
    let loaded = load("transfer = \"ct-metal\"\nlevel_width = [1500, 2000]\nshift = 100\nopacity_reference_mm = 1.0\nshading = 0.0\n").unwrap();
    let (_, node, _) = loaded.scene.volumes().next().unwrap();
    let expected = TransferFunction::ct_metal()
        .windowed(1500.0, 2000.0)
        .shifted(100.0);
    assert_eq!(*node.transfer, expected);
    assert_eq!(node.splats.opacity_reference_mm, 1.0);
    assert_eq!(node.splats.shading, 0.0);
    let err = load("transfer = \"ct-lung\"\n").unwrap_err().to_string();
    assert!(
        err.contains("ct-lung") && err.contains("ct-soft-tissue"),
        "{err}"
    );
    assert!(load("opacity_reference_mm = -1\n").is_err());
}

#[test]
fn a_raw_volume_without_dims_is_invalid() {
    // The file does not exist: the missing dims must be reported before any read.
    let err = SceneFile::parse(
        "[[volume]]\npath = \"ct.raw\"\nscalar = \"u8\"\n",
        Path::new("raw.toml"),
    )
    .unwrap()
    .load(Path::new("raw.toml"), Path::new("."))
    .unwrap_err();
    assert!(matches!(err, SceneFileError::Invalid { .. }), "{err:?}");
    assert!(err.to_string().contains("dims"), "{err}");
}

#[test]
fn a_scene_file_over_the_limit_is_refused() {
    let dir = TempDir::new("large");
    let comment = format!("#{}\n", "x".repeat(MAX_SCENE_BYTES as usize));
    let path = dir.write("large.toml", &comment);
    let err = SceneFile::read(&path).unwrap_err();
    assert!(matches!(err, SceneFileError::Invalid { .. }), "{err:?}");
    assert!(err.to_string().contains("too large"), "{err}");
    // Exactly at the limit a file is read (an empty scene, all comment).
    let at_limit = MAX_SCENE_BYTES as usize - 2;
    let path = dir.write("limit.toml", &format!("#{}\n", "x".repeat(at_limit)));
    assert_eq!(std::fs::metadata(&path).unwrap().len(), MAX_SCENE_BYTES);
    // `is_ok` rather than `unwrap`: a failure would print a mebibyte of parser context.
    assert!(SceneFile::read(&path).is_ok());
}

#[test]
fn the_anterior_cutaway_applies_to_the_phantom_only() {
    let load = |text: &str| {
        SceneFile::parse(text, Path::new("c.toml"))
            .unwrap()
            .load(Path::new("c.toml"), Path::new("."))
    };
    let err = load(
        "[[volume]]\npath = \"ct.raw\"\ndims = [2, 2, 2]\nscalar = \"u8\"\ncut_away_anterior_humerus = 30.0\n",
    )
    .unwrap_err();
    assert!(
        err.to_string().contains("builtin:shoulder-phantom"),
        "{err}"
    );
    let err =
        load("[[volume]]\npath = \"builtin:shoulder-phantom\"\ncut_away_anterior_humerus = -1.0\n")
            .unwrap_err();
    assert!(err.to_string().contains("positive"), "{err}");
}

#[test]
fn the_shoulder_example_is_the_built_in_scene() {
    let loaded = load_scene_file(&manifest_path("examples/scenes/shoulder.toml")).unwrap();
    let built_in = shoulder_scene().unwrap();
    let (file, code) = (&loaded.scene, &built_in);
    assert_eq!(loaded.size, Some((800, 600)));
    assert_eq!(file.nodes().len(), code.nodes().len());
    for (i, (a, b)) in file.nodes().iter().zip(code.nodes()).enumerate() {
        assert_eq!(a.name, b.name);
        let (wa, wb) = (file.world(NodeId(i)), code.world(NodeId(i)));
        assert!(wa.abs_diff_eq(wb, 1e-9), "{}: {wa} vs {wb}", a.name);
    }
    let (_, va, _) = file.volumes().next().unwrap();
    let (_, vb, _) = code.volumes().next().unwrap();
    assert!(*va.volume == *vb.volume, "the volumes differ");
    assert_eq!(va.transfer, vb.transfer);
    assert_eq!(va.splats, vb.splats);
    let (ca, cb) = (file.camera.unwrap(), code.camera.unwrap());
    assert!(ca.eye.abs_diff_eq(cb.eye, 1e-9), "{ca:?} vs {cb:?}");
    assert!(ca.target.abs_diff_eq(cb.target, 1e-9));
    assert_eq!(ca.up, cb.up);
    assert_eq!(ca.projection, cb.projection);
    assert_eq!(file.lights, code.lights);
}

#[test]
fn rotate_degrees_turn_about_x_then_y_then_z_and_matrices_are_column_major() {
    let spec = TransformSpec {
        rotate_degrees: Some([90.0, 90.0, 0.0]),
        ..TransformSpec::default()
    };
    // +y turned 90 degrees about x is +z; +z turned 90 degrees about y is +x.
    let m = transform(&spec).unwrap();
    assert!(m.transform_vector3(DVec3::Y).abs_diff_eq(DVec3::X, 1e-12));
    let mut cols = [0.0; 16];
    cols[0] = 1.0;
    cols[6] = 1.0; // y goes to z
    cols[9] = -1.0; // z goes to -y
    cols[12..16].copy_from_slice(&[5.0, 6.0, 7.0, 1.0]);
    let spec = TransformSpec {
        matrix: Some(cols),
        ..TransformSpec::default()
    };
    let m = transform(&spec).unwrap();
    assert_eq!(m.transform_point3(DVec3::Y), DVec3::new(5.0, 6.0, 8.0));
}

#[test]
fn mesh_units_and_frames_apply_before_the_transform() {
    let dir = TempDir::new("mesh-units");
    let plain = dir.write("plain.toml", "[[mesh]]\npath = \"builtin:prosthesis\"\n");
    let turned = dir.write(
        "turned.toml",
        "[[mesh]]\npath = \"builtin:prosthesis\"\nunits = \"cm\"\nframe = \"LPS\"\n\
         transform = { translate = [1, 2, 3] }\n",
    );
    let (lo, hi) = load_scene_file(&plain).unwrap().scene.bounds().unwrap();
    let (tlo, thi) = load_scene_file(&turned).unwrap().scene.bounds().unwrap();
    // Ten times larger, x and y mirrored through the origin (LPS to RAS), then moved.
    let expected_lo =
        DVec3::new(-10.0 * hi.x, -10.0 * hi.y, 10.0 * lo.z) + DVec3::new(1.0, 2.0, 3.0);
    let expected_hi =
        DVec3::new(-10.0 * lo.x, -10.0 * lo.y, 10.0 * hi.z) + DVec3::new(1.0, 2.0, 3.0);
    assert!(tlo.abs_diff_eq(expected_lo, 1e-3), "{tlo} vs {expected_lo}");
    assert!(thi.abs_diff_eq(expected_hi, 1e-3), "{thi} vs {expected_hi}");
    let bad = dir.write(
        "bad.toml",
        "[[mesh]]\npath = \"builtin:prosthesis\"\nunits = \"in\"\n",
    );
    let message = load_scene_file(&bad).unwrap_err().to_string();
    assert!(
        message.contains("\"in\"") && message.contains("mm, cm or m"),
        "{message}"
    );
}

#[test]
fn raw_volumes_take_an_orientation_and_header_files_refuse_raw_keys() {
    let dir = TempDir::new("orientation");
    std::fs::write(dir.0.join("v.raw"), [0u8; 24]).unwrap();
    let scene = |extra: &str| {
        dir.write(
            "v.toml",
            &format!(
                "[[volume]]\npath = \"v.raw\"\ndims = [2, 3, 4]\nscalar = \"u8\"\n\
                 transfer = \"ramp\"\nwindow = [1, 2]\n{extra}"
            ),
        )
    };
    let loaded = load_scene_file(&scene("orientation = \"LPI\"\n")).unwrap();
    let (_, node, _) = loaded.scene.volumes().next().unwrap();
    assert_eq!(
        node.volume.direction,
        glam::DMat3::from_diagonal(DVec3::splat(-1.0))
    );
    // The patient's superior is still world +z: the scene's up does not follow the grid.
    assert_eq!(loaded.scene.up_axis(), DVec3::Z);
    let message = load_scene_file(&scene("orientation = \"LPP\"\n"))
        .unwrap_err()
        .to_string();
    assert!(
        message.contains("LPP") && message.contains("R/L"),
        "{message}"
    );
    let message = load_scene_file(&scene("color = [1, 1, 1, 1]\ntransfer = \"ct-bone\"\n"));
    assert!(message.is_err(), "a key given twice");
    let phantom = dir.write(
        "p.toml",
        "[[volume]]\npath = \"builtin:shoulder-phantom\"\norientation = \"LPS\"\n",
    );
    let message = load_scene_file(&phantom).unwrap_err().to_string();
    assert!(message.contains("orientation"), "{message}");
    let preset = dir.write(
        "w.toml",
        "[[volume]]\npath = \"builtin:shoulder-phantom\"\ntransfer = \"ct-bone\"\nwindow = [1, 2]\n",
    );
    let message = load_scene_file(&preset).unwrap_err().to_string();
    assert!(
        message.contains("window applies to transfer = \"ramp\""),
        "{message}"
    );
}

#[test]
fn a_scene_file_given_as_a_volume_is_named_as_one() {
    let dir = TempDir::new("scene-as-volume");
    dir.write("inner.txt", "# a plan\n\n[camera]\nfov = 30\n");
    let path = dir.write("outer.toml", "[[volume]]\npath = \"inner.txt\"\n");
    let message = load_scene_file(&path).unwrap_err().to_string();
    assert!(
        message.contains("inner.txt") && message.contains("scene file, not a volume"),
        "{message}"
    );
}

#[test]
fn a_named_view_in_a_scene_file_looks_from_that_side() {
    let dir = TempDir::new("named-view");
    let path = dir.write(
        "v.toml",
        "[camera]\nview = \"superior\"\n\n[[volume]]\npath = \"builtin:shoulder-phantom\"\n",
    );
    let camera = load_scene_file(&path).unwrap().scene.camera.unwrap();
    let forward = (camera.target - camera.eye).normalize();
    assert!(forward.abs_diff_eq(DVec3::NEG_Z, 1e-9), "{forward}");
    assert!(
        camera.up.abs_diff_eq(DVec3::Y, 1e-9),
        "anterior at the top: {}",
        camera.up
    );
    let both = dir.write(
        "both.toml",
        "[camera]\nview = \"left\"\neye = [0, 0, 100]\n\n[[volume]]\npath = \"builtin:shoulder-phantom\"\n",
    );
    let message = load_scene_file(&both).unwrap_err().to_string();
    assert!(message.contains("camera.view"), "{message}");
    let unknown = dir.write("u.toml", "[camera]\nview = \"sideways\"\n");
    let message = load_scene_file(&unknown).unwrap_err().to_string();
    assert!(
        message.contains("sideways") && message.contains("anterior"),
        "{message}"
    );
}

#[test]
fn a_saved_view_loads_back_to_the_same_camera() {
    let dir = TempDir::new("saved-view");
    let path = dir.write(
        "s.toml",
        "[camera]\nview_from = [0.2, -1.0, -0.3]\n\n[[volume]]\npath = \"builtin:shoulder-phantom\"\n",
    );
    let loaded = load_scene_file(&path).unwrap();
    let camera = loaded
        .scene
        .camera
        .unwrap()
        .orbit_about(loaded.scene.up_axis(), 40.0, 20.0);
    let mut file = SceneFile::read(&path).unwrap().with_paths_from(&dir.0);
    file.camera = Some(CameraSpec::from_camera(&camera, loaded.scene.up_axis()));
    let saved = dir.write("saved.toml", &file.to_toml().unwrap());
    let again = load_scene_file(&saved).unwrap().scene.camera.unwrap();
    assert!(
        again.eye.abs_diff_eq(camera.eye, 1e-9) && again.target.abs_diff_eq(camera.target, 1e-9)
    );
    let (a, b) = (
        camera.pinhole(64, 64, 0.0).unwrap().frame().unwrap(),
        again.pinhole(64, 64, 0.0).unwrap().frame().unwrap(),
    );
    assert!(a.up.abs_diff_eq(b.up, 1e-9) && a.right.abs_diff_eq(b.right, 1e-9));
}

#[test]
fn the_overlay_example_parses_and_loads_when_the_data_is_there() {
    let path = manifest_path("examples/scenes/overlay-lidc2.toml");
    let file = SceneFile::read(&path).unwrap();
    assert_eq!(file.output.size, Some([512, 512]));
    let ct = "volumes/lidc2/lidc2_256x256x133_uint8.raw";
    if !data_dir().join(ct).exists() {
        assert!(
            std::env::var_os("CI").is_none(),
            "{} has no {ct} under CI: set SPLATSCENE_DATA",
            data_dir().display()
        );
        eprintln!("skipped loading: {} has no {ct}", data_dir().display());
        return;
    }
    let loaded = load_scene_file(&path).unwrap();
    let (_, node, _) = loaded.scene.volumes().next().unwrap();
    assert_eq!(node.volume.dims, [256, 256, 133]);
    // The prosthesis head centre, (-7.0004, 0, 7.0004) in its own frame, sits at the
    // humeral head centre found in the scan, voxel (25.7, 116.2, 7.8).
    let group = loaded.scene.find("prosthesis").unwrap();
    let head = loaded
        .scene
        .world(group)
        .transform_point3(DVec3::new(-7.0004, 0.0, 7.0004));
    // Orientation LAI: index x runs to the patient's left (-x), z inferior (-z).
    let expected = DVec3::new(-25.71 * 1.40625, 116.19 * 1.40625, -7.82 * 2.5);
    assert!(head.distance(expected) < 0.05, "{head} vs {expected}");
}

#[test]
fn a_mesh_file_named_by_several_nodes_is_read_once_and_shared() {
    let dir = TempDir::new("instanced");
    let mut stl = vec![0u8; 80];
    stl.extend(1u32.to_le_bytes());
    for v in [0f32, 0., 1., 0., 0., 0., 10., 0., 0., 0., 10., 0.] {
        stl.extend(v.to_le_bytes());
    }
    stl.extend([0u8; 2]);
    std::fs::write(dir.0.join("bone.stl"), &stl).unwrap();
    let mut text = String::new();
    for x in 0..30 {
        text.push_str(&format!(
            "[[mesh]]\npath = \"bone.stl\"\ntransform = {{ translate = [{x}, 0, 0] }}\n"
        ));
    }
    text.push_str("[[mesh]]\npath = \"./bone.stl\"\ncolor = [1, 0, 0]\n");
    let path = dir.write("many.toml", &text);
    let scene = load_scene_file(&path).unwrap().scene;
    let meshes: Vec<&crate::scene::MeshNode> = scene
        .nodes()
        .iter()
        .filter_map(|n| match &n.content {
            NodeContent::Mesh(m) => Some(m),
            _ => None,
        })
        .collect();
    assert_eq!(meshes.len(), 31);
    assert!(meshes.iter().all(|m| Arc::ptr_eq(&m.mesh, &meshes[0].mesh)));
    assert_eq!(meshes[0].mesh.indices.len(), 3);
    // Materials stay each node's own.
    assert_eq!(meshes[30].material.base_color, [1.0, 0.0, 0.0, 1.0]);
    assert_ne!(
        meshes[0].material.base_color,
        meshes[30].material.base_color
    );
}

#[test]
fn plans_write_transforms_as_people_do_where_they_load_back() {
    use super::save::transform_spec;
    let turned = |r: [f64; 3], t: [f64; 3], s: [f64; 3]| TransformSpec {
        translate: Some(t),
        rotate_degrees: Some(r),
        scale: Some(s),
        matrix: None,
    };
    for (r, t, s) in [
        ([90.0, 0.0, 90.0], [26.7, 163.4, 16.7], [1.0; 3]),
        ([180.0, 28.0, 0.0], [-26.69, 163.39, -16.66], [1.0; 3]),
        ([-10.0, 35.5, 170.0], [0.0; 3], [2.0, 2.0, 2.0]),
        ([0.0, 10.0, 0.0], [5.0, -3.0, 2.0], [1.0, -1.0, 1.0]),
    ] {
        let m = super::load::transform(&turned(r, t, s)).unwrap();
        let written = transform_spec(m);
        assert!(written.matrix.is_none(), "{r:?} {t:?} {s:?}: {written:?}");
        let back = super::load::transform(&written).unwrap();
        assert!(back.abs_diff_eq(m, 1e-9), "{written:?}");
        if s == [1.0; 3] {
            assert_eq!(written.rotate_degrees, Some(r), "the angles as typed");
            assert_eq!(written.translate, Some(t));
            assert_eq!(written.scale, None);
        }
    }
    // A shear has no such keys: its matrix is written.
    let shear = DMat4::from_cols_array(&[
        1.0, 0.0, 0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 2.0, 3.0, 1.0,
    ]);
    let written = transform_spec(shear);
    assert!(written.matrix.is_some() && written.translate.is_none());
    assert_eq!(transform_spec(DMat4::IDENTITY), TransformSpec::default());
}

#[test]
fn a_measurement_between_an_implant_and_the_world_follows_the_implant_end_only() {
    let dir = TempDir::new("anchors");
    let mesh = "[[mesh]]\nname = \"implant\"\npath = \"builtin:prosthesis\"\n\n";
    let path = dir.write(
        "gap.toml",
        &format!(
            "{mesh}[[measurement]]\nkind = \"distance\"\nlabel = \"gap\"\nnodes = [\"implant\", \"\"]\npoints = [[0, 0, 0], [30, 0, 0]]\n"
        ),
    );
    let file = SceneFile::read(&path).unwrap();
    let mut scene = file.load(&path, dir.0.as_path()).unwrap().scene;
    let implant = scene.find("implant").unwrap();
    let m = scene.measurements[0].clone();
    assert_eq!(m.anchors, vec![Some(implant), None]);
    assert_eq!(scene.measure(&m).unwrap().value, Some(30.0));
    // The implant moves 10 mm toward the world point: the distance shrinks by 10 mm.
    let moved = DMat4::from_translation(DVec3::new(10.0, 0.0, 0.0));
    scene.set_local(implant, moved).unwrap();
    assert!((scene.measure(&m).unwrap().value.unwrap() - 20.0).abs() < 1e-9);
    // Saved with its nodes, and loaded back to the same.
    let text = file.with_plan(&scene).unwrap().to_toml().unwrap();
    assert!(text.contains("nodes = [\"implant\", \"\"]"), "{text}");
    let again = load_scene_file(&dir.write("again.toml", &text))
        .unwrap()
        .scene;
    let back = &again.measurements[0];
    assert!((again.measure(back).unwrap().value.unwrap() - 20.0).abs() < 1e-9);
    // Refused: both keys, a name a point too few, a name the scene lacks.
    for (nodes, wanted) in [
        (
            "node = \"implant\"\nnodes = [\"implant\", \"\"]",
            "not both",
        ),
        ("nodes = [\"implant\"]", "1 nodes for 2 points"),
        (
            "nodes = [\"humerus\", \"\"]",
            "\"humerus\" is not in the scene",
        ),
    ] {
        let bad = dir.write(
            "bad.toml",
            &format!(
                "{mesh}[[measurement]]\nkind = \"distance\"\n{nodes}\npoints = [[0, 0, 0], [30, 0, 0]]\n"
            ),
        );
        let e = match load_scene_file(&bad) {
            Ok(_) => panic!("{nodes}: loaded"),
            Err(e) => e.to_string(),
        };
        assert!(e.contains(wanted), "{e}");
    }
}

/// Volumes and meshes given in memory load as those read from files would, their paths only
/// naming them; keys that would read a file are refused on them.
#[test]
fn given_volumes_and_meshes_stand_for_their_files() {
    let volume = Arc::new(crate::volume::CpuVolume {
        dims: [4, 3, 2],
        spacing: [1.0, 2.0, 3.0],
        origin: [5.0, 6.0, 7.0],
        direction: glam::DMat3::IDENTITY,
        values: (0..24).map(|v| v as f32 * 10.0).collect::<Vec<_>>().into(),
    });
    let cube =
        crate::mesh::load_mesh_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "triangle.obj")
            .expect("an OBJ triangle");
    let file = SceneFile {
        volumes: vec![VolumeSpec {
            name: Some("ct".into()),
            path: "<array>".into(),
            transfer: Some("ramp".into()),
            window: Some([0.0, 200.0]),
            ..VolumeSpec::default()
        }],
        meshes: vec![MeshSpec {
            name: Some("implant".into()),
            path: "<arrays>".into(),
            transform: TransformSpec {
                translate: Some([1.0, 2.0, 3.0]),
                ..TransformSpec::default()
            },
            ..MeshSpec::default()
        }],
        ..SceneFile::default()
    };
    let given = || Given {
        volumes: vec![Some(Arc::clone(&volume))],
        meshes: vec![Some(cube.clone())],
    };
    let loaded = file
        .load_given(Path::new("memory"), Path::new("."), given())
        .expect("the given parts load");
    let (_, node, _) = loaded.scene.volumes().next().expect("a volume");
    assert!(
        Arc::ptr_eq(&node.volume, &volume),
        "the volume is not copied"
    );
    let (_, mesh, world) = loaded.scene.meshes().next().expect("a mesh");
    assert_eq!(mesh.mesh.positions, cube.parts[0].mesh.positions);
    assert_eq!(
        world.transform_point3(DVec3::ZERO),
        DVec3::new(1.0, 2.0, 3.0)
    );
    // Without them the paths are read, and there is no such file.
    assert!(file.load(Path::new("memory"), Path::new(".")).is_err());
    for (key, spec) in [
        (
            "dims",
            VolumeSpec {
                dims: Some([4, 3, 2]),
                ..file.volumes[0].clone()
            },
        ),
        (
            "series",
            VolumeSpec {
                series: Some("2".into()),
                ..file.volumes[0].clone()
            },
        ),
    ] {
        let with_key = SceneFile {
            volumes: vec![spec],
            ..file.clone()
        };
        let e = with_key
            .load_given(Path::new("memory"), Path::new("."), given())
            .expect_err("a key that reads a file is refused")
            .to_string();
        assert!(e.contains(key) && e.contains("in memory"), "{e}");
    }
}
