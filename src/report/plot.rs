//! Error against run time as a scatter plot (plotters), as PNG and SVG.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::prelude::*;
use plotters::style::FontStyle;

use super::Summary;

/// Where the plot's font is looked for (Debian's fonts-dejavu-core).
const FONT_PATHS: [&str; 2] = [
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
];

/// Why the plot could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// No font to draw labels with.
    #[error("no font for the plot labels: install Debian's fonts-dejavu-core (looked for {0:?})")]
    NoFont(Vec<&'static str>),
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
    static FONT: OnceLock<Option<&'static [u8]>> = OnceLock::new();
    let bytes = FONT.get_or_init(|| {
        FONT_PATHS
            .iter()
            .find_map(|p| std::fs::read(p).ok())
            .map(|b| &*Box::leak(b.into_boxed_slice()))
    });
    let bytes = bytes.ok_or_else(|| PlotError::NoFont(FONT_PATHS.to_vec()))?;
    plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
        .map_err(|_| PlotError::NoFont(FONT_PATHS.to_vec()))
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
    draw(
        BitMapBackend::new(png, (900, 600)).into_drawing_area(),
        summaries,
        title,
        png,
    )?;
    draw(
        SVGBackend::new(svg, (900, 600)).into_drawing_area(),
        summaries,
        title,
        svg,
    )
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
    for (i, s) in summaries.iter().enumerate() {
        let colour = Palette99::pick(i).to_rgba();
        let point = (times[i], errors[i]);
        chart
            .draw_series(std::iter::once(Circle::new(point, 6, colour.filled())))
            .map_err(|e| fail(&e))?;
        let label = if s.rmse > 0.0 {
            s.ordering.to_string()
        } else {
            format!("{} (reference)", s.ordering)
        };
        chart
            .draw_series(std::iter::once(Text::new(label, point, ("sans-serif", 16))))
            .map_err(|e| fail(&e))?;
    }
    area.present().map_err(|e| fail(&e))
}

/// Log-axis bounds with some room around the values.
fn bounds(values: &[f64]) -> (f64, f64) {
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = values.iter().copied().fold(0.0, f64::max);
    if !(lo.is_finite() && hi > 0.0) {
        return (1e-3, 1.0);
    }
    (lo / 2.0, hi * 3.0)
}
