//! Feeds arbitrary text to the scene-file reader: parsed, its values checked, and, when it
//! names no volume (whose loading would dominate each run), loaded. Any result is fine; a
//! panic, an abort on a huge allocation or a hang is a bug.

#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use splatscene::scene::file::SceneFile;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let path = Path::new("fuzz.toml");
    if let Ok(file) = SceneFile::parse(text, path)
        && file.volumes.is_empty()
    {
        let _ = file.load(path, &std::env::temp_dir());
    }
});
