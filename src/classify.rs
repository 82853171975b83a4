//! Classification: a transfer function turns scalar values into colour and opacity, and only
//! voxels that are not (nearly) transparent become splats.

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

/// The significant voxels of a volume with their premultiplied colours (index = rank).
#[derive(Debug, Clone)]
pub struct Classified {
    /// Significant voxels.
    pub grid: SparseGrid,
    /// Premultiplied RGBA per significant voxel, in id order.
    pub colors: Vec<[f32; 4]>,
}

/// Classifies every voxel; those with opacity at or below `min_opacity` are left out.
pub fn classify(
    volume: &CpuVolume,
    tf: &TransferFunction,
    min_opacity: f32,
) -> Result<Classified, GridError> {
    let mut colors = Vec::new();
    let grid = SparseGrid::from_mask(volume.dims, |id| {
        let Some(&value) = volume.values.get(id as usize) else {
            return false;
        };
        let [r, g, b, a] = tf.sample(value);
        let keep = a > min_opacity;
        if keep {
            colors.push([r * a, g * a, b * a, a]);
        }
        keep
    })?;
    Ok(Classified { grid, colors })
}

#[cfg(test)]
mod tests {
    use super::*;
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
