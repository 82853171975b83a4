//! Classification: a transfer function turns scalar values into colour and opacity, and only
//! voxels that are not (nearly) transparent become splats.

use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering as AtomicOrdering};

use crate::grid::{BitsPart, GridError, SparseGrid};
use crate::volume::voxels::dispatch;
use crate::volume::{CpuVolume, Voxel, Voxels};

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

    // The presets' opacities are per millimetre of tissue. They were first tuned as opacities
    // per splat of 1 mm voxels (Gaussians of 0.7 voxels, whose layer carries 2 pi 0.7^2 = 3.08
    // times a splat's optical depth); each is that look per millimetre,
    // `1 - (1 - a)^3.08`, so that a CT of about 1 mm voxels looks as it did, and any other grid
    // alike.

    /// CT bone in Hounsfield units: transparent below 150 HU, cancellous bone faint and warm,
    /// cortical bone near-white and dense.
    pub fn ct_bone() -> Self {
        Self::new(vec![
            (150.0, [0.8, 0.55, 0.45, 0.0]),
            (300.0, [0.9, 0.7, 0.55, 0.325]),
            (700.0, [0.95, 0.88, 0.78, 0.84]),
            (1200.0, [1.0, 0.97, 0.92, 0.993]),
        ])
    }

    /// CT soft tissue with bone: faint skin and muscle (about -100 to 100 HU) under bone.
    pub fn ct_soft_tissue() -> Self {
        Self::new(vec![
            (-250.0, [0.75, 0.45, 0.35, 0.0]),
            (-50.0, [0.8, 0.5, 0.4, 0.046]),
            (100.0, [0.85, 0.55, 0.45, 0.09]),
            (200.0, [0.9, 0.75, 0.6, 0.174]),
            (700.0, [0.96, 0.9, 0.82, 0.882]),
            (1200.0, [1.0, 0.97, 0.92, 0.993]),
        ])
    }

    /// CT metal implants: bone faint, and the very dense values of metal (from about 2000 HU,
    /// stent-grafts, stems, screws) bright and nearly opaque, in a cool tint.
    pub fn ct_metal() -> Self {
        Self::new(vec![
            (300.0, [0.9, 0.8, 0.7, 0.0]),
            (1000.0, [0.95, 0.9, 0.85, 0.226]),
            (1800.0, [0.8, 0.85, 0.95, 0.277]),
            (2500.0, [0.75, 0.85, 1.0, 0.999]),
        ])
    }

    /// An MR default: a grey ramp over the upper part of a 0 to 1000 intensity range.
    pub fn mr_default() -> Self {
        Self::new(vec![
            (150.0, [0.8, 0.8, 0.8, 0.0]),
            (500.0, [0.9, 0.88, 0.85, 0.666]),
            (1000.0, [1.0, 1.0, 1.0, 0.975]),
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
/// 4096 bins, one pass over the values.
pub fn auto_transfer(values: &Voxels) -> AutoTransfer {
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
pub fn is_hounsfield(values: &Voxels) -> bool {
    let (lo, hi) = finite_range(values);
    lo <= HU_AIR && hi > 0.0
}

/// The window a slice of `volume` is drawn with when none is given: a bone window (-500 to
/// 1500 HU, window 2000 at level 500, which shows cortical and cancellous bone apart and soft
/// tissue dark) for CT, the values' whole range for other data.
pub fn default_window(volume: &crate::volume::CpuVolume) -> [f32; 2] {
    if is_hounsfield(&volume.values) {
        return [-500.0, 1500.0];
    }
    let (lo, hi) = finite_range(&volume.values);
    if lo < hi {
        [lo, hi]
    } else if lo.is_finite() {
        [lo - 0.5, lo + 0.5]
    } else {
        [0.0, 1.0]
    }
}

/// The least and greatest finite values (infinite, reversed, where there are none).
pub fn finite_range(values: &Voxels) -> (f32, f32) {
    values
        .par_chunks(1 << 16, |chunk| {
            chunk
                .iter()
                .filter(|v| v.is_finite())
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
                    (lo.min(v), hi.max(v))
                })
        })
        .into_iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |a, b| {
            (a.0.min(b.0), a.1.max(b.1))
        })
}

/// Two quantiles of the finite values above `lo` (`lo` and `hi` their range), from a histogram.
fn percentiles_above_min(values: &Voxels, lo: f32, hi: f32, a: f64, b: f64) -> (f32, f32) {
    match Histogram::over(values, lo, hi) {
        Some(h) => (h.quantile(a), h.quantile(b)),
        None => (lo.min(0.0), hi.max(1.0)),
    }
}

/// How many of a volume's finite values above their least fall in each of 4096 equal bins over
/// their range (the least left out: it is most often the background around the scan). The
/// automatic transfer function, the viewer's ramps for data that are no Hounsfield units and
/// the histogram under its window come from it.
#[derive(Debug, Clone, PartialEq)]
pub struct Histogram {
    /// The least finite value.
    pub lo: f32,
    /// The greatest finite value.
    pub hi: f32,
    /// The count in each bin, the first starting at `lo`.
    pub counts: Vec<u64>,
}

impl Histogram {
    /// The histogram of `values`; `None` where they hold fewer than two distinct finite values.
    pub fn of(values: &Voxels) -> Option<Self> {
        let (lo, hi) = finite_range(values);
        Self::over(values, lo, hi)
    }

    /// The histogram of `values` whose finite range is `lo` to `hi`.
    fn over(values: &Voxels, lo: f32, hi: f32) -> Option<Self> {
        if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
            return None;
        }
        let width = f64::from(hi) - f64::from(lo);
        let bin = |v: f32| {
            let t = (f64::from(v) - f64::from(lo)) / width;
            ((t * HISTOGRAM_BINS as f64) as usize).min(HISTOGRAM_BINS - 1)
        };
        // Runs of a million values: a histogram each, a few hundred for the largest volumes.
        let counts = values
            .par_chunks(1 << 20, |chunk| {
                let mut h = vec![0u64; HISTOGRAM_BINS];
                for &v in chunk.iter().filter(|v| v.is_finite() && **v > lo) {
                    h[bin(v)] += 1;
                }
                h
            })
            .into_iter()
            .fold(vec![0u64; HISTOGRAM_BINS], |mut x, y| {
                x.iter_mut().zip(&y).for_each(|(x, y)| *x += y);
                x
            });
        Some(Self { lo, hi, counts })
    }

    /// The value below which the fraction `q` of the counted values lie, to the middle of
    /// its bin.
    pub fn quantile(&self, q: f64) -> f32 {
        let total: u64 = self.counts.iter().sum();
        let wanted = (q * total as f64).ceil() as u64;
        let mut seen = 0;
        let i = self
            .counts
            .iter()
            .position(|&n| {
                seen += n;
                seen >= wanted.max(1)
            })
            .unwrap_or(self.counts.len() - 1);
        let width = f64::from(self.hi) - f64::from(self.lo);
        (f64::from(self.lo) + width * (i as f64 + 0.5) / self.counts.len() as f64) as f32
    }

    /// The counts gathered into `n` bins over the same range (for drawing).
    pub fn coarse(&self, n: usize) -> Vec<u64> {
        let n = n.max(1);
        let mut out = vec![0u64; n];
        for (i, c) in self.counts.iter().enumerate() {
            out[i * n / self.counts.len()] += c;
        }
        out
    }
}

/// A splat's colour as every compositor reads it: the transfer function's straight colour in
/// 8 bits a channel, and its density in half precision (see [`Opacity`]). Five bytes a splat,
/// packed: a classification holds one for each significant voxel (41M, 206 MB, for the
/// 0.75 mm abdomen CT with a window of soft tissue, where the 2-byte alignment of the density
/// would make them six).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C, packed)]
pub struct SplatColor {
    /// Straight (not premultiplied) red, green and blue.
    pub rgb: [u8; 3],
    /// The peak optical depth the splat puts on a ray through its centre, per millimetre that
    /// one index step along the ray spans: its opacity in a view is
    /// [`splat_alpha`]`(density, step_mm)` with `step_mm` from [`view_step_mm`].
    pub density: half::f16,
}

impl SplatColor {
    /// Premultiplied RGBA in a view whose index step spans `step_mm` millimetres.
    pub fn premultiplied(&self, step_mm: f32) -> [f32; 4] {
        let a = splat_alpha(self.density.to_f32(), step_mm);
        let [r, g, b] = self.rgb.map(|v| f32::from(v) / 255.0 * a);
        [r, g, b, a]
    }
}

/// The significant voxels of a volume with their colours (index = rank).
#[derive(Debug, Clone)]
pub struct Classified {
    /// Significant voxels.
    pub grid: SparseGrid,
    /// Colour and density per significant voxel, in id order.
    pub colors: Vec<SplatColor>,
}

impl Classified {
    /// Premultiplied RGBA per significant voxel in a view whose index step spans `step_mm`
    /// millimetres (the colours the CPU reference compositor takes).
    pub fn premultiplied(&self, step_mm: f32) -> Vec<[f32; 4]> {
        self.colors
            .iter()
            .map(|c| c.premultiplied(step_mm))
            .collect()
    }

    /// This classification and `other`, a classification of the same grid's other voxels
    /// (those of a [`Region`] this one left out, say): the significant voxels of both, each
    /// with its own colour. Classifying a region and then the bricks a later view adds gives
    /// what classifying the two regions at once gives, voxel for voxel, since a voxel's
    /// colour does not depend on the region it was classified within. Refused
    /// ([`GridError::NotDisjoint`]) where the grids differ in size or share a voxel, and
    /// ([`GridError::ColorsMismatch`]) where either holds other than a colour a voxel.
    pub fn joined_with(&self, other: Classified) -> Result<Self, GridError> {
        for c in [self, &other] {
            if c.colors.len() != c.grid.len() {
                return Err(GridError::ColorsMismatch {
                    colors: c.colors.len(),
                    voxels: c.grid.len(),
                });
            }
        }
        let grid = self.grid.joined_with(&other.grid)?;
        let mut colors = Vec::with_capacity(self.colors.len() + other.colors.len());
        let (mut i, mut j) = (0usize, 0usize);
        // Word by word: a word with voxels of one side only takes its colours as a stretch.
        for (a, b) in self.grid.word_pairs(&other.grid) {
            if b == 0 {
                let n = a.count_ones() as usize;
                colors.extend_from_slice(&self.colors[i..i + n]);
                i += n;
            } else if a == 0 {
                let n = b.count_ones() as usize;
                colors.extend_from_slice(&other.colors[j..j + n]);
                j += n;
            } else {
                let mut both = a | b;
                while both != 0 {
                    let bit = both & both.wrapping_neg();
                    if a & bit != 0 {
                        colors.push(self.colors[i]);
                        i += 1;
                    } else {
                        colors.push(other.colors[j]);
                        j += 1;
                    }
                    both ^= bit;
                }
            }
        }
        Ok(Self { grid, colors })
    }

    /// The significant voxels of a `dims` grid and their colours from per-slice lists, the
    /// slices in increasing id order.
    fn joined(dims: [u32; 3], parts: Vec<(BitsPart, Vec<SplatColor>)>) -> Result<Self, GridError> {
        for (bits, c) in &parts {
            if bits.len() != c.len() {
                return Err(GridError::ColorsMismatch {
                    colors: c.len(),
                    voxels: bits.len(),
                });
            }
        }
        let (bits, parts): (Vec<BitsPart>, Vec<Vec<SplatColor>>) = parts.into_iter().unzip();
        let grid = SparseGrid::from_bit_parts(dims, bits)?;
        // The colours laid end to end, each part's freed as it is taken: the whole list's
        // room is reserved at once, and its pages are touched only as they are written, so
        // that the colours are held about once, not twice.
        let mut colors = Vec::with_capacity(parts.iter().map(Vec::len).sum());
        for c in parts {
            colors.extend_from_slice(&c);
        }
        Ok(Self { grid, colors })
    }

    /// The next level of detail: each block of 2 x 2 x 2 voxels (fewer at an odd grid's far
    /// faces, and none along an axis of one voxel) becomes one splat, on the grid
    /// [`CpuVolume::halved`] makes. Its density is the mean of the block's densities (the
    /// block's mean extinction: a voxel twice as long then absorbs what its children did
    /// together) and its colour their colours weighted by density, so a ray through the block
    /// meets the same optical depth and emission. A block with no significant voxel is left
    /// out.
    pub fn halved(&self) -> Result<Classified, GridError> {
        self.halved_along([true; 3], None)
    }

    /// [`Classified::halved`] along the `axes` given alone: each block of 2 voxels along each
    /// of them (1 along the others) becomes one splat, on a grid of half as many voxels along
    /// them. An axis of one voxel is not halved.
    ///
    /// With a `front` along the one axis halved (ignored otherwise), that axis runs along the
    /// view direction, and the pair of voxels along it that a ray crosses one after the other
    /// are weighted as the ray composites them: the nearer by its opacity, the farther by its
    /// opacity times what the nearer lets through. The splat then shows the colour of a
    /// surface's first voxel, not a mean that the denser voxels behind it dominate. Its
    /// density is the pair's mean either way.
    pub fn halved_along(
        &self,
        axes: [bool; 3],
        front: Option<Front>,
    ) -> Result<Classified, GridError> {
        Ok(self.halved_measured(axes, front, None)?.0)
    }

    /// [`Classified::halved_along`], with what each splat of the level loses of its block:
    /// where `spread_mm` is given, per splat (in id order) the mean over the block's voxels
    /// of the squared distance between a voxel's premultiplied RGBA and the block's mean
    /// (the voxels of the block without a splat counting as clear), each voxel's opacity
    /// that of `spread_mm` millimetres of its tissue. It is the energy of the block's Haar
    /// details in the colours a ray meets: nothing where the block's voxels look alike, 1
    /// where half of them are opaque white and half clear.
    pub fn halved_measured(
        &self,
        axes: [bool; 3],
        front: Option<Front>,
        spread_mm: Option<f32>,
    ) -> Result<(Classified, Vec<f32>), GridError> {
        self.halved_unless_cancelled(axes, front, spread_mm, None)
    }

    /// [`Classified::halved_measured`], giving up with [`GridError::Cancelled`] once `cancel`
    /// is raised, looked at between output z-slices (a viewer's frame making a level of a
    /// thin-slice CT takes a few hundred milliseconds, and a drag meanwhile wants the cores).
    pub fn halved_unless_cancelled(
        &self,
        axes: [bool; 3],
        front: Option<Front>,
        spread_mm: Option<f32>,
        cancel: Option<&AtomicBool>,
    ) -> Result<(Classified, Vec<f32>), GridError> {
        let dims = self.grid.dims();
        let step: [u32; 3] = std::array::from_fn(|a| if axes[a] && dims[a] > 1 { 2 } else { 1 });
        // A front along the one axis halved; else none.
        let front = front.filter(|f| f.axis < 3 && (0..3).all(|a| (step[a] == 2) == (a == f.axis)));
        let out: [u32; 3] = std::array::from_fn(|a| dims[a].div_ceil(step[a]));
        let [ox, oy, oz] = out.map(|n| n as usize);
        // Opaque voxels (infinite density) count as the largest half, still opaque over any
        // step.
        let density = |d: half::f16| d.to_f32().min(65504.0);
        // A voxel's opacity along the front by the bits of its density, tabulated once (the
        // same expression for every value) rather than an exponential a voxel.
        let alphas: Vec<f32> = match front {
            Some(f) => (0..=u16::MAX)
                .map(|bits| f.alpha(density(half::f16::from_bits(bits))))
                .collect(),
            None => Vec::new(),
        };
        let alpha = |d: half::f16| alphas.get(usize::from(d.to_bits())).copied().unwrap_or(0.0);
        // Each voxel's opacity over `spread_mm`, tabulated as above.
        let spread_alphas: Vec<f32> = match spread_mm {
            Some(mm) => (0..=u16::MAX)
                .map(|bits| splat_alpha(density(half::f16::from_bits(bits)), mm))
                .collect(),
            None => Vec::new(),
        };
        let spread_alpha = |d: half::f16| {
            spread_alphas
                .get(usize::from(d.to_bits()))
                .copied()
                .unwrap_or(0.0)
        };
        // The x rows are read from every task below: made first, not by the first task.
        self.grid.prepare_rows(0);
        let parts = crate::cancel::Parts::new(cancel);
        let slices: Vec<(BitsPart, Vec<SplatColor>, Vec<f32>)> = (0..oz)
            .into_par_iter()
            .map(|k| {
                let (mut ids, mut colors, mut spreads) =
                    (BitsPart::default(), Vec::new(), Vec::new());
                // What a cancelled halving made is dropped whole below.
                if parts.skip() {
                    return (ids, colors, spreads);
                }
                // Per output voxel of the row: the density, and the weight and weighted colour
                // of its voxels (with a front, of its nearer voxel, then of its farther).
                let mut sums = vec![Pair::default(); ox];
                // With `spread_mm`, per output voxel of the row: the sum of its voxels'
                // premultiplied RGBA, and of their squared lengths.
                let mut spread_sums = vec![[0f64; 5]; if spread_mm.is_some() { ox } else { 0 }];
                for j in 0..oy {
                    // The slots this row touched, the only ones to emit and clear again: a
                    // whole row's slots (72 bytes each) cleared for every row came to 5 GB
                    // of writes on the 0.7 mm LIDC2 grid, most of whose rows hold few blocks.
                    let (mut lo, mut hi) = (ox, 0);
                    for z in (k as u32 * step[2]..(k as u32 + 1) * step[2]).filter(|&z| z < dims[2])
                    {
                        for y in
                            (j as u32 * step[1]..(j as u32 + 1) * step[1]).filter(|&y| y < dims[1])
                        {
                            for run in self.grid.row(0, y, z) {
                                let first = run.start + dims[0] * (y + dims[1] * z);
                                let Some(rank) = self.grid.rank(first) else {
                                    continue;
                                };
                                lo = lo.min((run.start / step[0]) as usize);
                                hi = hi.max(((run.end() - 1) / step[0]) as usize + 1);
                                for (i, x) in (run.start..run.end()).enumerate() {
                                    let c = &self.colors[rank as usize + i];
                                    let d = density(c.density);
                                    if let Some(s) = spread_sums.get_mut((x / step[0]) as usize) {
                                        let a = f64::from(spread_alpha(c.density));
                                        let p = c.rgb.map(|v| a * f64::from(v) / 255.0);
                                        for (sum, v) in s.iter_mut().zip([p[0], p[1], p[2], a]) {
                                            *sum += v;
                                        }
                                        s[4] += p.iter().map(|v| v * v).sum::<f64>() + a * a;
                                    }
                                    let slot = &mut sums[(x / step[0]) as usize];
                                    slot.density += f64::from(d);
                                    let (w, part) = match front {
                                        None => (f64::from(d), &mut slot.near),
                                        Some(f) if f.is_nearer([x, y, z]) => {
                                            (f64::from(alpha(c.density)), &mut slot.near)
                                        }
                                        Some(_) => (f64::from(alpha(c.density)), &mut slot.far),
                                    };
                                    part.0 += w;
                                    for (sum, v) in part.1.iter_mut().zip(c.rgb) {
                                        *sum += w * f64::from(v);
                                    }
                                }
                            }
                        }
                    }
                    if lo >= hi {
                        continue;
                    }
                    for (i, pair) in sums.iter().enumerate().take(hi).skip(lo) {
                        if pair.density <= 0.0 {
                            continue;
                        }
                        // The block's voxels inside the grid.
                        let count: u32 = (0..3)
                            .map(|a| {
                                let c = [i, j, k][a] as u32;
                                ((c + 1) * step[a]).min(dims[a]) - c * step[a]
                            })
                            .product();
                        ids.push((i + ox * (j + oy * k)) as u32);
                        colors.push(SplatColor {
                            rgb: pair.color(),
                            density: half::f16::from_f64(pair.density / f64::from(count)),
                        });
                        if let Some(s) = spread_sums.get(i) {
                            // Mean squared length less the squared mean, over the block.
                            let n = f64::from(count);
                            let mean_sq: f64 = s[..4].iter().map(|v| (v / n) * (v / n)).sum();
                            spreads.push((s[4] / n - mean_sq).max(0.0) as f32);
                        }
                    }
                    sums[lo..hi].fill(Pair::default());
                    if let Some(s) = spread_sums.get_mut(lo..hi) {
                        s.fill([0.0; 5]);
                    }
                }
                ids.shrink_to_fit();
                colors.shrink_to_fit();
                spreads.shrink_to_fit();
                (ids, colors, spreads)
            })
            .collect();
        let Some(slices) = parts.whole(slices) else {
            return Err(GridError::Cancelled);
        };
        let mut spreads = Vec::new();
        let parts = slices
            .into_iter()
            .map(|(ids, colors, s)| {
                spreads.extend_from_slice(&s);
                (ids, colors)
            })
            .collect();
        Ok((Self::joined(out, parts)?, spreads))
    }
}

/// A block of voxels becoming one splat ([`Classified::halved_along`]): its density summed,
/// and the weight and weighted colour of its voxels, those of the nearer voxel and of the
/// farther one apart where the block is a pair along the view.
#[derive(Debug, Clone, Copy, Default)]
struct Pair {
    density: f64,
    near: (f64, [f64; 3]),
    far: (f64, [f64; 3]),
}

impl Pair {
    /// The block's colour: the nearer voxel's over the farther one's, their weights their
    /// opacities (`near` holds every voxel of a block weighted by density, `far` none).
    fn color(&self) -> [u8; 3] {
        let through = 1.0 - self.near.0.min(1.0);
        let weight = self.near.0 + through * self.far.0;
        if weight.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return [0; 3];
        }
        std::array::from_fn(|c| {
            ((self.near.1[c] + through * self.far.1[c]) / weight)
                .round()
                .clamp(0.0, 255.0) as u8
        })
    }
}

/// The view direction a level of detail is halved along ([`Classified::halved_along`]): which
/// voxel of each pair along the axis a ray meets first, and how opaque a voxel is along it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Front {
    /// The axis halved along the view direction (0, 1 or 2).
    pub axis: usize,
    /// Whether the voxel of the larger index along it lies nearer the eye.
    pub larger_nearer: bool,
    /// The length in millimetres of one index step along the axis, for the voxels' opacities
    /// ([`splat_alpha`]).
    pub step_mm: f32,
}

impl Front {
    /// Whether voxel `k` is the nearer of its pair along the axis (pairs start at even
    /// indices).
    pub fn is_nearer(&self, k: [u32; 3]) -> bool {
        (k[self.axis] % 2 == 1) == self.larger_nearer
    }

    /// The opacity along the axis of a voxel of density `density`.
    pub fn alpha(&self, density: f32) -> f32 {
        splat_alpha(density, self.step_mm)
    }
}

/// What a transfer function's opacity means, and the splats that carry it.
///
/// The volume is the emission-absorption integral of the continuous field the splats
/// reconstruct: each voxel's Gaussian (standard deviation `sigma` voxels along every index
/// axis) weighted by its extinction, normalised so that the Gaussians of a grid sum to one
/// everywhere (their sum is `(2 pi sigma^2)^(3/2)` for `sigma` above about half a voxel). An
/// opacity `a` of the transfer function is the opacity of `reference_mm` millimetres of that
/// tissue: extinction `-ln(1 - a) / reference_mm` per millimetre, as VTK's scalar opacity unit
/// distance defines it. A ray through a splat's centre then meets the optical depth
/// `extinction * step_mm / (2 pi sigma^2 kept)`, where `step_mm` is the length of one index
/// step along the ray (a finer grid: shorter steps, more splats, the same total) and `kept` the
/// share of the footprint's integral inside the cut-off. So the picture does not depend on the
/// grid, only on the tissue.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Opacity {
    /// Millimetres of tissue the transfer function's opacities hold for (VTK's unit distance).
    pub reference_mm: f64,
    /// The splats' standard deviation, in voxels.
    pub sigma: f64,
    /// Where the footprint is cut off, in voxels from the centre.
    pub cutoff: f64,
}

/// The splats' default standard deviation, in voxels. Smaller than the original
/// ShellSplatting's 0.7: on the LIDC2 chest CT at 512 x 512 (soft-tissue and bone ramps, front
/// view) 0.55 brings the splats nearer the reference ray marcher's trilinear picture (RMSE
/// 0.024 against 0.026 on the 0.7 mm grid, 0.049 to 0.053 against 0.056 to 0.058 on the 1.4 x
/// 1.4 x 2.5 mm one), while the Gaussians of a grid still sum to one within 0.5% (the ripple
/// of a lattice of Gaussians is about `2 exp(-2 pi^2 sigma^2)` an axis).
pub const DEFAULT_SIGMA: f64 = 0.55;
/// Where the default splat's footprint is cut off, in voxels from its centre (2.9 sigma).
pub const DEFAULT_CUTOFF: f64 = 1.6;

impl Default for Opacity {
    /// Opacity per millimetre, splats of the default style ([`DEFAULT_SIGMA`],
    /// [`DEFAULT_CUTOFF`]).
    fn default() -> Self {
        Self {
            reference_mm: 1.0,
            sigma: DEFAULT_SIGMA,
            cutoff: DEFAULT_CUTOFF,
        }
    }
}

impl Opacity {
    /// Density per unit of extinction (per millimetre): `1 / (reference_mm 2 pi sigma^2 kept)`.
    fn scale(&self) -> f64 {
        let kept = 1.0 - (-0.5 * (self.cutoff / self.sigma).powi(2)).exp();
        let scale =
            1.0 / (self.reference_mm * std::f64::consts::TAU * self.sigma * self.sigma * kept);
        if scale.is_finite() && scale > 0.0 {
            scale
        } else {
            0.0
        }
    }

    /// The density of a splat whose cell has the transfer-function opacity `alpha` throughout
    /// (see [`SplatColor`]): its [`extinction`] times `1 / (reference_mm 2 pi sigma^2 kept)`.
    pub fn density(&self, alpha: f32) -> f32 {
        (extinction(alpha) * self.scale()) as f32
    }
}

/// `-ln(1 - a)` for an opacity `a` (accurate for small `a`), capped at [`MAX_DEPTH`] so that
/// opaque tissue has a finite extinction to average; 0 for `a` at or below 0 and for NaN.
pub fn extinction(alpha: f32) -> f64 {
    if alpha.is_nan() || alpha <= 0.0 {
        return 0.0;
    }
    (-(-f64::from(alpha.min(1.0))).ln_1p()).min(MAX_DEPTH)
}

/// A splat's opacity in a view: `1 - exp(-density step_mm)`.
pub fn splat_alpha(density: f32, step_mm: f32) -> f32 {
    let depth = density * step_mm;
    if depth.is_nan() || depth <= 0.0 {
        return 0.0;
    }
    -(-depth).exp_m1()
}

/// The length in millimetres of one index step along the view direction `forward` (world):
/// `1 / |L^-1 forward|` for the volume's index-to-world matrix `L`. A volume of voxels
/// 1.4 x 1.4 x 2.5 mm seen along its x axis steps 1.4 mm, along z 2.5 mm. Perspective views use
/// the central ray's direction for every splat. `None` where `L` is singular or `forward` is
/// zero or not finite.
pub fn view_step_mm(index_to_world: glam::DMat3, forward: glam::DVec3) -> Option<f64> {
    if index_to_world.determinant().abs() < f64::MIN_POSITIVE || !forward.is_finite() {
        return None;
    }
    let forward = forward.try_normalize()?;
    let per_mm = (index_to_world.inverse() * forward).length();
    let step = 1.0 / per_mm;
    (step.is_finite() && step > 0.0).then_some(step)
}

/// The unit index-space gradient of `volume` at voxel `k`, pointing from dense to less dense
/// (outward on bone surfaces), by central differences (one-sided at the faces), as snorm8.
/// Where those are all zero inside the grid, the differences summed over the 3 x 3 rows of
/// the voxel's neighbourhood along each axis instead; `None` where these are zero too. Never
/// all three zero otherwise: a unit vector has a component of at least 1/sqrt(3).
///
/// The splat stands for the field over its footprint, about its 3 x 3 x 3 neighbourhood.
/// Integer-valued CT has many voxels whose six neighbours are pairwise equal though the
/// field around them slopes: 26% of the significant voxels of the Stanford CT head resampled
/// to 0.5 mm and stored as u8, in its soft-tissue window (60-190), against 16% of a ray
/// caster's samples of its trilinear field there. A voxel with no gradient is drawn unshaded,
/// fully lit, so the translucent picture came out brighter than the ray caster's. The
/// neighbourhood's differences leave 15% of the voxels without one (of its middle 200
/// slices).
pub fn gradient_snorm8(volume: &CpuVolume, k: [u32; 3]) -> Option<[u8; 3]> {
    let g = differences(volume, k);
    if g == glam::Vec3::ZERO {
        return snorm8(-neighbourhood_differences(volume, k));
    }
    snorm8(-g)
}

/// The unit index-space gradient at voxel `k` of the grid `factors` times finer than
/// `volume`'s ([`classify_refined`]), as [`gradient_snorm8`] in the fine grid's index space:
/// the gradient of the volume's trilinear field at the fine voxel's centre, by central
/// differences half a fine voxel either side. Within one cell of the volume the field is
/// linear along each axis, so these are its exact slope there; where the fine centre is a
/// voxel of the volume (odd factors) they are the mean of the slopes either side, the
/// volume's own central difference. One fine voxel either side would reach into the next
/// cell on even factors and blend its slope in, shading the refined grid as a smoother field
/// than the one drawn (BENCHMARKS.md, "The reference's gradient at one distance on every
/// grid"). The volume's own gradient where every factor is 1.
pub fn refined_gradient_snorm8(
    volume: &CpuVolume,
    factors: [u32; 3],
    k: [u32; 3],
) -> Option<[u8; 3]> {
    if factors == [1, 1, 1] {
        return gradient_snorm8(volume, k);
    }
    let n = volume.dims.map(|d| d.max(1) as usize);
    let places = std::array::from_fn(|a| FinePlace::new(n[a], factors[a], k[a]));
    let g = dispatch!(&volume.values, values => refined_differences_in(values, n, &places));
    snorm8(-g)
}

/// [`refined_gradient_snorm8`] for every voxel of one refined grid, with where each fine
/// index lies along each axis worked out once (a frame's texels ask for tens of millions).
#[derive(Debug)]
pub struct RefinedGradients<V = std::sync::Arc<CpuVolume>> {
    volume: V,
    factors: [u32; 3],
    /// Per axis, per fine index along it.
    places: [Vec<FinePlace>; 3],
}

impl<V: std::ops::Deref<Target = CpuVolume>> RefinedGradients<V> {
    /// The gradients of `volume`'s field on its grid refined by `factors` (`volume` held as
    /// given: a reference, or an `Arc` for gradients asked for later).
    pub fn new(volume: V, factors: [u32; 3]) -> Self {
        let n = volume.dims.map(|d| d.max(1) as usize);
        let places = std::array::from_fn(|a| {
            if factors == [1, 1, 1] {
                return Vec::new();
            }
            (0..volume.dims[a].saturating_mul(factors[a]))
                .map(|k| FinePlace::new(n[a], factors[a], k))
                .collect()
        });
        Self {
            volume,
            factors,
            places,
        }
    }

    /// Whether `other` gives the same gradients: the same volume, refined by the same factors.
    pub fn same_field(&self, other: &Self) -> bool {
        std::ptr::eq(&*self.volume, &*other.volume) && self.factors == other.factors
    }

    /// [`refined_gradient_snorm8`] at fine voxel `k`.
    pub fn snorm8(&self, k: [u32; 3]) -> Option<[u8; 3]> {
        if self.factors == [1, 1, 1] {
            return gradient_snorm8(&self.volume, k);
        }
        let places = [0, 1, 2].map(|a| self.places[a].get(k[a] as usize));
        let [Some(x), Some(y), Some(z)] = places else {
            return None;
        };
        let n = self.volume.dims.map(|d| d.max(1) as usize);
        let places = [*x, *y, *z];
        let g =
            dispatch!(&self.volume.values, values => refined_differences_in(values, n, &places));
        snorm8(-g)
    }
}

/// Where one fine voxel lies along one axis of the coarse grid it refines: the coarse cell
/// its centre falls in and the weight of the cell's upper voxel there, and the cells its
/// extent overlaps (at most two) with the length of each overlap, in coarse voxels; all
/// clamped to the grid's outer voxel centres as [`CpuVolume::trilinear`] clamps.
#[derive(Debug, Clone, Copy)]
struct FinePlace {
    lower: u32,
    upper: u32,
    t: f32,
    spans: [(u32, f32); 2],
}

impl FinePlace {
    /// Fine voxel `k` of the `f` a coarse voxel splits into along an axis of `n` voxels.
    fn new(n: usize, f: u32, k: u32) -> Self {
        let f = f64::from(f.max(1));
        let last = (n.max(1) - 1) as f64;
        // Non-negative once clamped, so the truncation is the floor.
        let c = ((f64::from(k) + 0.5) / f - 0.5).clamp(0.0, last);
        let lower = (c as usize).min(n.max(1) - 1);
        let upper = (lower + 1).min(n.max(1) - 1);
        let mut spans = [(0u32, 0.0f32); 2];
        if n >= 2 {
            let lo = (f64::from(k) / f - 0.5).clamp(0.0, last);
            let hi = ((f64::from(k) + 1.0) / f - 0.5).clamp(0.0, last);
            // The extent is at most a voxel long: two cells at most.
            let mut from = lo;
            for span in &mut spans {
                if from >= hi {
                    break;
                }
                let j = (from as usize).min(n - 2);
                let to = hi.min((j + 1) as f64);
                *span = (j as u32, (to - from) as f32);
                from = to;
            }
        }
        Self {
            lower: lower as u32,
            upper: upper as u32,
            t: (c - lower as f64) as f32,
            spans,
        }
    }
}

/// The trilinear field of `values` (a grid of `n` voxels a side, x fastest) across a fine
/// voxel placed along each axis as `places` says: its value at the fine voxel's upper face
/// less its value at the lower, at the fine centre across the other two axes, the field
/// clamped at the grid's outer voxel centres as [`CpuVolume::trilinear`] clamps it. Taken as
/// the slopes of the cells the fine voxel's extent overlaps, each the bilinear mean across the
/// other axes of its four edges' differences, weighted by the overlap: the same number as two
/// trilinear samples' difference, from fewer loads and with the value type matched once, not
/// once a load. Zero where `values` is shorter than the grid.
fn refined_differences_in<T: Voxel>(
    values: &[T],
    n: [usize; 3],
    places: &[FinePlace; 3],
) -> glam::Vec3 {
    if values.len() < n[0] * n[1] * n[2] {
        return glam::Vec3::ZERO;
    }
    let strides = [1, n[0], n[0] * n[1]];
    let g: [f32; 3] = std::array::from_fn(|a| {
        let (b, c) = ((a + 1) % 3, (a + 2) % 3);
        let (pb, pc) = (&places[b], &places[c]);
        let [bl, bu, cl, cu] = [pb.lower, pb.upper, pc.lower, pc.upper].map(|v| v as usize);
        let mut sum = 0.0f32;
        for &(j, length) in &places[a].spans {
            if length == 0.0 {
                continue;
            }
            // Cell `j`'s slope (voxel j to j + 1 along `a`) at the centre across b and c.
            let (lo, hi) = (j as usize * strides[a], (j as usize + 1) * strides[a]);
            let edge = |ib: usize, ic: usize| {
                let base = ib * strides[b] + ic * strides[c];
                values[base + hi].to_f32() - values[base + lo].to_f32()
            };
            let near = edge(bl, cl) + pb.t * (edge(bu, cl) - edge(bl, cl));
            let far = edge(bl, cu) + pb.t * (edge(bu, cu) - edge(bl, cu));
            sum += length * (near + pc.t * (far - near));
        }
        sum
    });
    glam::Vec3::from(g)
}

/// A direction as snorm8 once made unit length; `None` for a zero or non-finite one.
pub(crate) fn snorm8(v: glam::Vec3) -> Option<[u8; 3]> {
    let n = v.try_normalize()?;
    // Rounded half away from zero as `round` does, without its library call on the x86-64
    // baseline: every component lies in [-1, 1].
    let q = |v: f32| {
        let r = v * 127.0;
        (r + 0.5f32.copysign(r)) as i8 as u8
    };
    Some([q(n.x), q(n.y), q(n.z)])
}

/// The index-space gradient of `volume` at voxel `k` by central differences (one-sided at the
/// faces; 0 along an axis of one voxel; 0 for a voxel past the values).
fn differences(volume: &CpuVolume, k: [u32; 3]) -> glam::Vec3 {
    dispatch!(&volume.values, values => differences_in(values, volume.dims, k))
}

/// The index-space gradient of `volume` at voxel `k` from its 3 x 3 x 3 neighbourhood: along
/// each axis, the central differences of the nine rows through the neighbourhood summed, over
/// 18 (the mean, halved as a central difference is). Zero at the grid's faces, where the
/// neighbourhood is not whole.
fn neighbourhood_differences(volume: &CpuVolume, k: [u32; 3]) -> glam::Vec3 {
    dispatch!(&volume.values, values => neighbourhood_differences_in(values, volume.dims, k))
}

/// [`neighbourhood_differences`] in values of one type.
fn neighbourhood_differences_in<T: Voxel>(values: &[T], dims: [u32; 3], k: [u32; 3]) -> glam::Vec3 {
    let [nx, ny, nz] = dims.map(|n| n as usize);
    let [x, y, z] = k.map(|c| c as usize);
    let (row, plane) = (nx, nx * ny);
    let centre = x + row * y + plane * z;
    if !((1..nx.saturating_sub(1)).contains(&x)
        && (1..ny.saturating_sub(1)).contains(&y)
        && (1..nz.saturating_sub(1)).contains(&z)
        && centre + plane + row + 1 < values.len())
    {
        return glam::Vec3::ZERO;
    }
    let steps = [1, row, plane];
    let g: [f32; 3] = std::array::from_fn(|a| {
        let [u, v] = [steps[(a + 1) % 3], steps[(a + 2) % 3]];
        let mut sum = 0.0;
        for i in [centre - u, centre, centre + u] {
            for j in [i - v, i, i + v] {
                sum += values[j + steps[a]].to_f32() - values[j - steps[a]].to_f32();
            }
        }
        sum / 18.0
    });
    glam::Vec3::from(g)
}

/// [`differences`] in values of one type (the type matched once a voxel, not once a value).
#[inline]
fn differences_in<T: Voxel>(values: &[T], dims: [u32; 3], k: [u32; 3]) -> glam::Vec3 {
    let [nx, ny, nz] = dims.map(|n| n as usize);
    let [x, y, z] = k.map(|c| c as usize);
    let (row, plane) = (nx, nx * ny);
    let centre = x + row * y + plane * z;
    if (1..nx.saturating_sub(1)).contains(&x)
        && (1..ny.saturating_sub(1)).contains(&y)
        && (1..nz.saturating_sub(1)).contains(&z)
        && centre + plane < values.len()
    {
        // Inside: both neighbours along every axis, no clamping.
        let d =
            |step: usize| (values[centre + step].to_f32() - values[centre - step].to_f32()) / 2.0;
        return glam::Vec3::new(d(1), d(row), d(plane));
    }
    let value = |x: usize, y: usize, z: usize| {
        values
            .get(x + nx * (y + ny * z))
            .map_or(0.0, |v| v.to_f32())
    };
    let diff = |k: usize, n: usize, at: &dyn Fn(usize) -> f32| {
        let (lo, hi) = (k.saturating_sub(1), (k + 1).min(n.max(1) - 1));
        if hi <= lo {
            0.0
        } else {
            (at(hi) - at(lo)) / (hi - lo) as f32
        }
    };
    glam::Vec3::new(
        diff(x, nx, &|i| value(i, y, z)),
        diff(y, ny, &|i| value(x, i, z)),
        diff(z, nz, &|i| value(x, y, i)),
    )
}

/// How a volume is classified.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClassifyOptions {
    /// Voxels whose transfer-function opacity is at or below this are left out (an opacity per
    /// [`Opacity::reference_mm`], so the same voxels stay at any grid).
    pub min_opacity: f32,
    /// What the opacities mean.
    pub opacity: Opacity,
    /// Shell mode: a voxel is kept only where one of its six neighbours has a
    /// transfer-function opacity at or below this (voxels outside the grid count as
    /// transparent), so the inside of thick opaque tissue, which never shows, is left out.
    pub shell: Option<f32>,
}

impl Default for ClassifyOptions {
    fn default() -> Self {
        Self {
            min_opacity: 1.0 / 255.0,
            opacity: Opacity::default(),
            shell: None,
        }
    }
}

/// Classifies every voxel with the default [`Opacity`]; those whose opacity is at or below
/// `min_opacity` are left out.
pub fn classify(
    volume: &CpuVolume,
    tf: &TransferFunction,
    min_opacity: f32,
) -> Result<Classified, GridError> {
    classify_with(
        volume,
        tf,
        &ClassifyOptions {
            min_opacity,
            ..Default::default()
        },
    )
}

/// Classifies every voxel as `options` say.
pub fn classify_with(
    volume: &CpuVolume,
    tf: &TransferFunction,
    options: &ClassifyOptions,
) -> Result<Classified, GridError> {
    classify_refined(volume, tf, options, [1, 1, 1])
}

/// The grid [`classify_refined`] makes from a `dims` grid refined by `factors`: `factors[a]`
/// voxels along axis `a` in place of each one.
pub fn refined_dims(dims: [u32; 3], factors: [u32; 3]) -> Result<[u32; 3], GridError> {
    let mut out = [0u32; 3];
    for a in 0..3 {
        out[a] = dims[a].checked_mul(factors[a]).ok_or(GridError::TooLarge {
            dims,
            count: u64::MAX,
        })?;
    }
    crate::grid::voxel_count(out)?;
    Ok(out)
}

/// Classifies the volume's field on a grid `factors[a]` times finer along each axis `a`: each
/// voxel's box split into `factors[0] x factors[1] x factors[2]` voxels, which keep the
/// volume's box (fine voxel `j` of voxel `k` centred at `k - 1/2 + (j + 1/2) / f`); `[1, 1,
/// 1]` is the volume's own grid. Each fine voxel's splat is its own cell of the trilinear
/// field, classified as [`classify_with`] classifies the own grid's cells, so a grid coarser
/// than the pixels can be drawn with splats about a pixel apart: a Gaussian a coarse voxel
/// wide is far softer than the trilinear
/// field a ray caster samples (measured in BENCHMARKS.md, "Grids coarser than the pixels").
/// The fine grid is never held as values: its cells are interpolated from the volume's.
pub fn classify_refined(
    volume: &CpuVolume,
    tf: &TransferFunction,
    options: &ClassifyOptions,
    factors: [u32; 3],
) -> Result<Classified, GridError> {
    classify_refined_in(volume, tf, options, factors, None, None)
}

/// [`classify_refined`], within `region` alone where one is given: the fine voxels of the
/// volume's voxels outside it are left out, never classified (a close-up's refinement
/// classifies only what lies on the image). A region made for a grid of other dimensions is
/// an error. Where `cancel` is given, the classification looks at it between fine z-slices
/// and gives up with [`GridError::Cancelled`] once it is raised (a viewer's refinement of a
/// close-up takes up to a second, and a drag meanwhile wants the cores).
pub fn classify_refined_in(
    volume: &CpuVolume,
    tf: &TransferFunction,
    options: &ClassifyOptions,
    factors: [u32; 3],
    region: Option<&Region>,
    cancel: Option<&AtomicBool>,
) -> Result<Classified, GridError> {
    if let Some(region) = region
        && region.dims != volume.dims
    {
        return Err(GridError::RegionMismatch {
            region: region.dims,
            dims: volume.dims,
        });
    }
    // Rows are sampled whole where the shell (which samples each cell's neighbours) is not
    // asked for.
    let by_rows = options.shell.is_none();
    classify_cells(volume, tf, options, factors, by_rows, region, cancel)
}

/// Which voxels of a grid a classification covers, by bricks of `side`^3 voxels.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Region {
    /// The grid's size.
    dims: [u32; 3],
    side: u32,
    /// Bricks along each axis.
    bricks: [u32; 3],
    /// Per brick, x fastest: whether its voxels are covered.
    covered: Vec<bool>,
}

impl Region {
    /// The bricks of `side`^3 voxels (fewer at the far ends) of a `dims` grid for which
    /// `covered(brick)` holds, `brick` its brick coordinates (voxel index / `side`). `None`
    /// for a side of 0.
    pub fn new(dims: [u32; 3], side: u32, covered: impl Fn([u32; 3]) -> bool) -> Option<Self> {
        if side == 0 {
            return None;
        }
        let bricks = dims.map(|n| n.div_ceil(side));
        let mut marks = Vec::with_capacity(bricks.iter().map(|&b| b as usize).product());
        for z in 0..bricks[2] {
            for y in 0..bricks[1] {
                for x in 0..bricks[0] {
                    marks.push(covered([x, y, z]));
                }
            }
        }
        Some(Self {
            dims,
            side,
            bricks,
            covered: marks,
        })
    }

    /// [`Region::new`] decided block by block: `covered(lo, hi)` says whether every brick
    /// from brick coordinates `lo` up to `hi` (exclusive) is covered (`Some(true)`), none is
    /// (`Some(false)`), or it cannot tell (`None`): the block is then cut in halves along its
    /// longest axis, down to single bricks, for which it must tell. A test that settles most
    /// large blocks at once makes a region of many bricks at a small fraction of the tests
    /// brick by brick. `None` for a side of 0.
    pub fn by_blocks(
        dims: [u32; 3],
        side: u32,
        covered: impl Fn([u32; 3], [u32; 3]) -> Option<bool>,
    ) -> Option<Self> {
        if side == 0 {
            return None;
        }
        let bricks = dims.map(|n| n.div_ceil(side));
        let mut marks = vec![false; bricks.iter().map(|&b| b as usize).product()];
        // Blocks still to settle; a block is cut in two, so at most one entry per level of
        // cutting (about 3 log2 of the bricks along an axis) waits beside the one in hand.
        let mut blocks = vec![([0u32; 3], bricks)];
        while let Some((lo, hi)) = blocks.pop() {
            if (0..3).any(|a| lo[a] >= hi[a]) {
                continue;
            }
            let single = (0..3).all(|a| hi[a] - lo[a] == 1);
            match covered(lo, hi) {
                Some(true) => {
                    for z in lo[2]..hi[2] {
                        for y in lo[1]..hi[1] {
                            let row = ((z * bricks[1] + y) * bricks[0]) as usize;
                            marks[row + lo[0] as usize..row + hi[0] as usize].fill(true);
                        }
                    }
                }
                Some(false) => {}
                // A single brick the test cannot settle is kept: nothing is left out that
                // the test does not leave out.
                None if single => {
                    marks[((lo[2] * bricks[1] + lo[1]) * bricks[0] + lo[0]) as usize] = true;
                }
                None => {
                    let a = (0..3).max_by_key(|&a| hi[a] - lo[a]).unwrap_or(0);
                    let mid = lo[a] + (hi[a] - lo[a]) / 2;
                    let (mut first_hi, mut second_lo) = (hi, lo);
                    first_hi[a] = mid;
                    second_lo[a] = mid;
                    blocks.push((lo, first_hi));
                    blocks.push((second_lo, hi));
                }
            }
        }
        Some(Self {
            dims,
            side,
            bricks,
            covered: marks,
        })
    }

    /// Whether the brick at brick coordinates `b` is covered (no brick past the grid is).
    pub fn covers_brick(&self, b: [u32; 3]) -> bool {
        (0..3).all(|a| b[a] < self.bricks[a])
            && self.covered[(b[0] + self.bricks[0] * (b[1] + self.bricks[1] * b[2])) as usize]
    }

    /// Whether voxel `k` is covered.
    pub fn covers(&self, k: [u32; 3]) -> bool {
        self.covers_brick(k.map(|c| c / self.side))
    }

    /// Whether every brick `other` covers, this one covers too (the same bricks of the same
    /// grid).
    pub fn contains(&self, other: &Region) -> bool {
        self.side == other.side
            && self.dims == other.dims
            && self
                .covered
                .iter()
                .zip(&other.covered)
                .all(|(&a, &b)| a || !b)
    }

    /// The bricks either region covers; `None` for regions of different bricks.
    pub fn union(&self, other: &Region) -> Option<Region> {
        (self.side == other.side && self.dims == other.dims).then(|| Region {
            covered: self
                .covered
                .iter()
                .zip(&other.covered)
                .map(|(&a, &b)| a || b)
                .collect(),
            ..self.clone()
        })
    }

    /// The bricks this region covers and `other` does not; `None` for regions of different
    /// bricks.
    pub fn without(&self, other: &Region) -> Option<Region> {
        (self.side == other.side && self.dims == other.dims).then(|| Region {
            covered: self
                .covered
                .iter()
                .zip(&other.covered)
                .map(|(&a, &b)| a && !b)
                .collect(),
            ..self.clone()
        })
    }

    /// The bricks this region does not cover.
    pub fn complement(&self) -> Region {
        Region {
            covered: self.covered.iter().map(|&c| !c).collect(),
            ..self.clone()
        }
    }

    /// Whether every brick is covered.
    pub fn is_whole(&self) -> bool {
        self.covered.iter().all(|&c| c)
    }

    /// How many bricks are covered.
    pub fn bricks_covered(&self) -> usize {
        self.covered.iter().filter(|&&c| c).count()
    }

    /// Clears `open` (one byte a voxel of row `y` of slice `z`) outside the region.
    /// Whether a brick covered holds a voxel of z-slices `z0..z1`.
    fn covers_any_in_z(&self, z0: usize, z1: usize) -> bool {
        let side = self.side as usize;
        if z0 >= z1 {
            return false;
        }
        let (b0, b1) = (z0 / side, (z1 - 1) / side);
        let layer = (self.bricks[0] * self.bricks[1]) as usize;
        self.covered
            .get(b0 * layer..((b1 + 1) * layer).min(self.covered.len()))
            .is_some_and(|marks| marks.iter().any(|&c| c))
    }

    fn clear_outside(&self, open: &mut [u8], y: usize, z: usize) {
        let side = self.side as usize;
        let (by, bz) = ((y / side) as u32, (z / side) as u32);
        for (bx, run) in open.chunks_mut(side).enumerate() {
            if !self.covers_brick([bx as u32, by, bz]) {
                run.fill(0);
            }
        }
    }
}

/// [`classify_refined`], each row's cells sampled whole or not (`by_rows`, see
/// [`classify_slab`]), within `region` where one is given.
fn classify_cells(
    volume: &CpuVolume,
    tf: &TransferFunction,
    options: &ClassifyOptions,
    factors: [u32; 3],
    by_rows: bool,
    region: Option<&Region>,
    cancel: Option<&AtomicBool>,
) -> Result<Classified, GridError> {
    let count = crate::grid::voxel_count(volume.dims)? as usize;
    if volume.values.len() < count {
        return Err(GridError::TooFewValues {
            values: volume.values.len(),
            voxels: count,
        });
    }
    let fine = refined_dims(volume.dims, factors)?;
    let nz = volume.dims[2] as usize;
    let clear = ClearIntervals::new(tf);
    let table = ExtinctionTable::new(tf);
    let cells = Cells {
        tf,
        table: &table,
        options,
        samples: factors.map(|f| Samples::new(f as usize)),
        fine: fine.map(|n| n as usize),
        dims: volume.dims.map(|n| n as usize),
        least_mean: least_mean(options.min_opacity),
        scale: options.opacity.scale() as f32,
    };
    // A slab given up (`None`) gives the whole classification up: what the others made is
    // dropped.
    let slabs: Option<Vec<(BitsPart, Vec<SplatColor>)>> = dispatch!(&volume.values, values => {
        (0..nz.div_ceil(SLAB))
            .into_par_iter()
            .map(|slab| {
                classify_slab(
                    values, volume.dims, factors, slab, &clear, &cells, by_rows, region, cancel,
                )
            })
            .collect()
    });
    let Some(slabs) = slabs else {
        return Err(GridError::Cancelled);
    };
    Classified::joined(fine, slabs)
}

/// The splats of z-slices `slab * SLAB ..` of a grid of `dims` holding `values`, refined by
/// `factors`: their fine ids and colours, in id order. With `by_rows` (no shell), each row
/// inside the grid has its cells' samples interpolated for all its open voxels at once
/// ([`RowSamples`]), once for each fine voxel along x; the result is the same, bit for bit.
#[allow(clippy::too_many_arguments)]
fn classify_slab<T: Voxel>(
    values: &[T],
    dims: [u32; 3],
    factors: [u32; 3],
    slab: usize,
    clear: &ClearIntervals,
    cells: &Cells,
    by_rows: bool,
    region: Option<&Region>,
    cancel: Option<&AtomicBool>,
) -> Option<(BitsPart, Vec<SplatColor>)> {
    let [nx, ny, nz] = dims.map(|n| n as usize);
    let [fx, fy, fz] = factors.map(|f| f as usize);
    let plane = nx * ny;
    let (mut ids, mut colors) = (BitsPart::default(), Vec::new());
    let z0 = slab * SLAB;
    let z1 = (z0 + SLAB).min(nz);
    // A slab the region leaves out whole is not read (a refinement joined with the few bricks
    // a turned view adds would else walk every slice of the grid).
    if region.is_some_and(|r| !r.covers_any_in_z(z0, z1)) {
        return Some((ids, colors));
    }
    // Per z-slice of the slab, with the slices beside it: which voxels' cells lie in one clear
    // interval of the transfer function. A fine voxel's cell lies in the 3x3x3 voxels around
    // the coarse voxel it splits, and trilinear interpolation stays in the interval its
    // corners lie in, so the same test skips it.
    let labels: Vec<Vec<u8>> = (z0.saturating_sub(1)..(z1 + 1).min(nz))
        .map(|z| uniform_in_plane(&clear.labels(&values[z * plane..][..plane]), nx, ny))
        .collect();
    let first = z0.saturating_sub(1);
    let (fine_row, fine_plane) = (nx * fx, nx * fx * ny * fy);
    let mut block = Block::default();
    // One row's samples for each fine voxel along x, and whether their sums were taken.
    let mut rows: Vec<RowSamples> = std::iter::repeat_with(RowSamples::default)
        .take(fx)
        .collect();
    let mut summed = vec![false; fx];
    let mut open = vec![0u8; plane];
    for z in z0..z1 {
        let below = &labels[z.saturating_sub(1) - first];
        let here = &labels[z - first];
        let above = &labels[(z + 1).min(nz - 1) - first];
        open_in_slice(below, here, above, &mut open);
        if let Some(region) = region {
            for (y, row) in open.chunks_mut(nx).enumerate() {
                region.clear_outside(row, y, z);
            }
        }
        // The rows with a voxel to classify: the others are passed over once, not for every
        // fine row they hold.
        let rows_open: Vec<bool> = open.chunks(nx).map(|r| r.iter().any(|&o| o != 0)).collect();
        for jz in 0..fz {
            if cancel.is_some_and(|c| c.load(AtomicOrdering::Relaxed)) {
                return None;
            }
            for y in (0..ny).filter(|&y| rows_open[y]) {
                let open = &open[nx * y..][..nx];
                let inner =
                    by_rows && nx >= 3 && (1..ny - 1).contains(&y) && (1..nz - 1).contains(&z);
                for jy in 0..fy {
                    let by_block =
                        |x: usize,
                         block: &mut Block,
                         ids: &mut BitsPart,
                         colors: &mut Vec<SplatColor>| {
                            block.load(values, dims, [x, y, z]);
                            for jx in 0..fx {
                                if let Some(c) = cells.color(block, [jx, jy, jz]) {
                                    let f = [x * fx + jx, y * fy + jy, z * fz + jz];
                                    ids.push((f[0] + fine_row * f[1] + fine_plane * f[2]) as u32);
                                    colors.push(c);
                                }
                            }
                        };
                    if !inner {
                        for_each_open(open, |x| by_block(x, &mut block, &mut ids, &mut colors));
                        continue;
                    }
                    // The row's ends by blocks (their cells may reach past the grid), the open
                    // stretch between them sampled whole.
                    if open[0] != 0 {
                        by_block(0, &mut block, &mut ids, &mut colors);
                    }
                    let between = &open[1..nx - 1];
                    if let (Some(first), Some(last)) = (
                        between.iter().position(|&o| o != 0),
                        between.iter().rposition(|&o| o != 0),
                    ) {
                        let (lo, hi) = (first + 1, last + 1);
                        for (jx, (row, summed)) in rows.iter_mut().zip(&mut summed).enumerate() {
                            row.sample(values, dims, [y, z], lo..=hi, &cells.samples, [jx, jy, jz]);
                            *summed = row.ramp_sums(cells.table, &open[lo..=hi]);
                        }
                        let at = fine_row * (y * fy + jy) + fine_plane * (z * fz + jz);
                        for_each_open(&open[lo..=hi], |j| {
                            for (jx, (row, &summed)) in rows.iter().zip(&summed).enumerate() {
                                let sums = if summed {
                                    row.sums_at(j)
                                } else {
                                    cells.table.weighted_sums(row.at(j))
                                };
                                if let Some(c) = cells.of_sums(sums) {
                                    ids.push((at + (lo + j) * fx + jx) as u32);
                                    colors.push(c);
                                }
                            }
                        });
                    }
                    if open[nx - 1] != 0 {
                        by_block(nx - 1, &mut block, &mut ids, &mut colors);
                    }
                }
            }
        }
    }
    // The slab's lists are held until all are joined: the room past their length freed.
    ids.shrink_to_fit();
    colors.shrink_to_fit();
    Some((ids, colors))
}

/// Per voxel of a slice: 1 where its 3x3x3 neighbourhood is not all in one clear interval
/// (`here`'s 3x3 label, as [`uniform_in_plane`] gives it, is 0 or differs from the slices'
/// below and above), so that its cell must be classified; else 0. One comparison of whole
/// slices, which the compiler vectorises: a test voxel by voxel, with its three loads and a
/// branch the processor cannot predict at the edges of the tissue, was a fifth of the
/// classification of a 139M-voxel CT.
fn open_in_slice(below: &[u8], here: &[u8], above: &[u8], open: &mut [u8]) {
    for (((o, &h), &b), &a) in open.iter_mut().zip(here).zip(below).zip(above) {
        *o = u8::from((h == 0) | (h != b) | (h != a));
    }
}

/// Calls `f` with each index of `open` (a row of [`open_in_slice`]) that holds a 1, in
/// increasing order, eight bytes at a time: a word of zeros (clear voxels, most of a CT's
/// air and fat) is passed over in one step.
#[inline(always)]
fn for_each_open(open: &[u8], mut f: impl FnMut(usize)) {
    let mut words = open.chunks_exact(8);
    let mut x = 0;
    for word in words.by_ref() {
        // Byte k of `bits` is 0 or 1, so bit 8k is set where index `x + k` is open.
        let mut bits = u64::from_le_bytes(word.try_into().unwrap_or([0; 8]));
        while bits != 0 {
            f(x + (bits.trailing_zeros() / 8) as usize);
            bits &= bits - 1;
        }
        x += 8;
    }
    for (k, &o) in words.remainder().iter().enumerate() {
        if o != 0 {
            f(x + k);
        }
    }
}

/// Z-slices a classification task takes.
const SLAB: usize = 16;

/// `-ln(1 - a)` is capped here (an opacity of 1 - 2e-9), so that opaque tissue has a finite
/// extinction to average.
pub const MAX_DEPTH: f64 = 20.0;

/// The value ranges over which a transfer function is fully transparent, numbered from 1.
struct ClearIntervals {
    /// Closed ranges, in increasing order.
    ranges: Vec<(f32, f32)>,
}

impl ClearIntervals {
    fn new(tf: &TransferFunction) -> Self {
        let points = tf.points();
        let mut ranges: Vec<(f32, f32)> = Vec::new();
        let mut i = 0;
        while i < points.len() {
            if points[i].1[3] > 0.0 {
                i += 1;
                continue;
            }
            let mut j = i;
            while j + 1 < points.len() && points[j + 1].1[3] <= 0.0 {
                j += 1;
            }
            let lo = if i == 0 {
                f32::NEG_INFINITY
            } else {
                points[i].0
            };
            let hi = if j + 1 == points.len() {
                f32::INFINITY
            } else {
                points[j].0
            };
            ranges.push((lo, hi));
            i = j + 1;
        }
        // Labels are bytes; past 254 ranges the rest are taken for opaque (never skipped).
        ranges.truncate(254);
        Self { ranges }
    }

    /// The number of the clear range holding each value, 0 for none (NaN included).
    fn labels<T: Voxel>(&self, values: &[T]) -> Vec<u8> {
        // One clear range (the usual transfer function, transparent below a threshold): a
        // comparison the compiler vectorises.
        if let [(lo, hi)] = self.ranges[..] {
            return values
                .iter()
                .map(|v| {
                    let v = v.to_f32();
                    u8::from(v >= lo && v <= hi)
                })
                .collect();
        }
        values
            .iter()
            .map(|v| {
                let v = v.to_f32();
                self.ranges
                    .iter()
                    .position(|&(lo, hi)| v >= lo && v <= hi)
                    .map_or(0, |i| i as u8 + 1)
            })
            .collect()
    }
}

/// Per voxel of an `nx` by `ny` plane of labels: its label where the 3x3 square around it
/// (clamped to the plane) holds that label alone, else 0. Written as whole-row comparisons of
/// shifted slices, which the compiler vectorises (this runs over every voxel of the volume).
fn uniform_in_plane(labels: &[u8], nx: usize, ny: usize) -> Vec<u8> {
    #[inline(always)]
    fn same(a: u8, b: u8, c: u8) -> u8 {
        a * u8::from((a == b) & (b == c))
    }
    let mut rows = vec![0u8; labels.len()];
    for (row, out) in labels.chunks_exact(nx).zip(rows.chunks_exact_mut(nx)) {
        if nx == 1 {
            out[0] = row[0];
            continue;
        }
        out[0] = same(row[0], row[0], row[1]);
        out[nx - 1] = same(row[nx - 2], row[nx - 1], row[nx - 1]);
        let inner = &mut out[1..nx - 1];
        for (((o, &a), &b), &c) in inner
            .iter_mut()
            .zip(&row[..nx - 2])
            .zip(&row[1..])
            .zip(&row[2..])
        {
            *o = same(a, b, c);
        }
    }
    let mut out = vec![0u8; labels.len()];
    for (y, line) in out.chunks_exact_mut(nx).enumerate() {
        let (up, down) = (y.saturating_sub(1), (y + 1).min(ny - 1));
        let [a, b, c] = [up, y, down].map(|r| &rows[r * nx..][..nx]);
        for (((o, &a), &b), &c) in line.iter_mut().zip(a).zip(b).zip(c) {
            *o = same(a, b, c);
        }
    }
    out
}

/// What classifying one voxel's cell takes.
struct Cells<'a> {
    tf: &'a TransferFunction,
    table: &'a ExtinctionTable,
    options: &'a ClassifyOptions,
    /// Per axis, where the fine voxels' cell samples lie in their coarse voxel's block.
    samples: [Samples; 3],
    /// The fine grid's size.
    fine: [usize; 3],
    /// The volume's own grid's size.
    dims: [usize; 3],
    /// The mean extinction at or below which a cell is left out: the minimum opacity's.
    least_mean: f32,
    /// Extinction to density ([`Opacity::scale`]).
    scale: f32,
}

/// Where the cells of the `f` fine voxels that split one coarse voxel along an axis are
/// sampled, in the coordinates of the coarse voxel's 3x3x3 [`Block`] (0, 1, 2: the voxel
/// before, the voxel, the one after).
struct Samples {
    /// Per fine voxel, its centre (1 at the coarse voxel's centre).
    centres: Vec<f32>,
    /// Per fine voxel, its two samples a quarter of its width either side of its centre, each
    /// as the lower of the two block values it lies between and the weight of the upper.
    at: Vec<[(usize, f32); 2]>,
    /// The same two samples as block coordinates.
    positions: Vec<[f32; 2]>,
}

impl Samples {
    fn new(f: usize) -> Self {
        let width = 1.0 / f as f64;
        let centres: Vec<f64> = (0..f).map(|j| 0.5 + (j as f64 + 0.5) * width).collect();
        let positions: Vec<[f64; 2]> = centres
            .iter()
            .map(|&c| [c - 0.25 * width, c + 0.25 * width])
            .collect();
        Self {
            centres: centres.into_iter().map(|c| c as f32).collect(),
            at: positions.iter().map(|p| p.map(Self::between)).collect(),
            positions: positions.iter().map(|p| p.map(|v| v as f32)).collect(),
        }
    }

    /// The lower block value a coordinate in `[0, 2]` lies after and the weight of the next.
    fn between(p: f64) -> (usize, f32) {
        let i = (p.floor().max(0.0) as usize).min(1);
        (i, (p - i as f64) as f32)
    }
}

/// The 3x3x3 values around one voxel (clamped to the grid), `values[z][y][x]`.
#[derive(Default)]
struct Block {
    /// The voxel they surround; `None` before the first load.
    voxel: Option<[usize; 3]>,
    values: [[[f32; 3]; 3]; 3],
}

impl Block {
    /// Holds the values around voxel `k` of `volume` (kept where they already are).
    fn load<T: Voxel>(&mut self, values: &[T], dims: [u32; 3], k: [usize; 3]) {
        if self.voxel == Some(k) {
            return;
        }
        let previous = self.voxel.replace(k);
        let dims = dims.map(|n| n as usize);
        let (row, plane) = (dims[0], dims[0] * dims[1]);
        let inside = (0..3).all(|a| k[a] >= 1 && k[a] + 1 < dims[a]);
        if inside && previous == Some([k[0] - 1, k[1], k[2]]) {
            // The voxel before along x: its block shifted by one column, the new column read.
            // (Its first column may have been clamped at x = 0: shifted out, it is not kept.)
            let next = k[0] + 1 + row * k[1] + plane * k[2];
            let values = &values[next - row - plane..=next + row + plane];
            for (dz, layer) in self.values.iter_mut().enumerate() {
                for (dy, line) in layer.iter_mut().enumerate() {
                    *line = [line[1], line[2], values[dz * plane + dy * row].to_f32()];
                }
            }
        } else if inside {
            // Inside: the 27 values by offsets from the centre, no clamping.
            let centre = k[0] + row * k[1] + plane * k[2];
            let values = &values[centre - 1 - row - plane..=centre + 1 + row + plane];
            for (dz, layer) in self.values.iter_mut().enumerate() {
                for (dy, line) in layer.iter_mut().enumerate() {
                    let start = dz * plane + dy * row;
                    let run = &values[start..start + 3];
                    *line = [run[0].to_f32(), run[1].to_f32(), run[2].to_f32()];
                }
            }
        } else {
            let at = |a: usize, d: usize| (k[a] + d).saturating_sub(1).min(dims[a] - 1);
            for (dz, layer) in self.values.iter_mut().enumerate() {
                for (dy, line) in layer.iter_mut().enumerate() {
                    for (dx, slot) in line.iter_mut().enumerate() {
                        *slot = values[at(0, dx) + row * at(1, dy) + plane * at(2, dz)].to_f32();
                    }
                }
            }
        }
    }

    /// The trilinear interpolation at `(x, y, z)` in block coordinates, each in `[0, 2]`.
    fn sample(&self, p: [f32; 3]) -> f32 {
        let [(ix, tx), (iy, ty), (iz, tz)] = p.map(|c| Samples::between(f64::from(c)));
        self.lerp([ix, iy, iz], [tx, ty, tz])
    }

    /// The trilinear interpolation at the 2 x 2 x 2 points whose coordinates along each axis
    /// are the two (lower value, weight of the next) of `at`, x fastest: what [`Block::lerp`]
    /// gives at each, with the same operations in the same order (so the same bits), the
    /// lerps along x and y that points share done once (38 lerps instead of 56).
    #[inline]
    fn lerp_2x2x2(&self, at: [&[(usize, f32); 2]; 3]) -> [f32; 8] {
        let v = &self.values;
        let [sx, sy, sz] = at;
        // Along x: every line of the block at both x points.
        let mut lines = [[[0.0f32; 2]; 3]; 3];
        for (z, layer) in v.iter().enumerate() {
            for (y, l) in layer.iter().enumerate() {
                for (out, &(i, t)) in lines[z][y].iter_mut().zip(sx) {
                    *out = l[i] + t * (l[i + 1] - l[i]);
                }
            }
        }
        // Along y: every plane at both y points, for both x points.
        let mut planes = [[[0.0f32; 2]; 2]; 3];
        for (z, plane) in planes.iter_mut().enumerate() {
            for (row, &(i, t)) in plane.iter_mut().zip(sy) {
                for (x, out) in row.iter_mut().enumerate() {
                    let a = lines[z][i][x];
                    *out = a + t * (lines[z][i + 1][x] - a);
                }
            }
        }
        // Along z.
        std::array::from_fn(|corner| {
            let (x, y) = (corner & 1, corner >> 1 & 1);
            let (i, t) = sz[corner >> 2 & 1];
            let a = planes[i][y][x];
            a + t * (planes[i + 1][y][x] - a)
        })
    }

    /// The trilinear interpolation in the cell whose lowest corner is `i`, at weights `t`.
    #[inline]
    fn lerp(&self, i: [usize; 3], t: [f32; 3]) -> f32 {
        let v = &self.values;
        let line = |z: usize, y: usize| {
            let l = &v[z][y];
            l[i[0]] + t[0] * (l[i[0] + 1] - l[i[0]])
        };
        let plane = |z: usize| {
            let a = line(z, i[1]);
            a + t[1] * (line(z, i[1] + 1) - a)
        };
        let a = plane(i[2]);
        a + t[2] * (plane(i[2] + 1) - a)
    }
}

/// Bins a segment of a transfer function (between two of its points) is tabulated in.
const BINS: usize = 256;

/// A transfer function's straight colour and extinction `-ln(1 - a)` (capped at
/// [`MAX_DEPTH`]), tabulated at [`BINS`] + 1 evenly spaced values on each segment between two
/// of its points and interpolated linearly: the colour exactly (it is linear on a segment),
/// the extinction within about `1e-5` of its own value below opacity 0.99 (the logarithm's
/// curvature over a bin). Classification takes eight samples a voxel, and a logarithm each
/// was most of its time.
struct ExtinctionTable {
    /// The function's points' values.
    knots: Vec<f32>,
    /// Per segment, `BINS + 1` entries of (r, g, b, extinction).
    entries: Vec<[f32; 4]>,
    /// Below the first point and above the last.
    ends: [[f32; 4]; 2],
}

impl ExtinctionTable {
    fn new(tf: &TransferFunction) -> Self {
        let entry = |v: f32| {
            let [r, g, b, a] = tf.sample(v);
            [r, g, b, extinction(a) as f32]
        };
        let knots: Vec<f32> = tf.points().iter().map(|p| p.0).collect();
        let mut entries = Vec::with_capacity(knots.len().saturating_sub(1) * (BINS + 1));
        for pair in knots.windows(2) {
            for i in 0..=BINS {
                let t = i as f32 / BINS as f32;
                // The segment's own end values at its ends, whatever the rounding.
                let v = if i == BINS {
                    pair[1]
                } else {
                    pair[0] + t * (pair[1] - pair[0])
                };
                let e = entry(v);
                entries.push(e);
            }
        }
        let first = knots.first().map_or([0.0; 4], |&v| entry(v));
        let last = knots.last().map_or([0.0; 4], |&v| entry(v));
        Self {
            knots,
            entries,
            ends: [first, last],
        }
    }

    /// Straight colour and extinction at `value`.
    #[inline]
    fn sample(&self, value: f32) -> [f32; 4] {
        let n = self.knots.len();
        if n == 0 {
            return [0.0; 4];
        }
        if value.is_nan() || value <= self.knots[0] {
            return self.ends[0];
        }
        if value >= self.knots[n - 1] {
            return self.ends[1];
        }
        // The segment `value` lies in: knots[s] <= value < knots[s + 1].
        let s = self.knots.partition_point(|&k| k <= value) - 1;
        let (v0, v1) = (self.knots[s], self.knots[s + 1]);
        let x = (value - v0) / (v1 - v0) * BINS as f32;
        let i = (x as usize).min(BINS - 1);
        let f = x - i as f32;
        let (a, b) = (
            self.entries[s * (BINS + 1) + i],
            self.entries[s * (BINS + 1) + i + 1],
        );
        std::array::from_fn(|c| a[c] + f * (b[c] - a[c]))
    }

    /// The extinction-weighted sums of [`ExtinctionTable::sample`] over eight values: the
    /// sums of extinction times red, green and blue, and of extinction (a transparent value
    /// adds nothing). A function of two points (a ramp, the usual case) has one segment, and
    /// its lookups need no search: a value's bin follows from one multiply, clamped to the
    /// segment (its ends are the function's values below and above it; NaN takes the lower).
    /// Each value's entry is four lanes (colour and extinction), weighted in one vector.
    #[inline(always)]
    fn weighted_sums(&self, values: [f32; 8]) -> [f32; 4] {
        let add = add_weighted;
        let mut sums = [0.0f32; 4];
        if let Some(Ramp {
            start: v0,
            scale,
            entries,
        }) = self.ramp()
        {
            for value in values {
                // `max` first: NaN becomes 0, the lower end. In [0, BINS], so the conversion
                // through i32 is exact.
                let x = ((value - v0) * scale).max(0.0).min(BINS as f32);
                let i = (x as i32 as usize).min(BINS - 1);
                let f = x - i as f32;
                let (a, b) = (entries[i], entries[i + 1]);
                sums = add(sums, std::array::from_fn(|c| a[c] + f * (b[c] - a[c])));
            }
        } else {
            for value in values {
                sums = add(sums, self.sample(value));
            }
        }
        sums
    }

    /// The table of a function of two points (a ramp), whose one segment's bins are found
    /// with no search; `None` for other functions.
    #[inline(always)]
    fn ramp(&self) -> Option<Ramp<'_>> {
        match (&self.knots[..], self.entries.first_chunk::<{ BINS + 1 }>()) {
            (&[v0, v1], Some(entries)) => Some(Ramp {
                start: v0,
                scale: BINS as f32 / (v1 - v0),
                entries,
            }),
            _ => None,
        }
    }

    /// [`ExtinctionTable::weighted_sums`] over the values whose bit is set in `mask` alone
    /// (bit `c` for `values[c]`): for cells some of whose samples lie outside the grid.
    fn weighted_sums_of(&self, values: [f32; 8], mask: u8) -> [f32; 4] {
        let mut sums = [0.0f32; 4];
        for (c, value) in values.into_iter().enumerate() {
            if mask >> c & 1 == 1 {
                sums = add_weighted(sums, self.sample(value));
            }
        }
        sums
    }
}

/// The one segment of a ramp's [`ExtinctionTable`]: a value `v`'s bin is `(v - start) *
/// scale`, clamped to `[0, BINS]`.
#[derive(Clone, Copy)]
struct Ramp<'a> {
    start: f32,
    scale: f32,
    entries: &'a [[f32; 4]; BINS + 1],
}

/// `sums` with an entry's colour weighted by its extinction, and the extinction, added.
#[inline]
fn add_weighted(sums: [f32; 4], e: [f32; 4]) -> [f32; 4] {
    std::array::from_fn(|c| sums[c] + e[3] * if c < 3 { e[c] } else { 1.0 })
}

/// The corners of a cell's 2x2x2 samples (bit 0 the x sample, bit 1 y, bit 2 z; a set bit the
/// upper sample) whose bit `axis_bit` is `value`, as a mask of the eight.
fn corners_where(axis_bit: usize, value: usize) -> u8 {
    (0..8)
        .filter(|c| c & axis_bit == value)
        .fold(0u8, |mask, c| mask | 1 << c)
}

/// The mean extinction at or below which a cell's opacity `1 - exp(-mean)` is at or below
/// `min_opacity` (infinite from an opacity of 1 on, below zero for a negative one; a NaN
/// minimum leaves nothing out, as a comparison with it would).
fn least_mean(min_opacity: f32) -> f32 {
    if min_opacity.is_nan() {
        f32::NEG_INFINITY
    } else if min_opacity >= 1.0 {
        f32::INFINITY
    } else {
        (-(-f64::from(min_opacity)).ln_1p()) as f32
    }
}

impl Cells<'_> {
    /// The splat of fine voxel `j` of the coarse voxel whose values `block` holds: the mean
    /// extinction of the transfer function over its cell (the box of the fine voxel, where
    /// the trilinear interpolation of the values is classified at the 2x2x2 points a quarter
    /// of the fine voxel from its centre along each axis), and the mean of their colours
    /// weighted by extinction; `None` where that is at or below the minimum opacity, or, in
    /// shell mode, where no face neighbour's opacity is at or below the shell's.
    ///
    /// The transfer function is applied to the interpolated field, as a ray caster does, and
    /// then averaged: a voxel's splat carries the tissue of its whole cell, so a coarse grid
    /// and a fine one resampled from it draw the same picture. Classifying the centre value
    /// alone made a thin rib on a 1.4 x 1.4 x 2.5 mm grid a row of full-strength splats two
    /// voxels wide, where the interpolated field crosses the threshold over a fraction of them.
    fn color(&self, block: &Block, j: [usize; 3]) -> Option<SplatColor> {
        let [sx, sy, sz] = [0, 1, 2].map(|a| &self.samples[a].at[j[a]]);
        let values = block.lerp_2x2x2([sx, sy, sz]);
        // The cell's samples that lie past the grid's outer voxel centres carry no tissue: the
        // data ends there, as the ray caster's box does, and a face cut through dense tissue
        // would otherwise draw half a voxel more of it (more on a coarse grid than on a fine
        // one). An axis of one voxel keeps its whole cell: a single slice is not empty.
        let k = block.voxel.unwrap_or_default();
        let mut inside = u8::MAX;
        for (a, samples) in self.samples.iter().enumerate() {
            let voxels = self.dims[a];
            if voxels < 2 || (k[a] > 0 && k[a] + 1 < voxels) {
                continue;
            }
            for (side, &p) in samples.positions[j[a]].iter().enumerate() {
                // 1 is the voxel's centre in block coordinates.
                if (k[a] == 0 && p < 1.0) || (k[a] + 1 == voxels && p > 1.0) {
                    inside &= !corners_where(1 << a, side << a);
                }
            }
        }
        let sums = if inside == u8::MAX {
            self.table.weighted_sums(values)
        } else {
            self.table.weighted_sums_of(values, inside)
        };
        if !self.kept(sums[3]) {
            return None;
        }
        if let Some(high) = self.options.shell {
            let factors = self.samples.each_ref().map(|s| s.centres.len());
            let at_face = (0..3).any(|a| {
                let f = k[a] * factors[a] + j[a];
                f == 0 || f + 1 == self.fine[a]
            });
            // The face neighbours' centres, one fine voxel away: within the block.
            let centre = [0, 1, 2].map(|a| self.samples[a].centres[j[a]]);
            let opaque = |a: usize, sign: f32| {
                let mut p = centre;
                p[a] += sign / factors[a] as f32;
                self.tf.sample(block.sample(p))[3] > high
            };
            if !at_face && (0..3).all(|a| opaque(a, -1.0) && opaque(a, 1.0)) {
                return None;
            }
        }
        Some(self.quantised(sums))
    }

    /// Whether a cell whose eight samples' extinctions sum to `depth` is a splat: `1 -
    /// exp(-mean) > min_opacity`, tested with no exponential (the opacity grows with the
    /// mean extinction). A cell with none is no splat, whatever the minimum.
    #[inline(always)]
    fn kept(&self, depth: f32) -> bool {
        depth > 0.0 && depth / 8.0 > self.least_mean
    }

    /// The splat of a cell whose samples' colours weighted by extinction, and extinctions,
    /// sum to `sums` (as [`ExtinctionTable::weighted_sums`] gives them).
    #[inline(always)]
    fn quantised(&self, [r, g, b, depth]: [f32; 4]) -> SplatColor {
        // Rounded as `+ 0.5` and a truncation: the value is never negative, and `round`
        // is a library call on the x86-64 baseline.
        let inverse = 1.0 / depth;
        let q = |v: f32| ((v * inverse).clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
        SplatColor {
            rgb: [r, g, b].map(q),
            density: half::f16::from_f32(depth / 8.0 * self.scale),
        }
    }

    /// The splat of a cell inside the grid, no shell asked for, from its samples' `sums`.
    #[inline(always)]
    fn of_sums(&self, sums: [f32; 4]) -> Option<SplatColor> {
        self.kept(sums[3]).then(|| self.quantised(sums))
    }
}

/// The eight cell samples of each voxel of a stretch of one row inside the own grid, as
/// [`Block::lerp_2x2x2`] takes them one voxel at a time, with the same operations in the same
/// order (so the same values, bit for bit), but each step done along the whole stretch: the
/// loops run over contiguous arrays, which the compiler vectorises. (With the transfer
/// function's table inlined into the loop that reads them, the 0.5 mm head's classification
/// went from 2.3 s to 1.45 s: BENCHMARKS.md, "Classification and run tables a row at a
/// time".)
#[derive(Default)]
struct RowSamples {
    /// Per sample corner (bit 0: x, 1: y, 2: z), the value at each voxel of the stretch.
    corners: [Vec<f32>; 8],
    /// Scratch: the 3 x 3 source rows around the stretch, then the rows lerped along x and
    /// along y.
    source: [[Vec<f32>; 3]; 3],
    lines: [[[Vec<f32>; 2]; 3]; 3],
    planes: [[[Vec<f32>; 2]; 2]; 3],
    /// Per voxel of the stretch, its samples' weighted sums ([`RowSamples::ramp_sums`]), red,
    /// green, blue and extinction apart.
    sums: [Vec<f32>; 4],
}

impl RowSamples {
    /// Samples the cells of fine voxel `j` (per axis, of the `samples`' fine voxels a coarse
    /// voxel splits into) of each of voxels `xs` of row `(y, z)` of a grid of `dims` holding
    /// `values`. The row and its neighbours must lie inside the grid: `1 <= xs`,
    /// `xs <= nx - 2`, likewise `y` and `z`.
    fn sample<T: Voxel>(
        &mut self,
        values: &[T],
        dims: [u32; 3],
        [y, z]: [usize; 2],
        xs: std::ops::RangeInclusive<usize>,
        samples: &[Samples; 3],
        j: [usize; 3],
    ) {
        let [nx, ny, _] = dims.map(|n| n as usize);
        let (lo, hi) = (*xs.start(), *xs.end());
        let n = hi + 1 - lo;
        // The voxels' blocks: source index j + b is block column b of stretch voxel j.
        for (dz, layer) in self.source.iter_mut().enumerate() {
            for (dy, row) in layer.iter_mut().enumerate() {
                let start = lo - 1 + nx * (y + dy - 1) + nx * ny * (z + dz - 1);
                row.clear();
                row.extend(values[start..start + n + 2].iter().map(|v| v.to_f32()));
            }
        }
        let [sx, sy, sz] = [0, 1, 2].map(|a| &samples[a].at[j[a]]);
        for (dz, layer) in self.lines.iter_mut().enumerate() {
            for (dy, line) in layer.iter_mut().enumerate() {
                let l = &self.source[dz][dy];
                for (out, &(i, t)) in line.iter_mut().zip(sx) {
                    out.clear();
                    out.extend(
                        l[i..i + n]
                            .iter()
                            .zip(&l[i + 1..i + 1 + n])
                            .map(|(&a, &b)| a + t * (b - a)),
                    );
                }
            }
        }
        for (dz, plane) in self.planes.iter_mut().enumerate() {
            for (row, &(i, t)) in plane.iter_mut().zip(sy) {
                for (x, out) in row.iter_mut().enumerate() {
                    let (a, b) = (&self.lines[dz][i][x], &self.lines[dz][i + 1][x]);
                    out.clear();
                    out.extend(a.iter().zip(b).map(|(&a, &b)| a + t * (b - a)));
                }
            }
        }
        for (corner, out) in self.corners.iter_mut().enumerate() {
            let (x, y) = (corner & 1, corner >> 1 & 1);
            let (i, t) = sz[corner >> 2 & 1];
            let (a, b) = (&self.planes[i][y][x], &self.planes[i + 1][y][x]);
            out.clear();
            out.extend(a.iter().zip(b).map(|(&a, &b)| a + t * (b - a)));
        }
    }

    /// The eight samples of voxel `j` of the stretch last sampled.
    #[inline(always)]
    fn at(&self, j: usize) -> [f32; 8] {
        std::array::from_fn(|c| self.corners[c].get(j).copied().unwrap_or(0.0))
    }

    /// Takes [`ExtinctionTable::weighted_sums`] of the voxels of the stretch last sampled that
    /// are open (`open[j] != 0`, one byte a voxel of the stretch), eight voxels a vector,
    /// where the function is a ramp and the processor has AVX2 ([`crate::simd::has_avx2`]):
    /// each lane does a voxel's operations in the same order as `weighted_sums`, so the sums
    /// are the same, bit for bit. (One voxel at a time, the eight samples' sums are a chain of
    /// dependent additions, and the table's lookups were two thirds of a dense CT's
    /// classification.) Returns whether it did; read them with [`RowSamples::sums_at`].
    fn ramp_sums(&mut self, table: &ExtinctionTable, open: &[u8]) -> bool {
        #[cfg(target_arch = "x86_64")]
        if let Some(ramp) = table.ramp()
            && crate::simd::has_avx2()
            && open.len() == self.corners[0].len()
        {
            let n = open.len();
            for sums in &mut self.sums {
                sums.resize(n.max(sums.len()), 0.0);
            }
            let whole = n - n % simd::LANES;
            #[allow(unsafe_code)]
            // SAFETY: the processor has AVX2, checked above; `open`, every corner and every
            // sums hold at least `n` values.
            unsafe {
                simd::ramp_sums(&self.corners, open, whole, ramp, &mut self.sums)
            };
            for j in whole..n {
                let sums = table.weighted_sums(self.at(j));
                for (out, v) in self.sums.iter_mut().zip(sums) {
                    out[j] = v;
                }
            }
            return true;
        }
        let _ = (table, open);
        false
    }

    /// The sums [`RowSamples::ramp_sums`] took for voxel `j` of the stretch.
    #[inline(always)]
    fn sums_at(&self, j: usize) -> [f32; 4] {
        std::array::from_fn(|c| self.sums[c].get(j).copied().unwrap_or(0.0))
    }
}

#[cfg(target_arch = "x86_64")]
mod simd;
#[cfg(test)]
mod tests;
