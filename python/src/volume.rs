//! Volumes: read from any file the command line reads, or made from a numpy array.

use std::path::PathBuf;
use std::sync::Arc;

use glam::{DMat3, DVec3};
use numpy::ndarray::ArrayView3;
use numpy::{Element, PyArray3, PyArrayDyn, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;

use splatscene::scene::file::{VolumeSpec, read_volume};
use splatscene::volume::detect::{LoadOptions, SeriesChoice, load_volume_with, scalar_type_name};
use splatscene::volume::{CpuVolume, Voxels};

use crate::convert::{bad, fail, grid_dims, json_to_py, matrix, three};

/// A CT or MR volume: values on a regular grid placed in RAS millimetres.
#[pyclass(frozen, module = "splatscene")]
pub struct Volume {
    /// The volume.
    pub inner: Arc<CpuVolume>,
    /// The file's format (`nifti`, `dicom`, `raw`...), `None` for an array.
    format: Option<String>,
    /// The value type the file stored (`int16`...), where known.
    scalar_type: Option<String>,
    /// The 4-D frame read.
    frame: u32,
    /// The file read, `None` for an array.
    pub path: Option<PathBuf>,
}

/// The numpy dtype name of the values as held.
fn held_name(values: &Voxels) -> &'static str {
    match values {
        Voxels::U8(_) => "uint8",
        Voxels::I8(_) => "int8",
        Voxels::U16(_) => "uint16",
        Voxels::I16(_) => "int16",
        Voxels::F32(_) => "float32",
    }
}

/// A numpy view of `values`, shaped `(nz, ny, nx)`, kept alive by `owner` and read-only.
fn view<'py, T: Element>(
    values: &[T],
    dims: [u32; 3],
    owner: Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let shape = (dims[2] as usize, dims[1] as usize, dims[0] as usize);
    let array = ArrayView3::from_shape(shape, values).map_err(fail)?;
    // The values live in the volume's `Arc<CpuVolume>`, which `owner` (the frozen Volume)
    // holds and never changes or reallocates; numpy keeps `owner` as the array's base, so the
    // memory outlives the array. The array is made read-only below, since the renderer reads
    // the same memory with the GIL released.
    #[allow(unsafe_code)]
    let array = unsafe { PyArray3::borrow_from_array(&array, owner) };
    array.call_method(
        "setflags",
        (),
        Some(&[("write", false)].into_py_dict(array.py())?),
    )?;
    Ok(array.into_any())
}

use pyo3::types::IntoPyDict;

#[pymethods]
impl Volume {
    /// The values as a read-only numpy array shaped `(z, y, x)`, as SimpleITK's
    /// `GetArrayFromImage` gives them, in the type the file stored (uint8, int8, uint16, int16,
    /// else float32); no copy is made.
    #[getter]
    fn array<'py>(slf: Bound<'py, Self>) -> PyResult<Bound<'py, PyAny>> {
        let inner = Arc::clone(&slf.get().inner);
        let dims = inner.dims;
        let owner = slf.into_any();
        match &inner.values {
            Voxels::U8(v) => view(v, dims, owner),
            Voxels::I8(v) => view(v, dims, owner),
            Voxels::U16(v) => view(v, dims, owner),
            Voxels::I16(v) => view(v, dims, owner),
            Voxels::F32(v) => view(v, dims, owner),
        }
    }

    /// Voxels along x, y and z (the array's shape reversed).
    #[getter]
    fn dims(&self) -> (u32, u32, u32) {
        let [x, y, z] = self.inner.dims;
        (x, y, z)
    }

    /// Distance between voxel centres along x, y and z, in millimetres.
    #[getter]
    fn spacing(&self) -> (f64, f64, f64) {
        let [x, y, z] = self.inner.spacing;
        (x, y, z)
    }

    /// Where voxel (0, 0, 0) sits, in RAS millimetres.
    #[getter]
    fn origin(&self) -> (f64, f64, f64) {
        let [x, y, z] = self.inner.origin;
        (x, y, z)
    }

    /// The 3x3 direction matrix in RAS: its columns are the x, y and z index axes.
    #[getter]
    fn direction<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let d = self.inner.direction;
        let rows: Vec<Vec<f64>> = (0..3).map(|r| d.row(r).to_array().to_vec()).collect();
        Ok(numpy::PyArray2::from_vec2(py, &rows)
            .map_err(fail)?
            .into_any())
    }

    /// The 4x4 matrix from voxel index (x, y, z, 1) to RAS millimetres.
    #[getter]
    fn affine<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let v = &self.inner;
        let linear = v.direction * DMat3::from_diagonal(DVec3::from(v.spacing));
        let mut rows: Vec<Vec<f64>> = (0..3)
            .map(|r| {
                let mut row = linear.row(r).to_array().to_vec();
                row.push(v.origin[r]);
                row
            })
            .collect();
        rows.push(vec![0.0, 0.0, 0.0, 1.0]);
        Ok(numpy::PyArray2::from_vec2(py, &rows)
            .map_err(fail)?
            .into_any())
    }

    /// The 3-D frame read from a 4-D file (0 for a 3-D one).
    #[getter]
    fn frame(&self) -> u32 {
        self.frame
    }

    /// The file's format (`nifti`, `dicom`, `nrrd`, `raw`...), `None` for an array.
    #[getter]
    fn format(&self) -> Option<String> {
        self.format.clone()
    }

    /// The value type stored in the file, where known; the held type for an array.
    #[getter]
    fn scalar_type(&self) -> Option<String> {
        self.scalar_type.clone()
    }

    /// The file read, `None` for an array.
    #[getter]
    fn path(&self) -> Option<String> {
        self.path.as_ref().map(|p| p.display().to_string())
    }

    /// The volume described as `splatscene info` describes a file: format, size, spacing,
    /// origin, direction (rows), scalar type, and the least, greatest and mean value.
    fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let info = splatscene::volume::loader::describe(
            &self.inner,
            self.path.as_deref(),
            self.format.as_deref(),
            self.scalar_type.as_deref(),
        );
        json_to_py(py, &info)
    }

    fn __repr__(&self) -> String {
        let [x, y, z] = self.inner.dims;
        let [sx, sy, sz] = self.inner.spacing;
        format!(
            "Volume({x}x{y}x{z} {}, spacing {sx}, {sy}, {sz} mm{})",
            held_name(&self.inner.values),
            self.path
                .as_ref()
                .map_or(String::new(), |p| format!(", from {}", p.display()))
        )
    }

    /// A volume from a numpy array of shape `(z, y, x)` (`axes="zyx"`, SimpleITK's order) or
    /// `(x, y, z)` (`axes="xyz"`, nibabel's), C-contiguous for "zyx", Fortran-contiguous for
    /// "xyz" (x fastest in memory either way), of a real dtype: uint8, int8, uint16 and int16
    /// are kept, other integers and floats become float32. `spacing` in millimetres (three
    /// positive numbers along x, y, z), `origin` the RAS position of voxel (0, 0, 0),
    /// `direction` a 3x3 orthonormal matrix whose columns are the x, y, z index axes in RAS.
    #[staticmethod]
    #[pyo3(signature = (array, spacing=None, origin=None, direction=None, axes="zyx"))]
    fn from_array(
        array: &Bound<'_, PyAny>,
        spacing: Option<&Bound<'_, PyAny>>,
        origin: Option<&Bound<'_, PyAny>>,
        direction: Option<&Bound<'_, PyAny>>,
        axes: &str,
    ) -> PyResult<Self> {
        let spacing = spacing.map_or(Ok([1.0; 3]), |s| three(s, "spacing"))?;
        if let Some(s) = spacing.iter().find(|s| **s <= 0.0) {
            return Err(bad(format!(
                "spacing: {s} mm; every spacing must be positive"
            )));
        }
        let origin = origin.map_or(Ok([0.0; 3]), |o| three(o, "origin"))?;
        let direction = match direction {
            Some(d) => rotation(d)?,
            None => DMat3::IDENTITY,
        };
        let untyped = array.cast::<PyUntypedArray>().map_err(|_| {
            PyTypeError::new_err(format!(
                "array: expected a numpy array, got {}",
                array
                    .get_type()
                    .name()
                    .map_or("?".into(), |n| n.to_string())
            ))
        })?;
        let shape = untyped.shape().to_vec();
        if shape.len() != 3 {
            return Err(bad(format!(
                "array: expected a 3-D array, got {} dimension{} {shape:?}",
                shape.len(),
                if shape.len() == 1 { "" } else { "s" }
            )));
        }
        let dims = match axes {
            "zyx" => [shape[2], shape[1], shape[0]],
            "xyz" => [shape[0], shape[1], shape[2]],
            other => {
                return Err(bad(format!(
                    "axes: {other:?}; \"zyx\" (SimpleITK's order) or \"xyz\" (nibabel's)"
                )));
            }
        };
        if dims.contains(&0) {
            return Err(bad(format!("array: empty, shape {shape:?}")));
        }
        let dims: [u32; 3] = dims
            .map(|n| u32::try_from(n).ok())
            .iter()
            .copied()
            .collect::<Option<Vec<u32>>>()
            .and_then(|v| v.try_into().ok())
            .ok_or_else(|| bad(format!("array: shape {shape:?} is too large")))?;
        let x_fastest = match axes {
            "zyx" => untyped.is_c_contiguous(),
            _ => untyped.is_fortran_contiguous(),
        };
        if !x_fastest {
            return Err(bad(format!(
                "array: not contiguous with x fastest in memory; pass numpy.{}(array)",
                if axes == "zyx" {
                    "ascontiguousarray"
                } else {
                    "asfortranarray"
                }
            )));
        }
        // Values stored in the other byte order (a big-endian file read by numpy) are turned
        // to this machine's order first; the layout is kept.
        let native;
        let untyped = if untyped.dtype().getattr("byteorder")?.extract::<String>()? == ">"
            && cfg!(target_endian = "little")
            || untyped.dtype().getattr("byteorder")?.extract::<String>()? == "<"
                && cfg!(target_endian = "big")
        {
            let order = untyped.dtype().call_method1("newbyteorder", ("=",))?;
            native = untyped
                .call_method1("astype", (order,))?
                .cast_into::<PyUntypedArray>()?;
            &native
        } else {
            untyped
        };
        let values = values_of(untyped)?;
        Ok(Self {
            inner: Arc::new(CpuVolume {
                dims,
                spacing,
                origin,
                direction,
                values,
            }),
            format: None,
            scalar_type: None,
            frame: 0,
            path: None,
        })
        .map(|mut v| {
            v.scalar_type = Some(held_name(&v.inner.values).into());
            v
        })
    }
}

/// The values of a contiguous numpy array in memory order, held as the library holds a file's.
fn values_of(array: &Bound<'_, PyUntypedArray>) -> PyResult<Voxels> {
    fn read<T: Element + Copy>(array: &Bound<'_, PyUntypedArray>) -> Option<PyResult<Vec<T>>> {
        let typed = array.cast::<PyArrayDyn<T>>().ok()?;
        let readonly = typed.try_readonly().ok()?;
        Some(
            readonly
                .as_slice()
                .map(<[T]>::to_vec)
                .map_err(|e| bad(format!("array: {e}"))),
        )
    }
    fn as_f32<T: Element + Copy + Into<f64>>(
        array: &Bound<'_, PyUntypedArray>,
    ) -> Option<PyResult<Voxels>> {
        read::<T>(array).map(|r| {
            r.map(|v| {
                v.into_iter()
                    .map(|x| x.into() as f32)
                    .collect::<Vec<f32>>()
                    .into()
            })
        })
    }
    if let Some(v) = read::<u8>(array) {
        return Ok(Voxels::U8(v?));
    }
    if let Some(v) = read::<i8>(array) {
        return Ok(Voxels::I8(v?));
    }
    if let Some(v) = read::<u16>(array) {
        return Ok(Voxels::U16(v?));
    }
    if let Some(v) = read::<i16>(array) {
        return Ok(Voxels::I16(v?));
    }
    if let Some(v) = read::<f32>(array) {
        return Ok(Voxels::F32(v?));
    }
    if let Some(v) = as_f32::<f64>(array)
        .or_else(|| as_f32::<u32>(array))
        .or_else(|| as_f32::<i32>(array))
    {
        return v;
    }
    // 64-bit integers (numpy's default) become float32 as 32-bit ones do.
    let wide = read::<i64>(array)
        .map(|r| r.map(|v| v.into_iter().map(|x| x as f32).collect::<Vec<f32>>()))
        .or_else(|| {
            read::<u64>(array)
                .map(|r| r.map(|v| v.into_iter().map(|x| x as f32).collect::<Vec<f32>>()))
        });
    if let Some(v) = wide {
        return v.map(Voxels::from);
    }
    let dtype = array.dtype();
    Err(PyTypeError::new_err(format!(
        "array: dtype {} is not a real number type; give uint8, int8, uint16, int16, int32, uint32, int64, uint64, float32 or float64",
        dtype.str().map_or("?".into(), |s| s.to_string())
    )))
}

/// A 3x3 direction matrix (rows, or nine numbers row by row as SimpleITK's `GetDirection`
/// gives them), checked: finite and orthonormal within 1e-4 (a rotation, or one with a
/// mirror, as a scanner's left-handed grid has).
pub fn rotation(value: &Bound<'_, PyAny>) -> PyResult<DMat3> {
    let flat = value.len().ok() == Some(9)
        && value
            .get_item(0)
            .is_ok_and(|first| first.extract::<f64>().is_ok());
    let rows = if flat {
        crate::convert::numbers(value, 9, "direction")?
            .chunks(3)
            .map(<[f64]>::to_vec)
            .collect()
    } else {
        matrix(value, 3, 3, "direction")?
    };
    let m = DMat3::from_cols_array_2d(&[
        [rows[0][0], rows[1][0], rows[2][0]],
        [rows[0][1], rows[1][1], rows[2][1]],
        [rows[0][2], rows[1][2], rows[2][2]],
    ]);
    let error = (m.transpose() * m - DMat3::IDENTITY)
        .to_cols_array()
        .iter()
        .fold(0.0f64, |a, b| a.max(b.abs()));
    if error > 1e-4 {
        return Err(bad(format!(
            "direction: not a rotation (its columns must be unit length and at right angles; off by {error:.3})"
        )));
    }
    Ok(m)
}

/// Reads a volume file of any format the command line reads, or a DICOM folder. Options as
/// on the command line: `series`, `skip_unreadable`, `frame`, `nifti_transform`,
/// `coordinate_frame`; for a headerless raw file `dims` and `scalar` (with `header_bytes`,
/// `spacing`, `origin`, `orientation`).
#[pyfunction]
#[pyo3(signature = (path, *, series=None, skip_unreadable=false, frame=None, nifti_transform=None, coordinate_frame=None, dims=None, scalar=None, header_bytes=None, spacing=None, origin=None, orientation=None))]
#[allow(clippy::too_many_arguments)]
pub fn load_volume(
    py: Python<'_>,
    path: PathBuf,
    series: Option<&Bound<'_, PyAny>>,
    skip_unreadable: bool,
    frame: Option<u32>,
    nifti_transform: Option<&str>,
    coordinate_frame: Option<&str>,
    dims: Option<&Bound<'_, PyAny>>,
    scalar: Option<&str>,
    header_bytes: Option<u64>,
    spacing: Option<&Bound<'_, PyAny>>,
    origin: Option<&Bound<'_, PyAny>>,
    orientation: Option<&str>,
) -> PyResult<Volume> {
    fn parsed<T: std::str::FromStr>(value: Option<&str>, key: &str) -> PyResult<Option<T>>
    where
        T::Err: std::fmt::Display,
    {
        value
            .map(|v| v.parse::<T>().map_err(|e| bad(format!("{key}: {e}"))))
            .transpose()
    }
    let series = series.map(|s| s.str().map(|s| s.to_string())).transpose()?;
    let spec = VolumeSpec {
        path: path.display().to_string(),
        dims: dims.map(|d| grid_dims(d, "dims")).transpose()?,
        scalar: parsed(scalar, "scalar")?,
        header_bytes,
        spacing: spacing.map(|s| three(s, "spacing")).transpose()?,
        origin: origin.map(|o| three(o, "origin")).transpose()?,
        orientation: parsed(orientation, "orientation")?,
        series,
        skip_unreadable: skip_unreadable.then_some(true),
        frame,
        nifti_transform: parsed(nifti_transform, "nifti_transform")?,
        coordinate_frame: parsed(coordinate_frame, "coordinate_frame")?,
        ..VolumeSpec::default()
    };
    let raw = spec.dims.is_some() || spec.scalar.is_some();
    let raw_keys = [
        ("header_bytes", spec.header_bytes.is_some()),
        ("spacing", spec.spacing.is_some()),
        ("origin", spec.origin.is_some()),
        ("orientation", spec.orientation.is_some()),
    ];
    if let Some((key, _)) = raw_keys.iter().find(|(_, given)| *given && !raw) {
        return Err(bad(format!(
            "{key} applies to a headerless raw volume, read with dims and scalar; {} places its grid from its header",
            path.display()
        )));
    }
    let loaded = py.detach(|| {
        if raw {
            read_volume(&spec, &path)
                .map(|v| (v, "raw".to_owned(), None))
                .map_err(|e| e.to_string())
        } else {
            let options = LoadOptions {
                series: spec.series.clone().map(SeriesChoice),
                skip_unreadable,
                frame,
                nifti_transform: spec.nifti_transform,
                coordinate_frame: spec.coordinate_frame,
            };
            let loaded = load_volume_with(&path, &options).map_err(|e| e.to_string())?;
            Ok((
                loaded.volume,
                loaded.format.name().to_owned(),
                loaded.scalar_type.map(|s| scalar_type_name(s).to_owned()),
            ))
        }
    });
    let (volume, format, scalar_type) = loaded.map_err(fail)?;
    let scalar_type = scalar_type.or_else(|| raw.then(|| held_name(&volume.values).to_owned()));
    Ok(Volume {
        scalar_type,
        inner: Arc::new(volume),
        format: Some(format),
        frame: frame.unwrap_or(0),
        path: Some(path),
    })
}
