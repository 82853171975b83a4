//! The Python module's tests (`python/tests`, pytest), run against this build's command line.
//!
//! They need a Python with the module installed, pytest, SimpleITK, nibabel, Pillow and mypy:
//! `SPLATSCENE_PYTHON` names its interpreter (default `target/python/bin/python`, the virtual
//! environment `.ci/run` makes with `pip install ./python`). Without one the test says what is
//! missing and passes, except under CI (`CI` set), where it fails.

use std::path::PathBuf;
use std::process::Command;

/// The interpreter that has the module, or why there is none.
fn python() -> Result<PathBuf, String> {
    let python = std::env::var_os("SPLATSCENE_PYTHON").map_or_else(
        || PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/python/bin/python"),
        PathBuf::from,
    );
    if !python.exists() {
        return Err(format!(
            "{}: no such interpreter; make one with `python3 -m venv target/python && target/python/bin/pip install ./python pytest SimpleITK nibabel pillow mypy` or set SPLATSCENE_PYTHON",
            python.display()
        ));
    }
    let probe = Command::new(&python)
        .args([
            "-c",
            "import splatscene, pytest, SimpleITK, nibabel, PIL, mypy",
        ])
        .output()
        .map_err(|e| format!("{}: {e}", python.display()))?;
    if !probe.status.success() {
        return Err(format!(
            "{} cannot import the module and the test tools: {}",
            python.display(),
            String::from_utf8_lossy(&probe.stderr)
        ));
    }
    Ok(python)
}

#[test]
fn the_python_module_passes_its_tests() {
    let python = match python() {
        Ok(p) => p,
        Err(why) => {
            assert!(
                std::env::var_os("CI").is_none(),
                "CI must install the Python module and its test tools: {why}"
            );
            eprintln!("skipped: {why}");
            return;
        }
    };
    let tests = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("python/tests");
    let status = Command::new(&python)
        .args(["-m", "pytest", "-q", "-p", "no:cacheprovider"])
        .arg(&tests)
        .current_dir(&tests)
        .env("SPLATSCENE_BIN", env!("CARGO_BIN_EXE_splatscene"))
        .env("NODEVICE_SELECT", "1")
        .status()
        .expect("run pytest");
    assert!(
        status.success(),
        "the Python module's tests failed (pytest's report is above)"
    );
}
