//! Running the command line, scratch folders and the shared data, for every test file.

use std::ops::Deref;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Runs the `splatscene` binary with `args`: GPU selection left to wgpu (`NODEVICE_SELECT`)
/// and no Slurm array task from the environment the tests run in.
pub fn splatscene(args: &[&str]) -> Output {
    command().args(args).output().expect("run splatscene")
}

/// Runs `splatscene` with `args` and asserts that it succeeds (the failure shows its stderr).
pub fn ok(args: &[&str]) -> Output {
    let out = splatscene(args);
    assert!(
        out.status.success(),
        "splatscene {}: {}",
        args.join(" "),
        stderr(&out)
    );
    out
}

/// Runs `splatscene` with `args`, asserts that it fails, and returns what it wrote to stderr.
pub fn fails(args: &[&str]) -> String {
    let out = splatscene(args);
    assert!(
        !out.status.success(),
        "splatscene {} succeeded",
        args.join(" ")
    );
    stderr(&out)
}

/// What a run wrote to stderr, as text.
pub fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Whether `tool` is on the PATH.
pub fn have(tool: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {tool}")])
        .output()
        .is_ok_and(|o| o.status.success())
}

/// The `splatscene` binary as [`splatscene`] runs it, for a test that adds to the command.
pub fn command() -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_splatscene"));
    command
        .env("NODEVICE_SELECT", "1")
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("SLURM_ARRAY_TASK_COUNT");
    command
}

/// A scratch folder, empty, removed when dropped: at the end of the test, and when it fails
/// too (a panic unwinds through it). With `SPLATSCENE_KEEP` set it stays, and its path is
/// printed, for looking at what a test wrote (the viewer tests' screenshots).
#[derive(Debug)]
pub struct Scratch(Option<tempfile::TempDir>);

impl Deref for Scratch {
    type Target = Path;

    fn deref(&self) -> &Path {
        self.0.as_ref().map_or(Path::new(""), |dir| dir.path())
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        self
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if std::env::var_os("SPLATSCENE_KEEP").is_some()
            && let Some(dir) = self.0.take()
        {
            eprintln!("kept {}", dir.keep().display());
        }
    }
}

/// A new scratch folder in the system's temporary folder, its name starting `splatscene-NAME-`.
pub fn scratch(name: &str) -> Scratch {
    Scratch(Some(
        tempfile::Builder::new()
            .prefix(&format!("splatscene-{name}-"))
            .tempdir()
            .expect("create a scratch folder"),
    ))
}

/// The shared test data folder (`$SPLATSCENE_DATA`, by default `../shared/data` next to the
/// repository), or `None` where it is missing outside CI (the caller then skips, saying so).
/// Missing in CI, it fails: CI has the data, and a silent pass would hide a broken setup.
pub fn data_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("SPLATSCENE_DATA")
        .filter(|v| !v.is_empty())
        .map_or_else(
            || Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data"),
            PathBuf::from,
        );
    if dir.is_dir() {
        return Some(dir);
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "{} is missing under CI: set SPLATSCENE_DATA",
        dir.display()
    );
    eprintln!(
        "skipped: {} is missing (set SPLATSCENE_DATA)",
        dir.display()
    );
    None
}

/// A file of the shared test data, or `None` where it is missing outside CI (see
/// [`data_dir`]).
pub fn data_file(relative: &str) -> Option<PathBuf> {
    let path = data_dir()?.join(relative);
    if path.exists() {
        return Some(path);
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "{} is missing",
        path.display()
    );
    eprintln!(
        "skipped: {} is missing (set SPLATSCENE_DATA)",
        path.display()
    );
    None
}

/// A path of this repository.
pub fn repo(relative: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(relative)
}
