//! CPU meshes and their loaders (glTF 2.0, OBJ with MTL, STL), with no GPU involved.
//!
//! A file loads as a [`Model`]: a list of [`MeshPart`]s, each a triangle mesh in its own
//! coordinates with the transform that places it in the file's frame (a glTF node hierarchy is
//! flattened into these transforms) and a material.

mod error;
mod gltf;
mod obj;
mod stl;

pub mod prosthesis;
pub mod write;

use std::io::Read;
use std::path::Path;

use glam::DMat4;

pub use error::MeshError;
use error::Origin;

/// The largest mesh file (or referenced buffer or material file) the loaders read: 2 GiB.
pub const MAX_FILE_BYTES: u64 = 2 << 30;

/// An indexed triangle mesh in single precision (model coordinates, millimetres by convention).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CpuMesh {
    /// Vertex positions.
    pub positions: Vec<[f32; 3]>,
    /// Unit vertex normals, one per position.
    pub normals: Vec<[f32; 3]>,
    /// Triangle list: three indices into `positions` per triangle.
    pub indices: Vec<u32>,
    /// Linear RGBA per position, multiplying the material's colour (a map of values painted
    /// on the surface); empty for none.
    pub colors: Vec<[f32; 4]>,
}

impl CpuMesh {
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Axis-aligned bounds `(min, max)` of the positions, or `None` for an empty mesh.
    pub fn bounds(&self) -> Option<([f32; 3], [f32; 3])> {
        let first = *self.positions.first()?;
        Some(self.positions.iter().fold((first, first), |(lo, hi), p| {
            (
                std::array::from_fn(|a| lo[a].min(p[a])),
                std::array::from_fn(|a| hi[a].max(p[a])),
            )
        }))
    }

    /// Replaces the normals with area-weighted vertex normals computed from the triangles;
    /// vertices on no triangle (or only degenerate ones) get +z.
    pub fn compute_normals(&mut self) {
        let mut sums = vec![[0f64; 3]; self.positions.len()];
        for t in self.indices.chunks_exact(3) {
            let [a, b, c] = [t[0], t[1], t[2]].map(|i| {
                let p = self.positions[i as usize];
                glam::DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))
            });
            let n = (b - a).cross(c - a);
            for &i in t {
                let s = &mut sums[i as usize];
                s[0] += n.x;
                s[1] += n.y;
                s[2] += n.z;
            }
        }
        self.normals = sums
            .into_iter()
            .map(|s| {
                let n = glam::DVec3::from(s)
                    .try_normalize()
                    .unwrap_or(glam::DVec3::Z);
                [n.x as f32, n.y as f32, n.z as f32]
            })
            .collect();
    }
}

/// Surface appearance of a mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// Linear RGBA base colour; an alpha below 1 draws the mesh translucent.
    pub base_color: [f32; 4],
    /// Perceptual roughness in 0..1 (0 is mirror-like).
    pub roughness: f32,
    /// Metalness in 0..1.
    pub metallic: f32,
}

impl Default for Material {
    fn default() -> Self {
        Self {
            base_color: [0.8, 0.8, 0.8, 1.0],
            roughness: 0.6,
            metallic: 0.0,
        }
    }
}

/// One mesh of a model, placed in the model's frame.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshPart {
    /// Name from the file (node or object name), or a generated one.
    pub name: String,
    /// Part coordinates to model-file coordinates.
    pub transform: DMat4,
    /// The triangles.
    pub mesh: CpuMesh,
    /// Its material.
    pub material: Material,
}

/// What one mesh file holds.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Model {
    /// The meshes.
    pub parts: Vec<MeshPart>,
    /// Things the loader worked around (a missing MTL file, say), for the user to see.
    pub warnings: Vec<String>,
}

/// A mesh file format, decided from the first bytes and then the extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Format {
    Glb,
    GltfJson,
    StlBinary,
    StlAscii,
    Obj,
}

/// Loads a mesh file: glTF 2.0 (`.gltf` with external or data-URI buffers, or `.glb`), OBJ with
/// its MTL material libraries, or binary or ASCII STL.
///
/// The format is sniffed from the first bytes (`glTF` magic, a JSON object, the binary STL length
/// rule, `solid`) and then taken from the extension. Files over [`MAX_FILE_BYTES`] are refused
/// before they are read. Problems the loader worked around are listed in [`Model::warnings`].
///
/// # Errors
///
/// A [`MeshError`] naming the file for anything that cannot be read or is malformed.
pub fn load_mesh(path: &Path) -> Result<Model, MeshError> {
    let origin = Origin::file(path);
    let bytes = read_file(path)?;
    load_with_origin(&bytes, path, &origin)
}

/// Loads a mesh held in memory. `name` gives the extension hint (`"prosthesis.glb"`) and names
/// the input in errors as `<embedded NAME>`. A `.gltf` held in memory may only use data URIs for
/// its buffers, and an OBJ's material libraries cannot be found (a warning, default materials).
///
/// # Errors
///
/// As [`load_mesh`].
pub fn load_mesh_bytes(bytes: &[u8], name: &str) -> Result<Model, MeshError> {
    let origin = Origin::embedded(name);
    check_size(bytes.len() as u64, &origin)?;
    load_with_origin(bytes, Path::new(name), &origin)
}

/// Reads accessor `index` of a glTF file (`.gltf` or `.glb`) as `f32` components, element after
/// element (normalized integers mapped to 0..1 or -1..1, sparse substitution applied). For
/// inspecting data that does not end up in a [`Model`], such as animation samplers.
///
/// # Errors
///
/// As [`load_mesh`], and [`MeshError::IndexOutOfRange`] when there is no such accessor.
pub fn read_gltf_accessor(path: &Path, index: usize) -> Result<Vec<f32>, MeshError> {
    let origin = Origin::file(path);
    let bytes = read_file(path)?;
    gltf::read_accessor(&bytes, &origin, index)
}

/// The largest coordinate a mesh file may hold, in its own units. Far past any planning scene
/// (a kilometre in millimetres), and where f32 positions still resolve well under a metre: a
/// triangle at 1e38 would be picked by the BVH's f64 rays while the depth buffer draws it
/// blank, so such a file is refused rather than drawn wrongly.
pub const MAX_COORDINATE: f32 = 1e9;

fn load_with_origin(bytes: &[u8], name: &Path, origin: &Origin) -> Result<Model, MeshError> {
    let model = load_format(bytes, name, origin)?;
    for part in &model.parts {
        let far = part
            .mesh
            .positions
            .iter()
            .flatten()
            .copied()
            .find(|c| c.abs() > MAX_COORDINATE);
        if let Some(value) = far {
            return Err(MeshError::FarCoordinate {
                file: origin.label.clone(),
                what: format!("part {:?}", part.name),
                value,
            });
        }
    }
    Ok(model)
}

fn load_format(bytes: &[u8], name: &Path, origin: &Origin) -> Result<Model, MeshError> {
    match sniff(bytes, name) {
        Some(Format::Glb) => gltf::load(bytes, origin, true),
        Some(Format::GltfJson) => gltf::load(bytes, origin, false),
        Some(Format::StlBinary | Format::StlAscii) => stl::load(bytes, origin),
        Some(Format::Obj) => obj::load(bytes, origin),
        None => Err(MeshError::UnknownFormat {
            file: origin.label.clone(),
            detail: format!(
                "{} bytes, no glTF, JSON or STL signature, and no .gltf/.glb/.obj/.stl extension",
                bytes.len()
            ),
        }),
    }
}

/// Decides the format from the first bytes, then from the extension of `name`.
fn sniff(bytes: &[u8], name: &Path) -> Option<Format> {
    if bytes.starts_with(b"glTF") {
        return Some(Format::Glb);
    }
    let text = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    if text.trim_ascii_start().starts_with(b"{") {
        return Some(Format::GltfJson);
    }
    if stl::is_binary(bytes) {
        return Some(Format::StlBinary);
    }
    if bytes.starts_with(b"solid") {
        return Some(Format::StlAscii);
    }
    let extension = name.extension()?.to_str()?.to_ascii_lowercase();
    match extension.as_str() {
        "glb" => Some(Format::Glb),
        "gltf" => Some(Format::GltfJson),
        "obj" => Some(Format::Obj),
        "stl" => Some(Format::StlBinary),
        _ => None,
    }
}

/// Whether files named inside a mesh file (glTF buffers and images, OBJ material libraries)
/// may lie outside that file's folder; off by default (see [`resolve_beside`]).
static OUTSIDE_PATHS: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Lets files named inside mesh files lie outside their folders (`--allow-outside-paths`).
pub fn allow_outside_paths(allow: bool) {
    OUTSIDE_PATHS.store(allow, std::sync::atomic::Ordering::Relaxed);
}

/// The file a path written inside a mesh file names, relative to that file's folder `dir`.
/// The policy: an absolute path, a drive or a URI scheme is refused; `.` and `..` are
/// followed, and a path that then leaves `dir` is refused unless [`allow_outside_paths`] said
/// otherwise. A percent-encoded URI must be decoded first, so that `%2F` and `%2E%2E` are
/// seen for what they are. Links inside the folder are followed by the reading itself.
pub(crate) fn resolve_beside(dir: &Path, relative: &str) -> Result<std::path::PathBuf, String> {
    use std::path::Component;
    let has_scheme = relative
        .split_once(':')
        .is_some_and(|(s, _)| !s.is_empty() && !s.contains(['/', '\\']));
    if has_scheme || relative.starts_with(['/', '\\']) || Path::new(relative).is_absolute() {
        return Err(format!(
            "{relative:?} is not a path relative to the file's folder"
        ));
    }
    let mut inside = Vec::new();
    let mut escapes = false;
    for part in Path::new(&relative.replace('\\', "/")).components() {
        match part {
            Component::Normal(name) => inside.push(name.to_owned()),
            Component::CurDir => {}
            Component::ParentDir => escapes |= inside.pop().is_none(),
            Component::RootDir | Component::Prefix(_) => {
                return Err(format!("{relative:?} is not a relative path"));
            }
        }
    }
    if escapes && !OUTSIDE_PATHS.load(std::sync::atomic::Ordering::Relaxed) {
        return Err(format!(
            "{relative:?} leads outside the file's folder (allowed with --allow-outside-paths)"
        ));
    }
    if escapes {
        return Ok(dir.join(relative));
    }
    Ok(inside
        .iter()
        .fold(dir.to_path_buf(), |path, name| path.join(name)))
}

fn check_size(len: u64, origin: &Origin) -> Result<(), MeshError> {
    if len > MAX_FILE_BYTES {
        return Err(origin.too_large("the file", len, MAX_FILE_BYTES));
    }
    Ok(())
}

/// Reads a whole file, refusing one over [`MAX_FILE_BYTES`] before reading it; errors name `path`.
fn read_file(path: &Path) -> Result<Vec<u8>, MeshError> {
    let io = |source| MeshError::Io {
        file: path.to_path_buf(),
        source,
    };
    let file = crate::input::open_regular(path).map_err(io)?;
    let len = file.metadata().map_err(io)?.len();
    let origin = Origin::file(path);
    check_size(len, &origin)?;
    // `len` is at most MAX_FILE_BYTES, which fits in usize on the 64-bit targets this runs on;
    // the `take` stops a file that grows meanwhile one byte past the limit.
    let mut bytes = Vec::with_capacity(usize::try_from(len).unwrap_or(0));
    file.take(MAX_FILE_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(io)?;
    check_size(bytes.len() as u64, &origin)?;
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sniffs_by_content_then_extension() {
        let p = Path::new;
        assert_eq!(sniff(b"glTF\x02\0\0\0", p("x.bin")), Some(Format::Glb));
        assert_eq!(sniff(b"  {\"asset\":{}}", p("x")), Some(Format::GltfJson));
        assert_eq!(sniff(b"solid cube\n", p("x")), Some(Format::StlAscii));
        assert_eq!(sniff(b"v 0 0 0\n", p("a.OBJ")), Some(Format::Obj));
        assert_eq!(sniff(b"", p("a.glb")), Some(Format::Glb));
        assert_eq!(sniff(b"hello", p("a.txt")), None);
        let mut stl = vec![0u8; 84 + 50];
        stl[..5].copy_from_slice(b"solid");
        stl[80] = 1;
        assert_eq!(sniff(&stl, p("x")), Some(Format::StlBinary));
    }

    #[test]
    fn unknown_format_names_the_input() {
        let err = load_mesh_bytes(b"hello", "notes.txt").unwrap_err();
        assert!(matches!(err, MeshError::UnknownFormat { .. }), "{err}");
        assert_eq!(err.file(), Path::new("<embedded notes.txt>"));
    }

    #[test]
    fn missing_file_is_an_io_error() {
        let err = load_mesh(Path::new("/nonexistent/dir/x.stl")).unwrap_err();
        assert!(matches!(err, MeshError::Io { .. }), "{err}");
    }
}
