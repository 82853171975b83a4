//! Arguments read from Python and values handed back: checked numbers, errors, JSON as Python
//! objects, PNG bytes.

use numpy::{PyArrayMethods, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList};

use crate::SplatsceneError;

/// What the library refused, as `SplatsceneError` with its message.
pub fn fail(e: impl std::fmt::Display) -> PyErr {
    SplatsceneError::new_err(e.to_string())
}

/// A `ValueError` with `message`.
pub fn bad(message: impl Into<String>) -> PyErr {
    PyValueError::new_err(message.into())
}

/// A number of a sequence, checked finite: `name` names the argument in errors.
fn finite(value: &Bound<'_, PyAny>, name: &str) -> PyResult<f64> {
    let x: f64 = value
        .extract()
        .map_err(|_| PyTypeError::new_err(format!("{name}: {} is not a number", repr(value))))?;
    if !x.is_finite() {
        return Err(bad(format!("{name}: {x} is not a finite number")));
    }
    Ok(x)
}

/// `repr(value)`, or a placeholder where it has none.
fn repr(value: &Bound<'_, PyAny>) -> String {
    value
        .repr()
        .map_or_else(|_| "the value".into(), |r| r.to_string())
}

/// The items of a sequence (a tuple, a list, a numpy array), exactly `n` of them; `what` says
/// what they should be in errors, `name` the argument.
fn items<'py>(
    value: &Bound<'py, PyAny>,
    n: usize,
    what: &str,
    name: &str,
) -> PyResult<Vec<Bound<'py, PyAny>>> {
    if value.is_instance_of::<pyo3::types::PyString>() {
        return Err(PyTypeError::new_err(format!(
            "{name}: expected {n} {what}, not a string"
        )));
    }
    let items: Vec<Bound<'py, PyAny>> = value
        .try_iter()
        .map_err(|_| {
            PyTypeError::new_err(format!("{name}: expected {n} {what}, got {}", repr(value)))
        })?
        .collect::<PyResult<_>>()?;
    if items.len() != n {
        return Err(bad(format!(
            "{name}: expected {n} {what}, got {}",
            items.len()
        )));
    }
    Ok(items)
}

/// The finite numbers of a sequence (a tuple, a list, a numpy array), exactly `n` of them.
pub fn numbers(value: &Bound<'_, PyAny>, n: usize, name: &str) -> PyResult<Vec<f64>> {
    items(value, n, "numbers", name)?
        .iter()
        .map(|v| finite(v, name))
        .collect()
}

/// A grid's three sizes from a sequence (a tuple, a list, a numpy array) of whole numbers:
/// `name` names the argument in errors.
pub fn grid_dims(value: &Bound<'_, PyAny>, name: &str) -> PyResult<[u32; 3]> {
    let items = items(value, 3, "whole numbers", name)?;
    let mut dims = [0u32; 3];
    for (slot, item) in dims.iter_mut().zip(&items) {
        let n: i64 = item.extract().map_err(|_| {
            PyTypeError::new_err(format!("{name}: {} is not a whole number", repr(item)))
        })?;
        *slot = u32::try_from(n)
            .map_err(|_| bad(format!("{name}: {n} is not a size from 0 to {}", u32::MAX)))?;
    }
    Ok(dims)
}

/// Three finite numbers.
pub fn three(value: &Bound<'_, PyAny>, name: &str) -> PyResult<[f64; 3]> {
    let v = numbers(value, 3, name)?;
    Ok([v[0], v[1], v[2]])
}

/// Two finite numbers.
pub fn two(value: &Bound<'_, PyAny>, name: &str) -> PyResult<[f64; 2]> {
    let v = numbers(value, 2, name)?;
    Ok([v[0], v[1]])
}

/// A matrix of `rows` rows of `cols` finite numbers (nested sequences or a 2-D numpy array),
/// row by row.
pub fn matrix(
    value: &Bound<'_, PyAny>,
    rows: usize,
    cols: usize,
    name: &str,
) -> PyResult<Vec<Vec<f64>>> {
    let shape_error = || bad(format!("{name}: expected a {rows}x{cols} matrix"));
    let items: Vec<Bound<'_, PyAny>> = value
        .try_iter()
        .map_err(|_| shape_error())?
        .collect::<PyResult<_>>()?;
    if items.len() != rows {
        return Err(shape_error());
    }
    items
        .iter()
        .map(|row| numbers(row, cols, name).map_err(|_| shape_error()))
        .collect()
}

/// An image size `(width, height)`: two whole numbers from 1 to 16384.
pub fn size(value: &Bound<'_, PyAny>) -> PyResult<(u32, u32)> {
    let items: Vec<Bound<'_, PyAny>> = value
        .try_iter()
        .map_err(|_| PyTypeError::new_err("size: expected (width, height)"))?
        .collect::<PyResult<_>>()?;
    let [w, h] = items.as_slice() else {
        return Err(bad("size: expected (width, height)"));
    };
    let side = |v: &Bound<'_, PyAny>| -> PyResult<u32> {
        let n: i64 = v.extract().map_err(|_| {
            PyTypeError::new_err(format!("size: {} is not a whole number", repr(v)))
        })?;
        if !(1..=16384).contains(&n) {
            return Err(bad(format!("size: {n} pixels is not from 1 to 16384")));
        }
        Ok(n as u32)
    };
    Ok((side(w)?, side(h)?))
}

/// JSON as Python objects: objects as dicts, arrays as lists, null as None. (Written here: the
/// values are few and small; a crate such as pythonize would be a dependency for ten lines.)
pub fn json_to_py<'py>(py: Python<'py>, value: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    use serde_json::Value;
    Ok(match value {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => b.into_pyobject(py)?.to_owned().into_any(),
        Value::Number(n) => match (n.as_i64(), n.as_f64()) {
            (Some(i), _) => i.into_pyobject(py)?.into_any(),
            (None, Some(f)) => f.into_pyobject(py)?.into_any(),
            (None, None) => py.None().into_bound(py),
        },
        Value::String(s) => s.into_pyobject(py)?.into_any(),
        Value::Array(items) => {
            let list = PyList::empty(py);
            for item in items {
                list.append(json_to_py(py, item)?)?;
            }
            list.into_any()
        }
        Value::Object(map) => {
            let dict = PyDict::new(py);
            for (k, v) in map {
                dict.set_item(k, json_to_py(py, v)?)?;
            }
            dict.into_any()
        }
    })
}

/// The PNG file of an RGBA image, `(height, width, 4)` uint8.
#[pyfunction]
pub fn encode_png<'py>(
    py: Python<'py>,
    image: PyReadonlyArray3<'py, u8>,
) -> PyResult<Bound<'py, PyBytes>> {
    let shape = image.shape();
    if shape[2] != 4 || shape[0] == 0 || shape[1] == 0 {
        return Err(bad(format!(
            "image: expected (height, width, 4) RGBA, got {shape:?}"
        )));
    }
    let (h, w) = (shape[0] as u32, shape[1] as u32);
    let pixels = image.as_array().iter().copied().collect::<Vec<u8>>();
    let rgba = image::RgbaImage::from_raw(w, h, pixels).ok_or_else(|| bad("image: wrong size"))?;
    let png = splatscene::render::encode_png(&rgba).map_err(fail)?;
    Ok(PyBytes::new(py, &png))
}

/// An `(h, w, 4)` uint8 numpy array of an RGBA image.
pub fn image_array<'py>(
    py: Python<'py>,
    image: image::RgbaImage,
) -> PyResult<Bound<'py, numpy::PyArray3<u8>>> {
    let (w, h) = image.dimensions();
    let flat = numpy::PyArray1::from_vec(py, image.into_raw());
    flat.reshape([h as usize, w as usize, 4])
}
