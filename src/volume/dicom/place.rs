//! Placing a series' slices: one orientation and spacing for all, ordered along the normal,
//! evenly stepped, no gap and no gantry tilt.

use super::*;

/// Every slice must share the first slice's size, orientation and pixel spacing.
pub(super) fn check_consistent(slices: &[SliceHeader]) -> Result<(), VolumeError> {
    let Some(first) = slices.first() else {
        return Ok(());
    };
    for slice in &slices[1..] {
        let problem = if (slice.rows, slice.columns) != (first.rows, first.columns) {
            "Rows x Columns"
        } else if !slice
            .row_dir
            .abs_diff_eq(first.row_dir, ORIENTATION_TOLERANCE)
            || !slice
                .col_dir
                .abs_diff_eq(first.col_dir, ORIENTATION_TOLERANCE)
        {
            "ImageOrientationPatient"
        } else if (0..2).any(|i| {
            let (a, b) = (slice.pixel_spacing[i], first.pixel_spacing[i]);
            (a - b).abs() > SPACING_TOLERANCE * b
        }) {
            "PixelSpacing"
        } else {
            continue;
        };
        let message = format!("{problem} differs from {} of the same series", first.name());
        let message = match slice.frame {
            Some(k) => format!("frame {}: {message}", k + 1),
            None => message,
        };
        return Err(dicom_error(&slice.path, message));
    }
    Ok(())
}

/// Sorts the slices along their normal and works out the grid's placement in RAS.
pub(super) fn place_slices(
    dir: &Path,
    slices: &mut [SliceHeader],
) -> Result<Placement, VolumeError> {
    let first = &slices[0];
    let normal = first.row_dir.cross(first.col_dir);
    let depth = |s: &SliceHeader| s.position.dot(normal);
    slices.sort_by(|a, b| {
        depth(a)
            .total_cmp(&depth(b))
            .then_with(|| a.path.cmp(&b.path))
            .then_with(|| a.frame.cmp(&b.frame))
    });
    let step = match slices {
        [only] => only.slice_thickness.unwrap_or(1.0),
        _ => slice_step(dir, slices, normal)?,
    };
    let first = &slices[0];
    let [dy, dx] = first.pixel_spacing;
    let lps_to_ras = DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0));
    Ok(Placement {
        spacing: [dx, dy, step],
        origin: (lps_to_ras * first.position).into(),
        direction: lps_to_ras * DMat3::from_cols(first.row_dir, first.col_dir, normal),
    })
}

/// The distance between consecutive slices, which must be the same all along the stack.
pub(super) fn slice_step(
    dir: &Path,
    slices: &[SliceHeader],
    normal: DVec3,
) -> Result<f64, VolumeError> {
    let depths: Vec<f64> = slices.iter().map(|s| s.position.dot(normal)).collect();
    check_gaps(dir, slices, &depths)?;
    let step = (depths[depths.len() - 1] - depths[0]) / (depths.len() - 1) as f64;
    let origin = slices[0].position;
    for (k, slice) in slices.iter().enumerate() {
        let off = (slice.position - origin - normal * (step * k as f64)).length();
        if off > POSITION_TOLERANCE * step {
            let message = format!(
                "slice {} is {off:.3} mm from its place in an evenly spaced stack of {step:.3} mm \
                 steps (uneven spacing or gantry tilt, not supported)",
                slice.name()
            );
            return Err(dicom_error(dir, message));
        }
    }
    Ok(step)
}

/// Refuses two slices at one position, and a step well over the smallest one: a missing slice.
/// `depths` are the sorted slices' positions along the normal, the same in LPS and RAS since
/// the flip between them is a rotation.
pub(super) fn check_gaps(
    dir: &Path,
    slices: &[SliceHeader],
    depths: &[f64],
) -> Result<(), VolumeError> {
    let steps: Vec<f64> = depths.windows(2).map(|w| w[1] - w[0]).collect();
    let smallest = steps.iter().copied().fold(f64::INFINITY, f64::min);
    // Two slices at one position first: with a zero step, every other step looks like a gap.
    let Some(i) = steps
        .iter()
        .position(|&step| step <= 1e-6)
        .or_else(|| steps.iter().position(|&step| step > GAP_FACTOR * smallest))
    else {
        return Ok(());
    };
    let what = if steps[i] <= 1e-6 {
        // Every position held the same number of times: time points or repeated stacks.
        let positions = 1 + steps.iter().filter(|&&step| step > 1e-6).count();
        let each = slices.len() / positions;
        if positions > 1 && each > 1 && each * positions == slices.len() {
            format!(
                "{} slices at {positions} positions, {each} at each: several time points or                  stacks in one series, which one 3-D volume cannot hold (split the series,                  for example by acquisition or temporal position, first); two slices at the                  same position",
                slices.len()
            )
        } else {
            "two slices at the same position".to_owned()
        }
    } else {
        let missing = (steps[i] / smallest).round() - 1.0;
        format!(
            "missing slice: gap of {:.3} mm where the step is {smallest:.3} mm, so about \
             {missing} slice(s) missing",
            steps[i]
        )
    };
    let message = format!(
        "{what}, between {} at {:.3} mm and {} at {:.3} mm along the slice normal",
        slices[i].name(),
        depths[i],
        slices[i + 1].name(),
        depths[i + 1]
    );
    Err(dicom_error(dir, message))
}
