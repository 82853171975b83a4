//! Meshes: read from glTF, GLB, OBJ or STL files, or made from vertex and face arrays.

use std::path::PathBuf;
use std::sync::Arc;

use numpy::{PyArray2, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;

use splatscene::mesh::{CpuMesh, Material, MeshPart, Model, load_mesh};
use splatscene::scene::file::{MeshSpec, TransformSpec};

use crate::convert::{bad, fail, numbers, three};

/// A triangle mesh (an implant, a bone surface) with its placement in the scene.
#[pyclass(frozen, module = "splatscene")]
pub struct Mesh {
    /// The file's parts.
    pub model: Arc<Model>,
    /// How a scene places and colours it, as a scene file's `[[mesh]]` table would.
    pub spec: MeshSpec,
}

/// The placement keys shared by every way of making a mesh.
struct Placement {
    translate: Option<[f64; 3]>,
    rotate_degrees: Option<[f64; 3]>,
    scale: Option<[f64; 3]>,
    matrix: Option<[f64; 16]>,
}

impl Placement {
    fn read(
        translate: Option<&Bound<'_, PyAny>>,
        rotate_degrees: Option<&Bound<'_, PyAny>>,
        scale: Option<&Bound<'_, PyAny>>,
        matrix: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let placement = Self {
            translate: translate.map(|v| three(v, "translate")).transpose()?,
            rotate_degrees: rotate_degrees
                .map(|v| three(v, "rotate_degrees"))
                .transpose()?,
            scale: scale.map(|v| three(v, "scale")).transpose()?,
            matrix: matrix.map(matrix4).transpose()?,
        };
        if placement.matrix.is_some()
            && (placement.translate.is_some()
                || placement.rotate_degrees.is_some()
                || placement.scale.is_some())
        {
            return Err(bad(
                "matrix replaces translate, rotate_degrees and scale: give the matrix alone",
            ));
        }
        if let Some(s) = placement.scale
            && s.contains(&0.0)
        {
            return Err(bad(format!(
                "scale: {s:?} has a zero: the mesh would be flat"
            )));
        }
        Ok(placement)
    }

    fn spec(self) -> TransformSpec {
        TransformSpec {
            translate: self.translate,
            rotate_degrees: self.rotate_degrees,
            scale: self.scale,
            matrix: self.matrix,
        }
    }
}

/// A 4x4 placement matrix, row by row, as the library's column-major array; its last row
/// must be 0, 0, 0, 1 and its 3x3 part invertible.
fn matrix4(value: &Bound<'_, PyAny>) -> PyResult<[f64; 16]> {
    let rows = crate::convert::matrix(value, 4, 4, "matrix")?;
    if rows[3] != [0.0, 0.0, 0.0, 1.0] {
        return Err(bad(
            "matrix: the last row must be 0, 0, 0, 1 (an affine placement)",
        ));
    }
    let mut cols = [0.0; 16];
    for (c, col) in cols.chunks_mut(4).enumerate() {
        for (r, v) in col.iter_mut().enumerate() {
            *v = rows[r][c];
        }
    }
    let m = glam::DMat4::from_cols_array(&cols);
    if m.determinant().abs() < 1e-12 {
        return Err(bad("matrix: singular; it would flatten the mesh"));
    }
    Ok(cols)
}

/// A colour: three or four numbers from 0 to 1 (linear RGB and alpha).
fn colour(value: &Bound<'_, PyAny>) -> PyResult<Vec<f32>> {
    let n = value.len().unwrap_or(0);
    let c = numbers(value, if n == 4 { 4 } else { 3 }, "color")?;
    if c.iter().any(|v| !(0.0..=1.0).contains(v)) {
        return Err(bad(format!("color: {c:?}; each channel runs from 0 to 1")));
    }
    Ok(c.into_iter().map(|v| v as f32).collect())
}

/// The appearance and placement keyword arguments, read into a spec.
#[allow(clippy::too_many_arguments)]
fn spec_of(
    path: String,
    name: Option<String>,
    units: Option<&str>,
    frame: Option<&str>,
    color: Option<&Bound<'_, PyAny>>,
    opacity: Option<f32>,
    placement: Placement,
) -> PyResult<MeshSpec> {
    if let Some(o) = opacity
        && !(o > 0.0 && o <= 1.0)
    {
        return Err(bad(format!("opacity: {o} is not in (0, 1]")));
    }
    Ok(MeshSpec {
        name,
        path,
        color: color.map(colour).transpose()?,
        opacity,
        units: units
            .map(|u| u.parse().map_err(|e| bad(format!("units: {e}"))))
            .transpose()?,
        frame: frame
            .map(|f| f.parse().map_err(|e| bad(format!("frame: {e}"))))
            .transpose()?,
        transform: placement.spec(),
        ..MeshSpec::default()
    })
}

#[pymethods]
impl Mesh {
    /// Reads a glTF, GLB, OBJ or STL file (`builtin:prosthesis` is the generated humeral
    /// stem). `units` the file's length unit (mm, cm or m), `frame` its patient frame (RAS, or
    /// LPS as 3D Slicer exports), then the placement in the scene: `translate` (mm),
    /// `rotate_degrees` (about x, then y, then z), `scale`, or a 4x4 `matrix` alone; `name`,
    /// `color` (RGB or RGBA from 0 to 1) and `opacity` as in scene files.
    #[staticmethod]
    #[pyo3(signature = (path, *, units=None, frame=None, name=None, color=None, opacity=None, translate=None, rotate_degrees=None, scale=None, matrix=None))]
    #[allow(clippy::too_many_arguments)]
    pub fn from_file(
        py: Python<'_>,
        path: PathBuf,
        units: Option<&str>,
        frame: Option<&str>,
        name: Option<String>,
        color: Option<&Bound<'_, PyAny>>,
        opacity: Option<f32>,
        translate: Option<&Bound<'_, PyAny>>,
        rotate_degrees: Option<&Bound<'_, PyAny>>,
        scale: Option<&Bound<'_, PyAny>>,
        matrix: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let placement = Placement::read(translate, rotate_degrees, scale, matrix)?;
        let text = path.display().to_string();
        let name = name.or_else(|| path.file_name().map(|n| n.to_string_lossy().into_owned()));
        let spec = spec_of(text.clone(), name, units, frame, color, opacity, placement)?;
        let model = py
            .detach(|| {
                if text == "builtin:prosthesis" {
                    splatscene::scene::shoulder::prosthesis_model()
                } else {
                    load_mesh(&path)
                }
            })
            .map_err(fail)?;
        Ok(Self {
            model: Arc::new(model),
            spec,
        })
    }

    /// A mesh from `vertices` (n x 3 numbers, millimetres in RAS) and `faces` (m x 3 vertex
    /// indices, counter-clockwise seen from outside), with the placement and appearance
    /// arguments of `from_file`.
    #[staticmethod]
    #[pyo3(signature = (vertices, faces, *, name=None, color=None, opacity=None, translate=None, rotate_degrees=None, scale=None, matrix=None))]
    #[allow(clippy::too_many_arguments)]
    fn from_arrays(
        vertices: &Bound<'_, PyAny>,
        faces: &Bound<'_, PyAny>,
        name: Option<String>,
        color: Option<&Bound<'_, PyAny>>,
        opacity: Option<f32>,
        translate: Option<&Bound<'_, PyAny>>,
        rotate_degrees: Option<&Bound<'_, PyAny>>,
        scale: Option<&Bound<'_, PyAny>>,
        matrix: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let placement = Placement::read(translate, rotate_degrees, scale, matrix)?;
        let positions = vertex_array(vertices)?;
        let indices = face_array(faces, positions.len())?;
        let mut mesh = CpuMesh {
            positions,
            indices,
            ..CpuMesh::default()
        };
        mesh.compute_normals();
        let name = name.unwrap_or_else(|| "mesh".into());
        let spec = spec_of(
            "<arrays>".into(),
            Some(name.clone()),
            None,
            None,
            color,
            opacity,
            placement,
        )?;
        let model = Model {
            parts: vec![MeshPart {
                name,
                transform: glam::DMat4::IDENTITY,
                mesh,
                material: Material::default(),
            }],
            warnings: Vec::new(),
        };
        Ok(Self {
            model: Arc::new(model),
            spec,
        })
    }

    /// This mesh placed anew: `translate`, `rotate_degrees`, `scale`, or a 4x4 `matrix`
    /// alone, replacing its placement.
    #[pyo3(signature = (*, translate=None, rotate_degrees=None, scale=None, matrix=None))]
    fn placed(
        &self,
        translate: Option<&Bound<'_, PyAny>>,
        rotate_degrees: Option<&Bound<'_, PyAny>>,
        scale: Option<&Bound<'_, PyAny>>,
        matrix: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let placement = Placement::read(translate, rotate_degrees, scale, matrix)?;
        Ok(Self {
            model: Arc::clone(&self.model),
            spec: MeshSpec {
                transform: placement.spec(),
                ..self.spec.clone()
            },
        })
    }

    /// The mesh's name in a scene.
    #[getter]
    fn name(&self) -> Option<String> {
        self.spec.name.clone()
    }

    /// The vertices of every part, n x 3 float32, in the file's coordinates.
    #[getter]
    fn vertices<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let flat: Vec<f32> = self
            .model
            .parts
            .iter()
            .flat_map(|p| p.mesh.positions.iter().flatten().copied())
            .collect();
        let n = flat.len() / 3;
        numpy::PyArray1::from_vec(py, flat).reshape([n, 3])
    }

    /// The triangles of every part, m x 3 uint32 indices into `vertices`.
    #[getter]
    fn faces<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<u32>>> {
        let mut flat = Vec::new();
        let mut base = 0u32;
        for part in &self.model.parts {
            flat.extend(part.mesh.indices.iter().map(|i| i + base));
            base += part.mesh.positions.len() as u32;
        }
        let m = flat.len() / 3;
        numpy::PyArray1::from_vec(py, flat).reshape([m, 3])
    }

    fn __repr__(&self) -> String {
        let triangles: usize = self
            .model
            .parts
            .iter()
            .map(|p| p.mesh.triangle_count())
            .sum();
        format!(
            "Mesh({:?}, {} part{}, {triangles} triangles)",
            self.spec.name.as_deref().unwrap_or(""),
            self.model.parts.len(),
            if self.model.parts.len() == 1 { "" } else { "s" }
        )
    }
}

/// Vertices: a numpy array (or nested sequence) of n x 3 finite numbers.
fn vertex_array(value: &Bound<'_, PyAny>) -> PyResult<Vec<[f32; 3]>> {
    let array = as_2d(value, "vertices")?;
    let floats = array
        .call_method1("astype", ("float64",))?
        .cast_into::<PyArray2<f64>>()
        .map_err(|_| PyTypeError::new_err("vertices: expected numbers"))?;
    let readonly = floats.readonly();
    let view = readonly.as_array();
    let mut out = Vec::with_capacity(view.nrows());
    for (i, row) in view.rows().into_iter().enumerate() {
        let p = [row[0], row[1], row[2]];
        if p.iter().any(|v| !v.is_finite()) {
            return Err(bad(format!("vertices: vertex {i} is {p:?}, not finite")));
        }
        out.push(p.map(|v| v as f32));
    }
    Ok(out)
}

/// Faces: m x 3 whole numbers, each below `vertices`.
fn face_array(value: &Bound<'_, PyAny>, vertices: usize) -> PyResult<Vec<u32>> {
    let array = as_2d(value, "faces")?;
    let kind: String = array.getattr("dtype")?.getattr("kind")?.extract()?;
    if kind != "i" && kind != "u" {
        return Err(PyTypeError::new_err(format!(
            "faces: expected whole numbers (an integer dtype), got dtype kind {kind:?}"
        )));
    }
    let ints = array
        .call_method1("astype", ("int64",))?
        .cast_into::<PyArray2<i64>>()
        .map_err(|_| PyTypeError::new_err("faces: expected whole numbers"))?;
    let readonly = ints.readonly();
    let mut out = Vec::with_capacity(readonly.as_array().len());
    for (i, v) in readonly.as_array().iter().enumerate() {
        if *v < 0 || *v as u64 >= vertices as u64 {
            return Err(bad(format!(
                "faces: face {} names vertex {v}; there are {vertices} vertices",
                i / 3
            )));
        }
        out.push(*v as u32);
    }
    if out.is_empty() {
        return Err(bad("faces: no triangles"));
    }
    Ok(out)
}

/// `value` as a 2-D numpy array of three columns.
fn as_2d<'py>(value: &Bound<'py, PyAny>, name: &str) -> PyResult<Bound<'py, PyUntypedArray>> {
    let numpy = value.py().import("numpy")?;
    let array = numpy
        .call_method1("asarray", (value,))
        .map_err(|_| PyTypeError::new_err(format!("{name}: expected an n x 3 array")))?;
    let array = array
        .cast_into::<PyUntypedArray>()
        .map_err(|_| PyTypeError::new_err(format!("{name}: expected an n x 3 array")))?;
    let shape = array.shape().to_vec();
    if shape.len() != 2 || shape[1] != 3 {
        return Err(bad(format!(
            "{name}: expected an n x 3 array, got shape {shape:?}"
        )));
    }
    let kind: String = array.getattr("dtype")?.getattr("kind")?.extract()?;
    if !matches!(kind.as_str(), "i" | "u" | "f") {
        return Err(PyTypeError::new_err(format!(
            "{name}: expected numbers, got dtype kind {kind:?}"
        )));
    }
    Ok(array)
}
