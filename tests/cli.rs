//! The `order` command line as outside checks use it: output format, stderr report, errors.

use std::process::Command;

use glam::DVec3;
use splatscene::grid::SparseGrid;
use splatscene::order::{OrderOptions, Ordering, ViewCase, VolumeGeometry, order};

mod common;
use common::{command, scratch, splatscene};

#[test]
fn order_writes_little_endian_ids_matching_the_library() {
    let dir = scratch("cli");
    let out = dir.join("order.bin");
    for name in [
        "btf",
        "wbtf",
        "pbtf",
        "ip-pbtf",
        "ip-pbtf-explicit",
        "ip-pbtf-implicit",
        "exact",
        "bucketed",
        "pyramid",
    ] {
        let result = splatscene(&[
            "order",
            "--dims",
            "7,5,4",
            "--spacing",
            "0.7,0.7,2.5",
            "--eye",
            "2.5,-3,1.2",
            "--ordering",
            name,
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(
            result.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&result.stderr)
        );
        let stderr = String::from_utf8_lossy(&result.stderr);
        assert!(stderr.contains("view case: face-on"), "{stderr}");
        assert!(stderr.contains("140 voxels in"), "{stderr}");
        let bytes = std::fs::read(&out).unwrap();
        let ids: Vec<u32> = bytes
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
            .collect();

        let geometry = VolumeGeometry::axis_aligned([7, 5, 4], [0.7, 0.7, 2.5], [0.0; 3]).unwrap();
        let eye = geometry.index_to_world_point(DVec3::new(2.5, -3.0, 1.2));
        let view = ViewCase::new(&geometry, eye, geometry.centre_world()).unwrap();
        let grid = SparseGrid::dense([7, 5, 4]).unwrap();
        let ordering: Ordering = name.parse().unwrap();
        assert_eq!(
            ids,
            order(&grid, &view, ordering, &OrderOptions::default()).unwrap(),
            "{name}"
        );
    }
}

#[test]
fn order_writes_to_stdout_without_out() {
    let result = splatscene(&[
        "order",
        "--dims",
        "3,2,2",
        "--eye",
        "1,1,-4",
        "--ordering",
        "exact",
    ]);
    assert!(result.status.success());
    assert_eq!(result.stdout.len(), 12 * 4);
}

#[test]
fn bad_arguments_fail_with_a_message() {
    let nan = splatscene(&[
        "order",
        "--dims",
        "4,4,4",
        "--eye",
        "nan,0,0",
        "--ordering",
        "btf",
    ]);
    assert!(!nan.status.success());
    assert!(String::from_utf8_lossy(&nan.stderr).contains("not finite"));
    let unknown = splatscene(&[
        "order",
        "--dims",
        "4,4,4",
        "--eye",
        "1,1,9",
        "--ordering",
        "zigzag",
    ]);
    assert!(!unknown.status.success());
    assert!(String::from_utf8_lossy(&unknown.stderr).contains("unknown ordering"));
    let huge = splatscene(&[
        "order",
        "--dims",
        "65536,65536,2",
        "--eye",
        "1,1,9",
        "--ordering",
        "btf",
    ]);
    assert!(!huge.status.success());
    assert!(String::from_utf8_lossy(&huge.stderr).contains("u32 voxel ids"));
    let same = splatscene(&[
        "order",
        "--dims",
        "4,4,4",
        "--eye",
        "1.5,1.5,1.5",
        "--ordering",
        "btf",
    ]);
    assert!(!same.status.success(), "eye at the default target");
}

#[test]
fn render_writes_the_built_in_scene_at_any_size_with_depth() {
    let dir = scratch("cli");
    let (out, depth) = (dir.join("shoulder.png"), dir.join("shoulder-depth.png"));
    let result = splatscene(&[
        "render",
        "--out",
        out.to_str().unwrap(),
        "--size",
        "161x97",
        "--depth",
        depth.to_str().unwrap(),
    ]);
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(
        stderr.contains("3 meshes") && stderr.contains("splats"),
        "{stderr}"
    );
    let color = image::open(&out).unwrap();
    assert_eq!((color.width(), color.height()), (161, 97));
    let depth_image = image::open(&depth).unwrap();
    assert!(
        matches!(depth_image, image::DynamicImage::ImageLuma16(_)),
        "16-bit grey depth"
    );
    let grey = depth_image.to_luma16();
    let (near, far) = grey
        .pixels()
        .fold((u16::MAX, 0), |(lo, hi), p| (lo.min(p[0]), hi.max(p[0])));
    assert!(
        near < far && far == u16::MAX,
        "the prosthesis has depth, the background is far"
    );
}

#[test]
fn a_small_picture_draws_a_coarser_level_unless_told_not_to() {
    // The built-in scene at 40x30: its voxels fall well under a pixel, so with `--lod on` a
    // coarser level of the pyramid is drawn and the stage line says which; `--lod off` draws
    // the full grid. The default (`auto`) makes the levels that pay within the one picture:
    // at 40x30 they do (the picture draws under a 60th of the full grid's splats); at
    // 200x150, where `on` halves the grid once, they do not, and the full grid is drawn,
    // the stage line saying why.
    let dir = scratch("cli");
    let out = dir.join("small-lod.png");
    let run_at = |lod: &str, size: &str| {
        let mut args = vec!["render", "--out", out.to_str().unwrap(), "--size", size];
        if !lod.is_empty() {
            args.extend(["--lod", lod]);
        }
        let result = splatscene(&args);
        assert!(
            result.status.success(),
            "{}",
            String::from_utf8_lossy(&result.stderr)
        );
        let stderr = String::from_utf8_lossy(&result.stderr).into_owned();
        let splats: usize = stderr
            .split(" splats")
            .next()
            .and_then(|s| s.rsplit(' ').next())
            .and_then(|n| n.parse().ok())
            .unwrap_or_else(|| panic!("a splat count in {stderr}"));
        (stderr, splats)
    };
    let run = |lod: &str| run_at(lod, "40x30");
    let (on, coarse) = run("on");
    let (off, full) = run("off");
    let (one, one_level) = run("volume");
    let (auto, auto_splats) = run("auto");
    let (default, default_splats) = run("");
    assert_eq!(auto_splats, coarse, "{auto}");
    assert_eq!(default_splats, coarse, "{default}");
    assert!(default.contains("level of detail 2/3/2"), "{default}");
    let (larger, larger_splats) = run_at("", "200x150");
    let (larger_on, larger_coarse) = run_at("on", "200x150");
    let (_, larger_full) = run_at("off", "200x150");
    assert!(
        larger.contains("no level of detail pays for one picture"),
        "{larger}"
    );
    assert_eq!(larger_splats, larger_full, "{larger}");
    assert!(larger_coarse < larger_full, "{larger_on}");
    assert!(on.contains("level of detail"), "{on}");
    assert!(one.contains("level of detail"), "{one}");
    assert!(!off.contains("level of detail"), "{off}");
    assert!(coarse * 4 < full, "{coarse} splats against {full}");
    assert!(one_level * 4 < full, "{one_level} splats against {full}");
    // By brick, no brick is drawn finer than the volume's one level.
    assert!(coarse <= one_level, "{coarse} splats against {one_level}");
    let bad = splatscene(&["render", "--out", out.to_str().unwrap(), "--lod", "maybe"]);
    assert!(!bad.status.success());
}

#[test]
fn render_without_an_adapter_names_the_package_to_install() {
    // No adapter of a backend this build lacks: wgpu finds nothing at all.
    let dir = scratch("cli");
    let out = dir.join("none.png");
    let result = command()
        .args(["render", "--out", out.to_str().unwrap(), "--size", "8x8"])
        .env("WGPU_BACKEND", "metal")
        .output()
        .unwrap();
    assert!(!result.status.success());
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(stderr.contains("mesa-vulkan-drivers"), "{stderr}");
    assert!(!out.exists(), "no file on failure");
}

#[test]
fn render_names_a_missing_scene_file() {
    let result = splatscene(&[
        "render",
        "/nonexistent/plan.toml",
        "--out",
        "/tmp/never.png",
    ]);
    assert!(!result.status.success());
    assert!(String::from_utf8_lossy(&result.stderr).contains("/nonexistent/plan.toml"));
}

fn json(output: &std::process::Output) -> serde_json::Value {
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_slice(&output.stdout).expect("JSON on standard output")
}

#[test]
fn pick_reports_the_prosthesis_head_and_misses_as_null() {
    // In the built-in view at 800x600, pixel (400, 200) lies on the prosthesis head.
    let hit = json(&splatscene(&["pick", "--pixel", "400,200"]));
    assert_eq!(hit["hit"]["kind"], "mesh", "{hit}");
    assert_eq!(hit["hit"]["node_name"], "head");
    assert!(hit["hit"]["distance"].as_f64().unwrap() > 0.0);
    let miss = json(&splatscene(&["pick", "--pixel", "0,0"]));
    assert!(miss["hit"].is_null(), "{miss}");
    let bone = json(&splatscene(&["pick", "--pixel", "300,300"]));
    assert_eq!(bone["hit"]["kind"], "volume", "{bone}");
    assert!(
        bone["hit"]["value"].as_f64().unwrap() > 150.0,
        "bone-like HU: {bone}"
    );
    let outside = splatscene(&["pick", "--pixel", "800,10"]);
    assert!(!outside.status.success());
    assert!(String::from_utf8_lossy(&outside.stderr).contains("outside the 800x600 image"));
}

#[test]
fn measure_distances_and_angles_and_draws_them() {
    let d = json(&splatscene(&[
        "measure", "--point", "0,0,0", "--point", "3,4,0",
    ]));
    assert_eq!(
        (d["kind"].as_str(), d["value"].as_f64(), d["unit"].as_str()),
        (Some("distance"), Some(5.0), Some("mm"))
    );
    let dir = scratch("cli");
    let out = dir.join("measure.png");
    let a = json(&splatscene(&[
        "measure",
        "--pixel",
        "400,200",
        "--pixel",
        "330,420",
        "--pixel",
        "480,260",
        "--size",
        "800x600",
        "--out",
        out.to_str().unwrap(),
    ]));
    assert_eq!(a["kind"], "angle");
    let points: Vec<glam::DVec3> = a["hits"]
        .as_array()
        .unwrap()
        .iter()
        .map(|h| {
            glam::DVec3::new(
                h["point"][0].as_f64().unwrap(),
                h["point"][1].as_f64().unwrap(),
                h["point"][2].as_f64().unwrap(),
            )
        })
        .collect();
    let (u, v) = (points[0] - points[1], points[2] - points[1]);
    let expected = u.angle_between(v).to_degrees();
    assert!(
        (a["value"].as_f64().unwrap() - expected).abs() < 1e-9,
        "{a}"
    );
    let image = image::open(&out).unwrap().to_rgb8();
    assert_eq!(image.dimensions(), (800, 600));
    // The vertex marker is drawn over the stem in the measurement's colour (amber).
    let p = image.get_pixel(330, 420);
    assert!(
        p[0] > 150 && p[1] > 100 && p[2] < 80,
        "marker at the vertex: {p:?}"
    );
    let one = splatscene(&["measure", "--point", "1,2,3"]);
    assert!(!one.status.success());
}

#[test]
fn info_describes_volumes_as_json_and_names_bad_files() {
    let data = std::env::var_os("SPLATSCENE_DATA").map_or(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data"),
        std::path::PathBuf::from,
    );
    let nhdr = data.join("volumes/vtk_headsq/quarter.nhdr");
    if !nhdr.exists() {
        assert!(
            std::env::var_os("CI").is_none(),
            "{} is missing under CI: set SPLATSCENE_DATA",
            nhdr.display()
        );
        eprintln!(
            "skipped: no data under {} (set SPLATSCENE_DATA)",
            data.display()
        );
        return;
    }
    // VTKData head, quarter resolution (BSD).
    let info = json(&splatscene(&["info", nhdr.to_str().unwrap()]));
    assert_eq!(info["format"], "nrrd");
    assert_eq!(info["size"], serde_json::json!([64, 64, 93]));
    assert_eq!(info["spacing"], serde_json::json!([3.2, 3.2, 1.5]));
    assert_eq!(info["scalar_type"], "int16");
    for key in ["origin", "direction", "min", "max", "mean"] {
        assert!(!info[key].is_null(), "{key} in {info}");
    }
    let two = json(&splatscene(&[
        "info",
        nhdr.to_str().unwrap(),
        nhdr.to_str().unwrap(),
    ]));
    assert_eq!(two.as_array().map(Vec::len), Some(2));
    let raw = data.join("volumes/engine/engine_256x256x128_uint8.raw");
    let refused = splatscene(&["info", raw.to_str().unwrap()]);
    assert!(!refused.status.success());
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(
        stderr.contains("engine_256x256x128_uint8.raw") && stderr.contains("raw options"),
        "{stderr}"
    );
}

#[test]
fn render_with_an_eye_keeps_the_scene_files_up_vector() {
    let dir = scratch("up");
    std::fs::create_dir_all(&dir).unwrap();
    let scene = dir.join("down.toml");
    std::fs::write(
        &scene,
        "[output]\nsize = [64, 48]\n[camera]\neye = [200, 300, 100]\ntarget = [50, 35, 60]\nup = [0, 0, -1]\n\
         [[volume]]\npath = \"builtin:shoulder-phantom\"\n",
    )
    .unwrap();
    let (a, b) = (dir.join("a.png"), dir.join("b.png"));
    let plain = splatscene(&[
        "render",
        scene.to_str().unwrap(),
        "--out",
        a.to_str().unwrap(),
    ]);
    assert!(
        plain.status.success(),
        "{}",
        String::from_utf8_lossy(&plain.stderr)
    );
    let moved = splatscene(&[
        "render",
        scene.to_str().unwrap(),
        "--out",
        b.to_str().unwrap(),
        "--eye",
        "200,300,100",
        "--target",
        "50,35,60",
    ]);
    assert!(
        moved.status.success(),
        "{}",
        String::from_utf8_lossy(&moved.stderr)
    );
    let (a, b) = (
        image::open(&a).unwrap().to_rgba8(),
        image::open(&b).unwrap().to_rgba8(),
    );
    assert!(a.pixels().any(|p| p[0] > 100), "something is drawn");
    assert_eq!(
        a, b,
        "the same eye and target give the same picture, up included"
    );
}

#[test]
fn orderings_on_a_raw_volume_show_ordering_errors() {
    let data = std::env::var_os("SPLATSCENE_DATA").map_or(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data"),
        std::path::PathBuf::from,
    );
    let raw = data.join("volumes/datraw_small/neghip_64x64x64_uint8.raw");
    if !raw.exists() {
        assert!(
            std::env::var_os("CI").is_none(),
            "{} is missing under CI: set SPLATSCENE_DATA",
            raw.display()
        );
        eprintln!("skipped: no data under {}", data.display());
        return;
    }
    // Open SciVis neghip (volvis.org). A one-colour transfer function would make every order
    // composite alike; the report's must not.
    let out = scratch("orderings");
    let result = splatscene(&[
        "orderings",
        raw.to_str().unwrap(),
        "--raw-dims",
        "64,64,64",
        "--raw-type",
        "u8",
        "--threshold",
        "60",
        "--orbit-views",
        "2",
        "--fly-in-views",
        "1",
        "--size",
        "48x48",
        "--out-dir",
        out.to_str().unwrap(),
        "--orderings",
        "btf,ip-pbtf,bucketed",
        "--bucket-widths",
        "0.25,6",
    ]);
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    let table = String::from_utf8_lossy(&result.stdout);
    let rmse = |name: &str| -> f64 {
        let row = table
            .lines()
            .find(|l| l.starts_with(&format!("| {name} |")))
            .unwrap_or_else(|| panic!("a {name} row in\n{table}"));
        row.split('|').nth(3).unwrap().trim().parse().unwrap()
    };
    assert!(rmse("btf") > 0.0, "BTF differs from the exact order");
    // Only the orderings asked for, the bucketed order once per width; wider buckets leave
    // more pairs to the IP-PBTF order inside each bucket.
    assert!(!table.contains("| pyramid |") && !table.contains("| bucketed |"));
    assert!(
        rmse("bucketed 0.25") < rmse("bucketed 6"),
        "error grows with the bucket width:\n{table}"
    );
    assert!(out.join("error-vs-time.svg").exists());
}

#[test]
fn bucket_width_options_are_checked() {
    let order = |extra: &[&str]| {
        let mut args = vec!["order", "--dims", "6,5,4", "--eye", "-3,2,9"];
        args.extend_from_slice(extra);
        splatscene(&args)
    };
    let fine = order(&["--ordering", "bucketed", "--bucket-width", "0.25"]);
    let coarse = order(&["--ordering", "bucketed", "--bucket-width", "4"]);
    assert!(fine.status.success() && coarse.status.success());
    assert_eq!(fine.stdout.len(), 120 * 4);
    assert_ne!(fine.stdout, coarse.stdout, "the width changes the order");
    let stderr = |o: std::process::Output| String::from_utf8_lossy(&o.stderr).into_owned();
    let zero = order(&["--ordering", "bucketed", "--bucket-width", "0"]);
    assert!(!zero.status.success());
    assert!(stderr(zero).contains("bucket width"));
    let other = order(&["--ordering", "pbtf", "--bucket-width", "1"]);
    assert!(!other.status.success());
    assert!(stderr(other).contains("bucketed order only"));
    let report = |extra: &[&str]| {
        let mut args = vec!["orderings", "--orbit-views", "1", "--fly-in-views", "0"];
        args.extend_from_slice(extra);
        splatscene(&args)
    };
    let negative = report(&["--bucket-widths", "1,-2"]);
    assert!(!negative.status.success());
    assert!(stderr(negative).contains("-2 is not a finite positive width"));
    let without = report(&["--orderings", "btf,pbtf", "--bucket-widths", "1"]);
    assert!(!without.status.success());
    assert!(stderr(without).contains("needs the bucketed order"));
    let on_gpu = report(&["--gpu", "--bucket-widths", "1"]);
    assert!(!on_gpu.status.success());
    assert!(stderr(on_gpu).contains("default width only"));
}

#[test]
fn out_follows_links_and_writes_into_pipes_without_replacing_them() {
    let dir = scratch("out");
    std::fs::create_dir_all(&dir).unwrap();
    let order = |out: &std::path::Path| {
        let result = splatscene(&[
            "order",
            "--dims",
            "2,2,2",
            "--eye",
            "0,0,0",
            "--ordering",
            "btf",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(
            result.status.success(),
            "{}",
            String::from_utf8_lossy(&result.stderr)
        );
        String::from_utf8_lossy(&result.stderr).into_owned()
    };
    // A link: the file it names gets the order, and the link stays a link.
    std::fs::write(dir.join("target.bin"), b"old").unwrap();
    std::os::unix::fs::symlink("target.bin", dir.join("link.bin")).unwrap();
    let said = order(&dir.join("link.bin"));
    assert!(
        said.contains("replaced the existing") && said.contains("target.bin"),
        "{said}"
    );
    assert!(
        std::fs::symlink_metadata(dir.join("link.bin"))
            .unwrap()
            .file_type()
            .is_symlink()
    );
    assert_eq!(std::fs::read(dir.join("target.bin")).unwrap().len(), 32);
    // A named pipe: written into, and still a pipe afterwards.
    let fifo = dir.join("pipe");
    let made = Command::new("mkfifo").arg(&fifo).status();
    if made.is_ok_and(|s| s.success()) {
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || std::fs::read(fifo).unwrap())
        };
        order(&fifo);
        assert_eq!(reader.join().unwrap().len(), 32);
        use std::os::unix::fs::FileTypeExt;
        assert!(std::fs::metadata(&fifo).unwrap().file_type().is_fifo());
        // A reader that comes a moment after the run wants to write is waited for.
        let late = {
            let fifo = fifo.clone();
            std::thread::spawn(move || {
                std::thread::sleep(std::time::Duration::from_millis(1500));
                std::fs::read(fifo).unwrap()
            })
        };
        let said = order(&fifo);
        assert_eq!(late.join().unwrap().len(), 32);
        assert!(said.contains("waiting up to"), "{said}");
    }
}

#[test]
fn render_refuses_one_file_for_colour_and_depth() {
    let dir = scratch("same");
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("shot.png");
    let again = dir.join(".").join("shot.png");
    let result = splatscene(&[
        "render",
        "--size",
        "32x24",
        "--out",
        out.to_str().unwrap(),
        "--depth",
        again.to_str().unwrap(),
    ]);
    assert!(!result.status.success());
    let said = String::from_utf8_lossy(&result.stderr);
    assert!(said.contains("the same file as --out"), "{said}");
    assert!(!out.exists(), "refused before rendering");
}

#[test]
fn a_dense_grid_larger_than_memory_is_refused_before_allocating() {
    // 2^32 - 1 voxels in a line: ids fit a u32, but the run tables, the order and the exact
    // sort's keys take about 256 GiB, more than any machine this runs on.
    let result = splatscene(&[
        "order",
        "--dims",
        "4294967295,1,1",
        "--eye",
        "0,0,0",
        "--ordering",
        "exact",
    ]);
    let said = String::from_utf8_lossy(&result.stderr);
    assert!(!result.status.success());
    assert!(said.contains("needs about 256.5 GiB"), "{said}");
}

/// A raw `n`^3 u8 volume in `dir`, every voxel significant in the window 100-150, and a
/// function that renders it at 32 x 32 on the CPU tiles into `out` (with `more` arguments)
/// under the memory limit it is given.
fn dense_cube_under<'a>(
    dir: &std::path::Path,
    n: usize,
    out: &'a std::path::Path,
    more: &'a [&'a str],
) -> impl Fn(&str) -> std::process::Output + 'a {
    let raw = dir.join(format!("dense{n}.raw"));
    std::fs::write(&raw, vec![200u8; n * n * n]).unwrap();
    let dims = format!("{n},{n},{n}");
    move |limit: &str| {
        command()
            .env("SPLATSCENE_MEMORY_LIMIT", limit)
            .env("RUST_BACKTRACE", "0")
            .arg("render")
            .arg(&raw)
            .args(["--dims", &dims, "--scalar", "u8", "--window", "100,150"])
            .args(["--size", "32x32", "--compositor", "cpu"])
            .args(more)
            .arg("--out")
            .arg(out)
            .output()
            .unwrap()
    }
}

#[test]
fn splats_past_the_memory_budget_are_refused_after_classification() {
    // A 64^3 raw volume, every voxel significant: the grid fits a 5 MiB budget (2 bytes a
    // voxel, 0.5 MiB), its 262,144 splats (30 bytes each, 7.5 MiB) do not.
    let dir = scratch("cli");
    let out = dir.join("dense64.png");
    let render = dense_cube_under(&dir, 64, &out, &[]);
    let refused = render("5M");
    let said = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success());
    assert!(
        said.contains("drawing 262144 splats needs 7.5 MiB"),
        "{said}"
    );
    assert!(!out.exists(), "nothing written");
    let drawn = render("64M");
    assert!(
        drawn.status.success(),
        "{}",
        String::from_utf8_lossy(&drawn.stderr)
    );
}

#[test]
fn a_memory_limit_bounds_the_whole_drawing_not_each_part_alone() {
    // A 128^3 raw volume, every voxel significant: its 2,097,152 splats take 60 MiB at 30
    // bytes each, which a 64 MiB limit holds alone, but not with what the process holds by
    // then (the values, 2 MiB, and the program itself, over 10 MiB): refused, the limit left
    // said. A 160 MiB limit draws it.
    let dir = scratch("cli-limit");
    let out = dir.join("dense128.png");
    let render = dense_cube_under(&dir, 128, &out, &["--lod", "off"]);
    let refused = render("64M");
    let said = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success(), "{said}");
    assert!(
        said.contains("drawing 2097152 splats needs 60.0 MiB"),
        "{said}"
    );
    let left = said
        .split("MiB of memory and ")
        .nth(1)
        .and_then(|rest| rest.split(" MiB").next())
        .and_then(|n| n.parse::<f64>().ok())
        .expect(&said);
    assert!(left < 54.0, "{said}");
    assert!(!out.exists(), "nothing written");
    let drawn = render("160M");
    assert!(
        drawn.status.success(),
        "{}",
        String::from_utf8_lossy(&drawn.stderr)
    );
    assert!(out.exists());
}

#[test]
fn numbers_that_are_not_finite_or_out_of_range_are_refused() {
    for args in [
        &["orderings", "--threshold", "NaN"][..],
        &["pick", "--pixel", "1,1", "--opacity", "2"],
        &["pick", "--pixel", "1,1", "--opacity", "nan"],
        &["measure", "--point", "NaN,0,0", "--point", "1,0,0"],
        &["measure", "--point", "1e400,0,0", "--point", "1,0,0"],
        &["render", "--orbit", "inf,0", "--out", "never.png"],
    ] {
        let result = splatscene(args);
        assert!(!result.status.success(), "{args:?}");
        let said = String::from_utf8_lossy(&result.stderr);
        assert!(
            said.contains("is not finite") || said.contains("is not an opacity"),
            "{args:?}: {said}"
        );
    }
}

#[test]
fn report_sizes_are_checked_before_any_work() {
    let report = |extra: &[&str]| {
        let mut args = vec!["orderings"];
        args.extend_from_slice(extra);
        let out = splatscene(&args);
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    // 160 GB of pixels: refused, not attempted.
    let huge = report(&["--size", "100000x100000"]);
    assert!(huge.contains("at most 16384 pixels a side"), "{huge}");
    let views = report(&["--orbit-views", "100000000"]);
    assert!(views.contains("at most 10000"), "{views}");
    // Neither loaded the phantom first.
    assert!(!huge.contains("significant") && !views.contains("significant"));
}

#[test]
fn orderings_composite_on_the_gpu_when_asked() {
    let out = scratch("gpu-report");
    // A plot already there is replaced, and the run says so.
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("error-vs-time.svg"), "mine").unwrap();
    let result = splatscene(&[
        "orderings",
        "--orbit-views",
        "1",
        "--fly-in-views",
        "1",
        "--size",
        "48x48",
        "--orderings",
        "pbtf,ip-pbtf",
        "--gpu",
        "--out-dir",
        out.to_str().unwrap(),
    ]);
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    let table = String::from_utf8_lossy(&result.stdout);
    assert!(table.contains("Composited on the GPU: "), "{table}");
    let row = table
        .lines()
        .find(|l| l.starts_with("| pbtf |"))
        .unwrap_or_else(|| panic!("a pbtf row in\n{table}"));
    let rmse: f64 = row.split('|').nth(3).unwrap().trim().parse().unwrap();
    assert!(
        rmse > 0.0,
        "PBTF differs from the exact order on GPU images too"
    );
    // No inversion count on the GPU; the splat pass time instead.
    let cells: Vec<&str> = row.split('|').map(str::trim).collect();
    assert_eq!(cells[6], "n/a", "{row}");
    let draw: f64 = cells[7].parse().unwrap();
    assert!(draw > 0.0, "{row}");
    assert!(out.join("error-vs-time.png").exists());
    let said = String::from_utf8_lossy(&result.stderr);
    assert!(
        said.contains("replaced the existing") && said.contains("error-vs-time.svg"),
        "{said}"
    );
    assert_eq!(said.matches("replaced the existing").count(), 1, "{said}");
}

#[test]
fn info_and_scene_files_take_the_nifti_transform_and_the_coordinate_frame() {
    let data = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let nifti = data.join("nifti2/sform-qform.nii");
    let nifti = nifti.to_str().unwrap();
    let origin = |args: &[&str]| -> Vec<f64> {
        let out = splatscene(args);
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let info = json(&out);
        info["origin"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect()
    };
    let near = |a: &[f64], b: [f64; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-4);
    // The sform (nibabel's choice), and ITK's rule, which takes the qform beside sform code 2.
    assert!(near(&origin(&["info", nifti]), [10.0, -20.0, 30.0]));
    let itk = origin(&["info", "--nifti-transform", "itk", nifti]);
    assert!(near(&itk, [-5.0, 12.0, 7.0]), "{itk:?}");
    // A VTK file read as LPS lands mirrored in x and y.
    let vti = data.join("vtk/vtk-appended-zlib.vti");
    let vti = vti.to_str().unwrap();
    let ras = origin(&["info", vti]);
    let lps = origin(&["info", "--coordinate-frame", "LPS", vti]);
    assert!(near(&lps, [-ras[0], -ras[1], ras[2]]), "{ras:?} {lps:?}");
    // Choices that cannot apply are refused, naming the file.
    let out = splatscene(&["info", "--coordinate-frame", "LPS", nifti]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success()
            && err.contains("coordinate frame")
            && err.contains("sform-qform.nii"),
        "{err}"
    );
    // Scene files: the same keys, checked where they are read.
    let dir = scratch("scene-keys");
    std::fs::create_dir_all(&dir).unwrap();
    let scene = |name: &str, volume: &str| {
        let path = dir.join(name);
        std::fs::write(&path, format!("[[volume]]\n{volume}\n")).unwrap();
        let out = splatscene(&[
            "render",
            path.to_str().unwrap(),
            "--size",
            "32x32",
            "--out",
            dir.join("x.png").to_str().unwrap(),
        ]);
        (
            out.status.success(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (ok, err) = scene(
        "bogus.toml",
        &format!("path = {nifti:?}\nnifti_transform = \"best\""),
    );
    assert!(
        !ok && err.contains("nifti_transform") && err.contains("none of sform, qform, itk"),
        "{err}"
    );
    let (ok, err) = scene(
        "raw.toml",
        &format!("path = {vti:?}\ndims = [4, 3, 2]\nscalar = \"u8\"\nframe = 1"),
    );
    assert!(
        !ok && err.contains("frame applies to 4-D NIfTI, not to a raw volume"),
        "{err}"
    );
    let (ok, err) = scene(
        "lps.toml",
        &format!("path = {nifti:?}\ncoordinate_frame = \"LPS\""),
    );
    assert!(!ok && err.contains("states its own patient frame"), "{err}");
}

#[test]
fn a_depth_path_that_links_to_the_colour_output_is_refused_even_before_it_exists() {
    let dir = scratch("dangling");
    std::fs::create_dir_all(&dir).unwrap();
    let link = dir.join("link.png");
    std::os::unix::fs::symlink("c.png", &link).unwrap();
    let out = dir.join("c.png");
    let result = splatscene(&[
        "render",
        "--size",
        "16x16",
        "--out",
        out.to_str().unwrap(),
        "--depth",
        link.to_str().unwrap(),
    ]);
    let said = String::from_utf8_lossy(&result.stderr);
    assert!(!result.status.success(), "{said}");
    assert!(said.contains("the same file as --out"), "{said}");
    assert!(!out.exists(), "nothing is written");
}

#[test]
fn captions_fill_their_placeholders_and_the_scene_camera_is_a_view() {
    let dir = scratch("captions");
    let out = |name: &str| dir.join(name).to_str().unwrap().to_owned();
    let ok = |args: &[&str]| {
        let o = splatscene(args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    let pixels = |name: &str| image::open(dir.join(name)).unwrap().to_rgba8().into_raw();
    // {view} in a caption is each view's name, as a caption written out is.
    ok(&[
        "render",
        "--view",
        "scene,anterior",
        "--size",
        "96x72",
        "--caption",
        "{view} view {size}",
        "--out",
        &out("c-{view}.png"),
    ]);
    ok(&[
        "render",
        "--view",
        "anterior",
        "--size",
        "96x72",
        "--caption",
        "anterior view 96x72",
        "--out",
        &out("written.png"),
    ]);
    assert_eq!(pixels("c-anterior.png"), pixels("written.png"));
    // `scene` is the scene's own camera, as without --view.
    ok(&[
        "render",
        "--size",
        "96x72",
        "--caption",
        "scene view 96x72",
        "--out",
        &out("own.png"),
    ]);
    assert_eq!(pixels("c-scene.png"), pixels("own.png"));
}

#[test]
fn a_binary_file_without_dims_is_named_as_a_raw_volume_that_needs_them() {
    let dir = scratch("raw-without-dims");
    let raw = dir.join("ct.raw");
    std::fs::write(
        &raw,
        (0..4096u32)
            .map(|i| (i * 7919 % 251) as u8)
            .collect::<Vec<_>>(),
    )
    .unwrap();
    let o = splatscene(&[
        "render",
        raw.to_str().unwrap(),
        "--out",
        dir.join("x.png").to_str().unwrap(),
    ]);
    let said = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        said.contains("ct.raw") && said.contains("--dims") && said.contains("not text"),
        "{said}"
    );
}

#[test]
fn named_views_fit_what_the_crop_box_leaves() {
    let dir = scratch("fit-crop");
    std::fs::write(dir.join("block.raw"), vec![200u8; 32 * 32 * 32]).unwrap();
    let volume = r#"path = "block.raw"
dims = [32, 32, 32]
scalar = "u8"
transfer = "ramp"
window = [0, 255]"#;
    std::fs::write(dir.join("whole.toml"), format!("[[volume]]\n{volume}\n")).unwrap();
    // A crop box in one corner of the block, a quarter of its side, in world coordinates.
    let whole = splatscene::scene::file::load_scene_file(&dir.join("whole.toml")).unwrap();
    let (lo, hi) = whole.scene.volume_bounds().unwrap();
    let (a, b) = (lo + 0.6 * (hi - lo), lo + 0.85 * (hi - lo));
    let cropped = format!(
        "[[volume]]\n{volume}\ncrop_box = {{ min = [{}, {}, {}], max = [{}, {}, {}] }}\n",
        a.x, a.y, a.z, b.x, b.y, b.z
    );
    std::fs::write(dir.join("cropped.toml"), cropped).unwrap();
    for view in ["anterior", "superior", "anterolateral-right"] {
        let out = dir.join(format!("{view}.png"));
        let o = splatscene(&[
            "render",
            dir.join("cropped.toml").to_str().unwrap(),
            "--view",
            view,
            "--size",
            "120x120",
            "--transparent",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        // What is drawn: the pixels with any cover, measured on the picture alone.
        let image = image::open(&out).unwrap().to_rgba8();
        let drawn: Vec<(u32, u32)> = image
            .enumerate_pixels()
            .filter(|(_, _, p)| p[3] > 0)
            .map(|(x, y, _)| (x, y))
            .collect();
        assert!(!drawn.is_empty(), "{view}: nothing drawn");
        let (x0, x1) = (
            drawn.iter().map(|p| p.0).min().unwrap(),
            drawn.iter().map(|p| p.0).max().unwrap(),
        );
        let (y0, y1) = (
            drawn.iter().map(|p| p.1).min().unwrap(),
            drawn.iter().map(|p| p.1).max().unwrap(),
        );
        // Centred, and filling a good part of the picture (the whole block would show the
        // cropped corner at a sixth of it, off to one side).
        let centre = (f64::from(x0 + x1) / 2.0, f64::from(y0 + y1) / 2.0);
        assert!(
            (centre.0 - 59.5).abs() < 8.0 && (centre.1 - 59.5).abs() < 8.0,
            "{view}: drawn about {centre:?}"
        );
        assert!(
            (x1 - x0).max(y1 - y0) > 55,
            "{view}: drawn over {}x{} px",
            x1 - x0,
            y1 - y0
        );
    }
}

#[test]
fn a_ct_preset_on_values_that_are_no_hounsfield_units_is_warned_about() {
    let dir = scratch("preset-mismatch");
    let raw = dir.join("u8.raw");
    std::fs::write(
        &raw,
        (0..16 * 16 * 16)
            .map(|i| (i % 256) as u8)
            .collect::<Vec<u8>>(),
    )
    .unwrap();
    let run = |preset: &str| {
        let o = splatscene(&[
            "render",
            raw.to_str().unwrap(),
            "--dims",
            "16,16,16",
            "--scalar",
            "u8",
            "--preset",
            preset,
            "--size",
            "32x24",
            "--out",
            dir.join(format!("{preset}.png")).to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    let bone = run("ct-bone");
    assert!(
        bone.contains("ct-bone is made for Hounsfield units, but the values run from 0 to 255"),
        "{bone}"
    );
    assert!(!run("mr-default").contains("Hounsfield"));
    // The built-in CT phantom is in Hounsfield units: no warning.
    let o = splatscene(&[
        "render",
        "--size",
        "32x24",
        "--out",
        dir.join("builtin.png").to_str().unwrap(),
    ]);
    assert!(!String::from_utf8_lossy(&o.stderr).contains("made for Hounsfield"));
}
