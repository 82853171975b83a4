//! From a patient's volume to a report figure through the command line, as a planning engineer
//! works: volumes and meshes straight from the command line, the patient frame, upright orbits,
//! named views, annotations and calibrated depth. Real data come from `SPLATSCENE_DATA`; under
//! CI (`CI` set) a missing file fails the test instead of skipping it.

use std::path::{Path, PathBuf};

use image::RgbaImage;

mod common;
use common::{data_file as data, fails, ok, scratch, stderr};

fn s(path: &Path) -> &str {
    path.to_str().unwrap()
}

fn read(path: &Path) -> RgbaImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgba8()
}

/// Pixels brighter than the background (bone, splats, meshes) in a region.
fn bright(image: &RgbaImage, x: std::ops::Range<u32>, y: std::ops::Range<u32>) -> usize {
    y.flat_map(|j| x.clone().map(move |i| (i, j)))
        .filter(|&(i, j)| {
            let p = image.get_pixel(i, j);
            u32::from(p[0]) + u32::from(p[1]) + u32::from(p[2]) > 240
        })
        .count()
}

/// The centroid of the bright pixels, as fractions of width and height.
fn centroid(image: &RgbaImage) -> Option<(f64, f64)> {
    let (mut sx, mut sy, mut n) = (0.0, 0.0, 0.0);
    for (x, y, p) in image.enumerate_pixels() {
        if u32::from(p[0]) + u32::from(p[1]) + u32::from(p[2]) > 240 {
            sx += f64::from(x);
            sy += f64::from(y);
            n += 1.0;
        }
    }
    (n > 0.0).then(|| {
        (
            sx / n / f64::from(image.width()),
            sy / n / f64::from(image.height()),
        )
    })
}

/// Pearson correlation of two images' grey values.
fn correlation(a: &RgbaImage, b: &RgbaImage) -> f64 {
    let grey = |p: &image::Rgba<u8>| f64::from(p[0]) + f64::from(p[1]) + f64::from(p[2]);
    let (xa, xb): (Vec<f64>, Vec<f64>) = a
        .pixels()
        .zip(b.pixels())
        .map(|(p, q)| (grey(p), grey(q)))
        .unzip();
    let n = xa.len() as f64;
    let (ma, mb) = (xa.iter().sum::<f64>() / n, xb.iter().sum::<f64>() / n);
    let cov: f64 = xa.iter().zip(&xb).map(|(a, b)| (a - ma) * (b - mb)).sum();
    let va: f64 = xa.iter().map(|a| (a - ma).powi(2)).sum();
    let vb: f64 = xb.iter().map(|b| (b - mb).powi(2)).sum();
    cov / (va * vb).sqrt()
}

/// A raw u8 volume of 24^3 voxels, empty but for two bright blocks: a large one at high index
/// z (the far end of the third axis) and a small one at high index x, low z.
fn marker_volume(dir: &Path) -> PathBuf {
    let n = 24usize;
    let mut bytes = vec![0u8; n * n * n];
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let top = z >= 18 && (6..18).contains(&x) && (6..18).contains(&y);
                let side = x >= 20 && z < 6 && (9..15).contains(&y);
                if top || side {
                    bytes[x + n * (y + n * z)] = 220;
                }
            }
        }
    }
    let path = dir.join("markers.raw");
    std::fs::write(&path, bytes).unwrap();
    path
}

#[test]
fn a_raw_volume_is_placed_by_its_orientation_and_seen_upright_from_named_views() {
    let dir = scratch("orientation");
    let raw = marker_volume(&dir);
    let raw_args = |orientation: &'static str| {
        vec![
            "--dims",
            "24,24,24",
            "--scalar",
            "u8",
            "--spacing",
            "2,2,2",
            "--orientation",
            orientation,
            "--window",
            "100,200",
        ]
    };
    // RAS: index z runs superior, index x to the patient's right. Seen from the front the big
    // block is at the top and the small one on the left of the picture (the patient's right).
    let ras = dir.join("ras-{view}.png");
    let mut args = vec![
        "render",
        s(&raw),
        "--out",
        s(&ras),
        "--size",
        "160x160",
        "--view",
        "anterior,posterior,superior",
    ];
    args.extend(raw_args("RAS"));
    let out = ok(&args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("anterior view") && stderr.contains("superior view"),
        "{stderr}"
    );
    // One classification for all three views: the later two make none.
    let views: Vec<&str> = stderr.lines().filter(|l| l.contains(" view on ")).collect();
    assert_eq!(views.len(), 3, "{stderr}");
    assert!(!views[0].contains("(0 classified)"), "{stderr}");
    assert!(
        views[1..].iter().all(|l| l.contains("(0 classified)")),
        "{stderr}"
    );
    let anterior = read(&dir.join("ras-anterior.png"));
    let (top, bottom) = (
        bright(&anterior, 0..160, 0..80),
        bright(&anterior, 0..160, 80..160),
    );
    assert!(
        top > 2 * bottom,
        "superior block at the top: {top} above, {bottom} below"
    );
    let (left, right) = (
        bright(&anterior, 0..80, 90..160),
        bright(&anterior, 80..160, 90..160),
    );
    assert!(
        left > 3 * right.max(1),
        "the patient's right on the left: {left} against {right}"
    );
    // From behind the right side shows on the right.
    let posterior = read(&dir.join("ras-posterior.png"));
    let (left, right) = (
        bright(&posterior, 0..80, 90..160),
        bright(&posterior, 80..160, 90..160),
    );
    assert!(
        right > 3 * left.max(1),
        "posterior view: {left} against {right}"
    );
    // LPI: the same file turned over; the big block is now inferior.
    let lpi = dir.join("lpi.png");
    let mut args = vec![
        "render",
        s(&raw),
        "--out",
        s(&lpi),
        "--size",
        "160x160",
        "--view",
        "anterior",
    ];
    args.extend(raw_args("LPI"));
    ok(&args);
    let flipped = read(&lpi);
    let (top, bottom) = (
        bright(&flipped, 0..160, 0..80),
        bright(&flipped, 0..160, 80..160),
    );
    assert!(
        bottom > 2 * top,
        "inferior block at the bottom: {top} above, {bottom} below"
    );
    // A bad code names the accepted letters.
    let mut args = vec!["render", s(&raw), "--out", s(&lpi)];
    args.extend(raw_args("XYZ"));
    let message = fails(&args);
    assert!(
        message.contains("XYZ") && message.contains("LPS"),
        "{message}"
    );
}

#[test]
fn orbits_turn_about_the_scene_up_and_keep_the_picture_upright() {
    let Some(ct) = data("volumes/lidc2/lidc2_256x256x133_uint8.raw") else {
        return;
    };
    let dir = scratch("orbit");
    // LIDC2 as index times spacing: +z is inferior, so the scene says its up is -z.
    let scene = dir.join("lidc2-up-minus-z.toml");
    std::fs::write(
        &scene,
        format!(
            "[camera]\nview_from = [0.0, -1.0, 0.0]\nup = [0.0, 0.0, -1.0]\n\n[[volume]]\npath = {:?}\n\
             dims = [256, 256, 133]\nscalar = \"u8\"\nspacing = [1.40625, 1.40625, 2.5]\n\
             transfer = \"ramp\"\nwindow = [130.0, 235.0]\n",
            s(&std::path::absolute(&ct).unwrap())
        ),
    )
    .unwrap();
    let render = |name: &str, orbit: &str| {
        let out = dir.join(name);
        ok(&[
            "render",
            s(&scene),
            "--out",
            s(&out),
            "--size",
            "128x128",
            "--orbit",
            orbit,
        ]);
        read(&out)
    };
    let still = render("still.png", "0,0");
    let turned = render("turned.png", "5,0");
    let pitched = render("pitched.png", "0,5");
    for (name, image) in [("yaw", &turned), ("pitch", &pitched)] {
        let r = correlation(&still, image);
        assert!(
            r > 0.8,
            "a 5 degree {name} keeps the picture: correlation {r}"
        );
        let (a, b) = (centroid(&still).unwrap(), centroid(image).unwrap());
        assert!(
            (a.1 - b.1).abs() < 0.05,
            "{name}: the top stays on top: {a:?} against {b:?}"
        );
    }
    // Straight along the up axis and on over the pole, the picture does not jump or flip.
    let over = render("over.png", "0,95");
    let pole = render("pole.png", "0,90");
    assert!(
        correlation(&over, &pole) > 0.99,
        "the pitch stops at the pole"
    );
}

#[test]
fn a_ct_goes_straight_to_a_picture_with_a_transfer_function_chosen_from_its_values() {
    let Some(nifti) = data("volumes/totalseg_ct/example_ct.nii.gz") else {
        return;
    };
    let Some(dicom) = data("volumes/totalseg_ct/example_ct_dicom") else {
        return;
    };
    let Some(lidc) = data("volumes/lidc2/lidc2_256x256x133_uint8.raw") else {
        return;
    };
    let dir = scratch("straight");
    for (name, input) in [("nifti", &nifti), ("dicom", &dicom)] {
        let out = dir.join(format!("{name}.png"));
        let result = ok(&["render", s(input), "--out", s(&out), "--size", "160x120"]);
        let stderr = String::from_utf8_lossy(&result.stderr);
        assert!(
            stderr.contains("ct-bone") && stderr.contains("Hounsfield"),
            "{name}: {stderr}"
        );
        let image = read(&out);
        // The DICOM series is a 40 mm slab seen from the front: a band of bone (382 bright
        // pixels with opacities per millimetre, measured).
        assert!(bright(&image, 0..160, 0..120) > 250, "{name}: bone shows");
    }
    // 8-bit data get a ramp over its histogram's upper percentiles, said on stderr.
    let out = dir.join("lidc.png");
    let result = ok(&[
        "render",
        s(&lidc),
        "--dims",
        "256,256,133",
        "--scalar",
        "u8",
        "--spacing",
        "1.40625,1.40625,2.5",
        "--orientation",
        "LAI",
        "--out",
        s(&out),
        "--size",
        "160x120",
    ]);
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(
        stderr.contains("ramp from") && stderr.contains("percentile"),
        "{stderr}"
    );
    assert!(bright(&read(&out), 0..160, 0..120) > 500);
    // A preset and a window by hand; a window with its ends swapped is refused.
    let out = dir.join("soft.png");
    ok(&[
        "render",
        s(&nifti),
        "--preset",
        "ct-soft-tissue",
        "--window",
        "-200,800",
        "--shift",
        "50",
        "--out",
        s(&out),
        "--size",
        "96x72",
    ]);
    let message = fails(&[
        "render",
        s(&nifti),
        "--window",
        "800,-200",
        "--out",
        s(&out),
    ]);
    assert!(message.contains("--window"), "{message}");
    let message = fails(&[
        "render",
        s(&nifti),
        "--preset",
        "ct-bones",
        "--out",
        s(&out),
    ]);
    assert!(
        message.contains("ct-bone") && message.contains("ct-metal"),
        "{message}"
    );
    // Raw placement on a file whose header places it is refused, naming the option.
    let message = fails(&[
        "render",
        s(&nifti),
        "--orientation",
        "LPS",
        "--dims",
        "1,1,1",
        "--out",
        s(&out),
    ]);
    assert!(!message.is_empty());
    let message = fails(&["render", s(&nifti), "--origin", "1,2,3", "--out", s(&out)]);
    assert!(
        message.contains("origin") && message.contains("raw"),
        "{message}"
    );
}

#[test]
fn meshes_from_the_command_line_take_units_and_frames_and_a_wrong_scale_is_named() {
    let Some(nifti) = data("volumes/totalseg_ct/example_ct.nii.gz") else {
        return;
    };
    let Some(humerus) = data("meshes/myosim_shoulder/humerus.stl") else {
        return;
    };
    let dir = scratch("meshes");
    let out = dir.join("humerus.png");
    // In metres, read as millimetres: a third of a millimetre long in a 400 mm CT.
    let result = ok(&[
        "render",
        s(&nifti),
        "--mesh",
        s(&humerus),
        "--out",
        s(&out),
        "--size",
        "96x72",
    ]);
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(
        stderr.contains("humerus.stl")
            && stderr.contains("units = \"m\"")
            && stderr.contains("--mesh-units m"),
        "{stderr}"
    );
    // With units = m the warning is gone and the bone is drawn at its size, turned from LPS.
    let pick = |frame: &str| {
        let result = ok(&[
            "pick",
            s(&nifti),
            "--mesh",
            s(&humerus),
            "--mesh-units",
            "m",
            "--mesh-frame",
            frame,
            "--mesh-transform",
            "{ translate = [0, 0, 0] }",
            "--size",
            "96x72",
            "--pixel",
            "48,36",
            "--meshes-only",
        ]);
        let stderr = String::from_utf8_lossy(&result.stderr).into_owned();
        assert!(!stderr.contains("warning"), "{stderr}");
        serde_json::from_slice::<serde_json::Value>(&result.stdout).unwrap()
    };
    let json = pick("RAS");
    assert_eq!(json["size"], serde_json::json!([96, 72]));
    let message = fails(&[
        "render",
        s(&nifti),
        "--mesh",
        s(&humerus),
        "--mesh-units",
        "furlong",
        "--out",
        s(&out),
    ]);
    assert!(
        message.contains("furlong") && message.contains("mm, cm or m"),
        "{message}"
    );
    let message = fails(&[
        "render",
        s(&nifti),
        "--mesh",
        s(&humerus),
        "--mesh-frame",
        "XYZ",
        "--out",
        s(&out),
    ]);
    assert!(
        message.contains("--mesh-frame") && message.contains("neither RAS nor LPS"),
        "{message}"
    );
    let message = fails(&["render", s(&nifti), "--mesh-units", "m", "--out", s(&out)]);
    assert!(message.contains("--mesh"), "{message}");
}

#[test]
fn picks_name_their_frame_and_units() {
    let Some(nifti) = data("volumes/totalseg_ct/example_ct.nii.gz") else {
        return;
    };
    let result = ok(&["pick", s(&nifti), "--size", "160x120", "--pixel", "80,60"]);
    let json: serde_json::Value = serde_json::from_slice(&result.stdout).unwrap();
    let hit = &json["hit"];
    assert_eq!(hit["kind"], "volume", "{json}");
    assert_eq!(hit["frame"], "RAS");
    assert_eq!(hit["unit"], "mm");
    assert_eq!(hit["value_unit"], "HU");
}

#[test]
fn several_views_need_a_view_pattern_and_names_are_checked() {
    let dir = scratch("views");
    let out = dir.join("one.png");
    let message = fails(&["render", "--view", "anterior,superior", "--out", s(&out)]);
    assert!(message.contains("{view}"), "{message}");
    let message = fails(&["render", "--view", "front", "--out", s(&out)]);
    assert!(
        message.contains("front") && message.contains("anterior") && message.contains("inferior"),
        "{message}"
    );
    let message = fails(&["render", "--view", "anterior-posterior", "--out", s(&out)]);
    assert!(message.contains("cancel"), "{message}");
    let message = fails(&["pick", "--view", "anterior,left", "--pixel", "1,1"]);
    assert!(message.contains("one --view"), "{message}");
}

#[test]
fn annotations_name_the_patient_directions_and_the_scale_of_each_view() {
    let dir = scratch("annotate");
    let raw = marker_volume(&dir);
    let base = [
        "--dims",
        "24,24,24",
        "--scalar",
        "u8",
        "--spacing",
        "2,2,2",
        "--window",
        "100,200",
    ];
    let render = |extra: &[&str]| {
        let mut args = vec!["render", s(&raw), "--size", "240x200"];
        args.extend(base);
        args.extend(extra);
        stderr(&ok(&args))
    };
    let plain = dir.join("plain.png");
    let said = render(&["--view", "anterior", "--out", s(&plain)]);
    assert!(!said.contains("annotated"), "{said}");
    let figure = dir.join("anterior.png");
    let said = render(&[
        "--view",
        "anterior",
        "--annotate",
        "--caption",
        "markers",
        "--out",
        s(&figure),
    ]);
    assert!(said.contains("left R, right L, top S, bottom I"), "{said}");
    assert!(
        said.contains("mm at the target") && said.contains("orientation marker"),
        "{said}"
    );
    // The marks lie in the corners and along the edges; the picture's middle is untouched.
    let (a, b) = (read(&plain), read(&figure));
    let changed = |x: std::ops::Range<u32>, y: std::ops::Range<u32>| {
        y.flat_map(|j| x.clone().map(move |i| (i, j)))
            .filter(|&(i, j)| a.get_pixel(i, j) != b.get_pixel(i, j))
            .count()
    };
    assert!(
        changed(0..80, 160..200) > 40,
        "a scale bar in the lower left"
    );
    assert!(
        changed(160..240, 120..200) > 40,
        "a marker in the lower right"
    );
    assert!(changed(0..120, 0..20) > 20, "a caption along the top");
    assert_eq!(changed(90..150, 70..130), 0, "nothing over the middle");
    // From above, anterior is up and the patient's right on the right; an orthographic view's
    // scale holds everywhere.
    let said = render(&[
        "--view",
        "superior",
        "--annotate",
        "letters,scale",
        "--orthographic",
        "80",
        "--out",
        s(&figure),
    ]);
    assert!(said.contains("left L, right R, top A, bottom P"), "{said}");
    assert!(
        said.contains("scale bar 10 mm;") || said.contains("scale bar 10 mm\n"),
        "{said}"
    );
    assert!(!said.contains("orientation marker"), "{said}");
    // The bar is as long as it says: 80 mm over 200 pixels is 2.5 pixels a millimetre, so
    // 10 mm is 25 pixels. The bar is the longest run of changed pixels in one row of the lower
    // left, against the same view with the letters alone.
    let letters = dir.join("letters.png");
    render(&[
        "--view",
        "superior",
        "--annotate",
        "letters",
        "--orthographic",
        "80",
        "--out",
        s(&letters),
    ]);
    let (a, b) = (read(&letters), read(&figure));
    let longest = (150..200)
        .map(|j| {
            let (mut best, mut run) = (0, 0);
            for i in 0..120 {
                run = if a.get_pixel(i, j) != b.get_pixel(i, j) {
                    run + 1
                } else {
                    0
                };
                best = best.max(run);
            }
            best
        })
        .max()
        .unwrap_or(0);
    // The line's round caps and anti-aliasing add a pixel or two at its ends.
    assert!(
        (24..=29).contains(&longest),
        "a 10 mm bar at 2.5 px/mm drawn {longest} px long"
    );
    // An oblique view names both directions of each edge.
    let said = render(&[
        "--view",
        "anterolateral-right",
        "--annotate",
        "letters",
        "--out",
        s(&figure),
    ]);
    assert!(said.contains("left RP, right LA"), "{said}");
    let message = fails(&["render", "--annotate", "triad", "--out", s(&figure)]);
    assert!(
        message.contains("triad") && message.contains("marker"),
        "{message}"
    );
}

#[test]
fn depth_images_carry_their_calibration_and_show_a_volume_surface() {
    let dir = scratch("depth");
    let raw = marker_volume(&dir);
    let (out, depth) = (dir.join("front.png"), dir.join("front-depth.png"));
    let args = [
        "render",
        s(&raw),
        "--dims",
        "24,24,24",
        "--scalar",
        "u8",
        "--spacing",
        "2,2,2",
        "--window",
        "100,200",
        "--view",
        "anterior",
        "--size",
        "120x120",
        "--out",
        s(&out),
        "--depth",
        s(&depth),
    ];
    let said = stderr(&ok(&args));
    assert!(
        said.contains("surface depth"),
        "a volume-only scene gets its surface: {said}"
    );
    // The PNG's text chunks and the sidecar agree.
    let decoder = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(&depth).unwrap(),
    ));
    let mut reader = decoder.read_info().unwrap();
    let text: std::collections::HashMap<String, String> = reader
        .info()
        .uncompressed_latin1_text
        .iter()
        .map(|t| (t.keyword.clone(), t.text.clone()))
        .collect();
    let sidecar: serde_json::Value =
        serde_json::from_slice(&std::fs::read(depth.with_extension("json")).unwrap()).unwrap();
    let near: f64 = text["splatscene:near_mm"].parse().unwrap();
    let far: f64 = text["splatscene:far_mm"].parse().unwrap();
    assert_eq!(sidecar["near_mm"].as_f64(), Some(near));
    assert_eq!(sidecar["far_mm"].as_f64(), Some(far));
    assert_eq!(sidecar["mode"], "surface");
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    reader.next_frame(&mut buf).unwrap();
    let grey = |x: usize, y: usize| {
        u16::from_be_bytes([buf[2 * (y * 120 + x)], buf[2 * (y * 120 + x) + 1]])
    };
    // The corner sees nothing; the upper block's front face lies where the ray enters the voxel
    // row y = 17 (index 17.5, world 35 mm), at eye_y - 35 along the view axis.
    assert_eq!(grey(0, 0), 65535);
    let mm = |g: u16| near + (far - near) * f64::from(g) / 65534.0;
    let eye_y = sidecar["eye"][1].as_f64().unwrap();
    let face = mm(grey(60, 36));
    assert!(
        (face - (eye_y - 35.0)).abs() < 0.6,
        "front face at {face} mm, expected {}",
        eye_y - 35.0
    );
    // Meshes only, in a scene without meshes, is refused rather than written all white.
    let mut mesh_only = args.to_vec();
    mesh_only.extend(["--depth-mode", "mesh"]);
    let message = fails(&mesh_only);
    assert!(
        message.contains("no meshes") && message.contains("surface"),
        "{message}"
    );
}

#[test]
fn a_folder_of_several_dicom_series_lists_them_and_renders_the_one_chosen() {
    // pydicom's test files (MIT): one folder holding CT, MR, RT dose, NM and segmentation
    // series, and a truncated file.
    let Some(folder) = data("reader_tests/pydicom_test_files") else {
        return;
    };
    let dir = scratch("series");
    let out = dir.join("ct.png");
    let message = fails(&["render", s(&folder), "--out", s(&out)]);
    assert!(
        message.contains("DICOM series in this folder") && message.contains("--series"),
        "{message}"
    );
    assert!(
        message.contains("CT 128x128, 1 images") && message.contains("MR 64x64"),
        "{message}"
    );
    // The listing as JSON, for the whole tree below a folder.
    let tree = folder.parent().unwrap();
    let listing: serde_json::Value =
        serde_json::from_slice(&ok(&["info", s(tree)]).stdout).unwrap();
    let series = listing["series"].as_array().unwrap();
    let ct = series
        .iter()
        .find(|s| s["modality"] == "CT")
        .expect("the CT series");
    assert_eq!(ct["size"], serde_json::json!([128, 128]));
    let uid = ct["uid"].as_str().unwrap();
    let result = ok(&[
        "render",
        s(&folder),
        "--series",
        uid,
        "--out",
        s(&out),
        "--size",
        "96x96",
    ]);
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(
        stderr.contains("MR_truncated.dcm"),
        "the unreadable file is named: {stderr}"
    );
    assert!(stderr.contains("Hounsfield"), "{stderr}");
    assert!(bright(&read(&out), 0..96, 0..96) > 100);
    // A file alone picks its own series, whatever else its folder holds.
    let info: serde_json::Value =
        serde_json::from_slice(&ok(&["info", s(&folder.join("CT_small.dcm"))]).stdout).unwrap();
    assert_eq!(info["size"], serde_json::json!([128, 128, 1]));
    let message = fails(&["render", s(&folder), "--series", "99", "--out", s(&out)]);
    assert!(message.contains("no series is \"99\""), "{message}");
    let empty = scratch("no-series");
    let message = fails(&["info", s(&empty)]);
    assert!(message.contains("no DICOM series"), "{message}");
}

#[test]
fn the_built_in_scene_takes_meshes_and_transfer_functions_like_any_scene() {
    let Some(humerus) = data("meshes/myosim_shoulder/humerus.stl") else {
        return;
    };
    let dir = scratch("builtin");
    let out = dir.join("plan.png");
    let result = ok(&[
        "render",
        "--mesh",
        s(&humerus),
        "--mesh-units",
        "m",
        "--preset",
        "ct-soft-tissue",
        "--size",
        "96x72",
        "--out",
        s(&out),
    ]);
    let stderr = String::from_utf8_lossy(&result.stderr);
    // The prosthesis' three parts and the humerus.
    assert!(stderr.contains("4 meshes"), "{stderr}");
    let message = fails(&["render", "--orientation", "LPS", "--out", s(&out)]);
    assert!(
        message.contains("--orientation") && message.contains("built-in"),
        "{message}"
    );
}
