//! The bone-contact map against answers known in closed form: a value field linear in world z
//! (which trilinear interpolation reproduces exactly), an axis-aligned box (its area below a
//! height by hand), an oblique box (each face clipped by the plane, an exact polygon area) and
//! a sphere (Archimedes: a zone's area is proportional to its height), within 2%; a mesh partly
//! and wholly outside the volume; and the errors a user meets.

use std::sync::Arc;

use glam::{DMat3, DMat4, DQuat, DVec3};
use splatscene::mesh::{CpuMesh, Material};
use splatscene::pick::contact::{Classes, ContactError, contact};
use splatscene::pick::paint::paint;
use splatscene::scene::{MeshNode, NodeContent, ObjectError, Scene};
use splatscene::volume::CpuVolume;

mod common;
use common::shapes::{cube, obj_text, scene_of, sphere, write_raw_f32};
use common::{fails, ok, scratch};

/// Value per millimetre of world z.
const SLOPE: f64 = 10.0;

/// A 128^3 volume of 0.5 mm voxels centred on the origin, its value `SLOPE * z` (world z).
fn ramp_volume() -> CpuVolume {
    let n = 128u32;
    let spacing = 0.5;
    let origin = -0.5 * spacing * f64::from(n - 1);
    let values = (0..n * n * n)
        .map(|id| {
            let z = origin + spacing * f64::from(id / (n * n));
            (SLOPE * z) as f32
        })
        .collect();
    CpuVolume {
        dims: [n; 3],
        spacing: [spacing; 3],
        origin: [origin; 3],
        direction: DMat3::IDENTITY,
        values,
    }
}

fn scene_with(mesh: CpuMesh, placed: DMat4) -> Scene {
    scene_of(ramp_volume(), Some((mesh, placed)))
}

/// The area of the part of convex polygon `poly` (world points) where z < `h`: the polygon
/// clipped by the plane (Sutherland-Hodgman), its area by the cross products of a fan.
fn area_below(poly: &[DVec3], h: f64) -> f64 {
    let mut kept = Vec::new();
    for (i, &a) in poly.iter().enumerate() {
        let b = poly[(i + 1) % poly.len()];
        if a.z < h {
            kept.push(a);
        }
        if (a.z < h) != (b.z < h) {
            kept.push(a + (b - a) * ((h - a.z) / (b.z - a.z)));
        }
    }
    (1..kept.len().saturating_sub(1))
        .map(|i| 0.5 * (kept[i] - kept[0]).cross(kept[i + 1] - kept[0]).length())
        .sum()
}

/// The six faces of the cube of side `side` placed by `m`, as world quads.
fn cube_faces(side: f64, m: DMat4) -> Vec<Vec<DVec3>> {
    let h = side / 2.0;
    let mut faces = Vec::new();
    for axis in 0..3 {
        for sign in [-1.0, 1.0] {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let face = [(-h, -h), (h, -h), (h, h), (-h, h)]
                .map(|(a, b)| {
                    let mut p = DVec3::ZERO;
                    p[axis] = sign * h;
                    p[u] = a;
                    p[v] = b;
                    m.transform_point3(p)
                })
                .to_vec();
            faces.push(face);
        }
    }
    faces
}

/// Checks the contact of a 20 mm cube placed by `m` against the clipped faces.
fn check_cube(m: DMat4) {
    let side = 20.0;
    let scene = scene_with(cube(side as f32), m);
    let edges = [SLOPE * -4.0, SLOPE * 3.0];
    let report = contact(&scene, Some("stem"), &Classes::from_edges(&edges).unwrap()).unwrap();
    let faces = cube_faces(side, m);
    let total = 6.0 * side * side;
    assert!((report.area_mm2 - total).abs() < 1e-6 * total, "{report:?}");
    assert_eq!(report.outside_mm2, 0.0);
    let below = |e: f64| faces.iter().map(|f| area_below(f, e / SLOPE)).sum::<f64>();
    let expected = [
        below(edges[0]),
        below(edges[1]) - below(edges[0]),
        total - below(edges[1]),
    ];
    for (class, want) in report.classes.iter().zip(expected) {
        assert!(
            (class.fraction - want / total).abs() < 0.02,
            "{}: {} against {} ({report:?})",
            class.name,
            class.fraction,
            want / total
        );
    }
    let sum: f64 = report.classes.iter().map(|c| c.fraction).sum();
    assert!((sum - 1.0).abs() < 1e-9, "{sum}");
    // The mean of a linear field over a centred symmetric surface is its value at the centre.
    let value = report.value.unwrap();
    let centre = SLOPE * m.w_axis.z;
    assert!(
        (value.mean - centre).abs() < 0.01 * SLOPE * side,
        "{value:?}"
    );
    let lowest = faces
        .iter()
        .flatten()
        .map(|p| p.z)
        .fold(f64::INFINITY, f64::min);
    let highest = faces
        .iter()
        .flatten()
        .map(|p| p.z)
        .fold(f64::NEG_INFINITY, f64::max);
    assert!(value.min >= SLOPE * lowest - 1e-3 && value.min < SLOPE * (lowest + 1.0));
    assert!(value.max <= SLOPE * highest + 1e-3 && value.max > SLOPE * (highest - 1.0));
}

#[test]
fn an_axis_aligned_box_splits_by_height_as_its_faces_do() {
    check_cube(DMat4::from_translation(DVec3::new(2.0, -3.0, 1.5)));
}

#[test]
fn an_oblique_box_splits_as_its_faces_clipped_by_the_planes_do() {
    let turn = DQuat::from_rotation_x(0.5) * DQuat::from_rotation_y(-0.8);
    check_cube(DMat4::from_rotation_translation(
        turn,
        DVec3::new(-1.0, 2.0, -2.5),
    ));
}

#[test]
fn a_sphere_splits_by_height_as_archimedes_says() {
    let r = 15.0;
    let centre = DVec3::new(1.0, 0.5, -2.0);
    let scene = scene_with(sphere(r as f32, 90, 180), DMat4::from_translation(centre));
    // Zones of the sphere between heights: area 2 pi r dh.
    let cuts = [-9.0, -2.0, 6.5];
    let edges = cuts.map(|c| SLOPE * (centre.z + c));
    let report = contact(&scene, None, &Classes::from_edges(&edges).unwrap()).unwrap();
    assert_eq!(report.mesh, "stem");
    let bounds = [-r, cuts[0], cuts[1], cuts[2], r];
    for (i, class) in report.classes.iter().enumerate() {
        let want = (bounds[i + 1] - bounds[i]) / (2.0 * r);
        assert!(
            (class.fraction - want).abs() < 0.02,
            "{}: {} against {want}",
            class.name,
            class.fraction
        );
    }
    let area = 4.0 * std::f64::consts::PI * r * r;
    assert!(
        (report.area_mm2 - area).abs() < 0.02 * area,
        "{}",
        report.area_mm2
    );
    assert!((report.value.unwrap().mean - SLOPE * centre.z).abs() < 0.01 * SLOPE * r);
}

#[test]
fn a_mesh_outside_the_volume_is_reported_outside_never_as_a_value() {
    // The volume spans -31.75..31.75 mm; a 20 mm box centred at x = 30 is half outside.
    let scene = scene_with(
        cube(20.0),
        DMat4::from_translation(DVec3::new(31.75, 0.0, 0.0)),
    );
    let report = contact(&scene, None, &Classes::ct()).unwrap();
    let total = 2400.0;
    // Outside: the x = +10 face (400) and half of the four faces around x (4 x 200).
    assert!(
        (report.outside_mm2 - 1200.0).abs() < 0.02 * total,
        "{report:?}"
    );
    let sum: f64 = report.classes.iter().map(|c| c.fraction).sum::<f64>() + report.outside_fraction;
    assert!((sum - 1.0).abs() < 1e-9);
    let far = scene_with(
        cube(20.0),
        DMat4::from_translation(DVec3::new(500.0, 0.0, 0.0)),
    );
    let report = contact(&far, None, &Classes::ct()).unwrap();
    assert_eq!(report.outside_fraction, 1.0);
    assert_eq!(report.value, None);
    assert!(
        report
            .classes
            .iter()
            .all(|c| c.area_mm2 == 0.0 && c.fraction == 0.0)
    );
    let json = serde_json::to_string(&report).unwrap();
    assert!(
        !json.contains("NaN") && json.contains("\"value\":null"),
        "{json}"
    );
}

#[test]
fn a_missing_mesh_or_volume_and_bad_edges_are_named() {
    let scene = scene_with(cube(10.0), DMat4::IDENTITY);
    let err = contact(&scene, Some("glenoid"), &Classes::ct()).unwrap_err();
    assert!(
        matches!(err, ContactError::Mesh(ObjectError::NoMesh { .. }))
            && err.to_string().contains("glenoid")
            && err.to_string().contains("\"stem\""),
        "{err}"
    );
    let mut meshes_only = Scene::new();
    meshes_only
        .add(
            "stem",
            DMat4::IDENTITY,
            None,
            NodeContent::Mesh(MeshNode {
                mesh: Arc::new(cube(10.0)),
                material: Material::default(),
            }),
        )
        .unwrap();
    assert!(matches!(
        contact(&meshes_only, None, &Classes::ct()),
        Err(ContactError::NoVolume)
    ));
    assert!(matches!(
        Classes::from_edges(&[700.0, 200.0]),
        Err(ContactError::BadEdges(_))
    ));
}

#[test]
fn the_command_line_prints_the_contact_of_a_mesh_given_beside_a_volume() {
    let dir = scratch("contact");
    let raw = dir.join("ramp.raw");
    write_raw_f32(&raw, &ramp_volume());
    let stl = dir.join("box.obj");
    std::fs::write(&stl, obj_text(&cube(20.0))).unwrap();
    let s = |p: &std::path::Path| p.to_str().unwrap().to_owned();
    let origin = format!("{0},{0},{0}", -0.5 * 0.5 * 127.0);
    let base = [
        "contact".to_owned(),
        s(&raw),
        "--dims".into(),
        "128,128,128".into(),
        "--scalar".into(),
        "f32".into(),
        "--spacing".into(),
        "0.5,0.5,0.5".into(),
        "--origin".into(),
        origin,
        "--mesh".into(),
        s(&stl),
    ];
    let run = |extra: &[&str]| {
        let mut args: Vec<&str> = base.iter().map(String::as_str).collect();
        args.extend_from_slice(extra);
        ok(&args)
    };
    let out = run(&["--classes", "-40,30"]);
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(report["mesh"], "box.obj");
    assert!((report["area_mm2"].as_f64().unwrap() - 2400.0).abs() < 1e-3);
    let names: Vec<&str> = report["classes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["below -40", "-40 to 30", "30 and above"]);
    assert!(report["classes"][0]["min"].is_null() && report["classes"][2]["max"].is_null());
    // The box spans z -10..10 mm: values -100..100; below -40: the bottom face and 6 mm of
    // each side, (400 + 4 x 120) / 2400.
    let below = report["classes"][0]["fraction"].as_f64().unwrap();
    assert!((below - 880.0 / 2400.0).abs() < 0.02, "{below}");
    // A name that is no file and no mesh of the scene, and edges that do not increase.
    let mut args: Vec<&str> = base.iter().map(String::as_str).collect();
    args.extend_from_slice(&["--mesh", "glenoid"]);
    let said = fails(&args);
    assert!(
        said.contains("glenoid") && said.contains("box.obj"),
        "{said}"
    );
    let mut args: Vec<&str> = base.iter().map(String::as_str).collect();
    args.extend_from_slice(&["--classes", "700,200"]);
    let said = fails(&args);
    assert!(said.contains("increasing"), "{said}");
}

/// The area of a triangle list.
fn area_of(mesh: &CpuMesh, placed: DMat4) -> f64 {
    mesh.indices
        .chunks_exact(3)
        .map(|t| {
            let p = |i: u32| {
                placed.transform_point3(DVec3::from(mesh.positions[i as usize].map(f64::from)))
            };
            0.5 * (p(t[1]) - p(t[0])).cross(p(t[2]) - p(t[0])).length()
        })
        .sum()
}

#[test]
fn a_painted_surface_keeps_its_area_and_each_vertex_has_the_colour_of_the_value_there() {
    // A sphere whose top rises out of the volume (whose last voxel centres lie 31.75 mm above
    // the origin; the contact counts half a voxel beyond them, to 32 mm).
    let placed = DMat4::from_translation(DVec3::new(2.0, -3.0, 25.0));
    let original = sphere(10.0, 24, 48);
    let scene = scene_with(original.clone(), placed);
    let range = [-100.0, 300.0];
    let painted = paint(&scene, None, range).unwrap();
    assert_eq!(painted.meshes.len(), 1);
    let (_, node) = &painted.meshes[0];
    let mesh = &node.mesh;
    assert_eq!(node.material.base_color, [1.0, 1.0, 1.0, 1.0]);
    assert_eq!(mesh.colors.len(), mesh.positions.len());
    let (before, after) = (area_of(&original, placed), area_of(mesh, placed));
    assert!((before - after).abs() < 1e-4 * before, "{before} {after}");
    let (mut inside, mut outside) = (0, 0);
    for t in mesh.indices.chunks_exact(3) {
        let p = |i: u32| DVec3::from(mesh.positions[i as usize].map(f64::from));
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            assert!((p(a) - p(b)).length() <= painted.step_mm + 1e-4);
        }
    }
    for (p, c) in mesh.positions.iter().zip(&mesh.colors) {
        let world = placed.transform_point3(DVec3::from(p.map(f64::from)));
        if world.z > 32.0 + 1e-3 {
            assert_eq!(*c, [0.45, 0.45, 0.45, 1.0], "outside the volume: grey");
            outside += 1;
        } else if world.z < 31.75 - 1e-3 {
            // The ramp's value there, through viridis, computed here.
            let t = ((SLOPE * world.z - range[0]) / (range[1] - range[0])).clamp(0.0, 1.0);
            let v = colorous::VIRIDIS.eval_continuous(t);
            let want = [v.r, v.g, v.b].map(|x| f32::from(x) / 255.0);
            for k in 0..3 {
                assert!(
                    (c[k] - want[k]).abs() <= 1.5 / 255.0,
                    "z {}: {c:?} {want:?}",
                    world.z
                );
            }
            inside += 1;
        }
    }
    assert!(inside > 1000 && outside > 100, "{inside} {outside}");
    // Colour ranges that mean nothing are refused.
    for bad in [[1.0, 1.0], [2.0, 1.0], [f64::NAN, 1.0]] {
        assert!(paint(&scene, None, bad).is_err());
    }
}

#[test]
fn render_paints_the_contact_map_with_its_colour_bar() {
    let dir = scratch("contact-map");
    let raw = dir.join("ramp.raw");
    write_raw_f32(&raw, &ramp_volume());
    std::fs::write(dir.join("box.obj"), obj_text(&cube(20.0))).unwrap();
    let origin = -0.5 * 0.5 * 127.0;
    // The volume left out of the picture (every voxel at or below the least opacity), so that
    // the painted box shows whole.
    std::fs::write(
        dir.join("plan.toml"),
        format!(
            r#"
[[volume]]
path = "ramp.raw"
dims = [128, 128, 128]
scalar = "f32"
spacing = [0.5, 0.5, 0.5]
origin = [{origin}, {origin}, {origin}]
transfer = "ramp"
window = [-100.0, 100.0]
color = [1.0, 1.0, 1.0, 0.5]
min_opacity = 0.9

[[mesh]]
name = "box"
path = "box.obj"
"#
        ),
    )
    .unwrap();
    let out = dir.join("map.png");
    let said = ok(&[
        "render",
        dir.join("plan.toml").to_str().unwrap(),
        "--contact",
        "--view",
        "anterior",
        "--orthographic",
        "40",
        "--size",
        "200x200",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        common::stderr(&said).contains("contact map"),
        "{}",
        common::stderr(&said)
    );
    let image = image::open(&out).unwrap().to_rgba8();
    // The box's front face spans z -10 to 10 mm, values -100 to 100: the window's whole map,
    // dark purple at the bottom (blue over green), yellow at the top (green over blue).
    // The box's rows: the column's coloured pixels (the text is white or grey).
    let coloured = |p: [u8; 4]| p[..3].iter().max().unwrap() - p[..3].iter().min().unwrap() > 30;
    let rows: Vec<u32> = (0..200)
        .filter(|&y| coloured(image.get_pixel(100, y).0))
        .collect();
    let (top, bottom) = (rows[0], rows[rows.len() - 1]);
    assert!(bottom - top > 20, "the box spans rows {top} to {bottom}");
    let (low, high) = (
        image.get_pixel(100, bottom - 2).0,
        image.get_pixel(100, top + 2).0,
    );
    assert!(low[2] > low[1] + 20, "bottom of the box {low:?}");
    assert!(
        high[1] > high[2] + 60 && high[0] > high[2] + 60,
        "top of the box {high:?}"
    );
    // The colour bar: filled straight, its top the map's yellow.
    let bar = (150..200)
        .rev()
        .map(|x| image.get_pixel(x, 31).0)
        .find(|p| p[2] < 80 && p[1] > 200);
    assert!(bar.is_some(), "no yellow colour bar at the top right");
    // Slices outline instead; a mesh that is not there is named.
    let said = fails(&[
        "render",
        dir.join("plan.toml").to_str().unwrap(),
        "--contact",
        "--slice",
        "axial",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(said.contains("--contact"), "{said}");
    let said = fails(&[
        "render",
        dir.join("plan.toml").to_str().unwrap(),
        "--contact",
        "glenoid",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        said.contains("glenoid") && said.contains("\"box\""),
        "{said}"
    );
}
