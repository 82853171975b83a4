//! glTF 2.0: `.gltf` JSON (buffers in data URIs or in files next to it) and `.glb`.
//!
//! The gltf crate parses and checks the JSON; everything that touches bytes is done here, so that
//! no declared offset, length or count is trusted before it is checked against the bytes that
//! hold it:
//! - the GLB container is split here (magic, version, total length, chunk lengths);
//! - buffers are resolved here (the GLB BIN chunk, base64 data URIs, relative files), lazily, only
//!   those that a mesh of the scene reads, each checked against its declared `byteLength`;
//! - accessors are decoded here rather than with the gltf crate's `Reader`, which can panic or
//!   misread on malformed input (it reads any component type as `f32` for positions, unwraps
//!   sparse values, and underflows on a zero count): every element range is checked against its
//!   buffer view and every view against its buffer before anything is allocated or read.
//!
//! All component types are read (so KHR_mesh_quantization files load), normalized integers are
//! mapped to 0..1 or -1..1, and sparse substitution is applied. Only triangle primitives become
//! parts (strips and fans are converted to lists); points and lines are skipped with a warning.

use std::borrow::Cow;
use std::collections::hash_map::Entry;
use std::collections::{HashMap, HashSet};

use ::gltf::accessor::sparse::{IndexType, Sparse};
use ::gltf::accessor::{DataType, Dimensions};
use ::gltf::buffer::{Source, View};
use ::gltf::json;
use ::gltf::mesh::{Mode, Semantic};
use ::gltf::scene::Transform;
use ::gltf::{Accessor, Document, Node, Primitive};
use base64::Engine as _;
use base64::engine::{DecodePaddingMode, GeneralPurpose, GeneralPurposeConfig};
use glam::{DMat4, DQuat, DVec3};

use super::{CpuMesh, MAX_FILE_BYTES, Material, MeshError, MeshPart, Model, Origin};

mod document;

use document::*;

/// Deepest node nesting walked; a deeper hierarchy is an error.
const MAX_DEPTH: usize = 64;
/// Most elements of an accessor with no buffer view (all zeros but for sparse values): nothing in
/// the file backs its count, so it is bounded here.
const MAX_UNBACKED_ELEMENTS: usize = 1 << 20;
/// Most bytes of mesh data in one model; nodes may instance a mesh many times over.
const MAX_OUTPUT_BYTES: u64 = MAX_FILE_BYTES;
/// Required extensions that change only appearance, besides every `KHR_materials_*`; the
/// geometry loads without them (with a warning). `KHR_mesh_quantization` is fully supported.
const APPEARANCE_EXTENSIONS: &[&str] = &[
    "KHR_texture_transform",
    "KHR_texture_basisu",
    "EXT_texture_webp",
    "EXT_texture_avif",
    "MSFT_texture_dds",
    "KHR_lights_punctual",
    "KHR_node_visibility",
    "KHR_animation_pointer",
];
/// Top-level glTF properties that the loader never reads, so their validation errors are moot.
const UNREAD_PROPERTIES: &[&str] = &[
    "animations",
    "asset",
    "cameras",
    "extensions",
    "extensionsUsed",
    "extras",
    "images",
    "materials",
    "samplers",
    "skins",
    "textures",
];
/// Base64 as written by glTF exporters, with or without padding.
const BASE64: GeneralPurpose = GeneralPurpose::new(
    &base64::alphabet::STANDARD,
    GeneralPurposeConfig::new()
        .with_decode_padding_mode(DecodePaddingMode::Indifferent)
        .with_decode_allow_trailing_bits(true),
);

/// Loads a glTF file held in `bytes`: a GLB container if `binary`, else JSON.
pub(super) fn load(bytes: &[u8], origin: &Origin, binary: bool) -> Result<Model, MeshError> {
    let mut warnings = Vec::new();
    let (json, bin) = split(bytes, origin, binary, &mut warnings)?;
    let parsed = parse_document(json, origin, &mut warnings)?;
    let mut loader = Loader::new(&parsed, origin, bin, binary, warnings);
    let instances = loader.instances()?;
    let parts = loader.parts(&instances)?;
    Ok(Model {
        parts,
        warnings: loader.warnings,
    })
}

/// Reads accessor `index` of the glTF held in `bytes` as `f32` components.
pub(super) fn read_accessor(
    bytes: &[u8],
    origin: &Origin,
    index: usize,
) -> Result<Vec<f32>, MeshError> {
    let mut warnings = Vec::new();
    let binary = bytes.starts_with(b"glTF");
    let (json, bin) = split(bytes, origin, binary, &mut warnings)?;
    let parsed = parse_document(json, origin, &mut warnings)?;
    let mut loader = Loader::new(&parsed, origin, bin, binary, warnings);
    let count = parsed.doc.accessors().len();
    let accessor = parsed.doc.accessors().nth(index);
    let accessor =
        accessor.ok_or_else(|| origin.out_of_range("accessors", index as u64, count as u64))?;
    loader.read_accessor(&accessor, true, |v| v as f32)
}

/// Byte layout of an accessor element.
#[derive(Debug, Clone, Copy)]
struct Layout {
    data_type: DataType,
    dims: Dimensions,
    normalized: bool,
}

impl Layout {
    /// The layout of `accessor`; `normalized` is honoured only when `honour_normalized`.
    fn of(accessor: &Accessor<'_>, honour_normalized: bool) -> Self {
        Self {
            data_type: accessor.data_type(),
            dims: accessor.dimensions(),
            normalized: honour_normalized && accessor.normalized(),
        }
    }

    fn components(self) -> usize {
        self.dims.multiplicity()
    }

    /// Rows and columns: matrices are stored column by column.
    fn shape(self) -> (usize, usize) {
        match self.dims {
            Dimensions::Mat2 => (2, 2),
            Dimensions::Mat3 => (3, 3),
            Dimensions::Mat4 => (4, 4),
            _ => (self.components(), 1),
        }
    }

    /// Bytes from one matrix column to the next: columns of 1- and 2-byte components are
    /// padded to a multiple of 4 bytes.
    fn column_stride(self) -> usize {
        let (rows, cols) = self.shape();
        let bytes = rows * self.data_type.size();
        if cols > 1 {
            bytes.next_multiple_of(4)
        } else {
            bytes
        }
    }

    fn element_size(self) -> usize {
        self.shape().1 * self.column_stride()
    }

    /// Decodes one element into `out` (one slot a component); `None` if `element` is short.
    fn decode<T>(self, element: &[u8], out: &mut [T], convert: fn(f64) -> T) -> Option<()> {
        let (rows, _) = self.shape();
        let size = self.data_type.size();
        for (k, slot) in out.iter_mut().enumerate() {
            let at = (k / rows) * self.column_stride() + (k % rows) * size;
            *slot = convert(component(element, at, self.data_type, self.normalized)?);
        }
        Some(())
    }
}

/// One little-endian component at byte `at`, normalized to 0..1 or -1..1 if asked.
fn component(bytes: &[u8], at: usize, data_type: DataType, normalized: bool) -> Option<f64> {
    fn take<const N: usize>(bytes: &[u8], at: usize) -> Option<[u8; N]> {
        bytes.get(at..at.checked_add(N)?)?.try_into().ok()
    }
    let (raw, scale) = match data_type {
        DataType::I8 => (f64::from(i8::from_le_bytes(take(bytes, at)?)), 127.0),
        DataType::U8 => (f64::from(u8::from_le_bytes(take(bytes, at)?)), 255.0),
        DataType::I16 => (f64::from(i16::from_le_bytes(take(bytes, at)?)), 32767.0),
        DataType::U16 => (f64::from(u16::from_le_bytes(take(bytes, at)?)), 65535.0),
        DataType::U32 => (
            f64::from(u32::from_le_bytes(take(bytes, at)?)),
            4_294_967_295.0,
        ),
        DataType::F32 => (f64::from(f32::from_le_bytes(take(bytes, at)?)), 1.0),
    };
    Some(if normalized {
        (raw / scale).max(-1.0)
    } else {
        raw
    })
}

/// The end of `count` elements of `elem` bytes, `stride` apart, from `offset`, or `u64::MAX`
/// if it overflows.
fn extent(offset: usize, stride: usize, count: usize, elem: usize) -> u64 {
    let Some(last) = count.checked_sub(1) else {
        return offset as u64;
    };
    last.checked_mul(stride)
        .and_then(|s| s.checked_add(offset))
        .and_then(|s| s.checked_add(elem))
        .map_or(u64::MAX, |end| end as u64)
}

/// Buffer bytes, resolved on first use.
struct Buffers<'a> {
    origin: &'a Origin,
    /// Whether the file is a GLB (where a buffer without a uri is the BIN chunk).
    glb: bool,
    bin: Option<&'a [u8]>,
    data: Vec<Option<Cow<'a, [u8]>>>,
}

impl<'a> Buffers<'a> {
    /// Resolves `buffer` unless it is already.
    fn load(&mut self, buffer: &::gltf::Buffer<'_>) -> Result<(), MeshError> {
        let i = buffer.index();
        if matches!(self.data.get(i), Some(Some(_))) {
            return Ok(());
        }
        let data = self.resolve(buffer)?;
        if let Some(slot) = self.data.get_mut(i) {
            *slot = Some(data);
        }
        Ok(())
    }

    /// The bytes of a buffer resolved before.
    fn get(&self, index: usize) -> Result<&[u8], MeshError> {
        match self.data.get(index) {
            Some(Some(data)) => Ok(data),
            _ => Err(self
                .origin
                .malformed("glTF", format!("buffer {index} was not resolved"))),
        }
    }

    /// Fetches a buffer's bytes and checks them against its declared `byteLength`; a GLB BIN
    /// chunk may be padded beyond it, and only the declared bytes are kept.
    fn resolve(&self, buffer: &::gltf::Buffer<'_>) -> Result<Cow<'a, [u8]>, MeshError> {
        let i = buffer.index();
        let what = format!("buffer {i}");
        let declared = buffer.length();
        if declared as u64 > MAX_FILE_BYTES {
            return Err(self.origin.too_large(what, declared as u64, MAX_FILE_BYTES));
        }
        let data = match buffer.source() {
            Source::Bin if i == 0 => Cow::Borrowed(self.bin.ok_or_else(|| {
                self.origin
                    .malformed("glTF", "buffer 0 has no uri and there is no BIN chunk")
            })?),
            Source::Bin => {
                let detail = format!("{what} has no uri (only buffer 0 can be the BIN chunk)");
                return Err(self.origin.malformed("glTF", detail));
            }
            Source::Uri(uri) => Cow::Owned(self.fetch(uri, &what)?),
        };
        if data.len() < declared {
            return Err(self
                .origin
                .too_short(what, declared as u64, data.len() as u64));
        }
        Ok(match data {
            Cow::Borrowed(b) => Cow::Borrowed(b.get(..declared).unwrap_or(b)),
            Cow::Owned(mut v) => {
                v.truncate(declared);
                Cow::Owned(v)
            }
        })
    }

    /// The bytes a buffer URI refers to: a base64 data URI, or a file relative to the glTF's.
    fn fetch(&self, uri: &str, what: &str) -> Result<Vec<u8>, MeshError> {
        if let Some(rest) = uri.strip_prefix("data:") {
            return decode_data_uri(rest, what, self.origin);
        }
        let Some(dir) = &self.origin.dir else {
            let detail =
                format!("{what}: URI {uri:?} names a file; in-memory glTF may only use data URIs");
            return Err(self.origin.unsupported(detail));
        };
        // Decoded before any check, so that an encoded `/` or `..` is seen for what it is.
        let relative = percent_decode(uri).ok_or_else(|| {
            self.origin.malformed(
                "glTF",
                format!("{what}: bad percent-encoding in URI {uri:?}"),
            )
        })?;
        let path = super::resolve_beside(dir, &relative).map_err(|why| {
            self.origin
                .unsupported(format!("{what}: URI {uri:?} decodes to {why}"))
        })?;
        super::read_file(&path)
    }
}

/// Decodes the part of a data URI after `data:`; only base64 is supported.
fn decode_data_uri(rest: &str, what: &str, origin: &Origin) -> Result<Vec<u8>, MeshError> {
    let Some((header, payload)) = rest.split_once(',') else {
        return Err(origin.malformed("glTF", format!("{what}: data URI without a comma")));
    };
    if !header.ends_with(";base64") {
        return Err(origin.unsupported(format!("{what}: data URI that is not base64")));
    }
    BASE64
        .decode(payload.trim())
        .map_err(|e| origin.malformed("glTF", format!("{what}: data URI: {e}")))
}

/// Decodes `%XX` escapes; `None` for a bad escape or a result that is not UTF-8.
fn percent_decode(uri: &str) -> Option<String> {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while let Some(&b) = bytes.get(i) {
        if b == b'%' {
            let hex = bytes
                .get(i + 1..i + 3)
                .filter(|h| h.iter().all(u8::is_ascii_hexdigit))?;
            out.push(u8::from_str_radix(std::str::from_utf8(hex).ok()?, 16).ok()?);
            i += 3;
        } else {
            out.push(b);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

/// A mesh placed by a node.
struct Instance<'a> {
    node: Node<'a>,
    mesh: ::gltf::Mesh<'a>,
    /// Node to file coordinates.
    transform: DMat4,
}

/// The decoded triangles and material of one primitive, or `None` if it has no triangles.
type Built = Option<(CpuMesh, Material)>;

/// Turns a parsed document into parts.
struct Loader<'a> {
    doc: &'a Document,
    origin: &'a Origin,
    bad_accessors: &'a HashSet<usize>,
    buffers: Buffers<'a>,
    warnings: Vec<String>,
}

impl<'a> Loader<'a> {
    fn new(
        parsed: &'a Parsed,
        origin: &'a Origin,
        bin: Option<&'a [u8]>,
        glb: bool,
        warnings: Vec<String>,
    ) -> Self {
        let buffers = Buffers {
            origin,
            glb,
            bin,
            data: vec![None; parsed.doc.buffers().len()],
        };
        Self {
            doc: &parsed.doc,
            origin,
            bad_accessors: &parsed.bad_accessors,
            buffers,
            warnings,
        }
    }

    /// Every mesh the scene places, with its node-to-file transform. The scene is the default
    /// one, else the first; with no scene at all, every root node (a node nobody's child) is
    /// walked, and a node left unreached then lies on a cycle.
    fn instances(&self) -> Result<Vec<Instance<'a>>, MeshError> {
        let node_count = self.doc.nodes().len();
        let mut visited = vec![false; node_count];
        let mut out = Vec::new();
        if let Some(scene) = self
            .doc
            .default_scene()
            .or_else(|| self.doc.scenes().next())
        {
            for node in scene.nodes() {
                self.walk(node, DMat4::IDENTITY, 1, &mut visited, &mut out)?;
            }
            return Ok(out);
        }
        let mut has_parent = vec![false; node_count];
        for child in self.doc.nodes().flat_map(|n| n.children()) {
            if let Some(flag) = has_parent.get_mut(child.index()) {
                *flag = true;
            }
        }
        let roots = self
            .doc
            .nodes()
            .filter(|n| has_parent.get(n.index()) == Some(&false));
        for node in roots {
            self.walk(node, DMat4::IDENTITY, 1, &mut visited, &mut out)?;
        }
        match visited.iter().position(|seen| !seen) {
            Some(node) => Err(MeshError::NodeCycle {
                file: self.origin.label.clone(),
                node,
            }),
            None => Ok(out),
        }
    }

    /// Walks the subtree of `node` at `depth` (1 for a root) under the `parent` transform.
    fn walk(
        &self,
        node: Node<'a>,
        parent: DMat4,
        depth: usize,
        visited: &mut [bool],
        out: &mut Vec<Instance<'a>>,
    ) -> Result<(), MeshError> {
        let index = node.index();
        self.enter(index, depth, visited)?;
        let transform = parent * local_transform(&node);
        if !transform.is_finite() {
            let what = format!("the transform of node {index}");
            return Err(self.origin.non_finite(what));
        }
        if let Some(mesh) = node.mesh() {
            let node = node.clone();
            out.push(Instance {
                node,
                mesh,
                transform,
            });
        }
        for child in node.children() {
            self.walk(child, transform, depth + 1, visited, out)?;
        }
        Ok(())
    }

    /// Marks node `index` visited at `depth`; an error if it was visited before (a cycle, or a
    /// node with two parents) or lies too deep.
    fn enter(&self, index: usize, depth: usize, visited: &mut [bool]) -> Result<(), MeshError> {
        let file = self.origin.label.clone();
        if depth > MAX_DEPTH {
            let limit = MAX_DEPTH;
            return Err(MeshError::NodeTooDeep {
                file,
                node: index,
                limit,
            });
        }
        match visited.get_mut(index) {
            Some(seen) if !*seen => {
                *seen = true;
                Ok(())
            }
            _ => Err(MeshError::NodeCycle { file, node: index }),
        }
    }

    /// One part per triangle primitive per instance. A primitive is decoded once however many
    /// nodes place it, and the total output is bounded.
    fn parts(&mut self, instances: &[Instance<'a>]) -> Result<Vec<MeshPart>, MeshError> {
        let mut built: HashMap<(usize, usize), Built> = HashMap::new();
        let mut parts = Vec::new();
        let mut total_bytes = 0u64;
        for instance in instances {
            self.warn_about_deformation(instance);
            let primitive_count = instance.mesh.primitives().len();
            for primitive in instance.mesh.primitives() {
                let key = (instance.mesh.index(), primitive.index());
                let decoded = match built.entry(key) {
                    Entry::Occupied(known) => known.into_mut(),
                    Entry::Vacant(slot) => slot.insert(self.primitive(&primitive, key)?),
                };
                let Some((mesh, material)) = decoded else {
                    continue;
                };
                total_bytes += (mesh.positions.len() * 24 + mesh.indices.len() * 4) as u64;
                if total_bytes > MAX_OUTPUT_BYTES {
                    let what = "the meshes placed by all nodes together";
                    return Err(self.origin.too_large(what, total_bytes, MAX_OUTPUT_BYTES));
                }
                parts.push(MeshPart {
                    name: part_name(instance, &primitive, primitive_count),
                    transform: instance.transform,
                    mesh: mesh.clone(),
                    material: *material,
                });
            }
        }
        Ok(parts)
    }

    /// Skins and morph targets are not applied: say so when they would change the shape.
    fn warn_about_deformation(&mut self, instance: &Instance<'a>) {
        let index = instance.node.index();
        let weights = instance.node.weights().or_else(|| instance.mesh.weights());
        if weights.is_some_and(|w| w.iter().any(|&x| x != 0.0)) {
            self.warnings
                .push(format!("node {index}: morph target weights not applied"));
        }
        let json = self.doc.as_json().nodes.get(index);
        if json.is_some_and(|n| n.skin.is_some()) {
            self.warnings
                .push(format!("node {index}: skin not applied (drawn unskinned)"));
        }
    }

    /// Decodes one primitive: positions, triangle indices, normals and material.
    fn primitive(
        &mut self,
        primitive: &Primitive<'a>,
        key: (usize, usize),
    ) -> Result<Built, MeshError> {
        let label = format!("mesh {} primitive {}", key.0, key.1);
        let position = match self.skip_reason(primitive) {
            Ok(position) => position,
            Err(reason) => {
                self.warnings.push(format!("{label}: skipped: {reason}"));
                return Ok(None);
            }
        };
        let positions = self.read_vec3(&position, &format!("{label} POSITION"))?;
        if positions.iter().flatten().any(|c| !c.is_finite()) {
            return Err(self.origin.non_finite(format!("{label} POSITION")));
        }
        let vertex_indices = match primitive.indices() {
            Some(accessor) => self.read_indices(&accessor, positions.len(), &label)?,
            None => (0..u32::try_from(positions.len()).unwrap_or(u32::MAX)).collect(),
        };
        let (indices, leftover) = triangle_list(primitive.mode(), vertex_indices);
        if leftover {
            let warning = format!("{label}: trailing indices that make no triangle dropped");
            self.warnings.push(warning);
        }
        if indices.is_empty() {
            self.warnings
                .push(format!("{label}: skipped: no triangles"));
            return Ok(None);
        }
        let normals = Vec::new();
        let mut mesh = CpuMesh {
            colors: Vec::new(),
            positions,
            normals,
            indices,
        };
        self.attach_normals(primitive, &mut mesh, &label)?;
        Ok(Some((mesh, material_of(primitive))))
    }

    /// The POSITION accessor of a primitive to be loaded, or why the primitive is skipped.
    fn skip_reason(&self, primitive: &Primitive<'a>) -> Result<Accessor<'a>, String> {
        let mode = primitive.mode();
        if !matches!(
            mode,
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            return Err(format!("{mode:?} (only triangles are loaded)"));
        }
        let position = primitive.get(&Semantic::Positions);
        let position = position.ok_or_else(|| "no POSITION attribute".to_owned())?;
        if let Some(buffer) = self.unsupplied_buffer(primitive) {
            return Err(format!(
                "its data lies in buffer {buffer}, which has no uri (only a GLB can supply one)"
            ));
        }
        Ok(position)
    }

    /// A buffer that the primitive reads and that a `.gltf` (not GLB) file declares without a
    /// `uri`. The specification reserves a missing uri for the GLB BIN chunk, so in a `.gltf`
    /// the buffer's bytes are not part of the file (the glTF validator accepts such files): the
    /// primitive is skipped with a warning rather than failing the whole file.
    fn unsupplied_buffer(&self, primitive: &Primitive<'a>) -> Option<usize> {
        if self.buffers.glb {
            return None;
        }
        let attributes = [Semantic::Positions, Semantic::Normals].map(|s| primitive.get(&s));
        let accessors = attributes
            .into_iter()
            .chain([primitive.indices()])
            .flatten();
        let usable = accessors.filter(|a| !self.bad_accessors.contains(&a.index()));
        let views = usable.flat_map(|a| {
            let sparse = a.sparse().into_iter();
            let sparse_views = sparse.flat_map(|s| [s.indices().view(), s.values().view()]);
            a.view().into_iter().chain(sparse_views)
        });
        let mut buffers = views.map(|v| v.buffer());
        buffers
            .find(|b| matches!(b.source(), Source::Bin))
            .map(|b| b.index())
    }

    /// Uses the primitive's normals when it has usable ones, else computes them.
    fn attach_normals(
        &mut self,
        primitive: &Primitive<'a>,
        mesh: &mut CpuMesh,
        label: &str,
    ) -> Result<(), MeshError> {
        let Some(accessor) = primitive.get(&Semantic::Normals) else {
            mesh.compute_normals();
            return Ok(());
        };
        let normals = self.read_vec3(&accessor, &format!("{label} NORMAL"))?;
        let finite = normals.iter().flatten().all(|c| c.is_finite());
        if normals.len() != mesh.positions.len() || !finite {
            let problem = if finite {
                "count differs from POSITION"
            } else {
                "non-finite values"
            };
            self.warnings.push(format!(
                "{label}: NORMAL unusable ({problem}), computed instead"
            ));
            mesh.compute_normals();
            return Ok(());
        }
        mesh.normals = normals.into_iter().map(unit_vector).collect();
        Ok(())
    }

    /// Fails for an accessor that did not pass validation (its wrapper methods would panic).
    fn check_valid(&self, accessor: &Accessor<'_>, what: &str) -> Result<(), MeshError> {
        if self.bad_accessors.contains(&accessor.index()) {
            let detail = format!("{what}: accessor {} is invalid", accessor.index());
            return Err(self.origin.malformed("glTF", detail));
        }
        Ok(())
    }

    fn read_vec3(
        &mut self,
        accessor: &Accessor<'a>,
        what: &str,
    ) -> Result<Vec<[f32; 3]>, MeshError> {
        self.check_valid(accessor, what)?;
        if accessor.dimensions() != Dimensions::Vec3 {
            let detail = format!("{what}: accessor {} is not VEC3", accessor.index());
            return Err(self.origin.malformed("glTF", detail));
        }
        let flat = self.read_accessor(accessor, true, |v| v as f32)?;
        Ok(flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
    }

    /// Reads vertex indices and checks each against the vertex count.
    fn read_indices(
        &mut self,
        accessor: &Accessor<'a>,
        vertex_count: usize,
        label: &str,
    ) -> Result<Vec<u32>, MeshError> {
        let what = format!("{label} indices");
        self.check_valid(accessor, &what)?;
        let unsigned = matches!(
            accessor.data_type(),
            DataType::U8 | DataType::U16 | DataType::U32
        );
        if accessor.dimensions() != Dimensions::Scalar || !unsigned {
            let detail = format!(
                "{what}: accessor {} is not unsigned scalars",
                accessor.index()
            );
            return Err(self.origin.malformed("glTF", detail));
        }
        let indices = self.read_accessor(accessor, false, |v| v as u32)?;
        if let Some(&bad) = indices.iter().find(|&&i| i as usize >= vertex_count) {
            return Err(self
                .origin
                .out_of_range(what, u64::from(bad), vertex_count as u64));
        }
        Ok(indices)
    }

    /// Reads an accessor, element after element, one `T` a component (`convert` maps the
    /// component value, normalized if the accessor says so and `honour_normalized`), with
    /// sparse substitution applied. Every range is checked before anything is allocated.
    fn read_accessor<T: Copy>(
        &mut self,
        accessor: &Accessor<'a>,
        honour_normalized: bool,
        convert: fn(f64) -> T,
    ) -> Result<Vec<T>, MeshError> {
        let what = format!("accessor {}", accessor.index());
        self.check_valid(accessor, &what)?;
        let sparse = accessor.sparse();
        let views = accessor.view().into_iter().chain(
            sparse
                .iter()
                .flat_map(|s| [s.indices().view(), s.values().view()]),
        );
        for view in views {
            self.buffers.load(&view.buffer())?;
        }
        let layout = Layout::of(accessor, honour_normalized);
        let count = accessor.count();
        let mut out = match accessor.view() {
            Some(view) => {
                self.read_dense(&view, accessor.offset(), count, layout, &what, convert)?
            }
            None if count <= MAX_UNBACKED_ELEMENTS => {
                vec![convert(0.0); count * layout.components()]
            }
            None => {
                let bytes = count as u64 * layout.element_size() as u64;
                let limit = (MAX_UNBACKED_ELEMENTS * layout.element_size()) as u64;
                return Err(self.origin.too_large(
                    format!("{what} without a buffer view"),
                    bytes,
                    limit,
                ));
            }
        };
        if let Some(sparse) = sparse {
            self.apply_sparse(&sparse, count, layout, &what, &mut out, convert)?;
        }
        Ok(out)
    }

    /// The bytes of a buffer view, checked to lie within its (resolved) buffer.
    fn view_bytes(&self, view: &View<'_>, what: &str) -> Result<&[u8], MeshError> {
        let data = self.buffers.get(view.buffer().index())?;
        let range = view.offset()..view.offset().saturating_add(view.length());
        data.get(range.clone()).ok_or_else(|| {
            let what = format!("{what}: buffer view {}", view.index());
            self.origin
                .too_short(what, range.end as u64, data.len() as u64)
        })
    }

    /// Checks that `count` elements of `elem` bytes, `stride` apart from `offset`, fit in `len`.
    fn check_extent(
        &self,
        what: &str,
        (offset, stride): (usize, usize),
        count: usize,
        elem: usize,
        len: usize,
    ) -> Result<(), MeshError> {
        let end = extent(offset, stride, count, elem);
        if end > len as u64 {
            return Err(self.origin.too_short(what, end, len as u64));
        }
        Ok(())
    }

    fn read_dense<T: Copy>(
        &self,
        view: &View<'_>,
        offset: usize,
        count: usize,
        layout: Layout,
        what: &str,
        convert: fn(f64) -> T,
    ) -> Result<Vec<T>, MeshError> {
        let bytes = self.view_bytes(view, what)?;
        let elem = layout.element_size();
        let stride = view.stride().unwrap_or(elem);
        if stride < elem {
            let detail =
                format!("{what}: byte stride {stride} is less than the {elem}-byte element");
            return Err(self.origin.malformed("glTF", detail));
        }
        self.check_extent(what, (offset, stride), count, elem, bytes.len())?;
        let n = layout.components();
        let mut out = vec![convert(0.0); count * n];
        for (i, slot) in out.chunks_exact_mut(n).enumerate() {
            let start = offset + i * stride;
            bytes
                .get(start..start + elem)
                .and_then(|element| layout.decode(element, slot, convert))
                .ok_or_else(|| {
                    self.origin
                        .too_short(what, (start + elem) as u64, bytes.len() as u64)
                })?;
        }
        Ok(out)
    }

    /// Substitutes the sparse values into `out` (`count` elements of `layout`).
    fn apply_sparse<T: Copy>(
        &self,
        sparse: &Sparse<'_>,
        count: usize,
        layout: Layout,
        what: &str,
        out: &mut [T],
        convert: fn(f64) -> T,
    ) -> Result<(), MeshError> {
        let targets = self.sparse_targets(sparse, count, what)?;
        let values = sparse.values();
        let elem = layout.element_size();
        let bytes = self.view_bytes(&values.view(), what)?;
        let values_what = format!("{what} sparse values");
        let n = targets.len();
        self.check_extent(&values_what, (values.offset(), elem), n, elem, bytes.len())?;
        let comps = layout.components();
        for (s, target) in targets.into_iter().enumerate() {
            let start = values.offset() + s * elem;
            let slot = out.get_mut(target * comps..(target + 1) * comps);
            slot.zip(bytes.get(start..start + elem))
                .and_then(|(slot, element)| layout.decode(element, slot, convert))
                .ok_or_else(|| {
                    self.origin
                        .too_short(&values_what, (start + elem) as u64, bytes.len() as u64)
                })?;
        }
        Ok(())
    }

    /// The element indices a sparse block substitutes, each checked to be below `count`.
    fn sparse_targets(
        &self,
        sparse: &Sparse<'_>,
        count: usize,
        what: &str,
    ) -> Result<Vec<usize>, MeshError> {
        let n = sparse.count();
        if n > count {
            let detail = format!("{what}: {n} sparse values for {count} elements");
            return Err(self.origin.malformed("glTF", detail));
        }
        let indices = sparse.indices();
        let index_type = match indices.index_type() {
            IndexType::U8 => DataType::U8,
            IndexType::U16 => DataType::U16,
            IndexType::U32 => DataType::U32,
        };
        let size = index_type.size();
        let bytes = self.view_bytes(&indices.view(), what)?;
        let what = format!("{what} sparse indices");
        self.check_extent(&what, (indices.offset(), size), n, size, bytes.len())?;
        (0..n)
            .map(|s| {
                let at = indices.offset() + s * size;
                let end = (at + size) as u64;
                let target = component(bytes, at, index_type, false);
                let target =
                    target.ok_or_else(|| self.origin.too_short(&what, end, bytes.len() as u64))?;
                if target >= count as f64 {
                    return Err(self.origin.out_of_range(&what, target as u64, count as u64));
                }
                Ok(target as usize)
            })
            .collect()
    }
}

/// A node's local transform in double precision; a rotation is normalized first.
fn local_transform(node: &Node<'_>) -> DMat4 {
    match node.transform() {
        Transform::Matrix { matrix } => {
            DMat4::from_cols_array_2d(&matrix.map(|c| c.map(f64::from)))
        }
        Transform::Decomposed {
            translation,
            rotation,
            scale,
        } => {
            let q = DQuat::from_array(rotation.map(f64::from));
            let len = q.length();
            let q = if len.is_finite() && len > 0.0 {
                q / len
            } else {
                DQuat::IDENTITY
            };
            DMat4::from_scale_rotation_translation(
                DVec3::from_array(scale.map(f64::from)),
                q,
                DVec3::from_array(translation.map(f64::from)),
            )
        }
    }
}

/// Triangle-list indices from a primitive's vertex indices in `mode`, and whether indices were
/// left over (a list whose length is not a multiple of three).
fn triangle_list(mode: Mode, mut v: Vec<u32>) -> (Vec<u32>, bool) {
    match mode {
        Mode::TriangleStrip => {
            let triangles = (2..v.len()).flat_map(|i| {
                // Every other triangle of a strip is flipped back to the strip's winding.
                if i % 2 == 0 {
                    [v[i - 2], v[i - 1], v[i]]
                } else {
                    [v[i - 2], v[i], v[i - 1]]
                }
            });
            (triangles.collect(), false)
        }
        Mode::TriangleFan => {
            let triangles = (2..v.len()).flat_map(|i| [v[i - 1], v[i], v[0]]);
            (triangles.collect(), false)
        }
        _ => {
            let whole = v.len() / 3 * 3;
            let leftover = whole != v.len();
            v.truncate(whole);
            (v, leftover)
        }
    }
}

fn unit_vector(n: [f32; 3]) -> [f32; 3] {
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if len > 0.0 { n.map(|c| c / len) } else { n }
}

fn material_of(primitive: &Primitive<'_>) -> Material {
    let pbr = primitive.material().pbr_metallic_roughness();
    let unit = |x: f32| {
        if x.is_finite() {
            x.clamp(0.0, 1.0)
        } else {
            0.0
        }
    };
    let mut base_color = pbr.base_color_factor().map(unit);
    // glTF: alpha counts only in BLEND mode (and MASK cuts, which is not drawn here); an
    // OPAQUE material is opaque whatever its alpha.
    if primitive.material().alpha_mode() != gltf::material::AlphaMode::Blend {
        base_color[3] = 1.0;
    }
    Material {
        base_color,
        roughness: unit(pbr.roughness_factor()),
        metallic: unit(pbr.metallic_factor()),
    }
}

/// The node's name, else the mesh's, else `node N`; with the primitive number if there are
/// several.
fn part_name(instance: &Instance<'_>, primitive: &Primitive<'_>, primitive_count: usize) -> String {
    let base = instance
        .node
        .name()
        .or_else(|| instance.mesh.name())
        .map_or_else(|| format!("node {}", instance.node.index()), str::to_owned);
    if primitive_count > 1 {
        format!("{base} #{}", primitive.index())
    } else {
        base
    }
}

#[cfg(test)]
mod tests;
