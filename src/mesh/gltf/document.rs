//! The glTF container and its JSON: splitting a GLB into its chunks, parsing the document
//! (relaxing what common exporters get wrong), and validating it before any mesh is read.

use super::*;

/// GLB chunk types.
pub(super) const CHUNK_JSON: u32 = u32::from_le_bytes(*b"JSON");

pub(super) const CHUNK_BIN: u32 = u32::from_le_bytes(*b"BIN\0");

/// The JSON text and the BIN chunk, if any, of a GLB (`binary`) or a JSON glTF file.
pub(super) fn split<'a>(
    bytes: &'a [u8],
    origin: &Origin,
    binary: bool,
    warnings: &mut Vec<String>,
) -> Result<(&'a [u8], Option<&'a [u8]>), MeshError> {
    if binary {
        split_glb(bytes, origin, warnings)
    } else {
        Ok((bytes, None))
    }
}

pub(super) fn u32_at(bytes: &[u8], at: usize) -> Option<u32> {
    let word = bytes.get(at..at.checked_add(4)?)?;
    Some(u32::from_le_bytes(word.try_into().ok()?))
}

/// Splits a GLB container into its JSON chunk and its BIN chunk, checking every chunk length
/// against the bytes there are. Unknown chunks are skipped with a warning.
pub(super) fn split_glb<'a>(
    bytes: &'a [u8],
    origin: &Origin,
    warnings: &mut Vec<String>,
) -> Result<(&'a [u8], Option<&'a [u8]>), MeshError> {
    let body = glb_body(bytes, origin, warnings)?;
    let bad = |detail: String| origin.malformed("GLB", detail);
    let (mut json, mut bin) = (None, None);
    let mut pos = 12;
    while pos < body.len() {
        let (kind, data, next) = chunk_at(body, pos).ok_or_else(|| {
            bad(format!(
                "chunk at byte {pos}: truncated header, or length past the end"
            ))
        })?;
        let problem = match (kind, json.is_some()) {
            (CHUNK_JSON, false) => json.replace(data).map(|_| ""),
            (_, false) => Some("the first chunk is not JSON"),
            (CHUNK_JSON, true) => Some("a second JSON chunk"),
            (CHUNK_BIN, true) if bin.is_none() => bin.replace(data).map(|_| ""),
            (CHUNK_BIN, true) => Some("a second BIN chunk"),
            _ => {
                warnings.push(format!("unknown GLB chunk type {kind:#010x} skipped"));
                None
            }
        };
        if let Some(problem) = problem {
            return Err(bad(format!("{problem} at byte {pos}")));
        }
        pos = next;
    }
    let json = json.ok_or_else(|| bad("no JSON chunk".to_owned()))?;
    Ok((json, bin))
}

/// Checks the 12-byte GLB header (magic, version 2, total length) and returns the bytes it
/// declares; bytes after them are ignored with a warning.
pub(super) fn glb_body<'a>(
    bytes: &'a [u8],
    origin: &Origin,
    warnings: &mut Vec<String>,
) -> Result<&'a [u8], MeshError> {
    let bad = |detail: String| origin.malformed("GLB", detail);
    let (Some(magic), Some(version), Some(length)) =
        (u32_at(bytes, 0), u32_at(bytes, 4), u32_at(bytes, 8))
    else {
        let len = bytes.len();
        return Err(bad(format!("{len} bytes, shorter than the 12-byte header")));
    };
    if magic != u32::from_le_bytes(*b"glTF") {
        return Err(bad(format!("bad magic {:02x?}", magic.to_le_bytes())));
    }
    if version != 2 {
        return Err(origin.unsupported(format!("GLB container version {version}")));
    }
    let body = bytes.get(..length as usize).filter(|b| b.len() >= 12);
    let body = body.ok_or_else(|| {
        bad(format!(
            "header declares {length} bytes, the file has {}",
            bytes.len()
        ))
    })?;
    if body.len() < bytes.len() {
        let extra = bytes.len() - body.len();
        warnings.push(format!(
            "{extra} bytes after the end of the GLB were ignored"
        ));
    }
    Ok(body)
}

/// The type, data and end of the GLB chunk starting at `pos`, if it fits in `body`.
pub(super) fn chunk_at(body: &[u8], pos: usize) -> Option<(u32, &[u8], usize)> {
    let len = u32_at(body, pos)? as usize;
    let kind = u32_at(body, pos + 4)?;
    let start = pos + 8;
    let end = start.checked_add(len)?;
    Some((kind, body.get(start..end)?, end))
}

/// A glTF document checked as far as the loader needs.
pub(super) struct Parsed {
    pub(super) doc: Document,
    /// Accessors that failed validation: reading one is an error (nothing else uses them).
    pub(super) bad_accessors: HashSet<usize>,
}

/// Parses and validates the JSON of a glTF asset.
pub(super) fn parse_document(
    json_text: &[u8],
    origin: &Origin,
    warnings: &mut Vec<String>,
) -> Result<Parsed, MeshError> {
    let mut root =
        deserialize_root(json_text).map_err(|e| origin.malformed("glTF JSON", e.to_string()))?;
    accept_required_extensions(&mut root, origin, warnings)?;
    check_position_references(&root, origin)?;
    let bad_accessors = validate(&root, origin)?;
    Ok(Parsed {
        doc: Document::from_json_without_validation(root),
        bad_accessors,
    })
}

/// Deserializes the root object. gltf-json refuses some JSON that the glTF specification (and
/// its validator) allows; when the strict parse fails, the text is read again as plain JSON,
/// relaxed (see [`relax`]) and deserialized from that.
pub(super) fn deserialize_root(text: &[u8]) -> Result<json::Root, json::Error> {
    let first = match json::deserialize::from_slice::<json::Root>(text) {
        Ok(root) => return Ok(root),
        Err(e) => e,
    };
    let Ok(mut value) = json::deserialize::from_slice::<json::Value>(text) else {
        return Err(first);
    };
    if !relax(&mut value) {
        return Err(first);
    }
    json::deserialize::from_value(value).map_err(|_| first)
}

/// Rewrites what the specification allows but gltf-json's deserializer refuses, in ways that
/// change nothing the loader reads: integral floats where integers are expected (`1.0`, `1e0`)
/// become integers, `extras` that are not objects are dropped, scenes without `nodes` get an
/// empty list, and animations are dropped (never read here; gltf-json requires a channel
/// target's `node`, which `KHR_animation_pointer` leaves out). Whether anything changed.
pub(super) fn relax(root: &mut json::Value) -> bool {
    let mut changed = relax_values(root);
    if let json::Value::Object(top) = root {
        changed |= top.remove("animations").is_some();
        if let Some(json::Value::Array(scenes)) = top.get_mut("scenes") {
            for scene in scenes.iter_mut() {
                if let json::Value::Object(scene) = scene
                    && !scene.contains_key("nodes")
                {
                    scene.insert("nodes".to_owned(), json::Value::Array(Vec::new()));
                    changed = true;
                }
            }
        }
    }
    changed
}

/// Integral floats to integers and non-object `extras` out, recursively. (The recursion is
/// bounded by serde_json's nesting limit of 128 on the parse before.)
pub(super) fn relax_values(value: &mut json::Value) -> bool {
    match value {
        json::Value::Number(n) if n.is_f64() => {
            let f = n.as_f64().unwrap_or(f64::NAN);
            let integral = f.fract() == 0.0 && f.abs() < 9.0e15;
            if integral {
                *value = json::Value::from(f as i64);
            }
            integral
        }
        json::Value::Array(items) => items.iter_mut().fold(false, |any, v| relax_values(v) | any),
        json::Value::Object(map) => {
            let before = map.len();
            map.retain(|key, v| key != "extras" || v.is_object());
            let dropped = map.len() != before;
            map.values_mut()
                .fold(dropped, |any, v| relax_values(v) | any)
        }
        _ => false,
    }
}

/// Drops the required extensions the geometry can be loaded without (warning about those that
/// change appearance), so that validation passes; any other required extension is unsupported.
pub(super) fn accept_required_extensions(
    root: &mut json::Root,
    origin: &Origin,
    warnings: &mut Vec<String>,
) -> Result<(), MeshError> {
    let mut required = std::mem::take(&mut root.extensions_required);
    required.sort_unstable();
    required.dedup();
    for ext in required {
        if ext == "KHR_mesh_quantization" {
            continue;
        }
        if ext.starts_with("KHR_materials_") || APPEARANCE_EXTENSIONS.contains(&ext.as_str()) {
            warnings.push(format!(
                "required extension {ext} ignored: appearance may differ"
            ));
        } else {
            return Err(origin.unsupported(format!("required extension {ext}")));
        }
    }
    Ok(())
}

/// The gltf-json validation indexes `accessors` with each primitive's POSITION accessor without
/// a bounds check (it panics on an out-of-range one), so those indices are checked first.
pub(super) fn check_position_references(
    root: &json::Root,
    origin: &Origin,
) -> Result<(), MeshError> {
    let semantic = json::validation::Checked::Valid(json::mesh::Semantic::Positions);
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            if let Some(index) = primitive.attributes.get(&semantic) {
                let what = format!("mesh {m} primitive {p} POSITION");
                let (index, len) = (index.value() as u64, root.accessors.len() as u64);
                if index >= len {
                    return Err(origin.out_of_range(what, index, len));
                }
            }
        }
    }
    Ok(())
}

/// Runs the gltf-json validation, and judges each error with [`judge`]: an invalid accessor is
/// remembered (an error only if it is read), and any fatal error makes the file malformed.
pub(super) fn validate(root: &json::Root, origin: &Origin) -> Result<HashSet<usize>, MeshError> {
    use json::validation::Validate;
    let mut fatal = Vec::new();
    let mut bad_accessors = HashSet::new();
    let mut report = |path: &dyn Fn() -> json::Path, error: json::validation::Error| {
        let path = path();
        match judge(path.as_str(), error) {
            Verdict::Moot => {}
            Verdict::BadAccessor(i) => {
                bad_accessors.insert(i);
            }
            Verdict::Fatal => fatal.push(format!("{}: {error}", path.as_str())),
        }
    };
    root.validate(root, json::Path::new, &mut report);
    match fatal.first() {
        None => Ok(bad_accessors),
        Some(first) => {
            let detail = format!("{first} ({} validation errors)", fatal.len());
            Err(origin.malformed("glTF", detail))
        }
    }
}

/// What a validation error means to the loader.
pub(super) enum Verdict {
    /// Nothing: it concerns data the loader does not read.
    Moot,
    /// The accessor is unusable.
    BadAccessor(usize),
    /// The file cannot be loaded.
    Fatal,
}

/// Judges the validation error `error` at JSON path `path`. Moot: errors in properties the
/// loader never reads, missing or ill-formed `min`/`max` bounds (unused here), a missing POSITION
/// (that primitive is skipped), and an accessor without a buffer view (zeros, as the
/// specification says). Fatal: anything else outside accessors (a bad index in a node, a mesh or
/// a buffer view, say), since the gltf crate's accessors would panic on it.
pub(super) fn judge(path: &str, error: json::validation::Error) -> Verdict {
    use json::validation::Error;
    let bounds = path.ends_with(".min") || path.ends_with(".max");
    if let Some((i, field)) = path
        .strip_prefix("accessors[")
        .and_then(|r| r.split_once(']'))
    {
        let zeros = field == ".bufferView" && error == Error::Missing;
        return if bounds || zeros {
            Verdict::Moot
        } else {
            Verdict::BadAccessor(i.parse().unwrap_or(usize::MAX))
        };
    }
    let top = path.split(['.', '[']).next().unwrap_or(path);
    let position = path.contains(".attributes[\"POSITION\"]");
    if UNREAD_PROPERTIES.contains(&top) || (position && (bounds || error == Error::Missing)) {
        Verdict::Moot
    } else {
        Verdict::Fatal
    }
}
