//! `splatscene orderings`: every ordering's run time against its image error along a camera
//! path, as a report with plots.

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{Context, Result, bail};
use glam::DMat4;
use indicatif::{ProgressBar, ProgressStyle};
use splatscene::classify::{Classified, TransferFunction, classify};
use splatscene::order::Ordering;
use splatscene::render::{GpuContext, Renderer};
use splatscene::report::{self, Compositor, Entry, ReportSettings};
use splatscene::scene::{NodeContent, Scene, SplatSettings, VolumeNode};
use splatscene::volume::CpuVolume;
use splatscene::volume::phantom::shoulder_phantom_default;
use splatscene::volume::raw::{RawSpec, ScalarFormat, load_raw, load_raw_slices, slice_stack};

use super::args::{parse_f64x3, parse_finite_f32, parse_size, parse_u32x3};

#[derive(clap::Args)]
pub(crate) struct OrderingsArgs {
    /// A raw volume (needs --raw-dims and --raw-type) or the first file of a slice stack such
    /// as CThead.1; the built-in shoulder phantom when absent.
    volume: Option<PathBuf>,
    /// Size of the raw volume NX,NY,NZ.
    #[arg(long, value_parser = parse_u32x3)]
    raw_dims: Option<[u32; 3]>,
    /// Scalar type of the raw volume: u8, i16le, u16be, f32...
    #[arg(long)]
    raw_type: Option<ScalarFormat>,
    /// Bytes to skip at the start of each raw file.
    #[arg(long, default_value_t = 0)]
    raw_header: u64,
    /// Voxel spacing SX,SY,SZ of a raw volume.
    #[arg(long, value_parser = parse_f64x3, default_value = "1,1,1")]
    spacing: [f64; 3],
    /// Scalar value where splats start to show (raw volumes; the phantom uses the CT bone preset).
    #[arg(long, value_parser = parse_finite_f32)]
    threshold: Option<f32>,
    /// Views on the orbit.
    #[arg(long, default_value_t = 16)]
    orbit_views: usize,
    /// Views on the fly-in.
    #[arg(long, default_value_t = 8)]
    fly_in_views: usize,
    /// Image size WxH.
    #[arg(long, value_parser = parse_size, default_value = "192x192")]
    size: (u32, u32),
    /// Folder for the plots (error against time, PNG and SVG).
    #[arg(long, default_value = "orderings-report")]
    out_dir: PathBuf,
    /// Orderings to compare, comma-separated (the exact order is always computed as the
    /// reference); all of them by default.
    #[arg(long, value_delimiter = ',')]
    orderings: Vec<Ordering>,
    /// Bucket widths of the bucketed order to compare, comma-separated, in the volume's world
    /// units: one row each, in place of the default width.
    #[arg(long, value_delimiter = ',')]
    bucket_widths: Vec<f64>,
    /// Composite on the GPU with the renderer (flat colours, the report's splat shape and
    /// near plane, transparent background) instead of the CPU reference compositor, so that
    /// the error is measured on GPU images; adjacent inversions are then not counted, and a
    /// column gives the GPU's splat pass per ordering. Order times are the CPU's either way.
    #[arg(long)]
    gpu: bool,
}

/// Views on each of the report's paths at most (each costs every ordering and a composite).
const MAX_VIEWS: usize = 10_000;

/// Measures every ordering asked for along the orbit and the fly-in and writes the report.
pub(crate) fn run_orderings(args: OrderingsArgs) -> Result<()> {
    let orderings = report_entries(&args.orderings, &args.bucket_widths)?;
    if args.gpu && !args.bucket_widths.is_empty() {
        bail!(
            "--bucket-widths: the GPU compositor draws the bucketed order at its default width only"
        );
    }
    // Sizes, the font and the folder of the plot, checked before minutes of measuring.
    splatscene::splat::reference::check_frame_size(args.size.0, args.size.1).context("--size")?;
    for (flag, views) in [
        ("--orbit-views", args.orbit_views),
        ("--fly-in-views", args.fly_in_views),
    ] {
        if views > MAX_VIEWS {
            bail!("{flag}: {views} views; the report takes at most {MAX_VIEWS} of each");
        }
    }
    if args.orbit_views + args.fly_in_views == 0 {
        bail!(
            "--orbit-views and --fly-in-views are both 0: the report's camera path needs at least one view"
        );
    }
    report::register_font()?;
    std::fs::create_dir_all(&args.out_dir)
        .with_context(|| format!("creating {}", args.out_dir.display()))?;
    let (name, volume, tf, classified) = load_for_report(&args)?;
    super::render::refuse_inputs(
        ["png", "svg"].map(|e| args.out_dir.join(format!("error-vs-time.{e}"))),
    )?;
    let geometry = volume.geometry()?;
    eprintln!(
        "{name}: {:?} voxels, spacing {:?}, {} significant",
        volume.dims,
        volume.spacing,
        classified.grid.len()
    );
    let settings = ReportSettings {
        orbit_views: args.orbit_views,
        fly_in_views: args.fly_in_views,
        size: args.size,
        orderings,
        ..ReportSettings::default()
    };
    let path = report::camera_path(&geometry, settings.orbit_views, settings.fly_in_views);
    let cases = report::case_views(&geometry);
    let gpu = if args.gpu {
        let ctx = GpuContext::headless()?;
        eprintln!("compositing on {}", ctx.describe());
        Some((ctx, report_scene(volume, tf, &settings)?))
    } else {
        None
    };
    // The report measures every ordering on the volume's own grid.
    let mut renderer = Renderer::new();
    renderer.set_level_of_detail(false);
    let mut compositor = match &gpu {
        Some((ctx, scene)) => Compositor::Gpu {
            ctx,
            renderer: &mut renderer,
            scene,
        },
        None => Compositor::Cpu,
    };
    let bar = progress(path.len() + cases.len());
    let path_results = report::measure_views_with(
        &geometry,
        &classified,
        &path,
        &settings,
        &mut compositor,
        || bar.inc(1),
    )?;
    let case_results = report::measure_views_with(
        &geometry,
        &classified,
        &cases,
        &settings,
        &mut compositor,
        || bar.inc(1),
    )?;
    bar.finish_and_clear();
    let summaries = report::summarise(&path_results);
    println!("# Orderings on {name}\n");
    if let Some((ctx, ..)) = &gpu {
        println!("Composited on the GPU: {}.\n", ctx.describe());
    }
    println!(
        "{} views ({} orbit, {} fly-in ending inside the volume), {}x{} pixels, splat sigma {} voxel cut at {} voxels; error against the exact order.\n",
        path.len(),
        settings.orbit_views,
        settings.fly_in_views,
        settings.size.0,
        settings.size.1,
        settings.style.sigma,
        settings.style.cutoff
    );
    println!("{}", report::summary_table(&summaries));
    println!("## Per view: image RMSE (share of pixels off by more than 4/255)\n");
    println!("{}", report::per_view_table(&case_results));
    println!("{}", report::per_view_table(&path_results));
    let png = args.out_dir.join("error-vs-time.png");
    let svg = args.out_dir.join("error-vs-time.svg");
    let existed: Vec<&PathBuf> = [&png, &svg].into_iter().filter(|p| p.exists()).collect();
    report::plot_error_against_time(&summaries, &format!("Orderings on {name}"), &png, &svg)?;
    for path in existed {
        eprintln!("replaced the existing {}", path.display());
    }
    eprintln!("wrote {} and {}", png.display(), svg.display());
    Ok(())
}

/// The report's entries: the orderings asked for (all by default), with the bucketed order
/// once per bucket width when widths are given. Widths are checked here, before any volume is
/// loaded.
fn report_entries(orderings: &[Ordering], widths: &[f64]) -> Result<Vec<Entry>> {
    let orderings = if orderings.is_empty() {
        &Ordering::ALL[..]
    } else {
        orderings
    };
    if let Some(w) = widths.iter().find(|w| !(w.is_finite() && **w > 0.0)) {
        bail!("--bucket-widths: {w} is not a finite positive width");
    }
    if !widths.is_empty() && !orderings.contains(&Ordering::Bucketed) {
        bail!("--bucket-widths needs the bucketed order among --orderings");
    }
    let mut entries = Vec::new();
    for &ordering in orderings {
        if ordering == Ordering::Bucketed && !widths.is_empty() {
            entries.extend(widths.iter().map(|&w| Entry::bucketed(w)));
        } else {
            entries.push(Entry::from(ordering));
        }
    }
    Ok(entries)
}

/// The scene the GPU compositor draws: the volume alone, at the identity, with flat colours
/// (as the CPU reference compositor draws them) and the report's splat shape.
fn report_scene(
    volume: CpuVolume,
    tf: TransferFunction,
    settings: &ReportSettings,
) -> Result<Scene> {
    let mut scene = Scene::new();
    let node = VolumeNode {
        volume: Arc::new(volume),
        transfer: Arc::new(tf),
        splats: SplatSettings {
            style: settings.style,
            shading: 0.0,
            ..SplatSettings::default()
        },
    };
    scene.add("volume", DMat4::IDENTITY, None, NodeContent::Volume(node))?;
    Ok(scene)
}

/// The volume of the report, its transfer function and its classification.
fn load_for_report(
    args: &OrderingsArgs,
) -> Result<(String, CpuVolume, TransferFunction, Classified)> {
    let Some(path) = &args.volume else {
        let volume = shoulder_phantom_default();
        let tf = TransferFunction::ct_bone();
        let classified = classify(&volume, &tf, 1.0 / 255.0)?;
        return Ok((
            "the built-in shoulder phantom".into(),
            volume,
            tf,
            classified,
        ));
    };
    let (Some(dims), Some(format)) = (args.raw_dims, args.raw_type) else {
        bail!(
            "{}: give --raw-dims and --raw-type for a raw volume",
            path.display()
        );
    };
    let spec = RawSpec {
        header_bytes: args.raw_header,
        spacing: args.spacing,
        ..RawSpec::new(dims, format.scalar, format.order)
    };
    let is_stack = path.extension().is_some_and(|e| e == "1");
    let volume = if is_stack {
        load_raw_slices(&slice_stack(path)?, &spec)?
    } else {
        load_raw(path, &spec)?
    };
    let threshold = args
        .threshold
        .context("give --threshold for a raw volume")?;
    let (lo, hi) = value_range(&volume.values);
    let ramp_top = threshold + 0.25 * (hi - threshold).max(1.0);
    // The colour must change with the value: with one colour, "over" gives the same image in
    // any order and every ordering would show no error.
    let tf = TransferFunction::new(vec![
        (threshold, [0.85, 0.45, 0.3, 0.0]),
        (ramp_top, [1.0, 0.93, 0.85, 0.6]),
        (hi.max(ramp_top + 1.0), [0.7, 0.85, 1.0, 0.8]),
    ]);
    let classified = classify(&volume, &tf, 1.0 / 255.0)?;
    eprintln!("values {lo} to {hi}; splats from {threshold}, fully opaque-ish from {ramp_top}");
    Ok((path.display().to_string(), volume, tf, classified))
}

fn value_range(values: &splatscene::volume::Voxels) -> (f32, f32) {
    values
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        })
}

fn progress(len: usize) -> ProgressBar {
    let bar = ProgressBar::new(len as u64);
    if let Ok(style) =
        ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} views, {eta} left")
    {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message("ordering and compositing");
    bar
}
