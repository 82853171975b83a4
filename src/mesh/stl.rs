//! STL, binary and ASCII, through `stl_io`.
//!
//! A binary file is 84 header bytes (80 free, then a little-endian `u32` triangle count) and 50
//! bytes a triangle. Some binary files start their free header with `solid` too, so a file whose
//! length matches its count is binary whatever it starts with; the count is checked against the
//! length before anything is read or allocated. Vertices are shared through `stl_io`'s indexed
//! mesh, and the normals are recomputed (the facet normals in STL files are often wrong).

use std::io::{Read, Seek, SeekFrom};

use glam::DMat4;

use super::{CpuMesh, Material, MeshError, MeshPart, Model, Origin};

/// Bytes before the first triangle of a binary STL.
const HEADER_BYTES: u64 = 84;
/// Bytes of one binary STL triangle record.
const RECORD_BYTES: u64 = 50;

/// The length a binary STL of this file's declared triangle count has, if the file is long
/// enough to declare one.
fn declared_binary_len(bytes: &[u8]) -> Option<u64> {
    let count: [u8; 4] = bytes.get(80..84)?.try_into().ok()?;
    Some(HEADER_BYTES + RECORD_BYTES * u64::from(u32::from_le_bytes(count)))
}

/// Whether `bytes` is a binary STL by the length rule: 84 + 50 * count bytes exactly.
pub(super) fn is_binary(bytes: &[u8]) -> bool {
    declared_binary_len(bytes) == Some(bytes.len() as u64)
}

/// Loads an STL file held in `bytes` as a one-part model.
pub(super) fn load(bytes: &[u8], origin: &Origin) -> Result<Model, MeshError> {
    let mut warnings = Vec::new();
    let indexed = if !is_binary(bytes) && bytes.starts_with(b"solid") {
        read_ascii(bytes, origin)?
    } else {
        read_binary(bytes, origin, &mut warnings)?
    };
    let mesh = to_cpu_mesh(&indexed, origin)?;
    if mesh.indices.is_empty() {
        warnings.push("the STL file holds no triangles".to_owned());
    }
    Ok(Model {
        parts: vec![MeshPart {
            name: origin.stem(),
            transform: DMat4::IDENTITY,
            mesh,
            material: Material::default(),
        }],
        warnings,
    })
}

/// Reads a binary STL after checking its declared triangle count against its length.
fn read_binary(
    bytes: &[u8],
    origin: &Origin,
    warnings: &mut Vec<String>,
) -> Result<stl_io::IndexedMesh, MeshError> {
    let actual = bytes.len() as u64;
    let Some(declared) = declared_binary_len(bytes) else {
        return Err(origin.malformed(
            "STL",
            format!("{actual} bytes: shorter than the 84-byte binary header, and not ASCII"),
        ));
    };
    if declared > actual {
        let what = "the triangle records the binary STL header declares";
        return Err(origin.too_large(what, declared - HEADER_BYTES, actual - HEADER_BYTES));
    }
    if declared < actual {
        warnings.push(format!(
            "{} bytes after the declared triangles were ignored",
            actual - declared
        ));
    }
    // Blank the free header so that stl_io, which takes a file starting with "solid " for ASCII,
    // reads this one as binary.
    let mut reader = Spliced::new(&[0; 80], bytes.get(80..).unwrap_or_default());
    read_with_stl_io(&mut reader, origin)
}

/// Reads an ASCII STL. stl_io wants the first line to start with `"solid "`; a bare `solid`
/// line (an unnamed solid) gets its space.
fn read_ascii(bytes: &[u8], origin: &Origin) -> Result<stl_io::IndexedMesh, MeshError> {
    let mut reader = match bytes.strip_prefix(b"solid") {
        Some(rest) if !rest.starts_with(b" ") => Spliced::new(b"solid ", rest),
        _ => Spliced::new(&[], bytes),
    };
    read_with_stl_io(&mut reader, origin)
}

fn read_with_stl_io(
    reader: &mut Spliced<'_>,
    origin: &Origin,
) -> Result<stl_io::IndexedMesh, MeshError> {
    stl_io::create_stl_reader(reader)
        .and_then(|mut triangles| triangles.as_indexed_triangles())
        .map_err(|e| origin.malformed("STL", e.to_string()))
}

/// Converts stl_io's indexed mesh, checking coordinates and indices, and computes normals.
fn to_cpu_mesh(indexed: &stl_io::IndexedMesh, origin: &Origin) -> Result<CpuMesh, MeshError> {
    let positions: Vec<[f32; 3]> = indexed.vertices.iter().map(|v| v.0).collect();
    if positions.iter().flatten().any(|c| !c.is_finite()) {
        return Err(origin.non_finite("STL vertex coordinates"));
    }
    let len = positions.len() as u64;
    let mut indices = Vec::with_capacity(indexed.faces.len() * 3);
    for &i in indexed.faces.iter().flat_map(|f| &f.vertices) {
        match u32::try_from(i) {
            Ok(i) if u64::from(i) < len => indices.push(i),
            _ => return Err(origin.out_of_range("STL facet", i as u64, len)),
        }
    }
    let mut mesh = CpuMesh {
        colors: Vec::new(),
        positions,
        normals: Vec::new(),
        indices,
    };
    mesh.compute_normals();
    Ok(mesh)
}

/// A seekable reader over `prefix` followed by `body`, without copying either.
struct Spliced<'a> {
    prefix: &'a [u8],
    body: &'a [u8],
    pos: u64,
}

impl<'a> Spliced<'a> {
    fn new(prefix: &'a [u8], body: &'a [u8]) -> Self {
        Self {
            prefix,
            body,
            pos: 0,
        }
    }

    fn len(&self) -> u64 {
        (self.prefix.len() + self.body.len()) as u64
    }
}

impl Read for Spliced<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let prefix_len = self.prefix.len() as u64;
        let source = if self.pos < prefix_len {
            self.prefix.get(self.pos as usize..)
        } else {
            self.body.get((self.pos - prefix_len) as usize..)
        };
        let source = source.unwrap_or_default();
        let n = source.len().min(buf.len());
        buf[..n].copy_from_slice(&source[..n]);
        self.pos += n as u64;
        Ok(n)
    }
}

impl Seek for Spliced<'_> {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        let target = match to {
            SeekFrom::Start(p) => Some(p),
            SeekFrom::End(d) => self.len().checked_add_signed(d),
            SeekFrom::Current(d) => self.pos.checked_add_signed(d),
        };
        let target = target.ok_or_else(|| {
            std::io::Error::new(std::io::ErrorKind::InvalidInput, "seek before the start")
        })?;
        self.pos = target;
        Ok(target)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A binary STL of the given triangles, its header starting with `header`.
    fn binary_stl(header: &[u8], triangles: &[[[f32; 3]; 3]]) -> Vec<u8> {
        let mut bytes = vec![0u8; 80];
        bytes[..header.len()].copy_from_slice(header);
        bytes.extend_from_slice(&(triangles.len() as u32).to_le_bytes());
        for t in triangles {
            bytes.extend_from_slice(&[0u8; 12]);
            for c in t.iter().flatten() {
                bytes.extend_from_slice(&c.to_le_bytes());
            }
            bytes.extend_from_slice(&[0, 0]);
        }
        bytes
    }

    const TRIANGLE: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];

    #[test]
    fn one_triangle_binary_even_with_a_solid_header() {
        let bytes = binary_stl(b"solid but binary", &[TRIANGLE]);
        let model = super::super::load_mesh_bytes(&bytes, "tri.stl").unwrap();
        let mesh = &model.parts[0].mesh;
        assert_eq!(mesh.triangle_count(), 1);
        assert_eq!(mesh.positions.len(), 3);
        assert_eq!(mesh.normals, vec![[0.0, 0.0, 1.0]; 3]);
        assert!(model.warnings.is_empty());
        assert_eq!(model.parts[0].name, "tri");
    }

    #[test]
    fn shared_vertices_are_merged() {
        let second = [[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
        let model = super::super::load_mesh_bytes(&binary_stl(b"", &[TRIANGLE, second]), "q.stl");
        let mesh = &model.unwrap().parts[0].mesh;
        assert_eq!((mesh.triangle_count(), mesh.positions.len()), (2, 4));
    }

    #[test]
    fn count_claiming_a_billion_triangles_is_refused_before_reading() {
        let mut bytes = binary_stl(b"", &[TRIANGLE]);
        bytes[80..84].copy_from_slice(&1_000_000_000u32.to_le_bytes());
        let err = super::super::load_mesh_bytes(&bytes, "huge.stl").unwrap_err();
        assert!(
            matches!(
                err,
                MeshError::TooLarge {
                    size: 50_000_000_000,
                    limit: 50,
                    ..
                }
            ),
            "{err}"
        );
    }

    #[test]
    fn nan_vertex_is_an_error() {
        let mut t = TRIANGLE;
        t[1][2] = f32::NAN;
        let err = super::super::load_mesh_bytes(&binary_stl(b"", &[t]), "nan.stl").unwrap_err();
        assert!(matches!(err, MeshError::NonFinite { .. }), "{err}");
    }

    #[test]
    fn ascii_with_and_without_a_name() {
        let body = "facet normal 0 0 0\n outer loop\n  vertex 0 0 0\n  vertex 1 0 0\n  \
                    vertex 0 1 0\n endloop\nendfacet\nendsolid\n";
        for first in ["solid tri\n", "solid\n"] {
            let text = format!("{first}{body}");
            let model = super::super::load_mesh_bytes(text.as_bytes(), "a.stl").unwrap();
            assert_eq!(model.parts[0].mesh.triangle_count(), 1, "{first:?}");
        }
    }

    #[test]
    fn truncated_ascii_and_short_binary_are_errors() {
        let err = super::super::load_mesh_bytes(b"solid x\nfacet normal 0 0 1\n", "t.stl");
        assert!(matches!(err, Err(MeshError::Malformed { .. })));
        let err = super::super::load_mesh_bytes(&[0u8; 20], "short.stl");
        assert!(matches!(err, Err(MeshError::Malformed { .. })));
    }

    #[test]
    fn spliced_reader_reads_and_seeks_across_the_seam() {
        let mut r = Spliced::new(b"ab", b"cde");
        let mut all = Vec::new();
        r.read_to_end(&mut all).unwrap();
        assert_eq!(all, b"abcde");
        assert_eq!(r.seek(SeekFrom::End(-2)).unwrap(), 3);
        let mut tail = String::new();
        r.read_to_string(&mut tail).unwrap();
        assert_eq!(tail, "de");
        assert!(r.seek(SeekFrom::Current(-9)).is_err());
    }
}
