//! Every `splatscene` command in README.md, run as written (from a scratch folder laid out like
//! the repository beside the shared data), so that the README never goes stale: each must
//! succeed and write the files its `--out` and `--depth` name. Two allowances, both to keep the
//! suite fast: `orderings` runs get `--orbit-views 2 --fly-in-views 1` added, and `view` runs
//! are opened under Xvfb until the window shows its first frame, then closed (they need Xvfb
//! and xdotool; without them the viewer lines are skipped with a note, except under CI).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::{Scratch, have, scratch};

/// The `splatscene` commands of the README's shell blocks, each split into arguments.
fn readme_commands() -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md"))
        .expect("read README.md");
    let mut commands = Vec::new();
    let mut in_sh = false;
    let mut pending = String::new();
    for line in text.lines() {
        if line.starts_with("```") {
            in_sh = line.trim() == "```sh";
            continue;
        }
        if !in_sh {
            continue;
        }
        let line = line.trim();
        if pending.is_empty() && !line.starts_with("splatscene ") {
            continue;
        }
        pending.push_str(line.trim_end_matches('\\'));
        pending.push(' ');
        if !line.ends_with('\\') {
            commands.push(split_words(&pending));
            pending.clear();
        }
    }
    commands
}

/// Splits a shell line into words, with double and single quotes (no escapes, no variables:
/// the README needs none).
fn split_words(line: &str) -> Vec<String> {
    let mut words = Vec::new();
    let mut word = String::new();
    let mut quote = None;
    let mut started = false;
    for c in line.chars() {
        match (quote, c) {
            (None, '"' | '\'') => {
                quote = Some(c);
                started = true;
            }
            (Some(q), c) if c == q => quote = None,
            (None, c) if c.is_whitespace() => {
                if started {
                    words.push(std::mem::take(&mut word));
                    started = false;
                }
            }
            (_, c) => {
                word.push(c);
                started = true;
            }
        }
    }
    assert!(quote.is_none(), "unclosed quote in {line}");
    if started {
        words.push(word);
    }
    words
}

/// A scratch folder `root/work` with `examples` linked from the repository and
/// `root/shared/data` linked to the shared data, so that the README's relative paths resolve.
fn workspace(data: &Path) -> Scratch {
    let root = scratch("readme");
    let work = root.join("work");
    std::fs::create_dir_all(&work).unwrap();
    std::fs::create_dir_all(root.join("shared")).unwrap();
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    std::os::unix::fs::symlink(repo.join("examples"), work.join("examples")).unwrap();
    std::os::unix::fs::symlink(std::path::absolute(data).unwrap(), root.join("shared/data"))
        .unwrap();
    root
}

/// The files a command says it writes: its `--out` and `--depth`, with `{view}` replaced by
/// each of its views and `{slice}` by each of its slices (whose calibration lies beside).
fn outputs(args: &[String]) -> Vec<String> {
    let list = |flag: &str| -> Vec<String> {
        args.windows(2)
            .find(|w| w[0] == flag)
            .map(|w| w[1].split(',').map(str::to_owned).collect())
            .unwrap_or_default()
    };
    let (views, slices) = (list("--view"), list("--slice"));
    args.windows(2)
        .filter(|w| w[0] == "--out" || w[0] == "--depth")
        .flat_map(|w| {
            if w[1].contains("{view}") {
                views.iter().map(|v| w[1].replace("{view}", v)).collect()
            } else if w[1].contains("{slice}") {
                slices
                    .iter()
                    .flat_map(|s| {
                        let png = w[1].replace("{slice}", s);
                        [png.replace(".png", ".json"), png]
                    })
                    .collect()
            } else {
                vec![w[1].clone()]
            }
        })
        .collect()
}

/// Opens the viewer on a fresh X display until its title shows a drawn frame.
fn open_viewer(args: &[String], work: &Path) {
    let display = (150..200)
        .find(|n| !Path::new(&format!("/tmp/.X{n}-lock")).exists())
        .map(|n| format!(":{n}"))
        .expect("a free display");
    let mut xvfb = Command::new("Xvfb")
        .args([
            display.as_str(),
            "-screen",
            "0",
            "1024x768x24",
            "-nolisten",
            "tcp",
            // No reset when the last client leaves: a client connecting then is refused.
            "-noreset",
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start Xvfb");
    // The server takes a moment to listen: wait for it before the viewer connects.
    let started = Instant::now();
    while started.elapsed() < Duration::from_secs(10) {
        let probe = Command::new("xdotool")
            .arg("getmouselocation")
            .env("DISPLAY", &display)
            .output();
        if probe.is_ok_and(|o| o.status.success()) {
            break;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let mut viewer = Command::new(env!("CARGO_BIN_EXE_splatscene"))
        .args(args)
        .current_dir(work)
        .env("DISPLAY", &display)
        .env("NODEVICE_SELECT", "1")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the viewer");
    let started = Instant::now();
    let mut drawn = false;
    while started.elapsed() < Duration::from_secs(90) {
        if let Ok(Some(status)) = viewer.try_wait() {
            let mut err = String::new();
            use std::io::Read;
            viewer.stderr.take().unwrap().read_to_string(&mut err).ok();
            let _ = xvfb.kill();
            panic!("splatscene {} exited with {status}: {err}", args.join(" "));
        }
        let title = Command::new("xdotool")
            .args(["search", "--name", "^splatscene.*splats"])
            .env("DISPLAY", &display)
            .output();
        if title.is_ok_and(|o| o.status.success() && !o.stdout.is_empty()) {
            drawn = true;
            break;
        }
        std::thread::sleep(Duration::from_millis(200));
    }
    let _ = viewer.kill();
    let _ = viewer.wait();
    // SIGTERM, so that the X server removes its lock file and its display number is free again.
    let _ = Command::new("kill")
        .args(["-TERM", &xvfb.id().to_string()])
        .stderr(Stdio::null())
        .status();
    let deadline = Instant::now() + Duration::from_secs(5);
    while Instant::now() < deadline && matches!(xvfb.try_wait(), Ok(None)) {
        std::thread::sleep(Duration::from_millis(50));
    }
    let _ = xvfb.kill();
    let _ = xvfb.wait();
    assert!(drawn, "splatscene {}: no frame in 90 s", args.join(" "));
}

#[test]
fn every_readme_command_runs() {
    let data = std::env::var_os("SPLATSCENE_DATA")
        .filter(|v| !v.is_empty())
        .map_or_else(|| PathBuf::from("../shared/data"), PathBuf::from);
    if !data.exists() {
        assert!(
            std::env::var_os("CI").is_none(),
            "{} is missing",
            data.display()
        );
        eprintln!(
            "skipped: {} is missing (set SPLATSCENE_DATA)",
            data.display()
        );
        return;
    }
    let commands = readme_commands();
    assert!(commands.len() >= 15, "found {} commands", commands.len());
    let root = workspace(&data);
    let work = root.join("work");
    let can_view = have("Xvfb") && have("xdotool");
    for words in &commands {
        let mut args: Vec<String> = words[1..].to_vec();
        match args[0].as_str() {
            "view" if !can_view => {
                assert!(
                    std::env::var_os("CI").is_none(),
                    "CI must install xvfb and xdotool"
                );
                eprintln!("skipped (no Xvfb): {}", words.join(" "));
                continue;
            }
            "view" => {
                open_viewer(&args, &work);
                continue;
            }
            "orderings" => {
                args.extend(["--orbit-views", "2", "--fly-in-views", "1"].map(String::from))
            }
            _ => {}
        }
        let started = Instant::now();
        let out = Command::new(env!("CARGO_BIN_EXE_splatscene"))
            .args(&args)
            .current_dir(&work)
            .env("NODEVICE_SELECT", "1")
            .output()
            .expect("run splatscene");
        assert!(
            out.status.success(),
            "{}: {}",
            words.join(" "),
            String::from_utf8_lossy(&out.stderr)
        );
        for file in outputs(&args) {
            let len = std::fs::metadata(work.join(&file)).map_or(0, |m| m.len());
            assert!(len > 0, "{}: {file} was not written", words.join(" "));
        }
        eprintln!(
            "{:.1} s: {}",
            started.elapsed().as_secs_f64(),
            words.join(" ")
        );
    }
}

#[test]
fn shell_words_split_like_a_shell() {
    assert_eq!(
        split_words(r#"render a --caption "two words" --t '{ x = [0, 1] }' "#),
        [
            "render",
            "a",
            "--caption",
            "two words",
            "--t",
            "{ x = [0, 1] }"
        ]
    );
}
