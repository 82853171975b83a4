//! Feeds arbitrary bytes to every volume loader: the input is written to a file with each
//! extension in turn and loaded through format detection. Any result is fine; a panic, an
//! abort on a huge allocation or a hang is a bug.

#![no_main]

use std::path::PathBuf;

use libfuzzer_sys::fuzz_target;
use splatscene::volume::detect::load_volume;

/// Extensions the loaders (or their data-file lookups) care about. Detection goes by content,
/// except that a gzip stream named `.nii.gz` is taken for NIfTI.
const EXTENSIONS: [&str; 7] = ["nrrd", "nhdr", "dat", "vtk", "vti", "nii", "nii.gz"];

/// One scratch folder per fuzzing process, so that parallel jobs never share files.
fn scratch() -> PathBuf {
    let dir = std::env::temp_dir().join(format!("splatscene-fuzz-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("cannot create the fuzzing scratch folder");
    dir
}

fuzz_target!(|data: &[u8]| {
    let dir = scratch();
    for extension in EXTENSIONS {
        let path = dir.join(format!("input.{extension}"));
        if std::fs::write(&path, data).is_ok() {
            let _ = load_volume(&path);
        }
        let _ = std::fs::remove_file(&path);
    }
});
