//! The viewer tried as a user would: under Xvfb, with lavapipe, the test starts
//! `splatscene view`, clicks on the prosthesis, presses the ordering, transfer-function and
//! screenshot keys (xdotool), takes screenshots of the screen (xwd), and checks that the pick
//! was reported at the right place and that the picture changed with each key.
//!
//! Needs `xvfb`, `xdotool` and `x11-apps` (CI installs them). Without them the test says so
//! and passes, except under CI (`CI` set), where it fails.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{Receiver, channel};
use std::time::{Duration, Instant};

/// The tests start X servers and windows: one at a time, so that two never pick the same free
/// display number.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn have(tool: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {tool}")])
        .output()
        .is_ok_and(|o| o.status.success())
}

/// Kills the child when dropped, so a failed assertion leaves no X server or viewer behind.
struct Guard(Child);

impl Drop for Guard {
    fn drop(&mut self) {
        // SIGTERM first, so that an X server removes its lock file and socket (a killed one
        // leaves them, and its display number stays taken); SIGKILL if it lingers.
        let _ = Command::new("kill")
            .args(["-TERM", &self.0.id().to_string()])
            .stderr(Stdio::null())
            .status();
        let deadline = Instant::now() + Duration::from_secs(5);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.0.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Whether Xvfb, xdotool and xwd are here; without them the test is skipped with a note,
/// except under CI (`CI` set), which must have them.
fn x11_tools() -> bool {
    if have("Xvfb") && have("xdotool") && have("xwd") {
        return true;
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "CI must install xvfb, xdotool and x11-apps"
    );
    eprintln!("skipped: needs Xvfb, xdotool and xwd (apt-get install xvfb xdotool x11-apps)");
    false
}

fn start_xvfb() -> (Guard, String) {
    for n in 90..140 {
        if Path::new(&format!("/tmp/.X{n}-lock")).exists() {
            continue;
        }
        let display = format!(":{n}");
        let child = Command::new("Xvfb")
            .args([
                display.as_str(),
                "-screen",
                "0",
                "1024x768x24",
                "-nolisten",
                "tcp",
                // No reset when the last client leaves: a client connecting during a reset is
                // refused (xdotool's probe is often the last client before the viewer).
                "-noreset",
            ])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start Xvfb");
        let guard = Guard(child);
        let started = Instant::now();
        while started.elapsed() < Duration::from_secs(10) {
            if xdo(&display, &["getmouselocation"]).is_some() {
                return (guard, display);
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }
    panic!("no X display could be started");
}

fn xdo(display: &str, args: &[&str]) -> Option<String> {
    let out = Command::new("xdotool")
        .args(args)
        .env("DISPLAY", display)
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_owned())
}

/// Waits until `check` gives something, or panics after `secs` seconds.
fn wait_for<T>(what: &str, secs: u64, mut check: impl FnMut() -> Option<T>) -> T {
    let started = Instant::now();
    loop {
        if let Some(v) = check() {
            return v;
        }
        assert!(
            started.elapsed() < Duration::from_secs(secs),
            "timed out waiting for {what}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn screen(display: &str, dir: &Path, name: &str) -> Vec<u8> {
    let path = dir.join(format!("{name}.xwd"));
    let ok = Command::new("xwd")
        .args(["-root", "-silent", "-out", path.to_str().unwrap()])
        .env("DISPLAY", display)
        .status()
        .is_ok_and(|s| s.success());
    assert!(ok, "xwd");
    std::fs::read(path).unwrap()
}

/// The next stdout line of the viewer that starts with `prefix`.
fn line(lines: &Receiver<String>, prefix: &str) -> String {
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let line = lines
            .recv_timeout(left)
            .unwrap_or_else(|_| panic!("no '{prefix}' line from the viewer"));
        if let Some(rest) = line.strip_prefix(prefix) {
            return rest.trim().to_owned();
        }
    }
}

/// Starts the viewer with `args` on `display`: the process, its standard output line by line,
/// and its window once it exists.
fn open_viewer(display: &str, args: &[&str]) -> (Guard, Receiver<String>, String) {
    // The viewer's stderr goes to a file, shown if its window never comes.
    let log = std::env::temp_dir().join(format!(
        "splatscene-viewer-{}-{}.log",
        std::process::id(),
        display.trim_start_matches(':')
    ));
    let mut viewer = Command::new(env!("CARGO_BIN_EXE_splatscene"))
        .args(args)
        .env("DISPLAY", display)
        .env("NODEVICE_SELECT", "1")
        .stdout(Stdio::piped())
        .stderr(std::fs::File::create(&log).expect("a log file"))
        .spawn()
        .expect("start the viewer");
    let stdout = viewer.stdout.take().unwrap();
    let viewer = Guard(viewer);
    let (send, lines) = channel();
    std::thread::spawn(move || {
        for l in BufReader::new(stdout).lines().map_while(Result::ok) {
            let _ = send.send(l);
        }
    });
    let started = Instant::now();
    let mut viewer = viewer;
    let window = loop {
        let found = xdo(display, &["search", "--name", "^splatscene"])
            .and_then(|s| s.lines().next().map(str::to_owned));
        if let Some(window) = found {
            break window;
        }
        let exited = viewer.0.try_wait().ok().flatten();
        if exited.is_some() || started.elapsed() > Duration::from_secs(60) {
            let said = std::fs::read_to_string(&log).unwrap_or_default();
            panic!("no viewer window on {display} (exit: {exited:?}): {said}");
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    std::fs::remove_file(&log).ok();
    (viewer, lines, window)
}

/// Waits for the window title to contain `text` (the title changes after each frame).
fn title(display: &str, window: &str, text: &str) -> String {
    title_where(display, window, &format!("a title with {text:?}"), |t| {
        t.contains(text)
    })
}

/// Waits for a window title that passes `check`, and returns it.
fn title_where(display: &str, window: &str, what: &str, check: impl Fn(&str) -> bool) -> String {
    let title = wait_for(what, 60, || {
        xdo(display, &["getwindowname", window]).filter(|t| check(t))
    });
    // The title is set after the frame is presented; give the X server a moment to show it.
    std::thread::sleep(Duration::from_millis(300));
    title
}

/// The splat count in a window title ("... | 54080 splats").
fn splats_in(title: &str) -> usize {
    let before = title.split(" splats").next().unwrap();
    before.rsplit(' ').next().unwrap().parse().unwrap()
}

#[test]
fn viewer_picks_switches_orderings_and_takes_screenshots_under_xvfb() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    if !x11_tools() {
        return;
    }
    let (_xvfb, display) = start_xvfb();
    let dir: PathBuf =
        std::env::temp_dir().join(format!("splatscene-viewer-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (viewer, lines, window) = open_viewer(
        &display,
        // The GPU's splat pass: its full frames take over 50 ms on lavapipe, so drags preview.
        &[
            "view",
            "--size",
            "640x480",
            "--compositor",
            "gpu",
            "--screenshots",
            dir.to_str().unwrap(),
        ],
    );
    title(&display, &window, " splats");
    xdo(&display, &["windowfocus", "--sync", &window]);
    let first = screen(&display, &dir, "first");

    // The built-in view at 640x480 shows the prosthesis head at (320, 160).
    xdo(
        &display,
        &["mousemove", "--window", &window, "320", "160", "click", "1"],
    )
    .expect("click");
    let pick: serde_json::Value = serde_json::from_str(&line(&lines, "pick")).unwrap();
    assert_eq!(pick["hit"]["node_name"], "head", "{pick}");
    assert_eq!(pick["hit"]["frame"], "RAS", "{pick}");
    assert_eq!(pick["pixel"], serde_json::json!([320, 160]));
    let point = glam::DVec3::from_array(std::array::from_fn(|i| {
        pick["hit"]["point"][i].as_f64().unwrap()
    }));
    let marks = splatscene::volume::shoulder_landmarks(
        splatscene::volume::phantom::DEFAULT_DIMS,
        splatscene::volume::phantom::DEFAULT_SPACING,
    );
    let from_centre = point.distance(glam::DVec3::from_array(marks.head_centre));
    let radius = splatscene::mesh::prosthesis::ProsthesisParams::default().head_radius;
    assert!(
        (from_centre - radius).abs() < 0.5,
        "the pick lies on the head's sphere: {from_centre} mm from its centre"
    );
    title(&display, &window, " splats");
    let marked = screen(&display, &dir, "marked");
    assert_ne!(first, marked, "the pick marker shows");

    xdo(&display, &["key", "2"]).expect("key 2");
    assert_eq!(line(&lines, "ordering"), "pbtf");
    title(&display, &window, "pbtf");
    let pbtf = screen(&display, &dir, "pbtf");
    assert_ne!(marked, pbtf, "PBTF draws a different picture from IP-PBTF");

    xdo(&display, &["key", "t"]).expect("key t");
    assert_eq!(line(&lines, "transfer function"), "ct-soft-tissue");
    title(&display, &window, "ct-soft-tissue");
    let dense = screen(&display, &dir, "dense");
    assert_ne!(pbtf, dense, "the transfer function changes the picture");

    xdo(&display, &["key", "c"]).expect("key c");
    assert!(line(&lines, "clip plane").starts_with("on"));
    xdo(&display, &["key", "bracketleft"]).expect("key [");
    line(&lines, "clip plane offset");
    title(&display, &window, " splats");
    let clipped = screen(&display, &dir, "clipped");
    assert_ne!(dense, clipped, "the clip plane cuts the volume");

    xdo(&display, &["key", "s"]).expect("key s");
    let shot = PathBuf::from(line(&lines, "screenshot"));
    let image = image::open(&shot).unwrap();
    assert_eq!((image.width(), image.height()), (640, 480));

    // A drag orbits with preview frames (an eighth of the splats), as it does where a full
    // frame takes over 50 ms (here on lavapipe, over 100 ms); the release draws the full frame
    // again.
    let full = splats_in(&title(&display, &window, " splats"));
    xdo(
        &display,
        &[
            "mousemove",
            "--window",
            &window,
            "200",
            "300",
            "mousedown",
            "1",
        ],
    )
    .expect("press");
    xdo(&display, &["mousemove", "--window", &window, "260", "320"]).expect("drag");
    let preview = title(&display, &window, "(preview)");
    assert!(
        splats_in(&preview) * 4 < full,
        "{preview} against {full} splats"
    );
    xdo(&display, &["mouseup", "1"]).expect("release");
    let after = title_where(&display, &window, "a full frame's title", |t| {
        t.ends_with(" splats")
    });
    assert!(splats_in(&after) > splats_in(&preview) * 4, "{after}");
    // A wheel step zooms with a preview, and the full frame follows once the wheel rests.
    xdo(
        &display,
        &["mousemove", "--window", &window, "320", "240", "click", "4"],
    )
    .expect("wheel");
    title(&display, &window, "(preview)");
    let settled = title_where(&display, &window, "the settled zoom's full frame", |t| {
        t.ends_with(" splats")
    });
    assert!(splats_in(&settled) > splats_in(&preview) * 4, "{settled}");

    xdo(&display, &["key", "q"]).expect("key q");
    let mut viewer = viewer;
    let status = wait_for("the viewer to quit", 30, || {
        viewer.0.try_wait().ok().flatten()
    });
    assert!(status.success(), "{status:?}");
    std::fs::remove_dir_all(&dir).ok();
}

/// Grey values of a PNG, row by row.
fn grey(path: &Path) -> (u32, u32, Vec<f64>) {
    let image = image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8();
    let values = image
        .pixels()
        .map(|p| p.0.iter().map(|&c| f64::from(c)).sum())
        .collect();
    (image.width(), image.height(), values)
}

fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let cov: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
    let va: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
    let vb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
    cov / (va * vb).sqrt()
}

/// The brightness of each row: a picture turned upside down reverses it.
fn row_profile(width: u32, values: &[f64]) -> Vec<f64> {
    values
        .chunks(width as usize)
        .map(|row| row.iter().sum())
        .collect()
}

/// LIDC2 placed as index times spacing, where +z is inferior: the scene says its up is -z. A
/// drag of 2 px and one of 200 px orbit about that up, so the picture stays upright; the
/// screenshot key saves the view as a scene file, and `render` of it draws the same picture.
#[test]
fn viewer_orbits_upright_and_saves_views_that_render_reproduces() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    if !x11_tools() {
        return;
    }
    let data = std::env::var_os("SPLATSCENE_DATA")
        .filter(|v| !v.is_empty())
        .map_or_else(|| PathBuf::from("../shared/data"), PathBuf::from);
    let ct = data.join("volumes/lidc2/lidc2_256x256x133_uint8.raw");
    if !ct.exists() {
        assert!(
            std::env::var_os("CI").is_none(),
            "{} is missing",
            ct.display()
        );
        eprintln!("skipped: {} is missing (set SPLATSCENE_DATA)", ct.display());
        return;
    }
    let dir: PathBuf =
        std::env::temp_dir().join(format!("splatscene-viewer-views-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene = dir.join("lidc2-up-minus-z.toml");
    std::fs::write(
        &scene,
        format!(
            "[camera]\nview_from = [0.0, -1.0, 0.3]\nup = [0.0, 0.0, -1.0]\n\n[[volume]]\n\
             path = {:?}\ndims = [256, 256, 133]\nscalar = \"u8\"\n\
             spacing = [1.40625, 1.40625, 2.5]\ntransfer = \"ramp\"\nwindow = [130.0, 235.0]\n",
            std::path::absolute(&ct).unwrap().to_str().unwrap()
        ),
    )
    .unwrap();
    let (_xvfb, display) = start_xvfb();
    let (viewer, lines, window) = open_viewer(
        &display,
        &[
            "view",
            scene.to_str().unwrap(),
            "--size",
            "256x256",
            "--screenshots",
            dir.to_str().unwrap(),
        ],
    );
    title(&display, &window, " splats");
    xdo(&display, &["windowfocus", "--sync", &window]);
    let shoot = || {
        xdo(&display, &["key", "s"]).expect("key s");
        let png = PathBuf::from(line(&lines, "screenshot"));
        let toml = PathBuf::from(line(&lines, "view"));
        (png, toml)
    };
    let drag = |dx: u32| {
        let end = (40 + dx).to_string();
        xdo(
            &display,
            &[
                "mousemove",
                "--window",
                &window,
                "40",
                "128",
                "mousedown",
                "1",
            ],
        )
        .expect("press");
        xdo(&display, &["mousemove", "--window", &window, &end, "128"]).expect("drag");
        xdo(&display, &["mouseup", "1"]).expect("release");
        title_where(&display, &window, "a full frame's title", |t| {
            t.ends_with(" splats")
        });
        // A drag without a frame in between may end before the viewer saw the motion.
        std::thread::sleep(Duration::from_millis(500));
    };
    // On a CPU adapter the tile compositor draws (auto), and says so in the title.
    let on_cpu = splatscene::render::GpuContext::headless()
        .is_ok_and(|c| c.adapter.get_info().device_type == wgpu::DeviceType::Cpu);
    // (" splats": the title before the first frame, "splatscene", holds "splats" too.)
    let first = title(&display, &window, " splats");
    assert_eq!(first.contains("(CPU tiles)"), on_cpu, "{first}");
    let (home, _) = shoot();
    drag(2);
    let (nudged, _) = shoot();
    drag(200);
    let (turned, turned_scene) = shoot();
    let (w, _, a) = grey(&home);
    let (_, _, b) = grey(&nudged);
    let (_, _, c) = grey(&turned);
    let r = correlation(&a, &b);
    assert!(r > 0.9, "a 2 px drag keeps the picture: correlation {r}");
    let rows = correlation(&row_profile(w, &a), &row_profile(w, &c));
    assert!(
        rows > 0.5,
        "after a 200 px drag the top stays on top: row profiles correlate {rows}"
    );
    assert_ne!(a, c, "the 200 px drag turned the view");
    // The saved view, rendered from the command line, is the same picture.
    let again = dir.join("again.png");
    let out = Command::new(env!("CARGO_BIN_EXE_splatscene"))
        .args(["render", turned_scene.to_str().unwrap(), "--out"])
        .arg(&again)
        .env("NODEVICE_SELECT", "1")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (_, _, d) = grey(&again);
    assert_eq!(c.len(), d.len(), "the saved view keeps the window's size");
    let rmse = (c
        .iter()
        .zip(&d)
        .map(|(x, y)| ((x - y) / 765.0).powi(2))
        .sum::<f64>()
        / c.len() as f64)
        .sqrt();
    assert!(rmse < 0.01, "render of the saved view: RMSE {rmse}");
    // The annotations (on by default) go off with A; the screen changes, the screenshots
    // never carried them.
    let annotated = screen(&display, &dir, "annotated");
    xdo(&display, &["key", "a"]).expect("key a");
    assert_eq!(line(&lines, "annotations"), "off");
    title(&display, &window, " splats");
    std::thread::sleep(Duration::from_millis(500));
    let plain = screen(&display, &dir, "plain");
    assert_ne!(annotated, plain, "the annotations showed on screen");
    xdo(&display, &["key", "q"]).expect("key q");
    let mut viewer = viewer;
    wait_for("the viewer to quit", 30, || {
        viewer.0.try_wait().ok().flatten()
    });
    std::fs::remove_dir_all(&dir).ok();
}

/// A world point from a pick line's hit.
fn hit_point(pick: &serde_json::Value) -> Option<glam::DVec3> {
    let p = &pick["hit"]["point"];
    p.is_array()
        .then(|| glam::DVec3::from_array(std::array::from_fn(|i| p[i].as_f64().unwrap())))
}

/// The translation of the mesh `name` in the scene file at `path`, as loaded.
fn mesh_translation(path: &Path, name: &str) -> glam::DVec3 {
    let scene = splatscene::scene::file::load_scene_file(path)
        .unwrap()
        .scene;
    let id = scene.find(name).unwrap();
    scene.node(id).unwrap().local().w_axis.truncate()
}

#[test]
fn a_plan_made_in_the_viewer_is_saved_undone_measured_and_reloaded_under_xvfb() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    if !x11_tools() {
        return;
    }
    let (_xvfb, display) = start_xvfb();
    let dir: PathBuf = std::env::temp_dir().join(format!("splatscene-plan-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    // Each step's screenshot stays in this folder when the test fails.
    eprintln!("screenshots in {}", dir.display());
    let original = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenes/shoulder.toml");
    let case = dir.join("case");
    std::fs::create_dir_all(&case).unwrap();
    let scene_path = case.join("shoulder.toml");
    std::fs::copy(&original, &scene_path).unwrap();
    let (viewer, lines, window) = open_viewer(
        &display,
        &[
            "view",
            scene_path.to_str().unwrap(),
            "--size",
            "640x480",
            "--screenshots",
            dir.to_str().unwrap(),
        ],
    );
    title(&display, &window, " splats");
    xdo(&display, &["windowfocus", "--sync", &window]);
    let first = screen(&display, &dir, "1-opened");

    // Click the prosthesis head (at 320,160 in this view): it is picked and selected.
    xdo(
        &display,
        &["mousemove", "--window", &window, "320", "160", "click", "1"],
    )
    .expect("click");
    line(&lines, "pick");
    assert_eq!(line(&lines, "selected"), "prosthesis");
    title(&display, &window, " splats");
    let selected = screen(&display, &dir, "2-selected");
    assert_ne!(first, selected, "the selection is tinted");

    // Drag it 40 pixels to the right: a drag that starts on the selected mesh moves it.
    let before = mesh_translation(&scene_path, "prosthesis");
    for step in [
        vec![
            "mousemove",
            "--window",
            &window,
            "320",
            "160",
            "mousedown",
            "1",
        ],
        vec!["mousemove", "--window", &window, "340", "160"],
        vec!["mousemove", "--window", &window, "360", "160"],
        vec!["mouseup", "1"],
    ] {
        xdo(&display, &step).expect("drag");
        std::thread::sleep(Duration::from_millis(150));
    }
    assert!(line(&lines, "moved").starts_with("prosthesis"));
    title(&display, &window, " splats");
    let moved = screen(&display, &dir, "3-moved");
    assert_ne!(selected, moved, "the prosthesis moved on screen");
    xdo(&display, &["key", "ctrl+s"]).expect("ctrl+s");
    let saved = PathBuf::from(line(&lines, "saved plan"));
    assert_eq!(saved, case.join("shoulder-plan.toml"));
    let after = mesh_translation(&saved, "prosthesis");
    // The pivot (the mesh's origin) followed the cursor: 40 pixels at its depth.
    let loaded = splatscene::scene::file::load_scene_file(&scene_path).unwrap();
    let camera = loaded.scene.camera.unwrap();
    let forward = (camera.target - camera.eye).normalize();
    let right = forward.cross(camera.up).normalize();
    let depth = (before - camera.eye).dot(forward);
    let splatscene::scene::Projection::Perspective { fov_y_degrees } = camera.projection else {
        panic!("the scene's camera is perspective");
    };
    let pixel = 2.0 * depth * (0.5 * fov_y_degrees.to_radians()).tan() / 480.0;
    let expected = before + 40.0 * pixel * right;
    assert!(
        after.distance(expected) < 1e-6,
        "moved to {after}, expected {expected} (40 px of {pixel} mm from {before})"
    );

    // Undo puts it back; the next save is a new file with the old place.
    xdo(&display, &["key", "ctrl+z"]).expect("ctrl+z");
    assert_eq!(line(&lines, "undo"), "move prosthesis");
    xdo(&display, &["key", "ctrl+s"]).expect("ctrl+s");
    let undone = PathBuf::from(line(&lines, "saved plan"));
    assert_eq!(undone, case.join("shoulder-plan-2.toml"));
    assert!(mesh_translation(&undone, "prosthesis").distance(before) < 1e-9);
    title(&display, &window, " splats");
    screen(&display, &dir, "4-undone");

    // Snap: a point of the prosthesis (its head) onto a point of the bone.
    xdo(&display, &["key", "n"]).expect("n");
    assert!(line(&lines, "snap:").starts_with("click a point"));
    xdo(
        &display,
        &["mousemove", "--window", &window, "320", "160", "click", "1"],
    )
    .expect("click");
    let source: serde_json::Value = serde_json::from_str(&line(&lines, "pick")).unwrap();
    let source = hit_point(&source).expect("the head is hit");
    assert!(line(&lines, "snap:").starts_with("now click"));
    let mut target = None;
    for (x, y) in [(250, 330), (300, 380), (380, 300), (420, 260)] {
        xdo(
            &display,
            &[
                "mousemove",
                "--window",
                &window,
                &x.to_string(),
                &y.to_string(),
                "click",
                "1",
            ],
        )
        .expect("click");
        let pick: serde_json::Value = serde_json::from_str(&line(&lines, "pick")).unwrap();
        if let Some(p) = hit_point(&pick) {
            target = Some(p);
            break;
        }
    }
    let target = target.expect("a click hit the bone");
    assert!(line(&lines, "snapped by").starts_with('('));
    xdo(&display, &["key", "ctrl+s"]).expect("ctrl+s");
    let snapped = PathBuf::from(line(&lines, "saved plan"));
    let moved_by = mesh_translation(&snapped, "prosthesis") - before;
    assert!(
        moved_by.distance(target - source) < 1e-6,
        "snapped by {moved_by}, the points are {} apart",
        target - source
    );
    title(&display, &window, " splats");
    screen(&display, &dir, "4b-snapped");
    xdo(&display, &["key", "ctrl+z"]).expect("ctrl+z");
    assert_eq!(line(&lines, "undo"), "move prosthesis");

    // Measure an angle with three clicks on the bone and the implant.
    xdo(&display, &["key", "Escape"]).expect("escape");
    assert_eq!(line(&lines, "selected"), "nothing");
    xdo(&display, &["key", "m"]).expect("m");
    assert_eq!(line(&lines, "measure"), "distance");
    xdo(&display, &["key", "m"]).expect("m");
    assert_eq!(line(&lines, "measure"), "angle");
    let mut points = Vec::new();
    for (x, y) in [
        (250, 330),
        (320, 160),
        (380, 300),
        (300, 380),
        (420, 260),
        (200, 250),
    ] {
        xdo(
            &display,
            &[
                "mousemove",
                "--window",
                &window,
                &x.to_string(),
                &y.to_string(),
                "click",
                "1",
            ],
        )
        .expect("click");
        let pick: serde_json::Value = serde_json::from_str(&line(&lines, "pick")).unwrap();
        if let Some(p) = hit_point(&pick) {
            points.push(p);
        }
        if points.len() == 3 {
            break;
        }
    }
    assert_eq!(points.len(), 3, "three of the clicks hit the scene");
    let said = line(&lines, "measurement 1");
    let (u, v) = (points[0] - points[1], points[2] - points[1]);
    let angle = u.angle_between(v).to_degrees();
    assert!(
        said.contains(&format!("{angle:.1}")),
        "{said} against {angle}"
    );
    title(&display, &window, " splats");
    let measured_shot = screen(&display, &dir, "5-measured");
    xdo(&display, &["key", "l"]).expect("l");
    xdo(&display, &["type", "neck"]).expect("type");
    xdo(&display, &["key", "Return"]).expect("enter");
    assert!(line(&lines, "measurement 1").contains("neck"));
    xdo(&display, &["key", "ctrl+s"]).expect("ctrl+s");
    let measured = PathBuf::from(line(&lines, "saved plan"));
    let plan = splatscene::scene::file::load_scene_file(&measured)
        .unwrap()
        .scene;
    assert_eq!(plan.measurements.len(), 1);
    assert_eq!(plan.measurements[0].label.as_deref(), Some("neck"));
    let value = plan.measure(&plan.measurements[0]).unwrap().value.unwrap();
    assert!(
        (value - angle).abs() < 1e-6,
        "saved {value}, clicked {angle}"
    );

    // The screenshot key's scene file renders to the same picture, measurement markers
    // included (the values are on-screen text, not in the screenshot).
    xdo(&display, &["key", "s"]).expect("s");
    let shot = PathBuf::from(line(&lines, "screenshot"));
    let view_file = PathBuf::from(line(&lines, "view"));
    let rendered = dir.join("rendered.png");
    let out = Command::new(env!("CARGO_BIN_EXE_splatscene"))
        .args(["render", view_file.to_str().unwrap(), "--annotate", "none"])
        .args(["--out", rendered.to_str().unwrap()])
        .env("NODEVICE_SELECT", "1")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (a, b) = (
        image::open(&shot).unwrap().to_rgba8(),
        image::open(&rendered).unwrap().to_rgba8(),
    );
    assert_eq!(a.dimensions(), b.dimensions());
    let differing = a.pixels().zip(b.pixels()).filter(|(p, q)| p != q).count();
    assert!(
        differing * 1000 < (a.width() * a.height()) as usize,
        "{differing} pixels differ between the viewer's screenshot and render of its file"
    );

    // B: a crop box, outlined, saved with the plan.
    xdo(&display, &["key", "b"]).expect("b");
    assert!(line(&lines, "crop box").starts_with("on"));
    title(&display, &window, " splats");
    screen(&display, &dir, "5a-cropped");
    xdo(&display, &["key", "ctrl+s"]).expect("ctrl+s");
    let cropped = PathBuf::from(line(&lines, "saved plan"));
    let file = splatscene::scene::file::SceneFile::read(&cropped).unwrap();
    assert!(file.volumes[0].crop_box.is_some(), "the crop box is saved");
    xdo(&display, &["key", "b"]).expect("b");
    assert_eq!(line(&lines, "crop box"), "off");

    // A plan that cannot be written is said so, and kept: its folder gone, then back.
    xdo(&display, &["key", "Delete"]).expect("delete");
    assert!(line(&lines, "measurement 1").starts_with("delete"));
    let moved_away = dir.join("case-moved");
    std::fs::rename(&case, &moved_away).unwrap();
    xdo(&display, &["key", "ctrl+s"]).expect("ctrl+s");
    assert!(line(&lines, "the plan was not saved").contains("kept here"));
    std::fs::rename(&moved_away, &case).unwrap();
    xdo(&display, &["key", "ctrl+z"]).expect("ctrl+z");
    assert!(line(&lines, "undo").starts_with("delete"));
    xdo(&display, &["key", "ctrl+s"]).expect("ctrl+s");
    let kept = PathBuf::from(line(&lines, "saved plan"));
    let plan = splatscene::scene::file::load_scene_file(&kept)
        .unwrap()
        .scene;
    assert_eq!(plan.measurements.len(), 1, "the undone deletion is saved");

    // T: the presets that fit this CT (ct-bone, the scene's own, is left out), then the
    // scene's own again; Alt+drag sets a window, saved as the volume's level_width.
    xdo(&display, &["key", "t"]).expect("t");
    assert_eq!(line(&lines, "transfer function"), "ct-soft-tissue");
    xdo(&display, &["key", "t"]).expect("t");
    assert_eq!(line(&lines, "transfer function"), "ct-metal");
    xdo(&display, &["key", "t"]).expect("t");
    assert_eq!(line(&lines, "transfer function"), "of the scene");
    for step in [
        vec!["keydown", "alt"],
        vec![
            "mousemove",
            "--window",
            &window,
            "100",
            "400",
            "mousedown",
            "1",
        ],
        vec!["mousemove", "--window", &window, "140", "400"],
        vec!["mouseup", "1"],
        vec!["keyup", "alt"],
    ] {
        xdo(&display, &step).expect("alt drag");
        std::thread::sleep(Duration::from_millis(150));
    }
    let window_said = line(&lines, "window level");
    title(&display, &window, "window level");
    screen(&display, &dir, "5b-windowed");
    xdo(&display, &["key", "ctrl+s"]).expect("ctrl+s");
    let windowed = PathBuf::from(line(&lines, "saved plan"));
    let file = splatscene::scene::file::SceneFile::read(&windowed).unwrap();
    let [level, width] = file.volumes[0].level_width.expect("the window is saved");
    // ct-bone spans 150 to 1200 HU: 40 pixels right raise the level by a tenth of that.
    assert!((width - 1050.0).abs() < 1e-3, "{width}");
    assert!(
        (level - (675.0 + 40.0 * 1050.0 / 400.0)).abs() < 1e-2,
        "{level}"
    );
    assert!(
        window_said.starts_with(&format!("{level:.0} width {width:.0}")),
        "{window_said}"
    );

    // An edit of the scene file beside the viewer is read again, the camera kept.
    let text = std::fs::read_to_string(&scene_path).unwrap();
    std::fs::write(
        &scene_path,
        text.replace(
            "name = \"prosthesis\"",
            "name = \"prosthesis\"\ncolor = [0.2, 0.4, 0.9]",
        ),
    )
    .unwrap();
    assert_eq!(PathBuf::from(line(&lines, "reloaded")), scene_path);
    title(&display, &window, " splats");
    let reloaded = screen(&display, &dir, "6-reloaded");
    assert_ne!(reloaded, measured_shot, "the blue prosthesis shows");

    xdo(&display, &["key", "q"]).expect("key q");
    let mut viewer = viewer;
    let status = wait_for("the viewer to quit", 30, || {
        viewer.0.try_wait().ok().flatten()
    });
    assert!(status.success(), "{status:?}");
    if std::env::var_os("SPLATSCENE_KEEP").is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    }
}
