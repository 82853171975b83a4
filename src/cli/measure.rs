//! `splatscene measure`: distances, angles and points in a scene, as JSON and as a figure.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use glam::DVec3;
use serde_json::Value;

use splatscene::annotate::{Annotations, Label};
use splatscene::pick::measure::{
    MarkerStyle, MeasureKind, Measurement, annotate, draw_scene_measurements, label_text,
};
use splatscene::pick::{PickOptions, Picker};
use splatscene::render::{FrameOptions, GpuContext, Renderer, ViewSetup, encode_png};

use super::args::{parse_f64x3, parse_opacity, parse_u32x2};
use super::files::write_replacing;
use super::input::{View, ViewArgs};
use super::pick::check_pixel;
use super::render::{AnnotateArgs, figure, refuse_inputs};

/// `splatscene measure`.
#[derive(clap::Args)]
pub struct MeasureArgs {
    #[command(flatten)]
    view: ViewArgs,
    /// Pixels X,Y to pick, in order: two for a distance, three for the angle at the second,
    /// four for the angle between the directed lines from the first to the second and from
    /// the third to the fourth (0 to 180 degrees).
    #[arg(long = "pixel", value_parser = parse_u32x2, required = true)]
    pixels: Vec<[u32; 2]>,
    /// World points X,Y,Z to measure instead of picking pixels.
    #[arg(long = "point", value_parser = parse_f64x3, allow_hyphen_values = true, conflicts_with = "pixels")]
    points: Vec<[f64; 3]>,
    /// Opacity a voxel must exceed to be hit (0 to 1).
    #[arg(long, default_value_t = 0.1, value_parser = parse_opacity)]
    opacity: f32,
    /// Also render the scene with the measurement drawn in and its value written beside it,
    /// to this PNG.
    #[arg(long)]
    out: Option<PathBuf>,
    #[command(flatten)]
    annotate: AnnotateArgs,
}
pub fn run_measure(args: MeasureArgs) -> Result<()> {
    let view = args.view.load()?;
    let camera = view.single_camera()?;
    let View {
        mut loaded, size, ..
    } = view;
    let scene = &loaded.scene;
    let view = ViewSetup::new(&camera, size, scene.bounds())?;
    let options = PickOptions {
        opacity_threshold: args.opacity,
        volumes: true,
    };
    let mut points = Vec::new();
    let mut hits = Vec::new();
    if args.points.is_empty() {
        let picker = Picker::new(scene);
        for &pixel in &args.pixels {
            check_pixel(pixel, size)?;
            let hit = picker
                .pick_pixel(scene, &view, pixel[0], pixel[1], &options)
                .with_context(|| {
                    format!("nothing to measure at pixel {},{}", pixel[0], pixel[1])
                })?;
            points.push(hit.point());
            hits.push(hit.to_json(scene));
        }
    } else {
        points.extend(args.points.iter().map(|p| DVec3::from(*p)));
    }
    let kind = match points.len() {
        2 => MeasureKind::Distance,
        3 => MeasureKind::Angle,
        4 => MeasureKind::LineAngle,
        n => bail!("give two, three or four points (got {n})"),
    };
    // Checked as every measurement is: finite, within reach, and making an angle.
    let measurement = Measurement::new(kind, &points).map_err(anyhow::Error::msg)?;
    let mut out = serde_json::to_value(&measurement)?;
    if let Some(object) = out.as_object_mut() {
        object.insert("frame".into(), "RAS".into());
        object.insert("hits".into(), Value::Array(hits));
    }
    println!("{}", serde_json::to_string_pretty(&out)?);
    if let Some(path) = &args.out {
        refuse_inputs([path.clone()])?;
        let style = MarkerStyle::for_scene(&loaded.scene);
        let mut labels = draw_scene_measurements(&mut loaded.scene).map_err(anyhow::Error::msg)?;
        annotate(&mut loaded.scene, &measurement, &style)?;
        let options = FrameOptions {
            background: loaded.background,
            ..FrameOptions::default()
        };
        let ctx = GpuContext::headless()?;
        let shot = Renderer::new().screenshot(&ctx, &loaded.scene, &camera, size, &options)?;
        // The value is always written beside the measurement; the other parts as asked.
        let mut parts = args
            .annotate
            .parts()?
            .unwrap_or_else(|| Annotations::parse_parts("measurements").unwrap_or_default());
        parts.measurements = true;
        labels.push(measurement_label(&measurement));
        let image = figure(&shot, &loaded.scene, &camera, Some(&parts), &labels)?;
        write_replacing(path, &encode_png(&image)?)?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}
/// The text of a measurement and where it goes: the middle of a distance, the vertex of an
/// angle, the middle of the first line of a line angle.
fn measurement_label(m: &Measurement) -> Label {
    Label {
        at: m.label_anchor(),
        text: label_text(m, None),
    }
}
