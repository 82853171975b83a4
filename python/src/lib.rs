//! `splatscene._native`: the splatscene library for Python. The package `splatscene`
//! (`python/splatscene/__init__.py`) wraps these classes and functions and adds what is written
//! in Python (reading SimpleITK and nibabel images, the image type with its PNG for notebooks).
//!
//! Arguments are checked here, before the library sees them: a wrong type is a `TypeError`, a
//! value that cannot mean anything (NaN, an array of the wrong shape, a direction that is not
//! orthonormal) a `ValueError` naming the argument; what the library refuses (a file it cannot
//! read, a scene that does not load) is a `splatscene.SplatsceneError` carrying its message.

use pyo3::prelude::*;

mod convert;
mod mesh;
mod research;
mod scene;
mod volume;

pyo3::create_exception!(
    _native,
    SplatsceneError,
    pyo3::exceptions::PyException,
    "What the splatscene library refused: a file it cannot read, a scene that does not load, a picture it cannot draw."
);

/// The native module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("SplatsceneError", m.py().get_type::<SplatsceneError>())?;
    m.add_class::<volume::Volume>()?;
    m.add_class::<mesh::Mesh>()?;
    m.add_class::<scene::Scene>()?;
    m.add_function(wrap_pyfunction!(volume::load_volume, m)?)?;
    m.add_function(wrap_pyfunction!(research::order, m)?)?;
    m.add_function(wrap_pyfunction!(research::error, m)?)?;
    m.add_function(wrap_pyfunction!(convert::encode_png, m)?)?;
    Ok(())
}
