//! The orderings research: draw orders of a grid, and an ordering's image error against the
//! exact order.

use glam::DVec3;
use numpy::PyArray1;
use pyo3::prelude::*;

use splatscene::classify::{TransferFunction, auto_transfer, classify};
use splatscene::grid::SparseGrid;
use splatscene::order::{OrderOptions, Orderer, Ordering, VolumeGeometry, dense_order_bytes};
use splatscene::report::{Entry, ReportSettings, View, measure_views};

use crate::convert::{bad, fail, grid_dims, json_to_py, three, two};
use crate::volume::Volume;

/// An ordering by its name (btf, wbtf, pbtf, ip-pbtf, ip-pbtf-explicit, ip-pbtf-implicit,
/// exact, bucketed, pyramid, rows).
fn ordering_named(name: &str) -> PyResult<Ordering> {
    name.parse::<Ordering>()
        .map_err(|e| bad(format!("ordering: {e}")))
}

/// The draw order of every voxel of a dense `dims` grid (x, y, z) for an `eye` in voxel index
/// coordinates (voxel centres at whole numbers), looking at `target` (the grid's centre by
/// default), as `splatscene order` writes it: voxel ids `x + nx * (y + ny * z)`, farthest
/// first, uint32. `spacing` is the voxel size; `cull_behind_eye` leaves out voxels on or
/// behind the plane through the eye; `bucket_width` is the bucketed order's bucket width.
#[pyfunction]
#[pyo3(signature = (dims, eye, ordering="ip-pbtf", *, spacing=None, target=None, cull_behind_eye=false, bucket_width=None))]
#[allow(clippy::too_many_arguments)]
pub fn order<'py>(
    py: Python<'py>,
    dims: &Bound<'py, PyAny>,
    eye: &Bound<'py, PyAny>,
    ordering: &str,
    spacing: Option<&Bound<'py, PyAny>>,
    target: Option<&Bound<'py, PyAny>>,
    cull_behind_eye: bool,
    bucket_width: Option<f64>,
) -> PyResult<Bound<'py, PyArray1<u32>>> {
    let ordering = ordering_named(ordering)?;
    let dims = grid_dims(dims, "dims")?;
    let spacing = spacing.map_or(Ok([1.0; 3]), |s| three(s, "spacing"))?;
    let eye = three(eye, "eye")?;
    let target = target.map(|t| three(t, "target")).transpose()?;
    if bucket_width.is_some() && ordering != Ordering::Bucketed {
        return Err(bad(format!(
            "bucket_width applies to the bucketed order only, not {ordering}"
        )));
    }
    if let Some(w) = bucket_width
        && !(w.is_finite() && w > 0.0)
    {
        return Err(bad(format!("bucket_width: {w} is not a positive number")));
    }
    let geometry =
        VolumeGeometry::axis_aligned(dims, spacing, [0.0; 3]).map_err(|e| bad(e.to_string()))?;
    let needed = dense_order_bytes(dims, ordering);
    let available = splatscene::budget::memory_budget();
    if needed > available {
        return Err(fail(format!(
            "dims {dims:?}: the {ordering} order of this dense grid needs about {:.1} GiB of memory; {:.1} GiB is available",
            needed as f64 / f64::from(1u32 << 30),
            available as f64 / f64::from(1u32 << 30)
        )));
    }
    let to_world = |p: [f64; 3]| geometry.index_to_world_point(DVec3::from(p));
    let view = splatscene::order::ViewCase::new(
        &geometry,
        to_world(eye),
        target.map_or(geometry.centre_world(), to_world),
    )
    .map_err(|e| bad(e.to_string()))?;
    let options = OrderOptions {
        cull_behind_eye,
        bucket_width,
    };
    let ids = py
        .detach(|| -> Result<Vec<u32>, String> {
            let grid = SparseGrid::dense(dims).map_err(|e| e.to_string())?;
            let mut ids = Vec::new();
            Orderer::new()
                .order(&grid, &view, ordering, &options, &mut ids)
                .map_err(|e| e.to_string())?;
            Ok(ids)
        })
        .map_err(fail)?;
    Ok(PyArray1::from_vec(py, ids))
}

/// Each ordering's image error against the exact order for one view of `volume`, as the
/// orderings report measures it: the volume classified with `transfer` (a preset, "ramp" with
/// `window`, or "auto"), drawn by the reference compositor at `size` (192 x 192 by default,
/// the report's) from `eye` (RAS millimetres) looking at `target` (the volume's centre by
/// default); `orderings` a name or a list of names (every ordering by default). Returns a list of
/// dicts, one an ordering: `ordering`, `case`, `order_ms`, `rmse`, `max_difference`,
/// `bad_pixels` (the share of pixels off by more than 4/255) and `inversions` (the share of
/// consecutive fragments on a pixel drawn nearer first).
#[pyfunction]
#[pyo3(signature = (volume, eye, *, target=None, orderings=None, size=None, transfer=None, window=None))]
#[allow(clippy::too_many_arguments)]
pub fn error<'py>(
    py: Python<'py>,
    volume: PyRef<'py, Volume>,
    eye: &Bound<'py, PyAny>,
    target: Option<&Bound<'py, PyAny>>,
    orderings: Option<&Bound<'py, PyAny>>,
    size: Option<&Bound<'py, PyAny>>,
    transfer: Option<&str>,
    window: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    let eye = DVec3::from(three(eye, "eye")?);
    let target = target.map(|t| three(t, "target")).transpose()?;
    let size = size.map_or(Ok((192, 192)), crate::convert::size)?;
    let names: Option<Vec<String>> = match orderings {
        None => None,
        Some(one) if one.is_instance_of::<pyo3::types::PyString>() => Some(vec![one.extract()?]),
        Some(many) => Some(many.extract().map_err(|_| {
            pyo3::exceptions::PyTypeError::new_err(
                "orderings: a name such as \"ip-pbtf\" or a list of names",
            )
        })?),
    };
    let entries: Vec<Entry> = match names {
        Some(names) if names.is_empty() => return Err(bad("orderings: empty")),
        Some(names) => names
            .iter()
            .map(|n| ordering_named(n).map(Entry::from))
            .collect::<PyResult<_>>()?,
        None => Ordering::ALL.map(Entry::from).to_vec(),
    };
    let window = window.map(|w| two(w, "window")).transpose()?;
    let inner = std::sync::Arc::clone(&volume.inner);
    let tf = match transfer {
        None | Some("auto") => match window {
            Some([lo, hi]) => ramp(lo, hi)?,
            None => auto_transfer(&inner.values).transfer,
        },
        Some("ramp") => {
            let [lo, hi] = window.ok_or_else(|| bad("transfer=\"ramp\" needs window=(lo, hi)"))?;
            ramp(lo, hi)?
        }
        Some(name) => {
            let preset = TransferFunction::preset(name).ok_or_else(|| {
                bad(format!(
                    "transfer: unknown {name:?} (auto, ramp, {})",
                    TransferFunction::PRESETS.join(", ")
                ))
            })?;
            match window {
                Some([lo, hi]) if lo < hi => {
                    preset.windowed((0.5 * (lo + hi)) as f32, (hi - lo) as f32)
                }
                Some([lo, hi]) => {
                    return Err(bad(format!(
                        "window: ({lo}, {hi}); low must lie below high"
                    )));
                }
                None => preset,
            }
        }
    };
    let results = py
        .detach(|| -> Result<_, String> {
            let geometry = inner.geometry().map_err(|e| e.to_string())?;
            let classified = classify(&inner, &tf, 1.0 / 255.0).map_err(|e| e.to_string())?;
            let view = View {
                name: "view",
                index: 0,
                eye,
                target: target.map_or(geometry.centre_world(), DVec3::from),
            };
            let settings = ReportSettings {
                size,
                orderings: entries,
                ..ReportSettings::default()
            };
            measure_views(&geometry, &classified, &[view], &settings, || {})
                .map_err(|e| e.to_string())
        })
        .map_err(fail)?;
    let view = &results[0];
    let rows: Vec<serde_json::Value> = view
        .per_ordering
        .iter()
        .map(|r| {
            serde_json::json!({
                "ordering": r.entry.to_string(),
                "case": view.kind.name(),
                "order_ms": r.order_seconds * 1e3,
                "rmse": r.difference.rmse,
                "max_difference": r.difference.max_abs,
                "bad_pixels": r.difference.bad_pixel_share,
                "inversions": r.fragments.map(|f| f.inversion_share()),
            })
        })
        .collect();
    json_to_py(py, &serde_json::Value::Array(rows))
}

/// A ramp from transparent at `lo` to the default colour at `hi`.
fn ramp(lo: f64, hi: f64) -> PyResult<TransferFunction> {
    if lo >= hi {
        return Err(bad(format!(
            "window: ({lo}, {hi}); low must lie below high"
        )));
    }
    Ok(TransferFunction::ramp(
        lo as f32,
        hi as f32,
        [1.0, 0.93, 0.85, 0.6],
    ))
}
