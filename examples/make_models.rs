//! Writes the generated humeral-stem prosthesis to `models/` as `prosthesis.gltf` and as
//! `prosthesis.obj` with `prosthesis.mtl`.
//!
//! Run with `cargo run --release --example make_models`. The files are committed, and a unit
//! test in `splatscene::mesh::prosthesis` fails when they differ from what the code generates,
//! so run this after changing the prosthesis or the writers.

use std::fs;
use std::path::Path;

use splatscene::mesh::prosthesis::{ProsthesisParams, humeral_prosthesis};
use splatscene::mesh::write::{write_gltf, write_obj};

fn main() -> std::io::Result<()> {
    // Next to Cargo.toml whatever the working directory, where the unit test looks.
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("models");
    fs::create_dir_all(&dir)?;
    let model = humeral_prosthesis(&ProsthesisParams::default());
    let (obj, mtl) = write_obj(&model, "prosthesis.mtl");
    let files = [
        ("prosthesis.gltf", write_gltf(&model)),
        ("prosthesis.obj", obj),
        ("prosthesis.mtl", mtl),
    ];
    for (name, text) in files {
        let path = dir.join(name);
        fs::write(&path, &text)?;
        println!("wrote {} ({} bytes)", path.display(), text.len());
    }
    for part in &model.parts {
        let count = part.mesh.triangle_count();
        println!("{}: {count} triangles", part.name);
    }
    Ok(())
}
