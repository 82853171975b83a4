//! Error against run time as a scatter plot (plotters), as PNG and SVG.

use std::path::{Path, PathBuf};

use plotters::prelude::*;
use plotters::style::FontStyle;

use super::Summary;

/// Why the plot could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// No font to draw labels with.
    #[error("the plot labels: {0}")]
    NoFont(#[from] crate::annotate::NoFont),
    /// Drawing or writing the file failed.
    #[error("drawing {path}: {message}")]
    Draw {
        /// The file being drawn.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
}

/// Finds and registers the font of the plot's labels. The plot does this itself; a caller
/// that measures for minutes before plotting calls it first, to fail before the work.
pub fn register_font() -> Result<(), PlotError> {
    let bytes = crate::annotate::font_bytes()?;
    plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
        .map_err(|_| PlotError::NoFont(crate::annotate::NoFont))
}

/// Draws mean image RMSE against median order time (log-log), one labelled point per
/// ordering, to `png` and `svg`.
pub fn plot_error_against_time(
    summaries: &[Summary],
    title: &str,
    png: &Path,
    svg: &Path,
) -> Result<(), PlotError> {
    register_font()?;
    // Drawn in memory and written through a temporary and a rename, as every output is.
    let (w, h) = (900u32, 600u32);
    let mut rgb = vec![0u8; (w * h * 3) as usize];
    draw(
        BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area(),
        summaries,
        title,
        png,
    )?;
    let mut svg_text = String::new();
    draw(
        SVGBackend::with_string(&mut svg_text, (w, h)).into_drawing_area(),
        summaries,
        title,
        svg,
    )?;
    let image = image::RgbImage::from_raw(w, h, rgb).expect("the buffer holds the whole plot");
    let mut png_bytes = Vec::new();
    image
        .write_to(
            &mut std::io::Cursor::new(&mut png_bytes),
            image::ImageFormat::Png,
        )
        .map_err(|e| PlotError::Draw {
            path: png.to_owned(),
            message: e.to_string(),
        })?;
    for (path, bytes) in [(png, png_bytes.as_slice()), (svg, svg_text.as_bytes())] {
        crate::output::write_atomic(path, bytes).map_err(|e| PlotError::Draw {
            path: path.to_owned(),
            message: e.to_string(),
        })?;
    }
    Ok(())
}

fn draw<DB: DrawingBackend>(
    area: DrawingArea<DB, plotters::coord::Shift>,
    summaries: &[Summary],
    title: &str,
    path: &Path,
) -> Result<(), PlotError>
where
    DB::ErrorType: 'static,
{
    let fail = |e: &dyn std::fmt::Display| PlotError::Draw {
        path: path.to_owned(),
        message: e.to_string(),
    };
    // The exact order has zero error by definition: plot it on the floor of the axis.
    let times: Vec<f64> = summaries
        .iter()
        .map(|s| (s.time[0] * 1e3).max(1e-3))
        .collect();
    let positive = summaries.iter().map(|s| s.rmse).filter(|e| *e > 0.0);
    let floor = positive.clone().fold(f64::INFINITY, f64::min).min(1e-3) / 3.0;
    let errors: Vec<f64> = summaries.iter().map(|s| s.rmse.max(floor)).collect();
    let (t0, t1) = bounds(&times);
    let (e0, e1) = bounds(&errors);
    area.fill(&WHITE).map_err(|e| fail(&e))?;
    let mut chart = ChartBuilder::on(&area)
        .caption(title, ("sans-serif", 22))
        .margin(20)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d((t0..t1).log_scale(), (e0..e1).log_scale())
        .map_err(|e| fail(&e))?;
    chart
        .configure_mesh()
        .x_desc("order time, median over views (ms)")
        .y_desc("image RMSE against the exact order (mean)")
        .draw()
        .map_err(|e| fail(&e))?;
    let mut placed: Vec<LabelBox> = Vec::new();
    for (i, point) in times.iter().zip(&errors).enumerate() {
        let colour = Palette99::pick(i).to_rgba();
        let point = (*point.0, *point.1);
        chart
            .draw_series(std::iter::once(Circle::new(point, 6, colour.filled())))
            .map_err(|e| fail(&e))?;
        // Points are drawn before any label so that the labels can avoid them all.
        placed.push(LabelBox::around(chart.backend_coord(&point), 7));
    }
    for (i, s) in summaries.iter().enumerate() {
        let label = if s.rmse > 0.0 {
            s.ordering.to_string()
        } else {
            format!("{} (reference)", s.ordering)
        };
        let at = chart.backend_coord(&(times[i], errors[i]));
        let spot = place_label(at, &label, &placed, area.dim_in_pixel());
        placed.push(spot);
        area.draw(&Text::new(
            label,
            (spot.x0, spot.y0),
            ("sans-serif", LABEL_PX),
        ))
        .map_err(|e| fail(&e))?;
    }
    area.present().map_err(|e| fail(&e))
}

/// Height of a label in pixels; its width is estimated from the character count.
const LABEL_PX: u32 = 16;

/// A rectangle in pixels taken by a point or a label.
#[derive(Debug, Clone, Copy, PartialEq)]
struct LabelBox {
    x0: i32,
    y0: i32,
    x1: i32,
    y1: i32,
}

impl LabelBox {
    /// The square of half-width `r` around `(x, y)`.
    fn around((x, y): (i32, i32), r: i32) -> Self {
        Self {
            x0: x - r,
            y0: y - r,
            x1: x + r,
            y1: y + r,
        }
    }

    fn overlaps(&self, other: &Self) -> bool {
        self.x0 < other.x1 && other.x0 < self.x1 && self.y0 < other.y1 && other.y0 < self.y1
    }
}

/// Where the label of the point at `at` goes: the first of several spots around the point
/// (right, above and below right, left, above, below, then farther out) that overlaps no box
/// already taken and stays inside the image, else the first spot.
fn place_label(at: (i32, i32), label: &str, taken: &[LabelBox], size: (u32, u32)) -> LabelBox {
    let h = LABEL_PX as i32;
    // About 0.55 em a character in DejaVu Sans.
    let w = (label.chars().count() as f64 * 0.55 * f64::from(LABEL_PX)).ceil() as i32;
    let (x, y) = at;
    let candidates = [
        (x + 9, y - h / 2),
        (x + 9, y - h - 4),
        (x + 9, y + 4),
        (x - 9 - w, y - h / 2),
        (x - w / 2, y - h - 9),
        (x - w / 2, y + 9),
        (x + 9, y - 2 * h - 4),
        (x + 9, y + h + 4),
        (x - 9 - w, y - h - 4),
        (x - 9 - w, y + 4),
    ];
    let boxes = candidates.map(|(x0, y0)| LabelBox {
        x0,
        y0,
        x1: x0 + w,
        y1: y0 + h,
    });
    let (width, height) = (size.0 as i32, size.1 as i32);
    boxes
        .iter()
        .find(|b| {
            b.x0 >= 0
                && b.y0 >= 0
                && b.x1 <= width
                && b.y1 <= height
                && !taken.iter().any(|t| t.overlaps(b))
        })
        .copied()
        .unwrap_or(boxes[0])
}

/// Log-axis bounds with some room around the values, widened to whole decades so that the
/// axis always shows at least two labelled powers of ten.
fn bounds(values: &[f64]) -> (f64, f64) {
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = values.iter().copied().fold(0.0, f64::max);
    if !(lo.is_finite() && lo > 0.0 && hi > 0.0) {
        return (1e-3, 1.0);
    }
    let lo = 10f64.powf((lo / 1.5).log10().floor());
    let hi = 10f64.powf((hi * 1.5).log10().ceil());
    (lo, hi.max(lo * 10.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axes_span_whole_decades() {
        assert_eq!(bounds(&[2.2, 63.0]), (1.0, 100.0));
        assert_eq!(bounds(&[0.0022, 0.0316]), (0.001, 0.1));
        // One value: still a decade.
        assert_eq!(bounds(&[5.0]), (1.0, 10.0));
        assert_eq!(bounds(&[]), (1e-3, 1.0));
    }

    /// Four points a few pixels apart, as IP-PBTF, WBTF and the pyramid order often fall:
    /// every label finds a spot clear of every point and of the other labels.
    #[test]
    fn labels_of_close_points_do_not_overlap() {
        let points = [(300, 200), (312, 204), (306, 214), (318, 196)];
        let mut taken: Vec<LabelBox> = points.iter().map(|&p| LabelBox::around(p, 7)).collect();
        let mut labels = Vec::new();
        for (&p, name) in points
            .iter()
            .zip(["ip-pbtf-implicit", "wbtf", "pyramid", "rows"])
        {
            let spot = place_label(p, name, &taken, (900, 600));
            taken.push(spot);
            labels.push(spot);
        }
        for (i, a) in labels.iter().enumerate() {
            for p in &points {
                assert!(
                    !a.overlaps(&LabelBox::around(*p, 7)),
                    "label {i} on a point"
                );
            }
            for b in &labels[i + 1..] {
                assert!(!a.overlaps(b), "{a:?} and {b:?}");
            }
        }
    }
}
