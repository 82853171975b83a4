//! Writers for [`Model`]s: self-contained glTF 2.0 (a `.gltf` JSON file with its one buffer
//! embedded as a base64 data URI) and Wavefront OBJ with its MTL material library.
//!
//! Output is deterministic: the same model gives the same text byte for byte (floats in the
//! glTF JSON are written as their shortest round-trip decimal, OBJ and MTL numbers with six
//! decimals), so generated files can be committed and checked against the code that made them.

use std::collections::HashSet;
use std::fmt::Write as _;

use base64::Engine as _;
use glam::{DMat3, DMat4, DVec3};

use super::{CpuMesh, Material, MeshPart, Model};

const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;
const TRIANGLES: u32 = 4;

/// The model as a self-contained glTF 2.0 JSON document.
///
/// One node, mesh and pbrMetallicRoughness material per part, in order, all in the default
/// scene; a node carries its part's transform as a column-major `matrix` unless that is the
/// identity. Positions (with `min`/`max`) and normals are float VEC3 and indices u32, all in
/// one buffer held in a `data:application/octet-stream;base64,` URI. A part without triangles
/// becomes a node without a mesh (glTF allows no empty accessors); normals are left out of a
/// part whose normal count differs from its position count.
pub fn write_gltf(model: &Model) -> String {
    let mut doc = GltfDoc::default();
    for part in &model.parts {
        doc.add_part(part);
    }
    doc.finish()
}

/// The glTF arrays being filled, each element already as JSON text.
#[derive(Default)]
struct GltfDoc {
    buffer: Vec<u8>,
    views: Vec<String>,
    accessors: Vec<String>,
    meshes: Vec<String>,
    materials: Vec<String>,
    nodes: Vec<String>,
}

impl GltfDoc {
    fn add_part(&mut self, part: &MeshPart) {
        let name = json_string(&part.name);
        let material = self.materials.len();
        self.materials.push(material_json(&name, &part.material));
        let mut node = format!("{{\"name\":{name}");
        if let Some(mesh) = self.add_mesh(&name, &part.mesh, material) {
            let _ = write!(node, ",\"mesh\":{mesh}");
        }
        if part.transform != DMat4::IDENTITY {
            let columns = part.transform.to_cols_array().map(|v| v as f32);
            let _ = write!(node, ",\"matrix\":{}", json_floats(&columns));
        }
        node.push('}');
        self.nodes.push(node);
    }

    /// Index of the new mesh, or `None` for a mesh without triangles.
    fn add_mesh(&mut self, name: &str, mesh: &CpuMesh, material: usize) -> Option<usize> {
        let (min, max) = mesh.bounds()?;
        if mesh.indices.len() < 3 {
            return None;
        }
        let position = self.add_vec3(&mesh.positions, Some((min, max)));
        let mut attributes = format!("\"POSITION\":{position}");
        if mesh.normals.len() == mesh.positions.len() {
            let normal = self.add_vec3(&mesh.normals, None);
            let _ = write!(attributes, ",\"NORMAL\":{normal}");
        }
        let indices = self.add_indices(&mesh.indices);
        self.meshes.push(format!(
            "{{\"name\":{name},\"primitives\":[{{\"attributes\":{{{attributes}}},\
             \"indices\":{indices},\"material\":{material},\"mode\":{TRIANGLES}}}]}}"
        ));
        Some(self.meshes.len() - 1)
    }

    /// Appends a buffer view holding `bytes`, starting on a 4-byte boundary as glTF requires
    /// for float and u32 data.
    fn add_view(&mut self, bytes: &[u8], target: u32) -> usize {
        self.buffer.resize(self.buffer.len().next_multiple_of(4), 0);
        self.views.push(format!(
            "{{\"buffer\":0,\"byteOffset\":{},\"byteLength\":{},\"target\":{target}}}",
            self.buffer.len(),
            bytes.len()
        ));
        self.buffer.extend_from_slice(bytes);
        self.views.len() - 1
    }

    fn add_vec3(&mut self, data: &[[f32; 3]], bounds: Option<([f32; 3], [f32; 3])>) -> usize {
        let bytes: Vec<u8> = data
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let view = self.add_view(&bytes, ARRAY_BUFFER);
        let mut accessor = format!(
            "{{\"bufferView\":{view},\"componentType\":{FLOAT},\"count\":{},\"type\":\"VEC3\"",
            data.len()
        );
        if let Some((min, max)) = bounds {
            let (min, max) = (json_floats(&min), json_floats(&max));
            let _ = write!(accessor, ",\"min\":{min},\"max\":{max}");
        }
        accessor.push('}');
        self.accessors.push(accessor);
        self.accessors.len() - 1
    }

    fn add_indices(&mut self, indices: &[u32]) -> usize {
        let bytes: Vec<u8> = indices.iter().flat_map(|i| i.to_le_bytes()).collect();
        let view = self.add_view(&bytes, ELEMENT_ARRAY_BUFFER);
        self.accessors.push(format!(
            "{{\"bufferView\":{view},\"componentType\":{UNSIGNED_INT},\"count\":{},\
             \"type\":\"SCALAR\"}}",
            indices.len()
        ));
        self.accessors.len() - 1
    }

    /// The whole document; arrays with nothing in them are left out, as glTF requires.
    fn finish(self) -> String {
        let mut members = vec![r#""asset":{"version":"2.0","generator":"splatscene"}"#.to_owned()];
        // gltf-json (and so the crate's own loader) wants a scene to list nodes, so a model
        // without parts has no scene.
        if !self.nodes.is_empty() {
            let roots: Vec<String> = (0..self.nodes.len()).map(|i| i.to_string()).collect();
            members.push("\"scene\":0".to_owned());
            let scene = format!("{{\"nodes\":[{}]}}", roots.join(","));
            members.push(json_member("scenes", &[scene]));
        }
        let arrays = [
            ("nodes", &self.nodes),
            ("meshes", &self.meshes),
            ("materials", &self.materials),
            ("accessors", &self.accessors),
            ("bufferViews", &self.views),
        ];
        for (key, items) in arrays.into_iter().filter(|(_, items)| !items.is_empty()) {
            members.push(json_member(key, items));
        }
        if !self.buffer.is_empty() {
            let buffer = format!(
                "{{\"byteLength\":{},\"uri\":\"data:application/octet-stream;base64,{}\"}}",
                self.buffer.len(),
                base64::engine::general_purpose::STANDARD.encode(&self.buffer)
            );
            members.push(json_member("buffers", &[buffer]));
        }
        format!("{{\n{}\n}}\n", members.join(",\n"))
    }
}

/// `"key":[...]` with one item a line, so that diffs of generated files stay readable.
fn json_member(key: &str, items: &[String]) -> String {
    format!("\"{key}\":[\n{}\n]", items.join(",\n"))
}

fn material_json(name: &str, material: &Material) -> String {
    format!(
        "{{\"name\":{name},\"pbrMetallicRoughness\":{{\"baseColorFactor\":{},\
         \"metallicFactor\":{},\"roughnessFactor\":{}}}}}",
        json_floats(&material.base_color),
        json_float(material.metallic),
        json_float(material.roughness)
    )
}

/// Shortest decimal that reads back as the same f32; JSON has no NaN or infinity, so those
/// become 0 rather than making the document unreadable.
fn json_float(v: f32) -> String {
    // -0 (from rotation matrices) reads as 0 anyway and only clutters diffs.
    if v.is_finite() && v != 0.0 {
        format!("{v}")
    } else {
        "0".to_owned()
    }
}

fn json_floats(values: &[f32]) -> String {
    let items: Vec<String> = values.iter().map(|&v| json_float(v)).collect();
    format!("[{}]", items.join(","))
}

/// `s` as a quoted JSON string.
fn json_string(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if u32::from(c) < 0x20 => {
                let _ = write!(out, "\\u{:04x}", u32::from(c));
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// The model as Wavefront OBJ text and the text of its MTL library, which the OBJ names
/// `mtl_name` (write it next to the OBJ under that name).
///
/// Each part becomes an object (`o`) with its own material (`usemtl`), named after the part
/// with whitespace replaced by `_` and a `_<index>` suffix where names repeat. Positions and
/// normals are transformed into the model frame (OBJ has no transforms), and faces are
/// `f a//a b//b c//c` (plain `f a b c` for a part whose normal count differs from its
/// position count). The MTL carries `Kd` (base colour), `Ks` (specular reflectance), `Ns`
/// (Phong exponent from roughness), `d` (alpha) and the PBR extension's `Pr` and `Pm`.
pub fn write_obj(model: &Model, mtl_name: &str) -> (String, String) {
    let mut obj = format!("# generated by splatscene\nmtllib {mtl_name}\n");
    let mut mtl = String::from("# generated by splatscene\n");
    // OBJ indices are 1-based and count the vertices of all the objects before.
    let mut first = 1;
    for (part, name) in model.parts.iter().zip(obj_names(model)) {
        write_obj_part(&mut obj, part, &name, first);
        write_mtl_material(&mut mtl, &name, &part.material);
        first += part.mesh.positions.len();
    }
    (obj, mtl)
}

/// Part names usable as OBJ object and MTL material names: no whitespace, not empty, unique.
fn obj_names(model: &Model) -> Vec<String> {
    let mut seen = HashSet::new();
    model
        .parts
        .iter()
        .enumerate()
        .map(|(i, part)| {
            let mut name: String = part
                .name
                .chars()
                .map(|c| if c.is_whitespace() { '_' } else { c })
                .collect();
            if name.is_empty() {
                name = "part".to_owned();
            }
            if !seen.insert(name.clone()) {
                name = format!("{name}_{i}");
                seen.insert(name.clone());
            }
            name
        })
        .collect()
}

fn write_obj_part(out: &mut String, part: &MeshPart, name: &str, first: usize) {
    let m = &part.mesh;
    let _ = write!(out, "o {name}\nusemtl {name}\n");
    for p in &m.positions {
        let p = part.transform.transform_point3(vec3(*p));
        let _ = writeln!(out, "v {}", fixed3(p));
    }
    let with_normals = m.normals.len() == m.positions.len();
    if with_normals {
        let normal_matrix = normal_matrix(part.transform);
        for n in &m.normals {
            let n = (normal_matrix * vec3(*n)).normalize_or_zero();
            let _ = writeln!(out, "vn {}", fixed3(n));
        }
    }
    // A mirroring transform turns the triangles inside out; glTF readers undo that for a
    // node, but the OBJ has the transform baked in, so the winding is reversed here.
    let mirrored = DMat3::from_mat4(part.transform).determinant() < 0.0;
    for t in m.indices.chunks_exact(3) {
        let [a, b, c] = [t[0], t[1], t[2]].map(|i| i as usize + first);
        let [a, b, c] = if mirrored { [a, c, b] } else { [a, b, c] };
        if with_normals {
            let _ = writeln!(out, "f {a}//{a} {b}//{b} {c}//{c}");
        } else {
            let _ = writeln!(out, "f {a} {b} {c}");
        }
    }
}

/// Takes normals along with a transform: the inverse transpose of its linear part (the part
/// itself when that is singular, which has no better answer).
fn normal_matrix(transform: DMat4) -> DMat3 {
    let linear = DMat3::from_mat4(transform);
    if linear.determinant().abs() > 1e-12 {
        linear.inverse().transpose()
    } else {
        linear
    }
}

/// Three numbers with six decimals; values that round to zero print as `0.000000`, never
/// `-0.000000`, whatever sign their rounding noise had.
fn fixed3(v: DVec3) -> String {
    let fixed = |x: f64| {
        let text = format!("{x:.6}");
        if text == "-0.000000" {
            text[1..].to_owned()
        } else {
            text
        }
    };
    format!("{} {} {}", fixed(v.x), fixed(v.y), fixed(v.z))
}

fn vec3(v: [f32; 3]) -> DVec3 {
    DVec3::from_array(v.map(f64::from))
}

fn write_mtl_material(out: &mut String, name: &str, material: &Material) {
    let [r, g, b, alpha] = material.base_color;
    // Dielectrics reflect about 4% at normal incidence; metals reflect their own colour.
    let f0 = |c: f32| 0.04 + (c - 0.04) * material.metallic;
    let shininess = 1000.0 * (1.0 - f64::from(material.roughness)).powi(2);
    let _ = write!(
        out,
        "\nnewmtl {name}\nKd {r:.6} {g:.6} {b:.6}\nKs {:.6} {:.6} {:.6}\nNs {shininess:.6}\n\
         d {alpha:.6}\nillum 2\nPr {:.6}\nPm {:.6}\n",
        f0(r),
        f0(g),
        f0(b),
        material.roughness,
        material.metallic
    );
}

#[cfg(test)]
mod tests {
    use std::io::BufReader;

    use super::*;

    fn tetrahedron() -> CpuMesh {
        let mut mesh = CpuMesh {
            colors: Vec::new(),
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
            ],
            normals: vec![],
            indices: vec![0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3],
        };
        mesh.compute_normals();
        mesh
    }

    /// Two tetrahedra with the same awkward name, one moved and turned, one mirrored, and an
    /// empty part.
    fn sample() -> Model {
        let mesh = tetrahedron();
        let material = Material {
            base_color: [0.9, 0.2, 0.1, 1.0],
            roughness: 0.25,
            metallic: 0.5,
        };
        let part = |name: &str, transform| MeshPart {
            name: name.to_owned(),
            transform,
            mesh: mesh.clone(),
            material,
        };
        let turned = DMat4::from_rotation_translation(
            glam::DQuat::from_rotation_z(0.5),
            DVec3::new(10.0, -2.0, 3.5),
        );
        let mut empty = part("empty", DMat4::IDENTITY);
        empty.mesh = CpuMesh::default();
        Model {
            parts: vec![
                part("plain \"quoted\"\\ part", turned),
                part(
                    "plain \"quoted\"\\ part",
                    DMat4::from_scale(DVec3::new(-1.0, 1.0, 1.0)),
                ),
                empty,
            ],
            warnings: vec![],
        }
    }

    fn decode_buffer(doc: &::gltf::Gltf) -> Vec<u8> {
        let buffer = doc.buffers().next().unwrap();
        let ::gltf::buffer::Source::Uri(uri) = buffer.source() else {
            panic!("the buffer is not a URI");
        };
        let data = uri
            .strip_prefix("data:application/octet-stream;base64,")
            .unwrap();
        let bytes = base64::engine::general_purpose::STANDARD
            .decode(data)
            .unwrap();
        assert_eq!(bytes.len(), buffer.length());
        bytes
    }

    #[test]
    fn gltf_is_valid_and_holds_the_model() {
        let model = sample();
        let text = write_gltf(&model);
        assert_eq!(text, write_gltf(&model), "deterministic");
        let doc = ::gltf::Gltf::from_slice(text.as_bytes()).expect("valid glTF");
        let bytes = decode_buffer(&doc);
        let nodes: Vec<_> = doc.default_scene().unwrap().nodes().collect();
        assert_eq!(nodes.len(), model.parts.len());
        for (node, part) in nodes.iter().zip(&model.parts) {
            assert_eq!(node.name(), Some(part.name.as_str()));
            let matrix =
                DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(f64::from)));
            assert!(matrix.abs_diff_eq(part.transform, 1e-6));
            let Some(mesh) = node.mesh() else {
                assert!(part.mesh.indices.is_empty());
                continue;
            };
            let primitive = mesh.primitives().next().unwrap();
            let pbr = primitive.material().pbr_metallic_roughness();
            assert_eq!(pbr.base_color_factor(), part.material.base_color);
            assert_eq!(pbr.metallic_factor(), part.material.metallic);
            assert_eq!(pbr.roughness_factor(), part.material.roughness);
            let reader = primitive.reader(|_| Some(&bytes));
            let positions: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
            let normals: Vec<[f32; 3]> = reader.read_normals().unwrap().collect();
            let indices: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
            assert_eq!(positions, part.mesh.positions);
            assert_eq!(normals, part.mesh.normals);
            assert_eq!(indices, part.mesh.indices);
        }
    }

    #[test]
    fn gltf_views_are_aligned_and_bounds_exact() {
        let model = crate::mesh::prosthesis::humeral_prosthesis(&Default::default());
        let doc = ::gltf::Gltf::from_slice(write_gltf(&model).as_bytes()).unwrap();
        for view in doc.views() {
            assert_eq!(view.offset() % 4, 0);
            assert!(view.target().is_some());
        }
        for (mesh, part) in doc.meshes().zip(&model.parts) {
            let primitive = mesh.primitives().next().unwrap();
            let position = primitive.get(&::gltf::Semantic::Positions).unwrap();
            let (lo, hi) = part.mesh.bounds().unwrap();
            let read = |v: Option<::gltf::json::Value>| -> Vec<f32> {
                let v = v.unwrap();
                v.as_array()
                    .unwrap()
                    .iter()
                    .map(|x| x.as_f64().unwrap() as f32)
                    .collect()
            };
            assert_eq!(read(position.min()), lo);
            assert_eq!(read(position.max()), hi);
        }
    }

    #[test]
    fn empty_model_is_still_valid_gltf() {
        let text = write_gltf(&Model::default());
        ::gltf::Gltf::from_slice(text.as_bytes()).expect("valid glTF");
        assert!(!text.contains("buffers"));
    }

    /// Reads OBJ and MTL text back with tobj.
    fn read_obj(obj: &str, mtl: &str) -> (Vec<tobj::Model>, Vec<tobj::Material>) {
        let options = tobj::LoadOptions::default();
        let (objects, materials) =
            tobj::load_obj_buf(&mut BufReader::new(obj.as_bytes()), &options, |path| {
                assert_eq!(path.to_str(), Some("sample.mtl"));
                tobj::load_mtl_buf(&mut BufReader::new(mtl.as_bytes()))
            })
            .unwrap();
        (objects, materials.unwrap())
    }

    #[test]
    fn obj_names_and_materials_read_back() {
        let model = sample();
        let (obj, mtl) = write_obj(&model, "sample.mtl");
        assert_eq!((obj.clone(), mtl.clone()), write_obj(&model, "sample.mtl"));
        let (objects, materials) = read_obj(&obj, &mtl);
        let names: Vec<&str> = objects.iter().map(|o| o.name.as_str()).collect();
        let awkward = "plain_\"quoted\"\\_part";
        assert_eq!(names, [awkward, &format!("{awkward}_1"), "empty"]);
        assert_eq!(materials.len(), 3);
        assert_eq!(materials[0].diffuse, Some([0.9, 0.2, 0.1]));
        let pr = materials[0].unknown_param.get("Pr");
        assert_eq!(pr.map(String::as_str), Some("0.250000"));
        assert!(objects[2].mesh.positions.is_empty());
    }

    #[test]
    fn obj_positions_are_the_transformed_part_positions() {
        let model = sample();
        let (obj, mtl) = write_obj(&model, "sample.mtl");
        let (objects, _) = read_obj(&obj, &mtl);
        // tobj renumbers vertices in the order faces use them, so compare face corners; the
        // mirrored part's triangles were written with two corners swapped.
        for (object, part) in objects.iter().zip(&model.parts).take(2) {
            let m = &object.mesh;
            let order = if part.transform.determinant() < 0.0 {
                [0, 2, 1]
            } else {
                [0, 1, 2]
            };
            assert_eq!(m.indices.len(), part.mesh.indices.len());
            for (read, written) in m.indices.chunks(3).zip(part.mesh.indices.chunks(3)) {
                for (&r, k) in read.iter().zip(order) {
                    let r = 3 * r as usize;
                    let got = DVec3::from_array(std::array::from_fn(|a| m.positions[r + a].into()));
                    let p = part.mesh.positions[written[k] as usize];
                    let expected = part.transform.transform_point3(vec3(p));
                    assert!(got.distance(expected) < 1e-5, "{got} vs {expected}");
                }
            }
        }
    }

    /// Face windings in the OBJ agree with its normals, mirrored part included.
    #[test]
    fn obj_faces_wind_with_their_normals() {
        let (obj, _) = write_obj(&sample(), "sample.mtl");
        let mut v = Vec::new();
        let mut vn = Vec::new();
        let mut faces = 0;
        for line in obj.lines() {
            let words: Vec<&str> = line.split_whitespace().collect();
            let number = |w: &str| w.parse::<f64>().unwrap();
            let index = |w: &str| w.split("//").next().unwrap().parse::<usize>().unwrap() - 1;
            match words.first().copied() {
                Some("v") => v.push(DVec3::new(
                    number(words[1]),
                    number(words[2]),
                    number(words[3]),
                )),
                Some("vn") => vn.push(DVec3::new(
                    number(words[1]),
                    number(words[2]),
                    number(words[3]),
                )),
                Some("f") => {
                    let [a, b, c] = [1, 2, 3].map(|k| index(words[k]));
                    let face = (v[b] - v[a]).cross(v[c] - v[a]);
                    assert!(face.dot(vn[a] + vn[b] + vn[c]) > 0.0, "{line}");
                    faces += 1;
                }
                _ => {}
            }
        }
        assert_eq!(faces, 8);
    }

    #[test]
    fn json_strings_escape_quotes_backslashes_and_controls() {
        assert_eq!(json_string("a\"b\\c\nd"), "\"a\\\"b\\\\c\\u000ad\"");
    }
}
