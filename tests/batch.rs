//! `splatscene batch` as a planning service runs it: a manifest of cases and views, checked
//! before anything is drawn, one index of inputs and outputs, resumed after a kill without
//! redoing finished jobs, and split into shards whose merged index and pictures equal the
//! unsharded batch's.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use serde_json::Value;

mod common;
use common::pictures::pictures;
use common::{fails, ok, repo, scratch, stderr};

/// Runs a command that must succeed; what it said on stderr.
fn ok_stderr(args: &[&str]) -> String {
    stderr(&ok(args))
}

/// A 20^3 u8 volume: a ball of 200 in a cube of 10.
fn write_ball(path: &Path) {
    let n = 20i32;
    let mut bytes = Vec::new();
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let d2 = (x - 10).pow(2) + (y - 9).pow(2) + (z - 10).pow(2);
                bytes.push(if d2 < 36 { 200 } else { 10 });
            }
        }
    }
    std::fs::write(path, bytes).unwrap();
}

/// A manifest of three small cases: the built-in scene (with and without its volume), a raw
/// volume and a second raw volume placed and coloured otherwise.
fn small_manifest(dir: &Path) -> PathBuf {
    write_ball(&dir.join("ball.raw"));
    let text = format!(
        r#"
[defaults]
views = ["anterior", "right"]
sizes = [[96, 72]]

[[job]]
name = "shoulder"
scene = "{}"
contents = ["all", "meshes"]
annotate = true
depth = "depth/{{job}}-{{view}}-{{content}}.png"
out = "{{job}}-{{view}}-{{content}}.png"

[[job]]
name = "ball"
volume = {{ path = "ball.raw", dims = [20, 20, 20], scalar = "u8", spacing = [2, 2, 2] }}
window = [50, 150]

[[job]]
name = "ball-superior"
volume = {{ path = "ball.raw", dims = [20, 20, 20], scalar = "u8", orientation = "LPS" }}
views = ["superior", {{ name = "oblique", view_from = [1, 1, -1] }}]
orderings = ["ip-pbtf", "btf"]
"#,
        repo("examples/scenes/shoulder.toml").display()
    );
    let path = dir.join("manifest.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn index(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn statuses(index: &Value) -> Vec<(String, String)> {
    index["jobs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| {
            (
                j["name"].as_str().unwrap().to_owned(),
                j["status"].as_str().unwrap().to_owned(),
            )
        })
        .collect()
}

#[test]
fn a_batch_renders_every_picture_with_an_index_and_leaves_finished_jobs_alone() {
    let dir = scratch("resume");
    let manifest = small_manifest(&dir);
    let out = dir.join("out");
    let (m, o) = (manifest.to_str().unwrap(), out.to_str().unwrap());
    ok(&["batch", m, "--out", o]);
    let first = index(&out.join("index.json"));
    assert_eq!(
        statuses(&first),
        [
            ("shoulder".into(), "rendered".into()),
            ("ball".into(), "rendered".into()),
            ("ball-superior".into(), "rendered".into())
        ]
    );
    assert_eq!(first["manifest_jobs"], 3);
    let jobs = first["jobs"].as_array().unwrap();
    // 2 contents x 2 views, each with a depth image and its calibration; 2 views; 2 x 2.
    assert_eq!(jobs[0]["outputs"].as_array().unwrap().len(), 12);
    assert_eq!(jobs[1]["outputs"].as_array().unwrap().len(), 2);
    assert_eq!(jobs[2]["outputs"].as_array().unwrap().len(), 4);
    for job in jobs {
        for output in job["outputs"].as_array().unwrap() {
            let file = out.join(output["file"].as_str().unwrap());
            let bytes = std::fs::read(&file).unwrap();
            assert_eq!(
                blake3::hash(&bytes).to_hex().as_str(),
                output["blake3"].as_str().unwrap(),
                "{}",
                file.display()
            );
            assert!(output["camera"]["eye"].is_array());
        }
        assert!(job["timings_ms"]["total"].as_f64().unwrap() > 0.0);
        assert!(!job["inputs"].as_array().unwrap().is_empty());
    }
    assert!(out.join("shoulder-right-meshes.png").exists());
    assert!(out.join("depth/shoulder-anterior-all.json").exists());
    assert!(out.join("ball-superior-oblique-btf.png").exists());
    assert!(
        out.join("ball-superior-superior-ip-pbtf-implicit.png")
            .exists()
    );
    // The picture without the volume fits the meshes it draws: it looks at the centre of
    // their vertices' box, from nearer than the picture with the volume.
    let camera = |content: &str| {
        let c = jobs[0]["outputs"]
            .as_array()
            .unwrap()
            .iter()
            .find(|o| o["view"] == "right" && o["kind"] == "image" && o["content"] == content)
            .map(|o| &o["camera"])
            .unwrap();
        let v = |key: &str| {
            let a: Vec<f64> = serde_json::from_value(c[key].clone()).unwrap();
            glam::DVec3::new(a[0], a[1], a[2])
        };
        (v("eye"), v("target"))
    };
    let (all_eye, all_target) = camera("all");
    let (mesh_eye, mesh_target) = camera("meshes");
    let scene = splatscene::scene::file::load_scene_file(&repo("examples/scenes/shoulder.toml"))
        .unwrap()
        .scene;
    let (mut lo, mut hi) = (glam::DVec3::splat(f64::MAX), glam::DVec3::splat(f64::MIN));
    for (_, mesh, world) in scene.meshes() {
        for p in &mesh.mesh.positions {
            let p = world.transform_point3(glam::DVec3::from(p.map(f64::from)));
            (lo, hi) = (lo.min(p), hi.max(p));
        }
    }
    assert!(
        mesh_target.distance(0.5 * (lo + hi)) < 0.01,
        "{mesh_target} against {}",
        0.5 * (lo + hi)
    );
    assert!(mesh_eye.distance(mesh_target) < all_eye.distance(all_target));
    // Without the volume the picture differs.
    let all = image::open(out.join("shoulder-right-all.png")).unwrap();
    let meshes = image::open(out.join("shoulder-right-meshes.png")).unwrap();
    assert_ne!(all.as_bytes(), meshes.as_bytes());

    // A second run leaves every file as it was.
    let before = pictures(&out);
    let modified = std::fs::metadata(out.join("ball-anterior.png"))
        .unwrap()
        .modified()
        .unwrap();
    let stderr = ok_stderr(&["batch", m, "--out", o]);
    assert!(stderr.contains("0 rendered, 3 up to date"), "{stderr}");
    assert_eq!(
        std::fs::metadata(out.join("ball-anterior.png"))
            .unwrap()
            .modified()
            .unwrap(),
        modified
    );
    assert_eq!(pictures(&out), before);

    // A changed input renders its jobs again, and only them; so does a damaged output.
    let mut ball = std::fs::read(dir.join("ball.raw")).unwrap();
    ball[0] = 11;
    std::fs::write(dir.join("ball.raw"), ball).unwrap();
    std::fs::write(out.join("shoulder-anterior-meshes.png"), b"not a png").unwrap();
    ok(&["batch", m, "--out", o]);
    assert_eq!(
        statuses(&index(&out.join("index.json"))),
        [
            ("shoulder".into(), "rendered".into()),
            ("ball".into(), "rendered".into()),
            ("ball-superior".into(), "rendered".into())
        ]
    );
    assert_eq!(pictures(&out), before, "the same pictures again");
    ok(&["batch", m, "--out", o]);
    let stderr = ok_stderr(&["batch", m, "--out", o, "--force"]);
    assert!(stderr.contains("3 rendered, 0 up to date"), "{stderr}");
    // Turning the level of detail off draws every job again; the same setting again, none.
    let stderr = ok_stderr(&["batch", m, "--out", o, "--lod", "off"]);
    assert!(stderr.contains("3 rendered, 0 up to date"), "{stderr}");
    let stderr = ok_stderr(&["batch", m, "--out", o, "--lod", "off"]);
    assert!(stderr.contains("0 rendered, 3 up to date"), "{stderr}");
    assert!(
        fails(&["batch", m, "--out", o, "--lod", "half"]).contains("half"),
        "a value other than on or off is refused"
    );
}

#[test]
fn batch_pictures_are_those_of_render() {
    let dir = scratch("same-as-render");
    let manifest = small_manifest(&dir);
    let out = dir.join("out");
    ok(&[
        "batch",
        manifest.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let single = dir.join("single.png");
    ok(&[
        "render",
        &repo("examples/scenes/shoulder.toml").display().to_string(),
        "--view",
        "right",
        "--size",
        "96x72",
        "--annotate",
        "--out",
        single.to_str().unwrap(),
    ]);
    let a = image::open(&single).unwrap();
    let b = image::open(out.join("shoulder-right-all.png")).unwrap();
    assert_eq!(a.as_bytes(), b.as_bytes());
}

#[test]
fn shards_merge_into_the_unsharded_batch() {
    let dir = scratch("shards");
    let manifest = small_manifest(&dir);
    let m = manifest.to_str().unwrap();
    let whole = dir.join("whole");
    ok(&["batch", m, "--out", whole.to_str().unwrap()]);
    let sharded = dir.join("sharded");
    let s = sharded.to_str().unwrap();
    let stderr = fails(&["batch", "--merge", s]);
    assert!(stderr.contains("no shard indexes"), "{stderr}");
    ok(&["batch", m, "--out", s, "--shard", "2/2"]);
    let stderr = fails(&["batch", "--merge", s]);
    assert!(stderr.contains("missing index-1-of-2.json"), "{stderr}");
    ok(&["batch", m, "--out", s, "--shard", "1/2"]);
    let one = index(&sharded.join("index-1-of-2.json"));
    assert_eq!(
        statuses(&one),
        [
            ("shoulder".into(), "rendered".into()),
            ("ball-superior".into(), "rendered".into())
        ]
    );
    ok(&["batch", "--merge", s]);
    let merged = index(&sharded.join("index.json"));
    let unsharded = index(&whole.join("index.json"));
    assert_eq!(merged["merged_shards"], 2);
    assert_eq!(statuses(&merged), statuses(&unsharded));
    let outputs = |i: &Value| -> Vec<Value> {
        i["jobs"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|j| j["outputs"].as_array().unwrap().clone())
            .collect()
    };
    assert_eq!(outputs(&merged), outputs(&unsharded));
    assert_eq!(pictures(&sharded), pictures(&whole));
}

/// Shards are merged only when they were made from the same manifest: the same file changed
/// between two shards' runs is another manifest, whatever its path.
#[test]
fn shards_of_a_manifest_changed_between_runs_are_not_merged() {
    let dir = scratch("changed-manifest");
    let manifest = small_manifest(&dir);
    let m = manifest.to_str().unwrap();
    let sharded = dir.join("sharded");
    let s = sharded.to_str().unwrap();
    ok(&["batch", m, "--out", s, "--shard", "2/2"]);
    let text = std::fs::read_to_string(&manifest).unwrap();
    std::fs::write(
        &manifest,
        text.replace("sizes = [[96, 72]]", "sizes = [[80, 60]]"),
    )
    .unwrap();
    ok(&["batch", m, "--out", s, "--shard", "1/2"]);
    let stderr = fails(&["batch", "--merge", s]);
    assert!(stderr.contains("another manifest"), "{stderr}");
    assert!(!sharded.join("index.json").exists(), "nothing merged");
}

#[test]
fn manifest_problems_are_all_reported_before_anything_is_drawn() {
    let dir = scratch("problems");
    let text = format!(
        r#"
[defaults]
views = ["anterior", "sideways"]
sizes = [[0, 100], [640, 480]]

[[job]]
name = "a"
scene = "{}"
out = "same.png"

[[job]]
name = "b"
volume = "missing.nrrd"
out = "same.png"

[[job]]
name = "a"
scene = "nowhere.toml"
orderings = ["sideways"]
contents = ["meshes"]
out = "../escape-{{view}}.png"
"#,
        repo("examples/scenes/shoulder.toml").display()
    );
    let manifest = dir.join("bad.toml");
    std::fs::write(&manifest, text).unwrap();
    let out = dir.join("out");
    let stderr = fails(&[
        "batch",
        manifest.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    for expected in [
        "defaults, key `views`",
        "\"sideways\"",
        "key `sizes`: [0, 100]",
        "job 2 (b), key `volume`",
        "missing.nrrd not found",
        "job 3 (a), key `scene`",
        "job 3 (a), key `name`: job 1 has this name too",
        "nowhere.toml",
        "job 3 (a), key `orderings`",
        "job 3 (a), key `out`",
        "nothing was rendered",
    ] {
        assert!(stderr.contains(expected), "{expected:?} not in {stderr}");
    }
    assert!(!out.exists(), "nothing is written for a bad manifest");

    // Names that collide only: both jobs write one file.
    let text = format!(
        r#"
[defaults]
views = ["anterior"]
sizes = [[64, 48]]
out = "figure-{{view}}.png"

[[job]]
name = "one"
scene = "{0}"

[[job]]
name = "two"
scene = "{0}"
"#,
        repo("examples/scenes/shoulder.toml").display().to_string()
    );
    std::fs::write(&manifest, text).unwrap();
    let stderr = fails(&[
        "batch",
        manifest.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        stderr.contains(
            "job 2 (two), key `out`: figure-anterior.png is written by one view anterior"
        ),
        "{stderr}"
    );
    // Unknown keys and misspelt tables name the key.
    std::fs::write(
        &manifest,
        "[[job]]\nname = \"x\"\nscene = \"s.toml\"\nveiws = [\"anterior\"]\n",
    )
    .unwrap();
    let stderr = fails(&[
        "batch",
        manifest.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(stderr.contains("veiws"), "{stderr}");
    for bad in ["3/2", "0/0"] {
        let stderr = fails(&[
            "batch",
            manifest.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--shard",
            bad,
        ]);
        assert!(stderr.contains(&format!("--shard {bad}")), "{stderr}");
    }
}

#[test]
fn a_failing_job_is_recorded_and_the_batch_goes_on() {
    let dir = scratch("failing");
    write_ball(&dir.join("ball.raw"));
    // Too short for its size: the job fails when it loads, not when the manifest is checked.
    std::fs::write(dir.join("short.raw"), [0u8; 100]).unwrap();
    let manifest = dir.join("manifest.toml");
    std::fs::write(
        &manifest,
        r#"
[defaults]
views = ["anterior"]
sizes = [[48, 48]]

[[job]]
name = "short"
volume = { path = "short.raw", dims = [20, 20, 20], scalar = "u8" }

[[job]]
name = "ball"
volume = { path = "ball.raw", dims = [20, 20, 20], scalar = "u8" }
"#,
    )
    .unwrap();
    let out = dir.join("out");
    let stderr = fails(&[
        "batch",
        manifest.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(stderr.contains("1 of 2 jobs failed"), "{stderr}");
    let i = index(&out.join("index.json"));
    assert_eq!(
        statuses(&i),
        [
            ("short".into(), "failed".into()),
            ("ball".into(), "rendered".into())
        ]
    );
    let error = i["jobs"][0]["error"].as_str().unwrap();
    assert!(error.contains("short.raw"), "{error}");
    assert!(out.join("ball-anterior.png").exists());
}

#[test]
fn a_batch_looks_for_a_gpu_adapter_only_where_a_picture_needs_one() {
    let dir = scratch("no-adapter");
    write_ball(&dir.join("ball.raw"));
    let manifest = |name: &str, text: &str| {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path
    };
    let ball = r#"
[defaults]
views = ["anterior"]
sizes = [[48, 48]]

[[job]]
name = "ball"
volume = { path = "ball.raw", dims = [20, 20, 20], scalar = "u8" }
window = [50, 150]
"#;
    let volumes = manifest("volumes.toml", ball);
    let with_meshes = manifest(
        "meshes.toml",
        &format!(
            "{ball}\n[[job]]\nname = \"shoulder\"\nscene = \"{}\"\n",
            repo("examples/scenes/shoulder.toml").display()
        ),
    );
    // No Vulkan driver at all: any look for an adapter finds none.
    let run = |manifest: &Path, more: &[&str], out: &Path| {
        Command::new(env!("CARGO_BIN_EXE_splatscene"))
            .args(["batch", manifest.to_str().unwrap(), "--out"])
            .arg(out)
            .args(more)
            .env("VK_ICD_FILENAMES", dir.join("no-such-driver.json"))
            .env("WGPU_BACKEND", "vulkan")
            .env("NODEVICE_SELECT", "1")
            .output()
            .unwrap()
    };
    let gpu_device = common::gpu_device_file();
    // Volumes alone, on the default compositor.
    let out = dir.join("volumes");
    let done = run(&volumes, &[], &out);
    let said = String::from_utf8_lossy(&done.stderr);
    assert!(done.status.success(), "{said}");
    let i = index(&out.join("index.json"));
    assert_eq!(statuses(&i), [("ball".into(), "rendered".into())]);
    if gpu_device {
        // `auto` must look, to learn whether an adapter is a CPU; it finds none, says so
        // before the first job, and draws on the CPU.
        let looked = said.find("no GPU adapter").expect(&said);
        assert!(looked < said.find("job 1 (ball)").expect(&said), "{said}");
        assert_eq!(i["device"], "no GPU adapter");
    } else {
        assert!(!said.contains("GPU adapter"), "{said}");
        assert_eq!(i["device"], "none looked for (volumes on the CPU)");
    }
    // The same picture as a batch with the driver there.
    let usual = dir.join("usual");
    ok(&[
        "batch",
        volumes.to_str().unwrap(),
        "--out",
        usual.to_str().unwrap(),
    ]);
    let picture = |out: &Path| {
        image::open(out.join("ball-anterior.png"))
            .unwrap()
            .to_rgba8()
    };
    assert_eq!(picture(&out), picture(&usual));
    // With the CPU tiles asked for, the volumes never need an adapter, on any machine; the
    // job with meshes looks for one when it comes, finds none and fails, saying why, and the
    // index then says no adapter was found.
    let out = dir.join("meshes");
    let done = run(&with_meshes, &["--compositor", "cpu"], &out);
    let said = String::from_utf8_lossy(&done.stderr);
    assert!(!done.status.success(), "{said}");
    let looked = said.find("no GPU adapter").expect(&said);
    assert!(said.find("job 1 (ball)").expect(&said) < looked, "{said}");
    let i = index(&out.join("index.json"));
    assert_eq!(
        statuses(&i),
        [
            ("ball".into(), "rendered".into()),
            ("shoulder".into(), "failed".into())
        ]
    );
    let error = i["jobs"][1]["error"].as_str().unwrap();
    assert!(error.contains("need a GPU adapter"), "{error}");
    assert_eq!(i["device"], "no GPU adapter");
    assert_eq!(picture(&out), picture(&usual));
}

#[test]
fn a_second_process_on_one_index_is_refused() {
    let dir = scratch("lock");
    let manifest = small_manifest(&dir);
    let out = dir.join("out");
    std::fs::create_dir_all(&out).unwrap();
    // This test holds the lock a running batch would hold.
    let lock = std::fs::File::create(out.join(".index.json.lock")).unwrap();
    lock.lock().unwrap();
    let stderr = fails(&[
        "batch",
        manifest.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(stderr.contains("another batch is writing"), "{stderr}");
    assert!(!out.join("index.json").exists());
    // Another shard takes another lock.
    ok(&[
        "batch",
        manifest.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--shard",
        "1/2",
    ]);
    drop(lock);
    ok(&[
        "batch",
        manifest.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
}

#[test]
fn a_killed_batch_resumes_without_redoing_finished_jobs() {
    let dir = scratch("kill");
    let manifest = small_manifest(&dir);
    // A fourth job that takes seconds: the batch is killed while it draws.
    let mut text = std::fs::read_to_string(&manifest).unwrap();
    text.push_str(&format!(
        "\n[[job]]\nname = \"slow\"\nscene = \"{}\"\nviews = [\"anterior\", \"posterior\", \"left\", \"right\", \"superior\", \"inferior\"]\nsizes = [[640, 480], [800, 600]]\norderings = [\"ip-pbtf\", \"btf\", \"pbtf\"]\n",
        repo("examples/scenes/shoulder.toml").display()
    ));
    std::fs::write(&manifest, text).unwrap();
    let out = dir.join("out");
    let mut child = Command::new(env!("CARGO_BIN_EXE_splatscene"))
        .args(["batch", manifest.to_str().unwrap(), "--out"])
        .arg(&out)
        .env("NODEVICE_SELECT", "1")
        .env_remove("SLURM_ARRAY_TASK_ID")
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    loop {
        let line = lines.next().expect("the batch ended early").unwrap();
        if line.starts_with("[3/4]") {
            break;
        }
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let killed = index(&out.join("index.json"));
    assert_eq!(
        statuses(&killed),
        [
            ("shoulder".into(), "rendered".into()),
            ("ball".into(), "rendered".into()),
            ("ball-superior".into(), "rendered".into()),
            ("slow".into(), "pending".into())
        ]
    );
    let stderr = ok_stderr(&[
        "batch",
        manifest.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(stderr.contains("1 rendered, 3 up to date"), "{stderr}");
    let resumed = index(&out.join("index.json"));
    assert_eq!(resumed["summary"]["pending"], 0);
    assert_eq!(resumed["jobs"][3]["outputs"].as_array().unwrap().len(), 36);
}

#[test]
fn a_plans_measurements_are_written_as_json_and_drawn() {
    let dir = scratch("measurements");
    std::fs::write(
        dir.join("plan.toml"),
        r#"
[[volume]]
path = "builtin:shoulder-phantom"

[[mesh]]
name = "prosthesis"
path = "builtin:prosthesis"
seat = "phantom"

[[measurement]]
kind = "line-angle"
label = "neck-shaft angle"
node = "prosthesis"
points = [[0, 0, 0], [0, 0, -40], [0, 0, 0], [-7.0004, 0, 7.0004]]

[[measurement]]
kind = "distance"
label = "offset"
points = [[0, 0, 0], [3, 4, 12]]
"#,
    )
    .unwrap();
    let manifest = dir.join("manifest.toml");
    std::fs::write(
        &manifest,
        r#"
[defaults]
views = ["anterior"]
sizes = [[128, 96]]

[[job]]
name = "labelled"
scene = "plan.toml"

[[job]]
name = "unlabelled"
scene = "plan.toml"
annotate = "marker"
measurements = "values/{job}.json"
"#,
    )
    .unwrap();
    let out = dir.join("out");
    ok(&[
        "batch",
        manifest.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let json: Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("labelled-measurements.json")).unwrap(),
    )
    .unwrap();
    let list = json["measurements"].as_array().unwrap();
    assert_eq!(list.len(), 2);
    assert_eq!(list[0]["label"], "neck-shaft angle");
    assert_eq!(list[0]["node"], "prosthesis");
    assert!(
        (list[0]["value"].as_f64().unwrap() - 135.0).abs() < 1e-6,
        "{json}"
    );
    assert_eq!(list[1]["value"].as_f64().unwrap(), 13.0);
    assert_eq!(json["frame"], "RAS");
    assert!(out.join("values/unlabelled.json").exists());
    let i = index(&out.join("index.json"));
    assert!(
        i["jobs"][0]["outputs"]
            .as_array()
            .unwrap()
            .iter()
            .any(|o| o["kind"] == "measurements" && o["file"] == "labelled-measurements.json")
    );
    // The values are written beside the markers unless the annotations leave them out; the
    // markers are drawn either way.
    let labelled = image::open(out.join("labelled-anterior.png")).unwrap();
    let unlabelled = image::open(out.join("unlabelled-anterior.png")).unwrap();
    assert_ne!(labelled.as_bytes(), unlabelled.as_bytes());
    let plain = dir.join("plain.png");
    ok(&[
        "render",
        dir.join("plan.toml").to_str().unwrap(),
        "--view",
        "anterior",
        "--size",
        "128x96",
        "--out",
        plain.to_str().unwrap(),
    ]);
    assert_eq!(
        image::open(&plain).unwrap().as_bytes(),
        labelled.as_bytes(),
        "batch and render draw a plan's measurements alike"
    );
}

#[test]
fn a_job_asking_for_contact_writes_it_and_the_index_holds_it() {
    let dir = scratch("contact");
    phantom_plan(&dir);
    let manifest = dir.join("manifest.toml");
    std::fs::write(
        &manifest,
        r#"
[defaults]
views = ["anterior"]
sizes = [[64, 48]]

[[job]]
name = "fit"
scene = "plan.toml"
contact = true
contents = ["volumes"]
"#,
    )
    .unwrap();
    let out = dir.join("out");
    let (m, o) = (manifest.to_str().unwrap(), out.to_str().unwrap());
    ok(&["batch", m, "--out", o]);
    let first = index(&out.join("index.json"));
    let job = &first["jobs"][0];
    let written: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("fit-contact.json")).unwrap())
            .unwrap();
    assert_eq!(job["contact"], written);
    assert_eq!(written["mesh"], "prosthesis");
    // The phantom is CT: the three CT classes, their shares adding up with what is outside.
    let classes = written["classes"].as_array().unwrap();
    assert_eq!(classes.len(), 3);
    let shares: f64 = classes
        .iter()
        .map(|c| c["fraction"].as_f64().unwrap())
        .sum::<f64>()
        + written["outside_fraction"].as_f64().unwrap();
    assert!((shares - 1.0).abs() < 1e-9, "{written}");
    assert!(
        job["outputs"]
            .as_array()
            .unwrap()
            .iter()
            .any(|o| o["kind"] == "contact" && o["file"] == "fit-contact.json")
    );
    // Run again: up to date, the contact kept in the index.
    ok(&["batch", m, "--out", o]);
    let again = index(&out.join("index.json"));
    assert_eq!(
        statuses(&again),
        [("fit".to_owned(), "up-to-date".to_owned())]
    );
    assert_eq!(again["jobs"][0]["contact"], written);
    // A job without a mesh cannot ask for it.
    std::fs::write(
        &manifest,
        "[[job]]\nname = \"bare\"\nvolume = \"builtin:shoulder-phantom\"\ncontact = true\n",
    )
    .unwrap();
    let said = fails(&["batch", m, "--out", o, "--check"]);
    assert!(
        said.contains("contact") && said.contains("needs a mesh"),
        "{said}"
    );
}

#[test]
fn a_job_asking_for_slices_writes_them_as_render_does_with_their_calibration() {
    let dir = scratch("batch-slices");
    phantom_plan(&dir);
    let manifest = dir.join("manifest.toml");
    std::fs::write(
        &manifest,
        r#"
[[job]]
name = "fit"
scene = "plan.toml"
views = ["anterior"]
sizes = [[64, 48]]
contents = ["volumes"]
slices = ["implant-long", "axial@40"]
"#,
    )
    .unwrap();
    let out = dir.join("out");
    let (m, o) = (manifest.to_str().unwrap(), out.to_str().unwrap());
    ok(&["batch", m, "--out", o]);
    let job = &index(&out.join("index.json"))["jobs"][0];
    let outputs = job["outputs"].as_array().unwrap();
    for name in ["implant-long", "axial@40"] {
        let figure = format!("fit-{name}.png");
        let calibration = format!("fit-{name}.json");
        assert!(
            outputs
                .iter()
                .any(|o| o["kind"] == "slice" && o["file"] == figure && o["slice"] == name),
            "{outputs:?}"
        );
        assert!(
            outputs
                .iter()
                .any(|o| o["kind"] == "slice-calibration" && o["file"] == calibration)
        );
        let c: Value =
            serde_json::from_str(&std::fs::read_to_string(out.join(&calibration)).unwrap())
                .unwrap();
        assert_eq!(c["plane"], name);
        assert_eq!(c["frame"], "RAS");
    }
    let c: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("fit-implant-long.json")).unwrap())
            .unwrap();
    assert_eq!(c["meshes"][0]["name"], "prosthesis");
    // The same figure as `render --slice` draws.
    let single = dir.join("single.png");
    ok(&[
        "render",
        dir.join("plan.toml").to_str().unwrap(),
        "--slice",
        "implant-long",
        "--out",
        single.to_str().unwrap(),
    ]);
    assert_eq!(
        image::open(&single).unwrap().as_bytes(),
        image::open(out.join("fit-implant-long.png"))
            .unwrap()
            .as_bytes()
    );
    // Planes that are none, and implant planes without a mesh, are refused at --check.
    std::fs::write(
        &manifest,
        "[[job]]\nname = \"bare\"\nvolume = \"builtin:shoulder-phantom\"\nslices = [\"oblique\", \"implant-cross\"]\n",
    )
    .unwrap();
    let said = fails(&["batch", m, "--out", o, "--check"]);
    assert!(
        said.contains("oblique") && said.contains("follow a mesh"),
        "{said}"
    );
}

/// A plan of the phantom with the prosthesis seated in it, as `dir/plan.toml`.
fn phantom_plan(dir: &Path) {
    std::fs::write(
        dir.join("plan.toml"),
        r#"
[[volume]]
path = "builtin:shoulder-phantom"

[[mesh]]
name = "prosthesis"
path = "builtin:prosthesis"
seat = "phantom"
"#,
    )
    .unwrap();
}
