//! The library's modules stand on the floors ARCHITECTURE.md lists: every `crate::` path in a
//! module's sources (comments left out) names a module on a lower floor, and every module of
//! `src/lib.rs` has a floor. A module on a floor of its own, or a new module, means editing the
//! table, which is the point: the layering is decided, not drifted into.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Module name to floor, from the table in ARCHITECTURE.md.
fn floors() -> BTreeMap<String, u32> {
    let text = std::fs::read_to_string(root().join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let mut floors = BTreeMap::new();
    for line in text.lines() {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        let (Some(floor), Some(modules)) = (cells.get(1), cells.get(2)) else {
            continue;
        };
        let Ok(floor) = floor.parse::<u32>() else {
            continue;
        };
        for module in modules.split(',') {
            let name = module.trim().trim_matches('`').to_string();
            assert!(
                floors.insert(name.clone(), floor).is_none(),
                "{name} is on two floors"
            );
        }
    }
    assert!(!floors.is_empty(), "no floor table in ARCHITECTURE.md");
    floors
}

/// The modules `src/lib.rs` declares.
fn library_modules() -> Vec<String> {
    let lib = std::fs::read_to_string(root().join("src/lib.rs")).expect("src/lib.rs");
    lib.lines()
        .filter_map(|l| l.trim().strip_prefix("pub mod "))
        .chain(lib.lines().filter_map(|l| l.trim().strip_prefix("mod ")))
        .map(|m| m.trim_end_matches(';').to_string())
        .collect()
}

/// The Rust files of module `name`: `src/name.rs` or everything under `src/name/`.
fn files_of(name: &str) -> Vec<PathBuf> {
    let file = root().join("src").join(format!("{name}.rs"));
    if file.is_file() {
        return vec![file];
    }
    let mut out = Vec::new();
    let mut stack = vec![root().join("src").join(name)];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
            let path = entry.expect("a folder entry").path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }
    out
}

/// The source without `//` comments (doc comments included: a link may name any module).
fn code_of(path: &Path) -> String {
    let text = std::fs::read_to_string(path).expect("a source file");
    text.lines()
        .map(|line| match line.find("//") {
            // A `//` inside a string (a URL) is rare in this code; "://" is kept as code.
            Some(at) if !line[..at].ends_with(':') => &line[..at],
            _ => line,
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// The top modules that `crate::` paths in `code` name, with the line of each.
fn crate_paths(code: &str) -> Vec<(String, usize)> {
    let mut out = Vec::new();
    for (n, line) in code.lines().enumerate() {
        let mut rest = line;
        while let Some(at) = rest.find("crate::") {
            let before = rest[..at].chars().last();
            rest = &rest[at + "crate::".len()..];
            // `$crate::` in a macro is the crate too; `foo_crate::` is not.
            if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
                continue;
            }
            let name: String = rest
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            out.push((name, n + 1));
        }
    }
    out
}

#[test]
fn no_module_uses_one_beside_or_above_it() {
    let floors = floors();
    let modules = library_modules();
    let mut problems = Vec::new();
    for module in &modules {
        let Some(&floor) = floors.get(module) else {
            problems.push(format!("src/lib.rs declares {module}, which has no floor"));
            continue;
        };
        for file in files_of(module) {
            for (used, line) in crate_paths(&code_of(&file)) {
                if used == *module {
                    continue;
                }
                match floors.get(&used) {
                    Some(&f) if f < floor => {}
                    Some(&f) => problems.push(format!(
                        "{}:{line}: {module} (floor {floor}) uses {used} (floor {f})",
                        file.strip_prefix(root()).unwrap_or(&file).display()
                    )),
                    None => problems.push(format!(
                        "{}:{line}: {module} uses crate::{used}, which is no module with a floor",
                        file.strip_prefix(root()).unwrap_or(&file).display()
                    )),
                }
            }
        }
    }
    for listed in floors.keys() {
        if !modules.contains(listed) {
            problems.push(format!(
                "ARCHITECTURE.md lists {listed}, which src/lib.rs lacks"
            ));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
fn the_checker_sees_an_import_that_climbs() {
    // The parts the test above stands on, on a made-up source.
    let code = "use crate::scene::Scene;\nfn f() { crate::grid::voxel_count([1; 3]); }\n";
    let paths = crate_paths(code);
    assert_eq!(paths, [("scene".to_string(), 1), ("grid".to_string(), 2)]);
    assert!(crate_paths("use my_crate::x;").is_empty());
    let floors = floors();
    assert!(floors["scene"] > floors["grid"], "{floors:?}");
    assert!(floors["geometry"] < floors["volume"], "{floors:?}");
}
