//! The pictures below an output folder, for comparing two batches file by file and pixel by
//! pixel.

use std::path::Path;

/// Every PNG below `dir` (its path relative to `dir`) with its decoded pixels, sorted by path.
pub fn pictures(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut found = Vec::new();
    let mut folders = vec![dir.to_path_buf()];
    while let Some(folder) = folders.pop() {
        for entry in std::fs::read_dir(&folder).unwrap().flatten() {
            let path = entry.path();
            if path.is_dir() {
                folders.push(path);
            } else if path.extension().is_some_and(|e| e == "png") {
                let rel = path.strip_prefix(dir).unwrap().display().to_string();
                found.push((rel, image::open(&path).unwrap().into_bytes()));
            }
        }
    }
    found.sort();
    found
}
