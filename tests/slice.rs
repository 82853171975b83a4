//! Slices against answers computed here without the code under test: a value field linear in
//! world coordinates (which trilinear interpolation reproduces exactly, whatever the grid's
//! tilt), so every pixel's value follows from the calibration's vectors alone; the sections of
//! a cylinder (across its axis a circle, along it a rectangle, obliquely an ellipse) and of a
//! turned cube, in closed form; the planes' directions in the patient; the errors a user meets;
//! and the command line's figures, their calibration read back to place the outline.

use std::sync::Arc;

use glam::{DMat3, DMat4, DQuat, DVec3, EulerRot};
use serde_json::Value;
use splatscene::measure::MeasureKind;
use splatscene::mesh::{CpuMesh, Material};
use splatscene::scene::{MeshNode, NodeContent, SceneMeasurement};
use splatscene::slice::{Pixels, Plane, PlaneKind, Slice, SliceError, SliceSpec, long_axis};
use splatscene::volume::CpuVolume;

mod common;
use common::shapes::{cube, cylinder, obj_text, scene_of, unindexed, write_raw_f32};
use common::{fails, ok, scratch};

/// The field sampled: linear in world millimetres.
fn field(p: DVec3) -> f64 {
    3.0 * p.x - 2.0 * p.y + 5.0 * p.z + 7.0
}

/// A 96^3 grid of 0.8 mm voxels centred on `centre`, its axes turned by `turn`, holding
/// [`field`] at every voxel centre.
fn field_volume(turn: DMat3, centre: DVec3) -> CpuVolume {
    let n = 96u32;
    let spacing = 0.8;
    let half = 0.5 * spacing * f64::from(n - 1);
    let origin = centre - turn * DVec3::splat(half);
    let values = (0..n * n * n)
        .map(|id| {
            let (i, j, k) = (id % n, (id / n) % n, id / (n * n));
            let p =
                origin + turn * (DVec3::new(f64::from(i), f64::from(j), f64::from(k)) * spacing);
            field(p) as f32
        })
        .collect();
    CpuVolume {
        dims: [n; 3],
        spacing: [spacing; 3],
        origin: origin.to_array(),
        direction: turn,
        values,
    }
}

fn spec(s: &str) -> SliceSpec {
    s.parse().unwrap()
}

fn vector(v: &Value) -> DVec3 {
    DVec3::new(
        v[0].as_f64().unwrap(),
        v[1].as_f64().unwrap(),
        v[2].as_f64().unwrap(),
    )
}

/// Whether world point `p` lies inside the grid of [`field_volume`] (voxel centres' box), with
/// a margin `m` in voxels: computed from the grid's own description, not the slicer's.
fn inside_grid(p: DVec3, turn: DMat3, centre: DVec3, m: f64) -> bool {
    let local = turn.transpose() * (p - centre) / 0.8;
    local.abs().max_element() <= 47.5 - m
}

#[test]
fn every_pixel_holds_the_field_at_the_point_its_calibration_names() {
    let turn = DMat3::from_euler(EulerRot::XYZ, 0.2, -0.35, 0.5);
    let centre = DVec3::new(4.0, -3.0, 10.0);
    let scene = scene_of(field_volume(turn, centre), None);
    for (name, normal) in [
        ("axial@13.3", DVec3::Z),
        ("coronal@-7.1", DVec3::Y),
        ("sagittal@0.4", DVec3::X),
    ] {
        let plane = Plane::of(&scene, spec(name), DVec3::ZERO, None).unwrap();
        let slice = Slice::new(&scene, plane, Pixels::Size(Some(0.9))).unwrap();
        let c = slice.calibration(&scene, [0.0, 1.0]);
        assert_eq!(
            (c["frame"].as_str(), c["unit"].as_str()),
            (Some("RAS"), Some("mm"))
        );
        let origin = vector(&c["origin_mm"]);
        let right = vector(&c["pixel_right_mm"]);
        let down = vector(&c["pixel_down_mm"]);
        assert!((right.length() - 0.9).abs() < 1e-9 && (down.length() - 0.9).abs() < 1e-9);
        assert!(right.dot(down).abs() < 1e-9 && right.dot(normal).abs() < 1e-9);
        let at: f64 = name.split('@').nth(1).unwrap().parse().unwrap();
        let (w, h) = (slice.values.width, slice.values.height);
        let (mut inside, mut checked) = (0, 0);
        for y in 0..h {
            for x in 0..w {
                let p = origin + right * f64::from(x) + down * f64::from(y);
                assert!((p.dot(normal) - at).abs() < 1e-6, "{name}: off the plane");
                let v = slice.values.values[(y * w + x) as usize];
                if inside_grid(p, turn, centre, 1e-3) {
                    let want = field(p);
                    assert!(
                        (f64::from(v) - want).abs() < 1e-3 * want.abs().max(100.0),
                        "{name} pixel {x},{y}: {v} where the field is {want}"
                    );
                    inside += 1;
                } else if !inside_grid(p, turn, centre, -1e-3) {
                    assert!(
                        v.is_nan(),
                        "{name} pixel {x},{y} outside the grid holds {v}"
                    );
                }
                checked += 1;
            }
        }
        // The section's box is covered, and most of it by the volume.
        assert!(inside > checked / 3, "{name}: {inside} of {checked} inside");
    }
}

#[test]
fn the_patient_planes_are_seen_as_radiologists_read_them() {
    let scene = scene_of(field_volume(DMat3::IDENTITY, DVec3::ZERO), None);
    let dirs = |name: &str| {
        let p = Plane::of(&scene, spec(name), DVec3::ZERO, None).unwrap();
        (p.right, p.down)
    };
    // Axial from the feet: the patient's right on the left, anterior up.
    assert_eq!(dirs("axial"), (DVec3::NEG_X, DVec3::NEG_Y));
    // Coronal from the front: right on the left, superior up.
    assert_eq!(dirs("coronal"), (DVec3::NEG_X, DVec3::NEG_Z));
    // Sagittal from the left: anterior on the left, superior up.
    assert_eq!(dirs("sagittal"), (DVec3::NEG_Y, DVec3::NEG_Z));
}

/// A cylinder of radius 8 mm and length 40 mm, tilted: its axis and its placement.
fn tilted_cylinder() -> (CpuMesh, DMat4, DVec3, DVec3) {
    // About x, then about z (as scene files' rotate_degrees turn).
    let turn = DQuat::from_rotation_z(0.7) * DQuat::from_rotation_x(0.45);
    let at = DVec3::new(3.0, -2.0, 5.0);
    let placed = DMat4::from_rotation_translation(turn, at);
    (cylinder(8.0, 20.0, 256), placed, turn * DVec3::Z, at)
}

#[test]
fn a_cylinder_cut_across_along_and_obliquely_gives_its_closed_form_sections() {
    let (mesh, placed, axis, at) = tilted_cylinder();
    let scene = scene_of(
        field_volume(DMat3::IDENTITY, DVec3::ZERO),
        Some((mesh, placed)),
    );
    let (r, length, n) = (8.0f64, 40.0f64, 256.0f64);
    // The long axis is the cylinder's, its superior end up.
    let found = long_axis(&scene.object_triangles(scene.find("stem").unwrap()));
    assert!(found.unwrap().dot(axis).abs() > 1.0 - 1e-9, "{found:?}");
    let section = |name: &str| {
        let plane = Plane::of(&scene, spec(name), at, None).unwrap();
        let slice = Slice::new(&scene, plane, Pixels::Size(Some(0.5))).unwrap();
        assert_eq!(slice.outlines.len(), 1, "{name}");
        let o = slice.outlines[0].clone();
        for (points, closed) in &o.polylines {
            assert!(closed, "{name}: an open outline of a closed mesh");
            for p in points {
                assert!(
                    plane.distance(*p).abs() < 1e-9,
                    "{name}: a point off the plane"
                );
            }
        }
        (plane, o)
    };
    // Across the axis: the regular 256-gon inscribed in the circle.
    let (plane, o) = section("implant-cross");
    assert!(plane.normal.dot(axis).abs() > 1.0 - 1e-9);
    let polygon_area = 0.5 * n * r * r * (std::f64::consts::TAU / n).sin();
    let polygon_length = 2.0 * n * r * (std::f64::consts::PI / n).sin();
    assert!(
        (o.area_mm2 - polygon_area).abs() < 1e-6 * polygon_area,
        "{}",
        o.area_mm2
    );
    assert!((o.length_mm - polygon_length).abs() < 1e-6 * polygon_length);
    assert_eq!(o.polylines.len(), 1);
    // Across, 15 mm down the axis: the same circle (the plane follows the implant).
    let (_, o) = section("implant-cross@-15");
    assert!((o.area_mm2 - polygon_area).abs() < 1e-6 * polygon_area);
    // Along the axis: a rectangle 2r by the length, the width within the polygon's.
    let (plane, o) = section("implant-long");
    assert!(plane.normal.dot(axis).abs() < 1e-9);
    assert!(plane.down.dot(axis).abs() > 1.0 - 1e-9);
    let width = o.area_mm2 / length;
    assert!(
        width <= 2.0 * r + 1e-9 && width >= 2.0 * r * (std::f64::consts::PI / n).cos() - 1e-9,
        "{width}"
    );
    assert!((o.length_mm - 2.0 * (length + width)).abs() < 1e-6);
    // Obliquely (an axial plane through the middle): an ellipse, semi-axes r and r / cos t.
    let cos_t = axis.z.abs();
    let (_, o) = section("axial");
    let ellipse = std::f64::consts::PI * r * r / cos_t;
    assert!(
        (o.area_mm2 - ellipse).abs() < 1e-3 * ellipse,
        "{} {ellipse}",
        o.area_mm2
    );
    let (a, b) = (r / cos_t, r);
    let h = ((a - b) / (a + b)).powi(2);
    let ramanujan =
        std::f64::consts::PI * (a + b) * (1.0 + 3.0 * h / (10.0 + (4.0 - 3.0 * h).sqrt()));
    assert!((o.length_mm - ramanujan).abs() < 1e-3 * ramanujan);
    // A plane past the cylinder's end crosses nothing.
    let plane = Plane::of(&scene, spec("implant-cross@25"), at, None).unwrap();
    let slice = Slice::new(&scene, plane, Pixels::Size(Some(0.5))).unwrap();
    assert!(slice.outlines.is_empty());
}

#[test]
fn a_turned_cube_stored_a_vertex_a_corner_joins_into_one_square() {
    let placed =
        DMat4::from_rotation_translation(DQuat::from_rotation_z(0.5), DVec3::new(1.0, 2.0, 3.0));
    for mesh in [cube(12.0), unindexed(&cube(12.0))] {
        let scene = scene_of(
            field_volume(DMat3::IDENTITY, DVec3::ZERO),
            Some((mesh, placed)),
        );
        for at in ["axial@3", "axial@7.5", "axial@-2.999"] {
            let plane = Plane::of(&scene, spec(at), DVec3::ZERO, None).unwrap();
            let slice = Slice::new(&scene, plane, Pixels::Size(None)).unwrap();
            let o = &slice.outlines[0];
            assert_eq!(o.polylines.len(), 1, "{at}");
            assert!(o.polylines[0].1, "{at}: open");
            assert!((o.area_mm2 - 144.0).abs() < 1e-6, "{at}: {}", o.area_mm2);
            assert!((o.length_mm - 48.0).abs() < 1e-6, "{at}: {}", o.length_mm);
        }
    }
}

#[test]
fn measurements_show_on_the_slice_they_lie_in_only() {
    let mut scene = scene_of(field_volume(DMat3::IDENTITY, DVec3::ZERO), None);
    scene.measurements.push(SceneMeasurement {
        kind: MeasureKind::Distance,
        points: vec![DVec3::new(-10.0, 0.0, 5.0), DVec3::new(10.0, 0.0, 5.2)],
        node: None,
        anchors: Vec::new(),
        label: Some("width".into()),
    });
    let on = |name: &str| {
        let plane = Plane::of(&scene, spec(name), DVec3::ZERO, None).unwrap();
        // 0.8 mm voxels and pixels: half a slice is 0.4 mm.
        Slice::new(&scene, plane, Pixels::Size(None))
            .unwrap()
            .measurements
            .iter()
            .map(|m| m.text.clone())
            .collect::<Vec<_>>()
    };
    assert_eq!(on("axial@5.1"), ["width: 20.0 mm"]);
    assert!(on("axial@6").is_empty());
    assert!(on("axial@4.75").is_empty());
    assert_eq!(on("coronal@0"), ["width: 20.0 mm"]);
}

#[test]
fn planes_that_miss_unknown_meshes_and_round_meshes_are_refused_by_name() {
    let scene = scene_of(
        field_volume(DMat3::IDENTITY, DVec3::ZERO),
        Some((cube(10.0), DMat4::IDENTITY)),
    );
    let err =
        |name: &str, mesh: Option<&str>| match Plane::of(&scene, spec(name), DVec3::ZERO, mesh) {
            Ok(plane) => Slice::new(&scene, plane, Pixels::Size(None)).unwrap_err(),
            Err(e) => e,
        };
    let e = err("axial@80", None);
    assert!(matches!(e, SliceError::Misses { .. }), "{e}");
    let said = e.to_string();
    assert!(
        said.contains("axial@80") && said.contains("-38.00 to 38.00"),
        "{said}"
    );
    let said = err("implant-long", Some("glenoid")).to_string();
    assert!(
        said.contains("glenoid") && said.contains("\"stem\""),
        "{said}"
    );
    // A cube is as long every way: no axis to follow.
    let said = err("implant-cross", None).to_string();
    assert!(
        said.contains("no long axis") && said.contains("stem"),
        "{said}"
    );
    let bare = scene_of(field_volume(DMat3::IDENTITY, DVec3::ZERO), None);
    let said = Plane::of(&bare, spec("implant-long"), DVec3::ZERO, None)
        .unwrap_err()
        .to_string();
    assert!(said.contains("no mesh"), "{said}");
    let plane = Plane::of(&scene, spec("axial"), DVec3::ZERO, None).unwrap();
    for bad in [0.0, -1.0, f64::NAN] {
        assert!(matches!(
            Slice::new(&scene, plane, Pixels::Size(Some(bad))),
            Err(SliceError::BadPixelSize(_))
        ));
    }
    assert!(matches!(
        Slice::new(&scene, plane, Pixels::Size(Some(1e-4))),
        Err(SliceError::TooLarge { .. })
    ));
    assert_eq!(spec("sagittal@2").kind, PlaneKind::Sagittal);
}

#[test]
fn a_tube_encloses_its_wall_not_its_bore() {
    let (outer, inner) = (cylinder(8.0, 20.0, 128), cylinder(5.0, 20.0, 128));
    let mut tube = outer.clone();
    let base = tube.positions.len() as u32;
    tube.positions.extend(&inner.positions);
    tube.indices.extend(inner.indices.iter().map(|i| i + base));
    tube.compute_normals();
    let scene = scene_of(
        field_volume(DMat3::IDENTITY, DVec3::ZERO),
        Some((tube, DMat4::IDENTITY)),
    );
    let plane = Plane::of(&scene, spec("axial@2"), DVec3::ZERO, None).unwrap();
    let o = &Slice::new(&scene, plane, Pixels::Size(None))
        .unwrap()
        .outlines[0];
    let gon = |r: f64| 0.5 * 128.0 * r * r * (std::f64::consts::TAU / 128.0).sin();
    assert_eq!(o.polylines.len(), 2);
    assert!(
        (o.area_mm2 - (gon(8.0) - gon(5.0))).abs() < 1e-6,
        "{}",
        o.area_mm2
    );
}

/// Writes [`field_volume`] (axis-aligned, centred on the origin) as raw f32 and the tilted
/// cylinder as OBJ; returns the arguments that load both.
fn files_on_disk(dir: &std::path::Path) -> Vec<String> {
    let raw = dir.join("field.raw");
    write_raw_f32(&raw, &field_volume(DMat3::IDENTITY, DVec3::ZERO));
    let (mesh, _, _, _) = tilted_cylinder();
    let obj = dir.join("stem.obj");
    std::fs::write(&obj, obj_text(&mesh)).unwrap();
    let origin = -0.5 * 0.8 * 95.0;
    vec![
        "render".into(),
        raw.to_str().unwrap().into(),
        "--dims".into(),
        "96,96,96".into(),
        "--scalar".into(),
        "f32".into(),
        "--spacing".into(),
        "0.8,0.8,0.8".into(),
        "--origin".into(),
        format!("{origin},{origin},{origin}"),
        "--mesh".into(),
        obj.to_str().unwrap().into(),
        // The tilted cylinder's placement: 0.45 rad about x, then 0.7 about z.
        "--mesh-transform".into(),
        format!(
            "{{ rotate_degrees = [{}, 0, {}], translate = [3, -2, 5] }}",
            0.45f64.to_degrees(),
            0.7f64.to_degrees()
        ),
    ]
}

fn run(base: &[String], extra: &[&str]) -> std::process::Output {
    let mut args: Vec<&str> = base.iter().map(String::as_str).collect();
    args.extend_from_slice(extra);
    ok(&args)
}

fn refused(base: &[String], extra: &[&str]) -> String {
    let mut args: Vec<&str> = base.iter().map(String::as_str).collect();
    args.extend_from_slice(extra);
    fails(&args)
}

fn json(path: &std::path::Path) -> Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

#[test]
fn the_command_line_writes_calibrated_slices_whose_pixels_follow_from_their_json() {
    let dir = scratch("slices");
    let base = files_on_disk(&dir);
    let out = dir.join("fit-{slice}.png");
    let out = out.to_str().unwrap();
    let said = run(
        &base,
        &[
            "--slice",
            "implant-cross,axial@1.5",
            "--window",
            "-200,200",
            "--out",
            out,
        ],
    );
    let said = String::from_utf8_lossy(&said.stderr).into_owned();
    assert!(said.contains("implant-cross slice"), "{said}");
    for name in ["implant-cross", "axial@1.5"] {
        let png = dir.join(format!("fit-{name}.png"));
        let c = json(&dir.join(format!("fit-{name}.json")));
        assert_eq!(c["plane"], name);
        assert_eq!(c["window"], serde_json::json!([-200.0, 200.0]));
        let image = image::open(&png).unwrap().to_rgba8();
        assert_eq!(
            [image.width(), image.height()],
            [
                c["size"][0].as_u64().unwrap() as u32,
                c["size"][1].as_u64().unwrap() as u32
            ]
        );
        // The PNG carries the calibration too.
        let decoder =
            png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&png).unwrap()));
        let reader = decoder.read_info().unwrap();
        let keys: Vec<&str> = reader
            .info()
            .uncompressed_latin1_text
            .iter()
            .map(|t| t.keyword.as_str())
            .collect();
        for key in [
            "splatscene:frame",
            "splatscene:origin_mm",
            "splatscene:pixel_right_mm",
        ] {
            assert!(keys.contains(&key), "{name}: {keys:?}");
        }
        let origin = vector(&c["origin_mm"]);
        let right = vector(&c["pixel_right_mm"]);
        let down = vector(&c["pixel_down_mm"]);
        let world = |x: f64, y: f64| origin + right * x + down * y;
        let pixel = |p: DVec3| {
            let d = p - origin;
            [
                d.dot(right) / right.length_squared(),
                d.dot(down) / down.length_squared(),
            ]
        };
        // The cylinder's section, computed here: the points of the plane at radius 8 from the
        // axis (for implant-cross a circle about the pivot, for axial an ellipse).
        let (_, placed, axis, at) = tilted_cylinder();
        let _ = placed;
        let radius = |p: DVec3| {
            let d = p - at;
            (d - axis * d.dot(axis)).length()
        };
        let (mut grey_checked, mut outline_checked) = (0, 0);
        for y in 0..image.height() {
            for x in 0..image.width() {
                let p = world(f64::from(x), f64::from(y));
                let px = image.get_pixel(x, y).0;
                let r = radius(p);
                let along = (p - at).dot(axis).abs();
                let near_outline = (r - 8.0).abs() < 0.8 * 4.0 && along < 21.0;
                if !near_outline {
                    // Grey by the window, from the field at the calibrated point.
                    let inside = p.abs().max_element() <= 38.0 - 1e-3;
                    if inside {
                        let want = ((field(p) + 200.0) / 400.0).clamp(0.0, 1.0) * 255.0;
                        assert!(
                            (f64::from(px[0]) - want).abs() <= 1.0,
                            "{name} pixel {x},{y}: {} where the field gives {want}",
                            px[0]
                        );
                        grey_checked += 1;
                    }
                } else if (r - 8.0).abs() < 0.05 && along < 19.0 {
                    // On the outline: the mesh's colour (0.8 grey, 204 as the 3D figures
                    // write it), whatever the field's grey there.
                    assert!(
                        px[0].abs_diff(204) <= 10,
                        "{name} pixel {x},{y} on the outline is {px:?}"
                    );
                    outline_checked += 1;
                }
            }
        }
        assert!(
            grey_checked > 1000 && outline_checked > 4,
            "{name}: {grey_checked} {outline_checked}"
        );
        // The outline's reported size: the circle (256-gon) across the axis.
        if name == "implant-cross" {
            let area = c["meshes"][0]["area_mm2"].as_f64().unwrap();
            assert!(
                (area - std::f64::consts::PI * 64.0).abs() < 0.01 * 64.0 * 3.2,
                "{area}"
            );
            let [cx, cy] = pixel(at);
            assert!(cx > 0.0 && cy > 0.0, "the pivot lies on the slice");
        }
    }
}

#[test]
fn the_command_line_refuses_slices_it_cannot_draw_and_names_why() {
    let dir = scratch("slice-errors");
    let base = files_on_disk(&dir);
    let out = dir.join("s.png");
    let out = out.to_str().unwrap();
    let cases: [(&[&str], &[&str]); 10] = [
        (
            &["--slice", "oblique"],
            &["oblique", "axial, coronal, sagittal"],
        ),
        (
            &["--slice", "axial@300"],
            &["axial@300", "misses", "-38.00 to 38.00"],
        ),
        (&["--slice", "axial,coronal"], &["{slice}"]),
        (
            &["--slice", "implant-long", "--slice-mesh", "glenoid"],
            &["glenoid", "stem.obj"],
        ),
        (
            &["--slice", "axial", "--slice-mesh", "stem.obj"],
            &["--slice-mesh", "no effect"],
        ),
        (
            &["--slice", "axial", "--view", "anterior,superior"],
            &["one --view"],
        ),
        (
            &["--slice", "axial", "--slice-mm-per-pixel", "0"],
            &["positive"],
        ),
        (&["--slice", "axial", "--depth", "d.png"], &["--depth"]),
        (
            &["--slice", "axial", "--size", "300x200"],
            &["--size", "no effect"],
        ),
        (
            &["--slice", "axial", "--ordering", "btf"],
            &["--ordering", "no effect"],
        ),
    ];
    for (extra, words) in cases {
        let mut args = extra.to_vec();
        args.extend(["--out", out]);
        let said = refused(&base, &args);
        for w in words {
            assert!(said.contains(w), "{extra:?}: {said}");
        }
    }
    // A slice never writes over an input: here the volume itself.
    let raw = dir.join("field.raw");
    let raw = raw.to_str().unwrap();
    let before = std::fs::read(raw).unwrap();
    let said = refused(&base, &["--slice", "axial", "--out", raw]);
    assert!(said.contains("field.raw"), "{said}");
    assert_eq!(std::fs::read(raw).unwrap(), before);
}

#[test]
fn a_scene_file_lists_its_slices_and_the_quad_layout_puts_the_planes_together() {
    let dir = scratch("slice-scene");
    let base = files_on_disk(&dir);
    let origin = -0.5 * 0.8 * 95.0;
    let scene = format!(
        r#"
[[volume]]
path = "field.raw"
dims = [96, 96, 96]
scalar = "f32"
spacing = [0.8, 0.8, 0.8]
origin = [{origin}, {origin}, {origin}]
transfer = "ramp"
window = [-200.0, 200.0]

[[mesh]]
name = "stem"
path = "stem.obj"
color = [0.9, 0.2, 0.1]
transform = {{ rotate_degrees = [{}, 0, {}], translate = [3, -2, 5] }}

[[slice]]
plane = "implant-long"
mesh = "stem"
mm_per_pixel = 0.4

[[slice]]
plane = "coronal@-2"
"#,
        0.45f64.to_degrees(),
        0.7f64.to_degrees()
    );
    let file = dir.join("plan.toml");
    std::fs::write(&file, &scene).unwrap();
    let file = file.to_str().unwrap();
    let out = dir.join("plan-{slice}.png");
    ok(&["render", file, "--out", out.to_str().unwrap()]);
    let c = json(&dir.join("plan-implant-long.json"));
    assert_eq!(c["mm_per_pixel"], 0.4);
    assert_eq!(c["meshes"][0]["name"], "stem");
    assert!(dir.join("plan-coronal@-2.png").is_file());
    // `--slice none` draws the 3D view of such a scene.
    let view = dir.join("view.png");
    ok(&[
        "render",
        file,
        "--slice",
        "none",
        "--size",
        "64x48",
        "--out",
        view.to_str().unwrap(),
    ]);
    assert_eq!(image::open(&view).unwrap().width(), 64);
    // A key with no effect where it stands is refused, naming the slice.
    let bad = scene.replace(
        "plane = \"coronal@-2\"",
        "plane = \"coronal@-2\"\nmesh = \"stem\"",
    );
    std::fs::write(dir.join("bad.toml"), bad).unwrap();
    let said = fails(&[
        "render",
        dir.join("bad.toml").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        said.contains("coronal@-2") && said.contains("mesh has no effect"),
        "{said}"
    );

    // The quad: the 3D view and the three planes through the target moved to z = 1.
    let quad = dir.join("quad.png");
    ok(&[
        "render",
        file,
        "--layout",
        "quad",
        "--slice",
        "axial@1",
        "--size",
        "320x240",
        "--out",
        quad.to_str().unwrap(),
    ]);
    let image = image::open(&quad).unwrap().to_rgba8();
    assert_eq!((image.width(), image.height()), (320, 240));
    let c = json(&dir.join("quad.json"));
    assert_eq!(c["layout"], "quad");
    let point = vector(&c["point_mm"]);
    assert!((point.z - 1.0).abs() < 1e-9);
    let panes = c["panes"].as_array().unwrap();
    let names: Vec<&str> = panes.iter().map(|p| p["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["3d", "axial", "sagittal", "coronal"]);
    for pane in &panes[1..] {
        // The pane's calibration, in the figure's pixels, puts the point where its lines
        // cross: the line along the rows in one plane's colour, along the columns another's.
        let origin = vector(&pane["origin_mm"]);
        let right = vector(&pane["pixel_right_mm"]);
        let down = vector(&pane["pixel_down_mm"]);
        let d = point - origin;
        let (x, y) = (
            (d.dot(right) / right.length_squared()).round() as u32,
            (d.dot(down) / down.length_squared()).round() as u32,
        );
        let rect: Vec<u32> = pane["rect"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap() as u32)
            .collect();
        assert!(x >= rect[0] && x < rect[0] + rect[2] && y >= rect[1] && y < rect[1] + rect[3]);
        let colours = [[241, 89, 70], [110, 176, 75], [237, 214, 80]];
        let row = image.get_pixel(rect[0] + 3, y).0;
        let column = image.get_pixel(x, rect[1] + rect[3] - 4).0;
        assert!(
            colours.iter().any(|c| c[..] == row[..3]),
            "{}: row {row:?}",
            pane["name"]
        );
        assert!(
            colours.iter().any(|c| c[..] == column[..3]),
            "{}: column {column:?}",
            pane["name"]
        );
        assert_ne!(row, column);
    }
    let _ = base;
}

#[test]
fn overlapping_parts_of_one_object_enclose_their_union() {
    let mut scene = scene_of(field_volume(DMat3::IDENTITY, DVec3::ZERO), None);
    let top = scene
        .add("implant", DMat4::IDENTITY, None, NodeContent::Empty)
        .unwrap();
    for (name, x) in [("head", 0.0), ("neck", 5.0)] {
        let part = MeshNode {
            mesh: Arc::new(cube(10.0)),
            material: Material::default(),
        };
        scene
            .add(
                name,
                DMat4::from_translation(DVec3::new(x, 0.0, 0.0)),
                Some(top),
                NodeContent::Mesh(part),
            )
            .unwrap();
    }
    let plane = Plane::of(&scene, spec("axial@1"), DVec3::ZERO, None).unwrap();
    let slice = Slice::new(&scene, plane, Pixels::Size(None)).unwrap();
    assert_eq!(slice.outlines.len(), 1);
    let o = &slice.outlines[0];
    assert_eq!(o.name, "implant");
    assert_eq!(o.polylines.len(), 2);
    // 15 by 10 mm: the overlap counted once.
    assert!((o.area_mm2 - 150.0).abs() < 1e-6, "{}", o.area_mm2);
    assert!((o.length_mm - 80.0).abs() < 1e-6, "{}", o.length_mm);
}
