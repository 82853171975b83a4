//! Classification: a transfer function turns scalar values into colour and opacity, and only
//! voxels that are not (nearly) transparent become splats.

use rayon::prelude::*;

use crate::grid::{GridError, SparseGrid};
use crate::volume::CpuVolume;

/// Piecewise-linear colour and opacity over the scalar value (straight, not premultiplied,
/// RGBA). Below the first point and above the last the end values hold.
#[derive(Debug, Clone, PartialEq)]
pub struct TransferFunction {
    points: Vec<(f32, [f32; 4])>,
}

impl TransferFunction {
    /// A transfer function through `points`; they are sorted by value, and NaN values dropped.
    pub fn new(mut points: Vec<(f32, [f32; 4])>) -> Self {
        points.retain(|(v, _)| !v.is_nan());
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        Self { points }
    }

    /// Transparent below `lo`, rising linearly to `color` at `hi` and above.
    pub fn ramp(lo: f32, hi: f32, color: [f32; 4]) -> Self {
        let clear = [color[0], color[1], color[2], 0.0];
        Self::new(vec![(lo, clear), (hi.max(lo), color)])
    }

    /// CT bone in Hounsfield units: transparent below 150 HU, cancellous bone faint and warm,
    /// cortical bone near-white and dense.
    pub fn ct_bone() -> Self {
        Self::new(vec![
            (150.0, [0.8, 0.55, 0.45, 0.0]),
            (300.0, [0.9, 0.7, 0.55, 0.12]),
            (700.0, [0.95, 0.88, 0.78, 0.45]),
            (1200.0, [1.0, 0.97, 0.92, 0.8]),
        ])
    }

    /// CT soft tissue with bone: faint skin and muscle (about -100 to 100 HU) under bone.
    pub fn ct_soft_tissue() -> Self {
        Self::new(vec![
            (-250.0, [0.75, 0.45, 0.35, 0.0]),
            (-50.0, [0.8, 0.5, 0.4, 0.015]),
            (100.0, [0.85, 0.55, 0.45, 0.03]),
            (200.0, [0.9, 0.75, 0.6, 0.06]),
            (700.0, [0.96, 0.9, 0.82, 0.5]),
            (1200.0, [1.0, 0.97, 0.92, 0.8]),
        ])
    }

    /// CT metal implants: bone faint, and the very dense values of metal (from about 2000 HU,
    /// stent-grafts, stems, screws) bright and nearly opaque, in a cool tint.
    pub fn ct_metal() -> Self {
        Self::new(vec![
            (300.0, [0.9, 0.8, 0.7, 0.0]),
            (1000.0, [0.95, 0.9, 0.85, 0.08]),
            (1800.0, [0.8, 0.85, 0.95, 0.1]),
            (2500.0, [0.75, 0.85, 1.0, 0.9]),
        ])
    }

    /// An MR default: a grey ramp over the upper part of a 0 to 1000 intensity range.
    pub fn mr_default() -> Self {
        Self::new(vec![
            (150.0, [0.8, 0.8, 0.8, 0.0]),
            (500.0, [0.9, 0.88, 0.85, 0.3]),
            (1000.0, [1.0, 1.0, 1.0, 0.7]),
        ])
    }

    /// A preset by name: `ct-bone`, `ct-soft-tissue`, `ct-metal` or `mr-default`.
    pub fn preset(name: &str) -> Option<Self> {
        match name {
            "ct-bone" => Some(Self::ct_bone()),
            "ct-soft-tissue" => Some(Self::ct_soft_tissue()),
            "ct-metal" => Some(Self::ct_metal()),
            "mr-default" => Some(Self::mr_default()),
            _ => None,
        }
    }

    /// Names accepted by [`Self::preset`].
    pub const PRESETS: [&'static str; 4] = ["ct-bone", "ct-soft-tissue", "ct-metal", "mr-default"];

    /// The same function moved along the value axis by `shift` (positive: it starts higher).
    pub fn shifted(&self, shift: f32) -> Self {
        Self::new(self.points.iter().map(|(v, c)| (v + shift, *c)).collect())
    }

    /// The same function stretched so that its points span the window `level - width / 2` to
    /// `level + width / 2` (the usual window and level of CT viewers); a function with a single
    /// point is moved to `level`.
    pub fn windowed(&self, level: f32, width: f32) -> Self {
        let (Some(first), Some(last)) = (self.points.first(), self.points.last()) else {
            return self.clone();
        };
        let span = last.0 - first.0;
        let lo = level - 0.5 * width.abs();
        let points = self
            .points
            .iter()
            .map(|(v, c)| {
                let t = if span > 0.0 {
                    (v - first.0) / span
                } else {
                    0.5
                };
                (lo + t * width.abs(), *c)
            })
            .collect();
        Self::new(points)
    }

    /// The points, sorted by value.
    pub fn points(&self) -> &[(f32, [f32; 4])] {
        &self.points
    }

    /// Straight RGBA at `value`.
    pub fn sample(&self, value: f32) -> [f32; 4] {
        let Some(first) = self.points.first() else {
            return [0.0; 4];
        };
        if value.is_nan() || value <= first.0 {
            return first.1;
        }
        let i = self.points.partition_point(|(v, _)| *v <= value);
        if i == self.points.len() {
            return self.points[i - 1].1;
        }
        let (v0, c0) = self.points[i - 1];
        let (v1, c1) = self.points[i];
        let t = (value - v0) / (v1 - v0);
        std::array::from_fn(|c| c0[c] + t * (c1[c] - c0[c]))
    }
}

/// A transfer function chosen from what a volume's values are, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct AutoTransfer {
    /// The function.
    pub transfer: TransferFunction,
    /// What was chosen and from what, for the user (`ct-bone: values reach -1000 (HU)`).
    pub reason: String,
    /// Whether the values are taken for Hounsfield units.
    pub hounsfield: bool,
}

/// Values reaching this are taken for Hounsfield units: air is -1000 HU and lung -500 to -900,
/// while scalars without a calibration (8-bit data, MR intensities) are rarely negative at
/// all. A scan cropped inside the body (no air in the field) still reaches it through lung or
/// the scanner's padding value (-1024, -2000).
const HU_AIR: f32 = -500.0;
/// Bins of the histogram the automatic ramp reads its percentiles from.
const HISTOGRAM_BINS: usize = 4096;

/// Chooses a transfer function for values of unknown meaning: Hounsfield units (values
/// reaching -500 or below, air and lung) get [`TransferFunction::ct_bone`]; anything else (8-bit data, MR,
/// unknown scalars) a ramp from the 90th to the 99.5th percentile of the values above the
/// smallest one (the background, usually air or padding, is left out of the histogram), so that
/// the densest tenth of the object shows. Percentiles come from a histogram of
/// [`HISTOGRAM_BINS`] bins, one pass over the values.
pub fn auto_transfer(values: &[f32]) -> AutoTransfer {
    let (lo, hi) = finite_range(values);
    if lo <= HU_AIR && hi > 0.0 {
        return AutoTransfer {
            transfer: TransferFunction::ct_bone(),
            reason: format!(
                "ct-bone: values run from {lo} to {hi}, reaching air or lung (-500 or below), so they are taken for Hounsfield units"
            ),
            hounsfield: true,
        };
    }
    let (from, to) = percentiles_above_min(values, lo, hi, 0.90, 0.995);
    let color = [1.0, 0.93, 0.85, 0.7];
    AutoTransfer {
        transfer: TransferFunction::ramp(from, to.max(from), color),
        reason: format!(
            "ramp from {from} to {to}: values run from {lo} to {hi}, not Hounsfield units; the ramp spans the 90th to 99.5th percentile of the values above {lo}"
        ),
        hounsfield: false,
    }
}

/// Whether values are taken for Hounsfield units: they reach -500 (air, lung) and rise above 0,
/// the rule [`auto_transfer`] chooses `ct-bone` by.
pub fn is_hounsfield(values: &[f32]) -> bool {
    let (lo, hi) = finite_range(values);
    lo <= HU_AIR && hi > 0.0
}

fn finite_range(values: &[f32]) -> (f32, f32) {
    values
        .par_chunks(1 << 16)
        .map(|chunk| {
            chunk
                .iter()
                .filter(|v| v.is_finite())
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
                    (lo.min(v), hi.max(v))
                })
        })
        .reduce(
            || (f32::INFINITY, f32::NEG_INFINITY),
            |a, b| (a.0.min(b.0), a.1.max(b.1)),
        )
}

/// Two quantiles of the finite values above `lo` (`lo` and `hi` their range), from a histogram.
fn percentiles_above_min(values: &[f32], lo: f32, hi: f32, a: f64, b: f64) -> (f32, f32) {
    if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
        return (lo.min(0.0), hi.max(1.0));
    }
    let width = f64::from(hi) - f64::from(lo);
    let bin = |v: f32| {
        let t = (f64::from(v) - f64::from(lo)) / width;
        ((t * HISTOGRAM_BINS as f64) as usize).min(HISTOGRAM_BINS - 1)
    };
    let histogram = values
        .par_chunks(1 << 16)
        .map(|chunk| {
            let mut h = vec![0u64; HISTOGRAM_BINS];
            for &v in chunk.iter().filter(|v| v.is_finite() && **v > lo) {
                h[bin(v)] += 1;
            }
            h
        })
        .reduce(
            || vec![0u64; HISTOGRAM_BINS],
            |mut x, y| {
                x.iter_mut().zip(&y).for_each(|(x, y)| *x += y);
                x
            },
        );
    let total: u64 = histogram.iter().sum();
    let at = |q: f64| {
        let wanted = (q * total as f64).ceil() as u64;
        let mut seen = 0;
        let i = histogram
            .iter()
            .position(|&n| {
                seen += n;
                seen >= wanted.max(1)
            })
            .unwrap_or(HISTOGRAM_BINS - 1);
        (f64::from(lo) + width * (i as f64 + 0.5) / HISTOGRAM_BINS as f64) as f32
    };
    (at(a), at(b))
}

/// The significant voxels of a volume with their premultiplied colours (index = rank).
#[derive(Debug, Clone)]
pub struct Classified {
    /// Significant voxels.
    pub grid: SparseGrid,
    /// Premultiplied RGBA per significant voxel, in id order.
    pub colors: Vec<[f32; 4]>,
}

/// Opacity corrected for the distance a ray travels through one splat: the transfer
/// function's opacity is defined for `reference` millimetres; a splat standing for `length`
/// millimetres of tissue absorbs as much as that length of it would
/// (`1 - (1 - alpha)^(length / reference)`), so the same transfer function looks the same at
/// any voxel spacing.
pub fn corrected_opacity(alpha: f32, length: f64, reference: f64) -> f32 {
    if !(length > 0.0 && reference > 0.0) || alpha >= 1.0 {
        return alpha;
    }
    // Transparent stays transparent, without the power: most voxels of a CT are air or
    // tissue the transfer function hides, and `powf` was most of their classification.
    if alpha <= 0.0 {
        return 0.0;
    }
    let exponent = (length / reference) as f32;
    1.0 - (1.0 - alpha.max(0.0)).powf(exponent)
}

/// The splat standard deviation, in voxels, that transfer-function opacities are meant for
/// (the original ShellSplatting's 0.7).
pub const REFERENCE_SIGMA: f64 = 0.7;

/// How many times the transfer function's reference length of tissue one splat stands for,
/// for [`corrected_opacity`]: the voxel's size (geometric mean of the spacing) over the
/// reference length, times `(REFERENCE_SIGMA / sigma)^2`. The second factor keeps the look
/// when splats grow: a ray through a slab of splats of standard deviation `sigma` voxels meets
/// the footprints of about `2 pi sigma^2` of them per voxel layer (the Gaussian's integral
/// over the image plane), so each must absorb that much less. Splats that project to about a
/// pixel or less are widened by the screen-space low-pass term, which this does not model.
pub fn opacity_length_ratio(spacing: [f64; 3], sigma: f64, reference_mm: f64) -> f64 {
    let size = (spacing[0] * spacing[1] * spacing[2]).cbrt();
    let footprint = (REFERENCE_SIGMA / sigma).powi(2);
    let ratio = size / reference_mm * footprint;
    if ratio.is_finite() && ratio > 0.0 {
        ratio
    } else {
        1.0
    }
}

/// Classifies every voxel; those with opacity at or below `min_opacity` are left out.
pub fn classify(
    volume: &CpuVolume,
    tf: &TransferFunction,
    min_opacity: f32,
) -> Result<Classified, GridError> {
    classify_corrected(volume, tf, min_opacity, 1.0)
}

/// Classifies z-slices in parallel: `colour(id)` gives the premultiplied colour of a splat or
/// `None`; the slices' ids come out in increasing order, as the grid wants them.
fn classify_slices(
    volume: &CpuVolume,
    colour: impl Fn(usize) -> Option<[f32; 4]> + Sync,
) -> Result<Classified, GridError> {
    let count = crate::grid::voxel_count(volume.dims)? as usize;
    let plane = (volume.dims[0] as usize * volume.dims[1] as usize).max(1);
    let slices: Vec<(Vec<u32>, Vec<[f32; 4]>)> = (0..count.div_ceil(plane))
        .into_par_iter()
        .map(|z| {
            let (mut ids, mut colors) = (Vec::new(), Vec::new());
            for id in z * plane..((z + 1) * plane).min(count) {
                if let Some(c) = colour(id) {
                    ids.push(id as u32);
                    colors.push(c);
                }
            }
            (ids, colors)
        })
        .collect();
    let total = slices.iter().map(|(ids, _)| ids.len()).sum();
    let (mut ids, mut colors) = (Vec::with_capacity(total), Vec::with_capacity(total));
    for (i, c) in slices {
        ids.extend(i);
        colors.extend(c);
    }
    Ok(Classified {
        grid: SparseGrid::from_sorted_ids(volume.dims, &ids)?,
        colors,
    })
}

/// [`classify`] with every opacity corrected by [`corrected_opacity`] for a splat standing for
/// `length_ratio` times the transfer function's reference length.
pub fn classify_corrected(
    volume: &CpuVolume,
    tf: &TransferFunction,
    min_opacity: f32,
    length_ratio: f64,
) -> Result<Classified, GridError> {
    classify_slices(volume, |id| {
        let [r, g, b, a] = tf.sample(*volume.values.get(id)?);
        let a = corrected_opacity(a, length_ratio, 1.0);
        (a > min_opacity).then_some([r * a, g * a, b * a, a])
    })
}

/// Shell classification, as the original ShellSplatting did: a voxel becomes a splat when its
/// opacity exceeds `min_opacity` and at least one of its six neighbours has opacity at or
/// below `high` (voxels outside the grid count as transparent). The inside of a thick opaque
/// region, which can never show, is left out. Opacities are corrected as in
/// [`classify_corrected`].
pub fn classify_shell(
    volume: &CpuVolume,
    tf: &TransferFunction,
    min_opacity: f32,
    high: f32,
    length_ratio: f64,
) -> Result<Classified, GridError> {
    let [nx, ny, nz] = volume.dims.map(|n| n as usize);
    let alpha = |x: usize, y: usize, z: usize| {
        let value = volume
            .values
            .get(x + nx * (y + ny * z))
            .copied()
            .unwrap_or(f32::NAN);
        corrected_opacity(tf.sample(value)[3], length_ratio, 1.0)
    };
    classify_slices(volume, |id| {
        let (x, y, z) = (id % nx, id / nx % ny, id / (nx * ny));
        let [r, g, b, a] = tf.sample(*volume.values.get(id)?);
        let a = corrected_opacity(a, length_ratio, 1.0);
        if a <= min_opacity {
            return None;
        }
        let at_face = x == 0 || y == 0 || z == 0 || x + 1 == nx || y + 1 == ny || z + 1 == nz;
        let open = at_face
            || [
                alpha(x - 1, y, z),
                alpha(x + 1, y, z),
                alpha(x, y - 1, z),
                alpha(x, y + 1, z),
                alpha(x, y, z - 1),
                alpha(x, y, z + 1),
            ]
            .iter()
            .any(|&n| n <= high);
        open.then_some([r * a, g * a, b * a, a])
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_automatic_transfer_function_follows_the_values() {
        let ct: Vec<f32> = (0..1000).map(|i| -1024.0 + 3.0 * i as f32).collect();
        let auto = auto_transfer(&ct);
        assert!(
            auto.hounsfield && auto.reason.starts_with("ct-bone"),
            "{}",
            auto.reason
        );
        assert_eq!(auto.transfer, TransferFunction::ct_bone());
        // 8-bit data: most voxels background (0), the object spread over 1 to 200: the ramp
        // spans the 90th to 99.5th percentile of the object's values.
        let mut bytes = vec![0.0f32; 10_000];
        bytes.extend((1..=200).flat_map(|v| std::iter::repeat_n(v as f32, 10)));
        let auto = auto_transfer(&bytes);
        assert!(!auto.hounsfield);
        let points = auto.transfer.points();
        let (from, to) = (points[0].0, points[points.len() - 1].0);
        assert!(
            (from - 180.0).abs() < 1.0 && (to - 199.0).abs() < 1.0,
            "{from} to {to}"
        );
        assert!(auto.reason.contains("percentile"), "{}", auto.reason);
        // Constant or empty data still give a usable function.
        for values in [vec![7.0; 10], Vec::new(), vec![f32::NAN; 3]] {
            let auto = auto_transfer(&values);
            assert!(
                auto.transfer.points().iter().all(|(v, _)| v.is_finite()),
                "{values:?}"
            );
        }
        assert!(is_hounsfield(&[-600.0, 40.0]) && !is_hounsfield(&[0.0, 4000.0]));
    }
    use glam::DMat3;

    #[test]
    fn sample_interpolates_and_clamps() {
        let tf = TransferFunction::ramp(100.0, 200.0, [1.0, 0.5, 0.0, 0.8]);
        assert_eq!(tf.sample(50.0)[3], 0.0);
        assert!((tf.sample(150.0)[3] - 0.4).abs() < 1e-6);
        assert_eq!(tf.sample(500.0), [1.0, 0.5, 0.0, 0.8]);
        assert_eq!(tf.sample(f32::NAN)[3], 0.0);
    }

    #[test]
    fn presets_windows_and_shifts() {
        for name in TransferFunction::PRESETS {
            let tf = TransferFunction::preset(name).unwrap();
            assert!(tf.points().len() >= 2, "{name}");
            assert_eq!(tf.sample(-5000.0)[3], 0.0, "{name}: air is clear");
        }
        assert!(TransferFunction::preset("ct-lung").is_none());
        let bone = TransferFunction::ct_bone();
        assert_eq!(bone.shifted(100.0).sample(400.0), bone.sample(300.0));
        let w = bone.windowed(500.0, 1000.0);
        assert_eq!(
            (w.points()[0].0, w.points().last().unwrap().0),
            (0.0, 1000.0)
        );
        assert_eq!(w.sample(1000.0), bone.sample(1200.0));
        // The metal preset keeps bone faint and metal nearly opaque.
        let metal = TransferFunction::ct_metal();
        assert!(metal.sample(700.0)[3] < 0.1 && metal.sample(3000.0)[3] > 0.8);
    }

    #[test]
    fn the_length_ratio_follows_voxel_size_and_splat_size() {
        assert!((opacity_length_ratio([1.0; 3], REFERENCE_SIGMA, 1.0) - 1.0).abs() < 1e-12);
        assert!((opacity_length_ratio([2.0; 3], REFERENCE_SIGMA, 1.0) - 2.0).abs() < 1e-12);
        assert!((opacity_length_ratio([0.5, 0.5, 4.0], REFERENCE_SIGMA, 1.0) - 1.0).abs() < 1e-12);
        assert!(
            (opacity_length_ratio([1.0; 3], 1.4, 1.0) - 0.25).abs() < 1e-12,
            "twice the sigma"
        );
        assert_eq!(
            opacity_length_ratio([1.0; 3], 0.0, 1.0),
            1.0,
            "degenerate input changes nothing"
        );
    }

    #[test]
    fn opacity_correction_compounds_with_length() {
        assert_eq!(corrected_opacity(0.5, 1.0, 1.0), 0.5);
        assert!(
            (corrected_opacity(0.5, 2.0, 1.0) - 0.75).abs() < 1e-6,
            "two layers of 0.5"
        );
        assert!(
            (corrected_opacity(0.75, 0.5, 1.0) - 0.5).abs() < 1e-6,
            "half a layer"
        );
        assert_eq!(corrected_opacity(1.0, 0.3, 1.0), 1.0);
        assert_eq!(
            corrected_opacity(0.4, 0.0, 1.0),
            0.4,
            "no length, no change"
        );
    }

    #[test]
    fn the_shell_keeps_the_surface_of_an_opaque_block() {
        // A 6^3 grid with an opaque 4^3 block inside: its 2^3 core has only opaque neighbours.
        let values = (0..216u32)
            .map(|id| {
                let k = [id % 6, id / 6 % 6, id / 36];
                if k.iter().all(|&c| (1..=4).contains(&c)) {
                    1000.0
                } else {
                    0.0
                }
            })
            .collect();
        let volume = CpuVolume {
            dims: [6; 3],
            spacing: [1.0; 3],
            origin: [0.0; 3],
            direction: DMat3::IDENTITY,
            values,
        };
        let tf = TransferFunction::ramp(100.0, 200.0, [1.0; 4]);
        let full = classify(&volume, &tf, 0.0).unwrap();
        let shell = classify_shell(&volume, &tf, 0.0, 0.5, 1.0).unwrap();
        assert_eq!(full.grid.len(), 64);
        assert_eq!(shell.grid.len(), 64 - 8, "the 2x2x2 core is left out");
        let core = 2 + 6 * (2 + 6 * 2);
        assert!(full.grid.contains(core) && !shell.grid.contains(core));
        assert_eq!(shell.colors.len(), shell.grid.len());
        // With `high` at full opacity every visible voxel is on the shell.
        assert_eq!(
            classify_shell(&volume, &tf, 0.0, 1.0, 1.0)
                .unwrap()
                .grid
                .len(),
            64
        );
    }

    #[test]
    fn only_visible_voxels_become_splats() {
        let values = (0..24).map(|i| i as f32 * 10.0).collect();
        let volume = CpuVolume {
            dims: [2, 3, 4],
            spacing: [1.0; 3],
            origin: [0.0; 3],
            direction: DMat3::IDENTITY,
            values,
        };
        let classified = classify(
            &volume,
            &TransferFunction::ramp(100.0, 200.0, [1.0; 4]),
            0.0,
        )
        .unwrap();
        assert_eq!(
            classified.grid.ids().collect::<Vec<_>>(),
            (11..24).collect::<Vec<_>>()
        );
        assert_eq!(classified.colors.len(), 13);
        assert!((classified.colors[0][3] - 0.1).abs() < 1e-6);
        assert!(
            (classified.colors[0][0] - 0.1).abs() < 1e-6,
            "premultiplied"
        );
    }
}
