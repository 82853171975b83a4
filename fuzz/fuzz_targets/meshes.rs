//! Feeds arbitrary bytes to the mesh loaders, under each name the format sniffing looks at
//! (GLB, glTF JSON, OBJ, STL). In-memory input may only use data URIs, so no file is read.
//! Any result is fine; a panic, an abort on a huge allocation or a hang is a bug.

#![no_main]

use libfuzzer_sys::fuzz_target;
use splatscene::mesh::load_mesh_bytes;

const NAMES: [&str; 4] = ["m.glb", "m.gltf", "m.obj", "m.stl"];

fuzz_target!(|data: &[u8]| {
    for name in NAMES {
        let _ = load_mesh_bytes(data, name);
    }
});
