//! The `splatscene` command line.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use glam::{DMat4, DVec3};
use indicatif::{ProgressBar, ProgressStyle};

use splatscene::classify::{Classified, TransferFunction, classify};
use splatscene::grid::SparseGrid;
use splatscene::order::{OrderOptions, Orderer, Ordering, ViewCase, VolumeGeometry};
use splatscene::render::{GpuContext, Renderer};
use splatscene::report::{self, Compositor, Entry, ReportSettings};
use splatscene::scene::{NodeContent, Scene, SplatSettings, VolumeNode};
use splatscene::volume::CpuVolume;
use splatscene::volume::phantom::shoulder_phantom_default;
use splatscene::volume::raw::{RawSpec, ScalarFormat, load_raw, load_raw_slices, slice_stack};

mod cli;

#[derive(Parser)]
#[command(
    name = "splatscene",
    version,
    about = "Shoulder-prosthesis planning scenes: CT splats in IP-PBTF order"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Let files named inside mesh files (glTF buffers, OBJ material libraries) lie outside
    /// the mesh file's folder; refused by default, so that a mesh from elsewhere cannot read
    /// any file of this machine.
    #[arg(long, global = true)]
    allow_outside_paths: bool,
}

#[derive(Subcommand)]
enum Command {
    /// Write the draw order of a dense grid as little-endian u32 voxel ids, first drawn first.
    Order(OrderArgs),
    /// Compare every ordering's run time and image error along a camera path.
    Orderings(OrderingsArgs),
    /// Render a scene file (the built-in shoulder scene without one) to a PNG.
    Render(cli::scenes::RenderArgs),
    /// Pick what lies under a pixel: prints the hit as JSON (or that nothing was hit).
    Pick(cli::scenes::PickArgs),
    /// Measure a distance or an angle between picked pixels or given points, as JSON.
    Measure(cli::scenes::MeasureArgs),
    /// Open a viewer window: orbit, pick, select and move meshes, measure, undo, save the plan,
    /// switch orderings and transfer functions.
    #[command(after_help = splatscene::viewer::keys_help())]
    View(cli::scenes::ViewerArgs),
    /// Render the pictures a manifest lists, many cases and views in one process (volumes
    /// classified once per job), resumable, and sharded over a Slurm array with --shard.
    Batch(cli::batch::BatchArgs),
    /// Describe volumes as JSON: size, spacing, origin, direction, scalar type, minimum,
    /// maximum and mean (one object for one file, an array for several). A DICOM series is
    /// given as its folder, a .dat or .nhdr volume as its header.
    Info(InfoArgs),
}

#[derive(clap::Args)]
struct InfoArgs {
    /// Volume files (or DICOM series folders).
    #[arg(required = true)]
    files: Vec<PathBuf>,
    #[command(flatten)]
    choices: cli::input::VolumeChoices,
}

#[derive(clap::Args)]
struct OrderArgs {
    /// Grid size NX,NY,NZ.
    #[arg(long, value_parser = parse_u32x3)]
    dims: [u32; 3],
    /// Voxel spacing SX,SY,SZ.
    #[arg(long, value_parser = parse_f64x3, default_value = "1,1,1")]
    spacing: [f64; 3],
    /// Eye in voxel index coordinates (voxel centres at integers).
    #[arg(long, value_parser = parse_f64x3, allow_hyphen_values = true)]
    eye: [f64; 3],
    /// Target in voxel index coordinates; the grid centre by default.
    #[arg(long, value_parser = parse_f64x3, allow_hyphen_values = true)]
    target: Option<[f64; 3]>,
    /// btf, wbtf, pbtf, ip-pbtf, ip-pbtf-explicit, ip-pbtf-implicit, exact, bucketed, pyramid or
    /// rows.
    #[arg(long)]
    ordering: Ordering,
    /// Output file; standard output when absent.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Leave out voxels on or behind the plane through the eye.
    #[arg(long)]
    cull_behind_eye: bool,
    /// Bucket width of the bucketed order, in the units of --spacing; half the smallest
    /// spacing by default.
    #[arg(long)]
    bucket_width: Option<f64>,
}

#[derive(clap::Args)]
struct OrderingsArgs {
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

fn main() -> Result<()> {
    quiet_device_select();
    let cli = Cli::parse();
    splatscene::mesh::allow_outside_paths(cli.allow_outside_paths);
    match cli.command {
        Command::Order(args) => run_order(args),
        Command::Orderings(args) => run_orderings(args),
        Command::Render(args) => cli::scenes::run_render(args),
        Command::Pick(args) => cli::scenes::run_pick(args),
        Command::Measure(args) => cli::scenes::run_measure(args),
        Command::View(args) => cli::scenes::run_viewer(args),
        Command::Info(args) => run_info(args),
        Command::Batch(args) => cli::batch::run_batch(args),
    }
}

/// Mesa's device-select Vulkan layer complains about XDG_RUNTIME_DIR on headless machines;
/// it is noise for a command-line renderer.
#[allow(unsafe_code)]
fn quiet_device_select() {
    if std::env::var_os("NODEVICE_SELECT").is_none() {
        // SAFETY: called first thing in main, before any other thread exists.
        unsafe { std::env::set_var("NODEVICE_SELECT", "1") };
    }
}

fn run_info(args: InfoArgs) -> Result<()> {
    let options = args.choices.options()?;
    let mut infos = Vec::with_capacity(args.files.len());
    for file in &args.files {
        infos.push(info_of(file, &options)?);
    }
    let out = match infos.len() {
        1 => infos.remove(0),
        _ => serde_json::Value::Array(infos),
    };
    println!("{}", serde_json::to_string_pretty(&out)?);
    Ok(())
}

/// Folders below a folder that `info` looks into for DICOM series, at most.
const MAX_INFO_FOLDERS: usize = 10_000;

/// A volume's description; for a folder tree holding anything but one series in the folder
/// itself, the list of every DICOM series found below it.
fn info_of(
    path: &Path,
    options: &splatscene::volume::detect::LoadOptions,
) -> Result<serde_json::Value> {
    let describe = |path: &Path| -> Result<serde_json::Value> {
        let loaded = splatscene::volume::detect::load_volume_with(path, options)?;
        Ok(loaded.info(path))
    };
    if !path.is_dir() || options.series.is_some() {
        return describe(path);
    }
    let mut series = Vec::new();
    let mut folders = vec![path.to_path_buf()];
    let mut seen = 0;
    while let Some(dir) = folders.pop() {
        seen += 1;
        if seen > MAX_INFO_FOLDERS {
            bail!(
                "{}: more than {MAX_INFO_FOLDERS} folders below it",
                path.display()
            );
        }
        series.extend(splatscene::volume::dicom::list_series(&dir)?);
        let mut subfolders: Vec<PathBuf> = std::fs::read_dir(&dir)
            .with_context(|| format!("{}: cannot list", dir.display()))?
            .filter_map(|e| e.ok())
            // Links to folders are not followed, so a link loop cannot walk forever.
            .filter(|e| e.file_type().is_ok_and(|t| t.is_dir()))
            .map(|e| e.path())
            .collect();
        subfolders.sort_unstable_by(|a, b| b.cmp(a));
        folders.extend(subfolders);
    }
    if let [only] = series.as_slice()
        && only.folder == path
    {
        return describe(path);
    }
    if series.is_empty() {
        bail!(
            "{}: no DICOM series in this folder or below it",
            path.display()
        );
    }
    Ok(serde_json::json!({
        "folder": path.display().to_string(),
        "series": series,
    }))
}

fn run_order(args: OrderArgs) -> Result<()> {
    let geometry = VolumeGeometry::axis_aligned(args.dims, args.spacing, [0.0; 3])?;
    let to_world = |p: [f64; 3]| geometry.index_to_world_point(DVec3::from(p));
    let target = args.target.map_or(geometry.centre_world(), to_world);
    let view = ViewCase::new(&geometry, to_world(args.eye), target)?;
    let needed = dense_order_bytes(args.dims, args.ordering);
    let available = splatscene::budget::memory_budget();
    if needed > available {
        let gib = |b: u64| b as f64 / f64::from(1u32 << 30);
        bail!(
            "--dims {},{},{}: the {} order of this dense grid needs about {:.1} GiB of memory; {:.1} GiB is available",
            args.dims[0],
            args.dims[1],
            args.dims[2],
            args.ordering,
            gib(needed),
            gib(available)
        );
    }
    let grid = SparseGrid::dense(args.dims)?;
    if args.bucket_width.is_some() && args.ordering != Ordering::Bucketed {
        bail!(
            "--bucket-width applies to the bucketed order only, not {}",
            args.ordering
        );
    }
    let options = OrderOptions {
        cull_behind_eye: args.cull_behind_eye,
        bucket_width: args.bucket_width,
    };
    let mut ids = Vec::new();
    let start = Instant::now();
    Orderer::new().order(&grid, &view, args.ordering, &options, &mut ids)?;
    let elapsed = start.elapsed();
    let bytes: Vec<u8> = ids.iter().flat_map(|id| id.to_le_bytes()).collect();
    match &args.out {
        Some(path) => write_replacing(path, &bytes)?,
        None => std::io::stdout()
            .lock()
            .write_all(&bytes)
            .context("writing the order to standard output")?,
    }
    eprintln!("{view}");
    eprintln!(
        "ordering {}: {} voxels in {:.3} ms",
        args.ordering,
        ids.len(),
        elapsed.as_secs_f64() * 1e3
    );
    Ok(())
}

/// About how many bytes ordering a dense grid of `dims` takes: the voxel bits, a run table
/// per axis (a row offset and a run per row), the order and its bytes, and the sort keys of
/// the exact and bucketed orders.
fn dense_order_bytes(dims: [u32; 3], ordering: Ordering) -> u64 {
    let n = dims.iter().map(|&d| u64::from(d)).product::<u64>();
    let rows: u64 = dims.iter().map(|&d| n / u64::from(d.max(1))).sum();
    let keys = match ordering {
        Ordering::Exact => 32 * n,
        Ordering::Bucketed => 8 * n,
        _ => 0,
    };
    n / 8 + 12 * rows + 8 * n + keys
}

pub(crate) use splatscene::output::{follow_links, write_atomic};

/// Writes `bytes` to `path` through a temporary file and a rename, so that a failed write
/// leaves any earlier file whole; says so when an existing file is replaced. A symbolic link
/// is followed and the file it names written; a device, pipe or socket (`/dev/null`, a FIFO)
/// is written into as it is, never replaced by a plain file.
pub(crate) fn write_replacing(path: &Path, bytes: &[u8]) -> Result<()> {
    // The file a link names is the one written, and the one to name.
    let target = follow_links(path)?;
    if write_atomic(&target, bytes)? {
        eprintln!("replaced the existing {}", target.display());
    }
    Ok(())
}

/// Views on each of the report's paths at most (each costs every ordering and a composite).
const MAX_VIEWS: usize = 10_000;

fn run_orderings(args: OrderingsArgs) -> Result<()> {
    let orderings = report_entries(&args.orderings, &args.bucket_widths)?;
    if args.gpu && !args.bucket_widths.is_empty() {
        bail!(
            "--bucket-widths: the GPU compositor draws the bucketed order at its default width only"
        );
    }
    // Sizes, the font and the folder of the plot, checked before minutes of measuring.
    splatscene::composite::check_frame_size(args.size.0, args.size.1).context("--size")?;
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
    cli::scenes::refuse_inputs(
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

fn parse_triple<T: std::str::FromStr>(s: &str) -> Result<[T; 3], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(format!("expected three comma-separated numbers, got {s:?}"));
    }
    let mut out = Vec::with_capacity(3);
    for p in parts {
        out.push(
            p.parse::<T>()
                .map_err(|_| format!("{p:?} is not a valid number"))?,
        );
    }
    out.try_into()
        .map_err(|_| "expected three numbers".to_owned())
}

pub(crate) fn parse_f64x2(s: &str) -> Result<[f64; 2], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let [a, b] = parts.as_slice() else {
        return Err(format!("expected two comma-separated numbers, got {s:?}"));
    };
    let parse = |v: &str| {
        v.parse::<f64>()
            .map_err(|_| format!("{v:?} is not a valid number"))
    };
    let pair = [parse(a)?, parse(b)?];
    finite(s, &pair)?;
    Ok(pair)
}

/// Refuses NaN and infinite numbers in the argument `s`.
fn finite(s: &str, values: &[f64]) -> Result<(), String> {
    match values.iter().find(|v| !v.is_finite()) {
        Some(v) => Err(format!("{v} in {s:?} is not finite")),
        None => Ok(()),
    }
}

/// A finite number.
pub(crate) fn parse_finite_f32(s: &str) -> Result<f32, String> {
    let v: f32 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a valid number"))?;
    finite(s, &[f64::from(v)])?;
    Ok(v)
}

/// An opacity, from 0 to 1.
pub(crate) fn parse_opacity(s: &str) -> Result<f32, String> {
    let v = parse_finite_f32(s)?;
    if (0.0..=1.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{v} is not an opacity from 0 to 1"))
    }
}

pub(crate) fn parse_f32x2(s: &str) -> Result<[f32; 2], String> {
    let [a, b] = parse_f64x2(s)?;
    let pair = [a as f32, b as f32];
    finite(s, &[f64::from(pair[0]), f64::from(pair[1])])?;
    Ok(pair)
}

pub(crate) fn parse_u32x2(s: &str) -> Result<[u32; 2], String> {
    let [a, b] = parse_f64x2(s)?;
    let whole =
        |v: f64| (v >= 0.0 && v.fract() == 0.0 && v <= f64::from(u32::MAX)).then_some(v as u32);
    match (whole(a), whole(b)) {
        (Some(a), Some(b)) => Ok([a, b]),
        _ => Err(format!("expected two whole numbers, got {s:?}")),
    }
}

pub(crate) fn parse_u32x3(s: &str) -> Result<[u32; 3], String> {
    parse_triple(s)
}

pub(crate) fn parse_f64x3(s: &str) -> Result<[f64; 3], String> {
    let triple = parse_triple(s)?;
    finite(s, &triple)?;
    Ok(triple)
}

pub(crate) fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("expected WxH, got {s:?}"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<u32>()
            .map_err(|_| format!("{v:?} is not a pixel count"))
    };
    let (w, h) = (parse(w)?, parse(h)?);
    if w == 0 || h == 0 {
        return Err("the image needs at least one pixel each way".into());
    }
    // The renderer's textures and the compositor's buffers bound an image.
    splatscene::budget::check_image(w.into(), h.into()).map_err(|e| e.to_string())?;
    Ok((w, h))
}
